#pragma once
// Per-pixel tone mapping for the ToneMap pass: plain functions over plain
// structs, so the same code compiles for CUDA (see loom/Kernel.h).
//
// Pipeline of one pixel (colour channels; alpha is only clamped to [0, 1]):
//   1. sanitize: NaN and negative values become 0, +Inf and huge values are
//      clamped to kMaxExposed after the exposure scale, so every operator
//      below stays finite (no Inf / Inf, no 0 * Inf);
//   2. exposure: v * scale, scale = 2^EV (times key / adapted luminance with
//      auto exposure, computed once per frame by the pass);
//   3. operator, per channel (see toneMapChannel), then clamp to [0, 1];
//   4. sRGB: the exact piecewise sRGB OETF (IEC 61966-2-1), rounded to the
//      nearest 8-bit code, through a table (SrgbEncodeTable, loom/SrgbEncode.h)
//      that reproduces round(255 * oetf(v)) computed in double for every float v.
//
// Auto exposure uses the log-average luminance of Reinhard et al. 2002,
// "Photographic Tone Reproduction for Digital Images", eq. 1:
//   Lavg = exp2( mean over finite pixels of log2(kLogEpsilon + Y) ),
// Y the Rec. 709 luminance of the (sanitized, unexposed) pixel. The pass takes
// the mean over the pixels of every 4th row (y % 4 == 0): a quarter of the
// frame, for a quarter of the logarithms.
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/SrgbEncode.h"

