// deep_commands.cpp — the deep compositing commands, in oiiotool's spelling where oiiotool
// has the command (--deepmerge, --deepholdout, --flatten, --deepen) plus --deeptidy and
// --deepslice. Each reads its arguments and calls one function of deep.h.
//
// Unlike oiiotool, --deepmerge keeps hidden samples unless :cull=1 (a deep defocus needs
// them to reveal what a foreground hides), merges any number of images (:n=), and
// --deepholdout keeps the result deep.

#include <bokeh/deep.h>
#include <bokeh/io.h>
#include <bokeh/plugin.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/strutil.h>

#include "memory_budget.h"

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using bokeh::StackImage;
using OIIO::Strutil::fmt::format;

OptionSpec nonfinite_option()
{
    return OptionSpec::Choice("nonfinite", { "zero", "error" },
                              "bad samples (NaN depth: dropped; ZBack < Z: made a point; NaN/Inf "
                              "colour: 0), counted and warned; or fail");
}

bokeh::DeepOptions deep_options(const CommandContext& c)
{
    bokeh::DeepOptions o;
    o.nonfinite = c.options.get_string("nonfinite") == "error" ? bokeh::NonFinitePolicy::Error
                                                                : bokeh::NonFinitePolicy::Zero;
    return o;
}

// Push `result` (made from the first input) or fail with its error; warn of repairs.
bool finish(CommandContext& c, std::shared_ptr<OIIO::ImageBuf> result, bool ok,
            const bokeh::DeepRepairs& repairs)
{
    if (!ok)
        return c.fail(result->geterror());
    if (repairs.total() > 0 && c.verbosity >= 1)
        c.message(format("  warning: {} bad deep samples repaired ({} with NaN depth dropped, {} with "
                         "ZBack < Z made points, {} NaN/Inf values set to 0)",
                         repairs.total(), repairs.nan_depth, repairs.back_before, repairs.nonfinite));
    StackImage out = c.inputs[0];
    out.buf        = std::move(result);
    c.outputs.push_back(std::move(out));
    return true;
}

// The command's result from `op(dst, options, report)`, a deep function of deep.h.
template<class Op> bool run_deep(CommandContext& c, Op&& op)
{
    bokeh::DeepRepairs rep;
    auto dst      = std::make_shared<OIIO::ImageBuf>();
    const bool ok = op(*dst, deep_options(c), &rep);
    return finish(c, dst, ok, rep);
}

bool tidy(CommandContext& c)
{
    return run_deep(c, [&](OIIO::ImageBuf& dst, const bokeh::DeepOptions& o, bokeh::DeepRepairs* rep) {
        return bokeh::deep_tidy(dst, *c.inputs[0].buf, o, rep, c.nthreads);
    });
}

bool merge(CommandContext& c)
{
    std::vector<const OIIO::ImageBuf*> srcs;
    // What the merge will hold before it is allocated, counted as a read counts a deep file
    // (io_budget.cpp: a pixel 16 + 8 x channels bytes, a sample a float a channel), twice:
    // the pooled image and its tidied copy (deep.h).
    int64_t samples = 0, channels = 0, pixels = 0;
    for (const StackImage& in : c.inputs) {
        srcs.push_back(in.buf.get());
        if (in.buf->deep() && in.buf->deepdata()) {
            const bokeh::DeepStats st = bokeh::deep_stats(*in.buf->deepdata());
            samples += st.total_samples;
            pixels   = std::max(pixels, st.pixels);
            channels = std::max<int64_t>(channels, in.buf->nchannels());
        }
    }
    if (!bokeh::within_memory_budget(c, 2 * (pixels * (16 + 8 * channels) + samples * 4 * channels),
                                     format("a merge of {} deep samples of {} channels", samples, channels)))
        return false;
    return run_deep(c, [&](OIIO::ImageBuf& dst, const bokeh::DeepOptions& o, bokeh::DeepRepairs* rep) {
        return bokeh::deep_merge(dst, srcs, c.options.get_bool("cull"), o, rep, c.nthreads);
    });
}

