// io.cpp — reading and writing flat and deep images through OpenImageIO.
//
// Reads first check what the file declares against a memory budget (io_budget.cpp), then
// force the whole file into memory so that a truncated or corrupt file fails at read
// time with the file's name, not later in a filter; exceptions from the readers become
// errors. A flat multipart EXR (a layer per part, as Nuke writes) is read part by part and
// merged into one image, names and windows by the rules in io.h. Writes use ImageOutput on
// a temporary file in the target's directory (same filesystem, so the final rename is
// atomic) and keep the spec: channel names, data/display windows, tiling, metadata; or
// write a part per layer, a compression or a tiling asked for (WriteOptions). A
// single-part scanline EXR with zip or zips compression (OpenEXR's and OIIO's default)
// is written by OIIO uncompressed into memory and compressed by exr_deflate.cpp, about
// twice as fast as OpenEXR 3.1's zlib (the measurement is in exr_deflate.cpp).

#include <bokeh/io.h>

#include "io/exr_deflate.h"
#include "io/io_views.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <mutex>
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

// OIIO error texts can span several lines and repeat the file name; keep the first line.
static std::string first_line(std::string s)
{
    s = OIIO::Strutil::strip(s);
    const size_t nl = s.find('\n');
    return nl == std::string::npos ? s : s.substr(0, nl);
}

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

// ---------------------------------------------------------------------------------------
// Temporary files of writes in progress.
//
// A write goes to ".<file>.openbokeh-partial.<host>.<pid><ext>" beside the target: hidden
// (a sequence pattern such as shot.#.exr never matches it), the target's extension last
// so the format plugin recognises it, and a name that says what it is. The host and pid
// let a later write to the same target remove one left by a process that died (SIGKILL,
// power loss): only when it was made on this host by a process that no longer exists.
// The registry below is read by remove_partial_writes() from signal handlers, so it is
// fixed-size storage and atomics only.

namespace {

constexpr int kPartialSlots = 16;
constexpr size_t kPartialPathBytes = 4096;
struct PartialSlot {
    std::atomic<bool> used{ false };
    char path[kPartialPathBytes];
};
PartialSlot g_partial[kPartialSlots];
std::mutex g_partial_mutex;  // between writers; the signal side only reads

int register_partial(const std::string& tmp)
{
    if (tmp.size() >= kPartialPathBytes)
        return -1;
    std::lock_guard<std::mutex> lock(g_partial_mutex);
    for (int i = 0; i < kPartialSlots; ++i)
        if (!g_partial[i].used.load(std::memory_order_acquire)) {
            std::memcpy(g_partial[i].path, tmp.c_str(), tmp.size() + 1);
            g_partial[i].used.store(true, std::memory_order_release);
            return i;
        }
    return -1;
}

void unregister_partial(int slot)
{
    if (slot >= 0)
        g_partial[slot].used.store(false, std::memory_order_release);
}

std::string host_name()
{
    char buf[256] = {};
    if (gethostname(buf, sizeof buf - 1) != 0 || !buf[0])
        return "host";
    std::string h(buf);
    h = h.substr(0, h.find('.'));
    for (char& c : h)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_')
            c = '_';
    return h;
}

const char* kPartialTag = ".openbokeh-partial.";

// Remove ".<file>.openbokeh-partial.<this host>.<pid><ext>" files left by processes of
// this host that no longer run.
void remove_stale_partials(const std::string& path)
{
    const std::string dir    = OIIO::Filesystem::parent_path(path);
    const std::string prefix = "." + OIIO::Filesystem::filename(path) + kPartialTag + host_name() + ".";
    const std::string ext    = OIIO::Filesystem::extension(path);
    std::vector<std::string> entries;
    if (!OIIO::Filesystem::get_directory_entries(dir.empty() ? "." : dir, entries))
        return;
    for (const std::string& e : entries) {
        const std::string name = OIIO::Filesystem::filename(e);
        if (name.size() <= prefix.size() + ext.size() || name.compare(0, prefix.size(), prefix) != 0
            || name.compare(name.size() - ext.size(), ext.size(), ext) != 0)
            continue;
        const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - ext.size());
        if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos
            || digits.size() > 9)
            continue;
        const pid_t pid = pid_t(std::stol(digits));
        if (pid == getpid() || (kill(pid, 0) == 0 || errno != ESRCH))
            continue;
        OIIO::Filesystem::remove(e);
    }
}

}  // namespace

