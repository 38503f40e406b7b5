// SVGF keeps the history of every surface point that stays visible while the camera moves: towards the scene
// (dolly), across it (strafe) and around it (orbit). Which points were visible last frame is decided here from the
// geometry alone, not by SVGF's own tests: a pixel's world position (GBuffer.posW), projected through last frame's
// camera, lands on a pixel whose world position last frame was the same point. Of those pixels, fewer than 0.5 % may
// restart their history (historyLength 1). With raw depths compared, a dolly at 4 radians per second (about 1.7 % of
// the camera's distance a frame) restarted about a fifth of them, the surfaces that face the camera.
#include <gtest/gtest.h>

#include <cmath>
#include <glm/glm.hpp>
#include <memory>
#include <string>

#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/Graph.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

const uint32_t kWidth = 160, kHeight = 120;

struct Motion {
    CameraPathKind kind;
    float speed;
    const char* name;
};

/// Counts, over frames 4..15, the pixels visible last frame and those of them whose history restarted.
struct Counts {
    uint64_t visible = 0, restarted = 0;
};

Counts historyUnderMotion(const Motion& m) {
    auto scene = Scene::load(test::dataScene("cornell_box.gltf"));
    scene->cameraPath.kind = m.kind;
    scene->cameraPath.speed = m.speed;
    RenderGraph graph(loadGraph(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracerSVGF.json"),
                      test::pluginRegistry());
    graph.setScene(scene);
    CompileOptions o;
    o.width = kWidth;
    o.height = kHeight;
    o.observe = {"GBuffer.posW", "SVGF.historyLength"};
    graph.compile(o);

    Counts counts;
    Texture prevPos(kWidth, kHeight, Format::RGBA32F);
    for (uint64_t frame = 0; frame < 16; ++frame) {
        graph.execute(cli::sceneFrame(*scene, frame, 60.0, kWidth, kHeight, frame == 0));
        const auto pos = graph.fieldTexture("GBuffer.posW")->view<glm::vec4>();
        const auto length = graph.fieldTexture("SVGF.historyLength")->view<float>();
        if (frame >= 4) {
            const glm::mat4 prevViewProj = scene->camera.prevViewProj();
            const glm::vec3 eye = scene->camera.position();
            const auto before = prevPos.view<glm::vec4>();
            for (uint32_t y = 0; y < kHeight; ++y)
                for (uint32_t x = 0; x < kWidth; ++x) {
                    const glm::vec4 p = pos.at(x, y);
                    if (p.w != 1.f) continue;  // a miss
                    const glm::vec4 clip = prevViewProj * glm::vec4(glm::vec3(p), 1.f);
                    if (clip.w <= 0.f) continue;
                    const float u = 0.5f * clip.x / clip.w + 0.5f, v = 0.5f - 0.5f * clip.y / clip.w;
                    const float px = u * float(kWidth), py = v * float(kHeight);
                    // One pixel inside the frame's border, so the whole bilinear footprint was on screen.
                    if (!(px >= 1.f && py >= 1.f && px < float(kWidth) - 1.f && py < float(kHeight) - 1.f)) continue;
                    const glm::vec4 q = before.at(uint32_t(px), uint32_t(py));
                    // The same point (within a pixel's footprint at its depth, generously): visible last frame.
                    const float footprint = 4.f * glm::length(glm::vec3(p) - eye) / float(kHeight);
                    if (q.w != 1.f || glm::length(glm::vec3(q) - glm::vec3(p)) > footprint) continue;
                    ++counts.visible;
                    if (length.at(x, y) <= 1.f) ++counts.restarted;
                }
        }
        prevPos.copyFrom(*graph.fieldTexture("GBuffer.posW"));
    }
    return counts;
}

}  // namespace

TEST(SVGFCameraMotion, VisibleSurfacesKeepTheirHistory) {
    for (const Motion& m : {Motion{CameraPathKind::Dolly, 4.f, "dolly 4"}, Motion{CameraPathKind::Dolly, 8.f, "dolly 8"},
                            Motion{CameraPathKind::Strafe, 4.f, "strafe 4"},
                            Motion{CameraPathKind::Orbit, 1.f, "orbit 1"}}) {
        SCOPED_TRACE(m.name);
        const Counts c = historyUnderMotion(m);
        // Most of the frame stays visible from one frame to the next: the count is a real test, not an empty one.
        EXPECT_GT(c.visible, uint64_t(12) * kWidth * kHeight / 2);
        EXPECT_LT(double(c.restarted), 0.005 * double(c.visible)) << c.restarted << " of " << c.visible;
        RecordProperty(std::string(m.name) + " restarted of visible",
                       std::to_string(c.restarted) + " of " + std::to_string(c.visible));
    }
}
