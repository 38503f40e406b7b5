// loom image: small image utilities for looking at results.
//   loom image montage A B C -o side.png   side-by-side of images of equal height
//   loom image merge PART... -o OUT        one frame's partial accumulations (sample shards) into one
//   loom image compare A B                 whether two images hold the same values, bit for bit
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <regex>
#include <string>
#include <vector>

#include "CliUtil.h"
#include "Display.h"
#include "loom/DoubleTexels.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"
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

namespace fs = std::filesystem;

/// One shard's partial accumulation of one frame of one pass: its double sums and sample counts, and where its
/// samples came from (the header attributes `loom render --hold` writes).
struct Partial {
    Texture sumRG, sumBA, count;
    std::string heldFrame;
    uint64_t seedOffset = 0, iterations = 0;
};

uint64_t attributeNumber(const ExrFile& f, const char* name) {
    const std::optional<std::string> v = f.stringAttribute(name);
    if (!v || v->empty() || v->find_first_not_of("0123456789") != std::string::npos)
        throwBadInput(f.path().string(), std::string("no header attribute ") + name + " with a count",
                      "a partial accumulation written by loom render --hold", "", f.path().string());
    return std::stoull(*v);
}

Partial readPartial(const fs::path& dir, const std::string& stem, const std::string& frame) {
    Partial p;
    const fs::path rg = dir / (stem + ".partialSumRG." + frame + ".exr");
    const fs::path ba = dir / (stem + ".partialSumBA." + frame + ".exr");
    const fs::path count = dir / (stem + ".partialCount." + frame + ".exr");
    for (const fs::path& f : {rg, ba, count})
        if (!fs::exists(f))
            throwBadInput(f.string(),
                          "missing: each shard needs " + stem +
                              "'s partialSumRG, partialSumBA and "
                              "partialCount of frame " +
                              frame,
                          "the outputs of every shard's run", "", f.string());
    p.sumRG = readImage(rg);
    p.sumBA = readImage(ba);
    p.count = readImage(count);
    const ExrFile header(count);
    p.heldFrame = header.stringAttribute("loomHeldFrame").value_or("");
    p.seedOffset = attributeNumber(header, "loomSeedOffset");
    p.iterations = attributeNumber(header, "loomIterations");
    return p;
}

/// Sums the shards' partial accumulations of each (pass, frame) found in the first shard's folder and writes the
/// merged partials (so merges compose) and their mean, <pass>.mean.<frame>.exr, into `out`. Means are formed as
/// AccumulatePass forms them (double sum / count, rounded to float), so where the double sums are exact (float
/// samples of a moderate range) the mean equals that of one run over all the shards' samples bit for bit.
void runMerge(const std::vector<std::string>& parts, const std::string& out) {
    if (parts.size() < 2) throwBadInput("loom image merge", "fewer than two partial accumulations", "two or more");
    for (const std::string& p : parts)
        if (!fs::is_directory(p))
            throwBadInput(p, "not a folder", "folders written by loom render --hold (one per shard)", "", p);
    static const std::regex name(R"((.+)\.partialCount\.([0-9]{4,})\.exr)");
    std::vector<std::pair<std::string, std::string>> groups;  // (pass, frame)
    for (const auto& e : fs::directory_iterator(parts.front())) {
        std::smatch m;
        const std::string file = e.path().filename().string();
        if (std::regex_match(file, m, name)) groups.emplace_back(m[1], m[2]);
    }
    std::sort(groups.begin(), groups.end());
    if (groups.empty())
        throwBadInput(parts.front(), "no partial accumulation (PASS.partialCount.FRAME.exr) in the folder",
                      "the outputs of a graph marking an AccumulatePass's partialSumRG, partialSumBA and partialCount "
                      "(graphs/ReferenceShard.json)",
                      "", parts.front());
    ensureWritableDir(out, "--out");
    for (const auto& [stem, frame] : groups) {
        std::vector<Partial> shards;
        for (const std::string& dir : parts) shards.push_back(readPartial(dir, stem, frame));
        const uint32_t w = shards.front().count.width(), h = shards.front().count.height();
        // The shards must be parts of one frame's samples: the same frame and size, disjoint sample ranges.
        std::vector<std::pair<uint64_t, uint64_t>> ranges;
        uint64_t iterations = 0;
        for (size_t i = 0; i < shards.size(); ++i) {
            const Partial& p = shards[i];
            for (const Texture* t : {&p.sumRG, &p.sumBA, &p.count})
                if (t->width() != w || t->height() != h || t->format() != Format::RGBA32U)
                    throwBadInput(parts[i],
                                  fmt::format("{} of frame {} is not a {}x{} image of counts", stem, frame, w, h),
                                  "partials of one frame at one size", "", parts[i]);
            if (p.heldFrame != shards.front().heldFrame)
                throwBadInput(
                    parts[i],
                    fmt::format("holds frame {}, the first shard frame {}", p.heldFrame, shards.front().heldFrame),
                    "shards of one frame", "", parts[i]);
            ranges.emplace_back(p.seedOffset, p.seedOffset + p.iterations);
            iterations += p.iterations;
        }
        std::vector<size_t> order(ranges.size());
        for (size_t i = 0; i < order.size(); ++i) order[i] = i;
        std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return ranges[a] < ranges[b]; });
        for (size_t k = 1; k < order.size(); ++k)
            if (ranges[order[k]].first < ranges[order[k - 1]].second)
                throwBadInput(parts[order[k]],
                              fmt::format("its samples (--seed-offset {}, {} iterations) overlap those of {}",
                                          ranges[order[k]].first, ranges[order[k]].second - ranges[order[k]].first,
                                          parts[order[k - 1]]),
                              "shards with disjoint --seed-offset ranges", "", parts[order[k]]);
        Texture sumRG(w, h, Format::RGBA32U), sumBA(w, h, Format::RGBA32U), count(w, h, Format::R32U),
            mean(w, h, Format::RGBA32F);
        const auto rg = sumRG.view<glm::uvec4>(), ba = sumBA.view<glm::uvec4>();
        const auto mv = mean.view<glm::vec4>();
        const auto cv = count.view<uint32_t>();
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) {
                glm::dvec4 sum(0.0);
                uint64_t n = 0;
                for (const Partial& p : shards) {  // in the order given: the same bits for the same order
                    sum += unpackDoubleSum(p.sumRG.view<glm::uvec4>().at(x, y), p.sumBA.view<glm::uvec4>().at(x, y));
                    n += p.count.view<glm::uvec4>().at(x, y).x;
                }
                if (n > 0xFFFFFFFFull) throwBadInput("loom image merge", "more than 2^32 samples in a pixel", "fewer");
                packDoubleSum(sum, rg.at(x, y), ba.at(x, y));
                cv.at(x, y) = uint32_t(n);
                mv.at(x, y) = n == 0 ? glm::vec4(0.f) : glm::vec4(sum / double(n));
            }
        const std::map<std::string, std::string> attributes = {
            {"loomHeldFrame", shards.front().heldFrame},
            {"loomSeedOffset", std::to_string(ranges[order.front()].first)},
            {"loomIterations", std::to_string(iterations)},
            {"loomShards", std::to_string(shards.size())}};
        const fs::path dir(out);
        writeImage(dir / (stem + ".partialSumRG." + frame + ".exr"), sumRG, attributes);
        writeImage(dir / (stem + ".partialSumBA." + frame + ".exr"), sumBA, attributes);
        writeImage(dir / (stem + ".partialCount." + frame + ".exr"), count, attributes);
        writeImage(dir / (stem + ".mean." + frame + ".exr"), mean, attributes);
        fmt::print("{} frame {}: {} shards, {} iterations -> {}\n", stem, frame, shards.size(), iterations,
                   (dir / (stem + ".mean." + frame + ".exr")).string());
    }
}

