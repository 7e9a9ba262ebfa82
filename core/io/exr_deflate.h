// exr_deflate.h — internal to the library: ZIP/ZIPS compression of a single-part scanline
// OpenEXR file that was written uncompressed (core/io/exr_deflate.cpp; io_write.cpp's write_image
// uses it).
#pragma once

#include <string>
#include <vector>

namespace bokeh::detail {

/// The OpenEXR compressions exr_deflate writes.
enum class ExrDeflate {
    Zip,   ///< ZIP_COMPRESSION: 16 scanlines a chunk
    Zips,  ///< ZIPS_COMPRESSION: one scanline a chunk
};

/// What deflate_exr_file did.
enum class DeflateResult {
    Written,   ///< `out` holds the compressed file
    Declined,  ///< not a single-part, flat, scanline, uncompressed file it can rewrite
};

/// Rewrite `uncompressed`, a complete single-part flat scanline OpenEXR file with
/// compression NONE, increasing line order and no subsampled channels, as the same file
/// compressed with `compression`: the header byte for byte except its compression
/// attribute, the pixels bit for bit. Chunks are compressed in parallel (the current TBB
/// arena) with libdeflate at `level` (1..12); the output does not depend on the thread
/// count. Declined (and `why` says what) for any other file.
DeflateResult deflate_exr_file(const std::vector<unsigned char>& uncompressed,
                               ExrDeflate compression, int level,
                               std::vector<unsigned char>& out, std::string& why);

}  // namespace bokeh::detail
