// Scene::load: glTF 2.0 (.gltf and .glb) through tinygltf (Debian's shared
// library build: no TINYGLTF_IMPLEMENTATION here, and it decodes images with
// libstb). tinygltf parses; everything it leaves unchecked (accessor ranges,
// index values, NaNs, degenerate triangles, ...) is validated here before it
// is read, and every problem is reported as a loom::Error or a warning that
// names the glTF object it is about.
#include <spdlog/spdlog.h>
#include <stb/stb_image.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <glm/gtc/type_ptr.hpp>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <set>
#include <type_traits>

#include "loom/Error.h"
#include "loom/ImageIO.h"
#include "loom/InputFile.h"
#include "loom/RayScene.h"
#include "loom/Scene.h"

namespace loom {

namespace {

namespace fs = std::filesystem;

/// Required extensions Loom implements. KHR_mesh_quantization only widens the
/// accessor types allowed for attributes, which the accessor reader handles.
const std::vector<std::string> kSupportedRequired = {"KHR_materials_emissive_strength",
                                                     "KHR_lights_punctual",
                                                     "KHR_mesh_quantization",
                                                     "KHR_texture_transform",
                                                     "KHR_materials_ior",
                                                     "KHR_materials_specular",
                                                     "KHR_animation_pointer"};

constexpr const char* kAnimationPointer = "KHR_animation_pointer";

std::string labelOf(const char* kind, size_t index, const std::string& name) {
    std::string s = std::string(kind) + "[" + std::to_string(index) + "]";
    if (!name.empty()) s += " '" + name + "'";
    return s;
}

void checkRequiredExtensions(const std::vector<std::string>& required, const std::string& file) {
    for (const std::string& ext : required) {
        if (std::find(kSupportedRequired.begin(), kSupportedRequired.end(), ext) != kSupportedRequired.end()) continue;
        std::string hint = "re-export the file without " + ext;
        if (ext == "KHR_draco_mesh_compression" || ext == "EXT_meshopt_compression")
            hint += " (uncompressed geometry), e.g. with gltf-transform";
        throwBadInput("extensionsRequired", "the file requires extension '" + ext + "', which Loom does not support",
                      "only these required extensions: " + join(kSupportedRequired), hint, file);
    }
}

// ---------------------------------------------------------------------------
// KHR_animation_pointer

/// An animation channel whose target path is "pointer", as the JSON gives it. tinygltf 2.7 drops channels without a
/// target node (and later versions keep them without their pointer's meaning), so Loom reads these from the JSON.
struct PointerChannel {
    size_t animation = 0, channel = 0;
    int64_t sampler = -1;                // -1: absent or not an integer
    std::optional<std::string> pointer;  // absent or not a string: nullopt
};

/// The pointer channels of a glTF JSON text (one already checked to parse). The text is parsed again only when it
/// names a pointer at all.
std::vector<PointerChannel> readPointerChannels(std::string_view text) {
    std::vector<PointerChannel> out;
    if (text.find("\"pointer\"") == std::string_view::npos) return out;
    const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
    if (!j.is_object() || !j.contains("animations") || !j["animations"].is_array()) return out;
    const auto& animations = j["animations"];
    for (size_t a = 0; a < animations.size(); ++a) {
        if (!animations[a].is_object() || !animations[a].contains("channels") || !animations[a]["channels"].is_array())
            continue;
        const auto& channels = animations[a]["channels"];
        for (size_t c = 0; c < channels.size(); ++c) {
            const auto& ch = channels[c];
            if (!ch.is_object() || !ch.contains("target") || !ch["target"].is_object()) continue;
            const auto& target = ch["target"];
            if (!target.contains("path") || target["path"] != "pointer") continue;
            PointerChannel pc;
            pc.animation = a;
            pc.channel = c;
            if (ch.contains("sampler") && ch["sampler"].is_number_integer()) pc.sampler = ch["sampler"].get<int64_t>();
            const nlohmann::json* ext = nullptr;
            if (target.contains("extensions") && target["extensions"].is_object() &&
                target["extensions"].contains(kAnimationPointer))
                ext = &target["extensions"][kAnimationPointer];
            if (ext && ext->is_object() && ext->contains("pointer") && (*ext)["pointer"].is_string())
                pc.pointer = (*ext)["pointer"].get<std::string>();
            out.push_back(std::move(pc));
        }
    }
    return out;
}

/// What a supported JSON pointer animates: the path, the kind of object and the object's index token.
struct PointerTarget {
    AnimPath path = AnimPath::Translation;
    const char* kind = "";  // "nodes", "materials" or "KHR_lights_punctual lights"
    std::string index;      // the reference token that names the object (checked by the caller)
};

/// The pointer's target when Loom animates it: node TRS, a material's emissiveFactor or emissiveStrength, a punctual
/// light's intensity or color. JSON pointers are RFC 6901: "/"-separated tokens with ~1 for "/" and ~0 for "~".
std::optional<PointerTarget> supportedPointer(const std::string& pointer) {
    if (pointer.empty() || pointer[0] != '/') return std::nullopt;
    std::vector<std::string> tokens;
    for (size_t at = 1;;) {
        const size_t end = pointer.find('/', at);
        std::string token = pointer.substr(at, end == std::string::npos ? std::string::npos : end - at);
        for (size_t k = 0; (k = token.find('~', k)) != std::string::npos; ++k)
            if (k + 1 < token.size() && (token[k + 1] == '0' || token[k + 1] == '1'))
                token.replace(k, 2, token[k + 1] == '0' ? "~" : "/");
        tokens.push_back(std::move(token));
        if (end == std::string::npos) break;
        at = end + 1;
    }
    const auto is = [&](std::initializer_list<const char*> pattern) {
        if (tokens.size() != pattern.size()) return false;
        size_t k = 0;
        for (const char* p : pattern) {
            if (p && tokens[k] != p) return false;
            ++k;
        }
        return true;
    };
    PointerTarget t;
    if (is({"nodes", nullptr, "translation"}) || is({"nodes", nullptr, "rotation"}) ||
        is({"nodes", nullptr, "scale"})) {
        t.kind = "nodes";
        t.path = tokens[2] == "translation" ? AnimPath::Translation
                 : tokens[2] == "rotation"  ? AnimPath::Rotation
                                            : AnimPath::Scale;
        t.index = tokens[1];
    } else if (is({"materials", nullptr, "emissiveFactor"})) {
        t.kind = "materials";
        t.path = AnimPath::EmissiveColor;
        t.index = tokens[1];
    } else if (is({"materials", nullptr, "extensions", "KHR_materials_emissive_strength", "emissiveStrength"})) {
        t.kind = "materials";
        t.path = AnimPath::EmissiveStrength;
        t.index = tokens[1];
    } else if (is({"extensions", "KHR_lights_punctual", "lights", nullptr, "intensity"}) ||
               is({"extensions", "KHR_lights_punctual", "lights", nullptr, "color"})) {
        t.kind = "KHR_lights_punctual lights";
        t.path = tokens[4] == "intensity" ? AnimPath::LightIntensity : AnimPath::LightColor;
        t.index = tokens[3];
    } else {
        return std::nullopt;
    }
    return t;
}

// ---------------------------------------------------------------------------
// Image decoding (replaces tinygltf's default loader)

/// A glTF image as the image callback leaves it: its header read and checked, its encoded bytes kept (a view into a
/// glTF buffer, or a copy of a file or data URI, which tinygltf frees), decoded later by Importer::convertImages, once
/// every image's size is known to fit the limits. Loom keeps the texels here rather than in tinygltf::Image so that
/// they are moved, not copied, into Scene::images.
struct PendingImage {
    uint32_t width = 0, height = 0;
    const unsigned char* encoded = nullptr;  ///< into a glTF buffer, or into `copy`
    size_t encodedSize = 0;
    std::vector<unsigned char> copy;
    int sameAs = -1;  ///< another glTF image with the same file: decoded once, shared
};

/// Shared with the image callback: tinygltf parses buffers and bufferViews
/// before images, so the callback can check an image's bufferView against
/// its buffer before reading it (tinygltf does not).
struct ImageLoadContext {
    const tinygltf::Model* model = nullptr;
    const SceneLoadOptions* options = nullptr;
    std::string file;
    std::vector<std::string> failures;  ///< per glTF image: why it cannot be decoded ("" = fine)
    std::vector<PendingImage> pending;  ///< per glTF image
    std::map<std::string, int> byUri;   ///< external image file -> the first glTF image that names it
    uint64_t textureBytes = 0;          ///< the decoded size of every image accepted so far
    std::optional<Error> fatal;         ///< a limit exceeded: loading stops with this error
};

std::string mib(uint64_t bytes) {
    return std::to_string((bytes + (uint64_t(1) << 19)) >> 20) + " MiB";
}

/// "images[3] 'name' (file 'brick.png')": how errors about a glTF image name it.
std::string imageLabel(size_t index, const tinygltf::Image& image) {
    std::string label = labelOf("images", index, image.name);
    if (!image.uri.empty() && image.uri.rfind("data:", 0) != 0) label += " (file '" + image.uri + "')";
    return label;
}

std::string decodeFailure(const unsigned char* bytes, size_t size) {
    return "cannot decode the image: " + describeImageDecodeFailure(bytes, size, stbi_failure_reason()) +
           "; PNG and JPEG are supported";
}

/// tinygltf's image callback. Reads the image's header (stb) and checks its size against the options' limits and
/// the scene's texture budget, so that a small file claiming a huge image is refused before anything is decoded or
/// allocated; exceeding a limit stops loading with an error naming the image. Data whose header cannot be read is
/// recorded, and the materials that use the image report it.
bool inspectImage(tinygltf::Image* image, const int index, std::string* /*err*/, std::string* /*warn*/,
                  int /*reqWidth*/, int /*reqHeight*/, const unsigned char* bytes, int size, void* user) {
    auto* ctx = static_cast<ImageLoadContext*>(user);
    if (index < 0) return true;
    const size_t i = size_t(index);
    if (i >= ctx->failures.size()) {
        ctx->failures.resize(i + 1);
        ctx->pending.resize(i + 1);
    }
    auto fail = [&](std::string why) {
        ctx->failures[i] = std::move(why);
        return true;  // reported by the materials that use the image
    };
    const SceneLoadOptions& limits = *ctx->options;
    auto fatal = [&](std::string what, std::string expected, std::string suggestion) {
        ctx->fatal = Error(Error::Info{ErrorKind::BadInput, ctx->file, imageLabel(i, *image), std::move(what),
                                       std::move(expected), std::move(suggestion)});
        return false;  // tinygltf stops; Scene::load throws the error
    };
    if (image->bufferView >= 0) {
        const auto& views = ctx->model->bufferViews;
        const auto& view = views[size_t(image->bufferView)];  // index checked by tinygltf
        const auto& buffer = ctx->model->buffers[size_t(view.buffer)];
        if (view.byteOffset > buffer.data.size() || view.byteLength > buffer.data.size() - view.byteOffset)
            return fail("bufferViews[" + std::to_string(image->bufferView) + "] runs past the end of its buffer");
    }
    if (!bytes || size <= 0) return fail("the image data is empty");
    // The same file named by several images is decoded once and shared.
    const bool external = !image->uri.empty() && image->uri.rfind("data:", 0) != 0;
    if (external) {
        const auto [it, inserted] = ctx->byUri.emplace(image->uri, index);
        if (!inserted) {
            ctx->pending[i].sameAs = it->second;
            ctx->failures[i] = ctx->failures[size_t(it->second)];
            return true;
        }
    }
    int w = 0, h = 0, channels = 0;
    if (!stbi_info_from_memory(bytes, size, &w, &h, &channels)) return fail(decodeFailure(bytes, size_t(size)));
    const uint64_t texels = uint64_t(w) * uint64_t(h), imageBytes = texels * 4;
    const std::string shape = std::to_string(w) + "x" + std::to_string(h);
    if (w <= 0 || h <= 0) return fail("the image header gives an empty " + shape + " image");
    if (uint64_t(w) > limits.maxTextureSide || uint64_t(h) > limits.maxTextureSide || texels > limits.maxTextureTexels)
        return fatal("the texture is " + shape + " (" + mib(imageBytes) + " decoded)",
                     "at most " + std::to_string(limits.maxTextureSide) + " pixels a side and " +
                         std::to_string(limits.maxTextureTexels) + " texels (" + mib(limits.maxTextureTexels * 4) + ")",
                     "downscale the image");
    if (imageBytes > limits.textureBudgetBytes || ctx->textureBytes > limits.textureBudgetBytes - imageBytes)
        return fatal("the " + shape + " texture (" + mib(imageBytes) + " decoded) takes the scene's textures to " +
                         mib(ctx->textureBytes + imageBytes),
                     "decoded textures within the texture budget of " + mib(limits.textureBudgetBytes),
                     "downscale the scene's textures, or raise the budget (--texture-budget)");
    ctx->textureBytes += imageBytes;
    PendingImage& out = ctx->pending[i];
    out.width = uint32_t(w);
    out.height = uint32_t(h);
    if (image->bufferView >= 0) {
        out.encoded = bytes;  // glTF buffers outlive the import
    } else {
        out.copy.assign(bytes, bytes + size);  // tinygltf frees a file's or data URI's bytes after this call
        out.encoded = out.copy.data();
    }
    out.encodedSize = size_t(size);
    // tinygltf's record of the image: its shape, no pixels (Loom keeps those in Scene::images).
    image->width = w;
    image->height = h;
    image->component = 4;
    image->bits = 8;
    image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    return true;
}

// ---------------------------------------------------------------------------
// Negative indices and offsets

/// Finds the first negative integer where glTF 2.0 requires an index, an offset or a size (all >= 0). tinygltf reads
/// a negative byteOffset as 0 and passes a negative index on, which would then mean "none" (material -2: the default
/// material): neither may pass silently. A SAX pass keeps the JSON path without building a document.
class NegativeIndexFinder : public nlohmann::json_sax<nlohmann::json> {
public:
    std::optional<std::pair<std::string, std::string>> found;  ///< the path ("accessors[1]/byteOffset"), the value

