// In-process byte-level fuzzing of Loom's file readers: the glTF loader (.gltf with data URIs, and .glb with the
// buffer and the images embedded), the EXR reader (every OpenEXR compression, scanline and tiled, float, half, uint
// and luminance channels), the Radiance .hdr reader and the PNG/JPEG decoders (alone and inside a scene).
//
// The seeds are built here from the shipped scenes (data/scenes/*.gltf), a Blender multilayer EXR
// (data/sequences) and from images written here. Each
// iteration takes a seed, applies one to four mutations (bit flips, bytes set to 0/0x7F/0x80/0xFF, truncation,
// inserted, deleted or repeated bytes, 32-bit counts set to 0/-1/huge, and finite-but-extreme or non-finite floats
// written into the float data of a buffer or an uncompressed EXR), writes the bytes to a file and reads it. The
// contract checked on every input:
//   - the reader returns, or throws a loom::Error of the bad-input kind (exit code 2 in the CLI) with a message;
//     any other exception, or a runtime error, is a finding;
//   - what it returns holds only finite values where Loom promises them (scene geometry and transforms, materials,
//     lights, environment maps);
//   - it does not hang: an iteration past --timeout seconds ends the run (exit code 3);
//   - no crash and, in the sanitizer build, no AddressSanitizer or UBSan report (the process aborts: the input
//     is then in the work folder's "current.*" file).
// Seeded: the same --seed and --iterations give the same inputs.
//
// Usage: loom_fuzz_loaders --source DIR [--seed N] [--iterations N] [--work DIR] [--crashers DIR] [--timeout S]
//                          [--only gltf|glb|exr|hdr|png|jpg|uri]
// --work: where the inputs are written (default: a new folder in /dev/shm, else in /tmp).
// Exit code 0 when every input kept the contract, 1 when any did not (each finding is printed and, with --crashers,
// its input saved there).
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfOutputFile.h>
#include <ImfTiledOutputFile.h>
#include <half.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <stb/stb_image_write.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/ExrFile.h"
#include "loom/ImageIO.h"
#include "loom/Scene.h"

namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

/// A seed input: its bytes, the extension it is read as, and byte ranges that hold floats (or image bytes) worth
/// aiming mutations at.
struct Seed {
    std::string name, ext, bytes;
    std::vector<std::pair<size_t, size_t>> floats;  ///< [begin, end) ranges of 4-byte floats
    std::vector<std::pair<size_t, size_t>> images;  ///< [begin, end) ranges of embedded PNG/JPEG bytes
};

// ---- base64 (the shipped scenes embed their buffers and images as data URIs) ----------------------------------

const char* kBase64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string base64Decode(const std::string& text) {
    std::string out;
    uint32_t acc = 0;
    int bits = 0;
    for (char c : text) {
        const char* p = std::strchr(kBase64, c);
        if (c == '=' || !p || c == 0) continue;
        acc = acc << 6 | uint32_t(p - kBase64);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            out += char((acc >> bits) & 0xFF);
        }
    }
    return out;
}

std::string base64Encode(const std::string& bytes) {
    std::string out;
    size_t i = 0;
    for (; i + 3 <= bytes.size(); i += 3) {
        const uint32_t v =
            uint32_t(uint8_t(bytes[i])) << 16 | uint32_t(uint8_t(bytes[i + 1])) << 8 | uint32_t(uint8_t(bytes[i + 2]));
        for (int k = 3; k >= 0; --k) out += kBase64[(v >> (6 * k)) & 63];
    }
    if (i < bytes.size()) {
        uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
        if (i + 1 < bytes.size()) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
        out += kBase64[(v >> 18) & 63];
        out += kBase64[(v >> 12) & 63];
        out += i + 1 < bytes.size() ? kBase64[(v >> 6) & 63] : '=';
        out += '=';
    }
    return out;
}

// ---- seeds ----------------------------------------------------------------------------------------------------

