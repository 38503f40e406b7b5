// PathTracer: properties, not snapshots. A closed emissive sphere converges to
// its analytic radiance; a diffuse plane under a point light matches the
// analytic irradiance; NEE, BSDF and MIS estimates agree; error falls as
// 1/sqrt(spp); output is identical for any thread count and with primary hits
// from a vbuffer; non-finite samples are dropped.
#include <gtest/gtest.h>
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "../../passes/PathTracer/Lights.h"
#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/CameraKernels.h"
#include "loom/Graph.h"
#include "loom/KernelMath.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

PluginRegistry& registry() { return test::pluginRegistry(); }
std::string scenePath(const std::string& name) { return test::dataScene(name); }

/// A graph of one PathTracer marking `color`, with params.
std::unique_ptr<RenderGraph> ptGraph(const nlohmann::json& params, uint32_t w, uint32_t h,
                                     const std::shared_ptr<Scene>& scene, bool split = false) {
    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "pt"},
                        {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", params}}}},
                        {"outputs", {"PT.color"}}};
    if (split) {
        g["outputs"].push_back("PT.direct");
        g["outputs"].push_back("PT.indirect");
    }
    return test::compiledGraph(g, scene, w, h);
}

void frame(RenderGraph& g, Scene& scene, uint64_t index, uint32_t w, uint32_t h) {
    scene.update(0.0);
    scene.camera.aspect = float(w) / float(h);
    scene.camera.beginFrame(index);
    g.execute(FrameInfo{index, 0.0, &scene, &scene.camera});
}

/// Mean of `frames` frames of PT.color (as double per pixel, RGB).
std::vector<glm::dvec3> averageFrames(RenderGraph& g, Scene& scene, uint32_t w, uint32_t h, uint64_t first,
                                      uint32_t frames) {
    std::vector<glm::dvec3> acc(size_t(w) * h, glm::dvec3(0.0));
    for (uint32_t f = 0; f < frames; ++f) {
        frame(g, scene, first + f, w, h);
        auto c = g.fieldTexture("PT.color")->view<glm::vec4>();
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) acc[size_t(y) * w + x] += glm::dvec3(glm::vec3(c.at(x, y)));
    }
    for (auto& v : acc) v /= double(frames);
    return acc;
}

/// A UV sphere of radius r whose front faces (and normals) point inward.
Mesh insideOutSphere(float r, uint32_t segments, uint32_t rings) {
    Mesh m;
    m.name = "sphere";
    for (uint32_t j = 0; j <= rings; ++j) {
        const float theta = float(j) / float(rings) * 3.14159265f;
        for (uint32_t i = 0; i <= segments; ++i) {
            const float phi = float(i) / float(segments) * 6.2831853f;
            const glm::vec3 d(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
            m.positions.push_back(r * d);
            m.normals.push_back(-d);
            m.tangents.push_back(glm::vec4(1.f, 0.f, 0.f, 1.f));
            m.uvs.push_back(glm::vec2(0.f));
        }
    }
    for (uint32_t j = 0; j < rings; ++j) {
        for (uint32_t i = 0; i < segments; ++i) {
            const uint32_t a = j * (segments + 1) + i, b = a + segments + 1;
            // Counter-clockwise seen from inside (the normal's side).
            if (j != 0) m.indices.insert(m.indices.end(), {a, b, a + 1});
            if (j + 1 != rings) m.indices.insert(m.indices.end(), {a + 1, b, b + 1});
        }
    }
    for (const auto& p : m.positions) m.bounds.extend(p);
    return m;
}

Mesh quad(glm::vec3 corner, glm::vec3 u, glm::vec3 v) {
    Mesh m;
    m.name = "quad";
    const glm::vec3 n = glm::normalize(glm::cross(u, v));
    for (glm::vec3 p : {corner, corner + u, corner + u + v, corner + v}) {
        m.positions.push_back(p);
        m.normals.push_back(n);
        m.tangents.push_back(glm::vec4(glm::normalize(u), 1.f));
        m.uvs.push_back(glm::vec2(0.f));
        m.bounds.extend(p);
    }
    m.indices = {0, 1, 2, 0, 2, 3};
    return m;
}

std::shared_ptr<Scene> sceneOf(std::vector<Mesh> meshes, std::vector<Material> materials) {
    auto s = std::make_shared<Scene>();
    s->name = "test";
    for (size_t i = 0; i < meshes.size(); ++i) {
        meshes[i].material = uint32_t(std::min(i, materials.size() - 1));
        s->meshes.push_back(std::move(meshes[i]));
        Node n;
        n.name = "n";
        n.name += std::to_string(i);  // not "n" + ...: GCC 12 warns falsely (-Wrestrict) on that
        n.meshes = {uint32_t(i)};
        s->nodes.push_back(n);
        s->roots.push_back(int(i));
    }
    s->materials = std::move(materials);
    return s;
}

Material lambert(glm::vec3 color, glm::vec3 emission = glm::vec3(0.f)) {
    Material m;
    m.baseColorFactor = glm::vec4(color, 1.f);
    m.metallicFactor = 0.f;
    m.roughnessFactor = 1.f;
    m.emissiveFactor = emission;
    return m;
}

void lookAt(Scene& s, glm::vec3 eye, glm::vec3 target, float fovY) {
    s.setCameraPose(glm::inverse(glm::lookAt(eye, target, glm::vec3(0.f, 0.f, -1.f))));
    s.camera.fovY = fovY;
}

double meanLuminance(const std::vector<glm::dvec3>& img) {
    double sum = 0.0;
    for (const auto& v : img) sum += kRec709R * v.x + kRec709G * v.y + kRec709B * v.z;
    return sum / double(img.size());
}

/// Mean luminance per B x B block of a W x H image, and over the whole image (the last entry), from `frames`
/// independent frames of PT.color: means, their standard errors (from the spread of the frames), and the variance
/// of one frame's pixel value, averaged over pixels.
struct BlockEstimate {
    std::vector<double> mean, se;
    double pixelVariance = 0.0;
};
BlockEstimate estimateBlocks(RenderGraph& g, Scene& scene, uint32_t W, uint32_t H, uint32_t B, uint32_t frames) {
    const uint32_t blocks = (W / B) * (H / B) + 1;
    std::vector<double> sum(blocks, 0.0), sumSq(blocks, 0.0), pixSum(W * H, 0.0), pixSumSq(W * H, 0.0);
    for (uint32_t f = 0; f < frames; ++f) {
        const auto img = averageFrames(g, scene, W, H, f, 1);
        std::vector<double> m(blocks, 0.0);
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                const glm::dvec3 v = img[size_t(y) * W + x];
                const double lum = kRec709R * v.x + kRec709G * v.y + kRec709B * v.z;
                m[(y / B) * (W / B) + x / B] += lum / double(B * B);
                m[blocks - 1] += lum / double(W * H);
                pixSum[y * W + x] += lum;
                pixSumSq[y * W + x] += lum * lum;
            }
        for (uint32_t i = 0; i < blocks; ++i) {
            sum[i] += m[i];
            sumSq[i] += m[i] * m[i];
        }
    }
    BlockEstimate e;
    for (uint32_t i = 0; i < blocks; ++i) {
        e.mean.push_back(sum[i] / frames);
        const double var = std::max(0.0, (sumSq[i] - sum[i] * sum[i] / frames) / (frames - 1));
        e.se.push_back(std::sqrt(var / frames));
    }
    for (uint32_t i = 0; i < W * H; ++i)
        e.pixelVariance += (pixSumSq[i] - pixSum[i] * pixSum[i] / frames) / (frames - 1) / double(W * H);
    return e;
}

