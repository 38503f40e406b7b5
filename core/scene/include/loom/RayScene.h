#pragma once
// Ray tracing over a Scene with Embree 3: one bottom-level scene per mesh and
// one instance per Scene::Instance, so animation moves instances and never
// rebuilds geometry.
#include <cstdint>
#include <memory>

#include <glm/glm.hpp>

#include "loom/Kernel.h"

namespace loom {

class Scene;

inline constexpr uint32_t kInvalidId = 0xFFFFFFFFu;

/// What a ray query honours (a bit set). Every pass traces by the same rules, so G-buffers and the path tracer see
/// one scene:
/// - kRayAlphaTest: glTF alphaMode MASK (no surface where alpha < alphaCutoff) and BLEND (stochastic
///   transparency, surfaceCovers in SurfaceKernels.h). Only geometry of MASK or BLEND materials carries an Embree
///   filter, so opaque geometry costs nothing extra.
/// - kRayCullBackFaces: back faces of single-sided materials are not hit. For camera rays, as rasterization culls
///   them; bounce and shadow rays see both faces (the common convention: a single-sided wall still blocks light
///   and reflects from behind, so closed scenes stay closed).
enum RayRules : uint32_t {
    kRayOpaque = 0,
    kRayAlphaTest = 1u << 0,
    kRayCullBackFaces = 1u << 1,
};

/// The world Loom traces in: ray origins and directions with a component beyond this (or not finite) are not
/// traced (no hit, no occluder), and an instance whose translation exceeds it is hidden (Instance::visible).
/// Embree rejects rays beyond about 1.8e18, also after it carries them into an instance: with origins, directions
/// and translations within 1e8 and inverse transforms within 1e9 (Instance::visible), that stays below 6e17.
inline constexpr float kWorldLimit = 1e8f;

/// Whether a ray is traced: every component of its origin and direction finite and within kWorldLimit.
LOOM_HD inline bool traceable(const glm::vec3& o, const glm::vec3& d) {
    const glm::vec3 limit(kWorldLimit);  // a comparison with NaN is false
    return glm::all(glm::lessThanEqual(glm::abs(o), limit)) && glm::all(glm::lessThanEqual(glm::abs(d), limit));
}

struct RayHit {
    uint32_t instance = kInvalidId;  ///< index into Scene::instances; kInvalidId on a miss
    uint32_t primitive = kInvalidId; ///< triangle index within the instance's mesh
    float u = 0.f, v = 0.f;          ///< barycentrics: p = (1-u-v) p0 + u p1 + v p2
    float t = 0.f;                   ///< distance along the (unnormalised) direction
    LOOM_HD bool hit() const { return instance != kInvalidId; }
};

class RayScene {
public:
    explicit RayScene(const Scene& scene);
    ~RayScene();
    RayScene(const RayScene&) = delete;
    RayScene& operator=(const RayScene&) = delete;

    /// Copies the instances' current world transforms and recommits the
    /// top-level scene (no geometry rebuild).
    void updateInstances(const Scene& scene);

    /// Closest hit in (tMin, tMax) under `rules` (RayRules); stochastic transparency draws from the ray's
    /// rayCoverageKey. Thread-safe.
    RayHit intersect(const glm::vec3& origin, const glm::vec3& dir, float tMin = 0.f, float tMax = 1e30f,
                     uint32_t rules = kRayAlphaTest) const;
    /// Any hit in (tMin, tMax) under `rules`, as intersect. Thread-safe.
    bool occluded(const glm::vec3& origin, const glm::vec3& dir, float tMin, float tMax,
                  uint32_t rules = kRayAlphaTest) const;

    /// 16 rays at once (for coherent primary rays); valid[i] = false skips lane i. keys[i] is lane i's coverage
    /// key (cameraCoverageKey for camera rays); without keys each ray's rayCoverageKey.
    void intersect16(const glm::vec3* origins, const glm::vec3* dirs, const bool* valid, float tMax, RayHit* hits,
                     uint32_t rules = kRayAlphaTest, const uint32_t* keys = nullptr) const;

    /// Whether any geometry is alpha-tested (a MASK or BLEND material): only then do coverage keys matter.
    bool hasAlphaTestedGeometry() const;

    /// The top-level Embree scene (an RTCScene), for passes that call Embree
    /// directly in their innermost loop; valid while this RayScene lives. Such calls pass a HitFilterContext
    /// (EmbreeRays.h), which the filters of alpha-tested geometry read.
    void* embreeScene() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

}  // namespace loom
