// io_budget.cpp — what reading an image file will allocate, known before anything is
// allocated, so a damaged header (a data window of 10^9 lines, 10^6 channels, deep
// sample counts of 2^31) is refused by name instead of ending the process in bad_alloc.
//
// EXR files are inspected with OpenEXR's C library (OpenEXRCore, openexr.h): it parses
// every part's header without reading pixels, checks each chunk's place in the file
// against the file's size, and is the part of OpenEXR that OSS-Fuzz exercises. For deep
// files the per-chunk sample-count tables are decoded (EXR_DECODE_SAMPLE_DATA_ONLY) and
// summed, stopping as soon as the sum passes the budget; the sample data are not read.
// Part 0's header is then parsed again by OpenEXR's C++ library (Imf::Header::readFrom,
// no pixel buffers), the one OIIO reads with: where the two parsers disagree on its data
// window or channel count, the file is refused as damaged (a 254-byte file the read fuzzer
// made reads as 64 x 64 to the C library and 10027009 x 1 to the C++ one, which then
// allocated 24 line buffers of 1.3 GB).
// Other formats: the header as OIIO's ImageInput::open reports it.
//
// The estimate is of what OIIO 2.4 allocates to read the file the way read_image does
// (subimage 0; every part of a flat multipart EXR, plus the merged image):
//  * flat: pixels x channels x 4 bytes (the image is read as float), plus 8 bytes per
//    chunk of every part (OpenEXR's chunk offset tables, read when the file is opened),
//    plus three rows of chunks in the file's own types (line and conversion buffers);
//  * deep: pixels x (16 + 8 x channels) bytes (OIIO's DeepData keeps 3 ints a pixel; its
//    EXR reader builds one pointer a channel a pixel, deepdata.cpp / exrinput.cpp) plus
//    samples x the bytes of one sample in the file's own channel types.
// Limits: subsampled EXR channels (x/y sampling > 1) are counted at full resolution
// (an overestimate); what later commands allocate is not part of this estimate.

#include <bokeh/io.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/openexr.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/sysutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

int64_t default_memory_budget_bytes()
{
    // Half the machine: the image read is rarely the only large buffer of a run (a
    // defocus holds several full-size planes beside it).
    const uint64_t physical = OIIO::Sysutil::physical_memory();
    return physical ? int64_t(physical / 2) : int64_t(8) << 30;
}

std::string memory_size_text(int64_t bytes)
{
    const double b = double(bytes);
    if (b >= double(int64_t(1) << 30))
        return format("{:.1f} GiB", b / double(int64_t(1) << 30));
    if (b >= double(1 << 20))
        return format("{:.1f} MiB", b / double(1 << 20));
    if (b >= 1024.0)
        return format("{:.1f} KiB", b / 1024.0);
    return format("{} bytes", bytes);
}

namespace {

bool is_exr_file(const std::string& path)
{
    unsigned char magic[4] = { 0, 0, 0, 0 };
    std::ifstream in(path, std::ios::binary);
    in.read(reinterpret_cast<char*>(magic), 4);
    return in.gcount() == 4 && magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31
           && magic[3] == 0x01;
}

// OpenEXRCore reports through a callback; keep the first message of the context.
struct CoreMessages {
    std::string first;
};

void keep_core_message(exr_const_context_t ctxt, exr_result_t code, const char* msg)
{
    void* user = nullptr;
    if (exr_get_user_data(ctxt, &user) != EXR_ERR_SUCCESS || !user)
        return;
    auto* m = static_cast<CoreMessages*>(user);
    if (m->first.empty())
        m->first = msg && *msg ? std::string(msg) : exr_get_default_error_message(code);
}

// Saturating a + b*c for byte counts from untrusted headers.
int64_t add_product(int64_t a, int64_t b, int64_t c)
{
    const int64_t cap = INT64_MAX / 4;
    if (b <= 0 || c <= 0)
        return a;
    if (b > cap / c)
        return cap;
    const int64_t p = b * c;
    return p > cap - a ? cap : a + p;
}

int pixel_type_bytes(exr_pixel_type_t t) { return t == EXR_PIXEL_HALF ? 2 : 4; }

class ExrInspector {
public:
    ExrInspector(const std::string& path, int64_t budget, ReadCost& cost, std::string& err)
        : m_path(path), m_budget(budget), m_cost(cost), m_err(err)
    {}
    ~ExrInspector()
    {
        if (m_ctxt)
            exr_finish(&m_ctxt);
    }

