// io_commands.cpp — the I/O-level commands of bokehtool: channels, metadata, colour
// spaces, and the built-in synthetic scenes. Each command reads its arguments and calls
// the library (or OIIO) once.

#include <bokeh/color.h>
#include <bokeh/plugin.h>
#include <bokeh/scene.h>

#include "aperture_options.h"
#include "defocus_options.h"
#include "memory_budget.h"

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace {

using bokeh::CommandContext;
using bokeh::OptionSpec;
using bokeh::StackImage;
using OIIO::Strutil::fmt::format;

// The image a command passes on: same pixels and labels, its own buffer.
StackImage copy_of(const StackImage& in)
{
    StackImage out = in;
    out.buf        = std::make_shared<OIIO::ImageBuf>(*in.buf);
    return out;
}

// --ch as in oiiotool: "R,G,B", "A=1.0" (constant), "Y=R" (rename), or channel numbers.
bool channels(CommandContext& c)
{
    const OIIO::ImageBuf& src = *c.inputs[0].buf;
    std::vector<int> order;
    std::vector<float> values;
    std::vector<std::string> names;
    for (const std::string& item : OIIO::Strutil::splits(c.args[0], ",")) {
        const size_t eq         = item.find('=');
        const std::string name  = OIIO::Strutil::strip(item.substr(0, eq));
        const std::string from  = eq == std::string::npos ? name
                                  : std::string(OIIO::Strutil::strip(item.substr(eq + 1)));
        int index = src.spec().channelindex(from);
        float value = 0.0f;
        if (index < 0) {
            OIIO::string_view sv(from);
            int number = -1;
            if (eq == std::string::npos && OIIO::Strutil::parse_int(sv, number) && sv.empty()) {
                if (number < 0 || number >= src.nchannels())
                    return c.fail(format("channel number {} is out of range (0..{})", number,
                                         src.nchannels() - 1));
                index = number;
            } else if (sv = from, eq == std::string::npos || !OIIO::Strutil::parse_float(sv, value)
                                      || !sv.empty()) {
                return c.fail(format("no channel '{}' in {} (has {})", from, c.inputs[0].origin,
                                     OIIO::Strutil::join(src.spec().channelnames, ",")));
            }
        }
        order.push_back(index);
        values.push_back(value);
        names.push_back(index >= 0 && eq == std::string::npos
                            ? std::string(src.spec().channel_name(index)) : name);
    }
    if (order.empty())
        return c.fail("no channels named");
    StackImage out = c.inputs[0];
    out.buf        = std::make_shared<OIIO::ImageBuf>();
    if (!OIIO::ImageBufAlgo::channels(*out.buf, src, int(order.size()), order, values, names,
                                      false, c.nthreads))
        return c.fail(out.buf->geterror());
    // A renamed channel keeps the pixel type it was read with.
    for (size_t i = 0; i < order.size(); ++i)
        if (order[i] >= 0) {
            auto t = c.inputs[0].file_types.find(src.spec().channel_name(order[i]));
            if (t != c.inputs[0].file_types.end())
                out.file_types[names[i]] = t->second;
        }
    c.outputs.push_back(std::move(out));
    return true;
}

// --attrib NAME VALUE; the type is inferred as oiiotool does unless :type= says.
bool attrib(CommandContext& c)
{
    StackImage out          = copy_of(c.inputs[0]);
    const std::string& name = c.args[0];
    const std::string& text = c.args[1];
    std::string type        = c.options.get_string("type");
    OIIO::string_view sv(text);
    int i   = 0;
    float f = 0.0f;
    if (type == "auto")
        type = (OIIO::Strutil::parse_int(sv, i) && sv.empty())
                   ? "int"
                   : ((sv = text, OIIO::Strutil::parse_float(sv, f) && sv.empty()) ? "float" : "string");
    sv = text;
    if (type == "int") {
        if (!OIIO::Strutil::parse_int(sv, i) || !sv.empty())
            return c.fail(format("'{}' is not an integer", text));
        out.buf->specmod().attribute(name, i);
    } else if (type == "float") {
        if (!OIIO::Strutil::parse_float(sv, f) || !sv.empty())
            return c.fail(format("'{}' is not a number", text));
        out.buf->specmod().attribute(name, f);
    } else {
        out.buf->specmod().attribute(name, text);
    }
    c.outputs.push_back(std::move(out));
    return true;
}

bool iscolorspace(CommandContext& c)
{
    if (!c.colors->has(c.args[0]))
        return c.fail(format("unknown colour space '{}' (known: {})", c.args[0],
                             OIIO::Strutil::join(c.colors->names(), ", ")));
    StackImage out = c.inputs[0];
    out.colorspace = c.args[0];
    c.outputs.push_back(std::move(out));
    return true;
}

bool convert_to(CommandContext& c, const std::string& from, const std::string& to)
{
    StackImage out = copy_of(c.inputs[0]);
    std::string err;
    if (!c.colors->convert(*out.buf, from, to, c.nthreads, err))
        return c.fail(err);
    out.colorspace = to;
    c.outputs.push_back(std::move(out));
    return true;
}

// The scene's options may ride on the command (--scene:width=64 lights) or, as the
// scene name's own modifiers, on its argument (--scene lights:width=64). output=truth
// takes the lens and aperture in --defocus's spelling (plugins/shared/).
const std::vector<OptionSpec>& scene_options()
{
    static const std::vector<OptionSpec> specs = [] {
        std::vector<OptionSpec> v = {
            OptionSpec::Int("width", 1920, 1, 32768, "width in pixels"),
            OptionSpec::Int("height", 1080, 1, 32768, "height in pixels"),
            OptionSpec::Int("aa", 3, 1, 16, "colour supersamples per axis (sharp and deep)"),
            OptionSpec::Int("seed", 1, 0, 2147483647, "texture and light placement"),
            OptionSpec::Choice("output", { "sharp", "truth", "deep" },
                               "sharp: the pinhole image, RGBA+Z; truth: the thin-lens truth traced "
                               "against the scene's geometry, RGBA (the lens options below, spp=); "
                               "deep: a deep RGBA+Z image of every surface along each pixel's aa x aa "
                               "rays, visible and hidden, alpha its share of the rays"),
        };
        for (OptionSpec& o : bokeh::thin_lens_option_specs()) {
            if (o.name == "focus")
                o.help = "truth: focus distance in metres, or a pixel x,y of the sharp scene "
                         "(default: the scene's)";
            else if (o.name == "fstop")
                o.help = "truth: f-number (default: the scene's)";
            else if (o.name == "focal")
                o.help = "truth: focal length mm the CoC is computed with (default: the scene's 50; "
                         "the frame stays the scene's)";
            else if (o.name == "sensor")
                o.help = "truth: film back width in mm or a preset (ff, super35, alexa-lf, ...) the "
                         "CoC is computed with (default: the scene's 36)";
            else
                o.help = "truth: " + o.help;
            v.push_back(std::move(o));
        }
        for (OptionSpec& o : bokeh::defocus_aperture_option_specs()) {
            o.help = "truth: " + o.help;
            v.push_back(std::move(o));
        }
        v.push_back(OptionSpec::Int("spp", 64, 1, 1048576,
                                    "truth: rays a pixel (the noise falls as 1/sqrt(spp))"));
        v.push_back(OptionSpec::Int("rayseed", 1, 0, 2147483647,
                                    "truth: the sampling sequence's scramble (--defocus:method=truth's seed=)"));
        return v;
    }();
    return specs;
}

// The options only output=truth reads.
bool is_truth_option(const std::string& name)
{
    if (name == "spp" || name == "rayseed")
        return true;
    for (const OptionSpec& o : bokeh::thin_lens_option_specs())
        if (o.name == name)
            return true;
    for (const OptionSpec& o : bokeh::defocus_aperture_option_specs())
        if (o.name == name)
            return true;
    return false;
}

bool scene(CommandContext& c)
{
    const size_t colon     = c.args[0].find(':');
    const std::string name = c.args[0].substr(0, colon);
    if (colon != std::string::npos) {
        bokeh::OptionValues own;
        std::string err;
        if (!bokeh::parse_options(scene_options(), c.args[0].substr(colon + 1), own, err))
            return c.fail(err);
        for (const auto& [key, given] : own.explicitly_given)
            if (given) {
                // Both `--scene:width=100 lights:width=200`: one would be dropped unseen.
                if (c.options.given(key))
                    return c.fail(format("option '{}' is given twice (--scene:{} and {})", key, key, c.args[0]));
                c.options.values[key]           = own.values[key];
                c.options.explicitly_given[key] = true;
            }
    }
    bokeh::SceneOptions o;
    o.width  = c.options.get_int("width");
    o.height = c.options.get_int("height");
    o.aa     = c.options.get_int("aa");
    o.seed   = uint32_t(c.options.get_int("seed"));
    const std::string& output = c.options.get_string("output");
    // What it will hold, estimated before anything is allocated: a sharp frame is RGBA + Z
    // float (20 bytes a pixel) and its copy on the way to the file; a truth's RGBA and its
    // sums; a deep frame's samples (about 2 a pixel in the built-in scenes at 24 bytes,
    // held twice while the image is assembled) and their counts.
    const int64_t per_pixel = output == "deep" ? 160 : output == "truth" ? 48 : 40;
    if (!bokeh::within_memory_budget(c, bokeh::image_bytes(o.width, o.height, per_pixel),
                                     format("a {}x{} {} scene", o.width, o.height, output)))
        return false;
    if (output == "truth"
        && !bokeh::within_timeout(c, double(o.width) * double(o.height) * double(c.options.get_int("spp")),
                                  format("a {}x{} truth at {} rays a pixel", o.width, o.height, c.options.get_int("spp"))))
        return false;
    if (output != "truth")
        for (const auto& [key, given] : c.options.explicitly_given)
            if (given && is_truth_option(key))
                return c.fail(format("{}= is for output=truth", key));
    StackImage out;
    out.buf = std::make_shared<OIIO::ImageBuf>();
    if (output == "deep") {
        if (!bokeh::make_deep_scene(*out.buf, name, o, c.nthreads))
            return c.fail(out.buf->geterror());
    } else if (output == "truth") {
        bokeh::SceneCamera camera;
        if (!bokeh::scene_camera(name, camera)) {
            bokeh::make_scene(*out.buf, name, o);  // fails, naming the known scenes
            return c.fail(out.buf->geterror());
        }
        // The scene's camera as its sharp image records it, read by --defocus's rule.
        OIIO::ImageSpec camera_spec;
        camera_spec.attribute("bokeh:focal_mm", OIIO::TypeDesc::DOUBLE, &camera.focal_mm);
        camera_spec.attribute("bokeh:sensor_width_mm", OIIO::TypeDesc::DOUBLE, &camera.sensor_width_mm);
        camera_spec.attribute("bokeh:focus_m", OIIO::TypeDesc::DOUBLE, &camera.focus_m);
        camera_spec.attribute("bokeh:fstop", OIIO::TypeDesc::DOUBLE, &camera.fstop);
        bokeh::CocOptions coc;
        coc.lens.depth_unit_mm = 1000.0;
        std::string err;
        if (!bokeh::thin_lens_from(c.options, camera_spec, coc, err))
            return c.fail(err);
        if (coc.focus_at_pixel) {  // the depth the sharp scene has there, as --defocus reads it
            OIIO::ImageBuf sharp;
            if (!bokeh::make_scene(sharp, name, o, c.nthreads))
                return c.fail(sharp.geterror());
            if (!bokeh::resolve_coc_options(coc, sharp, err))
                return c.fail(err);
        }
        bokeh::SceneTruthOptions t;
        t.lens = coc.lens;
        if (!bokeh::aperture_kernel_from(c.options, t.aperture, err))
            return c.fail(err);
        t.aspect = float(c.options.get_float("aspect"));
        t.spp    = c.options.get_int("spp");
        t.seed   = uint32_t(c.options.get_int("rayseed"));
        t.progress = c.progress;
        bokeh::SceneTruthReport report;
        if (!bokeh::make_scene_truth(*out.buf, name, o, t, &report, c.nthreads))
            return c.fail(out.buf->geterror());
        if (c.verbosity >= 1)
            c.message("  " + report.summary);
    } else if (!bokeh::make_scene(*out.buf, name, o, c.nthreads)) {
        return c.fail(out.buf->geterror());
    }
    out.colorspace = c.colors->scene_linear();
    out.origin     = "--scene " + name + (output == "sharp" ? std::string() : ":output=" + output);
    c.outputs.push_back(std::move(out));
    return true;
}

}  // namespace

