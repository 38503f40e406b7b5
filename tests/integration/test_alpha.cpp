// glTF alphaMode and sidedness, honoured alike by every pass and every ray: camera rays (PathTracer, GBufferRT,
// GBufferRaster), bounce rays and shadow rays. Each case is a tiny glTF written to a temporary folder: a test quad
// between the camera and an emitter, or between an emitter and a lit floor.
// - MASK below its cutoff (by factor or by texel) is not there: the image is bit-identical to the scene without
//   the quad, for camera, shadow (NEE only) and bounce (BRDF sampling only) rays; above the cutoff it blocks all.
// - BLEND of alpha 0.25 is there with probability 0.25: each sample sees either all or nothing of what lies
//   behind, and the fraction that passes is 0.75 within a bound derived from the samples themselves.
// - Single-sided quads seen from behind are culled for camera rays (PathTracer, GBufferRT, GBufferRaster);
//   double-sided ones are not.
// - Results are identical for 1 and 2 threads, and with primary hits from GBufferRT's vbuffer.
#include <gtest/gtest.h>
#include <stb/stb_image_write.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Bvh.h"
#include "loom/BvhTraversal.h"
#include "loom/Graph.h"
#include "loom/Parallel.h"
#include "loom/RayScene.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr uint32_t kW = 32, kH = 32;

/// The test quad's material.
struct QuadLook {
    std::string alphaMode = "OPAQUE";
    float alpha = 1.f;    // baseColorFactor alpha
    int texelAlpha = -1;  // 0..255: a 2x2 base colour texture of this alpha; -1: none
    float cutoff = 0.5f;
    bool doubleSided = false;
    bool facingAway = false;  // the node turns the quad half a turn about y (seeThroughScene: away from the camera)
};

