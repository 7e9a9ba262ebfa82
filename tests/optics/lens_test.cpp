// Thin-lens CoC, depth interpretation, CoC options and the CoC diagnostics (lens.h).
#include <bokeh/lens.h>

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include <OpenImageIO/imagebufalgo.h>

#include "test_util.h"

using namespace bokeh;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The lens of the hand computation: 50 mm, f/2, focus 2 m, full-frame 36 mm sensor.
Lens hand_lens()
{
    Lens l;
    l.focal_mm        = 50.0;
    l.fstop           = 2.0;
    l.sensor_width_mm = 36.0;
    l.focus_distance  = 2.0;
    l.depth_unit_mm   = 1000.0;
    return l;
}

// f^2 / (F (d0 - f)) / (sensor / width) = 2500 / (2 * 1950) / (36 / 1920).
constexpr double kHandCocPx = 2500.0 / (2.0 * 1950.0) / (36.0 / 1920.0);  // 34.188 px

// A float R, G, B, A, Z image (alpha_channel 3, z_channel 4) over a w x h data window at
// (x0, y0), with display window `full` (default: the data window); colour grey 0.5.
OIIO::ImageBuf rgbaz(int w, int h, const std::function<float(int, int)>& z, int x0 = 0, int y0 = 0,
                     OIIO::ROI full = {})
{
    return bokeh_test::rgbaz_image(
        w, h, [&](int x, int y) { return std::array<float, 5>{ 0.5f, 0.5f, 0.5f, 1.0f, z(x, y) }; },
        x0, y0, full);
}

CocOptions depth_options(double focus_m = 5.0)
{
    CocOptions o;
    o.lens                = hand_lens();
    o.lens.focus_distance = focus_m;
    o.mode                = DepthMode::Depth;
    return o;
}

}  // namespace

// --- thin lens ---------------------------------------------------------------------------

TEST(LensThin, CocMatchesTheHandComputation)
{
    const Lens l = hand_lens();
    // Expected figures: +34.188 px at infinity, -34.188 px at 1 m, 0 at the focus.
    EXPECT_NEAR(kHandCocPx, 34.188, 1e-3) << "the hand computation itself";
    EXPECT_NEAR(thin_lens_coc_px(l, kInf, 1920), 34.188, 1e-3);
    EXPECT_NEAR(thin_lens_coc_px(l, 1.0, 1920), -34.188, 1e-3);
    EXPECT_NEAR(thin_lens_coc_px(l, 2.0, 1920), 0.0, 1e-3);
    // 4 m: (4 - 2) / 4 = one half of the infinity figure; half the width halves the pixels.
    EXPECT_NEAR(thin_lens_coc_px(l, 4.0, 1920), 0.5 * kHandCocPx, 1e-3);
    EXPECT_NEAR(thin_lens_coc_px(l, kInf, 960), 0.5 * kHandCocPx, 1e-3);
    // The same lens with the depth channel in centimetres.
    Lens cm          = l;
    cm.depth_unit_mm = 10.0;
    cm.focus_distance = 200.0;
    EXPECT_NEAR(thin_lens_coc_px(cm, 100.0, 1920), -34.188, 1e-3);
}

// --- depth modes -----------------------------------------------------------------------------

