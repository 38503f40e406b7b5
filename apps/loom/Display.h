#pragma once
// 8-bit display of any field: what `loom view` shows and `loom image montage` writes.
#include <cstdint>
#include <string>
#include <vector>

#include "loom/Texture.h"

namespace loom::cli {

/// The exact sRGB encoding of a linear value in [0, 1] (clamped; not finite: 0 or 1 by sign), to 8 bits.
uint8_t encodeSrgb8(float linear);

/// RGBA8 (sRGB-encoded) of pixel (x, y) as a viewer shows it: 8-bit formats as they are (alpha too); float formats
/// multiplied by `scale`, clamped and sRGB-encoded (one channel as grey, two as red and green), a pixel with a
/// non-finite value magenta; integer formats (ids) as a colour hashed from the first channel, the miss value ~0 black.
void displayPixel(const Texture& t, uint32_t x, uint32_t y, float scale, uint8_t out[4]);

/// The values of pixel (x, y) as text, one per channel: "0.5, 0.25, 3, 1" (integers for integer formats).
std::string pixelText(const Texture& t, uint32_t x, uint32_t y);

/// The whole texture through displayPixel, rows top to bottom, 4 bytes a pixel, alpha 255.
std::vector<uint8_t> displayImage(const Texture& t, float scale);

}  // namespace loom::cli
