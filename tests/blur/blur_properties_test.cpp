// Properties every uniform blur keeps, by every method: energy, the identity at size 0,
// mirror symmetry, translation, no drift after a bright pixel, a constant image under the
// clamp and mirror borders, and the same bits on any thread count.
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

TEST(Blur, EnergyIsConservedWhenTheWindowGrows)
{
    // Every method, the approximations too (the weights each spreads sum to 1).
    const OIIO::ImageBuf src = test_image(40, 33);
    const std::vector<double> before = channel_sums(src);
    for (const Named& n : kernels())
    for (BlurMethod m : every_method(n.k)) {
        SCOPED_TRACE(n.name + method_name(m));
        BlurOptions o;
        o.grow   = true;
        o.method = m;
        OIIO::ImageBuf out;
        ASSERT_TRUE(blur(out, src, n.k, o));
        EXPECT_GT(out.roi().width(), src.roi().width());
        const std::vector<double> after = channel_sums(out);
        for (size_t c = 0; c < after.size(); ++c)
            EXPECT_NEAR(after[c], before[c], 1e-6 * before[c]) << "channel " << c;
    }
}

TEST(Blur, ZeroSizeIsTheIdentityBitForBit)
{
    // Every method, border, grown or not, with and without iris, hard or anti-aliased edge.
    const OIIO::ImageBuf src = test_image(23, 17, 5, -3);
    for (KernelShape s : { KernelShape::Box, KernelShape::Gaussian, KernelShape::Disk, KernelShape::Polygon,
                           KernelShape::Filter })
        for (float size : { 0.0f, 0.5f })
            for (KernelEdge edge : { KernelEdge::Antialiased, KernelEdge::Hard }) {
                if (s == KernelShape::Gaussian && size > 0.0f)
                    continue;  // sigma = 0.125 is small, not zero
                Kernel k;
                k.shape     = s;
                k.filter    = "lanczos3";  // OIIO's, one pixel wide at 0.5 px (make_kernel's window is 1)
                k.width_px  = size;
                k.height_px = size;
                k.edge      = edge;
                std::vector<BlurMethod> methods = every_method(k);
                if (s != KernelShape::Filter)  // refused for OIIO's filters
                    methods.push_back(BlurMethod::Reduced);
                methods.push_back(BlurMethod::Reference);
                for (BlurMethod m : methods)
                    for (Border border : { Border::Black, Border::Clamp, Border::Mirror })
                        for (bool grow : { false, true })
                            for (float iris : { 0.0f, 0.05f }) {
                                if (m == BlurMethod::Reduced && iris != 0.0f)
                                    continue;  // refused
                                SCOPED_TRACE(testing::Message() << int(s) << " size " << size << " edge "
                                                                << int(edge) << method_name(m) << " " << int(m)
                                                                << " border " << int(border) << " grow " << grow
                                                                << " iris " << iris);
                                BlurOptions o;
                                o.method = m;
                                o.border = border;
                                o.grow   = grow;
                                o.iris   = iris;
                                OIIO::ImageBuf out;
                                ASSERT_TRUE(blur(out, src, k, o)) << out.geterror();
                                ASSERT_EQ(out.roi(), src.roi());
                                EXPECT_EQ(std::memcmp(out.localpixels(), src.localpixels(), 23 * 17 * 4 * sizeof(float)), 0);
                            }
            }
}

TEST(Blur, AZeroSideIsTheIdentityForShapesAndOneAxisForSeparableKernels)
{
    // A disk or polygon with a zero side has no area: the identity, as 0 x 0. A box or a
    // Gaussian (and OIIO's separable filters) takes its axes apart: 0 x 7 blurs along y
    // alone, as a 1 px wide box does (a whole pixel: the identity along x).
    const OIIO::ImageBuf src = test_image(23, 17);
    for (KernelShape s : { KernelShape::Disk, KernelShape::Polygon })
        for (auto [w, h] : { std::pair{ 0.0f, 7.0f }, std::pair{ 7.0f, 0.0f } }) {
            Kernel k;
            k.shape     = s;
            k.width_px  = w;
            k.height_px = h;
            OIIO::ImageBuf out;
            ASSERT_TRUE(blur(out, src, k)) << out.geterror();
            EXPECT_EQ(std::memcmp(out.localpixels(), src.localpixels(), 23 * 17 * 4 * sizeof(float)), 0)
                << int(s) << " " << w << "x" << h;
        }
    Kernel line, narrow;
    line.shape     = narrow.shape = KernelShape::Box;
    line.width_px  = 0.0f;
    narrow.width_px = 1.0f;
    line.height_px = narrow.height_px = 7.0f;
    OIIO::ImageBuf a, b;
    ASSERT_TRUE(blur(a, src, line));
    ASSERT_TRUE(blur(b, src, narrow));
    EXPECT_EQ(bokeh_test::max_difference(a, b), 0.0);
    EXPECT_GT(bokeh_test::max_difference(a, src), 0.1) << "it blurs along y";
}