/// Two unbiased estimates of the same image agree per block within 4.5 standard errors, and that tolerance is tight
/// enough to mean something: under 5% of the image mean.
void expectSameImage(const BlockEstimate& a, const BlockEstimate& b, const std::string& what) {
    const size_t whole = a.mean.size() - 1;
    for (size_t i = 0; i <= whole; ++i) {
        const double tol = 4.5 * std::hypot(a.se[i], b.se[i]) + 1e-6;
        EXPECT_NEAR(a.mean[i], b.mean[i], tol) << what << ", block " << i;
    }
    EXPECT_LT(4.5 * std::hypot(a.se[whole], b.se[whole]), 0.05 * b.mean[whole]) << what;
}

}  // namespace

// Inside a closed sphere whose surface emits E and reflects a fraction a
// diffusely (Lambert), radiance everywhere is E (1 + a + ... + a^N) after N
// bounces: the white-furnace test of the whole integrator (NEE, MIS, RR).
TEST(PathTracer, ClosedEmissiveSphereConvergesToAnalyticRadiance) {
    const float a = 0.6f, E = 0.5f;
    for (int maxBounces : {0, 1, 4}) {
        auto scene = sceneOf({insideOutSphere(2.f, 48, 24)}, {lambert(glm::vec3(a), glm::vec3(E))});
        scene->finalize();
        scene->setCameraPose(glm::mat4(1.f));
        scene->camera.fovY = 1.2f;
        const uint32_t W = 24, H = 24;
        auto g = ptGraph({{"maxBounces", maxBounces}, {"samplesPerPixel", 16}, {"lambertOnly", true}}, W, H, scene);
        const auto img = averageFrames(*g, *scene, W, H, 0, 4);
        double expected = 0.0;
        for (int k = 0; k <= maxBounces; ++k) expected += E * std::pow(a, k);
        const double got = meanLuminance(img);
        std::printf("furnace maxBounces=%d: %.5f expected %.5f\n", maxBounces, got, expected);
        EXPECT_NEAR(got, expected, 0.01 * expected) << "maxBounces " << maxBounces;
    }
}

// A Lambertian plane under a point light: L = a/pi * I cos(theta) / d^2 at
// every pixel (one bounce; the light is a delta, so the estimate is exact).
TEST(PathTracer, DiffusePlaneUnderPointLightMatchesAnalyticIrradiance) {
    const float albedo = 0.7f, intensity = 5.f;
    const glm::vec3 lightPos(0.3f, 2.f, -0.2f);
    auto scene = sceneOf({quad(glm::vec3(-4.f, 0.f, 4.f), glm::vec3(8.f, 0.f, 0.f), glm::vec3(0.f, 0.f, -8.f))},
                         {lambert(glm::vec3(albedo))});
    Light l;
    l.type = LightType::Point;
    l.intensity = intensity;
    l.position = lightPos;
    scene->lights.push_back(l);
    scene->finalize();
    lookAt(*scene, glm::vec3(0.f, 3.f, 0.f), glm::vec3(0.f, 0.f, 0.f), 1.0f);
    const uint32_t W = 32, H = 32;
    auto g = ptGraph({{"maxBounces", 1}, {"lambertOnly", true}}, W, H, scene);
    frame(*g, *scene, 0, W, H);
    const CameraData cam = makeCameraData(scene->camera, W, H);
    auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
    int checked = 0;
    for (uint32_t y = 0; y < H; ++y) {
        for (uint32_t x = 0; x < W; ++x) {
            const glm::vec3 d = pixelRayDir(cam, x, y);
            ASSERT_LT(d.y, 0.f);
            const glm::vec3 p = cam.origin + d * (-cam.origin.y / d.y);
            const glm::vec3 toLight = lightPos - p;
            const float dist2 = glm::dot(toLight, toLight);
            const float cosTheta = toLight.y / std::sqrt(dist2);
            const float expected = albedo / 3.14159265f * intensity * cosTheta / dist2;
            EXPECT_NEAR(c.at(x, y).r, expected, 2e-3f * expected) << x << "," << y;
            ++checked;
        }
    }
    EXPECT_EQ(checked, int(W * H));
}

// Light sampling only, BRDF sampling only and their MIS combination are
// three unbiased estimators of the same image: per 8x8 block and overall,
// their means agree within 4.5 standard errors (estimated from the spread of
// independent frames).
TEST(PathTracer, NeeBsdfAndMisConvergeToTheSameImage) {
    const uint32_t W = 32, H = 32, frames = 24, B = 8;
    std::vector<BlockEstimate> e;
    const char* modes[] = {"mis", "nee", "bsdf"};
    for (int k = 0; k < 3; ++k) {
        auto scene = Scene::load(scenePath("cornell_box.gltf"));
        auto g = ptGraph({{"maxBounces", 2}, {"samplesPerPixel", 16}, {"lightSampling", modes[k]}}, W, H, scene);
        e.push_back(estimateBlocks(*g, *scene, W, H, B, frames));
        std::printf("%s: image mean %.5f +- %.5f\n", modes[k], e[k].mean.back(), e[k].se.back());
    }
    for (int k = 1; k < 3; ++k) expectSameImage(e[k], e[0], std::string(modes[k]) + " vs mis");
}

