// host.cpp — bokehtool's host. See host.h for the two-pass design.

#include "host.h"
#include "guard.h"
#include "help_markdown.h"
#include "sequence.h"

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <exception>
#include <filesystem>
#include <iostream>
#include <new>
#include <string_view>

#include <sys/resource.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <OpenImageIO/argparse.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/sysutil.h>
#include <OpenImageIO/timer.h>

#include <bokeh/io.h>

#ifndef BOKEH_VERSION
#    error "BOKEH_VERSION must be defined by the build"
#endif

namespace bokehtool {

using bokeh::Command;
using bokeh::CommandContext;
using bokeh::OptionSpec;
using bokeh::StackImage;
using OIIO::Strutil::fmt::format;

static const char* kProgram = "bokehtool";

// "4G", "512M", "100K" (binary units, optional "iB"/"B"), "1.5G", or a byte count.
static bool parse_memory_size(const std::string& text, int64_t& bytes)
{
    OIIO::string_view s(text);
    float value = 0;
    if (!OIIO::Strutil::parse_float(s, value) || !(value > 0) || !std::isfinite(value))
        return false;
    std::string unit = OIIO::Strutil::lower(std::string(s));
    if (unit == "b" || OIIO::Strutil::ends_with(unit, "ib"))
        unit = unit.substr(0, unit.size() - (unit == "b" ? 1 : 2));
    else if (unit.size() == 2 && unit[1] == 'b')
        unit = unit.substr(0, 1);
    const char* units = "kmgt";
    double scale      = 1;
    if (!unit.empty()) {
        const char* u = unit.size() == 1 ? std::strchr(units, unit[0]) : nullptr;
        if (!u)
            return false;
        scale = std::ldexp(1.0, 10 * int(u - units + 1));
    }
    const double b = double(value) * scale;
    if (b < 1 || b > 9.0e18)
        return false;
    bytes = int64_t(b);
    return true;
}

// "64,32" or "64x32" (oiiotool's form); "" = no tiles asked for.
static bool parse_tile_size(const std::string& text, int& width, int& height)
{
    width = height = 0;
    if (text.empty())
        return true;
    const std::vector<std::string> sides = OIIO::Strutil::splits(
        text, text.find(',') != std::string::npos ? "," : "x");
    if (sides.size() != 2)
        return false;
    OIIO::string_view w(sides[0]), h(sides[1]);
    return OIIO::Strutil::parse_int(w, width) && w.empty() && OIIO::Strutil::parse_int(h, height)
           && h.empty() && width > 0 && height > 0 && width <= 65536 && height <= 65536;
}

// A long command's progress on stderr (`--progress`), never on stdout with the messages:
// a line such as "--defocus: 37% (12.0 s)" when the percentage has changed and at least
// `interval_s` has passed since the command started or the last line, so a command of
// under a second prints none; "100%" at the end once a line was printed. The library calls
// it from one thread at a time; the lock keeps a plugin that does not from mixing lines.
class ProgressLine {
public:
    ProgressLine(std::string command, double interval_s) : m_command(std::move(command)), m_interval_s(interval_s) {}

    void report(float fraction)
    {
        std::lock_guard<std::mutex> lock(m_lock);
        const int percent = std::clamp(int(std::floor(double(fraction) * 100.0)), 0, 100);
        const double now  = m_timer();
        if (percent == m_percent || now - m_last_s < m_interval_s)
            return;
        print(percent, now);
    }

    void finish(bool ok)
    {
        std::lock_guard<std::mutex> lock(m_lock);
        if (ok && m_percent >= 0 && m_percent < 100)
            print(100, m_timer());
    }

private:
    void print(int percent, double now)
    {
        std::cerr << format("{}: {}% ({:.1f} s)\n", m_command, percent, now) << std::flush;
        m_percent = percent;
        m_last_s  = now;
    }