std::string readAll(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// A .glb holding the scene's JSON and one BIN chunk: the buffer, then each data-URI image as a bufferView.
Seed makeGlb(const std::string& name, const std::string& gltfText) {
    Json doc = Json::parse(gltfText);
    std::string bin = base64Decode(
        doc["buffers"][0]["uri"].get<std::string>().substr(doc["buffers"][0]["uri"].get<std::string>().find(',') + 1));
    std::vector<std::pair<size_t, size_t>> imageRanges;
    for (Json& image : doc["images"]) {
        const std::string uri = image.value("uri", "");
        if (uri.rfind("data:", 0) != 0) continue;
        const std::string bytes = base64Decode(uri.substr(uri.find(',') + 1));
        while (bin.size() % 4) bin += '\0';
        imageRanges.emplace_back(bin.size(), bin.size() + bytes.size());
        doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes.size()}});
        bin += bytes;
        image.erase("uri");
        image["bufferView"] = doc["bufferViews"].size() - 1;
        image["mimeType"] = uri.substr(5, uri.find(';') - 5);
    }
    while (bin.size() % 4) bin += '\0';
    doc["buffers"][0].erase("uri");
    doc["buffers"][0]["byteLength"] = bin.size();
    std::string json = doc.dump();
    while (json.size() % 4) json += ' ';
    auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
    Seed s{name + ".glb", ".glb", {}, {}, {}};
    s.bytes = "glTF" + u32(2) + u32(uint32_t(12 + 8 + json.size() + 8 + bin.size()));
    s.bytes += u32(uint32_t(json.size())) + u32(0x4E4F534Au) + json;
    s.bytes += u32(uint32_t(bin.size())) + u32(0x004E4942u);
    const size_t binStart = s.bytes.size();
    s.bytes += bin;
    for (const Json& acc : doc["accessors"]) {
        if (acc.value("componentType", 0) != 5126 || !acc.contains("bufferView")) continue;
        const Json& view = doc["bufferViews"][acc["bufferView"].get<size_t>()];
        const size_t begin = binStart + view.value("byteOffset", size_t(0));
        s.floats.emplace_back(begin, begin + view["byteLength"].get<size_t>());
    }
    for (auto [a, b] : imageRanges) s.images.emplace_back(binStart + a, binStart + b);
    return s;
}

/// OpenEXR writes through this into memory.
class MemoryStream : public Imf::OStream {
public:
    explicit MemoryStream(std::string& out) : Imf::OStream("memory"), mOut(out) {}
    void write(const char c[], int n) override {
        if (mPos + size_t(n) > mOut.size()) mOut.resize(mPos + size_t(n));
        std::memcpy(mOut.data() + mPos, c, size_t(n));
        mPos += size_t(n);
    }
    uint64_t tellp() override { return mPos; }
    void seekp(uint64_t pos) override { mPos = size_t(pos); }

private:
    std::string& mOut;
    size_t mPos = 0;
};

