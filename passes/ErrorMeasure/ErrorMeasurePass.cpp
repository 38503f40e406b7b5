#include "ErrorMeasurePass.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "ErrorMeasureDevice.h"
#include "ErrorMeasureKernels.h"
#include "loom/Error.h"
#include "loom/Metrics.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"

namespace loom {

namespace {

const char kSrc[] = "src";
const char kReference[] = "reference";
const char kDst[] = "dst";
const char kError[] = "error";
const char kPrevSrc[] = "prevSrc";
const char kPrevReference[] = "prevReference";

// Metric names: the `metrics` list, the `errorImage` enum and the stats keys, in Metric order.
const char* const kMetricNames[ErrorMeasurePass::kMetricCount] = {"relMSE", "smape", "psnr", "ssim", "flip"};
const char kStatTemporal[] = "temporal";
const char kStatNonFinite[] = "nonFinite";
const char kStatMeanPrefix[] = "mean.";
const char kStatMeanFrames[] = "meanFrames";

const char kDefaultMetrics[] = "relMSE,smape,psnr,ssim,flip";

std::vector<std::string> metricNames() {
    return {std::begin(kMetricNames), std::end(kMetricNames)};
}

std::string trim(const std::string& s) {
    const auto begin = s.find_first_not_of(" \t");
    if (begin == std::string::npos) return {};
    const auto end = s.find_last_not_of(" \t");
    return s.substr(begin, end - begin + 1);
}

MetricValue measure(ErrorMeasurePass::Metric m, MetricImage test, MetricImage ref, ImageView<float>* image) {
    using Metric = ErrorMeasurePass::Metric;
    switch (m) {
        case Metric::RelMSE:
            return relMSE(test, ref, image);
        case Metric::Smape:
            return smape(test, ref, image);
        case Metric::Psnr:
            return psnr(test, ref, image);
        case Metric::Ssim:
            return ssim(test, ref, image);
        case Metric::Flip:
            return flip(test, ref, image);
    }
    return {};
}

}  // namespace

void ErrorMeasurePass::reflect(Reflection& r, const CompileInfo&) const {
    r.input(kSrc, Format::RGBA32F).doc("image under evaluation, e.g. PathTracer.color (connect with an explicit edge)");
    r.input(kReference, Format::RGBA32F).doc("reference image, e.g. Accumulate.dst (connect with an explicit edge)");
    r.output(kDst, Format::RGBA32F)
        .doc(
            "src unchanged (bit-identical) except non-finite channels, which become 0, so the pass can sit in a chain");
    r.output(kError, Format::R32F)
        .optional()
        .doc("per-pixel error of the metric chosen by errorImage; computed only when consumed");
    r.history(kPrevSrc, Format::RGBA32F).doc("last frame's src, for the temporal-derivative error");
    r.history(kPrevReference, Format::RGBA32F).doc("last frame's reference, for the temporal-derivative error");
}

void ErrorMeasurePass::declareParams(ParamList& p) {
    p.add("metrics", &mMetrics, kDefaultMetrics)
        .doc(
            "comma-separated metrics computed and reported each frame, from relMSE, smape, psnr, ssim, flip "
            "(empty: none; the temporal error is always reported)");
    p.addEnum("errorImage", &mErrorImage, Metric::Flip, metricNames())
        .doc("metric whose per-pixel error image the `error` output holds (computed even when not in metrics)");
    p.add("warmupFrames", &mWarmupFrames, 16)
        .min(0)
        .doc("frames after a reset whose values are left out of the running means (mean.<metric>)");
    p.add("enabled", &mEnabled, true).doc("false: dst is still src, but nothing is measured or reported");
}

void ErrorMeasurePass::parseMetrics(const std::string& where) {
    std::array<bool, kMetricCount> selected{};
    const std::vector<std::string> names = metricNames();
    size_t start = 0;
    while (start <= mMetrics.size()) {
        const size_t comma = std::min(mMetrics.find(',', start), mMetrics.size());
        const std::string name = trim(mMetrics.substr(start, comma - start));
        start = comma + 1;
        if (name.empty()) continue;
        const auto it = std::find(names.begin(), names.end(), name);
        if (it == names.end())
            throwBadInput(where, "unknown metric '" + name + "' in metrics \"" + mMetrics + "\"",
                          "a comma-separated list of: " + join(names), didYouMean(name, names, "metrics"));
        selected[size_t(it - names.begin())] = true;
    }
    mSelected = selected;
    mParsedMetrics = mMetrics;
    mParsed = true;
}

void ErrorMeasurePass::compile(const CompileInfo&) {
    parseMetrics("ErrorMeasure.metrics");
}

void ErrorMeasurePass::resetHistory() {
    mFramesSeen = 0;
    mSums.fill(0.0);
    mCounts.fill(0);
}

bool ErrorMeasurePass::runsOn(DeviceKind device) const {
    return device == DeviceKind::Cpu || errormeasure::deviceRuns(device);
}

MetricValue ErrorMeasurePass::measureOnDevice(DeviceKind device, Metric m, const Texture& src, const Texture& ref,
                                              Texture* error) {
    using namespace errormeasure;
    switch (m) {
        case Metric::RelMSE: {
            const MetricSums s = relMseOnDevice(device, src, ref, error);
            return {cappedMetricMean(s), s.nonFinite};
        }
        case Metric::Smape: {
            const MetricSums s = smapeOnDevice(device, src, ref, error);
            return {metricMean(s), s.nonFinite};
        }
        case Metric::Psnr: {
            if (mToneMapTable.empty() || mToneMapTable.residence() != device)
                mToneMapTable = uploadToneMapTable(device);
            const MetricSums s = psnrOnDevice(device, mToneMapTable, src, ref, error);
            return {psnrOfSums(s), s.nonFinite};
        }
        case Metric::Ssim:
        case Metric::Flip:
            break;
    }
    // SSIM and FLIP run their CPU code (separable filters over tone-mapped planes) on host copies of src and the
    // reference, downloaded once a frame; their error image goes back with one upload.
    if (!mHostCopiesFresh) {
        for (auto [host, image] : {std::pair{&mHostSrc, &src}, std::pair{&mHostRef, &ref}}) {
            if (host->width() != image->width() || host->height() != image->height())
                *host = Texture(image->width(), image->height(), Format::RGBA32F);
            copyTexture(*host, *image);
        }
        mHostCopiesFresh = true;
    }
    if (error && (mHostError.width() != error->width() || mHostError.height() != error->height()))
        mHostError = Texture(error->width(), error->height(), Format::R32F);
    ImageView<float> errorView = error ? mHostError.view<float>() : ImageView<float>{};
    const MetricValue v = measure(m, std::as_const(mHostSrc).view<glm::vec4>(),
                                  std::as_const(mHostRef).view<glm::vec4>(), error ? &errorView : nullptr);
    if (error) copyTexture(*error, mHostError);
    return v;
}

void ErrorMeasurePass::execute(PassContext& ctx) {
    const DeviceKind device = ctx.device();
    const bool onDevice = device != DeviceKind::Cpu;
    const Texture& srcTex = *ctx.input(kSrc);
    const Texture& refTex = *ctx.input(kReference);
    // dst is src, except that a non-finite channel becomes 0: the metrics count such pixels (nonFinite), and no
    // output of Loom carries NaN or Inf on to the next pass.
    if (onDevice) {
        errormeasure::zeroNonFiniteOnDevice(device, srcTex, *ctx.output(kDst));
    } else {
        const auto in = srcTex.view<glm::vec4>();
        const auto out = ctx.output(kDst)->view<glm::vec4>();
        parallelForPixels(in.width, in.height,
                          [&](uint32_t x, uint32_t y) { out.at(x, y) = errormeasure::zeroNonFinite(in.at(x, y)); });
    }
    Texture* errorTex = ctx.output(kError);

    // A parameter set between frames is validated here (compile validated the one it saw).
    if (!mParsed || mParsedMetrics != mMetrics) parseMetrics(ctx.passName() + ".metrics");

    const bool historyValid = ctx.historyValid();
    Stats& stats = ctx.stats();
    mHostCopiesFresh = false;

    if (mEnabled) {
        if (!historyValid) resetHistory();
        const bool inMeans = mFramesSeen >= uint64_t(mWarmupFrames);
        ++mFramesSeen;
        auto record = [&](int index, const std::string& name, double value) {
            stats.set(name, value);
            if (inMeans) {
                mSums[size_t(index)] += value;
                ++mCounts[size_t(index)];
            }
        };

        uint64_t nonFinite = 0;
        ImageView<float> errorView;
        if (errorTex && !onDevice) errorView = errorTex->view<float>();
        for (int m = 0; m < kMetricCount; ++m) {
            const bool wantImage = errorTex && Metric(m) == mErrorImage;
            if (!mSelected[size_t(m)] && !wantImage) continue;
            const MetricValue v =
                onDevice ? measureOnDevice(device, Metric(m), srcTex, refTex, wantImage ? errorTex : nullptr)
                         : measure(Metric(m), srcTex.view<glm::vec4>(), refTex.view<glm::vec4>(),
                                   wantImage ? &errorView : nullptr);
            nonFinite = std::max(nonFinite, v.nonFinite);
            if (mSelected[size_t(m)]) record(m, kMetricNames[m], v.value);
        }
        if (historyValid) {
            const Texture& prevSrc = ctx.historyPrev(kPrevSrc);
            const Texture& prevRef = ctx.historyPrev(kPrevReference);
            MetricValue t;
            if (onDevice) {
                const MetricSums s = errormeasure::temporalOnDevice(device, srcTex, prevSrc, refTex, prevRef);
                t = {cappedMetricMean(s), s.nonFinite};
            } else {
                t = temporalError(srcTex.view<glm::vec4>(), prevSrc.view<glm::vec4>(), refTex.view<glm::vec4>(),
                                  prevRef.view<glm::vec4>());
            }
            record(kMetricCount, kStatTemporal, t.value);
        }
        stats.set(kStatNonFinite, double(nonFinite));
        for (int i = 0; i < kMeanCount; ++i) {
            if (mCounts[size_t(i)] == 0) continue;
            const char* name = i < kMetricCount ? kMetricNames[i] : kStatTemporal;
            stats.set(std::string(kStatMeanPrefix) + name, mSums[size_t(i)] / double(mCounts[size_t(i)]));
        }
        stats.set(kStatMeanFrames, double(mFramesSeen > uint64_t(mWarmupFrames) ? mFramesSeen - mWarmupFrames : 0));
    } else if (errorTex) {
        if (onDevice)
            errormeasure::clearOnDevice(device, *errorTex);
        else
            errorTex->clear();
    }

    // History is kept while disabled too, so the temporal error is right when enabled again.
    if (onDevice) {
        errormeasure::copyOnDevice(device, srcTex, ctx.historyCur(kPrevSrc));
        errormeasure::copyOnDevice(device, refTex, ctx.historyCur(kPrevReference));
    } else {
        ctx.historyCur(kPrevSrc).copyFrom(srcTex);
        ctx.historyCur(kPrevReference).copyFrom(refTex);
    }
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::ErrorMeasurePass>(
        "ErrorMeasure",
        "Image error of src against reference each frame (docs/METRICS.md); dst is src unchanged. Stats: one per "
        "metric in `metrics` (relMSE, smape, psnr, ssim, flip), temporal (temporal-derivative error against the "
        "previous frame, when history is valid), nonFinite (pixels with a non-finite value in src or reference), "
        "mean.<metric> and mean.temporal (running means over the frames after warmupFrames), meanFrames. The "
        "means restart on a history reset.");
}