namespace loom::tonemap {

enum class Operator : uint32_t { Linear, Reinhard, ModifiedReinhard, Aces, Hable };

/// Largest exposed value fed to an operator: its square (ACES, Hable) stays
/// far below FLT_MAX, so the rational operators never see Inf.
inline constexpr float kMaxExposed = 1e18f;
/// Added to the luminance before the logarithm (Reinhard 2002, eq. 1: delta).
inline constexpr float kLogEpsilon = 1e-4f;

// Uncharted 2 filmic curve (J. Hable, "Filmic Tonemapping Operators", 2010):
// the published constants and linear white point.
inline constexpr float kHableA = 0.15f;  ///< shoulder strength
inline constexpr float kHableB = 0.50f;  ///< linear strength
inline constexpr float kHableC = 0.10f;  ///< linear angle
inline constexpr float kHableD = 0.20f;  ///< toe strength
inline constexpr float kHableE = 0.02f;  ///< toe numerator
inline constexpr float kHableF = 0.30f;  ///< toe denominator
inline constexpr float kHableWhite = 11.2f;

/// What one frame's mapping needs. ToneMapPass binds its operator to `op`, so its default is the pass's too.
struct ToneMapParams {
    Operator op = Operator::Aces;
    float scale = 1.f;            ///< exposure scale applied before the operator
    float invWhiteSquared = 1.f;  ///< modified Reinhard: 1 / whitePoint^2
    float hableInvWhite = 1.f;    ///< Hable: 1 / hableCurve(kHableWhite)
};

/// Hable's curve before white normalisation.
LOOM_HD inline float hableCurve(float x) {
    return (x * (kHableA * x + kHableC * kHableB) + kHableD * kHableE) /
               (x * (kHableA * x + kHableB) + kHableD * kHableF) -
           kHableE / kHableF;
}

/// One colour channel through the operator, v >= 0 already exposed. Results
/// above 1 (linear, modified Reinhard past the white point) are clamped by the
/// caller.
///   linear            v
///   reinhard          v / (1 + v)                          Reinhard 2002, eq. 3
///   modifiedReinhard  v (1 + v / Lwhite^2) / (1 + v)       Reinhard 2002, eq. 4
///   aces              v (2.51 v + 0.03) / (v (2.43 v + 0.59) + 0.14)
///                     (K. Narkowicz, "ACES Filmic Tone Mapping Curve": a fit
///                     of the ACES RRT + sRGB ODT)
///   hable             hableCurve(v) / hableCurve(11.2)     Hable 2010
LOOM_HD inline float toneMapChannel(const ToneMapParams& p, float v) {
    switch (p.op) {
        case Operator::Linear:
            return v;
        case Operator::Reinhard:
            return v / (1.f + v);
        case Operator::ModifiedReinhard:
            return v * (1.f + v * p.invWhiteSquared) / (1.f + v);
        case Operator::Aces:
            return v * (2.51f * v + 0.03f) / (v * (2.43f * v + 0.59f) + 0.14f);
        case Operator::Hable:
        default:
            return hableCurve(v) * p.hableInvWhite;
    }
}

/// NaN and negatives -> 0; then exposed and clamped to kMaxExposed (+Inf too).
LOOM_HD inline float exposeChannel(float v, float scale) {
    v = v > 0.f ? v : 0.f;  // false for NaN
    v *= scale;
    return v < kMaxExposed ? v : kMaxExposed;
}

LOOM_HD inline float saturate(float v) {
    v = v > 0.f ? v : 0.f;
    return v < 1.f ? v : 1.f;
}

/// Alpha: clamped to [0, 1]; NaN gives 0.
LOOM_HD inline float alphaOut(float a) {
    return saturate(a);
}

/// The tone-mapped pixel, linear, every channel in [0, 1].
LOOM_HD inline glm::vec4 toneMapPixel(const ToneMapParams& p, const glm::vec4& c) {
    glm::vec4 o;
    for (int i = 0; i < 3; ++i) o[i] = saturate(toneMapChannel(p, exposeChannel(c[i], p.scale)));
    o.w = alphaOut(c.w);
    return o;
}

/// Packs a tone-mapped pixel (channels in [0, 1]) into RGBA8 sRGB: colour
/// through the OETF, alpha linear (round to nearest), as sRGB textures store it.
LOOM_HD inline uint32_t packSrgb8(const SrgbEncodeTable& t, const glm::vec4& c) {
    const uint32_t r = encodeSrgb8(t, c.x), g = encodeSrgb8(t, c.y), b = encodeSrgb8(t, c.z);
    const uint32_t a = uint32_t(c.w * 255.f + 0.5f);
    return r | (g << 8) | (b << 16) | (a << 24);
}

// ---------------------------------------------------------------------------
// Auto exposure

/// log2 of a positive normal float, |error| < 1e-8 + float rounding: the
/// exponent, and for the mantissa m in [sqrt(1/2), sqrt(2)) the series
/// log2(m) = 2/ln2 (t + t^3/3 + ... + t^9/9), t = (m - 1) / (m + 1), |t| <= 0.172.
LOOM_HD inline float fastLog2(float x) {
    const uint32_t bits = floatBits(x);
    int exponent = int(bits >> 23) - 127;
    float m = bitsToFloat((bits & 0x007FFFFFu) | 0x3F800000u);  // [1, 2)
    if (m > 1.41421356f) {
        m *= 0.5f;
        exponent += 1;
    }
    const float t = (m - 1.f) / (m + 1.f), t2 = t * t;
    const float series = t * (1.f + t2 * (1.f / 3.f + t2 * (1.f / 5.f + t2 * (1.f / 7.f + t2 * (1.f / 9.f)))));
    return float(exponent) + 2.8853900817779268f * series;  // 2 / ln 2
}

/// The term one pixel adds to the log-average; false (and nothing added) for
/// a pixel with a non-finite colour channel.
LOOM_HD inline bool logLuminance(const glm::vec4& c, float& out) {
    if (!isFinite(c.x) || !isFinite(c.y) || !isFinite(c.z)) return false;
    const glm::vec3 rgb(exposeChannel(c.x, 1.f), exposeChannel(c.y, 1.f), exposeChannel(c.z, 1.f));
    out = fastLog2(kLogEpsilon + luminance(rgb));
    return true;
}

/// The log-average luminance of `count` terms summing to `sum`: exp2 of their mean; false when there are none.
inline bool logAverageOf(double sum, uint64_t count, double& result) {
    if (count == 0) return false;
    result = std::exp2(sum / double(count));
    return true;
}

/// Exponential adaptation towards the measured luminance with time constant
/// tau (seconds): after dt the remaining gap is exp(-dt / tau) of what it was.
/// tau = 0 adapts immediately.
inline float adaptLuminance(float previous, float measured, double dt, float tau) {
    if (tau <= 0.f) return measured;
    const double keep = std::exp(-dt / double(tau));
    return float(double(measured) + (double(previous) - double(measured)) * keep);
}

}  // namespace loom::tonemap
