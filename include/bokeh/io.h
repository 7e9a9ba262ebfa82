// io.h — reading and writing images (flat and deep) the way a farm step needs.
//
// Reads check what OIIO would otherwise report late or vaguely (missing file, a
// directory, a declared size over the memory budget, unreadable or truncated data) and
// return one clear message. Writes go to a temporary file beside the target and are
// renamed into place, so an interrupted or failed write never leaves a half file at the
// output path, and keep the pixel types, channel names, windows and metadata of the
// image written.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// The memory a read may take by default: half the machine's physical memory.
int64_t default_memory_budget_bytes();

/// "12.0 GiB", "640.0 KiB", "512 bytes".
std::string memory_size_text(int64_t bytes);

struct ReadOptions {
    /// Largest memory (bytes) reading one file may allocate, checked against what the
    /// file's header declares before anything is allocated; 0 = default_memory_budget_bytes().
    int64_t memory_budget_bytes = 0;
    /// How an error names the budget (a host names its own option here).
    std::string budget_name = "the memory budget";
    /// A multi-view EXR: the view to read (its channels named without the view, the other
    /// views left out); an error names the file's views when it has no such view. Empty:
    /// the file's first view is the image, the others' channels prefixed by their view. A
    /// file without views is read whole either way.
    std::string view;
};

/// What reading `path` with read_image will allocate, from its header (and, for deep EXR,
/// its sample-count tables, counted only until the total passes `budget_bytes`).
struct ReadCost {
    int64_t bytes = 0;
    bool at_least = false;  ///< deep samples counted only until past the budget
    int64_t deep_samples = 0;  ///< counted so far (all of them unless `at_least`)
    std::string what;  ///< "1920 x 1080, 4 channels" (+ ", deep, N samples")
};
bool read_cost(const std::string& path, int64_t budget_bytes, ReadCost& cost, std::string& err);

/// Pixel types by channel name, as a file stored them (from a native spec).
using ChannelTypes = std::map<std::string, OIIO::TypeDesc>;

/// What a read learned besides the pixels.
struct ReadInfo {
    /// Each channel's type in the file, by its name in the image read.
    ChannelTypes file_types;
    /// The parts merged into the image, in file order ("" for an unnamed part); one
    /// entry for a single-part file.
    std::vector<std::string> part_names;
};

/// Read `path` into `dst`: flat images as float, deep images as stored. The declared size
/// is checked against the memory budget first, then the whole file is decoded now, so
/// truncation is found here. Exceptions from the readers (bad_alloc included) become
/// errors. False + `err` on failure.
///
/// A flat multipart file (OpenEXR 2, as Nuke writes layers) is read whole, every part
/// merged into one image (merged_channel_name gives the names); its data window is the
/// union of the parts' data windows, and a part's channels are 0 outside its own data
/// window (a depth of 0 is "no depth" for the lens); the display window and metadata are
/// part 0's. A stereo file's depth (part 0's view holds no Z, a later part of that view
/// holds one) becomes the image's "Z". A deep file: part 0 only. A flat file with a deep
/// part is refused.
/// The file's own types are kept in `dst.nativespec()` for a single part and in
/// `info->file_types` always.
bool read_image(OIIO::ImageBuf& dst, const std::string& path, const ReadOptions& opts,
                ReadInfo* info, std::string& err);
bool read_image(OIIO::ImageBuf& dst, const std::string& path, const ReadOptions& opts,
                std::string& err);
bool read_image(OIIO::ImageBuf& dst, const std::string& path, std::string& err);

/// The name channel `channel` of part `part` (0-based) takes in a merged multipart image:
/// part 0's channels keep their names; in a later part, a channel of another view than
/// part 0's (the part's "view" attribute) is prefixed by its view ("left.R", the single-part
/// multi-view convention), else a channel without a layer prefix is prefixed by the part's
/// name ("Z" of part "depth" -> "depth.Z"), else it keeps its name ("depth.Z" stays).
/// `part_name` empty: "part<N>".
std::string merged_channel_name(const std::string& channel, int part, const std::string& part_name,
                                const std::string& view, const std::string& first_view);

