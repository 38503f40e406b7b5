#pragma once
// Helpers shared by the test files.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <glm/vec2.hpp>
#include <glm/vec4.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/Graph.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/RenderPass.h"
#include "loom/Scene.h"

namespace loom::test {

/// Runs `fn`, expects a loom::Error, and returns it (a default-constructed one when nothing was thrown).
template <class Fn>
Error expectError(Fn&& fn) {
    try {
        fn();
    } catch (const Error& e) {
        return e;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected loom::Error, got another exception: " << e.what();
        return Error({});
    }
    ADD_FAILURE() << "expected loom::Error, nothing was thrown";
    return Error({});
}

/// One registry over the build's plugin folder, shared by a test binary (a type registers once per registry).
inline PluginRegistry& pluginRegistry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

/// The graph of JSON `g` with the build's plugins, on `scene` (none: nullptr), compiled at w x h (other options
/// from `base`).
inline std::unique_ptr<RenderGraph> compiledGraph(const nlohmann::json& g, const std::shared_ptr<Scene>& scene,
                                                  uint32_t w, uint32_t h, CompileOptions base = {}) {
    auto graph = std::make_unique<RenderGraph>(parseGraph(g.dump()), pluginRegistry());
    if (scene) graph->setScene(scene);
    base.width = w;
    base.height = h;
    graph->compile(base);
    return graph;
}

/// A test pass that emits "color" = fn(frame index, x, y) (zero without fn): any frame-dependent input a test
/// needs. Registered as "FunctionSource" by registryWithFunctionSource().
class FunctionSource final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override { r.output("color", Format::RGBA32F); }
    void execute(PassContext& ctx) override {
        auto dst = ctx.output("color")->view<glm::vec4>();
        for (uint32_t y = 0; y < dst.height; ++y)
            for (uint32_t x = 0; x < dst.width; ++x) dst.at(x, y) = fn ? fn(ctx.frameIndex(), x, y) : glm::vec4(0.f);
    }
    std::function<glm::vec4(uint64_t frame, uint32_t x, uint32_t y)> fn;
};

/// A test pass that emits "color" and "mvec" (uvPrev - uvCur) from functions of (frame, x, y) (zero without them):
/// TAA's inputs. Registered as "MotionSource" by registryWithFunctionSource().
class MotionSource final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output("color", Format::RGBA32F);
        r.output("mvec", Format::RG32F);
    }
    void execute(PassContext& ctx) override {
        auto c = ctx.output("color")->view<glm::vec4>();
        auto m = ctx.output("mvec")->view<glm::vec2>();
        for (uint32_t y = 0; y < c.height; ++y)
            for (uint32_t x = 0; x < c.width; ++x) {
                c.at(x, y) = color ? color(ctx.frameIndex(), x, y) : glm::vec4(0.f);
                m.at(x, y) = motion ? motion(ctx.frameIndex(), x, y) : glm::vec2(0.f);
            }
    }
    std::function<glm::vec4(uint64_t frame, uint32_t x, uint32_t y)> color;
    std::function<glm::vec2(uint64_t frame, uint32_t x, uint32_t y)> motion;
};

/// A registry over the build's plugin folder with FunctionSource and MotionSource registered (its own registry, so tests that
/// add a type do not change the shared one).
inline PluginRegistry& registryWithFunctionSource() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    static const bool registered = [] {
        r.registerPass("FunctionSource", "frame-dependent test input",
                       [] { return std::make_unique<FunctionSource>(); });
        r.registerPass("MotionSource", "frame-dependent colour and motion", [] { return std::make_unique<MotionSource>(); });
        return true;
    }();
    (void)registered;
    return r;
}

/// The fields a pass of `type` declares at 32x32 after its parameters are set to `params`: reflection must not
/// depend on parameter values, so tests compare this against the defaults' fields.
inline std::vector<FieldDesc> reflectedFields(PluginRegistry& registry, const std::string& type,
                                              const nlohmann::json& params) {
    std::unique_ptr<RenderPass> pass = registry.create(type);
    pass->params().setAll(params, "test");
    Reflection r;
    CompileInfo info;
    info.frameWidth = info.frameHeight = 32;
    pass->reflect(r, info);
    return r.fields();
}

/// Whether two textures hold the same texels, bit for bit (row padding aside).
inline bool sameBits(const Texture& a, const Texture& b) {
    if (a.width() != b.width() || a.height() != b.height() || a.format() != b.format()) return false;
    const size_t rowBytes = size_t(a.width()) * formatInfo(a.format()).bytesPerPixel;
    for (uint32_t y = 0; y < a.height(); ++y)
        if (std::memcmp(a.row(y), b.row(y), rowBytes) != 0) return false;
    return true;
}

/// Expects each field of `a` named "<prefix>..." (the graph's transfer copies aside) to hold the same bits in `b`,
/// the same graph run elsewhere (another device, thread count); returns how many fields it compared.
inline size_t expectSameFields(const RenderGraph& a, const RenderGraph& b, const std::string& prefix,
                               const std::string& what) {
    size_t fields = 0;
    for (const ResourceInfo& r : a.plan().resources) {
        if (r.name.rfind(prefix, 0) != 0 || r.name.find(' ') != std::string::npos) continue;
        const Texture* x = a.fieldTexture(r.name);
        const Texture* y = b.fieldTexture(r.name);
        EXPECT_TRUE(x && y) << r.name << " " << what;
        if (x && y) EXPECT_TRUE(sameBits(*x, *y)) << r.name << " " << what;
        ++fields;
    }
    return fields;
}

