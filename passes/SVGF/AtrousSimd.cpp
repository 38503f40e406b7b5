// Compiled once per Highway target (foreach_target) and dispatched at run time to the best one the CPU has:
// AVX2 on the x86-64-v3 baseline, AVX-512 where present.
#include "AtrousSimd.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "SVGFKernels.h"
#include "loom/Parallel.h"

#ifndef LOOM_ATROUS_SIMD_SHARED
#define LOOM_ATROUS_SIMD_SHARED
namespace loom::svgf::simd::detail {

// Packing runs over tiles of 64 x 64 pixels. A level runs over tiles of 128 x 64: with the taps' rows and columns
// around them its ten planes stay in L2 for steps up to 8, and the rows of a tile, twice as long as in 64 x 64 tiles,
// pay their per-row costs (prefetches, a new tap row from memory) over twice as many vectors (same-process A/B in
// the pipeline: the levels 0.88-0.92x of 64 x 64 tiles; 128 x 32 and 256 x 32 measured alike, longer rows slower).
constexpr uint32_t kTileSize = 64;
constexpr uint32_t kLevelTileWidth = 128, kLevelTileHeight = 64;
static_assert(kSkipTile % kMaxLanes == 0, "a vector lies in one low-variance tile");
// The B3 weights b(0), b(1), b(2) = 6/16, 4/16, 1/16 as exponents, -log2 b: the tap weight h(i, j) = b(i) b(j)
// joins the edge-stopping exponent as kB3Exponent[|i|] + kB3Exponent[|j|] (an addend of an FMA, free).
constexpr float kB3Exponent[3] = {1.4150374992788438f, 2.f, 4.f};
// Screen distances of the taps |(i, j)| for |i|, |j| in 0..2, as indices into the five distinct non-zero ones.
constexpr float kTapDistance[5] = {1.f, 1.41421356237f, 2.f, 2.2360679775f, 2.82842712475f};
constexpr int kDistanceIndex[3][3] = {{-1, 0, 2}, {0, 1, 3}, {2, 3, 4}};

/// Constants of one level shared by all its pixels.
struct LevelConstants {
    int step;
    float phiColor, phiDepthStep;
    float phiNormal;
    float series[4];  // -phi * log2(e) / k, k = 1..4: the normal weight's exponent in powers of two, negated
};

inline LevelConstants makeConstants(int step, const AtrousParams& p) {
    LevelConstants c{};
    c.step = step;
    c.phiColor = std::max(0.f, p.phiColor);
    c.phiDepthStep = std::max(0.f, p.phiDepth) * float(step);
    c.phiNormal = std::max(0.f, p.phiNormal);
    normalSeriesTerms(c.phiNormal, c.series);
    for (float& term : c.series) term = -term;  // the exponent is accumulated negative (maskedExp2)
    return c;
}

}  // namespace loom::svgf::simd::detail
#endif  // LOOM_ATROUS_SIMD_SHARED

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "AtrousSimd.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // must come first: it includes this file once per target
#include <hwy/highway.h>
#include <hwy/cache_control.h>
#include <hwy/contrib/math/math-inl.h>
#include "SimdCommon-inl.h"
#include "loom/simd/KernelMath-inl.h"
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace loom::svgf::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;
using namespace detail;

using D = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<D>;
using V = hn::Vec<D>;

/// q(g) ~ 2^g on [0, 1) (loom/KernelMath.h): sqrt(2) p(g - 1/2) for the degree-4 minimax p of 2^f on [-0.5, 0.5]
/// that varianceExp2Neg uses, expanded in powers of g, so its relative error is p's (<= 2.7e-6 in float).
using ::loom::simd::HWY_NAMESPACE::exp2Unit;

