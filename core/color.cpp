// color.cpp — OCIO config choice and colour conversion of images (via OIIO's ColorConfig).
//
// Conversions unpremultiply around the transform (IBA::colorconvert's unpremult), as a
// non-linear encoding such as sRGB must be applied to colour, not to colour * alpha.

#include <bokeh/color.h>

#include <cstdlib>

#include <OpenImageIO/color.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

struct ColorSystem::Impl {
    std::unique_ptr<OIIO::ColorConfig> config;
};

ColorSystem::ColorSystem()
    : m_impl(new Impl)
{
}

ColorSystem::~ColorSystem() = default;

std::string resolve_color_config(const std::string& explicit_path, const std::string& shipped_path)
{
    if (!explicit_path.empty())
        return explicit_path;
    const char* env = std::getenv("OCIO");
    if (env && *env)
        return env;
    return shipped_path;
}

bool ColorSystem::load(const std::string& config_path, std::string& err)
{
    if (!OIIO::Filesystem::is_regular(config_path)) {
        err = format("colour config '{}' does not exist", config_path);
        return false;
    }
    auto config = std::make_unique<OIIO::ColorConfig>(config_path);
    if (config->has_error()) {
        err = format("colour config '{}': {}", config_path,
                     OIIO::Strutil::strip(config->geterror()));
        return false;
    }
    const char* linear = config->getColorSpaceNameByRole("scene_linear");
    if (!linear || !*linear) {
        err = format("colour config '{}' has no scene_linear role", config_path);
        return false;
    }
    const char* display = config->getColorSpaceNameByRole("color_picking");
    m_scene_linear      = linear;
    m_display           = display && *display ? display : "sRGB";
    m_path              = config_path;
    m_impl->config      = std::move(config);
    return true;
}

bool ColorSystem::has(const std::string& name) const
{
    if (!m_impl->config || name.empty())
        return false;
    for (const std::string& n : m_impl->config->getColorSpaceNames())
        if (n == name)
            return true;
    // Roles and aliases resolve inside OCIO: a processor to itself exists only for a
    // name the config knows.
    return bool(m_impl->config->createColorProcessor(name, m_scene_linear));
}

std::vector<std::string> ColorSystem::names() const
{
    return m_impl->config ? m_impl->config->getColorSpaceNames() : std::vector<std::string>();
}

std::string ColorSystem::space_of_file(const OIIO::ImageSpec& native) const
{
    const OIIO::TypeDesc t = native.format;
    const bool display_referred = t.basetype == OIIO::TypeDesc::UINT8
                                  || t.basetype == OIIO::TypeDesc::UINT16
                                  || t.basetype == OIIO::TypeDesc::INT8
                                  || t.basetype == OIIO::TypeDesc::INT16;
    return display_referred ? m_display : m_scene_linear;
}

bool ColorSystem::convert(OIIO::ImageBuf& img, const std::string& from, const std::string& to,
                          int nthreads, std::string& err) const
{
    if (!m_impl->config) {
        err = "no colour config loaded";
        return false;
    }
    for (const std::string& name : { from, to })
        if (!has(name)) {
            err = format("unknown colour space '{}' (config {} has: {})", name, m_path,
                         OIIO::Strutil::join(names(), ", "));
            return false;
        }
    if (from == to)
        return true;
    if (img.deep()) {
        err = "colour conversion of deep images is not supported; flatten first";
        return false;
    }
    OIIO::ImageBuf result;
    if (!OIIO::ImageBufAlgo::colorconvert(result, img, from, to, true, "", "",
                                          m_impl->config.get(), {}, nthreads)) {
        err = format("cannot convert from '{}' to '{}': {}", from, to, result.geterror());
        return false;
    }
    img.swap(result);
    return true;
}

}  // namespace bokeh
