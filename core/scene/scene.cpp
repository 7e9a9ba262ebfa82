// scene.cpp — built-in synthetic scenes with known depth, ray cast through a pinhole.
//
// "lights": fairy lights (small emissive spheres, HDR 20..300) at depths 1.3..35 m, a
// string of them receding from near-left to far-right; a textured floor (continuous depth
// 2..40 m) and back wall (40 m); an in-focus sphere at 6 m; a foreground post at 1.6 m
// that occludes part of the scene.
//
// "edges": occlusion at depth edges; every surface is a plane facing the camera, so the
// only depths are 1.2, 3 and 30 m. Left half: an in-focus textured panel at 3 m over the
// lower left 45% of the width (a vertical right edge, a top edge slanted 20 degrees) in
// front of a dim wall at 30 m with a grid of HDR discs (50..500), some of them straddling
// the panel's edges. Right half: an out-of-focus orange panel at 1.2 m over the right 25%
// (a vertical edge) in front of an in-focus wall at 3 m with a fine checker, text-like
// print and a few HDR discs, one mostly behind the near panel.
//
// "giant": a giant-bokeh close-up: an in-focus printed card at 0.5 m over the middle third,
// five HDR lights at 0.15..0.25 m (huge front bokeh), a string of lights receding from
// 5 to 50 m (large back bokeh), a dim wall at 60 m.
//
// The camera is a 50 mm lens on a 36 mm-wide sensor; the metadata also records the focus
// distance and f-number each scene is meant to be defocused with (kScenes below).
//
// Colour is averaged over aa x aa stratified samples per pixel; depth (Z, camera-space
// distance along the optical axis, metres) is the nearest of those samples, as renderers'
// "closest" depth filter gives. Known limit: alpha is 1 everywhere (nothing is empty).
//
// Each scene is its geometry (scene_geometry.h: the surfaces a ray from any point of the
// lens plane meets, and their colours), so the same scene also gives its thin-lens truth
// (scene_truth.cpp) and its deep image (scene_deep.cpp); the pinhole rays test the
// surfaces in the order they always have, so the sharp pixels are those of before.

#include <bokeh/base.h>
#include <bokeh/parallel.h>
#include <bokeh/scene.h>

#include "base/numbers.h"
#include "base/plane.h"
#include "scene/scene_geometry.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/glm.hpp>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using detail::HitList;
using detail::Light;
using detail::SceneGeometry;
using detail::SceneHit;
using detail::SceneRandom;
using detail::SceneRay;

