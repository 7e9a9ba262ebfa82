// io.cpp — reading and writing flat and deep images through OpenImageIO.
//
// Reads first check what the file declares against a memory budget (io_budget.cpp), then
// force the whole file into memory so that a truncated or corrupt file fails at read
// time with the file's name, not later in a filter; exceptions from the readers become
// errors. Writes use ImageOutput on a
// temporary file in the target's directory (same filesystem, so the final rename is
// atomic) and keep the spec: channel names, data/display windows, tiling, metadata.

#include <bokeh/io.h>

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <new>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

// OIIO error texts can span several lines and repeat the file name; keep the first line.
static std::string first_line(std::string s)
{
    s = OIIO::Strutil::strip(s);
    const size_t nl = s.find('\n');
    return nl == std::string::npos ? s : s.substr(0, nl);
}

// The part of read_image that can throw: OIIO and OpenEXR allocate and decode here.
static bool read_checked(OIIO::ImageBuf& dst, const std::string& path, std::string& err)
{
    auto probe = OIIO::ImageInput::open(path);
    if (!probe) {
        err = format("{}: cannot read: {}", path, first_line(OIIO::geterror()));
        return false;
    }
    const bool deep = probe->spec().deep;
    probe.reset();

    // ImageBuf keeps what it learned of a file (spec, an open reader) in OIIO's shared
    // ImageCache under the file's name; a file replaced under the same name since then
    // would be read with the old size into a buffer of the new one (heap corruption inside
    // OIIO, found by the read fuzzer). Forget it first.
    OIIO::ImageCache* cache = OIIO::ImageCache::create(true);
    cache->invalidate(OIIO::ustring(path), true);
    OIIO::ImageBuf buf(path);
    const bool ok = deep ? buf.read(0, 0, true) : buf.read(0, 0, true, OIIO::TypeFloat);
    if (!ok || buf.has_error()) {
        err = format("{}: cannot read (corrupt or truncated?): {}", path,
                     first_line(buf.geterror()));
        return false;
    }
    dst = std::move(buf);
    return true;
}

bool read_image(OIIO::ImageBuf& dst, const std::string& path, const ReadOptions& opts,
                std::string& err)
{
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
        return read_checked(dst, path, err);
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

bool read_image(OIIO::ImageBuf& dst, const std::string& path, std::string& err)
{
    return read_image(dst, path, ReadOptions(), err);
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

    OIIO::ImageSpec spec = img.spec();
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
    spec.format = formats[0];
    spec.channelformats.clear();
    for (const OIIO::TypeDesc& t : formats)
        if (t != formats[0])
            spec.channelformats = formats;

    remove_stale_partials(path);
    const std::string tmp = partial_write_name(path);
    const int slot        = register_partial(tmp);
    bool ok               = false;
    try {
        ok = out->open(tmp, spec) && write_pixels(*out, img);
        ok = out->close() && ok;
        if (!ok)
            err = format("{}: cannot write: {}", path, first_line(out->geterror()));
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
