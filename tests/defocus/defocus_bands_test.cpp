// A flat defocus over its memory budget drawn in bands of output rows
// (core/defocus/defocus_bands.cpp), against the same defocus drawn at once: the same bits
// where no background is continued (lens character's sprites included), the continuation
// close, the counts the same, and what cannot be banded refused with the reason.

#include "test_util.h"

#include <bokeh/defocus.h>
#include <bokeh/scene.h>

#include <gtest/gtest.h>

#include <OpenImageIO/imagebufalgo.h>

#include <cmath>
#include <cstdio>
#include <limits>

using namespace bokeh;
using namespace bokeh_test;

namespace {

OIIO::ImageBuf lights_scene(int w, int h)
{
    SceneOptions so;
    so.width  = w;
    so.height = h;
    so.aa     = 1;
    OIIO::ImageBuf s;
    EXPECT_TRUE(make_scene(s, "lights", so)) << s.geterror();
    return s;
}

// The scene's own lens and focus, and a budget that holds the result and a band of about
// a third of the frame's rows (the frame at once needs 58 bytes a pixel: 26 a source
// pixel, 32 an output pixel; the result alone 16).
DefocusOptions banded_options(const OIIO::ImageBuf& s)
{
    DefocusOptions o      = scene_lens(s.spec());
    o.memory_budget_bytes = int64_t(s.spec().width) * s.spec().height * 40;
    return o;
}

}  // namespace

TEST(DefocusBands, TheSamePixelsAsAtOnceWhereNoBackgroundIsContinued)
{
    OIIO::ImageBuf s = lights_scene(480, 270);
    // Non-finite values in a band's reach and in its own rows: each counted once.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (int y : { 5, 131, 140, 266 }) {
        s.setpixel(100, y, std::vector<float>{ nan, 0.5f, 0.5f, 1.0f, 8.0f }.data());
        s.setpixel(300, y, std::vector<float>{ 0.5f, 0.5f, 0.5f, 1.0f, nan }.data());
    }
    // A data window inside the display window: the output grows past it, and the bands
    // start on the output's rows, not the data's.
    const OIIO::ImageBuf inner = OIIO::ImageBufAlgo::copy(s, OIIO::TypeUnknown, OIIO::ROI(37, 451, 21, 250));
    struct Case {
        const char* name;
        const OIIO::ImageBuf* src;
        DefocusMethod method;
        int supersample, dilate_px;
        int64_t nonfinite;  // of each kind, in the source's data window
        int max_sprites = 0;  // lens character with at most this many sprites (0: off)
        float iris      = 0.0f;
    };
    // Lens character's bands lie on its lens layers' grid of 256 rows: a taller frame, and a
    // budget (50 bytes a pixel) that holds a band of 256 rows beside the result.
    const OIIO::ImageBuf big = lights_scene(960, 540);
    for (const Case& c : { Case{ "layers", &s, DefocusMethod::Layers, 1, 0, 4 },
                           Case{ "layers, supersample 2, dilation 2", &s, DefocusMethod::Layers, 2, 2, 4 },
                           Case{ "reference", &s, DefocusMethod::Reference, 1, 0, 4 },
                           Case{ "layers, a data window inside the display window", &inner, DefocusMethod::Layers,
                                 1, 0, 2 },
                           Case{ "lens character, all highlights", &big, DefocusMethod::Layers, 1, 0, 0, 20000 },
                           Case{ "lens character, the 40 brightest", &big, DefocusMethod::Layers, 1, 0, 0, 40 },
                           Case{ "iris mode", &s, DefocusMethod::Layers, 1, 0, 4, 0, 0.1f },
                           Case{ "iris mode and lens character", &big, DefocusMethod::Layers, 1, 0, 0, 40, 0.1f } }) {
        SCOPED_TRACE(c.name);
        DefocusOptions o   = banded_options(s);
        o.fill             = DisocclusionFill::Foreground;
        o.method           = c.method;
        o.supersample      = c.supersample;
        o.depth_dilate_px  = c.dilate_px;
        o.lens_character   = c.max_sprites > 0;
        o.iris             = c.iris;
        o.max_sprites      = c.max_sprites > 0 ? c.max_sprites : o.max_sprites;
        if (c.supersample == 2)  // the result is 4 times larger (64 bytes a source pixel)
            o.memory_budget_bytes = int64_t(480) * 270 * 120;
        if (c.max_sprites > 0)
            o.memory_budget_bytes = int64_t(960) * 540 * 50;
        if (c.iris != 0.0f)  // the linear colour kept beside the exp space: 16 bytes a pixel more
            o.memory_budget_bytes += int64_t(c.src->spec().width) * c.src->spec().height * 20;
        DefocusReport banded, whole;
        const OIIO::ImageBuf b = run_defocus(*c.src, o, &banded);
        o.memory_budget_bytes  = 0;
        const OIIO::ImageBuf a = run_defocus(*c.src, o, &whole);
        std::printf("[ figures  ] %s: %d bands of %d rows, %zu layers\n", c.name, banded.bands, banded.band_rows,
                    banded.layer_coc_px.size());
        EXPECT_GE(banded.bands, 2) << banded.summary;
        EXPECT_EQ(whole.bands, 1);
        EXPECT_EQ(a.roi(), b.roi());
        EXPECT_EQ(error_of(b, a).max_abs, 0.0) << "the same bits";
        EXPECT_EQ(banded.layer_coc_px, whole.layer_coc_px);
        EXPECT_EQ(banded.layer_reduction, whole.layer_reduction);
        EXPECT_EQ(banded.nonfinite.colour, c.nonfinite);
        EXPECT_EQ(banded.nonfinite.depth, c.nonfinite);
        EXPECT_EQ(banded.fill_foreground_px, whole.fill_foreground_px);
        EXPECT_EQ(banded.sprites, whole.sprites);
        EXPECT_EQ(banded.sprite_candidates, whole.sprite_candidates);
        EXPECT_EQ(banded.sprites_drawn, whole.sprites_drawn);
        if (c.max_sprites > 0) {
            EXPECT_GT(whole.sprites, 0) << whole.summary;
            std::printf("[ figures  ]   %lld sprites of %lld highlights, %lld drawn (at once: %lld)\n",
                        (long long)banded.sprites, (long long)banded.sprite_candidates,
                        (long long)banded.sprites_drawn, (long long)whole.sprites_drawn);
        }
        EXPECT_NE(banded.summary.find(" bands of "), std::string::npos) << banded.summary;
        if (c.method == DefocusMethod::Layers && c.supersample == 1 && c.src == &s) {
            o.memory_budget_bytes         = banded_options(s).memory_budget_bytes;
            const OIIO::ImageBuf one_thread = run_defocus(s, o, nullptr, 1);
            EXPECT_EQ(error_of(one_thread, b).max_abs, 0.0) << "the same bits on one thread as on all";
        }
    }
}

