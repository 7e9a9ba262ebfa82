// fit_model.cpp — the model the lens fit minimises (fit/fit_model.h): rendering and
// sampling a crop's PSF, the linear part solved exactly, the Cauchy cost, and the bounded
// minimiser over NLopt. The crops it reads and the noise model: fit_crop.cpp.

#include <bokeh/base.h>
#include <bokeh/lens_fit.h>
#include <bokeh/parallel.h>

#include "fit/fit_model.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numeric>

#include <nlopt.h>

namespace bokeh {
namespace fit {

double luminance(const float* p, int channels)
{
    return channels >= 3 ? 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2] : p[0];
}

bool solve_linear(int n, double* a, double* b, double* x)
{
    for (int k = 0; k < n; ++k) {
        int p = k;
        for (int i = k + 1; i < n; ++i)
            if (std::abs(a[i * n + k]) > std::abs(a[p * n + k]))
                p = i;
        if (!(std::abs(a[p * n + k]) > 1e-300))
            return false;
        if (p != k) {
            for (int j = 0; j < n; ++j)
                std::swap(a[k * n + j], a[p * n + j]);
            std::swap(b[k], b[p]);
        }
        for (int i = k + 1; i < n; ++i) {
            const double f = a[i * n + k] / a[k * n + k];
            for (int j = k; j < n; ++j)
                a[i * n + j] -= f * a[k * n + j];
            b[i] -= f * b[k];
        }
    }
    for (int k = n - 1; k >= 0; --k) {
        double s = b[k];
        for (int j = k + 1; j < n; ++j)
            s -= a[k * n + j] * x[j];
        x[k] = s / a[k * n + k];
    }
    return true;
}

namespace {

// The Cauchy loss's scale in noise sigmas: residuals past ~3 sigma count logarithmically.
constexpr double kCauchyScale = 3.0;
// The spectral step while the fit searches (11 wavelengths over 400-710 nm instead of
// 32, a third of a coloured PSF's time); the report renders at the camera's own step. The
// axial-colour round trip of tests/fit/lens_fit_test.cpp (truth at 10 nm) recovers
// chromatic 1.452 of 1.5 with it.
constexpr double kFitWaveStepNm = 31.0;

}  // namespace

// ---------------------------------------------------------------------------------------
// The model

LensCharacter Model::lens_of(const State& s, bool coarse_spectrum) const
{
    LensCharacter l = m_opts.camera;
    l.preset        = LensPreset::Uncorrected;
    l.correction    = s.zonal;
    l.monochromatic = s.mono;
    l.chromatic     = s.chroma;
    l.spherochromatism = 0.0;
    l.onion         = s.onion;
    l.catseye       = s.catseye;
    l.astigmatism_px = s.astig;
    Kernel k;
    k.shape        = s.blades > 0 ? KernelShape::Polygon : KernelShape::Disk;
    k.blades       = std::max(3, s.blades);
    k.rotation_deg = float(s.rotation);
    k.curvature    = float(s.curvature);
    k.hole         = float(s.hole);
    std::string err;
    Aperture::from_kernel(k, l.aperture, err);
    if (coarse_spectrum)
        l.spectrum.step_nm = std::max(l.spectrum.step_nm, kFitWaveStepNm);
    return l;
}

bool Model::psf(Psf& out, const State& s, size_t i, bool coarse, int nthreads) const
{
    PsfRequest req;
    req.coc_px  = signed_coc(s, i);
    req.field_x = m_crops[i].fx;
    req.field_y = m_crops[i].fy;
    std::string err;
    return lens_psf(out, lens_of(s, coarse), req, err, nthreads);
}

namespace {

// Where a crop's pixels fall in the PSF for a centre (cx, cy). Every pixel shares the
// centre's fractional offset, so the four bilinear weights are computed once.
struct PsfPlacement {
    int ox = 0, oy = 0;  // the PSF column and row of pixel (0, 0)'s first tap
    double w[4] = {};    // the weights of taps (0, 0), (1, 0), (0, 1), (1, 1)
};

PsfPlacement place_psf(const Psf& p, double cx, double cy)
{
    const double x = 0.5 * (p.width - 1) + 0.5 - cx, y = 0.5 * (p.height - 1) + 0.5 - cy;
    PsfPlacement pl;
    pl.ox = int(std::floor(x)), pl.oy = int(std::floor(y));
    const double fx = x - pl.ox, fy = y - pl.oy;
    pl.w[0] = (1 - fx) * (1 - fy), pl.w[1] = fx * (1 - fy), pl.w[2] = (1 - fx) * fy, pl.w[3] = fx * fy;
    return pl;
}

// The PSF at crop pixel (i, j), bilinear, zero outside it.
void psf_at(const Psf& p, const PsfPlacement& pl, int i, int j, float out[3])
{
    const int x0 = i + pl.ox, y0 = j + pl.oy;
    out[0] = out[1] = out[2] = 0.0f;
    if (x0 < -1 || y0 < -1 || x0 >= p.width || y0 >= p.height)
        return;
    double v[3] = { 0, 0, 0 };
    for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
            const int xx = x0 + dx, yy = y0 + dy;
            if (xx < 0 || yy < 0 || xx >= p.width || yy >= p.height)
                continue;
            const double w = pl.w[dy * 2 + dx];
            const float* t = &p.rgb[(size_t(yy) * p.width + xx) * 3];
            v[0] += w * t[0], v[1] += w * t[1], v[2] += w * t[2];
        }
    out[0] = float(v[0]), out[1] = float(v[1]), out[2] = float(v[2]);
}

// Pixels a chunk of the fit's passes: fixed, so the sums are added in one order, and the
// cost is the same bits, on any number of threads.
constexpr int64_t kFitChunk = 2048;

}  // namespace

