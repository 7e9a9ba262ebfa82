// io.cpp — reading flat and deep images through OpenImageIO, and describing them.
//
// Reads first check what the file declares against a memory budget (io_budget.cpp), then
// force the whole file into memory so that a truncated or corrupt file fails at read
// time with the file's name, not later in a filter; exceptions from the readers become
// errors. A flat multipart EXR (a layer per part, as Nuke writes) is read part by part and
// merged into one image, names and windows by the rules in io.h; a multi-view file's views
// by io_views.cpp. Writing is core/io/io_write.cpp.

#include <bokeh/io.h>

#include "io/io_text.h"
#include "io/io_views.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using detail::channel_view;
using detail::multiview_list;
using detail::name_first_view_depth;
using detail::select_single_part_view;

using OIIO::Strutil::fmt::format;

using detail::first_line;

std::string channel_layer(const std::string& channel)
{
    const size_t dot = channel.rfind('.');
    return dot == std::string::npos ? std::string() : channel.substr(0, dot);
}

std::string merged_channel_name(const std::string& channel, int part, const std::string& part_name,
                                const std::string& view, const std::string& first_view)
{
    if (part == 0)
        return channel;
    if (!view.empty() && view != first_view)
        return view + "." + channel;
    if (channel.find('.') != std::string::npos)
        return channel;
    return (part_name.empty() ? format("part{}", part) : part_name) + "." + channel;
}

// The name OIIO gives a part ("" when the file names none).
static std::string part_name_of(const OIIO::ImageSpec& spec)
{
    return spec.get_string_attribute("oiio:subimagename");
}

