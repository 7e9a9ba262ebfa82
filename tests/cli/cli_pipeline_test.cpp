// bokehtool in a pipeline: multipart EXR in and out (depth in its own part, data windows
// that differ between parts, a part per layer on output), and oiiotool's flags for runs
// over sequences: -n, -u, --skip-bad-frames, --framepadding, --runstats, --missingfile,
// -o:compression= and -o:tile=.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <thread>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

// Write `parts` (each with its own spec; "oiio:subimagename" names the part) as one
// multipart file.
void write_multipart(const std::string& path, const std::vector<OIIO::ImageBuf>& parts)
{
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out);
    std::vector<OIIO::ImageSpec> specs;
    for (const OIIO::ImageBuf& p : parts)
        specs.push_back(p.spec());
    ASSERT_TRUE(out->open(path, int(specs.size()), specs.data())) << out->geterror();
    for (size_t i = 0; i < parts.size(); ++i) {
        if (i > 0) {
            ASSERT_TRUE(out->open(path, specs[i], OIIO::ImageOutput::AppendSubimage));
        }
        ASSERT_TRUE(parts[i].write(out.get())) << out->geterror();
    }
    ASSERT_TRUE(out->close());
}

constexpr int kW = 64, kH = 48;
// The depth part's data window, inside the colour part's 64 x 48: 8..55 x 4..43.
const OIIO::ROI kDepthWindow(8, 56, 4, 44);

float depth_value(int x, int y) { return 2.0f + 0.05f * float(x) + 0.03f * float(y); }

// Part "rgba" (half R, G, B, A over 64 x 48) and part "depth" (float Z over kDepthWindow),
// as Nuke writes a layer per part; and the same image as one part with Z set to 0 (no
// depth) outside kDepthWindow, the rule read_image follows.
void make_two_part_frame(const std::string& multipart, const std::string& single)
{
    OIIO::ImageSpec cs(kW, kH, 4, OIIO::TypeHalf);
    cs.channelnames = { "R", "G", "B", "A" };
    cs.alpha_channel = 3;
    cs.attribute("oiio:subimagename", "rgba");
    OIIO::ImageBuf colour(cs);
    OIIO::ImageSpec zs(kDepthWindow.width(), kDepthWindow.height(), 1, OIIO::TypeFloat);
    zs.x = kDepthWindow.xbegin, zs.y = kDepthWindow.ybegin;
    zs.full_width = kW, zs.full_height = kH;
    zs.channelnames = { "Z" };
    zs.attribute("oiio:subimagename", "depth");
    OIIO::ImageBuf depth(zs);
    OIIO::ImageSpec ss(kW, kH, 5, OIIO::TypeFloat);
    ss.channelnames   = { "R", "G", "B", "A", "Z" };
    ss.channelformats = { OIIO::TypeHalf, OIIO::TypeHalf, OIIO::TypeHalf, OIIO::TypeHalf,
                          OIIO::TypeFloat };
    ss.alpha_channel = 3, ss.z_channel = 4;
    OIIO::ImageBuf one(ss);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const bool light = (x / 8 + y / 8) % 2 == 0 || (x == 30 && y == 20);
            const float v = x == 30 && y == 20 ? 40.0f : light ? 0.8f : 0.1f;
            const float px[4] = { v, 0.5f * v, 0.25f, 1.0f };
            colour.setpixel(x, y, px);
            const bool inside = kDepthWindow.contains(x, y);
            if (inside) {
                const float z = depth_value(x, y);
                depth.setpixel(x, y, &z);
            }
            const float all[5] = { px[0], px[1], px[2], px[3], inside ? depth_value(x, y) : 0.0f };
            one.setpixel(x, y, all);
        }
    write_multipart(multipart, { colour, depth });
    ASSERT_TRUE(one.write(single));
}

OIIO::ImageBuf read_float(const std::string& path, int subimage = 0)
{
    OIIO::ImageBuf b(path, subimage, 0);
    EXPECT_TRUE(b.read(subimage, 0, true, OIIO::TypeFloat)) << path << ": " << b.geterror();
    return b;
}