/// 2^u for u <= 0 where `use`, exactly 0 elsewhere: 2^floor(u) q(u - floor(u)), u clamped to -kWeightMaxExponent
/// (a weight stays a normal float, >= 2^-100). The exponent is accumulated negative (every scale and constant of
/// the tap's sum carries the sign), so no negation is left to do here. On AVX-512 one vreduceps gives
/// u - floor(u) and one vscalefps multiplies by 2^floor(u) and applies the mask; AVX2 spends six operations there
/// (floor, subtraction, conversion, shift, addition, blend). Both are exact, so the two targets give the same bits.
/// Against the earlier form (2^-round(t) p(round(t) - t), then negated for vscalefps): a level 0.97-0.98x, same
/// process, and the fast path's largest difference from the reference 7.5e-6 -> 3.7e-6.
HWY_INLINE V maskedExp2(D d, hn::Mask<D> use, V u) {
    u = hn::Max(u, hn::Set(d, -kWeightMaxExponent));
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
    const V g{_mm512_reduce_ps(u.raw, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC)};
    return V{_mm512_maskz_scalef_ps(use.raw, exp2Unit(d, g).raw, u.raw)};
#else
    const DI di;
    const V n = hn::Floor(u);
    const V q = exp2Unit(d, hn::Sub(u, n));
    const auto e = hn::ShiftLeft<23>(hn::ConvertTo(di, n));  // 2^n: n added to q's exponent field
    return hn::IfThenElseZero(use, hn::BitCast(d, hn::Add(hn::BitCast(di, q), e)));
#endif
}

/// e plus the normal weight's exponent (in powers of two, <= 0) for the centre and tap normals.
template <bool kSeries>
HWY_INLINE V addNormalExponent(D d, V e, V ncx, V ncy, V ncz, V nqx, V nqy, V nqz, const LevelConstants& c) {
    // The compiler contracts the dot product into FMAs (this file keeps GCC's default contraction), so it may differ
    // from the reference's glm::dot by a rounding: at phi = 128 that is up to 1e-5 in a weight, inside the fast
    // path's tolerance. Every target contracts it alike, so they still agree to the bit.
    const V dot = hn::Add(hn::Add(hn::Mul(ncx, nqx), hn::Mul(ncy, nqy)), hn::Mul(ncz, nqz));
    if constexpr (kSeries) {
        // d = 1 - dot is exact for dot in [0.5, 2]. A dot just above 1 (rounding) gives the reference's weight
        // above 1 too; beyond 1.01 (non-unit normals) it is capped, so weights stay finite.
        const V dd = hn::Max(hn::Sub(hn::Set(d, 1.f), dot), hn::Set(d, -0.01f));
        V u = hn::MulAdd(dd, hn::Set(d, c.series[3]), hn::Set(d, c.series[2]));
        u = hn::MulAdd(dd, u, hn::Set(d, c.series[1]));
        u = hn::MulAdd(dd, u, hn::Set(d, c.series[0]));
        return hn::MulAdd(dd, u, e);
    } else {
        const V lg = hn::Log2(d, hn::Max(dot, hn::Set(d, 1e-30f)));
        return hn::MulAdd(hn::Set(d, c.phiNormal), lg, e);
    }
}

/// What every tap of a centre vector compares against.
struct Centre {
    V z, l, nx, ny, nz, invPhiL;
    V invPhiZ;  ///< -log2(e) / (phiZ + eps), for a tap at distance 1 (invPhiL is negative too)
};
struct Sums {
    V r, g, b, v, w;
};
struct TapContext {
    const GuidePlanes& G;
    const SignalPlanes& in;
    const LevelConstants& c;
    int W, H, y;
    ptrdiff_t o, stride;
    ptrdiff_t plane;  ///< floats from one plane to the next (planesEvenlySpaced; taken as G.dz - G.z, which
                      ///< measured 0.97x of a level against the same value from PlaneLayout::planeSize())
};

