#include "loom/Parallel.h"

#include <tbb/blocked_range2d.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#if defined(__SSE__) || defined(_M_X64)
#include <xmmintrin.h>
#define LOOM_HAVE_MXCSR 1
#endif

namespace loom {

namespace {

/// Flush-to-zero and denormals-are-zero for the scope of a task (see Parallel.h), the previous mode restored after.
class FlushDenormals {
public:
#ifdef LOOM_HAVE_MXCSR
    FlushDenormals() : mSaved(_mm_getcsr()) { _mm_setcsr(mSaved | kFtz | kDaz); }
    ~FlushDenormals() { _mm_setcsr(mSaved); }

private:
    static constexpr unsigned kFtz = 0x8000, kDaz = 0x0040;
    unsigned mSaved;
#endif
};

}  // namespace

void parallelFor2D(uint32_t width, uint32_t height, const std::function<void(const Tile&)>& fn, uint32_t tileSize) {
    parallelFor2D(width, height, fn, tileSize, tileSize);
}

void parallelFor2D(uint32_t width, uint32_t height, const std::function<void(const Tile&)>& fn, uint32_t tileWidth,
                   uint32_t tileHeight) {
    if (width == 0 || height == 0) return;
    const uint32_t tilesX = (width + tileWidth - 1) / tileWidth;
    const uint32_t tilesY = (height + tileHeight - 1) / tileHeight;
    // Tiles are fixed by the image size alone (not by the scheduler), so the
    // work each call sees is the same for any thread count.
    tbb::parallel_for(
        tbb::blocked_range2d<uint32_t>(0, tilesY, 1, 0, tilesX, 1),
        [&](const tbb::blocked_range2d<uint32_t>& r) {
            const FlushDenormals flush;
            for (uint32_t ty = r.rows().begin(); ty < r.rows().end(); ++ty)
                for (uint32_t tx = r.cols().begin(); tx < r.cols().end(); ++tx) {
                    Tile t{tx * tileWidth, ty * tileHeight, std::min(width, (tx + 1) * tileWidth),
                           std::min(height, (ty + 1) * tileHeight)};
                    fn(t);
                }
        },
        tbb::simple_partitioner());
}

ThreadLimit::ThreadLimit(unsigned threads) {
    if (threads > 0)
        mControl = new tbb::global_control(tbb::global_control::max_allowed_parallelism, threads);
}

ThreadLimit::~ThreadLimit() { delete static_cast<tbb::global_control*>(mControl); }

}  // namespace loom
