// plane.h — internal to the library, its base layer: the contiguous float planes every
// method works on, and the steps around them (border fill, row views, output into an
// ImageBuf, source checks, row sums); the convolutions over them are blur's
// (core/blur/convolve.h).
//
// Every method is a "valid" convolution of a padded plane: the source region the output
// needs, grown by the kernel's reach and filled past the data window by the border rule,
// is copied once into a contiguous interleaved float plane; the methods read only inside
// it, and finish() copies the wanted region into the destination. The direct paths (box,
// spans, bands and more; blur.cpp lists them) skip both copies: they read rows through
// source_row() per tile and write into a destination set up by prepare_destination(), so
// no whole-frame plane is made (the copies cost ~14 ms per call at 1080p on the project's
// machine).
#pragma once

#include <bokeh/base.h>
#include <bokeh/parallel.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

// The innermost loops are compiled for AVX-512, AVX2 and baseline x86-64 and chosen at load
// time (GCC function multiversioning), so one portable binary runs at the machine's width.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#    define BOKEH_HOT __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#    define BOKEH_HOT
#endif

namespace bokeh::detail {

/// Asks the kernel to back the whole 2 MB pages inside [p, p + bytes) with huge pages
/// (Linux transparent huge pages, "madvise" mode); call it before the memory is first
/// touched. A fresh 36 MB block then costs ~8 ms of page faults on first touch instead
/// of ~20 ms (measured on the project's machine; rewriting touched memory: ~4 ms), and
/// every blur allocates a few. Elsewhere, or when refused, nothing changes. Known limit:
/// with the kernel's THP defrag at "madvise" (Debian's default) a fault in such a region
/// may first compact memory, a stall on a fragmented machine that no run here showed.
void prefer_huge_pages(void* p, size_t bytes);

/// dst.reset(spec) with its pixels uninitialised and on huge pages (prefer_huge_pages).
/// Throws std::bad_alloc when the pixels cannot be allocated (require_pixels).
void reset_uninitialised(OIIO::ImageBuf& dst, const OIIO::ImageSpec& spec);

/// Throw std::bad_alloc when `buf` has a size but no pixels: OIIO's ImageBuf catches a
/// failed allocation itself (it prints "ImageBuf unable to allocate N bytes" and keeps
/// no pixels), and code writing the pixels would then write through a null pointer.
void require_pixels(const OIIO::ImageBuf& buf);

/// One RGBA pixel as a vector (GCC vector extensions), for loops over four channels that
/// the compiler's per-channel (SLP) vectorisation left scalar in every clone (generic
/// tuning, GCC 12; row_prefix, the box's running row): a pixel in memory (any float
/// alignment), its sums in double, and those in memory. Conversions between them are
/// written out with __builtin_convertvector where used: a helper taking or returning
/// these vectors would have another ABI in the baseline clone (GCC warns of it).
using PixelRgba    = float __attribute__((vector_size(16), aligned(4), may_alias));
using SumRgba      = double __attribute__((vector_size(32)));
using SumRgbaInMem = double __attribute__((vector_size(32), aligned(8), may_alias));

/// A contiguous interleaved float image. Its pixels start uninitialised: every method
/// writes each output value, and pad() writes the black ones itself.
struct Plane {
    int w = 0, h = 0, nc = 0;
    std::unique_ptr<float[]> px;
    Plane() = default;
    Plane(int w_, int h_, int nc_)
        : w(w_), h(h_), nc(nc_), px(new float[size_t(w_) * size_t(h_) * size_t(nc_)])
    {
        prefer_huge_pages(px.get(), size() * sizeof(float));
    }
    size_t stride() const { return size_t(w) * size_t(nc); }
    size_t size() const { return stride() * size_t(h); }
    float* row(int y) { return px.get() + size_t(y) * stride(); }
    const float* row(int y) const { return px.get() + size_t(y) * stride(); }
};

/// Index of coordinate i in [begin, end) under the border rule; kOutside = black.
constexpr int kOutside = std::numeric_limits<int>::min();
int border_index(int i, int begin, int end, Border b);

/// The source over `region`, border-filled (`transpose`: its transpose, pixel (x, y) at
/// row x, column y). `src` is float with local pixels.
Plane pad(const OIIO::ImageBuf& src, const OIIO::ROI& region, Border border, int nthreads,
          bool transpose = false);

/// Source row `sy` (inside the data window) over columns [x0, x1), filled past the data
/// window by the border rule, into out[0 .. (x1 - x0) nc). What pad() does per row; the
/// fused methods call it per tile so no padded copy of the whole frame is made.
void source_row(const OIIO::ImageBuf& src, int sy, int x0, int x1, Border border, float* out);

/// Source columns sx .. sx + n - 1 (inside the data window) over rows [y0, y1), filled
/// past the data window by the border rule, column i into out[i][0 .. (y1 - y0) nc):
/// columns of the transpose. A row's n pixels are read at once (a column alone re-reads
/// each cache line for each of its pixels).
void source_columns(const OIIO::ImageBuf& src, int sx, int n, int y0, int y1, Border border,
                    float* const* out);

/// How many column chunks a sweep down the rows (the box, the hexagon) cuts a frame `w`
/// wide into: about 960 columns each, an even count, fixed by the width (never by the
/// thread count, so the float rounding is too). Each chunk reads and computes its
/// kernel's reach again on both sides, which wide chunks make a small share. Measured
/// (bokeh-ab, 1080p RGBA, two threads): the box in two strips of 960 against 256
/// columns (512 from 96 px) 0.73-0.82x at 15-255 px, though a 255 px box's ring (3.9 MiB)
/// is then far out of this machine's 1 MiB L2, three strips of 640 the slowest; the
/// hexagon sweep in two chunks against four 0.90-0.96x at 15-95 px, and at 255 px on one
/// thread four, eight and sixteen took 1.2x, 1.4x and 2.5x the time of two.
inline int column_chunks(int w) { return 2 * std::max(1, (w + 960) / 1920); }

/// fn(xs, xe) for each non-empty strip [xs, xe) of the column_chunks(w) that cut [0, w),
/// the strips in parallel (the direct paths' sweeps down the rows).
template<class Fn> void for_each_column_strip(int w, int nthreads, Fn&& fn)
{
    const int nstrips = column_chunks(w);
    const int strip   = (w + nstrips - 1) / nstrips;
    parallel_for_chunks(0, nstrips, 1, nthreads, [&](int64_t s, int64_t) {
        const int xs = int(s) * strip, xe = std::min(w, xs + strip);
        if (xe > xs)
            fn(xs, xe);
    });
}

/// Columns a transposing reader or writer takes at once (source_columns): 16 RGBA float
/// pixels are four 64-byte cache lines. The upright hexagon's sweep at 63 px, 1080p
/// RGBA, interleaved in one process (bokeh-ab): 63 ms one at a time, 52 by 4, 48 by 8,
/// 45.5 by 16, 47 by 32.
constexpr int kColumnBatch = 16;
/// How many rows ahead a transposing reader or writer asks for its next batch's cache
/// lines (__builtin_prefetch): its rows are a frame's pitch apart, a new page each, where
/// the hardware's stream prefetch does not follow. Upright hexagon, 1080p RGBA, A/B
/// (bokeh-ab): 0.94-0.99x with the reads' prefetch, 0.93-0.95x more with the writes'
/// (8, 16 and 32 rows ahead measured alike).
constexpr int kPrefetchRows = 8;

/// __builtin_prefetch of the `bytes` from p, a cache line at a time (`write`: for writing).
inline void prefetch_lines(const void* p, size_t bytes, bool write = false)
{
    const char* c = static_cast<const char*>(p);
    for (size_t b = 0; b < bytes; b += 64)
        write ? __builtin_prefetch(c + b, 1) : __builtin_prefetch(c + b, 0);
}

/// dst[i] = src[i], i < n, written past the caches (non-temporal stores) where dst is
/// 16-byte aligned: a frame's output is not read again by the writer, so a plain store's
/// read for ownership is wasted memory traffic. Call stream_fence() before another thread
/// reads dst.
void stream_floats(float* dst, const float* src, size_t n);
void stream_fence();

/// Source row `sy` over columns [x0, x1): read in place where they lie inside the data
/// window, else filled into `buf` by source_row().
const float* source_row_view(const OIIO::ImageBuf& src, int sy, int x0, int x1, Border border,
                             float* buf);

/// Padded source row `y` (any row: the border rule picks the source row) over columns
/// [x0, x1), as source_row_view(); nullptr where the row is black (Border::Black).
const float* bordered_row_view(const OIIO::ImageBuf& src, int y, int x0, int x1, Border border,
                               float* buf);

/// A padded row over [x0, x1) whose pixels [lo, hi) are at p (p[0] is pixel x0 + lo) and
/// the rest black; p is null when the whole row is black.
struct RowSpan {
    const float* p = nullptr;
    int lo = 0, hi = 0;
};

/// Pixel i of the span's row (i in [lo, hi)), or `zero` (a run of black pixels) outside.
inline const float* span_pixel(const RowSpan& row, int i, size_t ncs, const float* zero)
{
    return row.p && i >= row.lo && i < row.hi ? row.p + size_t(i - row.lo) * ncs : zero;
}

/// Calls f(x0, x1) for the stretches of outputs [0, n) over which each of the readers,
/// reader k reading pixel x + offset[k] of the span's row for output x, stays wholly
/// inside the span or wholly outside it (at most 2 nreaders + 1 stretches; one when the
/// span covers every read). A row clipped by the frame is then read in place, its black
/// pixels from a zero run (span_pixel), with no padded copy.
template<int MaxReaders, class F>
inline __attribute__((always_inline)) void for_span_stretches(const RowSpan& row,
                                                              const int* offset, int nreaders,
                                                              int n, F&& f)
{
    const int lo = row.p ? row.lo : 0, hi = row.p ? row.hi : 0;
    int cut[2 * MaxReaders + 2], ncut = 0;
    cut[ncut++] = 0;
    cut[ncut++] = n;
    for (int k = 0; k < nreaders; ++k) {
        cut[ncut++] = std::clamp(lo - offset[k], 0, n);
        cut[ncut++] = std::clamp(hi - offset[k], 0, n);
    }
    std::sort(cut, cut + ncut);
    for (int j = 0; j + 1 < ncut; ++j)
        if (cut[j + 1] > cut[j])
            f(cut[j], cut[j + 1]);
}

/// Padded source row `y` over [x0, x1) as bordered_row_view(), but under Border::Black
/// never copied: the black pixels are left out of the span ([lo, hi)), so a reader that
/// takes them as zero reads the source in place. Other borders fill `buf` (lo = 0,
/// hi = x1 - x0) where the row reaches past the data window.
RowSpan bordered_row_span(const OIIO::ImageBuf& src, int y, int x0, int x1, Border border,
                          float* buf);

/// `dst` reset to float pixels (uninitialised) over `roi`, with `src`'s metadata.
void prepare_destination(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ROI& roi);

/// `dst` = plane `p` from (ox, oy) on, placed at `roi` (its size), with `src`'s metadata;
/// `transposed`: p holds the transpose (as pad(..., true) makes it).
bool finish(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ROI& roi, const Plane& p,
            int ox = 0, int oy = 0, bool transposed = false, int nthreads = 0);

/// Copies `count` pixels of `nc` channels from a run with `src_step` floats between pixels
/// to one with `dst_step` (the transposing copies; one vector move per pixel for 1, 3 and 4
/// channels).
void copy_pixels(float* dst, size_t dst_step, const float* src, size_t src_step, int count, int nc);

/// a / s rounded down (s > 0): the reduced pixel holding full-resolution coordinate a.
inline int floor_div(int a, int s) { return a >= 0 ? a / s : -((-a + s - 1) / s); }
/// a / s rounded up (s > 0).
inline int ceil_div(int a, int s) { return -floor_div(-a, s); }

/// `r` grown by rx, ry pixels on each side.
OIIO::ROI grown(OIIO::ROI r, int rx, int ry);

/// A float, local copy of `src` when it is not already one.
const OIIO::ImageBuf& float_source(const OIIO::ImageBuf& src, OIIO::ImageBuf& holder);

/// False + an error on `dst` when `src` cannot be blurred (empty, deep, volume).
bool check_source(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const char* what = "blur");

/// acc[i] += w * (hi[i] - lo[i]): one span of prefix sums.
void add_span(double* acc, const double* hi, const double* lo, double w, size_t n);
/// acc[i] += sum over s < count of w[s] * (hi[s][i] - lo[s][i]): several spans at once.
void add_spans(double* acc, const double* const* hi, const double* const* lo, const double* w,
               size_t count, size_t n);
/// a[i] += v[i] and, unless b is null, b[i] += v[i], where v[i] = sum over s < count of
/// w[s] * (hi[s][i] - lo[s][i]): spans shared by two output rows.
void add_spans_pair(double* a, double* b, const double* const* hi, const double* const* lo,
                    const double* w, size_t count, size_t n);
/// With v[i] = sum over s < count of w[s] * (hi[s][i] - lo[s][i]): fresh[i] = v[i] (a row's
/// first spans) unless fresh is null, and out[i] = float(last[i] + v[i]) (a row's last
/// spans, stored as its result) unless last is null; `last` is left undefined.
void start_and_finish_rows(double* fresh, double* last, float* out, const double* const* hi,
                           const double* const* lo, const double* w, size_t count, size_t n);
/// acc[i] += w * src[i].
void add_scaled(double* acc, const float* src, double w, size_t n);
/// out[i] = float(acc[i]).
void to_float(float* out, const double* acc, size_t n);
/// out[i] = float(sum_j w[j] * src[j][i]) for i < n, each in double with its taps in order
/// j, 16 values at a time held in registers over every tap.
void weighted_sum(float* out, const float* const* src, const double* w, size_t taps, size_t n);

/// p[(x + 1) nc + c] = sum of v[0 .. x] in channel c, p[c] = 0, for x < npx.
void row_prefix(double* p, const float* v, size_t npx, int nc);

/// Row prefix sums in double: prefix[y][(x + 1) nc + c] = sum of in[y][0..x] in channel c,
/// and prefix[y][c] = 0; rows of (in.w + 1) * nc values (blur_spans.cpp).
void row_prefix_sums(const Plane& in, double* prefix, int nthreads);

/// For every output row y, in tiles of 256-pixel column strips x 16 rows run in parallel
/// (each task owns its outputs; the input rows a tile reads stay in L2): `fn(y, i0, acc)`
/// adds into `acc` (zeroed; the values of out.row(y) from float index i0 on, in double),
/// which is then stored as float.
template<class RowFn> void accumulate_in_strips(Plane& out, int nthreads, RowFn fn)
{
    constexpr int kStrip = 256, kRows = 16;
    const int nstrips = (out.w + kStrip - 1) / kStrip;
    const int nrows   = (out.h + kRows - 1) / kRows;
    parallel_for_chunks(0, int64_t(nstrips) * nrows, 1, nthreads, [&](int64_t t, int64_t) {
        const int xs = int(t % nstrips) * kStrip, xe = std::min(out.w, xs + kStrip);
        const int ys = int(t / nstrips) * kRows, ye = std::min(out.h, ys + kRows);
        const size_t i0 = size_t(xs) * size_t(out.nc), n = size_t(xe - xs) * size_t(out.nc);
        std::vector<double> acc(n);
        for (int y = ys; y < ye; ++y) {
            std::fill(acc.begin(), acc.end(), 0.0);
            fn(y, i0, acc);
            to_float(out.row(y) + i0, acc.data(), n);
        }
    });
}

}  // namespace bokeh::detail
