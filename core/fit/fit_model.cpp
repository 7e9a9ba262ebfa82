// fit_model.cpp — the model the lens fit minimises (fit/fit_model.h): rendering and
// sampling a crop's PSF, the linear part solved exactly, the Cauchy cost, and the bounded
// minimiser over NLopt. The crops it reads and the noise model: fit_crop.cpp.

#include <bokeh/base.h>
#include <bokeh/lens_fit.h>
#include <bokeh/parallel.h>

#include "fit/fit_model.h"

#include <algorithm>
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
    l.correction    = 0.0;
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

void Model::sample(std::vector<float>& dst, const Psf& p, const CropData& d, double cx, double cy)
{
    dst.assign(size_t(d.w) * d.h * 3, 0.0f);
    const double hw = 0.5 * (p.width - 1), hh = 0.5 * (p.height - 1);
    for (int j = 0; j < d.h; ++j) {
        const double y = hh + (j + 0.5 - cy);
        const int y0   = int(std::floor(y));
        const double fy = y - y0;
        for (int i = 0; i < d.w; ++i) {
            const double x = hw + (i + 0.5 - cx);
            const int x0   = int(std::floor(x));
            const double fx = x - x0;
            // The four taps' weights and places, once for the three channels.
            double w[4];
            const float* tap[4];
            int taps = 0;
            for (int dy = 0; dy < 2; ++dy)
                for (int dx = 0; dx < 2; ++dx) {
                    const int xx = x0 + dx, yy = y0 + dy;
                    if (xx < 0 || yy < 0 || xx >= p.width || yy >= p.height)
                        continue;
                    w[taps]     = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
                    tap[taps++] = &p.rgb[(size_t(yy) * p.width + xx) * 3];
                }
            for (int c = 0; c < 3; ++c) {
                double v = 0.0;
                for (int t = 0; t < taps; ++t)
                    v += w[t] * tap[t][c];
                dst[(size_t(c) * d.h + j) * d.w + i] = float(v);
            }
        }
    }
}

void prepare_fit_arrays(CropData& d)
{
    d.fit_k.clear(), d.fit_x.clear(), d.fit_y.clear();
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i)
            if (d.use[size_t(j) * d.w + i]) {
                d.fit_k.push_back(uint32_t(size_t(j) * d.w + i));
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

}  // namespace

double Model::fit_linear(const CropData& d, const std::vector<float>& s, Linear& lin,
                         std::vector<double>* residuals, int* outliers, double floor_of_level)
{
    const double floor2 = floor_of_level * floor_of_level * d.level * d.level;
    ensure_weights(d, floor2);
    const size_t m = d.fit_k.size(), npix = size_t(d.w) * d.h;
    constexpr double inv_c2 = 1.0 / (kCauchyScale * kCauchyScale);
    std::vector<double> p(m);
    double cost = 0.0;
    for (int ch = 0; ch < d.channels; ++ch) {
        const float* v  = &d.fit_v[size_t(ch) * m];
        const float* iv = &d.fit_iv[size_t(ch) * m];
        const float* sp = &s[size_t(ch) * npix];
        // Pass 1: inverse-variance weights (the plane's sums precomputed).
        double pp = 0, p1 = 0, px = 0, py = 0, pv = 0;
        for (size_t n = 0; n < m; ++n) {
            p[n]            = sp[d.fit_k[n]];
            const double wp = iv[n] * p[n];
            pp += wp * p[n], p1 += wp, px += wp * d.fit_x[n], py += wp * d.fit_y[n], pv += wp * v[n];
        }
        double x[4];
        solve_normal(d.base[ch], pp, p1, px, py, pv, x);
        // Pass 2: the Cauchy weights of pass 1's residuals.
        double b[9] = {};
        pp = p1 = px = py = pv = 0;
        for (size_t n = 0; n < m; ++n) {
            const double xx = d.fit_x[n], yy = d.fit_y[n];
            const double r  = v[n] - (x[0] * p[n] + x[1] + x[2] * xx + x[3] * yy);
            const double w  = iv[n] / (1.0 + r * r * iv[n] * inv_c2);
            const double wp = w * p[n];
            pp += wp * p[n], p1 += wp, px += wp * xx, py += wp * yy, pv += wp * v[n];
            b[0] += w, b[1] += w * xx, b[2] += w * yy, b[3] += w * xx * xx, b[4] += w * xx * yy, b[5] += w * yy * yy;
            b[6] += w * v[n], b[7] += w * xx * v[n], b[8] += w * yy * v[n];
        }
        solve_normal(b, pp, p1, px, py, pv, x);
        lin.a[ch] = x[0], lin.b0[ch] = x[1], lin.bx[ch] = x[2], lin.by[ch] = x[3];
        // The cost: the Cauchy loss of pass 2's residuals.
        for (size_t n = 0; n < m; ++n) {
            const double r  = v[n] - (x[0] * p[n] + x[1] + x[2] * d.fit_x[n] + x[3] * d.fit_y[n]);
            const double u2 = r * r * iv[n] * inv_c2;
            cost += 0.5 * kCauchyScale * kCauchyScale * std::log1p(u2);
            if (residuals)
                residuals->push_back(r * std::sqrt(iv[n] / (1.0 + u2)));
            if (outliers && u2 > 1.0 && ch == 0)
                ++*outliers;
        }
    }
    return cost;
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
        sample(smp, p, m_crops[i], s.cx[i], s.cy[i]);
        Linear lin;
        costs[n] = fit_linear(m_crops[i], smp, lin, nullptr, nullptr, m_floor);
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
