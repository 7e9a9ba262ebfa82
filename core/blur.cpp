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

#include "plane.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

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

}  // namespace

namespace detail {

void row_prefix_sums(const Plane& in, double* prefix, int nthreads)
{
    const size_t nc = size_t(in.nc), pstride = size_t(in.w + 1) * nc;
    parallel_for_chunks(0, in.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y) {
            double* p      = prefix + size_t(y) * pstride;
            const float* v = in.row(int(y));
            std::fill_n(p, nc, 0.0);
            for (size_t i = 0, n = size_t(in.w) * nc; i < n; ++i)
                p[i + nc] = p[i] + v[i];
        }
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
    return finish(dst, in, roi, convolve_brute(p, weights, nthreads));
}

namespace {

bool is_hexagon(const Kernel& k)
{
    return k.shape == KernelShape::Polygon && k.blades == 6 && k.curvature == 0.0f && k.hole == 0.0f;
}

// The concrete method for `k`, or false + `err` when the asked one does not apply.
bool resolve_method(const Kernel& k, BlurMethod asked, BlurMethod& m, std::string& err)
{
    const bool gaussian = k.shape == KernelShape::Gaussian;
    const bool shape    = k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon;
    switch (asked) {
    case BlurMethod::Auto:
    case BlurMethod::Exact: m = BlurMethod::Exact; return true;
    case BlurMethod::Reference: m = asked; return true;
    case BlurMethod::Fast:
        m = gaussian       ? BlurMethod::ThreeBoxes
            : is_hexagon(k) ? BlurMethod::Parallelograms
            : shape && k.hole == 0.0f ? BlurMethod::Bands
                                      : BlurMethod::Exact;  // box: running sums are the fast method
        return true;
    case BlurMethod::ThreeBoxes:
        m = asked;
        if (!gaussian)
            err = "method=boxes3 is for the gaussian kernel";
        return gaussian;
    case BlurMethod::Parallelograms:
        m = asked;
        if (!is_hexagon(k))
            err = "method=parallelograms needs a hexagon (6 straight blades, no hole)";
        return is_hexagon(k);
    case BlurMethod::Bands:
        m = asked;
        if (!shape || k.hole != 0.0f)
            err = "method=bands is for disk and polygon kernels without a hole";
        return shape && k.hole == 0.0f;
    case BlurMethod::BilinearTaps: {
        m = asked;
        const bool ok = k.shape == KernelShape::Disk && k.edge == KernelEdge::Antialiased
                        && k.width_px == k.height_px && (k.width_px == 9.0f || k.width_px == 17.0f)
                        && k.hole == 0.0f;
        if (!ok)
            err = "method=taps is the seed's 9x9 or 17x17 anti-aliased disk only";
        return ok;
    }
    }
    err = "unknown method";
    return false;
}

}  // namespace

bool blur(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Kernel& k,
          const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    std::string err;
    BlurMethod method = BlurMethod::Exact;
    if (!validate(k, err) || !resolve_method(k, opts.method, method, err)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    if (opts.bands < 1 || opts.bands > 64) {
        dst.errorfmt("blur: bands {} is outside 1..64", opts.bands);
        return false;
    }
    if (!std::isfinite(opts.iris) || std::abs(opts.iris) > 1000.0f) {
        dst.errorfmt("blur: iris {} is outside -1000..1000", opts.iris);
        return false;
    }
    if (!check_source(dst, src))
        return false;
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = float_source(src, holder);

    // The weights the method computes with (the effective ones for the approximations
    // that have them) and how far the method reads around an output pixel.
    const KernelWeights weights = method == BlurMethod::Bands        ? banded_weights(k, opts.bands)
                                  : method == BlurMethod::BilinearTaps ? bilinear_tap_weights(k)
                                                                       : kernel_weights(k);
    int rx = weights.rx, ry = weights.ry;
    std::vector<double> box3x, box3y;
    if (method == BlurMethod::ThreeBoxes) {
        // Three boxes per axis with the Gaussian's variance.
        const auto [sx, sy] = gaussian_sigma(k);
        box3x = box_weights_1d(sx > 0 ? box_width_for_variance(sx * sx / 3.0) : 0.0);
        box3y = box_weights_1d(sy > 0 ? box_width_for_variance(sy * sy / 3.0) : 0.0);
        rx    = 3 * int(box3x.size() / 2);
        ry    = 3 * int(box3y.size() / 2);
    } else if (method == BlurMethod::Parallelograms && !weights.is_identity()) {
        rx = hexagon_reach(k, true);
        ry = hexagon_reach(k, false);
    }
    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), rx, ry) : in.roi();
    Plane p = pad(in, grown(roi, rx, ry), opts.border, nthreads);
    if (weights.is_identity())
        return finish(dst, in, roi, p);  // bit-exact copy

    Iris iris;
    if (opts.iris != 0.0f) {
        iris.k     = opts.iris;
        iris.alpha = in.spec().alpha_channel;
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
        out = hexagon_parallelograms(p, k, nthreads);
        ox  = rx;
        oy  = ry;
        break;
    case BlurMethod::Bands: out = convolve_banded(p, weights, nthreads); break;
    case BlurMethod::BilinearTaps: out = convolve_spans(p, weights, nthreads); break;
    default:
        switch (k.shape) {
        case KernelShape::Box:
            out = box_blur(p, box_weights_1d(k.width_px), box_weights_1d(k.height_px), nthreads);
            break;
        case KernelShape::Gaussian: {
            const auto [sx, sy] = gaussian_sigma(k);
            out = convolve_separable(p, gaussian_weights_1d(sx), gaussian_weights_1d(sy), nthreads);
            break;
        }
        case KernelShape::Disk:
        case KernelShape::Polygon: out = convolve_spans(p, weights, nthreads); break;
        }
    }
    if (opts.iris != 0.0f)
        iris.inverse(out, nthreads);
    return finish(dst, in, roi, out, ox, oy);
}

OIIO::ImageBuf blur(const OIIO::ImageBuf& src, const Kernel& k, const BlurOptions& opts,
                    OIIO::ROI roi, int nthreads)
{
    OIIO::ImageBuf dst;
    blur(dst, src, k, opts, roi, nthreads);
    return dst;
}

}  // namespace bokeh
