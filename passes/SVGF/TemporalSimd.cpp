// Compiled once per Highway target (foreach_target) and dispatched at run time, as AtrousSimd.cpp.
#include "TemporalSimd.h"

#include <algorithm>
#include <atomic>

#include "loom/Parallel.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "TemporalSimd.cpp"
// clang-format off
#include <hwy/foreach_target.h>  // must come first: it includes this file once per target
#include <hwy/highway.h>
#include <hwy/cache_control.h>
#include "SimdCommon-inl.h"
#include "loom/simd/KernelMath-inl.h"
#include "loom/simd/LaneIndex-inl.h"
#include "loom/simd/Stream-inl.h"
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace loom::svgf::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;
using ::loom::simd::HWY_NAMESPACE::firstPlusLane;
using ::loom::simd::HWY_NAMESPACE::luminanceSum;
using ::loom::simd::HWY_NAMESPACE::streamCopy;

using D = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<D>;
using DU = hn::RebindToUnsigned<D>;
using V = hn::Vec<D>;
using M = hn::Mask<D>;

/// maxf / minf of SVGFKernels.h: a > b ? a : b, a < b ? a : b (the same lanes win for NaN).
HWY_INLINE V maxOf(V a, V b) {
    return hn::IfThenElse(hn::Gt(a, b), a, b);
}
HWY_INLINE V minOf(V a, V b) {
    return hn::IfThenElse(hn::Lt(a, b), a, b);
}

/// a * (1 - t) + b * t, as glm::mix.
HWY_INLINE V mixOf(D d, V a, V b, V t) {
    return hn::Add(hn::Mul(a, hn::Sub(hn::Set(d, 1.f), t)), hn::Mul(b, t));
}

/// needsSpatialVariance lane-wise: a hit whose history is shorter than kSpatialVarianceFrames.
HWY_INLINE M needsSpatialVarianceVec(D d, V z, V length) {
    return hn::AndNot(hn::Ge(length, hn::Set(d, kSpatialVarianceFrames)), hn::Ge(z, hn::Zero(d)));
}

/// Where the N lanes read tap k (0..3) of their 2x2 reprojection footprint in last frame's fields: side by side from
/// texel (c0 + (k & 1), r0 + (k >> 1)) when every lane has the same integer offset and the footprint lies inside the
/// frame (a static camera, a pan), else each lane at its own texel (qx, qy), clamped into the frame (motion that
/// varies across the vector, a footprint at the frame's edge: the taps outside are invalid anyway).
struct Footprint {
    bool contiguous = true;
    uint32_t c0 = 0, r0 = 0;
    hn::Vec<DI> qx[4], qy[4];
};

/// Channels 0 .. C - 1 of tap k of every lane from an image of C floats per texel; gathered, only the first kUsed
/// (the others are left unspecified).
template <int kUsed, int C, class T>
HWY_INLINE void loadTap(D d, const Footprint& f, int k, ImageView<T> image, V (&out)[C]) {
    static_assert(kUsed <= C, "a texel has C channels");
    if (f.contiguous) {
        const float* p = reinterpret_cast<const float*>(&image.at(f.c0 + uint32_t(k & 1), f.r0 + uint32_t(k >> 1)));
        if constexpr (C == 1) {
            out[0] = hn::LoadU(d, p);
        } else if constexpr (C == 2) {
            hn::LoadInterleaved2(d, p, out[0], out[1]);
        } else {
            hn::LoadInterleaved4(d, p, out[0], out[1], out[2], out[3]);
        }
        return;
    }
    const DI di;
    const auto index = hn::Add(hn::Mul(f.qy[k], hn::Set(di, int32_t(image.rowPitch / sizeof(float)))),
                               hn::Mul(f.qx[k], hn::Set(di, C)));
    const float* base = reinterpret_cast<const float*>(image.data);
    for (int c = 0; c < kUsed; ++c) out[c] = hn::GatherIndex(d, base + c, index);
}

struct RowJob {
    const TemporalViews& v;
    const TemporalParams& p;
    const TemporalOutputs& out;
};

/// The reference for one pixel, plus the fused stage's extra outputs.
bool scalarPixel(const RowJob& j, uint32_t x, uint32_t y) {
    const bool rejected = temporalPixel(j.v, x, y, j.p);
    const glm::vec4 i0 = j.v.integrated0.at(x, y);
    const glm::vec4 i1 = j.p.split ? j.v.integrated1.at(x, y) : glm::vec4(0.f);
    j.out.estimate.at(x, y) = i0;
    if (j.p.split) j.out.estimate1.at(x, y) = i1;
    if (j.out.layout) {
        packSignalPixel(*j.out.layout, j.out.signal, x, y, i0);
        if (j.p.split) packSignalPixel(*j.out.layout, j.out.signal1, x, y, i1);
        packGuidePixel(*j.out.layout, j.out.guide, x, y, j.v.linearZ.at(x, y), j.v.normW.at(x, y));
    }
    if (j.out.variance.data) j.out.variance.at(x, y) = i0.a + i1.a;  // as the variance stage (i1 = 0 unsplit)
    return rejected;
}

/// What the temporal stage writes for N pixels: the integrated signals (a = temporal variance), the moments, the
/// history length.
struct Results {
    V i[4], j[4], m[4], length;
};
/// This frame's guides of the N pixels.
struct Guides {
    V z, dz, nx, ny, nz;
    hn::Vec<DU> mesh;
};

/// What writePixels stores besides history, planes and debug variance.
struct Scratch {
    bool integrated, estimate;
};

/// The scratch images N pixels from x need: the variance stage reads them at short histories (`anyShort`), and
/// its scalar columns (the first 3 and the last N + 3) read the integrated images 3 columns around.
HWY_INLINE Scratch scratchFor(const RowJob& j, uint32_t x, bool anyShort) {
    const uint32_t N = uint32_t(hn::Lanes(D())), W = j.v.integrated0.width;
    const bool nearEdge = x < 6 || x + 2 * N + 6 > W;
    return {j.out.everyIntegrated || anyShort || nearEdge, j.out.everyEstimate || anyShort};
}

