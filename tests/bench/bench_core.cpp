// Core benchmarks: compiling a 100-pass graph, compile time against graph size (chains of 1k to 100k passes), and
// the per-frame scheduling overhead of a 10-pass graph of no-op passes.
#include <benchmark/benchmark.h>

#include "loom/Parallel.h"
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

/// Compile time against graph size: creating and compiling chains of 1k to 100k Blur passes at 64x64. The
/// planner is O(n log n) in passes and fields, so the time per pass stays flat as the chain grows.
void BM_CreateAndCompileChain(benchmark::State& state) {
    const GraphDesc desc = chainGraph(int(state.range(0)), "Blur");
    CompileOptions o;
    o.width = 64;
    o.height = 64;
    for (auto _ : state) {
        RenderGraph graph(desc, registry());
        graph.compile(o);
        benchmark::DoNotOptimize(graph.plan().transientPeakBytes);
    }
    state.counters["passes"] = double(state.range(0));
    state.counters["seconds_per_pass"] =
        benchmark::Counter(double(state.range(0)), benchmark::Counter::kIsIterationInvariantRate |
                                                       benchmark::Counter::kInvert);
}
BENCHMARK(BM_CreateAndCompileChain)->Arg(1000)->Arg(10000)->Arg(100000)->Unit(benchmark::kMillisecond);

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

// The cost of denormal arithmetic, and what parallelFor2D's flush-to-zero mode saves: products of small weights
// that land in the denormal range (2^-65 squared, as a variance propagated with squared weights), summed in four
// independent chains; once on the calling thread (the default floating-point mode: each denormal result and input
// takes a microcode assist) and once inside a parallelFor2D task (FTZ and DAZ: flushed to 0). Arg 0: calling thread,
// 1: inside a task.
float denormalSums(float w, int n) {
    float sums[4] = {0.f, 0.f, 0.f, 0.f};
    for (int i = 0; i < n; i += 4)
        for (int k = 0; k < 4; ++k) {
            const float wi = w * (1.f + float((i + k) & 7) * 0x1p-4f);  // ~2^-65: a normal float
            sums[k] += wi * wi * 0x1p20f;                                // wi * wi ~ 2^-130: denormal
        }
    return (sums[0] + sums[1]) + (sums[2] + sums[3]);
}

void BM_DenormalProducts(benchmark::State& state) {
    const bool inTask = state.range(0) != 0;
    volatile float w = 0x1p-65f;
    constexpr int kProducts = 1 << 20;
    float sink = 0.f;
    for (auto _ : state) {
        if (inTask) {
            loom::parallelFor2D(1, 1, [&](const loom::Tile&) { sink += denormalSums(w, kProducts); });
        } else {
            sink += denormalSums(w, kProducts);
        }
    }
    benchmark::DoNotOptimize(sink);
    state.counters["ns_per_product"] = benchmark::Counter(double(state.iterations()) * kProducts,
                                                          benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_DenormalProducts)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The machine's peak rate of 8-wide single-precision FMAs on one core (twelve independent chains, registers only):
// the ceiling for compute-bound filter loops such as SVGF's à-trous taps. Counter: FMA instructions per second.
void BM_FmaThroughput(benchmark::State& state) {
    constexpr int kChains = 12, kRounds = 1 << 16;
    using V8 = float __attribute__((vector_size(32)));
    V8 a[kChains];
    for (int i = 0; i < kChains; ++i) a[i] = V8{} + (1.f + float(i) * 1e-3f);
    const V8 m = V8{} + 0.999999f, c = V8{} + 1e-7f;
    for (auto _ : state) {
        for (int r = 0; r < kRounds; ++r)
            for (int i = 0; i < kChains; ++i) a[i] = a[i] * m + c;  // contracted to one FMA (-ffp-contract=fast)
        benchmark::DoNotOptimize(a);
    }
    state.counters["fma_per_s"] =
        benchmark::Counter(double(state.iterations()) * kRounds * kChains, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_FmaThroughput)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
