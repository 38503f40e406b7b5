// The accumulation kernels (AccumulateKernels.h) on their own: doubles packed in uint texels, Neumaier summation,
// samples that are non-finite or would overflow the sum, and the blend with a denoised image.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <glm/glm.hpp>
#include <limits>

#include "../AccumulateKernels.h"

using namespace loom;

TEST(AccumulateKernels, DoublesRoundTripThroughUintTexelsLowWordFirst) {
    EXPECT_EQ(accumulate::packDoublePair(1.0, -2.0), glm::uvec4(0u, 0x3FF00000u, 0u, 0xC0000000u));
    const double values[] = {0.0, -0.0, 1.0 / 3.0, -1e300, 4.9e-324, 123456789.123456789};
    for (double a : values)
        for (double b : values) {
            const glm::dvec2 back = accumulate::unpackDoublePair(accumulate::packDoublePair(a, b));
            EXPECT_EQ(std::signbit(back.x), std::signbit(a));
            EXPECT_EQ(back.x, a);
            EXPECT_EQ(back.y, b);
        }
    glm::uvec4 rg, ba;
    accumulate::packDoubleSum(glm::dvec4(1.5, -2.25, 1e20, 7.0), rg, ba);
    EXPECT_EQ(accumulate::unpackDoubleSum(rg, ba), glm::dvec4(1.5, -2.25, 1e20, 7.0));
}

// Every precision keeps its sum in the same two uint texels: a state must come back bit for bit, NaN payloads and
// signed zeros included, so the pass's mean is what it would be with the state kept in float and double fields.
template <accumulate::Precision P>
accumulate::PixelState packedRoundTrip(const accumulate::PixelState& s) {
    glm::uvec4 first(0u), second(0u);
    accumulate::packSum<P>(s, first, second);
    if (P == accumulate::Precision::Float) {
        EXPECT_EQ(second, glm::uvec4(0u)) << "float leaves the second texel alone";
    }
    accumulate::PixelState back;
    accumulate::unpackSum<P>(first, second, back);
    return back;
}

TEST(AccumulateKernels, EveryPrecisionsSumRoundTripsBitForBitThroughTwoUintTexels) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    accumulate::PixelState s;
    s.sum = glm::vec4(-0.f, 1.f / 3.f, 3.4e38f, 1e-45f);
    s.compensation = glm::vec4(nan, -1e-30f, 0.f, -7.f);
    s.sumDouble = glm::dvec4(-0.0, 1e300, 1.0 / 3.0, 4.9e-324);
    const auto sameBits = [](const auto& a, const auto& b) { return std::memcmp(&a, &b, sizeof a) == 0; };

    const accumulate::PixelState f = packedRoundTrip<accumulate::Precision::Float>(s);
    EXPECT_TRUE(sameBits(f.sum, s.sum));
    const accumulate::PixelState k = packedRoundTrip<accumulate::Precision::Kahan>(s);
    EXPECT_TRUE(sameBits(k.sum, s.sum));
    EXPECT_TRUE(sameBits(k.compensation, s.compensation));
    const accumulate::PixelState d = packedRoundTrip<accumulate::Precision::Double>(s);
    EXPECT_TRUE(sameBits(d.sumDouble, s.sumDouble));

    // Double's texels are the DoubleTexels layout that partialSumRG / partialSumBA and `loom image merge` use.
    glm::uvec4 first, second, rg, ba;
    accumulate::packSum<accumulate::Precision::Double>(s, first, second);
    accumulate::packDoubleSum(s.sumDouble, rg, ba);
    EXPECT_EQ(first, rg);
    EXPECT_EQ(second, ba);
}

TEST(AccumulateKernels, NeumaierSumKeepsWhatFloatLoses) {
    float sum = 1e8f, compensation = 0.f;
    for (int i = 0; i < 1000; ++i) accumulate::neumaierAdd(sum, compensation, 1.f);
    EXPECT_EQ(double(sum) + double(compensation), 1e8 + 1000.0);
    // A sample larger than the running sum: plain Kahan summation loses the 1 here, Neumaier's variant does not.
    sum = 1.f;
    compensation = 0.f;
    accumulate::neumaierAdd(sum, compensation, 1e8f);
    accumulate::neumaierAdd(sum, compensation, -1e8f);
    EXPECT_EQ(double(sum) + double(compensation), 1.0);
}

TEST(AccumulateKernels, NonFiniteSamplesAreRejectedWhole) {
    const float inf = std::numeric_limits<float>::infinity();
    EXPECT_FALSE(isFinite(std::numeric_limits<float>::quiet_NaN()));
    EXPECT_FALSE(isFinite(-std::numeric_limits<float>::signaling_NaN()));
    EXPECT_FALSE(isFinite(inf));
    EXPECT_FALSE(isFinite(-inf));
    EXPECT_TRUE(isFinite(std::numeric_limits<float>::max()));
    EXPECT_TRUE(isFinite(std::numeric_limits<float>::denorm_min()));
    EXPECT_TRUE(isFinite(-0.f));

    for (auto precision : {accumulate::Precision::Float, accumulate::Precision::Kahan, accumulate::Precision::Double}) {
        accumulate::PixelState s;
        EXPECT_EQ(accumulate::mean(precision, s), glm::vec4(0.f)) << "no samples: zero, not 0/0";
        EXPECT_TRUE(accumulate::addSample(precision, s, glm::vec4(2.f)));
        EXPECT_FALSE(accumulate::addSample(precision, s, glm::vec4(1.f, inf, 1.f, 1.f)));
        EXPECT_TRUE(accumulate::addSample(precision, s, glm::vec4(4.f)));
        EXPECT_EQ(s.count, 2u);
        EXPECT_EQ(accumulate::mean(precision, s), glm::vec4(3.f));
        EXPECT_EQ(accumulate::sumAsFloat(precision, s), glm::vec4(6.f));
    }
}

