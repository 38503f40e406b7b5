#pragma once
// Zero-filled memory for images and other large buffers.
//
// An image row of 1280 RGBA32F pixels is 20 KiB: with 4 KiB pages every row of every image a kernel touches is
// a page of its own, and a filter that reads five rows of ten planes around each pixel (the a-trous levels), or
// twenty images at once (SVGF's temporal stage), keeps missing the TLB. Large buffers are therefore mapped
// 2 MiB-aligned and advised as transparent huge pages (madvise(MADV_HUGEPAGE)), which the kernel honours when
// transparent huge pages are set to "madvise" or "always" and ignores otherwise. The memory is zero-filled (lazily,
// on first touch, for mapped buffers). Under AddressSanitizer all buffers come from the heap, where it catches
// overruns.
#include <cstddef>

namespace loom {

class PageMemory {
public:
    /// Buffers from this size on are mapped and advised as huge pages (except under AddressSanitizer); smaller ones
    /// come from the heap.
    static constexpr size_t kMapThreshold = size_t(1) << 20;
    /// Alignment of every buffer's start: a cache line for heap buffers, 2 MiB for mapped ones.
    static constexpr size_t kHugePageSize = size_t(2) << 20;

    PageMemory() = default;
    /// bytes of zero-filled memory, at least 64-byte aligned; throws std::bad_alloc when none is available.
    explicit PageMemory(size_t bytes);
    ~PageMemory() { release(); }
    PageMemory(const PageMemory&) = delete;
    PageMemory& operator=(const PageMemory&) = delete;
    PageMemory(PageMemory&& o) noexcept { *this = static_cast<PageMemory&&>(o); }
    PageMemory& operator=(PageMemory&& o) noexcept;

    std::byte* data() const { return mData; }
    size_t size() const { return mSize; }
    bool empty() const { return mData == nullptr; }
    /// Whether the buffer is mapped (and advised as huge pages) rather than from the heap.
    bool mapped() const { return mMapped; }
    /// Frees the memory; the buffer becomes empty.
    void release();

    /// Whether buffers mapped from now on are advised as huge pages (MADV_HUGEPAGE) or advised against them
    /// (MADV_NOHUGEPAGE, also where the system's setting is "always"). On by default; the environment variable
    /// LOOM_HUGE_PAGES=0 turns it off. For measuring what huge pages buy, and for systems where they hurt.
    static void setHugePages(bool on);
    static bool hugePages();

private:
    std::byte* mData = nullptr;
    size_t mSize = 0;
    bool mMapped = false;
};

}  // namespace loom