TEST(LensDepth, DistanceFromDepthInEveryMode)
{
    // Depth: the distance itself; 0, negative and non-finite are "no depth" (+inf).
    EXPECT_DOUBLE_EQ(distance_from_depth(4.0, DepthMode::Depth, false), 4.0);
    EXPECT_DOUBLE_EQ(distance_from_depth(-4.0, DepthMode::Depth, true), 4.0) << "negated";
    EXPECT_EQ(distance_from_depth(4.0, DepthMode::Depth, true), kInf) << "negated positive";
    for (double v : { 0.0, -0.0, -3.0, kNaN, kInf, -kInf }) {
        EXPECT_EQ(distance_from_depth(v, DepthMode::Depth, false), kInf) << v;
        EXPECT_EQ(distance_from_depth(-v, DepthMode::Depth, true), kInf) << "negate " << -v;
    }

    // InverseDepth (far = 0): 1 / distance.
    EXPECT_DOUBLE_EQ(distance_from_depth(0.25, DepthMode::InverseDepth, false), 4.0);
    EXPECT_DOUBLE_EQ(distance_from_depth(-0.25, DepthMode::InverseDepth, true), 4.0);
    EXPECT_DOUBLE_EQ(distance_from_depth(2.0, DepthMode::InverseDepth, false), 0.5);
    for (double v : { 0.0, -0.0, -0.25, kNaN, kInf, -kInf }) {
        EXPECT_EQ(distance_from_depth(v, DepthMode::InverseDepth, false), kInf) << v;
        EXPECT_EQ(distance_from_depth(-v, DepthMode::InverseDepth, true), kInf) << "negate " << -v;
    }

    // FarIsOne (far = 1): 1 - 1 / distance, so 0.75 is 4 units; 1 and beyond are infinitely
    // far; a value below 0 lies nearer than one unit.
    EXPECT_DOUBLE_EQ(distance_from_depth(0.75, DepthMode::FarIsOne, false), 4.0);
    EXPECT_DOUBLE_EQ(distance_from_depth(-0.75, DepthMode::FarIsOne, true), 4.0);
    EXPECT_DOUBLE_EQ(distance_from_depth(0.5, DepthMode::FarIsOne, false), 2.0);
    EXPECT_DOUBLE_EQ(distance_from_depth(-1.0, DepthMode::FarIsOne, false), 0.5);
    for (double v : { 1.0, 1.5, kNaN, kInf, -kInf }) {
        EXPECT_EQ(distance_from_depth(v, DepthMode::FarIsOne, false), kInf) << v;
        EXPECT_EQ(distance_from_depth(-v, DepthMode::FarIsOne, true), kInf) << "negate " << -v;
    }
}

// lens.h's file comment: "a depth of 0 or a non-finite one means 'no depth here' and is
// taken as infinitely far" — in every mode, FarIsOne included (where 1 - 1/d = 0 would
// otherwise read as 1 unit away), as the Beachball renders' empty Z = 0 pixels need.
TEST(LensDepth, ZeroIsNoDepthInEveryMode)
{
    for (DepthMode m : { DepthMode::Depth, DepthMode::InverseDepth, DepthMode::FarIsOne })
        for (bool negate : { false, true }) {
            EXPECT_EQ(distance_from_depth(0.0, m, negate), kInf)
                << "mode " << int(m) << " negate " << negate << ": got "
                << distance_from_depth(0.0, m, negate);
            EXPECT_EQ(distance_from_depth(kNaN, m, negate), kInf) << int(m);
        }
}

// --- CoC of a depth value --------------------------------------------------------------------

