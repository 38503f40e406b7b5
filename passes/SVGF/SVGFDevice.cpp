// SVGFPass's stages as launch2D over its scalar kernels (SVGFDevice.h). Compiled by nvcc where the CUDA toolkit is
// found (LOOM_CUDA; CMake compiles this file as CUDA), else by the host compiler: the same source either way, and
// the launches run on the cuda device only in the first case.
#include "SVGFDevice.h"

#include "AtrousKernels.h"
#include "loom/Launch.h"

namespace loom::svgf::device {

namespace {

/// The demodulation albedo when specAlbedo is connected: albedo + specAlbedo, albedo's alpha (as SVGFPass on the
/// CPU forms it).
LOOM_HD inline glm::vec4 albedoPlusSpecular(const glm::vec4& a, const glm::vec4& s) {
    return glm::vec4(glm::vec3(a) + glm::vec3(s), a.a);
}

void copyImage(DeviceKind device, ImageView<const glm::vec4> src, ImageView<glm::vec4> dst) {
    launch2D(device, src.width, src.height, [=] LOOM_HD(uint32_t x, uint32_t y) { dst.at(x, y) = src.at(x, y); });
}

/// Whether the kSkipTile x kSkipTile tile of (x, y) keeps its input at every level: each of its hit pixels has a
/// variance below limit times its squared luminance in src (AtrousFilter::classifyTiles).
LOOM_HD inline bool tileKeepsInput(ImageView<const glm::vec4> src, ImageView<const glm::vec2> linearZ, uint32_t x,
                                   uint32_t y, float limit) {
    const uint32_t x0 = x - x % kSkipTile, y0 = y - y % kSkipTile;
    const uint32_t x1 = x0 + kSkipTile < src.width ? x0 + kSkipTile : src.width;
    const uint32_t y1 = y0 + kSkipTile < src.height ? y0 + kSkipTile : src.height;
    for (uint32_t ty = y0; ty < y1; ++ty)
        for (uint32_t tx = x0; tx < x1; ++tx) {
            if (!(linearZ.at(tx, ty).x >= 0.f)) continue;  // misses keep their input anyway
            const glm::vec4 p = src.at(tx, ty);
            const float l = luminance(glm::vec3(p));
            if (!(p.a < limit * l * l)) return false;  // not below (NaN included): filtered
        }
    return true;
}

}  // namespace

bool launchesOnCuda() { return launchesReach(DeviceKind::Cuda); }

void passThrough(DeviceKind device, ImageView<const glm::vec4> color, ImageView<glm::vec4> dst) {
    // remodulate() passes a miss pixel's colour through: non-finite channels as 0, alpha 1 where not finite.
    launch2D(device, dst.width, dst.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
        dst.at(x, y) = remodulate(glm::vec3(0.f), color.at(x, y), glm::vec4(0.f), glm::vec3(0.f), -1.f);
    });
}

void antilag(DeviceKind device, ImageView<const glm::vec2> gradient, ImageView<glm::vec2> samples,
             ImageView<glm::vec2> change) {
    const uint32_t w = change.width, h = change.height;
    const uint32_t bw = (w + kGradientBlock - 1) / kGradientBlock, bh = (h + kGradientBlock - 1) / kGradientBlock;
    // One sample per block (the channel replicates it over the block), then for each block the sums over the 3x3
    // blocks around it in a fixed order, written to the block's pixels: the CPU's order, so the same bits.
    launch2D(device, bw, bh, [=] LOOM_HD(uint32_t bx, uint32_t by) {
        samples.at(bx, by) = gradientSample(gradient.at(bx * kGradientBlock, by * kGradientBlock));
    });
    launch2D(device, bw, bh, [=] LOOM_HD(uint32_t bx, uint32_t by) {
        glm::vec2 around[9];
        int count = 0;
        const uint32_t j0 = by > 0 ? by - 1 : 0, j1 = by + 1 < bh ? by + 1 : bh - 1;
        const uint32_t i0 = bx > 0 ? bx - 1 : 0, i1 = bx + 1 < bw ? bx + 1 : bw - 1;
        for (uint32_t j = j0; j <= j1; ++j)
            for (uint32_t i = i0; i <= i1; ++i) around[count++] = samples.at(i, j);
        const glm::vec2 c = antilagChange(around, count);
        const uint32_t x1 = (bx + 1) * kGradientBlock < w ? (bx + 1) * kGradientBlock : w;
        const uint32_t y1 = (by + 1) * kGradientBlock < h ? (by + 1) * kGradientBlock : h;
        for (uint32_t y = by * kGradientBlock; y < y1; ++y)
            for (uint32_t x = bx * kGradientBlock; x < x1; ++x) change.at(x, y) = c;
    });
}

