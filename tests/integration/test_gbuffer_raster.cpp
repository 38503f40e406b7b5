// GBufferRaster (OpenGL 4.5 through headless EGL): channel values against
// analytic expectations and against SurfaceKernels.h on tiny scenes built in
// code, run through the real plugin and RenderGraph.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include "loom/CameraKernels.h"
#include "loom/Error.h"
#include "loom/Graph.h"
#include "loom/Kernel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"
#include "loom/SurfaceKernels.h"

using namespace loom;

namespace {

constexpr uint32_t kW = 64, kH = 48;
constexpr uint32_t kMissId = 0xFFFFFFFFu;

const char* const kAllChannels[] = {"posW",   "normW",      "faceNormalW", "linearZ", "pnFwidth", "mvec",
                                    "albedo", "specAlbedo", "emission",    "vbuffer", "meshId"};

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

/// A graph with one GBufferRaster pass whose listed channels are marked outputs.
std::unique_ptr<RenderGraph> makeGraph(const std::vector<std::string>& channels,
                                       const nlohmann::json& params = nlohmann::json::object(), uint32_t w = kW,
                                       uint32_t h = kH) {
    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "GBufferRasterTest"},
                        {"passes", {{{"name", "GBuffer"}, {"type", "GBufferRaster"}, {"params", params}}}},
                        {"edges", nlohmann::json::array()},
                        {"outputs", nlohmann::json::array()}};
    for (const auto& c : channels) g["outputs"].push_back("GBuffer." + c);
    auto graph = std::make_unique<RenderGraph>(parseGraph(g.dump()), registry());
    CompileOptions o;
    o.width = w;
    o.height = h;
    graph->compile(o);
    return graph;
}

std::vector<std::string> allChannels() { return {std::begin(kAllChannels), std::end(kAllChannels)}; }

/// A camera at the origin looking down -Z, static.
Camera makeCamera(uint32_t w = kW, uint32_t h = kH) {
    Camera c;
    c.world = glm::mat4(1.f);
    c.prevWorld = c.world;
    c.fovY = 0.8f;
    c.aspect = float(w) / float(h);
    return c;
}

/// Unnormalised camera ray through image position (px, py), as Camera.h defines it.
glm::vec3 rayDir(const Camera& c, float px, float py, uint32_t w = kW, uint32_t h = kH) {
    return cameraRayDir(makeCameraData(c, w, h), px, py);
}

/// Where the ray through (px, py) meets the plane z = -depth (camera at the origin looking down -Z).
glm::vec3 unprojectToDepth(const Camera& c, float px, float py, float depth) {
    const glm::vec3 d = rayDir(c, px, py);
    return d * (depth / -d.z);
}

/// View-space x of image column position px at a depth (camera at the origin).
float viewXAt(const Camera& c, float px, float depth) { return unprojectToDepth(c, px, 0.5f * kH, depth).x; }
float viewYAt(const Camera& c, float py, float depth) { return unprojectToDepth(c, 0.5f * kW, py, depth).y; }

Material plainMaterial() {
    Material m;
    m.baseColorFactor = glm::vec4(0.5f, 0.25f, 1.f, 1.f);
    m.metallicFactor = 0.f;
    m.roughnessFactor = 0.6f;
    m.emissiveFactor = glm::vec3(1.f, 2.f, 3.f);
    return m;
}

/// A rectangle [x0, x1] x [y0, y1] in the object's z = 0 plane, facing +Z
/// (counter-clockwise seen from +Z), as two triangles.
Mesh rectMesh(float x0, float y0, float x1, float y1, uint32_t material = 0) {
    Mesh m;
    m.name = "rect/0";
    m.positions = {{x0, y0, 0.f}, {x1, y0, 0.f}, {x1, y1, 0.f}, {x0, y1, 0.f}};
    m.normals.assign(4, glm::vec3(0.f, 0.f, 1.f));
    m.tangents.assign(4, glm::vec4(1.f, 0.f, 0.f, 1.f));
    m.uvs = {{0.f, 1.f}, {1.f, 1.f}, {1.f, 0.f}, {0.f, 0.f}};
    m.indices = {0, 1, 2, 0, 2, 3};
    m.material = material;
    for (const auto& p : m.positions) m.bounds.extend(p);
    return m;
}

/// A scene of one instance of `mesh` placed by one root node (finalize makes the instance).
std::shared_ptr<Scene> oneMeshScene(Mesh mesh, Material material, glm::vec3 translation,
                                    glm::quat rotation = glm::quat(1.f, 0.f, 0.f, 0.f)) {
    auto s = std::make_shared<Scene>();
    s->name = "test";
    s->meshes.push_back(std::move(mesh));
    s->materials.push_back(std::move(material));
    Node n;
    n.name = "node";
    n.translation = translation;
    n.rotation = rotation;
    n.meshes = {0};
    s->nodes.push_back(n);
    s->roots = {0};
    s->finalize();
    s->update(0.0);
    return s;
}

template <class T>
T texel(const Texture& t, uint32_t x, uint32_t y) {
    return t.view<T>().at(x, y);
}

const Texture& field(const RenderGraph& g, const std::string& channel) {
    const Texture* t = g.fieldTexture("GBuffer." + channel);
    if (!t) throw std::runtime_error("GBuffer." + channel + " was not allocated");
    return *t;
}

void expectMiss(const RenderGraph& g, uint32_t x, uint32_t y) {
    SCOPED_TRACE("miss pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
    for (const char* c : {"posW", "normW", "faceNormalW", "albedo", "specAlbedo", "emission"})
        EXPECT_EQ(texel<glm::vec4>(field(g, c), x, y), glm::vec4(0.f)) << c;
    EXPECT_EQ(texel<glm::vec2>(field(g, "linearZ"), x, y), glm::vec2(-1.f, 0.f));
    EXPECT_EQ(texel<glm::vec2>(field(g, "pnFwidth"), x, y), glm::vec2(0.f));
    EXPECT_EQ(texel<glm::uvec4>(field(g, "vbuffer"), x, y), glm::uvec4(kMissId));
    EXPECT_EQ(texel<uint32_t>(field(g, "meshId"), x, y), kMissId);
}

/// Builds the SceneView that SurfaceKernels.h evaluates, straight from the
/// scene's arrays (independent of Scene::view()).
struct HostView {
    std::vector<MeshView> meshes;
    std::vector<MaterialData> materials;
    std::vector<ImageView8> images;
    std::vector<InstanceView> instances;
    SceneView view;

    explicit HostView(const Scene& s) {
        for (const Mesh& m : s.meshes)
            meshes.push_back({m.positions.data(), m.normals.data(), m.tangents.data(), m.uvs.data(), m.indices.data(),
                              m.triangleCount(), m.material});
        for (const Material& m : s.materials) {
            MaterialData d;
            d.baseColorFactor = m.baseColorFactor;
            d.emissiveFactor = m.emissiveFactor;
            d.metallicFactor = m.metallicFactor;
            d.roughnessFactor = m.roughnessFactor;
            d.normalScale = m.normalScale;
            d.alphaCutoff = m.alphaCutoff;
            d.baseColorTexture = m.baseColorTexture;
            d.metallicRoughnessTexture = m.metallicRoughnessTexture;
            d.normalTexture = m.normalTexture;
            d.emissiveTexture = m.emissiveTexture;
            d.doubleSided = m.doubleSided;
            d.alphaMask = m.alphaMode == AlphaMode::Mask;
            materials.push_back(d);
        }
        for (const SceneImage& i : s.images) images.push_back({i.texels.data(), i.width, i.height});
        for (const Instance& i : s.instances) {
            InstanceView v;
            v.world = i.world;
            v.prevWorld = i.prevWorld;
            v.normalMatrix = glm::transpose(glm::inverse(glm::mat3(i.world)));
            v.mesh = i.mesh;
            instances.push_back(v);
        }
        view.meshes = meshes.data();
        view.materials = materials.data();
        view.images = images.data();
        view.instances = instances.data();
        view.meshCount = uint32_t(meshes.size());
        view.materialCount = uint32_t(materials.size());
        view.imageCount = uint32_t(images.size());
        view.instanceCount = uint32_t(instances.size());
    }
};

float relErr(float a, float b) { return std::fabs(a - b) / std::max(std::fabs(b), 1e-6f); }

}  // namespace