/// Stores N pixels' results: history, the scratch images `s` asks for, à-trous planes, debug variance.
HWY_INLINE void writePixels(const RowJob& j, uint32_t x, uint32_t y, const Results& r, const Guides& g, Scratch s) {
    const TemporalViews& v = j.v;
    const D d;
    const size_t N = hn::Lanes(d);
    const bool split = j.p.split;
    if (s.integrated) streamInterleaved4(d, r.i[0], r.i[1], r.i[2], r.i[3], &v.integrated0.at(x, y).x);
    streamInterleaved2(d, r.m[0], r.m[1], &v.curMoments0.at(x, y).x);
    if (split) streamInterleaved2(d, r.m[2], r.m[3], &v.curMoments1.at(x, y).x);
    hn::StoreU(r.length, d, &v.curLength.at(x, y));  // read again by the variance stage
    if (v.curLinearZ.data) {  // the guides for next frame, unless the graph keeps last frame's G-buffer
        streamCopy(d, &v.linearZ.at(x, y).x, &v.curLinearZ.at(x, y).x, 2 * N);
        streamCopy(d, &v.normW.at(x, y).x, &v.curNormW.at(x, y).x, 4 * N);
        hn::Stream(hn::BitCast(d, g.mesh), d, reinterpret_cast<float*>(&v.curMeshId.at(x, y)));
    }
    if (s.estimate) streamInterleaved4(d, r.i[0], r.i[1], r.i[2], r.i[3], &j.out.estimate.at(x, y).x);
    if (split) {
        if (s.integrated) streamInterleaved4(d, r.j[0], r.j[1], r.j[2], r.j[3], &v.integrated1.at(x, y).x);
        if (s.estimate) streamInterleaved4(d, r.j[0], r.j[1], r.j[2], r.j[3], &j.out.estimate1.at(x, y).x);
    }
    if (j.out.layout) {
        const size_t o = j.out.layout->offset(x, y);
        storeSignal<true>(d, j.out.signal, o, r.i[0], r.i[1], r.i[2], r.i[3]);
        if (split) storeSignal<true>(d, j.out.signal1, o, r.j[0], r.j[1], r.j[2], r.j[3]);
        storeGuide<true>(d, j.out.guide, o, g.z, g.dz, g.nx, g.ny, g.nz);
    }
    // As the variance stage: the two signals' variances summed (signal 1 is zero unsplit).
    if (j.out.variance.data) hn::StoreU(hn::Add(r.i[3], split ? r.j[3] : hn::Zero(d)), d, &j.out.variance.at(x, y));
}

/// Lanes of a vector group, one bit each (lane i: bit i).
using LaneBits = uint64_t;
constexpr LaneBits kEveryLane = ~LaneBits(0);

