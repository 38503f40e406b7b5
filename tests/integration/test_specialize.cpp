// Specialised kernels (parameter `specialize` of PathTracer, GBufferRT and GBufferRaster): every skip they make is
// exact, so the images with and without are the same bit for bit, frame after frame, on scenes that turn each
// scene feature on and off (textures, alpha-tested emitters, punctual lights, constant and mapped environments,
// animated nodes, camera and emission). Misses end at the primary ray, and a path whose throughput is exactly
// zero traces nothing more. skippedWork says what a scene lets each pass leave out.
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Graph.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

constexpr uint32_t kW = 64, kH = 64;
const char* const kGBufferChannels[] = {"posW",   "normW",      "faceNormalW", "linearZ", "pnFwidth", "mvec",
                                        "albedo", "specAlbedo", "emission",    "vbuffer", "meshId"};

/// A graph of one pass `type` named "P" with params, marking `outputs` (channel names).
std::unique_ptr<RenderGraph> passGraph(const std::string& type, nlohmann::json params,
                                       const std::vector<std::string>& outputs, const std::shared_ptr<Scene>& scene) {
    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "specialize"},
                        {"passes", {{{"name", "P"}, {"type", type}, {"params", params}}}},
                        {"outputs", nlohmann::json::array()}};
    for (const std::string& o : outputs) g["outputs"].push_back("P." + o);
    return test::compiledGraph(g, scene, kW, kH);
}

/// Renders `frames` frames (frame i at time times[i]) with two graphs in lockstep, `specialize` true and false,
/// and checks that every marked output is the same bit for bit each frame, and so are the pass's ray counts.
void expectSameWithAndWithout(const std::shared_ptr<Scene>& scene, const std::string& type, nlohmann::json params,
                              const std::vector<std::string>& outputs, const std::vector<double>& times,
                              const std::string& label) {
    params["specialize"] = true;
    auto on = passGraph(type, params, outputs, scene);
    params["specialize"] = false;
    auto off = passGraph(type, params, outputs, scene);
    for (size_t i = 0; i < times.size(); ++i) {
        scene->update(times[i]);
        scene->camera.aspect = float(kW) / float(kH);
        scene->camera.beginFrame(i);
        const FrameInfo info{i, times[i], scene.get(), &scene->camera};
        on->execute(info);
        off->execute(info);
        for (const std::string& o : outputs)
            EXPECT_TRUE(on->fieldTexture("P." + o)->samePixels(*off->fieldTexture("P." + o)))
                << label << ": P." << o << " differs at frame " << i;
        const auto& statsOn = on->lastStats().at("P");
        if (statsOn.count("rays")) {
            EXPECT_EQ(statsOn.at("rays"), off->lastStats().at("P").at("rays")) << label << ", frame " << i;
        }
    }
}

std::shared_ptr<Scene> shipped(const std::string& name) {
    return Scene::load(test::dataScene(name));
}

/// sky_sphere under an 16 x 8 environment map that varies in both directions.
std::shared_ptr<Scene> skyWithMap() {
    auto s = shipped("sky_sphere.gltf");
    s->environment.width = 16;
    s->environment.height = 8;
    for (uint32_t y = 0; y < 8; ++y)
        for (uint32_t x = 0; x < 16; ++x)
            s->environment.texels.push_back(glm::vec3(0.2f + 0.1f * float(x % 5), 0.3f + 0.2f * float(y % 3), 0.6f));
    return s;
}

std::shared_ptr<Scene> skyWithColour() {
    auto s = shipped("sky_sphere.gltf");
    s->environment.color = glm::vec3(0.5f, 0.6f, 0.8f);
    return s;
}

/// materials.gltf with its emitter alpha-blended (half covered): light samples evaluate the emitter's material.
std::shared_ptr<Scene> materialsWithBlendedEmitter() {
    auto s = shipped("materials.gltf");
    for (Material& m : s->materials)
        if (m.isEmissive()) {
            m.alphaMode = AlphaMode::Blend;
            m.baseColorFactor.a = 0.5f;
        }
    s->finalize();
    return s;
}

const std::vector<double> kStill = {0.0, 1 / 60.0, 2 / 60.0};

}  // namespace

