// The path tracer's kernels (Lights.h, PathTracerKernels.h) on their own: stratified points on a triangle, the
// density of light samples, and shading normals bent so that reflections stay above the surface.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <glm/glm.hpp>
#include <vector>

#include "../Lights.h"
#include "../PathTracerKernels.h"
#include "TestUtil.h"

using namespace loom;

// The points of subTriangleCentroid: m * m distinct points inside the triangle whose mean is its centroid.
TEST(PathTracerLights, SubTriangleCentroidsAreStratified) {
    for (uint32_t m : {1u, 2u, 3u, 7u, 64u}) {
        glm::dvec2 sum(0.0);
        std::vector<glm::vec2> points;
        for (uint32_t k = 0; k < m * m; ++k) {
            const glm::vec2 b = pt::subTriangleCentroid(m, k);
            ASSERT_TRUE(b.x > 0.f && b.y > 0.f && b.x + b.y < 1.f) << m << " " << k;
            sum += glm::dvec2(b);
            points.push_back(b);
        }
        EXPECT_NEAR(sum.x / double(m * m), 1.0 / 3.0, 1e-5) << m;
        EXPECT_NEAR(sum.y / double(m * m), 1.0 / 3.0, 1e-5) << m;
        std::sort(points.begin(), points.end(),
                  [](glm::vec2 a, glm::vec2 b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
        EXPECT_TRUE(std::adjacent_find(points.begin(), points.end()) == points.end()) << m;
    }
}

// The density a light sample reports is the density at which sampleLight produces that point: over samples from a
// point below four triangle lights (powers 0, 1, 0 and 3), the mean of 1 / pdf per picked triangle is its solid
// angle (Van Oosterom and Strackee's formula) within 1%, and each triangle is picked as often as its CDF interval
// says. Triangles of no power are never picked, and their light pdf (the one MIS uses for a BRDF-sampled hit) is 0.
TEST(PathTracerLights, LightSamplePdfIsTheDensityOfTheSamples) {
    std::vector<pt::EmissiveTri> tris;
    const float powers[] = {0.f, 1.f, 0.f, 3.f};
    for (uint32_t i = 0; i < 4; ++i) {
        pt::EmissiveTri t;
        t.p0 = glm::vec3(-1.f + 0.6f * float(i), 1.f + 0.2f * float(i), -0.5f);
        t.e1 = glm::vec3(0.5f, 0.1f, 0.2f);
        t.e2 = glm::vec3(0.f, 0.f, 1.f + 0.3f * float(i));  // e1 x e2 points down: the lit side faces the origin
        const glm::vec3 c = glm::cross(t.e1, t.e2);
        t.area = 0.5f * glm::length(c);
        t.normal = glm::normalize(c);
        ASSERT_LT(t.normal.y, 0.f);
        t.power = powers[i];
        t.primitive = i;
        tris.push_back(t);
    }
    std::vector<float> cdf(tris.size() + 1);
    pt::LightsView L;
    L.tris = tris.data();
    L.triCdf = cdf.data();
    L.triCount = uint32_t(tris.size());
    L.triPowerSum = float(pt::fillTriangleCdf(tris.data(), L.triCount, cdf.data()));
    L.pTris = 1.f;
    pt::setTrianglePdfs(tris.data(), L.triCount, cdf.data(), L.pTris);
    const glm::vec3 p(0.f);
    const uint32_t n = 1u << 18;
    std::vector<double> inversePdf(tris.size(), 0.0);
    std::vector<uint32_t> picks(tris.size(), 0);
    for (uint32_t k = 0; k < n; ++k) {
        const float u1 = (float(k) + 0.5f) / float(n);
        const float u2 = float(loom::test::hash01(k, 1, 2)), u3 = float(loom::test::hash01(k, 3, 4));
        const pt::LightSample s = pt::sampleLight(L, p, 0.f, u1, u2, u3);
        ASSERT_TRUE(s.valid);
        ++picks[s.primitive];
        inversePdf[s.primitive] += 1.0 / double(s.pdf);
        // The density MIS gives a BRDF-sampled ray through the same point.
        const pt::EmissiveTri& t = tris[s.primitive];
        EXPECT_FLOAT_EQ(pt::triLightPdf(L, t, s.distance * s.distance, -glm::dot(t.normal, s.wi)), s.pdf);
    }
    for (uint32_t i = 0; i < tris.size(); ++i) {
        const pt::EmissiveTri& t = tris[i];
        const glm::vec3 a = t.p0 - p, b = t.p0 + t.e1 - p, c = t.p0 + t.e2 - p;
        const float la = glm::length(a), lb = glm::length(b), lc = glm::length(c);
        const double solidAngle =
            2.0 * std::atan2(std::fabs(glm::dot(a, glm::cross(b, c))),
                             la * lb * lc + glm::dot(a, b) * lc + glm::dot(a, c) * lb + glm::dot(b, c) * la);
        std::printf("triangle %u: picked %u times, mean 1/pdf %.5f, solid angle %.5f\n", i, picks[i], inversePdf[i] / n,
                    solidAngle);
        EXPECT_NEAR(double(picks[i]) / n, double(cdf[i + 1] - cdf[i]), 1.0 / n) << i;
        if (powers[i] == 0.f) {
            EXPECT_EQ(picks[i], 0u) << i;
            EXPECT_EQ(pt::triLightPdf(L, t, 1.f, 1.f), 0.f) << i;
        } else {
            EXPECT_NEAR(inversePdf[i] / n, solidAngle, 0.01 * solidAngle) << i;
        }
    }
}

TEST(PathTracer, BentNormalsReflectAboveTheSurface) {
    const glm::vec3 ng(0.f, 0.f, 1.f);
    uint32_t bent = 0;
    for (int i = 0; i < 2000; ++i) {
        const float a = 0.001f * float(i), b = 0.0037f * float(i);
        const glm::vec3 wo = glm::normalize(glm::vec3(std::cos(b), std::sin(b), 0.05f + std::fmod(a, 1.f)));
        const glm::vec3 n = glm::normalize(glm::vec3(std::sin(3.f * a), std::cos(5.f * a), 0.3f + std::fmod(b, 1.f)));
        const glm::vec3 bentN = pt::bendShadingNormal(n, ng, wo);
        const glm::vec3 r = 2.f * glm::dot(wo, bentN) * bentN - wo;
        const float before = glm::dot(2.f * glm::dot(wo, n) * n - wo, ng);
        ASSERT_NEAR(glm::length(bentN), 1.f, 1e-5f);
        if (before >= pt::kMinReflectionCosine) {
            ASSERT_EQ(bentN, n);  // unchanged where the reflection is already above the surface
        } else {
            ++bent;
            ASSERT_NEAR(glm::dot(r, ng), pt::kMinReflectionCosine, 1e-4f);
            ASSERT_GT(glm::dot(bentN, ng), 0.f);
        }
    }
    EXPECT_GT(bent, 100u);
}
