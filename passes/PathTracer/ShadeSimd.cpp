#include "ShadeSimd.h"

#include <hwy/contrib/math/math-inl.h>
#include <hwy/highway.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "loom/simd/KernelMath-inl.h"

namespace loom::pt {

namespace hn = hwy::HWY_NAMESPACE;

namespace {

using D = hn::ScalableTag<float>;
using V = hn::Vec<D>;
using M = hn::Mask<D>;
static_assert(HWY_MAX_BYTES / sizeof(float) <= kMaxShadeLanes, "a vector holds more paths than a batch");

constexpr float kLn2 = 0.69314718055994530942f;

struct V3 {
    V x, y, z;
};

HWY_INLINE V3 add(const V3& a, const V3& b) {
    return {a.x + b.x, a.y + b.y, a.z + b.z};
}
HWY_INLINE V3 sub(const V3& a, const V3& b) {
    return {a.x - b.x, a.y - b.y, a.z - b.z};
}
HWY_INLINE V3 mul(const V3& a, const V3& b) {
    return {a.x * b.x, a.y * b.y, a.z * b.z};
}
HWY_INLINE V3 scale(const V3& a, V s) {
    return {a.x * s, a.y * s, a.z * s};
}
HWY_INLINE V dot(const V3& a, const V3& b) {
    return hn::MulAdd(a.x, b.x, hn::MulAdd(a.y, b.y, a.z * b.z));
}
HWY_INLINE V3 cross(const V3& a, const V3& b) {
    return {hn::MulSub(a.y, b.z, a.z * b.y), hn::MulSub(a.z, b.x, a.x * b.z), hn::MulSub(a.x, b.y, a.y * b.x)};
}
HWY_INLINE V3 normalize(D d, const V3& a) {
    return scale(a, hn::Div(hn::Set(d, 1.f), hn::Sqrt(dot(a, a))));
}
HWY_INLINE V3 select(M m, const V3& a, const V3& b) {
    return {hn::IfThenElse(m, a.x, b.x), hn::IfThenElse(m, a.y, b.y), hn::IfThenElse(m, a.z, b.z)};
}
HWY_INLINE M nonZero(D d, const V3& a) {
    const V z = hn::Zero(d);
    return hn::Or(hn::Or(hn::Ne(a.x, z), hn::Ne(a.y, z)), hn::Ne(a.z, z));
}
HWY_INLINE V luminance(D d, const V3& c) {
    return simd::HWY_NAMESPACE::luminanceFmaBlueFirst(d, c.x, c.y, c.z);
}
HWY_INLINE V clamp01(D d, V v) {
    return hn::Min(hn::Max(v, hn::Zero(d)), hn::Set(d, 1.f));
}
/// schlickWeight(): (1 - cos)^5 with 1 - cos clamped to [0, 1].
HWY_INLINE V schlickWeight(D d, V cosTheta) {
    const V m = clamp01(d, hn::Set(d, 1.f) - cosTheta);
    const V m2 = m * m;
    return m2 * m2 * m;
}

/// cosSinQuarter() (BRDF.h), |x| <= pi/4.
HWY_INLINE void cosSinQuarter(D d, V x, V& c, V& s) {
    const V x2 = x * x;
    c = hn::MulAdd(x2, hn::Set(d, -1.f / 3628800.f), hn::Set(d, 1.f / 40320.f));
    c = hn::MulAdd(x2, c, hn::Set(d, -1.f / 720.f));
    c = hn::MulAdd(x2, c, hn::Set(d, 1.f / 24.f));
    c = hn::MulAdd(x2, c, hn::Set(d, -1.f / 2.f));
    c = hn::MulAdd(x2, c, hn::Set(d, 1.f));
    s = hn::MulAdd(x2, hn::Set(d, 1.f / 362880.f), hn::Set(d, -1.f / 5040.f));
    s = hn::MulAdd(x2, s, hn::Set(d, 1.f / 120.f));
    s = hn::MulAdd(x2, s, hn::Set(d, -1.f / 6.f));
    s = hn::MulAdd(x2, s, hn::Set(d, 1.f));
    s = x * s;
}

/// cosSinTurn() (BRDF.h): cos and sin of 2 pi u, u in [0, 1).
HWY_INLINE void cosSinTurn(D d, V u, V& c, V& s) {
    const hn::RebindToSigned<D> di;
    const V t = hn::Set(d, 4.f) * u;
    const V q = hn::Floor(t + hn::Set(d, 0.5f));
    V c0, s0;
    cosSinQuarter(d, (t - q) * hn::Set(d, 0.5f * kPi), c0, s0);
    const auto quadrant = hn::And(hn::ConvertTo(di, q), hn::Set(di, 3));
    // Quadrants 1 and 3 swap cos and sin; cos is negative in quadrants 1 and 2, sin in 2 and 3.
    const M swap = hn::RebindMask(d, hn::Eq(hn::And(quadrant, hn::Set(di, 1)), hn::Set(di, 1)));
    const M cosNeg = hn::RebindMask(d, hn::Eq(hn::And(quadrant + hn::Set(di, 1), hn::Set(di, 2)), hn::Set(di, 2)));
    const M sinNeg = hn::RebindMask(d, hn::Eq(hn::And(quadrant, hn::Set(di, 2)), hn::Set(di, 2)));
    const V cs = hn::IfThenElse(swap, s0, c0), sn = hn::IfThenElse(swap, c0, s0);
    c = hn::IfThenElse(cosNeg, hn::Neg(cs), cs);
    s = hn::IfThenElse(sinNeg, hn::Neg(sn), sn);
}

/// makeFrame() (BRDF.h).
struct FrameV {
    V3 t, b, n;
    HWY_INLINE V3 toLocal(const V3& v) const { return {dot(v, t), dot(v, b), dot(v, n)}; }
    HWY_INLINE V3 toWorld(const V3& v) const { return add(add(scale(t, v.x), scale(b, v.y)), scale(n, v.z)); }
};
HWY_INLINE FrameV makeFrame(D d, const V3& n) {
    const V one = hn::Set(d, 1.f);
    const V sign = hn::CopySign(one, n.z);
    const V a = hn::Neg(hn::Div(one, sign + n.z));
    const V b = n.x * n.y * a;
    FrameV f;
    f.t = {hn::MulAdd(sign * n.x, n.x * a, one), sign * b, hn::Neg(sign * n.x)};
    f.b = {b, hn::MulAdd(n.y * n.y, a, sign), hn::Neg(n.y)};
    f.n = n;
    return f;
}

/// tableCell() (BRDF.h): x in [0, 1] (NaN read as 0) to a cell index of the albedo tables and the fraction in it.
HWY_INLINE hn::Vec<hn::RebindToSigned<D>> tableCell(D d, V x, V& frac) {
    const hn::RebindToSigned<D> di;
    const V clamped = hn::Min(hn::IfThenElseZero(hn::Gt(x, hn::Zero(d)), x), hn::Set(d, 1.f));
    const V t = clamped * hn::Set(d, float(kBrdfTableSize - 1));
    const V cell = hn::Min(hn::Floor(t), hn::Set(d, float(kBrdfTableSize - 2)));
    frac = t - cell;
    return hn::ConvertTo(di, cell);
}

/// ggxAlbedo() (BRDF.h) at n.wo = mu for lanes whose roughness row starts at `row` (2 kBrdfTableSize y) with
/// fraction fy.
HWY_INLINE void ggxAlbedo(D d, hn::Vec<hn::RebindToSigned<D>> row, V fy, V mu, V& e, V& es) {
    const hn::RebindToSigned<D> di;
    V fx;
    const auto x = tableCell(d, hn::Sqrt(hn::Max(mu, hn::Zero(d))), fx);
    const auto i0 = row + hn::ShiftLeft<1>(x), i1 = i0 + hn::Set(di, 2 * kBrdfTableSize);
    const float* t = ggxAlbedoTable();
    const V e00 = hn::GatherIndex(d, t, i0), s00 = hn::GatherIndex(d, t + 1, i0);
    const V e01 = hn::GatherIndex(d, t + 2, i0), s01 = hn::GatherIndex(d, t + 3, i0);
    const V e10 = hn::GatherIndex(d, t, i1), s10 = hn::GatherIndex(d, t + 1, i1);
    const V e11 = hn::GatherIndex(d, t + 2, i1), s11 = hn::GatherIndex(d, t + 3, i1);
    const V e0 = hn::MulAdd(e01 - e00, fx, e00), e1 = hn::MulAdd(e11 - e10, fx, e10);
    const V s0 = hn::MulAdd(s01 - s00, fx, s00), s1 = hn::MulAdd(s11 - s10, fx, s10);
    e = hn::MulAdd(e1 - e0, fy, e0);
    es = hn::MulAdd(s1 - s0, fy, s0);
}

/// multiScatterFresnel() (BRDF.h).
HWY_INLINE V multiScatterFresnel(D d, V f0, V f90, V eAvg) {
    const V one = hn::Set(d, 1.f);
    const V fAvg = hn::MulAdd(f90 - f0, hn::Set(d, 1.f / 21.f), f0);
    return hn::Div(fAvg * fAvg * eAvg, hn::NegMulAdd(fAvg, one - eAvg, one));
}

/// BrdfVertex (BRDF.h, with its BrdfLobes) for one path per lane.
struct VertexV {
    FrameV frame;
    V3 wo, f0, msScale, diffuseScale, dielectricF0, layerE, layerEs, layerC;
    V f90, dielectricF90;
    V alpha, a2, pSpec, invA2, invPiA2, smithWo, specPdfScale;
    hn::Vec<hn::RebindToSigned<D>> row;  ///< the roughness row of the albedo table (2 kBrdfTableSize y)
    V rowFrac;
    M valid;
};

/// makeBrdfVertex() and makeBrdfLobes() (BRDF.h).
HWY_INLINE void makeVertex(D d, const V3& n, const V3& woW, const V3& base, V metallic, V roughness,
                           const V3& specularF0, V specularF90, bool multiScatter, bool withPdf, VertexV& v) {
    const V one = hn::Set(d, 1.f), zero = hn::Zero(d), invPi = hn::Set(d, kInvPi);
    v.frame = makeFrame(d, n);
    v.wo = v.frame.toLocal(woW);
    v.valid = hn::Gt(v.wo.z, zero);
    const V m = metallic, oneMinusM = one - metallic;
    v.f0 = {hn::MulAdd(base.x - specularF0.x, m, specularF0.x), hn::MulAdd(base.y - specularF0.y, m, specularF0.y),
            hn::MulAdd(base.z - specularF0.z, m, specularF0.z)};
    v.f90 = hn::MulAdd(one - specularF90, m, specularF90);
    v.dielectricF0 = specularF0;
    v.dielectricF90 = specularF90;
    const hn::RebindToSigned<D> di;
    const auto rowCell = tableCell(d, roughness, v.rowFrac);
    v.row = rowCell * hn::Set(di, 2 * kBrdfTableSize);
    V eo, eso;
    ggxAlbedo(d, v.row, v.rowFrac, hn::Min(v.wo.z, one), eo, eso);
    // ggxAlbedoAverage(): the pairs of the row and of the next.
    const auto ia = hn::ShiftLeft<1>(rowCell);
    const float* avg = ggxAlbedoAvgTable();
    const V ea0 = hn::GatherIndex(d, avg, ia), sa0 = hn::GatherIndex(d, avg + 1, ia);
    const V ea1 = hn::GatherIndex(d, avg + 2, ia), sa1 = hn::GatherIndex(d, avg + 3, ia);
    const V eAvg = hn::MulAdd(ea1 - ea0, v.rowFrac, ea0), esAvg = hn::MulAdd(sa1 - sa0, v.rowFrac, sa0);
    const V lossAvg = one - eAvg;
    const M compensate = multiScatter ? hn::Gt(lossAvg, hn::Set(d, 1e-5f)) : hn::FirstN(d, 0);
    const V safeLoss = hn::IfThenElse(compensate, lossAvg, one);
    // The dielectric layer's albedo per channel, Ed(mu) = f0 (E - Es) + f90 Es + FmsLayer (1 - E).
    const V3 fmsLayer = {hn::IfThenElseZero(compensate, multiScatterFresnel(d, specularF0.x, specularF90, eAvg)),
                         hn::IfThenElseZero(compensate, multiScatterFresnel(d, specularF0.y, specularF90, eAvg)),
                         hn::IfThenElseZero(compensate, multiScatterFresnel(d, specularF0.z, specularF90, eAvg))};
    v.layerE = sub(specularF0, fmsLayer);
    v.layerEs = {specularF90 - specularF0.x, specularF90 - specularF0.y, specularF90 - specularF0.z};
    v.layerC = fmsLayer;
    const V3 diffuseOut = {hn::Max(one - hn::MulAdd(v.layerE.x, eo, hn::MulAdd(v.layerEs.x, eso, v.layerC.x)), zero),
                           hn::Max(one - hn::MulAdd(v.layerE.y, eo, hn::MulAdd(v.layerEs.y, eso, v.layerC.y)), zero),
                           hn::Max(one - hn::MulAdd(v.layerE.z, eo, hn::MulAdd(v.layerEs.z, eso, v.layerC.z)), zero)};
    const V3 diffuse = scale(base, oneMinusM * invPi);
    V3 fms = {zero, zero, zero};
    if (multiScatter) {
        fms = {hn::MulAdd(oneMinusM, fmsLayer.x,
                          hn::IfThenElseZero(compensate, m * multiScatterFresnel(d, base.x, one, eAvg))),
               hn::MulAdd(oneMinusM, fmsLayer.y,
                          hn::IfThenElseZero(compensate, m * multiScatterFresnel(d, base.y, one, eAvg))),
               hn::MulAdd(oneMinusM, fmsLayer.z,
                          hn::IfThenElseZero(compensate, m * multiScatterFresnel(d, base.z, one, eAvg)))};
        // diffuse (1 - Ed(mu_o)) / (1 - Ed_avg), per channel; 0 where the layer reflects everything.
        auto scaled = [&](V dc, V out, V le, V les, V lc) {
            const V layerAvg = hn::MulAdd(le, eAvg, hn::MulAdd(les, esAvg, lc));
            const M below1 = hn::Lt(layerAvg, one);
            return hn::IfThenElseZero(below1, dc * hn::Div(out, hn::IfThenElse(below1, one - layerAvg, one)));
        };
        v.diffuseScale = {scaled(diffuse.x, diffuseOut.x, v.layerE.x, v.layerEs.x, v.layerC.x),
                          scaled(diffuse.y, diffuseOut.y, v.layerE.y, v.layerEs.y, v.layerC.y),
                          scaled(diffuse.z, diffuseOut.z, v.layerE.z, v.layerEs.z, v.layerC.z)};
    } else {
        v.diffuseScale = diffuse;
    }
    v.msScale = scale(fms, hn::Div((one - eo) * invPi, safeLoss));
    v.alpha = hn::Max(roughness * roughness, hn::Set(d, kMinAlpha));
    v.a2 = v.alpha * v.alpha;
    v.smithWo = hn::Sqrt(hn::MulAdd(one - v.a2, v.wo.z * v.wo.z, v.a2));
    v.invA2 = hn::Div(one, v.a2);
    v.invPiA2 = v.invA2 * invPi;
    if (!withPdf) {  // makeBrdfVertex(withPdf = false): only f is wanted
        v.pSpec = v.specPdfScale = zero;
        return;
    }
    // Lobe selection: the GGX lobe's albedo against the others'.
    const V3 specAlbedo = {hn::MulAdd(v.f0.x, eo - eso, v.f90 * eso), hn::MulAdd(v.f0.y, eo - eso, v.f90 * eso),
                           hn::MulAdd(v.f0.z, eo - eso, v.f90 * eso)};
    const V spec = luminance(d, specAlbedo);
    const V other = hn::MulAdd(luminance(d, fms), one - eo, oneMinusM * luminance(d, mul(base, diffuseOut)));
    const V ratio = hn::Min(hn::Max(hn::Div(spec, spec + other), hn::Set(d, 0.1f)), hn::Set(d, 0.9f));
    v.pSpec = hn::IfThenElse(hn::Gt(other, zero), ratio, one);
    v.specPdfScale = hn::Div(v.pSpec, hn::Set(d, 2.f) * (v.wo.z + v.smithWo));
}

/// evalBrdfVertexLocal() (BRDF.h): f and the mixture pdf for a local wi; both 0 where the vertex is invalid.
HWY_INLINE void evalVertex(D d, const VertexV& v, const V3& wi, bool multiScatter, V3& f, V& pdf) {
    const V one = hn::Set(d, 1.f), zero = hn::Zero(d);
    const V3 hs = add(v.wo, wi);
    const V lenSq = dot(hs, hs);
    const M lenOk = hn::Gt(lenSq, hn::Set(d, 1e-12f));
    const V ts = hn::MulAdd(hn::MulAdd(hs.x, hs.x, hs.y * hs.y), v.invA2, hs.z * hs.z);
    const V ts2 = hn::IfThenElseZero(hn::And(lenOk, hn::Gt(hs.z, zero)), ts * ts);
    const M tsOk = hn::Gt(ts2, zero);
    const V lenSq2 = lenSq * lenSq;
    const M below = hn::Le(wi.z, zero);
    const V pdfBelow = hn::IfThenElseZero(tsOk, v.specPdfScale * hn::Div(v.invPiA2 * lenSq2, ts2));
    const V g = hn::MulAdd(wi.z, v.smithWo, v.wo.z * hn::Sqrt(hn::MulAdd(wi.z * wi.z, one - v.a2, v.a2)));
    const V r = hn::IfThenElseZero(tsOk, hn::Div(v.invPiA2 * lenSq2, ts2 * g));
    const V D_ = r * g, DV = hn::Set(d, 0.5f) * r;
    const V VdotH = hn::IfThenElseZero(lenOk, hn::Sqrt(hn::Set(d, 0.5f) * hn::Abs(dot(v.wo, hs))));
    const V pdfAbove = hn::MulAdd(v.specPdfScale, D_, (one - v.pSpec) * (wi.z * hn::Set(d, kInvPi)));
    const V w = schlickWeight(d, VdotH);
    // otherLobes(): multiple scattering and diffuse.
    V3 other;
    if (multiScatter) {
        V ei, esi;
        ggxAlbedo(d, v.row, v.rowFrac, hn::Min(wi.z, one), ei, esi);
        const V msIn = one - ei;
        auto diffuseIn = [&](V le, V les, V lc) {
            return hn::Max(one - hn::MulAdd(le, ei, hn::MulAdd(les, esi, lc)), zero);
        };
        other = {hn::MulAdd(v.msScale.x, msIn, v.diffuseScale.x * diffuseIn(v.layerE.x, v.layerEs.x, v.layerC.x)),
                 hn::MulAdd(v.msScale.y, msIn, v.diffuseScale.y * diffuseIn(v.layerE.y, v.layerEs.y, v.layerC.y)),
                 hn::MulAdd(v.msScale.z, msIn, v.diffuseScale.z * diffuseIn(v.layerE.z, v.layerEs.z, v.layerC.z))};
    } else {
        const V f90w = v.dielectricF90 * w;
        other = {v.diffuseScale.x * (one - hn::MulAdd(v.dielectricF0.x, one - w, f90w)),
                 v.diffuseScale.y * (one - hn::MulAdd(v.dielectricF0.y, one - w, f90w)),
                 v.diffuseScale.z * (one - hn::MulAdd(v.dielectricF0.z, one - w, f90w))};
    }
    const M above = hn::And(v.valid, hn::Not(below));
    f.x = hn::IfThenElseZero(above, hn::MulAdd(hn::MulAdd(v.f90 - v.f0.x, w, v.f0.x), DV, other.x));
    f.y = hn::IfThenElseZero(above, hn::MulAdd(hn::MulAdd(v.f90 - v.f0.y, w, v.f0.y), DV, other.y));
    f.z = hn::IfThenElseZero(above, hn::MulAdd(hn::MulAdd(v.f90 - v.f0.z, w, v.f0.z), DV, other.z));
    pdf = hn::IfThenElseZero(v.valid, hn::IfThenElse(below, pdfBelow, pdfAbove));
}

/// sampleBrdfVertex()'s direction (BRDF.h): GGX visible normals or the cosine-weighted hemisphere, by uLobe.
HWY_INLINE V3 sampleDirection(D d, const VertexV& v, V u0, V u1, V uLobe) {
    const V one = hn::Set(d, 1.f), zero = hn::Zero(d), half = hn::Set(d, 0.5f);
    // sampleGgxVndf().
    const V3 vh = normalize(d, {v.alpha * v.wo.x, v.alpha * v.wo.y, v.wo.z});
    const V lenSq = hn::MulAdd(vh.x, vh.x, vh.y * vh.y);
    const M tilted = hn::Gt(lenSq, zero);
    const V invLen = hn::Div(one, hn::Sqrt(hn::IfThenElse(tilted, lenSq, one)));
    const V3 t1 = {hn::IfThenElse(tilted, hn::Neg(vh.y) * invLen, one), hn::IfThenElseZero(tilted, vh.x * invLen),
                   zero};
    const V3 t2 = cross(vh, t1);
    const V r = hn::Sqrt(u0);
    V c, s;
    cosSinTurn(d, u1, c, s);
    const V p1 = r * c;
    const V sv = half * (one + vh.z);
    const V p2 = hn::MulAdd(one - sv, hn::Sqrt(hn::Max(hn::NegMulAdd(p1, p1, one), zero)), sv * r * s);
    const V3 nh = add(add(scale(t1, p1), scale(t2, p2)),
                      scale(vh, hn::Sqrt(hn::Max(hn::NegMulAdd(p2, p2, hn::NegMulAdd(p1, p1, one)), zero))));
    const V3 h = normalize(d, {v.alpha * nh.x, v.alpha * nh.y, hn::Max(nh.z, zero)});
    const V3 specDir = normalize(d, sub(scale(h, hn::Set(d, 2.f) * dot(v.wo, h)), v.wo));
    // sampleCosineHemisphere() through sampleConcentricDisk().
    const V a = hn::MulSub(hn::Set(d, 2.f), u0, one), b = hn::MulSub(hn::Set(d, 2.f), u1, one);
    const M useA = hn::Gt(hn::Abs(a), hn::Abs(b));
    const V num = hn::IfThenElse(useA, b, a), den = hn::IfThenElse(useA, a, b);
    const M centre = hn::Eq(den, zero);  // a = b = 0
    const V x =
        hn::IfThenElseZero(hn::Not(centre), hn::Set(d, 0.25f * kPi) * hn::Div(num, hn::IfThenElse(centre, one, den)));
    V cq, sq;
    cosSinQuarter(d, x, cq, sq);
    const V dx = den * hn::IfThenElse(useA, cq, sq), dy = den * hn::IfThenElse(useA, sq, cq);
    const V3 cosDir = {dx, dy, hn::Sqrt(hn::Max(one - dx * dx - dy * dy, zero))};
    return select(hn::Lt(uLobe, v.pSpec), specDir, cosDir);
}

// One batch's inputs and outputs, one path per lane (structure of arrays).
struct Batch {
    HWY_ALIGN float n[3][kMaxShadeLanes], fn[3][kMaxShadeLanes], wo[3][kMaxShadeLanes], base[3][kMaxShadeLanes];
    HWY_ALIGN float metallic[kMaxShadeLanes], roughness[kMaxShadeLanes];
    HWY_ALIGN float specularF0[3][kMaxShadeLanes], specularF90[kMaxShadeLanes];
    HWY_ALIGN float lightDir[3][kMaxShadeLanes], lightLi[3][kMaxShadeLanes], lightPdf[kMaxShadeLanes];
    HWY_ALIGN float throughput[3][kMaxShadeLanes];
    HWY_ALIGN float u[4][kMaxShadeLanes];  // BRDF direction (2), lobe, Russian roulette
    HWY_ALIGN float lightOk[kMaxShadeLanes], misWeighted[kMaxShadeLanes], scatter[kMaxShadeLanes],
        roulette[kMaxShadeLanes];
    // Outputs.
    HWY_ALIGN float shadow[kMaxShadeLanes], contrib[3][kMaxShadeLanes];
    HWY_ALIGN float next[kMaxShadeLanes], newThroughput[3][kMaxShadeLanes], dir[3][kMaxShadeLanes], pdf[kMaxShadeLanes];
    float lightDistance[kMaxShadeLanes];
};

HWY_INLINE V3 load3(D d, const float (&a)[3][kMaxShadeLanes]) {
    return {hn::Load(d, a[0]), hn::Load(d, a[1]), hn::Load(d, a[2])};
}
HWY_INLINE void store3(D d, const V3& v, float (&a)[3][kMaxShadeLanes]) {
    hn::Store(v.x, d, a[0]);
    hn::Store(v.y, d, a[1]);
    hn::Store(v.z, d, a[2]);
}
HWY_INLINE M flag(D d, const float* a) {
    return hn::Ne(hn::Load(d, a), hn::Zero(d));
}
HWY_INLINE void set3(float (&a)[3][kMaxShadeLanes], uint32_t lane, glm::vec3 v) {
    a[0][lane] = v.x;
    a[1][lane] = v.y;
    a[2][lane] = v.z;
}
HWY_INLINE glm::vec3 get3(const float (&a)[3][kMaxShadeLanes], uint32_t lane) {
    return {a[0][lane], a[1][lane], a[2][lane]};
}

/// The vector part: everything after the light sample, for every lane of the batch.
void shadeBatch(Batch& b, bool multiScatter) {
    const D d;
    const V zero = hn::Zero(d), one = hn::Set(d, 1.f);
    const V3 n = load3(d, b.n), fn = load3(d, b.fn), wo = load3(d, b.wo), base = load3(d, b.base);
    const V3 tp = load3(d, b.throughput);
    // The sampling pdf is needed where a lane scatters or weights its light sample by MIS; neither happens at a
    // last vertex (the lanes of a batch are at the same bounce: the wavefront advances every path by one vertex per
    // round).
    const bool scatters = !hn::AllFalse(d, flag(d, b.scatter));
    const bool withPdf = scatters || !hn::AllFalse(d, flag(d, b.misWeighted));
    VertexV v;  // filled in place: returned by value, its 25 vectors were copied through memory
    makeVertex(d, n, wo, base, hn::Load(d, b.metallic), hn::Load(d, b.roughness), load3(d, b.specularF0),
               hn::Load(d, b.specularF90), multiScatter, withPdf, v);

    // Next-event estimation.
    const V3 wl = load3(d, b.lightDir), Li = load3(d, b.lightLi);
    const V lightPdf = hn::Load(d, b.lightPdf);
    const V cosI = dot(n, wl);
    const M lightOk =
        hn::And(hn::And(flag(d, b.lightOk), hn::Gt(cosI, zero)), hn::And(hn::Gt(dot(fn, wl), zero), nonZero(d, Li)));
    V3 f;
    V bsdfPdf;
    evalVertex(d, v, v.frame.toLocal(wl), multiScatter, f, bsdfPdf);
    const M shadow = hn::And(lightOk, nonZero(d, f));
    const V safeLightPdf = hn::IfThenElse(shadow, lightPdf, one);
    const V wOverPdf = hn::IfThenElse(flag(d, b.misWeighted),
                                      hn::Div(safeLightPdf, hn::MulAdd(safeLightPdf, safeLightPdf, bsdfPdf * bsdfPdf)),
                                      hn::Div(one, safeLightPdf));
    const V3 contrib = scale(mul(scale(mul(tp, f), cosI), Li), wOverPdf);
    hn::Store(hn::IfThenElseZero(shadow, one), d, b.shadow);
    store3(d, contrib, b.contrib);

    // The BRDF sample, for the lanes that scatter.
    if (!scatters) {
        hn::Store(zero, d, b.next);
        return;
    }
    const V3 local = sampleDirection(d, v, hn::Load(d, b.u[0]), hn::Load(d, b.u[1]), hn::Load(d, b.u[2]));
    const V3 wi = v.frame.toWorld(local);
    const V3 wiL = v.frame.toLocal(wi);  // as the light-sample evaluation sees a world direction
    V3 fs;
    V pdf;
    evalVertex(d, v, wiL, multiScatter, fs, pdf);
    const M sampled =
        hn::And(hn::And(flag(d, b.scatter), hn::Gt(wiL.z, zero)),
                hn::And(hn::And(hn::Gt(pdf, zero), hn::Lt(pdf, hn::Set(d, std::numeric_limits<float>::infinity()))),
                        hn::Gt(dot(fn, wi), zero)));
    const V3 weight = scale(fs, hn::Div(wiL.z, hn::IfThenElse(sampled, pdf, one)));
    V3 tpNew = mul(tp, weight);
    // Russian roulette: survivors are reweighted by 1 / q.
    const M roulette = flag(d, b.roulette);
    const V q = hn::Min(hn::Max(hn::Max(tpNew.x, tpNew.y), tpNew.z), hn::Set(d, 0.95f));
    const M survives = hn::Or(hn::Not(roulette), hn::Lt(hn::Load(d, b.u[3]), q));
    tpNew = select(roulette, scale(tpNew, hn::Div(one, hn::IfThenElse(hn::Gt(q, zero), q, one))), tpNew);
    // Scalar code divides by q; a division and a multiplication by 1 / q differ by rounding only.
    const M next = hn::And(hn::And(sampled, survives), nonZero(d, tpNew));
    hn::Store(hn::IfThenElseZero(next, one), d, b.next);
    store3(d, tpNew, b.newThroughput);
    store3(d, wi, b.dir);
    hn::Store(pdf, d, b.pdf);
}

/// Lane contents for a path that does not scatter (ended, or padding): harmless values, every flag off.
void fillIdle(Batch& b, uint32_t lane) {
    for (int c = 0; c < 3; ++c) {
        b.n[c][lane] = b.fn[c][lane] = b.wo[c][lane] = b.lightDir[c][lane] = c == 2 ? 1.f : 0.f;
        b.base[c][lane] = 0.5f;
        b.lightLi[c][lane] = b.throughput[c][lane] = 0.f;
    }
    b.metallic[lane] = 0.f;
    b.roughness[lane] = 0.5f;
    for (int c = 0; c < 3; ++c) b.specularF0[c][lane] = kDielectricF0;
    b.specularF90[lane] = 1.f;
    b.lightPdf[lane] = 1.f;
    for (auto& u : b.u) u[lane] = 0.5f;
    b.lightOk[lane] = b.misWeighted[lane] = b.scatter[lane] = b.roulette[lane] = 0.f;
    b.lightDistance[lane] = 0.f;
}

}  // namespace

uint32_t shadeLanes() {
    return uint32_t(hn::Lanes(D()));
}

template <uint32_t F>
void shadeVerticesSimd(PathState* paths, const RayHit* hits, const uint32_t* idx, uint32_t count,
                       const SceneView& scene, const LightsView& lights, const PathTracerSettings& set,
                       uint32_t* requests, bool skipIdle) {
    const uint32_t lanes = shadeLanes();
    Batch b;
    bool active[kMaxShadeLanes] = {};
    // Scalar part, as shadeVertex() begins: emission, the surface, random numbers, the light sample.
    for (uint32_t j = 0; j < lanes; ++j) {
        if (j >= count) {
            fillIdle(b, j);
            continue;
        }
        PathState& st = paths[idx[j]];
        SurfaceHit s;
        if (!shadeEmission<F>(st, hits[idx[j]], scene, lights, set, s)) {
            fillIdle(b, j);
            continue;
        }
        active[j] = true;
        const uint32_t bounce = st.bounce;
        PathRng& rng = st.rng;
        rng.startBounce(bounce);
        const glm::vec3 wo = -st.rayDir;
        const ScatterFrame sf = scatterFrame(s, wo);
        st.rayOrigin = sf.p;
        const bool last = isLastVertex(bounce, set, s.roughness);
        // The same numbers in the same dimensions as shadeVertex() draws them.
        const glm::vec2 l01 = rng.next2(), l23 = rng.next2(), b01 = rng.next2();
        const float uLobe = rng.next(), uRoulette = rng.next();
        const LightSample ls = sampleLight(lights, sf.p, l01.x, l01.y, l23.x, l23.y);
        const glm::vec3 Li = ls.valid ? lightSampleRadiance<F>(scene, ls, sf.n, sf.fn) : glm::vec3(0.f);
        set3(b.n, j, sf.n);
        set3(b.fn, j, sf.fn);
        set3(b.wo, j, wo);
        set3(b.base, j, s.baseColor);
        const BrdfInputs in = brdfInputs(s, set.multiScatter);
        b.metallic[j] = in.metallic;
        b.roughness[j] = in.roughness;
        set3(b.specularF0, j, in.specularF0);
        b.specularF90[j] = in.specularF90;
        set3(b.lightDir, j, ls.valid ? ls.wi : glm::vec3(0.f, 0.f, 1.f));
        set3(b.lightLi, j, Li);
        b.lightPdf[j] = ls.valid ? ls.pdf : 1.f;
        b.lightDistance[j] = ls.distance;
        b.lightOk[j] = ls.valid ? 1.f : 0.f;
        b.misWeighted[j] = (!ls.delta && !last) ? 1.f : 0.f;
        set3(b.throughput, j, st.throughput);
        b.u[0][j] = b01.x;
        b.u[1][j] = b01.y;
        b.u[2][j] = uLobe;
        b.u[3][j] = uRoulette;
        b.scatter[j] = last ? 0.f : 1.f;
        b.roulette[j] = bounce + 1 >= set.rrStartBounce ? 1.f : 0.f;
    }

    // Every path ended here (a batch of misses): nothing to shade, no ray to ask for.
    if (skipIdle && std::none_of(active, active + lanes, [](bool a) { return a; })) {
        std::fill(requests, requests + count, 0u);
        return;
    }
    shadeBatch(b, set.multiScatter);

    // Back into the paths, as shadeVertex() leaves them.
    for (uint32_t j = 0; j < count; ++j) {
        requests[j] = 0u;
        if (!active[j]) continue;
        PathState& st = paths[idx[j]];
        if (b.shadow[j] != 0.f) {
            ++st.r.rays;
            st.shadowDir = get3(b.lightDir, j);
            st.shadowTMax = shadowRayTMax(b.lightDistance[j]);
            st.shadowContrib =
                st.bounce == 0 ? get3(b.contrib, j) : clampIndirect(get3(b.contrib, j), set.indirectClamp);
            st.shadowNearSurface = st.bounce == 0;
            requests[j] |= kShadowRay;
        }
        if (b.next[j] != 0.f) {
            st.throughput = get3(b.newThroughput, j);
            st.prevBsdfPdf = b.pdf[j];
            st.prevDelta = false;
            st.rayDir = get3(b.dir, j);
            st.bounce += 1;
            ++st.r.rays;
            requests[j] |= kNextRay;
        }
    }
}

template void shadeVerticesSimd<kAllFeatures>(PathState*, const RayHit*, const uint32_t*, uint32_t, const SceneView&,
                                              const LightsView&, const PathTracerSettings&, uint32_t*, bool);
template void shadeVerticesSimd<0u>(PathState*, const RayHit*, const uint32_t*, uint32_t, const SceneView&,
                                    const LightsView&, const PathTracerSettings&, uint32_t*, bool);

}  // namespace loom::pt
