// scene.cpp — built-in synthetic scenes with known depth, ray cast through a pinhole.
//
// "lights": fairy lights (small emissive spheres, HDR 20..300) at depths 1.3..35 m, a
// string of them receding from near-left to far-right; a textured floor (continuous depth
// 2..40 m) and back wall (40 m); an in-focus sphere at 6 m; a foreground post at 1.6 m
// that occludes part of the scene. The camera is a 50 mm lens on a 36 mm-wide sensor.
//
// Colour is averaged over aa x aa stratified samples per pixel; depth (Z, camera-space
// distance along the optical axis, metres) is the nearest of those samples, as renderers'
// "closest" depth filter gives. Known limit: alpha is 1 everywhere (nothing is empty).

#include <bokeh/parallel.h>
#include <bokeh/scene.h>

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

class LightsScene {
public:
    LightsScene(const SceneOptions& o)
        : m_opts(o)
        , m_half_w(0.5 * kSensorWidthMm / kFocalMm)
        , m_half_h(m_half_w * double(o.height) / double(o.width))
    {
        Random rng{ o.seed };
        const glm::dvec3 palette[] = { { 1.0, 0.78, 0.45 }, { 1.0, 0.25, 0.15 },
                                       { 0.3, 1.0, 0.35 },  { 0.3, 0.45, 1.0 },
                                       { 1.0, 0.55, 0.1 },  { 1.0, 1.0, 1.0 } };
        auto add = [&](double sx, double sy, double z, double size) {
            Light l;
            l.centre   = { sx * z * m_half_w, sy * z * m_half_h, z };
            l.radius   = size * z * m_half_w * rng.uniform(0.7, 1.3);
            l.emission = palette[size_t(rng.uniform() * 5.999)] * rng.uniform(20.0, 300.0);
            m_lights.push_back(l);
        };
        // A string receding from near-left to far-right, sagging between its ends.
        for (int i = 0; i < 28; ++i) {
            const double t = (i + 0.5) / 28.0;
            add(-0.85 + 1.6 * t, 0.55 - 0.3 * std::sin(3.14159265 * t),
                2.5 * std::pow(12.0, t), 0.0018);
        }
        for (int i = 0; i < 24; ++i)  // scattered far lights
            add(rng.uniform(-0.95, 0.95), rng.uniform(-0.2, 0.9), rng.uniform(8.0, 35.0), 0.0015);
        for (int i = 0; i < 6; ++i)  // a few near ones: the giant bokeh
            add(rng.uniform(-0.9, 0.9), rng.uniform(-0.8, 0.8), rng.uniform(1.3, 2.2), 0.002);

        // Rows each light's image can reach (its bounding sphere, projected, padded).
        for (Light& l : m_lights) {
            const double zc = std::max(l.centre.z - l.radius, 1e-3);
            const double y0 = (l.centre.y - l.radius) / zc, y1 = (l.centre.y + l.radius) / zc;
            l.ybegin = std::max(0, int(std::floor(row_of(std::max(y0, y1)))) - 1);
            l.yend   = std::min(o.height, int(std::ceil(row_of(std::min(y0, y1)))) + 2);
        }
    }

    // Image row of a ray slope dy/dz (row 0 at the top).
    double row_of(double slope) const
    {
        return (1.0 - slope / m_half_h) * 0.5 * double(m_opts.height);
    }

    Surface shade(double px, double py, const std::vector<const Light*>& lights) const
    {
        const double u = (2.0 * px / m_opts.width - 1.0) * m_half_w;
        const double v = (1.0 - 2.0 * py / m_opts.height) * m_half_h;
        const glm::dvec3 d(u, v, 1.0);  // z = 1: a ray's parameter is its depth
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

    const std::vector<Light>& lights() const { return m_lights; }

private:
    static constexpr double kWallZ  = 40.0;   // back wall, metres
    static constexpr double kFloorY = -1.6;   // floor height below the camera
    static constexpr double kSphereRadius = 0.6;
    static inline const glm::dvec3 kSphereCentre{ 0.8, -0.5, 6.0 };  // in focus
    static inline const glm::dvec3 kPostLo{ -0.40, -1.6, 1.6 };      // foreground occluder
    static inline const glm::dvec3 kPostHi{ -0.32, 3.0, 1.7 };

    static bool ray_box(const glm::dvec3& d, const glm::dvec3& lo, const glm::dvec3& hi,
                        double& t)
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

    static bool ray_sphere(const glm::dvec3& d, const glm::dvec3& c, double r, double& t)
    {
        const double a = glm::dot(d, d), b = glm::dot(d, c), k = glm::dot(c, c) - r * r;
        const double disc = b * b - a * k;
        if (disc < 0.0)
            return false;
        t = (b - std::sqrt(disc)) / a;
        return t > 0.0;
    }

    SceneOptions m_opts;
    double m_half_w, m_half_h;  // tangent of the half field of view
    std::vector<Light> m_lights;
};

}  // namespace

std::vector<std::string> scene_names() { return { "lights" }; }

std::string scene_description(const std::string& name)
{
    if (name == "lights")
        return "fairy lights at 1.3-35 m over a textured floor and wall, an in-focus "
               "sphere at 6 m, a foreground post at 1.6 m (50 mm lens, 36 mm sensor)";
    return {};
}

bool make_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                int nthreads)
{
    using OIIO::Strutil::fmt::format;
    if (name != "lights") {
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
    spec.attribute("oiio:ColorSpace", "lin_rec709");
    OIIO::ImageBuf buf(spec);

    const LightsScene scene(opts);
    const int aa = opts.aa;
    parallel_rows(buf.roi(), nthreads, [&](int y0, int y1) {
        std::vector<const Light*> row_lights;
        for (int y = y0; y < y1; ++y) {
            row_lights.clear();
            for (const Light& l : scene.lights())
                if (y >= l.ybegin && y < l.yend)
                    row_lights.push_back(&l);
            float* out = static_cast<float*>(buf.pixeladdr(0, y));
            for (int x = 0; x < opts.width; ++x, out += 5) {
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
    dst = std::move(buf);
    return true;
}

}  // namespace bokeh
