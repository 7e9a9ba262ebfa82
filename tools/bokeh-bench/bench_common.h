// bench_common.h — what bokeh-bench's tasks share: the CSV columns every task writes and
// the error fields in them, where on a frame an error is worth measuring, and the picture
// sheets that show it.
#pragma once

#include <bokeh/metrics.h>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh_bench {

/// The columns of every task's CSV (chart.py reads them by name). Errors are against the
/// task's exact reference: RMSE in linear light, PSNR after the fixed tone map x / (1 + x)
/// per channel (peak 1; 999 when identical), and the largest absolute linear difference.
inline constexpr const char* kCsvHeader
    = "task,method,peer,size_px,threads,median_ms,reps,rmse_linear,psnr_db_tonemapped,max_abs_linear";

/// The last three columns for `e`.
std::string error_fields(const bokeh::ImageError& e);

/// PSNR (compare's, over R, G, B, A) of `got` against `ref` over the pixels `in` marks
/// (a byte per pixel of `roi`, row by row, 1 = in): outside them `got` is taken as `ref`,
/// so the mean squared error over `roi` is theirs times their share of it, which the PSNR
/// then undoes. -1 when none is marked.
double masked_psnr(const OIIO::ImageBuf& got, const OIIO::ImageBuf& ref, const std::vector<uint8_t>& in,
                   const OIIO::ROI& roi, int threads);

/// The crop (at most w x h, inside `img`'s data window) where brightness varies most: a
/// light and the gradient around it. Searched on 8 x 8 blocks of R + G + B.
OIIO::ROI most_varied_crop(const OIIO::ImageBuf& img, int w, int h, int threads);

/// A picture sheet: `tiles` (label, RGB display values in 0..1, all the size of the first)
/// in a grid of `cols` columns, each with its label above it (DejaVu Sans; without that
/// font the tiles go unlabelled and their order is printed), as an 8-bit image at `path`.
/// False + `err` naming the file.
bool write_sheet(const std::string& path, const std::vector<std::pair<std::string, OIIO::ImageBuf>>& tiles,
                 int cols, int threads, std::string& err);

}  // namespace bokeh_bench