// Every part of a flat multipart file merged into one float image (io.h, read_image).
// Each part is decoded on its own and pasted into the union of the data windows, which
// starts zeroed: OpenEXR leaves pixels outside a data window undefined, Nuke and OIIO's
// tools take them as 0.
// With `view` given, only the parts of that view and those of none are merged, the first
// of them in part 0's place (io_views.cpp).
static bool read_merged_parts(OIIO::ImageBuf& dst, const std::string& path, int file_parts,
                              const std::string& view, ReadInfo* info, std::string& err)
{
    std::vector<int> keep;  // file part of each merged part
    std::vector<std::string> views;
    for (int p = 0; p < file_parts; ++p) {
        OIIO::ImageBuf probe;
        if (!probe.init_spec(path, p, 0)) {
            err = format("{}: cannot read part {}: {}", path, p, first_line(probe.geterror()));
            return false;
        }
        const std::string v = probe.spec().get_string_attribute("view");
        if (!v.empty() && std::find(views.begin(), views.end(), v) == views.end())
            views.push_back(v);
        if (view.empty() || v.empty() || v == view)
            keep.push_back(p);
    }
    if (!view.empty() && !views.empty() && std::find(views.begin(), views.end(), view) == views.end()) {
        err = format("{}: no view '{}' (its parts' views: {})", path, view, OIIO::Strutil::join(views, ", "));
        return false;
    }
    if (views.empty())  // not a multi-view file: every part, whatever view was asked for
        for (int p = int(keep.size()); p < file_parts; ++p)
            keep.push_back(p);
    std::sort(keep.begin(), keep.end());
    keep.erase(std::unique(keep.begin(), keep.end()), keep.end());
    // The view asked for: its first part takes part 0's place (its channels keep their names).
    for (size_t i = 0; i < keep.size() && !view.empty() && !views.empty(); ++i) {
        OIIO::ImageBuf probe;
        if (probe.init_spec(path, keep[i], 0) && probe.spec().get_string_attribute("view") == view) {
            std::rotate(keep.begin(), keep.begin() + std::ptrdiff_t(i), keep.begin() + std::ptrdiff_t(i) + 1);
            break;
        }
    }
    const int nparts = int(keep.size());
    std::vector<OIIO::ImageBuf> parts(static_cast<size_t>(nparts));
    for (int i = 0; i < nparts; ++i) {
        const int p          = keep[size_t(i)];
        OIIO::ImageBuf& part = parts[size_t(i)];
        part.reset(path, p, 0);
        if (!part.init_spec(path, p, 0)) {
            err = format("{}: cannot read part {}: {}", path, p, first_line(part.geterror()));
            return false;
        }
        if (part.spec().deep) {
            err = format("{}: part {} ('{}') is deep and part 0 is flat; a file mixing deep "
                         "and flat parts is not read",
                         path, p, part_name_of(part.spec()));
            return false;
        }
        if (!part.read(p, 0, true, OIIO::TypeFloat) || part.has_error()) {
            err = format("{}: cannot read part {} ('{}') (corrupt or truncated?): {}", path, p,
                         part_name_of(part.spec()), first_line(part.geterror()));
            return false;
        }
    }
    const OIIO::ImageSpec& first = parts[0].spec();
    const std::string first_view = first.get_string_attribute("view");
    OIIO::ImageSpec spec         = first;
    spec.channelnames.clear();
    spec.channelformats.clear();
    spec.set_format(OIIO::TypeFloat);
    spec.alpha_channel = spec.z_channel = -1;
    ChannelTypes types;
    OIIO::ROI window = parts[0].roi();
    int first_view_depths = 0, first_view_depth = -1;  // unprefixed Z of parts of part 0's view
    for (int p = 0; p < nparts; ++p) {
        const OIIO::ImageSpec& ps = parts[size_t(p)].spec();
        const std::string pname   = part_name_of(ps);
        const std::string pview   = ps.get_string_attribute("view");
        window                    = OIIO::roi_union(window, parts[size_t(p)].roi());
        for (int c = 0; c < ps.nchannels; ++c) {
            const std::string own = ps.channel_name(c);
            if (own == "Z" && (pview.empty() || pview == first_view)) {
                ++first_view_depths;
                first_view_depth = int(spec.channelnames.size());
            }
            std::string name = merged_channel_name(own, p, pname, ps.get_string_attribute("view"),
                                                   first_view);
            // Taken by an earlier part (two views of "depth.Z"): the part's name in front.
            if (types.count(name) && p > 0)
                name = (pname.empty() ? format("part{}", p) : pname) + "." + own;
            if (types.count(name)) {
                err = format("{}: channel '{}' is held by two parts (part {} '{}' and an "
                             "earlier one)",
                             path, name, p, pname);
                return false;
            }
            types[name] = parts[size_t(p)].nativespec().channelformat(c);
            spec.channelnames.push_back(name);
        }
    }
    spec.nchannels = int(spec.channelnames.size());
    spec.x = window.xbegin, spec.y = window.ybegin;
    spec.width = window.width(), spec.height = window.height();
    spec.alpha_channel = spec.channelindex("A");
    spec.z_channel     = spec.channelindex("Z");
    if (spec.z_channel < 0 && first_view_depths == 1 && !first_view.empty()) {
        // A stereo file's depth: part 0's view's one Z, in a part of its own.
        const std::string was = spec.channelnames[size_t(first_view_depth)];
        name_first_view_depth(spec, first_view_depth);
        types["Z"] = types[was];
        types.erase(was);
    }
    for (const char* per_part : { "oiio:subimagename", "oiio:subimages", "name", "view" })
        spec.erase_attribute(per_part);

    OIIO::ImageBuf merged(spec, OIIO::InitializePixels::Yes);
    int channel = 0;
    for (int p = 0; p < nparts; ++p) {
        const OIIO::ImageBuf& part = parts[size_t(p)];
        // set_pixels into the part's own window and channels (OIIO 2.4's IBA::paste moves a
        // source with an offset data window by that offset again).
        OIIO::ROI where = part.roi();
        where.chbegin   = channel;
        where.chend     = channel + part.nchannels();
        if (!part.localpixels() || !merged.set_pixels(where, OIIO::TypeFloat, part.localpixels())) {
            err = format("{}: cannot merge part {}: {}", path, p, first_line(merged.geterror()));
            return false;
        }
        channel += part.spec().nchannels;
        if (info)
            info->part_names.push_back(part_name_of(part.spec()));
    }
    if (info)
        info->file_types = std::move(types);
    dst = std::move(merged);
    return true;
}

