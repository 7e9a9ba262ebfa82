// resample.h — reduced buffers and their enlargement (Kawase, "Anti reduced-buffer
// artifacts"; docs/methods/resampling.md): reduce by an integer factor or to any size,
// enlarge by any factor with every method the talk compares, and depth-aware (PCF,
// joint-bilateral) enlargement of a low-resolution layer over a full-resolution depth.
//
// Geometry. Pixel (x, y) is the square [x, x+1) x [y, y+1); its value stands for its centre.
// Destination pixel x samples the source at u = (x + 0.5) / factor - 0.5 (in source pixels,
// centres at integers), as OIIO's resize does. Two ways to fix the factor:
//   * reduce(N) and enlarge(k) use the exact factor, anchored at coordinate 0: reduced
//     pixel i covers [i N, (i + 1) N), and enlarge(k) after reduce(k) puts every pixel
//     back where it was. The windows become the pixels they touch: a 1080-row image
//     reduced by 16 has 68 rows (the last half empty) and enlarges back to 1088.
//   * resize() and resample() map the display windows onto each other, as
//     IBA::resize and IBA::resample do.
//
// Enlargement filters, t in source pixels (all separable: the 2-D weight is w(tx) w(ty)):
//   Nearest     the source pixel whose square holds the sample (1 tap)
//   Bilinear    tent 1 - |t|, |t| < 1 (2 taps)                              C0
//   CatmullRom  Keys (1981) cubic convolution, a = -0.5 (4 taps)            C1, rings
//   BSpline     uniform cubic B-spline (Mitchell & Netravali 1988, B = 1, C = 0), applied
//               to the samples without prefiltering: smooths (4 taps)       C2
//   Lanczos2/3  sinc(t) sinc(t / a), |t| < a (4 / 6 taps), weights normalised  rings
//   Gaussian    exp(-t^2 / (2 sigma^2)), |t| < 4 sigma, normalised; sigma in source pixels
//               is the same at every factor: kGaussianSigma = 0.65 source pixels, i.e.
//               1.3, 2.6, 5.2, 10.4 output pixels at 2x, 4x, 8x, 16x (ResampleOptions::
//               gaussian_sigma overrides). A normalised Gaussian on a unit grid ripples
//               (about 2 exp(-2 pi^2 sigma^2)), which shows as Mach bands; 0.65 is the
//               smallest sigma whose Mach score (metrics.h) is that of the C2 cubic B-spline
//               (within 1.2 times) at 2x, 4x, 8x and 16x; 0.6 scores 1.4 to 2 times it, 0.5
//               4.6 to 7 times: the sharpest Gaussian without bands. The figures are in
//               tests/resample/resample_test.cpp.
//   Box         area-exact: the weight of a source pixel is the part of the destination
//               pixel's footprint it covers (nearest at integer enlargements)
//   ReducedBlur the talk's "reduced-buffer blur": a small Gaussian at low resolution
//               (sigma = blur_sigma, default 0.5 source pixels, pixel-integrated weights
//               as aperture.h's gaussian_weights_1d), then bilinear
//   UpscaleBlur the talk's upscale-blur: bilinear 2x, the binomial blur [1 2 1] / 4 on the
//               2x grid, bilinear to the final size
//   UpscaleBlurFused   its fused form: the 2x image is the mean of 4 bilinear reads of the
//               source at (u +- d, v +- d), d = fused_offset source pixels (default
//               sqrt(1/8) = 0.354, which gives the 2x step the same variance as the
//               unfused bilinear + [1 2 1] / 4), then bilinear to the final size
//   UpscaleBlurTwoStage   the talk's two-stage variant: bilinear 2x + [1 2 1] / 4, twice,
//               then bilinear to the final size
// A stage of the compound methods (the last four) enlarges by 2 only while at least 2 is
// left; below that it enlarges by what is left.
//
// Every filter is separable and linear, so each one is applied the same way: its 1-D
// weights are computed once per output column and once per output row (the compound
// methods' stages multiplied into one set of weights, borders included, so the result
// is the stages run one after the other, without their intermediate images), then one
// horizontal pass over the source rows and one vertical pass over the output rows. A
// factor of 1 along an axis is the identity for every filter, bit for bit (the reduced
// buffer at reduction 1 is the full-resolution one); the smoothing filters smooth only
// when they enlarge. Nearest, Bilinear, CatmullRom and Lanczos interpolate: where a
// sample falls on a source pixel centre (odd integer factors, every factor-th pixel) the
// output is that pixel's value, bit for bit; BSpline and Gaussian do not.
//
// Reduction. Filters reduce too (resize below the source size): the filter is stretched
// to the destination pixel (t in destination pixels, as IBA::resize does), Box is the
// area-exact box, Nearest point-samples, and the compound methods refuse (they only
// enlarge). resample() never stretches (IBA::resample: point or bilinear samples).
//
// Negative values. CatmullRom and Lanczos have negative lobes: a step overshoots (7.4 %
// Catmull-Rom, 11.7 % Lanczos-3) and a bright light on black gives negative pixels around
// it (one pixel of 1000 enlarged 4x: down to -71 with Catmull-Rom, -144 with Lanczos-3).
// We keep them by default (clamp_negative = false): the result is then the filter, linear
// (a sum of enlargements is the enlargement of the sum, which layered compositing relies
// on) and the same as IBA::resize's. Setting clamp_negative sets every negative output
// value of every channel to 0, which adds the negative lobes' share back as energy and
// breaks linearity. For scene-linear images with lights, the non-negative filters
// (Bilinear, BSpline, Gaussian, Box, the compound methods) do not need it.
//
// Channels. enlarge() and resize() filter every channel alike, depth included (as
// oiiotool's resize does): across a depth edge they invent in-between depths. reduce()
// takes min (or nearest-depth) for depth channels, and enlarge_depth_aware() enlarges a
// layer against a full-resolution depth.
//
// Bad values: a NaN or Inf source value reaches exactly the outputs whose filter support
// holds it with a non-zero weight (its footprint) and no other (zero-weight taps are not
// read). Reducers: a NaN in a block makes that block's Mean, Min or Max NaN;
// NearestDepth never picks a pixel with a NaN depth (a block of only NaN depths gives
// NaN). Sums are in float: at most a few dozen taps per output, so no drift (running sums
// elsewhere use double). Results are bit-identical for any thread count.
#pragma once

