// commands.h — the Python functions that are bokehtool commands run them through the same
// registry bokehtool uses: the built-in plugin modules are loaded from beside
// libOpenBokeh (the build tree mirrors the install tree), keyword arguments become the
// command's options, checked by bokeh::parse_options against the command's own specs
// (so names, defaults, ranges and messages are the command line's), and the command's
// function runs with the GIL released. Nothing here parses an option by itself.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <pybind11/pybind11.h>

#include <bokeh/color.h>
#include <bokeh/plugin.h>

#include "images.h"

namespace openbokeh_python {

namespace py = pybind11;

/// The registry with the built-in plugins, and the colour system the commands see.
class Commands {
public:
    /// Loaded on first use; std::runtime_error naming what failed (a plugin module, the
    /// OCIO config).
    static Commands& get();
    /// The command `name` ("--blur"); std::runtime_error when no plugin registered it.
    const bokeh::Command& find(const std::string& name) const;
    const bokeh::ColorSystem& colors() const { return m_colors; }
    const std::string& plugin_dir() const { return m_plugin_dir; }

private:
    Commands();
    bokeh::Registry m_registry;
    bokeh::ColorSystem m_colors;
    std::string m_plugin_dir;
};

/// The keyword arguments `kw` as `cmd`'s options, with `fixed` (options the binding sets
/// from its own arguments, which `kw` may not give). ValueError "function: reason" for an
/// unknown name, a value of the wrong type, out of range or not among the choices; None
/// means "not given" (the default).
bokeh::OptionValues options_from_kwargs(const std::string& function, const bokeh::Command& cmd,
                                        const py::dict& kw,
                                        const std::map<std::string, std::string>& fixed = {});

/// A Python number, bool or str as the command line writes it ("1"/"0" for a bool).
std::string option_text(const std::string& function, const std::string& name, const py::handle& value);

/// Run `cmd` on `inputs` (bottom of the stack first) with its arguments and options,
/// the GIL released while it works. RuntimeError "function: the command's message" on
/// failure; what the command says (warnings: repaired samples, replaced NaNs) is issued
/// as a Python RuntimeWarning. Returns its output images.
std::vector<std::shared_ptr<OIIO::ImageBuf>> run_command(const std::string& function,
                                                         const bokeh::Command& cmd,
                                                         const std::vector<ImageArg>& inputs,
                                                         const std::vector<std::string>& args,
                                                         bokeh::OptionValues options, int nthreads);

/// "function: why", without the function's name twice when the library already led with it.
std::string error_text(const std::string& function, const std::string& why);

/// The docstring section listing `cmd`'s options: name, default, allowed values, help.
std::string options_doc(const bokeh::Command& cmd, const std::vector<std::string>& skip = {});

/// Issue `text` as a Python RuntimeWarning (the GIL held).
void warn(const std::string& text);

}  // namespace openbokeh_python
