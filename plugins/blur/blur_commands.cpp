// blur_commands.cpp — `--blur`, spelled as oiiotool spells it (`--blur:kernel=disk 31x31`),
// with our kernels and options (`kernel=image`: the kernel from the stack, resized), and
// `--convolve` with an image kernel. The work is bokeh::blur, bokeh::resize and
// bokeh::convolve_image (core/).

#include <bokeh/blur.h>
#include <bokeh/plugin.h>
#include <bokeh/resample.h>

#include "aperture_options.h"

#include <algorithm>
#include <cmath>

#include <OpenImageIO/strutil.h>

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using OIIO::Strutil::fmt::format;

bokeh::BlurOptions blur_options(const CommandContext& c)
{
    bokeh::BlurOptions o;
    const std::string& border = c.options.get_string("border");
    o.border = border == "clamp"    ? bokeh::Border::Clamp
               : border == "mirror" ? bokeh::Border::Mirror
                                    : bokeh::Border::Black;
    o.grow = c.options.get_bool("grow");
    o.iris     = float(c.options.get_float("iris"));
    o.progress = c.progress;
    return o;
}

// The options that shape a kernel or tune a method, refused where they do not apply: an
// ignored option would let `kernel=box:blades=5` or `kernel=hex:blades=5` run as if it had
// not been given (a hexagon), as a method that does not apply is refused. False + the
// reason for the first one given that does not. (With method=fast, `bands` and `reduction`
// are taken where fast picks the bands or the reduced buffer: the help says so.)
bool options_apply(const CommandContext& c, const std::string& kernel, std::string& why)
{
    if (!bokeh::aperture_options_apply(c.options, kernel, why))
        return false;
    const std::string& method = c.options.get_string("method");
    const bool shaped = kernel == "polygon" || kernel == "hex" || kernel == "disk" || kernel == "star"
                        || kernel == "box" || kernel == "gaussian";
    // OIIO's filters are sampled at whole offsets: edge=hard is what they are already.
    if (c.options.given("edge") && !shaped && !(kernel != "image" && c.options.get_string("edge") == "hard")) {
        why = format("edge does not apply to kernel={}: it is for kernel=box, gaussian, disk, polygon, hex and star "
                     "(OIIO's filters: edge=hard, what they are)",
                     kernel);
        return false;
    }
    for (const auto& [option, methods] : { std::pair<const char*, const char*>{ "bands", "bands" },
                                           { "reduction", "reduced" } })
        if (c.options.given(option) && method != methods && method != "fast") {
            why = format("{} does not apply to method={}: it is for method={} and fast", option, method, methods);
            return false;
        }
    return true;
}

// A convolution's error with the two images it was given named (the kernel is the top one).
std::string with_inputs(const CommandContext& c, const std::string& err)
{
    return format("{} (image: {}; kernel image: {})", err, c.inputs[0].origin, c.inputs[1].origin);
}

// `--blur:kernel=image WxH`: the top image is the kernel (an aperture scan, say), resized
// to WxH and convolved as `--convolve` does.
bool blur_with_image_command(CommandContext& c, float width_px, float height_px)
{
    bokeh::Kernel size;  // the size rule every kernel follows, checked before resizing
    size.width_px  = width_px;
    size.height_px = height_px;
    std::string err;
    if (!bokeh::check_kernel(size, err))
        return c.fail(err);
    const std::string& method = c.options.get_string("method");
    if (method != "auto" && method != "exact" && method != "fft")
        return c.fail(format("method={} does not apply to kernel=image (convolved exactly, by FFT)",
                             method));
    const int w = int(std::lround(width_px)), h = int(std::lround(height_px));
    if (w != width_px || h != height_px)
        return c.fail(format("'{}': kernel=image takes a whole number of pixels", c.args[0]));
    bokeh::StackImage out = c.inputs[0];
    out.buf               = std::make_shared<OIIO::ImageBuf>();
    if (w == 0 || h == 0) {  // the zero-size kernel, as every other: the image itself
        // The kernel image is still checked: a script fails alike at every size.
        if (!bokeh::check_kernel_image(*c.inputs[1].buf, c.inputs[0].buf->nchannels(), blur_options(c), err))
            return c.fail(with_inputs(c, err));
        out.buf->copy(*c.inputs[0].buf);
        c.outputs.push_back(std::move(out));
        return true;
    }
    // Resized as `--resize` (bilinear, the edge repeated, as IBA::resize): a picture of
    // the aperture scaled to the bokeh's size.
    OIIO::ImageBuf kernel;
    if (!bokeh::resize(kernel, *c.inputs[1].buf, w, h, {}, c.nthreads))
        return c.fail(format("the kernel image: {}", kernel.geterror()));
    if (!bokeh::convolve_image(*out.buf, *c.inputs[0].buf, kernel, blur_options(c), {}, c.nthreads))
        return c.fail(with_inputs(c, out.buf->geterror()));
    c.outputs.push_back(std::move(out));
    return true;
}

