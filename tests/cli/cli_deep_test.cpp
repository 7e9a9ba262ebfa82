// The deep commands as a user runs them: oiiotool's spellings, the deep defocus, and bad
// input (one line, exit 1, nothing written).
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

#include <bokeh/deep.h>
#include <bokeh/io.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

// A small deep file with a volume, a point and, at one pixel, a bad sample of `kind`.
std::string write_deep(const std::string& dir, const std::string& name, const std::string& kind = "")
{
    const DeepPixel px = { { 0.2f, 0.1f, 0.0f, 0.4f, 2.0f, 4.0f }, { 0.0f, 0.3f, 0.6f, 1.0f, 3.0f, 3.0f } };
    OIIO::ImageBuf buf  = make_deep(8, 6, std::vector<DeepPixel>(48, px), true);
    OIIO::DeepData& dd  = *buf.deepdata();
    if (kind == "nan")
        dd.set_deep_value(9, 4, 0, NAN);
    else if (kind == "back")
        dd.set_deep_value(9, 5, 1, 1.0f);
    const std::string path = dir + "/" + name;
    std::string err;
    EXPECT_TRUE(bokeh::write_image(buf, path, {}, err)) << err;
    return path;
}

}  // namespace

TEST(CliDeep, OiiotoolSpellingsWork)
{
    const std::string dir = fresh_dir("cli_deep_spellings");
    const std::string a   = write_deep(dir, "a.exr");
    RunResult r = bokehtool(format("{} --deeptidy -o {}/tidy.exr", a, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{} {} {} --deepmerge:n=3 -o {}/m.exr --flatten -o {}/flat.exr", a, a, a, dir, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{} {} --deepholdout -o {}/h.exr", a, a, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{} --deepslice 2.5 inf -o {}/s.exr", a, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{}/flat.exr --deepen -o {}/deepened.exr", dir, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    std::string err;
    OIIO::ImageBuf m, flat, tidy;
    ASSERT_TRUE(bokeh::read_image(m, dir + "/m.exr", err)) << err;
    ASSERT_TRUE(m.deep());
    EXPECT_EQ(m.deepdata()->channeltype(0), OIIO::TypeHalf) << "half colour stays half";
    EXPECT_EQ(m.deepdata()->channeltype(4), OIIO::TypeFloat);
    ASSERT_TRUE(bokeh::read_image(flat, dir + "/flat.exr", err)) << err;
    EXPECT_FALSE(flat.deep());
    ASSERT_TRUE(bokeh::read_image(tidy, dir + "/tidy.exr", err)) << err;
    // The volume [2, 4) is cut at the point at 3: three samples a pixel.
    EXPECT_EQ(tidy.deepdata()->samples(0), 3);
}

TEST(CliDeep, DeepDefocusFlatAndDeepOut)
{
    const std::string dir = fresh_dir("cli_deep_defocus");
    const std::string a   = write_deep(dir, "a.exr");
    RunResult r = bokehtool(format("-v {} --defocus:math=direct:scale=3:method=reference -o {}/flat.exr", a, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("deep reference"), std::string::npos) << r.out;
    r = bokehtool(format("{} --defocus:math=direct:scale=3:method=reference:output=deep -o {}/deep.exr "
                         "--flatten --ch R,G,B,A {}/flat.exr --diff:fail=80",
                         a, dir, dir));
    ASSERT_EQ(r.status, 0) << r.err << r.out;
    std::string err;
    OIIO::ImageBuf d;
    ASSERT_TRUE(bokeh::read_image(d, dir + "/deep.exr", err)) << err;
    EXPECT_TRUE(d.deep());
    // The thin-lens truth of the same image: it reports its noise, and it agrees with the
    // deep reference to within what its noise and the layers' sharing allow.
    // (Nothing past the frame, as the rays see it: border=black; measured 41.5 dB at 1024 spp.)
    r = bokehtool(format("-v {} --defocus:math=direct:scale=3:method=reference:border=black {} "
                         "--defocus:math=direct:scale=3:method=truth:spp=256 -o {}/truth.exr --diff:fail=35",
                         a, a, dir));
    ASSERT_EQ(r.status, 0) << r.err << r.out;
    EXPECT_NE(r.out.find("defocus truth"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("noise"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("from the pixel's centre"), std::string::npos) << r.out;  // the default start
    expect_clean_failure(bokehtool(format("--scene lights:width=32:height=18 --defocus:method=truth -o {}/t.exr", dir)),
                         "deep", dir + "/t.exr");
    expect_clean_failure(bokehtool(format("{} --defocus:spp=16 -o {}/t.exr", a, dir)), "spp", dir + "/t.exr");
    expect_clean_failure(bokehtool(format("{} --defocus:unknown=1 -o {}/t.exr", a, dir)), "unknown", dir + "/t.exr");
    expect_clean_failure(bokehtool(format("{} --defocus:pixel=area -o {}/t.exr", a, dir)), "pixel", dir + "/t.exr");
    // pixel=area: the rays start over each pixel's square (the default, its centre).
    r = bokehtool(format("-v {} --defocus:math=direct:scale=3:method=truth:spp=16:pixel=area -o {}/area.exr", a, dir));
    ASSERT_EQ(r.status, 0) << r.err << r.out;
    EXPECT_NE(r.out.find("from the pixel's area"), std::string::npos) << r.out;
    // unknown=1: a fifth channel, the share of each pixel's rays that crossed what the file
    // does not record.
    r = bokehtool(format("{} --defocus:math=direct:scale=3:method=truth:spp=16:unknown=1 -o {}/unknown.exr", a, dir));
    ASSERT_EQ(r.status, 0) << r.err << r.out;
    OIIO::ImageBuf u;
    ASSERT_TRUE(bokeh::read_image(u, dir + "/unknown.exr", err)) << err;
    ASSERT_EQ(u.nchannels(), 5);
    EXPECT_EQ(u.spec().channel_name(4), "unknown");
    expect_clean_failure(bokehtool(format("{} --defocus:method=truth:bloom=2 -o {}/t.exr", a, dir)), "bloom",
                         dir + "/t.exr");
}

// --progress: a long command's progress on stderr, rising to 100 %, nothing on stdout and
// nothing without the flag; the output the same with and without it.
TEST(CliDeep, ProgressOfLongCommands)
{
    const std::string dir = fresh_dir("cli_deep_progress");
    const std::string a   = write_deep(dir, "a.exr");
    // The lines of `text` that report progress of `command` ("--defocus: 37% (0.2 s)").
    auto progress_lines = [](const std::string& text, const std::string& command) {
        std::vector<int> percents;
        for (const std::string& line : OIIO::Strutil::splits(text, "\n")) {
            if (!OIIO::Strutil::starts_with(line, command + ": "))
                continue;
            const size_t pct = line.find("% (");
            EXPECT_NE(pct, std::string::npos) << line;
            EXPECT_TRUE(OIIO::Strutil::ends_with(line, " s)")) << line;
            if (pct != std::string::npos)
                percents.push_back(std::stoi(line.substr(command.size() + 2, pct - command.size() - 2)));
        }
        return percents;
    };
    auto same_pixels = [](const std::string& p, const std::string& q) {
        OIIO::ImageBuf x(p), y(q);
        if (!x.read(0, 0, true, OIIO::TypeFloat) || !y.read(0, 0, true, OIIO::TypeFloat) || x.roi() != y.roi()
            || x.nchannels() != y.nchannels())
            return false;
        std::vector<float> vx(size_t(x.spec().image_pixels()) * size_t(x.nchannels())), vy(vx.size());
        return x.get_pixels(x.roi(), OIIO::TypeFloat, vx.data()) && y.get_pixels(y.roi(), OIIO::TypeFloat, vy.data())
               && vx == vy;
    };
    const std::vector<std::pair<std::string, std::string>> runs = {
        { "truth", format("{} --defocus:math=direct:scale=3:method=truth:spp=256", a) },
        { "reference", format("{} --defocus:math=direct:scale=3:method=reference", a) },
        { "blur", "--scene lights:width=96:height=54 --blur:method=reference 31" },
    };
    for (const auto& [name, line] : runs) {
        const std::string command = name == "blur" ? "--blur" : "--defocus";
        RunResult on = bokehtool(format("--progress:interval=0 {} -o {}/{}_on.exr", line, dir, name));
        ASSERT_EQ(on.status, 0) << name << ": " << on.err;
        const std::vector<int> shown = progress_lines(on.err, command);
        ASSERT_GE(shown.size(), 2u) << name << ": a line per percent with interval=0: " << on.err;
        EXPECT_TRUE(std::is_sorted(shown.begin(), shown.end())) << name << ": " << on.err;
        EXPECT_EQ(std::adjacent_find(shown.begin(), shown.end()), shown.end()) << name << ": no percent twice";
        EXPECT_EQ(shown.back(), 100) << name << ": " << on.err;
        EXPECT_TRUE(progress_lines(on.out, command).empty()) << name << ": progress stays off stdout: " << on.out;

        RunResult off = bokehtool(format("{} -o {}/{}_off.exr", line, dir, name));
        ASSERT_EQ(off.status, 0) << name << ": " << off.err;
        EXPECT_TRUE(progress_lines(off.err, command).empty()) << name << ": " << off.err;
        EXPECT_TRUE(same_pixels(format("{}/{}_on.exr", dir, name), format("{}/{}_off.exr", dir, name)))
            << name << ": the output does not depend on --progress";

        // -q silences it; the default interval (1 s) prints nothing for a command this short.
        RunResult quiet = bokehtool(format("-q --progress:interval=0 {} -o {}/{}_q.exr", line, dir, name));
        ASSERT_EQ(quiet.status, 0) << quiet.err;
        EXPECT_TRUE(progress_lines(quiet.err, command).empty()) << name << ": " << quiet.err;
    }
    RunResult brief = bokehtool(format("--progress {} --defocus:math=direct:scale=3 -o {}/brief.exr", a, dir));
    ASSERT_EQ(brief.status, 0) << brief.err;
    EXPECT_TRUE(progress_lines(brief.err, "--defocus").empty()) << "under a second, no line: " << brief.err;
    expect_clean_failure(bokehtool(format("--progress:interval=-1 {} --deeptidy -o {}/t.exr", a, dir)), "interval",
                         dir + "/t.exr");
}

TEST(CliDeep, BadInputFailsCleanly)
{
    const std::string dir = fresh_dir("cli_deep_bad");
    const std::string out = dir + "/out.exr";
    // A flat image given to a deep-only command.
    expect_clean_failure(bokehtool(format("--scene lights:width=32:height=18 --deeptidy -o {}", out)),
                         "flat", out);
    expect_clean_failure(bokehtool(format("--scene lights:width=32:height=18 --flatten -o {}", out)), "flat", out);
    // A deep image without Z.
    {
        OIIO::ImageSpec spec(4, 4, 2, OIIO::TypeFloat);
        spec.channelnames = { "R", "A" };
        spec.deep         = true;
        OIIO::ImageBuf noz(spec);
        std::string err;
        ASSERT_TRUE(bokeh::write_image(noz, dir + "/noz.exr", {}, err)) << err;
        expect_clean_failure(bokehtool(format("{}/noz.exr --flatten -o {}", dir, out)), "no Z channel", out);
    }
    // NaN depth and ZBack < Z: repaired and warned by default, refused under error.
    for (const char* kind : { "nan", "back" }) {
        const std::string bad = write_deep(dir, format("{}.exr", kind), kind);
        RunResult r           = bokehtool(format("{} --deeptidy -o {}", bad, out));
        ASSERT_EQ(r.status, 0) << r.err;
        EXPECT_NE((r.out + r.err).find("repaired"), std::string::npos) << kind << ": " << r.out << r.err;
        std::remove(out.c_str());
        // Strict everywhere: the read refuses the NaN, the command the ZBack < Z sample.
        expect_clean_failure(bokehtool(format("--nan:policy=error {} --deeptidy:nonfinite=error -o {}", bad, out)),
                             std::string(kind) == "nan" ? "non-finite" : "pixel (1, 1) has a sample with ZBack 1 < Z 3",
                             out);
    }
    // Merges of images with other channels; an empty slice; the gather method.
    const std::string a = write_deep(dir, "a.exr");
    expect_clean_failure(bokehtool(format("{} --ch R,A,Z {} --deepmerge -o {}", a, a, out)), "channel", out);
    expect_clean_failure(bokehtool(format("{} --deepslice 5 5 -o {}", a, out)), "empty", out);
    expect_clean_failure(bokehtool(format("{} --deepslice near 5 -o {}", a, out)), "NEAR", out);
    expect_clean_failure(bokehtool(format("{} --defocus:method=gather -o {}", a, out)), "gather", out);
    expect_clean_failure(bokehtool(format("{} --defocus:views=2:output=deep -o {}", a, out)),
                         "a deep result keeps one sample a layer", out);
    expect_clean_failure(bokehtool(format("{} --defocus:views=9 -o {}", a, out)), "views", out);
    expect_clean_failure(bokehtool(format("{} --defocus:views=2:output=coc -o {}", a, out)),
                         "views= composites the layers per sub-aperture; output=coc", out);
    expect_clean_failure(bokehtool(format("{} --defocus:method=truth:views=2 -o {}", a, out)),
                         "views= does not apply to method=truth", out);
    expect_clean_failure(bokehtool(format("--scene lights:width=32:height=18 --defocus:output=deep -o {}", out)),
                         "deep", out);
}
