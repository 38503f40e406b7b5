// ImageSequence: frames from files into the denoising graphs. The round trip through `loom render --dump` gives the
// same denoised frames bit for bit as rendering directly; Blender's multilayer names and conventions are read and
// converted; bad sequences are one clear error each (or, for non-finite samples, zeros and a count).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "ExrTestUtil.h"
#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/ImageIO.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

const std::string kSourceDir = LOOM_TEST_SOURCE_DIR;
const std::string kSequenceGraph = kSourceDir + "/graphs/DenoiseSequence.json";

nlohmann::json readJson(const std::string& path) {
    std::ifstream in(path);
    return nlohmann::json::parse(in);
}

const nlohmann::json& passNamed(const nlohmann::json& graph, const std::string& name) {
    for (const auto& p : graph["passes"])
        if (p["name"] == name) return p;
    static const nlohmann::json none;
    ADD_FAILURE() << "no pass " << name;
    return none;
}

/// Blender-like frame `k` of a w x h sequence: a plane z = 2 + 0.125 x + 0.25 y with a background column at
/// x = w-1, the previous position (k, -2) pixels away (y up), normals in world space (half as long at x = 0, as
/// Blender's blended ones at silhouettes), object index 2 (0 on the background), colour and albedo that say which
/// pixel they are.
std::map<std::string, test::ExrTestChannel> blenderFrame(int w, int h, int k) {
    std::map<std::string, test::ExrTestChannel> ch;
    const auto put = [&](const std::string& name, auto f) {
        std::vector<float> v;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) v.push_back(f(x, y));
        ch["ViewLayer." + name] = {v};
    };
    const auto background = [&](int x) { return x == w - 1; };
    put("Noisy Image.R", [&](int x, int y) { return float(x + 10 * y + 100 * k); });
    put("Noisy Image.G", [&](int, int) { return 0.5f; });
    put("Noisy Image.B", [&](int, int) { return 0.25f; });
    put("Noisy Image.A", [&](int, int) { return 1.f; });
    put("Combined.R", [&](int, int) { return -1.f; });  // the denoised image: not what the preset reads
    put("Combined.G", [&](int, int) { return -1.f; });
    put("Combined.B", [&](int, int) { return -1.f; });
    put("Denoising Albedo.R", [&](int x, int) { return 0.1f * float(x); });
    put("Denoising Albedo.G", [&](int, int y) { return 0.1f * float(y); });
    put("Denoising Albedo.B", [&](int, int) { return 0.75f; });
    put("Normal.X", [&](int, int) { return 0.f; });
    put("Normal.Y", [&](int x, int) { return background(x) ? 0.f : x == 0 ? 0.3f : 0.6f; });
    put("Normal.Z", [&](int x, int) { return background(x) ? 0.f : x == 0 ? 0.4f : 0.8f; });
    put("Depth.Z", [&](int x, int y) { return background(x) ? 1e10f : 2.f + 0.125f * float(x) + 0.25f * float(y); });
    put("Vector.X", [&](int, int) { return float(k); });
    put("Vector.Y", [&](int, int) { return -2.f; });
    put("Vector.Z", [&](int, int) { return 99.f; });  // the motion to the next frame: not read
    put("Vector.W", [&](int, int) { return 99.f; });
    put("IndexOB.X", [&](int x, int) { return background(x) ? 0.f : 2.f; });
    return ch;
}

class ImageSequence : public test::TempDirTest {
protected:
    static constexpr int kW = 8, kH = 6;

    /// Frames 1..count of the Blender-like sequence in mDir/blender/noisy_NNNN.exr; returns the pattern.
    std::string writeBlenderSequence(int count) {
        fs::create_directories(mDir / "blender");
        for (int k = 1; k <= count; ++k)
            test::writeExrChannels(mDir / "blender" / ("noisy_000" + std::to_string(k) + ".exr"), kW, kH,
                                   blenderFrame(kW, kH, k));
        return (mDir / "blender" / "noisy_####.exr").string();
    }

    test::CliResult loom(const std::string& args) { return test::runLoom(mDir, args); }

