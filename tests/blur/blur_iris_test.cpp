// Iris mode (BlurOptions::iris, core/blur/iris.cpp): the exp / mean / log blur against its
// brute force, its limit, its range, and the channels it leaves linear.
#include <bokeh/blur.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>

#include "blur_fixtures.h"
#include "test_util.h"

using namespace bokeh;
using namespace blur_test;

TEST(BlurIris, HighlightsDominateAndFlatAreasStay)
{
    Kernel disk;
    disk.shape    = KernelShape::Disk;
    disk.width_px = disk.height_px = 9;
    // A bright square on a dark ground: at the boundary the exp/log mean lies above the
    // plain mean (Jensen's inequality), and a flat area is unchanged.
    OIIO::ImageBuf src(OIIO::ImageSpec(40, 40, 4, OIIO::TypeFloat));
    for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 40; ++x) {
            const float v = (x >= 20 && y >= 20) ? 3.0f : 0.2f;
            const float px[4] = { v, v, v, 1.0f };
            src.setpixel(x, y, px);
        }
    src.specmod().alpha_channel = 3;
    BlurOptions plain, iris;
    plain.border = iris.border = Border::Clamp;
    iris.iris                  = 4.0f;
    OIIO::ImageBuf a, b;
    ASSERT_TRUE(blur(a, src, disk, plain));
    ASSERT_TRUE(blur(b, src, disk, iris)) << b.geterror();
    float pa[4], pb[4];
    a.getpixel(18, 25, pa);
    b.getpixel(18, 25, pb);
    EXPECT_GT(pb[0], pa[0] + 0.3f) << "the highlight wins at the edge";
    EXPECT_LT(pb[0], 3.0f);
    EXPECT_FLOAT_EQ(pb[3], 1.0f) << "alpha is averaged plainly";
    b.getpixel(5, 5, pb);
    EXPECT_NEAR(pb[0], 0.2f, 1e-5f) << "flat dark area";
    b.getpixel(34, 34, pb);
    EXPECT_NEAR(pb[0], 3.0f, 1e-5f) << "flat bright area";
    // A tiny k tends to the plain average.
    iris.iris = 1e-3f;
    ASSERT_TRUE(blur(b, src, disk, iris));
    EXPECT_LE(bokeh_test::max_difference(a, b), 2e-3);
    // exp(k x) past what the sums keep (|k| times the range over 30) is refused, not clamped.
    iris.iris = 40.0f;
    EXPECT_FALSE(blur(b, src, disk, iris));
    EXPECT_NE(b.geterror().find("exceeds 30"), std::string::npos) << b.geterror();
}

TEST(BlurIris, EveryMethodStaysWithinTheChannelRangeAtTheLimit)
{
    // An iris mean lies between the channel's least and greatest value (every method's
    // weights are >= 0); at |k| times the range just under the limit (0.003 .. 500 here)
    // each method keeps to it, and just over the limit the blur is refused. Past ~40 the
    // running sums returned NaN (bands) and values below the least.
    const OIIO::ImageBuf src = test_image(150, 120);
    const double lo = 0.0, hi = 500.0;  // black outside: the padding counts as 0
    struct Case {
        KernelShape shape;
        BlurMethod method;
    };
    for (const Case& c : { Case{ KernelShape::Disk, BlurMethod::Exact }, Case{ KernelShape::Disk, BlurMethod::Fft },
                           Case{ KernelShape::Disk, BlurMethod::Bands },
                           Case{ KernelShape::Polygon, BlurMethod::Parallelograms },
                           Case{ KernelShape::Gaussian, BlurMethod::ThreeBoxes }, Case{ KernelShape::Box, BlurMethod::Exact } }) {
        SCOPED_TRACE(int(c.method));
        SCOPED_TRACE(int(c.shape));
        Kernel k;
        k.shape     = c.shape;
        k.blades    = 6;
        k.width_px  = 19;
        k.height_px = 19;
        BlurOptions o;
        o.method = c.method;
        o.iris   = float(29.9 / (hi - lo));
        OIIO::ImageBuf out;
        ASSERT_TRUE(blur(out, src, k, o)) << out.geterror();
        const auto stats = OIIO::ImageBufAlgo::computePixelStats(out);
        for (int ch = 0; ch < 3; ++ch) {
            EXPECT_EQ(stats.nancount[size_t(ch)] + stats.infcount[size_t(ch)], 0u) << ch;
            EXPECT_GE(stats.min[size_t(ch)], lo - 1e-3) << ch;
            EXPECT_LE(stats.max[size_t(ch)], hi + 1e-3) << ch;
        }
        o.iris = float(30.5 / (hi - lo));
        EXPECT_FALSE(blur(out, src, k, o));
        EXPECT_NE(out.geterror().find("exceeds 30"), std::string::npos) << out.geterror();
    }
}

