#pragma once
// ToneMap off the host (docs/KERNELS.md): on the emulated and cuda devices the per-pixel kernels of
// ToneMapKernels.h run through launch2D and the frame's sums through reduceRows, over device views only. The CPU
// keeps its own vector path (ToneMap.cpp). ToneMapDevice.cpp is compiled by nvcc where the CUDA toolkit is found
//, by the host compiler otherwise.
#include <cstdint>
#include <glm/glm.hpp>

#include "ToneMapKernels.h"
#include "loom/Device.h"
#include "loom/Texture.h"

namespace loom::tonemap {

/// Whether the device path runs on `device`: emulated always, cuda where nvcc compiled it.
bool deviceRuns(DeviceKind device);

/// One frame's sums on the device: the log-luminance terms (logLuminance) of the finite pixels of every
/// `rowStep`-th row (none for rowStep 0) and their count, each row left to right, then the rows top to bottom;
/// and the pixels with a non-finite channel, over every row.
struct FrameSums {
    double logSum = 0.0;
    uint64_t logCount = 0;
    uint64_t nonFinite = 0;
};
FrameSums sumFrame(DeviceKind device, const Texture& src, uint32_t rowStep);

/// Texel (0, 0) of the 1x1 RGBA32F auto exposure state on the device, and its store.
glm::vec4 loadState(DeviceKind device, const Texture& state);
void storeState(DeviceKind device, Texture& state, const glm::vec4& value);

/// The sRGB table copied into the memory of `device` (a 4096 x 1 R32U texture).
Texture uploadSrgbTable(DeviceKind device, const SrgbEncodeTable& table);

/// Every pixel of src through toneMapPixel into dst (packSrgb8 with the device's table) and dstFloat (when given).
void mapFrame(DeviceKind device, const ToneMapParams& params, const Texture& srgbTable, const Texture& src,
              Texture& dst, Texture* dstFloat);

}  // namespace loom::tonemap
