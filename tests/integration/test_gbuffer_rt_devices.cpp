// GBufferRT on the emulated device (its camera rays through the scene's BVH, loom/BvhTraversal.h, by launch2D into
// device memory) against GBufferRT on the CPU (Embree's packets), on the data scenes at 48x32 over a few frames with
// Halton jitter: cornell_dynamic (a moving object: motion vectors) and materials (textures, normal maps, alpha).
//
// The two traversals find the same triangles (the BVH is checked against Embree in tests/unit/test_bvh.cpp), with t
// and barycentrics equal up to float rounding. So:
//   - hit/miss masks are equal everywhere (posW.w, linearZ.x < 0, vbuffer and meshId of misses);
//   - the vbuffer's instance and primitive are equal at every hit pixel, except ties: where the ray meets a shared
//     edge or vertex (barycentrics within 1e-3 of the triangle's border in both answers) at the same point (posW
//     within 1e-4 of the scene's size), both answers are right; at most 2 % of the hits may be ties;
//   - at pixels with the same triangle, the barycentrics within 1e-4 and every float channel within 1e-4 relative
//     (of max(1, |value|)) at >= 99.9 % of them, and within 1e-3 relative at all (measured: every pixel within
//     1e-4, the largest 8.2e-5, a texture's bilinear weights at barycentrics a rounding apart; no ties at 48x32);
//   - the emulated device gives the same bits at 1 and 2 threads.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <memory>
#include <string>
#include <vector>

#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/Graph.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

const char* const kFloatChannels[] = {"posW", "normW",  "faceNormalW", "linearZ", "pnFwidth",
                                      "mvec", "albedo", "specAlbedo",  "emission"};
const char* const kChannels[] = {"posW",   "normW",      "faceNormalW", "linearZ", "pnFwidth", "mvec",
                                 "albedo", "specAlbedo", "emission",    "vbuffer", "meshId"};
constexpr uint32_t kW = 48, kH = 32;

/// GBufferRT with every channel marked as an output, its passes placed on `device`.
std::unique_ptr<RenderGraph> gbufferOn(const std::string& device, const std::shared_ptr<Scene>& scene) {
    GraphDesc g;
    g.name = "gbuffer";
    g.passes.push_back({"GBuffer", "GBufferRT", nlohmann::json::object(), {}});
    for (const char* c : kChannels) g.outputs.push_back({"GBuffer", c, false});
    auto graph = std::make_unique<RenderGraph>(g, test::pluginRegistry());
    graph->setScene(scene);
    CompileOptions o;
    o.width = kW;
    o.height = kH;
    o.device = device;
    graph->compile(o);
    return graph;
}

const Texture& field(const RenderGraph& g, const std::string& channel) {
    const Texture* t = g.fieldTexture("GBuffer." + channel);
    if (!t) throw std::runtime_error("no field GBuffer." + channel);
    return *t;
}

bool onBorder(float u, float v) {
    constexpr float e = 1e-3f;
    return u < e || v < e || 1.f - u - v < e;
}

struct Comparison {
    uint32_t hits = 0, ties = 0, same = 0;
    uint32_t within[9] = {};  ///< per float channel: same-triangle pixels within 1e-4 relative
    double largest[9] = {};   ///< per float channel: the largest relative difference at same-triangle pixels
};