// A quad facing the camera at a known depth: every channel at every pixel.
TEST(GBufferRaster, QuadFacingCameraAllChannels) {
    const float depth = 3.7f;
    auto scene = oneMeshScene(rectMesh(-1.f, -0.75f, 1.f, 0.75f), plainMaterial(), glm::vec3(0.2f, 0.1f, -depth));
    Camera cam = makeCamera();
    auto graph = makeGraph(allChannels());
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});

    // Two geometry passes: 11 channels exceed llvmpipe's 8 draw buffers.
    const auto stats = graph->lastStats();
    ASSERT_TRUE(stats.count("GBuffer"));
    EXPECT_GE(stats.at("GBuffer").at("readbackMs"), 0.0);

    const Mesh& mesh = scene->meshes[0];
    const glm::vec3 offset(0.2f, 0.1f, -depth);
    const float step = 2.f * depth * std::tan(0.5f * cam.fovY) / float(kH);  // world size of a pixel at the quad
    int hits = 0, misses = 0;
    for (uint32_t y = 0; y < kH; ++y) {
        for (uint32_t x = 0; x < kW; ++x) {
            const glm::vec3 p = unprojectToDepth(cam, x + 0.5f, y + 0.5f, depth);
            const glm::vec3 local = p - offset;
            const float margin = 1e-3f;
            const bool inside = local.x > -1.f + margin && local.x < 1.f - margin && local.y > -0.75f + margin &&
                                local.y < 0.75f - margin;
            const bool outside = local.x < -1.f - margin || local.x > 1.f + margin || local.y < -0.75f - margin ||
                                 local.y > 0.75f + margin;
            if (outside) {
                expectMiss(*graph, x, y);
                // Static camera: the sky does not move.
                EXPECT_EQ(texel<glm::vec2>(field(*graph, "mvec"), x, y), glm::vec2(0.f));
                ++misses;
                continue;
            }
            if (!inside) continue;  // centre within a rounding error of an edge
            ++hits;
            SCOPED_TRACE("hit pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
            const glm::vec4 posW = texel<glm::vec4>(field(*graph, "posW"), x, y);
            ASSERT_EQ(posW.w, 1.f);
            EXPECT_NEAR(posW.x, p.x, 1e-4f * depth);
            EXPECT_NEAR(posW.y, p.y, 1e-4f * depth);
            EXPECT_NEAR(posW.z, p.z, 1e-4f * depth);
            const glm::vec2 lz = texel<glm::vec2>(field(*graph, "linearZ"), x, y);
            EXPECT_LT(relErr(lz.x, depth), 1e-4f);
            EXPECT_NEAR(lz.y, 0.f, 1e-4f);  // a plane facing the camera has constant depth
            EXPECT_EQ(texel<glm::vec4>(field(*graph, "normW"), x, y), glm::vec4(0.f, 0.f, 1.f, 0.f));
            EXPECT_EQ(texel<glm::vec4>(field(*graph, "faceNormalW"), x, y), glm::vec4(0.f, 0.f, 1.f, 0.f));
            // fwidth of posW: one pixel step in x and in y.
            const glm::vec2 pn = texel<glm::vec2>(field(*graph, "pnFwidth"), x, y);
            EXPECT_NEAR(pn.x, step * std::sqrt(2.f), 1e-3f * step);
            EXPECT_NEAR(pn.y, 0.f, 1e-6f);
            EXPECT_EQ(texel<glm::vec2>(field(*graph, "mvec"), x, y), glm::vec2(0.f));

            const glm::uvec4 vb = texel<glm::uvec4>(field(*graph, "vbuffer"), x, y);
            EXPECT_EQ(vb.x, 0u);
            ASSERT_LT(vb.y, 2u);
            // The rectangle's diagonal runs from vertex 0 to 2: triangle 0 is below it.
            EXPECT_EQ(vb.y, local.y < (local.x + 1.f) * 0.75f - 0.75f ? 0u : 1u);
            const float u = bitsToFloat(vb.z), v = bitsToFloat(vb.w);
            EXPECT_GE(u, 0.f);
            EXPECT_GE(v, 0.f);
            EXPECT_LE(u + v, 1.f + 1e-6f);
            const uint32_t* idx = mesh.indices.data() + 3 * vb.y;
            const glm::vec3 pObj =
                (1.f - u - v) * mesh.positions[idx[0]] + u * mesh.positions[idx[1]] + v * mesh.positions[idx[2]];
            const glm::vec3 fromBary = glm::vec3(scene->instances[0].world * glm::vec4(pObj, 1.f));
            EXPECT_NEAR(fromBary.x, posW.x, 1e-4f);
            EXPECT_NEAR(fromBary.y, posW.y, 1e-4f);
            EXPECT_NEAR(fromBary.z, posW.z, 1e-4f);
            EXPECT_EQ(texel<uint32_t>(field(*graph, "meshId"), x, y), 0u);

            // Material channels: metallic 0, so albedo is the base colour.
            const Material& m = scene->materials[0];
            EXPECT_EQ(texel<glm::vec4>(field(*graph, "albedo"), x, y), glm::vec4(glm::vec3(m.baseColorFactor), 1.f));
            EXPECT_EQ(texel<glm::vec4>(field(*graph, "emission"), x, y), glm::vec4(m.emissiveFactor, 1.f));
            const float NdotV = -glm::dot(glm::vec3(0.f, 0.f, 1.f), glm::normalize(rayDir(cam, x + 0.5f, y + 0.5f)));
            const glm::vec3 spec = specularAlbedo(glm::vec3(0.04f), NdotV, m.roughnessFactor);
            const glm::vec4 specOut = texel<glm::vec4>(field(*graph, "specAlbedo"), x, y);
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(specOut[c], spec[c], 1e-5f);
            EXPECT_EQ(specOut.w, 1.f);
        }
    }
    EXPECT_GT(hits, 500);
    EXPECT_GT(misses, 500);
}

// Row 0 is the top of the image and column 0 the left: a quad in the
// upper-left quadrant of the view covers the upper-left pixels.
TEST(GBufferRaster, ImageOrientation) {
    auto scene = oneMeshScene(rectMesh(-100.f, 0.f, 0.f, 100.f), plainMaterial(), glm::vec3(0.f, 0.f, -2.f));
    Camera cam = makeCamera();
    auto graph = makeGraph({"linearZ"});
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    const Texture& lz = field(*graph, "linearZ");
    EXPECT_GT(texel<glm::vec2>(lz, 0, 0).x, 0.f);
    EXPECT_EQ(texel<glm::vec2>(lz, kW - 1, 0).x, -1.f);
    EXPECT_EQ(texel<glm::vec2>(lz, 0, kH - 1).x, -1.f);
    EXPECT_EQ(texel<glm::vec2>(lz, kW - 1, kH - 1).x, -1.f);
}