TEST(Specialize, PathTracerImagesAreTheSameBitForBit) {
    const nlohmann::json pt = {{"maxBounces", 3}, {"samplesPerPixel", 2}};
    const std::vector<std::string> color = {"color", "direct", "indirect"};
    // Kernel without optional features: untextured opaque emitters, no environment map.
    expectSameWithAndWithout(shipped("cornell_box.gltf"), "PathTracer", pt, color, kStill, "cornell_box");
    expectSameWithAndWithout(skyWithColour(), "PathTracer", pt, color, kStill, "sky, constant");
    expectSameWithAndWithout(shipped("materials.gltf"), "PathTracer", pt, color, kStill, "materials");
    // The generic kernel: an environment map, an alpha-tested emitter.
    expectSameWithAndWithout(skyWithMap(), "PathTracer", pt, color, kStill, "sky, map");
    expectSameWithAndWithout(materialsWithBlendedEmitter(), "PathTracer", pt, color, kStill, "materials, blend");
    // Animated nodes and camera (light list rebuilt each frame), animated emission (across a light step).
    expectSameWithAndWithout(shipped("cornell_dynamic.gltf"), "PathTracer", pt, color, {0.0, 0.5, 0.52, 1.0},
                             "cornell_dynamic");
    expectSameWithAndWithout(shipped("cornell_lightstep.gltf"), "PathTracer", pt, color, {20 / 60.0, 21 / 60.0},
                             "cornell_lightstep");
    // The per-path (scalar) kernel too.
    nlohmann::json scalar = pt;
    scalar["simdShading"] = false;
    expectSameWithAndWithout(skyWithColour(), "PathTracer", scalar, color, kStill, "sky, scalar");
    expectSameWithAndWithout(skyWithMap(), "PathTracer", scalar, color, kStill, "sky map, scalar");
}

TEST(Specialize, PathTracerIsIdenticalForThreadCounts) {
    for (const auto& make : std::vector<std::function<std::shared_ptr<Scene>()>>{skyWithColour, skyWithMap}) {
        auto render = [&](unsigned threads) {
            ThreadLimit limit(threads);
            auto scene = make();
            auto g = passGraph("PathTracer", {{"samplesPerPixel", 2}}, {"color"}, scene);
            scene->update(0.0);
            scene->camera.aspect = float(kW) / float(kH);
            scene->camera.beginFrame(3);
            g->execute(FrameInfo{3, 0.0, scene.get(), &scene->camera});
            const Texture* c = g->fieldTexture("P.color");
            Texture copy(c->width(), c->height(), c->format());
            copy.copyFrom(*c);
            return copy;
        };
        EXPECT_TRUE(render(1).samePixels(render(2)));
    }
}

// A camera ray that misses ends the path: no light sample, no bounce, only the camera rays are traced.
TEST(Specialize, MissesTraceNothingButTheCameraRay) {
    for (bool specialize : {true, false}) {
        auto scene = skyWithColour();
        // Looking straight up, away from the sphere.
        scene->setCameraPose(
            glm::inverse(glm::lookAt(glm::vec3(0.f, 2.f, 0.f), glm::vec3(0.f, 5.f, 0.f), glm::vec3(0.f, 0.f, -1.f))));
        auto g = passGraph("PathTracer", {{"samplesPerPixel", 4}, {"specialize", specialize}}, {"color"}, scene);
        scene->update(0.0);
        scene->camera.aspect = float(kW) / float(kH);
        g->execute(FrameInfo{0, 0.0, scene.get(), &scene->camera});
        EXPECT_EQ(g->lastStats().at("P").at("rays"), double(kW * kH));
        // And what the camera sees is the environment.
        const auto c = g->fieldTexture("P.color")->view<glm::vec4>();
        EXPECT_EQ(glm::vec3(c.at(7, 9)), scene->environment.color);
    }
}

// A black surface without a specular lobe reflects nothing: its paths end at the first hit, with no shadow ray
// (the BRDF is 0 toward every light) and no bounce (the throughput is exactly 0), however long they may be.
TEST(Specialize, PathsStopWhenTheirThroughputIsZero) {
    for (bool simd : {true, false}) {
        auto scene = skyWithColour();
        scene->materials[0].baseColorFactor = glm::vec4(0.f, 0.f, 0.f, 1.f);
        scene->materials[0].specularFactor = 0.f;
        scene->finalize();
        ASSERT_TRUE(scene->features().diffuseOnly);
        auto g = passGraph("PathTracer", {{"maxBounces", 8}, {"rrStartBounce", 64}, {"simdShading", simd}}, {"color"},
                           scene);
        scene->update(0.0);
        scene->camera.aspect = float(kW) / float(kH);
        g->execute(FrameInfo{0, 0.0, scene.get(), &scene->camera});
        EXPECT_EQ(g->lastStats().at("P").at("rays"), double(kW * kH)) << "simd " << simd;
    }
}

