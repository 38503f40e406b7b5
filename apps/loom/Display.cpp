#include "Display.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace loom::cli {

uint8_t encodeSrgb8(float linear) {
    if (!std::isfinite(linear)) linear = linear > 0.f ? 1.f : 0.f;
    const float v = std::clamp(linear, 0.f, 1.f);
    const float e = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.f / 2.4f) - 0.055f;
    return uint8_t(std::lround(std::clamp(e, 0.f, 1.f) * 255.f));
}

namespace {

/// A well-mixed 32-bit hash (for id colours).
uint32_t mix(uint32_t v) {
    v ^= v >> 16;
    v *= 0x7feb352du;
    v ^= v >> 15;
    v *= 0x846ca68bu;
    v ^= v >> 16;
    return v;
}

}  // namespace

void displayPixel(const Texture& t, uint32_t x, uint32_t y, float scale, uint8_t out[4]) {
    const FormatInfo& info = formatInfo(t.format());
    out[3] = 255;
    if (info.component == ComponentType::Unorm8) {
        std::memcpy(out, t.row(y) + size_t(x) * 4, 4);
        return;
    }
    if (info.component == ComponentType::Uint32) {
        uint32_t id;
        std::memcpy(&id, t.row(y) + size_t(x) * info.bytesPerPixel, sizeof(id));
        const uint32_t h = id == ~0u ? 0u : mix(id) | 0x404040u;  // ids never black: black is the miss
        out[0] = uint8_t(h), out[1] = uint8_t(h >> 8), out[2] = uint8_t(h >> 16);
        return;
    }
    float v[3] = {0.f, 0.f, 0.f};
    bool finite = true;
    for (uint32_t c = 0; c < info.channels; ++c) {
        const float value = t.texel(x, y, c);
        finite = finite && std::isfinite(value);
        if (c < 3) v[c] = value * scale;
    }
    if (!finite) {
        out[0] = 255, out[1] = 0, out[2] = 255;
        return;
    }
    if (info.channels == 1) v[1] = v[2] = v[0];
    for (int c = 0; c < 3; ++c) out[c] = encodeSrgb8(v[c]);
}

std::string pixelText(const Texture& t, uint32_t x, uint32_t y) {
    const FormatInfo& info = formatInfo(t.format());
    std::string text;
    for (uint32_t c = 0; c < info.channels; ++c) {
        if (c) text += ", ";
        if (info.component == ComponentType::Uint32) {
            uint32_t v;
            std::memcpy(&v, t.row(y) + size_t(x) * info.bytesPerPixel + c * sizeof(v), sizeof(v));
            text += std::to_string(v);
        } else {
            char buffer[32];
            std::snprintf(buffer, sizeof buffer, "%.6g", t.texel(x, y, c));
            text += buffer;
        }
    }
    return text;
}

std::vector<uint8_t> displayImage(const Texture& t, float scale) {
    std::vector<uint8_t> image(size_t(t.width()) * t.height() * 4);
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x) {
            uint8_t* p = &image[(size_t(y) * t.width() + x) * 4];
            displayPixel(t, x, y, scale, p);
            p[3] = 255;  // opaque on screen whatever an 8-bit field's alpha holds
        }
    return image;
}

}  // namespace loom::cli
