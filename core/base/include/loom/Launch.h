#pragma once
// The one launch primitive of per-pixel work (docs/KERNELS.md): a LOOM_HD functor f(x, y) over width x height
// pixels, on the CPU's threads (parallelFor2D's tiles; cpu and emulated) or as a CUDA grid (cuda), from the same
// source. A pass's source file that launches on CUDA is compiled by nvcc where the toolkit is found; compiled by
// the host compiler, a launch on cuda is refused with an error (the pass declares which devices it runs on).
//
// Reductions are deterministic and the same on every device: each row is reduced left to right, then the rows top
// to bottom, in the functor's own arithmetic (reduceRows).
#include <cstdint>
#include <string>
#include <vector>

#include "loom/Device.h"
#include "loom/Error.h"
#include "loom/Kernel.h"
#include "loom/Parallel.h"

#if defined(__CUDACC__)
#include <cuda_runtime.h>
#endif

namespace loom {

namespace detail {

[[noreturn]] inline void launchRefused(const char* what) {
    throw Error(Error::Info{ErrorKind::Runtime, {}, "device",
                            std::string(what) + " on the cuda device, from code not compiled for it",
                            "passes that run on cuda compile their launches with nvcc (LOOM_CUDA)",
                            "place the pass on cpu or emulated"});
}

#if defined(__CUDACC__)
template <class F>
__global__ void launch2DKernel(uint32_t width, uint32_t height, F f) {
    const uint32_t x = blockIdx.x * blockDim.x + threadIdx.x, y = blockIdx.y * blockDim.y + threadIdx.y;
    if (x < width && y < height) f(x, y);
}

template <class T, class RowFn>
__global__ void reduceRowsKernel(uint32_t height, T* rows, RowFn rowFn) {
    const uint32_t y = blockIdx.x * blockDim.x + threadIdx.x;
    if (y < height) rows[y] = rowFn(y);
}

inline void checkCuda(cudaError_t e, const char* what) {
    if (e != cudaSuccess)
        throw Error(Error::Info{ErrorKind::Runtime, {}, "device", std::string(what) + ": " + cudaGetErrorString(e), {},
                                "check the GPU and its driver (nvidia-smi)"});
}
#endif

}  // namespace detail

/// Whether the launches of the source file that asks reach `device`: cpu and emulated always, cuda where nvcc
/// compiled the file (CMake's loom_device_sources). Internal linkage: each file answers for how it was compiled.
static inline bool launchesReach(DeviceKind device) {
#if defined(__CUDACC__)
    (void)device;
    return true;
#else
    return device != DeviceKind::Cuda;
#endif
}

/// Runs f(x, y) once for every pixel of width x height on `device`. f writes only its own pixel (so the result is
/// the same for any thread count and on every device) and is a LOOM_HD functor over plain values and ImageViews.
template <class F>
void launch2D(DeviceKind device, uint32_t width, uint32_t height, const F& f) {
    if (width == 0 || height == 0) return;
    if (device == DeviceKind::Cuda) {
#if defined(__CUDACC__)
        const dim3 block(16, 16), grid((width + 15) / 16, (height + 15) / 16);
        detail::launch2DKernel<<<grid, block>>>(width, height, f);
        detail::checkCuda(cudaGetLastError(), "a kernel launch");
        detail::checkCuda(cudaDeviceSynchronize(), "a kernel");
        return;
#else
        detail::launchRefused("a kernel launch");
#endif
    }
    parallelFor2D(width, height, [&](const Tile& t) {
        for (uint32_t y = t.y0; y < t.y1; ++y)
            for (uint32_t x = t.x0; x < t.x1; ++x) f(x, y);
    });
}

/// The sum (by `combine`, starting from `zero`) of value(x, y) over width x height, reduced row by row: each row
/// left to right, then the rows top to bottom. The order is fixed, so the result is the same for any thread count
/// and on every device. T is a plain value type; value and combine are LOOM_HD functors. value is called exactly
/// once a pixel, so it may also write that pixel's outputs: a kernel that counts what it did (skipped samples,
/// clipped history) is one reduceRows, not a launch2D and a second pass.
template <class T, class Value, class Combine>
T reduceRows(DeviceKind device, uint32_t width, uint32_t height, T zero, const Value& value, const Combine& combine) {
    const auto rowSum = [=] LOOM_HD(uint32_t y) {
        T s = zero;
        for (uint32_t x = 0; x < width; ++x) s = combine(s, value(x, y));
        return s;
    };
    std::vector<T> rows(height, zero);
    if (device == DeviceKind::Cuda) {
#if defined(__CUDACC__)
        T* d = nullptr;
        detail::checkCuda(cudaMalloc(&d, sizeof(T) * height), "cudaMalloc");
        detail::reduceRowsKernel<<<(height + 127) / 128, 128>>>(height, d, rowSum);
        cudaError_t e = cudaGetLastError();
        if (e == cudaSuccess) e = cudaMemcpy(rows.data(), d, sizeof(T) * height, cudaMemcpyDeviceToHost);
        cudaFree(d);
        detail::checkCuda(e, "a row reduction");
#else
        detail::launchRefused("a reduction");
#endif
    } else {
        parallelFor2D(1, height, [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y) rows[y] = rowSum(y);
        });
    }
    T total = zero;
    for (const T& r : rows) total = combine(total, r);
    return total;
}

}  // namespace loom
