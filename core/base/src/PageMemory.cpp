#include "loom/PageMemory.h"

#include <sys/mman.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string_view>
#include <utility>

#include "loom/Texture.h"  // alignUp

namespace loom {

namespace {

constexpr size_t kHeapAlignment = 64;
constexpr size_t kPageSize = 4096;
// Under AddressSanitizer every buffer comes from the heap, where overruns are caught.
#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAddressSanitizer = true;
#else
constexpr bool kAddressSanitizer = false;
#endif

std::atomic<bool>& hugePagesFlag() {
    static std::atomic<bool> flag{[] {
        const char* e = std::getenv("LOOM_HUGE_PAGES");
        return !(e && std::string_view(e) == "0");
    }()};
    return flag;
}

}  // namespace

PageMemory::PageMemory(size_t bytes) {
    if (bytes == 0) return;
    if (bytes < kMapThreshold || kAddressSanitizer) {
        mData = static_cast<std::byte*>(::operator new(bytes, std::align_val_t(kHeapAlignment)));
        std::memset(mData, 0, bytes);
        mSize = bytes;
        return;
    }
    // Map a huge page more than asked, keep the 2 MiB-aligned part: only whole aligned 2 MiB ranges can be huge pages.
    const size_t size = alignUp(bytes, kPageSize);
    const size_t reserve = size + kHugePageSize;
    void* p = mmap(nullptr, reserve, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    auto* begin = static_cast<std::byte*>(p);
    auto* aligned = reinterpret_cast<std::byte*>(alignUp(reinterpret_cast<uintptr_t>(begin), kHugePageSize));
    const size_t head = size_t(aligned - begin), tail = reserve - head - size;
    if (head) munmap(begin, head);
    if (tail) munmap(aligned + size, tail);
#if defined(MADV_HUGEPAGE) && defined(MADV_NOHUGEPAGE)
    // Advice: where the kernel has no transparent huge pages, nothing changes.
    madvise(aligned, size, hugePagesFlag().load() ? MADV_HUGEPAGE : MADV_NOHUGEPAGE);
#endif
    mData = aligned;
    mSize = size;
    mMapped = true;
}

PageMemory& PageMemory::operator=(PageMemory&& o) noexcept {
    if (this != &o) {
        release();
        mData = std::exchange(o.mData, nullptr);
        mSize = std::exchange(o.mSize, 0);
        mMapped = std::exchange(o.mMapped, false);
    }
    return *this;
}

void PageMemory::setHugePages(bool on) {
    hugePagesFlag().store(on);
}

bool PageMemory::hugePages() {
    return hugePagesFlag().load();
}

void PageMemory::release() {
    if (!mData) return;
    if (mMapped)
        munmap(mData, mSize);
    else
        ::operator delete(mData, std::align_val_t(kHeapAlignment));
    mData = nullptr;
    mSize = 0;
    mMapped = false;
}

}  // namespace loom
