// blur.cpp — uniform blurs: box by running sums, Gaussian by separable convolution or
// three boxes, disk and polygon by row spans, and the brute-force reference.
//
// Every method is a "valid" convolution of a padded plane: the source region the output
// needs, grown by the kernel radius and filled past the data window by the border rule,
// is copied once into a contiguous float plane; the methods read only inside it.
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
// in double; a fractional width adds its two partial end pixels explicitly.
//
// Fast Gaussian: three equal boxes whose variance adds up to sigma^2 (central limit;
// Wells 1986, "Efficient synthesis of Gaussian filters by cascaded uniform filters"). The
// box width is fractional, so the variance matches exactly, not to the nearest odd width.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

namespace {

// The innermost loops, compiled for AVX-512, AVX2 and baseline x86-64 and chosen at load
// time (GCC function multiversioning), so one portable binary runs at the machine's width.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#    define BOKEH_HOT __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#    define BOKEH_HOT
#endif

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

BOKEH_HOT void to_float(float* out, const double* acc, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        out[i] = float(acc[i]);
}

// A contiguous interleaved float image. Its pixels start uninitialised: every method
// writes each output value, and pad() writes the black ones itself.
struct Plane {
    int w = 0, h = 0, nc = 0;
    std::unique_ptr<float[]> px;
    Plane() = default;
    Plane(int w_, int h_, int nc_)
        : w(w_), h(h_), nc(nc_), px(new float[size_t(w_) * size_t(h_) * size_t(nc_)])
    {
    }
    size_t stride() const { return size_t(w) * size_t(nc); }
    float* row(int y) { return px.get() + size_t(y) * stride(); }
    const float* row(int y) const { return px.get() + size_t(y) * stride(); }
};

constexpr int kOutside = std::numeric_limits<int>::min();

// Index of coordinate i in [begin, end) under the border rule; kOutside = black.
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

// The source over `region`, border-filled. `src` is float with local pixels.
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

// --- weighted sums of rows (separable passes, brute force) ------------------------

// Each row y of `out` = sum_j w[j] * source(y, j), accumulated in double.
template<class Source>
void weighted_rows(Plane& out, const std::vector<double>& w, Source source, int nthreads)
{
    parallel_for_chunks(0, out.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        const size_t n = out.stride();
        std::vector<double> acc(n);
        for (int y = int(y0); y < int(y1); ++y) {
            std::fill(acc.begin(), acc.end(), 0.0);
            for (size_t j = 0; j < w.size(); ++j)
                add_scaled(acc.data(), source(y, j), w[j], n);
            to_float(out.row(y), acc.data(), n);
        }
    });
}

// --- brute force -------------------------------------------------------------------

// The weights point-reflected: out(x) = sum_d w(d) in(x - d) = sum_d w(-d) in(x + d), so a
// point spreads into the kernel's own shape (this matters for shapes without point
// symmetry, such as a pentagon).
KernelWeights reflected(const KernelWeights& k)
{
    KernelWeights r = k;
    std::reverse(r.w.begin(), r.w.end());
    return r;
}

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

// --- row spans ---------------------------------------------------------------------

struct Span {
    int dy, x0, x1;  // covers dx in [x0, x1]
    double weight;
};

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
    parallel_for_chunks(0, in.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y) {
            double* p       = prefix.get() + size_t(y) * pstride;
            const float* v  = in.row(int(y));
            for (int c = 0; c < nc; ++c)
                p[c] = 0.0;
            for (size_t i = 0, n = size_t(in.w) * size_t(nc); i < n; ++i)
                p[i + size_t(nc)] = p[i] + v[i];
        }
    });

    // Output in column strips x row chunks; each task owns its outputs.
    constexpr int kStrip = 256, kRows = 16;
    const int nstrips = (out.w + kStrip - 1) / kStrip;
    const int nrows   = (out.h + kRows - 1) / kRows;
    parallel_for_chunks(0, int64_t(nstrips) * nrows, 1, nthreads, [&](int64_t t, int64_t) {
        const int xs = int(t % nstrips) * kStrip, xe = std::min(out.w, xs + kStrip);
        const int ys = int(t / nstrips) * kRows, ye = std::min(out.h, ys + kRows);
        const size_t i0 = size_t(xs) * size_t(nc), n = size_t(xe - xs) * size_t(nc);
        std::vector<double> acc(n);
        for (int y = ys; y < ye; ++y) {
            std::fill(acc.begin(), acc.end(), 0.0);
            for (const Span& s : spans) {
                const double* p  = prefix.get() + size_t(y + k.ry + s.dy) * pstride + i0;
                const double* hi = p + size_t(k.rx + s.x1 + 1) * size_t(nc);
                const double* lo = p + size_t(k.rx + s.x0) * size_t(nc);
                add_span(acc.data(), hi, lo, s.weight, n);
            }
            to_float(out.row(y) + i0, acc.data(), n);
        }
    });
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

