// Formats, textures, half conversion and image files (EXR and PNG).
#include <gtest/gtest.h>
#include <stb/stb_image.h>
#include <stb/stb_image_write.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/Format.h"
#include "loom/Files.h"
#include "loom/ImageIO.h"
#include "loom/Texture.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

const Format kAllFormats[] = {Format::R32F,    Format::RG32F,   Format::RGBA32F,    Format::RGBA16F,  Format::R32U,
                              Format::RG32U,   Format::RGBA32U, Format::RGBA8Unorm, Format::RGBA8Srgb};

uint32_t bitsOf(float f) { return std::bit_cast<uint32_t>(f); }

/// A fresh folder per test, removed afterwards.
class ImageFiles : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = fs::temp_directory_path() /
               ("loom_test_image_" + std::to_string(::getpid()) + "_" + test->name());
        fs::remove_all(mDir);
        fs::create_directories(mDir);
    }
    void TearDown() override {
        std::error_code ec;
        fs::remove_all(mDir, ec);
    }

    /// Names of all entries in the test folder.
    std::vector<std::string> entries() const {
        std::vector<std::string> names;
        for (const auto& e : fs::directory_iterator(mDir)) names.push_back(e.path().filename().string());
        std::sort(names.begin(), names.end());
        return names;
    }

    fs::path mDir;
};

/// Fills every component of a 32-bit texture with raw bits from a fixed sequence of interesting floats and
/// random bit patterns (no NaNs, so comparisons stay simple).
void fillFloat32(Texture& tex, uint32_t seed) {
    const float special[] = {0.0f, -0.0f, 1.0f, -1.0f, 0.5f, 3.14159265f, 1e-40f /* subnormal */, 1e30f, -1e-30f,
                             std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                             std::numeric_limits<float>::max(), std::numeric_limits<float>::min()};
    std::mt19937 rng(seed);
    uint32_t channels = formatInfo(tex.format()).channels;
    size_t i = 0;
    for (uint32_t y = 0; y < tex.height(); ++y) {
        auto* row = reinterpret_cast<float*>(tex.row(y));
        for (uint32_t x = 0; x < tex.width() * channels; ++x, ++i) {
            float v;
            if (i < std::size(special)) {
                v = special[i];
            } else {
                do v = std::bit_cast<float>(uint32_t(rng())); while (std::isnan(v));
            }
            row[x] = v;
        }
    }
}

}  // namespace

// ---- formats -------------------------------------------------------------------------------------------------

TEST(Format, TableIsConsistent) {
    for (Format f : kAllFormats) {
        const FormatInfo& info = formatInfo(f);
        EXPECT_EQ(info.format, f);
        EXPECT_GE(info.channels, 1u);
        EXPECT_LE(info.channels, 4u);
        uint32_t componentBytes = info.component == ComponentType::Float16 ? 2
                                  : info.component == ComponentType::Unorm8 ? 1
                                                                              : 4;
        EXPECT_EQ(info.bytesPerPixel, info.channels * componentBytes) << info.name;
        EXPECT_EQ(parseFormat(info.name), f) << info.name;
    }
    EXPECT_EQ(formatInfo(Format::RGBA8Srgb).srgb, true);
    EXPECT_EQ(formatInfo(Format::RGBA8Unorm).srgb, false);
    EXPECT_TRUE(isFloatFormat(Format::RGBA16F));
    EXPECT_FALSE(isFloatFormat(Format::R32U));
    EXPECT_FALSE(parseFormat("RGBA32").has_value());
    EXPECT_FALSE(parseFormat("rgba32f").has_value());
    EXPECT_FALSE(parseFormat("").has_value());
}

TEST(Format, ImageExtension) {
    EXPECT_STREQ(imageExtension(Format::RGBA32F), "exr");
    EXPECT_STREQ(imageExtension(Format::RGBA16F), "exr");
    EXPECT_STREQ(imageExtension(Format::R32U), "exr");
    EXPECT_STREQ(imageExtension(Format::RGBA8Unorm), "png");
    EXPECT_STREQ(imageExtension(Format::RGBA8Srgb), "png");
}

