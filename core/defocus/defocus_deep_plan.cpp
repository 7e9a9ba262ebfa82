// defocus_deep_plan.cpp — the deep defocus's plan: each sample's CoC at its ends, whether
// the image records surfaces behind its defocused samples (and whether those are points or
// volumes), and from that the views, the ladder and the layers (the Reference's steps, the
// user's ladder, or the planner's). The layers are then filled and drawn by
// core/defocus/defocus_deep.cpp.
//
// Known limits: the planner's choices are steps measured on the two real deep files (the
// constants below), not a search over plans.

#include "defocus/defocus_deep_plan.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

// What the deep planner reads off the samples (method=auto). Measured against the thin-lens
// truth on held pixels (bokeh-bench --task deep, 256 rays; two truths agree to 65.6 dB on
// LowResLeftView, 62.1 on representativeDeepImage): on LowResLeftView's merged passes (point
// samples, forests recorded behind defocused leaves) the default ladder (r = 1.5) scored
// 60.2 dB, 2 x 2 views 61.0, r = 1.24 (30 layers) 62.5, both 65.1 in 0.55 s. On
// representativeDeepImage (a stack of volumes, 150 x 100; 2 threads, best of 3) no ladder
// reaches the truth with 2 x 2 views (r = 1.5: 57.0 dB, 1.125: 57.5) nor without a finer
// ladder (r = 1.5, 3 x 3 to 8 x 8 views: 56.1-57.2): both are needed. 3 x 3 views with
// r = 1.25 60.1 dB (92 ms), 1.15 60.8 (118 ms), 1.125 60.8 (124 ms), 1.1 60.2 (161 ms);
// 4 x 4 with 1.125 60.2, 8 x 8 61.0 (347 ms). A volume runs over CoCs where a point sits
// at one, so a ladder step splits each volume's light between rungs; the pupil's centre,
// which a 2 x 2 grid leaves out, sees through the stack along the axis.
constexpr float kHiddenSpreadPx   = 1.0f;   // samples this far apart in CoC: one behind the other
constexpr double kLayeredShare    = 0.01;   // of the pixels with samples: the image records what it hides
constexpr double kRecordedRatio   = 1.25;   // the ladder ratio for point samples that do
constexpr int kRecordedViews      = 2;      // and their views a side
constexpr double kVolumeRatio     = 1.15;   // the ladder ratio for volumes that do
constexpr int kVolumeViews        = 3;      // and their views a side

// Every sample's CoC at its ends: the range, and the CoCs the rungs are fitted to.
struct SampleCocs {
    std::vector<float> cocs;
    bool continuous = false;  // a volume's CoC runs over more than 1/8 px
    // Pixels whose samples' CoCs differ by more than kHiddenSpreadPx: a surface recorded
    // behind a defocused one, which the blur reveals along some rays and not others.
    int64_t layered_pixels = 0, pixels = 0;
    double zlo = std::numeric_limits<double>::infinity(), zhi = -std::numeric_limits<double>::infinity();
};
SampleCocs sample_cocs(const OIIO::DeepData& dd, const DeepChannels& ch, const CocOfDepth& coc_of)
{
    SampleCocs r;
    std::vector<float>& cocs = r.cocs;
    for (int64_t p = 0; p < dd.pixels(); ++p) {
        const size_t first = cocs.size();
        for (int s = 0; s < dd.samples(p); ++s) {
            const float z = dd.deep_value(p, ch.z, s);
            cocs.push_back(coc_of(z));
            r.zlo = std::min(r.zlo, double(z)), r.zhi = std::max(r.zhi, double(z));
            if (ch.zback >= 0) {
                const float zb = dd.deep_value(p, ch.zback, s);
                if (zb > z) {
                    cocs.push_back(coc_of(zb));
                    r.zhi = std::max(r.zhi, double(zb));
                    r.continuous = r.continuous || std::abs(cocs.back() - cocs[cocs.size() - 2]) > 0.125f;
                }
            }
        }
        if (cocs.size() > first) {
            const auto [lo, hi] = std::minmax_element(cocs.begin() + std::ptrdiff_t(first), cocs.end());
            ++r.pixels;
            r.layered_pixels += *hi - *lo > kHiddenSpreadPx ? 1 : 0;
        }
    }
    if (cocs.empty())
        cocs.push_back(0.0f);
    return r;
}