/// A deterministic pseudo-random value in [0, 1) from three integers (e.g. frame, x, y).
inline float hash01(uint64_t a, uint32_t b, uint32_t c) {
    uint64_t v = a * 0x9E3779B97F4A7C15ull ^ (uint64_t(b) << 32 | c);
    v ^= v >> 33;
    v *= 0xFF51AFD7ED558CCDull;
    v ^= v >> 33;
    v *= 0xC4CEB9FE1A85EC53ull;
    v ^= v >> 33;
    return float(v >> 40) / float(1u << 24);
}

/// Path of a scene shipped in data/scenes.
inline std::string dataScene(const std::string& name) {
    return std::string(LOOM_TEST_SOURCE_DIR) + "/data/scenes/" + name;
}

/// Exit code and captured output of one run of the loom binary.
struct CliResult {
    int code = -1;       ///< exit code (-1 when killed by a signal)
    std::string output;  ///< stdout and stderr
};

/// `s` quoted for /bin/sh.
inline std::string shellQuoted(const std::string& s) {
    std::string out = "'";
    for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

#ifdef LOOM_TEST_LOOM_EXE
/// Runs `loom ARGS` in `dir`, capturing stdout and stderr.
inline CliResult runLoom(const std::filesystem::path& dir, const std::string& args) {
    const std::string cmd =
        "cd " + shellQuoted(dir.string()) + " && " + shellQuoted(LOOM_TEST_LOOM_EXE) + " " + args + " 2>&1 </dev/null";
    CliResult r;
    FILE* pipe = ::popen(cmd.c_str(), "r");
    if (!pipe) {
        ADD_FAILURE() << "popen failed: " << cmd;
        return r;
    }
    char buffer[4096];
    size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) r.output.append(buffer, n);
    const int status = ::pclose(pipe);
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}
#endif

/// Writes dir/NAME.gltf and its buffer dir/NAME.bin: one node drawing one mesh of triangles (positions and uvs, xyz
/// and uv per vertex; three indices per triangle) with `material` (a glTF material object, or null for none).
/// `images` are image files (uris relative to dir) that become textures 0, 1, ... for the material to name.
/// Returns the .gltf's path.
inline std::filesystem::path writeTriangleGltf(const std::filesystem::path& dir, const std::string& name,
                                               const std::vector<float>& positions, const std::vector<float>& uvs,
                                               const std::vector<uint32_t>& indices, const nlohmann::json& material,
                                               const std::vector<std::string>& images = {}) {
    using json = nlohmann::json;
    std::string bin;
    json views = json::array(), accessors = json::array();
    auto add = [&](const void* data, size_t bytes, int componentType, size_t count, const char* type) {
        views.push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
        bin.append(static_cast<const char*>(data), bytes);
        accessors.push_back(
            {{"bufferView", views.size() - 1}, {"componentType", componentType}, {"count", count}, {"type", type}});
        return int(accessors.size() - 1);
    };
    const size_t vertices = positions.size() / 3;
    json attributes = {{"POSITION", add(positions.data(), positions.size() * 4, 5126, vertices, "VEC3")}};
    if (!uvs.empty()) attributes["TEXCOORD_0"] = add(uvs.data(), uvs.size() * 4, 5126, vertices, "VEC2");
    json primitive = {{"attributes", attributes},
                      {"indices", add(indices.data(), indices.size() * 4, 5125, indices.size(), "SCALAR")}};
    json doc = {{"asset", {{"version", "2.0"}}},
                {"buffers", {{{"uri", name + ".bin"}, {"byteLength", bin.size()}}}},
                {"bufferViews", views},
                {"accessors", accessors},
                {"meshes", {{{"name", name}, {"primitives", {primitive}}}}},
                {"nodes", {{{"name", name}, {"mesh", 0}}}},
                {"scenes", {{{"nodes", {0}}}}},
                {"scene", 0}};
    if (!material.is_null()) {
        doc["materials"] = json::array({material});
        doc["meshes"][0]["primitives"][0]["material"] = 0;
    }
    for (size_t i = 0; i < images.size(); ++i) {
        doc["images"].push_back({{"uri", images[i]}});
        doc["textures"].push_back({{"source", i}});
    }
    std::ofstream(dir / (name + ".bin"), std::ios::binary).write(bin.data(), std::streamsize(bin.size()));
    const std::filesystem::path gltf = dir / (name + ".gltf");
    std::ofstream(gltf, std::ios::binary) << doc.dump(1);
    return gltf;
}

/// A fresh folder per test (named after the suite and test), removed afterwards.
class TempDirTest : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = std::filesystem::temp_directory_path() / ("loom_test_" + std::string(test->test_suite_name()) + "_" +
                                                         std::to_string(::getpid()) + "_" + test->name());
        std::filesystem::remove_all(mDir);
        std::filesystem::create_directories(mDir);
    }
    void TearDown() override {
        std::error_code ec;
        std::filesystem::remove_all(mDir, ec);
    }
    void write(const std::filesystem::path& p, const std::string& text) {
        std::ofstream out(p, std::ios::binary);
        out << text;
    }
    std::filesystem::path mDir;
};

}  // namespace loom::test