namespace {

constexpr double kFocalMm       = 50.0;
constexpr double kSensorWidthMm = 36.0;
using detail::kInf;

// The lens each scene is meant to be defocused with. Thin-lens CoC diameter in pixels
// (docs/methods/optics.md, "The thin lens"), f = 50 mm, d0 = focus, F = f-number, at
// 1920 px wide:
//   CoC_px(d) = |d - d0| / d * f^2 / (F (d0 - f)) / (sensor_width_mm / image_width_px)
//   lights: d0 = 6 m,   F = 1.27: nearest light (1.3 m) 63.8 px, back wall (40 m) 15.0 px.
//   edges:  d0 = 3 m,   F = 1.06: near panel (1.2 m) 64.0 px, far wall (30 m) 38.4 px.
//   giant:  d0 = 0.5 m, F = 2:    nearest light (0.15 m) 346 px (32% of 1080 rows),
//           0.25 m 148 px, far lights (5..50 m) 133..147 px, wall (60 m) 147 px.
struct SceneInfo {
    const char* name;
    double focus_m;
    double fstop;
    const char* description;
};

constexpr SceneInfo kScenes[] = {
    { "lights", 6.0, 1.27,
      "fairy lights at 1.3-35 m over a textured floor and wall, an in-focus sphere at 6 m, "
      "a foreground post at 1.6 m" },
    { "edges", 3.0, 1.06,
      "depth edges: left, an in-focus panel at 3 m (vertical and 20-degree edges) over a "
      "30 m wall with a grid of HDR lights; right, a near panel at 1.2 m over an in-focus "
      "3 m wall with fine checker and print" },
    { "giant", 0.5, 2.0,
      "giant bokeh: an in-focus card at 0.5 m, HDR lights at 0.15-0.25 m and a string of "
      "lights at 5-50 m, dim wall at 60 m" },
};

const SceneInfo* find_scene(const std::string& name)
{
    for (const SceneInfo& s : kScenes)
        if (name == s.name)
            return &s;
    return nullptr;
}

// Value noise on an integer lattice, smoothly interpolated; fbm sums three octaves.
double lattice(int x, int y, uint32_t seed)
{
    uint32_t h = uint32_t(x) * 374761393u + uint32_t(y) * 668265263u + seed * 2246822519u;
    h          = (h ^ (h >> 13)) * 1274126177u;
    return double((h ^ (h >> 16)) & 0xFFFFu) / 65535.0;
}

double value_noise(double x, double y, uint32_t seed)
{
    const double fx = std::floor(x), fy = std::floor(y);
    const int ix = int(fx), iy = int(fy);
    double tx = x - fx, ty = y - fy;
    tx        = tx * tx * (3.0 - 2.0 * tx);
    ty        = ty * ty * (3.0 - 2.0 * ty);
    const double a = lattice(ix, iy, seed), b = lattice(ix + 1, iy, seed);
    const double c = lattice(ix, iy + 1, seed), d = lattice(ix + 1, iy + 1, seed);
    return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty;
}

double fbm(double x, double y, uint32_t seed)
{
    return 0.5 * value_noise(x, y, seed) + 0.3 * value_noise(2.1 * x, 2.1 * y, seed + 1)
           + 0.2 * value_noise(4.3 * x, 4.3 * y, seed + 2);
}

// Text-like print: the finest high-contrast detail a focus plane carries. Lines of blocky
// glyphs (3 strokes by 5 rows, random per glyph) with spaces between words; (x, y) in
// metres on the surface, lines running down from y = 0; `glyph` is the glyph height.
bool print_ink(double x, double y, double glyph, uint32_t seed)
{
    const double line    = -y / (1.8 * glyph);  // glyph plus 0.8 glyph of leading
    const double ln      = std::floor(line);
    const double in_line = (line - ln) * 1.8;
    if (in_line >= 1.0)
        return false;
    const double cell   = x / (0.75 * glyph);  // 3 strokes and a gap
    const double cl     = std::floor(cell);
    const int stroke    = int((cell - cl) * 4.0);
    if (stroke >= 3 || lattice(int(cl), int(ln), seed) < 0.2)
        return false;
    const int row = int(in_line * 5.0);
    return lattice(int(cl) * 4 + stroke, int(ln) * 8 + row, seed + 1) < 0.5;
}

// Ray against an axis-aligned box; t is the entry depth.
bool ray_box(const SceneRay& r, const glm::dvec3& lo, const glm::dvec3& hi, double& t)
{
    double tmin = 0.0, tmax = kInf;
    for (int a = 0; a < 3; ++a) {
        const double t0 = (lo[a] - r.origin[a]) / r.dir[a], t1 = (hi[a] - r.origin[a]) / r.dir[a];
        tmin = std::max(tmin, std::min(t0, t1));
        tmax = std::min(tmax, std::max(t0, t1));
    }
    t = tmin;
    return tmin <= tmax;
}

// Ray against a sphere; t is the nearer hit's depth.
bool ray_sphere(const SceneRay& r, const glm::dvec3& centre, double radius, double& t)
{
    const glm::dvec3 c = centre - r.origin;
    const glm::dvec3& d = r.dir;
    const double a = glm::dot(d, d), b = glm::dot(d, c), k = glm::dot(c, c) - radius * radius;
    const double disc = b * b - a * k;
    if (disc < 0.0)
        return false;
    t = (b - std::sqrt(disc)) / a;
    return t > 0.0;
}

// Where a ray at depth z is, in ray tangents (image-plane units): a plane facing the
// camera has there the shape it has in the image.
glm::dvec2 tangent_at(const SceneRay& r, double z)
{
    return { r.dir.x + r.origin.x / z, r.dir.y + r.origin.y / z };
}

class LightsScene : public SceneGeometry {
public:
    explicit LightsScene(const SceneOptions& o)
        : SceneGeometry(o)
    {
        // The draws are sequenced in the order GCC happened to evaluate them when this scene
        // was first written (z, y, x; brightness before hue), so its pixels have not changed.
        SceneRandom rng{ o.seed };
        // A string receding from near-left to far-right, sagging between its ends.
        for (int i = 0; i < 28; ++i) {
            const double t = (i + 0.5) / 28.0;
            add_light(rng, -0.85 + 1.6 * t, 0.55 - 0.3 * std::sin(3.14159265 * t),
                      2.5 * std::pow(12.0, t), 0.0018, 20.0, 300.0);
        }
        for (int i = 0; i < 24; ++i) {  // scattered far lights
            const double z = rng.uniform(8.0, 35.0), sy = rng.uniform(-0.2, 0.9);
            add_light(rng, rng.uniform(-0.95, 0.95), sy, z, 0.0015, 20.0, 300.0);
        }
        for (int i = 0; i < 6; ++i) {  // a few near ones: the giant bokeh
            const double z = rng.uniform(1.3, 2.2), sy = rng.uniform(-0.8, 0.8);
            add_light(rng, rng.uniform(-0.9, 0.9), sy, z, 0.002, 20.0, 300.0);
        }
        find_light_rows();
    }

