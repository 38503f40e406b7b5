// The path tracer's CUDA backend in a build without the CUDA toolkit (LOOM_CUDA=OFF, or no nvcc): no device.
#include "CudaBackend.h"
#include "loom/Error.h"

namespace loom::pt {

namespace {
const char* const kNoBackend =
    "this build has no CUDA backend (build with the CUDA toolkit installed, or LOOM_CUDA=ON)";
}  // namespace

struct CudaBackend::Impl {};

CudaBackend::CudaBackend() = default;
CudaBackend::~CudaBackend() = default;

void CudaBackend::launch(const FrameKernel&, uint64_t) {
    throw Error({ErrorKind::Runtime, "", "PathTracer.device", kNoBackend, "", ""});
}

CudaBackend::Counts CudaBackend::finish(const FrameKernel&, glm::uvec4*, uint64_t) {
    throw Error({ErrorKind::Runtime, "", "PathTracer.device", kNoBackend, "", ""});
}

CudaBackend::Counts CudaBackend::render(const FrameKernel&, const GradientReplay*, uint64_t) {
    throw Error({ErrorKind::Runtime, "", "PathTracer.device", kNoBackend, "", ""});
}

bool CudaBackend::compiled() {
    return false;
}

}  // namespace loom::pt
