// lens_fit.cpp — fit optics.h's lens model to crops of photographed bokeh (lens_fit.h has
// the model; docs/methods/lens-fit.md the method, its checks and its limits; the model's
// pieces are fit/fit_model.cpp's).
//
// The stages, coarse to fine; each one's parameters start from the best of a small grid
// of values, then BOBYQA [Powell, "The BOBYQA algorithm for bound constrained
// optimization without derivatives", 2009; NLopt's LN_BOBYQA] polishes them with every
// crop's CoC free:
//   1. size and place: each crop's CoC and centre under a round, aberration-free lens,
//      from the highlight's moments (the noise model is estimated from the pixels first);
//   2. aperture: blades 5..9 against round (rotation from a grid over one blade period);
//   3. hole; 4. spherical aberration (monochromatic, signed); 5. axial colour (chromatic,
//      signed; RGB crops only); 6. onion-ring contrast; 7. cat's eye and astigmatism
//      (crops off the axis only); 8. everything kept, together, then each crop's centre.
// A stage is kept when it lowers the cost (a negative log-likelihood under the Cauchy
// loss) by more than the Bayesian information criterion's price, k ln(N) / 2 for k
// parameters over N residuals [Schwarz, "Estimating the dimension of a model", 1978].
// The uncertainty of a fitted parameter is the square root of the diagonal of
// s^2 (J^T J)^-1 at the optimum (J the Jacobian of the weighted residuals by forward
// differences, s^2 their reduced chi-square).
//
// Known limits: a crop's sub-pixel centre moves the PSF by bilinear interpolation (a blur
// of at most half a pixel at the rim); one crop cannot tell a front bokeh from a back
// one with the aberrations' signs reversed (LensFitOptions::front says which); spherical
// aberration is fitted as third order (correction 0) on the `uncorrected` design, axial
// colour as that design's BK7 dispersion scaled (an achromat's secondary spectrum is
// approximated by it); diffraction, the onion rings' frequency and surface noise are not
// fitted (left at the camera's values).

#include <bokeh/base.h>
#include <bokeh/lens_fit.h>
#include <bokeh/parallel.h>

#include "fit/fit_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;
using namespace fit;

namespace {

// The noise floor a stage searches under (graduated non-convexity: fit_model.h), a
// fraction of each crop's light level.
constexpr double kSearchFloorOfLevel = 0.02;

// BIC's price of a parameter, k ln(N) / 2, times this: the PSF's 0.5 px radial bins make
// the cost rough at the 0.1 %-of-light level, and at the plain price the round trips of
// tests/fit/lens_fit_test.cpp (which print each stage's costs) kept holes and onion rings
// their crops do not have. At 4 they keep fewer; not none (a 9-blade aperture of
// curvature 0.74 on a round front bokeh with spherical aberration).
constexpr double kPriceFactor = 4.0;

// A CoC's bounds about its first estimate from the highlight's moments: spherical
// aberration moves the rim by up to the CoC itself before rays cross (a bright centre
// reads as a small highlight, a bright rim as a large one).
constexpr double kCocLow = 0.25, kCocHigh = 3.0;

// The crops a stage searches on (the rest join the final polish): 8 crops of 96 px took
// 2.6 times as long as 3 with all of them searched.
constexpr size_t kSearchCrops = 3;

// A stage's shared parameter: where it lives in the State, its bounds, grid of starts.
struct StageParam {
    const char* name;
    double State::*field;
    double lo, hi, step;
    std::vector<double> starts;
};

class Fitter {
public:
    Fitter(std::vector<CropData>& crops, const LensFitOptions& opts, int nthreads)
        : m_crops(crops), m_opts(opts), m_model(crops, opts, nthreads)
    {
        for (const CropData& d : crops) {
            m_s.coc.push_back(d.coc0);
            m_s.cx.push_back(d.cx0);
            m_s.cy.push_back(d.cy0);
        }
        use_all_crops();
    }
    void count_residuals()
    {
        m_residuals = 0.0;
        for (size_t i : m_active)
            m_residuals += double(m_crops[i].channels)
                           * double(std::count(m_crops[i].use.begin(), m_crops[i].use.end(), uint8_t(1)));
    }

    State& state() { return m_s; }
    const Model& model() const { return m_model; }
    std::vector<std::string>& log() { return m_log; }
    double price(int k) const { return kPriceFactor * 0.5 * k * std::log(std::max(m_residuals, 2.0)); }
    int left() const { return std::max(0, m_opts.max_evaluations - m_model.evaluations()); }
    double cost() const { return m_model.cost(m_s, true, m_active); }

    // The stages search on the crops that show the most (a large, bright bokeh above its
    // noise): at most kSearchCrops of them; the final polish takes them all.
    void choose_search_crops(double read2, double photon)
    {
        std::vector<std::pair<double, size_t>> score;
        for (size_t i = 0; i < m_crops.size(); ++i) {
            const CropData& d = m_crops[i];
            score.push_back({ -d.level / std::sqrt(read2 + photon * d.level) * m_s.coc[i], i });
        }
        std::sort(score.begin(), score.end());
        m_active.clear();
        for (size_t k = 0; k < std::min<size_t>(kSearchCrops, score.size()); ++k)
            m_active.push_back(score[k].second);
        std::sort(m_active.begin(), m_active.end());
        count_residuals();
    }
    void use_all_crops()
    {
        m_active.resize(m_crops.size());
        for (size_t i = 0; i < m_crops.size(); ++i)
            m_active[i] = i;
        count_residuals();
    }
    size_t searched() const { return m_active.size(); }

