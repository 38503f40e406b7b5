#include "loom/Texture.h"

#include "loom/Error.h"
#include "loom/PageMemory.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <new>
#include <stdexcept>
#include <string>

namespace loom {

namespace {

std::string shapeString(uint32_t width, uint32_t height, Format format) {
    return std::to_string(width) + "x" + std::to_string(height) + " " + std::string(formatName(format));
}

// Fills every 32-bit word of [begin, begin + bytes) with `word`; bytes is a multiple of 4.
void fillWords(std::byte* begin, size_t bytes, uint32_t word) {
    for (size_t i = 0; i + 4 <= bytes; i += 4) std::memcpy(begin + i, &word, 4);
}

}  // namespace

Texture::Texture(uint32_t width, uint32_t height, Format format)
    : mWidth(width), mHeight(height), mFormat(format),
      mRowPitch(alignUp(size_t(width) * formatInfo(format).bytesPerPixel, kRowAlignment)) {
    size_t bytes = mRowPitch * mHeight;
    if (bytes == 0) return;  // a 0-sized texture holds no memory and is empty()
    static_assert(kRowAlignment <= 64, "PageMemory aligns to 64 bytes at least");
    auto memory = std::make_shared<PageMemory>(bytes);
    mData = memory->data();
    mOwner = std::shared_ptr<std::byte>(memory, mData);  // shares the buffer's ownership
}

Texture Texture::onDevice(DeviceKind device, uint32_t width, uint32_t height, Format format, const std::string& what) {
    if (device == DeviceKind::Cpu) return Texture(width, height, format);
    Texture t = wrap(nullptr, width, height, format, device);
    if (t.byteSize() == 0) return t;
    t.mOwner = allocateOnDevice(device, t.byteSize(), what);
    t.mData = t.mOwner.get();
    return t;
}

void throwHostViewOfDeviceTexture(DeviceKind device) {
    throw Error(Error::Info{ErrorKind::Runtime,
                            {},
                            {},
                            std::string("host code read a texture that lives on the ") + deviceName(device) +
                                " device: a pass or tool reached device memory without a transfer",
                            "device memory read only by kernels on its device (deviceView) and by copyTexture",
                            "place the pass on that device, or let the graph insert a transfer"});
}

Texture Texture::wrap(std::byte* memory, uint32_t width, uint32_t height, Format format, DeviceKind device) {
    Texture t;
    t.mResidence = device;
    t.mWidth = width;
    t.mHeight = height;
    t.mFormat = format;
    t.mRowPitch = alignUp(size_t(width) * formatInfo(format).bytesPerPixel, kRowAlignment);
    t.mData = memory;
    return t;
}

void Texture::copyFrom(const Texture& other) {
    if (mResidence != DeviceKind::Cpu || other.mResidence != DeviceKind::Cpu) {
        copyTexture(*this, other);
        return;
    }
    if (other.mWidth != mWidth || other.mHeight != mHeight || other.mFormat != mFormat) {
        throw std::invalid_argument("Texture::copyFrom: cannot copy a " +
                                    shapeString(other.mWidth, other.mHeight, other.mFormat) + " texture into a " +
                                    shapeString(mWidth, mHeight, mFormat) + " texture");
    }
    if (other.mData == mData || byteSize() == 0) return;
    if (other.mRowPitch == mRowPitch) {
        std::memmove(mData, other.mData, byteSize());
        return;
    }
    size_t rowBytes = size_t(mWidth) * formatInfo(mFormat).bytesPerPixel;
    for (uint32_t y = 0; y < mHeight; ++y) std::memmove(row(y), other.row(y), rowBytes);
}

void Texture::clear() {
    if (!mData) return;
    if (mResidence == DeviceKind::Cuda) {
        const Texture zeros(mWidth, mHeight, mFormat);
        copyTexture(*this, zeros);
        return;
    }
    std::memset(mData, 0, byteSize());
}

void Texture::poison() {
    if (!mData) return;
    if (mResidence == DeviceKind::Cuda) {  // the same pattern, made on the host and copied over
        Texture pattern(mWidth, mHeight, mFormat);
        pattern.poison();
        copyTexture(*this, pattern);
        return;
    }
    const FormatInfo& info = formatInfo(mFormat);
    switch (info.component) {
    case ComponentType::Float32: fillWords(mData, byteSize(), 0x7FC00000u); break;  // quiet NaN
    case ComponentType::Float16: fillWords(mData, byteSize(), 0x7E007E00u); break;  // two half quiet NaNs
    case ComponentType::Uint32: fillWords(mData, byteSize(), 0xFFFFFFFFu); break;
    case ComponentType::Unorm8: std::memset(mData, 0xFF, byteSize()); break;
    }
}

float Texture::texel(uint32_t x, uint32_t y, uint32_t c) const {
    if (mResidence != DeviceKind::Cpu) throwHostViewOfDeviceTexture(mResidence);
    const FormatInfo& info = formatInfo(mFormat);
    if (x >= mWidth || y >= mHeight || c >= info.channels || !mData) {
        throw std::out_of_range("Texture::texel: (" + std::to_string(x) + ", " + std::to_string(y) + ") channel " +
                                std::to_string(c) + " is outside the " + shapeString(mWidth, mHeight, mFormat) +
                                " texture");
    }
    const std::byte* p = row(y) + size_t(x) * info.bytesPerPixel;
    switch (info.component) {
    case ComponentType::Float32: {
        float v;
        std::memcpy(&v, p + 4 * c, 4);
        return v;
    }
    case ComponentType::Float16: {
        uint16_t h;
        std::memcpy(&h, p + 2 * c, 2);
        return halfToFloat(h);
    }
    case ComponentType::Uint32: {
        uint32_t u;
        std::memcpy(&u, p + 4 * c, 4);
        return float(u);
    }
    case ComponentType::Unorm8:
        // sRGB textures return the encoded value too: no transfer function is applied.
        return float(std::to_integer<uint8_t>(p[c])) / 255.0f;
    }
    return 0.0f;
}

bool Texture::samePixels(const Texture& other) const {
    if (other.mWidth != mWidth || other.mHeight != mHeight || other.mFormat != mFormat) return false;
    if (mResidence != DeviceKind::Cpu) throwHostViewOfDeviceTexture(mResidence);
    if (other.mResidence != DeviceKind::Cpu) throwHostViewOfDeviceTexture(other.mResidence);
    if (other.mData == mData) return true;
    if (!mData || !other.mData) return byteSize() == 0;
    size_t rowBytes = size_t(mWidth) * formatInfo(mFormat).bytesPerPixel;
    for (uint32_t y = 0; y < mHeight; ++y) {
        if (std::memcmp(row(y), other.row(y), rowBytes) != 0) return false;
    }
    return true;
}

float halfToFloat(uint16_t h) {
    uint32_t sign = uint32_t(h & 0x8000u) << 16;
    uint32_t exponent = (h >> 10) & 0x1Fu;
    uint32_t mantissa = h & 0x3FFu;
    uint32_t bits;
    if (exponent == 0x1F) {
        bits = sign | 0x7F800000u | (mantissa << 13);  // inf, or NaN keeping its payload
    } else if (exponent != 0) {
        bits = sign | ((exponent + 127 - 15) << 23) | (mantissa << 13);
    } else if (mantissa == 0) {
        bits = sign;  // signed zero
    } else {
        // Subnormal half: normalize into a normal float.
        uint32_t e = 127 - 15 + 1;
        while ((mantissa & 0x400u) == 0) {
            mantissa <<= 1;
            --e;
        }
        bits = sign | (e << 23) | ((mantissa & 0x3FFu) << 13);
    }
    return std::bit_cast<float>(bits);
}

uint16_t floatToHalf(float f) {
    uint32_t x = std::bit_cast<uint32_t>(f);
    auto sign = uint16_t((x >> 16) & 0x8000u);
    x &= 0x7FFFFFFFu;
    if (x >= 0x7F800000u) {
        if (x == 0x7F800000u) return sign | 0x7C00u;  // inf
        return sign | 0x7E00u | uint16_t((x >> 13) & 0x3FFu);  // NaN: quiet, keeping the payload's top bits
    }
    // 65520 is halfway between the largest half (65504) and 2^16; ties go to even, which is infinity.
    if (x >= 0x477FF000u) return sign | 0x7C00u;
    if (x >= 0x38800000u) {
        // Normal half: rebias the exponent and round the mantissa to nearest even. A carry out of the
        // mantissa correctly bumps the exponent.
        uint32_t odd = (x >> 13) & 1u;
        x += (uint32_t(15 - 127) << 23) + 0xFFFu + odd;
        return sign | uint16_t(x >> 13);
    }
    // Subnormal half or zero: value = m * 2^(e - 150) = q * 2^-24, so q = m >> (126 - e).
    uint32_t e = x >> 23;
    uint32_t shift = 126 - e;  // >= 14 here
    if (e == 0 || shift > 24) return sign;  // below half the smallest subnormal (or a float subnormal)
    uint32_t m = (x & 0x7FFFFFu) | 0x800000u;
    uint32_t q = m >> shift;
    uint32_t rest = m & ((1u << shift) - 1);
    uint32_t halfway = 1u << (shift - 1);
    if (rest > halfway || (rest == halfway && (q & 1u))) ++q;  // may round up into the smallest normal: correct
    return sign | uint16_t(q);
}

}  // namespace loom