// The part of read_image that can throw: OIIO and OpenEXR allocate and decode here.
static bool read_checked(OIIO::ImageBuf& dst, const std::string& path, const std::string& view, ReadInfo* info,
                         std::string& err)
{
    auto probe = OIIO::ImageInput::open(path);
    if (!probe) {
        err = format("{}: cannot read: {}", path, first_line(OIIO::geterror()));
        return false;
    }
    const bool deep = probe->spec().deep;
    int nparts      = 1;
    while (!deep && probe->seek_subimage(nparts, 0))
        ++nparts;
    probe.reset();

    // ImageBuf keeps what it learned of a file (spec, an open reader) in OIIO's shared
    // ImageCache under the file's name; a file replaced under the same name since then
    // would be read with the old size into a buffer of the new one (heap corruption inside
    // OIIO, found by the read fuzzer). Forget it first.
    OIIO::ImageCache* cache = OIIO::ImageCache::create(true);
    cache->invalidate(OIIO::ustring(path), true);
    // The pixels are read into the image itself (force), so the cache's open reader is
    // closed on the way out: at 4K OpenEXR's compressors and line buffers held 14.8 MB
    // through the defocus's peak (heaptrack), and a sequence opens a file a frame.
    struct CloseWhenRead {
        OIIO::ImageCache* cache;
        OIIO::ustring name;
        ~CloseWhenRead() { cache->close(name); }
    } close_when_read{ cache, OIIO::ustring(path) };
    if (nparts > 1)
        return read_merged_parts(dst, path, nparts, view, info, err);
    OIIO::ImageBuf buf(path);
    const bool ok = deep ? buf.read(0, 0, true) : buf.read(0, 0, true, OIIO::TypeFloat);
    if (!ok || buf.has_error()) {
        err = format("{}: cannot read (corrupt or truncated?): {}", path,
                     first_line(buf.geterror()));
        return false;
    }
    if (info) {
        info->file_types = channel_types_of(buf.nativespec());
        info->part_names = { part_name_of(buf.spec()) };
    }
    const std::vector<std::string> views = multiview_list(buf.spec());
    if (!deep && !views.empty()) {
        const std::vector<std::string> names_in_file = buf.spec().channelnames;
        if (!select_single_part_view(buf, path, view, err))
            return false;
        if (info) {  // the types by the names the channels now have
            ChannelTypes renamed;
            for (const auto& [name, type] : info->file_types) {
                std::string plain;
                const std::string of = channel_view(name, views, plain);
                if (!view.empty() && of == view)
                    renamed[plain] = type;
                else if (view.empty())
                    renamed[buf.spec().channelindex(plain) >= 0 && of == views.front() ? plain : name] = type;
            }
            info->file_types = std::move(renamed);
        }
    }
    dst = std::move(buf);
    return true;
}

bool read_image(OIIO::ImageBuf& dst, const std::string& path, const ReadOptions& opts,
                ReadInfo* info, std::string& err)
{
    if (info)
        *info = ReadInfo();
    if (path.empty()) {
        err = "empty file name";
        return false;
    }
    if (OIIO::Filesystem::is_directory(path)) {
        err = format("{}: is a directory, not an image", path);
        return false;
    }
    if (!OIIO::Filesystem::exists(path)) {
        err = format("{}: no such file", path);
        return false;
    }
    const int64_t budget = opts.memory_budget_bytes > 0 ? opts.memory_budget_bytes
                                                        : default_memory_budget_bytes();
    try {
        ReadCost cost;
        if (!read_cost(path, budget, cost, err))
            return false;
        if (cost.bytes > budget) {
            err = format("{}: reading it needs {}{} ({}), more than {} of {}", path,
                         cost.at_least ? "at least " : "", memory_size_text(cost.bytes),
                         cost.what, opts.budget_name,
                         memory_size_text(budget));
            return false;
        }
        return read_checked(dst, path, opts.view, info, err);
    } catch (const std::bad_alloc&) {
        err = format("{}: out of memory while reading", path);
    } catch (const std::exception& e) {
        err = format("{}: cannot read: {}", path, first_line(e.what()));
    } catch (...) {
        err = format("{}: cannot read: unknown exception", path);
    }
    dst.clear();
    return false;
}

bool read_image(OIIO::ImageBuf& dst, const std::string& path, const ReadOptions& opts,
                std::string& err)
{
    return read_image(dst, path, opts, nullptr, err);
}