// Only consumed channels exist: a graph that marks only linearZ renders it alone.
TEST(GBufferRaster, OnlyConsumedChannels) {
    const float depth = 2.5f;
    auto scene = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), plainMaterial(), glm::vec3(0.f, 0.f, -depth));
    Camera cam = makeCamera();
    auto graph = makeGraph({"linearZ"});
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    for (const char* c : kAllChannels) {
        if (std::string(c) != "linearZ") {
            EXPECT_EQ(graph->fieldTexture(std::string("GBuffer.") + c), nullptr) << c;
        }
    }
    const Texture& lz = field(*graph, "linearZ");
    EXPECT_LT(relErr(texel<glm::vec2>(lz, kW / 2, kH / 2).x, depth), 1e-4f);
    EXPECT_EQ(texel<glm::vec2>(lz, 0, 0), glm::vec2(-1.f, 0.f));
    EXPECT_EQ(graph->lastStats().at("GBuffer").at("geometryPasses"), 1.0);
}

// A back face: culled for single-sided materials with cullMode back, drawn
// (unflipped) with cullMode none, and flipped to face the viewer when the
// material is double-sided.
TEST(GBufferRaster, BackFacesAndDoubleSided) {
    const float depth = 2.f;
    // Rotated half a turn about Y: the quad's front faces away from the camera.
    const glm::quat halfTurn = glm::angleAxis(glm::pi<float>(), glm::vec3(0.f, 1.f, 0.f));
    const uint32_t cx = kW / 2, cy = kH / 2;
    Camera cam = makeCamera();

    auto single = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), plainMaterial(), glm::vec3(0.f, 0.f, -depth), halfTurn);
    {
        auto graph = makeGraph(allChannels());
        graph->execute(FrameInfo{0, 0.0, single.get(), &cam});
        expectMiss(*graph, cx, cy);
    }
    {
        auto graph = makeGraph(allChannels(), {{"cullMode", "none"}});
        graph->execute(FrameInfo{0, 0.0, single.get(), &cam});
        EXPECT_EQ(texel<glm::vec4>(field(*graph, "posW"), cx, cy).w, 1.f);
        const glm::vec4 fn = texel<glm::vec4>(field(*graph, "faceNormalW"), cx, cy);
        const glm::vec4 n = texel<glm::vec4>(field(*graph, "normW"), cx, cy);
        EXPECT_NEAR(fn.z, -1.f, 1e-6f);
        EXPECT_NEAR(n.z, -1.f, 1e-6f);
    }
    Material two = plainMaterial();
    two.doubleSided = true;
    auto doubled = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), two, glm::vec3(0.f, 0.f, -depth), halfTurn);
    {
        auto graph = makeGraph(allChannels());  // cullMode back: double-sided is never culled
        graph->execute(FrameInfo{0, 0.0, doubled.get(), &cam});
        EXPECT_EQ(texel<glm::vec4>(field(*graph, "posW"), cx, cy).w, 1.f);
        EXPECT_LT(relErr(texel<glm::vec2>(field(*graph, "linearZ"), cx, cy).x, depth), 1e-4f);
        const glm::vec4 fn = texel<glm::vec4>(field(*graph, "faceNormalW"), cx, cy);
        const glm::vec4 n = texel<glm::vec4>(field(*graph, "normW"), cx, cy);
        EXPECT_NEAR(fn.z, 1.f, 1e-6f);
        EXPECT_NEAR(n.z, 1.f, 1e-6f);
    }
    // A mirroring transform flips the winding: the mirrored back face is a front face.
    {
        auto mirrored = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), plainMaterial(), glm::vec3(0.f, 0.f, -depth),
                                     halfTurn);
        mirrored->nodes[0].scale = glm::vec3(1.f, 1.f, -1.f);
        mirrored->update(0.0);
        auto graph = makeGraph({"faceNormalW"});
        graph->execute(FrameInfo{0, 0.0, mirrored.get(), &cam});
        EXPECT_NEAR(texel<glm::vec4>(field(*graph, "faceNormalW"), cx, cy).z, 1.f, 1e-6f);
    }
}

// Alpha-masked materials discard below their cutoff unless alphaTest is off.
TEST(GBufferRaster, AlphaTest) {
    Material m = plainMaterial();
    m.alphaMode = AlphaMode::Mask;
    m.alphaCutoff = 0.5f;
    m.baseColorFactor.a = 0.3f;
    auto scene = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), m, glm::vec3(0.f, 0.f, -2.f));
    Camera cam = makeCamera();
    auto tested = makeGraph({"meshId"});
    tested->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    EXPECT_EQ(texel<uint32_t>(field(*tested, "meshId"), kW / 2, kH / 2), kMissId);
    auto untested = makeGraph({"meshId"}, {{"alphaTest", false}});
    untested->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    EXPECT_EQ(texel<uint32_t>(field(*untested, "meshId"), kW / 2, kH / 2), 0u);
}

// Jitter moves the sample positions, not the motion vectors: with jitter
// (0.25, 0) a vertical edge 0.1 px right of a pixel centre covers that
// pixel; jitter (0, 0.25) does the same for a horizontal edge below a centre.
TEST(GBufferRaster, JitterMovesCoverageNotMotion) {
    const float depth = 2.f;
    const uint32_t col = 20, row = 30;
    Camera cam = makeCamera();
    // Left edge at image x = col + 0.6; top edge at image y = row + 0.6 (the quad extends right and down).
    const float xl = viewXAt(cam, col + 0.6f, depth);
    const float yt = viewYAt(cam, row + 0.6f, depth);
    auto scene = oneMeshScene(rectMesh(xl, -100.f, 100.f, yt), plainMaterial(), glm::vec3(0.f, 0.f, -depth));

    auto render = [&](glm::vec2 jitter) {
        Camera c = cam;
        c.jitter = jitter;
        c.prevJitter = jitter;
        auto graph = makeGraph({"meshId", "mvec", "posW"});
        graph->execute(FrameInfo{0, 0.0, scene.get(), &c});
        return graph;
    };
    {
        auto g = render(glm::vec2(0.f));
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col, row + 5), kMissId);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col + 1, row + 5), 0u);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col + 5, row), kMissId);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col + 5, row + 1), 0u);
    }
    {
        auto g = render(glm::vec2(0.25f, 0.f));
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col - 1, row + 5), kMissId);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col, row + 5), 0u);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col + 5, row), kMissId);  // y unchanged
        // The sample sits at the jittered position.
        const glm::vec3 p = unprojectToDepth(cam, col + 0.75f, row + 5.5f, depth);
        const glm::vec4 posW = texel<glm::vec4>(field(*g, "posW"), col, row + 5);
        EXPECT_NEAR(posW.x, p.x, 1e-4f * depth);
        EXPECT_NEAR(posW.y, p.y, 1e-4f * depth);
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) ASSERT_EQ(texel<glm::vec2>(field(*g, "mvec"), x, y), glm::vec2(0.f));
    }
    {
        auto g = render(glm::vec2(0.f, 0.25f));
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col + 5, row - 1), kMissId);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col + 5, row), 0u);
        EXPECT_EQ(texel<uint32_t>(field(*g, "meshId"), col, row + 5), kMissId);  // x unchanged
        const glm::vec3 p = unprojectToDepth(cam, col + 5.5f, row + 0.75f, depth);
        const glm::vec4 posW = texel<glm::vec4>(field(*g, "posW"), col + 5, row);
        EXPECT_NEAR(posW.x, p.x, 1e-4f * depth);
        EXPECT_NEAR(posW.y, p.y, 1e-4f * depth);
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) ASSERT_EQ(texel<glm::vec2>(field(*g, "mvec"), x, y), glm::vec2(0.f));
    }
}

