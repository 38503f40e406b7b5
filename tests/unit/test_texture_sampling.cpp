// Texture sampling (SurfaceKernels.h sampleTexture): wrap modes against GL's
// definition, nearest and bilinear filters, and the uv transform, on tiny
// images built in code. Exact checks: the chosen coordinates put bilinear
// weights at 0 or 1/2, where the filter's arithmetic is exact.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/glm.hpp>
#include <vector>

#include "loom/SceneView.h"
#include "loom/SurfaceKernels.h"

using namespace loom;

namespace {

/// A 4 x 2 linear image whose texels all differ, as the only image of a view.
struct OneImage {
    static constexpr uint32_t kW = 4, kH = 2;
    std::vector<glm::u8vec4> texels;
    ImageView8 image;
    SceneView view;
    OneImage() {
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x)
                texels.emplace_back(uint8_t(10 + 60 * x), uint8_t(20 + 100 * y), uint8_t(7 * x + 3 * y), 255);
        image = ImageView8{texels.data(), kW, kH};
        view.images = &image;
        view.imageCount = 1;
    }
    /// Texel (x, y) as a linear sample returns it.
    glm::vec4 texel(uint32_t x, uint32_t y) const { return glm::vec4(texels[y * kW + x]) / 255.f; }
    glm::vec4 sample(const TextureRef& t, float u, float v) const { return sampleTexture(view, t, {u, v}, false); }
};

TextureRef ref(TextureWrap s, TextureWrap t, bool nearest) {
    TextureRef r;
    r.image = 0;
    r.wrapS = s;
    r.wrapT = t;
    r.nearest = nearest ? 1u : 0u;
    return r;
}

/// v at the centre of row y: bilinear weights (0, 1) between rows, so the row is read alone.
float rowCentre(uint32_t y) {
    return (float(y) + 0.5f) / float(OneImage::kH);
}

}  // namespace

// GL 4.5, table 8.20, for n = 3 over i = -7 .. 8.
TEST(TextureSampling, WrapTexelFollowsGl) {
    const int repeat[] = {2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2};
    const int clamp[] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 2, 2, 2, 2, 2, 2, 2};
    const int mirrored[] = {0, 0, 1, 2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0, 1, 2};
    for (int i = -7; i <= 8; ++i) {
        SCOPED_TRACE("i = " + std::to_string(i));
        EXPECT_EQ(wrapTexel(i, 3, TextureWrap::Repeat), repeat[i + 7]);
        EXPECT_EQ(wrapTexel(i, 3, TextureWrap::ClampToEdge), clamp[i + 7]);
        EXPECT_EQ(wrapTexel(i, 3, TextureWrap::MirroredRepeat), mirrored[i + 7]);
    }
    // One texel: every mode reads it.
    for (int i = -3; i <= 3; ++i)
        for (TextureWrap w : {TextureWrap::Repeat, TextureWrap::ClampToEdge, TextureWrap::MirroredRepeat})
            EXPECT_EQ(wrapTexel(i, 1, w), 0);
}

// Outside [0, 1] a clamped axis reads its edge texel, with either filter; the other axis keeps its own mode.
TEST(TextureSampling, ClampToEdgeReadsTheEdgeTexel) {
    const OneImage img;
    for (bool nearest : {false, true}) {
        SCOPED_TRACE(nearest ? "nearest" : "bilinear");
        const TextureRef clampS = ref(TextureWrap::ClampToEdge, TextureWrap::Repeat, nearest);
        for (uint32_t y = 0; y < OneImage::kH; ++y) {
            // u * 4 - 0.5 at -2 (weight 0) and at 5.5, 8.5 (weights 1/2 on two copies of the edge texel).
            EXPECT_EQ(img.sample(clampS, -0.375f, rowCentre(y)), img.texel(0, y));
            EXPECT_EQ(img.sample(clampS, 1.5f, rowCentre(y)), img.texel(3, y));
            EXPECT_EQ(img.sample(clampS, 2.25f, rowCentre(y)), img.texel(3, y));
            // v repeats: one period up reads the same row.
            EXPECT_EQ(img.sample(clampS, -0.375f, rowCentre(y) + 1.f), img.texel(0, y));
        }
        const TextureRef clampT = ref(TextureWrap::Repeat, TextureWrap::ClampToEdge, nearest);
        // v * 2 - 0.5 at -1.5 and 3.5: row 0 below, row 1 above; u at texel 2's centre.
        EXPECT_EQ(img.sample(clampT, 0.625f, -0.5f), img.texel(2, 0));
        EXPECT_EQ(img.sample(clampT, 0.625f, 2.f), img.texel(2, 1));
        EXPECT_EQ(img.sample(clampT, 1.625f, 2.f), img.texel(2, 1));  // u repeats
    }
    // Nearest clamps any coordinate outside, not only the convenient ones.
    const TextureRef nearestClamp = ref(TextureWrap::ClampToEdge, TextureWrap::ClampToEdge, true);
    EXPECT_EQ(img.sample(nearestClamp, -0.3f, -7.1f), img.texel(0, 0));
    EXPECT_EQ(img.sample(nearestClamp, 1.7f, 1e6f), img.texel(3, 1));
    EXPECT_EQ(img.sample(nearestClamp, -1e30f, 0.2f), img.texel(0, 0));
}

