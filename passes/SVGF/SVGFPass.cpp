#include "SVGFPass.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <string>

#include "SVGFDevice.h"
#include "loom/Camera.h"
#include "loom/Channels.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"

namespace loom {

using namespace svgf;

namespace {

// Inputs (standard channel names, so they wire by name from the G-buffer and the path tracer).
using channel::kAlbedo;
using channel::kColor;
using channel::kDirect;
using channel::kEmission;
using channel::kGradient;
using channel::kIndirect;
using channel::kLinearZ;
using channel::kMeshId;
using channel::kMvec;
using channel::kNormW;
using channel::kSpecAlbedo;
// Last frame's guides from the G-buffer's @prev edges (optional: without them SVGF keeps its own copies).
const char kLinearZPrev[] = "linearZPrev";
const char kNormWPrev[] = "normWPrev";
const char kMeshIdPrev[] = "meshIdPrev";
// Outputs.
const char kFiltered[] = "filtered";
const char kVariance[] = "variance";
const char kHistoryLength[] = "historyLength";
// History.
const char kIllumHistory[] = "illumination";
const char kIndirectHistory[] = "illuminationIndirect";
const char kMomentsHistory[] = "moments";
const char kIndirectMomentsHistory[] = "momentsIndirect";
const char kLengthHistory[] = "length";
const char kPrevLinearZ[] = "prevLinearZ";
const char kPrevNormW[] = "prevNormW";
const char kPrevMeshId[] = "prevMeshId";
// Scratch.
const char kIntegrated[] = "integrated";
const char kIntegratedIndirect[] = "integratedIndirect";
const char kEstimate[] = "estimate";
const char kEstimateIndirect[] = "estimateIndirect";
const char kChange[] = "shadingChange";
const char kClampBox[] = "clampBox";

// Frame stats.
const char kStatNonFinite[] = "nonFinite";
const char kStatSplit[] = "split";
const char kStatSharedGuides[] = "sharedPrevGuides";
const char kStatReferencePixels[] = "temporal.referenceShare";
const char kStatSpatialPixels[] = "variance.spatialPixels";
const char kStatVarianceReference[] = "variance.referenceShare";
const char kStatReproject[] = "ms.reproject";
const char kStatVariance[] = "ms.variance";
const char kStatAtrousPrepare[] = "ms.atrous.prepare";
const char kStatAtrous[] = "ms.atrous";
const char kStatSkippedTiles[] = "atrousSkippedTiles";
const char kStatModulate[] = "ms.modulate";
const char kStatAntilag[] = "ms.antilag";
const char kStatNeighbourhood[] = "ms.neighbourhood";

// Tiles of the streaming stages: wider than the default so each row of a tile is a long contiguous run in each of
// the ~20 textures the temporal stage touches (hardware prefetch, fewer pages per tile).
constexpr uint32_t kStreamTileSize = 128;
// The fused temporal stage goes further: bands of whole rows (see TemporalSimd.cpp).
constexpr uint32_t kTemporalBandRows = 8;

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// A field's pixels as the pass's kernels reach them: a host view on the CPU (which fails for device memory), the
/// device view on any other device (SVGFDevice.h's launches).
template <class T>
ImageView<T> pixels(const PassContext& ctx, Texture& t) {
    return ctx.device() == DeviceKind::Cpu ? t.view<T>() : t.deviceView<T>();
}
template <class T>
ImageView<const T> pixels(const PassContext& ctx, const Texture& t) {
    return ctx.device() == DeviceKind::Cpu ? t.view<T>() : t.deviceView<T>();
}

template <class T>
ImageView<const T> inputView(const PassContext& ctx, const char* name) {
    const Texture* t = ctx.input(name);
    return t ? pixels<T>(ctx, *t) : ImageView<const T>{};
}

template <class T>
ImageView<T> outputView(const PassContext& ctx, const char* name) {
    Texture* t = ctx.output(name);
    return t ? pixels<T>(ctx, *t) : ImageView<T>{};
}

template <class T>
ImageView<const T> asConst(ImageView<T> v) {
    return {v.data, v.width, v.height, v.rowPitch};
}

/// The direct/indirect split: both parts connected (`connected(name)`: whether that input is).
template <class Connected>
bool splitSignals(Connected connected) {
    return connected(kDirect) && connected(kIndirect);
}

/// Last frame's guides come from the G-buffer's previous outputs (@prev edges) rather than this pass's copies.
template <class Connected>
bool sharedPrevGuides(Connected connected) {
    return connected(kLinearZPrev) && connected(kNormWPrev) && (!connected(kMeshId) || connected(kMeshIdPrev));
}

/// TemporalParams::prevDepth of a pinhole camera for a frame of w x h. The sample of pixel (x, y) lies along
/// d = forward + right nx tan(fov / 2) aspect + up ny tan(fov / 2), with nx = 2 (x + 0.5 + jitter.x) / w - 1 and
/// ny = 1 - 2 (y + 0.5 + jitter.y) / h (cameraRayDir), so dot(d, forward) = 1 and the point at view depth z is
/// origin + z d. Its depth in last frame's camera, dot(origin + z d - prevOrigin, prevForward), is affine in z,
/// and z's factor affine in x and y.
glm::vec4 expectedPrevDepthPlane(const Camera& c, uint32_t w, uint32_t h) {
    const glm::dvec3 origin(c.position()), forward(c.forward()), right(c.right()), up(c.up());
    const glm::dvec3 prevOrigin(c.prevWorld[3]);
    const glm::dvec3 prevForward = -glm::normalize(glm::dvec3(c.prevWorld[2]));
    const double t = std::tan(0.5 * double(c.fovY)), a = double(c.aspect);
    const double rf = glm::dot(right, prevForward) * t * a, uf = glm::dot(up, prevForward) * t;
    const double cx = 2.0 * rf / double(w), cy = -2.0 * uf / double(h);
    const double c0 = glm::dot(forward, prevForward) + (2.0 * (0.5 + double(c.jitter.x)) / double(w) - 1.0) * rf +
                      (1.0 - 2.0 * (0.5 + double(c.jitter.y)) / double(h)) * uf;
    const glm::vec4 plane(float(glm::dot(origin - prevOrigin, prevForward)), float(c0), float(cx), float(cy));
    // A camera matrix that is not finite keeps the plain test (the camera's own checks report it).
    return isFinite(plane.x) && isFinite(plane.y) && isFinite(plane.z) && isFinite(plane.w) ? plane
                                                                                          : TemporalParams{}.prevDepth;
}

}  // namespace

void SVGFPass::reflect(Reflection& r, const CompileInfo& info) const {
    // Once the wiring is known, the fields these connections do not use are left out: the indirect signal's
    // history and scratch without the split, the copies of last frame's guides when the @prev edges feed them.
    const auto connected = [&](const char* name) { return info.isInputConnected(name); };
    const bool splitFields = !info.wired || splitSignals(connected);
    const bool ownGuides = !info.wired || !sharedPrevGuides(connected);
    r.input(kColor, Format::RGBA32F).doc("path-traced radiance to filter (also what miss pixels pass through)");
    r.input(kDirect, Format::RGBA32F)
        .optional()
        .doc("direct part of color, emission seen by the camera included; with indirect: filtered separately");
    r.input(kIndirect, Format::RGBA32F).optional().doc("indirect part of color (direct + indirect = color)");
    r.input(kAlbedo, Format::RGBA32F).doc("diffuse reflectance at the primary hit, for demodulation");
    r.input(kSpecAlbedo, Format::RGBA32F)
        .optional()
        .doc(
            "directional albedo of the specular layer at the primary hit: when connected, the signal is demodulated "
            "by albedo + specAlbedo (metals, whose diffuse albedo is about 0, keep their texture out of the filter)");
    r.input(kEmission, Format::RGBA32F).optional().doc("emitted radiance at the primary hit (not filtered)");
    r.input(kLinearZ, Format::RG32F).doc("view depth (-1 on a miss) and its screen-space derivative");
    r.input(kNormW, Format::RGBA32F).doc("shading normal, world space");
    r.input(kMvec, Format::RG32F).doc("uvPrev - uvCur, for reprojection");
    r.input(kMeshId, Format::R32U).optional().doc("mesh/instance id for the disocclusion test (skipped if absent)");
    r.input(kGradient, Format::RG32F)
        .optional()
        .doc(
            "temporal gradients on last frame's pixel grid (the path tracer's gradient output): (luminance re-shaded "
            "now, luminance then) of one sample per 3x3 block; where they differ the history is shortened and the "
            "blend factors raised (A-SVGF anti-lag)");
    r.input(kLinearZPrev, Format::RG32F)
        .optional()
        .doc(
            "last frame's linearZ, from an edge \"GBuffer.linearZ@prev\": with normWPrev (and meshIdPrev when meshId "
            "is connected) SVGF reads last frame's guides there instead of copying them into prevLinearZ, prevNormW "
            "and prevMeshId");
    r.input(kNormWPrev, Format::RGBA32F).optional().doc("last frame's normW (\"GBuffer.normW@prev\"); see linearZPrev");
    r.input(kMeshIdPrev, Format::R32U).optional().doc("last frame's meshId (\"GBuffer.meshId@prev\"); see linearZPrev");

    r.output(kFiltered, Format::RGBA32F).doc("filtered radiance");
    r.output(kVariance, Format::R32F)
        .optional()
        .doc("debug: luminance variance of the demodulated signal fed to the first a-trous level (split: summed)");
    r.output(kHistoryLength, Format::R32F).optional().doc("debug: history length in frames (0: none)");

    r.history(kIllumHistory, Format::RGBA32F)
        .doc("colour (split: direct) history, demodulated rgb and variance: the output of level feedbackTap");
    if (splitFields) r.history(kIndirectHistory, Format::RGBA32F).doc("indirect history (split only), as illumination");
    r.history(kMomentsHistory, Format::RG32F).doc("luminance moments m1, m2 of colour (split: direct)");
    if (splitFields)
        r.history(kIndirectMomentsHistory, Format::RG32F).doc("luminance moments m1, m2 of indirect (split only)");
    r.history(kLengthHistory, Format::R32F).doc("history length in frames, capped at maxHistory; 0: no history");
    if (ownGuides) {
        r.history(kPrevLinearZ, Format::RG32F)
            .doc(
                "linearZ of the frame, for next frame's disocclusion test (not declared when linearZPrev is "
                "connected)");
        r.history(kPrevNormW, Format::RGBA32F)
            .doc("normW of the frame, for next frame's disocclusion test (not declared when linearZPrev is connected)");
        r.history(kPrevMeshId, Format::R32U)
            .doc(
                "meshId of the frame, for next frame's disocclusion test (not declared when linearZPrev is connected)");
    }

    r.internal(kIntegrated, Format::RGBA32F)
        .doc("colour (split: direct) after temporal accumulation, a = temporal variance; then the filtered result");
    if (splitFields) r.internal(kIntegratedIndirect, Format::RGBA32F).doc("indirect, as integrated (split only)");
    r.internal(kEstimate, Format::RGBA32F)
        .doc("input of the a-trous levels: integrated colour with its variance estimate (spatial while short)");
    if (splitFields) r.internal(kEstimateIndirect, Format::RGBA32F).doc("indirect, as estimate (split only)");
    // Two kinds of scratch need no field of their own, since they are dead before a field they fit in is written
    // (memory at the frame's peak, where SVGF runs): the gradient samples of the 3x3 blocks live in `estimate` until
    // the temporal stage writes it, and albedo + specAlbedo, the demodulation albedo, in `filtered` until the
    // remodulation overwrites each pixel with its result (it reads a pixel's albedo only to write that pixel).
    if (!info.wired || info.isInputConnected(kGradient))
        r.internal(kChange, Format::RG32F)
            .doc(
                "shading change on last frame's grid, what the anti-lag reprojects: lambda in [0, 1] and the "
                "luminance ratio now / then (gradient only)");
    if (!info.wired || !info.isInputConnected(kGradient))
        r.internal(kClampBox, Format::RGBA32F)
            .doc(
                "the history clamp's box: this frame's 3x3 mean and standard deviation of each signal's demodulated "
                "luminance (without gradient only)");
}

void SVGFPass::declareParams(ParamList& p) {
    p.add("enabled", &mEnabled, true).doc("false: filtered is a copy of color and the history restarts");
    p.add("temporal", &mTemporal, true)
        .doc(
            "false: no reprojection, variance estimated spatially every frame: a pure edge-avoiding a-trous filter "
            "(Dammertz et al. 2010) as a baseline");
    p.add("iterations", &mIterations, 4).range(0, 16).doc("a-trous levels (tap spacing 1, 2, 4, ...)");
    p.add("feedbackTap", &mFeedbackTap, -1)
        .range(-1, 15)
        .doc("the output of this level (0-based) is next frame's colour history; -1: the unfiltered signal");
    const svgf::TemporalParams temporal;
    p.add("alpha", &mTemporalParams.alpha, temporal.alpha)
        .range(0.0, 1.0)
        .doc("temporal blend factor of colour (at least 1 / history)");
    p.add("momentsAlpha", &mTemporalParams.momentsAlpha, temporal.momentsAlpha)
        .range(0.0, 1.0)
        .doc("temporal blend factor of the luminance moments (at least 1 / history)");
    p.add("historyClamp", &mHistoryClamp, true)
        .doc(
            "without a gradient input (frames of other renderers): clamp the reprojected history's luminance to this "
            "frame's 3x3 neighbourhood mean +- clampSigma standard deviations (demodulated), against stale history. "
            "With gradients the anti-lag does that job and the clamp is not used");
    p.add("clampSigma", &mTemporalParams.clampSigma, temporal.clampSigma)
        .range(0.0, 100.0)
        .doc("width of the history clamp's box, in standard deviations of the neighbourhood's luminance");
    p.add("outlierSigma", &mTemporalParams.outlierSigma, temporal.outlierSigma)
        .range(0.0, 100.0)
        .doc(
            "firefly clamp: where the history holds 4 frames or more, a sample brighter than its mean + this many "
            "standard deviations (luminance moments) is scaled down to that bound before blending (biased: the "
            "energy above it is lost); 0: off");
    const svgf::AtrousParams edgeStopping;
    p.add("phiColor", &mEdgeStopping.phiColor, edgeStopping.phiColor)
        .min(0.0)
        .doc("luminance edge-stopping, in standard deviations (eq. 5)");
    // Bounded: a normal's dot product with itself is 1 only to a few units in the last place, so past about 1e8
    // even a pixel's own weight vanishes, and with it the variance's (sum of weights)^2.
    p.add("phiNormal", &mEdgeStopping.phiNormal, edgeStopping.phiNormal)
        .range(0.0, 1e5)
        .doc("normal edge-stopping exponent (eq. 4)");
    p.add("phiDepth", &mEdgeStopping.phiDepth, edgeStopping.phiDepth)
        .min(0.0)
        .doc("depth edge-stopping, in depth derivatives (eq. 3)");
    p.add("skipRelVariance", &mEdgeStopping.skipRelVariance, edgeStopping.skipRelVariance)
        .range(0.0, 1.0)
        .doc(
            "a 16x16 tile whose hit pixels all have a variance below this times their squared luminance skips the "
            "a-trous levels (keeps the temporal result); 0: off. Stat atrousSkippedTiles: the fraction skipped");
    p.add("meanVariance", &mMeanVariance, true)
        .doc(
            "true: the a-trous levels get the variance of the accumulated mean (the per-sample variance times the sum "
            "of the history's squared weights), so phiColor counts standard deviations of the signal they filter; "
            "false: the per-sample variance (Falcor)");
    p.add("maxHistory", &mTemporalParams.maxHistory, temporal.maxHistory)
        .range(1, 1024)
        .doc("cap of the history length in frames");
    p.add("referenceAtrous", &mReferenceAtrous, false)
        .doc("run the scalar reference a-trous kernel instead of the fast path (validation)");
    p.add("referenceStages", &mReferenceStages, false)
        .doc(
            "run the scalar reference temporal, variance and remodulation stages one after the other instead of the "
            "fused fast path (validation: the history is bit-identical, the output within rounding)");
}

void SVGFPass::compile(const CompileInfo& info) {
    mEstimateObserved = info.isObserved(kEstimate) || info.isObserved(kEstimateIndirect);
    mIntegratedObserved = info.isObserved(kIntegrated) || info.isObserved(kIntegratedIndirect);
}

void SVGFPass::passThrough(PassContext& ctx) const {
    const auto color = ctx.input(kColor)->view<glm::vec4>();
    const auto dst = ctx.output(kFiltered)->view<glm::vec4>();
    parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) {
        const glm::vec4 c = color.at(x, y);
        dst.at(x, y) = glm::vec4(finiteOrZero(glm::vec3(c)), isFinite(c.a) ? c.a : 1.f);
    });
    if (Texture* t = ctx.output(kVariance)) t->clear();
    if (Texture* t = ctx.output(kHistoryLength)) t->clear();
    // Length 0 everywhere: no history when enabled again.
    ctx.historyCur(kLengthHistory).clear();
}

