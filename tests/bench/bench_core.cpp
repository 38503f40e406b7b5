// Core benchmarks: compiling a 100-pass graph, and the per-frame scheduling
// overhead of a 10-pass graph of no-op passes.
#include <benchmark/benchmark.h>

#include "loom/RenderGraph.h"

using namespace loom;

namespace {

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

/// A chain of n passes: Pattern -> Blur -> Blur ... (explicit edges).
GraphDesc chainGraph(int n, const std::string& type) {
    GraphDesc g;
    g.name = "chain";
    g.passes.push_back({"P0", type == "NoOp" ? "NoOp" : "Pattern", nlohmann::json::object()});
    for (int i = 1; i < n; ++i) {
        g.passes.push_back({"P" + std::to_string(i), type, nlohmann::json::object()});
        std::string out = type == "NoOp" || i == 1 ? "dst" : "dst";
        g.edges.push_back({{"P" + std::to_string(i - 1), out, false}, {"P" + std::to_string(i), "src", false}});
    }
    g.outputs.push_back({"P" + std::to_string(n - 1), "dst", false});
    return g;
}

void BM_Compile100Passes(benchmark::State& state) {
    RenderGraph graph(chainGraph(100, "Blur"), registry());
    CompileOptions o;
    o.width = 1280;
    o.height = 720;
    for (auto _ : state) {
        graph.compile(o);
        benchmark::DoNotOptimize(graph.plan().transientPeakBytes);
    }
    state.counters["passes"] = 100;
}
BENCHMARK(BM_Compile100Passes)->Unit(benchmark::kMillisecond);

void BM_FrameOverhead10NoOp(benchmark::State& state) {
    RenderGraph graph(chainGraph(10, "NoOp"), registry());
    CompileOptions o;
    o.width = 1280;
    o.height = 720;
    graph.compile(o);
    FrameInfo f;
    for (auto _ : state) {
        graph.execute(f);
        ++f.frameIndex;
    }
    state.counters["passes"] = 10;
}
BENCHMARK(BM_FrameOverhead10NoOp)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
