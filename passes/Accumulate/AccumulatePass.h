#pragma once
// AccumulatePass: the running mean of its input since the last reset, for
// reference images. All running state lives in graph history fields, so it can
// be dumped (`--dump 'Accumulate.*'`) and survives recompiles like any other
// history.
//
// State (reflection must not depend on parameters, so every precision keeps its
// running sum in the same 32 bytes a pixel, accumulate::packSum; what a precision
// does not use stays zero):
//   sum           RGBA32U  double: the sums of R and G as doubles, each as the
//                          (low, high) 32-bit words of its bits; float, kahan:
//                          the float sum's bits
//   sumExtra      RGBA32U  double: the sums of B and A, as `sum`; kahan: the bits
//                          of the float sum's rounding error (Neumaier); float: 0
//   count         R32U     per pixel: finite samples in the sum. Per pixel so a
//                          skipped non-finite sample leaves the other pixels alone
//   frames        R32U 1x1 frames accumulated since the reset; what maxFrames caps
//
// A new mean starts when the graph resets history (ctx.historyValid() false:
// first frame, resetHistory(), resize, new scene), when `precision` changes,
// when the pass is enabled again, when maxFrames is lowered below `frames`, and,
// with autoReset, when the camera, a scene instance or a punctual light moved, an
// animated light (emission, punctual light) changed, or a parameter of a pass it
// reads from changed value (ctx.inputParamsChanged()), in this frame. Animation
// time itself is not compared: on a still scene it runs on with nothing moving.
//
// With the optional `denoised` input (a denoiser's image of the same frames), dst
// is that image on the first frame after a reset and turns into the mean while
// nothing moves (accumulate::blendDenoised): a graph shows its denoiser in motion
// and converges to the reference when still.
#include <vector>

#include "AccumulateKernels.h"
#include "loom/RenderPass.h"

namespace loom {

class AccumulatePass final : public RenderPass {
public:
    using Precision = accumulate::Precision;

    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    /// cpu and emulated always; cuda where nvcc compiled AccumulateDevice.cpp.
    bool runsOn(DeviceKind device) const override;
    void execute(PassContext& ctx) override;

private:
    /// The partial* outputs, where used: the state after this frame as double sums and counts.
    void writePartial(PassContext& ctx) const;
    /// Has the camera, a scene instance or a punctual light moved, the scene's lighting changed, or a parameter
    /// of a pass upstream changed, in this frame? Call once per frame: it remembers the lights' poses.
    bool sceneMoved(const PassContext& ctx);
    /// Zeroes this frame's side of the history fields the current precision does not use.
    void clearUnusedState(PassContext& ctx) const;

    // Parameters.
    Precision mPrecision = Precision::Double;
    int mMaxFrames = 0;
    bool mAutoReset = true;
    bool mEnabled = true;
    float mDenoisedFrames = 64.f;

    // The precision the state in the history fields was accumulated with: a
    // different one cannot continue it.
    Precision mStatePrecision = Precision::Double;
    // Set while disabled: accumulation restarts when enabled again.
    bool mRestartPending = false;
    // Frames for which the fields of a previous precision still need zeroing
    // (two: both sides of each history pair hold stale values).
    int mStaleFrames = 0;
    // The scene's punctual lights last frame: position and direction of each.
    std::vector<glm::vec3> mLightPoses;
};

}  // namespace loom
