#include "loom/RayScene.h"

#include <embree3/rtcore.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <vector>

#include "loom/EmbreeRays.h"
#include "loom/Error.h"
#include "loom/Scene.h"

namespace loom {

struct RayScene::Impl {
    RTCDevice device = nullptr;
    RTCScene top = nullptr;
    std::vector<RTCScene> meshScenes;          // one per Scene::meshes
    std::vector<RTCGeometry> instanceGeoms;    // one per Scene::instances
    const SceneView* view = nullptr;           // the owning Scene's view (Scene is neither copied nor moved)
    bool alphaTested = false;                  // some geometry carries alphaFilter

    RayHit continuePastBackFaces(HitFilterContext& ctx, glm::vec3 o, glm::vec3 d, RayHit culled, float tMax,
                                 uint32_t key) const;
};

namespace {
void embreeError(void*, RTCError code, const char* str) {
    spdlog::error("Embree error {}: {}", int(code), str ? str : "");
}

/// The any-hit filter of geometry whose material is MASK or BLEND, for intersection and occlusion queries alike:
/// rejects a hit where the surface is not there (surfaceCovers, drawing from the ray's coverage key in its id).
/// Streams and packets call it with N > 1; lanes with valid[i] == 0 are left alone.
void alphaFilter(const RTCFilterFunctionNArguments* args) {
    const auto* ctx = reinterpret_cast<const HitFilterContext*>(args->context);
    if (!(ctx->rules & kRayAlphaTest)) return;
    const unsigned n = args->N;
    for (unsigned i = 0; i < n; ++i) {
        if (args->valid[i] == 0) continue;
        const uint32_t instance = RTCHitN_instID(args->hit, n, i, 0);
        const uint32_t prim = RTCHitN_primID(args->hit, n, i);
        if (!surfaceCovers(*ctx->scene, instance, prim, RTCHitN_u(args->hit, n, i), RTCHitN_v(args->hit, n, i),
                           RTCRayN_id(args->ray, n, i)))
            args->valid[i] = 0;
    }
}
}  // namespace

RayScene::RayScene(const Scene& scene) : mImpl(std::make_unique<Impl>()) {
    Impl& m = *mImpl;
    m.device = rtcNewDevice(nullptr);
    if (!m.device)
        throw Error(Error::Info{ErrorKind::Runtime, {}, {}, "cannot create the Embree device", {},
                                "check that the CPU supports SSE4.2 or better"});
    rtcSetDeviceErrorFunction(m.device, embreeError, nullptr);
    m.view = &scene.view();
    for (const Mesh& mesh : scene.meshes) {
        RTCScene s = rtcNewScene(m.device);
        rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_HIGH);
        if (!mesh.indices.empty()) {
            RTCGeometry g = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_TRIANGLE);
            // Copies with 16-byte vertices: Embree may read 4 floats of the last vertex.
            auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                                  4 * sizeof(float), mesh.positions.size()));
            for (size_t i = 0; i < mesh.positions.size(); ++i) {
                v[4 * i + 0] = mesh.positions[i].x;
                v[4 * i + 1] = mesh.positions[i].y;
                v[4 * i + 2] = mesh.positions[i].z;
                v[4 * i + 3] = 0.f;
            }
            auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                       3 * sizeof(uint32_t), mesh.triangleCount()));
            std::copy(mesh.indices.begin(), mesh.indices.end(), idx);
            // Only alpha-tested geometry gets a filter: opaque geometry is traversed at full speed.
            const bool alphaTested =
                mesh.material < scene.materials.size() && scene.materials[mesh.material].alphaMode != AlphaMode::Opaque;
            if (alphaTested) {
                rtcSetGeometryIntersectFilterFunction(g, alphaFilter);
                rtcSetGeometryOccludedFilterFunction(g, alphaFilter);
                m.alphaTested = true;
            }
            rtcCommitGeometry(g);
            rtcAttachGeometryByID(s, g, 0);
            rtcReleaseGeometry(g);
        }
        rtcCommitScene(s);
        m.meshScenes.push_back(s);
    }
    m.top = rtcNewScene(m.device);
    rtcSetSceneFlags(m.top, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(m.top, RTC_BUILD_QUALITY_LOW);
    for (size_t i = 0; i < scene.instances.size(); ++i) {
        RTCGeometry g = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_INSTANCE);
        rtcSetGeometryInstancedScene(g, m.meshScenes[scene.instances[i].mesh]);
        rtcSetGeometryTimeStepCount(g, 1);
        rtcAttachGeometryByID(m.top, g, unsigned(i));
        m.instanceGeoms.push_back(g);
    }
    updateInstances(scene);
}

RayScene::~RayScene() {
    Impl& m = *mImpl;
    for (RTCGeometry g : m.instanceGeoms) rtcReleaseGeometry(g);
    if (m.top) rtcReleaseScene(m.top);
    for (RTCScene s : m.meshScenes) rtcReleaseScene(s);
    if (m.device) rtcReleaseDevice(m.device);
}

void RayScene::updateInstances(const Scene& scene) {
    Impl& m = *mImpl;
    for (size_t i = 0; i < m.instanceGeoms.size() && i < scene.instances.size(); ++i) {
        const Instance& inst = scene.instances[i];
        // Embree carries rays into an instance through its inverse; a singular transform would make them
        // invalid, and a point-sized instance breaks the top-level build.
        if (!inst.visible()) {
            rtcDisableGeometry(m.instanceGeoms[i]);
            continue;
        }
        rtcSetGeometryTransform(m.instanceGeoms[i], 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &inst.world[0][0]);
        rtcCommitGeometry(m.instanceGeoms[i]);
        rtcEnableGeometry(m.instanceGeoms[i]);
    }
    rtcCommitScene(m.top);
}

