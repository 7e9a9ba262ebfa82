// defocus_commands.cpp — `--defocus`: depth of field from an RGBA + Z image, with the
// lens, depth modes, aperture, method and diagnostics as options. The work is
// bokeh::defocus, bokeh::coc_map, bokeh::focal_plane_view and bokeh::layer_map
// (core/defocus/defocus.cpp, core/optics/lens.cpp); the options become bokeh::DefocusOptions in
// plugins/shared/defocus_options.cpp, which the Python module shares.

#include <bokeh/deep.h>
#include <bokeh/io.h>
#include <bokeh/defocus.h>
#include <bokeh/plugin.h>
#include <bokeh/truth.h>

#include "defocus_options.h"
#include "memory_budget.h"

#include <algorithm>

#include <OpenImageIO/strutil.h>

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using OIIO::Strutil::fmt::format;

bool defocus_command(CommandContext& c)
{
    bokeh::StackImage in = c.inputs[0];
    bokeh::DefocusOptions o;
    std::string err;
    if (!bokeh::with_named_depth(c.options, c.inputs[0].buf, in.buf, err))
        return c.fail(err);
    if (!bokeh::defocus_options_from(c.options, in.buf->spec(), o, err))
        return c.fail(err);
    bokeh::StackImage out = in;
    out.buf               = std::make_shared<OIIO::ImageBuf>();
    const std::string& what = c.options.get_string("output");
    o.deep_output           = what == "deep";
    // The diagnostics of a deep image are those of its flatten (Z: its nearest visible depth).
    const bool diagnostic = what == "coc" || what == "focalplane" || what == "layers";
    OIIO::ImageBuf flat;
    if (diagnostic && in.buf->deep() && !bokeh::deep_flatten(flat, *in.buf, {}, nullptr, c.nthreads))
        return c.fail(flat.geterror());
    const OIIO::ImageBuf& src = diagnostic && in.buf->deep() ? flat : *in.buf;
    const std::string& method = bokeh::defocus_method_named(c.options);
    for (const char* name : { "spp", "seed", "unknown", "pixel" })
        if (c.options.given(name) && method != "truth")
            return c.fail(format("{}= is for method=truth", name));
    if (o.supersample > 1 && what != "image" && what != "deep")
        return c.fail(format("supersample= gives a finer image; output={} is a map of the frame's pixels", what));
    if (o.aperture_views > 1 && what != "image" && what != "deep")
        return c.fail(format("views= composites the layers per sub-aperture; output={} is a map of the frame's pixels",
                             what));
    if (c.options.given("fill") && (method == "gather" || in.buf->deep()))
        return c.fail(method == "gather" ? "fill= is for the layered methods; the gather has its own edge blur"
                                         : "fill= is for flat images; a deep image holds the background it hides");
    bool ok;
    if (method == "truth") {
        // The thin-lens rays through the scene a deep image encodes (truth.h).
        if (!in.buf->deep())
            return c.fail("method=truth traces rays through a deep image; this one is flat (--deepen makes one)");
        if (o.lens_character)
            return c.fail("lens character (lens=, highlights=, sprites=, ...) is for the layered methods, not method=truth");
        if (what != "image")
            return c.fail(format("method=truth gives an image, not output={}", what));
        for (const char* name : { "layers", "ratio", "planner", "reduction", "budget", "bloom", "bloomgain", "iris", "zdilate",
                                  "step", "border", "views", "fill" })
            if (c.options.given(name))
                return c.fail(format("{}= does not apply to method=truth", name));
        bokeh::TruthOptions t;
        t.coc       = o.coc;
        t.aperture  = o.aperture;
        t.aspect    = o.aspect;
        t.grow      = o.grow;
        t.nonfinite = o.nonfinite;
        t.spp       = c.options.get_int("spp");
        // Each ray crosses one cell at least: the pixels' rays are the time's floor.
        const OIIO::ROI d = in.buf->roi();
        if (!bokeh::within_timeout(c, double(d.width()) * double(d.height()) * double(t.spp),
                                   format("a truth of {}x{} pixels at {} rays a pixel", d.width(), d.height(), t.spp)))
            return false;
        t.seed      = uint32_t(c.options.get_int("seed"));
        t.unknown   = c.options.get_bool("unknown");
        t.pixel     = c.options.get_string("pixel") == "area" ? bokeh::TruthPixel::Area : bokeh::TruthPixel::Centre;
        t.progress  = c.progress;
        bokeh::TruthReport report;
        ok = bokeh::defocus_truth(*out.buf, *in.buf, t, &report, c.nthreads);
        if (ok && c.verbosity >= 1)
            c.message("  defocus truth: " + report.summary);
    } else if (what == "coc")
        ok = bokeh::defocus_coc_map(*out.buf, src, o, c.nthreads);
    else if (what == "focalplane")
        ok = bokeh::focal_plane_view(*out.buf, src, o.coc, 32.0f, c.nthreads);
    else if (what == "layers")
        ok = bokeh::layer_map(*out.buf, src, o, c.nthreads);
    else {
        bokeh::DefocusReport report;
        o.progress = c.progress;
        o.memory_budget_bytes = c.memory_budget_bytes > 0 ? c.memory_budget_bytes : bokeh::default_memory_budget_bytes();
        o.memory_budget_hint  = "--maxmemory raises it";
        // The popped input is this command's alone (a copy kept elsewhere, as --dup makes,
        // holds its own reference): once the defocus holds its pixels, let it go. Neither
        // `in.buf` nor the source is read after the call.
        o.source_done = [&]() {
            in.buf.reset();
            c.inputs[0].buf.reset();
        };
        ok = bokeh::defocus(*out.buf, *in.buf, o, &report, c.nthreads);
        if (ok && c.verbosity >= 2) {
            c.message("  defocus " + report.summary);
            std::string layers;
            for (size_t i = 0; i < report.layer_coc_px.size() && i < 64; ++i)
                layers += format(" {:g}{}", report.layer_coc_px[i],
                                 report.layer_reduction[i] > 1 ? format("/{}", report.layer_reduction[i])
                                                               : std::string());
            if (!layers.empty())
                c.message(format("  layer CoC px (/reduction):{}{}", layers,
                                 report.layer_coc_px.size() > 64 ? " ..." : ""));
            // The plans the planner weighed that no other beats on both time and accuracy.
            std::string front;
            int on_front = 0;
            double best_db = -1e300;
            for (const bokeh::DefocusPlanEstimate& p : report.plans) {  // cheapest first
                if (p.predicted_psnr_db <= best_db && !p.chosen)
                    continue;
                best_db = std::max(best_db, p.predicted_psnr_db);
                ++on_front;
                front += format("\n    {:<9} {:<9} {:3} layers {:6.1f} dB {:8.1f} ms{}",
                                p.ladder_ratio == 1.0f ? std::string("exact") : format("ratio {:.3g}", p.ladder_ratio),
                                std::isinf(p.min_reduced_coc_px) ? std::string("full res")
                                                                 : format("q {:g}", p.min_reduced_coc_px),
                                p.layers, p.predicted_psnr_db, p.predicted_ms, p.chosen ? "  <- chosen" : "");
            }
            if (report.plans.size() > 1)
                c.message(format("  planner: {} plans weighed against budget {:g} dB; {} on the time/accuracy "
                                 "front (predicted, single thread):{}",
                                 report.plans.size(), o.budget_db, on_front, front));
        }
        if (ok && report.nonfinite.total() > 0 && c.verbosity >= 1)
            c.message(format("  warning: {} non-finite colour and {} non-finite depth values "
                             "replaced (colour by 0, depth by far)",
                             report.nonfinite.colour, report.nonfinite.depth));
    }
    if (!ok)
        return c.fail(out.buf->geterror());
    c.outputs.push_back(std::move(out));
    return true;
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command c = bokeh::make_command(
        "--defocus", "", 1,
        "Depth of field from RGBA + Z or a deep image: thin-lens CoC, aperture-shaped bokeh, "
        "nearer over farther (a deep image's hidden background revealed; output=deep keeps it "
        "deep; output=coc|focalplane|layers for diagnostics)",
        defocus_command);
    c.needs_scene_linear = true;
    c.options = {
        OptionSpec::Choice("method", { "auto", "layers", "gather", "reference", "truth" },
                           "auto: layers set by the budget; gather: hikita12312's blurred levels; "
                           "reference: exact, slow; truth: thin-lens rays through a deep image (spp=)"),
        OptionSpec::Choice("quality", { "auto", "layers", "gather", "reference", "truth" },
                           "the same as method"),
        OptionSpec::Choice("output", { "image", "deep", "coc", "focalplane", "layers" },
                           "image; deep (a deep input's result kept deep: a sample a layer); or a "
                           "diagnostic: signed CoC map, focal-plane view (near red, focus green, far "
                           "blue), layer map"),
        OptionSpec::Choice("unit", { "m", "cm", "mm", "in", "ft" }, "unit of the depth channel"),
        OptionSpec::Choice("math", { "depth", "far0", "far1", "direct" },
                           "depth channel holds: distance; 1/distance (far = 0); 1 - 1/distance "
                           "(far = 1); the signed CoC in px"),
        OptionSpec::String("zchannel", "",
                           "the depth channel by name (depth.Z: channel Z of a multipart file's "
                           "part depth); default: Z, else the one layer's *.Z"),
        OptionSpec::Bool("negate", false, "the depth channel is negated (ZDefocus -depth, ...)"),
        OptionSpec::Float("scale", 1.0, -1e4, 1e4, "math=direct: CoC px per unit"),
        OptionSpec::Float("range", 0.0, 0.0, 1e9, "in-focus range around the focus, depth units"),
        OptionSpec::Float("front", 1.0, 0.0, 1e3, "multiplies the CoC in front of focus"),
        OptionSpec::Float("back", 1.0, 0.0, 1e3, "multiplies the CoC behind focus"),
        OptionSpec::Float("maxcoc", 512.0, 0.0, 8192.0, "largest CoC diameter in px"),
        OptionSpec::Int("layers", 0, 0, 1024, "layers: count (0: from the CoC range and budget)"),
        OptionSpec::Float("ratio", 0.0, 0.0, 16.0,
                          "layers: ratio between neighbouring rungs of the CoC ladder (1: the exact rungs, "
                          "refused for deep volumes; 0: the planner's)"),
        OptionSpec::Choice("planner", { "steps", "predicted" },
                           "flat layers: steps: the budget's measured settings; predicted: the cheapest plan "
                           "whose predicted PSNR clears the budget (-v lists the plans weighed; its error "
                           "model reads 10 dB optimistic to 30 dB pessimistic: docs/methods/planner.md); "
                           "refused for deep images"),
        OptionSpec::Int("reduction", 16, 1, 16, "layers: coarsest buffer reduction (buffers are 1/1, 1/2, 1/4, 1/8, 1/16: the largest power of two up to it)"),
        OptionSpec::String("budget", "40dB", "accuracy budget, PSNR against the reference"),
        OptionSpec::Float("bloom", 1.0, -1e30, 1e30, "bloom threshold (unpremultiplied colour)"),
        OptionSpec::Float("bloomgain", 1.0, 0.0, 1e4, "gain above the bloom threshold (1: off)"),
        OptionSpec::Float("iris", 0.0, -1000.0, 1000.0,
                          "iris mode: average exp(iris * colour), return log / iris (0: off)"),
        OptionSpec::Int("zdilate", 0, 0, 64,
                        "px: each pixel takes the nearest depth around it (remedy for "
                        "anti-aliased depth halos)"),
        OptionSpec::Choice("border", { "clamp", "black", "mirror" }, "pixels past the data window"),
        OptionSpec::Choice("fill", { "smooth", "mirror", "foreground" },
                           "flat layers, reference: the background a blurred foreground uncovers inside its "
                           "silhouette; smooth: the surfaces around it continued (a depth-aware pull-push), "
                           "mirror: their texture mirrored across the silhouette, foreground: its own colour"),
        OptionSpec::Bool("grow", true, "grow the data window to hold the bokeh (within the display window)"),
        OptionSpec::Choice("nonfinite", { "zero", "error" },
                           "NaN/Inf: colour -> 0, depth -> far (counted, warned); or fail"),
        OptionSpec::Float("step", 0.25, 1.0 / 64.0, 8.0,
                          "reference: spacing px of the CoC grid its layers lie on (a pixel shared between the two around its CoC)"),
        OptionSpec::Int("views", 0, 0, 8,
                        "layers, reference: the aperture cut into views x views sub-apertures, the layers "
                        "composited for each (a blurred silhouette hides the background along its own rays; "
                        "views^2 passes with kernels 1/views as tall: 3.4x the time at views=4); 0: 1 for a "
                        "flat image, 2 for a deep one recording surfaces behind its defocused samples (method=auto)"),
        OptionSpec::Int("spp", 64, 1, 1048576, "truth: rays a pixel (the noise falls as 1/sqrt(spp))"),
        OptionSpec::Int("seed", 1, 0, 2147483647, "truth: the sampling sequence's scramble"),
        OptionSpec::Choice("pixel", { "centre", "area" },
                           "truth: where a pixel's rays start; centre: the deep pixel already holds its area's "
                           "average (nearer the physics); area: over the pixel's square as well"),
        OptionSpec::Bool("unknown", false,
                         "truth: add a channel 'unknown', each pixel's share of light from space the deep "
                         "image does not record (behind its samples)"),
    };
    // The lens and the aperture in their shared spelling (--scene's geometric truth takes
    // them too), at their places in the list: after output=, and after maxcoc=.
    std::vector<OptionSpec> lens = bokeh::thin_lens_option_specs();
    c.options.insert(c.options.begin() + 3, lens.begin(), lens.end());
    const auto after_maxcoc = std::find_if(c.options.begin(), c.options.end(),
                                           [](const OptionSpec& o) { return o.name == "maxcoc"; }) + 1;
    std::vector<OptionSpec> aperture = bokeh::defocus_aperture_option_specs();
    c.options.insert(after_maxcoc, aperture.begin(), aperture.end());
    // Lens character on the highlights (any of these switches it on).
    for (OptionSpec& spec : bokeh::defocus_sprite_option_specs())
        c.options.push_back(std::move(spec));
    r.add(c);
}
