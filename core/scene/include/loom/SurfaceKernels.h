#pragma once
// Surface evaluation shared by every pass that shades a hit: interpolation of
// vertex attributes, texture sampling and the glTF metallic-roughness inputs.
// GBufferRaster's fragment shader implements the same formulas in GLSL; the
// two are tested against each other.
#include <cmath>

#include <glm/glm.hpp>

#include "loom/Kernel.h"
#include "loom/SceneView.h"

namespace loom {

/// sRGB-encoded [0,1] -> linear (IEC 61966-2-1).
LOOM_HD inline float srgbToLinear(float c) {
    return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
/// Linear [0,1] -> sRGB-encoded.
LOOM_HD inline float linearToSrgb(float c) {
    return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.f / 2.4f) - 0.055f;
}

/// Texel index i along an axis of n texels, wrapped into [0, n) as GL 4.5 does
/// it (section 8.14.2, table 8.20): repeat is i mod n; clamp to edge clamps;
/// mirrored repeat runs 0 .. n-1, n-1 .. 0, 0 .. n-1, ... (edge texels twice).
LOOM_HD inline int wrapTexel(int i, int n, TextureWrap wrap) {
    if (wrap == TextureWrap::ClampToEdge) return i < 0 ? 0 : (i >= n ? n - 1 : i);
    if (wrap == TextureWrap::MirroredRepeat) {
        int m = i % (2 * n);
        if (m < 0) m += 2 * n;
        return m < n ? m : 2 * n - 1 - m;
    }
    const int m = i % n;
    return m < 0 ? m + n : m;
}

/// KHR_texture_transform applied to a uv: transform * (u, v, 1).
LOOM_HD inline glm::vec2 transformUv(const TextureRef& tex, glm::vec2 uv) {
    const glm::mat3x2& m = tex.transform;
    return glm::vec2(m[0][0] * uv.x + m[1][0] * uv.y + m[2][0], m[0][1] * uv.x + m[1][1] * uv.y + m[2][1]);
}

/// Samples a material's texture reference at a (not yet transformed) uv: the
/// reference's KHR_texture_transform, then its sampler's filter and wrap modes
/// on the one level Loom keeps (no mipmaps). Every texture read of a surface
/// goes through here. Texel centres lie at ((i + 0.5) / size); nearest takes
/// texel floor(u * size), bilinear weighs the four texels around
/// u * size - 0.5, both wrapped per axis (wrapTexel), as GL samples level 0.
/// sRGB images are decoded before filtering (as GL does for SRGB8_ALPHA8).
/// A missing image reads as white.
LOOM_HD inline glm::vec4 sampleTexture(const SceneView& scene, const TextureRef& tex, glm::vec2 uv, bool srgb) {
    if (tex.image < 0 || uint32_t(tex.image) >= scene.imageCount) return glm::vec4(1.f);
    const ImageView8& img = scene.images[tex.image];
    if (!img.texels || img.width == 0 || img.height == 0) return glm::vec4(1.f);
    uv = transformUv(tex, uv);
    const int w = int(img.width), h = int(img.height);
    // Texel coordinates in a range where float -> int is defined (NaN goes to the low end); past 2^24 a float has
    // no fraction left to filter with anyway.
    auto texelCoord = [](float c) {
        const float limit = 16777216.f;
        return !(c >= -limit) ? -limit : (c > limit ? limit : c);
    };
    auto fetch = [&](int x, int y) {
        glm::u8vec4 t = img.texels[size_t(y) * img.width + size_t(x)];
        glm::vec4 c = glm::vec4(t) / 255.f;
        if (srgb) c = glm::vec4(srgbToLinear(c.r), srgbToLinear(c.g), srgbToLinear(c.b), c.a);
        return c;
    };
    if (tex.nearest) {
        const int x = int(std::floor(texelCoord(uv.x * float(w))));
        const int y = int(std::floor(texelCoord(uv.y * float(h))));
        return fetch(wrapTexel(x, w, tex.wrapS), wrapTexel(y, h, tex.wrapT));
    }
    const float fx = texelCoord(uv.x * float(w) - 0.5f);
    const float fy = texelCoord(uv.y * float(h) - 0.5f);
    const float x0f = std::floor(fx), y0f = std::floor(fy);
    const float tx = fx - x0f, ty = fy - y0f;
    const int x0 = wrapTexel(int(x0f), w, tex.wrapS), x1 = wrapTexel(int(x0f) + 1, w, tex.wrapS);
    const int y0 = wrapTexel(int(y0f), h, tex.wrapT), y1 = wrapTexel(int(y0f) + 1, h, tex.wrapT);
    return glm::mix(glm::mix(fetch(x0, y0), fetch(x1, y0), tx), glm::mix(fetch(x0, y1), fetch(x1, y1), tx), ty);
}

/// Directional albedo of the GGX specular lobe with Schlick Fresnel, from
/// Karis' analytic fit ("Physically Based Shading on Mobile", 2014).
LOOM_HD inline glm::vec3 specularAlbedo(glm::vec3 f0, float NdotV, float roughness) {
    const glm::vec4 c0(-1.f, -0.0275f, -0.572f, 0.022f);
    const glm::vec4 c1(1.f, 0.0425f, 1.04f, -0.04f);
    const glm::vec4 r = roughness * c0 + c1;
    // min as a compare and select: std::fmin stays a libm call under GCC's default floating-point rules.
    const float fall = std::exp2(-9.28f * NdotV), sq = r.x * r.x;
    const float a004 = (fall < sq ? fall : sq) * r.x + r.y;
    const float a = -1.04f * a004 + r.z;
    const float b = 1.04f * a004 + r.w;
    return glm::clamp(f0 * a + b, 0.f, 1.f);
}

/// A 32-bit integer hash with full avalanche (Wellons' "lowbias32" from hash-prospector). Only 32-bit integer
/// arithmetic, so GBufferRaster's GLSL computes the same bits.
LOOM_HD inline uint32_t hash32(uint32_t x) {
    x ^= x >> 16;
    x *= 0x7FEB352Du;
    x ^= x >> 15;
    x *= 0x846CA68Bu;
    x ^= x >> 16;
    return x;
}

/// The coverage key of a camera ray: pixel (x, y), row 0 at the top, and the frame index's low 32 bits. Every
/// pass computes it alike (GBufferRT, GBufferRaster from gl_FragCoord, PathTracer's own camera rays), so they
/// make the same stochastic-transparency decisions and a vbuffer agrees with camera rays.
LOOM_HD inline uint32_t cameraCoverageKey(uint32_t x, uint32_t y, uint32_t frame) {
    return hash32(x + hash32(y + hash32(frame + 0x9E3779B9u)));
}

/// The coverage key of any other ray: a hash of its origin and direction bits. A pure function of the ray, so
/// the decision never depends on which thread or which batch traced it.
LOOM_HD inline uint32_t rayCoverageKey(glm::vec3 o, glm::vec3 d) {
    uint32_t h = 0x85EBCA6Bu;
    h = hash32(h + floatBits(o.x));
    h = hash32(h + floatBits(o.y));
    h = hash32(h + floatBits(o.z));
    h = hash32(h + floatBits(d.x));
    h = hash32(h + floatBits(d.y));
    return hash32(h + floatBits(d.z));
}

/// Uniform in [0, 1) with 24 random bits for a ray of coverage `key` meeting triangle `prim` of `instance`.
LOOM_HD inline float coverageRandom(uint32_t key, uint32_t instance, uint32_t prim) {
    return float(hash32(key + hash32(instance + hash32(prim))) >> 8) * (1.f / 16777216.f);
}

/// Coverage alpha at barycentrics (u, v) of a triangle: baseColorFactor.a times the base colour texture's alpha,
/// sampled as evalSurface samples it (so the two agree on every hit).
LOOM_HD inline float coverageAlpha(const SceneView& scene, uint32_t instance, uint32_t prim, float u, float v) {
    const MeshView& mesh = scene.meshes[scene.instances[instance].mesh];
    const MaterialData& mat = scene.materials[mesh.material];
    float alpha = mat.baseColorFactor.a;
    if (mat.baseColorTexture.image >= 0) {
        const uint32_t i0 = mesh.indices[3 * prim], i1 = mesh.indices[3 * prim + 1], i2 = mesh.indices[3 * prim + 2];
        const float w = 1.f - u - v;
        const glm::vec2 uv = w * mesh.uvs[i0] + u * mesh.uvs[i1] + v * mesh.uvs[i2];
        alpha *= sampleTexture(scene, mat.baseColorTexture, uv, true).a;
    }
    return alpha;
}

/// The mean of surfaceCovers() over its random key: 0 or 1 for MASK by the cutoff, alpha (in [0, 1]) for BLEND, 1
/// for OPAQUE. Light sampling weights an alpha-tested emitter's radiance by it.
LOOM_HD inline float expectedCoverage(const SceneView& scene, uint32_t instance, uint32_t prim, float u, float v) {
    const MaterialData& mat = scene.materials[scene.meshes[scene.instances[instance].mesh].material];
    if (mat.alphaMask) return coverageAlpha(scene, instance, prim, u, v) >= mat.alphaCutoff ? 1.f : 0.f;
    if (mat.alphaBlend) return glm::clamp(coverageAlpha(scene, instance, prim, u, v), 0.f, 1.f);
    return 1.f;
}

/// Does a ray of coverage `key` stop at this hit? By the material's glTF alphaMode: OPAQUE always; MASK where the
/// coverage alpha reaches alphaCutoff; BLEND with probability alpha (stochastic transparency: the surface is there
/// when coverageRandom < alpha, so on average a fraction 1 - alpha of what lies behind shows through). Its mean over
/// keys is expectedCoverage(); the random number is drawn only where the coverage is fractional.
LOOM_HD inline bool surfaceCovers(const SceneView& scene, uint32_t instance, uint32_t prim, float u, float v,
                                  uint32_t key) {
    const float coverage = expectedCoverage(scene, instance, prim, u, v);
    return coverage >= 1.f || (coverage > 0.f && coverageRandom(key, instance, prim) < coverage);
}

/// A primary or secondary hit, evaluated.
struct SurfaceHit {
    glm::vec3 posW{0.f};
    glm::vec3 prevPosW{0.f};    ///< the same surface point last frame (instance's prevWorld)
    glm::vec3 faceNormalW{0.f}; ///< geometric, facing the viewer for double-sided materials
    glm::vec3 normalW{0.f};     ///< shading (interpolated, normal-mapped), same side as faceNormalW
    glm::vec2 uv{0.f};
    glm::vec3 baseColor{1.f};
    float alpha = 1.f;
    float metallic = 0.f;
    float roughness = 1.f;
    glm::vec3 specularF0{0.04f};  ///< the dielectric's reflectance at normal incidence (KHR_materials_ior, _specular)
    float specularF90 = 1.f;      ///< the dielectric's reflectance at grazing incidence (KHR_materials_specular)
    glm::vec3 emission{0.f};
    uint32_t material = 0;
    bool frontFacing = true;
};

/// What evalSurface computes. Shading leaves out prevPosW (motion, which only
/// G-buffers need) and, for materials without textures, uv (left 0).
enum class SurfaceEval : uint32_t { Full, Shading };

/// Evaluates the surface at barycentrics (u, v) of triangle `prim` of an
/// instance, seen along direction `rayDir` (from the viewer toward the hit).
LOOM_HD inline SurfaceHit evalSurface(const SceneView& scene, uint32_t instance, uint32_t prim, float u, float v,
                                      glm::vec3 rayDir, SurfaceEval what = SurfaceEval::Full) {
    const InstanceView& inst = scene.instances[instance];
    const MeshView& mesh = scene.meshes[inst.mesh];
    const MaterialData& mat = scene.materials[mesh.material];
    const uint32_t i0 = mesh.indices[3 * prim], i1 = mesh.indices[3 * prim + 1], i2 = mesh.indices[3 * prim + 2];
    const float w = 1.f - u - v;
    SurfaceHit s;
    s.material = mesh.material;
    const glm::vec3 p0 = mesh.positions[i0], p1 = mesh.positions[i1], p2 = mesh.positions[i2];
    const glm::vec3 pObj = w * p0 + u * p1 + v * p2;
    s.posW = glm::vec3(inst.world * glm::vec4(pObj, 1.f));
    const bool full = what == SurfaceEval::Full;
    if (full) s.prevPosW = glm::vec3(inst.prevWorld * glm::vec4(pObj, 1.f));
    glm::vec3 fn = glm::normalize(inst.normalMatrix * glm::cross(p1 - p0, p2 - p0));
    glm::vec3 n = glm::normalize(inst.normalMatrix *
                                 (w * mesh.normals[i0] + u * mesh.normals[i1] + v * mesh.normals[i2]));
    if (full || mat.normalTexture.image >= 0 || mat.baseColorTexture.image >= 0 ||
        mat.metallicRoughnessTexture.image >= 0 || mat.emissiveTexture.image >= 0)
        s.uv = w * mesh.uvs[i0] + u * mesh.uvs[i1] + v * mesh.uvs[i2];
    s.frontFacing = glm::dot(fn, rayDir) < 0.f;
    if (!s.frontFacing && mat.doubleSided) {
        fn = -fn;
        n = -n;
    }
    if (mat.normalTexture.image >= 0) {
        glm::vec4 t4 = w * mesh.tangents[i0] + u * mesh.tangents[i1] + v * mesh.tangents[i2];
        glm::vec3 t = glm::vec3(inst.world * glm::vec4(glm::vec3(t4), 0.f));
        t = t - n * glm::dot(n, t);
        const float tl = glm::length(t);
        if (tl > 1e-8f) {
            t /= tl;
            const glm::vec3 b = glm::cross(n, t) * (t4.w < 0.f ? -1.f : 1.f);
            glm::vec3 m = glm::vec3(sampleTexture(scene, mat.normalTexture, s.uv, false)) * 2.f - 1.f;
            m.x *= mat.normalScale;
            m.y *= mat.normalScale;
            const glm::vec3 mapped = t * m.x + b * m.y + n * m.z;
            if (glm::dot(mapped, mapped) > 1e-12f) n = glm::normalize(mapped);
        }
    }
    s.faceNormalW = fn;
    s.normalW = n;
    glm::vec4 base = mat.baseColorFactor;
    if (mat.baseColorTexture.image >= 0) base *= sampleTexture(scene, mat.baseColorTexture, s.uv, true);
    s.baseColor = glm::vec3(base);
    s.alpha = base.a;
    s.metallic = mat.metallicFactor;
    s.roughness = mat.roughnessFactor;
    if (mat.metallicRoughnessTexture.image >= 0) {
        glm::vec4 mr = sampleTexture(scene, mat.metallicRoughnessTexture, s.uv, false);
        s.roughness *= mr.g;
        s.metallic *= mr.b;
    }
    s.metallic = glm::clamp(s.metallic, 0.f, 1.f);
    s.roughness = glm::clamp(s.roughness, 0.f, 1.f);
    s.specularF0 = mat.specularF0;
    s.specularF90 = mat.specularFactor;
    s.emission = mat.emissiveFactor;
    if (mat.emissiveTexture.image >= 0) s.emission *= glm::vec3(sampleTexture(scene, mat.emissiveTexture, s.uv, true));
    return s;
}

/// Diffuse reflectance used for demodulation: baseColor * (1 - metallic).
LOOM_HD inline glm::vec3 diffuseAlbedo(const SurfaceHit& s) { return s.baseColor * (1.f - s.metallic); }

/// Specular reflectance at normal incidence: mix(0.04, baseColor, metallic).
LOOM_HD inline glm::vec3 specularF0(const SurfaceHit& s) { return glm::mix(glm::vec3(0.04f), s.baseColor, s.metallic); }

}  // namespace loom
