// aperture.cpp — the aperture as an edge-distance function of polar angle (the radial LUT
// of Kawase's "Bokeh Deep Dive" that turns a round beam pattern into any aperture's).
//
// Round and bladed apertures are evaluated in closed form (the polygon rule of
// core/aperture/kernel.cpp, shared through polygon_edge_distance, so a lens PSF and the flat
// kernel of the same aperture have the same edge); a star is the closed form of its
// 2N-gon; a picture is tabulated at 1024 angles and interpolated linearly.
// Limits: an edge-distance function describes star-shaped openings only; a picture's
// notches that a ray from the centroid crosses twice are filled.

#include <bokeh/base.h>
#include <bokeh/aperture.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {
constexpr int kTableSize = 1024;

double wrap_angle(double a, double period)
{
    a = std::fmod(a, period);
    return a < 0.0 ? a + period : a;
}
}  // namespace

double polygon_edge_distance(int blades, double curvature, double phi_from_vertex)
{
    const double sector = 2.0 * kPi / blades;
    const double psi    = wrap_angle(phi_from_vertex, sector) - 0.5 * sector;
    const double d_poly = std::cos(0.5 * sector) / std::cos(psi);
    return d_poly + curvature * (1.0 - d_poly);
}

bool Aperture::from_kernel(const Kernel& k, Aperture& out, std::string& err)
{
    if (k.shape != KernelShape::Disk && k.shape != KernelShape::Polygon) {
        err = "a lens aperture is a disk or a bladed polygon (kernel=disk|polygon|hex)";
        return false;
    }
    Kernel unit = k;
    unit.width_px = unit.height_px = 1.0f;
    if (!validate(unit, err))
        return false;
    out = Aperture();
    out.m_hole = k.hole;
    if (k.shape == KernelShape::Polygon && k.curvature < 1.0f) {
        out.m_kind       = Kind::Polygon;
        out.m_blades     = k.blades;
        out.m_curvature  = k.curvature;
        out.m_vertex_rad = 0.5 * kPi + k.rotation_deg * kPi / 180.0;
        out.m_min_edge   = polygon_edge_distance(k.blades, k.curvature, kPi / k.blades);
    }
    return true;
}

bool Aperture::star(int points, double inner_ratio, double rotation_deg, Aperture& out,
                    std::string& err)
{
    if (points < 3 || points > 32) {
        err = format("star points {} is outside 3..32", points);
        return false;
    }
    if (!(inner_ratio >= 0.1 && inner_ratio <= 1.0)) {
        err = format("star inner ratio {} is outside 0.1..1", inner_ratio);
        return false;
    }
    if (!std::isfinite(rotation_deg)) {
        err = "star rotation is not finite";
        return false;
    }
    out              = Aperture();
    out.m_kind       = Kind::Star;
    out.m_blades     = points;
    out.m_inner_ratio = inner_ratio;
    out.m_vertex_rad = 0.5 * kPi + rotation_deg * kPi / 180.0;
    out.m_min_edge   = 1.0;
    for (int i = 0; i < 4 * points; ++i)
        out.m_min_edge = std::min(out.m_min_edge, out.edge(out.m_vertex_rad + i * kPi / (2 * points)));
    return true;
}