/// Writes a glTF of quads (each its own mesh, material and root node, in order) and a camera into a folder.
class GltfWriter {
public:
    /// A quad corner, corner + u, corner + u + v, corner + v: its front (counter-clockwise) faces u x v.
    void quad(glm::vec3 corner, glm::vec3 u, glm::vec3 v, json material, json node = json::object()) {
        const glm::vec3 n = glm::normalize(glm::cross(u, v));
        std::vector<float> pos, nrm, uv;
        const glm::vec3 ps[4] = {corner, corner + u, corner + u + v, corner + v};
        const float uvs[8] = {0, 1, 1, 1, 1, 0, 0, 0};
        for (int i = 0; i < 4; ++i) {
            pos.insert(pos.end(), {ps[i].x, ps[i].y, ps[i].z});
            nrm.insert(nrm.end(), {n.x, n.y, n.z});
            uv.insert(uv.end(), {uvs[2 * i], uvs[2 * i + 1]});
        }
        const uint32_t idx[6] = {0, 1, 2, 0, 2, 3};
        json attributes = {{"POSITION", accessor(pos.data(), pos.size() * 4, 5126, 4, "VEC3", true)},
                           {"NORMAL", accessor(nrm.data(), nrm.size() * 4, 5126, 4, "VEC3")},
                           {"TEXCOORD_0", accessor(uv.data(), uv.size() * 4, 5126, 4, "VEC2")}};
        const int indices = accessor(idx, sizeof idx, 5125, 6, "SCALAR");
        mJ["materials"].push_back(std::move(material));
        const int m = int(mJ["materials"].size()) - 1;
        mJ["meshes"].push_back(
            {{"primitives", json::array({{{"attributes", attributes}, {"indices", indices}, {"material", m}}})}});
        node["mesh"] = int(mJ["meshes"].size()) - 1;
        mRoots.push_back(addNode(std::move(node)));
    }
    /// A 2x2 RGBA PNG of one colour (texture index returned).
    int image(glm::u8vec4 texel) {
        const glm::u8vec4 texels[4] = {texel, texel, texel, texel};
        std::vector<uint8_t> png;
        auto append = [](void* ctx, void* data, int size) {
            auto* out = static_cast<std::vector<uint8_t>*>(ctx);
            out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
        };
        EXPECT_NE(stbi_write_png_to_func(append, &png, 2, 2, 4, texels, 8), 0);
        mJ["images"].push_back({{"bufferView", view(png.data(), png.size())}, {"mimeType", "image/png"}});
        mJ["textures"].push_back({{"source", int(mJ["images"].size()) - 1}});
        return int(mJ["textures"].size()) - 1;
    }
    void camera(glm::vec3 position, glm::vec4 rotationXyzw, float yfov) {
        mJ["cameras"] = json::array({{{"type", "perspective"}, {"perspective", {{"yfov", yfov}, {"znear", 0.01}}}}});
        mRoots.push_back(addNode({{"camera", 0},
                                  {"translation", {position.x, position.y, position.z}},
                                  {"rotation", {rotationXyzw.x, rotationXyzw.y, rotationXyzw.z, rotationXyzw.w}}}));
    }
    std::shared_ptr<Scene> load(const fs::path& dir) const {
        fs::create_directories(dir);
        std::ofstream(dir / "scene.bin", std::ios::binary)
            .write(reinterpret_cast<const char*>(mBin.data()), std::streamsize(mBin.size()));
        json d = mJ;
        d["buffers"] = json::array({{{"byteLength", mBin.size()}, {"uri", "scene.bin"}}});
        d["scenes"] = json::array({{{"nodes", mRoots}}});
        d["scene"] = 0;
        std::ofstream(dir / "scene.gltf") << d.dump(1);
        return Scene::load(dir / "scene.gltf");
    }

private:
    int view(const void* data, size_t bytes) {
        while (mBin.size() % 4) mBin.push_back(0);
        const size_t offset = mBin.size();
        mBin.insert(mBin.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + bytes);
        mJ["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}});
        return int(mJ["bufferViews"].size()) - 1;
    }
    int accessor(const void* data, size_t bytes, int componentType, size_t count, const char* type,
                 bool withBounds = false) {
        json a = {
            {"bufferView", view(data, bytes)}, {"componentType", componentType}, {"count", count}, {"type", type}};
        if (withBounds) {  // glTF requires min and max on POSITION
            const auto* f = static_cast<const float*>(data);
            glm::vec3 lo(1e30f), hi(-1e30f);
            for (size_t i = 0; i < count; ++i) {
                lo = glm::min(lo, glm::vec3(f[3 * i], f[3 * i + 1], f[3 * i + 2]));
                hi = glm::max(hi, glm::vec3(f[3 * i], f[3 * i + 1], f[3 * i + 2]));
            }
            a["min"] = {lo.x, lo.y, lo.z};
            a["max"] = {hi.x, hi.y, hi.z};
        }
        mJ["accessors"].push_back(a);
        return int(mJ["accessors"].size()) - 1;
    }
    int addNode(json n) {
        mJ["nodes"].push_back(std::move(n));
        return int(mJ["nodes"].size()) - 1;
    }
    json mJ = {{"asset", {{"version", "2.0"}}}};
    std::vector<uint8_t> mBin;
    std::vector<int> mRoots;
};

json lambertMaterial(glm::vec4 base, glm::vec3 emission = glm::vec3(0.f)) {
    return {
        {"pbrMetallicRoughness",
         {{"baseColorFactor", {base.r, base.g, base.b, base.a}}, {"metallicFactor", 0.0}, {"roughnessFactor", 1.0}}},
        {"emissiveFactor", {emission.r, emission.g, emission.b}}};
}

/// The test quad's node and black material (it reflects and emits nothing at the bounce counts used).
void addTestQuad(GltfWriter& g, const QuadLook& look, glm::vec3 corner, glm::vec3 u, glm::vec3 v) {
    json m = lambertMaterial(glm::vec4(0.f, 0.f, 0.f, look.alpha));
    m["alphaMode"] = look.alphaMode;
    m["alphaCutoff"] = look.cutoff;
    m["doubleSided"] = look.doubleSided;
    if (look.texelAlpha >= 0)
        m["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", g.image(glm::u8vec4(0, 0, 0, look.texelAlpha))}};
    json node = json::object();
    if (look.facingAway) node["rotation"] = {0.0, 1.0, 0.0, 0.0};  // half a turn about y
    g.quad(corner, u, v, std::move(m), std::move(node));
}

