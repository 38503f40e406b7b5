// The à-trous filter of SVGF (passes/SVGF/Atrous.h): the vectorised fast path against the scalar reference kernel
// on images with depth edges, normal creases, misses and borders; constant signals; the closed form of a flat
// region; variance propagation; feedback tap semantics; thread-count independence; bad input.
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <glm/glm.hpp>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "../Atrous.h"
#include "../AtrousSimd.h"
#include "loom/Parallel.h"
#include "loom/Texture.h"

using namespace loom;
using namespace loom::svgf;

namespace {

/// Guides and illumination of one test frame.
struct Frame {
    Texture linearZ, normal, illum;
    uint32_t width = 0, height = 0;

    ImageView<const glm::vec2> z() const { return linearZ.view<glm::vec2>(); }
    ImageView<const glm::vec4> n() const { return normal.view<glm::vec4>(); }
    ImageView<const glm::vec4> signal() const { return illum.view<glm::vec4>(); }
};

/// A frame with real edges: a background wall, a slanted plane in front of it (a depth discontinuity), a normal
/// crease down the middle of the wall, a block of miss pixels and scattered misses; noisy positive illumination
/// whose level differs per surface, and a noisy variance.
Frame makeEdgyFrame(uint32_t w, uint32_t h, uint32_t seed) {
    Frame f;
    f.width = w;
    f.height = h;
    f.linearZ = Texture(w, h, Format::RG32F);
    f.normal = Texture(w, h, Format::RGBA32F);
    f.illum = Texture(w, h, Format::RGBA32F);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    auto z = f.linearZ.view<glm::vec2>();
    auto n = f.normal.view<glm::vec4>();
    auto c = f.illum.view<glm::vec4>();
    for (uint32_t y = 0; y < h; ++y) {
        for (uint32_t x = 0; x < w; ++x) {
            const float fx = float(x) / float(std::max(w, 2u) - 1), fy = float(y) / float(std::max(h, 2u) - 1);
            glm::vec3 normal(0.f, 0.f, 1.f);
            float depth = 10.f, slope = 0.02f;
            glm::vec3 base(0.8f, 0.6f, 0.4f);
            if (fx + fy < 0.9f) {  // the slanted plane in front
                depth = 4.f + 2.f * fx;
                slope = 0.03f;
                normal = glm::normalize(glm::vec3(-0.4f, 0.1f, 1.f));
                base = glm::vec3(0.2f, 0.5f, 0.9f);
            } else if (fx > 0.7f) {  // the wall folds: same depth along the crease, another normal
                normal = glm::normalize(glm::vec3(0.6f, 0.f, 0.8f));
                base = glm::vec3(1.5f, 1.2f, 0.7f);
            }
            // A slightly perturbed normal, as a G-buffer produces from interpolated vertex normals.
            normal = glm::normalize(normal + 0.01f * glm::vec3(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
            const bool miss = (fx > 0.35f && fx < 0.5f && fy > 0.6f && fy < 0.8f) || u(rng) < 0.03f;
            z.at(x, y) = miss ? glm::vec2(-1.f, 0.f) : glm::vec2(depth, slope);
            n.at(x, y) = glm::vec4(normal, 0.f);
            const float noise = 0.5f + u(rng);
            c.at(x, y) = glm::vec4(base * noise * (0.7f + 0.6f * u(rng)), 0.02f + 0.3f * u(rng));
        }
    }
    return f;
}

/// Every pixel on one plane (depth 5, derivative 0.05, normal +z), with illumination from fn.
template <class Fn>
Frame makeFlatFrame(uint32_t w, uint32_t h, Fn&& fn) {
    Frame f;
    f.width = w;
    f.height = h;
    f.linearZ = Texture(w, h, Format::RG32F);
    f.normal = Texture(w, h, Format::RGBA32F);
    f.illum = Texture(w, h, Format::RGBA32F);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            f.linearZ.view<glm::vec2>().at(x, y) = glm::vec2(5.f, 0.05f);
            f.normal.view<glm::vec4>().at(x, y) = glm::vec4(0.f, 0.f, 1.f, 0.f);
            f.illum.view<glm::vec4>().at(x, y) = fn(x, y);
        }
    return f;
}

struct Result {
    Texture dst, feedback;
};

Result runFilter(AtrousFilter& filter, const Frame& f, int iterations, bool reference, int tap = -1,
                 const AtrousParams& params = {}) {
    Result r;
    r.dst = Texture(f.width, f.height, Format::RGBA32F);
    r.feedback = Texture(f.width, f.height, Format::RGBA32F);
    r.dst.poison();
    r.feedback.poison();
    filter.setGuide(f.z(), f.n());
    filter.run(f.signal(), r.dst.view<glm::vec4>(), iterations, params, tap, r.feedback.view<glm::vec4>(), reference);
    return r;
}

Result runFilter(const Frame& f, int iterations, bool reference, int tap = -1, const AtrousParams& params = {}) {
    AtrousFilter filter;
    return runFilter(filter, f, iterations, reference, tap, params);
}

/// Largest relative error |a - b| / (|b| + floor) over every channel of every pixel.
double maxRelativeError(const Texture& a, const Texture& b, double floor = 1e-3) {
    double worst = 0.0;
    for (uint32_t y = 0; y < a.height(); ++y)
        for (uint32_t x = 0; x < a.width(); ++x)
            for (uint32_t ch = 0; ch < 4; ++ch) {
                const double va = a.texel(x, y, ch), vb = b.texel(x, y, ch);
                const double e = std::abs(va - vb) / (std::abs(vb) + floor);
                worst = std::max(worst, std::isfinite(e) ? e : std::numeric_limits<double>::infinity());
            }
    return worst;
}

// The fast path's stated tolerance, relative (values below 1e-3 count as 1e-3). AtrousSimd.h bounds each weight's
// relative error by ~6e-6 (exp polynomial 2.6e-6, normal series 3.2e-6 at phi >= 32); a level's output, a ratio of
// weighted sums, moves by about twice that, and errors add over levels (measured: <= 8e-6 after 5 levels).
constexpr double kTolerance = 3e-5;

}  // namespace

TEST(Atrous, ReferencePathRunsTheReferenceKernel) {
    const Frame f = makeEdgyFrame(40, 30, 1);
    const Result r = runFilter(f, 1, true);
    for (uint32_t y = 0; y < f.height; ++y)
        for (uint32_t x = 0; x < f.width; ++x) {
            const glm::vec4 want = atrousPixel(f.signal(), f.z(), f.n(), int(x), int(y), 1, AtrousParams{});
            ASSERT_EQ(0, std::memcmp(&want, &r.dst.view<glm::vec4>().at(x, y), sizeof want)) << x << "," << y;
        }
}

TEST(Atrous, FastPathAgreesWithReference) {
    const uint32_t sizes[][2] = {{67, 45}, {64, 64}, {1, 1}, {3, 200}, {200, 3}, {17, 9}};
    double worst = 0.0;
    for (const auto& s : sizes) {
        const Frame f = makeEdgyFrame(s[0], s[1], s[0] * 1000 + s[1]);
        for (int iterations = 1; iterations <= 5; ++iterations) {
            const Result fast = runFilter(f, iterations, false, 1);
            const Result ref = runFilter(f, iterations, true, 1);
            const double e = maxRelativeError(fast.dst, ref.dst);
            const double ef = maxRelativeError(fast.feedback, ref.feedback);
            EXPECT_LE(e, kTolerance) << s[0] << "x" << s[1] << " iterations " << iterations;
            EXPECT_LE(ef, kTolerance) << s[0] << "x" << s[1] << " feedback, iterations " << iterations;
            worst = std::max({worst, e, ef});
        }
    }
    RecordProperty("max_relative_error", std::to_string(worst));
    std::printf("fast vs reference: max relative error %.3g\n", worst);
}

TEST(Atrous, FastPathAgreesForOtherParameters) {
    // phiNormal below the series threshold takes the log2 path; a non-integer phi; edge stopping nearly off.
    const Frame f = makeEdgyFrame(67, 45, 7);
    const AtrousParams cases[] = {{10.f, 128.f, 1.f}, {10.f, 33.5f, 1.f},  {4.f, 8.f, 0.5f},   {2.f, 1.5f, 2.f},
                                  {10.f, 0.f, 1.f},   {1e4f, 128.f, 1e3f}, {0.5f, 300.f, 0.2f}};
    for (const AtrousParams& p : cases) {
        const Result fast = runFilter(f, 3, false, -1, p);
        const Result ref = runFilter(f, 3, true, -1, p);
        EXPECT_LE(maxRelativeError(fast.dst, ref.dst), kTolerance)
            << "phiColor " << p.phiColor << " phiNormal " << p.phiNormal << " phiDepth " << p.phiDepth;
    }
}

TEST(Atrous, StepsLargerThanTheImage) {
    // 9 levels: steps up to 256 on a 67x45 frame (beyond the default margins, so the planes are re-laid out).
    const Frame f = makeEdgyFrame(67, 45, 3);
    AtrousFilter filter;
    const Result fast = runFilter(filter, f, 9, false, 7);
    const Result ref = runFilter(f, 9, true, 7);
    EXPECT_LE(maxRelativeError(fast.dst, ref.dst), kTolerance);
    EXPECT_LE(maxRelativeError(fast.feedback, ref.feedback), kTolerance);
    // The same filter object again with fewer levels (the wide layout is kept).
    const Result again = runFilter(filter, f, 2, false);
    EXPECT_LE(maxRelativeError(again.dst, runFilter(f, 2, true).dst), kTolerance);
}

TEST(Atrous, ConstantSignalPassesThrough) {
    const glm::vec4 value(0.3f, 0.5f, 0.7f, 0.2f);
    Frame f = makeEdgyFrame(50, 40, 5);
    auto c = f.illum.view<glm::vec4>();
    for (uint32_t y = 0; y < f.height; ++y)
        for (uint32_t x = 0; x < f.width; ++x) c.at(x, y) = value;
    for (bool reference : {false, true}) {
        const Result r = runFilter(f, 4, reference);
        for (uint32_t y = 0; y < f.height; ++y)
            for (uint32_t x = 0; x < f.width; ++x) {
                const glm::vec4 o = r.dst.view<glm::vec4>().at(x, y);
                // Sums of 25 products over 4 levels: a few dozen float roundings at most.
                for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(o[ch], value[ch], 2e-6f * value[ch]) << x << "," << y;
                // Variance is propagated with squared weights: a constant variance can only shrink.
                ASSERT_LE(o.a, value.a * (1.f + 1e-6f));
                ASSERT_GT(o.a, 0.f);
            }
    }
}

TEST(Atrous, MissPixelsAreUntouched) {
    const Frame f = makeEdgyFrame(67, 45, 9);
    for (bool reference : {false, true}) {
        const Result r = runFilter(f, 4, reference);
        int misses = 0;
        for (uint32_t y = 0; y < f.height; ++y)
            for (uint32_t x = 0; x < f.width; ++x) {
                if (f.z().at(x, y).x >= 0.f) continue;
                ++misses;
                ASSERT_EQ(0, std::memcmp(&f.signal().at(x, y), &r.dst.view<glm::vec4>().at(x, y), sizeof(glm::vec4)));
            }
        EXPECT_GT(misses, 100);
    }
}

TEST(Atrous, IdenticalForOneAndTwoThreads) {
    const Frame f = makeEdgyFrame(131, 77, 11);
    for (bool reference : {false, true}) {
        Result one, two;
        {
            ThreadLimit limit(1);
            one = runFilter(f, 4, reference, 2);
        }
        {
            ThreadLimit limit(2);
            two = runFilter(f, 4, reference, 2);
        }
        EXPECT_TRUE(one.dst.samePixels(two.dst));
        EXPECT_TRUE(one.feedback.samePixels(two.feedback));
    }
}

TEST(Atrous, AVX512AndAVX2GiveTheSameBits) {
    // Both targets run the same arithmetic: AVX-512 forms the weight's power of two with vscalefps (and its mask)
    // instead of exponent-bit arithmetic and a blend, which must not change one bit. Five levels reach every step
    // form; a partial last vector (131 columns) and misses are covered.
    if (!(hwy::SupportedTargets() & HWY_AVX3)) GTEST_SKIP() << "this CPU has no AVX-512";
    const Frame f = makeEdgyFrame(131, 77, 21);
    Result results[2];
    const int64_t targets[2] = {HWY_AVX3, HWY_AVX2};
    const char* names[2] = {"AVX3", "AVX2"};
    for (int i = 0; i < 2; ++i) {
        hwy::SetSupportedTargetsForTest(targets[i]);
        EXPECT_EQ(names[i], simd::targetName());
        results[i] = runFilter(f, 5, false, 2);
    }
    hwy::SetSupportedTargetsForTest(0);  // back to what the CPU has
    EXPECT_TRUE(results[0].dst.samePixels(results[1].dst));
    EXPECT_TRUE(results[0].feedback.samePixels(results[1].feedback));
}

TEST(Atrous, FeedbackTapSemantics) {
    const Frame f = makeEdgyFrame(67, 45, 13);
    for (bool reference : {false, true}) {
        // feedback = output of level k: the dst of a run with k + 1 levels.
        for (int tap = 0; tap < 4; ++tap) {
            const Result r = runFilter(f, 4, reference, tap);
            const Result shorter = runFilter(f, tap + 1, reference);
            EXPECT_TRUE(r.feedback.samePixels(shorter.dst)) << "tap " << tap;
        }
        // A tap past the last level is clamped to it.
        const Result past = runFilter(f, 3, reference, 10);
        EXPECT_TRUE(past.feedback.samePixels(past.dst));
        // A negative tap copies the unfiltered signal; so do both outputs with zero iterations.
        const Result negative = runFilter(f, 3, reference, -1);
        EXPECT_TRUE(negative.feedback.samePixels(f.illum));
        EXPECT_FALSE(negative.dst.samePixels(f.illum));
        const Result none = runFilter(f, 0, reference, 2);
        EXPECT_TRUE(none.dst.samePixels(f.illum));
        EXPECT_TRUE(none.feedback.samePixels(f.illum));
    }
}

TEST(Atrous, FlatRegionIsTheB3SplineClosedForm) {
    // One plane, edge stopping on luminance made negligible (huge phiColor): the level is the normalised B3
    // spline, so in the interior the output is the h-weighted mean of the input and the variance is
    // sum h^2 Var_q; a constant variance v becomes v * (sum_i b_i^2)^2 = v * (70/256)^2.
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::vector<glm::vec4> values(48 * 40);
    for (glm::vec4& v : values) v = glm::vec4(u(rng), u(rng), u(rng), 0.1f);
    const Frame f = makeFlatFrame(48, 40, [&](uint32_t x, uint32_t y) { return values[y * 48 + x]; });
    const AtrousParams params{1e9f, 128.f, 1.f};
    const float b[5] = {1.f / 16.f, 4.f / 16.f, 6.f / 16.f, 4.f / 16.f, 1.f / 16.f};
    for (bool reference : {false, true}) {
        for (int step : {1, 2}) {
            // One level at step 1, or two levels whose second one (step 2) is checked against the first's output.
            const Result first = runFilter(f, 1, reference, -1, params);
            const Result r = runFilter(f, step, reference, 0, params);
            ImageView<const glm::vec4> in = step == 1 ? f.signal() : first.dst.view<glm::vec4>();
            for (uint32_t y = 2 * step; y + 2 * step < f.height; ++y)
                for (uint32_t x = 2 * step; x + 2 * step < f.width; ++x) {
                    glm::vec4 mean(0.f);
                    for (int j = -2; j <= 2; ++j)
                        for (int i = -2; i <= 2; ++i) {
                            const float h = b[i + 2] * b[j + 2];
                            const glm::vec4 q = in.at(x + i * step, y + j * step);
                            mean += glm::vec4(h * glm::vec3(q), h * h * q.a);
                        }
                    const glm::vec4 o = r.dst.view<glm::vec4>().at(x, y);
                    // Float rounding for the reference; the stated tolerance for the fast path (its weights carry
                    // the exp polynomial's error).
                    const float tol = reference ? 2e-6f : float(kTolerance);
                    for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(o[ch], mean[ch], tol * mean[ch]) << x << "," << y;
                    ASSERT_NEAR(o.a, mean.a, tol * mean.a);
                    if (step == 1) {
                        ASSERT_NEAR(o.a, 0.1f * std::pow(70.f / 256.f, 2.f), tol * mean.a);
                    }
                }
        }
    }
}

TEST(Atrous, VarianceDoesNotGrowOnAFlatRegion) {
    // Edge stopping on (noisy luminance), constant input variance: sum w^2 v / (sum w)^2 <= v for any w >= 0.
    std::mt19937 rng(19);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const Frame f = makeFlatFrame(64, 64, [&](uint32_t, uint32_t) { return glm::vec4(u(rng), u(rng), u(rng), 0.05f); });
    for (bool reference : {false, true}) {
        for (int iterations = 1; iterations <= 4; ++iterations) {
            const Result r = runFilter(f, iterations, reference);
            for (uint32_t y = 0; y < f.height; ++y)
                for (uint32_t x = 0; x < f.width; ++x) {
                    const float v = r.dst.view<glm::vec4>().at(x, y).a;
                    ASSERT_LE(v, 0.05f * (1.f + 1e-6f));
                    ASSERT_GT(v, 0.f);
                }
        }
    }
}

TEST(Atrous, BadInputStaysFinite) {
    Frame f = makeEdgyFrame(40, 30, 23);
    const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
    auto c = f.illum.view<glm::vec4>();
    auto z = f.linearZ.view<glm::vec2>();
    auto n = f.normal.view<glm::vec4>();
    c.at(3, 3) = glm::vec4(nan, 1.f, inf, -inf);
    c.at(10, 12) = glm::vec4(3e38f, 3e38f, 3e38f, 3e38f);
    z.at(20, 5) = glm::vec2(nan, nan);
    z.at(21, 5) = glm::vec2(5.f, inf);
    z.at(22, 5) = glm::vec2(inf, -1.f);
    n.at(30, 20) = glm::vec4(nan, 0.f, inf, 0.f);
    n.at(31, 20) = glm::vec4(0.f);
    const Result r = runFilter(f, 5, false, 2);
    for (uint32_t y = 0; y < f.height; ++y)
        for (uint32_t x = 0; x < f.width; ++x)
            for (int ch = 0; ch < 4; ++ch) {
                ASSERT_TRUE(std::isfinite(r.dst.view<glm::vec4>().at(x, y)[ch])) << x << "," << y;
                ASSERT_TRUE(std::isfinite(r.feedback.view<glm::vec4>().at(x, y)[ch])) << x << "," << y;
            }
}

// Normals that are not unit length (a cosine above 1) with sharp normal stopping: the reference's power of the
// cosine overflowed (Inf / Inf). Both paths cap the cosine at 1.01 and stay finite; unit normals are unaffected.
TEST(Atrous, NonUnitNormalsStayFiniteOnBothPaths) {
    Frame f = makeEdgyFrame(40, 30, 29);
    auto n = f.normal.view<glm::vec4>();
    for (uint32_t y = 20; y < 26; ++y)
        for (uint32_t x = 4; x < 12; ++x) n.at(x, y) = glm::vec4(0.f, 0.f, x % 2 ? 2.f : 1e3f, 0.f);
    AtrousParams sharp;
    sharp.phiNormal = 1e3f;
    for (const bool reference : {false, true})
        for (const AtrousParams& p : {AtrousParams{}, sharp}) {
            const Result r = runFilter(f, 5, reference, 2, p);
            for (uint32_t y = 0; y < f.height; ++y)
                for (uint32_t x = 0; x < f.width; ++x)
                    for (int ch = 0; ch < 4; ++ch) {
                        ASSERT_TRUE(std::isfinite(r.dst.view<glm::vec4>().at(x, y)[ch]))
                            << x << "," << y << " reference " << reference << " phiNormal " << p.phiNormal;
                        ASSERT_TRUE(std::isfinite(r.feedback.view<glm::vec4>().at(x, y)[ch]))
                            << x << "," << y << " reference " << reference << " phiNormal " << p.phiNormal;
                    }
        }
}

// The level addresses every plane of a tap from two pointers and the plane spacing, so it refuses planes that do
// not lie planeSize() apart instead of reading the wrong memory; the allocator's own layout passes the check.
TEST(Atrous, LevelRefusesPlanesNotEvenlySpaced) {
    const simd::PlaneLayout layout = simd::makeLayout(40, 8, 2);
    const size_t P = layout.planeSize();
    std::vector<float> block(15 * P, 0.f), stray(P, 0.f);
    float* base = block.data();
    const simd::GuidePlanes guide{base, base + P, base + 2 * P, base + 3 * P, base + 4 * P};
    const simd::SignalPlanes in{base + 5 * P, base + 6 * P, base + 7 * P, base + 8 * P, base + 9 * P};
    simd::LevelOutputs out;
    out.planes = {base + 10 * P, base + 11 * P, base + 12 * P, base + 13 * P, base + 14 * P};
    EXPECT_TRUE(simd::planesEvenlySpaced(layout, guide, in));
    std::fill(guide.z, guide.z + P, -1.f);  // misses everywhere: nothing to weigh, the input is copied
    EXPECT_NO_THROW(simd::filterLevel(layout, guide, in, out, 1, AtrousParams{}));

    simd::GuidePlanes strayGuide = guide;
    strayGuide.ny = stray.data();
    EXPECT_FALSE(simd::planesEvenlySpaced(layout, strayGuide, in));
    EXPECT_THROW(simd::filterLevel(layout, strayGuide, in, out, 1, AtrousParams{}), std::invalid_argument);
    simd::SignalPlanes strayIn = in;
    strayIn.l = stray.data();
    EXPECT_THROW(simd::filterLevel(layout, guide, strayIn, out, 1, AtrousParams{}), std::invalid_argument);
}

namespace {

/// The edgy frame with its variance set to zero on every tile of the low-variance skip but tile (1, 1), whose
/// variance stays high (well above 0.05 of its squared luminance).
Frame makeQuietFrame(uint32_t w, uint32_t h) {
    Frame f = makeEdgyFrame(w, h, 5);
    auto c = f.illum.view<glm::vec4>();
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const bool loud = x / kSkipTile == 1 && y / kSkipTile == 1;
            c.at(x, y).a = loud ? 4.f * luminance(glm::vec3(c.at(x, y))) * luminance(glm::vec3(c.at(x, y))) : 0.f;
        }
    return f;
}

bool inLoudTile(uint32_t x, uint32_t y) {
    return x / kSkipTile == 1 && y / kSkipTile == 1;
}

}  // namespace

