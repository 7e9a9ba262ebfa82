// lens_psf.cpp — the PSF of a lens with character at one signed CoC and field position
// (optics.h has the model), and the contact sheet `--bokeh:sheet=1` draws. The caches the
// defocus reads PSFs from are core/optics/psf_cache.cpp's.
//
// How a PSF is drawn (Kawase, "Bokeh Deep Dive": a light-beam-map column rotated about the
// axis and distorted by the aperture's radial LUT; docs/methods/lens-character.md):
//  1. Per wavelength, a radial table: rays at 8K pupil radii s in (0, 1) land at r(s) =
//     s (c/2 - a(s, l)); each ray's mass s ds is spread over the R interval its s step
//     covers, into bins 0.5 px wide; the bins' densities (mass over annulus area) are
//     kept at K + 1 pupil radii s = k / K, cumulatively, so the PSF of any pupil span
//     [lo, hi] along a direction is D(R, hi) - D(R, lo) (linear in s and R between).
//     The table is built as increments (the few bins each s step's rays reach) summed
//     over the wavelengths, then cumulated along s once; rows are built in parallel
//     bands and summed in a fixed order, so the table is the same for any thread count.
//  2. A pixel maps to the reference image by the field's linear map (squeeze,
//     astigmatism, anamorphic focus: image = M p for pure defocus, so p = M^-1 X), then
//     to polar (R, phi); pupil directions phi (rays landing at +R) and phi + pi (rays
//     landing at -R, the point-reflected front bokeh) each add their span's density. The
//     span along a direction is [hole e, e] of the aperture's edge distance e(psi), cut
//     by the cat's-eye barrel circle.
//  3. Diffraction at the rim (DiffractionModel::EdgeLaw): the geometric rim of the span
//     is at |r(hi)|; the intensity near it is the plateau density times the Fresnel edge
//     law F(v) (core/optics/wave_optics.cpp), v = sqrt(2) d / sqrt(l N c_eff), d the distance
//     across the edge in image px and c_eff = 2 |dr/ds| at the rim (docs/methods/optics.md, "Diffraction at the rim").
//     DiffractionModel::SeedMap puts the talk's pseudo-diffraction map in place of F: pi
//     times its lookup at rho = 1 - d / (c_eff / 2), at the wavelength's own fringe width.
//     Where the rim is not the outermost ray (a caustic), the law does not hold and the
//     rim stays geometric. The fringe factor is F's mean over a pixel-wide box (from F's
//     tabulated integral), so fringes finer than a pixel fade to their mean (the talk's
//     Nyquist fade).
//  4. Onion rings and surface noise multiply the density by a pattern in the pupil
//     (the pupil point a pixel comes from taken as s = R / |c/2|); the rings' cosine is
//     tabulated per request against the distance from their centre.
//  Samples past the light's reach on both sides of the axis are skipped before any
//  lookup (the exact zero they would add). A radially symmetric PSF (round aperture on
//  the axis, no squeeze, rings centred, no surface noise) is computed over one octant and
//  copied to the other seven.
//  5. Each wavelength's PSF is normalised to unit energy and added with its RGB weights.
// Limits: astigmatic and anamorphic PSFs carry the spherical aberration of the larger
// axis' CoC scaled along the other; their fringes use the mean scale. The hole's inner
// rim has no fringes.

#include <bokeh/base.h>
#include <bokeh/optics.h>
#include <bokeh/parallel.h>
#include <bokeh/wave_optics.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {

constexpr double kBinPx = 0.5;   // radial table bin width, reference px
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

const EdgeLawTable& edge_law_table()
{
    static const EdgeLawTable table;
    return table;
}

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
        const double u = std::max(0.0, std::abs(R) / kBinPx - 0.5);
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

// Rays per snapshot step of the radial table (step 1 of the header).
constexpr int kRaysPerRow = 8;

// The landing radii r(i ds) of one wavelength's rays, i = 0 .. K kRaysPerRow, ds = 1 / (K
// kRaysPerRow): the ray boundaries add_wavelength_rows spreads each ray's mass between.
void landing_radii(std::vector<double>& r, const Landing& L, int K)
{
    const int n     = K * kRaysPerRow;
    const double ds = 1.0 / (double(K) * kRaysPerRow);
    r.resize(size_t(n) + 1);
    r[0] = L.r(0.0);
    for (int i = 0; i < n; ++i)
        r[size_t(i) + 1] = L.r((i + 1) * ds);
}

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
                               int k_begin, int k_end, std::vector<double>& mass, bool tent)
{
    const int K = t.K, nb = t.bins();
    const double ds = 1.0 / (double(K) * kRaysPerRow);
    auto density = [&](int b) {  // per unit angle
        const double r0 = std::abs((b - t.half_bins) * kBinPx), r1 = std::abs((b - t.half_bins + 1) * kBinPx);
        return mass[size_t(b)] / (0.5 * std::abs(r1 * r1 - r0 * r0));
    };
    for (int k = std::max(1, k_begin); k < std::min(k_end, K + 1); ++k) {
        int touched_lo = nb, touched_hi = -1;
        for (int i = (k - 1) * kRaysPerRow; i < k * kRaysPerRow; ++i) {
            const double s_mid  = (i + 0.5) * ds;
            const double r_prev = r[size_t(i)], r_next = r[size_t(i) + 1];
            const double m      = s_mid * ds;  // pupil area per unit angle
            const double lo = std::min(r_prev, r_next), hi = std::max(r_prev, r_next);
            const double f_lo = lo / kBinPx + t.half_bins, f_hi = hi / kBinPx + t.half_bins;
            const int b_lo = std::clamp(int(std::floor(f_lo)), 0, nb - 1);
            const int b_hi = std::clamp(int(std::floor(f_hi)), 0, nb - 1);
            touched_lo     = std::min(touched_lo, b_lo);
            touched_hi     = std::max(touched_hi, b_hi);
            if (b_lo == b_hi || f_hi - f_lo < 1e-12) {
                mass[size_t(b_lo)] += m;
            } else {
                const double span = f_hi - f_lo;
                for (int b = b_lo; b <= b_hi; ++b) {
                    const double a = std::max(f_lo, double(b)), e = std::min(f_hi, double(b + 1));
                    if (e > a)
                        mass[size_t(b)] += m * (e - a) / span;
                }
            }
        }
        float* row = &t.dens[size_t(k) * nb * 3];
        const int v_lo = std::max(0, touched_lo - 1), v_hi = std::min(nb - 1, touched_hi + 1);
        for (int b = v_lo; b <= v_hi; ++b) {
            const bool pos  = b >= t.half_bins;
            const int first = pos ? t.half_bins : 0, last = pos ? nb - 1 : t.half_bins - 1;
            const double v  = tent ? 0.25 * density(std::max(b - 1, first)) + 0.5 * density(b)
                                         + 0.25 * density(std::min(b + 1, last))
                                   : density(b);
            if (v != 0.0)
                for (int c = 0; c < 3; ++c)
                    row[size_t(b) * 3 + c] += float(w[size_t(c)] * v);
        }
        std::fill(mass.begin() + touched_lo, mass.begin() + touched_hi + 1, 0.0);
    }
}

