// plane.cpp — padded float planes for the blur methods (see plane.h), the border rule
// per source row (source_row: shared by pad() and the direct paths of blur.cpp), and the
// vectorised inner loops of the prefix-sum methods (add_span, add_spans: up to four spans
// per pass over the accumulator, so it is loaded and stored once per four spans).

#include "plane.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

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

// p = f(p, channel) on every channel but `skip`.
template<class F> void map_channels(Plane& p, int skip, int nthreads, F f)
{
    parallel_for_chunks(0, p.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* r = p.row(y);
            for (size_t i = 0; i < p.stride(); ++i) {
                const int c = int(i % size_t(p.nc));
                if (c != skip)
                    r[i] = f(r[i], c);
            }
        }
    });
}

}  // namespace

bool Iris::forward(Plane& p, std::string& err, int nthreads)
{
    const int nc = p.nc;
    shift.assign(size_t(nc), 0.0);
    for (int c = 0; c < nc; ++c) {
        if (c == alpha)
            continue;
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        for (size_t i = size_t(c); i < p.size(); i += size_t(nc))
            if (std::isfinite(p.px[i])) {
                lo = std::min(lo, double(p.px[i]));
                hi = std::max(hi, double(p.px[i]));
            }
        if (!(hi >= lo))
            continue;
        if (std::abs(k) * (hi - lo) > 80.0) {
            err = OIIO::Strutil::fmt::format(
                "iris {} times channel {}'s range {} .. {} exceeds 80: exp() would overflow; "
                "lower iris",
                k, c, lo, hi);
            return false;
        }
        shift[size_t(c)] = k > 0 ? lo : hi;
    }
    map_channels(p, alpha, nthreads,
                 [&](float v, int c) { return float(std::exp(k * (v - shift[size_t(c)]))); });
    return true;
}

void Iris::inverse(Plane& p, int nthreads) const
{
    map_channels(p, alpha, nthreads,
                 [&](float v, int c) { return float(shift[size_t(c)] + std::log(double(v)) / k); });
}

void source_row(const OIIO::ImageBuf& src, int sy, int x0, int x1, Border border, float* out)
{
    const int nc        = src.nchannels();
    const OIIO::ROI data = src.roi();
    // The part of the row inside the data window in one copy, the rest by the rule.
    const int in0 = std::max(x0, data.xbegin);
    const int in1 = std::min(x1, data.xend);
    if (in1 > in0)
        std::copy_n(static_cast<const float*>(src.pixeladdr(in0, sy, data.zbegin)),
                    size_t(in1 - in0) * size_t(nc), out + size_t(in0 - x0) * size_t(nc));
    auto outside = [&](int xa, int xb) {
        for (int x = xa; x < xb; ++x) {
            const int sx = border_index(x, data.xbegin, data.xend, border);
            float* o     = out + size_t(x - x0) * size_t(nc);
            if (sx != kOutside)
                std::copy_n(static_cast<const float*>(src.pixeladdr(sx, sy, data.zbegin)), nc, o);
            else
                std::fill_n(o, nc, 0.0f);
        }
    };
    if (in1 > in0) {
        outside(x0, in0);
        outside(in1, x1);
    } else {
        outside(x0, x1);  // the whole row lies outside the data window
    }
}

namespace {

// A fixed pixel size: one vector move per pixel, not a call.
template<int NC>
void copy_pixels(float* dst, size_t dst_step, const float* src, size_t src_step, int count)
{
    for (int i = 0; i < count; ++i)
        std::memcpy(dst + size_t(i) * dst_step, src + size_t(i) * src_step, NC * sizeof(float));
}

}  // namespace

void copy_pixels(float* dst, size_t dst_step, const float* src, size_t src_step, int count, int nc)
{
    switch (nc) {
    case 1: copy_pixels<1>(dst, dst_step, src, src_step, count); return;
    case 3: copy_pixels<3>(dst, dst_step, src, src_step, count); return;
    case 4: copy_pixels<4>(dst, dst_step, src, src_step, count); return;
    default:
        for (int i = 0; i < count; ++i)
            std::copy_n(src + size_t(i) * src_step, nc, dst + size_t(i) * dst_step);
    }
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

void reset_uninitialised(OIIO::ImageBuf& dst, const OIIO::ImageSpec& spec)
{
    dst.reset(spec, OIIO::InitializePixels::No);
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

// Four channels keep their running sums in registers (one vector add per pixel); others
// go through memory.
void row_prefix(double* p, const float* v, size_t npx, int nc)
{
    if (nc == 4) {
        double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
        p[0] = p[1] = p[2] = p[3] = 0.0;
        for (size_t x = 0; x < npx; ++x) {
            a0 += double(v[4 * x]);
            a1 += double(v[4 * x + 1]);
            a2 += double(v[4 * x + 2]);
            a3 += double(v[4 * x + 3]);
            double* o = p + 4 * (x + 1);
            o[0] = a0, o[1] = a1, o[2] = a2, o[3] = a3;
        }
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

// acc[i] += sum over spans s of w[s] * (p[hi[s] + i] - p[lo[s] + i]), up to four spans per
// pass over acc (the one to three left over in one pass): a span then costs its two loads
// and a multiply-add, and the accumulator is loaded and stored once per pass instead of
// once per span.
BOKEH_HOT void add_spans(double* acc, const double* p, const size_t* hi, const size_t* lo,
                         const double* w, size_t count, size_t n)
{
    size_t s = 0;
    for (; s + 4 <= count; s += 4) {
        const double *h0 = p + hi[s], *h1 = p + hi[s + 1], *h2 = p + hi[s + 2], *h3 = p + hi[s + 3];
        const double *l0 = p + lo[s], *l1 = p + lo[s + 1], *l2 = p + lo[s + 2], *l3 = p + lo[s + 3];
        const double w0 = w[s], w1 = w[s + 1], w2 = w[s + 2], w3 = w[s + 3];
        for (size_t i = 0; i < n; ++i)
            acc[i] += (w0 * (h0[i] - l0[i]) + w1 * (h1[i] - l1[i]))
                      + (w2 * (h2[i] - l2[i]) + w3 * (h3[i] - l3[i]));
    }
    // The last one to three spans in one pass.
    if (count - s == 3) {
        const double *h0 = p + hi[s], *h1 = p + hi[s + 1], *h2 = p + hi[s + 2];
        const double *l0 = p + lo[s], *l1 = p + lo[s + 1], *l2 = p + lo[s + 2];
        const double w0 = w[s], w1 = w[s + 1], w2 = w[s + 2];
        for (size_t i = 0; i < n; ++i)
            acc[i] += (w0 * (h0[i] - l0[i]) + w1 * (h1[i] - l1[i])) + w2 * (h2[i] - l2[i]);
    } else if (count - s == 2) {
        const double *h0 = p + hi[s], *h1 = p + hi[s + 1];
        const double *l0 = p + lo[s], *l1 = p + lo[s + 1];
        const double w0 = w[s], w1 = w[s + 1];
        for (size_t i = 0; i < n; ++i)
            acc[i] += w0 * (h0[i] - l0[i]) + w1 * (h1[i] - l1[i]);
    } else if (count - s == 1) {
        add_span(acc, p + hi[s], p + lo[s], w[s], n);
    }
}

// acc[i] += w * src[i].
BOKEH_HOT void add_scaled(double* acc, const float* src, double w, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        acc[i] += w * double(src[i]);
}

BOKEH_HOT void to_float(float* out, const double* acc, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        out[i] = float(acc[i]);
}

}  // namespace bokeh::detail
