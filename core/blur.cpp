// blur.cpp — uniform blurs: box by running sums, Gaussian (and OIIO's separable filters,
// oiiotool's other --blur kernels) by separable convolution, the Gaussian also by three
// boxes, disk and polygon by row spans, and the brute-force reference.
//
// The exact box, separable and row-span methods, the three boxes (and the bands and
// parallelograms of blur_approx.cpp) read the source
// ImageBuf and write the destination directly, tile by tile ("direct" paths below); the
// others, and every method in iris mode, work as a "valid" convolution of a padded plane:
// the source region the output needs, grown by the kernel radius and filled past the data
// window by the border rule, copied once into a contiguous float plane.
//
// What changed and why (speed, issue 3): the plane path cost a padded copy and a copy out
// (~14 ms at 1080p) and, for spans and bands, a whole-frame double prefix plane of 68-77 MB
// (~60 ms); every pass was memory-bound. The direct paths keep their double sums per tile
// or column strip, in L2 (the sums also restart per tile, so they stay small: no drift
// from a 1e6 pixel), fuse the border rule into reading, and write the result once.
// * Box: per column strip (256 px; 512 for wide boxes), a horizontal running sum per
//   source row into a ring of the last 2 ry + 2 rows, and the vertical running sum over
//   the ring straight into `dst`.
// * Spans: per 128 x (>= 256)-pixel tile, the rows' prefix sums in a ring, then 128 x 4 sub-tiles
//   whose double accumulators stay in L1, each prefix row visited once per sub-tile and
//   the spans of two kernel rows added per pass (add_spans; with the blocked row_prefix,
//   3-4 % faster than one row per pass, A/B in one process); with 4 channels each prefix
//   row is kept twice, the copy one pixel on, so every span's vector loads start on a
//   64-byte boundary.
// * Spans of a kernel mirrored in y (a disk; a polygon symmetric about its horizontal axis;
//   convolve_symmetric_spans): each prefix row is computed once per tile and its span sums
//   for rows dy and -dy, the same spans, are added into both output rows that read them,
//   held in a ring of 2 ry + 1 output rows: 0.65-0.8x the time of the general path.
// * Bands: their own running sums per column strip (convolve_bands_direct, blur_approx.cpp).
// * Parallelograms: one sweep down the rows (hexagon_direct, blur_approx.cpp), in a frame
//   with sheared columns or rows at rotations off multiples of 30 degrees.
// * Gaussian by three boxes (session 16): per column strip, each padded row boxed three
//   times along x, then three running sums down the rows, each with its ring
//   (three_boxes_direct; before, three whole-frame box passes into two fresh images).
// * Separable convolution (the Gaussian below the FFT's crossover, OIIO's separable
//   filters; session 16): per column strip, each padded row filtered along x into a ring
//   of 2 ry + 1 rows, the ring's rows summed along y into `dst`, 16 sums held in registers
//   over every tap (separable_direct, weighted_sum; the same bits as the plane path).
// Known limits: the span cost still grows linearly with the diameter (about 2.6 spans per
// kernel row: 161 at 63 px); a tile recomputes the prefix sums of its kernel-high margin
// (tile height >= twice the kernel height, so under half a row more per output row).
//
// Row spans (disk, polygon): each kernel row's weight profile is cut into horizontal
// bars ("skyline" decomposition: one bar per rise of the profile), so a kernel becomes a
// list of (dy, x0, x1, weight) spans; a span's sum is a difference of two row prefix sums.
// Cost per pixel is linear in the number of spans, about 3 per kernel row for convex
// anti-aliased shapes, so linear in the diameter (SEEDS.md section 5 asks for cost that
// does not grow with the area). Prefix sums are double so a 1e6 pixel leaves no drift;
// output rows are computed in column strips so the rows of prefix sums in use stay in L2.
//
// Running sums (box): one add and one subtract per pixel per pass whatever the width,
// in double; a fractional width adds its two partial end pixels explicitly. Channel counts
// 1, 3 and 4 slide a running sum along the row; other counts take a row's prefix sums.
//
// Fast Gaussian: three equal boxes whose variance adds up to sigma^2 (central limit;
// Wells 1986, "Efficient synthesis of Gaussian filters by cascaded uniform filters"). The
// box width is fractional, so the variance matches exactly, not to the nearest odd width.
//
// Non-finite source values (session 15): every method above would carry a NaN or an
// infinity beyond its footprint (running and prefix sums along the row, the FFT over its
// tile). One pass over the source finds them (any_nonfinite, about a read of the frame:
// +1.1-1.9 ms at 1080p RGBA); if any, blur_nonfinite gives the brute force's answer.

#include <bokeh/blur.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>

#include "plane.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <tuple>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

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

// --- weighted sums of rows (separable passes, brute force) ------------------------

// Each row y of `out` = sum_j w[j] * source(y, j), accumulated in double (weighted_sum:
// 16 sums in registers over every tap; a row of double sums, added to once a tap, was
// load- and store-bound, 61 KiB a 1080p RGBA row, past L1).
template<class Source>
void weighted_rows(Plane& out, const std::vector<double>& w, Source source, int nthreads)
{
    parallel_for_chunks(0, out.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        std::vector<const float*> taps(w.size());
        for (int y = int(y0); y < int(y1); ++y) {
            for (size_t j = 0; j < w.size(); ++j)
                taps[j] = source(y, j);
            weighted_sum(out.row(y), taps.data(), w.data(), w.size(), out.stride());
        }
    });
}

// --- brute force -------------------------------------------------------------------

Plane convolve_brute(const Plane& in, const KernelWeights& kernel, int nthreads)
{
    const KernelWeights k = reflected(kernel);
    // The non-zero taps as (row offset, column offset) with their weights.
    std::vector<std::pair<int, int>> taps;
    std::vector<double> weights;
    for (int dy = -k.ry; dy <= k.ry; ++dy)
        for (int dx = -k.rx; dx <= k.rx; ++dx)
            if (k.at(dx, dy) != 0.0) {
                taps.emplace_back(k.ry + dy, k.rx + dx);
                weights.push_back(k.at(dx, dy));
            }
    Plane out(in.w - 2 * k.rx, in.h - 2 * k.ry, in.nc);
    const size_t nc = size_t(in.nc);
    weighted_rows(out, weights,
                  [&](int y, size_t j) { return in.row(y + taps[j].first) + size_t(taps[j].second) * nc; },
                  nthreads);
    return out;
}

// --- separable passes --------------------------------------------------------------

// Horizontal then vertical direct convolution with 1-D weights (Gaussian).
Plane convolve_separable(const Plane& in, const std::vector<double>& wx,
                         const std::vector<double>& wy, int nthreads)
{
    const int rx = int(wx.size() / 2), ry = int(wy.size() / 2);
    const size_t nc = size_t(in.nc);
    Plane mid(in.w - 2 * rx, in.h, in.nc);
    weighted_rows(mid, wx, [&](int y, size_t j) { return in.row(y) + j * nc; }, nthreads);
    Plane out(mid.w, in.h - 2 * ry, in.nc);
    weighted_rows(out, wy, [&](int y, size_t j) { return mid.row(y + int(j)); }, nthreads);
    return out;
}

// A box of fractional width, read off its 1-D weights: `full` pixels each side at
// weight `inner`, then one end pixel each side at weight `end` (0 when none).
struct BoxPass {
    int full = 0, radius = 0;
    double inner = 1.0, end = 0.0;
    explicit BoxPass(const std::vector<double>& w)
    {
        radius = int(w.size() / 2);
        inner  = w[size_t(radius)];
        const bool partial = radius > 0 && w.front() != inner;
        full   = partial ? radius - 1 : radius;
        end    = partial ? w.front() : 0.0;
    }
};

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

