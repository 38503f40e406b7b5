// Typed parameters (ParamList), command-line values, and the did-you-mean helpers in Error.h.
#include <gtest/gtest.h>

#include "TestUtil.h"

#include <cmath>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/Params.h"

using namespace loom;
using json = nlohmann::json;

namespace {

enum class ToneMap { Linear, Reinhard, Aces };

/// A pass-like owner of one parameter of each type.
struct Owner {
    bool enabled = false;
    int radius = -7;
    float alpha = -7.f;
    float gain = -7.f;  // no range
    std::string label = "unset";
    ToneMap tone = ToneMap::Linear;
    glm::vec3 tint{-7.f};
    glm::vec4 color{-7.f};
    ParamList params;

    Owner() {
        params.add("enabled", &enabled, true).doc("on or off");
        params.add("radius", &radius, 2).range(0, 64);
        params.add("alpha", &alpha, 0.25f).range(0.0, 1.0);
        params.add("gain", &gain, 1.5f);
        params.add("label", &label, std::string("hello"));
        params.addEnum("tonemap", &tone, ToneMap::Reinhard, {"linear", "reinhard", "aces"});
        params.add("tint", &tint, glm::vec3(0.5f, 0.25f, 1.f)).range(0.0, 2.0);
        params.add("color", &color, glm::vec4(1.f, 2.f, 3.f, 4.f));
    }
};

using test::expectError;

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

/// Checks the common shape of a bad-input error raised by ParamList::set.
void expectBadInput(const Error& e, const std::string& where) {
    EXPECT_EQ(e.kind(), ErrorKind::BadInput) << e.what();
    EXPECT_EQ(e.exitCode(), 2);
    EXPECT_EQ(e.info().where, where) << e.what();
    EXPECT_TRUE(contains(e.what(), where)) << e.what();
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Declarations and defaults

TEST(Params, DefaultsAreAssignedAtDeclaration) {
    Owner o;
    EXPECT_TRUE(o.enabled);
    EXPECT_EQ(o.radius, 2);
    EXPECT_FLOAT_EQ(o.alpha, 0.25f);
    EXPECT_FLOAT_EQ(o.gain, 1.5f);
    EXPECT_EQ(o.label, "hello");
    EXPECT_EQ(o.tone, ToneMap::Reinhard);
    EXPECT_EQ(o.tint, glm::vec3(0.5f, 0.25f, 1.f));
    EXPECT_EQ(o.color, glm::vec4(1.f, 2.f, 3.f, 4.f));
}

TEST(Params, DeclarationsKeepOrderTypesRangesAndDocs) {
    Owner o;
    const auto& decls = o.params.decls();
    ASSERT_EQ(decls.size(), 8u);
    const std::vector<std::string> names = {"enabled", "radius", "alpha", "gain", "label", "tonemap", "tint", "color"};
    const std::vector<ParamType> types = {ParamType::Bool,   ParamType::Int,  ParamType::Float, ParamType::Float,
                                          ParamType::String, ParamType::Enum, ParamType::Vec3,  ParamType::Vec4};
    for (size_t i = 0; i < decls.size(); ++i) {
        EXPECT_EQ(decls[i].name, names[i]);
        EXPECT_EQ(decls[i].type, types[i]) << names[i];
    }
    const ParamDecl* radius = o.params.find("radius");
    ASSERT_NE(radius, nullptr);
    ASSERT_TRUE(radius->min && radius->max);
    EXPECT_EQ(*radius->min, 0.0);
    EXPECT_EQ(*radius->max, 64.0);
    EXPECT_FALSE(o.params.find("gain")->min.has_value());
    EXPECT_EQ(o.params.find("enabled")->doc, "on or off");
    EXPECT_EQ(o.params.find("tonemap")->enumValues, (std::vector<std::string>{"linear", "reinhard", "aces"}));
    EXPECT_EQ(o.params.find("nope"), nullptr);
    EXPECT_STREQ(paramTypeName(ParamType::Vec4), "vec4");
    EXPECT_STREQ(paramTypeName(ParamType::Enum), "enum");
}

TEST(Params, BuilderMinOnlyIsOpenAbove) {
    int n = 0;
    ParamList p;
    p.add("count", &n, 1).min(1);
    EXPECT_NO_THROW(p.set("count", 1000000, "X.count"));
    EXPECT_EQ(n, 1000000);
    Error e = expectError([&] { p.set("count", 0, "X.count"); });
    expectBadInput(e, "X.count");
    EXPECT_TRUE(contains(e.info().expected, ">= 1")) << e.what();
    EXPECT_EQ(n, 1000000);
}

// ---------------------------------------------------------------------------------------------------------------
// set() of each type

TEST(Params, SetBool) {
    Owner o;
    o.params.set("enabled", false, "P.enabled");
    EXPECT_FALSE(o.enabled);
    EXPECT_EQ(o.params.get("enabled"), json(false));
    o.params.set("enabled", true, "P.enabled");
    EXPECT_TRUE(o.enabled);
}

TEST(Params, SetInt) {
    Owner o;
    o.params.set("radius", 17, "P.radius");
    EXPECT_EQ(o.radius, 17);
    EXPECT_EQ(o.params.get("radius"), json(17));
    // Both ends of the range are inclusive.
    o.params.set("radius", 0, "P.radius");
    EXPECT_EQ(o.radius, 0);
    o.params.set("radius", 64, "P.radius");
    EXPECT_EQ(o.radius, 64);
    // An unsigned JSON integer is an integer too.
    o.params.set("radius", json(5u), "P.radius");
    EXPECT_EQ(o.radius, 5);
}

TEST(Params, SetFloatAcceptsIntegersAndFloats) {
    Owner o;
    o.params.set("alpha", 0.75, "P.alpha");
    EXPECT_FLOAT_EQ(o.alpha, 0.75f);
    o.params.set("alpha", 1, "P.alpha");
    EXPECT_FLOAT_EQ(o.alpha, 1.f);
    o.params.set("alpha", 0.0, "P.alpha");
    EXPECT_FLOAT_EQ(o.alpha, 0.f);
    o.params.set("gain", -1234.5, "P.gain");
    EXPECT_FLOAT_EQ(o.gain, -1234.5f);
    EXPECT_EQ(o.params.get("gain"), json(-1234.5f));
}

TEST(Params, SetString) {
    Owner o;
    o.params.set("label", "world", "P.label");
    EXPECT_EQ(o.label, "world");
    o.params.set("label", "", "P.label");
    EXPECT_EQ(o.label, "");
    EXPECT_EQ(o.params.get("label"), json(""));
}

TEST(Params, SetEnumStoresTheIndex) {
    Owner o;
    o.params.set("tonemap", "aces", "P.tonemap");
    EXPECT_EQ(o.tone, ToneMap::Aces);
    EXPECT_EQ(o.params.get("tonemap"), json("aces"));
    o.params.set("tonemap", "linear", "P.tonemap");
    EXPECT_EQ(o.tone, ToneMap::Linear);
    EXPECT_EQ(o.params.get("tonemap"), json("linear"));
}

TEST(Params, SetVec3AndVec4) {
    Owner o;
    o.params.set("tint", json::array({0, 1.5, 2}), "P.tint");
    EXPECT_EQ(o.tint, glm::vec3(0.f, 1.5f, 2.f));
    EXPECT_EQ(o.params.get("tint"), json::array({0.f, 1.5f, 2.f}));
    o.params.set("color", json::array({-1, 0.5, 100, 7}), "P.color");
    EXPECT_EQ(o.color, glm::vec4(-1.f, 0.5f, 100.f, 7.f));
    EXPECT_EQ(o.params.get("color"), json::array({-1.f, 0.5f, 100.f, 7.f}));
}

TEST(Params, GetOfUnknownNameIsNull) {
    Owner o;
    EXPECT_TRUE(o.params.get("nope").is_null());
}

// ---------------------------------------------------------------------------------------------------------------
// set() errors: kind BadInput, the `where` passed in, and the value left unchanged

TEST(ParamsErrors, UnknownNameSuggestsNearMiss) {
    Owner o;
    Error e = expectError([&] { o.params.set("radus", 3, "/passes/1/params/radus"); });
    expectBadInput(e, "/passes/1/params/radus");
    EXPECT_TRUE(contains(e.what(), "unknown parameter 'radus'")) << e.what();
    EXPECT_EQ(e.info().suggestion, "did you mean 'radius'?");
    EXPECT_TRUE(contains(e.what(), "did you mean 'radius'?")) << e.what();
    // The expected text lists every declared parameter.
    for (const char* n : {"enabled", "radius", "alpha", "gain", "label", "tonemap", "tint", "color"})
        EXPECT_TRUE(contains(e.info().expected, n)) << e.info().expected;
    EXPECT_EQ(o.radius, 2);
}

TEST(ParamsErrors, UnknownNameFarFromAllListsThemOnce) {
    Owner o;
    Error e = expectError([&] { o.params.set("zzzzzzzzzzzz", 3, "Blur.zzzzzzzzzzzz"); });
    expectBadInput(e, "Blur.zzzzzzzzzzzz");
    EXPECT_FALSE(contains(e.what(), "did you mean")) << e.what();
    // The names are listed once, in `expected`; the hint says none is close instead of repeating them.
    EXPECT_TRUE(contains(e.info().expected, "one of: enabled, radius")) << e.what();
    EXPECT_EQ(e.info().suggestion, "none of these is close to 'zzzzzzzzzzzz': check its spelling");
}

TEST(ParamsErrors, StringForInt) {
    Owner o;
    Error e = expectError([&] { o.params.set("radius", "3", "Blur.radius"); });
    expectBadInput(e, "Blur.radius");
    EXPECT_TRUE(contains(e.what(), "wrong type")) << e.what();
    EXPECT_TRUE(contains(e.info().expected, "integer")) << e.what();
    EXPECT_EQ(o.radius, 2);
}

TEST(ParamsErrors, FractionForInt) {
    Owner o;
    Error e = expectError([&] { o.params.set("radius", 1.5, "Blur.radius"); });
    expectBadInput(e, "Blur.radius");
    EXPECT_TRUE(contains(e.what(), "wrong type")) << e.what();
    EXPECT_TRUE(contains(e.what(), "1.5")) << e.what();
    EXPECT_EQ(o.radius, 2);
}

TEST(ParamsErrors, IntegerTooLargeForInt32) {
    int n = 0;
    ParamList p;
    p.add("big", &n, 0);
    Error e = expectError([&] { p.set("big", json(int64_t(1) << 40), "X.big"); });
    expectBadInput(e, "X.big");
    EXPECT_TRUE(contains(e.what(), "32-bit")) << e.what();
    EXPECT_EQ(n, 0);
}

TEST(ParamsErrors, NumberForBool) {
    Owner o;
    for (const json& v : {json(1), json(0), json(0.5), json("true"), json(nullptr)}) {
        Error e = expectError([&] { o.params.set("enabled", v, "P.enabled"); });
        expectBadInput(e, "P.enabled");
        EXPECT_TRUE(contains(e.what(), "wrong type")) << e.what();
        EXPECT_TRUE(contains(e.info().expected, "true or false")) << e.what();
    }
    EXPECT_TRUE(o.enabled);
}

TEST(ParamsErrors, WrongTypeForStringFloatEnumAndVectors) {
    Owner o;
    expectBadInput(expectError([&] { o.params.set("label", 3, "P.label"); }), "P.label");
    expectBadInput(expectError([&] { o.params.set("alpha", "0.5", "P.alpha"); }), "P.alpha");
    expectBadInput(expectError([&] { o.params.set("alpha", true, "P.alpha"); }), "P.alpha");
    expectBadInput(expectError([&] { o.params.set("tonemap", 2, "P.tonemap"); }), "P.tonemap");
    expectBadInput(expectError([&] { o.params.set("tint", 1.0, "P.tint"); }), "P.tint");
    expectBadInput(expectError([&] { o.params.set("tint", json::array({1, 1}), "P.tint"); }), "P.tint");
    expectBadInput(expectError([&] { o.params.set("tint", json::array({1, 1, 1, 1}), "P.tint"); }), "P.tint");
    expectBadInput(expectError([&] { o.params.set("tint", json::array({1, "a", 1}), "P.tint"); }), "P.tint");
    expectBadInput(expectError([&] { o.params.set("color", json::array({1, 2, 3}), "P.color"); }), "P.color");
    Error e = expectError([&] { o.params.set("color", json::object(), "P.color"); });
    EXPECT_TRUE(contains(e.info().expected, "an array of 4 numbers")) << e.what();
    EXPECT_EQ(o.label, "hello");
    EXPECT_FLOAT_EQ(o.alpha, 0.25f);
    EXPECT_EQ(o.tone, ToneMap::Reinhard);
    EXPECT_EQ(o.tint, glm::vec3(0.5f, 0.25f, 1.f));
    EXPECT_EQ(o.color, glm::vec4(1.f, 2.f, 3.f, 4.f));
}

TEST(ParamsErrors, OutOfRangeBothEnds) {
    Owner o;
    for (int bad : {-1, 65, -1000000}) {
        Error e = expectError([&] { o.params.set("radius", bad, "/passes/0/params/radius"); });
        expectBadInput(e, "/passes/0/params/radius");
        EXPECT_TRUE(contains(e.what(), "out of range")) << e.what();
        EXPECT_TRUE(contains(e.what(), std::to_string(bad))) << e.what();
        EXPECT_EQ(e.info().expected, "a value in [0, 64]") << e.what();
    }
    for (double bad : {-0.001, 1.001}) {
        Error e = expectError([&] { o.params.set("alpha", bad, "P.alpha"); });
        expectBadInput(e, "P.alpha");
        EXPECT_TRUE(contains(e.what(), "out of range")) << e.what();
    }
    // Each vector component is checked against the range.
    expectBadInput(expectError([&] { o.params.set("tint", json::array({0, 2.5, 0}), "P.tint"); }), "P.tint");
    expectBadInput(expectError([&] { o.params.set("tint", json::array({-0.5, 0, 0}), "P.tint"); }), "P.tint");
    EXPECT_EQ(o.radius, 2);
    EXPECT_FLOAT_EQ(o.alpha, 0.25f);
    EXPECT_EQ(o.tint, glm::vec3(0.5f, 0.25f, 1.f));
}

TEST(ParamsErrors, EnumValueNotInListSuggestsNearMiss) {
    Owner o;
    Error e = expectError([&] { o.params.set("tonemap", "acse", "Tone.tonemap"); });
    expectBadInput(e, "Tone.tonemap");
    EXPECT_TRUE(contains(e.what(), "no value 'acse'")) << e.what();
    EXPECT_EQ(e.info().expected, "one of: linear, reinhard, aces");
    EXPECT_EQ(e.info().suggestion, "did you mean 'aces'?");
    EXPECT_EQ(o.tone, ToneMap::Reinhard);

    // Enum values are case-sensitive: "ACES" is rejected, with the right suggestion.
    Error upper = expectError([&] { o.params.set("tonemap", "ACES", "Tone.tonemap"); });
    EXPECT_EQ(upper.info().suggestion, "did you mean 'aces'?");

    Error far = expectError([&] { o.params.set("tonemap", "filmic-hable", "Tone.tonemap"); });
    EXPECT_EQ(far.info().expected, "one of: linear, reinhard, aces");
    EXPECT_EQ(far.info().suggestion, "none of these is close to 'filmic-hable': check its spelling");
    EXPECT_EQ(o.tone, ToneMap::Reinhard);
}

TEST(ParamsErrors, NonFinite) {
    Owner o;
    const double inf = std::numeric_limits<double>::infinity();
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (double bad : {inf, -inf, nan}) {
        Error e = expectError([&] { o.params.set("gain", bad, "P.gain"); });
        expectBadInput(e, "P.gain");
        EXPECT_TRUE(contains(e.what(), "not finite")) << e.what();
        Error ev = expectError([&] { o.params.set("color", json::array({0, 0, bad, 0}), "P.color"); });
        expectBadInput(ev, "P.color");
        EXPECT_TRUE(contains(ev.what(), "not finite")) << ev.what();
    }
    // NaN must not slip through a range check (every comparison with NaN is false).
    expectBadInput(expectError([&] { o.params.set("alpha", nan, "P.alpha"); }), "P.alpha");
    EXPECT_FLOAT_EQ(o.gain, 1.5f);
    EXPECT_FLOAT_EQ(o.alpha, 0.25f);
    EXPECT_EQ(o.color, glm::vec4(1.f, 2.f, 3.f, 4.f));
}

TEST(ParamsErrors, FiniteDoubleThatOverflowsFloat) {
    // 1e300 is a finite JSON number but not a finite float: storing it would put inf in the member.
    Owner o;
    Error e = expectError([&] { o.params.set("gain", 1e300, "P.gain"); });
    expectBadInput(e, "P.gain");
    EXPECT_TRUE(std::isfinite(o.gain));
    EXPECT_FLOAT_EQ(o.gain, 1.5f);
    expectBadInput(expectError([&] { o.params.set("color", json::array({0, -1e300, 0, 0}), "P.color"); }), "P.color");
    EXPECT_EQ(o.color, glm::vec4(1.f, 2.f, 3.f, 4.f));
}

// ---------------------------------------------------------------------------------------------------------------
// setAll and toJson

TEST(Params, SetAllAssignsEveryKey) {
    Owner o;
    o.params.setAll(json{{"radius", 9}, {"tonemap", "aces"}, {"tint", {1, 1, 1}}}, "/passes/3/params");
    EXPECT_EQ(o.radius, 9);
    EXPECT_EQ(o.tone, ToneMap::Aces);
    EXPECT_EQ(o.tint, glm::vec3(1.f));
    o.params.setAll(json::object(), "/passes/3/params");
    EXPECT_EQ(o.radius, 9);
}

TEST(ParamsErrors, SetAllOnNonObject) {
    Owner o;
    for (const json& v : {json::array({1, 2}), json(3), json("radius"), json(nullptr)}) {
        Error e = expectError([&] { o.params.setAll(v, "/passes/3/params"); });
        expectBadInput(e, "/passes/3/params");
        EXPECT_TRUE(contains(e.what(), "must be an object")) << e.what();
    }
}

TEST(ParamsErrors, SetAllNamesTheKeyInWhere) {
    Owner o;
    Error e = expectError([&] { o.params.setAll(json{{"radus", 3}}, "/passes/3/params"); });
    expectBadInput(e, "/passes/3/params/radus");
    EXPECT_EQ(e.info().suggestion, "did you mean 'radius'?");
    Error range = expectError([&] { o.params.setAll(json{{"radius", 100}}, "/passes/3/params"); });
    expectBadInput(range, "/passes/3/params/radius");
}

TEST(Params, ToJsonAllValues) {
    Owner o;
    json all = o.params.toJson(false);
    ASSERT_TRUE(all.is_object());
    EXPECT_EQ(all.size(), 8u);
    EXPECT_EQ(all["enabled"], json(true));
    EXPECT_EQ(all["radius"], json(2));
    EXPECT_EQ(all["label"], json("hello"));
    EXPECT_EQ(all["tonemap"], json("reinhard"));
    EXPECT_EQ(all["color"], json::array({1.f, 2.f, 3.f, 4.f}));
}

TEST(Params, ToJsonOnlyNonDefaultListsChangedValues) {
    Owner o;
    EXPECT_EQ(o.params.toJson(true), json::object());

    o.params.set("radius", 5, "P.radius");
    o.params.set("tonemap", "aces", "P.tonemap");
    o.params.set("tint", json::array({0.5, 0.25, 2}), "P.tint");
    o.params.set("label", "hello", "P.label");  // set, but to the default: not listed
    json changed = o.params.toJson(true);
    EXPECT_EQ(changed, (json{{"radius", 5}, {"tonemap", "aces"}, {"tint", {0.5f, 0.25f, 2.f}}})) << changed.dump();

    // Setting values back to their defaults removes them again.
    o.params.set("radius", 2, "P.radius");
    o.params.set("tonemap", "reinhard", "P.tonemap");
    o.params.set("tint", json::array({0.5, 0.25, 1}), "P.tint");
    EXPECT_EQ(o.params.toJson(true), json::object());
}

TEST(Params, ToJsonFeedsSetAll) {
    Owner a;
    a.params.setAll(json{{"alpha", 0.125}, {"enabled", false}, {"color", {4, 3, 2, 1}}, {"label", "x"}}, "/p");
    Owner b;
    b.params.setAll(a.params.toJson(true), "/p");
    EXPECT_EQ(b.params.toJson(false), a.params.toJson(false));
    EXPECT_FLOAT_EQ(b.alpha, 0.125f);
    EXPECT_FALSE(b.enabled);
    EXPECT_EQ(b.color, glm::vec4(4.f, 3.f, 2.f, 1.f));
}

// ---------------------------------------------------------------------------------------------------------------
// parseParamValue (command-line values)

TEST(ParamValue, ParsesJsonOrFallsBackToString) {
    json i = parseParamValue("3");
    EXPECT_TRUE(i.is_number_integer());
    EXPECT_EQ(i, json(3));

    json f = parseParamValue("0.5");
    EXPECT_TRUE(f.is_number_float());
    EXPECT_EQ(f.get<double>(), 0.5);

    json neg = parseParamValue("-2");
    EXPECT_TRUE(neg.is_number_integer());
    EXPECT_EQ(neg.get<int>(), -2);

    json b = parseParamValue("true");
    EXPECT_TRUE(b.is_boolean());
    EXPECT_EQ(b, json(true));
    EXPECT_EQ(parseParamValue("false"), json(false));

    json s = parseParamValue("aces");
    EXPECT_TRUE(s.is_string());
    EXPECT_EQ(s, json("aces"));

    json a = parseParamValue("[1,2,3]");
    ASSERT_TRUE(a.is_array());
    EXPECT_EQ(a, json::array({1, 2, 3}));

    EXPECT_EQ(parseParamValue("\"quoted\""), json("quoted"));
    EXPECT_EQ(parseParamValue("[1,2"), json("[1,2"));  // malformed JSON stays text
    EXPECT_EQ(parseParamValue("my file.exr"), json("my file.exr"));
    EXPECT_EQ(parseParamValue(""), json(""));
}

TEST(ParamValue, FeedsSet) {
    Owner o;
    o.params.set("radius", parseParamValue("7"), "--set Blur.radius");
    o.params.set("alpha", parseParamValue("0.5"), "--set X.alpha");
    o.params.set("enabled", parseParamValue("false"), "--set X.enabled");
    o.params.set("tonemap", parseParamValue("aces"), "--set X.tonemap");
    o.params.set("tint", parseParamValue("[1,2,0]"), "--set X.tint");
    o.params.set("label", parseParamValue("some text"), "--set X.label");
    EXPECT_EQ(o.radius, 7);
    EXPECT_FLOAT_EQ(o.alpha, 0.5f);
    EXPECT_FALSE(o.enabled);
    EXPECT_EQ(o.tone, ToneMap::Aces);
    EXPECT_EQ(o.tint, glm::vec3(1.f, 2.f, 0.f));
    EXPECT_EQ(o.label, "some text");
    expectBadInput(expectError([&] { o.params.set("radius", parseParamValue("2.5"), "--set Blur.radius"); }),
                   "--set Blur.radius");
}

// ---------------------------------------------------------------------------------------------------------------
// Error, closestMatch, didYouMean, join

// A plugin's declarations are checked when a pass is created (PluginRegistry::create): each fault is named.
TEST(ParamsErrors, DeclarationProblems) {
    EXPECT_EQ(Owner().params.declarationProblem(), "");
    const auto problem = [](auto declare) {
        float f = 0.f;
        int i = 0;
        ToneMap t{};
        ParamList p;
        declare(p, f, i, t);
        return p.declarationProblem();
    };
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) { p.add("a.b", &f, 0.f); }), "plain name"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) { p.add("", &f, 0.f); }), "plain name"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) { p.add("9x", &f, 0.f); }), "plain name"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int& i, ToneMap&) {
                             p.add("x", &f, 0.f);
                             p.add("x", &i, 0);
                         }),
                         "declared twice"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) { p.add("x", &f, 2.f).range(0, 1); }),
                         "default 2.0, outside its own range"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float&, int& i, ToneMap&) { p.add("x", &i, -1).min(0); }),
                         "outside its own range"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) { p.add("x", &f, 0.5f).range(1, 0); }),
                         "empty or non-finite range"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) {
                             p.add("x", &f, 0.f).range(0, std::numeric_limits<double>::infinity());
                         }),
                         "non-finite range"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float& f, int&, ToneMap&) {
                             p.add("x", &f, std::numeric_limits<float>::quiet_NaN());
                         }),
                         "outside its own range"));
    EXPECT_TRUE(contains(problem([](ParamList& p, float&, int&, ToneMap& t) {
                             p.addEnum("x", &t, ToneMap::Aces, {"linear", "reinhard"});
                         }),
                         "default outside its enum values"));
    EXPECT_TRUE(contains(
        problem([](ParamList& p, float&, int&, ToneMap& t) { p.addEnum("x", &t, ToneMap::Linear, {"a", "a"}); }),
        "enum value twice"));
    EXPECT_TRUE(
        contains(problem([](ParamList& p, float&, int&, ToneMap& t) { p.addEnum("x", &t, ToneMap::Linear, {}); }),
                 "without values"));
}

