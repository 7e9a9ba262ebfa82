// truth.cpp — the thin-lens truth of a deep image (truth.h): rays from each pixel's centre
// (or its area) over the aperture, walked through the deep image's pixel cells in depth
// order.
//
// Sources: the thin-lens geometry (a ray from sensor point P through lens point U is at
// P + U s (1/z_f - 1/z) at depth z, linear in 1/z; docs/methods/truth.md), with the flat
// defocus's orientation (core/defocus/defocus.cpp, aperture_weights); the cell walk is Amanatides
// and Woo's grid traversal ("A Fast Voxel Traversal Algorithm", 1987) run over the CoC
// instead of a ray length; the volume split and "over" are the OpenEXR deep rules (deep.h,
// docs/methods/deep.md); the sampler (Owen-scrambled Sobol', truth_sampler.h) is
// shared with the built-in scenes' geometric truth (scene_truth.cpp), so both draw the
// same rays for a pixel and seed.
//
// Ours: the CoC interval bookkeeping (a sample belongs to the cell where the ray is when
// the CoC is the sample's; half-open intervals, the first and last open-ended so a
// zero-size aperture composites exactly the pixel's own samples, in the order and
// arithmetic of flatten), the two half renders for the noise estimate, and the blocks:
// each 16 x 16 block of cells keeps its samples' CoC range, and a pixel's rays walk only
// the range of the blocks they can reach (on the merged LowResLeftView passes, 2.6 cells
// a ray instead of 15.3, the same pixels: build/bin/truth_measure, docs/methods/truth.md).
// The `unknown` share (TruthOptions::unknown) is ours: a ray adds its transmittance where
// it enters space the file does not record, behind an opaque pixel's last sample or past
// the data window (docs/methods/truth.md). So are the rays' start at the pixel's centre
// (TruthPixel) and the joined opaque points (kConnectedCocPx): both measured against the
// built-in scenes' geometric truth.
// Limits as truth.h says; cost is rays x cells crossed, the cells growing with the CoC
// range, stopping at the first opaque surface; 140-210 ns a ray on one core, mostly the
// sampler and the walk's set-up.

#include <bokeh/base.h>
#include <bokeh/parallel.h>
#include <bokeh/truth.h>

#include "base/numbers.h"
#include "base/progress.h"
#include "truth/truth_sampler.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

