#include "loom/ExrFile.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfMultiPartInputFile.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <ImfThreading.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <map>
#include <set>
#include <thread>

#include "loom/Error.h"

namespace loom {

namespace fs = std::filesystem;

namespace {

/// The largest image read: sides of 64 Ki pixels, 2^28 pixels (4 GiB as RGBA32F). A damaged header claims any
/// size; OpenEXR checks the sides and the tiles when it opens the file, before it allocates.
constexpr int kMaxReadSide = 1 << 16;
constexpr int64_t kMaxReadPixels = int64_t(1) << 28;

void limitImageSize() {
    static const bool limited = [] {
        Imf::Header::setMaxImageSize(kMaxReadSide, kMaxReadSide);
        Imf::Header::setMaxTileSize(kMaxReadSide, kMaxReadSide);
        // Blocks of scanlines decompress in parallel (zlib is most of a read); the pixels are the same.
        Imf::setGlobalThreadCount(int(std::max(1u, std::thread::hardware_concurrency())));
        return true;
    }();
    (void)limited;
}

[[noreturn]] void fail(const fs::path& path, const std::string& what, const std::string& expected,
                       const std::string& suggestion = {}) {
    throwBadInput("", what, expected, suggestion, path.string());
}

ExrSampleType sampleType(Imf::PixelType t) {
    switch (t) {
        case Imf::UINT:
            return ExrSampleType::Uint;
        case Imf::HALF:
            return ExrSampleType::Half;
        default:
            return ExrSampleType::Float;
    }
}

/// Component orders a layer's channels are read in, first match wins.
constexpr std::array<std::array<const char*, 4>, 3> kComponentOrders = {{
    {"R", "G", "B", "A"},
    {"X", "Y", "Z", "W"},
    {"U", "V", nullptr, nullptr},
}};

}  // namespace

std::string sequenceFramePath(std::string_view pattern, int64_t frame, const std::string& where) {
    const std::string text(pattern);
    const auto bad = [&](const std::string& what) {
        throwBadInput(where, what + " in '" + text + "'",
                      "one frame field: %04d (printf: %4d pads with spaces), or a run of # (digits, zero-padded); "
                      "%% for a literal %",
                      "name the frames like beauty.%04d.exr or beauty.####.exr");
    };
    if (frame < 0) throwBadInput(where, "frame " + std::to_string(frame) + " is negative", "frames from 0 on");
    constexpr int kMaxDigits = 18;
    // The printf field, if any: every '#' is then literal.
    size_t fieldAt = std::string::npos, fieldLength = 0;
    int width = 0;
    bool zeros = true;
    for (size_t i = 0; i < text.size(); ++i) {
        if (text[i] != '%') continue;
        size_t j = i + 1;
        if (j < text.size() && text[j] == '%') {  // "%%" is a literal percent sign
            i = j;
            continue;
        }
        const bool zeroFlag = j < text.size() && text[j] == '0';
        while (j < text.size() && text[j] == '0') ++j;
        int digits = 0;
        for (; j < text.size() && std::isdigit(static_cast<unsigned char>(text[j])); ++j)
            digits = std::min(digits * 10 + (text[j] - '0'), 1000);
        if (j >= text.size() || text[j] != 'd') bad("a '%' that is not %d, %Nd or %0Nd (write %% for a literal %)");
        if (digits > kMaxDigits) bad("a frame field wider than 18 digits");
        if (fieldAt != std::string::npos) bad("two frame fields");
        fieldAt = i;
        fieldLength = j + 1 - i;
        width = digits;
        zeros = zeroFlag;
        i = j;
    }
    if (fieldAt == std::string::npos) {
        // Otherwise the last run of '#' (earlier ones, in a folder's name say, are literal).
        const size_t last = text.rfind('#');
        if (last == std::string::npos) bad("no frame field");
        size_t first = last;
        while (first > 0 && text[first - 1] == '#') --first;
        fieldAt = first;
        fieldLength = last + 1 - first;
        width = int(fieldLength);
        if (width > kMaxDigits) bad("a frame field wider than 18 digits");
    }
    std::string number = std::to_string(frame);
    if (int(number.size()) < width) number.insert(0, size_t(width) - number.size(), zeros ? '0' : ' ');
    // The text around the field, with "%%" as '%'.
    std::string out;
    for (size_t i = 0; i < text.size(); ++i) {
        if (i == fieldAt) {
            out += number;
            i += fieldLength - 1;
        } else {
            out += text[i];
            if (text[i] == '%') ++i;  // the second '%' of "%%" (any other '%' is the field)
        }
    }
    return out;
}

std::string fileAbsence(const fs::path& path) {
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (ec == std::errc::too_many_symbolic_link_levels) return "is a symbolic link loop";
    if (!fs::exists(status)) {
        std::error_code linkEc;
        if (fs::is_symlink(fs::symlink_status(path, linkEc))) return "is a symbolic link to a missing file";
        return "does not exist";
    }
    if (!fs::is_regular_file(status)) return "is not a regular file";
    return {};
}

SequenceSource parseSequenceSource(std::string_view spec) {
    std::string lower(spec);
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    const size_t at = lower.find(".exr:");
    if (at == std::string::npos) return {std::string(spec), {}};
    return {std::string(spec.substr(0, at + 4)), std::string(spec.substr(at + 5))};
}

const char* exrSampleTypeName(ExrSampleType t) {
    switch (t) {
        case ExrSampleType::Uint:
            return "UINT";
        case ExrSampleType::Half:
            return "HALF";
        case ExrSampleType::Float:
            return "FLOAT";
    }
    return "?";
}

struct ExrFile::Impl {
    fs::path path;
    std::unique_ptr<Imf::InputFile> file;
    Imath::Box2i dataWindow;
    uint32_t width = 0, height = 0;
    std::vector<ExrChannel> channels;
};

ExrFile::ExrFile(const fs::path& path) : mImpl(std::make_unique<Impl>()) {
    limitImageSize();
    mImpl->path = path;
    if (const std::string absent = fileAbsence(path); !absent.empty()) {
        if (absent == "is not a regular file") fail(path, "not a regular file", "an EXR file");
        fail(path, absent == "does not exist" ? "image file not found" : "the path " + absent, "an existing EXR file",
             "check the path");
    }
    if (::access(path.c_str(), R_OK) != 0)
        fail(path, std::string("cannot read the file: ") + std::strerror(errno), "a readable EXR file",
             "check the file's permissions");
    try {
        mImpl->file = std::make_unique<Imf::InputFile>(path.c_str());
    } catch (const std::exception& e) {
        fail(path, std::string("cannot read the EXR image: ") + e.what(), "a valid OpenEXR file",
             "check that the file is a complete scanline or tiled EXR");
    }
    const Imf::Header& header = mImpl->file->header();
    const Imath::Box2i dw = header.dataWindow();
    const int64_t width = int64_t(dw.max.x) - dw.min.x + 1;
    const int64_t height = int64_t(dw.max.y) - dw.min.y + 1;
    if (width <= 0 || height <= 0) fail(path, "the image's data window is empty", "a non-empty image");
    if (width * height > kMaxReadPixels)
        fail(path, "image size " + std::to_string(width) + "x" + std::to_string(height) + " out of range",
             "at most " + std::to_string(kMaxReadPixels) + " pixels");
    mImpl->dataWindow = dw;
    mImpl->width = uint32_t(width);
    mImpl->height = uint32_t(height);
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it)
        mImpl->channels.push_back({it.name(), sampleType(it.channel().type)});
}