    bool number_integer(number_integer_t v) override {
        if (v < 0 && mustBeNonNegative()) {
            found.emplace(path(), std::to_string(v));
            return false;  // stop: one error is reported
        }
        return value();
    }
    bool null() override { return value(); }
    bool boolean(bool) override { return value(); }
    bool number_unsigned(number_unsigned_t) override { return value(); }
    bool number_float(number_float_t v, const string_t& text) override {
        if (v < 0 && mustBeNonNegative()) {  // -4.0: tinygltf drops it as it drops -4
            found.emplace(path(), text);
            return false;
        }
        return value();
    }
    bool string(string_t&) override { return value(); }
    bool binary(binary_t&) override { return value(); }
    bool start_object(std::size_t) override {
        mFrames.push_back({false, {}, 0});
        return true;
    }
    bool key(string_t& k) override {
        mFrames.back().key = k;
        return true;
    }
    bool end_object() override {
        mFrames.pop_back();
        return value();
    }
    bool start_array(std::size_t) override {
        mFrames.push_back({true, {}, 0});
        return true;
    }
    bool end_array() override {
        mFrames.pop_back();
        return value();
    }
    bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
        return false;  // the parser and tinygltf report malformed JSON
    }

private:
    struct Frame {
        bool array;
        std::string key;  // objects: the member being read
        size_t index;     // arrays: the element being read
    };
    /// A value ended: an array moves on to its next element.
    bool value() {
        if (!mFrames.empty() && mFrames.back().array) ++mFrames.back().index;
        return true;
    }
    bool mustBeNonNegative() const {
        static const std::set<std::string> kIndexKeys = {
            "byteOffset", "byteLength", "byteStride", "count", "bufferView", "buffer",  "material",
            "indices",    "mesh",       "camera",     "skin",  "source",     "sampler", "index",
            "texCoord",   "input",      "output",     "node",  "scene",      "light",   "skeleton"};
        static const std::set<std::string> kIndexArrays = {"children", "nodes", "joints"};
        // Extras are free-form, and so are extensions other than Khronos ones.
        for (size_t f = 0; f + 1 < mFrames.size(); ++f) {
            if (mFrames[f].array) continue;
            if (mFrames[f].key == "extras") return false;
            if (mFrames[f].key == "extensions" && !mFrames[f + 1].array && mFrames[f + 1].key.rfind("KHR_", 0) != 0)
                return false;
        }
        if (mFrames.empty()) return false;
        const Frame& top = mFrames.back();
        if (!top.array) {
            if (kIndexKeys.count(top.key)) return true;
            // A primitive's attributes and morph targets: accessor indices.
            return mFrames.size() >= 2 && !mFrames[mFrames.size() - 2].array &&
                   mFrames[mFrames.size() - 2].key == "attributes";
        }
        return mFrames.size() >= 2 && !mFrames[mFrames.size() - 2].array &&
               kIndexArrays.count(mFrames[mFrames.size() - 2].key);
    }
    std::string path() const {
        std::string out;
        for (const Frame& f : mFrames) {
            if (f.array)
                out += "[" + std::to_string(f.index) + "]";
            else
                out += (out.empty() ? "" : "/") + f.key;
        }
        return out;
    }
    std::vector<Frame> mFrames;
};

void checkNonNegativeIndices(std::string_view jsonText, const std::string& file) {
    NegativeIndexFinder finder;
    nlohmann::json::sax_parse(jsonText.begin(), jsonText.end(), &finder);
    if (!finder.found) return;
    const auto& [where, value] = *finder.found;
    const std::string key = where.substr(where.find_last_of('/') + 1);
    throwBadInput(where, key + " is " + printable(value) + ", a negative index, offset or size",
                  "an integer >= 0 (glTF 2.0)", "fix the exporter, or the file", file);
}

// ---------------------------------------------------------------------------
// Diagnosis when tinygltf refuses a file

std::string percentDecode(const std::string& s) {
    std::string out;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s[i] == '%' && i + 2 < s.size() && std::isxdigit((unsigned char)s[i + 1]) &&
            std::isxdigit((unsigned char)s[i + 2])) {
            out += char(std::stoi(s.substr(i + 1, 2), nullptr, 16));
            i += 2;
        } else {
            out += s[i];
        }
    }
    return out;
}

/// Bytes a base64 payload decodes to (whitespace and padding ignored).
size_t base64DecodedSize(const std::string& payload) {
    size_t n = 0;
    for (char c : payload)
        if (std::isalnum((unsigned char)c) || c == '+' || c == '/') ++n;
    return n * 3 / 4;
}

/// tinygltf's message, one line, without megabytes of data URI.
std::string cleanTinyMessage(const std::string& msg) {
    std::string out;
    size_t start = 0;
    while (start < msg.size()) {
        size_t end = msg.find('\n', start);
        if (end == std::string::npos) end = msg.size();
        std::string line = msg.substr(start, end - start);
        if (line.size() > 160) line = line.substr(0, 160) + "...";
        if (!line.empty()) out += (out.empty() ? "" : "; ") + line;
        start = end + 1;
    }
    return out.empty() ? "unknown error" : out;
}

/// o[key] when it is an integer, else `fallback` (the JSON under diagnosis may have any types).
int64_t intOr(const nlohmann::json& o, const char* key, int64_t fallback) {
    if (!o.is_object() || !o.contains(key) || !o[key].is_number_integer()) return fallback;
    return o[key].get<int64_t>();
}

/// The largest scene file and the largest buffer or image file a scene may reference.
constexpr uint64_t kMaxSceneFileBytes = uint64_t(4) << 30;

/// tinygltf's test for a referenced file, without opening it (opening a pipe blocks until a writer comes).
bool referencedFileExists(const std::string& path, void*) {
    std::error_code ec;
    return fs::exists(path, ec);
}

/// tinygltf's reading of the files a scene references (buffers, images): a folder, a pipe or a device is refused
/// with a message instead of being read (a folder's size reads as huge; a pipe may never end).
bool readReferencedFile(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
    if (const std::string problem = inputFileProblem(path, kMaxSceneFileBytes); !problem.empty()) {
        if (err) *err += "File " + problem + ": " + path + "\n";
        return false;
    }
    std::error_code ec;
    const uintmax_t size = fs::file_size(path, ec);
    std::ifstream in(path, std::ios::binary);
    out->resize(size_t(size));
    if (ec || !in || !in.read(reinterpret_cast<char*>(out->data()), std::streamsize(size))) {
        if (err) *err += "File cannot be read: " + path + "\n";
        return false;
    }
    return true;
}

/// tinygltf stops at the first problem with a terse message. Re-reads the
/// JSON to name the glTF object at fault, then throws.
[[noreturn]] void failLoad(const fs::path& path, const std::string& bytes, bool binary, const std::string& tinyErr) {
    const std::string file = path.string();
    std::string jsonText = bytes;
    std::optional<size_t> binChunk;  // size of a GLB BIN chunk, when there is one
    if (binary) {
        auto u32 = [&](size_t at) {
            uint32_t v;
            std::memcpy(&v, bytes.data() + at, 4);
            return v;
        };
        if (bytes.size() < 20)
            throwBadInput("GLB header", "the file is only " + std::to_string(bytes.size()) + " bytes",
                          "a 12-byte header and a JSON chunk", "the file is truncated", file);
        if (u32(4) != 2)
            throwBadInput("GLB header", "GLB container version " + std::to_string(u32(4)), "version 2 (glTF 2.0)", {},
                          file);
        if (u32(8) > bytes.size())
            throwBadInput("GLB header",
                          "the header gives a length of " + std::to_string(u32(8)) + " bytes but the file has " +
                              std::to_string(bytes.size()),
                          "the complete file", "the file is truncated: copy or export it again", file);
        const size_t jsonLen = u32(12);
        if (u32(16) != 0x4E4F534Au || 20 + jsonLen > bytes.size())
            throwBadInput("GLB JSON chunk", "the first chunk is not a complete JSON chunk",
                          "a JSON chunk of the length its header gives", "the file is truncated or not a GLB", file);
        jsonText = bytes.substr(20, jsonLen);
        const size_t binAt = 20 + ((jsonLen + 3) & ~size_t(3));
        if (binAt + 8 <= bytes.size()) {
            const size_t binLen = u32(binAt);
            if (binAt + 8 + binLen > bytes.size())
                throwBadInput("GLB BIN chunk",
                              "the chunk header gives " + std::to_string(binLen) + " bytes but only " +
                                  std::to_string(bytes.size() - binAt - 8) + " follow",
                              "the complete BIN chunk", "the file is truncated: copy or export it again", file);
            binChunk = binLen;
        }
    }
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(jsonText);
    } catch (const nlohmann::json::parse_error& e) {
        throwBadInput("JSON", std::string("the glTF JSON does not parse: ") + e.what(), "valid JSON", {}, file);
    }
    if (!j.is_object()) throwBadInput("JSON", "the top level is not an object", "a glTF JSON object", {}, file);

    // The checks read the JSON without trusting its types: a type surprise only means there is no better
    // diagnosis than tinygltf's own message.
    try {
        if (j.contains("extensionsRequired") && j["extensionsRequired"].is_array()) {
            std::vector<std::string> required;
            for (const auto& e : j["extensionsRequired"])
                if (e.is_string()) required.push_back(e.get<std::string>());
            checkRequiredExtensions(required, file);
        }

        auto arraySize = [&](const char* key) { return j.contains(key) && j[key].is_array() ? j[key].size() : 0; };
        auto nameOf = [](const nlohmann::json& o) {
            return o.is_object() && o.contains("name") && o["name"].is_string() ? o["name"].get<std::string>() : "";
        };

        // Buffers: the usual failure is data shorter than byteLength (a truncated .bin or data URI).
        for (size_t i = 0; i < arraySize("buffers"); ++i) {
            const auto& b = j["buffers"][i];
            if (!b.is_object()) continue;
            const std::string where = labelOf("buffers", i, nameOf(b));
            const int64_t byteLength = intOr(b, "byteLength", 0);
            const std::string uri = b.contains("uri") && b["uri"].is_string() ? b["uri"].get<std::string>() : "";
            int64_t have = 0;
            if (uri.empty()) {
                if (!binary || i != 0 || !binChunk)
                    throwBadInput(where, "the buffer has no uri and there is no GLB BIN chunk for it",
                                  "a uri, or the GLB's BIN chunk for buffer 0", {}, file);
                have = int64_t(*binChunk);
            } else if (uri.rfind("data:", 0) == 0) {
                const size_t comma = uri.find(";base64,");
                if (comma == std::string::npos)
                    throwBadInput(where, "the data URI is not base64", "data:application/octet-stream;base64,...", {},
                                  file);
                have = int64_t(base64DecodedSize(uri.substr(comma + 8)));
                if (have > byteLength)
                    throwBadInput(where,
                                  "the data URI holds " + std::to_string(have) + " bytes but byteLength says " +
                                      std::to_string(byteLength),
                                  "byteLength equal to the data size", "fix byteLength or the data", file);
            } else {
                const fs::path binPath = path.parent_path() / percentDecode(uri);
                std::error_code ec;
                if (!fs::is_regular_file(binPath, ec))
                    throwBadInput(where, "buffer file '" + binPath.string() + "' not found",
                                  "the file next to the glTF", "copy the .bin with the .gltf", file);
                have = int64_t(fs::file_size(binPath, ec));
                if (have > byteLength && !ec)
                    throwBadInput(where,
                                  "buffer file '" + binPath.string() + "' is " + std::to_string(have) +
                                      " bytes but byteLength says " + std::to_string(byteLength),
                                  "a file of exactly byteLength bytes",
                                  "the .bin does not belong to this .gltf, or byteLength is wrong", file);
            }
            if (have < byteLength)
                throwBadInput(where,
                              "byteLength is " + std::to_string(byteLength) + " bytes but the data holds only " +
                                  std::to_string(have),
                              "at least byteLength bytes of data",
                              "the buffer is truncated: copy or export the file again", file);
        }
        // Index accessors (tinygltf checks them before anything else in meshes).
        const size_t accessorCount = arraySize("accessors");
        for (size_t m = 0; m < arraySize("meshes"); ++m) {
            const auto& mesh = j["meshes"][m];
            if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array()) continue;
            for (size_t p = 0; p < mesh["primitives"].size(); ++p) {
                const auto& prim = mesh["primitives"][p];
                if (!prim.is_object() || !prim.contains("indices") || !prim["indices"].is_number_integer()) continue;
                const int64_t a = prim["indices"].get<int64_t>();
                const std::string where =
                    labelOf("meshes", m, nameOf(mesh)) + "/primitives[" + std::to_string(p) + "]/indices";
                if (a < 0 || uint64_t(a) >= accessorCount)
                    throwBadInput(where, "accessor " + std::to_string(a) + " does not exist",
                                  "an accessor index below " + std::to_string(accessorCount), {}, file);
                const auto& acc = j["accessors"][size_t(a)];
                const int64_t view = intOr(acc, "bufferView", -1);
                if (view < 0 || uint64_t(view) >= arraySize("bufferViews"))
                    throwBadInput(where, "index accessor " + std::to_string(a) + " has no valid bufferView",
                                  "an index accessor stored in a bufferView", {}, file);
            }
        }
        for (size_t i = 0; i < arraySize("images"); ++i) {
            const auto& img = j["images"][i];
            if (!img.is_object() || !img.contains("bufferView")) continue;
            const int64_t view = intOr(img, "bufferView", -1);
            if (view < 0 || uint64_t(view) >= arraySize("bufferViews"))
                throwBadInput(labelOf("images", i, nameOf(img)),
                              "bufferView " + std::to_string(view) + " does not exist",
                              "a bufferView index below " + std::to_string(arraySize("bufferViews")), {}, file);
        }
    } catch (const nlohmann::json::exception&) {
    }
    throwBadInput({}, "tinygltf cannot load the file: " + cleanTinyMessage(tinyErr), "a valid glTF 2.0 file",
                  "check it with the Khronos glTF Validator (https://github.khronos.org/glTF-Validator/)", file);
}