/// A small EXR: `channels` of `type`, scanline or tiled (optionally mip-mapped), with a pattern of values from
/// dark to bright. For uncompressed float files the pixel data is marked as a float range.
Seed makeExr(const std::string& name, Imf::Compression compression, Imf::PixelType type, const std::string& channels,
             int tiled) {
    const int w = 13, h = 7;
    Imf::Header header(w, h);
    header.compression() = compression;
    const size_t size = type == Imf::HALF ? 2 : 4;
    std::vector<std::vector<char>> planes;
    Imf::FrameBuffer fb;
    for (size_t c = 0; c < channels.size(); ++c) {
        const std::string ch(1, channels[c]);
        header.channels().insert(ch, Imf::Channel(type));
        std::vector<char> plane(size_t(w) * h * size);
        for (int i = 0; i < w * h; ++i) {
            const float v = float(i % 11) * 0.37f * float(c + 1);
            if (type == Imf::FLOAT) std::memcpy(&plane[size_t(i) * 4], &v, 4);
            if (type == Imf::UINT) {
                const uint32_t u = uint32_t(i * 7 + int(c));
                std::memcpy(&plane[size_t(i) * 4], &u, 4);
            }
            if (type == Imf::HALF) {
                const half hv(v);
                std::memcpy(&plane[size_t(i) * 2], &hv, 2);
            }
        }
        planes.push_back(std::move(plane));
    }
    for (size_t c = 0; c < channels.size(); ++c)
        fb.insert(std::string(1, channels[c]), Imf::Slice(type, planes[c].data(), size, size * w));
    Seed s{name, ".exr", {}, {}, {}};
    {
        MemoryStream stream(s.bytes);
        if (tiled) {
            header.setTileDescription(Imf::TileDescription(4, 4, tiled == 2 ? Imf::MIPMAP_LEVELS : Imf::ONE_LEVEL));
            Imf::TiledOutputFile file(stream, header);
            file.setFrameBuffer(fb);
            for (int level = 0; level < file.numLevels(); ++level)
                file.writeTiles(0, file.numXTiles(level) - 1, 0, file.numYTiles(level) - 1, level);
        } else {
            Imf::OutputFile file(stream, header);
            file.setFrameBuffer(fb);
            file.writePixels(h);
        }
    }
    if (compression == Imf::NO_COMPRESSION && type == Imf::FLOAT)
        s.floats.emplace_back(s.bytes.size() - size_t(h) * (8 + size_t(w) * 4 * channels.size()), s.bytes.size());
    return s;
}

/// A Radiance .hdr, run-length encoded (rows of 2, 2, width) or flat.
Seed makeHdr(const std::string& name, bool encoded) {
    const int w = encoded ? 24 : 5, h = 6;
    std::string s = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y " + std::to_string(h) + " +X " + std::to_string(w) + "\n";
    for (int y = 0; y < h; ++y) {
        std::vector<uint8_t> px(size_t(w) * 4);
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 4; ++c) px[size_t(x) * 4 + c] = uint8_t(c == 3 ? 120 + (x / 6) * 8 : (x / 3) * 30 + y);
        if (!encoded) {
            s.append(reinterpret_cast<const char*>(px.data()), px.size());
            continue;
        }
        s += std::string{2, 2, char(w >> 8), char(w & 0xFF)};
        for (int c = 0; c < 4; ++c) {
            for (int x = 0; x < w;) {
                int run = 1;
                while (x + run < w && run < 127 && px[size_t(x + run) * 4 + c] == px[size_t(x) * 4 + c]) ++run;
                if (run >= 3) {
                    s += char(128 + run);
                    s += char(px[size_t(x) * 4 + c]);
                    x += run;
                } else {
                    const int n = std::min(3, w - x);
                    s += char(n);
                    for (int k = 0; k < n; ++k) s += char(px[size_t(x + k) * 4 + c]);
                    x += n;
                }
            }
        }
    }
    return Seed{name, ".hdr", s, {}, {}};
}

Seed makeStbImage(const std::string& name, bool jpeg, int channels) {
    const int w = 17, h = 9;
    std::vector<uint8_t> px(size_t(w) * h * channels);
    for (size_t i = 0; i < px.size(); ++i) px[i] = uint8_t(i * 37 % 251);
    Seed s{name, jpeg ? ".jpg" : ".png", {}, {}, {}};
    auto append = [](void* context, void* data, int size) {
        static_cast<std::string*>(context)->append(static_cast<const char*>(data), size_t(size));
    };
    if (jpeg)
        stbi_write_jpg_to_func(append, &s.bytes, w, h, channels, px.data(), 80);
    else
        stbi_write_png_to_func(append, &s.bytes, w, h, channels, px.data(), w * channels);
    s.images.emplace_back(0, s.bytes.size());
    return s;
}

// ---- mutations ------------------------------------------------------------------------------------------------

