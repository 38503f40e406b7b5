// The graph planner from lists of reflections, without plugins: wiring by name, culling, order, cycles, second
// reflections, lifetimes and arena placement, and why what does not run or gets no memory is left out.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/GraphPlanner.h"

using namespace loom;
using loom::test::expectError;

namespace {

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

/// A pass for the planner: its name, and its fields as "kind:name" ("in:color", "out:color", "opt-in:albedo",
/// "opt-out:mask", "int:scratch", "hist:moments"), all RGBA32F at the frame size.
struct TestPass {
    std::string name;
    std::vector<std::string> fields;
    std::vector<std::string> unconnected = {};  ///< optional inputs the pass asks to leave unconnected
};

Reflection reflectionOf(const std::vector<std::string>& fields) {
    Reflection r;
    for (const auto& f : fields) {
        const auto colon = f.find(':');
        const std::string kind = f.substr(0, colon), name = f.substr(colon + 1);
        if (kind == "in") r.input(name, Format::RGBA32F);
        if (kind == "opt-in") r.input(name, Format::RGBA32F).optional();
        if (kind == "out") r.output(name, Format::RGBA32F);
        if (kind == "opt-out") r.output(name, Format::RGBA32F).optional();
        if (kind == "int") r.internal(name, Format::RGBA32F);
        if (kind == "hist") r.history(name, Format::RGBA32F);
        if (kind == "hist-in-place") r.history(name, Format::RGBA32F).inPlace();
        if (kind == "int-in-place") r.internal(name, Format::RGBA32F).inPlace();
    }
    return r;
}

struct Planned {
    GraphDesc desc;
    GraphPlan plan;
    std::vector<std::string> order() const { return plan.summary.order; }
};

Planned plan(const std::vector<TestPass>& passes, const std::vector<std::pair<std::string, std::string>>& edges,
             const std::vector<std::string>& outputs, const std::vector<std::string>& observe = {}, uint32_t size = 8) {
    Planned p;
    PlannerInput in;
    for (const auto& t : passes) {
        p.desc.passes.push_back({t.name, "T" + t.name, nlohmann::json::object(), t.unconnected});
        in.reflections.push_back(reflectionOf(t.fields));
    }
    for (const auto& [src, dst] : edges)
        p.desc.edges.push_back({parseChannelRef(src, "edge"), parseChannelRef(dst, "edge")});
    for (const auto& o : outputs) p.desc.outputs.push_back(parseChannelRef(o, "output"));
    in.desc = &p.desc;
    in.width = in.height = size;
    in.observe = observe;
    p.plan = planGraph(in);
    planResources(p.plan, p.desc);
    return p;
}

const ResourceInfo* resource(const GraphPlan& plan, const std::string& name) {
    for (const auto& r : plan.summary.resources)
        if (r.name == name) return &r;
    return nullptr;
}

/// No two transients whose lifetimes overlap share arena bytes, and every transient lies inside the arena.
void expectPlacementIsSound(const GraphPlan& plan) {
    const auto& rs = plan.summary.resources;
    for (size_t i = 0; i < rs.size(); ++i) {
        if (rs[i].kind != ResourceKind::Transient) continue;
        EXPECT_LE(rs[i].offset + rs[i].bytes, plan.summary.transientPeakBytes) << rs[i].name;
        for (size_t j = i + 1; j < rs.size(); ++j) {
            if (rs[j].kind != ResourceKind::Transient) continue;
            const bool alive = rs[i].firstUse <= rs[j].lastUse && rs[j].firstUse <= rs[i].lastUse;
            const bool share = rs[i].offset < rs[j].offset + rs[j].bytes && rs[j].offset < rs[i].offset + rs[i].bytes;
            EXPECT_FALSE(alive && share) << rs[i].name << " and " << rs[j].name;
        }
    }
}

}  // namespace

