// Image kernels (convolve_image) by FFT tiles: against the brute force, their properties,
// colour kernels and the centre rule, and the kernels refused. (Their non-finite values:
// blur_nonfinite_test.cpp.)
#include <bokeh/blur.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>

#include "blur_fixtures.h"
#include "test_util.h"

using namespace bokeh;
using namespace blur_test;

namespace {

OIIO::ImageBuf kernel_image(const KernelWeights& kw, int nchannels = 1)
{
    OIIO::ImageSpec spec(2 * kw.rx + 1, 2 * kw.ry + 1, nchannels, OIIO::TypeFloat);
    spec.x = -kw.rx;  // centred on (0, 0) as OIIO's make_kernel does
    spec.y = -kw.ry;
    OIIO::ImageBuf img(spec);
    for (int dy = -kw.ry; dy <= kw.ry; ++dy)
        for (int dx = -kw.rx; dx <= kw.rx; ++dx)
            for (int c = 0; c < nchannels; ++c) {
                const float v = float(kw.at(dx, dy) * (c + 1));
                img.setpixel(dx, dy, 0, &v, 1);
            }
    return img;
}

}  // namespace

TEST(BlurImageKernel, FftEqualsBruteForce)
{
    const OIIO::ImageBuf src = test_image(70, 55, 3, -4);
    for (const Named& n : kernels()) {
        SCOPED_TRACE(n.name);
        const KernelWeights kw = kernel_weights(n.k);
        for (Border border : { Border::Black, Border::Clamp, Border::Mirror }) {
            BlurOptions o;
            o.border = border;
            OIIO::ImageBuf got, ref;
            ASSERT_TRUE(convolve_image(got, src, kernel_image(kw), o)) << got.geterror();
            ASSERT_TRUE(convolve_reference(ref, src, kw, o));
            ASSERT_EQ(got.roi(), ref.roi());
            // Double FFT: round-off ~1e-15 of the sum; float output.
            EXPECT_LE(bokeh_test::max_difference(got, ref), 2e-6 * peak(ref));
        }
    }
}

TEST(BlurImageKernel, EnergyTranslationMirrorAndALonePixel)
{
    // The properties of every kernel, for an image kernel that is not symmetric (a ramp
    // over a 9 x 5 box, heavier to the right and down), by FFT tiles: energy (grown, black
    // border) to 1e-6, the same pixels at another origin bit for bit, a mirrored image and
    // kernel giving the mirrored result, a lone 1e6 pixel giving the normalised kernel.
    KernelWeights ramp{ 4, 2, {} };
    double total = 0.0;
    for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -4; dx <= 4; ++dx) {
            ramp.w.push_back(1.0 + 0.5 * (dx + 4) + 0.25 * (dy + 2));
            total += ramp.w.back();
        }
    for (double& v : ramp.w)
        v /= total;
    const OIIO::ImageBuf kernel = kernel_image(ramp);
    BlurOptions grow;
    grow.grow                = true;
    const OIIO::ImageBuf src = test_image(45, 31), moved = test_image(45, 31, 13, -7);
    OIIO::ImageBuf a, b;
    ASSERT_TRUE(convolve_image(a, src, kernel, grow)) << a.geterror();
    const std::vector<double> before = channel_sums(src), after = channel_sums(a);
    for (size_t c = 0; c < after.size(); ++c)
        EXPECT_NEAR(after[c], before[c], 1e-6 * before[c]) << "energy, channel " << c;
    ASSERT_TRUE(convolve_image(b, moved, kernel, grow));
    ASSERT_EQ(b.roi().xbegin - a.roi().xbegin, 13);
    ASSERT_EQ(b.roi().ybegin - a.roi().ybegin, -7);
    EXPECT_EQ(std::memcmp(a.localpixels(), b.localpixels(), size_t(a.roi().npixels()) * 4 * sizeof(float)), 0);
    for (Border border : { Border::Black, Border::Clamp, Border::Mirror }) {
        SCOPED_TRACE(int(border));
        BlurOptions o;
        o.border = border;
        OIIO::ImageBuf direct, back;
        ASSERT_TRUE(convolve_image(direct, src, kernel, o));
        OIIO::ImageBuf flopped_kernel = OIIO::ImageBufAlgo::flop(kernel);
        flopped_kernel.set_origin(-4, -2);
        ASSERT_TRUE(convolve_image(back, OIIO::ImageBufAlgo::flop(src), flopped_kernel, o));
        EXPECT_LE(bokeh_test::max_difference(OIIO::ImageBufAlgo::flop(back), direct), 2e-6 * peak(direct));
    }
    OIIO::ImageBuf lone(OIIO::ImageSpec(21, 15, 1, OIIO::TypeFloat));
    const float bright = 1e6f;
    lone.setpixel(10, 7, &bright);
    OIIO::ImageBuf out;
    ASSERT_TRUE(convolve_image(out, lone, kernel));
    double worst = 0.0;
    for (int y = 0; y < 15; ++y)
        for (int x = 0; x < 21; ++x) {
            float v;
            out.getpixel(x, y, &v);
            const int dx = x - 10, dy = y - 7;
            const double want = std::abs(dx) <= 4 && std::abs(dy) <= 2 ? ramp.at(dx, dy) : 0.0;
            worst = std::max(worst, std::abs(v / 1e6 - want));
        }
    EXPECT_LE(worst, 1e-7);
}

