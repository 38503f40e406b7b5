// The loom command line: render (outputs, dumps, frame numbering, stats), check, passes, and the exit code and
// message of each kind of bad input. Runs the real binary in a fresh folder per test.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <glm/vec4.hpp>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/ExrFile.h"
#include "loom/ImageIO.h"
#include "loom/Texture.h"

namespace fs = std::filesystem;

#define EXPECT_CONTAINS(text, part) \
    EXPECT_NE(std::string(text).find(part), std::string::npos) << "'" << (part) << "' not in:\n" << (text)

namespace {

using RunResult = loom::test::CliResult;
const auto& quoted = loom::test::shellQuoted;

const std::string kTestPattern = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/TestPattern.json";

class Cli : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = fs::temp_directory_path() / ("loom_test_cli_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(mDir);
        fs::create_directories(mDir);
    }
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }

    /// Runs `loom ARGS` in the test folder, capturing stdout and stderr.
    RunResult loom(const std::string& args) const { return ::loom::test::runLoom(mDir, args); }

    /// Runs a render of TestPattern at 64x64 into OUT with extra arguments.
    RunResult render(const std::string& extra, const std::string& graph = kTestPattern) const {
        return loom("render --graph " + quoted(graph) + " --size 64x64 --out out " + extra);
    }

    /// Expects exit code 2, a message starting with "error:" that contains every part, and no image written.
    void expectBadInput(const RunResult& r, const std::vector<std::string>& parts) const {
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_CONTAINS(r.output, "error:");
        for (const auto& p : parts) EXPECT_CONTAINS(r.output, p);
        EXPECT_TRUE(files("out").empty()) << "images written despite the error";
    }

    fs::path path(const std::string& rel) const { return mDir / rel; }

    void writeText(const std::string& rel, const std::string& text) const {
        std::ofstream out(path(rel), std::ios::binary);
        out << text;
    }

    std::string readText(const std::string& rel) const {
        std::ifstream in(path(rel), std::ios::binary);
        std::stringstream s;
        s << in.rdbuf();
        return s.str();
    }

    /// Sorted file names in a sub folder (empty when it does not exist).
    std::vector<std::string> files(const std::string& rel) const {
        std::vector<std::string> names;
        std::error_code ec;
        if (!fs::is_directory(path(rel), ec)) return names;
        for (const auto& e : fs::directory_iterator(path(rel))) names.push_back(e.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    }

    /// No temporary file of an atomic write (".NAME.PID.N.partial", formerly "NAME.tmp.PID.N") is left anywhere in
    /// the test folder. (A dump of a field named "tmp", like Blur.tmp.0001.exr, is not one.)
    void expectNoTemporaries() const {
        static const std::regex temporary(R"(.*\.tmp\.[0-9]+\.[0-9]+|.*\.partial)");
        for (const auto& e : fs::recursive_directory_iterator(mDir))
            EXPECT_FALSE(std::regex_match(e.path().filename().string(), temporary)) << e.path();
    }

    /// A copy of TestPattern.json with one substring replaced, written to the test folder.
    std::string patchedGraph(const std::string& from, const std::string& to) const {
        std::ifstream in(kTestPattern, std::ios::binary);
        std::stringstream s;
        s << in.rdbuf();
        std::string text = s.str();
        const size_t at = text.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        if (at != std::string::npos) text.replace(at, from.size(), to);
        writeText("graph.json", text);
        return path("graph.json").string();
    }

    fs::path mDir;
};

// ---------------------------------------------------------------------------------------------------------------
// render

TEST_F(Cli, RenderWritesTheMarkedOutputEveryFrame) {
    RunResult r = render("--frames 3");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "Rendered 3 frame(s) at 64x64");
    EXPECT_EQ(files("out"),
              (std::vector<std::string>{"Display.dst.0000.png", "Display.dst.0001.png", "Display.dst.0002.png"}));
    loom::Texture img = loom::readImage(path("out/Display.dst.0002.png"));
    EXPECT_EQ(img.width(), 64u);
    EXPECT_EQ(img.height(), 64u);
    expectNoTemporaries();
}

TEST_F(Cli, RenderDumpsMatchingFieldsOnlyForTheChosenFrames) {
    RunResult r = render("--frames 3 --dump 'Blur.*' --dump-frames 1");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "3 dump(s)");
    EXPECT_EQ(files("out"),
              (std::vector<std::string>{"Blur.dst.0001.exr", "Blur.src.0001.exr", "Blur.tmp.0001.exr",
                                        "Display.dst.0000.png", "Display.dst.0001.png", "Display.dst.0002.png"}));
    loom::Texture tmp = loom::readImage(path("out/Blur.tmp.0001.exr"));
    EXPECT_EQ(tmp.width(), 64u);
    EXPECT_EQ(tmp.format(), loom::Format::RGBA32F);
    expectNoTemporaries();
}

TEST_F(Cli, RenderNumbersFilesFromTheStartFrame) {
    RunResult r = render("--frames 2 --start-frame 5 -q");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(files("out"), (std::vector<std::string>{"Display.dst.0005.png", "Display.dst.0006.png"}));
}

