// bokehtool --bokeh as a user runs it: a PSF centred on (0, 0) summing to 1 per channel,
// usable as --convolve's kernel; the sheet and the beam map; bad lens values refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

#include <bokeh/lens_fit.h>

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

namespace {

// A 480 x 270 plate (display window 1920 x 1080 at (600, 300), as a crop of a frame
// keeps it) holding three highlights of one lens, rendered by bokeh::synthetic_crop at a
// peak SNR of 60 and pasted at (120, 100), (300, 90), (380, 200) of the plate.
std::string write_fit_plate(const std::string& dir, const bokeh::LensCharacter& lens)
{
    OIIO::ImageSpec spec(480, 270, 3, OIIO::TypeFloat);
    spec.x = 600, spec.y = 300, spec.full_x = 0, spec.full_y = 0, spec.full_width = 1920, spec.full_height = 1080;
    OIIO::ImageBuf plate(spec);
    const float bg[3] = { 0.05f, 0.06f, 0.08f };
    OIIO::ImageBufAlgo::fill(plate, { bg[0], bg[1], bg[2] });
    const int at[3][2] = { { 120, 100 }, { 300, 90 }, { 380, 200 } };
    for (int i = 0; i < 3; ++i) {
        bokeh::SyntheticCrop c;
        c.size_px  = 81;
        c.coc_px   = 34.0 + 4.0 * i;
        c.peak_snr = 60.0;
        c.seed     = unsigned(7 + i);
        bokeh::LensFitCrop crop;
        std::string err;
        EXPECT_TRUE(bokeh::synthetic_crop(crop, lens, c, err)) << err;
        for (int y = 0; y < 81; ++y)
            for (int x = 0; x < 81; ++x) {
                float v[3];
                crop.image.getpixel(x, y, v);
                plate.setpixel(600 + at[i][0] - 40 + x, 300 + at[i][1] - 40 + y, v);
            }
    }
    const std::string path = dir + "/plate.exr";
    EXPECT_TRUE(plate.write(path)) << plate.geterror();
    return path;
}

}  // namespace

