// Compile-only check (nvcc -x cu): the reference a-trous level of SVGF (AtrousKernels.h) is device code.
#include "../AtrousKernels.h"

__global__ void atrousLevel(loom::ImageView<const glm::vec4> illum, loom::ImageView<const glm::vec2> linearZ,
                            loom::ImageView<const glm::vec4> normal, loom::ImageView<glm::vec4> out, int step) {
    const loom::svgf::AtrousParams params;
    out.at(threadIdx.x, blockIdx.x) =
        loom::svgf::atrousPixel(illum, linearZ, normal, int(threadIdx.x), int(blockIdx.x), step, params);
}
