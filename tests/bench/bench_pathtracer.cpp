// PathTracer throughput: paths per second at 1280x720, 1 spp, on the data
// Cornell box, for path lengths 1, 3 and 8. "Path length" L follows the Embree
// tutorial path tracer (the anchor, tools/anchor_embree_pathtracer.sh): light
// transport over paths of up to L + 1 segments, i.e. direct light at up to L
// surface hits. In Loom that is maxBounces = L. Russian roulette is off, as
// in the tutorial. At the last vertex Loom samples lights only (no
// BRDF-sampled ray after it), as the anchor does. BM_PathTracerCuda runs the same on the CUDA backend.
// BM_PathTracerShading weighs the Highway twin of the shading (ShadeSimd) against the per-path functor it mirrors
// (simdShading false), at path length 3 on the Cornell box and on the textured, metallic materials scene.
#include <benchmark/benchmark.h>

#include <string>

#include "loom/Error.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

/// The path tracer on `device` (cpu, cuda, emulated); cuda without a usable device is skipped with the reason.
void runPathTracer(benchmark::State& state, const std::string& device, int pathLength,
                   const std::string& sceneName = "cornell_box", bool simdShading = true) {
    const uint32_t W = 1280, H = 720;
    auto scene = Scene::load(std::string(LOOM_SOURCE_DIR) + "/data/scenes/" + sceneName + ".gltf");
    const std::string graphText = R"({"loom_graph": 1, "passes": [{"name": "PT", "type": "PathTracer", "params":
        {"maxBounces": )" + std::to_string(pathLength) +
                                  R"(, "rrStartBounce": 64, "samplesPerPixel": 1, "simdShading": )" +
                                  (simdShading ? "true" : "false") + R"(, "device": ")" + device +
                                  R"("}}], "outputs": ["PT.color"]})";
    RenderGraph graph(parseGraph(graphText), registry());
    graph.setScene(scene);
    CompileOptions o;
    o.width = W;
    o.height = H;
    try {
        graph.compile(o);
    } catch (const Error& e) {
        state.SkipWithError(e.what());
        return;
    }
    scene->camera.aspect = float(W) / float(H);
    uint64_t frame = 0;
    double rays = 0;
    for (auto _ : state) {
        scene->camera.beginFrame(frame);
        graph.execute(FrameInfo{frame, 0.0, scene.get(), &scene->camera});
        rays += graph.lastStats().at("PT").at("rays");
        ++frame;
    }
    state.counters["paths/s"] = benchmark::Counter(double(W) * H * double(frame), benchmark::Counter::kIsRate);
    state.counters["Mrays/s"] = benchmark::Counter(rays * 1e-6, benchmark::Counter::kIsRate);
    state.counters["rays/path"] = rays / (double(W) * H * double(frame));
}
void BM_PathTracer(benchmark::State& state) {
    runPathTracer(state, "cpu", int(state.range(0)));
}
void BM_PathTracerCuda(benchmark::State& state) {
    runPathTracer(state, "cuda", int(state.range(0)));
}
/// Arg 0: the scene (0 cornell_box, 1 materials); arg 1: simdShading.
void BM_PathTracerShading(benchmark::State& state) {
    runPathTracer(state, "cpu", 3, state.range(0) == 0 ? "cornell_box" : "materials", state.range(1) != 0);
}
BENCHMARK(BM_PathTracer)->Arg(1)->Arg(3)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(3.0);
BENCHMARK(BM_PathTracerShading)
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->ArgNames({"scene", "simd"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(3.0);
// The CUDA backend (scripts/gpu-check.sh); skipped where there is no device. The output is copied to host memory
// every frame, and that copy is in the time.
BENCHMARK(BM_PathTracerCuda)->Arg(1)->Arg(3)->Arg(8)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

}  // namespace

BENCHMARK_MAIN();
