// bokehtool on a farm node: the memory budget (--maxmemory), running out of memory,
// --timeout, SIGTERM during a write, and temporary files left by a killed run.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <chrono>
#include <cstring>
#include <fstream>
#include <thread>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

std::string small_exr(const std::string& dir)
{
    OIIO::ImageBuf img = rgbaz_image(64, 48, [](int x, int y) {
        return std::array<float, 5>{ x / 64.0f, y / 48.0f, 0.5f, 1.0f, 3.0f };
    });
    const std::string path = dir + "/in.exr";
    img.specmod().attribute("compression", "zip");
    EXPECT_TRUE(img.write(path));
    return path;
}

std::vector<std::string> files_in(const std::string& dir)
{
    std::vector<std::string> files;
    OIIO::Filesystem::get_directory_entries(dir, files);
    for (std::string& f : files)
        f = OIIO::Filesystem::filename(f);
    std::sort(files.begin(), files.end());
    return files;
}

// This machine's name as the temporary files spell it (up to the first dot; other than
// letters, digits, '-' and '_' become '_').
std::string host_name()
{
    char buf[256] = {};
    gethostname(buf, sizeof buf - 1);
    std::string h(buf);
    h = h.substr(0, h.find('.'));
    for (char& c : h)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_')
            c = '_';
    return h.empty() ? "host" : h;
}

}  // namespace

TEST(Robust, MaxMemoryRefusesAFileByName)
{
    const std::string dir = fresh_dir("robust_maxmemory");
    const std::string in = small_exr(dir), out = dir + "/out.exr";
    // 64 x 48 x 5 channels x 4 bytes = 61440, plus 3 chunk offsets of 8 bytes (ZIP: 16
    // lines a chunk), plus 3 rows of chunks as stored (16 x 64 x 5 floats = 20480 bytes):
    // 122904 bytes = 120.0 KiB.
    RunResult r = bokehtool(format("--maxmemory 119K {} -o {}", in, out));
    expect_clean_failure(r, "in.exr: reading it needs 120.0 KiB (64 x 48, 5 channels), more "
                            "than --maxmemory of 119.0 KiB", out);
    r = bokehtool(format("--maxmemory 121K {} -o {}", in, out));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(exists(out));
    for (const char* bad : { "4X", "0", "-1", "K", "1.5Q" }) {
        r = bokehtool(format("--maxmemory {} {} -o {}/bad.exr", bad, in, dir));
        expect_clean_failure(r, format("--maxmemory: '{}' is not a memory size", bad), dir + "/bad.exr");
    }
    r = bokehtool(format("--maxmemory 0.5GiB {} -o {}/ok.exr", in, dir));
    EXPECT_EQ(r.status, 0) << r.err;
}

