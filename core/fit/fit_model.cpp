// fit_model.cpp — the model the lens fit minimises (fit/fit_model.h): reading a crop
// (what is left out, its background, noise and first estimates), rendering and sampling
// its PSF, the linear part solved exactly, the Cauchy cost, the noise model, and the
// bounded minimiser over NLopt.

#include <bokeh/base.h>
#include <bokeh/lens_fit.h>
#include <bokeh/parallel.h>

#include "fit/fit_model.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>

#include <nlopt.h>

#include <OpenImageIO/strutil.h>

namespace bokeh {
namespace fit {

using OIIO::Strutil::fmt::format;

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
// The noise model's floor, a fraction of the brightest crop's light level (CropData::
// level): the model's own precision (the PSF's 0.5 px radial bins, bilinear sub-pixel
// shifts, the fit's spectral step), so that a noise-free crop does not weigh a rounding
// difference as a feature.
constexpr double kModelFloorOfLevel = 1e-2;

double median_of(std::vector<double> v)
{
    if (v.empty())
        return 0.0;
    const size_t m = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + m, v.end());
    return v[m];
}



// The difference of pixel (i, j) (interior) from the mean of its four neighbours, of
// channel `ch` (-1: the luminance); false when any of the five is left out. Its variance
// is (1 + 1/4) sigma^2 where the signal is locally linear.
bool four_neighbour_difference(const CropData& d, int i, int j, int ch, double& r)
{
    const size_t k       = size_t(j) * d.w + i;
    const size_t nb[4]   = { k - 1, k + 1, k - size_t(d.w), k + size_t(d.w) };
    if (!d.use[k] || !d.use[nb[0]] || !d.use[nb[1]] || !d.use[nb[2]] || !d.use[nb[3]])
        return false;
    auto value = [&](size_t n) { return ch < 0 ? luminance(&d.px[n * d.channels], d.channels) : d.px[n * d.channels + ch]; };
    double mean = 0.0;
    for (size_t n : nb)
        mean += 0.25 * value(n);
    r = value(k) - mean;
    return true;
}

// Fit a plane to the crop's outermost two rows and columns per channel (least squares),
// and estimate the noise.
void border_background(const CropData& d, double plane[3][3], double& sigma, double& texture)
{
    // Least squares, reweighted three times (Cauchy at 3 MADs of the residuals) so that a
    // neighbour highlight across part of the border does not tilt the plane.
    auto border = [&](int i, int j) { return i < 2 || j < 2 || i >= d.w - 2 || j >= d.h - 2; };
    std::vector<size_t> ring;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i)
            if (border(i, j) && d.use[size_t(j) * d.w + i])
                ring.push_back(size_t(j) * d.w + i);
    for (int ch = 0; ch < 3; ++ch) {
        double x[3] = { 0, 0, 0 };
        std::vector<double> w(ring.size(), 1.0);
        for (int pass = 0; pass < 4 && ch < d.channels; ++pass) {
            double ata[9] = {}, atb[3] = {};
            for (size_t n = 0; n < ring.size(); ++n) {
                const int i = int(ring[n] % size_t(d.w)), j = int(ring[n] / size_t(d.w));
                const double col[3] = { 1.0, plane_x(d, i), plane_y(d, j) };
                for (int r = 0; r < 3; ++r) {
                    for (int c = 0; c < 3; ++c)
                        ata[r * 3 + c] += w[n] * col[r] * col[c];
                    atb[r] += w[n] * col[r] * d.px[ring[n] * d.channels + ch];
                }
            }
            if (!solve_linear(3, ata, atb, x))
                x[0] = x[1] = x[2] = 0.0;
            std::vector<double> res(ring.size());
            for (size_t n = 0; n < ring.size(); ++n) {
                const int i = int(ring[n] % size_t(d.w)), j = int(ring[n] / size_t(d.w));
                res[n] = d.px[ring[n] * d.channels + ch] - (x[0] + x[1] * plane_x(d, i) + x[2] * plane_y(d, j));
            }
            std::vector<double> a(res.size());
            for (size_t n = 0; n < res.size(); ++n)
                a[n] = std::abs(res[n]);
            const double scale = std::max(3.0 * 1.4826 * median_of(a), 1e-30);
            for (size_t n = 0; n < res.size(); ++n)
                w[n] = 1.0 / (1.0 + (res[n] / scale) * (res[n] / scale));
        }
        std::copy(x, x + 3, plane[ch]);
    }
    // The background's own texture: the luminance's MAD about the plane along the border,
    // as a normal's sigma (a textured wall behind the light is not noise, but no more a
    // highlight than noise is).
    std::vector<double> dev;
    for (size_t k : ring) {
        const int i = int(k % size_t(d.w)), j = int(k / size_t(d.w));
        float bg[3];
        for (int c = 0; c < 3; ++c)
            bg[c] = float(plane[c][0] + plane[c][1] * plane_x(d, i) + plane[c][2] * plane_y(d, j));
        dev.push_back(std::abs(luminance(&d.px[k * d.channels], d.channels) - luminance(bg, d.channels)));
    }
    texture = 1.4826 * median_of(dev);
    // The noise: the median of the luminance's four-neighbour differences over the crop
    // (the median passes over the rim, a neighbour and blocking), as a normal's sigma.
    std::vector<double> lap;
    for (int j = 1; j + 1 < d.h; ++j)
        for (int i = 1; i + 1 < d.w; ++i) {
            double r = 0.0;
            if (four_neighbour_difference(d, i, j, -1, r))
                lap.push_back(std::abs(r));
        }
    sigma = 1.4826 * median_of(lap) / std::sqrt(1.25);
}

