// psf_table.h — internal to the library: the radial tables a lens's PSF is drawn from
// (core/optics/psf_table.cpp builds them; core/optics/lens_psf.cpp samples them): the
// per-wavelength landing radii of the rays, the cumulative radial densities in RGB, the
// rim's fringe factor by the edge law, and the request's geometry (field map, cat's-eye
// barrel, onion-ring centre).
#pragma once

#include <bokeh/base.h>
#include <bokeh/optics.h>
#include <bokeh/wave_optics.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace bokeh::detail {

constexpr double kBinPx = 0.5;   // radial table bin width, reference px, for a disk of 8 px and more
// The bin width for a PSF of reference radius r_max: kBinPx, and r_max / 8 for a smaller
// disk (down to 1/64 px), so a disk just past a pixel of CoC, where the PSF stops being a
// point, is not spread a pixel by half-pixel bins (a 1.044 px disk put 22 % of its light
// outside the centre pixel where its area puts 0.5 %: a step as a light passed 1 px of
// CoC in a focus pull).
inline double radial_bin_px(double r_max) { return std::clamp(r_max / 8.0, 1.0 / 64.0, kBinPx); }
constexpr double kBandV = 8.0;   // edge-law band half-width in v: |F - 1| < 4 % past it
constexpr double kFadeV = 6.0;   // from here to kBandV, F fades to its mean (1 in, 0 out)

// The edge law F(v) (core/optics/wave_optics.cpp) tabulated over the band once, 1/256 apart in v
// (a period is 2 / v: 32 entries at the band's edge), faded to its mean from kFadeV on,
// so a pixel past the band gets F's mean without a step (the talk's Nyquist fade); F is
// linear between entries. A pixel takes F's mean over its width, from F's integral G
// (exact for the linear pieces): (G(v1) - G(v0)) / (v1 - v0).
struct EdgeLawTable {
    static constexpr double kPerV = 256.0;
    std::vector<double> f, g;  // F and its integral from -kBandV at the entries

    EdgeLawTable()
    {
        const int n = int(2.0 * kBandV * kPerV) + 1;
        f.resize(size_t(n) + 1);
        g.resize(size_t(n) + 1);
        for (int i = 0; i < n; ++i) {
            const double x    = -kBandV + i / kPerV;
            const double mean = x > 0.0 ? 1.0 : 0.0;
            const double fade = std::clamp((kBandV - std::abs(x)) / (kBandV - kFadeV), 0.0, 1.0);
            f[size_t(i)]      = double(float(mean + fade * (fresnel_edge_intensity(x) - mean)));
        }
        f[size_t(n)] = f[size_t(n) - 1];
        g[0]         = 0.0;
        for (int i = 1; i <= n; ++i)
            g[size_t(i)] = g[size_t(i) - 1] + 0.5 * (f[size_t(i) - 1] + f[size_t(i)]) / kPerV;
    }
    // G(v) = integral of F from -kBandV to v (F = 0 below the band, 1 above).
    double integral(double v) const
    {
        if (v <= -kBandV)
            return 0.0;
        if (v >= kBandV)
            return g[g.size() - 2] + (v - kBandV);
        const double x = (v + kBandV) * kPerV;
        const int i    = int(x);
        const double t = x - i;
        const double f0 = f[size_t(i)], f1 = f[size_t(i) + 1];
        return g[size_t(i)] + (f0 * t + 0.5 * (f1 - f0) * t * t) / kPerV;
    }
    // F's mean over [v0, v1], v0 < v1.
    double mean(double v0, double v1) const { return (integral(v1) - integral(v0)) / (v1 - v0); }
};

/// The edge-law table, built once.
const EdgeLawTable& edge_law_table();

