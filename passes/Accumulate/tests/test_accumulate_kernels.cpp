// The accumulation kernels (AccumulateKernels.h) on their own: doubles packed in uint texels, Neumaier summation,
// and samples that are non-finite or would overflow the sum.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
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