TEST(Blur, PolygonsMirrorAboutTheirVertexAxis)
{
    // With a vertex up (rotation 0) a polygon of any blade count, curved blades, a hole or
    // an anamorphic squeeze is mirror symmetric in x, and so is its blur: a mirrored
    // image's blur mirrored back is the blur (every exact method, and the bands).
    const OIIO::ImageBuf src = test_image(41, 33);
    std::vector<Named> cases;
    auto add = [&](const char* name, int blades, float w, float h, float curvature, float hole) {
        Kernel k;
        k.shape     = KernelShape::Polygon;
        k.blades    = blades;
        k.width_px  = w;
        k.height_px = h;
        k.curvature = curvature;
        k.hole      = hole;
        cases.push_back({ name, k });
    };
    add("triangle 15", 3, 15, 15, 0.0f, 0.0f);
    add("pentagon 19 curved 0.4", 5, 19, 19, 0.4f, 0.0f);
    add("pentagon 21 with a hole", 5, 21, 21, 0.0f, 0.3f);
    add("heptagon 17x23 curved 0.7", 7, 17, 23, 0.7f, 0.0f);
    add("nonagon 13.5 curved, holed", 9, 13.5f, 13.5f, 0.5f, 0.25f);
    for (const Named& n : cases) {
        SCOPED_TRACE(n.name);
        const KernelWeights kw = kernel_weights(n.k);
        for (int dy = -kw.ry; dy <= kw.ry; ++dy)
            for (int dx = -kw.rx; dx <= kw.rx; ++dx)
                ASSERT_NEAR(kw.at(dx, dy), kw.at(-dx, dy), 1e-12);
        std::vector<BlurMethod> methods = exact_methods(n.k);
        if (n.k.hole == 0.0f)
            methods.push_back(BlurMethod::Bands);
        for (BlurMethod m : methods)
            for (Border border : { Border::Black, Border::Mirror }) {
                SCOPED_TRACE(testing::Message() << method_name(m) << " border " << int(border));
                BlurOptions o;
                o.method = m;
                o.border = border;
                OIIO::ImageBuf direct, back;
                ASSERT_TRUE(blur(direct, src, n.k, o)) << direct.geterror();
                ASSERT_TRUE(blur(back, OIIO::ImageBufAlgo::flop(src), n.k, o)) << back.geterror();
                EXPECT_LE(bokeh_test::max_difference(OIIO::ImageBufAlgo::flop(back), direct), 2e-6 * peak(direct));
            }
    }
}

