// resample.cpp — reduction and enlargement (resample.h); the depth-aware enlargement
// is in resample_depth_aware.cpp.
//
// Source: Kawase, "Anti reduced-buffer artifacts" (reduced buffers; the enlargement methods
// the talk compares: bilinear, reduced-buffer blur, bicubic, Lanczos, Gaussian,
// upscale-blur, its fused and two-stage forms; docs/methods/resampling.md). Kernels: Keys 1981
// ("Cubic convolution interpolation for digital image processing", a = -0.5 is
// Catmull-Rom), Mitchell & Netravali 1988 (the cubic B-spline is their B = 1, C = 0),
// Lanczos' windowed sinc.
//
// How. Every enlargement method is a separable linear filter, so each becomes, per axis,
// a list of weights per output column (or row): the kernel evaluated at the sample
// position, normalised, with the border rule folded in (a clamped tap adds its weight to
// the edge pixel), zero weights at the ends dropped. The compound methods run on the GPU
// as several passes (bilinear 2x, a small blur, bilinear again); here, along x, the stages
// up to the last fine grid are multiplied into one weight list and run on each source row,
// then the bilinear step takes the row to the output's width; along y all the stages are
// one list (run_axes says why), so the full-size pass costs little more than bilinear's;
// at factor 2, where the fine grid is the output, all the stages are one pass with about
// four taps, like bicubic. Either way the result is that of the stages run in turn (tested
// against exactly that). The pass itself: for a strip of output rows, the source rows it
// needs are filtered along x into a strip buffer (at the source's height, so 1/k of the
// output rows), then each output row is the weighted sum of a few strip rows, one
// vectorised sweep per tap over the row.
//
// What differs from the talk: the fused upscale-blur's offset defaults to the value that
// gives its 2x step the variance of the unfused blur (the talk leaves it free); the
// Gaussian's sigma is fixed in source pixels (resample.h says why 0.6); min / max /
// nearest-depth reducers for depth and CoC channels (the talk only averages colour).
//
// Known limits: filters are separable (tensor-product), not radial; the compound methods
// only enlarge.

#include <bokeh/aperture.h>
#include <bokeh/base.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>
#include <bokeh/resample.h>

#include "base/plane.h"
#include "resample/resample_common.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using detail::bspline;
using detail::check_image;
using detail::check_map;
using detail::check_planes;
using detail::contiguous_float;
using detail::make_output;
using detail::tent;
using detail::view_of;
using detail::border_index;
using detail::ceil_div;
using detail::floor_div;
using detail::kOutside;
using OIIO::Strutil::fmt::format;