// ---------------------------------------------------------------------------
// Geometry helpers

template <glm::length_t N>
bool allFinite(const glm::vec<N, float>& v) {
    for (glm::length_t i = 0; i < N; ++i)
        if (!std::isfinite(v[i])) return false;
    return true;
}

/// Degenerate: the area is zero to float precision (sine of the angle between
/// the edges below ~1e-7), so no reliable face normal exists.
bool isDegenerate(const glm::vec3& p0, const glm::vec3& p1, const glm::vec3& p2) {
    const glm::vec3 e1 = p1 - p0, e2 = p2 - p0;
    const glm::vec3 c = glm::cross(e1, e2);
    const float cc = glm::dot(c, c);
    return !(cc > 1e-14f * glm::dot(e1, e1) * glm::dot(e2, e2)) || !std::isfinite(cc);
}

/// Any unit vector perpendicular to unit vector n.
glm::vec3 anyPerpendicular(const glm::vec3& n) {
    const glm::vec3 axis = std::fabs(n.x) < 0.9f ? glm::vec3(1.f, 0.f, 0.f) : glm::vec3(0.f, 1.f, 0.f);
    return glm::normalize(glm::cross(axis, n));
}

/// Per-vertex tangents from the UV mapping: each triangle's dP/du, dP/dv,
/// area-weighted at its vertices, then Gram-Schmidt against the normal.
/// Handedness follows glTF's normal-map convention (green = +Y = up in the
/// image, i.e. towards decreasing v, since glTF's v runs down the image):
/// the bitangent cross(n, t) * w must point along -dP/dv.
void generateTangents(Mesh& mesh) {
    const size_t n = mesh.positions.size();
    std::vector<glm::vec3> tan(n, glm::vec3(0.f)), bit(n, glm::vec3(0.f));
    for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
        const uint32_t i[3] = {mesh.indices[t], mesh.indices[t + 1], mesh.indices[t + 2]};
        const glm::vec3 e1 = mesh.positions[i[1]] - mesh.positions[i[0]];
        const glm::vec3 e2 = mesh.positions[i[2]] - mesh.positions[i[0]];
        const glm::vec2 d1 = mesh.uvs[i[1]] - mesh.uvs[i[0]];
        const glm::vec2 d2 = mesh.uvs[i[2]] - mesh.uvs[i[0]];
        const float det = d1.x * d2.y - d2.x * d1.y;
        if (!(std::fabs(det) > 1e-20f)) continue;  // no UV mapping here: contributes nothing
        const glm::vec3 dpdu = (e1 * d2.y - e2 * d1.y) / det;
        const glm::vec3 dpdv = (e2 * d1.x - e1 * d2.x) / det;
        const float area = glm::length(glm::cross(e1, e2));
        const float lu = glm::length(dpdu), lv = glm::length(dpdv);
        if (!(lu > 0.f) || !(lv > 0.f) || !std::isfinite(lu) || !std::isfinite(lv)) continue;
        for (uint32_t v : i) {
            tan[v] += dpdu * (area / lu);
            bit[v] += dpdv * (area / lv);
        }
    }
    mesh.tangents.resize(n);
    for (size_t v = 0; v < n; ++v) {
        const glm::vec3 nrm = mesh.normals[v];
        glm::vec3 t = tan[v] - nrm * glm::dot(nrm, tan[v]);
        const float len = glm::length(t);
        // A degenerate UV mapping has no preferred direction: any orthonormal tangent will do.
        t = len > 1e-12f && std::isfinite(len) ? t / len : anyPerpendicular(nrm);
        const float w = glm::dot(glm::cross(nrm, t), -bit[v]) < 0.f ? -1.f : 1.f;
        mesh.tangents[v] = glm::vec4(t, w);
    }
}

glm::vec3 faceNormal(const glm::vec3& p0, const glm::vec3& p1, const glm::vec3& p2) {
    return glm::normalize(glm::cross(p1 - p0, p2 - p0));  // counter-clockwise winding faces the viewer
}

/// Reads one component and converts it to double, applying glTF's
/// normalised-integer rules (glTF 2.0 section 3.11).
double componentValue(const unsigned char* p, int type, bool normalized) {
    switch (type) {
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
            int8_t v;
            std::memcpy(&v, p, 1);
            return normalized ? std::max(v / 127.0, -1.0) : double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
            uint8_t v;
            std::memcpy(&v, p, 1);
            return normalized ? v / 255.0 : double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
            int16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? std::max(v / 32767.0, -1.0) : double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
            uint16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? v / 65535.0 : double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_INT: {
            int32_t v;
            std::memcpy(&v, p, 4);
            return double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
            uint32_t v;
            std::memcpy(&v, p, 4);
            return normalized ? v / 4294967295.0 : double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_FLOAT: {
            float v;
            std::memcpy(&v, p, 4);
            return double(v);
        }
        case TINYGLTF_COMPONENT_TYPE_DOUBLE: {
            double v;
            std::memcpy(&v, p, 8);
            return v;
        }
        default:
            return 0.0;
    }
}

const char* typeName(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR:
            return "SCALAR";
        case TINYGLTF_TYPE_VEC2:
            return "VEC2";
        case TINYGLTF_TYPE_VEC3:
            return "VEC3";
        case TINYGLTF_TYPE_VEC4:
            return "VEC4";
        case TINYGLTF_TYPE_MAT2:
            return "MAT2";
        case TINYGLTF_TYPE_MAT3:
            return "MAT3";
        case TINYGLTF_TYPE_MAT4:
            return "MAT4";
        default:
            return "unknown";
    }
}

// ---------------------------------------------------------------------------
// The importer

class Importer {
public:
    Importer(const tinygltf::Model& model, ImageLoadContext& images, Scene& scene, const SceneLoadOptions& options,
             std::vector<PointerChannel> pointers)
        : m(model),
          mImageCtx(images),
          s(scene),
          mOptions(options),
          mFile(scene.file.string()),
          mPointers(std::move(pointers)) {}

    void run();

private:
    /// The elements of accessor `index` (which must be of `expectedType`), flattened, every component
    /// converted to T. Bounds, sparse substitution and (for floats) NaN/Inf are checked.
    template <class T>
    std::vector<T> readAccessor(int index, const std::string& where, int expectedType);
    std::vector<uint32_t> readIndices(int index, const std::string& where);

    void convertImages();
    void convertMaterials();
    void convertMeshes();
    std::optional<Mesh> convertPrimitive(size_t meshIndex, size_t primIndex);
    std::vector<uint32_t> triangleList(const tinygltf::Primitive& prim, int mode, size_t vertexCount,
                                       const std::string& label);
    void setNormals(Mesh& mesh, const std::vector<float>& nrm, const std::vector<float>& tng, const std::string& label);
    void setTangents(Mesh& mesh);
    void convertCameras();
    void convertNodes(const std::vector<int>& roots);
    void convertAnimations();
    void readSamplerValues(AnimationSampler& sampler, int output, int type, const std::string& where);
    void convertPointerChannel(const PointerChannel& pc, const tinygltf::Animation& src, Animation& anim,
                               const std::string& where);

    TextureRef textureRef(const tinygltf::TextureInfo& info, const std::string& material, const char* slot);
    TextureRef textureRef(int textureIndex, int texCoord, const tinygltf::ExtensionMap& extensions,
                          const std::string& material, const char* slot);
    void applySampler(int samplerIndex, const std::string& where, TextureRef& ref);
    glm::mat3x2 textureTransform(const tinygltf::Value& ext, const std::string& where, int& texCoord);
    void readIorAndSpecular(const tinygltf::Material& src, const std::string& label, Material& mat);
    uint32_t defaultMaterial();
    std::string meshLabel(size_t i) const { return labelOf("meshes", i, m.meshes[i].name); }
    std::string imageFileProblem(const std::string& uri) const;
    void checkNodeCycles() const;
    void checkWorldRange() const;

    [[noreturn]] void fail(const std::string& where, const std::string& what, const std::string& expected = {},
                           const std::string& suggestion = {}) const {
        throwBadInput(where, what, expected, suggestion, mFile);
    }
    void warn(std::string msg) {
        msg = printable(msg);  // it may quote a decoder's reason, bytes of the file
        spdlog::warn("{}: {}", printable(mFile), msg);
        s.warnings.push_back(std::move(msg));
    }

    const tinygltf::Model& m;
    ImageLoadContext& mImageCtx;  // its decoded texels move into Scene::images
    Scene& s;
    const SceneLoadOptions& mOptions;
    const std::string mFile;
    std::vector<int> mImageMap;                   // glTF image -> Scene::images index, -1 when not decoded
    std::vector<std::vector<uint32_t>> mMeshMap;  // glTF mesh -> Scene::meshes of its primitives
    int mDefaultMaterial = -1;
    std::vector<PointerChannel> mPointers;  // KHR_animation_pointer channels, read from the JSON
    std::set<std::string> mWarnedPointers;  // unsupported pointers already warned about
};

