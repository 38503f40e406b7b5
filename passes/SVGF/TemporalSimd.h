#pragma once
// The vectorised temporal stage of SVGF (Google Highway, dispatched at run time): one pass over the frame that does
// what temporalPixel (SVGFKernels.h) does, for the combined signal or for direct and indirect (the split), and
// writes every pixel's à-trous input as if its history were long, so the variance stage only revisits pixels whose
// history is short. With the fast à-trous it also packs the à-trous guide planes and input planes in the same loop,
// so the à-trous stage reads no image of its own.
//
// The common case is vectorised: N pixels of a row (N = 16 on AVX-512, 8 on AVX2) whose colour samples and motion
// vectors are finite. When their 2x2 bilinear footprints all have the same integer offset from the pixels (a camera
// pan or a static view) and lie inside the frame, each footprint row is a contiguous run of every history field;
// otherwise (motion that varies across the group, a footprint at the frame's border) each pixel's taps are gathered,
// taps off the frame invalid. A hit whose valid taps carry less than kMinBilinearWeight needs the 3x3 fallback: the
// vector path writes it with the others and temporalPixel then redoes that pixel alone. Groups with a non-finite
// sample, and the row's tail, run temporalPixel pixel by pixel.
//
// The vector path performs the reference's float operations in the reference's order (the build does not contract
// a * b + c into FMAs, and max / min follow maxf / minf), so its results are bit-identical to temporalPixel's;
// tests/integration/test_svgf.cpp checks that on a moving scene against the reference stages (`referenceStages`).
//
// varianceFused does the same for stage 2: the 7x7 spatial variance estimate of the pixels whose history is short
// (every pixel of the first frames and after a camera cut, disoccluded ones later), vector for vector, with the
// reference's weight (varianceWeight in SVGFKernels.h, written in operations both sides perform identically).
#include <cstdint>

#include "AtrousSimd.h"
#include "SVGFKernels.h"

namespace loom::svgf::simd {

/// What the fused temporal stage writes besides the TemporalViews of temporalPixel.
struct TemporalOutputs {
    const PlaneLayout* layout = nullptr;  ///< null: no à-trous planes are packed (guide and signal unused)
    GuidePlanes guide;                    ///< the à-trous guides of this frame
    SignalPlanes signal;                  ///< the à-trous input: integrated colour, a = temporal variance
    SignalPlanes signal1;                 ///< the split's second à-trous input (indirect)
    ImageView<glm::vec4> estimate;        ///< signal 0 as an image (the variance stage overwrites short histories)
    ImageView<glm::vec4> estimate1;       ///< signal 1 (indirect) as an image, split only
    ImageView<float> variance;            ///< optional debug output: the temporal variance (split: summed)
    /// Optional, one entry per row: set to 1 where a pixel of the row needs the spatial variance estimate
    /// (needsSpatialVariance), else 0, so the variance stage visits only those rows.
    uint8_t* shortRows = nullptr;
    /// Optional, remodulationGroupsPerRow(width) entries per row: what the remodulation of each group of
    /// kRemodulationGroup pixels reads (Remodulation::groups), from this frame's colour, alpha, misses and emission.
    uint8_t* remodulationGroups = nullptr;
    /// false: the estimate images are written only for groups of N pixels with a short history, the only ones the
    /// variance stage reads and completes (the à-trous input planes hold every pixel's estimate). true: every pixel,
    /// for whoever reads the images (the reference à-trous path, a dump).
    bool everyEstimate = true;
    /// false: the integrated images (TemporalViews) are written only for groups with a short history and for the
    /// groups within reach of the vectorised variance stage's scalar edge columns (the first and last N + 6
    /// columns), all it reads of them. true: every pixel.
    bool everyIntegrated = true;
};

/// Pixel counts of one frame of the fused stage.
struct TemporalCounts {
    uint64_t rejected = 0;   ///< non-finite colour samples
    uint64_t reference = 0;  ///< pixels that ran temporalPixel rather than the vector path
};

/// Stage 1 over the whole frame, in bands of `rows` whole rows: the combined signal, or with p.split direct and
/// indirect.
TemporalCounts temporalFused(const TemporalViews& v, const TemporalParams& p, const TemporalOutputs& out,
                             uint32_t rows);

/// Pixel counts of one frame of the fused variance stage.
struct VarianceCounts {
    uint64_t spatial = 0;    ///< pixels that took the spatial estimate (history shorter than kSpatialVarianceFrames)
    uint64_t reference = 0;  ///< of those, pixels that ran varianceEstimatePixel rather than the vector path
};

/// Stage 2 of the fused path, after temporalFused packed the à-trous planes (layout, guide, signal0 and with
/// split signal1): varianceEstimatePixel for every pixel whose history is short, vectorised where all 7x7 taps lie
/// in the frame's columns (the reference's operations in its order: bit-identical), then those pixels' à-trous
/// input planes repacked. Requires the series form of the weight (scales.series); rows: band height. shortRows
/// (optional, TemporalOutputs::shortRows of this frame): rows without a short history are skipped.
VarianceCounts varianceFused(const VarianceViews& v, const VarianceScales& scales, const PlaneLayout& layout,
                             const GuidePlanes& guide, const SignalPlanes& signal0, const SignalPlanes& signal1,
                             bool split, uint32_t rows, const uint8_t* shortRows = nullptr);

}  // namespace loom::svgf::simd