// Row k of the table = the sum of the increments of rows 0..k (summed in double, per bin,
// in row order: the same for any thread count).
void cumulate_rows(RgbTable& t, int nthreads)
{
    const int n = t.bins() * 3;
    parallel_for_chunks(0, n, 768, nthreads, [&](int64_t i0, int64_t i1) {
        std::vector<double> acc(size_t(i1 - i0), 0.0);
        for (int k = 0; k <= t.K; ++k) {
            float* row = &t.dens[size_t(k) * n];
            for (int64_t i = i0; i < i1; ++i) {
                acc[size_t(i - i0)] += row[i];
                row[i] = float(acc[size_t(i - i0)]);
            }
        }
    });
}

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

Geometry make_geometry(const LensCharacter& lens, const PsfRequest& req)
{
    Geometry g;
    g.field_h = std::hypot(req.field_x, req.field_y);
    if (g.field_h > 0.0) {
        g.dir_x = req.field_x / g.field_h;
        g.dir_y = req.field_y / g.field_h;
    }
    const double h2 = g.field_h * g.field_h;
    const double c  = req.coc_px + lens.field_curvature_px * h2;
    // B = c I + (anamorphic / 2) diag(1, -1) + (astigmatism H^2 / 2) (t t' - n n'),
    // t the field direction (tangential), n its normal (sagittal).
    const double a = 0.5 * lens.anamorphic_focus_px, s = 0.5 * lens.astigmatism_px * h2;
    const double tx = g.dir_x, ty = g.dir_y;
    double b00 = c + a + s * (tx * tx - ty * ty);
    double b11 = c - a + s * (ty * ty - tx * tx);
    double b01 = s * 2.0 * tx * ty;
    // Eigen-decomposition of the symmetric B; each eigenvalue kept at least 0.25 px from
    // 0 (a line-shaped bokeh is still a pixel wide), sign kept.
    const double mean = 0.5 * (b00 + b11), diff = 0.5 * (b00 - b11);
    const double rad  = std::hypot(diff, b01);
    double e1 = mean + rad, e2 = mean - rad;
    const double theta = 0.5 * std::atan2(2.0 * b01, b00 - b11);
    auto floor_mag = [](double e) { return std::abs(e) < 0.25 ? (e < 0.0 ? -0.25 : 0.25) : e; };
    e1 = floor_mag(e1);
    e2 = floor_mag(e2);
    const double cs = std::cos(theta), sn = std::sin(theta);
    b00 = e1 * cs * cs + e2 * sn * sn;
    b11 = e1 * sn * sn + e2 * cs * cs;
    b01 = (e1 - e2) * cs * sn;
    g.c_ref = std::abs(e1) >= std::abs(e2) ? e1 : e2;
    // M = S B / 2, S = diag(1, aspect) (x right, y up).
    g.m[0][0] = 0.5 * b00;
    g.m[0][1] = 0.5 * b01;
    g.m[1][0] = 0.5 * lens.aspect * b01;
    g.m[1][1] = 0.5 * lens.aspect * b11;
    const double det = g.m[0][0] * g.m[1][1] - g.m[0][1] * g.m[1][0];
    g.m_inv[0][0] = g.m[1][1] / det;
    g.m_inv[0][1] = -g.m[0][1] / det;
    g.m_inv[1][0] = -g.m[1][0] / det;
    g.m_inv[1][1] = g.m[0][0] / det;
    g.kappa = std::sqrt(std::abs(det)) / (0.5 * std::abs(g.c_ref));
    const double narrow = std::min(std::abs(e1), std::abs(e2)) * std::min(1.0, lens.aspect);  // px across
    g.ss = std::clamp(int(std::ceil(16.0 / narrow)), 1, 8);  // PSFs under 16 px: 2 x 2 and more
    g.barrel = lens.catseye > 0.0 && g.field_h > 0.0;
    g.barrel_x = lens.catseye * g.field_h * g.dir_x;
    g.barrel_y = lens.catseye * g.field_h * g.dir_y;
    const double onion_sign = lens.onion_behind_stop ? 1.0 : -1.0;
    g.onion_x = onion_sign * lens.onion_offset * g.field_h * g.dir_x;
    g.onion_y = onion_sign * lens.onion_offset * g.field_h * g.dir_y;
    return g;
}

// The pupil span [lo, hi] along direction psi: the aperture's [hole e, e] cut by the
// barrel circle |p - o| < 1 (docs/methods/optics.md, "Field effects": cat's eye). False when empty.
bool pupil_span(const LensCharacter& lens, const Geometry& g, double psi, double& lo, double& hi)
{
    const double e = lens.aperture.edge(psi);
    hi = e;
    lo = lens.aperture.hole() * e;
    if (g.barrel) {
        const double ux = std::cos(psi), uy = std::sin(psi);
        const double uo = ux * g.barrel_x + uy * g.barrel_y;
        const double disc = uo * uo - (g.barrel_x * g.barrel_x + g.barrel_y * g.barrel_y) + 1.0;
        if (disc <= 0.0)
            return false;
        const double root = std::sqrt(disc);
        hi = std::min(hi, uo + root);
        lo = std::max(lo, uo - root);
    }
    return hi > lo;
}

