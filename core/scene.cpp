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

#include <bokeh/parallel.h>
#include <bokeh/scene.h>

#include "plane.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/glm.hpp>
#include <OpenImageIO/strutil.h>

namespace bokeh {

namespace {

constexpr double kFocalMm       = 50.0;
constexpr double kSensorWidthMm = 36.0;
constexpr double kInf           = std::numeric_limits<double>::infinity();
constexpr double kPi            = 3.14159265358979323846;

// The lens each scene is meant to be defocused with. Thin-lens CoC diameter in pixels
// (SEEDS.md section 1), f = 50 mm, d0 = focus, F = f-number, at 1920 px wide:
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

// Small deterministic generator (SplitMix64), so scenes are identical everywhere.
struct Random {
    uint64_t state;
    double uniform()
    {
        uint64_t z = (state += 0x9E3779B97F4A7C15ull);
        z          = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z          = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return double((z ^ (z >> 31)) >> 11) * (1.0 / 9007199254740992.0);
    }
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
};

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

// Ray (origin at the camera) against an axis-aligned box; t is the entry parameter.
bool ray_box(const glm::dvec3& d, const glm::dvec3& lo, const glm::dvec3& hi, double& t)
{
    double tmin = 0.0, tmax = kInf;
    for (int a = 0; a < 3; ++a) {
        const double t0 = lo[a] / d[a], t1 = hi[a] / d[a];
        tmin = std::max(tmin, std::min(t0, t1));
        tmax = std::min(tmax, std::max(t0, t1));
    }
    t = tmin;
    return tmin <= tmax;
}

// Ray (origin at the camera) against a sphere; t is the nearer hit.
bool ray_sphere(const glm::dvec3& d, const glm::dvec3& c, double r, double& t)
{
    const double a = glm::dot(d, d), b = glm::dot(d, c), k = glm::dot(c, c) - r * r;
    const double disc = b * b - a * k;
    if (disc < 0.0)
        return false;
    t = (b - std::sqrt(disc)) / a;
    return t > 0.0;
}

// An emissive sphere, or ("edges") a disc lying on the wall at centre.z.
struct Light {
    glm::dvec3 centre;
    double radius;
    glm::dvec3 emission;  // linear RGB radiance
    int ybegin, yend;     // rows its image may touch
};

struct Surface {
    double z = kInf;
    glm::dvec3 colour{ 0.0 };
};

// What the scenes share: the pinhole camera, and lights that each know the image rows
// they can touch, so a row tests only its own few. A scene adds shade(px, py, lights).
class Scene {
public:
    explicit Scene(const SceneOptions& o)
        : m_opts(o)
        , m_half_w(0.5 * kSensorWidthMm / kFocalMm)
        , m_half_h(m_half_w * double(o.height) / double(o.width))
    {
    }

    const std::vector<Light>& lights() const { return m_lights; }

protected:
    // Ray through image position (px, py); z = 1, so a ray's parameter is its depth and
    // (x, y) are the tangents of its angles, the same scale horizontally and vertically.
    glm::dvec3 ray(double px, double py) const
    {
        const double u = (2.0 * px / m_opts.width - 1.0) * m_half_w;
        const double v = (1.0 - 2.0 * py / m_opts.height) * m_half_h;
        return { u, v, 1.0 };
    }

    // Image row of a ray slope dy/dz (row 0 at the top).
    double row_of(double slope) const
    {
        return (1.0 - slope / m_half_h) * 0.5 * double(m_opts.height);
    }

