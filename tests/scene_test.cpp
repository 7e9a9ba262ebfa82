// The built-in synthetic scene: known depths, HDR lights, determinism.
#include <bokeh/scene.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

using namespace bokeh;

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