// A moving instance: mvec = uvPrev - uvCur of the surface point, analytic.
TEST(GBufferRaster, MotionVectorsOfMovingInstance) {
    const float depth = 3.f;
    const glm::vec3 t0(-0.1f, 0.05f, -depth), t1(0.15f, -0.05f, -depth - 0.4f);
    auto scene = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), plainMaterial(), t0);
    scene->nodes[0].translation = t1;
    scene->update(1.0 / 30.0);
    ASSERT_EQ(scene->instances[0].prevWorld, glm::translate(glm::mat4(1.f), t0));
    ASSERT_EQ(scene->instances[0].world, glm::translate(glm::mat4(1.f), t1));

    Camera cam = makeCamera();
    cam.jitter = glm::vec2(0.3f, -0.2f);  // removed from motion vectors
    auto graph = makeGraph({"mvec", "posW"});
    graph->execute(FrameInfo{1, 1.0 / 30.0, scene.get(), &cam});
    const glm::mat4 viewProj = cam.viewProj();
    int checked = 0;
    for (uint32_t y = 0; y < kH; y += 3) {
        for (uint32_t x = 0; x < kW; x += 3) {
            const glm::vec4 posW = texel<glm::vec4>(field(*graph, "posW"), x, y);
            if (posW.w != 1.f) continue;
            const glm::vec3 p = unprojectToDepth(cam, x + 0.5f + cam.jitter.x, y + 0.5f + cam.jitter.y, -t1.z);
            const glm::vec3 prev = p - (t1 - t0);
            auto toUv = [&](glm::vec3 q) {
                const glm::vec4 c = viewProj * glm::vec4(q, 1.f);
                return glm::vec2(0.5f * c.x / c.w + 0.5f, 0.5f - 0.5f * c.y / c.w);
            };
            const glm::vec2 expected = toUv(prev) - toUv(p);
            const glm::vec2 mv = texel<glm::vec2>(field(*graph, "mvec"), x, y);
            EXPECT_NEAR(mv.x * kW, expected.x * kW, 1e-3f) << x << "," << y;
            EXPECT_NEAR(mv.y * kH, expected.y * kH, 1e-3f) << x << "," << y;
            ++checked;
        }
    }
    EXPECT_GT(checked, 50);
}

// Misses move with the camera's rotation only: the documented choice is
// CameraKernels.h missMotion (the direction at infinity through the previous
// camera), the same as GBufferRT.
TEST(GBufferRaster, MissMotionFollowsCameraRotation) {
    auto scene = std::make_shared<Scene>();
    scene->finalize();
    scene->update(0.0);
    Camera cam = makeCamera();
    cam.prevWorld = glm::rotate(glm::mat4(1.f), 0.05f, glm::vec3(0.f, 1.f, 0.f));
    cam.prevWorld[3] = glm::vec4(5.f, 1.f, 2.f, 1.f);  // translation does not move the sky
    auto graph = makeGraph({"mvec", "linearZ"});
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    const CameraData cd = makeCameraData(cam, kW, kH);
    for (uint32_t y = 0; y < kH; y += 5) {
        for (uint32_t x = 0; x < kW; x += 5) {
            EXPECT_EQ(texel<glm::vec2>(field(*graph, "linearZ"), x, y), glm::vec2(-1.f, 0.f));
            const glm::vec2 expected = missMotion(cd, pixelRayDir(cd, x, y));
            const glm::vec2 mv = texel<glm::vec2>(field(*graph, "mvec"), x, y);
            EXPECT_NEAR(mv.x * kW, expected.x * kW, 1e-3f);
            EXPECT_NEAR(mv.y * kH, expected.y * kH, 1e-3f);
        }
    }
}

