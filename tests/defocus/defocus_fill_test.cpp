// The background a blurred foreground uncovers inside its own silhouette (defocus_fill.cpp),
// against the thin-lens closed form of a straight silhouette.
//
// A foreground half-plane of CoC -D (a disk of radius R = D / 2) in front of a sharp
// background (CoC 0): the rays of a pixel at signed distance s from the silhouette (s > 0
// inside the foreground) meet the foreground's plane over a disk of radius R around the
// pixel, so the foreground covers the share
//     g(s) = 1/2 + (s sqrt(R^2 - s^2) + R^2 asin(s / R)) / (pi R^2)      (|s| <= R)
// of them and the sharp background, continued under the foreground, the rest:
// colour = g B + (1 - g) A. The layers' anti-aliased disk holds each pixel's exact area of
// the disk, so their blurred coverage meets g to within the disk's rim rounding.

#include "test_util.h"

#include <bokeh/defocus.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

using namespace bokeh;
using namespace bokeh_test;

namespace {

constexpr int kW = 96, kH = 64, kEdge = 48;  // the foreground is x >= kEdge
constexpr float kCoc = -20.0f;               // its CoC: a disk of radius 10
constexpr float kA[3] = { 0.2f, 0.5f, 0.8f };  // background colour
constexpr float kB[3] = { 0.9f, 0.3f, 0.1f };  // foreground colour

// The foreground's share of a pixel's rays at signed distance s (px) inside its silhouette.
double coverage(double s, double r)
{
    if (s >= r)
        return 1.0;
    if (s <= -r)
        return 0.0;
    return 0.5 + (s * std::sqrt(r * r - s * s) + r * r * std::asin(s / r)) / (kPi * r * r);
}

// The silhouette scene; `light`: an HDR 2 x 2 light (value 1000) on the background with its
// left column at x = light_x, rows 30-31; `empty_background`: the background is empty
// (alpha 0) instead of colour A.
OIIO::ImageBuf silhouette(int light_x = -1, bool empty_background = false)
{
    return make_image(kW, kH, [=](int x, int y) {
        Px p;
        if (x >= kEdge) {
            p.r = kB[0], p.g = kB[1], p.b = kB[2], p.z = kCoc;
            return p;
        }
        if (empty_background) {
            p.a = 0.0f;
            return p;
        }
        const bool lit = (x == light_x || x == light_x + 1) && (y == 30 || y == 31);
        p.r = lit ? 1000.0f : kA[0], p.g = lit ? 1000.0f : kA[1], p.b = lit ? 1000.0f : kA[2];
        return p;
    });
}

OIIO::ImageBuf defocus_with(const OIIO::ImageBuf& src, DisocclusionFill fill, DefocusMethod m = DefocusMethod::Layers,
                            DefocusReport* rep = nullptr)
{
    DefocusOptions o = direct_options(m, Border::Clamp, false);
    o.fill           = fill;
    return run_defocus(src, o, rep);
}

// Largest |output - closed form| over row y's channels R, G, B, A.
double worst_against_closed_form(const OIIO::ImageBuf& out, int y, bool empty_background)
{
    double worst = 0.0;
    for (int x = 0; x < kW; ++x) {
        const double g = coverage(double(x) + 0.5 - double(kEdge), 0.5 * std::abs(kCoc));
        for (int c = 0; c < 3; ++c) {
            const double want = g * kB[c] + (1.0 - g) * (empty_background ? 0.0 : kA[c]);
            worst             = std::max(worst, std::abs(double(at(out, x, y, c)) - want));
        }
        const double alpha = empty_background ? g : 1.0;
        worst              = std::max(worst, std::abs(double(at(out, x, y, 3)) - alpha));
    }
    return worst;
}

// The 10 %-90 % width (px) of the rise of channel R across the silhouette along row y,
// linear between pixel centres; `profile(x)` gives the row's values.
template<class Profile>
double ramp_width(Profile profile)
{
    const double lo = profile(0), hi = profile(kW - 1);
    auto crossing = [&](double level) {
        for (int x = 1; x < kW; ++x) {
            const double a = profile(x - 1), b = profile(x);
            if ((a - level) * (b - level) <= 0.0 && a != b)
                return double(x - 1) + (level - a) / (b - a);
        }
        return -1.0;
    };
    return crossing(lo + 0.9 * (hi - lo)) - crossing(lo + 0.1 * (hi - lo));
}

}  // namespace

