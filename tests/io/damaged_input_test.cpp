// Damaged input: a corpus made here from the real files in ../shared/data (a scanline
// EXR, a tiled and a two-part EXR made from it, two deep EXRs, a PNG) by truncation at
// many points, bit flips in the header, the chunk offset table and the pixel data, and
// header fields set to absurd values (data window, channel list, attribute sizes, tile
// size, deep sample counts and chunk sizes). Each case runs `bokehtool --info FILE -o
// out.exr` with a 10 s bound and must end in a clean one-line error (exit 1, the file
// named, nothing written) or a read whose output reads back; never a signal, another
// exit status or a hang. The counts are printed (docs/robustness.md shows them).
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>
#include <thread>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

constexpr double kBoundSeconds = 10.0;

void put_file(const std::string& path, const std::string& bytes)
{
    std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

template<typename T> void poke(std::string& b, size_t at, T v)
{
    if (at + sizeof(T) <= b.size())
        std::memcpy(&b[at], &v, sizeof(T));
}
template<typename T> T peek(const std::string& b, size_t at)
{
    T v{};
    if (at + sizeof(T) <= b.size())
        std::memcpy(&v, &b[at], sizeof(T));
    return v;
}

// ---------------------------------------------------------------------------------------
// The layout of an EXR file (OpenEXR file layout document): magic, version, headers of
// attributes (name\0 type\0 int32 size, value) each ended by \0 (multi-part: a further
// \0 after the last), then the chunk offset tables (uint64 each), then the chunks.

struct ExrAttr {
    std::string name, type;
    size_t size_at = 0, value_at = 0;  // offsets of the int32 size and of the value
    int32_t size   = 0;
};
struct ExrLayout {
    std::vector<ExrAttr> attrs;  // every part's
    size_t header_end = 0;       // first byte of the offset tables
    size_t chunks_at  = 0;       // first chunk (= the first offset-table entry's value)
    bool multipart    = false;
    bool ok           = false;
    const ExrAttr* find(const std::string& name) const
    {
        for (const ExrAttr& a : attrs)
            if (a.name == name)
                return &a;
        return nullptr;
    }
};

ExrLayout exr_layout(const std::string& b)
{
    ExrLayout L;
    if (b.size() < 8 || peek<uint32_t>(b, 0) != 20000630u)
        return L;
    L.multipart = (peek<uint32_t>(b, 4) & 0x1000) != 0;
    size_t p    = 8;
    auto cstr   = [&](std::string& out) {
        const size_t z = b.find('\0', p);
        if (z == std::string::npos)
            return false;
        out = b.substr(p, z - p);
        p   = z + 1;
        return true;
    };
    for (int part = 0; part < 16; ++part) {
        for (;;) {
            ExrAttr a;
            if (!cstr(a.name))
                return L;
            if (a.name.empty())
                break;
            if (!cstr(a.type) || p + 4 > b.size())
                return L;
            a.size_at  = p;
            a.size     = peek<int32_t>(b, p);
            a.value_at = p + 4;
            p += 4 + size_t(a.size);
            L.attrs.push_back(a);
        }
        if (!L.multipart || (p < b.size() && b[p] == '\0')) {
            if (L.multipart)
                ++p;
            break;
        }
    }
    L.header_end = p;
    L.chunks_at  = size_t(peek<uint64_t>(b, p));
    L.ok         = L.chunks_at > L.header_end && L.chunks_at < b.size();
    return L;
}

// ---------------------------------------------------------------------------------------
// Cases.

struct Case {
    std::string name;   // what was done, e.g. "scanline: truncated at 120"
    std::string bytes;  // the damaged file
};

struct Source {
    std::string label, ext, bytes;
};

void add_truncations(std::vector<Case>& cases, const Source& s, const ExrLayout& L)
{
    std::vector<size_t> at = { 0, 8 };
    if (L.ok) {
        at.push_back(L.header_end);
        at.push_back((L.header_end + L.chunks_at) / 2);
        at.push_back(L.chunks_at + 4);
    } else {
        at.push_back(20);
    }
    at.push_back(s.bytes.size() / 2);
    at.push_back(s.bytes.size() - 1);
    for (size_t n : at)
        if (n < s.bytes.size())
            cases.push_back({ format("{}: truncated at byte {} of {}", s.label, n, s.bytes.size()),
                              s.bytes.substr(0, n) });
}

void add_bit_flips(std::vector<Case>& cases, const Source& s, const std::string& region,
                   size_t begin, size_t end, int count, std::mt19937& rng)
{
    if (end <= begin)
        return;
    std::uniform_int_distribution<size_t> pos(begin, end - 1);
    std::uniform_int_distribution<int> bit(0, 7);
    for (int i = 0; i < count; ++i) {
        std::string b  = s.bytes;
        const size_t p = pos(rng);
        const int k    = bit(rng);
        b[p]           = char(b[p] ^ (1 << k));
        cases.push_back({ format("{}: bit {} of byte {} flipped ({})", s.label, k, p, region), b });
    }
}

void add_exr_field_damage(std::vector<Case>& cases, const Source& s, const ExrLayout& L)
{
    auto with = [&](const std::string& what, const std::function<void(std::string&)>& f) {
        std::string b = s.bytes;
        f(b);
        cases.push_back({ format("{}: {}", s.label, what), b });
    };
    if (const ExrAttr* dw = L.find("dataWindow")) {
        const size_t v = dw->value_at;
        with("dataWindow 2^30 x 2^30", [&](std::string& b) {
            poke<int32_t>(b, v + 8, (1 << 30) - 1 + peek<int32_t>(b, v));
            poke<int32_t>(b, v + 12, (1 << 30) - 1 + peek<int32_t>(b, v + 4));
        });
        with("dataWindow 2^31 lines tall", [&](std::string& b) {
            poke<int32_t>(b, v + 4, INT32_MIN);
            poke<int32_t>(b, v + 12, INT32_MAX);
        });
        with("dataWindow 100000 x 100000", [&](std::string& b) {
            poke<int32_t>(b, v + 8, peek<int32_t>(b, v) + 99999);
            poke<int32_t>(b, v + 12, peek<int32_t>(b, v + 4) + 99999);
        });
        with("dataWindow 60000 wide, height kept", [&](std::string& b) {
            poke<int32_t>(b, v + 8, peek<int32_t>(b, v) + 59999);
        });
        with("dataWindow inverted", [&](std::string& b) {
            const int32_t x0 = peek<int32_t>(b, v), x1 = peek<int32_t>(b, v + 8);
            poke<int32_t>(b, v, x1);
            poke<int32_t>(b, v + 8, x0 - 1);
        });
        with("dataWindow one line taller", [&](std::string& b) {
            poke<int32_t>(b, v + 12, peek<int32_t>(b, v + 12) + 1);
        });
    }
    if (const ExrAttr* ch = L.find("channels")) {
        // chlist: per channel name\0 int32 type, uint8 pLinear, 3 reserved, int32 xs, ys.
        const size_t first_type = s.bytes.find('\0', ch->value_at) + 1;
        with("first channel's pixel type 7", [&](std::string& b) { poke<int32_t>(b, first_type, 7); });
        with("first channel's x sampling 0", [&](std::string& b) { poke<int32_t>(b, first_type + 8, 0); });
        with("first channel's y sampling 2^30", [&](std::string& b) { poke<int32_t>(b, first_type + 12, 1 << 30); });
        with("channel list size 2^31-1", [&](std::string& b) { poke<int32_t>(b, ch->size_at, INT32_MAX); });
        with("channel list size -5", [&](std::string& b) { poke<int32_t>(b, ch->size_at, -5); });
        with("channel list without its end", [&](std::string& b) {
            b[ch->value_at + size_t(ch->size) - 1] = 'X';
        });
    }
    if (const ExrAttr* c = L.find("compression")) {
        with("compression 200", [&](std::string& b) { b[c->value_at] = char(200); });
    }
    if (const ExrAttr* t = L.find("tiles")) {
        with("tile size 1 x 1", [&](std::string& b) {
            poke<uint32_t>(b, t->value_at, 1);
            poke<uint32_t>(b, t->value_at + 4, 1);
        });
        with("tile size 2^31-1", [&](std::string& b) {
            poke<uint32_t>(b, t->value_at, INT32_MAX);
            poke<uint32_t>(b, t->value_at + 4, INT32_MAX);
        });
        with("tile mode ripmap", [&](std::string& b) { b[t->value_at + 8] = char(2); });
    }
    if (const ExrAttr* cc = L.find("chunkCount")) {
        with("chunkCount 2^31-1", [&](std::string& b) { poke<int32_t>(b, cc->value_at, INT32_MAX); });
        with("chunkCount -1", [&](std::string& b) { poke<int32_t>(b, cc->value_at, -1); });
    }
    if (!L.attrs.empty())
        with("first attribute size 2^31-1", [&](std::string& b) {
            poke<int32_t>(b, L.attrs.front().size_at, INT32_MAX);
        });
    if (L.ok) {
        const size_t t = L.header_end, n = (L.chunks_at - L.header_end) / 8;
        with("offset table: first entry 2^62", [&](std::string& b) { poke<uint64_t>(b, t, uint64_t(1) << 62); });
        with("offset table: every entry the first chunk", [&](std::string& b) {
            for (size_t i = 0; i < n; ++i)
                poke<uint64_t>(b, t + 8 * i, L.chunks_at);
        });
        with("offset table: every entry 0", [&](std::string& b) {
            for (size_t i = 0; i < n; ++i)
                poke<uint64_t>(b, t + 8 * i, 0);
        });
        with("offset table: entries point into the table", [&](std::string& b) {
            for (size_t i = 0; i < n; ++i)
                poke<uint64_t>(b, t + 8 * i, t);
        });
        with("offset table: last entry past the end", [&](std::string& b) {
            poke<uint64_t>(b, t + 8 * (n - 1), b.size() + 1000);
        });
        with("offset table: reversed", [&](std::string& b) {
            for (size_t i = 0; i < n / 2; ++i) {
                const uint64_t a = peek<uint64_t>(b, t + 8 * i), z = peek<uint64_t>(b, t + 8 * (n - 1 - i));
                poke(b, t + 8 * i, z);
                poke(b, t + 8 * (n - 1 - i), a);
            }
        });
        // The first chunk's leader: [int32 part,] int32 y (or 4 x int32 tile coordinates),
        // then its sizes.
        const size_t c    = L.chunks_at + (L.multipart ? 4 : 0);
        const bool tiled  = L.find("tiles") != nullptr;
        const bool deep   = s.label.find("deep") != std::string::npos;
        const size_t size = c + (tiled ? 16 : 4);
        with("first chunk: line/tile number 2^30", [&](std::string& b) { poke<int32_t>(b, c, 1 << 30); });
        if (!deep) {
            with("first chunk: data size 2^31-1", [&](std::string& b) { poke<int32_t>(b, size, INT32_MAX); });
            with("first chunk: data size -1", [&](std::string& b) { poke<int32_t>(b, size, -1); });
        } else {
            // Deep: uint64 packed count-table size, packed data size, unpacked data size;
            // then the count table (cumulative int32 a pixel; stored raw when uncompressed).
            with("first deep chunk: count-table size 2^40", [&](std::string& b) { poke<uint64_t>(b, size, uint64_t(1) << 40); });
            with("first deep chunk: data size 2^62", [&](std::string& b) { poke<uint64_t>(b, size + 8, uint64_t(1) << 62); });
            with("first deep chunk: unpacked size 2^62", [&](std::string& b) { poke<uint64_t>(b, size + 16, uint64_t(1) << 62); });
            const size_t table = size + 24;
            const uint64_t table_bytes = peek<uint64_t>(s.bytes, size);
            with("first deep chunk: last cumulative count 2^31-1", [&](std::string& b) {
                poke<int32_t>(b, table + table_bytes - 4, INT32_MAX);
            });
            with("first deep chunk: every count 2^31-1", [&](std::string& b) {
                for (size_t i = 0; i + 4 <= table_bytes; i += 4)
                    poke<int32_t>(b, table + i, INT32_MAX);
            });
            with("first deep chunk: counts decreasing", [&](std::string& b) {
                for (size_t i = 0; i + 4 <= table_bytes; i += 4)
                    poke<int32_t>(b, table + i, int32_t(1000000 - i));
            });
            with("every deep chunk: count 2^20 a pixel", [&](std::string& b) {
                for (size_t e = 0; e < n; ++e) {
                    const size_t ch = size_t(peek<uint64_t>(s.bytes, t + 8 * e)) + (size - L.chunks_at);
                    const uint64_t tb = peek<uint64_t>(s.bytes, ch);
                    for (size_t i = 0; i + 4 <= tb && i < (1u << 20); i += 4)
                        poke<int32_t>(b, ch + 24 + i, int32_t(std::min<uint64_t>((i / 4 + 1) << 20, INT32_MAX)));
                }
            });
        }
    }
}

// PNG: 8-byte signature, then chunks (uint32 BE length, type, data, CRC over type+data).
uint32_t crc32_png(const char* data, size_t n)
{
    uint32_t c = 0xffffffffu;
    for (size_t i = 0; i < n; ++i) {
        c ^= uint8_t(data[i]);
        for (int k = 0; k < 8; ++k)
            c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return ~c;
}
void put_be32(std::string& b, size_t at, uint32_t v)
{
    for (int i = 0; i < 4; ++i)
        b[at + size_t(i)] = char(v >> (24 - 8 * i));
}

void add_png_field_damage(std::vector<Case>& cases, const Source& s)
{
    // IHDR is the first chunk: its data (width, height, depth, colour type, ...) at 16.
    auto ihdr = [&](const std::string& what, const std::function<void(std::string&)>& f) {
        std::string b = s.bytes;
        f(b);
        put_be32(b, 29, crc32_png(&b[12], 17));  // a valid CRC, so the values are what is tested
        cases.push_back({ format("{}: {} (CRC fixed)", s.label, what), b });
    };
    ihdr("width 2^31-1", [](std::string& b) { put_be32(b, 16, 0x7fffffffu); });
    ihdr("width and height 100000", [](std::string& b) { put_be32(b, 16, 100000); put_be32(b, 20, 100000); });
    ihdr("height 0", [](std::string& b) { put_be32(b, 20, 0); });
    ihdr("bit depth 3", [](std::string& b) { b[24] = 3; });
    ihdr("colour type 5", [](std::string& b) { b[25] = 5; });
    std::string b = s.bytes;
    put_be32(b, 33, 0x7fffffffu);  // the second chunk's length
    cases.push_back({ s.label + ": second chunk length 2^31-1", b });
}

// ---------------------------------------------------------------------------------------
// Running one case.

struct Outcome {
    enum Kind { Read, Error, BadError, Crash, Hang } kind = Crash;
    double seconds = 0;
    std::string detail;
};

Outcome run_case(const std::string& file, const std::string& out, const std::string& dir)
{
    const std::string log_out = dir + "/stdout.txt", log_err = dir + "/stderr.txt";
    const auto t0 = std::chrono::steady_clock::now();
    const pid_t pid = fork();
    if (pid == 0) {
        const int o = open(log_out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        const int e = open(log_err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        const int n = open("/dev/null", O_RDONLY);
        dup2(n, 0), dup2(o, 1), dup2(e, 2);
        execl(BOKEHTOOL, BOKEHTOOL, "--threads", "1", "--info", file.c_str(), "-o", out.c_str(),
              static_cast<char*>(nullptr));
        _exit(127);
    }
    Outcome r;
    int status = 0;
    for (;;) {
        const pid_t w = waitpid(pid, &status, WNOHANG);
        r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (w == pid)
            break;
        if (r.seconds > kBoundSeconds) {
            kill(pid, SIGKILL);
            waitpid(pid, &status, 0);
            r.kind = Outcome::Hang;
            return r;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    const std::string err = file_bytes(log_err);
    std::vector<std::string> left;
    OIIO::Filesystem::get_directory_entries(dir, left);
    size_t partials = 0;
    for (const std::string& f : left)
        partials += f.find(".openbokeh-partial.") != std::string::npos;
    if (WIFSIGNALED(status)) {
        r.detail = format("signal {}: {}", WTERMSIG(status), err.substr(0, 300));
        return r;
    }
    const int code = WEXITSTATUS(status);
    if (code == 0) {
        OIIO::ImageBuf back(out);
        if (back.read(0, 0, true) && partials == 0 && err.find("ERROR") == std::string::npos) {
            r.kind = Outcome::Read;
        } else {
            r.kind   = Outcome::BadError;
            r.detail = format("exit 0 but the output does not read back: {} {}", back.geterror(), err);
        }
        return r;
    }
    if (code != 1) {
        r.detail = format("exit status {}: {}", code, err.substr(0, 300));
        return r;
    }
    const bool one_line = std::count(err.begin(), err.end(), '\n') == 1
                          && OIIO::Strutil::starts_with(err, "bokehtool ERROR: ");
    const bool names    = err.find(OIIO::Filesystem::filename(file)) != std::string::npos;
    if (one_line && names && !exists(out) && partials == 0) {
        r.kind   = Outcome::Error;
        r.detail = err;
    } else {
        r.kind   = Outcome::BadError;
        r.detail = format("exit 1 but not a clean error (one line {}, names the file {}, "
                          "output written {}, temporaries left {}): {}",
                          one_line, names, exists(out), partials, err.substr(0, 300));
    }
    return r;
}

// ---------------------------------------------------------------------------------------
// The sources, made small from the real files.

std::string bytes_of_written(const OIIO::ImageBuf& img, const std::string& path)
{
    EXPECT_TRUE(img.write(path)) << img.geterror();
    return file_bytes(path);
}

std::vector<Source> make_sources(const std::string& dir)
{
    std::vector<Source> sources;
    const std::string ball = shared_data("openexr-images/Beachball_singlepart.0001.exr");
    const std::string alpha = shared_data("oiio-testsuite/oiiotool-deep_src_deepalpha.exr");
    const std::string trunks = shared_data("openexr-images/LowResLeftView_Trunks.exr");
    if (ball.empty() || alpha.empty() || trunks.empty())
        return sources;

    // 48 x 40 of the ball, its R, G, B, A, Z in the types the file stores them in.
    OIIO::ImageBuf full(ball);
    EXPECT_TRUE(full.read(0, 0, true));
    const OIIO::ROI dw = full.roi();
    const OIIO::ROI crop(dw.xbegin + 400, dw.xbegin + 448, dw.ybegin + 400, dw.ybegin + 440);
    std::vector<int> rgbaz;
    for (const char* c : { "R", "G", "B", "A", "Z" })
        rgbaz.push_back(full.spec().channelindex(c));
    OIIO::ImageBuf small = OIIO::ImageBufAlgo::cut(OIIO::ImageBufAlgo::channels(full, 5, rgbaz), crop);
    small.specmod().attribute("compression", "zip");
    sources.push_back({ "scanline zip EXR", ".exr", bytes_of_written(small, dir + "/src_scanline.exr") });
    OIIO::ImageBuf tiled = small;
    tiled.specmod().attribute("compression", "piz");
    tiled.set_write_tiles(16, 16);
    sources.push_back({ "tiled piz EXR", ".exr", bytes_of_written(tiled, dir + "/src_tiled.exr") });
    {
        // Two parts: the crop, and its R,G,B as a second part.
        const std::string path = dir + "/src_multipart.exr";
        OIIO::ImageSpec specs[2] = { small.spec(), OIIO::ImageBufAlgo::channels(small, 3, {}).spec() };
        specs[0].attribute("oiio:subimagename", "beauty");
        specs[1].attribute("oiio:subimagename", "rgb");
        auto out = OIIO::ImageOutput::create(path);
        OIIO::ImageBuf rgb = OIIO::ImageBufAlgo::channels(small, 3, {});
        EXPECT_TRUE(out && out->open(path, 2, specs));
        EXPECT_TRUE(small.write(out.get()));
        EXPECT_TRUE(out->open(path, specs[1], OIIO::ImageOutput::AppendSubimage));
        EXPECT_TRUE(rgb.write(out.get()));
        out->close();
        sources.push_back({ "two-part EXR", ".exr", file_bytes(path) });
    }
    sources.push_back({ "PNG", ".png", bytes_of_written(OIIO::ImageBufAlgo::channels(small, 4, {}), dir + "/src.png") });
    {
        // The deep file as stored (tiled, zip), and as scanlines without compression so
        // its count tables are stored raw.
        sources.push_back({ "deep tiled zip EXR (deepalpha)", ".exr", file_bytes(alpha) });
        OIIO::ImageBuf deep(alpha);
        EXPECT_TRUE(deep.read(0, 0, true));
        deep.specmod().attribute("compression", "none");
        deep.set_write_tiles(0, 0);  // scanline
        sources.push_back({ "deep scanline uncompressed EXR", ".exr", bytes_of_written(deep, dir + "/src_deep_none.exr") });
    }
    sources.push_back({ "deep EXR (Trunks)", ".exr", file_bytes(trunks) });
    return sources;
}

}  // namespace

// The pixels of an output, flattened when deep, for comparing reads with the source's.
static OIIO::ImageBuf pixels_of(const std::string& path)
{
    OIIO::ImageBuf img(path);
    if (!img.read(0, 0, true, OIIO::TypeFloat))
        return {};
    return img.deep() ? OIIO::ImageBufAlgo::flatten(img) : img;
}

TEST(DamagedInput, NeverCrashesOrHangs)
{
    const std::string dir = fresh_dir("damaged_input");
    std::vector<Source> sources = make_sources(dir);
    if (sources.empty())
        GTEST_SKIP() << "../shared/data is not beside the project: no damaged corpus";

    std::mt19937 rng(20240615);
    std::vector<Case> cases;
    std::vector<size_t> source_of;  // the source each case was made from
    for (size_t si = 0; si < sources.size(); ++si) {
        const Source& s   = sources[si];
        const ExrLayout L = exr_layout(s.bytes);
        const bool big    = s.bytes.size() > 200000;  // the real deep file: fewer cases
        add_truncations(cases, s, L);
        if (s.ext == ".exr") {
            ASSERT_TRUE(L.ok) << s.label << ": the test's EXR layout reader failed";
            add_bit_flips(cases, s, "header", 8, L.header_end, big ? 2 : 4, rng);
            add_bit_flips(cases, s, "offset table", L.header_end, L.chunks_at, big ? 1 : 2, rng);
            add_bit_flips(cases, s, "pixel data", L.chunks_at, s.bytes.size(), big ? 1 : 2, rng);
            add_exr_field_damage(cases, s, L);
        } else {
            add_bit_flips(cases, s, "header", 8, 33, 3, rng);
            add_bit_flips(cases, s, "pixel data", 33, s.bytes.size(), 2, rng);
            add_png_field_damage(cases, s);
        }
        source_of.resize(cases.size(), si);
    }

    // What bokehtool makes of each undamaged source: a read of a damaged file that gives
    // the same pixels is a correct read.
    std::vector<OIIO::ImageBuf> reference;
    for (size_t si = 0; si < sources.size(); ++si) {
        const std::string ref_dir = format("{}/ref{}", dir, si);
        OIIO::Filesystem::create_directory(ref_dir);
        const std::string file = ref_dir + "/source" + sources[si].ext;
        put_file(file, sources[si].bytes);
        const Outcome r = run_case(file, ref_dir + "/out.exr", ref_dir);
        ASSERT_EQ(r.kind, Outcome::Read) << sources[si].label << ": " << r.detail;
        reference.push_back(pixels_of(ref_dir + "/out.exr"));
    }

    // Two cases at a time (the machine's cores), each in its own directory.
    std::vector<Outcome> outcomes(cases.size());
    std::atomic<size_t> next{ 0 };
    auto worker = [&](int w) {
        const std::string run_dir = format("{}/run{}", dir, w);
        for (size_t i; (i = next++) < cases.size();) {
            std::string e;
            OIIO::Filesystem::remove_all(run_dir, e);
            OIIO::Filesystem::create_directory(run_dir, e);
            const std::string file = format("{}/damaged_{:03}{}", run_dir, i, sources[source_of[i]].ext);
            put_file(file, cases[i].bytes);
            outcomes[i] = run_case(file, run_dir + "/out.exr", run_dir);
            if (outcomes[i].kind == Outcome::Read) {
                const OIIO::ImageBuf& ref = reference[source_of[i]];
                const OIIO::ImageBuf got  = pixels_of(run_dir + "/out.exr");
                outcomes[i].detail = max_difference(ref, got) == 0.0 ? "same pixels" : "different pixels";
            }
        }
    };
    const auto t0 = std::chrono::steady_clock::now();
    std::thread second(worker, 1);
    worker(0);
    second.join();
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

    int same = 0, differ = 0, errors = 0, bad_errors = 0, crashes = 0, hangs = 0;
    double slowest = 0;
    std::string slowest_case;
    for (size_t i = 0; i < cases.size(); ++i) {
        const Case& c    = cases[i];
        const Outcome& r = outcomes[i];
        if (r.seconds > slowest)
            slowest = r.seconds, slowest_case = c.name;
        switch (r.kind) {
        case Outcome::Read: (r.detail == "same pixels" ? same : differ) += 1; break;
        case Outcome::Error: ++errors; break;
        case Outcome::BadError: ++bad_errors; break;
        case Outcome::Crash: ++crashes; break;
        case Outcome::Hang: ++hangs; break;
        }
        if (r.kind == Outcome::Crash || r.kind == Outcome::Hang || r.kind == Outcome::BadError) {
            const std::string keep = format("{}/failing_{:03}{}", dir, i, sources[source_of[i]].ext);
            put_file(keep, c.bytes);
            ADD_FAILURE() << c.name << ": "
                          << (r.kind == Outcome::Hang ? "hang (killed after 10 s)" : r.detail)
                          << " (kept as " << keep << ")";
        }
        if (std::getenv("BOKEH_DAMAGED_VERBOSE"))
            std::cout << format("{:6.3f} s  {:<6}  {}  {}\n", r.seconds,
                                r.kind == Outcome::Read ? "read" : r.kind == Outcome::Error ? "error" : "FAIL",
                                c.name, OIIO::Strutil::strip(r.detail));
    }
    std::cout << format("damaged corpus: {} cases from {} sources: {} clean errors, {} reads "
                        "({} with the source's pixels, {} with other pixels), {} unclean "
                        "errors, {} crashes, {} hangs; slowest {:.2f} s ({}); {:.1f} s\n",
                        cases.size(), sources.size(), errors, same + differ, same, differ,
                        bad_errors, crashes, hangs, slowest, slowest_case, wall);
    EXPECT_EQ(crashes, 0);
    EXPECT_EQ(hangs, 0);
    EXPECT_EQ(bad_errors, 0);
    EXPECT_EQ(same + differ + errors, int(cases.size()));
}
