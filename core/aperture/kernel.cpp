// kernel.cpp — exact weights of the uniform kernels.
//
// Box: a rectangle of real width w over pixel squares; pixel i (offset from the centre)
// gets the length of [i - 1/2, i + 1/2] inside [-w/2, w/2], over w. Gaussian: the normal
// density integrated over each pixel (erf differences), out to 4 sigma, renormalised.
// Disk and polygon: the area of each pixel square inside the shape (anti-aliased) or the
// pixel-centre test (hard; OIIO's make_kernel("disk") is `(x/(w/2))^2 + (y/(h/2))^2 < 1`).
// Hard-edged box and Gaussian are OIIO's make_kernel("box" | "gaussian", w, h) (its filters'
// documented formulas, Filter2D in OIIO's filter.h): the filter's value at whole offsets,
// normalised; box 1 where |x| <= w/2 (an 8 px box is 9 equal taps), Gaussian
// exp(-2 (2x/w)^2) where |2x/w| < 1, i.e. sigma = w/4 cut at 2 sigma (8.9 % of a 2-D
// Gaussian's mass lies past it), so `--blur:edge=hard` gives oiiotool's kernels.
// Filter (oiiotool's other --blur kernels: triangle, bspline, lanczos3, ...): OIIO's own
// make_kernel is called, not reimplemented, so its weights are oiiotool's by construction;
// only their normalisation is redone in double. A separable one runs from its factors,
// make_kernel(name, w, 1)'s row and make_kernel(name, 1, h)'s column (its 2-D kernel is
// their product), so its N^2 kernel is made only where the brute force or the FFT asks.
// Disk, polygon and any other opening: the Aperture's inside test (core/aperture/
// aperture.cpp: a polygon's edge cos(pi/N) / cos(phi) from an edge's normal, curved blades
// blended toward the circle, a catadioptric hole of `hole * d`) at the kernel's half sizes.
// The area: a look at each pixel (5 x 5 points inside, 32 on its border), then 64 x 64
// stratified samples where it is mixed.
// Changed for speed (same samples, same bits): without a hole a disk or polygon is convex,
// so a pixel with four corners inside is inside and a boundary pixel's fine samples are
// counted by runs per sample row; pixels off the ellipse that bounds every shape are
// outside.

#include <bokeh/base.h>
#include <bokeh/aperture.h>
#include <bokeh/parallel.h>

#include "aperture/weights.h"
#include "base/plane.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include <OpenImageIO/filter.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;


namespace {

// make_kernel's binomial has ceil(W) weights for a ceil(W) | 1 wide window (past them, at
// even or fractional sizes, it reads memory it never wrote), and they sum to 2^(W - 1) in
// float (infinite past 128).
bool binomial_size(float v) { return v == 0.0f || (v == std::floor(v) && int(v) % 2 == 1 && v <= 127.0f); }

// OIIO's make_kernel(name, w, h) (a side of 0 is one pixel) in double, normalised, or none
// where it has no positive finite sum (check_kernel() names the cause).
std::optional<KernelWeights> oiio_kernel(const std::string& name, float w, float h)
{
    if (name == "binomial" && !(binomial_size(w) && binomial_size(h)))
        return std::nullopt;
    const OIIO::ImageBuf K = OIIO::ImageBufAlgo::make_kernel(name, std::max(w, 1.0f), std::max(h, 1.0f));
    const OIIO::ROI r      = K.roi();
    if (K.has_error() || r.xbegin != -(r.width() / 2) || r.ybegin != -(r.height() / 2))
        return std::nullopt;
    KernelWeights kw;
    kw.rx = r.width() / 2;
    kw.ry = r.height() / 2;
    kw.w.reserve(r.npixels());
    double sum = 0.0;
    for (OIIO::ImageBuf::ConstIterator<float> it(K); !it.done(); ++it) {
        kw.w.push_back(double(it[0]));
        sum += kw.w.back();
    }
    if (!(sum > 0.0) || !std::isfinite(sum))
        return std::nullopt;
    for (double& v : kw.w)
        v /= sum;
    return kw;
}

// Zero weights at both ends, dropped in pairs (the kernel stays centred).
std::vector<double> trimmed_1d(std::vector<double> w)
{
    while (w.size() > 1 && w.front() == 0.0 && w.back() == 0.0) {
        w.pop_back();
        w.erase(w.begin());
    }
    return w;
}

// A separable Filter's factors: make_kernel(name, w, 1)'s row and make_kernel(name, 1, h)'s
// column (its 2-D kernel is their product, in float), without the N^2 kernel.
std::optional<std::pair<std::vector<double>, std::vector<double>>> filter_factors(const Kernel& k)
{
    const std::optional<KernelWeights> row = oiio_kernel(k.filter, k.width_px, 1.0f);
    const std::optional<KernelWeights> col = oiio_kernel(k.filter, 1.0f, k.height_px);
    if (!row || !col)
        return std::nullopt;
    return std::pair{ trimmed_1d(row->w), trimmed_1d(col->w) };
}

}  // namespace

