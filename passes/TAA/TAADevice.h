#pragma once
// TAAPass off the host (docs/KERNELS.md): on the emulated and cuda devices the reference kernel (resolvePixel and
// outputColor of TAAKernels.h) runs through launch2D over device views, and the frame's pixel counts come from
// reduceRows. The CPU keeps its tiled vector path (TAASimd.h). TAADevice.cpp is compiled by nvcc where the CUDA
// toolkit is found, by the host compiler otherwise.
#include "TAAKernels.h"
#include "TAASimd.h"
#include "loom/Device.h"
#include "loom/Texture.h"

namespace loom::taa {

/// Whether the device path runs on `device`: emulated always, cuda where nvcc compiled it.
bool deviceRuns(DeviceKind device);

/// One frame on `device`: colorOut and this frame's history from colorIn, mvec and last frame's history (all on
/// the device), with the frame's pixel counts.
Counts resolveOnDevice(DeviceKind device, const TaaParams& params, bool historyValid, bool compress,
                       const Texture& colorIn, const Texture& mvec, const Texture& historyPrev, Texture& colorOut,
                       Texture& historyCur);

}  // namespace loom::taa
