// aperture.cpp — the aperture as an edge-distance function of polar angle (the radial LUT
// of Kawase's "Bokeh Deep Dive" that turns a round beam pattern into any aperture's), and
// the three things made from it: the inside test the kernels' exact weights count, the
// edge the lens PSFs draw, and the area-uniform pupil points the thin-lens truth shoots.
//
// Round and bladed apertures are evaluated in closed form (polygon_edge_distance); a star
// is the closed form of its 2N-gon; a picture is tabulated at 1024 angles and interpolated
// linearly. A polygon's inside test takes the largest projection on its blades' normals
// instead of an angle (2.5-3.6x faster kernel weights for 3-9 blades, the same bits as the
// angle's rule on 14 polygons of 3-64 blades; past ~40 blades the dot products cost more
// than the angle, so only up to 32 blades hold normals).
// The area sampler: a polygon's cumulative area inside a sector is closed-form, half the
// integral of d(t)^2 with d(t) = (1 - q) A / cos t + q (A the apothem, q the curvature):
// (1 - q)^2 A^2 tan t + 2 q (1 - q) A asinh(tan t) + q^2 t; any other edge's is summed at
// 8192 angles (midpoint rule; a star's or a picture's area to under 1e-6 of itself).
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

constexpr int kSectorSteps  = 4096;  // the polygon sampler's inverse CDF nodes a sector
constexpr int kEdgeSteps    = 8192;  // other edges: the angles their area is summed at

double wrap_angle(double a, double period)
{
    a = std::fmod(a, period);
    return a < 0.0 ? a + period : a;
}

// The area of a polygon's sector from its normal to angle t, times 2, up to a constant
// (the closed form in the header above): apothem A, curvature q.
double sector_area2(double A, double q, double t)
{
    const double tn = std::tan(t);
    return (1 - q) * (1 - q) * A * A * tn + 2 * q * (1 - q) * A * std::asinh(tn) + q * q * t;
}

// The blades' unit normals, (u, v) with v up, for a polygon of up to 32 blades.
std::vector<std::pair<double, double>> blade_normals(int blades, double vertex_rad)
{
    std::vector<std::pair<double, double>> n;
    if (blades > 32)
        return n;
    const double sector = 2.0 * kPi / blades;
    for (int j = 0; j < blades; ++j) {
        const double a = vertex_rad + (j + 0.5) * sector;  // the middle of sector j
        n.emplace_back(std::cos(a), std::sin(a));
    }
    return n;
}
}  // namespace

double polygon_edge_distance(int blades, double curvature, double phi_from_vertex)
{
    const double sector = 2.0 * kPi / blades;
    const double psi    = wrap_angle(phi_from_vertex, sector) - 0.5 * sector;
    const double d_poly = std::cos(0.5 * sector) / std::cos(psi);
    return d_poly + curvature * (1.0 - d_poly);
}

bool Aperture::polygon(int blades, double curvature, double rotation_deg, double hole, Aperture& out,
                       std::string& err)
{
    if (blades < 3 || blades > 64) {
        err = format("blades {} is outside 3..64", blades);
        return false;
    }
    if (!std::isfinite(rotation_deg)) {
        err = "rotation is not finite";
        return false;
    }
    if (!(curvature >= 0.0 && curvature <= 1.0)) {
        err = format("curvature {} is outside 0..1", curvature);
        return false;
    }
    if (!(hole >= 0.0 && hole < 1.0)) {
        err = format("hole {} is outside 0..<1", hole);
        return false;
    }
    out        = Aperture();
    out.m_hole = hole;
    if (curvature < 1.0) {  // curvature 1 is the circle
        out.m_kind       = Kind::Polygon;
        out.m_blades     = blades;
        out.m_curvature  = curvature;
        out.m_vertex_rad = 0.5 * kPi + rotation_deg * kPi / 180.0;
        out.m_apothem    = std::cos(0.5 * (2.0 * kPi / blades));
        out.m_min_edge   = polygon_edge_distance(blades, curvature, kPi / blades);
        out.m_normals    = blade_normals(blades, out.m_vertex_rad);
    }
    return true;
}

bool Aperture::from_kernel(const Kernel& k, Aperture& out, std::string& err)
{
    if (k.shape != KernelShape::Disk && k.shape != KernelShape::Polygon && k.shape != KernelShape::Opening) {
        err = "a lens aperture is a disk, a bladed polygon or an opening (kernel=disk|polygon|hex|star)";
        return false;
    }
    Kernel unit = k;
    unit.width_px = unit.height_px = 1.0f;
    if (!check_kernel(unit, err))
        return false;
    if (k.shape == KernelShape::Opening) {
        out = k.opening;
        return true;
    }
    if (k.shape == KernelShape::Polygon)
        return polygon(k.blades, k.curvature, k.rotation_deg, k.hole, out, err);
    out        = Aperture();
    out.m_hole = k.hole;
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
    const double r = std::sqrt(x * x + y * y);
    double d       = 1.0;
    if (m_kind != Kind::Round && r > 0.0) {  // at the centre any d > 0 gives the same answer
        if (!m_normals.empty()) {
            // The blade nearest in angle to a point is the one its projection is largest
            // on, p = r cos(psi), so the edge distance cos(pi/N) / cos(psi) is A r / p.
            double p = 0.0;
            for (const auto& [nx, ny] : m_normals)
                p = std::max(p, x * nx + y * ny);
            const double d_poly = m_apothem * r / p;
            d                   = d_poly + m_curvature * (1.0 - d_poly);
        } else {
            d = edge(std::atan2(y, x));
        }
    }
    return r < d && r >= m_hole * d;
}

