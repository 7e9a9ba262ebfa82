// defocus_planner.cpp — the flat Layers method's plan: the budget's steps (the default), or
// the cheapest ladder of CoC rungs and buffer reductions whose error against the reference
// the predicted planner puts within the accuracy budget (docs/methods/planner.md).
//
// Candidates: the exact rungs (when the frame needs at most 64) and geometric ladders of
// ratio 1.0625..3, each with the smallest reduced kernel q of 8..128 px or none (every
// layer at full resolution). Each gets a predicted PSNR and a predicted time from the
// frame's statistics, gathered once; the planner takes the cheapest whose prediction
// clears the budget by kMarginDb.
//
// Error (ours). A pixel of CoC c drawn as the mix w_a D_a + w_b D_b of the disks at the
// rungs around it (share_between) errs by the kernel dK = w_a D_a + w_b D_b - D_c. For
// concentric unit-sum disks <D_x, D_y> = 1 / max(A_x, A_y) (A: the disk's area), so with
// A_a < A_c < A_b
//     |dK|^2 = w_a^2 / A_a + (1 - 2 w_a) / A_c - w_b^2 / A_b.
// A layer in a buffer reduced by s is blurred more by the box that reduces it and the
// bilinear enlargement (variance s^2/12 + s^2/6, sigma = s/2): a disk's rim (perimeter pi c)
// softened by sigma errs by pi c sigma / sqrt(pi) / A_c^2, which is (2 / sqrt(pi)) (s / c)
// of the disk's own |D_c|^2 = 1 / A_c. The picture's error is dK convolved with the pixels
// of that CoC: dK lives at the kernel's scale, so what it meets is the picture's detail at
// about c / 4 — summed coherently within a cell of that size (a light of many pixels errs
// as one), the cell's sum against the mean about it. Each term is weighted by the slope of
// the bench's tone map x / (1 + x) at the blurred value (the mean over a cell of c), as
// the PSNR it predicts is taken after it.
//
// Cost (ours). The engine computes each layer in tiles of 64 reduced pixels where the layer
// reaches (core/defocus/defocus_engine.cpp); a tile costs its blur (the row-span model of
// core/blur/blur_spans.cpp, 5 channels), the full-resolution reads that reduce its input
// and the writes that lay it over the frame. Which tiles a layer reaches is counted from
// 64-px blocks of the frame and the quarter-pixel CoCs each holds.
//
// The models are checked against measured plans (tools/bokeh-bench's `plans` task;
// docs/methods/planner.md shows predicted against measured). The choice depends on the
// frame and the options only, never on the thread count, so results stay bit-identical.
//
// Known limits: the error model sees the frame's own pixels, not the edges of each layer's
// membership (a plane's silhouette over another) nor the disocclusion fill, and takes a
// pixel's error as independent of its neighbours' of other CoCs. Over the measured plans it
// reads from 10 dB optimistic (giant's coarse ladders, edges at q = 8) to 30 dB pessimistic
// (the real files), which is why it is not the default.

#include <bokeh/base.h>
#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace bokeh {

using namespace detail;

