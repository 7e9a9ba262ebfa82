// lens_distortion.cpp — radial distortion and lateral colour as a warp of the frame, and its
// STMap (distortion.h; docs/methods/distortion.md).
//
// The models are the radial terms of Brown-Conrady (polynomial) and Fitzgibbon's division
// model, each explicit one way: the polynomial gives the distorted radius of an undistorted
// one, the division model the reverse. The other way is found by Newton's method on the
// radius (the mapping is radial, so the direction is kept and only |p| is solved for);
// check_distortion refuses coefficients whose explicit mapping is not increasing out to the
// frame's farthest corner, so the solve has one root there and converges from the target
// radius in a few steps (to 1e-12 of the half-diagonal, far inside the 0.01 px asked of a
// round trip).
//
// Known limits: radial terms only (no tangential/decentring terms, no anamorphic squeeze);
// bilinear sampling (a warp by less than a pixel softens a little, as any bilinear warp);
// the lateral colour is one magnification per channel, not a spectrum.

#include <bokeh/distortion.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>

#include "base/plane.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {

// The explicit radial mapping of the model and its derivative: polynomial r_u -> r_d,
// division r_d -> r_u.
double explicit_radius(const LensDistortion& l, double r, double& slope)
{
    const double r2 = r * r;
    if (l.model == DistortionModel::Polynomial) {
        slope = 1.0 + 3.0 * l.k1 * r2 + 5.0 * l.k2 * r2 * r2;
        return r * (1.0 + l.k1 * r2 + l.k2 * r2 * r2);
    }
    const double d = 1.0 + l.k1 * r2 + l.k2 * r2 * r2;
    slope          = (d - r * (2.0 * l.k1 * r + 4.0 * l.k2 * r2 * r)) / (d * d);
    return r / d;
}

// The radius whose explicit mapping is `target`, by Newton's method from the target itself.
bool solve_radius(const LensDistortion& l, double target, double& r)
{
    r = target;
    for (int i = 0; i < 50; ++i) {
        double slope;
        const double f = explicit_radius(l, r, slope) - target;
        if (std::abs(f) < 1e-13)
            return r >= 0.0;
        if (!(slope > 0.0))
            return false;
        r -= f / slope;
    }
    return false;
}

// Scale (xa, ya) from radius r_from to radius r_to.
void rescale(double x, double y, double r_from, double r_to, double& ox, double& oy)
{
    const double s = r_from > 0.0 ? r_to / r_from : 1.0;
    ox = x * s, oy = y * s;
}

// The frame's normalisation: centre and half-diagonal of the display window.
struct Normalise {
    double cx, cy, radius;
    Normalise(const OIIO::ImageSpec& spec, const LensDistortion& l)
        : cx(spec.full_x + 0.5 * spec.full_width + l.centre_x_px)
        , cy(spec.full_y + 0.5 * spec.full_height + l.centre_y_px)
        , radius(0.5 * std::hypot(double(spec.full_width), double(spec.full_height)))
    {
    }
};

// The source position (continuous pixel coordinates, centres at i + 0.5) of output
// position (X, Y) for a channel magnified by `m`; false where the mapping has no inverse.
bool source_position(const LensDistortion& l, const Normalise& n, DistortDirection dir, double m, double X,
                     double Y, double& sx, double& sy)
{
    const double x = (X - n.cx) / n.radius, y = (Y - n.cy) / n.radius;
    double px, py;
    if (dir == DistortDirection::Distort) {  // output distorted: find its undistorted source
        if (!l.undistort(x / m, y / m, px, py))
            return false;
    } else {  // output undistorted: its recorded (distorted) source
        l.distort(x, y, px, py);
        if (!std::isfinite(px) || !std::isfinite(py))
            return false;
        px *= m, py *= m;
    }
    sx = n.cx + px * n.radius, sy = n.cy + py * n.radius;
    return true;
}

}  // namespace

void LensDistortion::distort(double xu, double yu, double& xd, double& yd) const
{
    const double ru = std::hypot(xu, yu);
    double rd = ru, slope;
    if (model == DistortionModel::Polynomial)
        rd = explicit_radius(*this, ru, slope);
    else if (!solve_radius(*this, ru, rd))
        rd = std::numeric_limits<double>::quiet_NaN();
    rescale(xu, yu, ru, rd, xd, yd);
}