#include <bokeh/base.h>

#include <cstddef>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

// --- planes: contiguous interleaved float pixels, for callers without an ImageBuf ------

/// `width` x `height` pixels of `nchannels` floats, row y at data + y * row_stride.
struct PlaneView {
    float* data    = nullptr;
    int width      = 0;
    int height     = 0;
    int nchannels  = 0;
    size_t row_stride = 0;  ///< floats from one row to the next (>= width * nchannels)
    float* row(int y) const { return data + size_t(y) * row_stride; }
};
struct ConstPlaneView {
    const float* data = nullptr;
    int width         = 0;
    int height        = 0;
    int nchannels     = 0;
    size_t row_stride = 0;
    ConstPlaneView() = default;
    ConstPlaneView(const float* d, int w, int h, int nc, size_t stride)
        : data(d), width(w), height(h), nchannels(nc), row_stride(stride)
    {
    }
    ConstPlaneView(const PlaneView& p)  // NOLINT: a writable plane is readable
        : data(p.data), width(p.width), height(p.height), nchannels(p.nchannels),
          row_stride(p.row_stride)
    {
    }
    const float* row(int y) const { return data + size_t(y) * row_stride; }
};

/// Where the centre of destination-plane pixel i falls in the source plane, along one
/// axis, in source pixels (centres at integers):
///     u(i) = (i + dst_origin + 0.5) * src_size / dst_size - 0.5 - src_origin
/// src_size / dst_size is the size of a destination pixel in source pixels; the origins
/// are the planes' first pixels in their images' coordinates.
struct AxisMap {
    double src_size   = 1.0;
    double dst_size   = 1.0;
    double dst_origin = 0.0;
    double src_origin = 0.0;
    double source(int i) const
    {
        return (double(i) + dst_origin + 0.5) * src_size / dst_size - 0.5 - src_origin;
    }
    /// Exact factor `k` (destination pixels per source pixel), anchored at coordinate 0.
    static AxisMap factor(double k, int dst_origin = 0, int src_origin = 0)
    {
        return { 1.0, k, double(dst_origin), double(src_origin) };
    }
};

