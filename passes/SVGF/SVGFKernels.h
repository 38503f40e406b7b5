#pragma once
// Per-pixel stages of SVGFPass (Schied et al. 2017, "Spatiotemporal Variance-Guided Filtering", HPG 2017) other
// than the à-trous levels (AtrousKernels.h): plain functions over plain structs and views, so the same code
// compiles for CUDA (loom/Kernel.h).
//
// A frame runs these stages, each one pass over the pixels:
//   1. temporalPixel: sanitize, take emission out and demodulate by albedo, reproject last frame's history through
//      mvec with per-tap disocclusion tests, accumulate colour and luminance moments (paper section 4.1, 4.2),
//      and copy this frame's guides into history for the next frame's tests.
//   2. varianceEstimatePixel: the temporal variance max(0, m2 - m1^2), or for history shorter than
//      kSpatialVarianceFrames a 7x7 edge-aware spatial estimate (paper section 4.2; Falcor's filter-moments pass).
//   3. à-trous levels (AtrousFilter), level `feedbackTap` becoming next frame's colour history.
//   4. modulatePixel: remodulate by albedo, add emission back, pass miss pixels through.
// Up to two signals are filtered side by side: signal 0 is `color` (or `direct` when the split is connected),
// signal 1 is `indirect` (split only). Each has its own history and moments; the history length and the
// disocclusion tests are shared (they depend on geometry only).
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "AtrousKernels.h"
#include "loom/Channels.h"
#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/Texture.h"