    bool run()
    {
        exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
        init.error_handler_fn          = keep_core_message;
        init.user_data                 = &m_messages;
        // Partial files are damage here: no search through the file for missing chunks.
        init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
        // A damaged attribute is reported and skipped by the parser, but OpenEXR's C++
        // library (which OIIO reads with) would allocate its declared size: refused too.
        if (exr_start_read(&m_ctxt, m_path.c_str(), &init) != EXR_ERR_SUCCESS
            || !m_messages.first.empty())
            return core_failed("damaged OpenEXR header");
        int parts = 0;
        if (exr_get_count(m_ctxt, &parts) != EXR_ERR_SUCCESS || parts < 1)
            return core_failed("an OpenEXR file with no part");
        // Every part's chunk offset table is read when OIIO opens the file.
        for (int p = 0; p < parts; ++p) {
            int32_t chunks = 0;
            if (exr_get_chunk_count(m_ctxt, p, &chunks) != EXR_ERR_SUCCESS || chunks < 0)
                return core_failed(format("damaged OpenEXR header (part {})", p));
            m_cost.bytes = add_product(m_cost.bytes, chunks, 8);
        }
        if (!part0())
            return false;
        return parts == 1 || m_deep || other_parts(parts);
    }

private:
    bool core_failed(const std::string& what)
    {
        m_err = format("{}: {}{}{}", m_path, what, m_messages.first.empty() ? "" : ": ",
                       m_messages.first);
        return false;
    }

    // Part 0's data window and channel count as OpenEXR's C++ library reads them, against
    // the C library's (`dw`, `nch`). Only the header is parsed (after the C library has
    // checked every attribute's size, so no declared size is allocated blindly).
    bool same_header_in_cpp(const exr_attr_box2i_t& dw, int64_t nch)
    {
        Imath::Box2i cpp_dw;
        int64_t cpp_nch = 0;
        try {
            Imf::StdIFStream in(m_path.c_str());
            char magic_version[8];
            in.read(magic_version, 8);
            int version = 0;
            std::memcpy(&version, magic_version + 4, 4);  // little-endian, as the file
            Imf::Header header;
            header.readFrom(in, version);
            cpp_dw = header.dataWindow();
            for (auto c = header.channels().begin(); c != header.channels().end(); ++c)
                ++cpp_nch;
        } catch (const std::exception& e) {
            return core_failed(format("damaged OpenEXR header: {}", OIIO::Strutil::strip(e.what())));
        }
        if (cpp_dw.min.x != dw.min.x || cpp_dw.min.y != dw.min.y || cpp_dw.max.x != dw.max.x
            || cpp_dw.max.y != dw.max.y || cpp_nch != nch)
            return core_failed(format("damaged OpenEXR header: OpenEXR's two parsers read it "
                                      "differently (data window {},{} to {},{} and {} channels; "
                                      "{},{} to {},{} and {} channels)",
                                      dw.min.x, dw.min.y, dw.max.x, dw.max.y, nch, cpp_dw.min.x,
                                      cpp_dw.min.y, cpp_dw.max.x, cpp_dw.max.y, cpp_nch));
        return true;
    }

