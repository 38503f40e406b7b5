// `loom image merge` and `loom image compare` (loom/ShardMerge.h): merged shards record exactly the iterations they
// hold, so chained merges give one run's mean bit for bit and never count a sample twice; the output folder is
// apart from every shard and written whole or not at all; damaged headers and sums are refused with exit code 2;
// compare sees every bit of integer and float images.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <glm/vec4.hpp>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/DoubleTexels.h"
#include "loom/ExrFile.h"
#include "loom/ImageIO.h"
#include "loom/ShardMerge.h"
#include "loom/Texture.h"

namespace fs = std::filesystem;

#define EXPECT_CONTAINS(text, part) \
    EXPECT_NE(std::string(text).find(part), std::string::npos) << "'" << (part) << "' not in:\n" << (text)

namespace {

using loom::test::shellQuoted;
const char* const kAttributes[] = {"loomHeldFrame", "loomSeedOffset", "loomIterations", "loomSampleRanges",
                                   "loomShards"};
const char* const kPartials[] = {"partialSumRG", "partialSumBA", "partialCount"};

std::string readBytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

size_t occurrences(const std::string& text, const std::string& part) {
    size_t n = 0;
    for (size_t at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
    return n;
}

/// The header attributes a merge reads, as the file has them.
std::map<std::string, std::string> attributesOf(const fs::path& exr) {
    const loom::ExrFile f(exr);
    std::map<std::string, std::string> a;
    for (const char* name : kAttributes)
        if (auto v = f.stringAttribute(name)) a[name] = *v;
    return a;
}

/// Rewrites an EXR with its pixels and header changed: `changes` set attributes ("" values remove them).
void rewrite(const fs::path& exr, const std::map<std::string, std::string>& changes,
             const std::function<void(loom::Texture&)>& pixels = {}) {
    loom::Texture tex = loom::readImage(exr);
    std::map<std::string, std::string> a = attributesOf(exr);
    for (const auto& [k, v] : changes) {
        if (v.empty())
            a.erase(k);
        else
            a[k] = v;
    }
    if (pixels) pixels(tex);
    loom::writeImage(exr, tex, a);
}

/// A shard written in process: PASS "Accumulate", frame 3, w x h, each pixel's sums `value` * count.
void writeShard(const fs::path& dir, uint64_t offset, uint64_t iterations, float value, uint32_t w = 4,
                uint32_t h = 3) {
    fs::create_directories(dir);
    const std::map<std::string, std::string> a = {{"loomHeldFrame", "3"},
                                                  {"loomSeedOffset", std::to_string(offset)},
                                                  {"loomIterations", std::to_string(iterations)}};
    loom::Texture rg(w, h, loom::Format::RGBA32U), ba(w, h, loom::Format::RGBA32U), count(w, h, loom::Format::R32U);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const uint32_t n = uint32_t(iterations % 1000);
            loom::packDoubleSum(glm::dvec4(double(value) * n, double(x) * n, double(y) * n, double(n)),
                                rg.view<glm::uvec4>().at(x, y), ba.view<glm::uvec4>().at(x, y));
            count.view<uint32_t>().at(x, y) = n;
        }
    loom::writeImage(dir / "Accumulate.partialSumRG.0003.exr", rg, a);
    loom::writeImage(dir / "Accumulate.partialSumBA.0003.exr", ba, a);
    loom::writeImage(dir / "Accumulate.partialCount.0003.exr", count, a);
}

class ImageMerge : public ::testing::Test {
protected:
    /// Shards of frame 3 of graphs/ReferenceShard.json on the Cornell box at 32x24, two iterations each: s0 holds
    /// iterations 0-1, s1 2-3, s2 4-5; `single` is one run of all six. Rendered once for the suite.
    static void SetUpTestSuite() {
        sShards = fs::temp_directory_path() / ("loom_test_image_merge_" + std::to_string(::getpid()));
        fs::remove_all(sShards);
        fs::create_directories(sShards);
        const std::string common =
            "render --graph " + shellQuoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/ReferenceShard.json") +
            " --scene " + shellQuoted(loom::test::dataScene("cornell_dynamic.gltf")) +
            " --start-frame 3 --hold --size 32x24 -q --set PathTracer.samplesPerPixel=1 --set PathTracer.device=cpu";
        for (const auto& [name, args] :
             std::vector<std::pair<std::string, std::string>>{{"s0", "--frames 2"},
                                                              {"s1", "--frames 2 --seed-offset 2"},
                                                              {"s2", "--frames 2 --seed-offset 4"},
                                                              {"single", "--frames 6"}}) {
            const loom::test::CliResult r = loom::test::runLoom(sShards, common + " " + args + " --out " + name);
            ASSERT_EQ(r.code, 0) << r.output;
        }
    }
    static void TearDownTestSuite() {
        std::error_code ec;
        fs::remove_all(sShards, ec);
    }

    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = fs::temp_directory_path() / ("loom_test_image_merge_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(mDir);
        fs::create_directories(mDir);
        for (const char* s : {"s0", "s1", "s2", "single"})
            if (fs::exists(sShards / s)) fs::copy(sShards / s, mDir / s, fs::copy_options::recursive);
    }
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }

    loom::test::CliResult loom(const std::string& args) const { return loom::test::runLoom(mDir, args); }
    fs::path path(const std::string& rel) const { return mDir / rel; }

    /// Every entry of the test folder, hidden ones included (a merge's staging folder would show here).
    std::vector<std::string> entries() const {
        std::vector<std::string> names;
        for (const auto& e : fs::directory_iterator(mDir)) names.push_back(e.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    }

    /// Exit code 2, "error:" and every part in the message, and nothing new in the test folder.
    void expectRefused(const std::string& args, const std::vector<std::string>& parts) const {
        const std::vector<std::string> before = entries();
        const loom::test::CliResult r = loom(args);
        EXPECT_EQ(r.code, 2) << args << "\n" << r.output;
        EXPECT_CONTAINS(r.output, "error:");
        for (const std::string& p : parts) EXPECT_CONTAINS(r.output, p);
        EXPECT_EQ(entries(), before) << args << ": the failed merge left something behind";
    }

    /// Sets header attributes of all three partial files of a shard.
    void setHeader(const std::string& shard, const std::map<std::string, std::string>& changes) const {
        for (const char* kind : kPartials) rewrite(path(shard + "/Accumulate." + kind + ".0003.exr"), changes);
    }

    static fs::path sShards;
    fs::path mDir;
};

fs::path ImageMerge::sShards;

// The issue's reproduction: merge(s0, s2) holds iterations 0-1 and 4-5, not 0-3; merging it with s1 gives the
// single run's mean bit for bit, and merging it with s2 again is refused.
TEST_F(ImageMerge, ChainedMergesRecordTheirIterationsExactly) {
    auto r = loom("image merge s0 s2 -o gap");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "2 shards, 4 iterations");
    for (const char* file : {"mean", "partialSumRG", "partialSumBA", "partialCount"}) {
        auto a = attributesOf(path(std::string("gap/Accumulate.") + file + ".0003.exr"));
        EXPECT_EQ(a["loomSampleRanges"], "0-1,4-5") << file;
        EXPECT_EQ(a["loomSeedOffset"], "0");
        EXPECT_EQ(a["loomIterations"], "4");
        EXPECT_EQ(a["loomHeldFrame"], "3");
    }

    r = loom("image merge gap s1 -o all");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "2 shards, 6 iterations");
    EXPECT_EQ(attributesOf(path("all/Accumulate.mean.0003.exr"))["loomSampleRanges"], "0-5");
    const loom::Texture single = loom::readImage(path("single/Accumulate.dst.0003.exr"));
    EXPECT_TRUE(loom::readImage(path("all/Accumulate.mean.0003.exr")).samePixels(single));
    EXPECT_TRUE(loom::readImage(path("all/Accumulate.partialCount.0003.exr"))
                    .samePixels(loom::readImage(path("single/Accumulate.partialCount.0003.exr"))));
    // The order of the chain does not matter.
    ASSERT_EQ(loom("image merge s1 gap -o all2").code, 0);
    EXPECT_TRUE(loom::readImage(path("all2/Accumulate.mean.0003.exr")).samePixels(single));
    // A merge is not the reference until all shards are in.
    EXPECT_FALSE(loom::readImage(path("gap/Accumulate.mean.0003.exr")).samePixels(single));

    expectRefused("image merge gap s2 -o dup", {"s2", "gap", "iterations 4-5", "0-1,4-5"});
    expectRefused("image merge all s0 -o dup", {"iterations 0-1", "all"});
    expectRefused("image merge s0 s1 s0 -o dup", {"the same folder given twice"});
}

