// host.h — bokehtool's host: the image stack, the built-in (global and I/O) commands,
// plugin loading, and the two-pass run of a command line.
//
// Pass 1 checks the whole command line before any pixel is touched: unknown commands,
// missing arguments, bad options, too few images on the stack; and applies the global
// options. Pass 2 runs it. Outputs (-o) are written only after every command of the
// frame has succeeded, each through a temporary file renamed into place, so a failing
// command line writes nothing.
#pragma once

#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <bokeh/color.h>
#include <bokeh/image.h>
#include <bokeh/io.h>
#include <bokeh/plugin.h>

namespace OIIO_NAMESPACE {
class ArgParse;
}

namespace bokehtool {

struct FramePlan;

class Host {
public:
    Host();
    /// Run the program on the arguments after its name; returns the exit status.
    int main(const std::vector<std::string>& args);

    /// Pass 1 alone, as main() runs it before touching a pixel: load the plugins, plan the
    /// frames, check the first frame's command line (commands, arguments, options, stack
    /// depths) and take its global options. Nothing is read, run or written. False after
    /// the one-line error on stderr. The command-line fuzz target
    /// (tests/fuzz/fuzz_command_line.cpp) drives the parser through this.
    bool check_only(const std::vector<std::string>& args);

private:
    struct PendingWrite {
        bokeh::StackImage image;
        std::string path;
        std::map<std::string, OIIO::TypeDesc> datatypes;  // -d in force at that -o
        bokeh::WriteOptions options;                       // -o's parts=, compression=, tile=
    };
    enum class MissingFile { Error, Black, Checker };

    void register_host_commands();
    void register_run_options();
    void register_sequence_options();
    void register_report_and_policy_options();
    void register_stack_commands();
    void add_host_command(bokeh::Command cmd, bool global);
    bool load_plugins();
    std::string plugin_dir() const;
    std::string shipped_color_config() const;

    void print_help() const;
    bool print_command_help(const std::string& name) const;
    void print_plugins() const;
    /// `--help-markdown [DIR]`: the command reference pages, printed or written into DIR.
    int print_markdown(const std::vector<std::string>& args, bool plugins_ok);

    bool parse(const std::vector<std::string>& args, bool checking);
    bool check_line(const std::vector<std::string>& args, FramePlan& plan);
    void dispatch(OIIO::ArgParse& ap, const std::vector<std::string>& argv, bool checking);
    bool check_command(const bokeh::Command& cmd, const std::string& modifiers,
                       const std::vector<std::string>& args, bokeh::OptionValues& opts);
    /// `spelled`: the command as typed, options and arguments included (names its result).
    bool run_command(const bokeh::Command& cmd, bokeh::OptionValues opts,
                     const std::vector<std::string>& args, const std::string& spelled);
    bool read_input(const std::string& path);
    bool write_pending();
    bool write_one(const PendingWrite& w);
    /// write_one without reporting: false + `err` (safe off the main thread).
    bool write_checked(const PendingWrite& w, std::string& err);
    int run_frames(const std::vector<std::string>& args);
    /// -u: true when every output of the frame line `line` exists, is newer than each of
    /// its inputs and records the same command line (`why` says which output decided);
    /// `stale` says why an existing output is made again.
    bool frame_up_to_date(const std::vector<std::string>& line, std::string& why,
                          std::string& stale);
    bool substitute_missing(const std::string& path);
    void print_runstats(double seconds) const;
    void set_current(const std::string& command);
    bool fail(const std::string& command, const std::string& why);
    void warn(const std::string& what) const;
    void message(const std::string& what) const;

    bokeh::Registry m_registry;
    std::map<std::string, bool> m_global;  // host commands that act in pass 1 only
    std::vector<std::string> m_plugin_files, m_plugin_failures;
    bokeh::ColorSystem m_colors;

    // Global settings (pass 1).
    int m_threads = 0, m_verbosity = 1;
    bool m_info = false, m_no_clobber = false, m_progress = false;
    double m_progress_interval_s = 1.0;  // --progress:interval=
    bokeh::NonFinitePolicy m_nan_policy = bokeh::NonFinitePolicy::Zero;
    std::string m_colorconfig;
    bokeh::ReadOptions m_read_options;
    double m_timeout_seconds = 0;  // 0 = no limit
    bool m_parallel_frames = false;
    bool m_dry_run = false, m_update = false, m_skip_bad_frames = false, m_runstats = false;
    MissingFile m_missing_file = MissingFile::Error;
    OIIO::ImageSpec m_last_read_spec;  // --missingfile substitutes an image of this size
    int m_frames_done = 0, m_frames_skipped = 0;
    std::vector<int> m_frames_failed;

    // Per-frame state (pass 2), and the stack depth pass 1 simulates.
    std::vector<bokeh::StackImage> m_stack;
    std::vector<PendingWrite> m_writes;
    std::map<std::string, OIIO::TypeDesc> m_datatypes;
    int m_depth = 0;
    bool m_failed = false;
    std::vector<std::string> m_line_inputs, m_line_outputs;  // files of the line checked last
    // The line checked last without the options that change no output (its "recipe"), and
    // the running frame's: recorded as "bokeh:command" in each file written, compared by -u.
    std::string m_line_recipe, m_frame_recipe;

    // --parallel-frames: the next frame's inputs read ahead, by file name.
    struct Prefetched {
        bool ok = false;
        std::shared_ptr<OIIO::ImageBuf> buf;
        bokeh::ReadInfo info;
    };
    std::map<std::string, std::shared_future<Prefetched>> m_read_ahead;
    std::mutex m_colors_mutex;  // colour conversions of the main thread and of a write behind
    void read_ahead(const std::vector<std::string>& line);
    std::string m_where;    // appended to errors: which frame of a sequence, and what follows
    std::string m_frame_label;  // "frame 3, 3 of 5" in a sequence, else empty
    std::string m_current;  // the command running, named by errors that are not its own
};

}  // namespace bokehtool
