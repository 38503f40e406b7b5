// Image error metrics (conventions in Metrics.h and docs/METRICS.md).
//
// Structure: RelMSE, SMAPE, PSNR and the temporal error are the per-pixel terms of loom/MetricKernels.h summed by
// reduceRows on the CPU (each row left to right, then the rows top to bottom): the functions and the order ErrorMeasure
// uses on a device, so the two agree bit for bit. The other metrics run over loom::parallelFor2D tiles and return one
// partial sum per tile (double), combined afterwards in tile order. Neither depends on the thread count. The filtered
// metrics (SSIM, FLIP) work on planar float copies of the tone-mapped inputs and run each tile's separable filters in
// tile-local scratch: a horizontal pass over the tile's rows plus the vertical halo, then a vertical pass fused with the
// per-pixel formula.
#include "loom/Metrics.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <string>

#include "hwy/contrib/math/math-inl.h"
#include "hwy/highway.h"
#include "loom/Error.h"
#include "loom/KernelMath.h"
#include "loom/MetricKernels.h"
#include "loom/Parallel.h"

namespace loom {

namespace {

namespace hn = hwy::HWY_NAMESPACE;

/// out[i] = base[i]^exponent[i] for base >= 0 (0^0 = 1, 0^e = 0 for e > 0), with Highway's Exp and
/// Log (statically compiled for the build's baseline target). The tail is padded to a full vector,
/// so every element takes the same arithmetic.
void powRow(const float* base, const float* exponent, float* out, int n) {
    const hn::ScalableTag<float> d;
    const int lanes = int(hn::Lanes(d));
    const auto zero = hn::Zero(d), one = hn::Set(d, 1.0f), tiny = hn::Set(d, 1e-30f);
    auto one_vector = [&](const float* b, const float* e, float* o) {
        const auto vb = hn::LoadU(d, b), ve = hn::LoadU(d, e);
        const auto r = hn::Exp(d, hn::Mul(ve, hn::Log(d, hn::Max(vb, tiny))));
        const auto atZero = hn::IfThenElse(hn::Eq(ve, zero), one, zero);
        hn::StoreU(hn::IfThenElse(hn::Le(vb, zero), atZero, r), d, o);
    };
    int i = 0;
    for (; i + lanes <= n; i += lanes) one_vector(base + i, exponent + i, out + i);
    if (i < n) {
        alignas(64) float b[64] = {}, e[64] = {}, o[64];
        for (int k = 0; k < n - i; ++k) {
            b[k] = base[i + k];
            e[k] = exponent[i + k];
        }
        one_vector(b, e, o);
        for (int k = 0; k < n - i; ++k) out[i + k] = o[k];
    }
}

// ---------------------------------------------------------------------------------------------
// Validation and reductions

void checkSameSize(const MetricImage& a, const MetricImage& b, const char* what) {
    if (a.width != b.width || a.height != b.height)
        throwBadInput(what,
                      "images of different sizes (" + std::to_string(a.width) + "x" + std::to_string(a.height) +
                          " and " + std::to_string(b.width) + "x" + std::to_string(b.height) + ")",
                      "two images of the same size");
}

void checkMap(const ImageView<float>* map, const MetricImage& a, const char* what) {
    if (map && (map->width != a.width || map->height != a.height || !map->data))
        throwBadInput(what, "error image of the wrong size", "an R32F image of the input size");
}

MetricImage viewOf(const Texture& t, const char* what) {
    if (t.format() != Format::RGBA32F)
        throwBadInput(what, std::string("texture of format ") + std::string(formatInfo(t.format()).name), "RGBA32F");
    return t.view<glm::vec4>();
}

ImageView<float> mapOf(Texture& t, const char* what) {
    if (t.format() != Format::R32F) throwBadInput(what, "error image not R32F", "an R32F texture");
    return t.view<float>();
}

struct Sums {
    double sum = 0.0;
    uint64_t count = 0;      // pixels that entered the mean
    uint64_t nonFinite = 0;  // pixels with a non-finite channel
    Sums& operator+=(const Sums& o) {
        sum += o.sum;
        count += o.count;
        nonFinite += o.nonFinite;
        return *this;
    }
};

/// Runs fn(tile) -> Sums over fixed tiles and adds the partial sums in tile order.
template <class Fn>
Sums reduceTiles(uint32_t width, uint32_t height, uint32_t tileSize, Fn&& fn) {
    const uint32_t tilesX = (width + tileSize - 1) / tileSize;
    const uint32_t tilesY = (height + tileSize - 1) / tileSize;
    std::vector<Sums> partial(size_t(tilesX) * tilesY);
    parallelFor2D(
        width, height, [&](const Tile& t) { partial[size_t(t.y0 / tileSize) * tilesX + t.x0 / tileSize] = fn(t); },
        tileSize);
    Sums total;
    for (const Sums& p : partial) total += p;
    return total;
}

bool finite3(const glm::vec4& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

double meanOf(const Sums& s, double perPixel) {
    return s.count ? s.sum / (double(s.count) * perPixel) : 0.0;
}

// ---------------------------------------------------------------------------------------------
// Tone map: clamp to [0, 1], then the sRGB OETF from a table indexed by the float's exponent and
// top 8 mantissa bits (9 octaves down to 2^-9, below which the OETF is linear), linearly
// interpolated: the error of the interpolation is below 4e-7 (h^2/8 times the curvature).

double srgbOetfExact(double x) {
    return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
}

struct OetfTable {
    // + 2: x = 1 reads index 9 * 256 and the one after it.
    alignas(64) std::array<float, kOetfTableSize> v{};
    OetfTable() {
        for (int i = 0; i <= kOetfOctaves * kOetfPerOctave; ++i) {
            const int octave = i / kOetfPerOctave, m = i % kOetfPerOctave;
            v[size_t(i)] = float(srgbOetfExact(std::ldexp(1.0 + double(m) / kOetfPerOctave, octave - kOetfOctaves)));
        }
        v.back() = v[v.size() - 2];
    }
};
const OetfTable kOetf;

/// In place over n values: OETF(clamp(x, 0, 1)); NaN becomes 0 (the callers apply the non-finite
/// rule first). Vectorised with Highway gathers; the tail is padded to a full vector, so the scalar
/// ldrToneMap() agrees bit for bit.
void toneMapRow(float* values, int n) {
    const hn::ScalableTag<float> d;
    const hn::RebindToSigned<decltype(d)> di;
    const int lanes = int(hn::Lanes(d));
    const auto zero = hn::Zero(d), one = hn::Set(d, 1.0f);
    const auto lowest = hn::Set(d, 0.001953125f), slope = hn::Set(d, 12.92f);
    const auto fracScale = hn::Set(d, 1.0f / float(1 << (23 - kOetfMantissaBits)));
    const auto base = hn::Set(di, int32_t((127 - kOetfOctaves) << kOetfMantissaBits));
    const auto fracMask = hn::Set(di, int32_t((1 << (23 - kOetfMantissaBits)) - 1));
    const float* table = kOetf.v.data();
    auto one_vector = [&](float* p) {
        const auto x = hn::Min(hn::Max(hn::LoadU(d, p), zero), one);  // maxps returns its 2nd operand for NaN
        const auto bits = hn::BitCast(di, hn::Max(x, lowest));
        const auto index = hn::Sub(hn::ShiftRight<23 - kOetfMantissaBits>(bits), base);
        const auto frac = hn::Mul(hn::ConvertTo(d, hn::And(bits, fracMask)), fracScale);
        const auto a = hn::GatherIndex(d, table, index), b = hn::GatherIndex(d, table + 1, index);
        const auto curve = hn::MulAdd(frac, hn::Sub(b, a), a);
        hn::StoreU(hn::IfThenElse(hn::Lt(x, lowest), hn::Mul(slope, x), curve), d, p);
    };
    int i = 0;
    for (; i + lanes <= n; i += lanes) one_vector(values + i);
    if (i < n) {
        alignas(64) float v[64] = {};
        for (int k = 0; k < n - i; ++k) v[k] = values[i + k];
        one_vector(v);
        for (int k = 0; k < n - i; ++k) values[i + k] = v[k];
    }
}

/// Tone map of one finite value.
inline float toneMapFinite(float x) {
    toneMapRow(&x, 1);
    return x;
}

/// Planar copies of the tone-mapped R, G, B of both images (test planes 0..2, reference 3..5),
/// with the non-finite rule applied; nonFinite marks the affected pixels.
struct LdrPlanes {
    uint32_t width = 0, height = 0;
    std::vector<float> plane[6];
    std::vector<uint8_t> nonFinite;
    uint64_t nonFiniteCount = 0;
};

/// Fills LdrPlanes. `linear` stores linear clamp(x, 0, 1) values instead of sRGB-encoded ones
/// (FLIP's input after its sRGB decode); the non-finite rule is decided on the encoded values.
void makeLdrPlanes(const MetricImage& test, const MetricImage& ref, bool linear, LdrPlanes& out) {
    out.width = test.width;
    out.height = test.height;
    const size_t n = size_t(test.width) * test.height;
    for (auto& p : out.plane) p.resize(n);
    out.nonFinite.assign(n, 0);
    const Sums s = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4* tr = test.row(y);
            const glm::vec4* rr = ref.row(y);
            const size_t rowBase = size_t(y) * test.width;
            // Deinterleave, then tone-map contiguous runs (vectorised); fix non-finite pixels after.
            float* __restrict pl[6];
            for (int p = 0; p < 6; ++p) pl[p] = out.plane[p].data() + rowBase;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                const glm::vec4 a = tr[x], b = rr[x];
                pl[0][x] = a.x;
                pl[1][x] = a.y;
                pl[2][x] = a.z;
                pl[3][x] = b.x;
                pl[4][x] = b.y;
                pl[5][x] = b.z;
            }
            uint32_t badBits = 0;  // any exponent of all ones (Inf or NaN)
            for (int p = 0; p < 6; ++p)
                for (uint32_t x = tile.x0; x < tile.x1; ++x)
                    badBits |= uint32_t((std::bit_cast<uint32_t>(pl[p][x]) & 0x7f800000u) == 0x7f800000u);
            const bool anyBad = badBits != 0;
            if (!linear)
                for (int p = 0; p < 6; ++p) toneMapRow(out.plane[p].data() + rowBase + tile.x0, int(tile.x1 - tile.x0));
            else
                for (int p = 0; p < 6; ++p) {
                    float* row = out.plane[p].data() + rowBase;
                    for (uint32_t x = tile.x0; x < tile.x1; ++x) row[x] = std::min(std::max(row[x], 0.0f), 1.0f);
                }
            if (!anyBad) continue;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                if (finite3(tr[x]) && finite3(rr[x])) continue;
                const size_t i = rowBase + x;
                float t[3], r[3];
                ldrPair(kOetf.v.data(), tr[x], rr[x], t, r);
                if (linear)  // finite channels keep their exact linear value; replaced ones are 0 or 1 in both
                    for (int c = 0; c < 3; ++c) {
                        if (std::isfinite(tr[x][c])) t[c] = std::clamp(tr[x][c], 0.0f, 1.0f);
                        if (std::isfinite(rr[x][c])) r[c] = std::clamp(rr[x][c], 0.0f, 1.0f);
                    }
                for (int c = 0; c < 3; ++c) {
                    out.plane[c][i] = t[c];
                    out.plane[3 + c][i] = r[c];
                }
                out.nonFinite[i] = 1;
                ++part.nonFinite;
            }
        }
        return part;
    });
    out.nonFiniteCount = s.nonFinite;
}

