// RenderGraph: wiring (explicit, by name, @prev), compile errors, culling, optional outputs, transient memory
// and NaN poisoning, history across frames and recompiles, field observation, determinism, desc().
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "loom/Error.h"
#include "loom/Graph.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Texture.h"

using namespace loom;

#define EXPECT_CONTAINS(text, part)                                                             \
    EXPECT_NE(std::string(text).find(part), std::string::npos) << "'" << (part) << "' not in:\n" \
                                                               << (text)

namespace {

/// Writes its "color" parameter to one RGBA32F output whose channel name is chosen at registration, so tests
/// can produce channels ("src", "bias") that the test passes only consume.
class FillPass final : public RenderPass {
public:
    explicit FillPass(std::string output) : mOutput(std::move(output)) {}
    void reflect(Reflection& r, const CompileInfo&) const override { r.output(mOutput, Format::RGBA32F); }
    void declareParams(ParamList& p) override { p.add("color", &mColor, glm::vec4(1.f)); }
    void execute(PassContext& ctx) override {
        auto dst = ctx.output(mOutput)->view<glm::vec4>();
        for (uint32_t y = 0; y < dst.height; ++y)
            for (uint32_t x = 0; x < dst.width; ++x) dst.at(x, y) = mColor;
    }

private:
    std::string mOutput;
    glm::vec4 mColor;
};

/// Consumes an R32F "mask" (by name: OptionalInput's optional output) and shows it in dst.r.
class MaskReaderPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input("mask", Format::R32F);
        r.output("dst", Format::RGBA32F);
    }
    void execute(PassContext& ctx) override {
        auto mask = ctx.input("mask")->view<float>();
        auto dst = ctx.output("dst")->view<glm::vec4>();
        for (uint32_t y = 0; y < dst.height; ++y)
            for (uint32_t x = 0; x < dst.width; ++x) dst.at(x, y) = glm::vec4(mask.at(x, y), 0.f, 0.f, 1.f);
    }
};

/// A pass whose compile() fails for frames wider than 100 pixels (like a pass with a size limit).
class WidthLimitPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override { r.output("out", Format::RGBA32F); }
    void compile(const CompileInfo& info) override {
        if (info.frameWidth > 100)
            throw Error(Error::Info{ErrorKind::Runtime, {}, "W.out", "frame too wide for this pass", {}, {}});
    }
    void execute(PassContext& ctx) override {
        auto dst = ctx.output("out")->view<glm::vec4>();
        for (uint32_t y = 0; y < dst.height; ++y)
            for (uint32_t x = 0; x < dst.width; ++x) dst.at(x, y) = glm::vec4(1.f);
    }
};

/// Adds its optional inputs "src" and "bias" into "dst". It keeps a history of src and a scratch copy of bias, and
/// once its connections are known (CompileInfo::wired) it declares each only when that input is connected; with
/// "changePorts" its second reflection also declares an extra output, which the compiler must refuse.
class ConnectionFieldsPass final : public RenderPass {
public:
    explicit ConnectionFieldsPass(bool changePorts = false) : mChangePorts(changePorts) {}
    void reflect(Reflection& r, const CompileInfo& info) const override {
        r.input("src", Format::RGBA32F).optional();
        r.input("bias", Format::RGBA32F).optional();
        r.output("dst", Format::RGBA32F);
        if (mChangePorts && info.wired) r.output("extra", Format::R32F);
        if (!info.wired || info.isInputConnected("src")) r.history("srcHistory", Format::RGBA32F);
        if (!info.wired || info.isInputConnected("bias")) r.internal("biasScratch", Format::RGBA32F);
    }
    void compile(const CompileInfo& info) override {
        mObserved = double(info.observedFields.size());
        mHistoryObserved = info.isObserved("srcHistory");
    }
    void execute(PassContext& ctx) override {
        ctx.stats().set("observedFields", mObserved);
        ctx.stats().set("srcHistoryObserved", mHistoryObserved ? 1.0 : 0.0);
        const Texture* src = ctx.input("src");
        const Texture* bias = ctx.input("bias");
        if (src) ctx.historyCur("srcHistory").copyFrom(*src);
        if (bias) ctx.internal("biasScratch")->copyFrom(*bias);
        auto dst = ctx.output("dst")->view<glm::vec4>();
        for (uint32_t y = 0; y < dst.height; ++y)
            for (uint32_t x = 0; x < dst.width; ++x)
                dst.at(x, y) = (src ? src->view<glm::vec4>().at(x, y) : glm::vec4(0.f)) +
                               (bias ? bias->view<glm::vec4>().at(x, y) : glm::vec4(0.f));
    }

private:
    bool mChangePorts;
    double mObserved = -1.0;
    bool mHistoryObserved = false;
};

/// A pass whose execute throws: a std::logic_error or, as a careless plugin might, an int.
class ThrowingPass final : public RenderPass {
public:
    explicit ThrowingPass(bool standard) : mStandard(standard) {}
    void reflect(Reflection& r, const CompileInfo&) const override { r.output("dst", Format::RGBA32F); }
    void execute(PassContext&) override {
        if (mStandard) throw std::logic_error("broken invariant");
        throw 42;
    }

private:
    bool mStandard;
};

/// A faulty plugin's pass: declares a field or a parameter it should not (which fault: the constructor's argument).
class BadDeclarationPass final : public RenderPass {
public:
    enum class Fault { FieldWithDot, EmptyField, ParamTwice, DefaultOutOfRange, DeclareThrows };
    explicit BadDeclarationPass(Fault fault) : mFault(fault) {}
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output(mFault == Fault::FieldWithDot ? "a.b" : mFault == Fault::EmptyField ? "" : "dst", Format::RGBA32F);
    }
    void declareParams(ParamList& p) override {
        if (mFault == Fault::ParamTwice) p.add("radius", &mInt, 1);
        if (mFault == Fault::DeclareThrows) throw std::runtime_error("no such table");
        p.add("radius", &mFloat, mFault == Fault::DefaultOutOfRange ? 9.f : 1.f).range(0, 4);
    }
    void execute(PassContext&) override {}

private:
    Fault mFault;
    int mInt = 0;
    float mFloat = 0.f;
};

/// The test passes plugin plus the pass types defined here (registered once per process).
PluginRegistry& registry() {
    static PluginRegistry reg({LOOM_TEST_PLUGIN_DIR}, false);
    static const bool registered = [] {
        reg.registerPass("SrcSource", "fills an output named 'src'", [] { return std::make_unique<FillPass>("src"); });
        reg.registerPass("BiasSource", "fills an output named 'bias'",
                         [] { return std::make_unique<FillPass>("bias"); });
        reg.registerPass("MaskReader", "reads 'mask'", [] { return std::make_unique<MaskReaderPass>(); });
        reg.registerPass("WidthLimit", "fails to compile above 100 pixels",
                         [] { return std::make_unique<WidthLimitPass>(); });
        reg.registerPass("ConnectionFields", "fields that depend on the connections",
                         [] { return std::make_unique<ConnectionFieldsPass>(); });
        reg.registerPass("PortChanger", "declares another output once wired",
                         [] { return std::make_unique<ConnectionFieldsPass>(true); });
        reg.registerPass("NullFactory", "a faulty plugin whose factory returns no pass",
                         []() -> std::unique_ptr<RenderPass> { return nullptr; });
        reg.registerPass("ThrowsInt", "a faulty plugin that throws an int from execute",
                         [] { return std::make_unique<ThrowingPass>(false); });
        reg.registerPass("ThrowsStd", "a faulty plugin that throws a std::logic_error from execute",
                         [] { return std::make_unique<ThrowingPass>(true); });
        using Fault = BadDeclarationPass::Fault;
        for (const auto& [type, fault] : std::vector<std::pair<std::string, Fault>>{
                 {"FieldWithDot", Fault::FieldWithDot},
                 {"EmptyField", Fault::EmptyField},
                 {"ParamTwice", Fault::ParamTwice},
                 {"DefaultOutOfRange", Fault::DefaultOutOfRange},
                 {"DeclareThrows", Fault::DeclareThrows}})
            reg.registerPass(type, "a faulty plugin's declarations",
                             [fault] { return std::make_unique<BadDeclarationPass>(fault); });
        return true;
    }();
    (void)registered;
    return reg;
}

