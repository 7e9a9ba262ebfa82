// A plugin built for another ABI number: the host must refuse it by name.
#include <bokeh/plugin.h>

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION + 100; }
BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry&) {}
