#pragma once
// AccumulatePass off the host (docs/KERNELS.md): on the emulated and cuda devices accumulatePixel
// (AccumulateKernels.h) runs through launch2D over device views, and the skipped samples are counted through
// reduceRows. AccumulateDevice.cpp is compiled by nvcc where the CUDA toolkit is found, by
// the host compiler otherwise.
#include <cstdint>

#include "AccumulateKernels.h"
#include "loom/Device.h"
#include "loom/Texture.h"

namespace loom::accumulate {

/// Whether the device path runs on `device`: emulated always, cuda where nvcc compiled it.
bool deviceRuns(DeviceKind device);

/// One frame over every pixel on `device` (accumulatePixel); returns the pixels whose sample was skipped.
uint64_t accumulateOnDevice(DeviceKind device, Precision precision, const FrameViews& views, bool reset,
                            bool addSamples);

/// The partial* outputs of a float or Kahan state (widenedSum), each where given.
void widenOnDevice(DeviceKind device, Precision precision, const Texture& sum, const Texture& sumExtra, Texture* rg,
                   Texture* ba);

/// Texel (0, 0) of the 1x1 R32U frame counter on the device, and its store.
uint32_t loadFrames(DeviceKind device, const Texture& frames);
void storeFrames(DeviceKind device, Texture& frames, uint32_t value);

}  // namespace loom::accumulate
