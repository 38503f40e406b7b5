// The shared vocabulary of passes: the standard channels (loom/Channels.h) and the parameter roles (loom/Params.h).
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>

#include "TestUtil.h"
#include "loom/Channels.h"
#include "loom/Error.h"
#include "loom/Params.h"
#include "loom/Plugin.h"

using namespace loom;
using namespace loom::test;

namespace {

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

}  // namespace

TEST(StandardChannels, TableIsWellFormed) {
    std::set<std::string> names;
    for (const ChannelInfo& c : kStandardChannels) {
        EXPECT_TRUE(isPlainName(c.name)) << c.name;
        EXPECT_TRUE(names.insert(c.name).second) << c.name << " is listed twice";
        EXPECT_NE(std::string(c.meaning), "") << c.name;
        EXPECT_EQ(std::string(c.meaning).find('\n'), std::string::npos) << c.name << ": the meaning is one line";
        EXPECT_EQ(findStandardChannel(c.name), &c);
    }
    EXPECT_EQ(findStandardChannel("notAChannel"), nullptr);
    EXPECT_EQ(findStandardChannel(""), nullptr);
    EXPECT_EQ(findStandardChannel("posw"), nullptr);  // names are case-sensitive
    ASSERT_NE(findStandardChannel(channel::kGradient), nullptr);
    EXPECT_GT(channel::kGradientBlock, 0u);
}

// Wiring by name is only sound when every pass means one format by a standard name: a shipped pass that declares a
// standard channel (as input or output) declares it with the table's format.
TEST(StandardChannels, ShippedPassesUseTheTableFormats) {
    PluginRegistry& registry = pluginRegistry();
    registry.loadAll();
    std::map<std::string, std::set<std::string>> producers;  // channel -> pass types that output it
    size_t checked = 0;
    for (const PassTypeInfo* info : registry.registeredTypes()) {
        const auto pass = registry.create(info->type);
        Reflection r;
        pass->reflect(r, CompileInfo{});
        for (const FieldDesc& f : r.fields()) {
            if (f.kind != FieldKind::Input && f.kind != FieldKind::Output) continue;  // private fields: any name
            const ChannelInfo* c = findStandardChannel(f.name);
            if (!c) continue;
            ++checked;
            EXPECT_EQ(formatName(f.format), formatName(c->format))
                << info->type << "." << f.name << " (" << fieldKindName(f.kind)
                << ") is not the standard channel's format";
            if (f.kind == FieldKind::Output) producers[f.name].insert(info->type);
        }
    }
    EXPECT_GT(checked, 0u);
    // With the G-buffer and the path tracer built, every standard channel has a producer.
    if (registry.knows("GBufferRT") && registry.knows("PathTracer"))
        for (const ChannelInfo& c : kStandardChannels)
            EXPECT_TRUE(producers.count(c.name)) << c.name << " has no producer";
}

// ---------------------------------------------------------------------------------------------------------------
// Parameter roles

TEST(ParamRoles, FindRole) {
    int spp = 1, seed = 0;
    bool reset = true;
    float alpha = 0.5f;
    ParamList p;
    p.add("alpha", &alpha, 0.5f);
    p.add("spp", &spp, 1).range(1, 64).role(ParamRole::SampleCount);
    p.add("seed", &seed, 0).role(ParamRole::Seed);
    p.add("restart", &reset, true).role(ParamRole::AutoReset);
    EXPECT_EQ(p.declarationProblem(), "");
    ASSERT_NE(p.findRole(ParamRole::SampleCount), nullptr);
    EXPECT_EQ(p.findRole(ParamRole::SampleCount)->name, "spp");
    EXPECT_EQ(p.findRole(ParamRole::Seed)->name, "seed");
    EXPECT_EQ(p.findRole(ParamRole::AutoReset)->name, "restart");
    EXPECT_EQ(p.findRole(ParamRole::None), nullptr);  // "no role" is not a role alpha plays
    ParamList none;
    none.add("alpha", &alpha, 0.5f);
    EXPECT_EQ(none.findRole(ParamRole::SampleCount), nullptr);
}

TEST(ParamRoles, DeclarationProblems) {
    int a = 1, b = 1;
    float f = 1.f;
    bool flag = false;
    {
        ParamList p;
        p.add("a", &a, 1).role(ParamRole::SampleCount);
        p.add("b", &b, 1).role(ParamRole::SampleCount);
        const std::string problem = p.declarationProblem();
        EXPECT_TRUE(contains(problem, "'b'") && contains(problem, "sampleCount") && contains(problem, "'a'"))
            << problem;
    }
    {
        ParamList p;
        p.add("f", &f, 1.f).role(ParamRole::SampleCount);
        EXPECT_TRUE(contains(p.declarationProblem(), "needs a parameter of type int")) << p.declarationProblem();
    }
    {
        ParamList p;
        p.add("flag", &flag, false).role(ParamRole::Seed);
        EXPECT_TRUE(contains(p.declarationProblem(), "seed")) << p.declarationProblem();
    }
    {
        ParamList p;
        p.add("a", &a, 1).role(ParamRole::AutoReset);
        EXPECT_TRUE(contains(p.declarationProblem(), "needs a parameter of type bool")) << p.declarationProblem();
    }
}

// `loom bench` drives the shipped graphs through roles: their path tracer and accumulator declare them, with the
// types the roles need (checked when the pass is created).
TEST(ParamRoles, ShippedPassesDeclareTheRolesBenchUses) {
    PluginRegistry& registry = pluginRegistry();
    for (const char* type : {"PathTracer", "CUDAPathTracer"}) {
        if (!registry.knows(type)) continue;
        const auto pass = registry.create(type);
        const ParamDecl* spp = pass->params().findRole(ParamRole::SampleCount);
        const ParamDecl* seed = pass->params().findRole(ParamRole::Seed);
        ASSERT_NE(spp, nullptr) << type;
        ASSERT_NE(seed, nullptr) << type;
        EXPECT_EQ(spp->type, ParamType::Int);
        EXPECT_GE(spp->min.value_or(0.0), 1.0) << "a sample count is at least 1";
        EXPECT_EQ(seed->type, ParamType::Int);
    }
    if (registry.knows("AccumulatePass")) {
        const ParamDecl* reset = registry.create("AccumulatePass")->params().findRole(ParamRole::AutoReset);
        ASSERT_NE(reset, nullptr);
        EXPECT_EQ(reset->type, ParamType::Bool);
    }
}