/// N pixels from x on row y in the vector path. Returns the lanes the reference must (re)do: kEveryLane when nothing
/// was written (a non-finite colour or motion vector), else the hits whose footprint needs the 3x3 fallback, which
/// the vector path writes with the others and the reference then overwrites.
LaneBits vectorPixels(const RowJob& j, uint32_t x, uint32_t y, bool& anyShort, uint8_t& reads) {
    const TemporalViews& v = j.v;
    const TemporalParams& p = j.p;
    const D d;
    const DI di;
    const DU du;
    const size_t N = hn::Lanes(d);
    const V zero = hn::Zero(d), one = hn::Set(d, 1.f);

    // Signal 0: colour, or direct in the split; signal 1: indirect (split only, else zero).
    const bool split = p.split;
    V cr, cg, cb, ca, dr = zero, dg = zero, db = zero, da;
    hn::LoadInterleaved4(d, &(split ? v.direct : v.color).at(x, y).x, cr, cg, cb, ca);
    if (!hn::AllTrue(d, hn::And(hn::And(hn::IsFinite(cr), hn::IsFinite(cg)), hn::IsFinite(cb)))) return kEveryLane;
    if (split) {
        hn::LoadInterleaved4(d, &v.indirect.at(x, y).x, dr, dg, db, da);
        if (!hn::AllTrue(d, hn::And(hn::And(hn::IsFinite(dr), hn::IsFinite(dg)), hn::IsFinite(db)))) return kEveryLane;
    }
    V z, dz;
    hn::LoadInterleaved2(d, &v.linearZ.at(x, y).x, z, dz);
    const M hit = hn::Ge(z, zero);
    // What the remodulation of these pixels reads (remodulationReads): the colour for a miss or an alpha other than
    // 1, the albedo for a hit (the emission below).
    if (split || !hn::AllTrue(d, hit) || !hn::AllTrue(d, hn::Eq(ca, one))) reads |= kReadsColour;
    if (!hn::AllFalse(d, hit)) reads |= kReadsAlbedo;
    V nx, ny, nz, nw;
    hn::LoadInterleaved4(d, &v.normW.at(x, y).x, nx, ny, nz, nw);
    const auto mesh = v.meshId.data ? hn::LoadU(du, &v.meshId.at(x, y)) : hn::Zero(du);
    if (hn::AllFalse(d, hit)) {
        // Misses only (sky): no history, zero signal, as below, without reading albedo, emission or motion.
        writePixels(j, x, y,
                    Results{{zero, zero, zero, zero}, {zero, zero, zero, zero}, {zero, zero, zero, zero}, zero},
                    Guides{z, dz, nx, ny, nz, mesh}, scratchFor(j, x, false));
        return 0;
    }

    // Reprojection (reproject() of SVGFKernels.h) through the 2x2 footprints (Footprint); the 3x3 fallback is left
    // to the reference.
    M valid = hn::FirstN(d, 0), fallback = valid;
    V rr = zero, rg = zero, rb = zero, rm[4] = {zero, zero, zero, zero}, rl = zero;
    V rc = zero, rq = one;  // reprojected shading change (anti-lag): lambda and luminance ratio; 0 and 1 without it
    if (v.prevChange.data) rq = zero;
    V sr = zero, sg = zero, sb = zero;  // signal 1's reprojected rgb
    if (p.temporal && !hn::AllFalse(d, hit)) {
        V mx, my;
        hn::LoadInterleaved2(d, &v.mvec.at(x, y).x, mx, my);
        if (!hn::AllTrue(d, hn::And(hn::IsFinite(mx), hn::IsFinite(my)))) return kEveryLane;
        const float W = float(v.color.width), H = float(v.color.height);
        const V xf = firstPlusLane(d, float(x)), yf = hn::Set(d, float(y));
        const V px = hn::Add(hn::Add(xf, hn::Mul(mx, hn::Set(d, W))), hn::Set(d, p.jitterDelta.x));
        const V py = hn::Add(hn::Add(yf, hn::Mul(my, hn::Set(d, H))), hn::Set(d, p.jitterDelta.y));
        const V fx0 = hn::Floor(px), fy0 = hn::Floor(py);
        const V ox = hn::Sub(fx0, xf), oy = hn::Sub(fy0, yf);
        const float ox0 = hn::GetLane(ox), oy0 = hn::GetLane(oy);
        // Columns x + ox0 .. x + ox0 + N (both taps of every lane) and rows y + oy0, y + oy0 + 1 inside the frame.
        const float col = float(x) + ox0, row = float(y) + oy0;
        Footprint f;
        f.contiguous = hn::AllTrue(d, hn::And(hn::Eq(ox, hn::Set(d, ox0)), hn::Eq(oy, hn::Set(d, oy0)))) &&
                       col >= 0.f && col + float(N) < W && row >= 0.f && row + 1.f < H;
        M inFrame[4];
        if (f.contiguous) {
            f.c0 = uint32_t(col);
            f.r0 = uint32_t(row);
            for (M& m : inFrame) m = hn::FirstN(d, N);
        } else {
            // reprojectionTapValid's frame test per lane. Positions far off the frame are clamped first (still off
            // it) so the conversion to integers cannot overflow.
            const auto ix = hn::ConvertTo(di, hn::Min(hn::Max(fx0, hn::Set(d, -2.f)), hn::Set(d, W + 1.f)));
            const auto iy = hn::ConvertTo(di, hn::Min(hn::Max(fy0, hn::Set(d, -2.f)), hn::Set(d, H + 1.f)));
            const auto w = hn::Set(di, int32_t(W)), h = hn::Set(di, int32_t(H)), zeroI = hn::Zero(di),
                       minusOne = hn::Set(di, -1);
            const auto maxX = hn::Sub(w, hn::Set(di, 1)), maxY = hn::Sub(h, hn::Set(di, 1));
            for (int k = 0; k < 4; ++k) {
                const auto qx = hn::Add(ix, hn::Set(di, k & 1)), qy = hn::Add(iy, hn::Set(di, k >> 1));
                inFrame[k] = hn::RebindMask(d, hn::And(hn::And(hn::Gt(qx, minusOne), hn::Lt(qx, w)),
                                                       hn::And(hn::Gt(qy, minusOne), hn::Lt(qy, h))));
                f.qx[k] = hn::Min(hn::Max(qx, zeroI), maxX);
                f.qy[k] = hn::Min(hn::Max(qy, zeroI), maxY);
            }
        }
        const V fx = hn::Sub(px, fx0), fy = hn::Sub(py, fy0);
        const V bw[4] = {hn::Mul(hn::Sub(one, fx), hn::Sub(one, fy)), hn::Mul(fx, hn::Sub(one, fy)),
                         hn::Mul(hn::Sub(one, fx), fy), hn::Mul(fx, fy)};
        // reprojectionTapValid, with the reference's comparisons (NaN guides pass the tests it lets them pass), against
        // expectedPrevDepth in its order of operations.
        const V zExpected = hn::Add(
            hn::Set(d, p.prevDepth.x),
            hn::Mul(z, hn::Add(hn::Add(hn::Set(d, p.prevDepth.y), hn::Mul(hn::Set(d, p.prevDepth.z), xf)),
                               hn::Mul(hn::Set(d, p.prevDepth.w), yf))));
        const V depthTolerance =
            hn::Mul(hn::Set(d, kDepthThreshold), hn::Add(dz, hn::Mul(hn::Set(d, kDepthEpsilon), z)));
        M tapValid[4];
        V sumW = zero;
        V prevLength[4];
        for (int k = 0; k < 4; ++k) {
            V zp[2], pn[4], length[1];
            loadTap<1>(d, f, k, v.prevLinearZ, zp);  // the depth, not its derivative
            loadTap<3>(d, f, k, v.prevNormW, pn);
            loadTap<1>(d, f, k, v.prevLength, length);
            prevLength[k] = length[0];
            const V dot = hn::Add(hn::Add(hn::Mul(nx, pn[0]), hn::Mul(ny, pn[1])), hn::Mul(nz, pn[2]));
            M m = hn::And(hn::And(hit, inFrame[k]), hn::Gt(bw[k], zero));
            m = hn::And(m, hn::Gt(prevLength[k], zero));
            m = hn::AndNot(hn::Lt(zp[0], zero), m);
            if (v.meshId.data) {
                V prevMesh[1];
                loadTap<1>(d, f, k, v.prevMeshId, prevMesh);  // the ids' bits
                m = hn::And(m, hn::RebindMask(d, hn::Eq(hn::BitCast(du, prevMesh[0]), mesh)));
            }
            m = hn::AndNot(hn::Gt(hn::Abs(hn::Sub(zExpected, zp[0])), depthTolerance), m);
            m = hn::AndNot(hn::Lt(dot, hn::Set(d, kNormalThreshold)), m);
            tapValid[k] = m;
            sumW = hn::Add(sumW, hn::IfThenElseZero(m, bw[k]));
        }
        const M bilinear = hn::Ge(sumW, hn::Set(d, kMinBilinearWeight));
        // A hit whose footprint carries too little weight needs the 3x3 fallback: the reference redoes it. Its lane
        // runs on here with no valid history (whatever it computes is overwritten).
        fallback = hn::AndNot(bilinear, hit);
        V ra = zero, sa = zero;
        for (int k = 0; k < 4; ++k) {
            if (hn::AllFalse(d, tapValid[k])) continue;
            const M m = tapValid[k];
            V illum[4], moments[2];
            loadTap<4>(d, f, k, v.prevIllum0, illum);
            loadTap<2>(d, f, k, v.prevMoments0, moments);
            const V w = bw[k];
            rr = hn::Add(rr, hn::IfThenElseZero(m, hn::Mul(w, illum[0])));
            rg = hn::Add(rg, hn::IfThenElseZero(m, hn::Mul(w, illum[1])));
            rb = hn::Add(rb, hn::IfThenElseZero(m, hn::Mul(w, illum[2])));
            ra = hn::Add(ra, hn::IfThenElseZero(m, hn::Mul(w, illum[3])));
            rm[0] = hn::Add(rm[0], hn::IfThenElseZero(m, hn::Mul(w, moments[0])));
            rm[1] = hn::Add(rm[1], hn::IfThenElseZero(m, hn::Mul(w, moments[1])));
            rl = hn::Add(rl, hn::IfThenElseZero(m, hn::Mul(w, prevLength[k])));
            if (v.prevChange.data) {
                V change[2];
                loadTap<2>(d, f, k, v.prevChange, change);
                rc = hn::Add(rc, hn::IfThenElseZero(m, hn::Mul(w, change[0])));
                rq = hn::Add(rq, hn::IfThenElseZero(m, hn::Mul(w, change[1])));
            }
            if (split) {  // unsplit, signal 1's sums stay zero, as the reference's sums of zero fields do
                loadTap<2>(d, f, k, v.prevMoments1, moments);
                rm[2] = hn::Add(rm[2], hn::IfThenElseZero(m, hn::Mul(w, moments[0])));
                rm[3] = hn::Add(rm[3], hn::IfThenElseZero(m, hn::Mul(w, moments[1])));
                loadTap<4>(d, f, k, v.prevIllum1, illum);
                sr = hn::Add(sr, hn::IfThenElseZero(m, hn::Mul(w, illum[0])));
                sg = hn::Add(sg, hn::IfThenElseZero(m, hn::Mul(w, illum[1])));
                sb = hn::Add(sb, hn::IfThenElseZero(m, hn::Mul(w, illum[2])));
                sa = hn::Add(sa, hn::IfThenElseZero(m, hn::Mul(w, illum[3])));
            }
        }
        const V inv = hn::Div(one, sumW);
        rr = hn::Mul(rr, inv);
        rg = hn::Mul(rg, inv);
        rb = hn::Mul(rb, inv);
        ra = hn::Mul(ra, inv);
        for (V& c : rm) c = hn::Mul(c, inv);
        rl = hn::Mul(rl, inv);
        if (v.prevChange.data) {
            rc = hn::Mul(rc, inv);
            rq = hn::Mul(rq, inv);
        }
        sr = hn::Mul(sr, inv);
        sg = hn::Mul(sg, inv);
        sb = hn::Mul(sb, inv);
        sa = hn::Mul(sa, inv);
        // History that is not finite counts as disoccluded (reference: r.valid).
        M finite = hn::And(hn::And(hn::IsFinite(rr), hn::IsFinite(rg)), hn::And(hn::IsFinite(rb), hn::IsFinite(ra)));
        finite = hn::And(
            finite, hn::And(hn::And(hn::IsFinite(sr), hn::IsFinite(sg)), hn::And(hn::IsFinite(sb), hn::IsFinite(sa))));
        finite = hn::And(finite, hn::And(hn::And(hn::IsFinite(rm[0]), hn::IsFinite(rm[1])),
                                         hn::And(hn::IsFinite(rm[2]), hn::IsFinite(rm[3]))));
        finite = hn::And(finite, hn::And(hn::IsFinite(rc), hn::IsFinite(rq)));
        valid = hn::And(hn::And(hit, bilinear), hn::And(finite, hn::IsFinite(rl)));
    }

    // Demodulation (temporalPixel): emission out, divided by the guarded albedo, clamped.
    V ar, ag, ab, aa, er = zero, eg = zero, eb = zero, ea;
    hn::LoadInterleaved4(d, &v.albedo.at(x, y).x, ar, ag, ab, aa);
    if (v.emission.data) {
        hn::LoadInterleaved4(d, &v.emission.at(x, y).x, er, eg, eb, ea);
        er = hn::IfThenElseZero(hn::IsFinite(er), er);
        eg = hn::IfThenElseZero(hn::IsFinite(eg), eg);
        eb = hn::IfThenElseZero(hn::IsFinite(eb), eb);
        const M lit = hn::Or(hn::Ne(er, zero), hn::Or(hn::Ne(eg, zero), hn::Ne(eb, zero)));
        if (!hn::AllFalse(d, hn::And(hit, lit))) reads |= kReadsEmission;
    }
    const V minAlbedo = hn::Set(d, kMinAlbedo), maxAlbedo = hn::Set(d, kMaxAlbedo),
            maxIllum = hn::Set(d, kMaxIllumination);
    auto demodulate = [&](V c, V e, V a) HWY_ATTR {
        a = minOf(maxOf(hn::IfThenElseZero(hn::IsFinite(a), a), minAlbedo), maxAlbedo);
        return minOf(maxOf(hn::Div(hn::Sub(c, e), a), zero), maxIllum);
    };
    const V lr = demodulate(cr, er, ar), lg = demodulate(cg, eg, ag), lb = demodulate(cb, eb, ab);
    const V lum = luminanceSum(d, lr, lg, lb);
    // Signal 1 (split): divided by the albedo, no emission (that is part of direct). Unsplit it is zero throughout.
    V kr = zero, kg = zero, kb = zero, lum1 = zero;
    if (split) {
        kr = demodulate(dr, zero, ar);
        kg = demodulate(dg, zero, ag);
        kb = demodulate(db, zero, ab);
        lum1 = luminanceSum(d, kr, kg, kb);
    }
    const V moments[4] = {lum, hn::Mul(lum, lum), lum1, hn::Mul(lum1, lum1)};
    const int momentCount = split ? 4 : 2;

    // Temporal accumulation (paper eq. 1 with Falcor's max(alpha, 1 / n)), with the anti-lag of temporalPixel.
    const V change = minOf(maxOf(rc, zero), one);
    // The history rescaled by the luminance ratio (temporalPixel).
    rr = hn::Mul(rr, rq);
    rg = hn::Mul(rg, rq);
    rb = hn::Mul(rb, rq);
    sr = hn::Mul(sr, rq);
    sg = hn::Mul(sg, rq);
    sb = hn::Mul(sb, rq);
    const V rq2 = hn::Mul(rq, rq);
    rm[0] = hn::Mul(rm[0], rq);
    rm[1] = hn::Mul(rm[1], rq2);
    rm[2] = hn::Mul(rm[2], rq);
    rm[3] = hn::Mul(rm[3], rq2);
    if (v.neighbourhood.data) {
        // The history clamp (temporalPixel, historyClampScale): the history scaled into this frame's neighbourhood.
        V b[4];
        hn::LoadInterleaved4(d, &v.neighbourhood.at(x, y).x, b[0], b[1], b[2], b[3]);
        const V sigmas = hn::Set(d, p.clampSigma);
        auto clampScale = [&](V lumV, V mean, V sd) HWY_ATTR {
            const V lo = maxOf(hn::Sub(mean, hn::Mul(sigmas, sd)), zero), hi = hn::Add(mean, hn::Mul(sigmas, sd));
            const V up = hn::IfThenElse(hn::And(hn::Lt(lumV, lo), hn::Gt(lumV, zero)), hn::Div(lo, lumV), one);
            return hn::IfThenElse(hn::Gt(lumV, hi), hn::Div(hi, lumV), up);
        };
        // One signal's history (rgb, moments m1 and m2) scaled by its clamp factor.
        auto clampSignal = [&](V& r, V& g, V& bl, V& m1, V& m2, V mean, V sd) HWY_ATTR {
            const V h = clampScale(luminanceSum(d, r, g, bl), mean, sd);
            r = hn::Mul(r, h);
            g = hn::Mul(g, h);
            bl = hn::Mul(bl, h);
            m1 = hn::Mul(m1, h);
            m2 = hn::Mul(m2, hn::Mul(h, h));
        };
        clampSignal(rr, rg, rb, rm[0], rm[1], b[0], b[1]);
        if (split) clampSignal(sr, sg, sb, rm[2], rm[3], b[2], b[3]);
    }
    const V length = hn::IfThenElse(
        valid, minOf(hn::Add(hn::Mul(rl, hn::Sub(one, change)), one), hn::Set(d, float(p.maxHistory))), one);
    const V invLength = hn::Div(one, length);
    const V a = maxOf(hn::Add(hn::Set(d, p.alpha), hn::Mul(change, hn::Set(d, 1.f - p.alpha))), invLength);
    const V am =
        maxOf(hn::Add(hn::Set(d, p.momentsAlpha), hn::Mul(change, hn::Set(d, 1.f - p.momentsAlpha))), invLength);
    // The firefly clamp (outlierScale) where the history is settled: the samples blended into it, moments included.
    V s0 = one, s1 = one;
    V blended[4] = {moments[0], moments[1], moments[2], moments[3]};
    if (p.outlierSigma > 0.f) {
        const M settled = hn::Ge(rl, hn::Set(d, kOutlierMinFrames));
        const V sigmas = hn::Set(d, p.outlierSigma);
        auto scale = [&](V lumV, V m1, V m2) HWY_ATTR {
            const V bound = hn::Add(m1, hn::Mul(sigmas, hn::Sqrt(maxOf(hn::Sub(m2, hn::Mul(m1, m1)), zero))));
            const M over = hn::And(settled, hn::And(hn::Gt(lumV, bound), hn::Ge(bound, zero)));
            return hn::IfThenElse(over, hn::Div(bound, lumV), one);
        };
        s0 = scale(lum, rm[0], rm[1]);
        const V c0 = hn::Mul(lum, s0);
        blended[0] = c0;
        blended[1] = hn::Mul(c0, c0);
        if (split) {
            s1 = scale(lum1, rm[2], rm[3]);
            const V c1 = hn::Mul(lum1, s1);
            blended[2] = c1;
            blended[3] = hn::Mul(c1, c1);
        }
    }
    V ir = hn::IfThenElse(valid, mixOf(d, rr, hn::Mul(lr, s0), a), lr);
    V ig = hn::IfThenElse(valid, mixOf(d, rg, hn::Mul(lg, s0), a), lg);
    V ib = hn::IfThenElse(valid, mixOf(d, rb, hn::Mul(lb, s0), a), lb);
    V m[4] = {zero, zero, zero, zero};
    for (int c = 0; c < momentCount; ++c) m[c] = hn::IfThenElse(valid, mixOf(d, rm[c], blended[c], am), moments[c]);
    // The variance of the accumulated mean: max(1 / n, varianceFloor) of the per-sample variance (n >= 1 here).
    const V meanScale = maxOf(invLength, hn::Set(d, p.varianceFloor));
    V ia = hn::Mul(maxOf(zero, hn::Sub(m[1], hn::Mul(m[0], m[0]))), meanScale);
    V jr = zero, jg = zero, jb = zero, ja = zero;
    if (split) {
        jr = hn::IfThenElseZero(hit, hn::IfThenElse(valid, mixOf(d, sr, hn::Mul(kr, s1), a), kr));
        jg = hn::IfThenElseZero(hit, hn::IfThenElse(valid, mixOf(d, sg, hn::Mul(kg, s1), a), kg));
        jb = hn::IfThenElseZero(hit, hn::IfThenElse(valid, mixOf(d, sb, hn::Mul(kb, s1), a), kb));
        ja = hn::IfThenElseZero(hit, hn::Mul(maxOf(zero, hn::Sub(m[3], hn::Mul(m[2], m[2]))), meanScale));
    }
    // Misses: no history, zero signal.
    ir = hn::IfThenElseZero(hit, ir);
    ig = hn::IfThenElseZero(hit, ig);
    ib = hn::IfThenElseZero(hit, ib);
    ia = hn::IfThenElseZero(hit, ia);
    for (V& c : m) c = hn::IfThenElseZero(hit, c);

    anyShort = !hn::AllFalse(d, needsSpatialVarianceVec(d, z, length));
    writePixels(j, x, y,
                Results{{ir, ig, ib, ia}, {jr, jg, jb, ja}, {m[0], m[1], m[2], m[3]}, hn::IfThenElseZero(hit, length)},
                Guides{z, dz, nx, ny, nz, mesh}, scratchFor(j, x, anyShort));
    uint8_t bits[8] = {};
    hn::StoreMaskBits(d, fallback, bits);
    LaneBits lanes = 0;
    for (int i = 0; i < 8; ++i) lanes |= LaneBits(bits[i]) << (8 * i);
    return lanes;
}

