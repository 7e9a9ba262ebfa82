// blur_approx.cpp — the fast approximations of the flat bokeh kernels, each measured
// against the exact kernel it stands for (bokeh-bench, tests/blur_test.cpp).
//
// Hexagon from three parallelograms (SEEDS.md section 5, seed 004; the rhombus split of
// McIntosh, Riecke and DiPaola 2012, "Efficiently simulating the bokeh of polygonal
// apertures in a post-process depth of field shader"). A hexagon with centre O and
// vertices P0..P5 is the union of the rhombi {a P(2j) + b P(2j+2) : a, b in [0, 1]},
// j = 0, 1, 2 (P1 = P0 + P2 for any affine image of a regular hexagon), so the uniform
// hexagon is the mean of three parallelogram kernels, and a parallelogram is the
// convolution of two uniform segments. With a, b, c the three segment directions, four
// segment passes make it: B = seg_b in, S = seg_a in + B, then (seg_c S + seg_a B) / 3.
// Each segment pass costs the same whatever its length: along its major axis it is a
// running sum (in double; fractional ends weighted by overlap); across, the plane is
// sheared so the segment runs down a column, and sheared back, each time with the
// three-tap quadratic B-spline. The interpolations keep energy and the centroid exactly
// and soften the kernel's slanted edges by under a pixel; that is the method's error
// against the exact hexagon.
// Changed for speed (issue 3): a steep segment's shear moves whole rows, so its pass is
// one sweep down the rows per chunk of columns (a SteepWindow, the one the fused sweep
// uses; its own strip sweep before measured 2-8 % faster, A/B, at rotations 7-20), each
// sheared row made once, when it enters the window, and kept in a ring until it leaves
// (session 12: 0.87-0.94x of the time of shearing the leaving row again), nothing
// transposed; the passes run in the
// frame (as given, or transposed when the plane is padded, see blur.cpp) where two of the
// three directions are steep, and the third, at rotations other than multiples of 30
// degrees, is sheared too and sweeps along the columns (gathered per line); along the rows
// (the upright and the flat-topped hexagon) the fused sweep below takes over. Each pass
// computes only the region the later ones read. Planes are
// reused once their values are used up, and allocated on huge pages (plane.h): the first
// touch of a fresh 1080p plane costs about half a pass even so. Measured (docs/benchmarks.md):
// 54-57 ms at 15-255 px for 1080p RGBA on two threads (session 13's machine; 67-92 on the
// one before), bound by memory traffic (four passes, the padding and, upright, the
// transposing copies). Since session 14 only a hexagon stretched so far that no shear
// leaves two of its segments steep takes them (45 x 15 px at 20 degrees, say): every other
// one the sweeps below, on the source or (iris mode) on the padded plane.
// Fused (issue 3): when the third segment runs along the rows of the working frame (the
// upright and the flat-topped hexagon, every rotation by a multiple of 30 degrees), one
// sweep down the rows makes the hexagon (hexagon_sweep), the rhombi grouped so that each
// steep segment runs once: two windows, on the source and on a ring of rows, and two sums
// along the rows (row prefix sums, the cheaper pass), where the four passes take three
// steep windows. Outside iris mode (hexagon_direct) it reads the source ImageBuf directly
// (the upright hexagon's lines are its columns, gathered once each into a ring; the
// flat-topped one's rows in place, under the black border also where the chunk reaches
// past the data window: RowSpan, the black read from a zero run) and writes `dst`
// directly: no padded or transposed copies. Measured A/B against the four
// passes at 15-255 px (1080p RGBA, two threads): 0.56-0.68 of their time upright,
// 0.42-0.53 flat-topped (session 9, with three windows). The upright sweep reads the
// source's columns and writes the destination's 16 at a time (kColumnBatch; one at a time
// a 1920 px frame's column falls in 2 of L1's 64 cache sets): 0.79-0.92x its time before
// (session 10).
// Known limit: 10-14 ms flat-topped and 11-18 upright at 15-255 px (1080p RGBA, two
// threads, session 13's machine), growing 1.36x and 1.66x from 15 to 255 px: the windows
// cover the chunk, c's length and their span's drift, and sweep the kernel's reach above
// and below the frame (~1.25x the work at 255 px; the upright frame's chunks are 540
// columns, so twice the share), and T's ring and the windows' rings of sheared rows (~6 MB
// a chunk at 255 px) are out of the 1 MiB L2 (~15-20 % of the 255 px time; see
// docs/benchmarks.md, session 13). Rotations off multiples of 30 degrees take the sheared
// sweep: ~1.3x the upright sweep's time (transposed frame) and 1.5-1.9x the flat-topped's
// (as given), 20-40 ms at 15-255 px in session 14's runs (a slow phase of the machine),
// 35.7-37.7 dB at 15 px. The window
// slides (double running sums) take ~20 % of the sweep's time, the shears' and unshears' three-tap reads ~17 %, the row
// sums ~25 %; upright, the column gathers and scatters ~22 % more. Float sums, a fused
// step, L1-sized blocks, narrower chunks and aligned buffers each changed the time by 11 %
// or less (session 9, docs/benchmarks.md); so did row sums in L1-sized tiles and rings on
// huge pages (session 11); an upright sweep without transposing (flat windows) lost 5-8 dB
// to the sampling of flat lines by rows.
// Sheared (issue 3, session 14): at other rotations one segment lies within 30 degrees of
// the rows and one within 30 of the columns; the frame's columns (or, transposed, its
// rows) are sheared through the B-spline's taps so that one of them runs along the
// working rows, the fused sweep runs there, and each output reads the result back through
// the taps (hexagon_sheared_direct): no padded planes, the lines gathered and the outputs
// scattered as the sweep goes. Of the two frames the cost model takes the cheaper (the
// sweep's lines grow by |m| per column of a chunk). A session-13 try sheared whole planes
// before and after the sweep (0.87-1.15x of the four passes: the planes' traffic and page
// faults); gathered per line it measured 0.42-0.59x of the four passes (A/B, 15-255 px,
// 1080p RGBA, two threads). The two extra B-spline reads smooth across the lines by
// 1/2 px^2 more than the upright and flat-topped sweeps do.
//
// Bands (disk, polygon): the exact kernel's rows are grouped into a few horizontal bands
// (boundaries by dynamic programming, least squares on the row areas; over the lower half,
// mirrored, for a kernel symmetric in y, else over all rows), each band's rows
// replaced by one interval of the same mean area and centre, anti-aliased at its ends;
// the bands are rectangles, so the cost depends on the band count, not the kernel size.
// Changed for speed (issue 3): outside iris mode (convolve_bands_direct) each task walks
// down a strip of output columns reading the source once: a row's double prefix sums give
// every band profile's horizontal sum (a band and its mirror image share one), kept in a
// ring of the last 2 ry + 2 rows, and one double running total slides down the rows, each
// band window adding the row entering it and taking away the row leaving it. Before,
// a summed-area table (Crow 1984) was built per output tile (its building grew with the
// kernel's reach) or for the whole frame (68-77 MB at 1080p); convolve_banded keeps that
// plane path for iris mode.
//
// Bilinear taps (SEEDS.md section 5): the seed's 9x9 disk from 25 bilinear fetches and
// a 17x17 one from 81. The taps are grouped 2 (or 1, the centre) per axis; a fetch sits
// at the area-weighted centroid of its group, weighted by the group's disk area, so its
// bilinear footprint matches the group's marginals but not its joint weights. On a GPU
// the fetches are free; on a CPU we convolve with the kernel they add up to.
//
// Reduced (SEEDS.md sections 4 and 6, the reduced buffers of issue 4 applied to one
// uniform kernel): the source reduced by N, any real factor (area mean; with the black
// border the blocks straddling the data window count the outside as 0, so energy is
// kept), the kernel scaled by 1/N and applied exactly there, the result enlarged
// bilinearly straight into `dst` (bilinear: no ringing around 1e6 highlights, which
// Catmull-Rom gives for 1-2 dB more). The cost falls as N^3 (pixels / N^2, row spans /
// N) down to the reduction and enlargement; the error is the detail lost under 1/N of
// the kernel, so the automatic N keeps the reduced kernel 25 px across. Measured on
// bokeh-bench's crop of the "lights" frame, against the exact disk: 41.0-51.2 dB from
// 38 to 255 px, with D = 63 at 41.3 dB in 21-23 ms (6 bands: 41.1 dB in 42-44 ms).
// Known limit: not for iris mode. Run on exp(k x) (and back by log / k before the
// enlargement) it measured 20 dB against the exact iris blur: a block's mean of exp(k x)
// is its brightest pixel's, so every highlight grows by up to a block.
//
// Known limits: the parallelogram split is for six-bladed straight apertures only;
// bands do not model a catadioptric hole. Iris mode's whole-frame summed-area table is
// double: an image whose total energy exceeds ~1e12 loses digits in dark areas (none of
// the test scenes comes within 1e4 of it); the direct path's prefix sums span one strip's
// row only.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>
#include <bokeh/resample.h>

#include "plane.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <optional>