// --- reduction -------------------------------------------------------------------------

/// How the pixels of a block become one reduced pixel.
enum class Reducer {
    Mean,          ///< area-weighted mean (colour, alpha)
    Min,           ///< smallest value (depth: the nearest surface)
    Max,           ///< largest value
    NearestDepth,  ///< the value of the block's pixel with the smallest depth (Z, CoC)
    /// Area-weighted mean over the block's pixels inside the data window, whatever
    /// `outside_is_black` says: a depth's mean (no energy to keep; outside is no surface,
    /// not a surface at 0). `ReduceOptions::depth = Mean` becomes this.
    MeanOverData,
};

struct ReduceOptions {
    Reducer colour = Reducer::Mean;  ///< every channel but depth
    /// Depth channels (Z, ZBack). Min by default: a mean of depths across an edge invents
    /// a surface between the two that no pixel has, while the nearest depth keeps the
    /// foreground's silhouette for later occlusion tests.
    Reducer depth = Reducer::Min;
    /// One per channel when not empty; overrides `colour` and `depth`.
    std::vector<Reducer> channels;
    /// The channel NearestDepth ranks by; -1: the image's Z channel.
    int depth_channel = -1;
    /// Block pixels outside the source's data window. false (default): left out, so a
    /// block at the edge of a full-frame image is the mean of its pixels inside. true:
    /// counted as 0, so the reduced image's sum times the block area is the source's sum
    /// (energy) also where blocks straddle the window.
    bool outside_is_black = false;
};

/// Reduce by `factor` (1, 2, 4, 8, 16 or any integer >= 1): reduced pixel (i, j) covers
/// source pixels [i N, (i + 1) N) x [j N, (j + 1) N). The data and display windows become
/// the blocks they touch. False + dst.geterror() on failure.
bool reduce(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int factor,
            const ReduceOptions& opts = {}, int nthreads = 0);
OIIO::ImageBuf reduce(const OIIO::ImageBuf& src, int factor, const ReduceOptions& opts = {},
                      int nthreads = 0);

/// Reduce to `width` x `height` (the new display window; the data window maps onto it
/// as in resize()): each output pixel's footprint, a rectangle of fractional size in the
/// source, weights each source pixel by the area it covers (Mean) or takes every pixel
/// it touches (Min, Max, NearestDepth).
bool reduce_to_size(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int width, int height,
                    const ReduceOptions& opts = {}, int nthreads = 0);
inline OIIO::ImageBuf reduce_to_size(const OIIO::ImageBuf& src, int width, int height, const ReduceOptions& opts = {},
                                     int nthreads = 0)
{
    OIIO::ImageBuf dst;
    reduce_to_size(dst, src, width, height, opts, nthreads);
    return dst;
}

// --- enlargement -----------------------------------------------------------------------

enum class ResampleFilter {
    Nearest,
    Bilinear,
    CatmullRom,
    BSpline,
    Lanczos2,
    Lanczos3,
    Gaussian,
    Box,
    ReducedBlur,
    UpscaleBlur,
    UpscaleBlurFused,
    UpscaleBlurTwoStage,
};

