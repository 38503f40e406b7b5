#pragma once
// The per-pixel math of the metrics that run where ErrorMeasure runs (docs/KERNELS.md; conventions in
// loom/Metrics.h and docs/METRICS.md): RelMSE, SMAPE, PSNR and the temporal-derivative error, written once as
// LOOM_HD functions, and their sums through reduceRows. The CPU (Metrics.cpp, on DeviceKind::Cpu) and the devices
// (passes/ErrorMeasure) call the same functions, so the sums are the same terms in the same order and agree bit for
// bit. Every product that meets a sum is an explicit fma, so a translation unit's contraction flag changes nothing.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <limits>

#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/Launch.h"
#include "loom/Metrics.h"
#include "loom/Texture.h"

namespace loom {

/// A metric's sums over pixels: the sum of the per-pixel terms (each the sum over R, G, B), the pixels that entered
/// the mean and those with a non-finite channel.
struct MetricSums {
    double sum = 0.0;
    uint64_t count = 0;
    uint64_t nonFinite = 0;
};

LOOM_HD inline MetricSums addMetricSums(const MetricSums& a, const MetricSums& b) {
    return {a.sum + b.sum, a.count + b.count, a.nonFinite + b.nonFinite};
}

LOOM_HD inline bool finiteRgb(const glm::vec4& v) {
    return isFinite(v.x) && isFinite(v.y) && isFinite(v.z);
}

// ---------------------------------------------------------------------------------------------------------------------
// Per-pixel terms

/// The sum over R, G, B of a pixel's RelMSE terms (x - y)^2 / (y^2 + eps), eps = kRelMseEpsilon.
LOOM_HD inline double relMsePixelSum(const glm::vec4& t, const glm::vec4& r) {
    double px = 0.0;
    for (int c = 0; c < 3; ++c) {
        const double d = double(t[c]) - double(r[c]);
        const double y = r[c];
        px += d * d / ::fma(y, y, kRelMseEpsilon);
    }
    return px;
}

/// RelMSE of one pixel: a finite pixel's term sum, or nothing but the count of a non-finite one.
LOOM_HD inline MetricSums relMseTerm(const glm::vec4& t, const glm::vec4& r) {
    if (!finiteRgb(t) || !finiteRgb(r)) return {0.0, 0, 1};
    return {relMsePixelSum(t, r), 1, 0};
}

/// SMAPE of one pixel: |x - y| / (|x| + |y| + eps) per channel, eps = kSmapeEpsilon; 1 for a non-finite one.
LOOM_HD inline MetricSums smapeTerm(const glm::vec4& t, const glm::vec4& r) {
    double px = 0.0;
    bool bad = false;
    for (int c = 0; c < 3; ++c) {
        const double a = t[c], b = r[c];
        if (!isFinite(t[c]) || !isFinite(r[c])) {
            px += 1.0;
            bad = true;
            continue;
        }
        px += ::fabs(a - b) / (::fabs(a) + ::fabs(b) + kSmapeEpsilon);
    }
    return {px, 1, uint64_t(bad)};
}

/// The temporal-derivative term |(x_t - x_{t-1}) - (y_t - y_{t-1})| summed over R, G, B; a pixel with a non-finite
/// channel in any of the four images is left out and counted.
LOOM_HD inline MetricSums temporalTerm(const glm::vec4& t, const glm::vec4& tPrev, const glm::vec4& r,
                                       const glm::vec4& rPrev) {
    if (!finiteRgb(t) || !finiteRgb(tPrev) || !finiteRgb(r) || !finiteRgb(rPrev)) return {0.0, 0, 1};
    double px = 0.0;
    for (int c = 0; c < 3; ++c) px += ::fabs((double(t[c]) - double(tPrev[c])) - (double(r[c]) - double(rPrev[c])));
    return {px, 1, 0};
}

// ---------------------------------------------------------------------------------------------------------------------
// The LDR tone map (ldrToneMap in loom/Metrics.h)

/// The OETF table: 9 octaves down to 2^-9 (below which the OETF is linear), 256 entries each, indexed by the
/// float's exponent and top 8 mantissa bits, plus 2 (x = 1 reads index 9 * 256 and the one after it).
inline constexpr int kOetfOctaves = 9;
inline constexpr int kOetfMantissaBits = 8;
inline constexpr int kOetfPerOctave = 1 << kOetfMantissaBits;
inline constexpr int kOetfTableSize = kOetfOctaves * kOetfPerOctave + 2;

/// The table in host memory (Metrics.cpp); a device copies it into its own memory.
const float* ldrToneMapTable();

/// OETF(clamp(x, 0, 1)) from `table`, linearly interpolated (NaN becomes 0). Each operation is the one of the vector
/// path of Metrics.cpp (max and min as x86's maxps and minps, the blend as an fma), so the two give the same bits.
LOOM_HD inline float ldrToneMapWith(const float* table, float v) {
    const float x = minf(maxf(v, 0.0f), 1.0f);
    const float lowest = 0.001953125f;  // 2^-9
    const uint32_t bits = floatBits(maxf(x, lowest));
    const int index = int(bits >> (23 - kOetfMantissaBits)) - ((127 - kOetfOctaves) << kOetfMantissaBits);
    const float frac =
        float(int(bits & ((1u << (23 - kOetfMantissaBits)) - 1u))) * (1.0f / float(1 << (23 - kOetfMantissaBits)));
    const float a = table[index], b = table[index + 1];
    const float curve = ::fmaf(frac, b - a, a);
    return x < lowest ? 12.92f * x : curve;
}

/// The non-finite rule of the tone-mapped metrics for one channel pair of [0, 1] values (test t, reference r), given
/// whether each was finite: the replaced value is the one farthest from the other image's. Returns true when either
/// was not finite.
LOOM_HD inline bool worstCase(float& t, float& r, bool tFinite, bool rFinite) {
    if (tFinite && rFinite) return false;
    if (!tFinite && !rFinite) {
        r = 0.0f;
        t = 1.0f;
    } else if (!tFinite) {
        t = r < 0.5f ? 1.0f : 0.0f;
    } else {
        r = t < 0.5f ? 1.0f : 0.0f;
    }
    return true;
}

/// Tone-mapped R, G, B of a pixel pair with the non-finite rule; returns true for a non-finite pixel.
LOOM_HD inline bool ldrPair(const float* table, const glm::vec4& test, const glm::vec4& ref, float t[3], float r[3]) {
    bool bad = false;
    for (int c = 0; c < 3; ++c) {
        const bool tf = isFinite(test[c]), rf = isFinite(ref[c]);
        t[c] = tf ? ldrToneMapWith(table, test[c]) : 0.0f;
        r[c] = rf ? ldrToneMapWith(table, ref[c]) : 0.0f;
        bad |= worstCase(t[c], r[c], tf, rf);
    }
    return bad;
}

/// PSNR's term of one pixel: the squared difference of the tone-mapped values summed over R, G, B.
LOOM_HD inline MetricSums psnrTerm(const float* table, const glm::vec4& test, const glm::vec4& ref) {
    float t[3], r[3];
    const bool bad = ldrPair(table, test, ref, t, r);
    double px = 0.0;
    for (int c = 0; c < 3; ++c) {
        const double d = double(t[c]) - double(r[c]);
        px = ::fma(d, d, px);
    }
    return {px, 1, uint64_t(bad)};
}

// ---------------------------------------------------------------------------------------------------------------------
// Sums over an image (reduceRows: each row left to right, then the rows top to bottom, on every device)

/// The sums of term(x, y) over width x height on `device`; where `error` has data, each pixel's term sum / 3 (the
/// per-pixel error image) is written into it.
template <class Term>
MetricSums sumMetric(DeviceKind device, uint32_t width, uint32_t height, ImageView<float> error, const Term& term) {
    return reduceRows(
        device, width, height, MetricSums{},
        [=] LOOM_HD(uint32_t x, uint32_t y) {
            const MetricSums s = term(x, y);
            if (error.data) error.at(x, y) = float(s.sum / 3.0);
            return s;
        },
        [] LOOM_HD(const MetricSums& a, const MetricSums& b) { return addMetricSums(a, b); });
}

// The sums of each metric. Internal linkage, as launchesReach: each translation unit keeps the launches it compiled
// (nvcc's reach cuda, the host compiler's refuse it), where one inline definition would stand for both.

static inline MetricSums relMseSums(DeviceKind device, MetricImage test, MetricImage ref, ImageView<float> error) {
    return sumMetric(device, test.width, test.height, error,
                     [=] LOOM_HD(uint32_t x, uint32_t y) { return relMseTerm(test.at(x, y), ref.at(x, y)); });
}

static inline MetricSums smapeSums(DeviceKind device, MetricImage test, MetricImage ref, ImageView<float> error) {
    return sumMetric(device, test.width, test.height, error,
                     [=] LOOM_HD(uint32_t x, uint32_t y) { return smapeTerm(test.at(x, y), ref.at(x, y)); });
}

/// `table`: ldrToneMapTable() on the CPU, a copy of it in the device's memory on a device.
static inline MetricSums psnrSums(DeviceKind device, const float* table, MetricImage test, MetricImage ref,
                                  ImageView<float> error) {
    return sumMetric(device, test.width, test.height, error,
                     [=] LOOM_HD(uint32_t x, uint32_t y) { return psnrTerm(table, test.at(x, y), ref.at(x, y)); });
}

static inline MetricSums temporalSums(DeviceKind device, MetricImage test, MetricImage testPrev, MetricImage ref,
                                      MetricImage refPrev) {
    return sumMetric(device, test.width, test.height, ImageView<float>{}, [=] LOOM_HD(uint32_t x, uint32_t y) {
        return temporalTerm(test.at(x, y), testPrev.at(x, y), ref.at(x, y), refPrev.at(x, y));
    });
}

// ---------------------------------------------------------------------------------------------------------------------
// Values from the sums (host)

/// The mean over the counted pixels and R, G, B; 0 when none were counted.
inline double metricMean(const MetricSums& s) {
    return s.count ? s.sum / (double(s.count) * 3.0) : 0.0;
}

/// The mean, capped at the largest double (a huge but finite term could overflow to Inf): RelMSE, temporal error.
inline double cappedMetricMean(const MetricSums& s) {
    return std::min(metricMean(s), std::numeric_limits<double>::max());
}

/// PSNR in dB of the sums of psnrTerm: 10 log10(1 / MSE), capped at kPsnrCap.
inline double psnrOfSums(const MetricSums& s) {
    const double mse = metricMean(s);
    return mse > 0.0 ? std::min(10.0 * std::log10(1.0 / mse), kPsnrCap) : kPsnrCap;
}

}  // namespace loom
