// SceneFeatures: each flag follows the content that needs it, on scenes built in code (one content change at a time
// against a plain scene) and on the shipped scenes; static scenes keep their ray-tracing instances between updates.
#include <gtest/gtest.h>

#include <glm/glm.hpp>
#include <memory>
#include <string>

#include "TestUtil.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

/// A plain scene: one quad, one opaque untextured dielectric, no light, black environment, nothing animated.
/// `edit` changes it before finalize().
template <class Edit>
std::shared_ptr<Scene> builtScene(Edit edit) {
    auto s = std::make_shared<Scene>();
    Mesh m;
    m.name = "quad";
    for (glm::vec3 p : {glm::vec3(0.f), glm::vec3(1.f, 0.f, 0.f), glm::vec3(1.f, 1.f, 0.f), glm::vec3(0.f, 1.f, 0.f)}) {
        m.positions.push_back(p);
        m.normals.push_back(glm::vec3(0.f, 0.f, 1.f));
        m.tangents.push_back(glm::vec4(1.f, 0.f, 0.f, 1.f));
        m.uvs.push_back(glm::vec2(p));
    }
    m.indices = {0, 1, 2, 0, 2, 3};
    s->meshes.push_back(m);
    Material mat;
    mat.metallicFactor = 0.f;
    s->materials.push_back(mat);
    Node n;
    n.name = "quad";
    n.meshes = {0};
    s->nodes.push_back(n);
    s->roots = {0};
    SceneImage img;
    img.name = "white";
    img.width = img.height = 1;
    img.texels = {glm::u8vec4(255)};
    s->images.push_back(img);
    edit(*s);
    s->finalize();
    return s;
}

std::shared_ptr<Scene> plainScene() {
    return builtScene([](Scene&) {});
}

/// An animation of one channel with two linear keys (0 s: a, 1 s: b).
Animation animationOf(AnimPath path, int node, int target, glm::vec4 a, glm::vec4 b) {
    Animation anim;
    anim.name = "anim";
    AnimationSampler sampler;
    sampler.times = {0.f, 1.f};
    sampler.values = {a, b};
    anim.samplers.push_back(sampler);
    AnimationChannel ch;
    ch.sampler = 0;
    ch.node = node;
    ch.path = path;
    ch.target = target;
    anim.channels.push_back(ch);
    return anim;
}

}  // namespace

TEST(SceneFeatures, APlainSceneNeedsNothing) {
    const SceneFeatures f = plainScene()->features();
    EXPECT_FALSE(f.textures);
    EXPECT_FALSE(f.normalMaps);
    EXPECT_FALSE(f.alphaTested);
    EXPECT_FALSE(f.emissiveTriangles);
    EXPECT_FALSE(f.punctualLights);
    EXPECT_EQ(f.environment, EnvironmentKind::None);
    EXPECT_FALSE(f.diffuseOnly);  // the default dielectric reflects 4 % specularly
    EXPECT_FALSE(f.animated());
}

TEST(SceneFeatures, EachTextureSlotCountsAndOnlyNormalMapsAreNormalMaps) {
    const auto slots = {&Material::baseColorTexture, &Material::metallicRoughnessTexture, &Material::normalTexture,
                        &Material::emissiveTexture};
    for (TextureRef Material::*slot : slots) {
        const SceneFeatures f = builtScene([&](Scene& s) { (s.materials[0].*slot).image = 0; })->features();
        EXPECT_TRUE(f.textures);
        EXPECT_EQ(f.normalMaps, slot == &Material::normalTexture);
    }
}

TEST(SceneFeatures, MaskAndBlendAreAlphaTestedOpaqueIsNot) {
    for (AlphaMode mode : {AlphaMode::Opaque, AlphaMode::Mask, AlphaMode::Blend}) {
        const SceneFeatures f = builtScene([&](Scene& s) { s.materials[0].alphaMode = mode; })->features();
        EXPECT_EQ(f.alphaTested, mode != AlphaMode::Opaque);
    }
}

TEST(SceneFeatures, EmissiveTrianglesIncludeEmissionThatOnlyAnAnimationTurnsOn) {
    EXPECT_TRUE(
        builtScene([](Scene& s) { s.materials[0].emissiveFactor = glm::vec3(1.f); })->features().emissiveTriangles);
    // Black at time 0, lit from the animation's strength later: conservative over the animation.
    const auto animated = builtScene([](Scene& s) {
        s.materials[0].emissiveColor = glm::vec3(1.f);
        s.materials[0].emissiveStrength = 0.f;
        s.animations.push_back(animationOf(AnimPath::EmissiveStrength, -1, 0, glm::vec4(0.f), glm::vec4(5.f)));
    });
    EXPECT_FALSE(animated->materials[0].isEmissive());
    EXPECT_TRUE(animated->features().emissiveTriangles);
    EXPECT_TRUE(animated->features().animatedLights);
    EXPECT_FALSE(animated->features().animatedNodes);
}

TEST(SceneFeatures, PunctualLights) {
    const auto s = builtScene([](Scene& s) {
        Light l;
        l.name = "point";
        l.node = 0;
        s.lights.push_back(l);
        s.nodes[0].light = 0;
    });
    EXPECT_TRUE(s->features().punctualLights);
}