    enum Surfaces { Wall, Floor, Sphere, Post, Lit };

    void intersect(const SceneRay& r, const std::vector<const Light*>& lights, HitList& out) const override
    {
        // The floor ends at the wall, the wall at the floor (below it no ray could see it,
        // and a deep image would hold it as a hidden surface); every other surface is in
        // front of the wall.
        double t       = kInf;
        const bool floor = r.dir.y < 0.0 && (t = (kFloorY - r.origin.y) / r.dir.y) < kWallZ;
        if (!floor || r.origin.y + r.dir.y * kWallZ >= kFloorY)
            out.add(kWallZ, Wall);
        if (floor)
            out.add(t, Floor);
        if (ray_sphere(r, kSphereCentre, kSphereRadius, t))
            out.add(t, Sphere);
        if (ray_box(r, kPostLo, kPostHi, t))
            out.add(t, Post);
        for (const Light* l : lights)
            if (ray_sphere(r, l->centre, l->radius, t))
                out.add(t, Lit, l);
    }

    glm::dvec3 colour(const SceneRay& r, const SceneHit& h, const std::vector<const Light*>&) const override
    {
        const glm::dvec3 p = r.origin + r.dir * h.z;
        switch (h.surface) {
        case Wall: {
            const double mortar = (std::fmod(std::abs(p.y) * 2.5, 1.0) < 0.08) ? 0.55 : 1.0;
            const double tex    = fbm(p.x * 1.5, p.y * 1.5, m_opts.seed + 10);
            return glm::dvec3(0.16, 0.13, 0.12) * (0.6 + 0.8 * tex) * mortar
                   + glm::dvec3(0.02, 0.03, 0.06) * std::max(0.0, p.y * 0.2);
        }
        case Floor: {
            const bool dark    = (int(std::floor(p.x)) + int(std::floor(p.z))) & 1;
            const double grout = (p.x - std::floor(p.x) < 0.04 || p.z - std::floor(p.z) < 0.04)
                                     ? 0.4 : 1.0;
            const double tex = fbm(p.x * 3.0, p.z * 3.0, m_opts.seed + 20);
            return (dark ? glm::dvec3(0.10, 0.09, 0.08) : glm::dvec3(0.32, 0.30, 0.27))
                   * (0.7 + 0.6 * tex) * grout;
        }
        case Sphere: {
            const glm::dvec3 n = glm::normalize(p - kSphereCentre);
            const double lambert =
                std::max(0.0, glm::dot(n, glm::normalize(glm::dvec3(-0.5, 0.7, -0.5))));
            const double stripes = 0.5 + 0.5 * std::sin(n.y * 18.0 + 3.0 * n.x);
            return glm::mix(glm::dvec3(0.6, 0.08, 0.05), glm::dvec3(0.55, 0.5, 0.42), stripes)
                   * (0.06 + 0.9 * lambert);
        }
        case Post: {
            const double grain = fbm(p.x * 60.0, p.y * 4.0, m_opts.seed + 30);
            return glm::dvec3(0.09, 0.05, 0.03) * (0.6 + 0.8 * grain);
        }
        default: return h.light->emission;
        }
    }

private:
    static constexpr double kWallZ  = 40.0;   // back wall, metres
    static constexpr double kFloorY = -1.6;   // floor height below the camera
    static constexpr double kSphereRadius = 0.6;
    static inline const glm::dvec3 kSphereCentre{ 0.8, -0.5, 6.0 };  // in focus
    static inline const glm::dvec3 kPostLo{ -0.40, -1.6, 1.6 };      // foreground occluder
    static inline const glm::dvec3 kPostHi{ -0.32, 3.0, 1.7 };
};

// The panels and walls are tested in ray-tangent space (the ray's x, y), where a plane
// facing the camera has the shape it has in the image, edges and angles included.
class EdgesScene : public SceneGeometry {
public:
    static constexpr double kFocusZ = 3.0;  // left panel and right wall, in focus
    static constexpr double kFarZ   = 30.0;
    static constexpr double kNearZ  = 1.2;

