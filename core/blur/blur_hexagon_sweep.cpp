// blur_hexagon_sweep.cpp — the hexagon's segment passes: the steep segment's window
// (SteepWindow), the four passes built on it, and the fused sweep that makes the hexagon
// in one pass down the rows (hexagon_sweep). blur_hexagon.cpp says which runs when.
//
// A segment pass: out(p) = mean over t in [0, 1] of in(p - t e). With a, b, c the three
// segment directions, four passes make the hexagon: B = seg_b in, S = seg_a in + B, then
// (seg_c S + seg_a B) / 3. Along its major axis a segment is a running sum (in double;
// fractional ends weighted by overlap: interval_weights); across it the plane is sheared
// so that the segment runs down a column, and sheared back, each time through the
// three-tap quadratic B-spline (Taps). A steep segment's shear moves whole rows, so its
// pass is one sweep down the rows per chunk of columns, each sheared row made once, when
// it enters the window, and kept in a ring until it leaves (measured A/B against shearing
// the leaving row again: 0.87-0.94x of the time, 1080p RGBA, 15-255 px). The four passes
// run in the frame where two of the three directions are steep; each computes only the
// region the later ones read; their planes are reused once their values are used up.
//
// The fused sweep: when c runs along the rows, out = (seg_a X + seg_c T) / 3 with
// T = seg_b in and X = seg_c in + T (rhombus(a, c) + rhombus(a, b) + rhombus(c, b)): two
// windows and two row passes (row prefix sums, the cheaper pass) where the four passes'
// grouping takes three windows (measured A/B: 0.91-0.95 of its time at 15-255 px, 1080p
// RGBA, two threads). Each source line is read once and each output row written once,
// with no middle planes.
//
// Limits (1080p RGBA, two threads, bokeh-bench): 10-14 ms flat-topped and 11-18 upright
// at 15-255 px, growing 1.36x and 1.66x over that range: the windows cover the chunk,
// c's length and their span's drift and sweep the kernel's reach above and below the
// frame (~1.25x the work at 255 px), and T's ring and the windows' rings (~6 MB a chunk at
// 255 px) fall out of a 1 MiB L2 (~15-20 % of the 255 px time). The window slides take
// ~20 % of the sweep's time, the shears' three-tap reads ~17 %, the row sums ~25 %;
// upright, the column gathers and scatters ~22 % more. Float sums, a fused step, L1-sized
// blocks, narrower chunks, aligned buffers, row sums in L1-sized tiles and rings on huge
// pages each changed the time by 11 % or less; an upright sweep without transposing (flat
// windows) lost 5-8 dB to the sampling of flat lines by rows.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/blur_methods.h"
#include "blur/hexagon.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