Plane box_blur(const Plane& in, const std::vector<double>& wx, const std::vector<double>& wy,
               int nthreads)
{
    return box_vertical(box_horizontal(in, BoxPass(wx), nthreads), BoxPass(wy), nthreads);
}

// The first 64-byte boundary at or after p (p from an allocation of 8 doubles more).
double* aligned64(double* p)
{
    return p + (8 - (reinterpret_cast<uintptr_t>(p) / sizeof(double)) % 8) % 8;
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
// bits. (The one- and three-channel clones are scalar, left so: the figures are
// RGBA.)
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
            // Past the caches (session 13: A/B 0.88-0.98x at 15-255 px, 1080p RGBA).
            stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + y)),
                          out_row.data(), n);
        }
        stream_fence();
    });
    return true;
}

// The separable convolution straight from the source to `dst` (the Gaussian's and OIIO's
// separable filters' exact method outside iris mode): each task walks down a strip of
// output columns, filters each padded source row along x into a ring of the last 2 ry + 1
// rows, and sums the ring's rows along y into the output row, each value's taps in the
// order convolve_separable adds them (the same bits). Before, a padded plane, a middle
// and an output plane (fresh pages: their zeroing took a quarter of the time) and a copy
// into `dst`.
bool separable_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                      const std::vector<double>& wx, const std::vector<double>& wy, Border border, int nthreads)
{
    prepare_destination(dst, in, roi);
    const size_t ncs = size_t(in.nchannels());
    const int w = roi.width(), h = roi.height();
    const int rx = int(wx.size() / 2), ry = int(wy.size() / 2), ring = 2 * ry + 1;
    for_each_column_strip(w, nthreads, [&](int xs, int xe) {
        const size_t n = size_t(xe - xs) * ncs;
        const int x0 = roi.xbegin + xs - rx, x1 = roi.xbegin + xe + rx;
        Plane rows(xe - xs, ring, int(ncs));  // written before read, or marked black
        std::vector<char> slot_black(size_t(ring), 0);
        std::vector<float> row(size_t(x1 - x0) * ncs), black(n, 0.0f), out_row(n);
        std::vector<const float*> taps(std::max(wx.size(), wy.size()));
        // The last padded row that read each source row: past an edge the clamp and mirror
        // borders read source rows again, and one still in the ring is copied, not filtered
        // again (a sigma 512 Gaussian on a 960 x 64 image: 13 s under clamp and 7 s under
        // mirror before, 1.1 and ~1 s after; the same bits).
        const int src_y0 = in.roi().ybegin;
        std::vector<int> last_read(size_t(in.roi().height()), std::numeric_limits<int>::min());
        // Padded row j (source row roi.ybegin - ry + j) along x into its ring slot.
        auto horizontal = [&](int j) {
            const int sy     = roi.ybegin - ry + j;
            const int source = border_index(sy, src_y0, in.roi().yend, border);
            if (source != kOutside) {
                int& prev = last_read[size_t(source - src_y0)];
                if (prev != std::numeric_limits<int>::min() && j - prev < ring) {
                    slot_black[size_t(j % ring)] = slot_black[size_t(prev % ring)];
                    if (prev % ring != j % ring)
                        std::copy_n(rows.row(prev % ring), n, rows.row(j % ring));
                    prev = j;
                    return;
                }
                prev = j;
            }
            const RowSpan span = bordered_row_span(in, sy, x0, x1, border, row.data());
            slot_black[size_t(j % ring)] = !span.p;
            if (!span.p)
                return;
            const float* v = span.lo == 0 && span.hi == x1 - x0 ? span.p
                                                                 : bordered_row_view(in, sy, x0, x1, border, row.data());
            for (size_t t = 0; t < wx.size(); ++t)
                taps[t] = v + t * ncs;
            weighted_sum(rows.row(j % ring), taps.data(), wx.data(), wx.size(), n);
        };
        for (int j = 0; j < 2 * ry; ++j)
            horizontal(j);
        for (int y = 0; y < h; ++y) {
            horizontal(y + 2 * ry);
            for (int t = 0; t < ring; ++t)
                taps[size_t(t)] = slot_black[size_t((y + t) % ring)] ? black.data() : rows.row((y + t) % ring);
            weighted_sum(out_row.data(), taps.data(), wy.data(), wy.size(), n);
            stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + y)), out_row.data(), n);
        }
        stream_fence();
    });
    return true;
}

// BlurMethod::ThreeBoxes straight from the source to `dst`: each task walks down a strip
// of output columns; a padded row is boxed three times along x in L1, then goes down
// three running sums along y, each holding a ring of the rows it reads (the box's
// 2 radius + 2), the rows of one fed to the next. Before (sessions 9-15), three box_direct
// passes over whole frames, each into a fresh image (two of them, zeroed page by page).
// The same arithmetic in another order (all x boxes before the y boxes): float rounding.
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

// BlurMethod::ThreeBoxes' box along x and along y: three of each make the Gaussian's
// variance (Wells 1986, "Efficient synthesis of Gaussian filters by cascaded uniform
// filters"; the boxes fractional, so the variance is met exactly).
std::pair<std::vector<double>, std::vector<double>> gaussian_boxes(const Kernel& k)
{
    const auto [sx, sy] = gaussian_sigma(k);
    return { box_weights_1d(sx > 0 ? box_width_for_variance(sx * sx / 3.0) : 0.0),
             box_weights_1d(sy > 0 ? box_width_for_variance(sy * sy / 3.0) : 0.0) };
}

// --- dispatch ----------------------------------------------------------------------

}  // namespace

namespace detail {

void row_prefix_sums(const Plane& in, double* prefix, int nthreads)
{
    const size_t nc = size_t(in.nc), pstride = size_t(in.w + 1) * nc;
    parallel_for_chunks(0, in.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y)
            row_prefix(prefix + size_t(y) * pstride, in.row(int(y)), size_t(in.w), in.nc);
    });
}

// The weights point-reflected: out(x) = sum_d w(d) in(x - d) = sum_d w(-d) in(x + d), so a
// point spreads into the kernel's own shape (this matters for shapes without point
// symmetry, such as a pentagon).
KernelWeights reflected(const KernelWeights& k)
{
    KernelWeights r = k;
    std::reverse(r.w.begin(), r.w.end());
    return r;
}

// Skyline decomposition of each kernel row into stacked horizontal bars.
std::vector<Span> kernel_spans(const KernelWeights& k)
{
    std::vector<Span> spans;
    struct Open {
        int start;
        double level;
    };
    for (int dy = -k.ry; dy <= k.ry; ++dy) {
        std::vector<Open> stack;
        for (int dx = -k.rx; dx <= k.rx + 1; ++dx) {
            const double h = dx <= k.rx ? k.at(dx, dy) : 0.0;
            while (!stack.empty() && h < stack.back().level) {
                const Open top = stack.back();
                stack.pop_back();
                const double below = std::max(h, stack.empty() ? 0.0 : stack.back().level);
                spans.push_back({ dy, top.start, dx - 1, top.level - below });
                if (h > (stack.empty() ? 0.0 : stack.back().level)) {
                    stack.push_back({ top.start, h });  // the lower part continues
                    break;
                }
            }
            if (h > (stack.empty() ? 0.0 : stack.back().level))
                stack.push_back({ dx, h });
        }
    }
    return spans;
}

// --- row spans ---------------------------------------------------------------------

