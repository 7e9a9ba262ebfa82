// optics_commands.cpp — `--bokeh`: the PSF of a lens with character at one signed CoC and
// field position (bokeh::lens_psf, core/optics/lens_psf.cpp), or a contact sheet of them across
// defocus and field (`:sheet=1`, bokeh::bokeh_sheet_image); `:map=1` the light-beam map
// (bokeh::beam_map_image). The PSF's data window is centred on (0, 0), so the result
// serves as `--blur:kernel=image` or `--convolve`'s kernel. `--fitlens`: the lens fitted to
// crops of photographed bokeh (bokeh::fit_lens, core/fit/), printed as the options
// `--defocus` and `--bokeh` take, its comparison sheet pushed.

#include <aperture_options.h>
#include <lens_options.h>

#include <bokeh/color.h>
#include <bokeh/lens.h>
#include <bokeh/lens_fit.h>
#include <bokeh/optics.h>
#include <bokeh/plugin.h>

#include "memory_budget.h"

#include <cmath>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using OIIO::Strutil::fmt::format;


// The aperture: a picture here, the rest by the rule every command reads its own by.
bool aperture_from(CommandContext& c, bokeh::Aperture& out, std::string& err)
{
    const auto& v            = c.options;
    const std::string& shape = v.get_string("kernel");
    if (shape == "image")
        return bokeh::aperture_options_apply(v, shape, err)
               && bokeh::Aperture::from_picture(*c.inputs.back().buf, out, err);
    bokeh::Kernel k;
    return bokeh::aperture_kernel_from(v, k, err) && bokeh::Aperture::from_kernel(k, out, err);
}

bool bokeh_command(CommandContext& c)
{
    const auto& v = c.options;
    double coc_px;
    if (!bokeh::parse_number(c.args[0], coc_px))
        return c.fail(format("'{}' is not a signed CoC in px (negative: in front of focus)", c.args[0]));
    bokeh::LensCharacter lens;
    std::string err;
    if (!aperture_from(c, lens.aperture, err))
        return c.fail(err);
    lens.aspect = v.get_float("aspect");
    lens.fstop  = v.get_float("fstop");
    lens.focal_mm = v.get_float("focal");
    double sensor_mm;
    const std::string& sensor = v.get_string("sensor");
    if (!bokeh::film_back_width(sensor, sensor_mm) && !bokeh::parse_number(sensor, sensor_mm))
        return c.fail(format("sensor '{}' is neither a width in mm nor a film back", sensor));
    lens.pixel_pitch_mm = sensor_mm / v.get_int("width");
    // Lateral colour as --lensdistort takes it (a magnification), in px at the corner of
    // the 16:9 frame `width` px wide the field is measured on (the sheet's rows run to it).
    const double half_diagonal_px = 0.5 * std::hypot(1.0, 9.0 / 16.0) * v.get_int("width");
    lens.lateral_r_px             = v.get_float("lateralr") * half_diagonal_px;
    lens.lateral_b_px             = v.get_float("lateralb") * half_diagonal_px;
    if (!bokeh::lens_character_from(v, lens, err))
        return c.fail(err);

    // A PSF is linear light whatever the picture its aperture came from was encoded in:
    // the host decodes the picture first (needs_scene_linear), and the result is labelled
    // scene-linear, so that writing it applies no transfer function after the
    // normalisation (a PNG aperture's PSF would otherwise sum to 1/12.92).
    bokeh::StackImage out;
    out.colorspace = c.colors->scene_linear();
    out.origin = format("--bokeh {}", c.args[0]);
    out.buf    = std::make_shared<OIIO::ImageBuf>();
    if (v.get_bool("map")) {
        const double reach = std::max(1.0, std::abs(coc_px));
        if (!bokeh::beam_map_image(*out.buf, lens, -reach, reach, v.get_int("size") > 0 ? v.get_int("size") : 512,
                                   256, c.nthreads))
            return c.fail(out.buf->geterror());
    } else if (v.get_bool("sheet")) {
        const int cell = v.get_int("size") > 0 ? v.get_int("size") : int(std::ceil(std::abs(coc_px) * 1.25)) + 8;
        // The sheet's RGB floats and the image made of them (24 bytes a pixel), checked
        // before either is allocated: 64 x 64 cells of 2048 px would be 384 GiB.
        const int64_t sheet_w = int64_t(v.get_int("columns")) * (cell | 1), sheet_h = int64_t(v.get_int("rows")) * (cell | 1);
        if (!bokeh::within_memory_budget(c, bokeh::image_bytes(sheet_w, sheet_h, 24),
                                         format("a {}x{} sheet of PSFs", sheet_w, sheet_h)))
            return false;
        if (!bokeh::bokeh_sheet_image(*out.buf, lens, std::abs(coc_px), v.get_int("columns"), v.get_int("rows"),
                                      cell, c.nthreads))
            return c.fail(out.buf->geterror());
    } else {
        bokeh::PsfRequest req;
        req.coc_px = coc_px;
        const std::string& field = v.get_string("field");
        std::vector<std::string> xy;
        OIIO::Strutil::split(field, xy, ",");
        if (xy.size() != 2 || !bokeh::parse_number(xy[0], req.field_x) || !bokeh::parse_number(xy[1], req.field_y))
            return c.fail(format("field '{}' is not a position x,y in half-diagonals (0,0 centre, "
                                 "0.87,0.49 a 16:9 frame's top-right corner)",
                                 field));
        req.size_px = v.get_int("size");
        // The PSF's RGB floats and its image (24 bytes a pixel): `size`, else the CoC with the
        // margin aberrations and fringes may take (its own extent is known only once built).
        const int64_t side = req.size_px > 0 ? req.size_px : int64_t(std::ceil(2.0 * std::abs(coc_px))) + 16;
        if (!bokeh::within_memory_budget(c, bokeh::image_bytes(side, side, 24), format("a {}x{} PSF", side, side)))
            return false;
        if (!bokeh::lens_psf_image(*out.buf, lens, req, c.nthreads))
            return c.fail(out.buf->geterror());
    }
    if (c.verbosity > 1)  // a description of what was asked for: -v, as other commands' details
        c.message(format("bokeh: {} lens, {} aperture, CoC {:g} px: {} x {} px", bokeh::lens_preset_name(lens.preset),
                         lens.aperture.describe(), coc_px, out.buf->spec().width, out.buf->spec().height));
    c.outputs.push_back(std::move(out));
    return true;
}