namespace bokeh {

using namespace detail;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Pixel i's share of the interval [a, b]: the length of [i - 1/2, i + 1/2] inside it,
// over b - a. `first` is the first pixel with a share; `w` the shares from there.
struct IntervalWeights {
    int first = 0;
    std::vector<double> w;
    int last() const { return first + int(w.size()) - 1; }
};

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

// --- hexagon from three parallelograms -----------------------------------------------

// Quadratic B-spline weights for reading a row at real position p: three taps from
// `first`, sum 1, centroid exactly p. Linear interpolation (two taps) also keeps both,
// but its response to a thin line depends on the line's phase ((1 - f)^2 + f^2 at
// coincidence): two sheared passes crossing each other then leave a 20 % moire inside
// the hexagon; the B-spline's phase dependence is an order smaller.
struct Taps {
    int first;
    float w[3];
    explicit Taps(double p, bool on_grid = false)
    {
        const double n = std::floor(p + 0.5), d = p - n;  // d in [-1/2, 1/2)
        first = int(n) - 1;
        if (on_grid) {  // no shear: read the pixel itself, no smoothing
            w[0] = w[2] = 0.0f;
            w[1]        = 1.0f;
            return;
        }
        w[0]  = float(0.5 * (0.5 - d) * (0.5 - d));
        w[1]  = float(0.75 - d * d);
        w[2]  = float(0.5 * (0.5 + d) * (0.5 + d));
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
// two ends need no double, and their conversions are saved (session 11, with band_row's
// the same: A/B 0.89-0.98x of the sweep's time).
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

// A rectangle of plane pixels, [x0, x1) x [y0, y1).
struct Region {
    int x0, y0, x1, y1;
};

// The same rectangle in the transposed frame.
Region transposed(const Region& r) { return { r.y0, r.x0, r.y1, r.x1 }; }

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
// input line is read and sheared per step. Before (sessions 9-11) the leaving line was
// read and sheared again, not stored: a third of the three-tap passes, and for the fused
// sweep a ring of X's rows and the oldest source rows read back from L3. A/B (1080p RGBA,
// 15-255 px, session 12): 0.87-0.94x two threads, 0.91-0.94x one; float rounding apart
// (1.2e-7: a column's shear is a vector or a scalar tap by where the call's range falls).
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


// Where the fused sweep reads and writes, in its working frame of w x h pixels: `lines`
// gives lines r .. r + n - 1 over columns [c0, c1) (lines[i] a view or filled into
// bufs[i], its span relative to c0; no pixels when all black), `out_row` where output
// row y goes over [x0, x1), or null to hand the rows to `store`, up to `batch` at once (y .. y + n - 1, one after another).
// A batch of more than one line suits a source read down its columns (hexagon_direct).
// `keep`: the rows handed to `store` come with the `keep` rows before them in memory
// (rows - keep * row length on; those before the chunk's first row undefined), for a
// store that reads taps across batches (the sheared frame's unshear).
// `lit`: lines and columns outside it are black (the source's data window under the black
// border), so no window slides before its first lit line, nor makes T where no lit column
// reaches. `first_lit`, where given, says the first line with a lit pixel in columns
// [c0, c1) instead of lit.y0; `out_rows` the output rows [y0, y1) a chunk of columns
// [x0, x1) needs instead of the out region's (the sheared frame, where they drift with x).
struct SweepIO {
    int w = 0, h = 0;
    int batch = 1, keep = 0;
    Region lit{ 0, 0, std::numeric_limits<int>::max(), std::numeric_limits<int>::max() };
    std::function<int(int c0, int c1)> first_lit;
    std::function<std::pair<int, int>(int x0, int x1)> out_rows;
    std::function<void(int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines)> lines;
    std::function<float*(int y, int x0, int x1)> out_row;
    std::function<void(int y, int n, int x0, int x1, const float* rows)> store;
};

// The hexagon in one sweep down the rows, when its third segment c runs along the rows
// (the upright hexagon in the transposed frame, the flat-topped one as given), the three
// rhombi grouped so that each steep segment runs once:
// out = (seg_a X + seg_c T) / 3 with T = seg_b in and X = seg_c in + T, i.e.
// rhombus(a, c) + rhombus(a, b) + rhombus(c, b). A steep segment is a window with a shear
// and an unshear; a segment along the rows is a row's prefix sums, the cheaper pass: two
// windows and two row passes, where hexagon_parallelograms' grouping
// ((seg_c (seg_a in + B) + seg_a B) / 3) takes three windows and one row pass (session 11:
// A/B 0.91-0.95 of that sweep's time at 15-255 px, 1080p RGBA, two threads). seg_a and
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
            // Past the caches (session 13: A/B 0.93-0.97x flat-topped at 15-255 px; the
            // upright store's columns, streamed, measured 1.06x and stay plain).
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

// Vertex i of the kernel's hexagon in pixel offsets (y down), as kernel.cpp places them.
std::pair<double, double> hexagon_vertex(const Kernel& k, int i)
{
    const double theta = kPi * (90.0 + k.rotation_deg + 60.0 * i) / 180.0;
    return { 0.5 * k.width_px * std::cos(theta), -0.5 * k.height_px * std::sin(theta) };
}

// --- the banded kernel's rectangles (its runs of equal rows) -----------------------------

struct Rect {
    int y0, y1, x0, x1;  // offsets, inclusive
    double weight;       // per pixel
};

// Runs of identical rows of the kernel's skyline spans, merged into rectangles.
std::vector<Rect> kernel_rects(const KernelWeights& k)
{
    std::vector<Rect> rects;
    std::vector<Span> open_spans;  // the spans of the previous row, with their rect index
    std::vector<size_t> open_index;
    int row = std::numeric_limits<int>::min();
    std::vector<Span> spans = kernel_spans(k);
    size_t i = 0;
    while (i < spans.size()) {
        const int dy = spans[i].dy;
        std::vector<Span> cur;
        for (; i < spans.size() && spans[i].dy == dy; ++i)
            cur.push_back(spans[i]);
        std::vector<size_t> idx;
        const bool continues = row == dy - 1 && cur.size() == open_spans.size()
                               && std::equal(cur.begin(), cur.end(), open_spans.begin(),
                                             [](const Span& a, const Span& b) {
                                                 return a.x0 == b.x0 && a.x1 == b.x1
                                                        && a.weight == b.weight;
                                             });
        for (size_t j = 0; j < cur.size(); ++j) {
            if (continues) {
                rects[open_index[j]].y1 = dy;
                idx.push_back(open_index[j]);
            } else {
                rects.push_back({ dy, dy, cur[j].x0, cur[j].x1, cur[j].weight });
                idx.push_back(rects.size() - 1);
            }
        }
        open_spans = cur;
        open_index = idx;
        row        = dy;
    }
    return rects;
}

// --- bands by running sums down the rows ---------------------------------------------------

// One bar of a band's rows in the reflected kernel: weight on offsets x0 .. x1.
struct Bar {
    int x0, x1;
    double weight;
    bool operator==(const Bar& o) const { return x0 == o.x0 && x1 == o.x1 && weight == o.weight; }
};

// The rows of one horizontal profile (a band and its mirror image share one): the bars
// along x, and the runs of kernel rows [y0, y1] (offsets) it covers.
struct Profile {
    std::vector<Bar> bars;
    std::vector<std::pair<int, int>> windows;
};

std::vector<Profile> band_profiles(const KernelWeights& banded)
{
    std::map<std::pair<int, int>, std::vector<Bar>> by_rows;
    for (const Rect& r : kernel_rects(reflected(banded)))
        by_rows[{ r.y0, r.y1 }].push_back({ r.x0, r.x1, r.weight });
    std::vector<Profile> profiles;
    for (const auto& [rows, bars] : by_rows) {
        auto same = std::find_if(profiles.begin(), profiles.end(),
                                 [&](const Profile& p) { return p.bars == bars; });
        if (same == profiles.end())
            profiles.push_back({ bars, { rows } });
        else
            same->windows.push_back(rows);
    }
    return profiles;
}

// h[i] = sum over the bars of w (p[i + hi] - p[i + lo]): one profile of a prefix row.
BOKEH_HOT void profile_row(float* h, const double* p, const size_t* hi, const size_t* lo,
                           const double* w, size_t nbars, size_t n)
{
    if (nbars == 1) {
        for (size_t i = 0; i < n; ++i)
            h[i] = float(w[0] * (p[i + hi[0]] - p[i + lo[0]]));
        return;
    }
    if (nbars == 2) {
        for (size_t i = 0; i < n; ++i)
            h[i] = float(w[0] * (p[i + hi[0]] - p[i + lo[0]]) + w[1] * (p[i + hi[1]] - p[i + lo[1]]));
        return;
    }
    if (nbars == 3) {
        for (size_t i = 0; i < n; ++i)
            h[i] = float(w[0] * (p[i + hi[0]] - p[i + lo[0]]) + w[1] * (p[i + hi[1]] - p[i + lo[1]])
                         + w[2] * (p[i + hi[2]] - p[i + lo[2]]));
        return;
    }
    for (size_t i = 0; i < n; ++i) {
        double s = 0.0;
        for (size_t b = 0; b < nbars; ++b)
            s += w[b] * (p[i + hi[b]] - p[i + lo[b]]);
        h[i] = float(s);
    }
}

// t[i] += sum over k < count of (add[k][i] - sub[k][i]), the differences in double.
BOKEH_HOT void slide_rows(double* t, const float* const* add, const float* const* sub,
                          size_t count, size_t n)
{
    size_t k = 0;
    for (; k + 4 <= count; k += 4) {
        const float *a0 = add[k], *a1 = add[k + 1], *a2 = add[k + 2], *a3 = add[k + 3];
        const float *s0 = sub[k], *s1 = sub[k + 1], *s2 = sub[k + 2], *s3 = sub[k + 3];
        for (size_t i = 0; i < n; ++i)
            t[i] += ((double(a0[i]) - double(s0[i])) + (double(a1[i]) - double(s1[i])))
                    + ((double(a2[i]) - double(s2[i])) + (double(a3[i]) - double(s3[i])));
    }
    for (; k < count; ++k)
        for (size_t i = 0; i < n; ++i)
            t[i] += double(add[k][i]) - double(sub[k][i]);
}

}  // namespace

namespace detail {

// Flat in the size, nearly linear in the band count: measured (1080p RGBA, two threads,
// session 9) 33-35 ms with 4 bands and 41-48 with 8 at 15-37 px, i.e. 5.5 + 0.67 ns a
// pixel and channel per band on one thread (a pentagon's 16 bands over all its rows: 62-70
// ms at 23-44 px, 15 ns); spans_cost_ns reads a disk's spans right (1.0-1.06 of measured
// at 15 and 63 px), so the two compare as they are.
double bands_cost_ns(int w, int h, int bands, bool mirrored)
{
    const int split = mirrored ? bands : 2 * bands;  // as banded_from splits
    return double(w) * double(h) * (5.5 + 0.67 * double(split));
}

bool convolve_bands_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                           const KernelWeights& banded, Border border, int nthreads)
{
    constexpr int kStrip = 256;
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    const int w = roi.width(), h = roi.height(), rx = banded.rx, ry = banded.ry;
    const std::vector<Profile> profiles = band_profiles(banded);
    // Per profile, its bars as offsets into a prefix row that starts rx columns left of
    // the strip: output x sums row pixels x + x0 .. x + x1 = prefix[x + rx + x1 + 1] -
    // prefix[x + rx + x0].
    std::vector<size_t> hi, lo, first_bar;
    std::vector<double> weight;
    for (const Profile& p : profiles) {
        first_bar.push_back(hi.size());
        for (const Bar& b : p.bars) {
            hi.push_back(size_t(rx + b.x1 + 1) * ncs);
            lo.push_back(size_t(rx + b.x0) * ncs);
            weight.push_back(b.weight);
        }
    }
    first_bar.push_back(hi.size());
    size_t nwindows = 0;
    for (const Profile& p : profiles)
        nwindows += p.windows.size();
    const int ring = 2 * ry + 2;  // padded rows y - 1 .. y + 2 ry are in use at output row y
    const size_t np = profiles.size();
    const int nstrips = (w + kStrip - 1) / kStrip;
    parallel_for_chunks(0, nstrips, 1, nthreads, [&](int64_t s, int64_t) {
        const int xs = int(s) * kStrip, xe = std::min(w, xs + kStrip);
        const size_t n = size_t(xe - xs) * ncs;
        const size_t npx = size_t(xe - xs + 2 * rx);
        std::vector<float> row(npx * ncs), rows(np * size_t(ring) * n), out_row(n);
        std::vector<double> prefix((npx + 1) * ncs), total(n);
        std::vector<const float*> add(nwindows), sub(nwindows);
        auto ring_row = [&](size_t p, int j) { return rows.data() + (p * size_t(ring) + size_t(j % ring)) * n; };
        // Padded row j (source row roi.ybegin - ry + j) through every profile.
        auto horizontal = [&](int j) {
            const int x0   = roi.xbegin + xs - rx, x1 = roi.xbegin + xe + rx;
            const float* v = bordered_row_view(in, roi.ybegin - ry + j, x0, x1, border, row.data());
            if (!v) {
                for (size_t p = 0; p < np; ++p)
                    std::fill_n(ring_row(p, j), n, 0.0f);
                return;
            }
            row_prefix(prefix.data(), v, npx, nc);
            for (size_t p = 0; p < np; ++p)
                profile_row(ring_row(p, j), prefix.data(), hi.data() + first_bar[p],
                            lo.data() + first_bar[p], weight.data() + first_bar[p],
                            first_bar[p + 1] - first_bar[p], n);
        };
        for (int j = 0; j < 2 * ry; ++j)
            horizontal(j);
        for (int y = 0; y < h; ++y) {
            horizontal(y + 2 * ry);
            // Kernel row dy of output row y is padded row y + ry + dy; each window slides
            // down by one row: its row y1 enters, the row above y0 leaves.
            if (y == 0) {
                std::fill(total.begin(), total.end(), 0.0);
                for (size_t p = 0; p < np; ++p)
                    for (const auto& [y0, y1] : profiles[p].windows)
                        for (int dy = y0; dy <= y1; ++dy)
                            add_scaled(total.data(), ring_row(p, ry + dy), 1.0, n);
            } else {
                size_t k = 0;
                for (size_t p = 0; p < np; ++p)
                    for (const auto& [y0, y1] : profiles[p].windows) {
                        add[k]   = ring_row(p, y + ry + y1);
                        sub[k++] = ring_row(p, y - 1 + ry + y0);
                    }
                slide_rows(total.data(), add.data(), sub.data(), nwindows, n);
            }
            to_float(out_row.data(), total.data(), n);
            stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + y)),
                          out_row.data(), n);
        }
        stream_fence();
    });
    return true;
}