void* RayScene::embreeScene() const { return mImpl->top; }

bool RayScene::hasAlphaTestedGeometry() const {
    return mImpl->alphaTested;
}

namespace {
/// Is hit h of a ray along d a back face to cull (kRayCullBackFaces): a single-sided material whose front (counter-
/// clockwise) face looks away from the ray? ngObj is Embree's geometric normal, (p1 - p0) x (p2 - p0) in the
/// instance's object space; the normal matrix carries it to world space.
bool culled(const SceneView& view, const RayHit& h, glm::vec3 ngObj, glm::vec3 d) {
    const InstanceView& inst = view.instances[h.instance];
    return !view.materials[view.meshes[inst.mesh].material].doubleSided &&
           !(glm::dot(inst.normalMatrix * ngObj, d) < 0.f);
}
}  // namespace

/// Continues a ray from just beyond a culled back face, and each further one, as GBufferRaster's culling drops
/// them (a miss after 16 such faces). Culling outside Embree: only camera rays cull, and most of their hits are
/// front faces, while a filter on every single-sided geometry would cost every ray.
RayHit RayScene::Impl::continuePastBackFaces(HitFilterContext& ctx, glm::vec3 o, glm::vec3 d, RayHit hit, float tMax,
                                             uint32_t key) const {
    for (int layer = 1; layer < 16; ++layer) {
        glm::vec3 ng;
        hit = embreeIntersect(top, ctx, o, d, std::nextafter(hit.t, 1e30f), tMax, key, &ng);
        if (!hit.hit() || !culled(*view, hit, ng, d)) return hit;
    }
    return {};
}

RayHit RayScene::intersect(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax, uint32_t rules) const {
    HitFilterContext ctx;
    initHitFilterContext(ctx, *mImpl->view, rules);
    const uint32_t key = mImpl->alphaTested ? rayCoverageKey(o, d) : 0u;  // keys matter to alpha filters only
    glm::vec3 ng;
    const RayHit h = embreeIntersect(mImpl->top, ctx, o, d, tMin, tMax, key, &ng);
    const bool cull = (rules & kRayCullBackFaces) && h.hit() && culled(*mImpl->view, h, ng, d);
    return cull ? mImpl->continuePastBackFaces(ctx, o, d, h, tMax, key) : h;
}

bool RayScene::occluded(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax, uint32_t rules) const {
    HitFilterContext ctx;
    initHitFilterContext(ctx, *mImpl->view, rules);
    return embreeOccluded(mImpl->top, ctx, o, d, tMin, tMax);
}

void RayScene::intersect16(const glm::vec3* origins, const glm::vec3* dirs, const bool* valid, float tMax, RayHit* hits,
                           uint32_t rules, const uint32_t* keys) const {
    HitFilterContext ctx;
    initHitFilterContext(ctx, *mImpl->view, rules, RTC_INTERSECT_CONTEXT_FLAG_COHERENT);
    alignas(64) RTCRayHit16 rh;
    alignas(64) int mask[16];
    for (int i = 0; i < 16; ++i) {
        const bool active = valid[i] && traceable(origins[i], dirs[i]);  // an untraceable ray hits nothing
        mask[i] = active ? -1 : 0;
        rh.ray.org_x[i] = active ? origins[i].x : 0.f;
        rh.ray.org_y[i] = active ? origins[i].y : 0.f;
        rh.ray.org_z[i] = active ? origins[i].z : 0.f;
        rh.ray.dir_x[i] = active ? dirs[i].x : 0.f;
        rh.ray.dir_y[i] = active ? dirs[i].y : 0.f;
        rh.ray.dir_z[i] = active ? dirs[i].z : 1.f;
        rh.ray.tnear[i] = 0.f;
        rh.ray.tfar[i] = tMax;
        rh.ray.time[i] = 0.f;
        rh.ray.mask[i] = 0xFFFFFFFFu;
        rh.ray.id[i] = keys ? keys[i] : 0u;
        rh.ray.flags[i] = 0;
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    // Keys matter to alpha filters only; hashed in a loop of their own, which keeps the one above simple.
    if (!keys && mImpl->alphaTested)
        for (int i = 0; i < 16; ++i) rh.ray.id[i] = rayCoverageKey(origins[i], dirs[i]);
    rtcIntersect16(mask, mImpl->top, &ctx.embree, &rh);
    const bool cull = rules & kRayCullBackFaces;
    for (int i = 0; i < 16; ++i) {
        RayHit h;
        if (mask[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID) {
            h.instance = rh.hit.instID[0][i];
            h.primitive = rh.hit.primID[i];
            h.u = rh.hit.u[i];
            h.v = rh.hit.v[i];
            h.t = rh.ray.tfar[i];
            if (cull && culled(*mImpl->view, h, glm::vec3(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]), dirs[i]))
                h = mImpl->continuePastBackFaces(ctx, origins[i], dirs[i], h, tMax, rh.ray.id[i]);
        }
        hits[i] = h;
    }
}

}  // namespace loom
