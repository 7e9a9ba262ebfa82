// aperture_options.cpp — which aperture options each kernel uses (aperture_options.h).

#include "aperture_options.h"

#include <OpenImageIO/strutil.h>

namespace bokeh {

bool aperture_options_apply(const OptionValues& v, const std::string& kernel, std::string& why)
{
    const bool polygon = kernel == "polygon" || kernel == "hex";
    // Only --bokeh draws a star (its option inner= says so): elsewhere the messages do not
    // name a kernel the command lacks.
    const bool has_star = v.values.count("inner") > 0;
    struct Rule {
        const char* option;
        bool applies;
        const char* to;
    };
    const Rule rules[] = {
        { "sigma", kernel == "gaussian", "kernel=gaussian" },
        { "blades", kernel == "polygon" || kernel == "star",
          has_star ? "kernel=polygon (and star, its points); kernel=hex has 6" : "kernel=polygon; kernel=hex has 6" },
        { "rotation", polygon || kernel == "star",
          has_star ? "kernel=polygon, hex and star; a disk's squeeze stays on the frame's axes"
                   : "kernel=polygon and hex; a disk's squeeze stays on the frame's axes" },
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
    k.shape        = shape == "disk" ? KernelShape::Disk : KernelShape::Polygon;
    k.blades       = shape == "hex" ? 6 : v.get_int("blades");
    k.rotation_deg = float(v.get_float("rotation"));
    k.curvature    = float(v.get_float("curvature"));
    k.hole         = float(v.get_float("hole"));
    return true;
}

}  // namespace bokeh
