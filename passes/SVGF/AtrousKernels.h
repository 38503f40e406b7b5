#pragma once
// The à-trous wavelet level of SVGF (Schied et al. 2017, section 4.3; Dammertz et al. 2010), one output pixel at a
// time. This scalar kernel is the reference: the CPU fast path (Atrous.h) and a CUDA backend must agree with it.
//
// Signal: demodulated illumination, rgb = colour, a = its luminance variance.
// Guides: the standard channels linearZ (x: view depth, -1 on a miss; y: its screen-space derivative) and normW.
//
// For a centre pixel p and a tap q = p + step * (i, j), i, j in [-2, 2]:
//   h(q)  = b(i) b(j), b = (1, 4, 6, 4, 1) / 16                                      (B3 spline)
//   w_z   = exp(-|z_p - z_q| / (phiDepth * dz_p * step * |(i, j)| + eps))               (paper eq. 3, the gradient
//           times the screen distance of the tap)
//   w_n   = min(clamp(n_p . n_q, 0, 1.01) ^ phiNormal, 1e15)                            (eq. 4; the caps matter only
//           for normals that are not unit length)
//   w_l   = exp(-|l_p - l_q| / (phiColor * sqrt(max(0, g(Var)_p)) + eps))              (eq. 5, g = 3x3 Gaussian
//           (1/4 centre, 1/8 edges, 1/16 corners) of the variance around p at unit spacing)
//   w     = w_z * w_n * w_l
//   out.rgb = sum h w c_q / sum h w,   out.a = sum h^2 w^2 Var_q / (sum h w)^2         (eq. 2 and variance
//           propagated with squared weights)
// Taps outside the frame and taps on miss pixels (z_q < 0) are skipped, and the weights renormalised, so a constant
// signal passes through unchanged. A miss centre pixel (z_p < 0) is passed through untouched.
#include <glm/glm.hpp>

#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/Texture.h"

namespace loom::svgf {

/// Edge-stopping parameters (the paper's). SVGFPass binds its phiColor, phiNormal and phiDepth to this struct, so these
/// are the pass's defaults too.
struct AtrousParams {
    float phiColor = 4.f;
    float phiNormal = 128.f;
    float phiDepth = 1.f;
    /// Low-variance tile skip: a tile of kSkipTile x kSkipTile pixels whose every hit pixel has a variance below
    /// this times its squared luminance (a relative variance) keeps its input at every level. 0: off (exact).
    float skipRelVariance = 0.f;
};

/// Side of the square tiles of AtrousParams::skipRelVariance, in pixels.
inline constexpr uint32_t kSkipTile = 16;

inline constexpr float kAtrousEpsilon = 1e-10f;
/// The largest cosine between normals the normal weight uses (the fast path's cap): above 1 only for normals that
/// are not unit length.
inline constexpr float kAtrousMaxCosine = 1.01f;
/// The largest normal weight: its square, summed over 25 taps, stays finite.
inline constexpr float kAtrousMaxNormalWeight = 1e15f;

/// 3x3 Gaussian of the variance (alpha) around (x, y) at unit spacing, over the in-frame, non-miss pixels.
LOOM_HD inline float blurredVariance(ImageView<const glm::vec4> illum, ImageView<const glm::vec2> linearZ, int x,
                                     int y) {
    const float kernel[2][2] = {{1.f / 4.f, 1.f / 8.f}, {1.f / 8.f, 1.f / 16.f}};
    float sum = 0.f, weight = 0.f;
    for (int j = -1; j <= 1; ++j) {
        for (int i = -1; i <= 1; ++i) {
            const int qx = x + i, qy = y + j;
            if (qx < 0 || qy < 0 || qx >= int(illum.width) || qy >= int(illum.height)) continue;
            if (linearZ.at(uint32_t(qx), uint32_t(qy)).x < 0.f) continue;
            const float k = kernel[i < 0 ? -i : i][j < 0 ? -j : j];
            sum += k * illum.at(uint32_t(qx), uint32_t(qy)).a;
            weight += k;
        }
    }
    return weight > 0.f ? sum / weight : 0.f;
}

/// One output pixel of an à-trous level with tap spacing `step` (1, 2, 4, ...).
LOOM_HD inline glm::vec4 atrousPixel(ImageView<const glm::vec4> illum, ImageView<const glm::vec2> linearZ,
                                     ImageView<const glm::vec4> normal, int x, int y, int step,
                                     const AtrousParams& p) {
    const glm::vec4 centre = illum.at(uint32_t(x), uint32_t(y));
    const glm::vec2 zCentre = linearZ.at(uint32_t(x), uint32_t(y));
    if (zCentre.x < 0.f) return centre;
    const glm::vec3 nCentre = glm::vec3(normal.at(uint32_t(x), uint32_t(y)));
    const float lCentre = luminance(glm::vec3(centre));
    const float variance = blurredVariance(illum, linearZ, x, y);
    const float phiL = p.phiColor * sqrtf(fmaxf(0.f, variance)) + kAtrousEpsilon;
    const float phiZ = p.phiDepth * zCentre.y * float(step);
    const float b3[3] = {6.f / 16.f, 4.f / 16.f, 1.f / 16.f};

    glm::vec3 sumColour(0.f);
    float sumVariance = 0.f, sumWeight = 0.f;
    for (int j = -2; j <= 2; ++j) {
        for (int i = -2; i <= 2; ++i) {
            const int qx = x + i * step, qy = y + j * step;
            if (qx < 0 || qy < 0 || qx >= int(illum.width) || qy >= int(illum.height)) continue;
            const glm::vec2 zq = linearZ.at(uint32_t(qx), uint32_t(qy));
            if (zq.x < 0.f) continue;
            const glm::vec4 cq = illum.at(uint32_t(qx), uint32_t(qy));
            const glm::vec3 nq = glm::vec3(normal.at(uint32_t(qx), uint32_t(qy)));
            const float h = b3[i < 0 ? -i : i] * b3[j < 0 ? -j : j];
            const float distance = sqrtf(float(i * i + j * j));
            const float wz = fabsf(zCentre.x - zq.x) / (phiZ * distance + kAtrousEpsilon);
            const float wl = fabsf(lCentre - luminance(glm::vec3(cq))) / phiL;
            // The cosine capped at kAtrousMaxCosine (as the fast path) and the power at kAtrousMaxNormalWeight: a
            // non-unit normal must not overflow it (Inf / Inf was NaN). Unit normals are unaffected.
            const float cosine = fminf(fmaxf(0.f, glm::dot(nCentre, nq)), kAtrousMaxCosine);
            const float wn = fminf(powf(cosine, p.phiNormal), kAtrousMaxNormalWeight);
            const float w = h * expf(-wz - wl) * wn;
            sumColour += w * glm::vec3(cq);
            sumVariance += w * w * cq.a;
            sumWeight += w;
        }
    }
    // The centre tap has w = h(0) > 0 (its own depth, normal and luminance), so sumWeight > 0 unless the normal
    // is degenerate; then keep the input.
    if (!(sumWeight > 0.f)) return centre;
    return glm::vec4(sumColour / sumWeight, sumVariance / (sumWeight * sumWeight));
}

}  // namespace loom::svgf
