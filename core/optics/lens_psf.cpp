// lens_psf.cpp — the PSF of a lens with character at one signed CoC and field position
// (optics.h has the model), and the contact sheet `--bokeh:sheet=1` draws. The caches the
// defocus reads PSFs from are core/optics/psf_cache.cpp's.
//
// How a PSF is drawn (Kawase, "Bokeh Deep Dive": a light-beam-map column rotated about the
// axis and distorted by the aperture's radial LUT; docs/methods/lens-character.md):
//  1. Per wavelength, a radial table: rays at 8K pupil radii s in (0, 1) land at r(s) =
//     s (c/2 - a(s, l)); each ray's mass s ds is spread over the R interval its s step
//     covers, into bins 0.5 px wide (an eighth of the radius for a disk under 8 px:
//     radial_bin_px); the bins' densities (mass over annulus area) are
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
//     DiffractionModel::PseudoMap puts the talk's pseudo-diffraction map in place of F: pi
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
//  6. Lateral colour (the talk's "magnification varying with radius / wavelength"): each
//     of R and B is the same PSF displaced radially by its px at the frame corner times
//     H, sampled at the displaced point (no resampling), so a white point's R-B fringe
//     is exactly |lateral_r_px - lateral_b_px| H (per channel, not per wavelength: the
//     magnification's spectrum inside a channel is not modelled).
// Limits: astigmatic and anamorphic PSFs carry the spherical aberration of the larger
// axis' CoC scaled along the other; their fringes use the mean scale. The hole's inner
// rim has no fringes.

#include <bokeh/base.h>
#include <bokeh/optics.h>
#include <bokeh/parallel.h>
#include <bokeh/wave_optics.h>

#include "optics/psf_table.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;
using namespace detail;

namespace {

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

// The request's checks: CoC, field position and size within what a PSF can be.
bool check_psf_request(const LensCharacter& lens, const PsfRequest& req, std::string& err)
{
    if (!check_lens(lens, err))
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
    return true;
}

// The radial table of every wavelength's rays (the file header's step 1), and how far
// from the centre each side of the axis has light (reach_px: + and - side, -1 for none).
// Each wavelength's rays, then the table's increments in bands of rows (every band adds
// the wavelengths in spectrum order), then their running sums: the same table for any
// thread count.
void build_radial_table(RgbTable& table, double reach_px[2], const LensCharacter& lens, const Geometry& g,
                        const std::vector<SpectralSample>& spectrum, double r_max, double na_per_pitch,
                        int nthreads)
{
    reach_px[0] = reach_px[1] = -1.0;
    table.K         = std::clamp(int(std::ceil(2.0 * r_max)), 32, 1024);  // half a px of radius apart
    table.bin_px    = radial_bin_px(r_max);
    table.half_bins = int(std::ceil(r_max / table.bin_px)) + 2;
    table.dens.assign(size_t(table.K + 1) * table.bins() * 3, 0.0f);
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
    for (int side = 0; side < 2; ++side)
        if (reach_px[side] >= 0.0)
            reach_px[side] = (std::floor(reach_px[side] / table.bin_px) + 3.0) * table.bin_px;
}

// Onion-ring contrast per channel: procedural, plus the physical law per wavelength
// 2 (2 pi a) sin(pi K^2 / (8 w)), w = W20 / l = c / (8 N l) in waves
// (docs/methods/optics.md, "Onion rings").
std::array<double, 3> onion_contrast(const LensCharacter& lens, const Geometry& g,
                                     const std::vector<SpectralSample>& spectrum)
{
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
    return onion;
}

// The PSF's RGB intensity at a point of the image (the file header's steps 2-4): the
// pupil span along each direction through the radial table, the rim's fringes, the onion
// rings and the surface noise where light lands.
struct PsfSampler {
    const LensCharacter& lens;
    const Geometry& g;
    const RgbTable& table;
    const SpanLut& spans;
    bool edge_law_on = false;
    std::array<double, 3> onion{};
    bool modulated = false;
    double p_sharp = 1.0, mean_p = 0.0;
    // Past branch_reach_px a side adds nothing, so a sample beyond both sides' reach is
    // skipped before its trigonometry (the square's corners, and the side of the axis a
    // back or front bokeh's rays never reach).
    double branch_reach_px[2] = { -1.0, -1.0 };
    double sample_reach_px    = 0.0;
    // The onion rings' cos(pi K rho / 2) against rho = |p - o| (the pupil point's distance
    // from the rings' centre) tabulated 0.01 rad of phase apart (linear between entries:
    // within 1.3e-5 of the ring's amplitude), signed so |cos|'s kinks stay exact.
    int ring_n = 2;
    double ring_per_rho = 1.0;
    std::vector<float> ring_cos;

