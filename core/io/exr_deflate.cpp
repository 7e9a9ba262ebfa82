// exr_deflate.cpp — ZIP and ZIPS compression of scanline OpenEXR files with libdeflate.
//
// Why: encoding is most of the cost of a frame in a sequence. Copying a 1920x1080 float
// RGBA+Z zip frame (oiiotool in.exr -o out.exr, OpenEXR 3.1) spends 68 % of its CPU time
// in zlib (`perf record`, `perf report --sort dso`), and the zip encode alone is about
// 1.0 CPU-second a frame. libdeflate writes the same zlib streams in 0.39-0.54 s at sizes
// within 0.1 % (levels 1-6; the figures and the command are in docs/io.md, "Writing zip
// at I/O speed"). OpenEXR 3.2 moved to libdeflate for the same reason; Debian's 3.1 has
// zlib, so write_image compresses the chunks itself and leaves the rest of the file to
// OpenEXR through OIIO: OIIO writes the file uncompressed into memory, and this file
// rewrites it compressed. The header stays OIIO's byte for byte but for its compression
// attribute, so metadata is written exactly as OIIO would write it.
//
// The format (OpenEXR, "OpenEXR File Layout" and "Technical Introduction"): magic
// 20000630, a version word (2, flags 0x200 tiled, 0x400 long names, 0x800 deep, 0x1000
// multipart), attributes as name\0 type\0 size:int32 value, a 0 byte; the offset table (a
// uint64 file position per chunk); chunks as y:int32 size:int32 data. An uncompressed
// chunk is one scanline holding each channel's pixels in turn (channels in the order of
// the channel list). A ZIP chunk is 16 scanlines (ZIPS: 1) of that data, the bytes split
// into the even-indexed half then the odd, each byte replaced by its difference from the
// one before plus 128 (mod 256), and deflated as a zlib stream; a chunk that deflates to
// no fewer bytes than it holds is stored as it is (readers take size == raw size as
// uncompressed).
//
// Limits: single-part flat scanline files with increasing line order and unsubsampled
// channels; anything else is declined and write_image keeps OIIO's own writer.

#include "io/exr_deflate.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>

#include <libdeflate.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

