// blur_box.cpp — the box blur by running sums, and the Gaussian by three boxes
// (BlurMethod::ThreeBoxes), straight from the source into the destination, with their
// plane paths for iris mode.
//
// Running sums (box): one add and one subtract per pixel per pass whatever the width, in
// double; a fractional width adds its two partial end pixels explicitly. Channel counts
// 1, 3 and 4 slide a running sum along the row; other counts take a row's prefix sums.
// The direct path (box_direct) works per column strip (column_chunks): a horizontal running
// sum per source row into a ring of the last 2 ry + 2 rows, and the vertical running sum
// over the ring straight into `dst`, so the frame is read once and written once whatever
// the size, with no padded copy of it (which cost ~14 ms at 1080p).
//
// Fast Gaussian: three equal boxes whose variance adds up to sigma^2 (central limit;
// Wells 1986, "Efficient synthesis of Gaussian filters by cascaded uniform filters"). The
// box width is fractional, so the variance matches exactly, not to the nearest odd width.
// Per column strip, each padded row is boxed three times along x in L1, then goes down
// three running sums along y, each with its ring (three_boxes_direct), rather than three
// whole-frame box passes into fresh images.
//
// Limits: the sums restart per strip, so they never hold more than one strip's row (a 1e6
// pixel leaves no drift); the three boxes are a piecewise-quadratic stand-in for the
// Gaussian (bokeh-bench measures them against the exact one: `make bench`).

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/blur_methods.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace bokeh {

using namespace detail;

namespace {

// sum[i] += add[i] - sub[i] (a running sum moving one row down).
BOKEH_HOT void slide(double* sum, const float* add, const float* sub, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        sum[i] += double(add[i]) - double(sub[i]);
}

// out[i] = inner * sum[i] (+ end * (lo[i] + hi[i]) when lo is given).
BOKEH_HOT void box_out(float* out, const double* sum, double inner, const float* lo,
                       const float* hi, double end, size_t n)
{
    if (lo) {
        for (size_t i = 0; i < n; ++i)
            out[i] = float(inner * sum[i] + end * (double(lo[i]) + double(hi[i])));
    } else {
        for (size_t i = 0; i < n; ++i)
            out[i] = float(inner * sum[i]);
    }
}

// out[i] = inner * (hi[i] - lo[i]) (+ end * (lo_end[i] + hi_end[i]) when given).
BOKEH_HOT void box_row(float* out, const double* hi, const double* lo, double inner,
                       const float* lo_end, const float* hi_end, double end, size_t n)
{
    if (lo_end) {
        for (size_t i = 0; i < n; ++i)
            out[i] = float(inner * (hi[i] - lo[i]) + end * (double(lo_end[i]) + double(hi_end[i])));
    } else {
        for (size_t i = 0; i < n; ++i)
            out[i] = float(inner * (hi[i] - lo[i]));
    }
}

// One box pass along x: a row's prefix sums (double, row_prefix), then each output is the
// difference of two of them, plus the fractional end pixels.
Plane box_horizontal(const Plane& in, const BoxPass& b, int nthreads)
{
    const int nc = in.nc;
    Plane out(in.w - 2 * b.radius, in.h, nc);
    const size_t n = out.stride(), ncs = size_t(nc);
    parallel_for_chunks(0, in.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        std::vector<double> prefix(in.stride() + ncs);
        for (int y = int(y0); y < int(y1); ++y) {
            const float* v = in.row(y);
            row_prefix(prefix.data(), v, size_t(in.w), nc);
            // Output x sums input [x + radius - full, x + radius + full].
            const double* hi = prefix.data() + size_t(b.radius + b.full + 1) * ncs;
            const double* lo = prefix.data() + size_t(b.radius - b.full) * ncs;
            float* o         = out.row(y);
            box_row(o, hi, lo, b.inner, b.end != 0.0 ? v : nullptr,
                    b.end != 0.0 ? v + size_t(2 * b.radius) * ncs : nullptr, b.end, n);
        }
    });
    return out;
}

// One box pass along y: running sums down the columns, a row of sums at a time.
Plane box_vertical(const Plane& in, const BoxPass& b, int nthreads)
{
    Plane out(in.w, in.h - 2 * b.radius, in.nc);
    const size_t n = in.stride();
    constexpr size_t kStrip = 1024;
    parallel_for_chunks(0, int64_t((n + kStrip - 1) / kStrip), 1, nthreads, [&](int64_t s, int64_t) {
        const size_t i0 = size_t(s) * kStrip, i1 = std::min(n, i0 + kStrip);
        const size_t n = i1 - i0;
        std::vector<double> sum(n, 0.0);
        for (int j = -b.full; j <= b.full; ++j)
            add_scaled(sum.data(), in.row(b.radius + j) + i0, 1.0, n);
        for (int y = 0; y < out.h; ++y) {
            const int centre = y + b.radius;
            const bool ends  = b.end != 0.0;
            box_out(out.row(y) + i0, sum.data(), b.inner,
                    ends ? in.row(centre - b.full - 1) + i0 : nullptr,
                    ends ? in.row(centre + b.full + 1) + i0 : nullptr, b.end, n);
            if (y + 1 < out.h)
                slide(sum.data(), in.row(centre + b.full + 1) + i0, in.row(centre - b.full) + i0, n);
        }
    });
    return out;
}

// One row of a horizontal box: out(x) = inner * (sum of the full pixels
// v[x + radius - full .. x + radius + full]) + end * (v[x] + v[x + 2 radius]), for the
// padded row v. A running sum in double slides along the row: cost per output independent
// of the width, and no prefix array, so a strip reads its reach but does not add it up
// twice. The row comes as a RowSpan: pixels outside [lo, hi) are black and are read from
// a zero run instead, so a strip at the frame's edge reads the source in place (copying
// its rows into a padded buffer took ~5 % of the box's time at 255 px).
// The row is walked in stretches (for_span_stretches) over which each of the four streams
// the step reads (the pixel entering, the one leaving, the two fractional ends) lies
// wholly inside the span or wholly outside it: one stretch for a strip inside the frame.
// Four pixels per step: their window changes (entering minus leaving) and the partial
// sums of those are formed off the running sum's chain, which then carries one add per
// four pixels instead of one per pixel (box_row_running is multiversioned). Measured A/B
// in one process against one pixel per step, compiled for baseline x86-64: RGBA box
// 15-21 % faster at 15-255 px, the Gaussian by three boxes 18 %, one channel 8-16 %; RGB
// within the noise (+-5 %).
struct BoxStreams {
    const float* add;   // the pixel entering after output x
    const float* sub;   // the one leaving
    const float* lo;    // the fractional ends, v[x] and v[x + 2 radius]
    const float* hi;
};

// Calls stretch(out_x, streams, count, s) for each stretch of the row, s the window's
// running sum per channel (summed first from the span: the first window in four
// interleaved partial sums, shorter dependency chains; the order does not depend on the
// thread count).
template<int NC, class Stretch>
inline __attribute__((always_inline)) void box_row_stretches(const RowSpan& v, const float* zero,
                                                             int npx, int radius, int full,
                                                             bool ends, Stretch&& stretch)
{
    const int a = radius - full, e = radius + full + 1;
    const int i0 = std::max(a, v.lo), i1 = std::min(e, v.hi);
    double s[NC];
    if constexpr (NC == 4) {  // in vector types, as box_stretch_rgba
        const auto* p      = reinterpret_cast<const PixelRgba*>(v.p);
        SumRgba part[4]    = {};
        for (int i = i0; i < i1; ++i)
            part[(i - a) & 3] += __builtin_convertvector(p[i - v.lo], SumRgba);
        const SumRgba t = (part[0] + part[1]) + (part[2] + part[3]);
        for (int c = 0; c < NC; ++c)
            s[c] = t[c];
    } else {
        double part[4][NC] = {};
        for (int i = i0; i < i1; ++i)
            for (int c = 0; c < NC; ++c)
                part[(i - a) & 3][c] += double(v.p[size_t(i - v.lo) * NC + c]);
        for (int c = 0; c < NC; ++c)
            s[c] = (part[0][c] + part[1][c]) + (part[2][c] + part[3][c]);
    }
    // Stream k reads padded pixel x + offset[k] for output x.
    const int offset[4] = { e, a, 0, 2 * radius };
    auto one = [&](int x0, int x1) __attribute__((always_inline)) {
        auto at = [&](int k) { return span_pixel(v, x0 + offset[k], NC, zero); };
        stretch(x0, BoxStreams{ at(0), at(1), at(2), at(3) }, x1 - x0, s);
    };
    for_span_stretches<4>(v, offset, ends ? 4 : 2, npx, one);
}

// A stretch for four channels in vector types (PixelRgba, plane.h), one pixel a vector:
// the per-channel form (box_stretch) was compiled scalar in every clone for four
// channels, as row_prefix was. Same sums in the same order as that form, so the same
// bits. (The one- and three-channel clones are scalar, left so: the figures bokeh-bench
// reports are RGBA.)
template<bool Ends>
inline __attribute__((always_inline)) void box_stretch_rgba(float* out, const BoxStreams& st,
                                                            int n, double* s_io, double inner,
                                                            double end)
{
    using Pixel      = PixelRgba;
    using Sum        = SumRgba;
    const auto* add  = reinterpret_cast<const Pixel*>(st.add);
    const auto* sub  = reinterpret_cast<const Pixel*>(st.sub);
    const auto* lo   = reinterpret_cast<const Pixel*>(st.lo);
    const auto* hi   = reinterpret_cast<const Pixel*>(st.hi);
    auto* o          = reinterpret_cast<Pixel*>(out);
    Sum s            = Sum{ s_io[0], s_io[1], s_io[2], s_io[3] };
    auto value = [&](const Sum& sum, int x) __attribute__((always_inline)) {
        Sum r = inner * sum;
        if (Ends)
            r += end * (__builtin_convertvector(lo[x], Sum) + __builtin_convertvector(hi[x], Sum));
        return __builtin_convertvector(r, Pixel);
    };
    Sum d[4];  // d[k]: pixel k's window change (entering less leaving)
    Sum q[4];  // q[k]: the sum k pixels on, less s
    int x = 0;
    for (; x + 4 <= n; x += 4) {
        for (int k = 0; k < 4; ++k)
            d[k] = __builtin_convertvector(add[x + k], Sum)
                   - __builtin_convertvector(sub[x + k], Sum);
        q[0] = Sum{};
        q[1] = d[0];
        q[2] = q[1] + d[1];
        q[3] = q[2] + d[2];
        for (int k = 0; k < 4; ++k)
            o[x + k] = value(s + q[k], x + k);
        s += q[3] + d[3];
    }
    for (; x < n; ++x) {
        o[x] = value(s, x);
        s += __builtin_convertvector(add[x], Sum) - __builtin_convertvector(sub[x], Sum);
    }
    for (int c = 0; c < 4; ++c)
        s_io[c] = s[c];
}

// A stretch for NC channels, one channel at a time (four: box_stretch_rgba).
template<int NC, bool Ends>
inline __attribute__((always_inline)) void box_stretch(float* out, const BoxStreams& st, int n,
                                                       double* s, double inner, double end)
{
    if constexpr (NC == 4) {
        box_stretch_rgba<Ends>(out, st, n, s, inner, end);
    } else {
        auto value = [&](double sum, size_t j) __attribute__((always_inline)) {
            return Ends ? float(inner * sum + end * (double(st.lo[j]) + double(st.hi[j])))
                        : float(inner * sum);
        };
        const float *add = st.add, *sub = st.sub;
        int x = 0;
        for (; x + 4 <= n; x += 4) {
            const size_t i = size_t(x) * NC;
            double q[4][NC];  // q[k]: the sum k pixels on, less s
            for (int c = 0; c < NC; ++c) {
                q[0][c] = 0.0;
                q[1][c] = double(add[i + c]) - double(sub[i + c]);
                q[2][c] = q[1][c] + (double(add[i + NC + c]) - double(sub[i + NC + c]));
                q[3][c] = q[2][c] + (double(add[i + 2 * NC + c]) - double(sub[i + 2 * NC + c]));
            }
            for (int k = 0; k < 4; ++k)
                for (int c = 0; c < NC; ++c) {
                    const size_t j = i + size_t(k) * NC + size_t(c);
                    out[j] = value(s[c] + q[k][c], j);
                }
            for (int c = 0; c < NC; ++c)
                s[c] += q[3][c] + (double(add[i + 3 * NC + c]) - double(sub[i + 3 * NC + c]));
        }
        for (; x < n; ++x)
            for (int c = 0; c < NC; ++c) {
                const size_t j = size_t(x) * NC + size_t(c);
                out[j] = value(s[c], j);
                s[c] += double(add[j]) - double(sub[j]);
            }
    }
}

// The running box per channel count, each multiversioned; `zero` is npx black pixels.
#define BOKEH_BOX_ROW(NC)                                                                        \
    BOKEH_HOT void box_row_running##NC(float* out, const RowSpan& v, const float* zero, int npx, \
                                       int radius, int full, double inner, double end)           \
    {                                                                                            \
        box_row_stretches<NC>(                                                                   \
            v, zero, npx, radius, full, end != 0.0,                                              \
            [&](int x, const BoxStreams& st, int n, double* s) __attribute__((always_inline)) {  \
                float* o = out + size_t(x) * NC;                                                 \
                if (end != 0.0)                                                                  \
                    box_stretch<NC, true>(o, st, n, s, inner, end);                              \
                else                                                                             \
                    box_stretch<NC, false>(o, st, n, s, inner, end);                             \
            });                                                                                  \
    }