    bool part0()
    {
        exr_storage_t storage = EXR_STORAGE_LAST_TYPE;
        exr_attr_box2i_t dw;
        const exr_attr_chlist_t* chans = nullptr;
        if (exr_get_storage(m_ctxt, 0, &storage) != EXR_ERR_SUCCESS
            || exr_get_data_window(m_ctxt, 0, &dw) != EXR_ERR_SUCCESS
            || exr_get_channels(m_ctxt, 0, &chans) != EXR_ERR_SUCCESS || !chans)
            return core_failed("damaged OpenEXR header");
        const int64_t width  = int64_t(dw.max.x) - dw.min.x + 1;
        const int64_t height = int64_t(dw.max.y) - dw.min.y + 1;
        const int64_t nch    = chans->num_channels;
        if (width <= 0 || height <= 0) {
            m_err = format("{}: damaged OpenEXR header: data window {},{} to {},{} is empty",
                           m_path, dw.min.x, dw.min.y, dw.max.x, dw.max.y);
            return false;
        }
        if (!same_header_in_cpp(dw, nch))
            return false;
        m_pixels            = add_product(0, width, height);  // saturating: sides up to 2^32
        const bool deep     = storage == EXR_STORAGE_DEEP_SCANLINE || storage == EXR_STORAGE_DEEP_TILED;
        m_deep              = deep;
        int64_t sample_size = 0;
        for (int c = 0; c < nch; ++c)
            sample_size += pixel_type_bytes(chans->entries[c].pixel_type);
        m_cost.what = format("{} x {}, {} channel{}", width, height, nch, nch == 1 ? "" : "s");
        if (!deep) {
            m_cost.bytes = add_product(m_cost.bytes, m_pixels, nch * 4);
            // One row of chunks in the file's own types, three times over: OpenEXR's
            // compressed and uncompressed line buffers and OIIO's buffer before its
            // conversion to float. Under 2 MB for a 1080p RGBA+Z float file, but a 269-byte
            // file declaring 10027009 x 1 half RGBA pixels (found by the read fuzzer) took
            // 227 MB to read against 160 MB of float pixels (/usr/bin/time, bokehtool FILE).
            // A chunk's full size, even past a smaller data window: OpenEXR sizes its
            // buffers by the chunk (a 254-byte ZIP file of 10027009 x 1 half RGBA pixels,
            // found by the read fuzzer, had it allocate 24 buffers of 1.3 GB, 16 lines each;
            // untouched in a normal build, they filled ASan's shadow memory). For tiles, the
            // tile the header declares, not the level's tiles clamped to the data window: a
            // 734-byte file of 16 x 12 half RGBA pixels in tiles of 8 x 4784136, also the
            // fuzzer's, took 730 MB and 6.4 s to be found truncated (/usr/bin/time bokehtool).
            int64_t rows = 0, row_width = width;
            int32_t scanlines = 0;
            uint32_t tile_x = 0, tile_y = 0;
            exr_tile_level_mode_t level_mode;
            exr_tile_round_mode_t round_mode;
            if (storage == EXR_STORAGE_TILED) {
                if (exr_get_tile_descriptor(m_ctxt, 0, &tile_x, &tile_y, &level_mode, &round_mode) == EXR_ERR_SUCCESS
                    && tile_x > 0) {
                    rows      = tile_y;
                    row_width = add_product(0, (width + int64_t(tile_x) - 1) / int64_t(tile_x), int64_t(tile_x));
                    // Tiles past the image are what costs then: the message says so.
                    if (int64_t(tile_x) > width || int64_t(tile_y) > height)
                        m_cost.what += format(", tiles of {} x {}", tile_x, tile_y);
                }
            } else if (exr_get_scanlines_per_chunk(m_ctxt, 0, &scanlines) == EXR_ERR_SUCCESS) {
                rows = scanlines;
            }
            const int64_t lines     = std::max<int64_t>(rows, 1);
            const int64_t chunk_row = add_product(0, add_product(0, lines, row_width), sample_size);
            m_cost.bytes = add_product(m_cost.bytes, chunk_row, 3);
            return true;
        }
        m_cost.bytes = add_product(m_cost.bytes, m_pixels, 16 + 8 * nch);
        m_cost.what += ", deep";
        if (m_cost.bytes > m_budget) {  // too large before a sample is counted
            m_cost.at_least = true;
            return true;
        }
        int64_t samples = 0;
        bool complete   = false;
        if (!count_samples(storage, dw, sample_size, samples, complete))
            return false;
        m_cost.bytes        = add_product(m_cost.bytes, samples, sample_size);
        m_cost.at_least     = !complete;
        m_cost.deep_samples = samples;
        m_cost.what += complete ? format(", {} samples", samples)
                                : format(", more than {} samples", samples);
        return true;
    }