bool Aperture::from_picture(const OIIO::ImageBuf& picture, Aperture& out, std::string& err)
{
    const OIIO::ROI roi = picture.roi();
    const int nch       = picture.nchannels();
    if (!roi.defined() || nch < 1) {
        err = "the aperture picture is empty";
        return false;
    }
    const int alpha = picture.spec().alpha_channel;
    const int w = roi.width(), h = roi.height();
    std::vector<float> px(size_t(w) * h * nch);
    if (!picture.get_pixels(roi, OIIO::TypeDesc::FLOAT, px.data())) {
        err = "the aperture picture cannot be read: " + picture.geterror();
        return false;
    }
    std::vector<float> opening(size_t(w) * h);
    float largest = 0.0f;
    for (size_t i = 0; i < opening.size(); ++i) {
        float v = 0.0f;
        if (alpha >= 0) {
            v = px[i * nch + alpha];
        } else {
            const int colour = std::min(nch, 3);
            for (int c = 0; c < colour; ++c)
                v += px[i * nch + c] / colour;
        }
        if (!std::isfinite(v)) {
            err = "the aperture picture holds NaN or infinite values";
            return false;
        }
        opening[i] = v;
        largest    = std::max(largest, v);
    }
    if (!(largest > 0.0f)) {
        err = "the aperture picture has no opening (every pixel is 0)";
        return false;
    }
    double sx = 0.0, sy = 0.0, n = 0.0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            if (opening[size_t(y) * w + x] >= 0.5f * largest) {
                sx += x + 0.5;
                sy += y + 0.5;
                n += 1.0;
            }
    const double cx = sx / n, cy = sy / n;
    auto open_at = [&](double x, double y) {
        const int ix = int(std::floor(x)), iy = int(std::floor(y));
        return ix >= 0 && iy >= 0 && ix < w && iy < h && opening[size_t(iy) * w + ix] >= 0.5f * largest;
    };
    // Each ray marched in quarter-pixel steps; the last step inside, plus half a step,
    // is its edge.
    const double reach = std::hypot(double(w), double(h));
    std::vector<float> table(kTableSize);
    double far = 0.0;
    for (int i = 0; i < kTableSize; ++i) {
        const double phi = 2.0 * kPi * i / kTableSize;
        const double dx = std::cos(phi), dy = -std::sin(phi);  // y down in the picture
        double last = 0.0;
        for (double t = 0.25; t < reach; t += 0.25)
            if (open_at(cx + t * dx, cy + t * dy))
                last = t + 0.125;
        table[size_t(i)] = float(last);
        far              = std::max(far, last);
    }
    if (far < 4.0) {
        err = format("the aperture picture's opening is {:.1f} px across; at least 8 are needed",
                     2.0 * far);
        return false;
    }
    out        = Aperture();
    out.m_kind = Kind::Table;
    out.m_min_edge = 1.0;
    for (float& e : table) {
        e              = std::max(float(e / far), 1e-3f);
        out.m_min_edge = std::min(out.m_min_edge, double(e));
    }
    out.m_table = std::move(table);
    return true;
}

double Aperture::edge(double phi) const
{
    switch (m_kind) {
    case Kind::Round: return 1.0;
    case Kind::Polygon: return polygon_edge_distance(m_blades, m_curvature, phi - m_vertex_rad);
    case Kind::Star: {
        // The ray meets the segment from an outer vertex (radius 1) to the next inner
        // one (radius inner_ratio, half a point further round): t = (P1 x D) / (u x D).
        const double half = kPi / m_blades;
        const double a    = wrap_angle(phi - m_vertex_rad, 2.0 * half);
        const double rel  = a <= half ? a : 2.0 * half - a;  // mirror into [0, half]
        const double p1x = 1.0, p1y = 0.0;
        const double p2x = m_inner_ratio * std::cos(half), p2y = m_inner_ratio * std::sin(half);
        const double dx = p2x - p1x, dy = p2y - p1y;
        const double ux = std::cos(rel), uy = std::sin(rel);
        return (p1x * dy - p1y * dx) / (ux * dy - uy * dx);
    }
    case Kind::Table: {
        const double f = wrap_angle(phi, 2.0 * kPi) / (2.0 * kPi) * kTableSize;
        const int i0   = int(f) % kTableSize;
        const int i1   = (i0 + 1) % kTableSize;
        const double t = f - std::floor(f);
        return (1.0 - t) * m_table[size_t(i0)] + t * m_table[size_t(i1)];
    }
    }
    return 1.0;
}

bool Aperture::inside(double x, double y) const
{
    const double r = std::hypot(x, y);
    if (r == 0.0)
        return m_hole == 0.0;
    const double e = edge(std::atan2(y, x));
    return r < e && r >= m_hole * e;
}

double Aperture::edge_normal_cos(double phi) const
{
    if (m_kind == Kind::Round)
        return 1.0;
    // For a polar curve R(phi) the ray and the normal meet at angle atan(R' / R).
    const double h  = m_kind == Kind::Table ? 2.0 * kPi / kTableSize : 1e-4;
    const double r  = edge(phi);
    const double dr = (edge(phi + h) - edge(phi - h)) / (2.0 * h);
    return r / std::sqrt(r * r + dr * dr);
}

bool Aperture::operator==(const Aperture& o) const
{
    return m_kind == o.m_kind && m_blades == o.m_blades && m_curvature == o.m_curvature
           && m_vertex_rad == o.m_vertex_rad && m_inner_ratio == o.m_inner_ratio && m_hole == o.m_hole
           && m_min_edge == o.m_min_edge && m_table == o.m_table;
}

std::string Aperture::describe() const
{
    switch (m_kind) {
    case Kind::Round: return m_hole > 0.0 ? format("round, hole {:g}", m_hole) : "round";
    case Kind::Polygon: return format("{} blades", m_blades);
    case Kind::Star: return format("star of {} points", m_blades);
    case Kind::Table: return "picture";
    }
    return "round";
}

}  // namespace bokeh
