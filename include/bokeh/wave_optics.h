// wave_optics.h — scalar wave optics of a defocused lens: Fresnel integrals and the exact
// straight-edge law for the fringes at a bokeh's rim; the exact defocused PSF of a round
// pupil (Hankel integral, Lommel series) and of any pupil (FFT); Kawase's
// pseudo-diffraction map; radial profiles that make the models interchangeable.
// docs/methods/diffraction.md has the formulas, the checks and the figures.
//
// Units. Functions that take physical lengths take them all in one unit of the caller's
// choice (the parameter names say which quantity), so `fringe_scale(0.0005, 2, 12)` with
// millimetres returns millimetres. Helpers with `_px`, `_nm`, `_mm` in their names convert
// from the project's units (CoC in pixels, wavelength in nanometres, pixel pitch in mm).
//
// Symbols (docs/methods/optics.md): N working f-number, lambda wavelength, c geometric CoC
// diameter on the sensor, d distance inward from the geometric edge of the bokeh.
#pragma once

#include <bokeh/spectrum.h>

#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// The Fresnel integrals C(x) = int_0^x cos(pi t^2 / 2) dt and S(x) = int_0^x sin(pi t^2 / 2) dt
/// (odd in x; both tend to 1/2 as x -> +inf). Absolute error below 1e-12 for every finite x.
struct FresnelCS {
    double C = 0.0;
    double S = 0.0;
};
FresnelCS fresnel_integrals(double x);

/// The straight-edge (knife-edge) Fresnel diffraction law, relative to the unobstructed
/// intensity: I / I_geo = 1/2 [ (C(v) + 1/2)^2 + (S(v) + 1/2)^2 ], v > 0 on the lit side
/// (inside the bokeh), v < 0 in the shadow (outside); 1/4 at the edge, 1 far inside.
double fresnel_edge_intensity(double v);

/// The length scale of the fringes at a defocused bokeh's edge, sqrt(lambda N c), in the
/// unit of the arguments (wavelength and coc in one unit). A distance d inward from the
/// geometric edge has edge-law argument v = sqrt(2) d / fringe_scale (edge_v below).
/// Returns NaN unless wavelength > 0, fnumber > 0, coc >= 0.
double fringe_scale(double wavelength, double fnumber, double coc);

/// fringe_scale in pixels from the project's units: a CoC diameter in pixels, a wavelength
/// in nanometres, the pixel pitch in millimetres.
double fringe_scale_px(double coc_px, double fnumber, double wavelength_nm, double pixel_pitch_mm);

/// The edge-law argument of a point `distance` inward from the geometric edge (negative:
/// outside), `distance` in the unit of fringe_scale_length.
inline double edge_v(double distance, double fringe_scale_length)
{
    return 1.4142135623730951 * distance / fringe_scale_length;
}

// ---------------------------------------------------------------------------------------
// The exact defocused PSF of a circular pupil (Born & Wolf 8.8)
//
//     I(v) = | 2 int_0^1 exp(i 2 pi W(rho)) J0(v rho) rho drho |^2,   v = k NA r = pi r / (lambda N)
//
// with W the pupil wavefront in waves. Normalisation: the in-focus peak is 1, and for every
// wavefront int_0^inf I(v) v dv = 2, i.e. I / (4 pi) is the energy per unit area of the
// (v_x, v_y) plane (in the sensor plane: I pi NA^2 / lambda^2 per unit area, NA = 1 / (2N)).
// Pure defocus W = W20 rho^2: geometric edge at v = u = 4 pi W20, flat geometric intensity
// I_geo = (2 / u)^2.

/// A rotationally symmetric pupil wavefront, all amplitudes in waves (units of lambda):
/// W(rho) = W20 rho^2 + W40 rho^4 + W60 rho^6 + a cos(pi K rho), K = ripple cycles across the
/// pupil diameter (concentric machining marks: onion rings, docs/methods/optics.md).
struct RadialWavefront {
    double defocus_waves     = 0.0;  ///< W20
    double spherical_waves   = 0.0;  ///< W40
    double spherical6_waves  = 0.0;  ///< W60
    double ripple_waves      = 0.0;  ///< a
    double ripple_cycles     = 0.0;  ///< K, cycles per pupil diameter
    /// W(rho) in waves.
    double waves(double rho) const;
    /// An upper bound of |dW/drho| over the pupil, in waves (bounds the integrand's frequency).
    double max_slope_waves() const;
};

