// The graph file format: parseGraph, loadGraph, graphToJson, saveGraph, and their errors.
#include <gtest/gtest.h>

#include "TestUtil.h"
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/Files.h"
#include "loom/Graph.h"

using namespace loom;
using json = nlohmann::json;
namespace fs = std::filesystem;

namespace {

const char kFile[] = "my_graph.json";

const char kValidGraph[] = R"({
  "loom_graph": 1,
  "name": "Valid",
  "passes": [
    {"name": "Pattern", "type": "Pattern", "params": {"frequency": 10.5, "speed": -2}},
    {"name": "Blur", "type": "Blur", "params": {"radius": 3}},
    {"name": "Counter", "type": "FrameCounter"},
    {"name": "Mix", "type": "Add", "params": {}},
    {"name": "Display", "type": "ToSrgb8"}
  ],
  "edges": [
    ["Pattern.dst", "Blur.src"],
    ["Blur.dst", "Mix.a"],
    ["Mix.dst@prev", "Mix.b"],
    ["Mix.dst", "Display.src"]
  ],
  "outputs": ["Display.dst", "Counter.dst"]
})";

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

using test::expectError;

/// Parses `text` as kFile and checks the error: BadInput, exit code 2, the file named in what(),
/// the JSON path `where`, and `needle` in the message. Returns the error for further checks.
Error expectGraphError(const std::string& text, const std::string& where, const std::string& needle) {
    Error e = expectError([&] { (void)parseGraph(text, kFile); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput) << e.what();
    EXPECT_EQ(e.exitCode(), 2) << e.what();
    EXPECT_EQ(e.info().file, kFile) << e.what();
    EXPECT_TRUE(contains(e.what(), kFile)) << e.what();
    EXPECT_EQ(e.info().where, where) << e.what();
    EXPECT_TRUE(contains(e.what(), needle)) << "missing '" << needle << "' in: " << e.what();
    return e;
}

/// A minimal valid graph as JSON, for tests to break one piece at a time.
json minimalGraph() {
    return json{
        {"loom_graph", 1},
        {"passes", json::array({json{{"name", "A"}, {"type", "Constant"}}, json{{"name", "B"}, {"type", "Blur"}}})},
        {"edges", json::array({json::array({"A.dst", "B.src"})})},
        {"outputs", json::array({"B.dst"})}};
}

/// A graph with one edge replaced.
std::string withEdge(const json& edge) {
    json g = minimalGraph();
    g["edges"] = json::array({edge});
    return g.dump();
}

class GraphFiles : public test::TempDirTest {};

/// Graphs of different shapes for the round-trip tests.
std::vector<GraphDesc> sampleGraphs() {
    std::vector<GraphDesc> out;
    out.push_back(parseGraph(kValidGraph, kFile));

    GraphDesc empty;  // no name, no passes, no edges, no outputs
    out.push_back(empty);

    GraphDesc g;
    g.name = "Hand built";
    g.passes.push_back({"C", "Constant", json{{"color", {0.1, 0.2, 0.3, 1.0}}}, {}});
    g.passes.push_back({"Counter", "FrameCounter", json::object(), {}});
    g.passes.push_back({"Opt", "OptionalInput", json{{"nested", {{"a", {1, 2, 3}}, {"b", nullptr}}}, {"s", "x\"y"}}, {}});
    g.edges.push_back({{"C", "dst", false}, {"Opt", "src", false}});
    g.edges.push_back({{"Opt", "dst", true}, {"Opt", "bias", false}});
    g.outputs.push_back({"Opt", "dst", false});
    g.outputs.push_back({"Opt", "mask", false});
    g.outputs.push_back({"Counter", "dst", false});
    out.push_back(g);

    GraphDesc unicode;
    unicode.name = "Ünïcødé — graph";
    unicode.passes.push_back({"Pässe_1", "Pattern", json{{"frequency", 0.1}, {"speed", 1e-7}}, {}});
    unicode.outputs.push_back({"Pässe_1", "dst", false});
    out.push_back(unicode);
    return out;
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Valid graphs

TEST(GraphJson, ParsesValidGraph) {
    GraphDesc g = parseGraph(kValidGraph, kFile);
    EXPECT_EQ(g.name, "Valid");
    EXPECT_EQ(g.file.string(), kFile);

    ASSERT_EQ(g.passes.size(), 5u);
    EXPECT_EQ(g.passes[0].name, "Pattern");
    EXPECT_EQ(g.passes[0].type, "Pattern");
    EXPECT_EQ(g.passes[0].params, (json{{"frequency", 10.5}, {"speed", -2}}));
    EXPECT_EQ(g.passes[1].params, (json{{"radius", 3}}));
    EXPECT_EQ(g.passes[2].name, "Counter");
    EXPECT_EQ(g.passes[2].type, "FrameCounter");
    EXPECT_TRUE(g.passes[2].params.is_object());
    EXPECT_TRUE(g.passes[2].params.empty());
    EXPECT_TRUE(g.passes[3].params.is_object());
    EXPECT_EQ(g.passes[4].type, "ToSrgb8");

    ASSERT_EQ(g.edges.size(), 4u);
    EXPECT_EQ(g.edges[0].src, (ChannelRef{"Pattern", "dst", false}));
    EXPECT_EQ(g.edges[0].dst, (ChannelRef{"Blur", "src", false}));
    EXPECT_EQ(g.edges[2].src, (ChannelRef{"Mix", "dst", true}));
    EXPECT_EQ(g.edges[2].dst, (ChannelRef{"Mix", "b", false}));
    EXPECT_EQ(g.edges[2].src.str(), "Mix.dst@prev");
    EXPECT_EQ(g.edges[3].dst.str(), "Display.src");

    ASSERT_EQ(g.outputs.size(), 2u);
    EXPECT_EQ(g.outputs[0], (ChannelRef{"Display", "dst", false}));
    EXPECT_EQ(g.outputs[1], (ChannelRef{"Counter", "dst", false}));

    ASSERT_NE(g.findPass("Blur"), nullptr);
    EXPECT_EQ(g.findPass("Blur")->type, "Blur");
    EXPECT_EQ(g.findPass("Nope"), nullptr);
}

TEST(GraphJson, OptionalKeysMayBeOmitted) {
    GraphDesc g = parseGraph(R"({"loom_graph": 1, "passes": [{"name": "A", "type": "Constant"}],
                                 "outputs": ["A.dst"]})",
                             kFile);
    EXPECT_EQ(g.name, "");
    EXPECT_TRUE(g.edges.empty());
    ASSERT_EQ(g.passes.size(), 1u);
    EXPECT_EQ(g.outputs.size(), 1u);
}