TEST(GraphPlanner, WiresByNameCullsAndOrders) {
    const Planned p =
        plan({{"Tone", {"in:hdr", "out:ldr"}}, {"Unused", {"in:hdr", "out:other"}}, {"Render", {"out:hdr"}}}, {},
             {"Tone.ldr"});
    EXPECT_EQ(p.order(), (std::vector<std::string>{"Render", "Tone"}));
    ASSERT_EQ(p.plan.summary.culled.size(), 1u);
    EXPECT_EQ(p.plan.summary.culled[0].name, "Unused");
    ASSERT_EQ(p.plan.summary.wires.size(), 1u);
    EXPECT_TRUE(p.plan.summary.wires[0].byName);
    EXPECT_EQ(p.plan.summary.wires[0].src.str(), "Render.hdr");
    const PassPlan& tone = p.plan.passes[0];
    ASSERT_EQ(tone.inputs.size(), 1u);
    EXPECT_EQ(tone.inputs[0].srcPass, 2u);
    EXPECT_EQ(tone.position, 1);
    EXPECT_EQ(p.plan.passes[1].position, -1);
    EXPECT_TRUE(tone.info.wired);
    EXPECT_EQ(tone.info.connectedInputs, std::vector<std::string>{"hdr"});
}

TEST(GraphPlanner, IndependentPassesRunInDescriptionOrder) {
    const Planned p = plan({{"C", {"out:c"}}, {"A", {"out:a"}}, {"B", {"out:b"}}}, {}, {"A.a", "B.b", "C.c"});
    EXPECT_EQ(p.order(), (std::vector<std::string>{"C", "A", "B"}));
}

TEST(GraphPlanner, ExplicitEdgesOverrideWiringByName) {
    const Planned p =
        plan({{"A", {"out:x"}}, {"B", {"out:x"}}, {"Use", {"in:x", "out:y"}}}, {{"B.x", "Use.x"}}, {"Use.y"});
    EXPECT_EQ(p.order(), (std::vector<std::string>{"B", "Use"}));
    ASSERT_EQ(p.plan.summary.wires.size(), 1u);
    EXPECT_FALSE(p.plan.summary.wires[0].byName);
}

TEST(GraphPlanner, AmbiguousAndMissingInputsAreErrorsOnlyWhenLive) {
    Error ambiguous = expectError([] {
        plan({{"A", {"out:x"}}, {"B", {"out:x"}}, {"Use", {"in:x", "out:y"}}}, {}, {"Use.y"});
    });
    EXPECT_TRUE(contains(ambiguous.what(), "ambiguous: several passes output 'x': A.x, B.x")) << ambiguous.what();
    Error missing = expectError([] { plan({{"Use", {"in:x", "out:y"}}}, {}, {"Use.y"}); });
    EXPECT_TRUE(contains(missing.what(), "no pass outputs a channel named 'x'")) << missing.what();
    // Culled, the same problem is a warning.
    const Planned p = plan({{"Use", {"in:x", "out:y"}}, {"Other", {"out:z"}}}, {}, {"Other.z"});
    ASSERT_EQ(p.plan.summary.warnings.size(), 1u);
    EXPECT_TRUE(contains(p.plan.summary.warnings[0], "Use (culled)")) << p.plan.summary.warnings[0];
}

TEST(GraphPlanner, CycleIsNamedAndPrevBreaksIt) {
    const std::vector<TestPass> passes = {{"A", {"in:b", "out:a"}}, {"B", {"in:a", "out:b"}}};
    Error e = expectError([&] { plan(passes, {}, {"B.b"}); });
    EXPECT_TRUE(contains(e.what(), "the graph has a cycle: B -> A -> B")) << e.what();
    const Planned p = plan(passes, {{"B.b@prev", "A.b"}}, {"B.b"});
    EXPECT_EQ(p.order(), (std::vector<std::string>{"A", "B"}));
    const ResourceInfo* history = resource(p.plan, "B.b");
    ASSERT_NE(history, nullptr);
    EXPECT_EQ(history->kind, ResourceKind::History);
    EXPECT_TRUE(p.plan.passes[0].inputs[0].prev);
}