// Finite but huge samples (near the largest float): a float or Kahan sum would overflow to Inf (and Kahan's
// compensation to -Inf, the mean to NaN). The sample that would overflow is skipped like a non-finite one, so the
// mean stays finite and is the mean of the samples kept; the double sum, which cannot overflow, shows as the largest
// float in `sum`.
TEST(AccumulateKernels, HugeSamplesNeverMakeTheMeanNonFinite) {
    const float big = 3e38f;
    for (auto precision : {accumulate::Precision::Float, accumulate::Precision::Kahan, accumulate::Precision::Double}) {
        accumulate::PixelState s;
        uint32_t kept = 0;
        for (int i = 0; i < 5; ++i) kept += accumulate::addSample(precision, s, glm::vec4(big, 1.f, -big, 0.f)) ? 1 : 0;
        const glm::vec4 m = accumulate::mean(precision, s);
        EXPECT_TRUE(isFinite(m)) << int(precision);
        EXPECT_TRUE(isFinite(accumulate::sumAsFloat(precision, s))) << int(precision);
        EXPECT_EQ(m, glm::vec4(big, 1.f, -big, 0.f)) << int(precision);
        EXPECT_EQ(kept, precision == accumulate::Precision::Double ? 5u : 1u) << int(precision);
    }
}

TEST(AccumulateKernels, BlendIsTheDenoisedImageBitForBitUntilASecondSample) {
    const glm::vec4 denoised(0.1f, 1e-30f, -0.f, 7.f), mean(5.f, 6.f, 7.f, 8.f);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (uint32_t count : {0u, 1u})
        for (float k : {0.f, 1.f, 64.f, 1e6f}) {
            const glm::vec4 out = accumulate::blendDenoised(denoised, mean, count, k);
            EXPECT_EQ(std::memcmp(&out, &denoised, sizeof out), 0) << "count " << count << ", K " << k;
            // The denoiser's own output, as it is: a NaN it wrote is not the blend's to hide on this frame.
            const glm::vec4 bad(nan, 1.f, 2.f, 3.f);
            const glm::vec4 passed = accumulate::blendDenoised(bad, mean, count, k);
            EXPECT_EQ(std::memcmp(&passed, &bad, sizeof passed), 0);
        }
}

TEST(AccumulateKernels, BlendWeighsTheMeanAsCountMinusOneFramesAgainstK) {
    // With D = 0 and M = 1 the output is the mean's weight: (n - 1) / (n - 1 + K), rising to 1.
    for (float k : {1.f, 16.f, 64.f, 300.f}) {
        float previous = 0.f;
        for (uint32_t n = 2; n <= 4096; n *= 2) {
            const float w = accumulate::blendDenoised(glm::vec4(0.f), glm::vec4(1.f), n, k).x;
            EXPECT_NEAR(w, double(n - 1) / (double(n - 1) + k), 1e-6) << "n " << n << ", K " << k;
            EXPECT_GT(w, previous);
            EXPECT_LT(w, 1.f);
            previous = w;
        }
        // Where both agree the blend is that value, and it always lies between them.
        const glm::vec4 v(0.25f, 3.f, 1e4f, 1.f);
        EXPECT_EQ(accumulate::blendDenoised(v, v, 37, k), v);
        const glm::vec4 out = accumulate::blendDenoised(glm::vec4(2.f), glm::vec4(-1.f), 9, k);
        for (int c = 0; c < 4; ++c) EXPECT_TRUE(out[c] >= -1.f && out[c] <= 2.f) << out[c];
    }
    // K = 0: the denoised image is worth nothing once there is a second sample.
    EXPECT_EQ(accumulate::blendDenoised(glm::vec4(9.f), glm::vec4(0.5f), 2, 0.f), glm::vec4(0.5f));
}

TEST(AccumulateKernels, ANonFiniteDenoisedPixelLeavesTheMeanAfterTheFirstSample) {
    const float inf = std::numeric_limits<float>::infinity();
    const glm::vec4 mean(0.5f, 0.25f, 0.125f, 1.f);
    for (const glm::vec4& bad : {glm::vec4(inf, 0.f, 0.f, 1.f), glm::vec4(0.f, -inf, 0.f, 1.f),
                                 glm::vec4(0.f, 0.f, std::numeric_limits<float>::quiet_NaN(), 1.f)})
        EXPECT_EQ(accumulate::blendDenoised(bad, mean, 2, 64.f), mean);
}