TEST(LensCoc, InFocusRangeGainsAndLimit)
{
    CocOptions o = depth_options(5.0);
    // Plain lens first: CocOfDepth is thin_lens_coc_px of the distance.
    {
        const CocOfDepth coc(o, 1920);
        for (double d : { 1.0, 2.5, 5.0, 7.0, 40.0 })
            EXPECT_NEAR(coc(float(d)), thin_lens_coc_px(o.lens, d, 1920), 1e-4) << d;
        EXPECT_NEAR(coc(0.0f), thin_lens_coc_px(o.lens, kInf, 1920), 1e-4) << "Z = 0 is far";
    }
    // In-focus range 2 m: 4..6 m are sharp; beyond, the distance moves 1 m toward the focus.
    o.infocus_range = 2.0;
    {
        const CocOfDepth coc(o, 1920);
        for (float d : { 4.0f, 4.5f, 5.0f, 5.9f, 6.0f })
            EXPECT_EQ(coc(d), 0.0f) << d;
        EXPECT_NEAR(coc(8.0f), thin_lens_coc_px(o.lens, 7.0, 1920), 1e-4);
        EXPECT_NEAR(coc(2.0f), thin_lens_coc_px(o.lens, 3.0, 1920), 1e-4);
        // Continuous at the range's edges: 1 mm past them the CoC is still ~0
        // (the thin lens gives about 0.003 px per mm here).
        EXPECT_NEAR(coc(6.001f), 0.0f, 0.02f);
        EXPECT_NEAR(coc(3.999f), 0.0f, 0.02f);
        EXPECT_GT(coc(6.001f), 0.0f);
        EXPECT_LT(coc(3.999f), 0.0f);
        EXPECT_NEAR(coc(0.0f), thin_lens_coc_px(o.lens, kInf, 1920), 1e-4) << "infinity stays";
    }
    o.infocus_range = 0.0;
    // Gains: front doubles the near CoC, back halves the far one.
    o.front_gain = 2.0;
    o.back_gain  = 0.5;
    {
        const CocOfDepth coc(o, 1920);
        EXPECT_NEAR(coc(2.0f), 2.0 * thin_lens_coc_px(o.lens, 2.0, 1920), 1e-4);
        EXPECT_NEAR(coc(20.0f), 0.5 * thin_lens_coc_px(o.lens, 20.0, 1920), 1e-4);
    }
    // Limit: |CoC| <= max_coc_px on both sides.
    o.front_gain = o.back_gain = 1.0;
    o.max_coc_px               = 10.0;
    {
        const CocOfDepth coc(o, 1920);
        ASSERT_LT(thin_lens_coc_px(o.lens, 1.0, 1920), -10.0);
        ASSERT_GT(thin_lens_coc_px(o.lens, 1000.0, 1920), 10.0);
        EXPECT_FLOAT_EQ(coc(1.0f), -10.0f);
        EXPECT_FLOAT_EQ(coc(1000.0f), 10.0f);
        EXPECT_NEAR(coc(5.5f), thin_lens_coc_px(o.lens, 5.5, 1920), 1e-4) << "within the limit";
    }
}

TEST(LensCoc, DirectModeScaleNegateAndNonFinite)
{
    CocOptions o;
    o.mode         = DepthMode::Direct;
    o.direct_scale = 2.0;
    {
        const CocOfDepth coc(o, 100);
        EXPECT_FLOAT_EQ(coc(3.0f), 6.0f);
        EXPECT_FLOAT_EQ(coc(-1.5f), -3.0f);
        EXPECT_FLOAT_EQ(coc(0.0f), 0.0f);
    }
    o.negate = true;
    {
        const CocOfDepth coc(o, 100);
        EXPECT_FLOAT_EQ(coc(3.0f), -6.0f);
        EXPECT_FLOAT_EQ(coc(-1.5f), 3.0f);
        // A direct CoC that is not a number means no blur (lens.cpp), not a guess.
        EXPECT_EQ(coc(std::numeric_limits<float>::quiet_NaN()), 0.0f);
        EXPECT_EQ(coc(std::numeric_limits<float>::infinity()), 0.0f);
        EXPECT_EQ(coc(-std::numeric_limits<float>::infinity()), 0.0f);
    }
    o.negate     = false;
    o.max_coc_px = 5.0;
    {
        const CocOfDepth coc(o, 100);
        EXPECT_FLOAT_EQ(coc(100.0f), 5.0f);
        EXPECT_FLOAT_EQ(coc(-100.0f), -5.0f);
    }
}

// --- resolving the options against an image ----------------------------------------------------

