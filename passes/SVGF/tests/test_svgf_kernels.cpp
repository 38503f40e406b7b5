// SVGF's kernels (SVGFKernels.h) on their own: the spatial variance weight against its closed form, and the
// anti-lag's reading of the temporal gradient samples.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>

#include "../SVGFKernels.h"

using namespace loom;

// The spatial variance estimate's weight, spelt for identical scalar and vector evaluation, against the closed
// form it stands for, exp(-|dl| / phiColor - |dz| invDepth) * max(0, cos)^phiNormal: within the documented
// bounds (series <= 3.2e-6 absolute, exponential 2.6e-6 relative, plus float rounding) over a sweep of normals,
// luminance and depth differences, exactly 0 for normals 90 degrees or more apart, and the clamp at 2^-100.
TEST(SVGF, VarianceWeightMatchesItsClosedForm) {
    using namespace loom::svgf;
    for (float t = 0.f; t <= 100.f; t += 0.0137f) {
        const double expected = std::exp2(-double(t));
        ASSERT_NEAR(varianceExp2Neg(t), expected, 3e-6 * expected) << "2^-" << t;
    }
    // Beyond 100 the exponent stays at 100: a small normal float, never 0 or a denormal.
    EXPECT_NEAR(varianceExp2Neg(1e6f), std::ldexp(1.0, -100), 3e-6 * std::ldexp(1.0, -100));
    EXPECT_EQ(varianceExp2Neg(1e6f), varianceExp2Neg(100.f));
    double worst = 0.0;
    for (float phi : {32.f, 64.f, 128.f, 300.f}) {
        AtrousParams p;
        p.phiNormal = phi;
        p.phiColor = 10.f;
        const VarianceScales s = varianceScales(p);
        ASSERT_TRUE(s.series);
        const glm::vec3 n(0.f, 0.f, 1.f);
        for (float angle = 0.f; angle < 1.6f; angle += 0.003f) {
            const glm::vec3 m(std::sin(angle), 0.f, std::cos(angle));
            const float cosine = (n.x * m.x + n.y * m.y) + n.z * m.z;
            for (float dl : {0.f, 0.5f, 3.f, 40.f})
                for (float dz : {0.f, 0.01f, 0.2f}) {
                    const float w = varianceWeight(dz, 10.f, n, m, 1.f, 1.f + dl, s);
                    if (cosine <= 0.f) {
                        ASSERT_EQ(w, 0.f);
                        continue;
                    }
                    const double closed = std::exp(-double(dl) / 10.0 - double(dz) * 10.0) *
                                          std::pow(double(std::min(cosine, 1.f)), double(phi));
                    worst = std::max(worst, std::fabs(w - closed));
                    ASSERT_NEAR(w, closed, 4e-6 + 4e-6 * closed) << "phi " << phi << " angle " << angle;
                }
        }
        // Orthogonal and opposite normals: no weight.
        EXPECT_EQ(varianceWeight(0.f, 1.f, n, glm::vec3(1.f, 0.f, 0.f), 1.f, 1.f, s), 0.f);
        EXPECT_EQ(varianceWeight(0.f, 1.f, n, -n, 1.f, 1.f, s), 0.f);
    }
    EXPECT_GT(worst, 0.0);  // the sweep compared real weights
}

// The anti-lag's reading of the gradient samples (new, old) around a block: a light that only dims or brightens is a
// ratio with nothing left over (the rescaled history is right, lambda 0); a shadow that moves over part of the
// window leaves a residual; nothing lit is no change.
TEST(SVGF, AntilagSeparatesRescalingFromChange) {
    const glm::vec2 dimmed[4] = {{0.5f, 2.f}, {0.25f, 1.f}, {1.f, 4.f}, {0.75f, 3.f}};
    const glm::vec2 c = svgf::antilagChange(dimmed, 4);
    EXPECT_EQ(c.y, 0.25f);
    EXPECT_EQ(c.x, 0.f);
    const glm::vec2 shadowed[4] = {{1.f, 1.f}, {1.f, 1.f}, {0.f, 1.f}, {0.f, 1.f}};
    const glm::vec2 s = svgf::antilagChange(shadowed, 4);
    EXPECT_FLOAT_EQ(s.y, 0.5f);
    EXPECT_FLOAT_EQ(s.x, 2.f / 3.f);  // rescaled by 0.5: residuals 4 x 0.5 over maxima 1 + 1 + 0.5 + 0.5
    const glm::vec2 dark[2] = {{0.f, 0.f}, {0.f, 0.f}};
    EXPECT_EQ(svgf::antilagChange(dark, 2), glm::vec2(0.f, 1.f));
    const glm::vec2 switchedOn[2] = {{2.f, 0.f}, {1.f, 0.f}};
    EXPECT_EQ(svgf::antilagChange(switchedOn, 2), glm::vec2(1.f, 1.f)) << "from black: no ratio, all change";
    // Non-finite and negative samples count as none.
    EXPECT_EQ(svgf::gradientSample(glm::vec2(std::nanf(""), 1.f)), glm::vec2(0.f));
    EXPECT_EQ(svgf::gradientSample(glm::vec2(1.f, -1.f)), glm::vec2(0.f));
}

// The firefly clamp's factor: a sample above mean + k sigma of the history's moments is brought exactly to that bound;
// one within it, any sample with the clamp off (k = 0), and any sample of a history with no bound (non-finite or
// negative) keep their value.
TEST(SVGF, OutlierScaleBringsFirefliesToTheBound) {
    const float mean = 2.f, sigma = 0.5f;
    const float m1 = mean, m2 = sigma * sigma + mean * mean;
    for (float k : {1.f, 2.f, 3.f}) {
        const float bound = mean + k * sigma;
        for (float lum : {bound * 1.01f, 10.f, 1e6f, 1e30f}) {
            const float s = svgf::outlierScale(lum, m1, m2, k);
            EXPECT_LT(s, 1.f) << k << " " << lum;
            EXPECT_NEAR(lum * s, bound, 1e-5f * bound) << k << " " << lum;
        }
        for (float lum : {0.f, 1.f, mean, bound * 0.999f}) EXPECT_EQ(svgf::outlierScale(lum, m1, m2, k), 1.f);
    }
    EXPECT_EQ(svgf::outlierScale(1e6f, m1, m2, 0.f), 1.f);
    // Moments whose variance rounds below zero give sigma 0: the bound is the mean.
    EXPECT_NEAR(5.f * svgf::outlierScale(5.f, 1.f, 0.999999f, 3.f), 1.f, 1e-5f);
    EXPECT_EQ(svgf::outlierScale(5.f, -1.f, 1.f, 0.f), 1.f);
    EXPECT_EQ(svgf::outlierScale(5.f, -10.f, 100.f, 1.f), 1.f);  // bound -10: nothing to clamp to
}