// RMSE against a long reference falls as spp^-1/2: the fitted log-log slope
// is near -0.5.
TEST(PathTracer, ErrorFallsAsInverseSquareRootOfSamples) {
    const uint32_t W = 24, H = 24;
    auto scene = Scene::load(scenePath("cornell_box.gltf"));
    auto ref = ptGraph({{"maxBounces", 3}, {"samplesPerPixel", 256}, {"seed", 7}}, W, H, scene);
    const auto reference = averageFrames(*ref, *scene, W, H, 0, 8);  // 2048 spp
    std::vector<double> xs, ys;
    for (int spp : {1, 4, 16, 64}) {
        // Average the squared error over several independent frames for a stable RMSE.
        auto g = ptGraph({{"maxBounces", 3}, {"samplesPerPixel", spp}, {"seed", 1}}, W, H, scene);
        double se = 0.0;
        const int repeats = 4;
        for (int r = 0; r < repeats; ++r) {
            const auto img = averageFrames(*g, *scene, W, H, uint64_t(100 + r), 1);
            for (size_t i = 0; i < img.size(); ++i) {
                const glm::dvec3 d = img[i] - reference[i];
                se += glm::dot(d, d) / 3.0;
            }
        }
        const double rmse = std::sqrt(se / (double(repeats) * double(W * H)));
        xs.push_back(std::log(double(spp)));
        ys.push_back(std::log(rmse));
        std::printf("spp %3d: RMSE %.5f\n", spp, rmse);
    }
    double mx = 0, my = 0;
    for (size_t i = 0; i < xs.size(); ++i) {
        mx += xs[i] / xs.size();
        my += ys[i] / ys.size();
    }
    double sxy = 0, sxx = 0;
    for (size_t i = 0; i < xs.size(); ++i) {
        sxy += (xs[i] - mx) * (ys[i] - my);
        sxx += (xs[i] - mx) * (xs[i] - mx);
    }
    const double slope = sxy / sxx;
    std::printf("fitted slope %.3f\n", slope);
    EXPECT_NEAR(slope, -0.5, 0.08);
}

// An emitter whose emissive texture is black on its left half and white on its right: a 4 x 4 grid of cells (32
// triangles) at y = 1 facing down over a white floor, written as a glTF with a PNG by the test. The cells span uv
// [0.125, 0.875]^2 over a 16 x 4 texture (texels 0-7 black, 8-15 white), so the first column (u up to 0.3125) lies
// over black texels only, the bilinear blend of black and white (u in (0.46875, 0.53125), repeat wrap) reaches into
// the second and third columns by 1/32, and the last reads white. Triangle 2 (4 j + i) + k is of cell column i, row j.
class HalfBlackEmitter : public loom::test::TempDirTest {
protected:
    static constexpr uint32_t kGrid = 4;
    std::shared_ptr<Scene> load() {
        std::vector<uint8_t> texels(16 * 4 * 4, 255);
        for (uint32_t y = 0; y < 4; ++y)
            for (uint32_t x = 0; x < 8; ++x)
                for (int c = 0; c < 3; ++c) texels[(y * 16 + x) * 4 + c] = 0;
        EXPECT_NE(stbi_write_png((mDir / "half.png").c_str(), 16, 4, 4, texels.data(), 16 * 4), 0);
        std::vector<float> positions, uvs;
        std::vector<uint32_t> indices;
        for (uint32_t j = 0; j <= kGrid; ++j)
            for (uint32_t i = 0; i <= kGrid; ++i) {
                positions.insert(positions.end(), {-1.f + 0.5f * float(i), 1.f, -1.f + 0.5f * float(j)});
                uvs.insert(uvs.end(), {0.125f + 0.1875f * float(i), 0.125f + 0.1875f * float(j)});
            }
        for (uint32_t j = 0; j < kGrid; ++j)
            for (uint32_t i = 0; i < kGrid; ++i) {
                const uint32_t a = j * (kGrid + 1) + i, b = a + 1, c = b + kGrid + 1, d = a + kGrid + 1;
                indices.insert(indices.end(), {a, b, c, a, c, d});  // counter-clockwise seen from below
            }
        const nlohmann::json material = {
            {"name", "HalfBlack"},
            {"pbrMetallicRoughness", {{"baseColorFactor", {0, 0, 0, 1}}, {"metallicFactor", 0}}},
            {"emissiveFactor", {1, 1, 1}},
            {"emissiveTexture", {{"index", 0}}}};
        auto scene = Scene::load(
            loom::test::writeTriangleGltf(mDir, "emitter", positions, uvs, indices, material, {"half.png"}));
        // A white floor below it, facing up.
        Mesh floor = quad(glm::vec3(-3.f, 0.f, 3.f), glm::vec3(6.f, 0.f, 0.f), glm::vec3(0.f, 0.f, -6.f));
        floor.material = uint32_t(scene->materials.size());
        scene->materials.push_back(lambert(glm::vec3(0.8f)));
        scene->meshes.push_back(std::move(floor));
        Node n;
        n.name = "floor";
        n.meshes = {uint32_t(scene->meshes.size() - 1)};
        scene->nodes.push_back(n);
        scene->roots.push_back(int(scene->nodes.size() - 1));
        scene->finalize();
        lookAt(*scene, glm::vec3(0.f, 0.6f, 4.f), glm::vec3(0.f, 0.f, 0.f), 0.9f);
        return scene;
    }
};

// The mean emission over each triangle (through evalSurface's texture sampling): exactly 0 over black texels, the
// emissive factor over white ones, and a sliver of the blend in the second column. Only the triangles with emission
// are lights (the pass's lightTriangles counter); with "area" weights (the texture ignored) all 32 are.
TEST_F(HalfBlackEmitter, TrianglesOverBlackTexelsAreNoLights) {
    auto scene = load();
    ASSERT_EQ(scene->instances.size(), 2u);
    ASSERT_EQ(scene->meshes[scene->instances[0].mesh].triangleCount(), 2 * kGrid * kGrid);
    for (uint32_t t = 0; t < 2 * kGrid * kGrid; ++t) {
        const uint32_t column = (t / 2) % kGrid;
        const float mean = pt::meanEmittedLuminance(scene->view(), 0, t, 8);
        if (column == 0)
            EXPECT_EQ(mean, 0.f) << t;
        else if (column == 1)
            EXPECT_TRUE(mean > 0.f && mean < 0.1f) << t << ": " << mean;  // the blend reaches its last sixth
        else if (column == 2)
            EXPECT_TRUE(mean > 0.85f && mean < 1.f) << t << ": " << mean;  // and its first sixth
        else
            EXPECT_NEAR(mean, 1.f, 1e-5f) << t;
    }
    for (const char* weights : {"texture", "area"}) {
        auto g = ptGraph({{"maxBounces", 1}, {"emissionWeights", weights}}, 8, 8, scene);
        frame(*g, *scene, 0, 8, 8);
        const std::map<std::string, double> stats = g->lastStats().at("PT");
        EXPECT_EQ(stats.at("emissiveTriangles"), 32.0);
        EXPECT_EQ(stats.at("lightTriangles"), std::string(weights) == "texture" ? 24.0 : 32.0) << weights;
    }
}

