// loom image: small image utilities for looking at results.
//   loom image montage A B C -o side.png   side-by-side of images of equal height
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "CliUtil.h"
#include "Display.h"
#include "loom/Error.h"
#include "loom/Files.h"
#include "loom/ImageIO.h"

namespace loom::cli {

namespace {

constexpr uint64_t kMaxMontageWidth = 65536;

void runMontage(const std::vector<std::string>& inputs, const std::string& output, uint32_t gap) {
    if (inputs.size() < 2) throwBadInput("loom image montage", "fewer than two input images", "two or more images");
    if (gap > 1024) throwBadInput("--gap", fmt::format("a gap of {} pixels is too wide", gap), "0 to 1024 pixels");
    checkOutputFile(output, "--out", std::vector<std::filesystem::path>(inputs.begin(), inputs.end()));
    std::vector<Texture> images;
    for (const std::string& path : inputs) images.push_back(readImage(path));
    const uint32_t height = images.front().height();
    uint64_t width = 0;
    for (size_t i = 0; i < images.size(); ++i) {
        if (images[i].height() != height)
            throwBadInput(inputs[i],
                          fmt::format("image is {} pixels high, the first is {}", images[i].height(), height),
                          "images of equal height", "render them at the same --size");
        width += images[i].width() + (i ? gap : 0);
    }
    if (width > kMaxMontageWidth)
        throwBadInput("loom image montage", fmt::format("the montage would be {} pixels wide", width),
                      fmt::format("at most {} pixels side by side", kMaxMontageWidth), "montage fewer images");
    Texture out(uint32_t(width), height, Format::RGBA8Srgb);
    uint32_t x0 = 0;
    for (const Texture& image : images) {
        for (uint32_t y = 0; y < height; ++y)
            for (uint32_t x = 0; x < image.width(); ++x)
                displayPixel(image, x, y, 1.f, reinterpret_cast<uint8_t*>(out.row(y)) + size_t(x0 + x) * 4);
        x0 += image.width();
        for (uint32_t g = 0; g < gap && x0 < width; ++g, ++x0)
            for (uint32_t y = 0; y < height; ++y) std::memset(out.row(y) + size_t(x0) * 4, 0xFF, 4);
    }
    writeImage(output, out);
}

}  // namespace

void addImageCommand(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand("image", "Image utilities (montage)");
    cmd->require_subcommand(1);
    CLI::App* montage = cmd->add_subcommand("montage", "Place images of equal height side by side into one PNG");
    static std::vector<std::string> inputs;
    static std::string output;
    static uint32_t gap = 4;
    montage->add_option("images", inputs, "PNG or EXR images, left to right (EXR: clamped, sRGB-encoded)")
        ->required()
        ->check(CLI::ExistingFile);
    montage->add_option("-o,--out", output, "output PNG")->required();
    montage->add_option("--gap", gap, "white pixels between images")->capture_default_str();
    montage->callback([] { runMontage(inputs, output, gap); });
}

}  // namespace loom::cli