const float kExtremeFloats[] = {1e30f,
                                -1e30f,
                                3e38f,
                                -3.4e38f,
                                std::numeric_limits<float>::max(),
                                std::numeric_limits<float>::min(),
                                std::numeric_limits<float>::denorm_min(),
                                -std::numeric_limits<float>::denorm_min(),
                                1e-40f,
                                -0.0f,
                                0.0f,
                                1e-30f,
                                std::numeric_limits<float>::infinity(),
                                -std::numeric_limits<float>::infinity(),
                                std::numeric_limits<float>::quiet_NaN()};
const int32_t kExtremeInts[] = {0, -1, 1, 0x7FFFFFFF, int32_t(0x80000000), 0xFFFF, 0x10000, 255, 256, 4096};

size_t pick(std::mt19937& rng, size_t n) {
    return n ? std::uniform_int_distribution<size_t>(0, n - 1)(rng) : 0;
}

void mutate(std::string& b, const Seed& seed, std::mt19937& rng) {
    const int count = 1 + int(pick(rng, 4));
    for (int m = 0; m < count; ++m) {
        const size_t op = pick(rng, 11);
        if (b.empty()) {
            b.push_back(char(pick(rng, 256)));
            continue;
        }
        switch (op) {
            case 0:
            case 1: {  // bit flips
                for (size_t k = 1 + pick(rng, 8); k > 0; --k) b[pick(rng, b.size())] ^= char(1u << pick(rng, 8));
                break;
            }
            case 2: {  // an interesting byte
                const char values[] = {0, 0x7F, char(0x80), char(0xFF), 1, 2};
                b[pick(rng, b.size())] = values[pick(rng, 6)];
                break;
            }
            case 3:  // truncation
                b.resize(pick(rng, b.size()));
                break;
            case 4: {  // inserted bytes
                std::string ins(1 + pick(rng, 16), '\0');
                for (char& c : ins) c = char(pick(rng, 256));
                b.insert(pick(rng, b.size() + 1), ins);
                break;
            }
            case 5: {  // deleted bytes
                const size_t at = pick(rng, b.size());
                b.erase(at, 1 + pick(rng, 16));
                break;
            }
            case 6: {  // a repeated stretch
                const size_t at = pick(rng, b.size());
                const std::string piece = b.substr(at, 1 + pick(rng, 64));
                b.insert(pick(rng, b.size() + 1), piece);
                break;
            }
            case 7: {  // a 32-bit count or length set to an extreme (aligned, as headers are)
                if (b.size() < 4) break;
                const size_t at = pick(rng, b.size() / 4) * 4;
                const int32_t v = kExtremeInts[pick(rng, std::size(kExtremeInts))];
                std::memcpy(b.data() + at, &v, 4);
                break;
            }
            case 8:
            case 9: {  // extreme floats into float data
                if (seed.floats.empty()) break;
                const auto [begin, end] = seed.floats[pick(rng, seed.floats.size())];
                for (size_t k = 1 + pick(rng, 6); k > 0; --k) {
                    const size_t at = begin + pick(rng, (end - begin) / 4) * 4;
                    const float v = kExtremeFloats[pick(rng, std::size(kExtremeFloats))];
                    if (at + 4 <= b.size()) std::memcpy(b.data() + at, &v, 4);
                }
                break;
            }
            default: {  // damage inside an embedded image
                if (seed.images.empty()) break;
                const auto [begin, end] = seed.images[pick(rng, seed.images.size())];
                for (size_t k = 1 + pick(rng, 4); k > 0; --k) {
                    const size_t at = begin + pick(rng, end - begin);
                    if (at < b.size()) b[at] = pick(rng, 2) ? char(pick(rng, 256)) : char(b[at] ^ (1 << pick(rng, 8)));
                }
                break;
            }
        }
    }
}

// ---- reading and checking -------------------------------------------------------------------------------------

