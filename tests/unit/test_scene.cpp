// Scenes: glTF loading (tiny glTF files built in the tests), bad input,
// animation sampling, hierarchy and motion, ray tracing, camera paths,
// environment maps and the `loom scene info` command.
#include <gtest/gtest.h>
#include <stb/stb_image_write.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <tuple>
#include <vector>

#include "GltfBuilder.h"
#include "loom/Camera.h"
#include "loom/Error.h"
#include "loom/RayScene.h"
#include "loom/Scene.h"
#include "loom/SurfaceKernels.h"

using namespace loom;
namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace loom::test;

namespace {

constexpr float kPi = std::numbers::pi_v<float>;

/// A PNG made by hand (stored zlib block): 16-bit greyscale, one row.
std::vector<uint8_t> png16Grey(const std::vector<uint16_t>& row) {
    auto crc32 = [](const std::vector<uint8_t>& d, size_t from) {
        uint32_t c = 0xFFFFFFFFu;
        for (size_t i = from; i < d.size(); ++i) {
            c ^= d[i];
            for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
        }
        return c ^ 0xFFFFFFFFu;
    };
    std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
    auto be32 = [](std::vector<uint8_t>& d, uint32_t v) {
        for (int k = 3; k >= 0; --k) d.push_back(uint8_t(v >> (8 * k)));
    };
    auto chunk = [&](const char* type, const std::vector<uint8_t>& data) {
        be32(png, uint32_t(data.size()));
        std::vector<uint8_t> body(type, type + 4);
        body.insert(body.end(), data.begin(), data.end());
        png.insert(png.end(), body.begin(), body.end());
        be32(png, crc32(body, 0));
    };
    std::vector<uint8_t> ihdr;
    be32(ihdr, uint32_t(row.size()));
    be32(ihdr, 1);
    ihdr.insert(ihdr.end(), {16, 0, 0, 0, 0});  // bit depth 16, greyscale
    chunk("IHDR", ihdr);
    std::vector<uint8_t> raw = {0};  // filter: none
    for (uint16_t v : row) raw.insert(raw.end(), {uint8_t(v >> 8), uint8_t(v & 0xFF)});
    std::vector<uint8_t> z = {0x78,
                              0x01,
                              0x01,
                              uint8_t(raw.size()),
                              uint8_t(raw.size() >> 8),
                              uint8_t(~raw.size()),
                              uint8_t(~raw.size() >> 8)};
    z.insert(z.end(), raw.begin(), raw.end());
    uint32_t a = 1, b = 0;
    for (uint8_t c : raw) {
        a = (a + c) % 65521;
        b = (b + a) % 65521;
    }
    be32(z, (b << 16) | a);
    chunk("IDAT", z);
    chunk("IEND", {});
    return png;
}

void expectNear(const glm::vec3& a, const glm::vec3& b, float eps = 1e-5f) {
    EXPECT_NEAR(a.x, b.x, eps);
    EXPECT_NEAR(a.y, b.y, eps);
    EXPECT_NEAR(a.z, b.z, eps);
}
void expectNear(const glm::vec4& a, const glm::vec4& b, float eps = 1e-5f) {
    expectNear(glm::vec3(a), glm::vec3(b), eps);
    EXPECT_NEAR(a.w, b.w, eps);
}
void expectNear(const glm::mat4& a, const glm::mat4& b, float eps = 1e-5f) {
    for (int c = 0; c < 4; ++c) expectNear(a[c], b[c], eps);
}

/// A fresh folder per test, removed afterwards.
class SceneFiles : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = fs::temp_directory_path() / ("loom_test_scene_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(mDir);
        fs::create_directories(mDir);
    }
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }
    fs::path write(const std::string& name, const std::string& bytes) {
        const fs::path p = mDir / name;
        std::ofstream(p, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
        return p;
    }
    fs::path write(const std::string& name, const std::vector<uint8_t>& bytes) {
        return write(name, std::string(bytes.begin(), bytes.end()));
    }
    std::shared_ptr<Scene> load(const Gltf& g, const std::string& name = "scene.gltf") {
        return Scene::load(write(name, g.text()));
    }
    /// Loads and expects a BadInput error; returns its message.
    std::string loadError(const fs::path& p) {
        try {
            Scene::load(p);
        } catch (const Error& e) {
            EXPECT_EQ(e.kind(), ErrorKind::BadInput) << e.what();
            EXPECT_EQ(e.info().file, p.string());
            return e.what();
        }
        ADD_FAILURE() << "loading " << p << " did not fail";
        return {};
    }
    static bool hasWarning(const Scene& s, const std::string& a, const std::string& b) {
        for (const auto& w : s.warnings)
            if (w.find(a) != std::string::npos && w.find(b) != std::string::npos) return true;
        return false;
    }
    fs::path mDir;
};

// ---------------------------------------------------------------------------
// Animation sampling, against values computed by hand

TEST(AnimationSampling, LinearTranslationMidpoint) {
    AnimationSampler s;
    s.times = {1.f, 3.f};
    s.values = {glm::vec4(0, 0, 0, 0), glm::vec4(2, 4, -6, 0)};
    expectNear(s.sample(2.f, AnimPath::Translation), glm::vec4(1, 2, -3, 0));
    expectNear(s.sample(1.5f, AnimPath::Translation), glm::vec4(0.5f, 1, -1.5f, 0));
}

TEST(AnimationSampling, LinearRotationIsSlerp) {
    // Identity to 90 degrees about +Y; halfway is 45 degrees: (0, sin 22.5, 0, cos 22.5) as (x, y, z, w).
    const float h = kPi / 4.f;
    AnimationSampler s;
    s.times = {0.f, 1.f};
    s.values = {glm::vec4(0, 0, 0, 1), glm::vec4(0, std::sin(h), 0, std::cos(h))};
    const glm::vec4 expected(0, std::sin(h / 2.f), 0, std::cos(h / 2.f));
    expectNear(s.sample(0.5f, AnimPath::Rotation), expected);
    // The same end rotation written as -q: the shortest arc gives the same orientation.
    s.values[1] = -s.values[1];
    EXPECT_NEAR(std::fabs(glm::dot(s.sample(0.5f, AnimPath::Rotation), expected)), 1.f, 1e-5f);
    // Results are unit quaternions even between unnormalised keys.
    s.values = {glm::vec4(0, 0, 0, 2), glm::vec4(0, 3.f * std::sin(h), 0, 3.f * std::cos(h))};
    EXPECT_NEAR(glm::length(s.sample(0.3f, AnimPath::Rotation)), 1.f, 1e-6f);
    expectNear(s.sample(0.5f, AnimPath::Rotation), expected);
}

TEST(AnimationSampling, Step) {
    AnimationSampler s;
    s.interpolation = Interpolation::Step;
    s.times = {0.f, 1.f, 2.f};
    s.values = {glm::vec4(1), glm::vec4(2), glm::vec4(3)};
    expectNear(s.sample(0.99f, AnimPath::Scale), glm::vec4(1));
    expectNear(s.sample(1.f, AnimPath::Scale), glm::vec4(2));
    expectNear(s.sample(1.5f, AnimPath::Scale), glm::vec4(2));
    expectNear(s.sample(2.5f, AnimPath::Scale), glm::vec4(3));
}

TEST(AnimationSampling, CubicSplineHermite) {
    // Keys at t = 0 and 2 (td = 2): value 0 with out-tangent 1, then value 1 with in-tangent 3.
    // At t = 0.5, s = 0.25: h00 = 0.84375, h10 = 0.140625, h01 = 0.15625, h11 = -0.046875;
    // p = h00*0 + h10*td*1 + h01*1 + h11*td*3 = 0.28125 + 0.15625 - 0.28125 = 0.15625.
    AnimationSampler s;
    s.interpolation = Interpolation::CubicSpline;
    s.times = {0.f, 2.f};
    s.values = {glm::vec4(9, 0, 0, 0), glm::vec4(0, 0, 0, 0), glm::vec4(1, 0, 0, 0),  // in, value, out
                glm::vec4(3, 0, 0, 0), glm::vec4(1, 0, 0, 0), glm::vec4(9, 0, 0, 0)};
    EXPECT_NEAR(s.sample(0.5f, AnimPath::Translation).x, 0.15625f, 1e-6f);
    // At the keys the spline passes through the values (tangents 9 must not leak in).
    EXPECT_NEAR(s.sample(0.f, AnimPath::Translation).x, 0.f, 1e-6f);
    EXPECT_NEAR(s.sample(2.f, AnimPath::Translation).x, 1.f, 1e-6f);
    // Midpoint, s = 0.5: h00 = h01 = 0.5, h10 = 0.125, h11 = -0.125: 0.25 + 0.5 - 0.75 = 0.
    EXPECT_NEAR(s.sample(1.f, AnimPath::Translation).x, 0.f, 1e-6f);
}

TEST(AnimationSampling, CubicSplineRotationIsNormalised) {
    AnimationSampler s;
    s.interpolation = Interpolation::CubicSpline;
    s.times = {0.f, 1.f};
    const glm::vec4 zero(0.f);
    s.values = {zero, glm::vec4(0, 0, 0, 1), zero, zero, glm::vec4(0, 1, 0, 0), zero};
    EXPECT_NEAR(glm::length(s.sample(0.5f, AnimPath::Rotation)), 1.f, 1e-6f);
}

TEST(AnimationSampling, ClampsOutsideTheKeys) {
    for (Interpolation mode : {Interpolation::Linear, Interpolation::Step}) {
        AnimationSampler s;
        s.interpolation = mode;
        s.times = {1.f, 2.f};
        s.values = {glm::vec4(5, 0, 0, 0), glm::vec4(7, 0, 0, 0)};
        EXPECT_EQ(s.sample(0.f, AnimPath::Translation).x, 5.f);
        EXPECT_EQ(s.sample(-3.f, AnimPath::Translation).x, 5.f);
        EXPECT_EQ(s.sample(2.f, AnimPath::Translation).x, 7.f);
        EXPECT_EQ(s.sample(100.f, AnimPath::Translation).x, 7.f);
    }
    AnimationSampler c;
    c.interpolation = Interpolation::CubicSpline;
    c.times = {1.f, 2.f};
    c.values = {glm::vec4(9), glm::vec4(5), glm::vec4(9), glm::vec4(9), glm::vec4(7), glm::vec4(9)};
    EXPECT_EQ(c.sample(0.f, AnimPath::Scale).x, 5.f);
    EXPECT_EQ(c.sample(3.f, AnimPath::Scale).x, 7.f);
}