// Light sampling by the texture's mean per triangle is unbiased and better: light sampling only, BRDF sampling only
// and MIS agree per 8x8 block within 4.5 standard errors (from the spread of independent frames), with either
// weighting; and light sampling's per-pixel variance is lower with per-triangle weights than with area weights
// (which spend about half the light samples on black texels).
TEST_F(HalfBlackEmitter, LightSamplingIsUnbiasedWithLowerVariance) {
    auto scene = load();
    const uint32_t W = 32, H = 32, frames = 16, B = 8;
    auto estimate = [&](const char* mode, const char* weights, bool lambert = true) {
        auto g = ptGraph({{"maxBounces", 2},
                          {"samplesPerPixel", 8},
                          {"lightSampling", mode},
                          {"lambertOnly", lambert},
                          {"emissionWeights", weights}},
                         W, H, scene);
        const BlockEstimate e = estimateBlocks(*g, *scene, W, H, B, frames);
        std::printf("%s, %s weights%s: image mean %.5f +- %.5f, mean per-pixel variance %.3g\n", mode, weights,
                    lambert ? "" : ", glTF BRDF", e.mean.back(), e.se.back(), e.pixelVariance);
        return e;
    };
    const BlockEstimate bsdf = estimate("bsdf", "texture");
    const BlockEstimate nee = estimate("nee", "texture"), mis = estimate("mis", "texture");
    const BlockEstimate neeArea = estimate("nee", "area"), misArea = estimate("mis", "area");
    expectSameImage(nee, bsdf, "nee vs bsdf");
    expectSameImage(mis, bsdf, "mis vs bsdf");
    expectSameImage(neeArea, bsdf, "nee (area weights) vs bsdf");
    expectSameImage(misArea, bsdf, "mis (area weights) vs bsdf");
    // The glTF BRDF, whose MIS runs in SIMD lanes (ShadeSimd.cpp), over the whole image: its specular lobe on the
    // emitter's underside reflects the lit floor, which BRDF sampling alone finds in a handful of paths, so blocks
    // that see only that can read exactly 0 at this sample count.
    const BlockEstimate misGltf = estimate("mis", "texture", false), bsdfGltf = estimate("bsdf", "texture", false);
    EXPECT_NEAR(misGltf.mean.back(), bsdfGltf.mean.back(), 4.5 * std::hypot(misGltf.se.back(), bsdfGltf.se.back()));
    EXPECT_GT(bsdf.mean.back(), 0.02);  // lit
    std::printf("variance ratio texture / area weights: nee %.3f, mis %.3f\n",
                nee.pixelVariance / neeArea.pixelVariance, mis.pixelVariance / misArea.pixelVariance);
    EXPECT_LT(nee.pixelVariance, 0.8 * neeArea.pixelVariance);
    EXPECT_LT(mis.pixelVariance, 0.9 * misArea.pixelVariance);
}

// The same image for any thread count, and with primary hits from GBufferRT's
// vbuffer instead of camera rays.
TEST(PathTracer, IdenticalForThreadCountsAndVBufferPrimaryHits) {
    const uint32_t W = 48, H = 40;
    auto render = [&](unsigned threads, bool viaVBuffer) {
        ThreadLimit limit(threads);
        auto scene = Scene::load(scenePath("cornell_box.gltf"));
        scene->camera.jitterPattern = JitterPattern::Halton;
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "pt"},
                            {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", {{"samplesPerPixel", 2}}}}}},
                            {"outputs", {"PT.color"}}};
        if (viaVBuffer) g["passes"].push_back({{"name", "GBuffer"}, {"type", "GBufferRT"}});
        RenderGraph graph(parseGraph(g.dump()), registry());
        graph.setScene(scene);
        CompileOptions o;
        o.width = W;
        o.height = H;
        graph.compile(o);
        EXPECT_EQ(graph.plan().order.size(), viaVBuffer ? 2u : 1u);  // vbuffer wired by name
        frame(graph, *scene, 5, W, H);
        const Texture* c = graph.fieldTexture("PT.color");
        Texture copy(c->width(), c->height(), c->format());
        copy.copyFrom(*c);
        return copy;
    };
    const Texture one = render(1, false), two = render(2, false), vb = render(2, true);
    EXPECT_TRUE(one.samePixels(two));
    EXPECT_TRUE(one.samePixels(vb));
}

// A sample that overflows to Inf is dropped and counted; nothing non-finite
// reaches the output.
TEST(PathTracer, NonFiniteSamplesAreDroppedAndCounted) {
    auto scene = sceneOf({insideOutSphere(1.f, 16, 8)}, {lambert(glm::vec3(0.5f), glm::vec3(3e38f))});
    scene->finalize();
    scene->setCameraPose(glm::mat4(1.f));
    const uint32_t W = 8, H = 8;
    auto g = ptGraph({{"maxBounces", 2}}, W, H, scene);
    frame(*g, *scene, 0, W, H);
    auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
    for (uint32_t y = 0; y < H; ++y)
        for (uint32_t x = 0; x < W; ++x)
            for (int k = 0; k < 4; ++k) ASSERT_TRUE(std::isfinite(c.at(x, y)[k])) << x << "," << y;
    EXPECT_GT(g->lastStats().at("PT").at("nonFiniteSamplesDropped"), 0.0);
}

// The only light, on a node scaled to 0 along its normal, keeps its area but is hidden (Instance::visible):
// next-event estimation must not sample it either, so the frame is black. Unflattened, it lights the floor.
TEST(PathTracer, AHiddenLightCastsNoLight) {
    for (bool flattened : {false, true}) {
        auto scene = sceneOf({quad({-2.f, 0.f, -2.f}, {4.f, 0.f, 0.f}, {0.f, 0.f, 4.f}),
                              quad({-0.5f, 0.f, -0.5f}, {1.f, 0.f, 0.f}, {0.f, 0.f, 1.f})},
                             {lambert(glm::vec3(0.8f)), lambert(glm::vec3(0.f), glm::vec3(5.f))});
        scene->nodes[0].translation = glm::vec3(0.f, -1.f, 0.f);  // the floor faces up, the light down
        scene->nodes[0].rotation = glm::angleAxis(3.14159265f, glm::vec3(1.f, 0.f, 0.f));
        scene->nodes[1].translation = glm::vec3(0.f, 1.f, 0.f);
        if (flattened) scene->nodes[1].scale = glm::vec3(1.f, 0.f, 1.f);
        scene->finalize();
        lookAt(*scene, glm::vec3(3.f, 0.5f, 0.f), glm::vec3(0.f, -1.f, 0.f), 1.2f);
        const uint32_t W = 16, H = 16;
        auto g = ptGraph({{"maxBounces", 2}, {"samplesPerPixel", 4}}, W, H, scene);
        const double mean = meanLuminance(averageFrames(*g, *scene, W, H, 0, 2));
        if (flattened)
            EXPECT_EQ(mean, 0.0);
        else
            EXPECT_GT(mean, 0.05);
    }
}

// color = direct + indirect.
TEST(PathTracer, DirectPlusIndirectIsColor) {
    const uint32_t W = 16, H = 16;
    auto scene = Scene::load(scenePath("cornell_box.gltf"));
    auto g = ptGraph({{"maxBounces", 4}}, W, H, scene, true);
    frame(*g, *scene, 0, W, H);
    auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
    auto d = g->fieldTexture("PT.direct")->view<glm::vec4>();
    auto i = g->fieldTexture("PT.indirect")->view<glm::vec4>();
    double indirectSum = 0.0;
    for (uint32_t y = 0; y < H; ++y)
        for (uint32_t x = 0; x < W; ++x) {
            const glm::vec4 s = d.at(x, y) + i.at(x, y);
            for (int k = 0; k < 3; ++k) EXPECT_NEAR(c.at(x, y)[k], s[k], 1e-5f * (1.f + std::fabs(s[k])));
            indirectSum += i.at(x, y).r;
        }
    EXPECT_GT(indirectSum, 0.0);
}

