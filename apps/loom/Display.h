#pragma once
// 8-bit display of any field: what `loom view` shows and `loom image montage` writes.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "loom/PartialFiles.h"
#include "loom/Texture.h"

namespace loom::cli {

/// The exact sRGB encoding of a linear value (clamped to [0, 1]; not finite: 0 or 1 by sign), correctly rounded to 8
/// bits.
uint8_t encodeSrgb8(float linear);

/// RGBA8 (sRGB-encoded) of pixel (x, y) as a viewer shows it: 8-bit formats as they are (alpha too); float formats
/// multiplied by `scale`, clamped and sRGB-encoded (one channel as grey, two as red and green), a pixel with a
/// non-finite value magenta; integer formats (ids) as a colour hashed from the first channel, the miss value ~0 black.
void displayPixel(const Texture& t, uint32_t x, uint32_t y, float scale, uint8_t out[4]);

/// The values of pixel (x, y) as text, one per channel: "0.5, 0.25, 3, 1" (integers for integer formats).
std::string pixelText(const Texture& t, uint32_t x, uint32_t y);

/// The whole texture through displayPixel, rows top to bottom, 4 bytes a pixel, alpha 255.
std::vector<uint8_t> displayImage(const Texture& t, float scale);

/// Where an image of w x h pixels lies on screen: its top-left corner and screen pixels per image pixel.
struct ImagePlacement {
    float x0 = 0.f, y0 = 0.f, scale = 1.f;
    /// The image pixel under screen point (sx, sy); false outside the image.
    bool pixelAt(float sx, float sy, uint32_t w, uint32_t h, uint32_t& x, uint32_t& y) const;
};

/// The viewer's zoom and pan of the shown image within its area of the window. Zoom 1 fits the image to the area,
/// centred; zooming about a screen point keeps the image point under it in place.
class ImageViewport {
public:
    static constexpr float kMaxScale = 64.f;  ///< screen pixels per image pixel at most
    ImagePlacement place(float areaW, float areaH, uint32_t w, uint32_t h) const;
    /// Multiplies the zoom by `factor` (clamped between a quarter of the fit, or 1:1 if that is less, and kMaxScale
    /// screen pixels per image pixel), keeping the image point under (sx, sy) where it is.
    void zoomAt(float factor, float sx, float sy, float areaW, float areaH, uint32_t w, uint32_t h);
    /// One screen pixel per image pixel, keeping the image point under (sx, sy).
    void actualSize(float sx, float sy, float areaW, float areaH, uint32_t w, uint32_t h);
    void pan(float dx, float dy) {
        mPanX += dx;
        mPanY += dy;
    }
    void fit() { *this = ImageViewport(); }

private:
    void setScaleAbout(float scale, float sx, float sy, float areaW, float areaH, uint32_t w, uint32_t h);
    float mZoom = 1.f, mPanX = 0.f, mPanY = 0.f;  ///< zoom relative to the fit; offset from the centred placement
};

/// A video of displayed frames as YUV4MPEG2 (.y4m): 8-bit Y'CbCr 4:4:4, full range, BT.601 coefficients on the
/// sRGB-encoded values; players and ffmpeg read it (`ffmpeg -i in.y4m out.mp4`). Written to PATH.partial and renamed
/// by finish(); destroyed unfinished (an error on the way), it removes the partial file. The partial file is registered
/// (loom/PartialFiles.h) while it exists, so a process ended by a signal removes it too.
class Y4mWriter {
public:
    Y4mWriter(const std::filesystem::path& path, uint32_t width, uint32_t height, double fps);
    ~Y4mWriter();
    Y4mWriter(const Y4mWriter&) = delete;
    Y4mWriter& operator=(const Y4mWriter&) = delete;
    /// Appends a frame of width x height RGBA8 pixels (displayImage's layout).
    void add(const std::vector<uint8_t>& rgba);
    void finish();
    uint32_t width() const { return mWidth; }
    uint32_t height() const { return mHeight; }

private:
    std::filesystem::path mPath, mPartial;
    std::unique_ptr<PartialFile> mRegistration;  ///< of mPartial, while it exists
    std::FILE* mFile = nullptr;
    uint32_t mWidth, mHeight;
};

/// BT.601 full-range Y'CbCr of an sRGB-encoded 8-bit colour, rounded: what Y4mWriter stores.
void rgbToYCbCr(const uint8_t rgb[3], uint8_t ycc[3]);

}  // namespace loom::cli
