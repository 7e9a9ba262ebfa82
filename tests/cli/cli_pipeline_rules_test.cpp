// The rules a pipeline relies on, each checked through bokehtool as a TD would meet it:
// colour conversions touch colour channels only and do what they name (against OCIO's own
// processor), metadata numbers of any type, outputs that say what they are, -d's order,
// point passes merged with volume passes, sequence patterns, -u's command-line check,
// --diff's labels, the defaults shared with oiiotool, and the farm scripts' contract.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include <OpenColorIO/OpenColorIO.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;
namespace OCIO = OCIO_NAMESPACE;

namespace {

OIIO::ImageBuf read_float(const std::string& path)
{
    OIIO::ImageBuf img(path);
    img.read(0, 0, true, OIIO::TypeFloat);
    return img;
}

OIIO::ImageSpec header(const std::string& path)
{
    auto in = OIIO::ImageInput::open(path);
    return in ? in->spec() : OIIO::ImageSpec();
}

// An RGBA + Z render with the channels a pipeline carries beside colour: an AOV, motion
// vectors, normals and an ID; premultiplied colour, alpha 0.25..1, Z = 40 m.
const std::vector<std::string> kChannels = { "R",         "G",         "B",         "A",   "Z",   "diffuse.R",
                                             "diffuse.G", "diffuse.B", "forward.u", "forward.v", "N.R", "N.G",
                                             "N.B",       "id" };

OIIO::ImageBuf pipeline_frame()
{
    const int w = 12, h = 6, n = int(kChannels.size());
    OIIO::ImageSpec spec(w, h, n, OIIO::TypeFloat);
    spec.channelnames  = kChannels;
    spec.alpha_channel = 3;
    spec.z_channel     = 4;
    OIIO::ImageBuf img(spec);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            std::vector<float> v(static_cast<size_t>(n));
            const float a = 0.25f + 0.75f * float((x + y) % 4) / 3.0f;
            for (int c = 0; c < n; ++c)
                v[size_t(c)] = a * (0.05f + float((x * 7 + y * 3 + c * 5) % 17) / 8.0f);
            v[3]  = a;
            v[4]  = 40.0f;
            v[8]  = float(x) - 5.5f;   // forward.u: signed, not light
            v[9]  = -float(y) * 0.5f;  // forward.v
            v[13] = float(1 + x % 3);  // id
            img.setpixel(x, y, v.data());
        }
    return img;
}

int index_of(const OIIO::ImageSpec& spec, const std::string& name) { return spec.channelindex(name); }

// R, G, B of each colour layer of `in` put through OCIO's own processor `from` -> `to`
// (a matrix here: premultiplication commutes with it), compared with `out`; every other
// channel bit for bit.
void expect_colour_only_converted(const OIIO::ImageBuf& in, const OIIO::ImageBuf& out, const char* from,
                                  const char* to, const std::string& what)
{
    OCIO::ConstConfigRcPtr config = OCIO::Config::CreateFromFile(BOKEH_OCIO_CONFIG);
    OCIO::ConstCPUProcessorRcPtr cpu = config->getProcessor(from, to)->getDefaultCPUProcessor();
    const OIIO::ImageSpec& s = in.spec();
    ASSERT_EQ(out.spec().nchannels, s.nchannels) << what;
    const std::vector<std::array<std::string, 3>> colour = { { "R", "G", "B" },
                                                             { "diffuse.R", "diffuse.G", "diffuse.B" } };
    std::vector<bool> is_colour(size_t(s.nchannels), false);
    for (const auto& layer : colour)
        for (const std::string& c : layer)
            is_colour[size_t(index_of(s, c))] = true;
    for (int y = 0; y < s.height; ++y)
        for (int x = 0; x < s.width; ++x) {
            for (int c = 0; c < s.nchannels; ++c)
                if (!is_colour[size_t(c)]) {
                    const int oc = index_of(out.spec(), s.channel_name(c));
                    ASSERT_GE(oc, 0) << what << ": " << s.channel_name(c) << " lost";
                    EXPECT_EQ(out.getchannel(x, y, 0, oc), in.getchannel(x, y, 0, c))
                        << what << ": " << s.channel_name(c) << " at " << x << "," << y << " changed";
                }
            for (const auto& layer : colour) {
                float rgb[3], got[3];
                for (int k = 0; k < 3; ++k) {
                    rgb[k] = in.getchannel(x, y, 0, index_of(s, layer[size_t(k)]));
                    got[k] = out.getchannel(x, y, 0, index_of(out.spec(), layer[size_t(k)]));
                }
                cpu->applyRGB(rgb);
                for (int k = 0; k < 3; ++k)
                    EXPECT_NEAR(got[k], rgb[k], 2e-6f * (1.0f + std::abs(rgb[k])))
                        << what << ": " << layer[size_t(k)] << " at " << x << "," << y;
            }
        }
}