// The pupil span and the edge normal's cosine tabulated over the direction (linear
// between entries; more than 8 entries a px of the largest radius), so a pixel costs one
// lookup instead of the aperture's and the barrel's trigonometry.
struct SpanLut {
    int n = 0;
    std::vector<float> lo, hi, ncos;
    std::vector<uint8_t> ok;
    double ncos_min = 1.0;  // over the directions with a span (lookup interpolates between them)

    SpanLut(const LensCharacter& lens, const Geometry& g, double r_max_px, int nthreads)
    {
        n = 1024;
        while (n < 8.0 * r_max_px * kPi / 4.0 && n < 65536)
            n *= 2;
        lo.resize(size_t(n) + 1);
        hi.resize(size_t(n) + 1);
        ncos.resize(size_t(n) + 1);
        ok.resize(size_t(n) + 1);
        // Entries are independent (the aperture's edge and normal cost ~0.5 us each).
        parallel_for_chunks(0, n + 1, 256, nthreads, [&](int64_t i0, int64_t i1) {
            for (int64_t i = i0; i < i1; ++i) {
                const double psi = 2.0 * kPi * double(i) / n;
                double l = 0.0, h = 0.0;
                ok[size_t(i)]   = pupil_span(lens, g, psi, l, h);
                lo[size_t(i)]   = float(l);
                hi[size_t(i)]   = float(h);
                ncos[size_t(i)] = float(lens.aperture.edge_normal_cos(psi));
            }
        });
        for (int i = 0; i <= n; ++i)
            if (ok[size_t(i)])
                ncos_min = std::min(ncos_min, double(ncos[size_t(i)]));
    }
    bool lookup(double psi, double& l, double& h, double& c) const
    {
        double f = psi * (n / (2.0 * kPi));
        // Into [0, n): psi is within -pi .. 2 pi from the pixel loop, so one step does
        // (the same value n floor(f / n) gives, without its division and floor).
        if (f < 0.0)
            f += n;
        else if (f >= n)
            f -= n;
        if (!(f >= 0.0 && f < n))
            f -= n * std::floor(f / n);
        const int i0 = std::min(int(f), n - 1);
        const double t = f - i0;
        const size_t a = size_t(i0), b = a + 1;
        if (!ok[a] || !ok[b]) {
            const size_t near = t < 0.5 ? a : b;
            if (!ok[near])
                return false;
            l = lo[near];
            h = hi[near];
            c = ncos[near];
            return true;
        }
        l = lo[a] + t * (lo[b] - lo[a]);
        h = hi[a] + t * (hi[b] - hi[a]);
        c = ncos[a] + t * (ncos[b] - ncos[a]);
        return h > l;
    }
};

// A smooth value noise in the pupil (surface noise), fixed, zero mean, unit-ish amplitude:
// three octaves of lattice values (a hash of the lattice point, -1..1) blended by
// smoothstep. The lattice values the pupil (|x|, |y| <= 1) uses are hashed once into a
// table (the hash's division was most of a sample's noise cost); points outside it
// (none from lens_psf) hash as they go.
double noise_lattice_hash(int i, int j)
{
    uint32_t h = uint32_t(i) * 374761393u + uint32_t(j) * 668265263u;
    h          = (h ^ (h >> 13)) * 1274126177u;
    return double(h ^ (h >> 16)) / 4294967295.0 * 2.0 - 1.0;
}

struct NoiseLattice {
    static constexpr int kOctaves = 3;
    static constexpr double kBaseFrequency = 6.0;
    // Octave o (frequency f = 6 2^o) at lattice points 0 .. 3f + 1 per axis: (x + 2) f
    // for |x| <= 1 and the next point.
    std::array<std::vector<double>, kOctaves> value;
    std::array<int, kOctaves> side{};
    NoiseLattice()
    {
        double f = kBaseFrequency;
        for (int o = 0; o < kOctaves; ++o, f *= 2.0) {
            side[size_t(o)] = int(3.0 * f) + 2;
            const int n     = side[size_t(o)];
            value[size_t(o)].resize(size_t(n) * n);
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i)
                    value[size_t(o)][size_t(j) * n + i] = noise_lattice_hash(i, j);
        }
    }
};

double pupil_noise(double x, double y)
{
    static const NoiseLattice lattice;
    double sum = 0.0, amp = 0.5, f = NoiseLattice::kBaseFrequency;
    for (int octave = 0; octave < NoiseLattice::kOctaves; ++octave, amp *= 0.5, f *= 2.0) {
        const double u = (x + 2.0) * f, v = (y + 2.0) * f;
        const int i = int(std::floor(u)), j = int(std::floor(v));
        const double tu = u - i, tv = v - j;
        const double su = tu * tu * (3 - 2 * tu), sv = tv * tv * (3 - 2 * tv);
        const int n = lattice.side[size_t(octave)];
        double h00, h10, h01, h11;
        if (i >= 0 && j >= 0 && i + 1 < n && j + 1 < n) {
            const double* row = &lattice.value[size_t(octave)][size_t(j) * n + i];
            h00 = row[0];
            h10 = row[1];
            h01 = row[n];
            h11 = row[n + 1];
        } else {
            h00 = noise_lattice_hash(i, j);
            h10 = noise_lattice_hash(i + 1, j);
            h01 = noise_lattice_hash(i, j + 1);
            h11 = noise_lattice_hash(i + 1, j + 1);
        }
        const double n0 = h00 + su * (h10 - h00);
        const double n1 = h01 + su * (h11 - h01);
        sum += amp * (n0 + sv * (n1 - n0));
    }
    return sum;
}

bool wavelength_independent(const LensCharacter& lens)
{
    const bool colour = lens.preset != LensPreset::Off && lens.chromatic != 0.0;
    const bool sphero = lens.preset != LensPreset::Off && lens.monochromatic != 0.0
                        && lens.spherochromatism != 0.0;
    return !colour && !sphero && lens.diffraction == DiffractionModel::Off && lens.onion_waves == 0.0;
}