// Mirrored repeat reflects at every integer: u = 1.25 reads what u = 0.75 reads, u = -0.25 what u = 0.25 reads.
TEST(TextureSampling, MirroredRepeatReflects) {
    const OneImage img;
    const TextureRef mirror = ref(TextureWrap::MirroredRepeat, TextureWrap::MirroredRepeat, false);
    const TextureRef repeat = ref(TextureWrap::Repeat, TextureWrap::Repeat, false);
    const float v = rowCentre(1);
    // Bilinear, at texel boundaries (u * 4 - 0.5 at half-integers: weights 1/2).
    EXPECT_EQ(img.sample(mirror, 1.25f, v), img.sample(mirror, 0.75f, v));
    EXPECT_EQ(img.sample(mirror, -0.25f, v), img.sample(mirror, 0.25f, v));
    EXPECT_EQ(img.sample(mirror, 2.25f, v), img.sample(mirror, 0.25f, v));           // period 2
    EXPECT_EQ(img.sample(mirror, 0.75f, -0.25f), img.sample(mirror, 0.75f, 0.25f));  // rows reflect too
    // u = 1.25 is half of texels 3 and 2 (4.5 reflected), where repeat reads half of texels 0 and 1.
    EXPECT_EQ(img.sample(mirror, 1.25f, v), 0.5f * img.texel(2, 1) + 0.5f * img.texel(3, 1));
    EXPECT_EQ(img.sample(repeat, 1.25f, v), img.sample(repeat, 0.25f, v));
    EXPECT_NE(img.sample(repeat, 1.25f, v), img.sample(mirror, 1.25f, v));
    // Elsewhere the two sides weigh the same texels in the opposite order (rounding may differ).
    for (float u = 0.02f; u < 1.f; u += 0.0625f) {
        const glm::vec4 a = img.sample(mirror, 2.f - u, v), b = img.sample(mirror, u, v);
        for (int c = 0; c < 4; ++c) EXPECT_NEAR(a[c], b[c], 1e-6f) << "u = " << u;
    }
    // Nearest, inside texels (at a boundary the reflected side owns the other texel, as in GL).
    const TextureRef mirrorNearest = ref(TextureWrap::MirroredRepeat, TextureWrap::MirroredRepeat, true);
    EXPECT_EQ(img.sample(mirrorNearest, 1.3f, v), img.texel(2, 1));
    EXPECT_EQ(img.sample(mirrorNearest, 0.7f, v), img.texel(2, 1));
    EXPECT_EQ(img.sample(mirrorNearest, -0.3f, v), img.sample(mirrorNearest, 0.3f, v));
    EXPECT_EQ(img.sample(mirrorNearest, 0.3f, -0.2f), img.texel(1, 0));
    EXPECT_EQ(img.sample(mirrorNearest, 0.3f, 1.2f), img.texel(1, 1));
}

