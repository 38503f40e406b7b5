#pragma once
// Marks functions that per-pixel kernels call, so the same code compiles for
// the CPU and, with nvcc, for CUDA devices. Kernel code uses plain structs and
// views: no virtual calls, exceptions, allocation or STL containers.
#if defined(__CUDACC__)
#define LOOM_HD __host__ __device__
#define GLM_FORCE_CUDA
#else
#define LOOM_HD
#endif

#include <cstdint>
#include <cstring>

namespace loom {
/// The IEEE bits of a float (for packing barycentrics into integer channels).
LOOM_HD inline uint32_t floatBits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
}
LOOM_HD inline float bitsToFloat(uint32_t u) {
    float f;
    std::memcpy(&f, &u, sizeof f);
    return f;
}
}  // namespace loom
