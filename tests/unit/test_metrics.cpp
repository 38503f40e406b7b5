// Image metrics: closed forms, identities, OpenCV's SSIM, FLIP's known behaviour, the non-finite
// rule and determinism across thread counts.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <random>

#include "TestUtil.h"
#include "loom/KernelMath.h"
#include "loom/MetricKernels.h"
#include "loom/Metrics.h"
#include "loom/Parallel.h"

#ifdef LOOM_TEST_HAVE_OPENCV_QUALITY
#include <opencv2/core.hpp>
#include <opencv2/quality/qualityssim.hpp>
#endif

using namespace loom;

namespace {

Texture makeImage(uint32_t w, uint32_t h, const std::function<glm::vec4(uint32_t, uint32_t)>& fn) {
    Texture t(w, h, Format::RGBA32F);
    auto v = t.view<glm::vec4>();
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) v.at(x, y) = fn(x, y);
    return t;
}

Texture constantImage(uint32_t w, uint32_t h, glm::vec4 c) {
    return makeImage(w, h, [&](uint32_t, uint32_t) { return c; });
}

/// A textured test scene in [0, 1]: smooth gradients, a disc and fine stripes.
glm::vec4 scene(uint32_t x, uint32_t y) {
    const float fx = float(x), fy = float(y);
    const float disc = (fx - 40) * (fx - 40) + (fy - 30) * (fy - 30) < 300.0f ? 0.6f : 0.0f;
    const float stripes = (x / 3 + y / 5) % 2 ? 0.2f : 0.0f;
    return {0.1f + 0.3f * fx / 96.0f + disc, 0.2f + 0.5f * fy / 80.0f * (1.0f - disc) + stripes,
            0.3f + 0.2f * std::sin(0.3f * fx) * std::cos(0.2f * fy), 1.0f};
}

Texture withNoise(const Texture& src, float sigma, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> n(0.0f, sigma);
    auto s = src.view<glm::vec4>();
    return makeImage(src.width(), src.height(), [&](uint32_t x, uint32_t y) {
        glm::vec4 v = s.at(x, y);
        return glm::vec4(v.x + n(rng), v.y + n(rng), v.z + n(rng), 1.0f);
    });
}

double srgbOetf(double x) {
    x = std::clamp(x, 0.0, 1.0);
    return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
}

uint64_t bits(double v) {
    uint64_t b;
    std::memcpy(&b, &v, sizeof b);
    return b;
}

}  // namespace

TEST(Metrics, ToneMapMatchesSrgbOetf) {
    double worst = 0.0;
    for (int i = 0; i <= 200000; ++i) {
        const float x = float(i) / 200000.0f;
        worst = std::max(worst, std::abs(double(ldrToneMap(x)) - srgbOetf(x)));
    }
    EXPECT_LT(worst, 1e-6);
    EXPECT_EQ(ldrToneMap(-3.0f), 0.0f);
    EXPECT_EQ(ldrToneMap(7.0f), 1.0f);
    EXPECT_EQ(ldrToneMap(std::numeric_limits<float>::quiet_NaN()), 0.0f);
}

TEST(Metrics, IdenticalImages) {
    const Texture a = withNoise(makeImage(96, 80, scene), 0.3f, 1);  // HDR-ish, some values > 1
    EXPECT_EQ(relMSE(a, a).value, 0.0);
    EXPECT_EQ(smape(a, a).value, 0.0);
    EXPECT_EQ(psnr(a, a).value, kPsnrCap);
    EXPECT_NEAR(ssim(a, a).value, 1.0, 1e-6);
    EXPECT_EQ(flip(a, a).value, 0.0);
    EXPECT_EQ(temporalError(a, a, a, a).value, 0.0);
}

TEST(Metrics, ConstantOffsetClosedForms) {
    const glm::vec4 y(0.2f, 0.4f, 0.1f, 1.0f);
    const float d = 0.05f;
    const Texture ref = constantImage(64, 64, y);
    const Texture test = constantImage(64, 64, y + glm::vec4(d, d, d, 0.0f));
    double rel = 0.0, mse = 0.0;
    for (int c = 0; c < 3; ++c) {
        const double diff = double(y[c] + d) - double(y[c]);  // as the floats hold it
        rel += diff * diff / (double(y[c]) * y[c] + kRelMseEpsilon) / 3.0;
        const double l = double(ldrToneMap(y[c] + d)) - double(ldrToneMap(y[c]));
        mse += l * l / 3.0;
    }
    EXPECT_NEAR(relMSE(test, ref).value, rel, 1e-12 * rel);
    EXPECT_NEAR(psnr(test, ref).value, 10.0 * std::log10(1.0 / mse), 1e-9);
    // And against the exact OETF (the table's error is below 1e-6).
    double mseExact = 0.0;
    for (int c = 0; c < 3; ++c) mseExact += std::pow(srgbOetf(y[c] + d) - srgbOetf(y[c]), 2) / 3.0;
    EXPECT_NEAR(psnr(test, ref).value, 10.0 * std::log10(1.0 / mseExact), 1e-3);
}

