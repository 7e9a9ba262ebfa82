// lens.cpp — thin-lens CoC, depth modes, the signed CoC map and its diagnostics.
//
// Source: the thin-lens circle of confusion as hikita12312's blog post "Implementing depth
// of field" (2017) gives it (derived in docs/methods/optics.md, "The thin lens")
//     CoC(d) = |d - d0| / d * f^2 / (F (d0 - f)) / eps,    eps = sensor width / image width,
// here signed (negative in front of focus). The depth modes follow Nuke ZDefocus's "math"
// choices by name; "far = 1" is read as 1 - 1/d (near 1 unit = 0, infinity = 1), our reading
// of a normalised inverse depth. Additions: an in-focus range (distances within half the
// range of the focus distance count as at it, the rest move toward it by half the range, so
// the CoC stays continuous), front/back gains and a CoC limit, as ZDefocus offers.
// Known limit: the thin lens has no aberrations, so the CoC is exactly linear in 1/d.

#include <bokeh/image.h>
#include <bokeh/lens.h>
#include <bokeh/parallel.h>

#include "base/numbers.h"
#include "base/plane.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

namespace {

using detail::kInf;

// The depth channel's value at data-window pixel (x, y) of a float local image.
float depth_at(const OIIO::ImageBuf& img, int zc, int x, int y)
{
    return static_cast<const float*>(img.pixeladdr(x, y, img.spec().z))[zc];
}

}  // namespace

const std::vector<FilmBack>& film_backs()
{
    // Published camera-aperture widths (manufacturers' data sheets).
    static const std::vector<FilmBack> backs = {
        { "ff", 36.0 },          { "super35", 24.89 },   { "academy35", 21.95 },
        { "alexa-lf", 36.70 },   { "alexa-mini", 28.25 }, { "alexa65", 54.12 },
        { "red-v-raptor", 40.96 }, { "apsc", 23.6 },      { "m43", 17.3 },
        { "super16", 12.52 },    { "imax70", 70.41 },
    };
    return backs;
}

bool film_back_width(const std::string& name, double& width_mm)
{
    for (const FilmBack& b : film_backs())
        if (name == b.name) {
            width_mm = b.width_mm;
            return true;
        }
    return false;
}

double thin_lens_coc_px(const Lens& lens, double distance, int image_width_px)
{
    const double f = lens.focal_mm, d0 = lens.focus_distance * lens.depth_unit_mm;
    const double pixel_mm = lens.sensor_width_mm / double(image_width_px);
    // (d - d0) / d, with its limit 1 at infinity.
    const double defocus = std::isinf(distance) ? 1.0
                                                : (distance * lens.depth_unit_mm - d0)
                                                      / (distance * lens.depth_unit_mm);
    return defocus * f * f / (lens.fstop * (d0 - f)) / pixel_mm;
}

double distance_from_depth(double value, DepthMode mode, bool negate)
{
    if (negate)
        value = -value;
    if (!std::isfinite(value) || value == 0.0)  // "no depth", in every mode
        return kInf;
    switch (mode) {
    case DepthMode::Depth: return value > 0.0 ? value : kInf;
    case DepthMode::InverseDepth: return value > 0.0 ? 1.0 / value : kInf;
    case DepthMode::FarIsOne: return value < 1.0 ? 1.0 / (1.0 - value) : kInf;
    case DepthMode::Direct: break;
    }
    return kInf;
}

void record_lens(OIIO::ImageSpec& spec, const CocOptions& resolved)
{
    static const char* names[] = { "bokeh:focal_mm", "bokeh:fstop", "bokeh:sensor_width_mm",
                                   "bokeh:focus_m" };
    if (resolved.mode == DepthMode::Direct) {
        for (const char* n : names)
            spec.erase_attribute(n);
        return;
    }
    const Lens& l = resolved.lens;
    spec.attribute(names[0], float(l.focal_mm));
    spec.attribute(names[1], float(l.fstop));
    spec.attribute(names[2], float(l.sensor_width_mm));
    spec.attribute(names[3], float(l.focus_distance * l.depth_unit_mm / 1000.0));
}

