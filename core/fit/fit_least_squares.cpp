// fit_least_squares.cpp — the lens fit's last steps (fit/fit_stages.h): the weighted
// residuals by crop, Levenberg-Marquardt over them, and the parameters' uncertainties.

#include <bokeh/parallel.h>

#include "fit/fit_stages.h"

#include <algorithm>
#include <cmath>
#include <functional>

namespace bokeh {
namespace fit {

// Crop i's weighted residuals (empty when its PSF is refused).
std::vector<double> crop_residuals(const Model& model, const State& s, size_t i, bool coarse)
{
    std::vector<double> r;
    Psf p;
    if (!model.psf(p, s, i, coarse, 1))
        return r;
    std::vector<float> smp;
    model.sample_crop(smp, p, s, i);
    Linear lin;
    Model::fit_linear(model.crops()[i], smp, lin, &r);
    return r;
}

// Every crop's weighted residuals, a block a crop (the crops in parallel).
std::vector<std::vector<double>> residual_blocks(const Model& model, const State& s, bool coarse, int nthreads)
{
    std::vector<std::vector<double>> blocks(model.crops().size());
    parallel_for_chunks(0, int64_t(blocks.size()), 1, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i)
            blocks[size_t(i)] = crop_residuals(model, s, size_t(i), coarse);
    });
    return blocks;
}

std::vector<double> residuals(const Model& model, const State& s, bool coarse, int nthreads)
{
    std::vector<double> r;
    for (const std::vector<double>& b : residual_blocks(model, s, coarse, nthreads))
        r.insert(r.end(), b.begin(), b.end());
    return r;
}

namespace {

// A parameter of the least-squares steps: the k-th of a State, and the crop it moves alone
// (kEvery: it moves every crop).
constexpr size_t kEvery = size_t(-1);
using ParameterOf = std::function<double&(State&, size_t)>;
using CropOf      = std::function<size_t(size_t)>;

// The forward-difference Jacobian of the weighted residuals `r0` (crop i's block from
// offset[i]) in `p` parameters, steps max(step, step |v|); columns in parallel. A crop's
// own parameter renders that crop alone: the other blocks of its column are zero.
std::vector<std::vector<double>> jacobian(const Model& model, const State& s, size_t p, const ParameterOf& value,
                                          const CropOf& crop_of, double step, const std::vector<double>& r0,
                                          const std::vector<size_t>& offset, bool coarse, int nthreads)
{
    const size_t n = r0.size();
    std::vector<std::vector<double>> J(p, std::vector<double>(n, 0.0));
    parallel_for_chunks(0, int64_t(p), 1, nthreads, [&](int64_t kb, int64_t ke) {
        for (int64_t kk = kb; kk < ke; ++kk) {
            const size_t k = size_t(kk);
            State t        = s;
            double& v      = value(t, k);
            const double h = std::max(step, step * std::abs(v));
            v += h;
            const size_t crop = crop_of(k);
            if (crop == kEvery) {
                const std::vector<double> r1 = residuals(model, t, coarse, 1);
                for (size_t i = 0; i < n && i < r1.size(); ++i)
                    J[k][i] = (r1[i] - r0[i]) / h;
            } else {
                const std::vector<double> r1 = crop_residuals(model, t, crop, coarse);
                for (size_t i = 0; i < r1.size() && offset[crop] + i < offset[crop + 1]; ++i)
                    J[k][offset[crop] + i] = (r1[i] - r0[offset[crop] + i]) / h;
            }
        }
    });
    return J;
}

// The residuals of every crop one after another, and where each crop's block starts.
std::vector<double> stacked_residuals(const Model& model, const State& s, bool coarse, int nthreads,
                                      std::vector<size_t>& offset)
{
    const std::vector<std::vector<double>> blocks = residual_blocks(model, s, coarse, nthreads);
    offset.assign(blocks.size() + 1, 0);
    std::vector<double> r;
    for (size_t i = 0; i < blocks.size(); ++i) {
        offset[i + 1] = offset[i] + blocks[i].size();
        r.insert(r.end(), blocks[i].begin(), blocks[i].end());
    }
    return r;
}

// The rows of the residuals parameter k moves: a crop's own parameter its crop's block,
// a shared one all of them.
std::pair<size_t, size_t> rows_moved(size_t k, const CropOf& crop_of, const std::vector<size_t>& offset)
{
    const size_t crop = crop_of(k);
    return crop == kEvery ? std::pair<size_t, size_t>(0, offset.back())
                          : std::pair<size_t, size_t>(offset[crop], offset[crop + 1]);
}

// J^T J (p x p), each product summed over the rows both columns move: two crops' own
// parameters share none, so the eight-crop fit's 29 x 29 products skip seven eighths of
// the rows (the skipped terms are zeros: the same sums).
std::vector<double> normal_matrix(const std::vector<std::vector<double>>& J, const CropOf& crop_of,
                                  const std::vector<size_t>& offset)
{
    const size_t p = J.size();
    std::vector<double> jtj(p * p, 0.0);
    for (size_t a = 0; a < p; ++a) {
        const std::pair<size_t, size_t> ra = rows_moved(a, crop_of, offset);
        for (size_t b = a; b < p; ++b) {
            const std::pair<size_t, size_t> rb = rows_moved(b, crop_of, offset);
            double acc = 0.0;
            for (size_t i = std::max(ra.first, rb.first); i < std::min(ra.second, rb.second); ++i)
                acc += J[a][i] * J[b][i];
            jtj[a * p + b] = jtj[b * p + a] = acc;
        }
    }
    return jtj;
}

}  // namespace