    /// `loom render` of `graph` (by default the shipped DenoiseSequence) on `pattern`, into mDir/out.
    test::CliResult renderSequence(const std::string& graph, const std::string& pattern, const std::string& more) {
        fs::create_directories(mDir / "out");
        return loom("render --graph " + test::shellQuoted(graph) + " --set " +
                    test::shellQuoted("Frames.path=" + pattern) + " --out out -q " + more);
    }
    test::CliResult renderSequence(const std::string& pattern, const std::string& more) {
        return renderSequence(kSequenceGraph, pattern, more);
    }

    void expectBadInput(const test::CliResult& r, const std::vector<std::string>& parts) {
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_NE(r.output.find("error:"), std::string::npos) << r.output;
        for (const auto& p : parts) EXPECT_NE(r.output.find(p), std::string::npos) << p << "\n" << r.output;
        EXPECT_EQ(r.output.find("Segmentation"), std::string::npos);
    }
};

}  // namespace

// The shipped graph is the default graph with its sources replaced: the same denoiser and tone mapping. Only
// SVGF's gradient input stays unconnected: A-SVGF's gradients need the renderer to re-shade last frame's samples,
// which other renderers do not write.
TEST(ImageSequenceGraph, DenoisesWithTheDefaultGraphsPasses) {
    const nlohmann::json sequence = readJson(kSequenceGraph);
    const nlohmann::json direct = readJson(kSourceDir + "/graphs/PathTracerSVGF.json");
    EXPECT_EQ(passNamed(sequence, "ToneMap"), passNamed(direct, "ToneMap"));
    nlohmann::json svgf = passNamed(sequence, "SVGF");
    EXPECT_EQ(svgf["unconnected"], nlohmann::json({"direct", "indirect", "gradient"}));
    svgf["unconnected"] = {"direct", "indirect"};
    EXPECT_EQ(svgf, passNamed(direct, "SVGF"));
}

// Render the default graph directly with its G-buffer and path tracer dumped; read the dumps back through the
// sequence graph with SVGF's gradient connected as in the default graph: the same denoised frames, bit for bit,
// whatever the thread count.
TEST_F(ImageSequence, RoundTripThroughDumpsGivesTheSameDenoisedFrames) {
    nlohmann::json graph = readJson(kSequenceGraph);
    for (auto& pass : graph["passes"])
        if (pass["name"] == "SVGF") pass["unconnected"] = {"direct", "indirect"};
    std::ofstream(mDir / "sequence.json") << graph.dump(1);
    const std::string scene = test::dataScene("cornell_dynamic.gltf");  // its camera moves every frame
    fs::create_directories(mDir / "direct");
    const test::CliResult direct =
        loom("render --graph " + test::shellQuoted(kSourceDir + "/graphs/PathTracerSVGF.json") + " --scene " +
             test::shellQuoted(scene) + " --size 64x64 --frames 4 --out direct -q --dump 'GBuffer.*' --dump "
             "'PathTracer.*' --dump SVGF.filtered");
    ASSERT_EQ(direct.code, 0) << direct.output;
    for (const char* threads : {"1", "2"}) {
        SCOPED_TRACE(threads);
        fs::remove_all(mDir / "out");
        const test::CliResult read = renderSequence(
            "sequence.json", (mDir / "direct").string(),
            std::string("--set Frames.preset=loom --set Frames.firstFrame=0 --size 64x64 --frames 4 --dump "
                        "SVGF.filtered --threads ") +
                threads);
        ASSERT_EQ(read.code, 0) << read.output;
        for (int f = 0; f < 4; ++f) {
            for (const std::string name : {"SVGF.filtered.000" + std::to_string(f) + ".exr",
                                           "ToneMap.dst.000" + std::to_string(f) + ".png"}) {
                SCOPED_TRACE(name);
                const Texture a = readImage(mDir / "direct" / name);
                const Texture b = readImage(mDir / "out" / name);
                EXPECT_TRUE(a.samePixels(b));
            }
        }
    }
}

