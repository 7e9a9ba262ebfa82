// defocus.h — depth defocus of a flat RGBA + Z image: the layered gather of hikita12312's blog post, a
// layered scatter with occlusion, and the exact reference they are measured against.
//
// Every method turns the signed CoC map (lens.h) into a depth-of-field image whose out-of-
// focus points take the aperture's shape (aperture.h's Kernel: disk, bladed polygon with
// curvature and hole; an anamorphic aspect), composites nearer over farther, and grows
// the data window to hold bokeh that spread past it.
#pragma once

#include <bokeh/aperture.h>
#include <bokeh/base.h>
#include <bokeh/image.h>
#include <bokeh/lens.h>
#include <bokeh/optics.h>

#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

enum class DefocusMethod {
    Auto,       ///< Layers with the settings the accuracy budget needs
    Layers,     ///< layered scatter with occlusion, large CoCs in reduced buffers
    Gather,     ///< hikita12312's method as published (blurred levels, masks, edge blur)
    Reference,  ///< one full-resolution layer per distinct CoC value, exact kernels
};

/// What fills the background a blurred foreground uncovers inside its own silhouette, which
/// a flat image never held (docs/methods/disocclusion.md).
enum class DisocclusionFill {
    Foreground,  ///< the foreground's own colour: the silhouette stays hard on its inner side
    Smooth,      ///< the farther surfaces around it continued under it (a depth-aware pull-push)
    Mirror,      ///< the background's texture mirrored across the silhouette (Smooth where it cannot)
};

/// How the flat Layers method picks its plan (docs/methods/planner.md).
enum class DefocusPlanner {
    Steps,      ///< the budget's measured steps: exact rungs when at most 64, else a ladder
    Predicted,  ///< the cheapest plan whose predicted PSNR clears the budget (error and cost models)
};

struct DefocusOptions {
    CocOptions coc;
    /// The aperture: shape, blades, rotation, curvature, hole, edge. Its size is ignored
    /// (each pixel's CoC sets it); use `aspect` for an anamorphic squeeze.
    Kernel aperture;
    float aspect = 1.0f;  ///< bokeh height / width (2 for a 2x anamorphic's tall ovals)
    DefocusMethod method = DefocusMethod::Auto;
    /// Layers: number of layers (0: from the CoC histogram and the budget).
    int layers = 0;
    /// Layers: the ratio between neighbouring rungs of the CoC ladder (> 1), or 1 for the
    /// exact rungs (a layer per CoC the frame holds, or per point of the 0.25 px grid
    /// around them). 0: the planner's.
    float ladder_ratio = 0.0f;
    /// Flat Layers and Auto: how the plan the options leave open is chosen.
    DefocusPlanner planner = DefocusPlanner::Steps;
    /// Layers: coarsest buffer reduction (1 = all at full resolution; 1, 2, 4, 8, 16).
    int max_reduction = 16;
    /// Layers: smallest kernel diameter, in reduced pixels, before a layer may be reduced
    /// (0: from the budget). Larger keeps more layers at full resolution.
    float min_reduced_coc_px = 0.0f;
    /// Auto: the PSNR (dB, after the bench's tone map) the result should reach against
    /// the reference: the steps' ladder ratio and smallest reduced kernel, or the target of
    /// the predicted planner (docs/methods/planner.md).
    float budget_db = 40.0f;
    /// Highlights: colour above `bloom_threshold` (unpremultiplied, per channel) is
    /// multiplied by `bloom_gain` before the blur (ZDefocus's bloom). Gain 1 = off.
    float bloom_threshold = 1.0f;
    float bloom_gain      = 1.0f;
    /// Iris mode (docs/methods/iris.md, as blur's `iris`): each layer averages
    /// exp(iris * colour) weighted by coverage and returns log(mean) / iris, so bright
    /// values dominate the bokeh as in a real lens. 0 = off; |iris| times each colour
    /// channel's range must stay within 80.
    float iris = 0.0f;
    /// Edge-halo remedy for anti-aliased (filtered) depth: each pixel takes the CoC of the
    /// nearest depth within this many pixels, so edge pixels whose depth was averaged
    /// between a foreground and a background go with the foreground. 0 = off.
    int depth_dilate_px = 0;
    /// Past the data window: Clamp repeats the edge pixels (and their depth), Black is
    /// empty (transparent), Mirror reflects.
    Border border = Border::Clamp;
    /// Grow the data window by the largest CoC radius, within the display window.
    bool grow = true;
    /// Flat Layers and Reference: what fills the background a blurred foreground uncovers
    /// (a deep image holds it; the gather has its own edge blur).
    DisocclusionFill fill = DisocclusionFill::Smooth;
    NonFinitePolicy nonfinite = NonFinitePolicy::Zero;
    /// Reference: CoC values are quantised to this step (px) to count as one layer.
    float reference_step_px = 0.25f;
    /// Layered methods and the reference, flat output: the aperture cut into views x views
    /// sub-apertures (an n x n grid over its bounding square), the layers composited for
    /// each on its own and the results averaged by the sub-apertures' shares of the light.
    /// A blurred nearer layer then hides a farther one only for the rays that pass it on
    /// the same side, as a lens does: one pass takes the product of two whole-aperture
    /// averages, which shows at a defocused silhouette over a defocused background. Cost:
    /// views^2 passes over the layers, each blurring with kernels about 1 / views as tall
    /// (the deep reference on LowResLeftView: 3.4x the time in 4 x 4 views). Disk, polygon
    /// and box apertures (a pupil with an edge to cut within). 1: off. 0: the planner's
    /// choice: 1 for a flat image (whose hidden background is invented anyway: nothing
    /// measurable to gain); for a deep image under method=auto with a flat result, 2 when
    /// it records surfaces behind its defocused samples (more than 1 % of its pixels hold
    /// samples whose CoCs differ by more than 1 px), else 1.
    int aperture_views = 0;
    /// A deep input's result as a deep image: one sample a layer per pixel, each a volume
    /// over its layer's depth range; its flatten is the flat result.
    bool deep_output = false;

