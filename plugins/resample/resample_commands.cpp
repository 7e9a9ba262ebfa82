// resample_commands.cpp — reduced buffers from the command line: `--resize:filter=NAME WxH`
// (also N% and Wx0, as oiiotool spells it), `--resample WxH` (oiiotool's, bilinear or
// nearest, unfiltered), `--reduce:z=min|max|nearest|mean N` and
// `--enlarge:filter=NAME N`. The work is bokeh::resize, resample, reduce and enlarge
// (core/resample/resample.cpp).

#include <bokeh/distortion.h>
#include <bokeh/plugin.h>
#include <bokeh/resample.h>

#include "memory_budget.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>

#include <OpenImageIO/strutil.h>

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using OIIO::Strutil::fmt::format;

// A finite number that is all of `text`.
bool parse_number(std::string_view text, double& v)
{
    const std::string s(text);
    if (s.empty() || std::isspace(static_cast<unsigned char>(s[0])))
        return false;
    char* end = nullptr;
    errno     = 0;
    v         = std::strtod(s.c_str(), &end);
    return errno == 0 && end == s.c_str() + s.size() && std::isfinite(v);
}

// oiiotool's size argument: "WxH", "N%" (both axes), or "Wx0" / "0xH" (the other from the
// aspect ratio of the display window).
bool parse_new_size(const std::string& arg, const OIIO::ImageSpec& spec, int& width, int& height,
                    std::string& err)
{
    err = format("'{}' is not a size (WxH, N% or Wx0)", arg);
    const int fw = spec.full_width, fh = spec.full_height;
    if (!arg.empty() && arg.back() == '%') {
        double percent = 0.0;
        if (!parse_number(std::string_view(arg).substr(0, arg.size() - 1), percent) || percent <= 0.0)
            return false;
        width  = std::max(1, int(std::lround(fw * percent / 100.0)));
        height = std::max(1, int(std::lround(fh * percent / 100.0)));
    } else {
        const size_t x = arg.find('x');
        double w = 0.0, h = 0.0;
        if (x == std::string::npos || !parse_number(std::string_view(arg).substr(0, x), w)
            || !parse_number(std::string_view(arg).substr(x + 1), h) || w < 0.0 || h < 0.0
            || w != std::floor(w) || h != std::floor(h) || (w == 0.0 && h == 0.0))
            return false;
        width  = w > 0.0 ? int(w) : std::max(1, int(std::lround(h * fw / fh)));
        height = h > 0.0 ? int(h) : std::max(1, int(std::lround(w * fh / fw)));
    }
    if (width > (1 << 20) || height > (1 << 20)) {
        err = format("size {}x{} is larger than 1048576", width, height);
        return false;
    }
    return true;
}

bokeh::ResampleOptions resample_options(const CommandContext& c)
{
    bokeh::ResampleOptions o;
    bokeh::parse_filter(c.options.get_string("filter"), o.filter);  // a Choice: always known
    const std::string& border = c.options.get_string("border");
    o.border = border == "black"    ? bokeh::Border::Black
               : border == "mirror" ? bokeh::Border::Mirror
                                    : bokeh::Border::Clamp;
    o.gaussian_sigma = float(c.options.get_float("sigma"));
    o.blur_sigma     = float(c.options.get_float("blur"));
    o.fused_offset   = float(c.options.get_float("offset"));
    o.clamp_negative = c.options.get_bool("clamp");
    return o;
}

bool push(CommandContext& c, const std::shared_ptr<OIIO::ImageBuf>& buf)
{
    bokeh::StackImage out = c.inputs[0];
    out.buf               = buf;
    c.outputs.push_back(std::move(out));
    return true;
}

// --resize and --resample: the size argument, then `run(dst, src, width, height)`.
template<class Run> bool to_new_size(CommandContext& c, Run run)
{
    const OIIO::ImageBuf& src = *c.inputs[0].buf;
    int w = 0, h = 0;
    std::string err;
    if (!parse_new_size(c.args[0], src.spec(), w, h, err))
        return c.fail(err);
    // The result, float, before it is allocated.
    if (!bokeh::within_memory_budget(c, bokeh::image_bytes(w, h, 4 * int64_t(src.nchannels())),
                                     format("a {}x{} result of {} channels", w, h, src.nchannels())))
        return false;
    auto out = std::make_shared<OIIO::ImageBuf>();
    if (!run(*out, src, w, h))
        return c.fail(out->geterror());
    return push(c, out);
}