namespace bokeh {

using namespace detail;

namespace detail {

// interval_weights (blur_methods.h): the overlap of each pixel with [a, b].
IntervalWeights interval_weights(double a, double b)
{
    IntervalWeights iw;
    iw.first     = int(std::floor(a + 0.5));
    const int i1 = int(std::ceil(b - 0.5));
    for (int i = iw.first; i <= i1; ++i) {
        const double lo = std::max(a, i - 0.5), hi = std::min(b, i + 0.5);
        iw.w.push_back(std::max(0.0, hi - lo) / (b - a));
    }
    return iw;
}

}  // namespace detail

namespace {

// A segment's weights along its major axis, for its signed length e there: an output reads
// the pixels i in [first, last] behind it, the newest (i = first) and the oldest (i = last)
// by their overlap, the ones between `inner` each (0 when there are none).
struct SegmentWeights {
    int first = 0, last = 0;
    double newest = 0.0, inner = 0.0, oldest = 0.0;
    explicit SegmentWeights(double e)
    {
        const IntervalWeights iw = interval_weights(std::min(0.0, e), std::max(0.0, e));
        first  = iw.first;
        last   = iw.last();
        newest = iw.w.front();
        oldest = last != first ? iw.w.back() : 0.0;
        inner  = iw.w.size() > 2 ? iw.w[1] : 0.0;
    }
};

// o[i] = (w0 p[i] + w1 p[i + stride] + w2 p[i + 2 stride] + add[i]) * scale: a row read
// through three taps (the shear, and the unshear with its extras); add may be null.
BOKEH_HOT void taps_row(float* o, const float* p, const float* add, float w0, float w1, float w2,
                        float scale, size_t stride, size_t n)
{
    if (add)
        for (size_t i = 0; i < n; ++i)
            o[i] = (w0 * p[i] + w1 * p[i + stride] + w2 * p[i + 2 * stride] + add[i]) * scale;
    else
        for (size_t i = 0; i < n; ++i)
            o[i] = (w0 * p[i] + w1 * p[i + stride] + w2 * p[i + 2 * stride]) * scale;
}

// Columns u in [u0, u1) of `row` (zero outside its span [lo, hi); all zero without
// pixels) read at u + shift: the taps `t` of the shift (Taps(shift): reads from column
// u + t.first). `identity`: no shift.
void shifted_row(float* g, const RowSpan& row, int nc, int u0, int u1, const Taps& t, bool identity)
{
    const size_t ncs = size_t(nc);
    const int lo = row.p ? row.lo : 0, hi = row.p ? row.hi : 0;
    const int reach  = identity ? 0 : 2;  // taps past the first
    const int first  = identity ? t.first + 1 : t.first;
    // [z0, z1): columns with a tap inside [lo, hi) (u + first + reach >= lo, u + first < hi);
    // [a, b): those with all taps inside (u + first >= lo, u + first + reach < hi).
    const int z0 = std::clamp(lo - first - reach, u0, u1), z1 = std::clamp(hi - first, z0, u1);
    const int a = std::clamp(lo - first, z0, z1), b = std::clamp(hi - reach - first, a, z1);
    std::fill(g, g + size_t(z0 - u0) * ncs, 0.0f);
    std::fill(g + size_t(z1 - u0) * ncs, g + size_t(u1 - u0) * ncs, 0.0f);
    auto edge = [&](int u) {
        float* o = g + size_t(u - u0) * ncs;
        std::fill_n(o, nc, 0.0f);
        for (int j = 0; j <= reach; ++j) {
            const int x = u + first + j;
            if (x < lo || x >= hi)
                continue;
            const float wj = identity ? 1.0f : t.w[j];
            for (int c = 0; c < nc; ++c)
                o[c] += wj * row.p[size_t(x - lo) * ncs + size_t(c)];
        }
    };
    for (int u = z0; u < a; ++u)
        edge(u);
    if (b > a) {
        float* o = g + size_t(a - u0) * ncs;
        const float* p = row.p + size_t(a + first - lo) * ncs;
        if (identity)
            std::copy_n(p, size_t(b - a) * ncs, o);
        else
            taps_row(o, p, nullptr, t.w[0], t.w[1], t.w[2], 1.0f, ncs, size_t(b - a) * ncs);
    }
    for (int u = b; u < z1; ++u)
        edge(u);
}

// The window moved by one row: s (the inner rows' sum) += enter - leave, in double (no
// drift), then h = inner s + wf newest + wl oldest (the fractional ends), in float: the
// two ends need no double, and their conversions are saved (with band_row's the same:
// bokeh-ab, 0.89-0.98x of the sweep's time).
BOKEH_HOT void slide_window(double* s, float* h, const float* newest, const float* enter,
                            const float* leave, const float* oldest, double wf, double inner,
                            double wl, size_t n)
{
    const float wf_f = float(wf), wl_f = float(wl);
    for (size_t i = 0; i < n; ++i) {
        s[i] += double(enter[i]) - double(leave[i]);
        h[i] = float(inner * s[i]) + wf_f * newest[i] + wl_f * oldest[i];
    }
}

// o[i] = (h[i] + add[i]) * scale; add may be null.
BOKEH_HOT void scaled_row(float* o, const float* h, const float* add, float scale, size_t n)
{
    if (add)
        for (size_t i = 0; i < n; ++i)
            o[i] = (h[i] + add[i]) * scale;
    else
        for (size_t i = 0; i < n; ++i)
            o[i] = h[i] * scale;
}

// Slot of row r (any sign) in a ring of n rows.
size_t ring_slot(int r, int n) { return size_t(((r % n) + n) % n); }

// One steep segment's window, for the four passes (segment_sweep) and the fused sweep
// (hexagon_sweep): one output row per step. Input lines are valid
// over columns [0, n_in) (zero outside; a null line is all zero); outputs are wanted over
// [x0, x1) for the steps [read0, ye). G row r is input line r read at u + m r (the
// shear's taps); the window sums G rows [y - last, y - first] down G's columns (interval
// weights, the inner rows' running sum in double); row y of the result reads the window
// at x - m y (the unshear's taps). Buffers span every G column the sweep reaches; a step
// works only on the columns read in the next few steps (the window's span), a range that
// drifts by under a column per step: a column joins with an empty sum and is never read
// before its window has filled, and one that leaves is never read again (see step()).
// G's rows are kept in a ring of the window's last - first + 1 rows: G row r depends on r
// alone, so the row leaving the window is the one made when it entered (a column that
// takes a row away was active when that row was made, see step()), and only the newest
// input line is read and sheared per step. Reading and shearing the leaving line again
// instead of storing it costs a third more three-tap passes, and for the fused sweep a
// ring of X's rows and the oldest source rows read back from L3: the ring measured
// 0.87-0.94x of that time on two threads, 0.91-0.94x on one (bokeh-ab, 1080p RGBA,
// 15-255 px); the two differ by float rounding (1.2e-7: a column's shear is a vector or a
// scalar tap by where the call's range falls).
class SteepWindow {
public:
    // Input lines before `line0` are all zero; steps run from start() to ye.
    SteepWindow(double ex, double ey, int nc, int n_in, int x0, int x1, int line0, int read0, int ye)
        : nc_(nc), n_in_(n_in), x0_(x0), x1_(x1), read0_(read0), ye_(ye)
    {
        shear_ = std::abs(ex) >= 1e-9 * std::abs(ey);
        m_     = shear_ ? ex / ey : 0.0;
        const SegmentWeights sw(ey);
        first  = sw.first;
        last   = sw.last;
        wf_    = sw.newest;
        wl_    = sw.oldest;
        inner_ = sw.inner;
        // Every G column a line of the sweep or a read touches (the tap offsets are
        // monotonic in the row, so the ends decide).
        start_ = line0 + first;
        read0_ = std::max(read0_, start_);
        const int r0 = line0 - (last - first), r1 = ye - first;
        g0_ = std::min({ -tap_first(r0) - 2, -tap_first(r1) - 2, x0 + back_first(read0_),
                         x0 + back_first(ye - 1) });
        g1_ = std::max({ n_in - tap_first(r0), n_in - tap_first(r1), x1 + back_first(read0_) + 3,
                         x1 + back_first(ye - 1) + 3 });
        const size_t n = size_t(g1_ - g0_) * size_t(nc);
        zero_.assign(n, 0.0f);
        h_.assign(n, 0.0f);
        sum_.assign(n, 0.0);
        // Uninitialised: a row is read only over the columns it was made for.
        nring_  = last - first + 1;
        g_ring_ = Plane(g1_ - g0_, nring_, nc);
        g_tag_.assign(size_t(nring_), std::numeric_limits<int>::min());
    }
    int first = 0, last = 0;
    int start() const { return start_; }

