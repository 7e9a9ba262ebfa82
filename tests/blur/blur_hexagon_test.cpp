// The hexagon from three parallelograms (BlurMethod::Parallelograms; core/blur/
// blur_hexagon*.cpp) against its definition written out plainly, its reach, its distance
// from the exact hexagon, and its equivariance.
#include <bokeh/blur.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>

#include "blur_fixtures.h"
#include "test_util.h"

using namespace bokeh;
using namespace blur_test;

namespace {

// The response to a unit pixel in the middle of an image large enough to hold it.
KernelWeights point_response(const Kernel& k, const BlurOptions& o, int r)
{
    OIIO::ImageBuf src(OIIO::ImageSpec(2 * r + 1, 2 * r + 1, 1, OIIO::TypeFloat));
    const float one = 1.0f;
    src.setpixel(r, r, &one);
    OIIO::ImageBuf out;
    EXPECT_TRUE(blur(out, src, k, o)) << out.geterror();
    KernelWeights kw{ r, r, {} };
    for (int y = 0; y <= 2 * r; ++y)
        for (int x = 0; x <= 2 * r; ++x) {
            float v = 0.0f;
            out.getpixel(x, y, &v);
            kw.w.push_back(v);
        }
    return kw;
}

}  // namespace

// The parallelogram method written out plainly from its definition in blur_hexagon*.cpp,
// in double, each segment pass a full sum over its rows: the reference the fused sweep
// and the four passes must both equal.
namespace parallelogram_reference {

// A plane in the method's working frame: w x h pixels of nc channels, zero outside.
struct Plane {
    int w, h, nc;
    std::vector<double> v;
    Plane(int w_, int h_, int nc_) : w(w_), h(h_), nc(nc_), v(size_t(w_) * h_ * nc_, 0.0) {}
    double at(int x, int y, int c) const
    {
        return x < 0 || y < 0 || x >= w || y >= h ? 0.0 : v[(size_t(y) * w + x) * nc + c];
    }
    double& ref(int x, int y, int c) { return v[(size_t(y) * w + x) * nc + c]; }
};

Plane transposed(const Plane& p)
{
    Plane t(p.h, p.w, p.nc);
    for (int y = 0; y < p.h; ++y)
        for (int x = 0; x < p.w; ++x)
            for (int c = 0; c < p.nc; ++c)
                t.ref(y, x, c) = p.at(x, y, c);
    return t;
}

// Pixel i's share of the interval [a, b] (b > a): the overlap of [i - 1/2, i + 1/2].
double share(int i, double a, double b)
{
    return std::max(0.0, std::min(b, i + 0.5) - std::max(a, i - 0.5)) / (b - a);
}

// The quadratic B-spline read at real position p: taps at first, first + 1, first + 2.
struct Taps {
    int first;
    double w[3];
    explicit Taps(double p)
    {
        const double n = std::floor(p + 0.5), d = p - n;
        first = int(n) - 1;
        w[0] = 0.5 * (0.5 - d) * (0.5 - d);
        w[1] = 0.75 - d * d;
        w[2] = 0.5 * (0.5 + d) * (0.5 + d);
    }
};

// out(p) = mean over t in [0, 1] of q(p - t e), as the method computes it.
Plane segment(const Plane& q, double ex, double ey)
{
    const double lo_y = std::min(0.0, ey), hi_y = std::max(0.0, ey);
    if (std::abs(ey) < 1e-9 * std::abs(ex)) {  // along the rows
        const double lo = std::min(0.0, ex), hi = std::max(0.0, ex);
        Plane out(q.w, q.h, q.nc);
        for (int y = 0; y < q.h; ++y)
            for (int x = 0; x < q.w; ++x)
                for (int i = int(std::floor(lo)) - 1; i <= int(std::ceil(hi)) + 1; ++i)
                    for (int c = 0; c < q.nc; ++c)
                        out.ref(x, y, c) += share(i, lo, hi) * q.at(x - i, y, c);
        return out;
    }
    if (std::abs(ey) < std::abs(ex))  // flat: the steep case on the transposed plane
        return transposed(segment(transposed(q), ey, ex));
    const bool shear = std::abs(ex) >= 1e-9 * std::abs(ey);
    const double m   = shear ? ex / ey : 0.0;
    // G(u, r) = q(u + m r, r) through the taps; out(x, y) = sum_i share_i G(x - m y ... )
    auto g = [&](int u, int r, int c) {
        if (!shear)
            return q.at(u, r, c);
        const Taps t(m * r);
        double s = 0.0;
        for (int j = 0; j < 3; ++j)
            s += t.w[j] * q.at(u + t.first + j, r, c);
        return s;
    };
    auto h = [&](int u, int y, int c) {
        double s = 0.0;
        for (int i = int(std::floor(lo_y)) - 1; i <= int(std::ceil(hi_y)) + 1; ++i)
            s += share(i, lo_y, hi_y) * g(u, y - i, c);
        return s;
    };
    Plane out(q.w, q.h, q.nc);
    for (int y = 0; y < q.h; ++y)
        for (int x = 0; x < q.w; ++x)
            for (int c = 0; c < q.nc; ++c) {
                if (!shear) {
                    out.ref(x, y, c) = h(x, y, c);
                    continue;
                }
                const Taps t(-m * y);
                for (int j = 0; j < 3; ++j)
                    out.ref(x, y, c) += t.w[j] * h(x + t.first + j, y, c);
            }
    return out;
}

Plane add(Plane a, const Plane& b)
{
    for (size_t i = 0; i < a.v.size(); ++i)
        a.v[i] += b.v[i];
    return a;
}

// Coordinate i of [begin, end) under the border rule (blur.h); kBlack: outside, black.
constexpr int kBlack = std::numeric_limits<int>::min();

int border_coordinate(int i, int begin, int end, Border b)
{
    if (i >= begin && i < end)
        return i;
    const int n = end - begin;
    if (b == Border::Clamp)
        return std::clamp(i, begin, end - 1);
    if (b == Border::Mirror) {
        const int t = ((i - begin) % (2 * n) + 2 * n) % (2 * n);
        return begin + (t < n ? t : 2 * n - 1 - t);
    }
    return kBlack;
}

// The kernel's vertices as kernel.cpp places them (y down; its segments P0, P2, P4), the
// passes' reach along x and y (interpolation included) and the output window: the data
// window of `src`, grown by the reach with `grow`.
struct Geometry {
    double vx[6], vy[6];
    int rx = 0, ry = 0;
    OIIO::ROI roi;
};

Geometry geometry(const OIIO::ImageBuf& src, const Kernel& k, bool grow)
{
    Geometry g;
    for (int i = 0; i < 6; ++i) {
        const double th = M_PI * (90.0 + k.rotation_deg + 60.0 * i) / 180.0;
        g.vx[i] = 0.5 * k.width_px * std::cos(th);
        g.vy[i] = -0.5 * k.height_px * std::sin(th);
        // + 6: a rhombus' two steep segments each spread by two shears' taps (< 3 px).
        g.rx    = std::max(g.rx, int(std::ceil(std::abs(g.vx[i]))) + 6);
        g.ry    = std::max(g.ry, int(std::ceil(std::abs(g.vy[i]))) + 6);
    }
    g.roi = src.roi();
    if (grow) {
        g.roi.xbegin -= g.rx;
        g.roi.xend += g.rx;
        g.roi.ybegin -= g.ry;
        g.roi.yend += g.ry;
    }
    return g;
}

// An image over `roi` with src's channels, channel c of pixel (x, y) value(x, y, c).
template<class Value>
OIIO::ImageBuf image_over(const OIIO::ImageBuf& src, const OIIO::ROI& roi, Value value)
{
    OIIO::ImageSpec spec = src.spec();
    spec.x      = roi.xbegin;
    spec.y      = roi.ybegin;
    spec.width  = roi.width();
    spec.height = roi.height();
    OIIO::ImageBuf out(spec);
    std::vector<float> v(static_cast<size_t>(spec.nchannels));
    for (int y = roi.ybegin; y < roi.yend; ++y)
        for (int x = roi.xbegin; x < roi.xend; ++x) {
            for (int ch = 0; ch < spec.nchannels; ++ch)
                v[size_t(ch)] = float(value(x, y, ch));
            out.setpixel(x, y, v.data());
        }
    return out;
}

// The hexagon of `k` over the data window of `src` (grown by the reach with `grow`), the
// outside by the border rule; with `iris`, of exp(iris x) and back by log / iris, alpha
// plain (the iris filter, as blur.h defines it).
OIIO::ImageBuf hexagon(const OIIO::ImageBuf& src, const Kernel& k, Border border, bool grow,
                       double iris = 0.0)
{
    const int alpha = src.spec().alpha_channel;
    auto exp_space  = [&](double v, int c) { return iris != 0.0 && c != alpha ? std::exp(iris * v) : v; };
    auto back       = [&](double v, int c) { return iris != 0.0 && c != alpha ? std::log(v) / iris : v; };
    const Geometry g = geometry(src, k, grow);
    const int rx = g.rx, ry = g.ry;
    struct Dir {
        double x, y;
        bool steep() const { return std::abs(y) >= std::abs(x); }
        double slope() const { return steep() ? std::abs(x / y) : 2.0; }
    };
    std::vector<Dir> d = { { g.vx[0], g.vy[0] }, { g.vx[2], g.vy[2] }, { g.vx[4], g.vy[4] } };
    // The working frame: transposed unless two segments are steep as given.
    const bool t = std::count_if(d.begin(), d.end(), [](Dir e) { return e.steep(); }) < 2;
    if (t)
        for (Dir& e : d)
            std::swap(e.x, e.y);
    std::sort(d.begin(), d.end(), [](Dir p, Dir q) { return p.slope() < q.slope(); });
    const OIIO::ROI data = src.roi(), roi = g.roi;
    const int x0 = roi.xbegin - rx, y0 = roi.ybegin - ry;
    const int w = roi.width() + 2 * rx, h = roi.height() + 2 * ry, nc = src.nchannels();
    Plane p(t ? h : w, t ? w : h, nc);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < nc; ++c) {
                const int sx = border_coordinate(x0 + x, data.xbegin, data.xend, border);
                const int sy = border_coordinate(y0 + y, data.ybegin, data.yend, border);
                const double v = sx == kBlack || sy == kBlack ? 0.0 : src.getchannel(sx, sy, 0, c);
                p.ref(t ? y : x, t ? x : y, c) = exp_space(v, c);
            }
    const Dir a = d[0], b = d[1], c = d[2];
    const Plane seg_b = segment(p, b.x, b.y);
    const Plane r = add(segment(add(segment(p, a.x, a.y), seg_b), c.x, c.y), segment(seg_b, a.x, a.y));
    return image_over(src, roi, [&](int x, int y, int ch) {
        const int px = x - x0, py = y - y0;
        return back(r.at(t ? py : px, t ? px : py, ch) / 3.0, ch);
    });
}

