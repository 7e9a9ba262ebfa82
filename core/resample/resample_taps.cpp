// resample_taps.cpp — the weights of one axis of a resampling (resample_taps.h): the 1-D
// kernels (Keys 1981's cubic convolution, a = -0.5: Catmull-Rom; Lanczos' windowed sinc;
// Mitchell & Netravali 1988's B-spline; the tent), evaluated at each output's source
// position, normalised, with the border rule folded in (a clamped tap adds its weight to
// the edge pixel) and zero weights at the ends dropped; the compound methods' stages
// (bilinear 2x, a small blur, bilinear again) kept apart or multiplied (compose).

#include <bokeh/aperture.h>
#include <bokeh/base.h>
#include <bokeh/resample.h>

#include "base/plane.h"
#include "resample/resample_common.h"
#include "resample/resample_taps.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

namespace {

using OIIO::Strutil::fmt::format;

// Keys (1981) cubic convolution with a = -0.5 (Catmull-Rom).
double catmull_rom(double t)
{
    t = std::abs(t);
    if (t < 1.0)
        return (1.5 * t - 2.5) * t * t + 1.0;
    if (t < 2.0)
        return ((-0.5 * t + 2.5) * t - 4.0) * t + 2.0;
    return 0.0;
}


// Lanczos window of `a` lobes: sinc(t) sinc(t / a). Exactly 1 at 0 and 0 at the other
// integers, so that it interpolates bit for bit (sin(pi n) is not exactly 0 in floating
// point).
double lanczos(double t, double a)
{
    t = std::abs(t);
    if (t >= a)
        return 0.0;
    if (t == 0.0)
        return 1.0;
    if (t == std::floor(t))
        return 0.0;
    const double x = kPi * t;
    return a * std::sin(x) * std::sin(x / a) / (x * x);
}

// Sums (source index, weight) pairs of one output into a dense row at the end of `m`,
// mapping each index by the border rule; `inside_only` drops outside taps and renormalises
// instead.
class RowBuilder {
public:
    RowBuilder(TapMatrix& m, int n_src, Border border, bool inside_only)
        : m_m(m), m_n(n_src), m_border(border), m_inside_only(inside_only)
    {
    }
    void add(int n, double w)
    {
        if (w == 0.0)
            return;
        m_total += w;
        int i = n;
        if (n < 0 || n >= m_n) {
            i = m_inside_only ? kOutside : border_index(n, 0, m_n, m_border);
            if (i == kOutside)
                return;
        }
        m_inside += w;
        std::vector<double>& r = m_m.w;
        const size_t begin     = m_m.offset.back();
        if (r.size() == begin) {
            m_first = i;
        } else if (i < m_first) {
            r.insert(r.begin() + std::ptrdiff_t(begin), size_t(m_first - i), 0.0);
            m_first = i;
        }
        const size_t at = begin + size_t(i - m_first);
        if (at >= r.size())
            r.resize(at + 1, 0.0);
        r[at] += w;
    }
    void finish(bool normalise)
    {
        // Normalise by the total before the border rule, so Black keeps its darkening;
        // inside_only renormalises over the taps that are left.
        const double sum = m_inside_only ? m_inside : m_total;
        if ((normalise || m_inside_only) && sum != 0.0 && sum != 1.0)
            for (size_t k = m_m.offset.back(); k < m_m.w.size(); ++k)
                m_m.w[k] /= sum;
        m_m.close_row(m_first);
    }

private:
    TapMatrix& m_m;
    int m_n;
    Border m_border;
    bool m_inside_only;
    int m_first    = 0;
    double m_total = 0.0, m_inside = 0.0;
};

// Point kernel f of support `radius` (filter units), stretched by `stretch`, at u.
template<class F>
void kernel_row(TapMatrix& m, double u, double radius, double stretch, int n_src, Border border, F f)
{
    RowBuilder b(m, n_src, border, false);
    const double reach = radius * stretch;
    const int lo = int(std::ceil(u - reach)), hi = int(std::floor(u + reach));
    for (int n = lo; n <= hi; ++n)
        b.add(n, f((double(n) - u) / stretch));
    b.finish(true);
}

// Area-exact box: the destination footprint [u - h, u + h] over source pixels.
void box_row(TapMatrix& m, double u, double h, int n_src, Border border, bool inside_only)
{
    RowBuilder b(m, n_src, border, inside_only);
    const double a = u - h, e = u + h;
    const int lo = int(std::floor(a + 0.5)), hi = int(std::ceil(e - 0.5));
    for (int n = lo; n <= hi; ++n) {
        const double overlap = std::min(e, n + 0.5) - std::max(a, n - 0.5);
        if (overlap > 0.0)
            b.add(n, overlap / (2.0 * h));
    }
    b.finish(false);
}

// A single tap of weight 1 at source index n.
void point_row(TapMatrix& m, int n, int n_src, Border border)
{
    RowBuilder b(m, n_src, border, false);
    b.add(n, 1.0);
    b.finish(false);
}

// A convolution on a grid of n pixels with the centred weights `k`, borders by rule.
TapMatrix convolution(int n, const std::vector<double>& k, Border border)
{
    TapMatrix m;
    m.reserve(size_t(n), size_t(n) * k.size());
    const int r = int(k.size() / 2);
    for (int i = 0; i < n; ++i) {
        RowBuilder b(m, n, border, false);
        for (int d = -r; d <= r; ++d)
            b.add(i + d, k[size_t(d + r)]);
        b.finish(false);
    }
    return m;
}

// `n` rows, row(m, u) adding output i's to m given its source position u = pos(i).
template<class Pos, class Row> TapMatrix rows(int n, Pos pos, Row row)
{
    TapMatrix m;
    m.reserve(size_t(n), size_t(n) * 4);
    for (int i = 0; i < n; ++i)
        row(m, pos(i));
    return m;
}

}  // namespace

