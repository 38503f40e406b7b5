#include "ErrorMeasureDevice.h"

#include "ErrorMeasureKernels.h"
#include "loom/Launch.h"

namespace loom::errormeasure {

namespace {

MetricImage imageOf(const Texture& t) {
    return t.deviceView<glm::vec4>();
}

ImageView<float> errorOf(Texture* error) {
    return error ? error->deviceView<float>() : ImageView<float>{};
}

}  // namespace

bool deviceRuns(DeviceKind device) {
    return device != DeviceKind::Cpu && launchesReach(device);
}

void zeroNonFiniteOnDevice(DeviceKind device, const Texture& src, Texture& dst) {
    const auto in = src.deviceView<glm::vec4>();
    const auto out = dst.deviceView<glm::vec4>();
    launch2D(device, in.width, in.height,
             [=] LOOM_HD(uint32_t x, uint32_t y) { out.at(x, y) = zeroNonFinite(in.at(x, y)); });
}

void copyOnDevice(DeviceKind device, const Texture& src, Texture& dst) {
    const auto in = src.deviceView<glm::vec4>();
    const auto out = dst.deviceView<glm::vec4>();
    launch2D(device, in.width, in.height, [=] LOOM_HD(uint32_t x, uint32_t y) { out.at(x, y) = in.at(x, y); });
}

void clearOnDevice(DeviceKind device, Texture& image) {
    const auto out = image.deviceView<float>();
    launch2D(device, out.width, out.height, [=] LOOM_HD(uint32_t x, uint32_t y) { out.at(x, y) = 0.f; });
}

Texture uploadToneMapTable(DeviceKind device) {
    const Texture host = Texture::wrap(reinterpret_cast<std::byte*>(const_cast<float*>(ldrToneMapTable())),
                                       kOetfTableSize, 1, Format::R32F);
    Texture onDevice = Texture::onDevice(device, kOetfTableSize, 1, Format::R32F, "ErrorMeasure's tone map table");
    copyTexture(onDevice, host);
    return onDevice;
}

MetricSums relMseOnDevice(DeviceKind device, const Texture& test, const Texture& ref, Texture* error) {
    return relMseSums(device, imageOf(test), imageOf(ref), errorOf(error));
}

MetricSums smapeOnDevice(DeviceKind device, const Texture& test, const Texture& ref, Texture* error) {
    return smapeSums(device, imageOf(test), imageOf(ref), errorOf(error));
}

MetricSums psnrOnDevice(DeviceKind device, const Texture& table, const Texture& test, const Texture& ref,
                        Texture* error) {
    return psnrSums(device, table.deviceView<float>().data, imageOf(test), imageOf(ref), errorOf(error));
}

MetricSums temporalOnDevice(DeviceKind device, const Texture& test, const Texture& testPrev, const Texture& ref,
                            const Texture& refPrev) {
    return temporalSums(device, imageOf(test), imageOf(testPrev), imageOf(ref), imageOf(refPrev));
}

}  // namespace loom::errormeasure
