#pragma once
// The frame graph: passes created from a graph description, compiled into an
// execution plan (wiring, culling, order, memory), and executed frame by frame.
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "loom/Graph.h"
#include "loom/Plugin.h"
#include "loom/RenderPass.h"

namespace loom {

struct CompileOptions {
    uint32_t width = 256;
    uint32_t height = 256;
    /// Glob patterns over "Pass.field" (e.g. "SVGF.*") that must be computed
    /// and shown to the field observer even when nothing consumes them.
    std::vector<std::string> observe;
    /// Fill transient memory with NaN (0xFFFFFFFF for integers) when its
    /// lifetime starts, so a read-before-write shows up.
    bool poisonTransients = false;
    /// Where passes run unless their graph entry names a device: "" (the
    /// graph's "device"), "auto", "cpu", "cuda" or "emulated" (--device).
    std::string device;
    /// Plan only (`loom check`): place, wire and plan memory without
    /// allocating or compiling passes, so a plan for cuda needs no GPU. A
    /// graph compiled so cannot execute.
    bool planOnly = false;
};

struct FrameInfo {
    uint64_t frameIndex = 0;
    double time = 0.0;
    const Scene* scene = nullptr;
    const Camera* camera = nullptr;
};

/// One connection in the compiled plan.
struct Wire {
    ChannelRef src;   ///< an output (src.prev: last frame's value)
    ChannelRef dst;   ///< an input
    bool byName = false;  ///< wired automatically by channel name
};

enum class ResourceKind { Transient, History };

/// One allocation of the compiled plan.
struct ResourceInfo {
    std::string name;  ///< "Pass.field" of the field that owns it
    uint32_t pass = 0;  ///< the owner's index in the graph description
    std::string field;  ///< the owner's field
    ResourceKind kind = ResourceKind::Transient;
    Format format = Format::RGBA32F;
    uint32_t width = 0, height = 0;
    size_t bytes = 0;        ///< per texture (a history pair holds two)
    DeviceKind device = DeviceKind::Cpu;  ///< whose memory holds it
    int firstUse = 0;        ///< execution position of the writer
    int lastUse = 0;         ///< last execution position that reads it (order size = after the frame)
    size_t offset = 0;       ///< transient: offset into the shared arena
    bool inPlace = false;    ///< history updated in place: one texture, not a pair
};

/// A copy the graph makes each frame because a field crosses devices: into a pass placed on another device than
/// the field's writer (before that pass runs), or to the host for a marked output or an observed field (after the
/// pass that writes it).
struct TransferInfo {
    std::string field;     ///< "Pass.field" (with "@prev" for last frame's value)
    DeviceKind from = DeviceKind::Cpu, to = DeviceKind::Cpu;
    size_t bytes = 0;      ///< per frame
    int position = 0;      ///< the execution position it runs at: before that pass (inputs), after it (to the host)
    bool after = false;    ///< after the pass at `position` (marked outputs, observed fields)
    std::string reason;    ///< "for SVGF", "marked output", "observed"
    std::string resource;  ///< the copy's resource name (inputs), empty for copies to the host
};

/// Where a live pass runs, and why it runs elsewhere than asked where it does.
struct PlacedPass {
    std::string name;
    DeviceKind device = DeviceKind::Cpu;
    std::string note;  ///< e.g. "asked for cuda; this pass has no cuda version"
};

struct CulledPass {
    std::string name;
    std::string reason;
};

/// What of the graph does not run or gets no memory.
enum class NotRunKind {
    Culled,        ///< a pass that does not run
    NotComputed,   ///< an optional output of a live pass, neither allocated nor written
    NotConnected,  ///< an optional input of a live pass that nothing feeds
    NotAllocated,  ///< an internal or history field the pass leaves out once its connections are known
};

/// One pass or field that does not run or gets no memory, and why (`loom check` lists them).
struct NotRun {
    std::string pass;
    std::string field;  ///< empty for the pass itself
    NotRunKind kind = NotRunKind::Culled;
    std::string reason;
};

/// "culled", "not computed", "not connected" or "not allocated".
const char* notRunKindName(NotRunKind kind);

/// The result of compiling: what `loom check` prints.
struct CompiledPlan {
    uint32_t width = 0, height = 0;
    std::vector<std::string> order;   ///< live passes in execution order
    std::vector<CulledPass> culled;
    std::vector<Wire> wires;           ///< between live passes
    std::vector<ChannelRef> outputs;   ///< marked outputs
    std::vector<ResourceInfo> resources;
    std::vector<std::string> skippedOutputs;  ///< optional outputs not computed
    /// Every culled pass, and every optional output not computed, optional input not connected and field left out
    /// of a live pass, with why: passes in description order, a pass's fields in declaration order. A field that
    /// shares arena memory or lives in a history pair is allocated, so it is not listed.
    std::vector<NotRun> notRun;
    std::vector<std::string> warnings;
    size_t transientPeakBytes = 0;     ///< size of the shared transient arena
    size_t transientSumBytes = 0;      ///< what the transients would take unshared
    size_t historyBytes = 0;           ///< both sides of every history pair
    std::vector<PlacedPass> placement;       ///< live passes in execution order
    std::vector<TransferInfo> transfers;     ///< every copy between devices, per frame
    /// Per device (indexed by DeviceKind): its transient arena and its history; transientPeakBytes and
    /// historyBytes above are the sums over devices.
    size_t devicePeakBytes[3] = {0, 0, 0};
    size_t deviceHistoryBytes[3] = {0, 0, 0};
};

struct PassTiming {
    std::string name;
    double lastMs = 0.0;
    double totalMs = 0.0;
    uint64_t runs = 0;
};

/// A frame size the graph's data gives, and the pass whose data gives it.
struct NaturalSize {
    uint32_t width = 0, height = 0;
    std::string pass;
};

class RenderGraph {
public:
    /// Creates the passes of `desc` and applies their parameters. Throws
    /// loom::Error for unknown types and bad parameters.
    RenderGraph(GraphDesc desc, PluginRegistry& registry);
    ~RenderGraph();
    RenderGraph(const RenderGraph&) = delete;
    RenderGraph& operator=(const RenderGraph&) = delete;

