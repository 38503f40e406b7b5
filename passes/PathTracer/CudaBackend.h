#pragma once
// The path tracer's CUDA backend: the launch glue around PixelKernel.h. It copies the scene (meshes, materials,
// images), the BVH and the lights into device memory, runs renderPixel for every pixel (one thread each), and
// copies the outputs into the graph's textures, which live in host memory (that copy counts in the pass's time).
// Everything that decides a pixel's value is in PixelKernel.h, which the tests run on the host; what is here is
// memory copies and one launch. Built by nvcc when CMake finds the CUDA toolkit (LOOM_CUDA); without it
// CudaBackendStub.cpp says so.
#include <cstdint>
#include <memory>
#include <string>

#include "PixelKernel.h"

namespace loom::pt {

/// Whether this process can run the backend: a build with it, a driver and a device.
struct CudaDeviceStatus {
    bool usable = false;
    std::string description;  ///< the device ("NVIDIA H200, compute 9.0, 139 GiB"), or why there is none
};

/// Probes once per process (the driver's answer does not change) and returns the same status after.
const CudaDeviceStatus& cudaDeviceStatus();

class CudaBackend {
public:
    CudaBackend();
    ~CudaBackend();
    CudaBackend(const CudaBackend&) = delete;
    CudaBackend& operator=(const CudaBackend&) = delete;

    /// Renders one frame. `k` holds host pointers (scene views, BVH arrays, lights, vbuffer, outputs); what the
    /// device lacks of them is copied first: the meshes, materials, images and bottom-level BVHs when `sceneKey`
    /// differs from the last frame's (a scene or geometry change), the instances, top-level BVH and lights every
    /// frame (small). The outputs are copied back into k's host images. Throws loom::Error (Runtime) naming the
    /// CUDA call that failed.
    void render(const FrameKernel& k, uint64_t sceneKey);

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

}  // namespace loom::pt
