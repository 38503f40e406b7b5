#pragma once
// SVGFPass: spatiotemporal variance-guided filtering (Schied et al. 2017, HPG) of a path-traced signal, with
// the paper's parameters. Per frame: demodulation by albedo (emission taken out first), reprojection with
// disocclusion tests, temporal accumulation of colour and luminance moments, a spatial variance estimate while
// history is short, à-trous wavelet levels guided by the variance (AtrousFilter; level `feedbackTap` is next
// frame's colour history), and remodulation. With `direct` and `indirect` connected, the two are filtered
// separately and recombined.
//
// All state lives in graph history fields, so it can be dumped and survives recompiles:
//   illumination          RGBA32F  colour (or direct) history: demodulated rgb, a = variance (feedback tap)
//   illuminationIndirect  RGBA32F  indirect history (split only), same layout
//   moments               RG32F    luminance moments (m1, m2) of colour/direct
//   momentsIndirect       RG32F    luminance moments (m1, m2) of indirect (split only)
//   length                R32F     history length in frames (capped at maxHistory); 0: no history there
//   prevLinearZ, prevNormW, prevMeshId   this frame's guides, for next frame's disocclusion tests; not written when
//                         the graph feeds last frame's G-buffer outputs instead (inputs linearZPrev, normWPrev,
//                         meshIdPrev from "GBuffer.linearZ@prev" ... edges: no copy, as the shipped graphs do)
// The pass object holds only parameters, the à-trous scratch and two maps of this frame that the fused stages pass
// on: which rows hold a short history, and what each group of 16 pixels' remodulation reads.
#include <cstdint>
#include <vector>

#include "Atrous.h"
#include "SVGFKernels.h"
#include "TemporalSimd.h"
#include "loom/RenderPass.h"

namespace loom {

class SVGFPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void compile(const CompileInfo& info) override;
    void execute(PassContext& ctx) override;
    /// cpu (the Highway twins) and emulated always; cuda where the device stages are compiled by nvcc.
    bool runsOn(DeviceKind device) const override;

private:
    struct Pipeline;
    struct Frame;
    Pipeline choosePipeline(const svgf::VarianceScales& scales) const;
    // The stages of a frame, in order (execute).
    void bindFrame(Frame& f);
    void antilagStage(Frame& f);
    /// The history clamp's box of every pixel (svgf::neighbourhoodPixel), when it is on.
    void neighbourhoodStage(Frame& f);
    /// The clamp box's view, empty when the clamp is off or the field is not declared (a gradient input).
    ImageView<glm::vec4> clampBox(PassContext& ctx) const;
    void temporalStage(Frame& f);
    void varianceStage(Frame& f);
    void atrousStage(Frame& f);
    void modulateStage(Frame& f);
    svgf::ModulateViews modulateViews(const Frame& f) const;

    void passThrough(PassContext& ctx) const;
    /// A frame on a device other than the CPU: every stage through launch2D over the scalar kernels (SVGFDevice.h).
    void executeOnDevice(PassContext& ctx);
    /// What the signal is demodulated by: albedo, or albedo + specAlbedo (in an internal image) when connected.
    ImageView<const glm::vec4> demodulationAlbedo(PassContext& ctx) const;
    /// The anti-lag's shading change on last frame's grid from the gradient input (empty without it).
    ImageView<const glm::vec2> shadingChange(PassContext& ctx) const;

    // Parameters.
    bool mEnabled = true;
    bool mTemporal = true;
    int mIterations = 4;
    int mFeedbackTap = -1;
    svgf::TemporalParams mTemporalParams;  ///< alpha, momentsAlpha, maxHistory: the kernel's struct holds the defaults
    svgf::AtrousParams mEdgeStopping;  ///< phiColor, phiNormal, phiDepth: the kernel's struct holds the defaults
    bool mMeanVariance = true;
    /// The history clamp (TemporalParams::clampSigma), where no gradient input is connected.
    bool mHistoryClamp = true;
    bool mReferenceAtrous = false;
    bool mReferenceStages = false;

    // Scratch of the à-trous levels (no state across frames).
    svgf::AtrousFilter mAtrous;
    bool mEstimateObserved = false;    ///< the estimate images are dumped: written for every pixel
    bool mIntegratedObserved = false;  ///< likewise the integrated images
    std::vector<uint8_t> mShortRows;   ///< per row of the frame: a short history in it (the fused stages' shortcut)
    std::vector<uint8_t> mRemodulationGroups;  ///< what the fused remodulation reads (simd::Remodulation::groups)
};

}  // namespace loom
