// diffraction_map.cpp — the pseudo-diffraction map of Kawase's "Bokeh Deep Dive", built by
// every rule the talk lists, so that its error against the exact PSF can be measured.
//
// Source: Kawase, "Bokeh Deep Dive", its diffraction-pattern part (docs/methods/
// diffraction.md, "Kawase's pseudo-diffraction map"): an isotropic 1-D radial fringe
// pattern stored as a 2-D map, U = log of the fringe width relative to the CoC, V =
// radius; a made-up trigonometric pattern (the talk's own words: crude, inaccurate near
// focus and at the centre) calibrated by w2 ~ 0.75 sqrt(Fe c lambda) for the second fringe.
// The talk does not publish its function. Ours (pseudo_fringe_pattern) is the simplest
// periodic one that follows its description: an outermost fringe made separately (the
// talk: "the outermost fringe is hard to generalise, so it is made separately and joined")
// and a cosine of constant spacing w2 inside, decaying as 1 / (1 + fringes) and tapered off
// over the band's last two fringe widths (so the clamped interior is flat); its edge value
// 1/4 and first height 1.35 are the classic straight-edge figures, its first maximum one
// fringe width in. Every fringe position it has therefore follows the talk's calibration.
//
// The rules, as implemented:
// * U: log x, x = width_scale sqrt(lambda N / c) from min to max_width_ratio; V: a band from
//   band_widths fringe widths inside the edge to outside_widths outside (fringe width in rho
//   is 2x), so the band holds the same number of fringes in every column;
// * Nyquist: where a column's fringe period spans under 4 texels the pattern fades to its
//   local mean (its average over one fringe width), fully at 2 texels; at lookup the same
//   against the output pixel (`pixel_rho`);
// * outside the edge: a smoothstep to 0 over outside_widths;
// * area-weighted energy normalisation: each column divided by its mean over the disc of
//   radius extent(x), the clamped interior counted at its clamped value, a ring at rho
//   weighted by rho (the talk's 3:1 example);
// * wavelength: horizontal lookup at x_ref (lambda / lambda_ref)^0.5, the geometric edge held
//   at rho = 1 (the vertical squeeze), intensity divided by the squared extent (the inverse
//   square of the squeeze): unit energy at every wavelength;
// * clamped interior: rho < 1 - 2x band_widths reads the band's innermost row; in the
//   spectral sum its tint is blended toward white by (1 - 1/X)^2, X = 1 / (2 x band_widths);
// * white normalisation: after the spectral sum each channel is scaled to unit energy.
// Limits: isotropic (an aperture shape is a radial distortion applied by the caller); no
// centre spot and no focus-side pattern (the talk's own limits); bilinear table lookups mix
// neighbouring columns whose bands differ slightly, as a texture fetch does.

#include <bokeh/base.h>
#include <bokeh/wave_optics.h>

#include <algorithm>
#include <cmath>

