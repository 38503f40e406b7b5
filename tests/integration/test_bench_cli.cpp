// loom bench on tiny cases (64x64, a few frames, low reference spp): every output file, the shape and sanity of the
// results (finite, the brute-force error falling with spp, a denoiser below 1 spp, the curve extended until it
// reaches every graph), the matched-length reference and its bias row, the reference noise estimate, box-filtered
// references for jittered sequences, the reference and brute-force caches (a second run hits them and gives
// bit-identical metrics, also with another thread count), sweeps, and bad input (exit 2). Then given references
// (--reference-sequence): a round trip through bench's own reference cache gives the same metrics bit for bit; a
// graph that needs no scene, measured against the frames `loom render` wrote of it, has no error (and some against
// other frames); every bad reference (missing frame, wrong size, no frame field, missing layer, truncated file, NaN
// or infinite pixels) and every option that would do nothing is refused with exit code 2.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <glm/vec4.hpp>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/ImageIO.h"
#include "loom/Texture.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

const std::string kDynamic = loom::test::dataScene("cornell_dynamic.gltf");
const std::string kBox = loom::test::dataScene("cornell_box.gltf");
const std::string kTestPattern = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/TestPattern.json";

/// The tiny case: the moving-object scene (a reference per frame), 8 frames, 2 of them warm-up.
std::string tinyArgs(const std::string& out) {
    return "bench --scene " + loom::test::shellQuoted(kDynamic) +
           " --size 64x64 --frames 8 --warmup 2 --reference-spp 32 --cache cache --out " + out;
}

std::vector<std::string> splitCsvLine(const std::string& line) {
    std::vector<std::string> fields;
    std::string cur;
    bool inQuotes = false;
    for (char c : line) {
        if (c == '"')
            inQuotes = !inQuotes;
        else if (c == ',' && !inQuotes) {
            fields.push_back(cur);
            cur.clear();
        } else
            cur += c;
    }
    fields.push_back(cur);
    return fields;
}

class BenchCli : public loom::test::TempDirTest {
protected:
    loom::test::CliResult run(const std::string& args) const { return loom::test::runLoom(mDir, args); }

    json readJson(const std::string& rel) const {
        std::ifstream in(mDir / rel);
        return json::parse(in, nullptr, false);
    }

    /// CSV rows as maps from the header's column names.
    std::vector<std::map<std::string, std::string>> readCsv(const std::string& rel) const {
        std::ifstream in(mDir / rel);
        std::string line;
        std::vector<std::map<std::string, std::string>> rows;
        if (!std::getline(in, line)) return rows;
        const std::vector<std::string> header = splitCsvLine(line);
        while (std::getline(in, line)) {
            const std::vector<std::string> f = splitCsvLine(line);
            EXPECT_EQ(f.size(), header.size()) << line;
            std::map<std::string, std::string> row;
            for (size_t i = 0; i < header.size() && i < f.size(); ++i) row[header[i]] = f[i];
            rows.push_back(std::move(row));
        }
        return rows;
    }

    /// Runs a successful bench of `scene` at 64x64 into `out` (cache "cache") and returns its results.json.
    json benchOk(const std::string& scene, const std::string& out, const std::string& extra) const {
        const auto r = run("bench --scene " + loom::test::shellQuoted(scene) + " --size 64x64 --cache cache --out " +
                           out + " " + extra);
        EXPECT_EQ(r.code, 0) << r.output;
        return readJson(out + "/results.json");
    }

    /// Expects exit code 2 and an "error:" message containing every part, and no result file. `options` replace
    /// the tiny case's options of the same name ("--frames 0") or are added.
    void expectBadInput(const std::vector<std::pair<std::string, std::string>>& options,
                        const std::vector<std::string>& parts) const {
        std::vector<std::pair<std::string, std::string>> args = {{"--scene", loom::test::shellQuoted(kDynamic)},
                                                                 {"--size", "64x64"},
                                                                 {"--frames", "8"},
                                                                 {"--warmup", "2"},
                                                                 {"--reference-spp", "32"},
                                                                 {"--cache", "cache"},
                                                                 {"--out", "out"},
                                                                 {"--graph", "PathTracerATrous"}};
        for (const auto& o : options) {
            auto it = std::find_if(args.begin(), args.end(), [&](const auto& a) { return a.first == o.first; });
            if (it != args.end())
                it->second = o.second;
            else
                args.push_back(o);
        }
        std::string command = "bench";
        for (const auto& [name, value] : args) command += " " + name + " " + value;
        expectRefused(run(command), parts, command);
    }

    /// Expects exit code 2, an "error:" message containing every part, and no results.csv in "out".
    void expectRefused(const loom::test::CliResult& r, const std::vector<std::string>& parts,
                       const std::string& command = "") const {
        EXPECT_EQ(r.code, 2) << command << "\n" << r.output;
        EXPECT_NE(r.output.find("error:"), std::string::npos) << r.output;
        for (const auto& p : parts)
            EXPECT_NE(r.output.find(p), std::string::npos) << "'" << p << "' not in\n" << r.output;
        EXPECT_FALSE(fs::exists(mDir / "out" / "results.csv")) << command;
    }
};