namespace detail {

double tent(double t)
{
    t = std::abs(t);
    return t < 1.0 ? 1.0 - t : 0.0;
}

// Uniform cubic B-spline (Mitchell & Netravali 1988, B = 1, C = 0).
double bspline(double t)
{
    t = std::abs(t);
    if (t < 1.0)
        return ((0.5 * t - 1.0) * t * t) + 2.0 / 3.0;
    if (t < 2.0) {
        const double u = 2.0 - t;
        return u * u * u / 6.0;
    }
    return 0.0;
}

bool check_planes(const ConstPlaneView& src, const PlaneView& dst, std::string& err)
{
    if (!src.data || !dst.data || src.width <= 0 || src.height <= 0 || dst.width <= 0
        || dst.height <= 0) {
        err = "empty plane";
        return false;
    }
    if (src.nchannels != dst.nchannels || src.nchannels <= 0) {
        err = format("channel counts differ ({} vs {})", src.nchannels, dst.nchannels);
        return false;
    }
    return true;
}

bool check_map(const AxisMap& m, std::string& err)
{
    if (!(m.src_size > 0.0 && m.dst_size > 0.0 && std::isfinite(m.src_size / m.dst_size)
          && std::isfinite(m.dst_origin) && std::isfinite(m.src_origin))) {
        err = "bad axis map (sizes must be finite and > 0)";
        return false;
    }
    return true;
}

bool check_image(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const char* what)
{
    if (!src.initialized()) {
        dst.errorfmt("{}: the source image is empty", what);
        return false;
    }
    if (src.deep()) {
        dst.errorfmt("{}: deep images cannot be resampled; flatten them first", what);
        return false;
    }
    if (src.spec().depth > 1) {
        dst.errorfmt("{}: volume images are not supported", what);
        return false;
    }
    return true;
}

// A float copy with contiguous local pixels, unless `src` is one.
const OIIO::ImageBuf& contiguous_float(const OIIO::ImageBuf& src, OIIO::ImageBuf& holder)
{
    const OIIO::ImageBuf& f = detail::float_source(src, holder);
    const auto px = OIIO::stride_t(sizeof(float)) * f.nchannels();
    if (f.pixel_stride() == px && f.scanline_stride() == px * f.spec().width)
        return f;
    holder.copy(src, OIIO::TypeFloat);
    return holder;
}

ConstPlaneView view_of(const OIIO::ImageBuf& f)
{
    const OIIO::ROI r = f.roi();
    return ConstPlaneView(static_cast<const float*>(f.pixeladdr(r.xbegin, r.ybegin, r.zbegin)),
                          r.width(), r.height(), f.nchannels(),
                          size_t(r.width()) * size_t(f.nchannels()));
}

// `dst` = a float image like `like` over `data`, display window `full`; its pixels as a plane.
PlaneView make_output(OIIO::ImageBuf& dst, const OIIO::ImageSpec& like, const OIIO::ROI& data,
                      const OIIO::ROI& full)
{
    OIIO::ImageSpec spec = like;
    spec.set_format(OIIO::TypeFloat);
    spec.channelformats.clear();
    spec.x = data.xbegin, spec.y = data.ybegin;
    spec.width = data.width(), spec.height = data.height();
    spec.full_x = full.xbegin, spec.full_y = full.ybegin;
    spec.full_width = full.width(), spec.full_height = full.height();
    // A tiled source's tile size may not suit the new size; the writer picks its own.
    spec.tile_width = spec.tile_height = 0;
    detail::reset_uninitialised(dst, spec);
    PlaneView p;
    p.data       = static_cast<float*>(dst.pixeladdr(data.xbegin, data.ybegin));
    p.width      = data.width();
    p.height     = data.height();
    p.nchannels  = spec.nchannels;
    p.row_stride = size_t(p.width) * size_t(p.nchannels);
    return p;
}

}  // namespace detail

namespace {


// --- 1-D kernels, t in filter units ---------------------------------------------------


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

// --- weights of one axis ------------------------------------------------------------

// Output i = sum_k w[k] * in[first + k], k < n (in double while being built and composed).
struct TapRow {
    int first       = 0;
    const double* w = nullptr;
    size_t n        = 0;
    bool empty() const { return n == 0; }
};

// The rows of one axis, their weights end to end in one array: an axis has thousands of
// rows, and one allocation each was most of the cost of building them.
struct TapMatrix {
    std::vector<int> first;
    std::vector<size_t> offset{ 0 };  // row i's weights are w[offset[i], offset[i + 1])
    std::vector<double> w;