ExrFile::~ExrFile() = default;
ExrFile::ExrFile(ExrFile&&) noexcept = default;
ExrFile& ExrFile::operator=(ExrFile&&) noexcept = default;

const fs::path& ExrFile::path() const {
    return mImpl->path;
}
uint32_t ExrFile::width() const {
    return mImpl->width;
}
uint32_t ExrFile::height() const {
    return mImpl->height;
}
const std::vector<ExrChannel>& ExrFile::channels() const {
    return mImpl->channels;
}

const ExrChannel* ExrFile::findChannel(std::string_view name) const {
    for (const ExrChannel& c : mImpl->channels)
        if (c.name == name) return &c;
    return nullptr;
}

std::optional<std::array<float, 16>> ExrFile::worldToCamera() const {
    const Imf::Header& header = mImpl->file->header();
    if (!Imf::hasWorldToCamera(header)) return std::nullopt;
    const Imath::M44f& m = Imf::worldToCamera(header);
    std::array<float, 16> out{};
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) out[size_t(r * 4 + c)] = m[r][c];
    return out;
}

std::optional<std::string> ExrFile::stringAttribute(const std::string& name) const {
    const auto* a = mImpl->file->header().findTypedAttribute<Imf::StringAttribute>(name);
    if (!a) return std::nullopt;
    return a->value();
}