TEST(SceneFeatures, EnvironmentKindFollowsTheEnvironmentAfterLoading) {
    auto s = plainScene();
    EXPECT_EQ(s->features().environment, EnvironmentKind::None);
    // Tools set the environment after loading: update() sees it.
    s->environment.color = glm::vec3(0.2f, 0.3f, 0.4f);
    s->update(0.0);
    EXPECT_EQ(s->features().environment, EnvironmentKind::Constant);
    s->environment.intensity = 0.f;
    s->update(0.0);
    EXPECT_EQ(s->features().environment, EnvironmentKind::None);
    s->environment.intensity = 1.f;
    s->environment.width = s->environment.height = 1;
    s->environment.texels = {glm::vec3(1.f)};
    s->update(0.0);
    EXPECT_EQ(s->features().environment, EnvironmentKind::Map);
}

TEST(SceneFeatures, DiffuseOnlyNeedsNoMetalAndNoDielectricSpecular) {
    const auto lambertian = [](float metallic, float specular) {
        return builtScene([&](Scene& s) {
                   s.materials[0].metallicFactor = metallic;
                   s.materials[0].specularFactor = specular;
                   // A metallic texture cannot make a material with factor 0 metallic: it stays diffuse.
                   s.materials[0].metallicRoughnessTexture.image = 0;
               })
            ->features()
            .diffuseOnly;
    };
    EXPECT_TRUE(lambertian(0.f, 0.f));
    EXPECT_FALSE(lambertian(0.f, 0.5f));
    EXPECT_FALSE(lambertian(0.25f, 0.f));
    // One specular material anywhere is enough.
    const auto mixed = builtScene([](Scene& s) {
        s.materials[0].specularFactor = 0.f;
        Material glossy;
        glossy.metallicFactor = 0.f;
        s.materials.push_back(glossy);
    });
    EXPECT_FALSE(mixed->features().diffuseOnly);
}

TEST(SceneFeatures, NodeAnimationAndCameraPaths) {
    const auto moving = builtScene([](Scene& s) {
        s.animations.push_back(
            animationOf(AnimPath::Translation, 0, -1, glm::vec4(0.f), glm::vec4(1.f, 0.f, 0.f, 0.f)));
    });
    EXPECT_TRUE(moving->features().animatedNodes);
    EXPECT_FALSE(moving->features().animatedLights);
    EXPECT_TRUE(moving->features().animated());
    auto orbiting = plainScene();
    EXPECT_FALSE(orbiting->features().animatedCamera);
    orbiting->cameraPath.kind = CameraPathKind::Orbit;
    orbiting->update(0.0);
    EXPECT_TRUE(orbiting->features().animatedCamera);
    EXPECT_FALSE(orbiting->features().animatedNodes);
}

TEST(SceneFeatures, ShippedScenes) {
    const SceneFeatures box = Scene::load(test::dataScene("cornell_box.gltf"))->features();
    EXPECT_FALSE(box.textures);
    EXPECT_FALSE(box.alphaTested);
    EXPECT_TRUE(box.emissiveTriangles);
    EXPECT_FALSE(box.punctualLights);
    EXPECT_FALSE(box.animated());
    const SceneFeatures materials = Scene::load(test::dataScene("materials.gltf"))->features();
    EXPECT_TRUE(materials.textures);
    EXPECT_TRUE(materials.normalMaps);
    EXPECT_TRUE(materials.punctualLights);
    EXPECT_FALSE(materials.diffuseOnly);  // gold spheres
    const SceneFeatures dynamic = Scene::load(test::dataScene("cornell_dynamic.gltf"))->features();
    EXPECT_TRUE(dynamic.animatedNodes);
    EXPECT_TRUE(dynamic.animatedCamera);
    EXPECT_FALSE(dynamic.animatedLights);
    const SceneFeatures lightstep = Scene::load(test::dataScene("cornell_lightstep.gltf"))->features();
    EXPECT_TRUE(lightstep.animatedLights);
    EXPECT_FALSE(lightstep.animatedNodes);
    const SceneFeatures sky = Scene::load(test::dataScene("sky_sphere.gltf"))->features();
    EXPECT_FALSE(sky.emissiveTriangles);
    EXPECT_TRUE(sky.punctualLights);
}

// A static scene commits its ray-tracing instances once: updates leave the geometry version alone, a moved node
// advances it (and the move is seen by rays).
TEST(SceneFeatures, StaticUpdatesDoNotRebuildMovedOnesDo) {
    auto s = plainScene();
    s->update(0.0);
    const uint64_t v = s->geometryVersion();
    for (int f = 1; f < 4; ++f) s->update(f / 60.0);
    EXPECT_EQ(s->geometryVersion(), v);
    s->nodes[0].translation = glm::vec3(0.f, 0.f, -1.f);
    s->update(4 / 60.0);
    EXPECT_GT(s->geometryVersion(), v);
    EXPECT_EQ(s->view().instances[0].world[3].z, -1.f);
    EXPECT_EQ(s->view().instances[0].prevWorld[3].z, 0.f);
    const uint64_t moved = s->geometryVersion();
    // Still now, but last frame's transform differs from this one's: one more rebuild, then none.
    s->update(5 / 60.0);
    EXPECT_GT(s->geometryVersion(), moved);
    EXPECT_EQ(s->view().instances[0].prevWorld[3].z, -1.f);
    const uint64_t still = s->geometryVersion();
    s->update(6 / 60.0);
    EXPECT_EQ(s->geometryVersion(), still);
}