template <class T>
std::vector<T> Importer::readAccessor(int index, const std::string& where, int expectedType) {
    if (index < 0 || size_t(index) >= m.accessors.size())
        fail(where, "accessor " + std::to_string(index) + " does not exist",
             "an accessor index below " + std::to_string(m.accessors.size()));
    const tinygltf::Accessor& acc = m.accessors[size_t(index)];
    const std::string at = where + " (accessors[" + std::to_string(index) + "])";
    if (acc.type != expectedType)
        fail(at, std::string("accessor type is ") + typeName(acc.type), typeName(expectedType));
    const int comps = tinygltf::GetNumComponentsInType(uint32_t(acc.type));
    const int compSize = tinygltf::GetComponentSizeInBytes(uint32_t(acc.componentType));
    if (comps <= 0 || compSize <= 0) fail(at, "unknown component type " + std::to_string(acc.componentType));
    const size_t elemSize = size_t(comps) * size_t(compSize);
    const size_t count = acc.count;

    // Checks that `n` elements of `size` bytes at `stride` from `offset` lie inside bufferView `viewIndex`
    // and that the bufferView lies inside its buffer; returns the first byte.
    auto locate = [&](int viewIndex, size_t offset, size_t n, size_t size, size_t stride,
                      const std::string& what) -> const unsigned char* {
        if (viewIndex < 0 || size_t(viewIndex) >= m.bufferViews.size())
            fail(at, what + "bufferView " + std::to_string(viewIndex) + " does not exist",
                 "a bufferView index below " + std::to_string(m.bufferViews.size()));
        const tinygltf::BufferView& view = m.bufferViews[size_t(viewIndex)];
        const std::string viewLabel = "bufferViews[" + std::to_string(viewIndex) + "]";
        if (view.buffer < 0 || size_t(view.buffer) >= m.buffers.size())
            fail(viewLabel, "buffer " + std::to_string(view.buffer) + " does not exist",
                 "a buffer index below " + std::to_string(m.buffers.size()));
        const size_t bufferSize = m.buffers[size_t(view.buffer)].data.size();
        if (view.byteOffset > bufferSize || view.byteLength > bufferSize - view.byteOffset)
            fail(viewLabel,
                 "bytes " + std::to_string(view.byteOffset) + " to " +
                     std::to_string(uint64_t(view.byteOffset) + view.byteLength) + " run past the end of buffers[" +
                     std::to_string(view.buffer) + "] (" + std::to_string(bufferSize) + " bytes)",
                 "a bufferView inside its buffer", "the buffer (.bin) is truncated, or the file is corrupt");
        if (n == 0) return nullptr;
        // Overflow-safe form of offset + (n - 1) * stride + size <= byteLength.
        const size_t len = view.byteLength;
        const bool fits =
            offset <= len && size <= len - offset && (n - 1) <= (len - offset - size) / std::max<size_t>(stride, 1);
        if (!fits)
            fail(at,
                 what + std::to_string(n) + " elements of " + std::to_string(size) + " bytes (stride " +
                     std::to_string(stride) + ") from byte " + std::to_string(offset) + " do not fit in " + viewLabel +
                     " (" + std::to_string(len) + " bytes)",
                 "count, byteOffset and byteStride that stay inside the bufferView",
                 "the accessor or bufferView is wrong, or the buffer is truncated");
        return m.buffers[size_t(view.buffer)].data.data() + view.byteOffset + offset;
    };

    const unsigned char* base = nullptr;
    size_t stride = elemSize;
    if (acc.bufferView >= 0) {
        // locate() bounds the count by the data, so the allocation below is safe.
        const size_t viewStride =
            size_t(acc.bufferView) < m.bufferViews.size() ? m.bufferViews[size_t(acc.bufferView)].byteStride : 0;
        if (viewStride) stride = viewStride;
        if (stride < elemSize)
            fail(at, "byteStride " + std::to_string(stride) + " is smaller than an element (" +
                         std::to_string(elemSize) + " bytes)");
        base = locate(acc.bufferView, acc.byteOffset, count, elemSize, stride, "");
    } else if (count > (size_t(1) << 28)) {
        // Without a bufferView nothing bounds the count (sparse or all-zero accessors).
        fail(at, "count " + std::to_string(count) + " is implausibly large for an accessor without a bufferView");
    }
    std::vector<T> out(count * size_t(comps), T(0));  // no bufferView: zeros (glTF 2.0 section 3.6.2.3)
    if (base) {
        for (size_t i = 0; i < count; ++i)
            for (int c = 0; c < comps; ++c)
                out[i * size_t(comps) + size_t(c)] = T(componentValue(base + i * stride + size_t(c) * size_t(compSize),
                                                                      acc.componentType, acc.normalized));
    }
    if (acc.sparse.isSparse && acc.sparse.count > 0) {
        // Sparse substitution (glTF 2.0 section 3.6.2.3): indices and values are tightly packed.
        const size_t n = size_t(acc.sparse.count);
        const int indexType = acc.sparse.indices.componentType;
        const int indexSize = tinygltf::GetComponentSizeInBytes(uint32_t(indexType));
        if (indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
            indexType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
            fail(at, "sparse indices have component type " + std::to_string(indexType), "unsigned byte, short or int");
        const unsigned char* idx = locate(acc.sparse.indices.bufferView, size_t(acc.sparse.indices.byteOffset), n,
                                          size_t(indexSize), size_t(indexSize), "sparse indices: ");
        const unsigned char* val = locate(acc.sparse.values.bufferView, size_t(acc.sparse.values.byteOffset), n,
                                          elemSize, elemSize, "sparse values: ");
        for (size_t k = 0; k < n; ++k) {
            const double target = componentValue(idx + k * size_t(indexSize), indexType, false);
            if (target >= double(count))
                fail(at, "sparse index " + std::to_string(uint64_t(target)) + " is out of range",
                     "below the accessor count " + std::to_string(count));
            for (int c = 0; c < comps; ++c)
                out[size_t(target) * size_t(comps) + size_t(c)] = T(componentValue(
                    val + k * elemSize + size_t(c) * size_t(compSize), acc.componentType, acc.normalized));
        }
    }
    if constexpr (std::is_floating_point_v<T>) {
        for (size_t i = 0; i < out.size(); ++i)
            if (!std::isfinite(out[i]))
                fail(at,
                     std::string(std::isnan(out[i]) ? "NaN" : "infinite") + " value in element " +
                         std::to_string(i / size_t(comps)),
                     "finite numbers", "fix the exporter or the source data");
    }
    return out;
}

std::vector<uint32_t> Importer::readIndices(int index, const std::string& where) {
    if (index >= 0 && size_t(index) < m.accessors.size()) {
        const int type = m.accessors[size_t(index)].componentType;
        if (type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
            type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
            fail(where + " (accessors[" + std::to_string(index) + "])", "index component type " + std::to_string(type),
                 "unsigned byte, short or int (5121, 5123, 5125)");
    }
    return readAccessor<uint32_t>(index, where, TINYGLTF_TYPE_SCALAR);
}

/// Decodes the images the callback accepted (stb: 1-3 channel images gain channels, 16-bit images are reduced to
/// 8 bits) and moves their texels into Scene::images. Running out of memory is an error naming the image.
void Importer::convertImages() {
    mImageMap.assign(m.images.size(), -1);
    for (size_t i = 0; i < m.images.size() && i < mImageCtx.pending.size(); ++i) {
        PendingImage& pending = mImageCtx.pending[i];
        if (pending.sameAs >= 0) {
            mImageMap[i] = mImageMap[size_t(pending.sameAs)];
            continue;
        }
        if (!pending.encoded) continue;
        const tinygltf::Image& img = m.images[i];
        const std::string shape = std::to_string(pending.width) + "x" + std::to_string(pending.height);
        const auto outOfMemory = [&] {
            fail(imageLabel(i, img),
                 "out of memory decoding the " + shape + " texture (" +
                     mib(uint64_t(pending.width) * pending.height * 4) + "; the scene's textures take " +
                     mib(mImageCtx.textureBytes) + ")",
                 "enough free memory for the scene's textures", "downscale the textures, or free memory");
        };
        SceneImage out;
        try {
            int w = 0, h = 0, channels = 0;
            std::unique_ptr<stbi_uc, void (*)(void*)> data(
                stbi_load_from_memory(pending.encoded, int(pending.encodedSize), &w, &h, &channels, 4),
                stbi_image_free);
            if (!data) {
                const char* reason = stbi_failure_reason();
                if (reason && std::strcmp(reason, "outofmem") == 0) outOfMemory();
                mImageCtx.failures[i] = decodeFailure(pending.encoded, pending.encodedSize);
                continue;
            }
            if (uint32_t(w) != pending.width || uint32_t(h) != pending.height) {
                mImageCtx.failures[i] = "the image decodes to " + std::to_string(w) + "x" + std::to_string(h) +
                                        " but its header says " + shape;
                continue;
            }
            const auto* first = reinterpret_cast<const glm::u8vec4*>(data.get());
            // The one copy: a vector cannot adopt stb's buffer.
            out.texels.assign(first, first + size_t(w) * size_t(h));
        } catch (const std::bad_alloc&) {
            outOfMemory();
        }
        pending = PendingImage{};  // the encoded copy is no longer needed
        out.name = img.name;
        if (out.name.empty()) out.name = !img.uri.empty() && img.uri.rfind("data:", 0) != 0 ? img.uri : "";
        if (out.name.empty()) out.name = "image" + std::to_string(i);
        out.width = uint32_t(img.width);
        out.height = uint32_t(img.height);
        mImageMap[i] = int(s.images.size());
        s.images.push_back(std::move(out));
    }
}

/// Why an external image file could not be read, as a texture error says it.
std::string Importer::imageFileProblem(const std::string& uri) const {
    const fs::path path = s.file.parent_path() / percentDecode(uri);
    std::string problem = inputFileProblem(path, kMaxSceneFileBytes);
    std::error_code ec;
    if (problem.empty()) problem = fs::file_size(path, ec) == 0 && !ec ? "is an empty file" : "cannot be read";
    return "image file '" + path.string() + "' " + problem;
}

TextureRef Importer::textureRef(const tinygltf::TextureInfo& info, const std::string& material, const char* slot) {
    return textureRef(info.index, info.texCoord, info.extensions, material, slot);
}

TextureRef Importer::textureRef(int textureIndex, int texCoord, const tinygltf::ExtensionMap& extensions,
                                const std::string& material, const char* slot) {
    TextureRef ref;
    if (textureIndex < 0) return ref;
    const std::string where = material + "/" + slot;
    if (size_t(textureIndex) >= m.textures.size()) {
        warn(where + ": texture " + std::to_string(textureIndex) + " does not exist; the texture is ignored");
        return ref;
    }
    auto transform = extensions.find("KHR_texture_transform");
    if (transform != extensions.end()) ref.transform = textureTransform(transform->second, where, texCoord);
    if (texCoord != 0)
        warn(where + ": uses TEXCOORD_" + std::to_string(texCoord) + "; only TEXCOORD_0 is supported and used instead");
    const tinygltf::Texture& texture = m.textures[size_t(textureIndex)];
    applySampler(texture.sampler, where, ref);
    const int source = texture.source;
    if (source < 0 || size_t(source) >= m.images.size()) {
        warn(where + ": texture " + std::to_string(textureIndex) +
             " has no image Loom can read (only PNG and JPEG sources); the texture is ignored");
        return ref;
    }
    ref.image = mImageMap[size_t(source)];
    if (ref.image < 0) {
        const tinygltf::Image& img = m.images[size_t(source)];
        size_t decoded = size_t(source);  // the image whose decoding failed (the first one naming the same file)
        if (decoded < mImageCtx.pending.size() && mImageCtx.pending[decoded].sameAs >= 0)
            decoded = size_t(mImageCtx.pending[decoded].sameAs);
        std::string why = decoded < mImageCtx.failures.size() ? mImageCtx.failures[decoded] : "";
        if (why.empty())
            why = !img.uri.empty() && img.uri.rfind("data:", 0) != 0 ? imageFileProblem(img.uri)
                                                                     : "the image could not be decoded";
        const std::string at = where + ": " + imageLabel(size_t(source), img);
        if (!mOptions.allowMissingTextures)
            fail(at, why, "a PNG or JPEG image Loom can read",
                 "fix or replace the image, or load with --allow-missing-textures to render the material without "
                 "the texture");
        warn(at + ": " + why + "; the texture is ignored (--allow-missing-textures)");
    }
    return ref;
}

/// The texture's sampler (glTF 2.0 section 5.26): wrap modes per axis, and one
/// filter. Loom samples points from a single level (no mipmaps, no footprint),
/// which GL calls magnification, so magFilter decides; without one, minFilter's
/// filter within a level (NEAREST_MIPMAP_LINEAR filters as NEAREST, ...).
/// Neither given: bilinear.
void Importer::applySampler(int samplerIndex, const std::string& where, TextureRef& ref) {
    if (samplerIndex < 0) return;  // glTF: repeat, and filtering left to the renderer
    if (size_t(samplerIndex) >= m.samplers.size()) {
        warn(where + ": sampler " + std::to_string(samplerIndex) + " does not exist; repeat and bilinear are used");
        return;
    }
    const tinygltf::Sampler& sampler = m.samplers[size_t(samplerIndex)];
    const std::string label = labelOf("samplers", size_t(samplerIndex), sampler.name);
    auto wrap = [&](int mode, const char* name) {
        switch (mode) {
            case TINYGLTF_TEXTURE_WRAP_REPEAT:
                return TextureWrap::Repeat;
            case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE:
                return TextureWrap::ClampToEdge;
            case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT:
                return TextureWrap::MirroredRepeat;
            default:
                break;
        }
        warn(where + ": " + label + ": unknown " + name + " " + std::to_string(mode) + "; REPEAT (10497) is used");
        return TextureWrap::Repeat;
    };
    ref.wrapS = wrap(sampler.wrapS, "wrapS");
    ref.wrapT = wrap(sampler.wrapT, "wrapT");
    // The filter within one level: 0 nearest, 1 linear, -1 not given (or unknown, with a warning).
    auto levelFilter = [&](int filter, const char* name) {
        switch (filter) {
            case -1:
                return -1;
            case TINYGLTF_TEXTURE_FILTER_NEAREST:
            case TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_NEAREST:
            case TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_LINEAR:
                return 0;
            case TINYGLTF_TEXTURE_FILTER_LINEAR:
            case TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_NEAREST:
            case TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_LINEAR:
                return 1;
            default:
                break;
        }
        warn(where + ": " + label + ": unknown " + name + " " + std::to_string(filter) + "; ignored");
        return -1;
    };
    const int mag = levelFilter(sampler.magFilter, "magFilter");
    const int min = levelFilter(sampler.minFilter, "minFilter");
    ref.nearest = (mag >= 0 ? mag : min) == 0 ? 1u : 0u;
}

/// KHR_texture_transform (offset, rotation, scale; texCoord overrides the
/// reference's) as the affine map uv' = T * R * S * uv. The rotation turns uv
/// "counter-clockwise" in glTF's v-down uv space: u' = cos * u + sin * v,
/// v' = -sin * u + cos * v, which is what the extension's example (the lower
/// left quadrant of the image, offset (0, 1), rotation pi/2, scale 0.5) and its
/// sample model need (the matrix printed in the extension's GLSL listing turns
/// the other way; KhronosGroup/glTF issue 1563).
glm::mat3x2 Importer::textureTransform(const tinygltf::Value& ext, const std::string& where, int& texCoord) {
    const std::string at = where + "/extensions/KHR_texture_transform";
    glm::vec2 offset(0.f), scale(1.f);
    float rotation = 0.f;
    if (!ext.IsObject()) {
        warn(at + ": not an object; the texture is mapped without a transform");
        return glm::mat3x2(1.f);
    }
    auto pair = [&](const char* name, glm::vec2& out) {
        if (!ext.Has(name)) return;
        const tinygltf::Value& v = ext.Get(name);
        if (!v.IsArray() || v.ArrayLen() != 2 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber()) {
            warn(at + ": " + name + " is not an array of two numbers; the default is used");
            return;
        }
        out = glm::vec2(float(v.Get(0).GetNumberAsDouble()), float(v.Get(1).GetNumberAsDouble()));
    };
    pair("offset", offset);
    pair("scale", scale);
    if (ext.Has("rotation")) {
        if (ext.Get("rotation").IsNumber())
            rotation = float(ext.Get("rotation").GetNumberAsDouble());
        else
            warn(at + ": rotation is not a number; 0 is used");
    }
    if (ext.Has("texCoord") && ext.Get("texCoord").IsNumber()) texCoord = ext.Get("texCoord").GetNumberAsInt();
    if (!allFinite(offset) || !allFinite(scale) || !std::isfinite(rotation))
        fail(at, "NaN or infinite offset, rotation or scale", "finite numbers");
    const float c = std::cos(rotation), sn = std::sin(rotation);
    return glm::mat3x2(glm::vec2(c * scale.x, -sn * scale.x), glm::vec2(sn * scale.y, c * scale.y), offset);
}

uint32_t Importer::defaultMaterial() {
    // glTF's default material: white, fully metallic, fully rough (section 3.9.6).
    if (mDefaultMaterial < 0) {
        Material mat;
        mat.name = "default";
        mDefaultMaterial = int(s.materials.size());
        s.materials.push_back(mat);
    }
    return uint32_t(mDefaultMaterial);
}

void Importer::convertMaterials() {
    for (size_t i = 0; i < m.materials.size(); ++i) {
        const tinygltf::Material& src = m.materials[i];
        const std::string label = labelOf("materials", i, src.name);
        Material mat;
        mat.name = !src.name.empty() ? src.name : "material" + std::to_string(i);
        const auto& pbr = src.pbrMetallicRoughness;
        if (pbr.baseColorFactor.size() == 4)
            mat.baseColorFactor = glm::vec4(float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]),
                                            float(pbr.baseColorFactor[2]), float(pbr.baseColorFactor[3]));
        mat.metallicFactor = float(pbr.metallicFactor);  // tinygltf applies glTF's default of 1 when absent
        mat.roughnessFactor = float(pbr.roughnessFactor);
        if (src.emissiveFactor.size() == 3)
            mat.emissiveFactor =
                glm::vec3(float(src.emissiveFactor[0]), float(src.emissiveFactor[1]), float(src.emissiveFactor[2]));
        mat.emissiveColor = mat.emissiveFactor;
        auto strength = src.extensions.find("KHR_materials_emissive_strength");
        if (strength != src.extensions.end() && strength->second.IsObject()) {
            const tinygltf::Value& v = strength->second.Get("emissiveStrength");
            if (v.IsNumber()) {
                mat.emissiveStrength = float(v.GetNumberAsDouble());
                mat.emissiveFactor *= mat.emissiveStrength;
            }
        }
        readIorAndSpecular(src, label, mat);
        const bool finite = std::isfinite(mat.metallicFactor) && std::isfinite(mat.roughnessFactor) &&
                            allFinite(mat.baseColorFactor) && allFinite(mat.emissiveFactor) && std::isfinite(mat.ior) &&
                            std::isfinite(mat.specularFactor) && allFinite(mat.specularColorFactor);
        if (!finite)
            fail(label, "a material factor is NaN or infinite",
                 "finite baseColor, metallic, roughness, emissive, ior and specular factors");
        const auto nonNegative = [&](glm::vec3& factor, const char* name) {
            if (!glm::any(glm::lessThan(factor, glm::vec3(0.f)))) return;
            warn(label + ": negative " + name + " clamped to 0");
            factor = glm::max(factor, glm::vec3(0.f));
        };
        nonNegative(mat.emissiveFactor, "emissive factor");
        // The factors an animation of either starts from (its product is checked and clamped above).
        mat.emissiveColor = glm::max(mat.emissiveColor, glm::vec3(0.f));
        mat.emissiveStrength = std::isfinite(mat.emissiveStrength) ? std::max(mat.emissiveStrength, 0.f) : 0.f;
        // KHR_materials_specular's colour is an F0 tint with no upper bound (the product with F0 is capped at 1).
        nonNegative(mat.specularColorFactor, "specularColorFactor");
        // KHR_materials_ior: >= 1, or exactly 0 (the extension's special value: a Fresnel term of 1).
        if (mat.ior != 0.f && mat.ior < 1.f) {
            warn(label + ": ior " + std::to_string(mat.ior) + " is below 1 (valid: >= 1, or 0); 1 is used");
            mat.ior = 1.f;
        }
        // glTF bounds these factors to [0, 1]. A base colour above 1 reflects more light than arrives: a path
        // gains energy at every bounce, and a filter that remodulates by the albedo can overflow.
        const auto unitRange = [&](auto& factor, const char* name) {
            using T = std::decay_t<decltype(factor)>;
            const T clamped = glm::clamp(factor, T(0.f), T(1.f));
            if (clamped == factor) return;
            warn(label + ": " + name + " outside [0, 1] clamped to it");
            factor = clamped;
        };
        unitRange(mat.baseColorFactor, "baseColorFactor");
        unitRange(mat.metallicFactor, "metallicFactor");
        unitRange(mat.roughnessFactor, "roughnessFactor");
        unitRange(mat.specularFactor, "specularFactor");
        // Images are kept as stored; the slot decides the decoding when sampled (base colour and emission
        // are sRGB, metallic-roughness and normal maps linear), so one image may serve both kinds of slot.
        mat.baseColorTexture = textureRef(pbr.baseColorTexture, label, "baseColorTexture");
        mat.metallicRoughnessTexture = textureRef(pbr.metallicRoughnessTexture, label, "metallicRoughnessTexture");
        mat.normalTexture = textureRef(src.normalTexture.index, src.normalTexture.texCoord,
                                       src.normalTexture.extensions, label, "normalTexture");
        mat.normalScale = float(src.normalTexture.scale);
        mat.emissiveTexture = textureRef(src.emissiveTexture, label, "emissiveTexture");
        mat.doubleSided = src.doubleSided;
        if (src.alphaMode == "MASK")
            mat.alphaMode = AlphaMode::Mask;
        else if (src.alphaMode == "BLEND")
            mat.alphaMode = AlphaMode::Blend;
        else if (src.alphaMode != "OPAQUE")
            warn(label + ": unknown alphaMode '" + src.alphaMode + "'; treated as OPAQUE");
        mat.alphaCutoff = float(src.alphaCutoff);
        s.materials.push_back(std::move(mat));
    }
}

