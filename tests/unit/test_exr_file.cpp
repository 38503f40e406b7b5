// ExrFile and numbered sequences: frame fields, layer lookup in multilayer files as Blender writes them, and the
// errors of damaged files.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "ExrTestUtil.h"
#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"

using namespace loom;
namespace fs = std::filesystem;

TEST(SequenceFramePath, ExpandsPrintfAndHashFields) {
    EXPECT_EQ(sequenceFramePath("a/beauty.%04d.exr", 7, "x"), "a/beauty.0007.exr");
    EXPECT_EQ(sequenceFramePath("beauty.%d.exr", 12, "x"), "beauty.12.exr");
    EXPECT_EQ(sequenceFramePath("noisy_####.exr", 3, "x"), "noisy_0003.exr");
    EXPECT_EQ(sequenceFramePath("f#.exr", 123, "x"), "f123.exr");      // the field widens, as printf's does
    EXPECT_EQ(sequenceFramePath("f%02d.exr", 12345, "x"), "f12345.exr");
    EXPECT_EQ(sequenceFramePath("100%%_%03d.exr", 5, "x"), "100%_005.exr");  // %% is a literal percent sign
}

TEST(SequenceFramePath, RefusesPatternsWithoutOneField) {
    for (const char* bad : {"beauty.exr", "a_%04d_%04d.exr", "a_%s.exr", "a_%", "a_%0999d.exr"}) {
        SCOPED_TRACE(bad);
        const Error e = test::expectError([&] { sequenceFramePath(bad, 1, "Frames.path"); });
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(std::string(e.what()).find("Frames.path"), std::string::npos) << e.what();
    }
    EXPECT_EQ(test::expectError([] { sequenceFramePath("a_%d.exr", -1, "x"); }).kind(), ErrorKind::BadInput);
}

TEST(SequenceSource, SplitsTheLayerAfterTheExtension) {
    const SequenceSource a = parseSequenceSource("frames/noisy_####.exr:ViewLayer.Noisy Image");
    EXPECT_EQ(a.pattern, "frames/noisy_####.exr");
    EXPECT_EQ(a.layer, "ViewLayer.Noisy Image");
    const SequenceSource b = parseSequenceSource("c:/x/ref.%04d.EXR");
    EXPECT_EQ(b.pattern, "c:/x/ref.%04d.EXR");
    EXPECT_EQ(b.layer, "");
    EXPECT_EQ(parseSequenceSource("ref.%04d.exr:").layer, "");
}

class ExrFileTest : public test::TempDirTest {
protected:
    /// A 3x2 multilayer file with Blender's channel names, and values that say where they come from.
    fs::path writeBlenderLike() {
        std::map<std::string, test::ExrTestChannel> ch;
        const auto ramp = [](float base) {
            std::vector<float> v;
            for (int i = 0; i < 6; ++i) v.push_back(base + float(i));
            return v;
        };
        for (const char* c : {"R", "G", "B", "A"}) ch[std::string("ViewLayer.Noisy Image.") + c] = {ramp(10.f * c[0])};
        for (const char* c : {"X", "Y", "Z"}) ch[std::string("ViewLayer.Normal.") + c] = {ramp(c[0])};
        for (const char* c : {"X", "Y", "Z", "W"}) ch[std::string("ViewLayer.Vector.") + c] = {ramp(-c[0])};
        ch["ViewLayer.Depth.Z"] = {ramp(1.f), Imf::HALF};
        ch["ViewLayer.IndexOB.X"] = {ramp(0.f)};
        ch["ViewLayer.Crypto.R"] = {ramp(0.f), Imf::UINT};
        const fs::path p = mDir / "blender_0001.exr";
        test::writeExrChannels(p, 3, 2, ch);
        return p;
    }
};

TEST_F(ExrFileTest, FindsLayersAndTheirComponentsInOrder) {
    ExrFile f(writeBlenderLike());
    EXPECT_EQ(f.width(), 3u);
    EXPECT_EQ(f.height(), 2u);
    EXPECT_EQ(f.layerChannels("ViewLayer.Noisy Image"),
              (std::vector<std::string>{"ViewLayer.Noisy Image.R", "ViewLayer.Noisy Image.G",
                                        "ViewLayer.Noisy Image.B", "ViewLayer.Noisy Image.A"}));
    EXPECT_EQ(f.layerChannels("ViewLayer.Vector"),
              (std::vector<std::string>{"ViewLayer.Vector.X", "ViewLayer.Vector.Y", "ViewLayer.Vector.Z",
                                        "ViewLayer.Vector.W"}));
    EXPECT_EQ(f.layerChannels("ViewLayer.Normal").size(), 3u);
    // A one-channel layer is that channel, whatever its component is called; so is a full channel name.
    EXPECT_EQ(f.layerChannels("ViewLayer.Depth"), std::vector<std::string>{"ViewLayer.Depth.Z"});
    EXPECT_EQ(f.layerChannels("ViewLayer.IndexOB.X"), std::vector<std::string>{"ViewLayer.IndexOB.X"});
    EXPECT_TRUE(f.layerChannels("ViewLayer.Denoising Albedo").empty());
    EXPECT_TRUE(f.layerChannels("").empty());
    EXPECT_EQ(f.findChannel("ViewLayer.Depth.Z")->type, ExrSampleType::Half);
    const std::vector<std::string> layers = f.layers();
    EXPECT_NE(std::find(layers.begin(), layers.end(), "ViewLayer.Noisy Image"), layers.end());
    EXPECT_FALSE(f.worldToCamera());
}

