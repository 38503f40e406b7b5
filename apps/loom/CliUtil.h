#pragma once
// Helpers shared by the loom subcommands.
#include <CLI/CLI.hpp>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

namespace loom::cli {

/// "1280x720" -> width, height. Throws loom::Error naming the option.
void parseSize(const std::string& text, const std::string& option, uint32_t& width, uint32_t& height);
/// Adds --size to a command that renders a graph. Given, it is the frame size; left out, the size of the frames the
/// graph's source passes read (RenderGraph::naturalSize), else `fallback`: frameSize() decides, after the
/// parameters are set.
void addSizeOption(CLI::App* cmd, std::string& size, const std::string& fallback, const std::string& use = "");
/// One graph the size is asked of, and how to name it in a message ("" when there is only one).
struct SizedGraph {
    const RenderGraph* graph = nullptr;
    std::string label;
};
/// The frame size to render at: `size` when `given` (parsed as --size), else the size the graphs' sources agree on
/// (logged with the pass that gives it), else `fallback`. Throws loom::Error (BadInput) for a bad --size, for
/// sources that cannot be read, and for sources of different sizes (naming both).
glm::uvec2 frameSize(const std::string& size, bool given, const std::vector<SizedGraph>& graphs,
                     const std::string& fallback);
/// The options every command that runs frames shares: the animation clock's frame rate (0.001 to 10^6 frames a
/// second) and the worker threads (at most kMaxThreads; 0: all cores). Throws loom::Error naming the option.
inline constexpr unsigned kMaxThreads = 1024;
void checkFpsAndThreads(double fps, unsigned threads);
/// The whole of `text` (spaces around it allowed) as a finite float, or nothing (not a number, trailing characters,
/// beyond a float's range).
std::optional<float> parseFiniteFloat(const std::string& text);
/// "3,10-12" -> {3, 10, 11, 12}. Throws loom::Error naming the option.
std::set<uint64_t> parseFrameList(const std::string& text, const std::string& option);
/// The registry every command uses (default folders + LOOM_PLUGIN_PATH).
PluginRegistry makeRegistry();
/// Fails with a clear error when `dir` cannot be created or written.
void ensureWritableDir(const std::string& dir, const std::string& option);
/// Bad input (at `option`) when one of `inputs` lies in the output folder `outDir` under a name the command writes
/// there (`written` says which names): the run would overwrite what it reads.
void checkInputsNotOverwritten(const std::string& outDir, const std::vector<std::filesystem::path>& inputs,
                               const std::function<bool(const std::string& name)>& written, const std::string& option);
/// Whether `file` lies in the folder `outDir` under a name `written` accepts.
bool writtenInto(const std::filesystem::path& file, const std::string& outDir,
                 const std::function<bool(const std::string& name)>& written);
/// Applies --set assignments "Pass.param=value" to a graph (loom::Error for a malformed one or a bad value). With
/// onlyKnownPasses, assignments to passes the graph does not have are skipped (one --set list for several graphs).
void applySet(RenderGraph& graph, const std::vector<std::string>& set, bool onlyKnownPasses = false);

/// The --device option of the commands that compile graphs: where passes run unless the graph names a device for
/// them (CompileOptions::device; checked when the graph compiles). `note` ends the help text.
void addDeviceOption(CLI::App* cmd, std::string& device, const std::string& note = "");

void addRenderCommand(CLI::App& app);
void addCheckCommand(CLI::App& app);
void addPassesCommand(CLI::App& app);
void addSceneCommand(CLI::App& app);
void addImageCommand(CLI::App& app);
void addBenchCommand(CLI::App& app);
void addViewCommand(CLI::App& app);

/// "orbit", "orbit:0.5", "dolly:1:0.25", "static" -> a camera path. Throws loom::Error naming the option.
CameraPath parseCameraPath(const std::string& text, const std::string& option);

}  // namespace loom::cli
