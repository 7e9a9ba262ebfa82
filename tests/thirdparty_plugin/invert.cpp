// A third-party command: --invert replaces colour c by (gain - c), alpha and depth kept.
#include <bokeh/plugin.h>

#include <OpenImageIO/imagebufalgo.h>

namespace {

bool invert(bokeh::CommandContext& c)
{
    const float gain = float(c.options.get_float("gain"));
    auto out         = std::make_shared<OIIO::ImageBuf>(*c.inputs[0].buf);
    const int nc     = std::min(3, out->nchannels());
    for (OIIO::ImageBuf::Iterator<float> it(*out); !it.done(); ++it)
        for (int ch = 0; ch < nc; ++ch)
            it[ch] = gain - it[ch];
    bokeh::StackImage result = c.inputs[0];
    result.buf               = out;
    c.outputs.push_back(result);
    return true;
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command c;
    c.name                = "--invert";
    c.help                = "Replace colour c by gain - c (a third-party example)";
    c.inputs              = 1;
    c.needs_scene_linear  = true;
    c.options             = { bokeh::OptionSpec::Float("gain", 1.0, 0.0, 100.0, "value to subtract from") };
    c.run                 = invert;
    r.add(c);
}