    // A light seen at frame position (sx, sy) in -1..1 (right, up) at depth z; its radius
    // is `size` of the half frame width, give or take 30%. Draws radius, brightness, hue,
    // in that order (see LightsScene).
    Light& add_light(Random& rng, double sx, double sy, double z, double size,
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

    // Rows each light's image can reach (its bounding sphere, projected, padded); call
    // once every light is in place.
    void find_light_rows()
    {
        for (Light& l : m_lights) {
            const double zc = std::max(l.centre.z - l.radius, 1e-3);
            const double y0 = (l.centre.y - l.radius) / zc, y1 = (l.centre.y + l.radius) / zc;
            l.ybegin = std::max(0, int(std::floor(row_of(std::max(y0, y1)))) - 1);
            l.yend   = std::min(m_opts.height, int(std::ceil(row_of(std::min(y0, y1)))) + 2);
        }
    }

    SceneOptions m_opts;
    double m_half_w, m_half_h;  // tangent of the half field of view
    std::vector<Light> m_lights;
};

class LightsScene : public Scene {
public:
    explicit LightsScene(const SceneOptions& o)
        : Scene(o)
    {
        // The draws are sequenced in the order GCC happened to evaluate them when this scene
        // was first written (z, y, x; brightness before hue), so its pixels have not changed.
        Random rng{ o.seed };
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

    Surface shade(double px, double py, const std::vector<const Light*>& lights) const
    {
        const glm::dvec3 d = ray(px, py);
        // Find the nearest surface first, then texture only that one.
        enum class What { Wall, Floor, Sphere, Post, Light } what = What::Wall;
        double z = kWallZ, t;
        const Light* lit = nullptr;
        if (d.y < 0.0 && kFloorY / d.y < z) {
            z    = kFloorY / d.y;
            what = What::Floor;
        }
        if (ray_sphere(d, kSphereCentre, kSphereRadius, t) && t < z) {
            z    = t;
            what = What::Sphere;
        }
        if (ray_box(d, kPostLo, kPostHi, t) && t < z) {
            z    = t;
            what = What::Post;
        }
        for (const Light* l : lights)
            if (ray_sphere(d, l->centre, l->radius, t) && t < z) {
                z    = t;
                what = What::Light;
                lit  = l;
            }
        Surface s;
        s.z                = z;
        const glm::dvec3 p = d * z;
        switch (what) {
        case What::Wall: {
            const double mortar = (std::fmod(std::abs(p.y) * 2.5, 1.0) < 0.08) ? 0.55 : 1.0;
            const double tex    = fbm(p.x * 1.5, p.y * 1.5, m_opts.seed + 10);
            s.colour = glm::dvec3(0.16, 0.13, 0.12) * (0.6 + 0.8 * tex) * mortar
                       + glm::dvec3(0.02, 0.03, 0.06) * std::max(0.0, p.y * 0.2);
            break;
        }
        case What::Floor: {
            const bool dark    = (int(std::floor(p.x)) + int(std::floor(p.z))) & 1;
            const double grout = (p.x - std::floor(p.x) < 0.04 || p.z - std::floor(p.z) < 0.04)
                                     ? 0.4 : 1.0;
            const double tex = fbm(p.x * 3.0, p.z * 3.0, m_opts.seed + 20);
            s.colour = (dark ? glm::dvec3(0.10, 0.09, 0.08) : glm::dvec3(0.32, 0.30, 0.27))
                       * (0.7 + 0.6 * tex) * grout;
            break;
        }
        case What::Sphere: {
            const glm::dvec3 n = glm::normalize(p - kSphereCentre);
            const double lambert =
                std::max(0.0, glm::dot(n, glm::normalize(glm::dvec3(-0.5, 0.7, -0.5))));
            const double stripes = 0.5 + 0.5 * std::sin(n.y * 18.0 + 3.0 * n.x);
            s.colour = glm::mix(glm::dvec3(0.6, 0.08, 0.05), glm::dvec3(0.55, 0.5, 0.42), stripes)
                       * (0.06 + 0.9 * lambert);
            break;
        }
        case What::Post: {
            const double grain = fbm(p.x * 60.0, p.y * 4.0, m_opts.seed + 30);
            s.colour           = glm::dvec3(0.09, 0.05, 0.03) * (0.6 + 0.8 * grain);
            break;
        }
        case What::Light: s.colour = lit->emission; break;
        }
        return s;
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
class EdgesScene : public Scene {
public:
    static constexpr double kFocusZ = 3.0;  // left panel and right wall, in focus
    static constexpr double kFarZ   = 30.0;
    static constexpr double kNearZ  = 1.2;

    explicit EdgesScene(const SceneOptions& o)
        : Scene(o)
        , m_edge_u(-0.1 * m_half_w)
        , m_corner_v(0.3 * m_half_h)
        , m_slant(std::tan(20.0 * kPi / 180.0))
        , m_near_u(0.5 * m_half_w)
    {
        Random rng{ o.seed };
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

    Surface shade(double px, double py, const std::vector<const Light*>& lights) const
    {
        const glm::dvec3 d = ray(px, py);
        enum class What { FarWall, FocusWall, Panel, NearPanel } what;
        double z;
        if (d.x >= m_near_u) {
            z    = kNearZ;
            what = What::NearPanel;
        } else if (d.x >= 0.0) {
            z    = kFocusZ;
            what = What::FocusWall;
        } else if (d.x <= m_edge_u && d.y <= m_corner_v + m_slant * (d.x - m_edge_u)) {
            z    = kFocusZ;
            what = What::Panel;
        } else {
            z    = kFarZ;
            what = What::FarWall;
        }
        Surface s;
        s.z                 = z;
        const glm::dvec3 p  = d * z;
        const uint32_t seed = m_opts.seed;
        switch (what) {
        case What::FarWall: {  // dim, so the discs' bokeh stand out
            const double tex = fbm(p.x * 0.5, p.y * 0.5, seed + 40);
            s.colour         = glm::dvec3(0.030, 0.032, 0.040) * (0.5 + tex);
            break;
        }
        case What::FocusWall: {  // checker (2.5 cm) above, print (1.2 cm glyphs) below
            bool ink;
            if (p.y >= 0.0)
                ink = (int(std::floor(p.x / 0.025)) + int(std::floor(p.y / 0.025))) & 1;
            else
                ink = print_ink(p.x - 0.01, p.y + 0.02, 0.012, seed + 41);
            s.colour = (ink ? glm::dvec3(0.03, 0.03, 0.035) : glm::dvec3(0.85, 0.83, 0.78))
                       * (0.85 + 0.3 * fbm(p.x * 20.0, p.y * 20.0, seed + 42));
            break;
        }
        case What::Panel: {  // painted board with graph-paper lines every 5 cm
            const double fx = p.x / 0.05 - std::floor(p.x / 0.05);
            const double fy = p.y / 0.05 - std::floor(p.y / 0.05);
            const double line = (fx < 0.04 || fy < 0.04) ? 0.35 : 1.0;
            const double tex  = fbm(p.x * 40.0, p.y * 40.0, seed + 43);
            s.colour          = glm::dvec3(0.30, 0.42, 0.46) * (0.6 + 0.8 * tex) * line;
            break;
        }
        case What::NearPanel: {  // saturated orange, ribbed every centimetre
            const double ribs = 0.85 + 0.15 * std::sin(p.x * (2.0 * kPi / 0.01));
            s.colour = glm::dvec3(0.95, 0.30, 0.02) * ribs
                       * (0.75 + 0.5 * fbm(p.x * 30.0, p.y * 8.0, seed + 44));
            break;
        }
        }
        if (what == What::FarWall || what == What::FocusWall)
            for (const Light* l : lights) {
                const double dx = p.x - l->centre.x, dy = p.y - l->centre.y;
                if (l->centre.z == z && dx * dx + dy * dy < l->radius * l->radius)
                    s.colour = l->emission;
            }
        return s;
    }

private:
    double m_edge_u;    // the left panel's vertical edge (ray tangent) ...
    double m_corner_v;  // ... up to its corner with the slanted top edge
    double m_slant;     // tan of the top edge's angle: it falls towards the left
    double m_near_u;    // the near panel's edge
};

class GiantScene : public Scene {
public:
    static constexpr double kCardZ = 0.5;  // in focus
    static constexpr double kWallZ = 60.0;

    explicit GiantScene(const SceneOptions& o)
        : Scene(o)
        , m_card_half_u(m_half_w / 3.0)
        , m_card_bottom_v(-0.7 * m_half_h)
        , m_card_top_v(0.6 * m_half_h)
    {
        Random rng{ o.seed };
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

    Surface shade(double px, double py, const std::vector<const Light*>& lights) const
    {
        const glm::dvec3 d = ray(px, py);
        enum class What { Wall, Card, Light } what = What::Wall;
        double z = kWallZ, t;
        const Light* lit = nullptr;
        if (std::abs(d.x) <= m_card_half_u && d.y >= m_card_bottom_v && d.y <= m_card_top_v) {
            z    = kCardZ;
            what = What::Card;
        }
        for (const Light* l : lights)
            if (ray_sphere(d, l->centre, l->radius, t) && t < z) {
                z    = t;
                what = What::Light;
                lit  = l;
            }
        Surface s;
        s.z                 = z;
        const glm::dvec3 p  = d * z;
        const uint32_t seed = m_opts.seed;
        switch (what) {
        case What::Wall: {
            const double tex = fbm(p.x * 0.4, p.y * 0.4, seed + 60);
            s.colour         = glm::dvec3(0.010, 0.012, 0.018) * (0.5 + tex);
            break;
        }
        case What::Card: {  // paper, a picture band at the top, print (3.5 mm glyphs) below
            const double margin = 0.006, half_x = m_card_half_u * kCardZ - margin;
            const double top = m_card_top_v * kCardZ - margin;
            const double grain = fbm(p.x * 400.0, p.y * 400.0, seed + 61);
            s.colour           = glm::dvec3(0.80, 0.76, 0.66) * (0.9 + 0.2 * grain);
            if (std::abs(p.x) < half_x && p.y > top - 0.03 && p.y < top) {
                const double hue = fbm(p.x * 60.0, p.y * 60.0, seed + 62);
                const double tex = fbm(p.x * 300.0, p.y * 300.0, seed + 63);
                s.colour = glm::mix(glm::dvec3(0.70, 0.15, 0.10), glm::dvec3(0.10, 0.35, 0.60), hue)
                           * (0.6 + 0.5 * tex);
            } else if (std::abs(p.x) < half_x && p.y < top - 0.036
                       && p.y > m_card_bottom_v * kCardZ + margin
                       && print_ink(p.x + half_x, p.y - (top - 0.036), 0.0035, seed + 64)) {
                s.colour = glm::dvec3(0.05, 0.05, 0.06);
            }
            break;
        }
        case What::Light: s.colour = lit->emission; break;
        }
        return s;
    }

private:
    double m_card_half_u, m_card_bottom_v, m_card_top_v;  // the card's outline (ray tangent)
};

// Colour: the mean of aa x aa stratified samples; Z: the nearest sample. Rows are
// independent, so the result does not depend on the thread count.
template<class SceneType>
void render(OIIO::ImageBuf& buf, const SceneType& scene, int aa, int nthreads)
{
    const int width = buf.spec().width;
    parallel_rows(buf.roi(), nthreads, [&](int y0, int y1) {
        std::vector<const Light*> row_lights;
        for (int y = y0; y < y1; ++y) {
            row_lights.clear();
            for (const Light& l : scene.lights())
                if (y >= l.ybegin && y < l.yend)
                    row_lights.push_back(&l);
            float* out = static_cast<float*>(buf.pixeladdr(0, y));
            for (int x = 0; x < width; ++x, out += 5) {
                glm::dvec3 sum(0.0);
                double zmin = kInf;
                for (int j = 0; j < aa; ++j)
                    for (int i = 0; i < aa; ++i) {
                        const Surface s = scene.shade(x + (i + 0.5) / aa, y + (j + 0.5) / aa,
                                                      row_lights);
                        sum += s.colour;
                        zmin = std::min(zmin, s.z);
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

bool make_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                int nthreads)
{
    const SceneInfo* info = find_scene(name);
    if (!info) {
        dst.errorfmt("unknown scene '{}' (known: {})", name,
                     OIIO::Strutil::join(scene_names(), ", "));
        return false;
    }
    if (opts.width < 1 || opts.height < 1 || opts.width > 32768 || opts.height > 32768) {
        dst.errorfmt("scene size {}x{} is outside 1x1 .. 32768x32768", opts.width, opts.height);
        return false;
    }
    if (opts.aa < 1 || opts.aa > 16) {
        dst.errorfmt("scene aa={} is outside 1..16", opts.aa);
        return false;
    }
    OIIO::ImageSpec spec(opts.width, opts.height, 5, OIIO::TypeFloat);
    spec.channelnames  = { "R", "G", "B", "A", "Z" };
    spec.alpha_channel = 3;
    spec.z_channel     = 4;
    spec.attribute("bokeh:scene", name);
    spec.attribute("bokeh:focal_mm", float(kFocalMm));
    spec.attribute("bokeh:sensor_width_mm", float(kSensorWidthMm));
    spec.attribute("bokeh:depth_unit", "m");
    spec.attribute("bokeh:focus_m", float(info->focus_m));
    spec.attribute("bokeh:fstop", float(info->fstop));
    spec.attribute("oiio:ColorSpace", "lin_rec709");
    OIIO::ImageBuf buf(spec);
    detail::require_pixels(buf);

    if (name == "lights")
        render(buf, LightsScene(opts), opts.aa, nthreads);
    else if (name == "edges")
        render(buf, EdgesScene(opts), opts.aa, nthreads);
    else
        render(buf, GiantScene(opts), opts.aa, nthreads);
    dst = std::move(buf);
    return true;
}

}  // namespace bokeh