/// A graph from JSON fragments: passes, edges and outputs arrays.
GraphDesc makeGraph(const std::string& passes, const std::string& edges, const std::string& outputs) {
    return parseGraph(R"({"loom_graph": 1, "name": "test", "passes": )" + passes + R"(, "edges": )" + edges +
                      R"(, "outputs": )" + outputs + "}");
}

GraphDesc testPatternGraph() { return loadGraph(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/TestPattern.json"); }

CompileOptions sized(uint32_t w = 64, uint32_t h = 64) {
    CompileOptions o;
    o.width = w;
    o.height = h;
    return o;
}

FrameInfo frameAt(uint64_t index) {
    FrameInfo f;
    f.frameIndex = index;
    f.time = double(index) / 60.0;
    return f;
}

/// Channel c of pixel (x, y) of a field after execute (NaN and a failure when the field has no texture).
float texel(const RenderGraph& g, const std::string& field, uint32_t c = 0, uint32_t x = 0, uint32_t y = 0) {
    const Texture* t = g.fieldTexture(field);
    if (!t) {
        ADD_FAILURE() << "no texture for " << field;
        return std::nanf("");
    }
    return t->texel(x, y, c);
}

std::unique_ptr<Texture> copyOf(const Texture& t) {
    auto c = std::make_unique<Texture>(t.width(), t.height(), t.format());
    c->copyFrom(t);
    return c;
}

std::unique_ptr<Texture> copyField(const RenderGraph& g, const std::string& field) {
    const Texture* t = g.fieldTexture(field);
    if (!t) {
        ADD_FAILURE() << "no texture for " << field;
        return std::make_unique<Texture>(1, 1, Format::RGBA32F);
    }
    return copyOf(*t);
}

size_t countNaN(const Texture& t) {
    const uint32_t channels = formatInfo(t.format()).channels;
    size_t n = 0;
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            for (uint32_t c = 0; c < channels; ++c) n += std::isnan(t.texel(x, y, c)) ? 1 : 0;
    return n;
}

/// Runs f, which must throw a BadInput loom::Error; returns it.
template <class F>
Error expectBadInput(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput) << e.what();
        return e;
    }
    ADD_FAILURE() << "expected a loom::Error";
    return Error(Error::Info{ErrorKind::Runtime, {}, {}, "<no error thrown>", {}, {}});
}

/// Compiles the graph at 64x64 and expects a BadInput error.
Error compileError(const GraphDesc& desc) {
    return expectBadInput([&] {
        RenderGraph g(desc, registry());
        g.compile(sized());
    });
}

const Wire* findWire(const CompiledPlan& plan, const std::string& dst) {
    for (const auto& w : plan.wires)
        if (w.dst.pass + "." + w.dst.channel == dst) return &w;
    return nullptr;
}

const ResourceInfo* findResource(const CompiledPlan& plan, const std::string& name) {
    for (const auto& r : plan.resources)
        if (r.name == name) return &r;
    return nullptr;
}

bool contains(const std::vector<std::string>& v, const std::string& s) {
    return std::find(v.begin(), v.end(), s) != v.end();
}

bool isCulled(const CompiledPlan& plan, const std::string& pass) {
    for (const auto& c : plan.culled)
        if (c.name == pass) return true;
    return false;
}

// ---------------------------------------------------------------------------------------------------------------
// Wiring

TEST(RenderGraphWiring, InputWithoutEdgeConnectsToTheSingleProducerOfItsName) {
    RenderGraph g(makeGraph(R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.25, 0.5, 0.75, 1]}},
                                {"name": "B", "type": "BiasSource", "params": {"color": [1, 2, 3, 0]}},
                                {"name": "O", "type": "OptionalInput"}])",
                            "[]", R"(["O.dst"])"),
                  registry());
    g.compile(sized());
    const Wire* src = findWire(g.plan(), "O.src");
    ASSERT_NE(src, nullptr);
    EXPECT_TRUE(src->byName);
    EXPECT_EQ(src->src.str(), "S.src");
    const Wire* bias = findWire(g.plan(), "O.bias");
    ASSERT_NE(bias, nullptr);
    EXPECT_TRUE(bias->byName);
    EXPECT_EQ(bias->src.str(), "B.bias");

    g.execute(frameAt(0));
    EXPECT_EQ(texel(g, "O.dst", 0, 5, 7), 1.25f);
    EXPECT_EQ(texel(g, "O.dst", 1, 63, 63), 2.5f);
    EXPECT_EQ(texel(g, "O.dst", 2, 0, 0), 3.75f);
    EXPECT_EQ(texel(g, "O.dst", 3, 0, 0), 1.f);
    EXPECT_EQ(g.lastStats()["O"]["biasConnected"], 1.0);
}

TEST(RenderGraphWiring, ExplicitEdgeIsNotByNameAndWinsOverSeveralProducers) {
    RenderGraph g(makeGraph(R"([{"name": "S1", "type": "SrcSource", "params": {"color": [1, 1, 1, 1]}},
                                {"name": "S2", "type": "SrcSource", "params": {"color": [2, 2, 2, 2]}},
                                {"name": "O", "type": "OptionalInput"}])",
                            R"([["S2.src", "O.src"]])", R"(["O.dst"])"),
                  registry());
    g.compile(sized());
    const Wire* w = findWire(g.plan(), "O.src");
    ASSERT_NE(w, nullptr);
    EXPECT_FALSE(w->byName);
    EXPECT_EQ(w->src.str(), "S2.src");
    EXPECT_TRUE(isCulled(g.plan(), "S1"));
    g.execute(frameAt(0));
    EXPECT_EQ(texel(g, "O.dst"), 2.f);
}

TEST(RenderGraphWiring, RequiredInputWithoutProducerIsAnErrorNamingIt) {
    Error e = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "Opt", "type": "OptionalInput"}])",
                                     "[]", R"(["Opt.dst"])"));
    EXPECT_EQ(e.info().where, "Opt.src");
    EXPECT_CONTAINS(e.what(), "'Opt.src' is not connected");
    EXPECT_CONTAINS(e.what(), "'src'");
}

TEST(RenderGraphWiring, OptionalInputWithoutProducerIsFineAndThePassSeesNothing) {
    RenderGraph g(makeGraph(R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.5, 0.5, 0.5, 1]}},
                                {"name": "O", "type": "OptionalInput"}])",
                            "[]", R"(["O.dst"])"),
                  registry());
    g.compile(sized());
    EXPECT_EQ(findWire(g.plan(), "O.bias"), nullptr);
    g.execute(frameAt(0));
    EXPECT_EQ(g.lastStats()["O"]["biasConnected"], 0.0);
    EXPECT_EQ(texel(g, "O.dst"), 0.5f);
}

TEST(RenderGraphWiring, SeveralProducersIsAnErrorListingThem) {
    Error e = compileError(makeGraph(R"([{"name": "S1", "type": "SrcSource"}, {"name": "S2", "type": "SrcSource"},
                                         {"name": "O", "type": "OptionalInput"}])",
                                     "[]", R"(["O.dst"])"));
    EXPECT_EQ(e.info().where, "O.src");
    EXPECT_CONTAINS(e.what(), "ambiguous");
    EXPECT_CONTAINS(e.what(), "S1.src");
    EXPECT_CONTAINS(e.what(), "S2.src");
}