namespace bokeh {

namespace {


double smoothstep01(double t)
{
    t = std::clamp(t, 0.0, 1.0);
    return t * t * (3 - 2 * t);
}

// 1 where a fringe period spans >= 4 samples, 0 at <= 2, smooth between.
double nyquist_weight(double period_samples) { return smoothstep01(0.5 * (period_samples - 2.0)); }

}  // namespace

double pseudo_fringe_pattern(const PseudoMapOptions& o, double s)
{
    const double e = o.edge_value, A = o.first_amplitude, s1 = o.first_max_widths;
    if (s < 0)
        return e * (1.0 - smoothstep01(-s / o.outside_widths));
    if (s < s1) {
        const double t = std::sin(0.5 * kPi * s / s1);
        return e + (1 + A - e) * t * t;
    }
    // The last two fringe widths of the band taper the fringes off, so the clamped interior
    // beyond reads the flat 1 (untapered, it would read the band's last residual fringe,
    // A / (1 + band - s1) = 4 % with the defaults, as the interior's level).
    const double taper = 1 - smoothstep01(0.5 * (s - (o.band_widths - 2)));
    return 1 + taper * A * std::cos(2 * kPi * (s - s1)) / (1 + (s - s1));
}

PseudoDiffractionMap::PseudoDiffractionMap(const PseudoMapOptions& options) : options_(options)
{
    PseudoMapOptions& o = options_;
    o.columns         = std::max(2, o.columns);
    o.rows            = std::max(8, o.rows);
    const int nu = o.columns, nv = o.rows;
    value_.assign(size_t(nu) * size_t(nv), 0.0f);
    mean_.assign(value_.size(), 0.0f);
    const double lo = std::log(o.min_width_ratio), hi = std::log(o.max_width_ratio);
    std::vector<double> val(static_cast<size_t>(nv)), avg(static_cast<size_t>(nv));
    for (int j = 0; j < nu; ++j) {
        const double x      = std::exp(lo + (hi - lo) * j / (nu - 1));
        const double f      = 2 * x;  // a fringe width in rho
        const double rho_in = clamp_radius(x), rho_out = extent(x);
        const double drho   = (rho_out - rho_in) / nv;
        const double w_tex  = nyquist_weight(f / drho);
        for (int i = 0; i < nv; ++i) {
            const double rho = rho_in + (i + 0.5) * drho;
            const double s   = (1 - rho) / f;
            const double g   = pseudo_fringe_pattern(o, s);
            double m         = 0;  // the local mean: the pattern averaged over one fringe width
            for (int k = 0; k < 16; ++k)
                m += pseudo_fringe_pattern(o, s - 0.5 + (k + 0.5) / 16);
            m /= 16;
            val[size_t(i)] = m + w_tex * (g - m);
            avg[size_t(i)] = m;
        }
        // Area-weighted mean over the disc of radius rho_out, the interior at its clamp value.
        double energy = val[0] * rho_in * rho_in;
        for (int i = 0; i < nv; ++i)
            energy += val[size_t(i)] * 2 * (rho_in + (i + 0.5) * drho) * drho;
        const double norm = energy / (rho_out * rho_out);
        for (int i = 0; i < nv; ++i) {
            value_[size_t(j) * size_t(nv) + size_t(i)] = float(val[size_t(i)] / norm);
            mean_[size_t(j) * size_t(nv) + size_t(i)]  = float(avg[size_t(i)] / norm);
        }
    }
}

double PseudoDiffractionMap::extent(double x) const { return 1 + 2 * x * options_.outside_widths; }

double PseudoDiffractionMap::clamp_radius(double x) const
{
    return std::max(0.0, 1 - 2 * x * options_.band_widths);
}

double PseudoDiffractionMap::width_ratio(double defocus_waves) const
{
    return options_.width_scale / std::sqrt(8 * defocus_waves);
}

double PseudoDiffractionMap::lookup(double rho, double x_ref, double wavelength_ratio,
                                  double pixel_rho) const
{
    const PseudoMapOptions& o = options_;
    // The talk's horizontal lookup: fringe widths scale as sqrt(lambda).
    const double x = x_ref * std::sqrt(wavelength_ratio);
    rho            = std::abs(rho);
    const double rho_in = clamp_radius(x), rho_out = extent(x);
    if (!(rho < rho_out))
        return 0.0;
    const int nu = o.columns, nv = o.rows;
    const double lo = std::log(o.min_width_ratio), hi = std::log(o.max_width_ratio);
    const double tu = std::clamp((std::log(x) - lo) / (hi - lo) * (nu - 1), 0.0, double(nu - 1));
    // The vertical squeeze: this column's band mapped so its geometric edge is at rho = 1;
    // inside the band, the clamped interior reads row 0.
    const double tv = std::clamp((rho - rho_in) / (rho_out - rho_in) * nv - 0.5, 0.0, double(nv - 1));
    const int j0 = std::min(int(tu), nu - 2), i0 = std::min(int(tv), nv - 2);
    const double fu = tu - j0, fv = tv - i0;
    const auto fetch = [&](const std::vector<float>& t) {
        const auto at = [&](int j, int i) { return double(t[size_t(j) * size_t(nv) + size_t(i)]); };
        return (1 - fu) * ((1 - fv) * at(j0, i0) + fv * at(j0, i0 + 1))
               + fu * ((1 - fv) * at(j0 + 1, i0) + fv * at(j0 + 1, i0 + 1));
    };
    double v = fetch(value_);
    if (pixel_rho > 0) {  // the output's Nyquist limit
        const double m = fetch(mean_);
        v              = m + nyquist_weight(2 * x / pixel_rho) * (v - m);
    }
    // The column is normalised to a 2-D mean of 1 over radius rho_out: unit energy is that
    // over pi rho_out^2 (the inverse square of the squeeze).
    return v / (kPi * rho_out * rho_out);
}

namespace {

class SeedMapProfile final : public RadialProfile {
public:
    SeedMapProfile(const PseudoDiffractionMap& map, double w, double pixel_rho)
        : map_(map), x_(map.width_ratio(w)), pixel_rho_(pixel_rho)
    {
    }
    double operator()(double rho) const override { return map_.lookup(rho, x_, 1.0, pixel_rho_); }
    double extent() const override { return map_.extent(x_); }
    const char* name() const override { return "pseudo-diffraction map"; }

private:
    const PseudoDiffractionMap& map_;
    double x_, pixel_rho_;
};

}  // namespace

std::unique_ptr<RadialProfile> pseudo_map_radial_profile(const PseudoDiffractionMap& map,
                                                       double defocus_waves, double pixel_rho)
{
    if (!(defocus_waves > 0) || !std::isfinite(defocus_waves) || !(pixel_rho >= 0)
        || !std::isfinite(pixel_rho))
        return nullptr;
    return std::make_unique<SeedMapProfile>(map, defocus_waves, pixel_rho);
}

namespace {

class FlatProfile final : public RadialProfile {
public:
    double operator()(double rho) const override { return std::abs(rho) < 1.0 ? 1.0 / kPi : 0.0; }
    double extent() const override { return 1.0; }
    const char* name() const override { return "flat disc"; }
};

}  // namespace

std::unique_ptr<RadialProfile> diffraction_radial_profile(DiffractionMethod method, double coc_px,
                                                          double fnumber, double wavelength_nm,
                                                          double pixel_pitch_mm,
                                                          const PseudoDiffractionMap* map)
{
    const double w = defocus_waves_px(coc_px, fnumber, wavelength_nm, pixel_pitch_mm);
    if (!(w > 0) || !std::isfinite(w) || !(wavelength_nm > 0))
        return nullptr;
    switch (method) {
    case DiffractionMethod::None: return std::make_unique<FlatProfile>();
    case DiffractionMethod::EdgeLaw: return edge_law_radial_profile(w);
    case DiffractionMethod::PseudoMap:
        return map ? pseudo_map_radial_profile(*map, w, 2.0 / std::abs(coc_px)) : nullptr;
    case DiffractionMethod::Exact: {
        RadialWavefront wf;
        wf.defocus_waves = w;
        return exact_radial_profile(wf);
    }
    }
    return nullptr;
}

bool pseudo_map_spectral_profile(RgbRadialProfile& out, const PseudoDiffractionMap& map, double coc_px,
                               double fnumber, double pixel_pitch_mm,
                               const std::vector<SpectralSample>& spectrum, int samples)
{
    out = {};
    const double c_mm = std::abs(coc_px) * pixel_pitch_mm;
    if (!(c_mm > 0) || !std::isfinite(c_mm) || !(fnumber > 0) || !std::isfinite(fnumber)
        || spectrum.empty() || samples < 16)
        return false;
    const PseudoMapOptions& o = map.options();
    const double lref_mm    = o.reference_nm * 1e-6;
    const double x_ref      = o.width_scale * std::sqrt(lref_mm * fnumber / c_mm);
    const double pixel_rho  = 2.0 / std::abs(coc_px);
    double extent           = 0;
    for (const SpectralSample& s : spectrum) {
        if (!(s.wavelength_nm > 0) || !std::isfinite(s.wavelength_nm))
            return false;
        extent = std::max(extent, map.extent(x_ref * std::sqrt(s.wavelength_nm / o.reference_nm)));
    }
    out.rho_step = extent / (samples - 1);
    out.values.assign(size_t(samples), {0.0, 0.0, 0.0});
    for (int i = 0; i < samples; ++i) {
        const double rho = i * out.rho_step;
        for (const SpectralSample& s : spectrum) {
            const double I = map.lookup(rho, x_ref, s.wavelength_nm / o.reference_nm, pixel_rho);
            for (int c = 0; c < 3; ++c)
                out.values[size_t(i)][size_t(c)] += s.rgb_weight[size_t(c)] * I;
        }
    }
    // The clamped interior: its tint toward white by (1 - 1/X)^2, white being the channels'
    // mean (each channel first divided by its total weight, so a flat interior reads 1/pi in
    // every channel whatever the spectrum).
    std::array<double, 3> total{};
    for (const SpectralSample& s : spectrum)
        for (int c = 0; c < 3; ++c)
            total[size_t(c)] += s.rgb_weight[size_t(c)];
    for (int c = 0; c < 3; ++c)
        if (total[size_t(c)] == 0 || !std::isfinite(total[size_t(c)])) {
            out = {};
            return false;
        }
    const double X = 1.0 / (2 * x_ref * o.band_widths);
    if (X > 1) {
        const double share = (1 - 1 / X) * (1 - 1 / X), rho_clamp = 1 - 1 / X;
        for (int i = 0; i < samples && i * out.rho_step < rho_clamp; ++i) {
            std::array<double, 3>& v = out.values[size_t(i)];
            double white             = 0;
            for (int c = 0; c < 3; ++c)
                white += v[size_t(c)] / total[size_t(c)] / 3;
            for (int c = 0; c < 3; ++c)
                v[size_t(c)] += share * (white * total[size_t(c)] - v[size_t(c)]);
        }
    }
    // White normalisation: each channel to unit energy (trapezoid in rho, weight 2 pi rho).
    for (int c = 0; c < 3; ++c) {
        double e = 0;
        for (int i = 0; i < samples; ++i) {
            const double wgt = (i == 0 || i == samples - 1) ? 0.5 : 1.0;
            e += wgt * 2 * kPi * (i * out.rho_step) * out.values[size_t(i)][size_t(c)];
        }
        e *= out.rho_step;
        if (!(e > 0)) {
            out = {};
            return false;
        }
        for (auto& v : out.values)
            v[size_t(c)] /= e;
    }
    return true;
}

}  // namespace bokeh
