// defocus_plan.cpp — which layers a layered defocus draws, and at which reductions: the
// planner of the Layers method and the Reference's layers.
//
// * Reference: a frame of at most 64 distinct CoCs (planes, a handful of lights) gets a
//   layer per CoC; others a layer per point of a grid reference_step_px apart that their
//   CoCs fall between, each pixel shared between the two around it; all at full
//   resolution with the exact anti-aliased kernel. Exact for the model but for the
//   sharing's second-moment match within one step; slow.
// * Layers: the reference's rungs when they are at most 64 (0.25 px grid), exact but for
//   the reductions; others a geometric ladder (0, +-1, +-r, +-r^2, ..., the frame's
//   extremes). A pixel between two rungs is shared between them with weights that keep
//   its kernel's second moment (so the mixed kernel has the spread of the true one). A
//   layer whose CoC allows it is built in a buffer reduced by 2..16 (large bokeh lose
//   little at low resolution). The accuracy budget sets r and the smallest reduced kernel
//   q (settings_for_budget, from the defocus chart in docs/benchmarks.md), kernels of at
//   most 2 q px unless at full resolution.
//
// In time: every rung but the outermost is a fixed function of CoC (a grid point or a
// power of r), and the outermost is the frame's extreme CoC, which moves smoothly; so a
// surface whose CoC changes smoothly changes the picture smoothly (docs/methods/defocus.md,
// "In time", measured by tools/bokeh-bench/temporal.py). A frame whose count of distinct
// CoCs or grid rungs crosses 64 switches between exact rungs and the ladder.
//
// Known limits: the budget's settings are steps measured on the synthetic scenes, not a
// search for the cheapest plan that meets it (that is the predicted planner's,
// core/defocus/defocus_planner.cpp, not yet accurate enough to be the default).

#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;
using OIIO::Strutil::fmt::format;

namespace {

// Shares of every pixel in the ladder `rungs` (share_between).
Membership share_between_rungs(const Frame& f, std::vector<float> rungs, int nthreads)
{
    Membership m;
    m.coc_px = std::move(rungs);
    m.lower.resize(f.coc.size());
    m.upper.resize(f.coc.size());
    parallel_for_chunks(0, int64_t(f.coc.size()), 4096, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i)
            share_between(f.coc[size_t(i)], m.coc_px, m.lower[size_t(i)], m.upper[size_t(i)]);
    });
    return m;
}

constexpr float kRungStep_px   = 0.25f;  // CoCs closer than this count as one
constexpr size_t kMaxExactRungs = 64;

// The frame's distinct CoC values, ascending, when it holds at most `most` of them (planes,
// a handful of lights); empty when it holds more (depth that varies continuously).
std::vector<float> few_distinct_cocs(const std::vector<float>& cocs, size_t most)
{
    std::vector<float> values;
    for (float c : cocs) {
        const auto at = std::lower_bound(values.begin(), values.end(), c);
        if (at != values.end() && *at == c)
            continue;
        if (values.size() == most)
            return {};
        values.insert(at, c);
    }
    return values;
}

// The rungs of a fixed grid `step` apart that the frame's CoCs need: for each CoC the grid
// point at or below it and, unless it lies on one, the next above (ascending). A pixel is
// then shared between the two grid points around its CoC (share_between): where a rung
// lies depends on the CoC alone, not on which other CoCs the frame holds, so a surface
// whose CoC changes smoothly (a focus pull, a dolly) changes the picture smoothly. A CoC on
// a grid point (planes at whole and quarter pixels), or at either end of the frame's range,
// has its own kernel exactly.
std::vector<float> coc_grid_rungs(const std::vector<float>& cocs, float lo, float hi, float step)
{
    const int64_t first = int64_t(std::floor(lo / step)), last = int64_t(std::floor(hi / step)) + 1;
    std::vector<uint8_t> used(size_t(last - first + 1), 0);
    for (float c : cocs) {
        const int64_t k = std::clamp(int64_t(std::floor(c / step)), first, last - 1);
        used[size_t(k - first)] = 1;
        if (c != float(double(k) * step))
            used[size_t(k + 1 - first)] = 1;
    }
    // The outermost rungs are the frame's extreme CoCs themselves (they move smoothly with
    // the frame), so no kernel is larger than the largest CoC the output region was grown for.
    std::vector<float> rungs;
    for (size_t i = 0; i < used.size(); ++i)
        if (used[i]) {
            const float r = std::clamp(float(double(first + int64_t(i)) * step), lo, hi);
            if (rungs.empty() || r > rungs.back())
                rungs.push_back(r);
        }
    return rungs;
}