TEST(GraphJson, ParseChannelRef) {
    EXPECT_EQ(parseChannelRef("A.b", "w"), (ChannelRef{"A", "b", false}));
    EXPECT_EQ(parseChannelRef("GBuffer.linearZ@prev", "w"), (ChannelRef{"GBuffer", "linearZ", true}));
    for (const char* bad : {"A", "A.b.c", "A.b@next", ".b", "A.", "", "@prev", "A.b@prev@prev", "A@prev.b"}) {
        Error e = expectError([&] { (void)parseChannelRef(bad, "/x", "f.json"); });
        EXPECT_EQ(e.kind(), ErrorKind::BadInput) << bad;
        EXPECT_EQ(e.info().where, "/x") << bad;
        EXPECT_EQ(e.info().file, "f.json") << bad;
    }
}

TEST(GraphJson, LineColumn) {
    const std::string text = "ab\ncd\n\nxyz";
    size_t line = 0, col = 0;
    lineColumn(text, 0, line, col);
    EXPECT_EQ(line, 1u);
    EXPECT_EQ(col, 1u);
    lineColumn(text, 1, line, col);
    EXPECT_EQ(line, 1u);
    EXPECT_EQ(col, 2u);
    lineColumn(text, 3, line, col);  // 'c'
    EXPECT_EQ(line, 2u);
    EXPECT_EQ(col, 1u);
    lineColumn(text, 6, line, col);  // the empty line
    EXPECT_EQ(line, 3u);
    EXPECT_EQ(col, 1u);
    lineColumn(text, 9, line, col);  // 'z'
    EXPECT_EQ(line, 4u);
    EXPECT_EQ(col, 3u);
}