    size_t size() const { return first.size(); }
    bool empty() const { return first.empty(); }
    TapRow operator[](size_t i) const
    {
        return { first[i], w.data() + offset[i], offset[i + 1] - offset[i] };
    }
    void reserve(size_t rows, size_t taps)
    {
        first.reserve(rows);
        offset.reserve(rows + 1);
        w.reserve(taps);
    }
    void clear()
    {
        first.clear();
        offset.resize(1);
        w.clear();
    }
    // Ends the row whose weights are w[offset.back(), w.size()), its first at `lo`, without
    // its zero ends (an empty row starts at 0).
    void close_row(int lo)
    {
        const size_t begin = offset.back();
        size_t b = begin, e = w.size();
        while (b < e && w[b] == 0.0)
            ++b;
        while (e > b && w[e - 1] == 0.0)
            --e;
        w.resize(e);
        w.erase(w.begin() + std::ptrdiff_t(begin), w.begin() + std::ptrdiff_t(b));
        first.push_back(e > b ? lo + int(b - begin) : 0);
        offset.push_back(w.size());
    }
};

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

// The weights of one axis. A compound method keeps its stages apart: `pre` takes the
// source to its last finer grid (n_mid pixels), `post` is the bilinear step from there to
// the output; every other method has only `post`, straight from the source.
struct AxisTaps {
    TapMatrix pre, post;
    int n_mid = 0;
    bool staged() const { return !pre.empty(); }
};

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

// The weights packed as float for the passes, each output's after the one before's.
// `runs` cuts the outputs into stretches of one tap count (bilinear: one run of 2 between a
// few border columns of 1), so that the horizontal pass picks its unrolled loop per run
// rather than per pixel.
struct Taps {
    struct Run {
        int begin, end, count;
    };
    std::vector<int> first, count, offset;
    std::vector<float> w;
    std::vector<Run> runs;
    explicit Taps(const TapMatrix& m)
    {
        first = m.first;
        count.reserve(m.size());
        offset.reserve(m.size());
        for (size_t i = 0; i < m.size(); ++i) {
            const int n = int(m.offset[i + 1] - m.offset[i]);
            count.push_back(n);
            offset.push_back(int(m.offset[i]));
            if (runs.empty() || runs.back().count != n)
                runs.push_back({ int(i), int(i), n });
            ++runs.back().end;
        }
        w.assign(m.w.begin(), m.w.end());
    }
};

// --- the separable pass ---------------------------------------------------------------

// Pixels [0, n) of a horizontal run: COUNT taps (0: `count`) of NC channels (0: `nc`) each,
// pixel x reading from in + first[x] nc with the weights w[x count ...]. The first tap sets
// the sum (not 0 + it), so one tap of weight 1 is exact, -0 included.
template<int NC, int COUNT>
inline void taps_run(float* o, const float* in, const int* first, const float* w, int n,
                     int nc_runtime, int count_runtime)
{
    const int nc    = NC > 0 ? NC : nc_runtime;
    const int count = COUNT > 0 ? COUNT : count_runtime;
    for (int x = 0; x < n; ++x, o += nc, w += count) {
        const float* p = in + size_t(first[x]) * size_t(nc);
        if constexpr (NC > 0) {
            // Summed in registers: summed in `o`, which may alias `p` for all the compiler
            // knows, each tap stored and reloaded the pixel one channel at a time, unvectorised.
            float acc[NC];
            for (int c = 0; c < NC; ++c)
                acc[c] = w[0] * p[c];
            for (int k = 1; k < count; ++k)
                for (int c = 0; c < NC; ++c)
                    acc[c] += w[k] * p[k * NC + c];
            for (int c = 0; c < NC; ++c)
                o[c] = acc[c];
        } else {
            for (int c = 0; c < nc; ++c)
                o[c] = w[0] * p[c];
            for (int k = 1; k < count; ++k)
                for (int c = 0; c < nc; ++c)
                    o[c] += w[k] * p[size_t(k) * size_t(nc) + size_t(c)];
        }
    }
}

// One source row filtered along x, run by run, the common tap counts unrolled.
template<int NC> void horizontal(float* out, const float* in, const Taps& t, int nc_runtime)
{
    const int nc = NC > 0 ? NC : nc_runtime;
    for (const Taps::Run& r : t.runs) {
        float* o       = out + size_t(r.begin) * size_t(nc);
        const int* f   = t.first.data() + r.begin;
        const float* w = t.w.data() + t.offset[size_t(r.begin)];
        const int n    = r.end - r.begin;
        switch (r.count) {
        case 0: std::fill_n(o, size_t(n) * size_t(nc), 0.0f); break;
        case 1: taps_run<NC, 1>(o, in, f, w, n, nc, r.count); break;
        case 2: taps_run<NC, 2>(o, in, f, w, n, nc, r.count); break;
        case 3: taps_run<NC, 3>(o, in, f, w, n, nc, r.count); break;
        case 4: taps_run<NC, 4>(o, in, f, w, n, nc, r.count); break;
        case 5: taps_run<NC, 5>(o, in, f, w, n, nc, r.count); break;
        case 6: taps_run<NC, 6>(o, in, f, w, n, nc, r.count); break;
        default: taps_run<NC, 0>(o, in, f, w, n, nc, r.count); break;
        }
    }
}

// out[i] = sum_k w[k] rows[k][i], summed left to right. Up to 6 taps in one sweep; more
// in blocks that stay in L1, one sweep per tap.
BOKEH_HOT void weighted_rows(float* out, const float* const* r, const float* w, int count,
                             size_t n)
{
    switch (count) {
    case 1:
        for (size_t i = 0; i < n; ++i)
            out[i] = w[0] * r[0][i];
        return;
    case 2:
        for (size_t i = 0; i < n; ++i)
            out[i] = w[0] * r[0][i] + w[1] * r[1][i];
        return;
    case 3:
        for (size_t i = 0; i < n; ++i)
            out[i] = w[0] * r[0][i] + w[1] * r[1][i] + w[2] * r[2][i];
        return;
    case 4:
        for (size_t i = 0; i < n; ++i)
            out[i] = w[0] * r[0][i] + w[1] * r[1][i] + w[2] * r[2][i] + w[3] * r[3][i];
        return;
    case 5:
        for (size_t i = 0; i < n; ++i)
            out[i] = w[0] * r[0][i] + w[1] * r[1][i] + w[2] * r[2][i] + w[3] * r[3][i]
                     + w[4] * r[4][i];
        return;
    case 6:
        for (size_t i = 0; i < n; ++i)
            out[i] = w[0] * r[0][i] + w[1] * r[1][i] + w[2] * r[2][i] + w[3] * r[3][i]
                     + w[4] * r[4][i] + w[5] * r[5][i];
        return;
    default: break;
    }
    constexpr size_t kBlock = 1024;
    for (size_t b = 0; b < n; b += kBlock) {
        const size_t e = std::min(n, b + kBlock);
        for (size_t i = b; i < e; ++i)
            out[i] = w[0] * r[0][i];
        for (int k = 1; k < count; ++k) {
            const float wk  = w[k];
            const float* rk = r[k];
            for (size_t i = b; i < e; ++i)
                out[i] += wk * rk[i];
        }
    }
}

BOKEH_HOT void clamp_below_zero(float* out, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        out[i] = out[i] < 0.0f ? 0.0f : out[i];  // NaN stays NaN
}

// One row filtered along x, the common channel counts unrolled.
void filter_row(float* out, const float* in, const Taps& t, int nc)
{
    if (nc == 4)
        horizontal<4>(out, in, t, nc);
    else if (nc == 1)
        horizontal<1>(out, in, t, nc);
    else
        horizontal<0>(out, in, t, nc);
}

// `pre_x`, when given, filters each source row along x before `tx` does (the first stages
// of a compound method, run_axes).
void separable_pass(const ConstPlaneView& src, const PlaneView& dst, const Taps& tx,
                    const Taps& ty, bool clamp_negative, int nthreads, const Taps* pre_x = nullptr)
{
    const int nc  = src.nchannels;
    const size_t n = size_t(dst.width) * size_t(nc);
    // Output rows per task: enough that the strip's halo (the taps' reach, recomputed by
    // neighbouring tasks) is a small part of it, few enough to share among threads.
    const int rows_per_task = std::clamp(dst.height / 16, 16, 64);
    parallel_for_chunks(0, dst.height, rows_per_task, nthreads, [&](int64_t y0, int64_t y1) {
        // The source rows these output rows read, filtered along x into a strip.
        int lo = std::numeric_limits<int>::max(), hi = std::numeric_limits<int>::min();
        for (int64_t y = y0; y < y1; ++y)
            if (ty.count[size_t(y)] > 0) {
                lo = std::min(lo, ty.first[size_t(y)]);
                hi = std::max(hi, ty.first[size_t(y)] + ty.count[size_t(y)]);
            }
        // Uninitialised: every value is written before it is read.
        const std::unique_ptr<float[]> strip(new float[lo < hi ? size_t(hi - lo) * n : 0]);
        const std::unique_ptr<float[]> row(new float[pre_x ? pre_x->first.size() * size_t(nc) : 0]);
        for (int j = lo; j < hi; ++j) {
            const float* in = src.row(j);
            if (pre_x) {
                filter_row(row.get(), in, *pre_x, nc);
                in = row.get();
            }
            filter_row(strip.get() + size_t(j - lo) * n, in, tx, nc);
        }
        std::vector<const float*> rows;
        for (int64_t y = y0; y < y1; ++y) {
            float* out      = dst.row(int(y));
            const int count = ty.count[size_t(y)];
            if (count == 0) {
                std::fill_n(out, n, 0.0f);
                continue;
            }
            rows.resize(size_t(count));
            for (int k = 0; k < count; ++k)
                rows[size_t(k)] = strip.get() + size_t(ty.first[size_t(y)] + k - lo) * n;
            weighted_rows(out, rows.data(), ty.w.data() + ty.offset[size_t(y)], count, n);
            if (clamp_negative)
                clamp_below_zero(out, n);
        }
    });
}

// Runs the enlargement of both axes. A compound method runs its stages in turn along x
// where its last grid is narrower than the output: the finer-grid steps on each source
// row, then the plain bilinear step to the output's width, so that the pass filters only
// the source's rows at full width, as bilinear's does (multiplied into one list, the taps
// are about twice as wide there, their count varying from column to column). Along y its
// stages are multiplied into one list (3 to 4 taps at 8x where bilinear has 2): the
// vertical sweep at full size is bound by its stores, so the extra taps cost little,
// whereas with the y stages in turn the full-width horizontal sweep filters the last
// grid's rows, twice the source's. Measured (2 threads, RGBA float): 240x135 -> 1080p
// upscale-blur 3.9 ms, 4.2 with both axes in turn, bilinear 3.6; 480x270 -> 1080p 4.5 ms,
// 5.2 as one multiplied pass. At 2x the last grid is the output: all the stages are one
// pass.
void run_axes(const ConstPlaneView& src, const PlaneView& dst, const AxisTaps& ax,
              const AxisTaps& ay, bool clamp_negative, int nthreads)
{
    auto whole = [](const AxisTaps& a) { return a.staged() ? compose(a.post, a.pre) : a.post; };
    const Taps ty(whole(ay));
    if (ax.staged() && ax.n_mid < dst.width) {
        const Taps pre(ax.pre);
        separable_pass(src, dst, Taps(ax.post), ty, clamp_negative, nthreads, &pre);
    } else {
        separable_pass(src, dst, Taps(whole(ax)), ty, clamp_negative, nthreads);
    }
}



bool check_options(const ResampleOptions& o, std::string& err)
{
    auto bad = [](float v) { return !std::isfinite(v) || v < 0.0f || v > 64.0f; };
    if (bad(o.gaussian_sigma) || bad(o.blur_sigma) || bad(o.fused_offset)) {
        err = format("gaussian_sigma {}, blur_sigma {} and fused_offset {} must be within 0..64",
                     o.gaussian_sigma, o.blur_sigma, o.fused_offset);
        return false;
    }
    return true;
}

}  // namespace