/// The calling thread's planes, kept between calls (no page faults on a fresh 22 MB at 720p). Taken
/// as a reference so that the tile workers, which capture it, see the caller's planes.
LdrPlanes& callerPlanes() {
    thread_local LdrPlanes planes;
    return planes;
}

/// Mirror without repeating the edge (OpenCV's BORDER_REFLECT_101).
inline int reflect101(int i, int n) {
    if (n == 1) return 0;
    while (i < 0 || i >= n) i = i < 0 ? -i : 2 * n - 2 - i;
    return i;
}

inline int clampIndex(int i, int n) {
    return std::clamp(i, 0, n - 1);
}

/// Thread-local scratch that grows as needed (allocation stays out of the per-pixel loops).
std::vector<float>& scratch(int which, size_t size) {
    thread_local std::vector<float> buffers[4];
    std::vector<float>& b = buffers[which];
    if (b.size() < size) b.resize(size);
    return b;
}

/// Accumulators per block of outputs: 4 AVX2 vectors stay in registers across the taps.
constexpr int kConvBlock = 32;

/// out[x] = sum_k w[k] * src[x + k] for x in [0, n), taps in order k = 0..taps-1.
inline void convolveRow(const float* src, const float* w, int taps, int n, float* out) {
    int x = 0;
    for (; x + kConvBlock <= n; x += kConvBlock) {
        float acc[kConvBlock] = {};
        for (int k = 0; k < taps; ++k) {
            const float wk = w[k];
            const float* s = src + x + k;
            for (int j = 0; j < kConvBlock; ++j) acc[j] += wk * s[j];
        }
        for (int j = 0; j < kConvBlock; ++j) out[x + j] = acc[j];
    }
    for (; x < n; ++x) {
        float acc = 0.0f;
        for (int k = 0; k < taps; ++k) acc += w[k] * src[x + k];
        out[x] = acc;
    }
}