Plane convolve_spans(const Plane& in, const KernelWeights& kernel, int nthreads)
{
    const int nc = in.nc;
    Plane out(in.w - 2 * kernel.rx, in.h - 2 * kernel.ry, nc);
    const KernelWeights k         = reflected(kernel);
    const std::vector<Span> spans = kernel_spans(k);

    // Row prefix sums: P[y][(x + 1) nc + c] = sum of in[y][0..x] in channel c.
    const size_t pstride = size_t(in.w + 1) * size_t(nc);
    // Every entry is written below: no need to zero 8 bytes x 4 channels x the plane.
    std::unique_ptr<double[]> prefix(new double[size_t(in.h) * pstride]);
    row_prefix_sums(in, prefix.get(), nthreads);

    accumulate_in_strips(out, nthreads, [&](int y, size_t i0, std::vector<double>& acc) {
        for (const Span& s : spans) {
            const double* p  = prefix.get() + size_t(y + k.ry + s.dy) * pstride + i0;
            const double* hi = p + size_t(k.rx + s.x1 + 1) * size_t(nc);
            const double* lo = p + size_t(k.rx + s.x0) * size_t(nc);
            add_span(acc.data(), hi, lo, s.weight, acc.size());
        }
    });
    return out;
}

// Single-thread time in ns of convolve_spans_direct over a w x h output, per channel:
// 0.10 ns per span and pixel (two prefix loads and a multiply-add) and 0.29 per kernel
// row and pixel (the row's accumulators loaded and stored, its prefix row found), both
// 0.7 of that for a kernel mirrored in y (convolve_symmetric_spans shares each span's sum
// between two output rows: 0.65-0.79x the time, A/B, session 8), plus 0.75 for the prefix
// sums and the copy out. Fitted (least relative squares) to 44 timings at 1080p RGBA on
// two threads, session 10: disks 15-191 px, hexagons at 0, 30 and 7 degrees, pentagons,
// a curved octagon, 2:1 and 1:2 ellipses and a catadioptric disk; it reads them within
// 0.84-1.21 of measured. The model before charged spans alone (0.15 ns each, growing
// with the rows): it read a hexagon's spans up to 1.30x low and large or holed kernels
// up to 1.7x high (a hexagon has ~2.2 spans per row against a disk's 2.6, a holed disk 5).
double spans_cost_ns(int w, int h, const std::vector<Span>& spans)
{
    std::set<int> rows;
    for (const Span& s : spans)
        rows.insert(s.dy);
    const double shared = spans_mirror_in_y(spans) ? 0.7 : 1.0;
    return double(w) * double(h)
           * (shared * (0.10 * double(spans.size()) + 0.29 * double(rows.size())) + 0.75);
}

// Single-thread time in ns of the separable convolution over a w x h output, per channel:
// ~0.4 ns per tap of the two passes, plus ~2 for the padded plane and the copy out.
// Fitted to Gaussians at 1080p on the project's machine (sigma = size / 4, 8 sigma + 1
// taps per pass; 2 threads: 114, 213, 407 ms at sizes 15, 31, 63; the model errs low
// above, 2250 ms measured at 255 against 1700). Session 16 (separable_direct, this
// machine): 43, 54, 71, 88, 116 ms at sizes 11, 15, 19, 23, 31 against the FFT tiles' 78,
// 60, 64, 93, 96 (medians of 9, one run): the crossover still falls between 19 and 31, so
// the model, which puts it at sigma ~7 (size 28), is left as it is.
double separable_cost_ns(int w, int h, int taps_x, int taps_y)
{
    return double(w) * double(h) * (0.4 * double(taps_x + taps_y) + 2.0);
}

bool spans_mirror_in_y(const std::vector<Span>& spans)
{
    std::map<int, std::vector<std::tuple<int, int, double>>> rows;
    for (const Span& s : spans)
        rows[s.dy].emplace_back(s.x0, s.x1, s.weight);
    for (const auto& [dy, bars] : rows) {
        const auto mirror = rows.find(-dy);
        if (mirror == rows.end() || mirror->second != bars)
            return false;
    }
    return true;
}

// Padded source row y over columns [x0, x1) as row prefix sums into p (pw values); with
// twin_at, again from p[twin_at] one pixel on (see convolve_spans_direct).
void span_prefix_row(double* p, const OIIO::ImageBuf& in, int y, int x0, int x1, Border border,
                     float* row, size_t pw, size_t twin_at)
{
    const size_t ncs = size_t(in.nchannels());
    const float* v   = bordered_row_view(in, y, x0, x1, border, row);
    if (v)
        row_prefix(p, v, pw / ncs - 1, in.nchannels());
    else
        std::fill_n(p, pw, 0.0);
    if (twin_at)
        std::copy(p + ncs, p + pw, p + twin_at);
}

// Columns per tile of the row-span methods (see convolve_spans_direct).
constexpr int kSpanTileW = 128;

// The row spans of a kernel whose rows dy and -dy have the same spans, from the source
// into `dst`, in tiles of kSpanTileW columns as convolve_spans_direct's. Prefix row r is
// read as row d = dy + ry of output row r - d and, with the same spans, as row
// nd - 1 - d of output row r - nd + 1 + d: its span sums for each d are computed once and
// added into both (add_spans_pair), so each span costs its two loads and two operations
// once per pair of output rows instead of once per output row. Each prefix row is used
// once, as it arrives, so the tile keeps a ring of the 2 ry + 1 output rows being summed
// instead of prefix rows (258 KB in double at 63 px, in L2). A/B against the general
// path: 0.77x at 63 px, 0.75x at 31, 0.79x at 15, 0.65x at 127, the same bits to 3e-8.
// A row's first spans are stored, not added, and its last written out with them as float
// (start_and_finish_rows), so no pass zeroes or copies the ring: 0.93-0.97x more at
// 15-63 px. Narrower column strips, so the ring fits L1, measured slower (16 px: 1.11x
// at 63; 64 px: 0.84x): a span's loop over fewer columns pays its setup more often.
// Tiles are fixed by the kernel and the image, so results do not depend on the thread
// count.
bool convolve_symmetric_spans(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                              int rx, int ry, const std::vector<size_t>& first,
                              const std::vector<size_t>& hi_off, const std::vector<size_t>& lo_off,
                              const std::vector<double>& span_w, size_t rs, size_t twin_at,
                              Border border, int nthreads)
{
    const int nc     = in.nchannels();
    const size_t ncs = size_t(nc);
    const int nd     = 2 * ry + 1;
    size_t most      = 0;
    for (size_t d = 0; d + 1 < first.size(); ++d)
        most = std::max(most, first[d + 1] - first[d]);
    const int w = roi.width(), h = roi.height();
    const int th  = std::max(256, 2 * nd);
    const int ntx = (w + kSpanTileW - 1) / kSpanTileW, nty = (h + th - 1) / th;
    parallel_for_chunks(0, int64_t(ntx) * nty, 1, nthreads, [&](int64_t t, int64_t) {
        const int xs = int(t % ntx) * kSpanTileW, xe = std::min(w, xs + kSpanTileW);
        const int ys = int(t / ntx) * th, ye = std::min(h, ys + th);
        const int rows_out = ye - ys;
        const size_t pw    = size_t(xe - xs + 2 * rx + 1) * ncs;  // one prefix row
        const size_t n     = size_t(xe - xs) * ncs;                // one output row
        // Uninitialised: every value read is written below.
        std::unique_ptr<double[]> prefix_store(new double[rs + 8]);
        double* const p = aligned64(prefix_store.get());
        std::vector<float> row(pw);
        // Output row yl sums into ring row yl % nd, set by its first prefix row.
        const size_t an = (n + 7) / 8 * 8;  // rows on 64-byte boundaries
        std::vector<double> acc_store(size_t(nd) * an + 8);
        double* const acc_base = aligned64(acc_store.data());
        auto acc = [&](int yl) { return acc_base + size_t(yl % nd) * an; };
        std::vector<const double*> hi_ptr(most), lo_ptr(most);
        for (int r = 0; r < rows_out + nd - 1; ++r) {
            span_prefix_row(p, in, roi.ybegin + ys - ry + r, roi.xbegin + xs - rx, roi.xbegin + xe + rx,
                            border, row.data(), pw, twin_at);
            for (int d = 0; d <= ry; ++d) {
                const int ya = r - d, yb = r - (nd - 1 - d);
                const bool a_ok = ya >= 0 && ya < rows_out;
                const bool b_ok = d < ry && yb >= 0 && yb < rows_out;
                if (!a_ok && !b_ok)
                    continue;
                size_t count = 0;
                for (size_t i = first[size_t(d)]; i < first[size_t(d) + 1]; ++i, ++count) {
                    hi_ptr[count] = p + hi_off[i];
                    lo_ptr[count] = p + lo_off[i];
                }
                const double* w_d = span_w.data() + first[size_t(d)];
                if (d > 0) {
                    add_spans_pair(a_ok ? acc(ya) : acc(yb), a_ok && b_ok ? acc(yb) : nullptr,
                                   hi_ptr.data(), lo_ptr.data(), w_d, count, n);
                    continue;
                }
                // d = 0: prefix row r is output row r's first (ya = r) and output row
                // r - 2 ry's last (yb): the one is stored, not added to, and the other
                // written out as float, with no pass to zero or copy either.
                float* out = b_ok ? static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + ys + yb))
                                  : nullptr;
                start_and_finish_rows(a_ok ? acc(ya) : nullptr, b_ok ? acc(yb) : nullptr, out,
                                      hi_ptr.data(), lo_ptr.data(), w_d, count, n);
            }
        }
    });
    return true;
}