    explicit EdgesScene(const SceneOptions& o)
        : SceneGeometry(o)
        , m_edge_u(-0.1 * m_half_w)
        , m_corner_v(0.3 * m_half_h)
        , m_slant(std::tan(20.0 * kPi / 180.0))
        , m_near_u(0.5 * m_half_w)
    {
        SceneRandom rng{ o.seed };
        // A grid of discs over the far wall's half; it goes on behind the panel.
        for (int j = 0; j < 10; ++j)
            for (int i = 0; i < 10; ++i)
                add_light(rng, -0.95 + 0.1 * i, 0.9 - 0.2 * j, kFarZ, 0.003, 50.0, 500.0);
        // Discs straddling the panel's edges, moved off the edge by a fraction of their
        // radius (outwards if positive), so each is partly hidden by the in-focus panel.
        const double straddle[] = { 0.5, -0.3, 0.0, 0.3, -0.5 };
        for (int k = 0; k < 5; ++k) {  // the vertical edge, below the corner
            const double sy = m_corner_v / m_half_h - 0.22 * (k + 0.6);
            Light& l        = add_light(rng, m_edge_u / m_half_w, sy, kFarZ, 0.004, 50.0, 500.0);
            l.centre.x += straddle[k] * l.radius;
        }
        const glm::dvec2 along(-std::cos(20.0 * kPi / 180.0), -std::sin(20.0 * kPi / 180.0));
        const glm::dvec2 outwards(along.y, -along.x);  // away from the panel
        for (int k = 0; k < 4; ++k) {  // the slanted edge, left of the corner
            const glm::dvec2 on_edge =
                glm::dvec2(m_edge_u, m_corner_v) + (0.12 + 0.22 * k) * m_half_w * along;
            Light& l = add_light(rng, on_edge.x / m_half_w, on_edge.y / m_half_h, kFarZ, 0.004,
                                 50.0, 500.0);
            l.centre += glm::dvec3(outwards * (straddle[k + 1] * l.radius), 0.0);
        }
        // A few on the in-focus wall, and one mostly behind the near panel's edge.
        for (int k = 0; k < 5; ++k) {
            const double sx = rng.uniform(0.06, 0.42), sy = rng.uniform(-0.85, 0.85);
            add_light(rng, sx, sy, kFocusZ, 0.003, 50.0, 500.0);
        }
        Light& hidden = add_light(rng, 0.5, 0.1, kFocusZ, 0.004, 50.0, 500.0);
        hidden.centre.x += 0.3 * hidden.radius;
        find_light_rows();
    }