TEST(RenderGraphWiring, OptionalInputListedAsUnconnectedIsNotWiredByName) {
    RenderGraph g(makeGraph(R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.5, 0.5, 0.5, 1]}},
                                {"name": "B", "type": "BiasSource", "params": {"color": [1, 2, 3, 0]}},
                                {"name": "O", "type": "OptionalInput", "unconnected": ["bias"]}])",
                            "[]", R"(["O.dst"])"),
                  registry());
    g.compile(sized());
    EXPECT_EQ(findWire(g.plan(), "O.bias"), nullptr);
    EXPECT_NE(findWire(g.plan(), "O.src"), nullptr);
    EXPECT_TRUE(isCulled(g.plan(), "B"));
    g.execute(frameAt(0));
    EXPECT_EQ(g.lastStats()["O"]["biasConnected"], 0.0);
    EXPECT_EQ(texel(g, "O.dst"), 0.5f);
    // The key survives a save and load.
    EXPECT_TRUE(parseGraph(graphToJson(g.desc()).dump()).sameAs(g.desc()));
}

TEST(RenderGraphWiring, UnconnectedMustNameAnOptionalInputWithoutAnEdge) {
    Error required = compileError(makeGraph(R"([{"name": "S", "type": "SrcSource"},
                                                {"name": "O", "type": "OptionalInput", "unconnected": ["src"]}])",
                                            "[]", R"(["O.dst"])"));
    EXPECT_EQ(required.info().where, "/passes/1/unconnected/0");
    EXPECT_CONTAINS(required.what(), "required");
    Error unknown = compileError(makeGraph(R"([{"name": "S", "type": "SrcSource"},
                                               {"name": "O", "type": "OptionalInput", "unconnected": ["bais"]}])",
                                           "[]", R"(["O.dst"])"));
    EXPECT_CONTAINS(unknown.what(), "did you mean 'bias'");
    Error both = compileError(makeGraph(R"([{"name": "S", "type": "SrcSource"}, {"name": "B", "type": "BiasSource"},
                                            {"name": "O", "type": "OptionalInput", "unconnected": ["bias"]}])",
                                        R"([["B.bias", "O.bias"]])", R"(["O.dst"])"));
    EXPECT_CONTAINS(both.what(), "an edge connects it");
    Error notList = expectBadInput([] {
        parseGraph(R"({"loom_graph": 1, "passes": [{"name": "O", "type": "X", "unconnected": "bias"}],
                       "outputs": ["O.dst"]})");
    });
    EXPECT_EQ(notList.info().where, "/passes/0/unconnected");
}

TEST(RenderGraphWiring, UnconnectedInputOfACulledPassIsOnlyAWarning) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "O", "type": "OptionalInput"}])", "[]",
                            R"(["C.dst"])"),
                  registry());
    ASSERT_NO_THROW(g.compile(sized()));
    EXPECT_TRUE(isCulled(g.plan(), "O"));
    ASSERT_EQ(g.plan().warnings.size(), 1u);
    EXPECT_CONTAINS(g.plan().warnings[0], "O.src");
}

// ---------------------------------------------------------------------------------------------------------------
// Errors

TEST(RenderGraphErrors, UnknownPassTypeSuggestsTheClosest) {
    Error e = expectBadInput([] {
        RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blr"}])", "[]",
                                R"(["B.dst"])"),
                      registry());
    });
    EXPECT_EQ(e.info().where, "/passes/1/type");
    EXPECT_CONTAINS(e.what(), "unknown pass type 'Blr'");
    EXPECT_CONTAINS(e.what(), "did you mean 'Blur'?");
}

TEST(RenderGraphErrors, UnknownChannelOnAnEdgeSuggestsTheClosest) {
    Error e = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blur"}])",
                                     R"([["C.dts", "B.src"]])", R"(["B.dst"])"));
    EXPECT_EQ(e.info().where, "/edges/0/0");
    EXPECT_CONTAINS(e.what(), "unknown channel 'dts'");
    EXPECT_CONTAINS(e.what(), "did you mean 'dst'?");

    Error in = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blur"}])",
                                      R"([["C.dst", "B.scr"]])", R"(["B.dst"])"));
    EXPECT_EQ(in.info().where, "/edges/0/1");
    EXPECT_CONTAINS(in.what(), "did you mean 'src'?");
}

TEST(RenderGraphErrors, UnknownPassOnAnEdgeSuggestsTheClosest) {
    Error e = compileError(makeGraph(R"([{"name": "Const", "type": "Constant"}, {"name": "B", "type": "Blur"}])",
                                     R"([["Cosnt.dst", "B.src"]])", R"(["B.dst"])"));
    EXPECT_EQ(e.info().where, "/edges/0/0");
    EXPECT_CONTAINS(e.what(), "unknown pass 'Cosnt'");
    EXPECT_CONTAINS(e.what(), "did you mean 'Const'?");
}

TEST(RenderGraphErrors, EdgeFromAnInputOrToAnOutput) {
    const std::string passes = R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blur"},
                                   {"name": "M", "type": "Add"}])";
    Error from = compileError(
        makeGraph(passes, R"([["C.dst", "B.src"], ["B.src", "M.a"], ["C.dst", "M.b"]])", R"(["M.dst"])"));
    EXPECT_EQ(from.info().where, "/edges/1/0");
    EXPECT_CONTAINS(from.what(), "'src' is an input of Blur, not an output");

    Error to = compileError(makeGraph(passes, R"([["C.dst", "B.dst"]])", R"(["B.dst"])"));
    EXPECT_EQ(to.info().where, "/edges/0/1");
    EXPECT_CONTAINS(to.what(), "'dst' is an output of Blur, not an input");
}

TEST(RenderGraphErrors, WrongFormatOnAnEdge) {
    Error e = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "S", "type": "ToSrgb8"},
                                         {"name": "B", "type": "Blur"}])",
                                     R"([["C.dst", "S.src"], ["S.dst", "B.src"]])", R"(["B.dst"])"));
    EXPECT_EQ(e.info().where, "/edges/1");
    EXPECT_CONTAINS(e.what(), "wrong format");
    EXPECT_CONTAINS(e.what(), "S.dst -> B.src");
    EXPECT_CONTAINS(e.what(), "RGBA8Srgb");
    EXPECT_CONTAINS(e.what(), "RGBA32F");
}

TEST(RenderGraphErrors, CycleIsNamedAndPrevIsSuggested) {
    Error e = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "A", "type": "Add"},
                                         {"name": "B", "type": "Add"}])",
                                     R"([["C.dst", "A.a"], ["B.dst", "A.b"], ["A.dst", "B.a"], ["C.dst", "B.b"]])",
                                     R"(["A.dst"])"));
    EXPECT_CONTAINS(e.what(), "cycle");
    const std::string msg = e.what();
    EXPECT_TRUE(msg.find("A -> B -> A") != std::string::npos || msg.find("B -> A -> B") != std::string::npos) << msg;
    EXPECT_CONTAINS(msg, "@prev");
}