// ---- half conversion -----------------------------------------------------------------------------------------

TEST(Half, KnownValues) {
    EXPECT_EQ(floatToHalf(1.0f), 0x3C00);
    EXPECT_EQ(halfToFloat(0x3C00), 1.0f);
    EXPECT_EQ(floatToHalf(-2.0f), 0xC000);
    EXPECT_EQ(halfToFloat(0xC000), -2.0f);
    EXPECT_EQ(floatToHalf(0.0f), 0x0000);
    EXPECT_EQ(floatToHalf(-0.0f), 0x8000);
    EXPECT_EQ(bitsOf(halfToFloat(0x8000)), 0x80000000u);

    // Largest finite half, and the rounding boundary above it.
    EXPECT_EQ(floatToHalf(65504.0f), 0x7BFF);
    EXPECT_EQ(halfToFloat(0x7BFF), 65504.0f);
    EXPECT_EQ(floatToHalf(65519.0f), 0x7BFF);
    EXPECT_EQ(floatToHalf(65520.0f), 0x7C00);  // tie rounds to even: infinity
    EXPECT_EQ(floatToHalf(1e10f), 0x7C00);
    EXPECT_EQ(floatToHalf(-1e10f), 0xFC00);

    // Smallest normal, subnormals.
    EXPECT_EQ(floatToHalf(std::ldexp(1.0f, -14)), 0x0400);
    EXPECT_EQ(halfToFloat(0x0400), std::ldexp(1.0f, -14));
    EXPECT_EQ(floatToHalf(std::ldexp(1.0f, -24)), 0x0001);
    EXPECT_EQ(halfToFloat(0x0001), std::ldexp(1.0f, -24));
    EXPECT_EQ(halfToFloat(0x03FF), std::ldexp(1023.0f, -24));
    EXPECT_EQ(floatToHalf(std::ldexp(1023.0f, -24)), 0x03FF);
    EXPECT_EQ(halfToFloat(0x8001), -std::ldexp(1.0f, -24));
    EXPECT_EQ(floatToHalf(std::ldexp(1.0f, -25)), 0x0000);   // tie between 0 and the smallest subnormal: even
    EXPECT_EQ(floatToHalf(std::ldexp(1.5f, -25)), 0x0001);   // above the tie
    EXPECT_EQ(floatToHalf(std::ldexp(3.0f, -25)), 0x0002);   // tie between 1 and 2 ulps: even
    EXPECT_EQ(floatToHalf(std::ldexp(1.0f, -26)), 0x0000);
    EXPECT_EQ(floatToHalf(std::ldexp(2047.0f, -25)), 0x0400);  // rounds up out of the subnormals
    EXPECT_EQ(floatToHalf(1e-40f), 0x0000);                     // float subnormal
    EXPECT_EQ(floatToHalf(-1e-40f), 0x8000);

    // Rounding in the normal range: 1 + 2^-11 is halfway between 1 and 1 + 2^-10.
    EXPECT_EQ(floatToHalf(1.0f + std::ldexp(1.0f, -11)), 0x3C00);
    EXPECT_EQ(floatToHalf(1.0f + std::ldexp(3.0f, -11)), 0x3C02);
    EXPECT_EQ(floatToHalf(std::nextafter(1.0f + std::ldexp(1.0f, -11), 2.0f)), 0x3C01);

    // Infinities and NaN.
    const float inf = std::numeric_limits<float>::infinity();
    EXPECT_EQ(floatToHalf(inf), 0x7C00);
    EXPECT_EQ(floatToHalf(-inf), 0xFC00);
    EXPECT_EQ(halfToFloat(0x7C00), inf);
    EXPECT_EQ(halfToFloat(0xFC00), -inf);
    uint16_t nan = floatToHalf(std::numeric_limits<float>::quiet_NaN());
    EXPECT_EQ(nan & 0x7C00, 0x7C00);
    EXPECT_NE(nan & 0x03FF, 0);
    EXPECT_TRUE(std::isnan(halfToFloat(0x7E00)));
    EXPECT_TRUE(std::isnan(halfToFloat(0x7C01)));  // signalling NaN stays NaN
    // A float NaN whose payload is only in the low bits must not turn into infinity.
    uint16_t lowPayload = floatToHalf(std::bit_cast<float>(0x7F800001u));
    EXPECT_TRUE(std::isnan(halfToFloat(lowPayload)));
}

