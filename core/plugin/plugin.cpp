// plugin.cpp — the command registry, option parsing and plugin module loading.
//
// Options follow oiiotool's modifier grammar, `--cmd:name=value:name2=value2`; values
// are checked against typed specs here, once, so no command parses its own options.
// Modules are loaded with dlopen and must export the entry points named in plugin.h.
// Known limit: a plugin that crashes (rather than throws) inside its register function
// takes the host with it; only a separate process could guard against that.

#include <bokeh/plugin.h>

#include <dlfcn.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <exception>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

OptionSpec OptionSpec::Int(std::string name, int def, double lo, double hi, std::string help)
{
    OptionSpec s;
    s.name          = std::move(name);
    s.type          = Type::Int;
    s.default_value = std::to_string(def);
    s.min           = lo;
    s.max           = hi;
    s.help          = std::move(help);
    return s;
}

OptionSpec OptionSpec::Float(std::string name, double def, double lo, double hi, std::string help)
{
    OptionSpec s;
    s.name          = std::move(name);
    s.type          = Type::Float;
    s.default_value = format("{}", def);
    s.min           = lo;
    s.max           = hi;
    s.help          = std::move(help);
    return s;
}

OptionSpec OptionSpec::String(std::string name, std::string def, std::string help)
{
    OptionSpec s;
    s.name          = std::move(name);
    s.type          = Type::String;
    s.default_value = std::move(def);
    s.help          = std::move(help);
    return s;
}

OptionSpec OptionSpec::Bool(std::string name, bool def, std::string help)
{
    OptionSpec s;
    s.name          = std::move(name);
    s.type          = Type::Bool;
    s.default_value = def ? "1" : "0";
    s.help          = std::move(help);
    return s;
}

OptionSpec OptionSpec::Choice(std::string name, std::vector<std::string> words, std::string help)
{
    OptionSpec s;
    s.name          = std::move(name);
    s.type          = Type::Choice;
    s.default_value = words.empty() ? std::string() : words.front();
    s.choices       = std::move(words);
    s.help          = std::move(help);
    return s;
}

int OptionValues::get_int(const std::string& name) const
{
    return OIIO::Strutil::stoi(get_string(name));
}

double OptionValues::get_float(const std::string& name) const
{
    return OIIO::Strutil::stod(get_string(name));
}

bool OptionValues::get_bool(const std::string& name) const
{
    return get_string(name) == "1";
}

const std::string& OptionValues::get_string(const std::string& name) const
{
    static const std::string empty;
    auto it = values.find(name);
    return it == values.end() ? empty : it->second;
}

bool OptionValues::given(const std::string& name) const
{
    auto it = explicitly_given.find(name);
    return it != explicitly_given.end() && it->second;
}

// A plain decimal number, the whole of `s` (strtod would also take "0x3" as hex 3).
static bool parse_decimal(std::string_view s, float& v)
{
    if (s.empty())
        return false;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v, std::chars_format::general);
    return ec == std::errc() && end == s.data() + s.size();
}

// Check one value against its spec and store it in canonical form.
static bool set_option(const OptionSpec& spec, std::string_view text, OptionValues& out,
                       std::string& err)
{
    using Type = OptionSpec::Type;
    std::string value(text);
    switch (spec.type) {
    case Type::Int:
    case Type::Float: {
        OIIO::string_view sv(value);
        double v       = 0.0;
        bool ok        = false;
        if (spec.type == Type::Int) {
            int i = 0;
            ok    = OIIO::Strutil::parse_int(sv, i) && sv.empty();
            v     = i;
        } else {
            float f = 0.0f;
            ok      = parse_decimal(value, f) && std::isfinite(f);
            v       = f;
        }
        if (!ok) {
            err = format("option '{}' wants {} but got '{}'", spec.name,
                         spec.type == Type::Int ? "an integer" : "a finite number", value);
            return false;
        }
        if (v < spec.min || v > spec.max) {
            err = format("option '{}' = {} is out of range [{}, {}]", spec.name, value,
                         spec.min, spec.max);
            return false;
        }
        break;
    }
    case Type::Bool:
        if (value == "1" || value == "true" || value == "on" || value == "yes")
            value = "1";
        else if (value == "0" || value == "false" || value == "off" || value == "no")
            value = "0";
        else {
            err = format("option '{}' wants 0 or 1 but got '{}'", spec.name, value);
            return false;
        }
        break;
    case Type::Choice:
        if (std::find(spec.choices.begin(), spec.choices.end(), value) == spec.choices.end()) {
            err = format("option '{}' = '{}' is not one of: {}", spec.name, value,
                         OIIO::Strutil::join(spec.choices, ", "));
            return false;
        }
        break;
    case Type::String: break;
    }
    out.values[spec.name]           = value;
    out.explicitly_given[spec.name] = true;
    return true;
}

