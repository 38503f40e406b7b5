// The limits of the render and bench command lines, each a clear refusal (exit code 2) instead of a wrong result or
// a silent wait: seed offsets that would reach another seed's random numbers, warm-ups of a billion frames, file
// numbers that overflow, and a pass's parameter given as if it were an option.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;
namespace fs = std::filesystem;

#define EXPECT_CONTAINS(text, part) \
    EXPECT_NE(std::string(text).find(part), std::string::npos) << "'" << (part) << "' not in:\n" << (text)

namespace {

const std::string kSourceDir = LOOM_TEST_SOURCE_DIR;
const std::string kDynamic = test::dataScene("cornell_dynamic.gltf");

class CliLimits : public test::TempDirTest {
protected:
    test::CliResult loom(const std::string& args) { return test::runLoom(mDir, args); }
    void expectBadInput(const test::CliResult& r, std::initializer_list<const char*> parts) {
        EXPECT_EQ(r.code, 2) << r.output;
        for (const char* p : parts) EXPECT_CONTAINS(r.output, p);
    }
    /// A held shard of the reference graph on the moving scene, 32x24, 1 spp.
    std::string shard(const std::string& more) {
        return "render --graph " + test::shellQuoted(kSourceDir + "/graphs/ReferenceShard.json") + " --scene " +
               test::shellQuoted(kDynamic) + " --size 32x24 --hold --set PathTracer.samplesPerPixel=1 -q " + more;
    }
};

}  // namespace

// A pass draws the random numbers of frame index + (seed << 32): a held iteration's index K + offset + i must stay
// below 2^32, or `--seed-offset 4294967296` would draw exactly PathTracer.seed=1's samples and a merge could not
// tell. The last index allowed renders.
TEST_F(CliLimits, SeedOffsetsNeverReachAnotherSeedsFrames) {
    expectBadInput(loom(shard("--seed-offset 4294967296 --out a")), {"--seed-offset", "another seed"});
    expectBadInput(loom(shard("--start-frame 3 --frames 2 --seed-offset 4294967292 --out b")),
                   {"--seed-offset", "frame index 4294967296", "at most 4294967291"});
    EXPECT_FALSE(fs::exists(mDir / "a" / "Accumulate.dst.0000.exr"));
    const test::CliResult last = loom(shard("--start-frame 3 --frames 2 --seed-offset 4294967291 --out c"));
    EXPECT_EQ(last.code, 0) << last.output;
    EXPECT_TRUE(fs::exists(mDir / "c" / "Accumulate.dst.0003.exr"));
}

