// scene_geometry.h — internal to the library: the built-in scenes' geometry as rays meet
// it, shared by the pinhole render (scene.cpp), the thin-lens truth (scene_truth.cpp) and
// the deep image (scene_deep.cpp).
//
// A ray has an origin on the lens plane (z = 0; the camera centre for the pinhole) and a
// direction with z = 1, so a ray's parameter is the depth it has reached. Every surface is
// opaque; a scene reports either the nearest surface along a ray or all of them (the
// front faces of spheres and boxes, each plane once), in the order the pinhole render has
// always tested them so that its pixels do not change.
#pragma once

#include <bokeh/scene.h>

#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <OpenImageIO/imagebuf.h>

namespace bokeh::detail {

struct SceneRay {
    glm::dvec3 origin{ 0.0 };  ///< on the lens plane, metres
    glm::dvec3 dir{ 0.0, 0.0, 1.0 };  ///< dir.z == 1: the parameter is the depth
};

// Small deterministic generator (SplitMix64), so scenes are identical everywhere.
struct SceneRandom {
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

// An emissive sphere, or ("edges") a disc lying on the wall at centre.z.
struct Light {
    glm::dvec3 centre;
    double radius;
    glm::dvec3 emission;  // linear RGB radiance
    int ybegin, yend;     // rows whose rays may touch it
};

/// One surface a ray meets: its depth, which surface (a scene's own numbering; lights by
/// `light`), and the light when it is one.
struct SceneHit {
    double z          = std::numeric_limits<double>::infinity();
    int surface       = -1;
    const Light* light = nullptr;
};

/// What a scene's intersect() fills: only the nearest hit (the first met wins a tie, as
/// the pinhole render always did), or every hit (sorted by depth afterwards).
struct HitList {
    bool all = false;
    SceneHit nearest;
    std::vector<SceneHit> hits;
    void reset(bool every)
    {
        all     = every;
        nearest = SceneHit{};
        hits.clear();
    }
    void add(double z, int surface, const Light* light = nullptr)
    {
        if (all)
            hits.push_back({ z, surface, light });
        else if (z < nearest.z)
            nearest = { z, surface, light };
    }
};

class SceneGeometry {
public:
    explicit SceneGeometry(const SceneOptions& o);
    virtual ~SceneGeometry() = default;

    const std::vector<Light>& lights() const { return m_lights; }
    const SceneOptions& options() const { return m_opts; }

    /// The pinhole ray through image position (px, py) (pixels, y down).
    SceneRay ray(double px, double py) const;
    /// Ray tangent per pixel (the same horizontally and vertically).
    double tangent_per_px() const { return 2.0 * m_half_w / double(m_opts.width); }

    /// Let each light's rows reach `extra(light)` more rows on either side (rays from an
    /// aperture reach past the light's pinhole image by half its CoC).
    void widen_light_rows(const std::function<double(const Light&)>& extra);
    /// The lights whose rows hold row y.
    void lights_of_row(int y, std::vector<const Light*>& out) const;

    /// The surfaces `r` meets, among the scene's fixed surfaces and `lights`.
    virtual void intersect(const SceneRay& r, const std::vector<const Light*>& lights, HitList& out) const = 0;
    /// The colour (linear RGB radiance) of the surface `h` where `r` meets it; `lights` as
    /// intersect() had them (discs painted on a wall are the wall's colour).
    virtual glm::dvec3 colour(const SceneRay& r, const SceneHit& h, const std::vector<const Light*>& lights) const = 0;

protected:
    // Image row of a ray slope dy/dz (row 0 at the top).
    double row_of(double slope) const;
    // A light seen at frame position (sx, sy) in -1..1 (right, up) at depth z; its radius
    // is `size` of the half frame width, give or take 30%. Draws radius, brightness, hue,
    // in that order.
    Light& add_light(SceneRandom& rng, double sx, double sy, double z, double size, double emission_lo,
                     double emission_hi);
    // Rows each light's image can reach (its bounding sphere, projected, padded); call
    // once every light is in place.
    void find_light_rows();

    SceneOptions m_opts;
    double m_half_w, m_half_h;  // tangent of the half field of view
    std::vector<Light> m_lights;
};

/// The geometry of scene `name` (one of scene_names()), or null.
std::unique_ptr<SceneGeometry> make_scene_geometry(const std::string& name, const SceneOptions& o);

/// The spec of a render of scene `name`: float `channels` (R, G, B, A first; Z fifth when
/// given) over the frame, with the scene's camera metadata. False + `err` for an unknown
/// name, an absurd size or aa.
bool scene_spec(const std::string& name, const SceneOptions& opts, const std::vector<std::string>& channels,
                OIIO::ImageSpec& spec, std::string& err);

}  // namespace bokeh::detail