// The hexagon at rotations off multiples of 30 degrees (blur_hexagon_sheared.cpp): the frame (the
// source, or its transpose with `transposed`) with its columns sheared so that the
// segment nearest its rows runs along them, line r at column x reading the source at
// (x, r + m x) through the B-spline's taps, and outputs read back at (x, y - m x); x counts
// from the frame's left edge less the kernel's reach, as the method's does (the taps'
// phases). Empty where the shear does not leave the other two segments steep.
OIIO::ImageBuf sheared_hexagon(const OIIO::ImageBuf& src, const Kernel& k, Border border, bool grow,
                               bool transposed, double iris = 0.0)
{
    const int alpha = src.spec().alpha_channel;
    auto exp_space  = [&](double v, int c) { return iris != 0.0 && c != alpha ? std::exp(iris * v) : v; };
    auto back       = [&](double v, int c) { return iris != 0.0 && c != alpha ? std::log(v) / iris : v; };
    const Geometry g = geometry(src, k, grow);
    const double *vx = g.vx, *vy = g.vy;
    struct Dir {
        double x, y;
    };
    std::vector<Dir> d = { { vx[0], vy[0] }, { vx[2], vy[2] }, { vx[4], vy[4] } };
    if (transposed)
        for (Dir& e : d)
            std::swap(e.x, e.y);
    std::sort(d.begin(), d.end(), [](Dir p, Dir q) { return std::abs(p.y / p.x) < std::abs(q.y / q.x); });
    if (std::abs(d[0].y) > std::abs(d[0].x))  // none within 45 degrees of the rows
        return {};
    const double m = d[0].y / d[0].x;
    Dir a{ d[1].x, d[1].y - m * d[1].x }, b{ d[2].x, d[2].y - m * d[2].x };
    const Dir c{ d[0].x, 0.0 };
    if (std::abs(a.y) < std::abs(a.x) || std::abs(b.y) < std::abs(b.x))
        return {};
    // a the less sheared, as the method orders them (its two steep passes do not commute
    // exactly: seg_a seg_b is one rhombus).
    if (std::abs(b.x / b.y) < std::abs(a.x / a.y))
        std::swap(a, b);
    const OIIO::ROI data = src.roi(), roi = g.roi;
    // The frame: columns across (from the reach before the output), lines down; line r is
    // at source position r + base + m x. The windows' own shears take their phases from
    // the line's index, so the frame starts where the method's does: the sheared kernel's
    // reach (and the interpolation's 2) before the first line an output reads.
    const int across0 = transposed ? roi.ybegin : roi.xbegin, across1 = transposed ? roi.yend : roi.xend;
    const int down0 = transposed ? roi.xbegin : roi.ybegin, down1 = transposed ? roi.xend : roi.yend;
    const int reach = transposed ? g.ry : g.rx, org = across0 - reach, w = across1 - across0 + 2 * reach;
    double sheared_reach = 0.0;
    for (int i = 0; i < 6; ++i)
        sheared_reach = std::max(sheared_reach, transposed ? std::abs(vx[i] - m * vy[i]) : std::abs(vy[i] - m * vx[i]));
    const int ry_w = int(std::ceil(sheared_reach)) + 2;
    int u_lo = std::numeric_limits<int>::max(), u_hi = std::numeric_limits<int>::min();
    for (int x = reach; x < w - reach; ++x) {
        u_lo = std::min(u_lo, Taps(-m * x).first);
        u_hi = std::max(u_hi, Taps(-m * x).first);
    }
    const int base = down0 + u_lo - ry_w, h = down1 - 1 - base + u_hi + 3 + ry_w, nc = src.nchannels();
    auto source = [&](int along, int line, int ch) {  // source pixel by frame axes
        const int x = transposed ? line : along, y = transposed ? along : line;
        const int sx = border_coordinate(x, data.xbegin, data.xend, border);
        const int sy = border_coordinate(y, data.ybegin, data.yend, border);
        return exp_space(sx == kBlack || sy == kBlack ? 0.0 : double(src.getchannel(sx, sy, 0, ch)), ch);
    };
    Plane p(w, h, nc);
    for (int r = 0; r < h; ++r)
        for (int x = 0; x < w; ++x) {
            const Taps t(m * x);
            for (int ch = 0; ch < nc; ++ch)
                for (int j = 0; j < 3; ++j)
                    p.ref(x, r, ch) += t.w[j] * source(org + x, base + r + t.first + j, ch);
        }
    const Plane seg_b = segment(p, b.x, b.y);
    const Plane res = add(segment(add(segment(p, a.x, a.y), seg_b), c.x, c.y), segment(seg_b, a.x, a.y));
    return image_over(src, roi, [&](int x, int y, int ch) {
        const int col = (transposed ? y : x) - org, line = (transposed ? x : y) - base;
        const Taps t(-m * col);
        double sum = 0.0;
        for (int j = 0; j < 3; ++j)
            sum += t.w[j] * res.at(col, line + t.first + j, ch);
        return back(sum / 3.0, ch);
    });
}