// The landing radius of one wavelength, px: r(s) = s (c/2 - a(s, l)).
struct Landing {
    const LensCharacter& lens;
    double c_half, na_per_pitch, nm;
    double r(double s) const
    {
        return s * (c_half - na_per_pitch * longitudinal_aberration_mm(lens, s, nm));
    }
    double drds(double s) const
    {
        const double h = 1e-5;
        return (r(s + h) - r(std::max(0.0, s - h))) / (s + h - std::max(0.0, s - h));
    }
};

// Cumulative radial densities in RGB (step 1 of the header) and the rim's fringe factor
// (step 3), both over the spectrum.
struct RgbTable {
    int K = 0, half_bins = 0;
    double bin_px = kBinPx;  // radial bin width, reference px (radial_bin_px)
    std::vector<float> dens;  // (K + 1) x bins x 3: density of the span [0, k / K]

    // Fringes: at Kf + 1 pupil radii s_j = s_lo + j (1 - s_lo) / Kf, the middle
    // wavelength's rim radius, the plateau radius (the innermost rim less two bins), the
    // side the rim lands on (+1, -1; 0 where a caustic hides it) and the factor per channel
    // against the distance d inward from the rim (-d_out .. d_in, step kFringeStep px).
    int Kf = 0;
    double s_lo = 1.0, d_in = 0.0, d_out = 0.0;
    int nd = 0;
    std::vector<float> rim, plateau, gain;
    std::vector<int8_t> side;
    std::vector<float> fringe;  // (Kf + 1) x nd x 3
    static constexpr double kFringeStep = 0.125;

    int bins() const { return 2 * half_bins; }

    // Channel densities of the span [0, s] at signed R (linear in s between snapshots and
    // in |R| between bin centres on R's own side of the axis: rays landing at +R and -R
    // come from opposite pupil directions and never mix).
    void cumulative(double R, double s, double out[3]) const
    {
        out[0] = out[1] = out[2] = 0.0;
        if (s <= 0.0)
            return;
        const double fk = std::min(s, 1.0) * K;
        const int k0    = std::min(int(fk), K - 1);
        const double tk = fk - k0;
        const bool negative = std::signbit(R);
        const double u = std::max(0.0, std::abs(R) / bin_px - 0.5);
        const int b0   = int(u);
        if (b0 >= half_bins)
            return;
        const double tb = u - b0;
        const int nb    = bins();
        auto idx = [&](int j) { return negative ? half_bins - 1 - j : half_bins + j; };
        const int i0 = idx(b0);
        const bool has1 = b0 + 1 < half_bins;
        const int i1 = has1 ? idx(b0 + 1) : i0;
        const double w1 = has1 ? tb : 0.0, w0 = 1.0 - tb;
        for (int kk = 0; kk < 2; ++kk) {
            const double wk = kk == 0 ? 1.0 - tk : tk;
            const float* row = &dens[(size_t(k0 + kk) * nb) * 3];
            for (int c = 0; c < 3; ++c)
                out[c] += wk * (w0 * row[size_t(i0) * 3 + c] + w1 * row[size_t(i1) * 3 + c]);
        }
    }

    struct Rim {
        double radius, plateau, gain;
        int side;
        int j0;
        double tj;
    };
    Rim rim_at(double s) const
    {
        const double f = Kf > 0 ? std::clamp((s - s_lo) / (1.0 - s_lo), 0.0, 1.0) * Kf : 0.0;
        const int j0   = std::min(int(f), std::max(Kf - 1, 0));
        const double t = Kf > 0 ? f - j0 : 0.0;
        const int j1   = std::min(j0 + 1, Kf);
        Rim r;
        r.radius  = (1.0 - t) * rim[size_t(j0)] + t * rim[size_t(j1)];
        r.plateau = (1.0 - t) * plateau[size_t(j0)] + t * plateau[size_t(j1)];
        r.gain    = (1.0 - t) * gain[size_t(j0)] + t * gain[size_t(j1)];
        r.side    = side[size_t(j0)] != 0 ? side[size_t(j0)] : side[size_t(j1)];
        r.j0      = j0;
        r.tj      = t;
        return r;
    }
    void fringe_at(const Rim& r, double d, double out[3]) const
    {
        const double f = std::clamp((d + d_out) / kFringeStep, 0.0, double(nd - 1));
        const int i0   = std::min(int(f), nd - 2);
        const double t = f - i0;
        const int j1   = std::min(r.j0 + 1, Kf);
        for (int c = 0; c < 3; ++c) {
            auto at = [&](int j, int i) { return double(fringe[(size_t(j) * nd + i) * 3 + c]); };
            const double a = at(r.j0, i0) + t * (at(r.j0, i0 + 1) - at(r.j0, i0));
            const double b = at(j1, i0) + t * (at(j1, i0 + 1) - at(j1, i0));
            out[c]         = a + r.tj * (b - a);
        }
    }
};

