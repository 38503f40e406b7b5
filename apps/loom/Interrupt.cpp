#include "Interrupt.h"

#include <pthread.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>

#include "loom/PartialFiles.h"

namespace loom::cli {

namespace {

std::atomic<int> gStopSignal{0};
std::atomic<int> gStoppers{0};  ///< StopOnSignal objects alive

static_assert(std::atomic<int>::is_always_lock_free, "read and written in a signal handler");

void say(const char* text) {
    ssize_t ignored = ::write(STDERR_FILENO, text, std::strlen(text));
    (void)ignored;
}

// Only async-signal-safe calls here: atomics, write(2), unlink(2) (in removePartialFiles) and endBySignal's.
extern "C" void onSignal(int signal) {
    const int savedErrno = errno;
    int none = 0;
    if (gStoppers.load() > 0 && gStopSignal.compare_exchange_strong(none, signal)) {
        say("\nloom: ");
        say(signalName(signal));
        say(": stopping after the current frame (send it again to quit at once)\n");
        errno = savedErrno;
        return;
    }
    removePartialFiles();
    endBySignal(signal);
}

}  // namespace

void installSignalHandlers() {
    for (const int signal : {SIGINT, SIGTERM}) {
        struct sigaction old {};
        if (::sigaction(signal, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;  // e.g. nohup
        struct sigaction action {};
        action.sa_handler = onSignal;
        sigemptyset(&action.sa_mask);
        sigaddset(&action.sa_mask, SIGINT);  // one handler at a time
        sigaddset(&action.sa_mask, SIGTERM);
        action.sa_flags = SA_RESTART;  // reads and writes interrupted by the first signal go on
        ::sigaction(signal, &action, nullptr);
    }
}

void endBySignal(int signal) {
    struct sigaction action {};
    action.sa_handler = SIG_DFL;
    sigemptyset(&action.sa_mask);
    ::sigaction(signal, &action, nullptr);
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, signal);
    ::pthread_sigmask(SIG_UNBLOCK, &set, nullptr);  // blocked while its handler runs
    ::raise(signal);
    ::_exit(128 + signal);  // not reached: the default action of SIGINT and SIGTERM ends the process
}

StopOnSignal::StopOnSignal() {
    ++gStoppers;
}
StopOnSignal::~StopOnSignal() {
    --gStoppers;
}

int stopSignal() {
    return gStopSignal.load();
}

const char* signalName(int signal) {
    switch (signal) {
        case SIGINT:
            return "SIGINT";
        case SIGTERM:
            return "SIGTERM";
        default:
            return "signal";
    }
}

void throwIfStopRequested() {
    if (const int s = stopSignal()) throw Interrupted{s};
}

}  // namespace loom::cli