template <bool kSeries, bool kVariance, bool kPadded, int I, int J>
HWY_INLINE void accumulateTap(D d, const TapContext& t, ptrdiff_t row, const Centre& k, Sums& s) {
    constexpr int ai = I < 0 ? -I : I, aj = J < 0 ? -J : J;
    if constexpr (I == 0 && J == 0) {
        return;  // the centre tap is accumulated by the caller
    } else {
        // A tap column off the frame for every pixel of the row lies past the planes' margins unless kPadded (the
        // margins cover 2 step columns): there its misses give weight 0 with no test. The per-tap test costs
        // where it is taken: the unpadded levels (steps beyond the frame's width) run at 0.91-0.93x the speed.
        if constexpr (!kPadded)
            if (ai * t.c.step >= t.W) return;
        const ptrdiff_t q = row + I * t.c.step;
        // Every plane from two pointers and multiples of the plane spacing (x86 addressing takes p + P * 1, 2, 4
        // or 8 in the load itself), rather than nine plane pointers, more than the general registers hold.
        const float* pz = t.G.z + q;
        const float* ps = t.in.r + q;
        const ptrdiff_t P = t.plane;
        const V zq = hn::LoadU(d, pz);
        const auto use = hn::Ge(zq, hn::Zero(d));  // a mask register from here: zq is not needed after the depth term
        constexpr int distance = kDistanceIndex[aj][ai];
        V depth = hn::Abs(hn::Sub(k.z, zq));
        if constexpr (distance != 0) depth = hn::Mul(depth, hn::Set(d, 1.f / kTapDistance[distance]));
        V e = hn::MulAdd(depth, k.invPhiZ, hn::Set(d, -(kB3Exponent[ai] + kB3Exponent[aj])));
        e = hn::MulAdd(hn::Abs(hn::Sub(k.l, hn::LoadU(d, ps + 4 * P))), k.invPhiL, e);
        e = addNormalExponent<kSeries>(d, e, k.nx, k.ny, k.nz, hn::LoadU(d, pz + 2 * P), hn::LoadU(d, pz + 3 * P),
                                       hn::LoadU(d, pz + 4 * P), t.c);
        const V w = maskedExp2(d, use, e);
        s.r = hn::MulAdd(w, hn::LoadU(d, ps), s.r);
        s.g = hn::MulAdd(w, hn::LoadU(d, ps + P), s.g);
        s.b = hn::MulAdd(w, hn::LoadU(d, ps + 2 * P), s.b);
        if constexpr (kVariance) s.v = hn::MulAdd(hn::Mul(w, w), hn::LoadU(d, ps + 3 * P), s.v);
        s.w = hn::Add(s.w, w);
    }
}

template <bool kSeries, bool kVariance, bool kPadded, int J>
HWY_INLINE void accumulateRow(D d, const TapContext& t, const Centre& k, Sums& s) {
    const int qy = t.y + J * t.c.step;
    if (qy < 0 || qy >= t.H) return;  // off-frame rows: uniform for the whole vector
    const ptrdiff_t row = t.o + ptrdiff_t(J) * t.c.step * t.stride;
    accumulateTap<kSeries, kVariance, kPadded, -2, J>(d, t, row, k, s);
    accumulateTap<kSeries, kVariance, kPadded, -1, J>(d, t, row, k, s);
    accumulateTap<kSeries, kVariance, kPadded, 0, J>(d, t, row, k, s);
    accumulateTap<kSeries, kVariance, kPadded, 1, J>(d, t, row, k, s);
    accumulateTap<kSeries, kVariance, kPadded, 2, J>(d, t, row, k, s);
}

/// Which images the remodulation of pixel x's group on row y reads (Remodulation::groups).
HWY_INLINE uint8_t remodulationGroupReads(const Remodulation& r, uint32_t x, uint32_t y) {
    return r.groups ? r.groups[size_t(y) * r.groupsPerRow + x / kRemodulationGroup] : kReadsAll;
}

/// Prefetches pixels x0 .. x1 - 1 of row y of the remodulation's inputs (those their groups read).
HWY_INLINE void prefetchRemodulation(const Remodulation& r, uint32_t x0, uint32_t x1, uint32_t y) {
    const ModulateViews& m = r.views;
    for (uint32_t x = x0; x < x1; x += 4) {  // 4 RGBA32F pixels to a cache line
        const uint8_t reads = remodulationGroupReads(r, x, y);
        if (reads & kReadsColour) hwy::Prefetch(&m.color.at(x, y));
        if (reads & kReadsAlbedo) hwy::Prefetch(&m.albedo.at(x, y));
        if (m.emission.data && (reads & kReadsEmission)) hwy::Prefetch(&m.emission.at(x, y));
        if (r.split) hwy::Prefetch(&m.filtered0.at(x, y));
        if ((x & 7) == 0) hwy::Prefetch(&m.linearZ.at(x, y));
    }
}