namespace {

// The constants. kReducedScale is fitted to the measured plans (giant's ladder at 1.0625
// with q = 32); the ladder term is the closed form as it stands (1), and the margin 0: no
// margin makes the prediction safe while it spreads 22 dB across the shots measured
// (docs/methods/planner.md). The tile's read and write costs per pixel and its fixed cost
// are estimates beside the measured row-span blur model, not fitted: the measured times of
// one shot's plans rank as predicted where the layers dominate (giant), not where fixed
// costs do (lights).
constexpr double kLadderScale    = 1.0;
constexpr double kReducedScale   = 26.7;
constexpr double kMarginDb       = 0.0;
constexpr double kReadNsPerPx    = 2.0;
constexpr double kWriteNsPerPx   = 3.0;
constexpr double kTileNs         = 20000.0;

constexpr int kBlockPx      = 64;     // the engine's tile at full resolution
constexpr float kKeyPx      = 0.25f;  // CoCs a block holds, to a quarter pixel
constexpr int kMaxBins      = 2048;   // CoC bins of the detail energy
constexpr double kRatios[]  = { 1.0625, 1.09, 1.125, 1.18, 1.25, 1.35, 1.5, 1.75, 2.0, 2.5, 3.0 };
constexpr float kMinReduced[] = { kSmallestReducedCocPx, 12, 16, 24, 32, 48, 64, 96, 128 };

// A disk's area in pixels (at least one: a kernel under a pixel is the pixel).
double disk_area(float c, float aspect)
{
    return std::max(0.25 * kPi * double(c) * double(c) * double(aspect), 1.0);
}

// What the planner knows of a frame.
struct FrameStats {
    float lo = 0.0f, bin_px = 1.0f;
    std::vector<double> energy;   // tone-weighted detail energy per CoC bin
    std::vector<float> bin_coc;   // each bin's energy-weighted mean CoC
    int cols = 0, rows = 0;       // blocks over f.out
    std::vector<std::vector<int32_t>> keys;  // per block, its CoCs / kKeyPx, rounded, ascending
    double values = 1.0;          // the output's values (pixels x 4): the PSNR's count
};

// Means of grey (mean of R, G, B) and alpha over cells of 2^l pixels, l = 1..: level l is
// (w >> l) x (h >> l) cells, rounding up.
struct Pyramid {
    std::vector<std::vector<float>> grey, alpha;
    std::vector<int> w, h;
    float at(const std::vector<std::vector<float>>& p, int l, int x, int y) const
    {
        return p[size_t(l)][size_t(std::min(y >> l, h[size_t(l)] - 1)) * size_t(w[size_t(l)])
                            + size_t(std::min(x >> l, w[size_t(l)] - 1))];
    }
};

Pyramid mean_pyramid(const Frame& f, int levels, int nthreads)
{
    Pyramid p;
    const std::vector<float>& rgba = f.linear();
    const int W = f.data.width(), H = f.data.height();
    p.grey.resize(size_t(levels) + 1);
    p.alpha.resize(size_t(levels) + 1);
    p.w.assign(size_t(levels) + 1, 0);
    p.h.assign(size_t(levels) + 1, 0);
    p.w[0] = W, p.h[0] = H;
    for (int l = 1; l <= levels; ++l) {
        const int w = std::max(1, (p.w[size_t(l) - 1] + 1) / 2), h = std::max(1, (p.h[size_t(l) - 1] + 1) / 2);
        p.w[size_t(l)] = w, p.h[size_t(l)] = h;
        std::vector<float>&g = p.grey[size_t(l)], &a = p.alpha[size_t(l)];
        g.assign(size_t(w) * size_t(h), 0.0f);
        a.assign(g.size(), 0.0f);
        const int pw = p.w[size_t(l) - 1], ph = p.h[size_t(l) - 1];
        parallel_for_chunks(0, h, 8, nthreads, [&, l, w](int64_t yb, int64_t ye) {
        for (int y = int(yb); y < int(ye); ++y)
            for (int x = 0; x < w; ++x) {
                double sg = 0.0, sa = 0.0;
                int n = 0;
                for (int j = 2 * y; j < std::min(2 * y + 2, ph); ++j)
                    for (int i = 2 * x; i < std::min(2 * x + 2, pw); ++i, ++n) {
                        if (l == 1) {
                            const float* v = &rgba[(size_t(j) * size_t(W) + size_t(i)) * 4];
                            sg += (v[0] + v[1] + v[2]) / 3.0;
                            sa += v[3];
                        } else {
                            sg += p.grey[size_t(l) - 1][size_t(j) * size_t(pw) + size_t(i)];
                            sa += p.alpha[size_t(l) - 1][size_t(j) * size_t(pw) + size_t(i)];
                        }
                    }
                g[size_t(y) * size_t(w) + size_t(x)] = float(sg / n);
                a[size_t(y) * size_t(w) + size_t(x)] = float(sa / n);
            }
        });
    }
    return p;
}

FrameStats frame_stats(const Frame& f, float lo, float hi, int nthreads)
{
    FrameStats st;
    st.values = double(f.out.width()) * double(f.out.height()) * 4.0;
    const int W = f.data.width(), H = f.data.height();
    // Detail energy by CoC bin.
    st.lo     = lo;
    st.bin_px = std::max(0.05f, (hi - lo) / float(kMaxBins));
    const int nbins = int((hi - lo) / st.bin_px) + 1;
    int levels      = 0;
    while ((std::max(W, H) >> levels) > 1 && levels < 12)
        ++levels;
    const Pyramid p              = mean_pyramid(f, std::max(levels, 2), nthreads);
    const int top                = std::max(levels, 2);
    const std::vector<float>& rgba = f.linear();
    // Per bin: the energy and its CoC moment (so a plane's pixels sit at their own CoC).
    const std::vector<double> sums = parallel_reduce_chunks(
        0, H, 16, nthreads, std::vector<double>(2 * size_t(nbins), 0.0),
        [&](int64_t y0, int64_t y1) {
            std::vector<double> e(2 * size_t(nbins), 0.0);
            for (int y = int(y0); y < int(y1); ++y)
                for (int x = 0; x < W; ++x) {
                    const size_t i = size_t(y) * size_t(W) + size_t(x);
                    const float c  = f.coc[i];
                    // The cell of about c / 4 (level l: 2^l px) and the mean about it, over a
                    // cell of about c (level l + 2).
                    int l = 0;
                    for (float reach = std::abs(c) * (0.25f / 1.4142f); reach >= 1.0f && l < top - 2; reach *= 0.5f)
                        ++l;
                    const float* v = &rgba[i * 4];
                    const float g  = l == 0 ? (v[0] + v[1] + v[2]) * (1.0f / 3.0f) : p.at(p.grey, l, x, y);
                    const float a  = l == 0 ? v[3] : p.at(p.alpha, l, x, y);
                    const float gm = p.at(p.grey, l + 2, x, y), am = p.at(p.alpha, l + 2, x, y);
                    // The tone map's slope squared, 1 / (1 + m)^4, at the blurred value.
                    const double sg = 1.0 + std::abs(double(gm)), sa = 1.0 + std::abs(double(am));
                    const double tg = 1.0 / (sg * sg * sg * sg), ta = 1.0 / (sa * sa * sa * sa);
                    const double dg = g - gm, da = a - am;
                    const double energy = std::ldexp(3.0 * tg * dg * dg + ta * da * da, 2 * l);
                    const size_t b = size_t(std::clamp(int((c - lo) / st.bin_px), 0, nbins - 1));
                    e[2 * b] += energy;
                    e[2 * b + 1] += energy * double(c);
                }
            return e;
        },
        [](std::vector<double>& acc, const std::vector<double>& e) {
            for (size_t b = 0; b < acc.size(); ++b)
                acc[b] += e[b];
        });
    st.energy.resize(size_t(nbins));
    st.bin_coc.resize(size_t(nbins));
    for (size_t b = 0; b < size_t(nbins); ++b) {
        st.energy[b]  = sums[2 * b];
        st.bin_coc[b] = sums[2 * b] > 0.0 ? float(std::clamp(sums[2 * b + 1] / sums[2 * b], double(lo), double(hi)))
                                          : lo + (float(b) + 0.5f) * st.bin_px;
    }
    // The CoCs each block of the output's tile grid holds.
    st.cols = (f.out.width() + kBlockPx - 1) / kBlockPx;
    st.rows = (f.out.height() + kBlockPx - 1) / kBlockPx;
    st.keys.assign(size_t(st.cols) * size_t(st.rows), {});
    parallel_for_chunks(0, st.rows, 1, nthreads, [&](int64_t by, int64_t) {
        const int y0 = std::max(f.data.ybegin, f.out.ybegin + int(by) * kBlockPx);
        const int y1 = std::min(f.data.yend, f.out.ybegin + int(by + 1) * kBlockPx);
        for (int y = y0; y < y1; ++y) {
            const float* row = f.coc.data() + f.img.index(f.data.xbegin, y);
            int32_t last     = std::numeric_limits<int32_t>::min();
            for (int x = f.data.xbegin; x < f.data.xend; ++x) {
                const int32_t k = int32_t(std::lround(row[x - f.data.xbegin] / kKeyPx));
                if (k == last)
                    continue;
                last = k;
                st.keys[size_t(by) * size_t(st.cols) + size_t((x - f.out.xbegin) / kBlockPx)].push_back(k);
            }
        }
        for (int bx = 0; bx < st.cols; ++bx) {
            std::vector<int32_t>& k = st.keys[size_t(by) * size_t(st.cols) + size_t(bx)];
            std::sort(k.begin(), k.end());
            k.erase(std::unique(k.begin(), k.end()), k.end());
        }
    });
    return st;
}

// The kernel error of a pixel of CoC c shared between rungs a and b (weights 1 - u, u),
// relative to nothing: |dK|^2 in 1 / px^2 (see the header).
double ladder_error(float c, float a, float b, float u, float aspect)
{
    if (u <= 0.0f || u >= 1.0f || a == b) {  // wholly in one rung
        const float r = u >= 1.0f ? b : a;
        if (r == c)
            return 0.0;
        return std::abs(1.0 / disk_area(r, aspect) - 1.0 / disk_area(c, aspect));
    }
    const double wa = 1.0 - double(u), wb = u;
    const double Aa = disk_area(a, aspect), Ab = disk_area(b, aspect), Ac = disk_area(c, aspect);
    return std::max(0.0, wa * wa / std::min(Aa, Ab) + (1.0 - 2.0 * wa) / Ac - wb * wb / std::max(Aa, Ab));
}

// The kernel error of a layer at CoC c in a buffer reduced by s, relative to the disk's
// own 1 / A_c: the rim's (2 / sqrt(pi)) (s / c) (see the header) where s / c is small; the
// measured plans fall faster with q = c / s than that (edges: 8.5 dB from q = 8 to 16, giant
// 3..6 dB per halving), as the kernel drawn in few reduced pixels loses its shape too:
// kReducedScale (s / c)^2, fitted to them.
double reduced_error(float c, int s, float aspect)
{
    if (s <= 1)
        return 0.0;
    const double q = std::max(std::abs(double(c)), 1.0) / double(s);
    return kReducedScale / (q * q) / disk_area(c, aspect);
}

// Predicted squared error (summed over the output's values, tone-mapped) of a plan.
double plan_error(const FrameStats& st, const std::vector<float>& rungs, const std::vector<int>& red,
                  bool exact, float aspect)
{
    double se = 0.0;
    for (size_t b = 0; b < st.energy.size(); ++b) {
        if (st.energy[b] <= 0.0)
            continue;
        const float c = st.bin_coc[b];
        uint16_t j;
        float u;
        share_between(c, rungs, j, u);
        const size_t k = std::min(size_t(j) + 1, rungs.size() - 1);
        double m = exact ? 0.0 : kLadderScale * ladder_error(c, rungs[j], rungs[k], u, aspect);
        m += ((1.0 - u) * (1.0 - u) * reduced_error(rungs[j], red[j], aspect)
                              + double(u) * u * reduced_error(rungs[k], red[k], aspect));
        se += st.energy[b] * m;
    }
    return se;
}

// The blocks each rung's layer holds pixels in (a CoC strictly between its neighbouring
// rungs, or on it): per rung, the blocks' indices.
std::vector<std::vector<int>> held_blocks(const FrameStats& st, const std::vector<float>& rungs)
{
    std::vector<std::vector<int>> held(rungs.size());
    for (int b = 0; b < st.cols * st.rows; ++b) {
        const std::vector<int32_t>& keys = st.keys[size_t(b)];
        if (keys.empty())
            continue;
        const float first = float(keys.front()) * kKeyPx, last = float(keys.back()) * kKeyPx;
        for (size_t k = 0; k < rungs.size(); ++k) {
            const float below = k > 0 ? rungs[k - 1] : -std::numeric_limits<float>::infinity();
            const float above = k + 1 < rungs.size() ? rungs[k + 1] : std::numeric_limits<float>::infinity();
            if (last <= below || first >= above)
                continue;
            const auto at = std::upper_bound(keys.begin(), keys.end(), int32_t(std::floor(below / kKeyPx)));
            if (at != keys.end() && float(*at) * kKeyPx < above)
                held[k].push_back(b);
        }
    }
    return held;
}

// Predicted single-thread ns of the layers' tiles: each layer's held blocks gathered into
// its tiles (kBlockPx * s), grown by the kernel's reach.
double plan_cost_ns(const FrameStats& st, const std::vector<std::vector<int>>& held_by_layer,
                    const std::vector<float>& rungs, const std::vector<int>& red, float aspect)
{
    double ns = 0.0;
    std::vector<uint8_t> held, reach;
    for (size_t k = 0; k < rungs.size(); ++k) {
        const int s  = red[k];
        const int tc = (st.cols + s - 1) / s, tr = (st.rows + s - 1) / s;
        held.assign(size_t(tc) * size_t(tr), 0);
        for (int b : held_by_layer[k])
            held[size_t((b / st.cols) / s) * size_t(tc) + size_t((b % st.cols) / s)] = 1;
        const float c  = std::abs(rungs[k]);
        const int tile = kBlockPx * s;
        const int rx   = int(std::ceil((0.5f * c + 1.0f) / float(tile)));
        const int ry   = int(std::ceil((0.5f * c * aspect + 1.0f) / float(tile)));
        reach.assign(held.size(), 0);
        for (int ty = 0; ty < tr; ++ty)
            for (int tx = 0; tx < tc; ++tx)
                if (held[size_t(ty) * size_t(tc) + size_t(tx)])
                    for (int j = std::max(0, ty - ry); j <= std::min(tr - 1, ty + ry); ++j)
                        for (int i = std::max(0, tx - rx); i <= std::min(tc - 1, tx + rx); ++i)
                            reach[size_t(j) * size_t(tc) + size_t(i)] = 1;
        int64_t tiles = 0;
        for (uint8_t r : reach)
            tiles += r;
        const double kx = c / float(s), ky = c * aspect / float(s);  // the reduced kernel
        const double rows_k = std::ceil(ky) + 1.0;
        const double blur   = 5.0 * 66.0 * 66.0 * (0.7 * (0.10 * 2.6 + 0.29) * rows_k + 0.75);
        const double read   = kReadNsPerPx * (66.0 + kx + 2.0) * (66.0 + ky + 2.0) * double(s) * double(s);
        const double write  = kWriteNsPerPx * double(tile) * double(tile);
        ns += double(tiles) * (blur + read + write + kTileNs);
    }
    return ns;
}

}  // namespace

