// Image error metrics (conventions in Metrics.h and docs/METRICS.md).
//
// Structure: every metric runs over loom::parallelFor2D tiles. Scalar metrics return one partial
// sum per tile (double), combined afterwards in tile order, so the value does not depend on the
// thread count. The filtered metrics (SSIM, FLIP) work on planar float copies of the tone-mapped
// inputs and run each tile's separable filters in tile-local scratch: a horizontal pass over the
// tile's rows plus the vertical halo, then a vertical pass fused with the per-pixel formula.
#include "loom/Metrics.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <string>

#include "loom/Error.h"
#include "loom/Parallel.h"

namespace loom {

namespace {

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
// Tone map: sRGB OETF from a table over the float's exponent and top mantissa bits.

constexpr int kOetfOctaves = 9;  // [2^-9, 1): below 2^-9 < 0.0031308 the OETF is linear
constexpr int kOetfMantissaBits = 8;
constexpr int kOetfPerOctave = 1 << kOetfMantissaBits;

double srgbOetfExact(double x) {
    return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
}

struct OetfTable {
    std::array<float, kOetfOctaves * kOetfPerOctave + 1> v{};
    OetfTable() {
        for (int i = 0; i <= kOetfOctaves * kOetfPerOctave; ++i) {
            const int octave = i / kOetfPerOctave, m = i % kOetfPerOctave;
            const double x = std::ldexp(1.0 + double(m) / kOetfPerOctave, octave - kOetfOctaves);
            v[size_t(i)] = float(srgbOetfExact(x));
        }
    }
};
const OetfTable kOetf;

/// Tone map of a finite value.
inline float toneMapFinite(float x) {
    if (!(x > 0.0f)) return 0.0f;
    if (x >= 1.0f) return 1.0f;
    if (x < 0.001953125f) return 12.92f * x;  // 2^-9
    const uint32_t bits = std::bit_cast<uint32_t>(x);
    const uint32_t index = (bits >> (23 - kOetfMantissaBits)) - ((127u - kOetfOctaves) << kOetfMantissaBits);
    const float frac =
        float(bits & ((1u << (23 - kOetfMantissaBits)) - 1)) * (1.0f / float(1u << (23 - kOetfMantissaBits)));
    const float a = kOetf.v[index], b = kOetf.v[index + 1];
    return a + frac * (b - a);
}

/// Applies the non-finite rule to one channel pair of [0, 1] values (test t, reference r), given
/// whether each was finite. Returns true when either was not.
inline bool worstCase(float& t, float& r, bool tFinite, bool rFinite) {
    if (tFinite && rFinite) return false;
    if (!tFinite && !rFinite) {
        r = 0.0f;
        t = 1.0f;
    } else if (!tFinite) {
        t = r < 0.5f ? 1.0f : 0.0f;
    } else {
        r = t < 0.5f ? 1.0f : 0.0f;
    }
    return true;
}

/// Tone-mapped R, G, B of a pixel pair with the non-finite rule; returns true for a non-finite pixel.
inline bool toneMapPair(const glm::vec4& test, const glm::vec4& ref, float t[3], float r[3]) {
    bool bad = false;
    for (int c = 0; c < 3; ++c) {
        const bool tf = std::isfinite(test[c]), rf = std::isfinite(ref[c]);
        t[c] = tf ? toneMapFinite(test[c]) : 0.0f;
        r[c] = rf ? toneMapFinite(ref[c]) : 0.0f;
        bad |= worstCase(t[c], r[c], tf, rf);
    }
    return bad;
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
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                const size_t i = size_t(y) * test.width + x;
                float t[3], r[3];
                const bool bad = toneMapPair(tr[x], rr[x], t, r);
                if (linear)  // finite channels keep their exact linear value; replaced ones are 0 or 1 in both
                    for (int c = 0; c < 3; ++c) {
                        if (std::isfinite(tr[x][c])) t[c] = std::clamp(tr[x][c], 0.0f, 1.0f);
                        if (std::isfinite(rr[x][c])) r[c] = std::clamp(rr[x][c], 0.0f, 1.0f);
                    }
                for (int c = 0; c < 3; ++c) {
                    out.plane[c][i] = t[c];
                    out.plane[3 + c][i] = r[c];
                }
                if (bad) {
                    out.nonFinite[i] = 1;
                    ++part.nonFinite;
                }
            }
        }
        return part;
    });
    out.nonFiniteCount = s.nonFinite;
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

}  // namespace

// ---------------------------------------------------------------------------------------------
// HDR metrics