TEST_F(Cli, RenderWritesStatsForEveryFrame) {
    RunResult r = render("--frames 3 -q --stats stats.json");
    ASSERT_EQ(r.code, 0) << r.output;
    nlohmann::json stats = nlohmann::json::parse(readText("stats.json"), nullptr, false);
    ASSERT_FALSE(stats.is_discarded()) << readText("stats.json");
    EXPECT_EQ(stats["width"], 64);
    EXPECT_EQ(stats["height"], 64);
    ASSERT_TRUE(stats["frames"].is_array());
    ASSERT_EQ(stats["frames"].size(), 3u);
    for (size_t i = 0; i < 3; ++i) {
        EXPECT_EQ(stats["frames"][i]["frame"], i);
        for (const char* pass : {"Pattern", "Blur", "Counter", "Mix", "Display"})
            EXPECT_TRUE(stats["frames"][i]["passes"][pass]["ms"].is_number()) << pass;
    }
    expectNoTemporaries();
}

// A shard of a sequence (--start-frame K) first runs frames 0..K-1 unwritten where the graph keeps history
// (--warmup auto), so its frames are those of one run from frame 0 bit for bit: SVGF's filtered image, dumped as
// float EXR, on the moving Cornell box. Cold (--warmup 0) they differ, which is why; a graph without history warms
// nothing up and needs none.
TEST_F(Cli, ShardsWarmUpHistoryToGiveTheFramesOfOneRun) {
    const std::string scene = quoted(loom::test::dataScene("cornell_dynamic.gltf"));
    const std::string svgf = quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracerSVGF.json");
    const std::string common =
        " --scene " + scene + " --size 64x64 -q --dump SVGF.filtered --set PathTracer.device=cpu";
    ASSERT_EQ(loom("render --graph " + svgf + common + " --frames 6 --out long").code, 0);
    const RunResult shard = loom("render --graph " + svgf + common +
                                 " --frames 2 --start-frame 4 --out shard "
                                 "--stats stats.json");
    ASSERT_EQ(shard.code, 0) << shard.output;
    ASSERT_EQ(loom("render --graph " + svgf + common + " --frames 2 --start-frame 4 --warmup 0 --out cold").code, 0);
    // Only the shard's own frames are written (and dumped).
    EXPECT_EQ(files("shard"), (std::vector<std::string>{"SVGF.filtered.0004.exr", "SVGF.filtered.0005.exr",
                                                        "ToneMap.dst.0004.png", "ToneMap.dst.0005.png"}));
    const nlohmann::json stats = nlohmann::json::parse(readText("stats.json"), nullptr, false);
    EXPECT_EQ(stats["warmup"]["from"], 0);
    EXPECT_EQ(stats["warmup"]["frames"], 4);
    ASSERT_EQ(stats["frames"].size(), 2u);
    for (const char* f : {"0004", "0005"}) {
        const std::string name = std::string("/SVGF.filtered.") + f + ".exr";
        const std::string one = readText("long" + name), warm = readText("shard" + name),
                          cold = readText("cold" + name);
        ASSERT_FALSE(one.empty()) << name;
        EXPECT_TRUE(one == warm) << name << ": the shard's frame differs from one run's";
        EXPECT_FALSE(one == cold) << name << ": history made no difference, so the test shows nothing";
    }

    // A graph without history: no warm-up, and the frames are the same anyway.
    const std::string pt = quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracer.json");
    const std::string plain =
        " --scene " + scene + " --size 64x64 -q --dump PathTracer.color --set PathTracer.device=cpu";
    ASSERT_EQ(loom("render --graph " + pt + plain + " --frames 3 --out ptlong").code, 0);
    ASSERT_EQ(loom("render --graph " + pt + plain + " --frames 1 --start-frame 2 --out ptshard --stats pt.json").code,
              0);
    EXPECT_FALSE(nlohmann::json::parse(readText("pt.json"), nullptr, false).contains("warmup"));
    EXPECT_EQ(readText("ptlong/PathTracer.color.0002.exr"), readText("ptshard/PathTracer.color.0002.exr"));

    expectBadInput(render("--start-frame 2 --warmup two"), {"--warmup", "'two' is not a frame count"});
}

