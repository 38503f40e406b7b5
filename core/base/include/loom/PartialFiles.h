#pragma once
// The temporary files outputs are written to before they take their names (an atomic write's hidden
// ".<name>.<pid>.<n>.partial", a video's FILE.partial). Each is registered while it may exist, so a process that must
// end at once (on a second Ctrl-C) removes them from its signal handler: removePartialFiles() is async-signal-safe.
// The registry is a fixed array of slots claimed with atomics: no lock, no allocation, any thread.
#include <string>

namespace loom {

/// One partial file registered for the lifetime of the object. Construct it before the file is created and call
/// created() once it is; rename or remove the file before the object dies. Not copyable: it owns its slot.
class PartialFile {
public:
    /// Registers `path`. Once removePartialFiles() has begun, the process is ending and the file must not be created
    /// behind its back: this waits for the end (and throws loom::Error, Runtime, if it has not come in 5 s). A path
    /// longer than a slot holds, or a registry whose slots are all taken, leaves the file unregistered (said at debug
    /// level): it is written as before, only not removed by removePartialFiles().
    explicit PartialFile(const std::string& path);
    ~PartialFile();
    PartialFile(const PartialFile&) = delete;
    PartialFile& operator=(const PartialFile&) = delete;

    /// The file exists now (its creation returned, successfully or not).
    void created();

private:
    int mSlot = -1;
};

/// Removes every registered partial file and refuses new registrations from then on. Async-signal-safe (atomics,
/// unlink(2), clock_gettime(2), gettid(2)); meant for a signal handler just before _exit(2). A file another thread
/// is about to create is waited for (up to a second) so that it is not created after the removal.
void removePartialFiles() noexcept;

/// When removePartialFiles() has begun (a signal handler on another thread is ending the process), waits for the end
/// (5 s at most), so that what failed because its partial file vanished is not reported as an error, nor the process
/// ended another way. Returns at once otherwise.
void awaitEndIfEnding();

/// Registered partial files (for tests).
int partialFileCount() noexcept;

}  // namespace loom
