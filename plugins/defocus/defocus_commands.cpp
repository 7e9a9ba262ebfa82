// defocus_commands.cpp — `--defocus`: depth of field from an RGBA + Z image, with the
// lens, depth modes, aperture, method and diagnostics as options. The work is
// bokeh::defocus, bokeh::coc_map, bokeh::focal_plane_view and bokeh::layer_map
// (core/defocus.cpp, core/lens.cpp).

#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/plugin.h>

#include "aperture_options.h"

#include <charconv>
#include <cmath>

#include <OpenImageIO/strutil.h>

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using OIIO::Strutil::fmt::format;

bool parse_number(std::string_view s, double& v)
{
    const char* end = s.data() + s.size();
    auto r          = std::from_chars(s.data(), end, v);
    return r.ec == std::errc() && r.ptr == end && std::isfinite(v);
}

// Millimetres per unit of the depth channel.
bool unit_mm(const std::string& u, double& mm)
{
    static const std::pair<const char*, double> units[] = {
        { "m", 1000.0 }, { "cm", 10.0 }, { "mm", 1.0 }, { "in", 25.4 }, { "ft", 304.8 }
    };
    for (const auto& [name, value] : units)
        if (u == name) {
            mm = value;
            return true;
        }
    return false;
}

bool read_options(CommandContext& c, const OIIO::ImageSpec& spec, bokeh::DefocusOptions& o)
{
    const bokeh::OptionValues& v = c.options;
    bokeh::CocOptions& coc       = o.coc;
    // Camera facts recorded in the image (our scenes write these) unless given.
    coc.lens.focal_mm = v.given("focal") ? v.get_float("focal")
                                         : spec.get_float_attribute("bokeh:focal_mm", 50.0f);
    coc.lens.fstop    = v.get_float("fstop");
    const std::string& sensor = v.get_string("sensor");
    if (!v.given("sensor"))
        coc.lens.sensor_width_mm = spec.get_float_attribute("bokeh:sensor_width_mm", 36.0f);
    else if (!bokeh::film_back_width(sensor, coc.lens.sensor_width_mm)
             && !parse_number(sensor, coc.lens.sensor_width_mm)) {
        std::string names;
        for (const bokeh::FilmBack& b : bokeh::film_backs())
            names += std::string(names.empty() ? "" : ", ") + b.name;
        return c.fail(format("sensor '{}' is neither a width in mm nor a film back ({})", sensor, names));
    }
    if (!unit_mm(v.get_string("unit"), coc.lens.depth_unit_mm))
        return c.fail(format("unit '{}' is not one of m, cm, mm, in, ft", v.get_string("unit")));

    const std::string& focus = v.get_string("focus");
    if (focus.find(',') != std::string::npos) {
        std::vector<std::string> xy;
        OIIO::Strutil::split(focus, xy, ",");
        double fx, fy;
        if (xy.size() != 2 || !parse_number(xy[0], fx) || !parse_number(xy[1], fy)
            || fx != std::floor(fx) || fy != std::floor(fy) || std::abs(fx) > 1e9 || std::abs(fy) > 1e9)
            return c.fail(format("focus '{}' is neither a distance nor a pixel x,y", focus));
        coc.focus_at_pixel = true;
        coc.focus_x        = int(fx);
        coc.focus_y        = int(fy);
    } else if (!parse_number(focus, coc.lens.focus_distance)) {
        return c.fail(format("focus '{}' is neither a distance nor a pixel x,y", focus));
    }
    const std::string& math = v.get_string("math");
    coc.mode = math == "direct" ? bokeh::DepthMode::Direct
               : math == "far0" ? bokeh::DepthMode::InverseDepth
               : math == "far1" ? bokeh::DepthMode::FarIsOne
                                : bokeh::DepthMode::Depth;
    coc.negate        = v.get_bool("negate");
    coc.direct_scale  = v.get_float("scale");
    coc.infocus_range = v.get_float("range");
    coc.front_gain    = v.get_float("front");
    coc.back_gain     = v.get_float("back");
    coc.max_coc_px    = v.get_float("maxcoc");

    const std::string& shape = v.get_string("kernel");
    std::string why;
    if (!bokeh::aperture_options_apply(v, shape, why))
        return c.fail(why);
    o.aperture.shape  = shape == "disk" ? bokeh::KernelShape::Disk : bokeh::KernelShape::Polygon;
    o.aperture.blades = shape == "hex" ? 6 : v.get_int("blades");
    o.aperture.rotation_deg = float(v.get_float("rotation"));
    o.aperture.curvature    = float(v.get_float("curvature"));
    o.aperture.hole         = float(v.get_float("hole"));
    o.aspect                = float(v.get_float("aspect"));

    // quality= and method= are one option under two spellings (method= the docs' and -v's).
    if (v.given("quality") && v.given("method") && v.get_string("quality") != v.get_string("method"))
        return c.fail(format("quality={} and method={} disagree; give one", v.get_string("quality"),
                             v.get_string("method")));
    const std::string& method = v.given("quality") ? v.get_string("quality") : v.get_string("method");
    o.method = method == "layers"      ? bokeh::DefocusMethod::Layers
               : method == "gather"    ? bokeh::DefocusMethod::Gather
               : method == "reference" ? bokeh::DefocusMethod::Reference
                                       : bokeh::DefocusMethod::Auto;
    o.layers        = v.get_int("layers");
    o.max_reduction = v.get_int("reduction");
    std::string budget = v.get_string("budget");
    if (OIIO::Strutil::iends_with(budget, "db"))
        budget.resize(budget.size() - 2);
    double budget_db;
    if (!parse_number(budget, budget_db) || budget_db <= 0.0 || budget_db > 120.0)
        return c.fail(format("budget '{}' is not a PSNR in dB within 0..120 (e.g. 40dB)",
                             v.get_string("budget")));
    o.budget_db       = float(budget_db);
    o.bloom_threshold = float(v.get_float("bloom"));
    o.bloom_gain      = float(v.get_float("bloomgain"));
    o.iris            = float(v.get_float("iris"));
    o.depth_dilate_px = v.get_int("zdilate");
    const std::string& border = v.get_string("border");
    o.border = border == "black"    ? bokeh::Border::Black
               : border == "mirror" ? bokeh::Border::Mirror
                                    : bokeh::Border::Clamp;
    o.grow      = v.get_bool("grow");
    o.nonfinite = v.get_string("nonfinite") == "error" ? bokeh::NonFinitePolicy::Error
                                                       : bokeh::NonFinitePolicy::Zero;
    o.reference_step_px = float(v.get_float("step"));
    return true;
}

