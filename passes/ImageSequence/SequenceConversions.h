#pragma once
// What ImageSequence does to another renderer's values to give Loom's channels (loom/Channels.h): normals into
// world space, a depth pass into linearZ with its screen-space derivative, motion in pixels into uvPrev - uvCur,
// float object indices into mesh ids, reflectances into [0, kMaxReflectance], and non-finite samples into 0. Plain
// functions on images, tested beside the pass (tests/test_sequence_conversions.cpp) and fuzzed
// (tests/fuzz/fuzz_sequence.cpp): whatever finite or non-finite values a file holds, what convertFrame() leaves is
// finite, or the frame is refused (a camera matrix that cannot turn normals).
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "loom/Error.h"
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

/// The largest absolute component of v.
inline float maxAbs(glm::vec3 v) {
    return std::fmax(std::fabs(v.x), std::fmax(std::fabs(v.y), std::fabs(v.z)));
}

/// v scaled to unit length, however long or short it is (components up to FLT_MAX, or denormal); zero where v is
/// zero or not finite.
inline glm::vec3 normalizedOrZero(glm::vec3 v) {
    const float len = glm::length(v);
    if (len > 1e-18f && len < 1e18f) return v / len;  // the squares neither overflow nor underflow
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) return glm::vec3(0.f);
    const float m = maxAbs(v);
    if (!(m > 0.f)) return glm::vec3(0.f);
    v /= m;  // the largest component is now +-1: the length below neither overflows nor underflows
    return v / glm::length(v);
}

/// The upper 3x3 of `worldToCamera` (OpenEXR's attribute: row-major, for row vectors, p_camera = p_world M) scaled
/// so that its largest entry is 1: a normal's direction does not depend on the matrix's scale, and the products
/// below stay finite.
inline std::array<float, 9> normalRotation(const std::array<float, 16>& worldToCamera) {
    float m = 0.f;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m = std::fmax(m, std::fabs(worldToCamera[size_t(r * 4 + c)]));
    std::array<float, 9> out{};
    if (!(m > 0.f) || !std::isfinite(m)) return out;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) out[size_t(r * 3 + c)] = worldToCamera[size_t(r * 4 + c)] / m;
    return out;
}

/// Why `worldToCamera` cannot turn camera-space normals into world space, or "" when it can: every entry finite, and
/// the upper 3x3 invertible (|det| of normalRotation() at least 1e-4; a rotation's is 0.19 or more).
inline std::string worldToCameraProblem(const std::array<float, 16>& worldToCamera) {
    for (size_t i = 0; i < 16; ++i)
        if (!std::isfinite(worldToCamera[i]))
            return fmt::format("entry [{}][{}] is {}", i / 4, i % 4, worldToCamera[i]);
    const std::array<float, 9> r = normalRotation(worldToCamera);
    const double det = double(r[0]) * (double(r[4]) * r[8] - double(r[5]) * r[7]) -
                       double(r[1]) * (double(r[3]) * r[8] - double(r[5]) * r[6]) +
                       double(r[2]) * (double(r[3]) * r[7] - double(r[4]) * r[6]);
    if (!(std::fabs(det) >= 1e-4)) return "its rotation (the upper 3x3) is singular";
    return {};
}

/// Throws loom::Error (BadInput, naming `file`) when worldToCameraProblem() finds one.
inline void requireUsableWorldToCamera(const std::array<float, 16>& worldToCamera, const std::string& where,
                                       const std::string& file) {
    const std::string problem = worldToCameraProblem(worldToCamera);
    if (problem.empty()) return;
    throwBadInput(where, "the file's worldToCamera attribute cannot turn the normals into world space: " + problem,
                  "a finite camera matrix whose upper 3x3 is a rotation (times a scale)",
                  "write the camera's matrix again, or set normals=world if the normals are in world space", file);
}

/// A normal from camera space into world space: n_world = n_camera R^T with R the upper 3x3 of `worldToCamera`,
/// scaled (normalRotation). Zero stays zero (no surface), and so does a normal the matrix cannot turn.
inline glm::vec3 cameraNormalToWorld(glm::vec3 n, const std::array<float, 9>& rotation) {
    glm::vec3 out;
    for (int j = 0; j < 3; ++j)
        out[j] =
            n.x * rotation[size_t(j * 3 + 0)] + n.y * rotation[size_t(j * 3 + 1)] + n.z * rotation[size_t(j * 3 + 2)];
    return normalizedOrZero(out);
}
inline glm::vec3 cameraNormalToWorld(glm::vec3 n, const std::array<float, 16>& worldToCamera) {
    return cameraNormalToWorld(normalizedOrZero(n), normalRotation(worldToCamera));
}

