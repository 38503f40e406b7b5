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

/// Non-temporal stores of n floats (a multiple of N) from src to dst, whole cache lines that this frame does not read
/// again soon (history for the next frame, the integrated and estimate images): no read-for-ownership of the
/// destination, which halves their memory traffic. dst is aligned to the vector (the x of a vector group is a
/// multiple of N, rows are 64-byte aligned).
template <class D>
HWY_INLINE void streamCopy(D d, const float* src, float* dst, size_t n) {
    for (size_t i = 0; i < n; i += hn::Lanes(d)) hn::Stream(hn::LoadU(d, src + i), d, dst + i);
}

/// Four channels of N pixels streamed to dst as interleaved RGBA.
template <class D, class V>
HWY_INLINE void streamInterleaved4(D d, V a, V b, V c, V e, float* dst) {
    HWY_ALIGN float lanes[4 * kMaxLanes];
    hn::StoreInterleaved4(a, b, c, e, d, lanes);
    streamCopy(d, lanes, dst, 4 * hn::Lanes(d));
}

/// Two channels of N pixels streamed to dst as interleaved pairs.
template <class D, class V>
HWY_INLINE void streamInterleaved2(D d, V a, V b, float* dst) {
    HWY_ALIGN float lanes[2 * kMaxLanes];
    hn::StoreInterleaved2(a, b, d, lanes);
    streamCopy(d, lanes, dst, 2 * hn::Lanes(d));
}

}  // namespace loom::svgf::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_SVGF_SIMD_COMMON_INL_H_