TEST(Specialize, GBufferRTChannelsAreTheSameBitForBit) {
    const std::vector<std::string> all(std::begin(kGBufferChannels), std::end(kGBufferChannels));
    expectSameWithAndWithout(shipped("cornell_box.gltf"), "GBufferRT", {}, all, kStill, "cornell_box");
    expectSameWithAndWithout(shipped("materials.gltf"), "GBufferRT", {}, all, kStill, "materials");
    expectSameWithAndWithout(shipped("cornell_dynamic.gltf"), "GBufferRT", {}, all,
                             {0.0, 0.5, 0.52, 1.0, 4.5, 4.6, 4.7}, "cornell_dynamic");
}

TEST(Specialize, GBufferRasterChannelsAreTheSameBitForBit) {
    const std::vector<std::string> all(std::begin(kGBufferChannels), std::end(kGBufferChannels));
    expectSameWithAndWithout(shipped("cornell_box.gltf"), "GBufferRaster", {}, all, kStill, "cornell_box");
    expectSameWithAndWithout(materialsWithBlendedEmitter(), "GBufferRaster", {}, all, kStill, "materials, blend");
    expectSameWithAndWithout(shipped("cornell_dynamic.gltf"), "GBufferRaster", {}, all,
                             {0.0, 0.5, 0.52, 1.0, 4.5, 4.6, 4.7}, "cornell_dynamic");
}

TEST(Specialize, SkippedWorkFollowsTheScene) {
    auto lines = [](const std::shared_ptr<Scene>& scene, const std::string& type, bool specialize) {
        auto g = passGraph(type, {{"specialize", specialize}}, {type == "PathTracer" ? "color" : "posW"}, scene);
        scene->update(0.0);
        scene->camera.aspect = float(kW) / float(kH);
        g->execute(FrameInfo{0, 0.0, scene.get(), &scene->camera});
        return g->pass("P")->skippedWork();
    };
    auto mentions = [](const std::vector<std::string>& l, const std::string& what) {
        return std::any_of(l.begin(), l.end(), [&](const std::string& s) { return s.rfind(what, 0) == 0; });
    };
    const auto box = lines(shipped("cornell_box.gltf"), "PathTracer", true);
    EXPECT_TRUE(mentions(box, "environment map lookups"));
    EXPECT_TRUE(mentions(box, "per-frame light list"));
    EXPECT_TRUE(mentions(box, "punctual-light sampling"));
    EXPECT_FALSE(mentions(box, "emissive-triangle sampling"));
    const auto sky = lines(skyWithMap(), "PathTracer", true);
    EXPECT_FALSE(mentions(sky, "environment map lookups"));
    EXPECT_TRUE(mentions(sky, "emissive-triangle sampling"));
    EXPECT_FALSE(mentions(sky, "punctual-light sampling"));
    EXPECT_FALSE(mentions(lines(shipped("cornell_dynamic.gltf"), "PathTracer", true), "per-frame light list"));
    EXPECT_TRUE(lines(shipped("cornell_box.gltf"), "PathTracer", false).empty());
    for (const char* type : {"GBufferRT", "GBufferRaster"}) {
        EXPECT_TRUE(mentions(lines(shipped("cornell_box.gltf"), type, true), "previous positions")) << type;
        EXPECT_FALSE(mentions(lines(shipped("cornell_dynamic.gltf"), type, true), "previous positions")) << type;
        EXPECT_TRUE(lines(shipped("cornell_box.gltf"), type, false).empty()) << type;
    }
    for (const std::string& l : box) EXPECT_NE(l.find(": "), std::string::npos) << l;  // "what: why"
    // Before the first frame (as loom check asks), the scene's features alone decide.
    const auto before = passGraph("PathTracer", {{"specialize", true}}, {"color"}, shipped("cornell_box.gltf"));
    const auto early = before->pass("P")->skippedWork();
    EXPECT_TRUE(mentions(early, "punctual-light sampling"));
    EXPECT_TRUE(mentions(early, "environment sampling"));
    EXPECT_TRUE(mentions(early, "per-frame light list"));
    EXPECT_FALSE(mentions(early, "emissive-triangle sampling"));
}
