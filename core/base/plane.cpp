// plane.cpp — padded float planes for the methods (see plane.h), the border rule
// per source row (source_row: shared by pad() and the direct paths of blur.cpp), and the
// vectorised inner loops of the prefix-sum methods (add_span, add_spans: up to eight spans
// per pass over the accumulator, so it is loaded and stored once per eight spans).

#include "base/plane.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <new>
#include <type_traits>

#if defined(__SSE2__)
#    include <immintrin.h>
#endif

#if defined(__linux__)
#    include <sys/mman.h>
#endif

#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

int border_index(int i, int begin, int end, Border b)
{
    if (i >= begin && i < end)
        return i;
    const int n = end - begin;
    switch (b) {
    case Border::Black: return kOutside;
    case Border::Clamp: return std::clamp(i, begin, end - 1);
    case Border::Mirror: {
        // ... 2 1 0 | 0 1 2 ... : period 2n with the edge pixel repeated.
        int t = (i - begin) % (2 * n);
        if (t < 0)
            t += 2 * n;
        return begin + (t < n ? t : 2 * n - 1 - t);
    }
    }
    return kOutside;
}

namespace {

// Pixels [a0, a1) of source row `fixed` (along x) or column `fixed` (along y), which lies
// inside the data window: the part inside in one copy, the rest by the border rule.
void source_line(const OIIO::ImageBuf& src, bool along_x, int fixed, int a0, int a1, Border border,
                 float* out)
{
    const int nc         = src.nchannels();
    const size_t ncs     = size_t(nc);
    const OIIO::ROI data = src.roi();
    const int begin = along_x ? data.xbegin : data.ybegin, end = along_x ? data.xend : data.yend;
    auto at = [&](int a) {
        return static_cast<const float*>(along_x ? src.pixeladdr(a, fixed, data.zbegin)
                                                 : src.pixeladdr(fixed, a, data.zbegin));
    };
    const int in0 = std::max(a0, begin), in1 = std::min(a1, end);
    if (in1 > in0 && along_x)
        std::copy_n(at(in0), size_t(in1 - in0) * ncs, out + size_t(in0 - a0) * ncs);
    else if (in1 > in0)
        copy_pixels(out + size_t(in0 - a0) * ncs, ncs, at(in0),
                    size_t(src.scanline_stride()) / sizeof(float), in1 - in0, nc);
    auto outside = [&](int lo, int hi) {
        for (int a = lo; a < hi; ++a) {
            const int s = border_index(a, begin, end, border);
            float* o    = out + size_t(a - a0) * ncs;
            if (s != kOutside)
                std::copy_n(at(s), nc, o);
            else
                std::fill_n(o, nc, 0.0f);
        }
    };
    if (in1 > in0) {
        outside(a0, in0);
        outside(in1, a1);
    } else {
        outside(a0, a1);  // the whole line lies outside the data window
    }
}

}  // namespace

void source_row(const OIIO::ImageBuf& src, int sy, int x0, int x1, Border border, float* out)
{
    source_line(src, true, sy, x0, x1, border, out);
}

namespace {

// f(std::integral_constant<size_t, N>) with N = nc for the common pixel sizes (1, 3, 4
// floats), so a pixel moves as one fixed-size copy, not a call; N = 0 for the others.
template<class F>
void by_pixel_size(int nc, F&& f)
{
    switch (nc) {
    case 1: f(std::integral_constant<size_t, 1>()); break;
    case 3: f(std::integral_constant<size_t, 3>()); break;
    case 4: f(std::integral_constant<size_t, 4>()); break;
    default: f(std::integral_constant<size_t, 0>());
    }
}

}  // namespace

