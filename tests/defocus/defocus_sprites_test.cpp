// Lens character in the depth defocus (defocus.h: lens_character; core/defocus/defocus_sprites.cpp):
// off is bit for bit the plain defocus, energy is counted once, a lone bright pixel is the
// lens PSF, an exposure ramp does not pop sprites, nearer layers hide sprites, deep input,
// and the brute-force scatter reference.
#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/metrics.h>
#include <bokeh/optics.h>
#include <bokeh/scene.h>

#include "test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/deepdata.h>

using namespace bokeh;
using bokeh_test::at;
using bokeh_test::channel_sum;
using bokeh_test::direct_options;
using bokeh_test::make_image;
using bokeh_test::Px;
using bokeh_test::run_defocus;
using bokeh_test::second_to_first_difference;
using bokeh_test::slanted_plane;

namespace {

DefocusOptions with_lens(DefocusOptions o, LensPreset preset)
{
    o.lens_character = true;
    o.lens.preset    = preset;
    return o;
}

// A sprite is drawn as ramps within 1e-3 of each PSF pixel's own value (below 1e-6 of the
// channel's peak, of that level) and literal runs, each PSF then rescaled to its exact sum
// (core/optics/psf_runs.h): `got` against `want` in units of that allowance's reference, so the
// bound 2e-3 holds the ramps' error plus the rescale's.
double ramp_error(double got, double want, double peak)
{
    return std::abs(got - want) / std::max(std::abs(want), 1e-6 * peak);
}
constexpr double kRampBound = 2e-3;

// The PSF a sprite of `o` at CoC `coc_px` is drawn with, on the axis, over an output
// `width_px` pixels wide, and its largest value.
Psf sprite_psf(const DefocusOptions& o, int width_px, double coc_px, float& peak)
{
    LensCharacter lens  = o.lens;
    lens.fstop          = o.coc.lens.fstop;
    lens.focal_mm       = o.coc.lens.focal_mm;
    lens.pixel_pitch_mm = o.coc.lens.sensor_width_mm / width_px;
    PsfRequest req;
    req.coc_px = coc_px;
    Psf psf;
    std::string err;
    EXPECT_TRUE(lens_psf(psf, lens, req, err)) << err;
    peak = 0.0f;
    for (float v : psf.rgb)
        peak = std::max(peak, v);
    return psf;
}

// A lone light of 1e6 (alpha 1) at (lx, ly), CoC `coc_px`, on a w x h transparent black
// frame of CoC `coc_px`.
OIIO::ImageBuf lone_light(int w, int h, int lx, int ly, float coc_px, OIIO::ROI full = {})
{
    return make_image(
        w, h,
        [=](int x, int y) {
            Px p;
            p.a = 0.0f;
            p.z = coc_px;
            if (x == lx && y == ly)
                p.r = p.g = p.b = 1e6f, p.a = 1.0f;
            return p;
        },
        0, 0, full);
}

// Channel c of `psf` at offset (dx, dy) from its centre; 0 outside it.
double psf_at(const Psf& psf, int dx, int dy, int c)
{
    const int px = dx + psf.width / 2, py = dy + psf.height / 2;
    return px >= 0 && px < psf.width && py >= 0 && py < psf.height ? double(psf.at(px, py, c)) : 0.0;
}

bool bit_identical(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b)
{
    if (a.roi() != b.roi() || a.nchannels() != b.nchannels() || a.deep() != b.deep())
        return false;
    if (a.deep()) {
        const OIIO::DeepData &da = *a.deepdata(), &db = *b.deepdata();
        for (int64_t p = 0; p < da.pixels(); ++p) {
            if (da.samples(p) != db.samples(p))
                return false;
            for (int s = 0; s < int(da.samples(p)); ++s)
                for (int c = 0; c < da.channels(); ++c) {
                    const float u = da.deep_value(p, c, s), v = db.deep_value(p, c, s);
                    if (std::memcmp(&u, &v, sizeof u) != 0)
                        return false;
                }
        }
        return true;
    }
    const OIIO::ROI r = a.roi();
    for (int y = r.ybegin; y < r.yend; ++y)
        for (int x = r.xbegin; x < r.xend; ++x)
            for (int c = 0; c < a.nchannels(); ++c) {
                const float u = at(a, x, y, c), v = at(b, x, y, c);
                if (std::memcmp(&u, &v, sizeof u) != 0)
                    return false;
            }
    return true;
}

float hash01(int x, int y)
{
    const unsigned h = unsigned(x) * 73856093u ^ unsigned(y) * 19349663u;
    return float((h * 2654435761u) >> 8) / float(1u << 24);
}

// 96 x 72 of dim texture (CoC +24) with 12 lights in front of it (20 .. 2000, CoCs -12 ..
// +20) on a 24 px grid, in a display window 48 px larger each side (black border: the
// bokeh have room). (A light behind an opaque background, seen through a one-pixel hole,
// is hidden by it in the layer model, and its energy with it.)
const OIIO::ROI kLightsDisplay(-48, 144, -48, 120);
OIIO::ImageBuf lights_scene(float exposure = 1.0f)
{
    return make_image(
        96, 72,
        [&](int x, int y) {
            Px p;
            p.r = p.g = p.b = 0.02f * hash01(x, y) * exposure;
            p.z             = 24.0f;
            if ((x - 12) % 24 == 0 && (y - 12) % 24 == 0) {
                const int i = (x - 12) / 24 + 4 * ((y - 12) / 24);
                const float v = 20.0f * std::pow(10.0f, float(i) / 5.5f) * exposure;
                p.r = v, p.g = 0.8f * v, p.b = 0.5f * v;
                p.z = -12.0f + 32.0f * float(i) / 11.0f;
            }
            return p;
        },
        0, 0, kLightsDisplay);
}

}  // namespace

TEST(DefocusSprites, LensCharacterOffIsBitForBitThePlainDefocus)
{
    // The lens described and the threshold changed, but lens character off: no difference
    // in any bit, for every method and for deep input.
    const OIIO::ImageBuf src = lights_scene();
    for (DefocusMethod m : { DefocusMethod::Auto, DefocusMethod::Layers, DefocusMethod::Reference,
                             DefocusMethod::Gather }) {
        SCOPED_TRACE(method_name(m));
        DefocusOptions described = with_lens(direct_options(m, Border::Clamp), LensPreset::Uncorrected);
        described.lens_character      = false;
        described.highlight_threshold = 0.01f;
        described.max_sprites         = 3;
        described.lens.diffraction    = DiffractionModel::EdgeLaw;
        DefocusReport rep;
        EXPECT_TRUE(
            bit_identical(run_defocus(src, direct_options(m, Border::Clamp)), run_defocus(src, described, &rep)));
        EXPECT_FALSE(rep.lens_character);
        EXPECT_EQ(rep.sprites, 0);
    }
    std::vector<bokeh_test::DeepPixel> px(32 * 32);
    for (int i = 0; i < 32 * 32; ++i)
        px[size_t(i)] = { { 0.1, 0.1, 0.1, 0.5, 2.0, 2.0 }, { 40.0 * hash01(i, 1), 5.0, 1.0, 1.0, 8.0, 8.0 } };
    const OIIO::ImageBuf deep = bokeh_test::make_deep(32, 32, px);
    DefocusOptions plain = direct_options(DefocusMethod::Auto, Border::Clamp), described = plain;
    described.lens.preset         = LensPreset::Achromat;
    described.highlight_threshold = 0.01f;
    EXPECT_TRUE(bit_identical(run_defocus(deep, plain), run_defocus(deep, described)));
    plain.deep_output = described.deep_output = true;
    EXPECT_TRUE(bit_identical(run_defocus(deep, plain), run_defocus(deep, described)));
}

