// The shipped OCIO config and known conversion values.
#include <bokeh/color.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include <OpenColorIO/OpenColorIO.h>

#include "test_util.h"

using namespace bokeh;
namespace OCIO = OCIO_NAMESPACE;

TEST(Color, ShippedConfigValidates)
{
    OCIO::ConstConfigRcPtr config = OCIO::Config::CreateFromFile(BOKEH_OCIO_CONFIG);
    ASSERT_TRUE(config);
    EXPECT_NO_THROW(config->validate());
    EXPECT_STREQ(config->getColorSpace("scene_linear")->getName(), "lin_rec709");
    EXPECT_FALSE(config->getColorSpace("linear")) << "'linear' names no primaries";
}

static float convert_one(const ColorSystem& cs, const std::string& from, const std::string& to,
                         float r, float g, float b, int channel)
{
    OIIO::ImageSpec spec(1, 1, 3, OIIO::TypeFloat);
    OIIO::ImageBuf buf(spec);
    const float px[3] = { r, g, b };
    buf.setpixel(0, 0, px);
    std::string err;
    EXPECT_TRUE(cs.convert(buf, from, to, 1, err)) << err;
    float out[3];
    buf.getpixel(0, 0, out);
    return out[channel];
}

TEST(Color, KnownValues)
{
    ColorSystem cs;
    std::string err;
    ASSERT_TRUE(cs.load(BOKEH_OCIO_CONFIG, err)) << err;
    EXPECT_EQ(cs.scene_linear(), "lin_rec709");
    EXPECT_EQ(cs.display_default(), "sRGB");
    // IEC 61966-2-1: ((0.5 + 0.055) / 1.055)^2.4 = 0.214041.
    EXPECT_NEAR(convert_one(cs, "sRGB", "lin_rec709", 0.5f, 0.5f, 0.5f, 0), 0.214041f, 2e-5f);
    EXPECT_NEAR(convert_one(cs, "sRGB", "lin_rec709", 0.02f, 0.02f, 0.02f, 0), 0.02f / 12.92f, 1e-6f);
    // ACEScg red in Rec.709: the first column of the AP1 -> Rec.709 (Bradford) matrix.
    EXPECT_NEAR(convert_one(cs, "ACEScg", "lin_rec709", 1, 0, 0, 0), 1.70505f, 1e-4f);
    EXPECT_NEAR(convert_one(cs, "ACEScg", "lin_rec709", 1, 0, 0, 1), -0.13026f, 1e-4f);
    EXPECT_NEAR(convert_one(cs, "ACEScg", "lin_rec709", 1, 0, 0, 2), -0.02400f, 1e-4f);
    // And back.
    EXPECT_NEAR(convert_one(cs, "lin_rec709", "sRGB", 0.214041f, 0, 0, 0), 0.5f, 2e-5f);
}

TEST(Color, UnknownSpacesAndConfigs)
{
    ColorSystem cs;
    std::string err;
    EXPECT_FALSE(cs.load("/nonexistent/config.ocio", err));
    EXPECT_NE(err.find("does not exist"), std::string::npos) << err;
    ASSERT_TRUE(cs.load(BOKEH_OCIO_CONFIG, err));
    OIIO::ImageBuf buf(OIIO::ImageSpec(1, 1, 3, OIIO::TypeFloat));
    EXPECT_FALSE(cs.convert(buf, "nonsense", "sRGB", 1, err));
    EXPECT_NE(err.find("unknown colour space 'nonsense'"), std::string::npos) << err;
    EXPECT_TRUE(cs.has("ACEScg"));
    EXPECT_TRUE(cs.has("acescg")) << "aliases resolve";
    EXPECT_FALSE(cs.has("nonsense"));
}

