// Lane-index vectors for the Highway translation units of the passes (TAASimd.cpp, TemporalSimd.cpp). Included once
// per target inside each unit's foreach_target loop, hence the toggling include guard Highway's -inl headers use.
#if defined(LOOM_PASSES_LANE_INDEX_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef LOOM_PASSES_LANE_INDEX_INL_H_
#undef LOOM_PASSES_LANE_INDEX_INL_H_
#else
#define LOOM_PASSES_LANE_INDEX_INL_H_
#endif

#include <hwy/highway.h>

#include <cstdint>

HWY_BEFORE_NAMESPACE();
namespace loom::lanes::HWY_NAMESPACE {

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

}  // namespace loom::lanes::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_PASSES_LANE_INDEX_INL_H_