/// A temporary folder per test and scene.
fs::path tempDir(const std::string& name) {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    return fs::temp_directory_path() /
           ("loom_test_alpha_" + std::to_string(::getpid()) + "_" + test->name() + "_" + name);
}

struct TempDirs {
    std::vector<fs::path> dirs;
    ~TempDirs() {
        std::error_code ec;
        for (const auto& d : dirs) fs::remove_all(d, ec);
    }
    fs::path make(const std::string& name) {
        dirs.push_back(tempDir(name));
        fs::remove_all(dirs.back());
        return dirs.back();
    }
};

/// Camera at z = 3 looking down -z at the test quad (z = 0, 4 x 4.3) in front of an emitter of radiance 1 (z = -1,
/// 8 x 8, facing the camera); without `look` there is no test quad.
std::shared_ptr<Scene> seeThroughScene(TempDirs& dirs, const std::string& name, const QuadLook* look) {
    GltfWriter g;
    g.quad(glm::vec3(-4.f, -4.f, -1.f), glm::vec3(8.f, 0.f, 0.f), glm::vec3(0.f, 8.f, 0.f),
           lambertMaterial(glm::vec4(0.f, 0.f, 0.f, 1.f), glm::vec3(1.f)));
    // Not square, so no pixel centre lies on the diagonal two triangles share: there the rasterizer and Embree may
    // pick different triangles, whose stochastic-transparency decisions differ (by design: the layers of a closed
    // BLEND mesh are independent).
    if (look) addTestQuad(g, *look, glm::vec3(-2.f, -2.1f, 0.f), glm::vec3(4.f, 0.f, 0.f), glm::vec3(0.f, 4.3f, 0.f));
    g.camera(glm::vec3(0.f, 0.f, 3.f), glm::vec4(0.f, 0.f, 0.f, 1.f), 0.6f);
    return g.load(dirs.make(name));
}

/// An emitter of radiance 1 (y = 2, 2 x 2, facing down) over a white floor (y = 0, facing up), the test quad
/// (y = 1, 8 x 8, its front facing up: the floor sees its back face) between them, and the camera at y = 0.5 looking
/// down at the floor (it sees neither the quad nor the emitter: every light it sees crossed the quad's plane). Without
/// `look` there is no quad.
std::shared_ptr<Scene> shadowScene(TempDirs& dirs, const std::string& name, const QuadLook* look) {
    GltfWriter g;
    g.quad(glm::vec3(-1.f, 2.f, -1.f), glm::vec3(2.f, 0.f, 0.f), glm::vec3(0.f, 0.f, 2.f),
           lambertMaterial(glm::vec4(0.f, 0.f, 0.f, 1.f), glm::vec3(1.f)));
    g.quad(glm::vec3(-3.f, 0.f, 3.f), glm::vec3(6.f, 0.f, 0.f), glm::vec3(0.f, 0.f, -6.f),
           lambertMaterial(glm::vec4(0.8f, 0.8f, 0.8f, 1.f)));
    if (look) addTestQuad(g, *look, glm::vec3(-4.f, 1.f, 4.f), glm::vec3(8.f, 0.f, 0.f), glm::vec3(0.f, 0.f, -8.f));
    // Rotated -90 degrees about x: the camera's -z looks down -y.
    g.camera(glm::vec3(0.f, 0.5f, 0.f), glm::vec4(-0.70710678f, 0.f, 0.f, 0.70710678f), 1.0f);
    return g.load(dirs.make(name));
}