TEST_F(ExrFileTest, ReadsLayersIntoRgbaAndRefusesWhatIsNotColour) {
    ExrFile f(writeBlenderLike());
    const Texture noisy = f.readRgba("ViewLayer.Noisy Image");
    for (uint32_t i = 0; i < 6; ++i) {
        EXPECT_EQ(noisy.texel(i % 3, i / 3, 0), 10.f * 'R' + float(i));
        EXPECT_EQ(noisy.texel(i % 3, i / 3, 3), 10.f * 'A' + float(i));
    }
    // Three components: alpha 1. A half channel reads exactly (small integers).
    const Texture normal = f.readRgba("ViewLayer.Normal");
    EXPECT_EQ(normal.texel(2, 1, 2), float('Z') + 5.f);
    EXPECT_EQ(normal.texel(2, 1, 3), 1.f);
    EXPECT_EQ(f.readRgba("ViewLayer.Depth").texel(1, 0, 0), 2.f);
    const Error missing = test::expectError([&] { f.readRgba("ViewLayer.Noisy Imag"); });
    EXPECT_EQ(missing.kind(), ErrorKind::BadInput);
    EXPECT_NE(std::string(missing.what()).find("ViewLayer.Noisy Image"), std::string::npos) << missing.what();
    EXPECT_EQ(test::expectError([&] { f.readRgba("ViewLayer.Crypto"); }).kind(), ErrorKind::BadInput);
}

TEST_F(ExrFileTest, ReadsAnyChannelsInOnePassWithGapsFilled) {
    ExrFile f(writeBlenderLike());
    std::vector<float> depth(6, -7.f), index(6), filled(6);
    std::vector<uint32_t> crypto(6);
    f.read({{"ViewLayer.Depth.Z", reinterpret_cast<std::byte*>(depth.data()), 4, 12, false, 0.0},
            {"ViewLayer.IndexOB.X", reinterpret_cast<std::byte*>(index.data()), 4, 12, false, 0.0},
            {"ViewLayer.IndexOB.X", reinterpret_cast<std::byte*>(filled.data()), 4, 12, false, 0.0},  // twice
            {"ViewLayer.Crypto.R", reinterpret_cast<std::byte*>(crypto.data()), 4, 12, true, 0.0}});
    for (int i = 0; i < 6; ++i) {
        EXPECT_EQ(depth[size_t(i)], 1.f + float(i));
        EXPECT_EQ(index[size_t(i)], float(i));
        EXPECT_EQ(filled[size_t(i)], float(i));
        EXPECT_EQ(crypto[size_t(i)], uint32_t(i));
    }
    std::vector<float> none(6, 3.f);
    f.read({{"", reinterpret_cast<std::byte*>(none.data()), 4, 12, false, 0.5}});
    for (float v : none) EXPECT_EQ(v, 0.5f);
}

TEST_F(ExrFileTest, KeepsTheWorldToCameraAttribute) {
    std::array<float, 16> m{};
    for (size_t i = 0; i < 16; ++i) m[i] = float(i) * 0.5f;
    const fs::path p = mDir / "cam.exr";
    test::writeExrChannels(p, 2, 2, {{"R", {{1, 2, 3, 4}}}}, m);
    const auto read = ExrFile(p).worldToCamera();
    ASSERT_TRUE(read);
    EXPECT_EQ(*read, m);
}

TEST_F(ExrFileTest, DamagedFilesAreBadInputNamingTheFile) {
    const fs::path good = writeBlenderLike();
    std::string bytes;
    {
        std::ifstream in(good, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    for (size_t keep : {bytes.size() - 9, bytes.size() / 2, size_t(40), size_t(3), size_t(0)}) {
        SCOPED_TRACE(keep);
        const fs::path cut = mDir / "cut.exr";
        std::ofstream(cut, std::ios::binary).write(bytes.data(), std::streamsize(keep));
        const Error e = test::expectError([&] {
            ExrFile f(cut);
            f.readRgba("ViewLayer.Noisy Image");
        });
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(std::string(e.what()).find("cut.exr"), std::string::npos) << e.what();
    }
    EXPECT_EQ(test::expectError([&] { ExrFile f(mDir / "absent.exr"); }).kind(), ErrorKind::BadInput);
}