// One box pass along x: a row's prefix sums (double), then each output is the
// difference of two of them, plus the fractional end pixels. The prefix is one add per
// value with the channels as independent chains; the rest vectorises.
Plane box_horizontal(const Plane& in, const BoxPass& b, int nthreads)
{
    const int nc = in.nc;
    Plane out(in.w - 2 * b.radius, in.h, nc);
    const size_t n = out.stride(), ncs = size_t(nc);
    parallel_for_chunks(0, in.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        std::vector<double> prefix(in.stride() + ncs);
        for (int y = int(y0); y < int(y1); ++y) {
            const float* v = in.row(y);
            std::fill_n(prefix.begin(), ncs, 0.0);
            for (size_t i = 0, e = in.stride(); i < e; ++i)
                prefix[i + ncs] = prefix[i] + double(v[i]);
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

// --- dispatch ----------------------------------------------------------------------

// A float, local copy of `src` when it is not already one.
const OIIO::ImageBuf& float_source(const OIIO::ImageBuf& src, OIIO::ImageBuf& holder)
{
    if (src.spec().format == OIIO::TypeFloat && src.localpixels())
        return src;
    holder.copy(src, OIIO::TypeFloat);
    return holder;
}

bool finish(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ROI& roi, const Plane& p)
{
    OIIO::ImageSpec spec = src.spec();
    spec.set_format(OIIO::TypeFloat);
    spec.channelformats.clear();
    spec.x      = roi.xbegin;
    spec.y      = roi.ybegin;
    spec.width  = roi.width();
    spec.height = roi.height();
    dst.reset(spec, OIIO::InitializePixels::No);
    for (int y = 0; y < p.h; ++y)
        std::copy_n(p.row(y), p.stride(),
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

bool check_source(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src)
{
    if (!src.initialized()) {
        dst.errorfmt("blur: the source image is empty");
        return false;
    }
    if (src.deep()) {
        dst.errorfmt("blur: deep images cannot be blurred; flatten them first");
        return false;
    }
    if (src.spec().depth > 1) {
        dst.errorfmt("blur: volume images are not supported");
        return false;
    }
    return true;
}

}  // namespace

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
    return finish(dst, in, roi, convolve_brute(p, weights, nthreads));
}

bool blur(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Kernel& k,
          const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    std::string err;
    if (!validate(k, err)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    if (!check_source(dst, src))
        return false;
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = float_source(src, holder);
    const KernelWeights weights = kernel_weights(k);
    if (opts.method == BlurMethod::Reference)
        return convolve_reference(dst, in, weights, opts, roi, nthreads);

    const bool gaussian = k.shape == KernelShape::Gaussian;
    if (opts.method == BlurMethod::Fast && !gaussian) {
        dst.errorfmt("blur: no fast approximation of this kernel shape yet (use method=exact)");
        return false;
    }
    if (opts.method == BlurMethod::Fast && !weights.is_identity()) {
        // Three boxes per axis with the Gaussian's variance.
        const auto [sx, sy] = gaussian_sigma(k);
        const std::vector<double> bx = box_weights_1d(sx > 0 ? box_width_for_variance(sx * sx / 3.0) : 0.0);
        const std::vector<double> by = box_weights_1d(sy > 0 ? box_width_for_variance(sy * sy / 3.0) : 0.0);
        const int rx = 3 * int(bx.size() / 2), ry = 3 * int(by.size() / 2);
        if (!roi.defined())
            roi = opts.grow ? grown(in.roi(), rx, ry) : in.roi();
        Plane p = pad(in, grown(roi, rx, ry), opts.border, nthreads);
        for (int pass = 0; pass < 3; ++pass)
            p = box_blur(p, bx, by, nthreads);
        return finish(dst, in, roi, p);
    }

    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), weights.rx, weights.ry) : in.roi();
    const Plane p = pad(in, grown(roi, weights.rx, weights.ry), opts.border, nthreads);
    if (weights.is_identity())
        return finish(dst, in, roi, p);  // bit-exact copy
    switch (k.shape) {
    case KernelShape::Box: {
        const std::vector<double> wx = box_weights_1d(k.width_px), wy = box_weights_1d(k.height_px);
        return finish(dst, in, roi, box_blur(p, wx, wy, nthreads));
    }
    case KernelShape::Gaussian: {
        const auto [sx, sy] = gaussian_sigma(k);
        return finish(dst, in, roi,
                      convolve_separable(p, gaussian_weights_1d(sx), gaussian_weights_1d(sy), nthreads));
    }
    case KernelShape::Disk:
    case KernelShape::Polygon: return finish(dst, in, roi, convolve_spans(p, weights, nthreads));
    }
    dst.errorfmt("blur: unknown kernel shape");
    return false;
}

OIIO::ImageBuf blur(const OIIO::ImageBuf& src, const Kernel& k, const BlurOptions& opts,
                    OIIO::ROI roi, int nthreads)
{
    OIIO::ImageBuf dst;
    blur(dst, src, k, opts, roi, nthreads);
    return dst;
}

}  // namespace bokeh