ImageView<const glm::vec4> SVGFPass::demodulationAlbedo(PassContext& ctx) const {
    const auto albedo = inputView<glm::vec4>(ctx, kAlbedo);
    const auto specular = inputView<glm::vec4>(ctx, kSpecAlbedo);
    if (!specular.data) return albedo;
    // In the output, until the remodulation replaces each pixel's albedo with its result (see reflect).
    const auto sum = ctx.output(kFiltered)->view<glm::vec4>();
    parallelFor2D(
        sum.width, sum.height,
        [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x) {
                    const glm::vec4 a = albedo.at(x, y), s = specular.at(x, y);
                    sum.at(x, y) = glm::vec4(glm::vec3(a) + glm::vec3(s), a.a);
                }
        },
        kStreamTileSize);
    return asConst(sum);
}

ImageView<const glm::vec2> SVGFPass::shadingChange(PassContext& ctx) const {
    const auto gradient = inputView<glm::vec2>(ctx, kGradient);
    if (!gradient.data || !mTemporal) return {};
    const auto change = ctx.internal(kChange)->view<glm::vec2>();
    const uint32_t w = change.width, h = change.height;
    // The samples, on the block grid, live in the estimate scratch: the temporal stage writes it after this one.
    const auto estimate = ctx.internal(kEstimate)->view<glm::vec4>();
    const ImageView<glm::vec2> samples{reinterpret_cast<glm::vec2*>(estimate.data),
                                       (w + kGradientBlock - 1) / kGradientBlock,
                                       (h + kGradientBlock - 1) / kGradientBlock, estimate.rowPitch};
    // One sample per block (the channel replicates it over the block): its terms on the block grid, then for each
    // block the sums over the 3x3 blocks around it, written to the block's pixels. Fixed-order sums: any thread
    // count gives the same bits.
    const int bw = int((w + kGradientBlock - 1) / kGradientBlock), bh = int((h + kGradientBlock - 1) / kGradientBlock);
    parallelFor2D(
        1, uint32_t(bh),
        [&](const Tile& band) {
            for (uint32_t by = band.y0; by < band.y1; ++by)
                for (int bx = 0; bx < bw; ++bx)
                    samples.at(uint32_t(bx), by) =
                        gradientSample(gradient.at(uint32_t(bx) * kGradientBlock, by * kGradientBlock));
        },
        kTemporalBandRows);
    parallelFor2D(
        1, uint32_t(bh),
        [&](const Tile& band) {
            for (uint32_t by = band.y0; by < band.y1; ++by)
                for (int bx = 0; bx < bw; ++bx) {
                    glm::vec2 around[9];
                    int count = 0;
                    for (int j = std::max(0, int(by) - 1); j <= std::min(bh - 1, int(by) + 1); ++j)
                        for (int i = std::max(0, bx - 1); i <= std::min(bw - 1, bx + 1); ++i)
                            around[count++] = samples.at(uint32_t(i), uint32_t(j));
                    const glm::vec2 c = antilagChange(around, count);
                    for (uint32_t y = by * kGradientBlock; y < std::min(h, (by + 1) * kGradientBlock); ++y)
                        for (uint32_t x = uint32_t(bx) * kGradientBlock; x < std::min(w, uint32_t(bx + 1) * kGradientBlock);
                             ++x)
                            change.at(x, y) = c;
                }
        },
        kTemporalBandRows);
    return asConst(change);
}