bool resize_command(CommandContext& c)
{
    return to_new_size(c, [&](OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int w, int h) {
        return bokeh::resize(dst, src, w, h, resample_options(c), c.nthreads);
    });
}

bool resample_command(CommandContext& c)
{
    return to_new_size(c, [&](OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int w, int h) {
        return bokeh::resample(dst, src, w, h, c.options.get_int("interp") != 0, c.nthreads);
    });
}

bool reduce_command(CommandContext& c)
{
    double n = 0.0;
    if (!parse_number(c.args[0], n) || n < 1.0 || n > 4096.0 || n != std::floor(n))
        return c.fail(format("'{}' is not a reduction factor (a whole number 1..4096)", c.args[0]));
    const std::string& z = c.options.get_string("z");
    bokeh::ReduceOptions o;
    o.depth = z == "max"       ? bokeh::Reducer::Max
              : z == "nearest" ? bokeh::Reducer::NearestDepth
              : z == "mean"    ? bokeh::Reducer::Mean
                               : bokeh::Reducer::Min;
    o.outside_is_black = c.options.get_bool("black");
    auto out = std::make_shared<OIIO::ImageBuf>();
    if (!bokeh::reduce(*out, *c.inputs[0].buf, int(n), o, c.nthreads))
        return c.fail(out->geterror());
    return push(c, out);
}

// --enlarge:depthaware=pcf|bilateral: the low-resolution layer on top of the stack enlarged
// over the full-resolution image below it (its Z), as the defocus composites its reduced
// layers (resample.h, enlarge_depth_aware).
bool enlarge_depth_aware_command(CommandContext& c, double k)
{
    for (const char* name : { "filter", "border", "sigma", "blur", "offset", "clamp" })
        if (c.options.given(name))
            return c.fail(format("{}= is for the filtered enlargement; depthaware= samples by depth", name));
    bokeh::DepthAwareOptions o;
    o.method          = c.options.get_string("depthaware") == "bilateral" ? bokeh::DepthAwareMethod::JointBilateral
                                                                          : bokeh::DepthAwareMethod::PCF;
    o.depth_tolerance = float(c.options.get_float("tolerance"));
    o.sigma_depth     = float(c.options.get_float("sigmadepth"));
    const OIIO::ImageBuf& full = *c.inputs[0].buf;
    const OIIO::ImageBuf& low  = *c.inputs[1].buf;
    if (!bokeh::within_memory_budget(c, bokeh::image_bytes(full.spec().width, full.spec().height,
                                                           4 * int64_t(low.nchannels())),
                                     format("a {}x{} result of {} channels", full.spec().width,
                                            full.spec().height, low.nchannels())))
        return false;
    auto out = std::make_shared<OIIO::ImageBuf>();
    if (!bokeh::enlarge_depth_aware(*out, low, full, k, o, c.nthreads))
        return c.fail(out->geterror());
    bokeh::StackImage result = c.inputs[1];
    result.buf               = out;
    c.outputs.push_back(std::move(result));
    return true;
}

bool enlarge_command(CommandContext& c)
{
    double k = 0.0;
    if (!parse_number(c.args[0], k))
        return c.fail(format("'{}' is not a factor (a number >= 1)", c.args[0]));
    if (c.options.get_string("depthaware") != "none")
        return enlarge_depth_aware_command(c, k);
    for (const char* name : { "tolerance", "sigmadepth" })
        if (c.options.given(name))
            return c.fail(format("{}= is for depthaware=pcf|bilateral", name));
    const OIIO::ImageSpec& in = c.inputs[0].buf->spec();
    if (k >= 1.0 && k < 1e9) {  // the library refuses the rest, naming the factor
        const int64_t w = int64_t(std::ceil(in.width * k)), h = int64_t(std::ceil(in.height * k));
        if (!bokeh::within_memory_budget(c, bokeh::image_bytes(w, h, 4 * int64_t(in.nchannels)),
                                         format("a {}x{} result of {} channels", w, h, in.nchannels)))
            return false;
    }
    auto out = std::make_shared<OIIO::ImageBuf>();
    if (!bokeh::enlarge(*out, *c.inputs[0].buf, k, resample_options(c), c.nthreads))
        return c.fail(out->geterror());
    return push(c, out);
}

