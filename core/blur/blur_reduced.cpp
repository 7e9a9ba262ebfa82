// blur_reduced.cpp — any kernel at reduced resolution (BlurMethod::Reduced; the defocus's
// reduced buffers applied to one uniform kernel, docs/methods/approximations.md).
//
// The source is reduced by N, any real factor (area mean; with the black border the blocks
// straddling the data window count the outside as 0, so energy is kept), the kernel scaled
// by 1/N and applied exactly there, and the result enlarged bilinearly straight into `dst`
// (bilinear: no ringing around 1e6 highlights, which Catmull-Rom gives for 1-2 dB more).
// The cost falls as N^3 (pixels / N^2, row spans / N) down to the reduction and
// enlargement; the error is the detail lost under 1/N of the kernel, so the automatic N
// keeps the reduced kernel 25 px across (30 for a polygon). Measured on bokeh-bench's crop
// of the "lights" frame against the exact disk: 41.0-51.2 dB from 38 to 255 px, with
// D = 63 at 41.3 dB in 21-23 ms (6 bands: 41.1 dB in 42-44 ms).
// Limits: not for iris mode. Run on exp(k x) (and back by log / k before the enlargement)
// it measured 20 dB against the exact iris blur: a block's mean of exp(k x) is its
// brightest pixel's, so every highlight grows by up to a block.

#include <bokeh/blur.h>
#include <bokeh/resample.h>

#include "blur/convolve.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace bokeh {

using namespace detail;

double reduction_factor(const Kernel& k)
{
    double across = std::min(k.width_px, k.height_px);
    if (k.shape == KernelShape::Gaussian) {
        const auto [sx, sy] = gaussian_sigma(k);
        across = 4.0 * std::min(sx, sy);
    }
    // 25 px for a disk: the smallest that keeps 40 dB on bokeh-bench's crop at every size
    // (24 px gave 39.9 dB at 63 px). The layered defocus found the same on its scenes: its
    // 40 dB budget keeps reduced kernels of 24 px (settings_for_budget, defocus.cpp).
    // 30 px for a polygon, whose straight edges and corners lose more: at 25 px the crop
    // measured 38.4-38.7 dB for a pentagon and 38.8-39.8 for a hexagon from 56 to 80 px;
    // at 30 px, 40.4-48.4 (pentagon), 41.1-44.4 (hexagon) and 42.3-50.2 (octagon) from 56
    // to 255 px.
    const double reduced_px = k.shape == KernelShape::Polygon ? 30.0 : 25.0;
    const double n = across / reduced_px;
    return n < 1.5 ? 1.0 : std::min(n, 8.0);
}

namespace detail {

bool blur_reduced(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const Kernel& k,
                  const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    double n = opts.reduction > 0.0f ? double(opts.reduction) : reduction_factor(k);
    BlurOptions exact = opts;
    exact.method      = BlurMethod::Exact;
    exact.reduction   = 0.0f;
    // A kernel that is a point stays the identity, bit for bit, whatever the factor.
    if (std::max({ k.width_px, k.height_px, 4.0f * k.sigma_px }) < 4.0f
        && kernel_weights(k).is_identity())
        n = 1.0;
    if (n == 1.0)
        return blur(dst, in, k, exact, roi, nthreads);
    Kernel low_k = k;
    low_k.width_px  = float(k.width_px / n);
    low_k.height_px = float(k.height_px / n);
    low_k.sigma_px  = float(k.sigma_px / n);
    if (!roi.defined() && !opts.grow) {
        roi = in.roi();
    } else if (!roi.defined()) {
        // The method's reach: the reduced kernel's, and a reduced pixel more, at full size.
        const KernelWeights low_w = kernel_weights(low_k, nthreads);
        roi = grown(in.roi(), int(std::ceil((low_w.rx + 1) * n)), int(std::ceil((low_w.ry + 1) * n)));
    }
    // Reduced pixel i covers [i n, (i + 1) n) (anchored at 0, as reduce() and enlarge()):
    // the reduced image is every pixel that touches the data window, the area mean of it
    // (the outside counted as 0 with the black border, so energy is kept).
    const int nc         = in.nchannels();
    const OIIO::ROI data = in.roi();
    auto below = [&](int v) { return int(std::floor(v / n)); };
    auto above = [&](int v) { return int(std::ceil(v / n)); };
    OIIO::ImageSpec low_spec(above(data.xend) - below(data.xbegin),
                             above(data.yend) - below(data.ybegin), nc, OIIO::TypeFloat);
    low_spec.x = below(data.xbegin);
    low_spec.y = below(data.ybegin);
    OIIO::ImageBuf low_src, low;
    reset_uninitialised(low_src, low_spec);
    const ConstPlaneView from(static_cast<const float*>(in.localpixels()), data.width(),
                              data.height(), nc, size_t(in.scanline_stride()) / sizeof(float));
    const PlaneView reduced{ static_cast<float*>(low_src.localpixels()), low_spec.width,
                             low_spec.height, nc, size_t(low_spec.width) * size_t(nc) };
    std::string err;
    if (!reduce_plane(from, reduced, AxisMap::factor(1.0 / n, low_spec.x, data.xbegin),
                      AxisMap::factor(1.0 / n, low_spec.y, data.ybegin),
                      std::vector<Reducer>(size_t(nc), Reducer::Mean), -1,
                      opts.border == Border::Black, err, nthreads)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    // The reduced pixels whose enlargement covers roi, and one more each side (the
    // bilinear reads), blurred there by the border rule.
    const OIIO::ROI low_roi(below(roi.xbegin) - 1, below(roi.xend - 1) + 2, below(roi.ybegin) - 1,
                            below(roi.yend - 1) + 2);
    exact.grow = false;
    if (!blur(low, low_src, low_k, exact, low_roi, nthreads)) {
        dst.errorfmt("{}", low.geterror());
        return false;
    }
    // Enlarged straight into `dst` over roi: pixel x reads the reduced image at
    // (x + 1/2) / n - 1/2, as enlarge() does.
    prepare_destination(dst, in, roi);
    const ConstPlaneView blurred(static_cast<const float*>(low.localpixels()), low_roi.width(),
                                 low_roi.height(), nc, size_t(low_roi.width()) * size_t(nc));
    const PlaneView into{ static_cast<float*>(dst.localpixels()), roi.width(), roi.height(), nc,
                          size_t(roi.width()) * size_t(nc) };
    ResampleOptions eo;
    eo.filter = ResampleFilter::Bilinear;
    if (!resample_plane(blurred, into, AxisMap::factor(n, roi.xbegin, low_roi.xbegin),
                        AxisMap::factor(n, roi.ybegin, low_roi.ybegin), eo, err, nthreads)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    return true;
}

}  // namespace detail

}  // namespace bokeh
