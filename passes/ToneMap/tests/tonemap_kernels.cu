// Compile-only check (nvcc -x cu): the tone-mapping kernel header is device code.
#include "../ToneMapKernels.h"

__global__ void toneMap(const loom::SrgbEncodeTable* table, const glm::vec4* src, uint32_t* dst, float* logLum) {
    using namespace loom::tonemap;
    ToneMapParams p;
    p.op = Operator::Hable;
    const glm::vec4 mapped = toneMapPixel(p, src[threadIdx.x]);
    dst[threadIdx.x] = packSrgb8(*table, mapped);
    float term = 0.f;
    if (logLuminance(src[threadIdx.x], term)) logLum[threadIdx.x] = term;
}