    // The window moved to row y: `newest` is input line y - first (a span over the lines'
    // columns [0, n_in)).
    void step(int y, const RowSpan& newest)
    {
        // Active: the columns read at this step and the next last - first + 1, whose windows
        // are filling. The range drifts by under a column per step; a column joins with an
        // empty sum (all columns at the first step, whose earlier lines are zero) and,
        // until the first line it added is the one leaving, takes nothing away ("young":
        // no read reaches it before then). So a column that takes G row y - last away was
        // in the newest line's columns when that row was made, and the ring holds it there.
        const int span = last - first;
        const int y_far = std::min(std::max(y, read0_) + span + 1, ye_ - 1);
        const int f_now = back_first(std::max(y, read0_)), f_far = back_first(y_far);
        const int a = std::max(g0_, x0_ + std::min(f_now, f_far));
        const int b = std::min(g1_, x1_ + std::max(f_now, f_far) + 3);
        // Columns that joined span - 1 steps ago or earlier (or at the first step).
        const int f_old = back_first(std::min(std::max(y + 2, read0_ + span + 1), ye_ - 1));
        const int ma = m_ > 0.0 ? std::max(a, x0_ + f_old) : a;
        const int mb = m_ < 0.0 ? std::min(b, x1_ + f_old + 3) : b;
        // The newest line over one column more each side: the next step's range moves
        // by at most one, and there this line is its previous one.
        const int na = std::max(g0_, a - 1), nb = std::min(g1_, b + 1);
        const int rn = y - first;
        const size_t slot = ring_slot(rn, nring_);
        g_tag_[slot] = std::numeric_limits<int>::min();
        if (newest.p && nb > na) {
            g_row(newest, rn, na, nb, g_ring_.row(int(slot)));
            g_tag_[slot] = rn;
        }
        const float* gn = g_of(rn);
        const bool inner_rows = span >= 2;
        const float* enter = inner_rows ? g_of(rn - 1) : zero_.data();
        if (mb > ma) {
            const float* go = span > 0 ? g_of(y - last) : zero_.data();
            const size_t k = size_t(ma - g0_) * size_t(nc_);
            slide_window(sum_.data() + k, h_.data() + k, gn + k, enter + k,
                         (inner_rows ? go : zero_.data()) + k, go + k, wf_, inner_, wl_,
                         size_t(mb - ma) * size_t(nc_));
        }
        auto young = [&](int u0, int u1) {
            if (u1 <= u0)
                return;
            const size_t k = size_t(u0 - g0_) * size_t(nc_);
            slide_window(sum_.data() + k, h_.data() + k, gn + k, enter + k, zero_.data() + k,
                         zero_.data() + k, wf_, inner_, wl_, size_t(u1 - u0) * size_t(nc_));
        };
        young(a, std::min(ma, b));
        young(std::max(mb, a), b);
    }