// --- filter names ---------------------------------------------------------------------

namespace {
struct FilterName {
    const char* name;
    ResampleFilter filter;
};
// The first name of each filter is the one filter_name() gives.
constexpr FilterName kFilterNames[] = {
    { "nearest", ResampleFilter::Nearest },
    { "bilinear", ResampleFilter::Bilinear },
    { "triangle", ResampleFilter::Bilinear },
    { "catmull-rom", ResampleFilter::CatmullRom },
    { "bspline", ResampleFilter::BSpline },
    { "b-spline", ResampleFilter::BSpline },
    { "lanczos2", ResampleFilter::Lanczos2 },
    { "lanczos3", ResampleFilter::Lanczos3 },
    { "gaussian", ResampleFilter::Gaussian },
    { "box", ResampleFilter::Box },
    { "reduced-blur", ResampleFilter::ReducedBlur },
    { "upscale-blur", ResampleFilter::UpscaleBlur },
    { "upscale-blur-fused", ResampleFilter::UpscaleBlurFused },
    { "upscale-blur-2stage", ResampleFilter::UpscaleBlurTwoStage },
};
}  // namespace

const char* filter_name(ResampleFilter f)
{
    for (const FilterName& n : kFilterNames)
        if (n.filter == f)
            return n.name;
    return "?";
}