bool check_aperture(const Kernel& aperture, float aspect, std::string& err)
{
    Kernel k    = aperture;
    k.width_px  = 1.0f;
    k.height_px = 1.0f;
    if (!check_kernel(k, err))
        return false;
    if (!(aspect >= kMinAspect && aspect <= kMaxAspect)) {
        err = format("aspect {} is outside {}..{}", aspect, kMinAspect, kMaxAspect);
        return false;
    }
    return true;
}

Kernel point_reflected(const Kernel& k)
{
    Kernel r = k;
    if (k.shape == KernelShape::Opening)
        r.opening = k.opening.point_reflected();
    else
        r.rotation_deg += 180.0f;  // a polygon's; a disk, box, Gaussian or filter has none to turn
    return r;
}

bool check_kernel(const Kernel& k, std::string& err)
{
    auto bad_size = [](float v) { return !std::isfinite(v) || v < 0.0f || v > 4096.0f; };
    if (bad_size(k.width_px) || bad_size(k.height_px)) {
        err = format("kernel size {}x{} is outside 0..4096 pixels", k.width_px, k.height_px);
        return false;
    }
    if (!std::isfinite(k.sigma_px) || k.sigma_px < 0.0f || k.sigma_px > 1024.0f) {
        err = format("sigma {} is outside 0..1024 pixels", k.sigma_px);
        return false;
    }
    if (k.blades < 3 || k.blades > 64) {
        err = format("blades {} is outside 3..64", k.blades);
        return false;
    }
    if (!std::isfinite(k.rotation_deg) || !std::isfinite(k.curvature) || k.curvature < 0.0f
        || k.curvature > 1.0f) {
        err = format("curvature {} is outside 0..1", k.curvature);
        return false;
    }
    if (!std::isfinite(k.hole) || k.hole < 0.0f || k.hole >= 1.0f) {
        err = format("hole {} is outside 0..<1", k.hole);
        return false;
    }
    if (k.shape == KernelShape::Filter) {
        const std::vector<std::string> names = oiio_filter_names();
        if (std::find(names.begin(), names.end(), k.filter) == names.end()) {
            err = format("'{}' is not one of OIIO's filters ({})", k.filter, OIIO::Strutil::join(names, ", "));
            return false;
        }
        if (k.filter == "sinc") {
            err = "OIIO's sinc is not scaled to the kernel's size: 0 at every whole offset, so the identity "
                  "(up to rounding) at any size; lanczos3 is the windowed sinc that blurs";
            return false;
        }
        if (k.filter == "binomial" && (!binomial_size(k.width_px) || !binomial_size(k.height_px))) {
            err = format("binomial takes odd whole sizes up to 127 px, not {}x{} (OIIO's make_kernel reads weights it "
                         "never wrote at even or fractional sizes; past 127 its weights overflow float)",
                         k.width_px, k.height_px);
            return false;
        }
        if (is_separable(k) ? !filter_factors(k) : !oiio_kernel(k.filter, k.width_px, k.height_px)) {
            err = format("filter {} at {}x{} has no positive finite sum of weights to normalise", k.filter, k.width_px,
                         k.height_px);
            return false;
        }
    }
    return true;
}

std::vector<std::string> oiio_filter_names()
{
    std::vector<std::string> names;
    for (int i = 0; i < OIIO::Filter2D::num_filters(); ++i) {
        const OIIO::FilterDesc& d = OIIO::Filter2D::get_filterdesc(i);
        const std::string name    = d.name;
        if (name != "box" && name != "gaussian" && name != "disk")
            names.push_back(name);
    }
    names.push_back("binomial");
    return names;
}

