// The conversions ImageSequence applies to another renderer's values (SequenceConversions.h), each against what the
// quantity means: a pixel's motion, a plane's depth slope, a rotation, an index.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "../SequenceConversions.h"

using namespace loom;
using namespace loom::sequence;

TEST(SequenceConversions, MotionInPixelsBecomesUvToThePreviousPosition) {
    // A point at pixel (10, 20) of a 100x50 frame was at (7, 24) last frame, in rows that run top to bottom.
    const glm::vec2 uvPrevMinusCur = {(7.f - 10.f) / 100.f, (24.f - 20.f) / 50.f};
    EXPECT_EQ(motionToUv({-3.f, 4.f}, MotionKind::PixelsToPrevious, false, 100, 50), uvPrevMinusCur);
    EXPECT_EQ(motionToUv({3.f, -4.f}, MotionKind::PixelsFromPrevious, false, 100, 50), uvPrevMinusCur);
    // With y growing upwards, the point moved up by 4 rows' worth in the stored value's sign.
    EXPECT_EQ(motionToUv({3.f, 4.f}, MotionKind::PixelsFromPrevious, true, 100, 50), uvPrevMinusCur);
    EXPECT_EQ(motionToUv({-3.f, -4.f}, MotionKind::PixelsToPrevious, true, 100, 50), uvPrevMinusCur);
    EXPECT_EQ(motionToUv(uvPrevMinusCur, MotionKind::Uv, true, 100, 50), uvPrevMinusCur);  // Loom's own: unchanged
}

TEST(SequenceConversions, DepthBecomesLinearZWithTheSurfacesSlope) {
    // A tilted plane z = 2 + 0.25 x + 0.5 y over 6x4 pixels, a background (1e10) column and a NaN.
    Texture t(6, 4, Format::RG32F);
    const auto z = t.view<glm::vec2>();
    for (uint32_t y = 0; y < 4; ++y)
        for (uint32_t x = 0; x < 6; ++x) z.at(x, y) = {2.f + 0.25f * float(x) + 0.5f * float(y), 123.f};
    for (uint32_t y = 0; y < 4; ++y) z.at(5, y).x = 1e10f;
    z.at(0, 0).x = std::numeric_limits<float>::quiet_NaN();
    depthToLinearZ(z, 1e9f);
    for (uint32_t y = 0; y < 4; ++y) {
        EXPECT_EQ(z.at(5, y), glm::vec2(-1.f, 0.f)) << y;  // misses
        for (uint32_t x = (y == 0 ? 1 : 0); x < 5; ++x) {
            EXPECT_EQ(z.at(x, y).x, 2.f + 0.25f * float(x) + 0.5f * float(y));
            // The larger slope (0.5 per row); the miss beside x = 4 and the NaN do not count as slope.
            EXPECT_EQ(z.at(x, y).y, 0.5f) << x << "," << y;
        }
    }
    EXPECT_EQ(z.at(0, 0), glm::vec2(-1.f, 0.f));
    // A lone surface pixel has no neighbour to measure a slope against.
    Texture lone(3, 1, Format::RG32F);
    lone.view<glm::vec2>().at(0, 0) = {0.f, 0.f};
    lone.view<glm::vec2>().at(1, 0) = {5.f, 0.f};
    lone.view<glm::vec2>().at(2, 0) = {-3.f, 0.f};
    depthToLinearZ(lone.view<glm::vec2>(), 1e9f);
    EXPECT_EQ(lone.view<glm::vec2>().at(1, 0), glm::vec2(5.f, 0.f));
    EXPECT_EQ(lone.view<glm::vec2>().at(0, 0).x, -1.f);
    EXPECT_EQ(lone.view<glm::vec2>().at(2, 0).x, -1.f);
}

TEST(SequenceConversions, CameraNormalsTurnByTheInverseOfWorldToCamera) {
    // A camera yawed 90 degrees: world +x is camera -z, world +z is camera +x (p_camera = p_world M, row vectors).
    const std::array<float, 16> worldToCamera = {0, 0, -1, 0,  //
                                                 0, 1, 0, 0,   //
                                                 1, 0, 0, 0,   //
                                                 5, 6, 7, 1};  // the translation does not touch directions
    const glm::vec3 worldX = cameraNormalToWorld({0, 0, -1}, worldToCamera);
    EXPECT_NEAR(worldX.x, 1.f, 1e-6f);
    EXPECT_NEAR(glm::length(worldX - glm::vec3(1, 0, 0)), 0.f, 1e-6f);
    EXPECT_NEAR(glm::length(cameraNormalToWorld({1, 0, 0}, worldToCamera) - glm::vec3(0, 0, 1)), 0.f, 1e-6f);
    EXPECT_NEAR(glm::length(cameraNormalToWorld({0, 2, 0}, worldToCamera) - glm::vec3(0, 1, 0)), 0.f, 1e-6f);
    EXPECT_EQ(cameraNormalToWorld({0, 0, 0}, worldToCamera), glm::vec3(0.f));  // no surface
}

TEST(SequenceConversions, ObjectIndicesBecomeMeshIdsAndNonFiniteSamplesZero) {
    EXPECT_EQ(objectIndexToMeshId(0.f), 0u);
    EXPECT_EQ(objectIndexToMeshId(3.f), 3u);
    EXPECT_EQ(objectIndexToMeshId(2.9999f), 3u);
    EXPECT_EQ(objectIndexToMeshId(-1.f), ~0u);
    EXPECT_EQ(objectIndexToMeshId(std::numeric_limits<float>::quiet_NaN()), ~0u);
    EXPECT_EQ(objectIndexToMeshId(std::numeric_limits<float>::infinity()), ~0u);
    Texture t(3, 2, Format::RGBA32F);
    auto v = t.view<glm::vec4>();
    v.at(0, 0) = {1, std::numeric_limits<float>::infinity(), 2, 3};
    v.at(2, 1) = {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::infinity(), 4, 5};
    EXPECT_EQ(zeroNonFinite(t), 3u);
    EXPECT_EQ(v.at(0, 0), glm::vec4(1, 0, 2, 3));
    EXPECT_EQ(v.at(2, 1), glm::vec4(0, 0, 4, 5));
    EXPECT_EQ(zeroNonFinite(t), 0u);
}