void source_columns(const OIIO::ImageBuf& src, int sx, int n, int y0, int y1, Border border,
                    float* const* out)
{
    const OIIO::ROI data = src.roi();
    const int nc         = src.nchannels();
    const size_t ncs     = size_t(nc);
    const int in0 = std::clamp(data.ybegin, y0, y1), in1 = std::clamp(data.yend, in0, y1);
    if (in1 > in0)  // the rows inside the data window: a row's n pixels at once
        by_pixel_size(nc, [&](auto pixel_floats) {
            constexpr size_t kNc = decltype(pixel_floats)::value;
            const size_t step    = kNc ? kNc : ncs;
            const size_t pitch   = size_t(src.scanline_stride()) / sizeof(float);
            const float* p       = static_cast<const float*>(src.pixeladdr(sx, in0, data.zbegin));
            const size_t bytes = size_t(n) * step * sizeof(float);
            for (int y = in0; y < in1; ++y, p += pitch) {
                if (y + kPrefetchRows < in1)
                    prefetch_lines(p + kPrefetchRows * pitch, bytes);
                const size_t at = size_t(y - y0) * step;
                for (int i = 0; i < n; ++i)
                    std::memcpy(out[i] + at, p + size_t(i) * step, step * sizeof(float));
            }
        });
    // The rows past the data window, by the border rule.
    for (int i = 0; i < n; ++i) {
        source_line(src, false, sx + i, y0, in0, border, out[i]);
        source_line(src, false, sx + i, in1, y1, border, out[i] + size_t(in1 - y0) * ncs);
    }
}

void stream_floats(float* dst, const float* src, size_t n)
{
#if defined(__SSE2__)
    size_t i = 0;
    for (; i < n && (reinterpret_cast<uintptr_t>(dst + i) & 15u); ++i)
        dst[i] = src[i];
    for (; i + 4 <= n; i += 4)
        _mm_stream_ps(dst + i, _mm_loadu_ps(src + i));
    for (; i < n; ++i)
        dst[i] = src[i];
#else
    std::copy_n(src, n, dst);
#endif
}

void stream_fence()
{
#if defined(__SSE2__)
    _mm_sfence();
#endif
}

void copy_pixels(float* dst, size_t dst_step, const float* src, size_t src_step, int count, int nc)
{
    by_pixel_size(nc, [&](auto pixel_floats) {
        constexpr size_t kNc = decltype(pixel_floats)::value;
        const size_t step    = kNc ? kNc : size_t(nc);
        for (int i = 0; i < count; ++i)
            std::memcpy(dst + size_t(i) * dst_step, src + size_t(i) * src_step, step * sizeof(float));
    });
}

Plane pad(const OIIO::ImageBuf& src, const OIIO::ROI& region, Border border, int nthreads,
          bool transpose)
{
    const int w = region.width(), h = region.height(), nc = src.nchannels();
    const size_t ncs = size_t(nc);
    Plane p = transpose ? Plane(h, w, nc) : Plane(w, h, nc);
    const OIIO::ROI data = src.roi();
    auto fill_row = [&](int j, float* out) {
        const int sy = border_index(region.ybegin + j, data.ybegin, data.yend, border);
        if (sy == kOutside)
            std::fill_n(out, size_t(w) * ncs, 0.0f);
        else
            source_row(src, sy, region.xbegin, region.xend, border, out);
    };
    if (!transpose) {
        parallel_for_chunks(0, h, 8, nthreads, [&](int64_t j0, int64_t j1) {
            for (int j = int(j0); j < int(j1); ++j)
                fill_row(j, p.row(j));
        });
        return p;
    }
    // Transposed: a block of source rows at a time, each column of it written as one
    // contiguous run of the plane's row.
    constexpr int kBlock = 32;
    parallel_for_chunks(0, (h + kBlock - 1) / kBlock, 1, nthreads, [&](int64_t b0, int64_t b1) {
        std::vector<float> rows(size_t(kBlock) * size_t(w) * ncs);
        for (int64_t b = b0; b < b1; ++b) {
            const int j0 = int(b) * kBlock, j1 = std::min(h, j0 + kBlock);
            for (int j = j0; j < j1; ++j)
                fill_row(j, rows.data() + size_t(j - j0) * size_t(w) * ncs);
            for (int i = 0; i < w; ++i)
                copy_pixels(p.row(i) + size_t(j0) * ncs, ncs, rows.data() + size_t(i) * ncs,
                            size_t(w) * ncs, j1 - j0, nc);
        }
    });
    return p;
}

const float* source_row_view(const OIIO::ImageBuf& src, int sy, int x0, int x1, Border border,
                             float* buf)
{
    const OIIO::ROI data = src.roi();
    if (x0 >= data.xbegin && x1 <= data.xend)
        return static_cast<const float*>(src.pixeladdr(x0, sy, data.zbegin));
    source_row(src, sy, x0, x1, border, buf);
    return buf;
}

