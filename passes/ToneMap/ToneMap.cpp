#include "ToneMap.h"

#include <hwy/cache_control.h>
#include <hwy/highway.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <vector>

#include "ToneMapDevice.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/simd/KernelMath-inl.h"

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

// Work is split into bands of whole rows (parallelFor2D over a 1 x height domain): long contiguous runs keep the
// hardware prefetchers streaming, which this memory-bound pass needs. One partial log-average sum per band.
constexpr uint32_t kBandRows = 8;
// Auto exposure measures the log-average on every kMeasureRowStep-th row (y % kMeasureRowStep == 0): a
// quarter of the frame's pixels (230 k at 1280x720) pins the exposure down as well as all of them, and the log per
// pixel would otherwise cost a third of the mapping. A multiple of it divides kBandRows, so each band measures the
// same rows whatever the split.
constexpr uint32_t kMeasureRowStep = 4;
static_assert(kBandRows % kMeasureRowStep == 0);

bool measuredRow(uint32_t y) {
    return y % kMeasureRowStep == 0;
}

namespace hn = hwy::HWY_NAMESPACE;
using FloatTag = hn::ScalableTag<float>;
using IntTag = hn::RebindToSigned<FloatTag>;
using FloatVec = hn::Vec<FloatTag>;
using IntVec = hn::Vec<IntTag>;

// The vector path below computes exactly what ToneMapKernels.h computes per pixel: the same operations in the same
// order (the plugin is built without FMA contraction, and the vector min / max are chosen to treat NaN as the
// scalar comparisons do), so its output is bit-identical to the reference kernel; a test checks it.

/// Channel exposure: NaN and negatives -> 0 (x86 max returns its second operand for NaN), clamp at kMaxExposed.
HWY_INLINE FloatVec exposeVec(FloatTag d, FloatVec v, FloatVec scale) {
    return hn::Min(hn::Mul(hn::Max(v, hn::Zero(d)), scale), hn::Set(d, tonemap::kMaxExposed));
}

HWY_INLINE FloatVec saturateVec(FloatTag d, FloatVec v) {
    return hn::Min(hn::Max(v, hn::Zero(d)), hn::Set(d, 1.f));
}

template <Operator Op>
HWY_INLINE FloatVec operatorVec(FloatTag d, FloatVec v, const ToneMapParams& p) {
    const FloatVec one = hn::Set(d, 1.f);
    if constexpr (Op == Operator::Linear) {
        return v;
    } else if constexpr (Op == Operator::Reinhard) {
        return hn::Div(v, hn::Add(one, v));
    } else if constexpr (Op == Operator::ModifiedReinhard) {
        return hn::Div(hn::Mul(v, hn::Add(one, hn::Mul(v, hn::Set(d, p.invWhiteSquared)))), hn::Add(one, v));
    } else if constexpr (Op == Operator::Aces) {
        const FloatVec num = hn::Mul(v, hn::Add(hn::Mul(hn::Set(d, 2.51f), v), hn::Set(d, 0.03f)));
        const FloatVec den =
            hn::Add(hn::Mul(v, hn::Add(hn::Mul(hn::Set(d, 2.43f), v), hn::Set(d, 0.59f))), hn::Set(d, 0.14f));
        return hn::Div(num, den);
    } else {
        using namespace tonemap;
        const FloatVec a = hn::Set(d, kHableA);
        const FloatVec num =
            hn::Add(hn::Mul(v, hn::Add(hn::Mul(a, v), hn::Set(d, kHableC * kHableB))), hn::Set(d, kHableD * kHableE));
        const FloatVec den =
            hn::Add(hn::Mul(v, hn::Add(hn::Mul(a, v), hn::Set(d, kHableB))), hn::Set(d, kHableD * kHableF));
        return hn::Mul(hn::Sub(hn::Div(num, den), hn::Set(d, kHableE / kHableF)), hn::Set(d, p.hableInvWhite));
    }
}

