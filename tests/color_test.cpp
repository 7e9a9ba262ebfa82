// The shipped OCIO config and known conversion values.
#include <bokeh/color.h>

#include <gtest/gtest.h>

#include <cstdlib>

#include <OpenColorIO/OpenColorIO.h>

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
