// bokehtool --bokeh as a user runs it: a PSF centred on (0, 0) summing to 1 per channel,
// usable as --convolve's kernel; the sheet and the beam map; bad lens values refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

#include <bokeh/lens_fit.h>

#include "psf_support.h"
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

namespace {

// bokehtool `args` -o dir/name.exr, read back as a PSF (its data window, row-major).
bokeh::Psf tool_psf(const std::string& dir, const std::string& name, const std::string& args)
{
    const RunResult r = bokehtool(format("{} -o {}/{}.exr", args, dir, name));
    EXPECT_EQ(r.status, 0) << args << ": " << r.err;
    OIIO::ImageBuf img(dir + "/" + name + ".exr");
    EXPECT_TRUE(img.read(0, 0, true, OIIO::TypeFloat)) << img.geterror();
    return psf_from_image(img);
}

// The mean of channel 1 over the 5 x 5 pixels about (dx, dy) px from the centre (y down):
// the level of a uniform opening.
double level_at(const bokeh::Psf& p, int dx = 0, int dy = 0)
{
    double s = 0.0;
    for (int y = -2; y <= 2; ++y)
        for (int x = -2; x <= 2; ++x)
            s += p.at(p.width / 2 + dx + x, p.height / 2 + dy + y, 1);
    return s / 25.0;
}

}  // namespace

TEST(CliBokeh, SheetCellsAreTheirPsfs)
{
    // Columns from -30 px through focus to +30, rows from the centre to the 16:9 frame's
    // corner along the diagonal, each cell the PSF there scaled to a peak of 1.
    const std::string dir = fresh_dir("cli_bokeh_sheet");
    const std::string lens = "size=41:lens=uncorrected:catseye=0.5";
    const bokeh::Psf sheet = tool_psf(dir, "sheet", "--bokeh:sheet=1:columns=3:rows=2:" + lens + " 30");
    ASSERT_EQ(sheet.width, 3 * 41);
    ASSERT_EQ(sheet.height, 2 * 41);
    const double corner = std::atan2(9.0, 16.0);
    for (int row = 0; row < 2; ++row)
        for (int col = 0; col < 3; ++col) {
            SCOPED_TRACE(format("cell {} {}", col, row));
            const bokeh::Psf cell = tool_psf(dir, format("cell{}{}", col, row),
                                             format("--bokeh:{}:field={:.17g},{:.17g} {}", lens, row * std::cos(corner),
                                                    row * std::sin(corner), 30 * (col - 1)));
            ASSERT_EQ(cell.width, 41);
            const double peak = psf_peak(cell);
            double worst = 0.0, cell_peak = 0.0;
            for (int y = 0; y < 41; ++y)
                for (int x = 0; x < 41; ++x)
                    for (int c = 0; c < 3; ++c) {
                        const double v = sheet.at(col * 41 + x, row * 41 + y, c);
                        worst          = std::max(worst, std::abs(v - cell.at(x, y, c) / peak));
                        cell_peak      = std::max(cell_peak, v);
                    }
            EXPECT_LT(worst, 1e-6);
            EXPECT_NEAR(cell_peak, 1.0, 1e-6);
        }
}