// The method's definitions for `k` over `src`: off multiples of 30 degrees the sheared
// frames that serve (the method takes the cheaper), else (along the rows, or a hexagon
// stretched past any shear) the plain one.
std::vector<OIIO::ImageBuf> definitions(const OIIO::ImageBuf& src, const Kernel& k, Border border, bool grow,
                                        double iris = 0.0)
{
    std::vector<OIIO::ImageBuf> frames;
    if (std::fmod(k.rotation_deg, 30.0f) != 0.0f)
        for (bool transposed : { false, true }) {
            OIIO::ImageBuf f = sheared_hexagon(src, k, border, grow, transposed, iris);
            if (f.initialized())
                frames.push_back(f);
        }
    if (frames.empty())
        frames.push_back(hexagon(src, k, border, grow, iris));
    return frames;
}

// How far `got` is from the nearest of `refs` (infinite, and a failure, where a window differs).
double closest(const OIIO::ImageBuf& got, const std::vector<OIIO::ImageBuf>& refs)
{
    double best = std::numeric_limits<double>::infinity();
    for (const OIIO::ImageBuf& r : refs) {
        if (got.roi() != r.roi()) {
            ADD_FAILURE() << "the result's window differs from the definition's";
            return std::numeric_limits<double>::infinity();
        }
        best = std::min(best, bokeh_test::max_difference(got, r));
    }
    return best;
}

}  // namespace parallelogram_reference