/// Exit 0 when A and B hold the same values bit for bit (size, format, every channel), else 1 with what differs.
int runCompare(const std::string& a, const std::string& b) {
    const Texture x = readImage(a), y = readImage(b);
    if (x.width() != y.width() || x.height() != y.height() || x.format() != y.format()) {
        fmt::print("{}x{} {} vs {}x{} {}\n", x.width(), x.height(), formatName(x.format()), y.width(), y.height(),
                   formatName(y.format()));
        return 1;
    }
    const uint32_t channels = formatInfo(x.format()).channels;
    uint64_t differ = 0;
    double largest = 0.0;
    for (uint32_t j = 0; j < x.height(); ++j)
        for (uint32_t i = 0; i < x.width(); ++i)
            for (uint32_t c = 0; c < channels; ++c) {
                const float u = x.texel(i, j, c), v = y.texel(i, j, c);
                if (std::memcmp(&u, &v, sizeof u) != 0) {
                    ++differ;
                    largest = std::max(largest, double(std::fabs(u - v)));
                }
            }
    const uint64_t total = uint64_t(x.width()) * x.height() * channels;
    if (differ == 0) {
        fmt::print("identical: {} values\n", total);
        return 0;
    }
    fmt::print("{} of {} values differ (largest difference {:g})\n", differ, total, largest);
    return 1;
}

}  // namespace

void addImageCommand(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand("image", "Image utilities (montage, merge, compare)");
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

    CLI::App* merge = cmd->add_subcommand(
        "merge",
        "Merge partial accumulations of one frame (folders of `loom render --hold --seed-offset K` runs of a graph "
        "marking an AccumulatePass's partialSumRG, partialSumBA and partialCount) into their mean");
    static std::vector<std::string> parts;
    static std::string mergeOut;
    merge->add_option("parts", parts, "one folder per shard")->required();
    merge->add_option("-o,--out", mergeOut, "output folder")->required();
    merge->callback([] { runMerge(parts, mergeOut); });

    CLI::App* compare = cmd->add_subcommand(
        "compare", "Exit 0 when two images hold the same values bit for bit, else 1 saying how many differ");
    static std::string first, second;
    compare->add_option("a", first, "an image")->required()->check(CLI::ExistingFile);
    compare->add_option("b", second, "another image")->required()->check(CLI::ExistingFile);
    compare->callback([] {
        // Different images are an answer, not an error: exit 1 (bad input stays 2).
        if (runCompare(first, second) != 0) {
            std::fflush(stdout);
            std::exit(1);
        }
    });
}

}  // namespace loom::cli