    // Each crop's CoC and centre, the lens held.
    // `search`: first under the search floor; `scan`: each CoC first from a scan.
    double refine_crops(int evaluations_each, bool search = false, bool scan = false)
    {
        if (search) {
            m_model.set_floor(kSearchFloorOfLevel);
            refine_crops(evaluations_each, false, scan);
            m_model.set_floor(0.0);
        }
        double total = 0.0;
        for (size_t i = 0; i < m_crops.size(); ++i) {
            const double c0 = m_crops[i].coc0;
            std::vector<Free> f = { { &m_s.coc[i], kCocLow * c0, kCocHigh * c0 + 4.0, 0.05 * c0 + 0.2 },
                                    { &m_s.cx[i], m_s.cx[i] - 3.0, m_s.cx[i] + 3.0, 0.5 },
                                    { &m_s.cy[i], m_s.cy[i] - 3.0, m_s.cy[i] + 3.0, 0.5 } };
            if (scan) {  // a crop the stages did not see: its CoC from a scan under the lens found
                double best = 1e300, best_coc = m_s.coc[i];
                for (double k = kCocLow; k <= 1.5; k += 0.1) {
                    m_s.coc[i]     = k * c0;
                    const double c = m_model.cost(m_s, true, { i });
                    if (c < best)
                        best = c, best_coc = m_s.coc[i];
                }
                m_s.coc[i] = best_coc;
            }
            total += minimise(f, [&] { return m_model.cost(m_s, true, { i }); },
                              std::min(evaluations_each, std::max(10, left())));
        }
        return total;
    }

    // Free the shared `params` (from their current values), those kept by earlier stages
    // and every CoC; the best cost.
    double polish(const std::vector<StageParam>& params, int evaluations)
    {
        std::vector<Free> f;
        for (const StageParam& p : params)
            f.push_back({ &(m_s.*p.field), p.lo, p.hi, p.step });
        for (const StageParam& p : m_kept)
            f.push_back({ &(m_s.*p.field), std::min(p.lo, m_s.*p.field), std::max(p.hi, m_s.*p.field), p.step });
        for (size_t i : m_active) {
            const double c0 = m_crops[i].coc0;
            f.push_back({ &m_s.coc[i], kCocLow * c0, kCocHigh * c0 + 4.0, 0.03 * c0 + 0.2 });
        }
        add_centres(f);
        const int n = int(f.size());
        return minimise(f, [&] { return cost(); }, std::min(evaluations + 12 * n, std::max(10, left())));
    }

    // A stage: the cost with what is kept polished; the best grid start (each parameter's
    // starts tried in turn, the others at their best); the polish; kept when the cost
    // falls by more than the parameters' price.
    bool stage(const char* name, const std::vector<StageParam>& params)
    {
        const double c0    = polish({}, 20);
        const State before = m_s;
        m_model.set_floor(kSearchFloorOfLevel);
        for (const StageParam& p : params) {
            double best = c0, best_v = m_s.*p.field;  // the current value is a start too
            State best_state = m_s;
            for (double v : p.starts) {
                m_s            = before;
                m_s.*p.field   = v;
                // An aberration moves the rim: each start with its CoCs refitted.
                const double c = polish_cocs(m_free_centres ? 30 : 6);
                if (c < best)
                    best = c, best_v = v, best_state = m_s;
            }
            m_s          = best_state;
            m_s.*p.field = best_v;
        }
        polish(params, 40);
        m_model.set_floor(0.0);
        const double c1   = polish(params, 30);
        const int k       = int(params.size());
        // A parameter left at its "none" value (0) buys nothing, whatever the CoCs' polish
        // gained beside it.
        const bool moved = std::any_of(params.begin(), params.end(), [&](const StageParam& p) {
            return std::abs(m_s.*p.field) > 1e-3 * (p.hi - p.lo);
        });
        const bool keep   = moved && c0 - c1 > price(k);
        m_log.push_back(format("{}: cost {:.1f} -> {:.1f} (price of {} parameter{} {:.1f}): {}", name, c0, c1, k,
                               k == 1 ? "" : "s", price(k), keep ? "kept" : "not shown by the crops"));
        if (!keep)
            m_s = before;
        else
            m_kept.insert(m_kept.end(), params.begin(), params.end());
        return keep;
    }

    const std::vector<StageParam>& kept() const { return m_kept; }

