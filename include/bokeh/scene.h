// scene.h — built-in synthetic test scenes with known depth.
//
// Real footage rarely holds bright point lights at known depths, yet those are what
// bokeh is judged on: the real test images hold few. These scenes are generated, so the
// depth of every pixel, and therefore the exact defocus reference, is known.
//
//   lights  fairy lights at 1.3..35 m over a floor and wall (40 m), an in-focus sphere at
//           6 m, a foreground post at 1.6 m.
//   edges   occlusion at depth edges, flat planes at 1.2, 3 and 30 m only: an in-focus
//           panel (3 m) over a far wall of HDR lights, some partly hidden by its edges; a
//           near panel (1.2 m) over an in-focus wall with fine checker and print.
//   giant   giant bokeh: an in-focus card at 0.5 m, HDR lights at 0.15..0.25 m and a
//           string of lights at 5..50 m over a dim wall at 60 m.
//
// Three renders of each: the sharp pinhole image (make_scene), the thin-lens truth traced
// against the scene's own geometry (make_scene_truth), and a deep image holding the
// surfaces behind the visible ones (make_deep_scene), so that the chain geometry truth ->
// deep truth (truth.h) -> deep defocus -> flat defocus is measured on known scenes
// (docs/deep.md, "The chain on known scenes").
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

#include <bokeh/aperture.h>
#include <bokeh/base.h>
#include <bokeh/lens.h>

namespace bokeh {

struct SceneOptions {
    int width  = 1920;
    int height = 1080;
    int aa     = 3;      ///< supersamples per axis for colour; depth keeps the nearest sample
    uint32_t seed = 1;   ///< texture and light placement
};

/// The names make_scene accepts.
std::vector<std::string> scene_names();

/// One-line description of a scene, for --help.
std::string scene_description(const std::string& name);

/// Render scene `name` into `dst`: float R, G, B, A, Z; Z is camera distance in metres.
/// The camera is recorded in the metadata ("bokeh:focal_mm", "bokeh:sensor_width_mm",
/// "bokeh:depth_unit"), and so is the lens setting the scene is meant to be defocused
/// with ("bokeh:focus_m", "bokeh:fstop"). Deterministic for a given name, options and
/// seed, whatever the thread count. False + error on `dst` for an unknown name or absurd
/// size.
bool make_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                int nthreads = 0);
/// What make_scene() checks: a known name, 1..32768 px a side, aa 1..16. False + `err`.
bool check_scene_options(const std::string& name, const SceneOptions& opts, std::string& err);
inline OIIO::ImageBuf make_scene(const std::string& name, const SceneOptions& opts, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    make_scene(dst, name, opts, nthreads);
    return dst;
}

/// A scene's camera and the lens setting it is meant to be defocused with.
struct SceneCamera {
    double focal_mm = 0.0, sensor_width_mm = 0.0;
    double focus_m = 0.0, fstop = 0.0;
};
/// False for an unknown name.
bool scene_camera(const std::string& name, SceneCamera& camera);

/// The thin lens of a geometric truth, as --defocus takes it.
struct SceneTruthOptions {
    /// Focal length, f-number, film-back width and focus distance (metres: depth_unit_mm
    /// must be 1000, the scenes' unit). The CoC is thin_lens_coc_px's for an image as wide
    /// as the scene, with no gains, in-focus range or limit.
    Lens lens;
    Kernel aperture;      ///< disk, polygon (blades, rotation, curvature, hole) or an opening; size ignored
    float aspect = 1.0f;  ///< bokeh height / width, 0.05..20
    int spp      = 64;    ///< rays a pixel, 1..1048576; two halves for the noise estimate
    uint32_t seed = 1;    ///< the sampler's scramble (truth.h's; the scene's own seed is SceneOptions')
    /// Called with the fraction done (0..1), from one thread at a time, in rising order.
    std::function<void(float)> progress;
};

struct SceneTruthReport {
    int64_t rays = 0;
    double seconds = 0.0;
    float min_coc_px = 0.0f, max_coc_px = 0.0f;  ///< at the nearest and farthest depths met
    /// The noise estimate of truth.h's TruthReport (two half renders' difference): RMS
    /// over R, G, B, A and its PSNR after the tone map x / (1 + |x|); -1 for spp 1.
    double noise_rmse = -1.0, noise_psnr_db = -1.0;
    std::string summary;  ///< one line
};

/// The thin-lens truth of scene `name`: each pixel the mean of `spp` rays from points of
/// the aperture through the pixel's point on the focus plane, each taking the colour of
/// the first surface it meets in the scene's geometry (no deep image, no CoC layers).
/// float R, G, B, A over the frame (A is 1: every ray meets the back wall), the scene's
/// metadata. The rays are those of defocus_truth (truth.h) for the same lens, aperture,
/// spp and seed: the same per-pixel sampler, sensor point P and aperture offset s (px per
/// px of CoC), and a ray meets the depth of signed CoC c at image position P - s c (front
/// bokeh point-reflected, y down); so the two compare pixel for pixel, their difference
/// being what the deep image leaves out. Bit-identical for any thread count. False + error
/// on `dst` for an unknown scene, bad size or bad options.
bool make_scene_truth(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                      const SceneTruthOptions& lens, SceneTruthReport* report = nullptr, int nthreads = 0);
/// What make_scene_truth() checks of the lens before it renders: metres, a positive
/// focal length, f-number and film back, focus beyond the focal length, the aperture and
/// the rays a pixel. False + `err` naming the option.
bool check_scene_truth_options(const SceneTruthOptions& lens, std::string& err);
inline OIIO::ImageBuf make_scene_truth(const std::string& name, const SceneOptions& opts, const SceneTruthOptions& lens,
                                       SceneTruthReport* report = nullptr, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    make_scene_truth(dst, name, opts, lens, report, nthreads);
    return dst;
}

/// A deep image of scene `name` (R, G, B, A, Z float point samples, premultiplied, tidy):
/// per pixel, the surfaces its aa x aa pinhole rays meet, the visible ones first and then,
/// layer after layer, the ones behind them. Layer 1 groups each ray's first surface by
/// surface, alpha = the group's rays / the rays not yet taken by a nearer group (so the
/// flatten is the sharp scene: each surface weighs its share of the rays), colour the mean
/// of the group's hits, Z the nearest of them. Layer k + 1 does the same with each ray's
/// next surface deeper than every sample of layer k (hidden behind its full opacity, so
/// the flatten does not see it). Surfaces a ray meets in front of the pixel's deepest
/// visible sample are left out: point samples cannot hold them without showing through.
bool make_deep_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                     int nthreads = 0);
inline OIIO::ImageBuf make_deep_scene(const std::string& name, const SceneOptions& opts, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    make_deep_scene(dst, name, opts, nthreads);
    return dst;
}

}  // namespace bokeh