MetricValue relMSE(MetricImage test, MetricImage ref, ImageView<float>* errorImage) {
    checkSameSize(test, ref, "relMSE");
    checkMap(errorImage, test, "relMSE");
    const Sums s = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4* tr = test.row(y);
            const glm::vec4* rr = ref.row(y);
            float* mr = errorImage ? errorImage->row(y) : nullptr;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                if (!finite3(tr[x]) || !finite3(rr[x])) {
                    ++part.nonFinite;
                    if (mr) mr[x] = 0.0f;
                    continue;
                }
                double px = 0.0;
                for (int c = 0; c < 3; ++c) {
                    const double d = double(tr[x][c]) - double(rr[x][c]);
                    const double yv = rr[x][c];
                    px += d * d / (yv * yv + kRelMseEpsilon);
                }
                part.sum += px;
                ++part.count;
                if (mr) mr[x] = float(px / 3.0);
            }
        }
        return part;
    });
    // A huge but finite term could still overflow to Inf: cap at the largest double.
    const double v = std::min(meanOf(s, 3.0), std::numeric_limits<double>::max());
    return {v, s.nonFinite};
}

MetricValue smape(MetricImage test, MetricImage ref, ImageView<float>* errorImage) {
    checkSameSize(test, ref, "smape");
    checkMap(errorImage, test, "smape");
    const Sums s = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4* tr = test.row(y);
            const glm::vec4* rr = ref.row(y);
            float* mr = errorImage ? errorImage->row(y) : nullptr;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                double px = 0.0;
                bool bad = false;
                for (int c = 0; c < 3; ++c) {
                    const double a = tr[x][c], b = rr[x][c];
                    if (!std::isfinite(a) || !std::isfinite(b)) {
                        px += 1.0;
                        bad = true;
                        continue;
                    }
                    px += std::abs(a - b) / (std::abs(a) + std::abs(b) + kSmapeEpsilon);
                }
                part.sum += px;
                ++part.count;
                part.nonFinite += bad;
                if (mr) mr[x] = float(px / 3.0);
            }
        }
        return part;
    });
    return {meanOf(s, 3.0), s.nonFinite};
}

// ---------------------------------------------------------------------------------------------
// LDR metrics

float ldrToneMap(float linear) {
    return std::isfinite(linear) ? toneMapFinite(linear) : 0.0f;
}

MetricValue psnr(MetricImage test, MetricImage ref, ImageView<float>* errorImage) {
    checkSameSize(test, ref, "psnr");
    checkMap(errorImage, test, "psnr");
    const Sums s = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4* tr = test.row(y);
            const glm::vec4* rr = ref.row(y);
            float* mr = errorImage ? errorImage->row(y) : nullptr;
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                float t[3], r[3];
                part.nonFinite += toneMapPair(tr[x], rr[x], t, r);
                double px = 0.0;
                for (int c = 0; c < 3; ++c) {
                    const double d = double(t[c]) - double(r[c]);
                    px += d * d;
                }
                part.sum += px;
                ++part.count;
                if (mr) mr[x] = float(px / 3.0);
            }
        }
        return part;
    });
    const double mse = meanOf(s, 3.0);
    const double v = mse > 0.0 ? std::min(10.0 * std::log10(1.0 / mse), kPsnrCap) : kPsnrCap;
    return {v, s.nonFinite};
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

}  // namespace