TEST(BlurApprox, ParallelogramsStayWithinTheirReach)
{
    // The reach a blur grows its window by holds everything the method spreads: the
    // energy of lone pixels in opposite corners stays in the grown window at every size
    // and rotation (the parallelograms spread up to 5 px past the hexagon; they were
    // given 2).
    OIIO::ImageBuf lone(OIIO::ImageSpec(9, 7, 4, OIIO::TypeFloat));
    const float bright[4] = { 1e6f, 1e6f, 1e6f, 1e6f };
    lone.setpixel(0, 0, bright);
    lone.setpixel(8, 6, bright);
    for (float size : { 2.5f, 3.0f, 5.0f, 7.5f, 9.0f, 11.0f, 15.0f, 20.0f, 31.0f, 47.0f })
        for (float rotation : { 0.0f, 30.0f, 7.0f, 25.0f, 45.0f, 60.0f, 83.0f, 13.0f }) {
            SCOPED_TRACE(testing::Message() << size << "@" << rotation);
            BlurOptions o;
            o.method = BlurMethod::Parallelograms;
            o.grow   = true;
            OIIO::ImageBuf out;
            ASSERT_TRUE(blur(out, lone, hexagon(size, size, rotation), o)) << out.geterror();
            for (double sum : channel_sums(out))
                EXPECT_NEAR(sum, 2e6, 2e6 * 1e-6);
        }
}