bool parse_filter(const std::string& name, ResampleFilter& f)
{
    for (const FilterName& n : kFilterNames)
        if (name == n.name) {
            f = n.filter;
            return true;
        }
    return false;
}

std::vector<std::string> filter_names()
{
    std::vector<std::string> names;
    for (const FilterName& n : kFilterNames)
        names.emplace_back(n.name);
    return names;
}

// --- planes -----------------------------------------------------------------------------

bool resample_plane(const ConstPlaneView& src, const PlaneView& dst, const AxisMap& mx,
                    const AxisMap& my, const ResampleOptions& opts, std::string& err,
                    int nthreads, bool prefilter)
{
    if (!check_planes(src, dst, err) || !check_map(mx, err) || !check_map(my, err)
        || !check_options(opts, err))
        return false;
    AxisTaps wx, wy;
    if (!axis_taps(wx, src.width, dst.width, mx, opts, prefilter, err)
        || !axis_taps(wy, src.height, dst.height, my, opts, prefilter, err))
        return false;
    run_axes(src, dst, wx, wy, opts.clamp_negative, nthreads);
    return true;
}

namespace {

// The box footprints of an axis (only the taps that hold a part of the footprint).
TapMatrix box_taps(int n_src, int n_dst, const AxisMap& m, bool outside_is_black)
{
    const double h = 0.5 * m.src_size / m.dst_size;
    return rows(n_dst, [&](int i) { return m.source(i); }, [&](TapMatrix& r, double u) {
        box_row(r, u, h, n_src, Border::Black, !outside_is_black);
    });
}

}  // namespace

