// resample_common.h — internal to the library: what the resampling files share
// (core/resample/resample.cpp defines it; core/resample/resample_depth_aware.cpp uses it): the two 1-D
// kernels the depth-aware enlargement also weights with, the checks of planes and axis
// maps, and the ImageBuf <-> plane plumbing of the image-level functions.
#pragma once

#include <bokeh/resample.h>


#include <string>

#include <OpenImageIO/imagebuf.h>

namespace bokeh::detail {

/// The tent (linear) kernel: 1 - |t| within |t| < 1.
double tent(double t);
/// The uniform cubic B-spline (Mitchell & Netravali 1988, B = 1, C = 0).
double bspline(double t);

/// False + `err` for an empty plane or differing channel counts.
bool check_planes(const ConstPlaneView& src, const PlaneView& dst, std::string& err);
/// False + `err` for an axis map with a size not finite and > 0.
bool check_map(const AxisMap& m, std::string& err);

/// False + an error on `dst` (prefixed by `what`) for an empty, deep or volume `src`.
bool check_image(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const char* what);
/// `src` if its pixels are contiguous local floats, else a float copy in `holder`.
const OIIO::ImageBuf& contiguous_float(const OIIO::ImageBuf& src, OIIO::ImageBuf& holder);
/// The data window of a contiguous float image as a plane.
ConstPlaneView view_of(const OIIO::ImageBuf& f);
/// `dst` = a float image like `like` over `data`, display window `full`; its pixels as a
/// plane.
PlaneView make_output(OIIO::ImageBuf& dst, const OIIO::ImageSpec& like, const OIIO::ROI& data,
                      const OIIO::ROI& full);

}  // namespace bokeh::detail
