#include "SceneSetup.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "CliUtil.h"
#include "loom/Error.h"
#include "loom/InputFile.h"

namespace loom::cli {

namespace {

/// The largest environment map file --env reads (a 16k x 8k float EXR is 1.5 GiB).
constexpr uint64_t kMaxEnvironmentFileBytes = uint64_t(4) << 30;

}  // namespace

void addSceneOptions(CLI::App* cmd, SceneOptions& o) {
    cmd->add_option("--scene,-s", o.scene, "glTF 2.0 scene (.gltf or .glb)");
    cmd->add_option("--camera-path", o.cameraPath,
                    "camera motion when the scene's camera is not animated: "
                    "static, orbit, dolly (along the view) or strafe (sideways)")
        ->capture_default_str();
    cmd->add_option("--camera-speed", o.cameraSpeed, "orbit: radians per second; dolly, strafe: phase in radians per second")
        ->capture_default_str();
    cmd->add_option("--jitter", o.jitter, "sub-pixel camera jitter: none, halton or stratified")->capture_default_str();
    cmd->add_option("--jitter-count", o.jitterCount, "period of the jitter pattern")->capture_default_str();
    cmd->add_option("--env", o.env, "environment: an equirectangular .hdr file, or a colour R,G,B");
    cmd->add_option("--texture-budget", o.textureBudgetMiB,
                    "MiB the scene's decoded textures may take together (RGBA8: 4 bytes a texel); beyond it loading "
                    "fails")
        ->capture_default_str();
    cmd->add_flag("--allow-missing-textures", o.allowMissingTextures,
                  "a texture whose image is missing or cannot be decoded is dropped with a warning instead of "
                  "failing the load");
}

std::shared_ptr<Scene> loadScene(const SceneOptions& o) {
    if (o.scene.empty()) {
        const SceneOptions defaults;
        if (o.cameraPath != defaults.cameraPath || o.cameraSpeed != defaults.cameraSpeed ||
            o.jitter != defaults.jitter || o.jitterCount != defaults.jitterCount || !o.env.empty())
            spdlog::warn(
                "--camera-path, --camera-speed, --jitter, --jitter-count and --env apply to a scene; "
                "without --scene they are ignored");
        return nullptr;
    }
    CameraPath path;
    if (o.cameraPath == "static")
        path.kind = CameraPathKind::Static;
    else if (o.cameraPath == "orbit")
        path.kind = CameraPathKind::Orbit;
    else if (o.cameraPath == "dolly")
        path.kind = CameraPathKind::Dolly;
    else if (o.cameraPath == "strafe")
        path.kind = CameraPathKind::Strafe;
    else
        throwBadInput("--camera-path", "unknown camera path '" + o.cameraPath + "'", "static, orbit, dolly or strafe",
                      didYouMean(o.cameraPath, {"static", "orbit", "dolly", "strafe"}, "paths"));
    if (!std::isfinite(o.cameraSpeed) || std::fabs(o.cameraSpeed) > 1000.f)
        throwBadInput("--camera-speed", fmt::format("camera speed {} is out of range", o.cameraSpeed),
                      "a value in [-1000, 1000]");
    path.speed = o.cameraSpeed;
    JitterPattern jitter;
    if (o.jitter == "none")
        jitter = JitterPattern::None;
    else if (o.jitter == "halton")
        jitter = JitterPattern::Halton;
    else if (o.jitter == "stratified")
        jitter = JitterPattern::Stratified;
    else
        throwBadInput("--jitter", "unknown jitter pattern '" + o.jitter + "'", "none, halton or stratified",
                      didYouMean(o.jitter, {"none", "halton", "stratified"}, "patterns"));
    if (o.jitterCount == 0 || o.jitterCount > 1024)
        throwBadInput("--jitter-count", "jitter period out of range", "1 to 1024 samples");

    if (o.textureBudgetMiB == 0 || o.textureBudgetMiB > (uint64_t(1) << 30))
        throwBadInput("--texture-budget", fmt::format("texture budget {} MiB is out of range", o.textureBudgetMiB),
                      "1 to 1073741824 MiB");
    SceneLoadOptions loadOptions;
    loadOptions.textureBudgetBytes = o.textureBudgetMiB << 20;
    loadOptions.allowMissingTextures = o.allowMissingTextures;
    std::shared_ptr<Scene> scene = Scene::load(o.scene, loadOptions);
    if (path.kind != CameraPathKind::Static && scene->cameraAnimated())
        spdlog::warn("--camera-path {} is ignored: {} animates its camera, which the frames follow", o.cameraPath,
                     o.scene);
    scene->cameraPath = path;
    scene->camera.jitterPattern = jitter;
    scene->camera.jitterSampleCount = o.jitterCount;
    if (!o.env.empty()) {
        std::error_code ec;
        if (o.env.find(',') != std::string::npos && !std::filesystem::exists(o.env, ec)) {
            // A colour R,G,B: exactly three plain decimal numbers (no hexadecimal floats, no infinity), each in
            // [0, 1e9].
            glm::vec3 c(0.f);
            bool ok = std::count(o.env.begin(), o.env.end(), ',') == 2 &&
                      o.env.find_first_not_of("0123456789.eE+- ,") == std::string::npos;
            std::istringstream in(o.env);
            std::string part;
            int n = 0;
            for (; ok && n < 3 && std::getline(in, part, ','); ++n) {
                const std::optional<float> v = parseFiniteFloat(part);
                ok = v && *v >= 0.f && *v <= 1e9f;
                if (ok) c[n] = *v;
            }
            if (!ok || n != 3)
                throwBadInput("--env", "'" + printable(o.env) + "' is neither a colour nor an existing file",
                              "R,G,B (three numbers from 0 to 1e9, e.g. 0.1,0.1,0.1) or an .hdr or .exr file",
                              "check the path, or give three numbers");
            scene->environment = Environment{};
            scene->environment.color = c;
        } else {
            // Named here, with the option: Scene::loadEnvironmentMap would only find no file.
            if (const std::string problem = inputFileProblem(o.env, kMaxEnvironmentFileBytes); !problem.empty())
                throwBadInput("--env", "the environment map " + problem,
                              "an equirectangular .hdr or .exr file, or a colour R,G,B",
                              problem == "does not exist" ? "check the path"
                              : problem == "is a folder"  ? "name an image file inside the folder"
                                                          : "",
                              o.env);
            scene->loadEnvironmentMap(o.env);
        }
    }
    if (!scene->emitsLight())
        spdlog::warn(
            "{} has no light: no emissive surface, no punctual light and {}, so it renders black; light it "
            "with --env, e.g. --env 1,1,1 (a uniform white sky) or --env sky.hdr",
            o.scene, o.env.empty() ? "no environment (no --env)" : "a black environment (--env)");
    return scene;
}

void beginSceneFrame(Scene& scene, uint64_t frameIndex, double time, uint32_t width, uint32_t height, bool firstFrame) {
    scene.update(time);
    if (firstFrame) scene.cutMotion();
    scene.camera.aspect = float(width) / float(height);
    scene.camera.beginFrame(frameIndex);
    if (firstFrame) scene.camera.cut();
}

FrameInfo sceneFrameAt(Scene* scene, uint64_t index, double time, uint32_t width, uint32_t height, bool first) {
    FrameInfo f;
    f.frameIndex = index;
    f.time = time;
    if (!scene) return f;
    beginSceneFrame(*scene, f.frameIndex, f.time, width, height, first);
    f.scene = scene;
    f.camera = &scene->camera;
    return f;
}

FrameInfo sceneFrame(Scene& scene, uint64_t index, double fps, uint32_t width, uint32_t height, bool first) {
    return sceneFrameAt(&scene, index, double(index) / fps, width, height, first);
}

FrameInfo sceneFrame(Scene* scene, uint64_t index, double fps, uint32_t width, uint32_t height, bool first) {
    return sceneFrameAt(scene, index, double(index) / fps, width, height, first);
}

}  // namespace loom::cli
