#pragma once
// Single rays against an Embree scene, inline so that hot loops (the path
// tracer's) avoid a call into libloom_scene per ray. RayScene uses the same
// functions, so both give identical hits. Including this header needs
// Embree 3's headers: link the `loom_embree_rays` target, which carries them.
#include <embree3/rtcore.h>

#include <glm/glm.hpp>

#include "loom/RayScene.h"
#include "loom/SceneView.h"
#include "loom/SurfaceKernels.h"

namespace loom {

/// Embree's intersection context extended with what Loom's filters read (Embree's documented pattern: the
/// RTCIntersectContext comes first, and a filter casts the context it is given back to this). Every query against
/// a RayScene's Embree scene passes one, made by initHitFilterContext. A ray's coverage key (cameraCoverageKey or
/// rayCoverageKey) travels in its `id`, which Embree hands to filters for single rays, packets and streams alike.
/// Back faces are culled outside Embree (RayScene::intersect16 and intersect continue past them): a filter on
/// every single-sided geometry would slow down every ray, for the camera rays' sake.
struct HitFilterContext {
    RTCIntersectContext embree;
    const SceneView* scene = nullptr;
    uint32_t rules = 0;  ///< RayRules
};

/// A context for queries under `rules` (RayRules) over `scene`, the view of the Scene the RayScene was built from.
inline void initHitFilterContext(HitFilterContext& c, const SceneView& scene, uint32_t rules,
                                 RTCIntersectContextFlags flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT) {
    rtcInitIntersectContext(&c.embree);
    c.embree.flags = flags;
    c.scene = &scene;
    c.rules = rules;
}

/// Closest hit of o + t d, t in (tMin, tMax), for a ray of coverage key `key`; none for a ray that is not
/// traceable(). Back faces are not culled here (RayScene::intersect does that). With ngObj, a hit's geometric
/// normal as Embree gives it, (p1 - p0) x (p2 - p0) in the instance's object space, goes there.
inline RayHit embreeIntersect(RTCScene scene, HitFilterContext& ctx, glm::vec3 o, glm::vec3 d, float tMin, float tMax,
                              uint32_t key, glm::vec3* ngObj = nullptr) {
    if (!traceable(o, d)) return {};
    RTCRayHit rh;
    rh.ray.org_x = o.x;
    rh.ray.org_y = o.y;
    rh.ray.org_z = o.z;
    rh.ray.tnear = tMin;
    rh.ray.dir_x = d.x;
    rh.ray.dir_y = d.y;
    rh.ray.dir_z = d.z;
    rh.ray.time = 0.f;
    rh.ray.tfar = tMax;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.id = key;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene, &ctx.embree, &rh);
    RayHit h;
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
        h.instance = rh.hit.instID[0];
        h.primitive = rh.hit.primID;
        h.u = rh.hit.u;
        h.v = rh.hit.v;
        h.t = rh.ray.tfar;
        if (ngObj) *ngObj = glm::vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z);
    }
    return h;
}

/// Any hit of o + t d, t in (tMin, tMax); none for a ray that is not traceable().
inline bool embreeOccluded(RTCScene scene, HitFilterContext& ctx, glm::vec3 o, glm::vec3 d, float tMin, float tMax) {
    if (!traceable(o, d)) return false;
    RTCRay r;
    r.org_x = o.x;
    r.org_y = o.y;
    r.org_z = o.z;
    r.tnear = tMin;
    r.dir_x = d.x;
    r.dir_y = d.y;
    r.dir_z = d.z;
    r.time = 0.f;
    r.tfar = tMax;
    r.mask = 0xFFFFFFFFu;
    r.id = rayCoverageKey(o, d);
    r.flags = 0;
    rtcOccluded1(scene, &ctx.embree, &r);
    return r.tfar < 0.f;  // Embree sets tfar to -inf on a hit
}

/// Sets up ray r of a stream (rtcIntersect1M, rtcOccluded1M): o + t d for t in (0, tMax), or, for a ray that is
/// not traceable(), an inactive one (tnear > tfar), which Embree leaves as it is: no hit, no occluder. `key` is
/// the ray's coverage key (rayCoverageKey(o, d) where the scene has alpha-tested geometry; anything otherwise).
inline void setStreamRay(RTCRay& r, glm::vec3 o, glm::vec3 d, float tMax, uint32_t key) {
    const bool active = traceable(o, d);
    r.org_x = active ? o.x : 0.f;
    r.org_y = active ? o.y : 0.f;
    r.org_z = active ? o.z : 0.f;
    r.tnear = active ? 0.f : 1.f;
    r.dir_x = active ? d.x : 0.f;
    r.dir_y = active ? d.y : 0.f;
    r.dir_z = active ? d.z : 1.f;
    r.time = 0.f;
    r.tfar = active ? tMax : 0.f;
    r.mask = 0xFFFFFFFFu;
    r.id = key;
    r.flags = 0;
}

}  // namespace loom
