// A plugin whose register function throws after adding a command: the host must report
// it by name and keep none of its commands.
#include <bokeh/plugin.h>

#include <stdexcept>

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }
BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command c;
    c.name = "--half-registered";
    c.run  = [](bokeh::CommandContext&) { return true; };
    r.add(c);
    throw std::runtime_error("deliberate failure");
}