/// out[x] = sum_k w[k] * rows[k * stride + x] for x in [0, n), taps in order.
inline void convolveColumn(const float* rows, size_t stride, const float* w, int taps, int n, float* out) {
    int x = 0;
    for (; x + kConvBlock <= n; x += kConvBlock) {
        float acc[kConvBlock] = {};
        for (int k = 0; k < taps; ++k) {
            const float wk = w[k];
            const float* s = rows + size_t(k) * stride + x;
            for (int j = 0; j < kConvBlock; ++j) acc[j] += wk * s[j];
        }
        for (int j = 0; j < kConvBlock; ++j) out[x + j] = acc[j];
    }
    for (; x < n; ++x) {
        float acc = 0.0f;
        for (int k = 0; k < taps; ++k) acc += w[k] * rows[size_t(k) * stride + size_t(x)];
        out[x] = acc;
    }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// HDR metrics

MetricValue relMSE(MetricImage test, MetricImage ref, ImageView<float>* errorImage) {
    checkSameSize(test, ref, "relMSE");
    checkMap(errorImage, test, "relMSE");
    const MetricSums s = relMseSums(DeviceKind::Cpu, test, ref, errorImage ? *errorImage : ImageView<float>{});
    return {cappedMetricMean(s), s.nonFinite};
}

MetricValue trimmedRelMSE(MetricImage test, MetricImage ref, double dropFraction) {
    checkSameSize(test, ref, "trimmedRelMSE");
    if (!(dropFraction >= 0.0 && dropFraction < 1.0))
        throwBadInput("trimmedRelMSE", "drop fraction out of range", "a value in [0, 1)");
    // Per-pixel terms (sum over R, G, B) at fixed positions; non-finite pixels are marked by -1 (terms are >= 0).
    const size_t n = size_t(test.width) * test.height;
    std::vector<double> terms(n, -1.0);
    const Sums all = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4* tr = test.row(y);
            const glm::vec4* rr = ref.row(y);
            double* out = terms.data() + size_t(y) * test.width;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                if (!finite3(tr[x]) || !finite3(rr[x])) {
                    ++part.nonFinite;
                    continue;
                }
                out[x] = std::min(relMsePixelSum(tr[x], rr[x]), std::numeric_limits<double>::max());
                ++part.count;
            }
        }
        return part;
    });
    const uint64_t finite = all.count;
    const uint64_t drop = uint64_t(std::floor(double(finite) * dropFraction));
    const uint64_t keep = finite - drop;
    if (keep == 0) return {0.0, all.nonFinite};
    // The threshold: the keep-th smallest finite term. Every term below it is kept; of those equal to it, as many
    // as make `keep` (ties are equal, so which ones does not matter and the sum is independent of order).
    std::vector<double> sorted;
    sorted.reserve(finite);
    for (double t : terms)
        if (t >= 0.0) sorted.push_back(t);
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(keep - 1), sorted.end());
    const double threshold = sorted[keep - 1];
    const Sums below = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const double* row = terms.data() + size_t(y) * test.width;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                if (row[x] >= 0.0 && row[x] < threshold) {
                    part.sum += row[x];
                    ++part.count;
                }
            }
        }
        return part;
    });
    const double sum = below.sum + double(keep - below.count) * threshold;
    const double v = std::min(sum / (double(keep) * 3.0), std::numeric_limits<double>::max());
    return {v, all.nonFinite};
}

MetricValue smape(MetricImage test, MetricImage ref, ImageView<float>* errorImage) {
    checkSameSize(test, ref, "smape");
    checkMap(errorImage, test, "smape");
    const MetricSums s = smapeSums(DeviceKind::Cpu, test, ref, errorImage ? *errorImage : ImageView<float>{});
    return {metricMean(s), s.nonFinite};
}

// ---------------------------------------------------------------------------------------------
// LDR metrics

const float* ldrToneMapTable() {
    return kOetf.v.data();
}

float ldrToneMap(float linear) {
    return std::isfinite(linear) ? toneMapFinite(linear) : 0.0f;
}

MetricValue psnr(MetricImage test, MetricImage ref, ImageView<float>* errorImage) {
    checkSameSize(test, ref, "psnr");
    checkMap(errorImage, test, "psnr");
    const MetricSums s =
        psnrSums(DeviceKind::Cpu, kOetf.v.data(), test, ref, errorImage ? *errorImage : ImageView<float>{});
    return {psnrOfSums(s), s.nonFinite};
}

namespace {

constexpr int kSsimRadius = 5;  // 11x11 window
constexpr double kSsimSigma = 1.5;
constexpr float kSsimC1 = 0.01f * 0.01f;  // (K1 L)^2, L = 1
constexpr float kSsimC2 = 0.03f * 0.03f;  // (K2 L)^2
constexpr uint32_t kFilterTile = 64;

std::array<float, 2 * kSsimRadius + 1> ssimWeights() {
    std::array<double, 2 * kSsimRadius + 1> w{};
    double sum = 0.0;
    for (int i = -kSsimRadius; i <= kSsimRadius; ++i)
        sum += w[size_t(i + kSsimRadius)] = std::exp(-i * i / (2.0 * kSsimSigma * kSsimSigma));
    std::array<float, 2 * kSsimRadius + 1> out{};
    for (size_t i = 0; i < w.size(); ++i) out[i] = float(w[i] / sum);
    return out;
}

/// The SSIM formula over a row of window statistics (5 rows of n: mean x, mean y, E[x^2], E[y^2],
/// E[xy], of the values minus shiftX and shiftY); writes the values and adds a third of each to the map row.
inline void ssimRow(const float* __restrict stats, int n, float shiftX, float shiftY, float* __restrict value,
                    float* __restrict map) {
    const float* __restrict mx = stats;
    const float* __restrict my = mx + n;
    const float* __restrict xx = my + n;
    const float* __restrict yy = xx + n;
    const float* __restrict xy = yy + n;
    for (int x = 0; x < n; ++x) {
        const float sx = xx[x] - mx[x] * mx[x], sy = yy[x] - my[x] * my[x];
        const float sxy = xy[x] - mx[x] * my[x];
        const float ux = mx[x] + shiftX, uy = my[x] + shiftY;  // the means of the values
        const float num = (2.0f * ux * uy + kSsimC1) * (2.0f * sxy + kSsimC2);
        const float den = (ux * ux + uy * uy + kSsimC1) * (sx + sy + kSsimC2);
        value[x] = num / den;
        map[x] += value[x] * (1.0f / 3.0f);
    }
}

}  // namespace