TEST(BlurIris, ExactMethodsMatchTheBruteForceOfExpMeanLog)
{
    // Iris mode's reference written out: exp(k x) per colour channel, the brute-force
    // convolution, log(mean) / k; alpha plainly. Under the black border the outside is 0,
    // so exp(k 0) = 1 in exp space: its weight (1 less the inside's, the brute force on a
    // ones image) adds 1 times it. Every kernel, every exact method, every border, k of
    // both signs up to |k| x range = 25 (the limit is 30).
    const OIIO::ImageBuf src = test_image(47, 39);  // 0 .. 500
    const int alpha          = src.spec().alpha_channel;
    OIIO::ImageBuf ones(src.spec());
    OIIO::ImageBufAlgo::fill(ones, { 1.0f, 1.0f, 1.0f, 1.0f });
    double worst = 0.0;
    for (const Named& n : kernels())
        for (BlurMethod m : exact_methods(n.k))
            for (Border border : { Border::Black, Border::Clamp, Border::Mirror })
                for (float k : { 0.05f, -0.05f, 0.004f }) {
                    SCOPED_TRACE(testing::Message() << n.name << method_name(m) << " border " << int(border)
                                                    << " k " << k);
                    BlurOptions o;
                    o.method = m;
                    o.border = border;
                    o.iris   = k;
                    OIIO::ImageBuf got;
                    const KernelWeights kw = kernel_weights(n.k);
                    if (std::any_of(kw.w.begin(), kw.w.end(), [](double v) { return v < 0.0; })) {
                        // Its mean of exp(k x) could fall to 0 or below (log: NaN): refused.
                        EXPECT_FALSE(blur(got, src, n.k, o));
                        EXPECT_NE(got.geterror().find("without negative weights"), std::string::npos)
                            << got.geterror();
                        continue;
                    }
                    ASSERT_TRUE(blur(got, src, n.k, o)) << got.geterror();
                    OIIO::ImageBuf e = src, mean_e, plain, inside;
                    for (OIIO::ImageBuf::Iterator<float> it(e); !it.done(); ++it)
                        for (int c = 0; c < 4; ++c)
                            if (c != alpha)
                                it[c] = std::exp(k * it[c]);
                    BlurOptions ref_o = o;
                    ref_o.iris        = 0.0f;
                    const KernelWeights w = kernel_weights(n.k);
                    ASSERT_TRUE(convolve_reference(mean_e, e, w, ref_o));
                    ASSERT_TRUE(convolve_reference(plain, src, w, ref_o));
                    ASSERT_TRUE(convolve_reference(inside, ones, w, ref_o));
                    double err = 0.0;
                    for (OIIO::ImageBuf::ConstIterator<float> it(got); !it.done(); ++it)
                        for (int c = 0; c < 4; ++c) {
                            const double outside = 1.0 - double(inside.getchannel(it.x(), it.y(), 0, c));
                            const double want
                                = c == alpha ? plain.getchannel(it.x(), it.y(), 0, c)
                                             : std::log(double(mean_e.getchannel(it.x(), it.y(), 0, c)) + outside) / k;
                            err = std::max(err, std::abs(double(it[c]) - want) / std::max(1.0, std::abs(want)));
                        }
                    // Tolerance: float exp-space sums, relative (log turns their relative
                    // rounding into an absolute error of about 1e-7 / |k|).
                    EXPECT_LE(err, 2e-4);
                    worst = std::max(worst, err);
                }
    RecordProperty("worst_relative_error", std::to_string(worst));  // 6.9e-5 measured
}

TEST(BlurIris, ASmallExponentTendsToThePlainBlur)
{
    // As k -> 0, log(mean(exp(k x))) / k -> mean(x) + k var / 2: within |k| range^2 / 8 of
    // the plain blur. Stored as a float exp(k d), d was kept only to 6e-8 / k (iris 1e-6
    // on this 0..1 image erred by 0.075, and from 1e-7 every colour was the channel's
    // minimum); stored as exp(k d) - 1 it keeps d's own digits. Every method that takes
    // iris mode, both signs.
    OIIO::ImageBuf src(OIIO::ImageSpec(48, 36, 4, OIIO::TypeFloat));
    for (int y = 0; y < 36; ++y)
        for (int x = 0; x < 48; ++x) {
            const float v     = float((x * 37 + y * 91) % 101) / 100.0f;
            const float px[4] = { v, 1.0f - v, (x + y) % 2 ? 1.0f : 0.0f, 1.0f };
            src.setpixel(x, y, px);
        }
    src.specmod().alpha_channel = 3;
    struct Case {
        KernelShape shape;
        BlurMethod method;
    };
    for (const Case& c : { Case{ KernelShape::Disk, BlurMethod::Spans }, Case{ KernelShape::Disk, BlurMethod::Fft },
                           Case{ KernelShape::Disk, BlurMethod::Bands },
                           Case{ KernelShape::Polygon, BlurMethod::Parallelograms },
                           Case{ KernelShape::Gaussian, BlurMethod::ThreeBoxes },
                           Case{ KernelShape::Box, BlurMethod::Exact } })
        for (float k : { 1e-4f, 1e-6f, 1e-9f, -1e-7f, 1e-30f, -1e-4f, -1e-6f, -1e-9f, 1e-7f, -1e-5f, 1e-5f }) {
            SCOPED_TRACE(testing::Message() << method_name(c.method) << " k " << k);
            Kernel kern;
            kern.shape    = c.shape;
            kern.blades   = 6;
            kern.width_px = kern.height_px = 9;
            BlurOptions plain;
            plain.method = c.method;
            plain.border = Border::Clamp;
            BlurOptions iris = plain;
            iris.iris        = k;
            OIIO::ImageBuf a, b;
            ASSERT_TRUE(blur(a, src, kern, plain)) << a.geterror();
            ASSERT_TRUE(blur(b, src, kern, iris)) << b.geterror();
            // The k var / 2 term, and float rounding of the plain blur's and the log's.
            EXPECT_LE(bokeh_test::max_difference(a, b), std::abs(k) / 8.0 + 1e-6);
        }
}

