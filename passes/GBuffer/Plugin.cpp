// The G-buffer plugin: GBufferRT (Embree) and GBufferRaster (OpenGL).
#include "GBufferRT.h"
#include "GBufferRaster.h"
#include "loom/Plugin.h"

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::GBufferRT>(
        "GBufferRT", "G-buffer channels (posW, normW, linearZ, mvec, albedo, vbuffer, ...) from Embree primary rays.");
    registrar.registerPass<loom::GBufferRaster>(
        "GBufferRaster", "G-buffer channels rasterized with OpenGL 4.5 (headless EGL); only consumed channels are drawn.");
}