/// One frame of a graph; returns a copy of `field`.
Texture renderField(RenderGraph& graph, Scene& scene, uint64_t frameIndex, const std::string& field) {
    scene.update(0.0);
    scene.camera.aspect = float(kW) / float(kH);
    scene.camera.beginFrame(frameIndex);
    graph.execute(FrameInfo{frameIndex, 0.0, &scene, &scene.camera});
    const Texture* t = graph.fieldTexture(field);
    EXPECT_NE(t, nullptr) << field;
    Texture copy(t->width(), t->height(), t->format());
    copy.copyFrom(*t);
    return copy;
}

/// A graph of the passes given (name, type, params) marking `outputs`, compiled at kW x kH for `scene`.
std::unique_ptr<RenderGraph> makeGraph(const json& passes, const std::vector<std::string>& outputs,
                                       const std::shared_ptr<Scene>& scene) {
    return test::compiledGraph({{"loom_graph", 1}, {"name", "alpha"}, {"passes", passes}, {"outputs", outputs}}, scene,
                               kW, kH);
}

/// PathTracer's colour for one frame; with `viaVBuffer` its primary hits come from GBufferRT's vbuffer.
Texture pathTrace(const std::shared_ptr<Scene>& scene, const json& params, uint64_t frameIndex,
                  bool viaVBuffer = false) {
    json passes = {{{"name", "PT"}, {"type", "PathTracer"}, {"params", params}}};
    if (viaVBuffer) passes.push_back({{"name", "GBuffer"}, {"type", "GBufferRT"}});
    auto graph = makeGraph(passes, {"PT.color"}, scene);
    EXPECT_EQ(graph->plan().order.size(), viaVBuffer ? 2u : 1u);  // vbuffer wired by name
    return renderField(*graph, *scene, frameIndex, "PT.color");
}

/// A G-buffer pass's vbuffer for one frame.
Texture vbufferOf(const std::string& type, const std::shared_ptr<Scene>& scene, uint64_t frameIndex) {
    auto graph = makeGraph({{{"name", "GBuffer"}, {"type", type}}}, {"GBuffer.vbuffer"}, scene);
    return renderField(*graph, *scene, frameIndex, "GBuffer.vbuffer");
}

/// Whether every pixel's red channel equals `value`.
bool allRed(const Texture& t, float value) {
    auto v = t.view<glm::vec4>();
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            if (v.at(x, y).r != value) return false;
    return true;
}

/// Whether every pixel's vbuffer names `instance`.
bool allInstance(const Texture& vb, uint32_t instance) {
    auto v = vb.view<glm::uvec4>();
    for (uint32_t y = 0; y < vb.height(); ++y)
        for (uint32_t x = 0; x < vb.width(); ++x)
            if (v.at(x, y).x != instance) return false;
    return true;
}

double sumRed(const Texture& t) {
    double s = 0.0;
    auto v = t.view<glm::vec4>();
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x) s += v.at(x, y).r;
    return s;
}

const json kCameraOnly = {{"maxBounces", 0}};
const json kShadowRaysOnly = {{"maxBounces", 1}, {"lightSampling", "nee"}, {"lambertOnly", true}};
const json kBounceRaysOnly = {{"maxBounces", 1}, {"lightSampling", "bsdf"}, {"lambertOnly", true}};
const json kFullPaths = {{"maxBounces", 3}, {"samplesPerPixel", 2}};

/// BLEND of alpha 0.25, double-sided.
QuadLook blendLook() {
    QuadLook look;
    look.alphaMode = "BLEND";
    look.alpha = 0.25f;
    look.doubleSided = true;
    return look;
}

/// The MASK cases: by factor and by texel, below and above the cutoff 0.5.
std::vector<std::pair<std::string, QuadLook>> maskLooks(bool below) {
    QuadLook factor, texel;
    factor.alphaMode = texel.alphaMode = "MASK";
    factor.alpha = below ? 0.3f : 0.7f;
    texel.texelAlpha = below ? 77 : 179;  // 0.30, 0.70
    return {{"factor", factor}, {"texel", texel}};
}

}  // namespace