bool LensDistortion::undistort(double xd, double yd, double& xu, double& yu) const
{
    const double rd = std::hypot(xd, yd);
    double ru = rd, slope;
    if (model == DistortionModel::Division)
        ru = explicit_radius(*this, rd, slope);
    else if (!solve_radius(*this, rd, ru))
        return false;
    rescale(xd, yd, rd, ru, xu, yu);
    return true;
}

bool check_distortion(const LensDistortion& l, const OIIO::ROI& display, std::string& err)
{
    for (const auto& [name, v] : { std::make_pair("k1", l.k1), std::make_pair("k2", l.k2),
                                   std::make_pair("lateral R", l.lateral_r), std::make_pair("lateral B", l.lateral_b),
                                   std::make_pair("centre x", l.centre_x_px), std::make_pair("centre y", l.centre_y_px) })
        if (!std::isfinite(v)) {
            err = format("{} is {}, not a finite number", name, v);
            return false;
        }
    for (const auto& [name, v] : { std::make_pair("lateral R", l.lateral_r), std::make_pair("lateral B", l.lateral_b) })
        if (std::abs(v) > 0.5) {
            err = format("{} {} is outside -0.5..0.5 (a magnification of 1 + {})", name, v, v);
            return false;
        }
    // The farthest corner from the centre, in half-diagonals, and a margin for lateral colour.
    OIIO::ImageSpec spec;
    spec.full_x = display.xbegin, spec.full_y = display.ybegin;
    spec.full_width = display.width(), spec.full_height = display.height();
    const Normalise n(spec, l);
    double reach = 0.0;
    for (double X : { double(display.xbegin), double(display.xend) })
        for (double Y : { double(display.ybegin), double(display.yend) })
            reach = std::max(reach, std::hypot(X - n.cx, Y - n.cy) / n.radius);
    reach *= 1.0 + std::max({ std::abs(l.lateral_r), std::abs(l.lateral_b), 0.0 });
    reach *= 1.05;
    // The explicit mapping, increasing from 0 to the farthest corner (1000 steps: a fold
    // narrower than that is no lens).
    double previous = 0.0;
    for (int i = 1; i <= 1000; ++i) {
        const double r = reach * double(i) / 1000.0;
        double slope;
        const double v = explicit_radius(l, r, slope);
        if (!(v > previous) || !(slope > 0.0)) {
            err = format("k1 {} and k2 {} fold the {} mapping over itself at {:.3g} of the half-diagonal, "
                         "inside the frame (it reaches {:.3g}): no lens distorts so, and it has no inverse",
                         l.k1, l.k2, l.model == DistortionModel::Polynomial ? "polynomial" : "division", r, reach);
            return false;
        }
        previous = v;
    }
    return true;
}

