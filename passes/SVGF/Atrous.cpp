#include "Atrous.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "loom/Parallel.h"

namespace loom::svgf {

namespace {

// Steps the planes are first laid out for (5 levels); more levels widen the margins once.
constexpr int kDefaultMaxStep = 16;
constexpr int kGuidePlanes = 5, kSignalPlanes = 5;

double msSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void copyImage(ImageView<const glm::vec4> src, ImageView<glm::vec4> dst) {
    parallelFor2D(src.width, src.height, [&](const Tile& t) {
        for (uint32_t y = t.y0; y < t.y1; ++y)
            for (uint32_t x = t.x0; x < t.x1; ++x) dst.at(x, y) = src.at(x, y);
    });
}

/// Low-variance tiles along an axis of n pixels.
uint32_t skipTilesAlong(uint32_t n) {
    return (n + kSkipTile - 1) / kSkipTile;
}

ImageView<const glm::vec4> asConst(ImageView<glm::vec4> v) {
    return {v.data, v.width, v.height, v.rowPitch};
}

}  // namespace

bool AtrousFilter::ensureLayout(int maxStep) {
    const simd::PlaneLayout want = simd::makeLayout(mWidth, mHeight, maxStep);
    if (!mPlaneStorage.empty() && mLayout.width == mWidth && mLayout.height == mHeight &&
        mLayout.margin >= want.margin && (mSlots < 2 || mSignal[1][0].r))
        return false;
    mLayout = want;
    const size_t plane = mLayout.planeSize();
    const int count = kGuidePlanes + 2 * kSignalPlanes * mSlots;
    mPlaneStorage.release();  // before the new allocation: the two need not fit at once
    mPlaneStorage = PageMemory(plane * size_t(count) * sizeof(float));  // zeroed, 64-byte aligned at least
    float* base = reinterpret_cast<float*>(mPlaneStorage.data());
    auto planeAt = [&](int i) { return base + plane * size_t(i); };
    mGuide = {planeAt(0), planeAt(1), planeAt(2), planeAt(3), planeAt(4)};
    for (int slot = 0; slot < 2; ++slot)
        for (int s = 0; s < 2; ++s) {
            if (slot >= mSlots) {
                mSignal[slot][s] = {};
                continue;
            }
            const int first = kGuidePlanes + (slot * 2 + s) * kSignalPlanes;
            mSignal[slot][s] = {planeAt(first), planeAt(first + 1), planeAt(first + 2), planeAt(first + 3),
                                planeAt(first + 4)};
        }
    // Margins read as misses; the interior is overwritten by every packGuide.
    std::fill(mGuide.z, mGuide.z + plane, -1.f);
    return true;
}

void AtrousFilter::packGuide() {
    const auto t0 = std::chrono::steady_clock::now();
    if (mWidth > 0 && mHeight > 0) simd::packGuide(mLayout, mLinearZ, mNormal, mGuide);
    mGuideMs = msSince(t0);
}

void AtrousFilter::setGuide(ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal) {
    mLinearZ = linearZ;
    mNormal = normal;
    mWidth = linearZ.width;
    mHeight = linearZ.height;
    ensureLayout(std::max(kDefaultMaxStep, mLayout.margin > 0 ? int(mLayout.margin / 2) : 0));
    packGuide();
    mSignalPacked[0] = mSignalPacked[1] = false;
}

AtrousFilter::FramePlanes AtrousFilter::preparePlanes(ImageView<const glm::vec2> linearZ,
                                                      ImageView<const glm::vec4> normal, int iterations,
                                                      int signals) {
    mLinearZ = linearZ;
    mNormal = normal;
    mWidth = linearZ.width;
    mHeight = linearZ.height;
    mSlots = std::max(mSlots, std::clamp(signals, 1, 2));
    const int maxStep = 1 << std::clamp(iterations - 1, 0, 30);
    ensureLayout(std::max({kDefaultMaxStep, maxStep, mLayout.margin > 0 ? int(mLayout.margin / 2) : 0}));
    mGuideMs = 0.0;
    mSignalPacked[0] = true;
    mSignalPacked[1] = signals >= 2;
    return {&mLayout, mGuide, mSignal[0][0], signals >= 2 ? mSignal[1][0] : simd::SignalPlanes{}};
}

uint32_t AtrousFilter::classifyTiles(ImageView<const glm::vec4> src, const AtrousParams& params) {
    const float limit = params.skipRelVariance;
    if (!(limit > 0.f)) return 0;  // off: no flags, and the levels read none
    mSkipTilesPerRow = skipTilesAlong(mWidth);
    mSkipTiles.assign(size_t(mSkipTilesPerRow) * skipTilesAlong(mHeight), 0);
    // One tile per task: each writes its own flag, so the result does not depend on the threads.
    parallelFor2D(
        mWidth, mHeight,
        [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x) {
                    if (!(mLinearZ.at(x, y).x >= 0.f)) continue;  // misses keep their input anyway
                    const glm::vec4 p = src.at(x, y);
                    const float l = luminance(glm::vec3(p));
                    // Not below (NaN included): the tile is filtered.
                    if (!(p.a < limit * l * l)) return;
                }
            mSkipTiles[size_t(t.y0 / kSkipTile) * mSkipTilesPerRow + t.x0 / kSkipTile] = 1;
        },
        kSkipTile, kSkipTile);
    return uint32_t(std::count(mSkipTiles.begin(), mSkipTiles.end(), uint8_t(1)));
}

