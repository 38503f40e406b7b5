// The path tracer's CUDA backend: device copies of what PixelKernel.h reads, one launch of renderPixel per frame,
// and the outputs copied back into the graph's host textures. No decision about a pixel is made here.
#include <cuda_runtime.h>

#include <string>
#include <vector>

#include "CudaBackend.h"
#include "loom/Error.h"

namespace loom::pt {

namespace {

[[noreturn]] void fail(const char* call, cudaError_t e) {
    throw Error({ErrorKind::Runtime, "", "PathTracer (CUDA)", std::string(call) + " failed: " + cudaGetErrorString(e),
                 "", "run with device cpu, or check the GPU and its driver (nvidia-smi)"});
}

void check(cudaError_t e, const char* call) {
    if (e != cudaSuccess) fail(call, e);
}

/// Device memory that grows to the largest size asked of it.
class DeviceBuffer {
public:
    DeviceBuffer() = default;
    DeviceBuffer(const DeviceBuffer&) = delete;
    DeviceBuffer& operator=(const DeviceBuffer&) = delete;
    DeviceBuffer(DeviceBuffer&& o) noexcept : mPtr(o.mPtr), mSize(o.mSize) {
        o.mPtr = nullptr;
        o.mSize = 0;
    }
    ~DeviceBuffer() {
        if (mPtr) cudaFree(mPtr);
    }
    void* reserve(size_t bytes) {
        if (bytes > mSize) {
            if (mPtr) cudaFree(mPtr);
            mPtr = nullptr;
            mSize = 0;
            check(cudaMalloc(&mPtr, bytes), "cudaMalloc");
            mSize = bytes;
        }
        return mPtr;
    }
    /// A device copy of `count` elements at `host` (nullptr for none).
    template <class T>
    const T* upload(const T* host, size_t count) {
        if (!host || count == 0) return nullptr;
        void* d = reserve(count * sizeof(T));
        check(cudaMemcpy(d, host, count * sizeof(T), cudaMemcpyHostToDevice), "cudaMemcpy (to the device)");
        return static_cast<const T*>(d);
    }

private:
    void* mPtr = nullptr;
    size_t mSize = 0;
};

template <class T>
BvhSpan<T> uploadSpan(DeviceBuffer& b, BvhSpan<T> s) {
    return {b.upload(s.data, s.count), s.count};
}

__global__ void renderFrame(FrameKernel k) {
    const uint32_t x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
    if (x < k.width && y < k.height) renderPixel(k, x, y);
}

}  // namespace

const CudaDeviceStatus& cudaDeviceStatus() {
    static const CudaDeviceStatus status = [] {
        CudaDeviceStatus s;
        int count = 0;
        const cudaError_t e = cudaGetDeviceCount(&count);
        if (e != cudaSuccess) {
            s.description = std::string("no usable CUDA device (") + cudaGetErrorString(e) + ")";
            return s;
        }
        if (count == 0) {
            s.description = "no CUDA device found";
            return s;
        }
        cudaDeviceProp p{};
        if (cudaGetDeviceProperties(&p, 0) != cudaSuccess) {
            s.description = "no usable CUDA device (its properties cannot be read)";
            return s;
        }
        s.usable = true;
        s.description = std::string(p.name) + ", compute " + std::to_string(p.major) + "." + std::to_string(p.minor) +
                        ", " + std::to_string(p.totalGlobalMem >> 30) + " GiB";
        return s;
    }();
    return status;
}

struct CudaBackend::Impl {
    uint64_t sceneKey = ~uint64_t(0);
    // The scene: per mesh its vertex arrays, then the views; materials; images.
    std::vector<DeviceBuffer> meshArrays;
    DeviceBuffer meshViews, materials, imageViews, instances;
    std::vector<DeviceBuffer> images;
    // The BVH's arrays (BvhArrays order).
    DeviceBuffer nodes, triangles, bvhMeshes, topNodes, topInstances, bvhInstances;
    BvhArrays bottom;  ///< device spans of the arrays built once per scene
    // Lights.
    DeviceBuffer tris, triCdf, instanceTriBase, punctual, envTexels, envMarginal, envConditional;
    // Per frame: the vbuffer and the outputs.
    DeviceBuffer vbuffer, color, direct, indirect, albedo, specAlbedo, emission, primaryHit, counts;
    SceneView scene;  ///< device pointers

    void uploadScene(const SceneView& host, const BvhArrays& bvh) {
        meshArrays.clear();
        meshArrays.reserve(size_t(host.meshCount) * 5);
        std::vector<MeshView> meshes(host.meshes, host.meshes + host.meshCount);
        for (MeshView& m : meshes) {
            uint32_t vertices = 0;  // the views hold no vertex count: the largest index says it
            for (uint32_t i = 0; i < m.triangleCount * 3; ++i) vertices = std::max(vertices, m.indices[i] + 1);
            const auto put = [&](auto* data, size_t count) {
                meshArrays.emplace_back();
                return meshArrays.back().upload(data, count);
            };
            m.positions = put(m.positions, vertices);
            m.normals = put(m.normals, vertices);
            m.tangents = put(m.tangents, vertices);
            m.uvs = put(m.uvs, vertices);
            m.indices = put(m.indices, size_t(m.triangleCount) * 3);
        }
        images.clear();
        images.reserve(host.imageCount);
        std::vector<ImageView8> imgs(host.images, host.images + host.imageCount);
        for (ImageView8& im : imgs) {
            images.emplace_back();
            im.texels = images.back().upload(im.texels, size_t(im.width) * im.height);
        }
        scene = host;
        scene.meshes = meshViews.upload(meshes.data(), meshes.size());
        scene.materials = materials.upload(host.materials, host.materialCount);
        scene.images = imageViews.upload(imgs.data(), imgs.size());
        bottom.nodes = uploadSpan(nodes, bvh.nodes);
        bottom.triangles = uploadSpan(triangles, bvh.triangles);
        bottom.meshes = uploadSpan(bvhMeshes, bvh.meshes);
    }

