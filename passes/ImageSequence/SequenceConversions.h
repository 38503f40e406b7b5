#pragma once
// What ImageSequence does to another renderer's values to give Loom's channels (loom/Channels.h): normals into
// world space, a depth pass into linearZ with its screen-space derivative, motion in pixels into uvPrev - uvCur,
// float object indices into mesh ids, and non-finite samples into 0. Plain functions on images, tested beside the
// pass (tests/test_sequence_conversions.cpp).
#include <array>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/Texture.h"

namespace loom::sequence {

/// How a sequence stores motion.
enum class MotionKind : int {
    Uv,                  ///< Loom's mvec: uvPrev - uvCur, in [0, 1] units of the frame
    PixelsFromPrevious,  ///< current minus previous position, in pixels
    PixelsToPrevious,    ///< previous minus current position, in pixels (Blender's Vector, x and y, y up)
};

/// Loom's mvec from a stored motion (x, y). `yUp`: the stored y grows upwards in the image (rows of the file run
/// top to bottom, as Loom's do, so y flips).
inline glm::vec2 motionToUv(glm::vec2 m, MotionKind kind, bool yUp, uint32_t width, uint32_t height) {
    if (kind == MotionKind::Uv) return m;
    if (yUp) m.y = -m.y;
    if (kind == MotionKind::PixelsFromPrevious) m = -m;
    return {m.x / float(width), m.y / float(height)};
}

/// A depth sample that is no surface: not finite, not positive, or at least `missDepth` (Blender writes 1e10
/// where a pixel sees the background).
inline bool isMissDepth(float z, float missDepth) {
    return !(z > 0.f) || !(z < missDepth) || !std::isfinite(z);
}

/// linearZ from one channel of view depth (distance along the camera axis) held in x: x becomes -1 on a miss, y the
/// larger of the depth's slopes along x and y, each the smaller of the differences to the left and right (up and
/// down) neighbours that are surfaces too, so a silhouette does not count as slope (0 where no neighbour is one).
/// Loom's G-buffers compute the same quantity from ray differentials.
inline void depthToLinearZ(ImageView<glm::vec2> z, float missDepth) {
    const uint32_t w = z.width, h = z.height;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            float& d = z.at(x, y).x;
            if (isMissDepth(d, missDepth)) d = -1.f;
        }
    const auto slope = [&](float c, const float* a, const float* b) {
        float s = INFINITY;
        for (const float* n : {a, b})
            if (n && *n > 0.f) s = std::fmin(s, std::fabs(*n - c));
        return std::isfinite(s) ? s : 0.f;
    };
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            glm::vec2& p = z.at(x, y);
            if (p.x <= 0.f) {
                p.y = 0.f;
                continue;
            }
            const float* left = x > 0 ? &z.at(x - 1, y).x : nullptr;
            const float* right = x + 1 < w ? &z.at(x + 1, y).x : nullptr;
            const float* up = y > 0 ? &z.at(x, y - 1).x : nullptr;
            const float* down = y + 1 < h ? &z.at(x, y + 1).x : nullptr;
            p.y = std::fmax(slope(p.x, left, right), slope(p.x, up, down));
        }
}

/// A normal from camera space into world space: `worldToCamera` is OpenEXR's attribute (row-major, for row
/// vectors: p_camera = p_world M), so n_world = n_camera R^T with R its upper 3x3. Zero stays zero (no surface).
inline glm::vec3 cameraNormalToWorld(glm::vec3 n, const std::array<float, 16>& worldToCamera) {
    glm::vec3 out;
    for (int j = 0; j < 3; ++j)
        out[j] = n.x * worldToCamera[size_t(j * 4 + 0)] + n.y * worldToCamera[size_t(j * 4 + 1)] +
                 n.z * worldToCamera[size_t(j * 4 + 2)];
    const float len = glm::length(out);
    return len > 0.f ? out / len : glm::vec3(0.f);
}

/// A normal of unit length with w = 0: one blended over a pixel (shorter at silhouettes) is rescaled; one within
/// 1e-3 of unit length keeps its bits (Loom's own); zero stays zero (no surface).
inline glm::vec4 unitNormal(glm::vec4 n) {
    const glm::vec3 v(n);
    const float len = glm::length(v);
    if (!(len > 0.f) || std::fabs(len - 1.f) <= 1e-3f) return {v, 0.f};
    return {v / len, 0.f};
}

/// A mesh id from a float object index (Blender's IndexOB): the nearest integer; negative or non-finite values
/// are no object (~0u).
inline uint32_t objectIndexToMeshId(float v) {
    if (!std::isfinite(v) || v < 0.f || v >= 4294967040.f) return ~0u;
    return uint32_t(std::lround(v));
}

/// Sets every non-finite float of a float texture to 0 and returns how many there were.
inline uint64_t zeroNonFinite(Texture& tex) {
    const uint32_t channels = formatInfo(tex.format()).channels;
    uint64_t count = 0;
    for (uint32_t y = 0; y < tex.height(); ++y) {
        auto* row = reinterpret_cast<float*>(tex.row(y));
        for (uint32_t i = 0; i < tex.width() * channels; ++i)
            if (!std::isfinite(row[i])) {
                row[i] = 0.f;
                ++count;
            }
    }
    return count;
}

}  // namespace loom::sequence