TEST(GraphPlanner, SecondReflectionMayDropInternalsButNotPorts) {
    GraphDesc desc;
    desc.passes.push_back({"P", "T", nlohmann::json::object(), {}});
    desc.outputs.push_back(parseChannelRef("P.out", "output"));
    PlannerInput in;
    in.desc = &desc;
    in.width = in.height = 4;
    in.reflections.push_back(reflectionOf({"opt-in:src", "out:out", "int:scratch"}));
    in.observe = {"P.scratch"};
    in.reflectWired = [](size_t, const CompileInfo& info) {
        EXPECT_TRUE(info.wired);
        EXPECT_TRUE(info.connectedInputs.empty());
        return reflectionOf({"opt-in:src", "out:out"});
    };
    GraphPlan p = planGraph(in);
    EXPECT_EQ(p.passes[0].reflection.fields().size(), 2u);
    ASSERT_EQ(p.summary.warnings.size(), 1u);
    EXPECT_TRUE(contains(p.summary.warnings[0], "'P.scratch' is not computed")) << p.summary.warnings[0];
    in.reflectWired = [](size_t, const CompileInfo&) { return reflectionOf({"out:out"}); };
    Error e = expectError([&] { (void)planGraph(in); });
    EXPECT_TRUE(contains(e.what(), "other inputs or outputs")) << e.what();
}

TEST(GraphPlanner, OptionalOutputsNobodyReadsAreSkipped) {
    const Planned p = plan({{"A", {"out:x", "opt-out:mask"}}}, {}, {"A.x"});
    EXPECT_EQ(p.plan.summary.skippedOutputs, std::vector<std::string>{"A.mask"});
    EXPECT_EQ(resource(p.plan, "A.mask"), nullptr);
    const Planned observed = plan({{"A", {"out:x", "opt-out:mask"}}}, {}, {"A.x"}, {"A.*"});
    EXPECT_TRUE(observed.plan.summary.skippedOutputs.empty());
    EXPECT_NE(resource(observed.plan, "A.mask"), nullptr);
}

// Observing (dumping, showing) a field never changes what its pass is told it must produce: an output another pass
// reads, one read next frame through "@prev", or a marked one is read whether or not it is also observed; one that
// is only observed is consumed (computed) but not read.
TEST(GraphPlanner, ObservingAnOutputDoesNotChangeWhetherItIsRead) {
    const std::vector<TestPass> passes = {{"Src", {"opt-out:color", "opt-out:aux", "opt-out:spare", "opt-out:late"}},
                                          {"Use", {"in:color", "opt-in:lateIn", "out:shown"}}};
    const std::vector<std::pair<std::string, std::string>> edges = {{"Src.late@prev", "Use.lateIn"}};
    for (const std::vector<std::string>& observe :
         {std::vector<std::string>{}, {"Src.color"}, {"Src.*"}, {"Src.color", "Src.late", "Use.*"}}) {
        const Planned p = plan(passes, edges, {"Use.shown", "Src.aux"}, observe);
        const CompileInfo& src = p.plan.passes[0].info;
        const std::string label = ::testing::PrintToString(observe);
        EXPECT_TRUE(src.isOutputRead("color")) << label;  // Use reads it
        EXPECT_TRUE(src.isOutputRead("aux")) << label;    // marked
        EXPECT_TRUE(src.isOutputRead("late")) << label;   // read next frame
        EXPECT_FALSE(src.isOutputRead("spare")) << label;
        EXPECT_EQ(src.isOutputConsumed("spare"), std::find(observe.begin(), observe.end(), "Src.*") != observe.end())
            << label;
        EXPECT_TRUE(p.plan.passes[1].info.isOutputRead("shown")) << label;
    }
}

// A chain ping-pongs: each output lives from its writer to its reader, so two textures' worth of arena serve any
// length; the marked output lives to the end of the frame.
TEST(GraphPlanner, ChainPlacementPingPongs) {
    for (int n : {2, 3, 10, 2000}) {
        std::vector<TestPass> passes = {{"P0", {"out:c0"}}};
        for (int i = 1; i < n; ++i)
            passes.push_back({"P" + std::to_string(i), {"in:c" + std::to_string(i - 1), "out:c" + std::to_string(i)}});
        const Planned p = plan(passes, {}, {"P" + std::to_string(n - 1) + ".c" + std::to_string(n - 1)});
        ASSERT_EQ(p.order().size(), size_t(n));
        const size_t bytes = textureByteSize(8, 8, Format::RGBA32F);
        EXPECT_EQ(p.plan.summary.transientPeakBytes, 2 * bytes) << n << " passes";
        EXPECT_EQ(p.plan.summary.transientSumBytes, size_t(n) * bytes);
        const ResourceInfo* last = resource(p.plan, "P" + std::to_string(n - 1) + ".c" + std::to_string(n - 1));
        ASSERT_NE(last, nullptr);
        EXPECT_EQ(last->lastUse, n);
        if (n <= 10) expectPlacementIsSound(p.plan);
    }
}

