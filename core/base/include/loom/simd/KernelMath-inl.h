// Lane-wise forms of loom/KernelMath.h for the Highway translation units, with its constants. Include it after
// <hwy/highway.h>; in a unit compiled once per target (foreach_target) it is included once per target, hence the
// toggling include guard of Highway's -inl headers.
//
// Each function names the order of its operations: a vector loop that reproduces a scalar kernel bit for bit calls
// the form that kernel rounds as (see KernelMath.h), and a translation unit's -ffp-contract setting applies to these
// as to its own code.
#if defined(LOOM_SIMD_KERNEL_MATH_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef LOOM_SIMD_KERNEL_MATH_INL_H_
#undef LOOM_SIMD_KERNEL_MATH_INL_H_
#else
#define LOOM_SIMD_KERNEL_MATH_INL_H_
#endif

#include <hwy/highway.h>

#include "loom/KernelMath.h"

HWY_BEFORE_NAMESPACE();
namespace loom::simd::HWY_NAMESPACE {

namespace hn = hwy::HWY_NAMESPACE;

/// Rec. 709 luminance as three products and two sums, (R r + G g) + B b: luminance() where nothing is contracted.
template <class D, class V>
HWY_INLINE V luminanceSum(D d, V r, V g, V b) {
    return hn::Add(hn::Add(hn::Mul(hn::Set(d, kLuminanceR), r), hn::Mul(hn::Set(d, kLuminanceG), g)),
                   hn::Mul(hn::Set(d, kLuminanceB), b));
}

/// Rec. 709 luminance as fma(B, b, fma(G, g, R r)): luminanceFma() lane-wise.
template <class D, class V>
HWY_INLINE V luminanceFma(D d, V r, V g, V b) {
    return hn::MulAdd(hn::Set(d, kLuminanceB), b,
                      hn::MulAdd(hn::Set(d, kLuminanceG), g, hn::Mul(hn::Set(d, kLuminanceR), r)));
}

/// Rec. 709 luminance as fma(R, r, fma(G, g, B b)), blue first: the path tracer's vector shading (within a rounding
/// of luminance()).
template <class D, class V>
HWY_INLINE V luminanceFmaBlueFirst(D d, V r, V g, V b) {
    return hn::MulAdd(hn::Set(d, kLuminanceR), r,
                      hn::MulAdd(hn::Set(d, kLuminanceG), g, hn::Mul(hn::Set(d, kLuminanceB), b)));
}

/// exp2Neg() lane-wise, the same operations: 2^-t for t in [0, 126] (the caller clamps).
template <class D, class V>
HWY_INLINE V exp2Neg(D d, V t) {
    const hn::RebindToSigned<D> di;
    const V magic = hn::Set(d, 12582912.f);  // 1.5 * 2^23
    const V r = hn::Add(t, magic);
    const V f = hn::Sub(hn::Sub(r, magic), t);
    V q = hn::Add(hn::Mul(hn::Set(d, kExp2C4), f), hn::Set(d, kExp2C3));
    q = hn::Add(hn::Mul(q, f), hn::Set(d, kExp2C2));
    q = hn::Add(hn::Mul(q, f), hn::Set(d, kExp2C1));
    q = hn::Add(hn::Mul(q, f), hn::Set(d, kExp2C0));
    return hn::BitCast(d, hn::Sub(hn::BitCast(di, q), hn::ShiftLeft<23>(hn::BitCast(di, r))));
}

/// q(g) ~ 2^g for g in [0, 1) (kExp2UnitC*, Horner's scheme in FMAs): with 2^floor(u) it makes 2^u.
template <class D, class V>
HWY_INLINE V exp2Unit(D d, V g) {
    V q = hn::MulAdd(hn::Set(d, kExp2UnitC4), g, hn::Set(d, kExp2UnitC3));
    q = hn::MulAdd(q, g, hn::Set(d, kExp2UnitC2));
    q = hn::MulAdd(q, g, hn::Set(d, kExp2UnitC1));
    return hn::MulAdd(q, g, hn::Set(d, kExp2UnitC0));
}

}  // namespace loom::simd::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // LOOM_SIMD_KERNEL_MATH_INL_H_
