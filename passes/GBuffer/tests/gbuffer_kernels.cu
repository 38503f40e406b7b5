// Compile-only check (nvcc -x cu): the G-buffer kernel header is device code.
#include "../GBufferKernels.h"

__global__ void gbuffer(loom::SceneView scene, loom::CameraData cam, loom::gbuffer::GBufferSample* out) {
    out[threadIdx.x] = threadIdx.x % 2 ? loom::gbuffer::hitSample(scene, cam, threadIdx.x, 0, 0, 0, 0.25f, 0.25f)
                                       : loom::gbuffer::missSample(cam, loom::pixelRayDir(cam, threadIdx.x, 0));
}

// GBufferRT's pixel off the CPU: the camera ray through the BVH, stored into the channels' views.
__global__ void traced(loom::BvhView bvh, loom::CameraData cam, loom::gbuffer::GBufferViews views) {
    const uint32_t x = threadIdx.x, y = blockIdx.x;
    loom::gbuffer::storeSample(views, x, y, loom::gbuffer::tracedSample<true>(bvh, cam, x, y, loom::kRayAlphaTest, true, 3));
    loom::gbuffer::storeSample(views, x, y, loom::gbuffer::tracedSample<false>(bvh, cam, x, y, 0u, false, 3));
}