bool read_image(OIIO::ImageBuf& dst, const std::string& path, std::string& err)
{
    return read_image(dst, path, ReadOptions(), nullptr, err);
}

ChannelTypes channel_types_of(const OIIO::ImageSpec& native)
{
    ChannelTypes types;
    for (int c = 0; c < native.nchannels; ++c)
        types[native.channel_name(c)] = native.channelformat(c);
    return types;
}

std::vector<OIIO::TypeDesc> formats_for(const OIIO::ImageSpec& spec, const ChannelTypes& types)
{
    OIIO::TypeDesc fallback = OIIO::TypeFloat;
    for (int c = 0; c < spec.nchannels; ++c) {
        auto it = types.find(spec.channel_name(c));
        if (it != types.end()) {
            fallback = it->second;
            break;
        }
    }
    std::vector<OIIO::TypeDesc> formats;
    for (int c = 0; c < spec.nchannels; ++c) {
        auto it = types.find(spec.channel_name(c));
        formats.push_back(it != types.end() ? it->second : fallback);
    }
    return formats;
}

DeepStats deep_stats(const OIIO::DeepData& deep)
{
    DeepStats st;
    st.pixels = deep.pixels();
    for (int64_t p = 0; p < st.pixels; ++p) {
        const int n = deep.samples(p);
        st.total_samples += n;
        st.empty_pixels += n == 0;
        st.min_samples = p == 0 ? n : std::min(st.min_samples, n);
        st.max_samples = std::max(st.max_samples, n);
    }
    return st;
}

// "half", or "half/float" when the channels differ, in channel order.
static std::string type_summary(const OIIO::ImageSpec& native)
{
    std::vector<std::string> names;
    for (int c = 0; c < native.nchannels; ++c) {
        const std::string t = native.channelformat(c).c_str();
        if (std::find(names.begin(), names.end(), t) == names.end())
            names.push_back(t);
    }
    return names.empty() ? std::string(native.format.c_str()) : OIIO::Strutil::join(names, "/");
}

std::string describe_image(const OIIO::ImageBuf& img, const std::string& name, bool verbose)
{
    const OIIO::ImageSpec& spec   = img.spec();
    const OIIO::ImageSpec& native = img.nativespec();
    std::string s = format("{} : {:4} x {:4}, {} channel, {}{} {}", name, spec.width,
                           spec.height, spec.nchannels, img.deep() ? "deep " : "",
                           type_summary(native), img.file_format_name());
    const DeepStats st = img.deep() ? deep_stats(*img.deepdata()) : DeepStats();
    if (img.deep())
        s += format(", {:.3f} samples/pixel", st.mean_samples());
    s += "\n";
    if (!verbose)
        return s;

    std::vector<std::string> chans;
    for (int c = 0; c < spec.nchannels; ++c) {
        std::string t = spec.channel_name(c);
        if (!native.channelformats.empty())
            t += format(" ({})", native.channelformat(c));
        chans.push_back(t);
    }
    s += format("    channel list: {}\n", OIIO::Strutil::join(chans, ", "));
    if (spec.x || spec.y || spec.z || spec.width != spec.full_width
        || spec.height != spec.full_height || spec.full_x || spec.full_y)
        s += format("    data window: {},{} to {},{}; display window: {},{} to {},{}\n",
                    spec.x, spec.y, spec.x + spec.width - 1, spec.y + spec.height - 1,
                    spec.full_x, spec.full_y, spec.full_x + spec.full_width - 1,
                    spec.full_y + spec.full_height - 1);
    if (spec.tile_width)
        s += format("    tile size: {} x {}\n", spec.tile_width, spec.tile_height);
    if (img.deep())
        s += format("    deep samples: {} total; per pixel min {}, max {}, mean {:.3f}; "
                    "{} of {} pixels empty\n",
                    st.total_samples, st.min_samples, st.max_samples, st.mean_samples(),
                    st.empty_pixels, st.pixels);
    for (const OIIO::ParamValue& p : spec.extra_attribs)
        s += format("    {}: {}\n", p.name(), spec.metadata_val(p, true));
    return s;
}

}  // namespace bokeh
