#pragma once
// loom bench: lag figures. How many frames a temporal graph needs to recover after an event: the camera cut that
// starts every run, a lighting step at a given frame, and the disocclusion of a pixel (by its age since it became
// visible). The definitions are in docs/BENCH.md ("Lag"); everything here is a plain function of its inputs.
#include <array>
#include <cstdint>
#include <glm/vec2.hpp>
#include <glm/vec4.hpp>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "loom/Texture.h"

namespace loom {
class RenderGraph;
}

namespace loom::cli::bench {

/// "Back": within this fraction above the steady state.
inline constexpr double kLagTolerance = 0.1;
/// Frames of the forward window that smooths the per-frame error before it is compared with the steady state.
inline constexpr size_t kLagWindow = 5;
/// Age buckets 0, 1, ..., kAgeCap - 1 and kAgeCap+ (the last bucket).
inline constexpr uint32_t kAgeCap = 16;
/// Relative depth tolerance of the age tracker's reprojection test (on top of one pixel's depth slope).
inline constexpr float kAgeDepthTolerance = 0.05f;

/// The recovery of a per-frame error curve after one event.
struct Recovery {
    uint64_t frame = 0;  ///< the event's frame
    std::string kind;    ///< "cut" or "light"
    /// Frames after the event until the smoothed error is back, for good, within the tolerance of the steady state;
    /// empty when the segment never settles (its last half is not flat).
    std::optional<uint64_t> frames;
    double steady = 0;  ///< the steady state: mean error over the last half of the segment
    bool settled = false;
    uint64_t segmentFrames = 0;  ///< frames from the event to the next event or the end of the run
};

/// Recovery after the event at index `event` of `errors` (per frame, consecutive), its segment ending before index
/// `end` (the next event, or errors.size()). Steady state S = mean of errors over the segment's last half,
/// [event + L/2, end) with L = end - event (L/2 rounded down). The segment is settled when the means of the two
/// halves of that last half differ by at most 2 * tolerance * S. The smoothed error at t is the mean of errors over
/// [t, t + w), w = min(window, length of the last half), without the largest of them when w >= 3 (one outlying
/// frame, a firefly, is no lag); frames to recover = the smallest k >= 0 such that the
/// smoothed error is <= (1 + tolerance) * S at every t in [event + k, event + L/2) (being below the steady state is
/// no lag; a settled segment recovers by the start of its last half). `frame`, `kind` are left for the caller.
/// Requires event < end <= errors.size().
Recovery recoverAfter(const std::vector<double>& errors, size_t event, size_t end, double tolerance = kLagTolerance,
                      size_t window = kLagWindow);

/// Recovery after the camera cut at `firstFrame` (the run's first frame, errors[0]) and after each event frame in
/// `events` that falls inside the run (firstFrame < e < firstFrame + errors.size(); sorted and deduplicated here);
/// each segment ends at the next event.
std::vector<Recovery> frameRecoveries(const std::vector<double>& errors, uint64_t firstFrame,
                                      std::vector<uint32_t> events, double tolerance = kLagTolerance,
                                      size_t window = kLagWindow);

// ---------------------------------------------------------------------------------------------------------------
// Disocclusion: per-pixel age since a pixel became visible.

/// This frame's G-buffer fields the age tracker reads (standard channels: linearZ, mvec, meshId).
struct AgeGBuffer {
    ImageView<const glm::vec2> linearZ, mvec;
    ImageView<const uint32_t> meshId;
};

/// Ages of this frame from last frame's (prevAges, prevLinearZ, prevMeshId): for a pixel p with a hit (linearZ.x >=
/// 0), q = the previous pixel nearest to p's centre moved by mvec (uvPrev = uv + mvec, uv = (p + 0.5) / size); p
/// continues q's history, age = prevAges(q) + 1, when q lies in the frame, was a hit with the same meshId, and
/// |z - zPrev| <= kAgeDepthTolerance * z + linearZ.y (a relative tolerance plus one pixel's depth slope, since q's
/// centre may lie half a pixel off along each axis); else age 0. Misses get age 0. `ages` has the frame's size.
void updateAges(const AgeGBuffer& cur, ImageView<const uint32_t> prevAges, ImageView<const glm::vec2> prevLinearZ,
                ImageView<const uint32_t> prevMeshId, ImageView<uint32_t> ages);

/// Per-pixel error summed by age: bucket a < kAgeCap holds pixels of age a, bucket kAgeCap those of age >= kAgeCap.
struct AgeBuckets {
    std::array<double, kAgeCap + 1> sum{};
    std::array<uint64_t, kAgeCap + 1> count{};
    std::optional<double> mean(uint32_t bucket) const;
};

/// Adds the per-pixel error (`error`, RelMSE's per-pixel term) of every hit pixel (linearZ.x >= 0) whose test and
/// reference colours are finite (`test`, `ref`) to its age's bucket, in row order.
void addAgeErrors(ImageView<const uint32_t> ages, ImageView<const glm::vec2> linearZ, ImageView<const float> error,
                  ImageView<const glm::vec4> test, ImageView<const glm::vec4> ref, AgeBuckets& buckets);

/// The smallest age a such that every non-empty bucket from a to kAgeCap - 1 has a mean error <= (1 + tolerance)
/// times the kAgeCap+ bucket's (kAgeCap: not before the last bucket, "16+" in summary.md); empty when that bucket is
/// empty.
std::optional<uint32_t> agesToRecover(const AgeBuckets& buckets, double tolerance = kLagTolerance);

/// Tracks ages over a run and collects the age buckets of its measured frames.
class DisocclusionTracker {
public:
    /// One frame, in order; `cut` resets every age to 0 (the run's first frame). `measured`: the frame's errors go
    /// into the buckets (frames after the warm-up). `test`, `ref`: RGBA32F.
    void addFrame(const AgeGBuffer& gbuffer, const Texture& test, const Texture& ref, bool cut, bool measured);
    const AgeBuckets& buckets() const { return mBuckets; }

private:
    Texture mAges, mPrevAges, mPrevLinearZ, mPrevMeshId, mError;
    AgeBuckets mBuckets;
};

/// The "Pass.field" names of a compiled graph's G-buffer (the first live pass that outputs the standard channels
/// linearZ, mvec and meshId) that the age tracker reads; empty when the graph has none.
std::vector<std::string> ageGBufferFields(const RenderGraph& graph);

/// Views of those fields after a frame; nullopt when one is missing or of another format.
std::optional<AgeGBuffer> ageGBuffer(const RenderGraph& graph, const std::vector<std::string>& fields);

/// The lag figures of one run.
struct Lag {
    std::vector<Recovery> recoveries;  ///< the cut first, then the lighting steps inside the run
    /// Disocclusion (graphs with a G-buffer only).
    std::optional<AgeBuckets> ages;
    std::optional<uint32_t> agesToRecover;
};

/// The lag figures of a run from its per-frame RelMSE (frames in order from `firstFrame`), the lighting steps, and
/// the age tracker of its measured frames (nullptr: the graph has no G-buffer).
Lag runLag(const std::vector<double>& relMSE, uint64_t firstFrame, const std::vector<uint32_t>& events,
           const DisocclusionTracker* ages);

/// The "lag" object of a run in results.json.
nlohmann::json lagJson(const Lag& lag);

/// The lag section of summary.md: frames to recover per run, and the RelMSE by age of the runs with a G-buffer.
/// `runs`: each run's label columns ("| graph | params") and its lag.
std::string lagMarkdown(const std::vector<std::pair<std::string, const Lag*>>& runs);

}  // namespace loom::cli::bench
