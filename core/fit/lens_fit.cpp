// lens_fit.cpp — fit optics.h's lens model to crops of photographed bokeh (lens_fit.h has
// the model; docs/methods/lens-fit.md the method, its checks and its limits). This file
// drives the fit and reports it; the crops' model is fit/fit_model.cpp's, the stages
// fit/fit_stages.cpp's, the last least-squares steps fit/fit_least_squares.cpp's.
//
// The order, coarse to fine:
//   1. the noise model from the pixels; each crop's CoC and centre under a round,
//      aberration-free lens, from the highlight's moments;
//   2-7. the stages (fit_stages.h): spherical aberration and its zonal correction, axial
//      colour (then the spherical aberration with it, when it was not kept alone), hole,
//      aperture, onion rings (with the spherical aberration searched again, when it was
//      kept and the rings alone were not), the field (asked only); each kept when it pays
//      BIC's price [Schwarz 1978]; the stages not kept run again when the residuals show
//      much less noise than the pixels' estimate;
//   8. everything kept, together (BOBYQA restarts), every crop joining; Levenberg-
//      Marquardt [Marquardt 1963] over the kept parameters and every crop's CoC and
//      centre; the uncertainties from its Jacobian.
//
// Known limits: a crop's sub-pixel centre moves the PSF by bilinear interpolation (a blur
// of at most half a pixel at the rim); one crop cannot tell a front bokeh from a back
// one with the aberrations' signs reversed (LensFitOptions::front says which); spherical
// aberration is fitted as third order on the `uncorrected` design, axial colour as its
// BK7 dispersion scaled (the achromat's and apochromat's zonal correction is outside the
// model); diffraction, the rings' frequency and surface noise are the camera's; the field
// stage does not recover a cat's eye (docs/methods/lens-fit.md, limits).

#include <bokeh/base.h>
#include <bokeh/lens_fit.h>

#include "fit/fit_stages.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;
using namespace fit;