/// The remodulated result of pixels x0 .. x0 + count - 1 of row y from the level's rgb.
HWY_INLINE void remodulateStore(D d, const Remodulation& modulation, uint32_t x0, uint32_t y, uint32_t count, V r, V g,
                                V b) {
    const ModulateViews& m = modulation.views;
    const size_t N = hn::Lanes(d);
    if (count < N) {
        HWY_ALIGN float lanes[3][kMaxLanes];
        hn::Store(r, d, lanes[0]);
        hn::Store(g, d, lanes[1]);
        hn::Store(b, d, lanes[2]);
        for (uint32_t k = 0; k < count; ++k) {
            const uint32_t x = x0 + k;
            const glm::vec3 emission = m.emission.data ? glm::vec3(m.emission.at(x, y)) : glm::vec3(0.f);
            glm::vec3 illum(lanes[0][k], lanes[1][k], lanes[2][k]);
            if (modulation.split) illum = glm::vec3(m.filtered0.at(x, y)) + illum;  // modulatePixel's order
            m.dst.at(x, y) = remodulate(illum, m.color.at(x, y), m.albedo.at(x, y), emission, m.linearZ.at(x, y).x);
        }
        return;
    }
    const V zero = hn::Zero(d), one = hn::Set(d, 1.f), minAlbedo = hn::Set(d, kMinAlbedo),
            maxAlbedo = hn::Set(d, kMaxAlbedo);
    // Only the images the group needs (Remodulation::groups): the colour where it has a miss or an alpha other than
    // 1, the albedo where it has a hit, the emission where a hit has some. The images skipped are zero here, which
    // the operations below never use: no hit takes the albedo's place, no miss the colour's, alpha 1 is the colour's.
    const uint8_t reads = remodulationGroupReads(modulation, x0, y);
    V cr = zero, cg = zero, cb = zero, ca = one, ar = zero, ag = zero, ab = zero, aa, er = zero, eg = zero, eb = zero,
      ea, z, dz;
    if (reads & kReadsColour) hn::LoadInterleaved4(d, &m.color.at(x0, y).x, cr, cg, cb, ca);
    if (reads & kReadsAlbedo) hn::LoadInterleaved4(d, &m.albedo.at(x0, y).x, ar, ag, ab, aa);
    if (m.emission.data && (reads & kReadsEmission)) hn::LoadInterleaved4(d, &m.emission.at(x0, y).x, er, eg, eb, ea);
    if (modulation.split) {
        // modulatePixel's filtered0 + filtered1: the other signal first.
        V sr, sg, sb, sa;
        hn::LoadInterleaved4(d, &m.filtered0.at(x0, y).x, sr, sg, sb, sa);
        r = hn::Add(sr, r);
        g = hn::Add(sg, g);
        b = hn::Add(sb, b);
    }
    hn::LoadInterleaved2(d, &m.linearZ.at(x0, y).x, z, dz);
    const auto hit = hn::Ge(z, zero);
    // As remodulate(): illum * clamp(finiteOrZero(albedo), kMinAlbedo, kMaxAlbedo) + finiteOrZero(emission) on hits,
    // the colour with non-finite channels as 0 on misses; alpha is the colour's (1 if not finite).
    auto channel = [&](V illum, V c, V a, V e) HWY_ATTR {
        a = hn::IfThenElseZero(hn::IsFinite(a), a);
        a = hn::IfThenElse(hn::Gt(a, minAlbedo), a, minAlbedo);
        a = hn::IfThenElse(hn::Lt(a, maxAlbedo), a, maxAlbedo);
        const V lit = hn::Add(hn::Mul(illum, a), hn::IfThenElseZero(hn::IsFinite(e), e));
        return hn::IfThenElse(hit, lit, hn::IfThenElseZero(hn::IsFinite(c), c));
    };
    // Streamed: the next pass reads the output long after this level has gone through the caches (same-process
    // A/B: the last level 0.89-0.95x, and the next pass, TAA, 0.91-0.93x).
    streamInterleaved4(d, channel(r, cr, ar, er), channel(g, cg, ag, eg), channel(b, cb, ab, eb),
                       hn::IfThenElse(hn::IsFinite(ca), ca, one), &m.dst.at(x0, y).x);
}