TEST(BlurApprox, ParallelogramsComputeTheirDefinition)
{
    // Against the method written out plainly (above): the fused sweep (rotations 0 and 30,
    // where the third segment runs along the rows of the working frame) and the sweep in a
    // sheared frame (other rotations), on an image tall enough that the sweep's columns
    // join and leave as the shear moves them, and wide enough for several chunks. Each
    // border rule and the grown window too: the sweeps read the source directly; in iris
    // mode they run on the padded plane (the sheared frame's, 4 px wider).
    // (Iris mode on the image without its 500-bright pixels: exp(k x) over 20 orders of
    // magnitude leaves every running sum's residue far above the dark pixels' values.)
    const OIIO::ImageBuf src = test_image(150, 120, 4, -3), plain = test_image(150, 120, 4, -3, false);
    struct Case {
        Kernel k;
        Border border;
        bool grow;
        float iris = 0.0f;
    };
    for (const Case& c : { Case{ hexagon(19, 19, 0), Border::Black, false },
                           Case{ hexagon(19, 19, 30), Border::Black, false },
                           Case{ hexagon(23, 17, 7), Border::Black, false },
                           Case{ hexagon(21, 21, 20), Border::Black, false },
                           Case{ hexagon(19, 19, 3), Border::Black, false },
                           Case{ hexagon(19, 19, 15), Border::Black, true },
                           Case{ hexagon(61, 61, 13), Border::Black, true },
                           Case{ hexagon(21, 21, 25), Border::Mirror, false },
                           Case{ hexagon(19, 19, -7), Border::Clamp, true },
                           Case{ hexagon(27, 19, -20), Border::Black, false },
                           Case{ hexagon(9, 9, 0), Border::Black, false },
                           Case{ hexagon(19, 19, 0), Border::Black, true },
                           Case{ hexagon(19, 19, 30), Border::Black, true },
                           Case{ hexagon(61, 61, 0), Border::Black, true },
                           Case{ hexagon(61, 61, 30), Border::Black, false },
                           Case{ hexagon(19, 19, 0), Border::Mirror, false },
                           Case{ hexagon(19, 19, 30), Border::Clamp, true },
                           Case{ hexagon(25, 25, 0), Border::Clamp, true },
                           Case{ hexagon(17, 17, 30), Border::Mirror, true },
                           Case{ hexagon(19, 19, 7), Border::Mirror, true },
                           Case{ hexagon(19, 19, 0), Border::Black, false, 2.0f },
                           Case{ hexagon(19, 19, 30), Border::Clamp, true, 2.0f },
                           Case{ hexagon(21, 21, 20), Border::Black, false, 2.0f },
                           Case{ hexagon(19, 19, 7), Border::Mirror, true, 2.0f },
                           Case{ hexagon(19, 19, -55), Border::Clamp, false, 2.0f },
                           // No shear leaves two segments steep: the four passes.
                           Case{ hexagon(45, 15, 20), Border::Clamp, false },
                           Case{ hexagon(15, 45, 10), Border::Black, true, 2.0f } }) {
        SCOPED_TRACE(c.k.rotation_deg);
        SCOPED_TRACE(c.k.width_px);
        SCOPED_TRACE(int(c.border));
        BlurOptions o;
        o.method = BlurMethod::Parallelograms;
        o.border = c.border;
        o.grow   = c.grow;
        o.iris   = c.iris;
        SCOPED_TRACE(c.iris);
        const OIIO::ImageBuf& in = c.iris != 0.0f ? plain : src;
        OIIO::ImageBuf got;
        ASSERT_TRUE(blur(got, in, c.k, o)) << got.geterror();
        // Off multiples of 30 degrees: the sweep in one of the two sheared frames (the
        // cheaper by the method's cost model, of those whose shear leaves two segments
        // steep: one for a stretched hexagon); where both are, they differ far beyond the
        // tolerance, so the check tells them apart. Where neither is (a hexagon stretched
        // further), and along the rows, the plain definition: the four passes, or the
        // sweep whose grouping equals them to float rounding.
        const std::vector<OIIO::ImageBuf> frames = parallelogram_reference::definitions(in, c.k, c.border, c.grow, c.iris);
        const double tol = 2e-6 * peak(frames[0]);
        if (frames.size() == 2) {
            EXPECT_GT(bokeh_test::max_difference(frames[0], frames[1]), 100 * tol);
        }
        EXPECT_LE(parallelogram_reference::closest(got, frames), tol);
    }
}