namespace {

std::string number(double v) { return format("{:.4g}", std::abs(v) < 1e-9 ? 0.0 : v); }

// What the stages kept, and what the crops could show.
struct Kept {
    bool aperture = false, hole = false, sa = false, zonal = false, colour = false, onion = false, cats = false,
         astig = false;
};
struct CropsShow {
    bool colour = true;       // every crop has three channels
    bool field_known = true;  // every crop's field position is known
    double max_h = 0.0;       // the farthest crop's field height
    double mean_coc = 0.0;
    bool off_axis() const { return field_known && max_h >= 0.3; }
};

CropsShow what_crops_show(const std::vector<CropData>& data, const State& s)
{
    CropsShow c;
    for (const CropData& d : data) {
        c.colour      = c.colour && d.channels == 3;
        c.max_h       = std::max(c.max_h, std::hypot(d.fx, d.fy));
        c.field_known = c.field_known && d.field_known;
    }
    for (double coc : s.coc)
        c.mean_coc += coc / double(s.coc.size());
    return c;
}

const StageParam kSphericalStage { "monochromatic", &State::mono, -8.0, 8.0, 0.2,
                                   { -1.5, -0.8, -0.4, -0.15, 0.15, 0.4, 0.8, 1.2, 2.0 } };
const StageParam kCatsEyeStage { "catseye", &State::catseye, 0.0, 1.5, 0.1, { 0.3, 0.7, 1.1 } };
const StageParam kOnionStage { "onion", &State::onion, 0.0, 1.0, 0.05, { 0.15, 0.4, 0.8 } };

// The stages (2-7 of fit_stages.h's order) not kept yet.
void run_stages(Fitter& f, const LensFitOptions& opts, const CropsShow& show, Kept& kept)
{
    if (opts.fit_spherical && !kept.sa)
        kept.sa = f.stage("spherical aberration", { kSphericalStage });
    // The zonal correction (LensCharacter::correction: SA5 = -correction SA3), searched with
    // the aberration from starts of both signs, as a correction past 1 turns the rim's
    // aberration around: the achromat and apochromat designs correct theirs at the rim and
    // leave a zone (correction 1.47), which third order alone drew 15-17 dB from their
    // PSFs. Kept only when it lowers the cost by a tenth: on the presets it took a third
    // off; on the round trips, whose lenses have none, it took 0.1-3.2 % (trading with
    // their onion rings) and, kept at BIC's price alone, put 4 of 40 below 35 dB.
    if (opts.fit_spherical && kept.sa && !kept.zonal) {
        StageParam sa = kSphericalStage;
        sa.starts     = { -0.8, -0.3, 0.3, 0.8 };
        kept.zonal = f.joint_stage("zonal correction (with the spherical aberration searched again)",
                                   { "correction", &State::zonal, 0.0, 3.0, 0.1, { 1.5 } }, sa, 0.1);
    }
    if (opts.fit_colour && show.colour && !kept.colour)
        kept.colour = f.stage("axial colour",
                              { { "chromatic", &State::chroma, -8.0, 8.0, 0.2, { -3.0, -1.0, -0.3, 0.3, 1.0, 3.0 } } });
    if (opts.fit_hole && !kept.hole)
        kept.hole = f.stage("hole", { { "hole", &State::hole, 0.0, 0.9, 0.05, { 0.2, 0.4, 0.6 } } });
    if (opts.fit_aperture && !kept.aperture)
        kept.aperture = f.aperture_stage();
    if (opts.fit_onion && !kept.onion)
        kept.onion = f.stage("onion rings", { kOnionStage });
    // Onion rings brighten a disk's inside, as a larger CoC with less spherical aberration
    // of the same sign also does: the aberration's stage, run without the rings, can
    // settle in that basin, which a search over the rings alone does not leave (4 of the
    // 40 round trips of `bokeh-bench --task lensfit --reps 5`, their refit PSFs 18-21 dB
    // from the truth's). With the aberration kept and the rings not, the rings are
    // searched again with the aberration from its starts of that sign.
    if (opts.fit_onion && !kept.onion && kept.sa) {
        StageParam same_sign = kSphericalStage;
        const double sa      = f.state().mono;
        same_sign.starts.erase(std::remove_if(same_sign.starts.begin(), same_sign.starts.end(),
                                              [&](double v) { return v * sa <= 0.0; }),
                               same_sign.starts.end());
        StageParam rings = kOnionStage;
        rings.starts     = { 0.45 };
        kept.onion = f.joint_stage("onion rings (with the spherical aberration searched again)", rings, same_sign);
    }
    if (opts.fit_field && show.off_axis()) {
        f.free_centres(true);
        f.centres_at_light(true);
        const double a = std::max(4.0, show.mean_coc);
        if (!kept.cats)
            kept.cats = f.stage("cat's eye", { kCatsEyeStage });
        const StageParam astig { "astigmatism", &State::astig, -a, a, 0.05 * a, { -0.3 * a, 0.3 * a } };
        if (!kept.astig)
            kept.astig = kept.cats ? f.joint_stage("astigmatism (with the cat's eye searched again)", astig, kCatsEyeStage)
                                   : f.stage("astigmatism", { astig });
    }
}

// The stages, the spherical aberration again with the colour, and the stages again under
// the residuals' noise when it is much lower than the pixels' estimate.
void search(Fitter& f, std::vector<CropData>& data, const LensFitOptions& opts, const CropsShow& show, Kept& kept,
            double& read2, double& photon)
{
    State& s = f.state();
    run_stages(f, opts, show, kept);
    // Axial colour blurs the rim a spherical aberration draws: when the aberration was
    // not kept before the colour was, it is searched again with the colour in the model.
    // A kept aberration is not searched again: with the colour right after it, that
    // changed no round trip's blade count and no refit PSF by more than 2.5 dB (`bokeh-bench
    // --task lensfit --reps 5`, 40 lenses) and cost a sixth of a one-crop fit.
    if (kept.colour && !kept.sa && opts.fit_spherical)
        kept.sa = f.stage("spherical aberration (with the colour)", { kSphericalStage });
    // The pixels' noise estimate counts fine structure (onion rings, coloured rims) as
    // noise; once the model holds some of it, the residuals may show less. When they show
    // under half the variance at the light's level, the stages not kept run again under it.
    double r2 = 0.0, ph = 0.0, level = 0.0;
    residual_noise(data, f.model(), s, r2, ph);
    for (const CropData& d : data)
        level = std::max(level, d.level);
    if (r2 + ph * level < 0.5 * (read2 + photon * level)) {
        read2 = std::min(read2, r2), photon = std::min(photon, ph);
        set_noise(data, read2, photon);
        f.count_residuals();
        f.log().push_back(format("noise from the residuals: read {:.3g}, photon {:.3g} x signal; the stages "
                                 "not kept again",
                                 std::sqrt(read2), photon));
        run_stages(f, opts, show, kept);
    }
}

// Everything kept, together, on the crops searched; every crop joins; Levenberg-Marquardt;
// each crop's centre; parameters back at their "none" dropped.
void finish(Fitter& f, size_t crops, Kept& kept, int nthreads)
{
    State& s = f.state();
    // BOBYQA's trust region can close before a valley of correlated parameters (CoC,
    // spherical aberration, curvature) is followed to its end: restarted until a round
    // gains under a tenth of one parameter's price, at most 4 rounds.
    for (int round = 0; round < 4 && !f.kept().empty(); ++round) {
        const double before = f.cost();
        const double after  = f.polish({}, 80);
        f.log().push_back(format("all together: cost {:.1f}", after));
        if (before - after < 0.1 * f.price(1))
            break;
    }
    if (f.searched() < crops) {
        f.use_all_crops();
        f.refine_crops(60, true, true);
        if (!f.kept().empty())
            f.log().push_back(format("all together, every crop: cost {:.1f}", f.polish({}, 40)));
    }
    if (!f.kept().empty()) {
        std::vector<double State::*> fields;
        std::vector<double> lo, hi;
        for (const StageParam& p : f.kept())
            fields.push_back(p.field), lo.push_back(p.lo), hi.push_back(p.hi);
        levenberg_marquardt(f.model(), s, fields, lo, hi, 15, nthreads);
        f.log().push_back(format("Levenberg-Marquardt: cost {:.1f}", f.cost()));
    }
    f.refine_crops(60);
    wrap_rotation(s);
    // A parameter the final polish took back to (nearly) its "none" is not shown by the
    // crops: below what a viewer could see (a hole of 3 % of the radius, 3 % ring
    // contrast, 2 % of the design's aberrations, a 3 % cat's-eye cut, half a pixel).
    auto none = [](bool& k, double& v, double visible) {
        if (k && std::abs(v) < visible)
            k = false, v = 0.0;
    };
    none(kept.hole, s.hole, 0.03);
    none(kept.sa, s.mono, 0.02);
    none(kept.zonal, s.zonal, 0.05);
    none(kept.colour, s.chroma, 0.02);
    none(kept.onion, s.onion, 0.03);
    none(kept.cats, s.catseye, 0.03);
    none(kept.astig, s.astig, 0.5);
}

// The lens, each parameter's value, uncertainty and status, and the options string.
void report_lens(LensFit& fit, const Fitter& f, const LensFitOptions& opts, const CropsShow& show, const Kept& kept,
                 std::vector<double>& coc_sigma, int nthreads)
{
    const State& s = f.state();
    std::vector<double State::*> fields;
    std::vector<std::string> names;
    for (const StageParam& p : f.kept())
        fields.push_back(p.field), names.push_back(p.name);
    const std::vector<double> sigma = uncertainties(f.model(), s, fields, coc_sigma, nthreads);
    fit.lens = f.model().lens_of(s, false);
    if (!kept.sa && !kept.colour) {
        fit.lens.preset           = opts.camera.preset;
        fit.lens.monochromatic    = opts.camera.monochromatic;
        fit.lens.chromatic        = opts.camera.chromatic;
        fit.lens.correction       = opts.camera.correction;
        fit.lens.spherochromatism = opts.camera.spherochromatism;
    }
    using Status = LensFitParameter::Status;
    auto param = [&](const char* name, double value, bool asked, bool on, const char* not_asked_why) {
        LensFitParameter p;
        p.name   = name;
        p.value  = value;
        p.status = !asked ? Status::Off : on ? Status::Fitted : Status::Undetermined;
        for (size_t k = 0; k < names.size() && on; ++k)
            if (names[k] == name)
                p.sigma = sigma[k];
        if (!asked)
            p.why = not_asked_why;
        else if (!on)
            p.why = "the crops do not show it (its stage did not pay its price)";
        fit.parameters.push_back(p);
    };
    param("blades", s.blades, opts.fit_aperture, kept.aperture, "not asked for");  // a count: no sigma
    param("rotation", s.rotation, opts.fit_aperture, kept.aperture, "not asked for");
    param("curvature", s.curvature, opts.fit_aperture, kept.aperture, "not asked for");
    param("hole", s.hole, opts.fit_hole, kept.hole, "not asked for");
    param("monochromatic", s.mono, opts.fit_spherical, kept.sa, "not asked for");
    param("correction", s.zonal, opts.fit_spherical, kept.zonal, "not asked for");
    param("chromatic", s.chroma, opts.fit_colour && show.colour, kept.colour,
          show.colour ? "not asked for" : "a crop has one channel");
    param("onion", s.onion, opts.fit_onion, kept.onion, "not asked for");
    const char* field_why = !show.field_known ? "a crop's field position is unknown"
                            : show.max_h < 0.3 ? "every crop is within 0.3 of the centre"
                                               : "not asked for";
    param("catseye", s.catseye, opts.fit_field && show.off_axis(), kept.cats, field_why);
    param("astigmatism", s.astig, opts.fit_field && show.off_axis(), kept.astig, field_why);

    std::vector<std::string> o;
    if (kept.aperture)
        o.push_back(format("kernel=polygon:blades={}:rotation={}:curvature={}", s.blades, number(s.rotation),
                           number(s.curvature)));
    if (kept.hole)
        o.push_back("hole=" + number(s.hole));
    if (kept.sa || kept.colour)
        o.push_back(format("lens=uncorrected:correction={}:monochromatic={}:chromatic={}", number(s.zonal),
                           number(s.mono), number(s.chroma)));
    if (kept.onion)
        o.push_back("onion=" + number(s.onion));
    if (kept.cats)
        o.push_back("catseye=" + number(s.catseye));
    if (kept.astig)
        o.push_back("astigmatism=" + number(s.astig));
    fit.options = OIIO::Strutil::join(o, ":");
}

// Each crop's fit: CoC, centre, light and background, residuals, PSNR.
LensFitCropResult report_crop(const Fitter& f, const CropData& d, size_t i, double coc_sigma, int nthreads)
{
    const State& s = f.state();
    LensFitCropResult r;
    r.coc_px       = f.model().signed_coc(s, i);
    r.coc_sigma_px = coc_sigma;
    r.centre_x = s.cx[i], r.centre_y = s.cy[i];
    r.field_x = d.fx, r.field_y = d.fy, r.field_known = d.field_known;
    r.clipped_px = d.clipped, r.nonfinite_px = d.nonfinite;
    Psf p;
    if (!f.model().psf(p, s, i, false, nthreads))
        return r;
    std::vector<float> smp, fitted;
    f.model().place(p, s, i, r.centre_x, r.centre_y);
    Model::sample(smp, p, d, r.centre_x, r.centre_y);
    Model::sample_fitted(fitted, p, d, r.centre_x, r.centre_y);
    Linear lin;
    Model::fit_linear(d, fitted, lin, nullptr, &r.outlier_px);
    r.outlier_px += d.others;
    const size_t n = size_t(d.w) * d.h;
    double peak = 0.0, se = 0.0;
    size_t cnt = 0;
    for (int ch = 0; ch < 3; ++ch) {
        const int c = std::min(ch, d.channels - 1);  // a one-channel crop: its one, thrice
        double sum2 = 0.0;
        size_t m    = 0;
        for (int j = 0; j < d.h; ++j)
            for (int x = 0; x < d.w; ++x) {
                const size_t k   = size_t(j) * d.w + x;
                const double mod = lin.a[c] * smp[c * n + k];
                peak             = std::max(peak, mod);
                if (!d.use[k])
                    continue;
                const double e = d.px[k * d.channels + c]
                                 - (mod + lin.b0[c] + lin.bx[c] * plane_x(d, x) + lin.by[c] * plane_y(d, j));
                sum2 += e * e, ++m;
            }
        r.amplitude[ch]     = lin.a[c];
        r.background[ch]    = lin.b0[c];
        r.background_dx[ch] = lin.bx[c];
        r.background_dy[ch] = lin.by[c];
        r.residual_rms[ch]  = std::sqrt(sum2 / std::max<size_t>(m, 1));
        if (ch < d.channels)
            se += sum2, cnt += m;
    }
    r.psnr_db = 10.0 * std::log10(peak * peak / std::max(se / std::max<size_t>(cnt, 1), 1e-30));
    return r;
}


}  // namespace

