// aperture.h — the shapes light is spread with. The Aperture first: an opening as the
// distance from its centre to its edge at each polar angle (the radial LUT of Kawase's
// "Bokeh Deep Dive": "distort the radial coordinate with a LUT"). It is the one
// description of an opening: the kernels' exact weights test points against it, the
// lens-character PSFs draw with its edge, and the thin-lens truth draws pupil points from
// its area (ApertureSampler). Then the kernels (Kernel: box, Gaussian, an aperture, or one
// of OIIO's filters, with a size) and their exact weights, which every blur and the
// defocus's layers use.
//
// An Aperture's coordinates are the pupil's, normalised so the circumscribed circle has radius 1, x
// right and y up; the polar angle phi is measured from +x, counter-clockwise. A point at
// radius r and angle phi is inside when hole * edge(phi) <= r < edge(phi). Every shape
// here is star-shaped about its centre (each ray from the centre crosses the edge once),
// which is what an edge-distance function can describe; a picture that is not is
// described by its outer edge along each ray (its notches filled).
#pragma once

#include <bokeh/base.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

struct Kernel;

/// The anamorphic squeeze an aperture takes (bokeh height / width): every command and
/// options struct holds it to this range.
constexpr float kMinAspect = 0.05f;
constexpr float kMaxAspect = 20.0f;

/// The edge distance of a polygon of `blades` blades with circumradius 1, at angle
/// `phi_from_vertex` (radians) from one of its vertices: cos(pi/N) / cos(psi), psi the
/// angle from the nearest edge normal; curved blades blend it toward the circle,
/// d + curvature (1 - d). The rule a polygon Aperture's edge follows.
double polygon_edge_distance(int blades, double curvature, double phi_from_vertex);

class Aperture {
public:
    /// A round aperture (edge 1 everywhere).
    Aperture() = default;

    /// A bladed opening: `blades` (3..64) straight blades (curvature 0) bulging to the
    /// circle (curvature 1), rotated by `rotation_deg` (0: a vertex straight up), with a
    /// catadioptric hole of `hole` (0..<1) of the edge distance. False + `err`.
    static bool polygon(int blades, double curvature, double rotation_deg, double hole, Aperture& out,
                        std::string& err);

    /// The aperture a kernel describes: Disk (with its hole), Polygon (blades, rotation,
    /// curvature, hole) or Opening (the kernel's own Aperture); its size and aspect are the
    /// PSF's business, not the aperture's. False + `err` for other shapes or invalid
    /// parameters.
    static bool from_kernel(const Kernel& k, Aperture& out, std::string& err);

    /// A star ("shuriken") of `points` points whose inner vertices lie at `inner_ratio`
    /// of the outer ones (0.1..1), rotated by `rotation_deg` (0: a point straight up).
    static bool star(int points, double inner_ratio, double rotation_deg, Aperture& out,
                     std::string& err);

    /// An aperture from a picture: the pixels whose alpha (or, without alpha, whose mean
    /// of the colour channels) is at least half the picture's largest are the opening;
    /// its centre is the opening's centroid; the edge along each of 1024 rays is the
    /// farthest opening pixel along that ray, scaled so the farthest is 1. A hole is not
    /// read from a picture. False + `err` for an empty, non-finite or tiny (< 8 px across)
    /// opening.
    static bool from_picture(const OIIO::ImageBuf& picture, Aperture& out, std::string& err);