// Sizes a user types are held to the same budget before anything is allocated: a scene
// larger than the machine (32768 x 32768 grew to 20 GB and was killed by the kernel), a
// resize or enlarge target, each refused in one line naming the size, the estimate and
// the budget; what fits still runs.
TEST(Robust, TypedSizesAreCheckedBeforeMemoryIsTaken)
{
    const std::string dir = fresh_dir("robust_typed_sizes"), out = dir + "/out.exr";
    const auto t0 = std::chrono::steady_clock::now();
    RunResult r   = bokehtool("--scene lights:width=32768:height=32768 -o " + out);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    expect_clean_failure(r, "--scene: a 32768x32768 sharp scene would take 40.0 GiB, over the memory budget of ", out);
    EXPECT_NE(r.err.find("(--maxmemory raises it)"), std::string::npos) << r.err;
    EXPECT_LT(seconds, 10.0) << "refused at once, not after trying";
    // 1000 x 1000 at 40 bytes a pixel: 38.1 MiB.
    r = bokehtool("--maxmemory 38M --scene lights:width=1000:height=1000 -o " + out);
    expect_clean_failure(r, "a 1000x1000 sharp scene would take 38.1 MiB, over the memory budget of 38.0 MiB", out);
    r = bokehtool(format("--maxmemory 39M --scene lights:width=1000:height=1000:aa=1 -o {}/fits.exr", dir));
    EXPECT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("--maxmemory 100M --scene lights:width=64:height=64:output=deep -o {}/deep.exr", dir));
    EXPECT_EQ(r.status, 0) << r.err;
    r = bokehtool("--maxmemory 1M --scene lights:width=200:height=200:output=deep -o " + out);
    expect_clean_failure(r, "a 200x200 deep scene would take", out);
    // Resize and enlarge targets: 100000 x 100000 x 5 floats is 186.3 GiB.
    const std::string small = "--scene lights:width=64:height=36:aa=1 ";
    r = bokehtool(small + "--resize 100000x100000 -o " + out);
    expect_clean_failure(r, "--resize: a 100000x100000 result of 5 channels would take 186.3 GiB", out);
    r = bokehtool(small + "--enlarge 4000 -o " + out);
    expect_clean_failure(r, "--enlarge: a 256000x144000 result of 5 channels would take", out);
    r = bokehtool(small + "--resample 70000x70000 -o " + out);
    expect_clean_failure(r, "--resample: a 70000x70000 result of 5 channels would take", out);
    r = bokehtool(small + "--resize 128x72 -o " + dir + "/resized.exr");
    EXPECT_EQ(r.status, 0) << r.err;
    // --bokeh: a sheet of 64 x 64 cells of 2049 px is 131136 px square, 24 bytes a pixel
    // (384.6 GiB); a PSF its size (or its CoC's extent), the same rate.
    r = bokehtool("--bokeh:sheet=1:columns=64:rows=64:size=2048 100 -o " + out);
    expect_clean_failure(r, "--bokeh: a 131136x131136 sheet of PSFs would take 384.", out);
    r = bokehtool("--maxmemory 1M --bokeh:size=301 100 -o " + out);
    expect_clean_failure(r, "--bokeh: a 301x301 PSF would take 2.1 MiB, over the memory budget of 1.0 MiB", out);
    r = bokehtool("--maxmemory 1M --bokeh 200 -o " + out);
    expect_clean_failure(r, "--bokeh: a 416x416 PSF would take", out);
    r = bokehtool(format("--maxmemory 1M --bokeh 60 -o {}/psf.exr", dir));
    EXPECT_EQ(r.status, 0) << r.err;
    // A deep merge: its inputs fit (3.05 MiB each), the pooled and tidied samples do not.
    const std::string two_deep = "--scene lights:width=200:height=100:output=deep "
                                 "--scene lights:width=200:height=100:output=deep:seed=2 ";
    r = bokehtool("--maxmemory 3.5M " + two_deep + "--deepmerge -o " + out);
    expect_clean_failure(r, "--deepmerge: a merge of 49092 deep samples of 5 channels would take 4.0 MiB, over the "
                            "memory budget of 3.5 MiB", out);
    r = bokehtool(format("--maxmemory 5M {}--deepmerge -o {}/merged.exr", two_deep, dir));
    EXPECT_EQ(r.status, 0) << r.err;
    // A defocus: a flat frame's working planes (26 bytes a source pixel, 32 an output pixel:
    // 1920 x 1080 x 58 is 114.7 MiB); a deep frame's layers, 20 bytes a pixel a layer, as
    // many as layers= asks for.
    // Past the budget a flat frame is drawn in bands of rows; the gather method blurs copies
    // of the whole frame, so it cannot be.
    const std::string flat = "--maxmemory 100M --scene lights:width=1920:height=1080:aa=1 ";
    r = bokehtool(flat + "--defocus:method=gather -o " + out);
    expect_clean_failure(r, "--defocus: the defocus of 1920x1080 pixels into 1920x1080 would take 114.7 MiB, over "
                            "the memory budget of 100.0 MiB (--maxmemory raises it; the gather method blurs copies "
                            "of the whole frame and is not drawn in bands)", out);
    r = bokehtool(format("-v {}--defocus -o {}/banded.exr", flat, dir));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("output 1920x1080, in 2 bands of "), std::string::npos) << r.out;
    // A deep result holds them all: refused. A flat one is drawn in groups of layers that fit.
    const std::string deep = "--maxmemory 64M --scene lights:width=480:height=270:aa=1 --deepen ";
    r = bokehtool(deep + "--defocus:layers=400:output=deep -o " + out);
    expect_clean_failure(r, "layers of 480x270 deep pixels and their deep result would take", out);
    EXPECT_NE(r.err.find("over the memory budget of 64.0 MiB (--maxmemory raises it; fewer layers need less)"),
              std::string::npos) << r.err;
    r = bokehtool(format("-v {}--defocus:layers=400 -o {}/deep_defocus.exr", deep, dir));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("at a time: the memory budget)"), std::string::npos) << r.out;
}