// A textured, normal-mapped, tilted surface: the shader's surface evaluation
// against SurfaceKernels.h evalSurface at the vbuffer's own barycentrics.
TEST(GBufferRaster, SurfaceMatchesSurfaceKernels) {
    auto scene = std::make_shared<Scene>();
    // 4x4 images: a colour ramp (sRGB slots) and a bumpy normal map / metal-roughness (linear slots).
    auto makeImage = [](const char* name, auto f) {
        SceneImage img;
        img.name = name;
        img.width = img.height = 4;
        for (uint32_t y = 0; y < 4; ++y)
            for (uint32_t x = 0; x < 4; ++x) img.texels.push_back(f(x, y));
        return img;
    };
    scene->images.push_back(makeImage("base", [](uint32_t x, uint32_t y) {
        return glm::u8vec4(uint8_t(40 + 60 * x), uint8_t(200 - 50 * y), uint8_t(17 * (x + y)), 255);
    }));
    scene->images.push_back(makeImage("normal", [](uint32_t x, uint32_t y) {
        return glm::u8vec4(uint8_t(128 + 30 * (int(x) - 2)), uint8_t(128 + 25 * (int(y) - 1)), 230, 255);
    }));
    scene->images.push_back(makeImage("mr", [](uint32_t x, uint32_t y) {
        return glm::u8vec4(0, uint8_t(60 + 40 * x), uint8_t(30 + 60 * y), 255);
    }));
    Material m;
    m.baseColorFactor = glm::vec4(0.9f, 0.8f, 1.f, 1.f);
    m.baseColorTexture.image = 0;
    m.emissiveTexture.image = 0;
    m.emissiveFactor = glm::vec3(0.5f, 1.f, 2.f);
    m.normalTexture.image = 1;
    m.normalScale = 0.8f;
    m.metallicRoughnessTexture.image = 2;
    m.metallicFactor = 0.7f;
    m.roughnessFactor = 0.9f;
    Mesh mesh = rectMesh(-1.f, -1.f, 1.f, 1.f);
    // Curved normals and uvs that wrap (repeat) once.
    mesh.normals = {glm::normalize(glm::vec3(-0.3f, -0.2f, 1.f)), glm::normalize(glm::vec3(0.3f, -0.2f, 1.f)),
                    glm::normalize(glm::vec3(0.3f, 0.2f, 1.f)), glm::normalize(glm::vec3(-0.3f, 0.2f, 1.f))};
    mesh.uvs = {{-0.3f, 1.7f}, {1.6f, 1.7f}, {1.6f, -0.2f}, {-0.3f, -0.2f}};
    mesh.tangents[2].w = -1.f;
    scene->meshes.push_back(mesh);
    scene->materials.push_back(m);
    Node n;
    n.translation = glm::vec3(0.1f, 0.f, -2.5f);
    n.rotation = glm::angleAxis(0.6f, glm::normalize(glm::vec3(1.f, 0.5f, 0.f)));
    n.meshes = {0};
    scene->nodes.push_back(n);
    scene->roots = {0};
    scene->finalize();
    scene->update(0.0);

    Camera cam = makeCamera();
    auto graph = makeGraph(allChannels());
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    HostView host(*scene);
    const CameraData cd = makeCameraData(cam, kW, kH);
    int checked = 0;
    for (uint32_t y = 0; y < kH; ++y) {
        for (uint32_t x = 0; x < kW; ++x) {
            const glm::uvec4 vb = texel<glm::uvec4>(field(*graph, "vbuffer"), x, y);
            if (vb.x == kMissId) continue;
            SCOPED_TRACE("pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
            const glm::vec3 dir = pixelRayDir(cd, x, y);
            const SurfaceHit s = evalSurface(host.view, vb.x, vb.y, bitsToFloat(vb.z), bitsToFloat(vb.w), dir);
            auto near3 = [](glm::vec3 a, glm::vec3 b, float tol) {
                return std::fabs(a.x - b.x) <= tol && std::fabs(a.y - b.y) <= tol && std::fabs(a.z - b.z) <= tol;
            };
            const glm::vec4 posW = texel<glm::vec4>(field(*graph, "posW"), x, y);
            EXPECT_TRUE(near3(glm::vec3(posW), s.posW, 1e-4f));
            // The hit lies on this pixel's camera ray.
            const glm::vec3 toHit = glm::normalize(glm::vec3(posW) - cam.position());
            EXPECT_GT(glm::dot(toHit, glm::normalize(dir)), 1.f - 1e-6f);
            EXPECT_TRUE(near3(glm::vec3(texel<glm::vec4>(field(*graph, "faceNormalW"), x, y)), s.faceNormalW, 1e-5f));
            // Textures: the shader filters texels as sampleTexture does (texelFetch), to float rounding.
            const float texTol = 1e-5f;
            EXPECT_TRUE(near3(glm::vec3(texel<glm::vec4>(field(*graph, "normW"), x, y)), s.normalW, texTol));
            EXPECT_TRUE(near3(glm::vec3(texel<glm::vec4>(field(*graph, "albedo"), x, y)), diffuseAlbedo(s), texTol));
            EXPECT_TRUE(near3(glm::vec3(texel<glm::vec4>(field(*graph, "emission"), x, y)), s.emission,
                              texTol * 2.f));
            const float NdotV = glm::clamp(-glm::dot(s.normalW, glm::normalize(dir)), 0.f, 1.f);
            const glm::vec3 spec = specularAlbedo(specularF0(s), NdotV, s.roughness);
            EXPECT_TRUE(near3(glm::vec3(texel<glm::vec4>(field(*graph, "specAlbedo"), x, y)), spec, texTol));
            const float depth = glm::dot(s.posW - cam.position(), cam.forward());
            EXPECT_LT(relErr(texel<glm::vec2>(field(*graph, "linearZ"), x, y).x, depth), 1e-4f);
            ++checked;
        }
    }
    EXPECT_GT(checked, 300);
}

// Samplers and texture transforms, per slot: GBufferRaster (sampleTexture in
// GLSL over texelFetch) and GBufferRT (SurfaceKernels.h) give the same albedo,
// specular albedo and emission. Where every slot a channel reads is nearest,
// exactly the same texel, away from texel boundaries (where the two sides' uv
// rounding may pick neighbours); bilinear to float rounding. Nearest slots
// also read the texel that wrapTexel names, so a clamped uv outside [0, 1]
// shows the edge texel in both G-buffers.
TEST(GBufferRaster, SamplersAndTransformsMatchGBufferRT) {
    constexpr uint32_t w = 128, h = 96, size = 4;
    auto scene = std::make_shared<Scene>();
    SceneImage img;
    img.name = "checker";
    img.width = img.height = size;
    for (uint32_t y = 0; y < size; ++y)
        for (uint32_t x = 0; x < size; ++x)
            img.texels.emplace_back(uint8_t(20 + 70 * x), uint8_t(230 - 60 * y), uint8_t(40 * ((x + y) % 3) + 5), 255);
    scene->images.push_back(img);
    using W = TextureWrap;
    auto texture = [](W s, W t, bool nearest, glm::mat3x2 transform = glm::mat3x2(1.f)) {
        TextureRef r;
        r.image = 0;
        r.wrapS = s;
        r.wrapT = t;
        r.nearest = nearest ? 1u : 0u;
        r.transform = transform;
        return r;
    };
    // Three materials, side by side; the slots of one material sample differently.
    Material m0;
    m0.metallicFactor = 0.f;
    m0.roughnessFactor = 0.7f;
    m0.emissiveFactor = glm::vec3(1.f);
    m0.baseColorTexture = texture(W::ClampToEdge, W::MirroredRepeat, true);
    m0.emissiveTexture = texture(W::MirroredRepeat, W::ClampToEdge, false);
    Material m1 = m0;
    m1.baseColorTexture = texture(W::ClampToEdge, W::ClampToEdge, false,
                                  glm::mat3x2(glm::vec2(0.8f, 0.3f), glm::vec2(-0.3f, 0.8f), glm::vec2(0.1f, -0.2f)));
    m1.emissiveTexture = texture(W::Repeat, W::MirroredRepeat, true,
                                 glm::mat3x2(glm::vec2(1.5f, 0.f), glm::vec2(0.f, -0.75f), glm::vec2(0.25f, 1.f)));
    Material m2 = m0;
    // Rotation by 0.5 rad, scale (1.25, 0.8), offset (0.3, 0.6), as the loader builds KHR_texture_transform.
    const float c = std::cos(0.5f), sn = std::sin(0.5f);
    m2.baseColorTexture =
        texture(W::MirroredRepeat, W::Repeat, true,
                glm::mat3x2(glm::vec2(c * 1.25f, -sn * 1.25f), glm::vec2(sn * 0.8f, c * 0.8f), glm::vec2(0.3f, 0.6f)));
    m2.metallicFactor = 1.f;
    m2.metallicRoughnessTexture = texture(W::ClampToEdge, W::ClampToEdge, true);
    m2.emissiveTexture = TextureRef{};
    scene->materials = {m0, m1, m2};
    for (uint32_t i = 0; i < 3; ++i) {
        const float x0 = -1.6f + 1.1f * float(i);
        Mesh mesh = rectMesh(x0, -1.1f, x0 + 1.f, 1.1f, i);
        mesh.uvs = {{-0.7f, 1.9f}, {1.8f, 1.9f}, {1.8f, -0.6f}, {-0.7f, -0.6f}};  // wraps and clamps
        scene->meshes.push_back(mesh);
        Node n;
        n.translation = glm::vec3(0.f, 0.f, -3.f);
        n.meshes = {i};
        scene->nodes.push_back(n);
        scene->roots.push_back(int(i));
    }
    scene->finalize();
    scene->update(0.0);
    Camera cam = makeCamera(w, h);

    nlohmann::json g = {
        {"loom_graph", 1},
        {"name", "RasterVsRTTextures"},
        {"passes", {{{"name", "Raster"}, {"type", "GBufferRaster"}}, {{"name", "RT"}, {"type", "GBufferRT"}}}},
        {"edges", nlohmann::json::array()},
        {"outputs", nlohmann::json::array()}};
    for (const char* pass : {"Raster", "RT"})
        for (const char* c : {"vbuffer", "albedo", "specAlbedo", "emission"})
            g["outputs"].push_back(std::string(pass) + "." + c);
    RenderGraph graph(parseGraph(g.dump()), registry());
    CompileOptions o;
    o.width = w;
    o.height = h;
    graph.compile(o);
    graph.execute(FrameInfo{0, 0.0, scene.get(), &cam});
    auto tex = [&](const char* pass, const char* c) -> const Texture& {
        const Texture* t = graph.fieldTexture(std::string(pass) + "." + c);
        if (!t) throw std::runtime_error(std::string(pass) + "." + c + " missing");
        return *t;
    };

    const SceneView& view = scene->view();
    const CameraData cd = makeCameraData(cam, w, h);
    // How a slot reads at a uv: exact (nearest, the lookup off texel boundaries) or not, and the texel it names.
    struct Lookup {
        bool exact = true;
        glm::vec4 texel{1.f};
    };
    auto lookup = [&](const TextureRef& t, glm::vec2 uv, bool srgb) {
        Lookup l;
        if (t.image < 0) return l;
        if (!t.nearest) return Lookup{false, {}};
        const glm::vec2 p = transformUv(t, uv) * float(size);
        const glm::vec2 off = glm::abs(p - glm::round(p));
        l.exact = off.x > 1e-3f && off.y > 1e-3f;
        const int x = wrapTexel(int(std::floor(p.x)), int(size), t.wrapS);
        const int y = wrapTexel(int(std::floor(p.y)), int(size), t.wrapT);
        const glm::vec4 v = glm::vec4(img.texels[size_t(y) * size + size_t(x)]) / 255.f;
        l.texel = srgb ? glm::vec4(srgbToLinear(v.r), srgbToLinear(v.g), srgbToLinear(v.b), v.a) : v;
        return l;
    };
    int compared[3] = {0, 0, 0}, exact[3] = {0, 0, 0}, clampedEdge = 0;
    for (uint32_t y = 0; y < h; ++y) {
        for (uint32_t x = 0; x < w; ++x) {
            const glm::uvec4 vr = texel<glm::uvec4>(tex("Raster", "vbuffer"), x, y);
            const glm::uvec4 vt = texel<glm::uvec4>(tex("RT", "vbuffer"), x, y);
            if (vt.x == kMissId || vr.x != vt.x || vr.y != vt.y) continue;
            SCOPED_TRACE("pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
            const SurfaceHit s =
                evalSurface(view, vt.x, vt.y, bitsToFloat(vt.z), bitsToFloat(vt.w), pixelRayDir(cd, x, y));
            const MaterialData& mat = view.materials[s.material];
            const Lookup base = lookup(mat.baseColorTexture, s.uv, true);
            const Lookup mr = lookup(mat.metallicRoughnessTexture, s.uv, false);
            const Lookup emissive = lookup(mat.emissiveTexture, s.uv, true);
            ++compared[s.material];
            const glm::vec3 albedoRT = glm::vec3(texel<glm::vec4>(tex("RT", "albedo"), x, y));
            const glm::vec3 albedoRaster = glm::vec3(texel<glm::vec4>(tex("Raster", "albedo"), x, y));
            const glm::vec3 emissionRT = glm::vec3(texel<glm::vec4>(tex("RT", "emission"), x, y));
            const glm::vec3 emissionRaster = glm::vec3(texel<glm::vec4>(tex("Raster", "emission"), x, y));
            const glm::vec3 specRT = glm::vec3(texel<glm::vec4>(tex("RT", "specAlbedo"), x, y));
            const glm::vec3 specRaster = glm::vec3(texel<glm::vec4>(tex("Raster", "specAlbedo"), x, y));
            auto near3 = [](glm::vec3 a, glm::vec3 b, float tol) {
                return glm::all(glm::lessThanEqual(glm::abs(a - b), glm::vec3(tol)));
            };
            // Bilinear is continuous: the two sides' uvs, a rounding error apart, give values as close.
            const float texTol = 1e-5f;
            if (base.exact && mr.exact) {
                ++exact[s.material];
                // The texel wrapTexel names, in both (the metallic from the B channel when textured).
                const float metallic =
                    mat.metallicFactor * (mat.metallicRoughnessTexture.image >= 0 ? mr.texel.b : 1.f);
                EXPECT_TRUE(near3(albedoRT, glm::vec3(base.texel) * (1.f - metallic), 1e-6f)) << "RT albedo";
                EXPECT_TRUE(near3(albedoRaster, albedoRT, 1e-6f)) << "albedo";
                EXPECT_TRUE(near3(specRaster, specRT, 1e-5f)) << "specAlbedo";
                const glm::vec2 uv = transformUv(mat.baseColorTexture, s.uv);
                if (mat.baseColorTexture.wrapS == W::ClampToEdge && uv.x < 0.f) {
                    // Left of the image: its first column, as texel (0, row).
                    const int row = wrapTexel(int(std::floor(uv.y * size)), int(size), mat.baseColorTexture.wrapT);
                    const glm::vec4 edge = glm::vec4(img.texels[size_t(row) * size]) / 255.f;
                    EXPECT_EQ(albedoRT.r, srgbToLinear(edge.r));
                    ++clampedEdge;
                }
            } else {
                EXPECT_TRUE(near3(albedoRaster, albedoRT, texTol)) << "albedo";
                EXPECT_TRUE(near3(specRaster, specRT, texTol)) << "specAlbedo";
            }
            if (emissive.exact) {
                EXPECT_TRUE(near3(emissionRT, glm::vec3(emissive.texel), 1e-6f)) << "RT emission";
                EXPECT_TRUE(near3(emissionRaster, emissionRT, 1e-6f)) << "emission";
            } else {
                EXPECT_TRUE(near3(emissionRaster, emissionRT, texTol)) << "emission";
            }
        }
    }
    for (int m = 0; m < 3; ++m) {
        EXPECT_GT(compared[m], 500) << "material " << m;
        if (m != 1) EXPECT_GT(exact[m], 400) << "material " << m;  // material 1's base colour is bilinear
    }
    EXPECT_GT(clampedEdge, 50);
}

// No instances: every pixel is a miss. No scene at all: a clear error.
TEST(GBufferRaster, EmptySceneAndNoScene) {
    auto scene = std::make_shared<Scene>();
    scene->finalize();
    scene->update(0.0);
    Camera cam = makeCamera();
    auto graph = makeGraph(allChannels());
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    for (uint32_t y = 0; y < kH; y += 7)
        for (uint32_t x = 0; x < kW; x += 7) expectMiss(*graph, x, y);

    try {
        graph->execute(FrameInfo{1, 0.0, nullptr, nullptr});
        FAIL() << "expected loom::Error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(std::string(e.what()).find("scene"), std::string::npos) << e.what();
    }
}

// Animation between frames: the same graph follows the instance, and the
// scene is uploaded once.
TEST(GBufferRaster, FollowsAnimatedInstances) {
    auto scene = oneMeshScene(rectMesh(-0.2f, -0.2f, 0.2f, 0.2f), plainMaterial(), glm::vec3(-0.5f, 0.f, -2.f));
    Camera cam = makeCamera();
    auto graph = makeGraph({"meshId"});
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    EXPECT_TRUE(graph->lastStats().at("GBuffer").count("uploadMs"));
    const Texture& id = field(*graph, "meshId");
    auto covered = [&](float wx) {
        const glm::vec4 c = cam.viewProj() * glm::vec4(wx, 0.f, -2.f, 1.f);
        const uint32_t px = uint32_t((0.5f * c.x / c.w + 0.5f) * kW);
        return texel<uint32_t>(id, px, kH / 2) == 0u;
    };
    EXPECT_TRUE(covered(-0.5f));
    EXPECT_FALSE(covered(0.5f));
    scene->nodes[0].translation.x = 0.5f;
    scene->update(1.0);
    graph->execute(FrameInfo{1, 1.0, scene.get(), &cam});
    EXPECT_FALSE(graph->lastStats().at("GBuffer").count("uploadMs"));
    EXPECT_FALSE(covered(-0.5f));
    EXPECT_TRUE(covered(0.5f));
}

// A channel's values do not depend on which other channels are consumed
// (dumping a field must never change a rendered value), including when the
// channels are split over two geometry passes.
TEST(GBufferRaster, ChannelValuesIndependentOfConsumedSet) {
    auto scene = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), plainMaterial(), glm::vec3(0.1f, 0.f, -2.f),
                              glm::angleAxis(0.7f, glm::normalize(glm::vec3(1.f, 1.f, 0.f))));
    Camera cam = makeCamera();
    cam.jitter = glm::vec2(0.1f, -0.3f);
    auto all = makeGraph(allChannels());
    all->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    for (const char* c : kAllChannels) {
        auto one = makeGraph({c});
        one->execute(FrameInfo{0, 0.0, scene.get(), &cam});
        EXPECT_TRUE(field(*one, c).samePixels(field(*all, c))) << c;
    }
}

