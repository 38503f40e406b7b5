// The path tracer plugin: PathTracer, also registered as CUDAPathTracer.
#include "PathTracer.h"
#include "loom/Plugin.h"

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::PathTracer>(
        "PathTracer", "Unidirectional path tracer: glTF BRDF, NEE with MIS over emissive triangles, punctual lights "
                      "and the environment, Russian roulette.");
    registrar.registerPass<loom::PathTracer>(
        "CUDAPathTracer", "The PathTracer under its Falcor name; `device` picks CUDA where usable, else the CPU.");
}