    // o = (row y of the segment over [x0, x1) + add) * scale; add may be null.
    void read(int y, float* o, const float* add, float scale) const
    {
        const Taps t = Taps(-m_ * y, !shear_);
        const size_t k = size_t(x0_ + t.first - g0_) * size_t(nc_), n = size_t(x1_ - x0_) * size_t(nc_);
        if (shear_)
            taps_row(o, h_.data() + k, add, t.w[0], t.w[1], t.w[2], scale, size_t(nc_), n);
        else
            scaled_row(o, h_.data() + k + size_t(nc_), add, scale, n);
    }

private:
    // G row r from the ring, or zero where its line was black (or before the start).
    const float* g_of(int r) const
    {
        const size_t slot = ring_slot(r, nring_);
        return g_tag_[slot] == r ? g_ring_.row(int(slot)) : zero_.data();
    }
    int tap_first(int r) const { return shear_ ? Taps(m_ * r).first : -1; }
    int back_first(int y) const { return shear_ ? Taps(-m_ * y).first : -1; }
    // G row r over columns [a, b), into buf at its own offsets.
    void g_row(const RowSpan& line, int r, int a, int b, float* buf) const
    {
        shifted_row(buf + size_t(a - g0_) * size_t(nc_), line, nc_, a, b, Taps(m_ * r, !shear_),
                    !shear_);
    }