TEST(Half, EveryHalfRoundTrips) {
    for (uint32_t h = 0; h <= 0xFFFF; ++h) {
        float f = halfToFloat(uint16_t(h));
        bool isNan = (h & 0x7C00) == 0x7C00 && (h & 0x03FF) != 0;
        if (isNan) {
            ASSERT_TRUE(std::isnan(f)) << std::hex << h;
            uint16_t back = floatToHalf(f);
            ASSERT_EQ(back & 0x7C00, 0x7C00) << std::hex << h;
            ASSERT_NE(back & 0x03FF, 0) << std::hex << h;
        } else {
            ASSERT_EQ(floatToHalf(f), h) << std::hex << h;
        }
    }
}

TEST(Half, MidpointsRoundToNearestEven) {
    // Between every pair of consecutive finite halves (both signs), the exact midpoint rounds to the one with an
    // even mantissa, and the floats just either side of it round to the nearer half.
    for (uint32_t h = 0; h < 0x7BFF; ++h) {
        for (uint32_t sign : {0u, 0x8000u}) {
            auto lo = uint16_t(h | sign), hi = uint16_t((h + 1) | sign);
            float a = halfToFloat(lo), b = halfToFloat(hi);
            float mid = (a + b) / 2;  // exact: floats have 13 more mantissa bits than halves
            ASSERT_EQ(floatToHalf(mid), (h & 1) ? hi : lo) << std::hex << h;
            ASSERT_EQ(floatToHalf(std::nextafter(mid, a)), lo) << std::hex << h;
            ASSERT_EQ(floatToHalf(std::nextafter(mid, b)), hi) << std::hex << h;
        }
    }
}

// ---- textures ------------------------------------------------------------------------------------------------

TEST(Texture, RowsAreAlignedAndZeroFilled) {
    for (Format f : kAllFormats) {
        for (uint32_t width : {1u, 3u, 15u, 16u, 17u, 63u, 64u, 65u, 100u, 1000u}) {
            Texture t(width, 5, f);
            SCOPED_TRACE(std::string(formatName(f)) + " width " + std::to_string(width));
            EXPECT_EQ(t.rowPitch() % kRowAlignment, 0u);
            EXPECT_GE(t.rowPitch(), size_t(width) * formatInfo(f).bytesPerPixel);
            EXPECT_LT(t.rowPitch(), size_t(width) * formatInfo(f).bytesPerPixel + kRowAlignment);
            EXPECT_EQ(reinterpret_cast<uintptr_t>(t.data()) % kRowAlignment, 0u);
            EXPECT_EQ(t.byteSize(), textureByteSize(width, 5, f));
            for (uint32_t y = 0; y < t.height(); ++y) {
                EXPECT_EQ(reinterpret_cast<uintptr_t>(t.row(y)) % kRowAlignment, 0u);
            }
            bool allZero = true;
            for (size_t i = 0; i < t.byteSize(); ++i) allZero = allZero && t.data()[i] == std::byte{0};
            EXPECT_TRUE(allZero);
        }
    }
}

TEST(Texture, DefaultAndMoved) {
    Texture empty;
    EXPECT_TRUE(empty.empty());
    Texture a(4, 4, Format::RGBA32F);
    EXPECT_FALSE(a.empty());
    std::byte* data = a.data();
    Texture b = std::move(a);
    EXPECT_EQ(b.data(), data);
    EXPECT_EQ(b.width(), 4u);
}

