#include "test_util.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>

#include <gtest/gtest.h>
#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

namespace bokeh_test {

namespace paths {
const char* const bokehtool      = BOKEH_TEST_PATH_BOKEHTOOL;
const char* const source_dir     = BOKEH_TEST_PATH_SOURCE_DIR;
const char* const shared_data    = BOKEH_TEST_PATH_SHARED_DATA;
const char* const test_tmp       = BOKEH_TEST_PATH_TMP;
const char* const bad_plugin_dir = BOKEH_TEST_PATH_BAD_PLUGIN_DIR;
const char* const ocio_config    = BOKEH_TEST_PATH_OCIO_CONFIG;
}  // namespace paths


std::string fresh_dir(const std::string& name)
{
    const std::string dir = std::string(BOKEH_TEST_TMP) + "/" + name;
    std::string err;
    OIIO::Filesystem::remove_all(dir, err);
    OIIO::Filesystem::create_directory(BOKEH_TEST_TMP, err);
    OIIO::Filesystem::create_directory(dir, err);
    return dir;
}

std::string shared_data(const std::string& relative)
{
    const std::string path = std::string(BOKEH_SHARED_DATA) + "/" + relative;
    return OIIO::Filesystem::exists(path) ? path : std::string();
}

std::string file_bytes(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

bool exists(const std::string& path) { return OIIO::Filesystem::exists(path); }

RunResult bokehtool(const std::string& args, const std::string& env)
{
    return run_shell(env + " " + BOKEHTOOL + " " + args);
}

RunResult run_shell(const std::string& command)
{
    static int counter = 0;
    const std::string base = std::string(BOKEH_TEST_TMP) + "/run" + std::to_string(getpid()) + "_"
                             + std::to_string(++counter);
    OIIO::Filesystem::create_directory(BOKEH_TEST_TMP);
    const std::string cmd = "( " + command + " ) </dev/null >" + base + ".out 2>" + base + ".err";
    RunResult r;
    const int raw = std::system(cmd.c_str());
    r.status      = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
    r.out         = file_bytes(base + ".out");
    r.err         = file_bytes(base + ".err");
    return r;
}

double max_difference(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b)
{
    if (a.roi() != b.roi() || a.nchannels() != b.nchannels())
        return std::numeric_limits<double>::infinity();
    // Thresholds above any difference: `error` would otherwise flag every difference.
    const float never = std::numeric_limits<float>::max();
    auto cmp          = OIIO::ImageBufAlgo::compare(a, b, never, never);
    return cmp.error ? std::numeric_limits<double>::infinity() : cmp.maxerror;
}

OIIO::ImageBuf rgbaz_image(int w, int h, const std::function<std::array<float, 5>(int, int)>& fn,
                           int x0, int y0, OIIO::ROI full)
{
    OIIO::ImageSpec spec(w, h, 5, OIIO::TypeFloat);
    spec.channelnames  = { "R", "G", "B", "A", "Z" };
    spec.alpha_channel = 3;
    spec.z_channel     = 4;
    spec.x             = x0;
    spec.y             = y0;
    if (!full.defined())
        full = OIIO::ROI(x0, x0 + w, y0, y0 + h);
    spec.full_x      = full.xbegin;
    spec.full_y      = full.ybegin;
    spec.full_width  = full.width();
    spec.full_height = full.height();
    OIIO::ImageBuf img(spec);
    for (int y = y0; y < y0 + h; ++y)
        for (int x = x0; x < x0 + w; ++x)
            img.setpixel(x, y, fn(x, y).data());
    return img;
}

OIIO::ImageBuf make_image(int w, int h, const std::function<Px(int, int)>& fn, int x0, int y0, OIIO::ROI full)
{
    return rgbaz_image(
        w, h,
        [&](int x, int y) {
            const Px p = fn(x, y);
            return std::array<float, 5>{ p.r, p.g, p.b, p.a, p.z };
        },
        x0, y0, full);
}

float at(const OIIO::ImageBuf& img, int x, int y, int c)
{
    const OIIO::ROI d = img.roi();
    if (x < d.xbegin || x >= d.xend || y < d.ybegin || y >= d.yend)
        return 0.0f;
    return static_cast<const float*>(img.pixeladdr(x, y))[c];
}

double channel_sum(const OIIO::ImageBuf& img, int c)
{
    double s          = 0.0;
    const OIIO::ROI d = img.roi();
    for (int y = d.ybegin; y < d.yend; ++y)
        for (int x = d.xbegin; x < d.xend; ++x)
            s += at(img, x, y, c);
    return s;
}

float texture(int x, int y, int salt)
{
    const unsigned h = unsigned(x) * 73856093u ^ unsigned(y) * 19349663u ^ unsigned(salt) * 83492791u;
    return float((h * 2654435761u) >> 8 & 0xffff) / 65535.0f;
}

OIIO::ImageBuf slanted_plane()
{
    return make_image(160, 90, [](int x, int y) {
        Px p;
        const float inv  = 1.0f + (0.1f - 1.0f) * float(x) / 159.0f;
        p.z              = 1.0f / inv;
        const bool check = ((x / 6) + (y / 6)) % 2 == 0;
        p.r              = check ? 0.9f : 0.1f;
        p.g              = 0.5f + 0.4f * std::sin(0.5f * float(y));
        p.b              = 0.3f + 0.6f * texture(x / 3, y / 3);
        return p;
    });
}

namespace {
// R, G, B of a frame after the tone map x / (1 + |x|), as doubles.
std::vector<double> tone_mapped_rgb(const OIIO::ImageBuf& img)
{
    std::vector<double> v;
    for (OIIO::ImageBuf::ConstIterator<float> it(img); !it.done(); ++it)
        for (int c = 0; c < 3; ++c)
            v.push_back(double(it[c]) / (1.0 + std::abs(double(it[c]))));
    return v;
}
}  // namespace

double second_to_first_difference(const std::vector<OIIO::ImageBuf>& a, const std::vector<OIIO::ImageBuf>& b)
{
    std::vector<std::vector<double>> fa, fb;
    for (size_t i = 0; i < a.size(); ++i) {
        fa.push_back(tone_mapped_rgb(a[i]));
        fb.push_back(tone_mapped_rgb(b[i]));
    }
    double e1 = 0.0, e2 = 0.0;
    for (size_t i = 0; i + 1 < fa.size(); ++i)
        for (size_t k = 0; k < fa[i].size(); ++k) {
            e1 += (fa[i + 1][k] - fa[i][k]) * (fb[i + 1][k] - fb[i][k]);
            if (i + 2 < fa.size())
                e2 += (fa[i + 2][k] - 2.0 * fa[i + 1][k] + fa[i][k]) * (fb[i + 2][k] - 2.0 * fb[i + 1][k] + fb[i][k]);
        }
    // Per frame: e1 has one more frame pair than e2.
    const double n1 = double(fa.size() - 1), n2 = double(fa.size() - 2);
    return std::sqrt(std::max(0.0, e2 / n2) / (e1 / n1));
}

bokeh::KernelWeights disk(float c)
{
    bokeh::Kernel k;
    k.shape     = bokeh::KernelShape::Disk;
    k.width_px  = std::abs(c);
    k.height_px = std::abs(c);
    return bokeh::kernel_weights(k);
}

bokeh::DefocusOptions direct_options(bokeh::DefocusMethod m, bokeh::Border border, bool grow)
{
    bokeh::DefocusOptions o;
    o.coc.mode = bokeh::DepthMode::Direct;
    o.method   = m;
    o.border   = border;
    o.grow     = grow;
    return o;
}

bokeh::DefocusOptions plane_lens(bokeh::DefocusMethod m)
{
    bokeh::DefocusOptions o;
    o.method                   = m;
    o.coc.mode                 = bokeh::DepthMode::Depth;
    o.coc.lens.focal_mm        = 85.0;
    o.coc.lens.fstop           = 1.4;
    o.coc.lens.sensor_width_mm = 36.0;
    return o;
}

bokeh::DefocusOptions scene_lens(const OIIO::ImageSpec& scene)
{
    bokeh::DefocusOptions o;
    o.coc.mode                 = bokeh::DepthMode::Depth;
    o.coc.lens.focus_distance  = scene.get_float_attribute("bokeh:focus_m", 6.0f);
    o.coc.lens.fstop           = scene.get_float_attribute("bokeh:fstop", 2.0f);
    o.coc.lens.focal_mm        = scene.get_float_attribute("bokeh:focal_mm", 50.0f);
    o.coc.lens.sensor_width_mm = scene.get_float_attribute("bokeh:sensor_width_mm", 36.0f);
    return o;
}

OIIO::ImageBuf run_defocus(const OIIO::ImageBuf& src, const bokeh::DefocusOptions& o, bokeh::DefocusReport* rep,
                           int nthreads)
{
    OIIO::ImageBuf dst;
    EXPECT_TRUE(bokeh::defocus(dst, src, o, rep, nthreads)) << dst.geterror();
    return dst;
}

bokeh::ImageError error_of(const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference)
{
    bokeh::ImageError e;
    std::string err;
    EXPECT_TRUE(bokeh::compare(e, result, reference, err)) << err;
    return e;
}

OIIO::ImageBuf make_deep(int w, int h, const std::vector<DeepPixel>& px, bool half_colour, int x0, int y0)
{
    OIIO::ImageSpec spec(w, h, 6, OIIO::TypeFloat);
    spec.x            = x0;
    spec.y            = y0;
    spec.channelnames = { "R", "G", "B", "A", "Z", "ZBack" };
    const OIIO::TypeDesc c = half_colour ? OIIO::TypeHalf : OIIO::TypeFloat;
    spec.channelformats    = { c, c, c, c, OIIO::TypeFloat, OIIO::TypeFloat };
    spec.alpha_channel     = 3;
    spec.z_channel         = 4;
    spec.deep              = true;
    OIIO::ImageBuf buf(spec);
    OIIO::DeepData& dd = *buf.deepdata();
    for (size_t p = 0; p < px.size(); ++p)
        dd.set_samples(int64_t(p), int(px[p].size()));
    for (size_t p = 0; p < px.size(); ++p)
        for (size_t s = 0; s < px[p].size(); ++s) {
            const DeepSample& m = px[p][s];
            const double v[6] = { m.r, m.g, m.b, m.a, m.z, m.zb };
            for (int ch = 0; ch < 6; ++ch)
                dd.set_deep_value(int64_t(p), ch, int(s), float(v[ch]));
        }
    return buf;
}

void expect_clean_failure(const RunResult& r, const std::string& what, const std::string& output)
{
    EXPECT_EQ(r.status, 1) << r.err;
    EXPECT_TRUE(OIIO::Strutil::starts_with(r.err, "bokehtool ERROR: ")) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "one line: " << r.err;
    EXPECT_NE(r.err.find(what), std::string::npos) << "expected '" << what << "' in: " << r.err;
    if (!output.empty()) {
        EXPECT_FALSE(exists(output)) << output << " was written";
    }
}

std::string stereo_parts_exr(const std::string& dir)
{
    const std::string path = dir + "/stereo_parts.exr";
    std::vector<OIIO::ImageSpec> specs;
    for (const char* part : { "rgba.left", "rgba.right", "depth.left", "depth.right" }) {
        const bool depth = std::strncmp(part, "depth", 5) == 0;
        OIIO::ImageSpec s(16, 8, depth ? 1 : 4, OIIO::TypeFloat);
        s.channelnames = depth ? std::vector<std::string>{ "Z" } : std::vector<std::string>{ "R", "G", "B", "A" };
        s.attribute("name", part);
        s.attribute("view", std::strstr(part, "left") ? "left" : "right");
        specs.push_back(s);
    }
    auto out = OIIO::ImageOutput::create(path);
    EXPECT_TRUE(out && out->open(path, int(specs.size()), specs.data()));
    for (size_t p = 0; p < specs.size(); ++p) {
        const bool left = p % 2 == 0;
        std::vector<float> px(size_t(16 * 8 * specs[p].nchannels));
        for (size_t i = 0; i < px.size(); ++i)
            px[i] = specs[p].nchannels == 1 ? (left ? 3.0f : 5.0f)
                                            : (i % 4 == 0 ? (left ? 0.25f : 0.75f) : i % 4 == 3 ? 1.0f : 0.5f);
        if (p > 0) {
            EXPECT_TRUE(out->open(path, specs[p], OIIO::ImageOutput::AppendSubimage));
        }
        EXPECT_TRUE(out->write_image(OIIO::TypeFloat, px.data()));
    }
    EXPECT_TRUE(out->close());
    return path;
}

std::string stereo_single_part_exr(const std::string& dir)
{
    const std::string path = dir + "/stereo_single.exr";
    OIIO::ImageSpec s(16, 8, 10, OIIO::TypeFloat);
    s.channelnames = { "left.R", "left.G", "left.B", "left.A", "left.Z",
                       "right.R", "right.G", "right.B", "right.A", "right.Z" };
    const char* views[] = { "left", "right" };
    s.attribute("multiView", OIIO::TypeDesc(OIIO::TypeDesc::STRING, 2), views);
    std::vector<float> px(size_t(16 * 8 * 10));
    const float pixel[10] = { 0.25f, 0.5f, 0.5f, 1.0f, 3.0f, 0.75f, 0.5f, 0.5f, 1.0f, 5.0f };
    for (size_t i = 0; i < px.size(); ++i)
        px[i] = pixel[i % 10];
    auto out = OIIO::ImageOutput::create(path);
    EXPECT_TRUE(out && out->open(path, s) && out->write_image(OIIO::TypeFloat, px.data()) && out->close());
    return path;
}


}  // namespace bokeh_test