/// The Hankel integral above by composite Simpson on a fixed node set, made once for a
/// wavefront and the largest v it will be asked for: 64 + 100 (max |dW/drho| + v_max / 2 pi)
/// nodes (about 100 per cycle of the integrand; Simpson's error is then ~1e-7 relative).
/// J0 from its Hankel asymptotic expansion for arguments >= 20, a cubic Hermite table of
/// the library's cyl_bessel_j below (within 5e-13 everywhere). Thread-safe to evaluate.
class HankelPsf {
public:
    HankelPsf(const RadialWavefront& wavefront, double v_max);
    /// I(v) as normalised above; v beyond v_max is still computed, less accurately.
    double operator()(double v) const;
    int nodes() const { return int(rho_.size()); }
    const RadialWavefront& wavefront() const { return wavefront_; }

private:
    RadialWavefront wavefront_;
    std::vector<double> rho_, re_, im_;  // node, Simpson weight x rho x cos / sin(2 pi W)
    double step_ = 0.0;
};

/// The same PSF for pure defocus by Lommel's functions (Born & Wolf 8.8.1): u = 4 pi W20,
/// inside (v < u) from V0, V1, outside from U1, U2. For u > 0; u = 0 gives the Airy pattern.
double defocus_psf_lommel(double u, double v);

/// J0 as the Hankel integral evaluates it (exposed for its test).
double bessel_j0(double x);

/// u = 4 pi W20 / lambda: the geometric edge in v.
inline double defocus_u(double defocus_waves) { return 12.566370614359172 * defocus_waves; }

/// W20 in waves of a geometric CoC diameter: c / (8 N lambda) (c, lambda in one unit).
double defocus_waves(double coc, double fnumber, double wavelength);
/// The same from the project's units.
double defocus_waves_px(double coc_px, double fnumber, double wavelength_nm, double pixel_pitch_mm);

/// v = pi r / (lambda N) of a radius of r_px pixels.
double radius_v_px(double r_px, double fnumber, double wavelength_nm, double pixel_pitch_mm);

// ---------------------------------------------------------------------------------------
// Radial profiles: interchangeable models of a round bokeh's intensity against rho = r / R
// (R the geometric CoC radius), each at one wavelength, given w = W20 / lambda = c / (8 N lambda)
// (the only parameter of a defocused aberration-free pupil).
// Normalised to unit energy with R as the unit of length, int_0^inf 2 pi rho I drho = 1, so a
// flat disc is 1 / pi inside.

class RadialProfile {
public:
    virtual ~RadialProfile() = default;
    /// Intensity at rho = r / R, unit energy.
    virtual double operator()(double rho) const = 0;
    /// rho beyond which the profile is taken as 0 (where rasterising may stop).
    virtual double extent() const = 0;
    virtual const char* name() const = 0;
};

/// The exact profile: HankelPsf at v = u rho, times u^2 / (4 pi). `wavefront.defocus_waves`
/// must be > 0 (it sets R). Evaluated out to rho_max (default 1.25). Null on bad values.
std::unique_ptr<RadialProfile> exact_radial_profile(const RadialWavefront& wavefront,
                                                    double rho_max = 1.25);

/// The straight-edge law (fresnel_edge_intensity) at v = 2 (1 - rho) sqrt(w), flat inside,
/// scaled to unit energy over rho <= extent = 1 + 3 / sqrt(w) (the law's shadow side
/// falls below 0.2 % of I_geo there). `defocus_waves` > 0; null otherwise.
std::unique_ptr<RadialProfile> edge_law_radial_profile(double defocus_waves);

// ---------------------------------------------------------------------------------------
// The exact PSF of any pupil by a zero-padded 2-D FFT (Fraunhofer diffraction of the pupil
// function P exp(i 2 pi W) in the focal plane of the converging wave: defocus is part of W;
// Goodman, "Introduction to Fourier Optics", 3rd ed., 6.4; as prysm and poppy do).

/// A pupil at normalised coordinates (x, y): the round pupil of the f-number is the unit
/// disc. Amplitude transmission in [0, 1] (an empty function: the unit disc) and the
/// wavefront in waves (empty: 0). The pupil grid spans [-1, 1]^2 only: transmission outside
/// it is not sampled. Both are called from several threads at once.
struct Pupil {
    std::function<double(double x, double y)> transmission;
    std::function<double(double x, double y)> wavefront_waves;
};

