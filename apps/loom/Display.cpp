#include "Display.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>

#include "loom/Error.h"
#include "loom/Parallel.h"
#include "loom/SrgbEncode.h"
#include "loom/SurfaceKernels.h"

namespace loom::cli {

uint8_t encodeSrgb8(float linear) {
    static const std::unique_ptr<SrgbEncodeTable> table = [] {
        auto t = std::make_unique<SrgbEncodeTable>();
        buildSrgbEncodeTable(*t);
        return t;
    }();
    if (!std::isfinite(linear)) return linear > 0.f ? 255 : 0;
    // The table takes [0, 1] with no sign bit: -0 and negatives become +0.
    return uint8_t(loom::encodeSrgb8(*table, linear > 0.f ? std::min(linear, 1.f) : 0.f));
}

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
        const uint32_t h = id == ~0u ? 0u : loom::hash32(id) | 0x404040u;  // ids never black: black is the miss
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
    parallelFor2D(t.width(), t.height(), [&](const Tile& tile) {
        for (uint32_t y = tile.y0; y < tile.y1; ++y)
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                uint8_t* p = &image[(size_t(y) * t.width() + x) * 4];
                displayPixel(t, x, y, scale, p);
                p[3] = 255;  // opaque on screen whatever an 8-bit field's alpha holds
            }
    });
    return image;
}

void rgbToYCbCr(const uint8_t rgb[3], uint8_t ycc[3]) {
    const float r = rgb[0], g = rgb[1], b = rgb[2];
    const float y = 0.299f * r + 0.587f * g + 0.114f * b;
    const float v[3] = {y, 128.f + (b - y) / 1.772f, 128.f + (r - y) / 1.402f};
    for (int c = 0; c < 3; ++c) ycc[c] = uint8_t(std::lround(std::clamp(v[c], 0.f, 255.f)));
}

Y4mWriter::Y4mWriter(const std::filesystem::path& path, uint32_t width, uint32_t height, double fps)
    : mPath(path),
      mPartial(path.string() + ".partial"),
      mRegistration(std::make_unique<PartialFile>(mPartial.string())),
      mWidth(width),
      mHeight(height) {
    mFile = std::fopen(mPartial.c_str(), "wb");
    mRegistration->created();
    if (!mFile)
        throw Error({ErrorKind::BadInput, path.string(), "--record", "cannot write the video", "a writable path",
                     "choose another --record file"});
    const long rate = std::lround(std::clamp(fps, 0.001, 1e6) * 1000.0);
    std::fprintf(mFile, "YUV4MPEG2 W%u H%u F%ld:1000 Ip A1:1 C444 XCOLORRANGE=FULL\n", width, height, rate);
}

Y4mWriter::~Y4mWriter() {
    if (!mFile) return;
    std::fclose(mFile);
    std::error_code ec;
    std::filesystem::remove(mPartial, ec);  // unfinished: no half-written video is left
}

void Y4mWriter::add(const std::vector<uint8_t>& rgba) {
    const size_t n = size_t(mWidth) * mHeight;
    if (rgba.size() != n * 4)
        throw Error({ErrorKind::BadInput, mPath.string(), "--record",
                     fmt::format("a frame of {} pixels, the video's are {}x{}", rgba.size() / 4, mWidth, mHeight),
                     "fields of the video's size", "record to a folder of PNGs to mix sizes"});
    std::vector<uint8_t> planes(n * 3);
    for (size_t i = 0; i < n; ++i) {
        uint8_t ycc[3];
        rgbToYCbCr(&rgba[i * 4], ycc);
        for (int c = 0; c < 3; ++c) planes[size_t(c) * n + i] = ycc[c];
    }
    std::fputs("FRAME\n", mFile);
    if (std::fwrite(planes.data(), 1, planes.size(), mFile) != planes.size())
        throw Error({ErrorKind::Runtime, mPath.string(), "--record", "writing the video failed", "", "check the disk"});
}

void Y4mWriter::finish() {
    if (!mFile) return;
    const bool ok = std::fflush(mFile) == 0;
    std::fclose(mFile);
    mFile = nullptr;
    std::error_code ec;
    if (ok) std::filesystem::rename(mPartial, mPath, ec);
    const bool renamed = ok && !ec;
    if (!renamed) awaitEndIfEnding();  // the failure may be the removal of the file by a signal handler
    if (!renamed) std::filesystem::remove(mPartial, ec);
    mRegistration.reset();
    if (!renamed) {
        throw Error({ErrorKind::Runtime, mPath.string(), "--record", "finishing the video failed", "", "check the disk"});
    }
}

bool ImagePlacement::pixelAt(float sx, float sy, uint32_t w, uint32_t h, uint32_t& x, uint32_t& y) const {
    const float fx = (sx - x0) / scale, fy = (sy - y0) / scale;
    if (!(scale > 0.f && fx >= 0.f && fy >= 0.f && fx < float(w) && fy < float(h))) return false;
    x = std::min(uint32_t(fx), w - 1);
    y = std::min(uint32_t(fy), h - 1);
    return true;
}

namespace {

float fitScale(float areaW, float areaH, uint32_t w, uint32_t h) {
    return std::min(areaW / float(std::max(w, 1u)), areaH / float(std::max(h, 1u)));
}

}  // namespace

ImagePlacement ImageViewport::place(float areaW, float areaH, uint32_t w, uint32_t h) const {
    const float scale = fitScale(areaW, areaH, w, h) * mZoom;
    return {0.5f * (areaW - float(w) * scale) + mPanX, 0.5f * (areaH - float(h) * scale) + mPanY, scale};
}

void ImageViewport::setScaleAbout(float scale, float sx, float sy, float areaW, float areaH, uint32_t w, uint32_t h) {
    const float fit = fitScale(areaW, areaH, w, h);
    if (!(fit > 0.f) || !std::isfinite(scale)) return;
    scale = std::clamp(scale, std::min(0.25f * fit, 1.f), std::max(kMaxScale, fit));
    const ImagePlacement before = place(areaW, areaH, w, h);
    // The image point under (sx, sy) stays there: x0' = sx - (sx - x0) scale' / scale.
    const float ratio = scale / before.scale;
    const float x0 = sx - (sx - before.x0) * ratio, y0 = sy - (sy - before.y0) * ratio;
    mZoom = scale / fit;
    mPanX = x0 - 0.5f * (areaW - float(w) * scale);
    mPanY = y0 - 0.5f * (areaH - float(h) * scale);
}

void ImageViewport::zoomAt(float factor, float sx, float sy, float areaW, float areaH, uint32_t w, uint32_t h) {
    setScaleAbout(place(areaW, areaH, w, h).scale * factor, sx, sy, areaW, areaH, w, h);
}

void ImageViewport::actualSize(float sx, float sy, float areaW, float areaH, uint32_t w, uint32_t h) {
    setScaleAbout(1.f, sx, sy, areaW, areaH, w, h);
}

}  // namespace loom::cli