namespace {

struct FineDerivatives {
    float linearZ = 0.f;
    glm::vec2 pnFwidth{0.f};
};

/// What fine screen-space derivatives of depth, position and interpolated
/// normal give at pixel (x, y) on triangle `prim` of an instance: the
/// differences between the pixels of its 2x2 quad, on the triangle's plane.
FineDerivatives fineDerivatives(const Scene& scene, const Camera& cam, uint32_t w, uint32_t h, uint32_t instance,
                                uint32_t prim, uint32_t x, uint32_t y) {
    const Instance& inst = scene.instances[instance];
    const Mesh& mesh = scene.meshes[inst.mesh];
    const uint32_t* idx = mesh.indices.data() + 3 * prim;
    glm::vec3 p[3], n[3];
    const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(inst.world)));
    for (int k = 0; k < 3; ++k) {
        p[k] = glm::vec3(inst.world * glm::vec4(mesh.positions[idx[k]], 1.f));
        n[k] = mesh.normals[idx[k]];
    }
    const glm::vec3 fn = glm::cross(p[1] - p[0], p[2] - p[0]);
    const CameraData cd = makeCameraData(cam, w, h);
    struct OnPlane {
        glm::vec3 pos, normal;
        float depth;
    };
    auto at = [&](uint32_t px, uint32_t py) {
        const glm::vec3 d = cameraRayDir(cd, px + 0.5f + cam.jitter.x, py + 0.5f + cam.jitter.y);
        const glm::vec3 q = cd.origin + d * (glm::dot(p[0] - cd.origin, fn) / glm::dot(d, fn));
        // Barycentrics of q, then the interpolated normal (GBufferRT's interpolatedNormal).
        const glm::vec3 e1 = p[1] - p[0], e2 = p[2] - p[0], r = q - p[0];
        const float d11 = glm::dot(e1, e1), d12 = glm::dot(e1, e2), d22 = glm::dot(e2, e2);
        const float det = d11 * d22 - d12 * d12;
        const float u = (d22 * glm::dot(r, e1) - d12 * glm::dot(r, e2)) / det;
        const float v = (d11 * glm::dot(r, e2) - d12 * glm::dot(r, e1)) / det;
        const glm::vec3 nw = glm::normalize(normalMatrix * ((1.f - u - v) * n[0] + u * n[1] + v * n[2]));
        return OnPlane{q, nw, glm::dot(q - cd.origin, cd.forward)};
    };
    const uint32_t x0 = x & ~1u, y0 = y & ~1u;
    const OnPlane ax = at(x0, y), bx = at(x0 + 1, y), ay = at(x, y0), by = at(x, y0 + 1);
    FineDerivatives f;
    f.linearZ = std::max(std::fabs(bx.depth - ax.depth), std::fabs(by.depth - ay.depth));
    f.pnFwidth.x = glm::length(glm::abs(bx.pos - ax.pos) + glm::abs(by.pos - ay.pos));
    f.pnFwidth.y = glm::length(glm::abs(bx.normal - ax.normal) + glm::abs(by.normal - ay.normal));
    return f;
}