bool finite(const glm::vec2& v) {
    return std::isfinite(v.x) && std::isfinite(v.y);
}
bool finite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
bool finite(const glm::vec4& v) {
    return finite(glm::vec3(v)) && std::isfinite(v.w);
}
bool finite(const glm::mat4& m) {
    return finite(m[0]) && finite(m[1]) && finite(m[2]) && finite(m[3]);
}

/// What a loaded scene promises: finite geometry, transforms, materials and lights; indices in range.
std::string checkScene(const loom::Scene& s) {
    for (size_t i = 0; i < s.meshes.size(); ++i) {
        const loom::Mesh& m = s.meshes[i];
        for (const auto& p : m.positions)
            if (!finite(p)) return "meshes[" + std::to_string(i) + "] has a non-finite position";
        for (const auto& n : m.normals)
            if (!finite(n)) return "meshes[" + std::to_string(i) + "] has a non-finite normal";
        for (const auto& t : m.tangents)
            if (!finite(t)) return "meshes[" + std::to_string(i) + "] has a non-finite tangent";
        for (const auto& uv : m.uvs)
            if (!finite(uv)) return "meshes[" + std::to_string(i) + "] has a non-finite uv";
        for (uint32_t index : m.indices)
            if (index >= m.positions.size()) return "meshes[" + std::to_string(i) + "] has an index out of range";
    }
    for (const auto& inst : s.instances)
        if (!finite(inst.world) || !finite(inst.prevWorld)) return "an instance has a non-finite transform";
    for (const auto& mat : s.materials)
        if (!finite(mat.baseColorFactor) || !finite(mat.emissiveFactor) || !std::isfinite(mat.metallicFactor) ||
            !std::isfinite(mat.roughnessFactor) || !std::isfinite(mat.ior) || !std::isfinite(mat.alphaCutoff))
            return "material '" + mat.name + "' has a non-finite factor";
    for (const auto& l : s.lights)
        if (!finite(l.color) || !std::isfinite(l.intensity) || !finite(l.position) || !finite(l.direction))
            return "a light has a non-finite value";
    return {};
}

std::string checkEnvironment(const loom::Scene& s) {
    for (const auto& t : s.environment.texels)
        if (!finite(t) || t.x < 0.f || t.y < 0.f || t.z < 0.f) return "the environment has a non-finite texel";
    return {};
}

/// Reads `path` as its extension says; returns "" when the contract held, else what broke it.
std::string readAndCheck(const fs::path& path, const std::string& ext, bool& rejected) {
    rejected = false;
    try {
        if (ext == ".gltf" || ext == ".glb") return checkScene(*loom::Scene::load(path));
        if (ext == ".exr" || ext == ".hdr") {
            loom::Scene scene;
            scene.loadEnvironmentMap(path);
            if (ext == ".exr") {
                loom::readImage(path);  // the montage's reading: uint and 8-bit channels too
                // ImageSequence's and bench's reading: every layer of a multilayer file.
                loom::ExrFile file(path);
                for (const std::string& layer : file.layers()) {
                    bool uint = false;
                    for (const std::string& c : file.layerChannels(layer))
                        uint = uint || (!c.empty() && file.findChannel(c)->type == loom::ExrSampleType::Uint);
                    if (!uint) file.readRgba(layer);
                }
            }
            return checkEnvironment(scene);
        }
        loom::readImage(path);
        return {};
    } catch (const loom::Error& e) {
        rejected = true;
        if (e.kind() != loom::ErrorKind::BadInput) return std::string("a runtime error for bad input: ") + e.what();
        if (std::string(e.what()).empty()) return "an error without a message";
        return {};
    } catch (const std::exception& e) {
        return std::string("an exception that is not a loom::Error: ") + e.what();
    }
}

const char* gCurrent = nullptr;
long gIteration = 0;

void onAlarm(int) {
    char msg[512];
    const int n = std::snprintf(msg, sizeof msg, "FAILED iteration %ld: no return within the timeout; input: %s\n",
                                gIteration, gCurrent ? gCurrent : "?");
    if (n > 0) (void)!::write(2, msg, size_t(n));
    _exit(3);
}

}  // namespace