/// kGaussianSigma: the Gaussian's sigma in source pixels at every enlargement factor.
constexpr double kGaussianSigma = 0.65;
/// The reduced-buffer blur's sigma, in source pixels.
constexpr double kReducedBlurSigma = 0.5;
/// The fused upscale-blur's offset, in source pixels: sqrt(1/8).
constexpr double kFusedOffset = 0.35355339059327373;

struct ResampleOptions {
    ResampleFilter filter = ResampleFilter::Bilinear;
    /// Source pixels outside its data window: Clamp (the edge repeats, as IBA::resize),
    /// Black, or Mirror.
    Border border = Border::Clamp;
    float gaussian_sigma = 0.0f;  ///< Gaussian: sigma in source pixels; 0: kGaussianSigma
    float blur_sigma     = 0.0f;  ///< ReducedBlur: sigma in source pixels; 0: kReducedBlurSigma
    float fused_offset   = 0.0f;  ///< UpscaleBlurFused: d in source pixels; 0: kFusedOffset
    bool clamp_negative  = false; ///< set negative results to 0 (see the header comment)
};

/// The filter's name as the commands spell it ("catmull-rom", "upscale-blur", ...).
const char* filter_name(ResampleFilter f);
/// The filter called `name` (ours, and OIIO's names for the shared ones: "triangle" is
/// Bilinear, "b-spline"/"bspline" BSpline, "lanczos3" Lanczos3); false if unknown.
bool parse_filter(const std::string& name, ResampleFilter& f);
/// Every name parse_filter accepts, for messages and help.
std::vector<std::string> filter_names();

/// Enlarge by `factor` (>= 1, any real number; exact factor, see the geometry above).
bool enlarge(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, double factor,
             const ResampleOptions& opts = {}, int nthreads = 0);
OIIO::ImageBuf enlarge(const OIIO::ImageBuf& src, double factor, const ResampleOptions& opts = {},
                       int nthreads = 0);

/// Resize to a `width` x `height` display window (IBA::resize's mapping), enlarging or
/// reducing each axis with `opts.filter` (reducing: stretched to the destination pixel).
bool resize(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int width, int height,
            const ResampleOptions& opts = {}, int nthreads = 0);
/// What enlarge() and resize() check of their options: the sigmas and the fused offset
/// within 0..64 px. False + `err` naming them.
bool check_resample_options(const ResampleOptions& opts, std::string& err);
inline OIIO::ImageBuf resize(const OIIO::ImageBuf& src, int width, int height, const ResampleOptions& opts = {},
                             int nthreads = 0)
{
    OIIO::ImageBuf dst;
    resize(dst, src, width, height, opts, nthreads);
    return dst;
}

/// Sample the source at the destination pixel centres (IBA::resample's mapping):
/// bilinear when `interpolate`, else the nearest pixel; never prefiltered.
bool resample(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, int width, int height,
              bool interpolate = true, int nthreads = 0);
inline OIIO::ImageBuf resample(const OIIO::ImageBuf& src, int width, int height, bool interpolate = true,
                               int nthreads = 0)
{
    OIIO::ImageBuf dst;
    resample(dst, src, width, height, interpolate, nthreads);
    return dst;
}

// --- depth-aware enlargement (the talk's reduced blend buffer) -----------------------

