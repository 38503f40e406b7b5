#include "loom/Format.h"

#include <array>
#include <cassert>

namespace loom {

namespace {

// Indexed by the enum value; the order must match the declaration of Format.
constexpr std::array<FormatInfo, 9> kFormats = {{
    {Format::R32F, "R32F", 1, 4, ComponentType::Float32, false},
    {Format::RG32F, "RG32F", 2, 8, ComponentType::Float32, false},
    {Format::RGBA32F, "RGBA32F", 4, 16, ComponentType::Float32, false},
    {Format::RGBA16F, "RGBA16F", 4, 8, ComponentType::Float16, false},
    {Format::R32U, "R32U", 1, 4, ComponentType::Uint32, false},
    {Format::RG32U, "RG32U", 2, 8, ComponentType::Uint32, false},
    {Format::RGBA32U, "RGBA32U", 4, 16, ComponentType::Uint32, false},
    {Format::RGBA8Unorm, "RGBA8Unorm", 4, 4, ComponentType::Unorm8, false},
    {Format::RGBA8Srgb, "RGBA8Srgb", 4, 4, ComponentType::Unorm8, true},
}};

constexpr bool tableMatchesEnum() {
    for (size_t i = 0; i < kFormats.size(); ++i) {
        if (size_t(kFormats[i].format) != i) return false;
    }
    return true;
}
static_assert(tableMatchesEnum(), "kFormats must be in the order of enum class Format");

}  // namespace

const FormatInfo& formatInfo(Format f) {
    auto i = size_t(f);
    assert(i < kFormats.size());
    if (i >= kFormats.size()) i = size_t(Format::RGBA32F);  // never reached with a valid enum value
    return kFormats[i];
}

std::optional<Format> parseFormat(std::string_view name) {
    for (const auto& info : kFormats) {
        if (info.name == name) return info.format;
    }
    return std::nullopt;
}

}  // namespace loom