    // A flat multipart file is read part by part, then merged (io.cpp): every part's
    // float pixels, plus the merged image over the union of the data windows.
    bool other_parts(int parts)
    {
        exr_attr_box2i_t all;
        if (exr_get_data_window(m_ctxt, 0, &all) != EXR_ERR_SUCCESS)
            return core_failed("damaged OpenEXR header");
        int64_t channels = 0;
        for (int p = 0; p < parts; ++p) {
            exr_attr_box2i_t dw;
            const exr_attr_chlist_t* chans = nullptr;
            if (exr_get_data_window(m_ctxt, p, &dw) != EXR_ERR_SUCCESS
                || exr_get_channels(m_ctxt, p, &chans) != EXR_ERR_SUCCESS || !chans)
                return core_failed(format("damaged OpenEXR header (part {})", p));
            const int64_t width  = int64_t(dw.max.x) - dw.min.x + 1;
            const int64_t height = int64_t(dw.max.y) - dw.min.y + 1;
            if (width <= 0 || height <= 0) {
                m_err = format("{}: damaged OpenEXR header: part {}'s data window {},{} to "
                               "{},{} is empty",
                               m_path, p, dw.min.x, dw.min.y, dw.max.x, dw.max.y);
                return false;
            }
            if (p > 0)
                m_cost.bytes = add_product(m_cost.bytes, add_product(0, width, height),
                                           int64_t(chans->num_channels) * 4);
            channels += chans->num_channels;
            all.min.x = std::min(all.min.x, dw.min.x), all.min.y = std::min(all.min.y, dw.min.y);
            all.max.x = std::max(all.max.x, dw.max.x), all.max.y = std::max(all.max.y, dw.max.y);
        }
        const int64_t pixels = add_product(0, int64_t(all.max.x) - all.min.x + 1,
                                           int64_t(all.max.y) - all.min.y + 1);
        m_cost.bytes = add_product(m_cost.bytes, pixels, channels * 4);
        m_cost.what  = format("{} x {}, {} channels in {} parts", int64_t(all.max.x) - all.min.x + 1,
                              int64_t(all.max.y) - all.min.y + 1, channels, parts);
        return true;
    }

