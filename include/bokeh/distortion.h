// distortion.h — a lens's radial distortion and lateral colour across the frame: the frame
// distorted or undistorted, and the STMap that carries the same warp to other tools
// (docs/methods/distortion.md).
//
// Coordinates. Pixel (x, y) stands for its centre (x + 0.5, y + 0.5). Positions are
// normalised by the display window: p = (X - c) / R, with c the display window's centre
// (plus `centre_px`) and R its half-diagonal, so a corner of the frame lies at |p| = 1.
//
// Models (r = |p|; the undistorted image is the ideal pinhole one, the distorted one what
// the lens records):
//   Polynomial  r_d = r_u (1 + k1 r_u^2 + k2 r_u^4)       (Brown-Conrady's radial terms;
//               k1 < 0 barrel, k1 > 0 pincushion)
//   Division    r_u = r_d / (1 + k1 r_d^2 + k2 r_d^4)     (Fitzgibbon, "Simultaneous linear
//               estimation of multiple view geometry and lens distortion", CVPR 2001;
//               k1 < 0 barrel)
// Lateral colour: the red and blue images are magnified by 1 + lateral_r and 1 + lateral_b
// against the green one about the same centre (the distorted position of channel c is
// (1 + lateral_c) times green's), so a white point at radius r px shows a fringe of
// |lateral_r - lateral_b| r px between its red and blue edges.
#pragma once

#include <bokeh/base.h>

#include <string>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

enum class DistortionModel { Polynomial, Division };

struct LensDistortion {
    DistortionModel model = DistortionModel::Polynomial;
    double k1 = 0.0, k2 = 0.0;
    double lateral_r = 0.0, lateral_b = 0.0;  ///< magnification of R, B against G, minus 1
    double centre_x_px = 0.0, centre_y_px = 0.0;  ///< the centre's offset from the display window's

    /// The normalised distorted position of green's undistorted position (xu, yu).
    void distort(double xu, double yu, double& xd, double& yd) const;
    /// Its inverse; false where the mapping has none (it folds past its monotone range).
    bool undistort(double xd, double yd, double& xu, double& yu) const;
};

/// Check the coefficients against the frame `display` (the display window): finite, and
/// the radial mapping increasing out to the frame's farthest corner (else the image folds
/// over itself and has no inverse there). False + `err` naming the coefficient.
bool check_distortion(const LensDistortion& lens, const OIIO::ROI& display, std::string& err);

enum class DistortDirection {
    Distort,    ///< undistorted (pinhole) input -> what the lens records
    Undistort,  ///< recorded input -> the pinhole image
};

/// Warp `src` by the lens: each output pixel samples `src` at its mapped position, bilinear
/// with black past the data window (OIIO's interppixel); depth channels (Z, ZBack, *.Z)
/// take the nearest pixel, so no depth between two surfaces is invented. R and B follow
/// their lateral colour; every other channel follows green. Output over `roi` (default:
/// src's data window), src's display window and metadata. False + dst.geterror().
bool lens_distort(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const LensDistortion& lens,
                  DistortDirection direction, OIIO::ROI roi = {}, int nthreads = 0);
inline OIIO::ImageBuf lens_distort(const OIIO::ImageBuf& src, const LensDistortion& lens, DistortDirection direction,
                                   OIIO::ROI roi = {}, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    lens_distort(dst, src, lens, direction, roi, nthreads);
    return dst;
}

/// The STMap of the same warp over `like`'s data window (display window `like`'s): R and G
/// hold the source position of each output pixel as Nuke's STMap reads it, s = (X - full_x)
/// / full_width and t = 1 - (Y - full_y) / full_height (t up, 0 at the bottom), so
/// sampling the source there gives lens_distort's result. One position a pixel: a lens
/// with lateral colour is refused (it moves R and B apart). False + dst.geterror().
bool distortion_stmap(OIIO::ImageBuf& dst, const OIIO::ImageSpec& like, const LensDistortion& lens,
                      DistortDirection direction, int nthreads = 0);
inline OIIO::ImageBuf distortion_stmap(const OIIO::ImageSpec& like, const LensDistortion& lens,
                                       DistortDirection direction, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    distortion_stmap(dst, like, lens, direction, nthreads);
    return dst;
}

}  // namespace bokeh