// Only MASK and BLEND geometry carries an Embree filter: a scene without it traces at full speed.
TEST(AlphaMode, OnlyAlphaTestedGeometryIsFiltered) {
    TempDirs dirs;
    EXPECT_FALSE(Scene::load(test::dataScene("cornell_box.gltf"))->rayScene().hasAlphaTestedGeometry());
    const QuadLook opaque;
    EXPECT_FALSE(seeThroughScene(dirs, "opaque", &opaque)->rayScene().hasAlphaTestedGeometry());
    for (const auto& [name, look] : maskLooks(true))
        EXPECT_TRUE(seeThroughScene(dirs, name, &look)->rayScene().hasAlphaTestedGeometry()) << name;
    const QuadLook blend = blendLook();
    EXPECT_TRUE(seeThroughScene(dirs, "blend", &blend)->rayScene().hasAlphaTestedGeometry());
}

// The BVH the CUDA device traverses (BvhTraversal.h) gives Embree's answers on alpha-tested and single-sided
// geometry: closest hits with and without the alpha test and back-face culling, and any hits, for rays from both
// sides of the test quad. The rules change some answers in each case, so the comparison means something.
TEST(AlphaMode, BvhAgreesWithEmbreeUnderEveryRule) {
    TempDirs dirs;
    std::vector<std::pair<std::string, QuadLook>> looks = maskLooks(true);
    for (auto& [name, look] : maskLooks(false)) looks.emplace_back(name + "_above", look);
    looks.emplace_back("blend", blendLook());
    QuadLook away;
    away.facingAway = true;
    looks.emplace_back("single_sided", away);
    for (const auto& [name, look] : looks) {
        auto scene = seeThroughScene(dirs, name, &look);
        const Bvh bvh(*scene);
        const BvhView view = bvh.view(scene->view());
        const RayScene& rays = scene->rayScene();
        const uint32_t rules[3] = {0u, kRayAlphaTest, kRayAlphaTest | kRayCullBackFaces};
        uint32_t hits[3] = {0, 0, 0}, disagree = 0;
        const uint32_t count = 20000;
        for (uint32_t i = 0; i < count; ++i) {
            auto r = [&](uint32_t k) { return test::hash01(7, i, k); };
            // Origins on both sides of the quad (z = 0), aimed through it at the emitter's plane (z = -1) or beyond.
            const glm::vec3 o(6.f * r(0) - 3.f, 6.f * r(1) - 3.f, -0.9f + 4.f * r(2));
            const glm::vec3 target(9.f * r(3) - 4.5f, 9.f * r(4) - 4.5f, -1.5f + 2.f * r(5));
            const glm::vec3 d = target - o;
            for (int k = 0; k < 3; ++k) {
                const RayHit e = rays.intersect(o, d, 0.f, 1e30f, rules[k]);
                const RayHit h = bvhIntersect(view, o, d, 0.f, 1e30f, rules[k]);
                hits[k] += e.hit() ? 1 : 0;
                const bool same =
                    e.hit() == h.hit() && (!e.hit() || (e.instance == h.instance && e.primitive == h.primitive &&
                                                        std::abs(e.t - h.t) <= 1e-5f * e.t));
                disagree += same ? 0 : 1;
            }
            disagree += rays.occluded(o, d, 0.f, 1.f) == bvhOccluded(view, o, d, 0.f, 1.f) ? 0 : 1;
        }
        EXPECT_LE(disagree, 4u * count / 10000) << name << ": 4 queries a ray, at least 99.99 % agreeing";
        const float alpha = look.alpha * (look.texelAlpha >= 0 ? float(look.texelAlpha) / 255.f : 1.f);
        const bool masked = look.alphaMode == "MASK" && alpha < look.cutoff;
        if (look.alphaMode == "BLEND" || masked)
            EXPECT_LT(hits[1], hits[0]) << name << ": the alpha test lets rays through";
        // (The emitter's back faces no ray here sees: culling shows on the test quad, where the alpha test keeps it.)
        if (!look.doubleSided && !masked) EXPECT_LT(hits[2], hits[1]) << name << ": culling lets rays past back faces";
    }
}

