// The built-in synthetic scenes: known depths, HDR lights, the intended lens, determinism.
#include <bokeh/scene.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>

using namespace bokeh;

namespace {

// R, G, B, A, Z of one pixel.
struct Pixel {
    float v[5];
    float sum() const { return v[0] + v[1] + v[2]; }
    float z() const { return v[4]; }
};

Pixel pixel(const OIIO::ImageBuf& img, int x, int y)
{
    Pixel p;
    img.getpixel(x, y, p.v);
    return p;
}

// Thin-lens CoC diameter (docs/methods/optics.md) at depth z metres, in pixels of a 1920-wide
// image, for the lens the scene's metadata asks for.
double coc_px_1920(const OIIO::ImageSpec& s, double z)
{
    const double f = s.get_float_attribute("bokeh:focal_mm");
    const double d0 = 1000.0 * s.get_float_attribute("bokeh:focus_m");
    const double F = s.get_float_attribute("bokeh:fstop");
    const double pixel_mm = s.get_float_attribute("bokeh:sensor_width_mm") / 1920.0;
    const double d = 1000.0 * z;
    return std::abs(d - d0) / d * f * f / (F * (d0 - f)) / pixel_mm;
}

// Every pixel finite, alpha 1, Z positive.
void expect_well_formed(const OIIO::ImageBuf& img)
{
    const OIIO::ImageSpec& s = img.spec();
    ASSERT_EQ(s.channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" }));
    for (int y = 0; y < s.height; ++y)
        for (int x = 0; x < s.width; ++x) {
            const Pixel p = pixel(img, x, y);
            ASSERT_TRUE(std::isfinite(p.sum()) && std::isfinite(p.z())) << x << "," << y;
            ASSERT_EQ(p.v[3], 1.0f) << x << "," << y;
            ASSERT_GT(p.z(), 0.0f) << x << "," << y;
        }
}

}  // namespace

TEST(Scene, ChannelsDepthsAndLights)
{
    SceneOptions o;
    o.width  = 480;
    o.height = 270;
    OIIO::ImageBuf img;
    ASSERT_TRUE(make_scene(img, "lights", o));
    const OIIO::ImageSpec& s = img.spec();
    EXPECT_EQ(s.channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" }));
    EXPECT_FLOAT_EQ(s.get_float_attribute("bokeh:focal_mm"), 50.0f);
    EXPECT_FLOAT_EQ(s.get_float_attribute("bokeh:sensor_width_mm"), 36.0f);
    float zmin = 1e9f, zmax = 0.0f, peak = 0.0f;
    int bright = 0;
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x) {
            float px[5];
            img.getpixel(x, y, px);
            ASSERT_TRUE(std::isfinite(px[0]) && std::isfinite(px[4]));
            ASSERT_EQ(px[3], 1.0f);
            zmin = std::min(zmin, px[4]);
            zmax = std::max(zmax, px[4]);
            peak = std::max(peak, px[0] + px[1] + px[2]);
            bright += (px[0] + px[1] + px[2]) > 3.0f;
        }
    EXPECT_GT(zmin, 1.2f) << "nearest light";
    EXPECT_LT(zmin, 1.6f) << "near lights stand in front of the post";
    EXPECT_FLOAT_EQ(zmax, 40.0f) << "the back wall";
    EXPECT_GT(peak, 20.0f) << "HDR point lights";
    EXPECT_GT(bright, 20) << "several lights visible";
    // The sphere's centre pixel is in focus territory: ~5.4 m.
    const double half_w = 0.5 * 36.0 / 50.0, half_h = half_w * 270.0 / 480.0;
    const int cx = int((0.8 / 6.0 / half_w + 1.0) * 0.5 * o.width);
    const int cy = int((1.0 - (-0.5 / 6.0) / half_h) * 0.5 * o.height);
    float px[5];
    img.getpixel(cx, cy, px);
    EXPECT_NEAR(px[4], 6.0f - 0.6f, 0.05f);
    // The foreground post spans x = -0.40..-0.32 m at 1.6 m.
    const int post_x = int((-0.36 / 1.6 / half_w + 1.0) * 0.5 * o.width);
    img.getpixel(post_x, o.height / 2, px);
    EXPECT_NEAR(px[4], 1.6f, 0.01f) << "the foreground post";
}

TEST(Scene, DeterministicAndSeeded)
{
    SceneOptions o;
    o.width  = 96;
    o.height = 54;
    OIIO::ImageBuf a, b, c;
    ASSERT_TRUE(make_scene(a, "lights", o));
    ASSERT_TRUE(make_scene(b, "lights", o));
    o.seed = 2;
    ASSERT_TRUE(make_scene(c, "lights", o));
    const size_t bytes = 96 * 54 * 5 * sizeof(float);
    EXPECT_EQ(std::memcmp(a.localpixels(), b.localpixels(), bytes), 0);
    EXPECT_NE(std::memcmp(a.localpixels(), c.localpixels(), bytes), 0);
}

TEST(Scene, BadRequests)
{
    OIIO::ImageBuf img;
    SceneOptions o;
    EXPECT_FALSE(make_scene(img, "nonsense", o));
    EXPECT_NE(img.geterror().find("unknown scene 'nonsense'"), std::string::npos);
    o.width = 0;
    EXPECT_FALSE(make_scene(img, "lights", o));
    o.width = 10;
    o.aa    = 0;
    EXPECT_FALSE(make_scene(img, "lights", o));
}

TEST(Scene, NamesLensAndMetadata)
{
    EXPECT_EQ(scene_names(), (std::vector<std::string>{ "lights", "edges", "giant" }));
    const struct {
        const char* name;
        float focus_m, fstop;
    } expected[] = { { "lights", 6.0f, 1.27f }, { "edges", 3.0f, 1.06f }, { "giant", 0.5f, 2.0f } };
    for (const auto& e : expected) {
        SCOPED_TRACE(e.name);
        EXPECT_NE(scene_description(e.name).find("focus"), std::string::npos);
        SceneOptions o;
        o.width  = 16;
        o.height = 9;
        OIIO::ImageBuf img;
        ASSERT_TRUE(make_scene(img, e.name, o));
        const OIIO::ImageSpec& s = img.spec();
        EXPECT_EQ(s.get_string_attribute("bokeh:scene"), e.name);
        EXPECT_FLOAT_EQ(s.get_float_attribute("bokeh:focal_mm"), 50.0f);
        EXPECT_FLOAT_EQ(s.get_float_attribute("bokeh:sensor_width_mm"), 36.0f);
        EXPECT_EQ(s.get_string_attribute("bokeh:depth_unit"), "m");
        EXPECT_FLOAT_EQ(s.get_float_attribute("bokeh:focus_m"), e.focus_m);
        EXPECT_FLOAT_EQ(s.get_float_attribute("bokeh:fstop"), e.fstop);
    }
    EXPECT_EQ(scene_description("nonsense"), "");
}

TEST(Scene, EdgesDepthPlanesAndHiddenLights)
{
    SceneOptions o;
    o.width  = 240;
    o.height = 135;
    OIIO::ImageBuf img;
    ASSERT_TRUE(make_scene(img, "edges", o));
    expect_well_formed(img);
    // Planes facing the camera: only three depths, each of them present.
    std::set<float> depths;
    float peak = 0.0f;
    int hidden_lights = 0;
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x) {
            const Pixel p = pixel(img, x, y);
            depths.insert(p.z());
            peak = std::max(peak, p.sum());
            // A pixel on the in-focus left panel (Z 3 keeps the nearest sample) that is
            // HDR: a far light straddling the panel's edge, partly hidden by it.
            hidden_lights += x < o.width / 2 && p.z() == 3.0f && p.sum() > 5.0f;
        }
    EXPECT_EQ(depths, (std::set<float>{ 1.2f, 3.0f, 30.0f }));
    EXPECT_GT(peak, 50.0f) << "HDR lights";
    EXPECT_GT(hidden_lights, 0) << "lights straddling the in-focus panel's edges";
    // Left: the panel (lower left, up to 45% of the width) over the far wall.
    EXPECT_EQ(pixel(img, 24, 121).z(), 3.0f) << "in-focus panel";
    EXPECT_EQ(pixel(img, 24, 13).z(), 30.0f) << "far wall above the panel";
    EXPECT_EQ(pixel(img, 107, 108).z(), 3.0f) << "left of the panel's vertical edge";
    EXPECT_EQ(pixel(img, 108, 108).z(), 30.0f) << "right of the panel's vertical edge";
    // Right: the near panel (right 25%) over the in-focus wall.
    EXPECT_EQ(pixel(img, 144, 67).z(), 3.0f) << "in-focus wall";
    EXPECT_EQ(pixel(img, 179, 67).z(), 3.0f) << "left of the near panel's edge";
    EXPECT_EQ(pixel(img, 180, 67).z(), 1.2f) << "near panel";
    const Pixel near = pixel(img, 216, 67);
    EXPECT_GT(near.v[0], 3.0f * near.v[2]) << "the near panel is saturated orange";
    // The recorded lens gives the intended blur: about 64 px at most, at 1920 wide.
    EXPECT_NEAR(coc_px_1920(img.spec(), 1.2), 64.0, 1.0);
    EXPECT_LT(coc_px_1920(img.spec(), 30.0), 64.0);
}

