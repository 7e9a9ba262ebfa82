// Channel lookup, working images, non-finite policy.
#include <bokeh/image.h>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace bokeh;

static OIIO::ImageSpec spec_with(std::vector<std::string> names)
{
    OIIO::ImageSpec s(4, 3, int(names.size()), OIIO::TypeFloat);
    s.channelnames  = names;
    s.alpha_channel = -1;
    s.z_channel     = -1;
    return s;
}

TEST(Channels, FindsByName)
{
    ChannelMap m = find_channels(spec_with({ "Z", "B", "G", "R", "A" }));
    EXPECT_EQ(m.r, 3);
    EXPECT_EQ(m.g, 2);
    EXPECT_EQ(m.b, 1);
    EXPECT_EQ(m.a, 4);
    EXPECT_EQ(m.z, 0);
    m = find_channels(spec_with({ "beauty.R", "beauty.G", "beauty.B", "beauty.A", "depth.Z" }));
    EXPECT_EQ(m.r, 0);
    EXPECT_EQ(m.a, 3);
    EXPECT_EQ(m.z, 4);
    // Two layers with an R: ambiguous, not guessed.
    m = find_channels(spec_with({ "left.R", "right.R" }));
    EXPECT_EQ(m.g, -1);
    m = find_channels(spec_with({ "Y" }));
    EXPECT_EQ(m.r, 0);
    EXPECT_FALSE(m.has_rgb());
}

TEST(WorkImage, RoundTripKeepsValuesAndUnpremultipliedStorage)
{
    OIIO::ImageSpec spec = spec_with({ "R", "G", "B", "A", "Z" });
    spec.x               = 5;  // an offset data window
    spec.y               = -2;
    spec.attribute("oiio:UnassociatedAlpha", 1);
    OIIO::ImageBuf buf(spec);
    for (int y = spec.y; y < spec.y + spec.height; ++y)
        for (int x = spec.x; x < spec.x + spec.width; ++x) {
            const float px[5] = { 0.5f, 0.25f, 2.0f, 0.5f, float(x + 10 * y) };
            buf.setpixel(x, y, px);
        }
    ASSERT_FALSE(is_premultiplied(buf.spec()));
    WorkImage w;
    std::string err;
    ASSERT_TRUE(to_work_image(w, buf, err, 2)) << err;
    EXPECT_EQ(w.roi.xbegin, 5);
    EXPECT_EQ(w.roi.ybegin, -2);
    const float* p = w.rgba_at(6, -1);
    EXPECT_FLOAT_EQ(p[0], 0.25f) << "premultiplied inside";
    EXPECT_FLOAT_EQ(p[2], 1.0f);
    EXPECT_FLOAT_EQ(p[3], 0.5f);
    EXPECT_FLOAT_EQ(w.z[w.index(6, -1)], 6.0f - 10.0f);

    OIIO::ImageBuf back(spec);
    ASSERT_TRUE(from_work_image(back, w, 2)) << back.geterror();
    float q[5];
    back.getpixel(6, -1, q);
    EXPECT_FLOAT_EQ(q[0], 0.5f) << "unpremultiplied again on the way out";
    EXPECT_FLOAT_EQ(q[4], -4.0f);
}

TEST(WorkImage, GreyAndAlphaLessInput)
{
    OIIO::ImageBuf buf(spec_with({ "Y" }));
    const float v = 0.3f;
    buf.setpixel(1, 1, &v);
    WorkImage w;
    std::string err;
    ASSERT_TRUE(to_work_image(w, buf, err, 0)) << err;
    EXPECT_FALSE(w.has_alpha);
    const float* p = w.rgba_at(1, 1);
    EXPECT_FLOAT_EQ(p[0], 0.3f);
    EXPECT_FLOAT_EQ(p[1], 0.3f);
    EXPECT_FLOAT_EQ(p[2], 0.3f);
    EXPECT_FLOAT_EQ(p[3], 1.0f);
}