// The SIMD vertex shading (ShadeSimd.cpp) and the per-path kernel (shadeVertex) implement the same estimator with the
// same random numbers: per pixel they agree to float rounding, except where rounding sends a ray the other way past
// an edge, which changes that path's later vertices. Checked on the Cornell box (diffuse, RR on), the dynamic scene's
// glossy sphere (the GGX lobe, VNDF sampling) and the materials scene (metals, textures, normal maps, a double-sided
// card, point and spot lights), with the direct/indirect split.
TEST(PathTracer, SimdShadingAgreesWithPerPathKernel) {
    const uint32_t W = 64, H = 64;
    for (const char* name :
         {"cornell_box.gltf", "cornell_dynamic.gltf", "materials.gltf", "materials.gltf plain", "materials.gltf ior"}) {
        // "plain": the BRDF without energy compensation; "ior": every material with a coloured dielectric Fresnel
        // (KHR_materials_ior and KHR_materials_specular).
        const std::string file = std::string(name).substr(0, std::string(name).find(' '));
        const bool compensated = std::string(name).find("plain") == std::string::npos;
        auto render = [&](bool simd) {
            auto scene = Scene::load(scenePath(file));
            if (std::string(name).find("ior") != std::string::npos) {
                for (Material& m : scene->materials) {
                    m.ior = 2.f;
                    m.specularFactor = 0.8f;
                    m.specularColorFactor = glm::vec3(1.f, 0.5f, 0.2f);
                }
                scene->finalize();
            }
            auto g = ptGraph({{"maxBounces", 4},
                              {"samplesPerPixel", 4},
                              {"rrStartBounce", 2},
                              {"simdShading", simd},
                              {"energyCompensation", compensated}},
                             W, H, scene, true);
            frame(*g, *scene, 3, W, H);
            std::vector<glm::vec4> out;
            for (const char* f : {"PT.color", "PT.direct", "PT.indirect"}) {
                auto v = g->fieldTexture(f)->view<glm::vec4>();
                for (uint32_t y = 0; y < H; ++y)
                    for (uint32_t x = 0; x < W; ++x) out.push_back(v.at(x, y));
            }
            return out;
        };
        const auto a = render(true), b = render(false);
        ASSERT_EQ(a.size(), b.size());
        size_t close = 0, lit = 0;
        double sumA = 0.0, sumB = 0.0;
        for (size_t i = 0; i < a.size(); ++i) {
            bool same = true;
            for (int k = 0; k < 3; ++k) {
                ASSERT_TRUE(std::isfinite(a[i][k]));
                same = same && std::fabs(a[i][k] - b[i][k]) <= 1e-4f * std::max(1.f, std::fabs(b[i][k]));
                sumA += a[i][k];
                sumB += b[i][k];
            }
            close += same ? 1 : 0;
            lit += (b[i].r + b[i].g + b[i].b > 0.f) ? 1 : 0;
        }
        std::printf("%s: %zu of %zu values agree to 1e-4, %zu lit\n", name, close, a.size(), lit);
        EXPECT_GT(lit, a.size() / 3) << name;  // the comparison is over lit images, not over black
        EXPECT_GE(double(close), 0.98 * double(a.size())) << name;
        EXPECT_NEAR(sumA, sumB, 1e-2 * sumB) << name;
    }
}

namespace {

/// A UV sphere of radius r around the origin, normals and front faces outward.
Mesh sphere(float r, uint32_t segments, uint32_t rings) {
    Mesh m = insideOutSphere(r, segments, rings);
    for (auto& n : m.normals) n = -n;
    for (size_t i = 0; i < m.indices.size(); i += 3) std::swap(m.indices[i + 1], m.indices[i + 2]);
    return m;
}

/// n.wo at the unit sphere's surface seen through pixel (x, y), or -1 where the ray misses it.
float sphereCosine(const CameraData& cam, uint32_t x, uint32_t y) {
    const glm::vec3 d = glm::normalize(pixelRayDir(cam, x, y)), o = cam.origin;
    const float b = glm::dot(o, d), c = glm::dot(o, o) - 1.f, disc = b * b - c;
    if (disc <= 0.f) return -1.f;
    const glm::vec3 p = o + d * (-b - std::sqrt(disc));
    return -glm::dot(glm::normalize(p), d);
}

}  // namespace

// The white furnace of issue-level accuracy: a white sphere under a uniform white environment reflects all the
// light it receives, so every pixel of it converges to 1, head-on and at grazing views. With the plain glTF model a
// rough metal loses the energy of multiple scattering (darker toward grazing views) and a smooth dielectric creates
// energy at grazing views; the compensated model stays within [0.97, 1.01] in every ring of views.
TEST(PathTracer, WhiteFurnaceSpheresReflectAllLight) {
    const uint32_t W = 64, H = 64, spp = 64;
    std::printf("| material | roughness | model | head-on (n.wo > 0.9) | middle | grazing (n.wo < 0.3) |\n");
    for (bool compensated : {false, true}) {
        for (float metallic : {0.f, 1.f}) {
            for (float roughness : {0.05f, 0.5f, 1.f}) {
                Material m;
                m.baseColorFactor = glm::vec4(1.f);
                m.metallicFactor = metallic;
                m.roughnessFactor = roughness;
                auto scene = sceneOf({sphere(1.f, 96, 48)}, {m});
                scene->environment.color = glm::vec3(1.f);
                scene->finalize();
                lookAt(*scene, glm::vec3(0.f, 3.2f, 0.f), glm::vec3(0.f), 0.75f);
                auto g = ptGraph({{"maxBounces", 8},
                                  {"rrStartBounce", 64},
                                  {"samplesPerPixel", int(spp)},
                                  {"energyCompensation", compensated}},
                                 W, H, scene);
                frame(*g, *scene, 0, W, H);
                const CameraData cam = makeCameraData(scene->camera, W, H);
                auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
                double sum[3] = {0, 0, 0};
                int count[3] = {0, 0, 0};
                for (uint32_t y = 0; y < H; ++y) {
                    for (uint32_t x = 0; x < W; ++x) {
                        const float mu = sphereCosine(cam, x, y);
                        // Pixels wholly on the sphere: its silhouette pixels mix in the environment.
                        if (mu < 0.08f) continue;
                        const int ring = mu > 0.9f ? 0 : mu < 0.3f ? 2 : 1;
                        sum[ring] += c.at(x, y).g;
                        ++count[ring];
                    }
                }
                double mean[3];
                for (int k = 0; k < 3; ++k) {
                    ASSERT_GT(count[k], 20);
                    mean[k] = sum[k] / count[k];
                }
                std::printf("| %s | %.2f | %s | %.4f | %.4f | %.4f |\n", metallic > 0.f ? "metal" : "dielectric",
                            roughness, compensated ? "compensated" : "plain", mean[0], mean[1], mean[2]);
                if (compensated) {
                    for (int k = 0; k < 3; ++k) {
                        EXPECT_GE(mean[k], 0.97) << "metallic " << metallic << " roughness " << roughness;
                        EXPECT_LE(mean[k], 1.01) << "metallic " << metallic << " roughness " << roughness;
                    }
                } else if (metallic > 0.f && roughness == 1.f) {
                    EXPECT_LT(mean[2], 0.9);  // the energy multiple scattering would return is lost
                }
            }
        }
    }
}

