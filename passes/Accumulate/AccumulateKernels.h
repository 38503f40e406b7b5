#pragma once
// Per-pixel running-mean arithmetic for AccumulatePass: plain functions over a
// plain per-pixel state, so the same code compiles for CUDA (see loom/Kernel.h).
//
// Three ways to keep the running sum, chosen by the pass's `precision`:
// - Float:  one float sum. Once the sum is large, each new sample loses the
//           bits below the sum's ulp (after 2^24 samples of 1.0, adding 1.0
//           does nothing at all).
// - Kahan:  a float sum plus a float compensation term that collects the
//           rounding error of every addition (Neumaier's variant of Kahan
//           summation, which stays correct when a sample is larger than the
//           sum: A. Neumaier, ZAMM 54, 1974). Error bounded independently of
//           the frame count, to first order.
// - Double: a double sum. Every float sample is added exactly until the sum
//           needs more than 53 bits, so for references of any practical length
//           the only rounding is the final division.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <glm/glm.hpp>

#include "loom/DoubleTexels.h"
#include "loom/Kernel.h"
#include "loom/KernelMath.h"
#include "loom/Texture.h"

namespace loom::accumulate {

enum class Precision : uint32_t { Float, Kahan, Double };

/// The running state of one pixel. Which members carry the state depends on
/// the precision: Float uses `sum`, Kahan `sum` and `compensation`, Double
/// `sumDouble`; all use `count`.
struct PixelState {
    glm::vec4 sum{0.f};
    glm::vec4 compensation{0.f};
    glm::dvec4 sumDouble{0.0};
    uint32_t count = 0;  ///< finite samples in the sum
};

/// sum + compensation accumulates x with the rounding error of the float
/// addition carried in compensation (Neumaier). The error term is exact: for
/// |a| >= |b|, (a - (a + b)) + b is the rounding error of a + b in IEEE float.
LOOM_HD inline void neumaierAdd(float& sum, float& compensation, float x) {
    const float t = sum + x;
    if (std::fabs(sum) >= std::fabs(x))
        compensation += (sum - t) + x;
    else
        compensation += (x - t) + sum;
    sum = t;
}

/// Adds one sample to the state. A sample with any non-finite channel is
/// skipped as a whole (channels stay consistent, and one NaN cannot poison the
/// mean forever); returns false then. So is a finite sample that would take
/// a float running sum past the largest float (samples near 3e38): the sum
/// would become Inf, and Kahan's compensation -Inf, their mean NaN.
LOOM_HD inline bool addSample(Precision precision, PixelState& s, const glm::vec4& x) {
    if (!isFinite(x)) return false;
    switch (precision) {
        case Precision::Float:
            if (!isFinite(s.sum + x)) return false;
            s.sum += x;
            break;
        case Precision::Kahan:
            if (!isFinite(s.sum + x)) return false;
            for (int c = 0; c < 4; ++c) neumaierAdd(s.sum[c], s.compensation[c], x[c]);
            break;
        case Precision::Double:
            s.sumDouble += glm::dvec4(x);
            break;
    }
    ++s.count;
    return true;
}

/// The mean of the samples in the state; zero while there are none (a pixel
/// whose every sample so far was non-finite), so the output stays finite.
LOOM_HD inline glm::vec4 mean(Precision precision, const PixelState& s) {
    if (s.count == 0) return glm::vec4(0.f);
    switch (precision) {
        case Precision::Float:
            return s.sum / float(s.count);
        case Precision::Kahan:
            // The compensated sum is sum + compensation; forming it in double keeps
            // the correction from being rounded away before the division.
            return glm::vec4((glm::dvec4(s.sum) + glm::dvec4(s.compensation)) / double(s.count));
        case Precision::Double:
        default:
            return glm::vec4(s.sumDouble / double(s.count));
    }
}

/// The output when a denoised image is blended in (the pass's `denoised` input, e.g. SVGF's output for the same
/// frames). The denoised image D counts as K = `denoisedFrames` frames and the running mean M of n = `count`
/// samples as n - 1 (its first sample is in D already, through the denoiser's own input):
///     out = (K D + (n - 1) M) / (K + n - 1).
/// - n <= 1 (a frame after a restart): D itself, bit for bit, so while anything moves the output is the
///   denoiser's. D is passed on as it is, the denoiser's own output, finite or not.
/// - If D and M are unbiased with errors e_D and s2 / n (s2: one sample's variance), the blend's mean squared
///   error is least for K = s2 / e_D, the samples the denoiser's image is worth; the weight of the mean grows like
///   n / (n + K), so the error falls like 1 / n once n >> K, to the image the samples converge to.
/// - A non-finite D (past the first sample) leaves the mean alone: one bad denoised pixel must not stop the
///   convergence.
LOOM_HD inline glm::vec4 blendDenoised(const glm::vec4& denoised, const glm::vec4& mean, uint32_t count,
                                       float denoisedFrames) {
    if (count <= 1) return denoised;
    if (!isFinite(denoised)) return mean;
    const float meanFrames = float(count - 1);
    const float w = meanFrames / (meanFrames + denoisedFrames);
    return denoised + w * (mean - denoised);
}

/// The running sum as a float, whatever the precision: what the `sum` field
/// shows when the state itself is kept elsewhere (Double).
LOOM_HD inline glm::vec4 sumAsFloat(Precision precision, const PixelState& s) {
    switch (precision) {
        case Precision::Kahan:
            return glm::vec4(glm::dvec4(s.sum) + glm::dvec4(s.compensation));
        case Precision::Double: {
            // A double sum of floats can exceed the largest float: shown clamped to it, not as Inf.
            const double m = 3.4028234663852886e38;
            return glm::vec4(glm::clamp(s.sumDouble, glm::dvec4(-m), glm::dvec4(m)));
        }
        case Precision::Float:
        default:
            return s.sum;
    }
}

// The double sum lives in RGBA32U texels, laid out as loom/DoubleTexels.h says: the first holds R in xy and G in zw,
// the second B and A.
using loom::packDoublePair;
using loom::packDoubleSum;
using loom::unpackDoublePair;
using loom::unpackDoubleSum;

LOOM_HD inline glm::uvec4 floatBits(const glm::vec4& v) {
    glm::uvec4 u;
    for (int c = 0; c < 4; ++c) std::memcpy(&u[c], &v[c], sizeof(float));
    return u;
}

LOOM_HD inline glm::vec4 bitsToFloat(const glm::uvec4& u) {
    glm::vec4 v;
    for (int c = 0; c < 4; ++c) std::memcpy(&v[c], &u[c], sizeof(float));
    return v;
}

/// Every precision keeps its running sum in the same two RGBA32U texels, so the storage does not depend on the
/// precision (reflection must not) and none of it is idle: Double the double sum (R, G | B, A as DoubleTexels.h
/// lays them out), Kahan the float sum's bits in the first and the compensation's in the second, Float the float
/// sum's bits in the first (the second is left as it is). The round trip is exact: a state stored and loaded is
/// the same bits.
template <Precision P>
LOOM_HD inline void packSum(const PixelState& s, glm::uvec4& first, glm::uvec4& second) {
    if constexpr (P == Precision::Double) {
        packDoubleSum(s.sumDouble, first, second);
    } else {
        first = floatBits(s.sum);
        if constexpr (P == Precision::Kahan) second = floatBits(s.compensation);
    }
}

template <Precision P>
LOOM_HD inline void unpackSum(const glm::uvec4& first, const glm::uvec4& second, PixelState& s) {
    if constexpr (P == Precision::Double) {
        s.sumDouble = unpackDoubleSum(first, second);
    } else {
        s.sum = bitsToFloat(first);
        if constexpr (P == Precision::Kahan) s.compensation = bitsToFloat(second);
    }
}

/// Every texture one frame touches, as typed views (the same on the host and on a device).
struct FrameViews {
    ImageView<const glm::vec4> src;
    ImageView<const glm::vec4> denoised;  ///< empty when not connected
    float denoisedFrames = 0.f;
    ImageView<glm::vec4> dst;
    ImageView<const glm::uvec4> prevSum, prevSumExtra;
    ImageView<glm::uvec4> curSum, curSumExtra;
    ImageView<const uint32_t> prevCount;
    ImageView<uint32_t> curCount;
};

// Loads and stores touch only the texels the precision keeps its state in: the
// pass is memory bound, and float precision should not pay for double's state.
template <Precision P>
LOOM_HD inline PixelState loadState(const FrameViews& v, uint32_t x, uint32_t y) {
    PixelState s;
    s.count = v.prevCount.at(x, y);
    const glm::uvec4 none(0u);
    unpackSum<P>(v.prevSum.at(x, y), P == Precision::Float ? none : v.prevSumExtra.at(x, y), s);
    return s;
}

template <Precision P>
LOOM_HD inline void storeState(const FrameViews& v, uint32_t x, uint32_t y, const PixelState& s) {
    v.curCount.at(x, y) = s.count;
    glm::uvec4 unused;
    packSum<P>(s, v.curSum.at(x, y), P == Precision::Float ? unused : v.curSumExtra.at(x, y));
}

/// One pixel of one frame: starts from zero when `reset`, adds this frame's sample when `addSamples`, writes the
/// state and the mean (blended with the denoised image when there is one). Returns false when the sample was
/// skipped as non-finite.
template <Precision P>
LOOM_HD inline bool accumulatePixel(const FrameViews& v, uint32_t x, uint32_t y, bool reset, bool addSamples) {
    PixelState s = reset ? PixelState{} : loadState<P>(v, x, y);
    const bool added = !addSamples || addSample(P, s, v.src.at(x, y));
    storeState<P>(v, x, y, s);
    const glm::vec4 m = mean(P, s);
    v.dst.at(x, y) = v.denoised.data ? blendDenoised(v.denoised.at(x, y), m, s.count, v.denoisedFrames) : m;
    return added;
}

/// The partial* outputs' texels (the running sum as doubles, packDoubleSum's layout) of a float or Kahan state
/// stored as packSum lays it out: the float sum widened, plus the compensation for Kahan.
LOOM_HD inline void widenedSum(Precision precision, const glm::uvec4& first, const glm::uvec4& second, glm::uvec4& rg,
                               glm::uvec4& ba) {
    glm::dvec4 d(bitsToFloat(first));
    if (precision == Precision::Kahan) d += glm::dvec4(bitsToFloat(second));
    packDoubleSum(d, rg, ba);
}

}  // namespace loom::accumulate