// Blender's pass names and conventions: the preset reads Noisy Image (not the denoised Combined), turns the depth
// into linearZ, the motion from the previous frame in pixels with y up into uvPrev - uvCur, and the object index
// into mesh ids; graph frame 0 is Blender's frame 1.
TEST_F(ImageSequence, BlenderMultilayerFramesAreReadAndConverted) {
    const std::string pattern = writeBlenderSequence(2);
    nlohmann::json g = readJson(kSequenceGraph);
    g["passes"][0]["params"]["path"] = pattern;
    CompileOptions o;
    o.observe = {"Frames.*"};
    auto graph = test::compiledGraph(g, nullptr, kW, kH, o);
    for (uint64_t f = 0; f < 2; ++f) {
        graph->execute(FrameInfo{f, double(f) / 24.0, nullptr, nullptr});
        const int k = int(f) + 1;
        const auto color = graph->fieldTexture("Frames.color")->view<glm::vec4>();
        const auto albedo = graph->fieldTexture("Frames.albedo")->view<glm::vec4>();
        const auto normal = graph->fieldTexture("Frames.normW")->view<glm::vec4>();
        const auto linearZ = graph->fieldTexture("Frames.linearZ")->view<glm::vec2>();
        const auto mvec = graph->fieldTexture("Frames.mvec")->view<glm::vec2>();
        const auto meshId = graph->fieldTexture("Frames.meshId")->view<uint32_t>();
        for (uint32_t y = 0; y < uint32_t(kH); ++y)
            for (uint32_t x = 0; x < uint32_t(kW); ++x) {
                SCOPED_TRACE(testing::Message() << "frame " << f << " pixel " << x << "," << y);
                const bool background = x == uint32_t(kW - 1);
                EXPECT_EQ(color.at(x, y), glm::vec4(float(x + 10 * y + 100 * uint32_t(k)), 0.5f, 0.25f, 1.f));
                EXPECT_EQ(albedo.at(x, y), glm::vec4(0.1f * float(x), 0.1f * float(y), 0.75f, 1.f));
                EXPECT_EQ(normal.at(x, y), background ? glm::vec4(0.f) : glm::vec4(0.f, 0.6f, 0.8f, 0.f));
                if (background) {
                    EXPECT_EQ(linearZ.at(x, y), glm::vec2(-1.f, 0.f));
                    EXPECT_EQ(meshId.at(x, y), 0u);
                } else {
                    EXPECT_EQ(linearZ.at(x, y), glm::vec2(2.f + 0.125f * float(x) + 0.25f * float(y), 0.25f));
                    EXPECT_EQ(meshId.at(x, y), 2u);
                }
                // Blender's Vector: the previous position is (k, -2) pixels away, y up: k pixels right and 2 rows
                // further down.
                EXPECT_EQ(mvec.at(x, y), glm::vec2(float(k) / float(kW), 2.f / float(kH)));
            }
    }
}

// Without Noisy Image the preset takes Combined; without Denoising Albedo the albedo is 1 (no demodulation).
TEST_F(ImageSequence, PresetFallsBackToCombinedAndToUnitAlbedo) {
    auto ch = blenderFrame(kW, kH, 1);
    for (const char* c : {"R", "G", "B", "A"}) ch.erase(std::string("ViewLayer.Noisy Image.") + c);
    for (const char* c : {"R", "G", "B"}) ch.erase(std::string("ViewLayer.Denoising Albedo.") + c);
    test::writeExrChannels(mDir / "f_0001.exr", kW, kH, ch);
    nlohmann::json g = readJson(kSequenceGraph);
    g["passes"][0]["params"]["path"] = (mDir / "f_####.exr").string();
    CompileOptions o;
    o.observe = {"Frames.*"};  // kept after the frame (transient memory is reused by later passes)
    auto graph = test::compiledGraph(g, nullptr, kW, kH, o);
    graph->execute(FrameInfo{0, 0.0, nullptr, nullptr});
    const Texture& color = *graph->fieldTexture("Frames.color");
    const Texture& albedo = *graph->fieldTexture("Frames.albedo");
    for (uint32_t y = 0; y < uint32_t(kH); ++y)
        for (uint32_t x = 0; x < uint32_t(kW); ++x) {
            EXPECT_EQ(color.texel(x, y, 0), -1.f);
            EXPECT_EQ(color.texel(x, y, 3), 1.f);  // Combined has no alpha here
            for (uint32_t c = 0; c < 4; ++c) EXPECT_EQ(albedo.texel(x, y, c), 1.f);
        }
}

