// TAAPass and ToneMap at 1280x720: the time of the pass itself (the graph's per-pass timing, reported as manual
// time), with a copy of one RGBA32F frame and the TAA reference kernel as baselines measured in the same run.
#include <benchmark/benchmark.h>
#include <hwy/targets.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <glm/glm.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Texture.h"

using namespace loom;

namespace {

constexpr uint32_t kWidth = 1280, kHeight = 720;
constexpr double kMegapixels = double(kWidth) * kHeight / 1e6;

/// Writes "color" (an HDR texture with noise; with `sky`, its top 45 % one black colour) and "mvec" once, on its first
/// frame: the benchmarks time the consumer only.
class BenchSource final : public RenderPass {
public:
    explicit BenchSource(bool moving, bool sky = false) : mMoving(moving), mSky(sky) {}
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output("color", Format::RGBA32F);
        r.output("mvec", Format::RG32F);
    }
    void execute(PassContext& ctx) override {
        if (mWritten) return;
        mWritten = true;
        auto c = ctx.output("color")->view<glm::vec4>();
        auto m = ctx.output("mvec")->view<glm::vec2>();
        for (uint32_t y = 0; y < c.height; ++y)
            for (uint32_t x = 0; x < c.width; ++x) {
                const uint32_t h = (x * 73856093u) ^ (y * 19349663u);
                const float noise = float(h % 1024u) / 1024.f;
                const float base = 2.f + 1.5f * std::sin(0.05f * float(x)) * std::cos(0.031f * float(y));
                c.at(x, y) = glm::vec4(base * (0.8f + 0.4f * noise), base * 0.6f, 4.f - base, 1.f);
                if (mSky && y < c.height * 9 / 20) c.at(x, y) = glm::vec4(0.f, 0.f, 0.f, 1.f);
                // A camera pan plus a slow zoom: fractional, varying motion (every pixel takes the bicubic path).
                m.at(x, y) = mMoving ? glm::vec2((1.37f + 0.002f * (float(x) - 640.f)) / float(c.width),
                                                 (0.43f + 0.002f * (float(y) - 360.f)) / float(c.height))
                                     : glm::vec2(0.f);
            }
    }

private:
    bool mMoving, mSky;
    bool mWritten = false;
};

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    static const bool registered = [] {
        r.registerPass("BenchSourceMoving", "bench input", [] { return std::make_unique<BenchSource>(true); });
        r.registerPass("BenchSourceStatic", "bench input", [] { return std::make_unique<BenchSource>(false); });
        r.registerPass("BenchSourceMovingSky", "bench input", [] { return std::make_unique<BenchSource>(true, true); });
        return true;
    }();
    (void)registered;
    return r;
}

std::unique_ptr<RenderGraph> makeGraph(const std::string& source, const std::string& type, const nlohmann::json& params,
                                       const std::string& input, const std::vector<std::string>& outputs) {
    nlohmann::json g = {
        {"loom_graph", 1},
        {"name", "bench_post"},
        {"passes", {{{"name", "Source"}, {"type", source}}, {{"name", "Pass"}, {"type", type}, {"params", params}}}},
        {"edges", nlohmann::json::array({nlohmann::json::array({"Source.color", "Pass." + input})})},
        {"outputs", outputs}};
    auto graph = std::make_unique<RenderGraph>(parseGraph(g.dump()), registry());
    CompileOptions o;
    o.width = kWidth;
    o.height = kHeight;
    graph->compile(o);
    return graph;
}

double passMs(const RenderGraph& graph) {
    for (const auto& t : graph.timings())
        if (t.name == "Pass") return t.lastMs;
    return 0.0;
}

/// Runs the graph's next frame; returns the pass's time.
double runFrame(RenderGraph& graph, uint64_t& frame) {
    FrameInfo f;
    f.frameIndex = frame++;
    f.time = double(f.frameIndex) / 60.0;
    graph.execute(f);
    return passMs(graph);
}