bool holdout(CommandContext& c)
{
    return run_deep(c, [&](OIIO::ImageBuf& dst, const bokeh::DeepOptions& o, bokeh::DeepRepairs* rep) {
        return bokeh::deep_holdout(dst, *c.inputs[0].buf, *c.inputs[1].buf, o, rep, c.nthreads);
    });
}

bool flatten(CommandContext& c)
{
    return run_deep(c, [&](OIIO::ImageBuf& dst, const bokeh::DeepOptions& o, bokeh::DeepRepairs* rep) {
        return bokeh::deep_flatten(dst, *c.inputs[0].buf, o, rep, c.nthreads);
    });
}

bool deepen(CommandContext& c)
{
    auto dst      = std::make_shared<OIIO::ImageBuf>();
    const bool ok = bokeh::deep_from_flat(*dst, *c.inputs[0].buf, float(c.options.get_float("z")), c.nthreads);
    return finish(c, dst, ok, {});
}

// A depth: a number, or inf / -inf.
bool parse_depth(const std::string& text, double& z)
{
    const std::string t = OIIO::Strutil::lower(text);
    if (t == "inf" || t == "+inf") {
        z = HUGE_VAL;
        return true;
    }
    if (t == "-inf") {
        z = -HUGE_VAL;
        return true;
    }
    OIIO::string_view sv(text);
    float f = 0.0f;
    if (!OIIO::Strutil::parse_float(sv, f) || !sv.empty() || !std::isfinite(f))
        return false;
    z = f;
    return true;
}

bool slice(CommandContext& c)
{
    double znear = 0.0, zfar = 0.0;
    if (!parse_depth(c.args[0], znear))
        return c.fail(format("NEAR '{}' is not a depth (a number, or -inf)", c.args[0]));
    if (!parse_depth(c.args[1], zfar))
        return c.fail(format("FAR '{}' is not a depth (a number, or inf)", c.args[1]));
    return run_deep(c, [&](OIIO::ImageBuf& dst, const bokeh::DeepOptions& o, bokeh::DeepRepairs* rep) {
        return bokeh::deep_slice(dst, *c.inputs[0].buf, znear, zfar, o, rep, c.nthreads);
    });
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    r.add(bokeh::make_command("--deeptidy", "", 1,
                              "Tidy a deep image by the OpenEXR rules: volumes split where samples "
                              "overlap, coincident samples merged, sorted by depth",
                              tidy, { nonfinite_option() }));

    bokeh::Command m = bokeh::make_command(
        "--deepmerge", "", 2,
        "Merge deep images (the top :n= of the stack; samples pooled and tidied). Keeps samples "
        "hidden behind opaque ones unless :cull=1 (oiiotool always culls)",
        merge,
        { OptionSpec::Int("n", 2, 2, 1024, "how many images to merge, from the top of the stack"),
          OptionSpec::Bool("cull", false,
                           "drop samples behind an accumulated opacity of 1 (what a flatten cannot see)"),
          nonfinite_option() });
    m.inputs_for = [](const bokeh::OptionValues& v) { return v.get_int("n"); };
    r.add(m);

    r.add(bokeh::make_command("--deepholdout", "", 2,
                              "Hold out the deep image below the top by the top one: each sample "
                              "times the holdout's transmittance in front of it (exact; stays deep)",
                              holdout, { nonfinite_option() }));
    r.add(bokeh::make_command("--flatten", "", 1,
                              "Composite a deep image front to back into a flat one (tidied first); "
                              "Z, ZBack = where the samples with alpha begin and end (1e30 where empty)",
                              flatten, { nonfinite_option() }));
    r.add(bokeh::make_command("--deepen", "", 1,
                              "Make a flat image deep: one sample a pixel (none where it is empty)",
                              deepen,
                              { OptionSpec::Float("z", 1.0, -1e30, 1e30,
                                                  "depth of the samples when the image has no Z channel") }));
    r.add(bokeh::make_command("--deepslice", "NEAR FAR", 1,
                              "Keep the part of a deep image in the depth range [NEAR, FAR) (volumes "
                              "split at its ends; inf allowed)",
                              slice, { nonfinite_option() }));
}
