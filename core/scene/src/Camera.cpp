#include "loom/Camera.h"

#include <cmath>
#include <numeric>

#include <glm/gtc/matrix_transform.hpp>

namespace loom {

float halton(uint64_t i, uint32_t base) {
    float f = 1.f, r = 0.f;
    while (i > 0) {
        f /= float(base);
        r += f * float(i % base);
        i /= base;
    }
    return r;
}

glm::mat4 Camera::proj() const { return glm::perspective(fovY, aspect, nearZ, farZ); }

glm::vec2 Camera::jitterNdcOffset(uint32_t width, uint32_t height) const {
    return {-2.f * jitter.x / float(width), 2.f * jitter.y / float(height)};
}

glm::vec2 Camera::jitterSample(JitterPattern pattern, uint32_t count, uint64_t i) {
    if (count == 0) count = 1;
    const uint64_t k = i % count;
    switch (pattern) {
        case JitterPattern::None: return glm::vec2(0.f);
        case JitterPattern::Halton:
            // Skip index 0 (which is (0, 0)) so every sample of the period is distinct.
            return glm::vec2(halton(k + 1, 2), halton(k + 1, 3)) - 0.5f;
        case JitterPattern::Stratified: {
            // n x n strata visited in a fixed scrambled order, centred in each stratum.
            const uint32_t n = std::max<uint32_t>(1, uint32_t(std::lround(std::sqrt(double(count)))));
            const uint64_t total = uint64_t(n) * n;
            uint64_t step = 7;  // coprime with total, so k -> cell is a permutation
            while (std::gcd(step, total) != 1) step += 2;
            const uint64_t cell = (k * step + 3) % total;
            const float sx = (float(cell % n) + 0.5f) / float(n);
            const float sy = (float(cell / n) + 0.5f) / float(n);
            return glm::vec2(sx, sy) - 0.5f;
        }
    }
    return glm::vec2(0.f);
}

void Camera::beginFrame(uint64_t frameIndex) {
    prevJitter = jitter;
    jitter = jitterSample(jitterPattern, jitterSampleCount, frameIndex);
}

void Camera::cut() {
    prevWorld = world;
    prevJitter = jitter;
}

}  // namespace loom
