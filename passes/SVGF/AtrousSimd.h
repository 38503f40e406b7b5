#pragma once
// The vectorised à-trous level (Google Highway, dispatched at run time to the CPU's best target) behind AtrousFilter's
// fast path. Everything works on float planes (structure of arrays) with a margin of off-frame columns on both sides,
// so every tap of the interior loop is an unconditional unaligned load: off-frame columns read as miss pixels (depth
// -1) and drop out through the same mask as real misses. Off-frame rows are skipped per row (uniform for a whole
// vector).
//
// Approximations against the scalar reference (atrousPixel), with their bounds:
// - one exponential per tap: the depth, luminance and normal terms and the B3 weight (log2 h) are summed, negative,
//   as a power of two u, and 2^u = 2^floor(u) * q(u - floor(u)), q a degree-4 polynomial on [0, 1) (relative error
//   <= 2.7e-6). u is clamped to -100: a weight the reference makes smaller than 2^-100 (8e-31) stays at that,
//   invisible unless a neighbour is brighter than ~1e25. Miss and off-frame taps are masked to exactly 0.
// - the normal weight max(0, n_p.n_q)^phi, for phi >= kWeightSeriesMinPhi: exp(-phi * (d + d^2/2 + d^3/3 + d^4/4)),
//   d = 1 - n_p.n_q, the first four terms of -ln(1 - d); its absolute error is <= 3.2e-6 over d in [0, 2] for
//   phi >= 32 (<= 1.5e-8 at the default 128). The dot product is contracted into FMAs (a rounding from the
//   reference's).
//   Smaller phi use exp2(phi * log2(max(dot, 1e-30))) with Highway's log2 (a few ulp).
// - the five depth scales of a centre, log2(e) / (phiZ |(i, j)| + eps), as log2(e) / (phiZ + eps) / |(i, j)|
//   (relative difference below 1e-6 for phiZ >= 1e-4).
// Each weight is within ~1e-5 relative of the reference; rgb and variance, ratios of weighted sums, agree to
// 3.7e-6 relative over 1-5 levels in tests/integration/test_atrous.cpp, which asserts 3e-5.
//
// Bad input: non-finite illumination values become 0 and magnitudes are clamped to 1e30 (no sums overflow);
// non-finite depth counts as a miss; non-finite or negative depth derivatives and non-finite normals become 0.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <glm/glm.hpp>
#include <string>

#include "AtrousKernels.h"
#include "SVGFKernels.h"
#include "loom/KernelMath.h"
#include "loom/Texture.h"

namespace loom::svgf::simd {

/// Shape of every plane: pixel (x, y) at y * stride + margin + x. The margin (left; the right one is margin +
/// kMaxLanes, the widest vector: loom/KernelMath.h) covers taps up to `margin` columns off-frame; taps further out
/// are off-frame for every pixel of the row and are skipped.
struct PlaneLayout {
    uint32_t width = 0, height = 0;
    uint32_t margin = 0;
    size_t stride = 0;

