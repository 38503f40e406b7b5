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
