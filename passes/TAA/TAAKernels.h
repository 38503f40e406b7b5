#pragma once
// Per-pixel temporal anti-aliasing for TAAPass: plain functions over plain
// structs, so the same code compiles for CUDA (see loom/Kernel.h). This is the
// reference; TAAPass.cpp runs a tiled CPU version of the same steps and a test
// checks that the two agree.
//
// One pixel:
//   1. Neighbourhood: the 3x3 current colours (edge pixels repeated at the
//      frame border) in YCoCg + alpha; mean mu and standard deviation s of the
//      finite ones, and their min / max. The box is
//        lo = clamp(mu - sigma s, min, max), hi = clamp(mu + sigma s, min, max)
//      (variance clipping, M. Salvi, "An Excursion in Temporal Supersampling",
//      GDC 2016, intersected with the min / max box of B. Karis, "High Quality
//      Temporal Supersampling", SIGGRAPH 2014 Advances course).
//   2. Motion dilation: the longest finite motion vector of the 3x3 (first in
//      row-major order on ties), so edges of moving objects reproject with the
//      object rather than with the background (Karis 2014).
//   3. History: Catmull-Rom (bicubic, B = 0, C = 1/2) sampling of last frame's
//      output at uvPrev = uvCur + mvec, 4x4 texels, edge texels repeated. The
//      current colour is used instead when history is invalid or uvPrev lies
//      outside [0, 1]^2. The taps are weighted as differences from the
//      nearest-lower texel, so constant history gives exactly that constant.
//   4. Clipping: the history in YCoCg + alpha is moved towards the box centre
//      along the line to it until it lies in the box (Salvi 2016; clipping
//      rather than per-channel clamping keeps the hue). History inside the box
//      is kept untouched. Each channel's half extent counts as at least 1e-4
//      of the box's luma scale (kMinRelativeExtent), so a channel flat but for
//      rounding does not decide the clip.
//   5. Blend: out = c + (1 - alpha) (h - c), an exponential moving average in
//      linear colour. Its expectation is the mean of the inputs it has seen,
//      so a static jittered image converges to the box-filtered mean of the
//      jitter positions (the supersampled image) and keeps its energy: TAA may
//      only move light as the reference's own pixel filter does. Written as
//      c + k (h - c) so that h == c gives exactly c.
//      Optional anti-flicker (antiFlicker, Karis 2014 after T. Lottes):
//        wc = alpha / (1 + Yc),  wh = (1 - alpha) / (1 + Yh),
//      Yc and Yh the (non-negative) YCoCg luma of current and clipped history,
//      k = wh / (wc + wh), computed as (1 - alpha)(1 + Yc) / (alpha (1 + Yh) +
//      (1 - alpha)(1 + Yc)). It stops a bright sample (a firefly) from
//      dominating the average, but a weighted mean whose weights fall with the
//      sample's own value is biased towards the dark samples: a pixel on a
//      light's edge that sees the light in some jitter positions converges far
//      below its mean (samples 100 and 0.1 in turn: 1.2 instead of 50). No
//      luminance weighting of the samples can avoid that (weights correlated
//      with the values always bias a weighted mean), so it is off by default;
//      tests/integration/test_taa.cpp measures what it costs.
// Non-finite current pixels are replaced by the mean of the finite
// neighbours (0 when there are none) and are left out of the statistics; a
// non-finite result (overflow of huge inputs) falls back to the current
// colour, so history stays finite.
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/Kernel.h"
#include "loom/KernelMath.h"

namespace loom::taa {

/// The resolve's parameters. TAAPass binds its alpha, sigma and antiFlicker to this struct, so these are the pass's
/// defaults too.
struct TaaParams {
    float alpha = 0.1f;  ///< weight of the current frame
    float sigma = 1.f;   ///< box half-size in standard deviations
    bool antiFlicker = false;  ///< luminance-weighted blend (biased: see step 5)
};

/// A read-only image of T with row pitch in bytes; reads clamp to the edges.
template <class T>
struct ClampedImage {
    const T* data = nullptr;
    uint32_t width = 0, height = 0;
    size_t rowPitch = 0;