std::string partial_write_name(const std::string& path)
{
    const std::string dir  = OIIO::Filesystem::parent_path(path);
    const std::string file = OIIO::Filesystem::filename(path);
    const std::string ext  = OIIO::Filesystem::extension(path);
    const std::string tmp  = format(".{}{}{}.{}{}", file, kPartialTag, host_name(), long(getpid()), ext);
    return dir.empty() ? tmp : dir + "/" + tmp;
}

void remove_partial_writes() noexcept
{
    for (PartialSlot& slot : g_partial)
        if (slot.used.load(std::memory_order_acquire))
            unlink(slot.path);
}

static bool write_pixels(OIIO::ImageOutput& out, const OIIO::ImageBuf& img)
{
    if (img.deep())
        return out.write_deep_image(*img.deepdata());
    if (img.localpixels() && img.spec().format == OIIO::TypeFloat)
        return out.write_image(OIIO::TypeFloat, img.localpixels());
    std::vector<float> pixels(img.spec().image_pixels() * size_t(img.nchannels()));
    return img.get_pixels(img.roi(), OIIO::TypeFloat, pixels.data())
           && out.write_image(OIIO::TypeFloat, pixels.data());
}

// libdeflate's level for zip and zips: level 6 writes files no larger than OpenEXR 3.1's
// zlib (on the built-in lights scene, 1920x1080 float RGBA+Z: 24.78 MB against 24.83 MB)
// in about half its CPU time (docs/io.md, "Writing zip at I/O speed").
constexpr int kExrDeflateLevel = 6;

// Write `img` with `spec` (single part, scanlines, `compression` zip or zips) to `tmp`:
// OIIO writes the file uncompressed into memory, exr_deflate compresses its chunks.
// `declined` when the file is not one exr_deflate rewrites; write_image then uses OIIO's
// own writer.
static bool write_exr_deflated(const OIIO::ImageBuf& img, const OIIO::ImageSpec& spec,
                               detail::ExrDeflate compression, const std::string& tmp,
                               bool& declined, std::string& err)
{
    declined = false;
    OIIO::ImageSpec plain = spec;
    plain.attribute("compression", "none");
    std::vector<unsigned char> file;
    file.reserve(size_t(plain.image_bytes()) + size_t(plain.height) * 16 + 65536);
    OIIO::Filesystem::IOVecOutput memory(file);
    auto out = OIIO::ImageOutput::create("openexr");
    if (!out || !out->supports("ioproxy")) {
        declined = true;
        return false;
    }
    out->set_ioproxy(&memory);
    if (!(out->open(tmp, plain) && write_pixels(*out, img) && out->close())) {
        err = first_line(out->geterror());
        return false;
    }
    std::vector<unsigned char> packed;
    std::string why;
    if (detail::deflate_exr_file(file, compression, kExrDeflateLevel, packed, why)
        != detail::DeflateResult::Written) {
        declined = true;
        return false;
    }
    file = std::vector<unsigned char>();
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) {
        err = std::strerror(errno);
        return false;
    }
    const bool wrote = std::fwrite(packed.data(), 1, packed.size(), f) == packed.size();
    const int saved  = errno;
    if (std::fclose(f) != 0 || !wrote) {
        err = std::strerror(wrote ? errno : saved);
        return false;
    }
    return true;
}

// OpenEXR's compression names (OIIO's spelling), each optionally ":quality".
static bool exr_compression_known(const std::string& value)
{
    static const char* names[] = { "none", "rle", "zip", "zips", "piz", "pxr24",
                                   "b44", "b44a", "dwaa", "dwab" };
    const std::string name = value.substr(0, value.find(':'));
    if (std::none_of(std::begin(names), std::end(names), [&](const char* n) { return name == n; }))
        return false;
    if (name.size() == value.size())
        return true;
    OIIO::string_view q(value);
    q.remove_prefix(name.size() + 1);
    int quality = 0;
    return OIIO::Strutil::parse_int(q, quality) && q.empty() && quality > 0;
}

// The parts of PartLayout::Layers: the channel indices of each, channels without a layer
// first (io.h).
struct LayerPart {
    std::string name;
    std::vector<int> channels;
};
static std::vector<LayerPart> layer_parts(const OIIO::ImageSpec& spec)
{
    std::vector<LayerPart> parts;
    for (int c = 0; c < spec.nchannels; ++c) {
        const std::string layer = channel_layer(spec.channel_name(c));
        auto it = std::find_if(parts.begin(), parts.end(), [&](const LayerPart& p) {
            return p.name == (layer.empty() ? "rgba" : layer);
        });
        if (it == parts.end()) {
            parts.push_back({ layer.empty() ? "rgba" : layer, {} });
            if (layer.empty())
                std::rotate(parts.begin(), parts.end() - 1, parts.end());
            it = layer.empty() ? parts.begin() : parts.end() - 1;
        }
        it->channels.push_back(c);
    }
    return parts;
}

