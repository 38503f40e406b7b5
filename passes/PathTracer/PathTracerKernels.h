#pragma once
// The path tracer's per-pixel integrator: unidirectional path tracing with
// next-event estimation and multiple importance sampling (Veach 1997, ch. 9),
// Russian roulette, and a Lambert-only mode for analytic validation. The ray
// tracer is a template parameter so the same code can run over Embree on the
// CPU or a device tracer later.
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "BRDF.h"
#include "Lights.h"
#include "Random.h"
#include "loom/Kernel.h"
#include "loom/RayScene.h"
#include "loom/SceneView.h"
#include "loom/SurfaceKernels.h"

namespace loom::pt {

enum LightSampling : uint32_t { kMis = 0, kNeeOnly = 1, kBsdfOnly = 2 };

/// What the integrator does. PathTracer binds its parameters of the same meaning to this struct, so these are the
/// pass's defaults too.
struct PathTracerSettings {
    uint32_t maxBounces = 3;     ///< scattering events; 0 shows only what the camera sees directly
    uint32_t rrStartBounce = 2;  ///< Russian roulette from this bounce on
    LightSampling lightSampling = kMis;
    bool lambertOnly = false;  ///< f = baseColor / pi, for analytic tests
    bool multiScatter = true;  ///< the BRDF's energy compensation (BrdfInputs::multiScatter)
    float indirectClamp = 0.f;  ///< firefly guard: largest channel of one indirect contribution; 0 = off
    /// Temporal gradients re-shade last frame's sample from this frame's camera position (view-dependent shading
    /// that changed with the camera shows in them) instead of along last frame's camera ray.
    bool gradientFromCurrentView = false;
};

/// The firefly guard of the real-time graphs: a contribution that reaches the pixel after the first bounce (what
/// PathResult files under "indirect") is scaled down so that its largest channel is at most `limit` (0: off). It
/// keeps the hue and biases the image darker where rare paths carry much energy (caustics through glossy
/// reflections, small bright lights seen in glossy surfaces); direct light is never clamped.
LOOM_HD inline glm::vec3 clampIndirect(glm::vec3 c, float limit) {
    if (!(limit > 0.f)) return c;
    const float m = glm::max(glm::max(c.x, c.y), c.z);
    return m > limit ? c * (limit / m) : c;
}

/// Work the shading kernels can be compiled without (template parameter F of shadeEmission, lightSampleRadiance and
/// shadeVerticesSimd). PathTracer picks the kernel once per scene from its light list, so a bit is left out only
/// where the scene never runs the code it guards, and the image is the generic kernel's bit for bit.
enum KernelFeature : uint32_t {
    /// A light sample evaluates the emitter's material at the sampled point (emissive texture or alpha-tested
    /// emitter); without it the sample's radiance is the triangle's emissive factor.
    kEmitterSurfaces = 1u,
    /// The environment is an equirectangular map; without it a constant colour (or black): no texel lookup on a
    /// miss, and its pdf is the uniform sphere's.
    kEnvironmentMap = 2u,
};
inline constexpr uint32_t kAllFeatures = kEmitterSurfaces | kEnvironmentMap;

struct PathResult {
    glm::vec3 color{0.f};
    glm::vec3 direct{0.f};    ///< emission seen directly, NEE at the first hit, and emission one bounce away
    glm::vec3 indirect{0.f};  ///< everything else
    uint32_t rays = 0;
};

/// Offsets a ray origin off a surface along its geometric normal, scaled
/// with the position's magnitude so it works far from the origin.
LOOM_HD inline glm::vec3 offsetOrigin(glm::vec3 p, glm::vec3 n) {
    const float scale = 1e-4f * (1.f + glm::max(glm::max(std::fabs(p.x), std::fabs(p.y)), std::fabs(p.z)));
    return p + n * scale;
}

/// Emission of the surface at a hit, seen from direction `toViewer` (front
/// faces only, unless the material is double-sided).
LOOM_HD inline glm::vec3 emittedRadiance(const SceneView& scene, const SurfaceHit& s, glm::vec3 rayDir) {
    if (s.emission == glm::vec3(0.f)) return glm::vec3(0.f);
    const bool doubleSided = scene.materials[s.material].doubleSided != 0;
    return (s.frontFacing || doubleSided) ? s.emission : glm::vec3(0.f);
}

/// Lambert-only mode: f = baseColor / pi, cosine-weighted sampling.
LOOM_HD inline glm::vec3 lambertEval(const SurfaceHit& s, glm::vec3 n, glm::vec3 wi) {
    return glm::dot(n, wi) > 0.f ? s.baseColor * kInvPi : glm::vec3(0.f);
}

/// One path between its vertices. tracePath() runs it to the end; the pass keeps many of them in flight per tile
/// (wavefront), calling the same functions in a different order, so both give bit-identical results.
struct PathState {
    glm::vec3 throughput{1.f};
    glm::vec3 rayOrigin{0.f};  ///< origin of the ray that reaches the next hit (and of the pending shadow ray)
    glm::vec3 rayDir{0.f, 0.f, -1.f};
    float prevBsdfPdf = 0.f;  ///< solid-angle pdf of the BSDF sample that produced rayDir
    bool prevDelta = true;    ///< camera ray: emission always counts fully
    bool shadowNearSurface = false;
    uint32_t bounce = 0;
    glm::vec3 shadowDir{0.f};  ///< pending shadow ray from rayOrigin (valid when shadeVertex() returned kShadowRay)
    float shadowTMax = 0.f;
    glm::vec3 shadowContrib{0.f};  ///< added to the result when the shadow ray is not occluded
    PathRng rng;
    PathResult r;
};

/// What shadeVertex() asks the caller to trace next.
enum PathRequest : uint32_t { kShadowRay = 1u, kNextRay = 2u };

/// Starts st as a camera path along (origin, dir); the shadow-ray fields are set by shadeVertex() when used.
LOOM_HD inline void beginPath(PathState& st, glm::vec3 origin, glm::vec3 dir, const PathRng& rng) {
    st.throughput = glm::vec3(1.f);
    st.rayOrigin = origin;
    st.rayDir = glm::normalize(dir);
    st.prevBsdfPdf = 0.f;
    st.prevDelta = true;
    st.bounce = 0;
    st.rng = rng;
    st.r = PathResult{};
}

/// The first part of shading a vertex: adds what the path sees at the hit (or miss) of st.rayOrigin + t st.rayDir
/// (emission, MIS-weighted) and evaluates the surface into s. Returns false when the path ends there (a miss, or
/// bounce == maxBounces); otherwise the caller scatters at s.
template <uint32_t F = kAllFeatures>
LOOM_HD inline bool shadeEmission(PathState& st, const RayHit& hit, const SceneView& scene, const LightsView& lights,
                                  const PathTracerSettings& set, SurfaceHit& s) {
    PathResult& r = st.r;
    const bool directSlot = st.bounce <= 1;  // emission reached here belongs to "direct"
    const glm::vec3 rayDir = st.rayDir;
    if (!hit.hit()) {
        // Without a map, envRadiance() and envPdf() reduce to these constants (the same expressions).
        constexpr bool map = (F & kEnvironmentMap) != 0;
        const glm::vec3 Le = map ? envRadiance(lights.env, rayDir) : lights.env.color * lights.env.intensity;
        float w = 1.f;
        if (!st.prevDelta && lights.hasEnv) {
            if (set.lightSampling == kNeeOnly)
                w = 0.f;
            else if (set.lightSampling == kMis)
                w = powerHeuristic(st.prevBsdfPdf,
                                   lights.pEnv * (map ? envPdf(lights.env, rayDir) : 1.f / (4.f * kPi)));
        }
        const glm::vec3 c =
            directSlot ? st.throughput * Le * w : clampIndirect(st.throughput * Le * w, set.indirectClamp);
        r.color += c;
        (directSlot ? r.direct : r.indirect) += c;
        return false;
    }
    s = evalSurface(scene, hit.instance, hit.primitive, hit.u, hit.v, rayDir, SurfaceEval::Shading);
    const glm::vec3 Le = emittedRadiance(scene, s, rayDir);
    if (Le != glm::vec3(0.f)) {
        float w = 1.f;
        if (!st.prevDelta) {
            if (set.lightSampling == kNeeOnly) {
                w = 0.f;
            } else if (set.lightSampling == kMis && lights.instanceTriBase &&
                       lights.instanceTriBase[hit.instance] != 0xFFFFFFFFu) {
                const EmissiveTri& t = lights.tris[lights.instanceTriBase[hit.instance] + hit.primitive];
                const glm::vec3 d = s.posW - st.rayOrigin;
                float cosLight = -glm::dot(t.normal, rayDir);
                if (t.doubleSided) cosLight = std::fabs(cosLight);
                w = powerHeuristic(st.prevBsdfPdf, triLightPdf(lights, t, glm::dot(d, d), cosLight));
            }
        }
        const glm::vec3 c =
            directSlot ? st.throughput * Le * w : clampIndirect(st.throughput * Le * w, set.indirectClamp);
        r.color += c;
        (directSlot ? r.direct : r.indirect) += c;
    }
    return st.bounce < set.maxBounces;
}

/// Smallest cosine between the geometric normal and the mirror direction about a bent shading normal
/// (bendShadingNormal()).
inline constexpr float kMinReflectionCosine = 0.02f;

/// A shading normal n bent, where needed, so that the mirror direction of wo about it stays above the geometric
/// surface (ng, on wo's side): the treatment of shading normals in Keller et al. 2017 ("The Iray Light Transport
/// Simulation and Rendering System", appendix A.3). A normal map can tilt n so far that the reflection of wo falls
/// below the surface; such a path would end there, and a normal-mapped mirror shows black rings. Here the mirror
/// direction r is lifted to the geometric horizon plus kMinReflectionCosine, keeping its azimuth, and n becomes the
/// half vector of wo and the lifted r (so reflecting wo about it gives exactly the lifted r). Where r is already
/// above the surface n is returned unchanged, so the map is continuous.
LOOM_HD inline glm::vec3 bendShadingNormal(glm::vec3 n, glm::vec3 ng, glm::vec3 wo) {
    const glm::vec3 r = 2.f * glm::dot(wo, n) * n - wo;
    const float c = glm::dot(r, ng);
    if (c >= kMinReflectionCosine) return n;
    const glm::vec3 tangential = r - c * ng;
    const float len = glm::length(tangential);
    if (!(len > 1e-6f)) return ng;
    const float lift = kMinReflectionCosine;
    const glm::vec3 lifted = tangential * (std::sqrt(1.f - lift * lift) / len) + lift * ng;
    return glm::normalize(wo + lifted);
}

/// Normals of a scattering vertex turned to the side the ray arrived from (wo = -rayDir), and the offset origin of
/// the rays that leave it. The shading normal is bent where its mirror direction would leave through the geometric
/// surface (bendShadingNormal()).
struct ScatterFrame {
    glm::vec3 n, fn, p;
};
LOOM_HD inline ScatterFrame scatterFrame(const SurfaceHit& s, glm::vec3 wo) {
    ScatterFrame f{s.normalW, s.faceNormalW, glm::vec3(0.f)};
    if (glm::dot(f.fn, wo) < 0.f) {
        f.fn = -f.fn;
        f.n = -f.n;
    }
    if (glm::dot(f.n, wo) <= 0.f) f.n = f.fn;  // shading normal beyond the silhouette: fall back to geometry
    f.n = bendShadingNormal(f.n, f.fn, wo);
    f.p = offsetOrigin(s.posW, f.fn);
    return f;
}

/// Radiance a light sample carries toward a shading point with normals (n, fn): the light's own value, or for a
/// textured emitter the material evaluated at the sampled point (only where the sample can reach the surface).
/// An alpha-tested emitter's coverage there scales it: a MASK emitter emits nothing where it is cut out, a BLEND
/// emitter its mean over its stochastic transparency (alpha times its radiance), as rays that hit it see.
template <uint32_t F = kAllFeatures>
LOOM_HD inline glm::vec3 lightSampleRadiance(const SceneView& scene, const LightSample& ls, glm::vec3 n, glm::vec3 fn) {
    if ((F & kEmitterSurfaces) == 0) return ls.Li;  // no light sample has isTriangle set
    if (!ls.isTriangle || !(glm::dot(n, ls.wi) > 0.f && glm::dot(fn, ls.wi) > 0.f)) return ls.Li;
    const SurfaceHit e =
        evalSurface(scene, ls.instance, ls.primitive, ls.bary.x, ls.bary.y, ls.wi, SurfaceEval::Shading);
    const glm::vec3 Le = emittedRadiance(scene, e, ls.wi);
    return ls.alphaTested ? Le * expectedCoverage(scene, ls.instance, ls.primitive, ls.bary.x, ls.bary.y) : Le;
}

/// Length of a shadow ray toward a light point at `distance` (stopping just short of the light's own surface), or
/// "infinite" for the environment and directional lights.
LOOM_HD inline float shadowRayTMax(float distance) {
    return distance >= 1e29f ? 1e30f : distance * (1.f - 1e-4f);
}

/// Roughness below which a path's last vertex still samples the BRDF (see isLastVertex()).
inline constexpr float kGlossyRoughness = 0.4f;

/// Whether the vertex at `bounce` is a path's last scattering vertex: no BRDF-sampled ray follows it, so light
/// sampling alone estimates direct light there (weight 1): unbiased, and it saves a closest-hit ray per path.
/// BRDF-only mode still traces it, and so does a glossy vertex (roughness below kGlossyRoughness): light sampling
/// alone meets the peak of a narrow lobe (D up to 1 / (pi alpha^2), 5e4 at roughness 0.05) with a small light pdf,
/// the fireflies of a glossy reflection of a light. There the BRDF sample is traced too, for the emission it finds
/// (the path ends at that hit, bounce = maxBounces), and both samples are MIS-weighted.
LOOM_HD inline bool isLastVertex(uint32_t bounce, const PathTracerSettings& set, float roughness) {
    return bounce + 1 == set.maxBounces && set.lightSampling != kBsdfOnly &&
           (set.lambertOnly || !(roughness < kGlossyRoughness));
}

/// Shades the hit (or miss) of st.rayOrigin + t st.rayDir: emission reached there, a light sample (the shadow ray
/// from st.rayOrigin along st.shadowDir, on return) and the BRDF-sampled continuation (st.rayOrigin/rayDir, on
/// return). Returns kShadowRay and/or kNextRay; without kNextRay the path has ended (after its shadow ray).
LOOM_HD inline uint32_t shadeVertex(PathState& st, const RayHit& hit, const SceneView& scene, const LightsView& lights,
                                    const PathTracerSettings& set) {
    SurfaceHit s;
    if (!shadeEmission(st, hit, scene, lights, set, s)) return 0u;
    PathResult& r = st.r;
    const uint32_t bounce = st.bounce;
    PathRng& rng = st.rng;
    rng.startBounce(bounce);
    const glm::vec3 wo = -st.rayDir;
    const ScatterFrame sf = scatterFrame(s, wo);
    const glm::vec3 n = sf.n, fn = sf.fn, p = sf.p;
    st.rayOrigin = p;
    uint32_t request = 0u;
    // Everything the BRDF needs from this vertex alone, computed once for NEE and the BRDF sample.
    // Made when first needed (a light sample that reaches the surface, or the BRDF sample).
    BrdfVertex bv;
    bool bvReady = false;
    const bool nearSurface = bounce == 0;
    const bool lastVertex = isLastVertex(bounce, set, s.roughness);

    // Next-event estimation: the shadow ray is left to the caller, with the contribution it carries when clear.
    const glm::vec2 l01 = rng.next2(), l23 = rng.next2();
    LightSample ls = sampleLight(lights, p, l01.x, l01.y, l23.x, l23.y);
    if (ls.valid && (set.lightSampling != kBsdfOnly || ls.delta)) {
        const float cosI = glm::dot(n, ls.wi);
        if (cosI > 0.f && glm::dot(fn, ls.wi) > 0.f) {
            const glm::vec3 Li = lightSampleRadiance(scene, ls, n, fn);
            if (Li != glm::vec3(0.f)) {
                glm::vec3 f;
                float bsdfPdf;
                if (set.lambertOnly) {
                    f = lambertEval(s, n, ls.wi);
                    bsdfPdf = cosI * kInvPi;
                } else {
                    bv = makeBrdfVertex(brdfInputs(s, set.multiScatter), n, wo,
                                        !lastVertex);  // no MIS weight at the last vertex
                    bvReady = true;
                    const BrdfEval e = evalBrdfVertex(bv, ls.wi);
                    f = e.f;
                    bsdfPdf = e.pdf;
                }
                if (f != glm::vec3(0.f)) {
                    ++r.rays;
                    st.shadowDir = ls.wi;
                    st.shadowTMax = shadowRayTMax(ls.distance);
                    // MIS weight over the light pdf, w / pdf, with the power heuristic's division shared:
                    // (p^2 / (p^2 + q^2)) / p = p / (p^2 + q^2).
                    const float wOverPdf = (!ls.delta && set.lightSampling == kMis && !lastVertex)
                                               ? ls.pdf / (ls.pdf * ls.pdf + bsdfPdf * bsdfPdf)
                                               : 1.f / ls.pdf;
                    st.shadowContrib = st.throughput * f * cosI * Li * wOverPdf;
                    if (!nearSurface) st.shadowContrib = clampIndirect(st.shadowContrib, set.indirectClamp);
                    st.shadowNearSurface = nearSurface;
                    request = kShadowRay;
                }
            }
        }
    }

    if (lastVertex) return request;

    // Continue the path by sampling the BRDF.
    const glm::vec2 b01 = rng.next2();
    const float b0 = b01.x, b1 = b01.y, b2 = rng.next();
    glm::vec3 wi;
    if (set.lambertOnly) {
        const glm::vec3 local = sampleCosineHemisphere(glm::vec2(b0, b1));
        wi = makeFrame(n).toWorld(local);
        const float cosI = glm::dot(n, wi);
        if (cosI <= 0.f || glm::dot(fn, wi) <= 0.f) return request;
        st.throughput *= s.baseColor;  // f cos / pdf = (a/pi) cos / (cos/pi)
        st.prevBsdfPdf = cosI * kInvPi;
    } else {
        if (!bvReady) bv = makeBrdfVertex(brdfInputs(s, set.multiScatter), n, wo);
        const BrdfSample bs = sampleBrdfVertex(bv, glm::vec2(b0, b1), b2);
        if (!bs.valid || glm::dot(fn, bs.wi) <= 0.f) return request;
        wi = bs.wi;
        st.throughput *= bs.weight;
        st.prevBsdfPdf = bs.pdf;
    }
    st.prevDelta = false;

    // Russian roulette (unbiased: survivors are reweighted by 1 / q).
    if (bounce + 1 >= set.rrStartBounce) {
        const float q = glm::min(glm::max(glm::max(st.throughput.x, st.throughput.y), st.throughput.z), 0.95f);
        if (rng.next() >= q) return request;
        st.throughput /= q;
    }
    if (st.throughput == glm::vec3(0.f)) return request;
    st.rayDir = wi;
    st.bounce = bounce + 1;
    ++r.rays;
    return request | kNextRay;
}

/// Adds the pending light sample of the last shadeVertex() unless its shadow ray was blocked.
LOOM_HD inline void resolveShadowRay(PathState& st, bool occluded) {
    if (occluded) return;
    st.r.color += st.shadowContrib;
    (st.shadowNearSurface ? st.r.direct : st.r.indirect) += st.shadowContrib;
}

/// Traces one whole path from a camera ray (origin, dir) whose first hit is `hit`.
template <class Tracer>
LOOM_HD PathResult tracePath(const Tracer& tracer, const SceneView& scene, const LightsView& lights,
                             const PathTracerSettings& set, glm::vec3 origin, glm::vec3 dir, RayHit hit, PathRng& rng) {
    PathState st;
    beginPath(st, origin, dir, rng);
    for (;;) {
        const uint32_t request = shadeVertex(st, hit, scene, lights, set);
        if (request & kShadowRay) resolveShadowRay(st, tracer.occluded(st.rayOrigin, st.shadowDir, 0.f, st.shadowTMax));
        if (!(request & kNextRay)) break;
        hit = tracer.intersect(st.rayOrigin, st.rayDir);
    }
    rng = st.rng;
    return st.r;
}

}  // namespace loom::pt
