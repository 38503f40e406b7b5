// Numbered file patterns as printf and Blender read them (sequenceFramePath): printf's widths pad with spaces, its
// 0 flag with zeros; widths up to 18 digits; "%%" is a literal '%'; without a printf field the last run of '#' is
// the frame number, so a '#' in a folder's name is literal. And what a path that cannot be opened is called.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/ExrFile.h"

using namespace loom;
namespace fs = std::filesystem;

TEST(SequencePatterns, PrintfWidthsPadAsPrintfDoes) {
    EXPECT_EQ(sequenceFramePath("f%4d.exr", 7, "x"), "f   7.exr");
    EXPECT_EQ(sequenceFramePath("f%04d.exr", 7, "x"), "f0007.exr");
    EXPECT_EQ(sequenceFramePath("f%018d.exr", 7, "x"), "f000000000000000007.exr");
    EXPECT_EQ(sequenceFramePath("f%18d.exr", 7, "x"), "f                 7.exr");
    for (const char* wide : {"f%019d.exr", "f%19d.exr", "f%99d.exr", "f%0999d.exr"}) {
        SCOPED_TRACE(wide);
        const Error e = test::expectError([&] { sequenceFramePath(wide, 1, "Frames.path"); });
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(e.info().what.find("wider than 18 digits"), std::string::npos) << e.what();
    }
    const Error e = test::expectError([] { sequenceFramePath("f%x.exr", 1, "Frames.path"); });
    EXPECT_NE(e.info().what.find("write %% for a literal %"), std::string::npos) << e.what();
}

TEST(SequencePatterns, PercentAndHashInFolderNamesAreLiteral) {
    EXPECT_EQ(sequenceFramePath("50%%/shot#2/f_####.exr", 3, "x"), "50%/shot#2/f_0003.exr");
    EXPECT_EQ(sequenceFramePath("take#1/f_###_##.exr", 3, "x"), "take#1/f_###_03.exr");  // the last run
    EXPECT_EQ(sequenceFramePath("a#b/##_%03d.exr", 3, "x"), "a#b/##_003.exr");  // a printf field: every '#' literal
    EXPECT_EQ(sequenceFramePath("100%%%%_%%d_%d.exr", 3, "x"), "100%%_%d_3.exr");
    EXPECT_EQ(sequenceFramePath("frame_####/beauty.exr", 12, "x"), "frame_0012/beauty.exr");  // a folder per frame
}

TEST(SequencePatterns, PathsThatCannotBeOpenedSayWhy) {
    const fs::path dir = fs::temp_directory_path() / ("loom_patterns_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::ofstream(dir / "file.exr") << "x";
    fs::create_symlink(dir / "b.exr", dir / "a.exr");
    fs::create_symlink(dir / "a.exr", dir / "b.exr");
    fs::create_symlink(dir / "gone.exr", dir / "dangling.exr");
    EXPECT_EQ(fileAbsence(dir / "file.exr"), "");
    EXPECT_EQ(fileAbsence(dir / "a.exr"), "is a symbolic link loop");
    EXPECT_EQ(fileAbsence(dir / "dangling.exr"), "is a symbolic link to a missing file");
    EXPECT_EQ(fileAbsence(dir / "none.exr"), "does not exist");
    EXPECT_EQ(fileAbsence(dir), "is not a regular file");
    const Error e = test::expectError([&] { ExrFile f(dir / "a.exr"); });
    EXPECT_NE(e.info().what.find("symbolic link loop"), std::string::npos) << e.what();
    fs::remove_all(dir);
}
