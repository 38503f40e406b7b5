// Animated light (KHR_animation_pointer): material emission and punctual lights follow their keys exactly (STEP,
// LINEAR, CUBICSPLINE), Scene reports light steps and per-frame lighting changes, and bad pointers or values are one
// clear error (exit code 2 from the CLI). The scenes are cornell_box.gltf with animations added in the test, and the
// shipped cornell_lightstep.gltf.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/Scene.h"

using namespace loom;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr int kFloat = 5126;
constexpr uint32_t kLightMaterial = 3;  // CeilingLightEmitter in the Cornell scenes
constexpr float kFullStrength = 17.f;   // its KHR_materials_emissive_strength
const char* kStrengthPointer = "/materials/3/extensions/KHR_materials_emissive_strength/emissiveStrength";

/// cornell_box.gltf with animations added. Their keys live in a second buffer, a .bin file written beside the copy.
class LightAnimationFile {
public:
    LightAnimationFile() {
        std::ifstream in(test::dataScene("cornell_box.gltf"));
        doc = json::parse(in);
        doc["extensionsUsed"].push_back("KHR_animation_pointer");
    }

    /// An accessor of `values` (SCALAR, VEC3 or VEC4 floats) in the second buffer.
    int floats(const std::vector<float>& values, const std::string& type) {
        const size_t comps = type == "SCALAR" ? 1 : type == "VEC3" ? 3 : 4;
        const size_t offset = bin.size();
        bin.resize(offset + values.size() * 4);
        std::memcpy(bin.data() + offset, values.data(), values.size() * 4);
        doc["bufferViews"].push_back({{"buffer", 1}, {"byteOffset", offset}, {"byteLength", values.size() * 4}});
        doc["accessors"].push_back({{"bufferView", doc["bufferViews"].size() - 1},
                                    {"componentType", kFloat},
                                    {"count", values.size() / comps},
                                    {"type", type}});
        return int(doc["accessors"].size() - 1);
    }

    /// One animation with one KHR_animation_pointer channel per entry: (pointer, times, values, type, interpolation).
    struct Channel {
        std::string pointer;
        std::vector<float> times, values;
        std::string type = "SCALAR";
        std::string interpolation = "STEP";
    };
    void animate(const std::vector<Channel>& channels) {
        json anim = {{"name", "Light"}, {"samplers", json::array()}, {"channels", json::array()}};
        for (const Channel& c : channels) {
            anim["samplers"].push_back({{"input", floats(c.times, "SCALAR")},
                                        {"output", floats(c.values, c.type)},
                                        {"interpolation", c.interpolation}});
            anim["channels"].push_back(
                {{"sampler", anim["samplers"].size() - 1},
                 {"target",
                  {{"path", "pointer"}, {"extensions", {{"KHR_animation_pointer", {{"pointer", c.pointer}}}}}}}});
        }
        doc["animations"].push_back(std::move(anim));
    }

    /// A KHR_lights_punctual point light (intensity 10, white) on a new root node; returns the light index.
    int addPointLight(float x) {
        doc["extensionsUsed"].push_back("KHR_lights_punctual");
        json& lights = doc["extensions"]["KHR_lights_punctual"]["lights"];
        lights.push_back({{"type", "point"}, {"intensity", 10.0}, {"color", {1.0, 1.0, 1.0}}});
        placeLight(int(lights.size() - 1), x);
        return int(lights.size() - 1);
    }
    void placeLight(int light, float x) {
        doc["nodes"].push_back(
            {{"translation", {x, 1.5, 0.0}}, {"extensions", {{"KHR_lights_punctual", {{"light", light}}}}}});
        doc["scenes"][0]["nodes"].push_back(doc["nodes"].size() - 1);
    }

    fs::path write(const fs::path& dir) const {
        json d = doc;
        d["buffers"].push_back({{"byteLength", bin.size()}, {"uri", "light.bin"}});
        std::ofstream(dir / "light.bin", std::ios::binary)
            .write(reinterpret_cast<const char*>(bin.data()), std::streamsize(bin.size()));
        std::ofstream(dir / "light.gltf") << d.dump(1);
        return dir / "light.gltf";
    }