// A normal map tilts a mirror's shading normal by 50 degrees: reflecting the head-on view about it would leave
// through the geometric surface, where a path ends (black). Bent normals (bendShadingNormal) keep the reflection
// above the surface, so a white mirror in a white furnace shows white.
TEST(PathTracer, NormalMappedMirrorHasNoBlackPixels) {
    const uint32_t W = 32, H = 32;
    Material m;
    m.baseColorFactor = glm::vec4(1.f);
    m.metallicFactor = 1.f;
    m.roughnessFactor = 0.f;
    m.normalTexture.image = 0;
    auto scene = sceneOf({quad(glm::vec3(-1.f, 0.f, -1.f), glm::vec3(0.f, 0.f, 2.f), glm::vec3(2.f, 0.f, 0.f))}, {m});
    SceneImage normalMap;
    normalMap.width = normalMap.height = 1;
    const float tilt = 50.f * 3.14159265f / 180.f;  // tangent-space normal (sin, 0, cos), encoded as n / 2 + 1 / 2
    normalMap.texels = {glm::u8vec4(uint8_t(std::lround((std::sin(tilt) * 0.5f + 0.5f) * 255.f)), 128,
                                    uint8_t(std::lround((std::cos(tilt) * 0.5f + 0.5f) * 255.f)), 255)};
    scene->images.push_back(normalMap);
    scene->environment.color = glm::vec3(1.f);
    scene->finalize();
    lookAt(*scene, glm::vec3(0.f, 3.f, 0.f), glm::vec3(0.f), 0.4f);  // the quad fills the frame
    auto g = ptGraph({{"maxBounces", 4}, {"samplesPerPixel", 4}}, W, H, scene);
    frame(*g, *scene, 0, W, H);
    auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
    double sum = 0.0;
    float lowest = 1e9f;
    for (uint32_t y = 0; y < H; ++y)
        for (uint32_t x = 0; x < W; ++x) {
            lowest = std::fmin(lowest, c.at(x, y).g);
            sum += c.at(x, y).g;
        }
    std::printf("normal-mapped mirror: darkest pixel %.4f, mean %.4f\n", lowest, sum / (W * H));
    // Without bending every path would end at the mirror (all black). With it, a path is lost only where GGX's long
    // tail (alpha 1e-3) tilts a sampled microfacet by more than the 1.1 degrees the lift leaves, about 0.25 % of
    // samples: no pixel loses more than one of its four.
    EXPECT_GE(lowest, 0.74f);
    EXPECT_GT(sum / (W * H), 0.99);
}

// The firefly guard changes no path, only what indirect contributions add: with the same random numbers every
// pixel's direct part is bit-identical, and its indirect part is channel by channel at most the unclamped one, and
// at most the number of indirect contributions of a path times the limit.
TEST(PathTracer, IndirectClampBoundsOnlyIndirectLight) {
    const uint32_t W = 48, H = 48;
    const float limit = 0.25f;
    const int bounces = 4;
    auto render = [&](float clamp) {
        auto scene = Scene::load(scenePath("materials.gltf"));
        auto g = ptGraph({{"maxBounces", bounces}, {"indirectClamp", clamp}}, W, H, scene, true);
        frame(*g, *scene, 2, W, H);
        std::vector<glm::vec4> out;
        for (const char* f : {"PT.direct", "PT.indirect"}) {
            auto v = g->fieldTexture(f)->view<glm::vec4>();
            for (uint32_t y = 0; y < H; ++y)
                for (uint32_t x = 0; x < W; ++x) out.push_back(v.at(x, y));
        }
        return out;
    };
    const auto off = render(0.f), on = render(limit);
    const size_t n = size_t(W) * H;
    size_t clamped = 0;
    for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(on[i], off[i]) << "direct light changed at " << i;
        for (int k = 0; k < 3; ++k) {
            ASSERT_LE(on[n + i][k], off[n + i][k] + 1e-6f * off[n + i][k]) << i;
            ASSERT_LE(on[n + i][k], 2.f * bounces * limit * 1.0001f) << i;
        }
        clamped += on[n + i] != off[n + i] ? 1 : 0;
    }
    EXPECT_GT(clamped, 0u);  // the limit is low enough to act on this scene
}

// A small light seen in a near-mirror (roughness 0.05) at a path's last vertex (maxBounces 1). Light sampling alone
// meets the lobe's peak (D ~ 5e4) with the small light's pdf: single samples of hundreds of times the light's
// radiance (fireflies that 3000 spp do not average out). isLastVertex() keeps the BRDF sample at glossy vertices,
// so both samples are MIS-weighted: a sample then carries about the light's radiance times the mirror's reflectance
// at most (the BRDF sample's weight is about 1, the light sample's MIS-weighted value at most half of it; the test
// allows twice the radiance). Light sampling alone gave 1383 here (138 times the light).
TEST(PathTracer, GlossyReflectionOfASmallLightHasNoFireflies) {
    const uint32_t W = 48, H = 48;
    const float Le = 10.f;
    Material mirror;
    mirror.baseColorFactor = glm::vec4(1.f);
    mirror.metallicFactor = 1.f;
    mirror.roughnessFactor = 0.05f;
    auto scene = sceneOf({quad(glm::vec3(-2.f, 0.f, -2.f), glm::vec3(0.f, 0.f, 4.f), glm::vec3(4.f, 0.f, 0.f)),
                          quad(glm::vec3(-0.15f, 2.f, -0.15f), glm::vec3(0.3f, 0.f, 0.f), glm::vec3(0.f, 0.f, 0.3f))},
                         {mirror, lambert(glm::vec3(0.5f), glm::vec3(Le))});
    scene->finalize();
    lookAt(*scene, glm::vec3(0.f, 2.f, 3.f), glm::vec3(0.f, 0.f, 1.2f), 0.9f);
    auto g = ptGraph({{"maxBounces", 1}}, W, H, scene);
    float largest = 0.f;
    double sum = 0.0;
    for (uint64_t f = 0; f < 16; ++f) {
        frame(*g, *scene, f, W, H);
        auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                largest = std::fmax(largest, c.at(x, y).g);
                sum += c.at(x, y).g;
            }
    }
    std::printf("glossy reflection of a small light: largest sample %.2f (light %.1f), mean %.5f\n", largest, Le,
                sum / (16.0 * W * H));
    EXPECT_GT(largest, 0.5f * Le);  // the reflection is in view
    EXPECT_LE(largest, 2.f * Le);   // and no sample exceeds what MIS allows
}