bool check_lens_fit_options(const LensFitOptions& opts, std::string& err)
{
    if (!(opts.clip_level >= 0.0) || !std::isfinite(opts.clip_level))
        return err = format("clip level {:g} is not a value >= 0", opts.clip_level), false;
    if (opts.max_evaluations < 50 || opts.max_evaluations > 1000000)
        return err = format("max_evaluations {} is outside 50..1000000", opts.max_evaluations), false;
    return check_lens(opts.camera, err);
}

bool fit_lens(LensFit& fit, const std::vector<LensFitCrop>& crops, const LensFitOptions& opts, std::string& err,
              int nthreads)
{
    const auto t0 = std::chrono::steady_clock::now();
    fit = LensFit();
    if (crops.empty())
        return err = "fit_lens: no crop given", false;
    if (crops.size() > 64)
        return err = format("fit_lens: {} crops (at most 64)", crops.size()), false;
    if (!check_lens_fit_options(opts, err))
        return err = "fit_lens: " + err, false;
    std::vector<CropData> data(crops.size());
    for (size_t i = 0; i < crops.size(); ++i)
        if (!prepare_crop(data[i], crops[i], i, opts.clip_level, err))
            return false;

    Fitter f(data, opts, nthreads);
    // 1. the noise model from the pixels; size and place.
    double read2 = 0.0, photon = 0.0;
    estimate_noise(data, read2, photon);
    f.refine_crops(150, true);
    f.choose_search_crops(read2, photon);
    f.log().push_back(format("size and place: cost {:.1f} over the {} crop{} searched; noise: read {:.3g}, photon "
                             "{:.3g} x signal",
                             f.cost(), f.searched(), f.searched() == 1 ? "" : "s", std::sqrt(read2), photon));
    const CropsShow show = what_crops_show(data, f.state());
    Kept kept;
    search(f, data, opts, show, kept, read2, photon);
    finish(f, data.size(), kept, nthreads);

    std::vector<double> coc_sigma;
    report_lens(fit, f, opts, show, kept, coc_sigma, nthreads);
    for (size_t i = 0; i < data.size(); ++i)
        fit.crops.push_back(report_crop(f, data[i], i, i < coc_sigma.size() ? coc_sigma[i] : 0.0, nthreads));
    fit.noise_read   = std::sqrt(read2);
    fit.noise_photon = photon;
    fit.evaluations  = f.model().evaluations();
    fit.stages       = f.log();
    fit.seconds      = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return true;
}
}  // namespace bokeh
