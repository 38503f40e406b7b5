// loom bench: run time against error. Renders (and caches) a per-frame reference of a scene and camera path, runs
// each graph (and each point of a parameter sweep) and the brute-force path tracer at 1, 2, 4, ... spp over the
// same sequence, and writes per-frame and summary results, the equal-error speedup, and optionally a plot.
// The protocol is documented in docs/BENCH.md.
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "BenchLag.h"
#include "BenchReport.h"
#include "CliUtil.h"
#include "Interrupt.h"
#include "SceneSetup.h"
#include "loom/Channels.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/Files.h"
#include "loom/ImageIO.h"
#include "loom/Log.h"
#include "loom/Metrics.h"
#include "loom/Parallel.h"
#include "loom/Params.h"
#include "loom/Reflection.h"
#include "loom/RenderGraph.h"
#include "loom/StatNames.h"

namespace loom::cli {

namespace {

namespace fs = std::filesystem;
using bench::FrameMetrics;
using bench::FrameResult;
using bench::Run;

// The command names no pass type, parameter or field: it asks for the one that declares a role. The path tracer is
// the pass whose parameters declare a sample count (ParamRole::SampleCount; its path length, Russian roulette and
// pixel filter are the parameters that declare MaxBounces, RussianRouletteStart and PixelFilter), the reference's
// accumulator the pass that declares ParamRole::AutoReset (it reports stat::kAccumulatedFrames), and the measured
// image what feeds the input that declares FieldRole::DisplayInput.

/// Reference batches use PathTracer seeds from here on, so their samples are independent of every graph's and of
/// the brute-force runs (which use seed 0 unless --set says otherwise).
constexpr uint32_t kReferenceSeedBase = 1u << 24;
/// Brute-force batches after the first use PathTracer seeds from here on (batch k: seed + k), so each batch is new.
constexpr uint32_t kBruteForceSeedBase = 1u << 25;
/// Bumped when the reference rendering protocol changes, so old cache entries are not reused.
constexpr int kCacheFormat = 2;
/// Brute-force times: the median of this many frames rendered directly at each spp (the first measured ones).
constexpr uint64_t kBruteForceTimingFrames = 3;
/// The reference noise should be this far below the smallest measured error.
constexpr double kNoiseMargin = 10.0;
const char* const kColorField = channel::kColor;

struct BenchOptions {
    SceneOptions scene;
    std::string device;  ///< --device: where the benchmarked graphs' passes run (references: the graphs' own)
    uint64_t frames = 32;
    std::string size;  ///< --size; without it (see given), the graphs' sources give the size (frameSize)
    std::vector<std::string> graphs;
    std::vector<std::string> sweeps;
    std::vector<std::string> set;
    std::string measure;
    std::string referenceGraph;
    uint32_t referenceSpp = 256;
    std::string bruteForceGraph;
    std::string bruteForceSpp;
    uint32_t bruteForceMax = 1024;
    std::string referenceBounces = "graph";
    uint64_t warmup = 16;
    double fps = 60.0;
    std::string cache;
    std::string out = "bench";
    bool plot = false;
    std::string plotScript;
    std::string python = "/usr/bin/python3";
    unsigned threads = 0;
    std::vector<uint32_t> eventFrames;  ///< --event-frame: lighting steps the lag figures measure the recovery after
    std::string referenceSequence;      ///< --reference-sequence: given reference frames, "PATTERN[:LAYER]"
    int64_t referenceFirstFrame = 0;    ///< --reference-first-frame: the file number of bench frame 0
    bool referencesOnly = false;        ///< --references-only: fill the reference cache, measure nothing
    std::string referenceFrames;        ///< --reference-frames: with --references-only, the frames to render
    std::set<std::string> given;        ///< which of the options below were given (not only their values)
};

/// Options whose presence (not only their value) matters: those that apply to a scene, to the brute-force curve or
/// to rendered references, refused where they would do nothing.
const char* const kSceneOptions[] = {"--camera-path",           "--camera-speed", "--jitter",
                                     "--jitter-count",          "--env",          "--texture-budget",
                                     "--allow-missing-textures"};
const char* const kBruteForceOptions[] = {"--brute-force-graph", "--brute-force-max"};
const char* const kRenderedReferenceOptions[] = {"--reference-graph", "--reference-spp", "--reference-bounces"};

/// One parameter sweep: Pass.param over values.
struct Sweep {
    std::string text;  ///< as given, for messages
    std::string pass, param;
    std::vector<std::string> values;  ///< as given
};

/// A graph to run with its sweep assignment (if any).
struct Variant {
    std::string file;
    GraphDesc desc;
    const Sweep* sweep = nullptr;
    std::string value;  ///< the sweep value
    std::string label() const { return sweep ? sweep->pass + "." + sweep->param + "=" + value : std::string(); }
};

std::string sourcePath(const std::string& rel) {
    return std::string(LOOM_SOURCE_DIR) + "/" + rel;
}

/// The bytes of a regular file (what the cache keys hash); nothing for a pipe, a device or a folder, which are
/// never read (a pipe may block for ever, a device never end); those inputs are refused where they are loaded.
std::string readBytes(const fs::path& path) {
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) return {};
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string loadAverage() {
    std::string text = readBytes("/proc/loadavg");
    std::istringstream in(text);
    std::string a, b, c;
    in >> a >> b >> c;
    return a.empty() ? std::string("unknown") : a + " " + b + " " + c;
}

/// 64-bit FNV-1a: a stable hash (std::hash is not stable across builds) for cache keys.
uint64_t fnv1a(const std::string& bytes) {
    uint64_t h = 1469598103934665603ull;
    for (unsigned char c : bytes) {
        h ^= c;
        h *= 1099511628211ull;
    }
    return h;
}

/// A graph given by path, or by the name of a shipped graph ("PathTracerSVGF" -> graphs/PathTracerSVGF.json).
std::string resolveGraph(const std::string& text, const std::string& option) {
    std::error_code ec;
    if (fs::exists(text, ec)) return text;
    if (text.find('/') == std::string::npos) {
        const std::string shipped = sourcePath("graphs/" + (text.ends_with(".json") ? text : text + ".json"));
        if (fs::exists(shipped, ec)) return shipped;
    }
    throwBadInput(option, "graph '" + text + "' does not exist",
                  "a graph file, or the name of a shipped graph in " + sourcePath("graphs"),
                  "e.g. --graph PathTracerSVGF or --graph graphs/PathTracerSVGF.json");
}

/// Splits a comma list at top level (commas inside [...] or {...} belong to a JSON value).
std::vector<std::string> splitValues(const std::string& text) {
    std::vector<std::string> out;
    std::string cur;
    int depth = 0;
    for (char c : text) {
        if (c == '[' || c == '{') ++depth;
        if (c == ']' || c == '}') --depth;
        if (c == ',' && depth == 0) {
            out.push_back(cur);
            cur.clear();
        } else {
            cur += c;
        }
    }
    out.push_back(cur);
    return out;
}

Sweep parseSweep(const std::string& text) {
    const std::string where = "--sweep " + text;
    const auto eq = text.find('=');
    const auto dot = text.find('.');
    if (eq == std::string::npos || dot == std::string::npos || dot > eq || dot == 0 || dot + 1 == eq)
        throwBadInput(where, "not a sweep", "Pass.param=v1,v2,..., e.g. SVGF.iterations=1,2,3,4,5");
    Sweep s;
    s.text = text;
    s.pass = text.substr(0, dot);
    s.param = text.substr(dot + 1, eq - dot - 1);
    s.values = splitValues(text.substr(eq + 1));
    for (const auto& v : s.values)
        if (v.empty()) throwBadInput(where, "empty value in the sweep", "a comma-separated list of values, e.g. 1,2,3");
    return s;
}

/// Is `input` (Pass.field) of a compiled graph the linear image its pass maps for display (FieldRole::DisplayInput)?
bool isDisplayInput(const RenderGraph& graph, const ChannelRef& input) {
    Reflection r;
    CompileInfo info;
    info.frameWidth = graph.plan().width;
    info.frameHeight = graph.plan().height;
    graph.pass(input.pass)->reflect(r, info);
    const FieldDesc* f = r.findRole(FieldRole::DisplayInput);
    return f && f->name == input.channel;
}

/// The field a graph's metrics are taken of: --measure, else the linear HDR image feeding the display transform's
/// input (ToneMap.src), else the first marked output. The graph must be compiled.
ChannelRef measuredField(const RenderGraph& graph, const std::string& measure, const std::string& file) {
    if (!measure.empty()) return parseChannelRef(measure, "--measure");
    for (const Wire& w : graph.plan().wires)
        if (!w.src.prev && isDisplayInput(graph, w.dst)) return w.src;
    if (graph.outputs().empty())
        throwBadInput("outputs", "the graph marks no output", "an RGBA32F output to measure", "", file);
    return graph.outputs().front();
}

/// Builds, configures and compiles one graph with its measured field observed.
struct PreparedGraph {
    std::unique_ptr<RenderGraph> graph;
    ChannelRef measured;
    std::vector<std::string> ageFields;  ///< the G-buffer fields of the disocclusion lag (none without a G-buffer)
};

PreparedGraph prepareGraph(const GraphDesc& desc, const std::string& file, PluginRegistry& registry,
                           const std::shared_ptr<Scene>& scene, const std::vector<std::string>& set,
                           bool onlyKnownPasses, const std::function<void(RenderGraph&)>& configure,
                           const std::string& measure, uint32_t width, uint32_t height,
                           const std::string& device) {
    PreparedGraph p;
    p.graph = std::make_unique<RenderGraph>(desc, registry);
    if (scene) p.graph->setScene(scene);
    applySet(*p.graph, set, onlyKnownPasses);
    if (configure) configure(*p.graph);
    CompileOptions copts;
    copts.width = width;
    copts.height = height;
    copts.device = device;
    p.graph->compile(copts);
    p.measured = measuredField(*p.graph, measure, file);
    if (!p.graph->pass(p.measured.pass))
        throwBadInput("--measure", "graph '" + desc.name + "' has no pass '" + p.measured.pass + "'",
                      "a Pass.field of every benchmarked graph", "", file);
    // Observing keeps the field allocated and readable after the frame; it never changes a rendered value.
    copts.observe = {p.measured.pass + "." + p.measured.channel};
    p.ageFields = bench::ageGBufferFields(*p.graph);
    copts.observe.insert(copts.observe.end(), p.ageFields.begin(), p.ageFields.end());
    p.graph->compile(copts);
    const Texture* tex = p.graph->fieldTexture(p.measured.str());
    if (!tex)
        throwBadInput("--measure", "field '" + p.measured.str() + "' is not computed by graph '" + desc.name + "'",
                      "a field of a live pass", "list the fields with `loom check --graph " + file + "`", file);
    if (tex->format() != Format::RGBA32F)
        throwBadInput("--measure", "field '" + p.measured.str() + "' is not RGBA32F", "a linear RGBA32F image", "",
                      file);
    return p;
}

Texture copyTexture(const Texture& src) {
    Texture t(src.width(), src.height(), src.format());
    t.copyFrom(src);
    return t;
}

// ---------------------------------------------------------------------------------------------------------------
// Reference cache

fs::path defaultCacheDir() {
    if (const char* c = std::getenv("LOOM_CACHE"); c && *c) return fs::path(c);
    if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return fs::path(x) / "loom" / "references";
    if (const char* h = std::getenv("HOME"); h && *h) return fs::path(h) / ".cache" / "loom" / "references";
    return fs::temp_directory_path() / "loom-references";
}

/// Hash of the scene: the file's bytes and, for a .gltf, those of every external buffer and image it names.
uint64_t sceneHash(const fs::path& scene) {
    std::string bytes = readBytes(scene);
    if (scene.extension() == ".gltf") {
        const nlohmann::json j = nlohmann::json::parse(bytes, nullptr, false);
        if (j.is_object()) {
            for (const char* list : {"buffers", "images"}) {
                if (!j.contains(list) || !j[list].is_array()) continue;
                for (const auto& item : j[list]) {
                    if (!item.is_object() || !item.contains("uri") || !item["uri"].is_string()) continue;
                    const std::string uri = item["uri"].get<std::string>();
                    if (uri.rfind("data:", 0) != 0) bytes += uri + readBytes(scene.parent_path() / uri);
                }
            }
        }
    }
    return fnv1a(bytes);
}

/// What the sequence depends on, as text (shared by the reference and brute-force cache keys).
std::string sequenceKeyText(const BenchOptions& o, uint32_t width, uint32_t height) {
    std::string env = o.scene.env;
    std::error_code ec;
    if (!env.empty() && fs::is_regular_file(env, ec)) env += " bytes " + fmt::format("{:016x}", fnv1a(readBytes(env)));
    return fmt::format(
        "loom reference cache format {}\nloom version {}\nscene {} bytes {:016x}\nsize {}x{}\ncamera path {} speed "
        "{}\njitter {} count {}\nenvironment {}\n",
        kCacheFormat, loom::version(), fs::path(o.scene.scene).filename().string(), sceneHash(o.scene.scene), width,
        height, o.scene.cameraPath, o.scene.cameraSpeed, o.scene.jitter, o.scene.jitterCount, env);
}

/// How a reference is rendered: the reference graph, its path tracer set to these values.
struct ReferenceSpec {
    std::optional<int> maxBounces;                 ///< overrides the reference graph's when set
    std::string pixelFilter = kPixelFilterCenter;  ///< the path tracer's ParamRole::PixelFilter
    uint64_t firstFrame = 0;                       ///< frames before it are not needed (left empty)
    std::string label = "reference";
    const std::set<uint64_t>* only = nullptr;  ///< with it, frames outside it are neither rendered nor read
};

/// Reference frames given as files (--reference-sequence): bench frame i is the file numbered i + first of the
/// pattern, its layer read as RGBA32F. Every frame is checked once up front (it exists, has the bench's size and
/// the layer, reads whole and holds only finite values), so bad input fails before anything runs; afterwards a
/// frame is read again when a run needs it, and the last kSlots stay in memory (a frame and its predecessor are what
/// a run reads together), so memory does not grow with --frames.
class SequenceReferences {
public:
    SequenceReferences(const std::string& spec, int64_t first, uint64_t frames, uint32_t width, uint32_t height)
        : mSource(parseSequenceSource(spec)), mFirst(first), mWidth(width), mHeight(height) {
        for (uint64_t i = 0; i < frames; ++i) {
            throwIfStopRequested();
            (void)load(i);
        }
        spdlog::info("reference: {} frame(s) of {}{}", frames, mSource.pattern,
                     mSource.layer.empty() ? std::string() : " (layer " + mSource.layer + ")");
    }

