#pragma once
// The path tracer's CUDA backend: the launch glue around PixelKernel.h. It copies the scene (meshes, materials,
// images), the BVH and the lights into device memory and runs renderPixel for every pixel (one thread each). Placed on
// the CPU with `device: cuda`, it copies the outputs into the graph's host textures (launch, finish; that copy
// counts in the pass's time); placed on cuda by the graph, it writes the pass's device fields (render).
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

    /// A frame placed on the cuda device by the graph: k's outputs, vbuffer and gradient history are views of the
    /// pass's fields in device memory, written there and never copied back (scene, BVH and lights are uploaded as
    /// for launch). With `replay`, the temporal gradients too (replayGradient over the 3x3 blocks, after the
    /// frame). Waits for both; the counts include the gradients' rays. Throws loom::Error (Runtime) naming the
    /// CUDA call that failed.
    Counts render(const FrameKernel& k, const GradientReplay* replay, uint64_t sceneKey);

    /// Whether this build has the backend (CudaBackend.cu compiled by nvcc), so the pass can run on cuda.
    static bool compiled();

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

}  // namespace loom::pt
