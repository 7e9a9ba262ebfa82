// The parallel helper: results bit-identical for any thread count.
#include <bokeh/image.h>
#include <bokeh/parallel.h>
#include <bokeh/scene.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "test_util.h"

using namespace bokeh;

TEST(Parallel, ChunksCoverTheRangeOnce)
{
    for (int threads : { 1, 2, 8 }) {
        std::vector<int> hits(1003, 0);
        parallel_for_chunks(0, 1003, 17, threads, [&](int64_t b, int64_t e) {
            for (int64_t i = b; i < e; ++i)
                ++hits[size_t(i)];
        });
        for (int h : hits)
            ASSERT_EQ(h, 1);
    }
}

TEST(Parallel, ReductionIsBitIdenticalAcrossThreadCounts)
{
    // A float sum whose rounding depends on the order of additions.
    auto sum = [](int threads) {
        return parallel_reduce_chunks(
            0, 200000, 1000, threads, 0.0f,
            [](int64_t b, int64_t e) {
                float s = 0.0f;
                for (int64_t i = b; i < e; ++i)
                    s += 1.0f / float(i + 1) + std::sin(float(i)) * 1e3f;
                return s;
            },
            [](float& acc, float p) { acc += p; });
    };
    const float one = sum(1);
    for (int threads : { 2, 8 }) {
        const float other = sum(threads);
        EXPECT_EQ(std::memcmp(&one, &other, sizeof one), 0) << threads << " threads";
    }
}

TEST(Parallel, SceneAndScrubAreBitIdenticalFor1_2_8Threads)
{
    SceneOptions o;
    o.width  = 160;
    o.height = 90;
    OIIO::ImageBuf ref;
    ASSERT_TRUE(make_scene(ref, "lights", o, 1));
    // Poison some pixels so the scrub has work whose count must also agree.
    for (int i = 0; i < 50; ++i)
        ref.setpixel((i * 37) % 160, (i * 11) % 90,
                     std::vector<float>(5, std::numeric_limits<float>::quiet_NaN()).data());
    NonFiniteCount ref_count;
    scrub_nonfinite(ref, NonFinitePolicy::Zero, ref_count, 1);
    EXPECT_EQ(ref_count.colour, 200);
    EXPECT_EQ(ref_count.depth, 50);
    for (int threads : { 2, 8 }) {
        OIIO::ImageBuf img;
        ASSERT_TRUE(make_scene(img, "lights", o, threads));
        for (int i = 0; i < 50; ++i)
            img.setpixel((i * 37) % 160, (i * 11) % 90,
                         std::vector<float>(5, std::numeric_limits<float>::quiet_NaN()).data());
        NonFiniteCount count;
        scrub_nonfinite(img, NonFinitePolicy::Zero, count, threads);
        EXPECT_EQ(count.total(), ref_count.total());
        const size_t bytes = size_t(o.width) * size_t(o.height) * 5 * sizeof(float);
        EXPECT_EQ(std::memcmp(ref.localpixels(), img.localpixels(), bytes), 0)
            << threads << " threads";
    }
}