/// encodeSrgb8 on a vector of saturated values: one gather per vector, none when every lane is black (code 0:
/// below the first bucket) or white (255), as a sky or a blown-out light is.
HWY_INLINE IntVec encodeSrgbVec(FloatTag d, const SrgbEncodeTable& t, FloatVec v) {
    using Table = SrgbEncodeTable;
    const IntTag di;
    const IntVec bits = hn::BitCast(di, v);
    const auto black = hn::Lt(bits, hn::Set(di, int32_t(Table::kFirstBits)));
    const auto white = hn::RebindMask(di, hn::Ge(v, hn::Set(d, 1.f)));
    if (hn::AllTrue(di, hn::Or(black, white))) return hn::IfThenElseZero(white, hn::Set(di, 255));
    IntVec index =
        hn::Sub(hn::ShiftRight<Table::kShift>(bits), hn::Set(di, int32_t(Table::kFirstBits >> Table::kShift)));
    index = hn::Min(hn::Max(index, hn::Zero(di)), hn::Set(di, int32_t(Table::kBuckets - 1)));  // lanes below are masked
    const IntVec entry = hn::GatherIndex(di, t.entry, index);
    const IntVec offset = hn::And(bits, hn::Set(di, int32_t(Table::kOffsetMask)));
    // offset >= threshold offset, as "not less than" (both non-negative).
    const auto reached = hn::Not(hn::Lt(offset, hn::ShiftRight<8>(entry)));
    IntVec code = hn::Add(hn::And(entry, hn::Set(di, 255)), hn::IfThenElseZero(reached, hn::Set(di, 1)));
    code = hn::IfThenZeroElse(black, code);
    return hn::IfThenElse(white, hn::Set(di, 255), code);
}

/// Lanes with a non-finite value.
HWY_INLINE hn::Mask<IntTag> nonFiniteVec(FloatVec v) {
    const IntTag di;
    const IntVec exponent = hn::Set(di, 0x7F800000);
    return hn::Eq(hn::And(hn::BitCast(di, v), exponent), exponent);
}

/// The log-luminance terms (fastLog2 of kLogEpsilon + luminance, lane-wise) of 8 pixels added to `acc`, and their
/// finite count to `finiteCount`; non-finite pixels add nothing.
HWY_INLINE void logLuminanceVec(FloatTag d, FloatVec r, FloatVec g, FloatVec b, FloatVec& acc, IntVec& finiteCount) {
    const IntTag di;
    const FloatVec one = hn::Set(d, 1.f);
    const auto bad = hn::Or(hn::Or(nonFiniteVec(r), nonFiniteVec(g)), nonFiniteVec(b));
    r = exposeVec(d, r, one);
    g = exposeVec(d, g, one);
    b = exposeVec(d, b, one);
    const FloatVec lum = simd::HWY_NAMESPACE::luminanceSum(d, r, g, b);
    const FloatVec v = hn::Add(hn::Set(d, tonemap::kLogEpsilon), lum);
    // fastLog2, lane-wise.
    const IntVec bits = hn::BitCast(di, v);
    IntVec exponent = hn::Sub(hn::ShiftRight<23>(bits), hn::Set(di, 127));
    FloatVec m = hn::BitCast(d, hn::Or(hn::And(bits, hn::Set(di, 0x007FFFFF)), hn::Set(di, 0x3F800000)));
    const auto high = hn::Gt(m, hn::Set(d, 1.41421356f));
    m = hn::IfThenElse(high, hn::Mul(m, hn::Set(d, 0.5f)), m);
    exponent = hn::Add(exponent, hn::IfThenElseZero(hn::RebindMask(di, high), hn::Set(di, 1)));
    const FloatVec t = hn::Div(hn::Sub(m, one), hn::Add(m, one));
    const FloatVec t2 = hn::Mul(t, t);
    FloatVec series = hn::Add(hn::Set(d, 1.f / 7.f), hn::Mul(t2, hn::Set(d, 1.f / 9.f)));
    series = hn::Add(hn::Set(d, 1.f / 5.f), hn::Mul(t2, series));
    series = hn::Add(hn::Set(d, 1.f / 3.f), hn::Mul(t2, series));
    series = hn::Mul(t, hn::Add(one, hn::Mul(t2, series)));
    const FloatVec term = hn::Add(hn::ConvertTo(d, exponent), hn::Mul(hn::Set(d, 2.8853900817779268f), series));
    acc = hn::Add(acc, hn::IfThenZeroElse(hn::RebindMask(d, bad), term));
    finiteCount = hn::Add(finiteCount, hn::IfThenZeroElse(bad, hn::Set(di, 1)));
}