// Below the cutoff the quad is not there for any ray: every image is bit-identical to the scene without it (the
// same hits on the other surfaces, and the same random numbers).
TEST(AlphaMode, MaskBelowCutoffIsSeenThroughByEveryRay) {
    TempDirs dirs;
    auto openSee = seeThroughScene(dirs, "open_see", nullptr);
    auto openShadow = shadowScene(dirs, "open_shadow", nullptr);
    const Texture seeRef = pathTrace(openSee, kCameraOnly, 0);
    ASSERT_TRUE(allRed(seeRef, 1.f));  // the emitter, seen directly
    const Texture shadowRef = pathTrace(openShadow, kShadowRaysOnly, 0);
    const Texture bounceRef = pathTrace(openShadow, kBounceRaysOnly, 0);
    const Texture fullRef = pathTrace(openShadow, kFullPaths, 0);
    ASSERT_GT(sumRed(shadowRef), 0.0);
    ASSERT_GT(sumRed(bounceRef), 0.0);
    for (const auto& [name, look] : maskLooks(true)) {
        SCOPED_TRACE(name);
        auto see = seeThroughScene(dirs, "see_" + name, &look);
        auto shadow = shadowScene(dirs, "shadow_" + name, &look);
        EXPECT_TRUE(pathTrace(see, kCameraOnly, 0).samePixels(seeRef)) << "camera rays";
        EXPECT_TRUE(pathTrace(shadow, kShadowRaysOnly, 0).samePixels(shadowRef)) << "shadow rays";
        EXPECT_TRUE(pathTrace(shadow, kBounceRaysOnly, 0).samePixels(bounceRef)) << "bounce rays";
        EXPECT_TRUE(pathTrace(shadow, kFullPaths, 0).samePixels(fullRef)) << "whole paths";
        // Both G-buffers see the emitter (instance 0) through it.
        EXPECT_TRUE(allInstance(vbufferOf("GBufferRT", see, 0), 0u));
        EXPECT_TRUE(allInstance(vbufferOf("GBufferRaster", see, 0), 0u));
    }
}

// Above the cutoff the quad is opaque: the black quad hides the emitter from the camera, and the floor under it
// gets no light by shadow rays nor by bounce rays.
TEST(AlphaMode, MaskAboveCutoffIsOpaqueForEveryRay) {
    TempDirs dirs;
    for (const auto& [name, look] : maskLooks(false)) {
        SCOPED_TRACE(name);
        auto see = seeThroughScene(dirs, "see_" + name, &look);
        auto shadow = shadowScene(dirs, "shadow_" + name, &look);
        EXPECT_TRUE(allRed(pathTrace(see, kCameraOnly, 0), 0.f)) << "camera rays";
        EXPECT_TRUE(allRed(pathTrace(shadow, kShadowRaysOnly, 0), 0.f)) << "shadow rays";
        EXPECT_TRUE(allRed(pathTrace(shadow, kBounceRaysOnly, 0), 0.f)) << "bounce rays";
        EXPECT_TRUE(allInstance(vbufferOf("GBufferRT", see, 0), 1u));
        EXPECT_TRUE(allInstance(vbufferOf("GBufferRaster", see, 0), 1u));
        // alphaTest off makes every material opaque, below the cutoff too.
        QuadLook below = maskLooks(true)[0].second;
        auto seeBelow = seeThroughScene(dirs, "see_below_" + name, &below);
        EXPECT_TRUE(allRed(pathTrace(seeBelow, {{"maxBounces", 0}, {"alphaTest", false}}, 0), 0.f));
    }
}