/// How a frame runs, decided once (SVGFPass::choosePipeline): the fused fast path or the scalar reference stages,
/// and within the fast path which stages share work.
struct SVGFPass::Pipeline {
    bool fusedTemporal = false;    ///< stage 1 vectorised, writing every estimate (else temporalPixel per pixel)
    bool packPlanes = false;       ///< stage 1 also packs the à-trous guide and input planes (the fast à-trous)
    bool vectorVariance = false;   ///< stage 2 vectorised over the packed planes
    bool fusedModulation = false;  ///< stage 4 inside the last fast à-trous level
};

/// Everything the stages of one frame share.
struct SVGFPass::Frame {
    PassContext& ctx;
    Pipeline pipe;
    bool split = false, sharedGuides = false;
    uint32_t w = 0, h = 0;
    AtrousParams ap;
    VarianceScales scales{};
    TemporalViews tv;
    TemporalParams tp;
    VarianceViews vv;
    AtrousFilter::FramePlanes planes{};
    uint64_t nonFinite = 0, referencePixels = 0;
};

SVGFPass::Pipeline SVGFPass::choosePipeline(const VarianceScales& scales) const {
    Pipeline p;
    if (mReferenceStages) return p;  // temporalPixel, varianceEstimatePixel, the à-trous from images, modulatePixel
    p.fusedTemporal = true;
    p.packPlanes = !mReferenceAtrous;
    p.vectorVariance = p.packPlanes && scales.series;
    p.fusedModulation = p.packPlanes && mIterations > 0;
    return p;
}