TemporalCounts temporalTile(const RowJob& j, const Tile& t) {
    const uint32_t N = uint32_t(hn::Lanes(D()));
    const uint32_t groupsPerRow = remodulationGroupsPerRow(j.v.color.width);
    TemporalCounts counts;
    for (uint32_t y = t.y0; y < t.y1; ++y) {
        bool rowShort = false;
        uint8_t* groups = j.out.remodulationGroups;
        if (groups) {
            groups += size_t(y) * groupsPerRow;
            std::fill_n(groups, groupsPerRow, uint8_t(0));
        }
        // A pixel the reference ran: the row's short-history flag and its group's remodulation reads from what the
        // reference wrote (its history length is in curLength).
        const auto noteScalarPixel = [&](uint32_t px) {
            rowShort |= needsSpatialVariance(j.v.linearZ.at(px, y).x, j.v.curLength.at(px, y));
            if (groups)
                groups[px / kRemodulationGroup] |=
                    remodulationReads(j.v.color, j.v.emission, j.v.linearZ, j.p.split, px, y);
        };
        uint32_t x = t.x0;
        for (; x + N <= t.x1; x += N) {
            bool anyShort = false;
            uint8_t reads = 0;
            const LaneBits redo = vectorPixels(j, x, y, anyShort, reads);
            rowShort |= anyShort;
            if (groups) groups[x / kRemodulationGroup] |= reads;  // N divides the group
            if (redo == 0) continue;
            // Lanes the vector path wrote are overwritten below: its streamed stores go first.
            if (redo != kEveryLane) hwy::FlushStream();
            for (uint32_t k = 0; k < N; ++k) {
                if (!((redo >> k) & 1)) continue;
                counts.rejected += scalarPixel(j, x + k, y) ? 1 : 0;
                noteScalarPixel(x + k);
                ++counts.reference;
            }
        }
        for (; x < t.x1; ++x, ++counts.reference) {
            counts.rejected += scalarPixel(j, x, y) ? 1 : 0;
            noteScalarPixel(x);
        }
        if (j.out.shortRows) j.out.shortRows[y] = rowShort ? 1 : 0;
    }
    hwy::FlushStream();  // the streamed stores are visible before the tile is reported done
    return counts;
}

