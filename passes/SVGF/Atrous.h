#pragma once
// The à-trous stage of SVGF on the CPU: every level of one frame, with the guides (depth, depth derivative,
// normal) packed once per frame and reused by each level. The result agrees with the scalar reference kernel
// (AtrousKernels.h) within a stated tolerance (3e-5 relative, see AtrousSimd.h); `reference = true` runs the
// reference kernel itself. The fast path allocates only when the size changes (or when more levels than ever before
// need wider plane margins); prepareMs covers the guide packing of setGuide and the signal packing of run.
#include <cstdint>
#include <vector>

#include "AtrousKernels.h"
#include "AtrousSimd.h"
#include "loom/PageMemory.h"
#include "loom/Texture.h"

namespace loom::svgf {

/// Per-level timings of the last run (milliseconds), for the pass's stats.
struct AtrousTimings {
    double prepareMs = 0.0;
    double levelMs[16] = {};
    uint32_t skippedTiles = 0;  ///< tiles that kept their input (AtrousParams::skipRelVariance)
    uint32_t tiles = 0;         ///< tiles of the frame, kSkipTile x kSkipTile
};

class AtrousFilter {
public:
    /// Packs this frame's guides. Memory is reallocated only when the size changes.
    void setGuide(ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal);

    /// The planes a caller fills itself instead of setGuide: this frame's guide planes and the input signal of the
    /// next run() (whose src must then hold the same pixels: the reference path and feedback tap -1 read it).
    struct FramePlanes {
        const simd::PlaneLayout* layout;
        simd::GuidePlanes guide;
        simd::SignalPlanes signal;   ///< input of the next run() with slot 0
        simd::SignalPlanes signal1;  ///< input of the next run() with slot 1 (signals = 2 only)
    };
    /// Lays out the planes for `iterations` levels and `signals` (1 or 2) inputs and returns them for the caller to
    /// fill (interior only).
    FramePlanes preparePlanes(ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal, int iterations,
                              int signals = 1);

    /// Runs `iterations` levels with steps 1, 2, 4, ... on src (rgb illumination, a variance) into dst.
    /// When `feedback` is non-null it receives the output of level `feedbackTap` (0-based; clamped to the last
    /// level; a negative tap copies src, the unfiltered signal). iterations == 0 copies src to dst.
    /// src, dst and feedback have the guide's size; dst and feedback may not alias src.
    /// With `modulate` (fast path only), the last level writes the remodulated result to modulate->dst instead of
    /// its rgb + variance to dst (dst is not written, and the last level's variance is not propagated unless it is
    /// the feedback tap).
    /// `slot` 1 runs a second signal on the same guides (SVGF's direct/indirect split) with planes of its own.
    void run(ImageView<const glm::vec4> src, ImageView<glm::vec4> dst, int iterations, const AtrousParams& params,
             int feedbackTap = -1, ImageView<glm::vec4> feedback = {}, bool reference = false,
             AtrousTimings* timings = nullptr, const simd::Remodulation* modulate = nullptr, int slot = 0);

private:
    /// (Re)allocates the planes for steps up to maxStep; true when the layout changed (guides need packing).
    bool ensureLayout(int maxStep);
    void packGuide();
    /// Flags the tiles whose hit pixels of src all have a relative variance below params.skipRelVariance (none
    /// when it is 0) into mSkipTiles; returns how many.
    uint32_t classifyTiles(ImageView<const glm::vec4> src, const AtrousParams& params);

    ImageView<const glm::vec2> mLinearZ;
    ImageView<const glm::vec4> mNormal;
    uint32_t mWidth = 0, mHeight = 0;
    // Ping-pong storage between levels of the reference path (allocated when it is first used).
    Texture mPing, mPong;
    // The fast path's planes: the guide and two signals, in one allocation.
    simd::PlaneLayout mLayout;
    PageMemory mPlaneStorage;  // huge pages where the system allows: each plane row is a 4 KiB page otherwise
    simd::GuidePlanes mGuide;
    simd::SignalPlanes mSignal[2][2];  // [slot][ping-pong]
    int mSlots = 1;  // signals laid out (mSignal[1] is allocated when 2)
    double mGuideMs = 0.0;
    bool mSignalPacked[2] = {false, false};  // preparePlanes was called: the slot's next input is in mSignal[slot][0]
    std::vector<uint8_t> mSkipTiles;         // classifyTiles: one flag per tile, mSkipTilesPerRow to a row
    uint32_t mSkipTilesPerRow = 0;
};

}  // namespace loom::svgf
