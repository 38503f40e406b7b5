// Compile check (nvcc, no GPU needed): launch2D and reduceRows instantiate as CUDA grids from the same functors the
// CPU runs (docs/KERNELS.md).
#include <glm/glm.hpp>

#include "loom/Launch.h"
#include "loom/Texture.h"

namespace loom {

void launchCheck(DeviceKind device, ImageView<glm::vec4> dst, ImageView<const glm::vec4> a, float scale) {
    launch2D(device, dst.width, dst.height, [=] LOOM_HD(uint32_t x, uint32_t y) { dst.at(x, y) = a.at(x, y) * scale; });
}

float reduceCheck(DeviceKind device, ImageView<const float> v) {
    return reduceRows(
        device, v.width, v.height, 0.f, [=] LOOM_HD(uint32_t x, uint32_t y) { return v.at(x, y); },
        [] LOOM_HD(float s, float t) { return s + t; });
}

}  // namespace loom
