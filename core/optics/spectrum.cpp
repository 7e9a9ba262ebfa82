// spectrum.cpp — the CIE 1931 colour-matching functions and the per-wavelength RGB
// weights of a spectral PSF (docs/methods/optics.md, "The spectrum"; the spectral
// integration of Kawase's "Bokeh Deep Dive": 400-710 nm through XYZ to the working RGB).
//
// The colour-matching functions are the analytic multi-lobe fit of Wyman, Sloan and
// Shirley (JCGT 2(2), 2013, table 1): each lobe a exp(-t^2 / 2), t = (l - mu) s with s
// one width below mu and another above. Used instead of the CIE's tabulated values
// because it is a dozen numbers, smooth, and within about 1 % of the table's peak.
// XYZ to Rec.709 is IEC 61966-2-1's matrix; another working space goes through the
// OCIO config's XYZ space, so the weights follow the config the frames are in.
// White balance: each channel's weights are normalised to sum 1, PSF_c = sum_l w_c(l)
// PSF_l, so every channel keeps the PSF's unit energy and a white light stays white
// (w_c(l) = [M S cmf]_c / sum over l, S the illuminant).

#include <bokeh/color.h>
#include <bokeh/spectrum.h>

#include <cmath>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {

struct Lobe {
    double alpha, mu_nm, s_below, s_above;
};

double lobe(const Lobe& g, double l)
{
    const double t = (l - g.mu_nm) * (l < g.mu_nm ? g.s_below : g.s_above);
    return g.alpha * std::exp(-0.5 * t * t);
}

// CIE daylight D65 relative spectral power, 400-710 nm in 10 nm steps (CIE 15:2004,
// table T.1), linearly interpolated between.
double d65(double l)
{
    static const double table[] = { 82.75, 91.49, 93.43, 86.68, 104.86, 117.01, 117.81, 114.86,
                                    115.92, 108.81, 109.35, 107.80, 104.79, 107.69, 104.41, 104.05,
                                    100.00, 96.33, 95.79, 88.69, 90.01, 89.60, 87.70, 83.29,
                                    83.70, 80.03, 80.21, 82.28, 78.28, 69.72, 71.61, 74.35 };
    constexpr int n = int(sizeof(table) / sizeof(table[0]));
    const double f  = (l - 400.0) / 10.0;
    if (f <= 0.0)
        return table[0];
    if (f >= n - 1)
        return table[n - 1];
    const int i = int(f);
    return table[i] + (f - i) * (table[i + 1] - table[i]);
}

}  // namespace

std::array<double, 3> cie1931_xyz(double l)
{
    static const Lobe x[] = { { 0.362, 442.0, 0.0624, 0.0374 },
                              { 1.056, 599.8, 0.0264, 0.0323 },
                              { -0.065, 501.1, 0.0490, 0.0382 } };
    static const Lobe y[] = { { 0.821, 568.8, 0.0213, 0.0247 }, { 0.286, 530.9, 0.0613, 0.0322 } };
    static const Lobe z[] = { { 1.217, 437.0, 0.0845, 0.0278 }, { 0.681, 459.0, 0.0385, 0.0725 } };
    std::array<double, 3> xyz{};
    for (const Lobe& g : x)
        xyz[0] += lobe(g, l);
    for (const Lobe& g : y)
        xyz[1] += lobe(g, l);
    for (const Lobe& g : z)
        xyz[2] += lobe(g, l);
    return xyz;
}

std::array<double, 3> xyz_to_rec709(const std::array<double, 3>& v)
{
    return { 3.2406 * v[0] - 1.5372 * v[1] - 0.4986 * v[2],
             -0.9689 * v[0] + 1.8758 * v[1] + 0.0415 * v[2],
             0.0557 * v[0] - 0.2040 * v[1] + 1.0570 * v[2] };
}

