#pragma once
// Pixel formats of Loom textures.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace loom {

enum class Format : uint8_t {
    R32F,
    RG32F,
    RGBA32F,
    RGBA16F,
    R32U,
    RG32U,
    RGBA32U,
    RGBA8Unorm,
    RGBA8Srgb,
};

enum class ComponentType : uint8_t { Float32, Float16, Uint32, Unorm8 };

struct FormatInfo {
    Format format;
    std::string_view name;   ///< as written in graphs and docs, e.g. "RGBA32F"
    uint32_t channels;       ///< 1..4
    uint32_t bytesPerPixel;  ///< size of one texel
    ComponentType component;
    bool srgb;
};

/// Static description of a format.
const FormatInfo& formatInfo(Format f);
/// "RGBA32F" -> Format::RGBA32F; nullopt for unknown names.
std::optional<Format> parseFormat(std::string_view name);
inline std::string_view formatName(Format f) { return formatInfo(f).name; }
/// True for formats whose components are floats (32 or 16 bit).
inline bool isFloatFormat(Format f) {
    auto c = formatInfo(f).component;
    return c == ComponentType::Float32 || c == ComponentType::Float16;
}

}  // namespace loom