// The plane path, for iris mode: a whole-frame summed-area table (Crow 1984), four reads
// a rectangle.
Plane convolve_banded(const Plane& in, const KernelWeights& kernel, int nthreads)
{
    const int nc = in.nc;
    Plane out(in.w - 2 * kernel.rx, in.h - 2 * kernel.ry, nc);
    const KernelWeights k         = reflected(kernel);
    const std::vector<Rect> rects = kernel_rects(k);

    // S[y][(x + 1) nc + c] = sum of in over rows < y, columns <= x (row 0 is zeros).
    const size_t sstride = size_t(in.w + 1) * size_t(nc);
    std::unique_ptr<double[]> sat(new double[size_t(in.h + 1) * sstride]);
    std::fill_n(sat.get(), sstride, 0.0);
    row_prefix_sums(in, sat.get() + sstride, nthreads);
    // Down the columns, in strips so each task owns its columns.
    constexpr size_t kStrip = 512;
    parallel_for_chunks(0, int64_t((sstride + kStrip - 1) / kStrip), 1, nthreads, [&](int64_t s, int64_t) {
        const size_t i0 = size_t(s) * kStrip, i1 = std::min(sstride, i0 + kStrip);
        for (int y = 2; y <= in.h; ++y) {
            double* p       = sat.get() + size_t(y) * sstride;
            const double* q = p - sstride;
            for (size_t i = i0; i < i1; ++i)
                p[i] += q[i];
        }
    });

    accumulate_in_strips(out, nthreads, [&](int y, size_t i0, std::vector<double>& acc) {
        const size_t n = acc.size();
        for (const Rect& r : rects) {
            // Rows y + ry + y0 .. y + ry + y1 of `in`: SAT rows (y + ry + y0) and (.. y1 + 1).
            const double* top = sat.get() + size_t(y + k.ry + r.y0) * sstride + i0;
            const double* bot = sat.get() + size_t(y + k.ry + r.y1 + 1) * sstride + i0;
            const size_t hi = size_t(k.rx + r.x1 + 1) * size_t(nc), lo = size_t(k.rx + r.x0) * size_t(nc);
            add_span(acc.data(), bot + hi, bot + lo, r.weight, n);
            add_span(acc.data(), top + lo, top + hi, r.weight, n);
        }
    });
    return out;
}

}  // namespace detail

// --- public --------------------------------------------------------------------------

double reduction_factor(const Kernel& k)
{
    double across = std::min(k.width_px, k.height_px);
    if (k.shape == KernelShape::Gaussian) {
        const auto [sx, sy] = gaussian_sigma(k);
        across = 4.0 * std::min(sx, sy);
    }
    // 25 px for a disk: the smallest that keeps 40 dB on bokeh-bench's crop at every size
    // (24 px gave 39.9 dB at 63 px). The layered defocus found the same on its scenes: its
    // 40 dB budget keeps reduced kernels of 24 px (settings_for_budget, defocus.cpp).
    // 30 px for a polygon, whose straight edges and corners lose more: at 25 px the crop
    // measured 38.4-38.7 dB for a pentagon and 38.8-39.8 for a hexagon from 56 to 80 px;
    // at 30 px, 40.4-48.4 (pentagon), 41.1-44.4 (hexagon) and 42.3-50.2 (octagon) from 56
    // to 255 px.
    const double reduced_px = k.shape == KernelShape::Polygon ? 30.0 : 25.0;
    const double n = across / reduced_px;
    return n < 1.5 ? 1.0 : std::min(n, 8.0);
}

KernelWeights banded_weights(const Kernel& k, int bands, int nthreads)
{
    return detail::banded_from(kernel_weights(k, nthreads), bands);
}