MetricValue ssim(MetricImage test, MetricImage ref, ImageView<float>* ssimImage) {
    checkSameSize(test, ref, "ssim");
    checkMap(ssimImage, test, "ssim");
    const int W = int(test.width), H = int(test.height);
    if (W == 0 || H == 0) return {};
    LdrPlanes& planes = callerPlanes();
    makeLdrPlanes(test, ref, false, planes);
    static const std::array<float, 2 * kSsimRadius + 1> w = ssimWeights();
    constexpr int R = kSsimRadius, K = 2 * kSsimRadius + 1;

    const Sums s = reduceTiles(test.width, test.height, kFilterTile, [&](const Tile& tile) {
        const int tw = int(tile.x1 - tile.x0), th = int(tile.y1 - tile.y0);
        const int rows = th + 2 * R, padW = tw + 2 * R;
        // Horizontal pass output: 5 quantities (x, y, x^2, y^2, xy) per row of the tile plus halo.
        std::vector<float>& hbuf = scratch(0, size_t(5) * rows * tw);
        std::vector<float>& pad = scratch(1, size_t(5) * padW);
        std::vector<float>& mapRow = scratch(2, size_t(th) * tw);
        std::fill(mapRow.begin(), mapRow.begin() + size_t(th) * tw, 0.0f);
        std::vector<float>& v = scratch(3, size_t(5) * tw + size_t(padW) + size_t(tw));
        float* valueRow = v.data() + size_t(5) * tw;
        int* xIndex = reinterpret_cast<int*>(valueRow + tw);
        static_assert(sizeof(int) == sizeof(float));
        for (int i = 0; i < padW; ++i) xIndex[i] = reflect101(int(tile.x0) + i - R, W);
        const bool interior = int(tile.x0) >= R && int(tile.x1) + R <= W;
        double sum = 0.0;
        for (int c = 0; c < 3; ++c) {
            const float* pt = planes.plane[c].data();
            const float* pr = planes.plane[3 + c].data();
            // Statistics of the values minus a value of the tile (its centre pixel's): variances are
            // shift-invariant, and values near the local mean lose less to float rounding in E[x^2] - E[x]^2; a
            // constant image's variances are exactly 0. The tiles do not depend on the thread count.
            const size_t centre = size_t((tile.y0 + tile.y1) / 2) * W + (tile.x0 + tile.x1) / 2;
            const float shiftT = pt[centre], shiftR = pr[centre];
            for (int r = 0; r < rows; ++r) {
                const int sy = reflect101(int(tile.y0) + r - R, H);
                const float* rowT = pt + size_t(sy) * W;
                const float* rowR = pr + size_t(sy) * W;
                float* __restrict p0 = pad.data();
                float* __restrict p1 = p0 + padW;
                float* __restrict p2 = p1 + padW;
                float* __restrict p3 = p2 + padW;
                float* __restrict p4 = p3 + padW;
                if (interior) {
                    const int x0 = int(tile.x0) - R;
                    for (int i = 0; i < padW; ++i) {
                        p0[i] = rowT[x0 + i] - shiftT;
                        p1[i] = rowR[x0 + i] - shiftR;
                    }
                } else {
                    for (int i = 0; i < padW; ++i) {
                        p0[i] = rowT[xIndex[i]] - shiftT;
                        p1[i] = rowR[xIndex[i]] - shiftR;
                    }
                }
                for (int i = 0; i < padW; ++i) {
                    p2[i] = p0[i] * p0[i];
                    p3[i] = p1[i] * p1[i];
                    p4[i] = p0[i] * p1[i];
                }
                for (int q = 0; q < 5; ++q)
                    convolveRow(pad.data() + size_t(q) * padW, w.data(), K, tw,
                                hbuf.data() + (size_t(q) * rows + r) * tw);
            }
            for (int y = 0; y < th; ++y) {
                for (int q = 0; q < 5; ++q)
                    convolveColumn(hbuf.data() + (size_t(q) * rows + y) * tw, size_t(tw), w.data(), K, tw,
                                   v.data() + size_t(q) * tw);
                ssimRow(v.data(), tw, shiftT, shiftR, valueRow, mapRow.data() + size_t(y) * tw);
                float rowSum = 0.0f;
                for (int x = 0; x < tw; ++x) rowSum += valueRow[x];
                sum += rowSum;
            }
        }
        if (ssimImage)
            for (int y = 0; y < th; ++y)
                std::copy_n(mapRow.data() + size_t(y) * tw, tw, ssimImage->row(tile.y0 + uint32_t(y)) + tile.x0);
        Sums part;
        part.sum = sum;
        part.count = uint64_t(tw) * uint64_t(th);
        return part;
    });
    return {meanOf(s, 3.0), planes.nonFiniteCount};
}

// ---------------------------------------------------------------------------------------------
// FLIP

double FlipViewing::pixelsPerDegree() const {
    return distanceMeters * (monitorWidthPixels / monitorWidthMeters) * (3.14159265358979323846 / 180.0);
}

namespace {

// Linear sRGB (D65) to CIE XYZ, IEC 61966-2-1.
constexpr double kRgbToXyz[3][3] = {
    {0.4124564, 0.3575761, 0.1804375}, {0.2126729, 0.7151522, 0.0721750}, {0.0193339, 0.1191920, 0.9503041}};

struct Mat3 {
    double m[3][3];
};

Mat3 inverse(const double a[3][3]) {
    Mat3 r{};
    const double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                       a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                       a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            const int i1 = (j + 1) % 3, i2 = (j + 2) % 3, j1 = (i + 1) % 3, j2 = (i + 2) % 3;
            r.m[i][j] = (a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]) / det;
        }
    return r;
}