// -o naming a shard, a folder inside one or one that holds one is refused before anything is written, however the
// path is spelt.
TEST_F(ImageMerge, OutputFolderApartFromEveryShard) {
    fs::create_directory_symlink(path("s0"), path("link"));
    const std::string before = readBytes(path("s0/Accumulate.partialSumRG.0003.exr"));
    for (const char* out : {"s0", "./s0", "s0/", "link", "s1/../s0"})
        expectRefused(std::string("image merge s0 s1 -o ") + out, {"--out", "is the shard folder"});
    expectRefused("image merge s0 s1 -o s1/merged", {"lies inside the shard folder 's1'"});
    expectRefused("image merge s0 s1 -o link/merged", {"lies inside the shard folder"});
    expectRefused("image merge s0 s1 -o .", {"holds the shard folder"});
    EXPECT_EQ(readBytes(path("s0/Accumulate.partialSumRG.0003.exr")), before);
    EXPECT_EQ(fs::directory_iterator(path("s0")) != fs::directory_iterator(), true);

    // An existing folder with files is never mixed into; an empty one is filled.
    fs::create_directory(path("full"));
    std::ofstream(path("full/keep.txt")) << "x";
    expectRefused("image merge s0 s1 -o full", {"exists and holds files", "remove it or choose another --out"});
    EXPECT_EQ(readBytes(path("full/keep.txt")), "x");
    fs::create_directory(path("empty"));
    const auto r = loom("image merge s0 s1 -o empty");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_TRUE(fs::exists(path("empty/Accumulate.mean.0003.exr")));
}

// A failed merge leaves no -o folder (nor the folders above it that it made, nor its staging folder); a failure
// at the last write leaves no new partials beside an older mean.
TEST_F(ImageMerge, FailedMergeLeavesNothing) {
    rewrite(path("s1/Accumulate.partialSumBA.0003.exr"), {},
            [](loom::Texture& t) { t.view<glm::uvec4>().at(5, 7) = loom::packDoublePair(std::nan(""), 0.0); });
    expectRefused("image merge s0 s1 -o new/deeper/out", {"pixel (5, 7)", "the sum of B is nan"});
    expectRefused("image merge s0 missing -o out", {"no such folder"});

    // In process, stopped before the last file (the mean): nothing of it is left.
    int calls = 0;
    const auto stopAtMean = [&] {
        if (++calls == 4) throw loom::Error({loom::ErrorKind::Runtime, "", "", "stopped", "", ""});
    };
    writeShard(path("a"), 0, 2, 1.f);
    writeShard(path("b"), 2, 3, 2.f);
    const std::vector<std::string> before = entries();
    EXPECT_THROW(loom::mergeShards({path("a"), path("b")}, path("made/out"), stopAtMean), loom::Error);
    EXPECT_EQ(calls, 4);
    EXPECT_EQ(entries(), before);
    const auto frames = loom::mergeShards({path("a"), path("b")}, path("made/out"));
    ASSERT_EQ(frames.size(), 1u);
    EXPECT_EQ(frames[0].iterations, 5u);
    EXPECT_EQ(frames[0].mean, fs::weakly_canonical(path("made/out/Accumulate.mean.0003.exr")));
    EXPECT_EQ(fs::directory_iterator(path("made")) != fs::directory_iterator(), true);
    for (const auto& e : fs::directory_iterator(path("made")))
        EXPECT_EQ(e.path().filename(), "out") << "staging left behind";
}