// ---------------------------------------------------------------------------------------
// The model

}  // namespace

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

namespace {

// A crop's pixels as floats (its first three channels, or one), the non-finite ones left
// out; `vmax` its largest finite value. False + `err` for an unusable image.
bool read_crop(CropData& d, const OIIO::ImageBuf& img, const std::string& name, float& vmax, std::string& err)
{
    const OIIO::ImageSpec& spec = img.spec();
    if (img.has_error() || spec.nchannels < 1 || spec.deep)
        return err = format("{}: not a flat image with channels", name), false;
    d.w = spec.width, d.h = spec.height;
    if (d.w < 9 || d.h < 9)
        return err = format("{} is {}x{} px: too small to hold a bokeh (at least 9x9)", name, d.w, d.h), false;
    if (size_t(d.w) * d.h > size_t(4096) * 4096)
        return err = format("{} is {}x{} px: larger than a crop of one highlight needs (at most 4096x4096)",
                            name, d.w, d.h),
               false;
    d.channels = spec.nchannels >= 3 ? 3 : 1;
    d.px.resize(size_t(d.w) * d.h * d.channels);
    img.get_pixels(OIIO::ROI(spec.x, spec.x + d.w, spec.y, spec.y + d.h, spec.z, spec.z + 1, 0, d.channels),
                   OIIO::TypeDesc::FLOAT, d.px.data());
    d.use.assign(size_t(d.w) * d.h, 1);

    // Left out: non-finite pixels.
    vmax = -std::numeric_limits<float>::infinity();
    for (size_t k = 0; k < d.use.size(); ++k)
        for (int c = 0; c < d.channels; ++c) {
            const float v = d.px[k * d.channels + c];
            if (!std::isfinite(v))
                d.use[k] = 0;
            else
                vmax = std::max(vmax, v);
        }
    for (uint8_t u : d.use)
        d.nonfinite += !u;
    if (size_t(d.nonfinite) == d.use.size())
        return err = format("{} holds no finite pixel", name), false;

    return true;
}

// Label the 4-connected regions of the pixels `lit` says are lit; the largest's label
// (-1: none). `label` holds each pixel's region (-1: not lit).
int largest_region(const CropData& d, const std::function<bool(size_t)>& lit, std::vector<int>& label)
{
    label.assign(size_t(d.w) * d.h, -1);
    int best_label = -1;
    size_t best_size = 0;
    std::vector<size_t> stack;
    for (size_t start = 0; start < label.size(); ++start) {
        if (label[start] >= 0 || !lit(start))
            continue;
        const int id = int(start);
        size_t size  = 0;
        stack.assign(1, start);
        label[start] = id;
        while (!stack.empty()) {
            const size_t k = stack.back();
            stack.pop_back();
            ++size;
            const int i = int(k % size_t(d.w)), j = int(k / size_t(d.w));
            const size_t nb[4] = { i > 0 ? k - 1 : k, i + 1 < d.w ? k + 1 : k, j > 0 ? k - size_t(d.w) : k,
                                   j + 1 < d.h ? k + size_t(d.w) : k };
            for (size_t n : nb)
                if (label[n] < 0 && lit(n)) {
                    label[n] = id;
                    stack.push_back(n);
                }
        }
        if (size > best_size)
            best_size = size, best_label = id;
    }
    return best_label;
}

// Whether a crop was cut inside its bokeh: no highlight stands above the plane the border
// gave, but the border itself holds light (its brightest tenth 10 noise levels above its
// darkest, as where the bokeh's edge crosses it); or the plane is the bokeh's plateau
// itself, a twentieth of the crop (its outside) far below it, past the noise and the
// background's texture.
bool cut_inside_bokeh(const CropData& d, const std::vector<double>& sig, double peak, double noise, double texture)
{
    std::vector<double> ring;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            if ((i == 0 || j == 0 || i == d.w - 1 || j == d.h - 1) && d.use[k])
                ring.push_back(luminance(&d.px[k * d.channels], d.channels));
        }
    std::sort(ring.begin(), ring.end());
    const double spread = ring.empty() ? 0.0 : ring[ring.size() * 9 / 10] - ring[ring.size() / 10];
    int below = 0;
    for (size_t k = 0; k < sig.size(); ++k)
        below += d.use[k] && sig[k] < -std::max(10.0 * noise, 6.0 * texture);
    return (!(peak > 10.0 * noise) && spread > 10.0 * noise) || below > int(sig.size() / 20);
}

