// The path tracer's CUDA backend in a build without the CUDA toolkit (LOOM_CUDA=OFF, or no nvcc): no device.
#include "CudaBackend.h"
#include "loom/Error.h"

namespace loom::pt {

const CudaDeviceStatus& cudaDeviceStatus() {
    static const CudaDeviceStatus status{
        false, "this build has no CUDA backend (build with the CUDA toolkit installed, or LOOM_CUDA=ON)"};
    return status;
}

struct CudaBackend::Impl {};

CudaBackend::CudaBackend() = default;
CudaBackend::~CudaBackend() = default;

void CudaBackend::launch(const FrameKernel&, uint64_t) {
    throw Error({ErrorKind::Runtime, "", "PathTracer.device", cudaDeviceStatus().description, "", ""});
}

CudaBackend::Counts CudaBackend::finish(const FrameKernel&, glm::uvec4*, uint64_t) {
    throw Error({ErrorKind::Runtime, "", "PathTracer.device", cudaDeviceStatus().description, "", ""});
}

}  // namespace loom::pt
