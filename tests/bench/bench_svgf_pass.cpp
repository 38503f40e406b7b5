// SVGFPass at 1280x720 on synthetic inputs (noisy colour over a G-buffer of two planes and a moving square, so
// reprojection, disocclusion and the short-history variance all run): ms per frame of the whole pass, and each
// stage from the pass's frame stats. Baseline in the same run: temporal = false (the plain edge-avoiding a-trous
// filter, Dammertz et al. 2010, with spatial variance every frame). BM_SVGF_Coverage weighs a frame whose hits cover
// a fifth of it (an object under the sky) against a frame covered in full, the two graphs alternating frame by frame.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <map>
#include <memory>
#include <string>
#include <utility>

#include "loom/Parallel.h"
#include "loom/RenderGraph.h"

using namespace loom;

namespace {

float hash01(uint64_t frame, uint32_t x, uint32_t y) {
    uint32_t h = uint32_t(frame) * 0x9E3779B1u ^ x * 0x85EBCA77u ^ y * 0xC2B2AE3Du;
    h ^= h >> 15;
    h *= 0x2C1B3C6Du;
    h ^= h >> 12;
    h *= 0x297A2D39u;
    h ^= h >> 15;
    return float(h >> 8) / float(1u << 24);
}

/// The SVGF inputs, filled in parallel (its own cost is not part of the SVGF figures: they come from the stats).
/// Parameter `coverage`: the fraction of the frame inside a centred ellipse that holds the hits; outside it every
/// pixel is a miss (sky).
class SyntheticInputs final : public RenderPass {
public:
    void declareParams(ParamList& p) override { p.add("coverage", &mCoverage, 1.f).range(0.0, 1.0); }
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output("color", Format::RGBA32F);
        r.output("albedo", Format::RGBA32F);
        r.output("emission", Format::RGBA32F);
        r.output("linearZ", Format::RG32F);
        r.output("normW", Format::RGBA32F);
        r.output("mvec", Format::RG32F);
        r.output("meshId", Format::R32U);
    }
    void execute(PassContext& ctx) override {
        const auto color = ctx.output("color")->view<glm::vec4>();
        const auto albedo = ctx.output("albedo")->view<glm::vec4>();
        const auto emission = ctx.output("emission")->view<glm::vec4>();
        const auto linearZ = ctx.output("linearZ")->view<glm::vec2>();
        const auto normW = ctx.output("normW")->view<glm::vec4>();
        const auto mvec = ctx.output("mvec")->view<glm::vec2>();
        const auto meshId = ctx.output("meshId")->view<uint32_t>();
        const uint64_t f = ctx.frameIndex();
        const uint32_t w = color.width, h = color.height;
        // An ellipse of the frame's aspect with area coverage * w * h: radius sqrt(coverage / pi) in units of the
        // frame's sides.
        const float radius = std::sqrt(mCoverage / 3.14159265f);
        parallelForPixels(w, h, [&](uint32_t x, uint32_t y) {
            const float u = (float(x) + 0.5f) / float(w) - 0.5f, v = (float(y) + 0.5f) / float(h) - 0.5f;
            if (mCoverage < 1.f && u * u + v * v > radius * radius) {
                albedo.at(x, y) = glm::vec4(0.f);
                emission.at(x, y) = glm::vec4(0.f);
                color.at(x, y) = glm::vec4(0.4f, 0.5f, 0.7f, 1.f);
                linearZ.at(x, y) = glm::vec2(-1.f, 0.f);
                normW.at(x, y) = glm::vec4(0.f);
                mvec.at(x, y) = glm::vec2(0.f);
                meshId.at(x, y) = ~0u;
                return;
            }
            const uint32_t s = w / 64;  // the square: 10 s wide, moving s / 5 pixels a frame
            const uint32_t x0 = s * 5 + (s * f / 5) % (w / 2);
            const bool square = y >= s * 10 && y < s * 20 && x >= x0 && x < x0 + s * 10;
            const glm::vec3 a = ((x / 16 + y / 16) % 2) ? glm::vec3(0.8f, 0.6f, 0.4f) : glm::vec3(0.3f, 0.5f, 0.7f);
            const float n = hash01(f, x, y);
            albedo.at(x, y) = glm::vec4(a, 1.f);
            emission.at(x, y) = glm::vec4(0.f);
            color.at(x, y) = glm::vec4(a * (0.2f + 1.6f * n * n), 1.f);
            linearZ.at(x, y) = square ? glm::vec2(2.f, 0.002f) : glm::vec2(5.f + float(y) * 0.002f, 0.002f);
            normW.at(x, y) = square ? glm::vec4(0.f, 0.6f, 0.8f, 0.f) : glm::vec4(0.f, 0.f, 1.f, 0.f);
            mvec.at(x, y) = square ? glm::vec2(-float(s) / 5.f / float(w), 0.f) : glm::vec2(0.f);
            meshId.at(x, y) = square ? 1u : 0u;
        });
    }

private:
    float mCoverage = 1.f;
};

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    static const bool registered = [] {
        r.registerPass("SyntheticInputs", "SVGF inputs", [] { return std::make_unique<SyntheticInputs>(); });
        return true;
    }();
    (void)registered;
    return r;
}

