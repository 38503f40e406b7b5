#pragma once
// Where a pass runs and a field lives (docs/KERNELS.md):
//   cpu       host memory, kernels on the CPU's threads (parallelFor2D);
//   cuda      an NVIDIA GPU's memory, kernels as CUDA grids;
//   emulated  the GPU path without a GPU: memory allocated apart from host memory and reached only through device
//             views and transfers, kernels on the CPU's threads. CI proves placement and transfers with it.
// The graph places each pass on one device and gives each field its pass's device; where a field crosses devices
// it inserts a transfer (copyTexture). No pass copies its own outputs.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

namespace loom {

class Texture;

enum class DeviceKind : uint8_t { Cpu, Cuda, Emulated };

/// "cpu", "cuda" or "emulated".
const char* deviceName(DeviceKind device);
/// The device of a name (cpu, cuda, emulated); nullopt for any other text ("auto" is resolved by the caller).
std::optional<DeviceKind> parseDeviceKind(std::string_view name);

/// Whether a CUDA device can be used here, and the one line that says which or why not ("no NVIDIA GPU or driver
/// ...", "this build has no CUDA support"). Asked once per process.
struct CudaStatus {
    bool usable = false;
    std::string description;
};
const CudaStatus& cudaStatus();

/// `bytes` of zero-filled memory on `device`, 256-byte aligned; throws loom::Error (runtime) when the device has
/// none left, naming `what` (the field) and the bytes. Host memory for cpu; memory kept apart for emulated.
std::shared_ptr<std::byte> allocateOnDevice(DeviceKind device, size_t bytes, const std::string& what);

/// Copies the pixels of `src` into `dst` (same size and format) across any two devices: the one way memory moves
/// between host and device. Throws loom::Error (runtime) on a CUDA failure.
void copyTexture(Texture& dst, const Texture& src);

}  // namespace loom
