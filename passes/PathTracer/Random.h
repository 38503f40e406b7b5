#pragma once
// Counter-based random numbers: a sample is a pure function of (pixel,
// frame, sample index, dimension), so the image never depends on which
// thread rendered which pixel, and any sample can be regenerated.
#include <cstdint>

#include <glm/glm.hpp>

#include "loom/Kernel.h"

namespace loom::pt {

/// SplitMix64 finaliser (Steele, Lea, Flood 2014): a bijective 64-bit mix
/// with good avalanche, cheap enough to call per random number.
LOOM_HD inline uint64_t mix64(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/// Random numbers of one path: dimensions are consumed in order; each bounce
/// starts at a fixed dimension so paths stay decorrelated when one bounce
/// consumes fewer numbers than another.
struct PathRng {
    uint64_t key = 0;
    uint32_t dim = 0;

    PathRng() = default;
    LOOM_HD PathRng(uint32_t pixelIndex, uint64_t frame, uint32_t sample)
        : key(mix64(mix64(uint64_t(pixelIndex) * 0x9E3779B97F4A7C15ull + frame) + uint64_t(sample) * 0xD1B54A32D192ED03ull)) {}

    /// Uniform in [0, 1) with 24 random bits (exactly representable floats).
    LOOM_HD float next() {
        const uint64_t r = mix64(key + uint64_t(dim++) * 0x632BE59BD9B4E019ull);
        return float(r >> 40) * (1.f / 16777216.f);
    }
    /// Two uniform numbers in [0, 1) from one hash: its top 24 bits and the 24 below them.
    LOOM_HD glm::vec2 next2() {
        const uint64_t r = mix64(key + uint64_t(dim++) * 0x632BE59BD9B4E019ull);
        return glm::vec2(float(r >> 40) * (1.f / 16777216.f), float((r >> 16) & 0xFFFFFFu) * (1.f / 16777216.f));
    }
    LOOM_HD void startBounce(uint32_t bounce) { dim = 64u * bounce; }
};

}  // namespace loom::pt
