// Plane stores and non-temporal (streaming) stores for the Highway translation units. Include it after
// <hwy/highway.h>; in a unit compiled once per target (foreach_target) it is included once per target, hence the
// toggling include guard of Highway's -inl headers.
#if defined(LOOM_SIMD_STREAM_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef LOOM_SIMD_STREAM_INL_H_
#undef LOOM_SIMD_STREAM_INL_H_
#else
#define LOOM_SIMD_STREAM_INL_H_
#endif

#include <hwy/highway.h>

#include <cstddef>

#include "loom/KernelMath.h"

HWY_BEFORE_NAMESPACE();
namespace loom::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;

/// A plane store; kStream: a non-temporal store (p aligned to the vector), which skips the read for ownership.
template <bool kStream, class D, class V>
HWY_INLINE void storePlane(D d, V v, float* p) {
    if constexpr (kStream)
        hn::Stream(v, d, p);
    else
        hn::StoreU(v, d, p);
}

/// Non-temporal stores of n floats (a multiple of N) from src to dst, whole cache lines that are not read again
/// soon: no read-for-ownership of the destination, which halves their memory traffic. dst is aligned to the vector.
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

}  // namespace loom::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_SIMD_STREAM_INL_H_
