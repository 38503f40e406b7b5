#pragma once
// One pixel of the path tracer as the CUDA backend runs it (one GPU thread per pixel), and as the host runs the
// same code to test it (`device: emulated`): the primary hit from a vbuffer or a camera ray, samplesPerPixel paths
// through pt::tracePath with the BVH of loom/BvhTraversal.h for every ray, their sums, and the outputs. The same
// random numbers, rules and coverage keys as the CPU path tracer (PathTracer.cpp), so the images agree wherever
// the two traversals find the same hits. Plain data only: the views point into host or device memory alike.
#include <cstdint>
#include <glm/glm.hpp>

#include "Lights.h"
#include "PathTracerKernels.h"
#include "loom/BvhTraversal.h"
#include "loom/CameraKernels.h"
#include "loom/Kernel.h"
#include "loom/SurfaceKernels.h"

namespace loom::pt {

/// The key that moves a box-filtered camera sample within its pixel: a path's own key xor this, so the path's
/// random numbers stay those of the centre filter.
inline constexpr uint64_t kPixelSampleKey = 0x5851F42D4C957F2Dull;

/// Rays for pt::tracePath through the BVH: bounce rays in (0, 1e30), shadow rays in (tMin, tMax), under `rules`,
/// stochastic transparency keyed by rayCoverageKey as RayScene::intersect and the CPU's ray streams key it.
struct BvhTracer {
    const BvhView* bvh;
    uint32_t rules;
    bool keyed;  ///< alpha-tested geometry is traced: coverage keys matter
    LOOM_HD RayHit intersect(glm::vec3 o, glm::vec3 d) const {
        return bvhIntersect(*bvh, o, d, 0.f, 1e30f, rules, keyed ? rayCoverageKey(o, d) : 0u);
    }
    LOOM_HD bool occluded(glm::vec3 o, glm::vec3 d, float tMin, float tMax) const {
        return bvhOccluded(*bvh, o, d, tMin, tMax, rules, keyed ? rayCoverageKey(o, d) : 0u);
    }
};

/// A pixel's sums over its samples, in double, in sample order (so any batching or thread count gives the same
/// bits). Samples with a non-finite value are dropped.
struct PixelSum {
    glm::dvec3 sum{0.0}, direct{0.0}, indirect{0.0};
    uint32_t kept = 0;
    /// Adds one path's result; false when it was dropped.
    LOOM_HD bool add(const PathResult& r) {
        if (!isFinite(r.color) || !isFinite(r.direct) || !isFinite(r.indirect)) return false;
        sum += glm::dvec3(r.color);
        direct += glm::dvec3(r.direct);
        indirect += glm::dvec3(r.indirect);
        ++kept;
        return true;
    }
    LOOM_HD double inverse() const { return kept ? 1.0 / double(kept) : 0.0; }
    LOOM_HD glm::vec3 color() const { return glm::vec3(sum * inverse()); }
};

/// What the primary hit gives the denoiser: diffuse albedo, specular albedo and emitted radiance (alpha 1; zero
/// on a miss).
struct PrimaryChannels {
    glm::vec4 albedo{0.f}, specAlbedo{0.f}, emission{0.f};
};

LOOM_HD inline PrimaryChannels primaryChannels(const SceneView& scene, const RayHit& primary, glm::vec3 dir) {
    PrimaryChannels c;
    if (!primary.hit()) return c;
    const SurfaceHit hs = evalSurface(scene, primary.instance, primary.primitive, primary.u, primary.v, dir);
    c.albedo = glm::vec4(diffuseAlbedo(hs), 1.f);
    const float NdotV = glm::clamp(glm::dot(hs.normalW, -dir), 0.f, 1.f);
    c.specAlbedo = glm::vec4(specularAlbedo(specularF0(hs), NdotV, hs.roughness), 1.f);
    c.emission = glm::vec4(emittedRadiance(scene, hs, dir), 1.f);
    return c;
}

/// An image the kernel writes: `pitch` elements per row; null to skip.
template <class T>
struct PixelOut {
    T* data = nullptr;
    uint32_t pitch = 0;
    LOOM_HD void store(uint32_t x, uint32_t y, const T& v) const {
        if (data) data[size_t(y) * pitch + x] = v;
    }
};

/// Everything one frame's pixels need, by value (a kernel argument).
struct FrameKernel {
    BvhView bvh;
    SceneView scene;
    LightsView lights;
    PathTracerSettings set;
    CameraData cam;
    uint32_t width = 0, height = 0, spp = 1;
    uint64_t frame = 0;                   ///< frame index + (seed << 32): the random numbers' frame
    uint32_t coverageFrame = 0;           ///< the frame index camera coverage keys use
    uint32_t cameraRules = 0;             ///< RayRules of camera rays
    uint32_t secondaryRules = 0;          ///< RayRules of bounce and shadow rays
    bool keyed = false;                   ///< the scene has alpha-tested geometry and alphaTest is on
    bool boxFilter = false;               ///< each sample at a uniform point of the pixel, its own camera ray
    const glm::uvec4* vbuffer = nullptr;  ///< primary hits (instance, primitive, u bits, v bits); null: camera rays
    uint32_t vbufferPitch = 0;
    PixelOut<glm::vec4> color, direct, indirect, albedo, specAlbedo, emission;
    PixelOut<glm::uvec4> primaryHit;  ///< the primary hit as a vbuffer holds it (for temporal gradients)
    PixelOut<glm::uvec2> counts;      ///< (rays traced, samples dropped)
    /// History of the temporal gradients, one texel per 3x3 block (bx, by), written by the block's gradientPixel of
    /// frame gradientIndex: its primary hit (as primaryHit) and its colour's luminance. Null to skip.
    PixelOut<glm::uvec4> gradientHit;
    PixelOut<float> gradientLum;
    uint64_t gradientIndex = 0;  ///< the frame index gradientPixel is drawn for (not shifted by the seed)
};

/// The pixel of 3x3 block (bx, by) whose sample frame `frameIndex` keeps for the next frame's temporal gradient: one
/// of the block's pixels at random (a hash of block and frame), so the samples do not form a fixed pattern.
LOOM_HD inline glm::uvec2 gradientPixel(uint32_t bx, uint32_t by, uint64_t frameIndex, uint32_t w, uint32_t h) {
    constexpr uint32_t block = 3;  // channel::kGradientBlock
    const uint64_t k = mix64((uint64_t(by) << 32 | bx) ^ mix64(frameIndex + 0x6A09E667F3BCC909ull)) % 9u;
    return {glm::min(bx * block + uint32_t(k % 3), w - 1), glm::min(by * block + uint32_t(k / 3), h - 1)};
}

/// Renders pixel (x, y): what the CPU path tracer's execute computes for it.
LOOM_HD inline void renderPixel(const FrameKernel& k, uint32_t x, uint32_t y) {
    uint32_t rays = 0, dropped = 0;
    RayHit primary;
    glm::vec3 dir;
    if (k.vbuffer) {
        const glm::uvec4 vb = k.vbuffer[size_t(y) * k.vbufferPitch + x];
        if (vb.x != kInvalidId) {
            primary.instance = vb.x;
            primary.primitive = vb.y;
            primary.u = bitsToFloat(vb.z);
            primary.v = bitsToFloat(vb.w);
        }
        dir = glm::normalize(pixelRayDir(k.cam, x, y));
    } else {
        const glm::vec3 d = pixelRayDir(k.cam, x, y);
        const uint32_t key = k.keyed ? cameraCoverageKey(x, y, k.coverageFrame) : 0u;
        primary = bvhIntersect(k.bvh, k.cam.origin, d, 0.f, 1e30f, k.cameraRules, key);
        dir = glm::normalize(d);
        ++rays;
    }
    const BvhTracer tracer{&k.bvh, k.secondaryRules, k.keyed};
    PixelSum acc;
    for (uint32_t s = 0; s < k.spp; ++s) {
        PathRng rng(y * k.width + x, k.frame, s);
        PathResult r;
        if (k.boxFilter) {
            PathRng pixelRng = rng;
            pixelRng.key ^= kPixelSampleKey;
            const glm::vec2 u = pixelRng.next2();
            const glm::vec3 d = cameraRayDir(k.cam, float(x) + u.x, float(y) + u.y);
            const uint32_t key = k.keyed ? rayCoverageKey(k.cam.origin, d) : 0u;
            const RayHit hit = bvhIntersect(k.bvh, k.cam.origin, d, 0.f, 1e30f, k.cameraRules, key);
            ++rays;
            r = tracePath(tracer, k.scene, k.lights, k.set, k.cam.origin, d, hit, rng);
        } else {
            r = tracePath(tracer, k.scene, k.lights, k.set, k.cam.origin, dir, primary, rng);
        }
        rays += r.rays;
        if (!acc.add(r)) ++dropped;
    }
    const double inv = acc.inverse();
    k.color.store(x, y, glm::vec4(acc.color(), 1.f));
    k.direct.store(x, y, glm::vec4(glm::vec3(acc.direct * inv), 1.f));
    k.indirect.store(x, y, glm::vec4(glm::vec3(acc.indirect * inv), 1.f));
    if (k.albedo.data || k.specAlbedo.data || k.emission.data) {
        const PrimaryChannels c = primaryChannels(k.scene, primary, dir);
        k.albedo.store(x, y, c.albedo);
        k.specAlbedo.store(x, y, c.specAlbedo);
        k.emission.store(x, y, c.emission);
    }
    k.primaryHit.store(x, y,
                       glm::uvec4(primary.hit() ? primary.instance : kInvalidId, primary.primitive,
                                  floatBits(primary.u), floatBits(primary.v)));
    k.counts.store(x, y, glm::uvec2(rays, dropped));
    if (k.gradientHit.data && gradientPixel(x / 3u, y / 3u, k.gradientIndex, k.width, k.height) == glm::uvec2(x, y)) {
        k.gradientHit.store(x / 3u, y / 3u,
                            glm::uvec4(primary.hit() ? primary.instance : kInvalidId, primary.primitive,
                                       floatBits(primary.u), floatBits(primary.v)));
        k.gradientLum.store(x / 3u, y / 3u, luminance(acc.color()));
    }
}

/// Last frame's gradient samples replayed this frame (the temporal gradients of A-SVGF): what one launch over the
/// 3x3 blocks reads and writes. Views of the pass's history and output, in the memory of the device it runs on.
struct GradientReplay {
    const glm::uvec4* prevHits = nullptr;  ///< last frame's FrameKernel::gradientHit
    uint32_t prevHitsPitch = 0;
    const float* prevLum = nullptr;  ///< last frame's FrameKernel::gradientLum
    uint32_t prevLumPitch = 0;
    PixelOut<glm::vec2> out;  ///< the gradient output: (luminance now, luminance then), replicated over the block
    CameraData prevCam;       ///< last frame's camera (pose and jitter)
    uint64_t prevFrame = 0;   ///< last frame's random-number frame (FrameKernel::frame - 1)
    uint64_t prevIndex = 0;   ///< last frame's index (its gradientPixel)
};

/// The ray along which a gradient sample (last frame's pixel (px, py), its primary hit `hit`) is re-shaded: last
/// frame's camera ray, or with set.gradientFromCurrentView the ray from this frame's camera position `origin` to
/// the same surface point.
LOOM_HD inline void gradientRay(const SceneView& scene, const PathTracerSettings& set, const CameraData& prevCam,
                                glm::vec3 currentOrigin, uint32_t px, uint32_t py, const RayHit& hit,
                                glm::vec3& origin, glm::vec3& dir) {
    origin = prevCam.origin;
    dir = glm::normalize(pixelRayDir(prevCam, px, py));
    if (!set.gradientFromCurrentView) return;
    const glm::vec3 p = evalSurface(scene, hit.instance, hit.primitive, hit.u, hit.v, dir).posW;
    const glm::vec3 d = p - currentOrigin;
    if (!(glm::dot(d, d) > 0.f)) return;
    origin = currentOrigin;
    dir = glm::normalize(d);
}

/// Block (bx, by)'s temporal gradient: last frame's sample of the block re-shaded now, at the same surface point
/// (its hit follows animated instances) along last frame's camera ray with last frame's random numbers, through the
/// same paths renderPixel traces, next to its luminance then. Where nothing changed both are the same bits. (0, 0)
/// where last frame's sample missed. Returns the rays traced.
LOOM_HD inline uint32_t replayGradient(const FrameKernel& k, const GradientReplay& g, uint32_t bx, uint32_t by) {
    const uint32_t w = k.width, h = k.height;
    const glm::uvec2 q = gradientPixel(bx, by, g.prevIndex, w, h);
    const glm::uvec4 e = g.prevHits[size_t(by) * g.prevHitsPitch + bx];
    uint32_t rays = 0;
    glm::vec2 value(0.f);
    if (e.x < k.scene.instanceCount && e.y < k.scene.meshes[k.scene.instances[e.x].mesh].triangleCount) {
        RayHit hit;
        hit.instance = e.x;
        hit.primitive = e.y;
        hit.u = bitsToFloat(e.z);
        hit.v = bitsToFloat(e.w);
        glm::vec3 origin, dir;
        gradientRay(k.scene, k.set, g.prevCam, k.cam.origin, q.x, q.y, hit, origin, dir);
        const BvhTracer tracer{&k.bvh, k.secondaryRules, k.keyed};
        PixelSum acc;
        for (uint32_t s = 0; s < k.spp; ++s) {
            PathRng rng(q.y * w + q.x, g.prevFrame, s);
            const PathResult r = tracePath(tracer, k.scene, k.lights, k.set, origin, dir, hit, rng);
            rays += r.rays;
            acc.add(r);
        }
        value = glm::vec2(luminance(acc.color()), g.prevLum[size_t(by) * g.prevLumPitch + bx]);
    }
    const uint32_t x1 = (bx + 1) * 3u < w ? (bx + 1) * 3u : w, y1 = (by + 1) * 3u < h ? (by + 1) * 3u : h;
    for (uint32_t y = by * 3u; y < y1; ++y)
        for (uint32_t x = bx * 3u; x < x1; ++x) g.out.store(x, y, value);
    return rays;
}

}  // namespace loom::pt
