// beam_map.cpp — a lens's longitudinal aberration LSA(s, l) and its beam map (the
// "light-beam map" of Kawase's "Bokeh Deep Dive"; docs/methods/optics.md, "Longitudinal
// aberration").
//
// LSA(s, l) = chromatic LCA(l) + monochromatic SA3 (1 + spherochromatism (l - 587.6) /
// 100) (s^2 - correction s^4): third- and fifth-order spherical aberration (SA5 = -
// correction SA3) plus axial colour. Magnitudes (docs/methods/optics.md, "The presets'
// magnitudes") scale with the lens: longitudinal spherical aberration as the focal length
// and as 1 / N^2 (third order: LSA ~ y^2 / f, y = f / 2N), axial colour as the focal
// length.
//   * uncorrected: SA3 = -1.0 mm at 50 mm f/2 (between a double-Gauss's -0.38 and a
//     best-form singlet's ~ -3), no zonal correction; a singlet's axial colour, f(l) =
//     f (n_d - 1) / (n(l) - 1) with BK7's Cauchy fit n = 1.5046 + 0.00420 um^2 / l^2
//     (n_d 1.5168, V 64: F-C spread f / V, 0.78 mm at 50 mm);
//   * achromat: the double-Gauss fit SA3 -0.38 mm, correction 1.47 (SA5 / SA3 = 0.56 /
//     0.38); secondary spectrum, a parabola through F (486.1 nm) and C (656.3 nm) whose
//     vertex lies f / 2000 in front of them;
//   * apochromat: SA3 -0.25 mm, correction 1.47; a cubic through 450, 550 and 650 nm a
//     tenth of the achromat's size, of the sign that leaves the talk's example, a cyan
//     rim behind focus (at 50 mm that is 2.5 um of focus, a twentieth of a pixel of rim
//     at 1080p: the `chromatic` knob shows it).
// Sign: positive LSA focuses behind the paraxial focus of 587.6 nm; under-corrected
// spherical aberration (marginal rays focus nearer the lens) is negative.
// The beam map: for each signed CoC (column, U), the density of the rays' landing radius
// (row, V) from the area-weighted pupil, each column normalised by its own spread and
// peak, summed over the spectrum to RGB.

#include <bokeh/lens.h>
#include <bokeh/optics.h>
#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {
constexpr double kReferenceNm = 587.6;  // helium d line

double bk7_index(double nm)
{
    const double um = nm * 1e-3;
    return 1.5046 + 0.00420 / (um * um);
}

// Axial colour of the preset in mm at 50 mm focal length, relative to the d line.
double axial_colour_mm_at_50(LensPreset p, double nm)
{
    switch (p) {
    case LensPreset::Off: return 0.0;
    case LensPreset::Uncorrected: {
        const double f = 50.0;
        return f * (bk7_index(kReferenceNm) - 1.0) / (bk7_index(nm) - 1.0) - f;
    }
    case LensPreset::Achromat: {
        const double half = 0.5 * (656.3 - 486.1);
        auto lca = [&](double l) { return (50.0 / 2000.0) * (l - 486.1) * (l - 656.3) / (half * half); };
        return lca(nm) - lca(kReferenceNm);
    }
    case LensPreset::Apochromat: {
        auto cubic = [](double l) { return (l - 450.0) * (l - 550.0) * (l - 650.0); };
        // Negative: blue-green and deep red focus nearest (the talk's example, a cyan
        // rim behind focus); violet farthest.
        const double k = -(50.0 / 20000.0) / cubic(486.1);
        return k * (cubic(nm) - cubic(kReferenceNm));
    }
    }
    return 0.0;
}

struct SphericalPreset {
    double sa3_mm_at_50_f2;
    double correction;
};

SphericalPreset spherical_preset(LensPreset p)
{
    switch (p) {
    case LensPreset::Off: return { 0.0, 0.0 };
    case LensPreset::Uncorrected: return { -1.0, 0.0 };
    case LensPreset::Achromat: return { -0.38, 1.47 };
    case LensPreset::Apochromat: return { -0.25, 1.47 };
    }
    return { 0.0, 0.0 };
}

}  // namespace

bool lens_preset_named(const std::string& name, LensPreset& out)
{
    for (LensPreset p : { LensPreset::Off, LensPreset::Uncorrected, LensPreset::Achromat,
                          LensPreset::Apochromat })
        if (name == lens_preset_name(p)) {
            out = p;
            return true;
        }
    return false;
}

const char* lens_preset_name(LensPreset p)
{
    switch (p) {
    case LensPreset::Off: return "off";
    case LensPreset::Uncorrected: return "uncorrected";
    case LensPreset::Achromat: return "achromat";
    case LensPreset::Apochromat: return "apochromat";
    }
    return "off";
}

