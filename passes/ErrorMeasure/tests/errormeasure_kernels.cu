// Compile-only check (nvcc -x cu): ErrorMeasure's kernel header and the metric terms it runs on a device are device
// code.
#include "../ErrorMeasureKernels.h"
#include "loom/MetricKernels.h"

__global__ void measure(const float* table, const glm::vec4* test, const glm::vec4* ref, glm::vec4* dst, double* out) {
    using namespace loom;
    const unsigned i = threadIdx.x;
    dst[i] = errormeasure::zeroNonFinite(test[i]);
    const MetricSums s =
        addMetricSums(addMetricSums(relMseTerm(test[i], ref[i]), smapeTerm(test[i], ref[i])),
                      addMetricSums(psnrTerm(table, test[i], ref[i]), temporalTerm(test[i], ref[i], ref[i], test[i])));
    out[i] = s.sum + double(s.count + s.nonFinite);
}
