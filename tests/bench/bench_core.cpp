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
    g.passes.push_back({"P0", type == "NoOp" ? "NoOp" : "Pattern", nlohmann::json::object(), {}});
    for (int i = 1; i < n; ++i) {
        g.passes.push_back({"P" + std::to_string(i), type, nlohmann::json::object(), {}});
        g.edges.push_back({{"P" + std::to_string(i - 1), "dst", false}, {"P" + std::to_string(i), "src", false}});
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

/// From a graph description to a runnable plan: creating 100 passes
/// (parameters applied) and the first compile, with fresh memory.
void BM_CreateAndCompile100Passes(benchmark::State& state) {
    const GraphDesc desc = chainGraph(100, "Blur");
    CompileOptions o;
    o.width = 1280;
    o.height = 720;
    for (auto _ : state) {
        RenderGraph graph(desc, registry());
        graph.compile(o);
        benchmark::DoNotOptimize(graph.plan().transientPeakBytes);
    }
    state.counters["passes"] = 100;
}
BENCHMARK(BM_CreateAndCompile100Passes)->Unit(benchmark::kMillisecond);

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