/// The factors of KHR_materials_ior and KHR_materials_specular, as given (convertMaterials validates them).
void Importer::readIorAndSpecular(const tinygltf::Material& src, const std::string& label, Material& mat) {
    // A number member of an extension object, or its default when absent; present but not a number is warned about.
    auto number = [&](const tinygltf::Value& ext, const std::string& name, float fallback) {
        if (!ext.Has(name)) return fallback;
        const tinygltf::Value& v = ext.Get(name);
        if (v.IsNumber()) return float(v.GetNumberAsDouble());
        warn(label + ": " + name + " is not a number; the default is used");
        return fallback;
    };
    auto ior = src.extensions.find("KHR_materials_ior");
    if (ior != src.extensions.end() && ior->second.IsObject()) mat.ior = number(ior->second, "ior", 1.5f);
    auto spec = src.extensions.find("KHR_materials_specular");
    if (spec == src.extensions.end() || !spec->second.IsObject()) return;
    const tinygltf::Value& ext = spec->second;
    mat.specularFactor = number(ext, "specularFactor", 1.f);
    if (ext.Has("specularColorFactor")) {
        const tinygltf::Value& v = ext.Get("specularColorFactor");
        if (v.IsArray() && v.ArrayLen() == 3 && v.Get(0).IsNumber() && v.Get(1).IsNumber() && v.Get(2).IsNumber())
            mat.specularColorFactor =
                glm::vec3(float(v.Get(0).GetNumberAsDouble()), float(v.Get(1).GetNumberAsDouble()),
                          float(v.Get(2).GetNumberAsDouble()));
        else
            warn(label + ": specularColorFactor is not an array of three numbers; the default (1, 1, 1) is used");
    }
    for (const char* texture : {"specularTexture", "specularColorTexture"})
        if (ext.Has(texture))
            warn(label + ": KHR_materials_specular " + texture + " is not supported; the factor alone is used");
}

/// The primitive's triangles as a list of vertex indices: its indices (checked against the vertex count) or the
/// vertices in order, strips and fans unrolled keeping glTF's winding, trailing indices dropped.
std::vector<uint32_t> Importer::triangleList(const tinygltf::Primitive& prim, int mode, size_t vertexCount,
                                             const std::string& label) {
    std::vector<uint32_t> idx;
    if (prim.indices >= 0) {
        idx = readIndices(prim.indices, label + "/indices");
        for (size_t i = 0; i < idx.size(); ++i)
            if (idx[i] >= vertexCount)
                fail(label + "/indices (accessors[" + std::to_string(prim.indices) + "])",
                     "index " + std::to_string(idx[i]) + " at position " + std::to_string(i) +
                         " is out of range: the primitive has " + std::to_string(vertexCount) + " vertices",
                     "indices below the vertex count");
    } else {
        idx.resize(vertexCount);  // non-indexed: vertices in order
        for (size_t i = 0; i < vertexCount; ++i) idx[i] = uint32_t(i);
    }

    // Strips and fans become lists, keeping glTF's winding (glTF 2.0 section 3.7.2.1).
    if (mode == TINYGLTF_MODE_TRIANGLE_STRIP || mode == TINYGLTF_MODE_TRIANGLE_FAN) {
        std::vector<uint32_t> list;
        for (size_t i = 2; i < idx.size(); ++i) {
            if (mode == TINYGLTF_MODE_TRIANGLE_FAN)
                list.insert(list.end(), {idx[0], idx[i - 1], idx[i]});
            else if (i % 2 == 0)
                list.insert(list.end(), {idx[i - 2], idx[i - 1], idx[i]});
            else
                list.insert(list.end(), {idx[i - 2], idx[i], idx[i - 1]});
        }
        idx = std::move(list);
    } else if (idx.size() % 3 != 0) {
        warn(label + ": " + std::to_string(idx.size() % 3) + " trailing indices do not form a triangle; ignored");
        idx.resize(idx.size() - idx.size() % 3);
    }

    return idx;
}