/// Per-frame metrics of every run in a results.json, keyed by run label and frame.
std::map<std::string, json> frameMetrics(const json& results) {
    std::map<std::string, json> out;
    for (const char* list : {"variants", "brute_force"}) {
        for (const json& run : results[list]) {
            for (const json& f : run["frames"]) {
                json m = f;
                m.erase("total_ms");
                m.erase("pass_ms");
                out[run["graph"].get<std::string>() + " " + run["params"].get<std::string>() + " " +
                    std::to_string(f["frame"].get<int>())] = m;
            }
        }
    }
    return out;
}

TEST_F(BenchCli, TinyRunWritesEveryOutputWithSaneValues) {
    const auto r =
        run(tinyArgs("out") + " --graph PathTracerSVGF --graph PathTracerATrous --graph PathTracerAccumulate");
    ASSERT_EQ(r.code, 0) << r.output;
    for (const char* file : {"results.csv", "results.json", "summary.md"})
        EXPECT_TRUE(fs::is_regular_file(mDir / "out" / file)) << file;

    const json results = readJson("out/results.json");
    ASSERT_FALSE(results.is_discarded());
    ASSERT_EQ(results["variants"].size(), 3u);
    // The default curve: 1, 2, 4, ... spp until the first point at or below every graph's RelMSE, trimmed RelMSE
    // and FLIP (the one before it is above some graph in some metric).
    const json& curve = results["brute_force"];
    ASSERT_GE(curve.size(), 4u);
    for (size_t i = 0; i < curve.size(); ++i) EXPECT_EQ(curve[i]["spp"].get<int>(), 1 << i);
    auto crossesAll = [&](const json& point) {
        for (const json& v : results["variants"])
            for (const char* m : {"relmse", "trimmed_relmse", "flip"})
                if (point["summary"][m].get<double>() > v["summary"][m].get<double>()) return false;
        return true;
    };
    EXPECT_TRUE(crossesAll(curve[curve.size() - 1]));
    EXPECT_FALSE(crossesAll(curve[curve.size() - 2]));
    EXPECT_EQ(results["reference"]["frames_rendered"].get<int>(), 8);
    EXPECT_FALSE(results["reference"]["shared"].get<bool>());
    // The reference traces the graphs' 3 bounces; the bias against the reference graph's 8 is a row of its own,
    // taken over the 6 measured frames only.
    EXPECT_EQ(results["reference"]["max_bounces"].get<int>(), 3);
    EXPECT_EQ(results["reference"]["pixel_filter"], "center");
    const json& bias = results["bias"];
    ASSERT_TRUE(bias.is_object());
    EXPECT_EQ(bias["graph_bounces"].get<int>(), 3);
    EXPECT_EQ(bias["full_bounces"].get<int>(), 8);
    EXPECT_EQ(bias["frames_rendered"].get<int>(), 6);
    EXPECT_GT(bias["relmse"].get<double>(), 0.0);
    EXPECT_LE(bias["trimmed_relmse"].get<double>(), bias["relmse"].get<double>());
    // Reference noise from its 4 batches: positive, and below the 1 spp brute force's error by far (32 spp).
    const double noise = results["reference"]["noise_relmse"].get<double>();
    EXPECT_GT(noise, 0.0);
    EXPECT_LT(noise, 0.2 * curve[0]["summary"]["relmse"].get<double>());

    // CSV: one row per graph and frame, and per brute-force point and frame after the first warm-up frame.
    const auto rows = readCsv("out/results.csv");
    size_t graphRows = 0, bruteRows = 0;
    for (const auto& row : rows) {
        (row.at("kind") == "graph" ? graphRows : bruteRows) += 1;
        // Brute force is timed on the first 3 measured frames only.
        const int frame = std::stoi(row.at("frame"));
        const bool timed = row.at("kind") == "graph" || (frame >= 2 && frame < 5);
        EXPECT_EQ(row.at("total_ms").empty(), !timed) << row.at("kind") << " " << frame;
        for (const char* col : {"relmse", "trimmed_relmse", "smape", "psnr", "ssim", "flip"}) {
            const double v = std::stod(row.at(col));
            EXPECT_TRUE(std::isfinite(v)) << col;
            EXPECT_GE(v, 0.0) << col;
        }
        EXPECT_LE(std::stod(row.at("smape")), 1.0);
        EXPECT_LE(std::stod(row.at("ssim")), 1.0);
        EXPECT_LE(std::stod(row.at("flip")), 1.0);
        EXPECT_EQ(row.at("non_finite"), "0");
    }
    EXPECT_EQ(graphRows, 3u * 8u);
    EXPECT_EQ(bruteRows, curve.size() * 7u);

    // The brute-force error falls with spp: each doubling lowers RelMSE, and 8 spp is well below 1 spp (the
    // variance part of RelMSE halves per doubling). Each point is timed.
    for (size_t i = 0; i + 1 < curve.size(); ++i)
        EXPECT_LT(curve[i + 1]["summary"]["relmse"].get<double>(), curve[i]["summary"]["relmse"].get<double>()) << i;
    const double bf1 = curve[0]["summary"]["relmse"].get<double>();
    EXPECT_LT(curve[3]["summary"]["relmse"].get<double>(), 0.5 * bf1);
    EXPECT_LT(curve[3]["summary"]["flip"].get<double>(), curve[0]["summary"]["flip"].get<double>());

    std::map<std::string, json> byGraph;
    for (const json& v : results["variants"]) byGraph[v["graph"].get<std::string>()] = v;
    // The denoiser beats one sample per pixel, and its speedup is a number or a bound, never made up.
    const json& atrous = byGraph.at("PathTracerATrous");
    EXPECT_EQ(atrous["measured"], "SVGF.filtered");
    EXPECT_LT(atrous["summary"]["relmse"].get<double>(), bf1);
    const std::set<std::string> kinds = {"exact", "at_least", "at_most"};
    for (const json& v : results["variants"]) {
        for (const char* s : {"speedup_relmse", "speedup_trimmed_relmse", "speedup_flip"}) {
            EXPECT_TRUE(kinds.count(v[s]["kind"].get<std::string>())) << v["graph"] << " " << s;
            EXPECT_GT(v[s]["value"].get<double>(), 0.0);
            // The curve reaches every graph: a number, or an upper bound for one worse than 1 spp, never "> x".
            EXPECT_NE(v[s]["kind"], "at_least") << v["graph"] << " " << s;
        }
        EXPECT_TRUE(v["summary"]["temporal"].is_number());
    }
    for (const json& point : curve) EXPECT_GT(point["summary"]["total_ms"].get<double>(), 0.0);
    // Below the 1 spp error at a cost above the 1 spp time: not an "at most" bound.
    EXPECT_NE(atrous["speedup_relmse"]["kind"], "at_most");
    // The object moves every frame, so the accumulation restarts every frame: it is the 1 spp path tracer, frame
    // for frame (same samples, same metrics).
    const json& accumulate = byGraph.at("PathTracerAccumulate");
    EXPECT_EQ(accumulate["measured"], "Accumulate.dst");
    for (const json& bf : curve[0]["frames"]) {
        const json& acc = accumulate["frames"][bf["frame"].get<size_t>()];
        EXPECT_EQ(acc["relmse"].get<double>(), bf["relmse"].get<double>()) << bf["frame"];
        EXPECT_EQ(acc["flip"].get<double>(), bf["flip"].get<double>()) << bf["frame"];
    }
    // The default graph's image is its accumulator's, which is SVGF's while anything moves.
    EXPECT_EQ(byGraph.at("PathTracerSVGF")["measured"], "Accumulate.dst");

    // The Markdown table has a row per variant and per curve point.
    std::ifstream md(mDir / "out" / "summary.md");
    std::stringstream text;
    text << md.rdbuf();
    EXPECT_NE(text.str().find("| graph | params |"), std::string::npos);
    for (const char* g : {"| PathTracerSVGF |", "| PathTracerATrous |", "| PathTracerAccumulate |",
                          "PathTracer.samplesPerPixel=8", "| bias: 3 vs 8 bounces |", "Reference noise (RelMSE)"})
        EXPECT_NE(text.str().find(g), std::string::npos) << g;
}

