// The shipped denoising graphs at 1280x720 on the animated data Cornell box: milliseconds per frame of every
// pass (median-free mean over the timed frames, after warm-up), and the stage times SVGFPass reports in its
// stats ("ms.*"). The graph files are the ones users run, so the figures are what `loom render` would show.
#include <benchmark/benchmark.h>

#include <map>
#include <string>

#include "loom/Camera.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

void runGraph(benchmark::State& state, const std::string& graphName, uint32_t width, uint32_t height) {
    auto scene = Scene::load(std::string(LOOM_SOURCE_DIR) + "/data/scenes/cornell_dynamic.gltf");
    scene->camera.jitterPattern = JitterPattern::Halton;
    RenderGraph graph(loadGraph(std::string(LOOM_SOURCE_DIR) + "/graphs/" + graphName + ".json"), registry());
    graph.setScene(scene);
    CompileOptions o;
    o.width = width;
    o.height = height;
    graph.compile(o);
    scene->camera.aspect = float(width) / float(height);

    uint64_t frame = 0;
    auto step = [&] {
        const double time = double(frame) / 30.0;
        scene->update(time);
        if (frame == 0) scene->cutMotion();
        scene->camera.beginFrame(frame);
        if (frame == 0) scene->camera.cut();
        graph.execute(FrameInfo{frame, time, scene.get(), &scene->camera});
        ++frame;
    };
    const int warmup = 8;  // SVGF's history fills, so its steady state (no spatial variance estimate) is timed
    for (int i = 0; i < warmup; ++i) step();

    std::map<std::string, double> passMs, stageMs;
    uint64_t timed = 0;
    for (auto _ : state) {
        step();
        for (const auto& t : graph.timings()) passMs[t.name] += t.lastMs;
        for (const auto& [pass, counters] : graph.lastStats())
            for (const auto& [name, value] : counters)
                if (name.rfind("ms.", 0) == 0) stageMs[pass + "." + name] += value;
        ++timed;
    }
    const double megapixels = double(width) * height * 1e-6;
    for (const auto& [name, ms] : passMs) {
        state.counters[name + " ms"] = ms / double(timed);
        state.counters[name + " ms/MP"] = ms / double(timed) / megapixels;
    }
    for (const auto& [name, ms] : stageMs) state.counters[name] = ms / double(timed);
}

void BM_PathTracerSVGF(benchmark::State& s) { runGraph(s, "PathTracerSVGF", 1280, 720); }
void BM_PathTracerSVGFDirectIndirect(benchmark::State& s) { runGraph(s, "PathTracerSVGFDirectIndirect", 1280, 720); }
void BM_PathTracerATrous(benchmark::State& s) { runGraph(s, "PathTracerATrous", 1280, 720); }
BENCHMARK(BM_PathTracerSVGF)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PathTracerSVGFDirectIndirect)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PathTracerATrous)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
