#include "ImageSequencePass.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <map>

#include "ImageSequenceDevice.h"
#include "loom/Channels.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/Plugin.h"

namespace loom {

namespace fs = std::filesystem;
using sequence::MotionKind;

namespace {

/// What a consumed channel the sequence lacks becomes.
enum class Missing { Error, Fill, FillWithWarning };

struct OutputInfo {
    const char* name;
    Format format;
    const char* doc;
    Missing missing;
    float fill;            ///< every component of a missing channel (Fill*)
    float fillAlpha;       ///< the fourth component where the source has three
    const char* loomPass;  ///< the pass whose dump the loom preset reads it from ("" = none)
};

constexpr char kReference[] = "reference";

const std::array<OutputInfo, ImageSequencePass::kOutputCount> kOutputs = {{
    {channel::kColor, Format::RGBA32F, "noisy radiance (Blender: Noisy Image, else Combined)", Missing::Error, 0.f, 1.f,
     "PathTracer"},
    {channel::kAlbedo, Format::RGBA32F,
     "diffuse reflectance for demodulation (Blender: Denoising Albedo); 1 where the sequence has none (no "
     "demodulation, with a warning)",
     Missing::FillWithWarning, 1.f, 1.f, "PathTracer"},
    {channel::kSpecAlbedo, Format::RGBA32F, "specular albedo; 0 where the sequence has none", Missing::Fill, 0.f, 1.f,
     "PathTracer"},
    {channel::kEmission, Format::RGBA32F, "emitted radiance at the primary hit; 0 where the sequence has none",
     Missing::Fill, 0.f, 1.f, "PathTracer"},
    {channel::kNormW, Format::RGBA32F,
     "shading normal, world space (camera space turned with the file's worldToCamera; Blender: Normal, in "
     "Blender's Z-up world), rescaled to unit length where it is off by more than 1e-3; w = 0",
     Missing::Error, 0.f, 0.f, "GBuffer"},
    {channel::kLinearZ, Format::RG32F,
     "view depth (-1 on a miss) and its derivative; from a one-channel depth (Blender: Depth) the derivative is "
     "computed from neighbours",
     Missing::Error, 0.f, 0.f, "GBuffer"},
    {channel::kMvec, Format::RG32F, "uvPrev - uvCur (Blender: Vector, converted from pixels)", Missing::Error, 0.f, 0.f,
     "GBuffer"},
    {channel::kMeshId, Format::R32U, "object id for the disocclusion test (Blender: IndexOB); 0 where none",
     Missing::Fill, 0.f, 0.f, "GBuffer"},
    {channel::kGradient, Format::RG32F, "temporal gradients (Loom's own dumps); (0, 0), no samples, where none",
     Missing::Fill, 0.f, 0.f, "PathTracer"},
    {kReference, Format::RGBA32F, "a reference image of the frame, e.g. for ErrorMeasure", Missing::Error, 0.f, 1.f,
     ""},
}};

/// Blender's pass names for the blender preset ('|' separates alternatives: the first the file has is read).
constexpr std::array<const char*, ImageSequencePass::kOutputCount> kBlenderLayers = {
    "Noisy Image|Combined", "Denoising Albedo", "", "", "Normal", "Depth", "Vector", "IndexOB", "", ""};

std::vector<std::string> splitAlternatives(const std::string& s) {
    std::vector<std::string> out;
    size_t start = 0;
    while (true) {
        const size_t bar = s.find('|', start);
        out.push_back(s.substr(start, bar == std::string::npos ? std::string::npos : bar - start));
        if (bar == std::string::npos) return out;
        start = bar + 1;
    }
}

bool mentionsExr(const std::string& s) {
    std::string lower = s;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return lower.find(".exr") != std::string::npos;
}

std::string where(const std::string& param) {
    return "ImageSequence." + param;
}

}  // namespace

/// A channel's source once the files are known: the pattern, and the file's channel of each component ("" fills).
struct ImageSequencePass::Resolved {
    std::array<std::string, kOutputCount> pattern;  ///< empty: the sequence has no such channel
    std::array<std::vector<std::string>, kOutputCount> channels;
    std::array<std::string, kOutputCount> described;  ///< "file: layer (components)" for the log
    /// Where the sequence has no such channel because no alternative's file exists: the parameter that named the
    /// pattern ("path", or the channel's), and the file of the first frame; empty otherwise.
    std::array<std::string, kOutputCount> absentParam, absentFile;
};

ImageSequencePass::ImageSequencePass() = default;
ImageSequencePass::~ImageSequencePass() = default;

void ImageSequencePass::reflect(Reflection& r, const CompileInfo&) const {
    for (const OutputInfo& o : kOutputs) r.output(o.name, o.format).optional().doc(o.doc);
}

void ImageSequencePass::declareParams(ParamList& p) {
    p.addEnum("preset", &mPreset, Preset::Blender, {"none", "loom", "blender"})
        .doc(
            "where each channel comes from unless its own parameter says: blender = one multilayer EXR per frame "
            "(path) with a Cycles View Layer's passes (Noisy Image or Combined, Denoising Albedo, Normal, Depth, "
            "Vector, IndexOB); loom = the files `loom render --dump` writes into the folder path "
            "(PathTracer.<channel>.NNNN.exr, GBuffer.<channel>.NNNN.exr); none = only the channel parameters");
    p.add("path", &mPath, std::string())
        .doc(
            "blender and none: the numbered multilayer file, e.g. frames/noisy_####.exr or beauty.%04d.exr (#### "
            "and %04d stand for the frame number); loom: the folder of the dumps");
    p.add("layer", &mLayer, std::string("ViewLayer"))
        .doc("the View Layer prefixed to layer names given without a file (\"\" for files whose layers have none)");
    for (int o = 0; o < kOutputCount; ++o)
        p.add(kOutputs[size_t(o)].name, &mSource[size_t(o)], std::string())
            .doc(fmt::format(
                "source of {}: \"\" = the preset's; \"none\" = not in the sequence; a layer of path's file "
                "(\"Denoising "
                "Normal\"), or PATTERN:LAYER for another file (\"refs/ref_####.exr:ViewLayer.Combined\"; no layer = R, "
                "G, B, A); '|' separates alternatives, the first found is read",
                kOutputs[size_t(o)].name));
    p.add("firstFrame", &mFirstFrame, 0)
        .range(0, 1e9)
        .doc("the file number of the graph's frame 0 (Blender numbers frames from 1)");
    p.addEnum("normals", &mNormals, NormalSpace::Auto, {"auto", "world", "camera"})
        .doc(
            "space of the normals: camera ones are turned into world space with the file's worldToCamera attribute "
            "(without it they stay in camera space, which only the temporal normal test notices); auto = world");
    p.addEnum("depth", &mDepth, DepthKind::Auto, {"auto", "linearZ", "depth"})
        .doc(
            "linearZ = Loom's two channels (depth, derivative); depth = one channel of distance along the camera "
            "axis, at least missDepth where there is no surface; auto = linearZ for loom, depth for blender");
    p.add("missDepth", &mMissDepth, 1e9f)
        .range(1e-3, 3.4e38)
        .doc("depth: values at or above this (Blender writes 1e10 on the background) are misses");
    p.addEnum("motion", &mMotion, Motion::Auto, {"auto", "uv", "pixelsFromPrevious", "pixelsToPrevious"})
        .doc(
            "motion vectors (the first two components): uv = Loom's uvPrev - uvCur; pixelsToPrevious = previous "
            "minus current position in pixels (Blender's Vector); pixelsFromPrevious = current minus previous in "
            "pixels; auto = uv for loom, pixelsToPrevious for blender");
    p.addEnum("motionY", &mMotionY, MotionY::Auto, {"auto", "down", "up"})
        .doc("direction of the motion's +y in the image: down (Loom) or up (Blender); auto = the preset's");
}

ImageSequencePass::Settings ImageSequencePass::settings() const {
    Settings s;
    s.path = mPath;
    s.layerPrefix = mLayer;
    s.firstFrame = mFirstFrame;
    s.missDepth = mMissDepth;
    const bool blender = mPreset == Preset::Blender;
    s.normals = mNormals == NormalSpace::Camera ? NormalSpace::Camera : NormalSpace::World;
    s.depth = mDepth != DepthKind::Auto ? mDepth : blender ? DepthKind::Depth : DepthKind::LinearZ;
    s.motion = mMotion != Motion::Auto ? sequence::MotionKind(int(mMotion) - 1)
               : blender               ? MotionKind::PixelsToPrevious
                                       : MotionKind::Uv;
    s.motionYUp = mMotionY != MotionY::Auto ? mMotionY == MotionY::Up : blender;
    for (int o = 0; o < kOutputCount; ++o) {
        const size_t i = size_t(o);
        if (!mSource[i].empty()) {
            s.source[i] = mSource[i] == "none" ? std::string() : mSource[i];
            s.optional[i] = false;
            continue;
        }
        s.optional[i] = true;
        if (blender) {
            s.source[i] = kBlenderLayers[i];
        } else if (mPreset == Preset::Loom && *kOutputs[i].loomPass) {
            // The folder's own '%' are literal ("%%"); its '#' are, as the pattern has a printf field.
            std::string folder;
            for (const char c : mPath) folder += c == '%' ? std::string("%%") : std::string(1, c);
            s.source[i] =
                (fs::path(folder) / fmt::format("{}.{}.%04d.exr", kOutputs[i].loomPass, kOutputs[i].name)).string() +
                ":";
        }
    }
    return s;
}

namespace {

/// The file has no layer `layer` for `channel`: what it has, and how to name one.
[[noreturn]] void missingLayer(const ExrFile& exr, const std::string& layer, const char* channel,
                               const std::string& at) {
    const std::string file = exr.path().string();
    std::vector<std::string> named;
    for (const std::string& l : exr.layers())
        if (!l.empty()) named.push_back(l);
    std::vector<std::string> quoted;
    for (const std::string& l : exr.layers()) quoted.push_back(l.empty() ? "R, G, B, A" : "'" + l + "'");
    if (layer.empty())
        throwBadInput(at,
                      fmt::format("the layer for {} is empty, which reads the channels R, G, B, A (or Y), and the "
                                  "file has none (it has {})",
                                  channel, join(quoted)),
                      "PATTERN:LAYER with the layer after the colon",
                      named.empty() ? std::string("name a layer of the file after the colon")
                                    : fmt::format("write the layer after the colon, e.g. PATTERN:{}", named.front()),
                      file);
    if (const int part = layer.empty() ? -1 : exr.partWithLayer(layer); part > 0)
        throwBadInput(at,
                      fmt::format("the layer '{}' for {} is in part {} of the file's {} parts, and only the first "
                                  "part is read (it has {})",
                                  layer, channel, part + 1, exr.partCount(), join(quoted)),
                      "the layers of a sequence in the first part of each file",
                      "write the frames as single-part multilayer EXRs (or with this layer in the first part)", file);
    throwBadInput(at, fmt::format("the file has no layer '{}' for {} (it has {})", layer, channel, join(quoted)),
                  "a layer of the file", didYouMean(layer, exr.layers(), ""), file);
}

}  // namespace

ImageSequencePass::Resolved ImageSequencePass::resolve(const Settings& s, int64_t number) {
    Resolved out;
    std::map<std::string, std::unique_ptr<ExrFile>> files;
    const auto open = [&](const std::string& path) -> ExrFile* {
        auto& f = files[path];
        if (!f) f = std::make_unique<ExrFile>(path);
        return f.get();
    };
    for (int o = 0; o < kOutputCount; ++o) {
        const size_t i = size_t(o);
        if (s.source[i].empty()) continue;
        std::vector<std::string> tried;
        bool onlyAbsentFiles = true;
        std::string absentParam, absentFile;
        for (const std::string& alternative : splitAlternatives(s.source[i])) {
            std::string pattern, layer;
            if (mentionsExr(alternative)) {
                const SequenceSource src = parseSequenceSource(alternative);
                pattern = src.pattern;
                layer = src.layer;
            } else {
                if (s.path.empty())
                    throwBadInput(where("path"),
                                  fmt::format("{} is read from the layer '{}' of path, and path is empty",
                                              kOutputs[i].name, alternative),
                                  "the numbered EXR file of each frame",
                                  "set path, e.g. --set Frames.path=frames/####.exr");
                pattern = s.path;
                layer = s.layerPrefix.empty() || alternative.empty() ? alternative : s.layerPrefix + "." + alternative;
            }
            // The preset's own patterns come from path (the loom preset's too); a channel parameter names its own.
            const std::string param = s.optional[i] || !mentionsExr(alternative) ? "path" : kOutputs[i].name;
            const std::string file = sequenceFramePath(pattern, number, where(param));
            if (s.optional[i]) {
                if (const std::string absent = fileAbsence(file); !absent.empty()) {
                    const std::string entry = fmt::format("{} {}", file, absent);
                    if (std::find(tried.begin(), tried.end(), entry) == tried.end()) tried.push_back(entry);
                    if (absentParam.empty()) {
                        absentParam = param;
                        absentFile = file;
                    }
                    continue;
                }
            }
            ExrFile* exr = open(file);
            std::vector<std::string> channels = exr->layerChannels(layer);
            if (channels.empty()) {
                if (s.optional[i]) {
                    onlyAbsentFiles = false;
                    const int part = layer.empty() ? -1 : exr->partWithLayer(layer);
                    tried.push_back(part > 0 ? fmt::format("layer '{}' in part {} of {}, and only the first part is "
                                                           "read: write single-part multilayer EXRs",
                                                           layer, part + 1, file)
                                             : fmt::format("no layer '{}' in {}", layer, file));
                    continue;
                }
                missingLayer(*exr, layer, kOutputs[i].name, where(kOutputs[i].name));
            }
            out.pattern[i] = pattern;
            out.channels[i] = std::move(channels);
            // "ViewLayer.Vector (X Y Z W)": the channels by their component names.
            std::vector<std::string> shown;
            for (const std::string& c : out.channels[i]) {
                const size_t dot = c.rfind('.');
                shown.push_back(c.empty() ? "-" : dot == std::string::npos ? c : c.substr(dot + 1));
            }
            const size_t dot = out.channels[i].front().rfind('.');
            const std::string prefix = dot == std::string::npos ? "" : out.channels[i].front().substr(0, dot) + " ";
            out.described[i] = fmt::format("{}({})", prefix, join(shown, " "));
            break;
        }
        if (out.pattern[i].empty() && !tried.empty()) {
            out.described[i] = fmt::format("not in the sequence ({})", join(tried, "; "));
            if (onlyAbsentFiles) {
                out.absentParam[i] = absentParam;
                out.absentFile[i] = absentFile;
            }
        }
    }
    return out;
}

namespace {

/// An error reading one frame's file (the pass adds the graph frame and the file number).
[[noreturn]] void frameError(const std::string& file, const std::string& what, const std::string& expected,
                             const std::string& suggestion = {}) {
    throwBadInput("ImageSequence", what, expected, suggestion, file);
}

/// A frame of another size than the graph's: the --size to render at, or, when the sequence's own frames differ
/// (this one and the first), that they do.
[[noreturn]] void sizeError(const ImageSequencePass::Settings& s, const std::string& pattern, const ExrFile& exr,
                            uint32_t width, uint32_t height) {
    const std::string file = exr.path().string();
    const std::string what =
        fmt::format("the image is {}x{}, the graph renders {}x{}", exr.width(), exr.height(), width, height);
    const std::string first = sequenceFramePath(pattern, s.firstFrame, where("path"));
    if (first != file && fileAbsence(first).empty()) {
        const ExrFile firstExr(first);
        if (firstExr.width() != exr.width() || firstExr.height() != exr.height())
            frameError(file,
                       fmt::format("{}, and the sequence's frames differ in size: its first frame, {}, is {}x{}", what,
                                   first, firstExr.width(), firstExr.height()),
                       "every frame of the sequence at one size",
                       fmt::format("write the sequence again at one size, or render only the frames of one size "
                                   "(--frames, firstFrame); --size {}x{} fits the first frame",
                                   firstExr.width(), firstExr.height()));
    }
    frameError(file, what, "frames of the graph's size",
               fmt::format("render at the sequence's size: --size {}x{}, or no --size", exr.width(), exr.height()));
}

}  // namespace

ImageSequencePass::Frame ImageSequencePass::readFrame(const Settings& s, const Resolved& r, int64_t number,
                                                      uint32_t width, uint32_t height,
                                                      const std::array<bool, kOutputCount>& wanted) {
    Frame frame;
    frame.number = number;
    // The reads of each file, so every file is opened and decoded once.
    std::map<std::string, std::vector<ExrChannelRead>> reads;
    std::map<std::string, std::unique_ptr<ExrFile>> files;
    std::array<Texture, kOutputCount> floatIds;  // a float object index, before it becomes a mesh id
    for (int o = 0; o < kOutputCount; ++o) {
        const size_t i = size_t(o);
        if (!wanted[i] || r.pattern[i].empty()) continue;
        const std::string file = sequenceFramePath(r.pattern[i], number, where(kOutputs[i].name));
        auto& exr = files[file];
        if (!exr) {
            if (const std::string absent = fileAbsence(file); !absent.empty())
                frameError(file, fmt::format("the file of {} {}", kOutputs[i].name, absent),
                           fmt::format("file {} for every frame the graph renders", r.pattern[i]),
                           "render fewer frames (--frames), or check firstFrame and the numbering");
            exr = std::make_unique<ExrFile>(file);
            if (exr->width() != width || exr->height() != height) sizeError(s, r.pattern[i], *exr, width, height);
        }
        const OutputInfo& info = kOutputs[i];
        const std::vector<std::string>& channels = r.channels[i];
        bool allUint = true;
        for (const std::string& c : channels) {
            if (c.empty()) continue;
            const ExrChannel* ch = exr->findChannel(c);
            if (!ch)
                frameError(file, fmt::format("the file has no channel '{}' for {}", c, info.name),
                           "the same channels in every frame");
            allUint = allUint && ch->type == ExrSampleType::Uint;
            if (ch->type == ExrSampleType::Uint && isFloatFormat(info.format))
                frameError(file, fmt::format("channel '{}' holds UINT samples; {} needs HALF or FLOAT", c, info.name),
                           "HALF or FLOAT samples", "map the channel to a layer of float samples");
        }
        const bool depthOnly = o == LinearZ && s.depth == DepthKind::Depth;
        const bool idFromFloat = o == MeshId && !allUint;
        Texture& tex = frame.channels[i];
        tex = Texture(width, height, info.format);
        Texture* target = &tex;
        if (idFromFloat) target = &(floatIds[i] = Texture(width, height, Format::R32F));
        const uint32_t components = formatInfo(target->format()).channels;
        for (uint32_t c = 0; c < components; ++c) {
            std::string channel = c < channels.size() && !(depthOnly && c > 0) ? channels[c] : std::string();
            const double fill = c == 3 ? info.fillAlpha : 0.0;
            reads[file].push_back({channel, target->data() + 4 * c, formatInfo(target->format()).bytesPerPixel,
                                   target->rowPitch(), !isFloatFormat(target->format()), fill});
        }
    }
    for (auto& [file, list] : reads) files[file]->read(list);

    // Conversions, with the count of what was not finite or out of range.
    if (!frame.channels[MeshId].empty() && !floatIds[MeshId].empty()) {
        const auto src = floatIds[MeshId].view<float>();
        const auto dst = frame.channels[MeshId].view<uint32_t>();
        for (uint32_t y = 0; y < height; ++y)
            for (uint32_t x = 0; x < width; ++x) dst.at(x, y) = sequence::objectIndexToMeshId(src.at(x, y));
    }
    sequence::FrameChannels channels;
    const auto present = [&](int o) {
        return frame.channels[size_t(o)].empty() ? nullptr : &frame.channels[size_t(o)];
    };
    channels.normW = present(NormW);
    channels.linearZ = present(LinearZ);
    channels.mvec = present(Mvec);
    for (int o : {Albedo, SpecAlbedo})
        if (Texture* t = present(o)) channels.reflectances.push_back(t);
    for (int o : {Color, Emission, Gradient, Reference})
        if (Texture* t = present(o)) channels.others.push_back(t);
    sequence::ConversionSettings conversion;
    conversion.depthFromOneChannel = s.depth == DepthKind::Depth;
    conversion.missDepth = s.missDepth;
    conversion.motion = s.motion;
    conversion.motionYUp = s.motionYUp;
    if (channels.normW && s.normals == NormalSpace::Camera) {
        const std::string file = sequenceFramePath(r.pattern[NormW], number, "");
        conversion.worldToCamera = files[file]->worldToCamera();
        if (conversion.worldToCamera)
            sequence::requireUsableWorldToCamera(*conversion.worldToCamera, where("normals"), file);
        else
            frame.cameraNormalsKept = true;
    }
    const sequence::Replaced replaced = sequence::convertFrame(channels, conversion);
    frame.nonFinite = replaced.nonFinite;
    frame.outOfRange = replaced.outOfRange;
    return frame;
}

void ImageSequencePass::compile(const CompileInfo& info) {
    mWidth = info.frameWidth;
    mHeight = info.frameHeight;
    // Only an output something reads must come from the sequence; one that is only observed (a dump, the viewer)
    // shows what the sequence lacks as zeros. Observing a read output changes nothing.
    for (int o = 0; o < kOutputCount; ++o) mConsumed[size_t(o)] = info.isOutputRead(kOutputs[size_t(o)].name);
    mPending.reset();  // a read of another size or of other channels
}

ImageSequencePass::Frame ImageSequencePass::take(int64_t number, const Settings& s,
                                                 const std::array<bool, kOutputCount>& wanted) {
    if (!mResolved || !(mResolvedFor == s)) {
        mPending.reset();
        mResolved = std::make_unique<Resolved>(resolve(s, number));
        mResolvedFor = s;
        mLogged = false;
    }
    if (mPending) {
        std::unique_ptr<Pending> p = std::move(mPending);
        if (p->number == number && p->wanted == wanted && p->width == mWidth && p->height == mHeight)
            return p->frame.get();  // rethrows what the read threw
        if (p->frame.valid()) p->frame.wait();
    }
    return readFrame(s, *mResolved, number, mWidth, mHeight, wanted);
}

void ImageSequencePass::prefetch(int64_t number, const Settings& s, const std::array<bool, kOutputCount>& wanted) {
    auto p = std::make_unique<Pending>();
    p->number = number;
    p->wanted = wanted;
    p->width = mWidth;
    p->height = mHeight;
    p->frame = std::async(std::launch::async, [s, r = *mResolved, number, w = mWidth, h = mHeight, wanted] {
        return readFrame(s, r, number, w, h, wanted);
    });
    mPending = std::move(p);
}

std::optional<glm::uvec2> ImageSequencePass::naturalSize() const {
    const Settings s = settings();
    const Resolved r = resolve(s, s.firstFrame);
    for (int o = 0; o < kOutputCount; ++o) {
        const size_t i = size_t(o);
        if (r.pattern[i].empty()) continue;
        const ExrFile exr(sequenceFramePath(r.pattern[i], s.firstFrame, where(kOutputs[i].name)));
        return glm::uvec2(exr.width(), exr.height());
    }
    // Every source the sequence names is absent: the first frame's files are not there.
    for (int o = 0; o < kOutputCount; ++o) {
        const size_t i = size_t(o);
        if (r.absentParam[i].empty()) continue;
        const std::string& param = r.absentParam[i];
        throwBadInput(where(param),
                      fmt::format("the frame size is that of the sequence's first frame (file {}), and its file {}: "
                                  "{}",
                                  s.firstFrame, fileAbsence(r.absentFile[i]), r.absentFile[i]),
                      mPreset == Preset::Loom && param == "path"
                          ? std::string("the folder of `loom render --dump`'s files")
                          : "a numbered file for each frame (#### or %04d stands for the frame number)",
                      fmt::format("check {} ('{}') and firstFrame ({}, the file number of graph frame 0)", param,
                                  param == "path" ? mPath : mSource[i], s.firstFrame));
    }
    return std::nullopt;  // every channel is "none"
}

bool ImageSequencePass::runsOn(DeviceKind device) const {
    return device == DeviceKind::Cpu || sequence::deviceRuns(device);
}

void ImageSequencePass::execute(PassContext& ctx) {
    const Settings s = settings();
    std::array<bool, kOutputCount> wanted{};
    for (int o = 0; o < kOutputCount; ++o) wanted[size_t(o)] = ctx.output(kOutputs[size_t(o)].name) != nullptr;
    const int64_t number = int64_t(s.firstFrame) + int64_t(ctx.frameIndex());
    Frame frame;
    try {
        frame = take(number, s, wanted);
    } catch (const Error& e) {
        // The reader names parameters by the pass type, and files by name; the graph knows this pass by its name and
        // the frame by its index.
        Error::Info info = e.info();
        const std::string type = "ImageSequence";
        if (info.where.compare(0, type.size(), type) == 0) info.where = ctx.passName() + info.where.substr(type.size());
        if (info.where.empty()) info.where = ctx.passName();
        info.what = fmt::format("graph frame {} (sequence frame {}): {}", ctx.frameIndex(), number, info.what);
        throw Error(info);
    }
    if (!mLogged) {
        mLogged = true;
        // One line per file pattern, then what the sequence lacks.
        std::map<std::string, std::vector<std::string>> byPattern;
        std::vector<std::string> absent;
        for (int o = 0; o < kOutputCount; ++o) {
            const size_t i = size_t(o);
            if (!wanted[i]) continue;
            if (mResolved->pattern[i].empty())
                absent.push_back(kOutputs[i].name);
            else
                byPattern[mResolved->pattern[i]].push_back(
                    fmt::format("{} <- {}", kOutputs[i].name, mResolved->described[i]));
        }
        for (const auto& [pattern, lines] : byPattern)
            spdlog::info("{}: {} (graph frame {} is file {}): {}", ctx.passName(), pattern, ctx.frameIndex(), number,
                         join(lines, ", "));
        if (!absent.empty()) spdlog::info("{}: not in the sequence: {}", ctx.passName(), join(absent));
        if (frame.cameraNormalsKept)
            spdlog::warn(
                "{}: the normals are in camera space and the files have no worldToCamera attribute: they stay in "
                "camera space (the spatial filter does not mind; the temporal normal test compares frames whose "
                "cameras turned)",
                ctx.passName());
    }
    const bool onDevice = ctx.device() != DeviceKind::Cpu;
    for (int o = 0; o < kOutputCount; ++o) {
        const size_t i = size_t(o);
        Texture* out = ctx.output(kOutputs[i].name);
        if (!out) continue;
        // On a device, the frame is read and converted on the host as on the CPU, and each output goes up once.
        if (!frame.channels[i].empty()) {
            if (onDevice)
                copyTexture(*out, frame.channels[i]);
            else
                out->copyFrom(frame.channels[i]);
            continue;
        }
        const OutputInfo& info = kOutputs[i];
        // Observed only (a dump, the viewer): what the sequence lacks shows as the fill, or as zeros.
        const Missing missing = mConsumed[i] ? info.missing : Missing::Fill;
        const float fill = mConsumed[i] || info.missing != Missing::Error ? info.fill : 0.f;
        if (missing == Missing::Error && !mResolved->absentParam[i].empty()) {
            // The files themselves are not there: the pattern (or firstFrame) is what to change.
            const std::string& param = mResolved->absentParam[i];
            const std::string pattern = param == "path" ? mPath : mSource[i];
            throwBadInput(fmt::format("{}.{}", ctx.passName(), param),
                          fmt::format("the graph reads {}.{}, and its file of graph frame {} (sequence frame {}) "
                                      "{}: {}",
                                      ctx.passName(), info.name, ctx.frameIndex(), number,
                                      fileAbsence(mResolved->absentFile[i]), mResolved->absentFile[i]),
                          param == "path" && mPreset == Preset::Loom
                              ? std::string("the folder of `loom render --dump`'s files")
                              : "a numbered file for each frame (#### or %04d stands for the frame number)",
                          fmt::format("check {}.{} ('{}') and {}.firstFrame ({}, the sequence frame of graph "
                                      "frame 0)",
                                      ctx.passName(), param, pattern, ctx.passName(), s.firstFrame));
        }
        if (missing == Missing::Error)
            throwBadInput(fmt::format("{}.{}", ctx.passName(), info.name),
                          fmt::format("the graph reads {}.{}, and the sequence has none: {}", ctx.passName(), info.name,
                                      mResolved->described[i].empty() ? "no source given" : mResolved->described[i]),
                          fmt::format("a source of {}", info.name),
                          fmt::format("set it, e.g. --set {}.{}=LAYER or PATTERN:LAYER", ctx.passName(), info.name));
        if (!mConsumed[i] && info.missing == Missing::Error && !mFillWarned[i]) {
            mFillWarned[i] = true;
            spdlog::warn("{}: the sequence has no {}; the dump shows zeros", ctx.passName(), info.name);
        }
        if (missing == Missing::FillWithWarning && !mFillWarned[i]) {
            mFillWarned[i] = true;
            spdlog::warn(
                "{}: the sequence has no {}: it is {} everywhere, so the denoiser filters without "
                "demodulation (textures get blurred)",
                ctx.passName(), info.name, info.fill);
        }
        Texture* filled = out;
        if (onDevice) {
            Texture& staging = mStaging[i];
            if (staging.width() != out->width() || staging.height() != out->height() ||
                staging.format() != out->format())
                staging = Texture(out->width(), out->height(), out->format());
            filled = &staging;
        }
        const uint32_t components = formatInfo(filled->format()).channels;
        for (uint32_t y = 0; y < filled->height(); ++y) {
            std::byte* row = filled->row(y);
            for (uint32_t k = 0; k < filled->width() * components; ++k) {
                if (isFloatFormat(filled->format())) {
                    const float v = fill;
                    std::memcpy(row + 4 * k, &v, 4);
                } else {
                    const uint32_t v = uint32_t(fill);
                    std::memcpy(row + 4 * k, &v, 4);
                }
            }
        }
        if (onDevice) copyTexture(*out, *filled);
    }
    ctx.stats().set("nonFinite", double(frame.nonFinite));
    ctx.stats().set("outOfRange", double(frame.outOfRange));
    if (frame.outOfRange > 0 && !mOutOfRangeWarned) {
        mOutOfRangeWarned = true;
        spdlog::warn(
            "{}: frame {} holds {} values out of range; they are clamped (albedos into [0, {}], motion into +-{} "
            "frames); the stat outOfRange counts them every frame",
            ctx.passName(), number, frame.outOfRange, sequence::kMaxReflectance, sequence::kMaxMotionUv);
    }
    if (frame.nonFinite > 0 && !mNonFiniteWarned) {
        mNonFiniteWarned = true;
        spdlog::warn(
            "{}: frame {} holds {} non-finite samples; they read as 0 (a depth as a miss); the stat "
            "nonFinite counts them every frame",
            ctx.passName(), number, frame.nonFinite);
    }
    prefetch(number + 1, s, wanted);
}

}  // namespace loom

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<loom::ImageSequencePass>(
        "ImageSequence",
        "Frames read from EXR files (another renderer's, or Loom's own dumps) into the standard channels, so the "
        "denoising graphs take them unchanged: a numbered file pattern and a layer per channel, presets for "
        "Blender's multilayer EXRs and Loom's dumps, conversions of normals, depth and motion; the next frame is "
        "read on a background thread. Stats: nonFinite (samples that were NaN or infinite and read as 0).");
}
