// bokehtool --bokeh as a user runs it: a PSF centred on (0, 0) summing to 1 per channel,
// usable as --convolve's kernel; the sheet and the beam map; bad lens values refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

TEST(CliBokeh, PsfCentredWithUnitEnergy)
{
    const std::string dir = fresh_dir("cli_bokeh_psf");
    const RunResult r = bokehtool(format(
        "-v --bokeh:lens=achromat:fstop=1.4:diffraction=exact:kernel=polygon:blades=7:field=0.5,0.2 -41 -o {}/psf.exr",
        dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("achromat lens, 7 blades"), std::string::npos) << r.out;
    OIIO::ImageBuf psf(dir + "/psf.exr");
    ASSERT_TRUE(psf.read(0, 0, true, OIIO::TypeFloat)) << psf.geterror();
    const OIIO::ImageSpec& s = psf.spec();
    EXPECT_EQ(s.nchannels, 3);
    EXPECT_EQ(s.width % 2, 1);
    EXPECT_EQ(s.x, -(s.width / 2));
    EXPECT_EQ(s.y, -(s.height / 2));
    double sum[3] = { 0, 0, 0 };
    for (int y = s.y; y < s.y + s.height; ++y)
        for (int x = s.x; x < s.x + s.width; ++x) {
            float px[3];
            psf.getpixel(x, y, px);
            for (int c = 0; c < 3; ++c)
                sum[c] += px[c];
        }
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(sum[c], 1.0, 1e-5) << "channel " << c;

    // As a convolution kernel: a lone light becomes the PSF, scaled by the light and
    // centred on it (out(x + d) = 100 psf(d)), its energy kept.
    OIIO::ImageBuf light(OIIO::ImageSpec(160, 120, 3, OIIO::TypeFloat));
    const float hundred[3] = { 100.0f, 100.0f, 100.0f };
    light.setpixel(80, 60, hundred);
    ASSERT_TRUE(light.write(dir + "/light.exr"));
    const RunResult conv = bokehtool(format("{0}/light.exr {0}/psf.exr --convolve:border=black -o {0}/conv.exr", dir));
    ASSERT_EQ(conv.status, 0) << conv.err;
    OIIO::ImageBuf out(dir + "/conv.exr");
    ASSERT_TRUE(out.read(0, 0, true, OIIO::TypeFloat)) << out.geterror();
    double energy[3] = { 0, 0, 0 }, worst = 0.0;
    for (int y = 0; y < 120; ++y)
        for (int x = 0; x < 160; ++x) {
            float got[3], want[3] = { 0, 0, 0 };
            out.getpixel(x, y, got);
            const int dx = x - 80, dy = y - 60;
            if (dx >= s.x && dx < s.x + s.width && dy >= s.y && dy < s.y + s.height)
                psf.getpixel(dx, dy, want);
            for (int c = 0; c < 3; ++c) {
                energy[c] += got[c];
                worst = std::max(worst, double(std::abs(got[c] - 100.0f * want[c])));
            }
        }
    ASSERT_LT(s.width, 160) << "the PSF fits inside the frame, so all its energy is there";
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(energy[c], 100.0, 1e-3) << "channel " << c;
    EXPECT_LT(worst, 1e-4) << "the output is the PSF, scaled and moved to the light";
}

TEST(CliBokeh, SheetStarPictureAndBeamMap)
{
    const std::string dir = fresh_dir("cli_bokeh_sheet");
    RunResult r = bokehtool(format("--bokeh:sheet=1:columns=3:rows=2:size=41:lens=uncorrected:catseye=0.5 30 -o {}/sheet.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    OIIO::ImageBuf sheet(dir + "/sheet.exr");
    ASSERT_TRUE(sheet.read(0, 0, true, OIIO::TypeFloat)) << sheet.geterror();
    EXPECT_EQ(sheet.spec().width, 3 * 41);
    EXPECT_EQ(sheet.spec().height, 2 * 41);

    r = bokehtool(format("--bokeh:kernel=star:blades=5:inner=0.4:rotation=10 40 -o {}/star.exr", dir));
    EXPECT_EQ(r.status, 0) << r.err;
    // A picture aperture from the stack: the star PSF itself, read back as an aperture.
    r = bokehtool(format("-v {}/star.exr --bokeh:kernel=image 60 -o {}/from_picture.exr", dir, dir));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("picture aperture"), std::string::npos) << r.out;

    r = bokehtool(format("--bokeh:map=1:lens=achromat 40 -o {}/map.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    OIIO::ImageBuf map(dir + "/map.exr");
    ASSERT_TRUE(map.read(0, 0, true, OIIO::TypeFloat));
    EXPECT_EQ(map.spec().width, 512);
    EXPECT_EQ(map.spec().height, 256);
}

TEST(CliBokeh, BadLensValuesFailCleanly)
{
    const std::string dir = fresh_dir("cli_bokeh_bad");
    const std::string out = dir + "/x.exr";
    const std::pair<std::string, std::string> cases[] = {
        { "--bokeh:fstop=-1 64", "fstop" },
        { "--bokeh:correction=5 64", "correction" },
        { "--bokeh:lens=achromat:wavelengths=700-400 64", "wavelength range" },
        { "--bokeh:wavelengths=blue 64", "wavelengths" },
        { "--bokeh:kernel=disk:blades=5 64", "blades does not apply" },
        { "--bokeh:inner=0.3 64", "inner does not apply" },
        { "--bokeh:field=2,2 64", "field position" },
        { "--bokeh:field=left 64", "field" },
        { "--bokeh big", "not a signed CoC" },
        { "--bokeh 9000", "coc" },
        { "--bokeh:lens=fisheye 64", "lens" },
        { "--bokeh:sheet=1:size=20 64", "under the cell size" },
    };
    for (const auto& [args, what] : cases) {
        SCOPED_TRACE(args);
        expect_clean_failure(bokehtool(format("{} -o {}", args, out)), what, out);
    }
}
