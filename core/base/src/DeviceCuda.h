#pragma once
// The CUDA runtime calls of the device layer, behind plain functions: DeviceCuda.cu where the CUDA toolkit is found
// (LOOM_HAVE_CUDA), else DeviceNoCuda.cpp, which says the build has no CUDA support.
#include <cstddef>

#include "loom/Device.h"

namespace loom::detail {

CudaStatus queryCudaStatus();
/// Zero-filled device memory, or nullptr when the device has none left; throws loom::Error for other failures.
std::byte* cudaAllocate(size_t bytes);
void cudaRelease(std::byte* memory);
/// A 2D copy of `rows` rows of `rowBytes` bytes between any two of host and CUDA memory; throws loom::Error.
void cudaCopy2D(std::byte* dst, size_t dstPitch, bool dstOnDevice, const std::byte* src, size_t srcPitch,
                bool srcOnDevice, size_t rowBytes, size_t rows);

}  // namespace loom::detail
