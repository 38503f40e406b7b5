#pragma once
// The path tracer's BRDF: glTF 2.0 metallic-roughness, as written in the glTF 2.0 specification, Appendix B
// ("BRDF Implementation"), with importance sampling and the matching pdf for multiple importance sampling.
//
// Conventions
//   n   the shading normal, unit length, on the viewer's side of the surface.
//   wo  unit direction from the shading point toward the viewer (the previous path vertex).
//   wi  unit direction from the shading point toward the light (the next path vertex).
//   The functions taking (n, wo, wi) work in a local frame where n is +z (makeFrame()); the *Local functions take
//   local directions directly. evalBrdf() is f(wo, wi) without the cosine: the integrator multiplies by n.wi.
//   Reflection only: f = 0 when n.wo <= 0 or n.wi <= 0.
//
// Model (glTF 2.0 Appendix B.3, "Specular BRDF", "Fresnel", "Metal BRDF and Dielectric BRDF")
//   alpha = max(roughness^2, kMinAlpha)
//   D     GGX / Trowbridge-Reitz normal distribution (Walter et al. 2007, "Microfacet Models for Refraction through
//         Rough Surfaces", eq. 33).
//   V     height-correlated Smith visibility, V = G2 / (4 |n.wi| |n.wo|), G2 = 1 / (1 + Lambda(wo) + Lambda(wi))
//         (Heitz 2014, "Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs", JCGT 3(2); the
//         closed form is glTF Appendix B, "Specular BRDF").
//   F     Schlick 1994 on VdotH: f0 + (f90 - f0) (1 - |wo.h|)^5, h = normalize(wo + wi). The dielectric has f0 = 0.04
//         and f90 = 1 unless KHR_materials_ior / KHR_materials_specular say otherwise; a metal has f0 = baseColor,
//         f90 = 1. Schlick's F is linear in (f0, f90), so the spec's mix(dielectric, metal, metallic) of the specular
//         lobes is one evaluation with mixed f0 and f90.
//
//   Two models (BrdfInputs::multiScatter):
//   - plain (false): the specification's model exactly,
//       f = F D V + (1 - metallic) baseColor / pi (1 - Fdielectric(wo.h))        (fresnel_mix of Appendix B)
//     It loses the energy of multiple scattering between microfacets (a rough white metal reflects 0.4 at
//     grazing views) and creates energy at grazing views of smooth dielectrics (1.85 at 89 degrees).
//   - energy-compensated (true, the default): the same single-scattering specular lobe, plus Kulla and Conty's
//     multiple-scattering lobe, and the diffuse lobe scaled by what the whole specular layer does not reflect
//     (makeBrdfLobes() has the formulas and the references). In a white furnace every white material reflects 1 of
//     the light at every view, up to the resolution of the albedo tables (test_brdf.cpp).
//
// Sampling: a one-sample mixture (Veach 1997, thesis section 9.2.4, "the one-sample model") of cosine-weighted
// hemisphere sampling for the diffuse lobe and GGX visible-normal sampling for the specular lobe (Heitz 2018,
// "Sampling the GGX Distribution of Visible Normals", JCGT 7(4)). The pdf that samples carry and pdfBrdf() returns is
// the density of the whole mixture, which is what MIS with light sampling needs. Visible-normal sampling can reflect
// below the surface; such samples are returned invalid (the path ends), and pdfBrdf() keeps their density so that it
// integrates to 1 over the sphere.
//
// This is kernel code (see loom/Kernel.h): plain inline functions over plain structs, so nvcc can compile it.
#include <cmath>
#include <glm/glm.hpp>

#include "BrdfTables.h"
#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/SurfaceKernels.h"

namespace loom::pt {

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInvPi = 0.31830988618379067154f;

/// Reflectance at normal incidence of the glTF dielectric (index of refraction 1.5: ((1.5 - 1) / (1.5 + 1))^2).
inline constexpr float kDielectricF0 = 0.04f;

/// Smallest GGX alpha used. roughness = 0 would make D a Dirac delta, which evalBrdf() cannot represent and which
/// would give 0/0 in the pdf; alpha = 1e-3 is a mirror for any practical purpose (lobe about 0.1 degree wide) while
/// D's peak 1 / (pi alpha^2) ~ 3e5 stays far from float overflow.
inline constexpr float kMinAlpha = 1e-3f;

// ---------------------------------------------------------------------------------------------------------------------
// Local frame

/// Orthonormal basis (t, b, n) with t x b = n.
struct Frame {
    glm::vec3 t{1.f, 0.f, 0.f}, b{0.f, 1.f, 0.f}, n{0.f, 0.f, 1.f};