TEST(Atrous, LowVarianceTilesKeepTheirInputExactly) {
    // Every tile but (1, 1) is below the threshold: its pixels come out as they went in, bit for bit, on both
    // paths, and the loud tile is filtered; the two paths still agree within the fast path's tolerance.
    const Frame f = makeQuietFrame(67, 53);
    AtrousParams skip;
    skip.skipRelVariance = 0.05f;
    Result fast, ref;
    AtrousTimings timings;
    {
        AtrousFilter filter;
        fast.dst = Texture(f.width, f.height, Format::RGBA32F);
        filter.setGuide(f.z(), f.n());
        filter.run(f.signal(), fast.dst.view<glm::vec4>(), 4, skip, -1, {}, false, &timings);
    }
    ref = runFilter(f, 4, true, -1, skip);
    EXPECT_EQ(timings.tiles, 5u * 4u);
    EXPECT_EQ(timings.skippedTiles, 5u * 4u - 1u);
    const Result plain = runFilter(f, 4, false);
    uint32_t loudChanged = 0;
    for (uint32_t y = 0; y < f.height; ++y)
        for (uint32_t x = 0; x < f.width; ++x) {
            const glm::vec4 in = f.signal().at(x, y);
            if (inLoudTile(x, y)) {
                loudChanged += fast.dst.view<glm::vec4>().at(x, y) != in;
                continue;
            }
            for (const Texture* t : {&fast.dst, &ref.dst})
                ASSERT_EQ(t->view<glm::vec4>().at(x, y), in) << x << ", " << y;
        }
    EXPECT_GT(loudChanged, kSkipTile * kSkipTile / 2);  // the loud tile is filtered (misses aside)
    EXPECT_LE(maxRelativeError(fast.dst, ref.dst), kTolerance);
    // Off, the same frame is filtered everywhere: the skip is what kept the quiet tiles.
    EXPECT_FALSE(plain.dst.samePixels(fast.dst));
}

TEST(Atrous, TileSkipOffOrBelowEveryVarianceChangesNothing) {
    // The edgy frame's relative variances are all far above 1e-9: no tile is skipped, and the bits are those of
    // the skip switched off.
    const Frame f = makeEdgyFrame(67, 53, 3);
    AtrousParams tiny;
    tiny.skipRelVariance = 1e-9f;
    for (bool reference : {false, true})
        EXPECT_TRUE(runFilter(f, 4, reference, 1, tiny).dst.samePixels(runFilter(f, 4, reference, 1).dst));
}