    LightsView uploadLights(const LightsView& h, uint32_t instanceCount) {
        LightsView d = h;
        d.tris = tris.upload(h.tris, h.triCount);
        d.triCdf = triCdf.upload(h.triCdf, h.tris ? size_t(h.triCount) + 1 : 0);
        d.instanceTriBase = instanceTriBase.upload(h.instanceTriBase, instanceCount);
        d.punctual = punctual.upload(h.punctual, h.punctualCount);
        if (h.env.texels) {
            const size_t w = h.env.width, ht = h.env.height;
            d.env.texels = envTexels.upload(h.env.texels, w * ht);
            d.env.marginalCdf = envMarginal.upload(h.env.marginalCdf, ht + 1);
            d.env.conditionalCdf = envConditional.upload(h.env.conditionalCdf, ht * (w + 1));
        }
        return d;
    }

    template <class T>
    PixelOut<T> output(DeviceBuffer& b, const PixelOut<T>& host, uint32_t w, uint32_t h) {
        if (!host.data) return {};
        return {static_cast<T*>(b.reserve(size_t(w) * h * sizeof(T))), w};
    }

    template <class T>
    void copyBack(const PixelOut<T>& host, const PixelOut<T>& device, uint32_t w, uint32_t h) {
        if (!host.data) return;
        check(cudaMemcpy2D(host.data, size_t(host.pitch) * sizeof(T), device.data, size_t(w) * sizeof(T),
                           size_t(w) * sizeof(T), h, cudaMemcpyDeviceToHost),
              "cudaMemcpy2D (to the host)");
    }
};

CudaBackend::CudaBackend() : mImpl(std::make_unique<Impl>()) {}
CudaBackend::~CudaBackend() = default;

void CudaBackend::render(const FrameKernel& k, uint64_t sceneKey) {
    Impl& m = *mImpl;
    const BvhArrays& arrays = k.bvh.bvh;
    if (m.sceneKey != sceneKey) {
        m.sceneKey = ~uint64_t(0);  // until the upload completes
        m.uploadScene(k.scene, arrays);
        m.sceneKey = sceneKey;
    }
    FrameKernel d = k;
    d.scene = m.scene;
    d.scene.instances = m.instances.upload(k.scene.instances, k.scene.instanceCount);
    d.bvh.scene = d.scene;
    d.bvh.bvh = m.bottom;
    d.bvh.bvh.topNodes = uploadSpan(m.topNodes, arrays.topNodes);
    d.bvh.bvh.topInstances = uploadSpan(m.topInstances, arrays.topInstances);
    d.bvh.bvh.instances = uploadSpan(m.bvhInstances, arrays.instances);
    d.lights = m.uploadLights(k.lights, k.scene.instanceCount);
    const uint32_t w = k.width, h = k.height;
    if (k.vbuffer) {
        void* vb = m.vbuffer.reserve(size_t(w) * h * sizeof(glm::uvec4));
        check(cudaMemcpy2D(vb, size_t(w) * sizeof(glm::uvec4), k.vbuffer, size_t(k.vbufferPitch) * sizeof(glm::uvec4),
                           size_t(w) * sizeof(glm::uvec4), h, cudaMemcpyHostToDevice),
              "cudaMemcpy2D (vbuffer to the device)");
        d.vbuffer = static_cast<const glm::uvec4*>(vb);
        d.vbufferPitch = w;
    }
    d.color = m.output(m.color, k.color, w, h);
    d.direct = m.output(m.direct, k.direct, w, h);
    d.indirect = m.output(m.indirect, k.indirect, w, h);
    d.albedo = m.output(m.albedo, k.albedo, w, h);
    d.specAlbedo = m.output(m.specAlbedo, k.specAlbedo, w, h);
    d.emission = m.output(m.emission, k.emission, w, h);
    d.primaryHit = m.output(m.primaryHit, k.primaryHit, w, h);
    d.counts = m.output(m.counts, k.counts, w, h);

    const dim3 block(16, 8), grid((w + block.x - 1) / block.x, (h + block.y - 1) / block.y);
    renderFrame<<<grid, block>>>(d);
    check(cudaGetLastError(), "the renderPixel launch");
    check(cudaDeviceSynchronize(), "the renderPixel kernel");

    m.copyBack(k.color, d.color, w, h);
    m.copyBack(k.direct, d.direct, w, h);
    m.copyBack(k.indirect, d.indirect, w, h);
    m.copyBack(k.albedo, d.albedo, w, h);
    m.copyBack(k.specAlbedo, d.specAlbedo, w, h);
    m.copyBack(k.emission, d.emission, w, h);
    m.copyBack(k.primaryHit, d.primaryHit, w, h);
    m.copyBack(k.counts, d.counts, w, h);
}

}  // namespace loom::pt
