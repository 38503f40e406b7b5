// loom bench's lag figures (apps/loom/BenchLag.h) on synthetic data whose answers follow by hand: frames to recover
// after an event on an exponential decay of known half-life, a step, pure noise and curves that never settle; the
// per-pixel age since disocclusion through motion vectors, mesh ids and depth; the age buckets and their recovery.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "loom/BenchLag.h"
#include "loom/Metrics.h"

namespace bench = loom::cli::bench;
using loom::Format;
using loom::ImageView;
using loom::Texture;

namespace {

/// e(t) = 1 + amplitude * 2^(-t / halfLife), t = 0 .. n-1.
std::vector<double> decay(size_t n, double amplitude, double halfLife) {
    std::vector<double> e(n);
    for (size_t t = 0; t < n; ++t) e[t] = 1.0 + amplitude * std::exp2(-double(t) / halfLife);
    return e;
}

template <class T>
ImageView<const T> cview(Texture& t) {
    const ImageView<T> v = t.view<T>();
    return {v.data, v.width, v.height, v.rowPitch};
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Frames to recover

TEST(BenchLag, ExponentialDecayRecoversWhenTheExcessFallsBelowTheTolerance) {
    // Excess 8 * 2^(-t/2) over a steady state of 1 (the tail left in the last half is below 2e-4).
    // Window 1: 8 * 2^(-t/2) <= 0.1 from t = 2 log2(80) = 12.6 on: 13 (t = 12 gives 0.125, t = 13 gives 0.088).
    const std::vector<double> e = decay(64, 8.0, 2.0);
    const bench::Recovery w1 = bench::recoverAfter(e, 0, e.size(), 0.1, 1);
    EXPECT_TRUE(w1.settled);
    EXPECT_NEAR(w1.steady, 1.0, 2e-4);
    EXPECT_EQ(w1.segmentFrames, 64u);
    ASSERT_TRUE(w1.frames);
    EXPECT_EQ(*w1.frames, 13u);
    // Window 5: the largest frame of [t, t + 5) is t, so the excess is the mean over t + 1 .. t + 4:
    // 8 * 2^(-t/2) * (2^-0.5 + 2^-1 + 2^-1.5 + 2^-2) / 4 = 3.62 * 2^(-t/2): 0.113 at t = 10, 0.080 at t = 11.
    const bench::Recovery w5 = bench::recoverAfter(e, 0, e.size(), 0.1, 5);
    ASSERT_TRUE(w5.frames);
    EXPECT_EQ(*w5.frames, 11u);
    // Twice the half-life: 4 log2(80) = 25.3, so 26 (0.105 at 25, 0.088 at 26).
    const std::vector<double> slow = decay(128, 8.0, 4.0);
    const bench::Recovery s = bench::recoverAfter(slow, 0, slow.size(), 0.1, 1);
    ASSERT_TRUE(s.frames);
    EXPECT_EQ(*s.frames, 26u);
}

TEST(BenchLag, StepRecoversWhereItEnds) {
    // 5 for 6 frames, then 1. Unsmoothed: 6. Window 5: the window from 4 holds two 5s, (5 + 3) / 4 = 2 > 1.1 without
    // its largest; the one from 5 holds one, dropped as an outlier: 5.
    std::vector<double> e(32, 1.0);
    for (size_t t = 0; t < 6; ++t) e[t] = 5.0;
    const bench::Recovery w1 = bench::recoverAfter(e, 0, e.size(), 0.1, 1);
    EXPECT_TRUE(w1.settled);
    EXPECT_DOUBLE_EQ(w1.steady, 1.0);
    ASSERT_TRUE(w1.frames);
    EXPECT_EQ(*w1.frames, 6u);
    const bench::Recovery w5 = bench::recoverAfter(e, 0, e.size());
    ASSERT_TRUE(w5.frames);
    EXPECT_EQ(*w5.frames, 5u);
}

TEST(BenchLag, PureNoiseIsNoLagOnceSmoothed) {
    // 1.3, 0.7, 1.3, ...: the steady state is 1; a 5-frame window without its largest is (2 * 1.3 + 2 * 0.7) / 4 = 1
    // or (1.3 + 3 * 0.7) / 4 = 0.85, so no lag. Unsmoothed, every other frame is above the bound (1.3 > 1.1), the
    // last of them before the last half (from frame 16 on) at frame 14: the noise would read as 15 frames of lag.
    std::vector<double> e(32);
    for (size_t t = 0; t < e.size(); ++t) e[t] = t % 2 ? 0.7 : 1.3;
    const bench::Recovery w5 = bench::recoverAfter(e, 0, e.size());
    EXPECT_TRUE(w5.settled);
    EXPECT_DOUBLE_EQ(w5.steady, 1.0);
    ASSERT_TRUE(w5.frames);
    EXPECT_EQ(*w5.frames, 0u);
    const bench::Recovery w1 = bench::recoverAfter(e, 0, e.size(), 0.1, 1);
    ASSERT_TRUE(w1.frames);
    EXPECT_EQ(*w1.frames, 15u);
    // One outlying frame (a firefly at frame 12) is no lag once smoothed; unsmoothed it would be 13 frames.
    std::vector<double> firefly(32, 1.0);
    firefly[12] = 10.0;
    EXPECT_EQ(bench::recoverAfter(firefly, 0, firefly.size()).frames.value_or(99), 0u);
    EXPECT_EQ(bench::recoverAfter(firefly, 0, firefly.size(), 0.1, 1).frames.value_or(99), 13u);
    // A constant curve (what a graph without history gives, noise aside) recovers at once.
    const bench::Recovery flat = bench::recoverAfter(std::vector<double>(10, 0.25), 0, 10);
    ASSERT_TRUE(flat.frames);
    EXPECT_EQ(*flat.frames, 0u);
}

TEST(BenchLag, RecoveryIsForGoodNotTheFirstLowFrame) {
    // Low at the cut, two high frames after it (a filter without history, then a short one): the lag ends after them.
    std::vector<double> e(32, 1.0);
    e[0] = 0.5;
    e[1] = e[2] = 3.0;
    const bench::Recovery w1 = bench::recoverAfter(e, 0, e.size(), 0.1, 1);
    ASSERT_TRUE(w1.frames);
    EXPECT_EQ(*w1.frames, 3u);
    // Window 5 without its largest: 5.5 / 4 from 0 and 6 / 4 from 1 (one 3 left in each), 1 from 2 on.
    const bench::Recovery w5 = bench::recoverAfter(e, 0, e.size());
    ASSERT_TRUE(w5.frames);
    EXPECT_EQ(*w5.frames, 2u);
}

TEST(BenchLag, CurvesThatNeverSettleHaveNoRecovery) {
    // Growing error: the last half's halves have means 20.5 and 28.5, more than 20 % of 24.5 apart.
    std::vector<double> grow(32);
    for (size_t t = 0; t < grow.size(); ++t) grow[t] = 1.0 + double(t);
    const bench::Recovery g = bench::recoverAfter(grow, 0, grow.size());
    EXPECT_FALSE(g.settled);
    EXPECT_FALSE(g.frames);
    // A decay too slow for the run (half-life 16 frames over 32 frames): still falling at the end; the last half's
    // halves have means of about 44 and 31, more than 20 % of their mean (38) apart.
    const std::vector<double> slow = decay(32, 100.0, 16.0);
    const bench::Recovery s = bench::recoverAfter(slow, 0, slow.size());
    EXPECT_FALSE(s.settled);
    EXPECT_FALSE(s.frames);
}

TEST(BenchLag, EventsSplitTheRunIntoSegmentsWithTheirOwnSteadyState) {
    // Frames 10..73: after the cut 5 for 6 frames then 1; a lighting step at frame 42 gives 3 for 4 frames, then 2.
    // Window 5 without its largest: the cut recovers at 5 (StepRecoversWhereItEnds); after the step the window from
    // 34 holds two 3s, (3 + 6) / 4 = 2.25 > 2.2, the one from 35 one: 3.
    std::vector<double> e(64, 1.0);
    for (size_t t = 0; t < 6; ++t) e[t] = 5.0;
    for (size_t t = 32; t < 64; ++t) e[t] = t < 36 ? 3.0 : 2.0;
    // Duplicates are merged; frames outside the run (before its first frame, after its end) are ignored.
    const std::vector<bench::Recovery> r = bench::frameRecoveries(e, 10, {42, 5, 42, 200, 10});
    ASSERT_EQ(r.size(), 2u);
    EXPECT_EQ(r[0].kind, "cut");
    EXPECT_EQ(r[0].frame, 10u);
    EXPECT_EQ(r[0].segmentFrames, 32u);
    EXPECT_DOUBLE_EQ(r[0].steady, 1.0);
    ASSERT_TRUE(r[0].frames);
    EXPECT_EQ(*r[0].frames, 5u);
    EXPECT_EQ(r[1].kind, "light");
    EXPECT_EQ(r[1].frame, 42u);
    EXPECT_DOUBLE_EQ(r[1].steady, 2.0);
    ASSERT_TRUE(r[1].frames);
    EXPECT_EQ(*r[1].frames, 3u);
    EXPECT_TRUE(bench::frameRecoveries({}, 0, {}).empty());
}

// ---------------------------------------------------------------------------------------------------------------
// Ages since disocclusion

namespace {

/// A W x H G-buffer with constant depth, mesh id and motion, plus last frame's ages, depth and mesh ids.
struct AgeFixture {
    static constexpr uint32_t W = 8, H = 4;
    Texture z{W, H, Format::RG32F}, mvec{W, H, Format::RG32F}, mesh{W, H, Format::R32U};
    Texture prevAges{W, H, Format::R32U}, prevZ{W, H, Format::RG32F}, prevMesh{W, H, Format::R32U};
    Texture ages{W, H, Format::R32U};

    AgeFixture(uint32_t prevAge = 3) {
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                z.view<glm::vec2>().at(x, y) = {2.0f, 0.0f};
                prevZ.view<glm::vec2>().at(x, y) = {2.0f, 0.0f};
                mesh.view<uint32_t>().at(x, y) = 7;
                prevMesh.view<uint32_t>().at(x, y) = 7;
                prevAges.view<uint32_t>().at(x, y) = prevAge + x;
            }
    }
    void update() {
        bench::updateAges({cview<glm::vec2>(z), cview<glm::vec2>(mvec), cview<uint32_t>(mesh)},
                          cview<uint32_t>(prevAges), cview<glm::vec2>(prevZ), cview<uint32_t>(prevMesh),
                          ages.view<uint32_t>());
    }
    uint32_t age(uint32_t x, uint32_t y) { return ages.view<uint32_t>().at(x, y); }
};

}  // namespace

TEST(BenchLag, StaticPixelsAgeByOneAndSaturateAtTheCap) {
    AgeFixture f;
    f.update();
    for (uint32_t y = 0; y < f.H; ++y)
        for (uint32_t x = 0; x < f.W; ++x) EXPECT_EQ(f.age(x, y), std::min(3 + x + 1, bench::kAgeCap));
    f.prevAges.view<uint32_t>().at(0, 0) = std::numeric_limits<uint32_t>::max();  // no overflow past the cap
    f.update();
    EXPECT_EQ(f.age(0, 0), bench::kAgeCap);
}

TEST(BenchLag, MotionVectorsFollowThePixelAndFramesEdgesDisocclude) {
    // Content moved one pixel right: uvPrev = uv - (1 / W, 0); pixel x continues x - 1, and x = 0 came into view.
    // A quarter pixel more still rounds to the same previous pixel.
    AgeFixture f;
    for (uint32_t y = 0; y < f.H; ++y)
        for (uint32_t x = 0; x < f.W; ++x) f.mvec.view<glm::vec2>().at(x, y) = {-1.25f / float(f.W), 0.1f / f.H};
    f.update();
    for (uint32_t y = 0; y < f.H; ++y) {
        EXPECT_EQ(f.age(0, y), 0u);
        for (uint32_t x = 1; x < f.W; ++x) EXPECT_EQ(f.age(x, y), std::min(3 + (x - 1) + 1, bench::kAgeCap));
    }
}

TEST(BenchLag, MeshDepthMissAndBadMotionDisocclude) {
    AgeFixture f;
    f.mesh.view<uint32_t>().at(1, 0) = 8;                       // another mesh now
    f.z.view<glm::vec2>().at(2, 0) = {2.0f * 1.06f, 0.0f};      // 6 % deeper: beyond the 5 % tolerance
    f.z.view<glm::vec2>().at(3, 0) = {2.0f * 1.04f, 0.0f};      // 4 % deeper: within it
    f.z.view<glm::vec2>().at(4, 0) = {2.0f * 1.06f, 0.05f};     // 6 % deeper on a slope of 0.05 per pixel
    f.z.view<glm::vec2>().at(5, 0) = {-1.0f, 0.0f};             // a miss
    f.prevZ.view<glm::vec2>().at(6, 0) = {-1.0f, 0.0f};         // was a miss
    f.mvec.view<glm::vec2>().at(7, 0) = {std::nanf(""), 0.0f};  // no motion
    f.mvec.view<glm::vec2>().at(0, 1) = {0.0f, 1e30f};          // far outside
    f.update();
    EXPECT_EQ(f.age(0, 0), 4u);
    EXPECT_EQ(f.age(1, 0), 0u);
    EXPECT_EQ(f.age(2, 0), 0u);
    EXPECT_EQ(f.age(3, 0), 7u);
    EXPECT_EQ(f.age(4, 0), 8u);
    EXPECT_EQ(f.age(5, 0), 0u);
    EXPECT_EQ(f.age(6, 0), 0u);
    EXPECT_EQ(f.age(7, 0), 0u);
    EXPECT_EQ(f.age(0, 1), 0u);
    EXPECT_EQ(f.age(1, 1), 5u);
}

TEST(BenchLag, AgeBucketsAverageTheErrorOfHitPixelsWithFiniteColours) {
    constexpr uint32_t W = 4, H = 1;
    Texture ages(W, H, Format::R32U), z(W, H, Format::RG32F), err(W, H, Format::R32F);
    Texture test(W, H, Format::RGBA32F), ref(W, H, Format::RGBA32F);
    const uint32_t a[W] = {0, 0, 20, 16};
    const float e[W] = {1.0f, 3.0f, 0.5f, 0.25f};
    for (uint32_t x = 0; x < W; ++x) {
        ages.view<uint32_t>().at(x, 0) = a[x];
        z.view<glm::vec2>().at(x, 0) = {1.0f, 0.0f};
        err.view<float>().at(x, 0) = e[x];
        test.view<glm::vec4>().at(x, 0) = glm::vec4(1.0f);
        ref.view<glm::vec4>().at(x, 0) = glm::vec4(1.0f);
    }
    bench::AgeBuckets b;
    bench::addAgeErrors(cview<uint32_t>(ages), cview<glm::vec2>(z), cview<float>(err), cview<glm::vec4>(test),
                        cview<glm::vec4>(ref), b);
    EXPECT_EQ(b.count[0], 2u);
    EXPECT_DOUBLE_EQ(*b.mean(0), 2.0);
    EXPECT_EQ(b.count[bench::kAgeCap], 2u);  // ages 16 and 20 share the last bucket
    EXPECT_DOUBLE_EQ(*b.mean(bench::kAgeCap), 0.375);
    EXPECT_FALSE(b.mean(1));
    // A miss, or a non-finite colour in either image, leaves the pixel out.
    z.view<glm::vec2>().at(0, 0) = {-1.0f, 0.0f};
    test.view<glm::vec4>().at(1, 0).x = std::numeric_limits<float>::infinity();
    ref.view<glm::vec4>().at(2, 0).y = std::nanf("");
    bench::AgeBuckets c;
    bench::addAgeErrors(cview<uint32_t>(ages), cview<glm::vec2>(z), cview<float>(err), cview<glm::vec4>(test),
                        cview<glm::vec4>(ref), c);
    EXPECT_EQ(c.count[0], 0u);
    EXPECT_EQ(c.count[bench::kAgeCap], 1u);
    EXPECT_DOUBLE_EQ(*c.mean(bench::kAgeCap), 0.25);
}

TEST(BenchLag, AgesToRecoverIsWhereTheBucketsStayNearTheOldest) {
    // Bucket a: 1 + 10 * 2^-a, the 16+ bucket 1: within 10 % from 10 * 2^-a <= 0.1 on, a = 7 (0.078; 0.156 at 6).
    bench::AgeBuckets b;
    for (uint32_t a = 0; a < bench::kAgeCap; ++a) {
        b.sum[a] = 2.0 * (1.0 + 10.0 * std::exp2(-double(a)));
        b.count[a] = 2;
    }
    b.sum[bench::kAgeCap] = 5.0;
    b.count[bench::kAgeCap] = 5;
    ASSERT_TRUE(bench::agesToRecover(b));
    EXPECT_EQ(*bench::agesToRecover(b), 7u);
    // A late bucket above the bound moves it past that bucket; empty buckets do not count.
    bench::AgeBuckets late = b;
    late.sum[11] = 1.5 * 2;
    late.count[12] = 0;
    late.sum[12] = 0;
    EXPECT_EQ(*bench::agesToRecover(late), 12u);
    // Flat buckets (no history, as brute force): 0. No pixel of the oldest age: no figure.
    bench::AgeBuckets flat;
    for (uint32_t a = 0; a <= bench::kAgeCap; ++a) {
        flat.sum[a] = 3.0;
        flat.count[a] = 3;
    }
    EXPECT_EQ(*bench::agesToRecover(flat), 0u);
    flat.count[bench::kAgeCap] = 0;
    EXPECT_FALSE(bench::agesToRecover(flat));
}

TEST(BenchLag, TrackerCountsEveryPixelOncePerMeasuredFrameAtItsAge) {
    // A static 6x5 view for 20 frames, the cut at frame 0, frames 2.. measured: a frame t holds every pixel at age t
    // (16+ from t = 16 on). The error is RelMSE's per-pixel term: test 1.5 against ref 1 gives 0.25 / 1.01.
    constexpr uint32_t W = 6, H = 5;
    Texture z(W, H, Format::RG32F), mvec(W, H, Format::RG32F), mesh(W, H, Format::R32U);
    Texture test(W, H, Format::RGBA32F), ref(W, H, Format::RGBA32F);
    for (uint32_t y = 0; y < H; ++y)
        for (uint32_t x = 0; x < W; ++x) {
            z.view<glm::vec2>().at(x, y) = {3.0f, 0.01f};
            mesh.view<uint32_t>().at(x, y) = 1;
            test.view<glm::vec4>().at(x, y) = glm::vec4(1.5f);
            ref.view<glm::vec4>().at(x, y) = glm::vec4(1.0f);
        }
    const bench::AgeGBuffer g{cview<glm::vec2>(z), cview<glm::vec2>(mvec), cview<uint32_t>(mesh)};
    bench::DisocclusionTracker tracker;
    for (uint32_t t = 0; t < 20; ++t) tracker.addFrame(g, test, ref, t == 0, t >= 2);
    const bench::AgeBuckets& b = tracker.buckets();
    const double perPixel = 0.25 / (1.0 + loom::kRelMseEpsilon);
    for (uint32_t a = 0; a < bench::kAgeCap; ++a) {
        EXPECT_EQ(b.count[a], a >= 2 ? uint64_t(W * H) : 0u) << "age " << a;
        if (a >= 2) {
            EXPECT_NEAR(*b.mean(a), perPixel, 1e-6);
        }
    }
    EXPECT_EQ(b.count[bench::kAgeCap], uint64_t(4 * W * H));  // frames 16..19
    // A second cut starts every pixel again at age 0.
    tracker.addFrame(g, test, ref, true, true);
    EXPECT_EQ(tracker.buckets().count[0], uint64_t(W * H));
}
