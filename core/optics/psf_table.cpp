// psf_table.cpp — the radial tables of a lens's PSF (psf_table.h; the method is
// core/optics/lens_psf.cpp's header, steps 1 and 3): each wavelength's rays landing at
// r(s) = s (c/2 - a(s, l)), their mass spread over the bins their s step covers and
// cumulated along the pupil radius; the request's geometry; and the rim's fringes by the
// Fresnel edge law (docs/methods/optics.md, "Diffraction at the rim").

#include "optics/psf_table.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

using OIIO::Strutil::fmt::format;

const EdgeLawTable& edge_law_table()
{
    static const EdgeLawTable table;
    return table;
}

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
        const double r0 = std::abs((b - t.half_bins) * t.bin_px), r1 = std::abs((b - t.half_bins + 1) * t.bin_px);
        return mass[size_t(b)] / (0.5 * std::abs(r1 * r1 - r0 * r0));
    };
    for (int k = std::max(1, k_begin); k < std::min(k_end, K + 1); ++k) {
        int touched_lo = nb, touched_hi = -1;
        for (int i = (k - 1) * kRaysPerRow; i < k * kRaysPerRow; ++i) {
            const double s_mid  = (i + 0.5) * ds;
            const double r_prev = r[size_t(i)], r_next = r[size_t(i) + 1];
            const double m      = s_mid * ds;  // pupil area per unit angle
            const double lo = std::min(r_prev, r_next), hi = std::max(r_prev, r_next);
            const double f_lo = lo / t.bin_px + t.half_bins, f_hi = hi / t.bin_px + t.half_bins;
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
    // DiffractionModel::PseudoMap: the talk's pseudo-diffraction map (core/optics/diffraction_map.cpp),
    // relative to its flat level 1 / pi, in place of the edge law.
    const bool pseudo = lens.diffraction == DiffractionModel::PseudoMap;
    static const PseudoDiffractionMap pseudo_map;
    const PseudoDiffractionMap* map = pseudo ? &pseudo_map : nullptr;
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
        t.plateau[size_t(j)] = float(std::max(0.0, innermost - 2.0 * t.bin_px));
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
            const double pseudo_width
                = pseudo ? map->width_ratio(defocus_waves_px(c_eff, lens.fstop, smp.wavelength_nm, lens.pixel_pitch_mm))
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
                if (pseudo) {
                    for (int k = 0; k < kSubsamples; ++k) {
                        const double d_k = d_l + ((k + 0.5) / kSubsamples - 0.5) / g.kappa;
                        f += kPi * map->lookup(1.0 - d_k * g.kappa / (0.5 * c_eff), pseudo_width);
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

}  // namespace bokeh::detail
