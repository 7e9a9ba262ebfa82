// module.cpp — the Python module `openbokeh`: the library's families on numpy arrays and
// OpenImageIO.ImageBufs. Blur, convolve, resample, the deep nodes and the scenes run the
// bokehtool commands themselves (commands.h), so every option has the command line's
// name, default and check; defocus reads its options the same way (the command's specs,
// defocus_options.h) and calls the library to return its report; compare, read_image and
// write_image call the library directly (they take no options). No algorithm lives here.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <OpenImageIO/strutil.h>

#include <bokeh/defocus.h>
#include <bokeh/io.h>
#include <bokeh/lens.h>
#include <bokeh/lens_fit.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>

#include "commands.h"
#include "defocus_options.h"
#include "images.h"

#ifndef BOKEH_VERSION
#    error "BOKEH_VERSION must be defined by the build"
#endif

namespace py = pybind11;
using namespace openbokeh_python;
using OIIO::Strutil::fmt::format;

namespace {

// The result of a call: an ImageBuf when an input was one (or the result is deep), else
// an array of its data window. The buffer is given away unless it is an input's.
py::object result_of(const std::shared_ptr<OIIO::ImageBuf>& out, const std::vector<ImageArg>& inputs,
                     bool force_imagebuf = false)
{
    bool as_imagebuf = force_imagebuf || out->deep(), owned = true;
    for (const ImageArg& in : inputs) {
        as_imagebuf = as_imagebuf || in.from_imagebuf;
        owned       = owned && in.buf.get() != out.get();
    }
    return as_imagebuf ? image_to_imagebuf(out, owned) : image_to_array(out, owned);
}

bool is_number(const py::handle& v)
{
    if (py::isinstance<py::bool_>(v))
        return false;
    return py::isinstance<py::int_>(v) || py::isinstance<py::float_>(v)
           || py::isinstance(v, py::module_::import("numpy").attr("number"));
}

// A size or factor argument as the command line writes it: a str as given, a number, or
// (for sizes) a pair of numbers "WxH".
std::string size_text(const std::string& function, const char* name, const py::object& v, bool pair_ok)
{
    if (py::isinstance<py::str>(v))
        return v.cast<std::string>();
    if (is_number(v))
        return option_text(function, name, v);
    if (pair_ok && (py::isinstance<py::tuple>(v) || py::isinstance<py::list>(v)) && py::len(v) == 2) {
        const py::sequence s = py::reinterpret_borrow<py::sequence>(v);
        if (is_number(s[0]) && is_number(s[1]))
            return option_text(function, name, s[0]) + "x" + option_text(function, name, s[1]);
    }
    throw py::type_error(format("{}: argument '{}' must be {}, not {}", function, name,
                                pair_ok ? "a number, a (width, height) pair or a str as the command "
                                          "line takes it"
                                        : "a number",
                                py::str(py::type::of(v).attr("__name__")).cast<std::string>()));
}

// One image in, one out, the command's arguments from `args`: most functions are this.
py::object run_one(const std::string& function, const char* command, const py::object& image,
                   const std::vector<std::string>& args, int threads, const py::object& channels,
                   const py::dict& kw, bool allow_array = true)
{
    const bokeh::Command& cmd = Commands::get().find(command);
    std::vector<ImageArg> in  = { image_arg(function, image, "image", channels, allow_array) };
    bokeh::OptionValues values = options_from_kwargs(function, cmd, kw);
    auto out = run_command(function, cmd, in, args, std::move(values), threads);
    return result_of(out.at(0), in);
}

std::string doc_of(const char* command, const std::string& text, const std::vector<std::string>& skip = {})
{
    return text + "\n\n" + options_doc(Commands::get().find(command), skip);
}

const char* kCommon = "threads: 0 = all cores (bokehtool --threads). channels: the channel names of "
                      "an array argument (\"R,G,B,A,Z\" or a sequence; default by count: Y; R,G; "
                      "R,G,B; R,G,B,A; R,G,B,A,Z).\n"
                      "Returns an OpenImageIO.ImageBuf when the image was one, else an (H, W, C) "
                      "float32 array of the result's data window.";

}  // namespace