// ---------------------------------------------------------------------------------------------------------------
// Round trips

TEST(GraphJson, RoundTripThroughJson) {
    for (const GraphDesc& g : sampleGraphs()) {
        json j = graphToJson(g);
        EXPECT_EQ(j["loom_graph"], json(kGraphFormatVersion));
        GraphDesc back = parseGraph(j.dump(), kFile);
        EXPECT_TRUE(back.sameAs(g)) << "graph '" << g.name << "' changed:\n" << j.dump(2);
        // Pretty-printed output parses to the same graph too.
        EXPECT_TRUE(parseGraph(j.dump(2), kFile).sameAs(g)) << g.name;
        // And serialising again is stable.
        EXPECT_EQ(graphToJson(back), j);
    }
}

TEST(GraphJson, RoundTripKeepsTheEmptyParamsOut) {
    GraphDesc g = parseGraph(kValidGraph, kFile);
    json j = graphToJson(g);
    EXPECT_FALSE(j["passes"][2].contains("params"));  // Counter had none
    EXPECT_EQ(j["passes"][1]["params"], (json{{"radius", 3}}));
    EXPECT_EQ(j["edges"][2], json::array({"Mix.dst@prev", "Mix.b"}));
    EXPECT_EQ(j["outputs"], json::array({"Display.dst", "Counter.dst"}));
}

TEST(GraphJson, SameAsDetectsDifferences) {
    const GraphDesc g = parseGraph(kValidGraph, kFile);
    GraphDesc other = g;
    other.file = "elsewhere.json";
    EXPECT_TRUE(other.sameAs(g));  // the file does not count

    other = g;
    other.passes[1].params["radius"] = 4;
    EXPECT_FALSE(other.sameAs(g));
    other = g;
    other.edges[2].src.prev = false;
    EXPECT_FALSE(other.sameAs(g));
    other = g;
    other.outputs.pop_back();
    EXPECT_FALSE(other.sameAs(g));
    other = g;
    other.name = "Other";
    EXPECT_FALSE(other.sameAs(g));
}

TEST_F(GraphFiles, SaveAndLoad) {
    int i = 0;
    for (const GraphDesc& g : sampleGraphs()) {
        const fs::path path = mDir / ("graph" + std::to_string(i++) + ".json");
        saveGraph(g, path);
        ASSERT_TRUE(fs::is_regular_file(path));
        GraphDesc back = loadGraph(path);
        EXPECT_TRUE(back.sameAs(g)) << path;
        EXPECT_EQ(back.file.string(), path.string());
    }
    // Saving over an existing file replaces it and leaves no temporary files behind.
    GraphDesc g = sampleGraphs()[0];
    g.name = "Replaced";
    saveGraph(g, mDir / "graph0.json");
    EXPECT_EQ(loadGraph(mDir / "graph0.json").name, "Replaced");
    size_t files = std::distance(fs::directory_iterator(mDir), fs::directory_iterator());
    EXPECT_EQ(files, sampleGraphs().size());
}