    /// The edge distance at polar angle `phi` (radians), in (0, 1].
    double edge(double phi) const;
    /// The smallest edge distance over all angles (a polygon's apothem).
    double min_edge() const { return m_min_edge; }
    /// The catadioptric hole, a fraction of the edge distance (0 = none).
    double hole() const { return m_hole; }
    /// Round: the edge distance is 1 at every angle (a hole is allowed).
    bool round() const { return m_kind == Kind::Round; }
    /// Whether (x, y) is in the opening: hole * edge <= r < edge. A polygon of up to 32
    /// blades is tested against its blades' normals (no angle computed): the kernels' exact
    /// weights test thousands of points a boundary pixel.
    bool inside(double x, double y) const;
    /// Convex without its hole (round, or a polygon whose blades bulge to the circle): the
    /// kernels' weights then count each row of samples as one run.
    bool convex() const { return m_kind == Kind::Round || m_kind == Kind::Polygon; }
    /// The opening's area at circumradius 1, hole removed (pi for a round one).
    double area() const;
    /// The same opening turned half a turn about its centre: the bokeh in front of focus,
    /// where the rays cross before the sensor.
    Aperture point_reflected() const;
    /// The cosine of the angle between the ray at `phi` and the edge's normal where the
    /// ray crosses it (1 for a circle; cos(psi) on a polygon's blade): a distance along
    /// the ray times it is the distance across the edge.
    double edge_normal_cos(double phi) const;

    /// "round", "6 blades", "star 5", "picture", for messages.
    std::string describe() const;

    /// The same opening: kind, blades, curvature, rotation, star ratio, hole and table.
    bool operator==(const Aperture& o) const;
    bool operator!=(const Aperture& o) const { return !(*this == o); }

private:
    friend class ApertureSampler;
    enum class Kind { Round, Polygon, Star, Table };
    Kind m_kind = Kind::Round;
    int m_blades = 0;
    double m_curvature = 0.0, m_vertex_rad = 0.0, m_inner_ratio = 1.0;
    double m_hole = 0.0, m_min_edge = 1.0, m_apothem = 1.0;
    std::vector<float> m_table;  ///< Table: edge distance at phi = 2 pi i / size
    /// Polygon of up to 32 blades: its blades' unit normals (derived from the above).
    std::vector<std::pair<double, double>> m_normals;
};

/// Area-uniform points of an aperture. A point (u1, u2) of the unit square maps by angle
/// (u1, through the inverse of the area's cumulative distribution over the polar angle)
/// and radius (u2, by sqrt for equal area, the hole removed), so stratified points stay
/// stratified. A polygon's sectors take equal shares of u1 and its cumulative area inside
/// a sector is closed-form (tabulated inverse at 4097 nodes); any other edge's is
/// integrated from edge(phi)^2 / 2 at 8192 angles.
class ApertureSampler {
public:
    ApertureSampler(const Aperture& aperture, float aspect);
    /// The offset, in px per px of CoC, of the aperture of diameter 1 px (x right, y down,
    /// height times the aspect): the kernel of width |c| is the set of offsets times |c|.
    std::array<double, 2> operator()(double u1, double u2) const;
    /// The shape's area at diameter 1 (pi/4 times the aspect for a disk without a hole).
    double area() const { return m_area; }

private:
    Aperture m_aperture;
    double m_sector = 0.0, m_first_normal = 0.0;  ///< a polygon's sector angle, its first normal
    double m_hole2 = 0.0, m_aspect = 1.0, m_area = 0.0;
    /// A polygon: the inverse CDF of the angle within a sector, at equal steps of area;
    /// another edge: the cumulative area at equal steps of angle.
    std::vector<double> m_angle;
};

enum class KernelShape {
    Box,       ///< rectangle, exact area weights for fractional sizes
    Gaussian,  ///< sigma = width / 4 as in oiiotool (or Kernel::sigma_px); anti-aliased:
               ///< not truncated; hard edge: oiiotool's, truncated at the footprint
    Disk,      ///< circle / ellipse
    Polygon,   ///< N straight or curved blades
    Opening,   ///< any other Aperture (Kernel::opening: a star, a picture), sized as a disk
    Filter,    ///< one of OIIO's named filters (Kernel::filter, oiio_filter_names()): the
               ///< weights of make_kernel(filter, width, height), as oiiotool's
               ///< `--blur:kernel=NAME`; exact methods only (separable ones by rows and
               ///< columns, the others by FFT)
};

/// How the kernel's edge is sampled.
enum class KernelEdge {
    Antialiased,  ///< each pixel weighted by the area of it inside the shape
    Hard,         ///< the shape sampled at whole-pixel offsets, OIIO's make_kernel rule:
                  ///< disk, polygon and box 0/1 by the pixel centre, the Gaussian its
                  ///< value there, cut at the footprint (|x| < width / 2)
};