// Sample shards of one held frame (--seed-offset) merged by `loom image merge` give one run's reference bit for bit:
// the shards keep their double sums and counts (graphs/ReferenceShard.json), the merge adds them in double and
// divides as AccumulatePass does. Each shard's EXRs say which samples they hold; overlapping shards are refused.
TEST_F(Cli, SampleShardsMergeIntoOneRunsReferenceBitForBit) {
    const std::string common = "render --graph " +
                               quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/ReferenceShard.json") + " --scene " +
                               quoted(loom::test::dataScene("cornell_dynamic.gltf")) +
                               " --size 64x64 --start-frame 3 --hold -q --set PathTracer.samplesPerPixel=2"
                               " --set PathTracer.device=cpu";
    ASSERT_EQ(loom(common + " --frames 8 --out single").code, 0);
    ASSERT_EQ(loom(common + " --frames 3 --out a").code, 0);
    ASSERT_EQ(loom(common + " --frames 5 --seed-offset 3 --out b").code, 0);
    const loom::ExrFile header(path("b/Accumulate.dst.0003.exr"));
    EXPECT_EQ(header.stringAttribute("loomHeldFrame"), "3");
    EXPECT_EQ(header.stringAttribute("loomSeedOffset"), "3");
    EXPECT_EQ(header.stringAttribute("loomIterations"), "5");

    const auto same = [&](const std::string& a, const std::string& b) {
        return loom::readImage(path(a)).samePixels(loom::readImage(path(b)));
    };
    for (const char* order : {"a b", "b a"}) {
        const std::string out = std::string("merged ") + order;  // a merge writes a new folder
        const RunResult merged = loom(std::string("image merge ") + order + " -o " + quoted(out));
        ASSERT_EQ(merged.code, 0) << merged.output;
        EXPECT_CONTAINS(merged.output, "2 shards, 8 iterations");
        EXPECT_TRUE(same(out + "/Accumulate.mean.0003.exr", "single/Accumulate.dst.0003.exr")) << order;
        EXPECT_TRUE(same(out + "/Accumulate.partialCount.0003.exr", "single/Accumulate.partialCount.0003.exr"));
    }
    // Neither shard alone is the reference: the merge is what makes it.
    EXPECT_FALSE(same("a/Accumulate.dst.0003.exr", "single/Accumulate.dst.0003.exr"));
    EXPECT_FALSE(same("b/Accumulate.dst.0003.exr", "single/Accumulate.dst.0003.exr"));

    const RunResult overlap = loom("image merge a b a -o twice");
    EXPECT_EQ(overlap.code, 2) << overlap.output;
    EXPECT_CONTAINS(overlap.output, "overlap");
    const RunResult noPartials = loom("image merge single/.. a -o none");
    EXPECT_EQ(noPartials.code, 2) << noPartials.output;
    expectBadInput(render("--seed-offset 4"), {"--seed-offset", "--hold"});
}

// An output file that cannot be written (a folder, a missing folder) is bad input; --stats is checked before the
// first frame, not after the last.
TEST_F(Cli, OutputFilePathsAreCheckedFirst) {
    fs::create_directories(mDir / "taken");
    expectBadInput(render("--frames 3 -q --stats taken"), {"--stats", "taken", "is a folder"});
    expectBadInput(render("--frames 3 -q --stats missing/stats.json"), {"--stats", "folder does not exist"});
    RunResult dot = loom("check " + quoted(kTestPattern) + " --dot taken");
    EXPECT_EQ(dot.code, 2) << dot.output;
    EXPECT_CONTAINS(dot.output, "is a folder");
    loom::writeImage(mDir / "a.png", loom::Texture(4, 4, loom::Format::RGBA8Unorm));
    RunResult montage = loom("image montage a.png a.png -o taken");
    EXPECT_EQ(montage.code, 2) << montage.output;
    EXPECT_CONTAINS(montage.output, "is a folder");
    expectNoTemporaries();
}

TEST_F(Cli, RenderWithPoisonSucceeds) {
    RunResult r = render("--frames 1 -q --poison --set Blur.radius=1");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(files("out"), (std::vector<std::string>{"Display.dst.0000.png"}));
}

// ---------------------------------------------------------------------------------------------------------------
// Bad input: exit code 2 and a message

TEST_F(Cli, MalformedGraphJsonReportsLineAndColumn) {
    writeText("bad.json",
              "{\n  \"loom_graph\": 1,\n  \"passes\": [\n    {\"name\": \"A\" \"type\": \"Constant\"}\n"
              "  ],\n  \"outputs\": [\"A.dst\"]\n}\n");
    RunResult r = render("", path("bad.json").string());
    expectBadInput(r, {"bad.json", "line 4", "column", "malformed JSON"});
}

TEST_F(Cli, UnknownPassType) {
    RunResult r = render("", patchedGraph(R"("type": "Blur")", R"("type": "Blr")"));
    expectBadInput(r, {"graph.json", "/passes/1/type", "unknown pass type 'Blr'", "did you mean 'Blur'?"});
}

TEST_F(Cli, UnknownChannel) {
    RunResult r = render("", patchedGraph(R"(["Pattern.dst", "Blur.src"])", R"(["Pattern.dts", "Blur.src"])"));
    expectBadInput(r, {"graph.json", "/edges/0/0", "unknown channel 'dts'", "did you mean 'dst'?"});
}

TEST_F(Cli, MissingGraphFile) {
    RunResult r = render("", path("nowhere.json").string());
    expectBadInput(r, {"nowhere.json", "graph file not found"});
}

TEST_F(Cli, BadSize) {
    RunResult r = loom("render --graph " + quoted(kTestPattern) + " --size 12by5 --out out");
    expectBadInput(r, {"--size", "'12by5' is not a size"});
}

TEST_F(Cli, SetOfAnUnknownParameter) {
    RunResult r = render("--set Blur.radiuz=3");
    expectBadInput(r, {"--set Blur.radiuz=3", "unknown parameter 'radiuz'", "did you mean 'radius'?"});
}

TEST_F(Cli, SetOutOfRange) {
    RunResult r = render("--set Blur.radius=1000");
    expectBadInput(r, {"--set Blur.radius=1000", "out of range"});
}

