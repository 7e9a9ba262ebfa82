// blur_fixtures.h — the images, kernels and method lists the blur tests (tests/blur/) share.
#pragma once

#include <bokeh/blur.h>

#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace blur_test {

/// Deterministic texture in 4 channels with a few very bright pixels (500; none without
/// `bright`), over a w x h data window at (x0, y0).
OIIO::ImageBuf test_image(int w, int h, int x0 = 0, int y0 = 0, bool bright = true);

/// A kernel and the name a trace gives it.
struct Named {
    std::string name;
    bokeh::Kernel k;
};

/// A hexagon (6 straight blades) w x h px at `rotation` degrees.
bokeh::Kernel hexagon(float w, float h, float rotation = 0.0f);

/// The kernels the tests run every method on: boxes, Gaussians, disks, polygons (curved,
/// rotated, holed, anamorphic), hard edges and OIIO's filters.
std::vector<Named> kernels();

/// The ways to compute `k` exactly: the automatic choice, and each exact method by name
/// (disk, polygon: row spans and FFT tiles; Gaussian: FFT tiles).
std::vector<bokeh::BlurMethod> exact_methods(const bokeh::Kernel& k);

/// The approximations that apply to `k` (each against its own effective kernel elsewhere):
/// the bands, the parallelograms, the three boxes, Kawase's bilinear taps, and fast.
std::vector<bokeh::BlurMethod> approximations(const bokeh::Kernel& k);

/// exact_methods(k), then approximations(k).
std::vector<bokeh::BlurMethod> every_method(const bokeh::Kernel& k);

/// " (spans)", " (fft)", ...: a method's name for a trace ("" for the others).
std::string method_name(bokeh::BlurMethod m);

/// The largest value of any channel (the scale of a tolerance).
double peak(const OIIO::ImageBuf& img);

/// Each channel's sum over the data window, in double.
std::vector<double> channel_sums(const OIIO::ImageBuf& img);

/// sum |a - b| over the kernel grid of the larger one (the L1 distance of two kernels,
/// 0..2; 2 = disjoint).
double kernel_distance(const bokeh::KernelWeights& a, const bokeh::KernelWeights& b);

}  // namespace blur_test
