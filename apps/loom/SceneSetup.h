#pragma once
// Scene options shared by the commands that render (render, bench, view).
#include <CLI/CLI.hpp>
#include <cstdint>
#include <memory>
#include <string>

#include "loom/RenderGraph.h"
#include "loom/Scene.h"

namespace loom::cli {

struct SceneOptions {
    std::string scene;
    std::string cameraPath = "static";
    float cameraSpeed = 0.5f;
    std::string jitter = "none";
    uint32_t jitterCount = 16;
    std::string env;
    uint64_t textureBudgetMiB = kDefaultTextureBudget >> 20;
    bool allowMissingTextures = false;
};

/// Adds --scene, --camera-path, --camera-speed, --jitter, --jitter-count, --env, --texture-budget,
/// --allow-missing-textures.
void addSceneOptions(CLI::App* cmd, SceneOptions& o);
/// Loads the scene and applies the options; nullptr when no --scene was given.
/// Throws loom::Error (BadInput) for bad values.
std::shared_ptr<Scene> loadScene(const SceneOptions& o);
/// Animates the scene to `time` and sets the camera for this frame. The first
/// frame of a sequence has no motion (prev = current).
void beginSceneFrame(Scene& scene, uint64_t frameIndex, double time, uint32_t width, uint32_t height, bool firstFrame);
/// The FrameInfo of frame `index` on a clock of `fps` frames per second, after beginSceneFrame() for it.
FrameInfo sceneFrame(Scene& scene, uint64_t index, double fps, uint32_t width, uint32_t height, bool firstFrame);
/// The same for a graph that may run without a scene (nullptr: the clock alone).
FrameInfo sceneFrame(Scene* scene, uint64_t index, double fps, uint32_t width, uint32_t height, bool firstFrame);
/// Frame `index` shown at scene time `time` (seconds), whatever the clock says: `loom render --hold` runs many
/// frame indices (fresh random numbers) at one time. nullptr: no scene.
FrameInfo sceneFrameAt(Scene* scene, uint64_t index, double time, uint32_t width, uint32_t height, bool firstFrame);

}  // namespace loom::cli
