// Source passes give the frame size: without --size, a graph whose source pass reads files renders at the files'
// size (RenderPass::naturalSize, RenderGraph::naturalSize); a given --size still wins, or is refused as before where
// the files differ; two sources of different sizes, and missing files, are one error each. The sequences Loom ships
// load through DenoiseSequence without --size.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "ExrTestUtil.h"
#include "TestUtil.h"
#include "loom/ImageIO.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

const std::string kSourceDir = LOOM_TEST_SOURCE_DIR;
const std::string kSequenceGraph = kSourceDir + "/graphs/DenoiseSequence.json";
const std::string kBlenderCornell = kSourceDir + "/data/sequences/blender_cornell/noisy_####.exr";
const std::string kLightStep = kSourceDir + "/data/sequences/loom_lightstep";

/// A still w x h frame with Blender's layer names.
std::map<std::string, test::ExrTestChannel> stillFrame(int w, int h) {
    std::map<std::string, test::ExrTestChannel> ch;
    const auto constant = [&](const std::string& name, float v) {
        ch["ViewLayer." + name] = {std::vector<float>(size_t(w * h), v)};
    };
    for (const char* c : {"R", "G", "B"}) constant(std::string("Combined.") + c, 0.4f);
    constant("Combined.A", 1.f);
    constant("Normal.Z", 1.f);
    constant("Depth.Z", 4.f);
    constant("Vector.X", 0.f);
    constant("Vector.Y", 0.f);
    return ch;
}

class SequenceSize : public test::TempDirTest {
protected:
    test::CliResult loom(const std::string& args) {
        fs::create_directories(mDir / "out");
        return test::runLoom(mDir, args);
    }
    /// `loom render` of DenoiseSequence on Blender's Cornell sequence, into mDir/out.
    test::CliResult renderCornell(const std::string& more) {
        return loom("render --graph " + test::shellQuoted(kSequenceGraph) + " --set " +
                    test::shellQuoted("Frames.path=" + kBlenderCornell) + " --out out -q " + more);
    }
    void expectBadInput(const test::CliResult& r, const std::vector<std::string>& parts) {
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_NE(r.output.find("error:"), std::string::npos) << r.output;
        for (const auto& p : parts) EXPECT_NE(r.output.find(p), std::string::npos) << p << "\n" << r.output;
    }
    Texture output(const std::string& name) { return readImage(mDir / "out" / name); }
};

}  // namespace

// The shipped sequence is 64x48: without --size the graph renders at it, and says so.
TEST_F(SequenceSize, DenoiseSequenceRendersAtTheSequencesSizeWithoutSize) {
    const test::CliResult r = renderCornell("--frames 2");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("frame size 64x48"), std::string::npos) << r.output;
    const Texture frame = output("ToneMap.dst.0001.png");
    EXPECT_EQ(frame.width(), 64u);
    EXPECT_EQ(frame.height(), 48u);
    // The plan and the dry run take the same size.
    const test::CliResult check = loom("check " + test::shellQuoted(kSequenceGraph) + " --set " +
                                       test::shellQuoted("Frames.path=" + kBlenderCornell));
    ASSERT_EQ(check.code, 0) << check.output;
    EXPECT_NE(check.output.find("64x48"), std::string::npos) << check.output;
    const test::CliResult dry = renderCornell("--frames 2 --dry-run");
    ASSERT_EQ(dry.code, 0) << dry.output;
    EXPECT_NE(dry.output.find("at 64x48 would render"), std::string::npos) << dry.output;
}

// A given --size wins where it fits the files, and is refused, naming the files' size, where it does not.
TEST_F(SequenceSize, AGivenSizeStillWinsOrIsRefused) {
    const test::CliResult same = renderCornell("--frames 1 --size 64x48");
    ASSERT_EQ(same.code, 0) << same.output;
    EXPECT_EQ(same.output.find("no --size"), std::string::npos) << same.output;
    EXPECT_EQ(output("ToneMap.dst.0000.png").width(), 64u);
    expectBadInput(renderCornell("--frames 1 --size 32x32"), {"is 64x48", "32x32", "--size 64x48"});
    expectBadInput(renderCornell("--frames 1 --size 0x48"), {"--size", "out of range"});
}

