// fit_model.h — the model the lens fit (core/fit/lens_fit.cpp) minimises: a crop read for
// fitting, the nonlinear parameters, the PSF sampled at a crop's pixels with its linear part
// (amplitude and background plane per channel) solved exactly, and a bounded minimiser.
#pragma once

#include <bokeh/lens_fit.h>
#include <bokeh/optics.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace bokeh {
namespace fit {

/// A crop read for fitting.
struct CropData {
    int w = 0, h = 0, channels = 3;
    std::vector<float> px;       // w h channels
    std::vector<uint8_t> use;    // 1: fitted
    std::vector<float> inv_var;  // 1 / sigma^2 per pixel value (the noise model at the data)
    double fx = 0, fy = 0;
    bool field_known = false;
    double peak = 0;             // the highlight's brightest luminance above the background
    double level = 0;            // its mean over a disk of the first CoC (the floors' scale)
    double coc0 = 0, cx0 = 0, cy0 = 0;
    int clipped = 0, nonfinite = 0;
    int others = 0;              // pixels of other highlights (a neighbour), left out
    // The fitted pixels, compact (prepare_fit_arrays): index, column and row, plane
    // coordinates, values channel-major; the weights and the plane's normal sums for a
    // noise floor, cached.
    std::vector<uint32_t> fit_k;
    std::vector<int> fit_i, fit_j;
    std::vector<float> fit_x, fit_y, fit_v;
    mutable std::vector<float> fit_iv;
    mutable double base[3][9] = {};
    mutable double cached_floor2 = -1.0;
};

/// Fill a crop's compact arrays from its `use` mask (after the mask changes).
void prepare_fit_arrays(CropData& d);

/// The nonlinear parameters.
struct State {
    std::vector<double> coc, cx, cy;  // per crop; CoC as a magnitude
    int blades = 0;                   // 0: round
    double rotation = 0, curvature = 0, hole = 0;
    double mono = 0, chroma = 0, onion = 0, catseye = 0, astig = 0;
    double zonal = 0;                 // the zonal correction (LensCharacter::correction)
};

/// A crop's linear part, per channel: amplitude, the plane's level and slopes.
struct Linear {
    double a[3] = { 0, 0, 0 }, b0[3] = { 0, 0, 0 }, bx[3] = { 0, 0, 0 }, by[3] = { 0, 0, 0 };
};

/// Solve the n x n system a x = b (Gaussian elimination, partial pivoting; `a` and `b`
/// are overwritten); false if singular.
bool solve_linear(int n, double* a, double* b, double* x);

/// The luminance (Rec. 709) of a pixel of `channels` (1: the value itself).
double luminance(const float* p, int channels);

/// Read crop `index`: its pixels as floats, what is left out, its field position and the
/// first estimates of its highlight. False + `err` (naming the crop) for an unusable crop.
bool prepare_crop(CropData& d, const LensFitCrop& crop, size_t index, double clip_level, std::string& err);

/// The plane coordinates of pixel column i / row j: -1..1 across the crop.
inline double plane_x(const CropData& d, int i) { return (i + 0.5 - 0.5 * d.w) / (0.5 * d.w); }
inline double plane_y(const CropData& d, int j) { return (j + 0.5 - 0.5 * d.h) / (0.5 * d.h); }

/// The crops' model for a State: PSFs rendered by lens_psf, costs summed over crops.
class Model {
public:
    Model(const std::vector<CropData>& crops, const LensFitOptions& opts, int nthreads)
        : m_crops(crops), m_opts(opts), m_nthreads(nthreads)
    {
    }
    /// The lens a State describes (the `uncorrected` design, third-order spherical
    /// aberration); `coarse_spectrum`: the fit's spectral step.
    LensCharacter lens_of(const State& s, bool coarse_spectrum) const;
    double signed_coc(const State& s, size_t i) const { return m_opts.front ? -s.coc[i] : s.coc[i]; }
    /// Crop i's PSF; false on a PSF the lens refuses.
    bool psf(Psf& out, const State& s, size_t i, bool coarse, int nthreads) const;
    /// The PSF sampled at crop d's pixels, centred at (cx, cy) (bilinear; zero outside the
    /// PSF), channel-major.
    static void sample(std::vector<float>& dst, const Psf& p, const CropData& d, double cx, double cy);
    /// The same at the crop's fitted pixels only, in their compact order (fit_k), channel-major.
    static void sample_fitted(std::vector<float>& dst, const Psf& p, const CropData& d, double cx, double cy,
                              int nthreads = 1);
    /// Solve the linear part for the PSF `s` sampled at the fitted pixels (sample_fitted:
    /// inverse-variance weights, then the
    /// Cauchy weights of their residuals) and return the Cauchy cost over the crop's pixels;
    /// `residuals` gets the weighted residuals sqrt(w) r, `outliers` the pixels past the
    /// scale; `floor_of_level` adds (floor_of_level x the crop's light level)^2 to each
    /// variance. The sums run in fixed chunks of pixels, so any `nthreads` gives the same bits.
    static double fit_linear(const CropData& d, const std::vector<float>& s, Linear& lin,
                             std::vector<double>* residuals = nullptr, int* outliers = nullptr,
                             double floor_of_level = 0.0, int nthreads = 1);
    /// The cost of the crops in `which` (all when empty).
    double cost(const State& s, bool coarse, const std::vector<size_t>& which = {}) const;
    int evaluations() const { return m_evaluations; }
    /// A noise floor, a fraction of each crop's light level, added to its noise model while a
    /// stage searches: it keeps the Cauchy loss in its quadratic part far from the
    /// optimum, where a noise-free crop's landscape is all outliers (graduated
    /// non-convexity, Blake & Zisserman 1987).
    void set_floor(double floor_of_level) { m_floor = floor_of_level; }
    /// A crop's centre names where its light's centroid is, not where the chief ray lands.
    /// Off the axis a cut pupil moves the light away from the chief ray's image: with the
    /// centres free as chief-ray positions, the cat's eye and astigmatism traded against
    /// them and a lens with both was not found (docs/methods/lens-fit.md); as centroids
    /// they stay where the crops show the light while the field effects change.
    void set_centres_at_light(bool on) { m_centres_at_light = on; }
    /// Where crop i's PSF is centred for a State: its centre, less the PSF's light
    /// centroid when the centres name the light.
    void place(const Psf& p, const State& s, size_t i, double& cx, double& cy) const;
    /// Crop i's PSF `p` placed for `s` (place) and sampled at its fitted pixels
    /// (sample_fitted): what fit_linear takes.
    void sample_crop(std::vector<float>& dst, const Psf& p, const State& s, size_t i, int nthreads = 1) const;
    const std::vector<CropData>& crops() const { return m_crops; }

private:
    const std::vector<CropData>& m_crops;
    const LensFitOptions& m_opts;
    int m_nthreads;
    mutable int m_evaluations = 0;
    double m_floor = 0.0;
    bool m_centres_at_light = false;
};

/// The noise model sigma^2 = read2 + photon * max(value, 0), estimated from the crops'
/// pixels alone (no model); each crop's inverse variances are set from it.
void estimate_noise(std::vector<CropData>& crops, double& read2, double& photon);
/// Set each crop's inverse variances from the noise model (read2, photon).
void set_noise(std::vector<CropData>& crops, double read2, double photon);

/// A parameter free in a minimisation: where it lives, its bounds, its first step.
struct Free {
    double* value;
    double lo, hi, step;
};

/// The noise model the residuals of `s` show (least squares of r^2 on (1, model), those
/// past 5 sigma of the current model left out); sets nothing.
void residual_noise(const std::vector<CropData>& crops, const Model& model, const State& s, double& read2,
                    double& photon);

/// Minimise `cost` over `free` from their current values (BOBYQA; Subplex for one
/// parameter), at most `max_evaluations` calls; leaves the best values set and returns
/// the best cost.
double minimise(std::vector<Free>& free, const std::function<double()>& cost, int max_evaluations);

}  // namespace fit
}  // namespace bokeh
