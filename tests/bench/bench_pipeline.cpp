// The shipped denoising graphs at 1280x720 on the animated data Cornell box: milliseconds per frame of every
// pass (median-free mean over the timed frames, after warm-up), and the stage times SVGFPass reports in its
// stats ("ms.*"). The graph files are the ones users run, so the figures are what `loom render` would show.
#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <string>

#include "loom/Camera.h"
#include "loom/PageMemory.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

/// A shipped graph on its own copy of the animated scene, stepped one frame at a time.
struct Pipeline {
    std::shared_ptr<Scene> scene;
    std::unique_ptr<RenderGraph> graph;
    uint64_t frame = 0;

    Pipeline(const std::string& graphName, uint32_t width, uint32_t height) {
        scene = Scene::load(std::string(LOOM_SOURCE_DIR) + "/data/scenes/cornell_dynamic.gltf");
        scene->camera.jitterPattern = JitterPattern::Halton;
        graph = std::make_unique<RenderGraph>(
            loadGraph(std::string(LOOM_SOURCE_DIR) + "/graphs/" + graphName + ".json"), registry());
        graph->setScene(scene);
        CompileOptions o;
        o.width = width;
        o.height = height;
        graph->compile(o);
        scene->camera.aspect = float(width) / float(height);
    }
    void step() {
        const double time = double(frame) / 30.0;
        scene->update(time);
        if (frame == 0) scene->cutMotion();
        scene->camera.beginFrame(frame);
        if (frame == 0) scene->camera.cut();
        graph->execute(FrameInfo{frame, time, scene.get(), &scene->camera});
        ++frame;
    }
    void warmUp() {
        // SVGF's history fills, so its steady state (no spatial variance estimate) is timed.
        for (int i = 0; i < 8; ++i) step();
    }
};

/// Adds the last frame's pass times and SVGF stage times ("ms.*") of p to the sums.
void addTimes(const Pipeline& p, std::map<std::string, double>& passMs, std::map<std::string, double>& stageMs) {
    for (const auto& t : p.graph->timings()) passMs[t.name] += t.lastMs;
    for (const auto& [pass, counters] : p.graph->lastStats())
        for (const auto& [name, value] : counters)
            if (name.rfind("ms.", 0) == 0) stageMs[pass + "." + name] += value;
}

void runGraph(benchmark::State& state, const std::string& graphName, uint32_t width, uint32_t height) {
    Pipeline p(graphName, width, height);
    p.warmUp();

    std::map<std::string, double> passMs, stageMs;
    uint64_t timed = 0;
    for (auto _ : state) {
        p.step();
        addTimes(p, passMs, stageMs);
        ++timed;
    }
    const double megapixels = double(width) * height * 1e-6;
    for (const auto& [name, ms] : passMs) {
        state.counters[name + " ms"] = ms / double(timed);
        state.counters[name + " ms/MP"] = ms / double(timed) / megapixels;
    }
    for (const auto& [name, ms] : stageMs) state.counters[name] = ms / double(timed);
}

/// The default graph twice in one process, memory advised against huge pages in one and for them in the other
/// (PageMemory), frames alternating between the two: per-pass times of each ("off" / "on") and their ratio.
void BM_PathTracerSVGFHugePages(benchmark::State& state) {
    const bool saved = PageMemory::hugePages();
    // The allocations happen in compile and in the first frames (SVGF's a-trous planes): warm up under each setting.
    PageMemory::setHugePages(false);
    Pipeline off("PathTracerSVGF", 1280, 720);
    off.warmUp();
    PageMemory::setHugePages(true);
    Pipeline on("PathTracerSVGF", 1280, 720);
    on.warmUp();
    PageMemory::setHugePages(saved);
    std::map<std::string, double> offMs, onMs, offStages, onStages;
    uint64_t timed = 0;
    for (auto _ : state) {
        off.step();
        addTimes(off, offMs, offStages);
        on.step();
        addTimes(on, onMs, onStages);
        ++timed;
    }
    for (const auto& [name, ms] : offMs) {
        state.counters[name + " off"] = ms / double(timed);
        state.counters[name + " on"] = onMs[name] / double(timed);
        state.counters[name + " on/off"] = onMs[name] / ms;
    }
    for (const char* stage : {"SVGF.ms.reproject", "SVGF.ms.atrous"})
        state.counters[std::string(stage) + " on/off"] = onStages[stage] / offStages[stage];
}

void BM_PathTracerSVGF(benchmark::State& s) {
    runGraph(s, "PathTracerSVGF", 1280, 720);
}
void BM_PathTracerSVGFDirectIndirect(benchmark::State& s) {
    runGraph(s, "PathTracerSVGFDirectIndirect", 1280, 720);
}
void BM_PathTracerATrous(benchmark::State& s) {
    runGraph(s, "PathTracerATrous", 1280, 720);
}
BENCHMARK(BM_PathTracerSVGF)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PathTracerSVGFDirectIndirect)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PathTracerATrous)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PathTracerSVGFHugePages)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