    // A kept parameter searched again from its grid with everything kept since (the
    // spherical aberration found before the axial colour took a rim's colour for its
    // profile); the better of the two states is kept.
    void revisit(const char* name, const StageParam& p)
    {
        const double c0    = polish({}, 20);
        const State before = m_s;
        m_model.set_floor(kSearchFloorOfLevel);
        double best = 1e300;
        State best_state = m_s;
        for (double v : p.starts) {
            m_s          = before;
            m_s.*p.field = v;
            const double c = polish_cocs(6);
            if (c < best)
                best = c, best_state = m_s;
        }
        m_s = best_state;
        polish({}, 40);
        m_model.set_floor(0.0);
        const double c1 = polish({}, 30);
        m_log.push_back(format("{} again: cost {:.1f} -> {:.1f}: {}", name, c0, c1, c1 < c0 ? "taken" : "not taken"));
        if (!(c1 < c0))
            m_s = before;
    }

    // The crops' centres, free while a field effect is fitted (a cut pupil's light is
    // not centred where a round one's is), within 4 px of the crop's first estimate.
    void add_centres(std::vector<Free>& f)
    {
        if (!m_free_centres)
            return;
        for (size_t i : m_active) {
            f.push_back({ &m_s.cx[i], m_crops[i].cx0 - 4.0, m_crops[i].cx0 + 4.0, 0.3 });
            f.push_back({ &m_s.cy[i], m_crops[i].cy0 - 4.0, m_crops[i].cy0 + 4.0, 0.3 });
        }
    }
    void free_centres(bool on) { m_free_centres = on; }

    // Only the CoCs free, a few evaluations a crop; the best cost.
    double polish_cocs(int evaluations_each)
    {
        std::vector<Free> f;
        for (size_t i : m_active) {
            const double c0 = m_crops[i].coc0;
            f.push_back({ &m_s.coc[i], kCocLow * c0, kCocHigh * c0 + 4.0, 0.05 * c0 + 0.2 });
        }
        add_centres(f);
        return minimise(f, [&] { return cost(); },
                        std::min(evaluations_each * int(f.size()) + 4, std::max(10, left())));
    }

