// GBufferRT on the data scenes: geometric consistency of the channels, and
// motion vectors that really lead to the same surface point last frame.
#include <gtest/gtest.h>

#include "TestUtil.h"

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include <glm/glm.hpp>

#include "loom/CameraKernels.h"
#include "loom/Graph.h"
#include "loom/Kernel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

PluginRegistry& registry() { return test::pluginRegistry(); }
std::string scenePath(const std::string& name) { return test::dataScene(name); }

/// A GBufferRT graph marking the given channels.
std::unique_ptr<RenderGraph> gbufferGraph(const std::vector<std::string>& channels, uint32_t w, uint32_t h,
                                          const std::shared_ptr<Scene>& scene) {
    GraphDesc g;
    g.name = "gbuffer";
    g.passes.push_back({"GBuffer", "GBufferRT", nlohmann::json::object(), {}});
    for (const auto& c : channels) g.outputs.push_back({"GBuffer", c, false});
    auto graph = std::make_unique<RenderGraph>(g, registry());
    graph->setScene(scene);
    CompileOptions o;
    o.width = w;
    o.height = h;
    graph->compile(o);
    return graph;
}

void renderFrame(RenderGraph& graph, Scene& scene, uint64_t frame, double time, uint32_t w, uint32_t h) {
    scene.update(time);
    scene.camera.aspect = float(w) / float(h);
    scene.camera.beginFrame(frame);
    graph.execute(FrameInfo{frame, time, &scene, &scene.camera});
}

/// Copies a field so it survives the next frame.
Texture snapshot(const RenderGraph& g, const std::string& field) {
    const Texture* t = g.fieldTexture(field);
    Texture copy(t->width(), t->height(), t->format());
    copy.copyFrom(*t);
    return copy;
}

}  // namespace

// Every hit's posW projects back to its pixel's sample position (jitter
// included), linearZ is its view depth, and the vbuffer's barycentrics
// interpolate the triangle to posW.
TEST(GBufferRT, ChannelsAreGeometricallyConsistent) {
    auto scene = Scene::load(scenePath("cornell_box.gltf"));
    scene->camera.jitterPattern = JitterPattern::Halton;
    const uint32_t W = 96, H = 80;
    auto graph = gbufferGraph({"posW", "linearZ", "vbuffer", "normW", "faceNormalW", "meshId"}, W, H, scene);
    renderFrame(*graph, *scene, 3, 0.0, W, H);
    ASSERT_NE(scene->camera.jitter, glm::vec2(0.f));
    const CameraData cam = makeCameraData(scene->camera, W, H);
    auto posW = graph->fieldTexture("GBuffer.posW")->view<glm::vec4>();
    auto linearZ = graph->fieldTexture("GBuffer.linearZ")->view<glm::vec2>();
    auto vbuffer = graph->fieldTexture("GBuffer.vbuffer")->view<glm::uvec4>();
    auto normW = graph->fieldTexture("GBuffer.normW")->view<glm::vec4>();
    auto faceN = graph->fieldTexture("GBuffer.faceNormalW")->view<glm::vec4>();
    auto meshId = graph->fieldTexture("GBuffer.meshId")->view<uint32_t>();
    int hits = 0, misses = 0;
    for (uint32_t y = 0; y < H; ++y) {
        for (uint32_t x = 0; x < W; ++x) {
            const glm::vec4 p = posW.at(x, y);
            const glm::uvec4 vb = vbuffer.at(x, y);
            if (p.w == 0.f) {
                ++misses;
                EXPECT_EQ(vb, glm::uvec4(0xFFFFFFFFu));
                EXPECT_EQ(meshId.at(x, y), 0xFFFFFFFFu);
                EXPECT_EQ(linearZ.at(x, y).x, -1.f);
                continue;
            }
            ++hits;
            ASSERT_EQ(p.w, 1.f);
            glm::vec2 uv;
            ASSERT_TRUE(clipToUv(cam.viewProj * glm::vec4(glm::vec3(p), 1.f), uv));
            EXPECT_NEAR(uv.x * W, x + 0.5f + cam.jitter.x, 2e-3f) << x << "," << y;
            EXPECT_NEAR(uv.y * H, y + 0.5f + cam.jitter.y, 2e-3f) << x << "," << y;
            EXPECT_NEAR(linearZ.at(x, y).x, glm::dot(glm::vec3(p) - cam.origin, cam.forward), 1e-4f);
            EXPECT_EQ(meshId.at(x, y), vb.x);
            const Instance& inst = scene->instances.at(vb.x);
            const Mesh& mesh = scene->meshes.at(inst.mesh);
            ASSERT_LT(vb.y, mesh.triangleCount());
            const float u = bitsToFloat(vb.z), v = bitsToFloat(vb.w);
            const uint32_t* idx = &mesh.indices[3 * vb.y];
            const glm::vec3 obj = (1.f - u - v) * mesh.positions[idx[0]] + u * mesh.positions[idx[1]] +
                                  v * mesh.positions[idx[2]];
            const glm::vec3 world = glm::vec3(inst.world * glm::vec4(obj, 1.f));
            EXPECT_LT(glm::length(world - glm::vec3(p)), 1e-4f);
            EXPECT_NEAR(glm::length(glm::vec3(normW.at(x, y))), 1.f, 1e-4f);
            EXPECT_NEAR(glm::length(glm::vec3(faceN.at(x, y))), 1.f, 1e-4f);
            // The Cornell box is single-sided and seen from inside: every visible face faces the camera.
            EXPECT_LT(glm::dot(glm::vec3(faceN.at(x, y)), glm::vec3(p) - cam.origin), 0.f);
        }
    }
    EXPECT_GT(hits, int(W * H) / 2);
    EXPECT_GT(misses, 0);  // the open front of the box shows the background at the edges
}