    enum Surfaces { FarWall, FocusWall, Panel, NearPanel };

    void intersect(const SceneRay& r, const std::vector<const Light*>&, HitList& out) const override
    {
        out.add(kFarZ, FarWall);
        const glm::dvec2 focus = tangent_at(r, kFocusZ);
        if (focus.x >= 0.0)
            out.add(kFocusZ, FocusWall);
        else if (focus.x <= m_edge_u && focus.y <= m_corner_v + m_slant * (focus.x - m_edge_u))
            out.add(kFocusZ, Panel);
        if (tangent_at(r, kNearZ).x >= m_near_u)
            out.add(kNearZ, NearPanel);
    }

    glm::dvec3 colour(const SceneRay& r, const SceneHit& h, const std::vector<const Light*>& lights) const override
    {
        const double z      = h.z;
        const glm::dvec3 p  = r.origin + r.dir * z;
        const uint32_t seed = m_opts.seed;
        glm::dvec3 colour;
        switch (h.surface) {
        case FarWall: {  // dim, so the discs' bokeh stand out
            const double tex = fbm(p.x * 0.5, p.y * 0.5, seed + 40);
            colour           = glm::dvec3(0.030, 0.032, 0.040) * (0.5 + tex);
            break;
        }
        case FocusWall: {  // checker (2.5 cm) above, print (1.2 cm glyphs) below
            bool ink;
            if (p.y >= 0.0)
                ink = (int(std::floor(p.x / 0.025)) + int(std::floor(p.y / 0.025))) & 1;
            else
                ink = print_ink(p.x - 0.01, p.y + 0.02, 0.012, seed + 41);
            colour = (ink ? glm::dvec3(0.03, 0.03, 0.035) : glm::dvec3(0.85, 0.83, 0.78))
                     * (0.85 + 0.3 * fbm(p.x * 20.0, p.y * 20.0, seed + 42));
            break;
        }
        case Panel: {  // painted board with graph-paper lines every 5 cm
            const double fx = p.x / 0.05 - std::floor(p.x / 0.05);
            const double fy = p.y / 0.05 - std::floor(p.y / 0.05);
            const double line = (fx < 0.04 || fy < 0.04) ? 0.35 : 1.0;
            const double tex  = fbm(p.x * 40.0, p.y * 40.0, seed + 43);
            colour            = glm::dvec3(0.30, 0.42, 0.46) * (0.6 + 0.8 * tex) * line;
            break;
        }
        default: {  // the near panel: saturated orange, ribbed every centimetre
            const double ribs = 0.85 + 0.15 * std::sin(p.x * (2.0 * kPi / 0.01));
            colour = glm::dvec3(0.95, 0.30, 0.02) * ribs
                     * (0.75 + 0.5 * fbm(p.x * 30.0, p.y * 8.0, seed + 44));
            break;
        }
        }
        if (h.surface == FarWall || h.surface == FocusWall)
            for (const Light* l : lights) {
                const double dx = p.x - l->centre.x, dy = p.y - l->centre.y;
                if (l->centre.z == z && dx * dx + dy * dy < l->radius * l->radius)
                    colour = l->emission;
            }
        return colour;
    }

private:
    double m_edge_u;    // the left panel's vertical edge (ray tangent) ...
    double m_corner_v;  // ... up to its corner with the slanted top edge
    double m_slant;     // tan of the top edge's angle: it falls towards the left
    double m_near_u;    // the near panel's edge
};

class GiantScene : public SceneGeometry {
public:
    static constexpr double kCardZ = 0.5;  // in focus
    static constexpr double kWallZ = 60.0;

