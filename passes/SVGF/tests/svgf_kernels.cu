// Compile-only check (nvcc -x cu): the SVGF stage kernels (SVGFKernels.h) are device code.
#include "../SVGFKernels.h"

__global__ void svgfTemporal(loom::svgf::TemporalViews tv, loom::svgf::TemporalParams tp, int* rejected) {
    if (loom::svgf::temporalPixel(tv, threadIdx.x, blockIdx.x, tp)) atomicAdd(rejected, 1);
}

__global__ void svgfVariance(loom::svgf::VarianceViews vv, loom::svgf::AtrousParams ap) {
    loom::svgf::varianceEstimatePixel(vv, threadIdx.x, blockIdx.x, loom::svgf::varianceScales(ap), true);
}

__global__ void svgfModulate(loom::svgf::ModulateViews mv) {
    loom::svgf::modulatePixel(mv, threadIdx.x, blockIdx.x, false);
}
