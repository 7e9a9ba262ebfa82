// color.h — colour handling: which OCIO config, what a file's pixels are, conversions.
//
// All filtering happens in scene-linear light (DESIGN.md, "Colour"). EXR and other float
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

    /// The space a file's pixels are in, judged from its native spec: float and half data
    /// are scene-linear, integer data display-referred (OIIO calls every EXR "Linear",
    /// a label we do not use; DESIGN.md).
    std::string space_of_file(const OIIO::ImageSpec& native) const;

    /// Convert the colour channels of `img` in place. Alpha and depth are untouched;
    /// premultiplied colour is unpremultiplied around the transform.
    bool convert(OIIO::ImageBuf& img, const std::string& from, const std::string& to,
                 int nthreads, std::string& err) const;

private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
    std::string m_path, m_scene_linear, m_display;
};

}  // namespace bokeh
