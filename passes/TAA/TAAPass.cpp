#include "TAAPass.h"

#include <hwy/cache_control.h>
#include <hwy/highway.h>

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

// Tiles of 128 x 16 pixels: rows long enough (2 KiB of colour) for the hardware prefetchers to stream, few enough
// rows that the scratch below stays in L2. They are dispatched as the cells of a tile grid through parallelFor2D.
constexpr uint32_t kTileW = 128, kTileH = 16;

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
    static constexpr uint32_t kW = kTileW, kR = kTileH + 2, kRW = kTileW + 2 + 8;  // + 8: whole vectors at the end
    float v[4][kR][kRW];
    float rowSum[4][kR][kW], rowSumSq[4][kR][kW], rowMin[4][kR][kW], rowMax[4][kR][kW];
    float mvx[kR][kRW], mvy[kR][kRW], mvLen[kR][kRW];
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

namespace hn = hwy::HWY_NAMESPACE;
using FloatTag = hn::ScalableTag<float>;
using FloatVec = hn::Vec<FloatTag>;
using FloatMask = hn::Mask<FloatTag>;
using Float4Tag = hn::FixedTag<float, 4>;
using Float4 = hn::Vec<Float4Tag>;

/// YCoCg + alpha of structure-of-arrays RGBA (toYCoCg, lane-wise).
HWY_INLINE void toYCoCgVec(FloatTag d, FloatVec r, FloatVec g, FloatVec b, FloatVec& y, FloatVec& co, FloatVec& cg) {
    const FloatVec rb = hn::Add(r, b);
    y = hn::Add(hn::Mul(hn::Set(d, 0.25f), rb), hn::Mul(hn::Set(d, 0.5f), g));
    co = hn::Mul(hn::Set(d, 0.5f), hn::Sub(r, b));
    cg = hn::Sub(hn::Mul(hn::Set(d, 0.5f), g), hn::Mul(hn::Set(d, 0.25f), rb));
}

HWY_INLINE FloatMask finiteVec(FloatTag d, FloatVec v) {
    const hn::RebindToSigned<FloatTag> di;
    const auto exponent = hn::Set(di, 0x7F800000);
    return hn::RebindMask(d, hn::Ne(hn::And(hn::BitCast(di, v), exponent), exponent));
}

/// sampleHistory for an interior position (all 16 taps inside the frame) from precomputed weights, with 256-bit
/// vectors holding two texels: the same products and order of additions as the reference.
HWY_INLINE glm::vec4 sampleInterior(const taa::ClampedImage<glm::vec4>& history, int ix, int iy, const float* wx,
                                    const float* wy) {
    const FloatTag d;  // 8 lanes = two texels
    const Float4Tag d4;
    const FloatVec w01 = hn::Combine(d, hn::Set(d4, wx[1]), hn::Set(d4, wx[0]));
    const FloatVec w23 = hn::Combine(d, hn::Set(d4, wx[3]), hn::Set(d4, wx[2]));
    FloatVec acc = hn::Zero(d);
    for (int j = 0; j < 4; ++j) {
        const float* row = reinterpret_cast<const float*>(&history.at(ix - 1, iy - 1 + j));
        // (w0 h0 | w1 h1) + (w2 h2 | w3 h3) = (even | odd) of this row.
        const FloatVec pair = hn::Add(hn::Mul(w01, hn::LoadU(d, row)), hn::Mul(w23, hn::LoadU(d, row + 8)));
        acc = hn::Add(acc, hn::Mul(hn::Set(d, wy[j]), pair));
    }
    glm::vec4 out;
    hn::StoreU(hn::Add(hn::LowerHalf(d4, acc), hn::UpperHalf(d4, acc)), d4, &out.x);
    return out;
}

/// catmullRomWeights, lane-wise.
HWY_INLINE void catmullRomVec(FloatTag d, FloatVec t, FloatVec w[4]) {
    const FloatVec t2 = hn::Mul(t, t), t3 = hn::Mul(t2, t), half = hn::Set(d, 0.5f);
    w[0] = hn::Mul(half, hn::Sub(hn::Add(hn::Neg(t3), hn::Mul(hn::Set(d, 2.f), t2)), t));
    w[1] = hn::Add(hn::Mul(half, hn::Sub(hn::Mul(hn::Set(d, 3.f), t3), hn::Mul(hn::Set(d, 5.f), t2))), hn::Set(d, 1.f));
    w[2] = hn::Mul(half, hn::Add(hn::Add(hn::Mul(hn::Set(d, -3.f), t3), hn::Mul(hn::Set(d, 4.f), t2)), t));
    w[3] = hn::Mul(half, hn::Sub(t3, t2));
}

