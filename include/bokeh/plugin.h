// plugin.h — the command registry that bokehtool plugins fill.
//
// A plugin is a shared module that exports two C functions:
//
//     BOKEH_PLUGIN_EXPORT int  bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }
//     BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& registry);
//
// bokehtool loads its built-in plugin directory and every directory in BOKEH_PLUGIN_PATH,
// checks the ABI number, and calls the register function, which adds Commands. A command
// is thin: it reads its arguments and options, calls a library function, and pushes the
// result. The built-in commands are plugins too.
//
// The ABI number changes whenever anything in this header or in the types it exposes
// changes layout; the host refuses a module built for another number.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <OpenImageIO/imagebuf.h>

#define BOKEH_PLUGIN_ABI_VERSION 3
#define BOKEH_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))

namespace bokeh {

class ColorSystem;

/// One image on bokehtool's stack.
struct StackImage {
    std::shared_ptr<OIIO::ImageBuf> buf;
    std::string colorspace;  ///< the OCIO space the pixel values are encoded in
    std::string origin;      ///< the file or generator it came from, for messages
    /// Pixel type per channel name to write with (half stays half); filled on read and
    /// carried from a command's first input to its outputs by the host.
    std::map<std::string, OIIO::TypeDesc> file_types;
};

/// A typed option of a command, given as `--command:name=value`.
struct OptionSpec {
    enum class Type { Int, Float, String, Bool, Choice };
    std::string name;
    Type type = Type::String;
    std::string default_value;
    double min = -std::numeric_limits<double>::infinity();  ///< Int and Float: allowed range
    double max = std::numeric_limits<double>::infinity();
    std::vector<std::string> choices;                        ///< Choice: allowed words
    std::string help;

    static OptionSpec Int(std::string name, int def, double lo, double hi, std::string help);
    static OptionSpec Float(std::string name, double def, double lo, double hi, std::string help);
    static OptionSpec String(std::string name, std::string def, std::string help);
    static OptionSpec Bool(std::string name, bool def, std::string help);
    static OptionSpec Choice(std::string name, std::vector<std::string> words, std::string help);
};

/// Option values of one call, validated against the command's specs; every option has a
/// value (its default when not given).
class OptionValues {
public:
    int get_int(const std::string& name) const;
    double get_float(const std::string& name) const;
    bool get_bool(const std::string& name) const;
    const std::string& get_string(const std::string& name) const;
    bool given(const std::string& name) const;  ///< set on the command line

    std::map<std::string, std::string> values;
    std::map<std::string, bool> explicitly_given;
};

/// Parse `modifiers` ("kernel=disk:grow=1", the part after the command's first colon)
/// against `specs`. False + `err` naming the option for an unknown name, a value of the
/// wrong type, outside its range, not among the choices, or given twice.
bool parse_options(const std::vector<OptionSpec>& specs, std::string_view modifiers,
                   OptionValues& out, std::string& err);

/// Parse an image size "WxH" or "N" (= NxN); both positive. False if malformed.
bool parse_size(std::string_view text, int& width, int& height);

/// Parse a kernel extent "WxH" or "N" in pixels; finite, >= 0, fractions allowed.
bool parse_extent(std::string_view text, float& width, float& height);

/// Parse a finite decimal number filling the whole text ("-60", "0.87", "1e3"). False if
/// malformed or not finite.
bool parse_number(std::string_view text, double& value);

/// What a command is given and gives back.
struct CommandContext {
    std::vector<std::string> args;    ///< the command's own arguments, after the command
    OptionValues options;
    std::vector<StackImage> inputs;   ///< popped from the stack, bottom-most first
    std::vector<StackImage> outputs;  ///< pushed after the command returns, in order
    int nthreads   = 0;               ///< 0 = all cores
    int verbosity  = 1;               ///< 0 quiet, 1 normal, 2 verbose
    const ColorSystem* colors = nullptr;
    std::function<void(const std::string&)> message;  ///< informational output (stdout)
    /// The fraction (0..1) of a long command done, rising; set by the host under
    /// `--progress` (it prints a throttled line on stderr), empty otherwise. Hand it to the
    /// library's `progress` options as it is: an empty one costs them nothing.
    std::function<void(float)> progress;
    std::string error;                ///< why the command failed
    /// The memory a command may take for what the user's numbers ask it to make (the
    /// host's --maxmemory; 0: default_memory_budget_bytes(), half the machine). Last in
    /// the struct, so that plugins built before it still find every other field.
    int64_t memory_budget_bytes = 0;
    /// The run's --timeout in seconds (0: none), for commands whose cost the user's numbers
    /// set (a truth's rays): refused at once when even a lower bound of their time is past
    /// it. Last in the struct for the same reason.
    double timeout_seconds = 0.0;

    /// Record the reason and return false: `return ctx.fail("...")`.
    bool fail(std::string why)
    {
        error = std::move(why);
        return false;
    }
};

using CommandFunction = std::function<bool(CommandContext&)>;

/// A command of bokehtool.
struct Command {
    std::string name;       ///< with its dashes: "--blur"
    std::string arguments;  ///< names of its arguments, space separated ("WxH"), or empty
    std::string help;       ///< one line
    int inputs  = 0;        ///< images it pops from the stack
    int outputs = 1;        ///< images it pushes
    /// Where the options change how many images it pops (`--blur:kernel=image` takes the
    /// kernel from the stack too): that count for the given options; unset: `inputs`.
    std::function<int(const OptionValues&)> inputs_for;
    /// The host converts the inputs to the scene-linear working space first (filters do).
    bool needs_scene_linear = false;
    std::vector<OptionSpec> options;
    CommandFunction run;
    std::string plugin;     ///< set by the registry: the module that registered it

    int argument_count() const;
    /// The images it pops with these options.
    int input_count(const OptionValues& options) const
    {
        return inputs_for ? inputs_for(options) : inputs;
    }
};

/// A command taking `inputs` images and pushing one, with the fields most commands set.
Command make_command(std::string name, std::string arguments, int inputs, std::string help,
                     CommandFunction run, std::vector<OptionSpec> options = {});

/// The set of commands, filled by plugins.
class Registry {
public:
    /// Add a command. False (with error()) for an empty or dash-less name, a missing
    /// function, or a name already taken (naming the module that has it).
    bool add(Command cmd);
    const Command* find(std::string_view name) const;
    const std::vector<Command>& commands() const { return m_commands; }

    /// The module whose register function is running; the host sets it.
    void set_current_plugin(std::string plugin)
    {
        m_current = std::move(plugin);
        m_error.clear();
    }
    const std::string& error() const { return m_error; }
    /// Remove every command `plugin` registered (a module that failed half-way).
    void remove_plugin(const std::string& plugin);

private:
    std::vector<Command> m_commands;
    std::string m_current, m_error;
};

/// Load the plugin module at `path` and let it register its commands. False + `err`
/// (naming the file) when it cannot be loaded, lacks an entry point, was built for
/// another ABI number, throws, or registers a command whose name is taken; commands
/// added before such a failure are removed again, so a module loads whole or not at all.
bool load_plugin(Registry& registry, const std::string& path, std::string& err);

/// Signatures of the two entry points a plugin module exports.
using PluginAbiFunction      = int (*)();
using PluginRegisterFunction = void (*)(Registry&);
constexpr const char* kPluginAbiSymbol      = "bokeh_plugin_abi_version";
constexpr const char* kPluginRegisterSymbol = "bokeh_plugin_register";

}  // namespace bokeh