TEST(LensResolve, FocusAtPixelAndItsFailures)
{
    // Data window 16 x 12 at (4, 2) in a 32 x 24 display window; Z = 1 + x / 4 m,
    // with no depth (Z = 0) at (6, 5).
    const OIIO::ImageBuf img = rgbaz(
        16, 12, [](int x, int y) { return x == 6 && y == 5 ? 0.0f : 1.0f + float(x) / 4.0f; }, 4, 2,
        OIIO::ROI(0, 32, 0, 24));
    CocOptions o       = depth_options(5.0);
    o.focus_at_pixel   = true;
    o.focus_x          = 10;
    o.focus_y          = 7;
    std::string err;
    CocOptions r = o;
    ASSERT_TRUE(resolve_coc_options(r, img, err)) << err;
    EXPECT_DOUBLE_EQ(r.lens.focus_distance, 3.5) << "Z at (10, 7) is 1 + 10 / 4";

    // InverseDepth reads the same sample as 1 / Z.
    r      = o;
    r.mode = DepthMode::InverseDepth;
    ASSERT_TRUE(resolve_coc_options(r, img, err)) << err;
    EXPECT_NEAR(r.lens.focus_distance, 1.0 / 3.5, 1e-12);

    // No depth at the focus pixel.
    r         = o;
    r.focus_x = 6;
    r.focus_y = 5;
    err.clear();
    EXPECT_FALSE(resolve_coc_options(r, img, err));
    EXPECT_NE(err.find("no depth"), std::string::npos) << err;

    // Outside the data window (inside the display window) and outside everything.
    for (auto [x, y] : { std::pair{ 2, 7 }, std::pair{ 10, 14 }, std::pair{ 20, 7 }, std::pair{ -1, -1 },
                         std::pair{ 500, 500 } }) {
        r         = o;
        r.focus_x = x;
        r.focus_y = y;
        err.clear();
        EXPECT_FALSE(resolve_coc_options(r, img, err)) << x << "," << y;
        EXPECT_NE(err.find("outside"), std::string::npos) << err;
    }

    // A focus nearer than the focal length (40 mm < 50 mm), and by pixel (Z = 0.03 m).
    r = depth_options(0.04);
    err.clear();
    EXPECT_FALSE(resolve_coc_options(r, img, err));
    EXPECT_NE(err.find("focal length"), std::string::npos) << err;
    const OIIO::ImageBuf near = rgbaz(4, 4, [](int, int) { return 0.03f; });
    r                         = o;
    r.focus_x = r.focus_y = 1;
    err.clear();
    EXPECT_FALSE(resolve_coc_options(r, near, err));
    EXPECT_NE(err.find("focal length"), std::string::npos) << err;

    // An image without Z.
    OIIO::ImageSpec spec(8, 8, 4, OIIO::TypeFloat);
    spec.channelnames  = { "R", "G", "B", "A" };
    spec.alpha_channel = 3;
    const OIIO::ImageBuf noz(spec);
    r = depth_options(5.0);
    err.clear();
    EXPECT_FALSE(resolve_coc_options(r, noz, err));
    EXPECT_NE(err.find("depth"), std::string::npos) << err;
    OIIO::ImageBuf dst;
    EXPECT_FALSE(coc_map(dst, noz, r));
    EXPECT_NE(dst.geterror().find("depth"), std::string::npos);
}

// --- diagnostics -------------------------------------------------------------------------------

TEST(LensDiagnostics, CocMapChannelWindowAndValues)
{
    // Offset data window; Z from 1 m to 20 m, some Z = 0 (no depth).
    const OIIO::ROI full(0, 64, 0, 48);
    const OIIO::ImageBuf img = rgbaz(
        40, 30, [](int x, int y) { return (x + y) % 11 == 0 ? 0.0f : 1.0f + 0.4f * float(x) + 0.1f * float(y); },
        5, 3, full);
    CocOptions o = depth_options(5.0);
    OIIO::ImageBuf map;
    ASSERT_TRUE(coc_map(map, img, o)) << map.geterror();
    const OIIO::ImageSpec& s = map.spec();
    EXPECT_EQ(s.nchannels, 1);
    ASSERT_EQ(s.channelnames.size(), 1u);
    EXPECT_EQ(s.channelnames[0], "coc");
    EXPECT_EQ(s.format, OIIO::TypeFloat);
    EXPECT_EQ(map.roi(), OIIO::ROI(5, 45, 3, 33, 0, 1, 0, 1)) << "the source's data window";
    EXPECT_EQ(map.roi_full(), OIIO::ROI(0, 64, 0, 48, 0, 1, 0, 1)) << "the source's display window";
    // The values: the CoC of each pixel's depth for an image 64 px wide (display width).
    const CocOfDepth coc(o, 64);
    double worst = 0.0;
    for (int y = 3; y < 33; ++y)
        for (int x = 5; x < 45; ++x)
            worst = std::max(worst, double(std::abs(map.getchannel(x, y, 0, 0) - coc(img.getchannel(x, y, 0, 4)))));
    EXPECT_EQ(worst, 0.0) << "coc_map differs from CocOfDepth by up to " << worst << " px";
    ASSERT_EQ(img.getchannel(11, 11, 0, 4), 0.0f);
    EXPECT_NEAR(map.getchannel(11, 11, 0, 0), thin_lens_coc_px(o.lens, kInf, 64), 1e-5)
        << "(11, 11) has Z = 0: far";
}