TEST(DefocusSprites, EnergyIsCountedOnce)
{
    // Sum of each colour channel out = in within 1e-4 (relative), with sprites on: the
    // sprites' share left the layers. Stated with the plain defocus alongside (its own
    // conservation on this scene is the floor). In 3 x 3 sub-aperture views too: each
    // view draws the whole PSF, and the views' shares sum to 1.
    const OIIO::ImageBuf src = lights_scene();
    for (int views : { 1, 3 }) {
        for (LensPreset preset : { LensPreset::Off, LensPreset::Achromat, LensPreset::Uncorrected }) {
            SCOPED_TRACE(lens_preset_name(preset) + std::string(views > 1 ? ", 3 x 3 views" : ""));
            DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), preset),
                           p = direct_options(DefocusMethod::Layers, Border::Black);
            o.lens.diffraction = DiffractionModel::EdgeLaw;
            o.aperture_views = p.aperture_views = views;
            DefocusReport rep;
            const OIIO::ImageBuf out   = run_defocus(src, o, &rep);
            const OIIO::ImageBuf plain = run_defocus(src, p);
            EXPECT_EQ(rep.sprites, 12) << "every light is a whole sprite (20 > 2 x threshold)";
            EXPECT_EQ(rep.sprites_drawn, 12) << "each view draws them; the report counts them once";
            for (int c = 0; c < 3; ++c) {
                const double in = channel_sum(src, c), lens = channel_sum(out, c), base = channel_sum(plain, c);
                std::printf("[ figures  ] energy %-11s channel %d: in %.6g, sprites %.6g (%.2e), plain %.6g (%.2e)\n",
                            lens_preset_name(preset), c, in, lens, lens / in - 1.0, base, base / in - 1.0);
                EXPECT_NEAR(lens / in, 1.0, 1e-4);
            }
        }
    }
}

TEST(DefocusSprites, LoneBrightPixelIsOneSpriteShapedAsThePsf)
{
    // A 1e6 pixel at CoC 32 px (a bin centre: no crossfade) in the display window's centre
    // (field 0), on transparent black: one sprite, each channel holding 1e6 (1e-5), and
    // every pixel equal to 1e6 times lens_psf's (ramp_error).
    const OIIO::ROI display(-48, 113, -48, 113);
    const OIIO::ImageBuf src = lone_light(65, 65, 32, 32, 32.0f, display);
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.diffraction = DiffractionModel::EdgeLaw;
    DefocusReport rep;
    const OIIO::ImageBuf out = run_defocus(src, o, &rep);
    EXPECT_EQ(rep.sprites, 1);
    EXPECT_FLOAT_EQ(rep.sprite_min_coc_px, 32.0f);

    float peak;
    const Psf psf = sprite_psf(o, display.width(), 32.0, peak);
    ASSERT_GT(psf.width, 0);
    double worst = 0.0;
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(channel_sum(out, c) / 1e6, 1.0, 1e-5) << "channel " << c;
        for (int y = -48; y < 113; ++y)
            for (int x = -48; x < 113; ++x)
                worst = std::max(worst, ramp_error(at(out, x, y, c), 1e6 * psf_at(psf, x - 32, y - 32, c), 1e6 * peak));
    }
    std::printf("[ figures  ] lone pixel: PSF %dx%d, largest difference %.2e of the pixel's value\n", psf.width,
                psf.height, worst);
    EXPECT_LT(worst, kRampBound);
}

namespace {
// The edge of a row profile `v` (index = px from the centre) going outwards from its
// plateau (the mean of its first `inner` values): where it crosses 0.9, 0.5 and 0.1 of
// the plateau, linearly between pixels, searched from the outside in.
struct Edge {
    double at90, at50, at10;
};
Edge row_edge(const std::vector<double>& v, int inner)
{
    double plateau = 0.0;
    for (int i = 0; i < inner; ++i)
        plateau += v[size_t(i)] / inner;
    auto crossing = [&](double level) {
        for (size_t i = v.size() - 1; i > 0; --i)
            if (v[i - 1] >= level * plateau && v[i] < level * plateau)
                return double(i - 1) + (v[i - 1] - level * plateau) / (v[i - 1] - v[i]);
        return -1.0;
    };
    return { crossing(0.9), crossing(0.5), crossing(0.1) };
}
}  // namespace

TEST(DefocusSprites, ARimStaysOneRimBetweenCachedCocs)
{
    // A lone light whose CoC walks from one cache bin (64 px) to the next (2^(1/16) x 64 =
    // 66.8 px) in eighths, with the plain aperture's hard, anti-aliased rim. Along the row
    // through its centre the drawn sprite's edge (10-90 % of its plateau) must be as narrow
    // as lens_psf's own PSF at that CoC (within 0.3 px: two rims crossfaded 4.4 % apart, as
    // the bins alone drew them, made it up to 0.98 px wider, 2.47 against 1.60), and sit
    // where that PSF's does (50 % within 0.2 px).
    const OIIO::ROI display(-60, 61, -60, 61);
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Off);
    double worst_width = 0.0, worst_shift = 0.0;
    for (int k = 0; k <= 8; ++k) {
        const double coc = 64.0 * std::exp2(k / 128.0);
        const OIIO::ImageBuf src = lone_light(1, 1, 0, 0, float(coc), display);
        const OIIO::ImageBuf out = run_defocus(src, o, nullptr);
        float peak;
        const Psf psf = sprite_psf(o, display.width(), coc, peak);
        std::vector<double> drawn, single;
        for (int x = 0; x <= 45; ++x) {
            drawn.push_back(0.5 * (at(out, x, 0, 1) + at(out, -x, 0, 1)));
            single.push_back(1e6 * psf_at(psf, x, 0, 1));
        }
        const Edge d = row_edge(drawn, 16), s = row_edge(single, 16);
        ASSERT_GT(d.at10, 0.0) << "CoC " << coc;
        ASSERT_GT(s.at10, 0.0) << "CoC " << coc;
        const double width = (d.at10 - d.at90) - (s.at10 - s.at90), shift = d.at50 - s.at50;
        std::printf("[ figures  ] rim at CoC %.3f px: 10-90 %% width %.2f px (the PSF's own %.2f), 50 %% at %.2f px "
                    "(the PSF's %.2f)\n",
                    coc, d.at10 - d.at90, s.at10 - s.at90, d.at50, s.at50);
        EXPECT_LT(width, 0.3) << "CoC " << coc << ": the rim is wider than one PSF's";
        EXPECT_NEAR(shift, 0.0, 0.2) << "CoC " << coc;
        worst_width = std::max(worst_width, width);
        worst_shift = std::max(worst_shift, std::abs(shift));
    }
    std::printf("[ figures  ] rim between two bins: widest %.2f px over the PSF's own, farthest %.2f px\n", worst_width,
                worst_shift);
}