std::vector<std::string> ExrFile::layerChannels(std::string_view layer) const {
    const std::string prefix = layer.empty() ? std::string() : std::string(layer) + ".";
    for (const auto& order : kComponentOrders) {
        std::vector<std::string> found(order.size());
        size_t count = 0, last = 0;
        for (size_t i = 0; i < order.size(); ++i)
            if (order[i] && findChannel(prefix + order[i])) {
                found[i] = prefix + order[i];
                ++count;
                last = i;
            }
        if (count == 0) continue;
        if (count == 1 && !layer.empty()) return {found[last]};  // "ViewLayer.Depth.Z" is the layer's first value
        found.resize(last + 1);
        return found;
    }
    if (layer.empty()) {
        if (findChannel("Y")) return {"Y"};
        return {};
    }
    if (findChannel(layer)) return {std::string(layer)};
    std::vector<std::string> under;
    for (const ExrChannel& c : mImpl->channels)
        if (c.name.size() > prefix.size() && c.name.compare(0, prefix.size(), prefix) == 0 &&
            c.name.find('.', prefix.size()) == std::string::npos)
            under.push_back(c.name);
    if (under.size() == 1) return under;
    return {};
}

std::vector<std::string> ExrFile::layers() const {
    std::set<std::string> names;
    for (const ExrChannel& c : mImpl->channels) {
        const size_t dot = c.name.rfind('.');
        names.insert(dot == std::string::npos ? std::string() : c.name.substr(0, dot));
    }
    return {names.begin(), names.end()};
}

int ExrFile::partCount() const {
    try {
        return Imf::MultiPartInputFile(mImpl->path.c_str()).parts();
    } catch (const std::exception&) {
        return 1;  // the first part was read; the rest is for messages only
    }
}

int ExrFile::partWithLayer(std::string_view layer) const {
    try {
        Imf::MultiPartInputFile file(mImpl->path.c_str());
        const std::string prefix = std::string(layer) + ".";
        for (int part = 0; part < file.parts(); ++part)
            for (auto it = file.header(part).channels().begin(); it != file.header(part).channels().end(); ++it) {
                const std::string name = it.name();
                if (name == layer || name.compare(0, prefix.size(), prefix) == 0) return part;
            }
    } catch (const std::exception&) {
    }
    return -1;
}

namespace {

std::string listLayers(const std::vector<std::string>& layers) {
    std::vector<std::string> quoted;
    for (const std::string& n : layers) quoted.push_back(n.empty() ? "channels without a layer" : "'" + n + "'");
    return join(quoted);
}

/// How to name a layer of `file`, with the first of its `layers` as the example.
std::string layerHint(const std::string& file, const std::vector<std::string>& layers) {
    for (const std::string& n : layers)
        if (!n.empty()) return "name the layer after the file name and a colon, e.g. '" + file + ":" + n + "'";
    return "name the layer after the file name and a colon (FILE.exr:LAYER)";
}

}  // namespace