TEST(Metrics, ScaledImageRelMseAndSmape) {
    for (float yv : {0.05f, 0.5f, 3.0f}) {
        for (float s : {0.5f, 2.0f, 1.1f}) {
            const Texture ref = constantImage(32, 48, {yv, yv, yv, 1});
            const Texture test = constantImage(32, 48, {s * yv, s * yv, s * yv, 1});
            const double y = yv, x = double(s * yv);
            EXPECT_NEAR(relMSE(test, ref).value, (x - y) * (x - y) / (y * y + kRelMseEpsilon), 1e-12)
                << "s " << s << " y " << yv;
            // (s-1)^2 y^2 / (y^2 + eps) up to the float rounding of s*y.
            EXPECT_NEAR(relMSE(test, ref).value, (s - 1.0) * (s - 1.0) * y * y / (y * y + kRelMseEpsilon), 1e-6);
            EXPECT_NEAR(smape(test, ref).value, std::abs(x - y) / (std::abs(x) + y + kSmapeEpsilon), 1e-12);
        }
    }
}

TEST(Metrics, SsimOfConstantImagesFollowsTheFormula) {
    const glm::vec4 a(0.1f, 0.5f, 0.9f, 1), b(0.3f, 0.45f, 0.2f, 1);
    const Texture ta = constantImage(40, 40, a), tb = constantImage(40, 40, b);
    double expected = 0.0;
    const double c1 = 1e-4;
    for (int c = 0; c < 3; ++c) {
        const double x = ldrToneMap(a[c]), y = ldrToneMap(b[c]);
        expected += (2 * x * y + c1) / (x * x + y * y + c1) / 3.0;  // contrast-structure term is C2/C2
    }
    // The window statistics are taken about a pixel of the tile, so a constant image's variances and covariance
    // are exactly 0 and the contrast-structure term is exactly C2/C2. What is left is float rounding (u = 2^-24)
    // with the same tone-mapped values (ldrToneMap agrees bit for bit with the planes): at most 8 roundings in a
    // pixel's value (two products of sums, the division) and 63 in a tile row's float sum of at most 64 values,
    // so a relative error below 71 u = 4.3e-6 of an SSIM of at most 1.
    EXPECT_NEAR(ssim(ta, tb).value, expected, 71.0 * std::ldexp(1.0, -24));
    EXPECT_LT(ssim(ta, tb).value, 0.99);
}

TEST(Metrics, SsimMatchesOpenCvQuality) {
#ifndef LOOM_TEST_HAVE_OPENCV_QUALITY
    GTEST_SKIP() << "OpenCV's quality module (libopencv-contrib-dev) was not found at configure time";
#else
    const uint32_t w = 96, h = 80;
    const Texture ref = makeImage(w, h, scene);
    auto rv = ref.view<glm::vec4>();
    std::vector<std::pair<const char*, Texture> > cases;
    cases.emplace_back("noise", withNoise(ref, 0.05f, 7));
    cases.emplace_back("blur", makeImage(w, h, [&](uint32_t x, uint32_t y) {
                           glm::vec4 s(0.0f);
                           for (int dy = -1; dy <= 1; ++dy)
                               for (int dx = -1; dx <= 1; ++dx)
                                   s += rv.at(uint32_t(std::clamp(int(x) + dx, 0, int(w) - 1)),
                                              uint32_t(std::clamp(int(y) + dy, 0, int(h) - 1)));
                           return s / 9.0f;
                       }));
    cases.emplace_back("shift",
                       makeImage(w, h, [&](uint32_t x, uint32_t y) { return rv.at(std::min(x + 2, w - 1), y); }));
    cases.emplace_back("contrast", makeImage(w, h, [&](uint32_t x, uint32_t y) {
                           return glm::vec4(0.35f) + 0.6f * (rv.at(x, y) - glm::vec4(0.35f));
                       }));
    auto toMat = [&](const Texture& t) {
        cv::Mat m(int(h), int(w), CV_32FC3);
        auto v = t.view<glm::vec4>();
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x)
                for (int c = 0; c < 3; ++c) m.at<cv::Vec3f>(int(y), int(x))[c] = 255.0f * ldrToneMap(v.at(x, y)[c]);
        return m;
    };
    const cv::Mat refMat = toMat(ref);
    for (const auto& [name, test] : cases) {
        const cv::Scalar s = cv::quality::QualitySSIM::compute(refMat, toMat(test), cv::noArray());
        const double expected = (s[0] + s[1] + s[2]) / 3.0;
        const double got = ssim(test, ref).value;
        EXPECT_NEAR(got, expected, 1e-4) << name;
        EXPECT_LT(got, 0.999) << name;  // the distortion is visible to both
        // SSIM is symmetric in its arguments.
        EXPECT_NEAR(ssim(ref, test).value, got, 1e-6) << name;
    }