/// SVGF (4 iterations) over the synthetic inputs at W x 9/16 W, warmed up: past the first frames every pixel outside
/// the moving square has history of 4 frames or more, so the spatial variance runs only where the square uncovers
/// the background (the steady state of a real sequence).
struct SvgfRun {
    RenderGraph graph;
    uint64_t frame = 0;
    std::map<std::string, double> sums, mins;
    int timed = 0;

    SvgfRun(uint32_t W, bool temporal, bool referenceStages, double coverage = 1.0)
        : graph(parseGraph(R"({"loom_graph": 1, "passes": [{"name": "Inputs", "type": "SyntheticInputs",
              "params": {"coverage": )" + std::to_string(coverage) + R"(}},
              {"name": "SVGF", "type": "SVGFPass", "params": {"iterations": 4, "temporal": )" +
                           std::string(temporal ? "true" : "false") + R"(, "referenceStages": )" +
                           std::string(referenceStages ? "true" : "false") + R"(}}], "outputs": ["SVGF.filtered"]})"),
                registry()) {
        CompileOptions o;
        o.width = W;
        o.height = W * 9 / 16;
        graph.compile(o);
        for (; frame < 5; ++frame) graph.execute(FrameInfo{frame, 0.0, nullptr, nullptr});
    }
    /// One timed frame: the pass's stage stats ("ms.*") and its whole time (ms.pass), summed and minimised.
    void step() {
        graph.execute(FrameInfo{frame++, 0.0, nullptr, nullptr});
        std::map<std::string, double> now;
        const auto stats = graph.lastStats();  // by value: keep it alive over the loop
        for (const auto& [name, value] : stats.at("SVGF"))
            if (name.rfind("ms.", 0) == 0) now[name] = value;
        for (const auto& t : graph.timings())
            if (t.name == "SVGF") now["ms.pass"] = t.lastMs;
        for (const auto& [name, value] : now) {
            sums[name] += value;
            mins[name] = timed == 0 ? value : std::min(mins[name], value);
        }
        ++timed;
    }
};

/// Arg 0: temporal (1) or the a-trous-only baseline (0); arg 1: threads (0 = all); arg 2: width (height = 9/16 of it);
/// arg 3: 1 runs the scalar reference stages one after the other (referenceStages), the baseline of the fused path.
/// The single-thread runs at widths 640, 960 and 1280 (ms/MP and the stages per megapixel) show how the cost scales
/// with the frame: planes that fit the last-level cache at 640 but not at 1280 would make the larger frame slower per
/// pixel if a stage were bound by memory.
void BM_SVGF(benchmark::State& state) {
    ThreadLimit limit(unsigned(state.range(1)));
    const uint32_t W = uint32_t(state.range(2));
    SvgfRun run(W, state.range(0) != 0, state.range(3) != 0);
    for (auto _ : state) run.step();
    for (const auto& [name, sum] : run.sums) state.counters[name] = sum / run.timed;
    state.counters["ms/MP"] = run.sums["ms.pass"] / run.timed / (double(W) * (W * 9 / 16) * 1e-6);
}
BENCHMARK(BM_SVGF)
    ->ArgNames({"temporal", "threads", "width", "referenceStages"})
    ->Args({1, 0, 1280, 0})
    ->Args({0, 0, 1280, 0})
    ->Args({1, 1, 1280, 0})
    ->Args({1, 0, 320, 0})
    ->Args({1, 1, 640, 0})
    ->Args({1, 1, 960, 0})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

/// The fused path against the reference stages (referenceStages) on a loaded machine: the two graphs alternate frame
/// by frame, so both see the same load. Counters: ref.* and fused.* (means), min.ref.* and min.fused.* (minima, the
/// least disturbed frames), and ratio = fused / ref of the mean whole-pass time. Arg 0: threads (0 = all).
void BM_SVGF_FusedVsReference(benchmark::State& state) {
    ThreadLimit limit(unsigned(state.range(0)));
    SvgfRun ref(1280, true, true), fused(1280, true, false);
    for (auto _ : state) {
        ref.step();
        fused.step();
    }
    auto report = [&](SvgfRun& run, const std::string& prefix) {
        for (const auto& [name, sum] : run.sums) {
            state.counters[prefix + name] = sum / run.timed;
            state.counters["min." + prefix + name] = run.mins[name];
        }
    };
    report(ref, "ref.");
    report(fused, "fused.");
    state.counters["ratio"] = fused.sums["ms.pass"] / ref.sums["ms.pass"];
}
BENCHMARK(BM_SVGF_FusedVsReference)
    ->ArgNames({"threads"})
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

/// A fifth of the frame covered (the rest sky) against all of it, alternating frame by frame at 1280x720: the
/// counters full.ms and part.ms (means of the whole pass) and ratio = part / full. Arg 0: threads (0 = all).
void BM_SVGF_Coverage(benchmark::State& state) {
    ThreadLimit limit(unsigned(state.range(0)));
    SvgfRun full(1280, true, false, 1.0), part(1280, true, false, 0.2);
    for (auto _ : state) {
        full.step();
        part.step();
    }
    state.counters["full.ms"] = full.sums["ms.pass"] / full.timed;
    state.counters["part.ms"] = part.sums["ms.pass"] / part.timed;
    state.counters["ratio"] = part.sums["ms.pass"] / full.sums["ms.pass"];
}
BENCHMARK(BM_SVGF_Coverage)->ArgNames({"threads"})->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
