// spectrum.h — wavelengths to RGB for spectral PSFs: the CIE 1931 2-degree colour-matching
// functions, XYZ to the working space, and the per-wavelength weights that make a white
// light stay white (docs/methods/optics.md, "The spectrum").
#pragma once

#include <array>
#include <string>
#include <vector>

namespace bokeh {

class ColorSystem;

/// The CIE 1931 2-degree colour-matching functions (x-bar, y-bar, z-bar) at `wavelength_nm`,
/// by the multi-lobe fit of Wyman, Sloan and Shirley, "Simple Analytic Approximations to
/// the CIE XYZ Color Matching Functions", JCGT 2(2), 2013 (their table 1; within ~1 % of
/// the CIE table's peak over the visible range).
std::array<double, 3> cie1931_xyz(double wavelength_nm);

/// XYZ to linear Rec.709 / sRGB primaries, D65 (IEC 61966-2-1).
std::array<double, 3> xyz_to_rec709(const std::array<double, 3>& xyz);

/// The light the spectrum is weighted by.
enum class Illuminant { EqualEnergy, D65 };

/// One wavelength of a spectral integral and what it adds to each RGB channel.
struct SpectralSample {
    double wavelength_nm = 550.0;
    std::array<double, 3> rgb_weight{};  ///< sums to 1 per channel over the samples
};

struct SpectrumOptions {
    double first_nm = 400.0;  ///< 400-710 nm: the range of Kawase's spectral integration
    double last_nm  = 710.0;
    double step_nm  = 10.0;   ///< fringe positions scale as sqrt(lambda): 10 nm suffices
    Illuminant illuminant = Illuminant::EqualEnergy;
};

/// The samples first_nm, first_nm + step_nm, ... last_nm (trapezoid weights), each with
/// the share of each working-space channel it carries:
///     w_c(l) = [M S(l) cmf(l) dl]_c / sum over l of the same
/// (M: XYZ to the working space), so a PSF_c = sum w_c(l) PSF_l keeps unit energy in every
/// channel and a white light stays white. Weights may be negative (the colour-matching
/// functions fall outside the RGB gamut): they are kept in linear light. `colors` may be
/// null (Rec.709 primaries) or a loaded config whose scene-linear space is the working
/// space (XYZ taken from the config's "CIE-XYZ-D65" space, or one holding "XYZ" in its
/// name). A range of one wavelength (first_nm == last_nm) is monochromatic light: one
/// sample of weight 1 in every channel (a sodium lamp's rings, a test's single
/// wavelength). False + `err` for a reversed range, a step outside 0.5..100 nm, or a
/// config without an XYZ space.
bool spectral_samples(std::vector<SpectralSample>& out, const SpectrumOptions& opts,
                      const ColorSystem* colors, std::string& err);

}  // namespace bokeh
