// scene.h — built-in synthetic test scenes with known depth.
//
// Real footage rarely holds bright point lights at known depths, yet those are what
// bokeh is judged on (REFERENCE.md, "Test data"). These scenes are generated, so the
// depth of every pixel, and therefore the exact defocus reference, is known.
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
/// "bokeh:depth_unit"). Deterministic for a given name, options and seed, whatever the
/// thread count. False + error on `dst` for an unknown name or absurd size.
bool make_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                int nthreads = 0);

}  // namespace bokeh