    // Sum the sample-count tables of part 0's chunks (level 0 for tiles), stopping when
    // the image passes the budget.
    bool count_samples(exr_storage_t storage, const exr_attr_box2i_t& dw, int64_t sample_size,
                       int64_t& samples, bool& complete)
    {
        exr_decode_pipeline_t decoder = EXR_DECODE_PIPELINE_INITIALIZER;
        bool initialised              = false;
        auto done = [&](bool ok) {
            if (initialised)
                exr_decoding_destroy(m_ctxt, &decoder);
            return ok;
        };
        const bool tiled = storage == EXR_STORAGE_DEEP_TILED;
        auto chunk = [&](const exr_chunk_info_t& cinfo) {
            if (cinfo.width < 1 || cinfo.height < 1)
                return false;
            exr_result_t r = initialised ? exr_decoding_update(m_ctxt, 0, &cinfo, &decoder)
                                         : exr_decoding_initialize(m_ctxt, 0, &cinfo, &decoder);
            if (r != EXR_ERR_SUCCESS)
                return false;
            if (!initialised) {
                initialised = true;
                // Cumulative counts, as stored (OpenEXRCore 3.1.5's individual-count
                // decoding fails with EXR_ERR_INVALID_SAMPLE_DATA on valid uncompressed
                // deep scanline files).
                decoder.decode_flags |= EXR_DECODE_SAMPLE_DATA_ONLY;
                if (exr_decoding_choose_default_routines(m_ctxt, 0, &decoder) != EXR_ERR_SUCCESS)
                    return false;
            }
            if (exr_decoding_run(m_ctxt, 0, &decoder) != EXR_ERR_SUCCESS || !decoder.sample_count_table)
                return false;
            // A tiled chunk's table is cumulative along each row of the tile (measured on
            // oiiotool-deep_src_deepalpha.exr: the row ends sum to the 28846 samples OIIO
            // reads, the chunk ends to 269); a scanline chunk's is cumulative over the
            // chunk. Deep scanline chunks hold one line except with ZIP (16); there the
            // larger of the two readings is taken, an overestimate if anything.
            const int32_t* table = decoder.sample_count_table;
            int64_t row_ends = 0, previous = 0;
            for (int64_t y = 0; y < cinfo.height; ++y) {
                const int32_t* row = table + y * int64_t(cinfo.width);
                for (int64_t x = 0; x < cinfo.width; ++x)
                    if (row[x] < (x ? row[x - 1] : 0))
                        return false;  // a cumulative table never decreases along a row
                row_ends += row[cinfo.width - 1];
                previous = row[cinfo.width - 1];
            }
            samples += tiled || cinfo.height == 1 ? row_ends : std::max(row_ends, previous);
            return true;
        };
        const int64_t base = m_cost.bytes;
        auto over_budget   = [&] { return add_product(base, samples, sample_size) > m_budget; };
        if (storage == EXR_STORAGE_DEEP_SCANLINE) {
            int32_t lines = 0;
            if (exr_get_scanlines_per_chunk(m_ctxt, 0, &lines) != EXR_ERR_SUCCESS || lines < 1)
                return done(core_failed("damaged OpenEXR header"));
            for (int64_t y = dw.min.y; y <= dw.max.y; y += lines) {
                exr_chunk_info_t cinfo;
                if (exr_read_scanline_chunk_info(m_ctxt, 0, int(y), &cinfo) != EXR_ERR_SUCCESS
                    || !chunk(cinfo))
                    return done(core_failed(format("damaged deep sample counts at line {}", y)));
                if (over_budget())
                    return done(true);
            }
        } else {
            int32_t tw = 0, th = 0;
            if (exr_get_tile_sizes(m_ctxt, 0, 0, 0, &tw, &th) != EXR_ERR_SUCCESS || tw < 1 || th < 1)
                return done(core_failed("damaged OpenEXR tile description"));
            const int64_t nx = (int64_t(dw.max.x) - dw.min.x + tw) / tw;
            const int64_t ny = (int64_t(dw.max.y) - dw.min.y + th) / th;
            for (int64_t ty = 0; ty < ny; ++ty)
                for (int64_t tx = 0; tx < nx; ++tx) {
                    exr_chunk_info_t cinfo;
                    if (exr_read_tile_chunk_info(m_ctxt, 0, int(tx), int(ty), 0, 0, &cinfo)
                            != EXR_ERR_SUCCESS
                        || !chunk(cinfo))
                        return done(core_failed(
                            format("damaged deep sample counts in tile {},{}", tx, ty)));
                    if (over_budget())
                        return done(true);
                }
        }
        complete = true;
        return done(true);
    }

    const std::string& m_path;
    int64_t m_budget;
    ReadCost& m_cost;
    std::string& m_err;
    CoreMessages m_messages;
    exr_context_t m_ctxt = nullptr;
    int64_t m_pixels     = 0;
    bool m_deep          = false;
};

}  // namespace

bool read_cost(const std::string& path, int64_t budget_bytes, ReadCost& cost, std::string& err)
{
    cost = ReadCost();
    if (is_exr_file(path))
        return ExrInspector(path, budget_bytes, cost, err).run();
    auto in = OIIO::ImageInput::open(path);
    if (!in) {
        std::string why = OIIO::Strutil::strip(OIIO::geterror());
        why             = why.substr(0, why.find('\n'));
        err             = format("{}: cannot read: {}", path, why);
        return false;
    }
    const OIIO::ImageSpec& spec = in->spec();
    const int64_t pixels        = int64_t(spec.width) * spec.height * std::max(spec.depth, 1);
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
        err = format("{}: damaged header: {} x {}, {} channels", path, spec.width, spec.height,
                     spec.nchannels);
        return false;
    }
    cost.bytes = add_product(0, pixels, int64_t(spec.nchannels) * 4);
    cost.what  = format("{} x {}, {} channel{}", spec.width, spec.height, spec.nchannels,
                        spec.nchannels == 1 ? "" : "s");
    return true;
}

}  // namespace bokeh
