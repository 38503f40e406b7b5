// The TAA kernels (TAAKernels.h) on their own: HDR compression, the anti-flicker blend, YCoCg, Catmull-Rom weights,
// and the clip to the neighbourhood's box.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>

#include "../TAAKernels.h"

using namespace loom;

TEST(TAAKernels, HdrCompressionIsInvertibleAndBounded) {
    // compressColor() puts every non-negative colour below luma 1 and expandColor() undoes it to rounding: 1 - Y'
    // cancels, so the relative error grows as float epsilon times (1 + Y) (1e-3 at a luma of 1e5).
    for (float v : {0.f, 1e-6f, 0.02f, 0.5f, 1.f, 7.f, 300.f, 1e5f}) {
        const glm::vec4 c(v, 0.5f * v, 2.f * v, 0.25f);
        const glm::vec4 k = taa::compressColor(c);
        const float luma = taa::toYCoCg(c).x;
        EXPECT_LT(taa::toYCoCg(k).x, 1.f) << v;
        EXPECT_EQ(k.w, c.w);
        const glm::vec4 e = taa::expandColor(k);
        for (int i = 0; i < 4; ++i)
            EXPECT_NEAR(e[i], c[i], 4e-7f * (1.f + luma) * std::max(1.f, c[i])) << v << " channel " << i;
    }
}

TEST(TAAKernels, AntiFlickerWeightsByInverseLuminance) {
    taa::TaaParams p;
    p.antiFlicker = true;
    const glm::vec4 c(10.f), h(0.f);
    // wc = 0.1 / 11, wh = 0.9 / 1: the bright current sample gets far less than its nominal 10 %.
    const glm::vec4 out = taa::blend(p, c, 10.f, h, 0.f);
    const double wc = 0.1 / 11.0, wh = 0.9;
    EXPECT_NEAR(out.x, 10.0 * wc / (wc + wh), 1e-5);
    p.antiFlicker = false;
    EXPECT_NEAR(taa::blend(p, c, 10.f, h, 0.f).x, 1.0, 1e-6);
    // YCoCg round trip.
    const glm::vec4 rgb(0.2f, 0.5f, 0.9f, 0.3f);
    const glm::vec4 back = taa::fromYCoCg(taa::toYCoCg(rgb));
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(back[i], rgb[i], 1e-6);
    // Catmull-Rom weights sum to one and interpolate.
    for (float t : {0.f, 0.25f, 0.5f, 0.9f}) {
        const glm::vec4 w = taa::catmullRomWeights(t);
        EXPECT_NEAR(w.x + w.y + w.z + w.w, 1.f, 1e-6);
        EXPECT_NEAR(-w.x + w.z + 2.f * w.w, t, 1e-6) << "reproduces linear functions";
    }
}

// A box whose chroma channel is flat but for rounding (a few ulp wide) must not decide the clip: history that matches
// in luma and is a few ulp off in that channel stays as it is; history really outside is still clipped into the box.
TEST(TAAKernels, ARoundingWideChannelDoesNotDecideTheClip) {
    taa::ClipBox box;
    box.lo = glm::vec4(10.f, 2.f, -1e-6f, 1.f);
    box.hi = glm::vec4(50.f, 10.f, 1e-6f, 1.f);
    glm::vec4 inside(30.f, 6.f, 4e-6f, 1.f);
    const glm::vec4 kept = inside;
    EXPECT_FALSE(taa::clipToBox(box, inside));
    EXPECT_EQ(inside, kept);
    glm::vec4 outside(80.f, 6.f, 0.f, 1.f);
    EXPECT_TRUE(taa::clipToBox(box, outside));
    EXPECT_NEAR(outside.x, 50.f, 1e-3f);
    // A black box keeps flat channels flat: any difference there pulls the point onto the centre.
    taa::ClipBox black;
    glm::vec4 off(0.f, 1e-6f, 0.f, 0.f);
    EXPECT_TRUE(taa::clipToBox(black, off));
    EXPECT_EQ(off, glm::vec4(0.f));
}