bool resolve_coc_options(CocOptions& o, const OIIO::ImageBuf& src, std::string& err)
{
    using OIIO::Strutil::fmt::format;
    const ChannelMap ch = find_channels(src.spec());
    if (ch.z < 0) {
        err = no_depth_message(src.spec());
        return false;
    }
    if (!(o.max_coc_px >= 0.0) || !std::isfinite(o.max_coc_px)) {
        err = format("max CoC {} must be finite and >= 0", o.max_coc_px);
        return false;
    }
    if (!(o.front_gain >= 0.0 && o.back_gain >= 0.0) || !std::isfinite(o.front_gain + o.back_gain)) {
        err = "front and back gains must be finite and >= 0";
        return false;
    }
    if (o.mode == DepthMode::Direct) {
        if (!std::isfinite(o.direct_scale)) {
            err = "the direct CoC scale must be finite";
            return false;
        }
        return true;
    }
    const Lens& l = o.lens;
    if (!(l.focal_mm >= kMinFocalMm && l.focal_mm <= kMaxFocalMm) || !(l.fstop >= kMinFstop && l.fstop <= kMaxFstop)
        || !(l.sensor_width_mm > 0.0 && l.sensor_width_mm < kMaxSensorWidthMm)
        || !(l.depth_unit_mm > 0.0 && std::isfinite(l.depth_unit_mm))) {
        err = format("lens focal {} mm, f/{}, sensor {} mm, unit {} mm: focal {:g}..{:g} mm, f/{:g}..{:g}, a "
                     "positive sensor width and depth unit",
                     l.focal_mm, l.fstop, l.sensor_width_mm, l.depth_unit_mm, kMinFocalMm, kMaxFocalMm, kMinFstop,
                     kMaxFstop);
        return false;
    }
    if (!(o.infocus_range >= 0.0) || !std::isfinite(o.infocus_range)) {
        err = format("in-focus range {} must be finite and >= 0", o.infocus_range);
        return false;
    }
    if (o.focus_at_pixel) {
        const OIIO::ROI d = src.roi();
        if (o.focus_x < d.xbegin || o.focus_x >= d.xend || o.focus_y < d.ybegin
            || o.focus_y >= d.yend) {
            err = format("focus pixel {},{} is outside the data window {},{} .. {},{}", o.focus_x,
                         o.focus_y, d.xbegin, d.ybegin, d.xend - 1, d.yend - 1);
            return false;
        }
        const float z = src.getchannel(o.focus_x, o.focus_y, 0, ch.z);
        const double dist = distance_from_depth(z, o.mode, o.negate);
        if (std::isinf(dist)) {
            err = format("focus pixel {},{} has no depth (Z = {})", o.focus_x, o.focus_y, z);
            return false;
        }
        o.lens.focus_distance = dist;
    }
    if (!(o.lens.focus_distance * l.depth_unit_mm > l.focal_mm)
        || !std::isfinite(o.lens.focus_distance)) {
        err = format("focus distance {} (x {} mm) must lie beyond the focal length {} mm",
                     o.lens.focus_distance, l.depth_unit_mm, l.focal_mm);
        return false;
    }
    return true;
}

CocOfDepth::CocOfDepth(const CocOptions& resolved, int image_width_px)
    : m_opts(resolved), m_width_px(image_width_px)
{
}