/// Everything FLIP derives from the viewing conditions and the colour constants.
struct FlipSetup {
    // Colour: white point, matrices.
    float white[3];        // D65 white = M * (1, 1, 1)
    float rgbToYcc[3][3];  // linear RGB -> (Y/Yw, X/Xw - Y/Yw, Y/Yw - Z/Zw) before scaling
    float xyzToRgb[3][3];
    float rgbToXyz[3][3];
    float cmax;  // (HyAB(green, blue))^qc
    // CSF (Yy, Cx, Cz first and second Gaussian) and feature filters (g, g', g'').
    int csfRadius = 0, featureRadius = 0;
    std::vector<float> csf[4];     // normalised 1D Gaussians, length 2 * csfRadius + 1
    float czWeight[2];             // weights of the two Cz Gaussians
    std::vector<float> g, g1, g2;  // feature Gaussian, first and second derivative
};

constexpr float kQc = 0.7f, kPc = 0.4f, kPt = 0.95f, kQf = 0.5f;
constexpr double kFeatureWidthDegrees = 0.082;

inline float labF(float t) {
    constexpr float d = 6.0f / 29.0f;
    return t > d * d * d ? std::cbrt(t) : t / (3.0f * d * d) + 4.0f / 29.0f;
}

/// Linear RGB in [0, 1] to Hunt-adjusted L*a*b*: (L, 0.01 L a, 0.01 L b).
inline void huntLab(const FlipSetup& f, float r, float g, float b, float out[3]) {
    float xyz[3];
    for (int i = 0; i < 3; ++i)
        xyz[i] = (f.rgbToXyz[i][0] * r + f.rgbToXyz[i][1] * g + f.rgbToXyz[i][2] * b) / f.white[i];
    const float fx = labF(xyz[0]), fy = labF(xyz[1]), fz = labF(xyz[2]);
    const float L = 116.0f * fy - 16.0f;
    out[0] = L;
    out[1] = 0.01f * L * 500.0f * (fx - fy);
    out[2] = 0.01f * L * 200.0f * (fy - fz);
}

inline float hyab(const float a[3], const float b[3]) {
    const float da = a[1] - b[1], db = a[2] - b[2];
    return std::abs(a[0] - b[0]) + std::sqrt(da * da + db * db);
}

FlipSetup makeFlipSetup(double ppd) {
    FlipSetup f{};
    for (int i = 0; i < 3; ++i) {
        f.white[i] = float(kRgbToXyz[i][0] + kRgbToXyz[i][1] + kRgbToXyz[i][2]);
        for (int j = 0; j < 3; ++j) f.rgbToXyz[i][j] = float(kRgbToXyz[i][j]);
    }
    const Mat3 inv = inverse(kRgbToXyz);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) f.xyzToRgb[i][j] = float(inv.m[i][j]);
    for (int j = 0; j < 3; ++j) {
        const double xn = kRgbToXyz[0][j] / f.white[0], yn = kRgbToXyz[1][j] / f.white[1],
                     zn = kRgbToXyz[2][j] / f.white[2];
        f.rgbToYcc[0][j] = float(116.0 * yn);  // Yy = 116 Y/Yw - 16 (offset added separately)
        f.rgbToYcc[1][j] = float(500.0 * (xn - yn));
        f.rgbToYcc[2][j] = float(200.0 * (yn - zn));
    }
    float green[3], blue[3];
    huntLab(f, 0, 1, 0, green);
    huntLab(f, 0, 0, 1, blue);
    f.cmax = std::pow(hyab(green, blue), kQc);

    // CSF (paper, sec. 3.1): S(x) = sum_i a_i sqrt(pi / b_i) exp(-pi^2 x^2 / b_i), x in degrees,
    // evaluated at the 2D distance; radius from the widest Gaussian (b = 0.04).
    constexpr double pi = 3.14159265358979323846;
    const double a[4] = {1.0, 1.0, 34.1, 13.5};
    const double b[4] = {0.0047, 0.0053, 0.04, 0.025};
    f.csfRadius = int(std::ceil(3.0 * std::sqrt(0.04 / (2.0 * pi * pi)) * ppd));
    double mass[4];
    for (int q = 0; q < 4; ++q) {
        std::vector<double> e(size_t(2 * f.csfRadius + 1));
        double sum = 0.0;
        for (int i = -f.csfRadius; i <= f.csfRadius; ++i) {
            const double x = i / ppd;
            sum += e[size_t(i + f.csfRadius)] = std::exp(-pi * pi * x * x / b[q]);
        }
        f.csf[q].resize(e.size());
        for (size_t i = 0; i < e.size(); ++i) f.csf[q][i] = float(e[i] / sum);
        mass[q] = a[q] * std::sqrt(pi / b[q]) * sum * sum;  // 2D sum of the unnormalised term
    }
    f.czWeight[0] = float(mass[2] / (mass[2] + mass[3]));
    f.czWeight[1] = float(mass[3] / (mass[2] + mass[3]));

    // Feature filters (paper, sec. 3.2): Gaussian of sigma 0.5 w ppd, w = 0.082 degrees; the first
    // and second derivatives normalised so positive weights sum to 1 and negative to -1.
    const double sigma = 0.5 * kFeatureWidthDegrees * ppd;
    f.featureRadius = int(std::ceil(3.0 * sigma));
    const size_t n = size_t(2 * f.featureRadius + 1);
    std::vector<double> g(n), g1(n), g2(n);
    double sg = 0, p1 = 0, p2 = 0, n2 = 0;
    for (int i = -f.featureRadius; i <= f.featureRadius; ++i) {
        const double x = i, gv = std::exp(-x * x / (2 * sigma * sigma));
        const size_t k = size_t(i + f.featureRadius);
        g[k] = gv;
        g1[k] = -x * gv;
        g2[k] = (x * x / (sigma * sigma) - 1.0) * gv;
        sg += gv;
        if (g1[k] > 0) p1 += g1[k];
        if (g2[k] > 0)
            p2 += g2[k];
        else
            n2 -= g2[k];
    }
    f.g.resize(n);
    f.g1.resize(n);
    f.g2.resize(n);
    for (size_t k = 0; k < n; ++k) {
        f.g[k] = float(g[k] / sg);
        f.g1[k] = float(g1[k] / p1);
        f.g2[k] = float(g2[k] > 0 ? g2[k] / p2 : g2[k] / n2);
    }
    return f;
}