TEST_F(Cli, SetOfAnUnknownPass) {
    RunResult r = render("--set Blr.radius=1");
    expectBadInput(r, {"unknown pass 'Blr'", "did you mean 'Blur'?"});
}

TEST_F(Cli, UnwritableOutFolder) {
    writeText("file", "not a folder");
    RunResult r = loom("render --graph " + quoted(kTestPattern) + " --size 64x64 --out file/sub");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "error:");
    EXPECT_CONTAINS(r.output, "--out");
    EXPECT_CONTAINS(r.output, "file/sub");
    EXPECT_EQ(readText("file"), "not a folder");

    RunResult same = loom("render --graph " + quoted(kTestPattern) + " --size 64x64 --out file");
    EXPECT_EQ(same.code, 2) << same.output;
    EXPECT_CONTAINS(same.output, "is not a folder");
}

TEST_F(Cli, BackwardsDumpFrames) {
    RunResult r = render("--dump 'Blur.*' --dump-frames 3-1");
    expectBadInput(r, {"--dump-frames", "'3-1' runs backwards"});
}

TEST_F(Cli, UnknownOption) {
    RunResult r = render("--bogus");
    expectBadInput(r, {"--bogus"});
}

TEST_F(Cli, UnknownCommand) {
    RunResult r = loom("frobnicate");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "error:");
    EXPECT_CONTAINS(r.output, "unknown command 'frobnicate'");
    EXPECT_CONTAINS(r.output, "render");

    RunResult close = loom("rendr --graph " + quoted(kTestPattern));
    EXPECT_EQ(close.code, 2) << close.output;
    EXPECT_CONTAINS(close.output, "did you mean 'render'?");
}

// ---------------------------------------------------------------------------------------------------------------
// check and passes

TEST_F(Cli, CheckPrintsThePlan) {
    RunResult r = loom("check " + quoted(kTestPattern) + " --size 64x64");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "Execution order");
    EXPECT_CONTAINS(r.output, "Blur (Blur)");
    EXPECT_CONTAINS(r.output, "Memory:");
    EXPECT_EQ(r.output.find("digraph"), std::string::npos);

    RunResult dot = loom("check " + quoted(kTestPattern) + " --size 64x64 --dot -");
    ASSERT_EQ(dot.code, 0) << dot.output;
    EXPECT_CONTAINS(dot.output, "Execution order");
    EXPECT_CONTAINS(dot.output, "digraph");
    EXPECT_CONTAINS(dot.output, "\"Pattern\":\"dst\" -> \"Blur\":\"src\"");
}

// check lists each culled pass, optional output not computed and input left unconnected once, with why; with a
// scene, also the work each live pass says it leaves out (NoOp reports its skippedWork parameter).
TEST_F(Cli, CheckSaysWhatDoesNotRunAndWhy) {
    writeText("why.json", R"({"loom_graph": 1, "name": "Why",
        "passes": [{"name": "Src", "type": "Constant"},
                   {"name": "Opt", "type": "OptionalInput"},
                   {"name": "Unused", "type": "Blur"},
                   {"name": "Idle", "type": "NoOp", "params": {"skippedWork": "idling: the graph asks for it"}}],
        "edges": [["Src.dst", "Opt.src"], ["Src.dst", "Unused.src"]],
        "outputs": ["Opt.dst", "Idle.dst"]})");
    const auto count = [](const std::string& text, const std::string& part) {
        size_t n = 0;
        for (size_t at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
        return n;
    };
    RunResult r = loom("check why.json --size 64x64");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "Not run or not allocated, and why:\n");
    EXPECT_CONTAINS(r.output, "  Unused (culled): no pass reads its outputs, and none is marked or observed\n");
    EXPECT_CONTAINS(r.output, "  Opt.mask (not computed): optional, not marked or observed, and no pass reads it\n");
    EXPECT_CONTAINS(r.output, "  Opt.bias (not connected): optional, and no pass outputs a channel named 'bias'\n");
    EXPECT_CONTAINS(r.output, "  Idle.src (not connected): optional, and no pass outputs a channel named 'src'\n");
    // Said once: the culled pass and the skipped output appear nowhere else in the plan.
    EXPECT_EQ(count(r.output, "Unused"), 1u) << r.output;
    EXPECT_EQ(count(r.output, "Opt.mask"), 1u) << r.output;
    EXPECT_EQ(r.output.find("Culled passes"), std::string::npos) << r.output;
    // Without a scene no pass is asked for the work it leaves out.
    EXPECT_EQ(r.output.find("idling"), std::string::npos) << r.output;

    const std::string scene = " --scene " + quoted(loom::test::dataScene("cornell_box.gltf"));
    RunResult withScene = loom("check why.json --size 64x64" + scene);
    ASSERT_EQ(withScene.code, 0) << withScene.output;
    const size_t section = withScene.output.find("Not run or not allocated, and why:\n");
    ASSERT_NE(section, std::string::npos) << withScene.output;
    const size_t line = withScene.output.find("\n  Idle: idling: the graph asks for it\n");
    ASSERT_NE(line, std::string::npos) << withScene.output;
    EXPECT_GT(line, section);
    EXPECT_LT(line, withScene.output.find("\nAllocations:"));
    // The line follows the parameter, as --set leaves it.
    RunResult set = loom("check why.json --size 64x64" + scene + " --set \"Idle.skippedWork=resting: --set\"");
    ASSERT_EQ(set.code, 0) << set.output;
    EXPECT_CONTAINS(set.output, "  Idle: resting: --set\n");
    EXPECT_EQ(set.output.find("idling"), std::string::npos) << set.output;

    // The scene as the first frame sees it: --env lights a scene whose file has no environment.
    const std::string pt = " " + quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracer.json");
    RunResult dark = loom("check" + pt + " --size 64x64" + scene);
    ASSERT_EQ(dark.code, 0) << dark.output;
    EXPECT_CONTAINS(dark.output, "  PathTracer: environment sampling: the environment is black\n");
    RunResult lit = loom("check" + pt + " --size 64x64" + scene + " --env 0.5,0.5,0.5");
    ASSERT_EQ(lit.code, 0) << lit.output;
    EXPECT_EQ(lit.output.find("the environment is black"), std::string::npos) << lit.output;
    EXPECT_CONTAINS(lit.output, "the environment is a constant colour\n");

    // A graph where everything runs says so.
    RunResult all = loom("check " + quoted(kTestPattern) + " --size 64x64");
    ASSERT_EQ(all.code, 0) << all.output;
    EXPECT_CONTAINS(all.output, "Not run or not allocated, and why: none\n");
}