// Exact convolution by row spans straight from the source ImageBuf into `dst`: no padded
// copy, no whole-frame prefix plane, no copy out. The output is cut into tiles of
// kSpanTileW columns x th rows; a tile takes the row prefix sums (double) of the source
// rows it reads, from its own first column on (border rule applied while reading), into a
// ring of its own that stays in L2: the rows one sub-tile reads, each computed once as the
// sub-tiles move down the tile. It then works in sub-tiles of kSubW x kSubH outputs
// whose double accumulators stay in L1, and walks the prefix rows once per sub-tile, each
// row adding its spans into every output row that reads it: each prefix row is fetched
// from L2 once per sub-tile instead of once per span and output row. Prefix sums start
// afresh at every tile, so they stay small (a 1e6 pixel leaves no drift, and digits are
// not lost to a long row's sum); tiles are fixed, so results do not depend on the thread
// count.
bool convolve_spans_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                           int rx, int ry, std::vector<Span> spans, Border border, int nthreads)
{
    // 128-column tiles: at D = 63 the tile's prefix ring (66 rows of 191 pixels, twice) is
    // 0.8 MB and stays in L2. Measured A/B in one process against 256 x 64 x 8: 5-9 % faster
    // at 15-127 px; sub-tiles of 32 x 16 were slower. The ring and tiles of >= 256 rows
    // (before: a table of all the tile's rows, tiles of 64 rows, so the prefix rows were
    // computed twice per output row at 63 px): 6-7 % faster at 63 and 127 px, same bits.
    constexpr int kSubW = 128, kSubH = 4;
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    // Output row y reads table rows y + d, d = dy + ry in [0, nd): the padded rows
    // y .. y + 2 ry.
    const int nd = 2 * ry + 1;
    std::stable_sort(spans.begin(), spans.end(),
                     [](const Span& a, const Span& b) { return a.dy < b.dy; });
    // first[d] .. first[d + 1]: the spans of table row d, as offsets into a table row
    // (hi, lo) and weights.
    std::vector<size_t> first(size_t(nd) + 1, spans.size());
    for (size_t i = spans.size(); i-- > 0;)
        first[size_t(spans[i].dy + ry)] = i;
    for (size_t d = first.size() - 1; d-- > 0;)
        first[d] = std::min(first[d], first[d + 1]);
    // A table row holds at most pmax values; rows are `rs` apart, on 64-byte boundaries.
    // With 4 channels a pixel is half a 64-byte vector, so half the spans would start
    // mid-vector and every load of theirs would split a cache line; each row is then
    // stored twice, the second copy one pixel on (twin), and a span starting at an odd
    // pixel reads the twin, from a vector boundary.
    const bool twin   = nc == 4;
    const size_t pmax = size_t(kSpanTileW + 2 * rx + 1) * ncs;
    const size_t pal  = (pmax + 7) / 8 * 8;
    const size_t rs   = twin ? 2 * pal : pal;
    auto offset = [&](int px) {
        return twin && px % 2 == 1 ? pal + size_t(px - 1) * ncs : size_t(px) * ncs;
    };
    std::vector<size_t> hi_off, lo_off;
    std::vector<double> span_w;
    for (const Span& s : spans) {
        hi_off.push_back(offset(rx + s.x1 + 1));
        lo_off.push_back(offset(rx + s.x0));
        span_w.push_back(s.weight);
    }

    // Rows dy and -dy with the same spans (a disk; a polygon symmetric about its
    // horizontal axis): each prefix row's span sums serve two output rows.
    if (ry > 0 && spans_mirror_in_y(spans))
        return convolve_symmetric_spans(dst, in, roi, rx, ry, first, hi_off, lo_off, span_w, rs,
                                        twin ? pal : 0, border, nthreads);

    // The most spans two consecutive kernel rows have (one pass of add_spans below).
    size_t most = 0;
    for (size_t d = 0; d + 1 < first.size(); ++d)
        most = std::max(most, first[std::min(d + 2, first.size() - 1)] - first[d]);
    const int w = roi.width(), h = roi.height();
    // Tile height: twice the kernel's at least, so a tile computes under 1.5 prefix rows
    // per output row (fixed by the kernel alone, never by the thread count).
    const int th = std::max(256, (2 * nd + kSubH - 1) / kSubH * kSubH);
    const int ntx = (w + kSpanTileW - 1) / kSpanTileW, nty = (h + th - 1) / th;
    // The prefix rows a sub-tile reads: a ring of that many, each row computed once per
    // tile as the sub-tiles move down.
    const int ring = nd - 1 + kSubH;
    parallel_for_chunks(0, int64_t(ntx) * nty, 1, nthreads, [&](int64_t t, int64_t) {
        const int xs = int(t % ntx) * kSpanTileW, xe = std::min(w, xs + kSpanTileW);
        const int ys = int(t / ntx) * th, ye = std::min(h, ys + th);
        const int tw = xe - xs;
        const size_t pw = size_t(tw + 2 * rx + 1) * ncs;  // one prefix row
        // Uninitialised: every value read is written below.
        std::unique_ptr<double[]> table_store(new double[size_t(ring) * rs + 8]);
        double* const table = aligned64(table_store.get());
        auto table_row = [&](int r) { return table + size_t(r % ring) * rs; };
        std::vector<float> row(pw);
        int computed = 0;  // tile-local prefix rows done
        auto compute_rows = [&](int r_end) {
            for (; computed < r_end; ++computed)
                span_prefix_row(table_row(computed), in, roi.ybegin + ys - ry + computed,
                                roi.xbegin + xs - rx, roi.xbegin + xe + rx, border, row.data(), pw,
                                twin ? pal : 0);
        };
        std::vector<const double*> hi_ptr(most), lo_ptr(most);
        std::vector<double> w_list(most);
        // Accumulators on a 64-byte boundary: rows of kSubW pixels then start on one too,
        // and no vector store splits a cache line.
        std::vector<double> acc_store(size_t(kSubH) * size_t(kSubW) * ncs + 8);
        double* const acc_base = aligned64(acc_store.data());
        const size_t acc_len = size_t(kSubH) * size_t(kSubW) * ncs;
        for (int sy0 = ys; sy0 < ye; sy0 += kSubH)
            for (int sx0 = xs; sx0 < xe; sx0 += kSubW) {
                const int sh = std::min(kSubH, ye - sy0);
                const size_t n = size_t(std::min(kSubW, xe - sx0)) * ncs;
                std::fill_n(acc_base, acc_len, 0.0);
                // Output row y (tile-local yl) reads prefix rows yl .. yl + 2 ry. Two prefix
                // rows at a time: each output row takes the spans of both in one pass.
                const int yl0   = sy0 - ys;
                const int r_end = yl0 + sh + nd - 1;
                compute_rows(r_end);
                for (int r = yl0; r < r_end; r += 2) {
                    const bool pair  = r + 1 < r_end;
                    const int j0 = std::max(0, r - yl0 - nd + 1);
                    const int j1 = std::min(sh, r - yl0 + (pair ? 2 : 1));
                    for (int j = j0; j < j1; ++j) {
                        size_t count = 0;
                        for (int q = 0; q < (pair ? 2 : 1); ++q) {
                            const int d = r + q - yl0 - j;
                            if (d < 0 || d >= nd)
                                continue;
                            const double* p = table_row(r + q) + size_t(sx0 - xs) * ncs;
                            for (size_t i = first[size_t(d)]; i < first[size_t(d) + 1]; ++i) {
                                hi_ptr[count] = p + hi_off[i];
                                lo_ptr[count] = p + lo_off[i];
                                w_list[count++] = span_w[i];
                            }
                        }
                        add_spans(acc_base + size_t(j) * n, hi_ptr.data(), lo_ptr.data(),
                                  w_list.data(), count, n);
                    }
                }
                for (int j = 0; j < sh; ++j)
                    to_float(static_cast<float*>(
                                 dst.pixeladdr(roi.xbegin + sx0, roi.ybegin + sy0 + j)),
                             acc_base + size_t(j) * n, n);
            }
    });
    return true;
}