bool is_separable(const Kernel& k)
{
    if (k.shape == KernelShape::Box || k.shape == KernelShape::Gaussian)
        return true;
    if (k.shape != KernelShape::Filter)
        return false;
    if (k.filter == "binomial")
        return true;
    std::unique_ptr<OIIO::Filter2D, void (*)(OIIO::Filter2D*)> f(
        OIIO::Filter2D::create(k.filter, std::max(k.width_px, 1.0f), std::max(k.height_px, 1.0f)),
        OIIO::Filter2D::destroy);
    return f && f->separable();
}

std::pair<double, double> gaussian_sigma(const Kernel& k)
{
    if (k.sigma_px > 0.0f)
        return { k.sigma_px, k.sigma_px };
    return { 0.25 * k.width_px, 0.25 * k.height_px };
}

std::vector<double> box_weights_1d(double width)
{
    if (!(width > 1.0))
        return { 1.0 };
    const double h = 0.5 * width;
    const int full = int(std::floor(h - 0.5));           // pixels wholly inside, each side
    const double f = h - (full + 0.5);                    // overlap of the next pixel out
    const int r    = f > 1e-12 ? full + 1 : full;
    std::vector<double> w(size_t(2 * r + 1), 1.0 / width);
    if (r > full)
        w.front() = w.back() = f / width;
    return w;
}

std::vector<double> gaussian_weights_1d(double sigma)
{
    if (!(sigma > 0.0))
        return { 1.0 };
    const int r = std::max(1, int(std::ceil(4.0 * sigma)));
    std::vector<double> w(size_t(2 * r + 1));
    const double k = 1.0 / (sigma * std::sqrt(2.0));
    double sum     = 0.0;
    for (int i = -r; i <= r; ++i) {
        w[size_t(i + r)] = 0.5 * (std::erf((i + 0.5) * k) - std::erf((i - 0.5) * k));
        sum += w[size_t(i + r)];
    }
    for (double& v : w)
        v /= sum;
    return w;
}

namespace {

// Samples of a filter at whole offsets |i| within `reach` (inclusive or not), normalised.
template<class Fn>
std::vector<double> sampled_1d(double reach, bool inclusive, Fn&& value)
{
    const int r = std::max(0, int(std::floor(reach)) - (!inclusive && std::floor(reach) == reach ? 1 : 0));
    std::vector<double> w(size_t(2 * r + 1));
    double sum = 0.0;
    for (int i = -r; i <= r; ++i)
        sum += w[size_t(i + r)] = value(double(i));
    for (double& v : w)
        v /= sum;
    return w;
}

}  // namespace

std::pair<std::vector<double>, std::vector<double>> separable_weights(const Kernel& k)
{
    const bool hard = k.edge == KernelEdge::Hard;
    if (k.shape == KernelShape::Box) {
        auto box = [&](double width) {
            return hard ? sampled_1d(0.5 * std::max(0.0, width), true, [](double) { return 1.0; })
                        : box_weights_1d(width);
        };
        return { box(k.width_px), box(k.height_px) };
    }
    if (k.shape == KernelShape::Gaussian) {
        const auto [sx, sy] = gaussian_sigma(k);
        auto gauss = [&](double sigma, double footprint) {
            if (!hard || !(sigma > 0.0))
                return gaussian_weights_1d(sigma);
            const double reach = 0.5 * (footprint > 0.0 ? footprint : 4.0 * sigma);
            return sampled_1d(reach, false, [&](double x) { return std::exp(-x * x / (2.0 * sigma * sigma)); });
        };
        return { gauss(sx, k.width_px), gauss(sy, k.height_px) };
    }
    if (is_separable(k)) {  // a Filter (check_kernel() has seen its factors made)
        if (const auto f = filter_factors(k))
            return *f;
    }
    return { { 1.0 }, { 1.0 } };
}

KernelWeights detail::outer(const std::vector<double>& wx, const std::vector<double>& wy)
{
    KernelWeights kw;
    kw.rx = int(wx.size() / 2);
    kw.ry = int(wy.size() / 2);
    kw.w.reserve(wx.size() * wy.size());
    for (double y : wy)
        for (double x : wx)
            kw.w.push_back(x * y);
    return kw;
}