bool reduce_plane(const ConstPlaneView& src, const PlaneView& dst, const AxisMap& mx,
                  const AxisMap& my, const std::vector<Reducer>& reducers, int depth_channel,
                  bool outside_is_black, std::string& err, int nthreads)
{
    if (!check_planes(src, dst, err) || !check_map(mx, err) || !check_map(my, err))
        return false;
    const int nc = src.nchannels;
    if (int(reducers.size()) != nc) {
        err = format("{} reducers for {} channels", reducers.size(), nc);
        return false;
    }
    const bool any_mean = std::count(reducers.begin(), reducers.end(), Reducer::Mean) > 0;
    const bool any_nearest =
        std::count(reducers.begin(), reducers.end(), Reducer::NearestDepth) > 0;
    if (any_nearest && (depth_channel < 0 || depth_channel >= nc)) {
        err = "the nearest-depth reducer needs a depth channel (Z)";
        return false;
    }
    const TapMatrix wx = box_taps(src.width, dst.width, mx, outside_is_black);
    const TapMatrix wy = box_taps(src.height, dst.height, my, outside_is_black);
    if (any_mean)
        separable_pass(src, dst, Taps(wx), Taps(wy), false, nthreads);
    if (!any_mean || std::count(reducers.begin(), reducers.end(), Reducer::Mean) < nc) {
        // Min, max and nearest depth over each footprint's pixels.
        const float nan = std::numeric_limits<float>::quiet_NaN();
        parallel_for_chunks(0, dst.height, 8, nthreads, [&](int64_t y0, int64_t y1) {
            std::vector<float> lo(static_cast<size_t>(nc)), hi(static_cast<size_t>(nc));
            for (int y = int(y0); y < int(y1); ++y) {
                const TapRow ry = wy[size_t(y)];
                for (int x = 0; x < dst.width; ++x) {
                    const TapRow rx = wx[size_t(x)];
                    float* o = dst.row(y) + size_t(x) * size_t(nc);
                    if (rx.empty() || ry.empty()) {
                        for (int c = 0; c < nc; ++c)
                            if (reducers[size_t(c)] != Reducer::Mean)
                                o[c] = 0.0f;
                        continue;
                    }
                    const float inf = std::numeric_limits<float>::infinity();
                    std::fill(lo.begin(), lo.end(), inf);
                    std::fill(hi.begin(), hi.end(), -inf);
                    const float* nearest = nullptr;
                    float nearest_z      = inf;
                    for (size_t j = 0; j < ry.n; ++j) {
                        const float* row = src.row(ry.first + int(j));
                        for (size_t i = 0; i < rx.n; ++i) {
                            const float* p = row + size_t(rx.first + int(i)) * size_t(nc);
                            for (int c = 0; c < nc; ++c) {
                                const float v = p[c];
                                float &l = lo[size_t(c)], &h = hi[size_t(c)];
                                if (std::isnan(v)) {  // a NaN in the block sticks
                                    l = h = v;
                                } else if (!std::isnan(l)) {
                                    l = std::min(l, v);
                                    h = std::max(h, v);
                                }
                            }
                            if (any_nearest) {
                                const float z = p[depth_channel];
                                if (!std::isnan(z) && (!nearest || z < nearest_z)) {
                                    nearest   = p;
                                    nearest_z = z;
                                }
                            }
                        }
                    }
                    for (int c = 0; c < nc; ++c) {
                        switch (reducers[size_t(c)]) {
                        case Reducer::Mean: break;
                        case Reducer::Min: o[c] = lo[size_t(c)]; break;
                        case Reducer::Max: o[c] = hi[size_t(c)]; break;
                        case Reducer::NearestDepth: o[c] = nearest ? nearest[c] : nan; break;
                        }
                    }
                }
            }
        });
    }
    return true;
}


// --- ImageBuf ---------------------------------------------------------------------------