BOKEH_PLUGIN_EXPORT int bokeh_plugin_abi_version() { return BOKEH_PLUGIN_ABI_VERSION; }

BOKEH_PLUGIN_EXPORT void bokeh_plugin_register(bokeh::Registry& r)
{
    r.add(bokeh::make_command("--ch", "CHANNELS", 1,
                  "Select, reorder, rename (NEW=OLD) or fill (NAME=VALUE) channels", channels));
    r.add(bokeh::make_command("--attrib", "NAME VALUE", 1, "Set a metadata attribute", attrib,
                  { OptionSpec::Choice("type", { "auto", "int", "float", "string" },
                                       "value type (auto: as the value reads)") }));
    r.add(bokeh::make_command("--iscolorspace", "SPACE", 1,
                  "Say which colour space the top image is in (pixels unchanged)", iscolorspace));
    r.add(bokeh::make_command("--tocolorspace", "SPACE", 1, "Convert the top image to a colour space",
                  [](CommandContext& c) { return convert_to(c, c.inputs[0].colorspace, c.args[0]); }));
    r.add(bokeh::make_command("--colorconvert", "FROM TO", 1, "Convert the top image between colour spaces",
                  [](CommandContext& c) { return convert_to(c, c.args[0], c.args[1]); }));

    std::string names;
    for (const std::string& n : bokeh::scene_names())
        names += format(" {}: {}.", n, bokeh::scene_description(n));
    r.add(bokeh::make_command("--scene", "NAME", 0,
                  "Push a built-in synthetic RGBA+Z scene with known depth (Z in metres); "
                  "options may also follow the name (lights:width=640)." + names,
                  scene, scene_options()));
}
