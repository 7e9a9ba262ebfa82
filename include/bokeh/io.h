// io.h — reading and writing images (flat and deep) the way a farm step needs.
//
// Reads check what OIIO would otherwise report late or vaguely (missing file, a
// directory, unreadable or truncated data) and return one clear message. Writes go to a
// temporary file beside the target and are renamed into place, so an interrupted or
// failed write never leaves a half file at the output path, and keep the pixel types,
// channel names, windows and metadata of the image written.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// Read all channels of subimage 0 of `path` into `dst`: flat images as float (the file's
/// own types are kept in `dst.nativespec()` for writing back), deep images as stored.
/// The whole file is decoded now, so truncation is found here. False + `err` on failure.
bool read_image(OIIO::ImageBuf& dst, const std::string& path, std::string& err);

struct WriteOptions {
    /// Pixel type per channel for the file; empty = the types `img` was read with
    /// (its nativespec), so half stays half.
    std::vector<OIIO::TypeDesc> channel_formats;
    bool no_clobber = false;  ///< fail rather than replace an existing file
};

/// Write `img` to `path` through a temporary file in the same directory, renamed into
/// place on success; on failure nothing is left at `path` (an existing file there is
/// untouched). False + `err` on failure.
bool write_image(const OIIO::ImageBuf& img, const std::string& path,
                 const WriteOptions& opts, std::string& err);

/// Pixel types by channel name, as a file stored them (from a native spec).
using ChannelTypes = std::map<std::string, OIIO::TypeDesc>;
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