namespace loom::svgf {

/// Albedo below this (per channel) is clamped for demodulation, and the same clamp is used to remodulate, so a
/// pixel the filter leaves alone comes back exactly (SVGF paper section 4; Falcor divides by max(albedo, 1e-3)).
inline constexpr float kMinAlbedo = 1e-3f;
/// Demodulated illumination is clamped to [0, kMaxIllumination], so the second moment l^2 stays finite.
inline constexpr float kMaxIllumination = 1e16f;
/// Albedo above this (per channel) is clamped too: a reflectance is at most 1, and the bound keeps the remodulated
/// illum * albedo (at most 1e22) finite, with any finite emission added, for albedos as large as floats go.
inline constexpr float kMaxAlbedo = 1e6f;
/// History shorter than this uses the spatial variance estimate (paper section 4.2).
inline constexpr float kSpatialVarianceFrames = 4.f;
/// Disocclusion tests (after Falcor's isReprjValid, depth relative to the depth derivative): a previous tap is
/// rejected when |zExpected - zPrev| / (dz + kDepthEpsilon * z) > kDepthThreshold, dot(n, nPrev) < kNormalThreshold,
/// or its mesh id differs. zExpected is the depth the pixel's surface point had in last frame's camera
/// (expectedPrevDepth), not this frame's depth: a camera moving towards a wall changes every depth by more than the
/// tolerance of a surface facing it. The depth epsilon is relative to z so the test does not depend on the scene's
/// units.
inline constexpr float kDepthThreshold = 10.f;
inline constexpr float kDepthEpsilon = 1e-3f;
inline constexpr float kNormalThreshold = 0.9f;
/// Bilinear footprints whose valid weights sum below this fall back to the 3x3 search (Falcor).
inline constexpr float kMinBilinearWeight = 0.01f;

/// Non-finite channels become 0.
LOOM_HD inline glm::vec3 finiteOrZero(const glm::vec3& v) {
    return glm::vec3(isFinite(v.x) ? v.x : 0.f, isFinite(v.y) ? v.y : 0.f, isFinite(v.z) ? v.z : 0.f);
}

/// The albedo demodulation divides by (and remodulation multiplies with), in [kMinAlbedo, kMaxAlbedo].
LOOM_HD inline glm::vec3 guardedAlbedo(const glm::vec4& albedo) {
    const glm::vec3 a = finiteOrZero(glm::vec3(albedo));
    return glm::vec3(minf(maxf(a.x, kMinAlbedo), kMaxAlbedo), minf(maxf(a.y, kMinAlbedo), kMaxAlbedo),
                     minf(maxf(a.z, kMinAlbedo), kMaxAlbedo));
}

LOOM_HD inline glm::vec3 clampIllumination(const glm::vec3& v) {
    return glm::vec3(minf(maxf(v.x, 0.f), kMaxIllumination), minf(maxf(v.y, 0.f), kMaxIllumination),
                     minf(maxf(v.z, 0.f), kMaxIllumination));
}

/// Parameters of the temporal stage. SVGFPass binds its alpha, momentsAlpha and maxHistory to this struct, so these
/// are the pass's defaults too.
struct TemporalParams {
    float alpha = 0.2f;         ///< colour blend factor (paper eq. 1)
    float momentsAlpha = 0.2f;  ///< moments blend factor
    int maxHistory = 32;        ///< history length cap, in frames
    bool temporal = true;       ///< false: no reprojection, every frame starts from history length 1
    bool split = false;         ///< two signals (direct, indirect) instead of one (color)
    /// The variance handed on is the luminance's per-sample variance times max(1 / n, varianceFloor): the variance
    /// of the accumulated mean (the sum of its squared weights: 1 / n while the blend is a plain mean, alpha / (2 -
    /// alpha) in the exponential average's steady state). 1: the per-sample variance itself (Falcor).
    float varianceFloor = 1.f;
    /// This frame's camera jitter minus last frame's, in pixels: the signal of pixel x was sampled at x + jitter,
    /// and the history is stored where last frame sampled, so a point that moved by mvec is found at
    /// x + mvec size + jitterDelta on last frame's grid (mvec is jitter-free).
    glm::vec2 jitterDelta{0.f};
    /// The depth in last frame's camera of the point at view depth z behind pixel (x, y), for a static point:
    /// prevDepth.x + z * ((prevDepth.y + prevDepth.z * x) + prevDepth.w * y) (expectedPrevDepthPlane). The default
    /// is z itself (no camera).
    glm::vec4 prevDepth{0.f, 1.f, 0.f, 0.f};
    /// Firefly clamp: where the history holds at least kOutlierMinFrames frames, a new sample whose luminance lies
    /// above the history's mean + outlierSigma standard deviations (its luminance moments) is scaled down to that
    /// bound before it is blended, moments included. 0: off.
    float outlierSigma = 3.f;
    /// History clamp (FidelityFX's and GAMES202's defence against stale history): where TemporalViews::neighbourhood
    /// is given, the reprojected history's luminance is brought within this frame's neighbourhood mean +-
    /// clampSigma standard deviations (neighbourhoodPixel), the history scaled as a whole, moments included.
    float clampSigma = 1.f;
};

/// The factor that brings a history of luminance lum within [max(mean - sigmas sigma, 0), mean + sigmas sigma]; 1
/// when it lies within, or when it is 0 (nothing to scale).
LOOM_HD inline float historyClampScale(float lum, float mean, float sigma, float sigmas) {
    const float lo = maxf(mean - sigmas * sigma, 0.f), hi = mean + sigmas * sigma;
    if (lum > hi) return hi / lum;
    if (lum < lo && lum > 0.f) return lo / lum;
    return 1.f;
}

/// History shorter than this leaves the new sample alone (its moments say too little yet).
inline constexpr float kOutlierMinFrames = 4.f;

/// The factor (at most 1) that brings a sample of luminance lum within mean + sigmas standard deviations of moments
/// (m1, m2). 1 when the clamp is off (sigmas 0) or lum is within the bound.
LOOM_HD inline float outlierScale(float lum, float m1, float m2, float sigmas) {
    if (!(sigmas > 0.f)) return 1.f;
    const float bound = m1 + sigmas * sqrtf(maxf(m2 - m1 * m1, 0.f));
    return lum > bound && bound >= 0.f ? bound / lum : 1.f;
}

/// TemporalParams::prevDepth at pixel (x, y) for view depth z, in this order of operations (TemporalSimd.cpp does
/// the same, so both round alike).
LOOM_HD inline float expectedPrevDepth(const TemporalParams& p, uint32_t x, uint32_t y, float z) {
    const float scale = (p.prevDepth.y + p.prevDepth.z * float(x)) + p.prevDepth.w * float(y);
    return p.prevDepth.x + z * scale;
}

/// varianceFloor for colour blend factor alpha: the squared weights of an exponential average sum to
/// alpha / (2 - alpha) in its steady state.
inline float meanVarianceFloor(float alpha) {
    return alpha >= 1.f ? 1.f : alpha / (2.f - alpha);
}

/// Everything the temporal stage reads and writes. Optional views have data == nullptr.
struct TemporalViews {
    // This frame's inputs.
    ImageView<const glm::vec4> color, direct, indirect, albedo, emission, normW;
    ImageView<const glm::vec2> linearZ, mvec;
    ImageView<const uint32_t> meshId;  // optional: without it the mesh test is skipped
    // Last frame's history.
    ImageView<const glm::vec4> prevIllum0, prevIllum1, prevNormW;
    ImageView<const glm::vec2> prevMoments0, prevMoments1, prevLinearZ;  // moments: (m1, m2) of each signal
    ImageView<const float> prevLength;
    ImageView<const uint32_t> prevMeshId;
    /// Optional: how the shading changed since last frame, on last frame's pixel grid (antilagChange of the path
    /// tracer's temporal gradients): (lambda in [0, 1], luminance ratio now / then); reprojected like the history.
    ImageView<const glm::vec2> prevChange;
    /// Optional: the history clamp's box, this frame's (mean, standard deviation) of each signal's demodulated
    /// luminance around each pixel (neighbourhoodPixel). Null: no clamp.
    ImageView<const glm::vec4> neighbourhood;
    // This frame's history (moments, length, guides) and the integrated signals (rgb, a = temporal variance).
    ImageView<glm::vec4> integrated0, integrated1, curNormW;
    ImageView<glm::vec2> curMoments0, curMoments1, curLinearZ;  // moments1: split only
    ImageView<float> curLength;
    ImageView<uint32_t> curMeshId;
};

/// The disocclusion test of one previous-frame tap (after Falcor's isReprjValid): zExpected is expectedPrevDepth of
/// the pixel, z and dz its depth and depth derivative now.
LOOM_HD inline bool reprojectionTapValid(const TemporalViews& v, int px, int py, float zExpected, float z, float dz,
                                         const glm::vec3& n, uint32_t mesh) {
    if (px < 0 || py < 0 || px >= int(v.color.width) || py >= int(v.color.height)) return false;
    const uint32_t qx = uint32_t(px), qy = uint32_t(py);
    // History length 0: no history there (first frame, reset, or SVGF was disabled).
    if (!(v.prevLength.at(qx, qy) > 0.f)) return false;
    const float zPrev = v.prevLinearZ.at(qx, qy).x;
    if (zPrev < 0.f) return false;
    if (v.meshId.data && v.prevMeshId.at(qx, qy) != mesh) return false;
    if (fabsf(zExpected - zPrev) > kDepthThreshold * (dz + kDepthEpsilon * z)) return false;
    if (glm::dot(n, glm::vec3(v.prevNormW.at(qx, qy))) < kNormalThreshold) return false;
    return true;
}

/// The reprojected history of one pixel.
struct Reprojected {
    glm::vec4 illum0{0.f}, illum1{0.f}, moments{0.f};
    float length = 0.f;
    glm::vec2 change{0.f, 1.f};  ///< TemporalViews::prevChange at the reprojected position ((0, 1) without it)
    bool valid = false;
};

/// The moments of both signals at (x, y) as (m1, m2) of signal 0 and of signal 1 (zero without its field).
LOOM_HD inline glm::vec4 momentsAt(ImageView<const glm::vec2> m0, ImageView<const glm::vec2> m1, uint32_t x,
                                   uint32_t y) {
    return glm::vec4(m0.at(x, y), m1.data ? m1.at(x, y) : glm::vec2(0.f));
}

/// Stores moments (m1, m2 of signal 0, of signal 1) into the two fields (the second only when present).
LOOM_HD inline void storeMoments(ImageView<glm::vec2> m0, ImageView<glm::vec2> m1, uint32_t x, uint32_t y,
                                 const glm::vec4& m) {
    m0.at(x, y) = glm::vec2(m.x, m.y);
    if (m1.data) m1.at(x, y) = glm::vec2(m.z, m.w);
}

LOOM_HD inline void addTap(const TemporalViews& v, Reprojected& r, uint32_t x, uint32_t y, float w) {
    r.illum0 += w * v.prevIllum0.at(x, y);
    if (v.prevIllum1.data) r.illum1 += w * v.prevIllum1.at(x, y);
    r.moments += w * momentsAt(v.prevMoments0, v.prevMoments1, x, y);
    r.length += w * v.prevLength.at(x, y);
    if (v.prevChange.data) r.change += w * v.prevChange.at(x, y);
}

/// Last frame's history at pixel (x, y) through the motion vector: bilinear over the valid taps of the 2x2
/// footprint (weights renormalised), else the mean of the valid taps of the 3x3 around the nearest pixel.
LOOM_HD inline Reprojected reproject(const TemporalViews& v, const TemporalParams& p, uint32_t x, uint32_t y, float z,
                                     float dz, const glm::vec3& n, uint32_t mesh) {
    Reprojected r;
    if (v.prevChange.data) r.change = glm::vec2(0.f);  // summed over the taps below
    const glm::vec2 mv = v.mvec.at(x, y);
    if (!isFinite(mv.x) || !isFinite(mv.y)) return r;
    // uvPrev = uv + mvec with uv = (x + 0.5) / width: the previous pixel centre coordinate is (uv + mvec) size - 0.5.
    const float w = float(v.color.width), h = float(v.color.height);
    const float px = float(x) + mv.x * w + p.jitterDelta.x, py = float(y) + mv.y * h + p.jitterDelta.y;
    // Far outside (also guards the float to int conversion).
    if (!(px > -2.f && py > -2.f && px < w + 1.f && py < h + 1.f)) return r;
    const float fx0 = floorf(px), fy0 = floorf(py);
    const int x0 = int(fx0), y0 = int(fy0);
    const float fx = px - fx0, fy = py - fy0;
    const float bw[4] = {(1.f - fx) * (1.f - fy), fx * (1.f - fy), (1.f - fx) * fy, fx * fy};
    const float zExpected = expectedPrevDepth(p, x, y, z);
    float sumW = 0.f;
    bool tapValid[4];
    for (int k = 0; k < 4; ++k) {
        tapValid[k] =
            bw[k] > 0.f && reprojectionTapValid(v, x0 + (k & 1), y0 + (k >> 1), zExpected, z, dz, n, mesh);
        if (tapValid[k]) sumW += bw[k];
    }
    if (sumW >= kMinBilinearWeight) {
        for (int k = 0; k < 4; ++k)
            if (tapValid[k]) addTap(v, r, uint32_t(x0 + (k & 1)), uint32_t(y0 + (k >> 1)), bw[k]);
    } else {
        // 3x3 fallback around the nearest previous pixel, equal weights.
        const int cx = int(floorf(px + 0.5f)), cy = int(floorf(py + 0.5f));
        sumW = 0.f;
        for (int j = -1; j <= 1; ++j)
            for (int i = -1; i <= 1; ++i)
                if (reprojectionTapValid(v, cx + i, cy + j, zExpected, z, dz, n, mesh)) {
                    addTap(v, r, uint32_t(cx + i), uint32_t(cy + j), 1.f);
                    sumW += 1.f;
                }
        if (sumW == 0.f) return r;
    }
    const float inv = 1.f / sumW;
    r.illum0 *= inv;
    r.illum1 *= inv;
    r.moments *= inv;
    r.length *= inv;
    if (v.prevChange.data) r.change *= inv;
    // History that is not finite (it never should be) counts as disoccluded, so it cannot persist.
    r.valid = isFinite(r.illum0) && isFinite(r.illum1) && isFinite(r.moments) && isFinite(r.length) &&
              isFinite(r.change.x) && isFinite(r.change.y);
    if (!r.valid) r = Reprojected{};
    return r;
}

/// The demodulated luminance of both signals of pixel (x, y) whose demodulation albedo is `albedoIn`, as
/// temporalPixel computes them (emission out, divided by the guarded albedo, clamped). False for a miss or a sample
/// that is not finite.
LOOM_HD inline bool demodulatedLuminance(const TemporalViews& v, bool split, uint32_t x, uint32_t y,
                                         const glm::vec4& albedoIn, float& lum0, float& lum1) {
    if (!(v.linearZ.at(x, y).x >= 0.f)) return false;
    const glm::vec4 c0 = split ? v.direct.at(x, y) : v.color.at(x, y);
    const glm::vec4 c1 = split ? v.indirect.at(x, y) : glm::vec4(0.f);
    if (!isFinite(glm::vec3(c0)) || !isFinite(glm::vec3(c1))) return false;
    const glm::vec3 emission = v.emission.data ? finiteOrZero(glm::vec3(v.emission.at(x, y))) : glm::vec3(0.f);
    const glm::vec3 albedo = guardedAlbedo(albedoIn);
    lum0 = luminance(clampIllumination((glm::vec3(c0) - emission) / albedo));
    lum1 = luminance(clampIllumination(glm::vec3(c1) / albedo));
    return true;
}

/// Side of the history clamp's window: the (2 kClampRadius + 1)^2 pixels around a pixel.
inline constexpr int kClampRadius = 1;

/// The history clamp's box of pixel (x, y) (TemporalViews::neighbourhood): the mean and standard deviation of the
/// demodulated luminance of each signal over the hits of the window around it, in frame (zeros where it has none).
/// albedoAt(x, y) gives a pixel's demodulation albedo.
template <class AlbedoAt>
LOOM_HD inline glm::vec4 neighbourhoodPixel(const TemporalViews& v, bool split, uint32_t x, uint32_t y,
                                            const AlbedoAt& albedoAt) {
    const int w = int(v.color.width), h = int(v.color.height);
    float n = 0.f, s0 = 0.f, q0 = 0.f, s1 = 0.f, q1 = 0.f;
    for (int j = -kClampRadius; j <= kClampRadius; ++j)
        for (int i = -kClampRadius; i <= kClampRadius; ++i) {
            const int qx = int(x) + i, qy = int(y) + j;
            if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
            float l0, l1;
            if (!demodulatedLuminance(v, split, uint32_t(qx), uint32_t(qy), albedoAt(uint32_t(qx), uint32_t(qy)), l0, l1))
                continue;
            n += 1.f;
            s0 += l0;
            q0 += l0 * l0;
            s1 += l1;
            q1 += l1 * l1;
        }
    if (n == 0.f) return glm::vec4(0.f);
    const float m0 = s0 / n, m1 = s1 / n;
    return glm::vec4(m0, sqrtf(maxf(q0 / n - m0 * m0, 0.f)), m1, sqrtf(maxf(q1 / n - m1 * m1, 0.f)));
}

/// Stage 1 for pixel (x, y). Returns true when this pixel's colour sample was not finite (and was rejected).
LOOM_HD inline bool temporalPixel(const TemporalViews& v, uint32_t x, uint32_t y, const TemporalParams& p) {
    const glm::vec2 z = v.linearZ.at(x, y);
    const glm::vec4 normal = v.normW.at(x, y);
    const uint32_t mesh = v.meshId.data ? v.meshId.at(x, y) : 0u;
    // Guides for next frame's tests (unless the graph keeps last frame's G-buffer: no views then).
    if (v.curLinearZ.data) {
        v.curLinearZ.at(x, y) = z;
        v.curNormW.at(x, y) = normal;
        v.curMeshId.at(x, y) = mesh;
    }

    const glm::vec4 c0 = p.split ? v.direct.at(x, y) : v.color.at(x, y);
    const glm::vec4 c1 = p.split ? v.indirect.at(x, y) : glm::vec4(0.f);
    const bool sampleFinite = isFinite(glm::vec3(c0)) && isFinite(glm::vec3(c1));
    if (!(z.x >= 0.f)) {
        // Miss: passed through by the modulation stage; no history.
        v.integrated0.at(x, y) = glm::vec4(0.f);
        if (p.split) v.integrated1.at(x, y) = glm::vec4(0.f);
        storeMoments(v.curMoments0, v.curMoments1, x, y, glm::vec4(0.f));
        v.curLength.at(x, y) = 0.f;
        return !sampleFinite;
    }

    // Emission seen by the camera is taken out first (it is part of `direct` in the split) and added back after
    // remodulation; only the reflected light is demodulated and filtered.
    const glm::vec3 emission = v.emission.data ? finiteOrZero(glm::vec3(v.emission.at(x, y))) : glm::vec3(0.f);
    const glm::vec3 albedo = guardedAlbedo(v.albedo.at(x, y));
    const glm::vec3 l0 = clampIllumination((glm::vec3(c0) - emission) / albedo);
    const glm::vec3 l1 = clampIllumination(glm::vec3(c1) / albedo);
    const float lum0 = luminance(l0), lum1 = luminance(l1);
    const glm::vec4 moments(lum0, lum0 * lum0, lum1, lum1 * lum1);

    Reprojected r;
    if (p.temporal) r = reproject(v, p, x, y, z.x, z.y, glm::vec3(normal), mesh);

    glm::vec4 i0, i1, m;
    float length;
    if (!sampleFinite) {
        // Rejected sample: keep the reprojected history as it is (or nothing where there is none).
        i0 = r.illum0;
        i1 = r.illum1;
        m = r.moments;
        length = r.valid ? r.length : 0.f;
    } else if (r.valid) {
        // Anti-lag (Schied et al. 2018, A-SVGF): where the shading changed by a fraction lambda since last frame,
        // the history counts (1 - lambda) as many frames and the blend factors grow to alpha + lambda (1 - alpha).
        // Beyond the paper, the history is first rescaled by the measured luminance ratio (moments by its square),
        // so a light that dims or brightens is followed at once rather than blended towards.
        const float change = minf(maxf(r.change.x, 0.f), 1.f);
        const float ratio = r.change.y;
        r.illum0 = glm::vec4(glm::vec3(r.illum0) * ratio, r.illum0.a);
        r.illum1 = glm::vec4(glm::vec3(r.illum1) * ratio, r.illum1.a);
        const float ratio2 = ratio * ratio;
        r.moments = glm::vec4(r.moments.x * ratio, r.moments.y * ratio2, r.moments.z * ratio, r.moments.w * ratio2);
        if (v.neighbourhood.data) {
            // Stale history (a light that changed, a reflection that moved) brought within what this frame's
            // neighbourhood holds.
            const glm::vec4 box = v.neighbourhood.at(x, y);
            const float h0 = historyClampScale(luminance(glm::vec3(r.illum0)), box.x, box.y, p.clampSigma);
            const float h1 = historyClampScale(luminance(glm::vec3(r.illum1)), box.z, box.w, p.clampSigma);
            r.illum0 = glm::vec4(glm::vec3(r.illum0) * h0, r.illum0.a);
            r.illum1 = glm::vec4(glm::vec3(r.illum1) * h1, r.illum1.a);
            r.moments = glm::vec4(r.moments.x * h0, r.moments.y * (h0 * h0), r.moments.z * h1, r.moments.w * (h1 * h1));
        }
        length = minf(r.length * (1.f - change) + 1.f, float(p.maxHistory));
        // Paper eq. 1 with Falcor's max(alpha, 1 / n): a plain mean until the history is 1 / alpha long.
        const float a = maxf(p.alpha + change * (1.f - p.alpha), 1.f / length);
        const float am = maxf(p.momentsAlpha + change * (1.f - p.momentsAlpha), 1.f / length);
        // Fireflies: a sample far above what the (rescaled) history expects is brought down to its bound.
        const bool settled = r.length >= kOutlierMinFrames;
        const float s0 = settled ? outlierScale(lum0, r.moments.x, r.moments.y, p.outlierSigma) : 1.f;
        const float s1 = settled ? outlierScale(lum1, r.moments.z, r.moments.w, p.outlierSigma) : 1.f;
        const float c0 = lum0 * s0, c1 = lum1 * s1;
        const glm::vec4 clamped(c0, c0 * c0, c1, c1 * c1);
        i0 = glm::vec4(glm::mix(glm::vec3(r.illum0), l0 * s0, a), 0.f);
        i1 = glm::vec4(glm::mix(glm::vec3(r.illum1), l1 * s1, a), 0.f);
        m = glm::mix(r.moments, clamped, am);
    } else {
        length = 1.f;
        i0 = glm::vec4(l0, 0.f);
        i1 = glm::vec4(l1, 0.f);
        m = moments;
    }
    // The variance of the accumulated mean (TemporalParams::varianceFloor). A rejected sample without history has
    // length 0: counted as 1.
    const float meanScale = maxf(1.f / maxf(length, 1.f), p.varianceFloor);
    i0.a = maxf(0.f, m.y - m.x * m.x) * meanScale;
    i1.a = maxf(0.f, m.w - m.z * m.z) * meanScale;
    v.integrated0.at(x, y) = i0;
    if (p.split) v.integrated1.at(x, y) = i1;
    storeMoments(v.curMoments0, v.curMoments1, x, y, m);
    v.curLength.at(x, y) = length;
    return !sampleFinite;
}

/// Temporal gradients (Schied et al. 2018, "Gradient Estimation for Real-Time Adaptive Temporal Filtering"): the
/// path tracer's `gradient` channel holds, on last frame's pixel grid, for one sample of each 3x3 block (replicated
/// over the block) the luminance of that sample re-shaded this frame with the same surface point and random numbers,
/// and its luminance last frame. Where nothing changed the two are equal. The change of a block comes from the
/// samples of the 3x3 blocks around it (antilagChange). The block side is the channel's contract (loom/Channels.h).
using channel::kGradientBlock;

inline constexpr float kAntilagMaxRatio = 16.f;  ///< bound of the history's rescaling (either way)

/// One gradient sample (new, old) if usable, else (0, 0): non-finite, negative or huge samples count as none.
LOOM_HD inline glm::vec2 gradientSample(const glm::vec2& g) {
    if (!(g.x >= 0.f && g.x < 1e18f) || !(g.y >= 0.f && g.y < 1e18f)) return glm::vec2(0.f);
    return g;
}

/// (lambda, ratio) from the gradient samples (new, old) around a block. The ratio is sum new / sum old (bounded to
/// [1 / kAntilagMaxRatio, kAntilagMaxRatio]; 1 where there was no light before): the history is rescaled by it. lambda
/// is what the rescaling does not explain, sum |new - ratio old| / sum max(new, ratio old) in [0, 1]: 0 for a light
/// that only dims or brightens (the rescaled history is right), large where a shadow moved or a light appeared
/// from black. (0, 1) where nothing was lit.
LOOM_HD inline glm::vec2 antilagChange(const glm::vec2* samples, int count) {
    float sumNew = 0.f, sumOld = 0.f;
    for (int k = 0; k < count; ++k) {
        sumNew += samples[k].x;
        sumOld += samples[k].y;
    }
    if (!(maxf(sumNew, sumOld) > 1e-12f)) return glm::vec2(0.f, 1.f);
    const float ratio = sumOld > 1e-12f ? minf(maxf(sumNew / sumOld, 1.f / kAntilagMaxRatio), kAntilagMaxRatio) : 1.f;
    float residual = 0.f, scale = 0.f;
    for (int k = 0; k < count; ++k) {
        const float rescaled = ratio * samples[k].y;
        residual += fabsf(samples[k].x - rescaled);
        scale += maxf(samples[k].x, rescaled);
    }
    return glm::vec2(scale > 1e-12f ? minf(residual / scale, 1.f) : 0.f, ratio);
}

/// The spatial variance estimate's weight, spelt in operations a vector unit performs identically (products and
/// sums without contraction, a polynomial exponential), so the vectorised variance stage (TemporalSimd.cpp)
/// reproduces it bit for bit. It is Falcor's computeWeight, exp(-|dl| / phiColor - |dz| / (phiDepth |(i, j)|)) *
/// max(0, n.n')^phiNormal (paper eq. 3-5 without the variance in the luminance term), as one power of two:
/// - the normal power, for phiNormal >= kWeightSeriesMinPhi, as exp(-phi (d + d^2/2 + d^3/3 + d^4/4)) with
///   d = 1 - n.n' in [0, 1) (the first terms of -ln(1 - d); absolute error <= 3.2e-6 for phi >= 32); below that,
///   powf;
/// - 2^-t = 2^-round(t) p(round(t) - t), p a degree-4 fit of 2^f on [-0.5, 0.5] (exp2Neg of loom/KernelMath.h,
///   relative error <= 2.6e-6), t clamped to 100 (weights below 2^-100 stay there).
/// The à-trous fast path (AtrousSimd.cpp) uses the same normal series and clamp, its exponential the same
/// polynomial shifted to [0, 1).
inline constexpr float kWeightSeriesMinPhi = 32.f;
inline constexpr float kWeightLog2e = 1.44269504088896341f;
inline constexpr float kWeightMaxExponent = 100.f;

/// 1 / |(i, j)| for tap (i, j) of the 7x7 footprint (|i|, |j| <= 3); 0 for the centre, whose depth term is 0.
LOOM_HD inline float varianceInvDistance(int i, int j) {
    switch (i * i + j * j) {
        case 1:
            return 1.f;
        case 2:
            return 0.707106769f;
        case 4:
            return 0.5f;
        case 5:
            return 0.447213590f;
        case 8:
            return 0.353553385f;
        case 9:
            return 0.333333343f;
        case 10:
            return 0.316227764f;
        case 13:
            return 0.277350098f;
        case 18:
            return 0.235702261f;
        default:
            return 0.f;
    }
}

/// 2^-t for t >= 0 (see above): the operations of the vector stage, lane for lane.
LOOM_HD inline float varianceExp2Neg(float t) {
    return exp2Neg(minf(t, kWeightMaxExponent));
}

/// What every tap of a centre shares: the scales of the luminance term and of the normal series.
struct VarianceScales {
    float invPhiL;    ///< 1 / phiColor (1e30 for phiColor <= 0)
    float phiNormal;  ///< the normal power
    bool series;      ///< phiNormal >= kWeightSeriesMinPhi: the series form
    float terms[4];   ///< phi log2(e) / k, k = 1..4
};

/// The series form's coefficients phi log2(e) / k, k = 1..4: the normal weight's exponent in powers of two (the
/// à-trous fast path's too).
LOOM_HD inline void normalSeriesTerms(float phi, float terms[4]) {
    for (int k = 0; k < 4; ++k) terms[k] = phi * kWeightLog2e / float(k + 1);
}

LOOM_HD inline VarianceScales varianceScales(const AtrousParams& p) {
    VarianceScales s{};
    s.invPhiL = p.phiColor > 0.f ? 1.f / p.phiColor : 1e30f;
    s.phiNormal = maxf(p.phiNormal, 0.f);
    s.series = s.phiNormal >= kWeightSeriesMinPhi;
    normalSeriesTerms(s.phiNormal, s.terms);
    return s;
}

/// The weight of a tap at depth difference |dz| (invDepth: 1 / (phiDepth |(i, j)|)), normals nC, nT (finite) and
/// luminances lC, lT.
LOOM_HD inline float varianceWeight(float dz, float invDepth, const glm::vec3& nC, const glm::vec3& nT, float lC,
                                    float lT, const VarianceScales& s) {
    const float cosine = (nC.x * nT.x + nC.y * nT.y) + nC.z * nT.z;
    if (!(cosine > 0.f)) return 0.f;
    const float linear = fabsf(lC - lT) * s.invPhiL + fabsf(dz) * invDepth;
    if (!s.series) {
        const float wn = cosine >= 1.f ? 1.f : powf(cosine, s.phiNormal);
        return expf(-linear) * wn;
    }
    const float d = maxf(1.f - cosine, 0.f);
    const float normal = d * (s.terms[0] + d * (s.terms[1] + d * (s.terms[2] + d * s.terms[3])));
    return varianceExp2Neg(linear * kWeightLog2e + normal);
}

/// Views of the variance stage: integrated signals and moments in, à-trous input out.
struct VarianceViews {
    ImageView<const glm::vec4> integrated0, integrated1, normW;
    ImageView<const glm::vec2> moments0, moments1;  // (m1, m2) of each signal; moments1 split only
    ImageView<const glm::vec2> linearZ;
    ImageView<const float> length;
    ImageView<glm::vec4> estimate0, estimate1;
    ImageView<float> variance;  // optional debug output: the estimate's variance (both signals summed)
};

/// Whether a pixel at depth z with history `length` takes the spatial estimate: a hit whose history is short.
LOOM_HD inline bool needsSpatialVariance(float z, float length) {
    return z >= 0.f && !(length >= kSpatialVarianceFrames);
}

/// Stage 2 for pixel (x, y): the temporal variance where history is long enough; else a 7x7 edge-aware filter of
/// the integrated colour and the moments whose variance is boosted by 4 / n for the first frames (Falcor), with
/// the weights' scales s (varianceScales).
LOOM_HD inline void varianceEstimatePixel(const VarianceViews& v, uint32_t x, uint32_t y, const VarianceScales& s,
                                          bool split) {
    const glm::vec4 i0 = v.integrated0.at(x, y);
    const glm::vec4 i1 = split ? v.integrated1.at(x, y) : glm::vec4(0.f);
    const float length = v.length.at(x, y);
    const glm::vec2 z = v.linearZ.at(x, y);
    if (!needsSpatialVariance(z.x, length)) {
        v.estimate0.at(x, y) = i0;
        if (split) v.estimate1.at(x, y) = i1;
        if (v.variance.data) v.variance.at(x, y) = i0.a + i1.a;
        return;
    }
    const glm::vec3 n = finiteOrZero(glm::vec3(v.normW.at(x, y)));
    const float l0 = luminance(glm::vec3(i0)), l1 = luminance(glm::vec3(i1));
    const float invPhiDepth = 1.f / (maxf(z.y, 1e-8f) * 3.f);
    glm::vec3 sum0(0.f), sum1(0.f);
    glm::vec4 sumMoments(0.f);
    float sumW0 = 0.f, sumW1 = 0.f;
    const int w = int(v.integrated0.width), h = int(v.integrated0.height);
    for (int j = -3; j <= 3; ++j) {
        const int qy = int(y) + j;
        if (qy < 0 || qy >= h) continue;
        for (int i = -3; i <= 3; ++i) {
            const int qx = int(x) + i;
            if (qx < 0 || qx >= w) continue;
            const glm::vec2 zq = v.linearZ.at(uint32_t(qx), uint32_t(qy));
            if (!(zq.x >= 0.f) || !isFinite(zq.x)) continue;  // misses and non-finite depths
            const glm::vec3 nq = finiteOrZero(glm::vec3(v.normW.at(uint32_t(qx), uint32_t(qy))));
            const glm::vec4 q0 = v.integrated0.at(uint32_t(qx), uint32_t(qy));
            const glm::vec4 mq = momentsAt(v.moments0, v.moments1, uint32_t(qx), uint32_t(qy));
            const float invDepth = invPhiDepth * varianceInvDistance(i, j);
            const float dz = z.x - zq.x;
            const float w0 = varianceWeight(dz, invDepth, n, nq, l0, luminance(glm::vec3(q0)), s);
            sum0.x += w0 * q0.x;
            sum0.y += w0 * q0.y;
            sum0.z += w0 * q0.z;
            sumMoments.x += w0 * mq.x;
            sumMoments.y += w0 * mq.y;
            sumW0 += w0;
            if (split) {
                const glm::vec4 q1 = v.integrated1.at(uint32_t(qx), uint32_t(qy));
                const float w1 = varianceWeight(dz, invDepth, n, nq, l1, luminance(glm::vec3(q1)), s);
                sum1.x += w1 * q1.x;
                sum1.y += w1 * q1.y;
                sum1.z += w1 * q1.z;
                sumMoments.z += w1 * mq.z;
                sumMoments.w += w1 * mq.w;
                sumW1 += w1;
            }
        }
    }
    // The centre tap has weight 1 unless its normal is degenerate; then keep the temporal values.
    const float boost = kSpatialVarianceFrames / maxf(length, 1.f);
    glm::vec4 e0 = i0, e1 = i1;
    if (sumW0 > 0.f) {
        const float m1 = sumMoments.x / sumW0, m2 = sumMoments.y / sumW0;
        e0 = glm::vec4(sum0.x / sumW0, sum0.y / sumW0, sum0.z / sumW0, maxf(0.f, m2 - m1 * m1) * boost);
    }
    if (split && sumW1 > 0.f) {
        const float m1 = sumMoments.z / sumW1, m2 = sumMoments.w / sumW1;
        e1 = glm::vec4(sum1.x / sumW1, sum1.y / sumW1, sum1.z / sumW1, maxf(0.f, m2 - m1 * m1) * boost);
    }
    v.estimate0.at(x, y) = e0;
    if (split) v.estimate1.at(x, y) = e1;
    if (v.variance.data) v.variance.at(x, y) = e0.a + (split ? e1.a : 0.f);
}

/// Views of the modulation stage (filtered1: split only).
struct ModulateViews {
    ImageView<const glm::vec4> filtered0, filtered1, color, albedo, emission;
    ImageView<const glm::vec2> linearZ;
    ImageView<glm::vec4> dst;
};

/// Remodulation of one pixel: albedo * illum + emission; miss pixels (z < 0) copy the input colour (non-finite
/// channels as 0). The alpha channel is the input colour's.
LOOM_HD inline glm::vec4 remodulate(const glm::vec3& illum, const glm::vec4& color, const glm::vec4& albedo,
                                    const glm::vec3& emission, float z) {
    const float alpha = isFinite(color.a) ? color.a : 1.f;
    if (!(z >= 0.f)) return glm::vec4(finiteOrZero(glm::vec3(color)), alpha);
    return glm::vec4(illum * guardedAlbedo(albedo) + finiteOrZero(emission), alpha);
}

/// Stage 4 for pixel (x, y): remodulate() of the sum of the filtered signals.
LOOM_HD inline void modulatePixel(const ModulateViews& v, uint32_t x, uint32_t y, bool split) {
    glm::vec3 illum = glm::vec3(v.filtered0.at(x, y));
    if (split) illum += glm::vec3(v.filtered1.at(x, y));
    const glm::vec3 emission = v.emission.data ? glm::vec3(v.emission.at(x, y)) : glm::vec3(0.f);
    v.dst.at(x, y) = remodulate(illum, v.color.at(x, y), v.albedo.at(x, y), emission, v.linearZ.at(x, y).x);
}

}  // namespace loom::svgf