struct Kernel {
    KernelShape shape = KernelShape::Disk;
    float width_px  = 0.0f;  ///< full footprint; 0 x 0 is the identity
    float height_px = 0.0f;
    float sigma_px  = 0.0f;  ///< Gaussian: > 0 overrides width / 4 (and height / 4)
    int blades      = 6;     ///< Polygon: number of aperture blades (3..64)
    float rotation_deg = 0.0f;  ///< Polygon: rotation; 0 puts a vertex straight up
    float curvature    = 0.0f;  ///< Polygon: 0 straight blades .. 1 a circle
    float hole         = 0.0f;  ///< Disk/Polygon: catadioptric hole, fraction of the radius
    KernelEdge edge    = KernelEdge::Antialiased;
    std::string filter;  ///< Filter: its name (triangle, lanczos3, ...; see oiio_filter_names())
    Aperture opening;    ///< Opening: the aperture (its own rotation and hole)
};
/// The names KernelShape::Filter takes: OIIO's 2-D filters and make_kernel's "binomial",
/// less those the other shapes are (box, gaussian, disk: theirs with a hard edge).
std::vector<std::string> oiio_filter_names();

/// A kernel's normalised weights on a (2 rx + 1) x (2 ry + 1) grid centred on (0, 0).
struct KernelWeights {
    int rx = 0, ry = 0;
    std::vector<double> w;  ///< row-major, sum 1
    double at(int dx, int dy) const { return w[size_t((dy + ry) * (2 * rx + 1) + (dx + rx))]; }
    bool is_identity() const { return rx == 0 && ry == 0; }
};

/// The Gaussian's sigma along x and y in pixels: `sigma_px` if set, else width / 4 and
/// height / 4 (oiiotool's width-to-sigma rule for `--blur:kernel=gaussian WxH`).
std::pair<double, double> gaussian_sigma(const Kernel& k);

/// Check a kernel's parameters; false + `err` naming the bad one.
bool check_kernel(const Kernel& k, std::string& err);

/// Check an aperture as the depth-defocus methods take it: the kernel's shape at unit size
/// (each depth's CoC sets the size) and the anamorphic aspect (bokeh height / width,
/// kMinAspect..kMaxAspect). False + `err` naming the bad one.
bool check_aperture(const Kernel& aperture, float aspect, std::string& err);

/// The kernel's bokeh in front of focus, where the rays cross before the sensor: its
/// aperture turned half a turn (a polygon's rotation + 180 degrees, an opening's
/// point_reflected(); a disk, box, Gaussian or filter is its own).
Kernel point_reflected(const Kernel& k);

/// The exact weights of `k` (what every exact method computes with). Anti-aliased edges
/// use 64 x 64 stratified samples per boundary pixel (area error below 3e-4 of a pixel).
/// `nthreads` as for the blurs; the weights do not depend on it.
KernelWeights kernel_weights(const Kernel& k, int nthreads = 0);

/// One-dimensional weights of the separable shapes, centred, sum 1.
std::vector<double> box_weights_1d(double width_px);
std::vector<double> gaussian_weights_1d(double sigma_px);
/// The box's or the Gaussian's weights along x and along y under its edge rule (each
/// centred, sum 1): anti-aliased, box_weights_1d and gaussian_weights_1d; hard, OIIO's
/// make_kernel("box" | "gaussian", width, height) factors: samples at whole offsets, the
/// box's where |i| <= width / 2, the Gaussian's exp(-i^2 / 2 sigma^2) where |i| < width / 2
/// (no width: 4 sigma); a separable Filter, its make_kernel weights' column and row sums.
/// Shapes that are not separable (is_separable): {1}, {1}.
std::pair<std::vector<double>, std::vector<double>> separable_weights(const Kernel& k);
/// Box, Gaussian, and the Filters OIIO calls separable (and binomial).
bool is_separable(const Kernel& k);


}  // namespace bokeh