/// Runs frames and reports the pass's own time per frame.
void runFrames(benchmark::State& state, RenderGraph& graph) {
    uint64_t frame = 0;
    for (int i = 0; i < 3; ++i) runFrame(graph, frame);  // warm up: the source writes, history becomes valid
    double totalMs = 0.0;
    for (auto _ : state) {
        const double ms = runFrame(graph, frame);
        totalMs += ms;
        state.SetIterationTime(ms / 1000.0);
    }
    const double msPerFrame = totalMs / double(state.iterations());
    state.counters["ms_per_frame"] = msPerFrame;
    state.counters["ms_per_MP"] = msPerFrame / kMegapixels;
}

/// Baseline: one copy of an RGBA32F frame (what a memory-bound pass that reads and writes a frame once costs).
void BM_CopyFrameRGBA32F(benchmark::State& state) {
    Texture a(kWidth, kHeight, Format::RGBA32F), b(kWidth, kHeight, Format::RGBA32F);
    double totalMs = 0.0;
    for (auto _ : state) {
        const auto t0 = std::chrono::steady_clock::now();
        b.copyFrom(a);
        benchmark::ClobberMemory();
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        totalMs += ms;
        state.SetIterationTime(ms / 1000.0);
    }
    const double msPerFrame = totalMs / double(state.iterations());
    state.counters["ms_per_frame"] = msPerFrame;
    state.counters["ms_per_MP"] = msPerFrame / kMegapixels;
}
BENCHMARK(BM_CopyFrameRGBA32F)->UseManualTime()->Unit(benchmark::kMillisecond);

void BM_TAA(benchmark::State& state) {
    const bool moving = state.range(0) != 0, reference = state.range(1) != 0;
    ThreadLimit limit(unsigned(state.range(2)));
    auto graph = makeGraph(moving ? "BenchSourceMoving" : "BenchSourceStatic", "TAAPass", {{"reference", reference}},
                           "colorIn", {"Pass.colorOut"});
    runFrames(state, *graph);
}
// Args: moving (0/1), reference kernel (0/1), threads (0 = all). With one thread the CPU column is the pass's own
// cost even on a loaded machine.
BENCHMARK(BM_TAA)
    ->Args({1, 0, 0})
    ->Args({0, 0, 0})
    ->Args({1, 1, 0})
    ->Args({1, 0, 1})
    ->Args({0, 0, 1})
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

/// TAA's tiled path restricted to AVX2 against the best target the CPU has (AVX-512 here), frames alternating in one
/// graph (the order swapping every iteration): the same-process comparison of the two. The dispatch is switched
/// through libhwy, which the plugin shares; the pass's vectorLanes stat shows what ran (label: AVX2 lanes vs best).
void BM_TAATargets(benchmark::State& state) {
    const bool moving = state.range(0) != 0;
    ThreadLimit limit(unsigned(state.range(1)));
    auto graph = makeGraph(moving ? "BenchSourceMoving" : "BenchSourceStatic", "TAAPass", nlohmann::json::object(),
                           "colorIn", {"Pass.colorOut"});
    uint64_t frame = 0;
    for (int i = 0; i < 3; ++i) runFrame(*graph, frame);
    double totalMs[2] = {0.0, 0.0}, lanes[2] = {0.0, 0.0};
    bool avx2First = true;
    for (auto _ : state) {
        double ms = 0.0;
        for (int k = 0; k < 2; ++k) {
            const int side = avx2First ? k : 1 - k;  // 0: AVX2, 1: the best target
            hwy::SetSupportedTargetsForTest(side == 0 ? HWY_AVX2 : 0);
            const double t = runFrame(*graph, frame);
            totalMs[side] += t;
            ms += t;
            lanes[side] = graph->lastStats().at("Pass").at("vectorLanes");
        }
        avx2First = !avx2First;
        state.SetIterationTime(ms / 1000.0);
    }
    hwy::SetSupportedTargetsForTest(0);
    const double n = double(state.iterations());
    state.counters["avx2_ms"] = totalMs[0] / n;
    state.counters["best_ms"] = totalMs[1] / n;
    state.counters["best_over_avx2"] = totalMs[1] / totalMs[0];
    state.SetLabel(std::to_string(int(lanes[0])) + " vs " + std::to_string(int(lanes[1])) + " lanes");
}
// Args: moving (0/1), threads (0 = all). One iteration is two frames, one on each target.
BENCHMARK(BM_TAATargets)
    ->Args({1, 0})
    ->Args({0, 0})
    ->Args({1, 1})
    ->Args({0, 1})
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

