#pragma once
// loom bench: the results of a run (per frame, per graph variant, per brute-force point), their summaries, the
// equal-error speedup, and the files they are written to (results.csv, results.json, summary.md).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "BenchLag.h"

namespace loom::cli::bench {

/// The metrics of one frame against its reference (docs/METRICS.md). `temporal` is empty on the first frame of a
/// run (no previous frame).
struct FrameMetrics {
    double relMSE = 0, smape = 0, psnr = 0, ssim = 0, flip = 0;
    double trimmedRelMSE = 0;  ///< RelMSE without the largest 0.1 % of per-pixel terms (Metrics.h)
    std::optional<double> temporal;
    uint64_t nonFinite = 0;  ///< the largest nonFinite count over the metrics
};

struct FrameResult {
    uint64_t frame = 0;
    double time = 0;                                     ///< seconds on the animation clock
    double totalMs = 0;  ///< wall time of the graph's execute; NaN where not timed (brute force: see Run)
    std::vector<std::pair<std::string, double>> passMs;  ///< per pass, execution order
    FrameMetrics metrics;
};

/// Equal-error speedup: the brute-force time per frame that reaches the variant's error, over the variant's time.
/// Outside the curve's error range only a bound is known.
struct Speedup {
    enum class Kind { None, Exact, AtLeast, AtMost };
    Kind kind = Kind::None;
    double value = 0;
    /// "3.21x", "> 5.0x", "< 0.80x" or "n/a".
    std::string text() const;
    /// "exact", "at_least", "at_most" or "none".
    const char* kindName() const;
};

/// Means over the measured (post-warm-up) frames; medians for times.
struct Summary {
    size_t frames = 0;
    double totalMs = 0;
    std::vector<std::pair<std::string, double>> passMs;
    double relMSE = 0, smape = 0, psnr = 0, ssim = 0, flip = 0, trimmedRelMSE = 0;
    std::optional<double> temporal;
    /// Static-camera flicker (FlickerAccumulator, Metrics.h) over the measured frames, when nothing moves (the
    /// sequence shares one reference); empty otherwise.
    std::optional<double> flicker;
    uint64_t nonFinite = 0;  ///< summed over the measured frames
};

/// One graph variant (a graph, or one point of a sweep over it) or one brute-force point.
struct Run {
    bool bruteForce = false;
    std::string graph;      ///< graph name
    std::string graphFile;  ///< as resolved
    std::string params;     ///< sweep assignment ("SVGF.iterations=2"), or "samplesPerPixel=N" for brute force
    std::string measured;   ///< "Pass.field" the metrics are taken of
    uint32_t spp = 0;       ///< brute force: samples per pixel per frame
    std::vector<FrameResult> frames;
    Summary summary;
    Speedup speedupRelMSE, speedupFlip, speedupTrimmed;
    Lag lag;  ///< frames to recover after the cut, lighting steps and disocclusion (BenchLag.h)
};

/// The bias of the matched reference's path length: its metrics against the reference graph's own (longer) paths,
/// averaged over the measured frames. The references share seeds, so it holds the noise of the longer paths only.
struct BiasRow {
    int graphBounces = 0, fullBounces = 0;
    double relMSE = 0, trimmedRelMSE = 0, flip = 0;
    std::optional<double> fullNoise;  ///< reference noise (RelMSE) of the full-length reference
    uint64_t framesCached = 0, framesRendered = 0;
    std::string cache;
    std::string label() const;  ///< "bias: 3 vs 8 bounces"
};

/// Everything about the run that is not a result: written at the top of every output.
struct BenchInfo {
    std::string loomVersion;
    std::string scene;  ///< the scene file's name; empty without a scene (given references, graphs of files)
    std::string cameraPath;
    float cameraSpeed = 0;
    std::string jitter;
    uint32_t width = 0, height = 0;
    uint64_t frames = 0, warmup = 0;
    double fps = 0;
    /// Frames of lighting steps (--event-frame, and any the scene defines): the lag figures measure the recovery
    /// after each, and the per-frame plot marks them.
    std::vector<uint32_t> eventFrames;
    std::vector<std::string> set;  ///< --set assignments applied to every graph
    /// --reference-sequence as given: the references are these files, not rendered (empty: rendered). Their noise
    /// is unknown; the rendered reference's fields below are then unset.
    std::string referenceSequence;
    int64_t referenceFirstFrame = 0;  ///< the file number of frame 0
    std::string referenceGraph;
    uint32_t referenceSpp = 0;
    std::string referenceCache;  ///< the cache entry folder
    uint64_t referenceFramesCached = 0, referenceFramesRendered = 0;
    bool referenceShared = false;  ///< one reference for every frame (nothing moves)
    int referenceBounces = 0, referenceRrStart = 0;  ///< the matched reference's path length
    std::string referenceBouncesFrom;                ///< "the graphs", "--reference-bounces" or "the reference graph"
    std::string pixelFilter;                         ///< the reference's (and brute force's) PathTracer.pixelFilter
    /// The reference's own noise as a RelMSE term (mean over the measured frames of the per-pixel variance of its
    /// mean, from the spread of its batches, over ref^2 + eps); empty with a single batch.
    std::optional<double> referenceNoise;
    std::optional<BiasRow> bias;
    std::string noiseWarning;  ///< set when the reference noise is not 10x below the smallest error
    uint32_t bruteForceTimingFrames = 0;
    std::string bruteForceCache;
    uint64_t bruteForceFramesCached = 0, bruteForceFramesRendered = 0;
    std::string bruteForceGraph;  ///< empty when there is no curve
    unsigned threads = 0;
    std::string loadBefore, loadAfter;  ///< /proc/loadavg at the start and the end
};

/// Medians of times (over the timed frames) and means of metrics over the frames with index >= warmup.
Summary summarize(const std::vector<FrameResult>& frames, uint64_t warmup);

/// Interpolates the brute-force curve (runs in increasing spp) in log(time)-log(error) at `error`; `metric` picks
/// the error (relMSE or flip) from a summary.
Speedup equalErrorSpeedup(const std::vector<Run>& curve, double error, double ms, double Summary::*metric);

/// Writes results.csv, results.json and summary.md into `dir` (atomically, each).
void writeResults(const std::filesystem::path& dir, const BenchInfo& info, const std::vector<Run>& variants,
                  const std::vector<Run>& curve);

}  // namespace loom::cli::bench