TEST(GraphJson, ShippedGraphsLoadAndRoundTrip) {
    const fs::path dir = fs::path(LOOM_TEST_SOURCE_DIR) / "graphs";
    ASSERT_TRUE(fs::is_directory(dir)) << dir;
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(dir))
        if (e.path().extension() == ".json") files.push_back(e.path());
    ASSERT_FALSE(files.empty()) << "no graphs in " << dir;
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
        SCOPED_TRACE(f.string());
        GraphDesc g;
        try {
            g = loadGraph(f);
        } catch (const Error& e) {
            ADD_FAILURE() << "shipped graph does not load: " << e.what();
            continue;
        }
        EXPECT_FALSE(g.passes.empty());
        EXPECT_FALSE(g.outputs.empty());
        EXPECT_TRUE(parseGraph(graphToJson(g).dump(), f.string()).sameAs(g));
        // Every edge and output names a pass of the graph.
        for (const auto& e : g.edges) {
            EXPECT_NE(g.findPass(e.src.pass), nullptr) << e.src.str();
            EXPECT_NE(g.findPass(e.dst.pass), nullptr) << e.dst.str();
        }
        for (const auto& o : g.outputs) EXPECT_NE(g.findPass(o.pass), nullptr) << o.str();
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Errors

TEST(GraphJsonErrors, MalformedJsonReportsLineAndColumn) {
    // A trailing comma: the '}' on line 4, column 38 is unexpected.
    const std::string text =
        "{\n"
        "  \"loom_graph\": 1,\n"
        "  \"passes\": [\n"
        "    {\"name\": \"A\", \"type\": \"Constant\",}\n"
        "  ],\n"
        "  \"outputs\": [\"A.dst\"]\n"
        "}\n";
    ASSERT_EQ(text.find("\",}") + 2 - text.find("    {\"name\""), 37u);  // the '}' is the 38th character of line 4
    Error e = expectGraphError(text, "line 4, column 38", "malformed JSON");
    EXPECT_TRUE(contains(e.what(), "my_graph.json: line 4, column 38: malformed JSON")) << e.what();
    EXPECT_FALSE(contains(e.what(), "[json.exception")) << e.what();
    EXPECT_FALSE(e.info().suggestion.empty());
}

TEST(GraphJsonErrors, MalformedJsonMissingCommaPointsAtTheNextToken) {
    // The missing comma after `1` is noticed at the string "passes" on line 3 (columns 3 to 10).
    const std::string text = "{\n  \"loom_graph\": 1\n  \"passes\": [],\n  \"outputs\": []\n}\n";
    Error e = expectError([&] { (void)parseGraph(text, kFile); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), kFile)) << e.what();
    EXPECT_TRUE(e.info().where.rfind("line 3, column ", 0) == 0) << e.what();
    int column = std::stoi(e.info().where.substr(std::string("line 3, column ").size()));
    EXPECT_GE(column, 3);
    EXPECT_LE(column, 10);
}

TEST(GraphJsonErrors, MalformedJsonEmptyAndTruncated) {
    expectGraphError("", "line 1, column 1", "malformed JSON");
    expectGraphError("   \n", "line 2, column 1", "malformed JSON");
    // Truncated after the '[' at line 2, column 12: the end of input is reported just after it.
    expectGraphError("{\"loom_graph\": 1,\n \"passes\": [", "line 2, column 13", "unexpected end of input");
}

// A message quotes bytes of the file (the parser's "last read"); bytes that are not UTF-8 reach the terminal as
// \xNN, while well-formed UTF-8 (a pass named in another script) stays as it is.
TEST(GraphJsonErrors, MessagesAreUtf8WhateverTheFileHolds) {
    const auto wellFormedUtf8 = [](const std::string& s) {
        for (size_t i = 0; i < s.size();) {
            const auto b = static_cast<unsigned char>(s[i]);
            const size_t n = b < 0x80             ? 1
                             : (b & 0xe0) == 0xc0 ? 2
                             : (b & 0xf0) == 0xe0 ? 3
                             : (b & 0xf8) == 0xf0 ? 4
                                                  : 0;
            if (n == 0 || i + n > s.size()) return false;
            for (size_t k = 1; k < n; ++k)
                if ((static_cast<unsigned char>(s[i + k]) & 0xc0) != 0x80) return false;
            i += n;
        }
        return true;
    };
    Error binary =
        expectError([&] { (void)parseGraph(std::string("{\"loom_graph\": 1, \"name\": \"\xff\xfe\"}"), kFile); });
    EXPECT_TRUE(wellFormedUtf8(binary.what())) << binary.what();
    EXPECT_TRUE(contains(binary.what(), "\\xff")) << binary.what();
    EXPECT_EQ(binary.info().what.find("\\xff"), std::string::npos);  // the info keeps the bytes
    Error lead = expectError([&] { (void)parseGraph(std::string("\xd0\x01garbage"), kFile); });
    EXPECT_TRUE(wellFormedUtf8(lead.what())) << lead.what();
    // Two passes named alike in Cyrillic: the message names them in their own letters.
    const std::string cyrillic = "\xd0\x9f\xd1\x80\xd0\xbe\xd1\x85\xd0\xbe\xd0\xb4";
    const std::string pass = "{\"name\": \"" + cyrillic + "\", \"type\": \"Constant\"}";
    Error e = expectError([&] {
        (void)parseGraph("{\"loom_graph\": 1, \"passes\": [" + pass + ", " + pass + "], \"outputs\": []}", kFile);
    });
    EXPECT_TRUE(wellFormedUtf8(e.what())) << e.what();
    EXPECT_TRUE(contains(e.what(), cyrillic)) << e.what();
}