TEST(Robust, DeepFileRefusedOnItsSampleCount)
{
    const std::string deep = shared_data("gaffer/representativeDeepImage.exr");
    REQUIRE_SHARED(deep);
    const std::string dir = fresh_dir("robust_deep_budget"), out = dir + "/out.exr";
    // 150 x 100 pixels x (16 + 8 x 6) bytes = 960000 bytes: under 1M, so the samples
    // (191482 of 4 half + 2 float channels = 16 bytes) are counted and pass it.
    const RunResult r = bokehtool(format("--maxmemory 1M {} -o {}", deep, out));
    expect_clean_failure(r, "(150 x 100, 6 channels, deep, more than ", out);
    EXPECT_NE(r.err.find("samples), more than --maxmemory of 1.0 MiB"), std::string::npos) << r.err;
    EXPECT_EQ(bokehtool(format("--maxmemory 5M {} -o {}", deep, out)).status, 0);
}

TEST(Robust, OutOfMemoryIsTheOneLineError)
{
#if defined(__SANITIZE_ADDRESS__)
    GTEST_SKIP() << "under ASan (it reserves terabytes of address space, so ulimit -v cannot be used)";
#endif
    const std::string dir = fresh_dir("robust_oom"), out = dir + "/out.exr";
    // 1.5 GB of address space: the 8 GB frame cannot be allocated (a budget above it lets
    // the allocation be tried: the failure past the budget's estimate is this one line too).
    RunResult r = bokehtool(format("--maxmemory 64G --scene lights:width=20000:height=20000 -o {}", out),
                            "ulimit -v 1500000;");
    expect_clean_failure(r, "--scene: out of memory (std::bad_alloc)", out);
    r = bokehtool(format("--scene lights:width=6000:height=6000:aa=1 --blur 5x5 -o {}", out),
                  "ulimit -v 1500000;");
    expect_clean_failure(r, "out of memory (std::bad_alloc)", out);
    EXPECT_TRUE(files_in(dir).empty());
}

TEST(Robust, TimeoutStopsTheRunCleanly)
{
    const std::string dir = fresh_dir("robust_timeout"), out = dir + "/out.exr";
    // The run whole (about 1.7 s on one core of the project's machine), then stopped at
    // 0.3 s: "stopped near its limit" is judged against the whole run measured here, so a
    // loaded machine slows both alike.
    const std::string line = "--threads 1 --scene lights:width=2000:height=1000:aa=1 --defocus -o ";
    const auto tw       = std::chrono::steady_clock::now();
    RunResult whole     = bokehtool(line + dir + "/whole.exr");
    const double full_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - tw).count();
    ASSERT_EQ(whole.status, 0) << whole.err;
    OIIO::Filesystem::remove(dir + "/whole.exr");
    const auto t0 = std::chrono::steady_clock::now();
    RunResult r   = bokehtool("--timeout 0.3 " + line + out);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // Its own exit status (GNU timeout's 124), one line, nothing written.
    EXPECT_EQ(r.status, 124) << r.err;
    EXPECT_TRUE(OIIO::Strutil::starts_with(r.err, "bokehtool ERROR: --timeout: still running after 0.3 s (in --"))
        << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_LT(seconds, 0.6 * full_s) << "stopped near its limit (the whole run took " << full_s << " s)";
    EXPECT_TRUE(files_in(dir).empty());
    // In a sequence the line names the frame it stopped in.
    r = bokehtool(format("--threads 1 --timeout 0.3 --frames 1-3 --scene lights:width=2000:height=1000:aa=1 "
                         "--defocus -o {}/seq.#.exr",
                         dir));
    EXPECT_EQ(r.status, 124) << r.err;
    EXPECT_NE(r.err.find(", frame 1, 1 of 3); stopped"), std::string::npos) << r.err;
    EXPECT_TRUE(files_in(dir).empty());
    for (const char* bad : { "0", "-2", "abc", "nan" }) {
        r = bokehtool(format("--timeout {} --scene lights:width=8:height=8 -o {}", bad, out));
        expect_clean_failure(r, format("--timeout: '{}' is not a time in seconds", bad), out);
    }
    r = bokehtool(format("--timeout 60 --scene lights:width=8:height=8 -o {}", out));
    EXPECT_EQ(r.status, 0) << r.err;
}

