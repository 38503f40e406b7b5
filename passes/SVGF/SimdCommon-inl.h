// Vector helpers shared by the Highway translation units of SVGF (AtrousSimd.cpp, TemporalSimd.cpp): the planes'
// packing, over the shared vector math and stores of loom/simd. Included once per target inside each unit's
// foreach_target loop, hence the toggling include guard Highway's -inl headers use.
#if defined(LOOM_SVGF_SIMD_COMMON_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef LOOM_SVGF_SIMD_COMMON_INL_H_
#undef LOOM_SVGF_SIMD_COMMON_INL_H_
#else
#define LOOM_SVGF_SIMD_COMMON_INL_H_
#endif

#include <hwy/highway.h>

#include "AtrousSimd.h"
#include "loom/simd/KernelMath-inl.h"
#include "loom/simd/Stream-inl.h"

HWY_BEFORE_NAMESPACE();
namespace loom::svgf::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;
using ::loom::simd::HWY_NAMESPACE::luminanceFma;
using ::loom::simd::HWY_NAMESPACE::storePlane;
using ::loom::simd::HWY_NAMESPACE::streamInterleaved2;
using ::loom::simd::HWY_NAMESPACE::streamInterleaved4;

/// Non-finite values become 0, magnitudes are clamped to kMagnitudeLimit (as sanitiseScalar).
template <class D, class V>
HWY_INLINE V sanitise(D d, V v) {
    const V limit = hn::Set(d, kMagnitudeLimit);
    return hn::IfThenElseZero(hn::IsFinite(v), hn::Min(hn::Max(v, hn::Neg(limit)), limit));
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
    storePlane<kStream>(d, luminanceFma(d, r, g, b), S.l + o);  // packSignalPixel's operations
}

}  // namespace loom::svgf::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_SVGF_SIMD_COMMON_INL_H_