namespace detail {

KernelWeights banded_from(const KernelWeights& exact, int bands)
{
    if (exact.is_identity() || bands < 1)
        return exact;
    // A kernel symmetric in y (a disk, a polygon with an even number of blades) is split
    // over rows 0..ry of its lower half and the split mirrored; any other (a pentagon) over
    // all its rows -ry..ry, with twice the bands. (Before, every kernel was mirrored: a
    // pentagon's upper half became its lower half's mirror image, 28-32 dB against the exact
    // pentagon at 23-44 px, a heptagon 33-38; session 9.)
    double peak = 0.0;
    for (double v : exact.w)
        peak = std::max(peak, v);
    bool mirrored = true;
    for (int r = 1; r <= exact.ry && mirrored; ++r)
        for (int dx = -exact.rx; dx <= exact.rx && mirrored; ++dx)
            mirrored = std::abs(exact.at(dx, r) - exact.at(dx, -r)) <= 1e-12 * peak;
    const int row0 = mirrored ? 0 : -exact.ry;  // band row r is kernel row row0 + r
    const int n    = exact.ry + 1 - row0;
    std::vector<double> area(static_cast<size_t>(n)), centre(static_cast<size_t>(n));
    for (int r = 0; r < n; ++r) {
        double a = 0.0, c = 0.0;
        for (int dx = -exact.rx; dx <= exact.rx; ++dx) {
            a += exact.at(dx, row0 + r);
            c += dx * exact.at(dx, row0 + r);
        }
        area[size_t(r)]   = a;
        centre[size_t(r)] = a > 0.0 ? c / a : 0.0;
    }
    // Least-squares split of rows 0..n-1 into at most `bands` runs (dynamic programming
    // over prefix sums: cost of a run = sum of (area - mean)^2).
    std::vector<double> s1(size_t(n) + 1, 0.0), s2(size_t(n) + 1, 0.0);
    for (int r = 0; r < n; ++r) {
        s1[size_t(r) + 1] = s1[size_t(r)] + area[size_t(r)];
        s2[size_t(r) + 1] = s2[size_t(r)] + area[size_t(r)] * area[size_t(r)];
    }
    auto run_cost = [&](int i, int j) {  // rows [i, j)
        const double s = s1[size_t(j)] - s1[size_t(i)];
        return (s2[size_t(j)] - s2[size_t(i)]) - s * s / (j - i);
    };
    const int nb = std::min(mirrored ? bands : 2 * bands, n);
    const double inf = std::numeric_limits<double>::infinity();
    std::vector<std::vector<double>> best(size_t(nb) + 1, std::vector<double>(size_t(n) + 1, inf));
    std::vector<std::vector<int>> cut(size_t(nb) + 1, std::vector<int>(size_t(n) + 1, 0));
    best[0][0] = 0.0;
    for (int b = 1; b <= nb; ++b)
        for (int j = 1; j <= n; ++j)
            for (int i = b - 1; i < j; ++i)
                if (best[size_t(b) - 1][size_t(i)] < inf) {
                    const double c = best[size_t(b) - 1][size_t(i)] + run_cost(i, j);
                    if (c < best[size_t(b)][size_t(j)]) {
                        best[size_t(b)][size_t(j)] = c;
                        cut[size_t(b)][size_t(j)]  = i;
                    }
                }
    std::vector<int> starts;
    for (int b = nb, j = n; b > 0; j = cut[size_t(b)][size_t(j)], --b)
        starts.push_back(cut[size_t(b)][size_t(j)]);
    std::reverse(starts.begin(), starts.end());
    starts.push_back(n);

    KernelWeights out;
    out.rx = exact.rx + 1;  // an interval of the mean width may end a pixel further out
    out.ry = exact.ry;
    const int onx = 2 * out.rx + 1;
    out.w.assign(size_t(onx) * size_t(2 * out.ry + 1), 0.0);
    for (size_t b = 0; b + 1 < starts.size(); ++b) {
        const int i = starts[b], j = starts[b + 1];
        double a = 0.0, c = 0.0;
        for (int r = i; r < j; ++r) {
            a += area[size_t(r)];
            c += centre[size_t(r)] * area[size_t(r)];
        }
        const double mean_area = a / (j - i), mean_centre = a > 0.0 ? c / a : 0.0;
        if (mean_area <= 0.0)
            continue;
        const double len = mean_area / peak;  // an interval at the kernel's full level
        const IntervalWeights iw = interval_weights(mean_centre - 0.5 * len, mean_centre + 0.5 * len);
        for (int r = i; r < j; ++r)
            for (int sign : { 1, -1 }) {
                if (sign < 0 && (r == 0 || !mirrored))
                    continue;
                const int dy = sign * (row0 + r);
                for (size_t q = 0; q < iw.w.size(); ++q) {
                    const int dx = iw.first + int(q);
                    if (std::abs(dx) <= out.rx)
                        out.w[size_t((dy + out.ry) * onx + (dx + out.rx))] = iw.w[q] * mean_area;
                }
            }
    }
    double sum = 0.0;
    for (double v : out.w)
        sum += v;
    for (double& v : out.w)
        v /= sum;
    return out;
}

// The banded kernel's error is in its edge rows, and on an image it grows with the kernel at
// equal L1 distance: on bokeh-bench's crop of the lights frame (disk, pentagon, heptagon,
// octagon at 0 and 22.5 degrees, 21-47 px, 2-8 bands; session 10), a distance of 0.049
// gave 38.9 dB at 47 px and 0.075 gave 40.9 at 21 px. Distance times the square root of
// the size under 0.27 kept all 490 cases at 41.0 dB or more (the least: a heptagon, 31
// px, 6 bands); the fewest bands within it are 4-6 for a disk at 21-47 px, 4-8 for the
// others. Calibrated on one frame, so a bound with ~1 dB to spare, not a guarantee.
int fast_band_count(const KernelWeights& exact, double size_px)
{
    constexpr int kFewest = 3, kMost = 8;
    for (int bands = kFewest; bands < kMost; ++bands) {
        const KernelWeights banded = banded_from(exact, bands);
        double l1 = 0.0;  // banded's grid is exact's, a column wider each side
        for (int dy = -banded.ry; dy <= banded.ry; ++dy)
            for (int dx = -banded.rx; dx <= banded.rx; ++dx)
                l1 += std::abs(banded.at(dx, dy) - (std::abs(dx) <= exact.rx ? exact.at(dx, dy) : 0.0));
        if (l1 * std::sqrt(size_px) < 0.27)
            return bands;
    }
    return kMost;
}

}  // namespace detail

KernelWeights bilinear_tap_weights(const Kernel& k, int* fetches)
{
    const KernelWeights exact = kernel_weights(k);
    // Pixels grouped per axis: the centre alone, then pairs outward.
    auto groups = [](int r) {
        std::vector<std::pair<int, int>> g;  // [first, last]
        for (int a = -r; a < 0; a += 2)
            g.push_back({ a, std::min(a + 1, -1) });
        g.push_back({ 0, 0 });
        for (int a = 1; a <= r; a += 2)
            g.push_back({ a, std::min(a + 1, r) });
        return g;
    };
    const auto gx = groups(exact.rx), gy = groups(exact.ry);
    KernelWeights out{ exact.rx, exact.ry, std::vector<double>(exact.w.size(), 0.0) };
    const int nx = 2 * exact.rx + 1;
    int count    = 0;
    for (const auto& [y0, y1] : gy)
        for (const auto& [x0, x1] : gx) {
            double total = 0.0, sx = 0.0, sy = 0.0;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    total += exact.at(x, y);
                    sx += (x - x0) * exact.at(x, y);
                    sy += (y - y0) * exact.at(x, y);
                }
            if (total <= 0.0)
                continue;
            ++count;
            // One fetch at the centroid: bilinear weights (1 - f, f) on each axis.
            const double fx = sx / total, fy = sy / total;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    const double wx = x == x0 ? 1.0 - fx : fx, wy = y == y0 ? 1.0 - fy : fy;
                    out.w[size_t((y + exact.ry) * nx + (x + exact.rx))] += total * wx * wy;
                }
        }
    if (fetches)
        *fetches = count;
    return out;
}

