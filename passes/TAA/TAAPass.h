#pragma once
// TAAPass: temporal anti-aliasing for jittered input (the G-buffer passes'
// Halton or stratified camera jitter): the current frame's 3x3 neighbourhood
// in YCoCg bounds the reprojected history (variance clipping), motion vectors
// are dilated to the longest of the 3x3, history is sampled with Catmull-Rom,
// and the blend is an exponential moving average in linear colour, which keeps
// a light's energy (luminance-weighted anti-flicker and HDR compression are
// optional: both bias a jittered edge towards dark). TAAKernels.h holds the
// per-pixel reference and the formulas with their sources.
//
// Fields (declared whatever the parameters):
//   colorIn       input   RGBA32F  this frame's (jittered) colour
//   mvec          input   RG32F    uvPrev - uvCur, jitter removed (wired by name from the G-buffer)
//   colorOut      output  RGBA32F  the anti-aliased colour
//   colorHistory  history RGBA32F  last frame's colorOut (graph history: dumpable, no state in the pass)
//
// History invalid (first frame, reset, resize, camera cut) or a reprojected
// position outside the frame: the output is the current colour. Non-finite
// input pixels never reach the output or the history.
#include "TAAKernels.h"
#include "TAASimd.h"
#include "loom/RenderPass.h"

namespace loom {

class TAAPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    /// cpu (the tiled vector path) and emulated always; cuda where nvcc compiled TAADevice.cpp. Off the host the
    /// reference kernel runs (the same as `reference` on the CPU, bit for bit).
    bool runsOn(DeviceKind device) const override;
    void execute(PassContext& ctx) override;

    /// Runs the per-pixel reference kernel instead of the tiled CPU path (for tests comparing the two; they agree to
    /// 1e-4 of max(1, |value|), not to the bit).
    void useReferenceKernel(bool on) { mReference = on; }

private:
    static void setStats(PassContext& ctx, const taa::Counts& counts, uint32_t vectorLanes);

    taa::TaaParams mParams;
    bool mReference = false;
    bool mHdrCompress = false;
};

}  // namespace loom