TEST(DefocusSprites, ASpriteCutByTheOutputsEdgeKeepsItsShape)
{
    // The lone light of the test above, 3 px from the left and 5 px from the top of an
    // output that does not grow past the data window: the sprite's ramps and runs are cut
    // at the edges, and what is left is lens_psf's pixels there (ramp_error), nothing more.
    const OIIO::ImageBuf src = lone_light(65, 65, 3, 5, 32.0f);
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.diffraction = DiffractionModel::EdgeLaw;
    o.grow             = false;
    const OIIO::ImageBuf out = run_defocus(src, o);
    ASSERT_EQ(out.roi().xbegin, 0);
    ASSERT_EQ(out.roi().xend, 65);
    ASSERT_EQ(out.roi().ybegin, 0);
    ASSERT_EQ(out.roi().yend, 65);

    // The field: 29 px left and 27 px up of the centre, 0.63 of the half-diagonal; an
    // achromat with no field effect asks every PSF on the axis.
    float peak;
    const Psf psf = sprite_psf(o, 65, 32.0, peak);
    ASSERT_GT(psf.width, 0);
    double worst = 0.0, inside_sum = 0.0, got_sum = 0.0;
    for (int c = 0; c < 3; ++c)
        for (int y = 0; y < 65; ++y)
            for (int x = 0; x < 65; ++x) {
                const double want = 1e6 * psf_at(psf, x - 3, y - 5, c);
                worst = std::max(worst, ramp_error(at(out, x, y, c), want, 1e6 * peak));
                inside_sum += want;
                got_sum += at(out, x, y, c);
            }
    std::printf("[ figures  ] sprite cut at the output's edge: largest difference %.2e of the pixel's value, "
                "%.3f of its light kept\n",
                worst, got_sum / 3e6);
    EXPECT_LT(worst, kRampBound);
    EXPECT_NEAR(got_sum / inside_sum, 1.0, kRampBound);
    EXPECT_LT(got_sum / 3e6, 0.5);  // most of it fell past the edges
}

TEST(DefocusSprites, FieldBinsAreInterpolated)
{
    // A 1e6 light at CoC 16 px (a CoC bin's centre) on the display window's horizontal
    // axis, with a cat's eye (a field effect). At x = 39 its field position lies 0.49 of
    // the way from the centre's field bin to the next (1/8 of the half-diagonal): the
    // sprite is 1e6 times the bilinear blend of lens_psf at the two bins (ramp_error of the
    // peak). Moved a pixel a frame across the next bin (x = 36 .. 60), the sprite's shape
    // (each frame against the one before, moved back by a pixel) changes by steps of
    // nearly equal size: the largest step within 2x their mean (snapped to the nearest bin
    // it would not change at all but at one jump).
    const OIIO::ROI display(-48, 113, -48, 113);
    auto frame = [&](int lx) { return lone_light(97, 65, lx, 32, 16.0f, display); };
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.catseye   = 0.8;
    LensCharacter lens  = o.lens;
    lens.fstop          = o.coc.lens.fstop;
    lens.focal_mm       = o.coc.lens.focal_mm;
    lens.pixel_pitch_mm = o.coc.lens.sensor_width_mm / display.width();
    const double half_diagonal = 0.5 * std::hypot(161.0, 161.0), cx = -48 + 80.5;
    const double g  = 8.0 * (39 + 0.5 - cx) / half_diagonal;
    const double t  = g - std::floor(g);
    Psf a, b;
    std::string err;
    ASSERT_TRUE(lens_psf(a, lens, PsfRequest{ 16.0, std::floor(g) / 8.0, 0.0, 0 }, err)) << err;
    ASSERT_TRUE(lens_psf(b, lens, PsfRequest{ 16.0, (std::floor(g) + 1.0) / 8.0, 0.0, 0 }, err)) << err;
    ASSERT_EQ(a.width, b.width);
    const OIIO::ImageBuf out = run_defocus(frame(39), o);
    double worst = 0.0, peak = 0.0;
    for (int c = 0; c < 3; ++c)
        for (int y = -48; y < 113; ++y)
            for (int x = -48; x < 113; ++x) {
                const int px = x - 39 + a.width / 2, py = y - 32 + a.height / 2;
                const bool inside = px >= 0 && px < a.width && py >= 0 && py < a.height;
                peak = std::max(peak, inside ? 1e6 * std::max(a.at(px, py, c), b.at(px, py, c)) : 0.0);
            }
    for (int c = 0; c < 3; ++c)
        for (int y = -48; y < 113; ++y)
            for (int x = -48; x < 113; ++x) {
                const int px = x - 39 + a.width / 2, py = y - 32 + a.height / 2;
                const bool inside = px >= 0 && px < a.width && py >= 0 && py < a.height;
                const double want = inside ? 1e6 * ((1.0 - t) * a.at(px, py, c) + t * b.at(px, py, c)) : 0.0;
                worst = std::max(worst, ramp_error(at(out, x, y, c), want, peak));
            }
    std::printf("[ figures  ] field bins %.3f apart: largest difference %.2e of the pixel's value\n", t, worst);
    EXPECT_LT(worst, kRampBound);

    std::vector<OIIO::ImageBuf> frames;
    for (int lx = 36; lx <= 60; ++lx)
        frames.push_back(run_defocus(frame(lx), o));
    std::vector<double> steps;
    for (size_t i = 0; i + 1 < frames.size(); ++i) {
        double sq = 0.0;
        for (int y = 0; y < 65; ++y)
            for (int dx = -32; dx <= 32; ++dx) {
                const double d = at(frames[i + 1], 37 + int(i) + dx, y, 1) - at(frames[i], 36 + int(i) + dx, y, 1);
                sq += d * d;
            }
        steps.push_back(std::sqrt(sq));
    }
    double mean = 0.0, largest = 0.0;
    for (double d : steps)
        mean += d / double(steps.size()), largest = std::max(largest, d);
    std::printf("[ figures  ] a light moving across a field bin: shape steps mean %.3g, largest %.2f of the mean\n",
                mean, largest / mean);
    EXPECT_GT(mean, 0.0);
    EXPECT_LT(largest, 2.0 * mean);
}