    // The aperture: each blade count's best rotation on a grid, briefly polished; the best
    // counts polished fully, the best kept against round.
    bool aperture_stage()
    {
        const double c0    = polish({}, 20);
        const State before = m_s;
        m_model.set_floor(kSearchFloorOfLevel);
        struct Try {
            int blades;
            double rotation, grid_cost, cost;
            State state;  // after the short polish
        };
        std::vector<Try> tries;
        for (int n = 5; n <= 9; ++n) {
            const double period = 360.0 / n;
            Try best { n, 0.0, 1e300, 1e300, before };
            m_s = before;
            // The CoC is the polygon's circumscribed diameter: start each at the area of
            // the round fit, (n / 2) R^2 sin(2 pi / n) = pi r^2.
            const double grow = std::sqrt(kPi / (0.5 * n * std::sin(2.0 * kPi / n)));
            for (double& c : m_s.coc)
                c *= grow;
            for (int k = 0; k < 8; ++k) {
                m_s.blades    = n;
                m_s.rotation  = period * k / 8.0;
                m_s.curvature = 0.15;
                const double c = cost();
                if (c < best.grid_cost)
                    best.grid_cost = c, best.rotation = m_s.rotation;
            }
            // A short polish: a grid point's cost says little while the spherical
            // aberration and the CoC were fitted to a round stop.
            m_s.rotation  = best.rotation;
            m_s.curvature = 0.15;
            const std::vector<StageParam> p = {
                { "rotation", &State::rotation, best.rotation - 0.5 * period, best.rotation + 0.5 * period,
                  period / 12.0, {} },
                { "curvature", &State::curvature, 0.0, 1.0, 0.1, {} },
            };
            best.cost  = polish(p, 10);
            best.state = m_s;
            tries.push_back(best);
        }
        // Polished fully: the two best by the grid and the two best after the short
        // polish (each ranking alone missed blade counts on the round trips).
        std::vector<size_t> by_grid(tries.size()), by_cost(tries.size()), chosen;
        std::iota(by_grid.begin(), by_grid.end(), size_t(0));
        by_cost = by_grid;
        std::sort(by_grid.begin(), by_grid.end(), [&](size_t a, size_t b) { return tries[a].grid_cost < tries[b].grid_cost; });
        std::sort(by_cost.begin(), by_cost.end(), [&](size_t a, size_t b) { return tries[a].cost < tries[b].cost; });
        for (size_t k = 0; k < 2; ++k)
            for (size_t t : { by_cost[k], by_grid[k] })
                if (std::find(chosen.begin(), chosen.end(), t) == chosen.end())
                    chosen.push_back(t);
        State best_state = before;
        double best_cost = 1e300;
        for (size_t t : chosen) {
            m_s                 = tries[t].state;
            const double period = 360.0 / m_s.blades;
            const std::vector<StageParam> p = {
                { "rotation", &State::rotation, m_s.rotation - 0.5 * period, m_s.rotation + 0.5 * period,
                  period / 12.0, {} },
                { "curvature", &State::curvature, 0.0, 1.0, 0.1, {} },
            };
            polish(p, 60);
            m_model.set_floor(0.0);
            const double c = polish(p, 30);
            m_model.set_floor(kSearchFloorOfLevel);
            if (c < best_cost)
                best_cost = c, best_state = m_s;
        }
        m_model.set_floor(0.0);
        const bool keep = c0 - best_cost > price(3);
        m_log.push_back(format("aperture: round {:.1f}, {} blades {:.1f} (price {:.1f}): {}", c0, best_state.blades,
                               best_cost, price(3), keep ? format("{} blades kept", best_state.blades) : "round kept"));
        m_s = keep ? best_state : before;
        if (keep) {
            const double period = 360.0 / m_s.blades;
            m_s.rotation        = std::fmod(std::fmod(m_s.rotation, period) + period, period);
            m_kept.push_back({ "rotation", &State::rotation, m_s.rotation - 0.25 * period,
                               m_s.rotation + 0.25 * period, period / 24.0, {} });
            m_kept.push_back({ "curvature", &State::curvature, 0.0, 1.0, 0.05, {} });
        }
        return keep;
    }

private:
    std::vector<CropData>& m_crops;
    const LensFitOptions& m_opts;
    Model m_model;
    State m_s;
    double m_residuals = 0.0;
    std::vector<std::string> m_log;
    std::vector<StageParam> m_kept;  // continuous shared parameters of the stages kept
    bool m_free_centres = false;
    std::vector<size_t> m_active;  // the crops the cost sums
};

// The weighted residuals of every crop (fine spectrum), for the Jacobian.
// Crop i's weighted residuals (empty when its PSF is refused).
std::vector<double> crop_residuals(const Model& model, const State& s, size_t i, bool coarse)
{
    std::vector<double> r;
    Psf p;
    if (!model.psf(p, s, i, coarse, 1))
        return r;
    std::vector<float> smp;
    Model::sample(smp, p, model.crops()[i], s.cx[i], s.cy[i]);
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

std::vector<double> residuals(const Model& model, const State& s, bool coarse = false, int nthreads = 0)
{
    std::vector<double> r;
    for (const std::vector<double>& b : residual_blocks(model, s, coarse, nthreads))
        r.insert(r.end(), b.begin(), b.end());
    return r;
}

// Levenberg-Marquardt on the weighted residuals [Marquardt, "An algorithm for least-squares
// estimation of nonlinear parameters", 1963]: `fields` (within `lo`..`hi`), every CoC and
// centre. BOBYQA's quadratic models stall in the narrow curved valley the CoC, the
// spherical aberration and the blades' curvature make together; steps along J^T J's
// own directions follow it. Forward-difference Jacobians; at most `iterations` steps.
void levenberg_marquardt(const Model& model, State& s, const std::vector<double State::*>& fields,
                         const std::vector<double>& lo, const std::vector<double>& hi, int iterations, int nthreads)
{
    const size_t nc = s.coc.size(), p = fields.size() + 3 * nc;
    auto value = [&](State& st, size_t k) -> double& {
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
    // A crop's own parameters (CoC, centre) move only its block of the residuals: their
    // Jacobian columns render that crop alone.
    std::vector<std::vector<double>> blocks = residual_blocks(model, s, true, nthreads);
    std::vector<size_t> offset(nc + 1, 0);
    for (size_t i = 0; i < nc; ++i)
        offset[i + 1] = offset[i] + blocks[i].size();
    std::vector<double> r0;
    for (const std::vector<double>& b : blocks)
        r0.insert(r0.end(), b.begin(), b.end());
    double c0 = chi2(r0), lambda = 1e-3;
    for (int it = 0; it < iterations; ++it) {
        const size_t n = r0.size();
        std::vector<std::vector<double>> J(p, std::vector<double>(n, 0.0));
        parallel_for_chunks(0, int64_t(p), 1, nthreads, [&](int64_t kb, int64_t ke) {
            for (int64_t kk = kb; kk < ke; ++kk) {
                const size_t k = size_t(kk);
                State t        = s;
                double& v      = value(t, k);
                const double h = std::max(1e-4, 1e-4 * std::abs(v));
                v += h;
                if (k < fields.size()) {
                    const std::vector<double> r1 = residuals(model, t, true, 1);
                    for (size_t i = 0; i < n && i < r1.size(); ++i)
                        J[k][i] = (r1[i] - r0[i]) / h;
                } else {
                    const size_t crop = (k - fields.size()) % nc;
                    const std::vector<double> r1 = crop_residuals(model, t, crop, true);
                    for (size_t i = 0; i < r1.size() && offset[crop] + i < offset[crop + 1]; ++i)
                        J[k][offset[crop] + i] = (r1[i] - r0[offset[crop] + i]) / h;
                }
            }
        });
        std::vector<double> jtj(p * p, 0.0), jtr(p, 0.0);
        for (size_t a = 0; a < p; ++a) {
            for (size_t b = a; b < p; ++b) {
                double acc = 0.0;
                for (size_t i = 0; i < n; ++i)
                    acc += J[a][i] * J[b][i];
                jtj[a * p + b] = jtj[b * p + a] = acc;
            }
            for (size_t i = 0; i < n; ++i)
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
    const std::vector<std::vector<double>> blocks = residual_blocks(model, s, false, nthreads);
    const size_t nc = s.coc.size(), p = fields.size() + nc;
    std::vector<size_t> offset(nc + 1, 0);
    std::vector<double> r0;
    for (size_t i = 0; i < nc; ++i) {
        offset[i + 1] = offset[i] + blocks[i].size();
        r0.insert(r0.end(), blocks[i].begin(), blocks[i].end());
    }
    const size_t n = r0.size();
    std::vector<std::vector<double>> J(p, std::vector<double>(n, 0.0));
    parallel_for_chunks(0, int64_t(p), 1, nthreads, [&](int64_t kb, int64_t ke) {
        for (int64_t kk = kb; kk < ke; ++kk) {
            const size_t k = size_t(kk);
            State t        = s;
            double& v      = k < fields.size() ? t.*fields[k] : t.coc[k - fields.size()];
            const double h = std::max(1e-3, 1e-3 * std::abs(v));
            v += h;
            if (k < fields.size()) {  // a lens parameter moves every crop
                const std::vector<double> r1 = residuals(model, t, false, 1);
                for (size_t i = 0; i < n && i < r1.size(); ++i)
                    J[k][i] = (r1[i] - r0[i]) / h;
            } else {  // a CoC only its own
                const size_t crop            = k - fields.size();
                const std::vector<double> r1 = crop_residuals(model, t, crop, false);
                for (size_t i = 0; i < r1.size() && offset[crop] + i < offset[crop + 1]; ++i)
                    J[k][offset[crop] + i] = (r1[i] - r0[offset[crop] + i]) / h;
            }
        }
    });
    double chi2 = 0.0;
    for (double r : r0)
        chi2 += r * r;
    const double s2 = chi2 / std::max<double>(1.0, double(n) - double(p));
    std::vector<double> a(p * p, 0.0), inv(p * p, 0.0);
    for (size_t i = 0; i < p; ++i)
        for (size_t j = 0; j < p; ++j) {
            double acc = 0.0;
            for (size_t m = 0; m < n; ++m)
                acc += J[i][m] * J[j][m];
            a[i * p + j] = acc;
        }
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

std::string number(double v) { return format("{:.4g}", std::abs(v) < 1e-9 ? 0.0 : v); }

}  // namespace

bool fit_lens(LensFit& fit, const std::vector<LensFitCrop>& crops, const LensFitOptions& opts, std::string& err,
              int nthreads)
{
    const auto t0 = std::chrono::steady_clock::now();
    fit = LensFit();
    if (crops.empty())
        return err = "fit_lens: no crop given", false;
    if (crops.size() > 64)
        return err = format("fit_lens: {} crops (at most 64)", crops.size()), false;
    if (!(opts.clip_level >= 0.0) || !std::isfinite(opts.clip_level))
        return err = format("fit_lens: clip level {:g} is not a value >= 0", opts.clip_level), false;
    if (opts.max_evaluations < 50 || opts.max_evaluations > 1000000)
        return err = format("fit_lens: max_evaluations {} is outside 50..1000000", opts.max_evaluations), false;
    if (!validate_lens(opts.camera, err))
        return err = "fit_lens: " + err, false;
    std::vector<CropData> data(crops.size());
    for (size_t i = 0; i < crops.size(); ++i)
        if (!prepare_crop(data[i], crops[i], i, opts.clip_level, err))
            return false;

    Fitter f(data, opts, nthreads);
    State& s = f.state();
    // 1. the noise model from the pixels; size and place.
    double read2 = 0.0, photon = 0.0;
    estimate_noise(data, read2, photon);
    f.refine_crops(150, true);
    f.choose_search_crops(read2, photon);
    f.log().push_back(format("size and place: cost {:.1f} over the {} crop{} searched; noise: read {:.3g}, photon "
                             "{:.3g} x signal",
                             f.cost(), f.searched(), f.searched() == 1 ? "" : "s", std::sqrt(read2), photon));

    const bool colour = std::all_of(data.begin(), data.end(), [](const CropData& d) { return d.channels == 3; });
    double max_h = 0.0, min_h = 1e9;
    bool field_known = true;
    for (const CropData& d : data) {
        max_h = std::max(max_h, std::hypot(d.fx, d.fy));
        min_h = std::min(min_h, std::hypot(d.fx, d.fy));
        field_known = field_known && d.field_known;
    }
    double mean_coc = 0.0;
    for (double c : s.coc)
        mean_coc += c / double(s.coc.size());

    bool kept_aperture = false, kept_hole = false, kept_sa = false, kept_colour = false, kept_onion = false;
    bool kept_cats = false, kept_astig = false;
    const bool off_axis = field_known && max_h >= 0.3;
    // The stages not kept yet.
    auto stages = [&] {
        if (opts.fit_spherical && !kept_sa)
            kept_sa = f.stage("spherical aberration",
                              { { "monochromatic", &State::mono, -8.0, 8.0, 0.2,
                                  { -1.5, -0.8, -0.4, -0.15, 0.15, 0.4, 0.8, 1.2, 2.0 } } });
        if (opts.fit_hole && !kept_hole)
            kept_hole = f.stage("hole", { { "hole", &State::hole, 0.0, 0.9, 0.05, { 0.2, 0.4, 0.6 } } });
        if (opts.fit_aperture && !kept_aperture)
            kept_aperture = f.aperture_stage();
        if (opts.fit_colour && colour && !kept_colour)
            kept_colour = f.stage("axial colour",
                                  { { "chromatic", &State::chroma, -8.0, 8.0, 0.2, { -3.0, -1.0, -0.3, 0.3, 1.0, 3.0 } } });
        if (opts.fit_onion && !kept_onion)
            kept_onion = f.stage("onion rings", { { "onion", &State::onion, 0.0, 1.0, 0.05, { 0.15, 0.4, 0.8 } } });
        if (opts.fit_field && off_axis) {
            f.free_centres(true);
            const double a = std::max(4.0, mean_coc);
            if (!kept_cats)
                kept_cats = f.stage("cat's eye", { { "catseye", &State::catseye, 0.0, 1.5, 0.1, { 0.3, 0.7, 1.1 } } });
            if (!kept_astig)
                kept_astig = f.stage("astigmatism",
                                     { { "astigmatism", &State::astig, -a, a, 0.05 * a, { -0.3 * a, 0.3 * a } } });
        }
    };
    stages();
    // Axial colour blurs the rim a spherical aberration draws: with the colour in the
    // model, the spherical aberration is searched again (from scratch when it was not kept).
    if (kept_colour && !kept_sa && opts.fit_spherical)
        kept_sa = f.stage("spherical aberration (with the colour)",
                          { { "monochromatic", &State::mono, -8.0, 8.0, 0.2,
                              { -1.5, -0.8, -0.4, -0.15, 0.15, 0.4, 0.8, 1.2, 2.0 } } });
    else if (kept_sa && kept_colour)
        f.revisit("spherical aberration", { "monochromatic", &State::mono, -8.0, 8.0, 0.2,
                                            { -1.5, -0.8, -0.4, -0.15, 0.15, 0.4, 0.8, 1.2, 2.0 } });
    // The pixels' noise estimate counts fine structure (onion rings, coloured rims) as
    // noise; once the model holds some of it, the residuals may show less. When they show
    // under half the variance at the light's level, the stages not kept run again under it.
    {
        double r2 = 0.0, ph = 0.0, level = 0.0;
        residual_noise(data, f.model(), s, r2, ph);
        for (const CropData& d : data)
            level = std::max(level, d.level);
        if (r2 + ph * level < 0.5 * (read2 + photon * level)) {
            read2 = std::min(read2, r2), photon = std::min(photon, ph);
            set_noise(data, read2, photon);
            f.count_residuals();
            f.log().push_back(format("noise from the residuals: read {:.3g}, photon {:.3g} x signal; the stages "
                                     "not kept again",
                                     std::sqrt(read2), photon));
            stages();
        }
    }

    // 8. everything kept, together, on the crops searched; then every crop joins.
    std::vector<double State::*> fields;
    std::vector<const char*> names;
    for (const StageParam& p : f.kept()) {
        fields.push_back(p.field);
        names.push_back(p.name);
    }
    // BOBYQA's trust region can close before a valley of correlated parameters (CoC,
    // spherical aberration, curvature) is followed to its end: restarted until a round
    // gains under a tenth of one parameter's price, at most 4 rounds.
    for (int round = 0; round < 4 && !f.kept().empty(); ++round) {
        const double before = f.cost();
        const double after  = f.polish({}, 80);
        f.log().push_back(format("all together: cost {:.1f}", after));
        if (before - after < 0.1 * f.price(1))
            break;
    }
    if (f.searched() < data.size()) {
        f.use_all_crops();
        f.refine_crops(60, true, true);
        if (!f.kept().empty())
            f.log().push_back(format("all together, every crop: cost {:.1f}", f.polish({}, 40)));
    }
    if (!f.kept().empty()) {
        std::vector<double> lo, hi;
        for (const StageParam& p : f.kept())
            lo.push_back(p.lo), hi.push_back(p.hi);
        levenberg_marquardt(f.model(), s, fields, lo, hi, 15, nthreads);
        f.log().push_back(format("Levenberg-Marquardt: cost {:.1f}", f.cost()));
    }
    f.refine_crops(60);
    const double period = s.blades > 0 ? 360.0 / s.blades : 360.0;
    if (s.blades > 0)
        s.rotation = std::fmod(std::fmod(s.rotation, period) + period, period);

    // A parameter the final polish took back to (nearly) its "none" is not shown by the
    // crops: below what a viewer could see (a hole of 3 % of the radius, 3 % ring
    // contrast, 2 % of the design's aberrations, a 3 % cat's-eye cut, half a pixel).
    auto none = [](bool& kept, double& v, double visible) {
        if (kept && std::abs(v) < visible)
            kept = false, v = 0.0;
    };
    none(kept_hole, s.hole, 0.03);
    none(kept_sa, s.mono, 0.02);
    none(kept_colour, s.chroma, 0.02);
    none(kept_onion, s.onion, 0.03);
    none(kept_cats, s.catseye, 0.03);
    none(kept_astig, s.astig, 0.5);

    // Uncertainties, the report.
    std::vector<double> coc_sigma;
    const std::vector<double> sigma = uncertainties(f.model(), s, fields, coc_sigma, nthreads);
    fit.lens = f.model().lens_of(s, false);
    if (!kept_sa && !kept_colour) {
        fit.lens.preset        = opts.camera.preset;
        fit.lens.monochromatic = opts.camera.monochromatic;
        fit.lens.chromatic     = opts.camera.chromatic;
        fit.lens.correction    = opts.camera.correction;
        fit.lens.spherochromatism = opts.camera.spherochromatism;
    }
    using Status = LensFitParameter::Status;
    auto sigma_of = [&](const char* name) {
        for (size_t k = 0; k < names.size(); ++k)
            if (std::string(names[k]) == name)
                return sigma[k];
        return 0.0;
    };
    auto param = [&](const char* name, double value, bool asked, bool on, const char* not_asked_why) {
        LensFitParameter p;
        p.name   = name;
        p.value  = value;
        p.status = !asked ? Status::Off : on ? Status::Fitted : Status::Undetermined;
        p.sigma  = on ? sigma_of(name) : 0.0;
        if (!asked)
            p.why = not_asked_why;
        else if (!on)
            p.why = "the crops do not show it (its stage did not pay its price)";
        fit.parameters.push_back(p);
    };
    param("blades", s.blades, opts.fit_aperture, kept_aperture, "not asked for");
    param("rotation", s.rotation, opts.fit_aperture, kept_aperture, "not asked for");
    param("curvature", s.curvature, opts.fit_aperture, kept_aperture, "not asked for");
    param("hole", s.hole, opts.fit_hole, kept_hole, "not asked for");
    param("monochromatic", s.mono, opts.fit_spherical, kept_sa, "not asked for");
    param("chromatic", s.chroma, opts.fit_colour && colour, kept_colour,
          colour ? "not asked for" : "a crop has one channel");
    param("onion", s.onion, opts.fit_onion, kept_onion, "not asked for");
    const char* field_why = !field_known ? "a crop's field position is unknown"
                            : max_h < 0.3 ? "every crop is within 0.3 of the centre"
                                          : "not asked for";
    param("catseye", s.catseye, opts.fit_field && off_axis, kept_cats, field_why);
    param("astigmatism", s.astig, opts.fit_field && off_axis, kept_astig, field_why);
    if (kept_aperture)
        fit.parameters[0].sigma = 0.0;  // a count: chosen, not estimated

    // The options string.
    std::vector<std::string> o;
    if (kept_aperture)
        o.push_back(format("kernel=polygon:blades={}:rotation={}:curvature={}", s.blades, number(s.rotation),
                           number(s.curvature)));
    if (kept_hole)
        o.push_back("hole=" + number(s.hole));
    if (kept_sa || kept_colour)
        o.push_back(format("lens=uncorrected:correction=0:monochromatic={}:chromatic={}", number(s.mono),
                           number(s.chroma)));
    if (kept_onion)
        o.push_back("onion=" + number(s.onion));
    if (kept_cats)
        o.push_back("catseye=" + number(s.catseye));
    if (kept_astig)
        o.push_back("astigmatism=" + number(s.astig));
    fit.options = OIIO::Strutil::join(o, ":");

    // Per crop.
    for (size_t i = 0; i < data.size(); ++i) {
        const CropData& d = data[i];
        LensFitCropResult r;
        r.coc_px = f.model().signed_coc(s, i);
        r.centre_x = s.cx[i], r.centre_y = s.cy[i];
        r.field_x = d.fx, r.field_y = d.fy, r.field_known = d.field_known;
        r.clipped_px = d.clipped, r.nonfinite_px = d.nonfinite;
        Psf p;
        if (f.model().psf(p, s, i, false, nthreads)) {
            std::vector<float> smp;
            Model::sample(smp, p, d, s.cx[i], s.cy[i]);
            Linear lin;
            Model::fit_linear(d, smp, lin, nullptr, &r.outlier_px);
            r.outlier_px += d.others;
            const size_t n = size_t(d.w) * d.h;
            double peak = 0.0, se = 0.0;
            size_t cnt = 0;
            for (int ch = 0; ch < d.channels; ++ch) {
                double sum2 = 0.0;
                size_t m    = 0;
                for (int j = 0; j < d.h; ++j)
                    for (int x = 0; x < d.w; ++x) {
                        const size_t k = size_t(j) * d.w + x;
                        const double mod = lin.a[ch] * smp[ch * n + k];
                        peak = std::max(peak, mod);
                        if (!d.use[k])
                            continue;
                        const double e = d.px[k * d.channels + ch]
                                         - (mod + lin.b0[ch] + lin.bx[ch] * plane_x(d, x) + lin.by[ch] * plane_y(d, j));
                        sum2 += e * e, ++m;
                    }
                r.amplitude[ch]    = lin.a[ch];
                r.background[ch]   = lin.b0[ch];
                r.background_dx[ch] = lin.bx[ch];
                r.background_dy[ch] = lin.by[ch];
                r.residual_rms[ch] = std::sqrt(sum2 / std::max<size_t>(m, 1));
                se += sum2, cnt += m;
            }
            for (int ch = d.channels; ch < 3; ++ch) {
                r.amplitude[ch]    = r.amplitude[0];
                r.background[ch]   = r.background[0];
                r.background_dx[ch] = r.background_dx[0];
                r.background_dy[ch] = r.background_dy[0];
                r.residual_rms[ch] = r.residual_rms[0];
            }
            r.psnr_db = 10.0 * std::log10(peak * peak / std::max(se / std::max<size_t>(cnt, 1), 1e-30));
        }
        r.coc_sigma_px = i < coc_sigma.size() ? coc_sigma[i] : 0.0;
        fit.crops.push_back(r);
    }
    fit.noise_read   = std::sqrt(read2);
    fit.noise_photon = photon;
    fit.evaluations  = f.model().evaluations();
    fit.stages       = f.log();
    fit.seconds      = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return true;
}

bool lens_fit_model_image(OIIO::ImageBuf& dst, const LensFit& fit, const std::vector<LensFitCrop>& crops, int index,
                          int nthreads)
{
    if (index < 0 || size_t(index) >= crops.size() || size_t(index) >= fit.crops.size())
        return dst.errorfmt("lens_fit_model_image: crop {} of {}", index + 1, crops.size()), false;
    const OIIO::ImageSpec& cs = crops[size_t(index)].image.spec();
    const LensFitCropResult& r = fit.crops[size_t(index)];
    PsfRequest req;
    req.coc_px = r.coc_px, req.field_x = r.field_x, req.field_y = r.field_y;
    Psf p;
    std::string err;
    if (!lens_psf(p, fit.lens, req, err, nthreads))
        return dst.errorfmt("lens_fit_model_image: {}", err), false;
    CropData d;
    d.w = cs.width, d.h = cs.height;
    std::vector<float> smp;
    Model::sample(smp, p, d, r.centre_x, r.centre_y);
    OIIO::ImageSpec spec(cs.width, cs.height, 3, OIIO::TypeDesc::FLOAT);
    spec.x = cs.x, spec.y = cs.y, spec.full_x = cs.full_x, spec.full_y = cs.full_y;
    spec.full_width = cs.full_width, spec.full_height = cs.full_height;
    dst.reset(spec);
    const size_t n = size_t(d.w) * d.h;
    std::vector<float> rgb(n * 3);
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i)
            for (int c = 0; c < 3; ++c) {
                const size_t k = size_t(j) * d.w + i;
                rgb[k * 3 + c] = float(r.amplitude[c] * smp[c * n + k] + r.background[c]
                                       + r.background_dx[c] * plane_x(d, i) + r.background_dy[c] * plane_y(d, j));
            }
    dst.set_pixels(dst.roi(), OIIO::TypeDesc::FLOAT, rgb.data());
    return true;
}

bool lens_fit_sheet(OIIO::ImageBuf& dst, const LensFit& fit, const std::vector<LensFitCrop>& crops, int nthreads)
{
    if (crops.empty() || fit.crops.size() != crops.size())
        return dst.errorfmt("lens_fit_sheet: {} crops for a fit of {}", crops.size(), fit.crops.size()), false;
    constexpr int kGutter = 2;
    int cell_w = 0, height = kGutter;
    for (const LensFitCrop& c : crops) {
        cell_w = std::max(cell_w, c.image.spec().width);
        height += c.image.spec().height + kGutter;
    }
    const int width = 4 * cell_w + 5 * kGutter;
    dst.reset(OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBufAlgo::zero(dst);
    int y = kGutter;
    for (size_t i = 0; i < crops.size(); ++i) {
        const OIIO::ImageSpec& cs = crops[i].image.spec();
        OIIO::ImageBuf model;
        if (!lens_fit_model_image(model, fit, crops, int(i), nthreads))
            return dst.errorfmt("{}", model.geterror()), false;
        const int channels = std::min(cs.nchannels, 3);
        const LensFitCropResult& r = fit.crops[i];
        for (int j = 0; j < cs.height; ++j)
            for (int x = 0; x < cs.width; ++x) {
                float crop[3], fitted[3], cells[4][3];
                crops[i].image.getpixel(cs.x + x, cs.y + j, crop, channels);
                model.getpixel(cs.x + x, cs.y + j, fitted, 3);
                const double px = (x + 0.5 - 0.5 * cs.width) / (0.5 * cs.width);
                const double py = (j + 0.5 - 0.5 * cs.height) / (0.5 * cs.height);
                for (int c = 0; c < 3; ++c) {
                    const float v = crop[channels == 3 ? c : 0];
                    cells[0][c]   = v;
                    cells[1][c]   = fitted[c];
                    cells[2][c]   = 4.0f * std::abs(v - fitted[c]);
                    cells[3][c]   = float(fitted[c] - r.background[c] - r.background_dx[c] * px
                                          - r.background_dy[c] * py);
                }
                for (int k = 0; k < 4; ++k)
                    dst.setpixel(kGutter + k * (cell_w + kGutter) + x, y + j, 0, cells[k], 3);
            }
        y += cs.height + kGutter;
    }
    return true;
}

}  // namespace bokeh
