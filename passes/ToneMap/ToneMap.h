#pragma once
// ToneMap: HDR colour to display colour. Exposure compensation in EV, optional
// auto exposure (Reinhard 2002 log-average luminance, adapted over time), one
// of five operators (see ToneMapKernels.h), and an exact 8-bit sRGB encoding.
//
// Fields (declared whatever the parameters):
//   src               input   RGBA32F  scene-referred colour
//   dst               output  RGBA8Srgb  tone-mapped, sRGB-encoded (exact OETF, round to nearest)
//   dstFloat          output  RGBA32F  optional: tone-mapped, still linear, in [0, 1]; computed
//                                      only when consumed
//   adaptedLuminance  history RGBA32F 1x1: x the adapted luminance the exposure follows (0 while
//                                      auto exposure is off), y this frame's measured log-average
//                                      luminance, z + w the frame time in seconds (a float pair
//                                      whose sum is the double time), so the time step needs no
//                                      state in the pass.
//
// Auto exposure, frame by frame: with valid history and adaptationTime > 0 a
// frame is exposed by the luminance adapted up to the previous frame, and its
// own log-average is measured while it is mapped (one read of src); the
// adapted luminance then moves towards it,
//   L(t + dt) = Lmeasured + (L(t) - Lmeasured) exp(-dt / adaptationTime).
// On the first frame, after a reset, with adaptationTime 0 or when time runs
// backwards, src is measured first and the frame is exposed by its own
// log-average (immediate adaptation). The scale is 2^EV * key / L. The
// log-average is measured on every 4th row (y % 4 == 0; see ToneMapKernels.h).
//
// The CPU path (ToneMap.cpp) runs 8 pixels per AVX2 vector (Google Highway)
// and gives the same bits as the per-pixel kernels (`reference` runs those).
// On emulated and cuda the per-pixel kernels run through launch2D and the
// log-average through reduceRows (ToneMapDevice.h): the same mapping, and the
// log-average summed in another order (a last-bit difference in its double).
#include <memory>

#include "ToneMapKernels.h"
#include "loom/RenderPass.h"
#include "loom/Texture.h"

namespace loom {

class ToneMapPass final : public RenderPass {
public:
    using Operator = tonemap::Operator;

    ToneMapPass();
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    /// cpu (the vector path) and emulated always; cuda where nvcc compiled ToneMapDevice.cpp.
    bool runsOn(DeviceKind device) const override;
    void execute(PassContext& ctx) override;

private:
    /// Log-average luminance of src over the finite pixels of its measured rows (deterministic: per-band sums added
    /// in band order);
    /// returns false when no pixel is finite.
    bool measureLogAverage(const Texture& src, double& logAverage) const;

    // Parameters.
    tonemap::ToneMapParams mMapping;  ///< op: the operator parameter, whose default the kernel's struct holds; the
                                      ///< other members are each frame's (execute)
    float mExposureEv = 0.f;
    bool mAutoExposure = false;
    float mKey = 0.18f;
    float mAdaptationTime = 1.f;
    float mWhitePoint = 4.f;
    bool mReference = false;

    std::unique_ptr<SrgbEncodeTable> mSrgbTable;
    Texture mDeviceSrgbTable;  ///< mSrgbTable in the memory of the device the pass last ran on (not the host)
};

}  // namespace loom