/// One source row of an image (linear R, G, B planes) to YyCxCz over n padded positions: source
/// x = x0 + i, or index[i] when given (the clamped border). The three outputs are followed in memory
/// by room for three more rows (the gathered R, G, B).
[[gnu::noinline]] void yccRow(const FlipSetup& f, const float* r, const float* g, const float* b, const int* index,
                              int x0, int n, float* __restrict yy, float* __restrict cx, float* __restrict cz) {
    float* __restrict rr = cz + n;
    float* __restrict gg = rr + n;
    float* __restrict bb = gg + n;
    if (index) {
        for (int i = 0; i < n; ++i) {
            rr[i] = r[index[i]];
            gg[i] = g[index[i]];
            bb[i] = b[index[i]];
        }
    } else {
        std::copy_n(r + x0, n, rr);
        std::copy_n(g + x0, n, gg);
        std::copy_n(b + x0, n, bb);
    }
    const float m00 = f.rgbToYcc[0][0], m01 = f.rgbToYcc[0][1], m02 = f.rgbToYcc[0][2];
    const float m10 = f.rgbToYcc[1][0], m11 = f.rgbToYcc[1][1], m12 = f.rgbToYcc[1][2];
    const float m20 = f.rgbToYcc[2][0], m21 = f.rgbToYcc[2][1], m22 = f.rgbToYcc[2][2];
    for (int i = 0; i < n; ++i) {
        yy[i] = m00 * rr[i] + m01 * gg[i] + m02 * bb[i] - 16.0f;
        cx[i] = m10 * rr[i] + m11 * gg[i] + m12 * bb[i];
        cz[i] = m20 * rr[i] + m21 * gg[i] + m22 * bb[i];
    }
}

/// Filtered YyCxCz rows of one image back to linear RGB (clamped to [0, 1]) and then to XYZ over the
/// white (3 rows). Not inlined: both images must take exactly the same instructions (with FMA
/// contraction, two inlined copies can round differently, and identical images must give 0).
[[gnu::noinline]] void filteredToXyzRow(const FlipSetup& f, const float* yy, const float* cx, const float* cz, int n,
                                        float* out) {
    for (int x = 0; x < n; ++x) {
        const float yn = (yy[x] + 16.0f) * (1.0f / 116.0f);
        const float X = (cx[x] * (1.0f / 500.0f) + yn) * f.white[0];
        const float Y = yn * f.white[1];
        const float Z = (yn - cz[x] * (1.0f / 200.0f)) * f.white[2];
        float rgb[3];
        for (int i = 0; i < 3; ++i)
            rgb[i] = std::min(std::max(0.0f, f.xyzToRgb[i][0] * X + f.xyzToRgb[i][1] * Y + f.xyzToRgb[i][2] * Z), 1.0f);
        for (int i = 0; i < 3; ++i)
            out[size_t(i) * size_t(n) + size_t(x)] =
                (f.rgbToXyz[i][0] * rgb[0] + f.rgbToXyz[i][1] * rgb[1] + f.rgbToXyz[i][2] * rgb[2]) / f.white[i];
    }
}

/// Hunt-adjusted L*a*b* rows of one image from its XYZ-over-white rows and their cube roots.
[[gnu::noinline]] void huntLabRow(const float* xyzn, const float* cube, int n, float* lab) {
    constexpr float d3 = (6.0f / 29.0f) * (6.0f / 29.0f) * (6.0f / 29.0f);
    constexpr float slope = 1.0f / (3.0f * (6.0f / 29.0f) * (6.0f / 29.0f));
    for (int x = 0; x < n; ++x) {
        float fv[3];
        for (int i = 0; i < 3; ++i) {
            const float t = xyzn[size_t(i) * size_t(n) + size_t(x)];
            fv[i] = t > d3 ? cube[size_t(i) * size_t(n) + size_t(x)] : t * slope + 4.0f / 29.0f;
        }
        const float L = 116.0f * fv[1] - 16.0f;
        lab[x] = L;
        lab[size_t(n) + size_t(x)] = 0.01f * L * 500.0f * (fv[0] - fv[1]);
        lab[size_t(2 * n) + size_t(x)] = 0.01f * L * 200.0f * (fv[1] - fv[2]);
    }
}

/// Edge and point magnitudes of one image from its four filtered feature rows.
[[gnu::noinline]] void featureRow(const float* ex, const float* ey, const float* px, const float* py, int n,
                                  float* edge, float* point) {
    for (int x = 0; x < n; ++x) {
        edge[x] = std::sqrt(ex[x] * ex[x] + ey[x] * ey[x]);
        point[x] = std::sqrt(px[x] * px[x] + py[x] * py[x]);
    }
}

/// Values per pixel and image after FLIP's vertical filtering: filtered Yy, Cx, Cz, edge x, edge y, point x, point y.
constexpr int kFlipPlanes = 7;