namespace {

using OIIO::Strutil::fmt::format;
using detail::kInf;

// Transmittance at or below which float stores the accumulated opacity as 1 (1 - 2^-25
// rounds to 1.0f): a ray stops there (deep.h's cull threshold).
constexpr double kOpaqueTransmittance = 1.0 / 33554432.0;
// A pixel whose samples let through at most this share of what lies behind them hides
// it from the camera: a ray crossing that space meets what the file does not record.
constexpr float kUnseenBehind = 1e-3f;
// A solid surface is continuous, but a deep image samples it as thin tiles at its pixels'
// depths: a ray that crosses from one pixel to the next at a depth between their tiles
// passes between them, through a crack no surface has (a cone of LowResLeftView seen
// edge-on let 1-9 % of the rays through 4 px inside its silhouette, and 18 % of the
// frame's pixels had rays that slipped into space behind opaque pixels). So an opaque
// point sample (alpha at least 1 - kUnseenBehind: it hides what is behind it) is met over
// [coc - reach, coc + reach], reach half the CoC gap to the nearest opaque point of each
// 4-neighbour whose gap is at most kConnectedCocPx: a ray crossing between two such
// pixels meets one of them. A ray moves at most half a pixel sideways per pixel of CoC, so
// where the two are different surfaces, what lies behind them loses a sliver at most half
// a pixel wide (times the aspect, vertically) at the aperture's rim. Partly transparent
// samples (coverage of an edge, a small light, smoke) are not tiles of a solid surface and
// stay points: connected too, the lights scene's fairy lights took rays from the wall
// around them, 1.6 dB further from its geometric truth (4 x 4 blocks, 1024 rays a pixel).
constexpr float kConnectedCocPx = 1.0f;


// --- the scene -----------------------------------------------------------------------

// One tidy sample, ready for the walk: depths, CoCs at its front and back, the alphas
// its R, G, B and A composite through, its premultiplied R, G, B.
struct TruthSample {
    float z, zback;    // zback == z: a point
    float coc, coc_back;
    float reach = 0.0f;  // a point is met over [coc - reach, coc + reach] (kConnectedCocPx)
    float alpha[4];    // R, G, B, A
    float colour[3];
};

// A point sample that hides what lies behind it (kConnectedCocPx).
bool opaque_point(const TruthSample& t)
{
    return !(t.zback > t.z) && t.alpha[3] >= 1.0f - kUnseenBehind;
}

struct Cell {
    uint32_t first = 0, count = 0;
    float coc_min = 0.0f, coc_max = 0.0f;  // over its samples' fronts and backs, reach included
    float reach_max = 0.0f;
    // The A transmittance through all its samples: how much of what lies behind them the
    // camera saw.
    float through = 1.0f;
};

struct Scene {
    OIIO::ROI data;  // the cells
    std::vector<Cell> cells;
    std::vector<TruthSample> samples;
    float coc_lo = 0.0f, coc_hi = 0.0f;
    // The CoC range of the samples in each kTile x kTile block of cells (empty: lo > hi):
    // a pixel's rays need only the range of the blocks they can reach.
    static constexpr int kTile = 16;
    int tiles_x = 0, tiles_y = 0;
    std::vector<float> tile_lo, tile_hi;
    const Cell& cell(int x, int y) const
    {
        return cells[size_t(y - data.ybegin) * size_t(data.width()) + size_t(x - data.xbegin)];
    }
    void build_tiles()
    {
        tiles_x = (data.width() + kTile - 1) / kTile;
        tiles_y = (data.height() + kTile - 1) / kTile;
        tile_lo.assign(size_t(tiles_x) * size_t(tiles_y), std::numeric_limits<float>::infinity());
        tile_hi.assign(tile_lo.size(), -std::numeric_limits<float>::infinity());
        for (int y = 0; y < data.height(); ++y)
            for (int x = 0; x < data.width(); ++x) {
                const Cell& c = cells[size_t(y) * size_t(data.width()) + size_t(x)];
                if (c.count == 0)
                    continue;
                const size_t t = size_t(y / kTile) * size_t(tiles_x) + size_t(x / kTile);
                tile_lo[t]     = std::min(tile_lo[t], c.coc_min);
                tile_hi[t]     = std::max(tile_hi[t], c.coc_max);
            }
    }
    // The CoC range of the samples in the blocks that cells [x0, x1] x [y0, y1] touch.
    void range_near(int x0, int x1, int y0, int y1, float& lo, float& hi) const
    {
        lo = std::numeric_limits<float>::infinity();
        hi = -std::numeric_limits<float>::infinity();
        x0 = std::max(x0, data.xbegin);
        y0 = std::max(y0, data.ybegin);
        x1 = std::min(x1, data.xend - 1);
        y1 = std::min(y1, data.yend - 1);
        if (x0 > x1 || y0 > y1)
            return;
        for (int ty = (y0 - data.ybegin) / kTile; ty <= (y1 - data.ybegin) / kTile; ++ty)
            for (int tx = (x0 - data.xbegin) / kTile; tx <= (x1 - data.xbegin) / kTile; ++tx) {
                const size_t t = size_t(ty) * size_t(tiles_x) + size_t(tx);
                lo             = std::min(lo, tile_lo[t]);
                hi             = std::max(hi, tile_hi[t]);
            }
    }
};

int channel_named(const OIIO::ImageSpec& s, std::initializer_list<const char*> names)
{
    for (const char* n : names)
        for (int c = 0; c < s.nchannels; ++c)
            if (s.channel_name(c) == n)
                return c;
    return -1;
}

// Read the tidy deep image into a Scene, with each sample's CoC; false + err when the CoC
// falls as Z grows within a pixel.
bool build_scene(Scene& sc, const OIIO::ImageBuf& tidy, const CocOfDepth& coc_of, int nthreads, std::string& err)
{
    const OIIO::ImageSpec& s  = tidy.spec();
    const OIIO::DeepData& dd  = *tidy.deepdata();
    const int cz = channel_named(s, { "Z" }), czb = channel_named(s, { "ZBack", "Zback" });
    const int cr = channel_named(s, { "R" }), cg = channel_named(s, { "G" }), cb = channel_named(s, { "B" });
    const int ca = channel_named(s, { "A" }), car = channel_named(s, { "AR" }), cag = channel_named(s, { "AG" }),
              cab = channel_named(s, { "AB" });
    sc.data = tidy.roi();
    const int64_t npx = int64_t(sc.data.width()) * sc.data.height();
    sc.cells.assign(size_t(npx), Cell{});
    uint64_t total = 0;
    for (int64_t p = 0; p < npx; ++p) {
        sc.cells[size_t(p)].first = uint32_t(total);
        sc.cells[size_t(p)].count = dd.samples(p);
        total += dd.samples(p);
    }
    if (total > uint64_t(std::numeric_limits<uint32_t>::max())) {
        err = format("{} samples: more than the truth holds (2^32)", total);
        return false;
    }
    sc.samples.resize(size_t(total));
    // Per chunk of rows: the CoC range and the first pixel where the CoC falls with Z.
    struct Part {
        float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
        int64_t bad = -1;
        float bad_z0 = 0, bad_z1 = 0, bad_c0 = 0, bad_c1 = 0;
    };
    const int w    = sc.data.width();
    const Part all = parallel_reduce_chunks(
        0, npx, int64_t(w) * 8, nthreads, Part{},
        [&](int64_t b, int64_t e) {
            Part part;
            auto value = [&](int64_t p, int c, int k) { return c >= 0 ? dd.deep_value(p, c, k) : 0.0f; };
            for (int64_t p = b; p < e; ++p) {
                Cell& cell = sc.cells[size_t(p)];
                float prev_c = -std::numeric_limits<float>::infinity(), prev_z = 0.0f;
                for (uint32_t k = 0; k < cell.count; ++k) {
                    TruthSample& t = sc.samples[cell.first + k];
                    t.z            = value(p, cz, int(k));
                    t.zback        = czb >= 0 ? std::max(t.z, value(p, czb, int(k))) : t.z;
                    if (std::isinf(t.zback))  // a medium reaching infinity holds its opacity there
                        t.z = t.zback;
                    t.coc      = coc_of(t.z);
                    t.coc_back = t.zback > t.z ? coc_of(t.zback) : t.coc;
                    const float a = value(p, ca, int(k));
                    const float ar = car >= 0 ? value(p, car, int(k)) : a, ag = cag >= 0 ? value(p, cag, int(k)) : a,
                                ab = cab >= 0 ? value(p, cab, int(k)) : a;
                    t.alpha[0] = ar;
                    t.alpha[1] = ag;
                    t.alpha[2] = ab;
                    t.alpha[3] = ca >= 0 ? a : (ar + ag + ab) / 3.0f;
                    t.colour[0] = value(p, cr, int(k));
                    t.colour[1] = value(p, cg, int(k));
                    t.colour[2] = value(p, cb, int(k));
                    if ((t.coc < prev_c || t.coc_back < t.coc) && part.bad < 0) {
                        part.bad    = p;
                        part.bad_z0 = t.coc < prev_c ? prev_z : t.z;
                        part.bad_z1 = t.coc < prev_c ? t.z : t.zback;
                        part.bad_c0 = t.coc < prev_c ? prev_c : t.coc;
                        part.bad_c1 = t.coc < prev_c ? t.coc : t.coc_back;
                    }
                    prev_c = t.coc_back;
                    prev_z = t.zback;
                    cell.through *= 1.0f - std::clamp(t.alpha[3], 0.0f, 1.0f);
                    if (k == 0) {
                        cell.coc_min = t.coc;
                        cell.coc_max = t.coc_back;
                    } else {
                        cell.coc_min = std::min(cell.coc_min, t.coc);
                        cell.coc_max = std::max(cell.coc_max, t.coc_back);
                    }
                }
                if (cell.count) {
                    part.lo = std::min(part.lo, cell.coc_min);
                    part.hi = std::max(part.hi, cell.coc_max);
                }
            }
            return part;
        },
        [](Part& acc, const Part& p) {
            acc.lo = std::min(acc.lo, p.lo);
            acc.hi = std::max(acc.hi, p.hi);
            if (acc.bad < 0 && p.bad >= 0) {
                const float lo = acc.lo, hi = acc.hi;
                acc    = p;
                acc.lo = lo;
                acc.hi = hi;
            }
        });
    if (all.bad >= 0) {
        err = format("pixel ({}, {}): the CoC falls from {} to {} px as Z grows from {} to {}; the depth "
                     "mode must read Z as a distance (nearer = smaller Z){}",
                     sc.data.xbegin + int(all.bad % w), sc.data.ybegin + int(all.bad / w), all.bad_c0, all.bad_c1,
                     all.bad_z0, all.bad_z1,
                     all.bad_z0 <= 0.0f ? " and a Z of 0 or below reads as no depth (infinitely far)" : "");
        return false;
    }
    sc.coc_lo = total ? all.lo : 0.0f;
    sc.coc_hi = total ? all.hi : 0.0f;
    return true;
}

// Each opaque point sample's reach (kConnectedCocPx): half its CoC gap to the nearest
// opaque point of each 4-neighbour pixel, where that gap is at most kConnectedCocPx; the
// cells' CoC bounds, and so the blocks' ranges, then include it. Returns the largest reach.
float connect_point_samples(Scene& sc, int nthreads)
{
    const int w = sc.data.width(), h = sc.data.height();
    parallel_for_chunks(0, int64_t(h), 8, nthreads, [&](int64_t y0, int64_t y1) {
        static constexpr int kNx[4] = { -1, 1, 0, 0 }, kNy[4] = { 0, 0, -1, 1 };
        for (int64_t y = y0; y < y1; ++y)
            for (int x = 0; x < w; ++x) {
                Cell& cell = sc.cells[size_t(y) * size_t(w) + size_t(x)];
                for (uint32_t k = 0; k < cell.count; ++k) {
                    TruthSample& t = sc.samples[cell.first + k];
                    if (!opaque_point(t))
                        continue;
                    float reach = 0.0f;
                    for (int n = 0; n < 4; ++n) {
                        const int nx = x + kNx[n], ny = int(y) + kNy[n];
                        if (nx < 0 || nx >= w || ny < 0 || ny >= h)
                            continue;
                        const Cell& nb = sc.cells[size_t(ny) * size_t(w) + size_t(nx)];
                        float gap = std::numeric_limits<float>::infinity();
                        for (uint32_t j = 0; j < nb.count; ++j) {
                            const TruthSample& u = sc.samples[nb.first + j];
                            if (!opaque_point(u))
                                continue;
                            gap = std::min(gap, std::max({ 0.0f, u.coc - t.coc, t.coc - u.coc_back }));
                        }
                        if (gap <= kConnectedCocPx)
                            reach = std::max(reach, 0.5f * gap);
                    }
                    t.reach = reach;
                }
            }
    });
    float largest = 0.0f;
    for (Cell& cell : sc.cells) {
        for (uint32_t k = 0; k < cell.count; ++k) {
            const TruthSample& t = sc.samples[cell.first + k];
            cell.coc_min         = std::min(cell.coc_min, t.coc - t.reach);
            cell.coc_max         = std::max(cell.coc_max, t.coc_back + t.reach);
            cell.reach_max       = std::max(cell.reach_max, t.reach);
        }
        largest = std::max(largest, cell.reach_max);
    }
    return largest;
}

// --- one ray -------------------------------------------------------------------------

// A depth of volume `t` where its CoC reaches `target` (coc < target <= coc_back), to
// 1e-5 of the CoC (a ray position within 5e-6 px). Regula falsi in w = 1/z with the
// Illinois modification: its first step is the thin lens's exact answer (the CoC is linear
// in 1/z), and where gains, the in-focus range or the limit bend the curve it still
// converges in a few steps, the bracket kept for safety.
double depth_of_coc(const TruthSample& t, float target, const CocOfDepth& coc_of)
{
    const bool in_w = t.z > 0.0f && std::isfinite(t.zback);
    const double tol = 1e-5 * std::max(1.0, std::abs(double(target)));
    double lo = t.z, hi = t.zback;
    double flo = double(t.coc) - target, fhi = double(t.coc_back) - target;  // flo < 0 <= fhi
    int kept = 0;  // which end the last step kept: -1 lo, +1 hi
    for (int i = 0; i < 60 && hi - lo > 1e-7 * std::max(1.0, std::abs(hi)); ++i) {
        const double f = flo / (flo - fhi);
        double z       = in_w ? 1.0 / (1.0 / lo + (1.0 / hi - 1.0 / lo) * f) : lo + (hi - lo) * f;
        if (!(z > lo && z < hi))
            z = 0.5 * (lo + hi);
        const double fz = double(coc_of(float(z))) - target;
        if (std::abs(fz) <= tol)
            return z;
        if (fz >= 0.0) {
            hi = z;
            fhi = fz;
            if (kept == -1)
                flo *= 0.5;
            kept = -1;
        } else {
            lo = z;
            flo = fz;
            if (kept == 1)
                fhi *= 0.5;
            kept = 1;
        }
    }
    return hi;
}

struct RayState {
    double acc[4];
    double T[4];
    double unknown = 0.0;  // the share of the ray's light that crossed unrecorded space
    int64_t cells = 0;
    void reset()
    {
        for (int c = 0; c < 4; ++c) {
            acc[c] = 0.0;
            T[c]   = 1.0;
        }
        unknown = 0.0;
    }
    bool opaque() const
    {
        return T[0] <= kOpaqueTransmittance && T[1] <= kOpaqueTransmittance && T[2] <= kOpaqueTransmittance
               && T[3] <= kOpaqueTransmittance;
    }
};

// Composite the samples of `cell` the ray meets while its CoC is in [c_in, c_out).
// Returns false once the ray is opaque.
bool visit_cell(const Scene& sc, const Cell& cell, float c_in, float c_out, const CocOfDepth& coc_of, RayState& r)
{
    if (cell.count == 0 || cell.coc_max < c_in || cell.coc_min >= c_out)
        return true;
    const TruthSample* smp = sc.samples.data() + cell.first;
    for (uint32_t k = 0; k < cell.count; ++k) {
        const TruthSample& t = smp[k];
        if (t.coc - cell.reach_max >= c_out)
            break;  // the CoC does not fall with Z: the rest are beyond
        double x = 1.0;  // the fraction of the sample's depth inside the interval
        if (t.zback > t.z) {
            if (t.coc_back < c_in || t.coc >= c_out)
                continue;
            const double lower = c_in <= t.coc ? double(t.z) : depth_of_coc(t, c_in, coc_of);
            const double upper = c_out > t.coc_back ? double(t.zback) : depth_of_coc(t, c_out, coc_of);
            if (!(upper > lower))
                continue;
            x = std::min(1.0, (upper - lower) / (double(t.zback) - double(t.z)));
        } else if (t.coc + t.reach < c_in || t.coc - t.reach >= c_out) {
            continue;
        }
        double a[4], col[4];
        for (int c = 0; c < 4; ++c) {
            const double al = t.alpha[c];
            a[c]            = x >= 1.0 ? al : al >= 1.0 ? 1.0 : -std::expm1(x * std::log1p(-al));
            const double v  = c < 3 ? double(t.colour[c]) : al;
            col[c]          = x >= 1.0 ? v : al == 0.0 ? v * x : v * (a[c] / al);
        }
        for (int c = 0; c < 4; ++c) {
            r.acc[c] += r.T[c] * col[c];
            r.T[c] *= 1.0 - a[c];
        }
        if (r.opaque())
            return false;
    }
    return true;
}

// Trace the ray from sensor position (px, py) through aperture offset (sx, sy) (per px
// of CoC): its image position at CoC c is (px - sx c, py - sy c), for c over [lo, hi],
// the CoC range of every sample the ray can reach.
void trace(const Scene& sc, float lo, float hi, double px, double py, double sx, double sy, const CocOfDepth& coc_of,
           RayState& r)
{
    const OIIO::ROI& d = sc.data;
    const double dx = -sx, dy = -sy;
    double ca = lo, cb = hi;
    // Clip [ca, cb] to where the ray is over the cells.
    auto clip = [&](double p, double dir, double lo, double hi) {
        if (dir == 0.0) {
            if (!(p >= lo && p < hi))
                cb = -kInf;
            return;
        }
        double c0 = (lo - p) / dir, c1 = (hi - p) / dir;
        if (c0 > c1)
            std::swap(c0, c1);
        ca = std::max(ca, c0);
        cb = std::min(cb, c1);
    };
    clip(px, dx, d.xbegin, d.xend);
    clip(py, dy, d.ybegin, d.yend);
    // Past the window the file records nothing: a ray that starts there could meet
    // something before it enters, and one that leaves carries its transmittance out.
    if (!(ca <= cb) || ca > lo) {
        r.unknown += 1.0;
        if (!(ca <= cb))
            return;
    }
    const bool leaves = cb < hi;
    // The first interval is open below unless the window cut it, the last open above.
    const float lower = ca > lo ? float(ca) : -std::numeric_limits<float>::infinity();
    const float upper = cb < hi ? float(cb) : std::numeric_limits<float>::infinity();
    int ix = std::clamp(int(std::floor(px + dx * ca)), d.xbegin, d.xend - 1);
    int iy = std::clamp(int(std::floor(py + dy * ca)), d.ybegin, d.yend - 1);
    const int stepx = dx > 0.0 ? 1 : -1, stepy = dy > 0.0 ? 1 : -1;
    const double invx = dx != 0.0 ? 1.0 / dx : 0.0, invy = dy != 0.0 ? 1.0 / dy : 0.0;
    auto next_x = [&] { return dx != 0.0 ? (double(ix + (stepx > 0)) - px) * invx : kInf; };
    auto next_y = [&] { return dy != 0.0 ? (double(iy + (stepy > 0)) - py) * invy : kInf; };
    double cx = next_x(), cy = next_y();
    float c_in = lower;
    for (;;) {
        const double c_next = std::min(cx, cy);
        const bool last     = c_next >= cb;
        const float c_out   = last ? upper : float(c_next);
        ++r.cells;
        const Cell& cell = sc.cell(ix, iy);
        if (!visit_cell(sc, cell, c_in, c_out, coc_of, r))
            return;
        // Past the last sample of a cell the camera could not see through: space the file
        // does not record (a renderer keeps samples until a pixel is opaque; behind a
        // partly transparent stack it would have kept what was there).
        if (cell.count && c_out > cell.coc_max && cell.through <= kUnseenBehind)
            r.unknown += r.T[3];
        if (last) {
            if (leaves)
                r.unknown += r.T[3];
            return;
        }
        if (cx <= cy) {
            ix += stepx;
            if (ix < d.xbegin || ix >= d.xend) {
                r.unknown += r.T[3];
                return;
            }
            cx = next_x();
        } else {
            iy += stepy;
            if (iy < d.ybegin || iy >= d.yend) {
                r.unknown += r.T[3];
                return;
            }
            cy = next_y();
        }
        c_in = c_out;
    }
}

}  // namespace

