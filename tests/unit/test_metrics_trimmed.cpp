// Trimmed RelMSE: RelMSE's value when nothing is an outlier, a bounded effect of one huge pixel (where RelMSE
// explodes), the exact trimming rule (ties included), the non-finite rule, and bit-identical results for any thread
// count.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <vector>

#include "loom/Error.h"
#include "loom/Metrics.h"
#include "loom/Parallel.h"

using namespace loom;

namespace {

Texture image(uint32_t w, uint32_t h, const std::function<glm::vec4(uint32_t, uint32_t)>& fn) {
    Texture t(w, h, Format::RGBA32F);
    auto v = t.view<glm::vec4>();
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) v.at(x, y) = fn(x, y);
    return t;
}

/// A smooth positive reference and a noisy test image of it (Gaussian noise, no outliers).
Texture reference(uint32_t w, uint32_t h) {
    return image(w, h, [](uint32_t x, uint32_t y) {
        return glm::vec4(0.2f + 0.5f * float(x % 97) / 97.f, 0.3f + 0.4f * float(y % 89) / 89.f, 0.5f, 1.f);
    });
}

Texture noisy(const Texture& ref, float sigma, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> n(0.f, sigma);
    auto r = ref.view<glm::vec4>();
    return image(ref.width(), ref.height(), [&](uint32_t x, uint32_t y) {
        const glm::vec4 v = r.at(x, y);
        return glm::vec4(v.x + n(rng), v.y + n(rng), v.z + n(rng), 1.f);
    });
}

/// The per-pixel RelMSE terms (sum over R, G, B), straight from the definition.
std::vector<double> terms(const Texture& test, const Texture& ref) {
    std::vector<double> out;
    auto t = test.view<glm::vec4>();
    auto r = ref.view<glm::vec4>();
    for (uint32_t y = 0; y < test.height(); ++y)
        for (uint32_t x = 0; x < test.width(); ++x) {
            double s = 0;
            for (int c = 0; c < 3; ++c) {
                const double d = double(t.at(x, y)[c]) - double(r.at(x, y)[c]);
                s += d * d / (double(r.at(x, y)[c]) * r.at(x, y)[c] + kRelMseEpsilon);
            }
            out.push_back(s);
        }
    return out;
}

uint64_t bits(double v) {
    uint64_t b;
    std::memcpy(&b, &v, sizeof b);
    return b;
}

}  // namespace

TEST(TrimmedRelMse, EqualsRelMseWithoutOutliers) {
    // Every pixel's term alike (a constant relative offset of a constant image): trimming changes nothing.
    const Texture ref = image(200, 150, [](uint32_t, uint32_t) { return glm::vec4(0.5f, 0.25f, 1.f, 1.f); });
    const Texture test = image(200, 150, [](uint32_t, uint32_t) { return glm::vec4(0.6f, 0.3f, 1.2f, 1.f); });
    EXPECT_NEAR(trimmedRelMSE(test, ref).value, relMSE(test, ref).value, 1e-12 * relMSE(test, ref).value);
    // Fewer than 1 / 0.001 pixels: nothing is dropped, the value is RelMSE's.
    const Texture smallRef = reference(30, 30), smallTest = noisy(smallRef, 0.05f, 3);
    EXPECT_NEAR(trimmedRelMSE(smallTest, smallRef).value, relMSE(smallTest, smallRef).value,
                1e-12 * relMSE(smallTest, smallRef).value);
    // Dropping nothing is RelMSE at any size.
    const Texture bigRef = reference(300, 200), bigTest = noisy(bigRef, 0.05f, 4);
    EXPECT_NEAR(trimmedRelMSE(bigTest, bigRef, 0.0).value, relMSE(bigTest, bigRef).value,
                1e-12 * relMSE(bigTest, bigRef).value);
    // Gaussian noise has no outliers: the 0.1 % trim moves the value by little (a few percent at most).
    const double r = relMSE(bigTest, bigRef).value, t = trimmedRelMSE(bigTest, bigRef).value;
    EXPECT_LE(t, r);
    EXPECT_GT(t, 0.95 * r);
}

