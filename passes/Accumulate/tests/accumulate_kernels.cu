// Compile-only check (nvcc -x cu): the accumulation kernel header is device code.
#include "../AccumulateKernels.h"

__global__ void accumulate(loom::accumulate::PixelState* states, const glm::vec4* samples, glm::vec4* out) {
    using namespace loom::accumulate;
    PixelState& s = states[threadIdx.x];
    addSample(Precision::Double, s, samples[threadIdx.x]);
    glm::uvec4 rg, ba;
    packDoubleSum(unpackDoubleSum(glm::uvec4(1u), glm::uvec4(2u)), rg, ba);
    out[threadIdx.x] = blendDenoised(samples[threadIdx.x], mean(Precision::Kahan, s), s.count, 64.f) +
                       sumAsFloat(Precision::Float, s) + glm::vec4(rg);
}