bool lens_distort(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const LensDistortion& lens,
                  DistortDirection direction, OIIO::ROI roi, int nthreads)
{
    if (!src.initialized() || src.deep()) {
        dst.errorfmt("lens distortion: {}", src.initialized() ? "a deep image cannot be warped; flatten it first"
                                                             : "no source image");
        return false;
    }
    const OIIO::ImageSpec& spec = src.spec();
    std::string err;
    if (!check_distortion(lens, spec.roi_full(), err)) {
        dst.errorfmt("lens distortion: {}", err);
        return false;
    }
    if (!roi.defined())
        roi = src.roi();
    roi.chbegin = 0, roi.chend = spec.nchannels;
    // The source as float, its data window, black past it.
    const OIIO::ROI data = src.roi();
    const int nc = spec.nchannels, sw = data.width(), sh = data.height();
    std::vector<float> px(size_t(sw) * size_t(sh) * size_t(nc));
    if (!src.get_pixels(data, OIIO::TypeFloat, px.data())) {
        dst.errorfmt("lens distortion: {}", src.geterror());
        return false;
    }
    OIIO::ImageSpec out = spec;
    out.set_format(OIIO::TypeFloat);
    out.channelformats.clear();
    out.x = roi.xbegin, out.y = roi.ybegin, out.width = roi.width(), out.height = roi.height();
    detail::reset_uninitialised(dst, out);
    // Which magnification each channel follows: R and B their own, the rest green's.
    std::vector<int> group(size_t(nc), 1);
    const double mag[3] = { 1.0 + lens.lateral_r, 1.0, 1.0 + lens.lateral_b };
    for (int c = 0; c < nc; ++c) {
        const std::string& name = spec.channel_name(c);
        group[size_t(c)]        = name == "R" ? 0 : name == "B" ? 2 : 1;
    }
    std::vector<bool> nearest(static_cast<size_t>(nc), false);
    for (int c = 0; c < nc; ++c)
        nearest[size_t(c)] = is_depth_channel(spec.channel_name(c)) || c == spec.z_channel;
    const Normalise n(spec, lens);
    auto at = [&](int x, int y, int c) -> float {
        if (x < data.xbegin || x >= data.xend || y < data.ybegin || y >= data.yend)
            return 0.0f;
        return px[(size_t(y - data.ybegin) * size_t(sw) + size_t(x - data.xbegin)) * size_t(nc) + size_t(c)];
    };
    parallel_for_chunks(roi.ybegin, roi.yend, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* row = static_cast<float*>(dst.pixeladdr(roi.xbegin, y));
            for (int x = roi.xbegin; x < roi.xend; ++x, row += nc) {
                double pos[3][2];
                bool ok[3];
                // Green's position once; red's and blue's only where lateral colour moves them.
                ok[1] = source_position(lens, n, direction, 1.0, x + 0.5, y + 0.5, pos[1][0], pos[1][1]);
                for (int g : { 0, 2 }) {
                    if (mag[g] == 1.0) {
                        ok[g] = ok[1], pos[g][0] = pos[1][0], pos[g][1] = pos[1][1];
                        continue;
                    }
                    ok[g] = source_position(lens, n, direction, mag[g], x + 0.5, y + 0.5, pos[g][0], pos[g][1]);
                }
                for (int c = 0; c < nc; ++c) {
                    const int g = group[size_t(c)];
                    if (!ok[g]) {
                        row[c] = 0.0f;
                        continue;
                    }
                    const double fx = pos[g][0] - 0.5, fy = pos[g][1] - 0.5;
                    if (nearest[size_t(c)]) {
                        row[c] = at(int(std::floor(pos[g][0])), int(std::floor(pos[g][1])), c);
                        continue;
                    }
                    const int ix = int(std::floor(fx)), iy = int(std::floor(fy));
                    const float tx = float(fx - ix), ty = float(fy - iy);
                    const float top = at(ix, iy, c) * (1.0f - tx) + at(ix + 1, iy, c) * tx;
                    const float bot = at(ix, iy + 1, c) * (1.0f - tx) + at(ix + 1, iy + 1, c) * tx;
                    row[c]          = top * (1.0f - ty) + bot * ty;
                }
            }
        }
    });
    return true;
}

bool distortion_stmap(OIIO::ImageBuf& dst, const OIIO::ImageSpec& like, const LensDistortion& lens,
                      DistortDirection direction, int nthreads)
{
    std::string err;
    if (lens.lateral_r != 0.0 || lens.lateral_b != 0.0) {
        dst.errorfmt("lens distortion: an STMap holds one source position a pixel; lateral colour moves red and "
                     "blue apart (warp the frame itself for it)");
        return false;
    }
    if (!check_distortion(lens, like.roi_full(), err)) {
        dst.errorfmt("lens distortion: {}", err);
        return false;
    }
    OIIO::ImageSpec out(like.width, like.height, 2, OIIO::TypeFloat);
    out.x = like.x, out.y = like.y;
    out.full_x = like.full_x, out.full_y = like.full_y;
    out.full_width = like.full_width, out.full_height = like.full_height;
    out.channelnames = { "R", "G" };
    detail::reset_uninitialised(dst, out);
    const Normalise n(like, lens);
    parallel_for_chunks(like.y, like.y + like.height, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* row = static_cast<float*>(dst.pixeladdr(like.x, y));
            for (int x = like.x; x < like.x + like.width; ++x, row += 2) {
                double sx, sy;
                if (!source_position(lens, n, direction, 1.0, x + 0.5, y + 0.5, sx, sy))
                    sx = sy = -1e6;  // no source: far outside, black when sampled
                row[0] = float((sx - like.full_x) / like.full_width);
                row[1] = float(1.0 - (sy - like.full_y) / like.full_height);
            }
        }
    });
    return true;
}

}  // namespace bokeh