// Write one part of a file opened with all its parts: `img`'s channels `channels`, `spec`
// being the part's (part 0 is current after the open; later ones are appended).
static bool write_part(OIIO::ImageOutput& out, const std::string& tmp, const OIIO::ImageBuf& img,
                       const std::vector<int>& channels, const OIIO::ImageSpec& spec, bool append)
{
    if (append && !out.open(tmp, spec, OIIO::ImageOutput::AppendSubimage))
        return false;
    if (int(channels.size()) == img.nchannels())
        return write_pixels(out, img);
    const OIIO::ImageBuf subset = OIIO::ImageBufAlgo::channels(img, int(channels.size()),
                                                               channels);
    return !subset.has_error() && write_pixels(out, subset);
}

namespace {

// The time a file is written, as TIFF and EXIF spell DateTime ("YYYY:MM:DD HH:MM:SS"), in
// UTC. SOURCE_DATE_EPOCH (the reproducible-builds convention: seconds since 1970) fixes
// it, so that two runs can give the same bytes.
std::string date_time_now()
{
    std::time_t t = std::time(nullptr);
    if (const char* epoch = std::getenv("SOURCE_DATE_EPOCH")) {
        char* end       = nullptr;
        const long long v = std::strtoll(epoch, &end, 10);
        if (end != epoch && *end == '\0' && v >= 0)
            t = std::time_t(v);
    }
    std::tm utc = {};
    gmtime_r(&t, &utc);
    char text[32];
    std::strftime(text, sizeof(text), "%Y:%m:%d %H:%M:%S", &utc);
    return text;
}

}  // namespace

void describe_output(OIIO::ImageSpec& spec, const WriteOptions& opts)
{
    // Facts about the file an image was read from, not about the one being written.
    for (const char* stale : { "openexr:chunkCount", "oiio:subimages" })
        spec.erase_attribute(stale);
    spec.attribute("Software", "OpenBokeh " BOKEH_VERSION);
    spec.attribute("DateTime", date_time_now());
    for (const OIIO::ParamValue& p : opts.metadata)
        spec.attribute(p.name().string(), p.type(), p.data());
}

// Each part's spec: its channels, names, alpha and depth, and pixel types (one format,
// or per channel where they differ); a single part keeps `spec`'s names.
static std::vector<OIIO::ImageSpec> part_specs(const OIIO::ImageSpec& spec, const std::vector<LayerPart>& parts,
                                               const std::vector<OIIO::TypeDesc>& formats)
{
    std::vector<OIIO::ImageSpec> specs;
    for (const LayerPart& part : parts) {
        OIIO::ImageSpec ps = spec;
        if (parts.size() > 1) {
            ps.nchannels = int(part.channels.size());
            ps.channelnames.clear();
            for (int c : part.channels)
                ps.channelnames.push_back(spec.channel_name(c));
            ps.alpha_channel = ps.channelindex("A");
            ps.z_channel     = ps.channelindex("Z");
            ps.attribute("oiio:subimagename", part.name);
        }
        std::vector<OIIO::TypeDesc> pf;
        for (int c : part.channels)
            pf.push_back(formats[size_t(c)]);
        ps.format = pf[0];
        ps.channelformats.clear();
        for (const OIIO::TypeDesc& t : pf)
            if (t != pf[0])
                ps.channelformats = pf;
        specs.push_back(std::move(ps));
    }
    return specs;
}

