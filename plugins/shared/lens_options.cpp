// lens_options.cpp — the lens-character options shared by the commands that draw with a
// lens (see lens_options.h); the model they set is optics.h's.

#include "lens_options.h"

#include <cmath>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

std::vector<OptionSpec> lens_option_specs()
{
    return {
        OptionSpec::Choice("lens", { "off", "uncorrected", "achromat", "apochromat" },
                           "lens design: its spherical aberration and axial colour"),
        OptionSpec::Float("monochromatic", 1.0, -20.0, 20.0,
                          "spherical aberration, times the lens's own (negative: its sign reversed)"),
        OptionSpec::Float("chromatic", 1.0, -20.0, 20.0, "axial colour, times the lens's own (negative reverses)"),
        OptionSpec::Float("correction", -1.0, -1.0, 3.0,
                          "zonal correction: 0 none, 1 at the rim, 1.6 over-corrected (bubble); -1 the lens's own"),
        OptionSpec::Float("spherochromatism", 0.0, -5.0, 5.0, "change of spherical aberration per 100 nm"),
        OptionSpec::Choice("diffraction", { "off", "exact", "pseudo" },
                           "rim fringes: exact = the Fresnel edge law, pseudo = Kawase's pseudo-diffraction map"),
        OptionSpec::String("wavelengths", "400-710", "spectrum integrated, nm (FIRST-LAST; one number: monochromatic)"),
        OptionSpec::Float("wavestep", 10.0, 0.5, 100.0, "spectral step, nm"),
        OptionSpec::Choice("illuminant", { "equal", "d65" }, "the light's spectrum"),
        OptionSpec::Float("onion", 0.0, 0.0, 1.0, "onion-ring contrast (procedural)"),
        OptionSpec::Float("onionwaves", 0.0, 0.0, 1.0, "onion rings from a surface ripple of this many waves (physical)"),
        OptionSpec::Float("onioncycles", 10.0, 1.0, 200.0, "onion rings per pupil diameter"),
        OptionSpec::Float("onionsharpness", 1.0, 1.0, 32.0, "1 sinusoidal .. larger: thin bright rings"),
        OptionSpec::Float("onionoffset", 0.3, -2.0, 2.0, "ring-centre shift at the frame corner, pupil radii"),
        OptionSpec::Bool("onionfront", false, "the rough element is in front of the stop (rings move slower)"),
        OptionSpec::Float("noise", 0.0, 0.0, 1.0, "lens-surface noise contrast"),
        OptionSpec::Float("catseye", 0.0, 0.0, 1.5, "cat's eye: barrel offset at the frame corner, pupil radii"),
        OptionSpec::Float("fieldcurvature", 0.0, -4096.0, 4096.0, "CoC px added at the frame corner"),
        OptionSpec::Float("astigmatism", 0.0, -4096.0, 4096.0,
                          "tangential minus sagittal CoC px at the corner (negative: swirl)"),
        OptionSpec::Float("anamorphicfocus", 0.0, -4096.0, 4096.0, "horizontal minus vertical CoC px"),
    };
}

bool lens_character_from(const OptionValues& v, LensCharacter& lens, std::string& err)
{
    if (!lens_preset_named(v.get_string("lens"), lens.preset)) {
        err = format("lens '{}' is not a lens design", v.get_string("lens"));
        return false;
    }
    lens.monochromatic    = v.get_float("monochromatic");
    lens.chromatic        = v.get_float("chromatic");
    lens.correction       = v.get_float("correction");
    lens.spherochromatism = v.get_float("spherochromatism");
    const std::string& diffraction = v.get_string("diffraction");
    lens.diffraction = diffraction == "exact" ? DiffractionModel::EdgeLaw
                       : diffraction == "pseudo" ? DiffractionModel::PseudoMap
                                               : DiffractionModel::Off;
    const std::string& range = v.get_string("wavelengths");
    const size_t dash        = range.find('-', 1);
    const bool one           = dash == std::string::npos;
    if (!parse_number(std::string_view(range).substr(0, dash), lens.spectrum.first_nm)
        || !parse_number(one ? std::string_view(range) : std::string_view(range).substr(dash + 1),
                         lens.spectrum.last_nm)) {
        err = format("wavelengths '{}' is neither a range FIRST-LAST nor one wavelength, in nm "
                     "(e.g. 400-710, 589)",
                     range);
        return false;
    }
    lens.spectrum.step_nm    = v.get_float("wavestep");
    lens.spectrum.illuminant = v.get_string("illuminant") == "d65" ? Illuminant::D65 : Illuminant::EqualEnergy;
    lens.onion               = v.get_float("onion");
    lens.onion_waves         = v.get_float("onionwaves");
    lens.onion_cycles        = v.get_float("onioncycles");
    lens.onion_sharpness     = v.get_float("onionsharpness");
    lens.onion_offset        = v.get_float("onionoffset");
    lens.onion_behind_stop   = !v.get_bool("onionfront");
    lens.surface_noise       = v.get_float("noise");
    lens.catseye             = v.get_float("catseye");
    lens.field_curvature_px  = v.get_float("fieldcurvature");
    lens.astigmatism_px      = v.get_float("astigmatism");
    lens.anamorphic_focus_px = v.get_float("anamorphicfocus");
    return check_lens(lens, err);
}

}  // namespace bokeh