    int nc_, n_in_, x0_, x1_, read0_, ye_;
    bool shear_  = false;
    double m_    = 0.0, wf_ = 0.0, inner_ = 0.0, wl_ = 0.0;
    int g0_ = 0, g1_ = 0, start_ = 0, nring_ = 1;
    std::vector<float> zero_, h_;
    std::vector<double> sum_;
    Plane g_ring_;
    std::vector<int> g_tag_;  // the G row each ring slot holds (min(): none)
};

// out = (seg(in) + add) * scale, where seg(in)(p) = mean over t in [0, 1] of in(p - t e),
// e = (ex, ey) with |ex| <= |ey|; same-size planes, `in` read as zero outside `valid`,
// `out` written over `region` alone, `add` optional: a SteepWindow per fixed chunk of
// about 256 output columns, its lines the rows of `in` in place, so the cost does not
// depend on the length.
// `columns`: the same on the planes' columns (a flat segment, e = (ex, ey) then given as
// (ey, ex) and the regions with x and y swapped): each column is gathered into a line and
// each output line scattered back; a chunk is a band of rows whose cache lines serve four
// columns running, so nothing is transposed.
void segment_sweep(const Plane& in, const Region& valid, Plane& out, const Region& region,
                   double ex, double ey, const Plane* add, float scale, int nthreads,
                   bool columns = false)
{
    const int nc = in.nc;
    const size_t ncs = size_t(nc);
    // Pixel c of line r: in(c, r) along a row, in(r, c) down a column.
    const size_t along = columns ? in.stride() : ncs, across = columns ? ncs : in.stride();
    auto at = [&](const Plane& p, int line, int c) {
        return p.px.get() + size_t(line) * across + size_t(c) * along;
    };
    const SegmentWeights sw(ey);
    const int width = region.x1 - region.x0;
    // An output reads the input within the segment's width and three taps more.
    const int reach = int(std::ceil(std::abs(ex))) + 4;
    // Chunks of ~256 columns, at least two so the sweeps balance (fixed by the sizes alone).
    const int nchunks = std::max(2, (width + 255) / 256);
    const int chunk   = (width + nchunks - 1) / nchunks;
    parallel_for_chunks(0, nchunks, 1, nthreads, [&](int64_t ci, int64_t) {
        const int X0 = region.x0 + int(ci) * chunk, X1 = std::min(region.x1, X0 + chunk);
        if (X1 <= X0)
            return;
        // The input columns the chunk reads, [i0, i1): the window's coordinates start at i0.
        const int i0 = std::max(valid.x0, X0 - reach), i1 = std::max(i0, std::min(valid.x1, X1 + reach));
        const int n_in = i1 - i0;
        // Lines before valid.y0 are zero; outputs before the window's start read zero.
        SteepWindow win(ex, ey, nc, n_in, X0 - i0, X1 - i0, valid.y0, region.y0, region.y1);
        const size_t n = size_t(X1 - X0) * ncs;
        std::vector<float> newest(columns ? size_t(n_in) * ncs : 0),
            line_out(columns ? n : 0), line_add(columns && add ? n : 0);
        // Line r of `in` over [i0, i1): in place along a row, gathered down a column.
        auto line = [&](int r, std::vector<float>& buf) -> RowSpan {
            if (r < valid.y0 || r >= valid.y1 || n_in == 0)
                return {};
            if (!columns)
                return { at(in, r, i0), 0, n_in };
            copy_pixels(buf.data(), ncs, at(in, r, i0), along, n_in, nc);
            return { buf.data(), 0, n_in };
        };
        for (int y = std::min(win.start(), region.y0); y < region.y1; ++y) {
            if (y >= win.start())
                win.step(y, line(y - sw.first, newest));
            if (y < region.y0)
                continue;
            const float* a = nullptr;
            if (add && columns) {
                copy_pixels(line_add.data(), ncs, at(*add, y, X0), along, X1 - X0, nc);
                a = line_add.data();
            } else if (add) {
                a = at(*add, y, X0);
            }
            float* o = columns ? line_out.data() : at(out, y, X0);
            win.read(y, o, a, scale);
            if (columns)
                copy_pixels(at(out, y, X0), along, o, ncs, X1 - X0, nc);
        }
    });
}

// o[i] = (wf newest[i] + wl oldest[i] + inner (p1[i] - p0[i]) + add[i]) * scale: a
// segment along a row from its two end pixels and the prefix sums of the ones between
// (the difference of the sums in double, the rest in float, as slide_window).
BOKEH_HOT void band_row(float* o, const float* newest, const float* oldest, const double* p1,
                        const double* p0, const float* add, double wf, double inner, double wl,
                        float scale, size_t n)
{
    const float wf_f = float(wf), wl_f = float(wl);
    for (size_t i = 0; i < n; ++i) {
        const float v = float(inner * (p1[i] - p0[i])) + wf_f * newest[i] + wl_f * oldest[i];
        o[i] = (v + (add ? add[i] : 0.0f)) * scale;
    }
}

// o = (seg(row) + add) * scale over n values, for a segment along a row of npx pixels,
// black outside its span (none read past npx): output pixel x reads the row's pixels from
// x (the oldest, its i = last) to x + last - first (the newest). The row's prefix sums
// (double) go into `prefix` (npx + 1 pixels: 0 before the span, its total after it), and
// the end pixels outside the span are read from `zero` (n values of 0), so a row clipped
// by the frame is read in place (for_span_stretches).
void segment_row(float* o, const RowSpan& row, double* prefix, int npx, int nc,
                 const SegmentWeights& s, const float* add, float scale, size_t n,
                 const float* zero)
{
    const size_t ncs = size_t(nc);
    const int lo = row.p ? row.lo : 0, hi = row.p ? row.hi : 0;
    std::fill_n(prefix, size_t(lo) * ncs, 0.0);
    row_prefix(prefix + size_t(lo) * ncs, row.p ? row.p : zero, size_t(hi - lo), nc);
    const double* total = prefix + size_t(hi) * ncs;  // a copy per pixel: no chain through memory
    for (size_t i = size_t(hi + 1) * ncs, e = size_t(npx + 1) * ncs; i < e; i += ncs)
        std::copy_n(total, ncs, prefix + i);
    // The pixels between the two ends: prefix sums to before the newest, less to the oldest.
    const int offset[2] = { s.last - s.first, 0 };  // the newest, the oldest
    for_span_stretches<2>(row, offset, 2, int(n / ncs), [&](int x0, int x1) {
        const size_t k = size_t(x0) * ncs;
        band_row(o + k, span_pixel(row, x0 + offset[0], ncs, zero),
                 span_pixel(row, x0 + offset[1], ncs, zero), prefix + k + size_t(offset[0]) * ncs,
                 prefix + k + ncs, add ? add + k : nullptr, s.newest, s.inner, s.oldest, scale,
                 size_t(x1 - x0) * ncs);
    });
}

}  // namespace

namespace detail {

// out = (seg(in) + add) * scale over `region`, `in` read as zero outside `valid`, for any
// segment e: a sweep down the rows when e is steep, else a sweep along the columns. (A
// segment along the rows never comes here: with one, the hexagon takes hexagon_sweep.)
void segment_pass(const Plane& in, const Region& valid, Plane& out, const Region& region,
                  double ex, double ey, const Plane* add, float scale, int nthreads)
{
    if (std::abs(ey) >= std::abs(ex)) {
        segment_sweep(in, valid, out, region, ex, ey, add, scale, nthreads);
    } else {
        segment_sweep(in, transposed(valid), out, transposed(region), ey, ex, add, scale,
                      nthreads, true);
    }
}

// `r` grown by what a segment pass along e reads around an output: out(p) reads in(p - t e),
// t in [0, 1], through the shear's and the unshear's taps (a pixel each side each, so
// three with rounding), clipped to the plane.
Region grown_by(const Region& r, double ex, double ey, int w, int h)
{
    const int lx = int(std::ceil(std::max(0.0, ex))) + 3, hx = int(std::ceil(std::max(0.0, -ex))) + 3;
    const int ly = int(std::ceil(std::max(0.0, ey))) + 3, hy = int(std::ceil(std::max(0.0, -ey))) + 3;
    return { std::max(0, r.x0 - lx), std::max(0, r.y0 - ly), std::min(w, r.x1 + hx), std::min(h, r.y1 + hy) };
}

Region hull(const Region& a, const Region& b)
{
    return { std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1) };
}

// The hexagon in one sweep down the rows, when its third segment c runs along the rows
// (the upright hexagon in the transposed frame, the flat-topped one as given), the three
// rhombi grouped so that each steep segment runs once:
// out = (seg_a X + seg_c T) / 3 with T = seg_b in and X = seg_c in + T, i.e.
// rhombus(a, c) + rhombus(a, b) + rhombus(c, b). A steep segment is a window with a shear
// and an unshear; a segment along the rows is a row's prefix sums, the cheaper pass: two
// windows and two row passes, where hexagon_parallelograms' grouping
// ((seg_c (seg_a in + B) + seg_a B) / 3) takes three windows and one row pass (bokeh-ab:
// 0.91-0.95 of that sweep's time at 15-255 px, 1080p RGBA, two threads). seg_a and
// seg_c commute exactly (every step of a steep window runs along the rows or sums down
// the columns), so the two groupings differ only by float rounding.
// Each row of T is made once, summed along the row at once into X, and kept in a ring
// until seg_c T reads it; each row of X is seg_a's newest as it is made (the windows keep
// their own sheared rows). Each source line is read once (a ring keeps the few lines of
// a step and of a column batch) and each output row written once, no middle planes.
// Columns run in fixed chunks (column_chunks: two at 1080p), each over the columns its
// outputs read; the windows' sums restart per chunk but add the same values in the same
// order, so only the row prefix sums depend on where a chunk starts (float rounding).
void hexagon_sweep(const SweepIO& io, int nc, const Region& out_region, double ax, double ay,
                   double bx, double by, double cx, int nthreads)
{
    const size_t ncs = size_t(nc);
    // seg_c along the rows: an output x reads its row at x - i, i in [fc, lc].
    const SegmentWeights seg_c(cx);
    const int fc = seg_c.first, lc = seg_c.last;
    // seg_a reads X over [x - la, x + ha) around an output x (grown_by); seg_b reads the
    // source within its segment's width and three taps more.
    const int la = int(std::ceil(std::max(0.0, ax))) + 3, ha = int(std::ceil(std::max(0.0, -ax))) + 3;
    const int reach_b = int(std::ceil(std::abs(bx))) + 4;
    // seg_a reads X's rows up to `lead` ahead of the output row.
    const int lead = std::max(0, -SegmentWeights(ay).first);
    const int width   = out_region.x1 - out_region.x0;
    const int nchunks = column_chunks(width);
    const int chunk   = (width + nchunks - 1) / nchunks;
    parallel_for_chunks(0, nchunks, 1, nthreads, [&](int64_t ci, int64_t) {
        const int X0 = out_region.x0 + int(ci) * chunk, X1 = std::min(out_region.x1, X0 + chunk);
        if (X1 <= X0)
            return;
        const auto [Y0, Y1] = io.out_rows ? io.out_rows(X0, X1) : std::pair{ out_region.y0, out_region.y1 };
        // X over [xa, xb) (zero outside the frame); seg_c of T reads T over
        // [X0 - lc, X1 - fc), so T's rows span [t0, t1), made over [ta, tb) inside the frame
        // and zero elsewhere; seg_c of the source row reads it over [u0, u1); the source
        // lines over [i0, i1).
        const int xa = std::max(0, X0 - la), xb = std::min(io.w, X1 + ha);
        const int t0 = std::min(xa, X0 - lc), t1 = std::max(xb, X1 - fc);
        // T is black beyond seg_b's reach of the lit columns (at 255 px most of the left
        // chunk's margin).
        const int lit_x0 = std::max(0, io.lit.x0), lit_x1 = std::min(io.w, io.lit.x1);
        const int ta = std::max({ 0, t0, lit_x0 - reach_b });
        const int tb = std::max(ta + 1, std::min({ io.w, t1, lit_x1 + reach_b }));
        const int u0 = xa - lc, u1 = xb - fc;
        const int i0 = std::max(0, std::min(ta - reach_b, u0));
        const int i1 = std::min(io.w, std::max(tb + reach_b, u1)), ni = i1 - i0;
        const int x_end = Y1 + lead;  // X's and T's rows end here
        // Lines before the first lit one are black: seg_b starts with it, not at the top of
        // the padded frame (at 255 px its ~110 black rows were 6-8 % of the steps).
        const int lit_y0 = std::clamp(io.first_lit ? io.first_lit(i0, i1) : io.lit.y0, 0, io.h);
        SteepWindow seg_b(bx, by, nc, ni, ta - i0, tb - i0, lit_y0, std::numeric_limits<int>::min(),
                          x_end);
        // X's rows before x_lo are black: the source's before lit_y0, T's before seg_b's start.
        const int x_lo = std::min(lit_y0, seg_b.start());
        SteepWindow seg_a(ax, ay, nc, xb - xa, X0 - xa, X1 - xa, x_lo, Y0, Y1);
        // T's rows from y to y + lead in a ring; X only as the row of this step, which
        // seg_a takes as its newest at once (it keeps the sheared rows it needs).
        const size_t nt_px = size_t(t1 - t0) * ncs, nx_px = size_t(xb - xa) * ncs;
        const int nt = lead + 2;
        // T's ring starts black (its columns outside [ta, tb) stay so).
        std::vector<float> t_ring(size_t(nt + 1) * nt_px, 0.0f), x_now(nx_px);
        const float* t_zero = t_ring.data() + size_t(nt) * nt_px;
        auto t_slot = [&](int r) { return t_ring.data() + ring_slot(r, nt) * nt_px; };
        auto t_row  = [&](int r) -> const float* {
            return r >= seg_b.start() && r < x_end ? t_slot(r) : t_zero;
        };
        // Source lines from seg_c's (row r) to seg_b's newest (r - first).
        const int lines_lo = lead, lines_hi = lead - seg_b.first;
        // A missing line comes with the batch - 1 after it, so the ring holds that many more
        // (written whole before it is read, so uninitialised).
        const int batch  = std::max(1, io.batch);
        const int nlines = lines_hi - lines_lo + 2 + batch;
        Plane line_store(ni, nlines, nc);
        std::vector<RowSpan> line_span(static_cast<size_t>(nlines));
        std::vector<int> line_tag(size_t(nlines), std::numeric_limits<int>::min());
        std::vector<float*> fetch_bufs(static_cast<size_t>(batch));
        std::vector<RowSpan> fetched(static_cast<size_t>(batch));
        auto slot_of = [&](int r) { return ring_slot(r, nlines); };
        auto in_line = [&](int r) -> RowSpan {
            if (r < 0 || r >= io.h)
                return {};
            if (line_tag[slot_of(r)] != r) {
                const int n = std::min(batch, io.h - r);
                for (int i = 0; i < n; ++i)
                    fetch_bufs[size_t(i)] = line_store.row(int(slot_of(r + i)));
                io.lines(r, n, i0, i1, fetch_bufs.data(), fetched.data());
                for (int i = 0; i < n; ++i) {
                    line_tag[slot_of(r + i)] = r + i;
                    line_span[slot_of(r + i)] = fetched[size_t(i)];
                }
            }
            return line_span[slot_of(r)];
        };
        // The source row over [u0, u1) as seg_c reads it (its span moved from [i0, i1)).
        auto source_for_c = [&](int r) -> RowSpan {
            RowSpan line = in_line(r);
            if (!line.p)
                return {};
            const int lo = std::max(line.lo + i0, u0), hi = std::min(line.hi + i0, u1);
            if (hi <= lo)
                return {};
            return { line.p + size_t(lo - i0 - line.lo) * ncs, lo - u0, hi - u0 };
        };
        // Output rows for `store`, a batch at a time.
        const size_t no = size_t(X1 - X0) * ncs;
        const int nt_read = (X1 - fc) - (X0 - lc);  // T's pixels seg_c reads for [X0, X1)
        const size_t keep = size_t(io.keep);
        std::vector<float> ab_row(no), o_rows((keep + size_t(batch)) * no);
        std::vector<double> prefix(size_t(std::max(u1 - u0, t1 - t0) + 1) * ncs);
        const int y_first = std::min(seg_b.start(), x_lo) - lead;
        // Outputs may start above the first step (a grown window over black lines): those
        // read the windows' empty sums.
        for (int y = std::min({ y_first, seg_a.start(), Y0 }); y < Y1; ++y) {
            const int r = y + lead;  // the row of T and X made at this step
            if (r >= seg_b.start() && r < x_end) {
                seg_b.step(r, in_line(r - seg_b.first));
                seg_b.read(r, t_slot(r) + size_t(ta - t0) * ncs, nullptr, 1.0f);
            }
            // X's row r, seg_a's newest (y - seg_a.first = y + lead = r).
            const bool x_made = r >= x_lo && r < x_end;
            if (x_made)
                segment_row(x_now.data(), source_for_c(r), prefix.data(), u1 - u0, nc, seg_c,
                            t_row(r) + size_t(xa - t0) * ncs, 1.0f, nx_px, t_zero);
            if (y >= seg_a.start())
                seg_a.step(y, x_made ? RowSpan{ x_now.data(), 0, xb - xa } : RowSpan{});
            if (y < Y0)
                continue;
            seg_a.read(y, ab_row.data(), nullptr, 1.0f);
            float* o       = io.out_row(y, X0, X1);
            const int held = (y - Y0) % batch;  // rows held for `store` before this one
            float* row     = o_rows.data() + (keep + size_t(held)) * no;
            segment_row(row, RowSpan{ t_row(y) + size_t(X0 - lc - t0) * ncs, 0, nt_read },
                        prefix.data(), nt_read, nc, seg_c, ab_row.data(), float(1.0 / 3.0), no,
                        t_zero);
            // Past the caches (bokeh-ab: 0.93-0.97x flat-topped at 15-255 px; the upright
            // store's columns, streamed, measured 1.06x and stay plain).
            if (o)
                stream_floats(o, row, no);
            else if (held == batch - 1 || y == Y1 - 1) {
                io.store(y - held, held + 1, X0, X1, o_rows.data() + keep * no);
                if (keep > 0)  // the batch's last rows, for the next one
                    std::memmove(o_rows.data(), o_rows.data() + size_t(batch) * no, keep * no * sizeof(float));
            }
        }
        stream_fence();
    });
}

}  // namespace detail

}  // namespace bokeh