// Nearest returns exactly one texel, texel (floor(u * w), floor(v * h)) wrapped; bilinear blends between them.
TEST(TextureSampling, NearestReturnsOneTexel) {
    const OneImage img;
    const TextureRef nearest = ref(TextureWrap::Repeat, TextureWrap::Repeat, true);
    const TextureRef bilinear = ref(TextureWrap::Repeat, TextureWrap::Repeat, false);
    int blended = 0;
    for (float v = -1.03f; v < 2.f; v += 0.11f) {
        for (float u = -1.01f; u < 2.f; u += 0.07f) {
            const int x = wrapTexel(int(std::floor(u * OneImage::kW)), OneImage::kW, TextureWrap::Repeat);
            const int y = wrapTexel(int(std::floor(v * OneImage::kH)), OneImage::kH, TextureWrap::Repeat);
            ASSERT_EQ(img.sample(nearest, u, v), img.texel(uint32_t(x), uint32_t(y))) << u << ", " << v;
            bool isTexel = false;
            for (uint32_t ty = 0; ty < OneImage::kH; ++ty)
                for (uint32_t tx = 0; tx < OneImage::kW; ++tx)
                    isTexel |= img.sample(bilinear, u, v) == img.texel(tx, ty);
            blended += isTexel ? 0 : 1;
        }
    }
    EXPECT_GT(blended, 100);  // the bilinear filter really blends, so the nearest result above is not a coincidence
    // sRGB slots decode the one texel.
    const glm::vec4 t = img.texel(1, 1);
    EXPECT_EQ(sampleTexture(img.view, nearest, {0.3f, 0.6f}, true),
              glm::vec4(srgbToLinear(t.r), srgbToLinear(t.g), srgbToLinear(t.b), t.a));
}

// The reference's transform is applied before wrapping and filtering.
TEST(TextureSampling, TransformMovesTheLookup) {
    const OneImage img;
    TextureRef plain = ref(TextureWrap::Repeat, TextureWrap::ClampToEdge, true);
    TextureRef moved = plain;
    // uv' = (2u + 0.25, -v + 1): scale, flip and offset.
    moved.transform = glm::mat3x2(glm::vec2(2.f, 0.f), glm::vec2(0.f, -1.f), glm::vec2(0.25f, 1.f));
    const glm::vec2 t = transformUv(moved, {0.1f, 0.2f});
    EXPECT_NEAR(t.x, 0.45f, 1e-7f);
    EXPECT_NEAR(t.y, 0.8f, 1e-7f);
    EXPECT_EQ(transformUv(plain, {0.1f, 0.2f}), glm::vec2(0.1f, 0.2f));  // identity, bit for bit
    // Inside texels of the moved lookup: 8u + 1 and 2 - 2v keep off integers.
    for (float v : {0.1f, 0.4f, 0.6f, 0.9f})
        for (int k = 1; k <= 8; ++k) {
            const float u = (float(k) - 0.5f) / 8.f;
            EXPECT_EQ(img.sample(moved, u, v), img.sample(plain, 2.f * u + 0.25f, 1.f - v)) << u << ", " << v;
        }
    // No image: white, whatever the sampler.
    TextureRef none = moved;
    none.image = -1;
    EXPECT_EQ(img.sample(none, 0.3f, 0.3f), glm::vec4(1.f));
}

// A reference with no sampler and no transform samples exactly as Loom did before samplers were honoured
// (bilinear, repeat, the same arithmetic), so scenes without them render bit for bit as before.
TEST(TextureSampling, DefaultReferenceKeepsTheBilinearRepeatArithmetic) {
    const OneImage img;
    TextureRef plain;
    plain.image = 0;
    for (float v = -1.37f; v < 2.f; v += 0.173f)
        for (float u = -1.29f; u < 2.f; u += 0.117f) {
            const float fx = u * float(OneImage::kW) - 0.5f, fy = v * float(OneImage::kH) - 0.5f;
            const float x0f = std::floor(fx), y0f = std::floor(fy);
            auto at = [&](int dx, int dy) {
                const int x = ((int(x0f) + dx) % int(OneImage::kW) + int(OneImage::kW)) % int(OneImage::kW);
                const int y = ((int(y0f) + dy) % int(OneImage::kH) + int(OneImage::kH)) % int(OneImage::kH);
                return img.texel(uint32_t(x), uint32_t(y));
            };
            const glm::vec4 expected =
                glm::mix(glm::mix(at(0, 0), at(1, 0), fx - x0f), glm::mix(at(0, 1), at(1, 1), fx - x0f), fy - y0f);
            ASSERT_EQ(img.sample(plain, u, v), expected) << u << ", " << v;
        }
}