/// Adds the lanes of the vector sums, then the scalar terms of [x, x1), in a fixed order.
HWY_INLINE void finishLogLuminance(FloatVec acc, IntVec finiteCount, const glm::vec4* in, uint32_t x, uint32_t x1,
                                   double& sum, uint64_t& count) {
    const FloatTag d;
    const IntTag di;
    const uint32_t n = uint32_t(hn::Lanes(d));
    alignas(64) float lanes[hn::MaxLanes(d)];
    alignas(64) int32_t counts[hn::MaxLanes(d)];
    hn::Store(acc, d, lanes);
    hn::Store(finiteCount, di, counts);
    for (uint32_t i = 0; i < n; ++i) {
        sum += double(lanes[i]);
        count += uint64_t(counts[i]);
    }
    for (; x < x1; ++x) {
        float term;
        if (tonemap::logLuminance(in[x], term)) {
            sum += double(term);
            ++count;
        }
    }
}

/// Sum of the log-luminance terms of a row segment and the number of finite pixels in it. Vector lanes sum in
/// float, then the lanes and the scalar rest are added in a fixed order.
void logLuminanceRow(const glm::vec4* in, uint32_t x0, uint32_t x1, double& sum, uint64_t& count) {
    const FloatTag d;
    const IntTag di;
    const uint32_t n = uint32_t(hn::Lanes(d));
    FloatVec acc = hn::Zero(d);
    IntVec finiteCount = hn::Zero(di);
    uint32_t x = x0;
    for (; x + n <= x1; x += n) {
        FloatVec r, g, b, a;
        hn::LoadInterleaved4(d, reinterpret_cast<const float*>(in + x), r, g, b, a);
        logLuminanceVec(d, r, g, b, acc, finiteCount);
    }
    finishLogLuminance(acc, finiteCount, in, x, x1, sum, count);
}

/// Pixels per chunk of mapRow: its mapped channels (4 x 2 KiB) stay in L1 next to the sRGB table (16 KiB).
constexpr uint32_t kChunk = 128;

/// One row segment [x0, x1) through the operator: chunks of whole vectors of pixels in two loops, the exposure and
/// the operator into a small buffer, then the sRGB encoding and the stores (two short loops whose iterations the
/// processor overlaps; one long one waits on each vector's divisions and table lookups in turn), then the reference
/// kernel for the rest. Returns the pixels with a non-finite channel.
/// With Measure, also sums the row's log-luminance terms into logSum / logCount from the same loads, with the same
/// operations and order as logLuminanceRow (so the sums are the same bits).
template <Operator Op, bool Measure>
uint64_t mapRow(const ToneMapParams& p, const SrgbEncodeTable& table, const glm::vec4* in, uint32_t* out,
                glm::vec4* outFloat, uint32_t x0, uint32_t x1, double& logSum, uint64_t& logCount) {
    const FloatTag d;
    const IntTag di;
    const uint32_t n = uint32_t(hn::Lanes(d));
    const FloatVec scale = hn::Set(d, p.scale);
    uint64_t nonFinite = 0;
    FloatVec logAcc = hn::Zero(d);
    IntVec logFinite = hn::Zero(di);
    alignas(64) float mapped[4][kChunk];
    uint32_t x = x0;
    while (x + n <= x1) {
        const uint32_t count = std::min(kChunk, (x1 - x) / n * n);
        for (uint32_t i = 0; i < count; i += n) {
            FloatVec r, g, b, a;
            hn::LoadInterleaved4(d, reinterpret_cast<const float*>(in + x + i), r, g, b, a);
            if constexpr (Measure) logLuminanceVec(d, r, g, b, logAcc, logFinite);
            nonFinite += hn::CountTrue(
                di, hn::Or(hn::Or(nonFiniteVec(r), nonFiniteVec(g)), hn::Or(nonFiniteVec(b), nonFiniteVec(a))));
            hn::Store(saturateVec(d, operatorVec<Op>(d, exposeVec(d, r, scale), p)), d, mapped[0] + i);
            hn::Store(saturateVec(d, operatorVec<Op>(d, exposeVec(d, g, scale), p)), d, mapped[1] + i);
            hn::Store(saturateVec(d, operatorVec<Op>(d, exposeVec(d, b, scale), p)), d, mapped[2] + i);
            hn::Store(saturateVec(d, a), d, mapped[3] + i);
        }
        for (uint32_t i = 0; i < count; i += n) {
            const FloatVec r = hn::Load(d, mapped[0] + i), g = hn::Load(d, mapped[1] + i);
            const FloatVec b = hn::Load(d, mapped[2] + i), a = hn::Load(d, mapped[3] + i);
            if (outFloat) hn::StoreInterleaved4(r, g, b, a, d, reinterpret_cast<float*>(outFloat + x + i));
            const IntVec alpha = hn::ConvertTo(di, hn::Add(hn::Mul(a, hn::Set(d, 255.f)), hn::Set(d, 0.5f)));
            IntVec packed = encodeSrgbVec(d, table, r);
            packed = hn::Or(packed, hn::ShiftLeft<8>(encodeSrgbVec(d, table, g)));
            packed = hn::Or(packed, hn::ShiftLeft<16>(encodeSrgbVec(d, table, b)));
            packed = hn::Or(packed, hn::ShiftLeft<24>(alpha));
            // Rows start 64-byte aligned and x is a multiple of the vector: a streaming store, which skips reading
            // the destination lines for ownership (a fifth of the pass's traffic).
            hn::Stream(packed, di, reinterpret_cast<int32_t*>(out + x + i));
        }
        x += count;
    }
    if constexpr (Measure) finishLogLuminance(logAcc, logFinite, in, x, x1, logSum, logCount);
    ToneMapParams scalar = p;
    scalar.op = Op;
    for (; x < x1; ++x) {
        const glm::vec4 c = in[x];
        nonFinite += !isFinite(c.x) || !isFinite(c.y) || !isFinite(c.z) || !isFinite(c.w);
        const glm::vec4 mapped = tonemap::toneMapPixel(scalar, c);
        out[x] = tonemap::packSrgb8(table, mapped);
        if (outFloat) outFloat[x] = mapped;
    }
    return nonFinite;
}