BOKEH_BOX_ROW(1)
BOKEH_BOX_ROW(3)
BOKEH_BOX_ROW(4)
#undef BOKEH_BOX_ROW

// The running box for 1, 3 or 4 channels; false for other counts.
bool box_row_running(float* out, const RowSpan& v, const float* zero, int npx, int nc, int radius,
                     int full, double inner, double end)
{
    switch (nc) {
    case 1: box_row_running1(out, v, zero, npx, radius, full, inner, end); return true;
    case 3: box_row_running3(out, v, zero, npx, radius, full, inner, end); return true;
    case 4: box_row_running4(out, v, zero, npx, radius, full, inner, end); return true;
    default: return false;
    }
}

// One box along a padded row `v` of npx + 2 b.radius pixels (black ones filled in) into
// `out` (npx pixels) by the row's prefix sums: the channel counts box_row_running has no
// running sum for.
void box_row_by_prefix_sums(float* out, const float* v, int npx, int nc, const BoxPass& b, double* prefix)
{
    const size_t ncs = size_t(nc), n = size_t(npx) * ncs;
    row_prefix(prefix, v, size_t(npx + 2 * b.radius), nc);
    // Output x sums padded [x + radius - full, x + radius + full].
    const double* hi = prefix + size_t(b.radius + b.full + 1) * ncs;
    const double* lo = prefix + size_t(b.radius - b.full) * ncs;
    const bool ends  = b.end != 0.0;
    box_row(out, hi, lo, b.inner, ends ? v : nullptr, ends ? v + size_t(2 * b.radius) * ncs : nullptr, b.end, n);
}