TEST(GraphJsonErrors, NotAnObject) {
    expectGraphError("[1, 2]", "/", "must be a JSON object");
    expectGraphError("42", "/", "must be a JSON object");
}

TEST(GraphJsonErrors, MissingVersion) {
    json g = minimalGraph();
    g.erase("loom_graph");
    expectGraphError(g.dump(), "", "missing key 'loom_graph'");
}

TEST(GraphJsonErrors, WrongVersion) {
    json g = minimalGraph();
    g["loom_graph"] = 2;
    Error e = expectGraphError(g.dump(), "/loom_graph", "unsupported graph format version 2");
    EXPECT_EQ(e.info().expected, "1");
    // Beyond 32 bits: read as 1 by an int conversion, a different version all the same.
    g["loom_graph"] = 4294967297LL;
    expectGraphError(g.dump(), "/loom_graph", "unsupported graph format version 4294967297");
    g["loom_graph"] = -4294967295LL;
    expectGraphError(g.dump(), "/loom_graph", "unsupported graph format version");
    g["loom_graph"] = "1";
    expectGraphError(g.dump(), "/loom_graph", "wrong type");
    g["loom_graph"] = 1.0;
    expectGraphError(g.dump(), "/loom_graph", "wrong type");
}

TEST(GraphJsonErrors, UnknownTopLevelKeySuggests) {
    json g = minimalGraph();
    g["edgse"] = g["edges"];
    g.erase("edges");
    Error e = expectGraphError(g.dump(), "/edgse", "unknown key 'edgse'");
    EXPECT_EQ(e.info().suggestion, "did you mean 'edges'?");
    EXPECT_TRUE(contains(e.what(), "did you mean 'edges'?")) << e.what();
}

TEST(GraphJsonErrors, MissingOrMistypedTopLevelKeys) {
    json g = minimalGraph();
    g.erase("passes");
    expectGraphError(g.dump(), "", "missing key 'passes'");
    g = minimalGraph();
    g.erase("outputs");
    expectGraphError(g.dump(), "", "missing key 'outputs'");
    g = minimalGraph();
    g["passes"] = json::object();
    expectGraphError(g.dump(), "/passes", "wrong type");
    g = minimalGraph();
    g["edges"] = "A.dst -> B.src";
    expectGraphError(g.dump(), "/edges", "must be an array");
    g = minimalGraph();
    g["name"] = 3;
    expectGraphError(g.dump(), "/name", "must be a string");
    g = minimalGraph();
    g["outputs"] = json::array({3});
    expectGraphError(g.dump(), "/outputs/0", "must be a string");
}

TEST(GraphJsonErrors, PassMissingType) {
    json g = minimalGraph();
    g["passes"][1].erase("type");
    expectGraphError(g.dump(), "/passes/1", "missing key 'type'");
    g = minimalGraph();
    g["passes"][0].erase("name");
    expectGraphError(g.dump(), "/passes/0", "missing key 'name'");
    g = minimalGraph();
    g["passes"][1]["type"] = 5;
    expectGraphError(g.dump(), "/passes/1/type", "wrong type");
}