TEST(Blur, SymmetricKernelsGiveSymmetricResults)
{
    // The weights, and the results: a mirrored image's blur mirrored back is the blur
    // (every exact method, and the bands and three boxes, whose kernels keep the symmetry).
    const OIIO::ImageBuf src = test_image(41, 33);
    auto mirrored = [](const OIIO::ImageBuf& img, bool in_x) {
        return in_x ? OIIO::ImageBufAlgo::flop(img) : OIIO::ImageBufAlgo::flip(img);
    };
    for (const Named& n : kernels()) {
        if (n.k.shape == KernelShape::Polygon && (n.k.blades % 2 == 1 || n.k.rotation_deg != 0.0f))
            continue;  // a pentagon is symmetric about its vertex axis only: checked below
        SCOPED_TRACE(n.name);
        std::vector<BlurMethod> methods = exact_methods(n.k);
        if ((n.k.shape == KernelShape::Disk || n.k.shape == KernelShape::Polygon) && n.k.hole == 0.0f)
            methods.push_back(BlurMethod::Bands);
        if (n.k.shape == KernelShape::Gaussian && n.k.edge == KernelEdge::Antialiased)
            methods.push_back(BlurMethod::ThreeBoxes);
        const std::vector<BlurMethod> approx = approximations(n.k);
        if (std::find(approx.begin(), approx.end(), BlurMethod::BilinearTaps) != approx.end())
            methods.push_back(BlurMethod::BilinearTaps);
        for (BlurMethod m : methods)
            for (bool in_x : { true, false })
                for (Border border : { Border::Black, Border::Mirror }) {
                    SCOPED_TRACE(testing::Message() << "method " << int(m) << (in_x ? " in x" : " in y")
                                                    << " border " << int(border));
                    BlurOptions o;
                    o.method = m;
                    o.border = border;
                    OIIO::ImageBuf direct, back;
                    ASSERT_TRUE(blur(direct, src, n.k, o)) << direct.geterror();
                    ASSERT_TRUE(blur(back, mirrored(src, in_x), n.k, o)) << back.geterror();
                    // Float rounding of sums taken in the other order, relative to the peak.
                    EXPECT_LE(bokeh_test::max_difference(mirrored(back, in_x), direct), 2e-6 * peak(direct));
                }
        const KernelWeights kw = kernel_weights(n.k);
        const bool y_symmetric = !(n.k.shape == KernelShape::Polygon && n.k.blades % 4 != 0
                                   && n.k.blades % 2 == 1);
        for (int dy = -kw.ry; dy <= kw.ry; ++dy)
            for (int dx = -kw.rx; dx <= kw.rx; ++dx) {
                ASSERT_NEAR(kw.at(dx, dy), kw.at(-dx, dy), 1e-12);
                if (y_symmetric) {
                    ASSERT_NEAR(kw.at(dx, dy), kw.at(dx, -dy), 1e-12);
                }
            }
    }
    Kernel pent;
    pent.shape  = KernelShape::Polygon;
    pent.blades = 5;
    pent.width_px = pent.height_px = 25;
    const KernelWeights kw = kernel_weights(pent);
    for (int dy = -kw.ry; dy <= kw.ry; ++dy)
        for (int dx = -kw.rx; dx <= kw.rx; ++dx)
            ASSERT_NEAR(kw.at(dx, dy), kw.at(-dx, dy), 1e-12) << "vertex up: mirror symmetric in x";
    // A vertex up reaches the circumcircle at the top; the opposite flat edge stops at
    // cos(36 deg) = 0.81 of the radius at the bottom.
    double top = 0.0, bottom = 0.0;
    for (int dx = -kw.rx; dx <= kw.rx; ++dx) {
        top += kw.at(dx, -kw.ry);
        bottom += kw.at(dx, kw.ry);
    }
    EXPECT_GT(top, 0.0);
    EXPECT_EQ(bottom, 0.0);
}

TEST(Blur, TranslationEquivariance)
{
    // The same pixels at another data-window origin give the same result there, bit for bit,
    // by every method (the approximations' chunks are fixed by the frame, not its origin).
    const OIIO::ImageBuf a = test_image(45, 31, 0, 0), b = test_image(45, 31, 13, -7);
    for (const Named& n : kernels())
    for (BlurMethod m : every_method(n.k)) {
        SCOPED_TRACE(n.name + method_name(m));
        BlurOptions o;
        o.grow   = true;
        o.method = m;
        OIIO::ImageBuf ra, rb;
        ASSERT_TRUE(blur(ra, a, n.k, o));
        ASSERT_TRUE(blur(rb, b, n.k, o));
        EXPECT_EQ(rb.roi().xbegin - ra.roi().xbegin, 13);
        EXPECT_EQ(rb.roi().ybegin - ra.roi().ybegin, -7);
        const size_t bytes = size_t(ra.roi().npixels()) * 4 * sizeof(float);
        EXPECT_EQ(std::memcmp(ra.localpixels(), rb.localpixels(), bytes), 0);
    }
}

