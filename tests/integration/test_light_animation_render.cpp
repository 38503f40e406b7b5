// Rendering an animated light (data/scenes/cornell_lightstep.gltf, whose only light steps between full and a quarter
// intensity): the path tracer is linear in the light, the G-buffers' emission follows it every frame, an
// accumulation restarts at each step (as after a move) and nowhere else, and frames are identical for any thread
// count.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;
using json = nlohmann::json;

namespace {

constexpr uint32_t kW = 64, kH = 64;
constexpr uint32_t kLightMaterial = 3;  // CeilingLightEmitter
// At 60 fps the light dims between frames 20 and 21 and comes back between frames 40 and 41 (data/scenes/README.md).
constexpr uint64_t kFullFrame = 20, kDimFrame = 21;

std::shared_ptr<Scene> lightStepScene() {
    return Scene::load(test::dataScene("cornell_lightstep.gltf"));
}

/// Sets the scene to frame `time`'s state and runs the graph as frame `index` (its random numbers).
void renderFrame(RenderGraph& graph, Scene& scene, uint64_t index, double time, bool first = false) {
    scene.update(time);
    if (first) scene.cutMotion();
    scene.camera.aspect = float(kW) / float(kH);
    scene.camera.beginFrame(index);
    graph.execute(FrameInfo{index, time, &scene, &scene.camera});
}

std::vector<glm::vec4> pixels(const RenderGraph& graph, const std::string& field) {
    const auto v = graph.fieldTexture(field)->view<glm::vec4>();
    std::vector<glm::vec4> out;
    for (uint32_t y = 0; y < v.height; ++y)
        for (uint32_t x = 0; x < v.width; ++x) out.push_back(v.at(x, y));
    return out;
}

json pathTracerGraph(const json& params = json::object()) {
    return {{"loom_graph", 1},
            {"name", "pt"},
            {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", params}}}},
            {"outputs", {"PT.color"}}};
}

json accumulateGraph(bool autoReset) {
    json g = pathTracerGraph();
    g["passes"].push_back({{"name", "Acc"}, {"type", "AccumulatePass"}, {"params", {{"autoReset", autoReset}}}});
    g["edges"] = json::array({json::array({"PT.color", "Acc.src"})});
    g["outputs"] = {"Acc.dst", "PT.color"};
    return g;
}

double stat(const RenderGraph& graph, const std::string& pass, const std::string& name) {
    const auto stats = graph.lastStats();
    const auto p = stats.find(pass);
    if (p == stats.end()) return std::nan("");
    const auto it = p->second.find(name);
    return it == p->second.end() ? std::nan("") : it->second;
}

TEST(LightAnimationRender, PathTracedFrameIsLinearInTheLight) {
    // The scene has no other light: four times the emission gives four times the radiance, with the same random
    // numbers (same frame index), for every light sampling strategy. Scaling by 4, a power of two, is exact in
    // floating point (every product and sum of radiance scales exactly), and the light-selection probabilities are
    // ratios of powers, which do not change: so the frames agree bit for bit. A stale light list or emission would
    // break it.
    auto scene = lightStepScene();
    for (const char* sampling : {"mis", "nee", "bsdf"}) {
        SCOPED_TRACE(sampling);
        auto graph = test::compiledGraph(pathTracerGraph({{"lightSampling", sampling}}), scene, kW, kH);
        renderFrame(*graph, *scene, 7, double(kFullFrame) / 60.0, true);
        const std::vector<glm::vec4> full = pixels(*graph, "PT.color");
        renderFrame(*graph, *scene, 7, double(kDimFrame) / 60.0);
        const std::vector<glm::vec4> dim = pixels(*graph, "PT.color");
        ASSERT_EQ(scene->materials[kLightMaterial].emissiveFactor,
                  scene->materials[kLightMaterial].emissiveColor * 4.25f);
        double lit = 0.0;
        size_t off = 0;
        for (size_t i = 0; i < full.size(); ++i) {
            for (int c = 0; c < 3; ++c) off += !(full[i][c] == 4.f * dim[i][c]);
            lit += double(full[i].x + full[i].y + full[i].z);
        }
        EXPECT_EQ(off, 0u) << "channels that are not exactly 4x the dim frame";
        EXPECT_GT(lit, 0.0);
    }
}

TEST(LightAnimationRender, GBufferEmissionFollowsTheLightEveryFrame) {
    for (const char* type : {"GBufferRT", "GBufferRaster"}) {
        SCOPED_TRACE(type);
        auto scene = lightStepScene();
        const json g = {{"loom_graph", 1},
                        {"name", "gb"},
                        {"passes", {{{"name", "GB"}, {"type", type}}}},
                        {"outputs", {"GB.emission"}}};
        auto graph = test::compiledGraph(g, scene, kW, kH);
        for (uint64_t f : {kFullFrame, kDimFrame, uint64_t(40), uint64_t(41)}) {
            renderFrame(*graph, *scene, f, double(f) / 60.0, f == kFullFrame);
            const glm::vec3 want = scene->materials[kLightMaterial].emissiveFactor;
            size_t lightPixels = 0;
            for (const glm::vec4& e : pixels(*graph, "GB.emission")) {
                if (glm::vec3(e) == glm::vec3(0.f)) continue;
                EXPECT_EQ(glm::vec3(e), want) << "frame " << f;
                ++lightPixels;
            }
            EXPECT_GT(lightPixels, 0u) << "frame " << f;
        }
    }
}

TEST(LightAnimationRender, AccumulationRestartsAtEachStepAndNowhereElse) {
    auto scene = lightStepScene();
    auto graph = test::compiledGraph(accumulateGraph(true), scene, kW, kH);
    const std::vector<float> steps = scene->lightStepTimes();
    for (uint64_t f = 16; f < 48; ++f) {
        renderFrame(*graph, *scene, f, double(f) / 60.0, f == 16);
        // A step between this frame and the last one restarts the mean.
        bool stepped = false;
        for (float t : steps) stepped |= double(f - 1) / 60.0 < t && t <= double(f) / 60.0;
        const double expected = f == 16 || stepped ? 1.0 : 0.0;
        EXPECT_EQ(stat(*graph, "Acc", "reset"), expected) << "frame " << f;
    }
    // Without autoReset nothing after the first frame restarts it.
    auto held = test::compiledGraph(accumulateGraph(false), scene, kW, kH);
    for (uint64_t f = 18; f < 24; ++f) {
        renderFrame(*held, *scene, f, double(f) / 60.0, f == 18);
        EXPECT_EQ(stat(*held, "Acc", "reset"), f == 18 ? 1.0 : 0.0) << "frame " << f;
    }
}

TEST(LightAnimationRender, FramesAcrossAStepAreIdenticalForAnyThreadCount) {
    auto render = [](unsigned threads) {
        ThreadLimit limit(threads);
        auto scene = lightStepScene();
        auto graph = test::compiledGraph(accumulateGraph(true), scene, kW, kH);
        std::vector<glm::vec4> all;
        for (uint64_t f = 18; f < 24; ++f) {
            renderFrame(*graph, *scene, f, double(f) / 60.0, f == 18);
            for (const char* field : {"PT.color", "Acc.dst"}) {
                const std::vector<glm::vec4> p = pixels(*graph, field);
                all.insert(all.end(), p.begin(), p.end());
            }
        }
        return all;
    };
    const std::vector<glm::vec4> one = render(1), two = render(2), three = render(3);
    ASSERT_EQ(one.size(), two.size());
    EXPECT_EQ(std::memcmp(one.data(), two.data(), one.size() * sizeof(glm::vec4)), 0);
    EXPECT_EQ(std::memcmp(one.data(), three.data(), one.size() * sizeof(glm::vec4)), 0);
}

}  // namespace