void AtrousFilter::run(ImageView<const glm::vec4> src, ImageView<glm::vec4> dst, int iterations,
                       const AtrousParams& params, int feedbackTap, ImageView<glm::vec4> feedback, bool reference,
                       AtrousTimings* timings, const simd::Remodulation* modulate, int slot) {
    const bool wantsFeedback = feedback.data != nullptr;
    slot = std::clamp(slot, 0, 1);
    bool packed = std::exchange(mSignalPacked[slot], false);
    mSlots = std::max(mSlots, slot + 1);  // a second signal's planes are allocated by ensureLayout below
    if (timings) *timings = AtrousTimings{};
    const uint32_t skipped = iterations > 0 ? classifyTiles(src, params) : 0;
    if (timings) {
        timings->skippedTiles = skipped;
        timings->tiles = skipTilesAlong(mWidth) * skipTilesAlong(mHeight);
    }
    const uint8_t* skipTiles = skipped ? mSkipTiles.data() : nullptr;
    if (iterations <= 0) {
        copyImage(src, dst);
        if (wantsFeedback) copyImage(src, feedback);
        return;
    }
    if (wantsFeedback && feedbackTap < 0) copyImage(src, feedback);
    const int tap = feedbackTap >= iterations ? iterations - 1 : feedbackTap;

    if (reference) {
        if (mPing.width() != mWidth || mPing.height() != mHeight) {
            mPing = Texture(mWidth, mHeight, Format::RGBA32F);
            mPong = Texture(mWidth, mHeight, Format::RGBA32F);
        }
        ImageView<const glm::vec4> in = src;
        for (int level = 0; level < iterations; ++level) {
            const auto t0 = std::chrono::steady_clock::now();
            const bool last = level == iterations - 1;
            ImageView<glm::vec4> out = last ? dst : (level % 2 == 0 ? mPing : mPong).view<glm::vec4>();
            const int step = 1 << level;
            parallelFor2D(mWidth, mHeight, [&](const Tile& t) {
                for (uint32_t y = t.y0; y < t.y1; ++y)
                    for (uint32_t x = t.x0; x < t.x1; ++x)
                        out.at(x, y) = skipTiles && skipTiles[(y / kSkipTile) * mSkipTilesPerRow + x / kSkipTile]
                                           ? in.at(x, y)
                                           : atrousPixel(in, mLinearZ, mNormal, int(x), int(y), step, params);
            });
            if (wantsFeedback && level == tap) copyImage(asConst(out), feedback);
            in = asConst(out);
            if (timings && level < 16) timings->levelMs[level] = msSince(t0);
        }
        return;
    }

    const auto t0 = std::chrono::steady_clock::now();
    // Steps beyond 2^30 reach no further than 2^30 in any frame a float image can hold.
    const int maxStep = 1 << std::min(iterations - 1, 30);
    double guideMs = mGuideMs;
    if (ensureLayout(maxStep)) {
        packGuide();
        guideMs += mGuideMs;
        packed = false;
    }
    simd::SignalPlanes* signal = mSignal[slot];
    if (!packed) simd::packSignal(mLayout, src, signal[0]);
    if (timings) timings->prepareMs = guideMs + msSince(t0);

    for (int level = 0; level < iterations; ++level) {
        const auto t1 = std::chrono::steady_clock::now();
        const bool last = level == iterations - 1;
        simd::LevelOutputs out;
        out.skipTiles = skipTiles;
        out.skipTilesPerRow = mSkipTilesPerRow;
        if (!last) out.planes = signal[(level + 1) % 2];
        const bool feedbackHere = wantsFeedback && level == tap;
        if (last && modulate) {
            out.modulate = *modulate;
            out.variance = feedbackHere;
        } else if (last) {
            out.image[0] = dst;
        }
        if (feedbackHere) out.image[1] = feedback;
        simd::filterLevel(mLayout, mGuide, signal[level % 2], out, 1 << std::min(level, 30), params);
        if (timings && level < 16) timings->levelMs[level] = msSince(t1);
    }
}

}  // namespace loom::svgf