TEST(RenderGraphErrors, BadParameterValueNamesItsJsonPath) {
    Error range = expectBadInput([] {
        RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"},
                                    {"name": "B", "type": "Blur", "params": {"radius": 100}}])",
                                R"([["C.dst", "B.src"]])", R"(["B.dst"])"),
                      registry());
    });
    EXPECT_EQ(range.info().where, "/passes/1/params/radius");
    EXPECT_CONTAINS(range.what(), "out of range");

    Error type = expectBadInput([] {
        RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant", "params": {"color": "red"}}])", "[]",
                                R"(["C.dst"])"),
                      registry());
    });
    EXPECT_EQ(type.info().where, "/passes/0/params/color");

    Error name = expectBadInput([] {
        RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"},
                                    {"name": "B", "type": "Blur", "params": {"radius": 1, "raduis": 2}}])",
                                R"([["C.dst", "B.src"]])", R"(["B.dst"])"),
                      registry());
    });
    EXPECT_EQ(name.info().where, "/passes/1/params/raduis");
    EXPECT_CONTAINS(name.what(), "did you mean 'radius'?");
}

TEST(RenderGraphErrors, NoOutputs) {
    Error e = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}])", "[]", "[]"));
    EXPECT_EQ(e.info().where, "/outputs");
    EXPECT_CONTAINS(e.what(), "no outputs");
}

TEST(RenderGraphErrors, MarkedOutputMustBeAnOutput) {
    Error e = compileError(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blur"}])",
                                     R"([["C.dst", "B.src"]])", R"(["B.src"])"));
    EXPECT_EQ(e.info().where, "/outputs/0");
    EXPECT_CONTAINS(e.what(), "not an output");
}

TEST(RenderGraphErrors, FailedSetDescDoesNotRunRemovedPasses) {
    // A viewer that reloads an edited graph keeps calling execute after a bad edit: passes that setDesc dropped
    // are destroyed and must not run; execute reports the problem again instead.
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "P", "type": "Probe"}])",
                            R"([["C.dst", "P.src"]])", R"(["P.probe"])"),
                  registry());
    g.compile(sized());
    g.execute(frameAt(0));
    expectBadInput([&] {
        g.setDesc(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blur"}])", "[]",
                            R"(["B.dst"])"));
    });
    EXPECT_FALSE(g.compiled());
    EXPECT_EQ(g.pass("P"), nullptr);
    EXPECT_TRUE(g.lastStats().empty());
    Error again = expectBadInput([&] { g.execute(frameAt(1)); });
    EXPECT_EQ(again.info().where, "B.src");

    // A good description makes it usable again, keeping C.
    g.setDesc(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "B", "type": "Blur"}])",
                        R"([["C.dst", "B.src"]])", R"(["B.dst"])"));
    g.execute(frameAt(2));
    EXPECT_EQ(texel(g, "B.dst"), 1.f);
}

TEST(RenderGraphErrors, SetDescWithAnUnknownTypeLeavesTheGraphAsItWas) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant", "params": {"color": [0.5, 0.5, 0.5, 1]}},
                                {"name": "P", "type": "Probe"}])",
                            R"([["C.dst", "P.src"]])", R"(["P.probe"])"),
                  registry());
    g.compile(sized());
    g.execute(frameAt(0));
    Error e = expectBadInput([&] {
        g.setDesc(makeGraph(R"([{"name": "C", "type": "Constant", "params": {"color": [2, 2, 2, 1]}},
                                {"name": "X", "type": "Nope"}])",
                            "[]", R"(["C.dst"])"));
    });
    EXPECT_EQ(e.info().where, "/passes/1/type");
    ASSERT_NE(g.pass("C"), nullptr);
    ASSERT_NE(g.pass("P"), nullptr);
    EXPECT_EQ(g.pass("C")->params().get("color"), nlohmann::json::array({0.5, 0.5, 0.5, 1}));
    EXPECT_TRUE(g.compiled());
    g.execute(frameAt(1));
    EXPECT_EQ(g.lastStats()["P"]["executed"], 1.0);
    EXPECT_EQ(texel(g, "P.probe"), 0.5f);

    // A bad parameter of a kept pass also leaves the graph usable.
    expectBadInput([&] {
        g.setDesc(makeGraph(R"([{"name": "C", "type": "Constant", "params": {"colour": [2, 2, 2, 1]}},
                                {"name": "P", "type": "Probe"}])",
                            R"([["C.dst", "P.src"]])", R"(["P.probe"])"));
    });
    g.execute(frameAt(2));
    EXPECT_EQ(texel(g, "P.probe"), 0.5f);
}

TEST(RenderGraphErrors, PassFailingToCompileLeavesNoStalePlan) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "W", "type": "WidthLimit"},
                                {"name": "P", "type": "Probe"}])",
                            R"([["C.dst", "P.src"]])", R"(["W.out", "P.probe"])"),
                  registry());
    g.compile(sized());
    g.execute(frameAt(0));
    try {
        g.compile(sized(128, 128));
        ADD_FAILURE() << "expected the pass's error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::Runtime);
        EXPECT_CONTAINS(e.what(), "frame too wide");
    }
    EXPECT_FALSE(g.compiled());
    // execute recompiles with the last options that worked.
    g.execute(frameAt(1));
    EXPECT_TRUE(g.compiled());
    ASSERT_NE(g.fieldTexture("P.probe"), nullptr);
    EXPECT_EQ(g.fieldTexture("P.probe")->width(), 64u);
    EXPECT_EQ(texel(g, "P.probe", 0, 63, 63), 1.f);
    EXPECT_EQ(g.lastStats()["P"]["executed"], 1.0);
}

// ---------------------------------------------------------------------------------------------------------------
// Culling and optional outputs

TEST(RenderGraphCulling, PassNotReachingAnOutputIsCulledAndNeverRuns) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant", "params": {"color": [0.5, 0.25, 0.125, 1]}},
                                {"name": "Used", "type": "Probe"}, {"name": "Unused", "type": "Probe"}])",
                            R"([["C.dst", "Used.src"], ["C.dst", "Unused.src"]])", R"(["Used.probe"])"),
                  registry());
    g.compile(sized());
    EXPECT_TRUE(isCulled(g.plan(), "Unused"));
    EXPECT_FALSE(isCulled(g.plan(), "Used"));
    EXPECT_FALSE(contains(g.plan().order, "Unused"));
    EXPECT_EQ(g.plan().order, (std::vector<std::string>{"C", "Used"}));
    EXPECT_EQ(findWire(g.plan(), "Unused.src"), nullptr);
    EXPECT_EQ(findResource(g.plan(), "Unused.probe"), nullptr);

    for (uint64_t f = 0; f < 2; ++f) {
        g.execute(frameAt(f));
        auto stats = g.lastStats();
        EXPECT_EQ(stats.count("Unused"), 0u);
        ASSERT_EQ(stats.count("Used"), 1u);
        EXPECT_EQ(stats["Used"]["executed"], 1.0);
    }
    EXPECT_EQ(texel(g, "Used.probe", 1), 0.25f);
    for (const auto& t : g.timings()) EXPECT_NE(t.name, "Unused");
}

TEST(RenderGraphCulling, UnconsumedOptionalOutputIsNotAllocatedNorComputed) {
    const std::string passes = R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.75, 0, 0, 1]}},
                                   {"name": "O", "type": "OptionalInput"}])";
    RenderGraph g(makeGraph(passes, "[]", R"(["O.dst"])"), registry());
    g.compile(sized());
    EXPECT_TRUE(contains(g.plan().skippedOutputs, "O.mask"));
    EXPECT_EQ(findResource(g.plan(), "O.mask"), nullptr);
    EXPECT_EQ(g.fieldTexture("O.mask"), nullptr);
    g.execute(frameAt(0));
    EXPECT_EQ(g.lastStats()["O"]["maskWritten"], 0.0);
}

