// bench_common.h — what bokeh-bench's tasks share: the CSV columns every task writes and
// the error fields in them, and where on a frame an error is worth measuring.
#pragma once

#include <bokeh/metrics.h>

#include <string>

#include <OpenImageIO/imagebuf.h>

namespace bokeh_bench {

/// The columns of every task's CSV (chart.py reads them by name). Errors are against the
/// task's exact reference: RMSE in linear light, PSNR after the fixed tone map x / (1 + x)
/// per channel (peak 1; 999 when identical), and the largest absolute linear difference.
inline constexpr const char* kCsvHeader
    = "task,method,peer,size_px,threads,median_ms,reps,rmse_linear,psnr_db_tonemapped,max_abs_linear";

/// The last three columns for `e`.
std::string error_fields(const bokeh::ImageError& e);

/// The crop (at most w x h, inside `img`'s data window) where brightness varies most: a
/// light and the gradient around it. Searched on 8 x 8 blocks of R + G + B.
OIIO::ROI most_varied_crop(const OIIO::ImageBuf& img, int w, int h, int threads);

}  // namespace bokeh_bench
