#pragma once
// Image error metrics: run time against error needs the field's metrics, each with one exact,
// documented convention (docs/METRICS.md has the same text with the formulas).
//
// Common rules for every metric here:
// - Inputs are two images of the same size, RGBA32F (ImageView<const glm::vec4> or a Texture of
//   format RGBA32F). Only R, G and B are read; alpha is ignored. `test` is the image under
//   evaluation, `ref` the reference. A size or format mismatch throws loom::Error (bad input).
// - Results are deterministic for any thread count: partial sums are kept in double and combined
//   in a fixed order: RelMSE, SMAPE, PSNR and the temporal error row by row (reduceRows, the order
//   of every device: loom/MetricKernels.h), the others in tile order (loom::parallelFor2D tiles
//   are fixed by the image size).
// - Non-finite values (NaN, +-Inf) never make a metric NaN or Inf. Every result carries
//   `nonFinite`, the number of pixels where the test or the reference image has a non-finite RGB
//   channel. Such a pixel is handled as follows (the rule is per metric and stated there):
//     * bounded metrics (SMAPE, PSNR, SSIM, FLIP) count it as maximal error: SMAPE term 1 per
//       channel; for the tone-mapped metrics the pixel's non-finite channels are replaced by the
//       value in [0, 1] farthest from the other image's tone-mapped value (1 when that is < 0.5,
//       else 0; a channel non-finite in both images becomes 0 in the reference and 1 in the test),
//       and FLIP's per-pixel error at that pixel is set to 1;
//     * unbounded metrics (RelMSE, temporal error, flicker) exclude the pixel from the mean (the
//       mean is over the remaining pixels; 0 when none remain) and report it in `nonFinite`.
//   A caller that must not accept any non-finite pixel checks `nonFinite == 0`.
// - An optional per-pixel error image (ImageView<float>, same size as the inputs) receives the
//   metric's per-pixel value: the mean over R, G, B of the per-channel term (RelMSE, SMAPE,
//   squared LDR error for PSNR, SSIM map) or the per-pixel FLIP error. Non-finite pixels get the
//   rule above (0 for the excluded metrics).
#include <cstdint>
#include <glm/vec4.hpp>
#include <vector>

#include "loom/Texture.h"

