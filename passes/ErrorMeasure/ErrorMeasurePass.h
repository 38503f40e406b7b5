#pragma once
// ErrorMeasure: measures `src` against `reference` every frame with the metrics of loom/Metrics.h
// (docs/METRICS.md) and reports them in the frame stats; `dst` is `src` unchanged, so the pass can sit
// in a chain. The optional `error` output is the per-pixel error image of one metric (`errorImage`),
// computed only when something consumes it.
//
// Last frame's src and reference live in the graph history fields `prevSrc` and `prevReference`
// (dumpable); the temporal-derivative error is skipped while history is invalid.
//
// On the emulated and cuda devices (docs/KERNELS.md) dst, the history copies and RelMSE, SMAPE, PSNR and the
// temporal error run as kernels over device memory (ErrorMeasureDevice.h), with the CPU's values bit for bit; SSIM
// and FLIP run their CPU code on host copies of src and the reference (one download of each a frame, and one upload
// of the error image when it holds theirs).
//
// The only state kept in the pass is the running means (a sum, a count and the number of frames seen
// since the reset, per metric). They restart on resetHistory() and whenever graph history is invalid
// (first frame, resize, camera cut).
#include <array>
#include <cstdint>
#include <string>

#include "loom/Metrics.h"
#include "loom/RenderPass.h"

namespace loom {

class ErrorMeasurePass final : public RenderPass {
public:
    enum class Metric { RelMSE, Smape, Psnr, Ssim, Flip };
    static constexpr int kMetricCount = 5;
    /// Running means: the five metrics, then the temporal error.
    static constexpr int kMeanCount = kMetricCount + 1;

    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void compile(const CompileInfo& info) override;
    void execute(PassContext& ctx) override;
    void resetHistory() override;
    bool runsOn(DeviceKind device) const override;

private:
    /// Parses `mMetrics` into mSelected (throws loom::Error, bad input, on an unknown name).
    void parseMetrics(const std::string& where);
    /// Metric m of src against ref on `device` (each texture in its memory); error, where given, gets the image.
    MetricValue measureOnDevice(DeviceKind device, Metric m, const Texture& src, const Texture& ref, Texture* error);

    // Parameters.
    std::string mMetrics;
    Metric mErrorImage = Metric::Flip;
    int mWarmupFrames = 16;
    bool mEnabled = true;

    // The parsed `metrics` list and the string it was parsed from.
    std::array<bool, kMetricCount> mSelected{};
    std::string mParsedMetrics;
    bool mParsed = false;

    // Running-mean counters (reset on resetHistory() and invalid history).
    uint64_t mFramesSeen = 0;
    std::array<double, kMeanCount> mSums{};
    std::array<uint64_t, kMeanCount> mCounts{};

    // On a device: the LDR tone map's table in its memory, and the host copies SSIM and FLIP read (src and reference
    // downloaded once a frame) and write (the error image, uploaded after).
    Texture mToneMapTable;
    Texture mHostSrc, mHostRef, mHostError;
    bool mHostCopiesFresh = false;
};

}  // namespace loom
