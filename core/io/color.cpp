// color.cpp — OCIO config choice and colour conversion of images (via OIIO's ColorConfig).
//
// Conversions touch colour channels only: each layer's R, G, B (the unprefixed ones and
// "diffuse.R"-style AOVs), never depth, alpha, IDs or data layers (normals, positions,
// motion), which pass through bit for bit (ocio/README.md, "Which channels are colour"). Colour is
// unpremultiplied around the transform (IBA::colorconvert's unpremult), as a non-linear
// encoding such as sRGB must be applied to colour, not to colour * alpha.

#include <bokeh/color.h>

#include <bokeh/image.h>

#include <cmath>
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

bool ColorSystem::is_scene_linear(const std::string& name) const
{
    if (!m_impl->config || !has(name))
        return false;
    if (name == m_scene_linear)
        return true;
    auto proc = m_impl->config->createColorProcessor(name, m_scene_linear);
    if (!proc)
        return false;
    // Linear light converts linearly (a change of primaries: a 3x3 matrix), so doubling a
    // colour doubles its conversion and black stays black; a transfer curve (sRGB's, a
    // log) fails both. Tested on HDR values too, where a display curve would clip.
    const float samples[][3] = { { 0.18f, 0.18f, 0.18f }, { 0.9f, 0.2f, 0.05f }, { 4.0f, 0.5f, 12.0f } };
    float zero[3]            = { 0.0f, 0.0f, 0.0f };
    proc->apply(zero);
    for (float z : zero)
        if (std::abs(z) > 1e-6f)
            return false;
    for (const auto& v : samples) {
        float once[3]  = { v[0], v[1], v[2] };
        float twice[3] = { 2 * v[0], 2 * v[1], 2 * v[2] };
        proc->apply(once);
        proc->apply(twice);
        for (int c = 0; c < 3; ++c)
            if (!(std::abs(twice[c] - 2 * once[c]) <= 1e-4f * (1.0f + std::abs(twice[c]))))
                return false;
    }
    return true;
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

namespace {

// Layers whose R, G, B channels hold data, not light, by the names renderers and
// compositors give them (normals, positions, motion, texture coordinates).
bool is_data_layer(const std::string& layer)
{
    static const char* data_layers[] = { "n",        "normal",   "normals",  "p",
                                         "pref",     "position", "pworld",   "worldposition",
                                         "motion",   "velocity", "vel",      "forward",
                                         "backward", "uv",       "st",       "depth" };
    const std::string l = OIIO::Strutil::lower(layer);
    for (const char* d : data_layers)
        if (l == d)
            return true;
    return false;
}

}  // namespace

std::vector<ColorChannels> color_channel_groups(const OIIO::ImageSpec& spec)
{
    std::vector<ColorChannels> groups;
    std::vector<std::string> layers_seen;
    for (int c = 0; c < spec.nchannels; ++c) {
        const std::string& name = spec.channel_name(c);
        if (name.empty() || name.back() != 'R')
            continue;
        const std::string prefix = name.substr(0, name.size() - 1);
        if (!prefix.empty() && prefix.back() != '.')
            continue;  // "ZR" or "fooR" is not a layer's red
        const std::string layer = prefix.empty() ? "" : prefix.substr(0, prefix.size() - 1);
        if (is_data_layer(layer.substr(layer.find_last_of('.') + 1)))  // npos + 1 == 0
            continue;
        ColorChannels g;
        g.layer = layer;
        g.r     = c;
        g.g     = spec.channelindex(prefix + "G");
        g.b     = spec.channelindex(prefix + "B");
        if (g.g < 0 || g.b < 0)
            continue;
        // A layer's own alpha, else the image's (OpenEXR's channel naming: a layer
        // without its own "A" is covered by the main one).
        g.a = spec.channelindex(prefix + "A");
        if (g.a < 0 && !prefix.empty())
            g.a = spec.channelindex("A");
        groups.push_back(g);
    }
    return groups;
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
    // Only colour goes through OCIO, one layer's R, G, B at a time; depth, alpha, IDs,
    // motion and every other channel keep their bits (OCIO's transforms are 3-channel:
    // anything else passed through them would be scaled and offset as if it were light).
    const bool premultiplied = is_premultiplied(img.spec());
    const OIIO::ROI data     = img.roi();
    for (const ColorChannels& g : color_channel_groups(img.spec())) {
        const bool with_alpha = g.a >= 0;
        std::vector<int> order = { g.r, g.g, g.b };
        if (with_alpha)
            order.push_back(g.a);
        OIIO::ImageBuf group;
        if (!OIIO::ImageBufAlgo::channels(group, img, int(order.size()), order, {}, {}, false,
                                          nthreads)) {
            err = format("cannot take the colour channels of layer '{}': {}", g.layer,
                         group.geterror());
            return false;
        }
        group.specmod().alpha_channel = with_alpha ? 3 : -1;
        group.specmod().z_channel     = -1;
        OIIO::ImageBuf result;
        if (!OIIO::ImageBufAlgo::colorconvert(result, group, from, to, with_alpha && premultiplied,
                                              "", "", m_impl->config.get(), {}, nthreads)) {
            err = format("cannot convert from '{}' to '{}': {}", from, to, result.geterror());
            return false;
        }
        std::vector<float> plane(data.npixels());
        for (int k = 0; k < 3; ++k) {
            OIIO::ROI in = data, out = data;
            in.chbegin = k, in.chend = k + 1;
            out.chbegin = order[size_t(k)], out.chend = order[size_t(k)] + 1;
            if (!result.get_pixels(in, OIIO::TypeFloat, plane.data())
                || !img.set_pixels(out, OIIO::TypeFloat, plane.data())) {
                err = format("cannot store converted channel {}: {}",
                             img.spec().channel_name(order[size_t(k)]), img.geterror());
                return false;
            }
        }
    }
    return true;
}

}  // namespace bokeh
