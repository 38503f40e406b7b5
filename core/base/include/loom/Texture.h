#pragma once
// A 2D image with 64-byte aligned rows, in host memory or on a device (loom/Device.h), and typed views of it.
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>

#include "loom/Device.h"
#include "loom/Format.h"
#include "loom/Kernel.h"

namespace loom {

inline constexpr size_t kRowAlignment = 64;

inline constexpr size_t alignUp(size_t v, size_t a) { return (v + a - 1) / a * a; }

/// Byte size of a texture of this shape, rows padded to kRowAlignment.
inline size_t textureByteSize(uint32_t width, uint32_t height, Format f) {
    return alignUp(size_t(width) * formatInfo(f).bytesPerPixel, kRowAlignment) * height;
}

/// Plain non-owning typed view: what per-pixel kernels see. Copyable, no
/// virtuals, usable from CUDA code.
template <class T>
struct ImageView {
    T* data = nullptr;
    uint32_t width = 0;
    uint32_t height = 0;
    size_t rowPitch = 0;  ///< bytes between rows

    LOOM_HD T* row(uint32_t y) const {
        using Byte = std::conditional_t<std::is_const_v<T>, const std::byte, std::byte>;
        return reinterpret_cast<T*>(reinterpret_cast<Byte*>(data) + rowPitch * y);
    }
    LOOM_HD T& at(uint32_t x, uint32_t y) const { return row(y)[x]; }
};

/// Throws loom::Error (runtime): host code asked for a host view of a texture on `device`.
[[noreturn]] void throwHostViewOfDeviceTexture(DeviceKind device);

/// A 2D image. Either owns its memory or views memory owned elsewhere (a
/// transient arena of a compiled graph). Non-copyable: copying pixels is
/// explicit (copyFrom, or copyTexture across devices).
///
/// Residence: host memory (cpu) by default. A texture on a device is reached
/// only through deviceView() (kernels launched on that device) and
/// copyTexture(); view(), row(), data() and texel() are for host textures, and
/// view() throws for a device texture, so a pass that reads device memory
/// without a transfer fails where it does so (on the emulated device too).
class Texture {
public:
    Texture() = default;
    /// Allocates zero-filled, 64-byte aligned host memory.
    Texture(uint32_t width, uint32_t height, Format format);
    /// Allocates zero-filled memory on `device`; `what` names it in an out-of-memory error.
    static Texture onDevice(DeviceKind device, uint32_t width, uint32_t height, Format format,
                            const std::string& what = "a texture");
    /// Views external memory of at least textureByteSize() bytes, residing on `device`.
    static Texture wrap(std::byte* memory, uint32_t width, uint32_t height, Format format,
                        DeviceKind device = DeviceKind::Cpu);

    Texture(const Texture&) = delete;
    Texture& operator=(const Texture&) = delete;
    Texture(Texture&& o) noexcept { *this = std::move(o); }
    Texture& operator=(Texture&& o) noexcept {
        mWidth = std::exchange(o.mWidth, 0);
        mHeight = std::exchange(o.mHeight, 0);
        mFormat = o.mFormat;
        mRowPitch = std::exchange(o.mRowPitch, 0);
        mData = std::exchange(o.mData, nullptr);
        mOwner = std::move(o.mOwner);
        mResidence = o.mResidence;
        return *this;
    }

    uint32_t width() const { return mWidth; }
    uint32_t height() const { return mHeight; }
    Format format() const { return mFormat; }
    size_t rowPitch() const { return mRowPitch; }
    size_t byteSize() const { return mRowPitch * mHeight; }
    bool empty() const { return mData == nullptr; }
    /// The device whose memory holds the pixels.
    DeviceKind residence() const { return mResidence; }
    bool onHost() const { return mResidence == DeviceKind::Cpu; }

    std::byte* data() { return mData; }
    const std::byte* data() const { return mData; }
    std::byte* row(uint32_t y) { return mData + mRowPitch * y; }
    const std::byte* row(uint32_t y) const { return mData + mRowPitch * y; }

    /// Typed host view; T's size must equal the format's bytes per pixel. Throws for a device texture.
    template <class T>
    ImageView<T> view() {
        if (mResidence != DeviceKind::Cpu) throwHostViewOfDeviceTexture(mResidence);
        return deviceView<T>();
    }
    template <class T>
    ImageView<const T> view() const {
        if (mResidence != DeviceKind::Cpu) throwHostViewOfDeviceTexture(mResidence);
        return deviceView<T>();
    }
    /// Typed view of the memory wherever it resides: for kernels launched on the texture's device (launch2D).
    template <class T>
    ImageView<T> deviceView() {
        assert(sizeof(T) == formatInfo(mFormat).bytesPerPixel);
        return {reinterpret_cast<T*>(mData), mWidth, mHeight, mRowPitch};
    }
    template <class T>
    ImageView<const T> deviceView() const {
        assert(sizeof(T) == formatInfo(mFormat).bytesPerPixel);
        return {reinterpret_cast<const T*>(mData), mWidth, mHeight, mRowPitch};
    }

    /// Copies pixels from a texture of identical shape and format.
    void copyFrom(const Texture& other);
    /// Sets every byte of the pixel area to zero.
    void clear();
    /// Fills with a poison pattern: quiet NaN for float formats, 0xFFFFFFFF
    /// for uint formats, 0xFF for 8-bit formats.
    void poison();
    /// Reads channel c of pixel (x, y) as float (16-bit and 8-bit converted,
    /// uint values converted numerically). For tests and tools, not kernels.
    float texel(uint32_t x, uint32_t y, uint32_t c) const;
    /// True when the pixel areas are byte-identical (row padding ignored).
    bool samePixels(const Texture& other) const;

private:
    uint32_t mWidth = 0;
    uint32_t mHeight = 0;
    Format mFormat = Format::RGBA32F;
    size_t mRowPitch = 0;
    std::byte* mData = nullptr;
    std::shared_ptr<std::byte> mOwner;  // empty for views
    DeviceKind mResidence = DeviceKind::Cpu;
};

/// Converts IEEE half bits to float and back (round to nearest even).
float halfToFloat(uint16_t h);
uint16_t floatToHalf(float f);

}  // namespace loom