/// One level's result r, g, b, v for a centre vector (rc .. lc: its planes) that has a hit among its lanes: the
/// blurred variance's edge-stopping scales, the 25 taps, the normalised sums; miss lanes, and pixels whose every
/// weight vanished (degenerate normal), keep their input.
template <bool kSeries, bool kVariance, bool kPadded>
HWY_INLINE void weighCentre(D d, const TapContext& t, V zc, V dzc, V ncx, V ncy, V ncz, V rc, V gc, V bc, V vc, V lc,
                            V& r, V& g, V& b, V& v) {
    const V zero = hn::Zero(d);
    constexpr float blurKernel[2][2] = {{1.f / 4.f, 1.f / 8.f}, {1.f / 8.f, 1.f / 16.f}};
    // 3x3 Gaussian of the variance over in-frame, non-miss pixels (off-frame columns are misses).
    V num = zero, den = zero;
    for (int j = -1; j <= 1; ++j) {
        const int qy = t.y + j;
        if (qy < 0 || qy >= t.H) continue;
        for (int i = -1; i <= 1; ++i) {
            const ptrdiff_t q = t.o + j * t.stride + i;
            const auto m = hn::Ge(hn::LoadU(d, t.G.z + q), zero);
            const V k = hn::Set(d, blurKernel[i < 0 ? -i : i][j < 0 ? -j : j]);
            num = hn::MulAdd(k, hn::IfThenElseZero(m, hn::LoadU(d, t.in.v + q)), num);
            den = hn::Add(den, hn::IfThenElseZero(m, k));
        }
    }
    const V blurred = hn::IfThenElseZero(hn::Gt(den, zero), hn::Div(num, hn::Max(den, hn::Set(d, 1e-30f))));
    const V sigma = hn::Sqrt(hn::Max(blurred, zero));
    const V log2e = hn::Set(d, -kWeightLog2e);  // negative: the exponents are summed negative
    const V eps = hn::Set(d, kAtrousEpsilon);
    // Inverse edge-stopping scales, pre-multiplied by log2(e) so the weight is one power of two.
    const V invPhiL = hn::Div(log2e, hn::MulAdd(hn::Set(d, t.c.phiColor), sigma, eps));
    const V phiZ = hn::Mul(hn::Set(d, t.c.phiDepthStep), dzc);
    // log2(e) / (phiZ |(i, j)| + eps) as log2(e) / (phiZ + eps) / |(i, j)|: one division instead of five, and the
    // tap divides its depth difference by its constant |(i, j)| (one register for all five distances: the tap loop
    // is short of registers; 0.975x of a level against five scales held per centre).
    // They differ by eps (1 - |(i, j)|) / (|(i, j)| (phiZ + eps)) relative, below 1e-6 for phiZ >= 1e-4;
    // only phiZ ~ eps (a zero depth derivative) moves the already enormous exponent of a depth step.
    const V invPhiZ1 = hn::Div(log2e, hn::Add(phiZ, eps));

    // Centre tap: no depth or luminance difference, only its normal with itself.
    const V w =
        maskedExp2(d, hn::Ge(zc, zero),
                   addNormalExponent<kSeries>(d, hn::Set(d, -2.f * kB3Exponent[0]), ncx, ncy, ncz, ncx, ncy, ncz, t.c));

    // The 24 other taps, unrolled: each tap's B3 weight and distance are compile-time constants.
    const Centre centre{zc, lc, ncx, ncy, ncz, invPhiL, invPhiZ1};
    Sums sums{hn::Mul(w, rc), hn::Mul(w, gc), hn::Mul(w, bc), hn::Mul(hn::Mul(w, w), vc), w};
    accumulateRow<kSeries, kVariance, kPadded, -2>(d, t, centre, sums);
    accumulateRow<kSeries, kVariance, kPadded, -1>(d, t, centre, sums);
    accumulateRow<kSeries, kVariance, kPadded, 0>(d, t, centre, sums);
    accumulateRow<kSeries, kVariance, kPadded, 1>(d, t, centre, sums);
    accumulateRow<kSeries, kVariance, kPadded, 2>(d, t, centre, sums);
    // Miss centres, and pixels whose every weight vanished (degenerate normal), keep their input.
    const auto keep = hn::Or(hn::Lt(zc, zero), hn::Not(hn::Gt(sums.w, hn::Set(d, 1e-30f))));
    const V inv = hn::Div(hn::Set(d, 1.f), hn::Max(sums.w, hn::Set(d, 1e-30f)));
    r = hn::IfThenElse(keep, rc, hn::Mul(sums.r, inv));
    g = hn::IfThenElse(keep, gc, hn::Mul(sums.g, inv));
    b = hn::IfThenElse(keep, bc, hn::Mul(sums.b, inv));
    if constexpr (kVariance) v = hn::IfThenElse(keep, vc, hn::Mul(hn::Mul(sums.v, inv), inv));
}