TEST_F(BenchCli, SecondRunHitsTheCacheWithIdenticalMetricsOnAnyThreadCount) {
    const auto first = run(tinyArgs("a") + " --graph PathTracerATrous --brute-force-spp 1,4 --threads 2");
    ASSERT_EQ(first.code, 0) << first.output;
    EXPECT_EQ(first.output.find("cache hit"), std::string::npos);
    const auto second = run(tinyArgs("b") + " --graph PathTracerATrous --brute-force-spp 1,4 --threads 1");
    ASSERT_EQ(second.code, 0) << second.output;
    EXPECT_NE(second.output.find("cache hit, 8 frame(s)"), std::string::npos) << second.output;
    const json a = readJson("a/results.json"), b = readJson("b/results.json");
    EXPECT_EQ(b["reference"]["frames_cached"].get<int>(), 8);
    EXPECT_EQ(b["reference"]["frames_rendered"].get<int>(), 0);
    EXPECT_EQ(b["bias"]["frames_rendered"].get<int>(), 0);
    // Brute-force images come from the cache too: 1 spp, and 4 spp as 1 spp plus a batch of 3, over 7 frames.
    EXPECT_EQ(a["brute_force_cache"]["frames_rendered"].get<int>(), 2 * 7);
    EXPECT_EQ(b["brute_force_cache"]["frames_rendered"].get<int>(), 0);
    EXPECT_EQ(b["brute_force_cache"]["frames_cached"].get<int>(), 2 * 7);
    EXPECT_EQ(frameMetrics(a), frameMetrics(b));
    EXPECT_EQ(frameMetrics(a).size(), 8u + 2u * 7u);

    // A different reference spp is a different reference entry (matched and full length); the brute force's
    // images do not depend on the reference and are reused.
    const json other =
        benchOk(kDynamic, "c", "--frames 8 --warmup 2 --reference-spp 16 --graph PathTracerATrous --brute-force-spp 1");
    EXPECT_EQ(other["reference"]["frames_cached"].get<int>(), 0);
    EXPECT_EQ(other["brute_force_cache"]["frames_rendered"].get<int>(), 0);
    std::map<std::string, int> entries;
    for (const auto& e : fs::directory_iterator(mDir / "cache")) {
        const std::string name = e.path().filename().string();
        if (!e.is_directory()) continue;
        entries[name.find("_bruteforce_") != std::string::npos ? "bruteforce"
                : name.find("_3b_") != std::string::npos       ? "matched"
                : name.find("_8b_") != std::string::npos       ? "full"
                                                               : name] += 1;
    }
    EXPECT_EQ(entries, (std::map<std::string, int>{{"bruteforce", 1}, {"full", 2}, {"matched", 2}}));
}

