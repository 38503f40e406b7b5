// GBufferRT's camera rays through the BVH (GBufferRTDevice.h). Compiled by nvcc where the CUDA toolkit is found
// (LOOM_CUDA; CMake compiles this file as CUDA), else by the host compiler: the same source either way, and the
// launches run on the cuda device only in the first case.
#include "GBufferRTDevice.h"

#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/Launch.h"

namespace loom::gbuffer::device {

bool launchesOnCuda() { return launchesReach(DeviceKind::Cuda); }

struct DeviceScene::Impl {
    uint64_t key = ~uint64_t(0);
#if defined(__CUDACC__)
    std::vector<std::shared_ptr<std::byte>> perScene, perFrame;  ///< device memory, kept while it is in use
    SceneView scene;   ///< device pointers to the meshes and images (materials, instances: per frame)
    BvhArrays bottom;  ///< device spans of the bottom-level arrays

    /// A device copy of `count` elements at `host` (nullptr for none), kept in `keep`.
    template <class T>
    static const T* upload(std::vector<std::shared_ptr<std::byte>>& keep, const T* host, size_t count,
                           const char* what) {
        if (!host || count == 0) return nullptr;
        std::shared_ptr<std::byte> mem =
            allocateOnDevice(DeviceKind::Cuda, count * sizeof(T), std::string("GBufferRT's scene (") + what + ")");
        detail::checkCuda(cudaMemcpy(mem.get(), host, count * sizeof(T), cudaMemcpyHostToDevice),
                          "cudaMemcpy (GBufferRT's scene to the device)");
        keep.push_back(mem);
        return reinterpret_cast<const T*>(mem.get());
    }
    template <class T>
    static BvhSpan<T> upload(std::vector<std::shared_ptr<std::byte>>& keep, BvhSpan<T> s, const char* what) {
        return {upload(keep, s.data, s.count, what), s.count};
    }

    void uploadScene(const BvhView& host) {
        perScene.clear();
        const SceneView& h = host.scene;
        std::vector<MeshView> meshes(h.meshes, h.meshes + h.meshCount);
        for (MeshView& m : meshes) {
            size_t vertices = 0;  // a MeshView holds no vertex count: its largest index says it
            for (size_t i = 0; i < size_t(m.triangleCount) * 3; ++i)
                vertices = m.indices[i] + size_t(1) > vertices ? m.indices[i] + size_t(1) : vertices;
            m.positions = upload(perScene, m.positions, vertices, "positions");
            m.normals = upload(perScene, m.normals, vertices, "normals");
            m.tangents = upload(perScene, m.tangents, vertices, "tangents");
            m.uvs = upload(perScene, m.uvs, vertices, "uvs");
            m.indices = upload(perScene, m.indices, size_t(m.triangleCount) * 3, "indices");
        }
        std::vector<ImageView8> images(h.images, h.images + h.imageCount);
        for (ImageView8& im : images) im.texels = upload(perScene, im.texels, size_t(im.width) * im.height, "texels");
        scene = h;
        scene.meshes = upload(perScene, meshes.data(), meshes.size(), "meshes");
        scene.images = upload(perScene, images.data(), images.size(), "images");
        bottom.nodes = upload(perScene, host.bvh.nodes, "BVH nodes");
        bottom.triangles = upload(perScene, host.bvh.triangles, "BVH triangles");
        bottom.meshes = upload(perScene, host.bvh.meshes, "BVH meshes");
    }
#endif
};

DeviceScene::DeviceScene() : mImpl(std::make_unique<Impl>()) {}
DeviceScene::~DeviceScene() = default;

BvhView DeviceScene::view(DeviceKind device, const BvhView& host, uint64_t sceneKey) {
    if (device != DeviceKind::Cuda) return host;  // emulated: kernels on the CPU's threads read the host's arrays
#if defined(__CUDACC__)
    Impl& m = *mImpl;
    if (m.key != sceneKey) {
        m.key = ~uint64_t(0);  // until the upload completes
        m.uploadScene(host);
        m.key = sceneKey;
    }
    m.perFrame.clear();
    BvhView d;
    d.scene = m.scene;
    d.scene.materials = Impl::upload(m.perFrame, host.scene.materials, host.scene.materialCount, "materials");
    d.scene.instances = Impl::upload(m.perFrame, host.scene.instances, host.scene.instanceCount, "instances");
    d.bvh = m.bottom;
    d.bvh.topNodes = Impl::upload(m.perFrame, host.bvh.topNodes, "BVH top nodes");
    d.bvh.topInstances = Impl::upload(m.perFrame, host.bvh.topInstances, "BVH top instances");
    d.bvh.instances = Impl::upload(m.perFrame, host.bvh.instances, "BVH instances");
    return d;
#else
    (void)sceneKey;
    detail::launchRefused("GBufferRT's scene upload");
#endif
}

void trace(DeviceKind device, const BvhView& scene, const TraceParams& params, const GBufferViews& out) {
    const BvhView s = scene;
    const GBufferViews o = out;
    const CameraData cam = params.cam;
    const uint32_t rules = params.rules, frame = params.frame;
    const bool keyed = params.keyed;
    // Moving is decided once per frame, as on the CPU: a static frame leaves out the previous-position transform.
    if (params.moving)
        launch2D(device, params.width, params.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
            storeSample(o, x, y, tracedSample<true>(s, cam, x, y, rules, keyed, frame));
        });
    else
        launch2D(device, params.width, params.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
            storeSample(o, x, y, tracedSample<false>(s, cam, x, y, rules, keyed, frame));
        });
}

}  // namespace loom::gbuffer::device