TEST(DefocusSprites, ExposureRampDoesNotPop)
{
    // 128 lights, 1/8 octave apart from 2^-6 to 2^9.9, over a dim floor, CoCs 10 .. 24 px,
    // with a lens whose sprites differ strongly from the layers' disk (uncorrected, onion
    // rings 0.8); exposure 2^(k/8), k = 0 .. 23, so 16 lights are inside the threshold band
    // (luminance 0.5 .. 2) in every frame. Each frame divided by its exposure: the step
    // d_k = RMS(frame k+1 - frame k) should follow the ramp smoothly. The lights in the band
    // are 2^(-1/8) as bright (after the division) each frame, so d_k falls by that factor a
    // step; a light moving wholly from the layers into a sprite in one step (a hard
    // threshold) would stand out of that trend by the whole difference of its two shapes,
    // where the smoothstep over 16 steps moves at most 1.5 / 16 of it a step. Bound: every
    // d_k within 0.75 .. 1.33 of the mean of its two neighbours.
    auto scene = [](float e) {
        return make_image(256, 128, [e](int x, int y) {
            Px p;
            p.r = p.g = p.b = 0.01f * hash01(x, y) * e;
            p.z             = 26.0f;  // behind every light
            if ((x - 8) % 16 == 0 && (y - 8) % 16 == 0) {
                const int i = (x - 8) / 16 + 16 * ((y - 8) / 16);
                const float v = std::exp2(float(i - 48) / 8.0f) * e;
                p.r = p.g = p.b = v;
                p.z = 10.0f + 14.0f * float(i % 5) / 4.0f;
            }
            return p;
        }, 0, 0, OIIO::ROI(-32, 288, -32, 160));
    };
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Uncorrected);
    o.lens.onion     = 0.8;
    std::vector<OIIO::ImageBuf> frames;
    std::vector<float> exposure;
    for (int k = 0; k < 24; ++k) {
        exposure.push_back(std::exp2(float(k) / 8.0f));
        frames.push_back(run_defocus(scene(exposure.back()), o));
    }
    std::vector<double> d;
    for (int k = 0; k + 1 < 24; ++k) {
        const OIIO::ROI r = frames[size_t(k)].roi();
        double sq = 0.0;
        for (int y = r.ybegin; y < r.yend; ++y)
            for (int x = r.xbegin; x < r.xend; ++x)
                for (int c = 0; c < 3; ++c) {
                    const double u = at(frames[size_t(k) + 1], x, y, c) / exposure[size_t(k) + 1];
                    const double v = at(frames[size_t(k)], x, y, c) / exposure[size_t(k)];
                    sq += (u - v) * (u - v);
                }
        d.push_back(std::sqrt(sq / (3.0 * double(r.npixels()))));
    }
    double mean = 0.0, lo = 1e30, hi = 0.0;
    std::string list;
    for (size_t i = 0; i < d.size(); ++i) {
        mean += d[i] / double(d.size());
        if (i > 0 && i + 1 < d.size()) {
            const double r = d[i] / (0.5 * (d[i - 1] + d[i + 1]));
            lo = std::min(lo, r), hi = std::max(hi, r);
        }
        char buf[32];
        std::snprintf(buf, sizeof buf, " %.2e", d[i]);
        list += buf;
    }
    std::printf("[ figures  ] exposure ramp: d_k =%s\n[ figures  ]   mean %.3e; d_k over the mean of its "
                "neighbours %.3f .. %.3f\n",
                list.c_str(), mean, lo, hi);
    EXPECT_GT(mean, 1e-6) << "the ramp moves energy between layers and sprites";
    EXPECT_GE(lo, 0.75) << "popping";
    EXPECT_LE(hi, 1.33) << "popping";
}

TEST(DefocusSprites, ChangeAsSteadilyAsThePlainLayers)
{
    // The temporal figure of DefocusTemporal (rms second over first difference of the
    // tone-mapped frames, 24 frames), with the lens off and lens character on against the
    // plain layers: sprites drawn with the aperture's own disk should change no less
    // steadily than the layers' disks. Two shots: the slanted plane of the focus-pull tests
    // (luminance up to 0.9, half a sprite at 1 against a threshold of 1: most of the plane is
    // in part sprites) dollying 0 -> 0.5 m nearer at focus 3 m, and the built-in lights scene
    // (240 x 135) through a 5 -> 7 m pull. Measured: the dolly 0.335 plain, 0.374 with
    // sprites (1.715 when a sprite's share in the rung nearer focus, drawn with its own wider
    // PSF, was divided by a visibility falling to 0: kSpriteGainFloor); the pull 0.435
    // plain, 0.424 with sprites (0.997 when a light passing 1 px of CoC jumped from a point
    // to a disk spread a pixel: radial_bin_px). Held within 1.2 times.
    for (const bool dolly : { true, false }) {
        SCOPED_TRACE(dolly ? "plane dolly" : "lights pull");
        OIIO::ImageBuf lights;
        DefocusOptions o;
        if (dolly) {
            o                         = bokeh_test::plane_lens(DefocusMethod::Auto);
            o.coc.lens.focus_distance = 3.0;
        } else {
            SceneOptions so;
            so.width  = 240;
            so.height = 135;
            ASSERT_TRUE(make_scene(lights, "lights", so)) << lights.geterror();
            o = bokeh_test::scene_lens(lights.spec());
        }
        std::vector<OIIO::ImageBuf> sources;
        std::vector<double> focus_m;
        for (int i = 0; i < 24; ++i) {
            if (dolly) {
                OIIO::ImageBuf src = slanted_plane();
                for (OIIO::ImageBuf::Iterator<float> it(src); !it.done(); ++it)
                    it[4] = it[4] - 0.5f * float(i) / 23.0f;
                sources.push_back(std::move(src));
                focus_m.push_back(3.0);
            } else {
                sources.push_back(lights);
                focus_m.push_back(1.0 / (1.0 / 5.0 + (1.0 / 7.0 - 1.0 / 5.0) * i / 23.0));
            }
        }
        double figure[2];
        for (const bool character : { false, true }) {
            DefocusOptions oc         = o;
            oc.lens_character         = character;
            oc.highlight_threshold    = 1.0f;
            std::vector<OIIO::ImageBuf> frames;
            int64_t sprites = 0;
            for (size_t i = 0; i < sources.size(); ++i) {
                oc.coc.lens.focus_distance = focus_m[i];
                DefocusReport rep;
                frames.push_back(run_defocus(sources[i], oc, &rep));
                sprites = std::max(sprites, rep.sprites);
            }
            figure[character] = second_to_first_difference(frames, frames);
            std::printf("[ figures  ] %s, %s: %.3f (%lld sprites at most)\n", dolly ? "plane dolly" : "lights pull",
                        character ? "lens character" : "plain", figure[character], (long long)sprites);
            if (character) {
                EXPECT_GT(sprites, 0) << "the shot has highlights";
            }
        }
        EXPECT_LE(figure[1], 1.2 * figure[0]) << "lens character steps in time";
    }
}

