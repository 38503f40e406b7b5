// The path tracer's CUDA backend: device copies of what PixelKernel.h reads, one launch of renderPixel per frame,
// and (placed on the CPU) the outputs copied back into the graph's host textures, or (placed on cuda) written into
// the pass's device fields. No decision about a pixel is made here.
#include <cuda_runtime.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "CudaBackend.h"
#include "loom/Error.h"
#include "loom/Parallel.h"

namespace loom::pt {

namespace {

[[noreturn]] void fail(const char* call, cudaError_t e) {
    throw Error({ErrorKind::Runtime, "", "PathTracer (CUDA)", std::string(call) + " failed: " + cudaGetErrorString(e),
                 "", "run with device cpu, or check the GPU and its driver (nvidia-smi)"});
}

void check(cudaError_t e, const char* call) {
    if (e != cudaSuccess) fail(call, e);
}

cudaError_t allocateDevice(void** p, size_t bytes) {
    return cudaMalloc(p, bytes);
}
cudaError_t allocatePinned(void** p, size_t bytes) {
    return cudaMallocHost(p, bytes);
}

/// Memory that grows to the largest size asked of it: on the device (cudaMalloc), or page-locked on the host
/// (cudaMallocHost), which the device copies to and from at full speed.
template <cudaError_t (*Allocate)(void**, size_t), cudaError_t (*Release)(void*)>
class GrowingBuffer {
public:
    GrowingBuffer() = default;
    GrowingBuffer(const GrowingBuffer&) = delete;
    GrowingBuffer& operator=(const GrowingBuffer&) = delete;
    GrowingBuffer(GrowingBuffer&& o) noexcept : mPtr(o.mPtr), mSize(o.mSize) {
        o.mPtr = nullptr;
        o.mSize = 0;
    }
    ~GrowingBuffer() {
        if (mPtr) Release(mPtr);
    }
    void* reserve(size_t bytes) {
        if (bytes > mSize) {
            if (mPtr) Release(mPtr);
            mPtr = nullptr;
            mSize = 0;
            check(Allocate(&mPtr, bytes), "a CUDA allocation");
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
using DeviceBuffer = GrowingBuffer<allocateDevice, cudaFree>;
using PinnedBuffer = GrowingBuffer<allocatePinned, cudaFreeHost>;

template <class T>
BvhSpan<T> uploadSpan(DeviceBuffer& b, BvhSpan<T> s) {
    return {b.upload(s.data, s.count), s.count};
}

/// Every pixel's path in rows y0..y1, then its warp's counters summed into sums[0] (rays) and sums[1] (dropped
/// samples): integer sums, the same in any order.
__global__ void renderFrame(FrameKernel k, uint32_t y0, uint32_t y1, unsigned long long* sums) {
    const uint32_t x = blockIdx.x * blockDim.x + threadIdx.x, y = y0 + blockIdx.y * blockDim.y + threadIdx.y;
    uint32_t rays = 0, dropped = 0;
    if (x < k.width && y < y1) {
        renderPixel(k, x, y);
        const glm::uvec2 c = k.counts.data[size_t(y) * k.counts.pitch + x];
        rays = c.x;
        dropped = c.y;
    }
    for (int offset = 16; offset > 0; offset /= 2) {
        rays += __shfl_down_sync(0xffffffffu, rays, offset);
        dropped += __shfl_down_sync(0xffffffffu, dropped, offset);
    }
    if ((threadIdx.y * blockDim.x + threadIdx.x) % 32 == 0) {
        atomicAdd(&sums[0], (unsigned long long)rays);
        atomicAdd(&sums[1], (unsigned long long)dropped);
    }
}

/// Each 3x3 block's primary hit at gradientPixel, row-major.
__global__ void gatherGradientHits(const glm::uvec4* primary, uint32_t w, uint32_t h, uint64_t frame, glm::uvec4* out) {
    const uint32_t bx = blockIdx.x * blockDim.x + threadIdx.x, by = blockIdx.y * blockDim.y + threadIdx.y;
    const uint32_t blocksX = (w + 2) / 3, blocksY = (h + 2) / 3;
    if (bx >= blocksX || by >= blocksY) return;
    const glm::uvec2 q = gradientPixel(bx, by, frame, w, h);
    out[size_t(by) * blocksX + bx] = primary[size_t(q.y) * w + q.x];
}

}  // namespace

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
    DeviceBuffer vbuffer, color, direct, indirect, albedo, specAlbedo, emission, primaryHit, counts, sums, blockHits;
    // Host staging of the outputs, in the order of FrameKernel's (color, direct, indirect, albedo, specAlbedo,
    // emission), then the sums and the gradient blocks' hits.
    PinnedBuffer staged[6], stagedSums, stagedBlockHits, stagedVbuffer;
    SceneView scene;                                         ///< device pointers
    cudaEvent_t kernelStart = nullptr, kernelEnd = nullptr;  ///< around the launches, for Counts::kernelMs
    FrameKernel device;                                      ///< the frame launched: device pointers
    // The frame runs in bands of rows: each band's outputs are copied back (on `copies`) while the next band
    // renders (on `kernels`), and copied into the graph's textures while later ones are still on their way.
    static constexpr int kBands = 4;
    cudaStream_t kernels = nullptr, copies = nullptr;
    cudaEvent_t rendered[kBands] = {}, copied[kBands] = {};
    uint32_t bandRows = 0;
    glm::vec4* stagedOutput[6] = {};  ///< this frame's staging of each output, or null

    /// Rows y0..y1 of band b of a frame `h` rows high (empty past the last row).
    std::pair<uint32_t, uint32_t> band(int b, uint32_t h) const {
        const uint32_t y0 = std::min(h, uint32_t(b) * bandRows);
        return {y0, std::min(h, y0 + bandRows)};
    }

    void createStreams() {
        if (kernels) return;
        check(cudaStreamCreate(&kernels), "cudaStreamCreate");
        check(cudaStreamCreate(&copies), "cudaStreamCreate");
        check(cudaEventCreate(&kernelStart), "cudaEventCreate");
        check(cudaEventCreate(&kernelEnd), "cudaEventCreate");
        for (int b = 0; b < kBands; ++b) {
            check(cudaEventCreateWithFlags(&rendered[b], cudaEventDisableTiming), "cudaEventCreate");
            check(cudaEventCreateWithFlags(&copied[b], cudaEventDisableTiming), "cudaEventCreate");
        }
    }

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

    /// `k` with device copies of its scene, BVH and lights: the meshes, materials, images and bottom-level BVHs
    /// uploaded when `sceneKey` differs from the last frame's, the rest every frame.
    FrameKernel prepare(const FrameKernel& k, uint64_t sceneKey);

    template <class T>
    PixelOut<T> output(DeviceBuffer& b, const PixelOut<T>& host, uint32_t w, uint32_t h) {
        if (!host.data) return {};
        return {static_cast<T*>(b.reserve(size_t(w) * h * sizeof(T))), w};
    }
};

CudaBackend::CudaBackend() : mImpl(std::make_unique<Impl>()) {}
CudaBackend::~CudaBackend() {
    Impl& m = *mImpl;
    if (!m.kernels) return;
    cudaStreamSynchronize(m.kernels);
    cudaStreamSynchronize(m.copies);
    for (cudaEvent_t e : {m.kernelStart, m.kernelEnd}) cudaEventDestroy(e);
    for (int b = 0; b < Impl::kBands; ++b) {
        cudaEventDestroy(m.rendered[b]);
        cudaEventDestroy(m.copied[b]);
    }
    cudaStreamDestroy(m.kernels);
    cudaStreamDestroy(m.copies);
}

bool CudaBackend::compiled() {
    return true;
}

namespace {

/// Block (bx, by)'s temporal gradient (replayGradient), its rays summed into sums[0] per warp.
__global__ void replayGradients(FrameKernel k, GradientReplay g, uint32_t blocksX, uint32_t blocksY,
                                unsigned long long* sums) {
    const uint32_t bx = blockIdx.x * blockDim.x + threadIdx.x, by = blockIdx.y * blockDim.y + threadIdx.y;
    uint32_t rays = 0;
    if (bx < blocksX && by < blocksY) rays = replayGradient(k, g, bx, by);
    for (int offset = 16; offset > 0; offset /= 2) rays += __shfl_down_sync(0xffffffffu, rays, offset);
    if ((threadIdx.y * blockDim.x + threadIdx.x) % 32 == 0) atomicAdd(&sums[0], (unsigned long long)rays);
}

}  // namespace

FrameKernel CudaBackend::Impl::prepare(const FrameKernel& k, uint64_t sceneKey) {
    Impl& m = *this;
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
    return d;
}

CudaBackend::Counts CudaBackend::render(const FrameKernel& k, const GradientReplay* replay, uint64_t sceneKey) {
    Impl& m = *mImpl;
    FrameKernel d = m.prepare(k, sceneKey);
    const uint32_t w = k.width, h = k.height;
    d.counts = {static_cast<glm::uvec2*>(m.counts.reserve(size_t(w) * h * sizeof(glm::uvec2))), w};
    auto* sums = static_cast<unsigned long long*>(m.sums.reserve(2 * sizeof(unsigned long long)));
    check(cudaMemsetAsync(sums, 0, 2 * sizeof(unsigned long long)), "cudaMemsetAsync");
    m.createStreams();
    // Everything on the legacy default stream, after the uploads above: the graph's next pass on the device reads
    // the fields once this returns.
    const dim3 block(16, 8);
    check(cudaEventRecord(m.kernelStart, 0), "cudaEventRecord");
    renderFrame<<<dim3((w + block.x - 1) / block.x, (h + block.y - 1) / block.y), block>>>(d, 0, h, sums);
    check(cudaGetLastError(), "the renderPixel launch");
    if (replay) {
        const uint32_t blocksX = (w + 2) / 3, blocksY = (h + 2) / 3;
        replayGradients<<<dim3((blocksX + block.x - 1) / block.x, (blocksY + block.y - 1) / block.y), block>>>(
            d, *replay, blocksX, blocksY, sums);
        check(cudaGetLastError(), "the gradients' launch");
    }
    check(cudaEventRecord(m.kernelEnd, 0), "cudaEventRecord");
    unsigned long long host[2] = {0, 0};
    check(cudaMemcpy(host, sums, sizeof(host), cudaMemcpyDeviceToHost), "the renderPixel kernel");
    float kernelMs = 0.f;
    check(cudaEventElapsedTime(&kernelMs, m.kernelStart, m.kernelEnd), "cudaEventElapsedTime");
    return {host[0], host[1], double(kernelMs)};
}

void CudaBackend::launch(const FrameKernel& k, uint64_t sceneKey) {
    Impl& m = *mImpl;
    FrameKernel d = m.prepare(k, sceneKey);
    const uint32_t w = k.width, h = k.height;
    if (k.vbuffer) {
        // Through page-locked staging (rows copied in parallel): a copy from pageable memory runs at a third of
        // the speed.
        const size_t bytes = size_t(w) * h * sizeof(glm::uvec4);
        auto* staged = static_cast<glm::uvec4*>(m.stagedVbuffer.reserve(bytes));
        parallelFor2D(
            w, h,
            [&](const Tile& t) {
                for (uint32_t y = t.y0; y < t.y1; ++y)
                    std::memcpy(staged + size_t(y) * w, k.vbuffer + size_t(y) * k.vbufferPitch,
                                size_t(w) * sizeof(glm::uvec4));
            },
            w, 16);
        void* vb = m.vbuffer.reserve(bytes);
        check(cudaMemcpyAsync(vb, staged, bytes, cudaMemcpyHostToDevice), "cudaMemcpyAsync (vbuffer to the device)");
        d.vbuffer = static_cast<const glm::uvec4*>(vb);
        d.vbufferPitch = w;
    }
    d.color = m.output(m.color, k.color, w, h);
    d.direct = m.output(m.direct, k.direct, w, h);
    d.indirect = m.output(m.indirect, k.indirect, w, h);
    d.albedo = m.output(m.albedo, k.albedo, w, h);
    d.specAlbedo = m.output(m.specAlbedo, k.specAlbedo, w, h);
    d.emission = m.output(m.emission, k.emission, w, h);
    d.primaryHit = {static_cast<glm::uvec4*>(m.primaryHit.reserve(size_t(w) * h * sizeof(glm::uvec4))), w};
    d.counts = {static_cast<glm::uvec2*>(m.counts.reserve(size_t(w) * h * sizeof(glm::uvec2))), w};
    auto* sums = static_cast<unsigned long long*>(m.sums.reserve(2 * sizeof(unsigned long long)));
    check(cudaMemsetAsync(sums, 0, 2 * sizeof(unsigned long long)), "cudaMemsetAsync");
    m.createStreams();
    // Bands of whole 8-row thread blocks; each band's outputs go to page-locked staging behind it.
    const dim3 block(16, 8);
    m.bandRows = ((h + Impl::kBands - 1) / Impl::kBands + block.y - 1) / block.y * block.y;
    const PixelOut<glm::vec4> devOut[6] = {d.color, d.direct, d.indirect, d.albedo, d.specAlbedo, d.emission};
    for (int i = 0; i < 6; ++i)
        m.stagedOutput[i] =
            devOut[i].data ? static_cast<glm::vec4*>(m.staged[i].reserve(size_t(w) * h * sizeof(glm::vec4))) : nullptr;
    // The uploads above ran on the legacy default stream, which these (blocking) streams wait for.
    check(cudaEventRecord(m.kernelStart, m.kernels), "cudaEventRecord");
    for (int b = 0; b < Impl::kBands; ++b) {
        const auto [y0, y1] = m.band(b, h);
        if (y0 < y1) {
            const dim3 grid((w + block.x - 1) / block.x, (y1 - y0 + block.y - 1) / block.y);
            renderFrame<<<grid, block, 0, m.kernels>>>(d, y0, y1, sums);
            check(cudaGetLastError(), "the renderPixel launch");
        }
        check(cudaEventRecord(m.rendered[b], m.kernels), "cudaEventRecord");
        check(cudaStreamWaitEvent(m.copies, m.rendered[b], 0), "cudaStreamWaitEvent");
        const size_t offset = size_t(y0) * w, bytes = size_t(y1 - y0) * w * sizeof(glm::vec4);
        for (int i = 0; i < 6; ++i)
            if (m.stagedOutput[i] && bytes)
                check(cudaMemcpyAsync(m.stagedOutput[i] + offset, devOut[i].data + offset, bytes,
                                      cudaMemcpyDeviceToHost, m.copies),
                      "cudaMemcpyAsync (outputs)");
        check(cudaEventRecord(m.copied[b], m.copies), "cudaEventRecord");
    }
    check(cudaEventRecord(m.kernelEnd, m.kernels), "cudaEventRecord");
    m.device = d;
}

CudaBackend::Counts CudaBackend::finish(const FrameKernel& k, glm::uvec4* gradientHits, uint64_t gradientFrame) {
    Impl& m = *mImpl;
    const FrameKernel& d = m.device;
    const uint32_t w = k.width, h = k.height;
    const uint32_t blocksX = (w + 2) / 3, blocksY = (h + 2) / 3;
    const PixelOut<glm::vec4> hostOut[6] = {k.color, k.direct, k.indirect, k.albedo, k.specAlbedo, k.emission};
    auto* sums = static_cast<unsigned long long*>(m.stagedSums.reserve(2 * sizeof(unsigned long long)));
    glm::uvec4* hits = nullptr;
    if (gradientHits) {
        const size_t bytes = size_t(blocksX) * blocksY * sizeof(glm::uvec4);
        auto* dHits = static_cast<glm::uvec4*>(m.blockHits.reserve(bytes));
        const dim3 block(16, 8), grid((blocksX + block.x - 1) / block.x, (blocksY + block.y - 1) / block.y);
        gatherGradientHits<<<grid, block, 0, m.kernels>>>(d.primaryHit.data, w, h, gradientFrame, dHits);
        check(cudaGetLastError(), "the gradient hits' launch");
        hits = static_cast<glm::uvec4*>(m.stagedBlockHits.reserve(bytes));
        check(cudaMemcpyAsync(hits, dHits, bytes, cudaMemcpyDeviceToHost, m.kernels), "cudaMemcpyAsync (hits)");
    }
    check(cudaMemcpyAsync(sums, m.sums.reserve(0), 2 * sizeof(unsigned long long), cudaMemcpyDeviceToHost, m.kernels),
          "cudaMemcpyAsync (counts)");
    // Each band into the graph's textures (whose rows may be padded) as soon as it has arrived, rows in parallel.
    for (int b = 0; b < Impl::kBands; ++b) {
        check(cudaEventSynchronize(m.copied[b]), "the renderPixel kernel");
        const std::pair<uint32_t, uint32_t> rows = m.band(b, h);
        const uint32_t y0 = rows.first, y1 = rows.second;
        if (y0 == y1) continue;
        parallelFor2D(
            w, y1 - y0,
            [&](const Tile& t) {
                for (int i = 0; i < 6; ++i)
                    if (m.stagedOutput[i])
                        for (uint32_t y = y0 + t.y0; y < y0 + t.y1; ++y)
                            std::memcpy(hostOut[i].data + size_t(y) * hostOut[i].pitch,
                                        m.stagedOutput[i] + size_t(y) * w, size_t(w) * sizeof(glm::vec4));
            },
            w, 16);
    }
    check(cudaStreamSynchronize(m.kernels), "the gradient hits' kernel");
    if (hits) std::memcpy(gradientHits, hits, size_t(blocksX) * blocksY * sizeof(glm::uvec4));
    float kernelMs = 0.f;
    check(cudaEventElapsedTime(&kernelMs, m.kernelStart, m.kernelEnd), "cudaEventElapsedTime");
    return {sums[0], sums[1], double(kernelMs)};
}

}  // namespace loom::pt
