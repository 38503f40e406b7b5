// loom image: small image utilities for looking at results.
//   loom image montage A B C -o side.png   side-by-side of images of equal height (B.exr:LAYER: one layer)
//   loom image merge PART... -o OUT        one frame's partial accumulations (sample shards) into one
//   loom image compare A B [--tolerance T] whether two images hold the same values
// The merge and the comparison themselves are loom/ShardMerge.h; this file parses their options.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "CliUtil.h"
#include "Display.h"
#include "Interrupt.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/Files.h"
#include "loom/ImageIO.h"
#include "loom/ShardMerge.h"

namespace loom::cli {

namespace {

constexpr uint64_t kMaxMontageWidth = 65536;

/// A montage input: an image file, or FILE.exr:LAYER for one layer of a multilayer EXR.
Texture readMontageImage(const std::string& spec) {
    const SequenceSource source = parseSequenceSource(spec);
    std::error_code ec;
    if (!std::filesystem::is_regular_file(source.pattern, ec))
        throwBadInput("", std::filesystem::exists(source.pattern, ec) ? "not a file" : "no such file",
                      "PNG or EXR images (FILE.exr:LAYER for a layer of a multilayer EXR)", "", source.pattern);
    if (!source.layer.empty()) return ExrFile(source.pattern).readRgba(source.layer);
    try {
        return readImage(source.pattern);
    } catch (const Error& e) {
        // A multilayer EXR without bare R, G, B: say how montage names a layer.
        std::optional<ExrFile> exr;
        try {
            exr.emplace(source.pattern);
        } catch (const Error&) {
            throw e;
        }
        const std::vector<std::string> layers = exr->layers();
        const auto named = std::find_if(layers.begin(), layers.end(), [](const std::string& l) { return !l.empty(); });
        if (!exr->layerChannels("").empty() || named == layers.end()) throw;
        Error::Info info = e.info();
        info.suggestion = "name the layer after the file, e.g. '" + source.pattern + ":" + *named + "'";
        throw Error(info);
    }
}

void runMontage(const std::vector<std::string>& inputs, const std::string& output, uint32_t gap) {
    if (inputs.size() < 2) throwBadInput("loom image montage", "fewer than two input images", "two or more images");
    if (gap > 1024) throwBadInput("--gap", fmt::format("a gap of {} pixels is too wide", gap), "0 to 1024 pixels");
    std::vector<std::filesystem::path> files;
    for (const std::string& spec : inputs) files.push_back(parseSequenceSource(spec).pattern);
    checkOutputFile(output, "--out", files);
    std::vector<Texture> images;
    for (const std::string& spec : inputs) images.push_back(readMontageImage(spec));
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

/// Exit 0 when A and B hold the same values (bit for bit, or floats within `tolerance`), else 1 saying what differs.
int runCompare(const std::string& a, const std::string& b, std::optional<double> tolerance) {
    if (tolerance && !(*tolerance >= 0.0 && std::isfinite(*tolerance)))
        throwBadInput("--tolerance", fmt::format("{:g} is not a tolerance", *tolerance),
                      "a finite absolute difference >= 0 (floats only: integers are compared exactly)");
    const Texture x = readImage(a), y = readImage(b);
    const ImageComparison c = compareImages(x, y, tolerance);
    fmt::print("{}\n", describeComparison(x, y, c, tolerance));
    return c.sameShape && c.differ == 0 ? 0 : 1;
}

}  // namespace

void addImageCommand(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand("image", "Image utilities (montage, merge, compare)");
    cmd->require_subcommand(1);
    CLI::App* montage = cmd->add_subcommand("montage", "Place images of equal height side by side into one PNG");
    static std::vector<std::string> inputs;
    static std::string output;
    static uint32_t gap = 4;
    montage
        ->add_option("images", inputs,
                     "PNG or EXR images, left to right (EXR: clamped, sRGB-encoded; FILE.exr:LAYER reads one layer "
                     "of a multilayer EXR)")
        ->required();
    montage->add_option("-o,--out", output, "output PNG")->required();
    montage->add_option("--gap", gap, "white pixels between images")->capture_default_str();
    montage->callback([] { runMontage(inputs, output, gap); });

    CLI::App* merge = cmd->add_subcommand(
        "merge",
        "Merge partial accumulations of one frame (folders of `loom render --hold --seed-offset K` runs of a graph "
        "marking an AccumulatePass's partialSumRG, partialSumBA and partialCount) into their mean");
    static std::vector<std::string> parts;
    static std::string mergeOut;
    merge->add_option("parts", parts, "one folder per shard (their iterations must not overlap)")->required();
    merge->add_option("-o,--out", mergeOut, "output folder: new or empty, written whole or not at all")->required();
    merge->callback([] {
        // A signal stops the merge between two files; what it wrote so far is removed.
        StopOnSignal stop;
        const std::vector<MergedFrame> frames = mergeShards(
            std::vector<std::filesystem::path>(parts.begin(), parts.end()), mergeOut, [] { throwIfStopRequested(); });
        for (const MergedFrame& f : frames)
            fmt::print("{} frame {}: {} shards, {} iterations -> {}\n", f.pass, f.frame, f.shards, f.iterations,
                       (std::filesystem::path(mergeOut) / f.mean.filename()).string());
    });

    CLI::App* compare = cmd->add_subcommand(
        "compare",
        "Exit 0 when two images hold the same values (integers exactly, floats bit for bit or within --tolerance), "
        "else 1 saying how many differ");
    static std::string first, second;
    static double tolerance = 0.0;
    static CLI::Option* toleranceOption = nullptr;
    compare->add_option("a", first, "an image")->required()->check(CLI::ExistingFile);
    compare->add_option("b", second, "another image")->required()->check(CLI::ExistingFile);
    toleranceOption =
        compare->add_option("--tolerance", tolerance,
                            "float values that differ by at most this much (absolute) count as equal; integer channels "
                            "are always compared exactly");
    compare->callback([] {
        // Different images are an answer, not an error: exit 1 (bad input stays 2).
        if (runCompare(first, second, toleranceOption->count() ? std::optional<double>(tolerance) : std::nullopt) !=
            0) {
            std::fflush(stdout);
            std::exit(1);
        }
    });
}

}  // namespace loom::cli