TEST(Texture, PoisonAndClear) {
    for (Format f : kAllFormats) {
        Texture t(7, 3, f);
        t.poison();
        const FormatInfo& info = formatInfo(f);
        for (uint32_t y = 0; y < t.height(); ++y) {
            for (uint32_t x = 0; x < t.width(); ++x) {
                for (uint32_t c = 0; c < info.channels; ++c) {
                    float v = t.texel(x, y, c);
                    switch (info.component) {
                    case ComponentType::Float32:
                    case ComponentType::Float16: ASSERT_TRUE(std::isnan(v)) << info.name; break;
                    case ComponentType::Uint32: ASSERT_EQ(v, 4294967295.0f) << info.name; break;
                    case ComponentType::Unorm8: ASSERT_EQ(v, 1.0f) << info.name; break;
                    }
                }
            }
        }
        if (f == Format::RGBA16F) {
            uint16_t h;
            std::memcpy(&h, t.row(2) + 8 * 6 + 6, 2);
            EXPECT_EQ(h, 0x7E00);
        }
        t.clear();
        for (uint32_t c = 0; c < info.channels; ++c) EXPECT_EQ(t.texel(6, 2, c), 0.0f);
    }
}

TEST(Texture, TexelConvertsComponents) {
    Texture f16(2, 2, Format::RGBA16F);
    f16.view<uint64_t>().at(1, 1) = uint64_t(floatToHalf(-0.25f)) << 32;  // channel 2
    EXPECT_EQ(f16.texel(1, 1, 2), -0.25f);

    Texture u(2, 1, Format::RG32U);
    reinterpret_cast<uint32_t*>(u.row(0))[3] = 123456;
    EXPECT_EQ(u.texel(1, 0, 1), 123456.0f);

    for (Format f : {Format::RGBA8Unorm, Format::RGBA8Srgb}) {
        Texture b(1, 1, f);
        b.data()[1] = std::byte{51};
        EXPECT_FLOAT_EQ(b.texel(0, 0, 1), 0.2f);  // no sRGB decode
    }
    EXPECT_THROW(u.texel(2, 0, 0), std::out_of_range);
    EXPECT_THROW(u.texel(0, 0, 2), std::out_of_range);
}

TEST(Texture, CopyFromAndSamePixels) {
    Texture a(13, 7, Format::RGBA32F);
    fillFloat32(a, 1);
    Texture b(13, 7, Format::RGBA32F);
    EXPECT_FALSE(b.samePixels(a));
    b.copyFrom(a);
    EXPECT_TRUE(b.samePixels(a));
    EXPECT_TRUE(a.samePixels(a));

    // Padding bytes do not matter.
    size_t rowBytes = 13 * 16;
    ASSERT_LT(rowBytes, b.rowPitch());
    b.row(3)[rowBytes] = std::byte{0x5A};
    EXPECT_TRUE(b.samePixels(a));
    b.row(3)[rowBytes - 1] ^= std::byte{1};
    EXPECT_FALSE(b.samePixels(a));

    Texture otherSize(13, 8, Format::RGBA32F), otherFormat(13, 7, Format::RGBA32U);
    EXPECT_THROW(otherSize.copyFrom(a), std::invalid_argument);
    EXPECT_THROW(otherFormat.copyFrom(a), std::invalid_argument);
    EXPECT_FALSE(otherFormat.samePixels(a));
}

TEST(Texture, WrapViewsExternalMemory) {
    size_t bytes = textureByteSize(5, 4, Format::R32F);
    alignas(64) std::byte memory[1024] = {};
    ASSERT_LE(bytes, sizeof(memory));
    Texture t = Texture::wrap(memory, 5, 4, Format::R32F);
    EXPECT_EQ(t.data(), memory);
    EXPECT_EQ(t.rowPitch() % kRowAlignment, 0u);
    t.view<float>().at(2, 3) = 7.5f;
    float v;
    std::memcpy(&v, memory + t.rowPitch() * 3 + 8, 4);
    EXPECT_EQ(v, 7.5f);

    Texture owned(5, 4, Format::R32F);
    owned.copyFrom(t);
    EXPECT_EQ(owned.texel(2, 3, 0), 7.5f);
    EXPECT_TRUE(owned.samePixels(t));
}

// ---- EXR -----------------------------------------------------------------------------------------------------