template <bool kSeries, bool kVariance, bool kPadded>
void filterRows(const PlaneLayout& L, const GuidePlanes& G, const SignalPlanes& in, const LevelOutputs& out,
                const LevelConstants& c, const Tile& t) {
    const D d;
    const size_t N = hn::Lanes(d);
    const int W = int(L.width), H = int(L.height);
    const ptrdiff_t stride = ptrdiff_t(L.stride);
    const V zero = hn::Zero(d);

    for (uint32_t y = t.y0; y < t.y1; ++y) {
        // The remodulation's inputs are read once, in short row segments of a tile: prefetch the next row's while
        // this one is filtered (the hardware prefetchers do not follow tiles across rows).
        if (out.modulate.views.dst.data && y + 1 < t.y1) prefetchRemodulation(out.modulate, t.x0, t.x1, y + 1);
        // Likewise the one tap row the next output row reads first (y + 1 + 2 step), margins included.
        if (y + 1 < t.y1 && int(y) + 1 + 2 * c.step < H) {
            const size_t row = L.offset(0, y + 1 + 2 * uint32_t(c.step));
            const ptrdiff_t from = ptrdiff_t(t.x0) - 2 * c.step, to = ptrdiff_t(t.x1) + 2 * c.step;
            for (const float* plane : {G.z, G.nx, G.ny, G.nz, in.r, in.g, in.b, in.v, in.l})
                for (ptrdiff_t x = from; x < to; x += 16) hwy::Prefetch(plane + ptrdiff_t(row) + x);
        }
        // And the next row's depth derivatives, which only centres read (no tap brings them in): without this the
        // first load of every centre vector waited on memory (a sampling profile put 12 % of the level there).
        if (y + 1 < t.y1) {
            const float* dz = G.dz + L.offset(0, y + 1);
            for (uint32_t x = t.x0; x < t.x1; x += 16) hwy::Prefetch(dz + x);
        }
        for (uint32_t x0 = t.x0; x0 < t.x1; x0 += uint32_t(N)) {
            const size_t o = L.offset(x0, y);
            const V zc = hn::LoadU(d, G.z + o);
            const V dzc = hn::LoadU(d, G.dz + o);
            const V ncx = hn::LoadU(d, G.nx + o), ncy = hn::LoadU(d, G.ny + o), ncz = hn::LoadU(d, G.nz + o);
            const V rc = hn::LoadU(d, in.r + o), gc = hn::LoadU(d, in.g + o), bc = hn::LoadU(d, in.b + o);
            const V vc = hn::LoadU(d, in.v + o), lc = hn::LoadU(d, in.l + o);

            // A vector of misses only (sky, or the margin past the frame's right edge) keeps its input, as every
            // miss centre does in weighCentre: nothing to weigh.
            // So does a vector of a low-variance tile (x0 is a multiple of N, which divides kSkipTile).
            V r = rc, g = gc, b = bc, v = kVariance ? vc : zero;
            const bool skipped = out.skipTiles && out.skipTiles[(y / kSkipTile) * out.skipTilesPerRow + x0 / kSkipTile];
            if (!skipped && !hn::AllTrue(d, hn::Lt(zc, zero)))
                weighCentre<kSeries, kVariance, kPadded>(
                    d, TapContext{G, in, c, W, H, int(y), ptrdiff_t(o), stride, G.dz - G.z}, zc, dzc, ncx, ncy, ncz, rc,
                    gc, bc, vc, lc, r, g, b, v);

            if (out.planes.r) {
                // Lanes past the frame's right edge have miss centres: they store the margin's zeros back.
                hn::StoreU(r, d, out.planes.r + o);
                hn::StoreU(g, d, out.planes.g + o);
                hn::StoreU(b, d, out.planes.b + o);
                hn::StoreU(v, d, out.planes.v + o);
                hn::StoreU(luminanceFma(d, r, g, b), d, out.planes.l + o);
            }
            const uint32_t count = std::min<uint32_t>(uint32_t(N), t.x1 - x0);
            if (out.modulate.views.dst.data) remodulateStore(d, out.modulate, x0, y, count, r, g, b);
            for (const ImageView<glm::vec4>& image : out.image) {
                if (!image.data) continue;
                float* px = &image.at(x0, y).x;
                if (count == N) {
                    streamInterleaved4(d, r, g, b, v, px);  // as the remodulated output
                } else {
                    HWY_ALIGN float lanes[4][kMaxLanes];
                    hn::Store(r, d, lanes[0]);
                    hn::Store(g, d, lanes[1]);
                    hn::Store(b, d, lanes[2]);
                    hn::Store(v, d, lanes[3]);
                    for (uint32_t k = 0; k < count; ++k)
                        for (int ch = 0; ch < 4; ++ch) px[4 * k + ch] = lanes[ch][k];
                }
            }
        }
    }
    hwy::FlushStream();  // order the streamed images before the level is reported done
}

