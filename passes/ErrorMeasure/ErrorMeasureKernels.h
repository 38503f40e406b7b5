#pragma once
// ErrorMeasure's own per-pixel math (the metrics' is in loom/MetricKernels.h): plain LOOM_HD functions, the same on
// the CPU and on a device (docs/KERNELS.md).
#include <glm/glm.hpp>

#include "loom/KernelMath.h"

namespace loom::errormeasure {

/// dst's pixel: src's, except that a non-finite channel becomes 0 (no output of Loom carries NaN or Inf on).
LOOM_HD inline glm::vec4 zeroNonFinite(glm::vec4 v) {
    for (int c = 0; c < 4; ++c)
        if (!isFinite(v[c])) v[c] = 0.f;
    return v;
}

}  // namespace loom::errormeasure
