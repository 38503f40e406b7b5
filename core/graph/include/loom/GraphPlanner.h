#pragma once
// The graph compiler's pure half: from a graph description and its passes' reflections to a plan. It resolves
// edges, wires inputs by name, culls, orders, asks live passes for their second reflection, and plans memory
// (lifetimes, arena placement). It creates no pass and allocates nothing: RenderGraph creates the passes, reflects
// them, and binds memory as the plan says. Every step is O(n log n) in the number of passes and fields.
#include <cstdint>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include "loom/Graph.h"
#include "loom/RenderGraph.h"

namespace loom {

/// "Pass.field": how fields are named in references, resources, globs and dump files.
inline std::string fieldKey(const std::string& pass, const std::string& field) { return pass + "." + field; }

/// What the planner reads. `reflections` holds one first reflection per pass of `desc`, in description order.
struct PlannerInput {
    const GraphDesc* desc = nullptr;
    std::vector<Reflection> reflections;
    uint32_t width = 0, height = 0;
    std::vector<std::string> observe;  ///< CompileOptions::observe
    /// Where each pass runs, in description order (empty: all on the CPU); notes say why a pass runs elsewhere
    /// than asked.
    std::vector<DeviceKind> devices;
    std::vector<std::string> deviceNotes;
    /// A live pass's second reflection, given its connections (CompileInfo::wired); empty: the first one stays.
    std::function<Reflection(size_t pass, const CompileInfo& info)> reflectWired;
};

/// An input of a live pass and what feeds it.
struct PlannedInput {
    std::string field;
    uint32_t srcPass = 0;  ///< index in the description
    std::string srcField;
    bool prev = false;  ///< last frame's value (the source is a history pair)
    int transfer = -1;  ///< the copy it reads (summary.transfers) when the source is on another device
};

/// One pass of the plan, at its index in the description.
struct PassPlan {
    bool live = false;
    int position = -1;                  ///< in the execution order; -1 when culled
    DeviceKind device = DeviceKind::Cpu;  ///< where it runs; its outputs, internals and history live there
    Reflection reflection;              ///< the second reflection of a live pass, else the first
    CompileInfo info;                   ///< wired: what compile() receives
    std::vector<PlannedInput> inputs;   ///< connected inputs
    std::vector<std::string> observed;  ///< fields shown to the field observer
    std::set<std::string> consumed;     ///< outputs read this frame, marked or observed
    std::set<std::string> history;      ///< outputs read next frame (@prev): kept in history pairs
    std::set<std::string> kept;         ///< marked outputs and observed fields: readable after the frame
};

/// The plan: per pass, the execution order, and the summary `loom check` prints (with resources once placed).
struct GraphPlan {
    std::vector<PassPlan> passes;
    std::vector<uint32_t> order;  ///< live pass indices in execution order
    CompiledPlan summary;
};

/// Resolves, wires, culls, orders and reflects again, and records why each culled pass, optional output not
/// computed, optional input not connected and field a live pass leaves out is missing (summary.notRun; the culled
/// passes' reasons are also summary.culled's). Throws loom::Error (bad input naming the graph file, or a
/// runtime error naming a pass whose reflections are faulty) at the first problem.
GraphPlan planGraph(const PlannerInput& input);

/// Lifetimes and memory: fills summary.resources (history pairs, then transients with their arena offsets), the
/// byte counts and the skipped optional outputs, and the transfers where a field crosses devices (a copy on the
/// reader's device, a transient there, made before the first reader on that device runs; a host copy of each
/// marked output and observed field of a pass off the host). Each device has its own arena. Transients are placed largest first, each at the lowest offset
/// free of every placed transient whose lifetime overlaps its own.
void planResources(GraphPlan& plan, const GraphDesc& desc);

}  // namespace loom