void SVGFPass::bindFrame(Frame& f) {
    PassContext& ctx = f.ctx;
    const auto connected = [&](const char* name) { return ctx.input(name) != nullptr; };
    f.split = splitSignals(connected);
    f.w = ctx.output(kFiltered)->width();
    f.h = ctx.output(kFiltered)->height();
    f.ap = mEdgeStopping;
    f.scales = varianceScales(f.ap);
    // A device runs the scalar reference stages (SVGFDevice.h), the CPU its fused fast path.
    f.pipe = ctx.device() == DeviceKind::Cpu ? choosePipeline(f.scales) : Pipeline{};
    f.referencePixels = uint64_t(f.w) * f.h;

    TemporalViews& tv = f.tv;
    tv.color = inputView<glm::vec4>(ctx, kColor);
    if (f.split) {
        tv.direct = inputView<glm::vec4>(ctx, kDirect);
        tv.indirect = inputView<glm::vec4>(ctx, kIndirect);
    }
    // On a device the sum albedo + specAlbedo is formed per pixel by the stages that read it (SVGFDevice.h).
    tv.albedo = ctx.device() == DeviceKind::Cpu ? demodulationAlbedo(ctx) : inputView<glm::vec4>(ctx, kAlbedo);
    tv.emission = inputView<glm::vec4>(ctx, kEmission);
    tv.normW = inputView<glm::vec4>(ctx, kNormW);
    tv.linearZ = inputView<glm::vec2>(ctx, kLinearZ);
    tv.mvec = inputView<glm::vec2>(ctx, kMvec);
    tv.meshId = inputView<uint32_t>(ctx, kMeshId);
    tv.prevIllum0 = pixels<glm::vec4>(ctx, ctx.historyPrev(kIllumHistory));
    if (f.split) tv.prevIllum1 = pixels<glm::vec4>(ctx, ctx.historyPrev(kIndirectHistory));
    tv.prevMoments0 = pixels<glm::vec2>(ctx, ctx.historyPrev(kMomentsHistory));
    if (f.split) tv.prevMoments1 = pixels<glm::vec2>(ctx, ctx.historyPrev(kIndirectMomentsHistory));
    tv.prevLength = pixels<float>(ctx, ctx.historyPrev(kLengthHistory));
    // Last frame's guides: the G-buffer's own previous outputs when the graph feeds them (@prev edges), else the
    // copies this pass keeps.
    f.sharedGuides = sharedPrevGuides(connected);
    if (f.sharedGuides) {
        tv.prevLinearZ = inputView<glm::vec2>(ctx, kLinearZPrev);
        tv.prevNormW = inputView<glm::vec4>(ctx, kNormWPrev);
        tv.prevMeshId = inputView<uint32_t>(ctx, kMeshIdPrev);
    } else {
        tv.prevLinearZ = pixels<glm::vec2>(ctx, ctx.historyPrev(kPrevLinearZ));
        tv.prevNormW = pixels<glm::vec4>(ctx, ctx.historyPrev(kPrevNormW));
        tv.prevMeshId = pixels<uint32_t>(ctx, ctx.historyPrev(kPrevMeshId));
    }
    tv.integrated0 = pixels<glm::vec4>(ctx, *ctx.internal(kIntegrated));
    if (f.split) tv.integrated1 = pixels<glm::vec4>(ctx, *ctx.internal(kIntegratedIndirect));
    tv.curMoments0 = pixels<glm::vec2>(ctx, ctx.historyCur(kMomentsHistory));
    if (f.split) tv.curMoments1 = pixels<glm::vec2>(ctx, ctx.historyCur(kIndirectMomentsHistory));
    tv.curLength = pixels<float>(ctx, ctx.historyCur(kLengthHistory));
    if (!f.sharedGuides) {  // else left empty: nothing is copied
        tv.curLinearZ = pixels<glm::vec2>(ctx, ctx.historyCur(kPrevLinearZ));
        tv.curNormW = pixels<glm::vec4>(ctx, ctx.historyCur(kPrevNormW));
        tv.curMeshId = pixels<uint32_t>(ctx, ctx.historyCur(kPrevMeshId));
    }

    TemporalParams& tp = f.tp;
    tp = mTemporalParams;  // alpha, momentsAlpha, maxHistory; the rest is this frame's
    tp.varianceFloor = mMeanVariance ? meanVarianceFloor(tp.alpha) : 1.f;
    if (const Camera* camera = ctx.camera()) {
        tp.jitterDelta = camera->jitter - camera->prevJitter;
        tp.prevDepth = expectedPrevDepthPlane(*camera, f.w, f.h);
    }
    // The graph zeroes the prev side after a reset (length 0: no history); the check is only a shortcut.
    tp.temporal = mTemporal && ctx.historyValid();
    tp.split = f.split;

    VarianceViews& vv = f.vv;
    vv.integrated0 = asConst(tv.integrated0);
    vv.integrated1 = asConst(tv.integrated1);
    vv.moments0 = asConst(tv.curMoments0);
    vv.moments1 = asConst(tv.curMoments1);
    vv.normW = tv.normW;
    vv.linearZ = tv.linearZ;
    vv.length = asConst(tv.curLength);
    vv.estimate0 = pixels<glm::vec4>(ctx, *ctx.internal(kEstimate));
    if (f.split) vv.estimate1 = pixels<glm::vec4>(ctx, *ctx.internal(kEstimateIndirect));
    vv.variance = outputView<float>(ctx, kVariance);
}