/// TAA's defaults (the blend in linear colour, which keeps energy) against the luminance-weighted resolve they replaced
/// (antiFlicker and hdrCompress on, the code path of the previous defaults), two graphs whose frames alternate in one
/// process (the order swapping every iteration), so both see the same load.
void BM_TAASettings(benchmark::State& state) {
    const bool moving = state.range(0) != 0;
    ThreadLimit limit(unsigned(state.range(1)));
    const char* source = moving ? "BenchSourceMoving" : "BenchSourceStatic";
    std::unique_ptr<RenderGraph> graphs[2] = {
        makeGraph(source, "TAAPass", nlohmann::json::object(), "colorIn", {"Pass.colorOut"}),
        makeGraph(source, "TAAPass", {{"antiFlicker", true}, {"hdrCompress", true}}, "colorIn", {"Pass.colorOut"})};
    uint64_t frames[2] = {0, 0};
    for (int k = 0; k < 2; ++k)
        for (int i = 0; i < 3; ++i) runFrame(*graphs[k], frames[k]);
    double totalMs[2] = {0.0, 0.0};
    bool defaultsFirst = true;
    for (auto _ : state) {
        double ms = 0.0;
        for (int k = 0; k < 2; ++k) {
            const int side = defaultsFirst ? k : 1 - k;  // 0: defaults, 1: weighted
            const double t = runFrame(*graphs[side], frames[side]);
            totalMs[side] += t;
            ms += t;
        }
        defaultsFirst = !defaultsFirst;
        state.SetIterationTime(ms / 1000.0);
    }
    const double n = double(state.iterations());
    state.counters["linear_ms"] = totalMs[0] / n;
    state.counters["weighted_ms"] = totalMs[1] / n;
    state.counters["linear_over_weighted"] = totalMs[0] / totalMs[1];
}
// Args: moving (0/1), threads (0 = all). One iteration is two frames, one of each graph.
BENCHMARK(BM_TAASettings)
    ->Args({1, 0})
    ->Args({0, 0})
    ->Args({1, 1})
    ->Args({0, 1})
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

/// TAA on a moving frame whose top 45 % is one colour (a black sky, as about half of the default scene's frame): the
/// one-colour tiles take their short path. Arg: threads (0 = all).
void BM_TAASky(benchmark::State& state) {
    ThreadLimit limit(unsigned(state.range(0)));
    auto graph = makeGraph("BenchSourceMovingSky", "TAAPass", nlohmann::json::object(), "colorIn", {"Pass.colorOut"});
    runFrames(state, *graph);
}
BENCHMARK(BM_TAASky)->Arg(0)->Arg(1)->UseManualTime()->Unit(benchmark::kMillisecond);

void BM_ToneMap(benchmark::State& state) {
    const bool autoExposure = state.range(0) != 0, withFloat = state.range(1) != 0;
    ThreadLimit limit(unsigned(state.range(3)));
    std::vector<std::string> outputs = {"Pass.dst"};
    if (withFloat) outputs.push_back("Pass.dstFloat");
    auto graph = makeGraph("BenchSourceStatic", "ToneMap",
                           {{"operator", "aces"}, {"autoExposure", autoExposure}, {"reference", state.range(2) != 0}},
                           "src", outputs);
    runFrames(state, *graph);
}
// Args: auto exposure (0/1), dstFloat consumed (0/1), reference kernel (0/1), threads (0 = all).
BENCHMARK(BM_ToneMap)
    ->Args({1, 0, 0, 0})
    ->Args({0, 0, 0, 0})
    ->Args({1, 1, 0, 0})
    ->Args({1, 0, 1, 0})
    ->Args({1, 0, 0, 1})
    ->UseManualTime()
    ->Unit(benchmark::kMillisecond);

void BM_ToneMapOperator(benchmark::State& state) {
    const char* ops[] = {"linear", "reinhard", "modifiedReinhard", "aces", "hable"};
    auto graph = makeGraph("BenchSourceStatic", "ToneMap", {{"operator", ops[state.range(0)]}, {"autoExposure", true}},
                           "src", {"Pass.dst"});
    state.SetLabel(ops[state.range(0)]);
    runFrames(state, *graph);
}
BENCHMARK(BM_ToneMapOperator)->DenseRange(0, 4)->UseManualTime()->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