TEST(GraphJsonErrors, PassUnknownKeyAndBadParams) {
    json g = minimalGraph();
    g["passes"][1]["parms"] = json::object();
    Error e = expectGraphError(g.dump(), "/passes/1/parms", "unknown key 'parms'");
    EXPECT_EQ(e.info().suggestion, "did you mean 'params'?");
    g = minimalGraph();
    g["passes"][1]["params"] = json::array({1});
    expectGraphError(g.dump(), "/passes/1/params", "must be an object");
    g = minimalGraph();
    g["passes"][0] = "A";
    expectGraphError(g.dump(), "/passes/0", "must be an object");
}

TEST(GraphJsonErrors, DuplicatePassName) {
    json g = minimalGraph();
    g["passes"].push_back(json{{"name", "A"}, {"type", "Blur"}});
    Error e = expectGraphError(g.dump(), "/passes/2/name", "duplicate pass name 'A'");
    EXPECT_FALSE(e.info().suggestion.empty());
}

TEST(GraphJsonErrors, PassNameNotAllowed) {
    // Names become parts of file names and of "Pass.field" references: at most 64 bytes, no control characters,
    // spaces or characters that file names or references give a meaning (UTF-8 letters are fine: RoundTrip*).
    for (const std::string& bad : std::vector<std::string>{"A.B", "A@B", "A B", "", "a/b", "a\\b", "a\nb", "a:b",
                                                           std::string("a\0b", 3), std::string(65, 'x'),
                                                           // U+202E (right-to-left override), U+200B (zero-width
                                                           // space), a C1 control. (Invalid UTF-8 is malformed JSON.)
                                                           "evil\xE2\x80\xAE" "exr", "a\xE2\x80\x8B", "a\xC2\x85"}) {
        json g = minimalGraph();
        g["passes"][0]["name"] = bad;
        expectGraphError(g.dump(), "/passes/0/name", "is not allowed");
    }
    json g = minimalGraph();
    g["passes"][0]["name"] = std::string(64, 'x');
    g["outputs"][0] = std::string(64, 'x') + ".dst";
    EXPECT_NO_THROW(parseGraph(g.dump()));
}

// A parser keeps one value of a key given twice, and stops at a NUL byte: both would let a file say something
// other than what it seems to say.
TEST(GraphJsonErrors, DuplicateKeysAreReported) {
    const std::string text = R"({"loom_graph": 1, "passes": [], "passes": [], "outputs": []})";
    Error e = expectError([&] { (void)parseGraph(text, kFile); });
    EXPECT_TRUE(contains(e.what(), "\"passes\" appears twice")) << e.what();
    EXPECT_TRUE(contains(e.what(), "line 1, column 33")) << e.what();
    // Nested objects have their own keys; the same key in two objects, or as a value, is fine.
    json g = minimalGraph();
    g["passes"][0]["params"] = json{{"name", "name"}};
    g["passes"][1]["params"] = json{{"name", "other"}};
    EXPECT_NO_THROW((void)parseGraph(g.dump(), kFile));
    const std::string inner = R"({"loom_graph": 1, "passes": [{"name": "A", "type": "T", "name": "B"}], "outputs": []})";
    Error e2 = expectError([&] { (void)parseGraph(inner, kFile); });
    EXPECT_TRUE(contains(e2.what(), "\"name\" appears twice")) << e2.what();
}

TEST(GraphJsonErrors, NulByteWithTextAfterIsReported) {
    const std::string graph = minimalGraph().dump();
    Error e = expectError([&] { (void)parseGraph(graph + std::string("\0garbage", 8), kFile); });
    EXPECT_TRUE(contains(e.what(), "NUL byte")) << e.what();
    // NUL padding at the very end (as some writers pad binary glTF's JSON chunk) is harmless.
    EXPECT_NO_THROW((void)parseGraph(graph + std::string("\0\0 \0", 4), kFile));
}