TEST_F(ImageFiles, ExrRgba32fRoundTripIsBitExact) {
    Texture tex(37, 23, Format::RGBA32F);
    fillFloat32(tex, 2);
    fs::path path = mDir / "a.exr";
    writeImage(path, tex);
    Texture back = readImage(path);
    EXPECT_EQ(back.format(), Format::RGBA32F);
    EXPECT_EQ(back.width(), 37u);
    EXPECT_EQ(back.height(), 23u);
    EXPECT_TRUE(back.samePixels(tex));
}

TEST_F(ImageFiles, ExrR32fReadsBackAsRgba32f) {
    Texture tex(19, 11, Format::R32F);
    fillFloat32(tex, 3);
    fs::path path = mDir / "r.exr";
    writeImage(path, tex);
    Texture back = readImage(path);
    ASSERT_EQ(back.format(), Format::RGBA32F);
    ASSERT_EQ(back.width(), 19u);
    ASSERT_EQ(back.height(), 11u);
    for (uint32_t y = 0; y < 11; ++y) {
        for (uint32_t x = 0; x < 19; ++x) {
            ASSERT_EQ(bitsOf(back.texel(x, y, 0)), bitsOf(tex.texel(x, y, 0))) << x << "," << y;
            ASSERT_EQ(back.texel(x, y, 1), 0.0f);
            ASSERT_EQ(back.texel(x, y, 2), 0.0f);
            ASSERT_EQ(back.texel(x, y, 3), 1.0f);
        }
    }
}

TEST_F(ImageFiles, ExrRg32fKeepsBothChannels) {
    Texture tex(5, 3, Format::RG32F);
    fillFloat32(tex, 4);
    fs::path path = mDir / "rg.exr";
    writeImage(path, tex);
    Texture back = readImage(path);
    for (uint32_t y = 0; y < 3; ++y) {
        for (uint32_t x = 0; x < 5; ++x) {
            EXPECT_EQ(bitsOf(back.texel(x, y, 0)), bitsOf(tex.texel(x, y, 0)));
            EXPECT_EQ(bitsOf(back.texel(x, y, 1)), bitsOf(tex.texel(x, y, 1)));
            EXPECT_EQ(back.texel(x, y, 2), 0.0f);
            EXPECT_EQ(back.texel(x, y, 3), 1.0f);
        }
    }
}

TEST_F(ImageFiles, ExrRgba16fValuesAreExact) {
    Texture tex(17, 9, Format::RGBA16F);
    std::mt19937 rng(5);
    for (uint32_t y = 0; y < tex.height(); ++y) {
        auto* row = reinterpret_cast<uint16_t*>(tex.row(y));
        for (uint32_t i = 0; i < tex.width() * 4; ++i) {
            uint16_t h;
            do h = uint16_t(rng()); while ((h & 0x7C00) == 0x7C00);  // finite values
            row[i] = h;
        }
    }
    fs::path path = mDir / "h.exr";
    writeImage(path, tex);
    Texture back = readImage(path);
    ASSERT_EQ(back.format(), Format::RGBA32F);
    for (uint32_t y = 0; y < tex.height(); ++y) {
        for (uint32_t x = 0; x < tex.width(); ++x) {
            for (uint32_t c = 0; c < 4; ++c) {
                ASSERT_EQ(bitsOf(back.texel(x, y, c)), bitsOf(tex.texel(x, y, c))) << x << "," << y << "," << c;
            }
        }
    }
}

TEST_F(ImageFiles, ExrRgba32uRoundTripIsExact) {
    Texture tex(21, 6, Format::RGBA32U);
    std::mt19937 rng(6);
    for (uint32_t y = 0; y < tex.height(); ++y) {
        auto* row = reinterpret_cast<uint32_t*>(tex.row(y));
        for (uint32_t i = 0; i < tex.width() * 4; ++i) row[i] = uint32_t(rng());
    }
    reinterpret_cast<uint32_t*>(tex.row(0))[0] = 0xFFFFFFFFu;
    reinterpret_cast<uint32_t*>(tex.row(0))[1] = 0;
    fs::path path = mDir / "u.exr";
    writeImage(path, tex);
    Texture back = readImage(path);
    EXPECT_EQ(back.format(), Format::RGBA32U);
    EXPECT_TRUE(back.samePixels(tex));
}

