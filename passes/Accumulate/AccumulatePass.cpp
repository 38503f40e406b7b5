#include "AccumulatePass.h"

#include <atomic>

#include "loom/Camera.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/Scene.h"
#include "loom/StatNames.h"

namespace loom {

using accumulate::PixelState;

namespace {

const char kSrc[] = "src";
const char kDst[] = "dst";
const char kSum[] = "sum";
const char kCompensation[] = "compensation";
const char kSumRG[] = "sumRG";
const char kSumBA[] = "sumBA";
const char kCount[] = "count";
const char kFrames[] = "frames";

const char* const kStateFields[] = {kSum, kCompensation, kSumRG, kSumBA, kCount, kFrames};

// Counters reported in the frame's stats.
const char kStatNonFinite[] = "nonFinite";
const char kStatReset[] = "reset";

/// Every texture one frame touches, as typed views.
struct FrameViews {
    ImageView<const glm::vec4> src;
    ImageView<glm::vec4> dst;
    ImageView<const glm::vec4> prevSum, prevCompensation;
    ImageView<glm::vec4> curSum, curCompensation;
    ImageView<const glm::uvec4> prevSumRG, prevSumBA;
    ImageView<glm::uvec4> curSumRG, curSumBA;
    ImageView<const uint32_t> prevCount;
    ImageView<uint32_t> curCount;
};

// Loads and stores touch only the fields the precision keeps its state in: the
// pass is memory bound, and float precision should not pay for double's state.
template <AccumulatePass::Precision P>
PixelState loadState(const FrameViews& v, uint32_t x, uint32_t y) {
    using Precision = AccumulatePass::Precision;
    PixelState s;
    s.count = v.prevCount.at(x, y);
    if constexpr (P == Precision::Float || P == Precision::Kahan) s.sum = v.prevSum.at(x, y);
    if constexpr (P == Precision::Kahan) s.compensation = v.prevCompensation.at(x, y);
    if constexpr (P == Precision::Double)
        s.sumDouble = accumulate::unpackDoubleSum(v.prevSumRG.at(x, y), v.prevSumBA.at(x, y));
    return s;
}

template <AccumulatePass::Precision P>
void storeState(const FrameViews& v, uint32_t x, uint32_t y, const PixelState& s) {
    using Precision = AccumulatePass::Precision;
    v.curCount.at(x, y) = s.count;
    // In double precision `sum` is not state but the double sum rounded to float, so a dump of it means something.
    v.curSum.at(x, y) = P == Precision::Double ? accumulate::sumAsFloat(P, s) : s.sum;
    if constexpr (P == Precision::Kahan) v.curCompensation.at(x, y) = s.compensation;
    if constexpr (P == Precision::Double)
        accumulate::packDoubleSum(s.sumDouble, v.curSumRG.at(x, y), v.curSumBA.at(x, y));
}

/// One frame over every pixel: starts from zero when `reset`, adds this frame's
/// sample when `addSamples`, writes the state and the mean. Returns the number of
/// pixels whose sample was skipped as non-finite.
template <AccumulatePass::Precision P>
uint64_t accumulateFrame(const FrameViews& v, bool reset, bool addSamples) {
    std::atomic<uint64_t> skipped{0};
    parallelFor2D(v.dst.width, v.dst.height, [&](const Tile& t) {
        uint64_t tileSkipped = 0;
        for (uint32_t y = t.y0; y < t.y1; ++y) {
            for (uint32_t x = t.x0; x < t.x1; ++x) {
                PixelState s = reset ? PixelState{} : loadState<P>(v, x, y);
                if (addSamples && !accumulate::addSample(P, s, v.src.at(x, y))) ++tileSkipped;
                storeState<P>(v, x, y, s);
                v.dst.at(x, y) = accumulate::mean(P, s);
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
    r.output(kDst, Format::RGBA32F).doc("mean of the finite samples since the last reset");
    r.history(kSum, Format::RGBA32F)
        .doc("running sum: the state for float and kahan; for double, the double sum rounded to float (to inspect)");
    r.history(kCompensation, Format::RGBA32F)
        .doc("kahan: rounding error of the float sum; the mean is (sum + compensation) / count. Zero otherwise");
    r.history(kSumRG, Format::RGBA32U)
        .doc("double: sums of R (xy) and G (zw), each double as the (low, high) words of its bits. Zero otherwise");
    r.history(kSumBA, Format::RGBA32U).doc("double: sums of B (xy) and A (zw), laid out as sumRG. Zero otherwise");
    r.history(kCount, Format::R32U).doc("finite samples in the sum of each pixel (non-finite samples are skipped)");
    r.history(kFrames, Format::R32U).fixedSize(1, 1).doc("frames accumulated since the last reset (maxFrames caps it)");
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
            "restart when the camera or a scene instance moved, or an animated light changed, in this frame (jitter "
            "alone does not restart); "
            "`loom render --hold` keeps an animated scene at one frame's time, to converge that frame");
    p.add("enabled", &mEnabled, true).doc("false: dst is a copy of src and the accumulated state is cleared");
}

bool AccumulatePass::sceneMoved(const PassContext& ctx) {
    if (const Camera* camera = ctx.camera(); camera && camera->world != camera->prevWorld) return true;
    if (const Scene* scene = ctx.scene()) {
        for (const Instance& instance : scene->instances)
            if (instance.world != instance.prevWorld) return true;
        if (scene->lightingChanged()) return true;  // an animated light changed: a new image, as after a move
    }
    return false;
}

void AccumulatePass::clearUnusedState(PassContext& ctx) const {
    if (mPrecision != Precision::Kahan) ctx.historyCur(kCompensation).clear();
    if (mPrecision != Precision::Double) {
        ctx.historyCur(kSumRG).clear();
        ctx.historyCur(kSumBA).clear();
    }
}

void AccumulatePass::execute(PassContext& ctx) {
    const auto src = ctx.input(kSrc)->view<glm::vec4>();
    const auto dst = ctx.output(kDst)->view<glm::vec4>();

    if (!mEnabled) {
        parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) { dst.at(x, y) = src.at(x, y); });
        for (const char* field : kStateFields) ctx.historyCur(field).clear();
        mRestartPending = true;
        ctx.stats().set(stat::kAccumulatedFrames, 0);
        ctx.stats().set(kStatNonFinite, 0);
        ctx.stats().set(kStatReset, 0);
        return;
    }

    // Frames in the previous mean; zero after a graph-level reset, which clears history.
    const uint32_t prevFrames = ctx.historyPrev(kFrames).view<uint32_t>().at(0, 0);
    const uint32_t maxFrames = uint32_t(mMaxFrames);
    const bool precisionChanged = mPrecision != mStatePrecision;
    const bool reset = !ctx.historyValid() || mRestartPending || precisionChanged ||
                       (maxFrames > 0 && prevFrames > maxFrames) || (mAutoReset && sceneMoved(ctx));
    if (precisionChanged) mStaleFrames = 2;
    mStatePrecision = mPrecision;
    mRestartPending = false;

    const uint32_t framesBefore = reset ? 0 : prevFrames;
    const bool frozen = maxFrames > 0 && framesBefore >= maxFrames;
    const uint32_t frames = frozen ? framesBefore : framesBefore + 1;

    FrameViews v;
    v.src = src;
    v.dst = dst;
    v.prevSum = ctx.historyPrev(kSum).view<glm::vec4>();
    v.curSum = ctx.historyCur(kSum).view<glm::vec4>();
    v.prevCompensation = ctx.historyPrev(kCompensation).view<glm::vec4>();
    v.curCompensation = ctx.historyCur(kCompensation).view<glm::vec4>();
    v.prevSumRG = ctx.historyPrev(kSumRG).view<glm::uvec4>();
    v.curSumRG = ctx.historyCur(kSumRG).view<glm::uvec4>();
    v.prevSumBA = ctx.historyPrev(kSumBA).view<glm::uvec4>();
    v.curSumBA = ctx.historyCur(kSumBA).view<glm::uvec4>();
    v.prevCount = ctx.historyPrev(kCount).view<uint32_t>();
    v.curCount = ctx.historyCur(kCount).view<uint32_t>();

    // A frozen mean still rewrites the state: history is ping-ponged, so this frame's side must hold it too.
    uint64_t skipped = 0;
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
    ctx.historyCur(kFrames).view<uint32_t>().at(0, 0) = frames;
    if (mStaleFrames > 0) {
        clearUnusedState(ctx);
        --mStaleFrames;
    }

    ctx.stats().set(stat::kAccumulatedFrames, frames);
    ctx.stats().set(kStatNonFinite, double(skipped));
    ctx.stats().set(kStatReset, reset ? 1 : 0);
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::AccumulatePass>(
        "AccumulatePass",
        "Running mean of its input since the last reset (references); float, Kahan or double precision. "
        "Non-finite samples are skipped per pixel. Stats: frames (in the mean), nonFinite (samples skipped this "
        "frame), reset (1 when this frame started a new mean).");
}