/// A normal of unit length with w = 0: one blended over a pixel (shorter at silhouettes) is rescaled; one within
/// 1e-3 of unit length keeps its bits (Loom's own); zero stays zero (no surface), and so does one that is not
/// finite.
inline glm::vec4 unitNormal(glm::vec4 n) {
    const glm::vec3 v(n);
    const float len = glm::length(v);
    if (std::fabs(len - 1.f) <= 1e-3f) return {v, 0.f};
    return {normalizedOrZero(v), 0.f};
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

/// The largest |uvPrev - uvCur| kept, in frames: a previous position that far away is off the frame either way, and
/// the reprojection's pixel arithmetic stays far from overflow.
inline constexpr float kMaxMotionUv = 1e4f;

/// The range reflectances (albedo, specAlbedo) are clamped into. Each lobe of a physical material reflects at most
/// all the light, and Blender's Denoising Albedo adds the lobes' colours (base colour plus specular: above 1 on
/// shiny surfaces), so a few units is the most a real one holds; beyond that a value is damage, and it would
/// overflow SVGF's remodulation (illum * albedo).
inline constexpr float kMaxReflectance = 4.f;

/// Clamps every finite float of a float texture into [lo, hi] and returns how many were outside (non-finite ones
/// are left to zeroNonFinite).
inline uint64_t clampInto(Texture& tex, float lo, float hi) {
    const uint32_t channels = formatInfo(tex.format()).channels;
    uint64_t count = 0;
    for (uint32_t y = 0; y < tex.height(); ++y) {
        auto* row = reinterpret_cast<float*>(tex.row(y));
        for (uint32_t i = 0; i < tex.width() * channels; ++i)
            if (row[i] < lo || row[i] > hi) {
                row[i] = row[i] < lo ? lo : hi;
                ++count;
            }
    }
    return count;
}

/// The channels of one frame as read from the files, converted in place by convertFrame(); null where absent.
struct FrameChannels {
    Texture* normW = nullptr;            ///< RGBA32F
    Texture* linearZ = nullptr;          ///< RG32F: Loom's linearZ, or a depth in x
    Texture* mvec = nullptr;             ///< RG32F, as stored
    std::vector<Texture*> reflectances;  ///< RGBA32F albedos: into [0, kMaxReflectance]
    std::vector<Texture*> others;        ///< other float channels (colour, emission, ...): made finite only
};

struct ConversionSettings {
    bool depthFromOneChannel = false;  ///< linearZ holds a depth in x (depthToLinearZ)
    float missDepth = 1e9f;
    MotionKind motion = MotionKind::Uv;
    bool motionYUp = false;
    /// Set: the normals are in camera space and turn with it (check it with requireUsableWorldToCamera first: an
    /// unusable one turns every normal into zero).
    std::optional<std::array<float, 16>> worldToCamera;
};

/// What convertFrame() replaced.
struct Replaced {
    uint64_t nonFinite = 0;   ///< samples that were NaN or infinite (read as 0; a depth as a miss)
    uint64_t outOfRange = 0;  ///< finite values clamped into their channel's range (reflectance, motion, linearZ)
};

/// Every conversion of one frame, in order: depth, motion, normals, reflectances; then every float sample that is
/// still not finite becomes 0. The count of non-finite samples is taken both before the conversions (what the file
/// held) and after them (what a conversion made), so nothing non-finite leaves uncounted.
inline Replaced convertFrame(const FrameChannels& f, const ConversionSettings& s) {
    Replaced out;
    std::vector<Texture*> floats = f.others;
    floats.insert(floats.end(), f.reflectances.begin(), f.reflectances.end());
    for (Texture* t : {f.normW, f.mvec})
        if (t) floats.push_back(t);
    if (f.linearZ) {
        const ImageView<glm::vec2> z = f.linearZ->view<glm::vec2>();
        for (uint32_t y = 0; y < z.height; ++y)
            for (uint32_t x = 0; x < z.width; ++x) {
                glm::vec2& p = z.at(x, y);
                if (!std::isfinite(p.x)) {
                    ++out.nonFinite;
                    p = {-1.f, 0.f};  // a miss
                }
                if (!s.depthFromOneChannel && !std::isfinite(p.y)) {
                    ++out.nonFinite;
                    p.y = 0.f;
                }
            }
        if (s.depthFromOneChannel) {
            depthToLinearZ(z, s.missDepth);
        } else {
            // Loom's linearZ: a positive depth and a slope of at least 0, or a miss (-1, 0). Any other depth of 0 or
            // less would be a surface at the eye to SVGF's depth test.
            for (uint32_t y = 0; y < z.height; ++y)
                for (uint32_t x = 0; x < z.width; ++x) {
                    glm::vec2& p = z.at(x, y);
                    if (!(p.x > 0.f) && p != glm::vec2(-1.f, 0.f)) {
                        ++out.outOfRange;
                        p = {-1.f, 0.f};
                    } else if (p.y < 0.f) {
                        ++out.outOfRange;
                        p.y = 0.f;
                    }
                }
        }
    }
    for (Texture* t : floats) out.nonFinite += zeroNonFinite(*t);
    if (f.mvec) {
        const ImageView<glm::vec2> m = f.mvec->view<glm::vec2>();
        for (uint32_t y = 0; y < m.height; ++y)
            for (uint32_t x = 0; x < m.width; ++x)
                m.at(x, y) = motionToUv(m.at(x, y), s.motion, s.motionYUp, m.width, m.height);
        out.outOfRange += clampInto(*f.mvec, -kMaxMotionUv, kMaxMotionUv);
    }
    if (f.normW) {
        // Blended at silhouettes (Blender's are down to 0.68 long there): back to unit length. Unit ones, as Loom's
        // own, keep their bits.
        const ImageView<glm::vec4> n = f.normW->view<glm::vec4>();
        std::optional<std::array<float, 9>> rotation;
        if (s.worldToCamera) rotation = normalRotation(*s.worldToCamera);
        for (uint32_t y = 0; y < n.height; ++y)
            for (uint32_t x = 0; x < n.width; ++x) {
                glm::vec4 v = unitNormal(n.at(x, y));
                if (rotation) v = glm::vec4(cameraNormalToWorld(glm::vec3(v), *rotation), 0.f);
                n.at(x, y) = v;
            }
    }
    for (Texture* t : f.reflectances) out.outOfRange += clampInto(*t, 0.f, kMaxReflectance);
    if (f.linearZ) floats.push_back(f.linearZ);
    for (Texture* t : floats) out.nonFinite += zeroNonFinite(*t);
    return out;
}

}  // namespace loom::sequence