TEST_F(ImageFiles, ExrR32uReadsBackAsRgba32u) {
    Texture tex(4, 4, Format::R32U);
    for (uint32_t y = 0; y < 4; ++y) {
        for (uint32_t x = 0; x < 4; ++x) tex.view<uint32_t>().at(x, y) = 1000000007u * (x + 4 * y);
    }
    fs::path path = mDir / "id.exr";
    writeImage(path, tex);
    Texture back = readImage(path);
    ASSERT_EQ(back.format(), Format::RGBA32U);
    for (uint32_t y = 0; y < 4; ++y) {
        for (uint32_t x = 0; x < 4; ++x) {
            const uint32_t* p = reinterpret_cast<const uint32_t*>(back.row(y)) + 4 * x;
            EXPECT_EQ(p[0], 1000000007u * (x + 4 * y));
            EXPECT_EQ(p[1], 0u);
            EXPECT_EQ(p[2], 0u);
            EXPECT_EQ(p[3], 1u);
        }
    }
}

// ---- PNG -----------------------------------------------------------------------------------------------------

TEST_F(ImageFiles, PngRoundTripIsExact) {
    for (Format f : {Format::RGBA8Unorm, Format::RGBA8Srgb}) {
        Texture tex(33, 10, f);
        std::mt19937 rng(7);
        for (uint32_t y = 0; y < tex.height(); ++y) {
            for (uint32_t i = 0; i < tex.width() * 4; ++i) tex.row(y)[i] = std::byte(rng() & 0xFF);
        }
        fs::path path = mDir / (std::string(formatName(f)) + ".png");
        writeImage(path, tex);
        Texture back = readImage(path);
        EXPECT_EQ(back.format(), Format::RGBA8Unorm);
        ASSERT_EQ(back.width(), tex.width());
        ASSERT_EQ(back.height(), tex.height());
        Texture expected(33, 10, Format::RGBA8Unorm);
        std::memcpy(expected.data(), tex.data(), tex.byteSize());
        EXPECT_TRUE(back.samePixels(expected)) << formatName(f);
    }
}

// ---- atomic writes and errors --------------------------------------------------------------------------------

TEST_F(ImageFiles, SuccessfulWritesLeaveNoTemporaryFiles) {
    Texture f(8, 8, Format::RGBA32F);
    Texture b(8, 8, Format::RGBA8Unorm);
    writeImage(mDir / "a.exr", f);
    writeImage(mDir / "b.png", b);
    writeFileAtomic(mDir / "c.txt", "hello");
    writeImage(mDir / "a.exr", f);  // overwriting an existing file
    EXPECT_EQ(entries(), (std::vector<std::string>{"a.exr", "b.png", "c.txt"}));
    std::ifstream in(mDir / "c.txt", std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text, "hello");
}

TEST_F(ImageFiles, WritingIntoMissingFolderIsBadInput) {
    Texture f(4, 4, Format::RGBA32F);
    Texture b(4, 4, Format::RGBA8Srgb);
    fs::path missing = mDir / "no" / "such";
    for (const fs::path& path : {missing / "x.exr", missing / "x.png"}) {
        try {
            writeImage(path, path.extension() == ".exr" ? f : b);
            FAIL() << "no error for " << path;
        } catch (const Error& e) {
            EXPECT_EQ(e.kind(), ErrorKind::BadInput);
            EXPECT_NE(std::string(e.what()).find("folder does not exist"), std::string::npos) << e.what();
            EXPECT_FALSE(e.info().suggestion.empty());
            EXPECT_EQ(e.info().file, path.string());
        }
    }
    EXPECT_THROW(writeFileAtomic(missing / "x.txt", "x"), Error);
    EXPECT_FALSE(fs::exists(mDir / "no"));
    EXPECT_TRUE(entries().empty());
}