// An alpha-tested emitter lights the scene as rays that hit it see it: a MASK emitter cut out everywhere (alpha
// 0.25 below the cutoff 0.5) lights nothing, also through light sampling; a BLEND emitter of alpha 0.5 gives, by
// light sampling, exactly half the light of the opaque one (its mean over the stochastic transparency), and BRDF
// sampling, which meets it through the any-hit filter, converges to the same.
TEST(PathTracer, AlphaTestedEmittersLightAsTheyAreSeen) {
    const uint32_t W = 32, H = 32;
    auto render = [&](AlphaMode mode, float alpha, const char* sampling, int spp) {
        Material emitter = lambert(glm::vec3(0.5f), glm::vec3(5.f));
        emitter.baseColorFactor.a = alpha;
        emitter.alphaMode = mode;
        auto scene = sceneOf({quad(glm::vec3(-2.f, 0.f, -2.f), glm::vec3(0.f, 0.f, 4.f), glm::vec3(4.f, 0.f, 0.f)),
                              quad(glm::vec3(-0.5f, 1.5f, -0.5f), glm::vec3(1.f, 0.f, 0.f), glm::vec3(0.f, 0.f, 1.f))},
                             {lambert(glm::vec3(0.8f)), emitter});
        scene->finalize();
        lookAt(*scene, glm::vec3(0.f, 1.2f, 0.f), glm::vec3(0.f, 0.f, 0.001f), 0.9f);  // under the emitter
        auto g = ptGraph({{"maxBounces", 1}, {"lightSampling", sampling}, {"samplesPerPixel", spp}}, W, H, scene);
        frame(*g, *scene, 0, W, H);
        std::vector<glm::vec3> out;
        auto c = g->fieldTexture("PT.color")->view<glm::vec4>();
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) out.push_back(glm::vec3(c.at(x, y)));
        return out;
    };
    auto mean = [](const std::vector<glm::vec3>& img) {
        double s = 0.0;
        for (const auto& v : img) s += v.g;
        return s / double(img.size());
    };
    const auto opaque = render(AlphaMode::Opaque, 1.f, "nee", 4);
    ASSERT_GT(mean(opaque), 0.05);
    for (const char* sampling : {"nee", "bsdf", "mis"})
        EXPECT_EQ(mean(render(AlphaMode::Mask, 0.25f, sampling, 4)), 0.0) << sampling;
    const auto blend = render(AlphaMode::Blend, 0.5f, "nee", 4);
    for (size_t i = 0; i < blend.size(); ++i) ASSERT_EQ(blend[i], 0.5f * opaque[i]) << i;
    const double bsdf = mean(render(AlphaMode::Blend, 0.5f, "bsdf", 256));
    std::printf("BLEND emitter, alpha 0.5: light sampling %.5f, BRDF sampling %.5f (opaque %.5f)\n", mean(blend), bsdf,
                mean(opaque));
    EXPECT_NEAR(bsdf, mean(blend), 0.03 * mean(blend));
}

// Temporal gradients (A-SVGF): last frame's sample of each 3x3 block, re-shaded this frame at the same surface
// point with the same random numbers, gives the very same luminance when only the camera moved (an orbit with
// jitter: last frame's rays, pose and jitter, are replayed exactly), for any thread count.
TEST(PathTracer, TemporalGradientsAreExactlyZeroWhereOnlyTheCameraMoved) {
    const uint32_t W = 40, H = 32;
    auto render = [&](unsigned threads) {
        ThreadLimit limit(threads);
        auto scene = Scene::load(scenePath("cornell_box.gltf"));
        scene->camera.jitterPattern = JitterPattern::Halton;
        scene->cameraPath.kind = CameraPathKind::Orbit;
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "pt"},
                            {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", {{"samplesPerPixel", 2}}}}}},
                            {"outputs", {"PT.color", "PT.gradient"}}};
        auto graph = test::compiledGraph(g, scene, W, H);
        std::vector<glm::vec2> last;
        size_t sampled = 0;
        for (uint64_t f = 0; f < 4; ++f) {
            const double time = double(f) / 30.0;
            graph->execute(cli::sceneFrameAt(scene.get(), f, time, W, H, false));
            const auto gradient = graph->fieldTexture("PT.gradient")->view<glm::vec2>();
            last.clear();
            for (uint32_t y = 0; y < H; ++y)
                for (uint32_t x = 0; x < W; ++x) {
                    const glm::vec2 v = gradient.at(x, y);
                    last.push_back(v);
                    if (f == 0) {
                        EXPECT_EQ(v, glm::vec2(0.f)) << "no history on the first frame";
                        continue;
                    }
                    EXPECT_EQ(floatBits(v.x), floatBits(v.y)) << "frame " << f << " pixel " << x << ", " << y;
                    sampled += v.y > 0.f ? 1 : 0;
                }
        }
        EXPECT_GT(sampled, size_t(3 * W * H) / 2) << "most blocks hold a lit sample";
        return last;
    };
    const auto one = render(1), two = render(2);
    ASSERT_EQ(one.size(), two.size());
    for (size_t i = 0; i < one.size(); ++i) EXPECT_EQ(one[i], two[i]);
}

// gradientFromCurrentView re-shades last frame's sample from this frame's camera position (A-SVGF's choice): under an
// orbit a view-independent BRDF (lambertOnly) still gives equal pairs, while the glTF BRDF's view-dependent
// reflections on materials.gltf make blocks differ; along last frame's rays (the default) they are all equal.
TEST(PathTracer, GradientsFromTheCurrentViewSeeViewDependentShading) {
    const uint32_t W = 48, H = 32;
    // The largest relative difference of a pair over frames 1..3, and how many lit blocks were compared.
    auto worstPair = [&](const std::string& sceneName, bool lambert, bool fromCurrent, size_t& lit) {
        auto scene = Scene::load(scenePath(sceneName));
        scene->cameraPath.kind = CameraPathKind::Orbit;
        nlohmann::json params = {{"samplesPerPixel", 1}, {"lambertOnly", lambert},
                                 {"gradientFromCurrentView", fromCurrent}};
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "pt"},
                            {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", params}}}},
                            {"outputs", {"PT.color", "PT.gradient"}}};
        auto graph = test::compiledGraph(g, scene, W, H);
        double worst = 0.0;
        lit = 0;
        for (uint64_t f = 0; f < 4; ++f) {
            const double time = double(f) / 30.0;  // a small turn: every wall still faces the camera
            graph->execute(cli::sceneFrameAt(scene.get(), f, time, W, H, false));
            if (f == 0) continue;
            const auto gradient = graph->fieldTexture("PT.gradient")->view<glm::vec2>();
            for (uint32_t y = 0; y < H; y += 3)
                for (uint32_t x = 0; x < W; x += 3) {
                    const glm::vec2 v = gradient.at(x, y);
                    if (!(v.y > 1e-3f)) continue;
                    ++lit;
                    worst = std::max(worst, double(std::fabs(v.x - v.y)) / double(v.y));
                }
        }
        return worst;
    };
    size_t lit = 0;
    EXPECT_LT(worstPair("cornell_box.gltf", true, true, lit), 1e-4) << "a Lambertian surface looks the same from anywhere";
    EXPECT_GT(lit, size_t(W * H / 9));
    EXPECT_GT(worstPair("materials.gltf", false, true, lit), 0.05) << "glossy reflections move with the view";
    EXPECT_GT(lit, size_t(W * H / 9));
    EXPECT_EQ(worstPair("materials.gltf", false, false, lit), 0.0) << "last frame's rays replayed exactly";
}