#endif
}

TEST(Metrics, SsimMapAveragesToTheValue) {
    const Texture ref = makeImage(70, 50, scene);
    const Texture test = withNoise(ref, 0.1f, 3);
    Texture map(70, 50, Format::R32F);
    const double v = ssim(test, ref, &map).value;
    double sum = 0.0;
    for (uint32_t y = 0; y < 50; ++y)
        for (uint32_t x = 0; x < 70; ++x) sum += map.texel(x, y, 0);
    EXPECT_NEAR(sum / (70 * 50), v, 1e-5);
}

TEST(Metrics, FlipBlackVersusWhiteIsNearOne) {
    const Texture black = constantImage(64, 64, {0, 0, 0, 1}), white = constantImage(64, 64, {1, 1, 1, 1});
    const double v = flip(black, white).value;
    EXPECT_GT(v, 0.95);
    EXPECT_LE(v, 1.0);
}

TEST(Metrics, FlipSmallColourShiftGivesSmallError) {
    const Texture grey = constantImage(64, 64, {0.5f, 0.5f, 0.5f, 1});
    const Texture shifted = constantImage(64, 64, {0.51f, 0.5f, 0.5f, 1});
    const Texture larger = constantImage(64, 64, {0.6f, 0.5f, 0.5f, 1});
    const double small = flip(shifted, grey).value, big = flip(larger, grey).value;
    EXPECT_GT(small, 0.0);
    EXPECT_LT(small, 0.1);
    EXPECT_GT(big, small);
}

TEST(Metrics, FlipIsMonotoneInNoiseAndSymmetric) {
    const Texture ref = makeImage(96, 80, scene);
    double last = 0.0;
    for (float sigma : {0.005f, 0.02f, 0.05f, 0.15f, 0.4f}) {
        const Texture test = withNoise(ref, sigma, 11);
        const double v = flip(test, ref).value;
        EXPECT_GT(v, last) << "sigma " << sigma;
        EXPECT_LT(v, 1.0);
        // The colour and the feature terms are both symmetric in the two images.
        EXPECT_NEAR(flip(ref, test).value, v, 1e-5) << "sigma " << sigma;
        last = v;
    }
}

TEST(Metrics, FlipErrorImageAndViewing) {
    EXPECT_NEAR(FlipViewing{}.pixelsPerDegree(), 67.02, 0.01);
    const Texture ref = makeImage(64, 64, scene);
    const Texture test = withNoise(ref, 0.05f, 5);
    Texture map(64, 64, Format::R32F);
    const double v = flip(test, ref, &map).value;
    double sum = 0.0, mx = 0.0;
    for (uint32_t y = 0; y < 64; ++y)
        for (uint32_t x = 0; x < 64; ++x) {
            sum += map.texel(x, y, 0);
            mx = std::max(mx, double(map.texel(x, y, 0)));
        }
    EXPECT_NEAR(sum / (64 * 64), v, 1e-6);
    EXPECT_LE(mx, 1.0);
    // Seen from farther away (more pixels per degree) the same noise is less visible.
    FlipViewing far;
    far.distanceMeters = 2.0;
    EXPECT_LT(flip(test, ref, nullptr, far).value, v);
}

