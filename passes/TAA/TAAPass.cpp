#include "TAAPass.h"

#include <hwy/cache_control.h>
#include <hwy/highway.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <limits>
#include <memory>

#include "loom/Parallel.h"
#include "loom/Plugin.h"

namespace loom {

using taa::ClipBox;
using taa::TaaInputs;

namespace {

const char kColorIn[] = "colorIn";
const char kMvec[] = "mvec";
const char kColorOut[] = "colorOut";
const char kColorHistory[] = "colorHistory";

// Counters reported in the frame's stats.
const char kStatNonFinite[] = "nonFinite";
const char kStatNoHistory[] = "noHistory";
const char kStatClipped[] = "clipped";

// Tiles of 128 x 16 pixels: rows long enough (2 KiB of colour) for the hardware prefetchers to stream, few enough
// rows that the scratch below stays in L2. They are dispatched as the cells of a tile grid through parallelFor2D.
constexpr uint32_t kTileW = 128, kTileH = 16;

/// Pixel counts of one tile or frame.
struct Counts {
    uint64_t nonFinite = 0, noHistory = 0, clipped = 0;
    void add(uint32_t flags) {
        nonFinite += (flags & taa::kNonFiniteInput) != 0;
        noHistory += (flags & taa::kNoHistory) != 0;
        clipped += (flags & taa::kClipped) != 0;
    }
};

/// Scratch of the tiled path for one tile: the tile plus a one-pixel border of
/// the current colour in YCoCg + alpha (structure of arrays, so the loops over
/// a row vectorize), the horizontal 3-tap statistics, and the motion vectors.
/// Rows are padded to whole vectors: every pixel, those of a partial tile too,
/// takes the same vector arithmetic (so a pixel's result never depends on where
/// its tile ends).
struct TileScratch {
    static constexpr uint32_t kW = kTileW, kR = kTileH + 2, kRW = kTileW + 2 + 8;  // + 8: whole vectors at the end
    float v[4][kR][kRW];
    float rowSum[4][kR][kW], rowSumSq[4][kR][kW], rowMin[4][kR][kW], rowMax[4][kR][kW];
    float mvx[kR][kRW], mvy[kR][kRW], mvLen[kR][kRW];
    float rowMvx[kR][kW], rowMvy[kR][kW], rowMvLen[kR][kW];
    // One output row between the three phases of the resolve: where last frame's pixel was, which lanes resolve
    // against the history, the clipping box (centre, half extent and its inverse, YCoCg + alpha), the history.
    alignas(64) float px[kW], py[kW], resolveHistory[kW];
    alignas(64) float center[4][kW], extent[4][kW], invExtent[4][kW], history[4][kW];
    bool anyHistory[kW];  // per vector (indexed by its first pixel): a lane resolves against the history
};

TileScratch& scratch() {
    thread_local std::unique_ptr<TileScratch> s = std::make_unique<TileScratch>();
    return *s;
}

uint32_t clampIndex(int v, uint32_t size) {
    return uint32_t(std::clamp(v, 0, int(size) - 1));
}

/// The reference kernel over one tile.
void resolveTileReference(const TaaInputs& in, const taa::TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                          const ImageView<glm::vec4>& history, Counts& counts) {
    for (uint32_t y = t.y0; y < t.y1; ++y)
        for (uint32_t x = t.x0; x < t.x1; ++x) {
            uint32_t flags = 0;
            const glm::vec4 c = taa::resolvePixel(in, p, x, y, flags);
            out.at(x, y) = taa::outputColor(in.compress, c, in.color.at(int(x), int(y)));
            history.at(x, y) = c;
            counts.add(flags);
        }
}

namespace hn = hwy::HWY_NAMESPACE;
using FloatTag = hn::ScalableTag<float>;
using FloatVec = hn::Vec<FloatTag>;
using FloatMask = hn::Mask<FloatTag>;
using Float4Tag = hn::FixedTag<float, 4>;
using Float4 = hn::Vec<Float4Tag>;
constexpr uint32_t kLanes = 8;  // AVX2: 8 floats (static dispatch to the build's -march target)

/// YCoCg + alpha of structure-of-arrays RGBA (toYCoCg, lane-wise).
HWY_INLINE void toYCoCgVec(FloatTag d, FloatVec r, FloatVec g, FloatVec b, FloatVec& y, FloatVec& co, FloatVec& cg) {
    const FloatVec rb = hn::Add(r, b);
    y = hn::Add(hn::Mul(hn::Set(d, 0.25f), rb), hn::Mul(hn::Set(d, 0.5f), g));
    co = hn::Mul(hn::Set(d, 0.5f), hn::Sub(r, b));
    cg = hn::Sub(hn::Mul(hn::Set(d, 0.5f), g), hn::Mul(hn::Set(d, 0.25f), rb));
}

/// compressColor() lane-wise: c / (1 + max(0, Y)), alpha kept.
/// nonNegativeLuma() lane-wise.
HWY_INLINE FloatVec nonNegativeLumaVec(FloatTag d, FloatVec r, FloatVec g, FloatVec b) {
    return hn::Max(hn::MulAdd(hn::Set(d, 0.25f), hn::Add(r, b), hn::Mul(hn::Set(d, 0.5f), g)), hn::Zero(d));
}

HWY_INLINE void compressVec(FloatTag d, FloatVec& r, FloatVec& g, FloatVec& b) {
    const FloatVec one = hn::Set(d, 1.f);
    const FloatVec k = hn::Div(one, hn::Add(one, nonNegativeLumaVec(d, r, g, b)));
    r = hn::Mul(r, k);
    g = hn::Mul(g, k);
    b = hn::Mul(b, k);
}

/// expandColor() lane-wise: c / max(1 - max(0, Y), 1e-7), alpha kept.
HWY_INLINE void expandVec(FloatTag d, FloatVec& r, FloatVec& g, FloatVec& b) {
    const FloatVec one = hn::Set(d, 1.f);
    const FloatVec k = hn::Div(one, hn::Max(hn::Sub(one, nonNegativeLumaVec(d, r, g, b)), hn::Set(d, 1e-7f)));
    r = hn::Mul(r, k);
    g = hn::Mul(g, k);
    b = hn::Mul(b, k);
}

HWY_INLINE FloatMask finiteVec(FloatTag d, FloatVec v) {
    const hn::RebindToSigned<FloatTag> di;
    const auto exponent = hn::Set(di, 0x7F800000);
    return hn::RebindMask(d, hn::Ne(hn::And(hn::BitCast(di, v), exponent), exponent));
}

/// 1 / x for finite x > 0: the hardware estimate (relative error < 1.5 2^-12) refined by one Newton step
/// (relative error below 1e-6).
HWY_INLINE FloatVec reciprocal(FloatTag d, FloatVec x) {
    const FloatVec r = hn::ApproximateReciprocal(x);
    return hn::MulAdd(r, hn::NegMulAdd(x, r, hn::Set(d, 1.f)), r);
}

/// sqrt(x) for finite x >= 0: x rsqrt(x) with the estimate refined by one Newton step (relative error below
/// 1e-6); exactly 0 at 0.
HWY_INLINE FloatVec squareRoot(FloatTag d, FloatVec x) {
    const FloatVec r = hn::ApproximateReciprocalSqrt(x);
    const FloatVec s = hn::Mul(x, r);
    // r' = r (3/2 - x r^2 / 2), so sqrt = x r' = s (3/2 - s r / 2).
    const FloatVec root = hn::Mul(s, hn::MulAdd(hn::Set(d, -0.5f), hn::Mul(s, r), hn::Set(d, 1.5f)));
    return hn::IfThenElseZero(hn::Gt(x, hn::Zero(d)), root);
}

/// catmullRomWeights, lane-wise, in Horner form with FMA. At t = 0 the weights are exactly (0, 1, 0, 0), so an
/// integer position reads its texel exactly.
HWY_INLINE void catmullRomVec(FloatTag d, FloatVec t, FloatVec w[4]) {
    const auto horner = [&](float a, float b, float c, float e) {
        return hn::MulAdd(hn::MulAdd(hn::MulAdd(hn::Set(d, a), t, hn::Set(d, b)), t, hn::Set(d, c)), t, hn::Set(d, e));
    };
    w[0] = horner(-0.5f, 1.f, -0.5f, 0.f);
    w[1] = horner(1.5f, -2.5f, 0.f, 1.f);
    w[2] = horner(-1.5f, 2.f, 0.5f, 0.f);
    w[3] = horner(0.5f, -0.5f, 0.f, 0.f);
}

/// Catmull-Rom sum of a 4 x 4 block of RGBA32F texels (row j at block + j pitch) with the weights of lane i, as
/// differences from texel (1, 1), which is added last (as sampleHistory does: constant history stays exact):
/// vertical first on pairs of texels in 256-bit vectors (columns 0 | 1 and 2 | 3), then the horizontal weights,
/// with FMA. An integer position (weights 0, 1, 0, 0 both ways) gives its texel exactly.
HWY_INLINE Float4 bicubicBlock(const unsigned char* block, size_t pitch, const float* wx, const float (&wy)[4][kLanes],
                               uint32_t i) {
    const FloatTag d;
    const Float4Tag d4;
    const float* refPtr = reinterpret_cast<const float*>(block + pitch) + 4;
    const FloatVec ref = hn::LoadDup128(d, refPtr);
    const float* row = reinterpret_cast<const float*>(block);
    FloatVec c01 = hn::Mul(hn::Set(d, wy[0][i]), hn::Sub(hn::LoadU(d, row), ref));
    FloatVec c23 = hn::Mul(hn::Set(d, wy[0][i]), hn::Sub(hn::LoadU(d, row + 8), ref));
    for (int j = 1; j < 4; ++j) {
        row = reinterpret_cast<const float*>(block + pitch * size_t(j));
        const FloatVec w = hn::Set(d, wy[j][i]);
        c01 = hn::MulAdd(w, hn::Sub(hn::LoadU(d, row), ref), c01);
        c23 = hn::MulAdd(w, hn::Sub(hn::LoadU(d, row + 8), ref), c23);
    }
    // wx: this lane's four horizontal weights; (w0 x4 | w1 x4) and (w2 x4 | w3 x4) by one permutation each.
    alignas(32) static constexpr int32_t k01[kLanes] = {0, 0, 0, 0, 1, 1, 1, 1}, k23[kLanes] = {2, 2, 2, 2, 3, 3, 3, 3};
    const FloatVec weights = hn::LoadDup128(d, wx);
    const FloatVec w01 = hn::TableLookupLanes(weights, hn::SetTableIndices(d, k01));
    const FloatVec w23 = hn::TableLookupLanes(weights, hn::SetTableIndices(d, k23));
    const FloatVec sum = hn::MulAdd(w23, c23, hn::Mul(w01, c01));
    return hn::Add(hn::LoadU(d4, refPtr), hn::Add(hn::LowerHalf(d4, sum), hn::UpperHalf(d4, sum)));
}

/// Four vectors of 8 lanes to 8 records of 4 (record i at out + 8 (i % 4) + 4 (i / 4)).
HWY_INLINE void transposeWeights(const FloatVec (&w)[4], float* out) {
    const FloatTag d;
    const hn::Repartition<double, FloatTag> dd;
    const auto a = hn::BitCast(dd, hn::InterleaveLower(w[0], w[1])),
               b = hn::BitCast(dd, hn::InterleaveLower(w[2], w[3]));
    const auto c = hn::BitCast(dd, hn::InterleaveUpper(d, w[0], w[1]));
    const auto e = hn::BitCast(dd, hn::InterleaveUpper(d, w[2], w[3]));
    hn::Store(hn::BitCast(d, hn::InterleaveLower(a, b)), d, out);
    hn::Store(hn::BitCast(d, hn::InterleaveUpper(dd, a, b)), d, out + kLanes);
    hn::Store(hn::BitCast(d, hn::InterleaveLower(c, e)), d, out + 2 * kLanes);
    hn::Store(hn::BitCast(d, hn::InterleaveUpper(dd, c, e)), d, out + 3 * kLanes);
}

/// Where transposeWeights puts lane i's record.
constexpr uint32_t weightRecord(uint32_t i) {
    return kLanes * (i % 4) + 4 * (i / 4);
}

/// Eight RGBA texels (one 128-bit vector each) to structure of arrays.
HWY_INLINE void transpose8(const Float4 (&s)[kLanes], FloatVec& r, FloatVec& g, FloatVec& b, FloatVec& a) {
    const FloatTag d;
    const hn::Repartition<double, FloatTag> dd;
    const FloatVec q0 = hn::Combine(d, s[4], s[0]), q1 = hn::Combine(d, s[5], s[1]);
    const FloatVec q2 = hn::Combine(d, s[6], s[2]), q3 = hn::Combine(d, s[7], s[3]);
    // Per 128-bit half: t0 = (r0 r1 g0 g1), t1 = (b0 b1 a0 a1), t2 = (r2 r3 g2 g3), t3 = (b2 b3 a2 a3).
    const auto t0 = hn::BitCast(dd, hn::InterleaveLower(q0, q1)), t1 = hn::BitCast(dd, hn::InterleaveUpper(d, q0, q1));
    const auto t2 = hn::BitCast(dd, hn::InterleaveLower(q2, q3)), t3 = hn::BitCast(dd, hn::InterleaveUpper(d, q2, q3));
    r = hn::BitCast(d, hn::InterleaveLower(t0, t2));
    g = hn::BitCast(d, hn::InterleaveUpper(dd, t0, t2));
    b = hn::BitCast(d, hn::InterleaveLower(t1, t3));
    a = hn::BitCast(d, hn::InterleaveUpper(dd, t1, t3));
}

/// 8 pixels from structure of arrays to interleaved RGBA: v[k] holds pixels 2k and 2k + 1.
HWY_INLINE void interleavePixels(FloatVec r, FloatVec g, FloatVec b, FloatVec a, FloatVec (&v)[4]) {
    const FloatTag d;
    const hn::Repartition<double, FloatTag> dd;
    // The inverse of transpose8: (r g b a) per pixel, pixels (0 1), (2 3), (4 5), (6 7) per vector.
    const auto t0 = hn::BitCast(dd, hn::InterleaveLower(r, g)), t1 = hn::BitCast(dd, hn::InterleaveLower(b, a));
    const auto t2 = hn::BitCast(dd, hn::InterleaveUpper(d, r, g)), t3 = hn::BitCast(dd, hn::InterleaveUpper(d, b, a));
    const FloatVec u0 = hn::BitCast(d, hn::InterleaveLower(t0, t1)),
                   u1 = hn::BitCast(d, hn::InterleaveUpper(dd, t0, t1));
    const FloatVec u2 = hn::BitCast(d, hn::InterleaveLower(t2, t3)),
                   u3 = hn::BitCast(d, hn::InterleaveUpper(dd, t2, t3));
    v[0] = hn::ConcatLowerLower(d, u1, u0);
    v[1] = hn::ConcatLowerLower(d, u3, u2);
    v[2] = hn::ConcatUpperUpper(d, u1, u0);
    v[3] = hn::ConcatUpperUpper(d, u3, u2);
}

/// Writes the first n of 8 interleaved pixels v (interleavePixels) to p; streaming when all 8 go to an aligned place.
HWY_INLINE void storeInterleaved(const FloatVec (&v)[4], glm::vec4* p, uint32_t n, bool stream) {
    const FloatTag d;
    float* o = reinterpret_cast<float*>(p);
    if (n == kLanes) {
        if (stream && reinterpret_cast<uintptr_t>(o) % 64 == 0) {
            for (uint32_t k = 0; k < 4; ++k) hn::Stream(v[k], d, o + k * kLanes);
        } else {
            for (uint32_t k = 0; k < 4; ++k) hn::StoreU(v[k], d, o + k * kLanes);
        }
        return;
    }
    alignas(64) float packed[4 * kLanes];
    for (uint32_t k = 0; k < 4; ++k) hn::Store(v[k], d, packed + k * kLanes);
    std::memcpy(o, packed, sizeof(glm::vec4) * n);
}

/// How many region rows ahead the load asks for.
constexpr uint32_t kPrefetchRows = 3;

/// Prefetches the cache lines of [p, p + bytes).
HWY_INLINE void prefetchRange(const void* p, size_t bytes) {
    const auto* b = reinterpret_cast<const unsigned char*>(uintptr_t(p) & ~uintptr_t(63));
    const auto* e = reinterpret_cast<const unsigned char*>(p) + bytes;
    for (; b < e; b += 64) hwy::Prefetch(b);
}

/// Last frame's colour (compressed when the resolve is) at the texel-centre positions (px, py) of 8 pixels, by the
/// Catmull-Rom filter of sampleHistory, in structure of arrays; lanes outside `wanted` are unspecified. Eight
/// consecutive integer positions on one row (a static camera, an integer pan) are one interleaved load of the texels
/// themselves (what the filter gives there, exactly); otherwise floor, fractions and weights are formed on vectors
/// and the taps per pixel, lanes near the frame's edge reading clamped copies of their taps. `prefetchNext`: ask for
/// the history row the next output row adds.
HWY_INLINE void sampleHistoryVec(const taa::ClampedImage<glm::vec4>& history, FloatVec px, FloatVec py,
                                 FloatMask wanted, bool prefetchNext, FloatVec& hr, FloatVec& hg, FloatVec& hb,
                                 FloatVec& ha) {
    const FloatTag d;
    const hn::RebindToSigned<FloatTag> di;
    const int32_t W = int32_t(history.width), H = int32_t(history.height), N = int32_t(kLanes);
    const FloatVec fx0 = hn::Floor(px), fy0 = hn::Floor(py);
    const auto ixv = hn::ConvertTo(di, fx0), iyv = hn::ConvertTo(di, fy0);
    const FloatMask integer = hn::And(hn::Eq(px, fx0), hn::Eq(py, fy0));
    const int32_t ix0 = hn::GetLane(ixv), iy0 = hn::GetLane(iyv);
    if (hn::AllTrue(d, integer) && ix0 >= 0 && ix0 + N <= W && iy0 >= 0 && iy0 < H &&
        hn::AllTrue(di, hn::And(hn::Eq(ixv, hn::Iota(di, ix0)), hn::Eq(iyv, hn::Set(di, iy0))))) {
        hn::LoadInterleaved4(d, reinterpret_cast<const float*>(&history.at(ix0, iy0)), hr, hg, hb, ha);
        if (prefetchNext && iy0 + 1 < H) prefetchRange(&history.at(ix0, iy0 + 1), sizeof(glm::vec4) * kLanes);
        return;
    }
    const size_t pitch = history.rowPitch;
    const auto* data = reinterpret_cast<const unsigned char*>(history.data);
    FloatVec wxv[4], wyv[4];
    catmullRomVec(d, hn::Sub(px, fx0), wxv);
    catmullRomVec(d, hn::Sub(py, fy0), wyv);
    alignas(64) float wx[4 * kLanes], wy[4][kLanes];
    alignas(64) int32_t kinds[kLanes], ixs[kLanes], iys[kLanes];
    enum : int32_t { kUnused = 0, kInterior = 1, kEdge = 2, kInteger = 3 };
    const auto interior = hn::And(hn::And(hn::Gt(ixv, hn::Zero(di)), hn::Gt(iyv, hn::Zero(di))),
                                  hn::And(hn::Lt(ixv, hn::Set(di, W - 2)), hn::Lt(iyv, hn::Set(di, H - 2))));
    auto kind = hn::IfThenElse(interior, hn::Set(di, kInterior), hn::Set(di, kEdge));
    // An integer position: the bicubic sum would give its texel exactly; read just that.
    kind = hn::IfThenElse(hn::RebindMask(di, integer), hn::Set(di, kInteger), kind);
    kind = hn::IfThenElseZero(hn::RebindMask(di, wanted), kind);
    hn::Store(kind, di, kinds);
    hn::Store(ixv, di, ixs);
    hn::Store(iyv, di, iys);
    transposeWeights(wxv, wx);
    for (int k = 0; k < 4; ++k) hn::Store(wyv[k], d, wy[k]);
    // Texel (ix - 1, iy - 1), the corner of a pixel's 4 x 4 block.
    const auto block = [&](uint32_t i) {
        return data + pitch * size_t(iys[i] - 1) + sizeof(glm::vec4) * size_t(ixs[i] - 1);
    };
    if (prefetchNext && kinds[0] == kInterior && kinds[N - 1] == kInterior && iys[0] + 3 < H) {
        // The next output row reads one history row more (iy + 3 here): ask for it now, a row ahead.
        const auto* first = block(0) + 4 * pitch;
        const auto* last = block(N - 1) + 4 * pitch + 4 * sizeof(glm::vec4);
        if (last > first && last - first < 512) prefetchRange(first, size_t(last - first));
    }
    Float4 sampled[kLanes];
    if (hn::AllTrue(di, hn::Eq(kind, hn::Set(di, kInterior)))) {
        // Every lane reads its block in place (the common case under motion): no per-lane branches.
        for (uint32_t i = 0; i < kLanes; ++i) sampled[i] = bicubicBlock(block(i), pitch, wx + weightRecord(i), wy, i);
    } else {
        for (uint32_t i = 0; i < kLanes; ++i) {
            if (kinds[i] == kInterior) {
                sampled[i] = bicubicBlock(block(i), pitch, wx + weightRecord(i), wy, i);
            } else if (kinds[i] == kInteger) {
                sampled[i] = hn::LoadU(Float4Tag(), reinterpret_cast<const float*>(&history.at(ixs[i], iys[i])));
            } else if (kinds[i] == kUnused) {
                sampled[i] = hn::Zero(Float4Tag());
            } else {
                // Near the frame's edge: the clamped taps, then the same arithmetic.
                alignas(64) glm::vec4 clampedBlock[4][4];
                for (int j = 0; j < 4; ++j)
                    for (int k = 0; k < 4; ++k) clampedBlock[j][k] = history.at(ixs[i] - 1 + k, iys[i] - 1 + j);
                sampled[i] = bicubicBlock(reinterpret_cast<const unsigned char*>(clampedBlock), sizeof(clampedBlock[0]),
                                          wx + weightRecord(i), wy, i);
            }
        }
    }
    transpose8(sampled, hr, hg, hb, ha);
}

/// The tiled path. The 3x3 statistics and the motion dilation are separable: each current pixel is converted to
/// YCoCg once (not nine times), sums, minima, maxima and the longest vector are formed over rows, then over
/// columns, and the rest runs on vectors of 8 pixels (Highway, AVX2). The bicubic history is fetched per pixel as
/// pairs of texels in 256-bit vectors (vertical weights first) and transposed in registers. It computes what the
/// reference kernel computes with FMA and with refined hardware estimates of sqrt and of the divisions, so it agrees
/// with it to a tolerance (a test checks it) rather than to the bit; minima, maxima, comparisons, the clipping
/// decision and the motion dilation are exact, and every pixel runs the same arithmetic wherever it lies, so a
/// constant image passes through exactly and integer motion reprojects exactly. A tile with a non-finite colour or
/// motion vector in reach runs the reference kernel instead (it skips those samples).
void resolveTile(const TaaInputs& in, const taa::TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                 const ImageView<glm::vec4>& history, Counts& counts) {
    TileScratch& s = scratch();
    const FloatTag d;
    const uint32_t N = kLanes;
    const uint32_t w = t.x1 - t.x0, h = t.y1 - t.y0;
    const uint32_t wv = (w + N - 1) / N * N;  // whole vectors
    const uint32_t rw = wv + 2, rh = h + 2;
    const uint32_t W = in.color.width, H = in.color.height;

    // Load the region (edges repeated), converting to YCoCg; note whether alpha is one constant over it.
    bool finite = true;
    // Region columns [vx0, vx1) read columns inside the frame: by vectors; the repeated edge columns beyond the frame
    // (and the padding of a partial tile) by scalar code.
    const uint32_t vx0 = t.x0 == 0 ? 1 : 0, vx1 = std::min(rw, W + 1 - t.x0);
    const bool byVectors = vx1 >= vx0 + N;
    const glm::vec4 color0 = in.color.at(int(t.x0), int(t.y0));
    const float alpha0 = color0.w;
    bool alphaConstant = true;
    // A region of one colour (a tile of black sky, a constant image): every pixel's neighbourhood is flat, so no
    // statistics are needed at all.
    bool colorConstant = true;
    for (uint32_t ry = 0; ry < rh; ++ry) {
        const uint32_t sy = clampIndex(int(t.y0 + ry) - 1, H);
        const glm::vec4* colorRow = &in.color.at(0, int(sy));
        const glm::vec2* mvecRow = &in.mvec.at(0, int(sy));
        if (ry + kPrefetchRows < rh) {
            // Each region row is a short run the hardware prefetchers barely get going on: ask for a later one.
            const uint32_t ay = clampIndex(int(t.y0 + ry + kPrefetchRows) - 1, H);
            const uint32_t ax = clampIndex(int(t.x0) - 1, W);
            prefetchRange(&in.color.at(int(ax), int(ay)), sizeof(glm::vec4) * rw);
            prefetchRange(&in.mvec.at(int(ax), int(ay)), sizeof(glm::vec2) * rw);
        }
        const auto scalarColumn = [&](uint32_t rx) {
            const uint32_t sx = clampIndex(int(t.x0 + rx) - 1, W);
            const glm::vec4 c = taa::currentColor(in, int(sx), int(sy));
            const glm::vec2 m = mvecRow[sx];
            finite &= taa::isFinite(c) & taa::isFinite(m);
            alphaConstant &= c.w == alpha0;
            colorConstant &= glm::vec3(colorRow[sx]) == glm::vec3(color0);  // the input's rgb, as the vector loop
            const glm::vec4 v = taa::toYCoCg(c);
            for (int ch = 0; ch < 4; ++ch) s.v[ch][ry][rx] = v[ch];
            s.mvx[ry][rx] = m.x;
            s.mvy[ry][rx] = m.y;
            s.mvLen[ry][rx] = m.x * m.x + m.y * m.y;
        };
        if (!byVectors) {
            for (uint32_t rx = 0; rx < rw; ++rx) scalarColumn(rx);
            continue;
        }
        for (uint32_t rx = 0; rx < vx0; ++rx) scalarColumn(rx);
        for (uint32_t rx = vx1; rx < rw; ++rx) scalarColumn(rx);
        FloatMask ok = hn::FirstN(d, N), same = ok;
        const FloatVec a0 = hn::Set(d, alpha0);
        const FloatVec r0 = hn::Set(d, color0.x), g0 = hn::Set(d, color0.y), b0 = hn::Set(d, color0.z);
        const glm::vec4* colorBase = colorRow + t.x0 - 1;
        const glm::vec2* mvecBase = mvecRow + t.x0 - 1;
        for (uint32_t rx = vx0; rx < vx1; rx += N) {
            rx = std::min(rx, vx1 - N);  // the last vector overlaps the one before
            FloatVec r, g, b, a, mx, my, y, co, cg;
            hn::LoadInterleaved4(d, reinterpret_cast<const float*>(colorBase + rx), r, g, b, a);
            same = hn::And(same, hn::And(hn::Eq(r, r0), hn::And(hn::Eq(g, g0), hn::Eq(b, b0))));
            if (in.compress) compressVec(d, r, g, b);  // finite colours stay finite, non-finite ones non-finite
            hn::LoadInterleaved2(d, reinterpret_cast<const float*>(mvecBase + rx), mx, my);
            ok = hn::And(ok, hn::And(hn::And(finiteVec(d, r), finiteVec(d, g)),
                                     hn::And(hn::And(finiteVec(d, b), hn::Eq(a, a0)),
                                             hn::And(finiteVec(d, mx), finiteVec(d, my)))));
            toYCoCgVec(d, r, g, b, y, co, cg);
            hn::StoreU(y, d, &s.v[0][ry][rx]);
            hn::StoreU(co, d, &s.v[1][ry][rx]);
            hn::StoreU(cg, d, &s.v[2][ry][rx]);
            hn::StoreU(a, d, &s.v[3][ry][rx]);
            hn::StoreU(mx, d, &s.mvx[ry][rx]);
            hn::StoreU(my, d, &s.mvy[ry][rx]);
            hn::StoreU(hn::Add(hn::Mul(mx, mx), hn::Mul(my, my)), d, &s.mvLen[ry][rx]);
        }
        colorConstant &= hn::AllTrue(d, same);
        if (!hn::AllTrue(d, ok)) {
            // Not all finite, or alpha varies: tell the two apart.
            for (uint32_t rx = vx0; rx < vx1; ++rx) {
                const glm::vec4 c = colorBase[rx];
                finite &= taa::isFinite(c) & taa::isFinite(mvecBase[rx]);
                alphaConstant &= c.w == alpha0;
            }
        }
    }
    if (!finite) {
        resolveTileReference(in, p, t, out, history, counts);
        return;
    }

    // Horizontal 3-tap statistics and longest vector, per region row (vectors over x; rw = wv + 2 so the taps at
    // x + 1 and x + 2 of the last vector stay in the region). A constant alpha needs no statistics: its box is
    // [alpha0, alpha0] (what the general formulas give too: the clamp to min / max).
    const FloatVec huge = hn::Set(d, taa::kHuge), negHuge = hn::Set(d, -taa::kHuge);
    const bool regionFlat = colorConstant && alphaConstant;
    const int channels = regionFlat ? 0 : alphaConstant ? 3 : 4;  // of the horizontal statistics
    for (uint32_t ry = 0; ry < rh; ++ry) {
        for (int ch = 0; ch < channels; ++ch) {
            const float* v = s.v[ch][ry];
            for (uint32_t x = 0; x < wv; x += N) {
                const FloatVec a = hn::LoadU(d, v + x), b = hn::LoadU(d, v + x + 1), c = hn::LoadU(d, v + x + 2);
                hn::StoreU(hn::Add(hn::Add(a, b), c), d, &s.rowSum[ch][ry][x]);
                hn::StoreU(hn::MulAdd(c, c, hn::MulAdd(b, b, hn::Mul(a, a))), d, &s.rowSumSq[ch][ry][x]);
                hn::StoreU(hn::Min(c, hn::Min(b, hn::Min(a, huge))), d, &s.rowMin[ch][ry][x]);
                hn::StoreU(hn::Max(c, hn::Max(b, hn::Max(a, negHuge))), d, &s.rowMax[ch][ry][x]);
            }
        }
        const float* mvx = s.mvx[ry];
        const float* mvy = s.mvy[ry];
        const float* len = s.mvLen[ry];
        for (uint32_t x = 0; x < wv; x += N) {
            // Strictly longer wins: the first of equals, as in the reference.
            FloatVec best = hn::LoadU(d, len + x), bx = hn::LoadU(d, mvx + x), by = hn::LoadU(d, mvy + x);
            for (uint32_t k = 1; k < 3; ++k) {
                const FloatVec l = hn::LoadU(d, len + x + k);
                const FloatMask longer = hn::Gt(l, best);
                best = hn::IfThenElse(longer, l, best);
                bx = hn::IfThenElse(longer, hn::LoadU(d, mvx + x + k), bx);
                by = hn::IfThenElse(longer, hn::LoadU(d, mvy + x + k), by);
            }
            hn::StoreU(best, d, &s.rowMvLen[ry][x]);
            hn::StoreU(bx, d, &s.rowMvx[ry][x]);
            hn::StoreU(by, d, &s.rowMvy[ry][x]);
        }
    }

    const FloatVec zero = hn::Zero(d), one = hn::Set(d, 1.f), half = hn::Set(d, 0.5f);
    const FloatVec infinity = hn::Set(d, std::numeric_limits<float>::infinity());
    const FloatVec sigma = hn::Set(d, p.sigma), ninth = hn::Set(d, 1.f / 9.f);
    alignas(64) glm::vec4 current[kLanes];
    // Each output row runs in three phases over its vectors, their results passed through the row scratch: the
    // box and the motion, the history, the clip and blend. One vector's chain from its loads to its stores is long
    // (square root, reciprocals, the bicubic taps, the blend); in shorter loops the processor overlaps consecutive
    // vectors instead of waiting on each.
    for (uint32_t y = 0; y < h; ++y) {
        const uint32_t py = t.y0 + y;
        glm::vec4* outRow = out.row(py);
        glm::vec4* historyRow = history.row(py);
        const glm::vec4* colorRow = &in.color.at(0, int(py));
        // Phase 1: dilated motion and previous position; the neighbourhood's box.
        for (uint32_t x = 0; x < wv; x += N) {
            const uint32_t n = std::min(N, w - x);
            const FloatMask valid = hn::FirstN(d, n);
            // Dilated motion: the longest of the three row winners, the first of equals.
            FloatVec best = hn::LoadU(d, &s.rowMvLen[y][x]);
            FloatVec mvx = hn::LoadU(d, &s.rowMvx[y][x]), mvy = hn::LoadU(d, &s.rowMvy[y][x]);
            for (uint32_t r = y + 1; r < y + 3; ++r) {
                const FloatVec len = hn::LoadU(d, &s.rowMvLen[r][x]);
                const FloatMask longer = hn::Gt(len, best);
                best = hn::IfThenElse(longer, len, best);
                mvx = hn::IfThenElse(longer, hn::LoadU(d, &s.rowMvx[r][x]), mvx);
                mvy = hn::IfThenElse(longer, hn::LoadU(d, &s.rowMvy[r][x]), mvy);
            }
            // previousPosition (the same operations as the reference: the off-frame decision is exact).
            const FloatVec px = hn::Add(hn::Iota(d, float(t.x0 + x)), hn::Mul(mvx, hn::Set(d, float(W))));
            const FloatVec pyv = hn::Add(hn::Set(d, float(py)), hn::Mul(mvy, hn::Set(d, float(H))));
            FloatMask useHistory =
                hn::And(hn::And(hn::Ge(px, hn::Set(d, -0.5f)), hn::Le(px, hn::Set(d, float(W) - 0.5f))),
                        hn::And(hn::Ge(pyv, hn::Set(d, -0.5f)), hn::Le(pyv, hn::Set(d, float(H) - 0.5f))));
            useHistory = in.historyValid ? hn::And(useHistory, valid) : hn::Not(hn::FirstN(d, N));
            // A neighbourhood of one value (ClipBox::flat: minimum = maximum in every channel) resolves to the
            // current colour: its history is not read. The minima and maxima bound the box too.
            FloatMask flat = hn::FirstN(d, N);
            FloatVec boxMin[4], boxMax[4];
            for (int ch = 0; ch < channels; ++ch) {  // a one-colour region: flat everywhere
                FloatVec mn = hn::LoadU(d, &s.rowMin[ch][y][x]), mx = hn::LoadU(d, &s.rowMax[ch][y][x]);
                for (uint32_t r = y + 1; r < y + 3; ++r) {
                    mn = hn::Min(hn::LoadU(d, &s.rowMin[ch][r][x]), mn);
                    mx = hn::Max(hn::LoadU(d, &s.rowMax[ch][r][x]), mx);
                }
                flat = hn::And(flat, hn::Eq(mn, mx));
                boxMin[ch] = mn;
                boxMax[ch] = mx;
            }
            counts.noHistory += n - hn::CountTrue(d, useHistory);
            s.anyHistory[x] = !hn::AllTrue(d, flat);
            if (!s.anyHistory[x]) continue;
            hn::Store(hn::VecFromMask(d, hn::AndNot(flat, useHistory)), d, &s.resolveHistory[x]);
            hn::Store(px, d, &s.px[x]);
            hn::Store(pyv, d, &s.py[x]);
            // The box (makeClipBox with n = 9) channel by channel, as centre and half extent (clipToBox); the
            // inverse extent for the ratio is the refined reciprocal, infinite for a flat channel, which pulls the
            // point exactly onto the centre. A constant alpha is the box [alpha0, alpha0].
            for (int ch = 0; ch < 4; ++ch) {
                FloatVec lo, hi;
                if (ch == 3 && alphaConstant) {
                    lo = hi = hn::Set(d, alpha0);
                } else {
                    FloatVec sum = hn::LoadU(d, &s.rowSum[ch][y][x]), sumSq = hn::LoadU(d, &s.rowSumSq[ch][y][x]);
                    for (uint32_t r = y + 1; r < y + 3; ++r) {
                        sum = hn::Add(sum, hn::LoadU(d, &s.rowSum[ch][r][x]));
                        sumSq = hn::Add(sumSq, hn::LoadU(d, &s.rowSumSq[ch][r][x]));
                    }
                    const FloatVec mn = boxMin[ch], mx = boxMax[ch];
                    const FloatVec mean = hn::Mul(sum, ninth);
                    const FloatVec var = hn::Max(hn::NegMulAdd(mean, mean, hn::Mul(sumSq, ninth)), zero);
                    const FloatVec dev = hn::Mul(sigma, squareRoot(d, var));
                    lo = hn::Min(hn::Max(hn::Sub(mean, dev), mn), mx);
                    hi = hn::Min(hn::Max(hn::Add(mean, dev), mn), mx);
                }
                const FloatVec extent = hn::Mul(half, hn::Sub(hi, lo));
                hn::Store(hn::Mul(half, hn::Add(lo, hi)), d, &s.center[ch][x]);
                hn::Store(extent, d, &s.extent[ch][x]);
                hn::Store(hn::IfThenElse(hn::Gt(extent, zero), reciprocal(d, extent), infinity), d,
                          &s.invExtent[ch][x]);
            }
        }
        // Phase 2: the history (compressed when the resolve is) where a lane resolves against it.
        for (uint32_t x = 0; x < wv; x += N) {
            if (!s.anyHistory[x]) continue;
            FloatVec hr, hg, hb, ha;
            sampleHistoryVec(in.history, hn::Load(d, &s.px[x]), hn::Load(d, &s.py[x]),
                             hn::MaskFromVec(hn::Load(d, &s.resolveHistory[x])), y + 1 < h, hr, hg, hb, ha);
            hn::Store(hr, d, &s.history[0][x]);
            hn::Store(hg, d, &s.history[1][x]);
            hn::Store(hb, d, &s.history[2][x]);
            hn::Store(ha, d, &s.history[3][x]);
        }
        // Phase 3: clip, blend, store.
        for (uint32_t x = 0; x < wv; x += N) {
            const uint32_t n = std::min(N, w - x);
            FloatVec cr, cgr, cb, ca;
            const glm::vec4* currentPixels = colorRow + t.x0 + x;
            if (n < N) {  // the end of a partial tile: do not read past the row
                for (uint32_t i = 0; i < N; ++i) current[i] = currentPixels[std::min(i, n - 1)];
                currentPixels = current;
            }
            hn::LoadInterleaved4(d, reinterpret_cast<const float*>(currentPixels), cr, cgr, cb, ca);
            // The linear input, kept for the output; the resolve runs on the compressed colour.
            const FloatVec lr = cr, lg = cgr, lb = cb;
            if (in.compress) compressVec(d, cr, cgr, cb);
            // The resolved (compressed) colour: the current one unless the history takes part.
            FloatVec orr = cr, og = cgr, ob = cb, oa = ca;
            FloatMask clipped = hn::FirstN(d, 0);
            if (s.anyHistory[x]) {
                const FloatMask resolveHistory = hn::MaskFromVec(hn::Load(d, &s.resolveHistory[x]));
                FloatVec hr = hn::Load(d, &s.history[0][x]), hg = hn::Load(d, &s.history[1][x]);
                FloatVec hb = hn::Load(d, &s.history[2][x]), ha = hn::Load(d, &s.history[3][x]);
                // clipToBox: the exact test "outside", the largest ratio of the channels outside.
                FloatVec hv[4];
                toYCoCgVec(d, hr, hg, hb, hv[0], hv[1], hv[2]);
                hv[3] = ha;
                FloatVec unit = zero, delta[4], center[4];
                for (int ch = 0; ch < 4; ++ch) {
                    center[ch] = hn::Load(d, &s.center[ch][x]);
                    delta[ch] = hn::Sub(hv[ch], center[ch]);
                    const FloatVec a = hn::Abs(delta[ch]);
                    const FloatMask outside = hn::Gt(a, hn::Load(d, &s.extent[ch][x]));
                    unit = hn::IfThenElse(outside, hn::Max(unit, hn::Mul(a, hn::Load(d, &s.invExtent[ch][x]))), unit);
                }
                clipped = hn::And(resolveHistory, hn::Gt(unit, zero));
                const FloatVec inv = hn::IfThenElseZero(hn::Lt(unit, infinity), reciprocal(d, unit));
                FloatVec cv[4];
                for (int ch = 0; ch < 4; ++ch)
                    cv[ch] = hn::IfThenElse(clipped, hn::MulAdd(delta[ch], inv, center[ch]), hv[ch]);
                // fromYCoCg where clipped; the sampled RGB elsewhere.
                hr = hn::IfThenElse(clipped, hn::Sub(hn::Add(cv[0], cv[1]), cv[2]), hr);
                hg = hn::IfThenElse(clipped, hn::Add(cv[0], cv[2]), hg);
                hb = hn::IfThenElse(clipped, hn::Sub(hn::Sub(cv[0], cv[1]), cv[2]), hb);
                ha = hn::IfThenElse(clipped, cv[3], ha);
                // Blend with anti-flicker: c + k (h - c), so h == c gives exactly c.
                FloatVec wc = hn::Set(d, p.alpha), wh = hn::Set(d, 1.f - p.alpha);
                if (p.antiFlicker) {
                    FloatVec yc, coc, cgc;
                    toYCoCgVec(d, cr, cgr, cb, yc, coc, cgc);
                    wc = hn::Mul(wc, hn::Add(one, hn::Max(cv[0], zero)));
                    wh = hn::Mul(wh, hn::Add(one, hn::Max(yc, zero)));
                }
                const FloatVec wsum = hn::Add(wc, wh);
                const FloatVec k = hn::IfThenElseZero(hn::Gt(wsum, zero), hn::Mul(wh, reciprocal(d, wsum)));
                orr = hn::MulAdd(k, hn::Sub(hr, cr), cr);
                og = hn::MulAdd(k, hn::Sub(hg, cgr), cgr);
                ob = hn::MulAdd(k, hn::Sub(hb, cb), cb);
                oa = hn::MulAdd(k, hn::Sub(ha, ca), ca);
                const FloatMask keep = hn::And(resolveHistory, hn::And(hn::And(finiteVec(d, orr), finiteVec(d, og)),
                                                                       hn::And(finiteVec(d, ob), finiteVec(d, oa))));
                orr = hn::IfThenElse(keep, orr, cr);
                og = hn::IfThenElse(keep, og, cgr);
                ob = hn::IfThenElse(keep, ob, cb);
                oa = hn::IfThenElse(keep, oa, ca);
            }
            FloatVec packed[4];
            interleavePixels(orr, og, ob, oa, packed);
            // History streams: it is read again only next frame, long after it has left the caches, and streaming
            // skips the read-for-ownership of its lines. (Streaming the output too measured no gain.)
            storeInterleaved(packed, historyRow + t.x0 + x, n, true);
            if (in.compress) {
                // outputColor(): the linear input where the resolve returned the compressed input, else expanded.
                const FloatMask same =
                    hn::And(hn::And(hn::Eq(orr, cr), hn::Eq(og, cgr)), hn::And(hn::Eq(ob, cb), hn::Eq(oa, ca)));
                expandVec(d, orr, og, ob);
                const FloatMask finiteOut =
                    hn::And(hn::And(finiteVec(d, orr), finiteVec(d, og)), hn::And(finiteVec(d, ob), finiteVec(d, oa)));
                orr = hn::IfThenElse(same, lr, hn::IfThenElseZero(finiteOut, orr));
                og = hn::IfThenElse(same, lg, hn::IfThenElseZero(finiteOut, og));
                ob = hn::IfThenElse(same, lb, hn::IfThenElseZero(finiteOut, ob));
                oa = hn::IfThenElse(same, ca, hn::IfThenElseZero(finiteOut, oa));
                interleavePixels(orr, og, ob, oa, packed);
            }
            storeInterleaved(packed, outRow + t.x0 + x, n, false);
            counts.clipped += hn::CountTrue(d, clipped);
        }
    }
    hwy::FlushStream();  // order the streaming stores before the frame's end
}

template <class T>
taa::ClampedImage<T> clamped(const Texture& t) {
    const auto v = t.view<T>();
    return {v.data, v.width, v.height, v.rowPitch};
}

}  // namespace

void TAAPass::reflect(Reflection& r, const CompileInfo&) const {
    r.input(kColorIn, Format::RGBA32F).doc("this frame's jittered colour (connect with an explicit edge)");
    r.input(kMvec, Format::RG32F).doc("uvPrev - uvCur in [0, 1]^2 uv, jitter removed (by name from the G-buffer)");
    r.output(kColorOut, Format::RGBA32F).doc("anti-aliased colour; always finite");
    r.history(kColorHistory, Format::RGBA32F)
        .doc("last frame's resolved colour, the history that is reprojected (compressed when hdrCompress)");
}

void TAAPass::declareParams(ParamList& p) {
    p.add("alpha", &mParams.alpha, 0.1f)
        .range(0.0, 1.0)
        .doc("weight of the current frame in the blend (1 = no history)");
    p.add("sigma", &mParams.sigma, 1.f)
        .range(0.0, 10.0)
        .doc("clipping box half-size in standard deviations of the 3x3 neighbourhood (YCoCg)");
    p.add("antiFlicker", &mParams.antiFlicker, true)
        .doc("weight current and history by 1 / (1 + luma) (Karis 2014) so bright outliers do not flicker");
    p.add("hdrCompress", &mHdrCompress, true)
        .doc(
            "resolve in c / (1 + luma) and expand after (Karis 2014), so a bright light does not bleed into dark "
            "neighbours through the bicubic history under motion");
    p.add("reference", &mReference, false)
        .doc("run the plain per-pixel reference kernel instead of the tiled CPU path (agrees to 1e-4, slower)");
}

void TAAPass::execute(PassContext& ctx) {
    TaaInputs in;
    in.color = clamped<glm::vec4>(*ctx.input(kColorIn));
    in.compress = mHdrCompress;
    in.mvec = clamped<glm::vec2>(*ctx.input(kMvec));
    in.history = clamped<glm::vec4>(ctx.historyPrev(kColorHistory));
    in.historyValid = ctx.historyValid();
    const auto out = ctx.output(kColorOut)->view<glm::vec4>();
    const auto history = ctx.historyCur(kColorHistory).view<glm::vec4>();

    std::atomic<uint64_t> nonFinite{0}, noHistory{0}, clipped{0};
    const taa::TaaParams params = mParams;
    const bool reference = mReference;
    const uint32_t tilesX = (out.width + kTileW - 1) / kTileW, tilesY = (out.height + kTileH - 1) / kTileH;
    parallelFor2D(
        tilesX, tilesY,
        [&](const Tile& cell) {
            const Tile t{cell.x0 * kTileW, cell.y0 * kTileH, std::min(out.width, (cell.x0 + 1) * kTileW),
                         std::min(out.height, (cell.y0 + 1) * kTileH)};
            Counts counts;
            if (reference)
                resolveTileReference(in, params, t, out, history, counts);
            else
                resolveTile(in, params, t, out, history, counts);
            // Integer sums: the same totals in any order.
            nonFinite += counts.nonFinite;
            noHistory += counts.noHistory;
            clipped += counts.clipped;
        },
        1);  // one cell of the tile grid per task

    ctx.stats().set(kStatNonFinite, double(nonFinite));
    ctx.stats().set(kStatNoHistory, double(noHistory));
    ctx.stats().set(kStatClipped, double(clipped));
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::TAAPass>(
        "TAAPass",
        "Temporal anti-aliasing: 3x3 YCoCg variance clipping, motion dilation (longest vector of the 3x3), "
        "Catmull-Rom history, luminance-weighted blend against flicker; history in a graph field. Non-finite input "
        "pixels are replaced by the neighbourhood mean; a neighbourhood of one colour (a black sky) resolves to it "
        "without reading the history. Stats: nonFinite (input pixels replaced), noHistory (pixels without usable "
        "history), clipped (pixels whose history was clipped; not those of one-colour neighbourhoods).");
}