TEST(Scene, GiantNearLightsCardAndFarString)
{
    SceneOptions o;
    o.width  = 240;
    o.height = 135;
    OIIO::ImageBuf img;
    ASSERT_TRUE(make_scene(img, "giant", o));
    expect_well_formed(img);
    float zmin = 1e9f, zmax = 0.0f;
    int near_light_px = 0, far_light_px = 0;
    for (int y = 0; y < o.height; ++y)
        for (int x = 0; x < o.width; ++x) {
            const Pixel p = pixel(img, x, y);
            zmin = std::min(zmin, p.z());
            zmax = std::max(zmax, p.z());
            near_light_px += p.z() < 0.26f;
            far_light_px += p.z() > 4.5f && p.z() < 55.0f;
        }
    EXPECT_GT(zmin, 0.14f) << "nearest light";
    EXPECT_LT(zmin, 0.16f) << "nearest light";
    EXPECT_FLOAT_EQ(zmax, 60.0f) << "the far wall";
    EXPECT_GE(near_light_px, 5) << "five lights at 0.15-0.25 m";
    EXPECT_GE(far_light_px, 10) << "the string of lights at 5-50 m";
    // The nearest light, at frame position (-0.72, 0.5), 0.15 m.
    const Pixel light = pixel(img, int(0.14 * o.width), int(0.25 * o.height));
    EXPECT_NEAR(light.z(), 0.15f, 0.002f);
    EXPECT_GT(light.sum(), 20.0f) << "HDR";
    EXPECT_EQ(pixel(img, o.width / 2, o.height / 2).z(), 0.5f) << "the in-focus card";
    EXPECT_EQ(pixel(img, 1, 1).z(), 60.0f) << "the far wall";
    // The recorded lens makes the nearest light's bokeh a quarter to a half of the frame
    // height (1080 rows at 1920 wide).
    const double giant = coc_px_1920(img.spec(), zmin);
    EXPECT_GT(giant, 300.0);
    EXPECT_LT(giant, 500.0);
}

TEST(Scene, EverySceneSameForAnyThreadCount)
{
    SceneOptions o;
    o.width  = 96;
    o.height = 54;
    const size_t bytes = 96 * 54 * 5 * sizeof(float);
    for (const std::string& name : scene_names()) {
        SCOPED_TRACE(name);
        OIIO::ImageBuf one, three, all, reseeded;
        ASSERT_TRUE(make_scene(one, name, o, 1));
        ASSERT_TRUE(make_scene(three, name, o, 3));
        ASSERT_TRUE(make_scene(all, name, o, 0));
        EXPECT_EQ(std::memcmp(one.localpixels(), three.localpixels(), bytes), 0);
        EXPECT_EQ(std::memcmp(one.localpixels(), all.localpixels(), bytes), 0);
        SceneOptions other = o;
        other.seed         = 2;
        ASSERT_TRUE(make_scene(reseeded, name, other));
        EXPECT_NE(std::memcmp(one.localpixels(), reseeded.localpixels(), bytes), 0);
    }
}
