// lens_fit.h — fit the lens model of optics.h to photographed bokeh: crops of defocused
// highlights from a plate give back the aperture (round or bladed, rotation, curvature,
// hole), the rim profile (spherical aberration's sign and amount), axial colour and onion
// rings (and, from crops across the frame, the cat's eye and astigmatism),
// as the LensCharacter that `--defocus` and `--bokeh` take (docs/methods/lens-fit.md has
// the method, its checks and its limits).
//
// Each crop is modelled as
//     crop_c(x, y) = A_c PSF_c(x - cx, y - cy; lens, CoC, field) + b_c + gx_c x + gy_c y
// (a light of unknown colour and brightness over a background plane). The amplitudes and
// planes are linear and solved exactly inside each evaluation (variable projection); the
// lens, each crop's CoC and centre are found by NLopt's BOBYQA (Powell 2009), in stages
// from the coarse to the fine, each stage kept only when it lowers the cost by more than
// the Bayesian information criterion's price of its parameters ("model no more than the
// crops show"), then refined together by Levenberg-Marquardt. Residuals are weighted by a noise model fitted to the crops (read noise
// plus photon noise) under a Cauchy loss, so a neighbour highlight or blocking costs
// little; clipped and non-finite pixels are left out.
#pragma once

#include <bokeh/optics.h>

#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// What a crop is and where it was in the frame.
struct LensFitCrop {
    OIIO::ImageBuf image;  ///< linear RGB (or one channel); its first three channels are used
    /// Field position of the crop's centre, half-diagonals (x right, y up), when known.
    /// Unset (NaN): read from the crop's data window inside its display window (a crop
    /// cut from a frame with its origin kept); a crop whose windows are the same is taken
    /// at the centre of the frame.
    double field_x = std::numeric_limits<double>::quiet_NaN();
    double field_y = std::numeric_limits<double>::quiet_NaN();
};

struct LensFitOptions {
    /// The camera the plate was shot with: fstop, focal_mm and pixel_pitch_mm of this lens
    /// scale the aberrations; the rest of it is where the fit starts (and, for what is not
    /// fitted, what it reports).
    LensCharacter camera;
    /// Pixels at or above this value in any channel are clipped and left out; 0: found
    /// from each crop (its maximum, when more than 2 pixels share it to 1e-4).
    double clip_level = 0.0;
    /// The highlights are in front of focus (negative CoC). One crop cannot tell a front
    /// bokeh from a back one with the aberrations' signs reversed; this says which.
    bool front = false;
    bool fit_aperture = true;    ///< blades (round, 5..9), rotation, curvature
    bool fit_hole     = true;    ///< a catadioptric hole
    bool fit_spherical = true;   ///< the rim profile: monochromatic (signed)
    bool fit_colour   = true;    ///< axial colour: chromatic (signed)
    bool fit_onion    = true;    ///< onion-ring contrast
    /// Cat's eye and astigmatism, when crops off the axis (0.3 half-diagonals or more) have
    /// known field positions (three crops centre to corner: a cat's eye of 0.6 with an
    /// astigmatism of 6 px read 0.598 and 5.92 px; either alone, and neither, read right).
    /// It about doubles the time of a fit of crops from across the frame.
    bool fit_field    = true;
    int max_evaluations = 4000;  ///< PSF evaluations over all stages
};

/// One fitted (or not fitted) parameter.
struct LensFitParameter {
    std::string name;        ///< the option name `--defocus`/`--bokeh` use ("blades", "monochromatic", ...)
    double value = 0.0;
    double sigma = 0.0;      ///< one standard deviation from the fit's curvature (0: not fitted)
    enum class Status { Fitted, Undetermined, Off } status = Status::Off;
    std::string why;         ///< for Undetermined/Off: why it was left at its default
};

