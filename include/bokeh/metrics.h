// metrics.h — how far a result is from its reference, and the artifacts of enlargement.
//
// The error every chart and accuracy test quotes: RMSE in linear light, and PSNR after a
// fixed tone map x / (1 + |x|) per channel (peak 1), so that HDR highlights (fairy lights
// at 300) do not swamp the measure and a dark-area error still counts.
//
// Artifact metrics (what an enlarged reduced buffer shows, as Kawase's "Anti reduced-buffer
// artifacts" names it): Mach bands, ringing, shimmer and loss of detail, each a number
// computed from images, plus the standard protocol that runs an enlargement method on the
// four test scenes. Every channel counts alike; sums are in double and combined in a fixed
// order, so the figures do not depend on the thread count.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

struct ImageError {
    double rmse_linear = 0.0;  ///< root mean square difference, linear values
    double psnr_db     = 0.0;  ///< PSNR of the tone-mapped values, peak 1; 999 when identical
    double max_abs     = 0.0;  ///< largest absolute linear difference
    int64_t values     = 0;    ///< channel values compared
    /// Values where one image holds NaN or an infinity and the other a different value.
    /// When any, the error is infinite: rmse_linear and max_abs +inf, psnr_db -inf.
    int64_t nonfinite = 0;
};

/// Compare `result` with `reference` channel by channel (same channel count) over `roi`
/// (default: the union of their data windows; a pixel outside an image's window counts
/// as 0 there). False + `err` when the channel counts differ or an image is deep.
bool compare(ImageError& e, const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference,
             std::string& err, OIIO::ROI roi = {}, int nthreads = 0);

// --- artifact metrics -----------------------------------------------------------------

/// Mach bands: how much the slope jumps from pixel to pixel beyond its smooth change. The
/// eye exaggerates a change of gradient; bilinear enlargement is piecewise linear, so its
/// slope jumps at every source pixel and a glare shows a grid of lines. Along every row
/// and column: d1 = (v[x+1] - v[x-1]) / 2, d2 = v[x+1] - 2 v[x] + v[x-1], and the residual
/// r = d2 - (mean of d2 over a centred window of `period_px`, the enlargement factor: the
/// curvature the content has). score = 100 * RMS(r) / RMS(d1), over `roi` (default: the
/// data window less 3 * period_px on each side, away from the borders' own effects).
/// Piecewise linear results score high, C2-smooth ones near 0; content with no slope
/// scores 0. Needs a smooth image (a glare), not texture: texture has curvature of its own.
bool mach_bands(double& score, const OIIO::ImageBuf& img, int period_px, std::string& err,
                OIIO::ROI roi = {}, int nthreads = 0);

/// Ringing: values the filter invents beyond the source's range (on a step or a light,
/// content whose every convex combination stays within the range).
struct Ringing {
    double overshoot  = 0.0;  ///< 100 * (max(result) - max(source)) / range, >= 0
    double undershoot = 0.0;  ///< 100 * (min(source) - min(result)) / range, >= 0
    double most_negative = 0.0;   ///< the lowest result value below 0 where the source has
                                  ///< no negative value (else 0)
    int64_t negative_values = 0;  ///< result values below 0 where the source has none
};
/// Per channel against the same channel's source range (max - min over the source's data
/// window; constant channels are skipped); the worst channel is reported.
bool ringing(Ringing& r, const OIIO::ImageBuf& result, const OIIO::ImageBuf& source,
             std::string& err, int nthreads = 0);

/// Shimmer: `frames[i]` is the enlargement of the same content moved by `shifts_px[i]`
/// destination pixels (x, y). Each frame is moved back; a shift-invariant method gives
/// identical frames, so whatever differs is the temporal twinkling the talk shows. score =
/// 100 * RMS over frames and pixels of (aligned frame - mean of the aligned frames) /
/// RMS(mean). `roi` (aligned coordinates; default: where every aligned frame has data,
/// less the largest shift on each side).
bool shimmer(double& score, const std::vector<OIIO::ImageBuf>& frames,
             const std::vector<std::array<int, 2>>& shifts_px, std::string& err,
             OIIO::ROI roi = {}, int nthreads = 0);

/// Detail: error on a high-frequency pattern against its full-resolution reference, as a
/// percentage of the pattern's contrast: 100 * RMS(result - reference) / RMS(reference -
/// mean(reference)). 100 is as wrong as a flat grey. `roi` default: the reference's data
/// window.
bool detail_error(double& score, const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference,
                  std::string& err, OIIO::ROI roi = {}, int nthreads = 0);

// --- the standard protocol ------------------------------------------------------------

/// The test scenes, one channel, at the low resolution (texel units; `factor` only sizes
/// the full-resolution ones). Coordinates: texel i covers [i, i + 1).
enum class ArtifactScene {
    /// 40 x 40: a glare 1 / (1 + (r / 1.5)^2) around (19.3, 20.6), sampled at texel centres
    Glare,
    /// 24 x 8: 0 left of x = 12, 1 from there on
    Step,
    /// 32 x 32: seven point lights (Gaussian, sigma 0.5 texel, peak 1 to 4), area-sampled,
    /// moved by `shift_texels` along x and y
    Lights,
    /// 32 x 32: 0.5 plus four plane waves of 0.31 to 0.42 cycles per texel (amplitudes
    /// 0.06 to 0.12), area-sampled
    Pattern,
    /// the same pattern area-sampled at full resolution (32 factor x 32 factor)
    PatternReference,
};
OIIO::ImageBuf artifact_scene(ArtifactScene scene, int factor = 1, double shift_texels = 0.0);

struct EnlargementArtifacts {
    double mach = 0.0;     ///< mach_bands of the enlarged Glare (period = factor)
    Ringing ring;          ///< ringing of the enlarged Step
    double shimmer = 0.0;  ///< shimmer of Lights moved in steps of 1/4 texel (1/factor
                           ///< below 4x) over one texel
    double detail = 0.0;   ///< detail_error of the enlarged Pattern against PatternReference
};

/// `enlarge(dst, src)` enlarges `src` by `factor` with the method under test (the result
/// is factor times the size, exact factor, pixel centres as in resample.h).
using EnlargeFunction = std::function<bool(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src)>;

/// Run `enlarge` on the four scenes and measure them. False + `err` when enlarge fails
/// (with its message) or returns the wrong size.
bool enlargement_artifacts(EnlargementArtifacts& a, int factor, const EnlargeFunction& enlarge,
                           std::string& err, int nthreads = 0);

}  // namespace bokeh