// The path tracer itself refuses an index past 2^32 - 1 (a runtime error, not a silent repeat of the next seed).
TEST_F(CliLimits, PathTracerRefusesFrameIndicesThatRepeatTheNextSeed) {
    auto scene = Scene::load(kDynamic);
    scene->update(0.0);
    const nlohmann::json g = {{"loom_graph", 1},
                              {"name", "pt"},
                              {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", {{"seed", 1}}}}}},
                              {"outputs", {"PT.color"}}};
    auto graph = test::compiledGraph(g, scene, 8, 8);
    graph->execute(FrameInfo{0xFFFFFFFFull, 0.0, scene.get(), &scene->camera});
    try {
        graph->execute(FrameInfo{0x100000000ull, 0.0, scene.get(), &scene->camera});
        FAIL() << "frame index 2^32 was rendered";
    } catch (const Error& e) {
        EXPECT_EQ(e.info().kind, ErrorKind::Runtime);
        EXPECT_CONTAINS(e.what(), "seed 2");
    }
}

// --start-frame K of a graph with history warms up from frame 0. A billion frames is refused at once (--warmup N is
// the way out); a small warm-up says what it runs.
TEST_F(CliLimits, HugeWarmUpsAreRefusedAndSmallOnesAnnounced) {
    const std::string graph =
        "render --graph " + test::shellQuoted(kSourceDir + "/graphs/PathTracerSVGF.json") + " --scene " +
        test::shellQuoted(kDynamic) + " --size 32x24 ";
    expectBadInput(loom(graph + "--start-frame 1000000000 --out a"),
                   {"--start-frame", "1000000000 unwritten warm-up frames", "--warmup 64", "--warmup all"});
    EXPECT_FALSE(fs::exists(mDir / "a" / "ToneMap.dst.1000000000.png"));
    const test::CliResult few = loom(graph + "--start-frame 1000000000 --warmup 2 --out b");
    EXPECT_EQ(few.code, 0) << few.output;
    EXPECT_CONTAINS(few.output, "warm-up: frames 999999998..999999999 (2 frame(s))");
    EXPECT_TRUE(fs::exists(mDir / "b" / "ToneMap.dst.1000000000.png"));
    const test::CliResult none = loom(graph + "--start-frame 3 --warmup 0 --out c");
    EXPECT_EQ(none.code, 0) << none.output;
    EXPECT_EQ(none.output.find("warm-up"), std::string::npos) << none.output;
}

// Bench frame i reads file number i + --reference-first-frame: a first number whose sum would overflow is refused
// before anything is read.
TEST_F(CliLimits, ReferenceFileNumbersThatOverflowAreRefused) {
    for (const char* first : {"9223372036854775807", "-9223372036854775807", "999999999999999997"})
        expectBadInput(loom(std::string("bench --graph PathTracerATrous --reference-sequence 'ref_####.exr' "
                                        "--size 8x8 --frames 4 --warmup 1 --reference-first-frame ") +
                            first),
                       {"--reference-first-frame", "out of range"});
}

// --references-only renders references (warm-up frames included) and measures nothing, so fewer frames than the
// warm-up are fine there; a benchmark of them still is not.
TEST_F(CliLimits, ReferencesOnlyAcceptsFewerFramesThanTheWarmUp) {
    const std::string bench = "bench --scene " + test::shellQuoted(kDynamic) +
                              " --size 32x24 --reference-spp 2 --cache cache --graph PathTracerATrous --frames 2";
    const test::CliResult only = loom(bench + " --references-only");
    ASSERT_EQ(only.code, 0) << only.output;
    EXPECT_CONTAINS(only.output, "references only: 2 frame(s) rendered");
    expectBadInput(loom(bench + " --out o"), {"--frames", "nothing to measure"});
}

// A pass's parameter given as an option names the passes that declare it and how to set it.
TEST_F(CliLimits, AParameterGivenAsAnOptionSaysHowToSetIt) {
    const test::CliResult r = loom("render --graph " + test::shellQuoted(kSourceDir + "/graphs/PathTracer.json") +
                                   " --maxBounces 3");
    expectBadInput(r, {"--maxBounces", "'maxBounces' is a parameter of", "PathTracer", "--set PASS.maxBounces=VALUE"});
    // An option no pass declares gets the plain hint.
    const test::CliResult other = loom("render --graph x.json --nonsense 1");
    EXPECT_EQ(other.code, 2);
    EXPECT_EQ(other.output.find("is a parameter of"), std::string::npos) << other.output;
}

// --dry-run checks everything a render would (graph, scene, --set, size, frame and seed limits, warm-up) and stops
// before the first frame: exit 0 with nothing written, or exit 2 naming what the render would refuse.
TEST_F(CliLimits, DryRunChecksEverythingAndWritesNothing) {
    const test::CliResult ok = loom(shard("--start-frame 3 --frames 4 --seed-offset 8 --dry-run --out dry"));
    EXPECT_EQ(ok.code, 0) << ok.output;
    EXPECT_CONTAINS(ok.output, "dry run: 4 frame(s) from frame 3 at 32x24 would render");
    EXPECT_FALSE(fs::exists(mDir / "dry"));
    expectBadInput(loom(shard("--set Nope.x=1 --dry-run --out dry")), {"Nope"});
    expectBadInput(loom(shard("--set PathTracer.samplesPerPixel=-1 --dry-run --out dry")), {"samplesPerPixel"});
    expectBadInput(loom(shard("--size 0x0 --dry-run --out dry")), {"--size"});
    expectBadInput(loom(shard("--seed-offset 4294967295 --frames 2 --dry-run --out dry")), {"--seed-offset"});
    const std::string svgf = "render --graph " + test::shellQuoted(kSourceDir + "/graphs/PathTracerSVGF.json") +
                             " --scene " + test::shellQuoted(kDynamic) + " --size 32x24 --dry-run --out dry ";
    expectBadInput(loom(svgf + "--start-frame 20000"), {"--warmup"});
    const test::CliResult warm = loom(svgf + "--start-frame 20");
    EXPECT_EQ(warm.code, 0) << warm.output;
    EXPECT_CONTAINS(warm.output, "after 20 warm-up frame(s)");
    EXPECT_FALSE(fs::exists(mDir / "dry"));
}

// A multilayer reference named without its layer (or with an empty one after the colon) says how to name one, with
// a layer the file has.
TEST_F(CliLimits, AMultilayerReferenceWithoutItsLayerSaysHowToNameIt) {
    const std::string pattern = kSourceDir + "/data/sequences/blender_cornell/reference_####.exr";
    for (const std::string& spec : {pattern, pattern + ":"})
        expectBadInput(loom("bench --graph DenoiseSequence --size 64x48 --frames 4 --warmup 1 --reference-first-frame 1 "
                            "--reference-sequence " +
                            test::shellQuoted(spec)),
                       {"after the file name and a colon", "reference_0001.exr:ViewLayer.Combined'"});
}