void SVGFPass::antilagStage(Frame& f) {
    f.tv.prevChange = shadingChange(f.ctx);
}

ImageView<glm::vec4> SVGFPass::clampBox(PassContext& ctx) const {
    // Declared only where no gradient input is connected (reflect).
    Texture* box = mHistoryClamp && !ctx.input(kGradient) ? ctx.internal(kClampBox) : nullptr;
    return box ? pixels<glm::vec4>(ctx, *box) : ImageView<glm::vec4>{};
}

void SVGFPass::neighbourhoodStage(Frame& f) {
    const ImageView<glm::vec4> box = clampBox(f.ctx);
    if (!f.tp.temporal || !box.data) return;
    svgf::device::neighbourhood(f.ctx.device(), f.tv, f.split, f.tv.albedo, {}, box);
    f.tv.neighbourhood = asConst(box);
}

void SVGFPass::temporalStage(Frame& f) {
    const uint32_t w = f.w, h = f.h;
    if (!f.pipe.fusedTemporal) {
        std::atomic<uint64_t> nonFinite{0};
        parallelFor2D(
            w, h,
            [&](const Tile& t) {
                uint64_t count = 0;
                for (uint32_t y = t.y0; y < t.y1; ++y)
                    for (uint32_t x = t.x0; x < t.x1; ++x) count += temporalPixel(f.tv, x, y, f.tp) ? 1 : 0;
                nonFinite += count;
            },
            kStreamTileSize);
        f.nonFinite = nonFinite.load();
        return;
    }
    // The fused fast path: stage 1 (vectorised) also writes every pixel's estimate and stage 2 revisits only the
    // short histories; with the fast à-trous, stage 1 also packs the à-trous guides and input planes.
    simd::TemporalOutputs to;
    if (f.pipe.packPlanes) {
        f.planes = mAtrous.preparePlanes(f.tv.linearZ, f.tv.normW, mIterations, f.split ? 2 : 1);
        to.layout = f.planes.layout;
        to.guide = f.planes.guide;
        to.signal = f.planes.signal;
        to.signal1 = f.planes.signal1;
        mRemodulationGroups.resize(size_t(simd::remodulationGroupsPerRow(w)) * h);
        to.remodulationGroups = mRemodulationGroups.data();
    }
    to.estimate = f.vv.estimate0;
    to.estimate1 = f.vv.estimate1;
    to.variance = f.vv.variance;
    mShortRows.resize(h);
    to.shortRows = mShortRows.data();
    // Only the variance stage's short histories read the estimate images on the fused path (the à-trous input
    // planes hold every estimate), unless the images are dumped or the levels take the unfiltered signal itself
    // (no levels, or feedback of the unfiltered signal).
    to.everyEstimate = !f.pipe.packPlanes || mEstimateObserved || mIterations <= 0 || mFeedbackTap < 0;
    // The vectorised variance stage reads the integrated images only at short histories and, in its scalar edge
    // columns, around them; the scalar variance stage reads them around every short history.
    to.everyIntegrated = !f.pipe.vectorVariance || mIntegratedObserved;
    const simd::TemporalCounts counts = simd::temporalFused(f.tv, f.tp, to, kTemporalBandRows);
    f.nonFinite = counts.rejected;
    f.referencePixels = counts.reference;
}