TEST_F(ImageFiles, WritingIntoReadOnlyFolderIsBadInput) {
    // A folder without write permission; root ignores permissions, so as root the folder is /proc/self, where
    // nobody may create files.
    const bool root = ::geteuid() == 0;
    fs::path folder = root ? fs::path("/proc/self") : mDir / "ro";
    if (!root) {
        fs::create_directory(folder);
        fs::permissions(folder, fs::perms::owner_read | fs::perms::owner_exec);
    }
    try {
        writeImage(folder / "x.exr", Texture(2, 2, Format::RGBA32F));
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(std::string(e.what()).find("cannot write"), std::string::npos) << e.what();
    }
    if (root) {
        EXPECT_FALSE(fs::exists(folder / "x.exr"));
        return;
    }
    fs::permissions(folder, fs::perms::owner_all);
    EXPECT_TRUE(fs::is_empty(folder));
}

TEST_F(ImageFiles, FailedRenameRemovesTemporaryFile) {
    // The target is an existing, non-empty folder: the rename fails after the temporary file was written.
    fs::create_directories(mDir / "taken.exr" / "inside");
    try {
        writeImage(mDir / "taken.exr", Texture(2, 2, Format::RGBA32F));
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::Runtime);
    }
    EXPECT_EQ(entries(), (std::vector<std::string>{"taken.exr"}));
}

TEST_F(ImageFiles, WrongExtensionIsBadInput) {
    try {
        writeImage(mDir / "x.png", Texture(2, 2, Format::RGBA32F));
        ADD_FAILURE() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    }
    EXPECT_TRUE(entries().empty());
}