// --lensdistort: the frame warped by a lens's radial distortion and lateral colour, or the
// STMap of the warp.
bool lensdistort_command(CommandContext& c)
{
    bokeh::LensDistortion l;
    l.model       = c.options.get_string("model") == "division" ? bokeh::DistortionModel::Division
                                                                : bokeh::DistortionModel::Polynomial;
    l.k1          = c.options.get_float("k1");
    l.k2          = c.options.get_float("k2");
    l.lateral_r   = c.options.get_float("lateralr");
    l.lateral_b   = c.options.get_float("lateralb");
    l.centre_x_px = c.options.get_float("centrex");
    l.centre_y_px = c.options.get_float("centrey");
    const bokeh::DistortDirection dir = c.options.get_string("direction") == "undistort"
                                            ? bokeh::DistortDirection::Undistort
                                            : bokeh::DistortDirection::Distort;
    const OIIO::ImageBuf& src = *c.inputs[0].buf;
    auto out                  = std::make_shared<OIIO::ImageBuf>();
    const bool stmap          = c.options.get_string("output") == "stmap";
    const bool ok = stmap ? bokeh::distortion_stmap(*out, src.spec(), l, dir, c.nthreads)
                          : bokeh::lens_distort(*out, src, l, dir, {}, c.nthreads);
    if (!ok)
        return c.fail(out->geterror());
    return push(c, out);
}

