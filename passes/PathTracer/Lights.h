#pragma once
// Light sampling for next-event estimation: emissive triangles chosen in
// proportion to their power (area times the mean emitted luminance over the
// triangle, its emissive texture's footprint included), punctual lights
// (KHR_lights_punctual), and the environment (importance-sampled when it is an
// HDR map). Plain views built by the pass each frame (emissive triangles move
// with their instances).
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "BRDF.h"  // kPi, kInvPi
#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/SceneView.h"
#include "loom/SurfaceKernels.h"

namespace loom::pt {

struct EmissiveTri {
    glm::vec3 p0, e1, e2;   ///< world space: p0, p1 - p0, p2 - p0
    glm::vec3 normal;       ///< unit geometric normal (front side)
    float area = 0.f;
    float power = 0.f;  ///< selection weight: area * mean luminance of the emission over the triangle; 0: no light
    uint32_t instance = 0, primitive = 0;
    uint32_t doubleSided = 0;
    uint32_t textured = 0;  ///< emission varies over the triangle (emissive texture): evaluate the material
    uint32_t alphaTested = 0;  ///< alphaMode MASK or BLEND (with alpha testing on): emission scaled by coverage
    glm::vec3 radiance{0.f};  ///< emitted radiance when not textured
    float pdfArea = 0.f;      ///< pTris * (triCdf[i + 1] - triCdf[i]) / area: area density of a light sample on it,
                              ///< selection included (the probability sampleLight picks it; filled by the pass)
};

enum PunctualType : uint32_t { kPoint = 0, kSpot = 1, kDirectional = 2 };

struct PunctualLight {
    uint32_t type = kPoint;
    glm::vec3 position{0.f};
    glm::vec3 direction{0.f, 0.f, -1.f};  ///< where the light points
    glm::vec3 intensity{0.f};             ///< colour * intensity (cd, or lux for directional)
    float cosInner = 1.f, cosOuter = 0.f;
    float range = 0.f;                    ///< 0 = infinite
};

/// Equirectangular environment: u = 0.5 + atan2(d.x, -d.z) / 2pi, v = acos(d.y) / pi (row 0 = +Y).
struct EnvView {
    const glm::vec3* texels = nullptr;  ///< nullptr: constant colour
    uint32_t width = 0, height = 0;
    glm::vec3 color{0.f};
    float intensity = 1.f;
    const float* marginalCdf = nullptr;     ///< height + 1 entries
    const float* conditionalCdf = nullptr;  ///< height rows of width + 1 entries
    float weightSum = 0.f;                  ///< sum of texel weights (luminance * sin(theta))
};

struct LightsView {
    const EmissiveTri* tris = nullptr;
    const float* triCdf = nullptr;      ///< triCount + 1 entries, triCdf[triCount] = 1
    const uint32_t* instanceTriBase = nullptr;  ///< per instance: index of its first triangle in tris, or ~0u
    uint32_t triCount = 0;
    float triPowerSum = 0.f;
    const PunctualLight* punctual = nullptr;
    uint32_t punctualCount = 0;
    EnvView env;
    bool hasEnv = false;
    float pTris = 0.f, pPunctual = 0.f, pEnv = 0.f;  ///< category selection probabilities
};

LOOM_HD inline glm::vec2 envUv(glm::vec3 d) {
    const float u = 0.5f + std::atan2(d.x, -d.z) * (0.5f * kInvPi);
    const float v = std::acos(glm::clamp(d.y, -1.f, 1.f)) * kInvPi;
    return {u, v};
}
LOOM_HD inline glm::vec3 envDir(glm::vec2 uv) {
    const float phi = (uv.x - 0.5f) * 2.f * kPi, theta = uv.y * kPi;
    const float s = std::sin(theta);
    return {s * std::sin(phi), std::cos(theta), -s * std::cos(phi)};
}

LOOM_HD inline glm::vec3 envRadiance(const EnvView& env, glm::vec3 d) {
    if (!env.texels) return env.color * env.intensity;
    const glm::vec2 uv = envUv(d);
    const uint32_t x = glm::min(uint32_t(uv.x * float(env.width)), env.width - 1);
    const uint32_t y = glm::min(uint32_t(uv.y * float(env.height)), env.height - 1);
    return env.texels[size_t(y) * env.width + x] * env.intensity;
}

/// First index i with cdf[i + 1] > u, for cdf of n + 1 increasing entries from 0 to 1.
LOOM_HD inline uint32_t searchCdf(const float* cdf, uint32_t n, float u) {
    uint32_t lo = 0, hi = n;
    while (lo + 1 < hi) {
        const uint32_t mid = (lo + hi) / 2;
        if (cdf[mid] <= u) lo = mid; else hi = mid;
    }
    return lo;
}

/// Solid-angle pdf of sampling direction d from the environment.
LOOM_HD inline float envPdf(const EnvView& env, glm::vec3 d) {
    if (!env.texels) return 1.f / (4.f * kPi);
    if (env.weightSum <= 0.f) return 0.f;
    const glm::vec2 uv = envUv(d);
    const uint32_t x = glm::min(uint32_t(uv.x * float(env.width)), env.width - 1);
    const uint32_t y = glm::min(uint32_t(uv.y * float(env.height)), env.height - 1);
    const float* row = env.conditionalCdf + size_t(y) * (env.width + 1);
    const float pRow = env.marginalCdf[y + 1] - env.marginalCdf[y];
    const float pCol = row[x + 1] - row[x];
    const float sinTheta = std::sqrt(glm::max(0.f, 1.f - d.y * d.y));
    if (sinTheta <= 1e-7f) return 0.f;
    // Uniform in (u, v) within the texel; dω = 2π² sinθ du dv.
    return pRow * pCol * float(env.width) * float(env.height) / (2.f * kPi * kPi * sinTheta);
}

struct LightSample {
    glm::vec3 wi{0.f};     ///< unit direction from the shading point to the light
    glm::vec3 Li{0.f};     ///< incident radiance (or irradiance-like value for delta lights)
    float pdf = 0.f;       ///< solid-angle pdf including the light selection; 1 for delta lights
    float distance = 0.f;  ///< to the light point (infinity for the environment and directional lights)
    bool delta = false;
    bool valid = false;
    uint32_t instance = 0, primitive = 0;  ///< emissive triangle (for evaluating textured emission)
    glm::vec2 bary{0.f};
    bool isTriangle = false;   ///< the caller evaluates the emission at the point (lightSampleRadiance())
    bool alphaTested = false;  ///< the emitter's coverage there scales it (expectedCoverage())
};

/// Fills the selection CDF of n emissive triangles by power (n + 1 entries, from 0 to exactly 1; uniform when no
/// triangle has power) and returns the power sum.
inline double fillTriangleCdf(const EmissiveTri* tris, uint32_t n, float* cdf) {
    double total = 0.0;
    for (uint32_t i = 0; i < n; ++i) total += tris[i].power;
    double acc = 0.0;
    cdf[0] = 0.f;
    for (uint32_t i = 0; i < n; ++i) {
        acc += tris[i].power;
        cdf[i + 1] = total > 0.0 ? float(acc / total) : float(i + 1) / float(n);
    }
    if (n > 0) cdf[n] = 1.f;
    return total;
}

/// Sets each triangle's pdfArea: the area density of a light sample on it, with the probability that sampleLight's
/// search of the CDF picks it (cdf[i + 1] - cdf[i], exactly as stored, times pTris). A triangle of no power has an
/// empty interval, is never picked and gets density 0, so a BRDF-sampled hit on it gets the full MIS weight.
inline void setTrianglePdfs(EmissiveTri* tris, uint32_t n, const float* cdf, float pTris) {
    for (uint32_t i = 0; i < n; ++i) {
        EmissiveTri& t = tris[i];
        t.pdfArea = t.area > 0.f && t.power > 0.f ? pTris * (cdf[i + 1] - cdf[i]) / t.area : 0.f;
    }
}

/// Area pdf of a triangle light point converted to solid angle, with selection.
LOOM_HD inline float triLightPdf(const LightsView& L, const EmissiveTri& t, float dist2, float cosLight) {
    if (cosLight <= 0.f || L.triPowerSum <= 0.f) return 0.f;
    return t.pdfArea * dist2 / cosLight;
}

/// Samples a light for shading point p. u: four uniform numbers.
/// For a textured emissive triangle the radiance is left to the caller
/// (isTriangle = true), which evaluates the material at the sampled point.
LOOM_HD inline LightSample sampleLight(const LightsView& L, glm::vec3 p, float u0, float u1, float u2, float u3) {
    LightSample s;
    if (u0 < L.pTris) {
        const uint32_t i = searchCdf(L.triCdf, L.triCount, u1);
        const EmissiveTri& t = L.tris[i];
        // Uniform point on the triangle (Shirley's square-root mapping).
        const float su = std::sqrt(u2);
        const float bu = su * (1.f - u3), bv = su * u3;
        const glm::vec3 q = t.p0 + bu * t.e1 + bv * t.e2;
        glm::vec3 d = q - p;
        const float dist2 = glm::dot(d, d);
        if (dist2 <= 1e-12f) return s;
        const float dist = std::sqrt(dist2);
        d *= 1.f / dist;
        float cosLight = -glm::dot(t.normal, d);
        if (t.doubleSided) cosLight = std::fabs(cosLight);
        s.pdf = triLightPdf(L, t, dist2, cosLight);
        if (s.pdf <= 0.f) return s;
        s.wi = d;
        s.distance = dist;
        s.instance = t.instance;
        s.primitive = t.primitive;
        s.bary = glm::vec2(bu, bv);
        s.isTriangle = t.textured != 0 || t.alphaTested != 0;  // else the radiance is known
        s.alphaTested = t.alphaTested != 0;
        s.Li = t.radiance;
        s.valid = true;
        return s;
    }
    u0 -= L.pTris;
    if (u0 < L.pPunctual) {
        const uint32_t i = glm::min(uint32_t(u1 * float(L.punctualCount)), L.punctualCount - 1);
        const PunctualLight& l = L.punctual[i];
        const float select = L.pPunctual / float(L.punctualCount);
        s.delta = true;
        s.pdf = select;
        if (l.type == kDirectional) {
            s.wi = -l.direction;
            s.distance = 1e30f;
            s.Li = l.intensity;
        } else {
            glm::vec3 d = l.position - p;
            const float dist2 = glm::dot(d, d);
            if (dist2 <= 1e-12f) return s;
            const float dist = std::sqrt(dist2);
            d /= dist;
            float atten = 1.f / dist2;
            if (l.range > 0.f) {
                // glTF's recommended smooth range falloff (KHR_lights_punctual).
                const float r = dist / l.range;
                atten *= glm::clamp(1.f - r * r * r * r, 0.f, 1.f);
            }
            if (l.type == kSpot) {
                const float cd = glm::dot(-d, l.direction);
                const float t = glm::clamp((cd - l.cosOuter) / glm::max(l.cosInner - l.cosOuter, 1e-4f), 0.f, 1.f);
                atten *= t * t;
            }
            s.wi = d;
            s.distance = dist;
            s.Li = l.intensity * atten;
        }
        s.valid = glm::dot(s.Li, s.Li) > 0.f;
        return s;
    }
    if (!L.hasEnv) return s;
    u0 -= L.pPunctual;
    const float uJitter = glm::clamp(u0 / glm::max(L.pEnv, 1e-12f), 0.f, 0.99999994f);  // reuse of the selector
    const EnvView& env = L.env;
    if (!env.texels) {
        // Uniform sphere for a constant environment.
        const float z = 1.f - 2.f * u1, r = std::sqrt(glm::max(0.f, 1.f - z * z)), phi = 2.f * kPi * u2;
        s.wi = glm::vec3(r * std::cos(phi), z, r * std::sin(phi));
    } else {
        const uint32_t y = searchCdf(env.marginalCdf, env.height, u1);
        const float* row = env.conditionalCdf + size_t(y) * (env.width + 1);
        const uint32_t x = searchCdf(row, env.width, u2);
        s.wi = envDir(glm::vec2((float(x) + u3) / float(env.width), (float(y) + uJitter) / float(env.height)));
    }
    const float pdf = envPdf(env, s.wi);
    if (pdf <= 0.f) return s;
    s.pdf = L.pEnv * pdf;
    s.distance = 1e30f;
    s.Li = envRadiance(env, s.wi);
    s.valid = true;
    return s;
}

/// Barycentrics (u, v) of point k of a stratified set of m * m points on a triangle: the centroids of the m * m
/// equal-area triangles of its m-fold subdivision (midpoint rule). Points k < m (m + 1) / 2 are the centroids of the
/// upright sub-triangles, row by row; the rest those of the inverted ones.
LOOM_HD inline glm::vec2 subTriangleCentroid(uint32_t m, uint32_t k) {
    const uint32_t upright = m * (m + 1) / 2;
    const bool inverted = k >= upright;
    if (inverted) k -= upright;
    const uint32_t rowLength0 = inverted ? m - 1 : m;  // sub-triangles in row 0; each row has one fewer
    uint32_t i = 0;
    while (k >= rowLength0 - i) k -= rowLength0 - i++;
    const float offset = inverted ? 2.f / 3.f : 1.f / 3.f;
    return glm::vec2((float(i) + offset) / float(m), (float(k) + offset) / float(m));
}

/// Mean luminance of the emission over triangle `prim` of an instance, from the material evaluated (evalSurface,
/// so the texture is sampled exactly as shading samples it) at the m * m points of subTriangleCentroid. The mean
/// over area: the barycentric grid is uniform over the triangle under any affine transform of it.
LOOM_HD inline float meanEmittedLuminance(const SceneView& scene, uint32_t instance, uint32_t prim, uint32_t m) {
    float sum = 0.f;
    for (uint32_t k = 0; k < m * m; ++k) {
        const glm::vec2 b = subTriangleCentroid(m, k);
        // The direction only decides which side faces the viewer; emission does not depend on it.
        sum += luminance(
            evalSurface(scene, instance, prim, b.x, b.y, glm::vec3(0.f, 0.f, -1.f), SurfaceEval::Shading).emission);
    }
    return sum / float(m * m);
}

/// Power heuristic (Veach 1997, eq. 9.13) with beta = 2.
LOOM_HD inline float powerHeuristic(float a, float b) {
    const float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.f ? a2 / (a2 + b2) : 0.f;
}

}  // namespace loom::pt