TEST(DefocusSprites, FocusPullDoesNotPop)
{
    // DefocusTemporal.FocusPullDoesNotPop (tests/defocus/defocus_test.cpp) with lens character on:
    // its 160 x 90 textured slanted plane (1 / Z linear in x from 1 m to 10 m; 85 mm f/1.4
    // on 36 mm; focus 1.5 m -> 6 m in 24 frames, evenly in 1 / distance), plus 12 lights
    // in two columns at x = 2 and 6 (1.0 m: in front of the focus all the pull, CoC -8 ..
    // -19 px, as lights crossing the focus make even the reference jump), of luminance 0.7
    // .. 7 against a highlights threshold of 2: part sprites (the band is 1 .. 4) and whole
    // ones; the plane (luminance up to 0.9) has none. The lens is one whose sprites differ
    // strongly from the layers' disk (uncorrected, onion rings 0.8), so a sprite changing
    // shape at once (a CoC bin, a layer boundary) would show. The measure is the existing test's: d_i = RMSE of frame
    // i+1 against frame i (linear), and a pop is a step |d_{i+1} - d_i| above 0.5 of the
    // mean d (the reference's steps stay under 0.1 of it on the plane alone).
    OIIO::ImageBuf src = slanted_plane();
    for (OIIO::ImageBuf::Iterator<float> it(src); !it.done(); ++it)
        if ((it.x() == 2 || it.x() == 6) && it.y() % 15 == 7) {
            const float v = 0.8f * std::pow(10.0f, float(it.y() / 15 + 6 * (it.x() == 6)) / 11.0f);
            it[0] = v, it[1] = 0.9f * v, it[2] = 0.7f * v;
        }
    for (DefocusMethod m : { DefocusMethod::Layers, DefocusMethod::Reference }) {
        for (bool character : { false, true }) {
            SCOPED_TRACE(std::string(method_name(m)) + (character ? " lens character" : " plain"));
            DefocusOptions o = bokeh_test::plane_lens(m);
            if (character) {
                o = with_lens(o, LensPreset::Uncorrected);
                o.lens.onion          = 0.8;
                o.highlight_threshold = 2.0f;
            }
            std::vector<OIIO::ImageBuf> frames;
            int64_t sprites = 0;
            for (int i = 0; i < 24; ++i) {
                o.coc.lens.focus_distance = 1.0 / (1.0 / 1.5 + (1.0 / 6.0 - 1.0 / 1.5) * i / 23.0);
                DefocusReport rep;
                frames.push_back(run_defocus(src, o, &rep));
                sprites = std::max(sprites, rep.sprites);
            }
            // The whole frame (the existing test's d_i), and the lights' strip alone (x < 20:
            // their bokeh, radius up to 10 px, where a sprite's pop is not diluted by the
            // plane).
            for (int strip : { 0, 1 }) {
                std::vector<double> d;
                for (int i = 0; i + 1 < 24; ++i) {
                    const OIIO::ROI r = frames[size_t(i)].roi();
                    double sq = 0.0;
                    int64_t n = 0;
                    for (int y = r.ybegin; y < r.yend; ++y)
                        for (int x = r.xbegin; x < (strip ? 20 : r.xend); ++x, ++n)
                            for (int c = 0; c < 3; ++c) {
                                const double u = at(frames[size_t(i) + 1], x, y, c) - at(frames[size_t(i)], x, y, c);
                                sq += u * u;
                            }
                    d.push_back(std::sqrt(sq / (3.0 * double(n))));
                }
                double mean = 0.0, jump = 0.0;
                std::string list;
                for (size_t i = 0; i < d.size(); ++i) {
                    mean += d[i] / double(d.size());
                    if (i + 1 < d.size())
                        jump = std::max(jump, std::abs(d[i + 1] - d[i]));
                    char buf[32];
                    std::snprintf(buf, sizeof buf, " %.4f", d[i]);
                    list += buf;
                }
                std::printf("[ figures  ] focus pull %-9s %-14s %-12s (%lld sprites): d_i =%s\n[ figures  ]   mean "
                            "%.4f, largest step %.4f (%.2f of the mean)\n",
                            method_name(m), character ? "lens character" : "plain", strip ? "lights' strip" : "frame",
                            static_cast<long long>(sprites), list.c_str(), mean, jump, jump / mean);
                EXPECT_GT(mean, 1e-3) << "the focus pull changes the image";
                EXPECT_LE(jump, 0.5 * mean) << "popping: step " << jump << " vs mean " << mean;
            }
            if (character) {
                int in_band = 0;  // lights above half the threshold (luminance 0.907 v)
                for (int i = 0; i < 12; ++i)
                    in_band += 0.907f * 0.8f * std::pow(10.0f, float(i) / 11.0f) > 1.0f;
                EXPECT_EQ(sprites, in_band) << "each light above the band's foot is a sprite";
            }
        }
    }
}

TEST(DefocusSprites, ReportCountsASpriteSharedBetweenLayersOnce)
{
    // Four layers for CoCs -12 .. +24: most of the 12 lights fall between two rungs and are
    // drawn in both, but each is one sprite, and none is merged (their PSFs are under 64 px
    // wide), so the report's drawn count is the sprite count. Deep input: a piece between
    // two rungs is one sprite too.
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.layers         = 4;
    DefocusReport rep;
    run_defocus(lights_scene(), o, &rep);
    int shared = 0;
    for (int i = 0; i < 12; ++i) {
        const float coc = -12.0f + 32.0f * float(i) / 11.0f;
        shared += std::none_of(rep.layer_coc_px.begin(), rep.layer_coc_px.end(),
                               [&](float r) { return std::abs(r - coc) < 1e-3f; });
    }
    std::printf("[ figures  ] 4 layers: %d of 12 lights between two rungs; %lld sprites, %lld drawn\n", shared,
                static_cast<long long>(rep.sprites), static_cast<long long>(rep.sprites_drawn));
    EXPECT_GE(shared, 6) << "the scene shares lights between layers";
    EXPECT_EQ(rep.sprites, 12);
    EXPECT_EQ(rep.sprites_drawn, 12);

    std::vector<bokeh_test::DeepPixel> px(48 * 48);
    for (int i = 0; i < 48 * 48; ++i)
        px[size_t(i)] = { { 0.1, 0.1, 0.1, 0.5, 1.0, 1.0 } };
    px[24 * 48 + 24].push_back({ 50.0, 50.0, 50.0, 1.0, 5.0, 5.0 });  // between the rungs at 1 and 12
    px[0].push_back({ 0.1, 0.1, 0.1, 1.0, 12.0, 12.0 });
    const OIIO::ImageBuf deep = bokeh_test::make_deep(48, 48, px);
    DefocusOptions d = with_lens(direct_options(DefocusMethod::Layers, Border::Clamp), LensPreset::Achromat);
    d.layers         = 3;
    run_defocus(deep, d, &rep);
    std::printf("[ figures  ] deep, 3 layers (%.1f, %.1f, %.1f px): %lld sprites, %lld drawn\n",
                rep.layer_coc_px.at(0), rep.layer_coc_px.at(1), rep.layer_coc_px.at(2),
                static_cast<long long>(rep.sprites), static_cast<long long>(rep.sprites_drawn));
    EXPECT_TRUE(std::none_of(rep.layer_coc_px.begin(), rep.layer_coc_px.end(), [](float r) { return r == 5.0f; }))
        << "the light lies between two rungs";
    EXPECT_EQ(rep.sprites, 1);
    EXPECT_EQ(rep.sprites_drawn, 1);
}

