// loom bench's lag figures end to end on a tiny case (64x64, 20 frames): every run has the camera cut and the
// lighting step, graphs with a G-buffer have the age buckets, the brute-force path tracer (no history) recovers at
// once, the CSV marks warm-up frames and events, summary.md has the lag tables, and bad event frames exit with 2.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "TestUtil.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

const std::string kDynamic = loom::test::dataScene("cornell_dynamic.gltf");

std::string benchArgs(const std::string& extra) {
    return "bench --scene " + loom::test::shellQuoted(kDynamic) +
           " --size 64x64 --frames 20 --warmup 16 --reference-spp 32 --brute-force-spp 4 --cache cache --out out " +
           extra;
}

class BenchLagCli : public loom::test::TempDirTest {
protected:
    loom::test::CliResult run(const std::string& args) const { return loom::test::runLoom(mDir, args); }
    std::string readText(const std::string& rel) const {
        std::ifstream in(mDir / rel);
        std::stringstream s;
        s << in.rdbuf();
        return s.str();
    }
};

}  // namespace

TEST_F(BenchLagCli, EveryRunHasItsLagFigures) {
    const auto r = run(benchArgs("--graph PathTracerSVGF --event-frame 18 --event-frame 18"));
    ASSERT_EQ(r.code, 0) << r.output;
    const json results = json::parse(readText("out/results.json"), nullptr, false);
    ASSERT_FALSE(results.is_discarded());
    EXPECT_EQ(results["event_frames"], json::array({18}));

    const json& svgf = results["variants"].at(0);
    const json& brute = results["brute_force"].at(0);
    for (const json* run : {&svgf, &brute}) {
        const json& lag = (*run)["lag"];
        ASSERT_TRUE(lag.is_object()) << (*run)["graph"];
        EXPECT_EQ(lag["metric"], "relmse");
        const json& events = lag["events"];
        ASSERT_EQ(events.size(), 2u);
        // The cut at the run's first frame (brute force starts at the last warm-up frame), then the step.
        EXPECT_EQ(events[0]["kind"], "cut");
        EXPECT_EQ(events[0]["frame"], (*run)["frames"][0]["frame"]);
        EXPECT_EQ(events[1]["kind"], "light");
        EXPECT_EQ(events[1]["frame"], 18);
        EXPECT_EQ(events[1]["segment_frames"], 2);
        for (const json& e : events) {
            EXPECT_GT(e["steady_relmse"].get<double>(), 0.0);
            if (e["frames_to_recover"].is_number()) {
                EXPECT_LT(e["frames_to_recover"].get<int>(), e["segment_frames"].get<int>());
            }
        }
    }
    // The whole warm-up is measured for the graph: 20 frames, the cut's segment up to the step at 18.
    EXPECT_EQ(svgf["frames"].size(), 20u);
    EXPECT_EQ(svgf["lag"]["events"][0]["segment_frames"], 18);
    // No history: the brute-force path tracer is back at its steady state at once after the cut.
    EXPECT_EQ(brute["lag"]["events"][0]["frames_to_recover"], 0) << brute["lag"].dump(1);
    EXPECT_TRUE(brute["lag"]["disocclusion"].is_null());

    // The graph's G-buffer gives the age buckets: every hit pixel of the 4 measured frames lands in one, and the
    // oldest bucket (16+) holds the pixels seen since the cut. (Which bucket is worst depends on the denoiser: at
    // 64x64 against an 8-bounce reference the bias of the graph's 3 bounces dominates the old pixels.)
    const json& dis = svgf["lag"]["disocclusion"];
    ASSERT_TRUE(dis.is_object()) << svgf["lag"].dump(1);
    ASSERT_EQ(dis["buckets"].size(), 17u);
    EXPECT_EQ(dis["buckets"][16]["label"], "16+");
    uint64_t samples = 0;
    for (const json& b : dis["buckets"]) {
        samples += b["samples"].get<uint64_t>();
        if (b["samples"].get<uint64_t>() > 0) {
            EXPECT_GE(b["relmse"].get<double>(), 0.0);
        } else {
            EXPECT_TRUE(b["relmse"].is_null());
        }
    }
    EXPECT_GT(samples, 0u);
    EXPECT_LE(samples, 4u * 64u * 64u);
    EXPECT_GT(dis["buckets"][16]["samples"].get<uint64_t>(), samples / 2);
    ASSERT_TRUE(dis["frames_to_recover"].is_number());
    EXPECT_LE(dis["frames_to_recover"].get<int>(), 16);

    // The CSV keeps every frame's error, warm-up marked, and names the events.
    std::istringstream csv(readText("out/results.csv"));
    std::string line;
    std::getline(csv, line);
    EXPECT_NE(line.find(",warmup,"), std::string::npos);
    EXPECT_NE(line.find(",event,"), std::string::npos);
    int cuts = 0, lights = 0;
    while (std::getline(csv, line)) {
        cuts += line.find(",cut,") != std::string::npos;
        lights += line.find(",light,") != std::string::npos;
    }
    EXPECT_EQ(cuts, 2);    // one per run
    EXPECT_EQ(lights, 2);  // frame 18 of each run

    const std::string md = readText("out/summary.md");
    EXPECT_NE(md.find("| graph | params | camera cut | lighting steps | disocclusion |"), std::string::npos) << md;
    EXPECT_NE(md.find("| 16+ |"), std::string::npos) << md;
}

TEST_F(BenchLagCli, EventFramesOutsideTheSequenceAreBadInput) {
    for (const char* frame : {"0", "20", "-3", "x"}) {
        const auto r = run(benchArgs("--graph PathTracerATrous --event-frame " + std::string(frame)));
        EXPECT_EQ(r.code, 2) << frame << "\n" << r.output;
        EXPECT_NE(r.output.find("--event-frame"), std::string::npos) << r.output;
        EXPECT_FALSE(fs::exists(mDir / "out" / "results.json"));
    }
}
