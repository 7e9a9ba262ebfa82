// bokehtool --resize, --resample, --reduce, --enlarge and --lensdistort as a user runs them: the same
// pixels as the library functions, the sizes oiiotool's spellings give, and bad input.
#include <bokeh/distortion.h>
#include <bokeh/resample.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

// A float RGBA + Z image of 40 x 30 with a light, written to `dir`/in.exr.
std::string make_input(const std::string& dir, OIIO::ImageBuf& img)
{
    img = rgbaz_image(40, 30, [](int x, int y) {
        const float light = x == 13 && y == 11 ? 50.0f : 0.0f;
        return std::array<float, 5>{ 0.5f + 0.4f * std::sin(0.3f * x) + light, 0.02f * y, 0.3f, 1.0f,
                                     1.0f + float((x * 7 + y * 3) % 13) };
    });
    const std::string path = dir + "/in.exr";
    EXPECT_TRUE(img.write(path));
    return path;
}

OIIO::ImageBuf read(const std::string& path)
{
    OIIO::ImageBuf img(path);
    EXPECT_TRUE(img.read(0, 0, true, OIIO::TypeFloat)) << path << ": " << img.geterror();
    return img;
}

}  // namespace

TEST(CliResample, ResizeResampleReduceEnlargeGiveTheLibrarysPixels)
{
    const std::string dir = fresh_dir("cli_resample");
    OIIO::ImageBuf src;
    const std::string in = make_input(dir, src);
    const RunResult r = bokehtool(format(
        "{0} --resize:filter=catmull-rom 100x70 -o {1}/resize.exr "
        "{0} --resize 50% -o {1}/half.exr "
        "{0} --resize 80x0 -o {1}/aspect.exr "
        "{0} --resample 17x13 -o {1}/resample.exr "
        "{0} --resample:interp=0 17x13 -o {1}/nearest.exr "
        "{0} --reduce 4 -o {1}/reduce.exr "
        "{0} --reduce:z=nearest 4 -o {1}/reduce_nearest.exr "
        "{0} --enlarge:filter=upscale-blur 4 -o {1}/enlarge.exr "
        "{0} --enlarge:filter=lanczos3:clamp=1 2.5 -o {1}/clamped.exr "
        "{0} --reduce 8 --enlarge:filter=gaussian 8 -o {1}/roundtrip.exr",
        in, dir));
    ASSERT_EQ(r.status, 0) << r.err;

    auto expect_same = [&](const std::string& name, const OIIO::ImageBuf& want) {
        SCOPED_TRACE(name);
        const OIIO::ImageBuf got = read(dir + "/" + name);
        EXPECT_EQ(got.roi(), want.roi());
        EXPECT_EQ(got.roi_full(), want.roi_full());
        EXPECT_EQ(max_difference(got, want), 0.0);
    };
    bokeh::ResampleOptions cr;
    cr.filter = bokeh::ResampleFilter::CatmullRom;
    OIIO::ImageBuf want;
    ASSERT_TRUE(bokeh::resize(want, src, 100, 70, cr));
    expect_same("resize.exr", want);
    bokeh::ResampleOptions l3;
    l3.filter = bokeh::ResampleFilter::Lanczos3;  // --resize's default, as oiiotool reducing
    ASSERT_TRUE(bokeh::resize(want, src, 20, 15, l3));
    expect_same("half.exr", want);
    ASSERT_TRUE(bokeh::resize(want, src, 80, 60, l3));
    expect_same("aspect.exr", want);
    ASSERT_TRUE(bokeh::resample(want, src, 17, 13, true));
    expect_same("resample.exr", want);
    ASSERT_TRUE(bokeh::resample(want, src, 17, 13, false));
    expect_same("nearest.exr", want);
    ASSERT_TRUE(bokeh::reduce(want, src, 4));
    expect_same("reduce.exr", want);
    bokeh::ReduceOptions nearest;
    nearest.depth = bokeh::Reducer::NearestDepth;
    ASSERT_TRUE(bokeh::reduce(want, src, 4, nearest));
    expect_same("reduce_nearest.exr", want);
    bokeh::ResampleOptions ub;
    ub.filter = bokeh::ResampleFilter::UpscaleBlur;
    ASSERT_TRUE(bokeh::enlarge(want, src, 4, ub));
    expect_same("enlarge.exr", want);
    l3.clamp_negative = true;
    ASSERT_TRUE(bokeh::enlarge(want, src, 2.5, l3));
    expect_same("clamped.exr", want);
    EXPECT_GE(OIIO::ImageBufAlgo::computePixelStats(want).min[0], 0.0f) << "the light would ring below 0";

    // Sizes: 30 rows reduced by 8 are 4 blocks, enlarged back 32 rows (crop to return to 30).
    const OIIO::ImageBuf round = read(dir + "/roundtrip.exr");
    EXPECT_EQ(round.roi(), OIIO::ROI(0, 40, 0, 32, 0, 1, 0, 5));
    // Depth by min by default: the reduced Z is the smallest of each block.
    const OIIO::ImageBuf reduced = read(dir + "/reduce.exr");
    EXPECT_EQ(reduced.spec().channelnames, src.spec().channelnames);
    float lowest = 1e9f;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x)
            lowest = std::min(lowest, src.getchannel(x, y, 0, 4));
    EXPECT_EQ(reduced.getchannel(0, 0, 0, 4), lowest);
}

