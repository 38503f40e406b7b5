#pragma once
// The exact 8-bit sRGB encoding of a linear value: round(255 * oetf(v)), the OETF of IEC 61966-2-1 computed in
// double, for every float v in [0, 1], by one table lookup. Plain functions over a plain struct, so kernels use it
// on the GPU as well (see loom/Kernel.h): ToneMap's sRGB output, the viewer's display.
#include <cmath>
#include <cstdint>

#include "loom/Kernel.h"

namespace loom {

/// The exact sRGB OETF in double (for building and checking the table).
inline double srgbOetf(double v) {
    return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
}

/// The 8-bit code of a linear value in [0, 1]: round(255 * oetf(v)), exact.
/// Buckets of 2^-8 relative width (the float's exponent and its top 8
/// mantissa bits) cover [2^-16, 1); no bucket holds more than one code
/// boundary (the code changes by at most 112 * 2^-8 < 1 across one: the
/// OETF's slope in log space, 255 * 1.055 / 2.4 * v^(1/2.4), is <= 112), so
/// the code is the bucket's first code plus one when v reaches the next
/// code's threshold. A bucket spans 2^15 consecutive float bit patterns, so
/// the threshold is stored as its offset in the bucket (15 bits, 2^15 = not
/// in this bucket) next to the first code: one 32-bit entry, one lookup (one
/// vector gather per channel on the CPU path). Below 2^-16 the code is 0
/// (code 1 starts at ~1.5e-4).
struct SrgbEncodeTable {
    static constexpr uint32_t kFirstBits = 111u << 23;  ///< 2^-16
    static constexpr uint32_t kShift = 15;              ///< keeps exponent + 8 mantissa bits
    static constexpr uint32_t kBuckets = 16u << 8;
    static constexpr uint32_t kOffsetMask = (1u << kShift) - 1u;
    /// Per bucket: first code (bits 0-7) | offset of the next code's threshold in the bucket << 8.
    int32_t entry[kBuckets];
};

/// Code of v in [0, 1] (v already saturated: no NaN).
LOOM_HD inline uint32_t encodeSrgb8(const SrgbEncodeTable& t, float v) {
    const uint32_t bits = floatBits(v);
    if (bits < SrgbEncodeTable::kFirstBits) return 0u;
    if (v >= 1.f) return 255u;
    const uint32_t i = (bits >> SrgbEncodeTable::kShift) - (SrgbEncodeTable::kFirstBits >> SrgbEncodeTable::kShift);
    const uint32_t e = uint32_t(t.entry[i]);
    return (e & 255u) + ((bits & SrgbEncodeTable::kOffsetMask) >= (e >> 8) ? 1u : 0u);
}

/// The exact code of a float, computed in double (reference for the table).
inline uint32_t srgbCodeExact(float v) {
    if (!(v > 0.f)) return 0u;
    if (v >= 1.f) return 255u;
    return uint32_t(std::floor(255.0 * srgbOetf(double(v)) + 0.5));
}

/// Fills the table (host side, once). Thresholds are found by bisection over
/// the float bit patterns (monotone for positive floats), so they are exact.
inline void buildSrgbEncodeTable(SrgbEncodeTable& t) {
    float threshold[257];
    threshold[0] = 0.f;
    for (uint32_t k = 1; k <= 255; ++k) {
        uint32_t lo = 0, hi = 0x3F800000u;  // code(lo) < k <= code(hi)
        while (hi - lo > 1) {
            const uint32_t mid = lo + (hi - lo) / 2;
            if (srgbCodeExact(bitsToFloat(mid)) >= k)
                hi = mid;
            else
                lo = mid;
        }
        threshold[k] = bitsToFloat(hi);
    }
    threshold[256] = 2.f;
    for (uint32_t i = 0; i < SrgbEncodeTable::kBuckets; ++i) {
        const uint32_t loBits = SrgbEncodeTable::kFirstBits + (i << SrgbEncodeTable::kShift);
        const uint32_t code = srgbCodeExact(bitsToFloat(loBits));
        const uint32_t next = floatBits(threshold[code + 1]);
        const uint32_t offset =
            next - loBits > (1u << SrgbEncodeTable::kShift) ? (1u << SrgbEncodeTable::kShift) : next - loBits;
        t.entry[i] = int32_t(code | (offset << 8));
    }
}

}  // namespace loom
