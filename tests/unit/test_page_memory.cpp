// PageMemory: zero-filled buffers, heap for small sizes, 2 MiB-aligned mappings advised as huge pages for large ones.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "loom/PageMemory.h"
#include "loom/Texture.h"

using namespace loom;

namespace {

// Under AddressSanitizer PageMemory takes every buffer from the heap (so that overruns are caught).
#if defined(__SANITIZE_ADDRESS__)
constexpr bool kLargeMapped = false;
#else
constexpr bool kLargeMapped = true;
#endif
constexpr size_t kLargeAlignment = kLargeMapped ? PageMemory::kHugePageSize : 64;

bool allZero(const std::byte* p, size_t n) {
    return std::all_of(p, p + n, [](std::byte b) { return b == std::byte{0}; });
}

/// The VmFlags line of the mapping of /proc/self/smaps that contains address p ("" if none).
std::string vmFlagsOf(const void* p) {
    std::ifstream smaps("/proc/self/smaps");
    const auto a = reinterpret_cast<uintptr_t>(p);
    std::string line;
    bool inside = false;
    while (std::getline(smaps, line)) {
        uintptr_t lo = 0, hi = 0;
        char dash = 0;
        std::istringstream head(line);
        if (head >> std::hex >> lo >> dash >> hi && dash == '-') {
            inside = a >= lo && a < hi;
            continue;
        }
        if (inside && line.rfind("VmFlags:", 0) == 0) return line;
    }
    return "";
}

}  // namespace

TEST(PageMemory, SmallBuffersAreZeroedAlignedAndFromTheHeap) {
    for (size_t bytes : {size_t(1), size_t(63), size_t(4096), PageMemory::kMapThreshold - 1}) {
        PageMemory m(bytes);
        ASSERT_FALSE(m.empty());
        EXPECT_FALSE(m.mapped()) << bytes;
        EXPECT_EQ(m.size(), bytes);
        EXPECT_EQ(reinterpret_cast<uintptr_t>(m.data()) % 64, 0u) << bytes;
        EXPECT_TRUE(allZero(m.data(), bytes)) << bytes;
        m.data()[bytes - 1] = std::byte{7};  // writable to the end
    }
}

TEST(PageMemory, LargeBuffersAreMappedOnHugePageBoundariesAndZeroed) {
    for (size_t bytes : {PageMemory::kMapThreshold, size_t(3824640) * 15 + 3}) {
        PageMemory m(bytes);
        ASSERT_EQ(m.mapped(), kLargeMapped) << bytes;
        EXPECT_GE(m.size(), bytes);
        EXPECT_EQ(reinterpret_cast<uintptr_t>(m.data()) % kLargeAlignment, 0u) << bytes;
        EXPECT_TRUE(allZero(m.data(), m.size())) << bytes;
        m.data()[0] = std::byte{1};
        m.data()[bytes - 1] = std::byte{2};
    }
}

TEST(PageMemory, LargeBuffersAreAdvisedAsHugePagesWhereTheKernelHasThem) {
    const bool kernelHasThem = kLargeMapped && std::filesystem::exists("/sys/kernel/mm/transparent_hugepage/enabled");
    PageMemory m(size_t(8) << 20);
    const std::string flags = vmFlagsOf(m.data());
    ASSERT_FALSE(flags.empty()) << "no mapping found for the buffer in /proc/self/smaps";
    // "hg": madvise(MADV_HUGEPAGE) is in effect on the mapping.
    EXPECT_EQ(flags.find(" hg") != std::string::npos, kernelHasThem) << flags;
}

TEST(PageMemory, TheAdviceCanBeTurnedAgainstHugePages) {
    if (!kLargeMapped || !std::filesystem::exists("/sys/kernel/mm/transparent_hugepage/enabled"))
        GTEST_SKIP() << "no transparent huge pages in this build or kernel";
    ASSERT_TRUE(PageMemory::hugePages());  // the default (LOOM_HUGE_PAGES unset)
    PageMemory::setHugePages(false);
    PageMemory off(size_t(8) << 20);
    PageMemory::setHugePages(true);
    PageMemory on(size_t(8) << 20);
    const std::string offFlags = vmFlagsOf(off.data()), onFlags = vmFlagsOf(on.data());
    EXPECT_NE(offFlags.find(" nh"), std::string::npos) << offFlags;  // MADV_NOHUGEPAGE
    EXPECT_EQ(offFlags.find(" hg"), std::string::npos) << offFlags;
    EXPECT_NE(onFlags.find(" hg"), std::string::npos) << onFlags;
}

TEST(PageMemory, MovesTransferOwnershipAndReleaseEmpties) {
    PageMemory a(size_t(4) << 20);
    std::byte* p = a.data();
    p[123] = std::byte{9};
    PageMemory b(std::move(a));
    EXPECT_TRUE(a.empty());  // NOLINT(bugprone-use-after-move): the moved-from state is specified
    EXPECT_EQ(a.size(), 0u);
    EXPECT_EQ(b.data(), p);
    EXPECT_EQ(b.data()[123], std::byte{9});
    PageMemory c(100);
    c = std::move(b);
    EXPECT_EQ(c.data(), p);
    EXPECT_EQ(c.mapped(), kLargeMapped);
    c.release();
    EXPECT_TRUE(c.empty());
    EXPECT_FALSE(c.mapped());
    EXPECT_TRUE(PageMemory(0).empty());
}

TEST(PageMemory, FrameSizedTexturesUseMappedMemoryAndStayZeroFilled) {
    Texture frame(1280, 720, Format::RGBA32F);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(frame.data()) % kLargeAlignment, 0u);
    EXPECT_TRUE(allZero(frame.data(), frame.byteSize()));
    Texture small(4, 4, Format::RGBA32F);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(small.data()) % kRowAlignment, 0u);
    EXPECT_TRUE(allZero(small.data(), small.byteSize()));
    // Moving a texture keeps its memory alive and in place.
    std::byte* p = frame.data();
    Texture moved(std::move(frame));
    EXPECT_EQ(moved.data(), p);
    moved.data()[moved.byteSize() - 1] = std::byte{1};
}
