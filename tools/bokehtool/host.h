// host.h — bokehtool's host: the image stack, the built-in (global and I/O) commands,
// plugin loading, and the two-pass run of a command line.
//
// Pass 1 checks the whole command line before any pixel is touched: unknown commands,
// missing arguments, bad options, too few images on the stack; and applies the global
// options. Pass 2 runs it. Outputs (-o) are written only after every command of the
// frame has succeeded, each through a temporary file renamed into place, so a failing
// command line writes nothing.
#pragma once

#include <map>
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
    };

    void register_host_commands();
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
    bool run_command(const bokeh::Command& cmd, bokeh::OptionValues opts,
                     const std::vector<std::string>& args);
    bool read_input(const std::string& path);
    bool write_pending();
    bool write_one(const PendingWrite& w);
    int run_frames(const std::vector<std::string>& args);
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
    bokeh::NonFinitePolicy m_nan_policy = bokeh::NonFinitePolicy::Zero;
    std::string m_colorconfig;
    bokeh::ReadOptions m_read_options;
    double m_timeout_seconds = 0;  // 0 = no limit

    // Per-frame state (pass 2), and the stack depth pass 1 simulates.
    std::vector<bokeh::StackImage> m_stack;
    std::vector<PendingWrite> m_writes;
    std::map<std::string, OIIO::TypeDesc> m_datatypes;
    int m_depth = 0;
    bool m_failed = false;
    std::string m_where;    // appended to errors: which frame of a sequence
    std::string m_current;  // the command running, named by errors that are not its own
};

}  // namespace bokehtool
