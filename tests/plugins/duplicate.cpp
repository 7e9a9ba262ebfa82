// A plugin that defines a command the built-in plugin already has.
#include <bokeh/plugin.h>

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }
BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command c;
    c.name   = "--ch";
    c.inputs = 1;
    c.run    = [](bokeh::CommandContext&) { return true; };
    r.add(c);
}