/// The tiled path. The 3x3 statistics and the motion dilation are separable: each current pixel is converted to
/// YCoCg once (not nine times), sums, minima, maxima and the longest vector are formed over rows, then over
/// columns, and the rest runs on vectors of 8 pixels (Highway, AVX2), with the bicubic history fetched per pixel
/// as pairs of texels in 256-bit vectors. Every step does the reference kernel's operations in its order (the plugin is
/// built without FMA contraction), so the output is bit-identical to it; a test checks that. A tile with a non-finite
/// colour or motion vector in reach runs the reference kernel instead (it skips those samples).
void resolveTile(const TaaInputs& in, const taa::TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                 const ImageView<glm::vec4>& history, Counts& counts) {
    TileScratch& s = scratch();
    const FloatTag d;
    const uint32_t N = uint32_t(hn::Lanes(d));
    const uint32_t w = t.x1 - t.x0, h = t.y1 - t.y0, rw = w + 2, rh = h + 2;
    const uint32_t W = in.color.width, H = in.color.height;

    // Load the region (edges repeated), converting to YCoCg.
    bool finite = true;
    const bool interiorX = t.x0 >= 1 && t.x1 + 1 <= W;
    for (uint32_t ry = 0; ry < rh; ++ry) {
        const uint32_t sy = clampIndex(int(t.y0 + ry) - 1, H);
        const glm::vec4* colorRow = &in.color.at(0, int(sy));
        const glm::vec2* mvecRow = &in.mvec.at(0, int(sy));
        uint32_t rx = 0;
        if (interiorX) {
            FloatMask ok = hn::FirstN(d, N);
            for (; rx + N <= rw; rx += N) {
                FloatVec r, g, b, a, mx, my, y, co, cg;
                hn::LoadInterleaved4(d, reinterpret_cast<const float*>(colorRow + t.x0 - 1 + rx), r, g, b, a);
                hn::LoadInterleaved2(d, reinterpret_cast<const float*>(mvecRow + t.x0 - 1 + rx), mx, my);
                ok = hn::And(ok, hn::And(hn::And(finiteVec(d, r), finiteVec(d, g)),
                                         hn::And(hn::And(finiteVec(d, b), finiteVec(d, a)),
                                                 hn::And(finiteVec(d, mx), finiteVec(d, my)))));
                toYCoCgVec(d, r, g, b, y, co, cg);
                hn::StoreU(y, d, &s.v[0][ry][rx]);
                hn::StoreU(co, d, &s.v[1][ry][rx]);
                hn::StoreU(cg, d, &s.v[2][ry][rx]);
                hn::StoreU(a, d, &s.v[3][ry][rx]);
                hn::StoreU(mx, d, &s.mvx[ry][rx]);
                hn::StoreU(my, d, &s.mvy[ry][rx]);
                hn::StoreU(hn::Add(hn::Mul(mx, mx), hn::Mul(my, my)), d, &s.mvLen[ry][rx]);
            }
            finite &= hn::AllTrue(d, ok);
        }
        for (; rx < rw; ++rx) {
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

    // Horizontal 3-tap statistics and longest vector, per region row (vectors over x; rw >= w + 2 so the taps at
    // x + 1 and x + 2 of the last full vector stay in the region).
    const FloatVec zero = hn::Zero(d), huge = hn::Set(d, taa::kHuge), negHuge = hn::Set(d, -taa::kHuge);
    for (uint32_t ry = 0; ry < rh; ++ry) {
        for (int ch = 0; ch < 4; ++ch) {
            const float* v = s.v[ch][ry];
            uint32_t x = 0;
            for (; x + N <= w; x += N) {
                const FloatVec a = hn::LoadU(d, v + x), b = hn::LoadU(d, v + x + 1), c = hn::LoadU(d, v + x + 2);
                hn::StoreU(hn::Add(hn::Add(hn::Add(zero, a), b), c), d, &s.rowSum[ch][ry][x]);
                hn::StoreU(hn::Add(hn::Add(hn::Add(zero, hn::Mul(a, a)), hn::Mul(b, b)), hn::Mul(c, c)), d,
                           &s.rowSumSq[ch][ry][x]);
                // glm::min(m, v) is (v < m) ? v : m: the same as x86 min(v, m) for these (never NaN) values.
                hn::StoreU(hn::Min(c, hn::Min(b, hn::Min(a, huge))), d, &s.rowMin[ch][ry][x]);
                hn::StoreU(hn::Max(c, hn::Max(b, hn::Max(a, negHuge))), d, &s.rowMax[ch][ry][x]);
            }
            for (; x < w; ++x) {
                const float a = v[x], b = v[x + 1], c = v[x + 2];
                s.rowSum[ch][ry][x] = ((0.f + a) + b) + c;
                s.rowSumSq[ch][ry][x] = ((0.f + a * a) + b * b) + c * c;
                float lo = taa::kHuge, hi = -taa::kHuge;
                lo = a < lo ? a : lo;
                lo = b < lo ? b : lo;
                lo = c < lo ? c : lo;
                hi = a > hi ? a : hi;
                hi = b > hi ? b : hi;
                hi = c > hi ? c : hi;
                s.rowMin[ch][ry][x] = lo;
                s.rowMax[ch][ry][x] = hi;
            }
        }
        const float* mvx = s.mvx[ry];
        const float* mvy = s.mvy[ry];
        const float* len = s.mvLen[ry];
        uint32_t x = 0;
        for (; x + N <= w; x += N) {
            // Strictly longer wins: the first of equals, as in the reference.
            FloatVec best = hn::LoadU(d, len + x), bx = hn::LoadU(d, mvx + x), by = hn::LoadU(d, mvy + x);
            for (uint32_t k = 1; k < 3; ++k) {
                const FloatVec l = hn::LoadU(d, len + x + k);
                const FloatMask longer = hn::Gt(l, best);
                best = hn::IfThenElse(longer, l, best);
                bx = hn::IfThenElse(longer, hn::LoadU(d, mvx + x + k), bx);
                by = hn::IfThenElse(longer, hn::LoadU(d, mvy + x + k), by);
            }
            hn::StoreU(best, d, &s.rowMvLen[ry][x]);
            hn::StoreU(bx, d, &s.rowMvx[ry][x]);
            hn::StoreU(by, d, &s.rowMvy[ry][x]);
        }
        for (; x < w; ++x) {
            float best = len[x], bx = mvx[x], by = mvy[x];
            for (uint32_t k = 1; k < 3; ++k) {
                const bool longer = len[x + k] > best;
                best = longer ? len[x + k] : best;
                bx = longer ? mvx[x + k] : bx;
                by = longer ? mvy[x + k] : by;
            }
            s.rowMvLen[ry][x] = best;
            s.rowMvx[ry][x] = bx;
            s.rowMvy[ry][x] = by;
        }
    }

    const float sigma = p.sigma;
    alignas(64) glm::vec4 sampled[16];
    alignas(64) float posX[16], posY[16];
    for (uint32_t y = 0; y < h; ++y) {
        const uint32_t py = t.y0 + y;
        glm::vec4* outRow = out.row(py);
        glm::vec4* historyRow = history.row(py);
        const glm::vec4* colorRow = &in.color.at(0, int(py));
        uint32_t x = 0;
        for (; x + N <= w; x += N) {
            // Box (makeClipBox with n = 9).
            FloatVec lo[4], hi[4];
            for (int ch = 0; ch < 4; ++ch) {
                FloatVec sum = zero, sumSq = zero, mn = huge, mx = negHuge;
                for (uint32_t r = y; r < y + 3; ++r) {
                    sum = hn::Add(sum, hn::LoadU(d, &s.rowSum[ch][r][x]));
                    sumSq = hn::Add(sumSq, hn::LoadU(d, &s.rowSumSq[ch][r][x]));
                    mn = hn::Min(hn::LoadU(d, &s.rowMin[ch][r][x]), mn);
                    mx = hn::Max(hn::LoadU(d, &s.rowMax[ch][r][x]), mx);
                }
                const FloatVec inv = hn::Set(d, 1.f / 9.f);
                const FloatVec mean = hn::Mul(sum, inv);
                const FloatVec var = hn::Max(hn::Sub(hn::Mul(sumSq, inv), hn::Mul(mean, mean)), zero);
                const FloatVec dev = hn::Mul(hn::Set(d, sigma), hn::Sqrt(var));
                lo[ch] = hn::Min(hn::Max(hn::Sub(mean, dev), mn), mx);
                hi[ch] = hn::Min(hn::Max(hn::Add(mean, dev), mn), mx);
            }
            // Dilated motion: the longest of the three row winners, the first of equals.
            FloatVec best = hn::LoadU(d, &s.rowMvLen[y][x]);
            FloatVec mvx = hn::LoadU(d, &s.rowMvx[y][x]), mvy = hn::LoadU(d, &s.rowMvy[y][x]);
            for (uint32_t r = y + 1; r < y + 3; ++r) {
                const FloatVec len = hn::LoadU(d, &s.rowMvLen[r][x]);
                const FloatMask longer = hn::Gt(len, best);
                best = hn::IfThenElse(longer, len, best);
                mvx = hn::IfThenElse(longer, hn::LoadU(d, &s.rowMvx[r][x]), mvx);
                mvy = hn::IfThenElse(longer, hn::LoadU(d, &s.rowMvy[r][x]), mvy);
            }
            // previousPosition.
            const FloatVec px = hn::Add(hn::Iota(d, float(t.x0 + x)), hn::Mul(mvx, hn::Set(d, float(W))));
            const FloatVec pyv = hn::Add(hn::Set(d, float(py)), hn::Mul(mvy, hn::Set(d, float(H))));
            FloatMask useHistory =
                hn::And(hn::And(hn::Ge(px, hn::Set(d, -0.5f)), hn::Le(px, hn::Set(d, float(W) - 0.5f))),
                        hn::And(hn::Ge(pyv, hn::Set(d, -0.5f)), hn::Le(pyv, hn::Set(d, float(H) - 0.5f))));
            if (!in.historyValid) useHistory = hn::And(useHistory, hn::Not(useHistory));
            // Bicubic history: floor, fractions and weights on vectors, the taps per pixel.
            const FloatVec fx0 = hn::Floor(px), fy0 = hn::Floor(pyv);
            FloatVec wxv[4], wyv[4];
            catmullRomVec(d, hn::Sub(px, fx0), wxv);
            catmullRomVec(d, hn::Sub(pyv, fy0), wyv);
            const auto di = hn::RebindToSigned<FloatTag>();
            const auto ixv = hn::ConvertTo(di, fx0), iyv = hn::ConvertTo(di, fy0);
            // Kinds: 0 unused, 1 one texel (integer position), 2 interior bicubic, 3 near the edge (reference).
            const FloatMask integer = hn::And(hn::Eq(px, fx0), hn::Eq(pyv, fy0));
            const auto interior =
                hn::And(hn::And(hn::Gt(ixv, hn::Zero(di)), hn::Gt(iyv, hn::Zero(di))),
                        hn::And(hn::Lt(ixv, hn::Set(di, int32_t(W) - 2)), hn::Lt(iyv, hn::Set(di, int32_t(H) - 2))));
            auto kind = hn::IfThenElse(hn::RebindMask(di, interior), hn::Set(di, 2), hn::Set(di, 3));
            kind = hn::IfThenElse(hn::RebindMask(di, integer), hn::Set(di, 1), kind);
            kind = hn::IfThenElseZero(hn::RebindMask(di, useHistory), kind);
            alignas(64) int32_t kinds[16], ixs[16], iys[16];
            alignas(64) float wx[4][16], wy[4][16];
            hn::Store(kind, di, kinds);
            hn::Store(ixv, di, ixs);
            hn::Store(iyv, di, iys);
            for (int k = 0; k < 4; ++k) {
                hn::Store(wxv[k], d, wx[k]);
                hn::Store(wyv[k], d, wy[k]);
            }
            hn::StoreU(px, d, posX);
            hn::StoreU(pyv, d, posY);
            for (uint32_t i = 0; i < N; ++i) {
                switch (kinds[i]) {
                    case 0:
                        sampled[i] = glm::vec4(0.f);
                        break;
                    case 1:
                        sampled[i] = in.history.at(ixs[i], iys[i]);
                        break;
                    case 2: {
                        const float wxi[4] = {wx[0][i], wx[1][i], wx[2][i], wx[3][i]};
                        const float wyi[4] = {wy[0][i], wy[1][i], wy[2][i], wy[3][i]};
                        sampled[i] = sampleInterior(in.history, ixs[i], iys[i], wxi, wyi);
                        break;
                    }
                    default:
                        sampled[i] = taa::sampleHistory(in.history, glm::vec2(posX[i], posY[i]));
                }
            }
            FloatVec hr, hg, hb, ha, cr, cgr, cb, ca;
            hn::LoadInterleaved4(d, reinterpret_cast<const float*>(sampled), hr, hg, hb, ha);
            hn::LoadInterleaved4(d, reinterpret_cast<const float*>(colorRow + t.x0 + x), cr, cgr, cb, ca);
            // Clip the history (clipToBox).
            FloatVec hv[4];
            toYCoCgVec(d, hr, hg, hb, hv[0], hv[1], hv[2]);
            hv[3] = ha;
            FloatVec unit = zero, delta[4], center[4];
            for (int ch = 0; ch < 4; ++ch) {
                center[ch] = hn::Mul(hn::Set(d, 0.5f), hn::Add(lo[ch], hi[ch]));
                const FloatVec extent = hn::Mul(hn::Set(d, 0.5f), hn::Sub(hi[ch], lo[ch]));
                delta[ch] = hn::Sub(hv[ch], center[ch]);
                const FloatVec a = hn::Abs(delta[ch]);
                const FloatMask outside = hn::Gt(a, extent);
                unit = hn::IfThenElse(outside, hn::Max(unit, hn::Div(a, extent)), unit);
            }
            const FloatMask clipped = hn::And(useHistory, hn::Gt(unit, zero));
            FloatVec cv[4];
            const FloatVec inv = hn::Div(hn::Set(d, 1.f), unit);
            for (int ch = 0; ch < 4; ++ch)
                cv[ch] = hn::IfThenElse(clipped, hn::Add(center[ch], hn::Mul(delta[ch], inv)), hv[ch]);
            // fromYCoCg where clipped; the sampled RGB elsewhere.
            hr = hn::IfThenElse(clipped, hn::Sub(hn::Add(cv[0], cv[1]), cv[2]), hr);
            hg = hn::IfThenElse(clipped, hn::Add(cv[0], cv[2]), hg);
            hb = hn::IfThenElse(clipped, hn::Sub(hn::Sub(cv[0], cv[1]), cv[2]), hb);
            ha = hn::IfThenElse(clipped, cv[3], ha);
            // Blend with anti-flicker.
            FloatVec wc = hn::Set(d, p.alpha), wh = hn::Set(d, 1.f - p.alpha);
            if (p.antiFlicker) {
                FloatVec yc, coc, cgc;
                toYCoCgVec(d, cr, cgr, cb, yc, coc, cgc);
                wc = hn::Mul(wc, hn::Add(hn::Set(d, 1.f), hn::Max(cv[0], zero)));
                wh = hn::Mul(wh, hn::Add(hn::Set(d, 1.f), hn::Max(yc, zero)));
            }
            const FloatVec wsum = hn::Add(wc, wh);
            const FloatVec k = hn::IfThenElseZero(hn::Gt(wsum, zero), hn::Div(wh, wsum));
            FloatVec orr = hn::Add(cr, hn::Mul(k, hn::Sub(hr, cr)));
            FloatVec og = hn::Add(cgr, hn::Mul(k, hn::Sub(hg, cgr)));
            FloatVec ob = hn::Add(cb, hn::Mul(k, hn::Sub(hb, cb)));
            FloatVec oa = hn::Add(ca, hn::Mul(k, hn::Sub(ha, ca)));
            const FloatMask keep = hn::And(useHistory, hn::And(hn::And(finiteVec(d, orr), finiteVec(d, og)),
                                                               hn::And(finiteVec(d, ob), finiteVec(d, oa))));
            orr = hn::IfThenElse(keep, orr, cr);
            og = hn::IfThenElse(keep, og, cgr);
            ob = hn::IfThenElse(keep, ob, cb);
            oa = hn::IfThenElse(keep, oa, ca);
            hn::StoreInterleaved4(orr, og, ob, oa, d, reinterpret_cast<float*>(outRow + t.x0 + x));
            // The history is read again only next frame, long after it has left the caches: streaming stores skip
            // the read-for-ownership of its lines (rows are 64-byte aligned and x is a multiple of 8 pixels).
            {
                alignas(64) float packed[4 * 16];
                hn::StoreInterleaved4(orr, og, ob, oa, d, packed);
                float* dst = reinterpret_cast<float*>(historyRow + t.x0 + x);
                if (reinterpret_cast<uintptr_t>(dst) % 64 == 0) {
                    for (uint32_t k = 0; k < 4; ++k) hn::Stream(hn::Load(d, packed + k * N), d, dst + k * N);
                } else {
                    for (uint32_t k = 0; k < 4; ++k) hn::StoreU(hn::Load(d, packed + k * N), d, dst + k * N);
                }
            }
            counts.noHistory += N - hn::CountTrue(d, useHistory);
            counts.clipped += hn::CountTrue(d, clipped);
        }
        // The rest of the row (partial tiles): scalar, the reference's per-pixel steps on the same statistics.
        for (; x < w; ++x) {
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
    hwy::FlushStream();  // order the streaming stores before the frame's end
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
    const uint32_t tilesX = (out.width + kTileW - 1) / kTileW, tilesY = (out.height + kTileH - 1) / kTileH;
    parallelFor2D(
        tilesX, tilesY,
        [&](const Tile& cell) {
            const Tile t{cell.x0 * kTileW, cell.y0 * kTileH, std::min(out.width, (cell.x0 + 1) * kTileW),
                         std::min(out.height, (cell.y0 + 1) * kTileH)};
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
        1);  // one cell of the tile grid per task

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