MetricValue ssim(MetricImage test, MetricImage ref, ImageView<float>* ssimImage) {
    checkSameSize(test, ref, "ssim");
    checkMap(ssimImage, test, "ssim");
    const int W = int(test.width), H = int(test.height);
    if (W == 0 || H == 0) return {};
    LdrPlanes planes;
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
        std::vector<float>& v = scratch(3, size_t(5) * tw);
        double sum = 0.0;
        for (int c = 0; c < 3; ++c) {
            const float* pt = planes.plane[c].data();
            const float* pr = planes.plane[3 + c].data();
            for (int r = 0; r < rows; ++r) {
                const int sy = reflect101(int(tile.y0) + r - R, H);
                const float* rowT = pt + size_t(sy) * W;
                const float* rowR = pr + size_t(sy) * W;
                float* p0 = pad.data();
                float* p1 = p0 + padW;
                float* p2 = p1 + padW;
                float* p3 = p2 + padW;
                float* p4 = p3 + padW;
                for (int i = 0; i < padW; ++i) {
                    const int sx = reflect101(int(tile.x0) + i - R, W);
                    // Statistics of the values minus 0.5: variances are shift-invariant, and the
                    // smaller squares lose less to float rounding in E[x^2] - E[x]^2.
                    const float a = rowT[sx] - 0.5f, b = rowR[sx] - 0.5f;
                    p0[i] = a;
                    p1[i] = b;
                    p2[i] = a * a;
                    p3[i] = b * b;
                    p4[i] = a * b;
                }
                for (int q = 0; q < 5; ++q) {
                    const float* src = pad.data() + size_t(q) * padW;
                    float* dst = hbuf.data() + (size_t(q) * rows + r) * tw;
                    for (int x = 0; x < tw; ++x) {
                        float acc = 0.0f;
                        for (int k = 0; k < K; ++k) acc += w[size_t(k)] * src[x + k];
                        dst[x] = acc;
                    }
                }
            }
            for (int y = 0; y < th; ++y) {
                for (int q = 0; q < 5; ++q) {
                    float* dst = v.data() + size_t(q) * tw;
                    const float* src = hbuf.data() + (size_t(q) * rows + y) * tw;
                    for (int x = 0; x < tw; ++x) dst[x] = 0.0f;
                    for (int k = 0; k < K; ++k) {
                        const float wk = w[size_t(k)];
                        const float* s = src + size_t(k) * tw;
                        for (int x = 0; x < tw; ++x) dst[x] += wk * s[x];
                    }
                }
                const float* mx = v.data();
                const float* my = mx + tw;
                const float* xx = my + tw;
                const float* yy = xx + tw;
                const float* xy = yy + tw;
                float* out = mapRow.data() + size_t(y) * tw;
                float rowSum = 0.0f;
                for (int x = 0; x < tw; ++x) {
                    const float sx = xx[x] - mx[x] * mx[x], sy = yy[x] - my[x] * my[x];
                    const float sxy = xy[x] - mx[x] * my[x];
                    const float ux = mx[x] + 0.5f, uy = my[x] + 0.5f;  // the means of the values
                    const float mxy = ux * uy, mx2 = ux * ux, my2 = uy * uy;
                    const float num = (2.0f * mxy + kSsimC1) * (2.0f * sxy + kSsimC2);
                    const float den = (mx2 + my2 + kSsimC1) * (sx + sy + kSsimC2);
                    const float value = num / den;
                    rowSum += value;
                    out[x] += value * (1.0f / 3.0f);
                }
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

/// out[x] = sum_k w[k] * src[x + k] for x in [0, n).
inline void convolveRow(const float* src, const float* w, int taps, int n, float* out) {
    for (int x = 0; x < n; ++x) out[x] = 0.0f;
    for (int k = 0; k < taps; ++k) {
        const float wk = w[k];
        const float* s = src + k;
        for (int x = 0; x < n; ++x) out[x] += wk * s[x];
    }
}

/// out[x] = sum_k w[k] * rows[k * stride + x] for x in [0, n).
inline void convolveColumn(const float* rows, size_t stride, const float* w, int taps, int n, float* out) {
    for (int x = 0; x < n; ++x) out[x] = 0.0f;
    for (int k = 0; k < taps; ++k) {
        const float wk = w[k];
        const float* s = rows + size_t(k) * stride;
        for (int x = 0; x < n; ++x) out[x] += wk * s[x];
    }
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
    LdrPlanes planes;
    makeLdrPlanes(test, ref, true, planes);
    const FlipSetup f = makeFlipSetup(ppd);
    const int cr = f.csfRadius, fr = f.featureRadius, halo = std::max(cr, fr);
    const int csfTaps = 2 * cr + 1, featTaps = 2 * fr + 1;

    // Per image the horizontal pass makes 7 rows per source row: CSF Yy, Cx, Cz (two Gaussians), and
    // the feature g, g', g'' of Yy. The vertical pass makes 7 values per pixel: filtered Yy, Cx, Cz,
    // edge x, edge y, point x, point y.
    constexpr int kH = 7, kV = 7;
    const Sums s = reduceTiles(test.width, test.height, kFilterTile, [&](const Tile& tile) {
        const int tw = int(tile.x1 - tile.x0), th = int(tile.y1 - tile.y0);
        const int rows = th + 2 * halo, padW = tw + 2 * halo;
        std::vector<float>& hbuf = scratch(0, size_t(kH) * rows * tw);
        std::vector<float>& pad = scratch(1, size_t(3) * padW);
        std::vector<float>& vbuf = scratch(2, size_t(2) * kV * th * tw);
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
                for (int i = 0; i < padW; ++i) {
                    const size_t sx = base + size_t(clampIndex(int(tile.x0) + i - halo, W));
                    const float rr = pr[sx], gg = pg[sx], bb = pb[sx];
                    yy[i] = f.rgbToYcc[0][0] * rr + f.rgbToYcc[0][1] * gg + f.rgbToYcc[0][2] * bb - 16.0f;
                    cx[i] = f.rgbToYcc[1][0] * rr + f.rgbToYcc[1][1] * gg + f.rgbToYcc[1][2] * bb;
                    cz[i] = f.rgbToYcc[2][0] * rr + f.rgbToYcc[2][1] * gg + f.rgbToYcc[2][2] * bb;
                }
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
        // Per-pixel combination.
        Sums part;
        const float invSqrt2 = 0.70710678118654752f;
        for (int y = 0; y < th; ++y) {
            float* mr = errorImage ? errorImage->row(tile.y0 + uint32_t(y)) + tile.x0 : nullptr;
            const size_t rowBase = size_t(tile.y0 + uint32_t(y)) * W + tile.x0;
            for (int x = 0; x < tw; ++x) {
                float lab[2][3], edge[2], point[2];
                for (int img = 0; img < 2; ++img) {
                    auto v = [&](int q) { return vbuf[((size_t(img) * kV + q) * th + y) * tw + x]; };
                    // Filtered YyCxCz back to linear RGB, clamped to [0, 1].
                    const float yn = (v(0) + 16.0f) / 116.0f;
                    const float X = (v(1) / 500.0f + yn) * f.white[0];
                    const float Y = yn * f.white[1];
                    const float Z = (yn - v(2) / 200.0f) * f.white[2];
                    float rgb[3];
                    for (int i = 0; i < 3; ++i)
                        rgb[i] =
                            std::clamp(f.xyzToRgb[i][0] * X + f.xyzToRgb[i][1] * Y + f.xyzToRgb[i][2] * Z, 0.0f, 1.0f);
                    huntLab(f, rgb[0], rgb[1], rgb[2], lab[img]);
                    // Features of the achromatic channel Y/Yw = (Yy + 16) / 116 (the kernels sum to 0).
                    edge[img] = std::sqrt(v(3) * v(3) + v(4) * v(4)) / 116.0f;
                    point[img] = std::sqrt(v(5) * v(5) + v(6) * v(6)) / 116.0f;
                }
                const float dc = std::pow(hyab(lab[0], lab[1]), kQc);
                const float pcm = kPc * f.cmax;
                const float colour =
                    std::min(1.0f, dc < pcm ? (kPt / pcm) * dc : kPt + (dc - pcm) / (f.cmax - pcm) * (1.0f - kPt));
                const float feature = std::pow(
                    std::min(1.0f, invSqrt2 * std::max(std::abs(edge[1] - edge[0]), std::abs(point[1] - point[0]))),
                    kQf);
                float e = std::pow(colour, 1.0f - feature);
                if (planes.nonFinite[rowBase + size_t(x)]) e = 1.0f;
                part.sum += e;
                if (mr) mr[x] = e;
            }
        }
        part.count = uint64_t(tw) * uint64_t(th);
        return part;
    });
    return {meanOf(s, 1.0), planes.nonFiniteCount};
}

// ---------------------------------------------------------------------------------------------
// Temporal metrics

MetricValue temporalError(MetricImage test, MetricImage testPrev, MetricImage ref, MetricImage refPrev) {
    checkSameSize(test, testPrev, "temporalError");
    checkSameSize(test, ref, "temporalError");
    checkSameSize(test, refPrev, "temporalError");
    const Sums s = reduceTiles(test.width, test.height, 64, [&](const Tile& tile) {
        Sums part;
        for (uint32_t y = tile.y0; y < tile.y1; ++y) {
            const glm::vec4 *a = test.row(y), *b = testPrev.row(y), *c = ref.row(y), *d = refPrev.row(y);
            for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                if (!finite3(a[x]) || !finite3(b[x]) || !finite3(c[x]) || !finite3(d[x])) {
                    ++part.nonFinite;
                    continue;
                }
                for (int k = 0; k < 3; ++k)
                    part.sum += std::abs((double(a[x][k]) - double(b[x][k])) - (double(c[x][k]) - double(d[x][k])));
                ++part.count;
            }
        }
        return part;
    });
    return {std::min(meanOf(s, 3.0), std::numeric_limits<double>::max()), s.nonFinite};
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
                const double l = 0.2126 * row[x].x + 0.7152 * row[x].y + 0.0722 * row[x].z;
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