TEST(Metrics, NonFinitePixelsAreCountedAndNeverNaN) {
    const Texture ref = makeImage(64, 64, scene);
    Texture test = withNoise(ref, 0.02f, 9);
    const double cleanRel = relMSE(test, ref).value, cleanSmape = smape(test, ref).value;
    const double cleanPsnr = psnr(test, ref).value, cleanSsim = ssim(test, ref).value,
                 cleanFlip = flip(test, ref).value;
    auto v = test.view<glm::vec4>();
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    v.at(3, 4).x = nan;
    v.at(30, 40).y = inf;
    v.at(50, 10) = glm::vec4(-inf, nan, inf, 1);
    Texture relMap(64, 64, Format::R32F), flipMap(64, 64, Format::R32F);
    const MetricValue r = relMSE(test, ref, &relMap), s = smape(test, ref), p = psnr(test, ref), q = ssim(test, ref);
    const MetricValue f = flip(test, ref, &flipMap);
    for (const MetricValue& m : {r, s, p, q, f}) {
        EXPECT_TRUE(std::isfinite(m.value));
        EXPECT_EQ(m.nonFinite, 3u);
    }
    // RelMSE excludes the 3 pixels: the mean of the others, which differs little from the clean value.
    double sum = 0.0;
    for (uint32_t y = 0; y < 64; ++y)
        for (uint32_t x = 0; x < 64; ++x) sum += relMap.texel(x, y, 0);
    EXPECT_NEAR(r.value, sum / (64 * 64 - 3), 1e-6 * r.value);
    EXPECT_NEAR(r.value, cleanRel, 0.01 * cleanRel);
    // The bounded metrics count them as maximal error: worse than the clean image.
    EXPECT_GT(s.value, cleanSmape);
    EXPECT_LT(p.value, cleanPsnr);
    EXPECT_LT(q.value, cleanSsim);
    EXPECT_GT(f.value, cleanFlip);
    EXPECT_EQ(flipMap.texel(3, 4, 0), 1.0f);
    EXPECT_EQ(flipMap.texel(50, 10, 0), 1.0f);
    // SMAPE: each non-finite channel contributes exactly 1.
    Texture smapeMap(64, 64, Format::R32F);
    smape(test, ref, &smapeMap);
    EXPECT_FLOAT_EQ(smapeMap.texel(50, 10, 0), 1.0f);
    // A non-finite reference is handled the same way.
    EXPECT_EQ(flip(ref, test).nonFinite, 3u);
    EXPECT_TRUE(std::isfinite(temporalError(test, ref, ref, ref).value));
    EXPECT_EQ(temporalError(test, ref, ref, ref).nonFinite, 3u);
}

TEST(Metrics, TemporalErrorClosedForms) {
    const Texture a0 = makeImage(48, 32, scene);
    const Texture a1 = makeImage(48, 32, [](uint32_t x, uint32_t y) { return scene(x + 1, y); });
    const glm::vec4 off(0.3f, -0.2f, 0.1f, 0);
    auto shifted = [&](const Texture& t) {
        auto v = t.view<glm::vec4>();
        return makeImage(48, 32, [&](uint32_t x, uint32_t y) { return v.at(x, y) + off; });
    };
    // A constant bias has the reference's temporal derivative: zero error.
    EXPECT_NEAR(temporalError(shifted(a1), shifted(a0), a1, a0).value, 0.0, 1e-6);
    // A static reference and a test that changes by d per frame: error |d|.
    const Texture r = constantImage(48, 32, {0.5f, 0.5f, 0.5f, 1});
    const Texture t0 = constantImage(48, 32, {0.5f, 0.5f, 0.5f, 1}),
                  t1 = constantImage(48, 32, {0.75f, 0.25f, 0.5f, 1});
    EXPECT_NEAR(temporalError(t1, t0, r, r).value, (0.25 + 0.25 + 0.0) / 3.0, 1e-7);
    EXPECT_EQ(temporalError(t1, t0, t1, t0).value, 0.0);
}