TEST(BlurImageKernel, KernelsLargerThanTheImageMatchTheSpans)
{
    // A 601 px disk as an image on a 300 x 200 image: every output reads past the data
    // window (mirror border), and a tile is larger than the image.
    Kernel k;
    k.shape    = KernelShape::Disk;
    k.width_px = k.height_px = 601;
    const KernelWeights kw   = kernel_weights(k);
    const OIIO::ImageBuf src = test_image(300, 200, -5, 9);
    BlurOptions o;
    o.border = Border::Mirror;
    OIIO::ImageBuf got, spans;
    ASSERT_TRUE(convolve_image(got, src, kernel_image(kw), o)) << got.geterror();
    o.method = BlurMethod::Spans;
    ASSERT_TRUE(blur(spans, src, k, o));
    ASSERT_EQ(got.roi(), spans.roi());
    // The kernel image is float: its weights differ from the double ones by ~1e-7 relative.
    EXPECT_LE(bokeh_test::max_difference(got, spans), 2e-6 * peak(spans));
}

TEST(BlurImageKernel, ColourKernelsAndTheCentreRule)
{
    // A 3-channel kernel: each channel its own (normalised) shape; alpha uses their mean.
    Kernel disk;
    disk.shape    = KernelShape::Disk;
    disk.width_px = disk.height_px = 7;
    Kernel box;
    box.shape    = KernelShape::Box;
    box.width_px = box.height_px = 7;
    const KernelWeights kd = kernel_weights(disk), kb = kernel_weights(box);
    OIIO::ImageBuf k(OIIO::ImageSpec(7, 7, 3, OIIO::TypeFloat));  // origin (0, 0): centre (3, 3)
    for (int y = 0; y < 7; ++y)
        for (int x = 0; x < 7; ++x) {
            const float px[3] = { float(kd.at(x - 3, y - 3)), float(kb.at(x - 3, y - 3)),
                                  float(3.0 * kd.at(x - 3, y - 3)) };
            k.setpixel(x, y, px);
        }
    const OIIO::ImageBuf src = test_image(30, 30);
    OIIO::ImageBuf got, rd, rb;
    ASSERT_TRUE(convolve_image(got, src, k)) << got.geterror();
    ASSERT_TRUE(blur(rd, src, disk));
    ASSERT_TRUE(blur(rb, src, box));
    const OIIO::ImageBuf r = OIIO::ImageBufAlgo::channels(got, 1, { 0 });
    const OIIO::ImageBuf g = OIIO::ImageBufAlgo::channels(got, 1, { 1 });
    const OIIO::ImageBuf b = OIIO::ImageBufAlgo::channels(got, 1, { 2 });
    EXPECT_LE(bokeh_test::max_difference(r, OIIO::ImageBufAlgo::channels(rd, 1, { 0 })), 2e-6 * peak(rd));
    EXPECT_LE(bokeh_test::max_difference(g, OIIO::ImageBufAlgo::channels(rb, 1, { 1 })), 2e-6 * peak(rb));
    EXPECT_LE(bokeh_test::max_difference(b, OIIO::ImageBufAlgo::channels(rd, 1, { 2 })), 2e-6 * peak(rd))
        << "a channel's scale does not matter: each is normalised";
    // A one-pixel kernel anywhere is the identity (to round-off).
    OIIO::ImageBuf one(OIIO::ImageSpec(1, 1, 1, OIIO::TypeFloat));
    const float v = 5.0f;
    one.setpixel(0, 0, &v);
    ASSERT_TRUE(convolve_image(got, src, one));
    EXPECT_LE(bokeh_test::max_difference(got, src), 1e-5 * peak(src));
}