TEST(BlurApprox, ParallelogramsComputeTheirDefinitionOnOneAndThreeChannels)
{
    // The sweeps' RGBA paths hold a pixel in one vector; other channel counts take the
    // general loops (the sheared frames' gathers and stores too).
    const OIIO::ImageBuf rgba = test_image(90, 70, 2, 1);
    for (int nc : { 1, 3 }) {
        const std::vector<int> order(nc == 1 ? std::vector<int>{ 0 } : std::vector<int>{ 0, 1, 2 });
        const OIIO::ImageBuf src = OIIO::ImageBufAlgo::channels(rgba, nc, order);
        for (const float rotation : { 30.0f, 0.0f, 7.0f, 25.0f }) {
            for (Border border : { Border::Black, Border::Clamp }) {
                SCOPED_TRACE(nc);
                SCOPED_TRACE(rotation);
                SCOPED_TRACE(int(border));
                const Kernel k = hexagon(17, 17, rotation);
                BlurOptions o;
                o.method = BlurMethod::Parallelograms;
                o.border = border;
                o.grow   = border == Border::Clamp;
                OIIO::ImageBuf got;
                ASSERT_TRUE(blur(got, src, k, o)) << got.geterror();
                const std::vector<OIIO::ImageBuf> want = parallelogram_reference::definitions(src, k, border, o.grow);
                EXPECT_LE(parallelogram_reference::closest(got, want), 2e-6 * peak(want[0]));
            }
        }
    }
    // A frame smaller than the kernel, grown: the sheared frames are mostly margin.
    const OIIO::ImageBuf tiny = test_image(3, 2, 5, 4);
    for (const float rotation : { 7.0f, 25.0f }) {
        SCOPED_TRACE(rotation);
        BlurOptions o;
        o.method = BlurMethod::Parallelograms;
        o.grow   = true;
        OIIO::ImageBuf got;
        ASSERT_TRUE(blur(got, tiny, hexagon(41, 41, rotation), o)) << got.geterror();
        const std::vector<OIIO::ImageBuf> want
            = parallelogram_reference::definitions(tiny, hexagon(41, 41, rotation), Border::Black, true);
        EXPECT_LE(parallelogram_reference::closest(got, want), 2e-6 * peak(want[0]));
        const std::vector<double> before = channel_sums(tiny), after = channel_sums(got);
        for (size_t c = 0; c < after.size(); ++c)
            EXPECT_NEAR(after[c], before[c], 1e-5 * before[c]) << "energy, channel " << c;
    }
}