bool blur_command(CommandContext& c)
{
    bokeh::Kernel k;
    if (!bokeh::parse_extent(c.args[0], k.width_px, k.height_px))
        return c.fail(format("'{}' is not a kernel size (WxH or N pixels, >= 0)", c.args[0]));
    const std::string& shape = c.options.get_string("kernel");
    std::string why;
    if (!options_apply(c, shape, why))
        return c.fail(why);
    if (shape == "image")
        return blur_with_image_command(c, k.width_px, k.height_px);
    const std::vector<std::string> apertures = bokeh::aperture_kernel_names();
    if (std::find(apertures.begin(), apertures.end(), shape) != apertures.end()) {
        if (!bokeh::aperture_kernel_from(c.options, k, why))
            return c.fail(why);
    } else {
        k.shape  = shape == "box" ? bokeh::KernelShape::Box
                   : shape == "gaussian" ? bokeh::KernelShape::Gaussian
                                         : bokeh::KernelShape::Filter;
        k.filter = shape;
    }
    k.sigma_px = float(c.options.get_float("sigma"));
    k.edge = c.options.get_string("edge") == "hard" ? bokeh::KernelEdge::Hard
                                                     : bokeh::KernelEdge::Antialiased;
    bokeh::BlurOptions o = blur_options(c);
    const std::string& method = c.options.get_string("method");
    o.method = method == "exact"            ? bokeh::BlurMethod::Exact
               : method == "fast"           ? bokeh::BlurMethod::Fast
               : method == "reference"      ? bokeh::BlurMethod::Reference
               : method == "boxes3"         ? bokeh::BlurMethod::ThreeBoxes
               : method == "parallelograms" ? bokeh::BlurMethod::Parallelograms
               : method == "bands"          ? bokeh::BlurMethod::Bands
               : method == "taps"           ? bokeh::BlurMethod::BilinearTaps
               : method == "reduced"        ? bokeh::BlurMethod::Reduced
               : method == "spans"          ? bokeh::BlurMethod::Spans
               : method == "fft"            ? bokeh::BlurMethod::Fft
               : method == "separable"      ? bokeh::BlurMethod::Separable
                                            : bokeh::BlurMethod::Auto;
    o.bands     = c.options.get_int("bands");
    o.reduction = float(c.options.get_float("reduction"));

    bokeh::StackImage out = c.inputs[0];
    out.buf               = std::make_shared<OIIO::ImageBuf>();
    if (!bokeh::blur(*out.buf, *c.inputs[0].buf, k, o, {}, c.nthreads))
        return c.fail(out.buf->geterror());
    c.outputs.push_back(std::move(out));
    return true;
}