    explicit GiantScene(const SceneOptions& o)
        : SceneGeometry(o)
        , m_card_half_u(m_half_w / 3.0)
        , m_card_bottom_v(-0.7 * m_half_h)
        , m_card_top_v(0.6 * m_half_h)
    {
        SceneRandom rng{ o.seed };
        // Near lights placed by hand so their huge bokeh stay mostly inside the frame.
        const glm::dvec3 near_lights[] = { { -0.72, 0.5, 0.15 }, { 0.6, -0.45, 0.18 },
                                    { 0.12, 0.62, 0.2 },  { -0.25, -0.7, 0.22 },
                                    { 0.82, 0.55, 0.25 } };
        for (const glm::dvec3& n : near_lights)
            add_light(rng, n.x, n.y, n.z, 0.006, 200.0, 1000.0);
        // A string receding from 5 m (left) to 50 m (right), partly behind the card.
        for (int i = 0; i < 24; ++i) {
            const double t = (i + 0.5) / 24.0;
            add_light(rng, -0.95 + 1.9 * t, 0.75 - 0.35 * std::sin(kPi * t),
                      5.0 * std::pow(10.0, t), 0.0025, 100.0, 600.0);
        }
        find_light_rows();
    }

    enum Surfaces { Wall, Card, Lit };

    void intersect(const SceneRay& r, const std::vector<const Light*>& lights, HitList& out) const override
    {
        out.add(kWallZ, Wall);
        const glm::dvec2 card = tangent_at(r, kCardZ);
        if (std::abs(card.x) <= m_card_half_u && card.y >= m_card_bottom_v && card.y <= m_card_top_v)
            out.add(kCardZ, Card);
        double t;
        for (const Light* l : lights)
            if (ray_sphere(r, l->centre, l->radius, t))
                out.add(t, Lit, l);
    }

    glm::dvec3 colour(const SceneRay& r, const SceneHit& h, const std::vector<const Light*>&) const override
    {
        const glm::dvec3 p  = r.origin + r.dir * h.z;
        const uint32_t seed = m_opts.seed;
        switch (h.surface) {
        case Wall: {
            const double tex = fbm(p.x * 0.4, p.y * 0.4, seed + 60);
            return glm::dvec3(0.010, 0.012, 0.018) * (0.5 + tex);
        }
        case Card: {  // paper, a picture band at the top, print (3.5 mm glyphs) below
            const double margin = 0.006, half_x = m_card_half_u * kCardZ - margin;
            const double top = m_card_top_v * kCardZ - margin;
            const double grain = fbm(p.x * 400.0, p.y * 400.0, seed + 61);
            glm::dvec3 colour  = glm::dvec3(0.80, 0.76, 0.66) * (0.9 + 0.2 * grain);
            if (std::abs(p.x) < half_x && p.y > top - 0.03 && p.y < top) {
                const double hue = fbm(p.x * 60.0, p.y * 60.0, seed + 62);
                const double tex = fbm(p.x * 300.0, p.y * 300.0, seed + 63);
                colour = glm::mix(glm::dvec3(0.70, 0.15, 0.10), glm::dvec3(0.10, 0.35, 0.60), hue)
                         * (0.6 + 0.5 * tex);
            } else if (std::abs(p.x) < half_x && p.y < top - 0.036
                       && p.y > m_card_bottom_v * kCardZ + margin
                       && print_ink(p.x + half_x, p.y - (top - 0.036), 0.0035, seed + 64)) {
                colour = glm::dvec3(0.05, 0.05, 0.06);
            }
            return colour;
        }
        default: return h.light->emission;
        }
    }

private:
    double m_card_half_u, m_card_bottom_v, m_card_top_v;  // the card's outline (ray tangent)
};

// Colour: the mean of aa x aa stratified samples; Z: the nearest sample. Rows are
// independent, so the result does not depend on the thread count.
void render(OIIO::ImageBuf& buf, const SceneGeometry& scene, int aa, int nthreads)
{
    const int width = buf.spec().width;
    parallel_rows(buf.roi(), nthreads, [&](int y0, int y1) {
        std::vector<const Light*> row_lights;
        HitList hits;
        for (int y = y0; y < y1; ++y) {
            scene.lights_of_row(y, row_lights);
            float* out = static_cast<float*>(buf.pixeladdr(0, y));
            for (int x = 0; x < width; ++x, out += 5) {
                glm::dvec3 sum(0.0);
                double zmin = kInf;
                for (int j = 0; j < aa; ++j)
                    for (int i = 0; i < aa; ++i) {
                        const SceneRay r = scene.ray(x + (i + 0.5) / aa, y + (j + 0.5) / aa);
                        hits.reset(false);
                        scene.intersect(r, row_lights, hits);
                        sum += scene.colour(r, hits.nearest, row_lights);
                        zmin = std::min(zmin, hits.nearest.z);
                    }
                sum /= double(aa * aa);
                out[0] = float(sum.r);
                out[1] = float(sum.g);
                out[2] = float(sum.b);
                out[3] = 1.0f;
                out[4] = float(zmin);
            }
        }
    });
}

}  // namespace

