// plane.cpp — padded float planes for the blur methods (see plane.h).

#include "plane.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>

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

Plane pad(const OIIO::ImageBuf& src, const OIIO::ROI& region, Border border, int nthreads)
{
    const int nc = src.nchannels();
    Plane p(region.width(), region.height(), nc);
    const OIIO::ROI data = src.roi();
    parallel_for_chunks(0, p.h, 8, nthreads, [&](int64_t j0, int64_t j1) {
        for (int j = int(j0); j < int(j1); ++j) {
            const int sy = border_index(region.ybegin + j, data.ybegin, data.yend, border);
            float* out   = p.row(j);
            if (sy == kOutside) {
                std::fill_n(out, p.stride(), 0.0f);
                continue;
            }
            // The part of the row inside the data window in one copy, the rest by the rule.
            const int in0 = std::max(region.xbegin, data.xbegin);
            const int in1 = std::min(region.xend, data.xend);
            if (in1 > in0)
                std::copy_n(static_cast<const float*>(src.pixeladdr(in0, sy, data.zbegin)),
                            size_t(in1 - in0) * size_t(nc),
                            out + size_t(in0 - region.xbegin) * size_t(nc));
            for (int i = 0; i < p.w; ++i) {
                const int x = region.xbegin + i;
                if (x >= in0 && x < in1)
                    continue;
                const int sx = border_index(x, data.xbegin, data.xend, border);
                if (sx != kOutside)
                    std::copy_n(static_cast<const float*>(src.pixeladdr(sx, sy, data.zbegin)), nc,
                                out + size_t(i) * size_t(nc));
                else
                    std::fill_n(out + size_t(i) * size_t(nc), nc, 0.0f);
            }
        }
    });
    return p;
}

bool finish(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ROI& roi, const Plane& p,
            int ox, int oy)
{
    OIIO::ImageSpec spec = src.spec();
    spec.set_format(OIIO::TypeFloat);
    spec.channelformats.clear();
    spec.x      = roi.xbegin;
    spec.y      = roi.ybegin;
    spec.width  = roi.width();
    spec.height = roi.height();
    dst.reset(spec, OIIO::InitializePixels::No);
    const size_t n = size_t(roi.width()) * size_t(p.nc);
    for (int y = 0; y < roi.height(); ++y)
        std::copy_n(p.row(y + oy) + size_t(ox) * size_t(p.nc), n,
                    static_cast<float*>(dst.pixeladdr(roi.xbegin, roi.ybegin + y)));
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

Plane transposed(const Plane& in, int nthreads)
{
    Plane out(in.h, in.w, in.nc);
    const size_t nc = size_t(in.nc);
    // 32 x 32 pixel tiles keep both the read and the written rows in cache.
    constexpr int kTile = 32;
    const int tx = (in.w + kTile - 1) / kTile, ty = (in.h + kTile - 1) / kTile;
    parallel_for_chunks(0, int64_t(tx) * ty, 4, nthreads, [&](int64_t t0, int64_t t1) {
        for (int64_t t = t0; t < t1; ++t) {
            const int x0 = int(t % tx) * kTile, y0 = int(t / tx) * kTile;
            const int x1 = std::min(in.w, x0 + kTile), y1 = std::min(in.h, y0 + kTile);
            for (int y = y0; y < y1; ++y)
                for (int x = x0; x < x1; ++x)
                    std::copy_n(in.row(y) + size_t(x) * nc, nc, out.row(x) + size_t(y) * nc);
        }
    });
    return out;
}

// acc[i] += w * (hi[i] - lo[i]): one span of prefix sums.
BOKEH_HOT void add_span(double* acc, const double* hi, const double* lo, double w, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        acc[i] += w * (hi[i] - lo[i]);
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