// The fringe tables of `t` (step 3): the middle wavelength's rim sets the distance axis;
// each wavelength adds its plateau density times the edge law at its own rim and scale.
void add_fringes(RgbTable& t, const LensCharacter& lens, const Geometry& g,
                 const std::vector<SpectralSample>& spectrum, double na_per_pitch, int nthreads)
{
    // The smallest outer pupil radius any direction uses.
    const double s_min = parallel_reduce_chunks(
        0, 720, 90, nthreads, 1.0,
        [&](int64_t i0, int64_t i1) {
            double m = 1.0;
            for (int64_t i = i0; i < i1; ++i) {
                double lo, hi;
                if (pupil_span(lens, g, 2.0 * kPi * double(i) / 720.0, lo, hi))
                    m = std::min(m, hi);
            }
            return m;
        },
        [](double& acc, double part) { acc = std::min(acc, part); });
    t.s_lo = std::max(0.0, std::min(s_min - 1.0 / t.K, 1.0 - 1.0 / t.K));
    t.Kf   = std::clamp(int(std::ceil((1.0 - t.s_lo) * 32.0)), 1, 32);
    const SpectralSample& mid = spectrum[spectrum.size() / 2];
    const Landing Lmid{ lens, 0.5 * g.c_ref, na_per_pitch, mid.wavelength_nm };
    // The distance axis: the band of the widest fringes, plus how far the other
    // wavelengths' rims lie from the middle one's.
    double scale_max = 0.0, spread = 0.0;
    for (int j = 0; j <= t.Kf; ++j) {
        const double s = t.s_lo + (1.0 - t.s_lo) * j / t.Kf;
        for (const SpectralSample& smp : spectrum) {
            const Landing L{ lens, 0.5 * g.c_ref, na_per_pitch, smp.wavelength_nm };
            const double c_eff = std::max(2.0 * std::abs(L.drds(s)) * g.kappa, 1e-3);
            scale_max = std::max(scale_max, fringe_scale_px(c_eff, lens.fstop, smp.wavelength_nm, lens.pixel_pitch_mm) / g.kappa);
            spread    = std::max(spread, std::abs(std::abs(L.r(s)) - std::abs(Lmid.r(s))));
        }
    }
    const double band = kBandV / std::sqrt(2.0) * scale_max + 1.0;
    t.d_in  = band + spread;
    t.d_out = band + spread;
    t.nd    = int(std::ceil((t.d_in + t.d_out) / RgbTable::kFringeStep)) + 2;
    t.rim.assign(size_t(t.Kf) + 1, 0.0f);
    t.plateau.assign(size_t(t.Kf) + 1, 0.0f);
    t.side.assign(size_t(t.Kf) + 1, 0);
    t.gain.assign(size_t(t.Kf) + 1, 0.0f);
    // Every row starts as the geometric step (1 inside the rim, 0 outside): rows without
    // fringes (a caustic) keep it, and rim_at's interpolation between rows stays a blend
    // of rims.
    t.fringe.assign(size_t(t.Kf + 1) * t.nd * 3, 0.0f);
    for (int j = 0; j <= t.Kf; ++j)
        for (int i = 0; i < t.nd; ++i)
            if (-t.d_out + i * RgbTable::kFringeStep > 0.0)
                for (int c = 0; c < 3; ++c)
                    t.fringe[(size_t(j) * t.nd + i) * 3 + c] = 1.0f;
    // DiffractionModel::SeedMap: the seed's pseudo-diffraction map (core/optics/diffraction_map.cpp),
    // relative to its flat level 1 / pi, in place of the edge law.
    const bool seed = lens.diffraction == DiffractionModel::SeedMap;
    static const SeedDiffractionMap seed_map;
    const SeedDiffractionMap* map = seed ? &seed_map : nullptr;
    const EdgeLawTable& law = edge_law_table();
    // The talk's pseudo-diffraction map: per distance step, then a pixel-wide box.
    constexpr int kSubsamples = 8;
    // The rows are independent (each writes its own entries): in parallel.
    parallel_for_chunks(0, t.Kf + 1, 1, nthreads, [&](int64_t j_begin, int64_t) {
        const int j = int(j_begin);
        const double s     = t.s_lo + (1.0 - t.s_lo) * j / t.Kf;
        const double r_mid = Lmid.r(s);
        const double slope = Lmid.drds(s);
        const int sd       = r_mid > 0.0 ? 1 : -1;
        // The rim bounds the beam when it moves outward with s there; toward a caustic
        // (dr/ds -> 0, where the edge law fails: docs/methods/optics.md) the fringes fade
        // out, from a slope of a quarter of the unaberrated one (c/2) to a twentieth, so
        // that a rim crossing the caustic as the aperture's edge turns shows no seam.
        // Rim and plateau radii are kept for every j, fringed or not: rim_at interpolates
        // them between neighbours.
        double innermost = std::abs(r_mid);
        for (const SpectralSample& smp : spectrum)
            innermost = std::min(innermost, std::abs(Landing{ lens, 0.5 * g.c_ref, na_per_pitch, smp.wavelength_nm }.r(s)));
        t.rim[size_t(j)]     = float(std::abs(r_mid));
        t.plateau[size_t(j)] = float(std::max(0.0, innermost - 2.0 * kBinPx));
        const double rel = slope * sd / (0.5 * std::abs(g.c_ref));
        const double x   = std::clamp((rel - 0.05) / 0.2, 0.0, 1.0);
        t.gain[size_t(j)] = float(x * x * (3.0 - 2.0 * x));
        if (t.gain[size_t(j)] <= 0.0f)
            return;
        t.side[size_t(j)] = int8_t(sd);
        std::vector<double> num(size_t(t.nd) * 3, 0.0);
        double den[3] = { 0.0, 0.0, 0.0 };
        for (const SpectralSample& smp : spectrum) {
            const Landing L{ lens, 0.5 * g.c_ref, na_per_pitch, smp.wavelength_nm };
            const double r = std::abs(L.r(s)), drds = L.drds(s) * sd;
            // This wavelength's own way to a caustic, as the middle one's above: its
            // fringes fade into a geometric step at its rim.
            const double rel_l = drds / (0.5 * std::abs(g.c_ref));
            const double xl    = std::clamp((rel_l - 0.05) / 0.2, 0.0, 1.0);
            const double gain_l = xl * xl * (3.0 - 2.0 * xl);
            const double slope_l = std::max(drds, 0.05 * 0.5 * std::abs(g.c_ref));
            // The geometric density at the rim, s / (R |dr/ds|) (docs/methods/optics.md, "Longitudinal aberration").
            const double p     = s / (std::max(r, 1e-6) * slope_l);
            const double c_eff = std::max(2.0 * slope_l * g.kappa, 1e-3);
            const double scale = fringe_scale_px(c_eff, lens.fstop, smp.wavelength_nm, lens.pixel_pitch_mm);
            // The talk's pseudo-diffraction map at this wavelength's own fringe-width ratio: its horizontal
            // lookup at (l / l_ref)^0.5 is the width ratio's own sqrt(l) scaling.
            const double seed_width
                = seed ? map->width_ratio(defocus_waves_px(c_eff, lens.fstop, smp.wavelength_nm, lens.pixel_pitch_mm))
                       : 0.0;
            double pw[3];
            for (int c = 0; c < 3; ++c) {
                pw[c] = smp.rgb_weight[size_t(c)] * p;
                den[c] += pw[c];
            }
            // A pixel-wide box about d, in reference px (kappa px of image each): in v
            // it is sqrt(2) / scale wide, and the geometric step covers the part of it
            // inside the rim.
            const double half_box_v = edge_v(0.5, scale);
            for (int i = 0; i < t.nd; ++i) {
                const double d_l = -t.d_out + i * RgbTable::kFringeStep + r - std::abs(r_mid);
                double f         = 0.0;
                if (seed) {
                    for (int k = 0; k < kSubsamples; ++k) {
                        const double d_k = d_l + ((k + 0.5) / kSubsamples - 0.5) / g.kappa;
                        f += kPi * map->lookup(1.0 - d_k * g.kappa / (0.5 * c_eff), seed_width);
                    }
                    f /= kSubsamples;
                } else {
                    const double v = edge_v(d_l * g.kappa, scale);
                    f              = law.mean(v - half_box_v, v + half_box_v);
                }
                const double inside = std::clamp(d_l * g.kappa + 0.5, 0.0, 1.0);
                f                   = gain_l * f + (1.0 - gain_l) * inside;
                for (int c = 0; c < 3; ++c)
                    num[size_t(i) * 3 + c] += pw[c] * f;
            }
        }
        // A channel whose weighted rim densities nearly cancel (negative colour-matching
        // lobes against a bright rim of one wavelength) keeps its geometric rim.
        for (int i = 0; i < t.nd; ++i)
            for (int c = 0; c < 3; ++c)
                t.fringe[(size_t(j) * t.nd + i) * 3 + c]
                    = den[c] > 0.0 ? float(std::clamp(num[size_t(i) * 3 + c] / den[c], -1.0, 4.0))
                                   : float(-t.d_out + i * RgbTable::kFringeStep > 0.0 ? 1.0 : 0.0);
    });
}

}  // namespace

