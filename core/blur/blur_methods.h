// blur_methods.h — internal to the library: the blur methods that blur() (blur.cpp)
// dispatches to and that have no declaration in plane.h, and what the method files share
// besides the planes: the box passes (blur_box.cpp), the separable convolution and the
// brute force (blur_separable.cpp), and the interval weights of the bands and the
// hexagon's segments.
#pragma once

#include "blur/convolve.h"

#include <functional>
#include <utility>
#include <vector>

namespace bokeh::detail {

/// A box of fractional width (blur_box.cpp), read off its 1-D weights: `full` pixels each side at
/// weight `inner`, then one end pixel each side at weight `end` (0 when none).
struct BoxPass {
    int full = 0, radius = 0;
    double inner = 1.0, end = 0.0;
    explicit BoxPass(const std::vector<double>& w)
    {
        radius = int(w.size() / 2);
        inner  = w[size_t(radius)];
        const bool partial = radius > 0 && w.front() != inner;
        full   = partial ? radius - 1 : radius;
        end    = partial ? w.front() : 0.0;
    }
};

/// The box along x then y on a padded plane ("valid" convolution; iris mode).
Plane box_blur(const Plane& in, const std::vector<double>& wx, const std::vector<double>& wy,
               int nthreads);
/// The box straight from the source into `dst` over `roi`, by the border rule.
bool box_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                const BoxPass& bx, const BoxPass& by, Border border, int nthreads);
/// BlurMethod::ThreeBoxes straight from the source into `dst` over `roi`: each of bx, by
/// three times.
bool three_boxes_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi, const BoxPass& bx,
                        const BoxPass& by, Border border, int nthreads);
/// BlurMethod::ThreeBoxes' box along x and along y for the Gaussian of `k`.
std::pair<std::vector<double>, std::vector<double>> gaussian_boxes(const Kernel& k);

/// The brute force on a padded plane (blur_separable.cpp): the reference; `progress` as
/// BlurOptions::progress (by rows).
Plane convolve_brute(const Plane& in, const KernelWeights& kernel, int nthreads,
                     const std::function<void(float)>& progress = {});
/// The separable convolution wx (x) wy on a padded plane (iris mode).
Plane convolve_separable(const Plane& in, const std::vector<double>& wx,
                         const std::vector<double>& wy, int nthreads);
/// The separable convolution straight from the source into `dst` over `roi`.
bool separable_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                      const std::vector<double>& wx, const std::vector<double>& wy, Border border, int nthreads);

/// Pixel i's share of the interval [a, b]: the length of [i - 1/2, i + 1/2] inside it,
/// over b - a. `first` is the first pixel with a share; `w` the shares from there.
struct IntervalWeights {
    int first = 0;
    std::vector<double> w;
    int last() const { return first + int(w.size()) - 1; }
};
/// The shares of the pixels [a, b] reaches (blur_hexagon_sweep.cpp; the bands' intervals
/// and the hexagon's segments).
IntervalWeights interval_weights(double a, double b);

}  // namespace bokeh::detail
