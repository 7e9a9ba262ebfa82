// diffraction_task.cpp — bokeh-bench's diffraction task: the fringe models of a round
// bokeh's rim (wave_optics.h) timed and measured against the exact defocused PSF.
//
// Setting: f/2, 550 nm, a 0.006 mm pixel (Kawase's example: a 24 mm sensor 4000 px tall),
// CoC 15 .. 255 px, i.e. W20 = c / (8 N lambda) = 10 .. 174 waves. Product of each method:
// the radial profile a PSF image is rasterised from, averaged over each 1 px ring out to
// 1.25 R (R = CoC / 2), in unit-energy units (a flat disc is 1 / pi). Sub-samples per ring:
// 16 for the exact Hankel PSF (its lambda N ripple from the far rim has a period of
// R / (4 W20) = 0.18 px here), 4 for the others. The reference is the exact profile itself,
// so its error is 0 by construction; its time is the cost of the truth.
// Errors: area-weighted RMS and largest ring difference, relative to the flat level.
// The pseudo-diffraction map's table is built once outside the timing (it is a texture made
// in advance); its build time is printed.

#include "diffraction_task.h"
#include "timing.h"

#include <bokeh/base.h>
#include <bokeh/wave_optics.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include <OpenImageIO/strutil.h>
#include <OpenImageIO/timer.h>

namespace bokeh_bench {

using OIIO::Strutil::fmt::format;

using bokeh::kPi;

namespace {

constexpr double kFnumber = 2.0, kWavelengthNm = 550.0, kPitchMm = 0.006, kExtent = 1.25;

// The mean of `profile` over each 1 px ring (area-weighted, `sub` sub-radii), R px radius.
std::vector<double> ring_profile(const std::function<double(double)>& profile, double R, int sub)
{
    const int n = int(std::ceil(R * kExtent));
    std::vector<double> out(size_t(n), 0.0);
    for (int i = 0; i < n; ++i) {
        double s = 0, w = 0;
        for (int k = 0; k < sub; ++k) {
            const double r = i + (k + 0.5) / sub;
            s += r * profile(r / R);
            w += r;
        }
        out[size_t(i)] = s / w;
    }
    return out;
}

}  // namespace

bool run_diffraction_task(int reps, bool quick, std::vector<std::string>& rows)
{
    OIIO::Timer build_timer;
    const bokeh::PseudoDiffractionMap map;
    std::printf("diffraction: f/%g, %g nm, pixel %g mm; the pseudo-diffraction map's table (%d x %d) built in "
                "%.2f ms\n",
                kFnumber, kWavelengthNm, kPitchMm, map.options().columns, map.options().rows,
                build_timer() * 1e3);
    std::printf("%-16s %6s %8s %10s %12s %12s\n", "method", "coc_px", "W20", "median_ms",
                "rms_rel_flat", "max_rel_flat");
    std::vector<double> sizes = {15, 31, 63, 127, 255};
    if (quick)
        sizes.resize(2);
    for (double coc_px : sizes) {
        const double w = bokeh::defocus_waves_px(coc_px, kFnumber, kWavelengthNm, kPitchMm);
        const double R = 0.5 * coc_px;
        bokeh::RadialWavefront wf;
        wf.defocus_waves = w;
        std::vector<double> ref;
        struct Method {
            const char* name;
            std::function<std::vector<double>()> run;
        };
        const std::vector<Method> methods = {
            {"exact (Hankel)",
             [&] {
                 const auto p = bokeh::exact_radial_profile(wf, kExtent);
                 return ring_profile([&](double rho) { return (*p)(rho); }, R, 16);
             }},
            {"edge law",
             [&] {
                 const auto p = bokeh::edge_law_radial_profile(w);
                 return ring_profile([&](double rho) { return (*p)(rho); }, R, 4);
             }},
            {"pseudo map",
             [&] {
                 const auto p = bokeh::pseudo_map_radial_profile(map, w, 1.0 / R);
                 return ring_profile([&](double rho) { return (*p)(rho); }, R, 4);
             }},
            {"flat disc",
             [&] {
                 return ring_profile([](double rho) { return rho < 1.0 ? 1.0 / kPi : 0.0; }, R, 4);
             }},
        };
        // The four methods timed together in interleaved rounds (timing.h), each timed run
        // right after an untimed one of the same method; the exact PSF (seconds a run from
        // 127 px) the median of 3 there.
        std::vector<std::vector<double>> outs(methods.size());
        std::vector<std::function<void()>> fns;
        std::vector<int> ns;
        for (size_t i = 0; i < methods.size(); ++i) {
            fns.push_back([&, i] { outs[i] = methods[i].run(); });
            ns.push_back(i == 0 && coc_px >= 127 ? std::min(reps, 3) : reps);
        }
        const std::vector<double> times = interleaved_medians_ms(fns, ns, std::vector<bool>(fns.size(), true));
        for (size_t i = 0; i < methods.size(); ++i) {
            const Method& m                = methods[i];
            const std::vector<double>& got = outs[i];
            const double ms                = times[i];
            const int n                    = ns[i];
            if (ref.empty())
                ref = got;
            if (got.size() != ref.size()) {
                std::fprintf(stderr, "bokeh-bench: diffraction: %s gave %zu rings, not %zu\n", m.name,
                             got.size(), ref.size());
                return false;
            }
            double se = 0, area = 0, worst = 0;
            for (size_t i = 0; i < ref.size(); ++i) {
                const double a = 2 * double(i) + 1;  // ring area, in pi px^2
                const double d = (got[i] - ref[i]) * kPi;
                se += a * d * d;
                area += a;
                worst = std::max(worst, std::abs(d));
            }
            const double rms = std::sqrt(se / area);
            std::printf("%-16s %6.0f %8.1f %10.3f %12.5f %12.5f\n", m.name, coc_px, w, ms, rms, worst);
            std::fflush(stdout);
            rows.push_back(format("diffraction,{},{},{:.2f},{:.4g},{},{:.6g},{:.6g}", m.name, coc_px, w,
                                  ms, n, rms, worst));
        }
    }
    return true;
}

}  // namespace bokeh_bench
