#include "ViewSession.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <sstream>

#include "CliUtil.h"
#include "Display.h"
#include "loom/Error.h"
#include "loom/Files.h"
#include "loom/ImageIO.h"
#include "loom/InputFile.h"

namespace loom::cli {

namespace {

const std::vector<std::string> kVerbs = {"view", "set", "exposure", "reset", "save", "shot", "move", "turn"};

/// The numbers of a command's argument: exactly `count` of them, finite. Throws BadInput naming `where`.
std::vector<float> numbers(const std::string& text, size_t count, const std::string& where, const std::string& form) {
    std::istringstream in(text);
    std::vector<float> values;
    std::string word;
    while (in >> word) {
        const std::optional<float> v = parseFiniteFloat(word);
        if (!v) throwBadInput(where, "'" + printable(word) + "' is not a number", form);
        values.push_back(*v);
    }
    if (values.size() != count) throwBadInput(where, fmt::format("{} numbers, not {}", count, values.size()), form);
    return values;
}

bool needsArgument(const std::string& verb) {
    return verb != "reset";
}

bool isVideo(const std::string& record) {
    return std::filesystem::path(record).extension() == ".y4m";
}

std::filesystem::file_time_type modificationTime(const std::string& path) {
    std::error_code ec;
    const auto t = std::filesystem::last_write_time(path, ec);
    return ec ? std::filesystem::file_time_type{} : t;
}

void checkExposure(float ev, const std::string& where) {
    if (!std::isfinite(ev) || std::fabs(ev) > 64.f)
        throwBadInput(where, fmt::format("exposure {} EV is out of range", ev), "a value in [-64, 64] EV");
}

}  // namespace

std::vector<ScriptCommand> parseViewScript(const std::string& path, const std::vector<std::filesystem::path>& inputs) {
    std::istringstream in(readInputFile(path, "script", "a text file of lines 'FRAME VERB [ARG]'", uint64_t(16) << 20));
    std::vector<ScriptCommand> commands;
    std::string text;
    int line = 0;
    while (std::getline(in, text)) {
        ++line;
        const std::string where = fmt::format("{}:{}", path, line);
        std::istringstream words(text);
        std::string first;
        if (!(words >> first) || first[0] == '#') continue;
        ScriptCommand c;
        c.line = line;
        size_t used = 0;
        try {
            c.frame = std::stoull(first, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used != first.size() || first[0] == '-')
            throwBadInput(where, "'" + printable(first) + "' is not a frame number",
                          "FRAME VERB [ARGUMENT], e.g. 10 view SVGF.variance");
        if (!(words >> c.verb))
            throwBadInput(where, "a frame number without a command", "FRAME VERB [ARGUMENT]", "verbs: " + join(kVerbs));
        if (std::find(kVerbs.begin(), kVerbs.end(), c.verb) == kVerbs.end())
            throwBadInput(where, "unknown command '" + printable(c.verb) + "'", "one of: " + join(kVerbs),
                          didYouMean(c.verb, kVerbs, ""));
        std::getline(words >> std::ws, c.arg);
        while (!c.arg.empty() && std::isspace(static_cast<unsigned char>(c.arg.back()))) c.arg.pop_back();
        if (needsArgument(c.verb) && c.arg.empty())
            throwBadInput(where, "'" + c.verb + "' needs an argument", "FRAME " + c.verb + " ARGUMENT");
        if (!commands.empty() && c.frame < commands.back().frame)
            throwBadInput(where, fmt::format("frame {} comes after frame {}", c.frame, commands.back().frame),
                          "lines in frame order");
        if (c.verb == "exposure") {
            c.numbers = numbers(c.arg, 1, where, "an exposure in EV, e.g. -1.5");
            checkExposure(c.numbers[0], where);
        }
        if (c.verb == "move") c.numbers = numbers(c.arg, 3, where, "move X Y Z, camera-local, in the scene's size");
        if (c.verb == "turn") c.numbers = numbers(c.arg, 2, where, "turn YAW PITCH, in degrees");
        if (c.verb == "save" || c.verb == "shot") {
            // Before any frame renders: a path that cannot be written, and a save before the first frame.
            checkOutputFile(c.arg, where, inputs);
            if (c.frame == 0)
                throwBadInput(where, "nothing is rendered before frame 0", "a frame of 1 or later",
                              "commands run before their frame renders: 1 " + c.verb + " saves frame 0");
        }
        commands.push_back(std::move(c));
    }
    return commands;
}

ViewSession::ViewSession(const ViewOptions& options)
    : mOptions(options), mRegistry(makeRegistry()), mExposure(options.exposure) {
    const bool sizeGiven = options.sizeGiven || !options.size.empty();
    if (sizeGiven) (void)frameSize(options.size, true, {}, "");  // a bad --size fails first
    checkFpsAndThreads(options.fps, options.threads);
    mThreadLimit.emplace(options.threads);  // before anything runs on the workers
    if (options.frames > 1000000)
        throwBadInput("--frames", fmt::format("frame count {} is out of range", options.frames),
                      "0 to 1000000 frames (0: until the window closes)");
    checkExposure(options.exposure, "--exposure");
    // What the run reads, which none of its outputs may replace.
    const std::vector<std::filesystem::path> inputs = {options.graph, options.scene.scene, options.scene.env,
                                                       options.script};
    if (!options.script.empty()) mScript = parseViewScript(options.script, inputs);
    if (isVideo(options.record))
        checkOutputFile(options.record, "--record", inputs);
    else if (!options.record.empty())
        ensureWritableDir(options.record, "--record");
    if (!options.screenshot.empty()) checkOutputFile(options.screenshot, "--screenshot", inputs);
    if (options.headless && options.frames == 0)
        throwBadInput("--frames", "--headless needs a frame count", "--frames N with N > 0");
    if (!options.windowShot.empty()) {
        if (options.headless)
            throwBadInput("--window-shot", "a window shot needs the window",
                          "--screenshot for the displayed image, or --window-shot without --headless");
        checkOutputFile(options.windowShot, "--window-shot", inputs);
    }
    mScene = loadScene(options.scene);
    mGraph = std::make_unique<RenderGraph>(loadGraph(options.graph), mRegistry);
    mGraphTime = modificationTime(options.graph);
    if (mScene) mGraph->setScene(mScene);
    applySet(*mGraph, options.set);
    const glm::uvec2 size = frameSize(options.size, sizeGiven, {{mGraph.get(), ""}}, "640x360");
    mWidth = size.x;
    mHeight = size.y;
    // Compile once to learn the fields, then with the one on display observed.
    CompileOptions copts;
    copts.width = mWidth;
    copts.height = mHeight;
    copts.device = options.device;
    mGraph->compile(copts);
    listFields();
    view(options.field.empty() ? defaultField() : options.field);
    mGraph->setFieldObserver(
        [this](const FrameInfo&, const std::string& pass, const std::string& field, const Texture& tex) {
            if (pass + "." + field != mViewed) return;
            if (mViewedTexture.width() != tex.width() || mViewedTexture.height() != tex.height() ||
                mViewedTexture.format() != tex.format())
                mViewedTexture = Texture(tex.width(), tex.height(), tex.format());
            mViewedTexture.copyFrom(tex);
        });
}

ViewSession::~ViewSession() = default;

void ViewSession::listFields() {
    mFields.clear();
    const CompiledPlan& plan = mGraph->plan();
    for (const ResourceInfo& r : plan.resources) mFields.push_back(r.name);
    for (const std::string& s : plan.skippedOutputs)
        if (std::find(mFields.begin(), mFields.end(), s) == mFields.end()) mFields.push_back(s);
    const auto position = [&](const std::string& field) {
        const std::string pass = field.substr(0, field.find('.'));
        return std::find(plan.order.begin(), plan.order.end(), pass) - plan.order.begin();
    };
    std::stable_sort(mFields.begin(), mFields.end(),
                     [&](const std::string& a, const std::string& b) { return position(a) < position(b); });
    if (mFields.empty()) throwBadInput(mOptions.graph, "the graph computes no field", "a graph with outputs");
}

std::string ViewSession::defaultField() const {
    const auto& outs = mGraph->outputs();
    return outs.empty() ? mFields.front() : outs.front().pass + "." + outs.front().channel;
}

void ViewSession::compileViewing(const std::string& field) {
    CompileOptions copts = mGraph->options();
    copts.observe = {field};
    mGraph->compile(copts);
}

void ViewSession::view(const std::string& field) {
    if (std::find(mFields.begin(), mFields.end(), field) == mFields.end())
        throwBadInput(field, "no field '" + printable(field) + "' in the graph", "a Pass.field the graph computes",
                      didYouMean(field, mFields, "fields"));
    if (field == mViewed) return;
    compileViewing(field);
    mViewed = field;
}

void ViewSession::set(const std::string& assignment) {
    applySet(*mGraph, {assignment});
}

void ViewSession::setExposure(float ev) {
    checkExposure(ev, "exposure");
    mExposure = ev;
    refreshDisplay();
}

std::string ViewSession::reloadIfChanged() {
    const auto t = modificationTime(mOptions.graph);
    if (t == mGraphTime) return {};
    mGraphTime = t;
    std::string error;
    try {
        // Recompiles with the shown field still observed.
        mGraph->setDesc(loadGraph(mOptions.graph));
    } catch (const Error& e) {
        error = e.what();  // setDesc leaves the graph as it ran before
    }
    listFields();
    if (std::find(mFields.begin(), mFields.end(), mViewed) == mFields.end()) view(defaultField());
    return error;
}

void ViewSession::runScript() {
    while (mScriptNext < mScript.size() && mScript[mScriptNext].frame <= mFrame) {
        const ScriptCommand& c = mScript[mScriptNext++];
        const std::string where = fmt::format("{}:{}", mOptions.script, c.line);
        try {
            if (c.verb == "view")
                view(c.arg);
            else if (c.verb == "set")
                set(c.arg);
            else if (c.verb == "exposure")
                setExposure(c.numbers[0]);
            else if (c.verb == "move")
                moveCamera(glm::vec3(c.numbers[0], c.numbers[1], c.numbers[2]), 0.f, 0.f);
            else if (c.verb == "turn")
                moveCamera(glm::vec3(0.f), glm::radians(c.numbers[0]), glm::radians(c.numbers[1]));
            else if (c.verb == "reset")
                resetHistory();
            else if (c.verb == "save")
                saveField(c.arg);
            else if (c.verb == "shot")
                saveDisplay(c.arg);
        } catch (const Error& e) {
            Error::Info info = e.info();  // the script line, then what the command named
            info.where = info.where.empty() ? where : where + ": " + info.where;
            throw Error(info);
        }
    }
}

void ViewSession::moveCamera(const glm::vec3& local, float yaw, float pitch) {
    if (!mScene) throwBadInput("camera", "the graph runs without a scene", "a --scene to move a camera in");
    if (mScene->cameraAnimated())
        throwBadInput("camera", "the scene animates its camera", "a scene whose camera is not animated",
                      "choose another camera of the scene, or remove its animation");
    // Moves before one frame add up: each starts from the pose the last one set.
    Camera cam = mScene->camera;
    if (mPendingPose) cam.world = *mPendingPose;
    mScene->cameraPath.kind = CameraPathKind::Static;  // the viewer has the camera now
    const Bounds b = mScene->bounds();
    const float size = b.valid() ? std::max(glm::length(b.extent()), 1e-3f) : 1.f;
    const glm::vec3 position =
        cam.position() + size * (local.x * cam.right() + local.y * cam.up() - local.z * cam.forward());
    // Yaw about the world's up (+Y), then pitch about the turned right axis, stopping short of the poles; the
    // camera's own right axis keeps the frame defined whatever it looks at.
    const glm::mat4 yawTurn = glm::rotate(glm::mat4(1.f), yaw, glm::vec3(0.f, 1.f, 0.f));
    const glm::vec3 right = glm::normalize(glm::vec3(yawTurn * glm::vec4(cam.right(), 0.f)));
    glm::vec3 forward = glm::normalize(glm::vec3(yawTurn * glm::vec4(cam.forward(), 0.f)));
    const glm::vec3 pitched = glm::vec3(glm::rotate(glm::mat4(1.f), pitch, right) * glm::vec4(forward, 0.f));
    if (std::fabs(pitched.y) < 0.995f || std::fabs(pitched.y) < std::fabs(forward.y)) forward = pitched;
    const glm::vec3 up = glm::normalize(glm::cross(right, forward));
    forward = glm::cross(up, right);
    glm::mat4 world(1.f);
    world[0] = glm::vec4(right, 0.f);
    world[1] = glm::vec4(up, 0.f);
    world[2] = glm::vec4(-forward, 0.f);
    world[3] = glm::vec4(position, 1.f);
    // The pose the next update starts from; the camera itself stays where it is until then, so that update moves it
    // from there and the frame's motion vectors carry the move.
    const glm::mat4 current = mScene->camera.world;
    mScene->setCameraPose(world);
    mScene->camera.world = current;
    mPendingPose = world;
}

void ViewSession::step() {
    runScript();
    const FrameInfo frame = sceneFrame(mScene.get(), mFrame, mOptions.fps, mWidth, mHeight, mFrame == 0);
    mPendingPose.reset();
    mGraph->execute(frame);
    ++mFrame;
    refreshDisplay();
    if (isVideo(mOptions.record)) {
        if (!mVideo)
            mVideo = std::make_unique<Y4mWriter>(mOptions.record, mViewedTexture.width(), mViewedTexture.height(),
                                                 mOptions.fps);
        mVideo->add(mDisplay);
    } else if (!mOptions.record.empty()) {
        saveDisplay(std::filesystem::path(mOptions.record) / fmt::format("frame.{:04}.png", mFrame - 1));
    }
}

std::string ViewSession::accumulationText() const {
    // The samples per pixel of each frame, when one pass declares them (a path tracer).
    int samplesPerFrame = 0, samplers = 0;
    for (const std::string& name : mGraph->plan().order)
        if (const ParamDecl* d = mGraph->pass(name)->params().findRole(ParamRole::SampleCount)) {
            samplesPerFrame = d->get().get<int>();
            ++samplers;
        }
    const auto stats = mGraph->lastStats();
    std::string text;
    for (const std::string& name : mGraph->plan().order) {
        const auto s = stats.find(name);
        if (s == stats.end() || !mGraph->pass(name)->params().findRole(ParamRole::AutoReset)) continue;
        const auto frames = s->second.find("frames");
        if (frames == s->second.end()) continue;
        text += fmt::format("{}{}: {:g} frames", text.empty() ? "" : ", ", name, frames->second);
        if (samplers == 1) text += fmt::format(" x {} spp", samplesPerFrame);
        text += " accumulated";
    }
    return text;
}

void ViewSession::finish() {
    if (mVideo) mVideo->finish();
}

void ViewSession::refreshDisplay() {
    if (mViewedTexture.empty()) return;
    mDisplay = displayImage(mViewedTexture, std::exp2(mExposure));
    ++mDisplayVersion;
}

void ViewSession::saveField(const std::filesystem::path& path) const {
    if (mViewedTexture.empty()) throwBadInput(path.string(), "nothing rendered yet", "a frame before saving");
    writeImage(path, mViewedTexture);
}

void ViewSession::saveDisplay(const std::filesystem::path& path) const {
    if (mDisplay.empty()) throwBadInput(path.string(), "nothing rendered yet", "a frame before saving");
    const uint32_t w = mViewedTexture.width();
    Texture t(w, mViewedTexture.height(), Format::RGBA8Srgb);
    for (uint32_t y = 0; y < t.height(); ++y)
        std::copy_n(&mDisplay[size_t(y) * w * 4], size_t(w) * 4, reinterpret_cast<uint8_t*>(t.row(y)));
    writeImage(path, t);
}

}  // namespace loom::cli
