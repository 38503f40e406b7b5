// ImageSequence on sequences a careless export or a typo produces: values far outside their range reach no output
// as Inf or NaN, and every refusal names the pass, the graph frame, the file and the parameter to change.
#include <ImfMultiPartOutputFile.h>
#include <ImfOutputPart.h>
#include <ImfPartType.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>

#include "ExrTestUtil.h"
#include "TestUtil.h"
#include "loom/ImageIO.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

const std::string kGraph = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/DenoiseSequence.json";
constexpr int kW = 16, kH = 12;

/// A w x h frame with Blender's layer names: a lit plane at depth 4 facing the camera, still, albedo 0.5.
std::map<std::string, test::ExrTestChannel> planeFrame(int w = kW, int h = kH) {
    std::map<std::string, test::ExrTestChannel> ch;
    const auto constant = [&](const std::string& name, float v) {
        ch["ViewLayer." + name] = {std::vector<float>(size_t(w * h), v)};
    };
    for (const char* c : {"R", "G", "B"}) {
        constant(std::string("Noisy Image.") + c, 0.4f);
        constant(std::string("Denoising Albedo.") + c, 0.5f);
    }
    constant("Noisy Image.A", 1.f);
    constant("Normal.X", 0.f);
    constant("Normal.Y", 0.f);
    constant("Normal.Z", 1.f);
    constant("Depth.Z", 4.f);
    constant("Vector.X", 0.f);
    constant("Vector.Y", 0.f);
    return ch;
}

void setRow(test::ExrTestChannel& c, int y, float v) {
    for (int x = 0; x < kW; ++x) c.values[size_t(y * kW + x)] = v;
}

bool allFinite(const Texture& t) {
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            for (uint32_t c = 0; c < formatInfo(t.format()).channels; ++c)
                if (!std::isfinite(t.texel(x, y, c))) return false;
    return true;
}

size_t occurrences(const std::string& text, const std::string& part) {
    size_t n = 0;
    for (size_t at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
    return n;
}

class ImageSequenceInputs : public test::TempDirTest {
protected:
    std::string write(const std::string& name, const std::map<std::string, test::ExrTestChannel>& ch,
                      const std::optional<std::array<float, 16>>& worldToCamera = std::nullopt, int w = kW,
                      int h = kH) {
        test::writeExrChannels(mDir / name, w, h, ch, worldToCamera);
        return (mDir / name).string();
    }
    test::CliResult render(const std::string& pattern, const std::string& more, const std::string& graph = kGraph) {
        fs::create_directories(mDir / "out");
        return test::runLoom(mDir, "render --graph " + test::shellQuoted(graph) + " --set " +
                                       test::shellQuoted("Frames.path=" + pattern) + " --out out -q " + more);
    }
    void expectBadInput(const test::CliResult& r, const std::vector<std::string>& parts) {
        EXPECT_EQ(r.code, 2) << r.output;
        for (const auto& p : parts) EXPECT_NE(r.output.find(p), std::string::npos) << p << "\n" << r.output;
    }
    nlohmann::json stats() {
        std::ifstream in(mDir / "stats.json");
        return nlohmann::json::parse(in);
    }
};

const std::string kSize = "--size " + std::to_string(kW) + "x" + std::to_string(kH);

}  // namespace

// Rows of albedo 1e38 (and -1e38) are clamped into a reflectance's range and counted; the denoised frame and the
// bench-style error figures stay finite.
TEST_F(ImageSequenceInputs, HugeAlbedoIsClampedAndCountedAndTheDenoisedFrameIsFinite) {
    auto ch = planeFrame();
    for (const char* c : {"R", "G", "B"}) {
        setRow(ch[std::string("ViewLayer.Denoising Albedo.") + c], 3, 1e38f);
        setRow(ch[std::string("ViewLayer.Denoising Albedo.") + c], 7, -1e38f);
    }
    write("huge_0001.exr", ch);
    const test::CliResult r = render((mDir / "huge_####.exr").string(),
                                     kSize + " --stats stats.json --dump Frames.albedo --dump SVGF.filtered");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("out of range"), std::string::npos) << r.output;
    EXPECT_EQ(stats()["frames"][0]["passes"]["Frames"]["outOfRange"], 2.0 * 3 * kW);
    EXPECT_TRUE(allFinite(readImage(mDir / "out" / "SVGF.filtered.0000.exr")));
    const Texture albedo = readImage(mDir / "out" / "Frames.albedo.0000.exr");
    EXPECT_EQ(albedo.texel(0, 3, 0), 4.f);
    EXPECT_EQ(albedo.texel(0, 7, 0), 0.f);
}

