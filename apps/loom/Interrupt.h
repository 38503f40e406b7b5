#pragma once
// SIGINT and SIGTERM. While a command that runs frames (render, bench, view) holds a StopOnSignal, the first signal
// only asks it to stop: it finishes the frame it is on, writes what it has, and the process ends by that signal.
// Otherwise, and on a second signal, the process removes its partial files (loom/PartialFiles.h) and ends by the
// signal at once. No half-written file is left either way. Ending by the signal itself (its default action, after
// the cleanup) rather than exit(128 + N) lets the parent see it: a shell still reports 128 + N (130, 143), and a
// script that runs loom stops on Ctrl-C as it would for any other command.

namespace loom::cli {

/// Installs the handlers of SIGINT and SIGTERM (a signal ignored when loom started stays ignored).
void installSignalHandlers();

/// While one lives, the first SIGINT or SIGTERM asks to stop (stopSignal()) instead of ending the process.
class StopOnSignal {
public:
    StopOnSignal();
    ~StopOnSignal();
    StopOnSignal(const StopOnSignal&) = delete;
    StopOnSignal& operator=(const StopOnSignal&) = delete;
};

/// The signal that asked to stop, 0 while none has.
int stopSignal();
inline bool stopRequested() {
    return stopSignal() != 0;
}
/// "SIGINT", "SIGTERM" (another signal: "signal").
const char* signalName(int signal);

/// Ends the process by `signal` with its default action (flush what must be flushed first). Async-signal-safe.
[[noreturn]] void endBySignal(int signal);

/// What a command throws when it stops on a signal with nothing more to write; main() ends by the signal.
struct Interrupted {
    int signal;
};
/// Throws Interrupted once a signal has asked to stop.
void throwIfStopRequested();

}  // namespace loom::cli
