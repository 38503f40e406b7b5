#pragma once
// Doubles in RGBA32U texels: two doubles per texel, each as the (low word, high word) of its IEEE-754 bits. A
// four-channel double sum takes two texels: R in xy and G in zw of the first, B and A of the second. AccumulatePass
// keeps its double-precision state so (its `sum` and `sumExtra` history, partialSumRG and partialSumBA), and
// `loom image merge` reads it.
#include <cstdint>
#include <cstring>
#include <glm/glm.hpp>

#include "loom/Kernel.h"

namespace loom {

LOOM_HD inline glm::uvec2 doubleToWords(double d) {
    uint64_t bits;
    std::memcpy(&bits, &d, sizeof bits);
    return glm::uvec2(uint32_t(bits), uint32_t(bits >> 32));
}

LOOM_HD inline double wordsToDouble(uint32_t lo, uint32_t hi) {
    const uint64_t bits = uint64_t(lo) | (uint64_t(hi) << 32);
    double d;
    std::memcpy(&d, &bits, sizeof d);
    return d;
}

/// Packs two doubles into one RGBA32U texel.
LOOM_HD inline glm::uvec4 packDoublePair(double a, double b) {
    const glm::uvec2 wa = doubleToWords(a), wb = doubleToWords(b);
    return glm::uvec4(wa.x, wa.y, wb.x, wb.y);
}

LOOM_HD inline glm::dvec2 unpackDoublePair(const glm::uvec4& t) {
    return glm::dvec2(wordsToDouble(t.x, t.y), wordsToDouble(t.z, t.w));
}

/// The four-channel double sum from its two texels (RG, BA), and back.
LOOM_HD inline glm::dvec4 unpackDoubleSum(const glm::uvec4& rg, const glm::uvec4& ba) {
    const glm::dvec2 a = unpackDoublePair(rg), b = unpackDoublePair(ba);
    return glm::dvec4(a.x, a.y, b.x, b.y);
}

LOOM_HD inline void packDoubleSum(const glm::dvec4& sum, glm::uvec4& rg, glm::uvec4& ba) {
    rg = packDoublePair(sum.x, sum.y);
    ba = packDoublePair(sum.z, sum.w);
}

}  // namespace loom