void ExrFile::read(const std::vector<ExrChannelRead>& reads) {
    const Imath::Box2i& dw = mImpl->dataWindow;
    Imf::FrameBuffer frameBuffer;
    // OpenEXR reads a channel into one slice only: a channel read twice is read once and copied after.
    std::map<std::string, const ExrChannelRead*> first;
    std::vector<std::pair<const ExrChannelRead*, const ExrChannelRead*>> copies;
    std::vector<const ExrChannelRead*> fills;
    for (const ExrChannelRead& r : reads) {
        if (r.channel.empty() || !findChannel(r.channel)) {
            fills.push_back(&r);
            continue;
        }
        if (auto it = first.find(r.channel); it != first.end()) {
            copies.emplace_back(&r, it->second);
            continue;
        }
        first[r.channel] = &r;
        // Slice::Make offsets the base so that pixel (dw.min.x, dw.min.y) lands at r.base.
        frameBuffer.insert(r.channel, Imf::Slice::Make(r.asUint ? Imf::UINT : Imf::FLOAT, r.base, dw, r.xStride,
                                                       r.yStride, 1, 1, r.fill));
    }
    try {
        if (!first.empty()) {  // OpenEXR refuses to read into no slice at all
            mImpl->file->setFrameBuffer(frameBuffer);
            mImpl->file->readPixels(dw.min.y, dw.max.y);
        }
    } catch (const std::exception& e) {
        fail(mImpl->path, std::string("cannot read the EXR image's pixels: ") + e.what(), "a complete OpenEXR file",
             "the file is truncated or damaged; write it again");
    }
    const auto each = [&](const ExrChannelRead& r, const auto& f) {
        for (uint32_t y = 0; y < mImpl->height; ++y)
            for (uint32_t x = 0; x < mImpl->width; ++x) f(r.base + y * r.yStride + x * r.xStride, x, y);
    };
    for (const ExrChannelRead* r : fills) {
        each(*r, [&](std::byte* p, uint32_t, uint32_t) {
            if (r->asUint) {
                const uint32_t v = uint32_t(r->fill);
                std::memcpy(p, &v, 4);
            } else {
                const float v = float(r->fill);
                std::memcpy(p, &v, 4);
            }
        });
    }
    for (const auto& [to, from] : copies)
        each(*to, [&](std::byte* p, uint32_t x, uint32_t y) {
            std::memcpy(p, from->base + y * from->yStride + x * from->xStride, 4);
        });
}

Texture ExrFile::readRgba(std::string_view layer) {
    const std::vector<std::string> names = layerChannels(layer);
    if (names.empty())
        fail(mImpl->path,
             layer.empty()
                 ? "the image has no R, G, B, A or Y channel (it has " + listLayers(layers()) + ")"
                 : "the image has no layer '" + std::string(layer) + "' (it has " + listLayers(layers()) + ")",
             layer.empty() ? "channels named R, G, B and A" : "a layer of the file",
             layer.empty() ? layerHint(mImpl->path.string(), layers()) : didYouMean(layer, layers(), ""));
    for (const std::string& n : names)
        if (!n.empty() && findChannel(n)->type == ExrSampleType::Uint)
            fail(mImpl->path, "channel '" + n + "' holds UINT samples", "HALF or FLOAT colour samples");
    Texture tex(mImpl->width, mImpl->height, Format::RGBA32F);
    std::vector<ExrChannelRead> reads;
    const bool grey = names.size() == 1 && names[0] == "Y";
    for (size_t c = 0; c < 4; ++c) {
        const std::string& channel = grey && c < 3 ? names[0] : c < names.size() ? names[c] : std::string();
        reads.push_back({channel, tex.data() + 4 * c, 16, tex.rowPitch(), false, c == 3 ? 1.0 : 0.0});
    }
    read(reads);
    return tex;
}

}  // namespace loom
