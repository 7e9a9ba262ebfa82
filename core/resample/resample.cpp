// resample.cpp — reduction and enlargement (resample.h): the filter names, the plane and
// image functions. The weights of an axis are built in resample_taps.cpp and run by the
// separable pass of resample_pass.cpp; the depth-aware enlargement is in
// resample_depth_aware.cpp.
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
#include "resample/resample_taps.h"

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
using detail::AxisTaps;
using detail::TapMatrix;
using detail::TapRow;
using detail::Taps;
using detail::axis_taps;
using detail::box_taps;
using detail::run_axes;
using detail::separable_pass;
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

bool check_resample_options(const ResampleOptions& o, std::string& err)
{
    auto bad = [](float v) { return !std::isfinite(v) || v < 0.0f || v > 64.0f; };
    if (bad(o.gaussian_sigma) || bad(o.blur_sigma) || bad(o.fused_offset)) {
        err = format("gaussian_sigma {}, blur_sigma {} and fused_offset {} must be within 0..64",
                     o.gaussian_sigma, o.blur_sigma, o.fused_offset);
        return false;
    }
    return true;
}

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
        || !check_resample_options(opts, err))
        return false;
    AxisTaps wx, wy;
    if (!axis_taps(wx, src.width, dst.width, mx, opts, prefilter, err)
        || !axis_taps(wy, src.height, dst.height, my, opts, prefilter, err))
        return false;
    run_axes(src, dst, wx, wy, opts.clamp_negative, nthreads);
    return true;
}

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
    const int n_mean      = int(std::count(reducers.begin(), reducers.end(), Reducer::Mean));
    const int n_data_mean = int(std::count(reducers.begin(), reducers.end(), Reducer::MeanOverData));
    const bool any_mean   = n_mean + n_data_mean > 0;
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
    if (n_data_mean > 0 && outside_is_black) {
        // The depth's mean over the pixels inside: the black taps are the inside taps times
        // the footprint's share inside the source (box_row), separably, so divide by the
        // product of the two rows' sums (1 away from the edges; 0: nothing inside, left 0).
        auto row_sums = [](const TapMatrix& m) {
            std::vector<double> sums(m.size(), 0.0);
            for (size_t i = 0; i < m.size(); ++i) {
                const TapRow r = m[i];
                for (size_t k = 0; k < r.n; ++k)
                    sums[i] += r.w[k];
            }
            return sums;
        };
        const std::vector<double> sx = row_sums(wx), sy = row_sums(wy);
        parallel_for_chunks(0, dst.height, 8, nthreads, [&](int64_t y0, int64_t y1) {
            for (int y = int(y0); y < int(y1); ++y)
                for (int x = 0; x < dst.width; ++x) {
                    const double inside = sx[size_t(x)] * sy[size_t(y)];
                    if (inside == 1.0 || inside == 0.0)
                        continue;
                    float* o = dst.row(y) + size_t(x) * size_t(nc);
                    for (int c = 0; c < nc; ++c)
                        if (reducers[size_t(c)] == Reducer::MeanOverData)
                            o[c] = float(o[c] / inside);
                }
        });
    }
    if (n_mean + n_data_mean < nc) {
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
                            if (reducers[size_t(c)] != Reducer::Mean && reducers[size_t(c)] != Reducer::MeanOverData)
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
                        case Reducer::Mean:
                        case Reducer::MeanOverData: break;
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
            r[size_t(c)] = o.depth == Reducer::Mean ? Reducer::MeanOverData : o.depth;
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
    if (!check_resample_options(opts, err)) {
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