    /// The image of bench frame i; valid until kSlots other frames have been asked for.
    const Texture& frame(uint64_t i) {
        Slot* slot = nullptr;
        for (Slot& s : mSlots)
            if (s.frame == i) slot = &s;
        if (!slot) {
            slot = &*std::min_element(mSlots.begin(), mSlots.end(),
                                      [](const Slot& a, const Slot& b) { return a.used < b.used; });
            slot->frame = i;
            slot->image = load(i);
        }
        slot->used = ++mClock;
        return slot->image;
    }

private:
    static constexpr size_t kSlots = 3;
    struct Slot {
        uint64_t frame = std::numeric_limits<uint64_t>::max();
        uint64_t used = 0;
        Texture image;
    };

    /// Reads bench frame i's file; loom::Error (BadInput) naming the file and the frame for every problem.
    Texture load(uint64_t i) const {
        const int64_t number = int64_t(i) + mFirst;
        const std::string file = sequenceFramePath(mSource.pattern, number, "--reference-sequence");
        const std::string frameText = fmt::format("the reference of frame {} (file number {})", i, number);
        std::error_code ec;
        if (!fs::is_regular_file(file, ec))
            throwBadInput("--reference-sequence",
                          frameText + (fs::exists(file, ec) ? " is not a regular file" : " does not exist"),
                          "one EXR file per bench frame, frame i numbered i + --reference-first-frame",
                          mFirst == 0 ? "if the sequence is numbered from 1 (Blender), add --reference-first-frame 1"
                                      : "check the pattern, --reference-first-frame and --frames",
                          file);
        Texture image;
        try {
            ExrFile exr(file);
            if (exr.width() != mWidth || exr.height() != mHeight)
                throwBadInput("--reference-sequence",
                              fmt::format("{} is {}x{}, the bench renders at {}x{}", frameText, exr.width(),
                                          exr.height(), mWidth, mHeight),
                              "references of the bench's size",
                              fmt::format("use --size {}x{}", exr.width(), exr.height()), file);
            image = exr.readRgba(mSource.layer);
        } catch (const Error& e) {
            // ExrFile names the file and the layer; the frame is said here.
            if (e.info().where == "--reference-sequence") throw;
            Error::Info info = e.info();
            info.where = "--reference-sequence";
            info.what = frameText + ": " + info.what;
            if (info.file.empty()) info.file = file;
            throw Error(info);
        }
        const auto v = image.view<glm::vec4>();
        uint64_t nonFinite = 0;
        for (uint32_t y = 0; y < image.height(); ++y)
            for (uint32_t x = 0; x < image.width(); ++x) {
                const glm::vec4 c = v.at(x, y);
                nonFinite += !(std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z) && std::isfinite(c.w));
            }
        if (nonFinite)
            throwBadInput("--reference-sequence",
                          fmt::format("{} has {} pixel(s) with a NaN or infinite value", frameText, nonFinite),
                          "a reference of finite values only", "", file);
        return image;
    }

    SequenceSource mSource;
    int64_t mFirst;
    uint32_t mWidth, mHeight;
    std::array<Slot, kSlots> mSlots;
    uint64_t mClock = 0;
};

/// A reference sequence's images by frame index: rendered ones (a shared, static, reference is one image that
/// serves every frame, held once rather than copied per frame: memory that grew with --frames), or given ones.
struct ReferenceFrames {
    const std::vector<Texture>* images = nullptr;
    SequenceReferences* sequence = nullptr;
    const Texture& operator[](size_t i) const {
        if (sequence) return sequence->frame(i);
        return images->size() == 1 ? images->front() : (*images)[i];
    }
};

/// A reference sequence: one image per frame (empty before the spec's first frame), the per-frame noise estimate
/// (RelMSE term; empty with a single batch), and where it came from.
struct ReferenceSet {
    std::vector<Texture> frames;
    std::vector<std::optional<double>> noise;
    bool shared = false;
    int maxBounces = 0, rrStartBounce = 0;
    std::string cache;
    uint64_t cached = 0, rendered = 0;