std::vector<OptionSpec> filter_options(const std::string& first)
{
    // The chosen default first (a Choice's default is its first word), then the rest.
    std::vector<std::string> names = { first };
    for (const std::string& n : bokeh::filter_names())
        if (n != first)
            names.push_back(n);
    return {
        OptionSpec::Choice("filter", names,
                           "bilinear (= triangle), catmull-rom, bspline, lanczos2, lanczos3, "
                           "gaussian, box (area-exact), nearest; enlarging only: reduced-blur, "
                           "upscale-blur, upscale-blur-fused, upscale-blur-2stage"),
        OptionSpec::Choice("border", { "clamp", "black", "mirror" },
                           "pixels outside the image: clamp (the edge repeats, as oiiotool's --resize "
                           "takes them), black, mirror"),
        OptionSpec::Float("sigma", 0.0, 0.0, 64.0,
                          "gaussian: sigma in source pixels (0: 0.65, the sharpest without Mach bands)"),
        OptionSpec::Float("blur", 0.0, 0.0, 64.0, "reduced-blur: sigma at low resolution (0: 0.5)"),
        OptionSpec::Float("offset", 0.0, 0.0, 64.0,
                          "upscale-blur-fused: tap offset in source pixels (0: 0.354)"),
        OptionSpec::Bool("clamp", false,
                         "set negative results to 0 (catmull-rom, lanczos ring below 0 near bright edges)"),
    };
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command resize = bokeh::make_command(
        "--resize", "WxH", 1,
        "Resize to WxH (N%: both axes; Wx0: keep the aspect ratio), display windows mapped onto "
        "each other as oiiotool's --resize; reducing stretches the filter to the new pixel",
        resize_command, filter_options("lanczos3"));
    resize.needs_scene_linear = true;
    r.add(resize);

    bokeh::Command resample = bokeh::make_command(
        "--resample", "WxH", 1,
        "Resample to WxH without filtering (oiiotool's --resample): bilinear, or the nearest "
        "pixel with :interp=0",
        resample_command,
        { OptionSpec::Int("interp", 1, 0, 1, "1: bilinear; 0: nearest pixel") });
    resample.needs_scene_linear = true;
    r.add(resample);

    bokeh::Command reduce = bokeh::make_command(
        "--reduce", "N", 1,
        "Reduce by a whole factor N with the area-exact box: each N x N block becomes one pixel "
        "(colour: mean; depth: :z=)",
        reduce_command,
        { OptionSpec::Choice("z", { "min", "max", "nearest", "mean" },
                             "depth channels (Z, ZBack): min (the nearest surface), max, nearest "
                             "(the value of the pixel of least Z), mean"),
          OptionSpec::Bool("black", false,
                           "colour: count block pixels outside the data window as 0 (keeps the energy); depth is reduced over the pixels inside") });
    reduce.needs_scene_linear = true;
    r.add(reduce);

    bokeh::Command lensdistort = bokeh::make_command(
        "--lensdistort", "", 1,
        "Warp the frame by a lens's radial distortion and lateral colour (distort a pinhole "
        "frame as the lens records it, or undistort a plate), or write the warp's STMap "
        "(docs/methods/distortion.md)",
        lensdistort_command,
        { OptionSpec::Choice("direction", { "distort", "undistort" },
                             "distort: a pinhole (CG) frame -> as the lens records it; undistort: a plate -> the "
                             "pinhole frame"),
          OptionSpec::Choice("model", { "polynomial", "division" },
                             "polynomial: r_d = r_u (1 + k1 r_u^2 + k2 r_u^4); division: r_u = r_d / (1 + k1 r_d^2 "
                             "+ k2 r_d^4); r in half-diagonals of the display window"),
          OptionSpec::Float("k1", 0.0, -10.0, 10.0, "first radial coefficient (< 0: barrel)"),
          OptionSpec::Float("k2", 0.0, -10.0, 10.0, "second radial coefficient"),
          OptionSpec::Float("lateralr", 0.0, -0.5, 0.5,
                            "lateral colour: red's magnification against green's, minus 1 (0.001: red 0.1 % larger)"),
          OptionSpec::Float("lateralb", 0.0, -0.5, 0.5, "lateral colour: blue's magnification against green's, minus 1"),
          OptionSpec::Float("centrex", 0.0, -1e5, 1e5, "the distortion centre's offset from the frame's centre, px (right)"),
          OptionSpec::Float("centrey", 0.0, -1e5, 1e5, "the distortion centre's offset from the frame's centre, px (down)"),
          OptionSpec::Choice("output", { "image", "stmap" },
                             "image: the warped frame (bilinear; depth channels nearest); stmap: R, G = Nuke STMap "
                             "s, t of each output pixel's source (no lateral colour)") });
    lensdistort.needs_scene_linear = true;
    r.add(lensdistort);

    std::vector<OptionSpec> enlarge_options = filter_options("bilinear");
    enlarge_options.push_back(OptionSpec::Choice(
        "depthaware", { "none", "pcf", "bilateral" },
        "enlarge the low-resolution layer on top of the stack over the full-resolution image below it "
        "(both with Z): pcf hides the layer behind nearer full-resolution surfaces with their edges "
        "(percentage-closer filtering); bilateral (joint-bilateral) keeps it from bleeding across "
        "depth edges; the result has the layer's channels over the full image's windows"));
    enlarge_options.push_back(
        OptionSpec::Float("tolerance", 0.01, 0.0, 10.0, "pcf: relative depth bias of the in-front test"));
    enlarge_options.push_back(OptionSpec::Float("sigmadepth", 0.02, 1e-6, 10.0, "bilateral: relative depth sigma"));
    bokeh::Command enlarge = bokeh::make_command(
        "--enlarge", "N", 1,
        "Enlarge by the factor N (>= 1, fractions allowed; pixel centres as --resize, anchored at "
        "0 so that --reduce N --enlarge N puts pixels back); depth-aware over a full-resolution "
        "image with :depthaware=",
        enlarge_command, enlarge_options);
    enlarge.inputs_for = [](const bokeh::OptionValues& o) { return o.get_string("depthaware") == "none" ? 1 : 2; };
    enlarge.needs_scene_linear = true;
    r.add(enlarge);
}