void Model::sample(std::vector<float>& dst, const Psf& p, const CropData& d, double cx, double cy)
{
    const size_t npix = size_t(d.w) * d.h;
    dst.resize(npix * 3);
    const PsfPlacement pl = place_psf(p, cx, cy);
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            float v[3];
            psf_at(p, pl, i, j, v);
            for (int c = 0; c < 3; ++c)
                dst[size_t(c) * npix + size_t(j) * d.w + i] = v[c];
        }
}

void Model::sample_fitted(std::vector<float>& dst, const Psf& p, const CropData& d, double cx, double cy,
                          int nthreads)
{
    const size_t m = d.fit_k.size();
    dst.resize(m * 3);
    const PsfPlacement pl = place_psf(p, cx, cy);
    parallel_for_chunks(0, int64_t(m), kFitChunk, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t n = b; n < e; ++n) {
            float v[3];
            psf_at(p, pl, d.fit_i[size_t(n)], d.fit_j[size_t(n)], v);
            for (int c = 0; c < 3; ++c)
                dst[size_t(c) * m + size_t(n)] = v[c];
        }
    });
}

void Model::place(const Psf& p, const State& s, size_t i, double& cx, double& cy) const
{
    cx = s.cx[i], cy = s.cy[i];
    if (!m_centres_at_light)
        return;
    double sum = 0.0, sx = 0.0, sy = 0.0;
    const double hw = 0.5 * (p.width - 1), hh = 0.5 * (p.height - 1);
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x) {
            const float* t = &p.rgb[(size_t(y) * p.width + x) * 3];
            const double l = luminance(t, 3);
            sum += l, sx += l * (x - hw), sy += l * (y - hh);
        }
    if (sum > 0.0)
        cx -= sx / sum, cy -= sy / sum;
}

void Model::sample_crop(std::vector<float>& dst, const Psf& p, const State& s, size_t i, int nthreads) const
{
    double cx, cy;
    place(p, s, i, cx, cy);
    sample_fitted(dst, p, m_crops[i], cx, cy, nthreads);
}

void prepare_fit_arrays(CropData& d)
{
    d.fit_k.clear(), d.fit_i.clear(), d.fit_j.clear(), d.fit_x.clear(), d.fit_y.clear();
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i)
            if (d.use[size_t(j) * d.w + i]) {
                d.fit_k.push_back(uint32_t(size_t(j) * d.w + i));
                d.fit_i.push_back(i), d.fit_j.push_back(j);
                d.fit_x.push_back(float(plane_x(d, i)));
                d.fit_y.push_back(float(plane_y(d, j)));
            }
    const size_t m = d.fit_k.size();
    d.fit_v.resize(m * size_t(d.channels));
    for (int ch = 0; ch < d.channels; ++ch)
        for (size_t n = 0; n < m; ++n)
            d.fit_v[size_t(ch) * m + n] = d.px[size_t(d.fit_k[n]) * d.channels + ch];
    d.cached_floor2 = -1.0;
}