/// Renders a shipped scene with GBufferRaster and GBufferRT in one graph and
/// compares them pixel by pixel where both see the same triangle.
/// `hide`: a node whose scale is set to (1, 1, 0) first; neither pass may show its instances.
void compareWithRayTracer(const std::string& sceneFile, double t0, double t1, glm::vec2 jitter,
                          const std::string& hide = {}) {
    auto scene = Scene::load(std::string(LOOM_TEST_SOURCE_DIR) + "/data/scenes/" + sceneFile);
    const uint32_t w = 160, h = 120;
    std::vector<uint32_t> hidden;
    if (!hide.empty()) {
        for (size_t i = 0; i < scene->nodes.size(); ++i)
            if (scene->nodes[i].name == hide) scene->nodes[i].scale = glm::vec3(1.f, 1.f, 0.f);
        for (size_t i = 0; i < scene->instances.size(); ++i)
            if (scene->nodes[scene->instances[i].node].name == hide) hidden.push_back(uint32_t(i));
        ASSERT_FALSE(hidden.empty()) << "no instance of node " << hide;
    }
    scene->update(t0);
    scene->update(t1);
    Camera cam = scene->camera;
    cam.aspect = float(w) / float(h);
    cam.jitter = jitter;

    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "RasterVsRT"},
                        {"passes",
                         {{{"name", "Raster"}, {"type", "GBufferRaster"}}, {{"name", "RT"}, {"type", "GBufferRT"}}}},
                        {"edges", nlohmann::json::array()},
                        {"outputs", nlohmann::json::array()}};
    for (const char* c : kAllChannels) {
        g["outputs"].push_back(std::string("Raster.") + c);
        g["outputs"].push_back(std::string("RT.") + c);
    }
    RenderGraph graph(parseGraph(g.dump()), registry());
    CompileOptions o;
    o.width = w;
    o.height = h;
    graph.compile(o);
    graph.execute(FrameInfo{1, t1, scene.get(), &cam});
    auto tex = [&](const char* pass, const char* c) -> const Texture& {
        const Texture* t = graph.fieldTexture(std::string(pass) + "." + c);
        if (!t) throw std::runtime_error(std::string(pass) + "." + c + " missing");
        return *t;
    };
    auto close4 = [](glm::vec4 a, glm::vec4 b, float tol) {
        return glm::all(glm::lessThanEqual(glm::abs(a - b), glm::vec4(tol)));
    };
    int same = 0, differ = 0;
    for (uint32_t y = 0; y < h; ++y) {
        for (uint32_t x = 0; x < w; ++x) {
            const glm::uvec4 vr = texel<glm::uvec4>(tex("Raster", "vbuffer"), x, y);
            const glm::uvec4 vt = texel<glm::uvec4>(tex("RT", "vbuffer"), x, y);
            for (uint32_t i : hidden) {
                EXPECT_NE(vr.x, i) << "Raster shows hidden instance " << i << " at " << x << ", " << y;
                EXPECT_NE(vt.x, i) << "RT shows hidden instance " << i << " at " << x << ", " << y;
            }
            if (vr.x != vt.x || vr.y != vt.y) {
                ++differ;  // a silhouette or shared edge: either triangle is right
                continue;
            }
            ++same;
            SCOPED_TRACE(sceneFile + " pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")");
            if (vr.x == kMissId) {
                EXPECT_EQ(vr, vt);
                const glm::vec2 mr = texel<glm::vec2>(tex("Raster", "mvec"), x, y);
                const glm::vec2 mt = texel<glm::vec2>(tex("RT", "mvec"), x, y);
                EXPECT_NEAR(mr.x * w, mt.x * w, 1e-3f);
                EXPECT_NEAR(mr.y * h, mt.y * h, 1e-3f);
                continue;
            }
            const glm::vec4 pr = texel<glm::vec4>(tex("Raster", "posW"), x, y);
            const glm::vec4 pt = texel<glm::vec4>(tex("RT", "posW"), x, y);
            const glm::vec2 zr = texel<glm::vec2>(tex("Raster", "linearZ"), x, y);
            const glm::vec2 zt = texel<glm::vec2>(tex("RT", "linearZ"), x, y);
            // At grazing angles (depth changing by a large fraction per pixel) ray-plane intersection in float
            // loses digits in both passes; tolerances widen with that relative slope.
            const float grazing = zt.y / std::max(zt.x, 1e-6f);
            EXPECT_NEAR(bitsToFloat(vr.z), bitsToFloat(vt.z), 1e-4f * (1.f + 10.f * grazing));
            EXPECT_NEAR(bitsToFloat(vr.w), bitsToFloat(vt.w), 1e-4f * (1.f + 10.f * grazing));
            EXPECT_TRUE(close4(pr, pt, 1e-4f * zt.x)) << "posW";
            EXPECT_LT(relErr(zr.x, zt.x), 1e-4f);
            EXPECT_TRUE(close4(texel<glm::vec4>(tex("Raster", "faceNormalW"), x, y),
                               texel<glm::vec4>(tex("RT", "faceNormalW"), x, y), 1e-5f))
                << "faceNormalW";
            EXPECT_TRUE(close4(texel<glm::vec4>(tex("Raster", "normW"), x, y),
                               texel<glm::vec4>(tex("RT", "normW"), x, y), 1e-2f))
                << "normW";
            for (const char* c : {"albedo", "specAlbedo", "emission"}) {
                const glm::vec4 a = texel<glm::vec4>(tex("Raster", c), x, y);
                const glm::vec4 b = texel<glm::vec4>(tex("RT", c), x, y);
                EXPECT_TRUE(close4(a, b, 2e-2f * std::max(1.f, glm::length(b)))) << c;
            }
            const glm::vec2 mr = texel<glm::vec2>(tex("Raster", "mvec"), x, y);
            const glm::vec2 mt = texel<glm::vec2>(tex("RT", "mvec"), x, y);
            EXPECT_NEAR(mr.x * w, mt.x * w, 1e-3f);
            EXPECT_NEAR(mr.y * h, mt.y * h, 1e-3f);
            EXPECT_EQ(texel<uint32_t>(tex("Raster", "meshId"), x, y), texel<uint32_t>(tex("RT", "meshId"), x, y));
            // Derivatives: GL's fine dFdx/dFdy difference the pixel with its
            // neighbour in its 2x2 quad (forward in even columns and rows,
            // backward in odd ones), GBufferRT with the next pixel (always
            // forward). Both evaluate the triangle's plane, so the raster's
            // values are checked against the quad differences on the plane.
            const FineDerivatives e = fineDerivatives(*scene, cam, w, h, vr.x, vr.y, x, y);
            const glm::vec2 fr = texel<glm::vec2>(tex("Raster", "pnFwidth"), x, y);
            EXPECT_NEAR(zr.y, e.linearZ, 1e-3f * (1.f + grazing) * e.linearZ + 1e-6f * zt.x) << "linearZ.y";
            EXPECT_NEAR(fr.x, e.pnFwidth.x, 1e-3f * (1.f + grazing) * e.pnFwidth.x + 1e-6f * zt.x) << "pnFwidth.x";
            EXPECT_NEAR(fr.y, e.pnFwidth.y, 1e-3f * e.pnFwidth.y + 1e-4f) << "pnFwidth.y";
        }
    }
    // The bar: the vbuffer names the same triangle on at least 99.5% of pixels.
    std::printf("%s: vbuffer identical on %d of %d pixels (%.3f%%)\n", sceneFile.c_str(), same, int(w * h),
                100.0 * same / double(w * h));
    EXPECT_GE(same, int(0.995 * w * h)) << "differ " << differ;
}

}  // namespace