// The field position of the highlight's centre: given, else from the crop's data window
// in its display window (a crop cut from a frame with its origin kept).
void set_field_position(CropData& d, const LensFitCrop& crop)
{
    const OIIO::ImageSpec& spec = crop.image.spec();
    const bool windowed = spec.full_width > 0 && spec.full_height > 0
                          && (spec.full_x != spec.x || spec.full_y != spec.y || spec.full_width != spec.width
                              || spec.full_height != spec.height);
    if (std::isfinite(crop.field_x) && std::isfinite(crop.field_y)) {
        d.fx = crop.field_x, d.fy = crop.field_y, d.field_known = true;
    } else if (windowed) {
        const double half_diag = 0.5 * std::hypot(double(spec.full_width), double(spec.full_height));
        d.fx = (spec.x + d.cx0 - (spec.full_x + 0.5 * spec.full_width)) / half_diag;
        d.fy = -(spec.y + d.cy0 - (spec.full_y + 0.5 * spec.full_height)) / half_diag;
        d.field_known = true;
    }
}

}  // namespace

bool prepare_crop(CropData& d, const LensFitCrop& crop, size_t index, double clip_level, std::string& err)
{
    const std::string name = format("crop {}", index + 1);
    float vmax             = 0.0f;
    if (!read_crop(d, crop.image, name, vmax, err))
        return false;

    // The background plane and read noise from the border (before clipping is decided:
    // a highlight's plateau shares its maximum exactly only where the plate clipped it, or
    // where there is no noise at all, as in a render).
    double plane[3][3];
    double sigma = 0.0, texture = 0.0;
    border_background(d, plane, sigma, texture);
    double clip = clip_level;
    if (clip <= 0.0 && std::isfinite(vmax) && vmax > 0.0f && sigma > 1e-7 * vmax) {
        int at_max = 0;
        for (size_t k = 0; k < d.use.size(); ++k)
            for (int c = 0; c < d.channels && d.use[k]; ++c)
                at_max += d.px[k * d.channels + c] == vmax;
        if (at_max > 2)
            clip = vmax;
    }
    if (clip > 0.0)
        for (size_t k = 0; k < d.use.size(); ++k)
            for (int c = 0; c < d.channels && d.use[k]; ++c)
                if (d.px[k * d.channels + c] >= clip) {
                    d.use[k] = 0;
                    ++d.clipped;
                }

    // The highlight's moments.
    std::vector<double> sig(d.use.size(), 0.0);
    double peak = 0.0;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            float bg[3];
            for (int c = 0; c < 3; ++c)
                bg[c] = float(plane[c][0] + plane[c][1] * plane_x(d, i) + plane[c][2] * plane_y(d, j));
            sig[k] = luminance(&d.px[k * d.channels], d.channels) - luminance(bg, d.channels);
            if (d.use[k])
                peak = std::max(peak, sig[k]);
        }
    const double noise = std::max(sigma, 1e-6 * std::max(peak, 1e-30));
    int clipped_in_light = 0, light = 0;
    double clip_sig = 0.0;
    for (size_t k = 0; k < sig.size(); ++k)
        if (!d.use[k] && d.nonfinite == 0 && sig[k] > 0.0)
            clip_sig = std::max(clip_sig, sig[k]);
    // The highlight: above a tenth of its peak (on a plate, the glow of other lights and
    // the background's large-scale shading reach past a few percent; a bright-centred
    // bokeh's halo below a tenth is then left to the stages, whose CoC may go to 3 times
    // this first estimate), 6 noise levels and 4 of the background's texture.
    const double level = std::max({ 0.1 * std::max(peak, clip_sig), 6.0 * noise, 4.0 * texture });
    // The highlight is the largest 4-connected region above the level; the others (a
    // neighbour across the crop's edge) are left out of the fit.
    std::vector<int> label;
    const int best_label = largest_region(
        d, [&](size_t k) { return sig[k] > level || (!d.use[k] && std::isfinite(sig[k]) && d.clipped > 0); }, label);
    for (size_t k = 0; k < sig.size(); ++k)
        if (label[k] >= 0 && label[k] != best_label && d.use[k]) {
            d.use[k] = 0;
            ++d.others;
        }
    double m0 = 0, mx = 0, my = 0;
    int touches[4] = { 0, 0, 0, 0 };
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            const bool clipped = !d.use[k] && std::isfinite(sig[k]) && d.clipped > 0;
            if (label[k] != best_label || label[k] < 0)
                continue;
            ++light;
            clipped_in_light += clipped;
            const double wgt = clipped ? std::max(peak, clip_sig) : sig[k];
            m0 += wgt, mx += wgt * (i + 0.5), my += wgt * (j + 0.5);
            touches[0] += i == 0, touches[1] += i == d.w - 1, touches[2] += j == 0, touches[3] += j == d.h - 1;
        }
    if (cut_inside_bokeh(d, sig, peak, noise, texture))
        return err = format("{} ({}x{} px) is smaller than its bokeh: light crosses its border; cut it wider "
                            "than the bokeh",
                            name, d.w, d.h),
               false;
    if (peak > 10.0 * noise && m0 <= 0.0)  // light, but none above the border's own spread
        return err = format("{} ({}x{} px) is smaller than its bokeh: its border holds light as bright as "
                            "its inside; cut it wider than the bokeh",
                            name, d.w, d.h),
               false;
    if (!(peak > 10.0 * noise) || m0 <= 0.0)
        return err = format("{} holds no highlight: its brightest pixel stands {:.1f} noise levels above the "
                            "background (a highlight needs 10)",
                            name, noise > 0 ? std::max(peak, 0.0) / noise : 0.0),
               false;
    if (light > 0 && clipped_in_light > 0.95 * light)
        return err = format("{} is clipped over {:.0f} % of its highlight: too little of the bokeh's profile "
                            "is left to fit",
                            name, 100.0 * clipped_in_light / light),
               false;
    d.cx0 = mx / m0, d.cy0 = my / m0;
    // Size from the second moment about the centre: a uniform disk of diameter D has
    // E[r^2] = D^2 / 8.
    double m2 = 0, ms = 0;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            if (label[k] != best_label || label[k] < 0)
                continue;
            const double dx = i + 0.5 - d.cx0, dy = j + 0.5 - d.cy0;
            m2 += dx * dx + dy * dy;
            ms += 1.0;
        }
    d.coc0 = std::max(2.0, std::sqrt(8.0 * m2 / std::max(ms, 1.0)));
    const int sides = (touches[0] > 0) + (touches[1] > 0) + (touches[2] > 0) + (touches[3] > 0);
    if (sides >= 3 || d.coc0 > 1.05 * std::min(d.w, d.h))
        return err = format("{} ({}x{} px) is smaller than its bokeh (about {:.0f} px across): cut it at least "
                            "{:.0f} px wide",
                            name, d.w, d.h, d.coc0, d.coc0 + 8.0),
               false;
    d.peak = std::max(peak, clip_sig);
    // The light's level: its plateau, the 90th percentile over the highlight (clipped
    // pixels at the peak), the scale the noise floors are set in (a bright-centred
    // bokeh's peak can be many times its plateau; the percentile does not lean on the
    // first CoC's estimate, nor on how much of a plate's glow the highlight's region took).
    std::vector<double> lit_values;
    for (size_t k = 0; k < sig.size(); ++k)
        if (label[k] == best_label && best_label >= 0)
            lit_values.push_back(d.use[k] ? sig[k] : d.peak);
    std::sort(lit_values.begin(), lit_values.end());
    d.level = lit_values.empty() ? d.peak : std::min(d.peak, lit_values[lit_values.size() * 9 / 10]);

    set_field_position(d, crop);
    if (std::hypot(d.fx, d.fy) > 1.5)
        return err = format("{}: field position ({:g}, {:g}) is outside the frame (half-diagonals)", name, d.fx,
                            d.fy),
               false;
    d.inv_var.assign(d.px.size(), float(1.0 / (noise * noise)));  // estimate_noise sets the model
    prepare_fit_arrays(d);
    return true;
}