TemporalCounts TemporalFusedTarget(const TemporalViews& v, const TemporalParams& p, const TemporalOutputs& out,
                                   uint32_t rows) {
    const RowJob job{v, p, out};
    std::atomic<uint64_t> rejected{0}, reference{0};
    // Bands of whole rows rather than square tiles: each of the some twenty streams is then one long run per row,
    // which the hardware prefetchers follow (with 128-pixel tiles they restart at every row).
    const uint32_t width = v.color.width;
    parallelFor2D(
        1, v.color.height,
        [j = &job, r = &rejected, s = &reference, width](const Tile& band) {
            const TemporalCounts c = temporalTile(*j, Tile{0, band.y0, width, band.y1});
            *r += c.rejected;
            *s += c.reference;
        },
        rows);
    return {rejected.load(), reference.load()};
}

/// varianceExp2Neg lane-wise (the same operations).
HWY_INLINE V exp2NegOf(D d, V t) {
    return ::loom::simd::HWY_NAMESPACE::exp2Neg(d, minOf(t, hn::Set(d, kWeightMaxExponent)));
}

struct VarianceJob {
    const VarianceViews& v;
    const VarianceScales& s;
    const PlaneLayout& L;
    const GuidePlanes& G;
    const SignalPlanes& S0;
    const SignalPlanes& S1;  ///< split only
};