// SVGF itself, handed albedo as large as floats go (here through Frames.reference, which is not clamped), remodulates
// to finite colour on its reference and its fused (SIMD) paths.
TEST_F(ImageSequenceInputs, SvgfRemodulatesHugeAlbedoToFiniteColour) {
    auto ch = planeFrame();
    for (const char* c : {"R", "G", "B"}) setRow(ch[std::string("ViewLayer.Denoising Albedo.") + c], 5, 1e38f);
    const std::string pattern = write("svgf_0001.exr", ch);
    nlohmann::json g;
    std::ifstream(kGraph) >> g;
    g["edges"].push_back({"Frames.reference", "SVGF.albedo"});
    const fs::path graph = mDir / "huge_albedo.json";
    std::ofstream(graph) << g.dump(1);
    for (const char* reference : {"true", "false"}) {
        SCOPED_TRACE(reference);
        const test::CliResult r =
            render((mDir / "svgf_####.exr").string(),
                   kSize + " --dump SVGF.filtered --set SVGF.referenceStages=" + reference + " --set " +
                       test::shellQuoted("Frames.reference=" + (mDir / "svgf_####.exr").string() +
                                         ":ViewLayer.Denoising Albedo"),
                   graph.string());
        ASSERT_EQ(r.code, 0) << r.output;
        EXPECT_TRUE(allFinite(readImage(mDir / "out" / "SVGF.filtered.0000.exr")));
    }
    (void)pattern;
}

// A camera matrix with an infinite entry, or one of 3e38 that leaves no rotation, cannot turn camera-space normals:
// bad input naming the file, the graph frame and the attribute. A rotation scaled by 1e30 turns them as it is.
TEST_F(ImageSequenceInputs, CameraMatricesThatCannotTurnNormalsAreBadInput) {
    const std::array<float, 16> identity = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    for (const float bad : {std::numeric_limits<float>::infinity(), 3e38f}) {
        SCOPED_TRACE(bad);
        std::array<float, 16> m = identity;
        m[1] = bad;
        write("cam_0001.exr", planeFrame(), m);
        expectBadInput(render((mDir / "cam_####.exr").string(), kSize + " --set Frames.normals=camera"),
                       {"cam_0001.exr", "Frames.normals", "graph frame 0", "worldToCamera", "normals=world"});
    }
    std::array<float, 16> scaled = identity;
    for (int i : {0, 5, 10}) scaled[size_t(i)] = 1e30f;
    write("cam_0001.exr", planeFrame(), scaled);
    const test::CliResult r =
        render((mDir / "cam_####.exr").string(), kSize + " --set Frames.normals=camera --dump Frames.normW");
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(readImage(mDir / "out" / "Frames.normW.0000.exr").texel(3, 3, 2), 1.f);
}

// A wrong path: the pass by its graph name, the missing file once, and path (not a channel) as what to change.
TEST_F(ImageSequenceInputs, AWrongPathNamesThePassTheFileOnceAndThePath) {
    const std::string pattern = (mDir / "nowhere" / "frame_####.exr").string();
    const test::CliResult r = render(pattern, kSize);
    expectBadInput(r, {"Frames.path", "does not exist: ", "check Frames.path", "Frames.firstFrame"});
    EXPECT_EQ(occurrences(r.output, "frame_0001.exr"), 1u) << r.output;
    EXPECT_EQ(r.output.find("ImageSequence."), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("set Frames.color"), std::string::npos) << r.output;
}

TEST_F(ImageSequenceInputs, ASymlinkLoopIsCalledOne) {
    fs::create_symlink(mDir / "loop_0002.exr", mDir / "loop_0001.exr");
    fs::create_symlink(mDir / "loop_0001.exr", mDir / "loop_0002.exr");
    expectBadInput(render((mDir / "loop_####.exr").string(), kSize), {"loop_0001.exr", "symbolic link loop"});
    // With the channel given, the file is opened as it is named.
    expectBadInput(
        render((mDir / "loop_####.exr").string(),
               kSize + " --set " +
                   test::shellQuoted("Frames.color=" + (mDir / "loop_####.exr").string() + ":ViewLayer.Noisy Image")),
        {"loop_0001.exr", "symbolic link loop"});
}