TEST_F(ImageSequence, MissingFramesWrongSizesAndDamagedFilesAreBadInput) {
    const std::string pattern = writeBlenderSequence(2);
    const std::string size = "--size " + std::to_string(kW) + "x" + std::to_string(kH);
    ASSERT_EQ(renderSequence(pattern, size + " --frames 2").code, 0);
    expectBadInput(renderSequence(pattern, size + " --frames 3"), {"frame 3", "noisy_0003.exr", "does not exist"});
    expectBadInput(renderSequence(pattern, "--size 16x16 --frames 1"), {"is 8x6", "16x16", "--size 8x6"});
    expectBadInput(renderSequence((mDir / "blender" / "noisy.exr").string(), size), {"Frames.path", "frame field"});
    expectBadInput(renderSequence(pattern, size + " --set Frames.normW=none"), {"normW", "no source"});
    expectBadInput(renderSequence(pattern, size + " --set 'Frames.normW=Denoising Normal'"),
                   {"Denoising Normal", "ViewLayer.Normal"});
    // A truncated second frame.
    const fs::path second = mDir / "blender" / "noisy_0002.exr";
    const auto bytes = fs::file_size(second);
    fs::resize_file(second, bytes / 2);
    expectBadInput(renderSequence(pattern, size + " --frames 2"), {"noisy_0002.exr"});
    // Colour in UINT samples.
    auto ch = blenderFrame(kW, kH, 1);
    for (const char* c : {"R", "G", "B", "A"}) ch[std::string("ViewLayer.Noisy Image.") + c].type = Imf::UINT;
    test::writeExrChannels(mDir / "uint_0001.exr", kW, kH, ch);
    expectBadInput(renderSequence((mDir / "uint_####.exr").string(), size), {"UINT", "color"});
}

// NaN and infinite samples read as 0 (a depth as a miss), are counted in the stat nonFinite, and never reach an
// output.
TEST_F(ImageSequence, NonFiniteSamplesAreZeroedAndCounted) {
    auto ch = blenderFrame(kW, kH, 1);
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    ch["ViewLayer.Noisy Image.R"].values[3] = nan;
    ch["ViewLayer.Noisy Image.G"].values[4] = inf;
    ch["ViewLayer.Vector.X"].values[5] = -inf;
    ch["ViewLayer.Depth.Z"].values[6] = nan;
    test::writeExrChannels(mDir / "nan_0001.exr", kW, kH, ch);
    const test::CliResult r = renderSequence((mDir / "nan_####.exr").string(),
                                             "--size 8x6 --stats stats.json --dump 'Frames.*' --dump SVGF.filtered");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("non-finite"), std::string::npos) << r.output;
    const nlohmann::json stats = readJson((mDir / "stats.json").string());
    EXPECT_EQ(stats["frames"][0]["passes"]["Frames"]["nonFinite"], 4.0);
    for (const char* name : {"Frames.color.0000.exr", "Frames.mvec.0000.exr", "SVGF.filtered.0000.exr"}) {
        const Texture t = readImage(mDir / "out" / name);
        for (uint32_t y = 0; y < t.height(); ++y)
            for (uint32_t x = 0; x < t.width(); ++x)
                for (uint32_t c = 0; c < 4; ++c) EXPECT_TRUE(std::isfinite(t.texel(x, y, c))) << name;
    }
    EXPECT_EQ(readImage(mDir / "out" / "Frames.linearZ.0000.exr").texel(6, 0, 0), -1.f);
}