/// FLIP's per-pixel combination over one tile, from the vertically filtered planes (kFlipPlanes per image, tw x th
/// each): the colour difference (HyAB of the Hunt-adjusted L*a*b*), the feature difference, and the error per
/// pixel, written to errorImage when given. Returns the tile's sum.
Sums flipCombineTile(const FlipSetup& f, const LdrPlanes& planes, const Tile& tile, uint32_t W, const float* vbuf,
                     int tw, int th, ImageView<float>* errorImage) {
    constexpr int kV = kFlipPlanes;
    // Per-pixel combination, in stages over a row so each loop vectorises (the powers go through
    // Highway's Exp and Log).
    Sums part;
    constexpr float invSqrt2 = 0.70710678118654752f;
    std::vector<float>& rowBuf = scratch(3, size_t(22) * tw);
    float* xyzn = rowBuf.data();          // 6 rows: X/Xw, Y/Yw, Z/Zw of both images
    float* cube = xyzn + size_t(6) * tw;  // 6 rows: their cube roots
    float* lab = cube + size_t(6) * tw;   // 6 rows: L, a', b' of both images
    float* feat = lab + size_t(6) * tw;   // 4 rows: edge, point of both images
    std::vector<float>& rowBuf2 = scratch(1, size_t(6) * tw);
    float* hy = rowBuf2.data();
    float* expo = hy + tw;
    float* colour = expo + tw;
    float* err = colour + tw;
    float* thirds = err + tw;
    float* qcs = thirds + tw;
    for (int x = 0; x < tw; ++x) {
        thirds[x] = 1.0f / 3.0f;
        qcs[x] = kQc;
    }
    const float pcm = kPc * f.cmax;
    for (int y = 0; y < th; ++y) {
        const float* vb[2][kV];
        for (int img = 0; img < 2; ++img)
            for (int q = 0; q < kV; ++q) vb[img][q] = vbuf + ((size_t(img) * kV + q) * th + y) * tw;
        for (int img = 0; img < 2; ++img) {
            filteredToXyzRow(f, vb[img][0], vb[img][1], vb[img][2], tw, xyzn + size_t(3 * img) * tw);
            for (int k = 0; k < 3; ++k)
                powRow(xyzn + size_t(3 * img + k) * tw, thirds, cube + size_t(3 * img + k) * tw, tw);
            huntLabRow(xyzn + size_t(3 * img) * tw, cube + size_t(3 * img) * tw, tw, lab + size_t(3 * img) * tw);
            featureRow(vb[img][3], vb[img][4], vb[img][5], vb[img][6], tw, feat + size_t(2 * img) * tw,
                       feat + size_t(2 * img + 1) * tw);
        }
        const float* l0 = lab;
        const float* l1 = lab + size_t(3) * tw;
        for (int x = 0; x < tw; ++x) {
            const float dl = l0[x] - l1[x], da = l0[tw + x] - l1[tw + x], db = l0[2 * tw + x] - l1[2 * tw + x];
            hy[x] = std::abs(dl) + std::sqrt(da * da + db * db);  // HyAB
            // Features of Y/Yw = (Yy + 16) / 116 (the derivative kernels sum to 0, so only the scale).
            const float de = std::abs(feat[x] - feat[size_t(2) * tw + x]);
            const float dp = std::abs(feat[tw + x] - feat[size_t(3) * tw + x]);
            const float fd = std::min(1.0f, invSqrt2 * (1.0f / 116.0f) * std::max(de, dp));
            expo[x] = 1.0f - std::sqrt(fd);  // 1 - dE_f, qf = 0.5
        }
        powRow(hy, qcs, err, tw);  // dE_c = HyAB^qc
        for (int x = 0; x < tw; ++x) {
            const float dc = err[x];
            colour[x] = std::min(1.0f, dc < pcm ? (kPt / pcm) * dc : kPt + (dc - pcm) / (f.cmax - pcm) * (1.0f - kPt));
        }
        powRow(colour, expo, err, tw);
        const size_t rowBase = size_t(tile.y0 + uint32_t(y)) * W + tile.x0;
        const uint8_t* bad = planes.nonFinite.data() + rowBase;
        for (int x = 0; x < tw; ++x) err[x] = bad[x] ? 1.0f : err[x];
        double rowSum = 0.0;
        for (int x = 0; x < tw; ++x) rowSum += err[x];
        part.sum += rowSum;
        if (errorImage) std::copy_n(err, tw, errorImage->row(tile.y0 + uint32_t(y)) + tile.x0);
    }
    part.count = uint64_t(tw) * uint64_t(th);
    return part;
}

}  // namespace

MetricValue flip(MetricImage test, MetricImage ref, ImageView<float>* errorImage, const FlipViewing& viewing) {
    checkSameSize(test, ref, "flip");
    checkMap(errorImage, test, "flip");
    const double ppd = viewing.pixelsPerDegree();
    if (!(ppd > 0.0) || !std::isfinite(ppd))
        throwBadInput("flip", "viewing conditions give " + std::to_string(ppd) + " pixels per degree",
                      "positive distance, monitor width and resolution");
    const int W = int(test.width), H = int(test.height);
    if (W == 0 || H == 0) return {};
    LdrPlanes& planes = callerPlanes();
    makeLdrPlanes(test, ref, true, planes);
    const FlipSetup f = makeFlipSetup(ppd);
    const int cr = f.csfRadius, fr = f.featureRadius, halo = std::max(cr, fr);
    const int csfTaps = 2 * cr + 1, featTaps = 2 * fr + 1;

    // Per image the horizontal pass makes 7 rows per source row: CSF Yy, Cx, Cz (two Gaussians), and
    // the feature g, g', g'' of Yy. The vertical pass makes 7 values per pixel: filtered Yy, Cx, Cz,
    // edge x, edge y, point x, point y.
    constexpr int kH = 7, kV = kFlipPlanes;
    const Sums s = reduceTiles(test.width, test.height, kFilterTile, [&](const Tile& tile) {
        const int tw = int(tile.x1 - tile.x0), th = int(tile.y1 - tile.y0);
        const int rows = th + 2 * halo, padW = tw + 2 * halo;
        std::vector<float>& hbuf = scratch(0, size_t(kH) * rows * tw);
        std::vector<float>& pad = scratch(1, size_t(6) * padW);
        std::vector<float>& vbuf = scratch(2, size_t(2) * kV * th * tw);
        thread_local std::vector<int> xIndexStore;
        if (xIndexStore.size() < size_t(padW)) xIndexStore.resize(size_t(padW));
        int* xIndex = xIndexStore.data();
        for (int i = 0; i < padW; ++i) xIndex[i] = clampIndex(int(tile.x0) + i - halo, W);
        const bool interior = int(tile.x0) >= halo && int(tile.x1) + halo <= W;
        for (int img = 0; img < 2; ++img) {
            const float* pr = planes.plane[3 * img].data();
            const float* pg = planes.plane[3 * img + 1].data();
            const float* pb = planes.plane[3 * img + 2].data();
            for (int r = 0; r < rows; ++r) {
                const int sy = clampIndex(int(tile.y0) + r - halo, H);
                const size_t base = size_t(sy) * W;
                float* yy = pad.data();
                float* cx = yy + padW;
                float* cz = cx + padW;
                yccRow(f, pr + base, pg + base, pb + base, interior ? nullptr : xIndex, int(tile.x0) - halo, padW, yy,
                       cx, cz);
                auto hrow = [&](int q) { return hbuf.data() + (size_t(q) * rows + r) * tw; };
                const int co = halo - cr, fo = halo - fr;
                convolveRow(yy + co, f.csf[0].data(), csfTaps, tw, hrow(0));
                convolveRow(cx + co, f.csf[1].data(), csfTaps, tw, hrow(1));
                convolveRow(cz + co, f.csf[2].data(), csfTaps, tw, hrow(2));
                convolveRow(cz + co, f.csf[3].data(), csfTaps, tw, hrow(3));
                convolveRow(yy + fo, f.g.data(), featTaps, tw, hrow(4));
                convolveRow(yy + fo, f.g1.data(), featTaps, tw, hrow(5));
                convolveRow(yy + fo, f.g2.data(), featTaps, tw, hrow(6));
            }
            std::vector<float>& tmp = scratch(3, size_t(tw));
            for (int y = 0; y < th; ++y) {
                auto hcol = [&](int q, int offset) { return hbuf.data() + (size_t(q) * rows + y + offset) * tw; };
                auto vrow = [&](int q) { return vbuf.data() + ((size_t(img) * kV + q) * th + y) * tw; };
                const int co = halo - cr, fo = halo - fr;
                convolveColumn(hcol(0, co), tw, f.csf[0].data(), csfTaps, tw, vrow(0));
                convolveColumn(hcol(1, co), tw, f.csf[1].data(), csfTaps, tw, vrow(1));
                convolveColumn(hcol(2, co), tw, f.csf[2].data(), csfTaps, tw, vrow(2));
                convolveColumn(hcol(3, co), tw, f.csf[3].data(), csfTaps, tw, tmp.data());
                float* czOut = vrow(2);
                for (int x = 0; x < tw; ++x) czOut[x] = f.czWeight[0] * czOut[x] + f.czWeight[1] * tmp[x];
                convolveColumn(hcol(5, fo), tw, f.g.data(), featTaps, tw, vrow(3));   // edge x: g'(x) g(y)
                convolveColumn(hcol(4, fo), tw, f.g1.data(), featTaps, tw, vrow(4));  // edge y: g(x) g'(y)
                convolveColumn(hcol(6, fo), tw, f.g.data(), featTaps, tw, vrow(5));   // point x: g''(x) g(y)
                convolveColumn(hcol(4, fo), tw, f.g2.data(), featTaps, tw, vrow(6));  // point y: g(x) g''(y)
            }
        }
        return flipCombineTile(f, planes, tile, uint32_t(W), vbuf.data(), tw, th, errorImage);
    });
    return {meanOf(s, 1.0), planes.nonFiniteCount};
}

