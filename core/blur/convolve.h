// convolve.h — internal to the library: the convolutions the blur methods are built from
// (row spans of prefix sums, FFT tiles, bands, the hexagon's parallelograms, the reduced
// buffer), their cost models, and iris mode's exp space. The defocus's layers use them
// too (core/defocus/).
#pragma once

#include <bokeh/aperture.h>
#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "aperture/weights.h"
#include "base/plane.h"

#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh::detail {

/// The weights point-reflected, so that out(x) = sum_d w(d) in(x - d) (blur_spans.cpp).
KernelWeights reflected(const KernelWeights& k);

/// One bar of a kernel row: weight `weight` on offsets dx in [x0, x1] of row dy.
struct Span {
    int dy, x0, x1;
    double weight;
};
/// Skyline decomposition of each kernel row into stacked horizontal bars (blur_spans.cpp).
std::vector<Span> kernel_spans(const KernelWeights& k);
/// Exact "valid" convolution by row spans: the output is `in` less (rx, ry) on each side.
Plane convolve_spans(const Plane& in, const KernelWeights& kernel, int nthreads);

/// The convolution with a list of spans straight from the source into `dst` over `roi`
/// (blur_spans.cpp), by the border rule, for a kernel reaching rx, ry. A span (dy, x0, x1, w)
/// adds w * (T[y + dy][x + x1 + 1] - T[y + dy][x + x0]) where T is the row prefix sums of
/// the padded source (dy in [-ry, ry]), built per output tile.
bool convolve_spans_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                           int rx, int ry, std::vector<Span> spans, Border border, int nthreads);

/// A blur with NaN and infinite source values kept within their footprint (blur_nonfinite.cpp):
/// `clean` blurs `in` with them replaced (by 0; by the channel's least finite value with
/// `keep_range`, for iris mode) into `dst`; then each output whose kernel
/// (kernels[kernel_of[c]] for channel c) has weight on one of them takes what the linear
/// convolution gives it (+inf, -inf or NaN).
bool blur_nonfinite(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const std::vector<KernelWeights>& kernels,
                    const std::vector<int>& kernel_of, Border border, bool keep_range,
                    const std::function<bool(OIIO::ImageBuf&, const OIIO::ImageBuf&)>& clean, int nthreads);

/// Predicted single-thread time in ns of the FFT convolution of a w x h output of nc
/// channels with a kernel reaching rx, ry, in the cheapest tiling, its kernel's transform
/// included (blur_fft.cpp's cost model); infinite for kernels of 8192 px or more.
double fft_convolve_cost_ns(int w, int h, int nc, int rx, int ry);
/// The exact convolution by FFT in overlap-save tiles, straight from the source into `dst`
/// over `roi`, by the border rule (blur_fft.cpp): channel c with kernels[kernel_of[c]],
/// all of the same reach; `progress` as BlurOptions::progress (by tiles and channels).
bool convolve_fft_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                         const std::vector<KernelWeights>& kernels, const std::vector<int>& kernel_of,
                         Border border, int nthreads, const std::function<void(float)>& progress = {});
/// The same as a "valid" convolution of a padded plane (iris mode): the output is `in`
/// less the kernels' reach on each side.
Plane convolve_fft(const Plane& in, const std::vector<KernelWeights>& kernels,
                   const std::vector<int>& kernel_of, int nthreads);

/// Whether the FFT tiles are the cheaper exact convolution of nc channels over a w x h
/// output, against the row spans `spans` reaching rx, ry (blur_spans.cpp: both cost models, the
/// FFT taken below 1.2 times the spans', as measured).
bool fft_cheaper_than_spans(int w, int h, int nc, int rx, int ry, const std::vector<Span>& spans);

/// Predicted single-thread time in ns of one channel of convolve_spans_direct over a
/// w x h output with the kernel's `spans` (blur_spans.cpp's cost model).
double spans_cost_ns(int w, int h, const std::vector<Span>& spans);
/// Whether kernel rows dy and -dy have the same spans (a disk; a polygon symmetric about
/// its horizontal axis): convolve_spans_direct then shares each span sum between two
/// output rows.
bool spans_mirror_in_y(const std::vector<Span>& spans);

/// Predicted single-thread time in ns of one channel of the separable convolution over a
/// w x h output with taps_x and taps_y taps (blur_separable.cpp's cost model).
double separable_cost_ns(int w, int h, int taps_x, int taps_y);