// Header numbers: 23 digits, signs, offsets whose ranges pass 2^64 - 1, and ranges that disagree are refused with
// the file and the attribute; iterations up to 2^64 - 1 are held exactly.
TEST_F(ImageMerge, HeaderNumbersAreCheckedNotWrapped) {
    const std::string file = "s1/Accumulate.partialCount.0003.exr";
    const auto refusedWith = [&](const std::map<std::string, std::string>& header, const std::string& attribute,
                                 const std::string& part) {
        setHeader("s1", header);
        const auto r = loom("image merge s0 s1 -o out");
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_CONTAINS(r.output, "error: " + file + ": " + attribute);
        EXPECT_CONTAINS(r.output, part);
        EXPECT_EQ(occurrences(r.output, "Accumulate.partialCount.0003.exr"), 1u) << r.output;
        EXPECT_FALSE(fs::exists(path("out")));
        setHeader("s1", {{"loomSeedOffset", "2"}, {"loomIterations", "2"}, {"loomSampleRanges", ""}});
    };
    refusedWith({{"loomSeedOffset", "12345678901234567890123"}}, "loomSeedOffset", "not a whole number below 2^64");
    refusedWith({{"loomIterations", "-2"}}, "loomIterations", "not a whole number");
    refusedWith({{"loomSeedOffset", "+2"}}, "loomSeedOffset", "not a whole number");
    refusedWith({{"loomSeedOffset", "18446744073709551615"}}, "loomIterations", "pass iteration 2^64 - 1");
    refusedWith({{"loomSampleRanges", "2-3,3-4"}}, "loomSampleRanges", "overlaps");
    refusedWith({{"loomSampleRanges", "5-2"}}, "loomSampleRanges", "ends before it starts");
    refusedWith({{"loomSampleRanges", "2-3"}, {"loomIterations", "3"}}, "loomIterations", "holds 2");
    refusedWith({{"loomSampleRanges", "4-5"}}, "loomSeedOffset", "starts at 4");

    // The last iteration there is: held, merged and written back exactly.
    setHeader("s1", {{"loomSeedOffset", "18446744073709551614"}, {"loomIterations", "2"}});
    auto r = loom("image merge s0 s1 -o top");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_CONTAINS(r.output, "4 iterations");
    EXPECT_EQ(attributesOf(path("top/Accumulate.mean.0003.exr"))["loomSampleRanges"],
              "0-1,18446744073709551614-18446744073709551615");
    r = loom("image merge top s2 -o top2");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(attributesOf(path("top2/Accumulate.mean.0003.exr"))["loomSampleRanges"],
              "0-1,4-5,18446744073709551614-18446744073709551615");
}

// Sums that are not finite, or whose mean a float cannot hold, are refused naming the file and the pixel: an
// output never holds NaN or Inf.
TEST_F(ImageMerge, NonFiniteSumsAreRefused) {
    const double inf = std::numeric_limits<double>::infinity();
    for (const auto& [value, part] : std::vector<std::pair<double, std::string>>{
             {std::nan(""), "the sum of G is nan"}, {inf, "the sum of G is inf"}, {-inf, "the sum of G is -inf"}}) {
        fs::copy_file(path("s1/Accumulate.partialSumRG.0003.exr"), path("rg.keep"));
        rewrite(path("s1/Accumulate.partialSumRG.0003.exr"), {},
                [&](loom::Texture& t) { t.view<glm::uvec4>().at(3, 2) = loom::packDoublePair(1.0, value); });
        expectRefused("image merge s0 s1 -o out",
                      {"s1/Accumulate.partialSumRG.0003.exr: pixel (3, 2): " + part, "finite sums"});
        fs::rename(path("rg.keep"), path("s1/Accumulate.partialSumRG.0003.exr"));
    }
    rewrite(path("s1/Accumulate.partialSumRG.0003.exr"), {},
            [&](loom::Texture& t) { t.view<glm::uvec4>().at(0, 0) = loom::packDoublePair(1e300, 0.0); });
    expectRefused("image merge s0 s1 -o out", {"pixel (0, 0)", "beyond a float's range"});
    // Finite doubles whose sum is not.
    writeShard(path("big0"), 0, 1, 3e38f);
    writeShard(path("big1"), 1, 1, 3e38f);
    const auto r = loom("image merge big0 big1 -o big");
    ASSERT_EQ(r.code, 0) << r.output;  // 3e38 is a float's mean
    rewrite(path("big1/Accumulate.partialSumRG.0003.exr"), {},
            [&](loom::Texture& t) { t.view<glm::uvec4>().at(1, 1) = loom::packDoublePair(1.7e308, 0.0); });
    rewrite(path("big0/Accumulate.partialSumRG.0003.exr"), {},
            [&](loom::Texture& t) { t.view<glm::uvec4>().at(1, 1) = loom::packDoublePair(1.7e308, 0.0); });
    expectRefused("image merge big0 big1 -o big2", {"pixel (1, 1)", "inf"});
    for (const char* s : {"big0", "big1"})
        rewrite(path(std::string(s) + "/Accumulate.partialCount.0003.exr"), {},
                [](loom::Texture& t) { t.view<glm::uvec4>().at(2, 0).x = 0xFFFFFFFFu; });
    // More samples than iterations (a shard counted twice would pass as one of none otherwise) ...
    expectRefused("image merge big0 big1 -o big2",
                  {"big0/Accumulate.partialCount.0003.exr: pixel (2, 0): 4294967295 samples, but the header says the "
                   "shard holds 1 iteration"});
    // ... and counts past 32 bits together.
    for (const char* kind : kPartials) {
        rewrite(path(std::string("big0/Accumulate.") + kind + ".0003.exr"), {{"loomIterations", "4294967295"}});
        rewrite(path(std::string("big1/Accumulate.") + kind + ".0003.exr"),
                {{"loomSeedOffset", "4294967295"}, {"loomIterations", "4294967295"}});
    }
    expectRefused("image merge big0 big1 -o big2", {"pixel (2, 0)", "8589934590 samples"});
}