// Following mvec from a pixel lands, in the previous frame's posW, on the
// surface point this pixel shows (moved back by its instance's motion), to
// within half a pixel's footprint, for a moving camera and a moving object.
TEST(GBufferRT, MotionVectorsLeadToTheSameSurfacePointLastFrame) {
    auto scene = Scene::load(scenePath("cornell_dynamic.gltf"));
    const uint32_t W = 128, H = 128;
    auto graph = gbufferGraph({"posW", "mvec", "vbuffer"}, W, H, scene);
    const double t0 = 1.0, t1 = 1.1;  // large motion: a wrong vector lands elsewhere
    renderFrame(*graph, *scene, 0, t0, W, H);
    const Texture prevPos = snapshot(*graph, "GBuffer.posW");
    const Texture prevVb = snapshot(*graph, "GBuffer.vbuffer");
    renderFrame(*graph, *scene, 1, t1, W, H);
    const CameraData cam = makeCameraData(scene->camera, W, H);
    ASSERT_NE(scene->camera.world, scene->camera.prevWorld) << "the camera should move between the frames";

    auto mvec = graph->fieldTexture("GBuffer.mvec")->view<glm::vec2>();
    auto vbuffer = graph->fieldTexture("GBuffer.vbuffer")->view<glm::uvec4>();
    auto pPos = prevPos.view<glm::vec4>();
    auto pVb = prevVb.view<glm::uvec4>();
    int checked = 0, movingChecked = 0, hits = 0;
    for (uint32_t y = 1; y + 1 < H; ++y) {
        for (uint32_t x = 1; x + 1 < W; ++x) {
            const glm::uvec4 vb = vbuffer.at(x, y);
            if (vb.x == 0xFFFFFFFFu) continue;
            ++hits;
            const Instance& inst = scene->instances[vb.x];
            const Mesh& mesh = scene->meshes[inst.mesh];
            const float u = bitsToFloat(vb.z), v = bitsToFloat(vb.w);
            const uint32_t* idx = &mesh.indices[3 * vb.y];
            const glm::vec3 obj = (1.f - u - v) * mesh.positions[idx[0]] + u * mesh.positions[idx[1]] +
                                  v * mesh.positions[idx[2]];
            const glm::vec3 prevPoint = glm::vec3(inst.prevWorld * glm::vec4(obj, 1.f));
            // Where the pixel was last frame, by the motion vector (sample positions, jitter is zero here).
            const glm::vec2 q = (glm::vec2((x + 0.5f) / W, (y + 0.5f) / H) + mvec.at(x, y)) * glm::vec2(W, H);
            const int qx = int(std::floor(q.x)), qy = int(std::floor(q.y));
            if (qx < 0 || qy < 0 || qx >= int(W) || qy >= int(H)) continue;
            // Only where the point was visible last frame: the nearest pixel shows the same triangle.
            const glm::uvec4 pv = pVb.at(uint32_t(qx), uint32_t(qy));
            if (pv.x != vb.x || pv.y != vb.y) continue;
            // The true previous position of this surface point must fall inside pixel (qx, qy), whose
            // centre is within half a pixel of q, i.e. |error| <= 0.5 px in x and y; and what frame 0
            // rendered there is that point's neighbourhood on the same triangle.
            glm::vec2 uvTrue;
            ASSERT_TRUE(clipToUv(cam.prevViewProj * glm::vec4(prevPoint, 1.f), uvTrue));
            const glm::vec2 pixelError = uvTrue * glm::vec2(W, H) - (glm::vec2(qx, qy) + 0.5f);
            EXPECT_LE(std::fabs(pixelError.x), 0.5f + 1e-3f) << x << "," << y;
            EXPECT_LE(std::fabs(pixelError.y), 0.5f + 1e-3f) << x << "," << y;
            // Independent check through frame 0's own render: its posW at that pixel projects to the pixel.
            glm::vec2 uvSeen;
            ASSERT_TRUE(clipToUv(cam.prevViewProj * glm::vec4(glm::vec3(pPos.at(uint32_t(qx), uint32_t(qy))), 1.f),
                                 uvSeen));
            EXPECT_LE(glm::length(uvSeen * glm::vec2(W, H) - uvTrue * glm::vec2(W, H)), 0.71f + 1e-3f);
            ++checked;
            if (inst.world != inst.prevWorld) ++movingChecked;
        }
    }
    // With a wrong motion vector (sign, scale, jitter, the wrong frame's transform) most pixels would land
    // on another triangle; triangle edges and disocclusions account for the few that do not.
    std::printf("motion: %d of %d hits land on their own triangle, %d on moving objects\n", checked, hits,
                movingChecked);
    EXPECT_GT(checked, hits * 85 / 100);
    EXPECT_GT(movingChecked, 50) << "the moving sphere should be covered";
}

// A static scene and camera give zero motion everywhere, jitter or not.
TEST(GBufferRT, StaticSceneHasZeroMotion) {
    auto scene = Scene::load(scenePath("cornell_box.gltf"));
    scene->camera.jitterPattern = JitterPattern::Halton;
    const uint32_t W = 64, H = 64;
    auto graph = gbufferGraph({"mvec"}, W, H, scene);
    renderFrame(*graph, *scene, 0, 0.0, W, H);
    renderFrame(*graph, *scene, 1, 0.1, W, H);
    auto mvec = graph->fieldTexture("GBuffer.mvec")->view<glm::vec2>();
    for (uint32_t y = 0; y < H; ++y)
        for (uint32_t x = 0; x < W; ++x) ASSERT_LT(glm::length(mvec.at(x, y)), 1e-6f) << x << "," << y;
}