TEST(NonFinite, ZeroPolicyReplacesAndCounts)
{
    OIIO::ImageBuf buf(spec_with({ "R", "G", "B", "A", "Z" }));
    const float inf = std::numeric_limits<float>::infinity();
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float px[5] = { nan, inf, -inf, 1.0f, nan };
    buf.setpixel(2, 1, px);
    const float px2[5] = { 1.0f, 2.0f, 3.0f, 1.0f, -inf };
    buf.setpixel(3, 2, px2);
    const float px3[5] = { 1.0f, 2.0f, 3.0f, 1.0f, inf };  // +inf depth is "far": valid
    buf.setpixel(0, 0, px3);
    NonFiniteCount n;
    ASSERT_TRUE(scrub_nonfinite(buf, NonFinitePolicy::Zero, n));
    EXPECT_EQ(n.colour, 3);
    EXPECT_EQ(n.depth, 2);
    float q[5];
    buf.getpixel(2, 1, q);
    EXPECT_EQ(q[0], 0.0f);
    EXPECT_EQ(q[1], 0.0f);
    EXPECT_EQ(q[2], 0.0f);
    EXPECT_EQ(q[4], inf);
    buf.getpixel(3, 2, q);
    EXPECT_EQ(q[4], inf);
    EXPECT_EQ(q[0], 1.0f) << "finite values untouched";
}

TEST(NonFinite, ErrorPolicyFailsAndLeavesPixels)
{
    OIIO::ImageBuf buf(spec_with({ "R", "G", "B" }));
    const float px[3] = { 0.0f, std::numeric_limits<float>::quiet_NaN(), 0.0f };
    buf.setpixel(0, 0, px);
    NonFiniteCount n;
    EXPECT_FALSE(scrub_nonfinite(buf, NonFinitePolicy::Error, n));
    EXPECT_EQ(n.total(), 1);
    float q[3];
    buf.getpixel(0, 0, q);
    EXPECT_TRUE(std::isnan(q[1]));
    OIIO::ImageBuf clean(spec_with({ "R", "G", "B" }));
    EXPECT_TRUE(scrub_nonfinite(clean, NonFinitePolicy::Error, n));
    EXPECT_EQ(n.total(), 0);
}

// A metadata number is read whatever type it was stored with; a non-number is refused by
// name, and an absent attribute leaves the default.
TEST(Metadata, NumbersOfAnyStoredType)
{
    OIIO::ImageSpec spec(1, 1, 3, OIIO::TypeFloat);
    spec.attribute("as_int", 85);
    spec.attribute("as_float", 85.0f);
    const double d = 85.0;
    spec.attribute("as_double", OIIO::TypeDesc::DOUBLE, &d);
    const unsigned u = 85;
    spec.attribute("as_uint", OIIO::TypeDesc::UINT, &u);
    const uint16_t half_85 = 0x5550;  // 85.0 in IEEE half: sign 0, exponent 21 (6 + 15), mantissa 0x150
    spec.attribute("as_half", OIIO::TypeDesc::HALF, &half_85);
    spec.attribute("as_string", " 85 ");
    spec.attribute("as_word", "eighty-five");
    spec.attribute("as_nan", std::numeric_limits<float>::quiet_NaN());
    const float vec[3] = { 85.0f, 1.0f, 2.0f };
    spec.attribute("as_vector", OIIO::TypeVector, vec);
    for (const char* name : { "as_int", "as_float", "as_double", "as_uint", "as_half", "as_string" }) {
        double v = 50.0;
        std::string err;
        EXPECT_TRUE(metadata_number(spec, name, v, err)) << name << ": " << err;
        EXPECT_EQ(v, 85.0) << name;
    }
    for (const char* name : { "as_word", "as_nan", "as_vector" }) {
        double v = 50.0;
        std::string err;
        EXPECT_FALSE(metadata_number(spec, name, v, err)) << name;
        EXPECT_NE(err.find(std::string("metadata ") + name), std::string::npos) << err;
        EXPECT_EQ(v, 50.0) << name << " leaves the value";
    }
    double v = 50.0;
    std::string err;
    EXPECT_TRUE(metadata_number(spec, "absent", v, err));
    EXPECT_EQ(v, 50.0);
}