    std::string m_command;
    double m_interval_s;
    OIIO::Timer m_timer;
    double m_last_s = 0.0;
    int m_percent   = -1;  // the last printed, -1 before the first line
    std::mutex m_lock;
};

Host::Host()
{
    m_registry.set_current_plugin(kProgram);
    register_host_commands();
    m_registry.set_current_plugin("");
}

void Host::add_host_command(Command cmd, bool global)
{
    m_global[cmd.name] = global;
    m_registry.add(std::move(cmd));
}

// A host command pushing `outputs` images (globals and -d push none).
static Command host_command(std::string name, std::string arguments, int inputs, int outputs,
                            std::string help, bokeh::CommandFunction run)
{
    Command c = bokeh::make_command(std::move(name), std::move(arguments), inputs,
                                    std::move(help), std::move(run));
    c.outputs = outputs;
    return c;
}

// The host's own commands, in the order --help lists them. Global options are applied in
// pass 1, wherever they stand on the line; stack commands in pass 2, in order.
void Host::register_host_commands()
{
    register_run_options();
    register_sequence_options();
    register_report_and_policy_options();
    register_stack_commands();
}

// What a run reads and how it is bounded: help, version, frames, threads, memory, views, time.
void Host::register_run_options()
{
    auto nothing = [](CommandContext&) { return true; };
    add_host_command(host_command("--help", "", 0, 0,
                                  "Print this help; --help COMMAND for one command", nothing),
                     true);
    add_host_command(host_command("--help-markdown", "", 0, 0,
                                  "Print the command reference as Markdown, a page per "
                                  "module; --help-markdown DIR writes the pages into DIR",
                                  nothing),
                     true);
    add_host_command(host_command("--version", "", 0, 0, "Print the version", nothing), true);
    add_host_command(host_command("--plugins", "", 0, 0,
                                  "List the plugin modules loaded, from where, and failures",
                                  nothing),
                     true);
    add_host_command(host_command("--frames", "SPEC", 0, 0,
                                  "Frames to run a sequence command line for (1-10, 1-10x2, 3,5)",
                                  nothing),
                     true);
    add_host_command(host_command("--threads", "N", 0, 0, "Threads to use (0 = all cores)",
                                  [this](CommandContext& c) {
                                      OIIO::string_view s(c.args[0]);
                                      int n = 0;
                                      if (!OIIO::Strutil::parse_int(s, n) || !s.empty()
                                          || n < 0 || n > 1024)
                                          return c.fail(format("'{}' is not a thread count "
                                                               "(0..1024, 0 = all cores)",
                                                               c.args[0]));
                                      m_threads = n;
                                      return true;
                                  }),
                     true);
    add_host_command(host_command("--maxmemory", "SIZE", 0, 0,
                                  "Memory one input file may take once read, and what a command "
                                  "may make from the sizes given (a scene, a resize target): 4G, "
                                  "512M, 100K or bytes; more is refused before it is allocated, "
                                  "but a defocus draws a deep frame's layers in groups and a flat "
                                  "frame's output in bands of rows to fit. Default: half the "
                                  "physical memory",
                                  [this](CommandContext& c) {
                                      int64_t bytes = 0;
                                      if (!parse_memory_size(c.args[0], bytes))
                                          return c.fail(format("'{}' is not a memory size "
                                                               "(4G, 512M, 100K or bytes; > 0)",
                                                               c.args[0]));
                                      m_read_options.memory_budget_bytes = bytes;
                                      return true;
                                  }),
                     true);
    add_host_command(host_command("--view", "NAME", 0, 0,
                                  "Multi-view (stereo) EXR: read view NAME of every multi-view input, "
                                  "its channels named without the view (R, G, B, A, Z), the other views "
                                  "left out; a file without views is read whole. Default: a file's first "
                                  "view is the image (its depth too, from a part of its own) and the "
                                  "others' channels are prefixed by their view (right.R)",
                                  [this](CommandContext& c) {
                                      if (c.args[0].empty() || c.args[0].find('.') != std::string::npos)
                                          return c.fail(format("'{}' is not a view name", c.args[0]));
                                      m_read_options.view = c.args[0];
                                      return true;
                                  }),
                     true);
    add_host_command(host_command("--timeout", "SECONDS", 0, 0,
                                  "Stop the run with an error after this long, or as soon as the "
                                  "running command's pace (its progress) says it would end past "
                                  "1.5 times the limit (a last resort on farms; temporary output "
                                  "files are removed; exit status 124)",
                                  [this](CommandContext& c) {
                                      OIIO::string_view s(c.args[0]);
                                      float t = 0;
                                      if (!OIIO::Strutil::parse_float(s, t) || !s.empty()
                                          || !(t > 0) || !std::isfinite(t))
                                          return c.fail(format("'{}' is not a time in seconds "
                                                               "(> 0)",
                                                               c.args[0]));
                                      m_timeout_seconds = t;
                                      return true;
                                  }),
                     true);
}

// How a sequence runs: dry run, update, bad and missing frames, padding, overlap, statistics.
void Host::register_sequence_options()
{
    add_host_command(host_command("-n", "", 0, 0,
                                  "Dry run: read and compute every frame, write nothing; print "
                                  "the files that would be written",
                                  [this](CommandContext&) { return m_dry_run = true, true; }),
                     true);
    add_host_command(host_command("-u", "", 0, 0,
                                  "Update: skip a frame whose outputs all exist and are newer "
                                  "than all its inputs (a resubmitted farm job redoes only "
                                  "what is missing or stale)",
                                  [this](CommandContext&) { return m_update = true, true; }),
                     true);
    add_host_command(host_command("--skip-bad-frames", "", 0, 0,
                                  "A frame that fails is reported by number and the run goes "
                                  "on; the exit status is still 1, with a last line naming the "
                                  "failed frames",
                                  [this](CommandContext&) { return m_skip_bad_frames = true, true; }),
                     true);
    add_host_command(host_command("--framepadding", "N", 0, 0,
                                  "Digits of a frame number in a '#' pattern (default 4; "
                                  "printf-style %0Nd patterns give their own)",
                                  [](CommandContext& c) {
                                      OIIO::string_view s(c.args[0]);
                                      int n = 0;
                                      if (!OIIO::Strutil::parse_int(s, n) || !s.empty() || n < 1
                                          || n > 9)
                                          return c.fail(format("'{}' is not a digit count (1..9)",
                                                               c.args[0]));
                                      return true;  // used where the patterns are expanded
                                  }),
                     true);
    add_host_command(host_command("--parallel-frames", "", 0, 0,
                                  "Overlap frames of a sequence: the next frame's inputs are read "
                                  "and the last frame's outputs written while this frame is "
                                  "computed (same results; about one frame more in memory)",
                                  [this](CommandContext&) { return m_parallel_frames = true, true; }),
                     true);
    add_host_command(host_command("--runstats", "", 0, 0,
                                  "At the end: frames done, skipped and failed, wall and CPU "
                                  "time, peak memory",
                                  [this](CommandContext&) { return m_runstats = true, true; }),
                     true);
    add_host_command(host_command("--missingfile", "POLICY", 0, 0,
                                  "A missing input file: error (default); black or checker: a "
                                  "warning, and an image of that kind in its place, the size of "
                                  "the last image read (else 1920x1080 RGBA), as oiiotool does",
                                  [this](CommandContext& c) {
                                      const std::string& a = c.args[0];
                                      if (a == "error")
                                          m_missing_file = MissingFile::Error;
                                      else if (a == "black")
                                          m_missing_file = MissingFile::Black;
                                      else if (a == "checker")
                                          m_missing_file = MissingFile::Checker;
                                      else
                                          return c.fail(format("'{}' is not a policy (error, "
                                                               "black, checker)",
                                                               a));
                                      return true;
                                  }),
                     true);
}

// What the run reports (verbosity, --info, progress) and its policies for existing outputs,
// colour and non-finite pixels.
void Host::register_report_and_policy_options()
{
    add_host_command(host_command("-v", "", 0, 0, "Verbose: timings and details",
                                  [this](CommandContext&) { return m_verbosity = 2, true; }),
                     true);
    add_host_command(host_command("-q", "", 0, 0, "Quiet: errors only",
                                  [this](CommandContext&) { return m_verbosity = 0, true; }),
                     true);
    add_host_command(host_command("--info", "", 0, 0,
                                  "Describe every input as it is read (with -v: channels, "
                                  "windows, metadata, deep sample statistics)",
                                  [this](CommandContext&) { return m_info = true, true; }),
                     true);
    add_host_command(host_command("--no-clobber", "", 0, 0,
                                  "Refuse to replace existing output files",
                                  [this](CommandContext&) { return m_no_clobber = true, true; }),
                     true);
    Command progress = host_command(
        "--progress", "", 0, 0,
        "Print a line per frame, and on stderr how far a long command is (the truth, a "
        "defocus, a reference or FFT blur): at most a line every interval= seconds",
        [this](CommandContext& c) {
            m_progress            = true;
            m_progress_interval_s = c.options.get_float("interval");
            return true;
        });
    progress.options = { OptionSpec::Float("interval", 1.0, 0.0, 3600.0,
                                           "seconds between progress lines (0: every percent)") };
    add_host_command(std::move(progress), true);
    add_host_command(host_command("--colorconfig", "FILE", 0, 0,
                                  "OCIO config to use (default: $OCIO, else the shipped one)",
                                  [this](CommandContext& c) {
                                      m_colorconfig = c.args[0];
                                      return true;
                                  }),
                     true);
    Command nan = host_command(
        "--nan", "", 0, 0,
        "Policy for NaN/Inf pixels read: zero (colour -> 0, depth -> no depth; counted, "
        "warned) or error",
        [this](CommandContext& c) {
            m_nan_policy = c.options.get_string("policy") == "error"
                               ? bokeh::NonFinitePolicy::Error
                               : bokeh::NonFinitePolicy::Zero;
            return true;
        });
    nan.options = { OptionSpec::Choice("policy", { "zero", "error" },
                                       "zero: replace and warn; error: fail") };
    add_host_command(std::move(nan), true);
}

// Stack commands of the host itself: read (-i), write (-o) and the type outputs take (-d).
void Host::register_stack_commands()
{
    add_host_command(host_command("-i", "FILE", 0, 1,
                                  "Read an image (a bare file name does the same)",
                                  [this](CommandContext& c) { return read_input(c.args[0]); }),
                     false);
    Command out = host_command(
        "-o", "FILE", 1, 1,
        "Write the top image (after the whole command line has succeeded)",
        [this](CommandContext& c) {
            PendingWrite w{ c.inputs[0], c.args[0], m_datatypes, {} };
            // What made the file, so that -u can tell a frame made with other options.
            w.options.metadata.attribute("bokeh:command", m_frame_recipe);
            w.options.parts       = c.options.get_string("parts") == "layers"
                                        ? bokeh::PartLayout::Layers
                                        : bokeh::PartLayout::Single;
            w.options.compression = c.options.get_string("compression");
            if (!parse_tile_size(c.options.get_string("tile"), w.options.tile_width,
                                 w.options.tile_height))
                return c.fail(format("tile={} is not a tile size (W,H or WxH, both > 0)",
                                     c.options.get_string("tile")));
            m_writes.push_back(std::move(w));
            c.outputs.push_back(c.inputs[0]);
            return true;
        });
    out.options = {
        OptionSpec::Choice("parts", { "single", "layers" },
                           "single: one part; layers: a part per layer, as Nuke writes "
                           "multipart EXR (R,G,B,A,... in part rgba, depth.Z in part depth)"),
        OptionSpec::String("compression", "",
                           "compression as oiiotool names it: zip, zips, piz, dwaa:45, none, ... "
                           "(default: the input's, else the format's)"),
        OptionSpec::String("tile", "", "tiles of W,H (or WxH) pixels (default: as read)"),
    };
    add_host_command(std::move(out), false);
    add_host_command(
        host_command("-d", "TYPE", 0, 0,
                     "Pixel type of later outputs: uint8, uint16, half, float; or CHANNEL=TYPE",
                     [this](CommandContext& c) {
                         const std::string& a = c.args[0];
                         const size_t eq      = a.find('=');
                         const std::string channel = eq == std::string::npos ? "" : a.substr(0, eq);
                         const OIIO::TypeDesc t(eq == std::string::npos ? a : a.substr(eq + 1));
                         if (t == OIIO::TypeUnknown || t.aggregate != OIIO::TypeDesc::SCALAR)
                             return c.fail(format("'{}' is not a pixel type (uint8, uint16, "
                                                  "half, float, ...)",
                                                  a));
                         // As in oiiotool, the global type and the per-channel types are
                         // separate settings: their order on the command line does not matter.
                         m_datatypes[channel] = t;
                         return true;
                     }),
        false);
}

// ---------------------------------------------------------------------------------------
// Plugins and the shipped files, found relative to the executable (bin/..).

static std::string prefix_dir()
{
    const std::string exe = OIIO::Sysutil::this_program_path();
    return OIIO::Filesystem::parent_path(OIIO::Filesystem::parent_path(exe));
}

std::string Host::plugin_dir() const { return prefix_dir() + "/" + BOKEH_PLUGIN_RELDIR; }

std::string Host::shipped_color_config() const
{
    return prefix_dir() + "/" + BOKEH_DATA_RELDIR + "/ocio/config.ocio";
}

bool Host::load_plugins()
{
    std::vector<std::string> dirs = { plugin_dir() };
    if (const char* path = std::getenv("BOKEH_PLUGIN_PATH"))
        for (const std::string& d : OIIO::Strutil::splits(path, ":"))
            if (!d.empty())
                dirs.push_back(d);
    for (const std::string& dir : dirs) {
        if (!OIIO::Filesystem::is_directory(dir)) {
            m_plugin_failures.push_back(format("plugin directory {}: does not exist", dir));
            continue;
        }
        std::vector<std::string> files;
        OIIO::Filesystem::get_directory_entries(dir, files, false);
        std::sort(files.begin(), files.end());
        for (const std::string& f : files) {
            if (OIIO::Filesystem::extension(f) != ".so")
                continue;
            std::string err;
            if (bokeh::load_plugin(m_registry, f, err))
                m_plugin_files.push_back(f);
            else
                m_plugin_failures.push_back(err);
        }
    }
    return m_plugin_failures.empty();
}

// ---------------------------------------------------------------------------------------
// Help.

static std::string option_line(const OptionSpec& o)
{
    using Type = OptionSpec::Type;
    std::string range;
    switch (o.type) {
    case Type::Int:
    case Type::Float: range = format("number in [{}, {}]", o.min, o.max); break;
    case Type::Bool: range = "0 or 1"; break;
    case Type::Choice: range = "one of " + OIIO::Strutil::join(o.choices, "|"); break;
    case Type::String: range = "text"; break;
    }
    return format("      :{}={}  ({}) {}\n", o.name, o.default_value, range, o.help);
}

void Host::print_help() const
{
    std::cout << format(
        "{} {} — lens defocus for VFX compositing (OpenBokeh)\n\n"
        "Usage: {} [INPUT | COMMAND ARGS...]... -o OUTPUT\n"
        "Images form a stack: an input file pushes one, a command pops its inputs and\n"
        "pushes its result, -o FILE writes the top. Options ride on a command:\n"
        "--cmd:opt=val:opt2=val. A file name with #, @ or %04d runs the command line once\n"
        "per frame (shot.#.exr, --frames 1-10x2). -- makes the next word an argument or a\n"
        "file name even if it begins with '-' (--bokeh -- -45, -- -plate.exr). Errors: one\n"
        "line, exit status 1, nothing written.\n",
        kProgram, BOKEH_VERSION, kProgram);
    std::string current = "-";
    for (const Command& c : m_registry.commands()) {
        if (c.plugin != current) {
            current = c.plugin;
            std::cout << (current == kProgram ? std::string("\nBuilt in:\n")
                                              : format("\nFrom {}:\n", current));
        }
        const std::string head = c.name + (c.arguments.empty() ? "" : " " + c.arguments);
        std::cout << format("  {:<24} {}\n", head, c.help);
        for (const OptionSpec& o : c.options)
            std::cout << option_line(o);
    }
    std::cout << format("\nMore on one command: {} --help COMMAND\n", kProgram);
}

bool Host::print_command_help(const std::string& name) const
{
    const Command* c = m_registry.find(name);
    if (!c)
        c = m_registry.find("--" + name);
    if (!c)
        return false;
    std::cout << format("{}{}\n    {}\n    takes {} image(s) from the stack{}, pushes {}; from {}\n",
                        c->name, c->arguments.empty() ? "" : " " + c->arguments, c->help,
                        c->inputs, c->inputs_for ? " (more with some options, below)" : "",
                        c->outputs, c->plugin);
    if (!c->options.empty())
        std::cout << "    options:\n";
    for (const OptionSpec& o : c->options)
        std::cout << option_line(o);
    return true;
}

int Host::print_markdown(const std::vector<std::string>& args, bool plugins_ok)
{
    // A reference made without a module that failed to load would be silently incomplete.
    if (!plugins_ok) {
        for (const std::string& f : m_plugin_failures)
            std::cerr << format("{} ERROR: --help-markdown: {}\n", kProgram, f);
        return 1;
    }
    if (args.size() > 2 || args[0] != "--help-markdown")
        return fail("--help-markdown", "takes one optional argument, the directory to write "
                                       "(bokehtool --help-markdown [DIR]), and nothing else"),
               1;
    const std::vector<MarkdownPage> pages = command_reference_pages(m_registry, kProgram,
                                                                    m_global);
    if (args.size() == 1) {
        for (const MarkdownPage& p : pages)
            std::cout << p.text << "\n";
        return 0;
    }
    std::string err;
    if (!write_markdown_pages(pages, args[1], err))
        return fail("--help-markdown", err), 1;
    return 0;
}

void Host::print_plugins() const
{
    std::cout << format("built-in plugin directory: {}\n", plugin_dir());
    const char* env = std::getenv("BOKEH_PLUGIN_PATH");
    std::cout << format("BOKEH_PLUGIN_PATH: {}\n", env ? env : "(not set)");
    for (const std::string& f : m_plugin_files) {
        std::vector<std::string> names;
        for (const Command& c : m_registry.commands())
            if (c.plugin == f)
                names.push_back(c.name);
        std::cout << format("loaded {}: {}\n", f, OIIO::Strutil::join(names, " "));
    }
    for (const std::string& f : m_plugin_failures)
        std::cout << format("FAILED {}\n", f);
}

// ---------------------------------------------------------------------------------------
// Messages.

bool Host::fail(const std::string& command, const std::string& why)
{
    // Library errors name their function ("resize: ..."); after "--resize: " that is the
    // same word twice.
    std::string_view reason = why;
    const std::string_view bare = std::string_view(command).substr(
        std::min(command.find_first_not_of('-'), command.size()));
    if (!bare.empty() && reason.size() > bare.size() + 2 && reason.substr(0, bare.size()) == bare
        && reason.substr(bare.size(), 2) == ": ")
        reason.remove_prefix(bare.size() + 2);
    if (!m_failed)
        std::cerr << format("{} ERROR: {}{}{}{}\n", kProgram, command,
                            command.empty() ? "" : ": ", reason, m_where);
    m_failed = true;
    return false;
}

void Host::warn(const std::string& what) const
{
    if (m_verbosity > 0)
        std::cerr << format("{} WARNING: {}\n", kProgram, what);
}

void Host::message(const std::string& what) const
{
    if (m_verbosity > 0)
        std::cout << what << (OIIO::Strutil::ends_with(what, "\n") ? "" : "\n");
}

// ---------------------------------------------------------------------------------------
// Parsing and running.

// `--` makes the word after it an argument or a file name even when it begins with '-'
// (a negative CoC, a file named "-plate.exr"). ArgParse sees such a word with this mark in
// front, which dispatch() takes off again.
constexpr char kLiteralMark = '\x1f';

bool Host::parse(const std::vector<std::string>& args, bool checking)
{
    if (checking)
        m_line_recipe.clear();
    OIIO::ArgParse ap;
    ap.prog(kProgram).add_help(false).exit_on_error(false);
    std::vector<std::string> words;
    for (size_t i = 0; i < args.size(); ++i) {
        if (args[i] != "--") {
            words.push_back(args[i]);
            continue;
        }
        if (i + 1 == args.size())
            return fail("--", "needs a word after it (it makes that word an argument or a file name)");
        words.push_back(kLiteralMark + args[++i]);
    }
    std::vector<const char*> argv = { kProgram };
    for (const std::string& a : words)
        argv.push_back(a.c_str());

    auto action = [this, &ap, checking](OIIO::cspan<const char*> a) {
        if (m_failed)
            return;
        std::vector<std::string> words(a.begin(), a.end());
        dispatch(ap, words, checking);
        if (m_failed)
            ap.abort();
    };
    for (const Command& c : m_registry.commands()) {
        const std::string decl = c.name + (c.arguments.empty() ? "" : " " + c.arguments);
        ap.add_argument(decl.c_str()).help(c.help).always_run().action(action);
    }
    ap.add_argument("filename").hidden().always_run().action(action);

    if (ap.parse_args(int(argv.size()), argv.data()) < 0 && !m_failed) {
        std::string why = OIIO::Strutil::strip(ap.geterror());
        return fail("", why.empty() ? "malformed command line" : why + " (see --help)");
    }
    return !m_failed;
}

// Global options that change how a run goes but not a pixel or a byte of what it writes;
// -u leaves them out of the command line it compares (a frame rendered with -v or on
// more threads is still up to date).
static bool changes_no_output(const std::string& name)
{
    static const char* names[] = { "--help",   "--help-markdown", "--version",         "--plugins",
                                   "--frames", "--threads",       "--maxmemory",       "--timeout",
                                   "-n",       "-u",              "--skip-bad-frames", "--framepadding",
                                   "-v",       "-q",              "--parallel-frames", "--runstats",
                                   "--info",   "--no-clobber",    "--progress" };
    return std::find(std::begin(names), std::end(names), name) != std::end(names);
}

void Host::dispatch(OIIO::ArgParse&, const std::vector<std::string>& marked, bool checking)
{
    std::vector<std::string> words = marked;
    for (std::string& w : words)
        if (!w.empty() && w[0] == kLiteralMark)
            w.erase(0, 1);
    const std::string& head = words[0];
    const bool is_file      = head.empty() || marked[0][0] == kLiteralMark || head[0] != '-' || head == "-";
    // The recipe: what decides the bytes written, so not where they go (-o's file name;
    // its modifiers stay) nor the options that change no output.
    const std::string head_name = head.substr(0, head.find(':'));
    if (checking && !changes_no_output(head_name))
        m_line_recipe += (m_line_recipe.empty() ? "" : " ")
                         + (head_name == "-o" ? head : OIIO::Strutil::join(words, " "));
    if (is_file) {
        if (checking) {
            ++m_depth;
            m_line_inputs.push_back(head);
        } else {
            set_current("-i");
            read_input(head);
        }
        return;
    }
    const size_t colon          = head.find(':');
    const std::string name      = head.substr(0, colon);
    const std::string modifiers = colon == std::string::npos ? "" : head.substr(colon + 1);
    const Command* cmd          = m_registry.find(name);
    if (!cmd) {
        fail(name, "unknown command (see --help)");
        return;
    }
    const std::vector<std::string> args(words.begin() + 1, words.end());
    bokeh::OptionValues opts;
    if (checking) {
        if (!check_command(*cmd, modifiers, args, opts))
            return;
        if (name == "-i")
            m_line_inputs.push_back(args[0]);
        else if (name == "-o")
            m_line_outputs.push_back(args[0]);
        if (m_global[name]) {
            CommandContext ctx;
            ctx.args    = args;
            ctx.options = opts;
            if (!cmd->run(ctx))
                fail(name, ctx.error);
        }
        return;
    }
    if (m_global[name])
        return;
    set_current(name);
    std::string err;
    bokeh::parse_options(cmd->options, modifiers, opts, err);  // checked in pass 1
    run_command(*cmd, opts, args, OIIO::Strutil::join(words, " "));
}

bool Host::check_command(const Command& cmd, const std::string& modifiers,
                         const std::vector<std::string>& args, bokeh::OptionValues& opts)
{
    std::string err;
    if (!bokeh::parse_options(cmd.options, modifiers, opts, err))
        return fail(cmd.name, err);
    if (int(args.size()) != cmd.argument_count())
        return fail(cmd.name, format("needs {} argument(s): {}", cmd.argument_count(),
                                     cmd.arguments));
    const int inputs = cmd.input_count(opts);
    if (m_depth < inputs)
        return fail(cmd.name, format("needs {} image(s) on the stack but {} {} there",
                                     inputs, m_depth, m_depth == 1 ? "is" : "are"));
    m_depth += cmd.outputs - inputs;
    return true;
}

bool Host::run_command(const Command& cmd, bokeh::OptionValues opts,
                       const std::vector<std::string>& args, const std::string& spelled)
{
    const int inputs = cmd.input_count(opts);
    if (int(m_stack.size()) < inputs)
        return fail(cmd.name, format("needs {} image(s) on the stack but {} there", inputs,
                                     m_stack.size()));
    CommandContext ctx;
    ctx.args      = args;
    ctx.options   = std::move(opts);
    ctx.nthreads  = m_threads;
    ctx.verbosity = m_verbosity;
    ctx.colors    = &m_colors;
    ctx.memory_budget_bytes = m_read_options.memory_budget_bytes;
    ctx.timeout_seconds     = m_timeout_seconds;
    ctx.message   = [this](const std::string& s) { message(s); };
    std::shared_ptr<ProgressLine> progress;
    if (m_progress && m_verbosity > 0) {
        progress     = std::make_shared<ProgressLine>(cmd.name, m_progress_interval_s);
        ctx.progress = [progress](float fraction) {
            progress->report(fraction);
            guard_progress(fraction);
        };
    } else if (m_timeout_seconds > 0) {  // the pace against --timeout (guard.h)
        ctx.progress = [](float fraction) { guard_progress(fraction); };
    }
    ctx.inputs.assign(m_stack.end() - inputs, m_stack.end());
    m_stack.resize(m_stack.size() - size_t(inputs));

    // A filter works in the scene-linear working space. An input in another linear space
    // (ACEScg) is converted for it and its result converted back, so that an ACEScg plate
    // stays ACEScg down the line and in the file (an encoded input, sRGB from a PNG, stays
    // in the working space: a float file holds linear light).
    std::string linear_space_in;
    if (cmd.needs_scene_linear && !ctx.inputs.empty() && !ctx.inputs[0].buf->deep()
        && ctx.inputs[0].colorspace != m_colors.scene_linear()
        && m_colors.is_scene_linear(ctx.inputs[0].colorspace))
        linear_space_in = ctx.inputs[0].colorspace;
    if (cmd.needs_scene_linear) {
        for (StackImage& in : ctx.inputs) {
            if (in.buf->deep() || in.colorspace == m_colors.scene_linear())
                continue;
            auto linear = std::make_shared<OIIO::ImageBuf>(*in.buf);
            std::string err;
            std::unique_lock<std::mutex> lock(m_colors_mutex);  // a write may convert meanwhile
            if (!m_colors.convert(*linear, in.colorspace, m_colors.scene_linear(), m_threads, err))
                return fail(cmd.name, err);
            lock.unlock();
            in.buf        = linear;
            in.colorspace = m_colors.scene_linear();
        }
    }

    OIIO::Timer timer;
    bool ok = false;
    try {
        ok = cmd.run(ctx);
    } catch (const std::bad_alloc&) {
        ctx.error = "out of memory (std::bad_alloc)";
    } catch (const std::exception& e) {
        ctx.error = format("failed with an exception: {}", e.what());
    } catch (...) {
        ctx.error = "failed with an unknown exception";
    }
    if (progress)
        progress->finish(ok);
    if (!ok)
        return fail(cmd.name, ctx.error.empty() ? "failed (no reason given)" : ctx.error);
    if (int(ctx.outputs.size()) != cmd.outputs)
        return fail(cmd.name, format("pushed {} image(s) but declares {} (a plugin bug; {})",
                                     ctx.outputs.size(), cmd.outputs, cmd.plugin));
    for (StackImage& out : ctx.outputs)
        if (!linear_space_in.empty() && out.buf && !out.buf->deep()
            && (out.colorspace.empty() || out.colorspace == m_colors.scene_linear())) {
            auto back = std::make_shared<OIIO::ImageBuf>(*out.buf);
            std::string err;
            std::lock_guard<std::mutex> lock(m_colors_mutex);
            if (!m_colors.convert(*back, m_colors.scene_linear(), linear_space_in, m_threads, err))
                return fail(cmd.name, err);
            out.buf        = back;
            out.colorspace = linear_space_in;
        }
    for (StackImage& out : ctx.outputs) {
        if (!out.buf || !out.buf->initialized())
            return fail(cmd.name, format("produced no image (a plugin bug; {})", cmd.plugin));
        if (!ctx.inputs.empty()) {
            if (out.file_types.empty())
                out.file_types = ctx.inputs[0].file_types;
            if (out.colorspace.empty())
                out.colorspace = ctx.inputs[0].colorspace;
            // A new image is named by what made it, as a command line reads: "shot.exr
            // --defocus:focus=6" (--diff labels its two images so). Plugins start a result
            // from a copy of their input, its name included; an image passed through (-o)
            // keeps its name.
            const bool made_here = out.buf != ctx.inputs[0].buf;
            if (out.origin.empty() || (made_here && out.origin == ctx.inputs[0].origin))
                out.origin = ctx.inputs[0].origin + " " + spelled;
        }
        if (out.colorspace.empty())
            out.colorspace = m_colors.scene_linear();
        if (out.origin.empty())
            out.origin = spelled;
        m_stack.push_back(std::move(out));
    }
    if (m_verbosity > 1 && cmd.name != "-o")
        message(format("  {} {}: {:.3f} s", cmd.name, OIIO::Strutil::join(args, " "),
                       timer()));
    return true;
}

// --missingfile black|checker: in place of a file that does not exist, an image the size
// and channels of the last one read (else 1920x1080 RGBA half, oiiotool's choice): zero, or
// oiiotool's checker (64-pixel squares, black at the origin, alpha 1).
bool Host::substitute_missing(const std::string& path)
{
    OIIO::ImageSpec spec = m_last_read_spec;
    if (spec.nchannels == 0) {
        spec = OIIO::ImageSpec(1920, 1080, 4, OIIO::TypeHalf);
        spec.alpha_channel = 3;
    }
    spec.deep = false;
    OIIO::ImageSpec work = spec;
    work.set_format(OIIO::TypeFloat);
    work.channelformats.clear();
    auto buf = std::make_shared<OIIO::ImageBuf>(work, OIIO::InitializePixels::Yes);
    const bool checker = m_missing_file == MissingFile::Checker;
    if (checker) {
        std::vector<float> dark(size_t(work.nchannels), 0.0f), light(size_t(work.nchannels), 1.0f);
        if (work.alpha_channel >= 0)
            dark[size_t(work.alpha_channel)] = 1.0f;
        if (work.z_channel >= 0)
            dark[size_t(work.z_channel)] = light[size_t(work.z_channel)] = 0.0f;  // no depth
        OIIO::ImageBufAlgo::checker(*buf, 64, 64, 1, dark, light, 0, 0, 0);
    }
    // A warning: the run goes on with the substitute (m_where's "the run stopped here" is
    // for errors).
    warn(format("{}: no such file; {} image of {} x {}, {} channels in its place "
                "(--missingfile {}{}); the run goes on",
                path, checker ? "a checker" : "a black", work.width, work.height, work.nchannels,
                checker ? "checker" : "black", m_frame_label.empty() ? "" : "; " + m_frame_label));
    StackImage img;
    img.colorspace = m_colors.scene_linear();
    img.file_types = bokeh::channel_types_of(spec);
    img.origin     = path;
    img.buf        = std::move(buf);
    m_stack.push_back(std::move(img));
    return true;
}

bool Host::read_input(const std::string& path)
{
    if (m_missing_file != MissingFile::Error && !path.empty()
        && !OIIO::Filesystem::exists(path))
        return substitute_missing(path);
    auto buf = std::make_shared<OIIO::ImageBuf>();
    std::string err;
    bokeh::ReadInfo info;
    bool read = false;
    std::string said;
    auto ahead = m_read_ahead.find(path);
    if (ahead != m_read_ahead.end()) {
        // Read while the previous frame was computed (--parallel-frames). A failure is
        // read again below, so that it is reported as any read is.
        Prefetched p = ahead->second.get();
        m_read_ahead.erase(ahead);
        if (p.ok) {
            buf  = std::move(p.buf);
            info = std::move(p.info);
            read = true;
        }
    }
    if (!read) {
        StderrCapture capture;
        read = bokeh::read_image(*buf, path, m_read_options, &info, err);
        said = OIIO::Strutil::strip(capture.finish());
    }
    if (!read)
        return fail("-i", err);
#if defined(__GLIBC__)
    // glibc keeps what the reader freed (OpenEXR's compressors and line buffers, 15 MB for
    // a 4K frame) in its heap, resident, while the next command maps its frame-sized
    // planes beside it: giving it back keeps a 4K float defocus within 3x its frame
    // (/usr/bin/time, the 4K float `lights` frame: 499 -> 489 MB peak; docs/defocus.md,
    // "Memory").
    malloc_trim(0);
#endif
    if (!said.empty())
        warn(format("{}: read, with the reader's message: {}", path,
                    OIIO::Strutil::join(OIIO::Strutil::splits(said, "\n"), " / ")));
    bokeh::NonFiniteCount count;
    if (!bokeh::scrub_nonfinite(*buf, m_nan_policy, count, m_threads))
        return fail("-i", format("{}: {} non-finite (NaN/Inf) value(s) and --nan:policy=error",
                                 path, count.total()));
    if (count.total() > 0)
        warn(format("{}: replaced {} non-finite colour value(s) by 0 and {} NaN/-inf depth "
                    "value(s) by +inf (no depth)",
                    path, count.colour, count.depth));
    if (m_info) {
        std::cout << bokeh::describe_image(*buf, path, m_verbosity > 1);
        if (info.part_names.size() > 1)
            std::cout << format("    {} parts merged: {}\n", info.part_names.size(),
                                OIIO::Strutil::join(info.part_names, ", "));
    }
    if (!buf->deep())
        m_last_read_spec = buf->spec();
    StackImage img;
    img.colorspace = m_colors.space_of_file(buf->nativespec());
    img.file_types = info.file_types;
    img.origin     = path;
    img.buf        = std::move(buf);
    m_stack.push_back(std::move(img));
    return true;
}

// Formats that hold only integer pixels: outputs there are display-referred (sRGB).
static bool integer_only_format(const std::string& path)
{
    static const char* names[] = { ".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tga",
                                   ".webp", ".ppm", ".pgm", ".pnm", ".ico" };
    const std::string ext = OIIO::Strutil::lower(OIIO::Filesystem::extension(path));
    return std::any_of(std::begin(names), std::end(names), [&](const char* n) { return ext == n; });
}

void Host::set_current(const std::string& command)
{
    m_current = command;
    set_guard_command(command);
}

bool Host::write_one(const PendingWrite& w)
{
    set_current("-o");
    std::string err;
    return write_checked(w, err) || fail("-o", err);
}

bool Host::write_checked(const PendingWrite& w, std::string& err)
{
    const StackImage& img = w.image;
    std::vector<OIIO::TypeDesc> formats = bokeh::formats_for(img.buf->spec(), img.file_types);
    for (int c = 0; c < img.buf->nchannels(); ++c) {
        auto all = w.datatypes.find(""), mine = w.datatypes.find(img.buf->spec().channel_name(c));
        if (mine != w.datatypes.end())
            formats[size_t(c)] = mine->second;
        else if (all != w.datatypes.end())
            formats[size_t(c)] = all->second;
    }
    // Display-referred 8/16-bit data cannot go into OpenEXR (float, half, uint32 only):
    // it becomes scene-linear half there, and float data becomes 8-bit sRGB in PNG/JPEG.
    const std::string ext = OIIO::Strutil::lower(OIIO::Filesystem::extension(w.path));
    bool integer          = true;
    for (OIIO::TypeDesc& t : formats) {
        if (integer_only_format(w.path) && t.is_floating_point())
            t = OIIO::TypeUInt8;
        if (ext == ".exr" && t.is_floating_point() == false && t.basetype != OIIO::TypeDesc::UINT32)
            t = OIIO::TypeHalf;
        integer = integer && !t.is_floating_point();
    }
    // Integer files hold display-referred colour (sRGB); float files hold linear light: in
    // the image's own space when it is linear (ACEScg stays ACEScg, as --colorconvert or
    // --iscolorspace left it), else converted to the working space.
    const std::string target = integer                                  ? m_colors.display_default()
                               : m_colors.is_scene_linear(img.colorspace) ? img.colorspace
                                                                          : m_colors.scene_linear();

    const OIIO::ImageBuf* pixels = img.buf.get();
    OIIO::ImageBuf converted;
    if (!img.buf->deep() && img.colorspace != target) {
        converted = *img.buf;
        std::string why;
        std::lock_guard<std::mutex> lock(m_colors_mutex);
        if (!m_colors.convert(converted, img.colorspace, target, m_threads, why)) {
            err = format("{}: {}", w.path, why);
            return false;
        }
        pixels = &converted;
    }
    bokeh::WriteOptions opts = w.options;
    opts.metadata.attribute("oiio:ColorSpace", target);  // what the pixels are, converted or not
    opts.channel_formats     = formats;
    opts.no_clobber          = m_no_clobber;
    if (m_dry_run) {
        message(format("-n: would write {}", w.path));
        return true;
    }
    if (!bokeh::write_image(*pixels, w.path, opts, err))
        return false;
    if (m_verbosity > 1)
        message(format("  wrote {}", w.path));
    return true;
}

bool Host::write_pending()
{
    for (const PendingWrite& w : m_writes)
        if (!write_one(w))
            return false;
    return true;
}

int Host::main(const std::vector<std::string>& args)
{
    auto has = [&](const char* flag) { return std::find(args.begin(), args.end(), flag) != args.end(); };
    if (has("--version")) {
        std::cout << format("{} {}\n", kProgram, BOKEH_VERSION);
        return 0;
    }
    const bool plugins_ok = load_plugins();
    if (has("--help-markdown"))
        return print_markdown(args, plugins_ok);
    auto help = std::find(args.begin(), args.end(), "--help");
    if (args.empty() || help != args.end()) {
        if (help != args.end() && help + 1 != args.end()) {
            if (!print_command_help(*(help + 1)))
                return fail("--help", format("unknown command '{}'", *(help + 1))), 1;
        } else {
            print_help();
        }
        return plugins_ok ? 0 : 1;
    }
    if (has("--plugins")) {
        print_plugins();
        return plugins_ok ? 0 : 1;
    }
    if (!plugins_ok) {
        // A broken plugin is a broken installation: say which, and stop.
        for (const std::string& f : m_plugin_failures)
            std::cerr << format("{} ERROR: {}\n", kProgram, f);
        return 1;
    }

    install_guards();
    set_current("");
    // OIIO's debug messages ("OIIO DEBUG: ImageBuf unable to allocate ...") would make a
    // second line under the one-line error that reports the same failure.
    OIIO::attribute("debug", 0);
    try {
        return run_frames(args);
    } catch (const std::bad_alloc&) {
        fail(m_current, "out of memory (std::bad_alloc)");
    } catch (const std::exception& e) {
        std::string what = OIIO::Strutil::strip(e.what());
        fail(m_current, "failed with an exception: " + what.substr(0, what.find('\n')));
    } catch (...) {
        fail(m_current, "failed with an unknown exception");
    }
    bokeh::remove_partial_writes();
    return 1;
}

bool Host::frame_up_to_date(const std::vector<std::string>& line, std::string& why,
                             std::string& stale)
{
    m_line_inputs.clear();
    m_line_outputs.clear();
    m_depth = 0;
    if (!parse(line, true) || m_line_outputs.empty())
        return false;
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::file_time_type newest_input = fs::file_time_type::min();
    for (const std::string& in : m_line_inputs) {
        const auto t = fs::last_write_time(in, ec);
        if (ec)
            return false;  // a missing input: let the run say so
        newest_input = std::max(newest_input, t);
    }
    for (const std::string& out : m_line_outputs) {
        const auto t = fs::last_write_time(out, ec);
        if (ec || !(t > newest_input))
            return false;
    }
    // A farm resubmitted with other options must not keep frames made with the old ones:
    // each output's recorded command line is compared with this frame's.
    for (const std::string& out : m_line_outputs) {
        auto in = OIIO::ImageInput::open(out);
        const std::string made_by = in ? in->spec().get_string_attribute("bokeh:command") : "";
        if (made_by != m_line_recipe) {
            stale = made_by.empty()
                        ? format("{} records no command line", out)
                        : format("{} was made by another command line ({})", out, made_by);
            return false;
        }
    }
    why = m_line_inputs.empty()
              ? format("{} exist(s)", OIIO::Strutil::join(m_line_outputs, ", "))
              : format("{} newer than {}", OIIO::Strutil::join(m_line_outputs, ", "),
                       OIIO::Strutil::join(m_line_inputs, ", "));
    return true;
}

void Host::print_runstats(double seconds) const
{
    struct rusage usage = {};
    getrusage(RUSAGE_SELF, &usage);
    const double cpu = double(usage.ru_utime.tv_sec) + 1e-6 * double(usage.ru_utime.tv_usec)
                       + double(usage.ru_stime.tv_sec) + 1e-6 * double(usage.ru_stime.tv_usec);
    // Linux reports ru_maxrss in KiB.
    std::cout << format("runstats: {} frame(s) done, {} skipped (-u), {} failed; {:.2f} s wall, "
                        "{:.2f} s CPU; peak memory {}\n",
                        m_frames_done, m_frames_skipped, m_frames_failed.size(), seconds, cpu,
                        bokeh::memory_size_text(int64_t(usage.ru_maxrss) * 1024));
}

void Host::read_ahead(const std::vector<std::string>& line)
{
    m_line_inputs.clear();
    m_line_outputs.clear();
    m_depth = 0;
    if (!parse(line, true))
        return;
    for (const std::string& path : m_line_inputs) {
        if (m_read_ahead.count(path) || !OIIO::Filesystem::exists(path))
            continue;
        const bokeh::ReadOptions options = m_read_options;
        m_read_ahead[path] = std::async(std::launch::async, [path, options] {
                                 Prefetched p;
                                 p.buf = std::make_shared<OIIO::ImageBuf>();
                                 std::string err;
                                 try {
                                     p.ok = bokeh::read_image(*p.buf, path, options, &p.info, err);
                                 } catch (...) {
                                     p.ok = false;  // read again, and reported, by read_input
                                 }
                                 return p;
                             }).share();
    }
}

// Pass 1: plan the frames, check the whole line (of the first frame) and take the global
// options.
bool Host::check_line(const std::vector<std::string>& args, FramePlan& plan)
{
    std::string err;
    if (!plan_frames(args, plan, err))
        return fail("", err);
    return parse(plan.frames.empty() ? plan.args : args_for_frame(plan, plan.frames.front()), true);
}

bool Host::check_only(const std::vector<std::string>& args)
{
    if (!load_plugins()) {
        for (const std::string& f : m_plugin_failures)
            std::cerr << format("{} ERROR: {}\n", kProgram, f);
        return false;
    }
    FramePlan plan;
    return check_line(args, plan);
}

int Host::run_frames(const std::vector<std::string>& args)
{
    OIIO::Timer run_timer;
    FramePlan plan;
    if (!check_line(args, plan))
        return 1;
    const bool sequence = !plan.frames.empty();
    const std::vector<int> frames = sequence ? plan.frames : std::vector<int>{ 0 };
    std::string err;
    if (!m_colors.load(bokeh::resolve_color_config(m_colorconfig, shipped_color_config()), err))
        return fail("--colorconfig", err), 1;
    OIIO::attribute("threads", m_threads);
    m_read_options.budget_name = m_read_options.memory_budget_bytes > 0 ? "--maxmemory"
                                                                        : "the memory budget "
                                                                          "(--maxmemory)";
    Watchdog watchdog(m_timeout_seconds);
    const bool overlap = m_parallel_frames && sequence && frames.size() > 1;

    // A frame's outputs written while the next one is computed (--parallel-frames).
    struct Written {
        bool ok = true;
        std::string err, where;
        int frame   = 0;
        size_t index = 0;
        double seconds = 0;
    };
    std::future<Written> writing;
    auto frame_done = [&](int frame, size_t index, double seconds) {
        ++m_frames_done;
        if (m_progress && m_verbosity > 0)
            std::cout << format("frame {} ({} of {}) done in {:.2f} s\n", frame, index + 1,
                                frames.size(), seconds);
    };
    // Wait for the write behind; false when it failed (reported here, naming its frame).
    auto collect = [&]() {
        if (!writing.valid())
            return true;
        Written w = writing.get();
        if (w.ok) {
            frame_done(w.frame, w.index, w.seconds);
            return true;
        }
        const std::string where = m_where;
        m_where                 = w.where;
        m_failed                = false;
        fail("-o", w.err);
        m_where = where;
        m_frames_failed.push_back(w.frame);
        return false;
    };
    auto stop = [&]() {
        collect();
        if (m_runstats)
            print_runstats(run_timer());
        return 1;
    };

    for (size_t i = 0; i < frames.size(); ++i) {
        OIIO::Timer timer;
        m_stack.clear();
        m_writes.clear();
        m_datatypes.clear();
        m_failed = false;
        const std::vector<std::string> line = sequence ? args_for_frame(plan, frames[i]) : plan.args;
        const std::string frame_name = sequence ? format("frame {}", frames[i]) : std::string("the image");
        if (sequence) {
            m_frame_label = format("frame {}, {} of {}", frames[i], i + 1, frames.size());
            set_guard_frame(m_frame_label);
            m_where       = format(" ({}; {})", m_frame_label,
                                   m_skip_bad_frames ? "skipped, the run goes on" : "the run stopped here");
        }
        std::string why, stale;
        if (m_update && frame_up_to_date(line, why, stale)) {
            ++m_frames_skipped;
            if (m_verbosity > 0)
                std::cout << format("-u: {} skipped, up to date ({})\n", frame_name, why);
            continue;
        }
        if (!stale.empty() && m_verbosity > 0)
            std::cout << format("-u: {} made again: {}\n", frame_name, stale);
        // Pass 1 again for this frame (cheap): its command line, recorded in what it
        // writes, and its outputs' folders, checked before anything is computed.
        m_line_inputs.clear();
        m_line_outputs.clear();
        m_depth          = 0;
        bool ready       = parse(line, true);
        m_frame_recipe   = m_line_recipe;
        for (const std::string& out : m_line_outputs) {
            const std::string dir = OIIO::Filesystem::parent_path(out);
            if (ready && !dir.empty() && !OIIO::Filesystem::is_directory(dir))
                ready = fail("-o", format("{}: directory '{}' does not exist", out, dir));
        }
        if (!ready) {
            m_frames_failed.push_back(frames[i]);
            if (m_skip_bad_frames && sequence)
                continue;
            return stop();
        }
        if (overlap && i + 1 < frames.size()) {
            read_ahead(args_for_frame(plan, frames[i + 1]));
            m_failed = false;
        }
        if (!parse(line, false)) {
            m_frames_failed.push_back(frames[i]);
            if (m_skip_bad_frames && sequence)
                continue;
            return stop();
        }
        if (!overlap) {
            if (!write_pending()) {
                m_frames_failed.push_back(frames[i]);
                if (m_skip_bad_frames && sequence)
                    continue;
                return stop();
            }
            frame_done(frames[i], i, timer());
            continue;
        }
        // The previous frame's outputs are on disk before this frame's are started: at most
        // one frame's outputs in memory besides the frame being computed.
        if (!collect() && !m_skip_bad_frames)
            return stop();
        set_current("-o");
        writing = std::async(std::launch::async,
                             [this, writes = std::move(m_writes), frame = frames[i], i,
                              where = m_where, timer]() mutable {
                                 Written w;
                                 w.frame = frame, w.index = i, w.where = where;
                                 try {
                                     for (const PendingWrite& pw : writes)
                                         if (!(w.ok = write_checked(pw, w.err)))
                                             break;
                                 } catch (const std::bad_alloc&) {
                                     w.ok = false, w.err = "out of memory (std::bad_alloc)";
                                 } catch (const std::exception& e) {
                                     w.ok = false, w.err = format("failed with an exception: {}", e.what());
                                 }
                                 w.seconds = timer();
                                 return w;
                             });
        m_writes.clear();
    }
    if (!collect() && !m_skip_bad_frames)
        return stop();
    if (m_runstats)
        print_runstats(run_timer());
    if (!m_frames_failed.empty()) {
        std::vector<std::string> names;
        for (int f : m_frames_failed)
            names.push_back(std::to_string(f));
        std::cerr << format("{} ERROR: --skip-bad-frames: {} of {} frames failed: {}\n", kProgram,
                            m_frames_failed.size(), frames.size(), OIIO::Strutil::join(names, ", "));
        return 1;
    }
    return 0;
}

}  // namespace bokehtool