/// The mesh's normals: the file's (zero-length ones replaced by the adjacent faces' normal) with its tangents, or
/// flat normals when the file has none (every triangle then gets its own three vertices).
void Importer::setNormals(Mesh& mesh, const std::vector<float>& nrm, const std::vector<float>& tng,
                          const std::string& label) {
    const size_t vertexCount = mesh.positions.size();
    if (nrm.empty()) {
        // glTF 2.0 section 3.7.2.1: without normals, flat normals. Every triangle gets its own three
        // vertices, so the normal is constant over it.
        Mesh flat;
        flat.name = mesh.name;
        const size_t n = mesh.indices.size();
        flat.positions.resize(n);
        flat.uvs.resize(n);
        flat.normals.resize(n);
        if (!tng.empty()) flat.tangents.resize(n);
        flat.indices.resize(n);
        for (size_t i = 0; i < n; ++i) {
            const uint32_t v = mesh.indices[i];
            flat.positions[i] = mesh.positions[v];
            flat.uvs[i] = mesh.uvs[v];
            if (!tng.empty()) flat.tangents[i] = glm::make_vec4(&tng[4 * size_t(v)]);
            flat.indices[i] = uint32_t(i);
        }
        for (size_t t = 0; t < n; t += 3) {
            const glm::vec3 fn = faceNormal(flat.positions[t], flat.positions[t + 1], flat.positions[t + 2]);
            flat.normals[t] = flat.normals[t + 1] = flat.normals[t + 2] = fn;
        }
        mesh = std::move(flat);
    } else {
        mesh.normals.resize(vertexCount);
        // Zero-length normals (seen in exported files) become the average of the adjacent faces' normals.
        std::vector<glm::vec3> faceSum;
        size_t repaired = 0;
        for (size_t v = 0; v < vertexCount; ++v) {
            const glm::vec3 n = glm::make_vec3(&nrm[3 * v]);
            // Scaled by its largest component first: the length of a normal near 1e30 overflows (Inf, and n / Inf
            // is a zero normal), that of one near 1e-30 underflows; the direction is what counts.
            const float largest = std::max({std::fabs(n.x), std::fabs(n.y), std::fabs(n.z)});
            if (largest > 0.f && std::isfinite(largest)) {
                const glm::vec3 d = n / largest;
                mesh.normals[v] = d / glm::length(d);
                continue;
            }
            if (faceSum.empty()) {
                faceSum.assign(vertexCount, glm::vec3(0.f));
                for (size_t t = 0; t < mesh.indices.size(); t += 3) {
                    const uint32_t* i = &mesh.indices[t];
                    const glm::vec3 c = glm::cross(mesh.positions[i[1]] - mesh.positions[i[0]],
                                                   mesh.positions[i[2]] - mesh.positions[i[0]]);
                    for (int k = 0; k < 3; ++k) faceSum[i[k]] += c;  // area-weighted
                }
            }
            const float fl = glm::length(faceSum[v]);
            mesh.normals[v] = fl > 0.f ? faceSum[v] / fl : glm::vec3(0.f, 0.f, 1.f);
            ++repaired;
        }
        if (repaired > 0)
            warn(label + ": " + std::to_string(repaired) + " zero-length normals replaced by face normals");
        if (!tng.empty()) {
            mesh.tangents.resize(vertexCount);
            for (size_t v = 0; v < vertexCount; ++v) mesh.tangents[v] = glm::make_vec4(&tng[4 * v]);
        }
    }
}

/// Tangents for every vertex: generated (or any perpendicular) when the file gives none, else the file's made unit,
/// orthogonal to the normal and with w exactly +-1, as the shading code assumes.
void Importer::setTangents(Mesh& mesh) {
    if (mesh.tangents.empty()) {
        if (mOptions.generateTangents) {
            generateTangents(mesh);
        } else {
            mesh.tangents.resize(mesh.positions.size());
            for (size_t v = 0; v < mesh.positions.size(); ++v)
                mesh.tangents[v] = glm::vec4(anyPerpendicular(mesh.normals[v]), 1.f);
        }
    } else {
        // File tangents: unit xyz orthogonal to the normal, w exactly +-1, as the shading code assumes.
        for (size_t v = 0; v < mesh.tangents.size(); ++v) {
            const glm::vec3 n = mesh.normals[v];
            glm::vec3 t = glm::vec3(mesh.tangents[v]);
            t -= n * glm::dot(n, t);
            const float len = glm::length(t);
            t = len > 1e-12f ? t / len : anyPerpendicular(n);
            mesh.tangents[v] = glm::vec4(t, mesh.tangents[v].w < 0.f ? -1.f : 1.f);
        }
    }
}

std::optional<Mesh> Importer::convertPrimitive(size_t meshIndex, size_t primIndex) {
    const tinygltf::Primitive& prim = m.meshes[meshIndex].primitives[primIndex];
    const std::string label = meshLabel(meshIndex) + "/primitives[" + std::to_string(primIndex) + "]";
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        static const char* names[] = {"points", "lines", "line loop", "line strip"};
        warn(label + ": primitive mode " + (mode >= 0 && mode < 4 ? names[mode] : std::to_string(mode)) +
             " is not made of triangles; the primitive is skipped");
        return std::nullopt;
    }
    auto attribute = [&](const char* name) {
        auto it = prim.attributes.find(name);
        return it == prim.attributes.end() ? -1 : it->second;
    };
    const int posAcc = attribute("POSITION");
    if (posAcc < 0) {
        warn(label + ": no POSITION attribute; the primitive is skipped");
        return std::nullopt;
    }

    Mesh mesh;
    const std::string& gltfName = m.meshes[meshIndex].name;
    mesh.name = (gltfName.empty() ? "mesh" + std::to_string(meshIndex) : gltfName) + "/" + std::to_string(primIndex);

    const std::vector<float> pos = readAccessor<float>(posAcc, label + "/POSITION", TINYGLTF_TYPE_VEC3);
    const size_t vertexCount = pos.size() / 3;
    if (vertexCount == 0) {
        warn(label + ": POSITION has no vertices; the primitive is skipped");
        return std::nullopt;
    }
    mesh.positions.resize(vertexCount);
    std::memcpy(mesh.positions.data(), pos.data(), pos.size() * sizeof(float));

    auto readMatching = [&](const char* name, int type, size_t comps) -> std::vector<float> {
        const int acc = attribute(name);
        if (acc < 0) return {};
        std::vector<float> v = readAccessor<float>(acc, label + "/" + name, type);
        if (v.size() / comps != vertexCount)
            fail(
                label + "/" + name + " (accessors[" + std::to_string(acc) + "])",
                "has " + std::to_string(v.size() / comps) + " elements but POSITION has " + std::to_string(vertexCount),
                "one element per vertex");
        return v;
    };
    const std::vector<float> nrm = readMatching("NORMAL", TINYGLTF_TYPE_VEC3, 3);
    const std::vector<float> tng = readMatching("TANGENT", TINYGLTF_TYPE_VEC4, 4);
    const std::vector<float> uv = readMatching("TEXCOORD_0", TINYGLTF_TYPE_VEC2, 2);
    if (attribute("COLOR_0") >= 0) warn(label + ": vertex colours (COLOR_0) are not supported and are ignored");
    if (!prim.targets.empty()) warn(label + ": morph targets are not supported; the base shape is used");

    mesh.uvs.assign(vertexCount, glm::vec2(0.f));
    if (!uv.empty()) std::memcpy(mesh.uvs.data(), uv.data(), uv.size() * sizeof(float));

    std::vector<uint32_t> idx = triangleList(prim, mode, vertexCount, label);

    // Degenerate triangles have no face normal and no area to hit: drop them.
    size_t degenerate = 0;
    for (size_t t = 0; t < idx.size(); t += 3) {
        if (isDegenerate(mesh.positions[idx[t]], mesh.positions[idx[t + 1]], mesh.positions[idx[t + 2]])) {
            ++degenerate;
            continue;
        }
        mesh.indices.insert(mesh.indices.end(), {idx[t], idx[t + 1], idx[t + 2]});
    }
    if (degenerate > 0)
        warn(label + ": " + std::to_string(degenerate) + " degenerate (zero-area) triangle" +
             (degenerate > 1 ? "s" : "") + " dropped");
    if (mesh.indices.empty()) {
        warn(label + ": no triangles left; the primitive is skipped");
        return std::nullopt;
    }

    setNormals(mesh, nrm, tng, label);
    setTangents(mesh);

    if (prim.material >= 0 && size_t(prim.material) < m.materials.size()) {
        mesh.material = uint32_t(prim.material);
    } else {
        if (prim.material >= 0)
            warn(label + ": material " + std::to_string(prim.material) +
                 " does not exist; the default material is used");
        mesh.material = defaultMaterial();
    }
    return mesh;
}

void Importer::convertMeshes() {
    mMeshMap.resize(m.meshes.size());
    for (size_t i = 0; i < m.meshes.size(); ++i) {
        for (size_t p = 0; p < m.meshes[i].primitives.size(); ++p) {
            std::optional<Mesh> mesh = convertPrimitive(i, p);
            if (!mesh) continue;
            mMeshMap[i].push_back(uint32_t(s.meshes.size()));
            s.meshes.push_back(std::move(*mesh));
        }
    }
}

void Importer::convertCameras() {
    for (size_t i = 0; i < m.cameras.size(); ++i) {
        const tinygltf::Camera& src = m.cameras[i];
        const std::string label = labelOf("cameras", i, src.name);
        Camera cam;
        cam.name = !src.name.empty() ? src.name : "camera" + std::to_string(i);
        if (src.type == "perspective") {
            const auto& p = src.perspective;
            if (p.yfov > 0.0 && p.yfov < std::numbers::pi)
                cam.fovY = float(p.yfov);
            else
                warn(label + ": yfov " + std::to_string(p.yfov) + " is not in (0, pi); using " +
                     std::to_string(cam.fovY));
            if (p.aspectRatio > 0.0) cam.aspect = float(p.aspectRatio);
            if (p.znear > 0.0) cam.nearZ = float(p.znear);
            // No zfar means an infinite projection; a float depth buffer resolves 1e5 x near well.
            cam.farZ = p.zfar > p.znear ? float(p.zfar) : cam.nearZ * 1e5f;
        } else {
            warn(label + ": " + (src.type.empty() ? std::string("untyped") : src.type) +
                 " camera is not supported; it is replaced by a perspective camera with the same pose");
            if (src.orthographic.znear >= 0.0 && src.orthographic.zfar > src.orthographic.znear) {
                cam.nearZ = std::max(float(src.orthographic.znear), 1e-3f);
                cam.farZ = float(src.orthographic.zfar);
            }
        }
        s.cameras.push_back(std::move(cam));
    }
}