// Everything about one request that does not depend on the wavelength.
struct Geometry {
    double m_inv[2][2]{};  // image px -> pupil units (pure defocus)
    double m[2][2]{};
    double c_ref  = 0.0;   // signed reference CoC, px
    double kappa  = 1.0;   // image distance per reference distance (mean)
    double field_h = 0.0, dir_x = 1.0, dir_y = 0.0;  // field height and direction
    bool barrel = false;
    double barrel_x = 0.0, barrel_y = 0.0;
    double onion_x = 0.0, onion_y = 0.0;
    int ss = 1;            // samples per pixel side
};

// The landing radii r(i ds) of one wavelength's rays, i = 0 .. K kRaysPerRow, ds = 1 / (K
// kRaysPerRow): the ray boundaries add_wavelength_rows spreads each ray's mass between.
void landing_radii(std::vector<double>& r, const Landing& L, int K);

// Adds one wavelength's increments, times its RGB weights, to rows [k_begin, k_end) of
// `t`: row k gets the density the rays of step k (pupil radii (k - 1) / K .. k / K) add,
// each ray's mass s ds spread over the R interval between its landing radii (`r`,
// landing_radii), divided by the bins' annulus areas and pre-filtered along R by a
// pixel-wide tent (1/4, 1/2, 1/4 of the half-pixel bins), each side of the axis alone, when
// `tent`: a pixel-centre sample then weighs an edge about as the pixel's area does (the
// flat kernels' anti-aliasing). Only for PSFs sampled once a pixel (Geometry::ss = 1):
// sub-samples integrate the pixel's area themselves, and a tent on top counted it twice
// (a point of CoC under a pixel came out 3 x 3, centre 0.49, where the flat kernel keeps
// it a point; on the edges scene's in-focus HDR print that cost the lens-off scatter
// reference 6.5 dB against the layers: bokeh-bench --task lens --size 640x360). A step's rays reach a few bins, so a row costs a few bins, not
// every bin reached so far; cumulate_rows turns the increments into the cumulative table.
void add_wavelength_increments(RgbTable& t, const std::vector<double>& r, const std::array<double, 3>& w,
                               int k_begin, int k_end, std::vector<double>& mass, bool tent);

// Row k of the table = the sum of the increments of rows 0..k (summed in double, per bin,
// in row order: the same for any thread count).
void cumulate_rows(RgbTable& t, int nthreads);

Geometry make_geometry(const LensCharacter& lens, const PsfRequest& req);

// The pupil span [lo, hi] along direction psi: the aperture's [hole e, e] cut by the
// barrel circle |p - o| < 1 (docs/methods/optics.md, "Field effects": cat's eye). False when empty.
bool pupil_span(const LensCharacter& lens, const Geometry& g, double psi, double& lo, double& hi);

// The fringe tables of `t` (step 3): the middle wavelength's rim sets the distance axis;
// each wavelength adds its plateau density times the edge law at its own rim and scale.
void add_fringes(RgbTable& t, const LensCharacter& lens, const Geometry& g,
                 const std::vector<SpectralSample>& spectrum, double na_per_pitch, int nthreads);

}  // namespace bokeh::detail