namespace {

// The weights with `floor2` added to each variance, and the sums of the linear part's
// normal equations that do not depend on the PSF (the plane's columns against
// themselves and the data), for the first pass; kept until the floor or noise changes.
void ensure_weights(const CropData& d, double floor2)
{
    if (d.cached_floor2 == floor2)
        return;
    const size_t m = d.fit_k.size();
    d.fit_iv.resize(m * size_t(d.channels));
    for (int ch = 0; ch < d.channels; ++ch) {
        double* b = d.base[ch];
        std::fill(b, b + 9, 0.0);
        for (size_t n = 0; n < m; ++n) {
            const double iv0 = d.inv_var[size_t(d.fit_k[n]) * d.channels + ch];
            const double iv  = floor2 > 0.0 ? 1.0 / (1.0 / iv0 + floor2) : iv0;
            d.fit_iv[size_t(ch) * m + n] = float(iv);
            const double x = d.fit_x[n], y = d.fit_y[n], v = d.fit_v[size_t(ch) * m + n];
            b[0] += iv, b[1] += iv * x, b[2] += iv * y, b[3] += iv * x * x, b[4] += iv * x * y, b[5] += iv * y * y;
            b[6] += iv * v, b[7] += iv * x * v, b[8] += iv * y * v;
        }
    }
    d.cached_floor2 = floor2;
}

// Solve the 4 x 4 normal equations of columns (P, 1, x, y) from their sums: `pp`, `p1`,
// `px`, `py`, `pv` those with the PSF, `b` the plane's (ensure_weights' order).
void solve_normal(const double b[9], double pp, double p1, double px, double py, double pv, double x[4])
{
    double a[16] = { pp + 1e-12, p1, px, py,  // 1e-12: a PSF wholly outside the crop, the plane alone
                     p1, b[0], b[1], b[2],
                     px, b[1], b[3], b[4],
                     py, b[2], b[4], b[5] };
    double r[4] = { pv, b[6], b[7], b[8] };
    if (!solve_linear(4, a, r, x))
        x[0] = x[1] = x[2] = x[3] = 0.0;
}

template<size_t N>
void add_sums(std::array<double, N>& acc, const std::array<double, N>& part)
{
    for (size_t k = 0; k < N; ++k)
        acc[k] += part[k];
}

}  // namespace

