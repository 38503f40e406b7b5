#pragma once
// The one way to spread per-pixel work over threads.
#include <cstdint>
#include <functional>

namespace loom {

/// A rectangle of pixels [x0, x1) x [y0, y1).
struct Tile {
    uint32_t x0, y0, x1, y1;
};

inline constexpr uint32_t kDefaultTileSize = 32;

/// Runs fn over tiles covering width x height, in parallel on oneTBB. Each
/// pixel is visited exactly once; which thread runs a tile never changes the
/// result as long as fn writes only pixels of its tile.
///
/// fn runs with denormal floats flushed to zero (x86 FTZ and DAZ): a result or
/// an input below 1.2e-38 in magnitude counts as 0. Filters whose weights fall
/// off exponentially (SVGF's à-trous, bilateral tests) produce such values at
/// every edge, and each one costs the CPU a microcode assist (BM_DenormalProducts
/// in loom_bench_core measures the difference). Every thread
/// runs every tile in the same mode, so results stay identical for any thread
/// count.
void parallelFor2D(uint32_t width, uint32_t height, const std::function<void(const Tile&)>& fn,
                   uint32_t tileSize = kDefaultTileSize);

/// The same over tiles of tileWidth x tileHeight pixels (long rows for row-streaming kernels, say).
void parallelFor2D(uint32_t width, uint32_t height, const std::function<void(const Tile&)>& fn, uint32_t tileWidth,
                   uint32_t tileHeight);

/// Per-pixel convenience form: fn(x, y).
template <class Fn>
void parallelForPixels(uint32_t width, uint32_t height, Fn&& fn, uint32_t tileSize = kDefaultTileSize) {
    parallelFor2D(
        width, height,
        [&](const Tile& t) {
            for (uint32_t y = t.y0; y < t.y1; ++y)
                for (uint32_t x = t.x0; x < t.x1; ++x) fn(x, y);
        },
        tileSize);
}

/// Limits the worker threads for the lifetime of the object (0 = all cores).
class ThreadLimit {
public:
    explicit ThreadLimit(unsigned threads);
    ~ThreadLimit();
    ThreadLimit(const ThreadLimit&) = delete;
    ThreadLimit& operator=(const ThreadLimit&) = delete;

private:
    void* mControl = nullptr;
};

}  // namespace loom