/// banded_weights (blur.h) from the kernel's exact weights.
KernelWeights banded_from(const KernelWeights& exact, int bands);
/// method=fast's band count for a kernel `size_px` across with these exact weights: the
/// fewest bands, 3..8, whose kernel stays within its accuracy bound (blur_bands.cpp).
int fast_band_count(const KernelWeights& exact, double size_px);
/// Predicted single-thread time in ns of one channel of convolve_bands_direct over a w x h
/// output with `bands` bands per half kernel (twice that over the height unless the kernel
/// is `mirrored` in y, as banded_from splits it), in spans_cost_ns's units (blur_bands.cpp).
double bands_cost_ns(int w, int h, int bands, bool mirrored);
/// A banded kernel (rows in runs of equal rows) straight from the source into `dst` over
/// `roi` by running sums down the rows (blur_bands.cpp): cost independent of its size.
bool convolve_bands_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                           const KernelWeights& banded, Border border, int nthreads);

/// The hexagon by parallelograms (blur_hexagon.cpp). Planes are the padded input's size.
/// Whether the parallelograms of `k` run on the transposed plane.
bool hexagon_transposed(const Kernel& k);
/// How much further than hexagon_reach the parallelograms of `k` read on a padded plane:
/// the sheared frame's two more taps.
int hexagon_plane_extra(const Kernel& k);
/// The hexagon of `k` by parallelograms; `in` transposed when hexagon_transposed(k), padded
/// by hexagon_reach + hexagon_plane_extra. Only the plane less `margin_x`, `margin_y` on
/// each side (in its own frame) is computed.
Plane hexagon_parallelograms(Plane in, const Kernel& k, int margin_x, int margin_y, int nthreads);
/// How far the parallelogram passes read along x (or y), interpolation included.
int hexagon_reach(const Kernel& k, bool along_x);
/// Whether the hexagon of `k` takes the fused sweep: its third segment along the rows of
/// the working frame (rotations by multiples of 30 degrees) or, in a frame with sheared
/// columns or rows, turned along them (other rotations, unless stretched past any shear).
bool hexagon_sweeps(const Kernel& k);
/// Predicted single-thread time in ns of one channel of the parallelograms over a w x h
/// output, in spans_cost_ns's units, so the two compare (the parallelograms' cost model).
double parallelograms_cost_ns(const Kernel& k, int w, int h);
/// The narrow side (px) from which the parallelograms of `k` keep within the 40 dB
/// budget of `method=fast` on bokeh-bench's scene.
double parallelograms_budget_px(const Kernel& k);
/// The fused sweep straight from `in` into `dst` over roi (no padded plane, no copy out),
/// where hexagon_sweeps(k); rx, ry as hexagon_reach.
bool hexagon_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                    const Kernel& k, int rx, int ry, Border border, int nthreads);

/// BlurMethod::Reduced (blur_reduced.cpp): `k` at 1/N resolution, N = opts.reduction or the
/// automatic factor (reduction_factor), enlarged back over `roi` (undefined: the source's
/// data window, grown by the method's reach if opts.grow).
bool blur_reduced(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const Kernel& k,
                  const BlurOptions& opts, OIIO::ROI roi, int nthreads);
/// Convolution with a kernel of repeated rows (bands) via a summed-area table (iris mode;
/// blur_bands.cpp).
Plane convolve_banded(const Plane& in, const KernelWeights& banded, int nthreads);

/// The largest |k| times a channel's range that iris mode takes. exp() would overflow float
/// past 88, but the sums in exp space give out first: they carry a bright pixel's exp(k x)
/// beside the dark ones' values near 0 (exp(k d) - 1, Iris), and double's 16 digits leave
/// the dark ones nothing past ~30.
/// Measured (blur, 19 px kernels, a 0.003 .. 500 image): at k x range = 30 the exact
/// methods stay within 3e-4 of the brute force; at 40 the bands return NaN and the exact
/// methods err by 0.9; the layered defocus on the lights scene returned -2.9 in red at 43
/// (its darkest red 0.03) and stays within the input's range at 29.
constexpr double kIrisMaxExponent = 30.0;

/// Iris mode (docs/methods/iris.md): values go to exp(k (x - shift)) - 1 before the blur and
/// come back by shift + log(1 + v) / k (the mean of exp less 1 is the mean of (exp - 1):
/// the weights sum to 1). The shift (the channel's minimum for k > 0, maximum for k < 0)
/// keeps every exponent in [0, kIrisMaxExponent], so nothing overflows, no dark value
/// underflows to an unrecoverable zero and the sums keep the dark values' digits; a wider
/// range is refused. Less 1 (expm1, log1p) because a float exp(k d) near 1 keeps d only to
/// 6e-8 / k: with exp itself iris 1e-4 on a 0..1 image erred by 7.6e-4, 1e-6 by 0.075 and
/// from 1e-7 every value became the channel's minimum; exp(k d) - 1 keeps d's own digits. Alpha and depth (channels `alpha`, `z`) are left linear: the
/// emphasis is for light, and a depth's range would only narrow what colour may use.
struct Iris {
    double k  = 0.0;
    int alpha = -1, z = -1;
    std::vector<double> shift;
    bool forward(Plane& p, std::string& err, int nthreads);
    void inverse(Plane& p, int nthreads) const;
};

}  // namespace bokeh::detail