namespace {

// Drop all-zero outer rows and columns (symmetrically), so a kernel that covers one
// pixel becomes the identity and the brute-force reference does no wasted work.
KernelWeights trimmed(const KernelWeights& kw)
{
    int rx = 0, ry = 0;
    for (int dy = -kw.ry; dy <= kw.ry; ++dy)
        for (int dx = -kw.rx; dx <= kw.rx; ++dx)
            if (kw.at(dx, dy) != 0.0) {
                rx = std::max(rx, std::abs(dx));
                ry = std::max(ry, std::abs(dy));
            }
    KernelWeights t;
    t.rx = rx;
    t.ry = ry;
    for (int dy = -ry; dy <= ry; ++dy)
        for (int dx = -rx; dx <= rx; ++dx)
            t.w.push_back(kw.at(dx, dy));
    return t;
}

// Inside test of an aperture kernel (disk, polygon, opening) in kernel pixel coordinates
// (y down): the Aperture's, at the kernel's half sizes.
struct Shape {
    Aperture aperture;
    double ax, ay;  // half sizes

    explicit Shape(const Kernel& kernel)
        : ax(0.5 * kernel.width_px)
        , ay(0.5 * kernel.height_px)
    {
        std::string err;
        Aperture::from_kernel(kernel, aperture, err);  // kernel_weights takes valid kernels
    }
    bool inside(double x, double y) const { return aperture.inside(x / ax, -y / ay); }
};

// How many of the fine x fine samples of pixel (dx, dy) are inside a convex shape. Each
// sample row's inside samples are one run (convexity), so a row starts from the middle of
// the run above and walks its ends out or in, instead of testing all its samples; a row
// with no run after one with a run ends the count (the inside rows are consecutive too).
// The same samples are tested at the run ends as a full count would, so the count is the
// same.
int convex_fine_count(const Shape& shape, int dx, int dy, int fine)
{
    int n = 0, lo = -1, hi = -1;  // the previous row's run [lo, hi], or none
    for (int j = 0; j < fine; ++j) {
        const double y = dy - 0.5 + (j + 0.5) / fine;
        auto in = [&](int i) { return shape.inside(dx - 0.5 + (i + 0.5) / fine, y); };
        int seed = -1;
        if (lo >= 0 && in((lo + hi) / 2))
            seed = (lo + hi) / 2;
        for (int i = 0; seed < 0 && i < fine; ++i)
            if (in(i))
                seed = i;
        if (seed < 0) {
            if (lo >= 0)
                break;  // below the last run: nothing more
            continue;
        }
        lo = hi = seed;
        while (lo > 0 && in(lo - 1))
            --lo;
        while (hi + 1 < fine && in(hi + 1))
            ++hi;
        n += hi - lo + 1;
    }
    return n;
}

KernelWeights shape_weights(const Kernel& k, int nthreads)
{
    const Shape shape(k);
    KernelWeights kw;
    kw.rx = int(std::floor(shape.ax + 0.5));
    kw.ry = int(std::floor(shape.ay + 0.5));
    const int nx = 2 * kw.rx + 1, ny = 2 * kw.ry + 1;
    kw.w.assign(size_t(nx) * size_t(ny), 0.0);
    constexpr int coarse = 5, fine = 64;
    // Without a hole a disk or a polygon (its sides bulge towards the circle) is convex: a
    // pixel whose four corners are inside is inside, which the 5 x 5 look below would also
    // find, so the corners (shared by neighbours) are tested once each.
    const bool convex = shape.aperture.convex() && shape.aperture.hole() == 0.0 && k.edge != KernelEdge::Hard;
    std::vector<char> corner;
    if (convex) {
        corner.resize(size_t(nx + 1) * size_t(ny + 1));
        parallel_for_chunks(0, ny + 1, 8, nthreads, [&](int64_t j0, int64_t j1) {
            for (int j = int(j0); j < int(j1); ++j)
                for (int i = 0; i <= nx; ++i)
                    corner[size_t(j) * size_t(nx + 1) + size_t(i)] =
                        shape.inside(i - kw.rx - 0.5, j - kw.ry - 0.5);
        });
    }
    auto corners_inside = [&](int dx, int dy) {
        const size_t i = size_t(dx + kw.rx), j = size_t(dy + kw.ry), s = size_t(nx + 1);
        return corner[j * s + i] && corner[j * s + i + 1] && corner[(j + 1) * s + i]
               && corner[(j + 1) * s + i + 1];
    };
    // Every shape lies inside its ellipse (an Aperture's edge is at most 1): a pixel whose
    // nearest point is not inside it has no sample inside the shape.
    auto outside_ellipse = [&](int dx, int dy) {
        const double x = std::clamp(0.0, dx - 0.5, dx + 0.5) / shape.ax;
        const double y = std::clamp(0.0, dy - 0.5, dy + 0.5) / shape.ay;
        return x * x + y * y >= 1.0;
    };
    // Rows in parallel (a polygon's boundary pixels cost thousands of inside tests each);
    // the sum after them, in one order.
    parallel_for_chunks(-kw.ry, kw.ry + 1, 4, nthreads, [&](int64_t y0, int64_t y1) {
    for (int dy = int(y0); dy < int(y1); ++dy)
        for (int dx = -kw.rx; dx <= kw.rx; ++dx) {
            double w;
            if (k.edge == KernelEdge::Hard) {
                w = shape.inside(dx, dy) ? 1.0 : 0.0;
            } else if (convex && corners_inside(dx, dy)) {
                w = 1.0;
            } else if (outside_ellipse(dx, dy)) {
                w = 0.0;
            } else {
                // A coarse look first; only pixels the boundary crosses get the fine grid.
                // The look takes 5 x 5 points inside the pixel and 32 on its border (the
                // corners among them, 1/8 apart): points inside alone missed a rim pixel's
                // clipped corner (the 31 px disk's pixel (15, 1) is 0.965 inside with all
                // 25 inner points in) and a polygon's tip poking into a pixel (0.08 of one;
                // tests/aperture/kernel_area_test.cpp). A unanimous look now leaves at most a
                // boundary crossing the border between two points 1/8 apart: a sliver under
                // 1/128 of the pixel.
                int in = 0, looked = 0;
                auto look = [&](double x, double y) {
                    in += shape.inside(x, y);
                    ++looked;
                };
                for (int j = 0; j < coarse; ++j)
                    for (int i = 0; i < coarse; ++i)
                        look(dx - 0.5 + (i + 0.5) / coarse, dy - 0.5 + (j + 0.5) / coarse);
                for (int s = 0; s < 8; ++s) {
                    const double t = -0.5 + s / 8.0;
                    look(dx + t, dy - 0.5);
                    look(dx + 0.5, dy + t);
                    look(dx - t, dy + 0.5);
                    look(dx - 0.5, dy - t);
                }
                if (in == 0 || in == looked) {
                    w = in ? 1.0 : 0.0;
                } else if (convex) {
                    w = double(convex_fine_count(shape, dx, dy, fine)) / (fine * fine);
                } else {
                    int n = 0;
                    for (int j = 0; j < fine; ++j)
                        for (int i = 0; i < fine; ++i)
                            n += shape.inside(dx - 0.5 + (i + 0.5) / fine, dy - 0.5 + (j + 0.5) / fine);
                    w = double(n) / (fine * fine);
                }
            }
            kw.w[size_t((dy + kw.ry) * nx + (dx + kw.rx))] = w;
        }
    });
    double sum = 0.0;
    for (double w : kw.w)
        sum += w;
    if (sum <= 0.0)  // smaller than any pixel centre (hard edge): the identity
        return KernelWeights{ 0, 0, { 1.0 } };
    for (double& v : kw.w)
        v /= sum;
    return trimmed(kw);
}

// A Filter's weights: its factors' product where it is separable (no N^2 make_kernel),
// else OIIO's whole kernel; check_kernel() has seen them made.
KernelWeights filter_weights(const Kernel& k)
{
    if (is_separable(k)) {
        const auto [wx, wy] = separable_weights(k);
        return detail::outer(wx, wy);
    }
    const std::optional<KernelWeights> kw = oiio_kernel(k.filter, k.width_px, k.height_px);
    return kw ? trimmed(*kw) : KernelWeights{ 0, 0, { 1.0 } };
}

}  // namespace

KernelWeights kernel_weights(const Kernel& k, int nthreads)
{
    if (k.width_px <= 0.0f && k.height_px <= 0.0f && k.sigma_px <= 0.0f)
        return KernelWeights{ 0, 0, { 1.0 } };
    switch (k.shape) {
    case KernelShape::Box:
    case KernelShape::Gaussian: {
        const auto [wx, wy] = separable_weights(k);
        return detail::outer(wx, wy);
    }
    case KernelShape::Disk:
    case KernelShape::Polygon:
    case KernelShape::Opening:
        if (k.width_px <= 0.0f || k.height_px <= 0.0f)
            return KernelWeights{ 0, 0, { 1.0 } };
        return shape_weights(k, nthreads);
    case KernelShape::Filter: return filter_weights(k);
    }
    return KernelWeights{ 0, 0, { 1.0 } };
}

}  // namespace bokeh