// The messages of a new user's mistakes: the path once, a missing folder called missing, and shards of another
// frame named with the frames they hold.
TEST_F(ImageMerge, MessagesNameWhatToChange) {
    auto r = loom("image merge s0 nowhere -o out");
    EXPECT_EQ(r.code, 2);
    EXPECT_CONTAINS(r.output, "error: nowhere: no such folder");
    EXPECT_EQ(occurrences(r.output, "nowhere"), 1u) << r.output;
    std::ofstream(path("file.txt")) << "x";
    r = loom("image merge s0 file.txt -o out");
    EXPECT_CONTAINS(r.output, "error: file.txt: not a folder");

    fs::create_directory(path("other"));
    for (const char* kind : kPartials)
        fs::copy_file(path(std::string("s1/Accumulate.") + kind + ".0003.exr"),
                      path(std::string("other/Accumulate.") + kind + ".0004.exr"));
    expectRefused("image merge s0 other -o out",
                  {"error: other: holds partial accumulations of Accumulate of frame 0004; the first shard, 's0', "
                   "of Accumulate of frame 0003"});
    fs::remove(path("s1/Accumulate.partialSumBA.0003.exr"));
    r = loom("image merge s0 s1 -o out");
    EXPECT_EQ(r.code, 2);
    EXPECT_EQ(occurrences(r.output, "s1/Accumulate.partialSumBA.0003.exr"), 1u) << r.output;
}

// Integers are compared as integers and floats bit for bit: values a float cannot tell apart differ.
TEST_F(ImageMerge, CompareSeesEveryBit) {
    const auto uintImage = [&](const std::string& name, uint32_t v) {
        loom::Texture t(1, 1, loom::Format::R32U);
        t.view<uint32_t>().at(0, 0) = v;
        loom::writeImage(path(name), t);
    };
    uintImage("a.exr", 16777216);
    uintImage("b.exr", 16777217);
    uintImage("c.exr", 16777216);
    auto r = loom("image compare a.exr b.exr");
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_CONTAINS(r.output, "1 of 4 values differ (largest difference 1, first at pixel (0, 0) channel R)");
    EXPECT_EQ(loom("image compare a.exr c.exr").code, 0);
    // Integers stay exact under a tolerance.
    EXPECT_EQ(loom("image compare a.exr b.exr --tolerance 10").code, 1);

    // One low-word bit of a double sum.
    fs::copy_file(path("s0/Accumulate.partialSumRG.0003.exr"), path("flipped.exr"));
    rewrite(path("flipped.exr"), {}, [](loom::Texture& t) { t.view<glm::uvec4>().at(4, 4).x ^= 1u; });
    r = loom("image compare s0/Accumulate.partialSumRG.0003.exr flipped.exr");
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_CONTAINS(r.output, "largest difference 1, first at pixel (4, 4) channel R");
    EXPECT_EQ(loom("image compare s0/Accumulate.partialSumRG.0003.exr s0/Accumulate.partialSumRG.0003.exr").code, 0);

    // Floats: bit for bit, or within a tolerance.
    const auto floatImage = [&](const std::string& name, float v) {
        loom::Texture t(1, 1, loom::Format::RGBA32F);
        t.view<glm::vec4>().at(0, 0) = glm::vec4(v, 0.f, 0.f, 1.f);
        loom::writeImage(path(name), t);
    };
    floatImage("one.exr", 1.f);
    floatImage("near.exr", 1.001f);
    floatImage("zero.exr", 0.f);
    floatImage("negzero.exr", -0.f);
    EXPECT_EQ(loom("image compare one.exr near.exr").code, 1);
    EXPECT_EQ(loom("image compare one.exr near.exr --tolerance 0.01").code, 0);
    r = loom("image compare one.exr near.exr --tolerance 0.0001");
    EXPECT_EQ(r.code, 1);
    EXPECT_CONTAINS(r.output, "differ by more than 0.0001");
    EXPECT_EQ(loom("image compare zero.exr negzero.exr").code, 1);
    EXPECT_EQ(loom("image compare zero.exr negzero.exr --tolerance 0").code, 0);
    for (const char* bad : {"-1", "nan", "inf"}) {
        r = loom(std::string("image compare one.exr near.exr --tolerance ") + bad);
        EXPECT_EQ(r.code, 2) << bad << r.output;
        EXPECT_CONTAINS(r.output, "--tolerance");
    }
}