    size_t offset(uint32_t x, uint32_t y) const { return size_t(y) * stride + margin + x; }
    size_t planeSize() const { return stride * height; }
};

/// A layout for width x height that covers taps up to 2 * maxStep columns off-frame.
PlaneLayout makeLayout(uint32_t width, uint32_t height, int maxStep);

/// Per-frame guide planes: depth (-1 on a miss and in the margins), its derivative, the normal.
struct GuidePlanes {
    float* z = nullptr;
    float* dz = nullptr;
    float* nx = nullptr;
    float* ny = nullptr;
    float* nz = nullptr;
};

/// One signal: rgb, variance and luminance planes (zero in the margins).
struct SignalPlanes {
    float* r = nullptr;
    float* g = nullptr;
    float* b = nullptr;
    float* v = nullptr;
    float* l = nullptr;
};

/// Illumination magnitudes are clamped to this in the planes (no weighted sum overflows).
inline constexpr float kMagnitudeLimit = 1e30f;

inline float sanitiseScalar(float v) {
    return std::isfinite(v) ? std::clamp(v, -kMagnitudeLimit, kMagnitudeLimit) : 0.f;
}

/// One pixel of packGuide: depth (-1 unless finite and >= 0), derivative (0 unless finite and > 0), normal
/// (non-finite components 0). The vector loops compute the same values.
inline void packGuidePixel(const PlaneLayout& L, const GuidePlanes& G, uint32_t x, uint32_t y, glm::vec2 z,
                           const glm::vec4& n) {
    const size_t o = L.offset(x, y);
    G.z[o] = std::isfinite(z.x) && z.x >= 0.f ? z.x : -1.f;
    G.dz[o] = std::isfinite(z.y) && z.y > 0.f ? z.y : 0.f;
    G.nx[o] = std::isfinite(n.x) ? n.x : 0.f;
    G.ny[o] = std::isfinite(n.y) ? n.y : 0.f;
    G.nz[o] = std::isfinite(n.z) ? n.z : 0.f;
}

/// One pixel of packSignal: sanitised rgb and variance, and the luminance with the vector loops' operations.
inline void packSignalPixel(const PlaneLayout& L, const SignalPlanes& S, uint32_t x, uint32_t y, const glm::vec4& p) {
    const size_t o = L.offset(x, y);
    S.r[o] = sanitiseScalar(p.r);
    S.g[o] = sanitiseScalar(p.g);
    S.b[o] = sanitiseScalar(p.b);
    S.v[o] = sanitiseScalar(p.a);
    S.l[o] = luminanceFma(S.r[o], S.g[o], S.b[o]);
}

/// Writes the guide planes' interior from linearZ (x: depth, y: derivative) and normal (xyz).
void packGuide(const PlaneLayout& layout, ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normal,
               const GuidePlanes& guide);

/// Writes a signal's interior planes from rgb + variance pixels (sanitised, luminance computed).
void packSignal(const PlaneLayout& layout, ImageView<const glm::vec4> src, const SignalPlanes& dst);

/// Remodulation fused into a level's output: modulatePixel() of SVGFKernels.h with the level's rgb as the last
/// filtered signal: views.filtered0, or with `split` views.filtered1 (filtered0, read from its view, is added first).
/// views.filtered1 is not read.
struct Remodulation {
    ModulateViews views;
    bool split = false;
    /// Optional (the temporal stage's TemporalOutputs::remodulationGroups of this frame): for each group of
    /// kRemodulationGroup pixels of a row, groupsPerRow to a row, which images its remodulation reads
    /// (kReadsColour, kReadsAlbedo, kReadsEmission). Null: all of them.
    const uint8_t* groups = nullptr;
    size_t groupsPerRow = 0;
};

/// Remodulation::groups: pixels x of a row in group x / kRemodulationGroup (the widest vector: a narrower one reads
/// its group's flags, which cover it).
inline constexpr uint32_t kRemodulationGroup = kMaxLanes;
inline uint32_t remodulationGroupsPerRow(uint32_t width) {
    return (width + kRemodulationGroup - 1) / kRemodulationGroup;
}
/// What a group's remodulation reads: the colour for a miss (passed through) or an alpha other than 1 (split:
/// always, the temporal stage does not read the colour there); the albedo for a hit; the emission for a hit that
/// has some. Half the default scene's pixels are sky: their groups read the colour alone; the rest mostly the albedo
/// alone. Hits and misses could be told from the depth the remodulation loads, but the prefetch of the next row's
/// inputs decides before any of it is loaded, so the flags carry them too.
inline constexpr uint8_t kReadsColour = 1, kReadsAlbedo = 2, kReadsEmission = 4, kReadsAll = 7;

/// The flags of one pixel, as remodulate() reads (non-finite emission counts as 0).
inline uint8_t remodulationReads(ImageView<const glm::vec4> color, ImageView<const glm::vec4> emission,
                                 ImageView<const glm::vec2> linearZ, bool split, uint32_t x, uint32_t y) {
    const bool hit = linearZ.at(x, y).x >= 0.f;
    uint8_t reads = (split || !hit || !(color.at(x, y).a == 1.f)) ? kReadsColour : 0;
    if (hit) reads |= kReadsAlbedo;
    if (hit && emission.data && finiteOrZero(glm::vec3(emission.at(x, y))) != glm::vec3(0.f)) reads |= kReadsEmission;
    return reads;
}

/// Where one level writes: its planes (skipped when planes.r is null), up to two rgb + variance images, and the
/// remodulated result (skipped when modulate.views.dst is null). variance = false: nobody reads the level's variance,
/// so it is not propagated (planes and images then receive 0 in its place).
struct LevelOutputs {
    SignalPlanes planes;
    ImageView<glm::vec4> image[2];
    Remodulation modulate;
    bool variance = true;
    /// Optional: one flag per kSkipTile x kSkipTile tile (row-major, skipTilesPerRow to a row); a set flag makes
    /// the tile's pixels keep their input, as miss pixels do (AtrousParams::skipRelVariance).
    const uint8_t* skipTiles = nullptr;
    uint32_t skipTilesPerRow = 0;
};

/// Whether the guide's planes (z, dz, nx, ny, nz) and the signal's (r, g, b, v, l) each follow one another
/// layout.planeSize() floats apart, as AtrousFilter allocates them: a tap then addresses all of them from two
/// pointers.
inline bool planesEvenlySpaced(const PlaneLayout& layout, const GuidePlanes& g, const SignalPlanes& s) {
    const size_t P = layout.planeSize();
    return g.dz == g.z + P && g.nx == g.z + 2 * P && g.ny == g.z + 3 * P && g.nz == g.z + 4 * P && s.g == s.r + P &&
           s.b == s.r + 2 * P && s.v == s.r + 3 * P && s.l == s.r + 4 * P;
}

/// One à-trous level with tap spacing `step` from `in` to `out`; the planes of `guide` and of `in` must be evenly
/// spaced (planesEvenlySpaced), else it throws std::invalid_argument.
void filterLevel(const PlaneLayout& layout, const GuidePlanes& guide, const SignalPlanes& in, const LevelOutputs& out,
                 int step, const AtrousParams& params);

/// The instruction set the dispatcher chose on this CPU (e.g. "AVX2", "AVX3" for AVX-512).
std::string targetName();

}  // namespace loom::svgf::simd
