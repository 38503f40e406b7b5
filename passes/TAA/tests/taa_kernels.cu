// Compile-only check (nvcc -x cu): the TAA kernel header is device code.
#include "../TAAKernels.h"

__global__ void resolve(loom::taa::TaaInputs in, loom::taa::TaaParams p, glm::vec4* out) {
    uint32_t flags = 0;
    const uint32_t x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y;
    out[y * in.color.width + x] = loom::taa::resolvePixel(in, p, x, y, flags);
}