// The noise model from the data alone (a model's misfit must not pass for noise): each
// interior pixel's difference from the mean of its four neighbours, r = v - (n + s + e +
// w) / 4, has variance (1 + 1/4) sigma^2 where the signal is locally linear.
void estimate_noise(std::vector<CropData>& crops, double& read2, double& photon)
{
    struct Point {
        double v, r2;
    };
    std::vector<Point> pts;
    double peak = 0.0;
    for (const CropData& d : crops) {
        peak = std::max(peak, d.level);
        for (int ch = 0; ch < d.channels; ++ch)
            for (int j = 1; j + 1 < d.h; ++j)
                for (int i = 1; i + 1 < d.w; ++i) {
                    double r = 0.0;
                    if (four_neighbour_difference(d, i, j, ch, r))
                        pts.push_back({ d.px[(size_t(j) * d.w + i) * d.channels + ch], r * r / 1.25 });
                }
    }
    // In 16 bins of equal count by value: the median of r^2 / 0.4549 (the median of a
    // chi-square of one degree), robust to the few pixels of structure (a bright centre, the
    // rim) a bin holds; then least squares of those on the bins' mean values.
    std::sort(pts.begin(), pts.end(), [](const Point& x, const Point& y) { return x.v < y.v; });
    constexpr int kBins = 16;
    double s11 = 0, s1m = 0, smm = 0, s1r = 0, smr = 0;
    for (int bin = 0; bin < kBins && pts.size() >= size_t(4 * kBins); ++bin) {
        const size_t lo = pts.size() * size_t(bin) / kBins, hi = pts.size() * size_t(bin + 1) / kBins;
        std::vector<double> r2;
        double mv = 0.0;
        for (size_t k = lo; k < hi; ++k) {
            r2.push_back(pts[k].r2);
            mv += std::max(pts[k].v, 0.0) / double(hi - lo);
        }
        const double var = median_of(r2) / 0.4549;
        s11 += 1, s1m += mv, smm += mv * mv, s1r += var, smr += mv * var;
    }
    double a = s1r / std::max(s11, 1.0), b = 0.0;
    const double det = s11 * smm - s1m * s1m;
    if (det > 1e-12 * s11 * smm) {
        const double a2 = (smm * s1r - s1m * smr) / det, b2 = (s11 * smr - s1m * s1r) / det;
        if (b2 >= 0.0 && a2 >= 0.0)
            a = a2, b = b2;
        else if (b2 >= 0.0)
            a = 0.0, b = smr / std::max(smm, 1e-300);
    }
    read2  = std::max(a, kModelFloorOfLevel * kModelFloorOfLevel * peak * peak);
    photon = b;
    set_noise(crops, read2, photon);
}