bool fitlens_command(CommandContext& c)
{
    const auto& v = c.options;
    bokeh::LensFitOptions o;
    o.camera.fstop    = v.get_float("fstop");
    o.camera.focal_mm = v.get_float("focal");
    double sensor_mm;
    const std::string& sensor = v.get_string("sensor");
    if (!bokeh::film_back_width(sensor, sensor_mm) && !bokeh::parse_number(sensor, sensor_mm))
        return c.fail(format("sensor '{}' is neither a width in mm nor a film back", sensor));
    // The frame's width: given, else the first crop's display window when it is a frame
    // (a crop that kept its origin), else 1920.
    const OIIO::ImageSpec& first = c.inputs.front().buf->spec();
    int width = v.get_int("width");
    if (width == 0)
        width = first.full_width != first.width || first.full_height != first.height ? first.full_width : 1920;
    o.camera.pixel_pitch_mm = sensor_mm / width;
    o.clip_level = v.get_float("clip");
    o.front      = v.get_bool("front");
    o.fit_field  = v.get_bool("field");
    // The crops: the images on the stack, or boxes cut from one plate around the
    // highlights `at` names (their origin kept, so each knows its field position).
    std::vector<bokeh::LensFitCrop> crops;
    std::vector<std::string> names;
    const std::string& at = v.get_string("at");
    if (at.empty()) {
        for (const bokeh::StackImage& in : c.inputs) {
            bokeh::LensFitCrop crop;
            crop.image = *in.buf;
            crops.push_back(std::move(crop));
            names.push_back(in.origin);
        }
    } else {
        const OIIO::ImageBuf& plate = *c.inputs.front().buf;
        const int box = v.get_int("box");
        for (const std::string& xy_text : OIIO::Strutil::splits(at, "/")) {
            std::vector<std::string> xy = OIIO::Strutil::splits(xy_text, ",");
            double x = 0.0, y = 0.0;
            if (xy.size() != 2 || !bokeh::parse_number(xy[0], x) || !bokeh::parse_number(xy[1], y))
                return c.fail(format("at '{}' is not a list of pixel positions x,y/x,y/... ('{}' is not x,y)", at,
                                     xy_text));
            const OIIO::ROI data = plate.roi();
            if (x < data.xbegin || x >= data.xend || y < data.ybegin || y >= data.yend)
                return c.fail(format("at {:g},{:g} is outside {}'s pixels ({}..{} x {}..{})", x, y,
                                     c.inputs.front().origin, data.xbegin, data.xend - 1, data.ybegin,
                                     data.yend - 1));
            OIIO::ROI roi(int(std::floor(x)) - box / 2, int(std::floor(x)) - box / 2 + box, int(std::floor(y)) - box / 2,
                          int(std::floor(y)) - box / 2 + box);
            roi = OIIO::roi_intersection(roi, data);
            roi.chbegin = 0, roi.chend = plate.nchannels();
            bokeh::LensFitCrop crop;
            if (!OIIO::ImageBufAlgo::crop(crop.image, plate, roi))
                return c.fail(crop.image.geterror());
            crops.push_back(std::move(crop));
            names.push_back(format("{},{}", xy[0], xy[1]));
        }
        if (crops.size() > 64)
            return c.fail(format("at names {} highlights (at most 64)", crops.size()));
    }
    bokeh::LensFit fit;
    std::string err;
    if (!bokeh::fit_lens(fit, crops, o, err, c.nthreads)) {
        // The library names a crop by its number; say where it was cut or what it was.
        double n = 0.0;
        const size_t end = err.find_first_of(" :", 5);
        if (OIIO::Strutil::starts_with(err, "crop ") && end != std::string::npos
            && bokeh::parse_number(std::string_view(err).substr(5, end - 5), n) && n >= 1.0 && n <= double(names.size()))
            err.insert(end, at.empty() ? format(" ({})", names[size_t(n) - 1]) : " at " + names[size_t(n) - 1]);
        return c.fail(err);
    }
    c.message(format("fitlens: lens {}", fit.options.empty() ? "kernel=disk (round, no aberration shown)" : fit.options));
    for (size_t i = 0; i < fit.crops.size(); ++i) {
        const bokeh::LensFitCropResult& r = fit.crops[i];
        c.message(format("fitlens: crop {} ({}): CoC {:.2f} +- {:.2f} px at ({:.1f}, {:.1f}), fit {:.1f} dB{}{}", i + 1,
                         names[i], r.coc_px, r.coc_sigma_px, r.centre_x, r.centre_y, r.psnr_db,
                         r.clipped_px ? format(", {} clipped px left out", r.clipped_px) : std::string(),
                         r.nonfinite_px ? format(", {} non-finite px left out", r.nonfinite_px) : std::string()));
    }
    if (c.verbosity > 1) {
        for (size_t i = 0; i < fit.crops.size(); ++i) {
            const bokeh::LensFitCropResult& r = fit.crops[i];
            c.message(format("fitlens:   crop {}: residual rms R {:.3g} G {:.3g} B {:.3g}; light {:.4g} {:.4g} {:.4g}; "
                             "background {:.4g} {:.4g} {:.4g}; {} px of other lights or past the loss's scale",
                             i + 1, r.residual_rms[0], r.residual_rms[1], r.residual_rms[2], r.amplitude[0],
                             r.amplitude[1], r.amplitude[2], r.background[0], r.background[1], r.background[2],
                             r.outlier_px));
        }
        for (const bokeh::LensFitParameter& p : fit.parameters)
            c.message(p.status == bokeh::LensFitParameter::Status::Fitted
                          ? format("fitlens:   {} = {:.4g} +- {:.2g}", p.name, p.value, p.sigma)
                          : format("fitlens:   {} left at its default: {}", p.name, p.why));
        for (const std::string& st : fit.stages)
            c.message("fitlens:   " + st);
        c.message(format("fitlens:   noise: read {:.3g}, photon {:.3g} x signal; {} PSF evaluations, {:.2f} s",
                         fit.noise_read, fit.noise_photon, fit.evaluations, fit.seconds));
    }
    bokeh::StackImage out;
    out.colorspace = c.colors->scene_linear();
    out.origin     = "--fitlens";
    out.buf        = std::make_shared<OIIO::ImageBuf>();
    if (!bokeh::lens_fit_sheet(*out.buf, fit, crops, c.nthreads))
        return c.fail(out.buf->geterror());
    out.buf->specmod().attribute("bokeh:fitted_lens", fit.options);
    c.outputs.push_back(std::move(out));
    return true;
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    std::vector<std::string> kernels = bokeh::aperture_kernel_names();
    kernels.push_back("image");
    std::vector<OptionSpec> options = {
        OptionSpec::Choice("kernel", kernels, "aperture: disk, bladed polygon, star, or the image on the stack"),
        OptionSpec::Int("width", 1920, 16, 65536, "image width in px the CoC is measured on"),
        OptionSpec::String("field", "0,0", "field position x,y in half-diagonals (x right, y up)"),
        OptionSpec::Int("size", 0, 0, 8191, "image side px (0: the PSF's own extent)"),
        OptionSpec::Bool("sheet", false, "a contact sheet: columns across defocus, rows across field"),
        OptionSpec::Int("columns", 9, 1, 64, "sheet: defocus columns (front .. focus .. back)"),
        OptionSpec::Int("rows", 4, 1, 64, "sheet: field rows (centre .. corner)"),
        OptionSpec::Bool("map", false, "Kawase's beam map: CoC across, ray height up"),
        OptionSpec::Float("lateralr", 0.0, -0.1, 0.1,
                          "lateral colour: red's magnification against green's, minus 1, as --lensdistort's"),
        OptionSpec::Float("lateralb", 0.0, -0.1, 0.1, "lateral colour: blue's magnification against green's, minus 1"),
    };
    // The aperture and camera options every command shares (aperture_options.h), after the kernel.
    std::vector<OptionSpec> shared = bokeh::aperture_shape_option_specs();
    shared.push_back(bokeh::aspect_option_spec());
    for (OptionSpec& o : bokeh::camera_option_specs(false))
        shared.push_back(std::move(o));
    options.insert(options.begin() + 1, shared.begin(), shared.end());
    for (OptionSpec& s : bokeh::lens_option_specs())
        options.push_back(std::move(s));
    bokeh::Command c = bokeh::make_command(
        "--bokeh", "COC", 0,
        "Render a lens's bokeh: the PSF at a signed CoC (px; negative in front of focus) with "
        "aberrations, spectrum, diffraction, onion rings and field effects, or a sheet of them",
        bokeh_command, std::move(options));
    c.inputs_for = [](const bokeh::OptionValues& v) { return v.get_string("kernel") == "image" ? 1 : 0; };
    c.needs_scene_linear = true;  // a picture aperture's transmission, decoded to linear
    r.add(c);

    std::vector<OptionSpec> fit_options = {
        OptionSpec::Int("crops", 1, 1, 64, "how many crops to take from the stack (the top ones)"),
        OptionSpec::String("at", "", "cut the crops from one plate around these pixels: x,y/x,y/..."),
        OptionSpec::Int("box", 128, 16, 4096, "at: the crops' side in px"),
        OptionSpec::Int("width", 0, 0, 65536,
                        "the plate's width in px (0: the crop's display window when it is the frame, else 1920)"),
        OptionSpec::Float("clip", 0.0, 0.0, 1e30, "pixels at or above this are clipped (0: found per crop)"),
        OptionSpec::Bool("front", false, "the highlights are in front of focus (their CoC negative)"),
        OptionSpec::Bool("field", true,
                         "fit cat's eye and astigmatism from crops off the axis (0: skip it, about half the time)"),
    };
    for (OptionSpec& o : bokeh::camera_option_specs(false))
        fit_options.push_back(std::move(o));
    bokeh::Command fit = bokeh::make_command(
        "--fitlens", "", 1,
        "Fit the lens model to crops of defocused highlights from a plate: prints the lens as "
        "--defocus/--bokeh options, pushes a sheet of crop | fit | difference x 4 | fitted light",
        fitlens_command, std::move(fit_options));
    fit.inputs_for = [](const bokeh::OptionValues& v) { return v.get_string("at").empty() ? v.get_int("crops") : 1; };
    fit.needs_scene_linear = true;  // a plate's light, linear
    r.add(fit);
}