bool fft_cheaper_than_spans(int w, int h, int nc, int rx, int ry, const std::vector<Span>& spans)
{
    return fft_convolve_cost_ns(w, h, nc, rx, ry) < 1.2 * nc * spans_cost_ns(w, h, spans);
}

// Non-finite source values (DESIGN.md, "bad values": never beyond the pixel's footprint).
// The running and prefix sums would carry a NaN or an infinity along the rest of its row
// and down the columns (and inf - inf is NaN), the FFT over its tile. So the blur runs on
// the source with them replaced (`clean`: by 0; in iris mode by the channel's least finite
// value, which leaves the range iris mode checks as the data's), and each output whose
// kernel has weight on one of them takes what the linear convolution gives it: an
// infinity (of the sign its weight gives it) where all those it reaches agree, NaN
// otherwise. (In iris mode exp(k * -inf) would be 0, so -inf would count for nothing
// there; one rule is kept for both.) Which outputs they reach: an indicator per channel
// and kind, convolved with the kernel's support (1 where its weight is positive; the
// negative weights of an image kernel, likewise, apart) by row spans, which leave exact
// whole counts, or by the FFT where the exact blur would take it (fft_cheaper_than_spans;
// counts to within 1e-9, read as reached from 0.5). Infinite depth (+inf in Z, "no depth") is the common case.
bool blur_nonfinite(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const std::vector<KernelWeights>& kernels,
                    const std::vector<int>& kernel_of, Border border, bool keep_range,
                    const std::function<bool(OIIO::ImageBuf&, const OIIO::ImageBuf&)>& clean, int nthreads)
{
    const OIIO::ROI data = in.roi();
    const int nc         = in.nchannels();
    const size_t ncs     = size_t(nc);
    // Kinds: 0 NaN, 1 +inf, 2 -inf; a negative weight swaps the infinities.
    auto kind = [](float v) { return std::isnan(v) ? 0 : v > 0.0f ? 1 : 2; };
    // Per channel: which kinds it holds (held[3 c + kind]) and its least finite value.
    struct Found {
        std::vector<int> held;
        std::vector<float> least;
    };
    const Found none{ std::vector<int>(3 * ncs, 0),
                      std::vector<float>(ncs, std::numeric_limits<float>::infinity()) };
    const Found found = parallel_reduce_chunks(
        data.ybegin, data.yend, 16, nthreads, none,
        [&](int64_t y0, int64_t y1) {
            Found f = none;
            for (int64_t y = y0; y < y1; ++y) {
                const float* row = static_cast<const float*>(in.pixeladdr(data.xbegin, int(y), data.zbegin));
                for (size_t i = 0; i < size_t(data.width()) * ncs; ++i) {
                    if (std::isfinite(row[i]))
                        f.least[i % ncs] = std::min(f.least[i % ncs], row[i]);
                    else
                        f.held[3 * (i % ncs) + size_t(kind(row[i]))] = 1;
                }
            }
            return f;
        },
        [](Found& acc, const Found& part) {
            for (size_t i = 0; i < acc.held.size(); ++i)
                acc.held[i] |= part.held[i];
            for (size_t c = 0; c < acc.least.size(); ++c)
                acc.least[c] = std::min(acc.least[c], part.least[c]);
        });
    std::vector<float> substitute(ncs, 0.0f);
    if (keep_range)
        for (size_t c = 0; c < ncs; ++c)
            substitute[c] = std::isfinite(found.least[c]) ? found.least[c] : 0.0f;
    OIIO::ImageBuf replaced;
    replaced.copy(in);
    parallel_rows(data, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            auto* row = static_cast<float*>(replaced.pixeladdr(data.xbegin, y, data.zbegin));
            for (size_t i = 0; i < size_t(data.width()) * ncs; ++i)
                if (!std::isfinite(row[i]))
                    row[i] = substitute[i % ncs];
        }
    });
    if (!clean(dst, replaced))
        return false;
    const OIIO::ROI out = dst.roi();
    const size_t npx    = size_t(out.npixels());
    // reached[3 c + kind]: where that kind (after the weights' signs) reaches channel c.
    std::vector<std::vector<char>> reached(3 * ncs);
    for (size_t j = 0; j < kernels.size(); ++j) {
        std::vector<std::pair<int, int>> channels;  // (channel, kind) convolved with kernel j
        for (int c = 0; c < nc; ++c)
            for (int kd = 0; kd < 3; ++kd)
                if (kernel_of[size_t(c)] == int(j) && found.held[size_t(3 * c + kd)])
                    channels.push_back({ c, kd });
        if (channels.empty())
            continue;
        const int nind = int(channels.size());
        OIIO::ImageSpec ispec(data.width(), data.height(), nind, OIIO::TypeFloat);
        ispec.x = data.xbegin;
        ispec.y = data.ybegin;
        OIIO::ImageBuf indicators(ispec, OIIO::InitializePixels::Yes);
        detail::require_pixels(indicators);
        parallel_rows(data, nthreads, [&](int y0, int y1) {
            for (int y = y0; y < y1; ++y) {
                const auto* row = static_cast<const float*>(in.pixeladdr(data.xbegin, y, data.zbegin));
                auto* ind       = static_cast<float*>(indicators.pixeladdr(data.xbegin, y));
                for (int x = 0; x < data.width(); ++x)
                    for (int i = 0; i < nind; ++i) {
                        const float v = row[size_t(x) * ncs + size_t(channels[size_t(i)].first)];
                        ind[size_t(x) * size_t(nind) + size_t(i)]
                            = !std::isfinite(v) && kind(v) == channels[size_t(i)].second ? 1.0f : 0.0f;
                    }
            }
        });
        for (const double sign : { 1.0, -1.0 }) {
            KernelWeights support = kernels[j];
            bool any              = false;
            for (double& w : support.w) {
                w   = w * sign > 0.0 ? 1.0 : 0.0;
                any = any || w > 0.0;
            }
            if (!any)
                continue;
            const std::vector<Span> spans = kernel_spans(reflected(support));
            const bool by_fft = fft_cheaper_than_spans(out.width(), out.height(), nind, support.rx, support.ry, spans);
            OIIO::ImageBuf reach;
            const bool ok = by_fft ? convolve_fft_direct(reach, indicators, out, { support },
                                                         std::vector<int>(size_t(nind), 0), border, nthreads)
                                   : convolve_spans_direct(reach, indicators, out, support.rx, support.ry, spans,
                                                           border, nthreads);
            if (!ok) {
                dst.errorfmt("blur: where the non-finite values reach: {}", reach.geterror());
                return false;
            }
            for (int i = 0; i < nind; ++i) {
                const auto [c, kd] = channels[size_t(i)];
                const int as       = sign > 0.0 || kd == 0 ? kd : 3 - kd;  // -inf through a negative weight: +inf
                std::vector<char>& r = reached[size_t(3 * c + as)];
                r.resize(npx, 0);
                parallel_rows(out, nthreads, [&](int y0, int y1) {
                    for (int y = y0; y < y1; ++y) {
                        const auto* v = static_cast<const float*>(reach.pixeladdr(out.xbegin, y));
                        char* hit     = r.data() + size_t(y - out.ybegin) * size_t(out.width());
                        for (int x = 0; x < out.width(); ++x)
                            hit[x] = char(hit[x] | (v[size_t(x) * size_t(nind) + size_t(i)] > 0.5f));
                    }
                });
            }
        }
    }
    constexpr float kInf = std::numeric_limits<float>::infinity();
    parallel_rows(out, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            auto* row = static_cast<float*>(dst.pixeladdr(out.xbegin, y));
            for (int x = 0; x < out.width(); ++x)
                for (int c = 0; c < nc; ++c) {
                    const size_t p = size_t(y - out.ybegin) * size_t(out.width()) + size_t(x);
                    auto hit       = [&](int kd) {
                        const std::vector<char>& r = reached[size_t(3 * c + kd)];
                        return !r.empty() && r[p];
                    };
                    const bool nan = hit(0), pos = hit(1), neg = hit(2);
                    float& v       = row[size_t(x) * ncs + size_t(c)];
                    if (nan || (pos && neg))
                        v = std::numeric_limits<float>::quiet_NaN();
                    else if (pos || neg)
                        v = pos ? kInf : -kInf;
                }
        }
    });
    return true;
}

}  // namespace detail

