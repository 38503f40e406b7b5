#pragma once
// SIGINT and SIGTERM. While a command that runs frames (render, bench, view) holds a StopOnSignal, the first signal
// only asks it to stop: it finishes the frame it is on, writes what it has and exits with 128 + the signal's number.
// Otherwise, and on a second signal, the process removes its partial files (loom/PartialFiles.h) and exits at once,
// with the same code. No half-written file is left either way.

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

/// What a command throws when it stops on a signal with nothing more to write; main() exits with 128 + signal.
struct Interrupted {
    int signal;
};
/// Throws Interrupted once a signal has asked to stop.
void throwIfStopRequested();

}  // namespace loom::cli