// Box width whose variance is `variance` (bisection: variance grows with width).
double box_width_for_variance(double variance)
{
    auto var = [](double w) {
        const std::vector<double> b = box_weights_1d(w);
        const int r = int(b.size() / 2);
        double v    = 0.0;
        for (int i = -r; i <= r; ++i)
            v += b[size_t(i + r)] * i * i;
        return v;
    };
    double lo = 1.0, hi = 2.0 * std::sqrt(3.0 * variance) + 3.0;
    for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (lo + hi);
        (var(mid) < variance ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}

}  // namespace

namespace detail {

Plane box_blur(const Plane& in, const std::vector<double>& wx, const std::vector<double>& wy,
               int nthreads)
{
    return box_vertical(box_horizontal(in, BoxPass(wx), nthreads), BoxPass(wy), nthreads);
}

// The box straight from the source ImageBuf into `dst` (no padded plane, no middle plane,
// no copy out). Each task owns a strip of output columns (column_chunks) and walks down
// it: the horizontal pass reads one source row of the strip plus the box's reach (in
// place; under the clamp and mirror borders an edge strip's row is filled into a small
// buffer by the border rule), slides a double running sum along it and keeps the result
// in a ring of the last 2 ry + 2 rows (3.9 MiB at 960 columns and ry = 127; black rows
// are not stored, but read from one zero row); the vertical running sum (double) over
// that ring is written straight into `dst`. The source and `dst` are each touched once,
// so the cost is one read and one write of the frame plus the arithmetic, whatever the
// size. Prefix sums start afresh at every strip, so they never grow beyond the sum of one
// strip's row (a 1e6 pixel leaves no drift); the strips are fixed by the width, so the
// result does not depend on the thread count.

bool box_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                const BoxPass& bx, const BoxPass& by, Border border, int nthreads)
{
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    const int w = roi.width(), h = roi.height(), ry = by.radius;
    const int ring = 2 * ry + 2;  // rows y .. y + 2 ry are in use, and row y - 1 by the slide
    for_each_column_strip(w, nthreads, [&](int xs, int xe) {
        const size_t n = size_t(xe - xs) * ncs;
        const size_t nrow = size_t(xe - xs + 2 * bx.radius) * ncs;
        // The ring starts uninitialised: a slot is written before it is read, or marked
        // black (a row outside the source under the black border) and read as `black`.
        Plane rows(xe - xs, ring, nc);
        std::vector<char> slot_black(size_t(ring), 0);
        std::vector<float> row(nrow), black(n, 0.0f), out_row(n);
        std::vector<double> prefix(nrow + ncs), sum(n, 0.0);
        // Horizontal box of padded row j (source row roi.ybegin - ry + j) into its ring slot.
        auto horizontal = [&](int j) {
            float* o       = rows.row(j % ring);
            const int x0   = roi.xbegin + xs - bx.radius, x1 = roi.xbegin + xe + bx.radius;
            const int sy       = roi.ybegin - ry + j;
            const RowSpan span = bordered_row_span(in, sy, x0, x1, border, row.data());
            slot_black[size_t(j % ring)] = !span.p;
            if (!span.p)
                return;
            // The common channel counts slide a running sum; others take prefix sums.
            if (box_row_running(o, span, black.data(), xe - xs, nc, bx.radius, bx.full, bx.inner,
                                bx.end))
                return;
            box_row_by_prefix_sums(o, span.lo == 0 && span.hi == x1 - x0 ? span.p
                                                                       : bordered_row_view(in, sy, x0, x1, border, row.data()),
                                   xe - xs, nc, bx, prefix.data());
        };
        auto ring_row = [&](int j) -> const float* {
            return slot_black[size_t(j % ring)] ? black.data() : rows.row(j % ring);
        };
        for (int j = 0; j < 2 * ry; ++j)
            horizontal(j);
        const bool ends = by.end != 0.0;
        for (int y = 0; y < h; ++y) {
            horizontal(y + 2 * ry);
            const int centre = y + ry;
            if (y == 0) {
                for (int j = -by.full; j <= by.full; ++j)
                    if (!slot_black[size_t((centre + j) % ring)])  // adding 0 changes no sum
                        add_scaled(sum.data(), ring_row(centre + j), 1.0, n);
            } else {
                slide(sum.data(), ring_row(centre + by.full), ring_row(centre - 1 - by.full), n);
            }
            box_out(out_row.data(), sum.data(), by.inner,
                    ends ? ring_row(centre - by.full - 1) : nullptr,
                    ends ? ring_row(centre + by.full + 1) : nullptr, by.end, n);
            // Past the caches (bokeh-ab: 0.88-0.98x the time at 15-255 px, 1080p RGBA).
            stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + y)),
                          out_row.data(), n);
        }
        stream_fence();
    });
    return true;
}

