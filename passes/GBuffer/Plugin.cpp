// The G-buffer plugin: GBufferRT (Embree on the CPU, the BVH on devices) and GBufferRaster (OpenGL).
#include "loom/Plugin.h"

#include "GBufferRT.h"
#include "GBufferRaster.h"

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::GBufferRT>(
        "GBufferRT",
        "G-buffer channels (posW, normW, linearZ, mvec, albedo, vbuffer, ...) from primary rays: Embree on the CPU, "
        "the scene BVH on emulated and cuda.");
    registrar.registerPass<loom::GBufferRaster>(
        "GBufferRaster",
        "G-buffer channels rasterized with OpenGL 4.5 (headless EGL); only consumed channels are drawn.");
}
