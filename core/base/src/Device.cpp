#include "loom/Device.h"

#include <fmt/format.h>

#include <cstring>
#include <new>

#include "DeviceCuda.h"
#include "loom/Error.h"
#include "loom/PageMemory.h"
#include "loom/Texture.h"

namespace loom {

const char* deviceName(DeviceKind device) {
    switch (device) {
        case DeviceKind::Cpu:
            return "cpu";
        case DeviceKind::Cuda:
            return "cuda";
        case DeviceKind::Emulated:
            return "emulated";
    }
    return "?";
}

std::optional<DeviceKind> parseDeviceKind(std::string_view name) {
    for (DeviceKind d : {DeviceKind::Cpu, DeviceKind::Cuda, DeviceKind::Emulated})
        if (name == deviceName(d)) return d;
    return std::nullopt;
}

const CudaStatus& cudaStatus() {
    static const CudaStatus status = detail::queryCudaStatus();
    return status;
}

namespace {

[[noreturn]] void outOfMemory(DeviceKind device, size_t bytes, const std::string& what) {
    throw Error(Error::Info{ErrorKind::BadInput,
                            {},
                            what,
                            fmt::format("the {} device has no {} bytes ({:.1f} MiB) left for {}", deviceName(device),
                                        bytes, double(bytes) / double(1 << 20), what),
                            "enough device memory for the graph's fields",
                            "render at a smaller size, or place some passes on another device"});
}

}  // namespace

std::shared_ptr<std::byte> allocateOnDevice(DeviceKind device, size_t bytes, const std::string& what) {
    if (device == DeviceKind::Cuda) {
        if (!cudaStatus().usable)
            throw Error(Error::Info{ErrorKind::BadInput, {}, what,
                                    std::string("the cuda device was asked for, and ") + cudaStatus().description,
                                    "a usable NVIDIA GPU with its driver, in a build with CUDA support",
                                    "use device auto (CUDA where usable, else the CPU), cpu or emulated"});
        std::byte* p = detail::cudaAllocate(bytes);
        if (!p) outOfMemory(device, bytes, what);
        return std::shared_ptr<std::byte>(p, [](std::byte* q) { detail::cudaRelease(q); });
    }
    // cpu, and emulated: host memory of its own, reached through device views and transfers only.
    try {
        auto memory = std::make_shared<PageMemory>(bytes);
        std::byte* data = memory->data();
        return std::shared_ptr<std::byte>(memory, data);
    } catch (const std::bad_alloc&) {
        outOfMemory(device, bytes, what);
    }
}

void copyTexture(Texture& dst, const Texture& src) {
    if (dst.width() != src.width() || dst.height() != src.height() || dst.format() != src.format())
        throw Error(Error::Info{ErrorKind::Runtime, {}, "copyTexture",
                                fmt::format("cannot copy a {}x{} {} texture into a {}x{} {} one", src.width(),
                                            src.height(), formatName(src.format()), dst.width(), dst.height(),
                                            formatName(dst.format())),
                                "textures of one size and format", {}});
    if (dst.byteSize() == 0 || dst.data() == src.data()) return;
    const size_t rowBytes = size_t(dst.width()) * formatInfo(dst.format()).bytesPerPixel;
    const bool dstCuda = dst.residence() == DeviceKind::Cuda, srcCuda = src.residence() == DeviceKind::Cuda;
    if (dstCuda || srcCuda) {
        detail::cudaCopy2D(dst.data(), dst.rowPitch(), dstCuda, src.data(), src.rowPitch(), srcCuda, rowBytes,
                           dst.height());
        return;
    }
    for (uint32_t y = 0; y < dst.height(); ++y)
        std::memmove(dst.data() + dst.rowPitch() * y, src.data() + src.rowPitch() * y, rowBytes);
}

}  // namespace loom