OIIO::ImageBuf channels_named(const OIIO::ImageBuf& img, const std::vector<std::string>& names)
{
    std::vector<int> order;
    for (const std::string& n : names) {
        order.push_back(img.spec().channelindex(n));
        EXPECT_GE(order.back(), 0) << "no channel " << n;
    }
    return OIIO::ImageBufAlgo::channels(img, int(order.size()), order);
}

std::vector<std::string> part_names(const std::string& path)
{
    std::vector<std::string> names;
    auto in = OIIO::ImageInput::open(path);
    if (!in)
        return names;
    for (int s = 0; in->seek_subimage(s, 0); ++s)
        names.push_back(in->spec().get_string_attribute("oiio:subimagename"));
    return names;
}

std::filesystem::file_time_type mtime(const std::string& path)
{
    return std::filesystem::last_write_time(path);
}

// Four frames of a 32 x 24 scene, the input of the sequence tests.
void make_frames(const std::string& dir, int first, int last)
{
    RunResult r = bokehtool(format("--frames {}-{} --scene lights:width=32:height=24 -o {}/in.#.exr",
                                   first, last, dir));
    ASSERT_EQ(r.status, 0) << r.err;
}

}  // namespace

TEST(Multipart, DepthInItsOwnPartIsFoundAndMatchesOnePart)
{
    const std::string dir = fresh_dir("mp_depth");
    make_two_part_frame(dir + "/mp.exr", dir + "/one.exr");
    const std::string before = file_bytes(dir + "/mp.exr");

    // Merged on read: the colour part's channels by their names, the depth part's Z as
    // depth.Z, over the union of the windows; --info names the parts.
    RunResult r = bokehtool(format("--info -v {0}/mp.exr -o {0}/merged.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("2 parts merged: rgba, depth"), std::string::npos) << r.out;
    OIIO::ImageBuf merged = read_float(dir + "/merged.exr");
    EXPECT_EQ(merged.spec().nchannels, 5);
    EXPECT_EQ(merged.roi(), OIIO::ROI(0, kW, 0, kH, 0, 1, 0, 5));
    const int zc = merged.spec().channelindex("depth.Z");
    ASSERT_GE(zc, 0);
    EXPECT_EQ(merged.nativespec().channelformat(zc), OIIO::TypeFloat) << "Z keeps its type";
    EXPECT_EQ(merged.nativespec().channelformat(0), OIIO::TypeHalf) << "colour stays half";
    // Inside the depth part's window its values, outside 0 (no depth): exactly.
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x)
            ASSERT_EQ(merged.getchannel(x, y, 0, zc),
                      kDepthWindow.contains(x, y) ? depth_value(x, y) : 0.0f)
                << x << "," << y;

    // --defocus finds depth.Z in the other part: the same pixels as the one-part frame
    // (the merge is a copy, so the tolerance is 0).
    r = bokehtool(format("{0}/mp.exr --defocus:focus=3:fstop=1.4:focal=200 -o {0}/a.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{0}/one.exr --defocus:focus=3:fstop=1.4:focal=200 -o {0}/b.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const OIIO::ImageBuf a = read_float(dir + "/a.exr"), b = read_float(dir + "/b.exr");
    const std::vector<std::string> rgba = { "R", "G", "B", "A" };
    EXPECT_EQ(max_difference(channels_named(a, rgba), channels_named(b, rgba)), 0.0);
    // The defocus did something: the 40-bright pixel was spread.
    OIIO::ImageBuf sharp = channels_named(read_float(dir + "/one.exr"), rgba);
    EXPECT_GT(max_difference(channels_named(b, rgba), sharp), 0.5);
    // Named explicitly, the same.
    r = bokehtool(format("{0}/mp.exr --defocus:focus=3:fstop=1.4:focal=200:zchannel=depth.Z -o {0}/c.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(max_difference(channels_named(read_float(dir + "/c.exr"), rgba), channels_named(b, rgba)), 0.0);
    EXPECT_EQ(file_bytes(dir + "/mp.exr"), before) << "input untouched";
}

TEST(Multipart, PartWithoutTheNamedChannelIsOneLine)
{
    const std::string dir = fresh_dir("mp_bad");
    make_two_part_frame(dir + "/mp.exr", dir + "/one.exr");
    RunResult r = bokehtool(format("{0}/mp.exr --defocus:zchannel=depth.Y -o {0}/x.exr", dir));
    expect_clean_failure(r, "--defocus: zchannel=depth.Y: no channel 'depth.Y': layer (or part) "
                            "'depth' holds depth.Z",
                         dir + "/x.exr");
    r = bokehtool(format("{0}/mp.exr --defocus:zchannel=shadow.Z -o {0}/x.exr", dir));
    expect_clean_failure(r, "no channel 'shadow.Z' (the image has R, G, B, A, depth.Z)",
                         dir + "/x.exr");
    // A part of its own name ("Z" in part "depth") but a look-up by the bare name.
    r = bokehtool(format("{0}/mp.exr --defocus:zchannel=Z -o {0}/x.exr", dir));
    expect_clean_failure(r, "no channel 'Z'", dir + "/x.exr");
}

TEST(Multipart, PartsPerLayerOnOutputRoundTrip)
{
    const std::string dir = fresh_dir("mp_layers");
    make_two_part_frame(dir + "/mp.exr", dir + "/one.exr");
    RunResult r = bokehtool(format("{0}/mp.exr --ch R,G,B,A,depth.Z,extra.mask=0.5 "
                                   "-o:parts=layers {0}/layers.exr",
                                   dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(part_names(dir + "/layers.exr"), (std::vector<std::string>{ "rgba", "depth", "extra" }));
    OIIO::ImageBuf p0 = read_float(dir + "/layers.exr", 0), p1 = read_float(dir + "/layers.exr", 1);
    EXPECT_EQ(p0.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A" }));
    EXPECT_EQ(p1.spec().channelnames, (std::vector<std::string>{ "depth.Z" }));
    EXPECT_EQ(p1.nativespec().format, OIIO::TypeFloat);
    EXPECT_EQ(p0.nativespec().format, OIIO::TypeHalf);
    // Read back by bokehtool: the same image as the multipart input read (tolerance 0).
    r = bokehtool(format("{0}/layers.exr -o {0}/back.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{0}/mp.exr --ch R,G,B,A,depth.Z,extra.mask=0.5 -o {0}/direct.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(max_difference(read_float(dir + "/back.exr"), read_float(dir + "/direct.exr")), 0.0);
    // Another format: refused by name, nothing written.
    r = bokehtool(format("{0}/mp.exr --ch R,G,B,depth.Z -o:parts=layers {0}/x.tif", dir));
    expect_clean_failure(r, "a part per layer is written to OpenEXR files, not tiff", dir + "/x.tif");
}

TEST(Multipart, BeachballSplitIntoPartsDefocusesAsTheSinglePartFrame)
{
    const std::string beachball = shared_data("openexr-images/Beachball_singlepart.0001.exr");
    REQUIRE_SHARED(beachball);
    const std::string dir = fresh_dir("mp_beachball");
    // OpenEXR's single-part frame written by bokehtool as a part per layer (rgba, depth
    // is Z there, disparityL, forward, left, ...), then both defocused.
    RunResult r = bokehtool(format("{} -o:parts=layers {}/parts.exr", beachball, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    const std::vector<std::string> parts = part_names(dir + "/parts.exr");
    EXPECT_GE(parts.size(), 5u);
    EXPECT_EQ(parts.front(), "rgba");
    const std::string opts = "--defocus:focus=5:fstop=2:focal=35 --ch R,G,B,A";
    r = bokehtool(format("{0}/parts.exr {1} -o {0}/a.exr", dir, opts));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("{0} {1} -o {2}/b.exr", beachball, opts, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(max_difference(read_float(dir + "/a.exr"), read_float(dir + "/b.exr")), 0.0);
}

// ---------------------------------------------------------------------------------------
// oiiotool's flags.

TEST(PipelineFlags, DryRunWritesNothing)
{
    const std::string dir = fresh_dir("flag_n");
    RunResult r = bokehtool(format("-n --frames 1-2 --scene lights:width=32:height=24 -o {}/f.#.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find(format("-n: would write {}/f.0001.exr", dir)), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(format("-n: would write {}/f.0002.exr", dir)), std::string::npos) << r.out;
    std::vector<std::string> files;
    OIIO::Filesystem::get_directory_entries(dir, files);
    EXPECT_TRUE(files.empty()) << files.size() << " files written";
    // Bad input is still found.
    r = bokehtool(format("-n {0}/nosuch.exr -o {0}/x.exr", dir));
    expect_clean_failure(r, "nosuch.exr: no such file", dir + "/x.exr");
}

TEST(PipelineFlags, UpdateSkipsFramesNewerThanTheirInputs)
{
    const std::string dir = fresh_dir("flag_u");
    make_frames(dir, 1, 3);
    const std::string line = format("-u --frames 1-3 {0}/in.#.exr --blur 3x3 -o {0}/out.#.exr", dir);
    RunResult r = bokehtool(line);
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.out.find("skipped"), std::string::npos) << "nothing to skip yet: " << r.out;
    const auto t1 = mtime(dir + "/out.0001.exr");
    OIIO::Filesystem::remove(dir + "/out.0002.exr");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    // Frame 3's input made newer than its output.
    std::filesystem::last_write_time(dir + "/in.0003.exr",
                                     std::filesystem::file_time_type::clock::now());
    r = bokehtool(line);
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("-u: frame 1 skipped, up to date"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("frame 2 skipped"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("frame 3 skipped"), std::string::npos) << r.out;
    EXPECT_EQ(mtime(dir + "/out.0001.exr"), t1) << "frame 1 not rewritten";
    EXPECT_TRUE(exists(dir + "/out.0002.exr"));
    EXPECT_GT(mtime(dir + "/out.0003.exr"), mtime(dir + "/in.0003.exr"));
    // A generated frame (no input file) is up to date once its output exists.
    r = bokehtool(format("-u --scene lights:width=16:height=8 -o {}/gen.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("-u --scene lights:width=16:height=8 -o {}/gen.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.out.find("-u: the image skipped"), std::string::npos) << r.out;
}

TEST(PipelineFlags, SkipBadFramesGoesOnAndStillFails)
{
    const std::string dir = fresh_dir("flag_skip");
    make_frames(dir, 1, 4);
    {
        std::ofstream bad(dir + "/in.0002.exr", std::ios::binary | std::ios::trunc);
        bad << "not an image at all";
    }
    const std::string before = file_bytes(dir + "/in.0002.exr");
    RunResult r = bokehtool(format("--skip-bad-frames --frames 1-4 {0}/in.#.exr -o {0}/out.#.exr", dir));
    EXPECT_EQ(r.status, 1);
    EXPECT_NE(r.err.find("(frame 2, 2 of 4; skipped, the run goes on)"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("bokehtool ERROR: --skip-bad-frames: 1 of 4 frames failed: 2\n"),
              std::string::npos)
        << r.err;
    for (int f : { 1, 3, 4 })
        EXPECT_TRUE(exists(format("{}/out.{:04d}.exr", dir, f))) << f;
    EXPECT_FALSE(exists(dir + "/out.0002.exr"));
    EXPECT_EQ(file_bytes(dir + "/in.0002.exr"), before);
    // Without the flag the run stops at frame 2.
    const std::string stop = fresh_dir("flag_skip_stop");
    make_frames(stop, 1, 3);
    OIIO::Filesystem::remove(stop + "/in.0002.exr");
    r = bokehtool(format("--frames 1-3 {0}/in.#.exr -o {0}/out.#.exr", stop));
    expect_clean_failure(r, "(frame 2, 2 of 3; the run stopped here)", stop + "/out.0002.exr");
    EXPECT_FALSE(exists(stop + "/out.0003.exr"));
}

TEST(PipelineFlags, FramePaddingAndRunstats)
{
    const std::string dir = fresh_dir("flag_pad");
    RunResult r = bokehtool(format("--framepadding 2 --runstats --frames 8-10 "
                                   "--scene lights:width=16:height=8 -o {}/f.#.exr",
                                   dir));
    ASSERT_EQ(r.status, 0) << r.err;
    for (const char* f : { "f.08.exr", "f.09.exr", "f.10.exr" })
        EXPECT_TRUE(exists(dir + "/" + f)) << f;
    EXPECT_NE(r.out.find("runstats: 3 frame(s) done, 0 skipped (-u), 0 failed;"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("peak memory"), std::string::npos) << r.out;
    r = bokehtool(format("--framepadding 0 --frames 1 --scene lights -o {}/g.#.exr", dir));
    expect_clean_failure(r, "--framepadding: '0' is not a digit count (1..9)", "");
}

TEST(PipelineFlags, MissingFilePolicies)
{
    const std::string dir = fresh_dir("flag_missing");
    OIIO::ImageBuf in = rgbaz_image(80, 40, [](int x, int y) {
        return std::array<float, 5>{ 0.5f, x / 80.0f, y / 40.0f, 1.0f, 4.0f };
    });
    ASSERT_TRUE(in.write(dir + "/in.0001.exr"));
    // error (the default): one line, the frame named, nothing written for it.
    RunResult r = bokehtool(format("--frames 1-2 {0}/in.#.exr -o {0}/e.#.exr", dir));
    expect_clean_failure(r, "in.0002.exr: no such file", dir + "/e.0002.exr");
    // black: a warning and a zero image the size of the last one read.
    r = bokehtool(format("--missingfile black --frames 1-2 {0}/in.#.exr -o {0}/b.#.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_NE(r.err.find("in.0002.exr: no such file; a black image of 80 x 40, 5 channels in its place"),
              std::string::npos)
        << r.err;
    // A warning says that the run goes on, as it does, not that it stopped.
    EXPECT_NE(r.err.find("(--missingfile black; frame 2, 2 of 2); the run goes on"), std::string::npos)
        << r.err;
    EXPECT_EQ(r.err.find("stopped"), std::string::npos) << r.err;
    OIIO::ImageBuf black = read_float(dir + "/b.0002.exr");
    EXPECT_EQ(black.spec().width, 80);
    auto stats = OIIO::ImageBufAlgo::computePixelStats(black);
    for (int c = 0; c < 5; ++c)
        EXPECT_EQ(stats.max[size_t(c)], 0.0f) << c;
    // checker: oiiotool's 64-pixel squares, black (alpha 1) at the origin, depth 0.
    r = bokehtool(format("--missingfile checker --frames 2 {0}/in.#.exr -o {0}/c.#.exr", dir));
    ASSERT_EQ(r.status, 0) << r.err;
    OIIO::ImageBuf checker = read_float(dir + "/c.0002.exr");
    EXPECT_EQ(checker.spec().width, 1920) << "nothing read before: oiiotool's 1920x1080 RGBA";
    EXPECT_EQ(checker.getchannel(0, 0, 0, 0), 0.0f);
    EXPECT_EQ(checker.getchannel(0, 0, 0, 3), 1.0f);
    EXPECT_EQ(checker.getchannel(64, 0, 0, 0), 1.0f);
    EXPECT_EQ(checker.getchannel(64, 64, 0, 0), 0.0f);
    r = bokehtool(format("--missingfile grey {0}/in.0001.exr -o {0}/x.exr", dir));
    expect_clean_failure(r, "--missingfile: 'grey' is not a policy (error, black, checker)",
                         dir + "/x.exr");
}

TEST(PipelineFlags, CompressionAndTilesAsOiiotoolTakesThem)
{
    const std::string dir = fresh_dir("flag_compress");
    const std::string scene = "--scene lights:width=64:height=32";
    struct Case {
        const char* modifier;
        const char* compression;
    };
    for (const Case& c : { Case{ "compression=dwaa:45", "dwaa" }, Case{ "compression=piz", "piz" },
                           Case{ "compression=none", "none" }, Case{ "compression=zips", "zips" } }) {
        RunResult r = bokehtool(format("{} -o:{} {}/c.exr", scene, c.modifier, dir));
        ASSERT_EQ(r.status, 0) << c.modifier << ": " << r.err;
        auto in = OIIO::ImageInput::open(dir + "/c.exr");
        ASSERT_TRUE(in);
        EXPECT_EQ(in->spec().get_string_attribute("compression"), c.compression) << c.modifier;
        if (std::string(c.compression) == "dwaa") {
            EXPECT_EQ(in->spec().get_float_attribute("openexr:dwaCompressionLevel"), 45.0f);
        }
    }
    for (const char* tile : { "16,8", "16x8" }) {
        RunResult r = bokehtool(format("{} -o:tile={}:compression=zip {}/t.exr", scene, tile, dir));
        ASSERT_EQ(r.status, 0) << r.err;
        auto in = OIIO::ImageInput::open(dir + "/t.exr");
        ASSERT_TRUE(in);
        EXPECT_EQ(in->spec().tile_width, 16) << tile;
        EXPECT_EQ(in->spec().tile_height, 8) << tile;
    }
    // The pixels are the same whatever the lossless compression and tiling.
    RunResult r = bokehtool(format("{0} -o {1}/plain.exr -o:tile=16,8:compression=piz {1}/tp.exr", scene, dir));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(max_difference(read_float(dir + "/plain.exr"), read_float(dir + "/tp.exr")), 0.0);

    r = bokehtool(format("{} -o:compression=bogus {}/x.exr", scene, dir));
    expect_clean_failure(r, "'bogus' is not an OpenEXR compression", dir + "/x.exr");
    r = bokehtool(format("{} -o:tile=0,8 {}/x.exr", scene, dir));
    expect_clean_failure(r, "-o: tile=0,8 is not a tile size", dir + "/x.exr");
    r = bokehtool(format("{} -o:tile=16,8 {}/x.png", scene, dir));
    expect_clean_failure(r, "cannot hold tiles", dir + "/x.png");
}

TEST(PipelineFlags, ParallelFramesGiveTheSameFilesAndReportFailures)
{
    const std::string dir = fresh_dir("flag_parallel");
    make_frames(dir, 1, 5);
    // The write time fixed (SOURCE_DATE_EPOCH), as the files are compared byte for byte.
    const std::string epoch = "SOURCE_DATE_EPOCH=1700000000";
    RunResult r = bokehtool(format("--frames 1-5 {0}/in.#.exr --defocus:focus=4 -o {0}/a.#.exr", dir), epoch);
    ASSERT_EQ(r.status, 0) << r.err;
    r = bokehtool(format("--parallel-frames --progress --frames 1-5 {0}/in.#.exr --defocus:focus=4 "
                         "-o {0}/b.#.exr",
                         dir),
                  epoch);
    ASSERT_EQ(r.status, 0) << r.err;
    for (int f = 1; f <= 5; ++f) {
        const std::string a = file_bytes(format("{}/a.{:04d}.exr", dir, f));
        EXPECT_FALSE(a.empty()) << f;
        EXPECT_EQ(a, file_bytes(format("{}/b.{:04d}.exr", dir, f))) << "frame " << f << " byte-identical";
        EXPECT_NE(r.out.find(format("frame {} ({} of 5) done", f, f)), std::string::npos) << r.out;
    }
    // A bad input frame (read ahead, then read again to report it) and an output that
    // cannot be written (written behind): each named, the others written.
    {
        std::ofstream bad(dir + "/in.0003.exr", std::ios::binary | std::ios::trunc);
        bad << "truncated";
    }
    r = bokehtool(format("--parallel-frames --skip-bad-frames --frames 1-5 {0}/in.#.exr "
                         "--defocus:focus=4 -o {0}/c.#.exr",
                         dir),
                  epoch);
    EXPECT_EQ(r.status, 1);
    EXPECT_NE(r.err.find("in.0003.exr: cannot read"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("(frame 3, 3 of 5; skipped, the run goes on)"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("1 of 5 frames failed: 3\n"), std::string::npos) << r.err;
    for (int f : { 1, 2, 4, 5 })
        EXPECT_EQ(file_bytes(format("{}/c.{:04d}.exr", dir, f)), file_bytes(format("{}/a.{:04d}.exr", dir, f))) << f;
    EXPECT_FALSE(exists(dir + "/c.0003.exr"));
    r = bokehtool(format("--parallel-frames --frames 1-2 {0}/in.#.exr -o {0}/nodir/e.#.exr", dir));
    expect_clean_failure(r, "directory '" + dir + "/nodir' does not exist (frame 1, 1 of 2; the run stopped here)",
                         dir + "/nodir/e.0001.exr");
}