namespace {





// Pixels [begin, end) scaled by k about 0: the pixels the scaled interval touches.
std::pair<int, int> scaled(int begin, int end, double k)
{
    constexpr double eps = 1e-9;
    return { int(std::floor(begin * k + eps)), int(std::ceil(end * k - eps)) };
}

// Windows of an image mapped to a new display size (resize's mapping). The display
// origin scales with the size; the data window is the pixels its image touches.
void mapped_windows(const OIIO::ImageSpec& s, int width, int height, OIIO::ROI& data,
                    OIIO::ROI& full, AxisMap& mx, AxisMap& my)
{
    const double kx = double(width) / s.full_width, ky = double(height) / s.full_height;
    const int fx = int(std::lround(s.full_x * kx)), fy = int(std::lround(s.full_y * ky));
    full = OIIO::ROI(fx, fx + width, fy, fy + height, 0, 1, 0, s.nchannels);
    const auto [x0, x1] = scaled(s.x - s.full_x, s.x + s.width - s.full_x, kx);
    const auto [y0, y1] = scaled(s.y - s.full_y, s.y + s.height - s.full_y, ky);
    data = OIIO::ROI(fx + x0, fx + x1, fy + y0, fy + y1, 0, 1, 0, s.nchannels);
    mx   = { double(s.full_width), double(width), double(data.xbegin - fx), double(s.x - s.full_x) };
    my   = { double(s.full_height), double(height), double(data.ybegin - fy), double(s.y - s.full_y) };
}

std::vector<Reducer> reducers_for(const OIIO::ImageSpec& spec, const ReduceOptions& o, int& zc)
{
    const ChannelMap ch = find_channels(spec);
    zc = o.depth_channel >= 0 ? o.depth_channel : ch.z;
    if (!o.channels.empty())
        return o.channels;
    std::vector<Reducer> r(size_t(spec.nchannels), o.colour);
    for (int c = 0; c < spec.nchannels; ++c) {
        const std::string& name = spec.channel_name(c);
        if (c == ch.z || name == "ZBack" || OIIO::Strutil::ends_with(name, ".ZBack"))
            r[size_t(c)] = o.depth;
    }
    return r;
}

bool reduce_common(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const ReduceOptions& opts,
                   const char* what, int nthreads,
                   const std::function<void(const OIIO::ImageSpec&, OIIO::ROI&, OIIO::ROI&, AxisMap&,
                                            AxisMap&)>& geometry)
{
    if (!check_image(dst, src, what))
        return false;
    int zc = -1;
    const std::vector<Reducer> reducers = reducers_for(src.spec(), opts, zc);
    if (int(reducers.size()) != src.nchannels()) {
        dst.errorfmt("{}: {} reducers given for {} channels", what, reducers.size(), src.nchannels());
        return false;
    }
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = contiguous_float(src, holder);
    OIIO::ROI data, full;
    AxisMap mx, my;
    geometry(in.spec(), data, full, mx, my);
    const OIIO::ImageSpec like = in.spec();
    const PlaneView out        = make_output(dst, like, data, full);
    std::string err;
    if (!reduce_plane(view_of(in), out, mx, my, reducers, zc, opts.outside_is_black, err, nthreads)) {
        dst.reset();
        dst.errorfmt("{}: {}", what, err);
        return false;
    }
    return true;
}

bool resample_common(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const ResampleOptions& opts,
                     bool prefilter, const char* what, int nthreads,
                     const std::function<void(const OIIO::ImageSpec&, OIIO::ROI&, OIIO::ROI&,
                                              AxisMap&, AxisMap&)>& geometry)
{
    if (!check_image(dst, src, what))
        return false;
    std::string err;
    if (!check_options(opts, err)) {
        dst.errorfmt("{}: {}", what, err);
        return false;
    }
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = contiguous_float(src, holder);
    OIIO::ROI data, full;
    AxisMap mx, my;
    geometry(in.spec(), data, full, mx, my);
    if (data.width() <= 0 || data.height() <= 0) {
        dst.errorfmt("{}: the result would be empty", what);
        return false;
    }
    // Build the weights first so that a refused filter leaves dst untouched.
    AxisTaps wx, wy;
    if (!axis_taps(wx, in.spec().width, data.width(), mx, opts, prefilter, err)
        || !axis_taps(wy, in.spec().height, data.height(), my, opts, prefilter, err)) {
        dst.errorfmt("{}: {}", what, err);
        return false;
    }
    const OIIO::ImageSpec like = in.spec();
    const PlaneView out        = make_output(dst, like, data, full);
    run_axes(view_of(in), out, wx, wy, opts.clamp_negative, nthreads);
    return true;
}

bool good_size(OIIO::ImageBuf& dst, const char* what, int width, int height)
{
    if (width < 1 || height < 1 || width > (1 << 20) || height > (1 << 20)) {
        dst.errorfmt("{}: size {}x{} is outside 1..1048576", what, width, height);
        return false;
    }
    return true;
}

}  // namespace

