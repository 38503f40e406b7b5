// loom render: run a graph headless for N frames, writing marked outputs and dumps.
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <regex>

#include "CliUtil.h"
#include "Interrupt.h"
#include "SceneSetup.h"
#include "loom/Error.h"
#include "loom/Files.h"
#include "loom/ImageIO.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/StatNames.h"

namespace loom::cli {

namespace {

struct RenderOptions {
    std::string graph;
    uint64_t frames = 1;
    uint64_t startFrame = 0;
    std::string size;        ///< --size; see sizeGiven
    bool sizeGiven = false;  ///< without --size, the graph's sources give the size (frameSize)
    std::string out = "out";
    std::vector<std::string> dump;
    std::string dumpFrames;
    std::vector<std::string> set;
    unsigned threads = 0;
    std::string statsFile;
    double fps = 60.0;
    bool quiet = false;
    bool poison = false;
    bool hold = false;
    std::string warmup = "auto";
    uint64_t seedOffset = 0;
    bool dryRun = false;
    std::string device;
    SceneOptions scene;
};

std::string frameFileName(const std::string& pass, const std::string& field, uint64_t frame, Format f) {
    return fmt::format("{}.{}.{:04}.{}", pass, field, frame, imageExtension(f));
}

/// Frame indices stay below 2^32: a pass's random numbers are those of frame index + (seed << 32).
constexpr uint64_t kMaxFrameIndex = 0xFFFFFFFFull;
/// Past this many frames, `--warmup auto` is refused rather than started silently (--warmup N or all say it).
constexpr uint64_t kWarmupLimit = 10000;

void progress(uint64_t done, uint64_t total, double msPerFrame, const char* what = "frames") {
    const int width = 30;
    int filled = int(width * done / std::max<uint64_t>(total, 1));
    std::fprintf(stderr, "\r[%.*s%*s] %llu/%llu %s  %.2f ms/frame", filled, "##############################",
                 width - filled, "", (unsigned long long)done, (unsigned long long)total, what, msPerFrame);
    if (done == total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
}

void runRender(const RenderOptions& o) {
    // SIGINT or SIGTERM: the frame under way finishes, then the outputs and --stats of the frames done are written.
    const StopOnSignal stopOnSignal;
    if (o.sizeGiven) (void)frameSize(o.size, true, {}, "");  // a bad --size fails first
    if (o.frames == 0 || o.frames > 1000000)
        throwBadInput("--frames", fmt::format("frame count {} is out of range", o.frames), "1 to 1000000 frames");
    if (o.startFrame > 1000000000)
        throwBadInput("--start-frame", fmt::format("first frame {} is out of range", o.startFrame), "0 to 1000000000");
    checkFpsAndThreads(o.fps, o.threads);
    if (o.hold && o.scene.scene.empty())
        throwBadInput("--hold", "there is no scene whose time it could hold (no --scene)", "--scene with --hold",
                      "add --scene, or drop --hold");
    std::set<uint64_t> dumpFrames;
    if (!o.dumpFrames.empty()) dumpFrames = parseFrameList(o.dumpFrames, "--dump-frames");
    if (o.dryRun) {  // nothing is created: a folder that is a file is all that can be refused here
        std::error_code ec;
        if (std::filesystem::exists(o.out, ec) && !std::filesystem::is_directory(o.out, ec))
            throwBadInput("--out", "'" + o.out + "' exists and is not a folder", "a folder to write into",
                          "choose another --out folder");
    } else {
        ensureWritableDir(o.out, "--out");
    }
    // Neither an input nor the statistics may have the name of an image the frames write into --out.
    static const std::regex frameFile(R"([^.]+\.[^.]+\.[0-9]{4,}\.(png|exr))");  // frameFileName's names
    const auto isFrameFile = [](const std::string& name) { return std::regex_match(name, frameFile); };
    const std::vector<std::filesystem::path> inputs = {o.graph, o.scene.scene, o.scene.env};
    checkInputsNotOverwritten(o.out, inputs, isFrameFile, "--out");
    if (!o.statsFile.empty()) {  // before the frames, not after them
        checkOutputFile(o.statsFile, "--stats", inputs);
        if (writtenInto(o.statsFile, o.out, isFrameFile))
            throwBadInput("--stats", "the statistics would take the place of a rendered image in " + o.out,
                          "a .json file", "name it stats.json", o.statsFile);
    }

    ThreadLimit threadLimit(o.threads);
    PluginRegistry registry = makeRegistry();
    std::shared_ptr<Scene> scene = loadScene(o.scene);
    RenderGraph graph(loadGraph(o.graph), registry);
    if (scene) graph.setScene(scene);
    applySet(graph, o.set);
    const glm::uvec2 size = frameSize(o.size, o.sizeGiven, {{&graph, ""}}, "256x256");
    const uint32_t width = size.x, height = size.y;
    CompileOptions copts;
    copts.width = width;
    copts.height = height;
    copts.observe = o.dump;
    copts.poisonTransients = o.poison;
    copts.device = o.device;
    graph.compile(copts);

    // Warm-up: a shard of a sequence (--start-frame K > 0) first runs frames K - W .. K - 1 unwritten, so that a
    // graph with history enters frame K as it would in one run from frame 0. auto: from frame 0 (the same frames
    // bit for bit) where the graph keeps history, none where it keeps none; a number: at most that many frames
    // (cheaper, and close once the history has forgotten its start). Nothing to warm for a held frame.
    uint64_t warmup = 0;
    if (o.warmup == "auto" || o.warmup == "all") {
        warmup = (o.warmup == "all" || graph.plan().historyBytes > 0) ? o.startFrame : 0;
    } else {
        char* end = nullptr;
        const unsigned long long n = std::strtoull(o.warmup.c_str(), &end, 10);
        if (o.warmup.empty() || *end || o.warmup[0] == '-')
            throwBadInput("--warmup", "'" + o.warmup + "' is not a frame count", "auto, all or a number of frames");
        warmup = std::min<uint64_t>(n, o.startFrame);
    }
    if (o.hold) warmup = 0;
    if (o.seedOffset > 0 && !o.hold)
        throwBadInput("--seed-offset", "--seed-offset shards the samples of a held frame, and there is no --hold",
                      "--hold with --seed-offset", "add --hold, or leave out --seed-offset");
    // A pass's random numbers are those of frame index + (seed << 32): indices below 2^32 never meet another seed's.
    if (o.seedOffset > kMaxFrameIndex - o.startFrame - (o.frames - 1))
        throwBadInput("--seed-offset",
                      fmt::format("--start-frame {} + --seed-offset {} + --frames {} reach frame index {}, past {}: "
                                  "its random numbers would be those of another seed",
                                  o.startFrame, o.seedOffset, o.frames, o.startFrame + o.seedOffset + o.frames - 1,
                                  kMaxFrameIndex),
                      fmt::format("--seed-offset at most {}", kMaxFrameIndex - o.startFrame - (o.frames - 1)),
                      "for more samples of one frame, use shards of more iterations each, or set PathTracer.seed");
    if (warmup > kWarmupLimit && o.warmup == "auto")
        throwBadInput("--start-frame",
                      fmt::format("a graph that keeps history enters frame {} as one run from frame 0 would only after "
                                  "{} unwritten warm-up frames (more than {})",
                                  o.startFrame, warmup, kWarmupLimit),
                      "--warmup N: the frames before --start-frame to run first",
                      fmt::format("give --warmup 64 (history close to one run's once it has forgotten its start), or "
                                  "--warmup all to run all {} frames",
                                  warmup));
    if (o.dryRun) {
        std::cout << fmt::format("dry run: {} frame(s) from frame {} at {}x{} would render{}; nothing was written\n",
                                 o.frames, o.startFrame, width, height,
                                 warmup > 0 ? fmt::format(" after {} warm-up frame(s)", warmup) : std::string());
        return;
    }
    bool warming = false;

    const std::filesystem::path outDir(o.out);
    uint64_t dumped = 0;
    if (!o.dump.empty()) {
        graph.setFieldObserver(
            [&](const FrameInfo& f, const std::string& pass, const std::string& field, const Texture& tex) {
                if (warming || (!dumpFrames.empty() && !dumpFrames.count(f.frameIndex))) return;
                writeImage(outDir / frameFileName(pass, field, f.frameIndex, tex.format()), tex);
                ++dumped;
            });
    }

    const bool showProgress = !o.quiet && isatty(STDERR_FILENO);
    nlohmann::json statsJson = {
        {"graph", o.graph}, {"width", width}, {"height", height}, {"frames", nlohmann::json::array()}};
    // --hold: every iteration shows the scene and camera at the time of --start-frame K, as frame index K + i (the
    // random numbers of each pass advance as in any run); nothing moves after the first, so accumulation never
    // restarts. The outputs are written once, after the last iteration, under frame K's name.
    const double heldTime = double(o.startFrame) / o.fps;
    if (o.hold) statsJson["heldFrame"] = {{"frame", o.startFrame}, {"time", heldTime}, {"iterations", o.frames}};
    uint64_t written = 0;
    // Frames after the first on which a pass restarted the mean that is its output (stat::kOutputMeanRestarted:
    // AccumulatePass restarts when the scene or the camera moves or an animated light changes), so a reference that
    // cannot converge does not pass silently.
    uint64_t restarts = 0;
    uint64_t done = 0;  // frames finished
    // A held frame's EXRs say which samples they hold, so that `loom image merge` can weigh and check shards.
    std::map<std::string, std::string> heldAttributes;
    const auto writeOutputs = [&](uint64_t named) {
        if (o.hold)
            heldAttributes = {{"loomHeldFrame", std::to_string(o.startFrame)},
                              {"loomSeedOffset", std::to_string(o.seedOffset)},
                              {"loomIterations", std::to_string(done)}};
        for (const auto& out : graph.outputs()) {
            const Texture* tex = graph.fieldTexture(out.pass + "." + out.channel);
            writeImage(outDir / frameFileName(out.pass, out.channel, named, tex->format()), *tex, heldAttributes);
            ++written;
        }
    };
    warming = true;
    if (warmup > 0 && !o.quiet)
        spdlog::info("warm-up: frames {}..{} ({} frame(s)) run unwritten first, so history enters frame {} as in one "
                     "run; --warmup N runs fewer",
                     o.startFrame - warmup, o.startFrame - 1, warmup, o.startFrame);
    const auto warmStart = std::chrono::steady_clock::now();
    for (uint64_t i = o.startFrame - warmup, n = 0; i < o.startFrame && !stopRequested(); ++i, ++n) {
        graph.execute(sceneFrame(scene.get(), i, o.fps, width, height, i == o.startFrame - warmup));
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - warmStart).count();
        // What the rest will cost, said once its first frames show the pace (and the rest is worth saying).
        if (n + 1 == std::min<uint64_t>(warmup, 4) && !o.quiet && ms / double(n + 1) * double(warmup) > 10000.0)
            spdlog::info("warm-up: about {:.0f} s for {} frame(s)", ms / double(n + 1) * double(warmup) / 1000.0,
                         warmup);
        if (showProgress) progress(n + 1, warmup, ms / double(n + 1), "warm-up");
    }
    warming = false;
    if (warmup > 0) statsJson["warmup"] = {{"from", o.startFrame - warmup}, {"frames", warmup}};
    auto start = std::chrono::steady_clock::now();
    for (uint64_t i = 0; i < o.frames && !stopRequested(); ++i) {
        // Held, iteration i runs as frame index K + seed offset + i: shards with disjoint offsets draw disjoint
        // samples of frame K, and together the samples of one longer run.
        const uint64_t index = o.startFrame + (o.hold ? o.seedOffset : 0) + i;
        const bool first = i == 0 && warmup == 0;
        const FrameInfo frame = o.hold ? sceneFrameAt(scene.get(), index, heldTime, width, height, first)
                                       : sceneFrame(scene.get(), index, o.fps, width, height, first);
        graph.execute(frame);
        if (i > 0) {
            const auto stats = graph.lastStats();
            restarts += std::any_of(stats.begin(), stats.end(), [](const auto& pass) {
                const auto restarted = pass.second.find(stat::kOutputMeanRestarted);
                return restarted != pass.second.end() && restarted->second != 0.0;
            });
        }
        done = i + 1;
        if (!o.hold || i + 1 == o.frames) writeOutputs(o.hold ? o.startFrame : frame.frameIndex);
        if (!o.statsFile.empty()) {
            nlohmann::json jf = {{"frame", frame.frameIndex}, {"passes", nlohmann::json::object()}};
            for (const auto& t : graph.timings()) jf["passes"][t.name]["ms"] = t.lastMs;
            for (const auto& [pass, counters] : graph.lastStats())
                for (const auto& [k, v] : counters) jf["passes"][pass][k] = v;
            statsJson["frames"].push_back(std::move(jf));
        }
        if (showProgress) {
            double elapsed =
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
            progress(i + 1, o.frames, elapsed / double(i + 1));
        }
    }
    const int stoppedBy = done < o.frames ? stopSignal() : 0;
    if (stoppedBy) {
        if (showProgress) std::fprintf(stderr, "\n");
        // A held frame stopped early: its outputs after the iterations done (less converged, still that frame).
        if (o.hold && done > 0) writeOutputs(o.startFrame);
        statsJson["interrupted"] = {{"signal", signalName(stoppedBy)}, {"framesDone", done}};
    }
    if (!o.statsFile.empty()) writeFileAtomic(o.statsFile, statsJson.dump(2) + "\n");
    if (restarts > 0)
        spdlog::warn(
            "an accumulation restarted on {} of the {} frames after the first, because the scene or the "
            "camera moved or an animated light changed: the images do not converge. To converge one frame "
            "K of a moving scene, hold it: --start-frame K --frames N --hold",
            restarts, done - 1);

    if (stoppedBy)
        spdlog::warn("stopped by {} after {} of {} frame(s); the outputs and statistics of those are written",
                     signalName(stoppedBy), done, o.frames);
    if (!o.quiet) {
        if (o.hold)
            std::cout << fmt::format(
                "Held frame {} (t = {:g} s) for {} iteration(s) at {}x{}: {} output image(s) (the last iteration's, "
                "numbered {}), {} dump(s) in {}\n",
                o.startFrame, heldTime, done, width, height, written, o.startFrame, dumped, o.out);
        else
            std::cout << fmt::format("Rendered {} frame(s) at {}x{}: {} output image(s), {} dump(s) in {}\n", done,
                                     width, height, written, dumped, o.out);
        std::cout << fmt::format("  {:24} {:>12} {:>12}\n", "pass", "mean ms", "total ms");
        double total = 0;
        for (const auto& t : graph.timings()) {
            std::cout << fmt::format("  {:24} {:>12.3f} {:>12.3f}\n", t.name, t.totalMs / std::max<uint64_t>(t.runs, 1),
                                     t.totalMs);
            total += t.totalMs;
        }
        std::cout << fmt::format("  {:24} {:>12.3f} {:>12.3f}\n", "all passes",
                                 total / double(std::max<uint64_t>(done, 1)), total);
    }
}

}  // namespace

void addRenderCommand(CLI::App& app) {
    auto o = std::make_shared<RenderOptions>();
    CLI::App* cmd = app.add_subcommand("render", "Render a graph headless and write its outputs");
    cmd->add_option("--graph,-g", o->graph, "graph file (.json)")->required();
    cmd->add_option("--frames,-n", o->frames, "number of frames")->capture_default_str();
    cmd->add_option("--start-frame", o->startFrame, "index of the first frame")->capture_default_str();
    addSizeOption(cmd, o->size, "256x256");
    cmd->add_option("--out,-o", o->out, "output folder")->capture_default_str();
    cmd->add_option("--dump", o->dump, "dump fields matching a glob, e.g. 'SVGF.*' (repeatable)");
    cmd->add_option("--dump-frames", o->dumpFrames, "frames to dump, e.g. 3,10-12 (default: all)");
    cmd->add_option("--set", o->set, "set a parameter: Pass.param=value (repeatable)");
    cmd->add_option("--threads", o->threads, "worker threads (0 = all cores)")->capture_default_str();
    cmd->add_option("--stats", o->statsFile, "write per-frame timings and counters as JSON");
    cmd->add_option("--fps", o->fps, "frames per second of the animation clock")->capture_default_str();
    cmd->add_flag("--quiet,-q", o->quiet, "no progress bar or summary");
    cmd->add_option("--warmup", o->warmup,
                    "before --start-frame K, run frames unwritten so history is as in one run from frame 0: auto "
                    "(from frame 0 where the graph keeps history, else none), all, or a number of frames")
        ->capture_default_str();
    cmd->add_option("--seed-offset", o->seedOffset,
                    "with --hold: iteration i runs as frame index K + offset + i, so runs with disjoint offsets "
                    "render disjoint samples of frame K (merge them with loom image merge)")
        ->capture_default_str();
    cmd->add_flag("--hold", o->hold,
                  "hold one frame: run --frames iterations of frame --start-frame at its scene time and camera "
                  "(fresh random numbers each; an accumulating graph converges that frame) and write the outputs "
                  "once, after the last, under that frame's number");
    addDeviceOption(cmd, o->device);
    cmd->add_flag("--dry-run", o->dryRun,
                  "check everything (graph, scene, parameters, size, frame and seed limits, warm-up) and stop before "
                  "the first frame: nothing is rendered or written (exit 0, or 2 naming what is wrong)");
    cmd->add_flag("--poison", o->poison, "fill transient memory with NaN when its lifetime starts (debug)");
    addSceneOptions(cmd, o->scene);
    cmd->callback([o, cmd] {
        o->sizeGiven = cmd->count("--size") > 0;
        runRender(*o);
    });
}

}  // namespace loom::cli