TEST(RenderGraphCulling, MarkedOptionalOutputIsComputed) {
    RenderGraph g(makeGraph(R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.75, 0, 0, 1]}},
                                {"name": "O", "type": "OptionalInput"}])",
                            "[]", R"(["O.dst", "O.mask"])"),
                  registry());
    g.compile(sized());
    EXPECT_FALSE(contains(g.plan().skippedOutputs, "O.mask"));
    ASSERT_NE(findResource(g.plan(), "O.mask"), nullptr);
    EXPECT_EQ(findResource(g.plan(), "O.mask")->format, Format::R32F);
    g.execute(frameAt(0));
    EXPECT_EQ(g.lastStats()["O"]["maskWritten"], 1.0);
    EXPECT_EQ(texel(g, "O.mask", 0, 10, 20), 1.f);
}

TEST(RenderGraphCulling, ConsumedOptionalOutputIsComputed) {
    RenderGraph g(makeGraph(R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.75, 0, 0, 1]}},
                                {"name": "O", "type": "OptionalInput"}, {"name": "R", "type": "MaskReader"}])",
                            "[]", R"(["R.dst"])"),
                  registry());
    g.compile(sized());
    EXPECT_TRUE(g.plan().skippedOutputs.empty());
    const Wire* w = findWire(g.plan(), "R.mask");
    ASSERT_NE(w, nullptr);
    EXPECT_TRUE(w->byName);
    EXPECT_EQ(g.plan().order, (std::vector<std::string>{"S", "O", "R"}));
    g.execute(frameAt(0));
    EXPECT_EQ(g.lastStats()["O"]["maskWritten"], 1.0);
    EXPECT_EQ(texel(g, "R.dst", 0, 33, 2), 1.f);
}

TEST(RenderGraphReflect, InternalAndHistoryFieldsMayDependOnTheConnections) {
    // src is wired by name, bias is not connected: the history of src is allocated, the scratch of bias is not.
    const std::string passes = R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.25, 0.5, 0, 1]}},
                                   {"name": "C", "type": "ConnectionFields"}])";
    RenderGraph g(makeGraph(passes, "[]", R"(["C.dst"])"), registry());
    CompileOptions o = sized();
    o.observe = {"C.*"};
    g.compile(o);
    ASSERT_NE(findResource(g.plan(), "C.srcHistory"), nullptr);
    EXPECT_EQ(findResource(g.plan(), "C.biasScratch"), nullptr);
    EXPECT_EQ(g.fieldTexture("C.biasScratch"), nullptr);
    bool warned = false;
    for (const auto& w : g.plan().warnings) warned |= w.find("'C.biasScratch' is not computed") != std::string::npos;
    EXPECT_TRUE(warned) << "observing a field the connections leave out is a warning";
    std::vector<std::string> seen;
    g.setFieldObserver([&](const FrameInfo&, const std::string& pass, const std::string& field, const Texture&) {
        seen.push_back(pass + "." + field);
    });
    g.execute(frameAt(0));
    EXPECT_TRUE(contains(seen, "C.srcHistory"));
    EXPECT_FALSE(contains(seen, "C.biasScratch"));
    EXPECT_EQ(texel(g, "C.dst", 1, 3, 4), 0.5f);
    EXPECT_EQ(texel(g, "C.srcHistory", 0, 3, 4), 0.25f);
    // compile() learns which of its fields are observed: those "C.*" matches that the pass declares once wired
    // (src, bias, dst, srcHistory; not biasScratch).
    EXPECT_EQ(g.lastStats()["C"]["observedFields"], 4.0);
    EXPECT_EQ(g.lastStats()["C"]["srcHistoryObserved"], 1.0);

    // Both connected (bias by an explicit edge from a second source): both fields exist and are used.
    RenderGraph both(makeGraph(R"([{"name": "S", "type": "SrcSource", "params": {"color": [0.25, 0.5, 0, 1]}},
                                   {"name": "B", "type": "BiasSource", "params": {"color": [1, 1, 1, 0]}},
                                   {"name": "C", "type": "ConnectionFields"}])",
                               R"([["B.bias", "C.bias"]])", R"(["C.dst"])"),
                     registry());
    both.compile(sized());
    EXPECT_NE(findResource(both.plan(), "C.srcHistory"), nullptr);
    EXPECT_NE(findResource(both.plan(), "C.biasScratch"), nullptr);
    both.execute(frameAt(0));
    EXPECT_EQ(texel(both, "C.dst", 0, 3, 4), 1.25f);
    EXPECT_EQ(both.lastStats()["C"]["observedFields"], 0.0) << "nothing observed";
    EXPECT_EQ(both.lastStats()["C"]["srcHistoryObserved"], 0.0);
}