/// Sampling of pupil_psf_fft: pupil samples across the diameter at
/// least the CoC in units of lambda N (8 W20), with a 1.5-2x margin; the FFT at least twice
/// that. The PSF pixel is then lambda N / Q, Q = fft_size / pupil_samples (pi / Q in v).
struct PupilSampling {
    int pupil_samples   = 0;  ///< across the diameter; 0: 8 x max |dW/drho| (4 per wave of tilt), >= 64
    int fft_size        = 0;  ///< 0: the smallest 2^a 3^b 5^c >= 2 x pupil_samples
    int edge_supersample = 4; ///< s x s sub-samples per pupil cell (antialiased pupil edge)
};

/// The PSF of a pupil: a 1-channel float image fft_size square, unit sum, the optical axis at
/// pixel (fft_size / 2, fft_size / 2); its pixel in units of lambda N and of v.
struct PupilPsf {
    OIIO::ImageBuf image;
    double pixel_lambda_n = 0.0;
    double pixel_v        = 0.0;
    int pupil_samples     = 0;
};

/// The PSF of `pupil` by FFT (FFTW, double). `max_slope_waves` (max |dW/drho|, e.g.
/// RadialWavefront::max_slope_waves()) sets the default sampling. False with a message in
/// `error` for bad sampling (pupil_samples < 8, fft_size < pupil_samples, over 8192) or a
/// pupil that lets no light through.
bool pupil_psf_fft(PupilPsf& out, const Pupil& pupil, double max_slope_waves,
                   const PupilSampling& sampling = {}, std::string* error = nullptr,
                   int nthreads = 0);

/// A round pupil with a radial wavefront (for comparing the FFT with HankelPsf).
Pupil round_pupil(const RadialWavefront& wavefront);

// ---------------------------------------------------------------------------------------
// Kawase's pseudo-diffraction map ("Bokeh Deep Dive"; core/optics/diffraction_map.cpp)
//
// A 2-D table of a made-up trigonometric fringe pattern, read the way the talk reads it:
// U = log of the fringe width relative to the CoC (x = scale sqrt(lambda N / c)), V = radius
// in a band around the geometric edge; each column energy-normalised with area weighting,
// faded to its local mean where its fringes pass the Nyquist limit (of the table, and of
// the output pixels at lookup), faded to zero a little outside the edge, clamped inside the
// band. The talk publishes the rules and the fringe-width calibration (w2 ~ 0.75 sqrt(Fe c
// lambda)), not its function: ours, below, is the simplest periodic one that follows them.
// Use it to compare with the exact PSF (the talk asks for a better approximation: the edge
// law answers, with the numbers in docs/methods/diffraction.md).

struct PseudoMapOptions {
    int columns              = 64;      ///< U samples (log fringe width / CoC)
    int rows                 = 256;     ///< V samples across a column's band
    double min_width_ratio   = 1e-4;    ///< x at the map's large-bokeh end
    double max_width_ratio   = 0.25;    ///< x at its near-focus end
    double width_scale       = 0.75;    ///< the talk's w2 / sqrt(lambda N c) (its scale knob)
    double band_widths       = 8.0;     ///< fringe widths stored inside the edge (then clamped)
    double outside_widths    = 1.5;     ///< fringe widths stored outside the edge (fade to 0)
    double first_max_widths  = 1.0;     ///< the first bright fringe, in fringe widths from the edge
    double edge_value        = 0.25;    ///< intensity at the geometric edge (flat interior = 1)
    double first_amplitude   = 0.35;    ///< the first bright fringe's height above 1
    double reference_nm      = 710.0;   ///< the wavelength the map is made for (the talk's)
};

/// The trig fringe pattern against s = distance inward from the geometric edge in fringe
/// widths (negative outside), before any fade or normalisation, flat interior = 1: outside,
/// the edge value falling to 0 over outside_widths (smoothstep); from the edge to the first
/// maximum the outermost fringe, e + (1 + A - e) sin^2(pi s / (2 s1)); beyond it
/// 1 + A cos(2 pi (s - s1)) / (1 + (s - s1)): constant spacing of one fringe width, tapered
/// to 1 (smoothstep) over the band's last two fringe widths.
double pseudo_fringe_pattern(const PseudoMapOptions& options, double s);