namespace detail {

namespace {

// The three segment directions P0, P2, P4 of the hexagon. Steep segments sweep down the
// rows, the cheapest pass, so the passes run in the frame (as given or transposed) where
// two of them are steep: three directions 60 degrees apart always leave two within 45
// degrees of one axis. For the upright hexagon (rotation 0) that is the transposed frame,
// where the third segment runs along the rows and needs no shear.
struct Dir {
    double x, y;
    bool steep() const { return std::abs(y) >= std::abs(x); }
    double slope() const { return steep() ? std::abs(x / y) : 2.0; }
};

std::array<Dir, 3> hexagon_dirs(const Kernel& k)
{
    std::array<Dir, 3> d;
    for (int i = 0; i < 3; ++i) {
        const auto [x, y] = hexagon_vertex(k, 2 * i);
        d[size_t(i)]      = { x, y };
    }
    return d;
}

}  // namespace

namespace {

// Whether the planes' passes (the sweep along the rows, the four passes) run on the
// transposed plane: where fewer than two segments are steep as given.
bool frame_transposed(const Kernel& k)
{
    const std::array<Dir, 3> d = hexagon_dirs(k);
    return std::count_if(d.begin(), d.end(), [](Dir v) { return v.steep(); }) < 2;
}

// The three segments in the source's frame or, `transposed`, in its transpose's.
std::array<Dir, 3> frame_dirs(const Kernel& k, bool transposed)
{
    std::array<Dir, 3> d = hexagon_dirs(k);
    if (transposed)
        for (Dir& v : d)
            std::swap(v.x, v.y);
    return d;
}

// The steep segments a and b (a the less sheared) and c in the frame the passes run in.
std::array<Dir, 3> working_dirs(const Kernel& k)
{
    std::array<Dir, 3> d = frame_dirs(k, frame_transposed(k));
    std::sort(d.begin(), d.end(), [](Dir p, Dir q) { return p.slope() < q.slope(); });
    return d;
}

bool runs_along_rows(const Dir& c) { return std::abs(c.y) < 1e-9 * std::abs(c.x); }

// Whether the hexagon's third segment runs along the rows of its working frame (the
// upright and the flat-topped hexagon: no shear needed).
bool along_rows(const Kernel& k) { return runs_along_rows(working_dirs(k)[2]); }

// The sheared frame's sweep on a padded plane (iris mode), where the hexagon takes one
// (defined with the sheared frame, below).
std::optional<Plane> sheared_on_plane(const Plane& in, const Kernel& k, int margin_x, int margin_y, int nthreads);

}  // namespace

Plane hexagon_parallelograms(Plane in, const Kernel& k, int margin_x, int margin_y, int nthreads)
{
    // a and b steep (a the less sheared: it runs twice), c the third.
    const std::array<Dir, 3> d = working_dirs(k);
    const Dir a = d[0], b = d[1], c = d[2];

    // hexagon = (rhombus(a, b) + rhombus(b, c) + rhombus(c, a)) / 3
    //         = (seg_c (seg_a + seg_b) + seg_a seg_b) / 3: one pass of c, here the
    // costliest (hexagon_sweep, where c runs along the rows, groups them the other way).
    // Two planes besides `in`, each reused once its values are used up (a fresh 1080p
    // plane costs its page faults).
    // Each pass computes only what the later ones read, back from the output region (the
    // plane less its margins): without that the passes would cover the whole padded
    // plane, which grows with the kernel (1.37x the pixels at 255 px).
    const int w = in.w, h = in.h;
    const Region all{ 0, 0, w, h };
    const Region out_region{ margin_x, margin_y, w - margin_x, h - margin_y };
    // Other rotations: the sheared frame's sweep, if one serves (blur.cpp padded the plane
    // as given then: hexagon_transposed is false for them); else the four passes below.
    if (!runs_along_rows(c))
        if (std::optional<Plane> out = sheared_on_plane(in, k, margin_x, margin_y, nthreads))
            return std::move(*out);
    if (runs_along_rows(c)) {  // one sweep (iris mode; hexagon_direct otherwise)
        Plane out(w, h, in.nc);
        const size_t ncs = size_t(in.nc);
        SweepIO io;
        io.w    = w;
        io.h    = h;
        io.lines = [&](int r, int n, int c0, int c1, float* const*, RowSpan* lines) {
            for (int i = 0; i < n; ++i)
                lines[i] = { in.row(r + i) + size_t(c0) * ncs, 0, c1 - c0 };
        };
        io.out_row = [&](int y, int x0, int) { return out.row(y) + size_t(x0) * ncs; };
        hexagon_sweep(io, in.nc, out_region, a.x, a.y, b.x, b.y, c.x, nthreads);
        return out;
    }
    const Region s_region = grown_by(out_region, c.x, c.y, w, h);
    const Region b_region = hull(s_region, grown_by(out_region, a.x, a.y, w, h));
    Plane segb(w, h, in.nc), sum_ab(w, h, in.nc);
    segment_pass(in, all, segb, b_region, b.x, b.y, nullptr, 1.0f, nthreads);
    segment_pass(in, all, sum_ab, s_region, a.x, a.y, &segb, 1.0f, nthreads);
    Plane& ab = in;
    segment_pass(segb, b_region, ab, out_region, a.x, a.y, nullptr, 1.0f, nthreads);
    Plane& out = segb;
    segment_pass(sum_ab, s_region, out, out_region, c.x, c.y, &ab, float(1.0 / 3.0), nthreads);
    return std::move(out);
}

namespace {

// o[i] = w0[i] p0[i] + w1[i] p1[i] + w2[i] p2[i], i < n: three taps whose weights change
// per pixel (spread over its channels), on a run of pixels that read the same rows.
inline void three_taps(float* __restrict o, const float* p0, const float* p1, const float* p2,
                       const float* w0, const float* w1, const float* w2, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        o[i] = w0[i] * p0[i] + w1[i] * p1[i] + w2[i] * p2[i];
}

// RGBA pixel o = t.w[0] p0 + t.w[1] p1 + t.w[2] p2, one vector.
inline void rgba_taps(float* o, const Taps& t, const float* p0, const float* p1, const float* p2)
{
    *reinterpret_cast<PixelRgba*>(o) = t.w[0] * *reinterpret_cast<const PixelRgba*>(p0)
                                       + t.w[1] * *reinterpret_cast<const PixelRgba*>(p1)
                                       + t.w[2] * *reinterpret_cast<const PixelRgba*>(p2);
}

// The sweep's cost in spans_cost_ns's units, flat-topped (its lines the source's rows) and
// upright (its lines the source's columns): see parallelograms_cost_ns.
constexpr double kSweepFlatNs = 3.6, kSweepUprightNs = 4.6;
// The sheared frame's lines and outputs read through three taps, over the sweep's cost
// in its frame (cheaper_shear): measured 1.14-1.56 at 63 px (session 14, 1080p RGBA, two
// threads, against the upright and the flat-topped sweeps in the same runs).
constexpr double kShearTapsCost = 1.4;

// The hexagon at other rotations (issue 3): its three segments lie 60 degrees apart, so
// one is within 30 degrees of the rows and one within 30 degrees of the columns. Shearing
// the frame's columns, (x, y) -> (x, y - m x) with m = c.y / c.x, turns the first, c, along
// the rows and leaves the other two steep (for the regular hexagon |y'| / |x'| >=
// sin 60 / (cos 30 cos(angle c)) >= 1), so the fused sweep runs in that frame as for the
// flat-topped hexagon; likewise in the transposed frame (the source's rows sheared) with
// the segment near the columns, as for the upright one. A shear of determinant one maps
// the hexagon's rhombi to the sheared hexagon's, weights and all. The two sweeps of
// session 13 took 10-18 ms at 15-255 px against the four passes' 54-57.
struct ColumnShear {
    bool transposed = false;  // the frame is the source's transpose (c near the columns)
    double m        = 0.0;
    Dir a, b, c;
};

// The shear that turns the segment nearest the rows of the frame (the source's, or its
// transpose's) along them, `m` and the segments in the sheared frame; none where a
// stretched hexagon's shear leaves a or b flat.
std::optional<ColumnShear> column_shear(const Kernel& k, bool transposed)
{
    std::array<Dir, 3> d = frame_dirs(k, transposed);
    auto rise = [](Dir v) { return std::abs(v.y) / std::max(std::abs(v.x), 1e-300); };
    std::sort(d.begin(), d.end(), [&](Dir p, Dir q) { return rise(p) < rise(q); });
    if (rise(d[0]) > 1.0)
        return std::nullopt;
    ColumnShear s;
    s.transposed = transposed;
    s.m          = d[0].y / d[0].x;
    s.c          = { d[0].x, 0.0 };
    Dir a = { d[1].x, d[1].y - s.m * d[1].x }, b = { d[2].x, d[2].y - s.m * d[2].x };
    if (!a.steep() || !b.steep())
        return std::nullopt;
    if (b.slope() < a.slope())
        std::swap(a, b);
    s.a = a;
    s.b = b;
    return s;
}

// The cheaper of the two frames' shears for a w x h output, by the sweeps' cost (the
// frames' base costs, parallelograms_cost_ns) times the lines a chunk of columns sweeps:
// its output's plus |m| per column of the chunk (two chunks at 1080p); `cost_ns` its
// cost in those units.
std::optional<ColumnShear> cheaper_shear(const Kernel& k, int w, int h, double* cost_ns = nullptr)
{
    std::optional<ColumnShear> best;
    double best_cost = 0.0;
    for (bool t : { false, true }) {
        const std::optional<ColumnShear> s = column_shear(k, t);
        if (!s)
            continue;
        const int across = t ? h : w, lines = t ? w : h;
        const int chunk  = (across + column_chunks(across) - 1) / column_chunks(across);
        // As given, the diagonal reads and writes cost ~1.9 |m| more: the frames measured
        // alike at 15-22 degrees (15-255 px; the transposed frame 0.72x the as-given one's
        // time at 7 and 0.78x at 5, 1.1x at 25 and 1.3-1.4x at 28; session 14).
        const double diagonal = t ? 1.0 : 1.0 + 1.9 * std::abs(s->m);
        const double cost     = (t ? kSweepUprightNs : kSweepFlatNs) * diagonal
                            * (1.0 + std::abs(s->m) * chunk / std::max(lines, 1));
        if (!best || cost < best_cost) {
            best      = s;
            best_cost = cost;
        }
    }
    if (cost_ns && best)  // else the caller's cost (the four passes') stands
        *cost_ns = best_cost;
    return best;
}

// hexagon_direct at rotations off multiples of 30 degrees (column_shear). In the working
// frame (the source, or its transpose), working column x is source column (row) org + x;
// line r reads the source at (x, base + r + m x) through the quadratic B-spline's taps
// across the lines (the taps the sweep's windows use along them: energy and centroid
// exact, variance 1/4 px^2 at every phase), and output (x, Y) reads the sweep's result
// back at (x, Y - base - m x) through them. Both taps depend on the column alone (r and Y
// are whole), so each is tabled per column. The lines a chunk of columns needs drift by m
// per column (SweepIO::out_rows): 1080 + 960 |m| as given at 1080p (two chunks of 960),
// 1920 + 540 |m| transposed. The sweep's rows come to the store in batches of
// kColumnBatch with the two rows before them kept (SweepIO::keep), so an output is written
// with the batch holding its last tap.
// As given, a line runs along a diagonal of the source (~1 / m pixels from each row) and
// an output batch along one of `dst`: a batch of lines is gathered a run of columns with
// one first tap at a time (its 18 rows' pieces in L1), the next run's rows prefetched.
// Transposed, a batch of 16 lines at column x reads 18 adjacent pixels of a source row,
// all with x's weights, and writes 16 adjacent pixels of an output row: the upright
// sweep's pattern.
class ShearedFrame {
public:
    // Outputs over roi go to `out` (pixel roi.xbegin, roi.ybegin), rows `pitch` floats apart.
    ShearedFrame(const OIIO::ImageBuf& in, float* out, size_t pitch, const OIIO::ROI& roi, const Kernel& k,
                 const ColumnShear& s, int rx, int ry, Border border)
        : in_(in), s_(s), roi_(roi), data_(in.roi()), border_(border), black_(border == Border::Black),
          t_(s.transposed), m_(s.m), ncs_(size_t(in.nchannels())), pitch_(pitch), d0_(out)
    {
        const bool t = t_;
        // Along the working columns ("across") and the lines ("down"), in source coordinates.
        const int across0 = t ? roi.ybegin : roi.xbegin, across1 = t ? roi.yend : roi.xend;
        down0_   = t ? roi.xbegin : roi.ybegin;
        down1_   = t ? roi.xend : roi.yend;
        data_d0_ = t ? data_.xbegin : data_.ybegin;
        data_d1_ = t ? data_.xend : data_.yend;
        reach_a_ = t ? ry : rx;
        w_       = across1 - across0 + 2 * reach_a_;
        org_     = across0 - reach_a_;
        down_.reserve(size_t(w_));
        up_.reserve(size_t(w_));
        for (int x = 0; x < w_; ++x) {
            down_.emplace_back(m_ * x);
            up_.emplace_back(-m_ * x);
        }
        // The sheared kernel's reach across the lines, and the frame: outputs read lines
        // [ry_w, h - ry_w), the kernel's reach around them.
        double reach = 0.0;
        for (int i = 0; i < 6; ++i) {
            const auto [vx, vy] = hexagon_vertex(k, i);
            reach = std::max(reach, t ? std::abs(vx - m_ * vy) : std::abs(vy - m_ * vx));
        }
        ry_w_                   = int(std::ceil(reach)) + 2;
        const auto [u_lo, u_hi] = first_range(up_, reach_a_, w_ - reach_a_);
        base_                   = down0_ + u_lo - ry_w_;
        h_                      = down1_ - 1 - base_ + u_hi + 3 + ry_w_;
        const int data_a0 = t ? data_.ybegin : data_.xbegin, data_a1 = t ? data_.yend : data_.xend;
        lit_x0_ = black_ ? std::max(0, data_a0 - org_) : 0;
        lit_x1_ = black_ ? std::min(w_, data_a1 - org_) : w_;
        spread(down_, down_w_);
        spread(up_, up_w_);
        zero_.assign(size_t(std::max(data_.width(), data_.height()) + 2 * kColumnBatch) * ncs_, 0.0f);
        if (t)
            transposed_tables();
        else
            as_given_tables();
    }