// A graph without a source pass keeps the command's default size.
TEST_F(SequenceSize, NoSourceKeepsTheDefaultSize) {
    const test::CliResult r =
        loom("render --graph " + test::shellQuoted(kSourceDir + "/graphs/TestPattern.json") + " --out out -q");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(r.output.find("no --size"), std::string::npos) << r.output;
    const Texture frame = output("Display.dst.0000.png");
    EXPECT_EQ(frame.width(), 256u);
    EXPECT_EQ(frame.height(), 256u);
}

// Two sources of different sizes: without --size, one error naming both passes and both sizes.
TEST_F(SequenceSize, SourcesThatDisagreeNameBoth) {
    test::writeExrChannels(mDir / "big_0001.exr", 16, 12, stillFrame(16, 12));
    test::writeExrChannels(mDir / "small_0001.exr", 8, 6, stillFrame(8, 6));
    std::ofstream(mDir / "two.json") << R"({"loom_graph": 1, "name": "Two", "passes": [
        {"name": "Big", "type": "ImageSequence", "params": {"path": "big_####.exr", "firstFrame": 1}},
        {"name": "Small", "type": "ImageSequence", "params": {"path": "small_####.exr", "firstFrame": 1}}],
      "outputs": ["Big.color", "Small.color"]})";
    const test::CliResult r = loom("render --graph two.json --out out -q");
    expectBadInput(r, {"Big is 16x12", "Small is 8x6", "one size"});
    EXPECT_EQ(loom("render --graph two.json --out out -q --size 8x6").code, 2);  // Big's files are not 8x6
    expectBadInput(loom("check two.json"), {"Big is 16x12", "Small is 8x6"});
}

// Missing files without --size: one error, naming the pass's parameter and the first frame's file.
TEST_F(SequenceSize, MissingFilesAreOneErrorNamingThePass) {
    const std::string pattern = (mDir / "nowhere" / "frame_####.exr").string();
    const test::CliResult r = loom("render --graph " + test::shellQuoted(kSequenceGraph) + " --set " +
                                   test::shellQuoted("Frames.path=" + pattern) + " --out out -q");
    expectBadInput(r, {"Frames.path", "frame_0001.exr", "does not exist", "firstFrame"});
    EXPECT_EQ(r.output.find("ImageSequence."), std::string::npos) << r.output;
    size_t errors = 0;
    for (size_t at = r.output.find("error:"); at != std::string::npos; at = r.output.find("error:", at + 1)) ++errors;
    EXPECT_EQ(errors, 1u) << r.output;
}

// bench takes the size from the benchmarked graphs' sources too, and checks the given references against it.
TEST_F(SequenceSize, BenchTakesTheSequencesSize) {
    const test::CliResult r =
        loom("bench --graph " + test::shellQuoted(kSequenceGraph) + " --set " +
             test::shellQuoted("Frames.path=" + kBlenderCornell) + " --frames 3 --warmup 1 --reference-sequence " +
             test::shellQuoted(kSourceDir + "/data/sequences/blender_cornell/reference_####.exr:ViewLayer.Combined") +
             " --reference-first-frame 1 --out out");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("frame size 64x48"), std::string::npos) << r.output;
}

// Loom's own light-step sequence (data/sequences/loom_lightstep) loads through DenoiseSequence with the loom preset,
// at its own size, and its references load as a bench's given references.
TEST_F(SequenceSize, LoomLightStepLoadsThroughDenoiseSequence) {
    const std::string frames = " --set Frames.preset=loom --set " + test::shellQuoted("Frames.path=" + kLightStep) +
                               " --set Frames.firstFrame=33";
    const test::CliResult r = loom("render --graph " + test::shellQuoted(kSequenceGraph) + frames +
                                   " --frames 2 --out out -q --stats stats.json");
    ASSERT_EQ(r.code, 0) << r.output;
    const Texture frame = output("ToneMap.dst.0001.png");
    EXPECT_EQ(frame.width(), 64u);
    EXPECT_EQ(frame.height(), 48u);
    const test::CliResult bench =
        loom("bench --graph " + test::shellQuoted(kSequenceGraph) + frames +
             " --frames 3 --warmup 1 --reference-sequence " +
             test::shellQuoted(kLightStep + "/reference_####.exr") + " --reference-first-frame 33 --out out");
    ASSERT_EQ(bench.code, 0) << bench.output;
}
