#include "BenchReport.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "loom/Files.h"
#include "loom/ImageIO.h"

namespace loom::cli::bench {

namespace {

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// log() that stays finite for a zero error or time (a perfect match is far below any curve point).
double safeLog(double x) {
    return std::log(std::max(x, 1e-30));
}

std::string csvField(const std::string& s) {
    if (s.find_first_of(",\"\n") == std::string::npos) return s;
    std::string out = "\"";
    for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
    return out + "\"";
}

/// Shortest round-trip text of a double, so CSV and JSON carry the same value.
std::string number(double v) {
    return fmt::format("{}", v);
}

std::string passList(const std::vector<std::pair<std::string, double>>& passMs, const char* sep, int digits) {
    std::string out;
    for (const auto& [name, ms] : passMs) {
        if (!out.empty()) out += sep;
        out += fmt::format("{} {:.{}f}", name, ms, digits);
    }
    return out;
}

nlohmann::json passJson(const std::vector<std::pair<std::string, double>>& passMs) {
    nlohmann::json j = nlohmann::json::object();
    for (const auto& [name, ms] : passMs) j[name] = ms;
    return j;
}

nlohmann::json optionalJson(const std::optional<double>& v) {
    return v ? nlohmann::json(*v) : nlohmann::json();
}

nlohmann::json speedupJson(const Speedup& s) {
    return {{"kind", s.kindName()},
            {"value", s.kind == Speedup::Kind::None ? nlohmann::json() : nlohmann::json(s.value)},
            {"text", s.text()}};
}

nlohmann::json runJson(const Run& r, bool withSpeedup) {
    nlohmann::json frames = nlohmann::json::array();
    for (const FrameResult& f : r.frames) {
        frames.push_back({{"frame", f.frame},
                          {"time", f.time},
                          {"total_ms", f.totalMs},
                          {"pass_ms", passJson(f.passMs)},
                          {"relmse", f.metrics.relMSE},
                          {"smape", f.metrics.smape},
                          {"psnr", f.metrics.psnr},
                          {"ssim", f.metrics.ssim},
                          {"flip", f.metrics.flip},
                          {"trimmed_relmse", f.metrics.trimmedRelMSE},
                          {"temporal", optionalJson(f.metrics.temporal)},
                          {"non_finite", f.metrics.nonFinite}});
    }
    const Summary& s = r.summary;
    nlohmann::json j = {{"graph", r.graph},
                        {"graph_file", r.graphFile},
                        {"params", r.params},
                        {"measured", r.measured},
                        {"summary",
                         {{"frames", s.frames},
                          {"total_ms", s.totalMs},
                          {"pass_ms", passJson(s.passMs)},
                          {"relmse", s.relMSE},
                          {"smape", s.smape},
                          {"psnr", s.psnr},
                          {"ssim", s.ssim},
                          {"flip", s.flip},
                          {"trimmed_relmse", s.trimmedRelMSE},
                          {"temporal", optionalJson(s.temporal)},
                          {"flicker", optionalJson(s.flicker)},
                          {"non_finite", s.nonFinite}}},
                        {"frames", std::move(frames)}};
    if (r.bruteForce) j["spp"] = r.spp;
    j["lag"] = lagJson(r.lag);
    if (withSpeedup) {
        j["speedup_relmse"] = speedupJson(r.speedupRelMSE);
        j["speedup_flip"] = speedupJson(r.speedupFlip);
        j["speedup_trimmed_relmse"] = speedupJson(r.speedupTrimmed);
    }
    return j;
}

std::string csvText(const std::vector<Run>& variants, const std::vector<Run>& curve, uint64_t warmup,
                    const std::vector<uint32_t>& events) {
    std::ostringstream s;
    s << "kind,graph,params,measured,frame,time,warmup,total_ms,relmse,smape,psnr,ssim,flip,temporal,non_finite,"
         "event,pass_ms,trimmed_relmse\n";
    // "cut" at a run's first frame, "light" at a lighting step.
    auto eventName = [&](const Run& r, uint64_t frame) {
        if (frame == r.frames.front().frame) return "cut";
        return std::find(events.begin(), events.end(), frame) != events.end() ? "light" : "";
    };
    auto rows = [&](const std::vector<Run>& runs) {
        for (const Run& r : runs) {
            for (const FrameResult& f : r.frames) {
                const FrameMetrics& m = f.metrics;
                s << (r.bruteForce ? "bruteforce" : "graph") << ',' << csvField(r.graph) << ',' << csvField(r.params)
                  << ',' << csvField(r.measured) << ',' << f.frame << ',' << number(f.time) << ','
                  << (f.frame < warmup ? 1 : 0) << ',' << (std::isfinite(f.totalMs) ? number(f.totalMs) : "") << ','
                  << number(m.relMSE) << ',' << number(m.smape) << ',' << number(m.psnr) << ',' << number(m.ssim) << ','
                  << number(m.flip) << ',' << (m.temporal ? number(*m.temporal) : std::string()) << ',' << m.nonFinite
                  << ',' << eventName(r, f.frame) << ',' << csvField(passList(f.passMs, ";", 4)) << ','
                  << number(m.trimmedRelMSE) << '\n';
            }
        }
    };
    rows(variants);
    rows(curve);
    return s.str();
}

std::string summaryMarkdown(const BenchInfo& info, const std::vector<Run>& variants, const std::vector<Run>& curve) {
    std::ostringstream s;
    const bool given = !info.referenceSequence.empty();
    if (info.scene.empty()) {
        s << fmt::format("### no scene — {}x{}", info.width, info.height);
    } else {
        s << fmt::format("### {} — {}x{}, camera {}", info.scene, info.width, info.height, info.cameraPath);
        if (info.cameraPath != "static") s << fmt::format(" (speed {})", info.cameraSpeed);
    }
    s << "\n\n";
    const std::string reference =
        given
            ? fmt::format(
                  "the given frames `{}` (frame i is file number i{}), not rendered", info.referenceSequence,
                  info.referenceFirstFrame == 0 ? std::string() : fmt::format(" + {}", info.referenceFirstFrame))
            : fmt::format("{} at {} spp per frame{} ({} frame(s) from the cache, {} rendered)", info.referenceGraph,
                          info.referenceSpp, info.referenceShared ? ", one image for every frame (nothing moves)" : "",
                          info.referenceFramesCached, info.referenceFramesRendered);
    s << fmt::format(
        "Loom {}; {} frames at {} fps, the first {} are warm-up; times are medians and metrics means over the {} "
        "frames after it. Reference: {}.{} Threads: {}. Load average (1, 5, 15 min) before: {}; after: {}.",
        info.loomVersion, info.frames, info.fps, info.warmup, info.frames - info.warmup, reference,
        info.scene.empty() ? std::string() : " Jitter: " + info.jitter + ".",
        info.threads ? std::to_string(info.threads) : std::string("all cores"), info.loadBefore, info.loadAfter);
    if (!info.set.empty()) {
        std::vector<std::string> quoted;
        for (const auto& a : info.set) quoted.push_back("`" + a + "`");
        s << " Set on every graph: " << fmt::format("{}", fmt::join(quoted, ", ")) << ".";
    }
    s << "\n\n";
    if (given)
        s << "Reference noise (RelMSE): unknown (given frames): there is no noise floor, and whatever noise the "
             "references hold adds to every error below.";
    else
        s << fmt::format(
            "Reference path length: maxBounces {} (from {}), Russian roulette from bounce {}; pixel filter {}. "
            "Reference noise (RelMSE): {}.",
            info.referenceBounces, info.referenceBouncesFrom, info.referenceRrStart, info.pixelFilter,
            info.referenceNoise ? fmt::format("{:.3g}", *info.referenceNoise) : std::string("n/a (one batch)"));
    if (!curve.empty())
        s << fmt::format(
            " Brute force: times are medians of {} frame(s) rendered at each spp; its images are built as means of "
            "cached batches ({} frame(s) from the cache, {} rendered).",
            info.bruteForceTimingFrames, info.bruteForceFramesCached, info.bruteForceFramesRendered);
    else
        s << (info.scene.empty() ? " Brute force: none (no scene to path-trace), so no speedups."
                                 : " Brute force: none (--brute-force-spp none), so no speedups.");
    s << "\n\n";
    if (!info.noiseWarning.empty()) s << "**Warning:** " << info.noiseWarning << "\n\n";
    s << "| graph | params | measured | ms/frame | per pass (ms) | RelMSE | trimmed RelMSE | SMAPE | PSNR (dB) | SSIM "
         "| FLIP | temporal | flicker | speedup (RelMSE) | speedup (trimmed) | speedup (FLIP) |\n";
    s << "|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    auto optional4 = [](const std::optional<double>& v) { return v ? fmt::format("{:.4f}", *v) : std::string("—"); };
    auto row = [&](const Run& r, bool withSpeedup) {
        const Summary& m = r.summary;
        s << fmt::format(
            "| {} | {} | {} | {:.1f} | {} | {:.4g} | {:.4g} | {:.4f} | {:.2f} | {:.4f} | {:.4f} | {} | {} | {} | {} | "
            "{} "
            "|\n",
            r.graph, r.params.empty() ? "—" : r.params, r.measured, m.totalMs, passList(m.passMs, " · ", 1), m.relMSE,
            m.trimmedRelMSE, m.smape, m.psnr, m.ssim, m.flip, optional4(m.temporal), optional4(m.flicker),
            withSpeedup ? r.speedupRelMSE.text() : "—", withSpeedup ? r.speedupTrimmed.text() : "—",
            withSpeedup ? r.speedupFlip.text() : "—");
    };
    for (const Run& r : variants) row(r, true);
    for (const Run& r : curve) row(r, false);
    if (info.bias) {
        const BiasRow& b = *info.bias;
        s << fmt::format("| {} | — | reference | — | — | {:.4g} | {:.4g} | — | — | — | {:.4f} | — | — | — | — | — |\n",
                         b.label(), b.relMSE, b.trimmedRelMSE, b.flip);
    }
    s << "\n";
    if (info.bias)
        s << fmt::format(
            "The {} row is the matched reference against the reference graph's own {} bounces (same seeds, so the "
            "difference is the longer paths' light; the full-length reference's own noise is {}), not an error of any "
            "graph: every graph and brute-force point carries it in addition to the error above.\n\n",
            info.bias->label(), info.bias->fullBounces,
            info.bias->fullNoise ? fmt::format("{:.3g}", *info.bias->fullNoise) : std::string("n/a"));
    std::vector<std::pair<std::string, const Lag*>> lags;
    for (const auto* runs : {&variants, &curve})
        for (const Run& r : *runs)
            lags.emplace_back(fmt::format("| {} | {}", r.graph, r.params.empty() ? "—" : r.params), &r.lag);
    s << lagMarkdown(lags);
    return s.str();
}

}  // namespace

std::string BiasRow::label() const {
    return fmt::format("bias: {} vs {} bounces", graphBounces, fullBounces);
}

std::string Speedup::text() const {
    switch (kind) {
        case Kind::Exact:
            return fmt::format("{:.2f}x", value);
        case Kind::AtLeast:
            return fmt::format("> {:.2f}x", value);
        case Kind::AtMost:
            return fmt::format("< {:.2f}x", value);
        case Kind::None:
            break;
    }
    return "n/a";
}

const char* Speedup::kindName() const {
    switch (kind) {
        case Kind::Exact:
            return "exact";
        case Kind::AtLeast:
            return "at_least";
        case Kind::AtMost:
            return "at_most";
        case Kind::None:
            break;
    }
    return "none";
}

Summary summarize(const std::vector<FrameResult>& frames, uint64_t warmup) {
    Summary s;
    std::vector<double> total;
    std::map<std::string, std::vector<double>> perPass;
    std::vector<std::string> passOrder;
    double temporalSum = 0;
    size_t temporalCount = 0;
    for (const FrameResult& f : frames) {
        if (f.frame < warmup) continue;
        ++s.frames;
        if (std::isfinite(f.totalMs)) total.push_back(f.totalMs);
        for (const auto& [name, ms] : f.passMs) {
            auto [it, inserted] = perPass.try_emplace(name);
            if (inserted) passOrder.push_back(name);
            it->second.push_back(ms);
        }
        const FrameMetrics& m = f.metrics;
        s.relMSE += m.relMSE;
        s.smape += m.smape;
        s.psnr += m.psnr;
        s.ssim += m.ssim;
        s.flip += m.flip;
        s.trimmedRelMSE += m.trimmedRelMSE;
        s.nonFinite += m.nonFinite;
        if (m.temporal) {
            temporalSum += *m.temporal;
            ++temporalCount;
        }
    }
    if (s.frames == 0) return s;
    const double n = double(s.frames);
    s.relMSE /= n;
    s.smape /= n;
    s.psnr /= n;
    s.ssim /= n;
    s.flip /= n;
    s.trimmedRelMSE /= n;
    if (temporalCount) s.temporal = temporalSum / double(temporalCount);
    s.totalMs = median(total);
    for (const auto& name : passOrder) s.passMs.emplace_back(name, median(perPass[name]));
    return s;
}

Speedup equalErrorSpeedup(const std::vector<Run>& curve, double error, double ms, double Summary::*metric) {
    Speedup out;
    if (curve.empty() || !(ms > 0.0) || !std::isfinite(error)) return out;
    const double target = safeLog(error);
    auto err = [&](size_t i) { return safeLog(curve[i].summary.*metric); };
    auto time = [&](size_t i) { return safeLog(curve[i].summary.totalMs); };
    // Worse than (or equal to) the cheapest point: brute force gets there in at most that point's time.
    if (target >= err(0)) {
        out.kind = Speedup::Kind::AtMost;
        out.value = curve[0].summary.totalMs / ms;
        return out;
    }
    // The first segment (in increasing spp) whose error range contains the target.
    for (size_t i = 0; i + 1 < curve.size(); ++i) {
        const double e0 = err(i), e1 = err(i + 1);
        if (e1 <= target && target < e0) {
            const double u = (target - e0) / (e1 - e0);
            out.kind = Speedup::Kind::Exact;
            out.value = std::exp(time(i) + u * (time(i + 1) - time(i))) / ms;
            return out;
        }
    }
    // Better than every point: brute force needs more than the most expensive point's time.
    out.kind = Speedup::Kind::AtLeast;
    out.value = curve.back().summary.totalMs / ms;
    return out;
}

void writeResults(const std::filesystem::path& dir, const BenchInfo& info, const std::vector<Run>& variants,
                  const std::vector<Run>& curve) {
    writeFileAtomic(dir / "results.csv", csvText(variants, curve, info.warmup, info.eventFrames));

    nlohmann::json j;
    j["loom_bench"] = 1;
    j["loom_version"] = info.loomVersion;
    const bool given = !info.referenceSequence.empty();
    const bool scene = !info.scene.empty();
    j["scene"] = scene ? nlohmann::json(info.scene) : nlohmann::json();
    j["camera_path"] = scene ? nlohmann::json(info.cameraPath) : nlohmann::json();
    j["camera_speed"] = scene ? nlohmann::json(info.cameraSpeed) : nlohmann::json();
    j["jitter"] = scene ? nlohmann::json(info.jitter) : nlohmann::json();
    j["width"] = info.width;
    j["height"] = info.height;
    j["frames"] = info.frames;
    j["warmup"] = info.warmup;
    j["fps"] = info.fps;
    j["event_frames"] = info.eventFrames;
    j["set"] = info.set;
    j["threads"] = info.threads;
    j["load_before"] = info.loadBefore;
    j["load_after"] = info.loadAfter;
    // "noise": how the reference's own noise is known: "estimated" (noise_relmse), "one batch" (a rendered
    // reference of a single batch: no spread to estimate it from) or "unknown" (given frames).
    const char* noise = given ? "unknown" : info.referenceNoise ? "estimated" : "one batch";
    // Given references have none of a rendered one's settings: those are null.
    auto rendered = [given](const nlohmann::json& v) { return given ? nlohmann::json() : v; };
    j["reference"] = {{"source", given ? "sequence" : "rendered"},
                      {"graph", rendered(info.referenceGraph)},
                      {"spp", rendered(info.referenceSpp)},
                      {"cache", rendered(info.referenceCache)},
                      {"frames_cached", info.referenceFramesCached},
                      {"frames_rendered", info.referenceFramesRendered},
                      {"shared", info.referenceShared},
                      {"max_bounces", rendered(info.referenceBounces)},
                      {"rr_start_bounce", rendered(info.referenceRrStart)},
                      {"bounces_from", rendered(info.referenceBouncesFrom)},
                      {"pixel_filter", rendered(info.pixelFilter)},
                      {"noise", noise},
                      {"noise_relmse", optionalJson(info.referenceNoise)},
                      {"noise_warning", info.noiseWarning}};
    if (given) {
        j["reference"]["sequence"] = info.referenceSequence;
        j["reference"]["first_frame"] = info.referenceFirstFrame;
    }
    if (info.bias) {
        const BiasRow& b = *info.bias;
        j["bias"] = {{"label", b.label()},
                     {"graph_bounces", b.graphBounces},
                     {"full_bounces", b.fullBounces},
                     {"relmse", b.relMSE},
                     {"trimmed_relmse", b.trimmedRelMSE},
                     {"flip", b.flip},
                     {"full_reference_noise_relmse", optionalJson(b.fullNoise)},
                     {"cache", b.cache},
                     {"frames_cached", b.framesCached},
                     {"frames_rendered", b.framesRendered}};
    } else {
        j["bias"] = nullptr;
    }
    j["brute_force_timing_frames"] = info.bruteForceTimingFrames;
    j["brute_force_cache"] = {
        {"folder", info.bruteForceCache.empty() ? nlohmann::json() : nlohmann::json(info.bruteForceCache)},
        {"frames_cached", info.bruteForceFramesCached},
        {"frames_rendered", info.bruteForceFramesRendered}};
    j["brute_force_graph"] = info.bruteForceGraph.empty() ? nlohmann::json() : nlohmann::json(info.bruteForceGraph);
    j["equal_error_metrics"] = {"relmse", "trimmed_relmse", "flip"};
    j["variants"] = nlohmann::json::array();
    for (const Run& r : variants) j["variants"].push_back(runJson(r, true));
    j["brute_force"] = nlohmann::json::array();
    for (const Run& r : curve) j["brute_force"].push_back(runJson(r, false));
    writeFileAtomic(dir / "results.json", j.dump(1) + "\n");

    writeFileAtomic(dir / "summary.md", summaryMarkdown(info, variants, curve));
}

}  // namespace loom::cli::bench