TEST(BlurImageKernel, BadKernelsAreRefused)
{
    const OIIO::ImageBuf src = test_image(10, 10);
    OIIO::ImageBuf k(OIIO::ImageSpec(3, 3, 1, OIIO::TypeFloat)), out;
    EXPECT_FALSE(convolve_image(out, src, k));
    EXPECT_NE(out.geterror().find("sums to 0"), std::string::npos) << out.geterror();
    const float nan = NAN;
    k.setpixel(1, 1, &nan);
    EXPECT_FALSE(convolve_image(out, src, k));
    EXPECT_NE(out.geterror().find("non-finite value at (1, 1)"), std::string::npos) << out.geterror();
    EXPECT_FALSE(convolve_image(out, src, OIIO::ImageBuf()));
    EXPECT_NE(out.geterror().find("kernel image"), std::string::npos) << out.geterror();
    // Weights that cancel (the kernel-image fuzz target's 7x1 finding; summed in double the
    // 1s before -3e38 are lost, so the sum reads 0.5): infinities from a
    // finite source before; refused, as in check_kernel_image. A sharpening kernel passes.
    OIIO::ImageBuf cancel(OIIO::ImageSpec(7, 1, 1, OIIO::TypeFloat));
    const float weights[7] = { 1, 1, 1, -3e38f, 1, 3e38f, 0.5f };
    ASSERT_TRUE(cancel.set_pixels(OIIO::ROI::All(), OIIO::TypeFloat, weights));
    EXPECT_FALSE(convolve_image(out, src, cancel));
    const std::string refused = out.geterror();
    EXPECT_NE(refused.find("kernel image channel 0: its weights cancel (absolute sum 6e+38, sum 0.5)"),
              std::string::npos) << refused;
    std::string why;
    EXPECT_FALSE(check_kernel_image(cancel, src.nchannels(), {}, why));
    EXPECT_NE(why.find("its weights cancel"), std::string::npos) << why;
    const float sharpen_weights[7] = { 0, -1, -1, 5, -1, -1, 0 };
    ASSERT_TRUE(cancel.set_pixels(OIIO::ROI::All(), OIIO::TypeFloat, sharpen_weights));
    EXPECT_TRUE(convolve_image(out, src, cancel)) << out.geterror();
    // More kernel channels than the image's: the extra ones would be dropped unseen.
    OIIO::ImageBuf wide(OIIO::ImageSpec(3, 3, src.nchannels() + 1, OIIO::TypeFloat));
    OIIO::ImageBufAlgo::fill(wide, std::vector<float>(size_t(src.nchannels() + 1), 1.0f));
    EXPECT_FALSE(convolve_image(out, src, wide));
    EXPECT_NE(out.geterror().find("channels, the image"), std::string::npos) << out.geterror();
    // ... unless the one too many is the kernel's alpha (an RGBA aperture picture on RGB):
    // dropped, the same as the kernel without it.
    const OIIO::ImageBuf rgb = OIIO::ImageBufAlgo::channels(src, 3, { 0, 1, 2 });
    OIIO::ImageBuf aperture(OIIO::ImageSpec(3, 5, 4, OIIO::TypeFloat));
    for (int y = 0; y < 5; ++y)
        for (int x = 0; x < 3; ++x) {
            const float px[4] = { float(1 + x), float(1 + y), 1.0f, 0.5f };
            aperture.setpixel(x, y, px);
        }
    aperture.specmod().alpha_channel = 3;
    OIIO::ImageBuf with_alpha, without;
    ASSERT_TRUE(convolve_image(with_alpha, rgb, aperture)) << with_alpha.geterror();
    ASSERT_TRUE(convolve_image(without, rgb, OIIO::ImageBufAlgo::channels(aperture, 3, { 0, 1, 2 })));
    EXPECT_EQ(bokeh_test::max_difference(with_alpha, without), 0.0);
}