TEST(BlurApprox, HexagonFromParallelogramsIsCloseToTheExactHexagon)
{
    BlurOptions par;
    par.method = BlurMethod::Parallelograms;
    // L1 distance of the point response from the exact anti-aliased hexagon: the shear's
    // interpolation softens the slanted edges by under a pixel, so the relative share of
    // edge pixels (and the distance) falls with the size.
    struct Case {
        Kernel k;
        double max_distance;
    };
    for (const Case& c : { Case{ hexagon(15, 15), 0.25 }, Case{ hexagon(31, 31), 0.13 },
                           Case{ hexagon(63, 63), 0.07 }, Case{ hexagon(41, 27, 15), 0.15 },
                           Case{ hexagon(45, 45, 30), 0.12 } }) {
        SCOPED_TRACE(c.k.width_px);
        SCOPED_TRACE(c.k.rotation_deg);
        const int r = int(std::max(c.k.width_px, c.k.height_px) / 2) + 4;
        const KernelWeights got = point_response(c.k, par, r);
        double sum = 0.0;
        for (double v : got.w)
            sum += v;
        EXPECT_NEAR(sum, 1.0, 1e-5) << "energy";
        const double d = kernel_distance(got, kernel_weights(c.k));
        EXPECT_LE(d, c.max_distance);
        EXPECT_GT(d, 0.0) << "an approximation";
        // Inside, the level is flat within 20 %: the rhombi are flat (two crossing sheared
        // passes left a 20 % moire there with linear interpolation, under 4 % with the
        // B-spline; see hexagon.h), but along the three seams where rhombi meet their
        // softened edges do not add up exactly: up to 16 % near the centre, measured.
        const KernelWeights exact = kernel_weights(c.k);
        const double level = exact.at(0, 0);
        double worst = 0.0;
        for (int dy = -r / 3; dy <= r / 3; ++dy)
            for (int dx = -r / 3; dx <= r / 3; ++dx)
                worst = std::max(worst, std::abs(got.at(dx, dy) / level - 1.0));
        EXPECT_LE(worst, 0.2);
    }
}

TEST(BlurApprox, ParallelogramCostDoesNotDependOnTheSizeButItsReachDoes)
{
    // Energy with a grown window and a translation check: shifting the image by whole
    // pixels shifts the result (the shear's phases follow the data window).
    const OIIO::ImageBuf a = test_image(70, 50, 0, 0), b = test_image(70, 50, 9, -5);
    BlurOptions o;
    o.method = BlurMethod::Parallelograms;
    o.grow   = true;
    OIIO::ImageBuf ra, rb;
    ASSERT_TRUE(blur(ra, a, hexagon(21, 21), o));
    ASSERT_TRUE(blur(rb, b, hexagon(21, 21), o));
    const std::vector<double> before = channel_sums(a), after = channel_sums(ra);
    for (size_t c = 0; c < after.size(); ++c)
        EXPECT_NEAR(after[c], before[c], 2e-6 * before[c]) << "channel " << c;
    ASSERT_EQ(rb.roi().xbegin - ra.roi().xbegin, 9);
    const size_t bytes = size_t(ra.roi().npixels()) * 4 * sizeof(float);
    EXPECT_EQ(std::memcmp(ra.localpixels(), rb.localpixels(), bytes), 0);
}

TEST(BlurApprox, ParallelogramsAreEquivariantUnderTransposition)
{
    // Mirroring the image in its diagonal mirrors the hexagon: rotation r becomes
    // -r - 30 (mod 60). Rotation 0 runs on the transposed plane and 30 on the plane as
    // given (blur_hexagon.cpp); 7 / -37 and 25 / -55 take the sheared sweep in the
    // transposed frame on one side and the frame as given on the other. Each pair checks
    // one path against another: equal to float rounding. (Near 20 degrees the two sheared
    // frames cost alike and the cost model, which charges the frame as given for its
    // diagonal reads, may take the transposed one on both sides; rotation 15 has a segment
    // at exactly 45 degrees, steep in both frames.)
    const OIIO::ImageBuf src = test_image(53, 41, 3, -2);
    OIIO::ImageBuf src_t;
    ASSERT_TRUE(OIIO::ImageBufAlgo::transpose(src_t, src));
    BlurOptions o;
    o.method = BlurMethod::Parallelograms;
    o.grow   = true;
    for (float r : { 0.0f, 7.0f, 25.0f }) {
        SCOPED_TRACE(r);
        OIIO::ImageBuf a, b, a_t;
        ASSERT_TRUE(blur(a, src, hexagon(19, 19, r), o));
        ASSERT_TRUE(blur(b, src_t, hexagon(19, 19, -r - 30.0f), o));
        ASSERT_TRUE(OIIO::ImageBufAlgo::transpose(a_t, a));
        ASSERT_EQ(a_t.roi(), b.roi());
        EXPECT_LE(bokeh_test::max_difference(a_t, b), 2e-6 * peak(a));
    }
}
