// blur.h — uniform (spatially constant) blurs with the kernels of aperture.h (box,
// Gaussian, disk, bladed polygon, OIIO's filters): the methods that compute them, their
// effective kernels, and the brute-force reference they are tested against.
//
// Sizes are the kernel's full footprint in pixels (width x height, like oiiotool's
// `--blur WxH`); width != height gives an anamorphic (elliptical) kernel. A kernel of
// size 0 (or one whose weights collapse to a single tap) is the identity, bit for bit; so
// is a disk or polygon with one side 0 (no area), while a box, a Gaussian or a separable
// OIIO filter with one side 0 blurs along the other axis alone.
// All channels of the image are filtered alike, as oiiotool's --blur does.
#pragma once

#include <bokeh/aperture.h>
#include <bokeh/base.h>

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// Which algorithm computes the blur. Auto, Exact and Reference give the kernel's exact
/// result; the others approximate it, each at a cost that does not grow with the size
/// (BilinearTaps: fixed sizes); bokeh-bench charts what each one costs and loses.
enum class BlurMethod {
    Auto,            ///< the fastest exact method for the shape
    Exact,           ///< box: running sums; Gaussian and OIIO's separable filters: separable
                     ///< convolution or FFT tiles; other filters: FFT tiles;
                     ///< disk and polygon: row spans or FFT tiles; whichever the cost model
                     ///< says is cheaper (on the project's machine at 1080p: FFT from
                     ///< ~100 px for a disk, sigma ~7 for a Gaussian)
    Fast,            ///< the cheapest method at >= 40 dB: anti-aliased Gaussian -> three
                     ///< boxes (a hard-edged one and OIIO's filters: Exact); disk
                     ///< and polygon (hexagon too) -> reduced where its automatic factor
                     ///< exceeds 1; below that, bands (the hexagon: parallelograms) or
                     ///< Exact, whichever the cost models say is cheaper, with the fewest
                     ///< bands within its accuracy bound unless BlurOptions::bands is set;
                     ///< in iris mode, Exact
    Reference,       ///< brute-force 2-D convolution (slow; tests and charts)
    ThreeBoxes,      ///< Gaussian: three fractional-width boxes with the same variance
    Parallelograms,  ///< hexagon (6 straight blades): three sheared parallelograms
    Bands,           ///< disk, polygon: rows grouped into BlurOptions::bands bands, by running sums
    BilinearTaps,    ///< disk: Kawase's 9x9 (25 fetches) or 17x17 (81 fetches) kernel
    Reduced,         ///< any shape but OIIO's filters: blurred exactly at 1/N resolution (area reduction, the
                     ///< kernel scaled by 1/N) and enlarged back bilinearly (docs/methods/approximations.md,
                     ///< "Reduced"); N = BlurOptions::reduction, any real >= 1
    Spans,           ///< disk, polygon: exact, by row spans of prefix sums
    Fft,             ///< disk, polygon, Gaussian, OIIO's filters: exact, by FFT in overlap-save tiles
    Separable,       ///< Gaussian, OIIO's separable filters: exact, by the separable convolution
};

struct BlurOptions {
    Border border     = Border::Black;
    bool grow         = false;  ///< enlarge the data window by the kernel radius
    BlurMethod method = BlurMethod::Auto;
    int bands         = 0;      ///< Bands: horizontal bands per half kernel (1..64; a kernel
                                ///< not symmetric in y, a pentagon: twice that over its
                                ///< height); 0: the method's choice (Bands: 8; Fast: the
                                ///< fewest, 3..8, within its accuracy bound, fast_band_count)
    /// Iris mode (docs/methods/iris.md): average exp(iris * x) and return log(mean) / iris,
    /// so bright values dominate the average as in a real lens; 0 = a plain average.
    /// Applies to every channel but alpha and depth (Z); iris * (max - min) must stay
    /// within 30 (past it the sums in exp space lose the dark values: refused).
    float iris = 0.0f;
    /// Reduced: the reduction factor N (a real number in 1..16; 1 is the exact blur); 0
    /// picks it from the kernel (reduction_factor). Iris mode is refused with it (a
    /// block's mean of exp(k x) widens every highlight by up to a block: 20 dB measured).
    float reduction = 0.0f;
    /// The methods whose single call can take long, method=reference and the FFT (large
    /// kernels, kernel images): called with the fraction done (0..1) as rows or tiles
    /// finish; from one thread at a time, in rising order. Empty: nothing is counted.
    std::function<void(float)> progress;
};

