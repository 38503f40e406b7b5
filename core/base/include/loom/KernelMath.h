#pragma once
// Per-pixel math that several passes share, written once: the Rec. 709 luminance, a polynomial power of two, finite
// tests and NaN-aware min / max, and the widest vector the Highway paths are sized for. Plain LOOM_HD functions
// (loom/Kernel.h), so the same code compiles for CUDA. The vector forms for Highway translation units are in
// loom/simd/KernelMath-inl.h and use the constants below.
//
// Bit identity: a float result depends on the order of the operations and on which products are fused into FMAs,
// and kernels with a vector twin reproduce each other bit for bit. Each function here is therefore spelt in the one
// order its callers rely on; a caller that needs another order calls the variant named for it. luminance() is
// written without FMAs: a translation unit built with -ffp-contract=off evaluates it as three products and two sums
// (the vector luminanceSum); one built with GCC's default contraction gets the FMAs the compiler picks (GCC 12:
// fma(B, b, fma(R, r, G g))), so code that must match a vector twin either turns contraction off or calls
// luminanceFma, whose FMAs are explicit.
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/Kernel.h"

namespace loom {

// ---------------------------------------------------------------------------------------------------------------------
// Luminance

/// The Rec. 709 luminance weights of linear R, G and B (ITU-R BT.709), in double: the precision of the metrics.
inline constexpr double kRec709R = 0.2126, kRec709G = 0.7152, kRec709B = 0.0722;
/// The same weights in float, for the kernels (each the float nearest the decimal).
inline constexpr float kLuminanceR = float(kRec709R), kLuminanceG = float(kRec709G), kLuminanceB = float(kRec709B);

/// Rec. 709 luminance of linear RGB: (R r + G g) + B b.
LOOM_HD inline float luminance(const glm::vec3& c) {
    return kLuminanceR * c.r + kLuminanceG * c.g + kLuminanceB * c.b;
}

/// Rec. 709 luminance with explicit FMAs, fma(B, b, fma(G, g, R r)): the same bits on every compiler, with any
/// flags, and in the vector form of the same name.
LOOM_HD inline float luminanceFma(float r, float g, float b) {
    return fmaf(kLuminanceB, b, fmaf(kLuminanceG, g, kLuminanceR * r));
}

// ---------------------------------------------------------------------------------------------------------------------
// Powers of two

/// p(f) ~ 2^f on [-1/2, 1/2], the degree-4 minimax polynomial (relative error <= 2.6e-6 in float), lowest degree
/// first, in double; the kernels read the float coefficients below.
inline constexpr double kExp2Poly0 = 0.9999992614457146, kExp2Poly1 = 0.6931218147367706,
                        kExp2Poly2 = 0.2402474482794381, kExp2Poly3 = 0.05591786031930501,
                        kExp2Poly4 = 0.009570101908089415;
/// p's coefficients in float (scalars, not an array: device code reads them as constants).
inline constexpr float kExp2C0 = float(kExp2Poly0), kExp2C1 = float(kExp2Poly1), kExp2C2 = float(kExp2Poly2),
                       kExp2C3 = float(kExp2Poly3), kExp2C4 = float(kExp2Poly4);

/// q(g) = sqrt(2) p(g - 1/2) ~ 2^g on [0, 1): p shifted to the unit interval (for 2^u = 2^floor(u) q(u - floor(u))),
/// its coefficients expanded in powers of g in double and rounded once, so q's relative error is p's.
inline constexpr double kSqrt2 = 1.4142135623730951;
inline constexpr float kExp2UnitC0 = float(kSqrt2 * (kExp2Poly0 - 0.5 * kExp2Poly1 + 0.25 * kExp2Poly2 -
                                                     0.125 * kExp2Poly3 + 0.0625 * kExp2Poly4)),
                       kExp2UnitC1 = float(kSqrt2 * (kExp2Poly1 - kExp2Poly2 + 0.75 * kExp2Poly3 - 0.5 * kExp2Poly4)),
                       kExp2UnitC2 = float(kSqrt2 * (kExp2Poly2 - 1.5 * kExp2Poly3 + 1.5 * kExp2Poly4)),
                       kExp2UnitC3 = float(kSqrt2 * (kExp2Poly3 - 2.0 * kExp2Poly4)),
                       kExp2UnitC4 = float(kSqrt2 * kExp2Poly4);

/// 2^-t for t in [0, 126] (the caller clamps): 2^-round(t) p(round(t) - t), products and sums written apart (see
/// the file comment). Adding 1.5 * 2^23 rounds t to an integer held in the low mantissa bits of r; shifted into the
/// exponent field and subtracted, it divides p by 2^round(t).
LOOM_HD inline float exp2Neg(float t) {
    const float magic = 12582912.f;  // 1.5 * 2^23
    const float r = t + magic;
    const float f = (r - magic) - t;  // in [-0.5, 0.5]
    float q = kExp2C4 * f + kExp2C3;
    q = q * f + kExp2C2;
    q = q * f + kExp2C1;
    q = q * f + kExp2C0;
    return bitsToFloat(floatBits(q) - (floatBits(r) << 23));
}

// ---------------------------------------------------------------------------------------------------------------------
// Finite tests, min and max

/// True unless the float is a NaN or an infinity (all exponent bits set). A bit test rather than std::isfinite, so
/// it holds under any math flags and in device code.
LOOM_HD inline bool isFinite(float v) {
    return (floatBits(v) & 0x7F800000u) != 0x7F800000u;
}
LOOM_HD inline bool isFinite(const glm::vec2& v) {
    return isFinite(v.x) && isFinite(v.y);
}
LOOM_HD inline bool isFinite(const glm::vec3& v) {
    return isFinite(v.x) && isFinite(v.y) && isFinite(v.z);
}
LOOM_HD inline bool isFinite(const glm::vec4& v) {
    return isFinite(v.x) && isFinite(v.y) && isFinite(v.z) && isFinite(v.w);
}

/// max and min as a compare and a select, one instruction each (fmaxf / fminf stay library calls unless NaN and
/// signed-zero rules are relaxed for the whole file). maxf(NaN, b) and minf(NaN, b) are b.
LOOM_HD inline float maxf(float a, float b) {
    return a > b ? a : b;
}
LOOM_HD inline float minf(float a, float b) {
    return a < b ? a : b;
}

// ---------------------------------------------------------------------------------------------------------------------
// Vectors

/// The most floats one vector of a compiled Highway target holds (AVX-512: 16): what scratch, plane margins and
/// tiles are sized for.
inline constexpr uint32_t kMaxLanes = 16;

}  // namespace loom