// The "-v" line of --defocus: "defocus layers: CoC a .. b px, ...".
std::string coc_line(const std::string& out)
{
    const size_t at = out.find("CoC ");
    return at == std::string::npos ? std::string("(no CoC line in: " + out + ")")
                                   : out.substr(at, out.find(" px", at) - at);
}

std::string scene_file(const std::string& dir)
{
    const std::string path = dir + "/scene.exr";
    if (!exists(path)) {
        const RunResult r = bokehtool(format("--scene lights:width=96:height=54:aa=1 -o {}", path));
        EXPECT_EQ(r.status, 0) << r.err;
    }
    return path;
}

}  // namespace

TEST(PipelineRules, ColourCommandsConvertColourChannelsOnly)
{
    const std::string dir = fresh_dir("rules_colour");
    ASSERT_TRUE(pipeline_frame().write(dir + "/in.exr"));
    const OIIO::ImageBuf in = read_float(dir + "/in.exr");

    // --iscolorspace relabels: an ACEScg plate written back is the same ACEScg plate.
    RunResult r = bokehtool(format("{0}/in.exr --iscolorspace ACEScg -o {0}/relabelled.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(max_difference(read_float(dir + "/relabelled.exr"), in), 0.0);

    // Conversions: colour as OCIO converts it, everything else bit for bit.
    r = bokehtool(format("{0}/in.exr --tocolorspace ACEScg -o {0}/to.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    expect_colour_only_converted(in, read_float(dir + "/to.exr"), "lin_rec709", "ACEScg", "--tocolorspace");
    r = bokehtool(format("{0}/in.exr --colorconvert lin_rec709 ACEScg -o {0}/cc.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    expect_colour_only_converted(in, read_float(dir + "/cc.exr"), "lin_rec709", "ACEScg", "--colorconvert");
    r = bokehtool(format("{0}/in.exr --iscolorspace ACEScg --tocolorspace lin_rec709 -o {0}/back.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    expect_colour_only_converted(in, read_float(dir + "/back.exr"), "ACEScg", "lin_rec709", "ACEScg -> rec709");

    // A filter on an ACEScg plate works in the working space and gives back ACEScg, depth
    // untouched: --defocus plans the CoC from the same Z as on the untagged frame.
    r = bokehtool(format("-v {0}/in.exr --defocus:focus=5:fstop=2 -o {0}/plain.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    RunResult tagged = bokehtool(format("-v {0}/in.exr --iscolorspace ACEScg --defocus:focus=5:fstop=2 -o {0}/tagged.exr", dir));
    ASSERT_EQ(tagged.status, 0) << tagged.err;
    EXPECT_EQ(coc_line(tagged.out), coc_line(r.out));
    EXPECT_NE(coc_line(r.out).find("CoC "), std::string::npos) << r.out;
}

TEST(PipelineRules, ColorconvertWritesItsDestinationSpace)
{
    const std::string dir = fresh_dir("rules_png");
    OIIO::ImageBuf png(OIIO::ImageSpec(8, 4, 3, OIIO::TypeUInt8));
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 8; ++x) {
            const float v[3] = { float(x) / 7.0f, float(y) / 3.0f, float((x + y) % 5) / 4.0f };
            png.setpixel(x, y, v);
        }
    ASSERT_TRUE(png.write(dir + "/in.png"));
    RunResult r = bokehtool(format("{0}/in.png --colorconvert sRGB ACEScg -o {0}/acescg.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{0}/in.png -o {0}/linear.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const OIIO::ImageBuf stored = read_float(dir + "/in.png"), acescg = read_float(dir + "/acescg.exr"),
                         linear = read_float(dir + "/linear.exr");
    OCIO::ConstConfigRcPtr config = OCIO::Config::CreateFromFile(BOKEH_OCIO_CONFIG);
    auto to_acescg = config->getProcessor("sRGB", "ACEScg")->getDefaultCPUProcessor();
    auto to_linear = config->getProcessor("sRGB", "lin_rec709")->getDefaultCPUProcessor();
    double apart = 0.0;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 8; ++x) {
            float a[3], l[3];
            for (int c = 0; c < 3; ++c)
                a[c] = l[c] = stored.getchannel(x, y, 0, c);
            to_acescg->applyRGB(a);
            to_linear->applyRGB(l);
            // 8-bit data is written to OpenEXR as half: 11 significant bits.
            for (int c = 0; c < 3; ++c) {
                EXPECT_NEAR(acescg.getchannel(x, y, 0, c), a[c], 1e-6f + std::abs(a[c]) / 1024.0f) << x << "," << y
                                                                                                 << " ACEScg";
                EXPECT_NEAR(linear.getchannel(x, y, 0, c), l[c], 1e-6f + std::abs(l[c]) / 1024.0f) << x << "," << y
                                                                                                 << " working space";
                apart = std::max(apart, double(std::abs(a[c] - l[c])));
            }
        }
    EXPECT_GT(apart, 0.01) << "the two spaces differ, so the test tells them apart";
}

TEST(PipelineRules, MetadataNumbersOfAnyType)
{
    const std::string dir = fresh_dir("rules_metadata"), scene = scene_file(dir);
    auto plan = [&](const std::string& attrib) {
        RunResult r = bokehtool(format("-v {} {} --defocus:focus=6:fstop=2 -o {}/x.exr", scene, attrib, dir));
        EXPECT_EQ(r.status, 0) << attrib << ": " << r.err;
        return coc_line(r.out);
    };
    const std::string as_float = plan("--attrib:type=float bokeh:focal_mm 85");
    EXPECT_NE(as_float, plan("")) << "85 mm plans another CoC than the scene's 50 mm";
    EXPECT_EQ(plan("--attrib bokeh:focal_mm 85"), as_float) << "an int";
    EXPECT_EQ(plan("--attrib:type=string bokeh:focal_mm 85"), as_float) << "a string holding a number";
    for (const char* bad : { "--attrib:type=string bokeh:focal_mm eighty", "--attrib bokeh:fstop 0" }) {
        RunResult r = bokehtool(format("{} {} --defocus:focus=6 -o {}/bad.exr", scene, bad, dir));
        expect_clean_failure(r, "metadata bokeh:", dir + "/bad.exr");
    }
}

TEST(PipelineRules, DefocusReadsTheLensTheFileRecords)
{
    const std::string dir = fresh_dir("rules_lens"), scene = scene_file(dir);
    const OIIO::ImageSpec s = header(scene);
    const float focus = s.get_float_attribute("bokeh:focus_m"), fstop = s.get_float_attribute("bokeh:fstop");
    ASSERT_GT(focus, 0.0f);
    ASSERT_TRUE(focus != 5.0f || fstop != 2.8f) << "the scene's lens must differ from the defaults";
    RunResult recorded = bokehtool(format("-v {} --defocus -o {}/a.exr", scene, dir));
    RunResult given    = bokehtool(format("-v {} --defocus:focus={}:fstop={} -o {}/b.exr", scene, focus, fstop, dir));
    RunResult defaults = bokehtool(format("-v {} --defocus:focus=5:fstop=2.8 -o {}/c.exr", scene, dir));
    ASSERT_EQ(recorded.status, 0) << recorded.err;
    EXPECT_EQ(coc_line(recorded.out), coc_line(given.out));
    EXPECT_NE(coc_line(recorded.out), coc_line(defaults.out));
    // A focus recorded in metres is converted to the depth unit given.
    RunResult cm = bokehtool(format("-v {} --defocus:unit=cm -o {}/d.exr", scene, dir));
    RunResult cm_given = bokehtool(format("-v {} --defocus:unit=cm:focus={}:fstop={} -o {}/e.exr", scene,
                                          focus * 100.0f, fstop, dir));
    ASSERT_EQ(cm.status, 0) << cm.err;
    EXPECT_EQ(coc_line(cm.out), coc_line(cm_given.out));
    EXPECT_NE(coc_line(cm.out), coc_line(recorded.out));
}

TEST(PipelineRules, OutputsSayWhatTheyAre)
{
    const std::string dir = fresh_dir("rules_outputs"), scene = scene_file(dir);
    RunResult r = bokehtool(format("{0} --attrib DateTime \"2001:02:03 04:05:06\" --defocus:focal=85:focus=6 "
                                   "-o {0}.dof.exr",
                                   scene));
    ASSERT_EQ(r.status, 0) << r.err;
    const OIIO::ImageSpec s = header(scene + ".dof.exr");
    EXPECT_EQ(s.get_float_attribute("bokeh:focal_mm"), 85.0f);
    EXPECT_EQ(s.get_float_attribute("bokeh:focus_m"), 6.0f);
    EXPECT_EQ(s.get_float_attribute("bokeh:fstop"), header(scene).get_float_attribute("bokeh:fstop"));
    EXPECT_TRUE(OIIO::Strutil::starts_with(s.get_string_attribute("Software"), "OpenBokeh "))
        << s.get_string_attribute("Software");
    const std::string when = s.get_string_attribute("DateTime");
    EXPECT_TRUE(std::regex_match(when, std::regex("[0-9]{4}:[0-9]{2}:[0-9]{2} [0-9]{2}:[0-9]{2}:[0-9]{2}"))) << when;
    EXPECT_NE(when, "2001:02:03 04:05:06") << "the time of writing, not the input's";
    EXPECT_NE(s.get_string_attribute("bokeh:command").find("--defocus:focal=85:focus=6"), std::string::npos)
        << s.get_string_attribute("bokeh:command");
    // SOURCE_DATE_EPOCH fixes the time; math=direct used no lens and records none.
    r = bokehtool(format("{0} --defocus:math=direct:scale=0.1 -o {0}.direct.exr", scene), "SOURCE_DATE_EPOCH=86400");
    ASSERT_EQ(r.status, 0) << r.err;
    const OIIO::ImageSpec d = header(scene + ".direct.exr");
    EXPECT_EQ(d.get_string_attribute("DateTime"), "1970:01:02 00:00:00");
    EXPECT_EQ(d.find_attribute("bokeh:focal_mm"), nullptr);
    // A deep file's chunk count (18 rows) describes that file: a flat result of another
    // height, one scanline a chunk (zips), has its own count or none.
    const std::string deep = dir + "/deep.exr";
    r = bokehtool(format("--scene lights:width=32:height=18:aa=1:output=deep -o {}", deep));
    ASSERT_EQ(r.status, 0) << r.err;
    ASSERT_EQ(header(deep).get_int_attribute("openexr:chunkCount"), 18);
    r = bokehtool(format("{0} --flatten --resize 32x36 -o:compression=zips {0}.flat.exr", deep));
    ASSERT_EQ(r.status, 0) << r.err;
    const int chunks = header(deep + ".flat.exr").get_int_attribute("openexr:chunkCount", 36);
    EXPECT_EQ(chunks, 36);
}

TEST(PipelineRules, PictureAperturePsfIsNormalisedLinearLight)
{
    const std::string dir = fresh_dir("rules_picture");
    // A binary disk: its values are 0 and 1 in any encoding, so the PNG and the EXR are
    // the same aperture.
    for (const char* ext : { "png", "exr" }) {
        OIIO::ImageBuf ap(OIIO::ImageSpec(33, 33, 3, std::string(ext) == "png" ? OIIO::TypeUInt8 : OIIO::TypeFloat));
        for (int y = 0; y < 33; ++y)
            for (int x = 0; x < 33; ++x) {
                const float v = (x - 16) * (x - 16) + (y - 16) * (y - 16) <= 15 * 15 ? 1.0f : 0.0f;
                const float px[3] = { v, v, v };
                ap.setpixel(x, y, px);
            }
        ASSERT_TRUE(ap.write(format("{}/aperture.{}", dir, ext)));
        RunResult r = bokehtool(format("{0}/aperture.{1} --bokeh:kernel=image 21 -o {0}/psf_{1}.exr", dir, ext));
        ASSERT_EQ(r.status, 0) << r.err;
        const auto stats = OIIO::ImageBufAlgo::computePixelStats(read_float(format("{}/psf_{}.exr", dir, ext)));
        const OIIO::ImageBuf psf = read_float(format("{}/psf_{}.exr", dir, ext));
        // The PNG's PSF is written as half (8-bit data goes to OpenEXR as half): each value
        // within 2^-11 of its own, the sum within about that.
        for (int c = 0; c < 3; ++c) {
            const double sum = stats.avg[size_t(c)] * double(psf.spec().image_pixels());
            EXPECT_NEAR(sum, 1.0, 1e-3) << ext << " channel " << c;
        }
    }
    const OIIO::ImageBuf from_png = read_float(dir + "/psf_png.exr"), from_exr = read_float(dir + "/psf_exr.exr");
    const double peak = OIIO::ImageBufAlgo::computePixelStats(from_exr).max[0];
    EXPECT_LT(max_difference(from_png, from_exr), peak / 1024.0);
}

TEST(PipelineRules, PerChannelAndGlobalPixelTypesInEitherOrder)
{
    const std::string dir = fresh_dir("rules_types"), scene = scene_file(dir);
    for (const char* order : { "-d Z=float -d half", "-d half -d Z=float" }) {
        RunResult r = bokehtool(format("{} {} -o {}/typed.exr", scene, order, dir));
        ASSERT_EQ(r.status, 0) << r.err;
        const OIIO::ImageSpec s = header(dir + "/typed.exr");
        EXPECT_EQ(s.channelformat(s.channelindex("Z")), OIIO::TypeFloat) << order;
        EXPECT_EQ(s.channelformat(s.channelindex("R")), OIIO::TypeHalf) << order;
    }
}

TEST(PipelineRules, DeepDefocusOutputMergesWithItsPass)
{
    const std::string dir = fresh_dir("rules_deep");
    RunResult r = bokehtool(format("--scene lights:width=48:height=27:aa=1:output=deep -o {0}/pass.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{0}/pass.exr --defocus:focus=6:fstop=2:output=deep -o {0}/dof_deep.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    ASSERT_LT(header(dir + "/pass.exr").channelindex("ZBack"), 0) << "a pass of point samples";
    ASSERT_GE(header(dir + "/dof_deep.exr").channelindex("ZBack"), 0) << "volume samples";
    r = bokehtool(format("{0}/dof_deep.exr {0}/pass.exr --deepmerge --flatten -o {0}/flat_a.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{0}/pass.exr {0}/dof_deep.exr --deepmerge --flatten -o {0}/flat_b.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_LT(max_difference(read_float(dir + "/flat_a.exr"), read_float(dir + "/flat_b.exr")), 1e-6)
        << "merge order does not matter";
}

TEST(PipelineRules, AFramePatternThatMatchesNothingNamesTheFileItLookedFor)
{
    const std::string dir = fresh_dir("rules_pattern"), scene = scene_file(dir);
    ASSERT_TRUE(OIIO::Filesystem::copy(scene, dir + "/shot.0001.exr"));
    RunResult r = bokehtool(format("{0}/shot.####.exr -o {0}/out.####.exr", dir));
    expect_clean_failure(r, format("frame 1 would be {}/shot.0000000000000001.exr; each '#' is 4 digits", dir), "");
    r = bokehtool(format("{0}/shot.#.exr -o {0}/out.#.exr", dir));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(exists(dir + "/out.0001.exr"));
}

TEST(PipelineRules, UpdateRedoesFramesMadeWithOtherOptions)
{
    const std::string dir = fresh_dir("rules_update"), scene = scene_file(dir);
    for (int f = 1; f <= 2; ++f)
        ASSERT_TRUE(OIIO::Filesystem::copy(scene, format("{}/in.{:04d}.exr", dir, f)));
    const std::string line = format("--frames 1-2 {0}/in.#.exr --defocus:focus=FOCUS -o {0}/out.#.exr", dir);
    auto run = [&](const std::string& flags, const char* focus) {
        return bokehtool(flags + " " + OIIO::Strutil::replace(line, "FOCUS", focus));
    };
    RunResult r = run("", "4");
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string first = file_bytes(dir + "/out.0001.exr");
    r = run("-u", "4");
    EXPECT_NE(r.out.find("-u: frame 1 skipped, up to date"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("-u: frame 2 skipped, up to date"), std::string::npos) << r.out;
    // Options that change no output leave the frames up to date.
    r = run("-u -v --threads 1 --progress --runstats", "4");
    EXPECT_NE(r.out.find("-u: frame 2 skipped, up to date"), std::string::npos) << r.out;
    // Another focus: both frames made again, and they differ.
    r = run("-u", "9");
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("-u: frame 1 made again: " + dir + "/out.0001.exr was made by another command line"),
              std::string::npos)
        << r.out;
    EXPECT_EQ(r.out.find("skipped"), std::string::npos) << r.out;
    EXPECT_NE(file_bytes(dir + "/out.0001.exr"), first);
    EXPECT_NE(header(dir + "/out.0002.exr").get_string_attribute("bokeh:command").find("focus=9"), std::string::npos);
}

TEST(PipelineRules, OutputFolderCheckedBeforeTheFrameIsComputed)
{
    const std::string dir = fresh_dir("rules_folder"), scene = scene_file(dir);
    RunResult r = bokehtool(format("-v {0} --defocus:focus=6 -o {1}/missing/out.exr", scene, dir));
    expect_clean_failure(r, format("-o: {0}/missing/out.exr: directory '{0}/missing' does not exist", dir), "");
    EXPECT_EQ(r.out.find("--defocus"), std::string::npos) << "nothing computed: " << r.out;
}

TEST(PipelineRules, DiffNamesEachImageByWhatMadeIt)
{
    const std::string dir = fresh_dir("rules_diff"), scene = scene_file(dir);
    RunResult r = bokehtool(format("{0} --defocus:focus=6:method=reference -o {1}/ref.exr {0} --defocus:focus=6 --diff",
                                   scene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find(format("diff {0} --defocus:focus=6 against the reference {0} --defocus:focus=6:method=reference:",
                                scene)),
              std::string::npos)
        << r.out;
    r = bokehtool(format("{0}/ref.exr {1} --defocus:focus=6 --diff", dir, scene));
    EXPECT_NE(r.out.find(format("against the reference {}/ref.exr:", dir)), std::string::npos) << r.out;
}

TEST(PipelineRules, BlurBorderIsOiiotools)
{
    const RunResult which = run_shell("command -v oiiotool");
    if (which.status != 0)
        GTEST_SKIP() << "oiiotool (Debian openimageio-tools) is not installed";
    const std::string dir = fresh_dir("rules_border");
    // A bright pixel at the left edge: clamp repeats it past the edge (10 + 10 + 0) / 3,
    // black counts 0 there (10 / 3).
    OIIO::ImageBuf img(OIIO::ImageSpec(6, 1, 1, OIIO::TypeFloat));
    const float ten = 10.0f;
    img.setpixel(0, 0, &ten);
    ASSERT_TRUE(img.write(dir + "/edge.exr"));
    ASSERT_EQ(run_shell(format("oiiotool {0}/edge.exr --blur:kernel=box 3x1 -o {0}/oiio.exr", dir)).status, 0);
    RunResult r = bokehtool(format("{0}/edge.exr --blur:kernel=box 3x1 -o {0}/ours.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const OIIO::ImageBuf oiio = read_float(dir + "/oiio.exr"), ours = read_float(dir + "/ours.exr");
    EXPECT_NEAR(oiio.getchannel(0, 0, 0, 0), 20.0f / 3.0f, 1e-5f) << "oiiotool clamps";
    EXPECT_LT(max_difference(oiio, ours), 1e-5);
}

TEST(PipelineRules, OptionMessagesAndRanges)
{
    const std::string dir = fresh_dir("rules_options"), scene = scene_file(dir);
    // reduction= takes its whole documented range.
    RunResult r = bokehtool(format("{0} --defocus:focus=6:reduction=3 -o {1}/r3.exr", scene, dir));
    EXPECT_EQ(r.status, 0) << r.err;
    // Every command with an aperture draws a star: the messages name what blades is for.
    for (const std::string& cmd : { format("{} --blur:kernel=disk:blades=5 9", scene),
                                   format("{} --defocus:kernel=disk:blades=5", scene), std::string("--bokeh:kernel=disk:blades=5 20") }) {
        r = bokehtool(format("{} -o {}/b.exr", cmd, dir));
        expect_clean_failure(r, "blades does not apply to kernel=disk: it is for kernel=polygon (and star, its points)",
                             dir + "/b.exr");
    }
    // --bokeh describes the lens only under -v.
    r = bokehtool(format("--bokeh 20 -o {}/p.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.out, "");
    r = bokehtool(format("-v --bokeh 20 -o {}/p.exr", dir));
    EXPECT_NE(r.out.find("bokeh: "), std::string::npos) << r.out;
}

TEST(FarmScripts, SubmitChecksBeforeQueueing)
{
    const std::string dir = fresh_dir("rules_farm"), submit = std::string(BOKEH_SOURCE_DIR) + "/examples/farm/submit_slurm.sh";
    RunResult r = run_shell(submit + " --help");
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("-n CPUS"), std::string::npos) << r.out;
    r = run_shell(submit + " -h");
    EXPECT_EQ(r.status, 0) << r.err;
    r = run_shell(format("BOKEHTOOL={}/no-such-tool {} 1 4 -- in.#.exr -o {}/o.#.exr", dir, submit, dir));
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("not found; put it on PATH or set BOKEHTOOL"), std::string::npos) << r.err;
    r = run_shell(format("BOKEHTOOL={} {} 1 4 -- in.#.exr -o {}/missing/o.#.exr", BOKEHTOOL, submit, dir));
    EXPECT_EQ(r.status, 2);
    EXPECT_NE(r.err.find("directory '" + dir + "/missing' does not exist"), std::string::npos) << r.err;
    r = run_shell(format("BOKEHTOOL={} {} -n 0 1 4 -- in.#.exr -o {}/o.#.exr", BOKEHTOOL, submit, dir));
    EXPECT_EQ(r.status, 2);
}

TEST(FarmScripts, ChunkRunsAsManyThreadsAsTheTaskHasCpus)
{
    const std::string dir = fresh_dir("rules_chunk"), chunk = std::string(BOKEH_SOURCE_DIR) + "/examples/farm/bokeh_chunk.sh";
    // A stand-in bokehtool that prints the arguments it is given.
    {
        std::ofstream fake(dir + "/fake_bokehtool");
        fake << "#!/bin/sh\necho \"args: $*\"\n";
    }
    ASSERT_EQ(run_shell("chmod +x " + dir + "/fake_bokehtool").status, 0);
    RunResult r = run_shell(format("SLURM_ARRAY_TASK_ID=1 SLURM_CPUS_PER_TASK=3 BOKEHTOOL={}/fake_bokehtool {} 1 10 4 "
                                   "slurm in.#.exr -o out.#.exr",
                                   dir, chunk));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("args: -u --skip-bad-frames --progress --runstats --threads 3 --frames 5-8 in.#.exr"),
              std::string::npos)
        << r.out;
    r = run_shell(format("env -u SLURM_CPUS_PER_TASK BOKEHTOOL={}/fake_bokehtool {} 1 10 4 0 in.#.exr", dir, chunk));
    EXPECT_NE(r.out.find("--threads 0 --frames 1-4"), std::string::npos) << r.out;
}

TEST(FarmScripts, BenchAnswersHelp)
{
    const std::string bench = OIIO::Filesystem::parent_path(BOKEHTOOL) + "/bokeh-bench";
    if (!exists(bench))
        GTEST_SKIP() << "bokeh-bench is not built";
    RunResult r = run_shell(bench + " --help");
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("usage: bokeh-bench"), std::string::npos) << r.out;
}

// Every command that takes an aperture or a camera spells them alike: the same names, value
// types, ranges and defaults in --defocus, --bokeh, --blur and --scene's truth (one table,
// plugins/shared/aperture_options.h). Read off each command's help, as a user sees them.
TEST(OptionTables, ApertureAndCameraOptionsAreTheSameInEveryCommand)
{
    // ":name=default  (type in [lo, hi]) help" -> "default  (type in [lo, hi])"
    auto options_of = [](const std::string& command) {
        const RunResult r = bokehtool("--help " + command);
        EXPECT_EQ(r.status, 0) << r.err;
        std::map<std::string, std::string> m;
        const std::regex line(R"(^\s+:([a-z]+)=(\S*)\s+\(([^)]*)\))");
        std::istringstream in(r.out);
        for (std::string l; std::getline(in, l);) {
            std::smatch s;
            if (std::regex_search(l, s, line))
                m[s[1]] = s[2].str() + "  (" + s[3].str() + ")";
        }
        return m;
    };
    const std::vector<std::string> commands = { "--defocus", "--bokeh", "--blur", "--scene" };
    std::map<std::string, std::map<std::string, std::string>> table;
    for (const std::string& c : commands)
        table[c] = options_of(c);
    const std::vector<std::string> shared = { "blades", "rotation", "curvature", "hole", "aspect",
                                              "fstop",  "focal",    "sensor" };
    int compared = 0;
    for (const std::string& name : shared) {
        std::string first_command, first;
        for (const std::string& c : commands) {
            const auto it = table[c].find(name);
            if (it == table[c].end())
                continue;
            if (first_command.empty()) {
                first_command = c;
                first         = it->second;
                continue;
            }
            ++compared;
            EXPECT_EQ(it->second, first) << name << ": " << c << " against " << first_command;
        }
    }
    // The aperture's shape in all four, the squeeze and the camera in the three lens commands.
    EXPECT_EQ(compared, 4 * 3 + 4 * 2);
    EXPECT_EQ(table["--defocus"]["fstop"], "2.8  (number in [0.5, 128])");
    EXPECT_EQ(table["--bokeh"]["focal"], "50  (number in [1, 5000])");
}