TEST(AnimationSampling, DurationIsTheLastKeyOfAChannel) {
    Animation a;
    a.samplers.resize(3);
    a.samplers[0].times = {0.f, 1.5f};
    a.samplers[1].times = {0.5f, 2.25f};
    a.samplers[2].times = {0.f, 9.f};  // drives no channel
    a.channels = {AnimationChannel{0, 0, AnimPath::Translation}, AnimationChannel{1, 0, AnimPath::Scale}};
    EXPECT_FLOAT_EQ(a.duration(), 2.25f);
}

// ---------------------------------------------------------------------------
// Camera jitter

TEST(CameraJitter, HaltonValues) {
    EXPECT_FLOAT_EQ(halton(1, 2), 0.5f);
    EXPECT_FLOAT_EQ(halton(2, 2), 0.25f);
    EXPECT_FLOAT_EQ(halton(3, 2), 0.75f);
    EXPECT_FLOAT_EQ(halton(1, 3), 1.f / 3.f);
    EXPECT_FLOAT_EQ(halton(2, 3), 2.f / 3.f);
    EXPECT_FLOAT_EQ(halton(3, 3), 1.f / 9.f);
}

TEST(CameraJitter, SamplesStayInsideThePixel) {
    for (JitterPattern p : {JitterPattern::None, JitterPattern::Halton, JitterPattern::Stratified}) {
        for (uint32_t count : {1u, 4u, 8u, 16u, 17u}) {
            for (uint64_t i = 0; i < 64; ++i) {
                const glm::vec2 j = Camera::jitterSample(p, count, i);
                EXPECT_GE(j.x, -0.5f);
                EXPECT_LE(j.x, 0.5f);
                EXPECT_GE(j.y, -0.5f);
                EXPECT_LE(j.y, 0.5f);
            }
        }
    }
    EXPECT_EQ(Camera::jitterSample(JitterPattern::Halton, 16, 0), glm::vec2(0.5f - 0.5f, 1.f / 3.f - 0.5f));
}

// ---------------------------------------------------------------------------
// Loading

TEST_F(SceneFiles, LoadsATriangle) {
    auto s = load(triangleScene());
    ASSERT_EQ(s->meshes.size(), 1u);
    EXPECT_EQ(s->meshes[0].name, "Tri/0");
    EXPECT_EQ(s->instances.size(), 1u);
    EXPECT_EQ(s->triangleCount(), 1u);
    ASSERT_EQ(s->materials.size(), 1u);  // the default material
    EXPECT_TRUE(s->warnings.empty()) << s->warnings.front();
    const Bounds b = s->bounds();
    expectNear(b.lo, glm::vec3(0, 0, 0));
    expectNear(b.hi, glm::vec3(1, 1, 0));
    // Views for kernels point at the mesh data.
    const SceneView& v = s->view();
    ASSERT_EQ(v.meshCount, 1u);
    EXPECT_EQ(v.meshes[0].positions, s->meshes[0].positions.data());
    EXPECT_EQ(v.meshes[0].triangleCount, 1u);
    EXPECT_EQ(v.instanceCount, 1u);
    EXPECT_EQ(v.materialCount, 1u);
}

TEST_F(SceneFiles, GeneratesFlatNormalsWhenAbsent) {
    // Two triangles sharing an edge, folded 90 degrees: flat normals differ per triangle, so the
    // shared vertices are split.
    Gltf g;
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, -1}, "VEC3");
    const int idx = g.indices(std::vector<uint16_t>{0, 1, 2, 0, 3, 1});
    g.scene({g.node({{"mesh", g.mesh("Fold", {{"POSITION", pos}}, idx)}})});
    auto s = load(g);
    const Mesh& m = s->meshes.at(0);
    ASSERT_EQ(m.triangleCount(), 2u);
    EXPECT_EQ(m.positions.size(), 6u);
    ASSERT_EQ(m.normals.size(), 6u);
    for (uint32_t t = 0; t < 2; ++t) {
        const glm::vec3 p0 = m.positions[m.indices[3 * t]], p1 = m.positions[m.indices[3 * t + 1]],
                        p2 = m.positions[m.indices[3 * t + 2]];
        for (int k = 0; k < 3; ++k) {
            const glm::vec3 n = m.normals[m.indices[3 * t + k]];
            EXPECT_NEAR(glm::length(n), 1.f, 1e-6f);
            EXPECT_NEAR(glm::dot(n, p1 - p0), 0.f, 1e-6f);
            EXPECT_NEAR(glm::dot(n, p2 - p0), 0.f, 1e-6f);
            EXPECT_GT(glm::dot(n, glm::cross(p1 - p0, p2 - p0)), 0.f);  // counter-clockwise faces the normal
        }
    }
    expectNear(m.normals[m.indices[0]], glm::vec3(0, 0, 1));   // (0,0,0) (1,0,0) (0,1,0)
    expectNear(m.normals[m.indices[3]], glm::vec3(0, -1, 0));  // (0,0,0) (0,0,-1) (1,0,0): (0,0,-1) x (1,0,0)
}

TEST_F(SceneFiles, GeneratedTangentsAreOrthonormalWithHandedness) {
    // A quad in the XY plane with glTF's usual mapping: u along +X, v down the image (-Y).
    // Its tangent is +X and the bitangent cross(n, t) * w must point up the image (+Y): w = +1.
    // Mirrored in u, the tangent flips to -X and w to -1.
    for (float mirror : {1.f, -1.f}) {
        Gltf g;
        const int pos = g.floats({0, 1, 0, mirror, 1, 0, 0, 0, 0, mirror, 0, 0}, "VEC3");
        // Bent normals (not the face normal) to check Gram-Schmidt.
        const glm::vec3 a = glm::normalize(glm::vec3(0.3f, 0.f, 1.f)), b = glm::normalize(glm::vec3(0.f, 0.4f, 1.f));
        const int nrm = g.floats({a.x, a.y, a.z, b.x, b.y, b.z, 0, 0, 1, a.x, a.y, a.z}, "VEC3");
        const int uv = g.floats({0, 0, 1, 0, 0, 1, 1, 1}, "VEC2");
        const int idx = g.indices(std::vector<uint32_t>{0, 2, 1, 1, 2, 3});
        g.scene({g.node({{"mesh", g.mesh("Quad", {{"POSITION", pos}, {"NORMAL", nrm}, {"TEXCOORD_0", uv}}, idx)}})});
        auto s = load(g);
        const Mesh& m = s->meshes.at(0);
        ASSERT_EQ(m.tangents.size(), 4u);
        for (size_t v = 0; v < 4; ++v) {
            const glm::vec3 t(m.tangents[v]);
            EXPECT_NEAR(glm::length(t), 1.f, 1e-5f);
            EXPECT_NEAR(glm::dot(t, m.normals[v]), 0.f, 1e-5f);
            EXPECT_EQ(m.tangents[v].w, mirror);
            EXPECT_GT(t.x * mirror, 0.9f);
        }
    }
}

TEST_F(SceneFiles, TangentsWithoutUvsAreStillOrthonormal) {
    auto s = load(triangleScene());
    for (const glm::vec4& t : s->meshes[0].tangents) {
        EXPECT_NEAR(glm::length(glm::vec3(t)), 1.f, 1e-5f);
        EXPECT_NEAR(glm::dot(glm::vec3(t), glm::vec3(0, 0, 1)), 0.f, 1e-5f);
        EXPECT_EQ(std::fabs(t.w), 1.f);
    }
}

