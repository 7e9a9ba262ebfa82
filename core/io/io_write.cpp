// io_write.cpp — writing flat and deep images through OpenImageIO, atomically.
//
// Writes use ImageOutput on a temporary file in the target's directory (same filesystem, so
// the final rename is atomic) and keep the spec: channel names, data/display windows,
// tiling, metadata; or write a part per layer, a compression or a tiling asked for
// (WriteOptions). A single-part scanline EXR with zip or zips compression (OpenEXR's and
// OIIO's default) is written by OIIO uncompressed into memory and compressed by
// exr_deflate.cpp, about twice as fast as OpenEXR 3.1's zlib (the measurement is in
// exr_deflate.cpp). Temporary files of writes in progress are registered so that signal
// handlers and later writes can remove them.

#include <bokeh/io.h>

#include "io/exr_deflate.h"
#include "io/io_text.h"

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
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using detail::first_line;
using OIIO::Strutil::fmt::format;

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
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) {
        err = std::strerror(errno);
        return false;
    }
    std::string why;
    const detail::DeflateResult done = detail::deflate_exr_file(file, compression, kExrDeflateLevel, f, why);
    const int saved                  = errno;
    if (std::fclose(f) != 0 && done == detail::DeflateResult::Written) {
        err = std::strerror(errno);
        return false;
    }
    if (done == detail::DeflateResult::Declined) {
        declined = true;  // the caller writes the file with OpenEXR's own codec
        return false;
    }
    if (done == detail::DeflateResult::WriteFailed) {
        err = std::strerror(saved);
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

}  // namespace bokeh