void SVGFPass::varianceStage(Frame& f) {
    Stats& stats = f.ctx.stats();
    const VarianceViews& vv = f.vv;
    const uint32_t w = f.w, h = f.h;
    const bool split = f.split;
    stats.set(kStatVarianceReference, 1.0);  // the scalar stages; the vector one counts
    if (f.pipe.vectorVariance) {
        const simd::VarianceCounts counts =
            simd::varianceFused(vv, f.scales, *f.planes.layout, f.planes.guide, f.planes.signal, f.planes.signal1,
                                split, kTemporalBandRows, mShortRows.data());
        stats.set(kStatSpatialPixels, double(counts.spatial));
        stats.set(kStatVarianceReference, counts.spatial ? double(counts.reference) / double(counts.spatial) : 0.0);
    } else if (f.pipe.fusedTemporal) {
        // Stage 1 wrote every estimate as if history were long; the short ones get the spatial estimate. Bands of
        // whole rows, as stage 1: the scan of the lengths is a plain stream.
        const AtrousFilter::FramePlanes& planes = f.planes;
        parallelFor2D(
            1, h,
            [&](const Tile& band) {
                for (uint32_t y = band.y0; y < band.y1; ++y)
                    for (uint32_t x = 0; x < w; ++x) {
                        if (!needsSpatialVariance(vv.linearZ.at(x, y).x, vv.length.at(x, y))) continue;
                        varianceEstimatePixel(vv, x, y, f.scales, split);
                        if (!f.pipe.packPlanes) continue;
                        simd::packSignalPixel(*planes.layout, planes.signal, x, y, vv.estimate0.at(x, y));
                        if (split) simd::packSignalPixel(*planes.layout, planes.signal1, x, y, vv.estimate1.at(x, y));
                    }
            },
            kTemporalBandRows);
    } else {
        parallelForPixels(
            w, h, [&](uint32_t x, uint32_t y) { varianceEstimatePixel(vv, x, y, f.scales, split); }, kStreamTileSize);
    }
}