bool detail::check_truth_rays(const Kernel& aperture, float aspect, int spp, std::string& err)
{
    if (aperture.shape != KernelShape::Disk && aperture.shape != KernelShape::Polygon
        && aperture.shape != KernelShape::Opening) {
        err = "the aperture must be a disk, a polygon or a star";
        return false;
    }
    if (!check_aperture(aperture, aspect, err))
        return false;
    if (spp < 1 || spp > (1 << 20)) {
        err = format("spp {} is outside 1..1048576", spp);
        return false;
    }
    return true;
}

bool check_truth_options(const TruthOptions& opt, std::string& err)
{
    return detail::check_truth_rays(opt.aperture, opt.aspect, opt.spp, err);
}

ApertureSampler detail::truth_pupil(const Kernel& aperture, float aspect)
{
    Aperture opening;
    std::string err;
    Aperture::from_kernel(aperture, opening, err);  // check_truth_rays has accepted it
    return ApertureSampler(opening, aspect);
}

// --- the render ----------------------------------------------------------------------

namespace {

// A deep image with depth, colour and alpha, and rays the sampler can draw. False + `err`.
bool check_truth_input(const OIIO::ImageBuf& src, const TruthOptions& opt, std::string& err)
{
    if (!src.initialized()) {
        err = "no image";
        return false;
    }
    if (!src.deep()) {
        err = "needs a deep image, this one is flat (--deepen makes one)";
        return false;
    }
    if (!check_truth_options(opt, err))
        return false;
    const OIIO::ImageSpec& spec = src.spec();
    if (channel_named(spec, { "Z" }) < 0) {
        err = format("the deep image has no Z channel (has {})", OIIO::Strutil::join(spec.channelnames, ","));
        return false;
    }
    if (channel_named(spec, { "R" }) < 0 || channel_named(spec, { "G" }) < 0 || channel_named(spec, { "B" }) < 0) {
        err = format("the deep image has no R, G, B channels (has {})", OIIO::Strutil::join(spec.channelnames, ","));
        return false;
    }
    if (channel_named(spec, { "A", "AR", "AG", "AB" }) < 0) {
        err = "the deep image has no alpha channel (A, or AR, AG, AB)";
        return false;
    }
    return true;
}

// The data window, grown (when asked) by the largest CoC radius `extreme` within the
// display window joined to the data window.
OIIO::ROI truth_output_region(const OIIO::ImageSpec& spec, const OIIO::ROI& data, float extreme,
                              const TruthOptions& opt)
{
    if (!opt.grow)
        return data;
    const OIIO::ROI display(spec.full_x, spec.full_x + spec.full_width, spec.full_y, spec.full_y + spec.full_height);
    const int gx = int(std::ceil(0.5f * extreme)), gy = int(std::ceil(0.5f * extreme * opt.aspect));
    OIIO::ROI g  = data;
    g.xbegin -= gx;
    g.xend += gx;
    g.ybegin -= gy;
    g.yend += gy;
    return OIIO::roi_intersection(g, OIIO::roi_union(display, data));
}

}  // namespace

