#include "Atrous.h"

#include <chrono>

#include "loom/Parallel.h"

namespace loom::svgf {

namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void copyImage(ImageView<const glm::vec4> src, ImageView<glm::vec4> dst) {
    parallelFor2D(src.width, src.height, [&](const Tile& t) {
        for (uint32_t y = t.y0; y < t.y1; ++y)
            for (uint32_t x = t.x0; x < t.x1; ++x) dst.at(x, y) = src.at(x, y);
    });
}

ImageView<const glm::vec4> asConst(ImageView<glm::vec4> v) { return {v.data, v.width, v.height, v.rowPitch}; }

}  // namespace

void AtrousFilter::setGuide(ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal) {
    mLinearZ = linearZ;
    mNormal = normal;
    if (mWidth != linearZ.width || mHeight != linearZ.height) {
        mWidth = linearZ.width;
        mHeight = linearZ.height;
        mPing = Texture(mWidth, mHeight, Format::RGBA32F);
        mPong = Texture(mWidth, mHeight, Format::RGBA32F);
    }
}

void AtrousFilter::run(ImageView<const glm::vec4> src, ImageView<glm::vec4> dst, int iterations,
                       const AtrousParams& params, int feedbackTap, ImageView<glm::vec4> feedback, bool reference,
                       AtrousTimings* timings) {
    (void)reference;  // only the reference kernel exists so far
    const bool wantsFeedback = feedback.data != nullptr;
    if (iterations <= 0) {
        copyImage(src, dst);
        if (wantsFeedback) copyImage(src, feedback);
        return;
    }
    if (wantsFeedback && feedbackTap < 0) copyImage(src, feedback);
    const int tap = feedbackTap >= iterations ? iterations - 1 : feedbackTap;

    ImageView<const glm::vec4> in = src;
    for (int level = 0; level < iterations; ++level) {
        const auto t0 = std::chrono::steady_clock::now();
        const bool last = level == iterations - 1;
        ImageView<glm::vec4> out = last ? dst : (level % 2 == 0 ? mPing : mPong).view<glm::vec4>();
        const int step = 1 << level;
        parallelFor2D(mWidth, mHeight, [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x)
                    out.at(x, y) = atrousPixel(in, mLinearZ, mNormal, int(x), int(y), step, params);
        });
        if (wantsFeedback && level == tap) copyImage(asConst(out), feedback);
        in = asConst(out);
        if (timings && level < 16) timings->levelMs[level] = msSince(t0);
    }
}

}  // namespace loom::svgf
