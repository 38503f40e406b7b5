// Lane-index vectors for the Highway translation units. Include it after <hwy/highway.h>; in a unit compiled once
// per target (foreach_target) it is included once per target, hence the toggling include guard of Highway's -inl
// headers.
#if defined(LOOM_SIMD_LANE_INDEX_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef LOOM_SIMD_LANE_INDEX_INL_H_
#undef LOOM_SIMD_LANE_INDEX_INL_H_
#else
#define LOOM_SIMD_LANE_INDEX_INL_H_
#endif

#include <hwy/highway.h>

#include <cstdint>

HWY_BEFORE_NAMESPACE();
namespace loom::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;

/// first, first + 1, ... in the lanes of a vector of 32-bit lanes (at most 16). Highway's Iota (1.0) writes its lanes
/// to the stack one by one and loads them back, which stalls the load on the stores; this adds `first` to a
/// constant.
template <class D, typename T>
HWY_INLINE hn::Vec<D> firstPlusLane(D d, T first) {
    static_assert(sizeof(hn::TFromD<D>) == 4, "32-bit lanes");
    static_assert(hn::MaxLanes(D()) <= 16, "at most 16 lanes");
    alignas(64) static constexpr int32_t kLane[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
    const hn::RebindToSigned<D> di;
    const auto lane = hn::Load(di, kLane);
    if constexpr (hwy::IsFloat<hn::TFromD<D>>())
        return hn::Add(hn::ConvertTo(d, lane), hn::Set(d, hn::TFromD<D>(first)));
    else
        return hn::Add(lane, hn::Set(d, hn::TFromD<D>(first)));
}

}  // namespace loom::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_SIMD_LANE_INDEX_INL_H_