    LOOM_HD const T& at(int x, int y) const {
        x = x < 0 ? 0 : (x >= int(width) ? int(width) - 1 : x);
        y = y < 0 ? 0 : (y >= int(height) ? int(height) - 1 : y);
        return reinterpret_cast<const T*>(reinterpret_cast<const unsigned char*>(data) + rowPitch * size_t(y))[x];
    }
};

struct TaaInputs {
    ClampedImage<glm::vec4> color;    ///< this frame (linear)
    ClampedImage<glm::vec2> mvec;     ///< uvPrev - uvCur
    ClampedImage<glm::vec4> history;  ///< last frame's output (compressed when `compress`)
    bool historyValid = false;
    bool compress = false;  ///< resolve in compressColor() space: every current colour is compressed as it is read
};

/// RGB + alpha to YCoCg + alpha (Malvar & Sullivan 2003): Y = R/4 + G/2 + B/4,
/// Co = (R - B)/2, Cg = -R/4 + G/2 - B/4.
LOOM_HD inline glm::vec4 toYCoCg(const glm::vec4& c) {
    return glm::vec4(0.25f * (c.x + c.z) + 0.5f * c.y, 0.5f * (c.x - c.z), 0.5f * c.y - 0.25f * (c.x + c.z), c.w);
}
LOOM_HD inline glm::vec4 fromYCoCg(const glm::vec4& v) {
    return glm::vec4(v.x + v.y - v.z, v.x + v.z, v.x - v.y - v.z, v.w);
}

/// The HDR compression TAAPass can resolve in (hdrCompress, off by default): c / (1 + Y), Y = max(0, YCoCg luma of
/// c), alpha kept (Karis 2014, "High Quality Temporal Supersampling": the reversible tone map). Every colour with
/// Y >= 0 lands at a luma below 1, so a light next to a dark surface differs from it by a bounded amount and the
/// bicubic history and the blend cannot carry a large fraction of the light into the dark side. expandColor() is its
/// inverse, exact up to rounding: Y(c') = Y / (1 + Y), hence c = c' / (1 - Y(c')). The pair is exact for one colour,
/// but an average taken between them is not the average of the colours (the map is concave): averaging in the
/// compressed space weights each colour by about 1 / (1 + Y), the same bias as antiFlicker, and it acts on every
/// blend, every bicubic resample and every clip, so a light's edges lose energy (see the blend, step 5).
LOOM_HD inline float nonNegativeLuma(const glm::vec4& c) {
    return glm::max(0.25f * (c.x + c.z) + 0.5f * c.y, 0.f);  // toYCoCg(c).x, clamped
}
LOOM_HD inline glm::vec4 compressColor(const glm::vec4& c) {
    const float k = 1.f / (1.f + nonNegativeLuma(c));
    return glm::vec4(c.x * k, c.y * k, c.z * k, c.w);
}
/// Inverse of compressColor(); a luma at or above 1 (only from rounding or non-HDR input) is held just below 1.
LOOM_HD inline glm::vec4 expandColor(const glm::vec4& c) {
    const float k = 1.f / glm::max(1.f - nonNegativeLuma(c), 1e-7f);
    return glm::vec4(c.x * k, c.y * k, c.z * k, c.w);
}

/// The current colour at (x, y) as the resolve sees it: compressed when in.compress. Compression keeps finiteness:
/// a finite colour compresses to a finite one, a non-finite one to a non-finite one.
LOOM_HD inline glm::vec4 currentColor(const TaaInputs& in, int x, int y) {
    const glm::vec4 c = in.color.at(x, y);
    return in.compress ? compressColor(c) : c;
}

/// Start value of a running minimum (and, negated, maximum).
inline constexpr float kHuge = 3.0e38f;

/// The clipping box of a neighbourhood in YCoCg + alpha.
struct ClipBox {
    glm::vec4 lo{0.f}, hi{0.f};
    glm::vec4 mean{0.f};
    uint32_t finiteCount = 0;
    /// One value in the neighbourhood (minimum = maximum in every channel): clipping would pin any history to
    /// it, so the resolve is the current colour, history unread (a black sky, a constant image).
    bool flat = false;
};

/// Box from the running sums of n finite samples (mean and variance as the
/// moments, the variance clamped at 0 against rounding).
LOOM_HD inline ClipBox makeClipBox(const glm::vec4& sum, const glm::vec4& sumSq, const glm::vec4& mn,
                                   const glm::vec4& mx, uint32_t n, float sigma) {
    ClipBox b;
    b.finiteCount = n;
    if (n == 0) return b;
    const float inv = 1.f / float(n);
    b.mean = sum * inv;
    const glm::vec4 var = glm::max(sumSq * inv - b.mean * b.mean, glm::vec4(0.f));
    const glm::vec4 dev = sigma * glm::sqrt(var);
    b.lo = glm::clamp(b.mean - dev, mn, mx);
    b.hi = glm::clamp(b.mean + dev, mn, mx);
    b.flat = mn == mx;
    return b;
}

/// The 3x3 statistics of the current colour around (x, y). Each row's sums
/// are formed first, then the rows are added, each sum starting from 0: the
/// order the tiled CPU path uses too, so both give the same bits.
LOOM_HD inline ClipBox neighbourhoodBox(const TaaInputs& in, int x, int y, float sigma) {
    glm::vec4 sum(0.f), sumSq(0.f), mn(kHuge), mx(-kHuge);
    uint32_t n = 0;
    for (int dy = -1; dy <= 1; ++dy) {
        glm::vec4 rowSum(0.f), rowSumSq(0.f), rowMin(kHuge), rowMax(-kHuge);
        for (int dx = -1; dx <= 1; ++dx) {
            const glm::vec4 c = currentColor(in, x + dx, y + dy);
            if (!isFinite(c)) continue;
            const glm::vec4 v = toYCoCg(c);
            rowSum += v;
            rowSumSq += v * v;
            rowMin = glm::min(rowMin, v);
            rowMax = glm::max(rowMax, v);
            ++n;
        }
        sum += rowSum;
        sumSq += rowSumSq;
        mn = glm::min(mn, rowMin);
        mx = glm::max(mx, rowMax);
    }
    return makeClipBox(sum, sumSq, mn, mx, n, sigma);
}

/// Longest finite motion vector of the 3x3 around (x, y); false when none is finite.
LOOM_HD inline bool dilatedMotion(const ClampedImage<glm::vec2>& mvec, int x, int y, glm::vec2& out) {
    float best = -1.f;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            const glm::vec2 m = mvec.at(x + dx, y + dy);
            if (!isFinite(m)) continue;
            const float l = m.x * m.x + m.y * m.y;
            if (l > best) {
                best = l;
                out = m;
            }
        }
    return best >= 0.f;
}

