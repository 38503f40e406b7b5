#include "loom/PartialFiles.h"

#include <spdlog/spdlog.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <climits>
#include <cstring>

#include "loom/Error.h"

namespace loom {

namespace {

// A slot's life: Free -> Claimed (its owner fills the path) -> Creating (the path is complete; the file may appear
// at any moment) -> Live (the file exists, or its creation failed) -> Free (renamed or removed by its owner).
enum SlotState : int { Free, Claimed, Creating, Live };

struct Slot {
    std::atomic<int> state{Free};
    std::atomic<unsigned> generation{0};  ///< claims so far: a copy of the path read while it held still is whole
    std::atomic<long> owner{0};           ///< the owning thread's id while claimed, else 0
    char path[PATH_MAX];
};

// A write registers one file, a video another: a few slots serve every command; more only if writes overlap.
constexpr size_t kSlots = 32;
std::array<Slot, kSlots> gSlots;
std::atomic<bool> gEnding{false};  ///< removePartialFiles() has begun

static_assert(std::atomic<int>::is_always_lock_free && std::atomic<unsigned>::is_always_lock_free &&
                  std::atomic<long>::is_always_lock_free && std::atomic<bool>::is_always_lock_free,
              "the registry is read from a signal handler: its atomics must be lock-free");

/// The calling thread's kernel id: gettid(2) is a plain system call, safe in a signal handler.
long threadId() noexcept {
    return long(::syscall(SYS_gettid));
}

double seconds() noexcept {
    timespec t{};
    ::clock_gettime(CLOCK_MONOTONIC, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

void release(Slot& s) noexcept {
    s.owner.store(0);
    s.state.store(Free);
}

}  // namespace

void awaitEndIfEnding() {
    for (int i = 0; i < 500 && gEnding.load(); ++i) ::usleep(10000);
}

namespace {

/// A file registered after removePartialFiles() began is not created: the signal handler that called it is about to
/// end the process.
[[noreturn]] void refuse(const std::string& path) {
    awaitEndIfEnding();
    throw Error(Error::Info{ErrorKind::Runtime, path, "", "the process is ending on a signal", "", ""});
}

}  // namespace

PartialFile::PartialFile(const std::string& path) {
    if (gEnding.load()) refuse(path);
    if (path.size() >= PATH_MAX) {
        spdlog::debug("{}: path too long to register as a partial file", path);
        return;
    }
    for (size_t i = 0; i < kSlots; ++i) {
        Slot& s = gSlots[i];
        int expected = Free;
        if (!s.state.compare_exchange_strong(expected, Claimed)) continue;
        s.generation.fetch_add(1);
        s.owner.store(threadId());
        std::memcpy(s.path, path.c_str(), path.size() + 1);
        s.state.store(Creating);
        // Sequentially consistent with removePartialFiles(), which sets gEnding and then reads the states: either it
        // sees this slot Creating (and removes the file), or this sees gEnding and the file is never created.
        if (gEnding.load()) {
            release(s);
            refuse(path);
        }
        mSlot = int(i);
        return;
    }
    spdlog::debug("{}: every partial-file slot is taken; the file is not registered", path);
}

void PartialFile::created() {
    if (mSlot >= 0) gSlots[size_t(mSlot)].state.store(Live);
}

PartialFile::~PartialFile() {
    if (mSlot >= 0) release(gSlots[size_t(mSlot)]);
}

void removePartialFiles() noexcept {
    gEnding.store(true);
    const long self = threadId();
    const double deadline = seconds() + 1.0;
    char path[PATH_MAX];
    for (Slot& s : gSlots) {
        // A slot freed and claimed again while its path is copied is read again: its owner saw gEnding by then, so
        // this ends within a few rounds.
        for (int round = 0; round < 8; ++round) {
            const unsigned generation = s.generation.load();
            int state = s.state.load();
            // Another thread between claiming the slot and creating its file finishes that step (the thread this
            // runs on cannot be waited for: it is the one interrupted).
            while ((state == Claimed || state == Creating) && s.owner.load() != self && seconds() < deadline)
                state = s.state.load();
            if (state != Creating && state != Live) break;
            std::memcpy(path, s.path, sizeof path);
            path[sizeof path - 1] = '\0';
            std::atomic_thread_fence(std::memory_order_acquire);
            if (s.generation.load() != generation) continue;
            ::unlink(path);
            break;
        }
    }
}

int partialFileCount() noexcept {
    int n = 0;
    for (const Slot& s : gSlots) n += s.state.load() != Free;
    return n;
}

}  // namespace loom
