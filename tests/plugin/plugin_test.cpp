// Registry, option parsing and plugin loading.
#include <bokeh/plugin.h>

#include <gtest/gtest.h>

#include "test_util.h"

using namespace bokeh;

static std::vector<OptionSpec> specs()
{
    return { OptionSpec::Int("size", 3, 1, 9, ""), OptionSpec::Float("gain", 1.0, 0.0, 10.0, ""),
             OptionSpec::Bool("grow", false, ""),
             OptionSpec::Choice("edge", { "black", "clamp", "mirror" }, ""),
             OptionSpec::String("name", "x", "") };
}

TEST(Options, DefaultsWhenNothingGiven)
{
    OptionValues v;
    std::string err;
    ASSERT_TRUE(parse_options(specs(), "", v, err));
    EXPECT_EQ(v.get_int("size"), 3);
    EXPECT_DOUBLE_EQ(v.get_float("gain"), 1.0);
    EXPECT_FALSE(v.get_bool("grow"));
    EXPECT_EQ(v.get_string("edge"), "black");
    EXPECT_FALSE(v.given("size"));
}

TEST(Options, ParsesEveryType)
{
    OptionValues v;
    std::string err;
    ASSERT_TRUE(parse_options(specs(), "size=7:gain=2.5:grow:edge=mirror:name=a b", v, err)) << err;
    EXPECT_EQ(v.get_int("size"), 7);
    EXPECT_DOUBLE_EQ(v.get_float("gain"), 2.5);
    EXPECT_TRUE(v.get_bool("grow"));
    EXPECT_EQ(v.get_string("edge"), "mirror");
    EXPECT_EQ(v.get_string("name"), "a b");
    EXPECT_TRUE(v.given("size"));
    ASSERT_TRUE(parse_options(specs(), "grow=off", v, err));
    EXPECT_FALSE(v.get_bool("grow"));
}

TEST(Options, RejectsWithTheOptionNamed)
{
    OptionValues v;
    std::string err;
    EXPECT_FALSE(parse_options(specs(), "sise=3", v, err));
    EXPECT_NE(err.find("unknown option 'sise'"), std::string::npos) << err;
    EXPECT_NE(err.find("size"), std::string::npos) << "lists the known options: " << err;
    EXPECT_FALSE(parse_options(specs(), "size=10", v, err));
    EXPECT_NE(err.find("out of range"), std::string::npos) << err;
    EXPECT_FALSE(parse_options(specs(), "size=2.5", v, err));
    EXPECT_NE(err.find("integer"), std::string::npos) << err;
    EXPECT_FALSE(parse_options(specs(), "gain=abc", v, err));
    EXPECT_FALSE(parse_options(specs(), "gain=nan", v, err));
    EXPECT_FALSE(parse_options(specs(), "gain=inf", v, err));
    EXPECT_FALSE(parse_options(specs(), "gain=0x3", v, err)) << "no hexadecimal";
    EXPECT_FALSE(parse_options(specs(), "edge=wrap", v, err));
    EXPECT_NE(err.find("black, clamp, mirror"), std::string::npos) << err;
    EXPECT_FALSE(parse_options(specs(), "grow=maybe", v, err));
    EXPECT_FALSE(parse_options(specs(), "size", v, err));
    EXPECT_NE(err.find("needs a value"), std::string::npos) << err;
    EXPECT_FALSE(parse_options(specs(), "edge=clamp:size=3:edge=mirror", v, err)) << "one would be dropped";
    EXPECT_NE(err.find("option 'edge' is given twice"), std::string::npos) << err;
    EXPECT_FALSE(parse_options(specs(), "grow:grow=0", v, err));
    EXPECT_NE(err.find("option 'grow' is given twice"), std::string::npos) << err;
}

TEST(Options, ParseSize)
{
    int w = 0, h = 0;
    EXPECT_TRUE(parse_size("31x17", w, h));
    EXPECT_EQ(w, 31);
    EXPECT_EQ(h, 17);
    EXPECT_TRUE(parse_size("9", w, h));
    EXPECT_EQ(w, 9);
    EXPECT_EQ(h, 9);
    for (const char* bad : { "", "x", "3x", "0x3", "-3x3", "3x3x3", "3y3", "abc", "2.5x3" })
        EXPECT_FALSE(parse_size(bad, w, h)) << bad;
    float fw = 0, fh = 0;
    EXPECT_TRUE(parse_extent("6.5x4.25", fw, fh));
    EXPECT_FLOAT_EQ(fw, 6.5f);
    EXPECT_FLOAT_EQ(fh, 4.25f);
    EXPECT_TRUE(parse_extent("0x5", fw, fh)) << "zero width, not hexadecimal 5";
    EXPECT_EQ(fw, 0.0f);
    EXPECT_EQ(fh, 5.0f);
    for (const char* bad : { "", "0x", "x2", "-1", "inf", "nan", "1e40", "3 x 3", "0x1p3" })
        EXPECT_FALSE(parse_extent(bad, fw, fh)) << bad;
}

TEST(Registry, RefusesBadAndDuplicateNames)
{
    Registry r;
    Command c;
    c.name = "--a";
    c.run  = [](CommandContext&) { return true; };
    r.set_current_plugin("first.so");
    EXPECT_TRUE(r.add(c));
    EXPECT_FALSE(r.add(c));
    EXPECT_NE(r.error().find("first.so"), std::string::npos) << r.error();
    Command nodash = c;
    nodash.name    = "a";
    EXPECT_FALSE(r.add(nodash));
    Command colon = c;
    colon.name    = "--a:b";
    EXPECT_FALSE(r.add(colon));
    Command nofn = c;
    nofn.name    = "--b";
    nofn.run     = nullptr;
    EXPECT_FALSE(r.add(nofn));
    ASSERT_NE(r.find("--a"), nullptr);
    EXPECT_EQ(r.find("--a")->plugin, "first.so");
    r.remove_plugin("first.so");
    EXPECT_EQ(r.find("--a"), nullptr);
}

static std::string bad_plugin(const std::string& name)
{
    return std::string(BOKEH_BAD_PLUGIN_DIR) + "/" + name + "/" + name + ".so";
}

TEST(LoadPlugin, EachFailureNamesTheFile)
{
    struct Case {
        std::string file, reason;
    };
    const Case cases[] = {
        { "/nonexistent/plugin.so", "cannot load" },
        { bad_plugin("no_entry"), "not an OpenBokeh plugin" },
        { bad_plugin("bad_abi"), "ABI" },
        { bad_plugin("throws"), "deliberate failure" },
    };
    for (const Case& k : cases) {
        Registry r;
        std::string err;
        EXPECT_FALSE(load_plugin(r, k.file, err)) << k.file;
        EXPECT_NE(err.find(k.file), std::string::npos) << err;
        EXPECT_NE(err.find(k.reason), std::string::npos) << err;
        EXPECT_TRUE(r.commands().empty()) << "a failed module leaves no command: " << k.file;
    }
}

TEST(LoadPlugin, DuplicateCommandIsRefused)
{
    Registry r;
    Command c;
    c.name = "--ch";
    c.run  = [](CommandContext&) { return true; };
    r.set_current_plugin("builtin");
    ASSERT_TRUE(r.add(c));
    std::string err;
    EXPECT_FALSE(load_plugin(r, bad_plugin("duplicate"), err));
    EXPECT_NE(err.find("'--ch' is already defined by builtin"), std::string::npos) << err;
    ASSERT_EQ(r.commands().size(), 1u);
    EXPECT_EQ(r.commands()[0].plugin, "builtin");
}