TEST(Metrics, FlickerOfAlternatingFramesIsHalfTheSwing) {
    FlickerAccumulator acc;
    EXPECT_EQ(acc.value().value, 0.0);
    const Texture lo = constantImage(40, 24, {0.2f, 0.2f, 0.2f, 1}), hi = constantImage(40, 24, {0.6f, 0.6f, 0.6f, 1});
    for (int i = 0; i < 10; ++i) acc.add(i % 2 ? hi : lo);
    EXPECT_EQ(acc.frames(), 10u);
    const double lumaLo = 0.2 * (kRec709R + kRec709G + kRec709B), lumaHi = 0.6 * (kRec709R + kRec709G + kRec709B);
    EXPECT_NEAR(acc.value().value, (lumaHi - lumaLo) / 2.0, 1e-7);
    // A NaN frame is skipped per pixel and reported.
    Texture bad = constantImage(40, 24, {0.2f, 0.2f, 0.2f, 1});
    bad.view<glm::vec4>().at(1, 1).x = std::numeric_limits<float>::quiet_NaN();
    acc.add(bad);
    const MetricValue v = acc.value();
    EXPECT_TRUE(std::isfinite(v.value));
    EXPECT_EQ(v.nonFinite, 1u);
    acc.reset();
    for (int i = 0; i < 5; ++i) acc.add(lo);
    EXPECT_EQ(acc.value().value, 0.0);
    EXPECT_THROW(acc.add(constantImage(8, 8, {0, 0, 0, 1})), Error);
}

TEST(Metrics, MismatchedInputsAreBadInput) {
    const Texture a = constantImage(16, 16, {0, 0, 0, 1}), b = constantImage(16, 17, {0, 0, 0, 1});
    EXPECT_THROW(relMSE(a, b), Error);
    EXPECT_THROW(ssim(a, b), Error);
    EXPECT_THROW(flip(a, b), Error);
    const Texture r8(16, 16, Format::RGBA8Unorm);
    EXPECT_THROW(psnr(a, r8), Error);
    Texture wrongMap(8, 8, Format::R32F);
    EXPECT_THROW(smape(a, a, &wrongMap), Error);
}

TEST(Metrics, DeterministicForAnyThreadCount) {
    // Larger than one tile in both directions, with odd sizes.
    const Texture ref = makeImage(150, 130, [](uint32_t x, uint32_t y) { return scene(x % 96, y % 80); });
    const Texture test = withNoise(ref, 0.1f, 21);
    std::vector<uint64_t> runs[2];
    std::vector<float> maps[2];
    for (int run = 0; run < 2; ++run) {
        ThreadLimit limit(run == 0 ? 1 : 2);
        Texture fm(150, 130, Format::R32F), sm(150, 130, Format::R32F);
        runs[run] = {bits(relMSE(test, ref).value),    bits(smape(test, ref).value),
                     bits(psnr(test, ref).value),      bits(ssim(test, ref, &sm).value),
                     bits(flip(test, ref, &fm).value), bits(temporalError(test, ref, ref, test).value)};
        FlickerAccumulator acc;
        acc.add(ref);
        acc.add(test);
        runs[run].push_back(bits(acc.value().value));
        for (uint32_t y = 0; y < 130; ++y)
            for (uint32_t x = 0; x < 150; ++x) {
                maps[run].push_back(fm.texel(x, y, 0));
                maps[run].push_back(sm.texel(x, y, 0));
            }
    }
    EXPECT_EQ(runs[0], runs[1]);
    EXPECT_TRUE(maps[0] == maps[1]);
}

TEST(Metrics, TinyAndThinImagesStayFiniteAndExact) {
    // Border paths: tiles narrower than the filter blocks and images smaller than the windows.
    for (auto [w, h] : {std::pair{1u, 1u}, {3u, 200u}, {200u, 3u}, {17u, 9u}, {65u, 33u}}) {
        const Texture ref = makeImage(w, h, [](uint32_t x, uint32_t y) { return scene(x % 96, y % 80); });
        const Texture test = withNoise(ref, 0.1f, w * 131 + h);
        EXPECT_EQ(flip(ref, ref).value, 0.0) << w << "x" << h;
        EXPECT_NEAR(ssim(ref, ref).value, 1.0, 1e-5) << w << "x" << h;
        const double f = flip(test, ref).value, s = ssim(test, ref).value;
        EXPECT_TRUE(std::isfinite(f) && f >= 0.0 && f <= 1.0) << w << "x" << h;
        EXPECT_TRUE(std::isfinite(s) && s <= 1.0) << w << "x" << h;
        EXPECT_TRUE(std::isfinite(psnr(test, ref).value)) << w << "x" << h;
    }
}