// BlurMethod::ThreeBoxes straight from the source to `dst`: each task walks down a strip
// of output columns; a padded row is boxed three times along x in L1, then goes down
// three running sums along y, each holding a ring of the rows it reads (the box's
// 2 radius + 2), the rows of one fed to the next, instead of three box_direct passes over
// whole frames, each into a fresh image (two of them, zeroed page by page). The same
// arithmetic as those three passes in another order (all x boxes before the y boxes): they
// differ by float rounding.
bool three_boxes_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi, const BoxPass& bx,
                        const BoxPass& by, Border border, int nthreads)
{
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    const int w = roi.width(), h = roi.height(), rx = bx.radius, ry = by.radius;
    const int ring = 2 * ry + 2;
    for_each_column_strip(w, nthreads, [&](int xs, int xe) {
        const int npx = xe - xs;
        const size_t n = size_t(npx) * ncs;
        const int x0 = roi.xbegin + xs - 3 * rx, x1 = roi.xbegin + xe + 3 * rx;
        std::vector<float> row(size_t(x1 - x0) * ncs), once(size_t(npx + 4 * rx) * ncs),
            twice(size_t(npx + 2 * rx) * ncs), black(size_t(x1 - x0) * ncs, 0.0f), out_row(n);
        std::vector<double> prefix(size_t(x1 - x0 + 1) * ncs);
        // The three vertical boxes: stage k's ring holds its input rows, `count` of them so
        // far; its output row q reads input rows q .. q + 2 ry (the box centred on q + ry).
        struct Stage {
            Plane rows;
            std::vector<double> sum;
            int count = 0;
        };
        std::array<Stage, 3> stages;
        for (Stage& st : stages) {
            st.rows = Plane(npx, ring, nc);  // each slot written before it is read
            st.sum.assign(n, 0.0);
        }
        const bool ends = by.end != 0.0;
        // Where the row entering stage k is written: its ring's next slot.
        auto entry = [&](int k) { return stages[size_t(k)].rows.row(stages[size_t(k)].count % ring); };
        // A row has entered stage 0: each stage with a new output row (q reads its input
        // rows q .. q + 2 ry) writes it into the next stage's entry, the last into dst.
        auto advance = [&] {
            for (int k = 0; k < 3; ++k) {
                Stage& st = stages[size_t(k)];
                const int r = st.count++;
                if (r < 2 * ry)
                    return;
                const int q = r - 2 * ry, centre = q + ry;
                auto at = [&](int j) { return st.rows.row(j % ring); };
                if (q == 0) {
                    for (int j = -by.full; j <= by.full; ++j)
                        add_scaled(st.sum.data(), at(centre + j), 1.0, n);
                } else {
                    slide(st.sum.data(), at(centre + by.full), at(centre - 1 - by.full), n);
                }
                float* o = k < 2 ? entry(k + 1) : out_row.data();
                box_out(o, st.sum.data(), by.inner, ends ? at(centre - by.full - 1) : nullptr,
                        ends ? at(centre + by.full + 1) : nullptr, by.end, n);
                if (k == 2)
                    stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + q)), o, n);
            }
        };
        // Each along x: a running sum (1, 3, 4 channels) or the row's prefix sums.
        auto box_x = [&](float* out, const RowSpan& v, int npx_out, auto full_row) {
            if (!box_row_running(out, v, black.data(), npx_out, nc, rx, bx.full, bx.inner, bx.end))
                box_row_by_prefix_sums(out, full_row(), npx_out, nc, bx, prefix.data());
        };
        for (int j = 0; j < h + 6 * ry; ++j) {
            const int sy       = roi.ybegin - 3 * ry + j;
            const RowSpan span = bordered_row_span(in, sy, x0, x1, border, row.data());
            if (!span.p) {
                std::fill_n(entry(0), n, 0.0f);
            } else {
                box_x(once.data(), span, npx + 4 * rx, [&] {
                    return span.lo == 0 && span.hi == x1 - x0 ? span.p
                                                               : bordered_row_view(in, sy, x0, x1, border, row.data());
                });
                box_x(twice.data(), RowSpan{ once.data(), 0, npx + 4 * rx }, npx + 2 * rx, [&] { return once.data(); });
                box_x(entry(0), RowSpan{ twice.data(), 0, npx + 2 * rx }, npx, [&] { return twice.data(); });
            }
            advance();
        }
        stream_fence();
    });
    return true;
}

