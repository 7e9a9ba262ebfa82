// fit_stages.cpp — the lens fit's stages (fit/fit_stages.h): each crop's CoC and centre,
// a stage's grid and polish and its price, the aperture's blade counts; the
// minimiser is fit_model.cpp's (NLopt's BOBYQA).

#include <bokeh/base.h>

#include "fit/fit_stages.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <OpenImageIO/strutil.h>

namespace bokeh {
namespace fit {

using OIIO::Strutil::fmt::format;


void wrap_rotation(State& s)
{
    if (s.blades <= 0)
        return;
    const double period = 360.0 / s.blades;
    s.rotation          = std::fmod(std::fmod(s.rotation, period) + period, period);
}

namespace {

// A parameter at its "none" value (0) buys nothing, whatever the CoCs' polish gained
// beside it: a stage counts only when it moved one off it.
bool off_none(const StageParam& p, const State& s) { return std::abs(s.*p.field) > 1e-3 * (p.hi - p.lo); }

}  // namespace

Free Fitter::coc_free(size_t i, double step_of_coc)
{
    const double c0 = m_crops[i].coc0;
    return { &m_s.coc[i], kCocLow * c0, kCocHigh * c0 + 4.0, step_of_coc * c0 + 0.2 };
}

double Fitter::best_start(const StageParam& p, const State& from, double best, int cocs_evaluations)
{
    m_model.set_floor(kSearchFloorOfLevel);
    State best_state = m_s;
    for (double v : p.starts) {
        m_s          = from;
        m_s.*p.field = v;
        // An aberration moves the rim: each start with its CoCs refitted.
        const double c = polish_cocs(cocs_evaluations);
        if (c < best)
            best = c, best_state = m_s;
    }
    m_s = best_state;
    return best;
}

void Fitter::count_residuals()
{
    m_residuals = 0.0;
    for (size_t i : m_active)
        m_residuals += double(m_crops[i].channels) * double(m_crops[i].fit_k.size());
}

// The stages search on the crops that show the most (a large, bright bokeh above its
// noise): at most kSearchCrops of them; the final polish takes them all.
void Fitter::choose_search_crops(double read2, double photon)
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


void Fitter::use_all_crops()
{
    m_active.resize(m_crops.size());
    for (size_t i = 0; i < m_crops.size(); ++i)
        m_active[i] = i;
    count_residuals();
}

// Each crop's CoC and centre, the lens held.
// `search`: first under the search floor; `scan`: each CoC first from a scan.
double Fitter::refine_crops(int evaluations_each, bool search, bool scan)
{
    if (search) {
        m_model.set_floor(kSearchFloorOfLevel);
        refine_crops(evaluations_each, false, scan);
        m_model.set_floor(0.0);
    }
    double total = 0.0;
    for (size_t i = 0; i < m_crops.size(); ++i) {
        const double c0 = m_crops[i].coc0;
        std::vector<Free> f = { coc_free(i, 0.05),
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
double Fitter::polish(const std::vector<StageParam>& params, int evaluations)
{
    std::vector<Free> f;
    for (const StageParam& p : params)
        f.push_back({ &(m_s.*p.field), p.lo, p.hi, p.step });
    for (const StageParam& p : m_kept)
        f.push_back({ &(m_s.*p.field), std::min(p.lo, m_s.*p.field), std::max(p.hi, m_s.*p.field), p.step });
    for (size_t i : m_active)
        f.push_back(coc_free(i, 0.03));
    add_centres(f);
    const int n = int(f.size());
    return minimise(f, [&] { return cost(); }, std::min(evaluations + 12 * n, std::max(10, left())));
}

// A stage: the cost with what is kept polished; the best grid start (each parameter's
// starts tried in turn, the others at their best); the polish; kept when the cost
// falls by more than the parameters' price.
bool Fitter::stage(const char* name, const std::vector<StageParam>& params)
{
    const double c0    = polish({}, 20);
    const State before = m_s;
    for (const StageParam& p : params)  // the current value is a start too
        best_start(p, before, c0, m_free_centres ? 30 : 6);
    polish(params, 40);
    m_model.set_floor(0.0);
    const double c1   = polish(params, 30);
    const int k       = int(params.size());
    const bool moved = std::any_of(params.begin(), params.end(), [&](const StageParam& p) { return off_none(p, m_s); });
    const bool keep   = moved && c0 - c1 > price(k);
    m_log.push_back(format("{}: cost {:.1f} -> {:.1f} (price of {} parameter{} {:.1f}): {}", name, c0, c1, k,
                           k == 1 ? "" : "s", price(k), keep ? "kept" : "not shown by the crops"));
    if (!keep)
        m_s = before;
    else
        m_kept.insert(m_kept.end(), params.begin(), params.end());
    return keep;
}

bool Fitter::joint_stage(const char* name, const StageParam& added, const StageParam& again, double min_gain)
{
    const double c0    = polish({}, 20);
    const State before = m_s;
    double best        = 1e300;
    State best_state   = before;
    for (double v : added.starts) {
        m_s             = before;
        m_s.*added.field = v;
        m_model.set_floor(kSearchFloorOfLevel);
        const double here = polish_cocs(6);  // the current value of `again` is a start too
        best_start(again, m_s, here, 6);
        polish({ added }, 40);
        m_model.set_floor(0.0);
        const double c = polish({ added }, 30);
        if (c < best)
            best = c, best_state = m_s;
    }
    m_model.set_floor(0.0);
    const bool keep = off_none(added, best_state) && c0 - best > std::max(price(1), min_gain * c0);
    m_log.push_back(format("{}: cost {:.1f} -> {:.1f} (price of 1 parameter {:.1f}): {}", name, c0, best, price(1),
                           keep ? "kept" : "not shown by the crops"));
    m_s = keep ? best_state : before;
    if (keep)
        m_kept.push_back(added);
    return keep;
}

// The crops' centres, free while a field effect is fitted (a cut pupil's light is
// not centred where a round one's is), within 4 px of the crop's first estimate.
void Fitter::add_centres(std::vector<Free>& f)
{
    if (!m_free_centres)
        return;
    for (size_t i : m_active) {
        f.push_back({ &m_s.cx[i], m_crops[i].cx0 - 4.0, m_crops[i].cx0 + 4.0, 0.3 });
        f.push_back({ &m_s.cy[i], m_crops[i].cy0 - 4.0, m_crops[i].cy0 + 4.0, 0.3 });
    }
}

// Only the CoCs free, a few evaluations a crop; the best cost.
double Fitter::polish_cocs(int evaluations_each)
{
    std::vector<Free> f;
    for (size_t i : m_active)
        f.push_back(coc_free(i, 0.05));
    add_centres(f);
    return minimise(f, [&] { return cost(); },
                    std::min(evaluations_each * int(f.size()) + 4, std::max(10, left())));
}

namespace {

// A polygon's rotation (within half a blade period of the current) and curvature.
std::vector<StageParam> blade_params(const State& s)
{
    const double period = 360.0 / s.blades;
    return { { "rotation", &State::rotation, s.rotation - 0.5 * period, s.rotation + 0.5 * period, period / 12.0, {} },
             { "curvature", &State::curvature, 0.0, 1.0, 0.1, {} } };
}

}  // namespace

// The aperture: each blade count's best rotation on a grid, briefly polished; the best
// counts polished fully, the best kept against round.
bool Fitter::aperture_stage()
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
        m_s.blades    = n;
        m_s.curvature = 0.15;
        for (int k = 0; k < 8; ++k) {
            m_s.rotation   = period * k / 8.0;
            const double c = cost();
            if (c < best.grid_cost)
                best.grid_cost = c, best.rotation = m_s.rotation;
        }
        // A short polish: a grid point's cost says little while the spherical
        // aberration and the CoC were fitted to a round stop.
        m_s.rotation  = best.rotation;
        m_s.curvature = 0.15;
        best.cost     = polish(blade_params(m_s), 10);
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
        m_s = tries[t].state;
        const std::vector<StageParam> p = blade_params(m_s);
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
        wrap_rotation(m_s);
        const double period = 360.0 / m_s.blades;
        m_kept.push_back({ "rotation", &State::rotation, m_s.rotation - 0.25 * period,
                           m_s.rotation + 0.25 * period, period / 24.0, {} });
        m_kept.push_back({ "curvature", &State::curvature, 0.0, 1.0, 0.05, {} });
    }
    return keep;
}

}  // namespace fit
}  // namespace bokeh