namespace {

// An impulse of 1 at (10, 10) in a black 21 x 21 frame, enlarged 2x by bokehtool with
// `filter`; the output's row through the impulse summed over y (the separable response
// along x times its sum along y).
std::vector<double> enlarged_impulse_row(const std::string& dir, const std::string& filter)
{
    OIIO::ImageBuf impulse(OIIO::ImageSpec(21, 21, 1, OIIO::TypeFloat));
    const float one = 1.0f;
    impulse.setpixel(10, 10, &one);
    const std::string in = dir + "/impulse.exr", out = dir + "/" + filter + ".exr";
    EXPECT_TRUE(impulse.write(in));
    const RunResult r = bokehtool(format("{} --enlarge:border=black:filter={} 2 -o {}", in,
                                         OIIO::Strutil::replace(filter, "_", ":"), out));
    EXPECT_EQ(r.status, 0) << r.err;
    OIIO::ImageBuf img(out);
    EXPECT_TRUE(img.read(0, 0, true, OIIO::TypeFloat)) << img.geterror();
    EXPECT_EQ(img.spec().width, 42);
    std::vector<double> row(42, 0.0);
    for (int y = 0; y < img.spec().height; ++y)
        for (int x = 0; x < 42; ++x)
            row[size_t(x)] += img.getchannel(x, y, 0, 0);
    return row;
}

double tent(double u) { return std::max(0.0, 1.0 - std::abs(u)); }

}  // namespace

TEST(CliResample, BlurAndOffsetOfTheEnlargementsDoWhatTheySay)
{
    // Output pixel j of a 2x enlargement sits at source coordinate u_j = (j + 0.5) / 2 -
    // 0.5 (the centres --resize places).
    const std::string dir = fresh_dir("cli_enlarge_blur_offset");
    auto u = [](int j) { return (j + 0.5) / 2.0 - 0.5 - 10.0; };  // from the impulse
    // upscale-blur-fused:offset=d: each output pixel the mean of two bilinear reads d
    // source pixels either side, so the impulse's weight is (tent(u - d) + tent(u + d)) / 2
    // along each axis (its sum along y is the sum of the same over y: 2, a whole tent
    // sampled at half-pixel steps). Exact up to float rounding.
    for (double d : { 0.3, 0.8 }) {
        const std::vector<double> row = enlarged_impulse_row(dir, format("upscale-blur-fused_offset={}", d));
        double worst = 0.0;
        for (int j = 0; j < 42; ++j)
            worst = std::max(worst, std::abs(row[size_t(j)] - 2.0 * 0.5 * (tent(u(j) - d) + tent(u(j) + d))));
        EXPECT_LT(worst, 1e-6) << "offset " << d;
    }
    // reduced-blur:blur=s: a Gaussian of sigma s at the source's resolution, then the
    // enlargement. Variances add under convolution, so the response's variance grows by
    // 2^2 (s2^2 - s1^2) output px^2 from s1 to s2, whatever the rest of the chain adds
    // (0.1 % : the Gaussian's tails past 4 sigma); its energy is 2 x 2 (a mean is kept).
    auto moments = [](const std::vector<double>& row, double& energy, double& variance) {
        double mean = 0.0;
        energy      = 0.0;
        for (size_t j = 0; j < row.size(); ++j) {
            energy += row[j];
            mean += row[j] * double(j);
        }
        mean /= energy;
        variance = 0.0;
        for (size_t j = 0; j < row.size(); ++j)
            variance += row[j] * (double(j) - mean) * (double(j) - mean) / energy;
    };
    double e1 = 0.0, v1 = 0.0, e2 = 0.0, v2 = 0.0;
    moments(enlarged_impulse_row(dir, "reduced-blur_blur=1"), e1, v1);
    moments(enlarged_impulse_row(dir, "reduced-blur_blur=2"), e2, v2);
    EXPECT_NEAR(e1, 4.0, 1e-5);
    EXPECT_NEAR(e2, 4.0, 1e-5);
    EXPECT_NEAR(v2 - v1, 4.0 * (4.0 - 1.0), 0.001 * 12.0);
}