void neighbourhood(DeviceKind device, const TemporalViews& v, bool split, ImageView<const glm::vec4> albedo,
                   ImageView<const glm::vec4> specAlbedo, ImageView<glm::vec4> box) {
    const TemporalViews views = v;
    launch2D(device, box.width, box.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
        box.at(x, y) = neighbourhoodPixel(views, split, x, y, [&](uint32_t qx, uint32_t qy) {
            return specAlbedo.data ? albedoPlusSpecular(albedo.at(qx, qy), specAlbedo.at(qx, qy)) : albedo.at(qx, qy);
        });
    });
}

uint64_t temporal(DeviceKind device, TemporalViews v, const TemporalParams& p, ImageView<const glm::vec4> albedo,
                  ImageView<const glm::vec4> specAlbedo) {
    const TemporalParams params = p;
    if (specAlbedo.data) {
        const ImageView<glm::vec4> sum = v.integrated0;
        v.albedo = ImageView<const glm::vec4>{sum.data, sum.width, sum.height, sum.rowPitch};
        launch2D(device, sum.width, sum.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
            sum.at(x, y) = albedoPlusSpecular(albedo.at(x, y), specAlbedo.at(x, y));
            temporalPixel(v, x, y, params);
        });
    } else {
        v.albedo = albedo;
        launch2D(device, v.color.width, v.color.height,
                 [=] LOOM_HD(uint32_t x, uint32_t y) { temporalPixel(v, x, y, params); });
    }
    // The rejected samples, counted apart (the count of temporalPixel's result, in a fixed order).
    const ImageView<const glm::vec4> c0 = params.split ? v.direct : v.color, c1 = v.indirect;
    const bool split = params.split;
    return reduceRows(
        device, c0.width, c0.height, uint64_t(0),
        [=] LOOM_HD(uint32_t x, uint32_t y) -> uint64_t {
            const bool finite =
                isFinite(glm::vec3(c0.at(x, y))) && (!split || isFinite(glm::vec3(c1.at(x, y))));
            return finite ? 0u : 1u;
        },
        [] LOOM_HD(uint64_t a, uint64_t b) { return a + b; });
}

void variance(DeviceKind device, const VarianceViews& v, const VarianceScales& scales, bool split) {
    const VarianceViews views = v;
    const VarianceScales s = scales;
    launch2D(device, v.estimate0.width, v.estimate0.height,
             [=] LOOM_HD(uint32_t x, uint32_t y) { varianceEstimatePixel(views, x, y, s, split); });
}

void atrous(DeviceKind device, ImageView<const glm::vec4> src, ImageView<glm::vec4> dst, ImageView<glm::vec4> scratch,
            ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normW, int iterations,
            const AtrousParams& params, int feedbackTap, ImageView<glm::vec4> feedback) {
    const bool wantsFeedback = feedback.data != nullptr;
    if (iterations <= 0) {
        copyImage(device, src, dst);
        if (wantsFeedback) copyImage(device, src, feedback);
        return;
    }
    if (wantsFeedback && feedbackTap < 0) copyImage(device, src, feedback);
    const int tap = feedbackTap >= iterations ? iterations - 1 : feedbackTap;
    const AtrousParams p = params;
    const float limit = params.skipRelVariance;
    const bool skip = limit > 0.f;
    ImageView<const glm::vec4> in = src;
    for (int level = 0; level < iterations; ++level) {
        // The last level writes dst: the levels before it alternate so that none reads what it writes.
        const ImageView<glm::vec4> out = (iterations - 1 - level) % 2 == 0 ? dst : scratch;
        const int step = 1 << (level < 30 ? level : 30);
        launch2D(device, src.width, src.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
            out.at(x, y) = skip && tileKeepsInput(src, linearZ, x, y, limit)
                               ? in.at(x, y)
                               : atrousPixel(in, linearZ, normW, int(x), int(y), step, p);
        });
        in = ImageView<const glm::vec4>{out.data, out.width, out.height, out.rowPitch};
        if (wantsFeedback && level == tap) copyImage(device, in, feedback);
    }
}

void modulate(DeviceKind device, ModulateViews v, bool split, ImageView<const glm::vec4> albedo,
              ImageView<const glm::vec4> specAlbedo, ImageView<float> lengthOut, ImageView<const float> length) {
    const ImageView<glm::vec4> dst = v.dst;
    if (specAlbedo.data)
        v.albedo = ImageView<const glm::vec4>{dst.data, dst.width, dst.height, dst.rowPitch};
    else
        v.albedo = albedo;
    const ModulateViews views = v;
    launch2D(device, dst.width, dst.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
        if (specAlbedo.data) dst.at(x, y) = albedoPlusSpecular(albedo.at(x, y), specAlbedo.at(x, y));
        modulatePixel(views, x, y, split);
        if (lengthOut.data) lengthOut.at(x, y) = length.at(x, y);
    });
}

}  // namespace loom::svgf::device
