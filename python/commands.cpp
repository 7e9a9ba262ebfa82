// commands.cpp — bokehtool's commands run from Python through the plugin registry
// (commands.h).

#include "commands.h"

#include <dlfcn.h>

#include <algorithm>
#include <exception>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>

#ifndef BOKEH_PLUGIN_FROM_LIBDIR
#    error "BOKEH_PLUGIN_FROM_LIBDIR (the plugin directory relative to the library's) must be defined"
#endif
#ifndef BOKEH_DATA_FROM_LIBDIR
#    error "BOKEH_DATA_FROM_LIBDIR (the data directory relative to the library's) must be defined"
#endif

namespace openbokeh_python {

using OIIO::Strutil::fmt::format;

// The directory libOpenBokeh was loaded from: the plugins and the shipped OCIO config lie
// at fixed places relative to it, in the build tree as when installed.
static std::string library_dir()
{
    Dl_info info{};
    if (!dladdr(reinterpret_cast<void*>(&bokeh::load_plugin), &info) || !info.dli_fname)
        throw std::runtime_error("cannot tell where libOpenBokeh was loaded from (dladdr failed)");
    return OIIO::Filesystem::parent_path(info.dli_fname);
}

Commands::Commands()
{
    const std::string lib = library_dir();
    m_plugin_dir          = lib + "/" + BOKEH_PLUGIN_FROM_LIBDIR;
    if (!OIIO::Filesystem::is_directory(m_plugin_dir))
        throw std::runtime_error(format("the plugin directory {} does not exist (beside {})",
                                        m_plugin_dir, lib));
    std::vector<std::string> files;
    OIIO::Filesystem::get_directory_entries(m_plugin_dir, files, false);
    std::sort(files.begin(), files.end());
    std::vector<std::string> failures;
    for (const std::string& f : files) {
        if (OIIO::Filesystem::extension(f) != ".so")
            continue;
        std::string err;
        if (!bokeh::load_plugin(m_registry, f, err))
            failures.push_back(err);
    }
    if (!failures.empty())
        throw std::runtime_error(OIIO::Strutil::join(failures, "; "));
    const std::string shipped = lib + "/" + BOKEH_DATA_FROM_LIBDIR + "/ocio/config.ocio";
    std::string err;
    if (!m_colors.load(bokeh::resolve_color_config("", shipped), err))
        throw std::runtime_error(format("the OCIO config: {}", err));
}

Commands& Commands::get()
{
    static Commands commands;  // a throw leaves it unmade; the next call tries again
    return commands;
}

const bokeh::Command& Commands::find(const std::string& name) const
{
    const bokeh::Command* c = m_registry.find(name);
    if (!c)
        throw std::runtime_error(format("no plugin in {} registers {}", m_plugin_dir, name));
    return *c;
}

std::string error_text(const std::string& function, const std::string& why)
{
    if (OIIO::Strutil::starts_with(why, function + ": "))
        return why;
    return function + ": " + why;
}

void warn(const std::string& text)
{
    PyErr_WarnEx(PyExc_RuntimeWarning, text.c_str(), 1);
    if (PyErr_Occurred())  // warnings turned into errors (-W error)
        throw py::error_already_set();
}

std::string option_text(const std::string& function, const std::string& name, const py::handle& value)
{
    const py::object numpy_generic = py::module_::import("numpy").attr("generic");
    if (py::isinstance<py::bool_>(value)
        || (py::isinstance(value, numpy_generic)
            && py::str(value.attr("dtype").attr("kind")).cast<std::string>() == "b"))
        return value.cast<bool>() ? "1" : "0";
    if (py::isinstance<py::str>(value)) {
        std::string s = value.cast<std::string>();
        // The command line's grammar separates options with ':'.
        if (s.find(':') != std::string::npos)
            throw py::value_error(format("{}: option '{}' = '{}': a value cannot hold ':'", function,
                                         name, s));
        return s;
    }
    if (py::isinstance<py::int_>(value)
        || (py::isinstance(value, numpy_generic)
            && std::string("iu").find(py::str(value.attr("dtype").attr("kind")).cast<std::string>())
                   != std::string::npos))
        return py::str(py::int_(py::reinterpret_borrow<py::object>(value))).cast<std::string>();
    if (py::isinstance<py::float_>(value) || py::isinstance(value, numpy_generic)) {
        try {
            return py::repr(py::float_(py::reinterpret_borrow<py::object>(value))).cast<std::string>();
        } catch (const py::error_already_set&) {
        }
    }
    throw py::type_error(format("{}: option '{}' takes a number, a bool or a str, not {}", function,
                                name,
                                py::str(py::type::of(value).attr("__name__")).cast<std::string>()));
}

bokeh::OptionValues options_from_kwargs(const std::string& function, const bokeh::Command& cmd,
                                        const py::dict& kw,
                                        const std::map<std::string, std::string>& fixed)
{
    std::vector<std::string> items;
    for (const auto& [key, value] : kw) {
        const std::string name = key.cast<std::string>();
        if (fixed.count(name))
            throw py::value_error(format("{}: option '{}' is set from the arguments; do not give it",
                                         function, name));
        if (value.is_none())
            continue;
        items.push_back(name + "=" + option_text(function, name, value));
    }
    for (const auto& [name, value] : fixed)
        items.push_back(name + "=" + value);
    bokeh::OptionValues values;
    std::string err;
    if (!bokeh::parse_options(cmd.options, OIIO::Strutil::join(items, ":"), values, err))
        throw py::value_error(error_text(function, err));
    return values;
}

std::vector<std::shared_ptr<OIIO::ImageBuf>> run_command(const std::string& function,
                                                         const bokeh::Command& cmd,
                                                         const std::vector<ImageArg>& inputs,
                                                         const std::vector<std::string>& args,
                                                         bokeh::OptionValues options, int nthreads)
{
    if (nthreads < 0 || nthreads > 1024)
        throw py::value_error(format("{}: threads = {} is not a thread count (0..1024, 0 = all cores)",
                                     function, nthreads));
    const Commands& commands = Commands::get();
    bokeh::CommandContext ctx;
    ctx.args      = args;
    ctx.options   = std::move(options);
    ctx.nthreads  = nthreads;
    ctx.verbosity = 1;
    ctx.colors    = &commands.colors();
    std::vector<std::string> messages;
    ctx.message = [&messages](const std::string& s) { messages.push_back(s); };
    if (int(inputs.size()) != cmd.input_count(ctx.options))
        throw std::logic_error(format("{}: {} takes {} image(s), the binding gave {}", function,
                                      cmd.name, cmd.input_count(ctx.options), inputs.size()));
    for (const ImageArg& in : inputs) {
        bokeh::StackImage img;
        img.buf        = in.buf;
        img.colorspace = commands.colors().scene_linear();
        img.origin     = in.origin;
        ctx.inputs.push_back(std::move(img));
    }
    bool ok = false;
    {
        py::gil_scoped_release release;
        try {
            ok = cmd.run(ctx);
        } catch (const std::exception& e) {
            ctx.error = format("failed with an exception: {}", e.what());
        } catch (...) {
            ctx.error = "failed with an unknown exception";
        }
    }
    // The warnings among the command's messages (bokehtool -v prints them all); the rest
    // (what was made, how long it took) is for the command line's verbose mode.
    for (const std::string& m : messages) {
        const std::string text(OIIO::Strutil::strip(m));
        if (OIIO::Strutil::starts_with(text, "warning:"))
            warn(function + ": " + text);
    }
    if (!ok)
        throw std::runtime_error(error_text(function, ctx.error.empty() ? "failed (no reason given)"
                                                                        : ctx.error));
    std::vector<std::shared_ptr<OIIO::ImageBuf>> outputs;
    for (bokeh::StackImage& out : ctx.outputs) {
        if (!out.buf || !out.buf->initialized())
            throw std::runtime_error(error_text(function, "produced no image"));
        outputs.push_back(std::move(out.buf));
    }
    return outputs;
}

std::string options_doc(const bokeh::Command& cmd, const std::vector<std::string>& skip)
{
    using Type = bokeh::OptionSpec::Type;
    std::string doc = format("Options (keyword arguments, as `bokehtool {}:NAME=VALUE`; None = the "
                             "default):\n",
                             cmd.name);
    for (const bokeh::OptionSpec& o : cmd.options) {
        if (std::find(skip.begin(), skip.end(), o.name) != skip.end())
            continue;
        std::string kind;
        switch (o.type) {
        case Type::Int: kind = format("int in [{}, {}]", o.min, o.max); break;
        case Type::Float: kind = format("float in [{}, {}]", o.min, o.max); break;
        case Type::Bool: kind = "bool"; break;
        case Type::String: kind = "str"; break;
        case Type::Choice: kind = "one of " + OIIO::Strutil::join(o.choices, "|"); break;
        }
        const std::string def = o.type == Type::Bool   ? (o.default_value == "1" ? "True" : "False")
                                : o.type == Type::Int || o.type == Type::Float ? o.default_value
                                                                              : "'" + o.default_value + "'";
        doc += format("    {}={} ({}): {}\n", o.name, def, kind, o.help);
    }
    return doc;
}

}  // namespace openbokeh_python