// Frames of two sizes: the error names both and does not send the user to a --size that fails on another frame.
TEST_F(ImageSequenceInputs, FramesOfDifferentSizesNameBothSizes) {
    write("var_0001.exr", planeFrame());
    write("var_0002.exr", planeFrame(8, 6), std::nullopt, 8, 6);
    expectBadInput(render((mDir / "var_####.exr").string(), kSize + " --frames 2"),
                   {"var_0002.exr", "is 8x6", "differ in size", "var_0001.exr, is 16x12", "one size",
                    "graph frame 1 (sequence frame 2)"});
}

// PATTERN: with nothing after the colon reads R, G, B, A; a multilayer file has none, and the error says how to
// name a layer.
TEST_F(ImageSequenceInputs, AnEmptyLayerSaysHowToNameOne) {
    write("ml_0001.exr", planeFrame());
    const test::CliResult r =
        render((mDir / "ml_####.exr").string(),
               kSize + " --set " + test::shellQuoted("Frames.color=" + (mDir / "ml_####.exr").string() + ":"));
    expectBadInput(r, {"Frames.color", "the layer for color is empty", "write the layer after the colon, e.g. "});
    EXPECT_EQ(r.output.find("has no layer ''"), std::string::npos) << r.output;
}

// A damaged second frame: the pass, the graph frame and the file.
TEST_F(ImageSequenceInputs, ADamagedFrameNamesThePassAndTheGraphFrame) {
    write("dmg_0001.exr", planeFrame());
    const std::string second = write("dmg_0002.exr", planeFrame());
    fs::resize_file(second, fs::file_size(second) / 2);
    expectBadInput(render((mDir / "dmg_####.exr").string(), kSize + " --frames 2"),
                   {"dmg_0002.exr", "Frames: graph frame 1 (sequence frame 2)"});
}

// '#' and '%' in a folder's name: the last run of '#' is the frame number, "%%" a literal '%'.
TEST_F(ImageSequenceInputs, FoldersWithHashAndPercentInTheirNames) {
    fs::create_directories(mDir / "take#2 50%");
    test::writeExrChannels(mDir / "take#2 50%" / "f_0001.exr", kW, kH, planeFrame());
    ASSERT_EQ(render((mDir / "take#2 50%%" / "f_####.exr").string(), kSize).code, 0);
    ASSERT_EQ(render((mDir / "take#2 50%%" / "f_%04d.exr").string(), kSize).code, 0);
}

// A two-part EXR with the normals in its second part: the error says where the layer is, and what to write instead.
TEST_F(ImageSequenceInputs, ALayerInASecondPartIsReportedWhereItIs) {
    const auto ch = planeFrame();
    std::vector<Imf::Header> headers(2, Imf::Header(kW, kH));
    for (int p = 0; p < 2; ++p) {
        headers[size_t(p)].setName(p == 0 ? "beauty" : "normals");
        headers[size_t(p)].setType(Imf::SCANLINEIMAGE);
    }
    for (const auto& [name, c] : ch)
        headers[name.find("Normal") != std::string::npos ? 1 : 0].channels().insert(name, Imf::Channel(Imf::FLOAT));
    {
        Imf::MultiPartOutputFile file((mDir / "parts_0001.exr").c_str(), headers.data(), 2);
        for (int p = 0; p < 2; ++p) {
            Imf::FrameBuffer fb;
            for (const auto& [name, c] : ch)
                if ((name.find("Normal") != std::string::npos) == (p == 1))
                    fb.insert(name,
                              Imf::Slice(Imf::FLOAT, const_cast<char*>(reinterpret_cast<const char*>(c.values.data())),
                                         4, 4 * size_t(kW)));
            Imf::OutputPart part(file, p);
            part.setFrameBuffer(fb);
            part.writePixels(kH);
        }
    }
    const std::string pattern = (mDir / "parts_####.exr").string();
    expectBadInput(render(pattern, kSize), {"'ViewLayer.Normal'", "in part 2 of", "single-part"});
    expectBadInput(render(pattern, kSize + " --set Frames.normW=Normal"),
                   {"Frames.normW", "in part 2 of the file's 2 parts", "single-part"});
}
