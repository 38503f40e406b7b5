#pragma once
// ImageSequence off the host (docs/KERNELS.md): the frames are read and converted on the host, and each output is
// uploaded into device memory with copyTexture. ImageSequenceDevice.cpp is compiled by nvcc where the CUDA toolkit is
// found, so that the pass runs on cuda exactly where the passes with kernels do.
#include "loom/Device.h"

namespace loom::sequence {

/// Whether the pass runs on `device`: emulated always, cuda where nvcc compiled ImageSequenceDevice.cpp.
bool deviceRuns(DeviceKind device);

}  // namespace loom::sequence
