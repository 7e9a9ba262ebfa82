// aperture.h — an aperture as the distance from its centre to its edge at each polar
// angle (the radial LUT of Kawase's "Bokeh Deep Dive": "distort the radial coordinate
// with a LUT"), the description the lens-character PSFs draw with.
//
// Coordinates are the pupil's, normalised so the circumscribed circle has radius 1, x
// right and y up; the polar angle phi is measured from +x, counter-clockwise. A point at
// radius r and angle phi is inside when hole * edge(phi) <= r < edge(phi). Every shape
// here is star-shaped about its centre (each ray from the centre crosses the edge once),
// which is what an edge-distance function can describe; a picture that is not is
// described by its outer edge along each ray (its notches filled).
#pragma once

#include <bokeh/blur.h>

#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// The edge distance of a polygon of `blades` blades with circumradius 1, at angle
/// `phi_from_vertex` (radians) from one of its vertices: cos(pi/N) / cos(psi), psi the
/// angle from the nearest edge normal; curved blades blend it toward the circle,
/// d + curvature (1 - d). The rule blur.h's Polygon kernel draws with (core/kernel.cpp).
double polygon_edge_distance(int blades, double curvature, double phi_from_vertex);

class Aperture {
public:
    /// A round aperture (edge 1 everywhere).
    Aperture() = default;

    /// The aperture a blur kernel describes: Disk (with its hole) or Polygon (blades,
    /// rotation, curvature, hole); its size and aspect are the PSF's business, not the
    /// aperture's. False + `err` for other shapes or invalid parameters.
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
    bool inside(double x, double y) const;
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
    enum class Kind { Round, Polygon, Star, Table };
    Kind m_kind = Kind::Round;
    int m_blades = 0;
    double m_curvature = 0.0, m_vertex_rad = 0.0, m_inner_ratio = 1.0;
    double m_hole = 0.0, m_min_edge = 1.0;
    std::vector<float> m_table;  ///< Table: edge distance at phi = 2 pi i / size
};

}  // namespace bokeh