float CocOfDepth::operator()(float value) const
{
    const CocOptions& o = m_opts;
    double c;
    if (o.mode == DepthMode::Direct) {
        c = (o.negate ? -double(value) : double(value)) * o.direct_scale;
        if (!std::isfinite(c))
            c = 0.0;  // a direct CoC that is not a number: no blur rather than a guess
    } else {
        const double d0 = o.lens.focus_distance, half_range = 0.5 * o.infocus_range;
        double dist = distance_from_depth(value, o.mode, o.negate);
        if (std::abs(dist - d0) <= half_range)
            dist = d0;
        else if (!std::isinf(dist))
            dist += dist > d0 ? -half_range : half_range;
        c = thin_lens_coc_px(o.lens, dist, m_width_px);
    }
    c *= c < 0.0 ? o.front_gain : o.back_gain;
    return float(std::clamp(c, -o.max_coc_px, o.max_coc_px));
}

bool signed_coc(std::vector<float>& coc, const OIIO::ImageBuf& src, const CocOptions& o,
                int nthreads, std::string& err)
{
    const ChannelMap ch = find_channels(src.spec());
    if (ch.z < 0) {
        err = no_depth_message(src.spec());
        return false;
    }
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& img = detail::float_source(src, holder);
    const OIIO::ROI d         = img.roi();
    const CocOfDepth coc_of(o, img.spec().full_width > 0 ? img.spec().full_width : d.width());
    coc.resize(size_t(d.width()) * size_t(d.height()));
    parallel_rows(d, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            float* out = coc.data() + size_t(y - d.ybegin) * size_t(d.width());
            for (int x = d.xbegin; x < d.xend; ++x)
                out[x - d.xbegin] = coc_of(depth_at(img, ch.z, x, y));
        }
    });
    return true;
}

bool coc_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const CocOptions& opts, int nthreads)
{
    std::string err;
    CocOptions o = opts;
    std::vector<float> coc;
    if (!resolve_coc_options(o, src, err) || !signed_coc(coc, src, o, nthreads, err)) {
        dst.errorfmt("coc: {}", err);
        return false;
    }
    detail::reset_uninitialised(dst, derived_spec(src.spec(), { "coc" }));
    const OIIO::ROI d = src.roi();
    for (int y = d.ybegin; y < d.yend; ++y)
        std::copy_n(coc.data() + size_t(y - d.ybegin) * size_t(d.width()), d.width(),
                    static_cast<float*>(dst.pixeladdr(d.xbegin, y)));
    return true;
}

bool focal_plane_view(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const CocOptions& opts,
                      float full_tint_px, int nthreads)
{
    std::string err;
    CocOptions o = opts;
    std::vector<float> coc;
    WorkImage w;
    if (!resolve_coc_options(o, src, err) || !signed_coc(coc, src, o, nthreads, err)
        || !to_work_image(w, src, err, nthreads)) {
        dst.errorfmt("focal plane: {}", err);
        return false;
    }
    detail::reset_uninitialised(dst, derived_spec(src.spec(), { "R", "G", "B" }));
    const float full = std::max(full_tint_px, 1.0f);
    parallel_rows(w.roi, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y)
            for (int x = w.roi.xbegin; x < w.roi.xend; ++x) {
                const float* p = w.rgba_at(x, y);
                // Rec. 709 luminance, compressed by l / (1 + l) so HDR values stay readable.
                float l       = std::max(0.0f, 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2]);
                l             = l / (1.0f + l);
                const float c = coc[w.index(x, y)];
                const bool sharp = std::abs(c) <= 1.0f;
                // Any defocus shows (at least 0.3), growing to full tint at full_tint_px.
                const float t = sharp ? 1.0f : 0.3f + 0.7f * std::min(1.0f, std::abs(c) / full);
                const float tint[3] = { !sharp && c < 0.0f ? 1.0f : 0.0f, sharp ? 1.0f : 0.0f,
                                        !sharp && c > 0.0f ? 1.0f : 0.0f };
                float* out = static_cast<float*>(dst.pixeladdr(x, y));
                for (int i = 0; i < 3; ++i)
                    out[i] = l * (1.0f - 0.6f * t) + 0.6f * t * tint[i];
            }
    });
    return true;
}

}  // namespace bokeh