void Importer::convertNodes(const std::vector<int>& roots) {
    bool skinWarned = false;
    s.nodes.resize(m.nodes.size());
    for (size_t i = 0; i < m.nodes.size(); ++i) {
        const tinygltf::Node& src = m.nodes[i];
        const std::string label = labelOf("nodes", i, src.name);
        Node& node = s.nodes[i];
        node.name = !src.name.empty() ? src.name : "node" + std::to_string(i);
        node.children = src.children;
        for (int c : node.children)
            if (c < 0 || size_t(c) >= m.nodes.size())
                fail(label, "child " + std::to_string(c) + " does not exist",
                     "a node index below " + std::to_string(m.nodes.size()));
        auto finite = [](const std::vector<double>& v) {
            return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
        };
        if (!finite(src.matrix) || !finite(src.translation) || !finite(src.rotation) || !finite(src.scale))
            fail(label, "the transform contains NaN or infinite values",
                 "finite matrix / translation / rotation / scale");
        if (src.matrix.size() == 16) {
            node.hasMatrix = true;
            for (int k = 0; k < 16; ++k) node.matrix[k / 4][k % 4] = float(src.matrix[size_t(k)]);  // column-major
        } else {
            if (src.translation.size() == 3)
                node.translation =
                    glm::vec3(float(src.translation[0]), float(src.translation[1]), float(src.translation[2]));
            if (src.rotation.size() == 4) {
                const glm::vec4 q(float(src.rotation[0]), float(src.rotation[1]), float(src.rotation[2]),
                                  float(src.rotation[3]));
                const float len = glm::length(q);
                node.rotation =
                    len > 0.f ? glm::quat(q.w / len, q.x / len, q.y / len, q.z / len) : glm::quat(1, 0, 0, 0);
            }
            if (src.scale.size() == 3)
                node.scale = glm::vec3(float(src.scale[0]), float(src.scale[1]), float(src.scale[2]));
        }
        if (src.mesh >= 0) {
            if (size_t(src.mesh) >= m.meshes.size())
                fail(label, "mesh " + std::to_string(src.mesh) + " does not exist",
                     "a mesh index below " + std::to_string(m.meshes.size()));
            node.meshes = mMeshMap[size_t(src.mesh)];
            if (src.skin >= 0 && !skinWarned) {
                warn(label + ": skinning is not supported; skinned meshes are drawn in their bind pose");
                skinWarned = true;
            }
        }
        if (src.camera >= 0) {
            if (size_t(src.camera) < s.cameras.size())
                node.camera = src.camera;
            else
                warn(label + ": camera " + std::to_string(src.camera) + " does not exist; ignored");
        }
    }
    // Lights are placed while walking the active scene, one Scene::Light per node that references a glTF
    // light, so that a light used by two nodes shines from both.
    std::vector<bool> visited(m.nodes.size(), false);
    std::vector<int> stack(roots.rbegin(), roots.rend());
    while (!stack.empty()) {
        const int n = stack.back();
        stack.pop_back();
        if (visited[size_t(n)]) continue;  // shared children and cycles are reported by finalize()
        visited[size_t(n)] = true;
        const tinygltf::Node& src = m.nodes[size_t(n)];
        for (auto it = src.children.rbegin(); it != src.children.rend(); ++it) stack.push_back(*it);
        auto ext = src.extensions.find("KHR_lights_punctual");
        if (ext == src.extensions.end() || !ext->second.IsObject()) continue;
        const tinygltf::Value& lv = ext->second.Get("light");
        const std::string label = labelOf("nodes", size_t(n), src.name);
        if (!lv.IsNumber() || lv.GetNumberAsInt() < 0 || size_t(lv.GetNumberAsInt()) >= m.lights.size()) {
            warn(label + ": KHR_lights_punctual light does not exist; ignored");
            continue;
        }
        const size_t li = size_t(lv.GetNumberAsInt());
        const tinygltf::Light& gl = m.lights[li];
        Light light;
        light.name = !gl.name.empty() ? gl.name : "light" + std::to_string(li);
        if (gl.type == "point") {
            light.type = LightType::Point;
        } else if (gl.type == "spot") {
            light.type = LightType::Spot;
            light.innerConeAngle = float(gl.spot.innerConeAngle);
            light.outerConeAngle = float(gl.spot.outerConeAngle);
        } else if (gl.type == "directional") {
            light.type = LightType::Directional;
        } else {
            warn(labelOf("KHR_lights_punctual lights", li, gl.name) + ": unknown type '" + gl.type + "'; ignored");
            continue;
        }
        if (gl.color.size() == 3) light.color = glm::vec3(float(gl.color[0]), float(gl.color[1]), float(gl.color[2]));
        light.intensity = float(gl.intensity);
        light.range = float(gl.range);
        if (!allFinite(light.color) || !std::isfinite(light.intensity) || !std::isfinite(light.range))
            fail(labelOf("KHR_lights_punctual lights", li, gl.name), "NaN or infinite light parameters",
                 "finite color, intensity and range");
        light.node = n;
        light.source = int(li);
        s.nodes[size_t(n)].light = int(s.lights.size());
        s.lights.push_back(std::move(light));
    }
}

void Importer::convertAnimations() {
    for (size_t a = 0; a < m.animations.size(); ++a) {
        const tinygltf::Animation& src = m.animations[a];
        const std::string label = labelOf("animations", a, src.name);
        Animation anim;
        anim.name = !src.name.empty() ? src.name : "animation" + std::to_string(a);
        for (size_t k = 0; k < src.samplers.size(); ++k) {
            const tinygltf::AnimationSampler& ss = src.samplers[k];
            const std::string where = label + "/samplers[" + std::to_string(k) + "]";
            AnimationSampler sampler;
            if (ss.interpolation == "STEP") {
                sampler.interpolation = Interpolation::Step;
            } else if (ss.interpolation == "CUBICSPLINE") {
                sampler.interpolation = Interpolation::CubicSpline;
            } else if (ss.interpolation != "LINEAR") {
                warn(where + ": unknown interpolation '" + ss.interpolation + "'; LINEAR is used");
            }
            sampler.times = readAccessor<float>(ss.input, where + "/input", TINYGLTF_TYPE_SCALAR);
            if (sampler.times.empty()) fail(where + "/input", "the sampler has no keyframes", "at least one key");
            for (size_t t = 1; t < sampler.times.size(); ++t)
                if (sampler.times[t] < sampler.times[t - 1])
                    fail(where + "/input", "key times decrease at key " + std::to_string(t), "increasing key times");
            if (sampler.times.front() < 0.f)
                fail(where + "/input", "negative key time " + std::to_string(sampler.times.front()), "key times >= 0");
            // The output type depends on the channel that uses the sampler; it is checked per channel below.
            if (ss.output < 0 || size_t(ss.output) >= m.accessors.size())
                fail(where + "/output", "accessor " + std::to_string(ss.output) + " does not exist",
                     "an accessor index below " + std::to_string(m.accessors.size()));
            const int type = m.accessors[size_t(ss.output)].type;
            if (type != TINYGLTF_TYPE_VEC3 && type != TINYGLTF_TYPE_VEC4) {
                anim.samplers.push_back(std::move(sampler));  // e.g. morph weights: unused, kept for indices
                continue;
            }
            readSamplerValues(sampler, ss.output, type, where);
            anim.samplers.push_back(std::move(sampler));
        }
        bool weightsWarned = false;
        for (size_t c = 0; c < src.channels.size(); ++c) {
            const tinygltf::AnimationChannel& ch = src.channels[c];
            const std::string where = label + "/channels[" + std::to_string(c) + "]";
            if (ch.target_path == "pointer") continue;  // read from the JSON (mPointers) below
            if (ch.target_path == "weights") {
                if (!weightsWarned) warn(where + ": morph-target weight animation is not supported; ignored");
                weightsWarned = true;
                continue;
            }
            AnimationChannel out;
            size_t comps = 3;
            if (ch.target_path == "translation") {
                out.path = AnimPath::Translation;
            } else if (ch.target_path == "rotation") {
                out.path = AnimPath::Rotation;
                comps = 4;
            } else if (ch.target_path == "scale") {
                out.path = AnimPath::Scale;
            } else {
                warn(where + ": unknown target path '" + ch.target_path + "'; ignored");
                continue;
            }
            if (ch.target_node < 0) continue;  // targets defined by an extension Loom does not know
            if (size_t(ch.target_node) >= m.nodes.size())
                fail(where, "target node " + std::to_string(ch.target_node) + " does not exist",
                     "a node index below " + std::to_string(m.nodes.size()));
            if (ch.sampler < 0 || size_t(ch.sampler) >= anim.samplers.size())
                fail(where, "sampler " + std::to_string(ch.sampler) + " does not exist",
                     "a sampler index below " + std::to_string(anim.samplers.size()));
            const tinygltf::Accessor& outAcc = m.accessors[size_t(src.samplers[size_t(ch.sampler)].output)];
            if (size_t(tinygltf::GetNumComponentsInType(uint32_t(outAcc.type))) != comps)
                fail(where, "the sampler's output is " + std::string(typeName(outAcc.type)) + " but " + ch.target_path +
                                " needs " + (comps == 3 ? "VEC3" : "VEC4"));
            if (s.nodes[size_t(ch.target_node)].hasMatrix) {
                warn(where + ": targets " +
                     labelOf("nodes", size_t(ch.target_node), m.nodes[size_t(ch.target_node)].name) +
                     ", which has a matrix (glTF forbids animating it); ignored");
                continue;
            }
            out.node = ch.target_node;
            out.sampler = uint32_t(ch.sampler);
            anim.channels.push_back(out);
        }
        for (const PointerChannel& pc : mPointers)
            if (pc.animation == a)
                convertPointerChannel(pc, src, anim, label + "/channels[" + std::to_string(pc.channel) + "]");
        s.animations.push_back(std::move(anim));
    }
}

/// The output accessor's values (SCALAR, VEC3 or VEC4; as vec4, unused components 0), checked against the key count.
void Importer::readSamplerValues(AnimationSampler& sampler, int output, int type, const std::string& where) {
    const std::vector<float> out = readAccessor<float>(output, where + "/output", type);
    const size_t comps = type == TINYGLTF_TYPE_SCALAR ? 1 : type == TINYGLTF_TYPE_VEC3 ? 3 : 4;
    const size_t expected = sampler.times.size() * (sampler.interpolation == Interpolation::CubicSpline ? 3 : 1);
    if (out.size() / comps != expected)
        fail(where + "/output",
             "has " + std::to_string(out.size() / comps) + " values for " + std::to_string(sampler.times.size()) +
                 " keys",
             std::to_string(expected) + " values" +
                 (sampler.interpolation == Interpolation::CubicSpline ? " (in-tangent, value, out-tangent per key)"
                                                                      : ""));
    sampler.values.resize(expected);
    for (size_t v = 0; v < expected; ++v)
        sampler.values[v] = comps == 1   ? glm::vec4(out[v], 0.f, 0.f, 0.f)
                            : comps == 3 ? glm::vec4(glm::make_vec3(&out[3 * v]), 0.f)
                                         : glm::make_vec4(&out[4 * v]);
}