TEST_F(Cli, CheckReportsABadGraph) {
    RunResult r = loom("check " + quoted(patchedGraph(R"(["Mix.dst", "Display.src"])", R"(["Mix.dst", "Display.a"])")));
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "unknown channel 'a'");
    EXPECT_EQ(r.output.find("Execution order"), std::string::npos);
}

TEST_F(Cli, PassesListsTheTypes) {
    RunResult r = loom("passes");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "FrameCounter");
    EXPECT_CONTAINS(r.output, "readScratchFirst");
}

TEST_F(Cli, PassesWritesMarkdown) {
    RunResult r = loom("passes --markdown PASSES.md");
    ASSERT_EQ(r.code, 0) << r.output;
    const std::string md = readText("PASSES.md");
    EXPECT_CONTAINS(md, "# Pass reference");
    EXPECT_CONTAINS(md, "## Blur");
    EXPECT_CONTAINS(md, "radius");
    EXPECT_CONTAINS(md, "## FrameCounter");
    expectNoTemporaries();
}

}  // namespace

using loom::Format;
using loom::readImage;
using loom::Texture;
using loom::writeImage;

TEST_F(Cli, ImageMontagePlacesImagesSideBySide) {
    Texture a(3, 2, Format::RGBA8Unorm), b(5, 2, Format::RGBA32F);
    for (uint32_t y = 0; y < 2; ++y) {
        for (uint32_t x = 0; x < 3; ++x) reinterpret_cast<uint8_t*>(a.row(y))[x * 4] = 10;
        // Linear 0.5 is sRGB 0.7353569 -> 188; 2.0 clamps to 255.
        for (uint32_t x = 0; x < 5; ++x) b.view<glm::vec4>().at(x, y) = glm::vec4(0.5f, 2.f, 0.f, 1.f);
    }
    writeImage(mDir / "a.png", a);
    writeImage(mDir / "b.exr", b);
    RunResult r = loom("image montage a.png b.exr --gap 1 -o side.png");
    ASSERT_EQ(r.code, 0) << r.output;
    Texture side = readImage(mDir / "side.png");
    ASSERT_EQ(side.width(), 3u + 1u + 5u);
    ASSERT_EQ(side.height(), 2u);
    EXPECT_EQ(side.texel(0, 1, 0) * 255.f, 10.f);
    EXPECT_EQ(side.texel(3, 0, 0), 1.f);  // the white gap
    EXPECT_EQ(std::lround(side.texel(4, 0, 0) * 255.f), 188);
    EXPECT_EQ(side.texel(8, 1, 1), 1.f);
    EXPECT_EQ(side.texel(8, 1, 2), 0.f);
}

TEST_F(Cli, ImageMontageOfUnequalHeightsIsBadInput) {
    writeImage(mDir / "a.png", Texture(4, 4, Format::RGBA8Unorm));
    writeImage(mDir / "b.png", Texture(4, 3, Format::RGBA8Unorm));
    RunResult r = loom("image montage a.png b.png -o side.png");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "b.png");
    EXPECT_CONTAINS(r.output, "equal height");
    EXPECT_FALSE(fs::exists(mDir / "side.png"));
    EXPECT_EQ(loom("image montage a.png missing.png -o side.png").code, 2);
}

// ---------------------------------------------------------------------------------------------------------------
// hostile inputs: files that are not files, JSON nested to exhaust a stack, counts and paths out of range

