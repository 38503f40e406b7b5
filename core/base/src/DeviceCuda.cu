// The device layer's CUDA runtime calls (built by nvcc where the toolkit is found).
#include <cuda_runtime.h>
#include <dlfcn.h>

#include <string>

#include "DeviceCuda.h"
#include "loom/Error.h"

namespace loom::detail {

namespace {
[[noreturn]] void fail(const char* call, cudaError_t e) {
    throw Error(Error::Info{ErrorKind::Runtime, {}, "device", std::string(call) + " failed: " + cudaGetErrorString(e),
                            {}, "check the GPU and its driver (nvidia-smi)"});
}
}  // namespace

CudaStatus queryCudaStatus() {
    CudaStatus s;
    int count = 0;
    const cudaError_t e = cudaGetDeviceCount(&count);
    if (e != cudaSuccess) {
        // With no NVIDIA driver at all the runtime reports an insufficient driver version: say what is missing.
        if (void* driver = dlopen("libcuda.so.1", RTLD_LAZY | RTLD_LOCAL)) {
            dlclose(driver);
            s.description = std::string("no usable CUDA device (") + cudaGetErrorString(e) + ")";
        } else {
            s.description = "no NVIDIA GPU or driver (libcuda.so.1 cannot be loaded)";
        }
        return s;
    }
    cudaDeviceProp p{};
    if (count == 0 || cudaGetDeviceProperties(&p, 0) != cudaSuccess) {
        s.description = "no NVIDIA GPU found";
        return s;
    }
    s.usable = true;
    s.description = std::string(p.name) + ", compute " + std::to_string(p.major) + "." + std::to_string(p.minor) +
                    ", " + std::to_string(p.totalGlobalMem >> 30) + " GiB";
    return s;
}

std::byte* cudaAllocate(size_t bytes) {
    void* p = nullptr;
    const cudaError_t e = cudaMalloc(&p, bytes);
    if (e == cudaErrorMemoryAllocation) {
        (void)cudaGetLastError();  // clear the sticky-free error so the next call is not blamed
        return nullptr;
    }
    if (e != cudaSuccess) fail("cudaMalloc", e);
    if (const cudaError_t z = cudaMemset(p, 0, bytes); z != cudaSuccess) fail("cudaMemset", z);
    return static_cast<std::byte*>(p);
}

void cudaRelease(std::byte* memory) { cudaFree(memory); }

void cudaCopy2D(std::byte* dst, size_t dstPitch, bool dstOnDevice, const std::byte* src, size_t srcPitch,
                bool srcOnDevice, size_t rowBytes, size_t rows) {
    const cudaMemcpyKind kind = dstOnDevice ? (srcOnDevice ? cudaMemcpyDeviceToDevice : cudaMemcpyHostToDevice)
                                            : (srcOnDevice ? cudaMemcpyDeviceToHost : cudaMemcpyHostToHost);
    if (const cudaError_t e = cudaMemcpy2D(dst, dstPitch, src, srcPitch, rowBytes, rows, kind); e != cudaSuccess)
        fail("cudaMemcpy2D", e);
}

}  // namespace loom::detail
