// SVGF's demodulation and remodulation (SVGFKernels.h) of finite inputs give finite results, however large the
// albedo: what is divided out is multiplied back with the same guarded albedo, and that is bounded.
#include <gtest/gtest.h>

#include <cfloat>

#include "../SVGFKernels.h"

using namespace loom;
using namespace loom::svgf;

TEST(SVGFAlbedoBounds, GuardedAlbedoStaysWithinItsBounds) {
    EXPECT_EQ(guardedAlbedo({0.5f, 0.f, -3.f, 1.f}), glm::vec3(0.5f, kMinAlbedo, kMinAlbedo));
    EXPECT_EQ(guardedAlbedo({1e38f, FLT_MAX, INFINITY, 1.f}), glm::vec3(kMaxAlbedo, kMaxAlbedo, kMinAlbedo));
    EXPECT_EQ(guardedAlbedo({1.7f, 1.f, 3.f, 1.f}), glm::vec3(1.7f, 1.f, 3.f));  // albedos above 1 are kept
}

TEST(SVGFAlbedoBounds, RemodulationOfFiniteInputsIsFinite) {
    // The largest illumination the filter hands on, times albedo as large as floats go, plus the largest emission.
    for (const float albedo : {1e38f, FLT_MAX, 1e6f, 1.f})
        for (const float emission : {0.f, FLT_MAX, -FLT_MAX}) {
            const glm::vec4 out = remodulate(glm::vec3(kMaxIllumination), glm::vec4(1.f),
                                             glm::vec4(albedo, albedo, albedo, 1.f), glm::vec3(emission), 1.f);
            EXPECT_TRUE(isFinite(out)) << albedo << " " << emission;
        }
    // A pixel the filter leaves alone comes back as it was, for an albedo within bounds.
    const glm::vec4 albedo(0.25f, 2.f, 1e5f, 1.f), color(3.f, 5.f, 7.f, 1.f);
    const glm::vec3 illum = clampIllumination(glm::vec3(color) / guardedAlbedo(albedo));
    const glm::vec4 back = remodulate(illum, color, albedo, glm::vec3(0.f), 1.f);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(back[c], color[c], 1e-6f * color[c]);
}
