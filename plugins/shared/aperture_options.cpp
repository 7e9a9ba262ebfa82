// aperture_options.cpp — which aperture options each kernel uses (aperture_options.h).

#include "aperture_options.h"

#include <bokeh/lens.h>

#include <OpenImageIO/strutil.h>

namespace bokeh {

std::vector<OptionSpec> aperture_shape_option_specs()
{
    return {
        OptionSpec::Int("blades", 6, 3, 64, "polygon: aperture blades; star: points"),
        OptionSpec::Float("rotation", 0.0, -360.0, 360.0, "polygon, hex and star: degrees (0: a vertex up)"),
        OptionSpec::Float("curvature", 0.0, 0.0, 1.0, "polygon and hex: 0 straight blades .. 1 circle"),
        OptionSpec::Float("hole", 0.0, 0.0, 0.95, "disk, polygon and hex: catadioptric hole (radius fraction)"),
        OptionSpec::Float("inner", 0.5, 0.1, 1.0, "star: inner vertices' radius, fraction of the outer"),
    };
}

std::vector<std::string> aperture_kernel_names() { return { "disk", "hex", "polygon", "star" }; }

OptionSpec aspect_option_spec()
{
    return OptionSpec::Float("aspect", 1.0, kMinAspect, kMaxAspect, "bokeh height / width (anamorphic squeeze)");
}

std::vector<OptionSpec> camera_option_specs(bool from_image)
{
    return {
        OptionSpec::Float("fstop", 2.8, kMinFstop, kMaxFstop, from_image ? "f-number (default: image's bokeh:fstop, else 2.8)" : "f-number"),
        OptionSpec::Float("focal", 50.0, kMinFocalMm, kMaxFocalMm,
                          from_image ? "focal length mm (default: image's bokeh:focal_mm, else 50)" : "focal length mm"),
        OptionSpec::String("sensor", "36",
                           from_image ? "film back width in mm or a preset (ff, super35, alexa-lf, ...); "
                                        "default: image's bokeh:sensor_width_mm, else 36"
                                      : "film back width in mm or a preset (ff, super35, alexa-lf, ...)"),
    };
}

bool aperture_options_apply(const OptionValues& v, const std::string& kernel, std::string& why)
{
    const bool polygon = kernel == "polygon" || kernel == "hex";
    struct Rule {
        const char* option;
        bool applies;
        const char* to;
    };
    const Rule rules[] = {
        { "sigma", kernel == "gaussian", "kernel=gaussian" },
        { "blades", kernel == "polygon" || kernel == "star", "kernel=polygon (and star, its points); kernel=hex has 6" },
        { "rotation", polygon || kernel == "star",
          "kernel=polygon, hex and star; a disk's squeeze stays on the frame's axes" },
        { "inner", kernel == "star", "kernel=star" },
        { "curvature", polygon, "kernel=polygon and hex" },
        { "hole", polygon || kernel == "disk", "kernel=disk, polygon and hex" },
    };
    for (const Rule& r : rules)
        if (v.given(r.option) && !r.applies) {
            why = OIIO::Strutil::fmt::format("{} does not apply to kernel={}: it is for {}", r.option, kernel,
                                             r.to);
            return false;
        }
    return true;
}

bool aperture_kernel_from(const OptionValues& v, Kernel& k, std::string& why)
{
    const std::string& shape = v.get_string("kernel");
    if (!aperture_options_apply(v, shape, why))
        return false;
    if (shape == "star") {
        k.shape = KernelShape::Opening;
        return Aperture::star(v.get_int("blades"), v.get_float("inner"), v.get_float("rotation"), k.opening, why);
    }
    k.shape        = shape == "disk" ? KernelShape::Disk : KernelShape::Polygon;
    k.blades       = shape == "hex" ? 6 : v.get_int("blades");
    k.rotation_deg = float(v.get_float("rotation"));
    k.curvature    = float(v.get_float("curvature"));
    k.hole         = float(v.get_float("hole"));
    return true;
}

}  // namespace bokeh
