// What ImageSequence's conversions make of extreme inputs (SequenceConversions.h): values as large as floats go,
// denormals, NaN and infinities in albedo, normals, depth and motion, and camera matrices that are not finite,
// singular or scaled far from 1. Every output is finite and in its channel's range, each replacement is counted, and
// a camera matrix that cannot turn normals is refused.
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <limits>

#include "../SequenceConversions.h"
#include "loom/Error.h"

using namespace loom;
using namespace loom::sequence;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
const float kNaN = std::numeric_limits<float>::quiet_NaN();

/// A camera yawed 90 degrees (world +x is camera -z), every entry of its rotation times `scale`.
std::array<float, 16> yawedCamera(float scale) {
    return {0, 0, -scale, 0, 0, scale, 0, 0, scale, 0, 0, 0, 5, 6, 7, 1};
}

Texture filled(uint32_t w, uint32_t h, Format f, float v) {
    Texture t(w, h, f);
    const uint32_t channels = formatInfo(f).channels;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t i = 0; i < w * channels; ++i) reinterpret_cast<float*>(t.row(y))[i] = v;
    return t;
}

}  // namespace

TEST(SequenceInputs, AlbedoBeyondAnyReflectanceIsClampedAndCounted) {
    Texture albedo = filled(4, 3, Format::RGBA32F, 0.5f);
    const auto a = albedo.view<glm::vec4>();
    a.at(0, 0) = {1e38f, -1e38f, FLT_MAX, 1.f};
    a.at(1, 0) = {1e-40f, kNaN, 1.5f, 1.f};  // a denormal is a (tiny) reflectance; 1.5 is Blender's shiny albedo
    FrameChannels f;
    f.reflectances = {&albedo};
    const Replaced r = convertFrame(f, {});
    EXPECT_EQ(a.at(0, 0), glm::vec4(kMaxReflectance, 0.f, kMaxReflectance, 1.f));
    EXPECT_EQ(a.at(1, 0), glm::vec4(1e-40f, 0.f, 1.5f, 1.f));
    EXPECT_EQ(r.outOfRange, 3u);
    EXPECT_EQ(r.nonFinite, 1u);
    EXPECT_EQ(a.at(3, 2), glm::vec4(0.5f));  // the rest keeps its bits
}

TEST(SequenceInputs, CameraMatricesThatCannotTurnNormalsAreRefused) {
    EXPECT_EQ(worldToCameraProblem(yawedCamera(1.f)), "");
    EXPECT_EQ(worldToCameraProblem(yawedCamera(3e37f)), "");  // a scale does not change directions
    EXPECT_EQ(worldToCameraProblem(yawedCamera(1e-30f)), "");
    for (const float bad : {kInf, -kInf, kNaN}) {
        std::array<float, 16> m = yawedCamera(1.f);
        m[5] = bad;
        EXPECT_NE(worldToCameraProblem(m).find("entry [1][1]"), std::string::npos) << bad;
    }
    std::array<float, 16> huge = yawedCamera(1.f);
    huge[2] = 3e38f;  // one entry dwarfs the rest: the rotation is singular to float precision
    EXPECT_NE(worldToCameraProblem(huge).find("singular"), std::string::npos);
    std::array<float, 16> flat = yawedCamera(1.f);
    flat[4] = flat[5] = flat[6] = 0.f;
    EXPECT_NE(worldToCameraProblem(flat).find("singular"), std::string::npos);
    try {
        requireUsableWorldToCamera(huge, "Frames.normals", "frame_0001.exr");
        FAIL() << "accepted";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_EQ(e.info().file, "frame_0001.exr");
        EXPECT_NE(e.info().what.find("worldToCamera"), std::string::npos);
        EXPECT_NE(e.info().suggestion.find("normals=world"), std::string::npos);
    }
}