TEST(RenderGraphReflect, InputsAndOutputsMustNotDependOnTheConnections) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "PortChanger"}])", "[]", R"(["C.dst"])"), registry());
    try {
        g.compile(sized());
        ADD_FAILURE() << "expected an error";
    } catch (const Error& e) {
        EXPECT_CONTAINS(e.what(), "declares other inputs or outputs once its connections are known");
        EXPECT_CONTAINS(e.what(), "C");
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Transient memory and poisoning

/// Pattern -> B1 -> ... -> B6, output B6.dst; B3 gets the params `b3Params`.
GraphDesc blurChain(const std::string& b3Params = "{}") {
    std::string passes = R"([{"name": "P", "type": "Pattern"})";
    std::string edges = R"([["P.dst", "B1.src"])";
    for (int i = 1; i <= 6; ++i) {
        passes += fmt::format(R"(, {{"name": "B{}", "type": "Blur", "params": {}}})", i,
                              i == 3 ? b3Params : std::string("{}"));
        if (i > 1) edges += fmt::format(R"(, ["B{}.dst", "B{}.src"])", i - 1, i);
    }
    return makeGraph(passes + "]", edges + "]", R"(["B6.dst"])");
}

std::vector<std::unique_ptr<Texture>> renderFrames(RenderGraph& g, const std::string& field, int frames) {
    std::vector<std::unique_ptr<Texture>> out;
    for (int f = 0; f < frames; ++f) {
        g.execute(frameAt(uint64_t(f)));
        out.push_back(copyField(g, field));
    }
    return out;
}

TEST(RenderGraphMemory, TransientsShareMemoryOnlyWhenLifetimesDoNotOverlap) {
    RenderGraph g(blurChain(), registry());
    g.compile(sized());
    const CompiledPlan& plan = g.plan();
    ASSERT_EQ(plan.order.size(), 7u);

    std::vector<ResourceInfo> transients;
    for (const auto& r : plan.resources)
        if (r.kind == ResourceKind::Transient) transients.push_back(r);
    ASSERT_EQ(transients.size(), 13u);  // P.dst, and dst + tmp of each blur
    const size_t texBytes = textureByteSize(64, 64, Format::RGBA32F);
    size_t sum = 0;
    for (const auto& r : transients) {
        EXPECT_EQ(r.bytes, texBytes) << r.name;
        EXPECT_LE(r.offset + r.bytes, plan.transientPeakBytes) << r.name;
        EXPECT_EQ(r.offset % kRowAlignment, 0u) << r.name;
        EXPECT_LE(r.firstUse, r.lastUse) << r.name;
        sum += r.bytes;
    }
    EXPECT_EQ(plan.transientSumBytes, sum);
    EXPECT_LT(plan.transientPeakBytes, plan.transientSumBytes);
    // At most three are alive at once (a blur's src, tmp and dst).
    EXPECT_LE(plan.transientPeakBytes, 3 * texBytes);
    EXPECT_EQ(plan.historyBytes, 0u);

    // Lifetimes follow the chain: B_i.dst is written at i and read at i + 1; B6.dst is marked (lives to the end).
    const ResourceInfo* b2 = findResource(plan, "B2.dst");
    ASSERT_NE(b2, nullptr);
    EXPECT_EQ(b2->firstUse, 2);
    EXPECT_EQ(b2->lastUse, 3);
    const ResourceInfo* b6 = findResource(plan, "B6.dst");
    ASSERT_NE(b6, nullptr);
    EXPECT_EQ(b6->lastUse, int(plan.order.size()));

    for (size_t i = 0; i < transients.size(); ++i)
        for (size_t j = i + 1; j < transients.size(); ++j) {
            const auto& a = transients[i];
            const auto& b = transients[j];
            const bool timeOverlap = a.firstUse <= b.lastUse && b.firstUse <= a.lastUse;
            const bool memOverlap = a.offset < b.offset + b.bytes && b.offset < a.offset + a.bytes;
            EXPECT_FALSE(timeOverlap && memOverlap) << a.name << " and " << b.name << " overlap";
        }
}

TEST(RenderGraphMemory, PoisonDoesNotChangeACorrectGraph) {
    RenderGraph plain(blurChain(), registry());
    plain.compile(sized());
    RenderGraph poisoned(blurChain(), registry());
    CompileOptions o = sized();
    o.poisonTransients = true;
    poisoned.compile(o);
    auto a = renderFrames(plain, "B6.dst", 2);
    auto b = renderFrames(poisoned, "B6.dst", 2);
    for (size_t f = 0; f < a.size(); ++f) {
        EXPECT_TRUE(a[f]->samePixels(*b[f])) << "frame " << f;
        EXPECT_EQ(countNaN(*b[f]), 0u) << "frame " << f;
    }
}

TEST(RenderGraphMemory, PoisonExposesReadBeforeWrite) {
    RenderGraph plain(blurChain(R"({"readScratchFirst": true})"), registry());
    plain.compile(sized());
    plain.execute(frameAt(0));
    EXPECT_EQ(countNaN(*plain.fieldTexture("B6.dst")), 0u);

    RenderGraph poisoned(blurChain(R"({"readScratchFirst": true})"), registry());
    CompileOptions o = sized();
    o.poisonTransients = true;
    poisoned.compile(o);
    poisoned.execute(frameAt(0));
    EXPECT_GT(countNaN(*poisoned.fieldTexture("B6.dst")), 0u);
}

// ---------------------------------------------------------------------------------------------------------------
// History

GraphDesc counterGraph(const std::string& name = "Counter") {
    return makeGraph(R"([{"name": ")" + name + R"(", "type": "FrameCounter"}])", "[]", R"([")" + name + R"(.dst"])");
}

TEST(RenderGraphHistory, CountsFramesAndResets) {
    RenderGraph g(counterGraph(), registry());
    g.compile(sized());
    ASSERT_NE(findResource(g.plan(), "Counter.count"), nullptr);
    EXPECT_EQ(findResource(g.plan(), "Counter.count")->kind, ResourceKind::History);
    EXPECT_EQ(g.plan().historyBytes, 2 * textureByteSize(64, 64, Format::R32F));
    uint64_t frame = 0;
    for (float expected = 1; expected <= 4; ++expected) {
        g.execute(frameAt(frame++));
        EXPECT_EQ(texel(g, "Counter.dst", 0, 17, 3), expected);
        EXPECT_EQ(texel(g, "Counter.count", 0, 17, 3), expected);
    }
    g.resetHistory();
    g.execute(frameAt(frame++));
    EXPECT_EQ(texel(g, "Counter.dst"), 1.f);
    g.execute(frameAt(frame++));
    EXPECT_EQ(texel(g, "Counter.dst"), 2.f);
}

TEST(RenderGraphHistory, SurvivesARecompileAtTheSameSize) {
    RenderGraph g(counterGraph(), registry());
    g.compile(sized());
    g.execute(frameAt(0));
    g.execute(frameAt(1));
    g.compile(sized());
    g.execute(frameAt(2));
    EXPECT_EQ(texel(g, "Counter.dst"), 3.f);

    // Adding an unrelated pass and marking its output keeps the counter's history.
    g.setDesc(makeGraph(R"([{"name": "Counter", "type": "FrameCounter"}, {"name": "C", "type": "Constant"}])", "[]",
                        R"(["Counter.dst", "C.dst"])"));
    EXPECT_EQ(g.plan().order.size(), 2u);
    g.execute(frameAt(3));
    EXPECT_EQ(texel(g, "Counter.dst"), 4.f);
    EXPECT_EQ(texel(g, "C.dst"), 1.f);
}

TEST(RenderGraphHistory, ResizeRestarts) {
    RenderGraph g(counterGraph(), registry());
    g.compile(sized());
    g.execute(frameAt(0));
    g.execute(frameAt(1));
    g.resize(32, 16);
    EXPECT_EQ(g.plan().width, 32u);
    EXPECT_EQ(g.plan().height, 16u);
    g.execute(frameAt(2));
    ASSERT_NE(g.fieldTexture("Counter.dst"), nullptr);
    EXPECT_EQ(g.fieldTexture("Counter.dst")->width(), 32u);
    EXPECT_EQ(g.fieldTexture("Counter.dst")->height(), 16u);
    EXPECT_EQ(texel(g, "Counter.dst", 0, 31, 15), 1.f);
    g.execute(frameAt(3));
    EXPECT_EQ(texel(g, "Counter.dst"), 2.f);
}

TEST(RenderGraphHistory, RenamedPassRestarts) {
    RenderGraph g(counterGraph(), registry());
    g.compile(sized());
    g.execute(frameAt(0));
    g.execute(frameAt(1));
    g.setDesc(counterGraph("Renamed"));
    EXPECT_EQ(g.pass("Counter"), nullptr);
    g.execute(frameAt(2));
    EXPECT_EQ(texel(g, "Renamed.dst"), 1.f);
    EXPECT_EQ(g.fieldTexture("Counter.dst"), nullptr);
}

// ---------------------------------------------------------------------------------------------------------------
// @prev edges

TEST(RenderGraphPrev, PrevEdgeFeedsLastFramesValue) {
    RenderGraph g(makeGraph(R"([{"name": "Counter", "type": "FrameCounter"}, {"name": "Mix", "type": "Add"}])",
                            R"([["Counter.dst@prev", "Mix.b"], ["Counter.dst", "Mix.a"]])", R"(["Mix.dst"])"),
                  registry());
    g.compile(sized());
    const ResourceInfo* h = findResource(g.plan(), "Counter.dst");
    ASSERT_NE(h, nullptr);
    EXPECT_EQ(h->kind, ResourceKind::History);
    const Wire* w = findWire(g.plan(), "Mix.b");
    ASSERT_NE(w, nullptr);
    EXPECT_TRUE(w->src.prev);
    EXPECT_EQ(g.plan().order, (std::vector<std::string>{"Counter", "Mix"}));

    for (int n = 1; n <= 4; ++n) {
        g.execute(frameAt(uint64_t(n - 1)));
        EXPECT_EQ(texel(g, "Mix.dst", 0, 9, 40), float(n + (n - 1))) << "frame " << n;
    }
    g.resetHistory();
    g.execute(frameAt(4));
    EXPECT_EQ(texel(g, "Mix.dst"), 1.f);  // 1 + 0: the previous value is zero again
}

TEST(RenderGraphPrev, PassMayReadItsOwnPreviousOutput) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant", "params": {"color": [0.5, 0.25, 0, 1]}},
                                {"name": "Sum", "type": "Add"}])",
                            R"([["C.dst", "Sum.a"], ["Sum.dst@prev", "Sum.b"]])", R"(["Sum.dst"])"),
                  registry());
    ASSERT_NO_THROW(g.compile(sized()));
    ASSERT_NE(findResource(g.plan(), "Sum.dst"), nullptr);
    EXPECT_EQ(findResource(g.plan(), "Sum.dst")->kind, ResourceKind::History);
    for (int n = 1; n <= 5; ++n) {
        g.execute(frameAt(uint64_t(n)));
        EXPECT_EQ(texel(g, "Sum.dst", 0), 0.5f * float(n));
        EXPECT_EQ(texel(g, "Sum.dst", 1), 0.25f * float(n));
        EXPECT_EQ(texel(g, "Sum.dst", 3), float(n));
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Observing (dumping)

/// TestPattern with a second marked output (the float mix).
GraphDesc observedGraph() {
    GraphDesc d = testPatternGraph();
    d.outputs.push_back(ChannelRef{"Mix", "dst"});
    return d;
}

TEST(RenderGraphObserve, ObservingEverythingChangesNoOutput) {
    constexpr int kFrames = 3;
    RenderGraph plain(observedGraph(), registry());
    plain.compile(sized());
    std::vector<std::unique_ptr<Texture>> display, mix;
    for (int f = 0; f < kFrames; ++f) {
        plain.execute(frameAt(uint64_t(f)));
        display.push_back(copyField(plain, "Display.dst"));
        mix.push_back(copyField(plain, "Mix.dst"));
    }

    RenderGraph watched(observedGraph(), registry());
    CompileOptions o = sized();
    o.observe = {"*"};
    watched.compile(o);
    EXPECT_TRUE(watched.plan().warnings.empty());
    std::map<std::string, std::unique_ptr<Texture>> seen;  // "frame:Pass.field"
    watched.setFieldObserver([&](const FrameInfo& frame, const std::string& pass, const std::string& field,
                                 const Texture& tex) {
        const std::string key = std::to_string(frame.frameIndex) + ":" + pass + "." + field;
        EXPECT_EQ(seen.count(key), 0u) << key << " observed twice";
        seen[key] = copyOf(tex);
    });
    for (int f = 0; f < kFrames; ++f) {
        watched.execute(frameAt(uint64_t(f)));
        EXPECT_TRUE(watched.fieldTexture("Display.dst")->samePixels(*display[f])) << "frame " << f;
        EXPECT_TRUE(watched.fieldTexture("Mix.dst")->samePixels(*mix[f])) << "frame " << f;
    }

    // Inputs, outputs, internals and history of every pass, every frame.
    for (int f = 0; f < kFrames; ++f)
        for (const char* field : {"Pattern.dst", "Blur.src", "Blur.tmp", "Blur.dst", "Counter.count", "Counter.dst",
                                  "Mix.a", "Mix.b", "Mix.dst", "Display.src", "Display.dst"})
            EXPECT_EQ(seen.count(std::to_string(f) + ":" + field), 1u) << field << " frame " << f;
    EXPECT_EQ(seen.size(), size_t(kFrames) * 11);

    // What the observer saw is what the passes saw.
    const std::string last = std::to_string(kFrames - 1) + ":";
    EXPECT_TRUE(seen[last + "Blur.src"]->samePixels(*seen[last + "Pattern.dst"]));
    EXPECT_TRUE(seen[last + "Mix.a"]->samePixels(*seen[last + "Blur.dst"]));
    EXPECT_TRUE(seen[last + "Mix.dst"]->samePixels(*mix.back()));
    EXPECT_TRUE(seen[last + "Display.dst"]->samePixels(*display.back()));
    EXPECT_EQ(seen[last + "Counter.count"]->format(), Format::R32F);
    EXPECT_EQ(seen[last + "Counter.count"]->texel(0, 0, 0), float(kFrames));
    EXPECT_EQ(seen[last + "Blur.tmp"]->format(), Format::RGBA32F);
    EXPECT_EQ(countNaN(*seen[last + "Blur.tmp"]), 0u);
}

TEST(RenderGraphObserve, ObservedFieldsAreReadableAfterExecute) {
    // fieldTexture() promises observed fields after execute, so their memory must not be reused later in the
    // frame (Pattern.dst and Blur.tmp would otherwise share memory with Counter.dst and Mix.dst).
    RenderGraph g(testPatternGraph(), registry());
    CompileOptions o = sized();
    o.observe = {"Pattern.dst", "Blur.tmp", "Mix.a"};
    g.compile(o);
    for (const char* field : {"Pattern.dst", "Blur.tmp"}) {
        const ResourceInfo* r = findResource(g.plan(), field);
        ASSERT_NE(r, nullptr) << field;
        EXPECT_EQ(r->lastUse, int(g.plan().order.size())) << field;
    }
    std::map<std::string, std::unique_ptr<Texture>> seen;
    g.setFieldObserver([&](const FrameInfo&, const std::string& pass, const std::string& field, const Texture& t) {
        seen[pass + "." + field] = copyOf(t);
    });
    g.execute(frameAt(3));
    ASSERT_EQ(seen.size(), 3u);
    for (const auto& [field, copy] : seen) {
        if (field == "Mix.a") continue;  // an input: its producer (Blur.dst) is not observed
        const Texture* after = g.fieldTexture(field);
        ASSERT_NE(after, nullptr) << field;
        EXPECT_TRUE(after->samePixels(*copy)) << field << " was overwritten later in the frame";
    }
}

TEST(RenderGraphObserve, ObservingAFieldOfACulledPassMakesItRun) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"}, {"name": "P", "type": "Probe"}])",
                            R"([["C.dst", "P.src"]])", R"(["C.dst"])"),
                  registry());
    CompileOptions o = sized();
    o.observe = {"P.pro*"};
    g.compile(o);
    EXPECT_FALSE(isCulled(g.plan(), "P"));
    int calls = 0;
    g.setFieldObserver([&](const FrameInfo&, const std::string& pass, const std::string& field, const Texture&) {
        EXPECT_EQ(pass + "." + field, "P.probe");
        ++calls;
    });
    g.execute(frameAt(0));
    EXPECT_EQ(calls, 1);
    EXPECT_EQ(g.lastStats()["P"]["executed"], 1.0);

    o.observe = {"Nothing.*"};
    g.compile(o);
    ASSERT_EQ(g.plan().warnings.size(), 1u);
    EXPECT_CONTAINS(g.plan().warnings[0], "Nothing.*");
    EXPECT_TRUE(isCulled(g.plan(), "P"));
}