// The layers of a deep defocus: the Reference's one full-resolution layer per occupied CoC
// step; the user's ladder (ratio 1: a rung per CoC the samples hold, as the flat's exact
// rungs; > 1: that ratio); else the planner's rungs (a volume's CoC runs continuously
// between its ends: no exact rungs then). False + `err` past 4096 reference steps, or for
// exact rungs over volumes.
bool deep_layer_plan(Membership& m, const SampleCocs& sc, const DefocusOptions& o, double ladder_ratio,
                     const DefocusReport& rep, std::string& err)
{
    if (rep.method == DefocusMethod::Reference) {
        std::vector<float> bins;
        for (float c : sc.cocs)
            bins.push_back(std::round(c / o.reference_step_px) * o.reference_step_px);
        std::sort(bins.begin(), bins.end());
        bins.erase(std::unique(bins.begin(), bins.end()), bins.end());
        if (!std::binary_search(bins.begin(), bins.end(), 0.0f))
            bins.insert(std::upper_bound(bins.begin(), bins.end(), 0.0f), 0.0f);
        if (bins.size() > 4096) {
            err = format("{} distinct CoC steps of {} px; raise the reference step", bins.size(), o.reference_step_px);
            return false;
        }
        m.coc_px = std::move(bins);
        m.reduction.assign(m.coc_px.size(), 1);
        return true;
    }
    if (o.ladder_ratio == 1.0f && sc.continuous) {
        err = "ratio=1 asks for a layer per CoC, and this deep image holds volume samples whose CoC runs between "
              "their ends: use method=reference (a layer every reference step) or a ratio above 1";
        return false;
    }
    m.coc_px    = layer_rungs(sc.cocs, o, rep.min_coc_px, rep.max_coc_px, !sc.continuous, ladder_ratio);
    m.reduction = layer_reductions(m.coc_px, o);
    return true;
}

}  // namespace

bool detail::plan_deep_layers(DeepPlan& plan, const OIIO::DeepData& dd, const DeepChannels& ch,
                              const CocOfDepth& coc_of, const DefocusOptions& o, DefocusReport& rep, std::string& err)
{
    const SampleCocs sc       = sample_cocs(dd, ch, coc_of);
    const auto [lo_it, hi_it] = std::minmax_element(sc.cocs.begin(), sc.cocs.end());
    rep.min_coc_px = *lo_it;
    rep.max_coc_px = *hi_it;
    plan.zlo = sc.zlo, plan.zhi = sc.zhi;
    // A deep image that records surfaces behind its defocused samples: each sub-aperture
    // sees them past a blurred edge on its own side (views), and point samples get a
    // finer ladder (the constants' measurements above).
    plan.layered_share        = sc.pixels > 0 ? double(sc.layered_pixels) / double(sc.pixels) : 0.0;
    const bool records_hidden = plan.layered_share > kLayeredShare;
    const bool pupil = o.aperture.shape == KernelShape::Disk || o.aperture.shape == KernelShape::Polygon
                       || o.aperture.shape == KernelShape::Opening || o.aperture.shape == KernelShape::Box;
    const bool planner = o.method == DefocusMethod::Auto;
    plan.options                = o;
    plan.options.aperture_views = o.aperture_views > 0 ? o.aperture_views
                                  : planner && records_hidden && pupil && !o.deep_output
                                      ? (sc.continuous ? kVolumeViews : kRecordedViews)
                                      : 1;
    // Volumes take the finer ladder only with views: in one view it loses (54.1 dB on
    // the budget's ladder, 52.2 on r = 1.15; the constants' measurements above).
    const double ladder_ratio = !planner || !records_hidden || o.layers != 0 ? 0.0
                                : !sc.continuous                              ? kRecordedRatio
                                : plan.options.aperture_views > 1             ? kVolumeRatio
                                                                              : 0.0;
    return deep_layer_plan(plan.m, sc, plan.options, ladder_ratio, rep, err);
}

}  // namespace bokeh
