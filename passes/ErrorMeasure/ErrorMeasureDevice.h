#pragma once
// ErrorMeasure off the host (docs/KERNELS.md): on the emulated and cuda devices, dst (zeroNonFinite), the history
// copies, the cleared error image and the metrics RelMSE, SMAPE, PSNR and temporal error (loom/MetricKernels.h,
// the functions and the row order of the CPU's, so the stats agree bit for bit) run through launch2D and reduceRows
// over device views only. SSIM and FLIP, whose separable filters and planes stay CPU code, are left to the pass: it
// runs them on host copies (ErrorMeasurePass.cpp). ErrorMeasureDevice.cpp is compiled by nvcc where the CUDA
// toolkit is found, by the host compiler otherwise.
#include "loom/Device.h"
#include "loom/MetricKernels.h"
#include "loom/Texture.h"

namespace loom::errormeasure {

/// Whether the device path runs on `device`: emulated always, cuda where nvcc compiled it.
bool deviceRuns(DeviceKind device);

/// dst = zeroNonFinite(src), pixel by pixel (RGBA32F, both on `device`).
void zeroNonFiniteOnDevice(DeviceKind device, const Texture& src, Texture& dst);
/// dst = src (RGBA32F, both on `device`): the history copies.
void copyOnDevice(DeviceKind device, const Texture& src, Texture& dst);
/// Every pixel of an R32F texture on `device` set to 0.
void clearOnDevice(DeviceKind device, Texture& image);

/// The tone map table of the LDR metrics (ldrToneMapTable) copied into the memory of `device` (kOetfTableSize x 1,
/// R32F).
Texture uploadToneMapTable(DeviceKind device);

/// The sums of a metric over images on `device`; `error`, where given (R32F on `device`), receives the per-pixel
/// error image. `table` is uploadToneMapTable's texture.
MetricSums relMseOnDevice(DeviceKind device, const Texture& test, const Texture& ref, Texture* error);
MetricSums smapeOnDevice(DeviceKind device, const Texture& test, const Texture& ref, Texture* error);
MetricSums psnrOnDevice(DeviceKind device, const Texture& table, const Texture& test, const Texture& ref,
                        Texture* error);
MetricSums temporalOnDevice(DeviceKind device, const Texture& test, const Texture& testPrev, const Texture& ref,
                            const Texture& refPrev);

}  // namespace loom::errormeasure
