// Reading and writing: clear failures, atomic writes, types/windows/metadata kept, deep.
#include <bokeh/image.h>
#include <bokeh/io.h>

#include <gtest/gtest.h>

#include <chrono>

#include <cstring>
#include <fstream>
#include <tuple>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <tbb/task_arena.h>

#include <unistd.h>

#include "test_util.h"

using namespace bokeh;
using namespace bokeh_test;

// A small half RGBA + float Z EXR with an offset data window and custom metadata.
static std::string make_exr(const std::string& dir, const std::string& name = "in.exr")
{
    OIIO::ImageSpec spec(40, 30, 5, OIIO::TypeHalf);
    spec.channelnames   = { "R", "G", "B", "A", "Z" };
    spec.channelformats = { OIIO::TypeHalf, OIIO::TypeHalf, OIIO::TypeHalf, OIIO::TypeHalf,
                            OIIO::TypeFloat };
    spec.alpha_channel  = 3;
    spec.z_channel      = 4;
    spec.x              = 7;
    spec.y              = 3;
    spec.full_x         = 0;
    spec.full_y         = 0;
    spec.full_width     = 64;
    spec.full_height    = 48;
    spec.attribute("studio:shot", "ab_0010");
    spec.attribute("studio:take", 3);
    const char* views[] = { "left", "right" };
    spec.attribute("multiView", OIIO::TypeDesc(OIIO::TypeDesc::STRING, 2), views);
    OIIO::ImageBuf buf(spec);
    for (int y = spec.y; y < spec.y + spec.height; ++y)
        for (int x = spec.x; x < spec.x + spec.width; ++x) {
            const float px[5] = { x / 64.0f, y / 48.0f, 0.25f, 1.0f, 1.0f + x * 0.01f + y };
            buf.setpixel(x, y, px);
        }
    const std::string path = dir + "/" + name;
    EXPECT_TRUE(buf.write(path));
    return path;
}

static size_t files_in(const std::string& dir)
{
    std::vector<std::string> files;
    OIIO::Filesystem::get_directory_entries(dir, files);
    return files.size();
}