int main(int argc, char** argv) {
    fs::path source = ".", work, crashers;
    unsigned seedValue = 1;
    long iterations = 1000;
    unsigned timeout = 30;
    std::string only;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string a = argv[i], v = argv[i + 1];
        if (a == "--source")
            source = v;
        else if (a == "--seed")
            seedValue = unsigned(std::stoul(v));
        else if (a == "--iterations")
            iterations = std::stol(v);
        else if (a == "--work")
            work = v;
        else if (a == "--crashers")
            crashers = v;
        else if (a == "--timeout")
            timeout = unsigned(std::stoul(v));
        else if (a == "--only")
            only = v;
        else {
            std::fprintf(stderr, "unknown option %s\n", a.c_str());
            return 2;
        }
    }
    spdlog::set_level(spdlog::level::off);  // the loaders' warnings, thousands of them
    std::mt19937 rng(seedValue);

    std::vector<Seed> seeds;
    std::vector<std::pair<std::string, Json>> uriScenes;  // scenes with data-URI images: the images are mutated
    for (const auto& entry : fs::directory_iterator(source / "data" / "scenes")) {
        if (entry.path().extension() != ".gltf") continue;
        const std::string text = readAll(entry.path()), stem = entry.path().stem().string();
        seeds.push_back(Seed{stem + ".gltf", ".gltf", text, {}, {}});
        seeds.push_back(makeGlb(stem, text));
        Json doc = Json::parse(text);
        if (doc.contains("images") && !doc["images"].empty()) uriScenes.emplace_back(stem, std::move(doc));
    }
    // A multilayer EXR as Blender writes it (ViewLayer.Combined.R, ViewLayer.Depth.Z, ...).
    seeds.push_back(Seed{"blender_multilayer.exr",
                         ".exr",
                         readAll(source / "data" / "sequences" / "blender_cornell" / "noisy_0001.exr"),
                         {},
                         {}});
    std::sort(seeds.begin(), seeds.end(), [](const Seed& a, const Seed& b) { return a.name < b.name; });
    std::sort(uriScenes.begin(), uriScenes.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    const Imf::Compression compressions[] = {Imf::NO_COMPRESSION,  Imf::RLE_COMPRESSION,  Imf::ZIPS_COMPRESSION,
                                             Imf::ZIP_COMPRESSION, Imf::PIZ_COMPRESSION,  Imf::PXR24_COMPRESSION,
                                             Imf::B44_COMPRESSION, Imf::B44A_COMPRESSION, Imf::DWAA_COMPRESSION,
                                             Imf::DWAB_COMPRESSION};
    for (Imf::Compression c : compressions) {
        const std::string n = "c" + std::to_string(int(c));
        seeds.push_back(makeExr("rgba-float-" + n, c, Imf::FLOAT, "RGBA", 0));
        seeds.push_back(makeExr("rgb-half-" + n, c, Imf::HALF, "BGR", 0));
    }
    seeds.push_back(makeExr("rgba-uint", Imf::ZIP_COMPRESSION, Imf::UINT, "RGBA", 0));
    seeds.push_back(makeExr("y-half", Imf::NO_COMPRESSION, Imf::HALF, "Y", 0));
    seeds.push_back(makeExr("tiled-float", Imf::NO_COMPRESSION, Imf::FLOAT, "RGB", 1));
    seeds.push_back(makeExr("tiled-mip-half", Imf::ZIP_COMPRESSION, Imf::HALF, "RGBA", 2));
    seeds.push_back(makeHdr("rle", true));
    seeds.push_back(makeHdr("flat", false));
    seeds.push_back(makeStbImage("rgba", false, 4));
    seeds.push_back(makeStbImage("grey", false, 1));
    seeds.push_back(makeStbImage("rgb", true, 3));
    seeds.push_back(makeStbImage("grey", true, 1));
    std::vector<Seed> uriImages;  // the images written into the data-URI scenes
    for (const Seed& s : seeds)
        if (s.ext == ".png" || s.ext == ".jpg") uriImages.push_back(s);
    if (!only.empty()) {
        std::vector<Seed> kept;
        for (Seed& s : seeds)
            if (s.ext == "." + only) kept.push_back(std::move(s));
        seeds = std::move(kept);
        if (only != "uri") uriScenes.clear();
    }
    if (seeds.empty() && uriScenes.empty()) {
        std::fprintf(stderr, "no seeds (is --source the source tree?)\n");
        return 2;
    }

    if (work.empty()) {  // a file a read: memory-backed /dev/shm is several times faster than a disk's /tmp
        const fs::path shm = "/dev/shm";
        work = (::access(shm.c_str(), W_OK) == 0 ? shm : fs::temp_directory_path()) /
               ("loom_fuzz_" + std::to_string(::getpid()));
    }
    fs::create_directories(work);
    if (!crashers.empty()) fs::create_directories(crashers);
    std::fprintf(stderr, "%zu seeds; inputs are written to %s/current.* (after a crash: the crashing input)\n",
                 seeds.size() + uriScenes.size(), work.c_str());
    signal(SIGALRM, onAlarm);

    std::map<std::string, std::array<long, 3>> counts;  // per extension: accepted, rejected, failed
    long failures = 0;
    double slowest = 0.0;
    const auto start = std::chrono::steady_clock::now();
    for (gIteration = 0; gIteration < iterations; ++gIteration) {
        std::string bytes, ext, label;
        const size_t choice = pick(rng, seeds.size() + (uriScenes.empty() ? 0 : seeds.size() / 6 + 1));
        if (choice < seeds.size()) {
            const Seed& seed = seeds[choice];
            bytes = seed.bytes;
            mutate(bytes, seed, rng);
            ext = seed.ext;
            label = seed.name;
        } else {  // a scene whose image data URI holds damaged PNG or JPEG bytes
            auto& [name, doc] = uriScenes[pick(rng, uriScenes.size())];
            Json d = doc;
            const Seed& image = uriImages[pick(rng, uriImages.size())];
            std::string img = image.bytes;
            mutate(img, image, rng);
            Json& target = d["images"][pick(rng, d["images"].size())];
            target["uri"] = std::string(image.ext == ".png" ? "data:image/png" : "data:image/jpeg") + ";base64," +
                            base64Encode(img);
            bytes = d.dump();
            ext = ".gltf";
            label = name + " with a damaged " + image.name + image.ext + " image";
        }
        const fs::path path = work / ("current" + ext);
        static std::string current;
        current = path.string();
        gCurrent = current.c_str();
        std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
        const auto t0 = std::chrono::steady_clock::now();
        alarm(timeout);
        bool rejected = false;
        const std::string why = readAndCheck(path, ext, rejected);
        alarm(0);
        slowest = std::max(slowest, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        auto& c = counts[ext];
        if (why.empty()) {
            ++c[rejected ? 1 : 0];
            continue;
        }
        ++c[2];
        ++failures;
        std::printf("FAILED iteration %ld (%s): %s\n", gIteration, label.c_str(), why.c_str());
        if (!crashers.empty())
            fs::copy_file(path, crashers / ("finding-" + std::to_string(gIteration) + ext),
                          fs::copy_options::overwrite_existing);
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    for (const auto& [ext, c] : counts)
        std::printf("%-6s %8ld read, %8ld rejected, %ld failed\n", ext.c_str(), c[0], c[1], c[2]);
    std::printf("%ld iterations in %.1f s (slowest %.3f s), %ld failed (seed %u)\n", iterations, seconds, slowest,
                failures, seedValue);
    std::error_code ec;
    fs::remove_all(work, ec);
    return failures ? 1 : 0;
}