TEST(GraphJsonErrors, EdgeNotAPair) {
    expectGraphError(withEdge(json::array({"A.dst"})), "/edges/0", "pair of strings");
    expectGraphError(withEdge(json::array({"A.dst", "B.src", "B.src"})), "/edges/0", "pair of strings");
    expectGraphError(withEdge(json("A.dst")), "/edges/0", "pair of strings");
    expectGraphError(withEdge(json::array({"A.dst", 3})), "/edges/0", "pair of strings");
    expectGraphError(withEdge(json{{"from", "A.dst"}, {"to", "B.src"}}), "/edges/0", "pair of strings");
}

TEST(GraphJsonErrors, BadChannelRefs) {
    expectGraphError(withEdge(json::array({"A", "B.src"})), "/edges/0/0", "'A' is not a channel reference");
    expectGraphError(withEdge(json::array({"A.dst", "A.b.c"})), "/edges/0/1", "'A.b.c' is not a channel reference");
    Error e = expectGraphError(withEdge(json::array({"A.b@next", "B.src"})), "/edges/0/0", "unknown modifier '@next'");
    EXPECT_TRUE(contains(e.info().suggestion, "@prev")) << e.what();
    json g = minimalGraph();
    g["outputs"] = json::array({"B.dst", "B"});
    expectGraphError(g.dump(), "/outputs/1", "not a channel reference");
}

TEST(GraphJsonErrors, PrevOnDestination) {
    Error e = expectGraphError(withEdge(json::array({"A.dst", "B.src@prev"})), "/edges/0/1",
                               "@prev is only allowed on an edge's source");
    EXPECT_TRUE(contains(e.info().suggestion, "A.dst@prev")) << e.what();
}

TEST(GraphJsonErrors, OutputWithPrev) {
    json g = minimalGraph();
    g["outputs"] = json::array({"B.dst@prev"});
    expectGraphError(g.dump(), "/outputs/0", "cannot be @prev");
}

TEST(GraphJsonErrors, DefaultFileNameIsShown) {
    Error e = expectError([] { (void)parseGraph("{"); });
    EXPECT_EQ(e.info().file, "<graph>");
    EXPECT_TRUE(contains(e.what(), "<graph>")) << e.what();
}

TEST_F(GraphFiles, MissingFile) {
    const fs::path path = mDir / "does_not_exist.json";
    Error e = expectError([&] { (void)loadGraph(path); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_EQ(e.exitCode(), 2);
    EXPECT_EQ(e.info().file, path.string());
    EXPECT_TRUE(contains(e.what(), path.string())) << e.what();
    EXPECT_TRUE(contains(e.what(), "not found")) << e.what();
}

TEST_F(GraphFiles, FolderIsNotAFile) {
    const fs::path path = mDir / "graphs.json";
    fs::create_directories(path);
    Error e = expectError([&] { (void)loadGraph(path); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_EQ(e.exitCode(), 2);
    EXPECT_TRUE(contains(e.what(), path.string())) << e.what();
    EXPECT_TRUE(contains(e.what(), "folder")) << e.what();
}

TEST_F(GraphFiles, ErrorsInAFileNameTheFile) {
    const fs::path path = mDir / "broken.json";
    json g = minimalGraph();
    g["edgse"] = json::array();
    write(path, g.dump(2));
    Error e = expectError([&] { (void)loadGraph(path); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_EQ(e.info().file, path.string());
    EXPECT_EQ(e.info().where, "/edgse");
    EXPECT_TRUE(contains(e.what(), path.string() + ": /edgse: unknown key")) << e.what();

    write(path, "{\n  \"loom_graph\": 1,\n  oops\n}\n");
    Error syntax = expectError([&] { (void)loadGraph(path); });
    EXPECT_EQ(syntax.info().file, path.string());
    EXPECT_TRUE(syntax.info().where.rfind("line 3, column ", 0) == 0) << syntax.what();
}
