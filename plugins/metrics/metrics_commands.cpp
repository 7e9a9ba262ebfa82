// metrics_commands.cpp — `--diff`: how far the top image is from the one below it (the
// reference), as RMSE, tone-mapped PSNR and max error (bokeh::compare, core/metrics/metrics.cpp).
// Like oiiotool's --diff it consumes both images; unlike it, it does not fail on a
// difference: `:fail=DB` makes it fail below a PSNR, for scripts.

#include <bokeh/metrics.h>
#include <bokeh/plugin.h>

#include <OpenImageIO/strutil.h>

namespace {

using OIIO::Strutil::fmt::format;

bool diff_command(bokeh::CommandContext& c)
{
    bokeh::ImageError e;
    std::string err;
    if (!bokeh::compare(e, *c.inputs[1].buf, *c.inputs[0].buf, err, {}, c.nthreads))
        return c.fail(err);
    // inputs[1] is the top image, inputs[0] the reference below it; each is named by what
    // made it (a file, or the file and the commands applied).
    c.message(format("diff {} against the reference {}: RMSE {:.6g}, PSNR {:.2f} dB (x/(1+x) tone "
                     "map), max {:.6g}{}",
                     c.inputs[1].origin, c.inputs[0].origin, e.rmse_linear, e.psnr_db, e.max_abs,
                     e.nonfinite > 0 ? format(" ({} values NaN or infinite on one side only)", e.nonfinite)
                                     : std::string()));
    const double fail_db = c.options.get_float("fail");
    if (fail_db > 0.0 && e.psnr_db < fail_db)
        return c.fail(format("PSNR {:.2f} dB is below {:g} dB", e.psnr_db, fail_db));
    return true;
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command c = bokeh::make_command(
        "--diff", "", 2,
        "Print RMSE, PSNR (after x/(1+x)) and max error of the top image against the one "
        "below it (the reference); both are consumed",
        diff_command,
        { bokeh::OptionSpec::Float("fail", 0.0, 0.0, 999.0, "fail when the PSNR is below this (0: never)") });
    c.outputs = 0;
    r.add(c);
}