bool defocus_truth(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const TruthOptions& opt, TruthReport* report,
                   int nthreads)
{
    const auto start = std::chrono::steady_clock::now();
    std::string err;
    auto fail = [&](const std::string& why) {
        dst.errorfmt("truth: {}", why);
        return false;
    };
    if (!check_truth_input(src, opt, err))
        return fail(err);
    const OIIO::ImageSpec& spec = src.spec();

    TruthReport rep;
    DeepOptions dopt;
    dopt.nonfinite = opt.nonfinite;
    OIIO::ImageBuf tidy;
    if (!deep_tidy(tidy, src, dopt, &rep.repairs, nthreads))
        return fail(tidy.geterror());

    CocOptions coc = opt.coc;
    if (coc.focus_at_pixel) {
        // The focus pixel's depth is that of its nearest visible sample (flatten's Z).
        OIIO::ImageBuf flat;
        if (!deep_flatten(flat, tidy, dopt, nullptr, nthreads))
            return fail(flat.geterror());
        const OIIO::ROI d = flat.roi();
        if (coc.focus_x >= d.xbegin && coc.focus_x < d.xend && coc.focus_y >= d.ybegin && coc.focus_y < d.yend
            && tidy.deepdata()->samples(int64_t(coc.focus_y - d.ybegin) * d.width() + (coc.focus_x - d.xbegin)) == 0)
            return fail(format("focus pixel {},{} has no samples", coc.focus_x, coc.focus_y));
        if (!resolve_coc_options(coc, flat, err))
            return fail(err);
    } else if (!resolve_coc_options(coc, src, err)) {  // reads the channel names only
        return fail(err);
    }
    const int width_px = spec.full_width > 0 ? spec.full_width : spec.width;
    const CocOfDepth coc_of(coc, width_px);
    Scene sc;
    if (!build_scene(sc, tidy, coc_of, nthreads, err))
        return fail(err);
    const float largest_reach = connect_point_samples(sc, nthreads);
    sc.build_tiles();
    rep.min_coc_px = sc.coc_lo;
    rep.max_coc_px = sc.coc_hi;

    const float extreme = std::max(std::abs(sc.coc_lo), std::abs(sc.coc_hi));
    OIIO::ROI out       = truth_output_region(spec, sc.data, extreme, opt);
    const int nc = opt.unknown ? 5 : 4;
    out.chbegin  = 0;
    out.chend    = nc;
    OIIO::ImageSpec ospec = derived_spec(spec, opt.unknown ? std::vector<std::string>{ "R", "G", "B", "A", "unknown" }
                                                           : std::vector<std::string>{ "R", "G", "B", "A" },
                                         out);
    ospec.deep            = false;
    OIIO::ImageBuf result(ospec);

    const ApertureSampler aperture = detail::truth_pupil(opt.aperture, opt.aspect);
    // How far from its pixel a ray can go: half the largest CoC (the aperture's offsets are
    // within 1/2 px per px of CoC, times the aspect in y), plus the pixel.
    // The walk's CoC range includes the samples' reach (kConnectedCocPx).
    const float walked = extreme + largest_reach;
    const int reach_x = int(std::ceil(0.5f * walked)) + 1, reach_y = int(std::ceil(0.5f * walked * opt.aspect)) + 1;
    const detail::SobolTable& table = detail::sobol_table();
    const int n_first = (opt.spp + 1) / 2, n_second = opt.spp / 2;
    const double inv_n = 1.0 / opt.spp;
    const bool area    = opt.pixel == TruthPixel::Area;

    struct Part {
        detail::HalvesNoise noise;
        int64_t cells = 0, rays = 0;
    };
    const int64_t rows = out.height(), row_chunk = 2;
    const int64_t nchunks = (rows + row_chunk - 1) / row_chunk;
    detail::ProgressCounter progress(opt.progress, double(nchunks));
    const Part total = parallel_reduce_chunks(
        0, rows, row_chunk, nthreads, Part{},
        [&](int64_t y0, int64_t y1) {
            Part part;
            RayState ray;
            double u[4];
            for (int64_t yy = y0; yy < y1; ++yy) {
                const int y = out.ybegin + int(yy);
                float* row  = static_cast<float*>(result.pixeladdr(out.xbegin, y));
                for (int x = out.xbegin; x < out.xend; ++x) {
                    const uint32_t px_seed = detail::pixel_seed(opt.seed, x, y);
                    double sum[2][4]       = {};
                    double unknown         = 0.0;
                    float lo, hi;
                    sc.range_near(x - reach_x, x + reach_x, y - reach_y, y + reach_y, lo, hi);
                    for (int half = 0; half < 2 && lo <= hi; ++half) {
                        detail::PixelSequence seq(table, detail::half_seed(px_seed, half));
                        const int n = half == 0 ? n_first : n_second;
                        for (int i = 0; i < n; ++i) {
                            seq.next(u);
                            const auto s = aperture(u[0], u[1]);
                            ray.reset();
                            trace(sc, lo, hi, x + (area ? u[2] : 0.5), y + (area ? u[3] : 0.5), s[0], s[1],
                                  coc_of, ray);
                            ++part.rays;
                            for (int c = 0; c < 4; ++c)
                                sum[half][c] += ray.acc[c];
                            unknown += std::min(1.0, ray.unknown);
                        }
                    }
                    if (nc == 5)
                        row[size_t(x - out.xbegin) * 5 + 4] = float(unknown * inv_n);
                    for (int c = 0; c < 4; ++c) {
                        row[size_t(x - out.xbegin) * size_t(nc) + size_t(c)] = float((sum[0][c] + sum[1][c]) * inv_n);
                        if (n_second > 0)
                            part.noise.add(sum[0][c] / n_first, sum[1][c] / n_second);
                    }
                }
            }
            part.cells = ray.cells;
            progress.add();
            return part;
        },
        [](Part& acc, const Part& p) {
            acc.noise.merge(p.noise);
            acc.cells += p.cells;
            acc.rays += p.rays;
        });

    rep.rays          = total.rays;
    rep.cells_visited = total.cells;
    const double values = double(out.npixels()) * 4.0;
    total.noise.figures(n_first, n_second, values, rep.noise_rmse, rep.noise_psnr_db);
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    rep.summary = format("truth: CoC {:.1f} .. {:.1f} px, {} spp from the pixel's {}, {} rays, {:.1f} cells a ray, "
                         "noise RMS {:.3g} ({:.1f} dB), output {}x{}, {:.2f} s{}",
                         rep.min_coc_px, rep.max_coc_px, opt.spp, area ? "area" : "centre", rep.rays,
                         rep.rays ? double(rep.cells_visited) / double(rep.rays) : 0.0, rep.noise_rmse,
                         rep.noise_psnr_db, out.width(), out.height(), rep.seconds,
                         rep.repairs.total() ? format(", {} bad samples repaired", rep.repairs.total())
                                             : std::string());
    dst = std::move(result);
    if (report)
        *report = std::move(rep);
    return true;
}

}  // namespace bokeh