TEST(Color, FileSpaceByPixelType)
{
    ColorSystem cs;
    std::string err;
    ASSERT_TRUE(cs.load(BOKEH_OCIO_CONFIG, err));
    EXPECT_EQ(cs.space_of_file(OIIO::ImageSpec(1, 1, 3, OIIO::TypeHalf)), "lin_rec709");
    EXPECT_EQ(cs.space_of_file(OIIO::ImageSpec(1, 1, 3, OIIO::TypeFloat)), "lin_rec709");
    EXPECT_EQ(cs.space_of_file(OIIO::ImageSpec(1, 1, 3, OIIO::TypeUInt8)), "sRGB");
    EXPECT_EQ(cs.space_of_file(OIIO::ImageSpec(1, 1, 3, OIIO::TypeUInt16)), "sRGB");
}

TEST(Color, ResolveOrder)
{
    unsetenv("OCIO");
    EXPECT_EQ(resolve_color_config("", "shipped"), "shipped");
    setenv("OCIO", "/env/config.ocio", 1);
    EXPECT_EQ(resolve_color_config("", "shipped"), "/env/config.ocio");
    EXPECT_EQ(resolve_color_config("/explicit.ocio", "shipped"), "/explicit.ocio");
    unsetenv("OCIO");
}

// Which channels are colour: each layer's R, G, B with its alpha; never depth, IDs, motion
// or data layers (normals, positions) that borrow the R, G, B names.
TEST(Color, ColourChannelGroups)
{
    OIIO::ImageSpec spec(1, 1, 16, OIIO::TypeFloat);
    spec.channelnames = { "R",   "G",   "B",   "A",   "Z",         "diffuse.R", "diffuse.G", "diffuse.B",
                          "N.R", "N.G", "N.B", "P.R", "forward.u", "spec.R",    "spec.G",    "spec.A" };
    const std::vector<ColorChannels> groups = color_channel_groups(spec);
    ASSERT_EQ(groups.size(), 2u) << "R,G,B and diffuse.*; N and P are data, spec lacks B";
    EXPECT_EQ(groups[0].layer, "");
    EXPECT_EQ(groups[0].r, 0);
    EXPECT_EQ(groups[0].b, 2);
    EXPECT_EQ(groups[0].a, 3);
    EXPECT_EQ(groups[1].layer, "diffuse");
    EXPECT_EQ(groups[1].r, 5);
    EXPECT_EQ(groups[1].a, 3) << "a layer without its own alpha is covered by the image's";
}

// A conversion changes colour as OCIO does and leaves every other channel's bits.
TEST(Color, ConvertLeavesOtherChannelsBitForBit)
{
    ColorSystem cs;
    std::string err;
    ASSERT_TRUE(cs.load(BOKEH_OCIO_CONFIG, err)) << err;
    OIIO::ImageSpec spec(2, 1, 8, OIIO::TypeFloat);
    spec.channelnames  = { "R", "G", "B", "A", "Z", "forward.u", "id", "N.R" };
    spec.alpha_channel = 3;
    spec.z_channel     = 4;
    OIIO::ImageBuf buf(spec);
    const float px[2][8] = { { 0.2f, 0.1f, 0.05f, 0.5f, 40.0f, -3.5f, 7.0f, 0.6f },
                             { 0.9f, 0.4f, 0.3f, 1.0f, 1e9f, 12.25f, 2.0f, -0.8f } };
    buf.setpixel(0, 0, px[0]);
    buf.setpixel(1, 0, px[1]);
    ASSERT_TRUE(cs.convert(buf, "lin_rec709", "sRGB", 1, err)) << err;
    for (int x = 0; x < 2; ++x) {
        for (int c = 3; c < 8; ++c)
            EXPECT_EQ(buf.getchannel(x, 0, 0, c), px[x][c]) << spec.channel_name(c);
        // sRGB encodes the unpremultiplied colour: 0.2 / 0.5 = 0.4 -> 0.665, times 0.5.
        if (x == 0) {
            EXPECT_NEAR(buf.getchannel(0, 0, 0, 0), 0.5f * (1.055f * std::pow(0.4f, 1.0f / 2.4f) - 0.055f), 2e-5f);
        }
    }
    EXPECT_TRUE(cs.is_scene_linear("ACEScg"));
    EXPECT_TRUE(cs.is_scene_linear("lin_rec709"));
    EXPECT_TRUE(cs.is_scene_linear("raw"));
    EXPECT_FALSE(cs.is_scene_linear("sRGB"));
}
