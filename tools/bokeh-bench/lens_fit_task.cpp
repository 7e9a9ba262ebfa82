// lens_fit_task.cpp — round trips of the lens fit (bokeh::fit_lens): random lenses (round
// or 5-9 blades, rotation, curvature, signed spherical aberration, axial colour, onion
// rings), each rendered as a 128 px crop by bokeh::synthetic_crop at a peak SNR of 20, 50
// or 100 with a background gradient, fitted back; a CSV row per parameter with the true
// value, the fitted one, its sigma and status, the fit's time and the refit PSF's PSNR
// against the true PSF at the crop's CoC. lens_fit_chart.py draws fitted against true.
// Then the speed cases the lens fit is held to: one 128 px crop, and 8 crops of one lens
// (medians of 3 runs).

#include "lens_fit_task.h"
#include "timing.h"

#include <bokeh/lens_fit.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>

#include <OpenImageIO/strutil.h>

namespace bokeh_bench {

using OIIO::Strutil::fmt::format;

namespace {

double psf_psnr(const bokeh::LensCharacter& truth, const bokeh::LensCharacter& fitted, double coc_px)
{
    bokeh::PsfRequest req;
    req.coc_px  = coc_px;
    req.size_px = int(std::ceil(std::abs(coc_px) * 1.5)) | 1;
    bokeh::Psf a, b;
    std::string err;
    if (!bokeh::lens_psf(a, truth, req, err, 1) || !bokeh::lens_psf(b, fitted, req, err, 1))
        return 0.0;
    double peak = 0, se = 0;
    for (size_t k = 0; k < a.rgb.size(); ++k) {
        peak = std::max(peak, double(a.rgb[k]));
        se += (a.rgb[k] - b.rgb[k]) * double(a.rgb[k] - b.rgb[k]);
    }
    return 10.0 * std::log10(peak * peak / std::max(se / double(a.rgb.size()), 1e-300));
}

bokeh::LensCharacter camera()
{
    bokeh::LensCharacter l;
    l.fstop = 2.0, l.focal_mm = 50.0, l.pixel_pitch_mm = 36.0 / 1920.0;
    l.preset = bokeh::LensPreset::Uncorrected, l.correction = 0.0;
    l.monochromatic = 0.0, l.chromatic = 0.0;
    return l;
}

}  // namespace

bool run_lens_fit_task(int trials, int threads, std::vector<std::string>& rows)
{
    std::mt19937 rng(2026);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::printf("lens fit round trips: %d random lenses, 128 px crops\n", trials);
    std::printf("%5s %5s %7s %6s  %-40s  %s\n", "trial", "snr", "coc", "s", "true -> fitted", "PSF dB");
    for (int t = 0; t < trials; ++t) {
        bokeh::LensCharacter lens = camera();
        const int blade_choice    = int(u(rng) * 6.0);  // 0 round, 1..5 -> 5..9 blades
        const int blades          = blade_choice == 0 ? 0 : 4 + blade_choice;
        const double rotation     = blades ? u(rng) * 360.0 / blades : 0.0;
        const double curvature    = blades ? 0.4 * u(rng) : 0.0;
        bokeh::Kernel k;
        k.shape        = blades ? bokeh::KernelShape::Polygon : bokeh::KernelShape::Disk;
        k.blades       = std::max(blades, 3);
        k.rotation_deg = float(rotation);
        k.curvature    = float(curvature);
        std::string err;
        if (!bokeh::Aperture::from_kernel(k, lens.aperture, err))
            return std::fprintf(stderr, "lens fit task: %s\n", err.c_str()), false;
        lens.monochromatic = u(rng) < 0.25 ? 0.0 : -0.4 + 1.3 * u(rng);
        lens.chromatic     = u(rng) < 0.25 ? 0.0 : 1.5 * u(rng);
        lens.onion         = u(rng) < 0.6 ? 0.0 : 0.2 + 0.5 * u(rng);
        const double snrs[] = { 20.0, 50.0, 100.0 };
        bokeh::SyntheticCrop spec;
        spec.size_px  = 127;
        spec.coc_px   = 30.0 + 30.0 * u(rng);
        spec.peak_snr = snrs[t % 3];
        spec.offset_x = int(u(rng) * 7.0) - 3, spec.offset_y = int(u(rng) * 7.0) - 3;
        spec.gradient_x = 2e-4 * (u(rng) - 0.5), spec.gradient_y = 2e-4 * (u(rng) - 0.5);
        spec.seed = unsigned(100 + t);
        bokeh::LensFitCrop crop;
        if (!bokeh::synthetic_crop(crop, lens, spec, err, threads))
            return std::fprintf(stderr, "lens fit task: %s\n", err.c_str()), false;
        bokeh::LensFitOptions o;
        o.camera = camera();
        bokeh::LensFit fit;
        if (!bokeh::fit_lens(fit, { crop }, o, err, threads))
            return std::fprintf(stderr, "lens fit task: trial %d: %s\n", t, err.c_str()), false;
        const double psnr = psf_psnr(lens, fit.lens, spec.coc_px);
        const double truth[] = { double(blades), rotation, curvature, 0.0, lens.monochromatic, lens.chromatic,
                                 lens.onion };
        const char* names[]  = { "blades", "rotation", "curvature", "hole", "monochromatic", "chromatic", "onion" };
        std::string summary;
        for (int p = 0; p < 7; ++p)
            for (const bokeh::LensFitParameter& fp : fit.parameters)
                if (fp.name == names[p]) {
                    const char* status = fp.status == bokeh::LensFitParameter::Status::Fitted ? "fitted"
                                         : fp.status == bokeh::LensFitParameter::Status::Undetermined
                                             ? "undetermined"
                                             : "off";
                    rows.push_back(format("lensfit,{},1,127,{},{},{:.6g},{:.6g},{:.4g},{},{:.3f},{:.2f}", t,
                                          spec.peak_snr, names[p], truth[p], fp.value, fp.sigma, status, fit.seconds,
                                          psnr));
                    if (p == 0 || p == 4 || p == 5)
                        summary += format("{} {:.3g}->{:.3g} ", names[p], truth[p], fp.value);
                }
        rows.push_back(format("lensfit,{},1,127,{},coc,{:.6g},{:.6g},{:.4g},fitted,{:.3f},{:.2f}", t, spec.peak_snr,
                              spec.coc_px, fit.crops[0].coc_px, fit.crops[0].coc_sigma_px, fit.seconds, psnr));
        std::printf("%5d %5.0f %7.1f %6.2f  %-40s  %.1f\n", t, spec.peak_snr, spec.coc_px, fit.seconds, summary.c_str(),
                    psnr);
    }

    // Speed: one 128 px crop; 8 crops of one lens (medians of 3).
    bokeh::LensCharacter lens = camera();
    bokeh::Kernel k;
    k.shape = bokeh::KernelShape::Polygon, k.blades = 7, k.rotation_deg = 12.0f, k.curvature = 0.15f;
    std::string err;
    bokeh::Aperture::from_kernel(k, lens.aperture, err);
    lens.monochromatic = 0.5, lens.chromatic = 0.8;
    std::vector<std::vector<bokeh::LensFitCrop>> sets;
    for (int n : { 1, 8 }) {
        std::vector<bokeh::LensFitCrop>& crops = sets.emplace_back();
        for (int i = 0; i < n; ++i) {
            bokeh::SyntheticCrop spec;
            spec.size_px  = 127;
            spec.coc_px   = 36.0 + 3.0 * i;
            spec.peak_snr = 50.0;
            spec.seed     = unsigned(500 + i);
            bokeh::LensFitCrop crop;
            if (!bokeh::synthetic_crop(crop, lens, spec, err, threads))
                return std::fprintf(stderr, "lens fit task: %s\n", err.c_str()), false;
            crops.push_back(crop);
        }
    }
    // Both timed together in interleaved rounds (timing.h), each timed run right after an
    // untimed one of the same set, the median of 3.
    bool fitted = true;
    std::vector<std::function<void()>> fns;
    for (size_t i = 0; i < sets.size(); ++i)
        fns.push_back([&, i] {
            bokeh::LensFitOptions o;
            o.camera = camera();
            bokeh::LensFit fit;
            fitted = bokeh::fit_lens(fit, sets[i], o, err, threads) && fitted;
        });
    const std::vector<double> ms = interleaved_medians_ms(fns, { 3, 3 }, { true, true });
    if (!fitted)
        return std::fprintf(stderr, "lens fit task: %s\n", err.c_str()), false;
    for (size_t i = 0; i < sets.size(); ++i) {
        const size_t n = sets[i].size();
        rows.push_back(format("lensfit-time,median of 3,{},127,50,time,,,,,{:.3f},", n, ms[i] / 1e3));
        std::printf("%zu crop%s of 127 px, %d threads: %.2f s (median of 3)\n", n, n == 1 ? "" : "s", threads,
                    ms[i] / 1e3);
    }
    return true;
}

}  // namespace bokeh_bench