TEST_F(Cli, AGraphOrScriptThatIsAPipeADeviceOrTooDeepIsBadInput) {
    // A pipe would block for ever and /dev/zero never ends: both are refused before any reading.
    ASSERT_EQ(::mkfifo(path("pipe.json").c_str(), 0600), 0);
    for (const std::string file : {"pipe.json", "/dev/zero"}) {
        RunResult r = loom("check " + file);
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_CONTAINS(r.output, "not a regular file");
        r = loom("view --headless --graph " + quoted(kTestPattern) + " --size 16x16 --frames 2 --script " + file);
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_CONTAINS(r.output, "not a regular file");
    }
    // 100,000 nested arrays as a parameter's value: copying or printing it would recurse that deep.
    const std::string deep = std::string(100000, '[') + std::string(100000, ']');
    expectBadInput(render("", patchedGraph("\"frequency\": 10.0", "\"frequency\": " + deep)),
                   {"graph.json", "line 5", "nested more than 200 deep"});
    expectBadInput(render("--set Pattern.frequency=" + std::string(300, '[') + std::string(300, ']')),
                   {"nested more than 200 deep"});
    // A shallow one is reported with the value cut short, not printed whole.
    const RunResult r = render(
        "", patchedGraph("\"frequency\": 10.0", "\"frequency\": " + std::string(150, '[') + std::string(150, ']')));
    expectBadInput(r, {"frequency", "wrong type", "[[[..."});
    EXPECT_LT(r.output.size(), 1000u) << r.output;
    // A number beyond a double: where it is, not the parser's bare exception.
    expectBadInput(render("", patchedGraph("\"frequency\": 10.0", "\"frequency\": 1e400")),
                   {"graph.json", "line 5", "1e400 is too large"});
}

TEST_F(Cli, CountsThreadsAndRatesOutOfRangeAreBadInput) {
    expectBadInput(render("--frames -1"), {"--frames", "-1 is out of range"});
    expectBadInput(render("--start-frame -5"), {"--start-frame", "-5 is out of range"});
    expectBadInput(render("--frames 2000000"), {"--frames", "out of range"});
    expectBadInput(render("--start-frame 99999999999"), {"--start-frame", "out of range"});
    expectBadInput(render("--threads 4294967295"), {"--threads", "too many"});
    expectBadInput(render("--fps 1e-45"), {"--fps", "out of range"});
    expectBadInput(render("--fps 1e38"), {"--fps", "out of range"});
    RunResult r = loom("view --headless --graph " + quoted(kTestPattern) + " --size 16x16 --frames 2 --threads 100000");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "--threads");
    expectBadInput(loom("render --graph " + quoted(kTestPattern) + " --size 100000x100000 --out out"),
                   {"--size", "out of range"});
    expectBadInput(loom("scene info " + quoted(loom::test::dataScene("cornell_box.gltf")) +
                        " --camera-path dolly:1:1e38 --time 0.25"),
                   {"--camera-path", "amount '1e38' is out of range"});
    // Scene options without a scene have nothing to apply to: a warning, not silence.
    r = render("--jitter halton -q");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "without --scene they are ignored");
}

TEST_F(Cli, OutputsNeverOverwriteInputs) {
    const std::string graph = patchedGraph("\"frequency\": 10.0", "\"frequency\": 10.0");
    const std::string graphText = readText("graph.json");
    // Each run must end with exit code 2 and a message containing `part`.
    const auto refused = [&](const std::string& args, const std::string& part) {
        const RunResult r = loom(args);
        EXPECT_EQ(r.code, 2) << args << "\n" << r.output;
        EXPECT_CONTAINS(r.output, part);
    };
    expectBadInput(render("--stats graph.json", graph), {"--stats", "would overwrite the input"});
    refused("check graph.json --dot graph.json", "would overwrite the input");
    EXPECT_EQ(readText("graph.json"), graphText);
    // Statistics named like a rendered image in the output folder would take its place.
    fs::create_directories(path("out"));
    expectBadInput(render("--stats out/Display.dst.0000.png"), {"--stats", "rendered image"});

    writeImage(mDir / "a.png", Texture(4, 4, Format::RGBA8Unorm));
    writeImage(mDir / "b.png", Texture(4, 4, Format::RGBA8Unorm));
    const std::string a = readText("a.png");
    refused("image montage a.png b.png -o a.png", "would overwrite the input");
    EXPECT_EQ(readText("a.png"), a);
    refused("image montage a.png b.png -o ''", "empty");
    refused("image montage a.png b.png --gap 4294967295 -o m.png", "--gap");
    EXPECT_FALSE(fs::exists(path("m.png")));
    refused("passes --markdown " + quoted(mDir.string()), "is a folder");
    // A pipe (or a device) is not replaced by a regular file.
    ASSERT_EQ(::mkfifo(path("pipe").c_str(), 0600), 0);
    refused("passes --markdown pipe", "not a regular file");
    EXPECT_TRUE(fs::is_fifo(path("pipe")));
    // Frames written into --out would replace a graph named like one of them.
    fs::copy_file(path("graph.json"), path("out/Display.dst.0000.png"));
    refused("render --graph out/Display.dst.0000.png --size 16x16 --out out -q", "would overwrite its input");
    EXPECT_EQ(readText("out/Display.dst.0000.png"), graphText);
    // The viewer's screenshot, and a script's save of the script itself.
    refused("view --headless --graph graph.json --size 16x16 --frames 2 --screenshot graph.json",
            "would overwrite the input");
    writeText("script.txt", "1 save script.txt\n");
    refused("view --headless --graph graph.json --size 16x16 --frames 2 --script script.txt",
            "would overwrite the input");
    EXPECT_EQ(readText("graph.json"), graphText);
    EXPECT_EQ(readText("script.txt"), "1 save script.txt\n");
    expectNoTemporaries();
}