LayerPlan detail::choose_layer_plan(const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads,
                                    std::vector<DefocusPlanEstimate>& considered)
{
    considered.clear();
    if (o.planner == DefocusPlanner::Steps) {
        LayerPlan plan;
        plan.coc_px    = layer_rungs(f.coc, o, lo, hi);
        plan.reduction = layer_reductions(plan.coc_px, o);
        DefocusPlanEstimate e;
        e.ladder_ratio       = o.layers > 0 ? float(ratio_for_count(o.layers, lo, hi)) : o.ladder_ratio;
        e.min_reduced_coc_px = o.max_reduction == 1 ? std::numeric_limits<float>::infinity()
                                                    : layer_min_reduced_coc_px(o);
        e.layers             = int(plan.coc_px.size());
        e.chosen             = true;
        considered.push_back(e);
        return plan;
    }
    // The ladders the options allow: the user's, or the exact rungs and every ratio.
    std::vector<double> ratios;
    std::vector<float> exact;
    if (o.layers > 0)
        ratios = { ratio_for_count(o.layers, lo, hi) };
    else if (o.ladder_ratio > 1.0f)
        ratios = { double(o.ladder_ratio) };
    else {
        exact = exact_layer_rungs(f.coc, lo, hi, o.ladder_ratio == 1.0f ? std::numeric_limits<size_t>::max() : 64);
        if (o.ladder_ratio == 0.0f)
            ratios.assign(std::begin(kRatios), std::end(kRatios));
        else if (exact.empty())
            exact = { 0.0f };  // ratio 1 over a frame without CoCs
    }
    std::vector<float> qs;
    if (o.min_reduced_coc_px > 0.0f)
        qs = { o.min_reduced_coc_px };
    else {
        qs.assign(std::begin(kMinReduced), std::end(kMinReduced));
        qs.push_back(std::numeric_limits<float>::infinity());
    }
    const bool only_one = (ratios.size() + (exact.empty() ? 0 : 1)) * qs.size() == 1;
    FrameStats st;
    if (!only_one)
        st = frame_stats(f, lo, hi, nthreads);

    struct Candidate {
        LayerPlan plan;
        DefocusPlanEstimate est;
    };
    std::vector<Candidate> all;
    auto weigh = [&](std::vector<float> rungs, double ratio, bool is_exact) {
        std::vector<int> last;
        const std::vector<std::vector<int>> held = only_one ? std::vector<std::vector<int>>()
                                                            : held_blocks(st, rungs);
        for (float q : qs) {
            Candidate c;
            c.plan.coc_px = rungs;
            for (float r : rungs)
                c.plan.reduction.push_back(reduction_for(r, q, o.max_reduction));
            if (c.plan.reduction == last)  // the same plan as the smaller q's
                continue;
            last = c.plan.reduction;
            c.est.ladder_ratio       = float(ratio);
            c.est.min_reduced_coc_px = q;
            c.est.layers             = int(rungs.size());
            if (!only_one) {
                const double se = plan_error(st, c.plan.coc_px, c.plan.reduction, is_exact, o.aspect);
                c.est.predicted_psnr_db = se > 0.0 ? 10.0 * std::log10(st.values / se) : 999.0;
                c.est.predicted_ms      = plan_cost_ns(st, held, c.plan.coc_px, c.plan.reduction, o.aspect) * 1e-6;
            }
            all.push_back(std::move(c));
        }
    };
    if (!exact.empty())
        weigh(exact, 1.0, true);
    for (double r : ratios)
        weigh(coc_ladder(lo, hi, r), r, false);

    // The cheapest that clears the budget; when none does, the most accurate.
    size_t best = 0;
    bool met    = false;
    for (size_t i = 0; i < all.size(); ++i) {
        const DefocusPlanEstimate& e = all[i].est;
        const bool ok                = e.predicted_psnr_db >= double(o.budget_db) + kMarginDb;
        const DefocusPlanEstimate& b = all[best].est;
        if (ok && (!met || e.predicted_ms < b.predicted_ms))
            best = i, met = true;
        else if (!met && !ok && e.predicted_psnr_db > b.predicted_psnr_db)
            best = i;
    }
    all[best].est.chosen = true;
    for (const Candidate& c : all)
        considered.push_back(c.est);
    std::stable_sort(considered.begin(), considered.end(),
                     [](const DefocusPlanEstimate& a, const DefocusPlanEstimate& b) {
                         return a.predicted_ms < b.predicted_ms;
                     });
    return std::move(all[best].plan);
}

}  // namespace bokeh
