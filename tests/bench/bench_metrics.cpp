// The image metrics at 1280x720 (docs/BENCHMARKS.md, "Metrics"), with a copy of one RGBA32F frame as the
// baseline measured in the same run. Argument: threads (0 = all cores).
#include <benchmark/benchmark.h>

#include <cmath>
#include <glm/glm.hpp>

#include "loom/Metrics.h"
#include "loom/Parallel.h"

using namespace loom;

namespace {

constexpr uint32_t kWidth = 1280, kHeight = 720;
constexpr double kMegapixels = double(kWidth) * kHeight / 1e6;

/// An HDR frame with structure and per-pixel noise; `seed` changes the noise.
Texture frame(uint32_t seed) {
    Texture t(kWidth, kHeight, Format::RGBA32F);
    auto v = t.view<glm::vec4>();
    for (uint32_t y = 0; y < kHeight; ++y)
        for (uint32_t x = 0; x < kWidth; ++x) {
            const uint32_t h = (x * 73856093u) ^ (y * 19349663u) ^ (seed * 83492791u);
            const float noise = float(h % 1024u) / 1024.f;
            const float base = 0.6f + 0.5f * std::sin(0.05f * float(x)) * std::cos(0.031f * float(y));
            v.at(x, y) = glm::vec4(base * (0.8f + 0.4f * noise), base * 0.6f, 1.2f - base, 1.f);
        }
    return t;
}

const Texture& reference() {
    static const Texture t = frame(0);
    return t;
}
const Texture& test() {
    static const Texture t = frame(1);
    return t;
}

template <class Fn>
void run(benchmark::State& state, Fn&& fn) {
    ThreadLimit limit(unsigned(state.range(0)));
    for (auto _ : state) benchmark::DoNotOptimize(fn());
    // Seconds per iteration divided by (MP / 1000): milliseconds per megapixel.
    state.counters["ms_per_MP"] = benchmark::Counter(
        kMegapixels / 1e3, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_CopyFrame(benchmark::State& state) {
    Texture dst(kWidth, kHeight, Format::RGBA32F);
    run(state, [&] {
        dst.copyFrom(test());
        return dst.data();
    });
}
void BM_RelMSE(benchmark::State& state) {
    run(state, [] { return relMSE(test(), reference()).value; });
}
void BM_SMAPE(benchmark::State& state) {
    run(state, [] { return smape(test(), reference()).value; });
}
void BM_PSNR(benchmark::State& state) {
    run(state, [] { return psnr(test(), reference()).value; });
}
void BM_SSIM(benchmark::State& state) {
    run(state, [] { return ssim(test(), reference()).value; });
}
void BM_FLIP(benchmark::State& state) {
    run(state, [] { return flip(test(), reference()).value; });
}
void BM_FLIPWithErrorImage(benchmark::State& state) {
    Texture map(kWidth, kHeight, Format::R32F);
    run(state, [&] { return flip(test(), reference(), &map).value; });
}
void BM_TemporalError(benchmark::State& state) {
    run(state, [] { return temporalError(test(), reference(), reference(), test()).value; });
}
void BM_FlickerAdd(benchmark::State& state) {
    FlickerAccumulator acc;
    run(state, [&] {
        acc.add(test());
        return acc.frames();
    });
}

}  // namespace

#define LOOM_METRIC_BENCH(name) BENCHMARK(name)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime()
LOOM_METRIC_BENCH(BM_CopyFrame);
LOOM_METRIC_BENCH(BM_RelMSE);
LOOM_METRIC_BENCH(BM_SMAPE);
LOOM_METRIC_BENCH(BM_PSNR);
LOOM_METRIC_BENCH(BM_SSIM);
LOOM_METRIC_BENCH(BM_FLIP);
LOOM_METRIC_BENCH(BM_FLIPWithErrorImage);
LOOM_METRIC_BENCH(BM_TemporalError);
LOOM_METRIC_BENCH(BM_FlickerAdd);

BENCHMARK_MAIN();