// ---------------------------------------------------------------------------------------------------------------
// Determinism

std::vector<std::unique_ptr<Texture>> renderWithThreads(unsigned threads) {
    ThreadLimit limit(threads);
    RenderGraph g(observedGraph(), registry());
    g.compile(sized(128, 128));
    std::vector<std::unique_ptr<Texture>> out;
    for (uint64_t f = 0; f < 3; ++f) {
        g.execute(frameAt(f * 7));
        out.push_back(copyField(g, "Mix.dst"));
        out.push_back(copyField(g, "Display.dst"));
    }
    return out;
}

TEST(RenderGraphDeterminism, SameOutputForAnyThreadCount) {
    auto one = renderWithThreads(1);
    auto two = renderWithThreads(2);
    auto all = renderWithThreads(0);
    ASSERT_EQ(one.size(), two.size());
    for (size_t i = 0; i < one.size(); ++i) {
        EXPECT_TRUE(one[i]->samePixels(*two[i])) << "texture " << i;
        EXPECT_TRUE(one[i]->samePixels(*all[i])) << "texture " << i;
        EXPECT_EQ(countNaN(*one[i]), 0u);
    }
    // Frames differ (the pattern animates), so the comparison is not trivially true.
    EXPECT_FALSE(one[0]->samePixels(*one[2]));
}

// ---------------------------------------------------------------------------------------------------------------
// Parameters and desc()