TEST_F(Cli, AnEnvironmentColourIsThreeNonNegativeNumbers) {
    const std::string gbuffer = quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/GBufferRT.json");
    const std::string scene = quoted(loom::test::dataScene("cornell_box.gltf"));
    for (const std::string env :
         {"1e39,0,0", "nan,0,0", "1,2", ",,", "-1,0,0", "0.5,0.5,0.5,0.5", "1,x,2", "1,2,3,", "0x1p3,0,0"}) {
        const RunResult r =
            loom("render --graph " + gbuffer + " --scene " + scene + " --size 16x16 -q --out out --env '" + env + "'");
        expectBadInput(r, {"--env", "neither a colour nor an existing file"});
    }
    EXPECT_EQ(
        loom("render --graph " + gbuffer + " --scene " + scene + " --size 16x16 -q --out out --env ' 0.1, 0.2 ,0.3'")
            .code,
        0);
}

TEST_F(Cli, ACameraPathOnAnAnimatedCameraIsIgnoredWithAWarning) {
    // cornell_dynamic animates its camera: the frames follow it, and --camera-path says it has no effect; on the
    // still box the path applies silently.
    const std::string gbuffer = quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/GBufferRT.json");
    RunResult r =
        loom("render --graph " + gbuffer + " --scene " + quoted(loom::test::dataScene("cornell_dynamic.gltf")) +
             " --size 16x16 --camera-path orbit -q --out out");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "--camera-path orbit is ignored");
    EXPECT_CONTAINS(r.output, "animates its camera");
    r = loom("render --graph " + gbuffer + " --scene " + quoted(loom::test::dataScene("cornell_box.gltf")) +
             " --size 16x16 --camera-path orbit -q --out out");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(r.output.find("ignored"), std::string::npos) << r.output;
}