TEST(CliBokeh, StarAndPictureOpeningsHaveTheirArea)
{
    // A star of n points, outer vertices on the CoC's circle (radius R) and inner ones at
    // inner R, is 2n triangles: area n R (inner R) sin(pi / n). The PSF is uniform over
    // it with unit energy, so its level inside is 1 / area (1 %: the rim's anti-aliasing
    // is outside the 5 x 5 pixels averaged).
    const std::string dir = fresh_dir("cli_bokeh_star");
    const bokeh::Psf star40 = tool_psf(dir, "star", "--bokeh:kernel=star:blades=5:inner=0.4:rotation=10 40");
    const double area40     = 5 * 20.0 * 8.0 * std::sin(bokeh::kPi / 5);
    EXPECT_NEAR(level_at(star40), 1.0 / area40, 0.01 / area40);
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(channel_sum(star40, c), 1.0, 1e-5);
    // That star read back as a picture aperture and drawn at 60 px is the star at 60 px:
    // the same level (2 %: the picture's opening is the 41 px raster's half-level
    // pixels, scaled 1.5x, so its area is within about a pixel's width along the rim)
    // and the same shape (90 % of the energy shared).
    const RunResult r = bokehtool(format("-v {0}/star.exr --bokeh:kernel=image 60 -o {0}/picture.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("picture aperture"), std::string::npos) << r.out;
    OIIO::ImageBuf picture_img(dir + "/picture.exr");
    ASSERT_TRUE(picture_img.read(0, 0, true, OIIO::TypeFloat)) << picture_img.geterror();
    const bokeh::Psf picture = psf_from_image(picture_img);
    const bokeh::Psf star60  = tool_psf(dir, "star60", "--bokeh:kernel=star:blades=5:inner=0.4:rotation=10 60");
    const double area60      = 5 * 30.0 * 12.0 * std::sin(bokeh::kPi / 5);
    EXPECT_NEAR(level_at(star60), 1.0 / area60, 0.01 / area60);
    EXPECT_NEAR(level_at(picture), 1.0 / area60, 0.02 / area60);
    double shared = 0.0;
    for (int y = 0; y < picture.height; ++y)
        for (int x = 0; x < picture.width; ++x) {
            const int sx = x - picture.width / 2 + star60.width / 2, sy = y - picture.height / 2 + star60.height / 2;
            if (sx >= 0 && sy >= 0 && sx < star60.width && sy < star60.height)
                shared += std::min(picture.at(x, y, 1), star60.at(sx, sy, 1));
        }
    std::printf("[ figures  ] star 60 px: level %.4g (1 / area %.4g); from its 40 px picture %.4g, %.1f %% shared\n",
                level_at(star60), 1.0 / area60, level_at(picture), 100.0 * shared);
    EXPECT_GT(shared, 0.9);
}

TEST(CliBokeh, BeamMapColumnsAreTheRaysLandingRadii)
{
    // The beam map's column at CoC c (U from -40 to 40 px over 512 columns) is the density
    // of the landing radius r(s) = s (c / 2 - a(s)) over the pupil's area, rows 0..255 from
    // the axis up to the column's largest |r|. Its ray-mass-weighted mean row is then
    // 255 <|r|> / max |r|, <|r|> = integral of |r(s)| 2 s ds over 0..1: computed here by the
    // midpoint rule for an under-corrected lens in one wavelength, a(s) = NA LSA(s) / pitch
    // with LSA = SA3 s^2 (correction 0, no axial colour; SA3 = -1.0 mm at 50 mm f/2, as
    // 1 / N^2 at f/2.8; NA = 1 / (2 N), pitch 36 / 1920 mm). Tolerance: the map rounds
    // each ray to its row (half a row) and sums 4096 rays: 0.3 rows.
    const std::string dir = fresh_dir("cli_bokeh_map");
    const bokeh::Psf map = tool_psf(dir, "map", "--bokeh:map=1:lens=uncorrected:correction=0:chromatic=0:wavelengths=587.6 40");
    ASSERT_EQ(map.width, 512);
    ASSERT_EQ(map.height, 256);
    const double sa3_mm = -1.0 * (2.0 / 2.8) * (2.0 / 2.8), na_per_pitch = 0.5 / 2.8 / (36.0 / 1920.0);
    double worst = 0.0;
    for (int x = 0; x < 512; x += 7) {
        const double c = -40.0 + 80.0 * (x + 0.5) / 512;
        double mean_r = 0.0, max_r = 0.0;
        const int n = 20000;
        for (int i = 0; i < n; ++i) {
            const double s = (i + 0.5) / n;
            const double r = std::abs(s * (0.5 * c - na_per_pitch * sa3_mm * s * s));
            mean_r += r * 2.0 * s / n;
            max_r = std::max(max_r, r);
        }
        double mass = 0.0, moment = 0.0;
        for (int row = 0; row < 256; ++row) {
            const double v = map.at(x, 255 - row, 1) * std::max(row, 1);  // density times the ring
            mass += v;
            moment += v * row;
        }
        worst = std::max(worst, std::abs(moment / mass - 255.0 * mean_r / max_r));
    }
    std::printf("[ figures  ] beam map: mean landing row within %.3f rows of the closed form\n", worst);
    EXPECT_LT(worst, 0.3);
}

TEST(CliBokeh, LensOptionsDoWhatTheySay)
{
    const std::string dir = fresh_dir("cli_bokeh_options");
    // anamorphicfocus: the horizontal and vertical CoCs 20 px apart, so at +10 px an oval
    // 20 px wide and 0 tall (held at half a pixel): a uniform ellipse's second moment is
    // (diameter / 4)^2, plus the pixel's 1/12; swapped at -10 px. 2 %.
    for (int coc : { 10, -10 }) {
        const PsfMoments m = psf_moments(tool_psf(dir, format("anamorphic{}", coc), format("--bokeh:anamorphicfocus=20 {}", coc)), 1);
        const double along = coc > 0 ? m.var_x : m.var_y, across = coc > 0 ? m.var_y : m.var_x;
        EXPECT_NEAR(along, 25.0 + 1.0 / 12.0, 0.5) << coc;
        EXPECT_LT(across, 0.3) << coc;
    }
    // onionoffset (and onionfront): at the frame's right edge (field 1, 0) the rings'
    // centre sits 0.5 pupil radii to the right behind the stop, to the left in front of
    // it; the PSF follows that pattern (docs/methods/optics.md) to 1e-4.
    for (int front : { 0, 1 }) {
        const bokeh::Psf p = tool_psf(dir, format("onion{}", front), format("--bokeh:onion=0.6:onioncycles=4:onionsharpness=2:"
                                                           "onionoffset=0.5:onionfront={}:field=1,0 120", front));
        const double side  = front ? -1.0 : 1.0;
        EXPECT_LT(onion_misfit(p, 120.0, OnionPattern{ 4.0, 2.0, 0.6, 0.5 * side, 0.0 }), 1e-4) << front;
        EXPECT_GT(onion_misfit(p, 120.0, OnionPattern{ 4.0, 2.0, 0.6, -0.5 * side, 0.0 }), 0.01) << front;
    }
    // monochromatic: r(s) = s (c / 2 - m a(s)) is odd in (c, m), so m = -1 at c is the
    // point reflection of m = 1 at -c (no axial colour); m = 0 is the plain aperture.
    const std::string sa = "--bokeh:size=61:lens=uncorrected:chromatic=0:monochromatic=";
    const bokeh::Psf reversed = tool_psf(dir, "reversed", sa + "-1 40"), front = tool_psf(dir, "front", sa + "1 -40");
    ASSERT_EQ(reversed.width, front.width);
    double worst = 0.0;
    for (int y = 0; y < front.height; ++y)
        for (int x = 0; x < front.width; ++x)
            worst = std::max(worst, double(std::abs(reversed.at(x, y, 1) - front.at(front.width - 1 - x, front.height - 1 - y, 1))));
    EXPECT_LT(worst, 1e-6 * psf_peak(front));
    EXPECT_GT(psf_difference(reversed, tool_psf(dir, "back", sa + "1 40")), 0.1 * psf_peak(front));
    EXPECT_LT(psf_difference(tool_psf(dir, "none", sa + "0 40"), tool_psf(dir, "off", "--bokeh:size=61 40")), 1e-6);
    // curvature: 0 is the hexagon, area (3 sqrt 3 / 2) R^2 (its level 1 / area, 1 %);
    // 1 is the circle (the disk's level 1 / (pi R^2), 1 %; and the disk, within the rim's
    // anti-aliasing).
    const double R = 30.0;
    const bokeh::Psf hexagon = tool_psf(dir, "hexagon", "--bokeh:kernel=polygon:blades=6:curvature=0 60");
    EXPECT_NEAR(level_at(hexagon), 1.0 / (1.5 * std::sqrt(3.0) * R * R), 0.01 / (1.5 * std::sqrt(3.0) * R * R));
    const bokeh::Psf round = tool_psf(dir, "round", "--bokeh:kernel=polygon:blades=6:curvature=1 60");
    const bokeh::Psf disk  = tool_psf(dir, "disk", "--bokeh 60");
    EXPECT_NEAR(level_at(round), 1.0 / (bokeh::kPi * R * R), 0.01 / (bokeh::kPi * R * R));
    if (round.width == disk.width)
        EXPECT_LT(psf_difference(round, disk), 0.5 / (bokeh::kPi * R * R));
    else
        ADD_FAILURE() << "the round polygon is " << round.width << " px, the disk " << disk.width;
    // hole: a catadioptric hole of half the radius is dark inside 0.5 R (a pixel from its
    // rim) and the ring's level is 1 / (pi R^2 (1 - 0.25)) (1 %).
    const bokeh::Psf ring = tool_psf(dir, "hole", "--bokeh:hole=0.5 60");
    double inside = 0.0;
    for (int y = 0; y < ring.height; ++y)
        for (int x = 0; x < ring.width; ++x)
            if (std::hypot(x - ring.width / 2, y - ring.height / 2) < 0.5 * R - 1.0)
                inside = std::max(inside, double(ring.at(x, y, 1)));
    EXPECT_EQ(inside, 0.0);
    const double ring_level = 1.0 / (bokeh::kPi * R * R * 0.75);
    EXPECT_NEAR(level_at(ring, 22, 0), ring_level, 0.01 * ring_level);
    EXPECT_NEAR(level_at(ring, 0, -22), ring_level, 0.01 * ring_level);
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
