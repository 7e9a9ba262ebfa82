// color.h — colour handling: which OCIO config, what a file's pixels are, conversions.
//
// All filtering happens in scene-linear light (docs/io.md, "Colour"). EXR and other float
// files are taken as scene-linear; 8/16-bit display images as sRGB. The config is the
// one the user names, else $OCIO, else the small config shipped in ocio/. OpenColorIO 2.1
// has no built-in configs, hence the shipped file.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// Pick the config file: `explicit_path` if given, else $OCIO if set, else `shipped_path`.
std::string resolve_color_config(const std::string& explicit_path,
                                 const std::string& shipped_path);

/// One layer's colour channels: R, G, B (and the alpha that covers them, -1 when none).
struct ColorChannels {
    std::string layer;  ///< "" for the unprefixed R, G, B; "diffuse" for diffuse.R, ...
    int r = -1, g = -1, b = -1, a = -1;
};

/// The colour channels of `spec`: every layer with R, G and B, except layers whose names
/// say they hold data (N, P, normal, position, motion, velocity, uv, ...). A layer's
/// alpha is its own "A", else the image's "A". Depth, IDs and any other channel are not
/// colour.
std::vector<ColorChannels> color_channel_groups(const OIIO::ImageSpec& spec);

class ColorSystem {
public:
    ColorSystem();
    ~ColorSystem();
    ColorSystem(const ColorSystem&)            = delete;
    ColorSystem& operator=(const ColorSystem&) = delete;

    /// Load an OCIO config. False + `err` if it cannot be read or lacks a scene_linear role.
    bool load(const std::string& config_path, std::string& err);
    const std::string& config_path() const { return m_path; }

    /// The scene-linear working space (the config's scene_linear role).
    const std::string& scene_linear() const { return m_scene_linear; }
    /// The space assumed for display-referred integer files (role color_picking, else "sRGB").
    const std::string& display_default() const { return m_display; }
    bool has(const std::string& name) const;
    std::vector<std::string> names() const;
    /// True when `name` holds scene-referred linear light (its conversion to the working
    /// space is linear: ACEScg, lin_rec709, raw); false for an encoding such as sRGB.
    /// A float file is written in such a space as it is; in any other it is converted.
    bool is_scene_linear(const std::string& name) const;

    /// The space a file's pixels are in, judged from its native spec: float and half data
    /// are scene-linear, integer data display-referred (OIIO calls every EXR "Linear",
    /// a label we do not use: it names no primaries).
    std::string space_of_file(const OIIO::ImageSpec& native) const;

    /// Convert the colour channels of `img` (color_channel_groups) in place; every other
    /// channel, alpha and depth included, keeps its bits. Premultiplied colour is
    /// unpremultiplied around the transform.
    bool convert(OIIO::ImageBuf& img, const std::string& from, const std::string& to,
                 int nthreads, std::string& err) const;

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
    std::string m_path, m_scene_linear, m_display;
};

}  // namespace bokeh