    /// Lens character (optics.h) on the highlights: pixels brighter than
    /// `highlight_threshold` are scattered as sprites, each the lens's PSF at its signed
    /// CoC and field position, inside the layer of its depth (nearer layers hide them as
    /// they hide any pixel); the rest goes through the layers, and the in-focus layer is
    /// blurred with the lens's PSF on axis (its in-focus softness and colour, which the
    /// aperture's point would leave out). Off: the output is the
    /// plain method's, bit for bit. Only the lens's aberrations, spectrum, diffraction,
    /// onion rings and field effects are read from `lens`: its aperture, aspect and camera
    /// (f-stop, focal length, pixel pitch) are this defocus's own (`aperture`, `aspect`,
    /// `coc`). The gather method has no layers to put sprites in and refuses it.
    bool lens_character = false;
    LensCharacter lens;
    /// Premultiplied luminance (Rec. 709 weights) at which a pixel is half a sprite: the
    /// sprite's share of the pixel rises smoothly (smoothstep in log luminance) from 0 at
    /// threshold / 2 to 1 at threshold * 2, so exposure or threshold changes never pop one.
    float highlight_threshold = 1.0f;
    /// At most this many sprites, the brightest (by the sprite's luminance); the rest stay
    /// in the layers. A cost guard: a pixel crossing the cut does pop.
    int max_sprites = 20000;
    /// Pseudo-high resolution (Kawase, "Bokeh Deep Dive"; docs/methods/lens-character-sprites.md): the output at this many times the
    /// input's resolution (1 or 2; its data and display windows scaled alike). The layers
    /// are built from the frame's own pixels as at 1 and enlarged bilinearly as they are
    /// composited; the sprites are drawn at the output's resolution (the lens PSF at the
    /// output's CoC and pixel pitch), so highlights keep their rims and fringes sharp.
    /// Each output pixel holds radiance as the input's did (a flat area keeps its value;
    /// the sum over the output is supersample^2 times the input's). Not for the gather
    /// method nor deep output.
    int supersample = 1;
    /// Layered methods and the reference (flat and deep): called with the fraction done
    /// (0..1) as the layers' tiles are blurred, each weighted by its kernel's size; from
    /// one thread at a time, in rising order. Empty: nothing is counted.
    std::function<void(float)> progress;
    /// The memory the defocus may hold, bytes (0: no limit): its estimate of what it will
    /// hold (the frame's working planes; a deep frame's layers, 20 bytes a pixel a layer) is
    /// checked before they are allocated, and one past it refused, with
    /// `memory_budget_hint` (how the caller's user raises it: a host names its option).
    int64_t memory_budget_bytes = 0;
    std::string memory_budget_hint;
    /// A flat defocus calls this once it holds the source's pixels in its own form and
    /// reads `src` no more (not even its spec): a caller that owns the only copy of the
    /// source may free it there, so the source and the result are never both held (a 4K
    /// RGBA + Z float frame is 166 MB). `src` must not be used by the defocus's caller
    /// after it either. Empty: nothing is called.
    std::function<void()> source_done;
};

/// One plan the flat Layers planner weighed: its ladder (ratio 1: the exact rungs, 0: the
/// budget's steps), its smallest reduced kernel (infinity: every layer at full resolution),
/// its layer count, and what the predicted planner predicted of it (0 under the steps).
struct DefocusPlanEstimate {
    float ladder_ratio       = 1.0f;
    float min_reduced_coc_px = 0.0f;
    int layers               = 0;
    double predicted_psnr_db = 0.0;  ///< against the reference, after the bench's tone map
    double predicted_ms      = 0.0;  ///< the layers' blur and composite on the threads given
    bool chosen              = false;
};

