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
void parallelFor2D(uint32_t width, uint32_t height, const std::function<void(const Tile&)>& fn,
                   uint32_t tileSize = kDefaultTileSize);

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