    /// Mean noise over frames [first, end); empty when any is unknown.
    std::optional<double> meanNoise(uint64_t first) const {
        double sum = 0;
        size_t n = 0;
        for (size_t i = first; i < noise.size(); ++i) {
            if (!noise[i]) return std::nullopt;
            sum += *noise[i];
            ++n;
        }
        return n ? std::optional<double>(sum / double(n)) : std::nullopt;
    }
};

/// The reference's own noise as a RelMSE term: the mean over pixels and channels of the variance of its mean
/// (`variance`, per channel) over ref^2 + eps. It adds about this much to any error measured against it.
double noiseRelMSE(const Texture& ref, const Texture& variance) {
    const auto r = ref.view<glm::vec4>();
    const auto v = variance.view<glm::vec4>();
    double sum = 0;
    uint64_t n = 0;
    for (uint32_t y = 0; y < ref.height(); ++y)
        for (uint32_t x = 0; x < ref.width(); ++x)
            for (int c = 0; c < 3; ++c) {
                const double rv = r.at(x, y)[c], vv = v.at(x, y)[c];
                if (!std::isfinite(rv) || !std::isfinite(vv)) continue;
                sum += vv / (rv * rv + kRelMseEpsilon);
                ++n;
            }
    return n ? sum / double(n) : 0.0;
}

/// A pass of a graph description and its parameter that plays a role.
struct RoleParam {
    std::string pass, param;  ///< both empty when no pass declares the role
};

/// The last pass of a graph description whose parameters declare `role`. Types the registry does not know are
/// skipped: building the graph reports them.
RoleParam findRole(const GraphDesc& desc, PluginRegistry& registry, ParamRole role) {
    RoleParam out;
    for (const PassDesc& p : desc.passes) {
        if (!registry.knows(p.type)) continue;
        if (const ParamDecl* d = registry.create(p.type)->params().findRole(role)) out = {p.name, d->name};
    }
    return out;
}

/// The path tracer of a graph description (the last pass that declares a sample count per pixel), or "".
std::string tracerOf(const GraphDesc& desc, PluginRegistry& registry) {
    return findRole(desc, registry, ParamRole::SampleCount).pass;
}

/// The name of the parameter of a built graph's pass that plays `role`.
std::string roleParam(const RenderGraph& graph, const std::string& pass, ParamRole role) {
    const ParamDecl* d = graph.pass(pass)->params().findRole(role);
    if (!d)
        throwBadInput(pass, fmt::format("pass '{}' declares no {} parameter", pass, paramRoleName(role)),
                      fmt::format("a path tracer whose parameters declare a sample count, a seed, a path length, "
                                  "a Russian roulette start and a pixel filter (the {} role among them)",
                                  paramRoleName(role)));
    return d->name;
}

/// The current value (default included) of the int parameter of a pass of a built graph that plays `role`; 0 when
/// none does.
int roleInt(const RenderGraph& graph, const std::string& pass, ParamRole role) {
    const ParamDecl* d = graph.pass(pass)->params().findRole(role);
    const nlohmann::json j = d ? d->get() : nlohmann::json();
    return j.is_number_integer() ? j.get<int>() : 0;
}

/// Renders or loads the reference of every frame. Per frame: the reference graph's history is reset, the scene is
/// set to the frame's time with no motion, and the graph runs spp / batchSpp times with different PathTracer
/// seeds while its AccumulatePass averages them; the spread of the batches gives the variance of their mean. Each
/// image (and its variance) is written to the cache atomically.
ReferenceSet references(const BenchOptions& o, PluginRegistry& registry, const std::shared_ptr<Scene>& scene,
                        uint32_t width, uint32_t height, const ReferenceSpec& spec) {
    ReferenceSet out;
    // With a box filter the image does not depend on the camera jitter.
    const bool shared = !scene->hasMotion() && (o.scene.jitter == "none" || spec.pixelFilter == kPixelFilterBox);
    out.shared = shared;
    const GraphDesc desc = loadGraph(o.referenceGraph);  // checked before its bytes are hashed

    const RoleParam spp = findRole(desc, registry, ParamRole::SampleCount);
    const RoleParam reset = findRole(desc, registry, ParamRole::AutoReset);
    const std::string &tracer = spp.pass, &accumulate = reset.pass;
    uint32_t batchSpp = 1;
    if (const PassDesc* p = desc.findPass(tracer);
        p && p->params.contains(spp.param) && p->params[spp.param].is_number_unsigned())
        batchSpp = p->params[spp.param].get<uint32_t>();
    if (tracer.empty() || accumulate.empty())
        throwBadInput("--reference-graph", "the reference graph needs a path tracer and an AccumulatePass",
                      "a graph like graphs/Reference.json", "", o.referenceGraph);
    batchSpp = std::max(1u, std::min(batchSpp, o.referenceSpp));
    if (o.referenceSpp % batchSpp != 0)
        throwBadInput(
            "--reference-spp",
            fmt::format("{} is not a multiple of the reference graph's {} spp per frame", o.referenceSpp, batchSpp),
            fmt::format("a multiple of {} (or at most {})", batchSpp, batchSpp));
    uint32_t batches = o.referenceSpp / batchSpp;
    // At least 4 batches where the count allows: their spread gives the reference's noise.
    while (batches < 4 && batchSpp % 2 == 0) {
        batchSpp /= 2;
        batches *= 2;
    }

    auto graph = std::make_unique<RenderGraph>(desc, registry);
    graph->setScene(scene);
    graph->setParam(tracer, spp.param, batchSpp, "--reference-spp");
    const std::string seedParam = roleParam(*graph, tracer, ParamRole::Seed);
    if (spec.maxBounces)
        graph->setParam(tracer, roleParam(*graph, tracer, ParamRole::MaxBounces), *spec.maxBounces,
                        "--reference-bounces");
    graph->setParam(tracer, roleParam(*graph, tracer, ParamRole::PixelFilter), spec.pixelFilter,
                    "reference pixel filter");
    CompileOptions copts;
    copts.width = width;
    copts.height = height;
    copts.observe = {tracer + "." + kColorField};  // each batch's mean, for the noise estimate
    graph->compile(copts);
    out.maxBounces = roleInt(*graph, tracer, ParamRole::MaxBounces);
    out.rrStartBounce = roleInt(*graph, tracer, ParamRole::RussianRouletteStart);

    const std::string key =
        sequenceKeyText(o, width, height) +
        fmt::format(
            "reference graph {} bytes {:016x}\nreference spp {}\npath tracer maxBounces {} rrStartBounce {} "
            "pixelFilter {}\n{}\n",
            fs::path(o.referenceGraph).filename().string(), fnv1a(readBytes(o.referenceGraph)), o.referenceSpp,
            out.maxBounces, out.rrStartBounce, spec.pixelFilter,
            shared ? std::string("frames: one image for every time (nothing moves)")
                   : fmt::format("frames: frame index i at time i / {} s", o.fps));
    const fs::path cacheRoot = o.cache.empty() ? defaultCacheDir() : fs::path(o.cache);
    const fs::path entry =
        cacheRoot / fmt::format("{}_{}x{}_{}spp_{}b_{:016x}", fs::path(o.scene.scene).stem().string(), width, height,
                                o.referenceSpp, out.maxBounces, fnv1a(key));
    ensureWritableDir(entry.string(), "--cache");
    writeFileAtomic(entry / "key.txt", key);
    out.cache = entry.string();

    // Renders frame `frame`: its mean, and the variance of that mean per channel (none with one batch).
    auto render = [&](uint64_t frame, Texture& variance) {
        graph->resetHistory();
        const FrameInfo f = sceneFrame(*scene, frame, o.fps, width, height, true);
        const size_t n = size_t(width) * height * 3;
        std::vector<double> mean(n, 0.0), m2(n, 0.0);
        for (uint32_t b = 0; b < batches; ++b) {
            throwIfStopRequested();  // between batches: a reference frame can take long
            graph->setParam(tracer, seedParam, kReferenceSeedBase + b, "reference");
            graph->execute(f);
            // Welford over the batch means, per pixel and channel.
            const auto c = graph->fieldTexture(tracer + "." + kColorField)->view<glm::vec4>();
            for (uint32_t y = 0; y < height; ++y)
                for (uint32_t x = 0; x < width; ++x)
                    for (int ch = 0; ch < 3; ++ch) {
                        const size_t i = (size_t(y) * width + x) * 3 + size_t(ch);
                        const double v = c.at(x, y)[ch], d = v - mean[i];
                        mean[i] += d / double(b + 1);
                        m2[i] += d * (v - mean[i]);
                    }
        }
        const auto stats = graph->lastStats();
        const auto acc = stats.find(accumulate);
        if (acc != stats.end() && acc->second.count(stat::kAccumulatedFrames) &&
            acc->second.at(stat::kAccumulatedFrames) != double(batches))
            throw Error({ErrorKind::Runtime, o.referenceGraph, accumulate,
                         fmt::format("the reference accumulated {} of {} batches (it restarted)",
                                     acc->second.at(stat::kAccumulatedFrames), batches),
                         "",
                         fmt::format("set {} false on the reference graph's {}", reset.param,
                                     desc.findPass(accumulate)->type)});
        if (batches >= 2) {
            variance = Texture(width, height, Format::RGBA32F);
            auto v = variance.view<glm::vec4>();
            for (uint32_t y = 0; y < height; ++y)
                for (uint32_t x = 0; x < width; ++x) {
                    const size_t i = (size_t(y) * width + x) * 3;
                    glm::vec4 px(0.f, 0.f, 0.f, 1.f);
                    for (int ch = 0; ch < 3; ++ch)
                        px[ch] = float(m2[i + size_t(ch)] / double(batches - 1) / double(batches));
                    v.at(x, y) = px;
                }
        }
        return copyTexture(*graph->fieldTexture(graph->outputs().front().str()));
    };

    const uint64_t count = shared ? 1 : o.frames;
    for (uint64_t i = 0; i < count; ++i) {
        // A shared image is frame 0's: the worker whose selection holds frame 0 renders it.
        if ((!shared && i < spec.firstFrame) || (spec.only && !spec.only->count(i))) {
            out.frames.emplace_back();
            out.noise.emplace_back();
            continue;
        }
        const std::string stem = shared ? std::string("static") : fmt::format("frame_{:06}", i);
        const fs::path file = entry / (stem + ".exr"), varFile = entry / (stem + "_var.exr");
        auto usable = [&](const Texture& t) {
            return t.width() == width && t.height() == height && t.format() == Format::RGBA32F;
        };
        std::error_code ec;
        if (fs::exists(file, ec) && (batches < 2 || fs::exists(varFile, ec))) {
            Texture t = readImage(file);
            Texture var = batches >= 2 ? readImage(varFile) : Texture();
            if (usable(t) && (batches < 2 || usable(var))) {
                out.noise.push_back(batches >= 2 ? std::optional<double>(noiseRelMSE(t, var)) : std::nullopt);
                out.frames.push_back(std::move(t));
                ++out.cached;
                continue;
            }
            spdlog::warn("{} {} has the wrong size or format; rendering it again", spec.label, file.string());
        }
        const auto start = std::chrono::steady_clock::now();
        Texture var;
        out.frames.push_back(render(i, var));
        if (batches >= 2) writeImage(varFile, var);  // before the image: an image in the cache has its variance
        writeImage(file, out.frames.back());
        out.noise.push_back(batches >= 2 ? std::optional<double>(noiseRelMSE(out.frames.back(), var)) : std::nullopt);
        ++out.rendered;
        spdlog::info("{} {}/{} rendered ({} spp, {} bounces, {:.1f} s)", spec.label, i + 1, count, o.referenceSpp,
                     out.maxBounces, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
    if (out.rendered == 0)
        spdlog::info("{}: cache hit, {} frame(s) from {}", spec.label, out.cached, entry.string());
    else
        spdlog::info("{}: {} frame(s) rendered, {} from the cache, in {}", spec.label, out.rendered, out.cached,
                     entry.string());
    // A shared reference serves every frame: one image (ReferenceFrames), its noise repeated.
    while (out.noise.size() < o.frames) out.noise.push_back(out.noise.front());
    return out;
}

// ---------------------------------------------------------------------------------------------------------------
// Runs

FrameMetrics measure(const Texture& test, const Texture& ref, const Texture* testPrev, const Texture* refPrev) {
    FrameMetrics m;
    const MetricValue relmse = relMSE(test, ref), sm = smape(test, ref), ps = psnr(test, ref), ss = ssim(test, ref),
                      fl = flip(test, ref), tr = trimmedRelMSE(test, ref);
    m.relMSE = relmse.value;
    m.trimmedRelMSE = tr.value;
    m.smape = sm.value;
    m.psnr = ps.value;
    m.ssim = ss.value;
    m.flip = fl.value;
    m.nonFinite = std::max({relmse.nonFinite, sm.nonFinite, ps.nonFinite, ss.nonFinite, fl.nonFinite});
    if (testPrev && refPrev) {
        const MetricValue t = temporalError(test, *testPrev, ref, *refPrev);
        m.temporal = t.value;
        m.nonFinite = std::max(m.nonFinite, t.nonFinite);
    }
    return m;
}

/// Runs a prepared graph over frames [first, frames) from the start of its history, measuring every frame; `scene`
/// is nullptr for a graph that reads its inputs from files (the frames follow the clock alone). With
/// `flicker`, the frames from `warmup` on also go into a FlickerAccumulator whose value lands there. With `ages`, every
/// frame's G-buffer goes to the age tracker of the disocclusion lag.
std::vector<FrameResult> runSequence(PreparedGraph& p, Scene* scene, ReferenceFrames refs, uint64_t first,
                                     uint64_t frames, double fps, uint32_t width, uint32_t height,
                                     const std::string& label, uint64_t warmup = 0,
                                     std::optional<double>* flicker = nullptr,
                                     bench::DisocclusionTracker* ages = nullptr) {
    std::vector<FrameResult> out;
    Texture prev;
    FlickerAccumulator flickerAcc;
    p.graph->resetHistory();
    const auto start = std::chrono::steady_clock::now();
    for (uint64_t i = first; i < frames; ++i) {
        throwIfStopRequested();
        const FrameInfo f = sceneFrame(scene, i, fps, width, height, i == first);
        const auto t0 = std::chrono::steady_clock::now();
        p.graph->execute(f);
        const auto t1 = std::chrono::steady_clock::now();
        FrameResult r;
        r.frame = i;
        r.time = f.time;
        r.totalMs = std::chrono::duration<double, std::milli>(t1 - t0).count();
        for (const PassTiming& t : p.graph->timings()) r.passMs.emplace_back(t.name, t.lastMs);
        const Texture& test = *p.graph->fieldTexture(p.measured.str());
        const bool hasPrev = i > first;
        r.metrics = measure(test, refs[i], hasPrev ? &prev : nullptr, hasPrev ? &refs[i - 1] : nullptr);
        if (flicker && i >= warmup) flickerAcc.add(test);
        if (ages)
            if (const auto g = bench::ageGBuffer(*p.graph, p.ageFields))
                ages->addFrame(*g, test, refs[i], i == first, i >= warmup);
        if (prev.empty()) prev = Texture(test.width(), test.height(), test.format());
        prev.copyFrom(test);
        out.push_back(std::move(r));
    }
    if (flicker) *flicker = flickerAcc.frames() >= 2 ? std::optional<double>(flickerAcc.value().value) : std::nullopt;
    spdlog::info("{}: {} frame(s) in {:.1f} s", label, frames - first,
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    return out;
}

/// The lag figures of a run (BenchLag.h) from its frames' RelMSE.
bench::Lag runLag(const std::vector<FrameResult>& frames, const std::vector<uint32_t>& events,
                  const bench::DisocclusionTracker* ages) {
    std::vector<double> relMSE;
    for (const FrameResult& f : frames) relMSE.push_back(f.metrics.relMSE);
    return bench::runLag(relMSE, frames.empty() ? 0 : frames.front().frame, events, ages);
}

/// The brute-force curve: its runs (increasing spp) and where its cached images are.
struct BruteForceCurve {
    std::vector<Run> runs;
    std::string cache;
    uint64_t cached = 0, rendered = 0;
};

/// Whether curve point `point` reaches (is at or below) the error of every variant in every equal-error metric.
bool crossesEveryVariant(const bench::Summary& point, const std::vector<Run>& variants) {
    for (const Run& v : variants)
        if (point.relMSE > v.summary.relMSE || point.trimmedRelMSE > v.summary.trimmedRelMSE ||
            point.flip > v.summary.flip)
            return false;
    return true;
}

/// Runs the brute-force graph at each spp of `spps` (increasing) over frames [first, frames). The image of point k
/// (n_k spp) is the mean of point k-1's image (cached) and a new batch of n_k - n_(k-1) spp with its own seed, so
/// the whole curve costs about its largest point. Every image is cached (keyed by the sequence, the brute-force
/// graph, --set and the spp chain), so a later run reuses it. A point's time is the median of `timingFrames`
/// frames rendered directly at its spp (seed as given), from the warm-up on. With `stopWhenCrossed`, the curve
/// ends at the first point that reaches every variant's error.
BruteForceCurve bruteForceCurve(const BenchOptions& o, PreparedGraph& brute, const std::string& tracer,
                                const std::string& bruteKey, Scene& scene, ReferenceFrames refs,
                                const std::vector<uint32_t>& spps, bool stopWhenCrossed,
                                const std::vector<Run>& variants, uint32_t width, uint32_t height, bool flicker) {
    BruteForceCurve out;
    const fs::path cacheRoot = o.cache.empty() ? defaultCacheDir() : fs::path(o.cache);
    const fs::path entry =
        cacheRoot / fmt::format("{}_{}x{}_bruteforce_{:016x}", fs::path(o.scene.scene).stem().string(), width, height,
                                fnv1a(bruteKey));
    ensureWritableDir(entry.string(), "--cache");
    writeFileAtomic(entry / "key.txt", bruteKey);
    out.cache = entry.string();
    const std::string sppParam = roleParam(*brute.graph, tracer, ParamRole::SampleCount);
    const std::string seedParam = roleParam(*brute.graph, tracer, ParamRole::Seed);
    const uint32_t seed = uint32_t(roleInt(*brute.graph, tracer, ParamRole::Seed));
    // Brute force has no history: of the warm-up frames it runs only the last one (which gives the first measured
    // frame its temporal predecessor).
    const uint64_t first = o.warmup > 0 ? o.warmup - 1 : 0;
    const uint64_t timingFrames = std::min<uint64_t>(kBruteForceTimingFrames, o.frames - o.warmup);
    std::string chain;
    uint32_t prevSpp = 0;
    for (size_t k = 0; k < spps.size(); ++k) {
        const uint32_t n = spps[k], batch = n - prevSpp;
        const std::string prevChain = chain;
        chain += (chain.empty() ? "" : ",") + std::to_string(n);
        auto fileOf = [&](const std::string& c, uint32_t spp, uint64_t i) {
            return entry / fmt::format("{}spp_{:08x}_frame_{:06}.exr", spp, uint32_t(fnv1a(c)), i);
        };
        Run r;
        r.bruteForce = true;
        r.graph = brute.graph->desc().name;
        r.graphFile = o.bruteForceGraph;
        r.params = fmt::format("{}.{}={}", tracer, sppParam, n);
        r.spp = n;
        r.measured = brute.measured.str();
        const auto start = std::chrono::steady_clock::now();

        // Times: frames rendered directly at n spp.
        std::vector<std::pair<double, std::vector<std::pair<std::string, double>>>> times;
        brute.graph->setParam(tracer, sppParam, n, "--brute-force-spp");
        brute.graph->setParam(tracer, seedParam, seed, "brute force");
        for (uint64_t t = 0; t < timingFrames; ++t) {
            throwIfStopRequested();
            const FrameInfo f = sceneFrame(scene, o.warmup + t, o.fps, width, height, true);
            const auto t0 = std::chrono::steady_clock::now();
            brute.graph->execute(f);
            const auto t1 = std::chrono::steady_clock::now();
            std::vector<std::pair<std::string, double>> passMs;
            for (const PassTiming& pt : brute.graph->timings()) passMs.emplace_back(pt.name, pt.lastMs);
            times.emplace_back(std::chrono::duration<double, std::milli>(t1 - t0).count(), std::move(passMs));
        }

        // Images: the cached mean of the previous point plus a new batch.
        brute.graph->setParam(tracer, sppParam, batch, "--brute-force-spp");
        brute.graph->setParam(tracer, seedParam, k == 0 ? seed : kBruteForceSeedBase + seed + uint32_t(k),
                              "brute force");
        FlickerAccumulator flickerAcc;
        Texture prevImage;
        for (uint64_t i = first; i < o.frames; ++i) {
            const fs::path file = fileOf(chain, n, i);
            Texture image;
            std::error_code ec;
            if (fs::exists(file, ec)) {
                image = readImage(file);
                if (image.width() != width || image.height() != height || image.format() != Format::RGBA32F)
                    image = Texture();
            }
            if (image.empty()) {
                throwIfStopRequested();
                brute.graph->execute(sceneFrame(scene, i, o.fps, width, height, i == first));
                image = copyTexture(*brute.graph->fieldTexture(brute.measured.str()));
                if (k > 0) {
                    const Texture before = readImage(fileOf(prevChain, prevSpp, i));
                    if (before.width() != width || before.height() != height || before.format() != Format::RGBA32F)
                        throw Error({ErrorKind::Runtime, fileOf(prevChain, prevSpp, i).string(), "--cache",
                                     "a cached brute-force image has the wrong size or format", "",
                                     "delete the cache folder " + entry.string()});
                    const auto b = before.view<glm::vec4>();
                    auto img = image.view<glm::vec4>();
                    const double wPrev = double(prevSpp) / double(n), wNew = double(batch) / double(n);
                    for (uint32_t y = 0; y < height; ++y)
                        for (uint32_t x = 0; x < width; ++x) {
                            const glm::dvec4 v = wPrev * glm::dvec4(b.at(x, y)) + wNew * glm::dvec4(img.at(x, y));
                            img.at(x, y) = glm::vec4(glm::vec3(v), 1.f);
                        }
                }
                writeImage(file, image);
                ++out.rendered;
            } else {
                ++out.cached;
            }
            FrameResult fr;
            fr.frame = i;
            fr.time = double(i) / o.fps;
            fr.totalMs = std::numeric_limits<double>::quiet_NaN();
            if (i >= o.warmup && i - o.warmup < times.size()) {
                fr.totalMs = times[i - o.warmup].first;
                fr.passMs = times[i - o.warmup].second;
            }
            const bool hasPrev = i > first;
            fr.metrics = measure(image, refs[i], hasPrev ? &prevImage : nullptr, hasPrev ? &refs[i - 1] : nullptr);
            if (flicker && i >= o.warmup) flickerAcc.add(image);
            prevImage = std::move(image);
            r.frames.push_back(std::move(fr));
        }
        r.summary = bench::summarize(r.frames, o.warmup);
        if (flicker && flickerAcc.frames() >= 2) r.summary.flicker = flickerAcc.value().value;
        spdlog::info("brute force {} spp: RelMSE {:.4g}, trimmed {:.4g}, FLIP {:.4f}, {:.1f} ms/frame ({:.1f} s)", n,
                     r.summary.relMSE, r.summary.trimmedRelMSE, r.summary.flip, r.summary.totalMs,
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        const bool done = stopWhenCrossed && crossesEveryVariant(r.summary, variants);
        out.runs.push_back(std::move(r));
        prevSpp = n;
        if (done) break;
    }
    return out;
}

/// Whether --brute-force-spp asks for no curve ("none" or "0").
bool noBruteForce(const BenchOptions& o) {
    return o.bruteForceSpp == "none" || o.bruteForceSpp == "0";
}

/// --brute-force-spp, or powers of two up to --brute-force-max (the curve stops earlier once it reaches every
/// graph's error); none for "none" or "0", and none without a scene (nothing to path-trace).
std::vector<uint32_t> bruteForceSpps(const BenchOptions& o) {
    std::vector<uint32_t> spps;
    if (noBruteForce(o) || o.scene.scene.empty()) return spps;
    if (!o.bruteForceSpp.empty()) {
        for (const auto& v : splitValues(o.bruteForceSpp)) {
            uint32_t n = 0;
            size_t used = 0;
            try {
                const unsigned long x = std::stoul(v, &used);
                n = x <= 4096 ? uint32_t(x) : 0;
            } catch (const std::exception&) {
                used = 0;
            }
            if (used != v.size() || n == 0)
                throwBadInput("--brute-force-spp", "'" + v + "' is not a sample count",
                              "integers in 1..4096, e.g. 1,2,4,8, or none (no curve)");
            spps.push_back(n);
        }
    } else {
        const uint32_t cap = std::max(1u, std::min(o.bruteForceMax, 4096u));
        for (uint32_t n = 1; n <= cap; n *= 2) spps.push_back(n);
    }
    std::sort(spps.begin(), spps.end());
    spps.erase(std::unique(spps.begin(), spps.end()), spps.end());
    return spps;
}

std::vector<Variant> variants(const BenchOptions& o, const std::vector<Sweep>& sweeps) {
    std::vector<Variant> out;
    std::vector<bool> sweepUsed(sweeps.size(), false);
    for (const auto& g : o.graphs) {
        Variant base;
        base.file = resolveGraph(g, "--graph");
        base.desc = loadGraph(base.file);
        bool swept = false;
        for (size_t s = 0; s < sweeps.size(); ++s) {
            if (!base.desc.findPass(sweeps[s].pass)) continue;
            swept = sweepUsed[s] = true;
            for (const auto& v : sweeps[s].values) {
                Variant var = base;
                var.sweep = &sweeps[s];
                var.value = v;
                out.push_back(std::move(var));
            }
        }
        if (!swept) out.push_back(std::move(base));
    }
    for (size_t s = 0; s < sweeps.size(); ++s) {
        if (sweepUsed[s]) continue;
        std::vector<std::string> passes;
        for (const auto& v : out)
            for (const auto& p : v.desc.passes)
                if (std::find(passes.begin(), passes.end(), p.name) == passes.end()) passes.push_back(p.name);
        throwBadInput("--sweep " + sweeps[s].text, "no benchmarked graph has a pass '" + sweeps[s].pass + "'",
                      "a pass of one of the --graph graphs: " + join(passes),
                      didYouMean(sweeps[s].pass, passes, "passes"));
    }
    return out;
}

std::string shellQuoted(const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

/// The plot script, checked with the interpreter before the benchmark runs, not after it.
std::string checkPlotter(const BenchOptions& o) {
    const std::string script = o.plotScript.empty() ? sourcePath("tools/plot_bench.py") : o.plotScript;
    std::error_code ec;
    if (!fs::exists(script, ec))
        throwBadInput("--plot", "the plot script '" + script + "' does not exist", "tools/plot_bench.py",
                      "pass --plot-script PATH");
    const std::string check = shellQuoted(o.python) + " -c 'import matplotlib' >/dev/null 2>&1";
    if (std::system(check.c_str()) != 0)
        throwBadInput("--plot", "plotting needs " + o.python + " with matplotlib, which is not installed",
                      "python3 and python3-matplotlib (Debian)",
                      "apt-get install python3-matplotlib, or leave out --plot");
    return script;
}

void runPlot(const BenchOptions& o, const std::string& script, const fs::path& out) {
    const std::string cmd = shellQuoted(o.python) + " " + shellQuoted(script) + " " +
                            shellQuoted((out / "results.json").string()) + " " +
                            shellQuoted((out / "plot.png").string()) + " --frames-output " +
                            shellQuoted((out / "plot_frames.png").string());
    const int status = std::system(cmd.c_str());
    if (status != 0)
        throw Error(
            {ErrorKind::Runtime, script, "--plot",
             fmt::format("the plot script failed (exit status {})", WIFEXITED(status) ? WEXITSTATUS(status) : -1), "",
             "run it by hand: " + cmd});
    spdlog::info("plots written to {} and {}", (out / "plot.png").string(), (out / "plot_frames.png").string());
}

void runBench(BenchOptions o) {
    // SIGINT or SIGTERM: the frame under way finishes (its reference or brute-force image goes into the cache, where
    // the next run finds it), then the run ends without results: a partial run has no equal-error figures.
    const StopOnSignal stopOnSignal;
    if (o.given.count("--size")) (void)frameSize(o.size, true, {}, "");  // a bad --size fails first
    const bool givenReference = !o.referenceSequence.empty();
    const bool hasScene = !o.scene.scene.empty();
    if (!hasScene && !givenReference)
        throwBadInput("--scene", "no scene given",
                      "a glTF scene, e.g. data/scenes/cornell_box.gltf, or --reference-sequence with graphs that read "
                      "their inputs from files");
    // Options that would do nothing are refused rather than ignored.
    if (!hasScene) {
        for (const char* name : kSceneOptions)
            if (o.given.count(name))
                throwBadInput(name, std::string(name) + " applies to a scene, and there is none (no --scene)", "",
                              std::string("add --scene, or leave out ") + name);
        for (const char* name : kBruteForceOptions)
            if (o.given.count(name))
                throwBadInput(name,
                              std::string(name) +
                                  " applies to the brute-force curve, which path-traces the scene: "
                                  "without --scene there is none",
                              "", std::string("add --scene, or leave out ") + name);
        if (!o.bruteForceSpp.empty() && !noBruteForce(o))
            throwBadInput("--brute-force-spp",
                          "the brute-force curve path-traces the scene: without --scene there is none",
                          "no --brute-force-spp, or none", "add --scene, or leave out --brute-force-spp");
    }
    if (givenReference) {
        for (const char* name : kRenderedReferenceOptions)
            if (o.given.count(name))
                throwBadInput(name,
                              std::string(name) + " applies to a rendered reference; --reference-sequence gives them",
                              "", std::string("leave out ") + name + " or --reference-sequence");
    } else if (o.given.count("--reference-first-frame")) {
        throwBadInput("--reference-first-frame",
                      "--reference-first-frame numbers the files of --reference-sequence, "
                      "which is not given",
                      "", "add --reference-sequence, or leave out --reference-first-frame");
    }
    std::set<uint64_t> referenceFrames;
    if (o.referencesOnly && givenReference)
        throwBadInput("--references-only", "--references-only renders references, and --reference-sequence gives them",
                      "", "leave out one of them");
    if (!o.referenceFrames.empty()) {
        if (!o.referencesOnly)
            throwBadInput("--reference-frames",
                          "--reference-frames selects the frames a --references-only run renders; a benchmark needs "
                          "every frame's reference",
                          "", "add --references-only, or leave out --reference-frames");
        referenceFrames = parseFrameList(o.referenceFrames, "--reference-frames");
        for (uint64_t f : referenceFrames)
            if (f >= o.frames)
                throwBadInput("--reference-frames", fmt::format("frame {} is not inside the sequence", f),
                              fmt::format("frames in 0..{}", o.frames - 1));
    }
    if (o.frames == 0) throwBadInput("--frames", "frame count is 0", "more frames than --warmup");
    if (o.frames > 100000) throwBadInput("--frames", "too many frames", "at most 100000");
    if (o.frames <= o.warmup && !o.referencesOnly)  // references are rendered for warm-up frames too
        throwBadInput("--frames",
                      fmt::format("{} frame(s) leave nothing to measure after {} warm-up frame(s)", o.frames, o.warmup),
                      "more frames than --warmup", fmt::format("use --frames {} or lower --warmup", o.warmup + 16));
    checkFpsAndThreads(o.fps, o.threads);
    for (uint32_t e : o.eventFrames)
        if (e == 0 || e >= o.frames)
            throwBadInput("--event-frame", fmt::format("frame {} is not inside the sequence", e),
                          fmt::format("a frame in 1..{} (frame 0 is the camera cut, always measured)", o.frames - 1));
    if (o.referenceSpp == 0 || o.referenceSpp > (1u << 20))
        throwBadInput("--reference-spp", "reference sample count out of range", "1 to 1048576");
    if (o.graphs.empty()) throwBadInput("--graph", "no graph to benchmark", "one or more --graph options");
    std::error_code ec;
    if (hasScene && !fs::is_regular_file(o.scene.scene, ec))
        throwBadInput("--scene", "scene '" + o.scene.scene + "' does not exist", "a glTF 2.0 file (.gltf or .glb)");
    // File numbers i + --reference-first-frame of every bench frame i, in range: no sum may overflow.
    constexpr int64_t kMaxFileNumber = 999999999999999999;  // 18 digits, the widest a sequence pattern writes
    if (o.referenceFirstFrame < 0 || o.referenceFirstFrame > kMaxFileNumber - int64_t(o.frames - 1))
        throwBadInput("--reference-first-frame",
                      fmt::format("file numbers {} + 0..{} are out of range", o.referenceFirstFrame, o.frames - 1),
                      fmt::format("a first file number from 0 to {}", kMaxFileNumber - int64_t(o.frames - 1)),
                      "the number of the sequence's first file, e.g. 1 for Blender's");
    if (givenReference)  // a pattern without a frame field fails here, before anything is loaded
        (void)sequenceFramePath(parseSequenceSource(o.referenceSequence).pattern, o.referenceFirstFrame,
                                "--reference-sequence");
    o.referenceGraph = o.referenceGraph.empty() ? sourcePath("graphs/Reference.json")
                                                : resolveGraph(o.referenceGraph, "--reference-graph");
    o.bruteForceGraph = o.bruteForceGraph.empty() ? sourcePath("graphs/PathTracer.json")
                                                  : resolveGraph(o.bruteForceGraph, "--brute-force-graph");
    std::vector<Sweep> sweeps;
    for (const auto& s : o.sweeps) sweeps.push_back(parseSweep(s));
    const std::vector<uint32_t> spps = bruteForceSpps(o);
    const std::vector<Variant> vars = variants(o, sweeps);
    ensureWritableDir(o.out, "--out");
    const fs::path outDir(o.out);
    std::vector<fs::path> inputs = {o.scene.scene, o.scene.env, o.referenceGraph, o.bruteForceGraph};
    for (const std::string& g : o.graphs) inputs.push_back(resolveGraph(g, "--graph"));
    checkInputsNotOverwritten(
        o.out, inputs,
        [](const std::string& name) {
            return name == "results.csv" || name == "results.json" || name == "summary.md" || name == "plot.png" ||
                   name == "plot_frames.png";
        },
        "--out");
    const std::string plotScript = o.plot ? checkPlotter(o) : std::string();

    ThreadLimit threadLimit(o.threads);
    PluginRegistry registry = makeRegistry();
    std::shared_ptr<Scene> scene = loadScene(o.scene);

    // Every variant is built, configured and compiled once before anything is rendered, so a bad graph, --set or
    // sweep value fails in seconds rather than after the reference.
    auto configureVariant = [](const Variant& v) -> std::function<void(RenderGraph&)> {
        if (!v.sweep) return {};
        return [&v](RenderGraph& g) {
            g.setParam(v.sweep->pass, v.sweep->param, parseParamValue(v.value), "--sweep " + v.sweep->text);
        };
    };
    // Without --size, the frames the variants' source passes read give it (all alike), with --set and the sweep
    // value applied as they will be.
    uint32_t width, height;
    {
        std::vector<std::unique_ptr<RenderGraph>> sized;
        std::vector<SizedGraph> asked;
        if (!o.given.count("--size")) {
            for (const Variant& v : vars) {
                sized.push_back(std::make_unique<RenderGraph>(v.desc, registry));
                applySet(*sized.back(), o.set);
                if (const auto configure = configureVariant(v)) configure(*sized.back());
                asked.push_back({sized.back().get(), v.desc.name + (v.sweep ? " " + v.label() : "")});
            }
        }
        const glm::uvec2 size = frameSize(o.size, o.given.count("--size") > 0, asked, "640x360");
        width = size.x;
        height = size.y;
    }

    bench::BenchInfo info;
    info.loomVersion = loom::version();
    if (hasScene) {
        info.scene = fs::path(o.scene.scene).filename().string();
        info.cameraPath = o.scene.cameraPath;
        info.cameraSpeed = o.scene.cameraSpeed;
        info.jitter = o.scene.jitter;
    }
    info.width = width;
    info.height = height;
    info.frames = o.frames;
    info.warmup = o.warmup;
    info.fps = o.fps;
    info.eventFrames = o.eventFrames;
    // The scene's own lighting steps (animated lights): the first frame at or after each.
    if (scene) {
        for (const float t : scene->lightStepTimes()) {
            const double frame = std::ceil(double(t) * o.fps);
            if (frame >= 1.0 && frame < double(o.frames)) info.eventFrames.push_back(uint32_t(frame));
        }
    }
    std::sort(info.eventFrames.begin(), info.eventFrames.end());
    info.eventFrames.erase(std::unique(info.eventFrames.begin(), info.eventFrames.end()), info.eventFrames.end());
    info.set = o.set;
    if (givenReference) {
        info.referenceSequence = o.referenceSequence;
        info.referenceFirstFrame = o.referenceFirstFrame;
    } else {
        info.referenceGraph = fs::path(o.referenceGraph).filename().string();
        info.referenceSpp = o.referenceSpp;
    }
    if (!spps.empty()) info.bruteForceGraph = fs::path(o.bruteForceGraph).filename().string();
    info.threads = o.threads;
    info.loadBefore = loadAverage();

    // The path length of each variant's path tracer (after --set and its sweep value), for the matched reference.
    std::vector<std::pair<std::string, std::pair<int, int>>> bounces;  // variant label -> (maxBounces, rrStart)
    for (const Variant& v : vars) {
        PreparedGraph p =
            prepareGraph(v.desc, v.file, registry, scene, o.set, false, configureVariant(v), o.measure, width, height,
                         o.device);
        const std::string tracer = tracerOf(v.desc, registry);
        if (!tracer.empty())
            bounces.emplace_back(v.desc.name + (v.sweep ? " " + v.label() : ""),
                                 std::make_pair(roleInt(*p.graph, tracer, ParamRole::MaxBounces),
                                                roleInt(*p.graph, tracer, ParamRole::RussianRouletteStart)));
    }
    // The brute-force curve path-traces the scene: none without one, or with --brute-force-spp none.
    std::optional<PreparedGraph> brute;
    std::string bruteTracer;
    if (!spps.empty()) {
        const GraphDesc bruteDesc = loadGraph(o.bruteForceGraph);
        brute = prepareGraph(bruteDesc, o.bruteForceGraph, registry, scene, o.set, true, {}, "", width, height, o.device);
        bruteTracer = tracerOf(bruteDesc, registry);
        if (bruteTracer.empty())
            throwBadInput("--brute-force-graph", "the brute-force graph has no path tracer",
                          "a graph like graphs/PathTracer.json", "", o.bruteForceGraph);
    } else {
        spdlog::info("no brute-force curve ({}): no equal-error speedups",
                     hasScene ? "--brute-force-spp none" : "no scene to path-trace");
    }

    // The graphs' common path length: the reference (and the brute force) trace it, so the errors measure noise and
    // the denoisers' bias, not the truncation of paths. Graphs of different lengths need --reference-bounces (given
    // references: the brute force alone, and only when they agree).
    std::optional<std::pair<int, int>> graphBounces;
    bool graphsDiffer = false;
    for (const auto& [label, b] : bounces) {
        if (!graphBounces) graphBounces = b;
        graphsDiffer = graphsDiffer || b.first != graphBounces->first;
    }
    if (!graphBounces && brute)
        graphBounces = std::make_pair(roleInt(*brute->graph, bruteTracer, ParamRole::MaxBounces),
                                      roleInt(*brute->graph, bruteTracer, ParamRole::RussianRouletteStart));
    ReferenceSpec spec;
    if (!referenceFrames.empty()) spec.only = &referenceFrames;
    if (givenReference) {
        // Nothing to match: the references are what they are.
    } else if (o.referenceBounces == "graph") {
        if (graphsDiffer) {
            std::vector<std::string> list;
            for (const auto& [label, b] : bounces) list.push_back(fmt::format("{} {}", label, b.first));
            throwBadInput("--reference-bounces",
                          "the benchmarked graphs trace paths of different lengths (maxBounces: " + join(list) + ")",
                          "graphs of one path length, so one matched reference serves them all",
                          "bench them in separate runs, or give --reference-bounces N");
        }
        if (graphBounces) {
            spec.maxBounces = graphBounces->first;
            info.referenceBouncesFrom = "the graphs";
        } else {
            info.referenceBouncesFrom = "the reference graph";  // no graph and no brute force traces paths
        }
    } else if (o.referenceBounces != "reference") {
        int n = -1;
        size_t used = 0;
        try {
            n = std::stoi(o.referenceBounces, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used != o.referenceBounces.size() || n < 0 || n > 64)
            throwBadInput("--reference-bounces", "'" + o.referenceBounces + "' is not a path length",
                          "graph (the benchmarked graphs' maxBounces), reference (the reference graph's own) or "
                          "an integer in 0..64");
        spec.maxBounces = n;
        info.referenceBouncesFrom = "--reference-bounces";
    } else {
        info.referenceBouncesFrom = "the reference graph";
    }
    // Jittered sequences are anti-aliased by TAA: their reference (and brute force) average over the pixel's area.
    spec.pixelFilter = o.scene.jitter == "none" ? kPixelFilterCenter : kPixelFilterBox;
    if (brute) {
        // Brute force traces what the graphs trace (when they agree), so it shares their bias.
        if (!graphsDiffer) {
            brute->graph->setParam(bruteTracer, roleParam(*brute->graph, bruteTracer, ParamRole::MaxBounces),
                                   graphBounces->first, "--reference-bounces");
            brute->graph->setParam(bruteTracer, roleParam(*brute->graph, bruteTracer, ParamRole::RussianRouletteStart),
                                   graphBounces->second, "--reference-bounces");
        }
        brute->graph->setParam(bruteTracer, roleParam(*brute->graph, bruteTracer, ParamRole::PixelFilter),
                               spec.pixelFilter, "--jitter");
    }
    if (!givenReference || brute) info.pixelFilter = spec.pixelFilter;

    // The references: given frames (read when a run needs them), or rendered and cached ones.
    std::optional<SequenceReferences> sequence;
    ReferenceSet refSet;
    ReferenceFrames refs;
    if (givenReference) {
        sequence.emplace(o.referenceSequence, o.referenceFirstFrame, o.frames, width, height);
        refs.sequence = &*sequence;
    } else {
        refSet = references(o, registry, scene, width, height, spec);
        refs.images = &refSet.frames;
        info.referenceShared = refSet.shared;
        info.referenceCache = refSet.cache;
        info.referenceFramesCached = refSet.cached;
        info.referenceFramesRendered = refSet.rendered;
        info.referenceBounces = refSet.maxBounces;
        info.referenceRrStart = refSet.rrStartBounce;
        info.referenceNoise = refSet.meanNoise(o.warmup);
    }

    // The bias of the matched path length: the matched reference against the reference graph's own length, over
    // the measured frames only.
    if (spec.maxBounces) {
        ReferenceSpec full;
        full.pixelFilter = spec.pixelFilter;
        full.firstFrame = o.warmup;
        full.label = "full-length reference";
        full.only = spec.only;
        // Its length first (cheap: the graph only), to skip it when the lengths agree.
        const ReferenceSet fullSet = [&] {
            const GraphDesc refDesc = loadGraph(o.referenceGraph);
            RenderGraph g(refDesc, registry);
            const std::string t = tracerOf(refDesc, registry);
            if (!t.empty() && roleInt(g, t, ParamRole::MaxBounces) == refSet.maxBounces) return ReferenceSet{};
            return references(o, registry, scene, width, height, full);
        }();
        if (o.referencesOnly) {
            if (!fullSet.cache.empty())
                spdlog::info("full-length reference: {} frame(s) rendered, {} from the cache, in {}", fullSet.rendered,
                             fullSet.cached, fullSet.cache);
        } else if (!fullSet.frames.empty()) {
            bench::BiasRow b;
            b.graphBounces = refSet.maxBounces;
            b.fullBounces = fullSet.maxBounces;
            b.cache = fullSet.cache;
            b.framesCached = fullSet.cached;
            b.framesRendered = fullSet.rendered;
            b.fullNoise = fullSet.meanNoise(o.warmup);
            const ReferenceFrames full{&fullSet.frames};
            for (uint64_t i = o.warmup; i < o.frames; ++i) {
                b.relMSE += relMSE(refs[i], full[i]).value;
                b.trimmedRelMSE += trimmedRelMSE(refs[i], full[i]).value;
                b.flip += flip(refs[i], full[i]).value;
            }
            const double n = double(o.frames - o.warmup);
            b.relMSE /= n;
            b.trimmedRelMSE /= n;
            b.flip /= n;
            spdlog::info("{}: RelMSE {:.4g}, trimmed {:.4g}, FLIP {:.4f}", b.label(), b.relMSE, b.trimmedRelMSE,
                         b.flip);
            info.bias = b;
        }
    }

    if (o.referencesOnly) {
        std::cout << fmt::format("references only: {} frame(s) rendered, {} from the cache, in {}\n", refSet.rendered,
                                 refSet.cached, refSet.cache);
        return;
    }

    std::vector<Run> results;
    for (const Variant& v : vars) {
        PreparedGraph p =
            prepareGraph(v.desc, v.file, registry, scene, o.set, false, configureVariant(v), o.measure, width, height,
                         o.device);
        Run r;
        r.graph = v.desc.name;
        r.graphFile = v.file;
        r.params = v.label();
        r.measured = p.measured.str();
        std::optional<double> flicker;
        bench::DisocclusionTracker ages;
        bench::DisocclusionTracker* tracked = p.ageFields.empty() ? nullptr : &ages;
        r.frames = runSequence(p, scene.get(), refs, 0, o.frames, o.fps, width, height,
                               r.graph + (r.params.empty() ? "" : " " + r.params), o.warmup,
                               info.referenceShared ? &flicker : nullptr, tracked);
        r.lag = runLag(r.frames, info.eventFrames, tracked);
        r.summary = bench::summarize(r.frames, o.warmup);
        r.summary.flicker = flicker;
        results.push_back(std::move(r));
    }

    BruteForceCurve bf;
    if (brute) {
        // The brute-force cache key: the sequence, the brute-force graph as configured (its parameters after --set,
        // the matched path length and the pixel filter) and the reference frames' timing.
        std::string bruteKey =
            sequenceKeyText(o, width, height) + fmt::format("brute-force graph {} bytes {:016x}\nfps {}\n",
                                                            fs::path(o.bruteForceGraph).filename().string(),
                                                            fnv1a(readBytes(o.bruteForceGraph)), o.fps);
        for (const PassDesc& p : brute->graph->desc().passes) {
            const ParamList& declared = brute->graph->pass(p.name)->params();
            nlohmann::json params = declared.toJson(false);
            if (const ParamDecl* d = declared.findRole(ParamRole::SampleCount))
                params.erase(d->name);  // the curve sets it
            bruteKey += "pass " + p.name + " " + params.dump() + "\n";
        }
        bf = bruteForceCurve(o, *brute, bruteTracer, bruteKey, *scene, refs, spps, o.bruteForceSpp.empty(), results,
                             width, height, info.referenceShared);
    }
    for (Run& r : bf.runs) r.lag = runLag(r.frames, info.eventFrames, nullptr);
    const std::vector<Run>& curve = bf.runs;
    info.bruteForceCache = bf.cache;
    info.bruteForceFramesCached = bf.cached;
    info.bruteForceFramesRendered = bf.rendered;
    info.bruteForceTimingFrames =
        brute ? uint32_t(std::min<uint64_t>(kBruteForceTimingFrames, o.frames - o.warmup)) : 0u;
    for (Run& r : results) {
        r.speedupRelMSE = bench::equalErrorSpeedup(curve, r.summary.relMSE, r.summary.totalMs, &bench::Summary::relMSE);
        r.speedupFlip = bench::equalErrorSpeedup(curve, r.summary.flip, r.summary.totalMs, &bench::Summary::flip);
        r.speedupTrimmed =
            bench::equalErrorSpeedup(curve, r.summary.trimmedRelMSE, r.summary.totalMs, &bench::Summary::trimmedRelMSE);
    }
    if (o.bruteForceSpp.empty() && !curve.empty() && !crossesEveryVariant(curve.back().summary, results))
        spdlog::warn(
            "the brute-force curve stopped at --brute-force-max {} spp before reaching every graph's error: "
            "some speedups are bounds",
            curve.back().spp);

    // The reference's noise against the smallest error measured against it (unknown for given references).
    if (info.referenceNoise) {
        double smallest = std::numeric_limits<double>::infinity();
        for (const Run& r : results) smallest = std::min(smallest, r.summary.relMSE);
        for (const Run& r : curve) smallest = std::min(smallest, r.summary.relMSE);
        if (*info.referenceNoise * kNoiseMargin > smallest) {
            info.noiseWarning = fmt::format(
                "the reference's own noise (RelMSE {:.3g}) is not {}x below the smallest error measured ({:.3g}): "
                "errors near it are inflated by up to that much and the crossing of the brute-force curve is "
                "uncertain; raise --reference-spp to about {} (the noise falls as 1 / spp)",
                *info.referenceNoise, kNoiseMargin, smallest,
                uint64_t(std::ceil(double(o.referenceSpp) * *info.referenceNoise * kNoiseMargin / smallest / 64.0)) *
                    64);
            spdlog::warn("{}", info.noiseWarning);
        }
    }

    info.loadAfter = loadAverage();
    bench::writeResults(outDir, info, results, curve);
    std::cout << readBytes(outDir / "summary.md");
    std::cout << fmt::format("Wrote results.csv, results.json and summary.md to {}\n", o.out);
    if (o.plot) runPlot(o, plotScript, outDir);
}

}  // namespace

void addBenchCommand(CLI::App& app) {
    auto o = std::make_shared<BenchOptions>();
    CLI::App* cmd = app.add_subcommand(
        "bench",
        "Run time against error: graphs and brute-force path tracing against a cached per-frame reference, or "
        "against given reference frames (--reference-sequence; then --scene is optional)");
    addSceneOptions(cmd, o->scene);
    cmd->add_option("--frames,-n", o->frames, "frames in the sequence (warm-up included)")->capture_default_str();
    addSizeOption(cmd, o->size, "640x360");
    cmd->add_option("--graph,-g", o->graphs, "graph to benchmark: a file or a shipped graph's name (repeatable)");
    cmd->add_option("--sweep", o->sweeps,
                    "run each graph with this pass once per value: Pass.param=v1,v2,... (repeatable; one sweep at "
                    "a time, not their product)");
    cmd->add_option("--set", o->set, "set a parameter on every graph: Pass.param=value (repeatable)");
    addDeviceOption(cmd, o->device, "; for the benchmarked graphs (references are rendered as their graphs say)");
    cmd->add_option("--measure", o->measure,
                    "field to measure in every graph (default: the input of ToneMap.src, else the first output)");
    cmd->add_option("--reference-sequence", o->referenceSequence,
                    "reference frames given as files instead of rendered ones: 'PATTERN[:LAYER]', a numbered EXR "
                    "sequence (#### or %04d) and, for a multilayer EXR, the layer to read (e.g. "
                    "'frames/reference_####.exr:ViewLayer.Combined'); bench frame i (warm-up included) is file "
                    "number i + --reference-first-frame. Nothing is rendered or cached for the reference and its noise "
                    "is unknown; --scene becomes optional (without it: no brute-force curve)");
    cmd->add_option("--reference-first-frame", o->referenceFirstFrame,
                    "file number of bench frame 0 in --reference-sequence (Blender numbers frames from 1)")
        ->capture_default_str();
    cmd->add_option("--reference-graph", o->referenceGraph, "reference graph (default graphs/Reference.json)");
    cmd->add_option("--reference-spp", o->referenceSpp, "samples per pixel of each frame's reference")
        ->capture_default_str();
    cmd->add_option("--brute-force-graph", o->bruteForceGraph, "brute-force graph (default graphs/PathTracer.json)");
    cmd->add_option("--reference-bounces", o->referenceBounces,
                    "path length of the reference: graph (the benchmarked graphs' PathTracer.maxBounces; the bias "
                    "against the reference graph's own length is reported apart), reference (the reference graph's "
                    "own) or N")
        ->capture_default_str();
    cmd->add_option("--brute-force-spp", o->bruteForceSpp,
                    "brute-force sample counts, e.g. 1,2,4,8, or none (no curve, no speedups) (default: powers of two "
                    "up to --brute-force-max, stopping once every graph's error is reached; none without --scene)");
    cmd->add_option("--brute-force-max", o->bruteForceMax, "largest default brute-force sample count (at most 4096)")
        ->capture_default_str();
    cmd->add_option("--warmup", o->warmup, "frames excluded from the summaries")->capture_default_str();
    cmd->add_option("--fps", o->fps, "frames per second of the animation clock")->capture_default_str();
    cmd->add_option("--cache", o->cache, "reference cache folder (default $LOOM_CACHE, else ~/.cache/loom/references)");
    cmd->add_option("--out,-o", o->out, "output folder")->capture_default_str();
    cmd->add_flag("--references-only", o->referencesOnly,
                  "render the references into the cache and stop: nothing is measured or written to --out (many "
                  "such runs, on other machines too, can fill one --cache folder)");
    cmd->add_option("--reference-frames", o->referenceFrames,
                    "with --references-only, the frames whose references to render, e.g. 0-15 or 3,7 (default: "
                    "all); a static scene's one reference is frame 0's");
    cmd->add_option("--event-frame", o->eventFrames,
                    "a lighting step at this frame: the lag figures measure the recovery after it (repeatable)");
    cmd->add_flag("--plot", o->plot,
                  "also write plot.png (error against time) and plot_frames.png (error per frame) with "
                  "tools/plot_bench.py");
    cmd->add_option("--plot-script", o->plotScript, "plot script (default tools/plot_bench.py of the source tree)");
    cmd->add_option("--python", o->python, "Python interpreter for --plot")->capture_default_str();
    cmd->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
    cmd->callback([o, cmd] {
        auto note = [&](const char* name) {
            if (cmd->count(name)) o->given.insert(name);
        };
        for (const char* name : kSceneOptions) note(name);
        for (const char* name : kBruteForceOptions) note(name);
        for (const char* name : kRenderedReferenceOptions) note(name);
        note("--reference-first-frame");
        note("--size");
        runBench(*o);
    });
}

}  // namespace loom::cli