/// What a defocus decided and found, for `-v` and for tests.
struct DefocusReport {
    DefocusMethod method = DefocusMethod::Auto;  ///< the method that ran
    std::vector<float> layer_coc_px;  ///< Layers, Reference: each layer's CoC, front to back
    std::vector<int> layer_reduction; ///< Layers: each layer's buffer reduction
    /// Flat Layers: the plans the planner weighed, cheapest first (the steps', or the
    /// user's, alone when nothing was predicted).
    std::vector<DefocusPlanEstimate> plans;
    float min_coc_px = 0.0f, max_coc_px = 0.0f;
    NonFiniteCount nonfinite;
    /// Flat Layers and Reference: output pixels whose uncovered background was filled with
    /// the continued background, and with the foreground's own colour (nothing behind it
    /// within reach, or fill Foreground).
    int64_t fill_continued_px = 0, fill_foreground_px = 0;
    /// A flat frame over the memory budget is drawn in bands of output rows: how many, and
    /// the rows of each (1 and 0: at once).
    int bands = 1, band_rows = 0;
    /// Lens character: how many sprites were scattered, their CoC range, the seconds their
    /// selection, PSFs and scatter took, and the distinct PSFs they use (built, or taken from
    /// the process's PSF cache: shared_psf_cache, optics.h).
    bool lens_character = false;
    int64_t sprites = 0;
    int64_t sprite_candidates = 0;  ///< pixels with a sprite share before the max_sprites cut
    /// Sprites drawn: large ones merged by source blocks; one shared between two layers is
    /// drawn in both and counted once (so sprites_drawn <= sprites)
    int64_t sprites_drawn = 0;
    float sprite_min_coc_px = 0.0f, sprite_max_coc_px = 0.0f;
    double sprite_seconds = 0.0;
    size_t sprite_psfs = 0;
    std::string summary;  ///< one line
};

/// Defocus `src` (R, G, B, optional A, and Z) into `dst`: premultiplied R, G, B(, A) as
/// float over the grown data window, with src's metadata. Z and other channels are not
/// carried (a defocused image has no single depth per pixel). A deep `src` (R, A, Z, and
/// optionally G, B, ZBack) is defocused sample by sample, each at its own depth's CoC, with
/// the background it holds behind every foreground (no disocclusion to invent); with
/// `deep_output` the result stays deep. False + dst.geterror().
bool defocus(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
             DefocusReport* report = nullptr, int nthreads = 0);
/// What defocus() checks before it reads an image: the lens, the aperture, the method's
/// and the planner's options. False + `err` naming the option.
bool check_defocus_options(const DefocusOptions& opts, std::string& err);
inline OIIO::ImageBuf defocus(const OIIO::ImageBuf& src, const DefocusOptions& opts, DefocusReport* report = nullptr,
                              int nthreads = 0)
{
    OIIO::ImageBuf dst;
    defocus(dst, src, opts, report, nthreads);
    return dst;
}

/// The signed CoC the defocus draws with, one channel "coc": coc_map's of `opts.coc`, each
/// pixel then given the nearest CoC within `opts.depth_dilate_px` (zdilate).
bool defocus_coc_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
                     int nthreads = 0);
inline OIIO::ImageBuf defocus_coc_map(const OIIO::ImageBuf& src, const DefocusOptions& opts, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    defocus_coc_map(dst, src, opts, nthreads);
    return dst;
}

/// The layer map of the Layers method: per pixel the index of the nearer of the two
/// layers it is shared between, plus its share in the farther one (channel "layer" =
/// index + share), so a user sees where layer boundaries fall.
bool layer_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
               int nthreads = 0);
inline OIIO::ImageBuf layer_map(const OIIO::ImageBuf& src, const DefocusOptions& opts, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    layer_map(dst, src, opts, nthreads);
    return dst;
}

/// The brute-force reference of lens character: every pixel of a flat `src` scattered with
/// the lens PSF of its own CoC (exact to `opts.reference_step_px`) and field position,
/// into one full-resolution layer per CoC step (alpha scattered with the PSF's mean of
/// R, G, B), layers composited nearer over farther with the layered method's occlusion
/// model: each layer divided by its visibility (the blur of 1 - coverage over the pixels
/// in nearer layers, with the layer's on-axis PSF), the border rule's pixels past the data
/// window scattered too, the disocclusion fill at the end. So it differs from the layered
/// reference (method reference) only in the PSFs. Slow by design: every pixel's PSF
/// square, and each layer's visibility gathered over its PSF; meant for frames up to about
/// 640x360. Uses opts.lens as `defocus` does (lens_character need not be set).
bool defocus_scatter_reference(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src,
                               const DefocusOptions& opts, int nthreads = 0);
inline OIIO::ImageBuf defocus_scatter_reference(const OIIO::ImageBuf& src, const DefocusOptions& opts,
                                                int nthreads = 0)
{
    OIIO::ImageBuf dst;
    defocus_scatter_reference(dst, src, opts, nthreads);
    return dst;
}

/// Method names for messages ("layers", "gather", ...).
const char* method_name(DefocusMethod m);

}  // namespace bokeh
