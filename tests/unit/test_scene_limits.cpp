// Scene loading limits and the messages of bad scene input: texture size and budget (checked from the image
// header, before decoding), textures that cannot be read, negative indices, node cycles, GLB versions, --env
// folders, PNG encoding of huge images, and instances scaled beyond float range. Every input is built here, small.
#include <gtest/gtest.h>
#include <stb/stb_image_write.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "../apps/loom/SceneSetup.h"
#include "GltfBuilder.h"
#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/ImageIO.h"
#include "loom/RayScene.h"
#include "loom/Scene.h"

using namespace loom;
using namespace loom::test;
namespace fs = std::filesystem;

namespace {

void appendBytes(void* ctx, void* data, int size) {
    auto* out = static_cast<std::vector<uint8_t>*>(ctx);
    out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
}

/// A w x h RGBA PNG whose texels depend on `seed` (so two images differ).
std::vector<uint8_t> png(int w, int h, uint8_t seed) {
    std::vector<uint8_t> rgba(size_t(w) * size_t(h) * 4);
    for (size_t i = 0; i < rgba.size(); ++i) rgba[i] = uint8_t(i * 7 + seed);
    std::vector<uint8_t> out;
    EXPECT_NE(stbi_write_png_to_func(appendBytes, &out, w, h, 4, rgba.data(), w * 4), 0);
    return out;
}

/// A PNG that is only a signature and an IHDR claiming w x h: what a header check sees of a huge image.
std::vector<uint8_t> pngHeaderOnly(uint32_t w, uint32_t h) {
    std::vector<uint8_t> out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n', 0, 0, 0, 13, 'I', 'H', 'D', 'R'};
    for (uint32_t v : {w, h})
        for (int k = 3; k >= 0; --k) out.push_back(uint8_t(v >> (8 * k)));
    out.insert(out.end(), {8, 6, 0, 0, 0, 0, 0, 0, 0});  // 8-bit RGBA, then a CRC stb does not check
    return out;
}

class SceneLimits : public TempDirTest {
protected:
    fs::path put(const std::string& name, const std::vector<uint8_t>& bytes) {
        write(mDir / name, std::string(bytes.begin(), bytes.end()));
        return mDir / name;
    }
    fs::path put(const std::string& name, const Gltf& g) { return put(name, toBytes(g.text())); }
    static std::vector<uint8_t> toBytes(const std::string& s) { return {s.begin(), s.end()}; }
    /// A triangle whose material 'Tex' has one base colour texture per image (`images`: glTF image objects).
    static Gltf texturedTriangle(const json& images) {
        Gltf g = triangleScene();
        g.j["images"] = images;
        json textures = json::array(), material = {{"name", "Tex"}};
        for (size_t i = 0; i < images.size(); ++i) textures.push_back({{"source", i}});
        g.j["textures"] = textures;
        material["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
        if (images.size() > 1) material["emissiveTexture"] = {{"index", 1}};
        g.j["materials"] = json::array({material});
        g.j["meshes"][0]["primitives"][0]["material"] = 0;
        return g;
    }
    /// Loads and expects a BadInput error naming the file; returns its message.
    static std::string loadError(const fs::path& file, const SceneLoadOptions& options = {}) {
        const Error e = expectError([&] { Scene::load(file, options); });
        EXPECT_EQ(e.kind(), ErrorKind::BadInput) << e.what();
        EXPECT_EQ(e.exitCode(), 2);
        EXPECT_EQ(e.info().file, file.string());
        return e.what();
    }
};

#define EXPECT_HAS(text, part) EXPECT_NE(std::string(text).find(part), std::string::npos) << (text)

// ---------------------------------------------------------------------------
// Texture size and budget

TEST_F(SceneLimits, TextureBeyondTheSideLimitIsRefusedFromItsHeader) {
    // Only the header exists: an error about the size proves nothing was decoded (the data would be truncated).
    put("huge.png", pngHeaderOnly(kMaxTextureSide + 1, 4));
    const fs::path file = put("scene.gltf", texturedTriangle(json::array({{{"uri", "huge.png"}}})));
    const std::string msg = loadError(file);
    EXPECT_HAS(msg, "images[0] (file 'huge.png')");
    EXPECT_HAS(msg, std::to_string(kMaxTextureSide + 1) + "x4");
    EXPECT_HAS(msg, "at most " + std::to_string(kMaxTextureSide) + " pixels a side");
}

TEST_F(SceneLimits, TextureBeyondTheTexelLimitIsRefused) {
    Gltf g = texturedTriangle(json::array({{{"uri", "tex.png"}}}));
    put("tex.png", png(8, 8, 1));
    const fs::path file = put("scene.gltf", g);
    SceneLoadOptions o;
    o.maxTextureTexels = 63;  // one texel short of 8 x 8
    EXPECT_HAS(loadError(file, o), "8x8");
    o.maxTextureTexels = 64;
    EXPECT_EQ(Scene::load(file, o)->images.size(), 1u);
}

TEST_F(SceneLimits, TexturesBeyondTheBudgetAreRefusedNamingTheImage) {
    put("a.png", png(8, 8, 1));
    put("b.png", png(8, 8, 2));
    const fs::path file = put("scene.gltf", texturedTriangle(json::array({{{"uri", "a.png"}}, {{"uri", "b.png"}}})));
    SceneLoadOptions o;
    o.textureBudgetBytes = 2 * 8 * 8 * 4 - 1;
    const std::string msg = loadError(file, o);
    EXPECT_HAS(msg, "images[1] (file 'b.png')");
    EXPECT_HAS(msg, "texture budget");
    o.textureBudgetBytes = 2 * 8 * 8 * 4;  // exactly both
    EXPECT_EQ(Scene::load(file, o)->images.size(), 2u);
}

TEST_F(SceneLimits, OneFileNamedByTwoImagesIsDecodedOnceAndCountedOnce) {
    put("a.png", png(8, 8, 1));
    const fs::path file = put("scene.gltf", texturedTriangle(json::array({{{"uri", "a.png"}}, {{"uri", "a.png"}}})));
    SceneLoadOptions o;
    o.textureBudgetBytes = 8 * 8 * 4;
    auto s = Scene::load(file, o);
    ASSERT_EQ(s->images.size(), 1u);
    EXPECT_EQ(s->materials[0].baseColorTexture.image, 0);
    EXPECT_EQ(s->materials[0].emissiveTexture.image, 0);
}

// ---------------------------------------------------------------------------
// Textures that cannot be read

TEST_F(SceneLimits, TruncatedJpegSaysSo) {
    std::vector<uint8_t> rgb(16 * 16 * 3, 128);
    std::vector<uint8_t> jpg;
    ASSERT_NE(stbi_write_jpg_to_func(appendBytes, &jpg, 16, 16, 3, rgb.data(), 90), 0);
    jpg.resize(jpg.size() / 3);
    put("cut.jpg", jpg);
    const std::string msg = loadError(put("scene.gltf", texturedTriangle(json::array({{{"uri", "cut.jpg"}}}))));
    EXPECT_HAS(msg, "truncated or corrupt JPEG");
    EXPECT_HAS(msg, "cut.jpg");
    EXPECT_EQ(msg.find("png"), std::string::npos) << msg;
}

TEST_F(SceneLimits, TruncatedPngSaysSoAfterItsHeaderPassed) {
    std::vector<uint8_t> bytes = png(16, 16, 3);
    bytes.resize(bytes.size() / 2);  // the header is whole, the pixel data is not
    put("cut.png", bytes);
    const std::string msg = loadError(put("scene.gltf", texturedTriangle(json::array({{{"uri", "cut.png"}}}))));
    EXPECT_HAS(msg, "truncated or corrupt PNG");
    EXPECT_HAS(msg, "images[0] (file 'cut.png')");
}

TEST_F(SceneLimits, EmptyTextureFileSaysEmpty) {
    put("empty.png", std::vector<uint8_t>{});
    const std::string msg = loadError(put("scene.gltf", texturedTriangle(json::array({{{"uri", "empty.png"}}}))));
    EXPECT_HAS(msg, "empty.png' is an empty file");
}

TEST_F(SceneLimits, TextureFileThatIsAFolderSaysSo) {
    fs::create_directories(mDir / "folder.png");
    const std::string msg = loadError(put("scene.gltf", texturedTriangle(json::array({{{"uri", "folder.png"}}}))));
    EXPECT_HAS(msg, "folder.png' is a folder");
}

// ---------------------------------------------------------------------------
// Structure

TEST_F(SceneLimits, NodeCycleListedAsRootNamesTheCycle) {
    Gltf g = triangleScene();
    g.j["nodes"][0]["children"] = {1};
    g.node({{"name", "Back"}, {"children", {0}}});
    const std::string msg = loadError(put("scene.gltf", g));
    EXPECT_HAS(msg, "cycle");
    EXPECT_HAS(msg, "'TriNode'");
    EXPECT_HAS(msg, "'Back'");
    EXPECT_EQ(msg.find("no triangles"), std::string::npos) << msg;
}

TEST_F(SceneLimits, NegativeAccessorByteOffsetIsAnError) {
    Gltf g = triangleScene();
    g.j["accessors"][0]["byteOffset"] = -4;
    const std::string msg = loadError(put("scene.gltf", g));
    EXPECT_HAS(msg, "accessors[0]/byteOffset");
    EXPECT_HAS(msg, "-4");
}

TEST_F(SceneLimits, NegativeByteOffsetWrittenAsAFloatIsAnError) {
    Gltf g = triangleScene();
    std::string text = g.text();
    const std::string view = "\"byteOffset\": 0";
    ASSERT_NE(text.find(view), std::string::npos);
    text.replace(text.find(view), view.size(), "\"byteOffset\": -4.0");
    const std::string msg = loadError(put("scene.gltf", toBytes(text)));
    EXPECT_HAS(msg, "bufferViews[0]/byteOffset");
    EXPECT_HAS(msg, "-4.0");
}

TEST_F(SceneLimits, NegativeMaterialIndexIsAnError) {
    Gltf g = triangleScene();
    g.j["meshes"][0]["primitives"][0]["material"] = -2;
    const std::string msg = loadError(put("scene.gltf", g));
    EXPECT_HAS(msg, "meshes[0]/primitives[0]/material");
    EXPECT_HAS(msg, "-2");
}

TEST_F(SceneLimits, NegativeNumbersInExtrasAreFree) {
    Gltf g = triangleScene();
    g.j["meshes"][0]["primitives"][0]["extras"] = {{"material", -2}, {"byteOffset", -4}};
    EXPECT_EQ(Scene::load(put("scene.gltf", g))->triangleCount(), 1u);
}

TEST_F(SceneLimits, GlbVersionOneIsRefused) {
    std::vector<uint8_t> glb = triangleScene().glb();
    EXPECT_EQ(Scene::load(put("v2.glb", glb))->triangleCount(), 1u);
    glb[4] = 1;  // the container version, little-endian
    EXPECT_HAS(loadError(put("v1.glb", glb)), "GLB container version 1");
}

// ---------------------------------------------------------------------------
// Instances scaled beyond float range

TEST_F(SceneLimits, InstanceScaledBeyondTheWorldIsAnErrorNamingTheNode) {
    // Uniform 1e30 overflows the transform's determinant; 1e20 on one axis stays finite but far beyond the range
    // rays are traced in, where positions, their derivatives and a camera framing them overflow (motion vectors
    // were NaN).
    for (const json& scale : {json{1e30, 1e30, 1e30}, json{1e20, 1, 1}, json{1e19, 1e19, 1e-19}}) {
        SCOPED_TRACE(scale.dump());
        Gltf g = triangleScene({{"scale", scale}});
        g.node({{"mesh", 0}, {"translation", {0, 0, -1}}});
        g.j["scenes"][0]["nodes"] = {0, 1};
        const std::string msg = loadError(put("scene.gltf", g));
        EXPECT_HAS(msg, "nodes[0] 'TriNode'");
        EXPECT_HAS(msg, "world coordinates");
    }
    // A parent's scale counts too.
    Gltf g = triangleScene();
    g.node({{"name", "Big"}, {"scale", {1e30, 1e30, 1e30}}, {"children", {0}}});
    g.j["scenes"][0]["nodes"] = {1};
    EXPECT_HAS(loadError(put("parent.gltf", g)), "nodes[0] 'TriNode'");
}

TEST_F(SceneLimits, LargeButTraceableScalesAndZeroScalesLoadWithFiniteGeometry) {
    for (const json& scale : {json{1e7, 1e7, 1e7}, json{0, 1e7, 1}, json{1e-30, 1e-30, 1e-30}}) {
        SCOPED_TRACE(scale.dump());
        Gltf g = triangleScene({{"scale", scale}});
        g.node({{"mesh", 0}, {"translation", {0, 0, -1}}});
        g.j["scenes"][0]["nodes"] = {0, 1};
        auto s = Scene::load(put("scene.gltf", g));
        const SceneView& v = s->view();
        for (uint32_t i = 0; i < v.instanceCount; ++i) {
            const InstanceView& inst = v.instances[i];
            const MeshView& mesh = v.meshes[inst.mesh];
            for (uint32_t k = 0; k < 3 * mesh.triangleCount; ++k) {
                const uint32_t vi = mesh.indices[k];
                const glm::vec4 p = inst.world * glm::vec4(mesh.positions[vi], 1.f);
                const glm::vec3 n = inst.normalMatrix * mesh.normals[vi];
                for (int c = 0; c < 3; ++c) {
                    EXPECT_TRUE(std::isfinite(p[c])) << i;
                    EXPECT_TRUE(std::isfinite(n[c])) << i;
                }
                if (s->instances[i].visible()) {
                    EXPECT_GT(glm::length(n), 0.f) << i;
                }
            }
        }
        EXPECT_TRUE(std::isfinite(s->bounds().extent().x));
    }
}

// ---------------------------------------------------------------------------
// Image files outside scenes

TEST_F(SceneLimits, EnvironmentFolderSaysItIsAFolder) {
    const fs::path scene = put("scene.gltf", triangleScene());
    fs::create_directories(mDir / "sky.hdr");
    cli::SceneOptions o;
    o.scene = scene.string();
    o.env = (mDir / "sky.hdr").string();
    const Error e = expectError([&] { cli::loadScene(o); });
    EXPECT_EQ(e.exitCode(), 2);
    EXPECT_HAS(e.what(), "is a folder");
    EXPECT_HAS(e.what(), "--env");
}

TEST_F(SceneLimits, PngTooLargeToEncodeNamesFileAndSize) {
    // A view of a few bytes with a width no PNG row can hold: refused before a byte is read.
    std::vector<std::byte> bytes(64);
    const Texture huge = Texture::wrap(bytes.data(), 1u << 30, 1, Format::RGBA8Unorm);
    const fs::path out = mDir / "huge.png";
    const Error e = expectError([&] { writeImage(out, huge); });
    EXPECT_HAS(e.what(), out.string());
    EXPECT_HAS(e.what(), "1073741824x1");
    EXPECT_FALSE(fs::exists(out));
}

TEST(ImageDecodeFailure, NamesTheFormatTheBytesClaim) {
    const unsigned char jpeg[] = {0xFF, 0xD8, 0xFF, 0xE0, 0x00};
    const unsigned char pngSig[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n', 0};
    const unsigned char gif[] = {'G', 'I', 'F', '8', '9', 'a'};
    EXPECT_HAS(describeImageDecodeFailure(jpeg, sizeof jpeg, "bad png sig"), "truncated or corrupt JPEG");
    EXPECT_HAS(describeImageDecodeFailure(pngSig, sizeof pngSig, nullptr), "truncated or corrupt PNG");
    EXPECT_HAS(describeImageDecodeFailure(gif, sizeof gif, nullptr), "starts with bytes 47 49 46 38");
    EXPECT_EQ(describeImageDecodeFailure(gif, 0, nullptr), "an empty file");
}

}  // namespace