    PsfSampler(const LensCharacter& l, const Geometry& geometry, const RgbTable& t, const SpanLut& s,
               const std::vector<SpectralSample>& spectrum, const double reach_px[2])
        : lens(l), g(geometry), table(t), spans(s)
    {
        edge_law_on = lens.diffraction != DiffractionModel::Off;  // either fringe model
        onion       = onion_contrast(lens, g, spectrum);
        modulated   = onion[0] > 0.0 || onion[1] > 0.0 || onion[2] > 0.0 || lens.surface_noise > 0.0;
        // |cos|^p has mean m_p = Gamma((p + 1) / 2) / (sqrt(pi) Gamma(p / 2 + 1)); the ring
        // pattern (|cos|^p - m_p) / max(m_p, 1 - m_p) has mean 0 and stays within -1..1.
        p_sharp = lens.onion_sharpness;
        mean_p  = std::tgamma(0.5 * (p_sharp + 1.0)) / (std::sqrt(kPi) * std::tgamma(0.5 * p_sharp + 1.0));
        branch_reach_px[0] = reach_px[0];
        branch_reach_px[1] = reach_px[1];
        // A fringed rim moves light out to its band's outer edge d_out (along the edge
        // normal), as far as the fringe table is 0 at the band's outer end (else its last
        // entry would hold on past it: no bound).
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
        sample_reach_px = std::max(branch_reach_px[0], branch_reach_px[1]);
        const double ring_phase_per_rho = 0.5 * kPi * lens.onion_cycles;
        const double ring_rho_max       = 1.0 + std::hypot(g.onion_x, g.onion_y) + 1e-6;
        ring_n       = std::clamp(int(std::ceil(ring_rho_max * ring_phase_per_rho / 0.01)), 2, 1 << 16);
        ring_per_rho = ring_n / ring_rho_max;
        if (modulated) {
            ring_cos.resize(size_t(ring_n) + 2);
            for (int i = 0; i <= ring_n + 1; ++i)
                ring_cos[size_t(i)] = float(std::cos(ring_phase_per_rho * i / ring_per_rho));
        }
    }

