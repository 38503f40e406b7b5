#pragma once
// The tiled CPU path of TAAPass and what it shares with the pass: tiles, counts, the reference kernel over a tile.
// The vector code (TAASimd.cpp, Google Highway) is compiled for AVX2 (the x86-64-v3 baseline) and AVX-512 and
// dispatched at run time to the best the CPU has.
#include <cstdint>

#include "TAAKernels.h"
#include "loom/KernelMath.h"
#include "loom/Parallel.h"
#include "loom/Texture.h"

namespace loom::taa {

// Tiles of 128 x 16 pixels: rows long enough (2 KiB of colour) for the hardware prefetchers to stream, few enough
// rows that the tile's scratch stays in L2.
inline constexpr uint32_t kTileW = 128, kTileH = 16;
// Whole vectors of every target: a pixel's arithmetic does not depend on where its tile ends.
static_assert(kTileW % kMaxLanes == 0, "the tile width must be a multiple of the widest vector");

/// Pixel counts of one tile or frame.
struct Counts {
    uint64_t nonFinite = 0, noHistory = 0, clipped = 0;
    void add(uint32_t flags) {
        nonFinite += (flags & kNonFiniteInput) != 0;
        noHistory += (flags & kNoHistory) != 0;
        clipped += (flags & kClipped) != 0;
    }
};

/// The reference kernel over one tile.
inline void resolveTileReference(const TaaInputs& in, const TaaParams& p, const Tile& t,
                                 const ImageView<glm::vec4>& out, const ImageView<glm::vec4>& history, Counts& counts) {
    for (uint32_t y = t.y0; y < t.y1; ++y)
        for (uint32_t x = t.x0; x < t.x1; ++x) {
            uint32_t flags = 0;
            const glm::vec4 c = resolvePixel(in, p, x, y, flags);
            out.at(x, y) = outputColor(in.compress, c, in.color.at(int(x), int(y)));
            history.at(x, y) = c;
            counts.add(flags);
        }
}

/// The tiled vector path over one tile (tiles of at most kTileW x kTileH pixels); agrees with
/// resolveTileReference to a tolerance (tests/integration/test_taa.cpp).
void resolveTileVector(const TaaInputs& in, const TaaParams& p, const Tile& t, const ImageView<glm::vec4>& out,
                       const ImageView<glm::vec4>& history, Counts& counts);

/// Floats per vector of the target resolveTileVector runs on now (8: AVX2, 16: AVX-512).
uint32_t vectorLanes();

}  // namespace loom::taa