double Model::fit_linear(const CropData& d, const std::vector<float>& s, Linear& lin,
                         std::vector<double>* residuals, int* outliers, double floor_of_level, int nthreads)
{
    const double floor2 = floor_of_level * floor_of_level * d.level * d.level;
    ensure_weights(d, floor2);
    const size_t m = d.fit_k.size();
    const int nch  = d.channels;
    constexpr double inv_c2 = 1.0 / (kCauchyScale * kCauchyScale);
    const float* fx = d.fit_x.data();
    const float* fy = d.fit_y.data();
    // One channel's compact arrays: the pixels' values, their inverse variances, the PSF.
    struct Channel {
        const float *v, *iv, *p;
    };
    const auto channel = [&](int ch) {
        return Channel { &d.fit_v[size_t(ch) * m], &d.fit_iv[size_t(ch) * m], &s[size_t(ch) * m] };
    };
    // The residual of pixel n under a channel's linear part x (amplitude, plane).
    const auto residual = [&](const Channel& c, const double* x, int64_t n) {
        return double(c.v[n]) - (x[0] * c.p[n] + x[1] + x[2] * fx[n] + x[3] * fy[n]);
    };

    // Pass 1: inverse-variance weights; per channel the PSF's sums (pp, p1, px, py, pv),
    // the plane's precomputed.
    using Pass1 = std::array<double, 15>;
    const Pass1 s1 = parallel_reduce_chunks(
        0, int64_t(m), kFitChunk, nthreads, Pass1 {},
        [&](int64_t b, int64_t e) {
            Pass1 part {};
            for (int ch = 0; ch < nch; ++ch) {
                const Channel c = channel(ch);
                double pp = 0, p1 = 0, px = 0, py = 0, pv = 0;
                for (int64_t n = b; n < e; ++n) {
                    const double wp = double(c.iv[n]) * c.p[n];
                    pp += wp * c.p[n], p1 += wp, px += wp * fx[n], py += wp * fy[n], pv += wp * c.v[n];
                }
                double* o = &part[size_t(ch) * 5];
                o[0] = pp, o[1] = p1, o[2] = px, o[3] = py, o[4] = pv;
            }
            return part;
        },
        add_sums<15>);
    double x[3][4];
    for (int ch = 0; ch < nch; ++ch) {
        const double* o = &s1[size_t(ch) * 5];
        solve_normal(d.base[ch], o[0], o[1], o[2], o[3], o[4], x[ch]);
    }

    // Pass 2: the Cauchy weights of pass 1's residuals; per channel the PSF's five sums
    // and the plane's nine.
    using Pass2 = std::array<double, 42>;
    const Pass2 s2 = parallel_reduce_chunks(
        0, int64_t(m), kFitChunk, nthreads, Pass2 {},
        [&](int64_t b, int64_t e) {
            Pass2 part {};
            for (int ch = 0; ch < nch; ++ch) {
                const Channel c = channel(ch);
                double q[14]    = {};
                for (int64_t n = b; n < e; ++n) {
                    const double xx = fx[n], yy = fy[n], vn = c.v[n], pn = c.p[n];
                    const double r  = residual(c, x[ch], n);
                    const double w  = c.iv[n] / (1.0 + r * r * c.iv[n] * inv_c2);
                    const double wp = w * pn;
                    q[0] += wp * pn, q[1] += wp, q[2] += wp * xx, q[3] += wp * yy, q[4] += wp * vn;
                    q[5] += w, q[6] += w * xx, q[7] += w * yy, q[8] += w * xx * xx, q[9] += w * xx * yy;
                    q[10] += w * yy * yy, q[11] += w * vn, q[12] += w * xx * vn, q[13] += w * yy * vn;
                }
                std::copy(q, q + 14, &part[size_t(ch) * 14]);
            }
            return part;
        },
        add_sums<42>);
    for (int ch = 0; ch < nch; ++ch) {
        const double* q = &s2[size_t(ch) * 14];
        solve_normal(q + 5, q[0], q[1], q[2], q[3], q[4], x[ch]);
        lin.a[ch] = x[ch][0], lin.b0[ch] = x[ch][1], lin.bx[ch] = x[ch][2], lin.by[ch] = x[ch][3];
    }

    // The cost: the Cauchy loss of pass 2's residuals (and the outliers: channel 0's
    // pixels past the loss's scale).
    const size_t first = residuals ? residuals->size() : 0;
    if (residuals)
        residuals->resize(first + size_t(nch) * m);
    using Pass3 = std::array<double, 2>;
    const Pass3 s3 = parallel_reduce_chunks(
        0, int64_t(m), kFitChunk, nthreads, Pass3 {},
        [&](int64_t b, int64_t e) {
            Pass3 part {};
            for (int ch = 0; ch < nch; ++ch) {
                const Channel c = channel(ch);
                double* res     = residuals ? &(*residuals)[first + size_t(ch) * m] : nullptr;
                // sum ln(1 + u) as the ln of a running product, taken when the product
                // passes 1e150: one logarithm for thousands of pixels, where a log1p a
                // pixel was a sixth of an eight-crop fit (perf record, the bench's speed
                // case). A product of k factors is exact to k ulps, so each logarithm is
                // off by under k 1.1e-16 in absolute terms: ~1e-12 over a crop, against
                // costs of ~1e4 compared to 1e-3 by the minimiser.
                double cost = 0.0, product = 1.0;
                for (int64_t n = b; n < e; ++n) {
                    const double r  = residual(c, x[ch], n);
                    const double u2 = r * r * c.iv[n] * inv_c2;
                    product *= 1.0 + u2;
                    if (product > 1e150)
                        cost += std::log(product), product = 1.0;
                    if (res)
                        res[n] = r * std::sqrt(c.iv[n] / (1.0 + u2));
                    if (ch == 0 && u2 > 1.0)
                        part[1] += 1.0;
                }
                cost += std::log(product);
                part[0] += 0.5 * kCauchyScale * kCauchyScale * cost;
            }
            return part;
        },
        add_sums<2>);
    if (outliers)
        *outliers += int(s3[1]);
    return s3[0];
}

