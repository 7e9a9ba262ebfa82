// scene.h — built-in synthetic test scenes with known depth.
//
// Real footage rarely holds bright point lights at known depths, yet those are what
// bokeh is judged on (REFERENCE.md, "Test data"). These scenes are generated, so the
// depth of every pixel, and therefore the exact defocus reference, is known.
//
//   lights  fairy lights at 1.3..35 m over a floor and wall (40 m), an in-focus sphere at
//           6 m, a foreground post at 1.6 m.
//   edges   occlusion at depth edges, flat planes at 1.2, 3 and 30 m only: an in-focus
//           panel (3 m) over a far wall of HDR lights, some partly hidden by its edges; a
//           near panel (1.2 m) over an in-focus wall with fine checker and print.
//   giant   giant bokeh: an in-focus card at 0.5 m, HDR lights at 0.15..0.25 m and a
//           string of lights at 5..50 m over a dim wall at 60 m.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

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

}  // namespace bokeh
