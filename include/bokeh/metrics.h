// metrics.h — how far a result is from its reference.
//
// The error every chart and accuracy test quotes: RMSE in linear light, and PSNR after a
// fixed tone map x / (1 + |x|) per channel (peak 1), so that HDR highlights (fairy lights
// at 300) do not swamp the measure and a dark-area error still counts.
#pragma once

#include <cstdint>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

struct ImageError {
    double rmse_linear = 0.0;  ///< root mean square difference, linear values
    double psnr_db     = 0.0;  ///< PSNR of the tone-mapped values, peak 1; 999 when identical
    double max_abs     = 0.0;  ///< largest absolute linear difference
    int64_t values     = 0;    ///< channel values compared
};

/// Compare `result` with `reference` channel by channel (same channel count) over `roi`
/// (default: the union of their data windows; a pixel outside an image's window counts
/// as 0 there). False + `err` when the channel counts differ or an image is deep.
bool compare(ImageError& e, const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference,
             std::string& err, OIIO::ROI roi = {}, int nthreads = 0);

}  // namespace bokeh