TEST(Robust, TimeoutStopsEarlyWhenTheCommandsPaceCannotMeetIt)
{
    // A scene truth of 300000 rays a pixel would run about 90 s here; under --timeout 30 its
    // pace stops it within seconds (not at the limit), naming the estimate.
    const std::string dir = fresh_dir("robust_pace"), out = dir + "/truth.exr";
    const auto t0 = std::chrono::steady_clock::now();
    const RunResult r = bokehtool(format("--timeout 30 --scene lights:width=48:height=48:output=truth:spp=300000 -o {}", out));
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(r.status, 124) << r.err;
    EXPECT_NE(r.err.find("bokehtool ERROR: --timeout: --scene would end after about"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("past the limit of 30 s; stopped now"), std::string::npos) << r.err;
    EXPECT_LT(seconds, 30.0) << "stopped by its pace, before the limit";
    EXPECT_FALSE(OIIO::Filesystem::exists(out));
    // A command whose pace meets the limit runs to the end.
    const RunResult ok = bokehtool(format("--timeout 60 --scene lights:width=48:height=24:output=truth:spp=256 -o {}", out));
    EXPECT_EQ(ok.status, 0) << ok.err;
}

TEST(Robust, ATruthThatCannotMeetTheTimeoutIsRefusedAtOnce)
{
    // 1920 x 1080 pixels at 1048576 rays a pixel is 2.2e12 rays: at 25 ns a ray a thread (a
    // fifth of the fastest measured) at least 7.5 h on 2 threads, refused before the first
    // ray, exit 1, nothing written; the defocus truth of a deep frame likewise.
    const std::string dir = fresh_dir("robust_truth_time"), out = dir + "/truth.exr";
    const auto t0 = std::chrono::steady_clock::now();
    RunResult r   = bokehtool("--threads 2 --timeout 5 --scene lights:width=1920:height=1080:output=truth:spp=1048576 -o " + out);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    expect_clean_failure(r, "--scene: a 1920x1080 truth at 1048576 rays a pixel is 2.2e+12 rays: at least 7.5 h on 2 "
                            "threads, past --timeout 5 s", out);
    EXPECT_LT(seconds, 3.0) << "refused at once";
    r = bokehtool("--threads 2 --timeout 10 --scene lights:width=480:height=270:output=deep "
                  "--defocus:method=truth:spp=1048576 -o " + out);
    expect_clean_failure(r, "--defocus: a truth of 480x270 pixels at 1048576 rays a pixel is 1.4e+11 rays: at least 28 "
                            "min on 2 threads, past --timeout 10 s", out);
    // Without --timeout nothing is refused for time (the same command, fewer rays, runs).
    r = bokehtool(format("--threads 2 --scene lights:width=48:height=27:output=truth:spp=64 -o {}/small.exr", dir));
    EXPECT_EQ(r.status, 0) << r.err;
}

TEST(Robust, SigtermDuringAWriteRemovesItsTemporaryFile)
{
    const std::string dir = fresh_dir("robust_sigterm"), out = dir + "/big.exr";
    const std::string scene = "lights:width=2000:height=1500:aa=1";
    const pid_t pid = fork();
    if (pid == 0) {
        const int n = open("/dev/null", O_RDWR);
        dup2(n, 0), dup2(n, 1), dup2(n, 2);
        execl(BOKEHTOOL, BOKEHTOOL, "--scene", scene.c_str(), "-o", out.c_str(),
              static_cast<char*>(nullptr));
        _exit(127);
    }
    // Wait for the temporary file to appear, then stop the run.
    bool seen     = false;
    const auto t0 = std::chrono::steady_clock::now();
    while (!seen && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(30)) {
        for (const std::string& f : files_in(dir))
            seen = seen || f.find(".openbokeh-partial.") != std::string::npos;
        if (!seen)
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    kill(pid, SIGTERM);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(seen) << "the write's temporary file never appeared";
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << "ends by the signal";
    EXPECT_TRUE(files_in(dir).empty()) << "left: " << OIIO::Strutil::join(files_in(dir), " ");
}

TEST(Robust, StaleTemporaryFilesOfDeadRunsAreRemoved)
{
    const std::string dir = fresh_dir("robust_stale");
    const std::string in = small_exr(dir), out = dir + "/out.exr";
    // A pid that no longer runs: a child that has ended and been reaped.
    const pid_t dead = fork();
    if (dead == 0)
        _exit(0);
    waitpid(dead, nullptr, 0);
    const std::string host = host_name();
    const std::string stale = format(".out.exr.openbokeh-partial.{}.{}.exr", host, dead);
    const std::string alive = format(".out.exr.openbokeh-partial.{}.{}.exr", host, getpid());
    const std::string other_host = format(".out.exr.openbokeh-partial.{}x.{}.exr", host, dead);
    const std::string other_file = format(".other.exr.openbokeh-partial.{}.{}.exr", host, dead);
    for (const std::string& f : { stale, alive, other_host, other_file })
        std::ofstream(dir + "/" + f) << "partial";
    const RunResult r = bokehtool(format("{} -o {}", in, out));
    ASSERT_EQ(r.status, 0) << r.err;
    const std::vector<std::string> left = files_in(dir);
    auto has = [&](const std::string& f) { return std::find(left.begin(), left.end(), f) != left.end(); };
    EXPECT_FALSE(has(stale)) << "a dead run's temporary file for this target is removed";
    EXPECT_TRUE(has(alive)) << "a running process's is kept";
    EXPECT_TRUE(has(other_host)) << "another host's is kept (its process may run)";
    EXPECT_TRUE(has(other_file)) << "another target's is kept";
    EXPECT_TRUE(has("out.exr"));
}

namespace {

// Every value of every channel of two images the same, bit for bit (and the same windows
// and channel names).
bool same_pixels(const std::string& a_path, const std::string& b_path, std::string& why)
{
    OIIO::ImageBuf a(a_path), b(b_path);
    if (!a.read(0, 0, true, OIIO::TypeFloat) || !b.read(0, 0, true, OIIO::TypeFloat)) {
        why = a.geterror() + b.geterror();
        return false;
    }
    if (a.roi() != b.roi() || a.spec().channelnames != b.spec().channelnames) {
        why = "windows or channels differ";
        return false;
    }
    for (OIIO::ImageBuf::ConstIterator<float> p(a), q(b); !p.done(); ++p, ++q)
        for (int c = 0; c < a.nchannels(); ++c) {
            const float u = p[c], v = q[c];
            uint32_t ub, vb;
            std::memcpy(&ub, &u, 4);
            std::memcpy(&vb, &v, 4);
            if (ub != vb) {
                why = format("pixel ({}, {}) channel {}: {} against {}", p.x(), p.y(), c, u, v);
                return false;
            }
        }
    return true;
}

// Start bokehtool with `args` (split on spaces) in the background, its output to /dev/null.
pid_t start_bokehtool(const std::string& args)
{
    std::vector<std::string> words;
    OIIO::Strutil::split(args, words, " ");
    const pid_t pid = fork();
    if (pid == 0) {
        const int n = open("/dev/null", O_RDWR);
        dup2(n, 0), dup2(n, 1), dup2(n, 2);
        std::vector<char*> argv{ const_cast<char*>(BOKEHTOOL) };
        for (std::string& w : words)
            argv.push_back(w.data());
        argv.push_back(nullptr);
        execv(BOKEHTOOL, argv.data());
        _exit(127);
    }
    return pid;
}

}  // namespace

TEST(Robust, SequenceKilledMidFrameResumesToTheSameFrames)
{
    // Six frames; the run is killed (SIGKILL: no handler runs) while frame 3 is being
    // written, then run again with -u. The frames must be those of a run never stopped,
    // and no temporary file may be left.
    const std::string dir = fresh_dir("robust_killed_sequence");
    for (int i = 1; i <= 6; ++i)
        ASSERT_EQ(bokehtool(format("--scene lights:width=1200:height=700:aa=1:seed={} -o {}/in.{:04d}.exr", i, dir, i))
                      .status,
                  0);
    const std::string job = format("--frames 1-6 {}/in.#.exr --defocus:focus=6:fstop=1.27", dir);
    ASSERT_EQ(bokehtool(format("{} -o {}/ref.#.exr", job, dir)).status, 0);

    const pid_t pid = start_bokehtool(format("{} -o {}/out.#.exr", job, dir));
    bool mid_frame  = false;
    const auto t0   = std::chrono::steady_clock::now();
    while (!mid_frame && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60)) {
        for (const std::string& f : files_in(dir))
            mid_frame = mid_frame || f.find(".out.0003.exr.openbokeh-partial.") == 0;
        if (!mid_frame)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    ASSERT_TRUE(mid_frame) << "frame 3's temporary file never appeared";
    EXPECT_TRUE(OIIO::Filesystem::exists(dir + "/out.0002.exr"));
    EXPECT_FALSE(OIIO::Filesystem::exists(dir + "/out.0003.exr")) << "an unfinished frame is never in place";

    const RunResult r = bokehtool(format("-u {} -o {}/out.#.exr", job, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    for (int i = 1; i <= 6; ++i) {
        std::string why;
        EXPECT_TRUE(same_pixels(format("{}/ref.{:04d}.exr", dir, i), format("{}/out.{:04d}.exr", dir, i), why))
            << "frame " << i << ": " << why;
    }
    for (const std::string& f : files_in(dir))
        EXPECT_EQ(f.find("openbokeh-partial"), std::string::npos) << "left behind: " << f;
}

TEST(Robust, TwoWritersOfOnePathLeaveOneCompleteFile)
{
    // Two runs write different images to the same path at the same time, three times over:
    // the path ends up holding one of the two images whole, never a mix or a torn file.
    const std::string dir = fresh_dir("robust_two_writers");
    const std::string a = "--scene lights:width=1600:height=900:aa=1:seed=1";
    const std::string b = "--scene lights:width=1600:height=900:aa=1:seed=2";
    ASSERT_EQ(bokehtool(format("{} -o {}/a.exr", a, dir)).status, 0);
    ASSERT_EQ(bokehtool(format("{} -o {}/b.exr", b, dir)).status, 0);
    for (int round = 0; round < 3; ++round) {
        const pid_t pa = start_bokehtool(format("{} -o {}/same.exr", a, dir));
        const pid_t pb = start_bokehtool(format("{} -o {}/same.exr", b, dir));
        int sa = 0, sb = 0;
        waitpid(pa, &sa, 0);
        waitpid(pb, &sb, 0);
        EXPECT_TRUE(WIFEXITED(sa) && WEXITSTATUS(sa) == 0);
        EXPECT_TRUE(WIFEXITED(sb) && WEXITSTATUS(sb) == 0);
        std::string why_a, why_b;
        EXPECT_TRUE(same_pixels(dir + "/same.exr", dir + "/a.exr", why_a)
                    || same_pixels(dir + "/same.exr", dir + "/b.exr", why_b))
            << "round " << round << ": neither whole image: " << why_a << "; " << why_b;
        for (const std::string& f : files_in(dir))
            EXPECT_EQ(f.find("openbokeh-partial"), std::string::npos) << "left behind: " << f;
    }
}
