// The shipped denoising graphs at 1280x720 on the animated data Cornell box: milliseconds per frame of every
// pass (the mean over the timed frames after warm-up, and the median frame), and the stage times SVGFPass reports in
// its stats ("ms.*"). The graph files are the ones users run, so the figures are what `loom render` would show.
#include <benchmark/benchmark.h>
#include <hwy/targets.h>

#include <algorithm>
#include <functional>
#include <map>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

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
    std::function<void()> beforeStep;  ///< called before each frame (e.g. to choose the vector target)

    /// The shipped graph file graphName; `edit`, when given, changes its description first.
    Pipeline(const std::string& graphName, uint32_t width, uint32_t height,
             const std::function<void(GraphDesc&)>& edit = {}) {
        scene = Scene::load(std::string(LOOM_SOURCE_DIR) + "/data/scenes/cornell_dynamic.gltf");
        scene->camera.jitterPattern = JitterPattern::Halton;
        GraphDesc desc = loadGraph(std::string(LOOM_SOURCE_DIR) + "/graphs/" + graphName + ".json");
        if (edit) edit(desc);
        graph = std::make_unique<RenderGraph>(std::move(desc), registry());
        graph->setScene(scene);
        CompileOptions o;
        o.width = width;
        o.height = height;
        graph->compile(o);
        scene->camera.aspect = float(width) / float(height);
    }
    void step() {
        if (beforeStep) beforeStep();
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

/// Each pass's time in every frame.
using FrameTimes = std::map<std::string, std::vector<double>>;

double sum(const std::vector<double>& v) {
    return std::accumulate(v.begin(), v.end(), 0.0);
}

/// Appends the last frame's pass times of p and adds its SVGF stage times ("ms.*") to the sums.
void addTimes(const Pipeline& p, FrameTimes& passMs, std::map<std::string, double>& stageMs) {
    for (const auto& t : p.graph->timings()) passMs[t.name].push_back(t.lastMs);
    for (const auto& [pass, counters] : p.graph->lastStats())
        for (const auto& [name, value] : counters)
            if (name.rfind("ms.", 0) == 0) stageMs[pass + "." + name] += value;
}

void runGraph(benchmark::State& state, const std::string& graphName, uint32_t width, uint32_t height) {
    Pipeline p(graphName, width, height);
    p.warmUp();

    FrameTimes passMs;
    std::map<std::string, double> stageMs;
    uint64_t timed = 0;
    for (auto _ : state) {
        p.step();
        addTimes(p, passMs, stageMs);
        ++timed;
    }
    const double megapixels = double(width) * height * 1e-6;
    for (auto& [name, times] : passMs) {
        const double mean = sum(times) / double(timed);
        state.counters[name + " ms"] = mean;
        state.counters[name + " ms/MP"] = mean / megapixels;
        // The median frame besides the mean: on a virtual machine a frame now and then runs while the host takes
        // the core away, which the mean carries and the median does not.
        std::nth_element(times.begin(), times.begin() + ptrdiff_t(times.size() / 2), times.end());
        state.counters[name + " ms median"] = times[times.size() / 2];
    }
    for (const auto& [name, ms] : stageMs) state.counters[name] = ms / double(timed);
}

/// Per-pass times of two pipelines stepped alternately frame by frame (so both see the same minutes of the machine),
/// as "<pass> a", "<pass> b" and "<pass> b/a", and the SVGF stages' ratios. Which of the two goes first alternates
/// too: the second of a pair otherwise finds caches and clocks in a different state (a measured bias of up to 5 %).
void compareAlternating(benchmark::State& state, Pipeline& a, Pipeline& b) {
    FrameTimes aMs, bMs;
    std::map<std::string, double> aStages, bStages;
    uint64_t timed = 0;
    for (auto _ : state) {
        for (int i = 0; i < 2; ++i) {
            if ((timed + uint64_t(i)) % 2 == 0) {
                a.step();
                addTimes(a, aMs, aStages);
            } else {
                b.step();
                addTimes(b, bMs, bStages);
            }
        }
        ++timed;
    }
    for (const auto& [name, times] : aMs) {
        const double ms = sum(times), other = sum(bMs[name]);
        state.counters[name + " a"] = ms / double(timed);
        state.counters[name + " b"] = other / double(timed);
        state.counters[name + " b/a"] = other / ms;
    }
    // Every SVGF stage's ratio (reprojection, variance, each level, ...).
    for (const auto& [stage, ms] : aStages)
        if (ms > 0.0) state.counters[stage + " b/a"] = bStages[stage] / ms;
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
    compareAlternating(state, off, on);  // a: without, b: with huge pages
}

/// The default graph as shipped (b: SVGF reads last frame's guides from the G-buffer's @prev outputs) against the
/// same graph without those edges (a: SVGF copies the guides into its own history), frames alternating.
void BM_PathTracerSVGFSharedGuides(benchmark::State& state) {
    Pipeline copies("PathTracerSVGF", 1280, 720, [](GraphDesc& g) {
        std::erase_if(g.edges, [](const EdgeDesc& e) { return e.src.prev && e.dst.pass == "SVGF"; });
    });
    copies.warmUp();
    Pipeline shared("PathTracerSVGF", 1280, 720);
    shared.warmUp();
    compareAlternating(state, copies, shared);
}

/// The default graph twice in one process, frames alternating: a restricted to Highway's AVX2 target, b on the
/// best target the CPU has (AVX-512): what the wider vectors give each pass that dispatches at run time.
void BM_PathTracerSVGFVectorWidth(benchmark::State& state) {
    if (!(hwy::SupportedTargets() & HWY_AVX3)) {
        state.SkipWithError("this CPU has no AVX-512");
        return;
    }
    Pipeline avx2("PathTracerSVGF", 1280, 720), best("PathTracerSVGF", 1280, 720);
    avx2.beforeStep = [] { hwy::SetSupportedTargetsForTest(HWY_AVX2); };
    best.beforeStep = [] { hwy::SetSupportedTargetsForTest(0); };
    avx2.warmUp();
    best.warmUp();
    compareAlternating(state, avx2, best);
    hwy::SetSupportedTargetsForTest(0);
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
BENCHMARK(BM_PathTracerSVGFSharedGuides)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PathTracerSVGFVectorWidth)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
