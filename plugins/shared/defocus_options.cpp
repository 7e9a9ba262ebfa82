// defocus_options.cpp — `--defocus`'s option values made into bokeh::DefocusOptions (see
// defocus_options.h): the lens (camera facts from the image's metadata unless given), the
// depth interpretation, the aperture, the method and its budget, bloom, iris, borders and
// lens character (highlights scattered with the lens's PSF).

#include "defocus_options.h"

#include "aperture_options.h"
#include "lens_options.h"

#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {

bool fail(std::string& err, std::string why)
{
    err = std::move(why);
    return false;
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

}  // namespace

const std::string& defocus_method_named(const OptionValues& v)
{
    return v.given("quality") ? v.get_string("quality") : v.get_string("method");
}

bool with_named_depth(const OptionValues& v, const std::shared_ptr<OIIO::ImageBuf>& in,
                      std::shared_ptr<OIIO::ImageBuf>& out, std::string& err)
{
    out                     = in;
    const std::string& name = v.get_string("zchannel");
    if (name.empty())
        return true;
    if (in->deep()) {
        err = "zchannel= names the depth of a flat image; a deep image's is its Z";
        return false;
    }
    std::string why;
    const int z = channel_index_named(in->spec(), name, why);
    if (z < 0) {
        err = "zchannel=" + name + ": " + why;
        return false;
    }
    out                        = std::make_shared<OIIO::ImageBuf>(*in);
    out->specmod().z_channel   = z;
    return true;
}

std::vector<OptionSpec> thin_lens_option_specs()
{
    std::vector<OptionSpec> v = {
        OptionSpec::String("focus", "5", "focus distance in depth units, or a pixel x,y to sample "
                           "(default: image's bokeh:focus_m, else 5)"),
    };
    for (OptionSpec& o : camera_option_specs(true))
        v.push_back(std::move(o));
    return v;
}

std::vector<OptionSpec> defocus_aperture_option_specs()
{
    std::vector<OptionSpec> v = { OptionSpec::Choice("kernel", aperture_kernel_names(), "aperture shape") };
    for (OptionSpec& o : aperture_shape_option_specs())
        v.push_back(std::move(o));
    v.push_back(aspect_option_spec());
    return v;
}

bool thin_lens_from(const OptionValues& v, const OIIO::ImageSpec& spec, CocOptions& coc, std::string& err)
{
    // Camera facts recorded in the image (the built-in scenes write these; a pipeline may
    // with --attrib) unless given: one rule for --defocus and --scene's truth.
    coc.lens.focal_mm        = 50.0;
    coc.lens.sensor_width_mm = 36.0;
    coc.lens.fstop           = 2.8;
    double focus_m           = std::numeric_limits<double>::quiet_NaN();
    if (!metadata_number(spec, "bokeh:focal_mm", coc.lens.focal_mm, err)
        || !metadata_number(spec, "bokeh:sensor_width_mm", coc.lens.sensor_width_mm, err)
        || !metadata_number(spec, "bokeh:fstop", coc.lens.fstop, err)
        || !metadata_number(spec, "bokeh:focus_m", focus_m, err))
        return false;
    // A recorded lens is held to the options' own ranges, so a bad header is refused as a
    // bad option would be (naming the attribute) instead of dividing by it.
    const auto in_range = [&](const char* option, const char* attribute, double value) {
        for (const OptionSpec& o : thin_lens_option_specs())
            if (o.name == option && (value < o.min || value > o.max))
                return fail(err, format("metadata {} is {:g}, outside {}='s range {:g}..{:g}",
                                        attribute, value, option, o.min, o.max));
        return true;
    };
    if (!in_range("focal", "bokeh:focal_mm", coc.lens.focal_mm)
        || !in_range("fstop", "bokeh:fstop", coc.lens.fstop))
        return false;
    if (!(coc.lens.sensor_width_mm > 0.0))
        return fail(err, format("metadata bokeh:sensor_width_mm is {:g}, not a width in mm",
                                coc.lens.sensor_width_mm));
    if (!std::isnan(focus_m) && !(focus_m > 0.0))
        return fail(err, format("metadata bokeh:focus_m is {:g}, not a distance", focus_m));
    if (v.given("focal"))
        coc.lens.focal_mm = v.get_float("focal");
    if (v.given("fstop"))
        coc.lens.fstop = v.get_float("fstop");
    const std::string& sensor = v.get_string("sensor");
    if (v.given("sensor") && !film_back_width(sensor, coc.lens.sensor_width_mm)
        && !parse_number(sensor, coc.lens.sensor_width_mm)) {
        std::string names;
        for (const FilmBack& b : film_backs())
            names += std::string(names.empty() ? "" : ", ") + b.name;
        return fail(err, format("sensor '{}' is neither a width in mm nor a film back ({})", sensor, names));
    }

    if (!v.given("focus") && !std::isnan(focus_m)) {
        coc.lens.focus_distance = focus_m * 1000.0 / coc.lens.depth_unit_mm;
        return true;
    }
    const std::string& focus = v.get_string("focus");
    if (focus.find(',') != std::string::npos) {
        std::vector<std::string> xy;
        OIIO::Strutil::split(focus, xy, ",");
        double fx, fy;
        if (xy.size() != 2 || !parse_number(xy[0], fx) || !parse_number(xy[1], fy)
            || fx != std::floor(fx) || fy != std::floor(fy) || std::abs(fx) > 1e9 || std::abs(fy) > 1e9)
            return fail(err, format("focus '{}' is neither a distance nor a pixel x,y", focus));
        coc.focus_at_pixel = true;
        coc.focus_x        = int(fx);
        coc.focus_y        = int(fy);
    } else if (!parse_number(focus, coc.lens.focus_distance)) {
        return fail(err, format("focus '{}' is neither a distance nor a pixel x,y", focus));
    }
    return true;
}