ModulateViews SVGFPass::modulateViews(const Frame& f) const {
    ModulateViews mv;
    mv.filtered0 = asConst(f.tv.integrated0);
    mv.filtered1 = asConst(f.tv.integrated1);
    mv.color = f.tv.color;
    mv.albedo = f.tv.albedo;
    mv.emission = f.tv.emission;
    mv.linearZ = f.tv.linearZ;
    mv.dst = outputView<glm::vec4>(f.ctx, kFiltered);
    return mv;
}

void SVGFPass::atrousStage(Frame& f) {
    Stats& stats = f.ctx.stats();
    // The integrated fields are free now and take the filtered signals.
    auto t0 = Clock::now();
    if (!f.pipe.packPlanes) mAtrous.setGuide(f.tv.linearZ, f.tv.normW);
    double prepareMs = msSince(t0);
    const int levels = mIterations;
    double levelMs[16] = {};
    uint32_t skippedTiles = 0, tiles = 0;
    // The remodulation is fused into the last fast level's output (split: the second signal's, adding the first's;
    // signal 0's result is in integrated0 by then). The groups say which images each group of pixels reads.
    const simd::Remodulation remodulation{modulateViews(f), f.split,
                                          f.pipe.fusedModulation ? mRemodulationGroups.data() : nullptr,
                                          simd::remodulationGroupsPerRow(f.w)};
    auto filter = [&](ImageView<glm::vec4> src, ImageView<glm::vec4> dst, ImageView<glm::vec4> feedback,
                      const simd::Remodulation* modulate, int slot) {
        AtrousTimings timings;
        mAtrous.run(asConst(src), dst, levels, f.ap, mFeedbackTap, feedback, mReferenceAtrous, &timings, modulate,
                    slot);
        prepareMs += timings.prepareMs;
        for (int level = 0; level < levels && level < 16; ++level) levelMs[level] += timings.levelMs[level];
        skippedTiles += timings.skippedTiles;
        tiles += timings.tiles;
    };
    const simd::Remodulation* modulate = f.pipe.fusedModulation ? &remodulation : nullptr;
    filter(f.vv.estimate0, f.tv.integrated0, f.ctx.historyCur(kIllumHistory).view<glm::vec4>(),
           f.split ? nullptr : modulate, 0);
    if (f.split)
        filter(f.vv.estimate1, f.tv.integrated1, f.ctx.historyCur(kIndirectHistory).view<glm::vec4>(), modulate, 1);
    stats.set(kStatAtrousPrepare, prepareMs);
    double atrousMs = 0.0;
    for (int level = 0; level < levels && level < 16; ++level) {
        stats.set(std::string(kStatAtrous) + std::to_string(level), levelMs[level]);
        atrousMs += levelMs[level];
    }
    stats.set(kStatAtrous, atrousMs);
    stats.set(kStatSkippedTiles, tiles ? double(skippedTiles) / tiles : 0.0);
}

void SVGFPass::modulateStage(Frame& f) {
    // Remodulation unless fused into the à-trous, and the debug history length.
    const auto lengthOut = outputView<float>(f.ctx, kHistoryLength);
    const bool modulate = !f.pipe.fusedModulation;
    if (!modulate && !lengthOut.data) return;
    const ModulateViews mv = modulateViews(f);
    parallelFor2D(
        f.w, f.h,
        [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x) {
                    if (modulate) modulatePixel(mv, x, y, f.split);
                    if (lengthOut.data) lengthOut.at(x, y) = f.tv.curLength.at(x, y);
                }
        },
        kStreamTileSize);
}

bool SVGFPass::runsOn(DeviceKind device) const {
    return device == DeviceKind::Cpu || device == DeviceKind::Emulated ||
           (device == DeviceKind::Cuda && svgf::device::launchesOnCuda());
}

void SVGFPass::execute(PassContext& ctx) {
    if (ctx.device() != DeviceKind::Cpu) {
        executeOnDevice(ctx);
        return;
    }
    Stats& stats = ctx.stats();
    if (!mEnabled) {
        passThrough(ctx);
        stats.set(kStatNonFinite, 0);
        return;
    }
    Frame f{ctx};
    bindFrame(f);
    // The stages, each timed under its stat.
    using Stage = void (SVGFPass::*)(Frame&);
    const std::pair<const char*, Stage> stages[] = {{kStatAntilag, &SVGFPass::antilagStage},
                                                    {kStatNeighbourhood, &SVGFPass::neighbourhoodStage},
                                                    {kStatReproject, &SVGFPass::temporalStage},
                                                    {kStatVariance, &SVGFPass::varianceStage},
                                                    {nullptr, &SVGFPass::atrousStage},  // times its levels itself
                                                    {kStatModulate, &SVGFPass::modulateStage}};
    for (const auto& [stat, stage] : stages) {
        const auto t0 = Clock::now();
        (this->*stage)(f);
        if (stat) stats.set(stat, msSince(t0));
    }
    stats.set(kStatNonFinite, double(f.nonFinite));
    stats.set(kStatReferencePixels, double(f.referencePixels) / (double(f.w) * f.h));
    stats.set(kStatSplit, f.split ? 1 : 0);
    stats.set(kStatSharedGuides, f.sharedGuides ? 1 : 0);
}