PYBIND11_MODULE(openbokeh, m)
{
    m.doc() =
        "OpenBokeh: lens defocus for VFX compositing, on numpy arrays and OpenImageIO.ImageBufs.\n\n"
        "Images: a C-contiguous numpy array (H, W, C) float32 (other dtypes, shapes and strided "
        "views are refused, naming the argument), or an OpenImageIO.ImageBuf (python3-openimageio); "
        "deep images only as ImageBufs. Pixels are taken as scene-linear, as bokehtool takes "
        "float files. Options are keyword arguments with the names and defaults of bokehtool's "
        "command-line options (each function lists them). Errors raise ValueError (an argument "
        "or option refused) or RuntimeError (the library's message); the GIL is released while "
        "the library works.";
    m.attr("__version__") = BOKEH_VERSION;

    // The plugins and the OCIO config now: a broken installation fails the import, naming
    // what is broken. OpenImageIO's module is imported if present (it registers ImageBuf).
    Commands& commands = Commands::get();
    have_oiio_module();
    m.attr("plugin_dir") = commands.plugin_dir();

    py::class_<bokeh::DefocusReport>(m, "DefocusReport",
                                     "What a defocus decided and found (bokehtool -v prints it).")
        .def_property_readonly("method", [](const bokeh::DefocusReport& r) { return bokeh::method_name(r.method); },
                               "the method that ran: layers, gather or reference")
        .def_readonly("layer_coc_px", &bokeh::DefocusReport::layer_coc_px,
                      "layers and reference: each layer's CoC diameter in px, front to back")
        .def_readonly("layer_reduction", &bokeh::DefocusReport::layer_reduction,
                      "layers: each layer's buffer reduction")
        .def_readonly("min_coc_px", &bokeh::DefocusReport::min_coc_px, "smallest signed CoC, px")
        .def_readonly("max_coc_px", &bokeh::DefocusReport::max_coc_px, "largest signed CoC, px")
        .def_property_readonly("nonfinite_colour", [](const bokeh::DefocusReport& r) { return r.nonfinite.colour; },
                               "non-finite colour values replaced by 0")
        .def_property_readonly("nonfinite_depth", [](const bokeh::DefocusReport& r) { return r.nonfinite.depth; },
                               "NaN or -inf depth values taken as far")
        .def_property_readonly(
            "plans",
            [](const bokeh::DefocusReport& r) {
                py::list plans;
                for (const bokeh::DefocusPlanEstimate& p : r.plans) {
                    py::dict d;
                    d["ladder_ratio"]       = p.ladder_ratio;
                    d["min_reduced_coc_px"] = p.min_reduced_coc_px;
                    d["layers"]             = p.layers;
                    d["predicted_psnr_db"]  = p.predicted_psnr_db;
                    d["predicted_ms"]       = p.predicted_ms;
                    d["chosen"]             = p.chosen;
                    plans.append(d);
                }
                return plans;
            },
            "flat layers: the plans the planner weighed, cheapest first, as dicts (ladder_ratio: 1 the exact "
            "rungs, 0 the budget's steps; min_reduced_coc_px: inf at full resolution; predicted_psnr_db, "
            "predicted_ms: planner='predicted' only; chosen)")
        .def_readonly("summary", &bokeh::DefocusReport::summary, "one line")
        .def("__repr__", [](const bokeh::DefocusReport& r) {
            return format("<DefocusReport {}: {} layer(s); {}>", bokeh::method_name(r.method),
                          r.layer_coc_px.size(), r.summary);
        });

    py::class_<bokeh::ImageError>(m, "ImageError", "How far a result is from its reference (compare).")
        .def_readonly("rmse_linear", &bokeh::ImageError::rmse_linear, "root mean square difference, linear")
        .def_readonly("psnr_db", &bokeh::ImageError::psnr_db,
                      "PSNR of the x/(1+|x|) tone-mapped values, peak 1; 999 when identical")
        .def_readonly("max_abs", &bokeh::ImageError::max_abs, "largest absolute linear difference")
        .def_readonly("values", &bokeh::ImageError::values, "channel values compared")
        .def_readonly("nonfinite", &bokeh::ImageError::nonfinite,
                      "values NaN or infinite on one side only (then the error is infinite)")
        .def("__repr__", [](const bokeh::ImageError& e) {
            return format("<ImageError RMSE {:.6g}, PSNR {:.2f} dB, max {:.6g}, {} values>", e.rmse_linear,
                          e.psnr_db, e.max_abs, e.values);
        });

    // --- blur family (blur.h) ----------------------------------------------------------
    m.def(
        "blur",
        [](const py::object& image, const py::object& size, int threads, const py::object& channels,
           const py::kwargs& kw) {
            const bokeh::Command& cmd = Commands::get().find("--blur");
            std::vector<ImageArg> in  = { image_arg("blur", image, "image", channels) };
            // kernel=<an image>: the aperture picture, as --blur:kernel=image takes it from the stack.
            py::dict options;
            std::map<std::string, std::string> fixed;
            for (const auto& [key, value] : kw) {
                if (key.cast<std::string>() == "kernel" && !value.is_none() && !py::isinstance<py::str>(value)) {
                    in.push_back(image_arg("blur", py::reinterpret_borrow<py::object>(value), "kernel", py::none()));
                    fixed["kernel"] = "image";
                } else {
                    options[key] = value;
                }
            }
            bokeh::OptionValues values = options_from_kwargs("blur", cmd, options, fixed);
            auto out = run_command("blur", cmd, in, { size_text("blur", "size", size, true) },
                                   std::move(values), threads);
            return result_of(out.at(0), in);
        },
        py::arg("image"), py::arg("size"), py::kw_only(), py::arg("threads") = 0,
        py::arg("channels") = py::none(),
        doc_of("--blur",
               std::string("blur(image, size, **options): blur with a uniform kernel, as bokehtool "
                           "--blur:OPTIONS WxH.\n\n"
                           "size: the kernel's full footprint in pixels: a number, a (width, height) "
                           "pair or \"WxH\" (fractions allowed; unequal sides: anamorphic). "
                           "kernel= may also be an image (array or ImageBuf): the aperture picture, "
                           "resized to the size and convolved, as --blur:kernel=image.\n")
                   + kCommon)
            .c_str());

    m.def(
        "convolve",
        [](const py::object& image, const py::object& kernel, int threads, const py::object& channels,
           const py::kwargs& kw) {
            const bokeh::Command& cmd = Commands::get().find("--convolve");
            std::vector<ImageArg> in  = { image_arg("convolve", image, "image", channels),
                                          image_arg("convolve", kernel, "kernel", py::none()) };
            bokeh::OptionValues values = options_from_kwargs("convolve", cmd, kw);
            auto out = run_command("convolve", cmd, in, {}, std::move(values), threads);
            return result_of(out.at(0), in);
        },
        py::arg("image"), py::arg("kernel"), py::kw_only(), py::arg("threads") = 0,
        py::arg("channels") = py::none(),
        doc_of("--convolve",
               std::string("convolve(image, kernel, **options): convolve with an image as the kernel "
                           "(any size, colour allowed, normalised per channel; by FFT), as bokehtool "
                           "IMAGE KERNEL --convolve.\n")
                   + kCommon)
            .c_str());

    // --- resample family (resample.h) --------------------------------------------------
    struct Sized {
        const char* function;
        const char* command;
        const char* argument;
        bool pair_ok;
        const char* text;
    };
    const Sized sized[] = {
        { "resize", "--resize", "size", true,
          "resize(image, size, **options): resize to a new display window, as bokehtool "
          "--resize:OPTIONS WxH.\n\nsize: (width, height), or a str as the command line takes it: "
          "\"WxH\", \"N%\", \"Wx0\" (the aspect ratio kept).\n" },
        { "resample", "--resample", "size", true,
          "resample(image, size, **options): sample at the new pixel centres without filtering "
          "(bilinear, or nearest with interp=0), as bokehtool --resample WxH.\n\nsize: as resize's.\n" },
        { "reduce", "--reduce", "factor", false,
          "reduce(image, factor, **options): reduce by a whole factor N with the area-exact box "
          "(depth channels: z=), as bokehtool --reduce N.\n" },
        { "enlarge", "--enlarge", "factor", false,
          "enlarge(image, factor, **options): enlarge by a factor >= 1 (fractions allowed; "
          "anchored at 0, so reduce(N) then enlarge(N) puts pixels back), as bokehtool "
          "--enlarge:OPTIONS N.\n" },
    };
    for (const Sized& s : sized) {
        const std::string function = s.function, command = s.command, argument = s.argument;
        const bool pair_ok = s.pair_ok;
        m.def(
            s.function,
            [function, command, argument, pair_ok](const py::object& image, const py::object& size, int threads,
                                                   const py::object& channels, const py::kwargs& kw) {
                return run_one(function, command.c_str(), image,
                               { size_text(function, argument.c_str(), size, pair_ok) }, threads, channels, kw);
            },
            py::arg("image"), py::arg(s.argument), py::kw_only(), py::arg("threads") = 0,
            py::arg("channels") = py::none(), doc_of(s.command, std::string(s.text) + kCommon).c_str());
    }

    m.def(
        "lens_distort",
        [](const py::object& image, int threads, const py::object& channels, const py::kwargs& kw) {
            return run_one("lens_distort", "--lensdistort", image, {}, threads, channels, kw);
        },
        py::arg("image"), py::kw_only(), py::arg("threads") = 0, py::arg("channels") = py::none(),
        doc_of("--lensdistort",
               std::string("lens_distort(image, **options): warp by a lens's radial distortion and lateral "
                           "colour, or (output=\"stmap\") its STMap, as bokehtool --lensdistort:OPTIONS.\n")
                   + kCommon)
            .c_str());

    // --- defocus (defocus.h) -----------------------------------------------------------
    m.def(
        "defocus",
        [](const py::object& image, int threads, const py::object& channels, const py::kwargs& kw) {
            const bokeh::Command& cmd  = Commands::get().find("--defocus");
            std::vector<ImageArg> in   = { image_arg("defocus", image, "image", channels) };
            bokeh::OptionValues values = options_from_kwargs("defocus", cmd, kw);
            bokeh::DefocusOptions opts;
            std::string err;
            if (!bokeh::with_named_depth(values, in[0].buf, in[0].buf, err))
                throw py::value_error(error_text("defocus", err));
            if (!bokeh::defocus_options_from(values, in[0].buf->spec(), opts, err))
                throw py::value_error(error_text("defocus", err));
            if (values.get_string("output") != "image" || values.get_string("method") == "truth") {
                // The diagnostics (coc, focalplane, layers) and the thin-lens truth of a deep
                // image (truth.h): the command makes them.
                auto out = run_command("defocus", cmd, in, {}, std::move(values), threads);
                return py::make_tuple(result_of(out.at(0), in), py::none());
            }
            if (threads < 0 || threads > 1024)
                throw py::value_error(format("defocus: threads = {} is not a thread count (0..1024, 0 = "
                                             "all cores)",
                                             threads));
            auto dst = std::make_shared<OIIO::ImageBuf>();
            bokeh::DefocusReport report;
            bool ok;
            {
                py::gil_scoped_release release;
                ok = bokeh::defocus(*dst, *in[0].buf, opts, &report, threads);
            }
            if (!ok)
                throw std::runtime_error(error_text("defocus", dst->geterror()));
            if (report.nonfinite.total() > 0)
                warn(format("defocus: {} non-finite colour and {} non-finite depth values replaced "
                            "(colour by 0, depth by far)",
                            report.nonfinite.colour, report.nonfinite.depth));
            return py::make_tuple(result_of(dst, in), py::cast(std::move(report)));
        },
        py::arg("image"), py::kw_only(), py::arg("threads") = 0, py::arg("channels") = py::none(),
        doc_of("--defocus",
               std::string(
                   "defocus(image, **options) -> (result, report): depth of field from R, G, B, "
                   "(A,) Z, as bokehtool --defocus:OPTIONS.\n\n"
                   "The focal length and film back come from the image's metadata (the scenes "
                   "record them) unless given. report: a DefocusReport (the method, its layers, "
                   "the CoC range); None for the diagnostic outputs (output=coc|focalplane|layers) and "
                   "for method=truth (the thin-lens rays through a deep image, spp= rays a pixel). "
                   "The result holds R, G, B(, A) premultiplied over the grown data window.\n")
                   + kCommon)
            .c_str());

    // --- deep nodes (deep.h) -----------------------------------------------------------
    struct DeepOne {
        const char* function;
        const char* command;
        const char* text;
    };
    const DeepOne deep_one[] = {
        { "deep_tidy", "--deeptidy",
          "deep_tidy(image, **options): tidy a deep ImageBuf by the OpenEXR rules (volumes split "
          "where samples overlap, coincident samples merged, sorted), as bokehtool --deeptidy.\n" },
        { "flatten", "--flatten",
          "flatten(image, **options): composite a deep ImageBuf front to back into a flat one "
          "(tidied first), as bokehtool --flatten. Returns an ImageBuf (to_array() makes it an "
          "array).\n" },
    };
    for (const DeepOne& d : deep_one) {
        const std::string function = d.function, command = d.command;
        m.def(
            d.function,
            [function, command](const py::object& image, int threads, const py::kwargs& kw) {
                return run_one(function, command.c_str(), image, {}, threads, py::none(), kw, false);
            },
            py::arg("image"), py::kw_only(), py::arg("threads") = 0,
            doc_of(d.command, std::string(d.text) + "threads: 0 = all cores.").c_str());
    }

    m.def(
        "deep_merge",
        [](const py::sequence& images, int threads, const py::kwargs& kw) {
            const bokeh::Command& cmd = Commands::get().find("--deepmerge");
            if (py::isinstance<py::str>(images))
                throw py::type_error("deep_merge: argument 'images' must be a sequence of deep ImageBufs");
            std::vector<ImageArg> in;
            std::vector<std::string> names;
            for (size_t i = 0; i < py::len(images); ++i)
                names.push_back(format("images[{}]", i));
            for (size_t i = 0; i < py::len(images); ++i)
                in.push_back(image_arg("deep_merge", images[i], names[i].c_str(), py::none(), false));
            if (in.size() < 2)
                throw py::value_error(format("deep_merge: needs at least 2 images, got {}", in.size()));
            bokeh::OptionValues values =
                options_from_kwargs("deep_merge", cmd, kw, { { "n", std::to_string(in.size()) } });
            auto out = run_command("deep_merge", cmd, in, {}, std::move(values), threads);
            return result_of(out.at(0), in);
        },
        py::arg("images"), py::kw_only(), py::arg("threads") = 0,
        doc_of("--deepmerge",
               "deep_merge(images, **options): merge deep ImageBufs (any number, >= 2; same channel "
               "names): samples pooled per pixel and tidied, hidden ones kept unless cull=True, as "
               "bokehtool A B ... --deepmerge:n=N.\nthreads: 0 = all cores.",
               { "n" })
            .c_str());

    m.def(
        "deep_holdout",
        [](const py::object& image, const py::object& holdout, int threads, const py::kwargs& kw) {
            const bokeh::Command& cmd  = Commands::get().find("--deepholdout");
            std::vector<ImageArg> in   = { image_arg("deep_holdout", image, "image", py::none(), false),
                                           image_arg("deep_holdout", holdout, "holdout", py::none(), false) };
            bokeh::OptionValues values = options_from_kwargs("deep_holdout", cmd, kw);
            auto out = run_command("deep_holdout", cmd, in, {}, std::move(values), threads);
            return result_of(out.at(0), in);
        },
        py::arg("image"), py::arg("holdout"), py::kw_only(), py::arg("threads") = 0,
        doc_of("--deepholdout",
               "deep_holdout(image, holdout, **options): every sample of the deep image times the "
               "holdout's transmittance in front of it (exact; the result stays deep), as bokehtool "
               "IMAGE HOLDOUT --deepholdout.\nthreads: 0 = all cores.")
            .c_str());

    m.def(
        "deep_slice",
        [](const py::object& image, const py::object& znear, const py::object& zfar, int threads,
           const py::kwargs& kw) {
            return run_one("deep_slice", "--deepslice", image,
                           { size_text("deep_slice", "znear", znear, false),
                             size_text("deep_slice", "zfar", zfar, false) },
                           threads, py::none(), kw, false);
        },
        py::arg("image"), py::arg("znear"), py::arg("zfar"), py::kw_only(), py::arg("threads") = 0,
        doc_of("--deepslice",
               "deep_slice(image, znear, zfar, **options): keep the part of a deep image in the depth "
               "range [znear, zfar) (volumes split at its ends; float('inf') allowed), as bokehtool "
               "--deepslice NEAR FAR.\nthreads: 0 = all cores.")
            .c_str());

    m.def(
        "deepen",
        [](const py::object& image, int threads, const py::object& channels, const py::kwargs& kw) {
            return run_one("deepen", "--deepen", image, {}, threads, channels, kw);
        },
        py::arg("image"), py::kw_only(), py::arg("threads") = 0, py::arg("channels") = py::none(),
        doc_of("--deepen",
               std::string("deepen(image, **options): a flat image (array or ImageBuf) made deep, one "
                           "sample a pixel (none where it is empty), as bokehtool --deepen. Returns a "
                           "deep ImageBuf.\n")
                   + kCommon)
            .c_str());

    // --- scenes (scene.h) --------------------------------------------------------------
    std::string scenes;
    for (const std::string& n : bokeh::scene_names())
        scenes += format("\n    {}: {}", n, bokeh::scene_description(n));
    m.def(
        "scene",
        [](const std::string& name, int threads, const py::kwargs& kw) {
            const bokeh::Command& cmd = Commands::get().find("--scene");
            if (name.find(':') != std::string::npos)
                throw py::value_error(format("scene: '{}': give the options as keyword arguments", name));
            bokeh::OptionValues values = options_from_kwargs("scene", cmd, kw);
            auto out = run_command("scene", cmd, {}, { name }, std::move(values), threads);
            return result_of(out.at(0), {}, true);
        },
        py::arg("name"), py::kw_only(), py::arg("threads") = 0,
        doc_of("--scene",
               "scene(name, **options): a built-in synthetic scene with known depth: float R, G, B, A, "
               "Z (metres), the camera in its metadata, as bokehtool --scene NAME. Returns an "
               "OpenImageIO.ImageBuf (to_array() makes it an array). Scenes:"
                   + scenes)
            .c_str());
    m.def("scene_names", &bokeh::scene_names, "The names scene() takes.");

    // --- optics (optics.h) ------------------------------------------------------------
    m.def(
        "bokeh",
        [](const py::object& coc, int threads, const py::kwargs& kw) {
            const bokeh::Command& cmd = Commands::get().find("--bokeh");
            if (py::isinstance<py::bool_>(coc) || py::isinstance<py::str>(coc))
                throw py::type_error("bokeh: coc must be a number (the signed CoC in pixels)");
            bokeh::OptionValues values = options_from_kwargs("bokeh", cmd, kw);
            auto out = run_command("bokeh", cmd, {}, { option_text("bokeh", "coc", coc) },
                                   std::move(values), threads);
            return result_of(out.at(0), {}, true);
        },
        py::arg("coc"), py::kw_only(), py::arg("threads") = 0,
        doc_of("--bokeh",
               "bokeh(coc, **options): the lens's point-spread function for a signed CoC in "
               "pixels (negative: in front of focus), with the lens character options (lens=, "
               "diffraction=, onion=, field=, ...), as bokehtool --bokeh:OPTIONS COC; sheet=True "
               "draws defocus columns by field rows, map=True the beam map. Returns an "
               "OpenImageIO.ImageBuf (to_array() makes it an array).")
            .c_str());

    m.def(
        "fit_lens",
        [](const py::list& crops, double fstop, double focal, const py::object& sensor, int width, double clip,
           bool front, bool field, int threads) {
            bokeh::LensFitOptions o;
            o.camera.fstop    = fstop;
            o.camera.focal_mm = focal;
            double sensor_mm  = 36.0;
            if (py::isinstance<py::str>(sensor)) {
                if (!bokeh::film_back_width(sensor.cast<std::string>(), sensor_mm))
                    throw py::value_error(format("fit_lens: sensor '{}' is not a film back", sensor.cast<std::string>()));
            } else {
                sensor_mm = sensor.cast<double>();
            }
            if (width < 16)
                throw py::value_error(format("fit_lens: width {} px is under 16", width));
            o.camera.pixel_pitch_mm = sensor_mm / width;
            o.clip_level = clip;
            o.front      = front;
            o.fit_field  = field;
            std::vector<ImageArg> args;
            std::vector<bokeh::LensFitCrop> in;
            for (size_t i = 0; i < crops.size(); ++i) {
                const std::string name = format("crops[{}]", i);
                args.push_back(image_arg("fit_lens", crops[i], name.c_str(), py::none()));
                bokeh::LensFitCrop c;
                c.image = *args.back().buf;
                in.push_back(std::move(c));
            }
            bokeh::LensFit fit;
            auto sheet = std::make_shared<OIIO::ImageBuf>();
            std::string err;
            bool ok;
            {
                py::gil_scoped_release release;
                ok = bokeh::fit_lens(fit, in, o, err, threads);
                if (ok && !bokeh::lens_fit_sheet(*sheet, fit, in, threads))
                    err = sheet->geterror(), ok = false;
            }
            if (!ok)
                throw py::value_error(error_text("fit_lens", err));
            py::dict params;
            for (const bokeh::LensFitParameter& p : fit.parameters) {
                const char* status = p.status == bokeh::LensFitParameter::Status::Fitted         ? "fitted"
                                     : p.status == bokeh::LensFitParameter::Status::Undetermined ? "undetermined"
                                                                                                 : "off";
                params[py::str(p.name)] = py::dict(py::arg("value") = p.value, py::arg("sigma") = p.sigma,
                                                   py::arg("status") = status, py::arg("why") = p.why);
            }
            py::list per_crop;
            for (const bokeh::LensFitCropResult& c : fit.crops)
                per_crop.append(py::dict(
                    py::arg("coc_px") = c.coc_px, py::arg("coc_sigma_px") = c.coc_sigma_px,
                    py::arg("centre") = py::make_tuple(c.centre_x, c.centre_y),
                    py::arg("field") = py::make_tuple(c.field_x, c.field_y), py::arg("field_known") = c.field_known,
                    py::arg("amplitude") = py::make_tuple(c.amplitude[0], c.amplitude[1], c.amplitude[2]),
                    py::arg("background") = py::make_tuple(c.background[0], c.background[1], c.background[2]),
                    py::arg("psnr_db") = c.psnr_db, py::arg("clipped_px") = c.clipped_px,
                    py::arg("nonfinite_px") = c.nonfinite_px, py::arg("outlier_px") = c.outlier_px));
            return py::dict(py::arg("options") = fit.options, py::arg("parameters") = params,
                            py::arg("crops") = per_crop, py::arg("stages") = fit.stages,
                            py::arg("noise") = py::make_tuple(fit.noise_read, fit.noise_photon),
                            py::arg("evaluations") = fit.evaluations, py::arg("seconds") = fit.seconds,
                            py::arg("sheet") = result_of(sheet, args));
        },
        py::arg("crops"), py::kw_only(), py::arg("fstop") = 2.8, py::arg("focal") = 50.0,
        py::arg("sensor") = py::float_(36.0), py::arg("width") = 1920, py::arg("clip") = 0.0,
        py::arg("front") = false, py::arg("field") = true, py::arg("threads") = 0,
        "fit_lens(crops, *, fstop=2.8, focal=50, sensor=36, width=1920, clip=0, front=False, field=False) -> "
        "dict: the lens model fitted to crops of defocused highlights (a list of arrays or ImageBufs; an "
        "ImageBuf cut from a frame with its origin kept knows its field position), as bokehtool --fitlens. "
        "'options' is the lens as --defocus/--bokeh options; 'parameters' each one's value, sigma and status; "
        "'crops' each crop's CoC and fit; 'sheet' crop | fit | difference x 4 | fitted light. ValueError "
        "naming the crop for one with no highlight, all clipped or smaller than its bokeh.");

    // --- metrics (metrics.h) -----------------------------------------------------------
    m.def(
        "compare",
        [](const py::object& result, const py::object& reference, int threads) {
            const ImageArg a = image_arg("compare", result, "result", py::none());
            const ImageArg b = image_arg("compare", reference, "reference", py::none());
            bokeh::ImageError e;
            std::string err;
            bool ok;
            {
                py::gil_scoped_release release;
                ok = bokeh::compare(e, *a.buf, *b.buf, err, {}, threads);
            }
            if (!ok)
                throw py::value_error(error_text("compare", err));
            return e;
        },
        py::arg("result"), py::arg("reference"), py::kw_only(), py::arg("threads") = 0,
        "compare(result, reference) -> ImageError: RMSE, PSNR after the x/(1+|x|) tone map, max "
        "error and the values compared, channel by channel over the union of the data windows "
        "(bokehtool --diff prints the same figures).");

    // --- io (io.h) ---------------------------------------------------------------------
    m.def(
        "read_image",
        [](const std::string& path, const std::string& view) {
            auto buf = std::make_shared<OIIO::ImageBuf>();
            std::string err;
            bool ok;
            {
                py::gil_scoped_release release;
                bokeh::ReadOptions opts;
                opts.view = view;
                ok        = bokeh::read_image(*buf, path, opts, err);
            }
            if (!ok)
                throw std::runtime_error(error_text("read_image", err));
            return image_to_imagebuf(buf, true);
        },
        py::arg("path"), py::arg("view") = "",
        "read_image(path, view='') -> ImageBuf: a file, whole and checked now: flat images as float "
        "(the file's types kept in nativespec for writing back), every part of a flat multipart EXR "
        "merged into one image (depth.Z from part depth; as bokehtool reads it), deep ones as "
        "stored (part 0). A multi-view (stereo) EXR: its first view is the image (its depth too), "
        "the others' channels prefixed by their view; view='right' reads that view alone, as "
        "bokehtool --view does. "
        "RuntimeError with the reason (missing, a directory, truncated, no such view, ...).");
    m.def(
        "write_image",
        [](const py::object& image, const std::string& path, bool no_clobber, const py::object& channels) {
            const ImageArg in = image_arg("write_image", image, "image", channels);
            bokeh::WriteOptions opts;
            opts.no_clobber = no_clobber;
            // The types it was read with, by channel name, as bokehtool's -o writes them.
            if (!in.buf->deep())
                opts.channel_formats = bokeh::formats_for(in.buf->spec(),
                                                          bokeh::channel_types_of(in.buf->nativespec()));
            std::string err;
            bool ok;
            {
                py::gil_scoped_release release;
                ok = bokeh::write_image(*in.buf, path, opts, err);
            }
            if (!ok)
                throw std::runtime_error(error_text("write_image", err));
        },
        py::arg("image"), py::arg("path"), py::kw_only(), py::arg("no_clobber") = false,
        py::arg("channels") = py::none(),
        "write_image(image, path, no_clobber=False): write an array or ImageBuf through a temporary "
        "file renamed into place (a failed write leaves nothing at path), in the types it was read "
        "with (half stays half; arrays: float). RuntimeError with the reason.");

    m.def(
        "to_array",
        [](const py::object& image, const py::object& channels) -> py::object {
            const ImageArg in = image_arg("to_array", image, "image", channels);
            if (!in.from_imagebuf)
                return image;
            return image_to_array(in.buf, false);
        },
        py::arg("image"), py::kw_only(), py::arg("channels") = py::none(),
        "to_array(image) -> array: a flat ImageBuf's data window as an (H, W, C) float32 array "
        "(a copy); an array is returned as it is, once checked.");
    m.def(
        "to_imagebuf",
        [](const py::object& image, const py::object& channels) {
            const ImageArg in = image_arg("to_imagebuf", image, "image", channels);
            return image_to_imagebuf(in.buf, false);
        },
        py::arg("image"), py::kw_only(), py::arg("channels") = py::none(),
        "to_imagebuf(array, channels=None) -> ImageBuf: an (H, W, C) float32 array copied into an "
        "OpenImageIO.ImageBuf with channel names (default by count: Y; R,G; R,G,B; R,G,B,A; "
        "R,G,B,A,Z).");
}