bool convolve_reference(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src,
                        const KernelWeights& weights, const BlurOptions& opts, OIIO::ROI roi,
                        int nthreads)
{
    if (!check_source(dst, src))
        return false;
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = float_source(src, holder);
    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), weights.rx, weights.ry) : in.roi();
    const Plane p = pad(in, grown(roi, weights.rx, weights.ry), opts.border, nthreads);
    return finish(dst, in, roi, convolve_brute(p, weights, nthreads), 0, 0, false, nthreads);
}

namespace {

bool is_hexagon(const Kernel& k)
{
    return k.shape == KernelShape::Polygon && k.blades == 6 && k.curvature == 0.0f && k.hole == 0.0f;
}

// The concrete method for `k`, or false + `err` when the asked one does not apply.
// Fast is the cheapest approximation measured at >= 40 dB on bokeh-bench's crop
// (docs/benchmarks.md): for a disk or polygon where the automatic reduction exceeds 1
// (37.5 px up; a polygon 45) the reduced buffer, 2-6x faster than 6 bands at the same
// accuracy (disk 63 px: 21 ms at 41.3 dB against 46 ms at 41.1; 255 px: 11 ms at 51.2
// against 66 at 48.1), below it the bands. The hexagon keeps its parallelograms
// (50-72 dB); hard-edged shapes keep the bands (the reduction was measured on anti-aliased
// ones only). In iris mode it is the exact method: exp(k x) magnifies every weight an
// approximation misplaces next to a highlight, and on the crop (range 0 .. 276) with
// |k| x range = 5 the bands measured 32-43 dB, the parallelograms 34-37, the three boxes
// 31-34 (22-30 dB at 10), against the exact iris blur.
bool resolve_method(const Kernel& k, const BlurOptions& opts, BlurMethod& m, std::string& err)
{
    const BlurMethod asked = opts.method;
    const bool gaussian = k.shape == KernelShape::Gaussian;
    const bool shape    = k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon;
    const bool filter   = k.shape == KernelShape::Filter;
    // A method asked for by name: taken where it applies to `k`, else refused with `why`.
    auto named = [&](bool applies, const char* why) {
        m = asked;
        if (!applies)
            err = why;
        return applies;
    };
    switch (asked) {
    case BlurMethod::Auto:
    case BlurMethod::Exact: m = BlurMethod::Exact; return true;
    case BlurMethod::Reference: m = asked; return true;
    case BlurMethod::Fast:
        // The hexagon too takes the reduction from 45 px: 40.9-42.2 dB from 45 to 63 px at
        // rotations 0, 30 and 7 degrees, and 41 ms at 45 px (1080p RGBA, 2 threads) against
        // the parallelograms' 36 (flat-topped), 60 (upright) and 132 (7 degrees, four
        // passes); 27 against 35 / 55 at 63 px (session 9, docs/benchmarks.md). Session 14,
        // the sheared sweep at 7 and 25 degrees, 63 px: 28 and 24 ms against the reduced
        // buffer's 19 (one run, a slow phase of the machine): still the reduction.
        // A hard-edged Gaussian is oiiotool's, cut at 2 sigma: three boxes stand for the
        // whole one.
        // OIIO's filters have no approximation here: exact.
        m = opts.iris != 0.0f || filter ? BlurMethod::Exact
            : gaussian                  ? (k.edge == KernelEdge::Hard ? BlurMethod::Exact : BlurMethod::ThreeBoxes)
            : shape && k.edge == KernelEdge::Antialiased && reduction_factor(k) > 1.0
                ? BlurMethod::Reduced
            : is_hexagon(k)           ? BlurMethod::Parallelograms  // or Exact: see blur()
            : shape && k.hole == 0.0f ? BlurMethod::Bands           // or Exact: see blur()
                                      : BlurMethod::Exact;  // box: running sums are the fast method
        return true;
    case BlurMethod::ThreeBoxes:
        return named(gaussian && k.edge == KernelEdge::Antialiased,
                     "method=boxes3 is for the anti-aliased gaussian kernel (edge=hard is oiiotool's, cut at 2 "
                     "sigma: method=exact)");
    case BlurMethod::Parallelograms:
        return named(is_hexagon(k), "method=parallelograms needs a hexagon (6 straight blades, no hole)");
    case BlurMethod::Bands:
        return named(shape && k.hole == 0.0f, "method=bands is for disk and polygon kernels without a hole");
    case BlurMethod::Reduced:
        return named(!filter, "method=reduced is not offered for OIIO's filters (no approximation of them is "
                              "measured); use an exact method");
    case BlurMethod::Spans: return named(shape, "method=spans is for disk and polygon kernels");
    case BlurMethod::Separable:
        return named(gaussian || (filter && is_separable(k)),
                     "method=separable is for the gaussian kernel and OIIO's separable filters");
    case BlurMethod::Fft:
        return named(shape || gaussian || filter, "method=fft is for disk, polygon, gaussian and OIIO's filter kernels");
    case BlurMethod::BilinearTaps:
        return named(k.shape == KernelShape::Disk && k.edge == KernelEdge::Antialiased
                         && k.width_px == k.height_px && (k.width_px == 9.0f || k.width_px == 17.0f)
                         && k.hole == 0.0f,
                     "method=taps is the seed's 9x9 or 17x17 anti-aliased disk only");
    }
    err = "unknown method";
    return false;
}

}  // namespace

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

