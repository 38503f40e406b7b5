#include "ToneMap.h"

#include <atomic>
#include <cmath>
#include <vector>

#include "loom/Parallel.h"
#include "loom/Plugin.h"

namespace loom {

using tonemap::Operator;
using tonemap::ToneMapParams;

namespace {

const char kSrc[] = "src";
const char kDst[] = "dst";
const char kDstFloat[] = "dstFloat";
const char kAdaptedLuminance[] = "adaptedLuminance";

// Counters reported in the frame's stats.
const char kStatExposure[] = "exposure";
const char kStatMeasured[] = "measuredLuminance";
const char kStatAdapted[] = "adaptedLuminance";
const char kStatNonFinite[] = "nonFinite";

constexpr uint32_t kTile = kDefaultTileSize;

uint32_t tilesAcross(uint32_t size) {
    return (size + kTile - 1) / kTile;
}

/// Maps every pixel of src to dst (and dstFloat when given) with operator Op; returns the number of pixels with a
/// non-finite channel (they map to finite values like any other).
template <Operator Op>
uint64_t mapFrame(const ToneMapParams& params, const tonemap::SrgbEncodeTable& table, const Texture& srcTexture,
                  Texture& dstTexture, Texture* dstFloatTexture) {
    ToneMapParams p = params;
    p.op = Op;  // a constant inside the loop: the switch in toneMapChannel folds away
    const auto src = srcTexture.view<glm::vec4>();
    const auto dst = dstTexture.view<uint32_t>();
    ImageView<glm::vec4> dstFloat{};
    if (dstFloatTexture) dstFloat = dstFloatTexture->view<glm::vec4>();
    std::atomic<uint64_t> nonFinite{0};
    parallelFor2D(
        src.width, src.height,
        [&](const Tile& t) {
            uint64_t tileNonFinite = 0;
            for (uint32_t y = t.y0; y < t.y1; ++y) {
                const glm::vec4* in = src.row(y);
                uint32_t* out = dst.row(y);
                glm::vec4* outFloat = dstFloatTexture ? dstFloat.row(y) : nullptr;
                for (uint32_t x = t.x0; x < t.x1; ++x) {
                    const glm::vec4 c = in[x];
                    tileNonFinite += !(tonemap::isFinite(c.x) && tonemap::isFinite(c.y) && tonemap::isFinite(c.z) &&
                                       tonemap::isFinite(c.w));
                    const glm::vec4 mapped = tonemap::toneMapPixel(p, c);
                    out[x] = tonemap::packSrgb8(table, mapped);
                    if (outFloat) outFloat[x] = mapped;
                }
            }
            nonFinite += tileNonFinite;  // integers: the same total in any order
        },
        kTile);
    return nonFinite;
}

}  // namespace

ToneMapPass::ToneMapPass() : mSrgbTable(std::make_unique<tonemap::SrgbEncodeTable>()) {
    tonemap::buildSrgbEncodeTable(*mSrgbTable);
}

void ToneMapPass::reflect(Reflection& r, const CompileInfo&) const {
    r.input(kSrc, Format::RGBA32F).doc("scene-referred (HDR) colour");
    r.output(kDst, Format::RGBA8Srgb)
        .doc("tone-mapped colour, sRGB-encoded (exact piecewise OETF, rounded to nearest); alpha clamped to [0, 1]");
    r.output(kDstFloat, Format::RGBA32F)
        .optional()
        .doc("tone-mapped colour before the sRGB encoding (linear, in [0, 1]); computed only when consumed");
    r.history(kAdaptedLuminance, Format::RGBA32F)
        .fixedSize(1, 1)
        .doc(
            "auto exposure state: x adapted luminance (0 while autoExposure is off), y this frame's log-average "
            "luminance, z + w the frame time in seconds");
}

void ToneMapPass::declareParams(ParamList& p) {
    p.addEnum("operator", &mOperator, Operator::Aces, {"linear", "reinhard", "modifiedReinhard", "aces", "hable"})
        .doc(
            "per-channel curve: linear (clamp), reinhard v/(1+v), modifiedReinhard v(1+v/white^2)/(1+v), aces "
            "(Narkowicz fit), hable (Uncharted 2 filmic, white 11.2)");
    p.add("exposure", &mExposureEv, 0.f).range(-20.0, 20.0).doc("exposure compensation in EV: colour times 2^EV");
    p.add("autoExposure", &mAutoExposure, false)
        .doc("scale by key / adapted log-average luminance (Reinhard 2002) before the exposure compensation");
    p.add("key", &mKey, 0.18f).range(1e-3, 100.0).doc("auto exposure: the value the log-average luminance maps to");
    p.add("adaptationTime", &mAdaptationTime, 1.f)
        .range(0.0, 1000.0)
        .doc(
            "auto exposure: time constant in seconds of the exponential adaptation (0 = immediate); the first "
            "frame and a history reset adapt immediately");
    p.add("whitePoint", &mWhitePoint, 4.f)
        .range(1e-3, 1e6)
        .doc("modifiedReinhard: the smallest exposed value that maps to white");
}

bool ToneMapPass::measureLogAverage(const Texture& srcTexture, double& logAverage, uint64_t& finitePixels) const {
    const auto src = srcTexture.view<glm::vec4>();
    const uint32_t tilesX = tilesAcross(src.width), tilesY = tilesAcross(src.height);
    std::vector<double> sums(size_t(tilesX) * tilesY, 0.0);
    std::vector<uint64_t> counts(sums.size(), 0);
    parallelFor2D(
        src.width, src.height,
        [&](const Tile& t) {
            double tileSum = 0.0;
            uint64_t tileCount = 0;
            for (uint32_t y = t.y0; y < t.y1; ++y) {
                const glm::vec4* in = src.row(y);
                // Rows are summed in float (at most kTile terms of magnitude < 128), tiles in double.
                float rowSum = 0.f;
                uint32_t rowCount = 0;
                for (uint32_t x = t.x0; x < t.x1; ++x) {
                    float term;
                    if (tonemap::logLuminance(in[x], term)) {
                        rowSum += term;
                        ++rowCount;
                    }
                }
                tileSum += double(rowSum);
                tileCount += rowCount;
            }
            const size_t index = size_t(t.y0 / kTile) * tilesX + t.x0 / kTile;
            sums[index] = tileSum;
            counts[index] = tileCount;
        },
        kTile);
    double sum = 0.0;
    finitePixels = 0;
    for (size_t i = 0; i < sums.size(); ++i) {  // fixed order: bit-identical for any thread count
        sum += sums[i];
        finitePixels += counts[i];
    }
    if (finitePixels == 0) return false;
    logAverage = std::exp2(sum / double(finitePixels));
    return true;
}

void ToneMapPass::execute(PassContext& ctx) {
    const Texture& src = *ctx.input(kSrc);
    Texture& dst = *ctx.output(kDst);
    Texture* dstFloat = ctx.output(kDstFloat);
    const glm::vec4 prevState = ctx.historyPrev(kAdaptedLuminance).view<glm::vec4>().at(0, 0);
    glm::vec4& state = ctx.historyCur(kAdaptedLuminance).view<glm::vec4>().at(0, 0);

    // The frame time as a float pair (hi + lo == the double time to ~48 bits).
    const double time = ctx.time();
    const float timeHi = float(time);
    const float timeLo = float(time - double(timeHi));

    double scale = std::exp2(double(mExposureEv));
    float adapted = 0.f, measured = 0.f;
    if (mAutoExposure) {
        double logAverage = 0.0;
        uint64_t finitePixels = 0;
        const bool prevUsable = ctx.historyValid() && prevState.x > 0.f && tonemap::isFinite(prevState.x);
        const double dt = time - (double(prevState.z) + double(prevState.w));
        if (measureLogAverage(src, logAverage, finitePixels)) {
            measured = float(logAverage);
            adapted = prevUsable && dt >= 0.0 ? tonemap::adaptLuminance(prevState.x, measured, dt, mAdaptationTime)
                                              : measured;
        } else {
            // Nothing finite to measure: keep the previous adaptation, or the key itself (scale 1).
            adapted = prevUsable ? prevState.x : mKey;
        }
        scale *= double(mKey) / double(adapted);
    }
    state = glm::vec4(adapted, measured, timeHi, timeLo);

    ToneMapParams params;
    params.scale = float(scale);
    params.invWhiteSquared = 1.f / (mWhitePoint * mWhitePoint);
    params.hableInvWhite = 1.f / tonemap::hableCurve(tonemap::kHableWhite);

    uint64_t nonFinite = 0;
    switch (mOperator) {
        case Operator::Linear:
            nonFinite = mapFrame<Operator::Linear>(params, *mSrgbTable, src, dst, dstFloat);
            break;
        case Operator::Reinhard:
            nonFinite = mapFrame<Operator::Reinhard>(params, *mSrgbTable, src, dst, dstFloat);
            break;
        case Operator::ModifiedReinhard:
            nonFinite = mapFrame<Operator::ModifiedReinhard>(params, *mSrgbTable, src, dst, dstFloat);
            break;
        case Operator::Aces:
            nonFinite = mapFrame<Operator::Aces>(params, *mSrgbTable, src, dst, dstFloat);
            break;
        case Operator::Hable:
            nonFinite = mapFrame<Operator::Hable>(params, *mSrgbTable, src, dst, dstFloat);
            break;
    }

    ctx.stats().set(kStatExposure, scale);
    ctx.stats().set(kStatMeasured, measured);
    ctx.stats().set(kStatAdapted, adapted);
    ctx.stats().set(kStatNonFinite, double(nonFinite));
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::ToneMapPass>(
        "ToneMap",
        "HDR to display: exposure compensation (EV), optional auto exposure from the log-average luminance adapted "
        "over time, linear / Reinhard / modified Reinhard / ACES / Hable operators, exact 8-bit sRGB output. "
        "Non-finite inputs map to finite outputs (NaN -> 0, +Inf -> white). Stats: exposure (scale applied), "
        "measuredLuminance, adaptedLuminance, nonFinite (pixels with a non-finite channel).");
}
