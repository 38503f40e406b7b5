// loom scene info: what a glTF scene contains, as Loom loads it.
#include <fmt/format.h>

#include <cmath>
#include <iostream>

#include "CliUtil.h"
#include "loom/Error.h"
#include "loom/Scene.h"

namespace loom::cli {

namespace {

struct SceneInfoOptions {
    std::string file;
    std::string cameraPath = "static";
    double time = 0.0;
};

/// "(x, y, z)"; adding 0 turns -0 into 0, which reads better.
std::string vec(const glm::vec3& v) {
    return fmt::format("({:.4g}, {:.4g}, {:.4g})", v.x + 0.f, v.y + 0.f, v.z + 0.f);
}

void runSceneInfo(const SceneInfoOptions& o) {
    const CameraPath path = parseCameraPath(o.cameraPath, "--camera-path");
    if (!std::isfinite(o.time) || o.time < 0.0) throwBadInput("--time", "time must be >= 0", "seconds, e.g. 1.5");
    std::shared_ptr<Scene> scene = Scene::load(o.file);
    scene->cameraPath = path;
    scene->update(o.time);

    size_t emissiveMaterials = 0;
    for (const Material& m : scene->materials) emissiveMaterials += m.isEmissive() ? 1 : 0;
    size_t texels = 0;
    for (const SceneImage& img : scene->images) texels += img.texels.size();
    size_t lightsByType[3] = {0, 0, 0};
    for (const Light& l : scene->lights) ++lightsByType[size_t(l.type)];
    size_t meshTriangles = 0;
    for (const Mesh& m : scene->meshes) meshTriangles += m.triangleCount();

    const Bounds b = scene->bounds();
    const Camera& cam = scene->camera;
    auto line = [](const std::string& label, const std::string& value) {
        std::cout << fmt::format("{:<20}{}\n", label + ":", value);
    };
    line("file", scene->file.string());
    line("scene", scene->name);
    line("triangles", fmt::format("{} in instances ({} in meshes)", scene->triangleCount(), meshTriangles));
    line("meshes", fmt::format("{} (glTF primitives)", scene->meshes.size()));
    line("instances", std::to_string(scene->instances.size()));
    line("nodes", std::to_string(scene->nodes.size()));
    line("materials", fmt::format("{} ({} emissive)", scene->materials.size(), emissiveMaterials));
    line("textures",
         fmt::format("{} images, {:.1f} MiB as RGBA8", scene->images.size(), double(texels) * 4.0 / (1024.0 * 1024.0)));
    line("lights", fmt::format("{} ({} point, {} spot, {} directional)", scene->lights.size(), lightsByType[0],
                               lightsByType[1], lightsByType[2]));
    line("emissive triangles", std::to_string(scene->emissiveTriangles.size()));
    line("cameras", fmt::format("{} in the file; rendering from '{}'{}", scene->cameras.size(), cam.name,
                                scene->activeCamera < 0 ? " (a default framing the bounds)" : ""));
    line(fmt::format("camera at t={:.3g}", o.time),
         fmt::format("position {}, forward {}, fovY {:.1f} deg", vec(cam.position()), vec(cam.forward()),
                     glm::degrees(cam.fovY)));
    line("animations", fmt::format("{}, length {:.3f} s{}", scene->animations.size(), scene->animationLength(),
                                   scene->hasMotion() ? "" : " (static scene)"));
    if (const std::vector<float> steps = scene->lightStepTimes(); !steps.empty())
        line("light steps", fmt::format("at {:.4g} s", fmt::join(steps, ", ")));
    if (b.valid())
        line(fmt::format("bounds at t={:.3g}", o.time),
             fmt::format("{} to {}, size {}", vec(b.lo), vec(b.hi), vec(b.extent())));
    line("warnings", std::to_string(scene->warnings.size()));
    for (const std::string& w : scene->warnings) std::cout << "  - " << w << "\n";
}

}  // namespace

void addSceneCommand(CLI::App& app) {
    CLI::App* scene = app.add_subcommand("scene", "Inspect glTF scenes");
    scene->require_subcommand(1);
    auto o = std::make_shared<SceneInfoOptions>();
    CLI::App* info = scene->add_subcommand("info", "Load a .gltf/.glb and print what it contains");
    info->add_option("file", o->file, "scene file (.gltf or .glb)")->required();
    info->add_option("--camera-path", o->cameraPath,
                     "procedural camera motion for scenes without an animated camera: "
                     "static, orbit[:SPEED rad/s], dolly[:SPEED[:AMOUNT]] or strafe[:SPEED[:AMOUNT]]")
        ->capture_default_str();
    info->add_option("--time", o->time, "time in seconds at which the camera and bounds are shown")
        ->capture_default_str();
    info->callback([o] { runSceneInfo(*o); });
}

}  // namespace loom::cli
