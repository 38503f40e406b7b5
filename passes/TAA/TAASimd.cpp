// The tiled vector path of TAAPass, compiled once per Highway target (foreach_target) and dispatched at run time to
// the best one the CPU has: AVX2 on the x86-64-v3 baseline, AVX-512 where present (as passes/SVGF/AtrousSimd.cpp).
#include "TAASimd.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <vector>

#ifndef LOOM_TAA_SIMD_SHARED
#define LOOM_TAA_SIMD_SHARED
namespace loom::taa::detail {

/// Scratch of the tiled path for one tile: the tile plus a one-pixel border of
/// the current colour in YCoCg + alpha (structure of arrays, so the loops over
/// a row vectorize), the horizontal 3-tap statistics, and the motion vectors.
/// Rows are padded to whole vectors: every pixel, those of a partial tile too,
/// takes the same vector arithmetic (so a pixel's result never depends on where
/// its tile ends).
struct TileScratch {
    static constexpr uint32_t kW = kTileW, kR = kTileH + 2, kRW = kTileW + 2 + kMaxLanes;  // whole vectors at the end
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

/// A tile's scratch, borrowed from a pool for the tile's duration and returned after (each tile overwrites what it
/// reads). Not thread_local: LeakSanitizer's scan of a dlopen'ed plugin's dynamic TLS crashes at exit.
class ScratchLease {
public:
    ScratchLease() {
        std::lock_guard lock(mutex());
        if (!pool().empty()) {
            mScratch = std::move(pool().back());
            pool().pop_back();
        } else {
            mScratch = std::make_unique<TileScratch>();
        }
    }
    ~ScratchLease() {
        std::lock_guard lock(mutex());
        pool().push_back(std::move(mScratch));
    }
    ScratchLease(const ScratchLease&) = delete;
    ScratchLease& operator=(const ScratchLease&) = delete;
    TileScratch& operator*() const { return *mScratch; }

private:
    static std::mutex& mutex() {
        static std::mutex m;
        return m;
    }
    static std::vector<std::unique_ptr<TileScratch>>& pool() {
        static std::vector<std::unique_ptr<TileScratch>> p;
        return p;
    }
    std::unique_ptr<TileScratch> mScratch;
};

uint32_t clampIndex(int v, uint32_t size) {
    return uint32_t(std::clamp(v, 0, int(size) - 1));
}

}  // namespace loom::taa::detail
#endif  // LOOM_TAA_SIMD_SHARED

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "TAASimd.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // must come first: it includes this file once per target
#include <hwy/highway.h>
#include <hwy/cache_control.h>
#include "loom/simd/LaneIndex-inl.h"
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace loom::taa::HWY_NAMESPACE {

using namespace detail;
using ::loom::simd::HWY_NAMESPACE::firstPlusLane;

namespace hn = hwy::HWY_NAMESPACE;
using FloatTag = hn::ScalableTag<float>;
using FloatVec = hn::Vec<FloatTag>;
using FloatMask = hn::Mask<FloatTag>;
using Float4Tag = hn::FixedTag<float, 4>;
// Floats per vector: 8 on AVX2, 16 on AVX-512. A vector holds kBlocks RGBA texels (128-bit blocks); a row of four
// texels (a row of a pixel's bicubic footprint) is kChunks vectors.
constexpr uint32_t kLanes = uint32_t(hn::MaxLanes(FloatTag()));
constexpr uint32_t kBlocks = kLanes / 4, kChunks = 4 / kBlocks;
static_assert(kLanes <= kMaxLanes && kTileW % kLanes == 0, "scratch and tiles are sized for at most kMaxLanes");

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

/// Lanes where every one of the vectors is finite: x * 0 is NaN exactly where x is infinite or NaN and a sum of
/// zeros is a zero, so one comparison tests them all (against two operations per vector and the masks' conjunction).
template <class... Vs>
HWY_INLINE FloatMask allFiniteVec(FloatTag d, FloatVec v, Vs... rest) {
    FloatVec t = hn::Mul(v, hn::Zero(d));
    ((t = hn::MulAdd(rest, hn::Zero(d), t)), ...);
    return hn::Eq(t, t);
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

/// Lane l of chunk k: the horizontal weight of texel column k kBlocks + l / 4 (a pixel's four weights broadcast to
/// the texels of a row of its block).
struct WeightLanes {
    alignas(64) int32_t index[kChunks][kLanes];
};
constexpr WeightLanes makeWeightLanes() {
    WeightLanes w{};
    for (uint32_t k = 0; k < kChunks; ++k)
        for (uint32_t l = 0; l < kLanes; ++l) w.index[k][l] = int32_t(k * kBlocks + l / 4);
    return w;
}
constexpr WeightLanes kWeightLanes = makeWeightLanes();

/// Catmull-Rom sum of a pixel's 4 x 4 block of RGBA32F texels (row j at block + j pitch) as differences from texel
/// (1, 1), `ref` (in every 128-bit block), which the caller adds last (as sampleHistory does: constant history stays
/// exact): vertical weights wy[j][i] (lane i's) first, on rows of four texels, kChunks vectors each, then the
/// horizontal ones, wx (lane i's four), with FMA. Returns kBlocks partial sums, one per 128-bit block, whose total
/// (sumBlocks) is the filtered difference: 0 exactly at an integer position (weights 0, 1, 0, 0 both ways).
HWY_INLINE FloatVec bicubicBlock(const unsigned char* block, size_t pitch, FloatVec ref, const float* wx,
                                 const float (&wy)[4][kLanes], uint32_t i) {
    const FloatTag d;
    FloatVec column[kChunks];
    for (uint32_t j = 0; j < 4; ++j) {
        const float* row = reinterpret_cast<const float*>(block + pitch * j);
        const FloatVec w = hn::Set(d, wy[j][i]);
        for (uint32_t k = 0; k < kChunks; ++k) {
            const FloatVec diff = hn::Sub(hn::LoadU(d, row + k * kLanes), ref);
            column[k] = j == 0 ? hn::Mul(w, diff) : hn::MulAdd(w, diff, column[k]);
        }
    }
    const FloatVec weights = hn::LoadDup128(d, wx);
    FloatVec sum = hn::Mul(hn::TableLookupLanes(weights, hn::SetTableIndices(d, kWeightLanes.index[0])), column[0]);
    for (uint32_t k = 1; k < kChunks; ++k)
        sum = hn::MulAdd(hn::TableLookupLanes(weights, hn::SetTableIndices(d, kWeightLanes.index[k])), column[k], sum);
    return sum;
}

/// Block m of the result: the sum of the kBlocks 128-bit blocks of part[m] (halves first, then quarters).
template <size_t kParts>
HWY_INLINE FloatVec sumBlocks(const FloatVec (&part)[kParts]) {
    static_assert(kParts == kBlocks);
    const FloatTag d;
    const auto halves = [d](FloatVec hi, FloatVec lo) {
        return hn::Add(hn::ConcatLowerLower(d, hi, lo), hn::ConcatUpperUpper(d, hi, lo));
    };
    if constexpr (kParts == 1) {
        return part[0];
    } else if constexpr (kParts == 2) {
        return halves(part[1], part[0]);
    } else {
        static_assert(kParts == 4);
        // Parts a, b, c, e with quarters 0..3: ac = (a0 + a2, a1 + a3, c0 + c2, c1 + c3), be likewise; the odd
        // quarters of ac swap with the even ones of be.
        const FloatVec ac = halves(part[2], part[0]), be = halves(part[3], part[1]);
        return hn::Add(hn::OddEvenBlocks(be, ac), hn::SwapAdjacentBlocks(hn::OddEvenBlocks(ac, be)));
    }
}

/// Block m of the result: the RGBA texel at texel[m].
template <size_t kTexels>
HWY_INLINE FloatVec blocksOf(const float* const (&texel)[kTexels]) {
    static_assert(kTexels == kBlocks);
    const FloatTag d;
    if constexpr (kTexels == 1) {
        return hn::LoadU(d, texel[0]);
    } else if constexpr (kTexels == 2) {
        return hn::OddEvenBlocks(hn::LoadDup128(d, texel[1]), hn::LoadDup128(d, texel[0]));
    } else {
        static_assert(kTexels == 4);
        const FloatVec t01 = hn::OddEvenBlocks(hn::LoadDup128(d, texel[1]), hn::LoadDup128(d, texel[0]));
        const FloatVec t23 = hn::OddEvenBlocks(hn::LoadDup128(d, texel[3]), hn::LoadDup128(d, texel[2]));
        return hn::ConcatUpperLower(d, t23, t01);
    }
}

/// Four vectors of RGBA texels, q[k] holding pixels k, k + 4, k + 8, ... (one per 128-bit block), to structure of
/// arrays.
HWY_INLINE void transposeBlocks(const FloatVec (&q)[4], FloatVec& r, FloatVec& g, FloatVec& b, FloatVec& a) {
    const FloatTag d;
    const hn::Repartition<double, FloatTag> dd;
    // Per 128-bit block: t0 = (r0 r1 g0 g1), t1 = (b0 b1 a0 a1), t2 = (r2 r3 g2 g3), t3 = (b2 b3 a2 a3).
    const auto t0 = hn::BitCast(dd, hn::InterleaveLower(q[0], q[1]));
    const auto t1 = hn::BitCast(dd, hn::InterleaveUpper(d, q[0], q[1]));
    const auto t2 = hn::BitCast(dd, hn::InterleaveLower(q[2], q[3]));
    const auto t3 = hn::BitCast(dd, hn::InterleaveUpper(d, q[2], q[3]));
    r = hn::BitCast(d, hn::InterleaveLower(t0, t2));
    g = hn::BitCast(d, hn::InterleaveUpper(dd, t0, t2));
    b = hn::BitCast(d, hn::InterleaveLower(t1, t3));
    a = hn::BitCast(d, hn::InterleaveUpper(dd, t1, t3));
}

/// Writes the first n of kLanes interleaved RGBA pixels (`packed`, 64-byte aligned) to p; streaming (`stream`) when
/// all of them go to a 64-byte aligned place.
HWY_INLINE void storePacked(const float* packed, glm::vec4* p, uint32_t n, bool stream) {
    const FloatTag d;
    float* o = reinterpret_cast<float*>(p);
    if (n < kLanes) {
        std::memcpy(o, packed, sizeof(glm::vec4) * n);
    } else if (stream && reinterpret_cast<uintptr_t>(o) % 64 == 0) {
        for (uint32_t k = 0; k < 4; ++k) hn::Stream(hn::Load(d, packed + k * kLanes), d, o + k * kLanes);
    } else {
        for (uint32_t k = 0; k < 4; ++k) hn::StoreU(hn::Load(d, packed + k * kLanes), d, o + k * kLanes);
    }
}

/// Writes the first n of the vector's pixels (r, g, b, a) interleaved to p, as storePacked.
HWY_INLINE void storePixels(FloatVec r, FloatVec g, FloatVec b, FloatVec a, glm::vec4* p, uint32_t n, bool stream) {
    const FloatTag d;
    if (n == kLanes && !stream) {
        hn::StoreInterleaved4(r, g, b, a, d, reinterpret_cast<float*>(p));
        return;
    }
    alignas(64) float packed[4 * kLanes];
    hn::StoreInterleaved4(r, g, b, a, d, packed);
    storePacked(packed, p, n, stream);
}

/// How many region rows ahead the load asks for.
constexpr uint32_t kPrefetchRows = 3;

/// Prefetches the cache lines of [p, p + bytes).
HWY_INLINE void prefetchRange(const void* p, size_t bytes) {
    const auto* b = reinterpret_cast<const unsigned char*>(uintptr_t(p) & ~uintptr_t(63));
    const auto* e = reinterpret_cast<const unsigned char*>(p) + bytes;
    for (; b < e; b += 64) hwy::Prefetch(b);
}

/// Last frame's colour (compressed when the resolve is) at the texel-centre positions (px, py) of a vector's pixels,
/// by the Catmull-Rom filter of sampleHistory, in structure of arrays; lanes outside `wanted` are unspecified. A
/// vector's consecutive integer positions on one row (a static camera, an integer pan) are one interleaved load of the
/// texels themselves (what the filter gives there, exactly); otherwise floor, fractions and weights are formed on
/// vectors and the taps per pixel, lanes near the frame's edge reading clamped copies of their taps. `prefetchNext`:
/// ask for the history row the next output row adds.
HWY_INLINE void sampleHistoryVec(const ClampedImage<glm::vec4>& history, FloatVec px, FloatVec py, FloatMask wanted,
                                 bool prefetchNext, FloatVec& hr, FloatVec& hg, FloatVec& hb, FloatVec& ha) {
    const FloatTag d;
    const hn::RebindToSigned<FloatTag> di;
    const int32_t W = int32_t(history.width), H = int32_t(history.height), N = int32_t(kLanes);
    const FloatVec fx0 = hn::Floor(px), fy0 = hn::Floor(py);
    const auto ixv = hn::ConvertTo(di, fx0), iyv = hn::ConvertTo(di, fy0);
    const FloatMask integer = hn::And(hn::Eq(px, fx0), hn::Eq(py, fy0));
    const int32_t ix0 = hn::GetLane(ixv), iy0 = hn::GetLane(iyv);
    // ix0 <= W - N rather than ix0 + N <= W: a position far off the frame converts to a saturated integer.
    if (hn::AllTrue(d, integer) && ix0 >= 0 && ix0 <= W - N && iy0 >= 0 && iy0 < H &&
        hn::AllTrue(di, hn::And(hn::Eq(ixv, firstPlusLane(di, ix0)), hn::Eq(iyv, hn::Set(di, iy0))))) {
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
    hn::StoreInterleaved4(wxv[0], wxv[1], wxv[2], wxv[3], d, wx);  // lane i's four weights at wx + 4 i
    for (int k = 0; k < 4; ++k) hn::Store(wyv[k], d, wy[k]);
    // Texel (ix - 1, iy - 1), the corner of a pixel's 4 x 4 block.
    const auto block = [&](uint32_t i) {
        return data + pitch * size_t(iys[i] - 1) + sizeof(glm::vec4) * size_t(ixs[i] - 1);
    };
    if (prefetchNext && kinds[0] == kInterior && kinds[N - 1] == kInterior && iys[0] + 3 < H) {
        // The next output row reads one history row more (iy + 3 here): ask for it now, a row ahead.
        const auto* first = block(0) + 4 * pitch;
        const auto* last = block(N - 1) + 4 * pitch + 4 * sizeof(glm::vec4);
        if (last > first && last - first < 64 * N) prefetchRange(first, size_t(last - first));
    }
    // Lanes k, k + 4, k + 8, ... as the 128-bit blocks of q[k], then to structure of arrays. `partial(i, texel)`
    // points `texel` at what lane i adds last, texel (ix, iy) (in its block, clamped to the frame near the edges; 0
    // where unused), and returns the lane's bicubic differences from it.
    const auto sample = [&](auto partial) {
        FloatVec q[4];
        for (uint32_t k = 0; k < 4; ++k) {
            const float* texels[kBlocks];
            FloatVec parts[kBlocks];
            for (uint32_t m = 0; m < kBlocks; ++m) parts[m] = partial(k + 4 * m, texels[m]);
            q[k] = hn::Add(blocksOf(texels), sumBlocks(parts));
        }
        transposeBlocks(q, hr, hg, hb, ha);
    };
    const auto inPlace = [&](uint32_t i, const float*& texel) {
        const unsigned char* b = block(i);
        texel = reinterpret_cast<const float*>(b + pitch + sizeof(glm::vec4));
        return bicubicBlock(b, pitch, hn::LoadDup128(d, texel), wx + 4 * i, wy, i);
    };
    if (hn::AllTrue(di, hn::Eq(kind, hn::Set(di, kInterior)))) {
        // Every lane reads its block in place (the common case under motion): no per-lane branches.
        sample(inPlace);
        return;
    }
    sample([&](uint32_t i, const float*& texel) {
        if (kinds[i] == kInterior) return inPlace(i, texel);
        alignas(16) static constexpr float kNothing[4] = {};
        texel = kinds[i] == kUnused ? kNothing : reinterpret_cast<const float*>(&history.at(ixs[i], iys[i]));
        if (kinds[i] != kEdge) return hn::Zero(d);  // an integer position or an unused lane: the texel alone
        // Near the frame's edge: the clamped taps, then the same arithmetic.
        alignas(64) glm::vec4 clampedBlock[4][4];
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) clampedBlock[j][k] = history.at(ixs[i] - 1 + k, iys[i] - 1 + j);
        return bicubicBlock(reinterpret_cast<const unsigned char*>(clampedBlock), sizeof(clampedBlock[0]),
                            hn::LoadDup128(d, texel), wx + 4 * i, wy, i);
    });
}

/// A tile whose region (the tile and its one-pixel border) holds one colour, the same bits everywhere, resolves to it:
/// every neighbourhood is flat, so the general path reads no history and returns each pixel's input, and its history
/// is that colour compressed (when the resolve compresses). Here that costs one pass of loads and comparisons over the
/// region and the two stores per pixel, without the YCoCg planes, the statistics, the motion dilation and the
/// per-pixel resolve. The motion still decides the noHistory count: if every motion vector of the region keeps every
/// pixel of the tile inside the frame (floating-point rounding is monotonic, so the extremes decide for all), no
/// pixel lacks history; otherwise, and for a colour or motion that is not finite or a region narrower than a vector,
/// this returns false having written nothing, and the general path takes the tile.
HWY_INLINE bool resolveOneColourTile(const TaaInputs& in, const Tile& t, const ImageView<glm::vec4>& out,
                                     const ImageView<glm::vec4>& history, Counts& counts) {
    const FloatTag d;
    const hn::RebindToSigned<FloatTag> di;
    const uint32_t N = kLanes, W = in.color.width, H = in.color.height;
    // The region's pixels inside the frame (the repeated edges copy them).
    const uint32_t cx0 = t.x0 == 0 ? 0 : t.x0 - 1, cx1 = std::min(t.x1 + 1, W);
    const uint32_t cy0 = t.y0 == 0 ? 0 : t.y0 - 1, cy1 = std::min(t.y1 + 1, H);
    if (cx1 - cx0 < N) return false;
    const glm::vec4 c0 = in.color.at(int(cx0), int(cy0));
    if (!isFinite(c0)) return false;
    // Four more pixels first (the other corners and the centre): most tiles that are not one colour stop here.
    const auto sameBits = [&](uint32_t x, uint32_t y) {
        return std::memcmp(&in.color.at(int(x), int(y)), &c0, sizeof(glm::vec4)) == 0;
    };
    if (!sameBits(cx1 - 1, cy0) || !sameBits(cx0, cy1 - 1) || !sameBits(cx1 - 1, cy1 - 1) ||
        !sameBits((cx0 + cx1) / 2, (cy0 + cy1) / 2))
        return false;
    // The pixels as they lie in memory, N / 4 to a vector: colour bits against c0 repeated, motion (x, y pairs) into
    // running extremes per lane, even lanes x and odd ones y.
    alignas(64) float pattern[4 * kLanes];  // c0, kLanes times: the output
    for (uint32_t i = 0; i < 4 * N; ++i) pattern[i] = c0[int(i % 4)];
    const auto c0Bits = hn::BitCast(di, hn::Load(d, pattern));
    auto same = hn::FirstN(di, N);
    FloatVec mvMin = hn::Set(d, kHuge), mvMax = hn::Set(d, -kHuge);
    FloatMask finite = hn::FirstN(d, N);
    for (uint32_t y = cy0; y < cy1; ++y) {
        const float* colorRow = &in.color.at(0, int(y)).x;
        const float* mvecRow = &in.mvec.at(0, int(y)).x;
        for (uint32_t x = cx0; x < cx1; x += N) {
            x = std::min(x, cx1 - N);  // the last vector overlaps the one before
            for (uint32_t k = 0; k < 4; ++k)
                same = hn::And(same, hn::Eq(hn::BitCast(di, hn::LoadU(d, colorRow + 4 * x + k * N)), c0Bits));
            for (uint32_t k = 0; k < 2; ++k) {
                const FloatVec m = hn::LoadU(d, mvecRow + 2 * x + k * N);
                finite = hn::And(finite, allFiniteVec(d, m));
                mvMin = hn::Min(mvMin, m);
                mvMax = hn::Max(mvMax, m);
            }
        }
        if (!hn::AllTrue(di, same)) return false;
    }
    if (!hn::AllTrue(d, finite)) return false;
    if (in.historyValid) {
        // The general path's previousPosition at the tile's extreme pixels and motion: the first and the last pixel
        // with the least and the greatest motion bound every pixel's position, so both inside the frame means all are.
        alignas(64) float lo[kLanes], hi[kLanes];
        hn::Store(mvMin, d, lo);
        hn::Store(mvMax, d, hi);
        glm::vec2 mn(lo[0], lo[1]), mx(hi[0], hi[1]), pos;
        for (uint32_t i = 2; i < N; ++i) {
            mn[int(i % 2)] = std::min(mn[int(i % 2)], lo[i]);
            mx[int(i % 2)] = std::max(mx[int(i % 2)], hi[i]);
        }
        if (!previousPosition(t.x0, t.y0, W, H, mn, pos) || !previousPosition(t.x1 - 1, t.y1 - 1, W, H, mx, pos))
            return false;
    } else {
        counts.noHistory += uint64_t(t.x1 - t.x0) * (t.y1 - t.y0);
    }
    // The output is the input colour; the history the colour the resolve works in (compressed or not), streamed as
    // the general path streams it.
    FloatVec hr = hn::Set(d, c0.x), hg = hn::Set(d, c0.y), hb = hn::Set(d, c0.z);
    if (in.compress) compressVec(d, hr, hg, hb);
    alignas(64) float historyPixels[4 * kLanes];
    hn::StoreInterleaved4(hr, hg, hb, hn::Set(d, c0.w), d, historyPixels);
    const uint32_t w = t.x1 - t.x0;
    for (uint32_t y = t.y0; y < t.y1; ++y)
        for (uint32_t x = 0; x < w; x += N) {
            const uint32_t n = std::min(N, w - x);
            storePacked(historyPixels, history.row(y) + t.x0 + x, n, true);
            storePacked(pattern, out.row(y) + t.x0 + x, n, false);
        }
    hwy::FlushStream();
    return true;
}

/// The tiled path. The 3x3 statistics and the motion dilation are separable: each current pixel is converted to
/// YCoCg once (not nine times), sums, minima, maxima and the longest vector are formed over rows, then over
/// columns, and the rest runs on vectors of kLanes pixels (8 on AVX2, 16 on AVX-512). The bicubic history is fetched
/// per pixel as rows of its 4 x 4 block (one 512-bit vector a row on AVX-512, two 256-bit ones on AVX2; vertical
/// weights first), reduced and transposed in registers. It computes what the reference kernel computes with FMA and
/// with refined hardware estimates of sqrt and of the divisions, so it agrees with it to a tolerance (a test checks
/// it) rather than to the bit; minima, maxima, comparisons, the clipping decision and the motion dilation are exact,
/// and every pixel runs the same arithmetic wherever it lies, so a constant image passes through exactly and integer
/// motion reprojects exactly. A tile with a non-finite colour or motion vector in reach runs the reference kernel
/// instead (it skips those samples); a tile of one colour is done by resolveOneColourTile where it can.
void ResolveTileTarget(const TaaInputs& in, const TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                       const ImageView<glm::vec4>& history, Counts& counts) {
    if (resolveOneColourTile(in, t, out, history, counts)) return;
    const ScratchLease lease;
    TileScratch& s = *lease;
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
            const glm::vec4 c = currentColor(in, int(sx), int(sy));
            const glm::vec2 m = mvecRow[sx];
            finite &= isFinite(c) & isFinite(m);
            alphaConstant &= c.w == alpha0;
            colorConstant &= glm::vec3(colorRow[sx]) == glm::vec3(color0);  // the input's rgb, as the vector loop
            const glm::vec4 v = toYCoCg(c);
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
            ok = hn::And(ok, hn::And(hn::Eq(a, a0), allFiniteVec(d, r, g, b, mx, my)));
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
                finite &= isFinite(c) & isFinite(mvecBase[rx]);
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
    const FloatVec huge = hn::Set(d, kHuge), negHuge = hn::Set(d, -kHuge);
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
    // The box of channel ch for the row's vector at x, from its bounds (makeClipBox with n = 9), as centre and half
    // extent floored at minExtent (flooredExtent; clipToBox); the inverse extent for the ratio is the refined
    // reciprocal, infinite for a flat channel of a black box, which pulls the point exactly onto the centre.
    const FloatVec minRelativeExtent = hn::Set(d, kMinRelativeExtent);
    const auto storeBox = [&](int ch, uint32_t x, FloatVec lo, FloatVec hi, FloatVec minExtent) {
        const FloatVec extent = hn::Max(hn::Mul(half, hn::Sub(hi, lo)), minExtent);
        hn::Store(hn::Mul(half, hn::Add(lo, hi)), d, &s.center[ch][x]);
        hn::Store(extent, d, &s.extent[ch][x]);
        hn::Store(hn::IfThenElse(hn::Gt(extent, zero), reciprocal(d, extent), infinity), d, &s.invExtent[ch][x]);
    };
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
            const FloatVec px = hn::Add(firstPlusLane(d, float(t.x0 + x)), hn::Mul(mvx, hn::Set(d, float(W))));
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
            // The box channel by channel (storeBox), luma first: its centre and extent give the floor of the
            // extents. A constant alpha's box is [alpha0, alpha0].
            FloatVec minExtent = zero;
            for (int ch = 0; ch < (alphaConstant ? 3 : 4); ++ch) {
                FloatVec sum = hn::LoadU(d, &s.rowSum[ch][y][x]), sumSq = hn::LoadU(d, &s.rowSumSq[ch][y][x]);
                for (uint32_t r = y + 1; r < y + 3; ++r) {
                    sum = hn::Add(sum, hn::LoadU(d, &s.rowSum[ch][r][x]));
                    sumSq = hn::Add(sumSq, hn::LoadU(d, &s.rowSumSq[ch][r][x]));
                }
                const FloatVec mn = boxMin[ch], mx = boxMax[ch];
                const FloatVec mean = hn::Mul(sum, ninth);
                const FloatVec var = hn::Max(hn::NegMulAdd(mean, mean, hn::Mul(sumSq, ninth)), zero);
                const FloatVec dev = hn::Mul(sigma, squareRoot(d, var));
                const FloatVec lo = hn::Min(hn::Max(hn::Sub(mean, dev), mn), mx);
                const FloatVec hi = hn::Min(hn::Max(hn::Add(mean, dev), mn), mx);
                if (ch == 0)  // flooredExtent(): the same operations, so the clipping decision is the reference's
                    minExtent = hn::Mul(minRelativeExtent, hn::Add(hn::Abs(hn::Mul(half, hn::Add(lo, hi))),
                                                                   hn::Mul(half, hn::Sub(hi, lo))));
                storeBox(ch, x, lo, hi, minExtent);
            }
            if (alphaConstant) storeBox(3, x, hn::Set(d, alpha0), hn::Set(d, alpha0), minExtent);
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
                const FloatMask keep = hn::And(resolveHistory, allFiniteVec(d, orr, og, ob, oa));
                orr = hn::IfThenElse(keep, orr, cr);
                og = hn::IfThenElse(keep, og, cgr);
                ob = hn::IfThenElse(keep, ob, cb);
                oa = hn::IfThenElse(keep, oa, ca);
            }
            // History streams: it is read again only next frame, long after it has left the caches, and streaming
            // skips the read-for-ownership of its lines. (Streaming the output too measured no gain.)
            storePixels(orr, og, ob, oa, historyRow + t.x0 + x, n, true);
            if (in.compress && !s.anyHistory[x]) {
                // Every lane resolved to its current colour: the output is the linear input (outputColor()).
                orr = lr;
                og = lg;
                ob = lb;
            } else if (in.compress) {
                // outputColor(): the linear input where the resolve returned the compressed input, else expanded.
                const FloatMask same =
                    hn::And(hn::And(hn::Eq(orr, cr), hn::Eq(og, cgr)), hn::And(hn::Eq(ob, cb), hn::Eq(oa, ca)));
                expandVec(d, orr, og, ob);
                const FloatMask finiteOut = allFiniteVec(d, orr, og, ob, oa);
                orr = hn::IfThenElse(same, lr, hn::IfThenElseZero(finiteOut, orr));
                og = hn::IfThenElse(same, lg, hn::IfThenElseZero(finiteOut, og));
                ob = hn::IfThenElse(same, lb, hn::IfThenElseZero(finiteOut, ob));
                oa = hn::IfThenElse(same, ca, hn::IfThenElseZero(finiteOut, oa));
            }
            storePixels(orr, og, ob, oa, outRow + t.x0 + x, n, false);
            counts.clipped += hn::CountTrue(d, clipped);
        }
    }
    hwy::FlushStream();  // order the streaming stores before the frame's end
}

uint32_t LanesTarget() {
    return kLanes;
}

}  // namespace loom::taa::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace loom::taa {

HWY_EXPORT(ResolveTileTarget);
HWY_EXPORT(LanesTarget);

void resolveTileVector(const TaaInputs& in, const TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                       const ImageView<glm::vec4>& history, Counts& counts) {
    HWY_DYNAMIC_DISPATCH(ResolveTileTarget)(in, p, t, out, history, counts);
}

uint32_t vectorLanes() {
    return HWY_DYNAMIC_DISPATCH(LanesTarget)();
}

}  // namespace loom::taa
#endif  // HWY_ONCE