double Model::cost(const State& s, bool coarse, const std::vector<size_t>& which) const
{
    std::vector<size_t> idx = which;
    if (idx.empty()) {
        idx.resize(m_crops.size());
        std::iota(idx.begin(), idx.end(), size_t(0));
    }
    std::vector<double> costs(idx.size(), 0.0);
    const int inner = idx.size() > 1 ? 1 : m_nthreads;
    auto one = [&](size_t n) {
        const size_t i = idx[n];
        Psf p;
        if (!psf(p, s, i, coarse, inner)) {
            costs[n] = 1e300;
            return;
        }
        std::vector<float> smp;
        sample_crop(smp, p, s, i, inner);
        Linear lin;
        costs[n] = fit_linear(m_crops[i], smp, lin, nullptr, nullptr, m_floor, inner);
    };
    if (idx.size() > 1)
        parallel_for_chunks(0, int64_t(idx.size()), 1, m_nthreads, [&](int64_t b, int64_t e) {
            for (int64_t n = b; n < e; ++n)
                one(size_t(n));
        });
    else
        one(0);
    ++m_evaluations;
    return std::accumulate(costs.begin(), costs.end(), 0.0);
}

namespace {

// ---------------------------------------------------------------------------------------
// Minimisation over a few named parameters (NLopt, bounded, scaled to 0..1)

struct Objective {
    std::vector<Free>* free;
    std::function<double()> cost;
    double best = 1e300;
    std::vector<double> best_x;
};

double objective_trampoline(unsigned n, const double* x, double*, void* data)
{
    auto* o = static_cast<Objective*>(data);
    for (unsigned k = 0; k < n; ++k) {
        const Free& f = (*o->free)[k];
        *f.value      = f.lo + x[k] * (f.hi - f.lo);
    }
    const double c = o->cost();
    if (c < o->best) {
        o->best = c;
        o->best_x.assign(x, x + n);
    }
    return c;
}

}  // namespace

double minimise(std::vector<Free>& free, const std::function<double()>& cost, int max_evaluations)
{
    const unsigned n = unsigned(free.size());
    std::vector<double> x(n), lo(n, 0.0), hi(n, 1.0), step(n);
    for (unsigned k = 0; k < n; ++k) {
        Free& f   = free[k];
        *f.value  = std::clamp(*f.value, f.lo, f.hi);
        x[k]      = (*f.value - f.lo) / (f.hi - f.lo);
        step[k]   = std::clamp(f.step / (f.hi - f.lo), 1e-4, 0.45);
    }
    Objective o { &free, cost, 1e300, x };
    nlopt_opt opt = nlopt_create(n >= 2 ? NLOPT_LN_BOBYQA : NLOPT_LN_SBPLX, n);
    nlopt_set_lower_bounds(opt, lo.data());
    nlopt_set_upper_bounds(opt, hi.data());
    nlopt_set_initial_step(opt, step.data());
    nlopt_set_min_objective(opt, objective_trampoline, &o);
    nlopt_set_xtol_abs1(opt, 2e-4);
    nlopt_set_ftol_abs(opt, 1e-3);
    nlopt_set_maxeval(opt, std::max(max_evaluations, int(2 * n + 3)));
    double f = 0.0;
    nlopt_optimize(opt, x.data(), &f);  // a stop at maxeval or roundoff still leaves the best seen
    nlopt_destroy(opt);
    for (unsigned k = 0; k < n; ++k)
        *free[k].value = free[k].lo + o.best_x[k] * (free[k].hi - free[k].lo);
    return o.best;
}

}  // namespace fit
}  // namespace bokeh