TEST(RenderGraphDesc, DescReflectsSetParamAndRoundTrips) {
    RenderGraph g(testPatternGraph(), registry());
    g.compile(sized());
    g.setParam("Blur", "radius", 5, "test");
    g.setParam("Mix", "scaleB", 0.5, "test");
    g.setParam("Pattern", "speed", 1.0, "test");  // the default: not listed
    EXPECT_EQ(g.pass("Blur")->params().get("radius"), 5);

    GraphDesc d = g.desc();
    ASSERT_EQ(d.passes.size(), 5u);
    EXPECT_EQ(d.passes[0].params, nlohmann::json({{"frequency", 10.0}}));
    EXPECT_EQ(d.passes[1].params, nlohmann::json({{"radius", 5}}));
    EXPECT_EQ(d.passes[3].params, nlohmann::json({{"scaleB", 0.5}}));
    EXPECT_TRUE(d.passes[2].params.empty());
    EXPECT_EQ(d.edges, testPatternGraph().edges);
    EXPECT_EQ(d.outputs, testPatternGraph().outputs);

    GraphDesc back = parseGraph(graphToJson(d).dump(2));
    EXPECT_TRUE(back.sameAs(d)) << graphToJson(back).dump(2) << "\nvs\n" << graphToJson(d).dump(2);

    // A graph made from the saved description has the changed values.
    RenderGraph again(back, registry());
    EXPECT_EQ(again.pass("Blur")->params().get("radius"), 5);
    EXPECT_EQ(again.pass("Mix")->params().get("scaleB"), 0.5);
}

TEST(RenderGraphDesc, SetParamErrorsNameTheOrigin) {
    RenderGraph g(testPatternGraph(), registry());
    Error pass = expectBadInput([&] { g.setParam("Blr", "radius", 1, "--set Blr.radius=1"); });
    EXPECT_EQ(pass.info().where, "--set Blr.radius=1");
    EXPECT_CONTAINS(pass.what(), "did you mean 'Blur'?");
    Error range = expectBadInput([&] { g.setParam("Blur", "radius", 65, "--set Blur.radius=65"); });
    EXPECT_EQ(range.info().where, "--set Blur.radius=65");
    EXPECT_CONTAINS(range.what(), "out of range");
    EXPECT_EQ(g.pass("Blur")->params().get("radius"), 3);  // unchanged
}

TEST(RenderGraphDesc, SetParamTakesEffectWithoutRecompiling) {
    RenderGraph g(makeGraph(R"([{"name": "C", "type": "Constant"}])", "[]", R"(["C.dst"])"), registry());
    g.compile(sized());
    g.execute(frameAt(0));
    const Texture* before = g.fieldTexture("C.dst");
    EXPECT_EQ(texel(g, "C.dst"), 1.f);
    g.setParam("C", "color", nlohmann::json::array({0.5, 0.5, 0.5, 1}), "test");
    g.execute(frameAt(1));
    EXPECT_EQ(g.fieldTexture("C.dst"), before);  // same allocation
    EXPECT_EQ(texel(g, "C.dst"), 0.5f);
}

TEST(RenderGraphDesc, PassesSeeParameterChangesOfThePassesTheyReadFrom) {
    // A and B feed Mix, which feeds P; C feeds Q on its own. B also reaches P through last frame's value.
    RenderGraph g(makeGraph(R"([{"name": "A", "type": "Constant"}, {"name": "B", "type": "Constant"},
                                {"name": "Mix", "type": "Add"}, {"name": "P", "type": "Probe"},
                                {"name": "C", "type": "Constant"}, {"name": "Q", "type": "Probe"}])",
                            R"([["A.dst", "Mix.a"], ["B.dst@prev", "Mix.b"], ["Mix.dst", "P.src"],
                                ["C.dst", "Q.src"]])",
                            R"(["P.probe", "Q.probe"])"),
                  registry());
    g.compile(sized());
    uint64_t frame = 0;
    const auto changed = [&](const std::string& probe) {
        return g.lastStats().at(probe).at("inputParamsChanged") != 0.0;
    };
    const auto run = [&] { g.execute(frameAt(frame++)); };
    run();
    run();
    EXPECT_FALSE(changed("P"));
    EXPECT_FALSE(changed("Q"));

    const nlohmann::json grey = nlohmann::json::array({0.5, 0.5, 0.5, 1});
    for (const char* upstream : {"A", "B", "Mix"}) {
        SCOPED_TRACE(upstream);
        g.setParam(upstream, upstream == std::string("Mix") ? "scaleA" : "color",
                   upstream == std::string("Mix") ? nlohmann::json(0.25) : grey, "test");
        run();
        EXPECT_TRUE(changed("P"));  // through Mix, whatever the path
        EXPECT_FALSE(changed("Q"));
        run();
        EXPECT_FALSE(changed("P"));  // one frame only
    }
    // The same value again is no change; another branch's change reaches only its own consumers.
    g.setParam("A", "color", grey, "test");
    run();
    EXPECT_FALSE(changed("P"));
    g.setParam("C", "color", grey, "test");
    run();
    EXPECT_FALSE(changed("P"));
    EXPECT_TRUE(changed("Q"));
    // A new description may rewire anything: every pass sees a change.
    g.setDesc(g.desc());
    run();
    EXPECT_TRUE(changed("P"));
    EXPECT_TRUE(changed("Q"));
    run();
    EXPECT_FALSE(changed("Q"));
}

}  // namespace

// Plugin faults are errors, not crashes: a factory that returns no pass, and a pass that throws something that is
// not a loom::Error (a std::exception, or not even that) from execute; each names what failed.
TEST(RenderGraphErrors, PluginFaultsAreErrorsNamingThePass) {
    try {
        registry().create("NullFactory");
        FAIL() << "a null pass was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("NullFactory"), std::string::npos) << e.what();
        EXPECT_EQ(e.kind(), ErrorKind::Runtime);
    }
    for (const char* type : {"ThrowsInt", "ThrowsStd"}) {
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "faulty"},
                            {"passes", {{{"name", "Faulty"}, {"type", type}}}},
                            {"outputs", {"Faulty.dst"}}};
        RenderGraph graph(parseGraph(g.dump()), registry());
        CompileOptions o;
        o.width = 8;
        o.height = 8;
        graph.compile(o);
        try {
            graph.execute(FrameInfo{});
            FAIL() << type << " did not fail";
        } catch (const Error& e) {
            EXPECT_EQ(e.info().where, "Faulty") << e.what();
            EXPECT_EQ(e.kind(), ErrorKind::Runtime);
        }
    }
}

// A plugin's declarations are checked: parameters when the pass is created, fields when the graph compiles.
// Names with a dot (or none) would break "Pass.field" references, globs and dump file names.
TEST(RenderGraphErrors, FaultyDeclarationsAreErrorsNamingThePass) {
    const std::vector<std::pair<std::string, std::string>> paramFaults = {
        {"ParamTwice", "parameter 'radius' is declared twice"},
        {"DefaultOutOfRange", "default 9.0, outside its own range"},
        {"DeclareThrows", "failed to declare its parameters: no such table"}};
    for (const auto& [type, message] : paramFaults) {
        try {
            (void)registry().create(type);
            ADD_FAILURE() << type << " was accepted";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find("'" + type + "'"), std::string::npos) << e.what();
            EXPECT_EQ(e.kind(), ErrorKind::Runtime);
        }
    }
    for (const std::string type : {"FieldWithDot", "EmptyField"}) {
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "faulty"},
                            {"passes", {{{"name", "Faulty"}, {"type", type}}}},
                            {"outputs", {"Faulty.dst"}}};
        RenderGraph graph(parseGraph(g.dump()), registry());
        try {
            graph.compile(sized(8, 8));
            ADD_FAILURE() << type << " compiled";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("not a plain name"), std::string::npos) << e.what();
            EXPECT_EQ(e.info().where, "Faulty") << e.what();
        }
    }
}