bool defocus_options_from(const OptionValues& v, const OIIO::ImageSpec& spec, DefocusOptions& o,
                          std::string& err)
{
    CocOptions& coc = o.coc;
    // The unit first: a focus distance recorded in the metadata (metres) is converted to it.
    if (!unit_mm(v.get_string("unit"), coc.lens.depth_unit_mm))
        return fail(err, format("unit '{}' is not one of m, cm, mm, in, ft", v.get_string("unit")));
    if (!thin_lens_from(v, spec, coc, err))
        return false;
    const std::string& math = v.get_string("math");
    coc.mode = math == "direct" ? DepthMode::Direct
               : math == "far0" ? DepthMode::InverseDepth
               : math == "far1" ? DepthMode::FarIsOne
                                : DepthMode::Depth;
    coc.negate        = v.get_bool("negate");
    coc.direct_scale  = v.get_float("scale");
    coc.infocus_range = v.get_float("range");
    coc.front_gain    = v.get_float("front");
    coc.back_gain     = v.get_float("back");
    coc.max_coc_px    = v.get_float("maxcoc");

    std::string why;
    if (!aperture_kernel_from(v, o.aperture, why))
        return fail(err, why);
    o.aspect = float(v.get_float("aspect"));

    // quality= and method= are one option under two spellings (method= the docs' and -v's).
    if (v.given("quality") && v.given("method") && v.get_string("quality") != v.get_string("method"))
        return fail(err, format("quality={} and method={} disagree; give one", v.get_string("quality"),
                                v.get_string("method")));
    const std::string& method = defocus_method_named(v);
    o.method = method == "layers"      ? DefocusMethod::Layers
               : method == "gather"    ? DefocusMethod::Gather
               : method == "reference" ? DefocusMethod::Reference
                                       : DefocusMethod::Auto;
    o.layers        = v.get_int("layers");
    o.max_reduction = v.get_int("reduction");
    o.ladder_ratio  = float(v.get_float("ratio"));
    o.planner       = v.get_string("planner") == "predicted" ? DefocusPlanner::Predicted : DefocusPlanner::Steps;
    std::string budget = v.get_string("budget");
    if (OIIO::Strutil::iends_with(budget, "db"))
        budget.resize(budget.size() - 2);
    double budget_db;
    if (!parse_number(budget, budget_db) || budget_db <= 0.0 || budget_db > 120.0)
        return fail(err, format("budget '{}' is not a PSNR in dB within 0..120 (e.g. 40dB)",
                                v.get_string("budget")));
    o.budget_db       = float(budget_db);
    o.bloom_threshold = float(v.get_float("bloom"));
    o.bloom_gain      = float(v.get_float("bloomgain"));
    o.iris            = float(v.get_float("iris"));
    o.depth_dilate_px = v.get_int("zdilate");
    const std::string& border = v.get_string("border");
    o.border = border == "black"    ? Border::Black
               : border == "mirror" ? Border::Mirror
                                    : Border::Clamp;
    o.grow      = v.get_bool("grow");
    const std::string& fill = v.get_string("fill");
    o.fill = fill == "foreground" ? DisocclusionFill::Foreground
             : fill == "mirror"   ? DisocclusionFill::Mirror
                                  : DisocclusionFill::Smooth;
    o.nonfinite = v.get_string("nonfinite") == "error" ? NonFinitePolicy::Error
                                                       : NonFinitePolicy::Zero;
    o.reference_step_px = float(v.get_float("step"));
    o.aperture_views    = v.get_int("views");

    // Lens character: on when any of its options (lens_option_specs, highlights=,
    // sprites=, supersample=) is given.
    bool character = v.given("highlights") || v.given("sprites") || v.given("supersample");
    for (const OptionSpec& spec : lens_option_specs())
        character = character || v.given(spec.name);
    o.lens_character = character;
    if (character) {
        if (!lens_character_from(v, o.lens, err))
            return false;
        o.highlight_threshold = float(v.get_float("highlights"));
        o.max_sprites         = v.get_int("sprites");
        o.supersample         = v.get_int("supersample");
    }
    return true;
}

std::vector<OptionSpec> defocus_sprite_option_specs()
{
    std::vector<OptionSpec> specs = lens_option_specs();
    specs.push_back(OptionSpec::Float("highlights", 1.0, 1e-6, 1e30,
                                      "lens character: luminance at which a pixel is half a sprite "
                                      "(a smooth share from half to twice it)"));
    specs.push_back(OptionSpec::Int("sprites", 20000, 0, 10000000,
                                    "lens character: at most this many sprites, the brightest"));
    specs.push_back(OptionSpec::Int("supersample", 1, 1, 2,
                                    "lens character: output at this many times the resolution, the "
                                    "sprites drawn at it, the layers enlarged (pseudo-high resolution)"));
    return specs;
}

}  // namespace bokeh
