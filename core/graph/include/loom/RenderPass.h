#pragma once
// The interface every render-pass plugin implements, and what it sees while
// executing.
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <glm/vec2.hpp>

#include "loom/Device.h"
#include "loom/Params.h"
#include "loom/Reflection.h"
#include "loom/Texture.h"

namespace loom {

class Scene;   // defined by the scene module
struct Camera; // defined by the scene module

/// What the compiler tells a pass when it reflects and compiles.
///
/// reflect() runs twice per compile. The first time (wired == false) the
/// lists are empty: the inputs and outputs declared then are what the graph
/// is wired from, and a pass declares every internal and history field it
/// might use. Once the wiring is known, each live pass reflects again with
/// wired == true and the lists filled: it must declare the same inputs and
/// outputs, and may leave out internal and history fields these connections
/// do not need (scratch of a signal that is not connected, say). Only the
/// second declaration is allocated. compile() sees the second one's info.
struct CompileInfo {
    uint32_t frameWidth = 0;
    uint32_t frameHeight = 0;
    /// The inputs that are connected, and the outputs that are computed
    /// (required ones, and optional ones someone consumes: an optional output
    /// not listed here is neither allocated nor expected). Filled when wired.
    std::vector<std::string> connectedInputs;
    std::vector<std::string> consumedOutputs;
    /// The outputs something other than an observer needs: another pass reads
    /// them (this frame or, through "@prev", the next), or the graph marks
    /// them. An output that is only observed (dumped, shown) is consumed but
    /// not read: a pass may fill what it cannot produce there, and must
    /// refuse it where the output is read.
    std::vector<std::string> readOutputs;
    /// This pass's fields that CompileOptions::observe matches (dumped, shown):
    /// a pass that leaves parts of a field unwritten where nothing of its own
    /// reads them must write them in full when the field is observed.
    std::vector<std::string> observedFields;
    bool wired = false;  ///< the lists above are filled (second reflect, compile)
    bool isInputConnected(std::string_view name) const;
    bool isOutputConsumed(std::string_view name) const;
    bool isOutputRead(std::string_view name) const;
    bool isObserved(std::string_view name) const;
};

/// Counters a pass reports for the frame (rays traced, samples dropped...).
class Stats {
public:
    void add(const std::string& name, double value) { mValues[name] += value; }
    void set(const std::string& name, double value) { mValues[name] = value; }
    const std::map<std::string, double>& values() const { return mValues; }
    void clear() { mValues.clear(); }

private:
    std::map<std::string, double> mValues;
};

/// One bound field of a pass during execute.
struct BoundField {
    std::string name;
    FieldKind kind;
    Texture* cur = nullptr;   ///< input, output, internal, or history "cur"
    Texture* prev = nullptr;  ///< history "prev"; for inputs fed by an @prev edge, unused
    const bool* valid = nullptr;  ///< history pairs and @prev inputs: does prev hold a real frame?
};

/// What a pass sees while executing one frame.
class PassContext {
public:
    /// Input texture; nullptr for an optional input that is not connected.
    const Texture* input(std::string_view name) const;
    /// Output texture; nullptr for an optional output nobody consumes.
    Texture* output(std::string_view name) const;
    /// Transient scratch texture (contents undefined on entry).
    Texture* internal(std::string_view name) const;
    /// History field: last frame's value (read) and this frame's (write).
    const Texture& historyPrev(std::string_view name) const;
    Texture& historyCur(std::string_view name) const;
    /// False on the first frame, after a reset, resize or camera cut: then
    /// the prev side of every history field (and of @prev inputs) is zero.
    bool historyValid() const { return mHistoryValid; }
    /// Whether a parameter of a pass this one reads from, directly or through other passes, changed value since
    /// the last frame, or the graph's description was replaced: what this pass receives may differ although
    /// nothing in the scene moved. Parameters with the role Seed or SampleCount do not count (they change the
    /// noise, not the image the samples estimate); nor do this pass's own. A pass that accumulates frames
    /// restarts on it.
    bool inputParamsChanged() const { return mInputParamsChanged; }

    uint64_t frameIndex() const { return mFrameIndex; }
    double time() const { return mTime; }
    uint32_t frameWidth() const { return mFrameWidth; }
    uint32_t frameHeight() const { return mFrameHeight; }
    const Scene* scene() const { return mScene; }
    const Camera* camera() const { return mCamera; }
    Stats& stats() const { return *mStats; }
    const std::string& passName() const { return mPassName; }
    /// The device the graph placed the pass on: where its fields live and its kernels launch (launch2D).
    DeviceKind device() const { return mDevice; }

private:
    friend class RenderGraph;
    const BoundField* find(std::string_view name, FieldKind kind) const;
    std::string mPassName;
    DeviceKind mDevice = DeviceKind::Cpu;
    std::vector<BoundField> mFields;
    bool mHistoryValid = false;
    bool mInputParamsChanged = false;
    uint64_t mFrameIndex = 0;
    double mTime = 0.0;
    uint32_t mFrameWidth = 0, mFrameHeight = 0;
    const Scene* mScene = nullptr;
    const Camera* mCamera = nullptr;
    Stats* mStats = nullptr;
};

/// A render pass. Plugins subclass it and register a factory.
class RenderPass {
public:
    virtual ~RenderPass() = default;

    /// Declares fields. Must not depend on parameter values: changing a
    /// parameter never reallocates.
    virtual void reflect(Reflection& r, const CompileInfo& info) const = 0;
    /// Declares parameters, bound to members (called once after creation).
    virtual void declareParams(ParamList& params) { (void)params; }
    /// Called after the graph is compiled (sizes and connections known).
    virtual void compile(const CompileInfo& info) { (void)info; }
    /// Renders one frame.
    virtual void execute(PassContext& ctx) = 0;
    virtual void setScene(const std::shared_ptr<const Scene>& scene) { (void)scene; }
    /// Forget any state carried from previous frames (graph history is
    /// reset by the graph itself).
    virtual void resetHistory() {}
    /// Work this pass leaves out for the current scene and parameters, one line each, "what: why" (for example
    /// "emissive-triangle sampling: the scene has no emissive triangles"). `loom check` lists them; the graph
    /// never calls it while rendering. Called after setScene and compile.
    virtual std::vector<std::string> skippedWork() const { return {}; }
    /// The frame size this pass's own data has, where it has one: a source that reads images (ImageSequence answers
    /// with its first frame's size). Asked after the parameters are set and before compile; the commands render at
    /// it when no --size is given (RenderGraph::naturalSize). Throws loom::Error (BadInput) where the data cannot
    /// be read, naming the parameter by the pass type ("ImageSequence.path"): the graph puts the pass's name there.
    virtual std::optional<glm::uvec2> naturalSize() const { return std::nullopt; }
    /// Whether the pass's kernels run on `device` (docs/KERNELS.md). The CPU only by default: the graph runs such a
    /// pass on the CPU wherever it is asked to run, and transfers what crosses devices.
    virtual bool runsOn(DeviceKind device) const { return device == DeviceKind::Cpu; }

    ParamList& params() { return mParams; }
    const ParamList& params() const { return mParams; }

private:
    ParamList mParams;
};

}  // namespace loom