// The scalar tone map of loom/MetricKernels.h (what PSNR's kernels call, on the CPU and on a device) gives the bits
// of the vector path ldrToneMap: every float of [2^-12, 1] at a stride, the edges, and values outside [0, 1].
TEST(MetricKernels, ScalarToneMapMatchesTheVectorPath) {
    const float* table = ldrToneMapTable();
    std::vector<float> values = {0.f, -0.f, 1.f, 2.f, -1.f, 1e30f, 1e-30f, 0.001953125f, 0.0031308f, 0.5f};
    for (uint32_t b = floatBits(1.f / 4096.f); b <= floatBits(1.f); b += 97) values.push_back(bitsToFloat(b));
    for (float v : values) ASSERT_EQ(floatBits(ldrToneMapWith(table, v)), floatBits(ldrToneMap(v))) << v;
}

// RelMSE, SMAPE, PSNR and the temporal error summed on the emulated device (device views of device memory, as
// ErrorMeasure does) equal the CPU functions bit for bit, error images included, at 1 and 2 threads; the CPU
// functions, which read host views, refuse device memory.
TEST(MetricKernels, EmulatedSumsEqualTheCpuMetricsBitForBit) {
    const uint32_t w = 150, h = 67;
    Texture ref = makeImage(w, h, [](uint32_t x, uint32_t y) { return 3.f * scene(x % 96, y % 80); });
    Texture test = withNoise(ref, 0.3f, 5);
    auto tv = test.view<glm::vec4>();
    tv.at(3, 4).y = std::numeric_limits<float>::quiet_NaN();
    tv.at(140, 60).x = std::numeric_limits<float>::infinity();
    const Texture prev = withNoise(ref, 0.2f, 9);
    const auto upload = [](const Texture& host, Format f) {
        Texture t = Texture::onDevice(DeviceKind::Emulated, host.width(), host.height(), f);
        copyTexture(t, host);
        return t;
    };
    const Texture dTest = upload(test, Format::RGBA32F), dRef = upload(ref, Format::RGBA32F),
                  dPrev = upload(prev, Format::RGBA32F);
    const Texture hostTable = Texture::wrap(reinterpret_cast<std::byte*>(const_cast<float*>(ldrToneMapTable())),
                                            kOetfTableSize, 1, Format::R32F);
    const Texture dTable = upload(hostTable, Format::R32F);
    const auto t = dTest.deviceView<glm::vec4>(), r = dRef.deviceView<glm::vec4>(), p = dPrev.deviceView<glm::vec4>();
    for (unsigned threads : {1u, 2u}) {
        SCOPED_TRACE(threads);
        ThreadLimit limit(threads);
        Texture cpuMap(w, h, Format::R32F), deviceMap = Texture::onDevice(DeviceKind::Emulated, w, h, Format::R32F);
        Texture downloaded(w, h, Format::R32F);
        const auto expectSame = [&](MetricValue cpu, MetricSums device, double value, const char* what) {
            SCOPED_TRACE(what);
            EXPECT_EQ(bits(cpu.value), bits(value));
            EXPECT_EQ(cpu.nonFinite, device.nonFinite);
            copyTexture(downloaded, deviceMap);
            EXPECT_TRUE(downloaded.samePixels(cpuMap));
        };
        expectSame(relMSE(test, ref, &cpuMap), relMseSums(DeviceKind::Emulated, t, r, deviceMap.deviceView<float>()),
                   cappedMetricMean(relMseSums(DeviceKind::Emulated, t, r, {})), "relMSE");
        expectSame(smape(test, ref, &cpuMap), smapeSums(DeviceKind::Emulated, t, r, deviceMap.deviceView<float>()),
                   metricMean(smapeSums(DeviceKind::Emulated, t, r, {})), "smape");
        const float* table = dTable.deviceView<float>().data;
        expectSame(psnr(test, ref, &cpuMap), psnrSums(DeviceKind::Emulated, table, t, r, deviceMap.deviceView<float>()),
                   psnrOfSums(psnrSums(DeviceKind::Emulated, table, t, r, {})), "psnr");
        const MetricValue cpuTemporal = temporalError(test, prev, ref, prev);
        const MetricSums deviceTemporal = temporalSums(DeviceKind::Emulated, t, p, r, p);
        EXPECT_EQ(bits(cpuTemporal.value), bits(cappedMetricMean(deviceTemporal)));
        EXPECT_EQ(cpuTemporal.nonFinite, deviceTemporal.nonFinite);
        EXPECT_EQ(cpuTemporal.nonFinite, 2u);
    }
    EXPECT_THROW(relMSE(dTest, dRef), Error);
    EXPECT_THROW(psnr(dTest, ref), Error);
}