// ---------------------------------------------------------------------------------------------
// Temporal metrics

MetricValue temporalError(MetricImage test, MetricImage testPrev, MetricImage ref, MetricImage refPrev) {
    checkSameSize(test, testPrev, "temporalError");
    checkSameSize(test, ref, "temporalError");
    checkSameSize(test, refPrev, "temporalError");
    const MetricSums s = temporalSums(DeviceKind::Cpu, test, testPrev, ref, refPrev);
    return {cappedMetricMean(s), s.nonFinite};
}

void FlickerAccumulator::add(MetricImage frame) {
    if (mFrames == 0) {
        mWidth = frame.width;
        mHeight = frame.height;
        const size_t n = size_t(mWidth) * mHeight;
        mMean.assign(n, 0.0);
        mM2.assign(n, 0.0);
        mCount.assign(n, 0);
        mHadNonFinite.assign(n, 0);
    } else if (frame.width != mWidth || frame.height != mHeight) {
        throwBadInput("FlickerAccumulator",
                      "frame of size " + std::to_string(frame.width) + "x" + std::to_string(frame.height),
                      "the size of the first frame, " + std::to_string(mWidth) + "x" + std::to_string(mHeight));
    }
    parallelFor2D(mWidth, mHeight, [&](const Tile& tile) {
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4* row = frame.row(y);
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                const size_t i = size_t(y) * mWidth + x;
                const double l = kRec709R * row[x].x + kRec709G * row[x].y + kRec709B * row[x].z;
                if (!std::isfinite(l)) {
                    mHadNonFinite[i] = 1;
                    continue;
                }
                // Welford's update.
                const uint32_t n = ++mCount[i];
                const double delta = l - mMean[i];
                mMean[i] += delta / n;
                mM2[i] += delta * (l - mMean[i]);
            }
        }
    });
    ++mFrames;
}

MetricValue FlickerAccumulator::value() const {
    if (mFrames == 0) return {};
    const Sums s = reduceTiles(mWidth, mHeight, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y)
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                const size_t i = size_t(y) * mWidth + x;
                part.nonFinite += mHadNonFinite[i];
                if (mCount[i] < 2) continue;
                part.sum += std::sqrt(std::max(0.0, mM2[i] / mCount[i]));
                ++part.count;
            }
        return part;
    });
    return {std::min(meanOf(s, 1.0), std::numeric_limits<double>::max()), s.nonFinite};
}

void FlickerAccumulator::reset() {
    *this = FlickerAccumulator();
}

// ---------------------------------------------------------------------------------------------
// Texture overloads

namespace {
template <class Fn>
MetricValue withTextures(const Texture& test, const Texture& ref, Texture* map, const char* what, Fn&& fn) {
    const MetricImage a = viewOf(test, what), b = viewOf(ref, what);
    if (!map) return fn(a, b, nullptr);
    ImageView<float> m = mapOf(*map, what);
    return fn(a, b, &m);
}
}  // namespace

MetricValue relMSE(const Texture& test, const Texture& ref, Texture* errorImage) {
    return withTextures(test, ref, errorImage, "relMSE",
                        [](MetricImage a, MetricImage b, ImageView<float>* m) { return relMSE(a, b, m); });
}
MetricValue trimmedRelMSE(const Texture& test, const Texture& ref, double dropFraction) {
    return trimmedRelMSE(viewOf(test, "trimmedRelMSE"), viewOf(ref, "trimmedRelMSE"), dropFraction);
}
MetricValue smape(const Texture& test, const Texture& ref, Texture* errorImage) {
    return withTextures(test, ref, errorImage, "smape",
                        [](MetricImage a, MetricImage b, ImageView<float>* m) { return smape(a, b, m); });
}
MetricValue psnr(const Texture& test, const Texture& ref, Texture* errorImage) {
    return withTextures(test, ref, errorImage, "psnr",
                        [](MetricImage a, MetricImage b, ImageView<float>* m) { return psnr(a, b, m); });
}
MetricValue ssim(const Texture& test, const Texture& ref, Texture* ssimImage) {
    return withTextures(test, ref, ssimImage, "ssim",
                        [](MetricImage a, MetricImage b, ImageView<float>* m) { return ssim(a, b, m); });
}
MetricValue flip(const Texture& test, const Texture& ref, Texture* errorImage, const FlipViewing& viewing) {
    return withTextures(test, ref, errorImage, "flip",
                        [&](MetricImage a, MetricImage b, ImageView<float>* m) { return flip(a, b, m, viewing); });
}
MetricValue temporalError(const Texture& test, const Texture& testPrev, const Texture& ref, const Texture& refPrev) {
    return temporalError(viewOf(test, "temporalError"), viewOf(testPrev, "temporalError"), viewOf(ref, "temporalError"),
                         viewOf(refPrev, "temporalError"));
}
void FlickerAccumulator::add(const Texture& frame) {
    add(viewOf(frame, "FlickerAccumulator"));
}

}  // namespace loom