TEST(DefocusBands, ASpritesGainFloorIsTheWholeFramesInEveryBand)
{
    // A layer's sprite gain floor (core/defocus/defocus_sprites.cpp, sprite_gain_floors)
    // depends on every sprite the layer holds, wherever it is in the frame: a band must use
    // the frame's, not its own rows'. CoC in px (direct), a ladder of ratio 2 (rungs 0, 1,
    // 2, 4, 8, 16 and the extreme 20). At the top a light at CoC 18, drawn in rung 16 with
    // its wider PSF: that layer's floor. At the bottom a light at CoC 16 (rung 16 alone)
    // against the edge of a card at CoC -30: near its disk's rim over the card, layer 16's
    // visibility falls under the floor where the card's wide blurred edge still lets the
    // light through. A band holding the bottom light but not the top one would divide by
    // less (measured: 1.39 off at most, where the frame's floor gives the same bits).
    const int w = 640, h = 640;
    const OIIO::ImageBuf src = make_image(w, h, [](int x, int y) {
        Px p;
        p.r = p.g = p.b = 0.2f;
        p.z             = 20.0f;  // the background
        if (x == 100 && y == 60)
            p.r = p.g = p.b = 50.0f, p.z = 18.0f;
        if (x == 316 && y == 520)
            p.r = p.g = p.b = 50.0f, p.z = 16.0f;
        if (x >= 317 && y >= 440 && y < 600)
            p.r = 0.6f, p.g = 0.3f, p.b = 0.1f, p.z = -30.0f;
        return p;
    });
    DefocusOptions o        = direct_options(DefocusMethod::Layers, Border::Clamp);
    o.ladder_ratio          = 2.0f;
    o.lens_character        = true;
    o.fill                  = DisocclusionFill::Foreground;
    o.memory_budget_bytes   = int64_t(w) * h * 50;
    DefocusReport banded, whole;
    const OIIO::ImageBuf b = run_defocus(src, o, &banded);
    o.memory_budget_bytes  = 0;
    const OIIO::ImageBuf a = run_defocus(src, o, &whole);
    std::printf("[ figures  ] %d bands of %d rows; %lld sprites; rungs", banded.bands, banded.band_rows,
                (long long)whole.sprites);
    for (float c : whole.layer_coc_px)
        std::printf(" %g", c);
    std::printf("\n");
    ASSERT_GE(banded.bands, 2) << banded.summary;
    EXPECT_EQ(whole.sprites, 2) << whole.summary;
    EXPECT_EQ(banded.layer_coc_px, whole.layer_coc_px);
    EXPECT_EQ(error_of(b, a).max_abs, 0.0) << "the same bits";
}