bool reduce(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int factor, const ReduceOptions& opts,
            int nthreads)
{
    if (factor < 1 || factor > 4096) {
        dst.errorfmt("reduce: factor {} is outside 1..4096", factor);
        return false;
    }
    return reduce_common(dst, src, opts, "reduce", nthreads,
                         [&](const OIIO::ImageSpec& s, OIIO::ROI& data, OIIO::ROI& full,
                             AxisMap& mx, AxisMap& my) {
                             data = OIIO::ROI(floor_div(s.x, factor), ceil_div(s.x + s.width, factor),
                                              floor_div(s.y, factor), ceil_div(s.y + s.height, factor),
                                              0, 1, 0, s.nchannels);
                             full = OIIO::ROI(floor_div(s.full_x, factor),
                                              ceil_div(s.full_x + s.full_width, factor),
                                              floor_div(s.full_y, factor),
                                              ceil_div(s.full_y + s.full_height, factor), 0, 1, 0,
                                              s.nchannels);
                             mx = { double(factor), 1.0, double(data.xbegin), double(s.x) };
                             my = { double(factor), 1.0, double(data.ybegin), double(s.y) };
                         });
}

OIIO::ImageBuf reduce(const OIIO::ImageBuf& src, int factor, const ReduceOptions& opts, int nthreads)
{
    OIIO::ImageBuf dst;
    reduce(dst, src, factor, opts, nthreads);
    return dst;
}

bool reduce_to_size(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int width, int height,
                    const ReduceOptions& opts, int nthreads)
{
    if (!good_size(dst, "reduce", width, height))
        return false;
    return reduce_common(dst, src, opts, "reduce", nthreads,
                         [&](const OIIO::ImageSpec& s, OIIO::ROI& data, OIIO::ROI& full,
                             AxisMap& mx, AxisMap& my) {
                             mapped_windows(s, width, height, data, full, mx, my);
                         });
}

bool enlarge(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, double factor,
             const ResampleOptions& opts, int nthreads)
{
    if (!(factor >= 1.0 && factor <= 256.0)) {
        dst.errorfmt("enlarge: factor {} is outside 1..256 (to reduce, use reduce or resize)", factor);
        return false;
    }
    return resample_common(dst, src, opts, true, "enlarge", nthreads,
                           [&](const OIIO::ImageSpec& s, OIIO::ROI& data, OIIO::ROI& full,
                               AxisMap& mx, AxisMap& my) {
                               const auto [x0, x1] = scaled(s.x, s.x + s.width, factor);
                               const auto [y0, y1] = scaled(s.y, s.y + s.height, factor);
                               const auto [fx0, fx1] = scaled(s.full_x, s.full_x + s.full_width, factor);
                               const auto [fy0, fy1] = scaled(s.full_y, s.full_y + s.full_height, factor);
                               data = OIIO::ROI(x0, x1, y0, y1, 0, 1, 0, s.nchannels);
                               full = OIIO::ROI(fx0, fx1, fy0, fy1, 0, 1, 0, s.nchannels);
                               mx   = AxisMap::factor(factor, x0, s.x);
                               my   = AxisMap::factor(factor, y0, s.y);
                           });
}

OIIO::ImageBuf enlarge(const OIIO::ImageBuf& src, double factor, const ResampleOptions& opts,
                       int nthreads)
{
    OIIO::ImageBuf dst;
    enlarge(dst, src, factor, opts, nthreads);
    return dst;
}

bool resize(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int width, int height,
            const ResampleOptions& opts, int nthreads)
{
    if (!good_size(dst, "resize", width, height))
        return false;
    return resample_common(dst, src, opts, true, "resize", nthreads,
                           [&](const OIIO::ImageSpec& s, OIIO::ROI& data, OIIO::ROI& full,
                               AxisMap& mx, AxisMap& my) {
                               mapped_windows(s, width, height, data, full, mx, my);
                           });
}

bool resample(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int width, int height,
              bool interpolate, int nthreads)
{
    if (!good_size(dst, "resample", width, height))
        return false;
    ResampleOptions o;
    o.filter = interpolate ? ResampleFilter::Bilinear : ResampleFilter::Nearest;
    return resample_common(dst, src, o, false, "resample", nthreads,
                           [&](const OIIO::ImageSpec& s, OIIO::ROI& data, OIIO::ROI& full,
                               AxisMap& mx, AxisMap& my) {
                               mapped_windows(s, width, height, data, full, mx, my);
                           });
}


}  // namespace bokeh