TEST(SequenceInputs, CameraNormalsTurnThroughScaledMatricesWithoutOverflow) {
    for (const float scale : {1.f, 3e37f, 1e-30f}) {
        Texture n = filled(2, 1, Format::RGBA32F, 0.f);
        n.view<glm::vec4>().at(0, 0) = {0.f, 0.f, -1.f, 0.f};
        n.view<glm::vec4>().at(1, 0) = {0.f, 0.f, 0.f, 0.f};
        FrameChannels f;
        f.normW = &n;
        ConversionSettings s;
        s.worldToCamera = yawedCamera(scale);
        const Replaced r = convertFrame(f, s);
        EXPECT_EQ(r.nonFinite, 0u) << scale;
        const glm::vec4 v = n.view<glm::vec4>().at(0, 0);
        EXPECT_NEAR(glm::length(glm::vec3(v) - glm::vec3(1, 0, 0)), 0.f, 1e-6f) << scale;
        EXPECT_EQ(n.view<glm::vec4>().at(1, 0), glm::vec4(0.f));
    }
}

TEST(SequenceInputs, NormalsOfAnyLengthBecomeUnitOrZero) {
    EXPECT_EQ(unitNormal({0.f, 0.6f, 0.8f, 7.f}), glm::vec4(0.f, 0.6f, 0.8f, 0.f));  // keeps its bits
    const glm::vec4 huge = unitNormal({3e38f, 3e38f, 0.f, 0.f});
    EXPECT_NEAR(huge.x, std::sqrt(0.5f), 1e-6f);
    EXPECT_NEAR(huge.y, std::sqrt(0.5f), 1e-6f);
    const glm::vec4 tiny = unitNormal({0.f, 1e-40f, 0.f, 0.f});
    EXPECT_EQ(tiny, glm::vec4(0.f, 1.f, 0.f, 0.f));
    EXPECT_EQ(unitNormal({kNaN, 1.f, 0.f, 0.f}), glm::vec4(0.f));
    EXPECT_EQ(unitNormal({kInf, 1.f, 0.f, 0.f}), glm::vec4(0.f));
}

TEST(SequenceInputs, MotionAndLinearZKeepToTheirRanges) {
    Texture mvec = filled(3, 1, Format::RG32F, 0.f);
    mvec.view<glm::vec2>().at(0, 0) = {3e38f, -3e38f};
    mvec.view<glm::vec2>().at(1, 0) = {0.25f, -0.5f};
    Texture z = filled(4, 1, Format::RG32F, 0.f);
    z.view<glm::vec2>().at(0, 0) = {-1.f, 0.f};    // a miss
    z.view<glm::vec2>().at(1, 0) = {0.f, 0.f};     // depth 0: no surface can be at the eye
    z.view<glm::vec2>().at(2, 0) = {2.f, -1e38f};  // a negative slope
    z.view<glm::vec2>().at(3, 0) = {3e38f, 1.f};   // far, but a surface
    FrameChannels f;
    f.mvec = &mvec;
    f.linearZ = &z;
    const Replaced r = convertFrame(f, {});
    EXPECT_EQ(mvec.view<glm::vec2>().at(0, 0), glm::vec2(kMaxMotionUv, -kMaxMotionUv));
    EXPECT_EQ(mvec.view<glm::vec2>().at(1, 0), glm::vec2(0.25f, -0.5f));
    EXPECT_EQ(z.view<glm::vec2>().at(0, 0), glm::vec2(-1.f, 0.f));
    EXPECT_EQ(z.view<glm::vec2>().at(1, 0), glm::vec2(-1.f, 0.f));
    EXPECT_EQ(z.view<glm::vec2>().at(2, 0), glm::vec2(2.f, 0.f));
    EXPECT_EQ(z.view<glm::vec2>().at(3, 0), glm::vec2(3e38f, 1.f));
    EXPECT_EQ(r.outOfRange, 4u);  // two motion components, the depth of 0, the negative slope
    EXPECT_EQ(r.nonFinite, 0u);
    // Pixels as motion: FLT_MAX pixels in a 1-pixel frame stays finite, and in range.
    Texture pixels = filled(1, 1, Format::RG32F, -FLT_MAX);
    FrameChannels p;
    p.mvec = &pixels;
    ConversionSettings s;
    s.motion = MotionKind::PixelsFromPrevious;
    s.motionYUp = true;
    convertFrame(p, s);
    EXPECT_EQ(pixels.view<glm::vec2>().at(0, 0), glm::vec2(kMaxMotionUv, -kMaxMotionUv));
}