// A diamond with scratch fields and different sizes: whatever the order of placement, live transients never share
// bytes (checked pairwise), and the arena is no larger than the sum.
TEST(GraphPlanner, PlacementNeverSharesLiveBytes) {
    const Planned p = plan({{"Src", {"out:a", "int:s0"}},
                            {"Left", {"in:a", "out:l", "int:s1", "int:s2"}},
                            {"Right", {"in:a", "out:r", "int:s3"}},
                            {"Join", {"in:l", "in:r", "out:j", "int:s4"}},
                            {"Tail", {"in:j", "out:t"}}},
                           {}, {"Tail.t", "Left.l"}, {}, 16);
    expectPlacementIsSound(p.plan);
    EXPECT_LT(p.plan.summary.transientPeakBytes, p.plan.summary.transientSumBytes);
    EXPECT_EQ(resource(p.plan, "Left.l")->lastUse, 5);  // marked: kept after the frame
    EXPECT_EQ(resource(p.plan, "Src.a")->lastUse, 2);   // read by Left (1) and Right (2)
}

// ---------------------------------------------------------------------------------------------------------------
// Why what does not run or gets no memory is left out

namespace {

/// The entry of plan.notRun for a pass (field empty) or a field; nullptr when there is none.
const NotRun* notRun(const GraphPlan& plan, const std::string& pass, const std::string& field = {}) {
    for (const auto& n : plan.summary.notRun)
        if (n.pass == pass && n.field == field) return &n;
    return nullptr;
}

/// The list agrees with the rest of the plan: culled passes are exactly those without a position; a listed field
/// has no memory; the optional outputs listed as not computed are exactly the skipped ones; passes come in
/// description order.
void expectNotRunAgreesWithThePlan(const Planned& p) {
    const CompiledPlan& s = p.plan.summary;
    std::vector<std::string> culled, notComputed;
    size_t lastPass = 0;
    for (const auto& n : s.notRun) {
        EXPECT_FALSE(n.reason.empty()) << n.pass << "." << n.field;
        size_t index = 0;
        while (index < p.desc.passes.size() && p.desc.passes[index].name != n.pass) ++index;
        ASSERT_LT(index, p.desc.passes.size()) << n.pass;
        EXPECT_GE(index, lastPass) << n.pass << " out of description order";
        lastPass = index;
        if (n.kind == NotRunKind::Culled) {
            EXPECT_TRUE(n.field.empty());
            EXPECT_EQ(p.plan.passes[index].position, -1) << n.pass;
            culled.push_back(n.pass);
        } else {
            EXPECT_TRUE(p.plan.passes[index].live) << n.pass;
            EXPECT_EQ(resource(p.plan, fieldKey(n.pass, n.field)), nullptr) << n.pass << "." << n.field;
        }
        if (n.kind == NotRunKind::NotComputed) notComputed.push_back(fieldKey(n.pass, n.field));
    }
    std::vector<std::string> culledInPlan;
    for (const auto& c : s.culled) culledInPlan.push_back(c.name);
    EXPECT_EQ(culled, culledInPlan);
    EXPECT_EQ(notComputed, s.skippedOutputs);
    for (size_t i = 0; i < p.plan.passes.size(); ++i) {
        if (!p.plan.passes[i].live) {
            EXPECT_NE(notRun(p.plan, p.desc.passes[i].name), nullptr) << i;
        }
    }
}

}  // namespace