    // The hexagon, into `out`.
    void sweep(int nthreads) const
    {
        hexagon_sweep(io(), int(ncs_), { reach_a_, ry_w_, w_ - reach_a_, h_ - ry_w_ }, s_.a.x, s_.a.y, s_.b.x, s_.b.y,
                      s_.c.x, nthreads);
    }

private:
    // The sweep's input and output through this frame.
    SweepIO io() const
    {
        SweepIO io;
        io.w        = w_;
        io.h        = h_;
        io.batch    = kColumnBatch;
        io.keep     = 2;
        io.out_rows = [this](int x0, int x1) {
            const auto [lo, hi] = first_range(up_, x0, x1);
            return std::pair{ down0_ - base_ + lo, down1_ - 1 - base_ + hi + 3 };
        };
        if (black_) {
            io.lit       = { lit_x0_, 0, lit_x1_, h_ };
            io.first_lit = [this](int c0, int c1) {
                const int a = std::max(c0, lit_x0_), b = std::min(c1, lit_x1_);
                return b > a ? data_d0_ - base_ - 2 - first_range(down_, a, b).second : h_;
            };
        }
        io.out_row = [](int, int, int) -> float* { return nullptr; };
        if (t_) {
            io.lines = [this](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
                lines_transposed(r, n, c0, c1, bufs, lines);
            };
            io.store = [this](int y, int n, int x0, int x1, const float* rows) { store_transposed(y, n, x0, x1, rows); };
        } else {
            io.lines = [this](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
                lines_as_given(r, n, c0, c1, bufs, lines);
            };
            io.store = [this](int y, int n, int x0, int x1, const float* rows) { store_as_given(y, n, x0, x1, rows); };
        }
        return io;
    }

    // The first taps over columns [x0, x1): monotonic in x (round(m x) - 1), so the ends.
    static std::pair<int, int> first_range(const std::vector<Taps>& tp, int x0, int x1)
    {
        const int p = tp[size_t(x0)].first, q = tp[size_t(x1 - 1)].first;
        return { std::min(p, q), std::max(p, q) };
    }

    // Each tap's weights spread over the channels (a run of pixels with the same taps'
    // rows is then one vector loop).
    void spread(const std::vector<Taps>& tp, std::array<std::vector<float>, 3>& wt) const
    {
        for (int j = 0; j < 3; ++j) {
            wt[size_t(j)].resize(size_t(w_) * ncs_);
            for (int x = 0; x < w_; ++x)
                std::fill_n(wt[size_t(j)].data() + size_t(x) * ncs_, ncs_, tp[size_t(x)].w[j]);
        }
    }

    // Lines r .. r + n - 1 over [c0, c1), lit over [a, b): their spans (none where a line
    // reads only black: all its taps outside the data window); how many have pixels.
    int line_spans(int r, int n, int c0, float* const* bufs, RowSpan* lines, int a, int b) const
    {
        int lit = 0;
        for (int i = 0; i < n; ++i) {
            bool dark = b <= a;
            if (!dark && black_) {
                const int row0 = base_ + r + i, f0 = down_[size_t(a)].first, f1 = down_[size_t(b - 1)].first;
                dark = row0 + std::max(f0, f1) + 2 < data_d0_ || row0 + std::min(f0, f1) >= data_d1_;
            }
            lines[i] = dark ? RowSpan{} : RowSpan{ bufs[i], a - c0, b - c0 };
            lit += !dark;
        }
        return lit;
    }

    // As given: the source rows the lines read (the zero row where black), each working
    // column's source column by the border rule, the runs of columns whose taps start on
    // one row and read adjacent source columns (run_end_[x]: where x's run ends), and the
    // unshear's columns by first tap.
    void as_given_tables()
    {
        const auto [d_lo, d_hi] = first_range(down_, 0, w_);
        s0_                     = base_ + d_lo;
        const int s1            = base_ + h_ + d_hi + 2;
        src_rows_.resize(size_t(s1 - s0_));
        for (int sr = s0_; sr < s1; ++sr) {
            const int sy = border_index(sr, data_.ybegin, data_.yend, border_);
            src_rows_[size_t(sr - s0_)] =
                sy == kOutside ? zero_.data() : static_cast<const float*>(in_.pixeladdr(data_.xbegin, sy, data_.zbegin));
        }
        col_.assign(size_t(w_), 0);
        for (int x = 0; x < w_; ++x) {
            const int sx   = border_index(org_ + x, data_.xbegin, data_.xend, border_);
            col_[size_t(x)] = sx == kOutside ? 0 : size_t(sx - data_.xbegin) * ncs_;
        }
        run_end_.resize(size_t(w_));
        for (int x = w_ - 1; x >= 0; --x) {
            const bool on = x + 1 < w_ && down_[size_t(x + 1)].first == down_[size_t(x)].first
                            && col_[size_t(x + 1)] == col_[size_t(x)] + ncs_;
            run_end_[size_t(x)] = on ? run_end_[size_t(x + 1)] : x + 1;
        }
        const auto [u_lo, u_hi] = first_range(up_, 0, w_);
        up_lo_                  = u_lo;
        up_columns_.assign(size_t(u_hi - u_lo + 1), { 0, 0 });
        for (int x = w_ - 1; x >= 0; --x) {
            auto& c = up_columns_[size_t(up_[size_t(x)].first - up_lo_)];
            c       = c.second > c.first ? std::pair{ x, c.second } : std::pair{ x, x + 1 };
        }
    }

    // Transposed: per working column, source row org + x by the border rule (null: black).
    void transposed_tables()
    {
        row_of_.resize(size_t(w_));
        for (int x = 0; x < w_; ++x) {
            const int sy = border_index(org_ + x, data_.ybegin, data_.yend, border_);
            row_of_[size_t(x)] =
                sy == kOutside ? nullptr : static_cast<const float*>(in_.pixeladdr(data_.xbegin, sy, data_.zbegin));
        }
    }

    void lines_as_given(int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) const
    {
        const int a = std::max(c0, lit_x0_), b = std::min(c1, lit_x1_);
        if (line_spans(r, n, c0, bufs, lines, a, b) == 0)
            return;
        // Line r + i reads rows[i + first + 0..2]; a run of columns with one first tap is
        // done for the batch's lines at once, its n + 2 rows' pieces in L1.
        const float* const* const rows = src_rows_.data() + (base_ + r - s0_);
        for (int x = a; x < b;) {
            const int e = std::min(run_end_[size_t(x)], b), f = down_[size_t(x)].first;
            const size_t j = col_[size_t(x)], kx = size_t(x) * ncs_, ox = size_t(x - a) * ncs_;
            const size_t len = size_t(e - x) * ncs_;
            if (e < b) {  // the next run's rows: a diagonal the hardware's prefetchers miss
                const int fn       = down_[size_t(e)].first;
                const size_t jn    = col_[size_t(e)];
                const size_t bytes = size_t(std::min(run_end_[size_t(e)], b) - e) * ncs_ * sizeof(float);
                for (int t = 0; t < n + 2; ++t)
                    prefetch_lines(rows[fn + t] + jn, bytes);
            }
            for (int i = 0; i < n; ++i)
                if (lines[i].p)
                    three_taps(bufs[i] + ox, rows[i + f] + j, rows[i + f + 1] + j, rows[i + f + 2] + j,
                               down_w_[0].data() + kx, down_w_[1].data() + kx, down_w_[2].data() + kx, len);
            x = e;
        }
    }

    void store_as_given(int y, int n, int x0, int x1, const float* rows) const
    {
        const ptrdiff_t no = ptrdiff_t(x1 - x0) * ptrdiff_t(ncs_);
        // Output row Y takes the columns whose last tap, line Y - base + u + 2, came in
        // this batch: u in [y - Y + base - 2, y + n - Y + base - 2), each u a run.
        const auto [u0, u1] = first_range(up_, x0, x1);
        const int yy0 = std::max(down0_, y + base_ - u1 - 2), yy1 = std::min(down1_, y + n + base_ - u0 - 2);
        for (int yy = yy0; yy < yy1; ++yy) {
            const int lo = y - yy + base_ - 2;
            // Line yy - base + u of the batch is row (yy - base - y) + u of `rows` (>= -2:
            // the kept rows); column x of the frame is pixel org + x - roi.xbegin of the row.
            const ptrdiff_t line0 = ptrdiff_t(yy - base_ - y);
            float* const orow     = d0_ + size_t(yy - roi_.ybegin) * pitch_;
            auto out_px           = [&](int x) { return orow + size_t(org_ + x - roi_.xbegin) * ncs_; };
            // Left to right (u falls with x where m > 0).
            const int ua = std::max(lo, u0), ub = std::min(lo + n, u1 + 1);
            if (ub <= ua)
                continue;
            if (ncs_ == 4) {  // one vector a pixel, each reading its own lines
                const int ul = m_ > 0.0 ? ub - 1 : ua, ur = m_ > 0.0 ? ua : ub - 1;
                const int xa = std::max(x0, up_columns_[size_t(ul - up_lo_)].first);
                const int xb = std::min(x1, up_columns_[size_t(ur - up_lo_)].second);
                for (int x = xa; x < xb; ++x) {
                    const Taps& tp  = up_[size_t(x)];
                    const float* qx = rows + (line0 + tp.first) * no + ptrdiff_t(x - x0) * 4;
                    rgba_taps(out_px(x), tp, qx, qx + no, qx + 2 * no);
                }
                continue;
            }
            for (int i = 0; i < ub - ua; ++i) {
                const int u         = m_ > 0.0 ? ub - 1 - i : ua + i;
                const auto [ca, cb] = up_columns_[size_t(u - up_lo_)];
                const int xa = std::max(ca, x0), xb = std::min(cb, x1);
                if (xb <= xa)
                    continue;
                const float* qx = rows + (line0 + u) * no + ptrdiff_t(xa - x0) * ptrdiff_t(ncs_);
                const size_t kx = size_t(xa) * ncs_;
                three_taps(out_px(xa), qx, qx + no, qx + 2 * no, up_w_[0].data() + kx, up_w_[1].data() + kx,
                           up_w_[2].data() + kx, size_t(xb - xa) * ncs_);
            }
        }
    }

