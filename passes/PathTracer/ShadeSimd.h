#pragma once
// The CPU path tracer's vertex shading for several paths at once: shadeVertex() (PathTracerKernels.h) with the BRDF
// work — the vertex's local frame and lobe terms, the light sample's BRDF value and pdf, the BRDF sample and its
// weight, Russian roulette — done in SIMD registers, one path per lane. What is irregular per path (the surface
// evaluation, emission, random numbers, the light sample) stays scalar and shared with shadeVertex(). The model and
// the random numbers are the same; results agree with shadeVertex() to float rounding (not bit for bit: the vector
// code rounds in another order), and are identical for any thread count.
//
// CPU only (Highway, the static target of the build); the kernel header stays the reference a CUDA backend reuses.
#include <cstdint>

#include "PathTracerKernels.h"

namespace loom::pt {

/// Most paths one shadeVerticesSimd() call takes (the widest vector of any target, 16 floats).
inline constexpr uint32_t kMaxShadeLanes = 16;

/// Paths per call that fill the vectors of this build's target (8 with AVX2).
uint32_t shadeLanes();

/// Whether shadeVerticesSimd() implements these settings (MIS with the glTF BRDF; the validation modes — NEE or
/// BRDF sampling only, Lambert only — use shadeVertex()).
inline bool simdShadingSupports(const PathTracerSettings& set) {
    return set.lightSampling == kMis && !set.lambertOnly;
}

/// shadeVertex<F>(paths[idx[j]], hits[idx[j]], ...) for j in [0, count), count <= shadeLanes(); requests[j] receives
/// its return value. Requires simdShadingSupports(set). With skipIdle, a call where every path ended at this vertex
/// (misses, paths at their last bounce) does no vector work; the results are the same. Instantiated for F =
/// kAllFeatures and F = 0.
template <uint32_t F>
void shadeVerticesSimd(PathState* paths, const RayHit* hits, const uint32_t* idx, uint32_t count,
                       const SceneView& scene, const LightsView& lights, const PathTracerSettings& set,
                       uint32_t* requests, bool skipIdle = true);

}  // namespace loom::pt