TEST(LensDiagnostics, FocalPlaneViewColours)
{
    // Three columns of mid grey: near (1 m), at the focus (5 m), far (50 m), in an image
    // 1920 px wide (display window) so the CoCs are large: -54 px, 0, +12 px (f/2, 50 mm).
    const OIIO::ImageBuf img = rgbaz(
        3, 1, [](int x, int) { return x == 0 ? 1.0f : x == 1 ? 5.0f : 50.0f; }, 0, 0, OIIO::ROI(0, 1920, 0, 1080));
    const CocOptions o = depth_options(5.0);
    OIIO::ImageBuf view;
    ASSERT_TRUE(focal_plane_view(view, img, o)) << view.geterror();
    EXPECT_EQ(view.spec().nchannels, 3);
    EXPECT_EQ(view.roi(), OIIO::ROI(0, 3, 0, 1, 0, 1, 0, 3));
    float nearp[3], sharp[3], farp[3];
    view.getpixel(0, 0, nearp);
    view.getpixel(1, 0, sharp);
    view.getpixel(2, 0, farp);
    EXPECT_GT(nearp[0], nearp[1] + 0.2f) << "near is red: " << nearp[0] << " " << nearp[1] << " " << nearp[2];
    EXPECT_GT(nearp[0], nearp[2] + 0.2f);
    EXPECT_GT(sharp[1], sharp[0] + 0.2f) << "in focus is green: " << sharp[0] << " " << sharp[1] << " " << sharp[2];
    EXPECT_GT(sharp[1], sharp[2] + 0.2f);
    EXPECT_GT(farp[2], farp[0] + 0.2f) << "far is blue: " << farp[0] << " " << farp[1] << " " << farp[2];
    EXPECT_GT(farp[2], farp[1] + 0.2f);
}

// --- real render ------------------------------------------------------------------------------

// The Beachball renders hold Z = 0 where nothing was rendered: those pixels are infinitely
// far (the CoC of infinity), not in focus (0) and not at the lens (a huge front CoC).
TEST(LensBeachball, ZeroDepthIsInfinitelyFar)
{
    const std::string path = bokeh_test::shared_data("openexr-images/Beachball_singlepart.0001.exr");
    REQUIRE_SHARED(path);
    OIIO::ImageBuf img(path);
    ASSERT_TRUE(img.read(0, 0, true, OIIO::TypeFloat)) << img.geterror();
    const int zc = img.spec().channelindex("Z");
    ASSERT_GE(zc, 0);
    CocOptions o = depth_options(5.0);
    OIIO::ImageBuf map;
    ASSERT_TRUE(coc_map(map, img, o)) << map.geterror();
    const int width     = img.spec().full_width;  // 2048
    const double at_inf = thin_lens_coc_px(o.lens, kInf, width);
    ASSERT_GT(at_inf, 1.0);
    int64_t zeros = 0, rendered = 0;
    double worst_zero = 0.0, worst_rendered = 0.0;
    const OIIO::ROI d = img.roi();
    for (int y = d.ybegin; y < d.yend; y += 3)
        for (int x = d.xbegin; x < d.xend; x += 3) {
            const float z = img.getchannel(x, y, 0, zc);
            const double c = map.getchannel(x, y, 0, 0);
            if (z == 0.0f) {
                ++zeros;
                worst_zero = std::max(worst_zero, std::abs(c - at_inf));
            } else {
                ++rendered;
                worst_rendered = std::max(worst_rendered, std::abs(c - thin_lens_coc_px(o.lens, z, width)));
            }
        }
    ASSERT_GT(zeros, 100) << "the render has empty (Z = 0) pixels";
    ASSERT_GT(rendered, 100);
    EXPECT_LT(worst_zero, 1e-4) << zeros << " Z = 0 samples, CoC of infinity " << at_inf
                                << " px, worst difference " << worst_zero;
    EXPECT_LT(worst_rendered, 1e-3) << rendered << " rendered samples";
}