TEST(CliResample, HelpNamesTheFilters)
{
    const RunResult r = bokehtool("--help --enlarge");
    ASSERT_EQ(r.status, 0) << r.err;
    for (const char* s : { "upscale-blur-fused", "lanczos2", "bspline", ":clamp=", "bokeh_resample.so" })
        EXPECT_NE(r.out.find(s), std::string::npos) << s << " in:\n" << r.out;
    const RunResult z = bokehtool("--help --reduce");
    EXPECT_NE(z.out.find(":z="), std::string::npos) << z.out;
}

TEST(CliResample, BadInputFailsCleanly)
{
    const std::string dir = fresh_dir("cli_resample_bad");
    OIIO::ImageBuf src;
    const std::string in  = make_input(dir, src);
    const std::string out = dir + "/out.exr";
    struct Case {
        std::string args, expected;
    };
    const Case cases[] = {
        { "--resize 12x", "--resize: '12x' is not a size (WxH, N% or Wx0)" },
        { "--resize 0x0", "'0x0' is not a size" },
        { "--resize -5%", "'-5%' is not a size" },
        { "--resize 10.5x4", "'10.5x4' is not a size" },
        { "--resize:filter=sinc 10x10", "--resize: option 'filter' = 'sinc' is not one of" },
        { "--resize:filter=upscale-blur 10x10", "--resize: filter upscale-blur only enlarges" },
        { "--resample 5", "--resample: '5' is not a size" },
        { "--resample:interp=2 5x5", "option 'interp' = 2 is out of range [0, 1]" },
        { "--reduce 0", "--reduce: '0' is not a reduction factor (a whole number 1..4096)" },
        { "--reduce 2.5", "'2.5' is not a reduction factor" },
        { "--reduce:z=median 2", "--reduce: option 'z' = 'median' is not one of: min, max, nearest, mean" },
        { "--enlarge abc", "--enlarge: 'abc' is not a factor (a number >= 1)" },
        { "--enlarge 0.5", "--enlarge: factor 0.5 is outside 1..256 (to reduce, use reduce or resize)" },
        { "--enlarge:sigma=-1 2", "option 'sigma' = -1 is out of range" },
        { "--enlarge", "--enlarge" },
        { "--lensdistort:k1=-3", "--lensdistort: lens distortion: k1 -3 and k2 0 fold the polynomial mapping over "
                                 "itself at 0.334 of the half-diagonal" },
        { "--lensdistort:k1=20", "--lensdistort: option 'k1' = 20 is out of range [-10, 10]" },
        { "--lensdistort:lateralr=0.01:output=stmap", "an STMap holds one source position a pixel" },
        { "--lensdistort:model=fisheye", "option 'model' = 'fisheye' is not one of: polynomial, division" },
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.args);
        expect_clean_failure(bokehtool(in + " " + c.args + " -o " + out), c.expected, out);
    }
    const std::string deep = shared_data("openexr-images/LowResLeftView_Balls.exr");
    if (!deep.empty()) {
        expect_clean_failure(bokehtool(deep + " --enlarge 2 -o " + out),
                             "deep images cannot be resampled; flatten them first", out);
        expect_clean_failure(bokehtool(deep + " --lensdistort:k1=0.1 -o " + out),
                             "a deep image cannot be warped; flatten it first", out);
    }
}