// BLEND of alpha 0.25 in front of an emitter of radiance 1: each pixel of each frame sees 0 or 1, and is 1 with
// probability 0.75 (independently, by the hash). Over n samples the fraction has standard deviation
// sqrt(0.75 * 0.25 / n); 5 of them bound it (a false failure once in 1.7 million runs; the hash is
// deterministic, so the outcome is fixed anyway). The same for shadow rays: each NEE sample of the floor carries
// its unblocked value c_i (the scene without the quad, same random numbers) or 0, so sum(blend) / sum(open) has
// mean 0.75 and standard deviation sqrt(0.75 * 0.25 * sum(c_i^2)) / sum(c_i).
TEST(AlphaMode, BlendTransmitsOneMinusAlphaOnAverage) {
    TempDirs dirs;
    const QuadLook look = blendLook();
    auto see = seeThroughScene(dirs, "see", &look);
    const uint32_t frames = 16;
    double passed = 0.0, n = 0.0;
    for (uint32_t f = 0; f < frames; ++f) {
        const Texture img = pathTrace(see, kCameraOnly, f);
        auto v = img.view<glm::vec4>();
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) {
                const float r = v.at(x, y).r;
                ASSERT_TRUE(r == 0.f || r == 1.f) << r;
                passed += r;
                n += 1.0;
            }
    }
    const double fraction = passed / n, sd = std::sqrt(0.75 * 0.25 / n);
    std::printf("BLEND camera rays: %.5f of the emitter passes (expected 0.75 +- %.5f)\n", fraction, sd);
    EXPECT_NEAR(fraction, 0.75, 5.0 * sd);

    auto open = shadowScene(dirs, "open", nullptr);
    auto shadow = shadowScene(dirs, "shadow", &look);
    double sumBlend = 0.0, sumOpen = 0.0, sumOpenSq = 0.0;
    for (uint32_t f = 0; f < frames; ++f) {
        const Texture b = pathTrace(shadow, kShadowRaysOnly, f), o = pathTrace(open, kShadowRaysOnly, f);
        auto bv = b.view<glm::vec4>();
        auto ov = o.view<glm::vec4>();
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) {
                const float c = ov.at(x, y).r, got = bv.at(x, y).r;
                ASSERT_TRUE(got == 0.f || got == c) << got << " vs " << c;  // all or nothing of the same sample
                sumBlend += got;
                sumOpen += c;
                sumOpenSq += double(c) * c;
            }
    }
    ASSERT_GT(sumOpen, 0.0);
    const double ratio = sumBlend / sumOpen, sdRatio = std::sqrt(0.75 * 0.25 * sumOpenSq) / sumOpen;
    std::printf("BLEND shadow rays: %.5f of the light passes (expected 0.75 +- %.5f)\n", ratio, sdRatio);
    EXPECT_NEAR(ratio, 0.75, 5.0 * sdRatio);
}

// Stochastic transparency is a hash of the ray, never of a thread: 1 and 2 threads give the same bits.
TEST(AlphaMode, BlendIsIdenticalForOneAndTwoThreads) {
    TempDirs dirs;
    const QuadLook look = blendLook();
    auto see = seeThroughScene(dirs, "see", &look);
    auto shadow = shadowScene(dirs, "shadow", &look);
    auto render = [&](unsigned threads) {
        ThreadLimit limit(threads);
        std::vector<Texture> images;
        images.push_back(pathTrace(see, kCameraOnly, 3));
        images.push_back(pathTrace(shadow, kFullPaths, 3));
        images.push_back(vbufferOf("GBufferRT", see, 3));
        return images;
    };
    const auto one = render(1), two = render(2);
    for (size_t i = 0; i < one.size(); ++i) EXPECT_TRUE(one[i].samePixels(two[i])) << "image " << i;
}