/// The same row with the per-pixel reference kernel only.
uint64_t mapRowReference(const ToneMapParams& p, const SrgbEncodeTable& table, const glm::vec4* in, uint32_t* out,
                         glm::vec4* outFloat, uint32_t x0, uint32_t x1) {
    uint64_t nonFinite = 0;
    for (uint32_t x = x0; x < x1; ++x) {
        const glm::vec4 c = in[x];
        nonFinite += !isFinite(c.x) || !isFinite(c.y) || !isFinite(c.z) || !isFinite(c.w);
        const glm::vec4 mapped = tonemap::toneMapPixel(p, c);
        out[x] = tonemap::packSrgb8(table, mapped);
        if (outFloat) outFloat[x] = mapped;
    }
    return nonFinite;
}

/// The log-luminance terms of a row segment, by the reference kernel.
void logLuminanceRowReference(const glm::vec4* in, uint32_t x0, uint32_t x1, double& sum, uint64_t& count) {
    for (uint32_t x = x0; x < x1; ++x) {
        float term;
        if (tonemap::logLuminance(in[x], term)) {
            sum += double(term);
            ++count;
        }
    }
}

/// Per-band partial sums of the log-average, added in band order at the end: the same bits for any thread count.
struct LogAverageSums {
    explicit LogAverageSums(uint32_t height)
        : sums((height + kBandRows - 1) / kBandRows, 0.0), counts(sums.size(), 0) {}
    void store(const Tile& band, double sum, uint64_t count) {
        sums[band.y0 / kBandRows] = sum;
        counts[band.y0 / kBandRows] = count;
    }
    /// exp2 of the mean term; false when no pixel was finite.
    bool logAverage(double& result) const {
        double sum = 0.0;
        uint64_t count = 0;
        for (size_t i = 0; i < sums.size(); ++i) {
            sum += sums[i];
            count += counts[i];
        }
        return tonemap::logAverageOf(sum, count, result);
    }
    std::vector<double> sums;
    std::vector<uint64_t> counts;
};

/// Maps every pixel of src to dst (and dstFloat when given) with operator Op, and, when `measure` is given, sums
/// the log-luminance of the measured rows while they are in cache (one read of src for both). Returns the number of
/// pixels with a non-finite channel (they map to finite values like any other).
template <Operator Op>
uint64_t mapFrame(const ToneMapParams& params, const SrgbEncodeTable& table, const Texture& srcTexture,
                  Texture& dstTexture, Texture* dstFloatTexture, LogAverageSums* measure, bool reference) {
    ToneMapParams p = params;
    p.op = Op;  // a constant inside the loop: the switch in toneMapChannel folds away
    const auto src = srcTexture.view<glm::vec4>();
    const auto dst = dstTexture.view<uint32_t>();
    ImageView<glm::vec4> dstFloat{};
    if (dstFloatTexture) dstFloat = dstFloatTexture->view<glm::vec4>();
    std::atomic<uint64_t> nonFinite{0};
    const uint32_t width = src.width;
    parallelFor2D(
        1, src.height,
        [&](const Tile& t) {
            uint64_t tileNonFinite = 0;
            double logSum = 0.0;
            uint64_t logCount = 0;
            for (uint32_t y = t.y0; y < t.y1; ++y) {
                const glm::vec4* in = src.row(y);
                glm::vec4* outFloat = dstFloatTexture ? dstFloat.row(y) : nullptr;
                if (reference) {
                    if (measure && measuredRow(y)) logLuminanceRowReference(in, 0, width, logSum, logCount);
                    tileNonFinite += mapRowReference(p, table, in, dst.row(y), outFloat, 0, width);
                } else if (measure && measuredRow(y)) {
                    tileNonFinite += mapRow<Op, true>(p, table, in, dst.row(y), outFloat, 0, width, logSum, logCount);
                } else {
                    tileNonFinite += mapRow<Op, false>(p, table, in, dst.row(y), outFloat, 0, width, logSum, logCount);
                }
            }
            hwy::FlushStream();
            if (measure) measure->store(t, logSum, logCount);
            nonFinite += tileNonFinite;  // integers: the same total in any order
        },
        kBandRows);
    return nonFinite;
}

}  // namespace

