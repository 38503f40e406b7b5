#pragma once
// The path tracer's CUDA backend: the launch glue around PixelKernel.h. It copies the scene (meshes, materials,
// images), the BVH and the lights into device memory, runs renderPixel for every pixel (one thread each), and
// copies the outputs into the graph's textures, which live in host memory (that copy counts in the pass's time).
// Per-pixel counters and primary hits stay on the device: their sums and the few hits the temporal gradients keep
// are all that comes back.
// Everything that decides a pixel's value is in PixelKernel.h, which the tests run on the host; what is here is
// memory copies and one launch. Built by nvcc when CMake finds the CUDA toolkit (LOOM_CUDA); without it
// NoCudaBackend.cpp says so.
#include <cstdint>
#include <memory>
#include <string>

#include "PixelKernel.h"

namespace loom::pt {

// Whether this process can run the backend is core's loom::cudaStatus() (loom/Device.h).

class CudaBackend {
public:
    CudaBackend();
    ~CudaBackend();
    CudaBackend(const CudaBackend&) = delete;
    CudaBackend& operator=(const CudaBackend&) = delete;

    /// Starts a frame and returns at once, the GPU rendering while the CPU goes on. `k` holds host pointers (scene
    /// views, BVH arrays, lights, vbuffer, outputs); what the device lacks of them is copied first: the meshes,
    /// materials, images and bottom-level BVHs when `sceneKey` differs from the last frame's (a scene or geometry
    /// change), the instances, top-level BVH and lights every frame (small). k.counts and k.primaryHit are not read:
    /// their sums and the gradient blocks' hits come back from finish. Throws loom::Error (Runtime) naming the
    /// CUDA call that failed.
    void launch(const FrameKernel& k, uint64_t sceneKey);

    /// The totals over a frame's pixels of FrameKernel::counts, and the kernel's time.
    struct Counts {
        uint64_t rays = 0, dropped = 0;
        double kernelMs = 0.0;  ///< the kernel's own time on the GPU (CUDA events)
    };
    /// Waits for the frame `launch` started with the same `k`, and copies its outputs into k's host images (through
    /// pinned staging memory, rows in parallel). With `gradientHits` (one per 3x3 block, row-major), also each
    /// block's primary hit at gradientPixel(bx, by, gradientFrame).
    Counts finish(const FrameKernel& k, glm::uvec4* gradientHits, uint64_t gradientFrame);

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

}  // namespace loom::pt
