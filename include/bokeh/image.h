// image.h — working-image helpers shared by every operation.
//
// Channel lookup by name (R, G, B, A, Z), premultiplication state, contiguous float
// RGBA + Z working images, and the policy for non-finite pixel values.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// Indices of the channels the algorithms care about; -1 where absent.
struct ChannelMap {
    int r = -1, g = -1, b = -1, a = -1, z = -1;
    bool has_rgb() const { return r >= 0 && g >= 0 && b >= 0; }
};

/// Find R, G, B, A, Z by name, as OpenEXR names them. A single-layer prefix
/// ("beauty.R") is accepted when there is no unprefixed channel; the spec's alpha_channel
/// and z_channel are used first when set.
ChannelMap find_channels(const OIIO::ImageSpec& spec);

/// A depth channel by its name: Z, ZBack, or a layer's (*.Z, *.ZBack). Non-finite depths
/// become "no depth" (+inf) where colour becomes 0; resampling takes the nearest depth.
bool is_depth_channel(const std::string& name);

/// "the image has no depth channel (Z)", naming the channels that look like a depth (last
/// component Z, depth or zdepth, any case: "left.Z", "right.depth.Z") when it has some,
/// and how to pick one.
std::string no_depth_message(const OIIO::ImageSpec& spec);

/// The index of the channel named `name` in `spec`; -1 + `err` when there is none, naming
/// what there is: the channels of `name`'s layer when the image has that layer (a part of
/// a multipart file merged by read_image is a layer: "depth.Z" is part "depth"'s "Z"),
/// else all channels.
int channel_index_named(const OIIO::ImageSpec& spec, const std::string& name, std::string& err);

/// True when the colour channels are stored multiplied by alpha, the OpenEXR convention
/// and what OIIO gives on read unless "oiio:UnassociatedAlpha" says otherwise.
bool is_premultiplied(const OIIO::ImageSpec& spec);

/// A contiguous float image in the layout the algorithms use: premultiplied RGBA
/// interleaved (4 floats a pixel) plus an optional depth plane, covering `roi`.
struct WorkImage {
    OIIO::ROI roi;                ///< the pixels held (x, y only)
    std::vector<float> rgba;      ///< roi.width() * roi.height() * 4
    std::vector<float> z;         ///< empty, or one value a pixel
    bool has_alpha = false;       ///< false: alpha was absent and set to 1

    int width() const { return roi.width(); }
    int height() const { return roi.height(); }
    size_t index(int x, int y) const
    {
        return size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin);
    }
    float* rgba_at(int x, int y) { return &rgba[index(x, y) * 4]; }
    const float* rgba_at(int x, int y) const { return &rgba[index(x, y) * 4]; }
};

/// Fill `dst` from the data window of `src` (flat images only), or from the part of it
/// `region` names (x and y; default: all of it). Missing G/B copy R (a grey image),
/// missing alpha is 1, colour is premultiplied if `src` is not. Returns false, with `err`
/// set, when `src` is deep or has no colour channel, or `region` is not within the data
/// window (`dst` is no ImageBuf to hold an error).
bool to_work_image(WorkImage& dst, const OIIO::ImageBuf& src, std::string& err, int nthreads = 0,
                   OIIO::ROI region = {});

/// Write a WorkImage back into `dst`'s R, G, B, A (and Z when both have one), converting
/// to unpremultiplied colour if `dst`'s spec says it stores that. `dst` must already
/// cover `src.roi`; other channels are left as they are. False + `dst.geterror()`.
bool from_work_image(OIIO::ImageBuf& dst, const WorkImage& src, int nthreads = 0);

/// The spec of an image derived from one with spec `like`: its metadata and display
/// window, float channels `names` (alpha where one is named "A", no depth channel, stored
/// premultiplied), over `data` (default: like's data window).
OIIO::ImageSpec derived_spec(const OIIO::ImageSpec& like, const std::vector<std::string>& names,
                             OIIO::ROI data = {});

/// The number held in metadata attribute `name` of `spec`, whatever type it was stored
/// with: any integer, half, float or double scalar, or a string holding a number
/// (`--attrib bokeh:focal_mm 85` stores an int, OpenEXR headers a float, other tools a
/// string). Returns true with `value` unchanged when the attribute is absent; false with
/// `err` naming it when it is there but holds no single finite number.
bool metadata_number(const OIIO::ImageSpec& spec, const std::string& name, double& value,
                     std::string& err);

/// What to do with NaN and Inf pixel values (docs/io.md, "Errors and bad values").
enum class NonFinitePolicy {
    Zero,   ///< colour -> 0, depth -> +inf ("no depth": infinitely far); counted
    Error,  ///< fail, naming the count
};

/// Count of values replaced (or found, under NonFinitePolicy::Error).
struct NonFiniteCount {
    int64_t colour = 0;  ///< non-finite values in any channel but depth
    int64_t depth  = 0;  ///< NaN or -inf depth values (+inf already means "far")
    int64_t total() const { return colour + depth; }
};

/// Whether a flat image holds a NaN or an infinity in any channel over its data window (one
/// pass; float images are read in place, others converted).
bool any_nonfinite(const OIIO::ImageBuf& img, int nthreads = 0);

/// Apply `policy` to every channel of a flat float image in place (deep images: every
/// sample). Returns false when the policy is Error and a non-finite value was found,
/// with the counts in `count` either way. Depth channels are those named Z or ZBack.
bool scrub_nonfinite(OIIO::ImageBuf& img, NonFinitePolicy policy, NonFiniteCount& count,
                     int nthreads = 0);

}  // namespace bokeh