namespace loom {

/// The view type every metric reads.
using MetricImage = ImageView<const glm::vec4>;

/// A metric's value and the number of pixels with non-finite values (see the rules above).
struct MetricValue {
    double value = 0.0;
    uint64_t nonFinite = 0;
};

/// Epsilon of RelMSE, in the units of the linear HDR values.
inline constexpr double kRelMseEpsilon = 1e-2;
/// Epsilon of SMAPE, in the units of the linear HDR values.
inline constexpr double kSmapeEpsilon = 1e-2;
/// PSNR value (dB) returned when the MSE is 0 (identical tone-mapped images), and the cap of any
/// PSNR: min(10 log10(1 / MSE), kPsnrCap).
inline constexpr double kPsnrCap = 100.0;

// ---------------------------------------------------------------------------------------------
// HDR metrics (linear values, no tone map)

/// RelMSE: mean over pixels and channels of (x - y)^2 / (y^2 + eps), eps = kRelMseEpsilon,
/// x = test, y = ref. Non-finite pixels are excluded and counted.
MetricValue relMSE(MetricImage test, MetricImage ref, ImageView<float>* errorImage = nullptr);
MetricValue relMSE(const Texture& test, const Texture& ref, Texture* errorImage = nullptr);

/// Fraction of the largest per-pixel RelMSE terms trimmedRelMSE drops by default: 0.1 %.
inline constexpr double kTrimmedRelMseDrop = 1e-3;

/// Trimmed RelMSE, robust to fireflies: the per-pixel RelMSE term (the sum over R, G, B of
/// (x - y)^2 / (y^2 + eps)) of every finite pixel is computed, the floor(N * dropFraction) largest
/// of the N finite pixels are dropped, and the value is the mean over the rest and the channels.
/// It is RelMSE's trimmed mean (a classical robust estimator of location): a few pixels of huge
/// error (a firefly in the test image, or one in the reference) cannot dominate it, yet the kept
/// pixels count exactly as in RelMSE, so a firefly-free image (every term alike, or fewer than
/// 1 / dropFraction pixels) gives RelMSE's value. When at least one pixel is dropped, raising one
/// pixel's term to any value (a firefly) raises the result by at most the smallest dropped term /
/// (3 (N - dropped)), where RelMSE grows without bound. Ties at the threshold are kept by count, so the
/// value is independent of the order of equal terms (and of the thread count). Non-finite pixels
/// are excluded and counted, as in RelMSE. dropFraction in [0, 1), else loom::Error (bad input).
MetricValue trimmedRelMSE(MetricImage test, MetricImage ref, double dropFraction = kTrimmedRelMseDrop);
MetricValue trimmedRelMSE(const Texture& test, const Texture& ref, double dropFraction = kTrimmedRelMseDrop);

/// SMAPE: mean over pixels and channels of |x - y| / (|x| + |y| + eps), eps = kSmapeEpsilon, no
/// factor 2: the value lies in [0, 1). Non-finite channels count as 1.
MetricValue smape(MetricImage test, MetricImage ref, ImageView<float>* errorImage = nullptr);
MetricValue smape(const Texture& test, const Texture& ref, Texture* errorImage = nullptr);

// ---------------------------------------------------------------------------------------------
// LDR metrics (PSNR, SSIM, FLIP) on the one documented tone map

/// The tone map of the LDR metrics: clamp(x, 0, 1), then the sRGB OETF (IEC 61966-2-1:
/// 12.92 x for x <= 0.0031308, else 1.055 x^(1/2.4) - 0.055). The result lies in [0, 1] (white is
/// exactly 1) and the data range is L = 1. The OETF comes from a table indexed by the float's
/// exponent and top 8 mantissa bits, linearly interpolated: maximum absolute error below 1e-6
/// against the formula (tested). Non-finite input returns 0 (the metrics apply the rule above first).
float ldrToneMap(float linear);

/// PSNR in dB: 10 log10(1 / MSE), MSE over pixels and the R, G, B channels of the tone-mapped
/// values (L = 1), capped at kPsnrCap (identical images give kPsnrCap).
MetricValue psnr(MetricImage test, MetricImage ref, ImageView<float>* errorImage = nullptr);
MetricValue psnr(const Texture& test, const Texture& ref, Texture* errorImage = nullptr);

/// SSIM (Wang et al. 2004) on the tone-mapped values, computed per channel and averaged over
/// R, G, B: local statistics with an 11x11 Gaussian window, sigma 1.5 (weights normalised to sum
/// 1), C1 = (0.01 L)^2, C2 = (0.03 L)^2 with L = 1, variances as E[x^2] - E[x]^2. The SSIM map is
/// evaluated at every pixel; window taps outside the image are mirrored without repeating the
/// edge pixel (gfedcb|abcdefgh|gfedcba). The value is the mean of the map over all pixels and
/// channels. This is the convention of OpenCV's cv::quality::QualitySSIM (there with L = 255), which
/// the tests compare against (within 1e-4). Symmetric in its arguments.
MetricValue ssim(MetricImage test, MetricImage ref, ImageView<float>* ssimImage = nullptr);
MetricValue ssim(const Texture& test, const Texture& ref, Texture* ssimImage = nullptr);

/// Viewing conditions of FLIP. Defaults: a 0.7 m wide 3840-pixel monitor seen from 0.7 m, which
/// gives about 67 pixels per degree.
struct FlipViewing {
    double distanceMeters = 0.7;
    double monitorWidthMeters = 0.7;
    double monitorWidthPixels = 3840.0;
    /// Pixels per degree of visual angle: distance * (widthPixels / widthMeters) * pi / 180.
    double pixelsPerDegree() const;
};

/// LDR FLIP (Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating Images") on the
/// tone-mapped images (FLIP's sRGB input, so its linear RGB is clamp(x, 0, 1)). The value is the
/// mean of the per-pixel FLIP error, which lies in [0, 1]; identical images give exactly 0. See
/// docs/METRICS.md for the pipeline and constants (CSF filters in YyCxCz, Hunt-adjusted L*a*b*,
/// HyAB with qc = 0.7, pc = 0.4, pt = 0.95, edge and point features with w = 0.082 degrees and
/// qf = 0.5). Symmetric in exact arithmetic (both terms are), so flip(a, b) and flip(b, a) agree to
/// float rounding, except where the non-finite rule applies.
MetricValue flip(MetricImage test, MetricImage ref, ImageView<float>* errorImage = nullptr,
                 const FlipViewing& viewing = {});
MetricValue flip(const Texture& test, const Texture& ref, Texture* errorImage = nullptr,
                 const FlipViewing& viewing = {});

// ---------------------------------------------------------------------------------------------
// Temporal metrics (linear values)

/// Temporal-derivative error: mean over pixels and channels of |(x_t - x_{t-1}) - (y_t - y_{t-1})|
/// with x the test sequence and y the reference sequence. Pixels with a non-finite channel in any
/// of the four images are excluded and counted.
MetricValue temporalError(MetricImage test, MetricImage testPrev, MetricImage ref, MetricImage refPrev);
MetricValue temporalError(const Texture& test, const Texture& testPrev, const Texture& ref, const Texture& refPrev);

/// Static-camera flicker: takes frames one by one and reports the mean over pixels of the
/// temporal standard deviation (population form, divide by n) of the Rec. 709 luminance Y
/// (linear, no tone map; in double, kRec709R/G/B of KernelMath.h). A pixel's non-finite samples are
/// skipped; `nonFinite` counts the pixels that had at least one. Pixels with fewer than two finite
/// samples are left out of the mean. Running sums are kept per pixel in double (Welford), so the
/// result is independent of the thread count.
class FlickerAccumulator {
public:
    /// Adds a frame; every frame must have the size of the first (else loom::Error).
    void add(MetricImage frame);
    void add(const Texture& frame);
    /// Mean temporal standard deviation of luminance; 0 before two frames.
    MetricValue value() const;
    uint32_t frames() const { return mFrames; }
    void reset();

private:
    uint32_t mWidth = 0, mHeight = 0, mFrames = 0;
    std::vector<double> mMean, mM2;
    std::vector<uint32_t> mCount;
    std::vector<uint8_t> mHadNonFinite;
};

}  // namespace loom
