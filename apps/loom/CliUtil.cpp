#include "CliUtil.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <regex>

#include "loom/Error.h"
#include "loom/Params.h"

namespace loom::cli {

void parseSize(const std::string& text, const std::string& option, uint32_t& width, uint32_t& height) {
    std::smatch m;
    static const std::regex re(R"((\d{1,9})[xX](\d{1,9}))");  // digits enough to say "out of range"
    if (!std::regex_match(text, m, re))
        throwBadInput(option, "'" + printable(text) + "' is not a size", "WIDTHxHEIGHT, e.g. 1280x720");
    width = uint32_t(std::stoul(m[1]));
    height = uint32_t(std::stoul(m[2]));
    if (width == 0 || height == 0 || width > 16384 || height > 16384)
        throwBadInput(option, "size '" + text + "' is out of range", "each side between 1 and 16384");
}

void addSizeOption(CLI::App* cmd, std::string& size, const std::string& fallback, const std::string& use) {
    cmd->add_option("--size", size,
                    fmt::format("frame size WIDTHxHEIGHT{} (default: the size of the frames the graph's source "
                                "passes read, ImageSequence's files; else {})",
                                use, fallback));
}

glm::uvec2 frameSize(const std::string& size, bool given, const std::vector<SizedGraph>& graphs,
                     const std::string& fallback) {
    glm::uvec2 out;
    if (given) {
        parseSize(size, "--size", out.x, out.y);
        return out;
    }
    std::optional<NaturalSize> found;
    std::string foundLabel;
    for (const SizedGraph& g : graphs) {
        const std::optional<NaturalSize> n = g.graph->naturalSize();
        if (!n) continue;
        if (found && (found->width != n->width || found->height != n->height)) {
            const auto name = [](const std::string& label, const std::string& pass) {
                return label.empty() ? pass : fmt::format("{} of {}", pass, label);
            };
            throwBadInput("--size",
                          fmt::format("without --size the frame size is that of the graphs' sources, and they "
                                      "disagree: {} is {}x{}, {} is {}x{}",
                                      name(foundLabel, found->pass), found->width, found->height,
                                      name(g.label, n->pass), n->width, n->height),
                          "sources of one size: the graphs render at one size", "point the sources at frames of one size");
        }
        if (!found) {
            found = n;
            foundLabel = g.label;
        }
    }
    if (!found) {
        parseSize(fallback, "--size", out.x, out.y);
        return out;
    }
    spdlog::info("frame size {}x{}: the frames {} reads (no --size)", found->width, found->height, found->pass);
    return {found->width, found->height};
}

std::optional<float> parseFiniteFloat(const std::string& text) {
    char* end = nullptr;
    const float v = std::strtof(text.c_str(), &end);
    if (end == text.c_str() || !std::isfinite(v)) return std::nullopt;
    while (*end == ' ' || *end == '\t') ++end;
    if (*end != '\0') return std::nullopt;
    return v;
}

void checkFpsAndThreads(double fps, unsigned threads) {
    if (!(fps >= 1e-3 && fps <= 1e6))
        throwBadInput("--fps", fmt::format("frame rate {} is out of range", fps), "0.001 to 1000000 frames a second",
                      "e.g. 60");
    if (threads > kMaxThreads)
        throwBadInput("--threads", fmt::format("{} worker threads are too many", threads),
                      fmt::format("at most {} (0: one per core)", kMaxThreads), "leave it out to use every core");
}

std::set<uint64_t> parseFrameList(const std::string& text, const std::string& option) {
    std::set<uint64_t> frames;
    static const std::regex item(R"((\d{1,9})(?:-(\d{1,9}))?)");
    size_t start = 0;
    while (start <= text.size()) {
        size_t comma = text.find(',', start);
        std::string part = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        std::smatch m;
        if (!std::regex_match(part, m, item))
            throwBadInput(option, "'" + part + "' in '" + text + "' is not a frame or range", "a list like 3,10-12");
        uint64_t a = std::stoull(m[1]), b = m[2].matched ? std::stoull(m[2]) : a;
        if (b < a) throwBadInput(option, "range '" + part + "' runs backwards", "FIRST-LAST with FIRST <= LAST");
        if (b - a > 1000000) throwBadInput(option, "range '" + part + "' is too long", "at most 10^6 frames");
        for (uint64_t f = a; f <= b; ++f) frames.insert(f);
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    return frames;
}

PluginRegistry makeRegistry() {
    return PluginRegistry(PluginRegistry::defaultDirs());
}

void addDeviceOption(CLI::App* cmd, std::string& device, const std::string& note) {
    cmd->add_option("--device", device,
                    "where passes run unless the graph names a device for them: auto (CUDA where a GPU is usable), "
                    "cpu, cuda or emulated (the GPU path on CPU threads)" +
                        note);
}

void ensureWritableDir(const std::string& dir, const std::string& option) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
        throwBadInput(option, "'" + dir + "' exists and is not a folder", "a folder to write into",
                      "choose another " + option + " folder");
    fs::create_directories(dir, ec);
    if (ec)
        throwBadInput(option, "cannot create folder '" + dir + "': " + ec.message(), "a writable location",
                      "choose another " + option + " folder");
    if (access(dir.c_str(), W_OK) != 0)
        throwBadInput(option, "folder '" + dir + "' is not writable", "a writable folder",
                      "choose another " + option + " folder or fix its permissions");
}

CameraPath parseCameraPath(const std::string& text, const std::string& option) {
    static const std::regex re(R"((static|orbit|dolly|strafe)(?::([-+0-9.eE]+))?(?::([-+0-9.eE]+))?)");
    std::smatch m;
    if (!std::regex_match(text, m, re))
        throwBadInput(option, "'" + text + "' is not a camera path",
                      "static, orbit[:SPEED], dolly[:SPEED[:AMOUNT]] or strafe[:SPEED[:AMOUNT]], e.g. orbit:0.5");
    CameraPath path;
    path.kind = m[1] == "orbit"    ? CameraPathKind::Orbit
                : m[1] == "dolly"  ? CameraPathKind::Dolly
                : m[1] == "strafe" ? CameraPathKind::Strafe
                                   : CameraPathKind::Static;
    // Speeds as --camera-speed allows them; a dolly's amount is a fraction of the camera's distance.
    auto number = [&](const std::string& s, const char* what, float limit) {
        const std::optional<float> v = parseFiniteFloat(s);
        if (!v)
            throwBadInput(option, std::string(what) + " '" + s + "' is not a number", "e.g. orbit:0.5 or dolly:1:0.25");
        if (std::fabs(*v) > limit)
            throwBadInput(option, std::string(what) + " '" + s + "' is out of range",
                          fmt::format("a {} in [-{}, {}]", what, limit, limit));
        return *v;
    };
    if (m[2].matched) path.speed = number(m[2], "speed", 1000.f);
    if (m[3].matched) {
        if (path.kind != CameraPathKind::Dolly && path.kind != CameraPathKind::Strafe)
            throwBadInput(option, "only dolly and strafe take an amount",
                          "orbit[:SPEED], dolly[:SPEED[:AMOUNT]] or strafe[:SPEED[:AMOUNT]]");
        path.amount = number(m[3], "amount", 100.f);
    }
    return path;
}

bool writtenInto(const std::filesystem::path& file, const std::string& outDir,
                 const std::function<bool(const std::string& name)>& written) {
    std::error_code ec;
    return !file.empty() && written(file.filename().string()) &&
           std::filesystem::equivalent(file.has_parent_path() ? file.parent_path() : ".", outDir, ec);
}

void checkInputsNotOverwritten(const std::string& outDir, const std::vector<std::filesystem::path>& inputs,
                               const std::function<bool(const std::string& name)>& written, const std::string& option) {
    for (const std::filesystem::path& input : inputs)
        if (writtenInto(input, outDir, written))
            throwBadInput(option, "the run would overwrite its input " + input.string() + " in " + outDir,
                          "an output folder where no input has the name of an output",
                          "choose another output folder or move the input", input.string());
}

void applySet(RenderGraph& graph, const std::vector<std::string>& set, bool onlyKnownPasses) {
    for (const auto& s : set) {
        const auto eq = s.find('=');
        const auto dot = s.find('.');
        if (eq == std::string::npos || dot == std::string::npos || dot > eq)
            throwBadInput("--set " + s, "not an assignment", "Pass.param=value, e.g. SVGF.iterations=4");
        const std::string pass = s.substr(0, dot);
        if (onlyKnownPasses && !graph.pass(pass)) continue;
        graph.setParam(pass, s.substr(dot + 1, eq - dot - 1), parseParamValue(s.substr(eq + 1)), "--set " + s);
    }
}

}  // namespace loom::cli