bool write_image(const OIIO::ImageBuf& img, const std::string& path, const WriteOptions& opts,
                 std::string& err)
{
    if (!img.initialized()) {
        err = format("{}: nothing to write", path);
        return false;
    }
    const std::string dir = OIIO::Filesystem::parent_path(path);
    if (!dir.empty() && !OIIO::Filesystem::is_directory(dir)) {
        err = format("{}: directory '{}' does not exist", path, dir);
        return false;
    }
    if (OIIO::Filesystem::is_directory(path)) {
        err = format("{}: is a directory", path);
        return false;
    }
    if (opts.no_clobber && OIIO::Filesystem::exists(path)) {
        err = format("{}: already exists (--no-clobber)", path);
        return false;
    }
    auto out = OIIO::ImageOutput::create(path);
    if (!out) {
        err = format("{}: no image format writes this file type: {}", path,
                     first_line(OIIO::geterror()));
        return false;
    }
    if (img.deep() && !out->supports("deepdata")) {
        err = format("{}: the {} format cannot hold deep images", path, out->format_name());
        return false;
    }
    const bool exr = std::string(out->format_name()) == "openexr";
    if (!opts.compression.empty() && exr && !exr_compression_known(opts.compression)) {
        err = format("{}: '{}' is not an OpenEXR compression (none, rle, zip, zips, piz, pxr24, "
                     "b44, b44a, dwaa, dwab; dwaa:45 gives a quality)",
                     path, opts.compression);
        return false;
    }
    if ((opts.tile_width > 0 || opts.tile_height > 0)
        && (opts.tile_width <= 0 || opts.tile_height <= 0 || !out->supports("tiles"))) {
        err = opts.tile_width <= 0 || opts.tile_height <= 0
                  ? format("{}: tile size {} x {} (both sides > 0)", path, opts.tile_width,
                           opts.tile_height)
                  : format("{}: the {} format cannot hold tiles", path, out->format_name());
        return false;
    }

    OIIO::ImageSpec spec = img.spec();
    describe_output(spec, opts);
    std::vector<OIIO::TypeDesc> formats = opts.channel_formats;
    if (img.deep()) {
        const auto types = img.deepdata()->all_channeltypes();  // deep samples keep their own types
        formats.assign(types.begin(), types.end());
    } else if (formats.empty()) {
        formats.assign(size_t(spec.nchannels), OIIO::TypeFloat);
    }
    if (int(formats.size()) != spec.nchannels) {
        err = format("{}: {} channel types given for {} channels", path, formats.size(),
                     spec.nchannels);
        return false;
    }
    if (!opts.compression.empty())
        spec.attribute("compression", opts.compression);
    if (opts.tile_width > 0) {
        spec.tile_width  = opts.tile_width;
        spec.tile_height = opts.tile_height;
        spec.tile_depth  = 1;
    }

    // The parts, each with its channels, names and types.
    std::vector<LayerPart> parts;
    if (opts.parts == PartLayout::Layers && !img.deep())
        parts = layer_parts(spec);
    // Other formats hold several images (TIFF pages), but no reader takes them as layers.
    if (opts.parts == PartLayout::Layers && !exr) {
        err = format("{}: a part per layer is written to OpenEXR files, not {}", path,
                     out->format_name());
        return false;
    }
    if (parts.size() <= 1) {
        parts.assign(1, LayerPart{ "", {} });
        for (int c = 0; c < spec.nchannels; ++c)
            parts[0].channels.push_back(c);
    }
    const std::vector<OIIO::ImageSpec> specs = part_specs(spec, parts, formats);

    remove_stale_partials(path);
    const std::string tmp = partial_write_name(path);
    const int slot        = register_partial(tmp);
    bool ok               = false;
    try {
        const std::string compression = specs[0].get_string_attribute("compression", "zip");
        bool declined                 = true;
        if (exr && !img.deep() && specs.size() == 1 && specs[0].tile_width == 0
            && (compression == "zip" || compression == "zips")) {
            std::string why;
            ok = write_exr_deflated(img, specs[0],
                                    compression == "zip" ? detail::ExrDeflate::Zip
                                                         : detail::ExrDeflate::Zips,
                                    tmp, declined, why);
            if (!ok && !declined)
                err = format("{}: cannot write: {}", path, why);
        }
        if (!declined) {
            out.reset();
        } else if (specs.size() == 1) {
            ok = out->open(tmp, specs[0]) && write_pixels(*out, img);
        } else {
            ok = out->open(tmp, int(specs.size()), specs.data());
            for (size_t p = 0; ok && p < specs.size(); ++p)
                ok = write_part(*out, tmp, img, parts[p].channels, specs[p], p > 0);
        }
        if (out) {
            ok = out->close() && ok;
            if (!ok)
                err = format("{}: cannot write: {}", path, first_line(out->geterror()));
        }
    } catch (const std::bad_alloc&) {
        err = format("{}: out of memory while writing", path);
    } catch (const std::exception& e) {
        err = format("{}: cannot write: {}", path, first_line(e.what()));
    }
    std::string why;
    if (ok && !OIIO::Filesystem::rename(tmp, path, why)) {
        err = format("{}: cannot move the finished file into place: {}", path, why);
        ok  = false;
    }
    if (!ok)
        OIIO::Filesystem::remove(tmp);
    unregister_partial(slot);
    return ok;
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