/// Catmull-Rom weights of the four taps at -1, 0, 1, 2 for a fraction t in [0, 1).
LOOM_HD inline glm::vec4 catmullRomWeights(float t) {
    const float t2 = t * t, t3 = t2 * t;
    return glm::vec4(0.5f * (-t3 + 2.f * t2 - t), 0.5f * (3.f * t3 - 5.f * t2) + 1.f, 0.5f * (-3.f * t3 + 4.f * t2 + t),
                     0.5f * (t3 - t2));
}

/// Where a pixel's centre was last frame, in pixels (texel centres at integers),
/// from its motion vector; false when that lies outside the frame.
LOOM_HD inline bool previousPosition(uint32_t x, uint32_t y, uint32_t width, uint32_t height, const glm::vec2& mv,
                                     glm::vec2& pos) {
    // uvPrev = (x + 0.5) / W + mv.x; in texel-centre coordinates that is x + mv.x W.
    pos = glm::vec2(float(x) + mv.x * float(width), float(y) + mv.y * float(height));
    return pos.x >= -0.5f && pos.x <= float(width) - 0.5f && pos.y >= -0.5f && pos.y <= float(height) - 0.5f;
}

/// Bicubic (Catmull-Rom) history at a texel-centre position, edge texels
/// repeated. Integer positions read one texel. The taps are summed as
/// differences from the texel at (floor x, floor y), which is added last:
/// the weights sum to one, so this is the same filter, but a region where a
/// channel is constant (typically alpha) gives exactly that constant, not a
/// value a rounding error away from it, which a box that is flat in that
/// channel would reject outright (see clipToBox). The 4x4 sum is formed as
/// (even taps) + (odd taps) of each row, weighted by row.
LOOM_HD inline glm::vec4 sampleHistory(const ClampedImage<glm::vec4>& history, const glm::vec2& pos) {
    const float fx0 = glm::floor(pos.x), fy0 = glm::floor(pos.y);
    const int ix = int(fx0), iy = int(fy0);
    const float fx = pos.x - fx0, fy = pos.y - fy0;
    const glm::vec4 ref = history.at(ix, iy);
    if (fx == 0.f && fy == 0.f) return ref;
    const glm::vec4 wx = catmullRomWeights(fx), wy = catmullRomWeights(fy);
    glm::vec4 even(0.f), odd(0.f);
    for (int j = 0; j < 4; ++j) {
        const int ty = iy - 1 + j;
        even += wy[j] * (wx[0] * (history.at(ix - 1, ty) - ref) + wx[2] * (history.at(ix + 1, ty) - ref));
        odd += wy[j] * (wx[1] * (history.at(ix, ty) - ref) + wx[3] * (history.at(ix + 2, ty) - ref));
    }
    return ref + (even + odd);
}

