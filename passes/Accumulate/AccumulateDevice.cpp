#include "AccumulateDevice.h"

#include "loom/Launch.h"

namespace loom::accumulate {

bool deviceRuns(DeviceKind device) {
#if defined(__CUDACC__)
    if (device == DeviceKind::Cuda) return true;
#endif
    return device == DeviceKind::Emulated;
}

template <Precision P>
void launchFrame(DeviceKind device, const FrameViews& v, bool reset, bool addSamples) {
    launch2D(device, v.dst.width, v.dst.height,
             [=] LOOM_HD(uint32_t x, uint32_t y) { accumulatePixel<P>(v, x, y, reset, addSamples); });
}

uint64_t accumulateOnDevice(DeviceKind device, Precision precision, const FrameViews& v, bool reset, bool addSamples) {
    switch (precision) {
        case Precision::Float:
            launchFrame<Precision::Float>(device, v, reset, addSamples);
            break;
        case Precision::Kahan:
            launchFrame<Precision::Kahan>(device, v, reset, addSamples);
            break;
        case Precision::Double:
            launchFrame<Precision::Double>(device, v, reset, addSamples);
            break;
    }
    if (!addSamples) return 0;
    // A sample added raises the pixel's count by one; a skipped one leaves it where the frame started.
    const auto prev = v.prevCount;
    const auto cur = v.curCount;
    return reduceRows(
        device, cur.width, cur.height, uint64_t(0),
        [=] LOOM_HD(uint32_t x, uint32_t y) { return uint64_t(cur.at(x, y) == (reset ? 0u : prev.at(x, y))); },
        [] LOOM_HD(uint64_t a, uint64_t b) { return a + b; });
}

void widenOnDevice(DeviceKind device, Precision precision, const Texture& sum, const Texture& sumExtra, Texture* rg,
                   Texture* ba) {
    const auto first = sum.deviceView<glm::uvec4>(), second = sumExtra.deviceView<glm::uvec4>();
    const auto rgView = rg ? rg->deviceView<glm::uvec4>() : ImageView<glm::uvec4>{};
    const auto baView = ba ? ba->deviceView<glm::uvec4>() : ImageView<glm::uvec4>{};
    launch2D(device, first.width, first.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
        glm::uvec4 a, b;
        widenedSum(precision, first.at(x, y), second.at(x, y), a, b);
        if (rgView.data) rgView.at(x, y) = a;
        if (baView.data) baView.at(x, y) = b;
    });
}

uint32_t loadFrames(DeviceKind device, const Texture& frames) {
    const auto v = frames.deviceView<uint32_t>();
    return reduceRows(
        device, 1, 1, 0u, [=] LOOM_HD(uint32_t, uint32_t) { return v.at(0, 0); },
        [] LOOM_HD(uint32_t a, uint32_t b) { return a + b; });
}

void storeFrames(DeviceKind device, Texture& frames, uint32_t value) {
    const auto v = frames.deviceView<uint32_t>();
    launch2D(device, 1, 1, [=] LOOM_HD(uint32_t, uint32_t) { v.at(0, 0) = value; });
}

}  // namespace loom::accumulate