// A pass is culled because nothing reads its outputs, because only culled passes do (named), because only itself
// does (@prev), or because it has no outputs.
TEST(GraphPlannerWhy, CulledPassesSayWhy) {
    const Planned p = plan({{"Render", {"out:hdr"}},
                            {"Tone", {"in:hdr", "out:ldr"}},
                            {"Dead", {"out:dead"}},
                            {"Feeder", {"out:f"}},
                            {"Reader", {"in:f", "out:r"}},
                            {"Loop", {"in:back", "out:fwd"}},
                            {"Sink", {"in:hdr"}}},
                           {{"Loop.fwd@prev", "Loop.back"}}, {"Tone.ldr"});
    EXPECT_EQ(p.order(), (std::vector<std::string>{"Render", "Tone"}));
    expectNotRunAgreesWithThePlan(p);
    EXPECT_EQ(p.plan.summary.notRun.size(), 5u);
    for (const std::string pass : {"Dead", "Feeder", "Reader", "Loop", "Sink"}) {
        const NotRun* n = notRun(p.plan, pass);
        ASSERT_NE(n, nullptr) << pass;
        EXPECT_EQ(n->kind, NotRunKind::Culled);
    }
    EXPECT_EQ(notRun(p.plan, "Dead")->reason, "no pass reads its outputs, and none is marked or observed");
    EXPECT_EQ(notRun(p.plan, "Feeder")->reason, "only culled passes read its outputs: Reader");
    EXPECT_EQ(notRun(p.plan, "Reader")->reason, "no pass reads its outputs, and none is marked or observed");
    EXPECT_TRUE(contains(notRun(p.plan, "Loop")->reason, "only itself reads its outputs (through @prev)"))
        << notRun(p.plan, "Loop")->reason;
    EXPECT_TRUE(contains(notRun(p.plan, "Sink")->reason, "it has no outputs")) << notRun(p.plan, "Sink")->reason;
    // Render feeds a culled pass too, but it is live: only culled passes are listed.
    EXPECT_EQ(notRun(p.plan, "Render"), nullptr);
    EXPECT_EQ(p.plan.summary.culled[1].reason, notRun(p.plan, "Feeder")->reason);
}

// The readers a reason names are distinct, in description order, and capped with a count of the rest.
TEST(GraphPlannerWhy, ManyCulledReadersAreCounted) {
    std::vector<TestPass> passes = {{"Out", {"out:o"}}, {"Shared", {"out:m"}}};
    for (int i = 5; i >= 0; --i) passes.push_back({"R" + std::to_string(i), {"in:m", "out:r" + std::to_string(i)}});
    const Planned p = plan(passes, {}, {"Out.o"});
    expectNotRunAgreesWithThePlan(p);
    EXPECT_EQ(notRun(p.plan, "Shared")->reason, "only culled passes read its outputs: R5, R4, R3, R2 and 2 more");
}

// An optional output of a live pass is not computed because only culled passes read it, or nothing does; inputs of
// its name that are listed as unconnected, or that read another output, are named.
TEST(GraphPlannerWhy, OptionalOutputsNotComputedSayWhy) {
    const Planned p = plan(
        {{"A",
          {"out:x", "opt-out:mask", "opt-out:depth", "opt-out:spare", "opt-out:y", "opt-out:kept", "opt-out:seen"}},
         {"Culled", {"in:mask", "out:c"}},
         {"U", {"opt-in:depth", "out:u"}, {"depth"}},
         {"Y", {"out:y"}},
         {"V", {"in:y", "in:kept", "out:v"}}},
        {{"Y.y", "V.y"}}, {"A.x", "U.u", "V.v"}, {"A.seen"});
    expectNotRunAgreesWithThePlan(p);
    const NotRun* mask = notRun(p.plan, "A", "mask");
    ASSERT_NE(mask, nullptr);
    EXPECT_EQ(mask->kind, NotRunKind::NotComputed);
    EXPECT_EQ(mask->reason, "optional, and only culled passes read it: Culled");
    const NotRun* depth = notRun(p.plan, "A", "depth");
    ASSERT_NE(depth, nullptr);
    EXPECT_EQ(depth->reason,
              "optional, not marked or observed, and no pass reads it (U.depth is listed as unconnected)");
    const NotRun* y = notRun(p.plan, "A", "y");
    ASSERT_NE(y, nullptr);
    EXPECT_EQ(y->reason, "optional, not marked or observed, and no pass reads it (V.y reads Y.y)");
    const NotRun* spare = notRun(p.plan, "A", "spare");
    ASSERT_NE(spare, nullptr);
    EXPECT_EQ(spare->reason, "optional, not marked or observed, and no pass reads it");
    // Read (by name), or observed: computed, allocated and not listed.
    EXPECT_EQ(notRun(p.plan, "A", "kept"), nullptr);
    EXPECT_NE(resource(p.plan, "A.kept"), nullptr);
    EXPECT_EQ(notRun(p.plan, "A", "seen"), nullptr);
    EXPECT_NE(resource(p.plan, "A.seen"), nullptr);
}

