#pragma once
// Primary rays of a tile, traced as coherent 4x4 packets.
#include <cstdint>
#include <glm/glm.hpp>

#include "loom/CameraKernels.h"
#include "loom/Parallel.h"
#include "loom/RayScene.h"
#include "loom/SurfaceKernels.h"

namespace loom {

/// Traces the (unnormalised) camera ray of every pixel of a tile in 4x4
/// rtcIntersect16 packets under `rules` (RayRules) and calls fn(x, y, dir, hit)
/// per pixel. Stochastic transparency draws from cameraCoverageKey(x, y, frame)
/// as GBufferRaster does, so passes that trace camera rays by the same rules
/// agree with a vbuffer made by another pass.
template <class Fn>
void traceCameraRays(const RayScene& rays, const CameraData& cam, const Tile& tile, uint32_t rules, uint32_t frame,
                     Fn&& fn) {
    const bool keyed = (rules & kRayAlphaTest) && rays.hasAlphaTestedGeometry();  // keys matter to alpha filters only
    for (uint32_t by = tile.y0; by < tile.y1; by += 4) {
        for (uint32_t bx = tile.x0; bx < tile.x1; bx += 4) {
            glm::vec3 origins[16], dirs[16];
            bool valid[16];
            uint32_t keys[16];
            RayHit hits[16];
            for (uint32_t i = 0; i < 16; ++i) {
                const uint32_t x = bx + (i & 3u), y = by + (i >> 2);
                valid[i] = x < tile.x1 && y < tile.y1;
                origins[i] = cam.origin;
                dirs[i] = valid[i] ? pixelRayDir(cam, x, y) : glm::vec3(0.f, 0.f, 1.f);
                if (keyed) keys[i] = cameraCoverageKey(x, y, frame);
            }
            rays.intersect16(origins, dirs, valid, 1e30f, hits, rules, keyed ? keys : nullptr);
            for (uint32_t i = 0; i < 16; ++i)
                if (valid[i]) fn(bx + (i & 3u), by + (i >> 2), dirs[i], hits[i]);
        }
    }
}

}  // namespace loom