    json doc;
    std::vector<uint8_t> bin;
};

class LightAnimation : public ::testing::Test {
protected:
    void SetUp() override {
        mDir = fs::temp_directory_path() / ("loom_light_" + std::to_string(::getpid()) + "_" +
                                            ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(mDir);
        fs::create_directories(mDir);
    }
    void TearDown() override { fs::remove_all(mDir); }

    std::shared_ptr<Scene> load(const LightAnimationFile& f) { return Scene::load(f.write(mDir)); }
    /// The error loading `f` raises (a test failure when it loads).
    std::string loadError(const LightAnimationFile& f) {
        const Error e = test::expectError([&] { load(f); });
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        return e.what();
    }

    fs::path mDir;
};

/// The emission cornell_box.gltf's light has with strength `strength` (the loader's own product).
glm::vec3 lightEmission(const Scene& s, float strength) {
    return s.materials[kLightMaterial].emissiveColor * strength;
}

// ---------------------------------------------------------------------------------------------------------------
// The shipped scene

TEST(LightStepScene, EmissionIsTheKeyValueExactlyBeforeAndAfterEveryStep) {
    auto s = Scene::load(test::dataScene("cornell_lightstep.gltf"));
    auto box = Scene::load(test::dataScene("cornell_box.gltf"));
    // At rest the scene is cornell_box.gltf, bit for bit.
    ASSERT_EQ(s->materials[kLightMaterial].emissiveFactor, box->materials[kLightMaterial].emissiveFactor);
    EXPECT_TRUE(s->warnings.empty()) << s->warnings.front();
    const std::vector<float> steps = s->lightStepTimes();
    ASSERT_EQ(steps.size(), 4u);
    const glm::vec3 full = box->materials[kLightMaterial].emissiveFactor;
    const glm::vec3 dim = lightEmission(*s, 0.25f * kFullStrength);
    for (size_t k = 0; k < steps.size(); ++k) {
        // At 60 fps each step falls between two frames: frame 20 + 20 k is before it, 21 + 20 k after.
        const double before = double(20 + 20 * k) / 60.0, after = double(21 + 20 * k) / 60.0;
        EXPECT_LT(before, steps[k]);
        EXPECT_GT(after, steps[k]);
        s->update(before);
        EXPECT_EQ(s->materials[kLightMaterial].emissiveFactor, k % 2 == 0 ? full : dim) << "before step " << k;
        EXPECT_EQ(s->view().materials[kLightMaterial].emissiveFactor, s->materials[kLightMaterial].emissiveFactor);
        EXPECT_FALSE(s->lightingChanged());
        s->update(after);
        EXPECT_EQ(s->materials[kLightMaterial].emissiveFactor, k % 2 == 0 ? dim : full) << "after step " << k;
        EXPECT_EQ(s->view().materials[kLightMaterial].emissiveFactor, s->materials[kLightMaterial].emissiveFactor);
        EXPECT_TRUE(s->lightingChanged()) << "step " << k;
        s->update(after);  // the same time again: nothing changed
        EXPECT_FALSE(s->lightingChanged());
    }
    // The light emits at every time, so the scene is never dark.
    EXPECT_TRUE(s->emitsLight());
    EXPECT_TRUE(s->hasMotion());
    EXPECT_FALSE(box->hasMotion());
    EXPECT_TRUE(box->lightStepTimes().empty());
}

TEST(LightStepScene, CutMotionClearsTheChangeAndOtherScenesNeverChangeLight) {
    auto s = Scene::load(test::dataScene("cornell_lightstep.gltf"));
    s->update(0.0);
    s->update(0.5);  // dimmed at 20.5/60 s
    EXPECT_TRUE(s->lightingChanged());
    s->cutMotion();
    EXPECT_FALSE(s->lightingChanged());
    for (const char* name : {"cornell_box.gltf", "cornell_dynamic.gltf", "materials.gltf"}) {
        auto other = Scene::load(test::dataScene(name));
        EXPECT_TRUE(other->lightStepTimes().empty()) << name;
        for (int f = 0; f < 240; f += 7) {
            other->update(f / 60.0);
            EXPECT_FALSE(other->lightingChanged()) << name << " at frame " << f;
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Interpolation and targets

TEST_F(LightAnimation, LinearEmissiveFactorAndStrengthHitTheMidpoint) {
    LightAnimationFile f;
    f.animate({{"/materials/3/emissiveFactor", {0.f, 2.f}, {1.f, 0.f, 0.f, 0.f, 0.f, 1.f}, "VEC3", "LINEAR"},
               {kStrengthPointer, {0.f, 2.f}, {2.f, 6.f}, "SCALAR", "LINEAR"}});
    auto s = load(f);
    s->update(1.0);
    const Material& m = s->materials[kLightMaterial];
    EXPECT_EQ(m.emissiveColor, glm::vec3(0.5f, 0.f, 0.5f));
    EXPECT_EQ(m.emissiveStrength, 4.f);
    EXPECT_EQ(m.emissiveFactor, glm::vec3(2.f, 0.f, 2.f));
    s->update(2.0);
    EXPECT_EQ(s->materials[kLightMaterial].emissiveFactor, glm::vec3(0.f, 0.f, 6.f));
    // Smooth changes are no steps.
    EXPECT_TRUE(s->lightStepTimes().empty());
    EXPECT_TRUE(s->hasMotion());
}

TEST_F(LightAnimation, StrengthAloneKeepsTheFilesEmissiveFactor) {
    LightAnimationFile f;
    f.animate({{kStrengthPointer, {0.f, 1.f}, {17.f, 34.f}, "SCALAR", "STEP"}});
    auto s = load(f);
    auto box = Scene::load(test::dataScene("cornell_box.gltf"));
    EXPECT_EQ(s->materials[kLightMaterial].emissiveFactor, box->materials[kLightMaterial].emissiveFactor);
    s->update(1.0);
    EXPECT_EQ(s->materials[kLightMaterial].emissiveFactor, 2.f * box->materials[kLightMaterial].emissiveFactor);
    // The other materials are untouched.
    for (size_t i = 0; i < s->materials.size(); ++i) {
        if (i != kLightMaterial) {
            EXPECT_EQ(s->materials[i].emissiveFactor, box->materials[i].emissiveFactor);
        }
    }
}

TEST_F(LightAnimation, CubicSplineNeverEmitsNegativeLight) {
    LightAnimationFile f;
    // (in-tangent, value, out-tangent) per key: a steep fall that overshoots below 0 between the keys.
    f.animate({{kStrengthPointer, {0.f, 1.f}, {0.f, 1.f, -20.f, -20.f, 0.f, 0.f}, "SCALAR", "CUBICSPLINE"}});
    auto s = load(f);
    for (int k = 0; k <= 20; ++k) {
        s->update(k / 20.0);
        EXPECT_GE(s->materials[kLightMaterial].emissiveStrength, 0.f) << k;
        EXPECT_TRUE(glm::all(glm::greaterThanEqual(s->materials[kLightMaterial].emissiveFactor, glm::vec3(0.f))));
    }
    s->update(1.0);
    EXPECT_EQ(s->materials[kLightMaterial].emissiveStrength, 0.f);
}

TEST_F(LightAnimation, StepTimesAreValueChangesOfStepKeysAndCoincidentLinearKeys) {
    LightAnimationFile f;
    f.animate({// STEP: a change at 1 and 3; the key at 2 repeats the value before it.
               {kStrengthPointer, {0.f, 1.f, 2.f, 3.f}, {1.f, 2.f, 2.f, 5.f}, "SCALAR", "STEP"},
               // LINEAR: a ramp, then a jump at 1.5 (two keys at the same time), and the jump at 3 again.
               {"/materials/3/emissiveFactor",
                {0.f, 1.5f, 1.5f, 3.f, 3.f},
                {0, 0, 0, 1, 1, 1, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 1, 0, 0},
                "VEC3",
                "LINEAR"}});
    auto s = load(f);
    EXPECT_EQ(s->lightStepTimes(), (std::vector<float>{1.f, 1.5f, 3.f}));
    // After a coincident pair the second key's value holds.
    s->update(1.5);
    EXPECT_EQ(s->materials[kLightMaterial].emissiveColor, glm::vec3(0.5f));
    s->update(1.4999);
    EXPECT_GT(s->materials[kLightMaterial].emissiveColor.x, 0.99f);
}

TEST_F(LightAnimation, PunctualLightIntensityAndColorFollowEveryNodeOfTheLight) {
    LightAnimationFile f;
    const int light = f.addPointLight(-0.5f);
    f.placeLight(light, 0.5f);  // the same light twice
    f.animate({{"/extensions/KHR_lights_punctual/lights/0/intensity", {0.f, 1.f}, {10.f, 40.f}, "SCALAR", "STEP"},
               {"/extensions/KHR_lights_punctual/lights/0/color", {0.f, 2.f}, {1, 1, 1, 0, 1, 0}, "VEC3", "LINEAR"}});
    auto s = load(f);
    ASSERT_EQ(s->lights.size(), 2u);
    s->update(1.0);
    for (const Light& l : s->lights) {
        EXPECT_EQ(l.intensity, 40.f);
        EXPECT_EQ(l.color, glm::vec3(0.5f, 1.f, 0.5f));
    }
    EXPECT_EQ(s->lightStepTimes(), (std::vector<float>{1.f}));
}

TEST_F(LightAnimation, EmitsLightFollowsTheAnimationAndEmissiveTrianglesCoverTheLight) {
    LightAnimationFile f;
    // The only light goes out at 1 s, and the light starts out dark in a second file.
    f.animate({{kStrengthPointer, {0.f, 1.f}, {17.f, 0.f}, "SCALAR", "STEP"}});
    auto s = load(f);
    EXPECT_TRUE(s->emitsLight());
    s->update(1.0);
    EXPECT_FALSE(s->emitsLight());

    LightAnimationFile g;
    g.animate({{kStrengthPointer, {0.f, 1.f}, {0.f, 17.f}, "SCALAR", "STEP"}});
    auto dark = load(g);
    EXPECT_FALSE(dark->emitsLight());
    EXPECT_EQ(dark->emissiveTriangles.size(), 2u);  // the light quad: a light at some time
    dark->update(1.0);
    EXPECT_TRUE(dark->emitsLight());
}

TEST_F(LightAnimation, NodePointersMoveNodesLikePlainChannels) {
    LightAnimationFile f;
    const int node = int(f.doc["nodes"].size() - 1);  // the camera
    f.animate({{"/nodes/" + std::to_string(node) + "/translation", {0.f, 1.f}, {0, 1, 4, 0, 1, 3}, "VEC3", "LINEAR"}});
    auto s = load(f);
    s->update(0.5);
    EXPECT_EQ(s->nodes[size_t(node)].translation, glm::vec3(0.f, 1.f, 3.5f));
    EXPECT_TRUE(s->cameraAnimated());
    EXPECT_TRUE(s->lightStepTimes().empty());
}

// ---------------------------------------------------------------------------------------------------------------
// Unsupported pointers and bad input

TEST_F(LightAnimation, UnsupportedPointerIsOneWarningOrAnErrorWhenRequired) {
    LightAnimationFile f;
    const char* base = "/materials/3/pbrMetallicRoughness/baseColorFactor";
    f.animate({{base, {0.f, 1.f}, {1, 1, 1, 1, 0, 0, 0, 1}, "VEC4", "STEP"},
               {base, {0.f, 2.f}, {1, 1, 1, 1, 0, 0, 0, 1}, "VEC4", "STEP"}});
    auto s = load(f);
    size_t mentions = 0;
    for (const std::string& w : s->warnings) mentions += w.find(base) != std::string::npos;
    EXPECT_EQ(mentions, 1u);
    EXPECT_TRUE(s->animations[0].channels.empty());

    f.doc["extensionsRequired"] = {"KHR_animation_pointer"};
    const std::string msg = loadError(f);
    EXPECT_NE(msg.find(base), std::string::npos) << msg;
    EXPECT_NE(msg.find("requires KHR_animation_pointer"), std::string::npos) << msg;
}

TEST_F(LightAnimation, SupportedPointersLoadWhenTheExtensionIsRequired) {
    LightAnimationFile f;
    f.doc["extensionsRequired"] = {"KHR_animation_pointer"};
    f.animate({{kStrengthPointer, {0.f, 1.f}, {17.f, 4.f}, "SCALAR", "STEP"}});
    auto s = load(f);
    EXPECT_EQ(s->animations[0].channels.size(), 1u);
    for (const std::string& w : s->warnings) EXPECT_EQ(w.find("KHR_animation_pointer"), std::string::npos) << w;
}

TEST_F(LightAnimation, BadPointersAndValuesAreOneClearError) {
    struct Case {
        const char* name;
        LightAnimationFile::Channel channel;
        const char* expected;  // in the message
    };
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const std::vector<Case> cases = {
        {"material out of range", {"/materials/9/emissiveFactor", {0.f}, {1, 1, 1}, "VEC3"}, "materials 9 does not"},
        {"light out of range", {"/extensions/KHR_lights_punctual/lights/0/intensity", {0.f}, {1.f}}, "does not exist"},
        {"index not a number", {"/materials/x/emissiveFactor", {0.f}, {1, 1, 1}, "VEC3"}, "'x' is not an index"},
        {"leading zero", {"/materials/03/emissiveFactor", {0.f}, {1, 1, 1}, "VEC3"}, "'03' is not an index"},
        {"negative strength", {kStrengthPointer, {0.f, 1.f}, {1.f, -2.f}}, "negative value"},
        {"negative colour", {"/materials/3/emissiveFactor", {0.f}, {1, -1, 1}, "VEC3"}, "negative value"},
        {"NaN strength", {kStrengthPointer, {0.f, 1.f}, {1.f, nan}}, "NaN"},
        {"infinite strength", {kStrengthPointer, {0.f, 1.f}, {inf, 1.f}}, "infinite"},
        {"wrong output type", {kStrengthPointer, {0.f}, {1, 1, 1}, "VEC3"}, "SCALAR"},
        {"wrong key count", {kStrengthPointer, {0.f, 1.f}, {1.f, 2.f, 3.f}}, "values for 2 keys"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        LightAnimationFile f;
        f.animate({c.channel});
        const std::string msg = loadError(f);
        EXPECT_NE(msg.find(c.expected), std::string::npos) << msg;
        EXPECT_NE(msg.find("light.gltf"), std::string::npos) << msg;  // names the file
    }
    LightAnimationFile f;
    f.animate({{kStrengthPointer, {0.f}, {1.f}}});
    f.doc["animations"][0]["channels"][0]["target"]["extensions"]["KHR_animation_pointer"].erase("pointer");
    EXPECT_NE(loadError(f).find("pointer is missing"), std::string::npos);
}

TEST_F(LightAnimation, CliSaysOnceAndExitsWith2OnABadValue) {
    LightAnimationFile f;
    f.animate({{kStrengthPointer, {0.f, 1.f}, {1.f, -2.f}}});
    const fs::path file = f.write(mDir);
    const test::CliResult r = test::runLoom(mDir, "scene info " + file.string());
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("negative value"), std::string::npos) << r.output;
    size_t lines = 0;
    for (char ch : r.output) lines += ch == '\n';
    EXPECT_LE(lines, 3u) << r.output;

    const test::CliResult ok = test::runLoom(mDir, "scene info " + test::dataScene("cornell_lightstep.gltf"));
    EXPECT_EQ(ok.code, 0) << ok.output;
    EXPECT_NE(ok.output.find("light steps"), std::string::npos) << ok.output;
}

}  // namespace
