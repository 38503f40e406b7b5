// Vector helpers shared by the Highway translation units of SVGF (AtrousSimd.cpp, TemporalSimd.cpp). Included once
// per target inside each unit's foreach_target loop, hence the toggling include guard Highway's -inl headers use.
#if defined(LOOM_SVGF_SIMD_COMMON_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef LOOM_SVGF_SIMD_COMMON_INL_H_
#undef LOOM_SVGF_SIMD_COMMON_INL_H_
#else
#define LOOM_SVGF_SIMD_COMMON_INL_H_
#endif

#include <hwy/highway.h>

#include "AtrousSimd.h"

HWY_BEFORE_NAMESPACE();
namespace loom::svgf::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;

/// Non-finite values become 0, magnitudes are clamped to kMagnitudeLimit (as sanitiseScalar).
template <class D, class V>
HWY_INLINE V sanitise(D d, V v) {
    const V limit = hn::Set(d, kMagnitudeLimit);
    return hn::IfThenElseZero(hn::IsFinite(v), hn::Min(hn::Max(v, hn::Neg(limit)), limit));
}

/// Rec. 709 luminance with the operations packSignalPixel uses.
template <class D, class V>
HWY_INLINE V luminanceOf(D d, V r, V g, V b) {
    return hn::MulAdd(hn::Set(d, 0.0722f), b, hn::MulAdd(hn::Set(d, 0.7152f), g, hn::Mul(hn::Set(d, 0.2126f), r)));
}

/// A plane store; kStream: a non-temporal store (p aligned to the vector), which skips the read for ownership.
template <bool kStream, class D, class V>
HWY_INLINE void storePlane(D d, V v, float* p) {
    if constexpr (kStream)
        hn::Stream(v, d, p);
    else
        hn::StoreU(v, d, p);
}

/// N pixels of packGuide at plane offset o.
template <bool kStream = false, class D, class V>
HWY_INLINE void storeGuide(D d, const GuidePlanes& G, size_t o, V z, V dz, V nx, V ny, V nz) {
    const V zero = hn::Zero(d);
    storePlane<kStream>(d, hn::IfThenElse(hn::And(hn::IsFinite(z), hn::Ge(z, zero)), z, hn::Set(d, -1.f)), G.z + o);
    storePlane<kStream>(d, hn::IfThenElseZero(hn::And(hn::IsFinite(dz), hn::Gt(dz, zero)), dz), G.dz + o);
    storePlane<kStream>(d, hn::IfThenElseZero(hn::IsFinite(nx), nx), G.nx + o);
    storePlane<kStream>(d, hn::IfThenElseZero(hn::IsFinite(ny), ny), G.ny + o);
    storePlane<kStream>(d, hn::IfThenElseZero(hn::IsFinite(nz), nz), G.nz + o);
}

/// N pixels of packSignal (rgb + variance, sanitised, and the luminance) at plane offset o.
template <bool kStream = false, class D, class V>
HWY_INLINE void storeSignal(D d, const SignalPlanes& S, size_t o, V r, V g, V b, V v) {
    r = sanitise(d, r);
    g = sanitise(d, g);
    b = sanitise(d, b);
    storePlane<kStream>(d, r, S.r + o);
    storePlane<kStream>(d, g, S.g + o);
    storePlane<kStream>(d, b, S.b + o);
    storePlane<kStream>(d, sanitise(d, v), S.v + o);
    storePlane<kStream>(d, luminanceOf(d, r, g, b), S.l + o);
}

}  // namespace loom::svgf::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_SVGF_SIMD_COMMON_INL_H_