TEST(DefocusFill, SilhouetteMatchesTheThinLensClosedForm)
{
    // Tolerance 0.012: the anti-aliased disk's rim pixels hold their area to about 0.002
    // each (the exact-area kernel test); a few of them over a straight edge, times the
    // colours' spread of 0.7.
    const OIIO::ImageBuf src = silhouette();
    for (DefocusMethod m : { DefocusMethod::Layers, DefocusMethod::Reference })
        for (DisocclusionFill fill : { DisocclusionFill::Smooth, DisocclusionFill::Mirror }) {
            SCOPED_TRACE(std::string(method_name(m)) + (fill == DisocclusionFill::Smooth ? " smooth" : " mirror"));
            DefocusReport rep;
            const OIIO::ImageBuf out = defocus_with(src, fill, m, &rep);
            EXPECT_LE(worst_against_closed_form(out, 20, false), 0.012);
            EXPECT_GT(rep.fill_continued_px, 0);
            EXPECT_EQ(rep.fill_foreground_px, 0) << "the background lies beside every filled pixel";
        }
    // The foreground's own colour (the fill before the continuation) is far from it: the
    // test tells the two apart.
    DefocusReport rep;
    const OIIO::ImageBuf old = defocus_with(src, DisocclusionFill::Foreground, DefocusMethod::Layers, &rep);
    EXPECT_GT(worst_against_closed_form(old, 20, false), 0.2);
    EXPECT_EQ(rep.fill_continued_px, 0);
    EXPECT_GT(rep.fill_foreground_px, 0);
}

TEST(DefocusFill, SilhouetteSoftensBothWaysAsALensDoes)
{
    // The 10-90 % ramp across the silhouette within 25 % of the closed form's; the
    // foreground fill's inner side is hard, its ramp about half as wide.
    auto closed = [](int x) {
        const double g = coverage(double(x) + 0.5 - double(kEdge), 10.0);
        return g * kB[0] + (1.0 - g) * kA[0];
    };
    const double truth_px = ramp_width(closed);
    const OIIO::ImageBuf smooth = defocus_with(silhouette(), DisocclusionFill::Smooth);
    const OIIO::ImageBuf old    = defocus_with(silhouette(), DisocclusionFill::Foreground);
    const double smooth_px = ramp_width([&](int x) { return double(at(smooth, x, 20, 0)); });
    const double old_px    = ramp_width([&](int x) { return double(at(old, x, 20, 0)); });
    std::printf("[ figures  ] 10-90 %% ramp: closed form %.2f px, smooth %.2f px, foreground fill %.2f px\n",
                truth_px, smooth_px, old_px);
    EXPECT_NEAR(smooth_px, truth_px, 0.25 * truth_px);
    EXPECT_LT(old_px, 0.75 * truth_px);
}

TEST(DefocusFill, EmptyBackgroundLeavesTheSilhouetteTransparent)
{
    // Nothing behind the foreground: its blurred edge thins out into transparency on both
    // sides (alpha = g), as the deep defocus and the thin-lens truth give; the foreground
    // fill would make it opaque again inside.
    const OIIO::ImageBuf src = silhouette(-1, true);
    for (DisocclusionFill fill : { DisocclusionFill::Smooth, DisocclusionFill::Mirror }) {
        const OIIO::ImageBuf out = defocus_with(src, fill);
        EXPECT_LE(worst_against_closed_form(out, 20, true), 0.012);
    }
    const OIIO::ImageBuf old = defocus_with(src, DisocclusionFill::Foreground);
    EXPECT_GT(worst_against_closed_form(old, 20, true), 0.2);
}

TEST(DefocusFill, HdrLightBesideTheSilhouetteDoesNotSmearUnderIt)
{
    // A light of 1000 on the sharp background, 5 px outside the silhouette: a lens sees it
    // at its own pixels only (the background is sharp; the light is not behind the
    // foreground). What the light adds inside the silhouette is invented: at most a fifth
    // of the background's own level near the light (the mirror's copy is held to twice
    // the continuation's luminance), under 1 % of it a blur radius and 16 px along the
    // edge away (the smooth continuation's coarsest cells span 32 px): no streak.
    const OIIO::ImageBuf plain = silhouette();
    const OIIO::ImageBuf lit   = silhouette(kEdge - 7);
    for (DisocclusionFill fill : { DisocclusionFill::Smooth, DisocclusionFill::Mirror }) {
        SCOPED_TRACE(fill == DisocclusionFill::Smooth ? "smooth" : "mirror");
        const OIIO::ImageBuf a = defocus_with(plain, fill), b = defocus_with(lit, fill);
        double near_light = 0.0, far_along = 0.0, added = 0.0;
        for (int y = 0; y < kH; ++y)
            for (int x = kEdge; x < kW; ++x) {
                const double d = double(at(b, x, y, 1)) - double(at(a, x, y, 1));
                added += d;
                if (std::abs(y - 30.5) > 16.0 + 10.0)
                    far_along = std::max(far_along, std::abs(d));
                else
                    near_light = std::max(near_light, std::abs(d));
            }
        std::printf("[ figures  ] light beside the silhouette, %s: inside it adds up to %.3f near the light, "
                    "%.2g farther along the edge, %.2f in all (the light holds 4000)\n",
                    fill == DisocclusionFill::Smooth ? "smooth" : "mirror", near_light, far_along, added);
        EXPECT_LE(near_light, 0.2 * kA[1]);
        EXPECT_LE(far_along, 0.01 * kA[1]);
        EXPECT_LE(added, 0.001 * 4000.0) << "a thousandth of the light's energy";
    }
}