// --- what the scenes share -----------------------------------------------------------

namespace detail {

SceneGeometry::SceneGeometry(const SceneOptions& o)
    : m_opts(o)
    , m_half_w(0.5 * kSensorWidthMm / kFocalMm)
    , m_half_h(m_half_w * double(o.height) / double(o.width))
{
}

// z = 1, so a ray's parameter is its depth and (x, y) are the tangents of its angles, the
// same scale horizontally and vertically.
SceneRay SceneGeometry::ray(double px, double py) const
{
    SceneRay r;
    r.dir = { (2.0 * px / m_opts.width - 1.0) * m_half_w, (1.0 - 2.0 * py / m_opts.height) * m_half_h, 1.0 };
    return r;
}

double SceneGeometry::row_of(double slope) const
{
    return (1.0 - slope / m_half_h) * 0.5 * double(m_opts.height);
}

Light& SceneGeometry::add_light(SceneRandom& rng, double sx, double sy, double z, double size,
                                double emission_lo, double emission_hi)
{
    static const glm::dvec3 palette[] = { { 1.0, 0.78, 0.45 }, { 1.0, 0.25, 0.15 },
                                          { 0.3, 1.0, 0.35 },  { 0.3, 0.45, 1.0 },
                                          { 1.0, 0.55, 0.1 },  { 1.0, 1.0, 1.0 } };
    Light l;
    l.centre   = { sx * z * m_half_w, sy * z * m_half_h, z };
    l.radius   = size * z * m_half_w * rng.uniform(0.7, 1.3);
    const double brightness = rng.uniform(emission_lo, emission_hi);
    l.emission = palette[size_t(rng.uniform() * 5.999)] * brightness;
    m_lights.push_back(l);
    return m_lights.back();
}

void SceneGeometry::find_light_rows()
{
    for (Light& l : m_lights) {
        const double zc = std::max(l.centre.z - l.radius, 1e-3);
        const double y0 = (l.centre.y - l.radius) / zc, y1 = (l.centre.y + l.radius) / zc;
        l.ybegin = std::max(0, int(std::floor(row_of(std::max(y0, y1)))) - 1);
        l.yend   = std::min(m_opts.height, int(std::ceil(row_of(std::min(y0, y1)))) + 2);
    }
}

void SceneGeometry::widen_light_rows(const std::function<double(const Light&)>& extra)
{
    for (Light& l : m_lights) {
        const int rows = int(std::ceil(extra(l)));
        l.ybegin       = std::max(0, l.ybegin - rows);
        l.yend         = std::min(m_opts.height, l.yend + rows);
    }
}

void SceneGeometry::lights_of_row(int y, std::vector<const Light*>& out) const
{
    out.clear();
    for (const Light& l : m_lights)
        if (y >= l.ybegin && y < l.yend)
            out.push_back(&l);
}

std::unique_ptr<SceneGeometry> make_scene_geometry(const std::string& name, const SceneOptions& o)
{
    if (name == "lights")
        return std::make_unique<LightsScene>(o);
    if (name == "edges")
        return std::make_unique<EdgesScene>(o);
    if (name == "giant")
        return std::make_unique<GiantScene>(o);
    return nullptr;
}

bool scene_spec(const std::string& name, const SceneOptions& opts, const std::vector<std::string>& channels,
                OIIO::ImageSpec& spec, std::string& err)
{
    if (!check_scene_options(name, opts, err))
        return false;
    const SceneInfo* info = find_scene(name);
    spec = OIIO::ImageSpec(opts.width, opts.height, int(channels.size()), OIIO::TypeFloat);
    spec.channelnames  = channels;
    spec.alpha_channel = 3;
    spec.z_channel     = channels.size() > 4 ? 4 : -1;
    spec.attribute("bokeh:scene", name);
    spec.attribute("bokeh:focal_mm", float(kFocalMm));
    spec.attribute("bokeh:sensor_width_mm", float(kSensorWidthMm));
    spec.attribute("bokeh:depth_unit", "m");
    spec.attribute("bokeh:focus_m", float(info->focus_m));
    spec.attribute("bokeh:fstop", float(info->fstop));
    spec.attribute("oiio:ColorSpace", "lin_rec709");
    return true;
}

}  // namespace detail

