// The G-buffer plugin: GBufferRT (Embree) and GBufferRaster (OpenGL).
#include "GBufferRT.h"
#include "loom/Plugin.h"
#if __has_include("GBufferRaster.h")
#include "GBufferRaster.h"
#define LOOM_HAS_GBUFFER_RASTER 1
#endif

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::GBufferRT>(
        "GBufferRT", "G-buffer channels (posW, normW, linearZ, mvec, albedo, vbuffer, ...) from Embree primary rays.");
#ifdef LOOM_HAS_GBUFFER_RASTER
    registrar.registerPass<loom::GBufferRaster>(
        "GBufferRaster", "G-buffer channels rasterized with OpenGL 4.5 (headless EGL); only consumed channels are drawn.");
#endif
}
