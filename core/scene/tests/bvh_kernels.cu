// Compile-only check (nvcc -x cu): the BVH traversal (closest hit, any hit, alpha test, back faces) is device code.
#include "loom/BvhTraversal.h"

__global__ void traceRays(loom::BvhView view, const glm::vec3* origins, const glm::vec3* dirs, loom::RayHit* hits,
                          bool* occluded) {
    const unsigned i = threadIdx.x;
    hits[i] = loom::bvhIntersect(view, origins[i], dirs[i], 0.f, 1e30f, loom::kRayAlphaTest | loom::kRayCullBackFaces);
    occluded[i] = loom::bvhOccluded(view, origins[i], dirs[i], 0.f, hits[i].t);
}