const float* bordered_row_view(const OIIO::ImageBuf& src, int y, int x0, int x1, Border border,
                               float* buf)
{
    const OIIO::ROI data = src.roi();
    const int sy         = border_index(y, data.ybegin, data.yend, border);
    return sy == kOutside ? nullptr : source_row_view(src, sy, x0, x1, border, buf);
}

RowSpan bordered_row_span(const OIIO::ImageBuf& src, int y, int x0, int x1, Border border,
                          float* buf)
{
    const OIIO::ROI data = src.roi();
    const int sy         = border_index(y, data.ybegin, data.yend, border);
    if (sy == kOutside)
        return {};
    if (border != Border::Black)
        return { source_row_view(src, sy, x0, x1, border, buf), 0, x1 - x0 };
    const int c0 = std::max(x0, data.xbegin), c1 = std::min(x1, data.xend);
    if (c1 <= c0)
        return {};
    return { static_cast<const float*>(src.pixeladdr(c0, sy, data.zbegin)), c0 - x0, c1 - x0 };
}

void prefer_huge_pages(void* p, size_t bytes)
{
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    constexpr uintptr_t kHuge = uintptr_t(2) << 20;
    const uintptr_t b = (reinterpret_cast<uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
    const uintptr_t e = (reinterpret_cast<uintptr_t>(p) + bytes) & ~(kHuge - 1);
    if (e > b)
        madvise(reinterpret_cast<void*>(b), e - b, MADV_HUGEPAGE);  // advice: failure is harmless
#else
    (void)p, (void)bytes;
#endif
}

void require_pixels(const OIIO::ImageBuf& buf)
{
    if (buf.spec().image_bytes() > 0 && !buf.localpixels())
        throw std::bad_alloc();
}

void reset_uninitialised(OIIO::ImageBuf& dst, const OIIO::ImageSpec& spec)
{
    dst.reset(spec, OIIO::InitializePixels::No);
    require_pixels(dst);
    if (dst.localpixels())
        prefer_huge_pages(dst.localpixels(), size_t(dst.spec().image_bytes()));
}

void prepare_destination(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ROI& roi)
{
    OIIO::ImageSpec spec = src.spec();
    spec.set_format(OIIO::TypeFloat);
    spec.channelformats.clear();
    spec.x      = roi.xbegin;
    spec.y      = roi.ybegin;
    spec.width  = roi.width();
    spec.height = roi.height();
    reset_uninitialised(dst, spec);
}

bool finish(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ROI& roi, const Plane& p,
            int ox, int oy, bool transposed, int nthreads)
{
    prepare_destination(dst, src, roi);
    const size_t nc = size_t(p.nc), n = size_t(roi.width()) * nc;
    float* const first_row = static_cast<float*>(dst.pixeladdr(roi.xbegin, roi.ybegin));
    const size_t row_step  = size_t(dst.spec().width) * nc;  // prepare_destination: roi-sized
    auto out_row           = [&](int y) { return first_row + size_t(y) * row_step; };
    if (!transposed) {
        parallel_for_chunks(0, roi.height(), 16, nthreads, [&](int64_t y0, int64_t y1) {
            for (int y = int(y0); y < int(y1); ++y)
                std::copy_n(p.row(y + oy) + size_t(ox) * nc, n, out_row(y));
        });
        return true;
    }
    // Output (x, y) is p(y + oy, x + ox): per block of output rows, each plane row gives
    // one contiguous run, spread over the block's rows.
    constexpr int kBlock = 32;
    parallel_for_chunks(0, (roi.height() + kBlock - 1) / kBlock, 1, nthreads, [&](int64_t b0, int64_t b1) {
        for (int64_t b = b0; b < b1; ++b) {
            const int y0 = int(b) * kBlock, y1 = std::min(roi.height(), y0 + kBlock);
            for (int x = 0; x < roi.width(); ++x)
                copy_pixels(out_row(y0) + size_t(x) * nc, row_step, p.row(x + ox) + size_t(y0 + oy) * nc,
                            nc, y1 - y0, p.nc);
        }
    });
    return true;
}

OIIO::ROI grown(OIIO::ROI r, int rx, int ry)
{
    r.xbegin -= rx;
    r.xend += rx;
    r.ybegin -= ry;
    r.yend += ry;
    return r;
}

const OIIO::ImageBuf& float_source(const OIIO::ImageBuf& src, OIIO::ImageBuf& holder)
{
    if (src.spec().format == OIIO::TypeFloat && src.localpixels())
        return src;
    holder.copy(src, OIIO::TypeFloat);
    return holder;
}

bool check_source(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const char* what)
{
    if (!src.initialized()) {
        dst.errorfmt("{}: the source image is empty", what);
        return false;
    }
    if (src.deep()) {
        dst.errorfmt("{}: deep images cannot be blurred; flatten them first", what);
        return false;
    }
    if (src.spec().depth > 1) {
        dst.errorfmt("{}: volume images are not supported", what);
        return false;
    }
    return true;
}

// Four channels: four pixels at a time, their sums within the block formed off the chain,
// so the running sum (one vector add per block, not per pixel) is the only dependency
// carried from block to block. Written with vector types (PixelRgba, plane.h): the same
// steps written per channel were compiled scalar in every clone, 2x slower in isolation
// and 18 % of the fused hexagon sweep's time. Other channel counts go
// through memory.
BOKEH_HOT void row_prefix(double* p, const float* v, size_t npx, int nc)
{
    if (nc == 4) {
        using Sum      = SumRgba;
        const auto* in = reinterpret_cast<const PixelRgba*>(v);
        auto* out      = reinterpret_cast<SumRgbaInMem*>(p);
        Sum run        = { 0.0, 0.0, 0.0, 0.0 };
        out[0]         = run;
        size_t x       = 0;
        for (; x + 4 <= npx; x += 4) {
            const Sum s0 = __builtin_convertvector(in[x], Sum);
            const Sum s1 = s0 + __builtin_convertvector(in[x + 1], Sum);
            const Sum s2 = s1 + __builtin_convertvector(in[x + 2], Sum);
            const Sum s3 = s2 + __builtin_convertvector(in[x + 3], Sum);
            out[x + 1] = run + s0;
            out[x + 2] = run + s1;
            out[x + 3] = run + s2;
            out[x + 4] = run + s3;
            run += s3;
        }
        for (; x < npx; ++x)
            out[x + 1] = run += __builtin_convertvector(in[x], Sum);
        return;
    }
    const size_t ncs = size_t(nc);
    std::fill_n(p, ncs, 0.0);
    for (size_t i = 0, e = npx * ncs; i < e; ++i)
        p[i + ncs] = p[i] + double(v[i]);
}

// acc[i] += w * (hi[i] - lo[i]): one span of prefix sums.
BOKEH_HOT void add_span(double* acc, const double* hi, const double* lo, double w, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        acc[i] += w * (hi[i] - lo[i]);
}

namespace {

// For each i < n, store(i, v) with v = sum over k < N of w[k] * (hi[k][i] - lo[k][i]): the
// span sums of N spans, kept in registers per i, stored once.
template <int N, class Store>
inline __attribute__((always_inline)) void span_sums(const double* const* hi, const double* const* lo,
                                                     const double* w, size_t n, Store store)
{
    const double* h[N > 0 ? N : 1];  // a kernel row may have no spans
    const double* l[N > 0 ? N : 1];
    double wk[N > 0 ? N : 1];
    for (int k = 0; k < N; ++k)
        h[k] = hi[k], l[k] = lo[k], wk[k] = w[k];
    // The prefix rows are read only; what `store` writes is no prefix row.
#pragma GCC ivdep
    for (size_t i = 0; i < n; ++i) {
        double v = 0.0;
        for (int k = 0; k < N; ++k)
            v += wk[k] * (h[k][i] - l[k][i]);
        store(i, v);
    }
}

// span_sums for count <= 8 spans, their number a compile-time constant.
template <class Store>
inline __attribute__((always_inline)) void span_sums_upto8(size_t count, const double* const* hi,
                                                           const double* const* lo, const double* w,
                                                           size_t n, Store store)
{
    switch (count) {
    case 0: span_sums<0>(hi, lo, w, n, store); break;
    case 1: span_sums<1>(hi, lo, w, n, store); break;
    case 2: span_sums<2>(hi, lo, w, n, store); break;
    case 3: span_sums<3>(hi, lo, w, n, store); break;
    case 4: span_sums<4>(hi, lo, w, n, store); break;
    case 5: span_sums<5>(hi, lo, w, n, store); break;
    case 6: span_sums<6>(hi, lo, w, n, store); break;
    case 7: span_sums<7>(hi, lo, w, n, store); break;
    default: span_sums<8>(hi, lo, w, n, store); break;
    }
}

// a[i] += v, and b[i] += v when Both, eight spans per pass: a span then costs its two
// loads and a multiply-add, and an accumulator is loaded and stored once per pass
// instead of once per span.
template <bool Both>
inline __attribute__((always_inline)) void add_spans_n(double* a, double* b, const double* const* hi,
                                                       const double* const* lo, const double* w,
                                                       size_t count, size_t n)
{
    for (; count > 0; hi += 8, lo += 8, w += 8, count -= std::min<size_t>(count, 8))
        span_sums_upto8(std::min<size_t>(count, 8), hi, lo, w, n, [=](size_t i, double v) {
            a[i] += v;
            if (Both)
                b[i] += v;
        });
}

// fresh[i] = v when Fresh, out[i] = float(last[i] + v) when Last; count <= 8.
template <bool Fresh, bool Last>
inline __attribute__((always_inline)) void start_finish_n(double* fresh, const double* last, float* out,
                                                          const double* const* hi, const double* const* lo,
                                                          const double* w, size_t count, size_t n)
{
    span_sums_upto8(count, hi, lo, w, n, [=](size_t i, double v) {
        if (Fresh)
            fresh[i] = v;
        if (Last)
            out[i] = float(last[i] + v);
    });
}

}  // namespace

BOKEH_HOT void start_and_finish_rows(double* fresh, double* last, float* out, const double* const* hi,
                                     const double* const* lo, const double* w, size_t count, size_t n)
{
    if (count > 8) {  // rare: through the accumulators, then out
        if (fresh)
            std::fill_n(fresh, n, 0.0);
        if (fresh && last)
            add_spans_n<true>(fresh, last, hi, lo, w, count, n);
        else if (fresh || last)
            add_spans_n<false>(fresh ? fresh : last, nullptr, hi, lo, w, count, n);
        if (last)
            to_float(out, last, n);
    } else if (fresh && last) {
        start_finish_n<true, true>(fresh, last, out, hi, lo, w, count, n);
    } else if (fresh) {
        start_finish_n<true, false>(fresh, nullptr, nullptr, hi, lo, w, count, n);
    } else if (last) {
        start_finish_n<false, true>(nullptr, last, out, hi, lo, w, count, n);
    }
}

BOKEH_HOT void add_spans(double* acc, const double* const* hi, const double* const* lo,
                         const double* w, size_t count, size_t n)
{
    add_spans_n<false>(acc, nullptr, hi, lo, w, count, n);
}

BOKEH_HOT void add_spans_pair(double* a, double* b, const double* const* hi, const double* const* lo,
                              const double* w, size_t count, size_t n)
{
    if (b)
        add_spans_n<true>(a, b, hi, lo, w, count, n);
    else
        add_spans_n<false>(a, nullptr, hi, lo, w, count, n);
}

// acc[i] += w * src[i].
BOKEH_HOT void add_scaled(double* acc, const float* src, double w, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        acc[i] += w * double(src[i]);
}

BOKEH_HOT void weighted_sum(float* out, const float* const* src, const double* w, size_t taps, size_t n)
{
    constexpr size_t kBlock = 16;
    size_t i = 0;
    for (; i + kBlock <= n; i += kBlock) {
        double acc[kBlock] = {};
        for (size_t j = 0; j < taps; ++j) {
            const float* s = src[j] + i;
            const double wj = w[j];
            for (size_t k = 0; k < kBlock; ++k)
                acc[k] += wj * double(s[k]);
        }
        for (size_t k = 0; k < kBlock; ++k)
            out[i + k] = float(acc[k]);
    }
    for (; i < n; ++i) {
        double acc = 0.0;
        for (size_t j = 0; j < taps; ++j)
            acc += w[j] * double(src[j][i]);
        out[i] = float(acc);
    }
}

BOKEH_HOT void to_float(float* out, const double* acc, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        out[i] = float(acc[i]);
}

}  // namespace bokeh::detail