// Where the lighting changes, the gradient says by how much: cornell_lightstep dims its only light to a quarter at
// frame 21 (60 fps); the samples re-shaded then are a quarter of what they were (light is linear in emission, and
// with one light its selection is unchanged), while the frames around the step have equal pairs.
TEST(PathTracer, TemporalGradientsMeasureALightingStep) {
    const uint32_t W = 30, H = 30;
    auto scene = Scene::load(scenePath("cornell_lightstep.gltf"));
    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "pt"},
                        {"passes", {{{"name", "PT"}, {"type", "PathTracer"}}}},
                        {"outputs", {"PT.color", "PT.gradient"}}};
    auto graph = test::compiledGraph(g, scene, W, H);
    for (uint64_t f = 19; f <= 22; ++f) {
        const double time = double(f) / 60.0;
        graph->execute(cli::sceneFrameAt(scene.get(), f, time, W, H, false));
        if (f == 19) continue;
        const auto gradient = graph->fieldTexture("PT.gradient")->view<glm::vec2>();
        size_t lit = 0;
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                const glm::vec2 v = gradient.at(x, y);
                const float expected = f == 21 ? 0.25f * v.y : v.y;
                EXPECT_NEAR(v.x, expected, 1e-5f * (1.f + v.y)) << "frame " << f << " pixel " << x << ", " << y;
                lit += v.y > 0.f ? 1 : 0;
            }
        EXPECT_GT(lit, size_t(W * H) / 2) << "frame " << f;
    }
}

// pixelFilter "box": each sample starts uniformly inside its pixel, so the image of an emitter's edge converges to
// the area of each pixel the emitter covers (found here by testing a 64 x 64 grid of points per pixel against the
// quad), where "center" sees 0 or 1. Box ignores the camera jitter and is identical for any thread count.
TEST(PathTracer, BoxPixelFilterConvergesToPixelCoverage) {
    const uint32_t W = 24, H = 20, spp = 1024;
    // A large emissive quad on the ground whose near edge crosses the view at a slant, seen from above.
    const glm::vec3 u = glm::vec3(1.f, 0.f, 0.37f) * 20.f, v = glm::vec3(0.37f, 0.f, -1.f) * 20.f;
    const glm::vec3 corner = glm::vec3(0.11f, 0.f, 0.07f) - 0.5f * u;
    auto makeScene = [&] {
        auto scene = sceneOf({quad(corner, u, v)}, {lambert(glm::vec3(0.f), glm::vec3(1.f))});
        scene->finalize();
        lookAt(*scene, glm::vec3(0.f, 3.f, 0.f), glm::vec3(0.f, 0.f, 0.f), 0.6f);
        return scene;
    };
    auto render = [&](const char* filter, unsigned threads, bool jitter) {
        ThreadLimit limit(threads);
        auto scene = makeScene();
        if (jitter) scene->camera.jitterPattern = JitterPattern::Halton;
        auto g = ptGraph({{"maxBounces", 0}, {"samplesPerPixel", spp}, {"pixelFilter", filter}}, W, H, scene);
        frame(*g, *scene, 3, W, H);
        const Texture* c = g->fieldTexture("PT.color");
        Texture copy(c->width(), c->height(), c->format());
        copy.copyFrom(*c);
        return copy;
    };
    // Coverage of each pixel by the quad: the fraction of a 64 x 64 grid of points whose ray hits it.
    auto scene = makeScene();
    scene->camera.aspect = float(W) / float(H);
    const CameraData cam = makeCameraData(scene->camera, W, H);
    auto inside = [&](glm::vec3 p) {
        const float a = glm::dot(p - corner, u) / glm::dot(u, u), b = glm::dot(p - corner, v) / glm::dot(v, v);
        return a >= 0.f && a <= 1.f && b >= 0.f && b <= 1.f;
    };
    auto coverage = [&](uint32_t x, uint32_t y) {
        const int n = 64;
        int hits = 0;
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const glm::vec3 d =
                    cameraRayDir(cam, float(x) + (float(i) + 0.5f) / n, float(y) + (float(j) + 0.5f) / n);
                hits += inside(cam.origin + d * (-cam.origin.y / d.y)) ? 1 : 0;
            }
        return double(hits) / double(n * n);
    };

    const Texture box = render("box", 2, false), center = render("center", 2, false);
    const auto b = box.view<glm::vec4>(), c = center.view<glm::vec4>();
    int edgePixels = 0;
    double sumError = 0.0, sumVariance = 0.0;
    for (uint32_t y = 0; y < H; ++y) {
        for (uint32_t x = 0; x < W; ++x) {
            const double cov = coverage(x, y);
            EXPECT_TRUE(c.at(x, y).r == 0.f || c.at(x, y).r == 1.f) << x << "," << y;
            if (cov == 0.0 || cov == 1.0) {
                EXPECT_NEAR(b.at(x, y).r, cov, 1e-6) << x << "," << y;  // every sample agrees
                continue;
            }
            // A Bernoulli mean of spp samples: within 5 standard deviations (and the grid's resolution).
            const double sd = std::sqrt(cov * (1.0 - cov) / spp);
            EXPECT_NEAR(b.at(x, y).r, cov, 5.0 * sd + 1.0 / 64.0) << x << "," << y;
            sumError += b.at(x, y).r - cov;
            sumVariance += cov * (1.0 - cov) / spp;
            ++edgePixels;
        }
    }
    ASSERT_GE(edgePixels, int(W));  // the edge crosses the whole view
    EXPECT_LT(std::abs(sumError), 5.0 * std::sqrt(sumVariance) + edgePixels / 4096.0);
    std::printf("box filter: %d edge pixels, mean error %.5f\n", edgePixels, sumError / edgePixels);
    // The camera jitter moves "center" samples, never "box" ones; the thread count changes nothing.
    EXPECT_TRUE(box.samePixels(render("box", 1, true)));
    EXPECT_FALSE(center.samePixels(render("center", 2, true)));
}
