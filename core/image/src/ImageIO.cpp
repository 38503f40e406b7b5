#include "loom/ImageIO.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfStdIO.h>
#include <ImfStringAttribute.h>
#include <ImfVersion.h>
#include <stb/stb_image.h>
#include <stb/stb_image_write.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <memory>
#include <new>
#include <system_error>
#include <vector>

#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/Files.h"

namespace loom {

namespace fs = std::filesystem;

namespace {

constexpr std::array<const char*, 4> kChannelNames = {"R", "G", "B", "A"};

/// The most pixels readImage decodes from a PNG or JPEG (2^30, 4 GiB as RGBA8), checked from the header before
/// anything is allocated.
constexpr uint64_t kMaxReadTexels = uint64_t(1) << 30;

[[noreturn]] void throwRuntime(const fs::path& file, std::string what, std::string suggestion = {}) {
    throw Error(Error::Info{ErrorKind::Runtime, file.string(), "", std::move(what), "", std::move(suggestion)});
}

std::string lowerExtension(const fs::path& path) {
    std::string ext = path.extension().string();
    if (!ext.empty() && ext[0] == '.') ext.erase(0, 1);
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

Imf::PixelType exrPixelType(ComponentType c) {
    switch (c) {
        case ComponentType::Float32:
            return Imf::FLOAT;
        case ComponentType::Float16:
            return Imf::HALF;
        case ComponentType::Uint32:
            return Imf::UINT;
        case ComponentType::Unorm8:
            break;
    }
    return Imf::NUM_PIXELTYPES;
}

size_t pixelTypeSize(Imf::PixelType t) {
    return t == Imf::HALF ? 2 : 4;
}

void writeExr(const fs::path& path, const Texture& tex, const std::map<std::string, std::string>& attributes) {
    const FormatInfo& info = formatInfo(tex.format());
    const Imf::PixelType type = exrPixelType(info.component);
    Imf::Header header(int(tex.width()), int(tex.height()));
    for (const auto& [name, value] : attributes) header.insert(name, Imf::StringAttribute(value));
    Imf::FrameBuffer frameBuffer;
    // OpenEXR's slices take non-const pointers, but writing only reads through them.
    char* base = reinterpret_cast<char*>(const_cast<std::byte*>(tex.data()));
    for (uint32_t c = 0; c < info.channels; ++c) {
        header.channels().insert(kChannelNames[c], Imf::Channel(type));
        frameBuffer.insert(kChannelNames[c],
                           Imf::Slice(type, base + c * pixelTypeSize(type), info.bytesPerPixel, tex.rowPitch()));
    }
    writeAtomically(path, [&](std::ofstream& out, const std::string& tmp) {
        Imf::StdOFStream stream(out, tmp.c_str());
        Imf::OutputFile file(stream, header);
        file.setFrameBuffer(frameBuffer);
        file.writePixels(int(tex.height()));
    });
}

void writePng(const fs::path& path, const Texture& tex) {
    struct Encoded {
        std::string bytes;
        bool outOfMemory = false;
    } encoded;
    // stb is C: nothing may be thrown through it, so a failed append is noted and reported below.
    auto append = [](void* context, void* data, int size) {
        auto* out = static_cast<Encoded*>(context);
        if (out->outOfMemory) return;
        try {
            out->bytes.append(static_cast<const char*>(data), size_t(size));
        } catch (const std::bad_alloc&) {
            out->outOfMemory = true;
            out->bytes = std::string();
        }
    };
    const std::string size = std::to_string(tex.width()) + "x" + std::to_string(tex.height()) + " (" +
                             std::to_string(tex.byteSize() >> 20) + " MiB of pixels)";
    if (tex.rowPitch() > size_t(std::numeric_limits<int>::max()) || tex.height() > uint32_t(1) << 30)
        throwRuntime(path, "the " + size + " image is too large to encode as PNG", "dump a smaller region or as EXR");
    const bool ok = stbi_write_png_to_func(append, &encoded, int(tex.width()), int(tex.height()), 4, tex.data(),
                                           int(tex.rowPitch())) != 0;
    if (!ok || encoded.outOfMemory)
        throwRuntime(path, "out of memory encoding the " + size + " image as PNG",
                     "free memory, or write a smaller image");
    writeFileAtomic(path, encoded.bytes);
}

/// The first four bytes of a file (zeros past its end), which tell the image formats apart.
std::array<char, 4> leadingBytes(const fs::path& path) {
    std::array<char, 4> magic{};
    std::ifstream(path, std::ios::binary).read(magic.data(), magic.size());
    return magic;
}

/// An EXR's R, G, B and A (or Y) channels: into RGBA32U when all of them are UINT, else into RGBA32F (ExrFile).
Texture readExr(const fs::path& path) {
    ExrFile file(path);
    const std::vector<std::string> names = file.layerChannels("");
    const bool allUint = !names.empty() && std::all_of(names.begin(), names.end(), [&](const std::string& n) {
        return n.empty() || file.findChannel(n)->type == ExrSampleType::Uint;
    });
    if (!allUint) return file.readRgba("");
    Texture tex(file.width(), file.height(), Format::RGBA32U);
    std::vector<ExrChannelRead> reads;
    for (size_t c = 0; c < 4; ++c) {
        const std::string channel = names == std::vector<std::string>{"Y"} ? (c < 3 ? "Y" : "")
                                    : c < names.size()                     ? names[c]
                                                                           : "";
        reads.push_back({channel, tex.data() + 4 * c, 16, tex.rowPitch(), true, c == 3 ? 1.0 : 0.0});
    }
    file.read(reads);
    return tex;
}

Texture readStb(const fs::path& path) {
    const std::string bytes = readFileBytes(path);
    const auto* data = reinterpret_cast<const stbi_uc*>(bytes.data());
    int width = 0, height = 0, channelsInFile = 0;
    // The header's size first: a small file may claim a huge image.
    if (bytes.size() <= size_t(std::numeric_limits<int>::max()) &&
        stbi_info_from_memory(data, int(bytes.size()), &width, &height, &channelsInFile) &&
        (uint64_t(width) * uint64_t(height) > kMaxReadTexels || width <= 0 || height <= 0))
        throwBadInput("",
                      "the image is " + std::to_string(width) + "x" + std::to_string(height) + " (" +
                          std::to_string(uint64_t(width) * uint64_t(height) * 4 >> 20) + " MiB decoded)",
                      "at most " + std::to_string(kMaxReadTexels) + " pixels", "downscale the image", path.string());
    std::unique_ptr<stbi_uc, void (*)(void*)> pixels(
        bytes.size() <= size_t(std::numeric_limits<int>::max())
            ? stbi_load_from_memory(data, int(bytes.size()), &width, &height, &channelsInFile, 4)
            : nullptr,
        stbi_image_free);
    if (!pixels) {
        const char* reason = stbi_failure_reason();
        if (reason && std::strcmp(reason, "outofmem") == 0)
            throwRuntime(
                path, "out of memory decoding the " + std::to_string(width) + "x" + std::to_string(height) + " image");
        throwBadInput("", "cannot read the image: " + describeImageDecodeFailure(data, bytes.size(), reason),
                      "a valid PNG or EXR file", "check that the file is a complete PNG or OpenEXR image",
                      path.string());
    }
    Texture tex(uint32_t(width), uint32_t(height), Format::RGBA8Unorm);
    const size_t rowBytes = size_t(width) * 4;
    for (uint32_t y = 0; y < tex.height(); ++y) std::memcpy(tex.row(y), pixels.get() + rowBytes * y, rowBytes);
    return tex;
}

/// Radiance RGBE (.hdr): the header's lines up to an empty one, the resolution line "-Y height +X width", then
/// rows either flat (4 bytes a pixel) or run-length encoded per channel (a row opening with 2, 2 and its width).
/// Every count is checked against what is left of the row and of the file, so a damaged file is an error, never a
/// loop that does not advance. A texel is m 2^(e - 136) per channel (0 when e = 0), alpha 1.
class RadianceReader {
public:
    RadianceReader(const fs::path& path, std::string bytes) : mPath(path), mBytes(std::move(bytes)) {}

    Texture read() {
        header();
        // The smallest a row can be (flat: 4 bytes a pixel; encoded: 4 bytes, then per channel runs of at most 127
        // pixels in 2 bytes): a damaged size line must not allocate more than the file can hold.
        const uint64_t flat = uint64_t(mWidth) * 4, encoded = 4 + 8 * ((uint64_t(mWidth) + 126) / 127);
        const uint64_t minRow = mWidth >= 8 && mWidth < 32768 ? std::min(flat, encoded) : flat;
        if (minRow * mHeight > mBytes.size() - mPos)
            fail("the file is too short for a " + std::to_string(mWidth) + "x" + std::to_string(mHeight) + " image",
                 "a complete image", "the file is truncated, or its size line is damaged");
        Texture tex(mWidth, mHeight, Format::RGBA32F);
        std::vector<uint8_t> rgbe(size_t(mWidth) * 4);
        for (uint32_t y = 0; y < mHeight; ++y) {
            row(y, rgbe);
            auto* out = reinterpret_cast<float*>(tex.row(y));
            for (uint32_t x = 0; x < mWidth; ++x) {
                const uint8_t* p = &rgbe[size_t(x) * 4];
                const float scale = p[3] == 0 ? 0.f : std::ldexp(1.f, int(p[3]) - 136);
                for (int c = 0; c < 3; ++c) out[4 * x + c] = float(p[c]) * scale;
                out[4 * x + 3] = 1.f;
            }
        }
        return tex;
    }

private:
    [[noreturn]] void fail(const std::string& what, const std::string& expected,
                           const std::string& suggestion = {}) const {
        throwBadInput("", what, expected, suggestion, mPath.string());
    }
    /// A header line as an error quotes it: at most 40 bytes (the message escapes what is not text).
    static std::string quoted(const std::string& l) {
        return "'" + (l.size() > 40 ? l.substr(0, 40) + "..." : l) + "'";
    }
    std::string line() {
        const size_t end = mBytes.find('\n', mPos);
        if (end == std::string::npos) fail("the header ends before the image size", "a complete Radiance header");
        std::string l = mBytes.substr(mPos, end - mPos);
        mPos = end + 1;
        if (!l.empty() && l.back() == '\r') l.pop_back();
        return l;
    }
    void header() {
        const std::string signature = line();
        if (signature != "#?RADIANCE" && signature != "#?RGBE")
            fail("not a Radiance HDR image (it does not start with #?RADIANCE)", "a Radiance .hdr file",
                 "convert the map to .hdr or .exr");
        for (std::string l = line(); !l.empty(); l = line()) {
            if (l.rfind("FORMAT=", 0) == 0 && l != "FORMAT=32-bit_rle_rgbe")
                fail("unsupported pixel format " + quoted(l.substr(7)), "FORMAT=32-bit_rle_rgbe",
                     "convert the map to RGB (not XYZ) .hdr or to .exr");
        }
        const std::string size = line();
        char ySign = 0, xSign = 0, yAxis = 0, xAxis = 0, rest = 0;
        unsigned long h = 0, w = 0;
        if (std::sscanf(size.c_str(), "%c%c %lu %c%c %lu %c", &ySign, &yAxis, &h, &xSign, &xAxis, &w, &rest) != 6 ||
            ySign != '-' || yAxis != 'Y' || xSign != '+' || xAxis != 'X')
            fail("unsupported image size line " + quoted(size), "-Y <height> +X <width> (rows top to bottom)",
                 "re-save the map in the usual orientation");
        if (w == 0 || h == 0 || w > kMaxSide || h > kMaxSide)
            fail("image size " + std::to_string(w) + "x" + std::to_string(h) + " out of range",
                 "1 to " + std::to_string(kMaxSide) + " pixels a side");
        mWidth = uint32_t(w);
        mHeight = uint32_t(h);
    }
    void truncated(uint32_t y) const {
        fail("the file ends in row " + std::to_string(y) + " of " + std::to_string(mHeight), "a complete image",
             "the file is truncated; copy or download it again");
    }
    void row(uint32_t y, std::vector<uint8_t>& rgbe) {
        const size_t left = mBytes.size() - mPos;
        const auto* in = reinterpret_cast<const uint8_t*>(mBytes.data()) + mPos;
        const bool encoded =
            mWidth >= 8 && mWidth < 32768 && left >= 4 && in[0] == 2 && in[1] == 2 && (in[2] & 0x80) == 0;
        if (!encoded) {
            if (left < rgbe.size()) truncated(y);
            std::memcpy(rgbe.data(), in, rgbe.size());
            mPos += rgbe.size();
            return;
        }
        if ((uint32_t(in[2]) << 8 | in[3]) != mWidth)
            fail("row " + std::to_string(y) + " is encoded for a width of " + std::to_string(in[2] << 8 | in[3]),
                 "rows of the header's width, " + std::to_string(mWidth), "the file is damaged");
        size_t pos = 4;
        for (uint32_t c = 0; c < 4; ++c) {
            for (uint32_t x = 0; x < mWidth;) {
                if (pos >= left) truncated(y);
                const uint32_t count = in[pos++];
                const bool run = count > 128;
                const uint32_t n = run ? count - 128 : count;
                if (n == 0 || n > mWidth - x)
                    fail("row " + std::to_string(y) + " holds a run of " + std::to_string(n) + " at column " +
                             std::to_string(x),
                         "runs of 1 to the " + std::to_string(mWidth - x) + " pixels left in the row",
                         "the file is damaged");
                if (pos + (run ? 1 : n) > left) truncated(y);
                for (uint32_t k = 0; k < n; ++k) rgbe[size_t(x + k) * 4 + c] = in[run ? pos : pos + k];
                pos += run ? 1 : n;
                x += n;
            }
        }
        mPos += pos;
    }

    static constexpr unsigned long kMaxSide = 1u << 16;
    fs::path mPath;
    std::string mBytes;
    size_t mPos = 0;
    uint32_t mWidth = 0, mHeight = 0;
};

}  // namespace

std::string describeImageDecodeFailure(const unsigned char* bytes, size_t size, const char* reason) {
    if (!bytes || size == 0) return "an empty file";
    // stb tries every decoder in turn: when the data's own decoder fails early, the reason left is another
    // decoder's ("bad png sig" for a truncated JPEG), which would only mislead.
    std::string why = reason ? reason : "";
    for (const char* other : {"png", "jpeg", "jpg", "bmp", "gif", "psd", "tga", "pnm", "hdr", "pic", "image type"})
        if (why.find(other) != std::string::npos) why.clear();
    const std::string stb = why.empty() ? "" : " (stb: " + why + ")";
    const auto startsWith = [&](std::initializer_list<unsigned char> magic) {
        if (size < magic.size()) return false;
        size_t i = 0;
        for (unsigned char m : magic)
            if (bytes[i++] != m) return false;
        return true;
    };
    if (startsWith({0xFF, 0xD8, 0xFF})) return "a truncated or corrupt JPEG" + stb;
    if (startsWith({0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'})) return "a truncated or corrupt PNG" + stb;
    std::string lead;
    for (size_t i = 0; i < std::min<size_t>(size, 4); ++i) {
        static const char* hex = "0123456789abcdef";
        lead += std::string(lead.empty() ? "" : " ") + hex[bytes[i] >> 4] + hex[bytes[i] & 15];
    }
    return "not a PNG or JPEG image (it starts with bytes " + lead + ")" + stb;
}

const char* imageExtension(Format f) {
    return formatInfo(f).component == ComponentType::Unorm8 ? "png" : "exr";
}

void writeImage(const fs::path& path, const Texture& tex, const std::map<std::string, std::string>& attributes) {
    if (tex.empty() || tex.width() == 0 || tex.height() == 0) {
        throwRuntime(path, "cannot write an empty " + std::to_string(tex.width()) + "x" + std::to_string(tex.height()) +
                               " image");
    }
    const std::string expected = imageExtension(tex.format());
    const std::string ext = lowerExtension(path);
    if ((ext == "exr" || ext == "png") && ext != expected) {
        throwBadInput("", "a " + std::string(formatName(tex.format())) + " texture cannot be written as ." + ext,
                      "a ." + expected + " file", "name the file with the ." + expected + " extension", path.string());
    }
    if (expected == "png") {
        writePng(path, tex);
    } else {
        writeExr(path, tex, attributes);
    }
}

namespace {

void checkReadable(const fs::path& path) {
    std::error_code ec;
    if (!fs::exists(path, ec)) {
        throwBadInput("", "image file not found", "an existing image file", "check the path and the working folder",
                      path.string());
    }
    if (!fs::is_regular_file(path, ec)) {
        throwBadInput("", "not a regular file", "an image file", "", path.string());
    }
    if (::access(path.c_str(), R_OK) != 0) {
        throwBadInput("", std::string("cannot read the file: ") + std::strerror(errno), "a readable image file",
                      "check the file's permissions", path.string());
    }
}

}  // namespace

Texture readImage(const fs::path& path) {
    checkReadable(path);
    const std::array<char, 4> magic = leadingBytes(path);
    if (Imf::isImfMagic(magic.data())) return readExr(path);
    if (magic[0] == '#' && magic[1] == '?') return readRadianceHdr(path);  // "#?RADIANCE"
    return readStb(path);
}

Texture readRadianceHdr(const fs::path& path) {
    checkReadable(path);
    return RadianceReader(path, readFileBytes(path)).read();
}

}  // namespace loom