bool lens_psf(Psf& out, const LensCharacter& lens, const PsfRequest& req, std::string& err,
              int nthreads)
{
    out = Psf();
    if (!validate_lens(lens, err))
        return false;
    if (!std::isfinite(req.coc_px) || std::abs(req.coc_px) > 4096.0) {
        err = format("coc {:g} is outside -4096..4096 px", req.coc_px);
        return false;
    }
    if (!(std::isfinite(req.field_x) && std::isfinite(req.field_y)) || std::hypot(req.field_x, req.field_y) > 1.5) {
        err = "field position is outside the frame (field height over 1.5 half-diagonals)";
        return false;
    }
    if (req.size_px < 0 || req.size_px > 8191) {
        err = format("size {} is outside 0..8191 px", req.size_px);
        return false;
    }
    std::vector<SpectralSample> spectrum;
    if (wavelength_independent(lens)) {
        SpectralSample white;
        white.rgb_weight = { 1.0, 1.0, 1.0 };
        spectrum.push_back(white);
    } else if (!spectral_samples(spectrum, lens.spectrum, nullptr, err)) {
        return false;
    }

    const Geometry g          = make_geometry(lens, req);
    const double na_per_pitch = 0.5 / lens.fstop / lens.pixel_pitch_mm;
    // The reference extent: the largest landing radius over the spectrum.
    double r_max = 0.5 * std::abs(g.c_ref);
    for (const SpectralSample& smp : spectrum) {
        const Landing L{ lens, 0.5 * g.c_ref, na_per_pitch, smp.wavelength_nm };
        for (int i = 0; i <= 256; ++i)
            r_max = std::max(r_max, std::abs(L.r(i / 256.0)));
    }
    const bool edge_law_on = lens.diffraction != DiffractionModel::Off;  // either fringe model

    RgbTable table;
    double reach_px[2] = { -1.0, -1.0 };  // light's extent on the + and - side of the axis (-1: none)
    table.K         = std::clamp(int(std::ceil(2.0 * r_max)), 32, 1024);  // half a px of radius apart
    table.half_bins = int(std::ceil(r_max / kBinPx)) + 2;
    table.dens.assign(size_t(table.K + 1) * table.bins() * 3, 0.0f);
    {
        // Each wavelength's rays, then the table's increments in bands of rows (every band
        // adds the wavelengths in spectrum order), then their running sums: the same table
        // for any thread count.
        const int nspec = int(spectrum.size());
        std::vector<std::vector<double>> radii{ size_t(nspec) };
        parallel_for_chunks(0, nspec, 1, nthreads, [&](int64_t i, int64_t) {
            landing_radii(radii[size_t(i)], Landing{ lens, 0.5 * g.c_ref, na_per_pitch, spectrum[size_t(i)].wavelength_nm },
                          table.K);
        });
        parallel_for_chunks(1, table.K + 1, 32, nthreads, [&](int64_t k0, int64_t k1) {
            std::vector<double> mass(size_t(table.bins()), 0.0);
            for (int i = 0; i < nspec; ++i)
                add_wavelength_increments(table, radii[size_t(i)], spectrum[size_t(i)].rgb_weight, int(k0), int(k1), mass,
                                          g.ss == 1);
        });
        cumulate_rows(table, nthreads);
        // How far from the centre each side of the axis has light: table.cumulative is 0
        // past the outermost ray's bin, its tent neighbour and the interpolation's next bin.
        for (const std::vector<double>& r : radii)
            for (double ri : r) {
                if (ri >= 0.0)
                    reach_px[0] = std::max(reach_px[0], ri);
                else
                    reach_px[1] = std::max(reach_px[1], -ri);
            }
        for (double& reach : reach_px)
            if (reach >= 0.0)
                reach = (std::floor(reach / kBinPx) + 3.0) * kBinPx;
    }
    if (edge_law_on)
        add_fringes(table, lens, g, spectrum, na_per_pitch, nthreads);

    // Onion-ring contrast per channel: procedural, plus the physical law per wavelength
    // 2 (2 pi a) sin(pi K^2 / (8 w)), w = W20 / l = c / (8 N l) in waves (docs/methods/optics.md, "Onion rings").
    std::array<double, 3> onion{ lens.onion, lens.onion, lens.onion };
    if (lens.onion_waves > 0.0)
        for (const SpectralSample& smp : spectrum) {
            const double w20 = std::abs(g.c_ref) * lens.pixel_pitch_mm / (8.0 * lens.fstop * smp.wavelength_nm * 1e-6);
            const double contrast = w20 > 0.0 ? std::abs(4.0 * kPi * lens.onion_waves
                                                         * std::sin(kPi * lens.onion_cycles * lens.onion_cycles / (8.0 * w20)))
                                              : 0.0;
            for (int c = 0; c < 3; ++c)
                onion[size_t(c)] += smp.rgb_weight[size_t(c)] * contrast;
        }
    for (double& o : onion)
        o = std::clamp(o, 0.0, 1.0);
    const bool modulated = onion[0] > 0.0 || onion[1] > 0.0 || onion[2] > 0.0 || lens.surface_noise > 0.0;
    // |cos|^p has mean m_p = Gamma((p + 1) / 2) / (sqrt(pi) Gamma(p / 2 + 1)); the ring
    // pattern (|cos|^p - m_p) / max(m_p, 1 - m_p) has mean 0 and stays within -1..1.
    const double p_sharp = lens.onion_sharpness;
    const double mean_p  = std::tgamma(0.5 * (p_sharp + 1.0)) / (std::sqrt(kPi) * std::tgamma(0.5 * p_sharp + 1.0));

    double margin_px = 1.0;
    if (edge_law_on)
        margin_px += table.d_out * g.kappa;
    // The image of the reference disk of radius r_max: A = M (2 / c_ref).
    const double a_scale = 2.0 / std::abs(g.c_ref);
    const double ex = r_max * a_scale * std::hypot(g.m[0][0], g.m[0][1]) + margin_px;
    const double ey = r_max * a_scale * std::hypot(g.m[1][0], g.m[1][1]) + margin_px;
    int w = 2 * int(std::ceil(ex)) + 1, h = 2 * int(std::ceil(ey)) + 1;
    if (req.size_px > 0)
        w = h = req.size_px | 1;
    if (w > 8191 || h > 8191) {
        err = format("the PSF would be {} x {} px; at most 8191 across", w, h);
        return false;
    }
    out.width  = w;
    out.height = h;
    out.rgb.assign(size_t(w) * h * 3, 0.0f);
    const int cx = w / 2, cy = h / 2;
    // All light (fringe band included) within half a pixel of the centre: the centre
    // pixel's square holds that whole disk, so the pixel-area integral is exactly a point,
    // as the flat kernel's (the half-pixel bins' interpolation would spread it a pixel).
    if (ex - 1.0 <= 0.5 && ey - 1.0 <= 0.5) {
        for (int c = 0; c < 3; ++c)
            out.rgb[(size_t(cy) * w + cx) * 3 + c] = 1.0f;
        return true;
    }

    const SpanLut spans(lens, g, r_max, nthreads);
    // Past branch_reach_px a side adds nothing, so a sample beyond both sides' reach is
    // skipped before its trigonometry (the square's corners, and the side of the axis a
    // back or front bokeh's rays never reach). A fringed rim moves light out to its band's
    // outer edge d_out (along the edge normal), as far as the fringe table is 0 at the band's
    // outer end (else its last entry would hold on past it: no bound).
    double branch_reach_px[2] = { reach_px[0], reach_px[1] };
    if (edge_law_on) {
        bool tail_zero = true;
        for (int j = 0; j <= table.Kf; ++j)
            for (int c = 0; c < 3; ++c)
                tail_zero = tail_zero && table.fringe[size_t(j) * table.nd * 3 + c] == 0.0f;
        const double rim_max = *std::max_element(table.rim.begin(), table.rim.end());
        for (int side = 0; side < 2; ++side) {
            if (std::find(table.side.begin(), table.side.end(), int8_t(side == 0 ? 1 : -1)) == table.side.end())
                continue;
            branch_reach_px[side] = tail_zero && spans.ncos_min > 0.01
                                        ? std::max(branch_reach_px[side], rim_max + table.d_out / spans.ncos_min + 1.0)
                                        : std::numeric_limits<double>::infinity();
        }
    }
    const double sample_reach_px = std::max(branch_reach_px[0], branch_reach_px[1]);
    // The onion rings' cos(pi K rho / 2) against rho = |p - o| (the pupil point's distance
    // from the rings' centre) tabulated 0.01 rad of phase apart (linear between entries:
    // within 1.3e-5 of the ring's amplitude), signed so |cos|'s kinks stay exact.
    const double ring_phase_per_rho = 0.5 * kPi * lens.onion_cycles;
    const double ring_rho_max       = 1.0 + std::hypot(g.onion_x, g.onion_y) + 1e-6;
    const int ring_n = std::clamp(int(std::ceil(ring_rho_max * ring_phase_per_rho / 0.01)), 2, 1 << 16);
    const double ring_per_rho = ring_n / ring_rho_max;
    std::vector<float> ring_cos;
    if (modulated) {
        ring_cos.resize(size_t(ring_n) + 2);
        for (int i = 0; i <= ring_n + 1; ++i)
            ring_cos[size_t(i)] = float(std::cos(ring_phase_per_rho * i / ring_per_rho));
    }
    // RGB intensity at a point of the image (x right, y up, px from the centre).
    auto intensity = [&](double x, double y, double sum[3]) {
        const double qx = g.m_inv[0][0] * x + g.m_inv[0][1] * y;
        const double qy = g.m_inv[1][0] * x + g.m_inv[1][1] * y;
        const double xr = 0.5 * g.c_ref * qx, yr = 0.5 * g.c_ref * qy;
        const double R  = std::sqrt(xr * xr + yr * yr);
        if (R >= sample_reach_px)
            return;
        const double phi = std::atan2(yr, xr);
        for (int branch = 1; branch >= -1; branch -= 2) {
            if (R >= branch_reach_px[branch > 0 ? 0 : 1])
                continue;
            const double psi = branch > 0 ? phi : phi + kPi;
            double lo, hi, ncos;
            if (!spans.lookup(psi, lo, hi, ncos))
                continue;
            double a[3] = { 0.0, 0.0, 0.0 }, b[3] = { 0.0, 0.0, 0.0 };
            double Rs = branch * R;
            double fringe[3] = { 1.0, 1.0, 1.0 };
            if (edge_law_on) {
                const RgbTable::Rim rim = table.rim_at(hi);
                if (rim.side == branch && rim.gain > 0.0) {
                    const double d = (rim.radius - R) * ncos;
                    if (d < -table.d_out && rim.gain >= 1.0)
                        continue;
                    if (d < table.d_in) {
                        table.fringe_at(rim, d, fringe);
                        // Outside the rim past the fringes' reach: an exact zero.
                        if (rim.gain >= 1.0 && fringe[0] == 0.0 && fringe[1] == 0.0 && fringe[2] == 0.0)
                            continue;
                        if (R > rim.plateau)
                            Rs = branch * rim.plateau;
                    }
                }
                if (rim.gain < 1.0 && Rs != branch * R) {
                    // Part way to a caustic: the geometric rim blended with the fringed one.
                    double ga[3], gb[3];
                    table.cumulative(branch * R, hi, ga);
                    table.cumulative(branch * R, lo, gb);
                    table.cumulative(Rs, hi, a);
                    table.cumulative(Rs, lo, b);
                    for (int c = 0; c < 3; ++c) {
                        a[c] = rim.gain * (a[c] - b[c]) * fringe[c] + (1.0 - rim.gain) * (ga[c] - gb[c]);
                        b[c] = 0.0;
                        fringe[c] = 1.0;
                    }
                    Rs = std::nan("");
                }
            }
            if (!std::isnan(Rs)) {
                table.cumulative(Rs, hi, a);
                table.cumulative(Rs, lo, b);
            }
            double m[3] = { 1.0, 1.0, 1.0 };
            // The pupil pattern only where light lands (most of a PSF's square is dark).
            if (modulated && (a[0] != b[0] || a[1] != b[1] || a[2] != b[2])) {
                // The pupil point: s along psi (psi's direction is branch (xr, yr) / R).
                const double s  = std::min(1.0, R / (0.5 * std::abs(g.c_ref)));
                const double to_p = R > 0.0 ? branch * s / R : 0.0;
                const double px = to_p * xr, py = to_p * yr;
                const double rho_x = px - g.onion_x, rho_y = py - g.onion_y;
                const double fr = std::sqrt(rho_x * rho_x + rho_y * rho_y) * ring_per_rho;
                const int ir    = std::min(int(fr), ring_n);
                const double wave = std::abs(ring_cos[size_t(ir)] + (fr - ir) * (ring_cos[size_t(ir) + 1] - ring_cos[size_t(ir)]));
                const double ring = ((p_sharp == 1.0 ? wave : std::pow(wave, p_sharp)) - mean_p)
                                    / std::max(mean_p, 1.0 - mean_p);
                const double noise = lens.surface_noise > 0.0 ? lens.surface_noise * pupil_noise(px, py) : 0.0;
                for (int c = 0; c < 3; ++c)
                    m[c] = std::max(0.0, (1.0 + onion[size_t(c)] * ring) * (1.0 + noise));
            }
            for (int c = 0; c < 3; ++c)
                sum[c] += (a[c] - b[c]) * fringe[c] * m[c];
        }
    };

    // Pixel (px, py)'s mean over its ss x ss sub-samples.
    auto pixel = [&](int px, int py, float o[3]) {
        const int ss   = g.ss;
        const double x = px - cx, y = cy - double(py);
        double v[3]    = { 0.0, 0.0, 0.0 };
        for (int j = 0; j < ss; ++j)
            for (int i = 0; i < ss; ++i)
                intensity(x - 0.5 + (i + 0.5) / ss, y - 0.5 + (j + 0.5) / ss, v);
        for (int c = 0; c < 3; ++c)
            o[c] = float(v[c] / (ss * ss));
    };
    // A round aperture on the axis, unsqueezed, with no off-centre pattern: the intensity
    // is a function of the radius alone (the span, the rim and its fringes are the same at
    // every angle), and the sub-samples of a pixel map onto those of its images under the
    // square's eight symmetries. So the octant 0 <= dx <= dy (dy up) is computed and
    // copied to the other seven: an eighth of the lookups, the same pixels but for the
    // order of each pixel's sub-sample sum. (Off the axis too, when nothing depends on the
    // field but the CoC: no cat's eye, astigmatism or rings.)
    const bool radial = lens.aperture.round() && !g.barrel && g.m_inv[0][1] == 0.0 && g.m_inv[1][0] == 0.0
                        && g.m_inv[0][0] == g.m_inv[1][1] && w == h
                        && (!modulated || (lens.surface_noise == 0.0 && g.onion_x == 0.0 && g.onion_y == 0.0));
    const int rows_per_chunk = 8;
    if (radial)
        parallel_for_chunks(0, cy + 1, rows_per_chunk, nthreads, [&](int64_t y0, int64_t y1) {
            for (int dy = int(y0); dy < int(y1); ++dy)
                for (int dx = 0; dx <= dy; ++dx) {
                    float o[3];
                    pixel(cx + dx, cy - dy, o);
                    const int images[8][2] = { { dx, dy },  { -dx, dy },  { dx, -dy }, { -dx, -dy },
                                               { dy, dx },  { -dy, dx },  { dy, -dx }, { -dy, -dx } };
                    for (const auto& im : images)
                        std::copy_n(o, 3, &out.rgb[(size_t(cy - im[1]) * w + size_t(cx + im[0])) * 3]);
                }
        });
    else
        parallel_for_chunks(0, h, rows_per_chunk, nthreads, [&](int64_t y0, int64_t y1) {
            for (int64_t py = y0; py < y1; ++py)
                for (int px = 0; px < w; ++px)
                    pixel(px, int(py), &out.rgb[(size_t(py) * w + px) * 3]);
        });
    const int nchunks = (h + rows_per_chunk - 1) / rows_per_chunk;
    std::vector<std::array<double, 3>> chunk_sum(size_t(nchunks), { 0.0, 0.0, 0.0 });
    parallel_for_chunks(0, h, rows_per_chunk, nthreads, [&](int64_t y0, int64_t y1) {
        std::array<double, 3> acc{ 0.0, 0.0, 0.0 };
        for (int64_t i = y0 * w; i < y1 * w; ++i)
            for (int c = 0; c < 3; ++c)
                acc[size_t(c)] += out.rgb[size_t(i) * 3 + size_t(c)];
        chunk_sum[size_t(y0 / rows_per_chunk)] = acc;
    });
    std::array<double, 3> total{ 0.0, 0.0, 0.0 };
    for (const auto& s : chunk_sum)
        for (int c = 0; c < 3; ++c)
            total[size_t(c)] += s[size_t(c)];
    // Nothing landed in the image (a size smaller than the PSF's offset, or a pupil cut
    // away): that channel's energy goes to the centre pixel.
    std::array<bool, 3> empty{};
    std::array<double, 3> inv{};
    for (int c = 0; c < 3; ++c) {
        empty[size_t(c)] = !(total[size_t(c)] > 0.0);
        inv[size_t(c)]   = empty[size_t(c)] ? 0.0 : 1.0 / total[size_t(c)];
    }
    parallel_for_chunks(0, int64_t(w) * h, 16384, nthreads, [&](int64_t i0, int64_t i1) {
        for (int64_t i = i0; i < i1; ++i)
            for (int c = 0; c < 3; ++c) {
                float& v = out.rgb[size_t(i) * 3 + size_t(c)];
                v        = empty[size_t(c)] ? 0.0f : float(v * inv[size_t(c)]);
            }
    });
    for (int c = 0; c < 3; ++c)
        if (empty[size_t(c)])
            out.rgb[(size_t(cy) * w + cx) * 3 + c] = 1.0f;
    return true;
}