/// The smallest half extent a channel of the clip box counts as, relative to the box's luma scale |centre| +
/// half extent. A channel whose values differ only by rounding (the chroma of colours of one hue: Cg of (v, 0.8 v,
/// 0.6 v) is 0 up to a few ulp) has an extent of a few ulp; history a few ulp off in that channel would give a huge
/// ratio and pull the whole colour onto the box centre, however well it matches in luma: a bias of several percent
/// on a jittered light's edges. 1e-4 is some 1000 rounding errors and far below anything visible.
inline constexpr float kMinRelativeExtent = 1e-4f;

/// The half extent of each channel of a box with centre `center` and half extent `extent`, floored at
/// kMinRelativeExtent of its luma scale (0 for a black box, whose flat channels stay flat).
LOOM_HD inline glm::vec4 flooredExtent(const glm::vec4& center, const glm::vec4& extent) {
    const float minExtent = kMinRelativeExtent * (glm::abs(center.x) + extent.x);
    return glm::max(extent, glm::vec4(minExtent));
}

/// The history point moved along the line to the box centre into the box
/// (unchanged when already inside).
LOOM_HD inline bool clipToBox(const ClipBox& b, glm::vec4& v) {
    const glm::vec4 center = 0.5f * (b.lo + b.hi);
    const glm::vec4 extent = flooredExtent(center, 0.5f * (b.hi - b.lo));
    const glm::vec4 d = v - center;
    float unit = 0.f;
    for (int c = 0; c < 4; ++c) {
        const float a = glm::abs(d[c]);
        // Only channels outside the box count (then a > 0). A flat channel of a black box (extent 0) gives an
        // infinite unit, which pulls the point exactly onto the centre (d / inf = 0).
        if (a > extent[c]) unit = glm::max(unit, a / extent[c]);
    }
    if (unit <= 0.f) return false;
    const float inv = 1.f / unit;  // one division for the four channels
    v = center + d * inv;
    return true;
}