TEST(Blur, NoDriftAlongA4KRowAfterA1e6Pixel)
{
    // One, three and four channels (each its own running-sum loop), every channel bright.
    for (int nc : { 1, 3, 4 }) {
    OIIO::ImageBuf src(OIIO::ImageSpec(3840, 3, nc, OIIO::TypeFloat));
    std::vector<float> px(static_cast<size_t>(nc));
    for (int y = 0; y < 3; ++y)
        for (int x = 0; x < 3840; ++x) {
            for (int c = 0; c < nc; ++c)
                px[size_t(c)] = x == 20 && y == 1 ? 1e6f : 0.25f + 0.25f * float((x * 37 + c * 5) % 11) / 11.0f;
            src.setpixel(x, y, px.data());
        }
    // The approximations against themselves on the row without the bright pixel.
    OIIO::ImageBuf dim = src;
    const std::vector<float> level(size_t(nc), 0.25f);
    dim.setpixel(20, 1, level.data());
    for (const Named& n : kernels())
    for (BlurMethod m : every_method(n.k)) {
        SCOPED_TRACE(n.name + method_name(m) + " channels " + std::to_string(nc));
        BlurOptions o;
        o.method = m;
        OIIO::ImageBuf out, ref;
        ASSERT_TRUE(blur(out, src, n.k, o));
        const bool exact = m == BlurMethod::Auto || m == BlurMethod::Spans || m == BlurMethod::Fft;
        if (exact)
            ASSERT_TRUE(convolve_reference(ref, src, kernel_weights(n.k)));
        else
            ASSERT_TRUE(blur(ref, dim, n.k, o)) << ref.geterror();
        // Far from the bright pixel the values are ~0.3: any drift would show.
        OIIO::ROI far = src.roi();
        far.xbegin    = 200;
        EXPECT_LE(bokeh_test::max_difference(OIIO::ImageBufAlgo::cut(out, far),
                                             OIIO::ImageBufAlgo::cut(ref, far)),
                  1e-6);
    }
    }
}

TEST(Blur, EveryMethodKeepsAConstantImageUnderClampAndMirror)
{
    // Under the clamp and mirror borders a constant image stays constant on every pixel,
    // the frame's edges too: a method whose reach (the padding it is given) fell short of
    // what it reads would take black there. The parallelograms read up to 5 px past the
    // hexagon (each of a rhombus' two steep segments spreads by its shear's and unshear's
    // taps) and were given 2: their edge pixels lost up to 7.7e-6 of the value at 9 px.
    OIIO::ImageBuf flat(OIIO::ImageSpec(30, 20, 4, OIIO::TypeFloat));
    const float value[4] = { 0.75f, 10.0f, 3.0f, 1.0f };
    OIIO::ImageBufAlgo::fill(flat, value);
    std::vector<Named> cases = kernels();
    for (float size : { 3.0f, 5.0f, 7.5f, 9.0f, 11.0f, 20.0f, 31.0f })
        for (float rotation : { 0.0f, 30.0f, 7.0f, 25.0f, 45.0f, 83.0f })
            cases.push_back({ "hexagon " + std::to_string(size) + "@" + std::to_string(rotation),
                              hexagon(size, size, rotation) });
    for (const Named& n : cases)
        for (BlurMethod m : every_method(n.k))
            for (Border b : { Border::Clamp, Border::Mirror }) {
                SCOPED_TRACE(n.name + method_name(m) + (b == Border::Clamp ? " clamp" : " mirror"));
                BlurOptions o;
                o.method = m;
                o.border = b;
                OIIO::ImageBuf out;
                ASSERT_TRUE(blur(out, flat, n.k, o)) << out.geterror();
                const auto st = OIIO::ImageBufAlgo::computePixelStats(out);
                for (int c = 0; c < 4; ++c) {
                    EXPECT_NEAR(st.min[size_t(c)], value[c], 1e-6 * value[c]) << "channel " << c;
                    EXPECT_NEAR(st.max[size_t(c)], value[c], 1e-6 * value[c]) << "channel " << c;
                }
            }
    OIIO::ImageBuf out;
    Kernel k;
    k.width_px = k.height_px = 11;
    ASSERT_TRUE(blur(out, flat, k));
    float corner[4];
    out.getpixel(0, 0, corner);
    EXPECT_LT(corner[0], 0.5f) << "black outside darkens the corner";
}

TEST(Blur, ThreadCountDoesNotChangeResults)
{
    const OIIO::ImageBuf src = test_image(300, 200);
    for (const Named& n : kernels())
    for (BlurMethod m : exact_methods(n.k)) {
        SCOPED_TRACE(n.name + method_name(m));
        BlurOptions o;
        o.method = m;
        OIIO::ImageBuf one, two, eight;
        ASSERT_TRUE(blur(one, src, n.k, o, {}, 1));
        ASSERT_TRUE(blur(two, src, n.k, o, {}, 2));
        ASSERT_TRUE(blur(eight, src, n.k, o, {}, 8));
        const size_t bytes = size_t(src.roi().npixels()) * 4 * sizeof(float);
        EXPECT_EQ(std::memcmp(one.localpixels(), two.localpixels(), bytes), 0);
        EXPECT_EQ(std::memcmp(one.localpixels(), eight.localpixels(), bytes), 0);
        EXPECT_EQ(kernel_weights(n.k, 1).w, kernel_weights(n.k, 8).w) << "the weights, too";
    }
}