// A single-sided quad seen from behind is culled for camera rays by every pass (the emitter behind shows);
// double-sided, it is hit. The quad is turned by its node, so culling is decided in the instance's frame.
TEST(AlphaMode, SingleSidedBackFacesAreCulledForCameraRaysByEveryPass) {
    TempDirs dirs;
    for (bool doubleSided : {false, true}) {
        SCOPED_TRACE(doubleSided ? "double-sided" : "single-sided");
        QuadLook look;
        look.facingAway = true;
        look.doubleSided = doubleSided;
        auto see = seeThroughScene(dirs, doubleSided ? "double" : "single", &look);
        const uint32_t seen = doubleSided ? 1u : 0u;  // the quad, or the emitter behind it
        EXPECT_TRUE(allRed(pathTrace(see, kCameraOnly, 0), doubleSided ? 0.f : 1.f));
        EXPECT_TRUE(allInstance(vbufferOf("GBufferRT", see, 0), seen));
        EXPECT_TRUE(allInstance(vbufferOf("GBufferRaster", see, 0), seen));
    }
    // cullMode none: the back face is hit.
    QuadLook single;
    single.facingAway = true;
    auto see = seeThroughScene(dirs, "single_nocull", &single);
    EXPECT_TRUE(allRed(pathTrace(see, {{"maxBounces", 0}, {"cullMode", "none"}}, 0), 0.f));
}

// Bounce and shadow rays do not cull: a single-sided quad whose back faces the floor still blocks the light.
TEST(AlphaMode, BounceAndShadowRaysSeeBothFaces) {
    TempDirs dirs;
    const QuadLook look;  // opaque, single-sided
    auto shadow = shadowScene(dirs, "shadow", &look);
    EXPECT_TRUE(allRed(pathTrace(shadow, kShadowRaysOnly, 0), 0.f));
    EXPECT_TRUE(allRed(pathTrace(shadow, kBounceRaysOnly, 0), 0.f));
}

// GBufferRaster's stochastic transparency (GLSL) makes the same decisions as GBufferRT's (Embree filter) for the
// same pixel and frame: their vbuffers name the same instance everywhere.
TEST(AlphaMode, BlendDecisionsAgreeBetweenGBufferRasterAndGBufferRT) {
    TempDirs dirs;
    const QuadLook look = blendLook();
    auto see = seeThroughScene(dirs, "see", &look);
    for (uint64_t f : {0u, 1u, 7u}) {
        const Texture rt = vbufferOf("GBufferRT", see, f), raster = vbufferOf("GBufferRaster", see, f);
        auto a = rt.view<glm::uvec4>();
        auto b = raster.view<glm::uvec4>();
        uint32_t differ = 0, quad = 0;
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) {
                differ += a.at(x, y).x != b.at(x, y).x;
                quad += a.at(x, y).x == 1u;
            }
        EXPECT_EQ(differ, 0u) << "frame " << f;
        EXPECT_GT(quad, 0u);
        EXPECT_LT(quad, kW * kH);
    }
}

// The path tracer's own camera rays and GBufferRT's vbuffer give the same primary hits, so the same colour, on
// every scene here.
TEST(AlphaMode, PathTracerWithAndWithoutVBufferAgree) {
    TempDirs dirs;
    std::vector<std::pair<std::string, QuadLook>> looks = maskLooks(true);
    for (auto& l : maskLooks(false)) looks.push_back({l.first + "_above", l.second});
    QuadLook single, twoSided;
    single.facingAway = true;
    twoSided.facingAway = true;
    twoSided.doubleSided = true;
    looks.push_back({"blend", blendLook()});
    looks.push_back({"single", single});
    looks.push_back({"double", twoSided});
    for (const auto& [name, look] : looks) {
        SCOPED_TRACE(name);
        auto see = seeThroughScene(dirs, "see_" + name, &look);
        auto shadow = shadowScene(dirs, "shadow_" + name, &look);
        for (uint64_t f : {0u, 5u}) {
            EXPECT_TRUE(pathTrace(see, kFullPaths, f).samePixels(pathTrace(see, kFullPaths, f, true)));
            EXPECT_TRUE(pathTrace(shadow, kFullPaths, f).samePixels(pathTrace(shadow, kFullPaths, f, true)));
        }
    }
}