void set_noise(std::vector<CropData>& crops, double read2, double photon)
{
    for (CropData& d : crops) {
        for (size_t k = 0; k < d.inv_var.size(); ++k) {
            const double v = d.px[k];
            d.inv_var[k]   = std::isfinite(v) ? float(1.0 / (read2 + photon * std::max(v, 0.0))) : 0.0f;
        }
        d.cached_floor2 = -1.0;
    }
}

void residual_noise(const std::vector<CropData>& crops, const Model& model, const State& s, double& read2,
                    double& photon)
{
    double s11 = 0, s1m = 0, smm = 0, s1r = 0, smr = 0, peak = 0;
    for (size_t i = 0; i < crops.size(); ++i) {
        const CropData& d = crops[i];
        peak = std::max(peak, d.level);
        Psf p;
        if (!model.psf(p, s, i, true, 0))
            continue;
        std::vector<float> smp;
        Model::sample(smp, p, d, s.cx[i], s.cy[i]);
        Linear lin;
        Model::fit_linear(d, smp, lin);
        const size_t m = d.fit_k.size(), npix = size_t(d.w) * d.h;
        for (int ch = 0; ch < d.channels; ++ch)
            for (size_t n = 0; n < m; ++n) {
                const double mod = lin.a[ch] * smp[size_t(ch) * npix + d.fit_k[n]] + lin.b0[ch]
                                   + lin.bx[ch] * d.fit_x[n] + lin.by[ch] * d.fit_y[n];
                const double r  = d.fit_v[size_t(ch) * m + n] - mod;
                const double iv = d.inv_var[size_t(d.fit_k[n]) * d.channels + ch];
                if (r * r * iv > 25.0)  // past 5 sigma of the current model: not noise
                    continue;
                const double mm = std::max(mod, 0.0);
                s11 += 1, s1m += mm, smm += mm * mm, s1r += r * r, smr += mm * r * r;
            }
    }
    const double det = s11 * smm - s1m * s1m;
    double a = s1r / std::max(s11, 1.0), b = 0.0;
    if (det > 1e-12 * s11 * smm) {
        const double a2 = (smm * s1r - s1m * smr) / det, b2 = (s11 * smr - s1m * s1r) / det;
        if (a2 >= 0.0 && b2 >= 0.0)
            a = a2, b = b2;
    }
    read2  = std::max(a, kModelFloorOfLevel * kModelFloorOfLevel * peak * peak);
    photon = b;
}

}  // namespace fit
}  // namespace bokeh
