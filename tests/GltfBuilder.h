#pragma once
// Tiny glTF documents built in code, for the scene loader's tests: one binary buffer, written as a .gltf with a
// base64 data URI or as a .glb.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace loom::test {

using json = nlohmann::json;

inline constexpr int kByte = 5121, kShort = 5123, kUInt = 5125, kFloat = 5126;

inline std::string base64(const std::vector<uint8_t>& data) {
    static const char* abc = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (size_t i = 0; i < data.size(); i += 3) {
        uint32_t v = uint32_t(data[i]) << 16;
        if (i + 1 < data.size()) v |= uint32_t(data[i + 1]) << 8;
        if (i + 2 < data.size()) v |= data[i + 2];
        out += abc[(v >> 18) & 63];
        out += abc[(v >> 12) & 63];
        out += i + 1 < data.size() ? abc[(v >> 6) & 63] : '=';
        out += i + 2 < data.size() ? abc[v & 63] : '=';
    }
    return out;
}

/// Builds a glTF document with one binary buffer, written either as a .gltf
/// with a base64 data URI or as a .glb.
struct Gltf {
    json j = {{"asset", {{"version", "2.0"}}}};
    std::vector<uint8_t> bin;

    int view(const void* data, size_t bytes) {
        while (bin.size() % 4) bin.push_back(0);
        const size_t offset = bin.size();
        bin.insert(bin.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + bytes);
        j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}});
        return int(j["bufferViews"].size() - 1);
    }
    int accessor(int bufferView, int componentType, size_t count, const std::string& type) {
        j["accessors"].push_back(
            {{"bufferView", bufferView}, {"componentType", componentType}, {"count", count}, {"type", type}});
        return int(j["accessors"].size() - 1);
    }
    int floats(const std::vector<float>& v, const std::string& type) {
        const size_t comps = type == "SCALAR" ? 1 : type == "VEC2" ? 2 : type == "VEC3" ? 3 : 4;
        return accessor(view(v.data(), v.size() * 4), kFloat, v.size() / comps, type);
    }
    template <class T>
    int indices(const std::vector<T>& v) {
        const int type = sizeof(T) == 1 ? kByte : sizeof(T) == 2 ? kShort : kUInt;
        return accessor(view(v.data(), v.size() * sizeof(T)), type, v.size(), "SCALAR");
    }
    /// A mesh with one primitive; attributes maps names to accessors.
    int mesh(const std::string& name, json attributes, int indexAccessor = -1, int material = -1) {
        json prim = {{"attributes", attributes}};
        if (indexAccessor >= 0) prim["indices"] = indexAccessor;
        if (material >= 0) prim["material"] = material;
        j["meshes"].push_back({{"name", name}, {"primitives", json::array({prim})}});
        return int(j["meshes"].size() - 1);
    }
    int node(json n) {
        j["nodes"].push_back(std::move(n));
        return int(j["nodes"].size() - 1);
    }
    void scene(std::vector<int> roots) {
        j["scenes"] = json::array({{{"nodes", roots}}});
        j["scene"] = 0;
    }
    json document(int64_t byteLengthDelta = 0) const {
        json d = j;
        if (!bin.empty())
            d["buffers"] = json::array({{{"byteLength", int64_t(bin.size()) + byteLengthDelta},
                                         {"uri", "data:application/octet-stream;base64," + base64(bin)}}});
        return d;
    }
    std::string text(int64_t byteLengthDelta = 0) const { return document(byteLengthDelta).dump(1); }
    std::vector<uint8_t> glb() const {
        json d = j;
        d["buffers"] = json::array({{{"byteLength", bin.size()}}});
        std::string js = d.dump();
        while (js.size() % 4) js += ' ';  // the JSON chunk is padded with spaces
        std::vector<uint8_t> b = bin;
        while (b.size() % 4) b.push_back(0);  // the BIN chunk with zeros
        std::vector<uint8_t> out;
        auto u32 = [&](uint32_t v) {
            for (int k = 0; k < 4; ++k) out.push_back(uint8_t(v >> (8 * k)));
        };
        u32(0x46546C67u);  // "glTF"
        u32(2);
        u32(uint32_t(12 + 8 + js.size() + 8 + b.size()));
        u32(uint32_t(js.size()));
        u32(0x4E4F534Au);  // "JSON"
        out.insert(out.end(), js.begin(), js.end());
        u32(uint32_t(b.size()));
        u32(0x004E4942u);  // "BIN\0"
        out.insert(out.end(), b.begin(), b.end());
        return out;
    }
};

/// One triangle (0,0,0), (1,0,0), (0,1,0): counter-clockwise seen from +Z.
inline Gltf triangleScene(json nodeExtra = json::object()) {
    Gltf g;
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    const int mesh = g.mesh("Tri", {{"POSITION", pos}});
    json n = {{"name", "TriNode"}, {"mesh", mesh}};
    n.update(nodeExtra);
    g.scene({g.node(n)});
    return g;
}

}  // namespace loom::test