bool parse_options(const std::vector<OptionSpec>& specs, std::string_view modifiers,
                   OptionValues& out, std::string& err)
{
    out = OptionValues();
    for (const OptionSpec& s : specs) {
        out.values[s.name]           = s.default_value;
        out.explicitly_given[s.name] = false;
    }
    if (modifiers.empty())
        return true;
    const OptionSpec* last_string = nullptr;  // the option the previous item set, if a String
    for (const std::string& item : OIIO::Strutil::splits(modifiers, ":")) {
        if (item.empty())
            continue;
        const size_t eq        = item.find('=');
        const std::string name = item.substr(0, eq);
        auto spec = std::find_if(specs.begin(), specs.end(),
                                 [&](const OptionSpec& s) { return s.name == name; });
        // A piece without '=' naming no option continues a String value that holds a colon,
        // as oiiotool takes `-o:compression=dwaa:45`.
        if (spec == specs.end() && eq == std::string::npos && last_string) {
            out.values[last_string->name] += ":" + item;
            continue;
        }
        last_string = nullptr;
        if (spec == specs.end()) {
            std::vector<std::string> known;
            for (const OptionSpec& s : specs)
                known.push_back(s.name);
            err = known.empty() ? format("unknown option '{}' (this command has none)", name)
                                : format("unknown option '{}' (known: {})", name,
                                         OIIO::Strutil::join(known, ", "));
            return false;
        }
        // Twice (`kernel=disk:kernel=box`): one of the two would be dropped unseen.
        if (out.given(name)) {
            err = format("option '{}' is given twice", name);
            return false;
        }
        if (eq == std::string::npos) {
            // A bare name switches a Bool on, as in oiiotool's `--cmd:flag`.
            if (spec->type != OptionSpec::Type::Bool) {
                err = format("option '{}' needs a value ({}=...)", name, name);
                return false;
            }
            if (!set_option(*spec, "1", out, err))
                return false;
        } else if (!set_option(*spec, std::string_view(item).substr(eq + 1), out, err)) {
            return false;
        } else if (spec->type == OptionSpec::Type::String) {
            last_string = &*spec;
        }
    }
    return true;
}

bool parse_extent(std::string_view text, float& width, float& height)
{
    const size_t x = text.find('x');
    float w = 0.0f, h = 0.0f;
    if (!parse_decimal(text.substr(0, x), w))
        return false;
    if (x == std::string_view::npos)
        h = w;
    else if (!parse_decimal(text.substr(x + 1), h))
        return false;
    if (!std::isfinite(w) || !std::isfinite(h) || w < 0.0f || h < 0.0f)
        return false;
    width  = w;
    height = h;
    return true;
}

bool parse_number(std::string_view text, double& value)
{
    double v             = 0.0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v))
        return false;
    value = v;
    return true;
}

bool parse_size(std::string_view text, int& width, int& height)
{
    float w = 0.0f, h = 0.0f;
    if (!parse_extent(text, w, h) || w < 1.0f || h < 1.0f || w != std::floor(w)
        || h != std::floor(h) || w > 1e9f || h > 1e9f)
        return false;
    width  = int(w);
    height = int(h);
    return true;
}

Command make_command(std::string name, std::string arguments, int inputs, std::string help,
                     CommandFunction run, std::vector<OptionSpec> options)
{
    Command c;
    c.name      = std::move(name);
    c.arguments = std::move(arguments);
    c.inputs    = inputs;
    c.help      = std::move(help);
    c.run       = std::move(run);
    c.options   = std::move(options);
    return c;
}

int Command::argument_count() const
{
    return int(OIIO::Strutil::splits(arguments, " ").size());
}

bool Registry::add(Command cmd)
{
    if (cmd.name.size() < 2 || cmd.name[0] != '-') {
        m_error = format("command name '{}' must start with '-'", cmd.name);
        return false;
    }
    if (cmd.name.find_first_of(": \t") != std::string::npos) {
        m_error = format("command name '{}' may not contain ':' or spaces", cmd.name);
        return false;
    }
    if (!cmd.run) {
        m_error = format("command '{}' has no function", cmd.name);
        return false;
    }
    if (const Command* other = find(cmd.name)) {
        m_error = format("command '{}' is already defined by {}", cmd.name,
                         other->plugin.empty() ? std::string("the host") : other->plugin);
        return false;
    }
    cmd.plugin = m_current;
    m_commands.push_back(std::move(cmd));
    return true;
}

const Command* Registry::find(std::string_view name) const
{
    for (const Command& c : m_commands)
        if (c.name == name)
            return &c;
    return nullptr;
}

void Registry::remove_plugin(const std::string& plugin)
{
    m_commands.erase(std::remove_if(m_commands.begin(), m_commands.end(),
                                    [&](const Command& c) { return c.plugin == plugin; }),
                     m_commands.end());
}

bool load_plugin(Registry& registry, const std::string& path, std::string& err)
{
    // RTLD_LOCAL keeps one plugin's symbols from resolving another's.
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char* why = dlerror();
        err = format("plugin {}: cannot load: {}", path, why ? why : "unknown reason");
        return false;
    }
    auto abi = reinterpret_cast<PluginAbiFunction>(dlsym(handle, kPluginAbiSymbol));
    auto reg = reinterpret_cast<PluginRegisterFunction>(dlsym(handle, kPluginRegisterSymbol));
    if (!abi || !reg) {
        err = format("plugin {}: not an OpenBokeh plugin (missing {})", path,
                     !abi ? kPluginAbiSymbol : kPluginRegisterSymbol);
        dlclose(handle);
        return false;
    }
    const int version = abi();
    if (version != BOKEH_PLUGIN_ABI_VERSION) {
        err = format("plugin {}: built for plugin ABI {}, this bokehtool has ABI {}", path,
                     version, BOKEH_PLUGIN_ABI_VERSION);
        dlclose(handle);
        return false;
    }
    // The module stays loaded (never dlclose'd) once it may have registered functions.
    registry.set_current_plugin(path);
    std::string why;
    try {
        reg(registry);
        why = registry.error();
    } catch (const std::exception& e) {
        why = format("threw while registering: {}", e.what());
    } catch (...) {
        why = "threw while registering";
    }
    registry.set_current_plugin("");
    if (!why.empty()) {
        registry.remove_plugin(path);
        err = format("plugin {}: {}", path, why);
        return false;
    }
    return true;
}

}  // namespace bokeh