// Workers that each render some frames' references (--references-only --reference-frames) fill one cache: a
// benchmark after them renders nothing, and the cached images are those of one machine rendering every frame, bit
// for bit (each frame's seeds depend on the frame alone).
TEST_F(BenchCli, ReferencesOnlyWorkersFillOneSharedCache) {
    const std::string graph = " --graph PathTracerATrous";
    const auto a = run(tinyArgs("a") + graph + " --references-only --reference-frames 0-3");
    ASSERT_EQ(a.code, 0) << a.output;
    EXPECT_NE(a.output.find("references only: 4 frame(s) rendered, 0 from the cache"), std::string::npos) << a.output;
    const auto b = run(tinyArgs("b") + graph + " --references-only --reference-frames 4-7 --threads 1");
    ASSERT_EQ(b.code, 0) << b.output;
    EXPECT_NE(b.output.find("references only: 4 frame(s) rendered, 0 from the cache"), std::string::npos) << b.output;
    EXPECT_FALSE(fs::exists(mDir / "a" / "results.json"));
    EXPECT_FALSE(fs::exists(mDir / "b" / "results.json"));

    const json c = benchOk(kDynamic, "c", "--frames 8 --warmup 2 --reference-spp 32 --brute-force-spp none" + graph);
    EXPECT_EQ(c["reference"]["frames_cached"].get<int>(), 8);
    EXPECT_EQ(c["reference"]["frames_rendered"].get<int>(), 0);
    EXPECT_EQ(c["bias"]["frames_rendered"].get<int>(), 0);

    // One machine, every frame, into another cache: the same files.
    const auto one =
        run("bench --scene " + loom::test::shellQuoted(kDynamic) +
            " --size 64x64 --frames 8 --warmup 2 --reference-spp 32 --cache single --references-only" + graph);
    ASSERT_EQ(one.code, 0) << one.output;
    size_t compared = 0;
    for (const auto& entry : fs::directory_iterator(mDir / "single"))
        for (const auto& f : fs::directory_iterator(entry.path())) {
            if (f.path().extension() != ".exr") continue;
            const fs::path shared = mDir / "cache" / entry.path().filename() / f.path().filename();
            ASSERT_TRUE(fs::exists(shared)) << shared;
            std::ifstream x(f.path(), std::ios::binary), y(shared, std::ios::binary);
            const std::string bx((std::istreambuf_iterator<char>(x)), {}), by((std::istreambuf_iterator<char>(y)), {});
            EXPECT_TRUE(bx == by) << f.path().filename();
            ++compared;
        }
    // Matched and full-length references, image and variance: 8 + 6 frames (the full one skips the warm-up).
    EXPECT_EQ(compared, 2u * (8u + 6u));

    expectBadInput({{"--reference-frames", "0-3"}}, {"--reference-frames", "--references-only"});
    expectBadInput({{"--references-only", ""}, {"--reference-frames", "5-9"}}, {"frame 8 is not inside the sequence"});
}

TEST_F(BenchCli, SweepGivesOneResultPerValue) {
    const json results =
        benchOk(kDynamic, "out",
                "--frames 4 --warmup 1 --reference-spp 16 --brute-force-spp 1 --graph PathTracerATrous "
                "--graph PathTracerAccumulate --sweep SVGF.iterations=1,3,5");
    ASSERT_EQ(results["variants"].size(), 4u);  // three sweep points, and the graph without an SVGF pass once
    std::vector<std::string> params;
    std::set<double> errors;
    for (const json& v : results["variants"]) {
        params.push_back(v["params"]);
        if (v["graph"] == "PathTracerATrous") errors.insert(v["summary"]["relmse"].get<double>());
    }
    EXPECT_EQ(params, (std::vector<std::string>{"SVGF.iterations=1", "SVGF.iterations=3", "SVGF.iterations=5", ""}));
    EXPECT_EQ(errors.size(), 3u) << "the swept parameter must change the result";
    EXPECT_EQ(readCsv("out/results.csv").size(), 4u * 4u + 1u * 4u);
}