// The two G-buffer passes are interchangeable: same triangles, same values.
TEST(GBufferRaster, MatchesGBufferRTOnCornellDynamic) {
    compareWithRayTracer("cornell_dynamic.gltf", 1.0, 1.0 + 1.0 / 30.0, glm::vec2(0.2f, -0.35f));
}

TEST(GBufferRaster, MatchesGBufferRTOnCornellBox) {
    compareWithRayTracer("cornell_box.gltf", 0.0, 0.0, glm::vec2(-0.3f, 0.15f));
}

// A node scaled to 0 along one axis has no inverse transform: both passes hide it (Instance::visible), though
// the sphere, flattened along the view axis, would still cover its disc.
TEST(GBufferRaster, MatchesGBufferRTWithAFlattenedInstance) {
    compareWithRayTracer("cornell_dynamic.gltf", 1.0, 1.0, glm::vec2(0.f), "Sphere");
}

TEST(GBufferRaster, MatchesGBufferRTOnMaterials) {
    compareWithRayTracer("materials.gltf", 0.0, 0.0, glm::vec2(0.f));
}

namespace {

/// Runs the loom CLI with a shell prefix (environment), capturing its output.
int runLoom(const std::string& prefix, const std::string& args, std::string& output) {
    const std::string cmd = prefix + " '" + std::string(LOOM_TEST_LOOM_EXE) + "' " + args + " 2>&1 </dev/null";
    FILE* pipe = ::popen(cmd.c_str(), "r");
    if (!pipe) return -1;
    char buffer[4096];
    size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) output.append(buffer, n);
    const int status = ::pclose(pipe);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

// Without a usable EGL (here: GLVND pointed at no vendor library) the run
// fails with a runtime error that names EGL and says what to do.
TEST(GBufferRaster, NoEglIsAClearRuntimeError) {
    const auto out = std::filesystem::temp_directory_path() / ("loom_test_noegl_" + std::to_string(::getpid()));
    std::string output;
    const int code = runLoom("__EGL_VENDOR_LIBRARY_FILENAMES=/nonexistent/vendor.json",
                             "render -q --size 16x16 --graph '" + std::string(LOOM_TEST_SOURCE_DIR) +
                                 "/graphs/GBufferRaster.json' --scene '" + std::string(LOOM_TEST_SOURCE_DIR) +
                                 "/data/scenes/cornell_box.gltf' --out '" + out.string() + "'",
                             output);
    std::filesystem::remove_all(out);
    EXPECT_EQ(code, 1) << output;
    EXPECT_NE(output.find("EGL"), std::string::npos) << output;
    EXPECT_NE(output.find("OpenGL 4.5"), std::string::npos) << output;
    EXPECT_NE(output.find("GBufferRT"), std::string::npos) << output;  // the alternative
}

// meshId is read from vbuffer's attachment when both are consumed: nine
// channels still fit one geometry pass (llvmpipe has 8 draw buffers).
TEST(GBufferRaster, MeshIdSharesVBufferAttachment) {
    auto scene = oneMeshScene(rectMesh(-1.f, -1.f, 1.f, 1.f), plainMaterial(), glm::vec3(0.f, 0.f, -2.f));
    Camera cam = makeCamera();
    auto graph = makeGraph({"posW", "normW", "faceNormalW", "linearZ", "mvec", "albedo", "specAlbedo", "vbuffer",
                            "meshId"});
    graph->execute(FrameInfo{0, 0.0, scene.get(), &cam});
    EXPECT_EQ(graph->lastStats().at("GBuffer").at("geometryPasses"), 1.0);
    EXPECT_EQ(texel<uint32_t>(field(*graph, "meshId"), kW / 2, kH / 2), 0u);
    EXPECT_EQ(texel<uint32_t>(field(*graph, "meshId"), 0, 0), kMissId);
}