// C = B * A: B maps the mid grid to the output, A the source to the mid grid.
TapMatrix compose(const TapMatrix& b, const TapMatrix& a)
{
    TapMatrix c;
    c.reserve(b.size(), b.w.size() * 2);
    for (size_t i = 0; i < b.size(); ++i) {
        const TapRow rb = b[i];
        int lo = std::numeric_limits<int>::max(), hi = std::numeric_limits<int>::min();
        for (size_t j = 0; j < rb.n; ++j) {
            const TapRow ra = a[size_t(rb.first) + j];
            if (rb.w[j] == 0.0 || ra.empty())
                continue;
            lo = std::min(lo, ra.first);
            hi = std::max(hi, ra.first + int(ra.n) - 1);
        }
        if (lo > hi) {
            c.close_row(0);
            continue;
        }
        const size_t begin = c.w.size();
        c.w.resize(begin + size_t(hi - lo + 1), 0.0);
        for (size_t j = 0; j < rb.n; ++j) {
            const TapRow ra = a[size_t(rb.first) + j];
            for (size_t k = 0; k < ra.n; ++k)
                c.w[begin + size_t(ra.first - lo) + k] += rb.w[j] * ra.w[k];
        }
        c.close_row(lo);
    }
    return c;
}


// n_dst outputs from n_src source pixels along map `m`.
bool axis_taps(AxisTaps& taps, int n_src, int n_dst, const AxisMap& m, const ResampleOptions& o,
               bool prefilter, std::string& err)
{
    TapMatrix& out = taps.post;
    const Border border = o.border;
    const double ratio  = m.src_size / m.dst_size;  // destination pixel in source pixels
    auto pos            = [&](int i) { return m.source(i); };
    // A factor of 1 on whole pixels: the identity, whatever the filter.
    if (ratio == 1.0 && pos(0) == std::floor(pos(0))) {
        out = rows(n_dst, pos, [&](TapMatrix& r, double u) { point_row(r, int(u), n_src, border); });
        return true;
    }
    const double stretch = prefilter ? std::max(1.0, ratio) : 1.0;
    switch (o.filter) {
    case ResampleFilter::Nearest:
        out = rows(n_dst, pos,
                   [&](TapMatrix& r, double u) { point_row(r, int(std::floor(u + 0.5)), n_src, border); });
        return true;
    case ResampleFilter::Box:
        out = rows(n_dst, pos, [&](TapMatrix& r, double u) { box_row(r, u, 0.5 * ratio, n_src, border, false); });
        return true;
    case ResampleFilter::Bilinear:
        out = rows(n_dst, pos,
                   [&](TapMatrix& r, double u) { kernel_row(r, u, 1.0, stretch, n_src, border, tent); });
        return true;
    case ResampleFilter::CatmullRom:
        out = rows(n_dst, pos,
                   [&](TapMatrix& r, double u) { kernel_row(r, u, 2.0, stretch, n_src, border, catmull_rom); });
        return true;
    case ResampleFilter::BSpline:
        out = rows(n_dst, pos,
                   [&](TapMatrix& r, double u) { kernel_row(r, u, 2.0, stretch, n_src, border, bspline); });
        return true;
    case ResampleFilter::Lanczos2:
    case ResampleFilter::Lanczos3: {
        const double a = o.filter == ResampleFilter::Lanczos2 ? 2.0 : 3.0;
        out = rows(n_dst, pos, [&](TapMatrix& r, double u) {
            kernel_row(r, u, a, stretch, n_src, border, [a](double t) { return lanczos(t, a); });
        });
        return true;
    }
    case ResampleFilter::Gaussian: {
        const double s = o.gaussian_sigma > 0.0f ? o.gaussian_sigma : kGaussianSigma;
        out = rows(n_dst, pos, [&](TapMatrix& r, double u) {
            kernel_row(r, u, 4.0 * s, stretch, n_src, border,
                       [s](double t) { return std::exp(-t * t / (2.0 * s * s)); });
        });
        return true;
    }
    default: break;
    }

    // The compound methods: stages on finer grids.
    if (ratio > 1.0) {
        err = format("filter {} only enlarges (the destination is smaller than the source "
                     "along an axis); use box, bilinear or a cubic to reduce",
                     filter_name(o.filter));
        return false;
    }
    auto bilinear_at = [&](int n) {
        return [n, border](TapMatrix& r, double u) { kernel_row(r, u, 1.0, 1.0, n, border, tent); };
    };
    const std::vector<double> binomial = { 0.25, 0.5, 0.25 };
    TapMatrix acc;           // source -> current grid
    int n_cur      = n_src;  // current grid size
    double f_total = 1.0;    // current grid pixels per source pixel
    double left    = 1.0 / ratio;
    if (o.filter == ResampleFilter::ReducedBlur) {
        const double s = o.blur_sigma > 0.0f ? o.blur_sigma : kReducedBlurSigma;
        acc = convolution(n_src, gaussian_weights_1d(s), border);
    } else {
        const int stages = o.filter == ResampleFilter::UpscaleBlurTwoStage ? 2 : 1;
        for (int s = 0; s < stages && left > 1.0; ++s) {
            const double f = std::min(2.0, left);
            const int n_next = int(std::ceil(n_cur * f - 1e-9));
            // Stage grid pixel j sits at (j + 0.5) / f - 0.5 on the current grid.
            const auto at = [f](int j) { return (j + 0.5) / f - 0.5; };
            TapMatrix up;
            if (o.filter == ResampleFilter::UpscaleBlurFused) {
                const double d = (o.fused_offset > 0.0f ? o.fused_offset : kFusedOffset) * f_total;
                TapMatrix read;  // one bilinear read at a time
                up = rows(n_next, at, [&](TapMatrix& m, double c) {
                    RowBuilder b(m, n_cur, border, false);
                    for (double side : { -d, d }) {
                        read.clear();
                        bilinear_at(n_cur)(read, c + side);
                        const TapRow r = read[0];
                        for (size_t k = 0; k < r.n; ++k)
                            b.add(r.first + int(k), 0.5 * r.w[k]);
                    }
                    b.finish(false);
                });
            } else {
                up = compose(convolution(n_next, binomial, border), rows(n_next, at, bilinear_at(n_cur)));
            }
            acc = acc.empty() ? std::move(up) : compose(up, acc);
            n_cur = n_next;
            f_total *= f;
            left /= f;
        }
        if (acc.empty())  // nothing to enlarge by 2 (factor < 1 was refused above)
            acc = convolution(n_src, { 1.0 }, border);
    }
    // Bilinear from the current grid to the output.
    taps.post  = rows(n_dst, [&](int i) { return (pos(i) + 0.5) * f_total - 0.5; }, bilinear_at(n_cur));
    taps.pre   = std::move(acc);
    taps.n_mid = n_cur;
    return true;
}

TapMatrix box_taps(int n_src, int n_dst, const AxisMap& m, bool outside_is_black)
{
    const double h = 0.5 * m.src_size / m.dst_size;
    return rows(n_dst, [&](int i) { return m.source(i); }, [&](TapMatrix& r, double u) {
        box_row(r, u, h, n_src, Border::Black, !outside_is_black);
    });
}

}  // namespace bokeh::detail
