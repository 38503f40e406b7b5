#include "loom/RayScene.h"

#include "loom/EmbreeRays.h"

#include <embree3/rtcore.h>

#include <vector>

#include <spdlog/spdlog.h>

#include "loom/Error.h"
#include "loom/Scene.h"

namespace loom {

struct RayScene::Impl {
    RTCDevice device = nullptr;
    RTCScene top = nullptr;
    std::vector<RTCScene> meshScenes;          // one per Scene::meshes
    std::vector<RTCGeometry> instanceGeoms;    // one per Scene::instances
};

namespace {
void embreeError(void*, RTCError code, const char* str) {
    spdlog::error("Embree error {}: {}", int(code), str ? str : "");
}
}  // namespace

RayScene::RayScene(const Scene& scene) : mImpl(std::make_unique<Impl>()) {
    Impl& m = *mImpl;
    m.device = rtcNewDevice(nullptr);
    if (!m.device)
        throw Error(Error::Info{ErrorKind::Runtime, {}, {}, "cannot create the Embree device", {},
                                "check that the CPU supports SSE4.2 or better"});
    rtcSetDeviceErrorFunction(m.device, embreeError, nullptr);
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

RayHit RayScene::intersect(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax) const {
    return embreeIntersect(mImpl->top, o, d, tMin, tMax);
}

bool RayScene::occluded(const glm::vec3& o, const glm::vec3& d, float tMin, float tMax) const {
    return embreeOccluded(mImpl->top, o, d, tMin, tMax);
}

void RayScene::intersect16(const glm::vec3* origins, const glm::vec3* dirs, const bool* valid, float tMax,
                           RayHit* hits) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
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
        rh.ray.id[i] = unsigned(i);
        rh.ray.flags[i] = 0;
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect16(mask, mImpl->top, &ctx, &rh);
    for (int i = 0; i < 16; ++i) {
        RayHit h;
        if (mask[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID) {
            h.instance = rh.hit.instID[0][i];
            h.primitive = rh.hit.primID[i];
            h.u = rh.hit.u[i];
            h.v = rh.hit.v[i];
            h.t = rh.ray.tfar[i];
        }
        hits[i] = h;
    }
}

}  // namespace loom