TEST(TrimmedRelMse, IsTheMeanOfTheSmallestTerms) {
    const Texture ref = reference(123, 77), test = noisy(ref, 0.1f, 7);
    std::vector<double> e = terms(test, ref);
    std::sort(e.begin(), e.end());
    for (double drop : {0.001, 0.01, 0.25}) {
        const size_t keep = e.size() - size_t(std::floor(double(e.size()) * drop));
        double sum = 0;
        for (size_t i = 0; i < keep; ++i) sum += e[i];
        const double expected = sum / (3.0 * double(keep));
        EXPECT_NEAR(trimmedRelMSE(test, ref, drop).value, expected, 1e-9 * expected) << drop;
    }
    // Ties at the threshold: half the pixels have one term, half another; dropping 25 % keeps the rest exactly.
    const Texture flat = image(100, 20, [](uint32_t, uint32_t) { return glm::vec4(1.f, 1.f, 1.f, 1.f); });
    const Texture twoLevels =
        image(100, 20, [](uint32_t x, uint32_t) { return x % 2 ? glm::vec4(2.f, 1.f, 1.f, 1.f) : glm::vec4(1.f); });
    const double high = 1.0 / (1.0 + kRelMseEpsilon);  // one channel off by 1 against 1
    EXPECT_NEAR(trimmedRelMSE(twoLevels, flat, 0.25).value, (0.25 * high) / (0.75 * 3.0) * 1.0, 1e-12);
}

TEST(TrimmedRelMse, OneHugePixelHasABoundedEffect) {
    const Texture ref = reference(160, 120);  // 19200 pixels: 19 dropped
    const Texture clean = noisy(ref, 0.05f, 11);
    Texture firefly(clean.width(), clean.height(), Format::RGBA32F);
    firefly.copyFrom(clean);
    firefly.view<glm::vec4>().at(37, 59) = glm::vec4(1e6f, 1e6f, 1e6f, 1.f);

    std::vector<double> e = terms(clean, ref);
    std::sort(e.begin(), e.end(), std::greater<>());
    const size_t n = e.size(), drop = n / 1000;
    const double smallestDropped = e[drop - 1];

    const double before = trimmedRelMSE(clean, ref).value, after = trimmedRelMSE(firefly, ref).value;
    EXPECT_GE(after, before);
    EXPECT_LE(after - before, smallestDropped / (3.0 * double(n - drop)) * (1 + 1e-9));
    // RelMSE, by contrast, is taken over by the one pixel.
    EXPECT_GT(relMSE(firefly, ref).value, 1000.0 * relMSE(clean, ref).value);
    // A firefly in the reference instead: bounded the same way.
    Texture refFirefly(ref.width(), ref.height(), Format::RGBA32F);
    refFirefly.copyFrom(ref);
    refFirefly.view<glm::vec4>().at(3, 4) = glm::vec4(0.f, 0.f, 0.f, 1.f);  // a hole: relative error 1/eps
    std::vector<double> e2 = terms(clean, ref);
    const double moved = trimmedRelMSE(clean, refFirefly).value - before;
    EXPECT_LE(std::abs(moved), smallestDropped / (3.0 * double(n - drop)) * (1 + 1e-9) +
                                   *std::max_element(e2.begin(), e2.end()) / (3.0 * double(n - drop)));
}

TEST(TrimmedRelMse, NonFinitePixelsAreExcludedAndBadFractionsRefused) {
    const Texture ref = reference(64, 64), test = noisy(ref, 0.05f, 5);
    Texture bad(64, 64, Format::RGBA32F);
    bad.copyFrom(test);
    bad.view<glm::vec4>().at(1, 1) = glm::vec4(std::nanf(""), 0.f, 0.f, 1.f);
    bad.view<glm::vec4>().at(2, 1) = glm::vec4(INFINITY, 0.f, 0.f, 1.f);
    const MetricValue v = trimmedRelMSE(bad, ref);
    EXPECT_EQ(v.nonFinite, 2u);
    EXPECT_TRUE(std::isfinite(v.value));
    EXPECT_EQ(trimmedRelMSE(ref, ref).value, 0.0);
    EXPECT_THROW(trimmedRelMSE(test, ref, 1.0), Error);
    EXPECT_THROW(trimmedRelMSE(test, ref, -0.1), Error);
    EXPECT_THROW(trimmedRelMSE(test, ref, std::nan("")), Error);
}

TEST(TrimmedRelMse, DeterministicForAnyThreadCount) {
    const Texture ref = reference(333, 211);
    Texture test = noisy(ref, 0.2f, 9);
    for (uint32_t i = 0; i < 40; ++i) test.view<glm::vec4>().at(i * 7, i * 5) = glm::vec4(50.f, 1.f, 1.f, 1.f);
    uint64_t value[3];
    for (unsigned threads : {1u, 2u, 4u}) {
        ThreadLimit limit(threads);
        value[threads / 2] = bits(trimmedRelMSE(test, ref).value);
    }
    EXPECT_EQ(value[0], value[1]);
    EXPECT_EQ(value[0], value[2]);
}