/// Lanes of the N pixels from x on row y that take the spatial estimate (varianceEstimatePixel's test).
HWY_INLINE M shortHistory(D d, const VarianceViews& v, uint32_t x, uint32_t y, V& z, V& dz) {
    hn::LoadInterleaved2(d, &v.linearZ.at(x, y).x, z, dz);
    return needsSpatialVarianceVec(d, z, hn::LoadU(d, &v.length.at(x, y)));
}

/// One signal's sums over the 7x7 taps.
struct VarianceSums {
    V r, g, b, m1, m2, w;
};

/// The signal's estimate from its sums where a weight survived (the centre's unless its normal is degenerate),
/// else the temporal values (i), blended into the short lanes of the estimate image at p.
HWY_INLINE V storeEstimate(D d, const VarianceSums& s, V ir, V ig, V ib, V ia, V boost, M isShort, float* p) {
    const V zero = hn::Zero(d);
    const V m1 = hn::Div(s.m1, s.w), m2 = hn::Div(s.m2, s.w);
    const M has = hn::Gt(s.w, zero);
    const V er = hn::IfThenElse(has, hn::Div(s.r, s.w), ir), eg = hn::IfThenElse(has, hn::Div(s.g, s.w), ig);
    const V eb = hn::IfThenElse(has, hn::Div(s.b, s.w), ib);
    const V ea = hn::IfThenElse(has, hn::Mul(maxOf(zero, hn::Sub(m2, hn::Mul(m1, m1))), boost), ia);
    V pr, pg, pb, pa;  // the other lanes keep what stage 1 wrote
    hn::LoadInterleaved4(d, p, pr, pg, pb, pa);
    hn::StoreInterleaved4(hn::IfThenElse(isShort, er, pr), hn::IfThenElse(isShort, eg, pg),
                          hn::IfThenElse(isShort, eb, pb), hn::IfThenElse(isShort, ea, pa), d, p);
    return ea;
}