// Messages show invisible formatting characters as bytes: a right-to-left override would reverse what follows it.
TEST(ErrorHelpers, PrintableEscapesInvisibleFormatting) {
    EXPECT_EQ(printable("a\xE2\x80\xAE" "b"), "a\\xe2\\x80\\xaeb");
    EXPECT_EQ(printable("\xEF\xBB\xBFx"), "\\xef\\xbb\\xbfx");  // byte-order mark
    EXPECT_EQ(printable("\xC2\x85"), "\\xc2\\x85");              // C1 control NEL
    EXPECT_EQ(printable("caf\xC3\xA9 \xE2\x86\x92"), "caf\xC3\xA9 \xE2\x86\x92");  // letters and arrows stay
}

TEST(ErrorHelpers, PlainNames) {
    for (const char* good : {"a", "_x", "normW", "pass_2"}) EXPECT_TRUE(isPlainName(good)) << good;
    for (const char* bad : {"", "2a", "a.b", "a b", "a-b", "a@prev", "caf\xC3\xA9"}) EXPECT_FALSE(isPlainName(bad)) << bad;
}

TEST(ErrorHelpers, ClosestMatch) {
    const std::vector<std::string> names = {"radius", "sigma", "alpha", "iterations"};
    EXPECT_EQ(closestMatch("radus", names), "radius");
    EXPECT_EQ(closestMatch("radiuss", names), "radius");
    EXPECT_EQ(closestMatch("sigam", names), "sigma");
    EXPECT_EQ(closestMatch("RADIUS", names), "radius");  // case-insensitive
    EXPECT_EQ(closestMatch("alpha", names), "alpha");
    EXPECT_EQ(closestMatch("iteratoins", names), "iterations");
    EXPECT_EQ(closestMatch("zzzzzzzz", names), "");
    EXPECT_EQ(closestMatch("radius", {}), "");
    EXPECT_EQ(closestMatch("edgse", {"loom_graph", "name", "passes", "edges", "outputs"}), "edges");
    // A short name allows at most two edits.
    EXPECT_EQ(closestMatch("ab", {"xyz"}), "");
    EXPECT_EQ(closestMatch("ab", {"abcd"}), "abcd");
    EXPECT_EQ(closestMatch("ab", {"abcde"}), "");
}