// The exact rungs of a frame: its CoC values when it holds few (each pixel then in one
// layer, its own), else the grid points `step` apart around them (coc_grid_rungs).
std::vector<float> exact_rungs(const std::vector<float>& cocs, float lo, float hi, float step)
{
    std::vector<float> rungs = few_distinct_cocs(cocs, kMaxExactRungs);
    return rungs.empty() ? coc_grid_rungs(cocs, lo, hi, step) : rungs;
}

// Layer settings an accuracy budget asks for: the ladder's ratio r and the smallest reduced
// kernel diameter q. From the defocus chart (docs/benchmarks.md), the coarsest settings at
// which every synthetic scene meets the budget: the ladder's spacing sets the error of
// scenes of continuous depth (lights), q that of hard bokeh and silhouette edges in
// reduced buffers (edges, giant: q = 16 gave 41.6 and 35.5 dB, q = 24 gives 92.8 and 42.0).
struct LayerSettings {
    double ratio;
    float min_reduced_coc_px;
};
LayerSettings settings_for_budget(float budget_db)
{
    if (budget_db <= 30.0f) return { 2.0, 12.0f };
    if (budget_db <= 40.0f) return { 1.5, 24.0f };
    if (budget_db <= 50.0f) return { 1.125, 64.0f };
    return { 1.0625, 96.0f };
}

}  // namespace

// The reference's layers: exact_rungs, each pixel shared between the two around its CoC,
// all at full resolution.
Membership detail::one_layer_per_coc(const Frame& f, float lo, float hi, float step, int nthreads)
{
    Membership m = share_between_rungs(f, reference_rungs(f.coc, lo, hi, step), nthreads);
    m.reduction.assign(m.coc_px.size(), 1);
    return m;
}

std::vector<float> detail::reference_rungs(const std::vector<float>& cocs, float lo, float hi, float step)
{
    return exact_rungs(cocs, lo, hi, step);
}

bool detail::reference_range_fits(float lo, float hi, float step, std::string& err)
{
    if ((hi - lo) / step <= 65535.0f)
        return true;
    err = format("CoC range {} .. {} px holds too many {} px steps; raise the reference step", lo, hi, step);
    return false;
}

Membership detail::layer_membership(const Frame& f, LayerPlan plan, int nthreads)
{
    Membership m = share_between_rungs(f, std::move(plan.coc_px), nthreads);
    m.reduction  = std::move(plan.reduction);
    return m;
}

Membership detail::layer_plan(const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads,
                              std::vector<DefocusPlanEstimate>* considered)
{
    std::vector<DefocusPlanEstimate> weighed;
    LayerPlan plan = choose_layer_plan(f, o, lo, hi, nthreads, weighed);
    if (considered)
        *considered = std::move(weighed);
    return layer_membership(f, std::move(plan), nthreads);
}

std::vector<float> detail::coc_ladder(float lo, float hi, double ratio)
{
    std::vector<float> rungs = { 0.0f };
    for (int side = -1; side <= 1; side += 2) {
        const float extreme = side < 0 ? -lo : hi;
        if (extreme <= 0.0f)
            continue;
        for (double r = 1.0;; r *= ratio) {
            if (r >= extreme * 0.999) {
                rungs.push_back(float(side) * extreme);
                break;
            }
            rungs.push_back(float(side * r));
        }
    }
    std::sort(rungs.begin(), rungs.end());
    return rungs;
}

int detail::reduction_for(float c, float q, int max_reduction)
{
    int s = 1;
    while (s * 2 <= max_reduction && std::abs(c) / float(s * 2) >= q)
        s *= 2;
    return s;
}

float detail::layer_min_reduced_coc_px(const DefocusOptions& o)
{
    return o.min_reduced_coc_px > 0.0f ? o.min_reduced_coc_px
                                       : settings_for_budget(o.budget_db).min_reduced_coc_px;
}

double detail::ratio_for_count(int layers, float lo, float hi)
{
    const double span = std::log(std::max(1.0f, -lo)) + std::log(std::max(1.0f, hi));
    const int sides   = (lo < -1.0f ? 1 : 0) + (hi > 1.0f ? 1 : 0);
    const int steps   = std::max(1, layers - 1 - sides);
    return span > 0.0 ? std::max(std::exp(span / steps), 1.01) : 2.0;
}