ToneMapPass::ToneMapPass() : mSrgbTable(std::make_unique<SrgbEncodeTable>()) {
    buildSrgbEncodeTable(*mSrgbTable);
}

void ToneMapPass::reflect(Reflection& r, const CompileInfo&) const {
    r.input(kSrc, Format::RGBA32F).role(FieldRole::DisplayInput).doc("scene-referred (HDR) colour");
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
    p.addEnum("operator", &mMapping.op, tonemap::ToneMapParams{}.op,
              {"linear", "reinhard", "modifiedReinhard", "aces", "hable"})
        .doc(
            "per-channel curve: linear (clamp), reinhard v/(1+v), modifiedReinhard v(1+v/white^2)/(1+v), aces "
            "(Narkowicz fit), hable (Uncharted 2 filmic, white 11.2)");
    p.add("exposure", &mExposureEv, 0.f).range(-20.0, 20.0).doc("exposure compensation in EV: colour times 2^EV");
    p.add("autoExposure", &mAutoExposure, false)
        .doc(
            "scale by key / adapted log-average luminance (Reinhard 2002; measured on every 4th row) before the "
            "exposure compensation");
    p.add("key", &mKey, 0.18f).range(1e-3, 100.0).doc("auto exposure: the value the log-average luminance maps to");
    p.add("adaptationTime", &mAdaptationTime, 1.f)
        .range(0.0, 1000.0)
        .doc(
            "auto exposure: time constant in seconds of the exponential adaptation (0 = immediate); the first "
            "frame and a history reset adapt immediately");
    p.add("whitePoint", &mWhitePoint, 4.f)
        .range(1e-3, 1e6)
        .doc("modifiedReinhard: the smallest exposed value that maps to white");
    p.add("reference", &mReference, false)
        .doc("run the plain per-pixel reference kernel instead of the vector CPU path (same output, slower)");
}

bool ToneMapPass::measureLogAverage(const Texture& srcTexture, double& logAverage) const {
    const auto src = srcTexture.view<glm::vec4>();
    LogAverageSums sums(src.height);
    parallelFor2D(
        1, src.height,
        [&](const Tile& t) {
            double sum = 0.0;
            uint64_t count = 0;
            for (uint32_t y = t.y0; y < t.y1; ++y) {
                if (!measuredRow(y)) continue;
                if (mReference)
                    logLuminanceRowReference(src.row(y), 0, src.width, sum, count);
                else
                    logLuminanceRow(src.row(y), 0, src.width, sum, count);
            }
            sums.store(t, sum, count);
        },
        kBandRows);
    return sums.logAverage(logAverage);
}

bool ToneMapPass::runsOn(DeviceKind device) const {
    return device == DeviceKind::Cpu || tonemap::deviceRuns(device);
}

