// bokehtool --defocus and --diff as a user runs them: outputs, diagnostics, -v, bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

const char* kScene = "--scene lights:width=160:height=90";

}  // namespace

TEST(CliDefocus, WritesRgba)
{
    const std::string dir = fresh_dir("cli_defocus_rgba");
    const RunResult r = bokehtool(format("{} --defocus:focus=6:fstop=2 -o {}/out.exr", kScene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    OIIO::ImageBuf out(dir + "/out.exr");
    ASSERT_TRUE(out.read(0, 0, true, OIIO::TypeFloat)) << out.geterror();
    const OIIO::ImageSpec& s = out.spec();
    EXPECT_EQ(s.nchannels, 4);
    EXPECT_EQ(s.channelnames, (std::vector<std::string>{ "R", "G", "B", "A" }));
    EXPECT_EQ(s.full_width, 160);
    EXPECT_EQ(s.full_height, 90);
    // A real image: finite, alpha within 0..1, not black. (Whether an opaque input stays
    // opaque is DefocusOcclusion.OpaqueInputStaysOpaque's business.)
    double sum = 0.0;
    for (int y = s.y; y < s.y + s.height; ++y)
        for (int x = s.x; x < s.x + s.width; ++x) {
            float px[4];
            out.getpixel(x, y, px);
            ASSERT_TRUE(std::isfinite(px[0] + px[1] + px[2] + px[3])) << x << "," << y;
            ASSERT_GE(px[3], 0.0f) << x << "," << y;
            ASSERT_LE(px[3], 1.0f + 1e-4f) << x << "," << y;
            sum += px[0] + px[1] + px[2];
        }
    EXPECT_GT(sum, 100.0);
    // Differs from the sharp scene (it was defocused).
    ASSERT_EQ(bokehtool(format("{} --ch R,G,B,A -o {}/sharp.exr", kScene, dir)).status, 0);
    OIIO::ImageBuf sharp(dir + "/sharp.exr");
    EXPECT_GT(max_difference(out, sharp), 0.01);
}

TEST(CliDefocus, DiagnosticOutputs)
{
    const std::string dir = fresh_dir("cli_defocus_diag");
    const std::pair<const char*, int> outputs[] = { { "coc", 1 }, { "focalplane", 3 }, { "layers", 1 } };
    for (const auto& [what, channels] : outputs) {
        SCOPED_TRACE(what);
        const std::string path = dir + "/" + what + ".exr";
        const RunResult r = bokehtool(format("{} --defocus:focus=6:fstop=2:output={} -o {}", kScene, what, path));
        ASSERT_EQ(r.status, 0) << r.err;
        OIIO::ImageBuf img(path);
        ASSERT_TRUE(img.read(0, 0, true, OIIO::TypeFloat)) << img.geterror();
        EXPECT_EQ(img.spec().nchannels, channels);
        EXPECT_EQ(img.spec().width, 160);
        EXPECT_EQ(img.spec().height, 90);
    }
    // The CoC map holds both signs (the lights scene has front and back bokeh) and 0 near
    // the in-focus sphere's depth.
    OIIO::ImageBuf coc(dir + "/coc.exr");
    ASSERT_TRUE(coc.read(0, 0, true, OIIO::TypeFloat));
    float lo = 1e9f, hi = -1e9f;
    for (int y = 0; y < 90; ++y)
        for (int x = 0; x < 160; ++x) {
            const float c = coc.getchannel(x, y, 0, 0);
            lo            = std::min(lo, c);
            hi            = std::max(hi, c);
        }
    EXPECT_LT(lo, -0.5f);
    EXPECT_GT(hi, 0.5f);
}

TEST(CliDefocus, VerboseNamesTheLayers)
{
    const std::string dir = fresh_dir("cli_defocus_verbose");
    const RunResult r = bokehtool(format("-v {} --defocus:focus=6:fstop=2 -o {}/out.exr", kScene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    std::vector<std::string> lines;
    OIIO::Strutil::split(r.out, lines, "\n");
    bool found = false;
    for (const std::string& l : lines)
        found = found || (l.find("layers") != std::string::npos && l.find("CoC") != std::string::npos);
    EXPECT_TRUE(found) << "no line with 'layers' and 'CoC' in:\n" << r.out;
    // quality= is method= under another spelling.
    const RunResult g = bokehtool(format("-v {} --defocus:focus=6:fstop=2:quality=gather -o {}/g.exr", kScene, dir));
    ASSERT_EQ(g.status, 0) << g.err;
    EXPECT_NE(g.out.find("gather"), std::string::npos) << g.out;
    // planner=predicted lists the plans it weighed, its choice marked.
    const RunResult p = bokehtool(format("-v {} --defocus:focus=6:fstop=2:planner=predicted -o {}/p.exr", kScene, dir));
    ASSERT_EQ(p.status, 0) << p.err;
    EXPECT_NE(p.out.find("plans weighed against budget 40 dB"), std::string::npos) << p.out;
    EXPECT_NE(p.out.find("<- chosen"), std::string::npos) << p.out;
    // Without -v it says nothing.
    const RunResult q = bokehtool(format("{} --defocus:focus=6:fstop=2 -o {}/q.exr", kScene, dir));
    ASSERT_EQ(q.status, 0) << q.err;
    EXPECT_EQ(q.out.find("CoC"), std::string::npos) << q.out;
}

TEST(CliDefocus, FillChoosesWhatABlurredForegroundUncovers)
{
    // lights at f/1.27: the post (CoC about -10 px at this size) uncovers the floor behind it.
    const std::string dir = fresh_dir("cli_defocus_fill");
    const char* scene = "--scene lights:width=320:height=180";
    auto run = [&](const std::string& fill) {
        const RunResult r = bokehtool(format("-v {} --defocus:focus=6:fstop=1.27:fill={} -o {}/{}.exr", scene, fill, dir, fill));
        EXPECT_EQ(r.status, 0) << r.err;
        return r.out;
    };
    const std::string fg = run("foreground"), smooth = run("smooth"), mirror = run("mirror");
    EXPECT_NE(fg.find("uncovered background: 0 px continued"), std::string::npos) << fg;
    for (const std::string& out : { smooth, mirror }) {
        const size_t at = out.find("uncovered background: ");
        ASSERT_NE(at, std::string::npos) << out;
        EXPECT_GT(std::atoi(out.c_str() + at + 22), 0) << out;
    }
    // The fills differ where the post's edge uncovers the floor, and only there: most pixels
    // are the same in all three.
    OIIO::ImageBuf a(dir + "/foreground.exr"), b(dir + "/smooth.exr");
    int64_t differ = 0, total = 0;
    for (OIIO::ImageBuf::ConstIterator<float> p(a), q(b); !p.done(); ++p, ++q, ++total) {
        bool d = false;
        for (int c = 0; c < 4; ++c)
            d = d || std::abs(p[c] - q[c]) > 0.01f;
        differ += d;
    }
    EXPECT_GT(differ, 50);
    EXPECT_LT(differ, total / 10);
    // Where it cannot apply, said so.
    for (const char* bad : { "method=gather:fill=smooth", "fill=inpaint" }) {
        const RunResult r = bokehtool(format("{} --defocus:focus=6:{} -o {}/bad.exr", scene, bad, dir));
        EXPECT_EQ(r.status, 1) << bad;
        EXPECT_NE(r.err.find("fill"), std::string::npos) << r.err;
        EXPECT_FALSE(OIIO::Filesystem::exists(dir + "/bad.exr"));
    }
}

TEST(CliDefocus, BadInputFailsCleanly)
{
    const std::string dir = fresh_dir("cli_defocus_bad");
    const std::string out = dir + "/out.exr";
    struct Case {
        std::string args, expected;
    };
    const Case cases[] = {
        { format("{} --defocus:focus=abc -o {}", kScene, out), "focus 'abc'" },
        { format("{} --defocus:focus=500,500 -o {}", kScene, out), "focus pixel 500,500 is outside" },
        { format("{} --defocus:unit=furlong -o {}", kScene, out), "furlong" },
        { format("{} --ch R,G,B --defocus:focus=6 -o {}", kScene, out), "no depth channel" },
        { format("{} --defocus:focus=0.01 -o {}", kScene, out), "focal length" },
        { format("{} --defocus:quality=gather:method=layers -o {}", kScene, out), "disagree" },
        { format("{} --defocus:iris=5000 -o {}", kScene, out), "iris" },
        { format("{} --defocus:ratio=0.5 -o {}", kScene, out), "ladder ratio 0.5 is outside 1..16" },
        { format("{} --defocus:planner=guess -o {}", kScene, out), "planner" },
        { format("{} --defocus:fstop=2:iris=100 -o {}", kScene, out), "exceeds 30" },
        // Aperture options the kernel would ignore (as --blur refuses them).
        { format("{} --defocus:kernel=hex:blades=5 -o {}", kScene, out), "blades does not apply to kernel=hex" },
        { format("{} --defocus:kernel=disk:rotation=20 -o {}", kScene, out), "rotation does not apply to kernel=disk" },
        { format("{} --defocus:curvature=0.5 -o {}", kScene, out), "curvature does not apply to kernel=disk" },
    };
    for (const Case& k : cases) {
        SCOPED_TRACE(k.args);
        const RunResult r = bokehtool(k.args);
        expect_clean_failure(r, k.expected, out);
        EXPECT_NE(r.err.find("--defocus"), std::string::npos) << "names the command: " << r.err;
    }
    std::vector<std::string> files;
    OIIO::Filesystem::get_directory_entries(dir, files);
    EXPECT_TRUE(files.empty()) << "left behind: " << (files.empty() ? "" : files[0]);
}

TEST(CliDefocus, DiffPrintsPsnr)
{
    const std::string dir = fresh_dir("cli_defocus_diff");
    const RunResult r = bokehtool(format("{0} --defocus:focus=6:fstop=2:method=reference -o {1}/ref.exr "
                                         "{0} --defocus:focus=6:fstop=2:method=layers -o {1}/lay.exr --diff",
                                         kScene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const size_t at = r.out.find("PSNR");
    ASSERT_NE(at, std::string::npos) << r.out;
    // "PSNR 52.34 dB": the figure is a number, and layers are within the 40 dB budget.
    const double db = std::atof(r.out.c_str() + at + 5);
    std::printf("[ figures  ] --diff: %s", r.out.c_str());
    EXPECT_GE(db, 40.0) << r.out;
    // The same two files given by name.
    const RunResult f = bokehtool(format("{0}/ref.exr {0}/lay.exr --diff", dir));
    ASSERT_EQ(f.status, 0) << f.err;
    EXPECT_NE(f.out.find("PSNR"), std::string::npos) << f.out;
}

TEST(CliDefocus, LensCharacterSprites)
{
    // lens= switches lens character on; -v says how many sprites, their CoC range and time;
    // without any lens option the file is the plain defocus's.
    const std::string dir = fresh_dir("cli_defocus_lens");
    const RunResult r = bokehtool(format("-v {} --defocus:focus=6:fstop=2:lens=achromat:diffraction=exact:"
                                         "highlights=2 -o {}/lens.exr", kScene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("sprites"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("CoC"), std::string::npos) << r.out;
    ASSERT_EQ(bokehtool(format("{} --defocus:focus=6:fstop=2 -o {}/plain.exr", kScene, dir)).status, 0);
    OIIO::ImageBuf lens(dir + "/lens.exr"), plain(dir + "/plain.exr");
    EXPECT_GT(max_difference(lens, plain), 0.01) << "the highlights took the lens's shape";
    const std::string out = dir + "/bad.exr";
    expect_clean_failure(bokehtool(format("{} --defocus:lens=zoom -o {}", kScene, out)), "lens", out);
    expect_clean_failure(bokehtool(format("{} --defocus:highlights=0 -o {}", kScene, out)), "highlights", out);
    expect_clean_failure(bokehtool(format("{} --defocus:lens=achromat:method=gather -o {}", kScene, out)),
                         "gather", out);
}

// The CoC options, each against what it means, on the signed CoC map (output=coc) of the
// same frame: front= and back= multiply the CoC in front of and behind focus, maxcoc=
// clamps it, negate=1 on a negated depth gives the same map, range= makes depths
// within half of it of the focus sharp and moves the rest half of it toward the focus
// (so their blur shrinks), and zdilate= gives each pixel the nearest depth around it.
TEST(CliDefocus, CocOptionsDoWhatTheySay)
{
    const std::string dir = fresh_dir("cli_defocus_coc_options");
    RunResult r = bokehtool(format("--scene lights:width=192:height=108:aa=1 -o {}/scene.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    OIIO::ImageBuf scene(dir + "/scene.exr");
    ASSERT_TRUE(scene.read(0, 0, true, OIIO::TypeFloat));
    OIIO::ImageBuf negated = scene;
    const int zc           = scene.spec().channelindex("Z");
    for (int y = 0; y < 108; ++y)
        for (int x = 0; x < 192; ++x) {
            std::vector<float> px(size_t(scene.nchannels()));
            scene.getpixel(x, y, px.data());
            px[size_t(zc)] = -px[size_t(zc)];
            negated.setpixel(x, y, px.data());
        }
    ASSERT_TRUE(negated.write(dir + "/negated.exr", OIIO::TypeFloat));
    auto coc_map = [&](const std::string& in, const std::string& opts, const std::string& name) {
        RunResult run = bokehtool(format("{0}/{1} --defocus:focus=6:fstop=2:output=coc{2} -o {0}/{3}.exr", dir, in,
                                         opts, name));
        EXPECT_EQ(run.status, 0) << name << ": " << run.err;
        OIIO::ImageBuf map(dir + "/" + name + ".exr");
        EXPECT_TRUE(map.read(0, 0, true, OIIO::TypeFloat)) << name;
        return map;
    };
    const OIIO::ImageBuf base = coc_map("scene.exr", "", "base"), front = coc_map("scene.exr", ":front=2", "front"),
                         back = coc_map("scene.exr", ":back=0.5", "back"),
                         clamp = coc_map("scene.exr", ":maxcoc=2", "maxcoc"),
                         neg = coc_map("negated.exr", ":negate=1", "negate"),
                         range = coc_map("scene.exr", ":range=2", "range"),
                         dilated = coc_map("scene.exr", ":zdilate=3", "zdilate");
    int in_front = 0, behind = 0, clamped = 0, sharp = 0, moved = 0;
    for (int y = 0; y < 108; ++y)
        for (int x = 0; x < 192; ++x) {
            const float c = base.getchannel(x, y, 0, 0), z = scene.getchannel(x, y, 0, zc);
            EXPECT_FLOAT_EQ(front.getchannel(x, y, 0, 0), c < 0 ? 2.0f * c : c) << x << "," << y;
            EXPECT_FLOAT_EQ(back.getchannel(x, y, 0, 0), c > 0 ? 0.5f * c : c) << x << "," << y;
            EXPECT_FLOAT_EQ(clamp.getchannel(x, y, 0, 0), std::clamp(c, -2.0f, 2.0f)) << x << "," << y;
            EXPECT_EQ(neg.getchannel(x, y, 0, 0), c) << x << "," << y;
            const float rc = range.getchannel(x, y, 0, 0);
            if (std::abs(z - 6.0f) <= 1.0f) {
                EXPECT_EQ(rc, 0.0f) << x << "," << y << " at " << z << " m";
                sharp += 1;
            } else {
                EXPECT_LT(std::abs(rc), std::abs(c)) << x << "," << y << " at " << z << " m";
                EXPECT_EQ(rc < 0, c < 0) << x << "," << y;
                moved += 1;
            }
            in_front += c < 0;
            behind += c > 0;
            clamped += std::abs(c) > 2.0f;  // the post in front reaches -3.6 px at this width
        }
    // zdilate=3: each pixel takes the nearest depth (the smallest signed CoC) of the 7 x 7
    // pixels about it, the frame's edge cutting the square; brute force over the square.
    int grown = 0;
    for (int y = 0; y < 108; ++y)
        for (int x = 0; x < 192; ++x) {
            float nearest = base.getchannel(x, y, 0, 0);
            for (int j = std::max(0, y - 3); j <= std::min(107, y + 3); ++j)
                for (int i = std::max(0, x - 3); i <= std::min(191, x + 3); ++i)
                    nearest = std::min(nearest, base.getchannel(i, j, 0, 0));
            EXPECT_EQ(dilated.getchannel(x, y, 0, 0), nearest) << x << "," << y;
            grown += nearest < base.getchannel(x, y, 0, 0);
        }
    EXPECT_GT(grown, 100) << "the dilation moved edges";
    // The frame holds every case the checks tell apart.
    EXPECT_GT(in_front, 0);
    EXPECT_GT(behind, 0);
    EXPECT_GT(clamped, 0);
    EXPECT_GT(sharp, 0);
    EXPECT_GT(moved, 0);
}

// More options against what they mean: sensor= scales the CoC in pixels by the film back
// (CoC px = CoC mm x width px / sensor mm: half the back, twice the CoC); the reference
// makes a layer for each point of a step=-wide grid next to a pixel's CoC; sprites= caps the highlights
// drawn with the lens's PSF; supersample=2 doubles the output's pixels.
TEST(CliDefocus, SensorStepSpritesSupersample)
{
    const std::string dir = fresh_dir("cli_defocus_more_options");
    RunResult r = bokehtool(format("--scene lights:width=192:height=108:aa=1 -o {}/scene.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string scene = dir + "/scene.exr";
    auto read = [](const std::string& path) {
        OIIO::ImageBuf img(path);
        EXPECT_TRUE(img.read(0, 0, true, OIIO::TypeFloat)) << path;
        return img;
    };
    for (const char* back : { "36", "18" }) {
        r = bokehtool(format("{} --defocus:focus=6:fstop=2:sensor={}:output=coc -o {}/coc{}.exr", scene, back, dir, back));
        ASSERT_EQ(r.status, 0) << r.err;
    }
    const OIIO::ImageBuf full = read(dir + "/coc36.exr"), half = read(dir + "/coc18.exr");
    for (int y = 0; y < 108; y += 3)
        for (int x = 0; x < 192; x += 3) {
            const float c = full.getchannel(x, y, 0, 0);
            EXPECT_NEAR(half.getchannel(x, y, 0, 0), 2.0f * c, 1e-5f * (1.0f + std::abs(c))) << x << "," << y;
        }

    // The reference (a frame of more than 64 distinct CoCs): a layer for each point of the
    // grid of whole steps next to some pixel's CoC (the one at or below it, and the one
    // above unless the CoC lies on the grid), the outermost moved onto the frame's extreme
    // CoCs; counted here from the CoC map.
    auto occupied_bins = [&](double step) {
        double lo = 1e30, hi = -1e30;
        for (int y = 0; y < 108; ++y)
            for (int x = 0; x < 192; ++x) {
                lo = std::min(lo, double(full.getchannel(x, y, 0, 0)));
                hi = std::max(hi, double(full.getchannel(x, y, 0, 0)));
            }
        std::vector<double> points;
        for (int y = 0; y < 108; ++y)
            for (int x = 0; x < 192; ++x) {
                const double c = full.getchannel(x, y, 0, 0);
                points.push_back(std::clamp(std::floor(c / step) * step, lo, hi));
                points.push_back(std::clamp(std::ceil(c / step) * step, lo, hi));
            }
        std::sort(points.begin(), points.end());
        return int(std::unique(points.begin(), points.end()) - points.begin());
    };
    auto layers = [&](const char* step) {
        RunResult v = bokehtool(format("-v {} --defocus:focus=6:fstop=2:method=reference:step={} -o {}/ref.exr", scene,
                                       step, dir));
        EXPECT_EQ(v.status, 0) << v.err;
        const size_t at = v.out.find(" layers");
        const size_t from = v.out.rfind(' ', at - 1);
        return at == std::string::npos ? -1 : std::atoi(v.out.substr(from + 1, at - from - 1).c_str());
    };
    EXPECT_EQ(layers("1"), occupied_bins(1.0));
    EXPECT_EQ(layers("0.25"), occupied_bins(0.25));
    EXPECT_GT(occupied_bins(0.25), occupied_bins(1.0)) << "the steps tell the cases apart";

    // Lens character: at most sprites= highlights drawn; supersample=2 doubles the frame.
    r = bokehtool(format("-v {} --defocus:focus=6:fstop=2:lens=achromat:sprites=5 -o {}/few.exr", scene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const size_t s = r.out.find(" sprites (");
    ASSERT_NE(s, std::string::npos) << r.out;
    const int sprites = std::atoi(r.out.substr(r.out.rfind(' ', s - 1) + 1).c_str());
    EXPECT_GE(sprites, 1) << r.out;
    EXPECT_LE(sprites, 5) << r.out;
    r = bokehtool(format("{} --defocus:focus=6:fstop=2:lens=achromat:supersample=2 -o {}/ss.exr", scene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const OIIO::ImageBuf ss = read(dir + "/ss.exr");
    EXPECT_EQ(ss.spec().full_width, 2 * 192);
    EXPECT_EQ(ss.spec().full_height, 2 * 108);
}

// kernel=star is one aperture in every command: a white point on an opaque black plane at
// one depth, defocused with a star, is --blur's star at the CoC --defocus reports (behind
// focus), and the same star turned half a turn in front of focus (the rays cross before
// the sensor). Expected from --blur, whose star weights are checked against exact pixel
// areas (tests/aperture/kernel_area_test.cpp); the odd star's wrong orientation differs.
TEST(CliDefocus, EveryCommandDrawsTheSameStar)
{
    const std::string dir = fresh_dir("cli_defocus_star");
    constexpr int kN = 61;
    const std::string star = "kernel=star:blades=5:inner=0.4:rotation=10";
    for (const float depth : { 9.0f, 4.2f }) {  // behind and in front of focus at 6 m
        OIIO::ImageSpec spec(kN, kN, 5, OIIO::TypeFloat);
        spec.channelnames = { "R", "G", "B", "A", "Z" };
        spec.alpha_channel = 3;
        spec.z_channel     = 4;
        OIIO::ImageBuf plane(spec);
        for (int y = 0; y < kN; ++y)
            for (int x = 0; x < kN; ++x) {
                const float v    = x == kN / 2 && y == kN / 2 ? 1.0f : 0.0f;
                const float px[] = { v, v, v, 1.0f, depth };
                plane.setpixel(x, y, px);
            }
        const std::string in = format("{}/plane_{}.exr", dir, depth);
        ASSERT_TRUE(plane.write(in));
        const std::string lens = "focus=6:fstop=2:focal=50:sensor=0.3:method=layers:" + star;
        RunResult r = bokehtool(format("{} --defocus:{}:output=coc -o {}/coc.exr", in, lens, dir));
        ASSERT_EQ(r.status, 0) << r.err;
        OIIO::ImageBuf cocs(dir + "/coc.exr");
        ASSERT_TRUE(cocs.read(0, 0, true, OIIO::TypeFloat));
        const float coc = cocs.getchannel(kN / 2, kN / 2, 0, 0);
        ASSERT_GT(std::abs(coc), 12.0f) << depth;
        ASSERT_LT(std::abs(coc), 24.0f) << depth;  // under the reduced buffers' first size
        r = bokehtool(format("{} --defocus:{} -o {}/defocused.exr", in, lens, dir));
        ASSERT_EQ(r.status, 0) << r.err;
        auto blurred = [&](float rotation) {
            RunResult b = bokehtool(format("{} --blur:kernel=star:blades=5:inner=0.4:rotation={}:border=black {} -o "
                                           "{}/blur.exr",
                                           in, rotation, std::abs(coc), dir));
            EXPECT_EQ(b.status, 0) << b.err;
            OIIO::ImageBuf img(dir + "/blur.exr");
            EXPECT_TRUE(img.read(0, 0, true, OIIO::TypeFloat));
            return img;
        };
        OIIO::ImageBuf defocused(dir + "/defocused.exr");
        ASSERT_TRUE(defocused.read(0, 0, true, OIIO::TypeFloat));
        const OIIO::ImageBuf same = blurred(coc > 0 ? 10.0f : 190.0f), turned = blurred(coc > 0 ? 190.0f : 10.0f);
        double worst = 0.0, worst_turned = 0.0, peak = 0.0;
        for (int y = 0; y < kN; ++y)
            for (int x = 0; x < kN; ++x) {
                const double d = defocused.getchannel(x, y, 0, 0);
                peak           = std::max(peak, d);
                worst          = std::max(worst, std::abs(d - same.getchannel(x, y, 0, 0)));
                worst_turned   = std::max(worst_turned, std::abs(d - turned.getchannel(x, y, 0, 0)));
            }
        std::cout << "depth " << depth << " m, CoC " << coc << " px: peak " << peak << ", largest difference "
                  << worst << " (the star turned: " << worst_turned << ")\n";
        // One layer at one depth is the blur with the aperture at the CoC: float rounding.
        EXPECT_LT(worst, 1e-5 * peak + 1e-7) << depth;
        EXPECT_GT(worst_turned, 0.3 * peak) << depth;
    }
}