void SVGFPass::executeOnDevice(PassContext& ctx) {
    namespace dev = svgf::device;
    const DeviceKind device = ctx.device();
    Stats& stats = ctx.stats();
    if (!mEnabled) {
        dev::passThrough(device, inputView<glm::vec4>(ctx, kColor), outputView<glm::vec4>(ctx, kFiltered));
        if (Texture* t = ctx.output(kVariance)) t->clear();
        if (Texture* t = ctx.output(kHistoryLength)) t->clear();
        ctx.historyCur(kLengthHistory).clear();  // length 0 everywhere: no history when enabled again
        stats.set(kStatNonFinite, 0);
        return;
    }
    // The stages of the reference path (referenceStages, referenceAtrous), each a launch over the scalar kernels;
    // the scratch is the graph's fields (the demodulation albedo, the à-trous ping-pong: see SVGFDevice.h).
    Frame f{ctx};
    bindFrame(f);
    const auto albedo = inputView<glm::vec4>(ctx, kAlbedo), specAlbedo = inputView<glm::vec4>(ctx, kSpecAlbedo);
    auto t0 = Clock::now();
    const auto gradient = inputView<glm::vec2>(ctx, kGradient);
    if (gradient.data && mTemporal) {
        const auto change = pixels<glm::vec2>(ctx, *ctx.internal(kChange));
        // The samples, on the block grid, live in the estimate scratch until the temporal stage writes it.
        const ImageView<glm::vec2> samples{reinterpret_cast<glm::vec2*>(f.vv.estimate0.data),
                                           (f.w + kGradientBlock - 1) / kGradientBlock,
                                           (f.h + kGradientBlock - 1) / kGradientBlock, f.vv.estimate0.rowPitch};
        dev::antilag(device, gradient, samples, change);
        f.tv.prevChange = asConst(change);
    }
    stats.set(kStatAntilag, msSince(t0));

    t0 = Clock::now();
    if (const ImageView<glm::vec4> box = clampBox(ctx); f.tp.temporal && box.data) {
        dev::neighbourhood(device, f.tv, f.split, albedo, specAlbedo, box);
        f.tv.neighbourhood = asConst(box);
    }
    stats.set(kStatNeighbourhood, msSince(t0));

    t0 = Clock::now();
    f.nonFinite = dev::temporal(device, f.tv, f.tp, albedo, specAlbedo);
    stats.set(kStatReproject, msSince(t0));

    t0 = Clock::now();
    dev::variance(device, f.vv, f.scales, f.split);
    stats.set(kStatVariance, msSince(t0));
    stats.set(kStatVarianceReference, 1.0);

    // The levels ping-pong between the integrated field (free since the variance stage; it takes the result) and
    // the output, which the remodulation writes last.
    t0 = Clock::now();
    const auto scratch = outputView<glm::vec4>(ctx, kFiltered);
    const auto normW = f.tv.normW;
    dev::atrous(device, asConst(f.vv.estimate0), f.tv.integrated0, scratch, f.tv.linearZ, normW, mIterations, f.ap,
                mFeedbackTap, pixels<glm::vec4>(ctx, ctx.historyCur(kIllumHistory)));
    if (f.split)
        dev::atrous(device, asConst(f.vv.estimate1), f.tv.integrated1, scratch, f.tv.linearZ, normW, mIterations,
                    f.ap, mFeedbackTap, pixels<glm::vec4>(ctx, ctx.historyCur(kIndirectHistory)));
    stats.set(kStatAtrous, msSince(t0));

    t0 = Clock::now();
    dev::modulate(device, modulateViews(f), f.split, albedo, specAlbedo, outputView<float>(ctx, kHistoryLength),
                  asConst(f.tv.curLength));
    stats.set(kStatModulate, msSince(t0));

    stats.set(kStatNonFinite, double(f.nonFinite));
    stats.set(kStatReferencePixels, 1.0);
    stats.set(kStatSplit, f.split ? 1 : 0);
    stats.set(kStatSharedGuides, f.sharedGuides ? 1 : 0);
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::SVGFPass>(
        "SVGFPass",
        "Spatiotemporal variance-guided filtering (Schied et al. 2017) with the paper's parameters: demodulation "
        "(by albedo, + specAlbedo when connected), "
        "reprojection with disocclusion tests, moments, spatial variance while history is short, a-trous levels "
        "with feedback, remodulation; direct and indirect filtered separately when both are connected. History in "
        "graph fields; last frame's guides from the G-buffer's @prev outputs when the graph connects linearZPrev, "
        "normWPrev "
        "(and meshIdPrev), else copied into its own history. Stats: nonFinite (colour samples rejected), split, "
        "sharedPrevGuides (1 when last frame's guides come from @prev inputs), temporal.referenceShare (fraction of "
        "pixels "
        "the temporal stage ran through the scalar reference kernel rather than the vector path), "
        "variance.spatialPixels (pixels given the spatial variance estimate; fused path only), "
        "variance.referenceShare (fraction of those through the scalar kernel), ms.reproject, "
        "ms.variance, ms.atrous.prepare, ms.atrous0.. (per level), ms.atrous (all levels), ms.modulate, "
        "atrousSkippedTiles (fraction of tiles skipRelVariance left unfiltered).");
}