TEST(ErrorHelpers, DidYouMean) {
    const std::vector<std::string> names = {"Blur", "Constant", "Add"};
    EXPECT_EQ(didYouMean("Blr", names), "did you mean 'Blur'?");
    EXPECT_EQ(didYouMean("Qqqqqqqqq", names), "known: Blur, Constant, Add");
    EXPECT_EQ(didYouMean("Qqqqqqqqq", names, "types"), "types: Blur, Constant, Add");
    EXPECT_EQ(didYouMean("Qqqqqqqqq", {}), "");
}

TEST(ErrorHelpers, Join) {
    EXPECT_EQ(join({}), "");
    EXPECT_EQ(join({"a"}), "a");
    EXPECT_EQ(join({"a", "b", "c"}), "a, b, c");
    EXPECT_EQ(join({"a", "b"}, " | "), "a | b");
}

TEST(ErrorHelpers, ErrorFormatAndExitCodes) {
    Error e(Error::Info{ErrorKind::BadInput, "g.json", "/passes/0", "broken", "fixed", "fix it"});
    EXPECT_STREQ(e.what(), "g.json: /passes/0: broken\n  expected: fixed\n  hint: fix it");
    EXPECT_EQ(e.exitCode(), 2);

    Error r(Error::Info{ErrorKind::Runtime, "", "", "disk full", "", ""});
    EXPECT_STREQ(r.what(), "disk full");
    EXPECT_EQ(r.kind(), ErrorKind::Runtime);
    EXPECT_EQ(r.exitCode(), 1);

    Error withFile = r.withFile("out.exr");
    EXPECT_EQ(withFile.info().file, "out.exr");
    EXPECT_STREQ(withFile.what(), "out.exr: disk full");
    EXPECT_EQ(withFile.kind(), ErrorKind::Runtime);
    // withFile does not replace a file that is already set.
    EXPECT_EQ(e.withFile("other.json").info().file, "g.json");

    Error thrown = expectError([] { throwBadInput("W", "what", "exp", "sugg", "f.json"); });
    EXPECT_EQ(thrown.kind(), ErrorKind::BadInput);
    EXPECT_EQ(thrown.info().file, "f.json");
    EXPECT_EQ(thrown.info().where, "W");
    EXPECT_EQ(thrown.info().what, "what");
    EXPECT_EQ(thrown.info().expected, "exp");
    EXPECT_EQ(thrown.info().suggestion, "sugg");
}