// BlurMethod::ThreeBoxes' box along x and along y: three of each make the Gaussian's
// variance (Wells 1986, "Efficient synthesis of Gaussian filters by cascaded uniform
// filters"; the boxes fractional, so the variance is met exactly).
std::pair<std::vector<double>, std::vector<double>> gaussian_boxes(const Kernel& k)
{
    const auto [sx, sy] = gaussian_sigma(k);
    return { box_weights_1d(sx > 0 ? box_width_for_variance(sx * sx / 3.0) : 0.0),
             box_weights_1d(sy > 0 ? box_width_for_variance(sy * sy / 3.0) : 0.0) };
}

}  // namespace detail

KernelWeights three_box_weights(const Kernel& k)
{
    const auto [bx, by] = gaussian_boxes(k);
    auto thrice         = [](const std::vector<double>& b) {  // b * b * b
        std::vector<double> w{ 1.0 };
        for (int pass = 0; pass < 3; ++pass) {
            std::vector<double> next(w.size() + b.size() - 1, 0.0);
            for (size_t i = 0; i < w.size(); ++i)
                for (size_t j = 0; j < b.size(); ++j)
                    next[i + j] += w[i] * b[j];
            w.swap(next);
        }
        return w;
    };
    return outer(thrice(bx), thrice(by));
}

}  // namespace bokeh