// Dumping a field never changes what a pass receives or what is refused: a sequence without the colour the denoiser
// reads is bad input whether or not Frames.color is also dumped (a dump of it alone shows zeros instead).
TEST_F(ImageSequence, DumpingARequiredChannelDoesNotHideThatItIsMissing) {
    auto ch = blenderFrame(kW, kH, 1);
    for (const char* c : {"R", "G", "B", "A"}) ch.erase(std::string("ViewLayer.Noisy Image.") + c);
    for (const char* c : {"R", "G", "B"}) ch.erase(std::string("ViewLayer.Combined.") + c);
    test::writeExrChannels(mDir / "nocolor_0001.exr", kW, kH, ch);
    const std::string pattern = (mDir / "nocolor_####.exr").string();
    const std::string size = "--size " + std::to_string(kW) + "x" + std::to_string(kH);
    for (const char* dump : {"", " --dump Frames.color", " --dump 'Frames.*'", " --dump '*'"})
        expectBadInput(renderSequence(pattern, size + dump), {"color"});
    // Observed only (no pass reads it, nothing marks it): computed as zeros, and the run goes on.
    nlohmann::json g = readJson(kSequenceGraph);
    g["passes"] = nlohmann::json::array({passNamed(g, "Frames")});
    g["passes"][0]["params"]["path"] = pattern;
    g["edges"] = nlohmann::json::array();
    g["outputs"] = nlohmann::json::array({"Frames.albedo"});
    const fs::path only = mDir / "frames_only.json";
    std::ofstream(only) << g.dump(2);
    const test::CliResult shown = renderSequence(only.string(), pattern, size + " --dump Frames.color");
    ASSERT_EQ(shown.code, 0) << shown.output;
    const Texture color = readImage(mDir / "out" / "Frames.color.0000.exr");
    for (uint32_t y = 0; y < uint32_t(kH); ++y)
        for (uint32_t x = 0; x < uint32_t(kW); ++x) EXPECT_EQ(color.texel(x, y, 0), 0.f);
}

// On the emulated device the frames are read and converted on the host and each output goes up once: every channel
// equals the CPU's bit for bit, at 1 and 2 threads, and so do the stats, for a full sequence and for one whose albedo
// is filled (the pass's host staging texture). The pass runs on emulated, so nothing it writes is copied into the
// passes after it (SVGF, ToneMap, on emulated too); only the observed channels come back to the host.
TEST_F(ImageSequence, OnEmulatedEqualsCpuBitForBit) {
    const std::string full = writeBlenderSequence(3);
    auto ch = blenderFrame(kW, kH, 1);
    for (const char* c : {"R", "G", "B"}) ch.erase(std::string("ViewLayer.Denoising Albedo.") + c);
    test::writeExrChannels(mDir / "noalbedo_0001.exr", kW, kH, ch);
    test::writeExrChannels(mDir / "noalbedo_0002.exr", kW, kH, ch);
    for (const std::string& pattern : {full, (mDir / "noalbedo_####.exr").string()}) {
        nlohmann::json g = readJson(kSequenceGraph);
        g["passes"][0]["params"]["path"] = pattern;
        for (unsigned threads : {1u, 2u}) {
            SCOPED_TRACE(pattern + " threads " + std::to_string(threads));
            ThreadLimit limit(threads);
            CompileOptions o;
            o.observe = {"Frames.*"};
            auto cpu = test::compiledGraph(g, nullptr, kW, kH, o);
            o.device = "emulated";
            auto emulated = test::compiledGraph(g, nullptr, kW, kH, o);
            for (const PlacedPass& p : emulated->plan().placement) {
                if (p.name == "Frames") EXPECT_EQ(p.device, DeviceKind::Emulated);
            }
            size_t uploads = 0;
            for (const TransferInfo& t : emulated->plan().transfers) {
                EXPECT_FALSE(!t.after && t.field.rfind("Frames.", 0) == 0) << t.field << " " << t.reason;
                uploads += t.after ? 0 : 1;
            }
            EXPECT_EQ(uploads, 0u);
            for (uint64_t f = 0; f < 2; ++f) {
                const FrameInfo frame{f, double(f) / 24.0, nullptr, nullptr};
                cpu->execute(frame);
                emulated->execute(frame);
                const size_t fields = test::expectSameFields(*cpu, *emulated, "Frames.", "frame " + std::to_string(f));
                EXPECT_GE(fields, 6u);
                EXPECT_EQ(cpu->lastStats().at("Frames"), emulated->lastStats().at("Frames")) << "frame " << f;
            }
        }
    }
}