TEST(Read, MissingDirectoryGarbageTruncated)
{
    const std::string dir = fresh_dir("io_read");
    OIIO::ImageBuf buf;
    std::string err;
    EXPECT_FALSE(read_image(buf, dir + "/nope.exr", err));
    EXPECT_NE(err.find("nope.exr: no such file"), std::string::npos) << err;
    EXPECT_FALSE(read_image(buf, dir, err));
    EXPECT_NE(err.find("is a directory"), std::string::npos) << err;

    std::ofstream(dir + "/garbage.exr") << "this is not an image at all";
    EXPECT_FALSE(read_image(buf, dir + "/garbage.exr", err));
    EXPECT_NE(err.find("garbage.exr"), std::string::npos) << err;

    const std::string good = make_exr(dir);
    const std::string bytes = file_bytes(good);
    std::ofstream(dir + "/truncated.exr", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    EXPECT_FALSE(read_image(buf, dir + "/truncated.exr", err));
    EXPECT_NE(err.find("truncated.exr"), std::string::npos) << err;
    std::string corrupt = bytes;
    for (size_t i = corrupt.size() / 2; i < corrupt.size(); i += 7)
        corrupt[i] = char(0xA5);
    std::ofstream(dir + "/corrupt.exr", std::ios::binary) << corrupt;
    EXPECT_FALSE(read_image(buf, dir + "/corrupt.exr", err));
    EXPECT_NE(err.find("corrupt.exr"), std::string::npos) << err;
}

TEST(Read, TruncatedRealFile)
{
    const std::string beach = shared_data("openexr-images/Beachball_singlepart.0001.exr");
    REQUIRE_SHARED(beach);
    const std::string dir   = fresh_dir("io_read_real");
    const std::string bytes = file_bytes(beach);
    std::ofstream(dir + "/cut.exr", std::ios::binary) << bytes.substr(0, bytes.size() * 3 / 4);
    OIIO::ImageBuf buf;
    std::string err;
    EXPECT_FALSE(read_image(buf, dir + "/cut.exr", err));
    EXPECT_TRUE(read_image(buf, beach, err)) << err;
    EXPECT_EQ(buf.spec().width, 911);
}

TEST(Write, KeepsTypesWindowsAndMetadata)
{
    const std::string dir = fresh_dir("io_write");
    const std::string in  = make_exr(dir);
    OIIO::ImageBuf buf;
    std::string err;
    ASSERT_TRUE(read_image(buf, in, err)) << err;
    EXPECT_EQ(buf.spec().format, OIIO::TypeFloat) << "worked on as float";
    WriteOptions opts;
    opts.channel_formats = formats_for(buf.spec(), channel_types_of(buf.nativespec()));
    ASSERT_TRUE(write_image(buf, dir + "/out.exr", opts, err)) << err;

    OIIO::ImageBuf back(dir + "/out.exr");
    ASSERT_TRUE(back.read(0, 0, true));
    const OIIO::ImageSpec& s = back.nativespec();
    EXPECT_EQ(s.channelformat(0), OIIO::TypeHalf);
    EXPECT_EQ(s.channelformat(4), OIIO::TypeFloat);
    EXPECT_EQ(s.channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" }));
    EXPECT_EQ(s.x, 7);
    EXPECT_EQ(s.y, 3);
    EXPECT_EQ(s.full_width, 64);
    EXPECT_EQ(s.full_height, 48);
    EXPECT_EQ(s.get_string_attribute("studio:shot"), "ab_0010");
    EXPECT_EQ(s.get_int_attribute("studio:take"), 3);
    const OIIO::ParamValue* views = s.find_attribute("multiView");
    ASSERT_NE(views, nullptr);
    EXPECT_EQ(views->type().arraylen, 2);
    OIIO::ImageBuf orig(in);
    EXPECT_EQ(max_difference(orig, back), 0.0) << "pixels identical";
    EXPECT_EQ(files_in(dir), 2u) << "no temporary file left behind";
}

TEST(Write, FailureLeavesNothingAndKeepsExistingFile)
{
    const std::string dir = fresh_dir("io_write_fail");
    const std::string in  = make_exr(dir);
    OIIO::ImageBuf buf;
    std::string err;
    ASSERT_TRUE(read_image(buf, in, err));
    EXPECT_FALSE(write_image(buf, dir + "/missing/out.exr", {}, err));
    EXPECT_NE(err.find("does not exist"), std::string::npos) << err;
    EXPECT_FALSE(write_image(buf, dir + "/out.unknownformat", {}, err));
    EXPECT_FALSE(exists(dir + "/out.unknownformat"));
    EXPECT_FALSE(write_image(buf, "/proc/bokeh_test_out.exr", {}, err)) << "read-only place";

    // An existing output survives a failed write and --no-clobber.
    std::ofstream(dir + "/keep.exr") << "precious";
    WriteOptions bad;
    bad.channel_formats = { OIIO::TypeHalf };  // wrong count: fails before writing
    EXPECT_FALSE(write_image(buf, dir + "/keep.exr", bad, err));
    WriteOptions nc;
    nc.no_clobber = true;
    EXPECT_FALSE(write_image(buf, dir + "/keep.exr", nc, err));
    EXPECT_NE(err.find("already exists"), std::string::npos) << err;
    EXPECT_EQ(file_bytes(dir + "/keep.exr"), "precious");
    EXPECT_EQ(files_in(dir), 2u) << "only in.exr and keep.exr";
}

TEST(Deep, RoundTripOfTheRealDeepPasses)
{
    for (const char* name : { "Balls", "Leaves", "Trunks" }) {
        const std::string path = shared_data(std::string("openexr-images/LowResLeftView_") + name + ".exr");
        REQUIRE_SHARED(path);
        const std::string dir = fresh_dir(std::string("io_deep_") + name);
        OIIO::ImageBuf a;
        std::string err;
        ASSERT_TRUE(read_image(a, path, err)) << err;
        ASSERT_TRUE(a.deep());
        ASSERT_TRUE(write_image(a, dir + "/rt.exr", {}, err)) << err;
        OIIO::ImageBuf b;
        ASSERT_TRUE(read_image(b, dir + "/rt.exr", err)) << err;
        ASSERT_TRUE(b.deep());
        EXPECT_EQ(a.spec().channelnames, b.spec().channelnames);
        EXPECT_EQ(a.roi(), b.roi());
        EXPECT_EQ(a.spec().full_width, b.spec().full_width);
        const OIIO::DeepData &da = *a.deepdata(), &db = *b.deepdata();
        ASSERT_EQ(da.pixels(), db.pixels());
        ASSERT_EQ(da.channels(), db.channels());
        for (int c = 0; c < da.channels(); ++c)
            EXPECT_EQ(da.channeltype(c), db.channeltype(c)) << "types kept";
        int64_t mismatches = 0, samples = 0;
        for (int64_t p = 0; p < da.pixels(); ++p) {
            ASSERT_EQ(da.samples(p), db.samples(p)) << "pixel " << p;
            for (int s = 0; s < da.samples(p); ++s, ++samples)
                for (int c = 0; c < da.channels(); ++c)
                    mismatches += da.deep_value(p, c, s) != db.deep_value(p, c, s);
        }
        EXPECT_EQ(mismatches, 0);
        EXPECT_GT(samples, 10000) << name;
        const DeepStats st = deep_stats(da);
        EXPECT_EQ(st.total_samples, samples);
        EXPECT_GE(st.max_samples, 1);
    }
}

TEST(Deep, StatsAndDescription)
{
    OIIO::ImageSpec spec(3, 1, 5, OIIO::TypeFloat);
    spec.channelnames = { "R", "G", "B", "A", "Z" };
    spec.deep         = true;
    OIIO::ImageBuf buf(spec);
    buf.deepdata()->set_samples(0, 2);
    buf.deepdata()->set_samples(2, 4);
    const DeepStats st = deep_stats(*buf.deepdata());
    EXPECT_EQ(st.pixels, 3);
    EXPECT_EQ(st.empty_pixels, 1);
    EXPECT_EQ(st.total_samples, 6);
    EXPECT_EQ(st.min_samples, 0);
    EXPECT_EQ(st.max_samples, 4);
    EXPECT_DOUBLE_EQ(st.mean_samples(), 2.0);
    const std::string d = describe_image(buf, "x.exr", true);
    EXPECT_NE(d.find("deep samples: 6 total; per pixel min 0, max 4, mean 2.000; 1 of 3 pixels empty"),
              std::string::npos)
        << d;
}

TEST(ReadCost, DeepSampleCountsAreTheFilesOwn)
{
    // The sample-count tables summed before reading equal the samples OIIO reads: a deep
    // tiled zip file, a scanline one, and one with up to 227 volume samples a pixel.
    for (const char* rel : { "oiio-testsuite/oiiotool-deep_src_deepalpha.exr",
                             "openexr-images/LowResLeftView_Trunks.exr",
                             "gaffer/representativeDeepImage.exr" }) {
        const std::string path = shared_data(rel);
        REQUIRE_SHARED(path);
        SCOPED_TRACE(rel);
        ReadCost cost;
        std::string err;
        ASSERT_TRUE(read_cost(path, int64_t(1) << 40, cost, err)) << err;
        OIIO::ImageBuf buf;
        ASSERT_TRUE(read_image(buf, path, err)) << err;
        EXPECT_FALSE(cost.at_least);
        EXPECT_EQ(cost.deep_samples, deep_stats(*buf.deepdata()).total_samples);
        EXPECT_NE(cost.what.find(", deep, "), std::string::npos) << cost.what;
        // A budget below it stops the count early and refuses the file by name.
        ReadOptions tight;
        tight.memory_budget_bytes = cost.bytes - 1;
        EXPECT_FALSE(read_image(buf, path, tight, err));
        EXPECT_NE(err.find("more than the memory budget of"), std::string::npos) << err;
    }
}

TEST(ReadCost, ATileIsCountedAsTheHeaderDeclaresIt)
{
    // The read fuzzer's 734-byte file of 16 x 12 half RGBA pixels in tiles of 8 x 4784136
    // (tests/fuzz/regressions/read_image): OpenEXR sizes its tile buffers by the declared
    // tile, not by the data window (its read took 730 MB and 6.4 s before it was found
    // truncated). The estimate: the float pixels, the offsets of its 2 chunks, and three
    // rows of declared tiles, two tiles wide (16 px): 3 x 4784136 x 16 x 8 bytes; a 256 MiB
    // budget refuses the file before it is opened, at once.
    const std::string path =
        std::string(BOKEH_SOURCE_DIR) + "/tests/fuzz/regressions/read_image/tiles-8x4784136-over-16x12-half-rgba.exr";
    ReadCost cost;
    std::string err;
    ASSERT_TRUE(read_cost(path, int64_t(1) << 40, cost, err)) << err;
    EXPECT_EQ(cost.bytes, 16 * 12 * 4 * 4 + 2 * 8 + int64_t(3) * 4784136 * 16 * 8);
    OIIO::ImageBuf buf;
    ReadOptions o;
    o.memory_budget_bytes = int64_t(256) << 20;
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_FALSE(read_image(buf, path, o, err));
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_NE(err.find("more than the memory budget of"), std::string::npos) << err;
    EXPECT_NE(err.find("(16 x 12, 4 channels, tiles of 8 x 4784136)"), std::string::npos) << err;
    EXPECT_LT(s, 1.0) << "refused before OpenEXR allocates its tiles";
}

TEST(ReadCost, FlatImageIsFloatPixelsAndChunkTable)
{
    const std::string dir = fresh_dir("io_read_cost");
    const std::string in  = make_exr(dir);
    ReadCost cost;
    std::string err;
    ASSERT_TRUE(read_cost(in, int64_t(1) << 40, cost, err)) << err;
    // 40 x 30 x 5 x 4 bytes, plus the offsets of the chunks (OIIO's default EXR
    // compression, zip: 16 lines a chunk, so 2 chunks), plus three rows of chunks in the
    // file's types (16 lines x 40 pixels x (4 half + 1 float = 12 bytes)).
    EXPECT_EQ(cost.bytes, 40 * 30 * 5 * 4 + 2 * 8 + 3 * 16 * 40 * 12);
    EXPECT_EQ(cost.what, "40 x 30, 5 channels");
    EXPECT_EQ(memory_size_text(1536), "1.5 KiB");
    EXPECT_EQ(memory_size_text(int64_t(3) << 30), "3.0 GiB");
    EXPECT_GT(default_memory_budget_bytes(), int64_t(1) << 28);
    const std::string tmp = partial_write_name(dir + "/out.exr");
    EXPECT_NE(tmp.find("/.out.exr.openbokeh-partial."), std::string::npos) << tmp;
    EXPECT_TRUE(OIIO::Strutil::ends_with(tmp, "." + std::to_string(getpid()) + ".exr")) << tmp;
}

TEST(Read, AFileRewrittenInPlaceIsReadAfresh)
{
    // The same name, the same file (inode), new content within the same second: OIIO's
    // shared ImageCache still held the first file's spec, and the read wrote the new
    // 64 x 40 x 4 pixels into a buffer made for 8 x 8 x 3 (a heap overflow inside OIIO,
    // found by the read fuzzer).
    const std::string dir = fresh_dir("io_rewritten");
    OIIO::ImageBuf small(OIIO::ImageSpec(8, 8, 3, OIIO::TypeFloat)), large(OIIO::ImageSpec(64, 40, 4, OIIO::TypeFloat));
    ASSERT_TRUE(small.write(dir + "/small.exr"));
    ASSERT_TRUE(large.write(dir + "/large.exr"));
    const std::string path = dir + "/same.exr";
    std::string err;
    std::ofstream(path, std::ios::binary) << file_bytes(dir + "/small.exr");
    OIIO::ImageBuf first, second;
    ASSERT_TRUE(read_image(first, path, err)) << err;
    {
        std::ofstream rewrite(path, std::ios::binary | std::ios::trunc);  // same inode
        rewrite << file_bytes(dir + "/large.exr");
    }
    ASSERT_TRUE(read_image(second, path, err)) << err;
    EXPECT_EQ(second.spec().width, 64);
    EXPECT_EQ(second.spec().height, 40);
    EXPECT_EQ(second.nchannels(), 4);
}

TEST(Multipart, ChannelNamesOfMergedParts)
{
    EXPECT_EQ(merged_channel_name("R", 0, "rgba", "", ""), "R");
    EXPECT_EQ(merged_channel_name("Z", 1, "depth", "", ""), "depth.Z");
    EXPECT_EQ(merged_channel_name("depth.Z", 1, "depth", "", ""), "depth.Z");
    EXPECT_EQ(merged_channel_name("Z", 2, "", "", ""), "part2.Z");
    EXPECT_EQ(merged_channel_name("R", 1, "rgba_left", "left", "right"), "left.R");
    EXPECT_EQ(merged_channel_name("Z", 1, "depth", "right", "right"), "depth.Z");
    EXPECT_EQ(channel_layer("forward.left.u"), "forward.left");
    EXPECT_EQ(channel_layer("R"), "");
}

TEST(Multipart, WriteReadRoundTripAndBudget)
{
    const std::string dir = fresh_dir("io_multipart");
    // R, G, B, A (half), depth.Z (float), mask.a (half): three parts per layer.
    OIIO::ImageSpec spec(24, 16, 6, OIIO::TypeFloat);
    spec.channelnames = { "R", "G", "B", "A", "depth.Z", "mask.a" };
    spec.alpha_channel = 3;
    spec.x = 5, spec.y = 2, spec.full_width = 40, spec.full_height = 30;
    OIIO::ImageBuf img(spec);
    for (int y = spec.y; y < spec.y + spec.height; ++y)
        for (int x = spec.x; x < spec.x + spec.width; ++x) {
            const float px[6] = { 0.25f * float(x), 0.5f, float(y), 1.0f, 3.0f + float(x), 0.125f };
            img.setpixel(x, y, px);
        }
    WriteOptions w;
    w.parts           = PartLayout::Layers;
    w.channel_formats = { OIIO::TypeHalf, OIIO::TypeHalf, OIIO::TypeHalf, OIIO::TypeHalf,
                          OIIO::TypeFloat, OIIO::TypeHalf };
    std::string err;
    ASSERT_TRUE(write_image(img, dir + "/p.exr", w, err)) << err;
    OIIO::ImageBuf back;
    ReadInfo info;
    ASSERT_TRUE(read_image(back, dir + "/p.exr", ReadOptions(), &info, err)) << err;
    EXPECT_EQ(info.part_names, (std::vector<std::string>{ "rgba", "depth", "mask" }));
    EXPECT_EQ(back.spec().channelnames, spec.channelnames);
    EXPECT_EQ(back.roi(), img.roi());
    EXPECT_EQ(back.spec().full_width, 40);
    EXPECT_EQ(back.spec().alpha_channel, 3);
    EXPECT_EQ(info.file_types.at("depth.Z"), OIIO::TypeFloat);
    EXPECT_EQ(info.file_types.at("mask.a"), OIIO::TypeHalf);
    // All values are exact in half.
    EXPECT_EQ(max_difference(back, img), 0.0);
    // The budget counts every part and the merged image: over 24 x 16 x 6 floats twice.
    ReadCost cost;
    ASSERT_TRUE(read_cost(dir + "/p.exr", int64_t(1) << 30, cost, err)) << err;
    EXPECT_GE(cost.bytes, 2 * 24 * 16 * 6 * 4);
    EXPECT_NE(cost.what.find("6 channels in 3 parts"), std::string::npos) << cost.what;
    ReadOptions tight;
    tight.memory_budget_bytes = 24 * 16 * 6 * 4;
    EXPECT_FALSE(read_image(back, dir + "/p.exr", tight, err));
    EXPECT_NE(err.find("more than the memory budget"), std::string::npos) << err;
}

// Zip and zips files are compressed by the library (core/io/exr_deflate.cpp), not by
// OpenEXR: they must read back bit for bit through OpenEXR's own zlib decoder, carry the
// header OIIO writes, be no larger than OpenEXR's, and not depend on the thread count.
TEST(Write, ZipChunksReadBackThroughOpenExr)
{
    const std::string dir = fresh_dir("io_zip");
    // 97 x 53: the last zip chunk holds 5 scanlines. The first 16 rows are random bits
    // (no deflate makes them smaller: the chunk is stored raw); the rest a smooth ramp.
    OIIO::ImageSpec spec(97, 53, 5, OIIO::TypeFloat);
    spec.channelnames = { "R", "G", "B", "A", "Z" };
    spec.z_channel    = 4;
    spec.x            = -3;
    spec.y            = 11;
    spec.attribute("studio:shot", "zz_0020");
    spec.attribute("studio:lens_mm", 35.0f);
    OIIO::ImageBuf img(spec);
    uint32_t state = 12345u;
    for (int y = spec.y; y < spec.y + spec.height; ++y)
        for (int x = spec.x; x < spec.x + spec.width; ++x)
            for (int c = 0; c < 5; ++c) {
                float v = 0.01f * float(x) + 0.1f * float(y) + float(c);
                if (y < spec.y + 16) {
                    state = state * 1664525u + 1013904223u;
                    const uint32_t bits = (state & 0x3fffffffu) | 0x00800000u;  // finite
                    std::memcpy(&v, &bits, 4);
                }
                static_cast<float*>(img.pixeladdr(x, y))[c] = v;
            }
    auto raw_pixels = [](const std::string& path, OIIO::ImageSpec& native) {
        auto in = OIIO::ImageInput::open(path);
        EXPECT_TRUE(in) << OIIO::geterror();
        std::vector<float> px;
        if (!in)
            return px;
        native = in->spec();
        px.resize(native.image_pixels() * size_t(native.nchannels));
        EXPECT_TRUE(in->read_image(0, 0, 0, native.nchannels, OIIO::TypeFloat, px.data()));
        return px;
    };
    const std::vector<float> want(static_cast<const float*>(img.localpixels()),
                                  static_cast<const float*>(img.localpixels())
                                      + spec.image_pixels() * 5);
    for (const std::string compression : { "zip", "zips" }) {
        SCOPED_TRACE(compression);
        WriteOptions opts;
        opts.compression = compression;
        std::string err;
        const std::string ours = dir + "/ours_" + compression + ".exr";
        ASSERT_TRUE(write_image(img, ours, opts, err)) << err;
        OIIO::ImageSpec ours_spec, oiio_spec;
        const std::vector<float> back = raw_pixels(ours, ours_spec);
        ASSERT_EQ(back.size(), want.size());
        EXPECT_EQ(std::memcmp(back.data(), want.data(), want.size() * 4), 0) << "bit for bit";
        EXPECT_EQ(ours_spec.get_string_attribute("compression"), compression);

        // OpenEXR's own writer, through OIIO, for the header and the size.
        OIIO::ImageSpec direct_spec = spec;
        describe_output(direct_spec, opts);  // the attributes every write adds
        direct_spec.attribute("compression", compression);
        const std::string theirs = dir + "/oiio_" + compression + ".exr";
        {
            auto out = OIIO::ImageOutput::create(theirs);
            ASSERT_TRUE(out && out->open(theirs, direct_spec)
                        && out->write_image(OIIO::TypeFloat, img.localpixels()) && out->close());
        }
        raw_pixels(theirs, oiio_spec);
        ASSERT_EQ(ours_spec.extra_attribs.size(), oiio_spec.extra_attribs.size());
        for (const OIIO::ParamValue& p : oiio_spec.extra_attribs) {
            if (p.name() == "DateTime")  // the clock's
                continue;
            const OIIO::ParamValue* q = ours_spec.find_attribute(p.name());
            ASSERT_NE(q, nullptr) << p.name();
            EXPECT_EQ(q->type(), p.type()) << p.name();
            EXPECT_EQ(q->get_string(), p.get_string()) << p.name();
        }
        EXPECT_EQ(ours_spec.x, spec.x);
        EXPECT_EQ(ours_spec.y, spec.y);
        const uint64_t ours_bytes   = OIIO::Filesystem::file_size(ours);
        const uint64_t theirs_bytes = OIIO::Filesystem::file_size(theirs);
        EXPECT_LE(double(ours_bytes), 1.01 * double(theirs_bytes))
            << ours_bytes << " bytes against OpenEXR's " << theirs_bytes;

        // One thread and two give the same file.
        std::string one, two;
        for (int threads : { 1, 2 }) {
            const std::string path = dir + "/t" + std::to_string(threads) + ".exr";
            tbb::task_arena arena(threads);
            bool wrote = false;
            arena.execute([&] { wrote = write_image(img, path, opts, err); });
            ASSERT_TRUE(wrote) << err;
            std::string bytes;
            ASSERT_TRUE(OIIO::Filesystem::read_text_file(path, bytes));
            (threads == 1 ? one : two) = bytes;
        }
        EXPECT_TRUE(one == two) << "thread count changed the file";
    }
}


TEST(MultiView, StereoPartsReadAsTheFirstViewWithItsDepth)
{
    const std::string dir = fresh_dir("io_stereo_parts"), path = stereo_parts_exr(dir);
    OIIO::ImageBuf img;
    std::string err;
    ReadInfo info;
    ASSERT_TRUE(read_image(img, path, ReadOptions(), &info, err)) << err;
    EXPECT_EQ(img.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "right.R", "right.G", "right.B",
                                                                  "right.A", "Z", "right.Z" }));
    EXPECT_EQ(img.spec().z_channel, 8);
    EXPECT_EQ(img.getchannel(3, 2, 0, 8), 3.0f) << "the left view's depth";
    EXPECT_EQ(info.file_types.at("Z"), OIIO::TypeFloat);
    // A view asked for: its parts only, named without the view.
    for (const auto& [view, r, z] : { std::make_tuple("left", 0.25f, 3.0f), std::make_tuple("right", 0.75f, 5.0f) }) {
        ReadOptions o;
        o.view = view;
        ASSERT_TRUE(read_image(img, path, o, &info, err)) << err;
        EXPECT_EQ(img.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" })) << view;
        EXPECT_EQ(img.getchannel(3, 2, 0, 0), r) << view;
        EXPECT_EQ(img.getchannel(3, 2, 0, 4), z) << view;
    }
    ReadOptions o;
    o.view = "centre";
    EXPECT_FALSE(read_image(img, path, o, err));
    EXPECT_EQ(err, path + ": no view 'centre' (its parts' views: left, right)");
}

TEST(MultiView, SinglePartViewsByTheChannelPrefix)
{
    const std::string dir = fresh_dir("io_stereo_single"), path = stereo_single_part_exr(dir);
    OIIO::ImageBuf img;
    std::string err;
    ASSERT_TRUE(read_image(img, path, err)) << err;
    EXPECT_EQ(img.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z", "right.R", "right.G",
                                                                  "right.B", "right.A", "right.Z" }))
        << "without a view asked for, the first view is the image and the others keep their prefix";
    EXPECT_EQ(img.getchannel(3, 2, 0, 4), 3.0f);
    // Where no rule says which depth is the image's, the error names the candidates.
    OIIO::ImageSpec two_depths(4, 4, 6, OIIO::TypeFloat);
    two_depths.channelnames = { "R", "G", "B", "A", "left.Z", "right.depth.Z" };
    EXPECT_EQ(no_depth_message(two_depths),
              "the image has no depth channel (Z); it holds left.Z, right.depth.Z: zchannel=NAME names one as the "
              "depth, or --view NAME reads one view of a stereo file");
    two_depths.channelnames = { "R", "G", "B", "A", "N.x", "N.y" };
    EXPECT_EQ(no_depth_message(two_depths), "the image has no depth channel (Z)");
    for (const auto& [view, r, z] : { std::make_tuple("left", 0.25f, 3.0f), std::make_tuple("right", 0.75f, 5.0f) }) {
        ReadOptions o;
        o.view = view;
        ReadInfo info;
        ASSERT_TRUE(read_image(img, path, o, &info, err)) << err;
        EXPECT_EQ(img.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" })) << view;
        EXPECT_EQ(img.spec().z_channel, 4);
        EXPECT_EQ(img.getchannel(3, 2, 0, 0), r) << view;
        EXPECT_EQ(img.getchannel(3, 2, 0, 4), z) << view;
        EXPECT_EQ(info.file_types.size(), 5u);
    }
    ReadOptions o;
    o.view = "centre";
    EXPECT_FALSE(read_image(img, path, o, err));
    EXPECT_EQ(err, path + ": no view 'centre' (its views: left, right)");
    // OpenEXR's own convention: the default view's channels unprefixed ("R", "Z"), the
    // other's prefixed ("right.R").
    OIIO::ImageSpec s(4, 2, 10, OIIO::TypeFloat);
    s.channelnames = { "R", "G", "B", "A", "Z", "right.R", "right.G", "right.B", "right.A", "right.Z" };
    const char* views[] = { "left", "right" };
    s.attribute("multiView", OIIO::TypeDesc(OIIO::TypeDesc::STRING, 2), views);
    std::vector<float> px(4 * 2 * 10);
    const float pixel[10] = { 0.25f, 0.5f, 0.5f, 1.0f, 3.0f, 0.75f, 0.5f, 0.5f, 1.0f, 5.0f };
    for (size_t i = 0; i < px.size(); ++i)
        px[i] = pixel[i % 10];
    auto out = OIIO::ImageOutput::create(dir + "/conv.exr");  // (ImageBuf::write drops multiView)
    ASSERT_TRUE(out && out->open(dir + "/conv.exr", s) && out->write_image(OIIO::TypeFloat, px.data())
                && out->close());
    ASSERT_TRUE(read_image(img, dir + "/conv.exr", err)) << err;
    EXPECT_EQ(img.spec().z_channel, 4) << "the default view's Z, as written";
    for (const auto& [view, r, z] : { std::make_tuple("left", 0.25f, 3.0f), std::make_tuple("right", 0.75f, 5.0f) }) {
        ReadOptions o;
        o.view = view;
        ASSERT_TRUE(read_image(img, dir + "/conv.exr", o, err)) << err;
        EXPECT_EQ(img.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" })) << view;
        EXPECT_EQ(img.getchannel(1, 1, 0, 0), r) << view;
        EXPECT_EQ(img.getchannel(1, 1, 0, 4), z) << view;
    }
}