/// BlurMethod::Reduced's automatic factor: the kernel's narrower side (a Gaussian: 4 sigma)
/// over 25, so the reduced kernel is 25 pixels across (a polygon's: 30, for its corners),
/// at most 8; 1 (the exact blur) when that is under 1.5 (kernels under 37.5 pixels, a
/// polygon under 45), where the reduction saves too little.
/// docs/benchmarks.md charts what it costs and loses.
double reduction_factor(const Kernel& k);

/// The effective kernel of BlurMethod::Bands: the exact kernel's rows grouped into at
/// most `bands` bands per half, each band one anti-aliased interval of the band's mean
/// area and centre. Same energy as the exact kernel.
KernelWeights banded_weights(const Kernel& k, int bands, int nthreads = 0);

/// The effective kernel of BlurMethod::BilinearTaps: what Kawase's bilinear fetches
/// (one per 2 x 2 group of pixels, at the group's centroid, weighted by its area) add up
/// to. `fetches` receives the number that carry weight (25 for 9 x 9; 77 of the
/// 81 for 17 x 17, whose corner groups miss the disk).
KernelWeights bilinear_tap_weights(const Kernel& k, int* fetches = nullptr);

/// The effective kernel of BlurMethod::ThreeBoxes: three uniform boxes along x and three
/// along y (fractional widths), together of the Gaussian's variance.
KernelWeights three_box_weights(const Kernel& k);

/// Blur `src` into `dst` (ImageBufAlgo style: false + dst.geterror() on failure).
/// `roi` (default: the source data window, grown if asked) is the region computed.
/// NaN and infinite source values (infinite depth, say) reach exactly the outputs whose
/// exact kernel has weight on them, as in the brute-force convolution: +inf or -inf where
/// all they reach have that sign, NaN otherwise (the same rule in iris mode, where
/// exp(k * -inf) = 0 would otherwise drop a -inf); every other output is the blur with them
/// read as 0 (in iris mode as the channel's least finite value, so its range stays the
/// data's), whatever the method (they are looked for in one pass over the source).
bool blur(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Kernel& k,
          const BlurOptions& opts = {}, OIIO::ROI roi = {}, int nthreads = 0);
/// What blur() checks before it reads an image: the kernel (check_kernel), the method
/// against the kernel, bands, iris and reduction. False + `err` naming the option.
bool check_blur_options(const Kernel& k, const BlurOptions& opts, std::string& err);
OIIO::ImageBuf blur(const OIIO::ImageBuf& src, const Kernel& k, const BlurOptions& opts = {},
                    OIIO::ROI roi = {}, int nthreads = 0);

/// Convolve with an image as the kernel (any size, colour allowed), by FFT. The kernel's
/// centre is its data window's pixel (xbegin + width / 2, ybegin + height / 2), which is
/// (0, 0) for OIIO's make_kernel results. Channels: a 1-channel kernel blurs every
/// channel; otherwise source channel c uses kernel channel c, and source channels past
/// the kernel's (alpha, say) use the mean of the kernel's channels; a kernel with more
/// channels than the source is refused, unless the one too many is the kernel's alpha
/// (an RGBA aperture picture on an RGB image: its alpha is dropped). Each kernel channel
/// is normalised to sum 1 (energy kept); a channel summing to <= 0 or whose weights cancel
/// (absolute sum over 1e6 times the sum), or any non-finite kernel value, is refused, and
/// in iris mode a kernel with negative weights (its mean of exp(k x) could fall to 0 or
/// below). NaN and infinite source values reach exactly the
/// outputs whose kernel channel has weight on them, as for blur() (an infinity through a
/// negative weight changes sign). opts.method and opts.bands are ignored; opts.iris applies.
/// Computed in overlap-save tiles (core/blur/blur_fft.cpp) in double.
bool convolve_image(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ImageBuf& kernel,
                    const BlurOptions& opts = {}, OIIO::ROI roi = {}, int nthreads = 0);

/// convolve_image's checks of `kernel` alone, for an image of `image_channels` channels
/// (what a caller runs where it will not convolve, e.g. at size 0). False + `err`.
bool check_kernel_image(const OIIO::ImageBuf& kernel, int image_channels, const BlurOptions& opts, std::string& err);

/// Convolve with explicit weights by brute force: the exact reference for every method.
bool convolve_reference(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src,
                        const KernelWeights& weights, const BlurOptions& opts = {},
                        OIIO::ROI roi = {}, int nthreads = 0);

}  // namespace bokeh