class PseudoDiffractionMap {
public:
    explicit PseudoDiffractionMap(const PseudoMapOptions& options = {});
    const PseudoMapOptions& options() const { return options_; }
    /// Monochrome intensity at rho = r / R, unit energy (int 2 pi rho I drho = 1), for a
    /// bokeh whose fringe width relative to its CoC is `width_ratio_ref` at the reference
    /// wavelength, seen at `wavelength_ratio` = lambda / lambda_ref: the talk's horizontal
    /// lookup at x_ref (lambda / lambda_ref)^0.5, its vertical squeeze keeping the geometric
    /// edge at rho = 1, intensity scaled by the inverse square of the squeeze.
    /// `pixel_rho` (> 0: one output pixel in units of R) fades the fringes to the local
    /// mean where their period falls under 4 pixels (fully at 2).
    double lookup(double rho, double width_ratio_ref, double wavelength_ratio = 1.0,
                  double pixel_rho = 0.0) const;
    /// The outer radius (rho) the lookup covers at fringe-width ratio x.
    double extent(double width_ratio) const;
    /// The radius inside which the lookup is clamped (flat) at x: 1 - 2 x band_widths, >= 0.
    double clamp_radius(double width_ratio) const;
    /// The fringe-width ratio of W20 / lambda = defocus_waves: width_scale / sqrt(8 w).
    double width_ratio(double defocus_waves) const;

private:
    PseudoMapOptions options_;
    std::vector<float> value_, mean_;  // columns x rows, column-major; normalised
};

/// The diffraction models of a round bokeh, interchangeable as RadialProfiles.
enum class DiffractionMethod {
    None,     ///< the flat disc of geometric optics (1 / pi inside rho < 1)
    EdgeLaw,  ///< edge_law_radial_profile
    PseudoMap,  ///< pseudo_map_radial_profile (needs a map), faded at the output's Nyquist limit
    Exact,    ///< exact_radial_profile (pure defocus; seconds for large bokeh, see the docs)
};

/// One wavelength's profile of a round bokeh of CoC `coc_px` pixels (the sign ignored) at an
/// f-number, wavelength (nm) and pixel pitch (mm), by `method`. Null on bad values, or for
/// PseudoMap without a map (which must outlive the profile).
std::unique_ptr<RadialProfile> diffraction_radial_profile(DiffractionMethod method, double coc_px,
                                                          double fnumber, double wavelength_nm,
                                                          double pixel_pitch_mm,
                                                          const PseudoDiffractionMap* map = nullptr);

/// The pseudo-diffraction map as a RadialProfile at W20 / lambda = defocus_waves, looked up
/// at the map's reference wavelength's column for this W20 (so profiles at several
/// wavelengths follow the talk's wavelength rule when built with their own defocus_waves).
/// `pixel_rho` as in lookup. The map must outlive the profile. Null on bad values.
std::unique_ptr<RadialProfile> pseudo_map_radial_profile(const PseudoDiffractionMap& map,
                                                       double defocus_waves, double pixel_rho = 0.0);

/// A three-channel radial profile sampled at rho = i * rho_step, i = 0 .. size - 1.
struct RgbRadialProfile {
    double rho_step = 0.0;
    std::vector<std::array<double, 3>> values;
};

/// The talk's spectral path for one bokeh (CoC `coc_px` pixels, f-number, pixel pitch mm):
/// the map looked up per wavelength (horizontal (lambda / lambda_ref)^0.5, squeeze, inverse
/// square), summed with the weights; the clamped interior's tint blended toward white by
/// (1 - 1/X)^2, X = 1 / (2 x_ref band_widths) the map's shrink (when X > 1); then each
/// channel normalised to unit energy (white normalisation: a white light stays white).
/// The spectrum's weights are spectrum.h's (spectral_samples); any three channel weights
/// per wavelength will do. `samples` rho samples from 0 to the largest extent. False (and `out` empty) on bad values.
bool pseudo_map_spectral_profile(RgbRadialProfile& out, const PseudoDiffractionMap& map, double coc_px,
                               double fnumber, double pixel_pitch_mm,
                               const std::vector<SpectralSample>& spectrum, int samples = 1024);

}  // namespace bokeh
