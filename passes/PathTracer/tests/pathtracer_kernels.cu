// Compile-only check (nvcc -x cu): the path tracer's kernel headers are device code.
#include "../BRDF.h"
#include "../PathTracerKernels.h"

namespace {
struct DeviceTracer {
    __host__ __device__ loom::RayHit intersect(glm::vec3, glm::vec3) const { return {}; }
    __host__ __device__ bool occluded(glm::vec3, glm::vec3, float, float) const { return false; }
};
}  // namespace

__global__ void tracePaths(loom::SceneView scene, loom::pt::LightsView lights, loom::pt::PathTracerSettings set,
                           glm::vec3* out) {
    loom::pt::PathRng rng(threadIdx.x, 0, 0);
    const auto r = loom::pt::tracePath(DeviceTracer{}, scene, lights, set, glm::vec3(0.f), glm::vec3(0.f, 0.f, -1.f),
                                       loom::RayHit{}, rng);
    const loom::pt::BrdfInputs in{glm::vec3(0.5f), 0.f, 0.5f};
    const auto s = loom::pt::sampleBrdf(in, glm::vec3(0, 0, 1), glm::vec3(0, 0, 1), glm::vec2(0.5f), 0.5f);
    out[threadIdx.x] = r.color + s.weight + loom::pt::evalBrdf(in, glm::vec3(0, 0, 1), glm::vec3(0, 0, 1), s.wi) +
                       glm::vec3(loom::pt::pdfBrdf(in, glm::vec3(0, 0, 1), glm::vec3(0, 0, 1), s.wi));
}