TEST(DefocusBands, TheContinuedBackgroundStaysCloseToTheFrameAtOnce)
{
    // Each band's plate is built from its own rows, so a continuation may differ from the
    // frame's where a coarse cell reaches past them.
    const OIIO::ImageBuf s = lights_scene(480, 270);
    for (DisocclusionFill fill : { DisocclusionFill::Smooth, DisocclusionFill::Mirror }) {
        DefocusOptions o = banded_options(s);
        o.fill           = fill;
        DefocusReport banded, whole;
        const OIIO::ImageBuf b = run_defocus(s, o, &banded);
        o.memory_budget_bytes  = 0;
        const OIIO::ImageBuf a = run_defocus(s, o, &whole);
        const ImageError e     = error_of(b, a);
        std::printf("[ figures  ] fill %d: %d bands, banded against at once %.1f dB, max %.3g; continued %lld "
                    "against %lld px\n",
                    int(fill), banded.bands, e.psnr_db, e.max_abs, (long long)banded.fill_continued_px,
                    (long long)whole.fill_continued_px);
        EXPECT_GE(banded.bands, 2);
        EXPECT_GT(whole.fill_continued_px, 0) << "the scene has background to continue";
        EXPECT_GE(e.psnr_db, 60.0);
        EXPECT_EQ(banded.fill_continued_px + banded.fill_foreground_px,
                  whole.fill_continued_px + whole.fill_foreground_px);
    }
}

TEST(DefocusBands, WhatCannotBeBandedIsRefusedWithTheReason)
{
    const OIIO::ImageBuf s = lights_scene(240, 135);
    auto refused = [&](DefocusOptions o, const std::string& why) {
        OIIO::ImageBuf dst;
        EXPECT_FALSE(defocus(dst, s, o)) << why;
        const std::string err = dst.geterror();
        EXPECT_NE(err.find("over the memory budget of"), std::string::npos) << err;
        EXPECT_NE(err.find(why), std::string::npos) << err;
    };
    DefocusOptions o = banded_options(s);
    DefocusOptions gather = o;
    gather.method         = DefocusMethod::Gather;
    refused(gather, "the gather method");
    DefocusOptions predicted = o;
    predicted.planner        = DefocusPlanner::Predicted;
    refused(predicted, "the predicted planner");
    // Iris mode past its exponent's range: the frame's own error, banded or not.
    DefocusOptions iris = o;
    iris.iris           = 0.5f;
    std::vector<std::string> errors;
    for (int64_t budget : { o.memory_budget_bytes, int64_t(0) }) {
        iris.memory_budget_bytes = budget;
        OIIO::ImageBuf dst;
        EXPECT_FALSE(defocus(dst, s, iris));
        errors.push_back(dst.geterror());
    }
    EXPECT_NE(errors[0].find("iris 0.5 times channel R's range "), std::string::npos) << errors[0];
    EXPECT_EQ(errors[0], errors[1]);
    // Less than the result itself: no band fits.
    DefocusOptions tiny     = o;
    tiny.memory_budget_bytes = int64_t(240) * 135 * 8;
    refused(tiny, "the defocus of 240x135 pixels in bands of ");
}
