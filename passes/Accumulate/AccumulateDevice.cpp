#include "AccumulateDevice.h"

#include "loom/Launch.h"

namespace loom::accumulate {

bool deviceRuns(DeviceKind device) { return device != DeviceKind::Cpu && launchesReach(device); }

/// One frame's update of every pixel; with samples added, the count of those skipped (not finite). Each pixel is
/// updated exactly once, by the reduction's value when it counts (the state is updated in place, so it cannot be
/// read back afterwards to tell what was added).
template <Precision P>
uint64_t runFrame(DeviceKind device, const FrameViews& v, bool reset, bool addSamples) {
    if (!addSamples) {
        launch2D(device, v.dst.width, v.dst.height,
                 [=] LOOM_HD(uint32_t x, uint32_t y) { accumulatePixel<P>(v, x, y, reset, false); });
        return 0;
    }
    return reduceRows(
        device, v.dst.width, v.dst.height, uint64_t(0),
        [=] LOOM_HD(uint32_t x, uint32_t y) { return uint64_t(!accumulatePixel<P>(v, x, y, reset, true)); },
        [] LOOM_HD(uint64_t a, uint64_t b) { return a + b; });
}

uint64_t accumulateOnDevice(DeviceKind device, Precision precision, const FrameViews& v, bool reset, bool addSamples) {
    switch (precision) {
        case Precision::Float:
            return runFrame<Precision::Float>(device, v, reset, addSamples);
        case Precision::Kahan:
            return runFrame<Precision::Kahan>(device, v, reset, addSamples);
        case Precision::Double:
            return runFrame<Precision::Double>(device, v, reset, addSamples);
    }
    return 0;
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
