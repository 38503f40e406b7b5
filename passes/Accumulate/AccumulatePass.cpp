#include "AccumulatePass.h"

#include <atomic>

#include "AccumulateDevice.h"
#include "loom/Camera.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/Scene.h"
#include "loom/StatNames.h"

namespace loom {

using accumulate::FrameViews;

namespace {

const char kSrc[] = "src";
const char kDenoised[] = "denoised";
const char kDst[] = "dst";
const char kSum[] = "sum";
const char kSumExtra[] = "sumExtra";
const char kCount[] = "count";
const char kFrames[] = "frames";
const char kPartialSumRG[] = "partialSumRG";
const char kPartialSumBA[] = "partialSumBA";
const char kPartialCount[] = "partialCount";

const char* const kStateFields[] = {kSum, kSumExtra, kCount, kFrames};

// Counters reported in the frame's stats.
const char kStatNonFinite[] = "nonFinite";
const char kStatReset[] = "reset";
const char kStatMeanWeight[] = "meanWeight";

/// One frame over every pixel: starts from zero when `reset`, adds this frame's
/// sample when `addSamples`, writes the state and the mean (blended with the
/// denoised image when there is one). Returns the number of pixels whose sample
/// was skipped as non-finite.
template <AccumulatePass::Precision P>
uint64_t accumulateFrame(const FrameViews& v, bool reset, bool addSamples) {
    std::atomic<uint64_t> skipped{0};
    parallelFor2D(v.dst.width, v.dst.height, [&](const Tile& t) {
        uint64_t tileSkipped = 0;
        for (uint32_t y = t.y0; y < t.y1; ++y) {
            for (uint32_t x = t.x0; x < t.x1; ++x) {
                if (!accumulate::accumulatePixel<P>(v, x, y, reset, addSamples)) ++tileSkipped;
            }
        }
        // An integer sum: the same total whatever order the tiles finish in.
        skipped += tileSkipped;
    });
    return skipped;
}

}  // namespace

void AccumulatePass::reflect(Reflection& r, const CompileInfo&) const {
    // Every precision's state fields are declared whatever the precision: reflection must not depend on
    // parameters, so switching precision never reallocates.
    r.input(kSrc, Format::RGBA32F).doc("samples to average, e.g. PathTracer.color (connect with an explicit edge)");
    r.input(kDenoised, Format::RGBA32F)
        .optional()
        .doc(
            "a denoised image of the same frames (e.g. SVGF.filtered): the output starts as it after every reset and "
            "turns into the mean as frames accumulate (see denoisedFrames)");
    r.output(kDst, Format::RGBA32F)
        .doc("mean of the finite samples since the last reset; with `denoised`, the blend of the two");
    r.output(kPartialSumRG, Format::RGBA32U)
        .optional()
        .doc(
            "the running sums of R (xy) and G (zw) as doubles, each as the (low, high) words of its bits (any "
            "precision: float and kahan sums widened), for merging partial accumulations of one frame (`loom image "
            "merge`)");
    r.output(kPartialSumBA, Format::RGBA32U).optional().doc("the sums of B and A, as partialSumRG");
    r.output(kPartialCount, Format::R32U)
        .optional()
        .doc("the finite samples in each pixel's sums: dst is partialSum / partialCount (0 where it is 0)");
    // One layout holds every precision's running sum (accumulate::packSum): 32 bytes a pixel, what double needs.
    // Each texel is loaded and stored by its own pixel alone (accumulatePixel), so the state is updated in place:
    // one texture per field, not a ping-pong pair.
    r.history(kSum, Format::RGBA32U)
        .inPlace()
        .doc(
            "running sum, as bits: double: the sums of R (xy) and G (zw), each double as the (low, high) words of its "
            "bits (the layout of partialSumRG); float and kahan: the float sum's RGBA bits");
    r.history(kSumExtra, Format::RGBA32U)
        .inPlace()
        .doc(
            "double: the sums of B (xy) and A (zw), laid out as sum; kahan: the bits of the float sum's rounding "
            "error (the mean is (sum + compensation) / count); float: zero");
    r.history(kCount, Format::R32U).inPlace().doc("finite samples in the sum of each pixel (non-finite samples are skipped)");
    r.history(kFrames, Format::R32U).fixedSize(1, 1).inPlace().doc("frames accumulated since the last reset (maxFrames caps it)");
}

void AccumulatePass::declareParams(ParamList& p) {
    p.addEnum("precision", &mPrecision, Precision::Double, {"float", "kahan", "double"})
        .doc(
            "running-sum arithmetic: float (drifts on long runs), kahan (float with Neumaier compensation) or "
            "double (rounding negligible at any practical frame count); a change restarts the accumulation");
    p.add("maxFrames", &mMaxFrames, 0)
        .min(0)
        .doc(
            "stop after this many frames and keep their mean (0 = never stop); lowering it below the frames "
            "already accumulated restarts");
    p.add("autoReset", &mAutoReset, true)
        .role(ParamRole::AutoReset)
        .doc(
            "restart when the camera, a scene instance or a light moved, an animated light changed, or a parameter "
            "of a pass upstream changed (not a seed or sample count), in this frame (jitter alone does not restart); "
            "`loom render --hold` keeps an animated scene at one frame's time, to converge that frame");
    p.add("enabled", &mEnabled, true)
        .doc("false: dst is a copy of src (of denoised, when connected) and the accumulated state is cleared");
    p.add("denoisedFrames", &mDenoisedFrames, 64.f)
        .range(0.f, 1e6f)
        .doc(
            "with `denoised` connected: the frames of the mean the denoised image is worth. With n frames in the "
            "mean, dst = (K denoised + (n-1) mean) / (K + n-1): the denoised image on the first frame after a reset, "
            "then the mean's weight grows like n / (n + K)");
}

bool AccumulatePass::sceneMoved(const PassContext& ctx) {
    // Punctual lights have no previous pose in the scene: the last frame's is kept here.
    std::vector<glm::vec3> lightPoses;
    if (const Scene* scene = ctx.scene())
        for (const Light& light : scene->lights) lightPoses.insert(lightPoses.end(), {light.position, light.direction});
    const bool lightMoved = lightPoses.size() == mLightPoses.size() && lightPoses != mLightPoses;
    mLightPoses = std::move(lightPoses);

    if (lightMoved || ctx.inputParamsChanged()) return true;  // a parameter upstream changed: a new image too
    if (const Camera* camera = ctx.camera(); camera && camera->world != camera->prevWorld) return true;
    if (const Scene* scene = ctx.scene()) {
        for (const Instance& instance : scene->instances)
            if (instance.world != instance.prevWorld) return true;
        if (scene->lightingChanged()) return true;  // an animated light changed: a new image, as after a move
    }
    return false;
}

void AccumulatePass::clearUnusedState(PassContext& ctx) const {
    if (mPrecision == Precision::Float) ctx.historyCur(kSumExtra).clear();
}

void AccumulatePass::writePartial(PassContext& ctx) const {
    Texture* rgOut = ctx.output(kPartialSumRG);
    Texture* baOut = ctx.output(kPartialSumBA);
    if (Texture* count = ctx.output(kPartialCount)) count->copyFrom(ctx.historyCur(kCount));
    if (!rgOut && !baOut) return;
    if (mPrecision == Precision::Double) {
        if (rgOut) rgOut->copyFrom(ctx.historyCur(kSum));
        if (baOut) baOut->copyFrom(ctx.historyCur(kSumExtra));
        return;
    }
    if (ctx.device() != DeviceKind::Cpu) {
        accumulate::widenOnDevice(ctx.device(), mPrecision, ctx.historyCur(kSum), ctx.historyCur(kSumExtra), rgOut,
                                  baOut);
        return;
    }
    const auto sum = ctx.historyCur(kSum).view<glm::uvec4>();
    const auto comp = ctx.historyCur(kSumExtra).view<glm::uvec4>();
    const auto rg = rgOut ? rgOut->view<glm::uvec4>() : ImageView<glm::uvec4>{};
    const auto ba = baOut ? baOut->view<glm::uvec4>() : ImageView<glm::uvec4>{};
    parallelForPixels(sum.width, sum.height, [&](uint32_t x, uint32_t y) {
        glm::uvec4 a, b;
        accumulate::widenedSum(mPrecision, sum.at(x, y), comp.at(x, y), a, b);
        if (rg.data) rg.at(x, y) = a;
        if (ba.data) ba.at(x, y) = b;
    });
}

bool AccumulatePass::runsOn(DeviceKind device) const {
    return device == DeviceKind::Cpu || accumulate::deviceRuns(device);
}

void AccumulatePass::execute(PassContext& ctx) {
    // Off the host (emulated, cuda) the same per-pixel kernel runs through launch2D, the counts through reduceRows
    // (AccumulateDevice.h); views are device views there, host views (which check the residence) on the CPU.
    const DeviceKind device = ctx.device();
    const bool onDevice = device != DeviceKind::Cpu;
    const Texture* denoised = ctx.input(kDenoised);

    if (!mEnabled) {
        ctx.output(kDst)->copyFrom(denoised ? *denoised : *ctx.input(kSrc));
        for (const char* field : kStateFields) ctx.historyCur(field).clear();
        for (const char* field : {kPartialSumRG, kPartialSumBA, kPartialCount})
            if (Texture* t = ctx.output(field)) t->clear();
        mRestartPending = true;
        ctx.stats().set(stat::kAccumulatedFrames, 0);
        ctx.stats().set(kStatNonFinite, 0);
        ctx.stats().set(kStatReset, 0);
        ctx.stats().set(stat::kOutputMeanRestarted, 0);
        return;
    }

    // Frames in the previous mean; zero after a graph-level reset, which clears history.
    const uint32_t prevFrames = onDevice ? accumulate::loadFrames(device, ctx.historyPrev(kFrames))
                                         : ctx.historyPrev(kFrames).view<uint32_t>().at(0, 0);
    const uint32_t maxFrames = uint32_t(mMaxFrames);
    const bool precisionChanged = mPrecision != mStatePrecision;
    const bool moved = sceneMoved(ctx);  // every frame: it keeps the lights' poses for the next
    const bool reset = !ctx.historyValid() || mRestartPending || precisionChanged ||
                       (maxFrames > 0 && prevFrames > maxFrames) || (mAutoReset && moved);
    if (precisionChanged) mStaleFrames = 2;
    mStatePrecision = mPrecision;
    mRestartPending = false;

    const uint32_t framesBefore = reset ? 0 : prevFrames;
    const bool frozen = maxFrames > 0 && framesBefore >= maxFrames;
    const uint32_t frames = frozen ? framesBefore : framesBefore + 1;

    const auto view = [onDevice](auto& texture, auto texel) {
        using T = decltype(texel);
        return onDevice ? texture.template deviceView<T>() : texture.template view<T>();
    };
    FrameViews v;
    v.src = view(*ctx.input(kSrc), glm::vec4());
    if (denoised) v.denoised = view(*denoised, glm::vec4());
    v.denoisedFrames = mDenoisedFrames;
    v.dst = view(*ctx.output(kDst), glm::vec4());
    v.prevSum = view(ctx.historyPrev(kSum), glm::uvec4());
    v.curSum = view(ctx.historyCur(kSum), glm::uvec4());
    v.prevSumExtra = view(ctx.historyPrev(kSumExtra), glm::uvec4());
    v.curSumExtra = view(ctx.historyCur(kSumExtra), glm::uvec4());
    v.prevCount = view(ctx.historyPrev(kCount), uint32_t());
    v.curCount = view(ctx.historyCur(kCount), uint32_t());

    // A frozen mean still stores the state it loaded (the state is updated in place, texel by texel: see reflect).
    uint64_t skipped = 0;
    if (onDevice) {
        skipped = accumulate::accumulateOnDevice(device, mPrecision, v, reset, !frozen);
    } else {
        switch (mPrecision) {
            case Precision::Float:
                skipped = accumulateFrame<Precision::Float>(v, reset, !frozen);
                break;
            case Precision::Kahan:
                skipped = accumulateFrame<Precision::Kahan>(v, reset, !frozen);
                break;
            case Precision::Double:
                skipped = accumulateFrame<Precision::Double>(v, reset, !frozen);
                break;
        }
    }
    if (onDevice)
        accumulate::storeFrames(device, ctx.historyCur(kFrames), frames);
    else
        ctx.historyCur(kFrames).view<uint32_t>().at(0, 0) = frames;
    writePartial(ctx);
    if (mStaleFrames > 0) {
        clearUnusedState(ctx);
        --mStaleFrames;
    }

    ctx.stats().set(stat::kAccumulatedFrames, frames);
    ctx.stats().set(kStatNonFinite, double(skipped));
    ctx.stats().set(kStatReset, reset ? 1 : 0);
    ctx.stats().set(stat::kOutputMeanRestarted, reset && !v.denoised.data ? 1 : 0);
    if (v.denoised.data)
        ctx.stats().set(kStatMeanWeight,
                        frames > 1 ? double(frames - 1) / (double(frames - 1) + mDenoisedFrames) : 0.0);
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::AccumulatePass>(
        "AccumulatePass",
        "Running mean of its input since the last reset (references); float, Kahan or double precision. "
        "Non-finite samples are skipped per pixel. With a denoised input, starts as it after every reset and "
        "converges to the mean while nothing moves. Stats: frames (in the mean), nonFinite (samples skipped this "
        "frame), reset (1 when this frame started a new mean), outputMeanRestarted (the same without denoised: dst "
        "lost its mean), meanWeight (with denoised: the mean's share of dst).");
}