void PackGuideTarget(const PlaneLayout& L, ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal,
                     const GuidePlanes& guide) {
    const struct {
        const PlaneLayout& L;
        ImageView<const glm::vec2> linearZ;
        ImageView<const glm::vec4> normal;
        const GuidePlanes& G;
    } job{L, linearZ, normal, guide};
    parallelFor2D(
        L.width, L.height,
        [j = &job](const Tile& t) HWY_ATTR {
            const auto& [L, linearZ, normal, G] = *j;
            const D d;
            const uint32_t N = uint32_t(hn::Lanes(d));
            for (uint32_t y = t.y0; y < t.y1; ++y) {
                const glm::vec2* zRow = linearZ.row(y);
                const glm::vec4* nRow = normal.row(y);
                uint32_t x = t.x0;
                for (; x + N <= t.x1; x += N) {
                    V z, dz, nx, ny, nz, nw;
                    hn::LoadInterleaved2(d, &zRow[x].x, z, dz);
                    hn::LoadInterleaved4(d, &nRow[x].x, nx, ny, nz, nw);
                    storeGuide(d, G, L.offset(x, y), z, dz, nx, ny, nz);
                }
                for (; x < t.x1; ++x) packGuidePixel(L, G, x, y, zRow[x], nRow[x]);
            }
        },
        kTileSize);
}

void PackSignalTarget(const PlaneLayout& L, ImageView<const glm::vec4> src, const SignalPlanes& signal) {
    const struct {
        const PlaneLayout& L;
        ImageView<const glm::vec4> src;
        const SignalPlanes& S;
    } job{L, src, signal};
    parallelFor2D(
        L.width, L.height,
        [j = &job](const Tile& t) HWY_ATTR {
            const auto& [L, src, S] = *j;
            const D d;
            const uint32_t N = uint32_t(hn::Lanes(d));
            for (uint32_t y = t.y0; y < t.y1; ++y) {
                const glm::vec4* row = src.row(y);
                uint32_t x = t.x0;
                for (; x + N <= t.x1; x += N) {
                    V r, g, b, v;
                    hn::LoadInterleaved4(d, &row[x].x, r, g, b, v);
                    storeSignal(d, S, L.offset(x, y), r, g, b, v);
                }
                for (; x < t.x1; ++x) packSignalPixel(L, S, x, y, row[x]);
            }
        },
        kTileSize);
}

