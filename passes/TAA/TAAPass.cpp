#include "TAAPass.h"

#include <algorithm>
#include <atomic>

#include "TAADevice.h"
#include "TAASimd.h"
#include "loom/Channels.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"

namespace loom {

using taa::Counts;
using taa::kTileH;
using taa::kTileW;
using taa::TaaInputs;

namespace {

const char kColorIn[] = "colorIn";
using channel::kMvec;
const char kColorOut[] = "colorOut";
const char kColorHistory[] = "colorHistory";

// Counters reported in the frame's stats.
const char kStatNonFinite[] = "nonFinite";
const char kStatNoHistory[] = "noHistory";
const char kStatClipped[] = "clipped";
const char kStatVectorLanes[] = "vectorLanes";

template <class T>
taa::ClampedImage<T> clamped(const Texture& t) {
    const auto v = t.view<T>();
    return {v.data, v.width, v.height, v.rowPitch};
}

}  // namespace

void TAAPass::reflect(Reflection& r, const CompileInfo&) const {
    r.input(kColorIn, Format::RGBA32F).doc("this frame's jittered colour (connect with an explicit edge)");
    r.input(kMvec, Format::RG32F).doc("uvPrev - uvCur in [0, 1]^2 uv, jitter removed (by name from the G-buffer)");
    r.output(kColorOut, Format::RGBA32F).doc("anti-aliased colour; always finite");
    r.history(kColorHistory, Format::RGBA32F)
        .doc("last frame's resolved colour, the history that is reprojected (compressed when hdrCompress)");
}

void TAAPass::declareParams(ParamList& p) {
    const taa::TaaParams defaults;
    p.add("alpha", &mParams.alpha, defaults.alpha)
        .range(0.0, 1.0)
        .doc("weight of the current frame in the blend (1 = no history)");
    p.add("sigma", &mParams.sigma, defaults.sigma)
        .range(0.0, 10.0)
        .doc("clipping box half-size in standard deviations of the 3x3 neighbourhood (YCoCg)");
    p.add("antiFlicker", &mParams.antiFlicker, defaults.antiFlicker)
        .doc(
            "weight current and history by 1 / (1 + luma) (Karis 2014) so bright outliers do not flicker; biased: it "
            "darkens a light's jittered edges (the Cornell box lamp loses about 10 %)");
    p.add("hdrCompress", &mHdrCompress, false)
        .doc(
            "resolve in c / (1 + luma) and expand after (Karis 2014), so a bright light bleeds less into dark "
            "neighbours through the bicubic history; biased like antiFlicker: averages in that space darken a "
            "light's edges (the Cornell box lamp loses about 12 %)");
    p.add("reference", &mReference, false)
        .doc("run the plain per-pixel reference kernel instead of the tiled CPU path (agrees to 1e-4, slower)");
}

bool TAAPass::runsOn(DeviceKind device) const {
    return device == DeviceKind::Cpu || taa::deviceRuns(device);
}

void TAAPass::execute(PassContext& ctx) {
    if (ctx.device() != DeviceKind::Cpu) {  // the reference kernel through launch2D (TAADevice.h)
        const Counts counts = taa::resolveOnDevice(
            ctx.device(), mParams, ctx.historyValid(), mHdrCompress, *ctx.input(kColorIn), *ctx.input(kMvec),
            ctx.historyPrev(kColorHistory), *ctx.output(kColorOut), ctx.historyCur(kColorHistory));
        setStats(ctx, counts, 0);
        return;
    }
    TaaInputs in;
    in.color = clamped<glm::vec4>(*ctx.input(kColorIn));
    in.compress = mHdrCompress;
    in.mvec = clamped<glm::vec2>(*ctx.input(kMvec));
    in.history = clamped<glm::vec4>(ctx.historyPrev(kColorHistory));
    in.historyValid = ctx.historyValid();
    const auto out = ctx.output(kColorOut)->view<glm::vec4>();
    const auto history = ctx.historyCur(kColorHistory).view<glm::vec4>();

    std::atomic<uint64_t> nonFinite{0}, noHistory{0}, clipped{0};
    const taa::TaaParams params = mParams;
    const bool reference = mReference;
    parallelFor2D(
        out.width, out.height,
        [&](const Tile& t) {
            Counts counts;
            if (reference)
                taa::resolveTileReference(in, params, t, out, history, counts);
            else
                taa::resolveTileVector(in, params, t, out, history, counts);
            // Integer sums: the same totals in any order.
            nonFinite += counts.nonFinite;
            noHistory += counts.noHistory;
            clipped += counts.clipped;
        },
        kTileW, kTileH);

    setStats(ctx, Counts{nonFinite, noHistory, clipped}, reference ? 0 : taa::vectorLanes());
}

void TAAPass::setStats(PassContext& ctx, const Counts& counts, uint32_t vectorLanes) {
    ctx.stats().set(kStatNonFinite, double(counts.nonFinite));
    ctx.stats().set(kStatNoHistory, double(counts.noHistory));
    ctx.stats().set(kStatClipped, double(counts.clipped));
    ctx.stats().set(kStatVectorLanes, double(vectorLanes));
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::TAAPass>(
        "TAAPass",
        "Temporal anti-aliasing: 3x3 YCoCg variance clipping, motion dilation (longest vector of the 3x3), "
        "Catmull-Rom history, blend in linear colour that keeps energy (optional luminance-weighted anti-flicker and "
        "HDR "
        "compression, both biased); history in a graph field. Non-finite input "
        "pixels are replaced by the neighbourhood mean; a neighbourhood of one colour (a black sky) resolves to it "
        "without reading the history. Stats: nonFinite (input pixels replaced), noHistory (pixels without usable "
        "history), clipped (pixels whose history was clipped; not those of one-colour neighbourhoods), vectorLanes "
        "(floats per vector of the tiled path as dispatched at run time: 8 AVX2, 16 AVX-512; 0 with the reference "
        "kernel).");
}