/// varianceEstimatePixel (series normal weight) for the N pixels from x on row y, all of whose taps lie inside the
/// frame's columns: the reference's operations in the reference's order, taps read from the à-trous planes stage 1
/// packed (the same values, sanitised as the reference sanitises them) and from the moments. Returns the number
/// of short lanes (0: nothing written).
template <bool kSplit>
size_t varianceVector(const VarianceJob& j, uint32_t x, uint32_t y) {
    const VarianceViews& v = j.v;
    const D d;
    const V zero = hn::Zero(d), one = hn::Set(d, 1.f);
    V zc, dzc;
    const M isShort = shortHistory(d, v, x, y, zc, dzc);
    const size_t count = hn::CountTrue(d, isShort);
    if (count == 0) return 0;
    const size_t o = j.L.offset(x, y);
    const ptrdiff_t stride = ptrdiff_t(j.L.stride);
    const GuidePlanes& G = j.G;
    const SignalPlanes &S0 = j.S0, &S1 = j.S1;
    const V ncx = hn::LoadU(d, G.nx + o), ncy = hn::LoadU(d, G.ny + o), ncz = hn::LoadU(d, G.nz + o);
    V ir, ig, ib, ia, kr = zero, kg = zero, kb = zero, ka = zero;
    hn::LoadInterleaved4(d, &v.integrated0.at(x, y).x, ir, ig, ib, ia);
    if constexpr (kSplit) hn::LoadInterleaved4(d, &v.integrated1.at(x, y).x, kr, kg, kb, ka);
    const V lc0 = luminanceSum(d, ir, ig, ib), lc1 = kSplit ? luminanceSum(d, kr, kg, kb) : zero;
    const V invPhiDepth = hn::Div(one, hn::Mul(maxOf(dzc, hn::Set(d, 1e-8f)), hn::Set(d, 3.f)));
    const V invPhiL = hn::Set(d, j.s.invPhiL), log2e = hn::Set(d, kWeightLog2e);
    const V t0 = hn::Set(d, j.s.terms[0]), t1 = hn::Set(d, j.s.terms[1]), t2 = hn::Set(d, j.s.terms[2]),
            t3 = hn::Set(d, j.s.terms[3]);
    VarianceSums s0{zero, zero, zero, zero, zero, zero}, s1 = s0;
    const int H = int(v.integrated0.height);
    for (int jy = -3; jy <= 3; ++jy) {
        const int qy = int(y) + jy;
        if (qy < 0 || qy >= H) continue;
        const ptrdiff_t row = ptrdiff_t(o) + jy * stride;
        const glm::vec2* moments0 = v.moments0.row(uint32_t(qy)) + x;
        const glm::vec2* moments1 = kSplit ? v.moments1.row(uint32_t(qy)) + x : nullptr;
        for (int ix = -3; ix <= 3; ++ix) {
            const ptrdiff_t q = row + ix;
            const V zq = hn::LoadU(d, G.z + q);
            const V cosine =
                hn::Add(hn::Add(hn::Mul(ncx, hn::LoadU(d, G.nx + q)), hn::Mul(ncy, hn::LoadU(d, G.ny + q))),
                        hn::Mul(ncz, hn::LoadU(d, G.nz + q)));
            const M use = hn::And(hn::Ge(zq, zero), hn::Gt(cosine, zero));
            const V invDepth = hn::Mul(invPhiDepth, hn::Set(d, varianceInvDistance(ix, jy)));
            const V depthTerm = hn::Mul(hn::Abs(hn::Sub(zc, zq)), invDepth);
            const V dd = maxOf(hn::Sub(one, cosine), zero);
            const V normal =
                hn::Mul(dd, hn::Add(t0, hn::Mul(dd, hn::Add(t1, hn::Mul(dd, hn::Add(t2, hn::Mul(dd, t3)))))));
            V m0, m1, m2 = zero, m3 = zero;
            hn::LoadInterleaved2(d, &moments0[ix].x, m0, m1);
            if constexpr (kSplit) hn::LoadInterleaved2(d, &moments1[ix].x, m2, m3);
            // varianceWeight and the sums of one signal.
            auto accumulate = [&](const SignalPlanes& P, V lc, V ma, V mb, VarianceSums& s) HWY_ATTR {
                const V rq = hn::LoadU(d, P.r + q), gq = hn::LoadU(d, P.g + q), bq = hn::LoadU(d, P.b + q);
                const V linear =
                    hn::Add(hn::Mul(hn::Abs(hn::Sub(lc, luminanceSum(d, rq, gq, bq))), invPhiL), depthTerm);
                const V w = hn::IfThenElseZero(use, exp2NegOf(d, hn::Add(hn::Mul(linear, log2e), normal)));
                s.r = hn::Add(s.r, hn::Mul(w, rq));
                s.g = hn::Add(s.g, hn::Mul(w, gq));
                s.b = hn::Add(s.b, hn::Mul(w, bq));
                s.m1 = hn::Add(s.m1, hn::Mul(w, ma));
                s.m2 = hn::Add(s.m2, hn::Mul(w, mb));
                s.w = hn::Add(s.w, w);
            };
            accumulate(S0, lc0, m0, m1, s0);
            if constexpr (kSplit) accumulate(S1, lc1, m2, m3, s1);
        }
    }
    const V boost = hn::Div(hn::Set(d, kSpatialVarianceFrames), maxOf(hn::LoadU(d, &v.length.at(x, y)), one));
    const V ea0 = storeEstimate(d, s0, ir, ig, ib, ia, boost, isShort, &v.estimate0.at(x, y).x);
    const V ea1 = kSplit ? storeEstimate(d, s1, kr, kg, kb, ka, boost, isShort, &v.estimate1.at(x, y).x) : zero;
    if (v.variance.data) {
        float* variance = &v.variance.at(x, y);
        hn::StoreU(hn::IfThenElse(isShort, hn::Add(ea0, ea1), hn::LoadU(d, variance)), d, variance);
    }
    return count;
}