std::vector<float> detail::exact_layer_rungs(const std::vector<float>& cocs, float lo, float hi, size_t most)
{
    if (!((hi - lo) / kRungStep_px < 1e6f))
        return {};
    std::vector<float> rungs = exact_rungs(cocs, lo, hi, kRungStep_px);
    if (rungs.size() > most)
        return {};
    // A rung at 0, so no two neighbouring rungs lie on opposite sides of focus (the
    // shares keep the second moment of one side's disks).
    if (!std::binary_search(rungs.begin(), rungs.end(), 0.0f))
        rungs.insert(std::upper_bound(rungs.begin(), rungs.end(), 0.0f), 0.0f);
    return rungs;
}

void detail::share_between(float c, const std::vector<float>& r, uint16_t& lower, float& upper)
{
    c        = std::clamp(c, r.front(), r.back());
    size_t j = size_t(std::upper_bound(r.begin(), r.end(), c) - r.begin());
    j        = j == 0 ? 0 : std::min(j - 1, r.size() - 1);
    float u  = 0.0f;
    if (j + 1 < r.size() && c != r[j]) {
        if (r[j] < 0.0f && r[j + 1] > 0.0f) {
            // Rungs on both sides of focus (the reference's bins with none at 0): a mix of
            // a front and a back disk has no second moment to keep; the nearer rung.
            u = c - r[j] > r[j + 1] - c ? 1.0f : 0.0f;
        } else {
            const double a2 = double(r[j]) * r[j], b2 = double(r[j + 1]) * r[j + 1];
            u = float(std::clamp((double(c) * c - a2) / (b2 - a2), 0.0, 1.0));
        }
    }
    lower = uint16_t(j);
    upper = u;
}

std::vector<float> detail::layer_rungs(const std::vector<float>& cocs, const DefocusOptions& o, float lo, float hi,
                                       bool exact_allowed, double ladder_ratio)
{
    // The user's ladder: ratio 1 the exact rungs whatever their count, > 1 that ratio.
    std::vector<float> rungs;
    if (o.ladder_ratio == 1.0f && exact_allowed)
        rungs = exact_layer_rungs(cocs, lo, hi, std::numeric_limits<size_t>::max());
    else if (o.ladder_ratio > 1.0f && o.layers == 0)
        rungs = coc_ladder(lo, hi, o.ladder_ratio);
    if (!rungs.empty())
        return rungs;
    const LayerSettings set = settings_for_budget(o.budget_db);
    double ratio            = ladder_ratio > 0.0 ? std::min(ladder_ratio, set.ratio) : set.ratio;
    if (o.layers > 0)
        ratio = ratio_for_count(o.layers, lo, hi);
    // A scene of few depths (planes, a handful of lights) gets one rung per CoC it holds,
    // so its layers are exact but for the reductions; others get the ladder.
    if (o.layers == 0 && exact_allowed)
        rungs = exact_layer_rungs(cocs, lo, hi, kMaxExactRungs);
    if (rungs.empty())
        rungs = coc_ladder(lo, hi, ratio);
    return rungs;
}

std::vector<int> detail::layer_reductions(const std::vector<float>& rungs, const DefocusOptions& o)
{
    std::vector<int> r;
    const float q = layer_min_reduced_coc_px(o);
    for (float c : rungs)
        r.push_back(reduction_for(c, q, o.max_reduction));
    return r;
}

OIIO::ROI detail::defocus_output_bound(const OIIO::ImageSpec& s, const OIIO::ROI& data, bool grow)
{
    return grow ? OIIO::roi_union(OIIO::get_roi_full(s), data) : data;
}

OIIO::ROI detail::defocus_output_region(const OIIO::ImageSpec& s, const OIIO::ROI& data, float extreme,
                                const DefocusOptions& o)
{
    OIIO::ROI out = data;
    if (o.grow) {
        const OIIO::ROI limit = defocus_output_bound(s, data, true);
        // Half the largest kernel: how far bokeh spread past the data window; a layer in a
        // buffer reduced by s reaches up to 1.5 s px farther (its box and the bilinear
        // enlargement).
        int spill = 0;
        if (o.method == DefocusMethod::Auto || o.method == DefocusMethod::Layers) {
            // The predicted planner may reduce down to kSmallestReducedCocPx.
            const float q = o.planner == DefocusPlanner::Predicted && o.min_reduced_coc_px == 0.0f
                                ? kSmallestReducedCocPx
                                : layer_min_reduced_coc_px(o);
            const int r   = reduction_for(extreme, q, o.max_reduction);
            spill       = r > 1 ? (3 * r + 1) / 2 : 0;
        }
        const int gx = int(std::ceil(0.5f * extreme)) + spill;
        const int gy = int(std::ceil(0.5f * extreme * o.aspect)) + spill;
        out = OIIO::roi_intersection(grown(data, gx, gy), limit);
    }
    out.chbegin = 0;
    out.chend   = 4;
    return out;
}

}  // namespace bokeh