void FilterLevelTarget(const PlaneLayout& L, const GuidePlanes& G, const SignalPlanes& in, const LevelOutputs& out,
                       int step, const AtrousParams& params) {
    if (!planesEvenlySpaced(L, G, in))
        throw std::invalid_argument(
            "filterLevel: the guide's and the input signal's planes must each lie "
            "planeSize() floats apart, in member order (as AtrousFilter allocates them)");
    const LevelConstants c = makeConstants(step, params);
    const bool series = c.phiNormal >= kWeightSeriesMinPhi;
    // Tap columns reach 2 step past a vector's lanes; the margins cover that unless the step exceeds the frame.
    const bool padded = 2 * int64_t(step) <= int64_t(L.margin);
    using Rows = void (*)(const PlaneLayout&, const GuidePlanes&, const SignalPlanes&, const LevelOutputs&,
                          const LevelConstants&, const Tile&);
    // [series][variance][padded]
    static constexpr Rows kRows[2][2][2] = {
        {{&filterRows<false, false, false>, &filterRows<false, false, true>},
         {&filterRows<false, true, false>, &filterRows<false, true, true>}},
        {{&filterRows<true, false, false>, &filterRows<true, false, true>},
         {&filterRows<true, true, false>, &filterRows<true, true, true>}}};
    // One pointer captured: the std::function holds it without allocating.
    const struct {
        const PlaneLayout& L;
        const GuidePlanes& G;
        const SignalPlanes& in;
        const LevelOutputs& out;
        const LevelConstants& c;
        Rows rows;
    } job{L, G, in, out, c, kRows[series][out.variance][padded]};
    parallelFor2D(
        L.width, L.height, [j = &job](const Tile& t) { j->rows(j->L, j->G, j->in, j->out, j->c, t); },
        kLevelTileWidth, kLevelTileHeight);
}

int64_t TargetBits() {
    return HWY_TARGET;
}

}  // namespace loom::svgf::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace loom::svgf::simd {

using namespace detail;

HWY_EXPORT(PackGuideTarget);
HWY_EXPORT(PackSignalTarget);
HWY_EXPORT(FilterLevelTarget);
HWY_EXPORT(TargetBits);

PlaneLayout makeLayout(uint32_t width, uint32_t height, int maxStep) {
    PlaneLayout L;
    L.width = width;
    L.height = height;
    const uint64_t reach = std::min<uint64_t>(2 * uint64_t(std::max(maxStep, 1)), std::max(width, 1u));
    L.margin = uint32_t(alignUp(std::max<uint64_t>(reach, kMaxLanes), kMaxLanes));
    L.stride = alignUp(size_t(L.margin) * 2 + width + kMaxLanes, kMaxLanes);
    return L;
}

void packGuide(const PlaneLayout& L, ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal,
               const GuidePlanes& G) {
    HWY_DYNAMIC_DISPATCH(PackGuideTarget)(L, linearZ, normal, G);
}

void packSignal(const PlaneLayout& L, ImageView<const glm::vec4> src, const SignalPlanes& S) {
    HWY_DYNAMIC_DISPATCH(PackSignalTarget)(L, src, S);
}

void filterLevel(const PlaneLayout& L, const GuidePlanes& G, const SignalPlanes& in, const LevelOutputs& out, int step,
                 const AtrousParams& params) {
    HWY_DYNAMIC_DISPATCH(FilterLevelTarget)(L, G, in, out, step, params);
}

std::string targetName() {
    return hwy::TargetName(HWY_DYNAMIC_DISPATCH(TargetBits)());
}

}  // namespace loom::svgf::simd
#endif  // HWY_ONCE