TEST(DefocusSprites, NearerSharpForegroundHidesASprite)
{
    // A 1e4 light at CoC 24 behind an in-focus (CoC 0) opaque grey 0.3 card over x >= 40:
    // the light's sprite reaches to x = 42 and more, but every card pixel 7 px or more from
    // the card's edges stays 0.3 (1e-5), while the light shows left of the card. (The lens's
    // in-focus PSF, its axial colour, softens and tints the card's own edges over a pixel
    // or two: InFocusLayersTakeTheLensPsf.)
    const OIIO::ImageBuf src = make_image(96, 64, [](int x, int y) {
        Px p;
        p.z = 24.0f;
        if (x == 30 && y == 32)
            p.r = p.g = p.b = 1e4f;
        if (x >= 40)
            p.r = p.g = p.b = 0.3f, p.z = 0.0f;
        return p;
    }, 0, 0, OIIO::ROI(-32, 128, -32, 96));
    for (DefocusMethod m : { DefocusMethod::Layers, DefocusMethod::Reference }) {
        SCOPED_TRACE(method_name(m));
        DefocusReport rep;
        const OIIO::ImageBuf out
            = run_defocus(src, with_lens(direct_options(m, Border::Black), LensPreset::Uncorrected), &rep);
        EXPECT_EQ(rep.sprites, 1);
        double card = 0.0, left = 0.0;
        for (int y = 0; y < 64; ++y) {
            for (int x = 47; x < 89 && y >= 7 && y < 57; ++x)
                card = std::max(card, double(std::abs(at(out, x, y, 0) - 0.3f)));
            for (int x = 0; x < 40; ++x)
                left += at(out, x, y, 0);
        }
        EXPECT_LT(card, 1e-5) << "the sprite shows through the card";
        EXPECT_GT(left, 0.5 * 1e4) << "the light's visible part";
    }
}

TEST(DefocusSprites, ASpriteIsOccludedAsItsLayerIs)
{
    // A light of 100 at CoC 12 on a dim wall, 4 px left of an in-focus opaque card over
    // x >= 24: the card hides the right part of the light's disk. With lens character
    // and the lens off, the light is a sprite drawn with the aperture's PSF; it must come
    // out as the plain layers draw it, divided by the layer's visibility as the layer's
    // own colour is (the layered model continues a layer under a nearer one's blurred
    // edge). Measured against the plain defocus over the wall left of the card: the
    // light's energy within 2 % and no pixel off by more than 10 % of the light's peak
    // (measured 0.06 % and 7.6 %, at the disk's anti-aliased rim, where the lens-off PSF
    // and the aperture's kernel differ: LensPsf.OffIsTheFlatDiskKernel). Not divided by
    // the visibility the sprite came out 19 % short, its worst pixel 45 % of the peak.
    const OIIO::ImageBuf src = make_image(64, 48, [](int x, int y) {
        Px p;
        p.r = p.g = p.b = 0.02f;
        p.z             = 12.0f;
        if (x == 20 && y == 24)
            p.r = p.g = p.b = 100.0f;
        if (x >= 24)
            p.r = p.g = p.b = 0.3f, p.z = 0.0f;
        return p;
    }, 0, 0, OIIO::ROI(-16, 80, -16, 64));
    for (DefocusMethod m : { DefocusMethod::Layers, DefocusMethod::Reference }) {
        SCOPED_TRACE(method_name(m));
        DefocusOptions plain = direct_options(m, Border::Black), lens = with_lens(plain, LensPreset::Off);
        DefocusReport rep;
        const OIIO::ImageBuf a = run_defocus(src, plain), b = run_defocus(src, lens, &rep);
        EXPECT_EQ(rep.sprites, 1);
        double sum_a = 0.0, sum_b = 0.0, worst = 0.0, peak = 0.0;
        for (int y = 0; y < 48; ++y)
            for (int x = 0; x < 24; ++x) {
                sum_a += at(a, x, y, 0) - 0.02;
                sum_b += at(b, x, y, 0) - 0.02;
                worst = std::max(worst, double(std::abs(at(a, x, y, 0) - at(b, x, y, 0))));
                peak  = std::max(peak, double(at(a, x, y, 0)));
            }
        std::printf("%s: the light left of the card %.3f plain, %.3f as a sprite; worst pixel %.4f of peak %.3f\n",
                    method_name(m), sum_a, sum_b, worst, peak);
        EXPECT_NEAR(sum_b / sum_a, 1.0, 0.02);
        EXPECT_LT(worst, 0.1 * peak);
    }
}

TEST(DefocusSprites, InFocusLayersTakeTheLensPsf)
{
    // A dim texture in focus (CoC 0, no highlights): with lens character each channel is the
    // texture convolved with that channel of the lens's PSF at CoC 0 (the uncorrected
    // singlet's axial colour, 1/40 mm pixels: a blur of several pixels), edges clamped.
    // The layers trim the PSF's faint tail (1e-4 of its light) and renormalise; so within
    // 1e-4 of the texture's range. The scatter reference agrees within the same. Alpha
    // stays 1. Lens off, the texture is unchanged.
    const int w = 48, h = 40;
    const OIIO::ImageBuf src = make_image(w, h, [](int x, int y) {
        Px p;
        p.r = 0.5f * hash01(x, y), p.g = 0.5f * hash01(y, x + 7), p.b = 0.5f * hash01(x + 3, y + 5);
        return p;
    });
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Clamp), LensPreset::Uncorrected);
    o.coc.lens.sensor_width_mm      = 48.0 / 40.0;  // pitch 1/40 mm
    LensCharacter lens;
    lens.preset         = LensPreset::Uncorrected;
    lens.fstop          = o.coc.lens.fstop;
    lens.focal_mm       = o.coc.lens.focal_mm;
    lens.pixel_pitch_mm = 1.0 / 40.0;
    Psf psf;
    std::string err;
    ASSERT_TRUE(lens_psf(psf, lens, PsfRequest{ 0.0, 0.0, 0.0, 0 }, err)) << err;
    ASSERT_GE(psf.width, 7) << "the in-focus PSF should spread over pixels";
    const int hw = psf.width / 2, hh = psf.height / 2;
    DefocusReport rep;
    const OIIO::ImageBuf out = run_defocus(src, o, &rep);
    EXPECT_EQ(rep.sprites, 0);
    OIIO::ImageBuf ref;
    ASSERT_TRUE(defocus_scatter_reference(ref, src, o)) << ref.geterror();
    double worst = 0.0, worst_ref = 0.0, worst_alpha = 0.0, moved = 0.0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            for (int c = 0; c < 3; ++c) {
                double want = 0.0;
                for (int j = 0; j < psf.height; ++j)
                    for (int i = 0; i < psf.width; ++i) {
                        const int sx = std::clamp(x - (i - hw), 0, w - 1), sy = std::clamp(y - (j - hh), 0, h - 1);
                        want += double(psf.at(i, j, c)) * at(src, sx, sy, c);
                    }
                worst     = std::max(worst, std::abs(at(out, x, y, c) - want));
                worst_ref = std::max(worst_ref, double(std::abs(at(out, x, y, c) - at(ref, x, y, c))));
                moved     = std::max(moved, double(std::abs(at(out, x, y, c) - at(src, x, y, c))));
            }
            worst_alpha = std::max(worst_alpha, double(std::abs(at(out, x, y, 3) - 1.0f)));
        }
    std::printf("in-focus lens layer: worst %.2e against the convolution, %.2e against the scatter reference, "
                "alpha %.2e, largest change %.3f\n", worst, worst_ref, worst_alpha, moved);
    EXPECT_LT(worst, 0.5e-4);
    EXPECT_LT(worst_ref, 0.5e-4);
    EXPECT_LT(worst_alpha, 1e-5);
    EXPECT_GT(moved, 0.05) << "the lens's in-focus blur is visible";
    const OIIO::ImageBuf plain = run_defocus(src, direct_options(DefocusMethod::Layers, Border::Clamp));
    double plain_moved = 0.0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int c = 0; c < 4; ++c)
                plain_moved = std::max(plain_moved, double(std::abs(at(plain, x, y, c) - at(src, x, y, c))));
    EXPECT_LT(plain_moved, 1e-6) << "lens off: the in-focus texture stays sharp";
}