TEST_F(Cli, ASceneWithNoLightWarnsOnceAndNamesEnv) {
    // One grey triangle: no emission, no punctual light; black until --env lights it.
    loom::test::writeTriangleGltf(mDir, "dark", {-1, -1, 0, 1, -1, 0, 0, 1, 0}, {}, {0, 1, 2},
                                  {{"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1}}}}});
    const std::string pt = quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracer.json");
    const auto warnings = [](const std::string& text) {
        size_t n = 0;
        for (size_t at = text.find("has no light"); at != std::string::npos; at = text.find("has no light", at + 1))
            ++n;
        return n;
    };
    RunResult r = loom("render --graph " + pt + " --scene dark.gltf --size 16x16 --frames 3 -q --out out");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(warnings(r.output), 1u) << r.output;
    EXPECT_CONTAINS(r.output, "renders black");
    EXPECT_CONTAINS(r.output, "--env 1,1,1");
    EXPECT_CONTAINS(r.output, "no environment (no --env)");
    // bench and view load scenes the same way, and say it the same once.
    r = loom(
        "bench --scene dark.gltf --size 16x16 --frames 3 --warmup 1 --reference-spp 4 --graph PathTracerRaw "
        "--brute-force-spp 1 --cache cache --out bench");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(warnings(r.output), 1u) << r.output;
    r = loom("view --graph " + pt + " --scene dark.gltf --size 16x16 --headless --frames 2");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(warnings(r.output), 1u) << r.output;
    r = loom("render --graph " + pt + " --scene dark.gltf --size 16x16 -q --out out --env 0,0,0");
    EXPECT_EQ(warnings(r.output), 1u) << r.output;
    EXPECT_CONTAINS(r.output, "a black environment (--env)");
    // Lit by the environment, by an emitter, or by a punctual light: no word.
    r = loom("render --graph " + pt + " --scene dark.gltf --size 16x16 -q --out out --env 1,1,1");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(warnings(r.output), 0u) << r.output;
    for (const char* lit : {"cornell_box.gltf", "materials.gltf"}) {
        r = loom("render --graph " + pt + " --scene " + quoted(loom::test::dataScene(lit)) +
                 " --size 16x16 -q --out out");
        EXPECT_EQ(warnings(r.output), 0u) << lit << "\n" << r.output;
    }
}

// --hold converges one frame of an animated scene: every iteration sees the scene and camera at the time of
// --start-frame (its vbuffer at the first and the last iteration is byte for byte that of a plain render of that
// frame, and not that of the frame whose index the last iteration has), the random numbers advance (the squared
// error against a longer held run falls as 1/N), and only the held result is written, under the frame's number.
TEST_F(Cli, HoldAccumulatesOneFrameOfAnAnimatedScene) {
    writeText("held.json", R"({"loom_graph": 1, "name": "Held", "passes": [
        {"name": "GBuffer", "type": "GBufferRT"},
        {"name": "PathTracer", "type": "PathTracer", "params": {"maxBounces": 3}},
        {"name": "Accumulate", "type": "AccumulatePass", "params": {"precision": "double"}}],
      "edges": [["PathTracer.color", "Accumulate.src"]], "outputs": ["Accumulate.dst"]})");
    const std::string scene = quoted(loom::test::dataScene("cornell_dynamic.gltf"));
    const auto run = [&](const std::string& out, const std::string& extra) {
        const RunResult r =
            loom("render --graph held.json --scene " + scene + " --size 32x32 -q --out " + out + " " + extra);
        EXPECT_EQ(r.code, 0) << r.output;
        return r;
    };
    // Frame 30 held for 16 iterations (indices 30-45), and plain renders of frames 30 and 45.
    run("held", "--start-frame 30 --frames 16 --hold --dump GBuffer.vbuffer --dump-frames 30,45");
    run("plain30", "--start-frame 30 --frames 1 --dump GBuffer.vbuffer");
    run("plain45", "--start-frame 45 --frames 1 --dump GBuffer.vbuffer");
    // Accumulating a moving scene without --hold restarts every frame: one warning that names --hold. Held, or on
    // a still scene, none.
    const RunResult moving = run("moving", "--start-frame 30 --frames 3");
    const std::string restarted = "restarted on 2 of the 2 frames";
    const size_t at = moving.output.find(restarted);
    ASSERT_NE(at, std::string::npos) << moving.output;
    EXPECT_EQ(moving.output.find(restarted, at + 1), std::string::npos) << moving.output;  // once
    EXPECT_NE(moving.output.find("--hold"), std::string::npos) << moving.output;
    EXPECT_EQ(run("held3", "--start-frame 30 --frames 3 --hold").output.find("restarted"), std::string::npos);
    const RunResult still =
        loom("render --graph held.json --scene " + quoted(loom::test::dataScene("cornell_box.gltf")) +
             " --size 32x32 -q --out still --frames 3");
    EXPECT_EQ(still.code, 0) << still.output;
    EXPECT_EQ(still.output.find("restarted"), std::string::npos) << still.output;
    // The default graph's accumulator restarts under motion by design (its output is SVGF's then): no warning.
    const RunResult converging = loom(
        "render --graph " + quoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracerSVGF.json") + " --scene " +
        quoted(loom::test::dataScene("cornell_dynamic.gltf")) + " --size 32x32 -q --out converging --frames 3");
    EXPECT_EQ(converging.code, 0) << converging.output;
    EXPECT_EQ(converging.output.find("restarted"), std::string::npos) << converging.output;
    const std::vector<std::string> expected = {"Accumulate.dst.0030.exr", "GBuffer.vbuffer.0030.exr",
                                               "GBuffer.vbuffer.0045.exr"};
    EXPECT_EQ(files("held"), expected);
    const std::string first = readText("held/GBuffer.vbuffer.0030.exr");
    ASSERT_FALSE(first.empty());
    EXPECT_EQ(readText("held/GBuffer.vbuffer.0045.exr"), first);
    EXPECT_EQ(readText("plain30/GBuffer.vbuffer.0030.exr"), first);
    EXPECT_NE(readText("plain45/GBuffer.vbuffer.0045.exr"), first);  // the scene moves between frames 30 and 45

    // Squared error against 128 iterations of 16 spp (2048 spp) for N = 1, 4, 16, 64 iterations of 1 spp.
    run("ref", "--start-frame 30 --frames 128 --hold --set PathTracer.samplesPerPixel=16 --set PathTracer.seed=9");
    const loom::Texture ref = loom::readImage(path("ref/Accumulate.dst.0030.exr"));
    std::vector<double> xs, ys;
    for (int n : {1, 4, 16, 64}) {
        const std::string out = "n" + std::to_string(n);
        run(out, "--start-frame 30 --hold --frames " + std::to_string(n));
        const loom::Texture img = loom::readImage(path(out + "/Accumulate.dst.0030.exr"));
        ASSERT_EQ(img.width(), ref.width());
        const auto a = img.view<glm::vec4>(), b = ref.view<glm::vec4>();
        double se = 0.0;
        for (uint32_t y = 0; y < img.height(); ++y)
            for (uint32_t x = 0; x < img.width(); ++x)
                for (int k = 0; k < 3; ++k)
                    se += double(a.at(x, y)[k] - b.at(x, y)[k]) * (a.at(x, y)[k] - b.at(x, y)[k]);
        const double mse = se / (3.0 * img.width() * img.height());
        std::printf("held %2d iterations: MSE %.4g\n", n, mse);
        xs.push_back(std::log(double(n)));
        ys.push_back(std::log(mse));
    }
    double mx = 0, my = 0, sxy = 0, sxx = 0;
    for (size_t i = 0; i < xs.size(); ++i) {
        mx += xs[i] / double(xs.size());
        my += ys[i] / double(xs.size());
    }
    for (size_t i = 0; i < xs.size(); ++i) {
        sxy += (xs[i] - mx) * (ys[i] - my);
        sxx += (xs[i] - mx) * (xs[i] - mx);
    }
    std::printf("fitted slope of log MSE over log N: %.3f\n", sxy / sxx);
    EXPECT_NEAR(sxy / sxx, -1.0, 0.2);

    // Nonsense: --hold needs a scene whose time it holds.
    expectBadInput(render("--hold --frames 4"), {"--hold", "--scene"});
}
