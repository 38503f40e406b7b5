#pragma once
// The state behind `loom view`, with no window code: the graph and its scene, the frame clock, the field on display
// and its 8-bit image, parameter edits, reloads of the edited graph file, and a script of timed commands. The window
// (ViewCommand.cpp) draws what this holds; `loom view --headless` runs it without one.
#include <cstdint>
#include <filesystem>
#include <glm/mat4x4.hpp>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "Display.h"
#include "SceneSetup.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Texture.h"

namespace loom::cli {

struct ViewOptions {
    std::string graph;
    std::string size;        ///< --size; empty and not sizeGiven: the graph's sources give the size (frameSize)
    bool sizeGiven = false;  ///< --size was given (perhaps empty, which is refused)
    std::vector<std::string> set;
    std::string device;    ///< where passes run unless the graph names a device for them (--device)
    std::string field;     ///< field shown first ("Pass.field"); empty: the graph's first output
    float exposure = 0.f;  ///< EV applied to float fields on display
    double fps = 60.0;
    unsigned threads = 0;
    uint64_t frames = 0;     ///< stop after this many frames (0: when the window closes)
    std::string script;      ///< file of timed commands (parseViewScript)
    std::string record;      ///< a .y4m video of the displayed frames, or a folder of numbered PNGs
    std::string screenshot;  ///< at the end: the displayed image as PNG
    std::string windowShot;  ///< after the last frame or when the window closes: the whole window as PNG
    bool headless = false;
    bool openPasses = false;  ///< the panel starts with every pass's parameters shown
    SceneOptions scene;
};

/// One line of a --script file: before frame `frame` renders, `verb` with `arg`.
struct ScriptCommand {
    uint64_t frame = 0;
    std::string verb, arg;
    std::vector<float> numbers;  ///< exposure, move and turn: the argument's numbers
    int line = 0;
};
/// Lines "FRAME VERB [ARG]"; blank lines and lines starting with # are skipped. Verbs: view FIELD, set
/// Pass.param=value, exposure EV, reset, save PATH (the viewed field's own values), shot PATH (the displayed image),
/// move X Y Z (ViewSession::moveCamera, in the scene's size), turn YAW PITCH (degrees).
/// Throws loom::Error (BadInput) naming the file and line.
std::vector<ScriptCommand> parseViewScript(const std::string& path,
                                           const std::vector<std::filesystem::path>& inputs = {});

class ViewSession {
public:
    /// Loads the scene and the graph, applies --set, compiles with the first field on display. Throws loom::Error.
    explicit ViewSession(const ViewOptions& options);
    ~ViewSession();

    /// Runs the script's commands due before the next frame, renders it and refreshes the display.
    void step();
    /// Completes the outputs of a run: the --record video. Without it an unfinished video is removed.
    void finish();
    /// Frames rendered so far.
    uint64_t frame() const { return mFrame; }
    uint32_t width() const { return mWidth; }
    uint32_t height() const { return mHeight; }

    /// Every field that can be shown, "Pass.field", in execution order (outputs, internals, history, and optional
    /// outputs nobody consumes, which showing them computes).
    const std::vector<std::string>& fields() const { return mFields; }
    const std::string& viewed() const { return mViewed; }
    /// Shows another field from the next frame on. Recompiles with it observed: no parameter, state or history
    /// changes, so the rendered values are those of a run that never switched. Throws BadInput for an unknown field.
    void view(const std::string& field);
    /// "Pass.param=value", as --set; never reallocates. Throws loom::Error for a bad assignment.
    void set(const std::string& assignment);
    float exposure() const { return mExposure; }
    void setExposure(float ev);
    void resetHistory() { mGraph->resetHistory(); }
    /// Moves the camera in its own frame (x right, y up, z backward), `local` in units of the scene's size (the
    /// diagonal of its bounds), and turns it: `yaw` about the world's up axis, `pitch` about the camera's right
    /// axis, radians. The first move takes the camera off its --camera-path (static from then on). The move shows in
    /// the next frame's motion vectors; history is kept. Throws BadInput without a scene or when the scene animates
    /// its camera.
    void moveCamera(const glm::vec3& local, float yaw, float pitch);
    /// Reloads the graph file if it changed on disk since it was last read. Passes whose name and type stay keep
    /// their state and history. On an error the message is returned and the running graph stays as it was.
    std::string reloadIfChanged();

    /// The viewed field as of the last frame (empty before the first) and its display (RGBA8, 4 bytes a pixel).
    const Texture& viewedTexture() const { return mViewedTexture; }
    const std::vector<uint8_t>& display() const { return mDisplay; }
    /// Counts the changes of display(): a window uploads it again only when this moved.
    uint64_t displayVersion() const { return mDisplayVersion; }
    /// Writes the viewed field's values (EXR for float formats, PNG for 8-bit) or the displayed image (PNG).
    void saveField(const std::filesystem::path& path) const;
    void saveDisplay(const std::filesystem::path& path) const;

    /// What the accumulating passes (those with an AutoReset parameter) hold after the last frame, e.g.
    /// "Accumulate: 57 frames x 1 spp accumulated"; empty when the graph has none.
    std::string accumulationText() const;

    RenderGraph& graph() { return *mGraph; }
    const ViewOptions& options() const { return mOptions; }

private:
    /// The graph's first output (its first field when it marks none).
    std::string defaultField() const;
    void compileViewing(const std::string& field);
    void refreshDisplay();
    void runScript();
    void listFields();

    ViewOptions mOptions;
    std::optional<ThreadLimit> mThreadLimit;  ///< --threads, in force once the options are checked
    uint32_t mWidth = 0, mHeight = 0;
    PluginRegistry mRegistry;
    std::shared_ptr<Scene> mScene;
    std::unique_ptr<RenderGraph> mGraph;
    std::vector<std::string> mFields;
    std::string mViewed;
    float mExposure = 0.f;
    Texture mViewedTexture;
    std::vector<uint8_t> mDisplay;
    uint64_t mDisplayVersion = 0;
    uint64_t mFrame = 0;
    std::vector<ScriptCommand> mScript;
    size_t mScriptNext = 0;
    std::filesystem::file_time_type mGraphTime{};
    std::unique_ptr<Y4mWriter> mVideo;  ///< --record FILE.y4m, opened with the first frame
    std::optional<glm::mat4> mPendingPose;  ///< the camera pose moves set since the last frame
};

}  // namespace loom::cli
