// loom bench: run time against error. Renders (and caches) a per-frame reference of a scene and camera path, runs
// each graph (and each point of a parameter sweep) and the brute-force path tracer at 1, 2, 4, ... spp over the
// same sequence, and writes per-frame and summary results, the equal-error speedup, and optionally a plot.
// The protocol is documented in docs/BENCHMARKS.md ("loom bench: run time against error").
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "BenchLag.h"
#include "BenchReport.h"
#include "CliUtil.h"
#include "SceneSetup.h"
#include "loom/Error.h"
#include "loom/ImageIO.h"
#include "loom/Log.h"
#include "loom/Metrics.h"
#include "loom/Parallel.h"
#include "loom/Params.h"
#include "loom/RenderGraph.h"

namespace loom::cli {

namespace {

namespace fs = std::filesystem;
using bench::FrameMetrics;
using bench::FrameResult;
using bench::Run;

// Pass types and parameters the command relies on.
const char kToneMapType[] = "ToneMap";
const char kToneMapInput[] = "src";
const char kAccumulateType[] = "AccumulatePass";
const char kAccumulateFramesStat[] = "frames";
const char kSppParam[] = "samplesPerPixel";
const char kSeedParam[] = "seed";

/// Reference batches use PathTracer seeds from here on, so their samples are independent of every graph's and of
/// the brute-force runs (which use seed 0 unless --set says otherwise).
constexpr uint32_t kReferenceSeedBase = 1u << 24;
/// Bumped when the reference rendering protocol changes, so old cache entries are not reused.
constexpr int kCacheFormat = 1;

struct BenchOptions {
    SceneOptions scene;
    uint64_t frames = 32;
    std::string size = "640x360";
    std::vector<std::string> graphs;
    std::vector<std::string> sweeps;
    std::vector<std::string> set;
    std::string measure;
    std::string referenceGraph;
    uint32_t referenceSpp = 256;
    std::string bruteForceGraph;
    std::string bruteForceSpp;
    uint32_t bruteForceMax = 64;
    uint64_t warmup = 16;
    double fps = 60.0;
    std::string cache;
    std::string out = "bench";
    bool plot = false;
    std::string plotScript;
    std::string python = "/usr/bin/python3";
    unsigned threads = 0;
    std::vector<uint32_t> eventFrames;  ///< --event-frame: lighting steps the lag figures measure the recovery after
};

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

/// The field a graph's metrics are taken of: --measure, else the linear HDR image feeding ToneMap.src, else the
/// first marked output. The graph must be compiled.
ChannelRef measuredField(const RenderGraph& graph, const std::string& measure, const std::string& file) {
    if (!measure.empty()) return parseChannelRef(measure, "--measure");
    const GraphDesc desc = graph.desc();
    for (const Wire& w : graph.plan().wires) {
        const PassDesc* p = desc.findPass(w.dst.pass);
        if (p && p->type == kToneMapType && w.dst.channel == kToneMapInput && !w.src.prev) return w.src;
    }
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
                           const std::string& measure, uint32_t width, uint32_t height) {
    PreparedGraph p;
    p.graph = std::make_unique<RenderGraph>(desc, registry);
    p.graph->setScene(scene);
    applySet(*p.graph, set, onlyKnownPasses);
    if (configure) configure(*p.graph);
    CompileOptions copts;
    copts.width = width;
    copts.height = height;
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

/// What a reference depends on, as text: hashed into the cache entry's name and stored in it (key.txt).
std::string referenceKeyText(const BenchOptions& o, uint32_t width, uint32_t height, bool shared) {
    std::string env = o.scene.env;
    std::error_code ec;
    if (!env.empty() && fs::is_regular_file(env, ec)) env += " bytes " + fmt::format("{:016x}", fnv1a(readBytes(env)));
    return fmt::format(
        "loom reference cache format {}\nloom version {}\nscene {} bytes {:016x}\nreference graph {} bytes {:016x}\n"
        "reference spp {}\nsize {}x{}\ncamera path {} speed {}\njitter {} count {}\nenvironment {}\n{}\n",
        kCacheFormat, loom::version(), fs::path(o.scene.scene).filename().string(), sceneHash(o.scene.scene),
        fs::path(o.referenceGraph).filename().string(), fnv1a(readBytes(o.referenceGraph)), o.referenceSpp, width,
        height, o.scene.cameraPath, o.scene.cameraSpeed, o.scene.jitter, o.scene.jitterCount, env,
        shared ? std::string("frames: one image for every time (nothing moves)")
               : fmt::format("frames: frame index i at time i / {} s", o.fps));
}

/// Renders or loads the reference of every frame. Per frame: the reference graph's history is reset, the scene is
/// set to the frame's time with no motion, and the graph runs spp / batchSpp times with different PathTracer
/// seeds while its AccumulatePass averages them. Each image is written to the cache atomically.
std::vector<Texture> references(const BenchOptions& o, PluginRegistry& registry, const std::shared_ptr<Scene>& scene,
                                uint32_t width, uint32_t height, bench::BenchInfo& info) {
    const bool shared = !scene->hasMotion() && o.scene.jitter == "none";
    info.referenceShared = shared;
    const GraphDesc desc = loadGraph(o.referenceGraph);  // checked before its bytes are hashed
    const std::string key = referenceKeyText(o, width, height, shared);
    const fs::path cacheRoot = o.cache.empty() ? defaultCacheDir() : fs::path(o.cache);
    const fs::path entry = cacheRoot / fmt::format("{}_{}x{}_{}spp_{:016x}", fs::path(o.scene.scene).stem().string(),
                                                   width, height, o.referenceSpp, fnv1a(key));
    ensureWritableDir(entry.string(), "--cache");
    writeFileAtomic(entry / "key.txt", key);
    info.referenceCache = entry.string();

    std::string tracer, accumulate;
    uint32_t batchSpp = 1;
    for (const PassDesc& p : desc.passes) {
        if (p.params.contains(kSppParam) || p.type == "PathTracer" || p.type == "CUDAPathTracer") {
            tracer = p.name;
            if (p.params.contains(kSppParam) && p.params[kSppParam].is_number_unsigned())
                batchSpp = p.params[kSppParam].get<uint32_t>();
        }
        if (p.type == kAccumulateType) accumulate = p.name;
    }
    if (tracer.empty() || accumulate.empty())
        throwBadInput("--reference-graph", "the reference graph needs a path tracer and an AccumulatePass",
                      "a graph like graphs/Reference.json", "", o.referenceGraph);
    batchSpp = std::max(1u, std::min(batchSpp, o.referenceSpp));
    if (o.referenceSpp % batchSpp != 0)
        throwBadInput(
            "--reference-spp",
            fmt::format("{} is not a multiple of the reference graph's {} spp per frame", o.referenceSpp, batchSpp),
            fmt::format("a multiple of {} (or at most {})", batchSpp, batchSpp));
    const uint32_t batches = o.referenceSpp / batchSpp;

    std::unique_ptr<RenderGraph> graph;
    auto render = [&](uint64_t frame) {
        if (!graph) {
            graph = std::make_unique<RenderGraph>(desc, registry);
            graph->setScene(scene);
            graph->setParam(tracer, kSppParam, batchSpp, "--reference-spp");
            CompileOptions copts;
            copts.width = width;
            copts.height = height;
            graph->compile(copts);
        }
        graph->resetHistory();
        const FrameInfo f = sceneFrame(*scene, frame, o.fps, width, height, true);
        for (uint32_t b = 0; b < batches; ++b) {
            graph->setParam(tracer, kSeedParam, kReferenceSeedBase + b, "reference");
            graph->execute(f);
        }
        const auto stats = graph->lastStats();
        const auto acc = stats.find(accumulate);
        if (acc != stats.end() && acc->second.count(kAccumulateFramesStat) &&
            acc->second.at(kAccumulateFramesStat) != double(batches))
            throw Error({ErrorKind::Runtime, o.referenceGraph, accumulate,
                         fmt::format("the reference accumulated {} of {} batches (it restarted)",
                                     acc->second.at(kAccumulateFramesStat), batches),
                         "", "set autoReset false on the reference graph's AccumulatePass"});
        return copyTexture(*graph->fieldTexture(graph->outputs().front().str()));
    };

    std::vector<Texture> refs;
    const uint64_t count = shared ? 1 : o.frames;
    for (uint64_t i = 0; i < count; ++i) {
        const fs::path file = entry / (shared ? std::string("static.exr") : fmt::format("frame_{:06}.exr", i));
        std::error_code ec;
        if (fs::exists(file, ec)) {
            Texture t = readImage(file);
            if (t.width() == width && t.height() == height && t.format() == Format::RGBA32F) {
                refs.push_back(std::move(t));
                ++info.referenceFramesCached;
                continue;
            }
            spdlog::warn("reference {} has the wrong size or format; rendering it again", file.string());
        }
        const auto start = std::chrono::steady_clock::now();
        refs.push_back(render(i));
        writeImage(file, refs.back());
        ++info.referenceFramesRendered;
        spdlog::info("reference {}/{} rendered ({} spp, {:.1f} s)", i + 1, count, o.referenceSpp,
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
    if (info.referenceFramesRendered == 0)
        spdlog::info("reference: cache hit, {} frame(s) from {}", info.referenceFramesCached, entry.string());
    else
        spdlog::info("reference: {} frame(s) rendered, {} from the cache, in {}", info.referenceFramesRendered,
                     info.referenceFramesCached, entry.string());
    // A shared reference serves every frame.
    while (refs.size() < o.frames) refs.push_back(copyTexture(refs.front()));
    return refs;
}

// ---------------------------------------------------------------------------------------------------------------
// Runs

FrameMetrics measure(const Texture& test, const Texture& ref, const Texture* testPrev, const Texture* refPrev) {
    FrameMetrics m;
    const MetricValue relmse = relMSE(test, ref), sm = smape(test, ref), ps = psnr(test, ref), ss = ssim(test, ref),
                      fl = flip(test, ref);
    m.relMSE = relmse.value;
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

/// Runs a prepared graph over frames [first, frames) from the start of its history, measuring every frame. With
/// `flicker`, the frames from `warmup` on also go into a FlickerAccumulator whose value lands there. With `ages`, every
/// frame's G-buffer goes to the age tracker of the disocclusion lag.
std::vector<FrameResult> runSequence(PreparedGraph& p, Scene& scene, const std::vector<Texture>& refs, uint64_t first,
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

/// --brute-force-spp, or powers of two up to --brute-force-max (and at most a quarter of the reference's spp, so
/// the reference's own noise stays small against the curve's).
std::vector<uint32_t> bruteForceSpps(const BenchOptions& o) {
    std::vector<uint32_t> spps;
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
                              "integers in 1..4096, e.g. 1,2,4,8");
            spps.push_back(n);
        }
    } else {
        const uint32_t cap = std::max(1u, std::min(o.bruteForceMax, o.referenceSpp / 4));
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
    uint32_t width, height;
    parseSize(o.size, "--size", width, height);
    if (o.scene.scene.empty())
        throwBadInput("--scene", "no scene given", "a glTF scene, e.g. data/scenes/cornell_box.gltf");
    if (o.frames == 0) throwBadInput("--frames", "frame count is 0", "more frames than --warmup");
    if (o.frames > 100000) throwBadInput("--frames", "too many frames", "at most 100000");
    if (o.frames <= o.warmup)
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
    if (!fs::is_regular_file(o.scene.scene, ec))
        throwBadInput("--scene", "scene '" + o.scene.scene + "' does not exist", "a glTF 2.0 file (.gltf or .glb)");
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

    bench::BenchInfo info;
    info.loomVersion = loom::version();
    info.scene = fs::path(o.scene.scene).filename().string();
    info.cameraPath = o.scene.cameraPath;
    info.cameraSpeed = o.scene.cameraSpeed;
    info.jitter = o.scene.jitter;
    info.width = width;
    info.height = height;
    info.frames = o.frames;
    info.warmup = o.warmup;
    info.fps = o.fps;
    info.eventFrames = o.eventFrames;
    // The scene's own lighting steps (animated lights): the first frame at or after each.
    for (const float t : scene->lightStepTimes()) {
        const double frame = std::ceil(double(t) * o.fps);
        if (frame >= 1.0 && frame < double(o.frames)) info.eventFrames.push_back(uint32_t(frame));
    }
    std::sort(info.eventFrames.begin(), info.eventFrames.end());
    info.eventFrames.erase(std::unique(info.eventFrames.begin(), info.eventFrames.end()), info.eventFrames.end());
    info.set = o.set;
    info.referenceGraph = fs::path(o.referenceGraph).filename().string();
    info.referenceSpp = o.referenceSpp;
    info.bruteForceGraph = fs::path(o.bruteForceGraph).filename().string();
    info.threads = o.threads;
    info.loadBefore = loadAverage();

    // Every variant is built, configured and compiled once before anything is rendered, so a bad graph, --set or
    // sweep value fails in seconds rather than after the reference.
    auto configureVariant = [](const Variant& v) -> std::function<void(RenderGraph&)> {
        if (!v.sweep) return {};
        return [&v](RenderGraph& g) {
            g.setParam(v.sweep->pass, v.sweep->param, parseParamValue(v.value), "--sweep " + v.sweep->text);
        };
    };
    for (const Variant& v : vars)
        prepareGraph(v.desc, v.file, registry, scene, o.set, false, configureVariant(v), o.measure, width, height);
    const GraphDesc bruteDesc = loadGraph(o.bruteForceGraph);
    PreparedGraph brute =
        prepareGraph(bruteDesc, o.bruteForceGraph, registry, scene, o.set, true, {}, "", width, height);
    std::string bruteTracer;
    for (const PassDesc& p : bruteDesc.passes)
        if (p.type == "PathTracer" || p.type == "CUDAPathTracer") bruteTracer = p.name;
    if (bruteTracer.empty())
        throwBadInput("--brute-force-graph", "the brute-force graph has no path tracer",
                      "a graph like graphs/PathTracer.json", "", o.bruteForceGraph);

    const std::vector<Texture> refs = references(o, registry, scene, width, height, info);

    std::vector<Run> results;
    for (const Variant& v : vars) {
        PreparedGraph p =
            prepareGraph(v.desc, v.file, registry, scene, o.set, false, configureVariant(v), o.measure, width, height);
        Run r;
        r.graph = v.desc.name;
        r.graphFile = v.file;
        r.params = v.label();
        r.measured = p.measured.str();
        std::optional<double> flicker;
        bench::DisocclusionTracker ages;
        bench::DisocclusionTracker* tracked = p.ageFields.empty() ? nullptr : &ages;
        r.frames = runSequence(p, *scene, refs, 0, o.frames, o.fps, width, height,
                               r.graph + (r.params.empty() ? "" : " " + r.params), o.warmup,
                               info.referenceShared ? &flicker : nullptr, tracked);
        r.lag = runLag(r.frames, info.eventFrames, tracked);
        r.summary = bench::summarize(r.frames, o.warmup);
        r.summary.flicker = flicker;
        results.push_back(std::move(r));
    }

    // Brute force has no history: of the warm-up frames it runs only the last one (which warms caches and gives the
    // first measured frame its temporal predecessor).
    std::vector<Run> curve;
    const uint64_t bruteFirst = o.warmup > 0 ? o.warmup - 1 : 0;
    for (uint32_t n : spps) {
        brute.graph->setParam(bruteTracer, kSppParam, n, "--brute-force-spp");
        Run r;
        r.bruteForce = true;
        r.graph = bruteDesc.name;
        r.graphFile = o.bruteForceGraph;
        r.params = fmt::format("{}.{}={}", bruteTracer, kSppParam, n);
        r.spp = n;
        r.measured = brute.measured.str();
        std::optional<double> flicker;
        r.frames =
            runSequence(brute, *scene, refs, bruteFirst, o.frames, o.fps, width, height,
                        fmt::format("brute force {} spp", n), o.warmup, info.referenceShared ? &flicker : nullptr);
        r.lag = runLag(r.frames, info.eventFrames, nullptr);
        r.summary = bench::summarize(r.frames, o.warmup);
        r.summary.flicker = flicker;
        curve.push_back(std::move(r));
    }
    for (Run& r : results) {
        r.speedupRelMSE = bench::equalErrorSpeedup(curve, r.summary.relMSE, r.summary.totalMs, &bench::Summary::relMSE);
        r.speedupFlip = bench::equalErrorSpeedup(curve, r.summary.flip, r.summary.totalMs, &bench::Summary::flip);
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
        "bench", "Run time against error: graphs and brute-force path tracing against a cached per-frame reference");
    addSceneOptions(cmd, o->scene);
    cmd->add_option("--frames,-n", o->frames, "frames in the sequence (warm-up included)")->capture_default_str();
    cmd->add_option("--size", o->size, "frame size WIDTHxHEIGHT")->capture_default_str();
    cmd->add_option("--graph,-g", o->graphs, "graph to benchmark: a file or a shipped graph's name (repeatable)");
    cmd->add_option("--sweep", o->sweeps,
                    "run each graph with this pass once per value: Pass.param=v1,v2,... (repeatable; one sweep at "
                    "a time, not their product)");
    cmd->add_option("--set", o->set, "set a parameter on every graph: Pass.param=value (repeatable)");
    cmd->add_option("--measure", o->measure,
                    "field to measure in every graph (default: the input of ToneMap.src, else the first output)");
    cmd->add_option("--reference-graph", o->referenceGraph, "reference graph (default graphs/Reference.json)");
    cmd->add_option("--reference-spp", o->referenceSpp, "samples per pixel of each frame's reference")
        ->capture_default_str();
    cmd->add_option("--brute-force-graph", o->bruteForceGraph, "brute-force graph (default graphs/PathTracer.json)");
    cmd->add_option("--brute-force-spp", o->bruteForceSpp,
                    "brute-force sample counts, e.g. 1,2,4,8 (default: powers of two up to --brute-force-max and "
                    "a quarter of --reference-spp)");
    cmd->add_option("--brute-force-max", o->bruteForceMax, "largest default brute-force sample count")
        ->capture_default_str();
    cmd->add_option("--warmup", o->warmup, "frames excluded from the summaries")->capture_default_str();
    cmd->add_option("--fps", o->fps, "frames per second of the animation clock")->capture_default_str();
    cmd->add_option("--cache", o->cache, "reference cache folder (default $LOOM_CACHE, else ~/.cache/loom/references)");
    cmd->add_option("--out,-o", o->out, "output folder")->capture_default_str();
    cmd->add_option("--event-frame", o->eventFrames,
                    "a lighting step at this frame: the lag figures measure the recovery after it (repeatable)");
    cmd->add_flag("--plot", o->plot,
                  "also write plot.png (error against time) and plot_frames.png (error per frame) with "
                  "tools/plot_bench.py");
    cmd->add_option("--plot-script", o->plotScript, "plot script (default tools/plot_bench.py of the source tree)");
    cmd->add_option("--python", o->python, "Python interpreter for --plot")->capture_default_str();
    cmd->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
    cmd->callback([o] { runBench(*o); });
}

}  // namespace loom::cli
