#pragma once
// Writes EXR files with any channel names and sample types, as other renderers do (Blender's multilayer
// "ViewLayer.Noisy Image.R"), straight through OpenEXR, so the readers are tested on files Loom did not write.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfStandardAttributes.h>
#include <half.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace loom::test {

/// One channel: width x height samples, row 0 at the top. UINT channels hold integers in `values`.
struct ExrTestChannel {
    std::vector<float> values;
    Imf::PixelType type = Imf::FLOAT;
};

/// Writes `channels` (name -> samples) as a single-part scanline EXR, with OpenEXR's worldToCamera attribute when
/// given (row-major).
inline void writeExrChannels(const std::filesystem::path& path, int width, int height,
                             const std::map<std::string, ExrTestChannel>& channels,
                             const std::optional<std::array<float, 16>>& worldToCamera = std::nullopt) {
    Imf::Header header(width, height);
    Imf::FrameBuffer frameBuffer;
    // Converted copies kept alive until the pixels are written.
    std::vector<std::vector<uint32_t>> uints;
    std::vector<std::vector<uint16_t>> halves;
    uints.reserve(channels.size());
    halves.reserve(channels.size());
    for (const auto& [name, ch] : channels) {
        header.channels().insert(name, Imf::Channel(ch.type));
        char* base = nullptr;
        size_t size = 4;
        if (ch.type == Imf::UINT) {
            auto& u = uints.emplace_back();
            for (float v : ch.values) u.push_back(uint32_t(v));
            base = reinterpret_cast<char*>(u.data());
        } else if (ch.type == Imf::HALF) {
            auto& h = halves.emplace_back();
            for (float v : ch.values) h.push_back(half(v).bits());
            base = reinterpret_cast<char*>(h.data());
            size = 2;
        } else {
            base = const_cast<char*>(reinterpret_cast<const char*>(ch.values.data()));
        }
        frameBuffer.insert(name, Imf::Slice(ch.type, base, size, size * size_t(width)));
    }
    if (worldToCamera) {
        Imath::M44f m;
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) m[r][c] = (*worldToCamera)[size_t(r * 4 + c)];
        Imf::addWorldToCamera(header, m);
    }
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(frameBuffer);
    file.writePixels(height);
}

}  // namespace loom::test