TEST(BlurIris, AnImageKernelMatchesExpMeanLogAndShiftsWithTheImage)
{
    // convolve_image in iris mode against its definition: exp(k x) per colour channel, the
    // plain convolution with the same kernel image (convolve_image, itself checked against
    // the brute force in blur_image_kernel_test.cpp), log / k; alpha plainly. A colour kernel, not symmetric, both
    // signs of k up to |k| x range = 5. Then translation: the image moved by whole pixels
    // (its data window) gives the same pixels, moved.
    const OIIO::ImageBuf src = test_image(37, 29), moved = test_image(37, 29, 9, -5);  // 0 .. 500
    OIIO::ImageBuf kernel(OIIO::ImageSpec(5, 7, 3, OIIO::TypeFloat));
    for (int y = 0; y < 7; ++y)
        for (int x = 0; x < 5; ++x) {
            const float w[3] = { float(1 + (x * 3 + y) % 4), x + y < 6 ? 1.0f : 0.0f, float(1 + x * y) };
            kernel.setpixel(x, y, w);
        }
    const int alpha = src.spec().alpha_channel;
    for (float k : { 0.01f, -0.01f, 0.002f }) {
        SCOPED_TRACE(k);
        BlurOptions o;
        o.border = Border::Clamp;  // no outside term: exp of clamped values
        o.iris   = k;
        OIIO::ImageBuf got, shifted;
        ASSERT_TRUE(convolve_image(got, src, kernel, o)) << got.geterror();
        OIIO::ImageBuf e = src;
        for (OIIO::ImageBuf::Iterator<float> it(e); !it.done(); ++it)
            for (int c = 0; c < 4; ++c)
                if (c != alpha)
                    it[c] = std::exp(k * it[c]);
        BlurOptions plain = o;
        plain.iris        = 0.0f;
        OIIO::ImageBuf mean_e, linear;
        ASSERT_TRUE(convolve_image(mean_e, e, kernel, plain));
        ASSERT_TRUE(convolve_image(linear, src, kernel, plain));
        double err = 0.0;
        for (OIIO::ImageBuf::ConstIterator<float> it(got); !it.done(); ++it)
            for (int c = 0; c < 4; ++c) {
                const double want = c == alpha ? linear.getchannel(it.x(), it.y(), 0, c)
                                               : std::log(double(mean_e.getchannel(it.x(), it.y(), 0, c))) / k;
                err = std::max(err, std::abs(double(it[c]) - want) / std::max(1.0, std::abs(want)));
            }
        EXPECT_LE(err, 2e-4) << "relative (log turns exp-space rounding into ~1e-7 / |k|)";
        ASSERT_TRUE(convolve_image(shifted, moved, kernel, o)) << shifted.geterror();
        ASSERT_EQ(shifted.roi().xbegin - got.roi().xbegin, 9);
        ASSERT_EQ(shifted.roi().ybegin - got.roi().ybegin, -5);
        double moved_err = 0.0;
        for (OIIO::ImageBuf::ConstIterator<float> it(got); !it.done(); ++it)
            for (int c = 0; c < 4; ++c)
                moved_err = std::max(moved_err, double(std::abs(it[c] - shifted.getchannel(it.x() + 9, it.y() - 5, 0, c))));
        EXPECT_LE(moved_err, 1e-6 * peak(got)) << "the FFT's tiles follow the data window";
    }
}