// Levenberg-Marquardt on the weighted residuals [Marquardt, "An algorithm for least-squares
// estimation of nonlinear parameters", 1963]: `fields` (within `lo`..`hi`), every CoC and
// centre. BOBYQA's quadratic models stall in the narrow curved valley the CoC, the
// spherical aberration and the blades' curvature make together; steps along J^T J's
// own directions follow it. Forward-difference Jacobians; at most `iterations` steps.
void levenberg_marquardt(const Model& model, State& s, const std::vector<double State::*>& fields,
                         const std::vector<double>& lo, const std::vector<double>& hi, int iterations, int nthreads)
{
    const size_t nc = s.coc.size(), p = fields.size() + 3 * nc;
    const ParameterOf value = [&](State& st, size_t k) -> double& {
        if (k < fields.size())
            return st.*fields[k];
        k -= fields.size();
        return k < nc ? st.coc[k] : k < 2 * nc ? st.cx[k - nc] : st.cy[k - 2 * nc];
    };
    auto chi2 = [](const std::vector<double>& r) {
        double c = 0.0;
        for (double x : r)
            c += x * x;
        return c;
    };
    // A crop's own parameters (CoC, centre) move only its block of the residuals.
    const CropOf crop_of = [&](size_t k) { return k < fields.size() ? kEvery : (k - fields.size()) % nc; };
    std::vector<size_t> offset;
    std::vector<double> r0 = stacked_residuals(model, s, true, nthreads, offset);
    double c0 = chi2(r0), lambda = 1e-3;
    for (int it = 0; it < iterations; ++it) {
        const std::vector<std::vector<double>> J = jacobian(model, s, p, value, crop_of, 1e-4, r0, offset, true, nthreads);
        const std::vector<double> jtj = normal_matrix(J, crop_of, offset);
        std::vector<double> jtr(p, 0.0);
        for (size_t a = 0; a < p; ++a) {
            const std::pair<size_t, size_t> ra = rows_moved(a, crop_of, offset);
            for (size_t i = ra.first; i < ra.second; ++i)
                jtr[a] += J[a][i] * r0[i];
        }
        bool improved = false;
        for (int tries = 0; tries < 6 && !improved; ++tries) {
            std::vector<double> m = jtj, b(p), dx(p, 0.0);
            for (size_t a = 0; a < p; ++a) {
                m[a * p + a] += lambda * std::max(jtj[a * p + a], 1e-12);
                b[a] = -jtr[a];
            }
            if (!solve_linear(int(p), m.data(), b.data(), dx.data())) {
                lambda *= 10.0;
                continue;
            }
            State t = s;
            for (size_t k = 0; k < p; ++k) {
                double& v = value(t, k);
                v += dx[k];
                if (k < fields.size())
                    v = std::clamp(v, lo[k], hi[k]);
                else if (k < fields.size() + nc)
                    v = std::max(v, 0.5);
            }
            std::vector<double> r1 = residuals(model, t, true, nthreads);
            const double c1 = chi2(r1);
            if (r1.size() == r0.size() && c1 < c0) {
                s = t, r0 = std::move(r1);
                improved = c0 - c1 > 1e-6 * c0 || true;
                const bool small = c0 - c1 < 1e-5 * c0;
                c0 = c1;
                lambda = std::max(lambda / 3.0, 1e-7);
                if (small)
                    return;
            } else {
                lambda *= 4.0;
            }
        }
        if (!improved)
            return;
    }
}

// One-sigma uncertainties of `fields` (and every CoC) from s^2 (J^T J)^-1.
std::vector<double> uncertainties(const Model& model, const State& s, const std::vector<double State::*>& fields,
                                  std::vector<double>& coc_sigma, int nthreads)
{
    const size_t nc = s.coc.size(), p = fields.size() + nc;
    std::vector<size_t> offset;
    const std::vector<double> r0 = stacked_residuals(model, s, false, nthreads, offset);
    const size_t n               = r0.size();
    const ParameterOf value      = [&](State& t, size_t k) -> double& {
        return k < fields.size() ? t.*fields[k] : t.coc[k - fields.size()];
    };
    const CropOf crop_of = [&](size_t k) { return k < fields.size() ? kEvery : k - fields.size(); };
    const std::vector<std::vector<double>> J = jacobian(model, s, p, value, crop_of, 1e-3, r0, offset, false, nthreads);
    double chi2 = 0.0;
    for (double r : r0)
        chi2 += r * r;
    const double s2 = chi2 / std::max<double>(1.0, double(n) - double(p));
    const std::vector<double> a = normal_matrix(J, crop_of, offset);
    std::vector<double> sigma(p, 0.0);
    for (size_t c = 0; c < p; ++c) {  // column c of the inverse
        std::vector<double> m = a, b(p, 0.0), x(p, 0.0);
        b[c] = 1.0;
        if (solve_linear(int(p), m.data(), b.data(), x.data()))
            sigma[c] = std::sqrt(std::max(0.0, s2 * x[c]));
    }
    coc_sigma.assign(sigma.begin() + long(fields.size()), sigma.end());
    sigma.resize(fields.size());
    return sigma;
}

}  // namespace fit
}  // namespace bokeh
