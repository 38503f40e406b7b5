#pragma once
// SVGFPass's stages on a device other than the CPU (emulated, or cuda where SVGFDevice.cpp is compiled by nvcc):
// each one launch2D over the scalar LOOM_HD reference kernels (SVGFKernels.h, AtrousKernels.h), reading and writing
// only the views given, which are device views of graph fields (docs/KERNELS.md). The CPU keeps its Highway twins
// (TemporalSimd, AtrousSimd); these reproduce the reference stages of SVGFPass (referenceStages, referenceAtrous)
// bit for bit on the emulated device.
#include <cstdint>
#include <glm/glm.hpp>

#include "SVGFKernels.h"
#include "loom/Device.h"
#include "loom/Texture.h"

namespace loom::svgf::device {

/// Whether the launches below were compiled by nvcc: only then do they run on the cuda device.
bool launchesOnCuda();

/// Disabled filter: dst = the colour with non-finite channels as 0 (alpha 1 where not finite).
void passThrough(DeviceKind device, ImageView<const glm::vec4> color, ImageView<glm::vec4> dst);

/// The anti-lag's shading change (antilagChange of the gradient samples of the 3x3 blocks around each block),
/// written to every pixel of `change`. `samples` is scratch on the block grid (ceil(size / kGradientBlock)).
void antilag(DeviceKind device, ImageView<const glm::vec2> gradient, ImageView<glm::vec2> samples,
             ImageView<glm::vec2> change);

/// The history clamp's box (neighbourhoodPixel) of every pixel into `box`, with the demodulation albedo albedo (+
/// specAlbedo when given), formed per pixel as `temporal` forms it. v's colour, direct, indirect, emission and
/// linearZ are read; `box` must not alias them.
void neighbourhood(DeviceKind device, const TemporalViews& v, bool split, ImageView<const glm::vec4> albedo,
                   ImageView<const glm::vec4> specAlbedo, ImageView<glm::vec4> box);

/// Stage 1 (temporalPixel) for every pixel. With `specAlbedo`, the demodulation albedo albedo + specAlbedo is formed
/// per pixel in v.integrated0, which temporalPixel reads (v.albedo is ignored) before it writes its result there.
/// Returns how many colour samples were not finite (and rejected).
uint64_t temporal(DeviceKind device, TemporalViews v, const TemporalParams& p, ImageView<const glm::vec4> albedo,
                  ImageView<const glm::vec4> specAlbedo);

/// Stage 2 (varianceEstimatePixel) for every pixel.
void variance(DeviceKind device, const VarianceViews& v, const VarianceScales& scales, bool split);

/// The à-trous levels of one signal, as AtrousFilter::run's reference path: src -> ... -> dst, ping-ponging between
/// dst and `scratch` (neither may alias src, which stays unchanged); level `feedbackTap` (clamped to the last; < 0:
/// src itself) is copied to `feedback` when given. Low-variance tiles (params.skipRelVariance) keep src at every
/// level.
void atrous(DeviceKind device, ImageView<const glm::vec4> src, ImageView<glm::vec4> dst, ImageView<glm::vec4> scratch,
            ImageView<const glm::vec2> linearZ, ImageView<const glm::vec4> normW, int iterations,
            const AtrousParams& params, int feedbackTap, ImageView<glm::vec4> feedback);

/// Stage 4 (modulatePixel) for every pixel, by albedo (+ specAlbedo when given: formed per pixel in v.dst, which
/// modulatePixel reads before it writes the result there; v.albedo is then ignored); and the debug history length
/// (lengthOut, when given) copied from `length`.
void modulate(DeviceKind device, ModulateViews v, bool split, ImageView<const glm::vec4> albedo,
              ImageView<const glm::vec4> specAlbedo, ImageView<float> lengthOut, ImageView<const float> length);

}  // namespace loom::svgf::device