double Aperture::area() const
{
    double unit = 0.0;
    switch (m_kind) {
    case Kind::Round: unit = kPi; break;
    case Kind::Polygon: {
        const double half = kPi / m_blades;
        unit = 0.5 * m_blades * (sector_area2(m_apothem, m_curvature, half) - sector_area2(m_apothem, m_curvature, -half));
        break;
    }
    default: {
        const double step = 2.0 * kPi / kEdgeSteps;
        for (int i = 0; i < kEdgeSteps; ++i) {
            const double e = edge((i + 0.5) * step);
            unit += 0.5 * e * e * step;
        }
    }
    }
    return unit * (1.0 - m_hole * m_hole);
}

Aperture Aperture::point_reflected() const
{
    Aperture r = *this;
    switch (m_kind) {
    case Kind::Round: break;
    case Kind::Polygon:
    case Kind::Star:
        r.m_vertex_rad = m_vertex_rad + kPi;
        r.m_normals    = m_kind == Kind::Polygon ? blade_normals(m_blades, r.m_vertex_rad) : m_normals;
        break;
    case Kind::Table:
        std::rotate(r.m_table.begin(), r.m_table.begin() + kTableSize / 2, r.m_table.end());
        break;
    }
    return r;
}

// --- area-uniform points -------------------------------------------------------------

ApertureSampler::ApertureSampler(const Aperture& a, float aspect)
    : m_aperture(a)
    , m_hole2(a.m_hole * a.m_hole)
    , m_aspect(aspect)
    , m_area(a.area() * 0.25 * aspect)
{
    if (a.m_kind == Aperture::Kind::Polygon) {
        m_sector       = 2.0 * kPi / a.m_blades;
        m_first_normal = a.m_vertex_rad + 0.5 * m_sector;
        const double A = a.m_apothem, q = a.m_curvature;
        const double half = 0.5 * m_sector, h0 = sector_area2(A, q, -half), total = sector_area2(A, q, half) - h0;
        m_angle.resize(kSectorSteps + 1);
        m_angle.front() = -half;
        m_angle.back()  = half;
        for (int i = 1; i < kSectorSteps; ++i) {
            const double target = total * double(i) / kSectorSteps;
            double lo = -half, hi = half;
            for (int it = 0; it < 60; ++it) {
                const double mid = 0.5 * (lo + hi);
                (sector_area2(A, q, mid) - h0 < target ? lo : hi) = mid;
            }
            m_angle[size_t(i)] = 0.5 * (lo + hi);
        }
    } else if (a.m_kind != Aperture::Kind::Round) {
        // The cumulative area at the edges of kEdgeSteps equal angle cells, each cell's
        // share from its middle's edge distance (Aperture::area's sum, kept cell by cell).
        const double step = 2.0 * kPi / kEdgeSteps;
        m_angle.resize(kEdgeSteps + 1);
        m_angle.front() = 0.0;
        for (int i = 0; i < kEdgeSteps; ++i) {
            const double e         = a.edge((i + 0.5) * step);
            m_angle[size_t(i) + 1] = m_angle[size_t(i)] + 0.5 * e * e * step;
        }
    }
}

std::array<double, 2> ApertureSampler::operator()(double u1, double u2) const
{
    const Aperture& a = m_aperture;
    double phi, d = 1.0;
    if (a.m_kind == Aperture::Kind::Polygon) {
        const double s = u1 * a.m_blades;
        const int j    = std::min(a.m_blades - 1, int(s));
        const double f = (s - j) * kSectorSteps;
        const int i    = std::min(kSectorSteps - 1, int(f));
        const double t = m_angle[size_t(i)] + (m_angle[size_t(i) + 1] - m_angle[size_t(i)]) * (f - i);
        phi            = m_first_normal + j * m_sector + t;
        d              = polygon_edge_distance(a.m_blades, a.m_curvature, t + 0.5 * m_sector);  // t from the sector's normal
    } else if (a.m_kind == Aperture::Kind::Round) {
        phi = 2.0 * kPi * u1;
    } else {
        // The cell holding the share u1 of the area, then uniform in angle inside it.
        const double target = u1 * m_angle.back();
        const size_t i = std::min(size_t(kEdgeSteps - 1),
                                  size_t(std::upper_bound(m_angle.begin(), m_angle.end(), target) - m_angle.begin()) - 1);
        const double cell = m_angle[i + 1] - m_angle[i];
        const double f    = cell > 0.0 ? std::clamp((target - m_angle[i]) / cell, 0.0, 1.0) : 0.5;
        phi               = (double(i) + f) * (2.0 * kPi / kEdgeSteps);
        d                 = a.edge(phi);
    }
    const double r = d * std::sqrt(m_hole2 + (1.0 - m_hole2) * u2);
    // Unit circumradius, v up -> diameter 1 px, y down, height times the aspect.
    return { 0.5 * r * std::cos(phi), -0.5 * m_aspect * r * std::sin(phi) };
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