/// The layer of a channel name: what comes before its last '.' ("" for "R").
std::string channel_layer(const std::string& channel);

/// How write_image lays the channels out in the file.
enum class PartLayout {
    Single,  ///< one part (every format)
    /// A part per layer, as Nuke writes multipart EXR: the channels without a layer
    /// (R, G, B, A, Z, ...) in the first part, named "rgba"; then a part per layer,
    /// named by the layer, holding its channels under their full names ("depth.Z"), in
    /// the order of the layers' first channels. Same windows and metadata in every part.
    Layers,
};

struct WriteOptions {
    /// Pixel type per channel for the file; empty = the types `img` was read with
    /// (its nativespec), so half stays half.
    std::vector<OIIO::TypeDesc> channel_formats;
    bool no_clobber = false;  ///< fail rather than replace an existing file
    PartLayout parts = PartLayout::Single;
    /// The file's compression, as OIIO names it ("zip", "piz", "dwaa:45", "none"; OpenEXR's
    /// names are checked); empty = the image's own, else the format's default.
    std::string compression;
    /// Tile size in pixels; 0 = as the image was read (scanlines unless it was tiled).
    int tile_width = 0, tile_height = 0;
    /// Attributes to set on the file besides the image's own (bokehtool records the
    /// command line that made it as "bokeh:command").
    OIIO::ParamValueList metadata;
};

/// The metadata a written file carries: the image's own, less what described the file it
/// was read from (its chunk and part counts), with "Software" (OpenBokeh and its
/// version), "DateTime" (the time of writing, UTC; SOURCE_DATE_EPOCH fixes it) and
/// `opts.metadata`. write_image applies it.
void describe_output(OIIO::ImageSpec& spec, const WriteOptions& opts);

/// Write `img` to `path` through a temporary file in the same directory, renamed into
/// place on success; on failure nothing is left at `path` (an existing file there is
/// untouched). False + `err` on failure.
bool write_image(const OIIO::ImageBuf& img, const std::string& path,
                 const WriteOptions& opts, std::string& err);

/// The temporary file write_image uses for `path` in this process:
/// ".<file>.openbokeh-partial.<host>.<pid><ext>" beside it. A write removes such files
/// for its target left by processes of this host that no longer run; any other one may
/// be deleted once its process has ended.
std::string partial_write_name(const std::string& path);

/// Remove the temporary files of the writes now in progress (those writes then fail).
/// Async-signal-safe: for a host's SIGINT/SIGTERM handler or a watchdog.
void remove_partial_writes() noexcept;

/// Pixel types by channel name, as a file stored them (from a native spec).
ChannelTypes channel_types_of(const OIIO::ImageSpec& native);

/// The per-channel types to write `spec` with: each channel's type from `types` by name;
/// a channel `types` does not know (made by a command) takes the type of the first
/// known channel, or float when none is known.
std::vector<OIIO::TypeDesc> formats_for(const OIIO::ImageSpec& spec, const ChannelTypes& types);

/// Sample statistics of a deep image.
struct DeepStats {
    int64_t pixels        = 0;
    int64_t empty_pixels  = 0;  ///< pixels with no sample
    int64_t total_samples = 0;
    int min_samples       = 0;
    int max_samples       = 0;
    double mean_samples() const { return pixels ? double(total_samples) / double(pixels) : 0.0; }
};
DeepStats deep_stats(const OIIO::DeepData& deep);

/// A description of an image in the style of `oiiotool --info`: one line (size, channel
/// count, types, deep or flat), with `verbose` the channel list, windows, metadata and,
/// for deep images, the sample statistics.
std::string describe_image(const OIIO::ImageBuf& img, const std::string& name, bool verbose);

}  // namespace bokeh