// oiiotool's `--convolve`: the top image is the kernel, the one below it is blurred.
bool convolve_command(CommandContext& c)
{
    bokeh::StackImage out = c.inputs[0];
    out.buf               = std::make_shared<OIIO::ImageBuf>();
    if (!bokeh::convolve_image(*out.buf, *c.inputs[0].buf, *c.inputs[1].buf, blur_options(c), {},
                               c.nthreads))
        return c.fail(with_inputs(c, out.buf->geterror()));
    c.outputs.push_back(std::move(out));
    return true;
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    bokeh::Command c = bokeh::make_command(
        "--blur", "WxH", 1,
        "Blur with a uniform kernel of WxH pixels (fractions allowed; WxH unequal: "
        "anamorphic). Exact methods match the brute-force reference",
        blur_command);
    c.needs_scene_linear = true;
    // The options blur_options() reads, for both commands.
    const std::vector<OptionSpec> shared = {
        OptionSpec::Choice("border", { "clamp", "black", "mirror" },
                           "pixels outside the image: clamp (the edge repeats, as oiiotool's --blur "
                           "and --convolve take them), black, mirror"),
        OptionSpec::Bool("grow", false, "grow the data window by the kernel radius"),
        OptionSpec::Float("iris", 0.0, -1000.0, 1000.0,
                          "highlight emphasis: log(mean(exp(k x))) / k, k = this (0: off)"),
    };
    std::vector<std::string> kernels = { "gaussian", "box" };
    for (const std::string& a : bokeh::aperture_kernel_names())
        kernels.push_back(a);
    kernels.push_back("image");
    const std::vector<std::string> oiio_filters = bokeh::oiio_filter_names();
    kernels.insert(kernels.end(), oiio_filters.begin(), oiio_filters.end());
    c.options = {
        OptionSpec::Choice("kernel", kernels,
                           "kernel shape (gaussian: sigma = W/4 as oiiotool, not truncated unless edge=hard; "
                           "image: the top image of the stack, resized to WxH, blurs the one "
                           "below it, as --convolve; the names after it are OIIO's filters, "
                           "oiiotool's make_kernel weights, computed exactly; sinc is refused with "
                           "its reason: OIIO's is not scaled to the size, the identity)"),
        OptionSpec::Choice("edge", { "aa", "hard" },
                           "aa: area-weighted edge; hard: sampled at pixel centres as oiiotool's kernels "
                           "(disk, box; gaussian cut at WxH; with border=clamp, oiiotool's --blur to 1e-5); "
                           "OIIO's filters take hard only (what they are), kernel=image neither"),
        OptionSpec::Choice("method",
                           { "auto", "exact", "fast", "reference", "boxes3", "parallelograms",
                             "bands", "taps", "reduced", "spans", "fft", "separable" },
                           "exact: disk/polygon/star by spans or fft, gaussian and OIIO's separable filters "
                           "separable or fft, whichever is cheaper (other filters: fft); "
                           "fast: the cheapest method measured at >= 40 dB "
                           "(gaussian: boxes3, edge=hard: exact; disk/polygon/hex: reduced from 37.5/45 px, "
                           "below that bands (hex: parallelograms) or exact, whichever costs "
                           "less, with the fewest bands that keep 40 dB; star, OIIO's filters and iris: exact); "
                           "taps: Kawase's 9x9/17x17 "
                           "bilinear-fetch disk; reduced: exact at 1/N size, enlarged "
                           "bilinearly (not for OIIO's filters); reference: brute force"),
        OptionSpec::Int("bands", 0, 0, 64,
                        "method=bands or fast: bands per half kernel (a kernel not symmetric "
                        "in y, a pentagon: twice that over its height); 0: the method's choice "
                        "(bands: 8; fast: the fewest, 3..8, within its accuracy bound)"),
        OptionSpec::Float("reduction", 0.0, 0.0, 16.0,
                          "method=reduced (or fast, where it picks the reduced buffer): the factor "
                          "N, 1..16 (0: the kernel's narrower side over 25, a polygon's over 30, at "
                          "most 8; 1 below 1.5)"),
        OptionSpec::Float("sigma", 0.0, 0.0, 1024.0, "Gaussian sigma in pixels (0: W/4)"),
    };
    for (OptionSpec& o : bokeh::aperture_shape_option_specs())
        c.options.push_back(std::move(o));
    c.options.insert(c.options.end(), shared.begin(), shared.end());
    c.inputs_for = [](const bokeh::OptionValues& o) { return o.get_string("kernel") == "image" ? 2 : 1; };
    r.add(c);

    bokeh::Command conv = bokeh::make_command(
        "--convolve", "", 2,
        "Convolve the second image with the top one as the kernel (any shape, colour "
        "allowed; normalised per channel; by FFT)",
        convolve_command);
    conv.needs_scene_linear = true;
    conv.options            = shared;
    r.add(conv);
}