VarianceCounts VarianceFusedTarget(const VarianceViews& v, const VarianceScales& scales, const PlaneLayout& L,
                                   const GuidePlanes& G, const SignalPlanes& S0, const SignalPlanes& S1, bool split,
                                   uint32_t rows, const uint8_t* shortRows) {
    const VarianceJob job{v, scales, L, G, S0, S1};
    // Rows stage 1 found no short history in have nothing to do in either loop below.
    const auto skipRow = [shortRows](uint32_t y) { return shortRows && !shortRows[y]; };
    const uint32_t W = v.integrated0.width, H = v.integrated0.height;
    const uint32_t N = uint32_t(hn::Lanes(D()));
    auto isShort = [&v](uint32_t x, uint32_t y) {
        return needsSpatialVariance(v.linearZ.at(x, y).x, v.length.at(x, y));
    };
    std::atomic<uint64_t> spatial{0}, reference{0};
    // The estimates. The planes are read as taps here, so they are repacked only once every estimate is done.
    parallelFor2D(
        1, H,
        [&](const Tile& band) {
            uint64_t vectorCount = 0, scalarCount = 0;
            for (uint32_t y = band.y0; y < band.y1; ++y) {
                if (skipRow(y)) continue;
                for (uint32_t x = 0; x < W;) {
                    if (x >= 3 && x + N + 3 <= W) {
                        vectorCount += split ? varianceVector<true>(job, x, y) : varianceVector<false>(job, x, y);
                        x += N;
                        continue;
                    }
                    if (isShort(x, y)) {
                        varianceEstimatePixel(v, x, y, scales, split);
                        ++scalarCount;
                    }
                    ++x;
                }
            }
            spatial += vectorCount + scalarCount;
            reference += scalarCount;
        },
        rows);
    // The à-trous input planes of the pixels whose estimate changed.
    parallelFor2D(
        1, H,
        [&](const Tile& band) {
            const D d;
            for (uint32_t y = band.y0; y < band.y1; ++y) {
                if (skipRow(y)) continue;
                uint32_t x = 0;
                for (; x + N <= W; x += N) {
                    V z, dz;
                    if (hn::AllFalse(d, shortHistory(d, v, x, y, z, dz))) continue;
                    // Every lane: the unchanged ones store what stage 1 stored from the same values.
                    V r, g, b, a;
                    hn::LoadInterleaved4(d, &v.estimate0.at(x, y).x, r, g, b, a);
                    storeSignal(d, S0, L.offset(x, y), r, g, b, a);
                    if (!split) continue;
                    hn::LoadInterleaved4(d, &v.estimate1.at(x, y).x, r, g, b, a);
                    storeSignal(d, S1, L.offset(x, y), r, g, b, a);
                }
                for (; x < W; ++x) {
                    if (!isShort(x, y)) continue;
                    packSignalPixel(L, S0, x, y, v.estimate0.at(x, y));
                    if (split) packSignalPixel(L, S1, x, y, v.estimate1.at(x, y));
                }
            }
        },
        rows);
    return {spatial.load(), reference.load()};
}

}  // namespace loom::svgf::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace loom::svgf::simd {

HWY_EXPORT(TemporalFusedTarget);
HWY_EXPORT(VarianceFusedTarget);

TemporalCounts temporalFused(const TemporalViews& v, const TemporalParams& p, const TemporalOutputs& out,
                             uint32_t rows) {
    return HWY_DYNAMIC_DISPATCH(TemporalFusedTarget)(v, p, out, rows);
}

VarianceCounts varianceFused(const VarianceViews& v, const VarianceScales& scales, const PlaneLayout& layout,
                             const GuidePlanes& guide, const SignalPlanes& signal0, const SignalPlanes& signal1,
                             bool split, uint32_t rows, const uint8_t* shortRows) {
    return HWY_DYNAMIC_DISPATCH(VarianceFusedTarget)(v, scales, layout, guide, signal0, signal1, split, rows,
                                                     shortRows);
}

}  // namespace loom::svgf::simd
#endif  // HWY_ONCE