enum class DepthAwareMethod {
    /// Percentage-closer filtering (Reeves, Salesin & Cook 1987, as the talk uses it for
    /// reduced blend buffers): out = sum_n w_n pass_n L_n over the 2 x 2 low-resolution
    /// texels n around the sample, w_n the bilinear weights, pass_n = 1 where the texel's
    /// depth is in front of (or at) the full-resolution pixel's depth:
    /// z_low(n) <= z_full * (1 + depth_tolerance). Where every texel passes it is bilinear;
    /// where none does, 0 (the layer is hidden). The layer's alpha carries the visibility,
    /// so compositing `over` the full-resolution image hides the layer behind nearer full-
    /// resolution surfaces with full-resolution edges. Answers "how much of the layer is in
    /// front of this pixel's surface".
    PCF,
    /// Joint-bilateral upsampling (Kopf, Cohen, Lischinski & Uyttendaele 2007): a weighted
    /// mean over the 4 x 4 texels around the sample, weight = the cubic B-spline spatial
    /// weight times exp(-d^2 / 2), d = (z_low(n) - z_full) / (sigma_depth * z_full);
    /// renormalised; when every texel is far in depth (weights below 1e-6 of the spatial
    /// ones), the texel of the nearest depth. Answers "what is the layer at this pixel's
    /// depth": for enlarging a reduced image of the same surfaces (a reduced blur of the
    /// frame itself) without bleeding across depth edges. It never hides the layer.
    JointBilateral,
};

struct DepthAwareOptions {
    DepthAwareMethod method = DepthAwareMethod::PCF;
    float depth_tolerance = 0.01f;  ///< PCF: relative depth bias of the test
    float sigma_depth     = 0.02f;  ///< JointBilateral: relative depth sigma
};

/// Enlarge the low-resolution layer `low` (its Z channel is the layer's depth) by `factor`
/// over the full-resolution depth `full_depth` (its Z channel, or its only channel). The
/// output covers full_depth's data and display windows, with low's channels and metadata;
/// full-resolution pixels with a NaN depth get 0. Exact factor as enlarge().
bool enlarge_depth_aware(OIIO::ImageBuf& dst, const OIIO::ImageBuf& low,
                         const OIIO::ImageBuf& full_depth, double factor,
                         const DepthAwareOptions& opts = {}, int nthreads = 0);
/// What enlarge_depth_aware() checks of its options: depth_tolerance 0..10, sigma_depth
/// (0, 10]. False + `err` naming them.
bool check_depth_aware_options(const DepthAwareOptions& opts, std::string& err);
inline OIIO::ImageBuf enlarge_depth_aware(const OIIO::ImageBuf& low, const OIIO::ImageBuf& full_depth, double factor,
                                          const DepthAwareOptions& opts = {}, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    enlarge_depth_aware(dst, low, full_depth, factor, opts, nthreads);
    return dst;
}

// --- the same on planes ----------------------------------------------------------------

/// `dst` = `src` resampled with `opts` along the maps; an axis whose destination pixel
/// is larger than a source pixel reduces (stretched filter) unless `prefilter` is false.
/// Channel counts must agree. False + `err` on bad options.
bool resample_plane(const ConstPlaneView& src, const PlaneView& dst, const AxisMap& mx,
                    const AxisMap& my, const ResampleOptions& opts, std::string& err,
                    int nthreads = 0, bool prefilter = true);

/// `dst` = `src` reduced by blocks: each destination pixel's footprint (its square mapped
/// into the source) with channel c reduced by reducers[c] (one per channel; NearestDepth
/// ranks by channel `depth_channel`). `outside_is_black` counts the footprint's pixels
/// outside the source as 0 for Mean (energy kept); the other reducers use only the pixels
/// inside.
bool reduce_plane(const ConstPlaneView& src, const PlaneView& dst, const AxisMap& mx,
                  const AxisMap& my, const std::vector<Reducer>& reducers, int depth_channel,
                  bool outside_is_black, std::string& err, int nthreads = 0);

/// Depth-aware enlargement of `low` (depth in channel `low_depth_channel`) over the
/// one-channel `full_depth` (same size as `dst`).
bool enlarge_depth_aware_plane(const ConstPlaneView& low, int low_depth_channel,
                               const ConstPlaneView& full_depth, const PlaneView& dst,
                               const AxisMap& mx, const AxisMap& my,
                               const DepthAwareOptions& opts, std::string& err, int nthreads = 0);

}  // namespace bokeh