TEST_F(BenchCli, StaticSceneSharesOneReferenceAndAccumulationConverges) {
    const json results = benchOk(kBox, "out",
                                 "--frames 6 --warmup 1 --reference-spp 64 --brute-force-spp 1,16 "
                                 "--graph PathTracerAccumulate");
    EXPECT_TRUE(results["reference"]["shared"].get<bool>());
    EXPECT_EQ(results["reference"]["frames_rendered"].get<int>(), 1);
    EXPECT_TRUE(fs::exists(mDir / results["reference"]["cache"].get<std::string>() / "static.exr"));
    // Nothing moves: the running mean of 6 frames is well below one frame's error.
    const json& frames = results["variants"][0]["frames"];
    EXPECT_LT(frames[5]["relmse"].get<double>(), 0.5 * frames[0]["relmse"].get<double>());
    // Static-camera flicker (temporal standard deviation of luminance over the measured frames): 16 spp per frame
    // flickers about a quarter as much as 1 spp, and the running mean less than either single-frame point.
    const double f1 = results["brute_force"][0]["summary"]["flicker"].get<double>();
    const double f16 = results["brute_force"][1]["summary"]["flicker"].get<double>();
    const double fAcc = results["variants"][0]["summary"]["flicker"].get<double>();
    EXPECT_GT(f1, 0.0);
    EXPECT_LT(f16, 0.4 * f1);
    EXPECT_GT(f16, 0.1 * f1);
    EXPECT_LT(fAcc, f1);

    // An orbiting camera moves: one reference per frame.
    const json orbit = benchOk(kBox, "orbit",
                               "--camera-path orbit --frames 3 --warmup 1 --reference-spp 16 --brute-force-spp 1 "
                               "--graph PathTracerAccumulate");
    EXPECT_FALSE(orbit["reference"]["shared"].get<bool>());
    EXPECT_EQ(orbit["reference"]["frames_rendered"].get<int>(), 3);
    EXPECT_TRUE(orbit["variants"][0]["summary"]["flicker"].is_null());  // flicker is a static-camera metric
}

TEST_F(BenchCli, ReferenceBouncesAndNoise) {
    // The reference graph's own length: no bias row.
    const json own =
        benchOk(kBox, "own",
                "--frames 3 --warmup 1 --reference-spp 32 --brute-force-spp 1 --graph PathTracerAccumulate "
                "--reference-bounces reference");
    EXPECT_EQ(own["reference"]["max_bounces"].get<int>(), 8);
    EXPECT_TRUE(own["bias"].is_null());
    // A given length: the bias row compares it with the reference graph's 8 bounces. One bounce loses much more
    // light than three.
    const json one =
        benchOk(kBox, "one",
                "--frames 3 --warmup 1 --reference-spp 32 --brute-force-spp 1 --graph PathTracerAccumulate "
                "--reference-bounces 1");
    const json three = benchOk(kBox, "three",
                               "--frames 3 --warmup 1 --reference-spp 32 --brute-force-spp 1 "
                               "--graph PathTracerAccumulate");
    EXPECT_EQ(one["reference"]["max_bounces"].get<int>(), 1);
    EXPECT_EQ(one["reference"]["bounces_from"], "--reference-bounces");
    EXPECT_EQ(three["reference"]["bounces_from"], "the graphs");
    EXPECT_GT(one["bias"]["relmse"].get<double>(), 2.0 * three["bias"]["relmse"].get<double>());
    // The noise estimate falls as 1 / spp: four times the samples, about a quarter of the noise.
    const json more = benchOk(kBox, "more",
                              "--frames 3 --warmup 1 --reference-spp 128 --brute-force-spp 1 "
                              "--graph PathTracerAccumulate");
    const double ratio =
        more["reference"]["noise_relmse"].get<double>() / three["reference"]["noise_relmse"].get<double>();
    EXPECT_GT(ratio, 0.15);
    EXPECT_LT(ratio, 0.4);
    // A reference as noisy as the errors measured against it is flagged.
    const json noisy = benchOk(kBox, "noisy",
                               "--frames 3 --warmup 1 --reference-spp 4 --brute-force-spp 1,64 "
                               "--graph PathTracerAccumulate");
    EXPECT_NE(noisy["reference"]["noise_warning"].get<std::string>().find("raise --reference-spp"), std::string::npos);
}

TEST_F(BenchCli, JitterUsesABoxFilteredReference) {
    // TAA's output is anti-aliased: the reference of a jittered sequence averages over each pixel's area, ignores
    // the jitter, and so is shared when nothing moves.
    const json r = benchOk(kBox, "out",
                           "--jitter halton --frames 4 --warmup 1 --reference-spp 32 --brute-force-spp 1 "
                           "--graph PathTracerSVGF");
    EXPECT_EQ(r["reference"]["pixel_filter"], "box");
    EXPECT_TRUE(r["reference"]["shared"].get<bool>());
    EXPECT_EQ(r["reference"]["frames_rendered"].get<int>(), 1);
}

TEST_F(BenchCli, TrimmedRelMseIsMonotonicAlongTheCurveWithFireflies) {
    // materials.gltf has fireflies: RelMSE along the brute-force curve need not fall, its trimmed form does.
    const json r = benchOk(loom::test::dataScene("materials.gltf"), "out",
                           "--frames 3 --warmup 1 --reference-spp 256 --brute-force-spp 1,2,4,8,16,32,64 "
                           "--graph PathTracerAccumulate");
    const json& curve = r["brute_force"];
    ASSERT_EQ(curve.size(), 7u);
    for (size_t i = 0; i + 1 < curve.size(); ++i) {
        std::printf("materials %d spp: RelMSE %.4g, trimmed %.4g\n", curve[i]["spp"].get<int>(),
                    curve[i]["summary"]["relmse"].get<double>(), curve[i]["summary"]["trimmed_relmse"].get<double>());
        EXPECT_LT(curve[i + 1]["summary"]["trimmed_relmse"].get<double>(),
                  curve[i]["summary"]["trimmed_relmse"].get<double>())
            << curve[i + 1]["spp"];
    }
}