/// The final blend (step 5 above).
LOOM_HD inline glm::vec4 blend(const TaaParams& p, const glm::vec4& current, float currentLuma,
                               const glm::vec4& history, float historyLuma) {
    // wh / (wc + wh) with both weights multiplied by (1 + Yc)(1 + Yh): one division.
    float wc = p.alpha, wh = 1.f - p.alpha;
    if (p.antiFlicker) {
        wc *= 1.f + glm::max(historyLuma, 0.f);
        wh *= 1.f + glm::max(currentLuma, 0.f);
    }
    const float sum = wc + wh;
    const float k = sum > 0.f ? wh / sum : 0.f;
    return current + k * (history - current);
}

/// What one pixel reports besides its colour.
enum PixelFlags : uint32_t {
    kNonFiniteInput = 1u,  ///< the current colour was not finite and was replaced
    kNoHistory = 2u,       ///< history unusable (invalid, off-frame or no finite motion): output = current
    kClipped = 4u,         ///< the history was outside the box and was clipped
};

/// The current colour with a non-finite pixel replaced by the neighbourhood mean.
LOOM_HD inline glm::vec4 saneCurrent(const glm::vec4& c, const ClipBox& box, uint32_t& flags) {
    if (isFinite(c)) return c;
    flags |= kNonFiniteInput;
    const glm::vec4 mean = box.finiteCount > 0 ? fromYCoCg(box.mean) : glm::vec4(0.f);
    return isFinite(mean) ? mean : glm::vec4(0.f);  // the mean of huge neighbours can overflow
}

/// Steps 3 to 5 for a pixel whose box and dilated motion are known.
LOOM_HD inline glm::vec4 resolveWithBox(const TaaInputs& in, const TaaParams& p, uint32_t x, uint32_t y,
                                        const glm::vec4& current, const ClipBox& box, bool motionFinite,
                                        const glm::vec2& motion, uint32_t& flags) {
    glm::vec2 pos;
    if (!in.historyValid || !motionFinite || !previousPosition(x, y, in.color.width, in.color.height, motion, pos)) {
        flags |= kNoHistory;
        return current;
    }
    if (box.flat) return current;  // the clip would pin the history to the one value (ClipBox::flat)
    glm::vec4 history = sampleHistory(in.history, pos);
    glm::vec4 historyYCoCg = toYCoCg(history);
    if (clipToBox(box, historyYCoCg)) {
        history = fromYCoCg(historyYCoCg);
        flags |= kClipped;
    }
    const glm::vec4 out = blend(p, current, toYCoCg(current).x, history, historyYCoCg.x);
    return isFinite(out) ? out : current;
}

/// The whole reference kernel for pixel (x, y).
LOOM_HD inline glm::vec4 resolvePixel(const TaaInputs& in, const TaaParams& p, uint32_t x, uint32_t y,
                                      uint32_t& flags) {
    flags = 0;
    const ClipBox box = neighbourhoodBox(in, int(x), int(y), p.sigma);
    const glm::vec4 current = saneCurrent(currentColor(in, int(x), int(y)), box, flags);
    glm::vec2 motion(0.f);
    const bool motionFinite = dilatedMotion(in.mvec, int(x), int(y), motion);
    return resolveWithBox(in, p, x, y, current, box, motionFinite, motion, flags);
}

/// The pass's output for a resolved value (compressed when in.compress) and the pixel's linear input: without
/// compression the value itself; with it, the linear input exactly where the resolve returned the compressed input
/// (no history, or history equal to it, as for a constant image), else the expanded value (0 if that overflows).
LOOM_HD inline glm::vec4 outputColor(bool compress, const glm::vec4& resolved, const glm::vec4& linearInput) {
    if (!compress) return resolved;
    if (resolved == compressColor(linearInput)) return linearInput;
    const glm::vec4 e = expandColor(resolved);
    return isFinite(e) ? e : glm::vec4(0.f);
}

}  // namespace loom::taa