void ToneMapPass::execute(PassContext& ctx) {
    const Texture& src = *ctx.input(kSrc);
    Texture& dst = *ctx.output(kDst);
    Texture* dstFloat = ctx.output(kDstFloat);
    // Off the host (emulated, cuda) the kernels run through launch2D and the frame's sums through reduceRows; the
    // state texel comes and goes through them too (ToneMapDevice.h). The sums come first there: the log-average
    // when auto exposure needs it, and the non-finite pixels.
    const DeviceKind device = ctx.device();
    const bool onDevice = device != DeviceKind::Cpu;
    const glm::vec4 prevState = onDevice ? tonemap::loadState(device, ctx.historyPrev(kAdaptedLuminance))
                                         : ctx.historyPrev(kAdaptedLuminance).view<glm::vec4>().at(0, 0);
    tonemap::FrameSums deviceSums;
    if (onDevice) deviceSums = tonemap::sumFrame(device, src, mAutoExposure ? kMeasureRowStep : 0);

    // The frame time as a float pair (hi + lo == the double time to ~48 bits).
    const double time = ctx.time();
    const float timeHi = float(time);
    const float timeLo = float(time - double(timeHi));

    // Auto exposure. While adapting (history valid, adaptationTime > 0), this frame is exposed by the luminance
    // adapted up to the previous frame, and its own log-average is measured in the same pass as the mapping (one
    // read of src); the adapted value then moves towards it. Otherwise (first frame, reset, adaptationTime 0, time
    // going backwards) src is measured first and the frame is exposed by its own log-average: immediate adaptation.
    double scale = std::exp2(double(mExposureEv));
    float adapted = 0.f, measured = 0.f;
    bool measureWhileMapping = false;
    double dt = 0.0;
    if (mAutoExposure) {
        const bool prevUsable = ctx.historyValid() && prevState.x > 0.f && isFinite(prevState.x);
        dt = time - (double(prevState.z) + double(prevState.w));
        measureWhileMapping = prevUsable && dt >= 0.0 && mAdaptationTime > 0.f;
        if (measureWhileMapping) {
            adapted = prevState.x;
        } else {
            double logAverage = 0.0;
            // Nothing finite to measure: keep the previous adaptation, or the key itself (scale 1).
            const bool finite = onDevice ? tonemap::logAverageOf(deviceSums.logSum, deviceSums.logCount, logAverage)
                                         : measureLogAverage(src, logAverage);
            adapted = finite ? (measured = float(logAverage)) : prevUsable ? prevState.x : mKey;
        }
        scale *= double(mKey) / double(adapted);
    }

    ToneMapParams params = mMapping;
    params.scale = float(scale);
    params.invWhiteSquared = 1.f / (mWhitePoint * mWhitePoint);
    params.hableInvWhite = 1.f / tonemap::hableCurve(tonemap::kHableWhite);

    std::unique_ptr<LogAverageSums> sums;
    if (measureWhileMapping && !onDevice) sums = std::make_unique<LogAverageSums>(src.height());
    uint64_t nonFinite = 0;
    if (onDevice) {
        if (mDeviceSrgbTable.empty() || mDeviceSrgbTable.residence() != device)
            mDeviceSrgbTable = tonemap::uploadSrgbTable(device, *mSrgbTable);
        tonemap::mapFrame(device, params, mDeviceSrgbTable, src, dst, dstFloat);
        nonFinite = deviceSums.nonFinite;
    } else {
        switch (params.op) {
            case Operator::Linear:
                nonFinite = mapFrame<Operator::Linear>(params, *mSrgbTable, src, dst, dstFloat, sums.get(), mReference);
                break;
            case Operator::Reinhard:
                nonFinite =
                    mapFrame<Operator::Reinhard>(params, *mSrgbTable, src, dst, dstFloat, sums.get(), mReference);
                break;
            case Operator::ModifiedReinhard:
                nonFinite = mapFrame<Operator::ModifiedReinhard>(params, *mSrgbTable, src, dst, dstFloat, sums.get(),
                                                                 mReference);
                break;
            case Operator::Aces:
                nonFinite = mapFrame<Operator::Aces>(params, *mSrgbTable, src, dst, dstFloat, sums.get(), mReference);
                break;
            case Operator::Hable:
                nonFinite = mapFrame<Operator::Hable>(params, *mSrgbTable, src, dst, dstFloat, sums.get(), mReference);
                break;
        }
    }
    if (measureWhileMapping) {
        double logAverage = 0.0;
        const bool finite = onDevice ? tonemap::logAverageOf(deviceSums.logSum, deviceSums.logCount, logAverage)
                                     : sums->logAverage(logAverage);
        if (finite) {
            measured = float(logAverage);
            adapted = tonemap::adaptLuminance(prevState.x, measured, dt, mAdaptationTime);
        }  // else: nothing finite, the adaptation stays where it was
    }
    const glm::vec4 state(adapted, measured, timeHi, timeLo);
    if (onDevice)
        tonemap::storeState(device, ctx.historyCur(kAdaptedLuminance), state);
    else
        ctx.historyCur(kAdaptedLuminance).view<glm::vec4>().at(0, 0) = state;

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