// An optional input of a live pass is not connected because the pass lists it as unconnected, or because no other
// pass outputs a channel of its name; a connected one, and a culled pass's inputs, are not listed.
TEST(GraphPlannerWhy, UnconnectedInputsSayWhy) {
    const Planned p = plan({{"Src", {"out:color", "out:direct"}},
                            {"P", {"in:color", "opt-in:direct", "opt-in:albedo", "out:o"}, {"direct"}},
                            {"Off", {"opt-in:nothing", "out:off"}}},
                           {}, {"P.o"});
    expectNotRunAgreesWithThePlan(p);
    const NotRun* direct = notRun(p.plan, "P", "direct");
    ASSERT_NE(direct, nullptr);
    EXPECT_EQ(direct->kind, NotRunKind::NotConnected);
    EXPECT_EQ(direct->reason, "optional, and listed in the pass's \"unconnected\"");
    const NotRun* albedo = notRun(p.plan, "P", "albedo");
    ASSERT_NE(albedo, nullptr);
    EXPECT_EQ(albedo->reason, "optional, and no pass outputs a channel named 'albedo'");
    EXPECT_EQ(notRun(p.plan, "P", "color"), nullptr);
    EXPECT_EQ(notRun(p.plan, "Off", "nothing"), nullptr);  // the pass is listed, not its fields
    EXPECT_EQ(notRun(p.plan, "Off")->kind, NotRunKind::Culled);
    // A required output nobody reads is still computed: not listed.
    EXPECT_EQ(notRun(p.plan, "Src", "direct"), nullptr);
    EXPECT_NE(resource(p.plan, "Src.direct"), nullptr);
}

// Internal and history fields the second reflection leaves out get no memory and say so; fields that share the
// arena or live in a history pair are allocated and not listed.
TEST(GraphPlannerWhy, FieldsLeftOutSayWhy) {
    GraphDesc desc;
    desc.passes.push_back({"P", "T", nlohmann::json::object(), {}});
    desc.passes.push_back({"Q", "T", nlohmann::json::object(), {}});
    desc.outputs.push_back(parseChannelRef("Q.q", "output"));
    desc.edges.push_back({parseChannelRef("P.out@prev", "edge"), parseChannelRef("Q.back", "edge")});
    PlannerInput in;
    in.desc = &desc;
    in.width = in.height = 4;
    in.reflections.push_back(reflectionOf({"out:out", "out:now", "int:scratch", "hist:moments", "int:used"}));
    in.reflections.push_back(reflectionOf({"in:back", "in:now", "out:q", "int:tmp"}));
    in.reflectWired = [](size_t pass, const CompileInfo&) {
        return pass == 0 ? reflectionOf({"out:out", "out:now", "int:used"})
                         : reflectionOf({"in:back", "in:now", "out:q", "int:tmp"});
    };
    Planned p;
    p.desc = desc;
    p.plan = planGraph(in);
    planResources(p.plan, desc);
    expectNotRunAgreesWithThePlan(p);
    ASSERT_EQ(p.plan.summary.notRun.size(), 2u);
    const NotRun* scratch = notRun(p.plan, "P", "scratch");
    ASSERT_NE(scratch, nullptr);
    EXPECT_EQ(scratch->kind, NotRunKind::NotAllocated);
    EXPECT_EQ(scratch->reason, "internal field the pass does not use with these connections");
    const NotRun* moments = notRun(p.plan, "P", "moments");
    ASSERT_NE(moments, nullptr);
    EXPECT_EQ(moments->reason, "history field the pass does not use with these connections");
    // A history pair (P.out, read @prev) and arena transients are allocated.
    ASSERT_NE(resource(p.plan, "P.out"), nullptr);
    EXPECT_EQ(resource(p.plan, "P.out")->kind, ResourceKind::History);
    EXPECT_NE(resource(p.plan, "P.used"), nullptr);
    EXPECT_NE(resource(p.plan, "Q.tmp"), nullptr);
}

// A graph where everything runs and is allocated lists nothing.
TEST(GraphPlannerWhy, NothingLeftOutListsNothing) {
    const Planned p = plan({{"A", {"out:a", "opt-out:b"}}, {"B", {"in:a", "in:b", "out:c"}}}, {}, {"B.c"});
    EXPECT_TRUE(p.plan.summary.notRun.empty());
}

