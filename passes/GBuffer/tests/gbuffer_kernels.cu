// Compile-only check (nvcc -x cu): the G-buffer kernel header is device code.
#include "../GBufferKernels.h"

__global__ void gbuffer(loom::SceneView scene, loom::CameraData cam, loom::gbuffer::GBufferSample* out) {
    out[threadIdx.x] = threadIdx.x % 2 ? loom::gbuffer::hitSample(scene, cam, threadIdx.x, 0, 0, 0, 0.25f, 0.25f)
                                       : loom::gbuffer::missSample(cam, loom::pixelRayDir(cam, threadIdx.x, 0));
}
