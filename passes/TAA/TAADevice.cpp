#include "TAADevice.h"

#include "loom/Launch.h"

namespace loom::taa {

bool deviceRuns(DeviceKind device) { return device != DeviceKind::Cpu && launchesReach(device); }

template <class T>
ClampedImage<T> clampedOnDevice(const Texture& t) {
    const auto v = t.deviceView<T>();
    return {v.data, v.width, v.height, v.rowPitch};
}

Counts resolveOnDevice(DeviceKind device, const TaaParams& params, bool historyValid, bool compress,
                       const Texture& colorIn, const Texture& mvec, const Texture& historyPrev, Texture& colorOut,
                       Texture& historyCur) {
    TaaInputs in;
    in.color = clampedOnDevice<glm::vec4>(colorIn);
    in.mvec = clampedOnDevice<glm::vec2>(mvec);
    in.history = clampedOnDevice<glm::vec4>(historyPrev);
    in.historyValid = historyValid;
    in.compress = compress;
    const auto out = colorOut.deviceView<glm::vec4>();
    const auto history = historyCur.deviceView<glm::vec4>();
    const TaaParams p = params;
    // One visit a pixel: the reduction's value resolves it, writes it and returns its flags as counts.
    return reduceRows(
        device, out.width, out.height, Counts{},
        [=] LOOM_HD(uint32_t x, uint32_t y) {
            uint32_t flags = 0;
            const glm::vec4 c = resolvePixel(in, p, x, y, flags);
            out.at(x, y) = outputColor(in.compress, c, in.color.at(int(x), int(y)));
            history.at(x, y) = c;
            Counts n;
            n.nonFinite = (flags & kNonFiniteInput) != 0;
            n.noHistory = (flags & kNoHistory) != 0;
            n.clipped = (flags & kClipped) != 0;
            return n;
        },
        [] LOOM_HD(const Counts& a, const Counts& b) {
            Counts c;
            c.nonFinite = a.nonFinite + b.nonFinite;
            c.noHistory = a.noHistory + b.noHistory;
            c.clipped = a.clipped + b.clipped;
            return c;
        });
}

}  // namespace loom::taa