// --- the public entry points ---------------------------------------------------------

bool check_scene_options(const std::string& name, const SceneOptions& opts, std::string& err)
{
    if (!find_scene(name)) {
        err = OIIO::Strutil::fmt::format("unknown scene '{}' (known: {})", name,
                                         OIIO::Strutil::join(scene_names(), ", "));
        return false;
    }
    if (opts.width < 1 || opts.height < 1 || opts.width > 32768 || opts.height > 32768) {
        err = OIIO::Strutil::fmt::format("scene size {}x{} is outside 1x1 .. 32768x32768", opts.width,
                                         opts.height);
        return false;
    }
    if (opts.aa < 1 || opts.aa > 16) {
        err = OIIO::Strutil::fmt::format("scene aa={} is outside 1..16", opts.aa);
        return false;
    }
    return true;
}

std::vector<std::string> scene_names()
{
    std::vector<std::string> names;
    for (const SceneInfo& s : kScenes)
        names.push_back(s.name);
    return names;
}

std::string scene_description(const std::string& name)
{
    const SceneInfo* s = find_scene(name);
    if (!s)
        return {};
    return OIIO::Strutil::fmt::format("{} (50 mm lens, 36 mm sensor; meant for focus {} m at f/{})",
                                      s->description, s->focus_m, s->fstop);
}

bool scene_camera(const std::string& name, SceneCamera& camera)
{
    const SceneInfo* s = find_scene(name);
    if (!s)
        return false;
    camera.focal_mm        = kFocalMm;
    camera.sensor_width_mm = kSensorWidthMm;
    camera.focus_m         = s->focus_m;
    camera.fstop           = s->fstop;
    return true;
}

bool make_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                int nthreads)
{
    OIIO::ImageSpec spec;
    std::string err;
    if (!detail::scene_spec(name, opts, { "R", "G", "B", "A", "Z" }, spec, err)) {
        dst.errorfmt("{}", err);
        return false;
    }
    OIIO::ImageBuf buf(spec);
    detail::require_pixels(buf);
    render(buf, *detail::make_scene_geometry(name, opts), opts.aa, nthreads);
    dst = std::move(buf);
    return true;
}

}  // namespace bokeh