    void lines_transposed(int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) const
    {
        const int a = std::max(c0, lit_x0_), b = std::min(c1, lit_x1_);
        if (line_spans(r, n, c0, bufs, lines, a, b) == 0)
            return;
        std::vector<float> run;  // a row's pixels by the border rule, near the data window's edges
        for (int x = a; x < b; ++x) {
            // Source row org + x, columns base + r + f + [0, n + 2): in place inside the
            // data window, else by the border rule.
            const float* const row = row_of_[size_t(x)];
            const int sx0          = base_ + r + down_[size_t(x)].first;
            const float* p         = zero_.data();
            if (row) {
                if (sx0 >= data_.xbegin && sx0 + n + 2 <= data_.xend)
                    p = row + size_t(sx0 - data_.xbegin) * ncs_;
                else {
                    run.resize(size_t(n + 2) * ncs_);
                    for (int j = 0; j < n + 2; ++j) {
                        const int sx   = border_index(sx0 + j, data_.xbegin, data_.xend, border_);
                        const float* v = sx == kOutside ? zero_.data() : row + size_t(sx - data_.xbegin) * ncs_;
                        std::copy_n(v, ncs_, run.data() + size_t(j) * ncs_);
                    }
                    p = run.data();
                }
            }
            const size_t kx = size_t(x) * ncs_, ox = size_t(x - a) * ncs_;
            if (ncs_ == 4) {  // one vector a pixel, the weights held
                const Taps& tp = down_[size_t(x)];
                for (int i = 0; i < n; ++i, p += 4)
                    rgba_taps(bufs[i] + ox, tp, p, p + 4, p + 8);
                continue;
            }
            for (int i = 0; i < n; ++i, p += ncs_)
                three_taps(bufs[i] + ox, p, p + ncs_, p + 2 * ncs_, down_w_[0].data() + kx, down_w_[1].data() + kx,
                           down_w_[2].data() + kx, ncs_);
        }
    }

    void store_transposed(int y, int n, int x0, int x1, const float* rows) const
    {
        const ptrdiff_t no = ptrdiff_t(x1 - x0) * ptrdiff_t(ncs_);
        for (int x = x0; x < x1; ++x) {
            // Output row org + x takes the columns X whose last tap, line X - base + u + 2,
            // came in this batch.
            const int u  = up_[size_t(x)].first;
            const int xa = std::max(down0_, y + base_ - u - 2), xb = std::min(down1_, y + n + base_ - u - 2);
            if (xb <= xa)
                continue;
            float* o = d0_ + size_t(org_ + x - roi_.ybegin) * pitch_ + size_t(xa - roi_.xbegin) * ncs_;
            if (x + kPrefetchRows < x1)
                prefetch_lines(o + kPrefetchRows * pitch_, size_t(xb - xa) * ncs_ * sizeof(float), true);
            const float* q  = rows + ptrdiff_t(xa - base_ + u - y) * no + ptrdiff_t(x - x0) * ptrdiff_t(ncs_);
            const size_t kx = size_t(x) * ncs_;
            if (ncs_ == 4) {  // one vector a pixel, the weights held
                const Taps& tp = up_[size_t(x)];
                for (int X = xa; X < xb; ++X, o += ncs_, q += no)
                    rgba_taps(o, tp, q, q + no, q + 2 * no);
                continue;
            }
            for (int X = xa; X < xb; ++X, o += ncs_, q += no)
                three_taps(o, q, q + no, q + 2 * no, up_w_[0].data() + kx, up_w_[1].data() + kx, up_w_[2].data() + kx,
                           ncs_);
        }
    }

    const OIIO::ImageBuf& in_;
    const ColumnShear s_;
    const OIIO::ROI roi_, data_;
    const Border border_;
    const bool black_, t_;
    const double m_;
    const size_t ncs_, pitch_;  // pitch_: floats from one output row to the next
    float* const d0_;
    int down0_ = 0, down1_ = 0, data_d0_ = 0, data_d1_ = 0, reach_a_ = 0;
    int w_ = 0, h_ = 0, org_ = 0, base_ = 0, ry_w_ = 0, lit_x0_ = 0, lit_x1_ = 0;
    std::vector<Taps> down_, up_;  // per working column: the shear's taps, the unshear's
    std::array<std::vector<float>, 3> down_w_, up_w_;
    std::vector<float> zero_;
    // As given (as_given_tables).
    int s0_ = 0, up_lo_ = 0;
    std::vector<const float*> src_rows_;
    std::vector<size_t> col_;
    std::vector<int> run_end_;
    std::vector<std::pair<int, int>> up_columns_;
    // Transposed (transposed_tables).
    std::vector<const float*> row_of_;
};

bool hexagon_sheared_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                            const Kernel& k, const ColumnShear& s, int rx, int ry, Border border,
                            int nthreads)
{
    prepare_destination(dst, in, roi);
    ShearedFrame(in, static_cast<float*>(dst.localpixels()), size_t(dst.spec().width) * size_t(in.nchannels()), roi,
                 k, s, rx, ry, border)
        .sweep(nthreads);
    return true;
}

}  // namespace

namespace {

std::optional<Plane> sheared_on_plane(const Plane& in, const Kernel& k, int margin_x, int margin_y, int nthreads)
{
    const int w = in.w - 2 * margin_x, h = in.h - 2 * margin_y;
    const std::optional<ColumnShear> s = cheaper_shear(k, w, h);
    if (!s)
        return std::nullopt;
    // The plane as a source (no copy; only read), its outputs past the margins; the taps'
    // phases count from the reach before the output, as hexagon_direct's do.
    const OIIO::ImageSpec spec(in.w, in.h, in.nc, OIIO::TypeFloat);
    const OIIO::ImageBuf view(spec, const_cast<float*>(in.row(0)));
    const OIIO::ROI roi(margin_x, margin_x + w, margin_y, margin_y + h);
    Plane out(in.w, in.h, in.nc);
    ShearedFrame(view, out.row(margin_y) + size_t(margin_x) * size_t(in.nc), out.stride(), roi, k, *s,
                 hexagon_reach(k, true), hexagon_reach(k, false), Border::Black)
        .sweep(nthreads);
    return out;
}

}  // namespace

namespace {

// Whether the hexagon takes a sheared frame: not along the rows, and a shear serves.
bool sheared(const Kernel& k) { return !along_rows(k) && (column_shear(k, false) || column_shear(k, true)); }

}  // namespace

bool hexagon_transposed(const Kernel& k) { return frame_transposed(k) && !sheared(k); }

int hexagon_plane_extra(const Kernel& k) { return sheared(k) ? 4 : 0; }

bool hexagon_sweeps(const Kernel& k) { return along_rows(k) || sheared(k); }

// Flat in the size, by path, in spans_cost_ns's units (ns a pixel and channel on one
// thread): the sweep 3.6 flat-topped and 4.6 upright, the four passes 30. Refitted in
// session 13 on this project's machine (AMD EPYC, 1 MiB L2), where the sweep had become
// the cheaper of the two against the exact spans from 9-10 px (spot timings, 1080p RGBA,
// two threads, 9 runs each: upright 10.8 against the spans' 10.6 ms at 9 px, 11.1 against
// 12.1 at 11; flat-topped 10.3 against 10.6 at 9, 10.2 against 9.0 at 7): with these,
// `fast` takes the sweep from 9 px flat-topped and 10 px upright. (Session 12's 5 and 7.5,
// fitted on the machine before, crossed at 13 and 19 px; the four passes measured 3.7-3.8x
// the spans at 15 px on both machines.) spans_cost_ns reads a hexagon's spans within
// 0.84-1.18 of measured at 31-63 px (session 10), so the two models compare as they are.
// The sheared sweep (session 14): its frame's cost (cheaper_shear) times kShearTapsCost.
double parallelograms_cost_ns(const Kernel& k, int w, int h)
{
    double ns = 30.0;  // the four passes
    if (along_rows(k))
        ns = hexagon_transposed(k) ? kSweepUprightNs : kSweepFlatNs;
    else if (cheaper_shear(k, w, h, &ns))
        ns *= kShearTapsCost;
    return double(w) * double(h) * ns;
}