/// Compares one frame's channels of the CPU graph `a` with the emulated graph `b`; fails where masks or triangles
/// differ other than at ties.
Comparison compareFrame(const RenderGraph& a, const RenderGraph& b, float sceneSize, const std::string& where) {
    Comparison c;
    const auto va = field(a, "vbuffer").view<glm::uvec4>(), vb = field(b, "vbuffer").view<glm::uvec4>();
    const auto ma = field(a, "meshId").view<uint32_t>(), mb = field(b, "meshId").view<uint32_t>();
    const auto pa = field(a, "posW").view<glm::vec4>(), pb = field(b, "posW").view<glm::vec4>();
    for (uint32_t y = 0; y < kH; ++y)
        for (uint32_t x = 0; x < kW; ++x) {
            const glm::uvec4 ha = va.at(x, y), hb = vb.at(x, y);
            const bool hitA = ha.x != ~0u, hitB = hb.x != ~0u;
            EXPECT_EQ(hitA, hitB) << where << " pixel " << x << "," << y << ": hit on one device only";
            EXPECT_EQ(pa.at(x, y).w, pb.at(x, y).w) << where << " pixel " << x << "," << y;
            if (hitA != hitB) continue;
            if (!hitA) {
                EXPECT_EQ(ha, hb) << where << " pixel " << x << "," << y;
                EXPECT_EQ(ma.at(x, y), mb.at(x, y)) << where << " pixel " << x << "," << y;
                continue;
            }
            ++c.hits;
            if (ha.x != hb.x || ha.y != hb.y) {
                const float ua = bitsToFloat(ha.z), vA = bitsToFloat(ha.w), ub = bitsToFloat(hb.z),
                            vB = bitsToFloat(hb.w);
                const float apart = glm::length(glm::vec3(pa.at(x, y)) - glm::vec3(pb.at(x, y)));
                EXPECT_TRUE(onBorder(ua, vA) && onBorder(ub, vB) && apart <= 1e-4f * sceneSize)
                    << where << " pixel " << x << "," << y << ": triangles " << ha.x << "/" << ha.y << " and " << hb.x
                    << "/" << hb.y << " are no tie (barycentrics " << ua << "," << vA << " and " << ub << "," << vB
                    << ", " << apart << " apart)";
                ++c.ties;
                continue;
            }
            ++c.same;
            EXPECT_EQ(ma.at(x, y), mb.at(x, y)) << where << " pixel " << x << "," << y;
            EXPECT_NEAR(bitsToFloat(ha.z), bitsToFloat(hb.z), 1e-4f) << where << " pixel " << x << "," << y;
            EXPECT_NEAR(bitsToFloat(ha.w), bitsToFloat(hb.w), 1e-4f) << where << " pixel " << x << "," << y;
            for (int k = 0; k < 9; ++k) {
                const Texture &ta = field(a, kFloatChannels[k]), &tb = field(b, kFloatChannels[k]);
                double worst = 0.0;
                for (uint32_t ch = 0; ch < formatInfo(ta.format()).channels; ++ch) {
                    const double u = ta.texel(x, y, ch), v = tb.texel(x, y, ch);
                    worst = std::max(worst, std::fabs(u - v) / std::max(1.0, std::fabs(u)));
                }
                c.within[k] += worst <= 1e-4 ? 1u : 0u;
                c.largest[k] = std::max(c.largest[k], worst);
            }
        }
    return c;
}

void checkScene(const std::string& name) {
    auto scene = Scene::load(test::dataScene(name));
    scene->camera.jitterPattern = JitterPattern::Halton;
    auto cpu = gbufferOn("cpu", scene);
    auto emulated1 = gbufferOn("emulated", scene), emulated2 = gbufferOn("emulated", scene);
    Comparison total;
    bool moved = false;
    for (uint64_t f = 0; f < 4; ++f) {
        const double time = 0.25 * double(f);
        const FrameInfo frame = cli::sceneFrameAt(scene.get(), f, time, kW, kH, false);
        cpu->execute(frame);
        {
            ThreadLimit one(1);
            emulated1->execute(frame);
        }
        {
            ThreadLimit two(2);
            emulated2->execute(frame);
        }
        const std::string where = name + " frame " + std::to_string(f);
        for (const char* c : kChannels) {
            ASSERT_TRUE(field(*emulated1, c).onHost()) << c << ": fieldTexture gives the host copy";
            EXPECT_TRUE(field(*emulated1, c).samePixels(field(*emulated2, c)))
                << where << " " << c << ": 1 and 2 threads";
        }
        const Comparison c = compareFrame(*cpu, *emulated1, glm::length(scene->bounds().extent()), where);
        total.hits += c.hits;
        total.ties += c.ties;
        total.same += c.same;
        for (int k = 0; k < 9; ++k) {
            total.within[k] += c.within[k];
            total.largest[k] = std::max(total.largest[k], c.largest[k]);
        }
        // The moving object's motion vectors: pixels whose mvec is not the camera's alone show on both devices.
        const auto mv = field(*emulated1, "mvec").view<glm::vec2>();
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) moved = moved || mv.at(x, y) != glm::vec2(0.f);
    }
    EXPECT_GT(total.hits, kW * kH);  // over 4 frames: a scene in view
    EXPECT_LE(total.ties, total.hits / 50) << name;
    for (int k = 0; k < 9; ++k) {
        EXPECT_GE(double(total.within[k]), 0.999 * total.same) << name << " " << kFloatChannels[k];
        EXPECT_LE(total.largest[k], 1e-3) << name << " " << kFloatChannels[k];
    }
    if (name == "cornell_dynamic.gltf") EXPECT_TRUE(moved) << "the moving object's motion vectors";
}

}  // namespace

TEST(GBufferRTDevices, EmulatedMatchesCpuOnTheDynamicCornellBox) {
    checkScene("cornell_dynamic.gltf");
}

TEST(GBufferRTDevices, EmulatedMatchesCpuOnTexturedAlphaTestedMaterials) {
    checkScene("materials.gltf");
}

// The pass declares the emulated device (and cuda where its device file is compiled by nvcc): the graph places it
// there and keeps its fields in device memory.
TEST(GBufferRTDevices, PlacedOnTheEmulatedDevice) {
    auto scene = Scene::load(test::dataScene("cornell_box.gltf"));
    auto g = gbufferOn("emulated", scene);
    bool placed = false;
    for (const PlacedPass& p : g->plan().placement)
        if (p.name == "GBuffer") placed = p.device == DeviceKind::Emulated;
    EXPECT_TRUE(placed);
}