    LOOM_HD glm::vec3 toLocal(glm::vec3 v) const { return glm::vec3(glm::dot(v, t), glm::dot(v, b), glm::dot(v, n)); }
    LOOM_HD glm::vec3 toWorld(glm::vec3 v) const { return t * v.x + b * v.y + n * v.z; }
};

/// Basis around a unit normal (Duff et al. 2017, "Building an Orthonormal Basis, Revisited", JCGT 6(1): Frisvad's
/// construction with a copysign instead of a branch, accurate for every n including n near -z). Its discontinuity
/// where n.z changes sign is harmless: BRDFs here are isotropic, so only n matters.
LOOM_HD inline Frame makeFrame(glm::vec3 n) {
    const float sign = std::copysign(1.f, n.z);
    const float a = -1.f / (sign + n.z);
    const float b = n.x * n.y * a;
    Frame f;
    f.t = glm::vec3(1.f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    f.b = glm::vec3(b, sign + n.y * n.y * a, -n.y);
    f.n = n;
    return f;
}

// ---------------------------------------------------------------------------------------------------------------------
// Hemisphere sampling

/// cos(x) and sin(x) for |x| <= pi/4 from their Taylor series to x^10 and x^9: the first omitted terms are below
/// 2e-9 there, so the result is as accurate as float arithmetic allows (a few ulp), with no range reduction and no
/// libm call. Sampling calls it with angles already in that range.
LOOM_HD inline glm::vec2 cosSinQuarter(float x) {
    const float x2 = x * x;
    const float c = 1.f + x2 * (-1.f / 2.f + x2 * (1.f / 24.f + x2 * (-1.f / 720.f + x2 * (1.f / 40320.f +
                                                                                              x2 * (-1.f / 3628800.f)))));
    const float s = x * (1.f + x2 * (-1.f / 6.f + x2 * (1.f / 120.f + x2 * (-1.f / 5040.f + x2 * (1.f / 362880.f)))));
    return {c, s};
}

/// cos and sin of 2 pi u for u in [0, 1): the angle is split into the nearest multiple of pi/2 and a remainder in
/// [-pi/4, pi/4] (cosSinQuarter()), then rotated by the quadrant.
LOOM_HD inline glm::vec2 cosSinTurn(float u) {
    const float t = 4.f * u;
    const float q = std::floor(t + 0.5f);
    const glm::vec2 cs = cosSinQuarter((t - q) * (0.5f * kPi));
    switch (int(q) & 3) {
        case 0: return cs;
        case 1: return {-cs.y, cs.x};
        case 2: return -cs;
        default: return {cs.y, -cs.x};
    }
}

/// Maps the unit square to the unit disk, preserving area and keeping strata compact (Shirley and Chiu 1997, "A Low
/// Distortion Map Between Disk and Square").
LOOM_HD inline glm::vec2 sampleConcentricDisk(glm::vec2 u) {
    const float a = 2.f * u.x - 1.f, b = 2.f * u.y - 1.f;
    if (a == 0.f && b == 0.f) return glm::vec2(0.f);
    // phi = pi/4 (b / a), or pi/2 - pi/4 (a / b) whose cosine and sine are the sine and cosine of pi/4 (a / b).
    if (std::fabs(a) > std::fabs(b)) return a * cosSinQuarter(0.25f * kPi * (b / a));
    const glm::vec2 cs = cosSinQuarter(0.25f * kPi * (a / b));
    return b * glm::vec2(cs.y, cs.x);
}

/// Cosine-weighted direction about +z: a uniform disk point lifted to the hemisphere (Malley's method, as in Pharr
/// et al., "Physically Based Rendering"). pdf = cos(theta) / pi.
LOOM_HD inline glm::vec3 sampleCosineHemisphere(glm::vec2 u) {
    const glm::vec2 d = sampleConcentricDisk(u);
    return glm::vec3(d.x, d.y, std::sqrt(maxf(1.f - d.x * d.x - d.y * d.y, 0.f)));
}

/// Solid-angle pdf of sampleCosineHemisphere() for a direction with n.w = cosTheta.
LOOM_HD inline float cosineHemispherePdf(float cosTheta) {
    return cosTheta > 0.f ? cosTheta * kInvPi : 0.f;
}

// ---------------------------------------------------------------------------------------------------------------------
// GGX microfacet terms (local frame, n = +z)

/// GGX alpha from glTF perceptual roughness: alpha = roughness^2 (glTF Appendix B, "Specular BRDF"), clamped to
/// kMinAlpha.
LOOM_HD inline float alphaFromRoughness(float roughness) {
    return maxf(roughness * roughness, kMinAlpha);
}

/// GGX normal distribution D(h) for a unit local half vector (Walter et al. 2007, eq. 33), written as
/// 1 / (pi alpha^2 (x^2/alpha^2 + y^2/alpha^2 + z^2)^2) (Heitz 2018, eq. 1): with the tangential components kept
/// apart it does not lose precision to 1 - cos^2 when alpha is tiny.
LOOM_HD inline float ggxD(glm::vec3 h, float alpha) {
    if (h.z <= 0.f) return 0.f;
    const float a2 = alpha * alpha;
    const float t = (h.x * h.x + h.y * h.y) / a2 + h.z * h.z;
    return 1.f / (kPi * a2 * t * t);
}

/// Smith masking G1 = 1 / (1 + Lambda) for GGX, with Lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2 (Heitz 2014;
/// Walter et al. 2007, eq. 34), rewritten in cosines: 2 cos / (cos + sqrt(alpha^2 + (1 - alpha^2) cos^2)).
LOOM_HD inline float ggxG1(float cosTheta, float alpha) {
    if (cosTheta <= 0.f) return 0.f;
    const float a2 = alpha * alpha;
    return 2.f * cosTheta / (cosTheta + std::sqrt(a2 + (1.f - a2) * cosTheta * cosTheta));
}

/// Height-correlated Smith visibility V = G2 / (4 NdotL NdotV) for GGX, G2 = 1 / (1 + Lambda(wo) + Lambda(wi))
/// (Heitz 2014); the closed form is glTF Appendix B, "Specular BRDF".
LOOM_HD inline float ggxVisibility(float NdotL, float NdotV, float alpha) {
    if (NdotL <= 0.f || NdotV <= 0.f) return 0.f;
    const float a2 = alpha * alpha;
    const float gv = NdotL * std::sqrt(NdotV * NdotV * (1.f - a2) + a2);
    const float gl = NdotV * std::sqrt(NdotL * NdotL * (1.f - a2) + a2);
    return 0.5f / (gv + gl);
}

/// Schlick's weight (1 - cos)^5 (Schlick 1994, "An Inexpensive BRDF Model for Physically-based Rendering").
LOOM_HD inline float schlickWeight(float cosTheta) {
    const float m = glm::clamp(1.f - cosTheta, 0.f, 1.f);
    const float m2 = m * m;
    return m2 * m2 * m;
}

/// Schlick's Fresnel approximation f0 + (1 - f0) (1 - cos)^5.
LOOM_HD inline glm::vec3 schlickFresnel(glm::vec3 f0, float cosTheta) {
    return f0 + (glm::vec3(1.f) - f0) * schlickWeight(cosTheta);
}

/// Samples a microfacet normal from the GGX distribution of normals visible from wo (wo.z > 0), with density
/// D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z (Heitz 2018, eq. 2), by Heitz 2018's algorithm: stretch the view to the
/// alpha = 1 configuration, sample the projected area of the hemisphere (a disk whose far half is foreshortened by
/// the view), lift the point to the hemisphere and unstretch the normal.
LOOM_HD inline glm::vec3 sampleGgxVndf(glm::vec3 wo, float alpha, glm::vec2 u) {
    const glm::vec3 vh = glm::normalize(glm::vec3(alpha * wo.x, alpha * wo.y, wo.z));
    // Basis around the stretched view; any t1 works when the view is along +z.
    const float lenSq = vh.x * vh.x + vh.y * vh.y;
    const glm::vec3 t1 = lenSq > 0.f ? glm::vec3(-vh.y, vh.x, 0.f) / std::sqrt(lenSq) : glm::vec3(1.f, 0.f, 0.f);
    const glm::vec3 t2 = glm::cross(vh, t1);
    // Uniform point on the disk, then warp t2 so the density matches the hemisphere's projected area seen from the
    // view: the half of the disk beyond the horizon is foreshortened by (1 + vh.z) / 2.
    const float r = std::sqrt(u.x);
    const glm::vec2 cs = cosSinTurn(u.y);  // phi = 2 pi u.y
    const float p1 = r * cs.x;
    const float s = 0.5f * (1.f + vh.z);
    const float p2 = (1.f - s) * std::sqrt(maxf(1.f - p1 * p1, 0.f)) + s * r * cs.y;
    const glm::vec3 nh = p1 * t1 + p2 * t2 + std::sqrt(maxf(1.f - p1 * p1 - p2 * p2, 0.f)) * vh;
    return glm::normalize(glm::vec3(alpha * nh.x, alpha * nh.y, maxf(nh.z, 0.f)));
}

/// Solid-angle density of wi = reflect(-wo, h) for h drawn by sampleGgxVndf(): D_wo(h) / (4 wo.h) (Heitz 2018; the
/// Jacobian of reflection dh/dwi = 1 / (4 wi.h) is Walter et al. 2007, eq. 14). With G1 written out, wo.h and wo.z
/// cancel: D(h) / (2 (wo.z + sqrt(alpha^2 + (1 - alpha^2) wo.z^2))). Defined for wi below the surface too.
LOOM_HD inline float ggxReflectionPdf(glm::vec3 wo, glm::vec3 wi, float alpha) {
    if (wo.z <= 0.f) return 0.f;
    const glm::vec3 hSum = wo + wi;
    const float lenSq = glm::dot(hSum, hSum);
    if (!(lenSq > 1e-12f)) return 0.f;
    const glm::vec3 h = hSum / std::sqrt(lenSq);
    const float a2 = alpha * alpha;
    return ggxD(h, alpha) / (2.f * (wo.z + std::sqrt(a2 + (1.f - a2) * wo.z * wo.z)));
}

// ---------------------------------------------------------------------------------------------------------------------
// Directional albedo of the GGX lobe (BrdfTables.h)
//
// E(mu, roughness)  = integral over wi of D V (n.wi) with F = 1: the single-scattering albedo of the specular lobe;
// Es(mu, roughness) = the same integral weighted by Schlick's (1 - wo.h)^5.
// A lobe with Fresnel F = f0 + (f90 - f0) (1 - wo.h)^5 reflects f0 (E - Es) + f90 Es, for any f0 and f90.
// Both are tabulated on a kBrdfTableSize^2 grid of sqrt(mu) and roughness (nodes at i / (size - 1): dense toward
// grazing views, where E changes fastest), read bilinearly;
// the cosine-weighted means Eavg = 2 integral E(mu) mu dmu are the exact means of that bilinear interpolant, so
// the compensation below conserves energy exactly whatever the tables' resolution (only the single-scattering part
// is integrated for real).

/// Values of the tables (see ggxAlbedoTable()); on the device a copy in constant memory.
#if defined(__CUDACC__)
static __constant__ float kGgxAlbedoDevice[] = {LOOM_GGX_ALBEDO_TABLE};
static __constant__ float kGgxAlbedoAvgDevice[] = {LOOM_GGX_ALBEDO_AVG_TABLE};
#endif
inline constexpr float kGgxAlbedoHost[] = {LOOM_GGX_ALBEDO_TABLE};
inline constexpr float kGgxAlbedoAvgHost[] = {LOOM_GGX_ALBEDO_AVG_TABLE};
static_assert(sizeof(kGgxAlbedoHost) == sizeof(float) * 2 * kBrdfTableSize * kBrdfTableSize, "table size");
static_assert(sizeof(kGgxAlbedoAvgHost) == sizeof(float) * 2 * kBrdfTableSize, "table size");

/// [roughness][mu][E, Es], row-major.
LOOM_HD inline const float* ggxAlbedoTable() {
#if defined(__CUDA_ARCH__)
    return kGgxAlbedoDevice;
#else
    return kGgxAlbedoHost;
#endif
}
/// [roughness][Eavg, Esavg].
LOOM_HD inline const float* ggxAlbedoAvgTable() {
#if defined(__CUDA_ARCH__)
    return kGgxAlbedoAvgDevice;
#else
    return kGgxAlbedoAvgHost;
#endif
}

/// A table coordinate: x in [0, 1] (NaN read as 0) to a cell index and the fraction within it.
LOOM_HD inline int tableCell(float x, float& frac) {
    const float t = (x > 0.f ? (x < 1.f ? x : 1.f) : 0.f) * float(kBrdfTableSize - 1);
    const int i = int(t) < kBrdfTableSize - 2 ? int(t) : kBrdfTableSize - 2;
    frac = t - float(i);
    return i;
}

/// E and Es (see above) of one lobe.
struct GgxAlbedo {
    float e = 1.f;   ///< albedo with F = 1
    float es = 0.f;  ///< albedo weighted by (1 - wo.h)^5
};

/// E and Es at (mu = n.wo, roughness), bilinear in (sqrt(mu), roughness).
LOOM_HD inline GgxAlbedo ggxAlbedo(float mu, float roughness) {
    float fx, fy;
    const int x = tableCell(std::sqrt(maxf(mu, 0.f)), fx), y = tableCell(roughness, fy);
    const float* r0 = ggxAlbedoTable() + 2 * (y * kBrdfTableSize + x);
    const float* r1 = r0 + 2 * kBrdfTableSize;
    const float e0 = r0[0] + (r0[2] - r0[0]) * fx, e1 = r1[0] + (r1[2] - r1[0]) * fx;
    const float s0 = r0[1] + (r0[3] - r0[1]) * fx, s1 = r1[1] + (r1[3] - r1[1]) * fx;
    return {e0 + (e1 - e0) * fy, s0 + (s1 - s0) * fy};
}

/// The cosine-weighted means of E and Es over mu, at a roughness (linear in the table).
LOOM_HD inline GgxAlbedo ggxAlbedoAverage(float roughness) {
    float f;
    const int y = tableCell(roughness, f);
    const float* r = ggxAlbedoAvgTable() + 2 * y;
    return {r[0] + (r[2] - r[0]) * f, r[1] + (r[3] - r[1]) * f};
}

/// Kulla and Conty 2017 ("Revisiting Physically Based Shading at Imageworks", SIGGRAPH course, slides 18-20): the
/// fraction of the energy lost by single scattering that multiple scattering returns with Fresnel F:
/// Fms = Favg^2 Eavg / (1 - Favg (1 - Eavg)), with Favg = 2 integral F(mu) mu dmu = f0 + (f90 - f0) / 21 for Schlick.
LOOM_HD inline float multiScatterFresnel(float f0, float f90, float eAvg) {
    const float fAvg = f0 + (f90 - f0) * (1.f / 21.f);
    return fAvg * fAvg * eAvg / (1.f - fAvg * (1.f - eAvg));
}
LOOM_HD inline glm::vec3 multiScatterFresnel(glm::vec3 f0, float f90, float eAvg) {
    return {multiScatterFresnel(f0.x, f90, eAvg), multiScatterFresnel(f0.y, f90, eAvg),
            multiScatterFresnel(f0.z, f90, eAvg)};
}

// ---------------------------------------------------------------------------------------------------------------------
// The material

/// The glTF metallic-roughness inputs of the BRDF (linear baseColor; metallic and roughness in [0, 1]), the
/// dielectric's Fresnel (KHR_materials_ior and KHR_materials_specular; glTF's default is f0 = 0.04, f90 = 1), and the
/// model: energy-compensated (default) or the specification's plain single-scattering model.
struct BrdfInputs {
    glm::vec3 baseColor{1.f};
    float metallic = 0.f;
    float roughness = 1.f;
    glm::vec3 specularF0{kDielectricF0};  ///< dielectric reflectance at normal incidence, in [0, 1]
    float specularF90 = 1.f;              ///< dielectric reflectance at grazing incidence, in [0, 1]
    bool multiScatter = true;             ///< false: glTF Appendix B exactly (loses and creates energy)
};

/// The BRDF inputs of an evaluated surface hit (evalSurface() has applied the textures and clamped the factors).
LOOM_HD inline BrdfInputs brdfInputs(const SurfaceHit& hit, bool multiScatter = true) {
    BrdfInputs in;
    in.baseColor = hit.baseColor;
    in.metallic = hit.metallic;
    in.roughness = hit.roughness;
    in.specularF0 = hit.specularF0;
    in.specularF90 = hit.specularF90;
    in.multiScatter = multiScatter;
    return in;
}

/// Specular reflectance at normal incidence: mix(dielectric f0, baseColor, metallic) (glTF Appendix B, "Metal BRDF
/// and Dielectric BRDF"; the same as specularF0(SurfaceHit) for the default dielectric).
LOOM_HD inline glm::vec3 brdfF0(const BrdfInputs& in) {
    return glm::mix(in.specularF0, in.baseColor, in.metallic);
}

/// What the BRDF needs of the material and the view direction alone (see the model in the header of this file).
/// Every term is per unit of its lobe's shape: for a light direction with E(n.wi) = ei, Es(n.wi) = esi,
///   f = F(wo.h) D V + msScale (1 - ei) + diffuseScale * diffuseIn,
///   diffuseIn = 1 - (layerE ei + layerEs esi + layerC)   (compensated), or 1 - Fdielectric(wo.h)  (plain).
struct BrdfLobes {
    glm::vec3 f0{0.04f};  ///< Fresnel of the specular lobe, F = f0 + (f90 - f0) (1 - wo.h)^5
    float f90 = 1.f;
    glm::vec3 msScale{0.f};       ///< Fms (1 - E(mu_o)) / (pi (1 - Eavg)); 0 for the plain model
    glm::vec3 diffuseScale{0.f};  ///< (1 - metallic) baseColor / pi, times (1 - Ed(mu_o)) / (1 - Ed_avg) compensated
    glm::vec3 layerE{0.f}, layerEs{0.f}, layerC{0.f};  ///< per channel, Ed(mu) = layerE E + layerEs Es + layerC
    glm::vec3 dielectricF0{0.04f};  ///< plain model: the diffuse weight is 1 - (f0 + (f90 - f0) (1 - wo.h)^5)
    float dielectricF90 = 1.f;
    float roughness = 1.f;
    float pSpec = 1.f;  ///< probability of sampling the GGX lobe (specularLobeProbability())
    bool multiScatter = true;
};

/// The per-view terms for a view with n.wo = NdotV (0 < NdotV <= 1).
///
/// Multiple scattering (Kulla and Conty 2017): the specular lobe gets f_ms = Fms (1 - E(mu_o)) (1 - E(mu_i)) /
/// (pi (1 - Eavg)), whose albedo (1 - E(mu_o)) Fms is what single scattering loses. With F = 1 the two sum to 1.
/// The diffuse lobe under the dielectric is scaled by what the whole dielectric specular layer (its single and
/// multiple scattering, albedo Ed) does not reflect, on both sides to stay reciprocal: (1 - Ed(mu_o)) (1 - Ed(mu_i)) /
/// (1 - Ed_avg), the albedo-scaling layering of Kulla and Conty 2017 (slide 31) as in Dassault Systemes' Enterprise
/// PBR shading model (2022, "Albedo scaling"). A white dielectric then reflects Ed(mu_o) + (1 - Ed(mu_o)) = 1 of the
/// light: glTF's fresnel_mix on wo.h (Appendix B) would reflect up to 1.85 at grazing views of a smooth one. Ed is
/// taken per colour channel, so a coloured dielectric Fresnel (KHR_materials_specular) conserves energy channel by
/// channel too. Metals mix in by metallic as in the specification.
LOOM_HD inline BrdfLobes makeBrdfLobes(const BrdfInputs& in, float NdotV) {
    BrdfLobes L;
    const float m = in.metallic;
    L.f0 = brdfF0(in);
    L.f90 = in.specularF90 + (1.f - in.specularF90) * m;
    L.multiScatter = in.multiScatter;
    L.roughness = in.roughness;
    L.dielectricF0 = in.specularF0;
    L.dielectricF90 = in.specularF90;
    const GgxAlbedo eo = ggxAlbedo(NdotV, in.roughness), avg = ggxAlbedoAverage(in.roughness);
    const float lossAvg = 1.f - avg.e;  // energy single scattering loses, averaged over views
    // Below 1e-5 the lost energy is negligible and 1 / lossAvg would amplify rounding: no compensation there.
    const bool compensate = in.multiScatter && lossAvg > 1e-5f;
    // The dielectric layer's albedo, Ed(mu) = f0 (E - Es) + f90 Es + FmsLayer (1 - E).
    const glm::vec3 fmsLayer = compensate ? multiScatterFresnel(in.specularF0, in.specularF90, avg.e) : glm::vec3(0.f);
    L.layerE = in.specularF0 - fmsLayer;
    L.layerEs = glm::vec3(in.specularF90) - in.specularF0;
    L.layerC = fmsLayer;
    const glm::vec3 layerOut = L.layerE * eo.e + L.layerEs * eo.es + L.layerC;
    const glm::vec3 diffuseOut = glm::max(glm::vec3(1.f) - layerOut, glm::vec3(0.f));
    const glm::vec3 diffuse = ((1.f - m) * kInvPi) * in.baseColor;
    glm::vec3 fms(0.f);
    if (compensate) {
        fms = (1.f - m) * fmsLayer + m * multiScatterFresnel(in.baseColor, 1.f, avg.e);
        L.msScale = fms * ((1.f - eo.e) * kInvPi / lossAvg);
    }
    if (in.multiScatter) {
        const glm::vec3 layerAvg = L.layerE * avg.e + L.layerEs * avg.es + L.layerC;
        for (int c = 0; c < 3; ++c)
            L.diffuseScale[c] = layerAvg[c] < 1.f ? diffuse[c] * (diffuseOut[c] / (1.f - layerAvg[c])) : 0.f;
    } else {
        L.diffuseScale = diffuse;
    }
    // Lobe selection (variance only): the albedo of the GGX lobe against the other two, which the cosine-weighted
    // hemisphere samples. Neither is starved ([0.1, 0.9]); without the others the GGX lobe alone (1).
    const float spec = luminance(L.f0 * (eo.e - eo.es) + glm::vec3(L.f90 * eo.es));
    const float other = luminance(fms) * (1.f - eo.e) + (1.f - m) * luminance(in.baseColor * diffuseOut);
    L.pSpec = other > 0.f ? glm::clamp(spec / (spec + other), 0.1f, 0.9f) : 1.f;
    return L;
}

/// Probability that sampleBrdf() samples the specular lobe, seen from a view with n.wo = NdotV (affects variance only).
LOOM_HD inline float specularLobeProbability(const BrdfInputs& in, float NdotV) {
    return makeBrdfLobes(in, glm::clamp(NdotV, 0.f, 1.f)).pSpec;
}

/// The lobes other than single-scattering GGX (multiple scattering and diffuse) toward a light direction with
/// n.wi = NdotL; w = (1 - wo.h)^5 (the plain model's diffuse weight needs it).
LOOM_HD inline glm::vec3 otherLobes(const BrdfLobes& L, float NdotL, float w) {
    if (!L.multiScatter)
        return L.diffuseScale * (glm::vec3(1.f) - (L.dielectricF0 + (L.dielectricF90 - L.dielectricF0) * w));
    const GgxAlbedo ei = ggxAlbedo(NdotL, L.roughness);
    const glm::vec3 diffuseIn =
        glm::max(glm::vec3(1.f) - (L.layerE * ei.e + L.layerEs * ei.es + L.layerC), glm::vec3(0.f));
    return L.msScale * (1.f - ei.e) + L.diffuseScale * diffuseIn;
}

/// The BRDF value and the sampling pdf for one pair of directions.
struct BrdfEval {
    glm::vec3 f{0.f};  ///< BRDF value (without the cosine)
    float pdf = 0.f;   ///< solid-angle density of sampleBrdf() producing wi
};

/// The BRDF f(wo, wi) in the local frame (see the model at the top of this file and makeBrdfLobes()).
LOOM_HD inline glm::vec3 evalBrdfLocal(const BrdfInputs& in, glm::vec3 wo, glm::vec3 wi) {
    if (wo.z <= 0.f || wi.z <= 0.f) return glm::vec3(0.f);
    const BrdfLobes L = makeBrdfLobes(in, glm::min(wo.z, 1.f));
    const glm::vec3 h = glm::normalize(wo + wi);
    const float w = schlickWeight(std::fabs(glm::dot(wo, h)));
    const float alpha = alphaFromRoughness(in.roughness);
    const glm::vec3 F = L.f0 + (glm::vec3(L.f90) - L.f0) * w;
    return F * (ggxD(h, alpha) * ggxVisibility(wi.z, wo.z, alpha)) + otherLobes(L, glm::min(wi.z, 1.f), w);
}

/// Solid-angle pdf of sampleBrdfLocal() producing wi: the full lobe mixture. Nonzero below the surface where the
/// specular lobe reaches there (those samples are invalid), so that it integrates to 1 over the sphere.
LOOM_HD inline float pdfBrdfLocal(const BrdfInputs& in, glm::vec3 wo, glm::vec3 wi) {
    if (wo.z <= 0.f) return 0.f;
    const float pSpec = specularLobeProbability(in, wo.z);
    const float alpha = alphaFromRoughness(in.roughness);
    return pSpec * ggxReflectionPdf(wo, wi, alpha) + (1.f - pSpec) * cosineHemispherePdf(wi.z);
}

/// f and pdf in the local frame, for light samples that need both (MIS).
LOOM_HD inline BrdfEval evalBrdfAndPdfLocal(const BrdfInputs& in, glm::vec3 wo, glm::vec3 wi) {
    BrdfEval e;
    e.f = evalBrdfLocal(in, wo, wi);
    e.pdf = pdfBrdfLocal(in, wo, wi);
    return e;
}

/// BRDF value f(wo, wi) without the cosine (world directions; n the unit shading normal).
LOOM_HD inline glm::vec3 evalBrdf(const BrdfInputs& in, glm::vec3 n, glm::vec3 wo, glm::vec3 wi) {
    const Frame frame = makeFrame(n);
    return evalBrdfLocal(in, frame.toLocal(wo), frame.toLocal(wi));
}

/// Solid-angle pdf with which sampleBrdf() produces wi (the full mixture; use it as the BRDF pdf in MIS weights).
LOOM_HD inline float pdfBrdf(const BrdfInputs& in, glm::vec3 n, glm::vec3 wo, glm::vec3 wi) {
    const Frame frame = makeFrame(n);
    return pdfBrdfLocal(in, frame.toLocal(wo), frame.toLocal(wi));
}

/// f and pdf at once (world directions), cheaper than evalBrdf() and pdfBrdf() apart.
LOOM_HD inline BrdfEval evalBrdfAndPdf(const BrdfInputs& in, glm::vec3 n, glm::vec3 wo, glm::vec3 wi) {
    const Frame frame = makeFrame(n);
    return evalBrdfAndPdfLocal(in, frame.toLocal(wo), frame.toLocal(wi));
}

/// A sampled continuation direction.
struct BrdfSample {
    glm::vec3 wi{0.f};      ///< unit direction toward the next vertex
    glm::vec3 weight{0.f};  ///< f(wo, wi) |n.wi| / pdf: the path throughput factor
    float pdf = 0.f;        ///< solid-angle pdf of the whole mixture (pdfBrdf(in, n, wo, wi))
    bool valid = false;     ///< false: no direction (wo or the sample below the surface); end the path
};

/// Draws a direction from the lobe mixture in the local frame (Veach 1997's one-sample model, section 9.2.4):
/// uLobe < specularLobeProbability() picks the GGX lobe (visible normals), else the cosine-weighted hemisphere, which
/// stands for the diffuse and multiple-scattering lobes. The result may point below the surface (z <= 0) when a
/// visible normal reflects wo downward.
LOOM_HD inline glm::vec3 sampleBrdfDirectionLocal(const BrdfInputs& in, glm::vec3 wo, glm::vec2 u, float uLobe) {
    if (uLobe < specularLobeProbability(in, wo.z)) {
        const glm::vec3 h = sampleGgxVndf(wo, alphaFromRoughness(in.roughness), u);
        return glm::normalize(2.f * glm::dot(wo, h) * h - wo);
    }
    return sampleCosineHemisphere(u);
}

/// The sample record for a drawn direction wi (local frame): the weight divides by the mixture pdf, not by the chosen
/// lobe's, so it is right whichever lobe produced wi.
LOOM_HD inline BrdfSample brdfSampleLocal(const BrdfInputs& in, glm::vec3 wo, glm::vec3 wi) {
    BrdfSample s;
    if (wo.z <= 0.f || wi.z <= 0.f) return s;  // wi.z <= 0: a specular sample reflected below the surface
    const float pdf = pdfBrdfLocal(in, wo, wi);
    if (!(pdf > 0.f) || !std::isfinite(pdf)) return s;
    s.wi = wi;
    s.pdf = pdf;
    s.weight = evalBrdfLocal(in, wo, wi) * (wi.z / pdf);
    s.valid = true;
    return s;
}

/// Samples wi in the local frame. u: two uniform numbers in [0, 1) for the direction; uLobe: one more for the lobe.
LOOM_HD inline BrdfSample sampleBrdfLocal(const BrdfInputs& in, glm::vec3 wo, glm::vec2 u, float uLobe) {
    if (wo.z <= 0.f) return BrdfSample{};
    return brdfSampleLocal(in, wo, sampleBrdfDirectionLocal(in, wo, u, uLobe));
}

/// Samples wi (world directions; n the unit shading normal, wo toward the viewer). See sampleBrdfLocal().
/// f and the pdf are evaluated for wi after its trip to world space, exactly as evalBrdf() and pdfBrdf() see it:
/// near a narrow lobe the rounding of the frame change moves the pdf by up to ~1e-3 relative, and MIS weights
/// computed later from pdfBrdf(n, wo, s.wi) should agree with s.pdf exactly.
LOOM_HD inline BrdfSample sampleBrdf(const BrdfInputs& in, glm::vec3 n, glm::vec3 wo, glm::vec2 u, float uLobe) {
    const Frame frame = makeFrame(n);
    const glm::vec3 woLocal = frame.toLocal(wo);
    if (woLocal.z <= 0.f) return BrdfSample{};
    const glm::vec3 wi = frame.toWorld(sampleBrdfDirectionLocal(in, woLocal, u, uLobe));
    BrdfSample s = brdfSampleLocal(in, woLocal, frame.toLocal(wi));
    if (s.valid) s.wi = wi;
    return s;
}

// ---------------------------------------------------------------------------------------------------------------------
// Per-vertex evaluation: the integrator shades one vertex with the same (n, wo) several times (light sample f and pdf,
// then a BRDF sample); BrdfVertex holds what depends only on the vertex (frame, local wo, alpha, the lobes, the
// wo-side Smith term), computed once. The results are the same model as the functions above (evalBrdf, pdfBrdf,
// sampleBrdf), with the half vector and D shared between f and the pdf.

struct BrdfVertex {
    Frame frame;
    glm::vec3 wo{0.f};        ///< local
    BrdfLobes lobes;
    float alpha = 1.f, a2 = 1.f;
    float invA2 = 1.f;        ///< 1 / a2
    float invPiA2 = kInvPi;   ///< 1 / (pi a2): D = invPiA2 / t^2
    float smithWo = 0.f;      ///< sqrt(a2 + (1 - a2) wo.z^2)
    float specPdfScale = 0.f; ///< pSpec / (2 (wo.z + smithWo)): the specular pdf is D times this
    bool valid = false;       ///< wo.z > 0
};

/// withPdf = false leaves out the specular pdf scale (left 0): for a vertex where only f is wanted, such as a path's
/// last vertex, whose light sample needs no MIS weight.
LOOM_HD inline BrdfVertex makeBrdfVertex(const BrdfInputs& in, glm::vec3 n, glm::vec3 wo, bool withPdf = true) {
    BrdfVertex v;
    v.frame = makeFrame(n);
    v.wo = v.frame.toLocal(wo);
    v.valid = v.wo.z > 0.f;
    if (!v.valid) return v;
    v.lobes = makeBrdfLobes(in, glm::min(v.wo.z, 1.f));
    v.alpha = alphaFromRoughness(in.roughness);
    v.a2 = v.alpha * v.alpha;
    v.smithWo = std::sqrt(v.a2 + (1.f - v.a2) * v.wo.z * v.wo.z);
    v.invA2 = 1.f / v.a2;
    v.invPiA2 = v.invA2 * kInvPi;
    if (withPdf) {
        v.specPdfScale = v.lobes.pSpec / (2.f * (v.wo.z + v.smithWo));
    } else {
        v.lobes.pSpec = v.specPdfScale = 0.f;
    }
    return v;
}

/// f and the mixture pdf for a local wi (evalBrdfAndPdfLocal()'s values).
LOOM_HD inline BrdfEval evalBrdfVertexLocal(const BrdfVertex& v, glm::vec3 wi) {
    BrdfEval e;
    if (!v.valid) return e;
    const glm::vec3 wo = v.wo;
    const glm::vec3 hSum = wo + wi;
    const float lenSq = glm::dot(hSum, hSum);
    // With s = wo + wi unnormalised (h = s / |s|), ggxD(h) = invPiA2 |s|^4 / ts^2, ts = (s.x^2 + s.y^2) / a2 + s.z^2:
    // no square root on the way to D (latency), the per-vertex divisions hoisted, and D and V share one division.
    float ts2 = 0.f;  // 0: D = 0 (h below the surface or undefined)
    if (lenSq > 1e-12f && hSum.z > 0.f) {
        const float ts = (hSum.x * hSum.x + hSum.y * hSum.y) * v.invA2 + hSum.z * hSum.z;
        ts2 = ts * ts;
    }
    const float lenSq2 = lenSq * lenSq;
    if (wi.z <= 0.f) {
        e.pdf = ts2 > 0.f ? v.specPdfScale * (v.invPiA2 * lenSq2 / ts2) : 0.f;
        return e;
    }
    // Height-correlated Smith visibility (ggxVisibility()) V = 0.5 / g, with the wo-side root precomputed.
    const float g = wi.z * v.smithWo + wo.z * std::sqrt(wi.z * wi.z * (1.f - v.a2) + v.a2);
    float D = 0.f, DV = 0.f;
    if (ts2 > 0.f) {
        const float r = v.invPiA2 * lenSq2 / (ts2 * g);
        D = r * g;
        DV = 0.5f * r;
    }
    // |wo.h| = |wo.s| / |s| (Schlick's weight). For unit wo and wi, |s|^2 = 2 (1 + wo.wi) = 2 wo.s, so this is
    // sqrt(|wo.s| / 2): one square root and no division.
    const float VdotH = lenSq > 1e-12f ? std::sqrt(0.5f * std::fabs(glm::dot(wo, hSum))) : 0.f;
    const BrdfLobes& L = v.lobes;
    e.pdf = v.specPdfScale * D + (1.f - L.pSpec) * (wi.z * kInvPi);
    const float w = schlickWeight(VdotH);
    const glm::vec3 F = L.f0 + (glm::vec3(L.f90) - L.f0) * w;
    e.f = F * DV + otherLobes(L, glm::min(wi.z, 1.f), w);
    return e;
}

/// f and pdf for a world direction wi (evalBrdfAndPdf()'s values).
LOOM_HD inline BrdfEval evalBrdfVertex(const BrdfVertex& v, glm::vec3 wi) {
    return evalBrdfVertexLocal(v, v.frame.toLocal(wi));
}

/// sampleBrdf() with the per-vertex terms precomputed.
LOOM_HD inline BrdfSample sampleBrdfVertex(const BrdfVertex& v, glm::vec2 u, float uLobe) {
    BrdfSample s;
    if (!v.valid) return s;
    glm::vec3 local;
    if (uLobe < v.lobes.pSpec) {
        const glm::vec3 h = sampleGgxVndf(v.wo, v.alpha, u);
        local = glm::normalize(2.f * glm::dot(v.wo, h) * h - v.wo);
    } else {
        local = sampleCosineHemisphere(u);
    }
    const glm::vec3 wi = v.frame.toWorld(local);
    const glm::vec3 wiL = v.frame.toLocal(wi);  // as evalBrdfVertex() will see wi (see sampleBrdf())
    if (wiL.z <= 0.f) return s;
    const BrdfEval e = evalBrdfVertexLocal(v, wiL);
    if (!(e.pdf > 0.f) || !std::isfinite(e.pdf)) return s;
    s.wi = wi;
    s.pdf = e.pdf;
    s.weight = e.f * (wiL.z / e.pdf);
    s.valid = true;
    return s;
}

}  // namespace loom::pt