namespace {

// The working space's XYZ-to-RGB matrix from the config: the images of the three XYZ
// unit vectors under its XYZ space -> scene_linear transform.
bool config_xyz_matrix(const ColorSystem& colors, double m[3][3], std::string& err)
{
    std::string xyz;
    for (const std::string& n : colors.names())
        if (n == "CIE-XYZ-D65" || (xyz.empty() && n.find("XYZ") != std::string::npos))
            xyz = n;
    if (xyz.empty()) {
        err = format("the colour config {} has no XYZ colour space (e.g. CIE-XYZ-D65) to "
                     "turn wavelengths into its working space",
                     colors.config_path());
        return false;
    }
    OIIO::ImageBuf unit(OIIO::ImageSpec(3, 1, 3, OIIO::TypeDesc::FLOAT));
    for (int i = 0; i < 3; ++i) {
        float px[3] = { 0.0f, 0.0f, 0.0f };
        px[i]       = 1.0f;
        unit.setpixel(i, 0, px);
    }
    if (!colors.convert(unit, xyz, colors.scene_linear(), 1, err))
        return false;
    for (int i = 0; i < 3; ++i) {
        float px[3];
        unit.getpixel(i, 0, px);
        for (int c = 0; c < 3; ++c)
            m[c][i] = px[c];
    }
    return true;
}

}  // namespace

bool spectral_samples(std::vector<SpectralSample>& out, const SpectrumOptions& o,
                      const ColorSystem* colors, std::string& err)
{
    out.clear();
    if (!(std::isfinite(o.first_nm) && std::isfinite(o.last_nm) && o.first_nm >= 300.0
          && o.last_nm <= 900.0 && o.first_nm <= o.last_nm)) {
        err = format("wavelength range {:g}..{:g} nm is not an increasing range within 300..900 nm",
                     o.first_nm, o.last_nm);
        return false;
    }
    if (o.first_nm == o.last_nm) {  // one wavelength, drawn in every channel
        SpectralSample smp;
        smp.wavelength_nm = o.first_nm;
        smp.rgb_weight    = { 1.0, 1.0, 1.0 };
        out.push_back(smp);
        return true;
    }
    if (!(o.step_nm >= 0.5 && o.step_nm <= 100.0)) {
        err = format("wavelength step {:g} nm is outside 0.5..100", o.step_nm);
        return false;
    }
    double m[3][3] = { { 3.2406, -1.5372, -0.4986 }, { -0.9689, 1.8758, 0.0415 }, { 0.0557, -0.2040, 1.0570 } };
    if (colors && colors->scene_linear() != "lin_rec709" && !config_xyz_matrix(*colors, m, err))
        return false;

    const int n = std::max(1, int(std::ceil((o.last_nm - o.first_nm) / o.step_nm - 1e-9))) + 1;
    const double step = (o.last_nm - o.first_nm) / (n - 1);
    std::array<double, 3> total{};
    for (int i = 0; i < n; ++i) {
        const double l    = o.first_nm + i * step;
        const double dl   = (i == 0 || i == n - 1) ? 0.5 * step : step;  // trapezoid
        const double s    = o.illuminant == Illuminant::D65 ? d65(l) / 100.0 : 1.0;
        const auto xyz    = cie1931_xyz(l);
        SpectralSample smp;
        smp.wavelength_nm = l;
        for (int c = 0; c < 3; ++c) {
            smp.rgb_weight[size_t(c)] = s * dl * (m[c][0] * xyz[0] + m[c][1] * xyz[1] + m[c][2] * xyz[2]);
            total[size_t(c)] += smp.rgb_weight[size_t(c)];
        }
        out.push_back(smp);
    }
    for (int c = 0; c < 3; ++c)
        if (!(total[size_t(c)] > 0.0)) {
            err = format("the spectrum {:g}..{:g} nm carries no energy into channel {}", o.first_nm,
                         o.last_nm, "RGB"[c]);
            out.clear();
            return false;
        }
    for (SpectralSample& smp : out)
        for (int c = 0; c < 3; ++c)
            smp.rgb_weight[size_t(c)] /= total[size_t(c)];
    return true;
}

}  // namespace bokeh