bool blur(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Kernel& k,
          const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    std::string err;
    BlurMethod method = BlurMethod::Exact;
    if (!validate(k, err) || !resolve_method(k, opts, method, err)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    if (opts.bands < 0 || opts.bands > 64) {
        dst.errorfmt("blur: bands {} is outside 0..64 (0: the method's choice)", opts.bands);
        return false;
    }
    if (!std::isfinite(opts.iris) || std::abs(opts.iris) > 1000.0f) {
        dst.errorfmt("blur: iris {} is outside -1000..1000", opts.iris);
        return false;
    }
    if (!(opts.reduction == 0.0f || (opts.reduction >= 1.0f && opts.reduction <= 16.0f))) {
        dst.errorfmt("blur: reduction {} is outside 1..16 (0: automatic)", opts.reduction);
        return false;
    }
    if (method == BlurMethod::Reduced && opts.iris != 0.0f) {
        // Tried: the reduction and the blur on exp(k x), back by log / k before the
        // enlargement. A block's mean of exp(k x) is its brightest pixel's, so every
        // highlight grows by up to a block: 20 dB against the exact iris blur (disk 51 px,
        // iris 0.3, the lights scene at 640 x 360), too far to offer.
        dst.errorfmt("blur: method=reduced does not take iris (a block's mean of exp(k x) "
                     "widens every highlight by up to a block); use an exact method");
        return false;
    }
    if (k.shape == KernelShape::Filter && opts.iris != 0.0f) {
        // As for image kernels: a weighted mean of exp(k x) with negative weights can fall
        // to 0 or below, whose log is NaN.
        const KernelWeights w = kernel_weights(k, nthreads);
        if (std::any_of(w.w.begin(), w.w.end(), [](double v) { return v < 0.0; })) {
            dst.errorfmt("blur: iris mode needs a kernel without negative weights ({} has some)", k.filter);
            return false;
        }
    }
    if (!check_source(dst, src))
        return false;
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = float_source(src, holder);
    if (any_nonfinite(in, nthreads))
        return blur_nonfinite(dst, in, { kernel_weights(k, nthreads) }, std::vector<int>(size_t(in.nchannels()), 0),
                              opts.border, opts.iris != 0.0f,
                              [&](OIIO::ImageBuf& out, const OIIO::ImageBuf& replaced) {
                                  return blur(out, replaced, k, opts, roi, nthreads);
                              }, nthreads);
    // Before the exact weights, which it does not need at full size.
    if (method == BlurMethod::Reduced)
        return blur_reduced(dst, in, k, opts, roi, nthreads);

    // method=fast below the reduction weighs its approximation (the parallelograms for a
    // hexagon, the bands for other shapes) against the exact row spans by the cost models,
    // and takes the exact blur where it costs less: small kernels (15 px: a disk's spans
    // 27 ms against 8 bands' 41, a hexagon's 26-29 against the parallelograms' 33
    // flat-topped and 54 upright; sessions 9, 10). With the spans model and the band counts
    // of session 10 the crossings fall at ~21 px for a disk (4 bands), ~31 for a pentagon,
    // ~23 for an octagon, and (session 13, parallelograms_cost_ns refitted on this
    // machine) ~9 px for the flat-topped hexagon and ~10 for the upright one, ~7 for the
    // sheared sweep (session 14). The parallelograms are taken only from the size where
    // they keep to the 40 dB budget (parallelograms_budget_px, on the narrow side: 15 px,
    // stretched 21, sheared 27; before session 14 the cost alone decided, and the sweep ran
    // from 9 px at 36.5 dB; before session 15 the wide side, and a 27 x 9 hexagon took the
    // sweep at 36.9 dB).
    // (Only up to 64 px across: the spans' cost grows with the size and is past every
    // approximation's by then, and a large polygon's exact weights cost tens of ms.)
    // Its bands, unless the user named a count: the fewest within its accuracy bound
    // (fast_band_count; 8 bands measured 41-48 ms at 15-37 px, 4 bands 33-35, session 9).
    // The budget holds at every size: a stretched hexagon past 64 px (81 x 15) too.
    if (opts.method == BlurMethod::Fast && method == BlurMethod::Parallelograms
        && std::min(k.width_px, k.height_px) < parallelograms_budget_px(k))
        method = BlurMethod::Exact;
    std::optional<KernelWeights> exact_weights;
    int bands = opts.bands > 0 ? opts.bands : 8;
    if (opts.method == BlurMethod::Fast && std::max(k.width_px, k.height_px) <= 64.0f
        && (method == BlurMethod::Parallelograms || method == BlurMethod::Bands)) {
        exact_weights = kernel_weights(k, nthreads);
        if (method == BlurMethod::Bands && opts.bands == 0)
            bands = fast_band_count(*exact_weights, std::max(k.width_px, k.height_px));
        const std::vector<Span> s = kernel_spans(reflected(*exact_weights));
        const int w = in.roi().width(), h = in.roi().height();
        const bool mirrored    = spans_mirror_in_y(s);
        const double approx_ns = method == BlurMethod::Parallelograms
                                     ? parallelograms_cost_ns(k, w, h)
                                     : bands_cost_ns(w, h, bands, mirrored);
        if (spans_cost_ns(w, h, s) < approx_ns)
            method = BlurMethod::Exact;
    }
    // The weights the method computes with (the effective ones for the approximations
    // that have them) and how far the method reads around an output pixel.
    // The parallelograms read no weights, only whether the kernel is a point (the
    // identity); the exact weights of a large polygon (supersampled) cost tens of ms.
    const bool no_weights = method == BlurMethod::Parallelograms && !exact_weights
                            && std::min(k.width_px, k.height_px) >= 2.0f;
    // Separable kernels (box, Gaussian, OIIO's separable filters) run from their 1-D
    // factors, made once here, on every path but the brute force and the FFT, so their N^2
    // weights are made only for those (below, once the FFT is chosen): a Gaussian of sigma
    // 1024 made 8193^2 doubles, 1.2 GB, to read its reach.
    const auto factors = is_separable(k) && method != BlurMethod::Reference && method != BlurMethod::Fft
                             ? std::optional{ separable_weights(k) }
                             : std::nullopt;
    KernelWeights weights = no_weights ? KernelWeights{ 1, 1, {} }
                            : factors  ? KernelWeights{ int(factors->first.size() / 2), int(factors->second.size() / 2), {} }
                                  : method == BlurMethod::Bands && exact_weights
                                      ? banded_from(*exact_weights, bands)
                                  : method == BlurMethod::Bands        ? banded_weights(k, bands, nthreads)
                                  : method == BlurMethod::BilinearTaps ? bilinear_tap_weights(k)
                                  : exact_weights                      ? *exact_weights
                                                                       : kernel_weights(k, nthreads);
    int rx = weights.rx, ry = weights.ry;
    std::vector<double> box3x, box3y;
    if (method == BlurMethod::ThreeBoxes) {
        std::tie(box3x, box3y) = gaussian_boxes(k);
        rx    = 3 * int(box3x.size() / 2);
        ry    = 3 * int(box3y.size() / 2);
    } else if (method == BlurMethod::Parallelograms && !weights.is_identity()) {
        rx = hexagon_reach(k, true);
        ry = hexagon_reach(k, false);
    }
    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), rx, ry) : in.roi();
    // A disk or polygon, exactly: row spans or FFT tiles, whichever the cost models say is
    // cheaper. In iris mode too: against the brute force (disk 19 px, 0.003 .. 500, k x
    // range = 29.9) both err by 2.2e-4 at most, the transform spreading its brightest
    // exp(k x)'s rounding over its tile as the spans do along their rows. The FFT is taken
    // when its model is under 1.2 times the spans': at 95-191 px its wall time measured
    // 0.69-0.85 of its model, at 15-63 px 0.85-1.0, against the spans model's 0.84-1.21
    // (session 10, 44 timings, two threads); of the factors 0.85-1.25 tried, 1.2 lost the
    // least time by its wrong picks over those timings (33 ms in all: a 63 px pentagon
    // by FFT at 1.11-1.17x the spans' time; 0.85, the margin before, lost 876 ms, 1.0
    // lost 427). A disk crosses at ~99 px (measured FFT / spans: 1.05 at 95 px, 0.77 at 127).
    // A Gaussian: the separable convolution or FFT tiles when the FFT's model promises
    // to be 15 % cheaper (at 1080p the FFT from sigma ~7: 0.72x the separable's time at
    // sigma 7.75, 0.47x at 15.75, 0.25x at 63.75, A/B).
    const int nc = in.nchannels();
    auto fft_ns      = [&] { return fft_convolve_cost_ns(roi.width(), roi.height(), nc, rx, ry); };
    const bool shape = k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon;
    const bool by_spans = method == BlurMethod::Spans || method == BlurMethod::BilinearTaps
                          || (shape && method == BlurMethod::Exact);
    const std::vector<Span> spans = by_spans && !weights.is_identity()
                                        ? kernel_spans(reflected(weights))
                                        : std::vector<Span>{};
    if (shape && method == BlurMethod::Exact && !weights.is_identity())
        method = fft_cheaper_than_spans(roi.width(), roi.height(), nc, rx, ry, spans) ? BlurMethod::Fft
                                                                                       : BlurMethod::Spans;
    // OIIO's separable filters likewise (rows and columns, any signs); the others by FFT.
    const bool separable = k.shape == KernelShape::Gaussian || (k.shape == KernelShape::Filter && is_separable(k));
    if (separable && method == BlurMethod::Exact && !weights.is_identity())
        method = fft_ns() < 0.85 * nc * separable_cost_ns(roi.width(), roi.height(), 2 * rx + 1, 2 * ry + 1)
                     ? BlurMethod::Fft
                     : BlurMethod::Separable;
    if (k.shape == KernelShape::Filter && method == BlurMethod::Exact && !weights.is_identity())
        method = BlurMethod::Fft;
    if (method == BlurMethod::Fft && weights.w.empty() && !weights.is_identity())
        weights = kernel_weights(k, nthreads);
    if (opts.method == BlurMethod::Fft && !std::isfinite(fft_ns())) {  // chosen, it is finite
        dst.errorfmt("blur: method=fft takes kernels under 8192 px across; this one reaches {}x{}",
                     2 * rx + 1, 2 * ry + 1);
        return false;
    }
    const std::vector<int> one_kernel(size_t(nc), 0);
    // The exact box and shapes go straight from the source to `dst` (no padded plane);
    // iris mode transforms a padded plane, so it keeps the plane path.
    if (method == BlurMethod::Exact && opts.iris == 0.0f && !weights.is_identity()) {
        if (k.shape == KernelShape::Box)
            return box_direct(dst, in, roi, BoxPass(factors->first), BoxPass(factors->second), opts.border,
                              nthreads);
    }
    if ((method == BlurMethod::Spans || method == BlurMethod::BilinearTaps) && opts.iris == 0.0f
        && !weights.is_identity())
        return convolve_spans_direct(dst, in, roi, weights.rx, weights.ry, spans, opts.border, nthreads);
    if (method == BlurMethod::Separable && opts.iris == 0.0f && !weights.is_identity())
        return separable_direct(dst, in, roi, factors->first, factors->second, opts.border, nthreads);
    if (method == BlurMethod::Fft && opts.iris == 0.0f && !weights.is_identity())
        return convolve_fft_direct(dst, in, roi, { weights }, one_kernel, opts.border, nthreads);
    if (method == BlurMethod::ThreeBoxes && opts.iris == 0.0f && !weights.is_identity()) {
        return three_boxes_direct(dst, in, roi, BoxPass(box3x), BoxPass(box3y), opts.border, nthreads);
    }
    if (method == BlurMethod::Bands && opts.iris == 0.0f && !weights.is_identity())
        return convolve_bands_direct(dst, in, roi, weights, opts.border, nthreads);
    if (method == BlurMethod::Parallelograms && opts.iris == 0.0f && !weights.is_identity()
        && hexagon_sweeps(k))
        return hexagon_direct(dst, in, roi, k, rx, ry, opts.border, nthreads);
    // The parallelograms of an upright hexagon run on the transposed plane (blur_approx.cpp);
    // it is padded and finished transposed rather than transposed twice more.
    const bool transpose = method == BlurMethod::Parallelograms && !weights.is_identity()
                           && hexagon_transposed(k);
    const int extra = method == BlurMethod::Parallelograms && !weights.is_identity() ? hexagon_plane_extra(k) : 0;
    Plane p = pad(in, grown(roi, rx + extra, ry + extra), opts.border, nthreads, transpose);
    if (weights.is_identity())
        return finish(dst, in, roi, p, 0, 0, false, nthreads);  // bit-exact copy

    Iris iris;
    if (opts.iris != 0.0f) {
        iris.k     = opts.iris;
        iris.alpha = in.spec().alpha_channel;
        iris.z     = in.spec().z_channel;
        if (!iris.forward(p, err, nthreads)) {
            dst.errorfmt("blur: {}", err);
            return false;
        }
    }
    Plane out;
    int ox = 0, oy = 0;  // where the output starts in `out` (planes the size of p)
    switch (method) {
    case BlurMethod::Reference: out = convolve_brute(p, weights, nthreads); break;
    case BlurMethod::ThreeBoxes:
        out = std::move(p);
        for (int pass = 0; pass < 3; ++pass)
            out = box_blur(out, box3x, box3y, nthreads);
        break;
    case BlurMethod::Parallelograms:
        out = hexagon_parallelograms(std::move(p), k, (transpose ? ry : rx) + extra, (transpose ? rx : ry) + extra,
                                     nthreads);
        ox  = rx + extra;
        oy  = ry + extra;
        break;
    case BlurMethod::Bands: out = convolve_banded(p, weights, nthreads); break;
    case BlurMethod::BilinearTaps:
    case BlurMethod::Spans: out = convolve_spans(p, weights, nthreads); break;
    case BlurMethod::Fft: out = convolve_fft(p, { weights }, one_kernel, nthreads); break;
    case BlurMethod::Separable: out = convolve_separable(p, factors->first, factors->second, nthreads); break;
    default:  // Exact: the box (the shapes and the Gaussian took their methods above)
        out = box_blur(p, factors->first, factors->second, nthreads);
    }
    if (opts.iris != 0.0f)
        iris.inverse(out, nthreads);
    return finish(dst, in, roi, out, ox, oy, transpose, nthreads);
}

OIIO::ImageBuf blur(const OIIO::ImageBuf& src, const Kernel& k, const BlurOptions& opts,
                    OIIO::ROI roi, int nthreads)
{
    OIIO::ImageBuf dst;
    blur(dst, src, k, opts, roi, nthreads);
    return dst;
}

}  // namespace bokeh