TEST(BlurIris, ExactMethodsShiftWithTheImage)
{
    // Translation equivariance in iris mode: every exact method, the image's data window
    // moved by whole pixels.
    const OIIO::ImageBuf a = test_image(43, 31), b = test_image(43, 31, -7, 12);
    for (const Named& n : kernels()) {
        const std::vector<double> w = kernel_weights(n.k).w;
        if (std::any_of(w.begin(), w.end(), [](double v) { return v < 0.0; }))
            continue;  // negative lobes: refused in iris mode (tested above)
        for (BlurMethod m : exact_methods(n.k)) {
            SCOPED_TRACE(n.name + method_name(m));
            BlurOptions o;
            o.method = m;
            o.iris   = 0.01f;
            OIIO::ImageBuf ra, rb;
            ASSERT_TRUE(blur(ra, a, n.k, o)) << ra.geterror();
            ASSERT_TRUE(blur(rb, b, n.k, o)) << rb.geterror();
            ASSERT_EQ(rb.roi().xbegin - ra.roi().xbegin, -7);
            double worst = 0.0;
            for (OIIO::ImageBuf::ConstIterator<float> it(ra); !it.done(); ++it)
                for (int c = 0; c < 4; ++c)
                    worst = std::max(worst, double(std::abs(it[c] - rb.getchannel(it.x() - 7, it.y() + 12, 0, c))));
            EXPECT_LE(worst, 1e-6 * peak(ra));
        }
    }
}

TEST(BlurIris, NonFiniteValuesDoNotWidenTheRange)
{
    // Iris mode checks |k| times each channel's range against its limit. The blur runs with
    // the non-finite values replaced, by the channel's least finite value in iris mode (by 0
    // the range here would be 0 .. 1019, far past the limit, and the blur refused).
    OIIO::ImageBuf src(OIIO::ImageSpec(40, 30, 4, OIIO::TypeFloat));
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 40; ++x) {
            const float px[4] = { 1000.0f + float((x + y) % 20), 1000.0f, 1005.0f, 1.0f };
            src.setpixel(x, y, px);
        }
    const float bad[4] = { std::numeric_limits<float>::quiet_NaN(), 1000.0f, 1005.0f, 1.0f };
    src.setpixel(10, 10, bad);
    Kernel disk;
    disk.shape    = KernelShape::Disk;
    disk.width_px = disk.height_px = 9;
    BlurOptions o;
    o.border = Border::Clamp;
    o.iris   = 1.0f;
    OIIO::ImageBuf got;
    ASSERT_TRUE(blur(got, src, disk, o)) << got.geterror();
    for (OIIO::ImageBuf::ConstIterator<float> it(got); !it.done(); ++it) {
        const int d2 = (it.x() - 10) * (it.x() - 10) + (it.y() - 10) * (it.y() - 10);
        if (d2 <= 9) {
            EXPECT_TRUE(std::isnan(it[0])) << it.x() << ", " << it.y();
        }
        if (d2 > 25) {
            EXPECT_GE(it[0], 1000.0f) << it.x() << ", " << it.y();
            EXPECT_LE(it[0], 1019.0f) << it.x() << ", " << it.y();
        }
        EXPECT_TRUE(std::isfinite(it[1]) && std::isfinite(it[2]));
    }
}

TEST(BlurIris, DepthStaysLinear)
{
    // Z is blurred plainly in iris mode, as alpha is: its range (here 2 .. 70, 68 times
    // iris 1) does not count against the limit, and its values are the plain blur's.
    OIIO::ImageSpec spec(60, 40, 5, OIIO::TypeFloat);
    spec.channelnames = { "R", "G", "B", "A", "Z" };
    spec.alpha_channel = 3;
    spec.z_channel     = 4;
    OIIO::ImageBuf src(spec);
    for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 60; ++x) {
            const float px[5] = { (x * 7 + y) % 13 == 0 ? 9.0f : 0.2f, 0.3f, 0.1f, 1.0f, 2.0f + float(x + y) * 0.7f };
            src.setpixel(x, y, px);
        }
    Kernel k;
    k.width_px = k.height_px = 11;
    BlurOptions plain, iris;
    iris.iris = 1.0f;
    OIIO::ImageBuf a, b;
    ASSERT_TRUE(blur(a, src, k, plain));
    ASSERT_TRUE(blur(b, src, k, iris)) << b.geterror();
    double z_diff = 0.0, r_diff = 0.0;
    for (int y = 0; y < 40; ++y)
        for (int x = 0; x < 60; ++x) {
            z_diff = std::max(z_diff, double(std::abs(a.getchannel(x, y, 0, 4) - b.getchannel(x, y, 0, 4))));
            r_diff = std::max(r_diff, double(std::abs(a.getchannel(x, y, 0, 0) - b.getchannel(x, y, 0, 0))));
        }
    EXPECT_LE(z_diff, 1e-4) << "depth is averaged plainly";
    EXPECT_GT(r_diff, 0.5) << "colour takes the iris";
}