TEST(GraphPlanner, AFieldRoleFitsOneFieldOfItsKind) {
    const auto planWith = [](Reflection r) {
        GraphDesc desc;
        desc.passes.push_back({"P", "T", nlohmann::json::object(), {}});
        desc.outputs.push_back(parseChannelRef("P.out", "output"));
        PlannerInput in;
        in.desc = &desc;
        in.width = in.height = 4;
        in.reflections.push_back(std::move(r));
        return planGraph(in);
    };
    Reflection good = reflectionOf({"opt-in:src", "out:out"});
    good.input("display", Format::RGBA32F).optional().role(FieldRole::DisplayInput);
    EXPECT_NO_THROW((void)planWith(good));
    Reflection twice = good;
    twice.input("again", Format::RGBA32F).optional().role(FieldRole::DisplayInput);
    Error e = expectError([&] { (void)planWith(twice); });
    EXPECT_TRUE(contains(e.what(), "a second field with the role 'displayInput'")) << e.what();
    Reflection onOutput = reflectionOf({"opt-in:src"});
    onOutput.output("out", Format::RGBA32F).role(FieldRole::DisplayInput);
    e = expectError([&] { (void)planWith(onOutput); });
    EXPECT_TRUE(contains(e.what(), "cannot play the role 'displayInput'")) << e.what();
    Reflection wrongFormat = reflectionOf({"out:out"});
    wrongFormat.input("src", Format::R32F).optional().role(FieldRole::DisplayInput);
    e = expectError([&] { (void)planWith(wrongFormat); });
    EXPECT_TRUE(contains(e.what(), "cannot play the role")) << e.what();
}

// A history field updated in place is one texture: it counts once in the history bytes; inPlace on any other kind of
// field is the pass's error.
TEST(GraphPlanner, InPlaceHistoryIsOneTexture) {
    const Planned pair = plan({{"A", {"out:x", "hist:state"}}}, {}, {"A.x"});
    const Planned one = plan({{"A", {"out:x", "hist-in-place:state"}}}, {}, {"A.x"});
    const ResourceInfo* p = resource(pair.plan, "A.state");
    const ResourceInfo* o = resource(one.plan, "A.state");
    ASSERT_TRUE(p && o);
    EXPECT_FALSE(p->inPlace);
    EXPECT_TRUE(o->inPlace);
    EXPECT_EQ(pair.plan.summary.historyBytes, 2 * p->bytes);
    EXPECT_EQ(one.plan.summary.historyBytes, o->bytes);
    Error e = expectError([&] { (void)plan({{"A", {"out:x", "int-in-place:scratch"}}}, {}, {"A.x"}); });
    EXPECT_TRUE(contains(e.what(), "inPlace on history fields only")) << e.what();
}

// A field of one texel per block covers every pixel of the frame, a partial block at the right and bottom edges
// included: ceil(size / block), never 0.
TEST(Reflection, PerBlockFieldsCoverEveryPixel) {
    Reflection r;
    r.history("blocks", Format::RGBA32U).perBlock(3, 3);
    r.output("tiles", Format::R32U).perBlock(8, 4);
    uint32_t w = 0, h = 0;
    const FieldDesc& blocks = r.fields()[0];
    const FieldDesc& tiles = r.fields()[1];
    for (uint32_t size : {1u, 2u, 3u, 4u, 8u, 9u, 10u, 719u, 720u, 1280u, 1281u}) {
        blocks.resolveSize(size, size + 1, w, h);
        EXPECT_EQ(w, (size + 2) / 3) << size;
        EXPECT_EQ(h, (size + 3) / 3) << size;
        EXPECT_GE(w * 3, size);
        EXPECT_LT((w - 1) * 3, size);
        tiles.resolveSize(size, size, w, h);
        EXPECT_EQ(w, (size + 7) / 8) << size;
        EXPECT_EQ(h, (size + 3) / 4) << size;
    }
    // A block of 0 is taken as 1: the frame size.
    Reflection zero;
    zero.output("same", Format::R32F).perBlock(0, 0);
    zero.fields()[0].resolveSize(17, 5, w, h);
    EXPECT_EQ(w, 17u);
    EXPECT_EQ(h, 5u);
}