namespace bokeh::detail {

namespace {

constexpr uint32_t kExrMagic       = 20000630;
constexpr uint32_t kFlagTiled      = 0x200;
constexpr uint32_t kFlagDeep       = 0x800;
constexpr uint32_t kFlagMultipart  = 0x1000;
constexpr uint8_t kCompressionNone = 0;
constexpr uint8_t kCompressionZips = 2;
constexpr uint8_t kCompressionZip  = 3;

uint32_t read_u32(const unsigned char* p)
{
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
int32_t read_i32(const unsigned char* p) { return int32_t(read_u32(p)); }
uint64_t read_u64(const unsigned char* p)
{
    return uint64_t(read_u32(p)) | uint64_t(read_u32(p + 4)) << 32;
}
void put_u32(std::vector<unsigned char>& out, uint32_t v)
{
    for (int i = 0; i < 4; ++i)
        out.push_back(static_cast<unsigned char>(v >> (8 * i)));
}
void put_u64(unsigned char* p, uint64_t v)
{
    for (int i = 0; i < 8; ++i)
        p[i] = static_cast<unsigned char>(v >> (8 * i));
}

// What the header says about the pixels, and where its compression byte is.
struct ScanlineHeader {
    size_t header_bytes      = 0;  // up to and including the terminating 0 byte
    size_t compression_at    = 0;  // offset of the compression attribute's value
    int ymin = 0, ymax = -1;
    int64_t line_bytes       = 0;  // one uncompressed scanline, all channels
    bool has_compression     = false;
    bool has_data_window     = false;
    bool has_channels        = false;
    uint8_t compression      = 0xff;
    uint8_t line_order       = 0;
};

// The uncompressed bytes one pixel of each channel takes, summed, from a chlist value;
// false for subsampled channels or an unknown pixel type.
bool channel_list_bytes(const unsigned char* p, const unsigned char* end, int width,
                        int64_t& line_bytes)
{
    line_bytes = 0;
    while (p < end && *p) {
        const unsigned char* name_end = static_cast<const unsigned char*>(
            std::memchr(p, 0, size_t(end - p)));
        if (!name_end || end - name_end < 17)
            return false;
        p                       = name_end + 1;
        const int32_t type      = read_i32(p);
        const int32_t xsampling = read_i32(p + 8);
        const int32_t ysampling = read_i32(p + 12);
        if (xsampling != 1 || ysampling != 1 || type < 0 || type > 2)
            return false;
        line_bytes += int64_t(width) * (type == 1 ? 2 : 4);  // UINT 0, HALF 1, FLOAT 2
        p += 16;
    }
    return p < end && line_bytes > 0;
}

bool parse_header(const std::vector<unsigned char>& file, ScanlineHeader& h, std::string& why)
{
    const unsigned char* data = file.data();
    const size_t size         = file.size();
    if (size < 8 || read_u32(data) != kExrMagic) {
        why = "not an OpenEXR file";
        return false;
    }
    const uint32_t version = read_u32(data + 4);
    if ((version & 0xff) != 2 || (version & (kFlagTiled | kFlagDeep | kFlagMultipart))) {
        why = "not a single-part scanline file";
        return false;
    }
    int width  = 0;
    size_t pos = 8;
    std::vector<std::pair<size_t, size_t>> channels_value;  // deferred: needs the width
    while (pos < size && data[pos] != 0) {
        const auto* name_end = static_cast<const unsigned char*>(
            std::memchr(data + pos, 0, size - pos));
        if (!name_end)
            break;
        const std::string name(reinterpret_cast<const char*>(data + pos),
                               size_t(name_end - (data + pos)));
        const size_t type_at = size_t(name_end - data) + 1;
        const auto* type_end = type_at < size ? static_cast<const unsigned char*>(
                                   std::memchr(data + type_at, 0, size - type_at))
                                              : nullptr;
        if (!type_end || size_t(type_end - data) + 5 > size)
            break;
        const size_t size_at = size_t(type_end - data) + 1;
        const int32_t vsize  = read_i32(data + size_at);
        const size_t value   = size_at + 4;
        if (vsize < 0 || value + size_t(vsize) > size)
            break;
        if (name == "compression" && vsize == 1) {
            h.has_compression = true;
            h.compression     = data[value];
            h.compression_at  = value;
        } else if (name == "dataWindow" && vsize == 16) {
            h.has_data_window = true;
            width             = read_i32(data + value + 8) - read_i32(data + value) + 1;
            h.ymin            = read_i32(data + value + 4);
            h.ymax            = read_i32(data + value + 12);
        } else if (name == "lineOrder" && vsize == 1) {
            h.line_order = data[value];
        } else if (name == "channels") {
            channels_value = { { value, size_t(vsize) } };
        }
        pos = value + size_t(vsize);
    }
    if (pos >= size || data[pos] != 0 || !h.has_compression || !h.has_data_window
        || channels_value.empty()) {
        why = "header incomplete";
        return false;
    }
    h.header_bytes = pos + 1;
    if (h.compression != kCompressionNone || h.line_order != 0 || width <= 0
        || h.ymax < h.ymin) {
        why = "not uncompressed with increasing line order";
        return false;
    }
    const unsigned char* chlist = data + channels_value[0].first;
    h.has_channels = channel_list_bytes(chlist, chlist + channels_value[0].second, width,
                                        h.line_bytes);
    if (!h.has_channels) {
        why = "channels subsampled or of an unknown type";
        return false;
    }
    return true;
}

// A libdeflate compressor and the predictor's scratch, one per worker thread.
struct ChunkCoder {
    explicit ChunkCoder(int level) : compressor(libdeflate_alloc_compressor(level)) {}
    ~ChunkCoder() { libdeflate_free_compressor(compressor); }
    ChunkCoder(const ChunkCoder&)            = delete;
    ChunkCoder& operator=(const ChunkCoder&) = delete;
    libdeflate_compressor* compressor;
    std::vector<unsigned char> predicted;
};

// One chunk's stored bytes (without its y and size): the raw scanlines split into even
// and odd bytes, differenced, deflated; or the raw bytes where that is no smaller.
void encode_chunk(ChunkCoder& coder, const std::vector<const unsigned char*>& lines,
                  size_t line_bytes, std::vector<unsigned char>& stored)
{
    const size_t n = line_bytes * lines.size();
    coder.predicted.resize(n);
    unsigned char* even = coder.predicted.data();
    unsigned char* odd  = even + (n + 1) / 2;
    size_t k            = 0;
    for (const unsigned char* line : lines)
        for (size_t i = 0; i < line_bytes; ++i, ++k)
            *((k & 1) ? odd++ : even++) = line[i];
    unsigned char* t = coder.predicted.data();
    int previous     = t[0];
    for (size_t i = 1; i < n; ++i) {
        const int current = t[i];
        t[i]              = static_cast<unsigned char>(current - previous + 128 + 256);
        previous          = current;
    }
    stored.resize(libdeflate_zlib_compress_bound(coder.compressor, n));
    const size_t packed = coder.compressor
                              ? libdeflate_zlib_compress(coder.compressor, t, n,
                                                         stored.data(), stored.size())
                              : 0;
    if (packed == 0 || packed >= n) {
        stored.resize(n);
        unsigned char* o = stored.data();
        for (const unsigned char* line : lines)
            o = std::copy(line, line + line_bytes, o);
    } else {
        stored.resize(packed);
        // The bound reserved a raw chunk's size; kept, the chunks' slack adds up to about
        // a second uncompressed copy of the frame until the file is written. Measured
        // (/usr/bin/time, `bokehtool in.exr -o out.exr` of a 3840x2160 half RGBA+Z zip
        // frame): peak resident 719 MB kept, 657 MB given back.
        stored.shrink_to_fit();
    }
}

}  // namespace

DeflateResult deflate_exr_file(const std::vector<unsigned char>& uncompressed,
                               ExrDeflate compression, int level,
                               std::FILE* f, std::string& why)
{
    ScanlineHeader h;
    if (!parse_header(uncompressed, h, why))
        return DeflateResult::Declined;
    const int64_t height = int64_t(h.ymax) - h.ymin + 1;
    const size_t table   = h.header_bytes;
    if (uncompressed.size() < table + size_t(height) * 8) {
        why = "offset table truncated";
        return DeflateResult::Declined;
    }
    // Every scanline's bytes, checked against its chunk header.
    std::vector<const unsigned char*> line_at(static_cast<size_t>(height));
    for (int64_t i = 0; i < height; ++i) {
        const uint64_t at = read_u64(uncompressed.data() + table + size_t(i) * 8);
        if (at > uncompressed.size() || uncompressed.size() - at < 8 + uint64_t(h.line_bytes)
            || read_i32(uncompressed.data() + at) != h.ymin + i
            || read_i32(uncompressed.data() + at + 4) != h.line_bytes) {
            why = "a scanline chunk is not where the offset table says";
            return DeflateResult::Declined;
        }
        line_at[size_t(i)] = uncompressed.data() + at + 8;
    }

    const int lines_per_chunk = compression == ExrDeflate::Zip ? 16 : 1;
    const size_t nchunks      = size_t((height + lines_per_chunk - 1) / lines_per_chunk);
    const size_t chunk_bytes  = size_t(lines_per_chunk) * size_t(h.line_bytes);
    const size_t per_batch    = std::max<size_t>(1, (size_t(16) << 20) / std::max<size_t>(chunk_bytes, 1));

    // The header with its compression, and room for the offset table, filled in last.
    std::vector<unsigned char> head(uncompressed.begin(), uncompressed.begin() + long(table));
    head[h.compression_at] = compression == ExrDeflate::Zip ? kCompressionZip : kCompressionZips;
    std::vector<unsigned char> offsets(nchunks * 8);
    if (std::fwrite(head.data(), 1, head.size(), f) != head.size()
        || std::fwrite(offsets.data(), 1, offsets.size(), f) != offsets.size())
        return DeflateResult::WriteFailed;
    uint64_t at = table + offsets.size();

    std::vector<std::vector<unsigned char>> stored(std::min(per_batch, nchunks));
    tbb::enumerable_thread_specific<ChunkCoder> coders(level);
    std::vector<unsigned char> chunk_head;
    for (size_t first_chunk = 0; first_chunk < nchunks; first_chunk += per_batch) {
        const size_t n = std::min(per_batch, nchunks - first_chunk);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const auto& range) {
            ChunkCoder& coder = coders.local();
            std::vector<const unsigned char*> lines;
            for (size_t k = range.begin(); k != range.end(); ++k) {
                const size_t first = (first_chunk + k) * size_t(lines_per_chunk);
                const size_t last  = std::min(first + size_t(lines_per_chunk), size_t(height));
                lines.assign(line_at.begin() + long(first), line_at.begin() + long(last));
                encode_chunk(coder, lines, size_t(h.line_bytes), stored[k]);
            }
        });
        for (size_t k = 0; k < n; ++k) {
            const size_t c = first_chunk + k;
            put_u64(offsets.data() + c * 8, at);
            chunk_head.clear();
            put_u32(chunk_head, uint32_t(h.ymin + int(c) * lines_per_chunk));
            put_u32(chunk_head, uint32_t(stored[k].size()));
            if (std::fwrite(chunk_head.data(), 1, chunk_head.size(), f) != chunk_head.size()
                || std::fwrite(stored[k].data(), 1, stored[k].size(), f) != stored[k].size())
                return DeflateResult::WriteFailed;
            at += chunk_head.size() + stored[k].size();
        }
    }
    if (std::fseek(f, long(table), SEEK_SET) != 0
        || std::fwrite(offsets.data(), 1, offsets.size(), f) != offsets.size())
        return DeflateResult::WriteFailed;
    return DeflateResult::Written;
}

}  // namespace bokeh::detail
