// lens.h — thin-lens circle of confusion, depth-channel interpretation, and the signed
// CoC map every depth-defocus method starts from.
//
// Signed CoC (docs/methods/optics.md, "The thin lens"): the diameter in pixels of the blur
// disk of a point, negative in front of the focus plane (near, "front bokeh"), positive
// behind it (far, "back bokeh"). Depth channels come in the forms Nuke's ZDefocus reads
// ("math": direct, depth, far = 0, far = 1, each possibly negated); a depth of 0 or a
// non-finite one means "no depth here" and is taken as infinitely far (the Beachball
// renders hold Z = 0 where nothing was rendered).
#pragma once

#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// What the depth channel holds.
enum class DepthMode {
    Direct,        ///< the signed CoC in pixels itself (times CocOptions::direct_scale)
    Depth,         ///< camera distance in depth units (most renderers' Z)
    InverseDepth,  ///< 1 / distance: far = 0 (ZDefocus "far = 0", Nuke's ScanlineRender)
    FarIsOne,      ///< 1 - 1 / distance: far = 1 (ZDefocus "far = 1"); 0 is still "no depth"
};

/// A physical thin lens. Lengths of the lens in millimetres; distances in the depth
/// channel's unit, `depth_unit_mm` millimetres each (1000 for metres).
/// The ranges a camera's numbers are held to: one table for the thin lens, the lens
/// character and every command that takes a camera (f-number; focal length and film-back
/// width in mm). f/128 is past the smallest stop of any photographic lens; 1 and 5000 mm
/// past the shortest fisheye and the longest lens made for a camera. Outside them a CoC or
/// a PSF would be sensible arithmetic but no camera a user could be matching.
inline constexpr double kMinFstop = 0.5, kMaxFstop = 128.0;
inline constexpr double kMinFocalMm = 1.0, kMaxFocalMm = 5000.0;
inline constexpr double kMaxSensorWidthMm = 1e4;

struct Lens {
    double focal_mm        = 50.0;
    double fstop           = 2.8;
    double sensor_width_mm = 36.0;  ///< film back width (see film_back_width)
    double focus_distance  = 5.0;   ///< in depth units
    double depth_unit_mm   = 1000.0;
};

/// Film-back presets: name and width in mm ("ff" 36, "super35" 24.89, "alexa-lf" 36.70, ...).
struct FilmBack {
    const char* name;
    double width_mm;
};
const std::vector<FilmBack>& film_backs();
/// The width of the preset `name`, or false.
bool film_back_width(const std::string& name, double& width_mm);

struct CocOptions {
    Lens lens;
    DepthMode mode      = DepthMode::Depth;
    bool negate         = false;  ///< the channel holds the value negated (ZDefocus "-depth", ...)
    double direct_scale = 1.0;    ///< Direct: CoC px = value * direct_scale
    /// Focus by pixel: when set, focus_distance is the depth sampled at (focus_x, focus_y).
    bool focus_at_pixel = false;
    int focus_x = 0, focus_y = 0;
    double infocus_range = 0.0;   ///< depth units around the focus distance kept sharp
    double front_gain    = 1.0;   ///< multiplies the CoC in front of focus
    double back_gain     = 1.0;   ///< multiplies the CoC behind focus
    double max_coc_px    = 512.0; ///< |CoC| limit (ZDefocus "maximum")
};

/// Signed CoC diameter in pixels of a point at `distance` (depth units; +inf allowed)
/// for an image `image_width_px` wide on the lens's sensor (docs/methods/optics.md):
///     CoC = (d - d0) / d * f^2 / (F (d0 - f)) / (sensor_width / image_width)
/// No gains, range or limit: those are signed_coc's.
double thin_lens_coc_px(const Lens& lens, double distance, int image_width_px);

/// The distance (depth units) a depth-channel value stands for under `mode`; +inf for
/// "no depth" (0, non-finite, or a value that puts the point behind the camera).
/// Not for DepthMode::Direct.
double distance_from_depth(double value, DepthMode mode, bool negate);

/// Check the options against `src` (the focus pixel inside the data window, the focus
/// beyond the focal length, ...) and resolve focus-by-pixel into lens.focus_distance.
/// False + `err` naming the option.
bool resolve_coc_options(CocOptions& opts, const OIIO::ImageBuf& src, std::string& err);

/// Write into `spec` the lens a defocus used (resolved options): "bokeh:focal_mm",
/// "bokeh:fstop", "bokeh:sensor_width_mm" and "bokeh:focus_m" (metres), so that an output
/// says what it is rather than what its input was meant for. With DepthMode::Direct no
/// lens made the CoC, and those attributes are removed.
void record_lens(OIIO::ImageSpec& spec, const CocOptions& resolved);

/// The signed CoC of a depth-channel value, for resolved options and an image
/// `image_width_px` wide (the display window's width): the lens's CoC with the in-focus
/// range, the gains and the limit applied. Non-finite or "no depth" values are far.
class CocOfDepth {
public:
    CocOfDepth(const CocOptions& resolved, int image_width_px);
    float operator()(float depth_value) const;

private:
    CocOptions m_opts;
    int m_width_px;
};

/// The signed CoC of every pixel of `src`'s data window (row-major), from its Z channel.
/// `opts` must be resolved. The pixel size comes from the display window's width.
/// Non-finite depth counts as "no depth". False + `err` when there is no depth channel.
bool signed_coc(std::vector<float>& coc, const OIIO::ImageBuf& src, const CocOptions& opts,
                int nthreads, std::string& err);

/// The CoC map as an image: one float channel "coc" over `src`'s data window.
bool coc_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const CocOptions& opts,
             int nthreads = 0);
inline OIIO::ImageBuf coc_map(const OIIO::ImageBuf& src, const CocOptions& opts, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    coc_map(dst, src, opts, nthreads);
    return dst;
}

/// The focal-plane view: the image's luminance tinted red in front of focus, green in
/// focus (|CoC| <= 1 px), blue behind, the tint growing with |CoC| (from 30 % just out of
/// focus to full at `full_tint_px`).
bool focal_plane_view(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const CocOptions& opts,
                      float full_tint_px = 32.0f, int nthreads = 0);
inline OIIO::ImageBuf focal_plane_view(const OIIO::ImageBuf& src, const CocOptions& opts, float full_tint_px = 32.0f,
                                       int nthreads = 0)
{
    OIIO::ImageBuf dst;
    focal_plane_view(dst, src, opts, full_tint_px, nthreads);
    return dst;
}

}  // namespace bokeh