bool lens_psf_image(OIIO::ImageBuf& dst, const LensCharacter& lens, const PsfRequest& req, int nthreads)
{
    Psf psf;
    std::string err;
    if (!lens_psf(psf, lens, req, err, nthreads))
        return dst.errorfmt("lens_psf: {}", err), false;
    OIIO::ImageSpec spec(psf.width, psf.height, 3, OIIO::TypeDesc::FLOAT);
    spec.x = spec.full_x = -(psf.width / 2);
    spec.y = spec.full_y = -(psf.height / 2);
    dst.reset(spec);
    dst.set_pixels(dst.roi(), OIIO::TypeDesc::FLOAT, psf.rgb.data());
    return true;
}

// ---------------------------------------------------------------------------------------
// The contact sheet

bool bokeh_sheet_image(OIIO::ImageBuf& dst, const LensCharacter& lens, double coc_max_px,
                       int columns, int rows, int cell_px, int nthreads)
{
    if (columns < 1 || rows < 1 || columns > 64 || rows > 64 || cell_px < 8 || cell_px > 2048)
        return dst.errorfmt("bokeh_sheet: 1..64 columns and rows, cells of 8..2048 px"), false;
    if (!(std::isfinite(coc_max_px) && coc_max_px > 0.0 && coc_max_px < cell_px))
        return dst.errorfmt("bokeh_sheet: the largest CoC {:g} must be above 0 and under the cell size {}",
                            coc_max_px, cell_px),
               false;
    const int cell = cell_px | 1;
    const int W = columns * cell, H = rows * cell;
    std::vector<float> sheet(size_t(W) * H * 3, 0.0f);
    // The frame corner of a 16:9 frame, in half-diagonals.
    const double corner = std::atan2(9.0, 16.0);
    for (int row = 0; row < rows; ++row)
        for (int col = 0; col < columns; ++col) {
            PsfRequest req;
            req.coc_px  = columns == 1 ? coc_max_px : coc_max_px * (2.0 * col / (columns - 1) - 1.0);
            const double fh = rows == 1 ? 0.0 : double(row) / (rows - 1);
            req.field_x = fh * std::cos(corner);
            req.field_y = fh * std::sin(corner);
            req.size_px = cell;
            Psf psf;
            std::string err;
            if (!lens_psf(psf, lens, req, err, nthreads))
                return dst.errorfmt("bokeh_sheet: {}", err), false;
            float peak = 1e-30f;
            for (float v : psf.rgb)
                peak = std::max(peak, v);
            for (int y = 0; y < cell; ++y)
                for (int x = 0; x < cell; ++x)
                    for (int c = 0; c < 3; ++c)
                        sheet[(size_t(row * cell + y) * W + col * cell + x) * 3 + c] = psf.at(x, y, c) / peak;
        }
    dst.reset(OIIO::ImageSpec(W, H, 3, OIIO::TypeDesc::FLOAT));
    dst.set_pixels(dst.roi(), OIIO::TypeDesc::FLOAT, sheet.data());
    return true;
}

}  // namespace bokeh