TEST_F(ImageFiles, ReadingMissingFileIsBadInput) {
    fs::path path = mDir / "missing.exr";
    try {
        readImage(path);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
}

TEST_F(ImageFiles, ReadingGarbageIsBadInput) {
    writeFileAtomic(mDir / "garbage.png", "this is not an image at all");
    writeFileAtomic(mDir / "garbage.exr", std::string(1000, '\x42'));
    writeFileAtomic(mDir / "empty.png", "");
    for (const char* name : {"garbage.png", "garbage.exr", "empty.png"}) {
        try {
            readImage(mDir / name);
            ADD_FAILURE() << "no error for " << name;
        } catch (const Error& e) {
            EXPECT_EQ(e.kind(), ErrorKind::BadInput) << name;
            EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
        }
    }
}

TEST_F(ImageFiles, ReadingTruncatedExrIsBadInput) {
    Texture tex(64, 64, Format::RGBA32F);
    fillFloat32(tex, 8);
    writeImage(mDir / "full.exr", tex);
    std::ifstream in(mDir / "full.exr", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GT(bytes.size(), 200u);
    writeFileAtomic(mDir / "cut.exr", bytes.substr(0, bytes.size() / 2));
    try {
        readImage(mDir / "cut.exr");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    }
}

// ---- Radiance .hdr -------------------------------------------------------------------------------------------

namespace {

/// A w x h RGB image over many magnitudes, with runs of equal pixels (which the writer run-length encodes).
std::vector<float> hdrPixels(uint32_t w, uint32_t h) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    std::vector<float> rgb(size_t(w) * h * 3);
    for (size_t i = 0; i < rgb.size(); ++i) {
        const size_t pixel = i / 3;
        if (pixel % 11 >= 6 && pixel > 0) {
            rgb[i] = rgb[i - 3];  // runs of five equal pixels
        } else {
            rgb[i] = pixel % 13 == 0 ? 0.f : unit(rng) * std::exp2(float(int(pixel % 40) - 20));
        }
    }
    return rgb;
}

std::string fileBytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

// Rows narrower than 8 are stored flat, wider ones run-length encoded per channel: both decode to what stb decodes
// (m 2^(e - 136) per channel), with alpha 1.
TEST_F(ImageFiles, RadianceHdrFlatAndEncodedRowsDecodeLikeStb) {
    for (uint32_t w : {5u, 37u, 300u}) {
        const uint32_t h = 4;
        const fs::path file = mDir / ("sky" + std::to_string(w) + ".hdr");
        const std::vector<float> rgb = hdrPixels(w, h);
        ASSERT_NE(stbi_write_hdr(file.c_str(), int(w), int(h), 3, rgb.data()), 0);
        int sw = 0, sh = 0, sc = 0;
        std::unique_ptr<float, void (*)(void*)> expected(stbi_loadf(file.c_str(), &sw, &sh, &sc, 3), stbi_image_free);
        ASSERT_TRUE(expected) << stbi_failure_reason();
        for (const Texture& tex : {readImage(file), readRadianceHdr(file)}) {
            ASSERT_EQ(tex.format(), Format::RGBA32F);
            ASSERT_EQ(tex.width(), w);
            ASSERT_EQ(tex.height(), h);
            size_t zeros = 0;
            for (uint32_t y = 0; y < h; ++y)
                for (uint32_t x = 0; x < w; ++x) {
                    for (uint32_t c = 0; c < 3; ++c) {
                        const float e = expected.get()[(size_t(y) * w + x) * 3 + c];
                        EXPECT_EQ(bitsOf(tex.texel(x, y, c)), bitsOf(e)) << w << ": " << x << "," << y << " c" << c;
                        zeros += e == 0.f;
                    }
                    EXPECT_EQ(tex.texel(x, y, 3), 1.f);
                }
            EXPECT_GT(zeros, 0u);  // the test covers e = 0
        }
    }
}

// Every prefix of a file is an error that names it (the decoder never reads past the end, nor loops on a run of
// length 0), and so are damaged runs, other pixel formats and orientations, and absurd sizes.
TEST_F(ImageFiles, DamagedOrTruncatedRadianceHdrIsBadInput) {
    const uint32_t w = 37, h = 3;
    const fs::path whole = mDir / "whole.hdr";
    const std::vector<float> rgb = hdrPixels(w, h);
    ASSERT_NE(stbi_write_hdr(whole.c_str(), int(w), int(h), 3, rgb.data()), 0);
    const std::string bytes = fileBytes(whole);
    const size_t dataStart = bytes.find("+X 37\n") + 6;
    ASSERT_NE(dataStart, std::string::npos + 6);
    ASSERT_EQ(bytes.substr(dataStart, 4), std::string("\x02\x02\x00\x25", 4));  // an encoded row of width 37
    const auto expectBadInput = [&](const std::string& content, const std::string& label) {
        const fs::path f = mDir / "bad.hdr";
        writeFileAtomic(f, content);
        try {
            readRadianceHdr(f);
            ADD_FAILURE() << "no error for " << label;
        } catch (const Error& e) {
            EXPECT_EQ(e.kind(), ErrorKind::BadInput) << label;
            EXPECT_NE(std::string(e.what()).find("bad.hdr"), std::string::npos) << e.what();
        }
    };
    for (size_t n = 0; n < bytes.size(); ++n) expectBadInput(bytes.substr(0, n), "prefix " + std::to_string(n));
    std::string zeroRun = bytes, longRun = bytes, narrow = bytes;
    zeroRun[dataStart + 4] = 0;               // a literal run of no pixels: no progress
    longRun[dataStart + 4] = char(128 + 38);  // a repeated run one longer than the row
    narrow[dataStart + 3] = 36;               // a row encoded for another width
    expectBadInput(zeroRun, "run of 0");
    expectBadInput(longRun, "run past the row");
    expectBadInput(narrow, "row of another width");
    const std::string header = bytes.substr(0, dataStart), data = bytes.substr(dataStart);
    const auto withSize = [&](const std::string& size) {
        return header.substr(0, header.find("-Y 3 +X 37")) + size + "\n" + data;
    };
    expectBadInput(withSize("+Y 3 +X 37"), "bottom-up rows");
    expectBadInput(withSize("-Y 0 +X 37"), "no rows");
    expectBadInput(withSize("-Y 70000 +X 70000"), "too large");
    expectBadInput(withSize("-Y 3"), "no width");
    std::string xyz = bytes;
    const size_t format = xyz.find("FORMAT=32-bit_rle_rgbe");
    ASSERT_NE(format, std::string::npos);
    xyz.replace(format, 22, "FORMAT=32-bit_rle_xyze");
    expectBadInput(xyz, "XYZ pixels");
    expectBadInput("P6\n1 1\n255\n\x01\x02\x03", "another format");
}
