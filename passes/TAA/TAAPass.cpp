#include "TAAPass.h"

#include <algorithm>
#include <atomic>
#include <memory>

#include "loom/Parallel.h"
#include "loom/Plugin.h"

namespace loom {

using taa::ClipBox;
using taa::TaaInputs;

namespace {

const char kColorIn[] = "colorIn";
const char kMvec[] = "mvec";
const char kColorOut[] = "colorOut";
const char kColorHistory[] = "colorHistory";

// Counters reported in the frame's stats.
const char kStatNonFinite[] = "nonFinite";
const char kStatNoHistory[] = "noHistory";
const char kStatClipped[] = "clipped";

constexpr uint32_t kTile = kDefaultTileSize;

/// Pixel counts of one tile or frame.
struct Counts {
    uint64_t nonFinite = 0, noHistory = 0, clipped = 0;
    void add(uint32_t flags) {
        nonFinite += (flags & taa::kNonFiniteInput) != 0;
        noHistory += (flags & taa::kNoHistory) != 0;
        clipped += (flags & taa::kClipped) != 0;
    }
};

/// Scratch of the tiled path for one tile: the tile plus a one-pixel border of
/// the current colour in YCoCg + alpha (structure of arrays, so the loops over
/// a row vectorize), the horizontal 3-tap statistics, and the motion vectors.
struct TileScratch {
    static constexpr uint32_t kW = kTile, kR = kTile + 2;
    float v[4][kR][kR];
    float rowSum[4][kR][kW], rowSumSq[4][kR][kW], rowMin[4][kR][kW], rowMax[4][kR][kW];
    float mvx[kR][kR], mvy[kR][kR], mvLen[kR][kR];
    float rowMvx[kR][kW], rowMvy[kR][kW], rowMvLen[kR][kW];
};

TileScratch& scratch() {
    thread_local std::unique_ptr<TileScratch> s = std::make_unique<TileScratch>();
    return *s;
}

uint32_t clampIndex(int v, uint32_t size) {
    return uint32_t(std::clamp(v, 0, int(size) - 1));
}

/// The reference kernel over one tile.
void resolveTileReference(const TaaInputs& in, const taa::TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                          const ImageView<glm::vec4>& history, Counts& counts) {
    for (uint32_t y = t.y0; y < t.y1; ++y)
        for (uint32_t x = t.x0; x < t.x1; ++x) {
            uint32_t flags = 0;
            const glm::vec4 c = taa::resolvePixel(in, p, x, y, flags);
            out.at(x, y) = c;
            history.at(x, y) = c;
            counts.add(flags);
        }
}

/// The tiled path: the 3x3 statistics and the motion dilation are separable, so each current pixel is converted to
/// YCoCg once (not nine times) and the sums, minima, maxima and the longest vector are formed over rows, then over
/// columns, in the reference kernel's order. A tile with a non-finite colour or motion vector in reach runs the
/// reference kernel instead (it skips those samples).
void resolveTile(const TaaInputs& in, const taa::TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                 const ImageView<glm::vec4>& history, Counts& counts) {
    TileScratch& s = scratch();
    const uint32_t w = t.x1 - t.x0, h = t.y1 - t.y0, rw = w + 2, rh = h + 2;
    const uint32_t W = in.color.width, H = in.color.height;

    // Load the region (edges repeated), converting to YCoCg.
    bool finite = true;
    for (uint32_t ry = 0; ry < rh; ++ry) {
        const uint32_t sy = clampIndex(int(t.y0 + ry) - 1, H);
        const glm::vec4* colorRow = &in.color.at(0, int(sy));
        const glm::vec2* mvecRow = &in.mvec.at(0, int(sy));
        for (uint32_t rx = 0; rx < rw; ++rx) {
            const uint32_t sx = clampIndex(int(t.x0 + rx) - 1, W);
            const glm::vec4 c = colorRow[sx];
            const glm::vec2 m = mvecRow[sx];
            finite &= taa::isFinite(c) & taa::isFinite(m);
            const glm::vec4 v = taa::toYCoCg(c);
            for (int ch = 0; ch < 4; ++ch) s.v[ch][ry][rx] = v[ch];
            s.mvx[ry][rx] = m.x;
            s.mvy[ry][rx] = m.y;
            s.mvLen[ry][rx] = m.x * m.x + m.y * m.y;
        }
    }
    if (!finite) {
        resolveTileReference(in, p, t, out, history, counts);
        return;
    }

    // Horizontal 3-tap statistics and longest vector, per region row.
    for (uint32_t ry = 0; ry < rh; ++ry) {
        for (int ch = 0; ch < 4; ++ch) {
            const float* v = s.v[ch][ry];
            float* sum = s.rowSum[ch][ry];
            float* sumSq = s.rowSumSq[ch][ry];
            float* mn = s.rowMin[ch][ry];
            float* mx = s.rowMax[ch][ry];
            for (uint32_t x = 0; x < w; ++x) {
                const float a = v[x], b = v[x + 1], c = v[x + 2];
                sum[x] = ((0.f + a) + b) + c;
                sumSq[x] = ((0.f + a * a) + b * b) + c * c;
                // glm::min(m, v) is (v < m) ? v : m; the same order as the reference.
                float lo = taa::kHuge, hi = -taa::kHuge;
                lo = a < lo ? a : lo;
                lo = b < lo ? b : lo;
                lo = c < lo ? c : lo;
                hi = a > hi ? a : hi;
                hi = b > hi ? b : hi;
                hi = c > hi ? c : hi;
                mn[x] = lo;
                mx[x] = hi;
            }
        }
        const float* mvx = s.mvx[ry];
        const float* mvy = s.mvy[ry];
        const float* len = s.mvLen[ry];
        for (uint32_t x = 0; x < w; ++x) {
            // Strictly longer wins: the first of equals, as in the reference.
            float best = len[x], bx = mvx[x], by = mvy[x];
            const bool b1 = len[x + 1] > best;
            best = b1 ? len[x + 1] : best;
            bx = b1 ? mvx[x + 1] : bx;
            by = b1 ? mvy[x + 1] : by;
            const bool b2 = len[x + 2] > best;
            best = b2 ? len[x + 2] : best;
            bx = b2 ? mvx[x + 2] : bx;
            by = b2 ? mvy[x + 2] : by;
            s.rowMvLen[ry][x] = best;
            s.rowMvx[ry][x] = bx;
            s.rowMvy[ry][x] = by;
        }
    }

    // Vertical combination and the per-pixel rest.
    for (uint32_t y = 0; y < h; ++y) {
        const uint32_t py = t.y0 + y;
        glm::vec4* outRow = out.row(py);
        glm::vec4* historyRow = history.row(py);
        const glm::vec4* colorRow = &in.color.at(0, int(py));
        for (uint32_t x = 0; x < w; ++x) {
            glm::vec4 sum, sumSq, mn, mx;
            for (int ch = 0; ch < 4; ++ch) {
                sum[ch] = ((0.f + s.rowSum[ch][y][x]) + s.rowSum[ch][y + 1][x]) + s.rowSum[ch][y + 2][x];
                sumSq[ch] = ((0.f + s.rowSumSq[ch][y][x]) + s.rowSumSq[ch][y + 1][x]) + s.rowSumSq[ch][y + 2][x];
                float lo = taa::kHuge, hi = -taa::kHuge;
                for (uint32_t r = y; r < y + 3; ++r) {
                    lo = s.rowMin[ch][r][x] < lo ? s.rowMin[ch][r][x] : lo;
                    hi = s.rowMax[ch][r][x] > hi ? s.rowMax[ch][r][x] : hi;
                }
                mn[ch] = lo;
                mx[ch] = hi;
            }
            const ClipBox box = taa::makeClipBox(sum, sumSq, mn, mx, 9, p.sigma);
            float best = s.rowMvLen[y][x];
            glm::vec2 motion(s.rowMvx[y][x], s.rowMvy[y][x]);
            for (uint32_t r = y + 1; r < y + 3; ++r)
                if (s.rowMvLen[r][x] > best) {
                    best = s.rowMvLen[r][x];
                    motion = glm::vec2(s.rowMvx[r][x], s.rowMvy[r][x]);
                }
            const uint32_t px = t.x0 + x;
            uint32_t flags = 0;
            const glm::vec4 c = taa::resolveWithBox(in, p, px, py, colorRow[px], box, true, motion, flags);
            outRow[px] = c;
            historyRow[px] = c;
            counts.add(flags);
        }
    }
}

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
    r.history(kColorHistory, Format::RGBA32F).doc("last frame's colorOut, the history that is reprojected");
}

void TAAPass::declareParams(ParamList& p) {
    p.add("alpha", &mParams.alpha, 0.1f)
        .range(0.0, 1.0)
        .doc("weight of the current frame in the blend (1 = no history)");
    p.add("sigma", &mParams.sigma, 1.f)
        .range(0.0, 10.0)
        .doc("clipping box half-size in standard deviations of the 3x3 neighbourhood (YCoCg)");
    p.add("antiFlicker", &mParams.antiFlicker, true)
        .doc("weight current and history by 1 / (1 + luma) (Karis 2014) so bright outliers do not flicker");
    p.add("reference", &mReference, false)
        .doc("run the plain per-pixel reference kernel instead of the tiled CPU path (same result, slower)");
}

void TAAPass::execute(PassContext& ctx) {
    TaaInputs in;
    in.color = clamped<glm::vec4>(*ctx.input(kColorIn));
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
                resolveTileReference(in, params, t, out, history, counts);
            else
                resolveTile(in, params, t, out, history, counts);
            // Integer sums: the same totals in any order.
            nonFinite += counts.nonFinite;
            noHistory += counts.noHistory;
            clipped += counts.clipped;
        },
        kTile);

    ctx.stats().set(kStatNonFinite, double(nonFinite));
    ctx.stats().set(kStatNoHistory, double(noHistory));
    ctx.stats().set(kStatClipped, double(clipped));
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::TAAPass>(
        "TAAPass",
        "Temporal anti-aliasing: 3x3 YCoCg variance clipping, motion dilation (longest vector of the 3x3), "
        "Catmull-Rom history, luminance-weighted blend against flicker; history in a graph field. Non-finite input "
        "pixels are replaced by the neighbourhood mean. Stats: nonFinite (input pixels replaced), noHistory (pixels "
        "that used the current colour alone), clipped (pixels whose history was clipped).");
}
