// guard.h — process-wide guards of a bokehtool run on a farm node: no run ends in an
// abort without the one-line error, no run leaves its temporary output files behind when
// it is stopped, and no run outlives its --timeout.
#pragma once

#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

namespace bokehtool {

/// Install the handlers: SIGINT, SIGTERM, SIGHUP remove this run's temporary output files
/// and end the process by the same signal; SIGSEGV, SIGBUS, SIGFPE, SIGILL and SIGABRT
/// also print one line "bokehtool ERROR: <command>: internal fault (signal N)" first; an
/// uncaught exception (std::terminate) prints the one-line error and exits with status 1.
void install_guards();

/// The command named by the guards' messages (the one running now).
void set_guard_command(const std::string& name);
/// The frame of a sequence the --timeout message names ("frame 3, 3 of 5"; "" for none).
void set_guard_frame(const std::string& frame);

/// A command's progress (0..1) under a --timeout: once it is kPaceMinFraction done and has
/// run kPaceMinSeconds, its pace says when it would end; past kPaceMargin times the limit,
/// the run stops now as the watchdog would (one line naming the command and the estimate,
/// temporary files removed, kTimeoutStatus), instead of at the limit. A truth of millions of
/// rays a pixel is refused in seconds, not after the hours --timeout allows. The margin is
/// wide because a defocus's progress counts tiles weighted by their kernels, whose cost
/// varies by more than the truth's rows do.
void guard_progress(float fraction);
constexpr float kPaceMinFraction = 0.01f;
constexpr double kPaceMinSeconds = 2.0;
constexpr double kPaceMargin     = 1.5;

/// The exit status of a run stopped by --timeout: 124, as GNU timeout(1) gives, so that a
/// farm tells "too slow, retry elsewhere" from 1, "the command or an input is wrong".
constexpr int kTimeoutStatus = 124;

/// Messages that libraries print straight to stderr (libpng's "libpng error: ...") while
/// it lives are caught instead of shown, so that a failed read still ends in one line;
/// finish() returns them (the host shows them as a warning when the read succeeds).
/// The guards' own messages still reach the terminal.
class StderrCapture {
public:
    StderrCapture();
    ~StderrCapture();
    std::string finish();
    StderrCapture(const StderrCapture&) = delete;
    StderrCapture& operator=(const StderrCapture&) = delete;

private:
    int m_saved = -1;
    std::FILE* m_file = nullptr;
};

/// After `seconds` (> 0), print "bokehtool ERROR: --timeout: ..." naming the command
/// running and the frame, remove the temporary output files and exit with kTimeoutStatus. Stopped when
/// destroyed; 0 seconds = no watchdog.
class Watchdog {
public:
    explicit Watchdog(double seconds);
    ~Watchdog();
    Watchdog(const Watchdog&) = delete;
    Watchdog& operator=(const Watchdog&) = delete;

private:
    std::mutex m_mutex;
    std::condition_variable m_wake;
    bool m_stop = false;
    std::thread m_thread;
};

}  // namespace bokehtool
