// The tone-mapping kernels (ToneMapKernels.h) on their own: every operator monotone and bounded, and the fast log2
// of the auto exposure.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>

#include "../ToneMapKernels.h"

using namespace loom;

TEST(ToneMap, OperatorsAreMonotoneAndBounded) {
    tonemap::ToneMapParams p;
    p.invWhiteSquared = 1.f / 16.f;
    p.hableInvWhite = 1.f / tonemap::hableCurve(tonemap::kHableWhite);
    for (auto op : {tonemap::Operator::Linear, tonemap::Operator::Reinhard, tonemap::Operator::ModifiedReinhard,
                    tonemap::Operator::Aces, tonemap::Operator::Hable}) {
        p.op = op;
        float previous = 0.f;
        for (float v = 0.f; v < 1e5f; v = v * 1.01f + 1e-5f) {
            const float m = tonemap::toneMapPixel(p, glm::vec4(v)).x;
            ASSERT_GE(m, previous) << "operator " << int(op) << " at " << v;
            ASSERT_LE(m, 1.f);
            previous = m;
        }
        // Non-linear operators approach white: near 1 far above the white point.
        EXPECT_GT(previous, 0.99f) << "operator " << int(op);
    }
}

TEST(ToneMapKernels, FastLog2IsAccurate) {
    for (float x = 1e-4f; x < 1e18f; x *= 1.0137f)
        ASSERT_NEAR(tonemap::fastLog2(x), std::log2(double(x)), 2e-6 * std::max(1.0, std::fabs(std::log2(double(x)))))
            << x;
}