TEST_F(ImageMerge, CompareInProcessReportsNanAndLargestDifference) {
    loom::Texture a(2, 1, loom::Format::RG32F), b(2, 1, loom::Format::RG32F);
    a.view<glm::vec2>().at(0, 0) = {1.f, std::nanf("")};
    b.view<glm::vec2>().at(0, 0) = {3.5f, std::nanf("")};
    a.view<glm::vec2>().at(1, 0) = {0.f, 2.f};
    b.view<glm::vec2>().at(1, 0) = {0.f, std::nanf("")};
    loom::ImageComparison c = loom::compareImages(a, b);
    EXPECT_EQ(c.differ, 2u);
    EXPECT_TRUE(std::isnan(c.largestFloat));
    b.view<glm::vec2>().at(1, 0).y = 2.f;
    c = loom::compareImages(a, b, 2.0);
    EXPECT_EQ(c.differ, 1u);
    EXPECT_EQ(c.largestFloat, 2.5);
    EXPECT_EQ(loom::compareImages(a, b, 3.0).differ, 0u);
    EXPECT_FALSE(loom::compareImages(a, loom::Texture(2, 1, loom::Format::RG32U)).sameShape);
}

TEST_F(ImageMerge, IterationSetsParseAndJoin) {
    using loom::IterationSet;
    EXPECT_EQ(loom::parseIterationSet("0-1,2-3,7", "f", "a"), (IterationSet{{0, 3}, {7, 7}}));
    EXPECT_EQ(loom::formatIterationSet({{0, 3}, {7, 7}}), "0-3,7");
    EXPECT_TRUE(loom::parseIterationSet("", "f", "a").empty());
    EXPECT_EQ(loom::iterationCount({{0, 3}, {7, 7}}), 5u);
    EXPECT_EQ(loom::iterationCount({{0, std::numeric_limits<uint64_t>::max()}}), std::nullopt);
    EXPECT_EQ(loom::iterationCount({{1, std::numeric_limits<uint64_t>::max()}}), std::numeric_limits<uint64_t>::max());
    for (const char* bad :
         {"1,,2", ",", "1-", "-1", "a", "3-1", "1-2,2", "5,4", " 1", "1-18446744073709551616", "0x10", "1,2,"}) {
        const loom::Error e = loom::test::expectError([&] { loom::parseIterationSet(bad, "f.exr", "attr"); });
        EXPECT_EQ(e.kind(), loom::ErrorKind::BadInput) << bad;
        EXPECT_CONTAINS(e.what(), "f.exr: attr: ");
    }
}

// montage names the layer of a multilayer EXR as the other commands do (FILE.exr:LAYER), and says so.
TEST_F(ImageMerge, MontageReadsALayer) {
    const std::string exr =
        shellQuoted(std::string(LOOM_TEST_SOURCE_DIR) + "/data/sequences/blender_cornell/noisy_0001.exr");
    auto r = loom("image montage " + exr + " " + exr + " -o side.png");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "noisy_0001.exr:ViewLayer.Combined'");
    r = loom("image montage " + exr + ":ViewLayer.Combined " + exr + ":ViewLayer.Normal -o side.png");
    ASSERT_EQ(r.code, 0) << r.output;
    const loom::Texture side = loom::readImage(path("side.png"));
    const loom::Texture one =
        loom::ExrFile(std::string(LOOM_TEST_SOURCE_DIR) + "/data/sequences/blender_cornell/noisy_0001.exr")
            .readRgba("ViewLayer.Combined");
    EXPECT_EQ(side.width(), 2 * one.width() + 4);
    r = loom("image montage " + exr + ":Nope " + exr + " -o side2.png");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_CONTAINS(r.output, "'Nope'");
    EXPECT_EQ(loom("image montage missing.exr:Layer " + exr + ":ViewLayer.Combined -o side3.png").code, 2);
}

}  // namespace