// Their error is the slanted edges' softening by the taps, under a pixel, so it falls with
// the size: on bokeh-bench's scene (PSNR after its tone map, 1080p, session 14) the sweep
// along the rows measured 38.8-39.0 dB at 13 px and 40.5-40.6 at 15; the sheared sweep,
// two reads through the taps more, 38.5-38.7 at 23 px and 40.0-40.2 at 27 (7 and 20
// degrees). Stretched hexagons (anamorphic) are softened as much on their narrow side, so
// that side decides, and more (bokeh-bench's crop blurred alone, session 15): 2:1 and 3:1
// along the rows (0 and 90 degrees) 38.2-40.1 dB at 15 px across, 39.7-43.0 at 18,
// 43.0-45.1 at 21; sheared or the four passes (left for hexagons stretched past any shear)
// 36.4-37.2 at 15 across, 39.2 at 21, 40.5-43.7 at 27 (54 x 27 to 81 x 27 at 7 and 20
// degrees).
double parallelograms_budget_px(const Kernel& k)
{
    if (!along_rows(k))
        return 27.0;
    return k.width_px == k.height_px ? 15.0 : 21.0;
}

bool hexagon_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                    const Kernel& k, int rx, int ry, Border border, int nthreads)
{
    const std::array<Dir, 3> d = working_dirs(k);
    const Dir a = d[0], b = d[1], c = d[2];
    if (!runs_along_rows(c))
        return hexagon_sheared_direct(dst, in, roi, k, *cheaper_shear(k, roi.width(), roi.height()), rx, ry,
                                      border, nthreads);
    const bool t = hexagon_transposed(k);
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    const OIIO::ROI data = in.roi(), region = grown(roi, rx, ry);
    // Working pixel (x, y) is source pixel (region.xbegin + x, region.ybegin + y), or
    // (region.xbegin + y, region.ybegin + x) transposed; outputs are the frame less its
    // margins, which is roi.
    SweepIO io;
    io.w = t ? region.height() : region.width();
    io.h = t ? region.width() : region.height();
    const Region out_region{ t ? ry : rx, t ? rx : ry, io.w - (t ? ry : rx), io.h - (t ? rx : ry) };
    if (border == Border::Black) {
        const Region lit{ data.xbegin - region.xbegin, data.ybegin - region.ybegin,
                          data.xend - region.xbegin, data.yend - region.ybegin };
        io.lit = t ? transposed(lit) : lit;
    }
    if (!t) {
        io.lines = [&](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
            for (int i = 0; i < n; ++i)
                lines[i] = bordered_row_span(in, region.ybegin + r + i, region.xbegin + c0,
                                             region.xbegin + c1, border, bufs[i]);
        };
        io.out_row = [&](int y, int x0, int) {
            return static_cast<float*>(dst.pixeladdr(region.xbegin + x0, region.ybegin + y));
        };
    } else {
        // Lines are source columns and output rows destination columns, so both go by
        // batches of adjacent columns (kColumnBatch): a row's pixels of a batch share cache
        // lines, read or written at once. One column at a time, a 1920 px frame's column
        // put its pixels' cache lines in 2 of L1's 64 sets (the row pitch, 30720 bytes, is
        // 480 lines), and each line was fetched again for each of its four pixels: the
        // upright hexagon at 63 px took 45-51 ms on a 1900 px wide frame against 54-58 at
        // 1920, and a bare column-at-a-time transpose 6.6 ms against 14.7. Batched, A/B
        // against one at a time: 0.79-0.86x at 15-63 px, 0.89-0.92x at 127-255 (session 10).
        io.batch = kColumnBatch;
        io.lines = [&](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
            // Only the lit part of a column is gathered; the rest is black by the span.
            const int a = std::max(c0, io.lit.x0), b = std::min(c1, io.lit.x1);
            for (int i = 0; i < n;) {
                const int sx = border_index(region.xbegin + r + i, data.xbegin, data.xend, border);
                if (sx == kOutside || b <= a) {
                    lines[i++] = {};
                    continue;
                }
                int run = 1;  // the source columns adjacent to sx, in order
                while (i + run < n
                       && border_index(region.xbegin + r + i + run, data.xbegin, data.xend, border) == sx + run)
                    ++run;
                source_columns(in, sx, run, region.ybegin + a, region.ybegin + b, border, bufs + i);
                for (int j = 0; j < run; ++j, ++i)
                    lines[i] = { bufs[i], a - c0, b - c0 };
            }
        };
        io.out_row = [](int, int, int) -> float* { return nullptr; };
        const size_t pitch = size_t(dst.spec().width) * ncs;  // prepare_destination: roi-sized
        // `pitch` by value: this block ends before hexagon_sweep calls the lambda.
        io.store = [&, pitch](int y, int n, int x0, int x1, const float* rows) {
            const size_t row_len = size_t(x1 - x0) * ncs;
            float* d = static_cast<float*>(dst.pixeladdr(region.xbegin + y, region.ybegin + x0));
            const size_t bytes = size_t(n) * ncs * sizeof(float);
            for (int x = x0; x < x1; ++x, d += pitch) {
                if (x + kPrefetchRows < x1)
                    prefetch_lines(d + kPrefetchRows * pitch, bytes, true);
                copy_pixels(d, ncs, rows + size_t(x - x0) * ncs, row_len, n, nc);
            }
        };
    }
    hexagon_sweep(io, nc, out_region, a.x, a.y, b.x, b.y, c.x, nthreads);
    return true;
}

bool blur_reduced(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const Kernel& k,
                  const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    double n = opts.reduction > 0.0f ? double(opts.reduction) : reduction_factor(k);
    BlurOptions exact = opts;
    exact.method      = BlurMethod::Exact;
    exact.reduction   = 0.0f;
    // A kernel that is a point stays the identity, bit for bit, whatever the factor.
    if (std::max({ k.width_px, k.height_px, 4.0f * k.sigma_px }) < 4.0f
        && kernel_weights(k).is_identity())
        n = 1.0;
    if (n == 1.0)
        return blur(dst, in, k, exact, roi, nthreads);
    Kernel low_k = k;
    low_k.width_px  = float(k.width_px / n);
    low_k.height_px = float(k.height_px / n);
    low_k.sigma_px  = float(k.sigma_px / n);
    if (!roi.defined() && !opts.grow) {
        roi = in.roi();
    } else if (!roi.defined()) {
        // The method's reach: the reduced kernel's, and a reduced pixel more, at full size.
        const KernelWeights low_w = kernel_weights(low_k, nthreads);
        roi = grown(in.roi(), int(std::ceil((low_w.rx + 1) * n)), int(std::ceil((low_w.ry + 1) * n)));
    }
    // Reduced pixel i covers [i n, (i + 1) n) (anchored at 0, as reduce() and enlarge()):
    // the reduced image is every pixel that touches the data window, the area mean of it
    // (the outside counted as 0 with the black border, so energy is kept).
    const int nc         = in.nchannels();
    const OIIO::ROI data = in.roi();
    auto below = [&](int v) { return int(std::floor(v / n)); };
    auto above = [&](int v) { return int(std::ceil(v / n)); };
    OIIO::ImageSpec low_spec(above(data.xend) - below(data.xbegin),
                             above(data.yend) - below(data.ybegin), nc, OIIO::TypeFloat);
    low_spec.x = below(data.xbegin);
    low_spec.y = below(data.ybegin);
    OIIO::ImageBuf low_src, low;
    reset_uninitialised(low_src, low_spec);
    const ConstPlaneView from(static_cast<const float*>(in.localpixels()), data.width(),
                              data.height(), nc, size_t(in.scanline_stride()) / sizeof(float));
    const PlaneView reduced{ static_cast<float*>(low_src.localpixels()), low_spec.width,
                             low_spec.height, nc, size_t(low_spec.width) * size_t(nc) };
    std::string err;
    if (!reduce_plane(from, reduced, AxisMap::factor(1.0 / n, low_spec.x, data.xbegin),
                      AxisMap::factor(1.0 / n, low_spec.y, data.ybegin),
                      std::vector<Reducer>(size_t(nc), Reducer::Mean), -1,
                      opts.border == Border::Black, err, nthreads)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    // The reduced pixels whose enlargement covers roi, and one more each side (the
    // bilinear reads), blurred there by the border rule.
    const OIIO::ROI low_roi(below(roi.xbegin) - 1, below(roi.xend - 1) + 2, below(roi.ybegin) - 1,
                            below(roi.yend - 1) + 2);
    exact.grow = false;
    if (!blur(low, low_src, low_k, exact, low_roi, nthreads)) {
        dst.errorfmt("{}", low.geterror());
        return false;
    }
    // Enlarged straight into `dst` over roi: pixel x reads the reduced image at
    // (x + 1/2) / n - 1/2, as enlarge() does.
    prepare_destination(dst, in, roi);
    const ConstPlaneView blurred(static_cast<const float*>(low.localpixels()), low_roi.width(),
                                 low_roi.height(), nc, size_t(low_roi.width()) * size_t(nc));
    const PlaneView into{ static_cast<float*>(dst.localpixels()), roi.width(), roi.height(), nc,
                          size_t(roi.width()) * size_t(nc) };
    ResampleOptions eo;
    eo.filter = ResampleFilter::Bilinear;
    if (!resample_plane(blurred, into, AxisMap::factor(n, roi.xbegin, low_roi.xbegin),
                        AxisMap::factor(n, roi.ybegin, low_roi.ybegin), eo, err, nthreads)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    return true;
}

int hexagon_reach(const Kernel& k, bool along_x)
{
    double r = 0.0;
    for (int i = 0; i < 6; ++i) {
        const auto [x, y] = hexagon_vertex(k, i);
        r = std::max(r, std::abs(along_x ? x : y));
    }
    // A rhombus is two steep segments in series, and each spreads its segment by its
    // shear's and its unshear's three taps (< 1.5 px each) and its last row's drift
    // (< 0.5 px): < 7 px past the hexagon, so at whole offsets at most ceil(r) + 6.
    // It was + 2: measured, the parallelograms reach up to 5 px past the hexagon (9 px:
    // 10 against 4.5), and under clamp or mirror the frame's edge pixels lost up to 7.7e-6
    // of a constant image, read as black past the padding (session 17).
    return int(std::ceil(r)) + 6;
}

}  // namespace detail

}  // namespace bokeh
