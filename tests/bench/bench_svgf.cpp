// SVGF à-trous benchmarks at 1280x720, 4 levels, 2 threads: the scalar reference kernel and the vectorised fast
// path on a synthetic but realistic frame (a floor, a back wall, two boxes at other depths and orientations, sky
// misses at the top; noisy illumination with per-surface levels and variance).
// BM_AtrousFast/2 reports its time relative to BM_AtrousReference/2 of the same run (the reference runs first).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>
#include <random>
#include <utility>

#include "../../passes/SVGF/Atrous.h"
#include "loom/Parallel.h"
#include "loom/Texture.h"

using namespace loom;
using namespace loom::svgf;

namespace {

constexpr uint32_t kWidth = 1280, kHeight = 720;
constexpr int kIterations = 4;
constexpr unsigned kThreads = 2;

struct Frame {
    Texture linearZ{kWidth, kHeight, Format::RG32F};
    Texture normal{kWidth, kHeight, Format::RGBA32F};
    Texture illum{kWidth, kHeight, Format::RGBA32F};
    Texture dst{kWidth, kHeight, Format::RGBA32F};
    Texture feedback{kWidth, kHeight, Format::RGBA32F};

    Frame() {
        std::mt19937 rng(1234);
        std::uniform_real_distribution<float> u(0.f, 1.f);
        auto z = linearZ.view<glm::vec2>();
        auto n = normal.view<glm::vec4>();
        auto c = illum.view<glm::vec4>();
        for (uint32_t y = 0; y < kHeight; ++y)
            for (uint32_t x = 0; x < kWidth; ++x) {
                const float fx = float(x) / kWidth, fy = float(y) / kHeight;
                float depth = 20.f, slope = 0.02f;
                glm::vec3 normal(0.f, 0.f, 1.f), base(0.7f, 0.7f, 0.7f);
                bool miss = false;
                if (fy > 0.6f) {  // floor, receding
                    depth = 4.f + 12.f * (1.f - fy) / 0.4f;
                    slope = 0.05f * depth;
                    normal = glm::vec3(0.f, 1.f, 0.f);
                    base = glm::vec3(0.5f, 0.45f, 0.4f);
                } else if (fy < 0.12f) {
                    miss = true;
                }
                if (fx > 0.15f && fx < 0.4f && fy > 0.3f && fy < 0.75f) {  // near box, its face turned left
                    depth = 7.f + 3.f * (fx - 0.15f);
                    slope = 0.03f;
                    normal = glm::normalize(glm::vec3(-0.5f, 0.f, 0.87f));
                    base = glm::vec3(0.9f, 0.2f, 0.2f);
                    miss = false;
                } else if (fx > 0.55f && fx < 0.85f && fy > 0.2f && fy < 0.7f) {  // far box, turned right
                    depth = 12.f - 2.f * (fx - 0.55f);
                    slope = 0.025f;
                    normal = glm::normalize(glm::vec3(0.4f, 0.f, 0.92f));
                    base = glm::vec3(0.2f, 0.8f, 0.3f);
                    miss = false;
                }
                normal = glm::normalize(normal + 0.01f * glm::vec3(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
                z.at(x, y) = miss ? glm::vec2(-1.f, 0.f) : glm::vec2(depth, slope);
                n.at(x, y) = glm::vec4(normal, 0.f);
                // Path-traced noise at a few samples per pixel: a heavy-tailed multiplier.
                const float noise = -std::log(std::max(u(rng), 1e-4f));
                c.at(x, y) = glm::vec4(base * noise, 0.5f * noise * noise);
            }
    }
};

Frame& frame() {
    static Frame f;
    return f;
}

double gReferenceMs = 0.0;

void runBenchmark(benchmark::State& state, bool reference) {
    ThreadLimit limit(unsigned(state.range(0)));
    Frame& f = frame();
    AtrousFilter filter;
    AtrousTimings timings, sum, least;
    int frames = 0;
    for (auto _ : state) {
        filter.setGuide(std::as_const(f.linearZ).view<glm::vec2>(), std::as_const(f.normal).view<glm::vec4>());
        filter.run(std::as_const(f.illum).view<glm::vec4>(), f.dst.view<glm::vec4>(), kIterations, AtrousParams{}, 0,
                   f.feedback.view<glm::vec4>(), reference, &timings);
        sum.prepareMs += timings.prepareMs;
        for (int l = 0; l < kIterations; ++l) {
            sum.levelMs[l] += timings.levelMs[l];
            least.levelMs[l] = frames == 0 ? timings.levelMs[l] : std::min(least.levelMs[l], timings.levelMs[l]);
        }
        ++frames;
        benchmark::DoNotOptimize(f.dst.data());
    }
    double total = sum.prepareMs;
    for (int l = 0; l < kIterations; ++l) total += sum.levelMs[l];
    const double msPerFrame = total / frames;
    state.counters["ms_frame"] = msPerFrame;
    state.counters["ms_MP"] = msPerFrame / (double(kWidth) * kHeight * 1e-6);
    state.counters["prep_ms"] = sum.prepareMs / frames;
    // The least time of each level over the frames: the least disturbed by other processes on a busy machine.
    for (int l = 0; l < kIterations; ++l) {
        state.counters["L" + std::to_string(l) + "_ms"] = sum.levelMs[l] / frames;
        state.counters["L" + std::to_string(l) + "_min_ms"] = least.levelMs[l];
    }
    state.SetLabel(reference ? "scalar" : simd::targetName());
    if (reference)
        gReferenceMs = msPerFrame;
    else if (gReferenceMs > 0.0 && state.range(0) == kThreads)
        state.counters["vs_ref"] = msPerFrame / gReferenceMs;
}

void BM_AtrousReference(benchmark::State& state) {
    runBenchmark(state, true);
}
void BM_AtrousFast(benchmark::State& state) {
    runBenchmark(state, false);
}

// Argument: threads. The single-thread run's CPU time is the cost per core, which time slicing on a busy machine
// does not inflate the way it inflates wall-clock time.
BENCHMARK(BM_AtrousReference)->Arg(kThreads)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AtrousFast)->Arg(kThreads)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