/// A KHR_animation_pointer channel: node TRS, a material's emission, a punctual light's intensity or colour. An
/// unsupported pointer is ignored with one warning per pointer, or is an error when the file requires the
/// extension; a malformed pointer, an index out of range, a wrong output type and a negative light value are errors.
void Importer::convertPointerChannel(const PointerChannel& pc, const tinygltf::Animation& src, Animation& anim,
                                     const std::string& where) {
    if (!pc.pointer)
        fail(where, "the target path is \"pointer\" but target/extensions/KHR_animation_pointer/pointer is missing",
             "a JSON pointer string such as \"/materials/0/emissiveFactor\"");
    const std::string& pointer = *pc.pointer;
    const std::string at = where + " (pointer '" + pointer + "')";
    const std::optional<PointerTarget> target = supportedPointer(pointer);
    if (!target) {
        const std::string supported =
            "/nodes/{i}/translation|rotation|scale, /materials/{i}/emissiveFactor, "
            "/materials/{i}/extensions/KHR_materials_emissive_strength/emissiveStrength, "
            "/extensions/KHR_lights_punctual/lights/{i}/intensity|color";
        if (std::find(m.extensionsRequired.begin(), m.extensionsRequired.end(), kAnimationPointer) !=
            m.extensionsRequired.end())
            fail(at, "the file requires KHR_animation_pointer and Loom cannot animate this property",
                 "one of " + supported, "remove the channel or KHR_animation_pointer from extensionsRequired");
        if (mWarnedPointers.insert(pointer).second)
            warn(at + ": KHR_animation_pointer target not supported (Loom animates " + supported +
                 "); the channel is ignored");
        return;
    }
    // The object's index: an RFC 6901 array index (no sign, no leading zero) below the object count.
    const size_t count = target->kind == std::string("nodes")       ? m.nodes.size()
                         : target->kind == std::string("materials") ? s.materials.size()
                                                                    : m.lights.size();
    const std::string& token = target->index;
    const bool digits = !token.empty() && token.size() <= 9 &&
                        std::all_of(token.begin(), token.end(), [](char c) { return c >= '0' && c <= '9'; }) &&
                        (token == "0" || token[0] != '0');
    if (!digits) fail(at, "'" + token + "' is not an index into " + target->kind, "a decimal index");
    const size_t index = size_t(std::stoul(token));
    if (index >= count)
        fail(at, std::string(target->kind) + " " + token + " does not exist",
             "an index below " + std::to_string(count));
    if (pc.sampler < 0 || size_t(pc.sampler) >= anim.samplers.size())
        fail(at, "sampler " + std::to_string(pc.sampler) + " does not exist",
             "a sampler index below " + std::to_string(anim.samplers.size()));
    const int expectedType = target->path == AnimPath::Rotation ? TINYGLTF_TYPE_VEC4
                             : target->path == AnimPath::EmissiveStrength || target->path == AnimPath::LightIntensity
                                 ? TINYGLTF_TYPE_SCALAR
                                 : TINYGLTF_TYPE_VEC3;
    const tinygltf::AnimationSampler& ss = src.samplers[size_t(pc.sampler)];
    const int type = m.accessors[size_t(ss.output)].type;  // the index was checked with the sampler
    if (type != expectedType)
        fail(at, std::string("the sampler's output is ") + typeName(type), typeName(expectedType));
    AnimationSampler& sampler = anim.samplers[size_t(pc.sampler)];
    if (sampler.values.empty())
        readSamplerValues(sampler, ss.output, type, where + "/samplers[" + std::to_string(pc.sampler) + "]");

    AnimationChannel out;
    out.path = target->path;
    out.sampler = uint32_t(pc.sampler);
    if (!animatesLight(target->path)) {
        if (s.nodes[index].hasMatrix) {
            warn(at + ": targets " + labelOf("nodes", index, m.nodes[index].name) +
                 ", which has a matrix (glTF forbids animating it); ignored");
            return;
        }
        out.node = int(index);
        anim.channels.push_back(out);
        return;
    }
    // Emitted light is never negative (the values are finite: readAccessor checked them). Cubic-spline tangents may
    // be negative; the sampled value is clamped at 0 when it overshoots.
    const bool cubic = sampler.interpolation == Interpolation::CubicSpline;
    const size_t comps = type == TINYGLTF_TYPE_SCALAR ? 1 : 3;
    for (size_t k = 0; k < sampler.times.size(); ++k) {
        const glm::vec4 v = sampler.values[cubic ? 3 * k + 1 : k];
        for (size_t c = 0; c < comps; ++c)
            if (v[int(c)] < 0.f)
                fail(at, "key " + std::to_string(k) + " has the negative value " + std::to_string(v[int(c)]),
                     "values >= 0 (emitted light)");
    }
    out.target = int(index);
    anim.channels.push_back(out);
}

/// A node that is its own descendant is an error naming it, before the scene's roots are worked out (a cycle has
/// no root: otherwise the scene would only look empty).
void Importer::checkNodeCycles() const {
    enum : uint8_t { kNew, kOpen, kDone };
    std::vector<uint8_t> state(m.nodes.size(), kNew);
    std::vector<std::pair<size_t, size_t>> stack;  // (node, next child)
    for (size_t start = 0; start < m.nodes.size(); ++start) {
        if (state[start] != kNew) continue;
        stack.assign(1, {start, 0});
        state[start] = kOpen;
        while (!stack.empty()) {
            auto& [n, next] = stack.back();
            const std::vector<int>& children = m.nodes[n].children;
            if (next == children.size()) {
                state[n] = kDone;
                stack.pop_back();
                continue;
            }
            const int c = children[next++];
            if (c < 0 || size_t(c) >= m.nodes.size()) continue;  // reported by convertNodes
            if (state[size_t(c)] == kOpen) {
                std::string path;
                bool on = false;
                for (const auto& [k, _] : stack) {
                    on = on || k == size_t(c);
                    if (on) path += labelOf("nodes", k, m.nodes[k].name) + " -> ";
                }
                path += labelOf("nodes", size_t(c), m.nodes[size_t(c)].name);
                fail(labelOf("nodes", size_t(c), m.nodes[size_t(c)].name), "the node hierarchy has a cycle: " + path,
                     "a tree: no node is its own ancestor", "remove the child reference that closes the cycle");
            }
            if (state[size_t(c)] == kNew) {
                state[size_t(c)] = kOpen;
                stack.emplace_back(size_t(c), 0);
            }
        }
    }
}

/// Every instance's vertices at time 0 lie within kWorldLimit, the range rays are traced in: beyond it (a node scaled
/// by 1e30, say) positions, their derivatives and the camera that frames them overflow to Inf and NaN (motion vectors
/// were NaN). A node scaled to 0 on some axis (hidden, Instance::visible) collapses its vertices and passes.
void Importer::checkWorldRange() const {
    for (const Instance& inst : s.instances) {
        const Bounds& b = s.meshes[inst.mesh].bounds;
        float largest = 0.f;
        for (int corner = 0; corner < 8; ++corner) {
            const glm::vec3 p(corner & 1 ? b.hi.x : b.lo.x, corner & 2 ? b.hi.y : b.lo.y, corner & 4 ? b.hi.z : b.lo.z);
            const glm::vec4 w = inst.world * glm::vec4(p, 1.f);
            for (int c = 0; c < 3; ++c) largest = std::isfinite(w[c]) ? std::max(largest, std::fabs(w[c])) : INFINITY;
        }
        if (largest <= kWorldLimit) continue;
        char value[32];
        std::snprintf(value, sizeof value, "%g", double(largest));
        fail(labelOf("nodes", inst.node, m.nodes[inst.node].name),
             "the node places mesh '" + s.meshes[inst.mesh].name + "' at world coordinates up to " + value +
                 " (at time 0, its parents' transforms included)",
             "world coordinates within +-1e8, the range Loom traces rays in",
             "scale the scene down, or fix the node's (or a parent's) scale, translation or matrix");
    }
}

void Importer::run() {
    checkRequiredExtensions(m.extensionsRequired, mFile);
    checkNodeCycles();
    for (const std::string& ext : m.extensionsUsed) {
        const bool handled =
            std::find(kSupportedRequired.begin(), kSupportedRequired.end(), ext) != kSupportedRequired.end();
        if (!handled) warn("extension '" + ext + "' is not supported; its data is ignored");
    }

    // The active scene: "scene", else the first one; with no scenes at all, every root node.
    std::vector<bool> isChild(m.nodes.size(), false);
    for (const tinygltf::Node& n : m.nodes)
        for (int c : n.children)
            if (c >= 0 && size_t(c) < m.nodes.size()) isChild[size_t(c)] = true;
    std::vector<int> roots;
    if (!m.scenes.empty()) {
        size_t si = 0;
        if (m.defaultScene >= 0 && size_t(m.defaultScene) < m.scenes.size())
            si = size_t(m.defaultScene);
        else if (m.defaultScene >= 0)
            warn("scene " + std::to_string(m.defaultScene) + " does not exist; scenes[0] is shown");
        roots = m.scenes[si].nodes;
        s.name = m.scenes[si].name;
        for (int r : roots)
            if (r < 0 || size_t(r) >= m.nodes.size())
                fail(labelOf("scenes", si, m.scenes[si].name), "node " + std::to_string(r) + " does not exist",
                     "a node index below " + std::to_string(m.nodes.size()));
        if (roots.empty())
            fail(labelOf("scenes", si, m.scenes[si].name), "scene has no triangles (it has no nodes)",
                 "a scene with at least one mesh");
        // A scene lists root nodes only, once each; anything else would instance meshes twice.
        std::vector<int> unique;
        for (int r : roots) {
            if (isChild[size_t(r)])
                warn(labelOf("scenes", si, m.scenes[si].name) + ": " +
                     labelOf("nodes", size_t(r), m.nodes[size_t(r)].name) +
                     " is listed as a root but is the child of another node; it is shown once, under its parent");
            else if (std::find(unique.begin(), unique.end(), r) == unique.end())
                unique.push_back(r);
        }
        roots = std::move(unique);
    } else {
        for (size_t i = 0; i < m.nodes.size(); ++i)
            if (!isChild[i]) roots.push_back(int(i));
        if (!roots.empty()) warn("the file defines no scene; all root nodes are shown");
    }
    if (s.name.empty()) s.name = s.file.stem().string();

    convertImages();
    convertMaterials();
    convertMeshes();
    convertCameras();
    convertNodes(roots);
    convertAnimations();
    if (s.materials.empty()) defaultMaterial();
    s.roots = roots;
    if (s.roots.empty()) fail({}, "scene has no triangles (the file has no nodes)", "at least one node with a mesh");

    try {
        s.finalize();
    } catch (const Error& e) {
        throw e.withFile(mFile);
    }
    checkWorldRange();
    if (s.triangleCount() == 0)
        fail({}, "scene has no triangles", "at least one node with a triangle mesh in the active scene",
             s.warnings.empty() ? "" : "see the warnings above for skipped primitives");
    s.update(0.0);
}

[[noreturn]] void throwOutOfMemory(const std::string& file, const std::string& doing) {
    throwBadInput({}, "out of memory " + doing, "a scene that fits in memory",
                  "free memory, or simplify the scene (smaller textures, fewer triangles)", file);
}

}  // namespace

std::shared_ptr<Scene> Scene::load(const std::filesystem::path& file, const SceneLoadOptions& options) {
    const std::string name = file.string();
    std::error_code ec;
    if (!fs::exists(file, ec))
        throwBadInput({}, "scene file not found", "a .gltf or .glb file", "check the path", name);
    // Read once: the magic, the JSON check before tinygltf (which recurses into nested values: extras,
    // extensions), tinygltf itself and the diagnosis of a failure all use these bytes.
    const std::string bytes = readInputFile(file, "scene file", "a .gltf or .glb file", kMaxSceneFileBytes);
    // The magic decides, whatever the extension says: "glTF" starts a binary container.
    const bool binary = bytes.compare(0, 4, "glTF") == 0;
    std::string ext = file.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext == ".glb" && !binary)
        throwBadInput({}, "the file has a .glb extension but does not start with the GLB magic 'glTF'",
                      "a binary glTF container", "if it is JSON, rename it to .gltf", name);

    auto scene = std::make_shared<Scene>();
    scene->file = file;

    std::string_view jsonText;
    if (!binary) {
        checkJsonText(bytes, name);
        jsonText = bytes;
    } else if (bytes.size() >= 12) {
        uint32_t version;
        std::memcpy(&version, bytes.data() + 4, 4);
        // tinygltf reads a GLB of any version as glTF 2.0; version 1 is the KHR_binary_glTF container of glTF 1.0.
        if (version != 2)
            throwBadInput("GLB header", "GLB container version " + std::to_string(version), "version 2 (glTF 2.0)",
                          version == 1 ? "convert the glTF 1.0 file to glTF 2.0" : "", name);
    }
    if (binary && bytes.size() >= 20) {
        uint32_t length, type;
        std::memcpy(&length, bytes.data() + 12, 4);
        std::memcpy(&type, bytes.data() + 16, 4);
        if (type == 0x4E4F534Au && length <= bytes.size() - 20) {
            jsonText = std::string_view(bytes).substr(20, length);
            checkJsonText(jsonText, name);
        }
    }
    checkNonNegativeIndices(jsonText, name);

    tinygltf::Model model;
    ImageLoadContext images;
    images.model = &model;
    images.options = &options;
    images.file = name;
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(&inspectImage, &images);
    loader.SetFsCallbacks(
        {&referencedFileExists, &tinygltf::ExpandFilePath, &readReferencedFile, &tinygltf::WriteWholeFile, nullptr});
    std::string err, warn;
    const std::string baseDir = file.parent_path().string();
    bool ok = false;
    try {
        ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn,
                                                  reinterpret_cast<const unsigned char*>(bytes.data()),
                                                  unsigned(bytes.size()), baseDir)
                    : loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(), unsigned(bytes.size()), baseDir);
    } catch (const std::bad_alloc&) {
        if (!images.fatal) throwOutOfMemory(name, "parsing the file and its buffers");
    } catch (const std::exception& e) {
        err = e.what();  // diagnosed below with the rest
    }
    if (images.fatal) throw *images.fatal;  // a texture limit: the image is named
    // tinygltf's warnings are about images, which are reported again per material that uses them.
    if (!warn.empty()) spdlog::debug("{}: tinygltf: {}", name, cleanTinyMessage(warn));
    if (!ok) failLoad(file, bytes, binary, err.empty() ? warn : err);

    try {
        Importer(model, images, *scene, options, readPointerChannels(jsonText)).run();
    } catch (const std::bad_alloc&) {
        throwOutOfMemory(name, "converting the meshes and textures (" + mib(images.textureBytes) + " of textures)");
    }
    return scene;
}

}  // namespace loom
