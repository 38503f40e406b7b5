// The device layer in a build without the CUDA toolkit: every CUDA request is refused, saying why.
#include "DeviceCuda.h"

#include "loom/Error.h"

namespace loom::detail {

namespace {
[[noreturn]] void noCuda() {
    throw Error(Error::Info{ErrorKind::BadInput, {}, "device", "this build has no CUDA support",
                            "a build with the CUDA toolkit installed (LOOM_CUDA=ON)", "use device cpu or emulated"});
}
}  // namespace

CudaStatus queryCudaStatus() {
    return {false, "this build has no CUDA support (build with the CUDA toolkit installed, or LOOM_CUDA=ON)"};
}
std::byte* cudaAllocate(size_t) { noCuda(); }
void cudaRelease(std::byte*) {}
void cudaCopy2D(std::byte*, size_t, bool, const std::byte*, size_t, bool, size_t, size_t) { noCuda(); }

}  // namespace loom::detail