    /// The frame size the passes' own data gives (RenderPass::naturalSize, asked of every pass with its current
    /// parameters), or none where no pass has one: what to render at when no size is given. Throws loom::Error
    /// (BadInput) where two passes give different sizes (naming both), or where a pass cannot read its data.
    std::optional<NaturalSize> naturalSize() const;
    /// Validates and plans the graph for a frame size. History whose field
    /// declaration (pass type, format, size) is unchanged survives; any other
    /// history starts invalid. Throws loom::Error for bad wiring, formats,
    /// cycles and outputs.
    void compile(const CompileOptions& options);
    /// Replaces the description (edges, outputs, passes) and recompiles with
    /// the last options. Passes whose name and type are unchanged are kept,
    /// with their state and history.
    void setDesc(GraphDesc desc);
    /// Changes the frame size and recompiles (history resets).
    void resize(uint32_t width, uint32_t height);

    /// Gives every pass (present and future) the scene. Resets history.
    void setScene(std::shared_ptr<const Scene> scene);

    /// Runs every live pass once, then swaps history.
    void execute(const FrameInfo& frame);
    /// Invalidates all history (camera cut, explicit reset).
    void resetHistory();

    /// Sets a parameter; never recompiles or reallocates. `where` names the
    /// origin for errors (e.g. "--set SVGF.alpha").
    void setParam(const std::string& pass, const std::string& param, const nlohmann::json& value,
                  const std::string& where);
    RenderPass* pass(const std::string& name) const;

    /// The texture of a field after execute: marked outputs, history (cur),
    /// and anything that was observed. nullptr when not allocated.
    const Texture* fieldTexture(const std::string& passDotField) const;
    const std::vector<ChannelRef>& outputs() const { return mPlan.outputs; }

    using FieldObserver =
        std::function<void(const FrameInfo&, const std::string& pass, const std::string& field, const Texture&)>;
    /// Called for every field matching CompileOptions::observe: inputs just
    /// before the pass executes, outputs, internals and history right after.
    void setFieldObserver(FieldObserver observer) { mObserver = std::move(observer); }

    const CompiledPlan& plan() const { return mPlan; }
    bool compiled() const { return mCompiled; }
    const CompileOptions& options() const { return mOptions; }
    std::vector<PassTiming> timings() const;
    /// Counters each pass reported in the last frame.
    std::map<std::string, std::map<std::string, double>> lastStats() const;

    /// The description with current parameter values (non-default ones).
    GraphDesc desc() const;

    /// Human-readable plan (for `loom check`) and Graphviz. With a scene set, the section on what does not run also
    /// lists the work each live pass leaves out (RenderPass::skippedWork) for the scene and its parameters.
    std::string planText() const;
    std::string planDot() const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
    CompiledPlan mPlan;
    CompileOptions mOptions;
    FieldObserver mObserver;
    bool mCompiled = false;
};

/// fnmatch-style glob ('*', '?', '[...]') over a whole string.
bool globMatch(const std::string& pattern, const std::string& text);

}  // namespace loom