    // RGB intensity at a point of the image (x right, y up, px from the centre), added to sum.
    void intensity(double x, double y, double sum[3]) const
    {
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
    }
};

// Every pixel of `out` (w x h, centre cx, cy) the mean of its ss x ss sub-samples. A round
// aperture on the axis, unsqueezed, with no off-centre pattern: the intensity is a
// function of the radius alone (the span, the rim and its fringes are the same at every
// angle), and the sub-samples of a pixel map onto those of its images under the square's
// eight symmetries. So the octant 0 <= dx <= dy (dy up) is computed and copied to the
// other seven: an eighth of the lookups, the same pixels but for the order of each
// pixel's sub-sample sum. (Off the axis too, when nothing depends on the field but the
// CoC: no cat's eye, astigmatism or rings.)
// Lateral colour: channel c's image displaced by shift[c] px (x right, y up; green's 0) is
// sampled at the point less its shift, three lookups a sub-sample instead of one.
void rasterise(Psf& out, const PsfSampler& sampler, const double shift[3][2], int rows_per_chunk, int nthreads)
{
    const Geometry& g  = sampler.g;
    const int w = out.width, h = out.height, cx = w / 2, cy = h / 2;
    bool shifted = false;
    for (int c = 0; c < 3; ++c)
        shifted = shifted || shift[c][0] != 0.0 || shift[c][1] != 0.0;
    auto pixel = [&](int px, int py, float o[3]) {
        const int ss   = g.ss;
        const double x = px - cx, y = cy - double(py);
        double v[3]    = { 0.0, 0.0, 0.0 };
        for (int j = 0; j < ss; ++j)
            for (int i = 0; i < ss; ++i) {
                const double sx = x - 0.5 + (i + 0.5) / ss, sy = y - 0.5 + (j + 0.5) / ss;
                if (!shifted) {
                    sampler.intensity(sx, sy, v);
                    continue;
                }
                for (int c = 0; c < 3; ++c) {
                    double one[3] = { 0.0, 0.0, 0.0 };
                    sampler.intensity(sx - shift[c][0], sy - shift[c][1], one);
                    v[c] += one[c];
                }
            }
        for (int c = 0; c < 3; ++c)
            o[c] = float(v[c] / (ss * ss));
    };
    const bool radial = !shifted && sampler.lens.aperture.round() && !g.barrel && g.m_inv[0][1] == 0.0 && g.m_inv[1][0] == 0.0
                        && g.m_inv[0][0] == g.m_inv[1][1] && w == h
                        && (!sampler.modulated
                            || (sampler.lens.surface_noise == 0.0 && g.onion_x == 0.0 && g.onion_y == 0.0));
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
}

// Each channel scaled to sum 1 (sums by chunks of rows, added in order: the same for any
// thread count). A channel where nothing landed in the image (a size smaller than the
// PSF's offset, or a pupil cut away) puts its energy in the centre pixel.
void normalise_channels(Psf& out, int rows_per_chunk, int nthreads)
{
    const int w = out.width, h = out.height, cx = w / 2, cy = h / 2;
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
}

}  // namespace

bool lens_psf(Psf& out, const LensCharacter& lens, const PsfRequest& req, std::string& err,
              int nthreads)
{
    out = Psf();
    if (!check_psf_request(lens, req, err))
        return false;
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
    double reach_px[2];
    build_radial_table(table, reach_px, lens, g, spectrum, r_max, na_per_pitch, nthreads);
    if (edge_law_on)
        add_fringes(table, lens, g, spectrum, na_per_pitch, nthreads);

    double margin_px = 1.0;
    if (edge_law_on)
        margin_px += table.d_out * g.kappa;
    // Lateral colour: R and B displaced along the field's direction by their px at the
    // corner times H (x right, y up, as the field); the square grows to hold them.
    double shift[3][2] = { { 0.0, 0.0 }, { 0.0, 0.0 }, { 0.0, 0.0 } };
    const double lateral_px[3] = { lens.lateral_r_px, 0.0, lens.lateral_b_px };
    for (int c = 0; c < 3; ++c) {
        shift[c][0] = lateral_px[c] * req.field_x;
        shift[c][1] = lateral_px[c] * req.field_y;
    }
    const double shift_x = std::max(std::abs(shift[0][0]), std::abs(shift[2][0]));
    const double shift_y = std::max(std::abs(shift[0][1]), std::abs(shift[2][1]));
    // The image of the reference disk of radius r_max: A = M (2 / c_ref).
    const double a_scale = 2.0 / std::abs(g.c_ref);
    const double ex = r_max * a_scale * std::hypot(g.m[0][0], g.m[0][1]) + margin_px + shift_x;
    const double ey = r_max * a_scale * std::hypot(g.m[1][0], g.m[1][1]) + margin_px + shift_y;
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
    // All light (fringe band included) within half a pixel of the centre: the centre
    // pixel's square holds that whole disk, so the pixel-area integral is exactly a point,
    // as the flat kernel's (the half-pixel bins' interpolation would spread it a pixel).
    if (ex - 1.0 <= 0.5 && ey - 1.0 <= 0.5 && shift_x == 0.0 && shift_y == 0.0) {
        for (int c = 0; c < 3; ++c)
            out.rgb[(size_t(h / 2) * w + w / 2) * 3 + c] = 1.0f;
        return true;
    }
    const SpanLut spans(lens, g, r_max, nthreads);
    const PsfSampler sampler(lens, g, table, spans, spectrum, reach_px);
    constexpr int kRowsPerChunk = 8;
    rasterise(out, sampler, shift, kRowsPerChunk, nthreads);
    normalise_channels(out, kRowsPerChunk, nthreads);
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
