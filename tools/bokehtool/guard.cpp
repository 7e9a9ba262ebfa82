// guard.cpp — see guard.h. The signal handlers use only async-signal-safe calls (write,
// unlink through bokeh::remove_partial_writes, signal, raise); the command name they print
// is kept in a fixed buffer for that reason.

#include "guard.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <iostream>

#include <OpenImageIO/strutil.h>

#include <bokeh/io.h>

namespace bokehtool {

namespace {

char g_command[128] = "bokehtool";
char g_frame[64]    = "";  // "frame 3, 3 of 5" in a sequence
// The watchdog's limit and start, and when the running command began (guard_progress).
using Clock = std::chrono::steady_clock;
std::atomic<double> g_timeout_s{ 0.0 };
std::atomic<int64_t> g_run_start_ns{ 0 }, g_command_start_ns{ 0 };
int64_t now_ns() { return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count(); }
int g_stderr = 2;  // the terminal's stderr, also while a StderrCapture holds fd 2

void write_text(const char* s) { (void)!write(g_stderr, s, std::strlen(s)); }

void stop_signal(int sig)
{
    bokeh::remove_partial_writes();
    signal(sig, SIG_DFL);
    raise(sig);
}

// The fault handler and its number writer: installed only without ASan (install_guards).
#if !defined(__SANITIZE_ADDRESS__)
void write_number(int n)
{
    char digits[16];
    int i = 15;
    digits[i] = 0;
    unsigned v = unsigned(n < 0 ? -n : n);
    do {
        digits[--i] = char('0' + v % 10);
        v /= 10;
    } while (v && i > 1);
    if (n < 0)
        digits[--i] = '-';
    write_text(digits + i);
}

void fault_signal(int sig)
{
    bokeh::remove_partial_writes();
    write_text("bokehtool ERROR: ");
    write_text(g_command);
    write_text(": internal fault (signal ");
    write_number(sig);
    write_text("); temporary output files removed\n");
    signal(sig, SIG_DFL);
    raise(sig);
}
#endif

void on_terminate()
{
    std::string why = "terminated by an uncaught exception";
    if (std::exception_ptr e = std::current_exception()) {
        try {
            std::rethrow_exception(e);
        } catch (const std::bad_alloc&) {
            why = "out of memory (std::bad_alloc)";
        } catch (const std::exception& ex) {
            why = std::string("failed with an exception: ") + ex.what();
        } catch (...) {
        }
    }
    why = "bokehtool ERROR: " + std::string(g_command) + ": " + why.substr(0, why.find('\n')) + "\n";
    bokeh::remove_partial_writes();
    write_text(why.c_str());
    std::_Exit(1);
}

}  // namespace

void set_guard_command(const std::string& name)
{
    const size_t n = std::min(name.size(), sizeof g_command - 1);
    std::memcpy(g_command, name.data(), n);
    g_command[n] = 0;
    g_command_start_ns = now_ns();
}

void guard_progress(float fraction)
{
    const double limit = g_timeout_s.load();
    if (!(limit > 0.0) || fraction < kPaceMinFraction || fraction >= 1.0f)
        return;
    const double in_command = 1e-9 * double(now_ns() - g_command_start_ns.load());
    if (in_command < kPaceMinSeconds)
        return;
    const double before = 1e-9 * double(g_command_start_ns.load() - g_run_start_ns.load());
    const double ends   = before + in_command / double(fraction);
    if (ends <= kPaceMargin * limit)
        return;
    bokeh::remove_partial_writes();
    write_text(OIIO::Strutil::fmt::format("bokehtool ERROR: --timeout: {} would end after about {:.0f} s at its pace "
                                          "({:.0f} % in {:.1f} s{}{}), past the limit of {:g} s; stopped now, "
                                          "temporary output files removed\n",
                                          g_command, ends, 100.0 * fraction, in_command, g_frame[0] ? ", " : "",
                                          g_frame, limit)
                   .c_str());
    std::_Exit(kTimeoutStatus);
}

void set_guard_frame(const std::string& frame)
{
    const size_t n = std::min(frame.size(), sizeof g_frame - 1);
    std::memcpy(g_frame, frame.data(), n);
    g_frame[n] = 0;
}

void install_guards()
{
    const int fd = dup(2);
    if (fd >= 0)
        g_stderr = fd;
    for (int sig : { SIGINT, SIGTERM, SIGHUP })
        signal(sig, stop_signal);
#if !defined(__SANITIZE_ADDRESS__)  // under ASan its own report says more
    for (int sig : { SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT })
        signal(sig, fault_signal);
#endif
    std::set_terminate(on_terminate);
}

StderrCapture::StderrCapture()
{
    std::fflush(stderr);
    std::cerr.flush();
    m_file = std::tmpfile();
    if (!m_file)
        return;
    m_saved = dup(2);
    if (m_saved < 0 || dup2(fileno(m_file), 2) < 0) {
        std::fclose(m_file);
        m_file = nullptr;
    }
}

std::string StderrCapture::finish()
{
    if (!m_file)
        return {};
    std::fflush(stderr);
    std::cerr.flush();
    dup2(m_saved, 2);
    close(m_saved);
    std::string text;
    std::rewind(m_file);
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof buf, m_file)) > 0 && text.size() < 65536;)
        text.append(buf, n);
    std::fclose(m_file);
    m_file = nullptr;
    return text;
}

StderrCapture::~StderrCapture() { finish(); }

Watchdog::Watchdog(double seconds)
{
    if (!(seconds > 0))
        return;
    g_run_start_ns = now_ns();
    g_timeout_s    = seconds;
    m_thread = std::thread([this, seconds] {
        std::unique_lock<std::mutex> lock(m_mutex);
        const auto limit = std::chrono::duration<double>(seconds);
        if (m_wake.wait_for(lock, limit, [this] { return m_stop; }))
            return;
        bokeh::remove_partial_writes();
        write_text(OIIO::Strutil::fmt::format("bokehtool ERROR: --timeout: still running after "
                                              "{:g} s (in {}{}{}); stopped, temporary output files "
                                              "removed\n",
                                              seconds, g_command, g_frame[0] ? ", " : "", g_frame)
                       .c_str());
        std::_Exit(kTimeoutStatus);
    });
}

Watchdog::~Watchdog()
{
    g_timeout_s = 0.0;
    if (!m_thread.joinable())
        return;
    {
        std::lock_guard<std::mutex> lock(m_mutex);
        m_stop = true;
    }
    m_wake.notify_all();
    m_thread.join();
}

}  // namespace bokehtool