bool defocus_command(CommandContext& c)
{
    const bokeh::StackImage& in = c.inputs[0];
    bokeh::DefocusOptions o;
    if (!read_options(c, in.buf->spec(), o))
        return false;
    bokeh::StackImage out = in;
    out.buf               = std::make_shared<OIIO::ImageBuf>();
    const std::string& what = c.options.get_string("output");
    o.deep_output           = what == "deep";
    // The diagnostics of a deep image are those of its flatten (Z: its nearest visible depth).
    const bool diagnostic = what == "coc" || what == "focalplane" || what == "layers";
    OIIO::ImageBuf flat;
    if (diagnostic && in.buf->deep() && !bokeh::flatten(flat, *in.buf, {}, c.nthreads))
        return c.fail(flat.geterror());
    const OIIO::ImageBuf& src = diagnostic && in.buf->deep() ? flat : *in.buf;
    bool ok;
    if (what == "coc")
        ok = bokeh::coc_map(*out.buf, src, o.coc, c.nthreads);
    else if (what == "focalplane")
        ok = bokeh::focal_plane_view(*out.buf, src, o.coc, 32.0f, c.nthreads);
    else if (what == "layers")
        ok = bokeh::layer_map(*out.buf, src, o, c.nthreads);
    else {
        bokeh::DefocusReport report;
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
        OptionSpec::Choice("method", { "auto", "layers", "gather", "reference" },
                           "auto: layers set by the budget; gather: the seed's method; "
                           "reference: exact, slow"),
        OptionSpec::Choice("quality", { "auto", "layers", "gather", "reference" },
                           "the same as method"),
        OptionSpec::Choice("output", { "image", "deep", "coc", "focalplane", "layers" },
                           "image; deep (a deep input's result kept deep: a sample a layer); or a "
                           "diagnostic: signed CoC map, focal-plane view (near red, focus green, far "
                           "blue), layer map"),
        OptionSpec::String("focus", "5", "focus distance in depth units, or a pixel x,y to sample"),
        OptionSpec::Float("fstop", 2.8, 0.5, 1e4, "f-number"),
        OptionSpec::Float("focal", 50.0, 0.1, 1e5, "focal length mm (default: image's bokeh:focal_mm, else 50)"),
        OptionSpec::String("sensor", "36",
                           "film back width in mm or a preset (ff, super35, alexa-lf, ...); "
                           "default: image's bokeh:sensor_width_mm, else 36"),
        OptionSpec::Choice("unit", { "m", "cm", "mm", "in", "ft" }, "unit of the depth channel"),
        OptionSpec::Choice("math", { "depth", "far0", "far1", "direct" },
                           "depth channel holds: distance; 1/distance (far = 0); 1 - 1/distance "
                           "(far = 1); the signed CoC in px"),
        OptionSpec::Bool("negate", false, "the depth channel is negated (ZDefocus -depth, ...)"),
        OptionSpec::Float("scale", 1.0, -1e4, 1e4, "math=direct: CoC px per unit"),
        OptionSpec::Float("range", 0.0, 0.0, 1e9, "in-focus range around the focus, depth units"),
        OptionSpec::Float("front", 1.0, 0.0, 1e3, "multiplies the CoC in front of focus"),
        OptionSpec::Float("back", 1.0, 0.0, 1e3, "multiplies the CoC behind focus"),
        OptionSpec::Float("maxcoc", 512.0, 0.0, 8192.0, "largest CoC diameter in px"),
        OptionSpec::Choice("kernel", { "disk", "hex", "polygon" }, "aperture shape"),
        OptionSpec::Int("blades", 6, 3, 64, "polygon: aperture blades"),
        OptionSpec::Float("rotation", 0.0, -360.0, 360.0, "polygon and hex: degrees"),
        OptionSpec::Float("curvature", 0.0, 0.0, 1.0, "polygon and hex: 0 straight blades .. 1 circle"),
        OptionSpec::Float("hole", 0.0, 0.0, 0.95, "catadioptric hole (radius fraction)"),
        OptionSpec::Float("aspect", 1.0, 0.05, 20.0, "bokeh height / width (anamorphic squeeze)"),
        OptionSpec::Int("layers", 0, 0, 1024, "layers: count (0: from the CoC range and budget)"),
        OptionSpec::Int("reduction", 16, 1, 16, "layers: coarsest buffer reduction (1, 2, 4, 8, 16)"),
        OptionSpec::String("budget", "40dB", "accuracy budget, PSNR against the reference"),
        OptionSpec::Float("bloom", 1.0, -1e30, 1e30, "bloom threshold (unpremultiplied colour)"),
        OptionSpec::Float("bloomgain", 1.0, 0.0, 1e4, "gain above the bloom threshold (1: off)"),
        OptionSpec::Float("iris", 0.0, -1000.0, 1000.0,
                          "iris mode: average exp(iris * colour), return log / iris (0: off)"),
        OptionSpec::Int("zdilate", 0, 0, 64,
                        "px: each pixel takes the nearest depth around it (remedy for "
                        "anti-aliased depth halos)"),
        OptionSpec::Choice("border", { "clamp", "black", "mirror" }, "pixels past the data window"),
        OptionSpec::Bool("grow", true, "grow the data window to hold the bokeh (within the display window)"),
        OptionSpec::Choice("nonfinite", { "zero", "error" },
                           "NaN/Inf: colour -> 0, depth -> far (counted, warned); or fail"),
        OptionSpec::Float("step", 0.25, 1.0 / 64.0, 8.0, "reference: CoC quantisation step px"),
    };
    r.add(c);
}