TEST(DefocusSprites, SharedPsfCacheChangesNoResult)
{
    // The process keeps each lens's PSFs across calls (shared_psf_cache): a second frame
    // with the same lens, and one after the caches are dropped, are bit for bit the first,
    // on 1 and 2 threads; the same lens gets the same cache, another lens (one field
    // changed) its own.
    const OIIO::ImageBuf src = lights_scene();
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.diffraction = DiffractionModel::EdgeLaw;
    clear_shared_psf_caches();
    const OIIO::ImageBuf cold = run_defocus(src, o);
    OIIO::ImageBuf warm, warm1;
    ASSERT_TRUE(defocus(warm, src, o, nullptr, 2)) << warm.geterror();
    ASSERT_TRUE(defocus(warm1, src, o, nullptr, 1)) << warm1.geterror();
    clear_shared_psf_caches();
    const OIIO::ImageBuf again = run_defocus(src, o);
    EXPECT_TRUE(bit_identical(cold, warm));
    EXPECT_TRUE(bit_identical(cold, warm1));
    EXPECT_TRUE(bit_identical(cold, again));

    LensCharacter lens;
    lens.preset = LensPreset::Achromat;
    const std::shared_ptr<PsfCache> a = shared_psf_cache(lens, 1), b = shared_psf_cache(lens, 2);
    EXPECT_EQ(a, b);
    LensCharacter other = lens;
    other.onion_offset = 0.5;
    EXPECT_FALSE(same_lens(lens, other));
    EXPECT_NE(shared_psf_cache(other, 1), a);
    std::string err;
    Kernel hexagonal;
    hexagonal.shape = KernelShape::Polygon;
    ASSERT_TRUE(Aperture::from_kernel(hexagonal, other.aperture, err)) << err;
    other.onion_offset = lens.onion_offset;
    EXPECT_FALSE(same_lens(lens, other));
    EXPECT_TRUE(same_lens(lens, LensCharacter(lens)));
}

TEST(DefocusSprites, DeepInputGetsSprites)
{
    // A deep 48 x 48: a grey card (alpha 0.5, CoC 2) in front of a light of 1e3 at CoC 12 in
    // the middle: one sprite, in its own layer; the colour's sum is the card's and half
    // the light's, which shows through the card (1e-4; clamp: the uniform card keeps its
    // sum at the frame's edges, and the light's bokeh stays inside).
    std::vector<bokeh_test::DeepPixel> px(48 * 48);
    for (int y = 0; y < 48; ++y)
        for (int x = 0; x < 48; ++x) {
            bokeh_test::DeepPixel& p = px[size_t(y) * 48 + size_t(x)];
            p.push_back({ 0.05, 0.05, 0.05, 0.5, 2.0, 2.0 });
            if (x == 24 && y == 24)
                p.push_back({ 1e3, 1e3, 1e3, 1.0, 12.0, 12.0 });
        }
    const OIIO::ImageBuf deep = bokeh_test::make_deep(48, 48, px);
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Auto, Border::Clamp), LensPreset::Achromat);
    DefocusReport rep;
    const OIIO::ImageBuf out = run_defocus(deep, o, &rep);
    EXPECT_EQ(rep.sprites, 1);
    EXPECT_FLOAT_EQ(rep.sprite_max_coc_px, 12.0f);
    const double in = 48.0 * 48.0 * 0.05 + 0.5 * 1e3;  // the card's, and the light's half through it
    EXPECT_NEAR(channel_sum(out, 0) / in, 1.0, 1e-4);
    DefocusOptions deep_out = o;
    deep_out.deep_output    = true;
    OIIO::ImageBuf as_deep = run_defocus(deep, deep_out), flat;
    ASSERT_TRUE(deep_flatten(flat, as_deep, {}));
    EXPECT_NEAR(channel_sum(flat, 0) / in, 1.0, 1e-4) << "the deep result's flatten";
    // Pseudo-high resolution from deep input: twice the size, the same radiance (sum / 4);
    // a deep result is not supersampled.
    DefocusOptions fine = o;
    fine.supersample    = 2;
    const OIIO::ImageBuf big = run_defocus(deep, fine, &rep);
    EXPECT_EQ(big.roi().width(), 2 * out.roi().width());
    EXPECT_EQ(big.spec().full_width, 2 * deep.spec().full_width);
    EXPECT_EQ(rep.sprites, 1);
    EXPECT_NEAR(channel_sum(big, 0) / 4.0 / in, 1.0, 1e-4) << "supersample 2";
    fine.deep_output = true;
    OIIO::ImageBuf refused;
    EXPECT_FALSE(defocus(refused, deep, fine));
    EXPECT_NE(refused.geterror().find("supersample"), std::string::npos) << refused.geterror();
}

TEST(DefocusSprites, HybridAgainstTheScatterReference)
{
    // The brute force (every pixel its own PSF, the layered model's occlusion) against the
    // hybrid on the lights scene. Lens off, the reference is the layered reference but for
    // the PSFs: they agree in energy (which the visibility division and the border rule
    // change alike in both), and in PSNR as the PSFs' rims do (measured 35.2 dB; the
    // hybrid 35.7 lens off, 36.4 achromat, its CoC bins crossfaded). Achromat: the hybrid
    // draws the lights with the lens, the dim floor keeps the plain aperture.
    const OIIO::ImageBuf src = lights_scene();
    for (LensPreset preset : { LensPreset::Off, LensPreset::Achromat }) {
        SCOPED_TRACE(lens_preset_name(preset));
        const DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), preset);
        OIIO::ImageBuf ref;
        ASSERT_TRUE(defocus_scatter_reference(ref, src, o)) << ref.geterror();
        const OIIO::ImageBuf out = run_defocus(src, o);
        ImageError e;
        std::string err;
        ASSERT_TRUE(compare(e, out, ref, err)) << err;
        std::printf("[ figures  ] hybrid vs scatter reference, %s: PSNR %.1f dB\n", lens_preset_name(preset),
                    e.psnr_db);
        EXPECT_GT(e.psnr_db, 35.0);
        if (preset == LensPreset::Off) {
            DefocusOptions layered = direct_options(DefocusMethod::Reference, Border::Black);
            const OIIO::ImageBuf model = run_defocus(src, layered);
            ImageError em;
            ASSERT_TRUE(compare(em, model, ref, err)) << err;
            std::printf("[ figures  ] layered reference vs scatter reference, lens off: PSNR %.1f dB\n", em.psnr_db);
            EXPECT_GT(em.psnr_db, 34.0);
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(channel_sum(ref, c) / channel_sum(model, c), 1.0, 1e-3) << "energy against the model's";
        }
    }
}