TEST(CliFitlens, PrintsTheLensTheBokehCameFromAndItsSheet)
{
    // The printed options, given back to --bokeh, draw the true lens's PSF: an
    // independent check of the round trip through the command line (the fit's own
    // parameter checks are tests/fit/'s).
    const std::string dir = fresh_dir("cli_fitlens");
    bokeh::LensCharacter lens;
    lens.fstop = 2.0, lens.focal_mm = 50.0, lens.pixel_pitch_mm = 36.0 / 1920.0;
    lens.preset = bokeh::LensPreset::Uncorrected, lens.correction = 0.0;
    lens.monochromatic = 0.5, lens.chromatic = 0.7;
    bokeh::Kernel k;
    k.shape = bokeh::KernelShape::Polygon, k.blades = 6, k.rotation_deg = 20.0f, k.curvature = 0.25f;
    std::string err;
    ASSERT_TRUE(bokeh::Aperture::from_kernel(k, lens.aperture, err)) << err;
    const std::string plate = write_fit_plate(dir, lens);
    const RunResult r = bokehtool(format("{} --fitlens:at=720,400/900,390/980,500:box=96:fstop=2 -o {}/sheet.exr", plate, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const size_t at = r.out.find("fitlens: lens ");
    ASSERT_NE(at, std::string::npos) << r.out;
    const std::string options = r.out.substr(at + 14, r.out.find('\n', at) - at - 14);
    EXPECT_NE(options.find("kernel=polygon:blades=6"), std::string::npos) << options;
    const size_t c3 = r.out.find("crop 3 (980,500): CoC ");
    ASSERT_NE(c3, std::string::npos) << r.out;
    EXPECT_NEAR(std::atof(r.out.c_str() + c3 + 22), 42.0, 0.3) << r.out;

    const RunResult truth = bokehtool(format(
        "--bokeh:kernel=polygon:blades=6:rotation=20:curvature=0.25:lens=uncorrected:correction=0:monochromatic=0.5:"
        "chromatic=0.7:fstop=2:size=61 40 -o {}/truth.exr",
        dir));
    ASSERT_EQ(truth.status, 0) << truth.err;
    const RunResult fitted = bokehtool(format("--bokeh:{}:fstop=2:size=61 40 -o {}/fitted.exr", options, dir));
    ASSERT_EQ(fitted.status, 0) << fitted.err;
    OIIO::ImageBuf a(dir + "/truth.exr"), b(dir + "/fitted.exr");
    double peak = 0.0, se = 0.0;
    int n = 0;
    for (int y = -30; y <= 30; ++y)
        for (int x = -30; x <= 30; ++x) {
            float pa[3], pb[3];
            a.getpixel(x, y, pa);
            b.getpixel(x, y, pb);
            for (int c = 0; c < 3; ++c, ++n) {
                peak = std::max(peak, double(pa[c]));
                se += (pa[c] - pb[c]) * double(pa[c] - pb[c]);
            }
        }
    const double psnr = 10.0 * std::log10(peak * peak / (se / n));
    EXPECT_GT(psnr, 40.0) << options;

    // The sheet: three rows of four cells, the lens in its metadata.
    OIIO::ImageBuf sheet(dir + "/sheet.exr");
    ASSERT_TRUE(sheet.read(0, 0, true, OIIO::TypeFloat)) << sheet.geterror();
    EXPECT_EQ(sheet.spec().width, 4 * 96 + 5 * 2);
    EXPECT_EQ(sheet.spec().height, 3 * 96 + 4 * 2);
    EXPECT_EQ(sheet.spec().get_string_attribute("bokeh:fitted_lens"), options);
}

TEST(CliFitlens, UnusableCropsAndPositionsFailCleanly)
{
    const std::string dir = fresh_dir("cli_fitlens_bad");
    bokeh::LensCharacter lens;
    const std::string plate = write_fit_plate(dir, lens);
    const std::string out   = dir + "/out.exr";
    expect_clean_failure(bokehtool(format("{} --fitlens:at=100,100 -o {}", plate, out)), "is outside", out);
    expect_clean_failure(bokehtool(format("{} --fitlens:at=720:400 -o {}", plate, out)), "at", out);
    expect_clean_failure(bokehtool(format("{} '--fitlens:at=720;400' -o {}", plate, out)), "is not x,y", out);
    // An empty part of the plate: no highlight.
    expect_clean_failure(bokehtool(format("{} --fitlens:at=620,560:box=64 -o {}", plate, out)), "holds no highlight",
                         out);
    // A crop cut smaller than its bokeh.
    for (int box : { 32, 40 })
        expect_clean_failure(bokehtool(format("{} --fitlens:at=980,500:box={} -o {}", plate, box, out)),
                             "smaller than its bokeh", out);
}

TEST(CliFitlens, ADefocusedSceneGivesBackItsLens)
{
    // A plate made by another renderer than the fit's model: the built-in scene defocused
    // by the layer engine with highlight sprites of a known lens (7 blades, rotation 12,
    // curvature 0.15, spherical aberration 0.5, axial colour 0.8), three of its lights
    // fitted. Measured 11.98, 0.150, 0.497, 0.797.
    const std::string dir = fresh_dir("cli_fitlens_scene");
    const std::string lens = "kernel=polygon:blades=7:rotation=12:curvature=0.15:lens=uncorrected:correction=0:"
                             "monochromatic=0.5:chromatic=0.8";
    const RunResult plate = bokehtool(format("--scene lights --defocus:focus=2.5:fstop=1.4:{} -o {}/plate.exr", lens, dir));
    ASSERT_EQ(plate.status, 0) << plate.err;
    const RunResult r = bokehtool(
        format("{}/plate.exr --fitlens:at=575,187/1548,498/1850,588:box=96:fstop=1.4 -o {}/sheet.exr", dir, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    auto value = [&](const std::string& name) {
        const size_t at = r.out.find(":" + name + "=");
        EXPECT_NE(at, std::string::npos) << name << " in " << r.out;
        return at == std::string::npos ? 0.0 : std::atof(r.out.c_str() + at + name.size() + 2);
    };
    EXPECT_NE(r.out.find("kernel=polygon:blades=7:"), std::string::npos) << r.out;
    EXPECT_NEAR(value("rotation"), 12.0, 0.5);
    EXPECT_NEAR(value("curvature"), 0.15, 0.03);
    EXPECT_NEAR(value("monochromatic"), 0.5, 0.03);
    EXPECT_NEAR(value("chromatic"), 0.8, 0.04);
}
