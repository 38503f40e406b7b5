// The graph files shipped in graphs/: each one compiles with a data scene, wires what its name promises, and the
// default graph really denoises (its output is closer to a converged reference than the 1 spp input's).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Camera.h"
#include "loom/Graph.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

std::string graphPath(const std::string& name) { return std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/" + name; }

std::unique_ptr<RenderGraph> compiled(const std::string& file, std::shared_ptr<Scene> scene, uint32_t w,
                                      uint32_t h) {
    auto g = std::make_unique<RenderGraph>(loadGraph(file), test::pluginRegistry());
    g->setScene(std::move(scene));
    CompileOptions o;
    o.width = w;
    o.height = h;
    g->compile(o);
    return g;
}

const Wire* wireTo(const CompiledPlan& plan, const std::string& dst) {
    for (const Wire& w : plan.wires)
        if (w.dst.pass + "." + w.dst.channel == dst) return &w;
    return nullptr;
}

/// Renders `frames` frames (static scene, Halton jitter) and returns the marked 8-bit output of the last one as
/// floats in [0, 1] (RGB).
std::vector<float> renderLast(const std::string& graph, uint64_t firstFrame, uint32_t frames,
                              const std::vector<std::pair<std::string, int>>& intParams = {}) {
    const uint32_t w = 128, h = 128;
    auto scene = Scene::load(test::dataScene("cornell_box.gltf"));
    scene->camera.jitterPattern = JitterPattern::Halton;
    auto g = compiled(graphPath(graph), scene, w, h);
    for (const auto& [name, value] : intParams) {
        const auto dot = name.find('.');
        g->setParam(name.substr(0, dot), name.substr(dot + 1), value, "test");
    }
    for (uint64_t f = firstFrame; f < firstFrame + frames; ++f) {
        scene->update(0.0);
        scene->camera.aspect = 1.f;
        scene->camera.beginFrame(f);
        g->execute(FrameInfo{f, 0.0, scene.get(), &scene->camera});
    }
    const Texture* out = g->fieldTexture(g->outputs().front().str());
    std::vector<float> rgb;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x)
            for (uint32_t c = 0; c < 3; ++c) rgb.push_back(out->texel(x, y, c));
    return rgb;
}

double rmse(const std::vector<float>& a, const std::vector<float>& b) {
    double sum = 0;
    for (size_t i = 0; i < a.size(); ++i) sum += double(a[i] - b[i]) * double(a[i] - b[i]);
    return std::sqrt(sum / double(a.size()));
}

}  // namespace

TEST(ShippedGraphs, EveryGraphCompilesWithADataScene) {
    auto scene = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    int count = 0;
    for (const auto& entry : std::filesystem::directory_iterator(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs")) {
        if (entry.path().extension() != ".json") continue;
        SCOPED_TRACE(entry.path().filename().string());
        EXPECT_NO_THROW(compiled(entry.path().string(), scene, 64, 48));
        ++count;
    }
    EXPECT_GE(count, 9);
}

TEST(ShippedGraphs, DefaultGraphFiltersTheCombinedColourAndTheSplitGraphTheSplit) {
    auto scene = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto combined = compiled(graphPath("PathTracerSVGF.json"), scene, 64, 48);
    EXPECT_EQ(wireTo(combined->plan(), "SVGF.direct"), nullptr);
    EXPECT_EQ(wireTo(combined->plan(), "SVGF.indirect"), nullptr);
    ASSERT_NE(wireTo(combined->plan(), "SVGF.color"), nullptr);
    EXPECT_EQ(wireTo(combined->plan(), "PathTracer.vbuffer")->src.str(), "GBuffer.vbuffer");
    const std::vector<std::string> order = combined->plan().order;
    EXPECT_EQ(order, (std::vector<std::string>{"GBuffer", "PathTracer", "SVGF", "Accumulate", "ToneMap"}));
    EXPECT_EQ(wireTo(combined->plan(), "Accumulate.src")->src.str(), "PathTracer.color");
    EXPECT_EQ(wireTo(combined->plan(), "Accumulate.denoised")->src.str(), "SVGF.filtered");

    auto split = compiled(graphPath("PathTracerSVGFDirectIndirect.json"), scene, 64, 48);
    ASSERT_NE(wireTo(split->plan(), "SVGF.direct"), nullptr);
    EXPECT_EQ(wireTo(split->plan(), "SVGF.direct")->src.str(), "PathTracer.direct");
    EXPECT_EQ(wireTo(split->plan(), "SVGF.indirect")->src.str(), "PathTracer.indirect");

    // Each allocates what its connections use: the indirect signal's fields only with the split, SVGF's own copies of
    // last frame's guides in neither (both feed it the G-buffer's @prev outputs).
    for (const char* field : {"SVGF.illuminationIndirect", "SVGF.momentsIndirect", "SVGF.estimateIndirect"}) {
        EXPECT_EQ(combined->fieldTexture(field), nullptr) << field;
        EXPECT_NE(split->fieldTexture(field), nullptr) << field;
    }
    for (const char* field : {"SVGF.prevLinearZ", "SVGF.prevNormW", "SVGF.prevMeshId"}) {
        EXPECT_EQ(combined->fieldTexture(field), nullptr) << field;
        EXPECT_EQ(split->fieldTexture(field), nullptr) << field;
    }
}

TEST(ShippedGraphs, DefaultGraphIsCloserToTheReferenceThanTheNoisyInput) {
    const uint64_t frames = 16, last = frames - 1;
    // Reference: the same last frame, 512 samples per pixel, through the same tone map.
    const auto reference = renderLast("PathTracerAccumulate.json", last, 1, {{"PathTracer.samplesPerPixel", 512}});
    const auto noisy = renderLast("PathTracerRaw.json", last, 1);
    const auto denoised = renderLast("PathTracerSVGF.json", 0, frames);
    const auto atrous = renderLast("PathTracerATrous.json", 0, frames);
    const double noisyError = rmse(noisy, reference), denoisedError = rmse(denoised, reference),
                 atrousError = rmse(atrous, reference);
    EXPECT_LT(denoisedError, 0.5 * noisyError) << "noisy " << noisyError << ", SVGF " << denoisedError;
    EXPECT_LT(atrousError, noisyError) << "noisy " << noisyError << ", a-trous " << atrousError;
}