/// What the fit found for one crop.
struct LensFitCropResult {
    double coc_px = 0.0;                 ///< signed CoC
    double coc_sigma_px = 0.0;           ///< its one-sigma uncertainty
    double centre_x = 0.0, centre_y = 0.0;  ///< in crop pixels from its data window's corner
    double field_x = 0.0, field_y = 0.0;
    bool field_known = false;
    double amplitude[3] = { 0, 0, 0 };   ///< the light's energy per channel
    double background[3] = { 0, 0, 0 };  ///< the plane's level at the crop's centre
    double background_dx[3] = { 0, 0, 0 };  ///< its change from the centre to the right edge
    double background_dy[3] = { 0, 0, 0 };  ///< its change from the centre to the bottom edge
    double residual_rms[3] = { 0, 0, 0 };  ///< over the pixels fitted, in crop units
    double psnr_db = 0.0;                 ///< fit against crop over the fitted pixels, peak = the light's
    int clipped_px = 0, nonfinite_px = 0;  ///< left out
    int outlier_px = 0;  ///< another highlight's pixels (left out) and residuals past the loss's scale
};

struct LensFit {
    LensCharacter lens;                    ///< the fitted lens (the camera's fields kept)
    std::vector<LensFitParameter> parameters;
    std::vector<LensFitCropResult> crops;
    std::string options;                   ///< the lens as `--defocus`/`--bokeh` options
    double noise_read = 0.0;               ///< fitted noise model: sigma^2 = read^2 + photon * signal
    double noise_photon = 0.0;
    int evaluations = 0;
    double seconds = 0.0;
    std::vector<std::string> stages;       ///< each stage's cost and whether it was kept, for -v
};

/// Fit the lens to `crops` (at least one). False + `err` naming the crop and the reason for
/// a crop with no highlight, one all clipped, one smaller than its bokeh, or bad options.
bool fit_lens(LensFit& fit, const std::vector<LensFitCrop>& crops, const LensFitOptions& opts,
              std::string& err, int nthreads = 0);
/// What fit_lens() checks of its options: the clip level, the evaluation budget, the
/// camera (check_lens). False + `err` naming the option.
bool check_lens_fit_options(const LensFitOptions& opts, std::string& err);

/// The fit's PSF for crop `index` rendered as that crop: A PSF + background (RGB float,
/// the crop's windows).
bool lens_fit_model_image(OIIO::ImageBuf& dst, const LensFit& fit, const std::vector<LensFitCrop>& crops,
                          int index, int nthreads = 0);
inline OIIO::ImageBuf lens_fit_model_image(const LensFit& fit, const std::vector<LensFitCrop>& crops, int index,
                                           int nthreads = 0)
{
    OIIO::ImageBuf dst;
    lens_fit_model_image(dst, fit, crops, index, nthreads);
    return dst;
}

/// A comparison sheet: a row per crop of crop | fit | |crop - fit| x 4 | the fitted light
/// alone (the PSF times its amplitude, no background), each cell the crop's size with a
/// 2 px black gutter, RGB float (a one-channel crop is shown grey).
bool lens_fit_sheet(OIIO::ImageBuf& dst, const LensFit& fit, const std::vector<LensFitCrop>& crops,
                    int nthreads = 0);
inline OIIO::ImageBuf lens_fit_sheet(const LensFit& fit, const std::vector<LensFitCrop>& crops, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    lens_fit_sheet(dst, fit, crops, nthreads);
    return dst;
}

/// A crop of a known lens's highlight as a plate would hold it, for round trips and
/// demos: energy x PSF at an integer offset from the crop's centre, over a background
/// plane, with photon noise (sigma^2 = g v, g set by the SNR at the light's peak) and read
/// noise (1 % of the peak's noise), clipped at `clip`.
struct SyntheticCrop {
    double coc_px  = 40.0;  ///< signed
    int size_px    = 97;    ///< the crop's side (odd)
    int offset_x = 0, offset_y = 0;  ///< the light's centre from the crop's centre, px
    double energy[3]     = { 4000.0, 3600.0, 3000.0 };  ///< the light's, per channel
    double background[3] = { 0.05, 0.06, 0.08 };
    double gradient_x = 0.0, gradient_y = 0.0;  ///< background change per px
    double peak_snr = 0.0;   ///< 0: no noise
    double clip     = 0.0;   ///< 0: none
    double field_x = 0.0, field_y = 0.0;  ///< also set on the crop
    unsigned seed  = 1;
};
bool synthetic_crop(LensFitCrop& dst, const LensCharacter& lens, const SyntheticCrop& spec, std::string& err,
                    int nthreads = 0);

}  // namespace bokeh
