#pragma once
// GBufferRT off the CPU (emulated, or cuda where GBufferRTDevice.cpp is compiled by nvcc): one launch2D of
// tracedSample (GBufferKernels.h) over the frame, the camera rays traversing the scene's BVH (loom/Bvh.h) instead of
// Embree, writing the device views of the pass's outputs (docs/KERNELS.md).
#include <cstdint>
#include <memory>

#include "GBufferKernels.h"
#include "loom/Device.h"

namespace loom::gbuffer::device {

/// Whether the launches below were compiled by nvcc: only then do they run on the cuda device.
bool launchesOnCuda();

/// What one frame's camera rays need besides the scene.
struct TraceParams {
    CameraData cam;
    uint32_t width = 0, height = 0;
    uint32_t rules = 0;  ///< RayRules of the camera rays
    uint32_t frame = 0;  ///< the frame index coverage keys use
    bool keyed = false;  ///< alpha-tested geometry is traced: coverage keys matter
    bool moving = true;  ///< some instance moved since the last frame (hitSample<true>)
};

/// The scene and its BVH where a device's kernels read them. The emulated device runs on the CPU's threads and
/// reads the host's arrays, which are no graph field. On cuda, device copies: meshes, images and the bottom-level
/// BVH are uploaded when the scene key changes (a new scene or BVH), materials, instances and the top-level BVH
/// (a few kilobytes, changed by animation) at every frame.
class DeviceScene {
public:
    DeviceScene();
    ~DeviceScene();
    DeviceScene(const DeviceScene&) = delete;
    DeviceScene& operator=(const DeviceScene&) = delete;

    /// The view of `host` (host arrays and the host SceneView) that kernels on `device` traverse; valid until the
    /// next call. `sceneKey` changes whenever the meshes, images or bottom-level BVH do.
    BvhView view(DeviceKind device, const BvhView& host, uint64_t sceneKey);

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

/// Every pixel's tracedSample stored into `out` (device views of the pass's outputs), on `device`.
void trace(DeviceKind device, const BvhView& scene, const TraceParams& params, const GBufferViews& out);

}  // namespace loom::gbuffer::device
