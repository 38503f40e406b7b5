// parallelFor2D: every pixel once, and the floating-point mode its tasks run in.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cfloat>
#include <vector>

#include "loom/Parallel.h"

namespace loom {
namespace {

TEST(Parallel, EveryPixelIsVisitedExactlyOnce) {
    const uint32_t w = 131, h = 77;
    std::vector<std::atomic<int>> visits(size_t(w) * h);
    parallelFor2D(
        w, h,
        [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x) ++visits[size_t(y) * w + x];
        },
        16);
    for (const auto& v : visits) ASSERT_EQ(v.load(), 1);
}

TEST(Parallel, RectangularTilesHaveTheAskedSize) {
    const uint32_t w = 300, h = 77, tw = 128, th = 16;
    std::vector<std::atomic<int>> visits(size_t(w) * h);
    std::atomic<int> tiles{0};
    parallelFor2D(
        w, h,
        [&](const Tile& t) {
            EXPECT_EQ(t.x0 % tw, 0u);
            EXPECT_EQ(t.y0 % th, 0u);
            EXPECT_EQ(t.x1, std::min(w, t.x0 + tw));
            EXPECT_EQ(t.y1, std::min(h, t.y0 + th));
            ++tiles;
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x) ++visits[size_t(y) * w + x];
        },
        tw, th);
    EXPECT_EQ(tiles.load(), 3 * 5);
    for (const auto& v : visits) ASSERT_EQ(v.load(), 1);
}

// Inside a task, denormal results are flushed to zero and denormal inputs read as zero (FTZ and DAZ), on every
// thread; the calling thread's own mode is restored after.
TEST(Parallel, TasksFlushDenormalsToZero) {
#if !(defined(__SSE__) || defined(_M_X64))
    GTEST_SKIP() << "flushing denormals is implemented for x86 only";
#endif
    volatile float small = FLT_MIN;  // the smallest normal float
    volatile float half = 0.5f;
    const float outside = small * half;  // a denormal here (the default mode)
    ASSERT_GT(outside, 0.f);
    volatile float denormal = outside;
    std::atomic<int> flushedResults{0}, zeroInputs{0}, tiles{0};
    parallelFor2D(
        64, 64,
        [&](const Tile&) {
            const float product = small * half;
            const float sum = denormal + 0.f;
            flushedResults += product == 0.f ? 1 : 0;
            zeroInputs += sum == 0.f ? 1 : 0;
            ++tiles;
        },
        8);
    EXPECT_EQ(flushedResults.load(), tiles.load());
    EXPECT_EQ(zeroInputs.load(), tiles.load());
    const float after = small * half;
    EXPECT_GT(after, 0.f) << "the caller's floating-point mode was not restored";
}

}  // namespace
}  // namespace loom