bool check_lens(const LensCharacter& l, std::string& err)
{
    struct Range {
        const char* name;
        double value, lo, hi;
    };
    const Range ranges[] = {
        { "fstop", l.fstop, kMinFstop, kMaxFstop },
        { "focal", l.focal_mm, kMinFocalMm, kMaxFocalMm },
        { "pixel pitch (mm)", l.pixel_pitch_mm, 1e-4, 1.0 },
        { "aspect", l.aspect, kMinAspect, kMaxAspect },
        { "monochromatic", l.monochromatic, -20.0, 20.0 },
        { "chromatic", l.chromatic, -20.0, 20.0 },
        { "spherochromatism", l.spherochromatism, -5.0, 5.0 },
        { "onion", l.onion, 0.0, 1.0 },
        { "onion_waves", l.onion_waves, 0.0, 1.0 },
        { "onion_cycles", l.onion_cycles, 1.0, 200.0 },
        { "onion_sharpness", l.onion_sharpness, 1.0, 32.0 },
        { "onion_offset", l.onion_offset, -2.0, 2.0 },
        { "surface_noise", l.surface_noise, 0.0, 1.0 },
        { "catseye", l.catseye, 0.0, 1.5 },
        { "field_curvature", l.field_curvature_px, -4096.0, 4096.0 },
        { "astigmatism", l.astigmatism_px, -4096.0, 4096.0 },
        { "anamorphic_focus", l.anamorphic_focus_px, -4096.0, 4096.0 },
        { "lateral_r (px)", l.lateral_r_px, -512.0, 512.0 },
        { "lateral_b (px)", l.lateral_b_px, -512.0, 512.0 },
    };
    for (const Range& r : ranges)
        if (!(std::isfinite(r.value) && r.value >= r.lo && r.value <= r.hi)) {
            err = format("{} {:g} is outside {:g}..{:g}", r.name, r.value, r.lo, r.hi);
            return false;
        }
    if (!(l.correction < 0.0 ? l.correction == -1.0 : l.correction <= 3.0)) {
        err = format("correction {:g} is outside 0..3 (1 corrected at the rim, 1.6 over-corrected)",
                     l.correction);
        return false;
    }
    std::vector<SpectralSample> s;
    return spectral_samples(s, l.spectrum, nullptr, err);
}

double longitudinal_aberration_mm(const LensCharacter& l, double s, double nm)
{
    const SphericalPreset sp = spherical_preset(l.preset);
    const double correction  = l.correction < 0.0 ? sp.correction : l.correction;
    const double scale_sa    = (l.focal_mm / 50.0) * (2.0 / l.fstop) * (2.0 / l.fstop);
    const double sa3 = l.monochromatic * sp.sa3_mm_at_50_f2 * scale_sa
                       * (1.0 + l.spherochromatism * (nm - kReferenceNm) / 100.0);
    const double s2 = s * s;
    return l.chromatic * axial_colour_mm_at_50(l.preset, nm) * (l.focal_mm / 50.0)
           + sa3 * (s2 - correction * s2 * s2);
}

bool beam_map_image(OIIO::ImageBuf& dst, const LensCharacter& lens, double coc_min_px,
                    double coc_max_px, int width, int height, int nthreads)
{
    std::string err;
    if (!check_lens(lens, err))
        return dst.errorfmt("beam_map: {}", err), false;
    if (!(std::isfinite(coc_min_px) && std::isfinite(coc_max_px) && coc_min_px < coc_max_px)
        || width < 2 || height < 2 || width > 8192 || height > 8192)
        return dst.errorfmt("beam_map: needs coc_min < coc_max and 2..8192 px each way"), false;
    std::vector<SpectralSample> spectrum;
    if (!spectral_samples(spectrum, lens.spectrum, nullptr, err))
        return dst.errorfmt("beam_map: {}", err), false;

    const double na_per_pitch = 0.5 / lens.fstop / lens.pixel_pitch_mm;
    constexpr int kRays       = 4096;
    std::vector<float> map(size_t(width) * height * 3, 0.0f);
    parallel_for_chunks(0, width, 1, nthreads, [&](int64_t x0, int64_t x1) {
        std::vector<double> column(size_t(height) * 3);
        for (int64_t x = x0; x < x1; ++x) {
            const double c = coc_min_px + (coc_max_px - coc_min_px) * (x + 0.5) / width;
            std::fill(column.begin(), column.end(), 0.0);
            // The column's spread: the largest landing radius over the spectrum.
            double spread = 1e-9;
            for (const SpectralSample& smp : spectrum)
                for (int i = 0; i < kRays; ++i) {
                    const double s = (i + 0.5) / kRays;
                    const double r = s * (0.5 * c - na_per_pitch * longitudinal_aberration_mm(lens, s, smp.wavelength_nm));
                    spread = std::max(spread, std::abs(r));
                }
            for (const SpectralSample& smp : spectrum)
                for (int i = 0; i < kRays; ++i) {
                    const double s = (i + 0.5) / kRays;
                    const double r = s * (0.5 * c - na_per_pitch * longitudinal_aberration_mm(lens, s, smp.wavelength_nm));
                    // Density per unit area of the rotated column: mass s ds over 2 pi R dR.
                    const double v = std::abs(r) / spread * (height - 1);
                    const int row  = std::min(height - 1, int(v + 0.5));
                    const double ring = std::max(row, 1);
                    for (int ch = 0; ch < 3; ++ch)
                        column[size_t(row) * 3 + ch] += smp.rgb_weight[size_t(ch)] * s / (kRays * ring);
                }
            double peak = 1e-30;
            for (double v : column)
                peak = std::max(peak, v);
            for (int row = 0; row < height; ++row)
                for (int ch = 0; ch < 3; ++ch)
                    map[(size_t(height - 1 - row) * width + x) * 3 + ch] = float(std::max(0.0, column[size_t(row) * 3 + ch] / peak));
        }
    });
    dst.reset(OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::FLOAT));
    dst.set_pixels(dst.roi(), OIIO::TypeDesc::FLOAT, map.data());
    return true;
}

}  // namespace bokeh
