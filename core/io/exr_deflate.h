// exr_deflate.h — internal to the library: ZIP/ZIPS compression of a single-part scanline
// OpenEXR file that was written uncompressed (core/io/exr_deflate.cpp; io_write.cpp's write_image
// uses it).
#pragma once

#include <cstdio>
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
    Written,      ///< the compressed file is written
    Declined,     ///< not a single-part, flat, scanline, uncompressed file it can rewrite
    WriteFailed,  ///< a write to the file failed (errno says why)
};

/// Rewrite `uncompressed`, a complete single-part flat scanline OpenEXR file with
/// compression NONE, increasing line order and no subsampled channels, into `f` as the
/// same file compressed with `compression`: the header byte for byte except its
/// compression attribute, the pixels bit for bit. Chunks are compressed in parallel (the
/// current TBB arena) with libdeflate at `level` (1..12), a batch of about 16 MiB of
/// scanlines at a time, each batch written before the next is compressed, and the offset
/// table filled in last: the compressed frame is never held whole beside the image and
/// the uncompressed file (93 MB for a 3840x2160 float RGBA+Z frame). The output does not
/// depend on the thread count. Declined (and `why` says what) for any other file, before
/// anything is written to `f`.
DeflateResult deflate_exr_file(const std::vector<unsigned char>& uncompressed,
                               ExrDeflate compression, int level, std::FILE* f, std::string& why);

}  // namespace bokeh::detail