TEST_F(BenchCli, PlotWithoutMatplotlibIsRefusedBeforeTheBenchmarkRuns) {
    // A plot that cannot be made is known before the frames: nothing is rendered or written.
    const auto r = run(tinyArgs("out") + " --graph PathTracerAccumulate --brute-force-spp 1 --plot --python " +
                       loom::test::shellQuoted((mDir / "no-python").string()));
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("matplotlib"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(mDir / "out" / "results.csv"));
    EXPECT_FALSE(fs::exists(mDir / "out" / "results.json"));
    EXPECT_FALSE(fs::exists(mDir / "out" / "plot.png"));
}

TEST_F(BenchCli, BadInputExitsWithCode2AndAMessage) {
    expectBadInput({{"--graph", "NoSuchGraph"}}, {"graph 'NoSuchGraph' does not exist"});
    expectBadInput({{"--sweep", "SVFG.iterations=1,2"}}, {"no benchmarked graph has a pass 'SVFG'", "SVGF"});
    expectBadInput({{"--sweep", "SVGF.iteratoins=1,2"}}, {"iteratoins"});
    expectBadInput({{"--sweep", "SVGF.iterations"}}, {"not a sweep"});
    expectBadInput({{"--sweep", "SVGF.iterations=1,,2"}}, {"empty value"});
    expectBadInput({{"--sweep", "SVGF.iterations=1000"}}, {"SVGF.iterations"});
    expectBadInput({{"--measure", "Nowhere.color"}}, {"has no pass 'Nowhere'"});
    expectBadInput({{"--reference-spp", "100"}}, {"not a multiple"});
    expectBadInput({{"--brute-force-spp", "1,x"}}, {"'x' is not a sample count"});
    expectBadInput({{"--reference-bounces", "eight"}}, {"'eight' is not a path length"});
    expectBadInput({{"--reference-bounces", "65"}}, {"not a path length"});
    expectBadInput({{"--sweep", "PathTracer.maxBounces=2,3"}}, {"different lengths", "--reference-bounces"});
    expectBadInput({{"--size", "64by64"}}, {"is not a size"});
    expectBadInput({{"--frames", "0"}}, {"frame count is 0"});
    expectBadInput({{"--warmup", "8"}}, {"nothing to measure"});
    expectBadInput({{"--scene", "missing.gltf"}}, {"scene 'missing.gltf' does not exist"});
    // A reference graph that is a pipe is refused, not read for the cache key (which would block for ever).
    ASSERT_EQ(::mkfifo((mDir / "pipe.json").c_str(), 0600), 0);
    expectBadInput({{"--reference-graph", "pipe.json"}}, {"not a regular file"});
    // Outputs never replace inputs: a graph named like a result in the output folder.
    fs::create_directories(mDir / "out");
    fs::copy_file(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracerATrous.json", mDir / "out" / "results.json");
    expectBadInput({{"--graph", "out/results.json"}}, {"would overwrite its input"});
}

// ---------------------------------------------------------------------------------------------------------------
// Given references: --reference-sequence

class BenchRefSeq : public BenchCli {
protected:
    std::string readText(const std::string& rel) const {
        std::ifstream in(mDir / rel, std::ios::binary);
        std::stringstream s;
        s << in.rdbuf();
        return s.str();
    }

    /// Renders `frames` frames of TestPattern at 64x64 into `dir`, dumping its linear image Mix.dst
    /// (dir/Mix.dst.0000.exr, ...): the frames a scene-less bench of the same graph measures.
    void renderPattern(const std::string& dir, int frames) const {
        const auto r = run("render --graph " + loom::test::shellQuoted(kTestPattern) + " --size 64x64 --frames " +
                           std::to_string(frames) + " --dump Mix.dst --out " + dir);
        ASSERT_EQ(r.code, 0) << r.output;
        ASSERT_TRUE(fs::exists(mDir / dir / "Mix.dst.0000.exr")) << r.output;
    }

    /// A scene-less bench of TestPattern (measuring Mix.dst) at `size`, `frames` frames of which 2 are warm-up,
    /// into `out`, with extra options.
    loom::test::CliResult benchPattern(const std::string& out, const std::string& extra, int frames = 6,
                                       const std::string& size = "64x64") const {
        return run("bench --graph " + loom::test::shellQuoted(kTestPattern) + " --measure Mix.dst --size " + size +
                   " --frames " + std::to_string(frames) + " --warmup 2 --out " + out + " " + extra);
    }
};

TEST_F(BenchRefSeq, CachedReferencesGivenBackAsASequenceGiveIdenticalMetrics) {
    // A run that renders its references (one per frame: the sphere moves), then the same run reading them back
    // from the cache as a sequence: every metric of every frame, of the graph and of the brute-force points, is the
    // same bit for bit.
    const std::string common = "bench --scene " + loom::test::shellQuoted(kDynamic) +
                               " --size 64x64 --frames 5 --warmup 2 --brute-force-spp 1,2 --graph PathTracerATrous "
                               "--cache cache ";
    const auto first = run(common + "--reference-spp 16 --out rendered");
    ASSERT_EQ(first.code, 0) << first.output;
    const json rendered = readJson("rendered/results.json");
    EXPECT_EQ(rendered["reference"]["source"], "rendered");
    EXPECT_EQ(rendered["reference"]["frames_rendered"].get<int>(), 5);
    const fs::path entry = rendered["reference"]["cache"].get<std::string>();
    for (int i = 0; i < 5; ++i)
        ASSERT_TRUE(fs::is_regular_file(mDir / entry / ("frame_00000" + std::to_string(i) + ".exr"))) << i;
    size_t entries = 0;
    for (const auto& e : fs::directory_iterator(mDir / "cache")) entries += e.is_directory();

    const auto second = run(common + "--reference-sequence " +
                            loom::test::shellQuoted((entry / "frame_######.exr").string()) + " --out given");
    ASSERT_EQ(second.code, 0) << second.output;
    const json given = readJson("given/results.json");
    const auto a = frameMetrics(rendered), b = frameMetrics(given);
    EXPECT_EQ(a.size(), 5u + 2u * 4u);
    EXPECT_EQ(a, b);
    // Nothing rendered or cached for the reference: its noise is unknown, and there is no bias row (no rendered
    // reference to compare lengths with). The brute force is the same images, from the cache.
    EXPECT_EQ(given["reference"]["source"], "sequence");
    EXPECT_EQ(given["reference"]["sequence"], (entry / "frame_######.exr").string());
    EXPECT_EQ(given["reference"]["first_frame"].get<int>(), 0);
    EXPECT_EQ(given["reference"]["noise"], "unknown");
    EXPECT_TRUE(given["reference"]["noise_relmse"].is_null());
    EXPECT_TRUE(given["reference"]["cache"].is_null());
    EXPECT_EQ(given["reference"]["frames_rendered"].get<int>(), 0);
    EXPECT_TRUE(given["bias"].is_null());
    EXPECT_EQ(given["brute_force_cache"]["frames_rendered"].get<int>(), 0);
    size_t entriesAfter = 0;
    for (const auto& e : fs::directory_iterator(mDir / "cache")) entriesAfter += e.is_directory();
    EXPECT_EQ(entriesAfter, entries);
    // The speedups are read from the same curve at the same errors.
    EXPECT_EQ(given["variants"][0]["speedup_relmse"]["kind"], rendered["variants"][0]["speedup_relmse"]["kind"]);
    const std::string summary = readText("given/summary.md");
    EXPECT_NE(summary.find("frame_######.exr"), std::string::npos) << summary;
    EXPECT_NE(summary.find("Reference noise (RelMSE): unknown"), std::string::npos) << summary;
}

TEST_F(BenchRefSeq, SceneLessGraphAgainstItsOwnFramesHasNoError) {
    // TestPattern needs no scene: bench runs it on the clock alone, against the frames `loom render` wrote of it.
    renderPattern("seq", 7);
    const auto same = benchPattern("same", "--reference-sequence " + loom::test::shellQuoted("seq/Mix.dst.%04d.exr"));
    ASSERT_EQ(same.code, 0) << same.output;
    EXPECT_NE(same.output.find("no brute-force curve"), std::string::npos) << same.output;
    const json r = readJson("same/results.json");
    EXPECT_TRUE(r["scene"].is_null());
    EXPECT_TRUE(r["brute_force"].empty());
    ASSERT_EQ(r["variants"].size(), 1u);
    const json& v = r["variants"][0];
    EXPECT_EQ(v["measured"], "Mix.dst");
    ASSERT_EQ(v["frames"].size(), 6u);
    for (const json& f : v["frames"]) {
        EXPECT_EQ(f["relmse"].get<double>(), 0.0) << f["frame"];
        EXPECT_EQ(f["trimmed_relmse"].get<double>(), 0.0) << f["frame"];
        EXPECT_EQ(f["smape"].get<double>(), 0.0) << f["frame"];
        EXPECT_EQ(f["ssim"].get<double>(), 1.0) << f["frame"];
        EXPECT_EQ(f["flip"].get<double>(), 0.0) << f["frame"];
        if (f["temporal"].is_number()) {
            EXPECT_EQ(f["temporal"].get<double>(), 0.0) << f["frame"];
        }
        EXPECT_EQ(f["non_finite"].get<int>(), 0);
    }
    // No curve, so no speedup; the lag figures of the per-frame error are still there.
    EXPECT_EQ(v["speedup_relmse"]["kind"], "none");
    EXPECT_TRUE(v["lag"].is_object());
    EXPECT_NE(readText("same/summary.md").find("no scene"), std::string::npos);

    // The frames one later (file i + 1 for frame i): the frame counter differs everywhere, so every frame has an
    // error.
    const auto shifted =
        benchPattern("shifted", "--reference-sequence " + loom::test::shellQuoted("seq/Mix.dst.####.exr") +
                                    " --reference-first-frame 1");
    ASSERT_EQ(shifted.code, 0) << shifted.output;
    const json s = readJson("shifted/results.json");
    EXPECT_EQ(s["reference"]["first_frame"].get<int>(), 1);
    for (const json& f : s["variants"][0]["frames"]) {
        EXPECT_GT(f["relmse"].get<double>(), 0.0) << f["frame"];
        EXPECT_LT(f["ssim"].get<double>(), 1.0) << f["frame"];
    }
    // --brute-force-spp none is accepted without a scene (it asks for what happens anyway).
    EXPECT_EQ(benchPattern("none", "--reference-sequence " + loom::test::shellQuoted("seq/Mix.dst.%04d.exr") +
                                       " --brute-force-spp none")
                  .code,
              0);
}

TEST_F(BenchRefSeq, BadReferencesAreRefusedWithExitCode2) {
    renderPattern("seq", 6);
    const std::string seq = "--reference-sequence " + loom::test::shellQuoted("seq/Mix.dst.%04d.exr");
    // A frame past the end of the sequence, named with its file and frame.
    expectRefused(benchPattern("out", seq, 8), {"Mix.dst.0006.exr", "frame 6", "does not exist"});
    // Blender numbers from 1: the hint says so.
    expectRefused(benchPattern("out", seq + " --reference-first-frame 3"),
                  {"Mix.dst.0006.exr", "frame 3 (file number 6)"});
    // Another size than --size: both sizes, and the --size that fits.
    expectRefused(benchPattern("out", seq, 6, "32x32"), {"64x64", "32x32", "--size 64x64"});
    // A pattern with no frame field.
    expectRefused(benchPattern("out", "--reference-sequence seq/Mix.dst.0000.exr"),
                  {"--reference-sequence", "no frame field"});
    // A layer the files do not have.
    expectRefused(benchPattern("out", "--reference-sequence " +
                                          loom::test::shellQuoted("seq/Mix.dst.%04d.exr:ViewLayer.Combined")),
                  {"ViewLayer.Combined", "frame 0"});
    // A truncated file.
    fs::create_directories(mDir / "cut");
    for (int i = 0; i < 6; ++i) {
        const std::string name = "Mix.dst.000" + std::to_string(i) + ".exr";
        fs::copy_file(mDir / "seq" / name, mDir / "cut" / name);
    }
    fs::resize_file(mDir / "cut" / "Mix.dst.0003.exr", fs::file_size(mDir / "cut" / "Mix.dst.0003.exr") / 2);
    expectRefused(benchPattern("out", "--reference-sequence " + loom::test::shellQuoted("cut/Mix.dst.%04d.exr")),
                  {"Mix.dst.0003.exr", "frame 3"});
    // NaN and infinite pixels: a reference must be finite.
    fs::create_directories(mDir / "nan");
    for (int i = 0; i < 6; ++i) {
        const std::string name = "Mix.dst.000" + std::to_string(i) + ".exr";
        loom::Texture t = loom::readImage(mDir / "seq" / name);
        if (i == 4) {
            auto v = t.view<glm::vec4>();
            v.at(1, 2).x = std::numeric_limits<float>::quiet_NaN();
            v.at(5, 6).z = std::numeric_limits<float>::infinity();
            v.at(7, 7) = glm::vec4(-std::numeric_limits<float>::infinity());
        }
        loom::writeImage(mDir / "nan" / name, t);
    }
    expectRefused(benchPattern("out", "--reference-sequence " + loom::test::shellQuoted("nan/Mix.dst.%04d.exr")),
                  {"Mix.dst.0004.exr", "frame 4", "3 pixel(s) with a NaN or infinite value"});
}

TEST_F(BenchRefSeq, OptionsThatWouldDoNothingAreRefused) {
    renderPattern("seq", 6);
    const std::string seq = "--reference-sequence " + loom::test::shellQuoted("seq/Mix.dst.%04d.exr");
    // No scene and no references: nothing to measure against.
    expectRefused(benchPattern("out", ""), {"no scene given", "--reference-sequence"});
    // Without a scene: its options, and the brute-force curve (which path-traces it).
    expectRefused(benchPattern("out", seq + " --jitter halton"), {"--jitter", "no --scene"});
    expectRefused(benchPattern("out", seq + " --env 1,1,1"), {"--env", "no --scene"});
    expectRefused(benchPattern("out", seq + " --brute-force-spp 1,2"), {"--brute-force-spp", "without --scene"});
    expectRefused(benchPattern("out", seq + " --brute-force-max 8"), {"--brute-force-max", "without --scene"});
    // Given references are not rendered.
    expectRefused(benchPattern("out", seq + " --reference-spp 64"), {"--reference-spp", "--reference-sequence"});
    expectRefused(benchPattern("out", seq + " --reference-bounces 3"), {"--reference-bounces", "--reference-sequence"});
    // A graph that needs a scene, run without one: a clear error, not a crash.
    expectRefused(run("bench --graph PathTracerATrous --size 64x64 --frames 6 --warmup 2 --out out " + seq),
                  {"needs a scene"});
    // Numbering without a sequence.
    expectRefused(run("bench --scene " + loom::test::shellQuoted(kDynamic) +
                      " --graph PathTracerATrous --size 64x64 --frames 4 --warmup 1 --reference-first-frame 1 --out "
                      "out"),
                  {"--reference-first-frame", "--reference-sequence"});
}

}  // namespace