namespace {

// The 2 x 2 box mean of a supersampled result over the frame's pixels of `frame` (for
// comparing it with the plain resolution's; 0 past big's data window).
OIIO::ImageBuf box_reduced(const OIIO::ImageBuf& big, const OIIO::ROI& frame)
{
    const OIIO::ROI r(2 * frame.xbegin, 2 * frame.xend, 2 * frame.ybegin, 2 * frame.yend);
    return make_image(r.width() / 2, r.height() / 2, [&](int x, int y) {
        float v[3] = { 0, 0, 0 };
        for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx)
                for (int c = 0; c < 3; ++c)
                    v[c] += 0.25f * at(big, r.xbegin + 2 * x + dx, r.ybegin + 2 * y + dy, c);
        Px p;
        p.r = v[0], p.g = v[1], p.b = v[2];
        return p;
    });
}

}  // namespace

TEST(DefocusSprites, SupersampleDoublesTheOutputAndKeepsEnergy)
{
    // supersample=2 on the lights scene: the display window is twice the plain result's,
    // the data window too within 2 output px a side (it reaches as far as the sprites' PSFs
    // do, and at the output's CoC they are other points of the CoC grid), each output pixel
    // radiance (the sum is 4 times the input's, each channel within 1e-4: the plain one's
    // conservation), for lens off, achromat and uncorrected.
    const OIIO::ImageBuf src = lights_scene();
    for (LensPreset preset : { LensPreset::Off, LensPreset::Achromat, LensPreset::Uncorrected }) {
        SCOPED_TRACE(lens_preset_name(preset));
        DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), preset);
        const OIIO::ImageBuf plain = run_defocus(src, o);
        o.supersample = 2;
        DefocusReport rep;
        const OIIO::ImageBuf big = run_defocus(src, o, &rep);
        const OIIO::ROI p = plain.roi(), b = big.roi();
        EXPECT_NEAR(b.xbegin, 2 * p.xbegin, 2);
        EXPECT_NEAR(b.xend, 2 * p.xend, 2);
        EXPECT_NEAR(b.ybegin, 2 * p.ybegin, 2);
        EXPECT_NEAR(b.yend, 2 * p.yend, 2);
        EXPECT_EQ(big.spec().full_x, 2 * src.spec().full_x);
        EXPECT_EQ(big.spec().full_width, 2 * src.spec().full_width);
        EXPECT_EQ(big.spec().full_height, 2 * src.spec().full_height);
        EXPECT_EQ(rep.sprites, 12);
        for (int c = 0; c < 3; ++c) {
            const double in = channel_sum(src, c), out = channel_sum(big, c) / 4.0;
            std::printf("[ figures  ] supersample 2, %-11s channel %d: in %.6g, out / 4 %.6g (%.2e)\n",
                        lens_preset_name(preset), c, in, out, out / in - 1.0);
            EXPECT_NEAR(out / in, 1.0, 1e-4);
        }
        // Sane against the plain resolution: its 2 x 2 means are the plain result but for
        // the layers' bilinear enlargement and the sprites' finer sampling.
        ImageError e;
        std::string err;
        ASSERT_TRUE(compare(e, box_reduced(big, p), make_image(p.width(), p.height(), [&](int x, int y) {
                                Px q;
                                q.r = at(plain, p.xbegin + x, p.ybegin + y, 0);
                                q.g = at(plain, p.xbegin + x, p.ybegin + y, 1);
                                q.b = at(plain, p.xbegin + x, p.ybegin + y, 2);
                                return q;
                            }),
                            err))
            << err;
        std::printf("[ figures  ] supersample 2, %-11s: its 2x2 means vs the plain resolution: PSNR %.1f dB\n",
                    lens_preset_name(preset), e.psnr_db);
        EXPECT_GT(e.psnr_db, 35.0);
    }
}

TEST(DefocusSprites, SupersampledLonePixelIsTheFinerPsf)
{
    // The lone 1e6 pixel at CoC 32 px with supersample=2: one sprite, the lens PSF at CoC
    // 64 output px (the output's pixel pitch, half the frame's), box-folded so that it is
    // centred on the frame pixel's centre (the corner of its 2 x 2 output pixels): each
    // output pixel within 1e-5 of the peak, each channel's sum 4e6 (1e-5).
    const OIIO::ROI display(-48, 113, -48, 113);
    const OIIO::ImageBuf src = lone_light(65, 65, 32, 32, 32.0f, display);
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.diffraction = DiffractionModel::EdgeLaw;
    o.supersample      = 2;
    DefocusReport rep;
    const OIIO::ImageBuf out = run_defocus(src, o, &rep);
    EXPECT_EQ(rep.sprites, 1);

    float peak;
    const Psf psf = sprite_psf(o, 2 * display.width(), 64.0, peak);
    ASSERT_GT(psf.width, 0);
    // Output pixel (X, Y) covers [X/2, X/2 + 1/2) in frame units; the frame pixel 32's
    // centre is output coordinate 65, the corner of output pixels 64 and 65.
    auto folded = [&](int X, int Y, int c) {
        double v = 0.0;
        for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx)
                v += 0.25 * psf_at(psf, X - dx - 64, Y - dy - 64, c);
        return v;
    };
    double worst = 0.0;
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(channel_sum(out, c) / 4e6, 1.0, 1e-5) << "channel " << c;
        for (int y = 2 * -48; y < 2 * 113; ++y)
            for (int x = 2 * -48; x < 2 * 113; ++x)
                worst = std::max(worst, ramp_error(at(out, x, y, c), 4e6 * folded(x, y, c), 4e6 * peak));
    }
    std::printf("[ figures  ] supersampled lone pixel: PSF %dx%d at CoC 64, largest difference %.2e of the "
                "pixel's value\n",
                psf.width, psf.height, worst);
    EXPECT_LT(worst, kRampBound);
    // Centred: the light's centroid is the frame pixel's centre, output coordinate 65.
    double sx = 0.0, sy = 0.0, sw = 0.0;
    const OIIO::ROI r = out.roi();
    for (int y = r.ybegin; y < r.yend; ++y)
        for (int x = r.xbegin; x < r.xend; ++x) {
            const double v = at(out, x, y, 1);
            sx += v * (x + 0.5), sy += v * (y + 0.5), sw += v;
        }
    EXPECT_NEAR(sx / sw, 65.0, 1e-3);
    EXPECT_NEAR(sy / sw, 65.0, 1e-3);
}

TEST(DefocusSprites, BadOptionsRefusedByName)
{
    const OIIO::ImageBuf src = lights_scene();
    auto refused = [&](DefocusOptions o, const char* word) {
        OIIO::ImageBuf dst;
        EXPECT_FALSE(defocus(dst, src, o));
        EXPECT_NE(dst.geterror().find(word), std::string::npos) << dst.geterror();
    };
    DefocusOptions o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.highlight_threshold = 0.0f;
    refused(o, "threshold");
    o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.max_sprites = -1;
    refused(o, "sprites");
    refused(with_lens(direct_options(DefocusMethod::Gather, Border::Black), LensPreset::Achromat), "gather");
    o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.onion = 2.0;
    refused(o, "onion");
    o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.lens.lateral_r_px = 2.0;
    refused(o, "lens_distort");
    o = with_lens(direct_options(DefocusMethod::Layers, Border::Black), LensPreset::Achromat);
    o.supersample = 3;
    refused(o, "supersample");
    o.supersample = 2;
    o.method      = DefocusMethod::Gather;
    o.lens_character = false;
    refused(o, "gather");
}
