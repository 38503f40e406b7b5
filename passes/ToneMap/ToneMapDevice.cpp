#include "ToneMapDevice.h"

#include "loom/Launch.h"

namespace loom::tonemap {

bool deviceRuns(DeviceKind device) { return device != DeviceKind::Cpu && launchesReach(device); }

FrameSums sumFrame(DeviceKind device, const Texture& src, uint32_t rowStep) {
    const auto in = src.deviceView<glm::vec4>();
    return reduceRows(
        device, in.width, in.height, FrameSums{},
        [=] LOOM_HD(uint32_t x, uint32_t y) {
            const glm::vec4 c = in.at(x, y);
            FrameSums s;
            s.nonFinite = !isFinite(c.x) || !isFinite(c.y) || !isFinite(c.z) || !isFinite(c.w);
            float term;
            if (rowStep > 0 && y % rowStep == 0 && logLuminance(c, term)) {
                s.logSum = double(term);
                s.logCount = 1;
            }
            return s;
        },
        [] LOOM_HD(const FrameSums& a, const FrameSums& b) {
            return FrameSums{a.logSum + b.logSum, a.logCount + b.logCount, a.nonFinite + b.nonFinite};
        });
}

glm::vec4 loadState(DeviceKind device, const Texture& state) {
    const auto v = state.deviceView<glm::vec4>();
    // The one texel, "reduced" by keeping the later operand: its bits, whatever they are.
    return reduceRows(
        device, 1, 1, glm::vec4(0.f), [=] LOOM_HD(uint32_t, uint32_t) { return v.at(0, 0); },
        [] LOOM_HD(const glm::vec4&, const glm::vec4& b) { return b; });
}

void storeState(DeviceKind device, Texture& state, const glm::vec4& value) {
    const auto v = state.deviceView<glm::vec4>();
    launch2D(device, 1, 1, [=] LOOM_HD(uint32_t, uint32_t) { v.at(0, 0) = value; });
}

Texture uploadSrgbTable(DeviceKind device, const SrgbEncodeTable& table) {
    static_assert(sizeof(table.entry) == SrgbEncodeTable::kBuckets * sizeof(uint32_t));
    const Texture host = Texture::wrap(reinterpret_cast<std::byte*>(const_cast<int32_t*>(table.entry)),
                                       SrgbEncodeTable::kBuckets, 1, Format::R32U);
    Texture onDevice = Texture::onDevice(device, SrgbEncodeTable::kBuckets, 1, Format::R32U, "ToneMap's sRGB table");
    copyTexture(onDevice, host);
    return onDevice;
}

void mapFrame(DeviceKind device, const ToneMapParams& params, const Texture& srgbTable, const Texture& src,
              Texture& dst, Texture* dstFloat) {
    const auto in = src.deviceView<glm::vec4>();
    const auto out = dst.deviceView<uint32_t>();
    const auto outFloat = dstFloat ? dstFloat->deviceView<glm::vec4>() : ImageView<glm::vec4>{};
    const auto* table = reinterpret_cast<const SrgbEncodeTable*>(srgbTable.deviceView<uint32_t>().data);
    const ToneMapParams p = params;
    launch2D(device, in.width, in.height, [=] LOOM_HD(uint32_t x, uint32_t y) {
        const glm::vec4 mapped = toneMapPixel(p, in.at(x, y));
        out.at(x, y) = packSrgb8(*table, mapped);
        if (outFloat.data) outFloat.at(x, y) = mapped;
    });
}

}  // namespace loom::tonemap