TEST(CliResample, LensDistortGivesTheLibrarysPixelsAndItsStmap)
{
    const std::string dir = fresh_dir("cli_lensdistort");
    OIIO::ImageBuf src;
    const std::string in = make_input(dir, src);
    ASSERT_EQ(bokehtool(format("{} --lensdistort:k1=-0.1:k2=0.02:lateralr=0.003 -o {}/d.exr", in, dir)).status, 0);
    ASSERT_EQ(bokehtool(format("{} --lensdistort:k1=-0.1:k2=0.02:output=stmap -o {}/st.exr", in, dir)).status, 0);
    bokeh::LensDistortion l;
    l.k1 = -0.1, l.k2 = 0.02, l.lateral_r = 0.003;
    OIIO::ImageBuf want;
    ASSERT_TRUE(bokeh::lens_distort(want, src, l, bokeh::DistortDirection::Distort)) << want.geterror();
    EXPECT_EQ(max_difference(read(dir + "/d.exr"), want), 0.0);
    const OIIO::ImageBuf st = read(dir + "/st.exr");
    EXPECT_EQ(st.spec().channelnames, (std::vector<std::string>{ "R", "G" }));
    EXPECT_EQ(st.roi().width(), 40);
}

TEST(CliResample, DepthAwareEnlargeGivesTheLibrarysPixels)
{
    // A full-resolution frame (a near square at Z 2 over a wall at Z 10) and a layer at a
    // quarter of its resolution at Z 5: PCF hides the layer behind the square with the
    // square's own edges; bilateral enlarges it without hiding it.
    const std::string dir = fresh_dir("cli_enlarge_depthaware");
    const OIIO::ImageBuf full = rgbaz_image(64, 48, [](int x, int y) {
        const bool near = x >= 20 && x < 40 && y >= 12 && y < 30;
        return std::array<float, 5>{ 0.2f, 0.3f, 0.4f, 1.0f, near ? 2.0f : 10.0f };
    });
    const OIIO::ImageBuf low = rgbaz_image(16, 12, [](int x, int y) {
        return std::array<float, 5>{ 1.0f + 0.1f * float(x), 0.5f, 0.25f, 1.0f, 5.0f + 0.0f * float(y) };
    });
    ASSERT_TRUE(full.write(dir + "/full.exr") && low.write(dir + "/low.exr"));
    for (const auto& [name, method] : { std::make_pair("pcf", bokeh::DepthAwareMethod::PCF),
                                        std::make_pair("bilateral", bokeh::DepthAwareMethod::JointBilateral) }) {
        SCOPED_TRACE(name);
        const RunResult r = bokehtool(format("{0}/full.exr {0}/low.exr --enlarge:depthaware={1} 4 -o {0}/{1}.exr", dir, name));
        ASSERT_EQ(r.status, 0) << r.err;
        bokeh::DepthAwareOptions o;
        o.method = method;
        OIIO::ImageBuf want;
        ASSERT_TRUE(bokeh::enlarge_depth_aware(want, low, full, 4.0, o)) << want.geterror();
        const OIIO::ImageBuf got = read(format("{}/{}.exr", dir, name));
        EXPECT_EQ(max_difference(got, want), 0.0);
        // Inside the near square PCF leaves nothing of the layer (it lies behind), outside all of it.
        if (method == bokeh::DepthAwareMethod::PCF) {
            EXPECT_EQ(got.getchannel(30, 20, 0, 3), 0.0f);
            EXPECT_EQ(got.getchannel(5, 5, 0, 3), 1.0f);
        } else {
            EXPECT_EQ(got.getchannel(30, 20, 0, 3), 1.0f);
        }
    }
    const std::string out = dir + "/bad.exr";
    expect_clean_failure(bokehtool(format("{}/low.exr --enlarge:depthaware=pcf 4 -o {}", dir, out)),
                         "--enlarge: needs 2 image(s) on the stack but 1 is there", out);
    expect_clean_failure(bokehtool(format("{0}/full.exr {0}/low.exr --enlarge:depthaware=pcf:filter=bspline 4 -o {1}",
                                          dir, out)),
                         "filter= is for the filtered enlargement; depthaware= samples by depth", out);
    expect_clean_failure(bokehtool(format("{0}/low.exr --enlarge:tolerance=0.1 4 -o {1}", dir, out)),
                         "tolerance= is for depthaware=pcf|bilateral", out);
}
