#pragma once
// Per-pixel G-buffer evaluation from a primary hit (plain functions over
// plain data, so they compile for CUDA as well).
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/BvhTraversal.h"
#include "loom/CameraKernels.h"
#include "loom/Kernel.h"
#include "loom/SceneView.h"
#include "loom/SurfaceKernels.h"
#include "loom/Texture.h"

namespace loom::gbuffer {

inline constexpr uint32_t kMiss = 0xFFFFFFFFu;

/// Everything the G-buffer channels hold for one pixel.
struct GBufferSample {
    glm::vec4 posW{0.f};
    glm::vec4 normW{0.f};
    glm::vec4 faceNormalW{0.f};
    glm::vec2 linearZ{-1.f, 0.f};
    glm::vec2 pnFwidth{0.f};
    glm::vec2 mvec{0.f};
    glm::vec4 albedo{0.f};
    glm::vec4 specAlbedo{0.f};
    glm::vec4 emission{0.f};
    glm::uvec4 vbuffer{kMiss};
    uint32_t meshId = kMiss;
};

LOOM_HD inline GBufferSample missSample(const CameraData& cam, glm::vec3 dir) {
    GBufferSample g;
    g.mvec = missMotion(cam, dir);
    return g;
}

/// Where the ray o + t d meets the plane through p with normal n (t may be
/// negative for grazing rays; callers clamp what they derive from it).
LOOM_HD inline glm::vec3 rayPlane(glm::vec3 o, glm::vec3 d, glm::vec3 p, glm::vec3 n) {
    const float denom = glm::dot(d, n);
    if (std::fabs(denom) < 1e-12f) return p;
    return o + d * (glm::dot(p - o, n) / denom);
}

/// Barycentrics (u, v) of point q in the plane of triangle (a, b, c).
LOOM_HD inline glm::vec2 barycentrics(glm::vec3 q, glm::vec3 a, glm::vec3 b, glm::vec3 c) {
    const glm::vec3 e1 = b - a, e2 = c - a, r = q - a;
    const float d11 = glm::dot(e1, e1), d12 = glm::dot(e1, e2), d22 = glm::dot(e2, e2);
    const float r1 = glm::dot(r, e1), r2 = glm::dot(r, e2);
    const float det = d11 * d22 - d12 * d12;
    if (std::fabs(det) < 1e-30f) return glm::vec2(0.f);
    return glm::vec2((d22 * r1 - d12 * r2) / det, (d11 * r2 - d12 * r1) / det);
}

/// Shading normal (world, normalised, same side as `side`) at barycentrics (u, v).
LOOM_HD inline glm::vec3 interpolatedNormal(const SceneView& scene, uint32_t instance, uint32_t prim, glm::vec2 uv,
                                            glm::vec3 side) {
    const InstanceView& inst = scene.instances[instance];
    const MeshView& mesh = scene.meshes[inst.mesh];
    const uint32_t* idx = mesh.indices + 3 * prim;
    const glm::vec3 n =
        (1.f - uv.x - uv.y) * mesh.normals[idx[0]] + uv.x * mesh.normals[idx[1]] + uv.y * mesh.normals[idx[2]];
    glm::vec3 w = glm::normalize(inst.normalMatrix * n);
    return glm::dot(w, side) < 0.f ? -w : w;
}

/// The G-buffer sample of a primary hit. Screen-space derivatives come from
/// ray differentials: the rays through the next pixel in x and y are
/// intersected with the hit triangle's plane, as a rasterizer's dFdx/dFdy see
/// a planar triangle. Moving = false is for frames where every instance's
/// prevWorld equals its world: the surface's position last frame is its
/// position now (motion is the camera's alone), and neither it nor the uv of an
/// untextured material is computed; the sample is the same bit for bit.
template <bool Moving = true>
LOOM_HD inline GBufferSample hitSample(const SceneView& scene, const CameraData& cam, uint32_t x, uint32_t y,
                                       uint32_t instance, uint32_t prim, float u, float v) {
    const glm::vec3 dir = pixelRayDir(cam, x, y);
    SurfaceHit s = evalSurface(scene, instance, prim, u, v, dir, Moving ? SurfaceEval::Full : SurfaceEval::Shading);
    if (!Moving) s.prevPosW = s.posW;
    GBufferSample g;
    g.posW = glm::vec4(s.posW, 1.f);
    g.normW = glm::vec4(s.normalW, 0.f);
    g.faceNormalW = glm::vec4(s.faceNormalW, 0.f);
    const float depth = glm::dot(s.posW - cam.origin, cam.forward);

    const float px = float(x) + 0.5f + cam.jitter.x, py = float(y) + 0.5f + cam.jitter.y;
    const glm::vec3 qx = rayPlane(cam.origin, cameraRayDir(cam, px + 1.f, py), s.posW, s.faceNormalW);
    const glm::vec3 qy = rayPlane(cam.origin, cameraRayDir(cam, px, py + 1.f), s.posW, s.faceNormalW);
    const glm::vec3 dpdx = qx - s.posW, dpdy = qy - s.posW;
    g.linearZ =
        glm::vec2(depth, std::fmax(std::fabs(glm::dot(dpdx, cam.forward)), std::fabs(glm::dot(dpdy, cam.forward))));

    // Normal derivatives: interpolate the vertex normals at the neighbours'
    // plane points (in object space, through the inverse instance transform).
    const InstanceView& inst = scene.instances[instance];
    const MeshView& mesh = scene.meshes[inst.mesh];
    const uint32_t* idx = mesh.indices + 3 * prim;
    const glm::vec3 a = glm::vec3(inst.world * glm::vec4(mesh.positions[idx[0]], 1.f));
    const glm::vec3 b = glm::vec3(inst.world * glm::vec4(mesh.positions[idx[1]], 1.f));
    const glm::vec3 c = glm::vec3(inst.world * glm::vec4(mesh.positions[idx[2]], 1.f));
    const glm::vec3 nx = interpolatedNormal(scene, instance, prim, barycentrics(qx, a, b, c), s.faceNormalW);
    const glm::vec3 ny = interpolatedNormal(scene, instance, prim, barycentrics(qy, a, b, c), s.faceNormalW);
    const glm::vec3 n0 = interpolatedNormal(scene, instance, prim, glm::vec2(u, v), s.faceNormalW);
    g.pnFwidth =
        glm::vec2(glm::length(glm::abs(dpdx) + glm::abs(dpdy)), glm::length(glm::abs(nx - n0) + glm::abs(ny - n0)));

    g.mvec = surfaceMotion(cam, s.posW, s.prevPosW);
    g.albedo = glm::vec4(diffuseAlbedo(s), 1.f);
    const float NdotV = glm::clamp(-glm::dot(s.normalW, glm::normalize(dir)), 0.f, 1.f);
    g.specAlbedo = glm::vec4(specularAlbedo(specularF0(s), NdotV, s.roughness), 1.f);
    g.emission = glm::vec4(s.emission, 1.f);
    g.vbuffer = glm::uvec4(instance, prim, floatBits(u), floatBits(v));
    g.meshId = instance;
    return g;
}

/// The channels a G-buffer pass writes, as views of its outputs (host views on the CPU, device views elsewhere);
/// data == nullptr for a channel nobody consumes.
struct GBufferViews {
    ImageView<glm::vec4> posW, normW, faceNormalW, albedo, specAlbedo, emission;
    ImageView<glm::vec2> linearZ, pnFwidth, mvec;
    ImageView<glm::uvec4> vbuffer;
    ImageView<uint32_t> meshId;
};

/// Writes pixel (x, y) of every channel that has a view.
LOOM_HD inline void storeSample(const GBufferViews& o, uint32_t x, uint32_t y, const GBufferSample& g) {
    if (o.posW.data) o.posW.at(x, y) = g.posW;
    if (o.normW.data) o.normW.at(x, y) = g.normW;
    if (o.faceNormalW.data) o.faceNormalW.at(x, y) = g.faceNormalW;
    if (o.linearZ.data) o.linearZ.at(x, y) = g.linearZ;
    if (o.pnFwidth.data) o.pnFwidth.at(x, y) = g.pnFwidth;
    if (o.mvec.data) o.mvec.at(x, y) = g.mvec;
    if (o.albedo.data) o.albedo.at(x, y) = g.albedo;
    if (o.specAlbedo.data) o.specAlbedo.at(x, y) = g.specAlbedo;
    if (o.emission.data) o.emission.at(x, y) = g.emission;
    if (o.vbuffer.data) o.vbuffer.at(x, y) = g.vbuffer;
    if (o.meshId.data) o.meshId.at(x, y) = g.meshId;
}

/// GBufferRT's pixel (x, y) off the CPU: its camera ray through the BVH (BvhTraversal.h) under `rules`, then the
/// sample of the hit or the miss. The ray and its rules are those the CPU's Embree packets trace
/// (traceCameraRays): direction pixelRayDir, t in (0, 1e30], coverage key cameraCoverageKey(x, y, frame) where
/// alpha-tested geometry is traced (`keyed`), else 0. So the two find the same triangles, up to ties at shared
/// edges, with t and barycentrics equal up to float rounding.
template <bool Moving = true>
LOOM_HD inline GBufferSample tracedSample(const BvhView& bvh, const CameraData& cam, uint32_t x, uint32_t y,
                                          uint32_t rules, bool keyed, uint32_t frame) {
    const glm::vec3 dir = pixelRayDir(cam, x, y);
    const uint32_t key = keyed ? cameraCoverageKey(x, y, frame) : 0u;
    const RayHit hit = bvhIntersect(bvh, cam.origin, dir, 0.f, 1e30f, rules, key);
    return hit.hit() ? hitSample<Moving>(bvh.scene, cam, x, y, hit.instance, hit.primitive, hit.u, hit.v)
                     : missSample(cam, dir);
}

}  // namespace loom::gbuffer