TEST_F(SceneFiles, MaterialDefaultsFollowGltf) {
    Gltf g = triangleScene();
    g.j["materials"] =
        json::array({{{"name", "Plain"}}, {{"name", "Rough"}, {"pbrMetallicRoughness", {{"roughnessFactor", 0.25}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 1;
    auto s = load(g);
    ASSERT_EQ(s->materials.size(), 2u);
    for (const Material& m : s->materials) {
        EXPECT_EQ(m.metallicFactor, 1.f) << m.name;  // absent metallicFactor means fully metallic
        EXPECT_EQ(m.baseColorFactor, glm::vec4(1.f));
        EXPECT_FALSE(m.isEmissive());
    }
    EXPECT_EQ(s->materials[0].roughnessFactor, 1.f);
    EXPECT_EQ(s->materials[1].roughnessFactor, 0.25f);
    EXPECT_EQ(s->meshes[0].material, 1u);
    EXPECT_EQ(s->view().materials[1].roughnessFactor, 0.25f);
}

// glTF bounds base colour, metallic and roughness to [0, 1]; a factor outside is clamped to it, with a warning
// naming the material. A base colour of 1e30 would otherwise multiply a path's energy at every bounce.
TEST_F(SceneFiles, MaterialFactorsOutsideTheirRangeAreClampedWithAWarning) {
    Gltf g = triangleScene();
    g.j["materials"] = json::array(
        {{{"name", "Glowing"},
          {"pbrMetallicRoughness",
           {{"baseColorFactor", {0.5, 1e30, -2.0, 1.0}}, {"metallicFactor", -0.5}, {"roughnessFactor", 7.0}}}},
         {{"name", "Valid"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.0, 1.0, 0.25, 1.0}}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    auto s = load(g);
    ASSERT_EQ(s->materials.size(), 2u);
    const Material& m = s->materials[0];
    EXPECT_EQ(m.baseColorFactor, glm::vec4(0.5f, 1.f, 0.f, 1.f));
    EXPECT_EQ(m.metallicFactor, 0.f);
    EXPECT_EQ(m.roughnessFactor, 1.f);
    EXPECT_EQ(s->materials[1].baseColorFactor, glm::vec4(0.f, 1.f, 0.25f, 1.f));
    ASSERT_EQ(s->warnings.size(), 3u);
    for (const char* factor : {"baseColorFactor", "metallicFactor", "roughnessFactor"})
        EXPECT_TRUE(hasWarning(*s, "'Glowing'", factor)) << factor;
}

TEST_F(SceneFiles, EmissiveStrengthMultipliesEmissiveFactor) {
    Gltf g = triangleScene();
    g.j["extensionsUsed"] = {"KHR_materials_emissive_strength"};
    g.j["materials"] =
        json::array({{{"name", "Lamp"},
                      {"emissiveFactor", {1.0, 0.5, 0.0}},
                      {"alphaMode", "MASK"},
                      {"doubleSided", true},
                      {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 4.0}}}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    // The mesh placed twice: every triangle of every instance is an emissive triangle.
    g.j["nodes"].push_back({{"mesh", 0}, {"translation", {0, 0, 2}}});
    g.j["scenes"][0]["nodes"].push_back(1);
    auto s = load(g);
    ASSERT_EQ(s->materials.size(), 1u);
    const Material& m = s->materials[0];
    expectNear(m.emissiveFactor, glm::vec3(4.f, 2.f, 0.f));
    EXPECT_TRUE(m.isEmissive());
    EXPECT_EQ(m.alphaMode, AlphaMode::Mask);
    EXPECT_TRUE(m.doubleSided);
    ASSERT_EQ(s->emissiveTriangles.size(), 2u);
    EXPECT_EQ(s->emissiveTriangles[0].instance, 0u);
    EXPECT_EQ(s->emissiveTriangles[1].instance, 1u);
    EXPECT_EQ(s->view().materials[0].alphaMask, 1u);
}

TEST_F(SceneFiles, AllIndexTypes) {
    std::vector<std::vector<uint32_t>> results;
    for (int type : {kByte, kShort, kUInt}) {
        Gltf g;
        // A strip of two triangles over four vertices, indexed out of order.
        const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0}, "VEC3");
        const std::vector<uint32_t> idx = {0, 1, 2, 2, 1, 3};
        int acc;
        if (type == kByte)
            acc = g.indices(std::vector<uint8_t>(idx.begin(), idx.end()));
        else if (type == kShort)
            acc = g.indices(std::vector<uint16_t>(idx.begin(), idx.end()));
        else
            acc = g.indices(idx);
        const int nrm = g.floats({0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1}, "VEC3");
        g.scene({g.node({{"mesh", g.mesh("Quad", {{"POSITION", pos}, {"NORMAL", nrm}}, acc)}})});
        auto s = load(g);
        EXPECT_EQ(s->meshes.at(0).indices, idx) << "component type " << type;
    }
}

// Normals of any finite length, huge or tiny, keep their direction: the length of (1e30, 0, 0) overflows a float
// and that of 1e-30 underflows, so normalising by it gave a zero normal (NaN downstream in the G-buffers).
TEST_F(SceneFiles, NormalsOfExtremeLengthKeepTheirDirection) {
    Gltf g;
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0}, "VEC3");
    const int idx = g.indices(std::vector<uint32_t>{0, 1, 2, 2, 1, 3});
    const int nrm = g.floats({1e30f, 0, 0, 0, -3e38f, 0, 0, 0, 1e-30f, 2e30f, 2e30f, 0}, "VEC3");
    g.scene({g.node({{"mesh", g.mesh("Quad", {{"POSITION", pos}, {"NORMAL", nrm}}, idx)}})});
    auto s = load(g);
    const Mesh& m = s->meshes.at(0);
    ASSERT_EQ(m.normals.size(), 4u);
    expectNear(m.normals[0], glm::vec3(1, 0, 0));
    expectNear(m.normals[1], glm::vec3(0, -1, 0));
    expectNear(m.normals[2], glm::vec3(0, 0, 1));
    expectNear(m.normals[3], glm::normalize(glm::vec3(1, 1, 0)));
}

TEST_F(SceneFiles, NonIndexedStripAndSparse) {
    Gltf g;
    // Four vertices; vertex 3 is wrong in the buffer and fixed by a sparse substitution.
    const std::vector<float> base = {0, 0, 0, 1, 0, 0, 0, 1, 0, 7, 7, 7};
    const int pos = g.floats(base, "VEC3");
    const uint8_t sparseIdx[1] = {3};
    const float sparseVal[3] = {1, 1, 0};
    const int iv = g.view(sparseIdx, 1), vv = g.view(sparseVal, 12);
    g.j["accessors"][pos]["sparse"] = {
        {"count", 1}, {"indices", {{"bufferView", iv}, {"componentType", kByte}}}, {"values", {{"bufferView", vv}}}};
    json prim = {{"attributes", {{"POSITION", pos}}}, {"mode", 5}};  // TRIANGLE_STRIP
    g.j["meshes"] = json::array({{{"name", "Strip"}, {"primitives", json::array({prim})}}});
    g.scene({g.node({{"mesh", 0}})});
    auto s = load(g);
    const Mesh& m = s->meshes.at(0);
    ASSERT_EQ(m.triangleCount(), 2u);
    const Bounds b = s->bounds();
    expectNear(b.hi, glm::vec3(1, 1, 0));  // the sparse value replaced (7, 7, 7)
    // Both strip triangles keep the counter-clockwise winding: flat normals +Z.
    for (const glm::vec3& n : m.normals) expectNear(n, glm::vec3(0, 0, 1));
}

TEST_F(SceneFiles, LoadsGlb) {
    Gltf g = triangleScene();
    auto s = Scene::load(write("tri.glb", g.glb()));
    EXPECT_EQ(s->triangleCount(), 1u);
    EXPECT_EQ(s->meshes[0].name, "Tri/0");
    // The magic decides: a GLB with a .gltf name loads too.
    EXPECT_EQ(Scene::load(write("misnamed.gltf", g.glb()))->triangleCount(), 1u);
}

TEST_F(SceneFiles, LoadsExternalBin) {
    Gltf g = triangleScene();
    json d = g.j;
    d["buffers"] = json::array({{{"byteLength", g.bin.size()}, {"uri", "tri%20data.bin"}}});
    write("tri data.bin", g.bin);
    auto s = Scene::load(write("tri.gltf", d.dump()));
    EXPECT_EQ(s->triangleCount(), 1u);
}

TEST_F(SceneFiles, DecodesTexturesToRgba8) {
    Gltf g = triangleScene();
    // 8-bit grey (one channel) via stb, and 16-bit grey made by hand.
    const uint8_t grey[2] = {10, 200};
    std::vector<uint8_t> a;
    auto append = [](void* ctx, void* data, int size) {
        auto* out = static_cast<std::vector<uint8_t>*>(ctx);
        out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
    };
    ASSERT_NE(stbi_write_png_to_func(append, &a, 2, 1, 1, grey, 2), 0);
    const std::vector<uint8_t> b = png16Grey({0xFFFF, 0x8080});
    g.j["images"] = json::array({{{"bufferView", g.view(a.data(), a.size())}, {"mimeType", "image/png"}},
                                 {{"uri", "data:image/png;base64," + base64(b)}}});
    g.j["textures"] = json::array({{{"source", 0}}, {{"source", 1}}});
    g.j["materials"] =
        json::array({{{"name", "Textured"},
                      {"pbrMetallicRoughness",
                       {{"baseColorTexture", {{"index", 0}}}, {"metallicRoughnessTexture", {{"index", 1}}}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    auto s = load(g);
    ASSERT_EQ(s->images.size(), 2u);
    EXPECT_TRUE(s->warnings.empty()) << s->warnings.front();
    const SceneImage& i8 = s->images[0];
    ASSERT_EQ(i8.width, 2u);
    EXPECT_EQ(i8.texels[0], glm::u8vec4(10, 10, 10, 255));
    EXPECT_EQ(i8.texels[1], glm::u8vec4(200, 200, 200, 255));
    const SceneImage& i16 = s->images[1];
    ASSERT_EQ(i16.texels.size(), 2u);
    EXPECT_EQ(i16.texels[0], glm::u8vec4(255, 255, 255, 255));
    EXPECT_EQ(i16.texels[1], glm::u8vec4(128, 128, 128, 255));
    EXPECT_EQ(s->materials[0].baseColorTexture.image, 0);
    EXPECT_EQ(s->materials[0].metallicRoughnessTexture.image, 1);
    EXPECT_EQ(s->view().images[1].texels, i16.texels.data());
}

TEST_F(SceneFiles, LightsAndCameras) {
    Gltf g = triangleScene();
    g.j["extensionsUsed"] = {"KHR_lights_punctual"};
    g.j["extensions"] = {{"KHR_lights_punctual",
                          {{"lights", json::array({{{"type", "point"}, {"color", {1, 0.5, 0.25}}, {"intensity", 20}},
                                                   {{"type", "spot"}, {"spot", {{"outerConeAngle", 0.5}}}},
                                                   {{"type", "directional"}}})}}}};
    const float h = kPi / 4.f;  // 90 degrees about +Y turns -Z into -X
    const int spot = g.node({{"name", "Spot"},
                             {"rotation", {0, std::sin(h), 0, std::cos(h)}},
                             {"extensions", {{"KHR_lights_punctual", {{"light", 1}}}}}});
    const int point = g.node({{"name", "Point"},
                              {"translation", {1, 2, 3}},
                              {"children", {spot}},
                              {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    const int sun = g.node({{"extensions", {{"KHR_lights_punctual", {{"light", 2}}}}}});
    g.j["cameras"] = json::array({{{"name", "Cam"},
                                   {"type", "perspective"},
                                   {"perspective", {{"yfov", 0.5}, {"aspectRatio", 1.5}, {"znear", 0.1}}}}});
    const int cam = g.node({{"camera", 0}, {"translation", {0, 0, 5}}});
    g.j["scenes"][0]["nodes"] = {0, point, sun, cam};
    auto s = load(g);
    ASSERT_EQ(s->lights.size(), 3u);
    const Light& p = s->lights[0];
    EXPECT_EQ(p.type, LightType::Point);
    EXPECT_EQ(p.intensity, 20.f);
    expectNear(p.color, glm::vec3(1, 0.5f, 0.25f));
    expectNear(p.position, glm::vec3(1, 2, 3));
    const Light& sp = s->lights[1];
    EXPECT_EQ(sp.type, LightType::Spot);
    EXPECT_EQ(sp.outerConeAngle, 0.5f);
    expectNear(sp.position, glm::vec3(1, 2, 3));  // inherits the parent's translation
    expectNear(sp.direction, glm::vec3(-1, 0, 0));
    EXPECT_EQ(s->lights[2].type, LightType::Directional);
    expectNear(s->lights[2].direction, glm::vec3(0, 0, -1));

    EXPECT_EQ(s->activeCamera, 0);
    EXPECT_EQ(s->camera.name, "Cam");
    EXPECT_EQ(s->camera.fovY, 0.5f);
    EXPECT_EQ(s->camera.aspect, 1.5f);
    EXPECT_FLOAT_EQ(s->camera.nearZ, 0.1f);
    EXPECT_GT(s->camera.farZ, 1000.f);  // no zfar: an infinite projection, approximated far away
    expectNear(s->camera.position(), glm::vec3(0, 0, 5));
    expectNear(s->camera.forward(), glm::vec3(0, 0, -1));
}

TEST_F(SceneFiles, OrthographicCameraFallsBackToPerspective) {
    Gltf g = triangleScene();
    g.j["cameras"] = json::array(
        {{{"type", "orthographic"}, {"orthographic", {{"xmag", 1}, {"ymag", 1}, {"znear", 0.01}, {"zfar", 50}}}}});
    g.j["scenes"][0]["nodes"].push_back(g.node({{"camera", 0}, {"translation", {0, 0, 3}}}));
    auto s = load(g);
    EXPECT_EQ(s->activeCamera, 0);
    EXPECT_TRUE(hasWarning(*s, "cameras[0]", "orthographic"));
    EXPECT_FLOAT_EQ(s->camera.farZ, 50.f);
}

// ---------------------------------------------------------------------------
// Hierarchy, animation and motion

/// Parent (translated and turned 90 degrees about +Y) with a child (translated, scaled) that draws the
/// triangle; the parent's translation is animated from x = 1 at t = 0 to x = 5 at t = 1.
Gltf hierarchyScene(bool animated) {
    Gltf g;
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    const int mesh = g.mesh("Tri", {{"POSITION", pos}});
    const float h = kPi / 4.f;
    g.node({{"name", "Parent"},
            {"translation", {1, 0, 0}},
            {"rotation", {0, std::sin(h), 0, std::cos(h)}},
            {"children", {1}}});
    g.node({{"name", "Child"}, {"mesh", mesh}, {"translation", {0, 0, 1}}, {"scale", {2, 2, 2}}});
    g.scene({0});
    if (animated) {
        const int in = g.floats({0, 1}, "SCALAR");
        const int out = g.floats({1, 0, 0, 5, 0, 0}, "VEC3");
        g.j["animations"] = json::array(
            {{{"name", "Slide"},
              {"samplers", json::array({{{"input", in}, {"output", out}}})},
              {"channels", json::array({{{"sampler", 0}, {"target", {{"node", 0}, {"path", "translation"}}}}})}}});
    }
    return g;
}

TEST_F(SceneFiles, NodeHierarchyTransforms) {
    auto s = load(hierarchyScene(false));
    ASSERT_EQ(s->nodes.size(), 2u);
    EXPECT_EQ(s->nodes[1].parent, 0);
    ASSERT_EQ(s->instances.size(), 1u);
    const Instance& inst = s->instances[0];
    EXPECT_EQ(inst.node, 1u);
    expectNear(inst.world, s->nodes[0].local() * s->nodes[1].local());
    // By hand: the child's origin (0,0,1) turned 90 degrees about +Y is (1,0,0), plus the parent's (1,0,0).
    expectNear(glm::vec3(inst.world[3]), glm::vec3(2, 0, 0));
    // Its local +X axis, scaled by 2, turns to -Z.
    expectNear(glm::vec3(inst.world[0]), glm::vec3(0, 0, -2));
    expectNear(s->view().instances[0].world, inst.world);
    // The normal matrix is the inverse transpose: the scale divides instead of multiplying.
    expectNear(s->view().instances[0].normalMatrix * glm::vec3(1, 0, 0), glm::vec3(0, 0, -0.5f));
    EXPECT_FALSE(s->hasMotion());
}

TEST_F(SceneFiles, AnimatedParentMovesChildAndKeepsPrevious) {
    auto s = load(hierarchyScene(true));
    EXPECT_FLOAT_EQ(s->animationLength(), 1.f);
    EXPECT_TRUE(s->hasMotion());
    s->update(0.0);
    const glm::mat4 world0 = s->instances[0].world;
    expectNear(glm::vec3(world0[3]), glm::vec3(2, 0, 0));
    expectNear(s->instances[0].prevWorld, world0);
    s->update(0.5);
    expectNear(glm::vec3(s->instances[0].world[3]), glm::vec3(4, 0, 0));  // parent at x = 3, child 1 further
    expectNear(s->instances[0].prevWorld, world0);
    expectNear(s->view().instances[0].prevWorld, world0);
    s->update(10.0);  // past the end: the last pose holds
    expectNear(glm::vec3(s->instances[0].world[3]), glm::vec3(6, 0, 0));
    s->cutMotion();
    expectNear(s->instances[0].prevWorld, s->instances[0].world);
}

TEST_F(SceneFiles, RayHitsTheRightInstanceAndFollowsAnimation) {
    Gltf g = hierarchyScene(true);
    g.j["nodes"].push_back({{"name", "Static"}, {"mesh", 0}, {"translation", {0, 5, 0}}});
    g.j["scenes"][0]["nodes"].push_back(2);
    auto s = load(g);
    ASSERT_EQ(s->instances.size(), 2u);
    EXPECT_EQ(s->instances[1].node, 2u);
    const RayScene& rt = s->rayScene();
    // The static triangle spans (0..1, 5..6, 0); shoot down -Z at (0.25, 5.25).
    RayHit hit = rt.intersect({0.25f, 5.25f, 5.f}, {0, 0, -1});
    ASSERT_TRUE(hit.hit());
    EXPECT_EQ(hit.instance, 1u);
    EXPECT_EQ(hit.primitive, 0u);
    EXPECT_NEAR(hit.t, 5.f, 1e-4f);
    EXPECT_NEAR(hit.u, 0.25f, 1e-4f);
    EXPECT_NEAR(hit.v, 0.25f, 1e-4f);
    EXPECT_FALSE(rt.intersect({0.75f, 5.75f, 5.f}, {0, 0, -1}).hit());  // outside the hypotenuse
    EXPECT_FALSE(rt.intersect({20.f, 20.f, 5.f}, {0, 0, -1}).hit());
    // The animated triangle, scaled by 2 and turned, is (2,0,0) (2,0,-2) (2,2,0) at t = 0.
    hit = rt.intersect({10.f, 0.5f, -0.5f}, {-1, 0, 0});
    ASSERT_TRUE(hit.hit());
    EXPECT_EQ(hit.instance, 0u);
    EXPECT_NEAR(hit.t, 8.f, 1e-4f);
    s->update(0.5);  // parent at x = 3: the plane moves to x = 4
    hit = s->rayScene().intersect({10.f, 0.5f, -0.5f}, {-1, 0, 0});
    ASSERT_TRUE(hit.hit());
    EXPECT_EQ(hit.instance, 0u);
    EXPECT_NEAR(hit.t, 6.f, 1e-4f);
    EXPECT_TRUE(s->rayScene().occluded({10.f, 0.5f, -0.5f}, {-1, 0, 0}, 0.f, 100.f));
    EXPECT_FALSE(s->rayScene().occluded({10.f, 0.5f, -0.5f}, {-1, 0, 0}, 0.f, 5.f));
}

/// A full 16-ray packet through RayScene::intersect16; ray(i) is lane i's (origin, direction).
template <class Ray>
std::array<RayHit, 16> tracePacket(const RayScene& rt, Ray ray) {
    glm::vec3 origins[16], dirs[16];
    bool valid[16];
    for (int i = 0; i < 16; ++i) {
        std::tie(origins[i], dirs[i]) = ray(i);
        valid[i] = true;
    }
    std::array<RayHit, 16> hits;
    rt.intersect16(origins, dirs, valid, 1e30f, hits.data());
    return hits;
}

// A transform without an inverse (a zero scale on some axis, a common way to hide an object in an animation)
// hides its instance: rays pass it, single and in packets, and it is back once the scale recovers. Embree would
// carry rays into it through the inverse and reject them.
TEST_F(SceneFiles, InstancesWithASingularTransformAreHiddenUntilTheyRecover) {
    Gltf g;
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    const int mesh = g.mesh("Tri", {{"POSITION", pos}});
    const int shrinking = g.node({{"name", "Shrinking"}, {"mesh", mesh}});
    const int behind = g.node({{"name", "Behind"}, {"mesh", mesh}, {"translation", {0, 0, -1}}});
    g.scene({shrinking, behind});
    // Flattened along z, the axis the triangle lies across: it would keep its whole area.
    const int in = g.floats({0, 1, 2}, "SCALAR");
    const int out = g.floats({1, 1, 1, 1, 1, 0, 1, 1, 1}, "VEC3");
    g.j["animations"] = json::array(
        {{{"name", "Squash"},
          {"samplers", json::array({{{"input", in}, {"output", out}}})},
          {"channels", json::array({{{"sampler", 0}, {"target", {{"node", shrinking}, {"path", "scale"}}}}})}}});
    auto s = load(g);
    ASSERT_EQ(s->instances.size(), 2u);
    const auto firstHit = [&](bool packet) {
        if (!packet) return s->rayScene().intersect({0.25f, 0.25f, 5.f}, {0, 0, -1});
        const auto hits = tracePacket(s->rayScene(), [](int i) {
            return std::pair{glm::vec3(0.05f + 0.04f * float(i % 4), 0.05f + 0.04f * float(i / 4), 5.f),
                             glm::vec3(0, 0, -1)};
        });
        for (int i = 1; i < 16; ++i) EXPECT_EQ(hits[i].instance, hits[0].instance) << i;
        return hits[5];
    };
    for (double t : {0.0, 1.0, 2.0}) {
        s->update(t);
        const bool hidden = t == 1.0;
        EXPECT_EQ(s->instances[0].visible(), !hidden) << t;
        EXPECT_TRUE(s->instances[1].visible()) << t;
        for (bool packet : {false, true}) {
            const RayHit hit = firstHit(packet);
            ASSERT_TRUE(hit.hit()) << t;
            EXPECT_EQ(hit.instance, hidden ? 1u : 0u) << "t " << t << " packet " << packet;
            EXPECT_NEAR(hit.t, hidden ? 6.f : 5.f, 1e-4f);
        }
        const glm::mat3& nm = s->view().instances[0].normalMatrix;
        for (int c = 0; c < 3; ++c)
            for (int r = 0; r < 3; ++r) EXPECT_TRUE(std::isfinite(nm[c][r])) << t;
    }
}

// A camera node scaled to 0 (or with a position beyond float's range) keeps a usable pose: orthonormal axes and a
// finite position, so every primary ray is finite.
TEST_F(SceneFiles, CameraOnADegenerateNodeKeepsAUsablePose) {
    // The last: a parent scaled by 1e30 moves the camera's 1e30 translation to infinity.
    // The matrices: all zeros, a projective bottom row, parallel axes (no orientation left), a shear.
    for (const json& extra : {json{{"scale", {0, 0, 0}}}, json{{"scale", {1, 0, 1}}},
                              json{{"translation", {1e30, 0, 0}}}, json{{"matrix", std::vector<float>(16, 0.f)}},
                              json{{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 1, 0, 1, 3.9, 0}}},
                              json{{"matrix", {1, 1, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 0, 0, 3, 1}}},
                              json{{"matrix", {1, 0, 0, 0, 0.5, 1, 0, 0, 0, 0, 1, 0, 0, 0, 3, 1}}}}) {
        const bool far = extra.contains("translation");
        Gltf g = triangleScene();
        g.j["cameras"] = json::array({{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.1}}}}});
        json camera = {{"name", "Cam"}, {"camera", 0}};
        if (!extra.contains("matrix")) camera["translation"] = {0, 0, 3};
        camera.update(extra);
        g.j["nodes"].push_back(camera);
        if (far) g.j["nodes"].push_back({{"name", "Huge"}, {"scale", {1e30, 1e30, 1e30}}, {"children", {1}}});
        g.j["scenes"][0]["nodes"].push_back(far ? 2 : 1);
        auto s = load(g);
        s->update(0.0);
        const glm::mat4& w = s->camera.world;
        SCOPED_TRACE(extra.dump());
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) ASSERT_TRUE(std::isfinite(w[c][r])) << c << "," << r;
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(glm::length(glm::vec3(w[c])), 1.f, 1e-5f) << c;
        // A rotation and a translation: the view (its inverse) exists and is finite.
        EXPECT_NEAR(std::fabs(glm::determinant(glm::mat3(w))), 1.f, 1e-4f);
        EXPECT_EQ(glm::vec4(w[0][3], w[1][3], w[2][3], w[3][3]), glm::vec4(0.f, 0.f, 0.f, 1.f));
        const glm::mat4 view = s->camera.view();
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) ASSERT_TRUE(std::isfinite(view[c][r])) << c << "," << r;
    }
}

TEST_F(SceneFiles, JsonTooDeepOrNumbersBeyondDoubleAreBadInputBeforeParsing) {
    // tinygltf recurses into nested values (extras): 100,000 levels would exhaust the stack.
    Gltf g = triangleScene();
    g.j["asset"]["extras"] = "DEEP";
    std::string text = g.text();
    text.replace(text.find("\"DEEP\""), 6, std::string(100000, '[') + std::string(100000, ']'));
    std::string msg = loadError(write("deep.gltf", text));
    EXPECT_NE(msg.find("nested more than"), std::string::npos) << msg.substr(0, 300);
    g = triangleScene();
    g.j["asset"]["extras"] = "BIG";
    text = g.text();
    text.replace(text.find("\"BIG\""), 5, "1e400");
    msg = loadError(write("big.gltf", text));
    EXPECT_NE(msg.find("1e400 is too large"), std::string::npos) << msg;
}

TEST_F(SceneFiles, AReferencedFileThatIsAFolderOrAPipeIsBadInput) {
    Gltf g = triangleScene();
    json d = g.j;
    fs::create_directories(mDir / "folder.bin");
    ASSERT_EQ(::mkfifo((mDir / "pipe.bin").c_str(), 0600), 0);
    for (const char* uri : {".", "folder.bin", "pipe.bin"}) {
        d["buffers"] = json::array({{{"byteLength", g.bin.size()}, {"uri", uri}}});
        const std::string msg = loadError(write("t.gltf", d.dump()));
        EXPECT_NE(msg.find("buffers[0]"), std::string::npos) << uri << ": " << msg;
    }
}

// Rays beyond the traced world (kWorldLimit) or not finite hit nothing and are occluded by nothing, single or in a
// packet, where Embree would reject them; the other lanes of a packet are unaffected.
TEST_F(SceneFiles, UntraceableRaysHitNothing) {
    auto s = load(triangleScene());
    const RayScene& rt = s->rayScene();
    const glm::vec3 down(0, 0, -1), o(0.25f, 0.25f, 5.f);
    ASSERT_TRUE(rt.intersect(o, down).hit());
    for (const auto& [origin, dir] :
         {std::pair{glm::vec3(0.25f, 0.25f, 2e8f), down}, std::pair{glm::vec3(0.25f, 0.25f, 1e30f), down},
          std::pair{o, glm::vec3(0.f, 0.f, -1e9f)}, std::pair{o, glm::vec3(NAN, 0.f, -1.f)},
          std::pair{glm::vec3(INFINITY, 0.f, 0.f), down}}) {
        EXPECT_FALSE(traceable(origin, dir));
        EXPECT_FALSE(rt.intersect(origin, dir).hit());
        EXPECT_FALSE(rt.occluded(origin, dir, 0.f, 1e30f));
        const auto hits = tracePacket(rt, [&](int i) { return i == 7 ? std::pair{origin, dir} : std::pair{o, down}; });
        for (int i = 0; i < 16; ++i) EXPECT_EQ(hits[i].hit(), i != 7) << i;
    }
    EXPECT_TRUE(traceable(glm::vec3(-kWorldLimit), glm::vec3(kWorldLimit)));
}

TEST(SceneInCode, InstanceVisibilityNeedsAFiniteModerateInverse) {
    const auto visible = [](const glm::mat4& world) {
        Instance inst;
        inst.world = world;
        return inst.visible();
    };
    EXPECT_TRUE(visible(glm::mat4(1.f)));
    EXPECT_TRUE(visible(glm::scale(glm::mat4(1.f), glm::vec3(1e-5f))));
    EXPECT_TRUE(visible(glm::scale(glm::mat4(1.f), glm::vec3(-2.f, 3.f, 1e4f))));  // mirrored
    EXPECT_FALSE(visible(glm::scale(glm::mat4(1.f), glm::vec3(0.f))));
    EXPECT_FALSE(visible(glm::scale(glm::mat4(1.f), glm::vec3(1.f, 0.f, 1.f))));
    EXPECT_FALSE(visible(glm::scale(glm::mat4(1.f), glm::vec3(1e-30f))));              // determinant rounds to 0
    EXPECT_FALSE(visible(glm::scale(glm::mat4(1.f), glm::vec3(1e-20f, 1e20f, 1.f))));  // inverse beyond 1e18
    EXPECT_FALSE(visible(glm::translate(glm::mat4(1.f), glm::vec3(NAN, 0.f, 0.f))));
    EXPECT_TRUE(visible(glm::translate(glm::mat4(1.f), glm::vec3(0.f, -kWorldLimit, 0.f))));
    EXPECT_FALSE(visible(glm::translate(glm::mat4(1.f), glm::vec3(0.f, -2.f * kWorldLimit, 0.f))));
    EXPECT_FALSE(visible(glm::scale(glm::mat4(1.f), glm::vec3(1e-10f))));  // inverse 1e10
    EXPECT_FALSE(visible(glm::scale(glm::mat4(1.f), glm::vec3(INFINITY, 1.f, 1.f))));
}

TEST_F(SceneFiles, CubicSplineAnimationFromFile) {
    Gltf g = triangleScene();
    const int in = g.floats({0, 2}, "SCALAR");
    // Scale channel, (in, value, out) per key as in the hand-computed sampler test: x at t = 0.5 is 0.15625.
    const int out = g.floats({9, 9, 9, 0, 1, 1, 1, 1, 1, 3, 3, 3, 1, 1, 1, 9, 9, 9}, "VEC3");
    g.j["animations"] =
        json::array({{{"samplers", json::array({{{"input", in}, {"output", out}, {"interpolation", "CUBICSPLINE"}}})},
                      {"channels", json::array({{{"sampler", 0}, {"target", {{"node", 0}, {"path", "scale"}}}}})}}});
    auto s = load(g);
    ASSERT_EQ(s->animations.size(), 1u);
    EXPECT_EQ(s->animations[0].samplers[0].interpolation, Interpolation::CubicSpline);
    s->update(0.5);
    EXPECT_NEAR(s->nodes[0].scale.x, 0.15625f, 1e-6f);
    EXPECT_NEAR(s->nodes[0].scale.y, 1.f, 1e-6f);
}

/// One triangle (0,0,0), (1,0,0), (0,1,0) facing +Z, made in code.
Mesh triangleMesh() {
    Mesh m;
    m.name = "tri";
    m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    m.normals.assign(3, glm::vec3(0, 0, 1));
    m.tangents.assign(3, glm::vec4(1, 0, 0, 1));
    m.uvs.assign(3, glm::vec2(0));
    m.indices = {0, 1, 2};
    return m;
}

TEST(SceneInCode, FinalizeBuildsInstancesDepthFirst) {
    Scene s;
    s.meshes.push_back(triangleMesh());
    s.materials.emplace_back();
    s.nodes.resize(4);
    s.nodes[0].children = {2, 1};
    s.nodes[0].meshes = {0};
    s.nodes[1].meshes = {0};
    s.nodes[2].meshes = {0};
    s.nodes[2].translation = {0, 0, -3};
    s.nodes[3].meshes = {0};  // a second root
    s.finalize();
    ASSERT_EQ(s.instances.size(), 4u);
    EXPECT_EQ(s.instances[0].node, 0u);
    EXPECT_EQ(s.instances[1].node, 2u);  // children in their listed order
    EXPECT_EQ(s.instances[2].node, 1u);
    EXPECT_EQ(s.instances[3].node, 3u);
    EXPECT_EQ(s.triangleCount(), 4u);
    EXPECT_EQ(s.nodes[2].parent, 0);
    // No camera: a default one looks down -Z at the bounds centre and sees the whole bounding sphere.
    EXPECT_EQ(s.activeCamera, -1);
    const Bounds b = s.bounds();
    const glm::vec3 toCenter = b.center() - s.camera.position();
    expectNear(glm::normalize(toCenter), glm::vec3(0, 0, -1));
    const float radius = 0.5f * glm::length(b.extent());
    EXPECT_LE(std::asin(radius / glm::length(toCenter)), 0.5f * s.camera.fovY + 1e-5f);

    s.nodes[1].children = {0};  // a cycle
    EXPECT_THROW(s.finalize(), Error);
}

// What lights a scene (the CLI warns when nothing does): an emissive material on an instance (with a texel that is
// not black when its emission is textured), a punctual light of some intensity, an environment that is not black.
TEST(SceneInCode, EmitsLightOnlyWhenSomethingDoes) {
    Scene s;
    s.meshes.push_back(triangleMesh());
    s.materials.emplace_back();
    s.nodes.resize(1);
    s.nodes[0].meshes = {0};
    s.roots = {0};
    s.finalize();
    EXPECT_FALSE(s.emitsLight());
    s.materials[0].emissiveFactor = glm::vec3(0.f, 0.f, 2.f);
    EXPECT_TRUE(s.emitsLight());
    SceneImage black;
    black.width = black.height = 2;
    black.texels.assign(4, glm::u8vec4(0, 0, 0, 255));
    s.images.push_back(black);
    s.materials[0].emissiveTexture.image = 0;
    EXPECT_FALSE(s.emitsLight());  // an emissive factor times a black texture
    s.images[0].texels[3].g = 1;
    EXPECT_TRUE(s.emitsLight());
    s.materials[0].emissiveFactor = glm::vec3(0.f);
    Light l;
    l.intensity = 0.f;
    s.lights.push_back(l);
    EXPECT_FALSE(s.emitsLight());
    s.lights[0].intensity = 3.f;
    EXPECT_TRUE(s.emitsLight());
    s.lights.clear();
    s.environment.color = glm::vec3(0.1f);
    EXPECT_TRUE(s.emitsLight());
    s.environment.intensity = 0.f;
    EXPECT_FALSE(s.emitsLight());
    s.environment = Environment{};
    s.environment.width = s.environment.height = 1;
    s.environment.texels = {glm::vec3(0.f)};
    EXPECT_FALSE(s.emitsLight());  // a black map
    s.environment.texels[0].x = 0.5f;
    EXPECT_TRUE(s.emitsLight());
}

TEST_F(SceneFiles, OrbitDollyAndStrafeCameraPaths) {
    auto s = load(triangleScene());
    const glm::vec3 center = s->bounds().center();
    s->cameraPath = {CameraPathKind::Orbit, 0.5f, 0.25f};
    s->update(0.0);
    const glm::vec3 p0 = s->camera.position();
    const float d0 = glm::length(p0 - center);
    expectNear(p0 - center, glm::vec3(0, 0, d0));  // the default camera sits on +Z of the centre
    s->update(kPi);                                // 0.5 rad/s for pi seconds: a quarter turn about +Y takes +Z to +X
    const glm::vec3 p1 = s->camera.position();
    EXPECT_NEAR(glm::length(p1 - center), d0, 1e-4f);
    expectNear(p1 - center, glm::vec3(d0, 0, 0), 1e-4f);
    expectNear(s->camera.forward(), glm::vec3(-1, 0, 0));  // still looking at the centre
    expectNear(glm::vec3(s->camera.prevWorld[3]), p0);
    // Dolly: along the view direction by amount * distance * sin(speed * t).
    s->cameraPath = {CameraPathKind::Dolly, 1.f, 0.25f};
    s->update(kPi / 2.f);
    EXPECT_NEAR(glm::length(s->camera.position() - center), 0.75f * d0, 1e-4f);
    s->update(3.f * kPi / 2.f);
    EXPECT_NEAR(glm::length(s->camera.position() - center), 1.25f * d0, 1e-4f);
    // Strafe: along the camera's right axis (+X here) by amount * distance * sin(speed * t); the view direction and
    // the depth of the centre's plane stay as they are.
    s->cameraPath = {CameraPathKind::Strafe, 1.f, 0.25f};
    s->update(kPi / 2.f);
    expectNear(s->camera.position() - center, glm::vec3(0.25f * d0, 0, d0), 1e-4f);
    expectNear(s->camera.forward(), glm::vec3(0, 0, -1));
    s->update(3.f * kPi / 2.f);
    expectNear(s->camera.position() - center, glm::vec3(-0.25f * d0, 0, d0), 1e-4f);
}

TEST_F(SceneFiles, AnimatedCameraIgnoresThePath) {
    Gltf g = triangleScene();
    g.j["cameras"] = json::array({{{"type", "perspective"}, {"perspective", {{"yfov", 0.7}, {"znear", 0.1}}}}});
    const int cam = g.node({{"camera", 0}, {"translation", {0, 0, 5}}});
    g.j["scenes"][0]["nodes"].push_back(cam);
    const int in = g.floats({0, 1}, "SCALAR");
    const int out = g.floats({0, 0, 5, 0, 0, 9}, "VEC3");
    g.j["animations"] = json::array(
        {{{"samplers", json::array({{{"input", in}, {"output", out}}})},
          {"channels", json::array({{{"sampler", 0}, {"target", {{"node", cam}, {"path", "translation"}}}}})}}});
    auto s = load(g);
    s->cameraPath.kind = CameraPathKind::Orbit;
    s->update(0.5);
    expectNear(s->camera.position(), glm::vec3(0, 0, 7));
    expectNear(glm::vec3(s->camera.prevWorld[3]), glm::vec3(0, 0, 5));
}

// ---------------------------------------------------------------------------
// Bad input

TEST_F(SceneFiles, MissingFile) {
    const std::string msg = loadError(mDir / "nope.gltf");
    EXPECT_NE(msg.find("not found"), std::string::npos) << msg;
}

TEST_F(SceneFiles, TruncatedDataUriBuffer) {
    const std::string msg = loadError(write("t.gltf", triangleScene().text(+100)));
    EXPECT_NE(msg.find("buffers[0]"), std::string::npos) << msg;
    EXPECT_NE(msg.find("truncated"), std::string::npos) << msg;
}

TEST_F(SceneFiles, TruncatedBinFile) {
    Gltf g = triangleScene();
    json d = g.j;
    d["buffers"] = json::array({{{"byteLength", g.bin.size()}, {"uri", "tri.bin"}}});
    write("tri.bin", std::vector<uint8_t>(g.bin.begin(), g.bin.begin() + 20));
    const std::string msg = loadError(write("t.gltf", d.dump()));
    EXPECT_NE(msg.find("buffers[0]"), std::string::npos) << msg;
    EXPECT_NE(msg.find("truncated"), std::string::npos) << msg;
}

TEST_F(SceneFiles, TruncatedGlb) {
    std::vector<uint8_t> glb = triangleScene().glb();
    glb.resize(glb.size() - 8);
    const std::string msg = loadError(write("t.glb", glb));
    EXPECT_NE(msg.find("truncated"), std::string::npos) << msg;
}

TEST_F(SceneFiles, AccessorRunsPastItsBufferView) {
    Gltf g = triangleScene();
    g.j["accessors"][0]["count"] = 30;
    const std::string msg = loadError(write("t.gltf", g.text()));
    EXPECT_NE(msg.find("meshes[0] 'Tri'/primitives[0]/POSITION"), std::string::npos) << msg;
    EXPECT_NE(msg.find("accessors[0]"), std::string::npos) << msg;
}

TEST_F(SceneFiles, AccessorIndexOutOfRange) {
    Gltf g = triangleScene();
    g.j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 99;
    std::string msg = loadError(write("a.gltf", g.text()));
    EXPECT_NE(msg.find("meshes[0] 'Tri'/primitives[0]/POSITION"), std::string::npos) << msg;
    EXPECT_NE(msg.find("accessor 99"), std::string::npos) << msg;
    // tinygltf itself rejects an index accessor out of range; the message still names the primitive.
    g = triangleScene();
    g.j["meshes"][0]["primitives"][0]["indices"] = 42;
    msg = loadError(write("b.gltf", g.text()));
    EXPECT_NE(msg.find("meshes[0] 'Tri'/primitives[0]/indices"), std::string::npos) << msg;
    EXPECT_NE(msg.find("accessor 42"), std::string::npos) << msg;
}

TEST_F(SceneFiles, IndexValueOutOfRange) {
    Gltf g;
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
    const int idx = g.indices(std::vector<uint16_t>{0, 1, 7});
    g.scene({g.node({{"mesh", g.mesh("Broken", {{"POSITION", pos}}, idx)}})});
    const std::string msg = loadError(write("t.gltf", g.text()));
    EXPECT_NE(msg.find("meshes[0] 'Broken'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("index 7"), std::string::npos) << msg;
}

TEST_F(SceneFiles, NanInPositions) {
    Gltf g;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const int pos = g.floats({0, 0, 0, 1, nan, 0, 0, 1, 0}, "VEC3");
    g.scene({g.node({{"mesh", g.mesh("Spiky", {{"POSITION", pos}})}})});
    const std::string msg = loadError(write("t.gltf", g.text()));
    EXPECT_NE(msg.find("meshes[0] 'Spiky'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("POSITION"), std::string::npos) << msg;
    EXPECT_NE(msg.find("NaN"), std::string::npos) << msg;
    EXPECT_NE(msg.find("element 1"), std::string::npos) << msg;

    Gltf h = triangleScene();
    const float inf = std::numeric_limits<float>::infinity();
    const int uv = h.floats({0, 0, inf, 0, 0, 1}, "VEC2");
    h.j["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = uv;
    const std::string msg2 = loadError(write("u.gltf", h.text()));
    EXPECT_NE(msg2.find("TEXCOORD_0"), std::string::npos) << msg2;
    EXPECT_NE(msg2.find("infinite"), std::string::npos) << msg2;
}

TEST_F(SceneFiles, DegenerateTrianglesAreDroppedWithAWarning) {
    Gltf g;
    // Triangle 0 is fine, 1 repeats a vertex, 2 is collinear.
    const int pos = g.floats({0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 0, 0}, "VEC3");
    const int idx = g.indices(std::vector<uint8_t>{0, 1, 2, 0, 1, 1, 0, 1, 3});
    g.scene({g.node({{"mesh", g.mesh("Sliver", {{"POSITION", pos}}, idx)}})});
    auto s = load(g);
    EXPECT_EQ(s->triangleCount(), 1u);
    ASSERT_EQ(s->warnings.size(), 1u);
    EXPECT_NE(s->warnings[0].find("'Sliver'"), std::string::npos) << s->warnings[0];
    EXPECT_NE(s->warnings[0].find("2 degenerate"), std::string::npos) << s->warnings[0];
}

TEST_F(SceneFiles, MissingTextureImageIsAnErrorUnlessAllowed) {
    Gltf g = triangleScene();
    g.j["images"] = json::array({{{"uri", "missing.png"}}});
    g.j["textures"] = json::array({{{"source", 0}}});
    g.j["materials"] =
        json::array({{{"name", "Brick"}, {"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    const fs::path file = write("scene.gltf", g.text());
    const std::string msg = loadError(file);
    EXPECT_NE(msg.find("'Brick'/baseColorTexture"), std::string::npos) << msg;
    EXPECT_NE(msg.find("missing.png' does not exist"), std::string::npos) << msg;
    SceneLoadOptions allow;
    allow.allowMissingTextures = true;
    auto s = Scene::load(file, allow);
    EXPECT_EQ(s->triangleCount(), 1u);
    EXPECT_EQ(s->materials[0].baseColorTexture.image, -1);
    EXPECT_TRUE(s->images.empty());
    EXPECT_TRUE(hasWarning(*s, "'Brick'", "missing.png")) << (s->warnings.empty() ? "" : s->warnings[0]);
}

TEST_F(SceneFiles, UndecodableTextureIsAnErrorUnlessAllowed) {
    Gltf g = triangleScene();
    const std::string junk = "this is not an image";
    g.j["images"] = json::array({{{"bufferView", g.view(junk.data(), junk.size())}, {"mimeType", "image/png"}}});
    g.j["textures"] = json::array({{{"source", 0}}});
    g.j["materials"] =
        json::array({{{"name", "Glow"}, {"emissiveTexture", {{"index", 0}}}, {"emissiveFactor", {1, 1, 1}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    const fs::path file = write("scene.gltf", g.text());
    const std::string msg = loadError(file);
    EXPECT_NE(msg.find("'Glow'/emissiveTexture"), std::string::npos) << msg;
    EXPECT_NE(msg.find("not a PNG or JPEG image (it starts with bytes 74 68 69 73)"), std::string::npos) << msg;
    SceneLoadOptions allow;
    allow.allowMissingTextures = true;
    auto s = Scene::load(file, allow);
    EXPECT_EQ(s->materials[0].emissiveTexture.image, -1);
    EXPECT_TRUE(hasWarning(*s, "'Glow'/emissiveTexture", "decode"));
}

// ---------------------------------------------------------------------------
// Samplers, KHR_texture_transform, KHR_materials_ior and KHR_materials_specular

namespace {

/// Texel (x, y) of the test images: every texel differs.
glm::u8vec4 testTexel(uint32_t x, uint32_t y) {
    return glm::u8vec4(uint8_t(30 + 60 * x), uint8_t(40 + 50 * y), uint8_t(10 * (x + y)), 255);
}

/// A 4 x 4 RGBA PNG of testTexel, as a data URI.
std::string testImageUri() {
    std::vector<uint8_t> rgba;
    for (uint32_t y = 0; y < 4; ++y)
        for (uint32_t x = 0; x < 4; ++x) {
            const glm::u8vec4 t = testTexel(x, y);
            rgba.insert(rgba.end(), {t.r, t.g, t.b, t.a});
        }
    std::vector<uint8_t> png;
    auto append = [](void* ctx, void* data, int size) {
        auto* out = static_cast<std::vector<uint8_t>*>(ctx);
        out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
    };
    EXPECT_NE(stbi_write_png_to_func(append, &png, 4, 4, 4, rgba.data(), 16), 0);
    return "data:image/png;base64," + base64(png);
}

/// testTexel(x, y) as a slot samples it: sRGB-decoded (colour slots) or not.
glm::vec4 decodedTexel(uint32_t x, uint32_t y, bool srgb) {
    const glm::vec4 c = glm::vec4(testTexel(x, y)) / 255.f;
    return srgb ? glm::vec4(srgbToLinear(c.r), srgbToLinear(c.g), srgbToLinear(c.b), c.a) : c;
}

/// A base colour texture reference with a KHR_texture_transform.
json transformedTexture(int index, json transform) {
    return {{"index", index}, {"extensions", {{"KHR_texture_transform", std::move(transform)}}}};
}

}  // namespace

TEST_F(SceneFiles, SamplersSetWrapModesAndFilter) {
    Gltf g = triangleScene();
    g.j["images"] = json::array({{{"uri", testImageUri()}}});
    g.j["samplers"] = json::array({
        {{"wrapS", 33071}, {"wrapT", 33648}, {"magFilter", 9728}, {"minFilter", 9987}},  // clamp, mirrored, nearest
        {{"minFilter", 9986}},                       // NEAREST_MIPMAP_LINEAR and no magFilter: nearest
        {{"magFilter", 9729}, {"minFilter", 9728}},  // magFilter decides: bilinear
        {{"wrapS", 12345}},                          // unknown: repeat, with a warning
    });
    g.j["textures"] = json::array({{{"source", 0}, {"sampler", 0}},
                                   {{"source", 0}, {"sampler", 1}},
                                   {{"source", 0}, {"sampler", 2}},
                                   {{"source", 0}, {"sampler", 3}},
                                   {{"source", 0}},
                                   {{"source", 0}, {"sampler", 9}}});
    for (int t = 0; t < 6; ++t)
        g.j["materials"].push_back(
            {{"name", "M" + std::to_string(t)}, {"pbrMetallicRoughness", {{"baseColorTexture", {{"index", t}}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    auto s = load(g);
    const SceneView& view = s->view();
    auto tex = [&](size_t m) { return view.materials[m].baseColorTexture; };
    using W = TextureWrap;
    const std::tuple<W, W, uint32_t> expected[] = {{W::ClampToEdge, W::MirroredRepeat, 1u},
                                                   {W::Repeat, W::Repeat, 1u},
                                                   {W::Repeat, W::Repeat, 0u},
                                                   {W::Repeat, W::Repeat, 0u},
                                                   {W::Repeat, W::Repeat, 0u},
                                                   {W::Repeat, W::Repeat, 0u}};
    for (size_t m = 0; m < 6; ++m) {
        SCOPED_TRACE("material " + std::to_string(m));
        EXPECT_EQ(tex(m).image, 0);
        EXPECT_EQ(tex(m).wrapS, std::get<0>(expected[m]));
        EXPECT_EQ(tex(m).wrapT, std::get<1>(expected[m]));
        EXPECT_EQ(tex(m).nearest, std::get<2>(expected[m]));
        EXPECT_EQ(tex(m).transform, glm::mat3x2(1.f));
        EXPECT_EQ(s->materials[m].baseColorTexture.wrapS, tex(m).wrapS);  // the view carries the scene's
    }
    EXPECT_EQ(s->warnings.size(), 2u);
    EXPECT_TRUE(hasWarning(*s, "'M3'/baseColorTexture: samplers[3]", "wrapS 12345"));
    EXPECT_TRUE(hasWarning(*s, "'M5'/baseColorTexture", "sampler 9 does not exist"));

    // Sampling honours them. Nearest, clamped along u: outside [0, 1] the edge column; mirrored along v.
    auto sample = [&](size_t m, float u, float v) { return sampleTexture(view, tex(m), {u, v}, true); };
    EXPECT_EQ(sample(0, -0.3f, 0.3f), decodedTexel(0, 1, true));
    EXPECT_EQ(sample(0, 1.7f, 0.3f), decodedTexel(3, 1, true));
    EXPECT_EQ(sample(0, 0.6f, 1.3f), decodedTexel(2, 2, true));  // row 5 reflects to row 2
    EXPECT_EQ(sample(0, 0.6f, 1.3f), sample(0, 0.6f, 0.7f));
    EXPECT_EQ(sample(1, 1.6f, -0.3f), decodedTexel(2, 2, true));  // nearest, repeat
    // Bilinear between texel centres: (u, v) = (0.25, 0.125) is halfway between texels (0, 0) and (1, 0).
    EXPECT_EQ(sample(2, 0.25f, 0.125f), 0.5f * decodedTexel(0, 0, true) + 0.5f * decodedTexel(1, 0, true));
}

TEST_F(SceneFiles, TextureTransformMovesTexels) {
    Gltf g = triangleScene();
    g.j["extensionsUsed"] = {"KHR_texture_transform"};
    g.j["extensionsRequired"] = {"KHR_texture_transform"};
    g.j["images"] = json::array({{{"uri", testImageUri()}}});
    g.j["samplers"] = json::array({{{"magFilter", 9728}}});
    g.j["textures"] = json::array({{{"source", 0}, {"sampler", 0}}});
    const float halfPi = kPi / 2.f;
    auto baseColor = [&](const char* name, json transform) {
        g.j["materials"].push_back(
            {{"name", name}, {"pbrMetallicRoughness", {{"baseColorTexture", transformedTexture(0, transform)}}}});
    };
    // The extension's example: the lower left quadrant of the image, turned.
    baseColor("Quadrant", {{"offset", {0, 1}}, {"rotation", halfPi}, {"scale", {0.5, 0.5}}});
    baseColor("Offset", {{"offset", {0.25, 0.5}}});
    baseColor("Scale", {{"scale", {2, 0.5}}});
    baseColor("Rotation", {{"rotation", halfPi}});
    baseColor("OtherSet", {{"texCoord", 1}});
    // Every slot of a material with its own offset (the triangle has no TEXCOORD_0: uv is (0, 0) everywhere, so
    // each slot reads the texel under its offset).
    g.j["materials"].push_back({{"name", "Slots"},
                                {"pbrMetallicRoughness",
                                 {{"baseColorTexture", transformedTexture(0, {{"offset", {0.375, 0.125}}})},
                                  {"metallicRoughnessTexture", transformedTexture(0, {{"offset", {0.625, 0.125}}})}}},
                                {"normalTexture", transformedTexture(0, {{"offset", {0.125, 0.875}}})},
                                {"emissiveTexture", transformedTexture(0, {{"offset", {0.875, 0.625}}})},
                                {"emissiveFactor", {1, 1, 1}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 5;
    auto s = load(g);
    ASSERT_EQ(s->warnings.size(), 1u) << s->warnings[0];
    EXPECT_TRUE(hasWarning(*s, "'OtherSet'/baseColorTexture", "TEXCOORD_1"));

    const SceneView& view = s->view();
    auto tex = [&](size_t m) { return view.materials[m].baseColorTexture; };
    auto near = [](glm::vec2 a, glm::vec2 b) { return glm::all(glm::lessThan(glm::abs(a - b), glm::vec2(1e-6f))); };
    // The quadrant's corners.
    EXPECT_TRUE(near(transformUv(tex(0), {0.f, 0.f}), {0.f, 1.f}));
    EXPECT_TRUE(near(transformUv(tex(0), {1.f, 0.f}), {0.f, 0.5f}));
    EXPECT_TRUE(near(transformUv(tex(0), {0.f, 1.f}), {0.5f, 1.f}));
    EXPECT_TRUE(near(transformUv(tex(0), {1.f, 1.f}), {0.5f, 0.5f}));
    // Known texels at known uvs (nearest, inside texels).
    auto sample = [&](size_t m, float u, float v) { return sampleTexture(view, tex(m), {u, v}, true); };
    EXPECT_EQ(sample(0, 0.1f, 0.2f), decodedTexel(0, 3, true));  // (0.1, 0.95)
    EXPECT_EQ(sample(0, 0.7f, 0.3f), decodedTexel(0, 2, true));  // (0.15, 0.65)
    EXPECT_EQ(sample(0, 0.3f, 0.9f), decodedTexel(1, 3, true));  // (0.45, 0.85)
    EXPECT_EQ(sample(1, 0.1f, 0.1f), decodedTexel(1, 2, true));  // (0.35, 0.6)
    EXPECT_EQ(sample(2, 0.3f, 0.9f), decodedTexel(2, 1, true));  // (0.6, 0.45)
    EXPECT_EQ(sample(3, 0.3f, 0.6f), decodedTexel(2, 2, true));  // (0.6, -0.3), repeated to (0.6, 0.7)
    EXPECT_EQ(tex(4).transform, glm::mat3x2(1.f));               // texCoord only: no transform

    // evalSurface reads every slot through its own transform.
    const MaterialData& slots = view.materials[5];
    EXPECT_EQ(slots.normalTexture.transform[2], glm::vec2(0.125f, 0.875f));
    const SurfaceHit hit = evalSurface(view, 0, 0, 0.2f, 0.3f, glm::vec3(0.f, 0.f, -1.f));
    EXPECT_EQ(hit.baseColor, glm::vec3(decodedTexel(1, 0, true)));
    EXPECT_EQ(hit.roughness, decodedTexel(2, 0, false).g);
    EXPECT_EQ(hit.metallic, decodedTexel(2, 0, false).b);
    EXPECT_EQ(hit.emission, glm::vec3(decodedTexel(3, 2, true)));

    // An infinite transform is bad input.
    g.j["materials"][1]["pbrMetallicRoughness"]["baseColorTexture"] = transformedTexture(0, {{"offset", {1e39, 0}}});
    const std::string msg = loadError(write("inf.gltf", g.text()));
    EXPECT_NE(msg.find("'Offset'/baseColorTexture/extensions/KHR_texture_transform"), std::string::npos) << msg;
}

TEST_F(SceneFiles, IorAndSpecularFactorsAreLoaded) {
    Gltf g = triangleScene();
    g.j["extensionsUsed"] = {"KHR_materials_ior", "KHR_materials_specular"};
    auto material = [&](const char* name, json extensions) {
        json m = {{"name", name}};
        if (!extensions.empty()) m["extensions"] = std::move(extensions);
        g.j["materials"].push_back(std::move(m));
    };
    material("Water", {{"KHR_materials_ior", {{"ior", 1.33}}},
                       {"KHR_materials_specular", {{"specularFactor", 0.5}, {"specularColorFactor", {0.2, 1.5, 0}}}}});
    material("Plain", json::object());
    material("SpecGloss", {{"KHR_materials_ior", {{"ior", 0}}}});  // 0: the extension's "Fresnel term 1"
    material("Odd",
             {{"KHR_materials_ior", {{"ior", 0.5}}},
              {"KHR_materials_specular",
               {{"specularFactor", 1.5}, {"specularColorFactor", {-1, 0.5, 2}}, {"specularTexture", {{"index", 0}}}}}});
    g.j["meshes"][0]["primitives"][0]["material"] = 0;
    auto s = load(g);
    struct Expected {
        float ior, specular;
        glm::vec3 color;
    };
    const Expected expected[] = {{1.33f, 0.5f, {0.2f, 1.5f, 0.f}},
                                 {1.5f, 1.f, glm::vec3(1.f)},
                                 {0.f, 1.f, glm::vec3(1.f)},
                                 {1.f, 1.f, {0.f, 0.5f, 2.f}}};
    for (size_t m = 0; m < 4; ++m) {
        SCOPED_TRACE(s->materials[m].name);
        EXPECT_EQ(s->materials[m].ior, expected[m].ior);
        EXPECT_EQ(s->materials[m].specularFactor, expected[m].specular);
        EXPECT_EQ(s->materials[m].specularColorFactor, expected[m].color);
        const MaterialData& d = s->view().materials[m];
        EXPECT_EQ(d.ior, expected[m].ior);
        EXPECT_EQ(d.specularFactor, expected[m].specular);
        EXPECT_EQ(d.specularColorFactor, expected[m].color);
    }
    // The odd one's four problems, and nothing else (the extensions themselves are loaded, not ignored).
    EXPECT_EQ(s->warnings.size(), 4u);
    EXPECT_TRUE(hasWarning(*s, "'Odd'", "ior 0.5"));
    EXPECT_TRUE(hasWarning(*s, "'Odd'", "specularFactor outside [0, 1]"));
    EXPECT_TRUE(hasWarning(*s, "'Odd'", "negative specularColorFactor"));
    EXPECT_TRUE(hasWarning(*s, "'Odd'", "specularTexture is not supported"));

    g.j["materials"][0]["extensions"]["KHR_materials_ior"]["ior"] = 1e39;  // infinite as a float
    const std::string msg = loadError(write("inf.gltf", g.text()));
    EXPECT_NE(msg.find("'Water'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("NaN or infinite"), std::string::npos) << msg;
}

TEST_F(SceneFiles, UnsupportedRequiredExtension) {
    Gltf g = triangleScene();
    g.j["extensionsUsed"] = {"KHR_draco_mesh_compression", "KHR_lights_punctual"};
    g.j["extensionsRequired"] = {"KHR_lights_punctual", "KHR_draco_mesh_compression"};
    const std::string msg = loadError(write("t.gltf", g.text()));
    EXPECT_NE(msg.find("KHR_draco_mesh_compression"), std::string::npos) << msg;
    EXPECT_NE(msg.find("extensionsRequired"), std::string::npos) << msg;
}

TEST_F(SceneFiles, EmptyScene) {
    Gltf g;
    g.scene({g.node({{"name", "Empty"}})});
    std::string msg = loadError(write("a.gltf", g.text()));
    EXPECT_NE(msg.find("scene has no triangles"), std::string::npos) << msg;
    g.j["scenes"][0]["nodes"] = json::array();
    msg = loadError(write("b.gltf", g.text()));
    EXPECT_NE(msg.find("scene has no triangles"), std::string::npos) << msg;
    // Every primitive degenerate: warned about, and then nothing is left.
    Gltf d;
    const int pos = d.floats({0, 0, 0, 1, 0, 0, 2, 0, 0}, "VEC3");
    d.scene({d.node({{"mesh", d.mesh("Line", {{"POSITION", pos}})}})});
    msg = loadError(write("c.gltf", d.text()));
    EXPECT_NE(msg.find("scene has no triangles"), std::string::npos) << msg;
}

TEST_F(SceneFiles, PrimitiveWithoutVerticesIsSkipped) {
    Gltf g = triangleScene();
    const int empty = g.accessor(0, kFloat, 0, "VEC3");
    g.j["meshes"][0]["primitives"].push_back({{"attributes", {{"POSITION", empty}}}});
    auto s = load(g);
    EXPECT_EQ(s->meshes.size(), 1u);
    EXPECT_TRUE(hasWarning(*s, "'Tri'/primitives[1]", "no vertices"));
}

TEST_F(SceneFiles, NotGltf) {
    std::string msg = loadError(write("junk.gltf", std::string("{ this is not json")));
    EXPECT_NE(msg.find("JSON"), std::string::npos) << msg;
    msg = loadError(write("junk.glb", std::string("not a glb at all")));
    EXPECT_NE(msg.find("magic"), std::string::npos) << msg;
}

TEST_F(SceneFiles, NonTriangleModesAreSkipped) {
    Gltf g = triangleScene();
    json lines = {{"attributes", {{"POSITION", 0}}}, {"mode", 1}};
    g.j["meshes"][0]["primitives"].push_back(lines);
    auto s = load(g);
    EXPECT_EQ(s->meshes.size(), 1u);
    EXPECT_TRUE(hasWarning(*s, "'Tri'/primitives[1]", "lines"));
}

// ---------------------------------------------------------------------------
// Environment maps

TEST_F(SceneFiles, EnvironmentMap) {
    auto s = load(triangleScene());
    const float rgb[6] = {1.f, 2.f, 4.f, 0.5f, 0.25f, 0.125f};
    const fs::path hdr = mDir / "sky.hdr";
    ASSERT_NE(stbi_write_hdr(hdr.c_str(), 2, 1, 3, rgb), 0);
    s->loadEnvironmentMap(hdr);
    EXPECT_FALSE(s->environment.isConstant());
    ASSERT_EQ(s->environment.width, 2u);
    ASSERT_EQ(s->environment.height, 1u);
    expectNear(s->environment.texels[0], glm::vec3(1, 2, 4), 0.02f);
    expectNear(s->environment.texels[1], glm::vec3(0.5f, 0.25f, 0.125f), 0.01f);

    try {
        s->loadEnvironmentMap(mDir / "none.hdr");
        ADD_FAILURE() << "no error for a missing map";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(std::string(e.what()).find("none.hdr"), std::string::npos) << e.what();
    }
    const uint8_t px[4] = {1, 2, 3, 255};
    const fs::path png = mDir / "ldr.png";
    ASSERT_NE(stbi_write_png(png.c_str(), 1, 1, 4, px, 4), 0);
    EXPECT_THROW(s->loadEnvironmentMap(png), Error);
}

// ---------------------------------------------------------------------------
// loom scene info

TEST_F(SceneFiles, SceneInfoCommand) {
    auto run = [](const std::string& args, std::string& out) {
        const std::string cmd = std::string(LOOM_TEST_LOOM_EXE) + " " + args + " 2>&1";
        FILE* p = popen(cmd.c_str(), "r");
        if (!p) return -1;
        std::array<char, 4096> buf;
        out.clear();
        while (size_t n = fread(buf.data(), 1, buf.size(), p)) out.append(buf.data(), n);
        const int status = pclose(p);
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    };
    std::string out;
    const fs::path file = write("tri.gltf", hierarchyScene(true).text());
    EXPECT_EQ(run("scene info " + file.string(), out), 0) << out;
    EXPECT_NE(out.find("triangles:          1 in instances"), std::string::npos) << out;
    EXPECT_NE(out.find("instances:          1\n"), std::string::npos) << out;
    EXPECT_NE(out.find("length 1.000 s"), std::string::npos) << out;
    EXPECT_EQ(run("scene info " + (mDir / "missing.gltf").string(), out), 2) << out;
    EXPECT_NE(out.find("not found"), std::string::npos) << out;
    EXPECT_EQ(run("scene info " + file.string() + " --camera-path spin", out), 2) << out;
    EXPECT_EQ(run("scene info " + file.string() + " --camera-path orbit:0.5 --time 1", out), 0) << out;
}

}  // namespace
