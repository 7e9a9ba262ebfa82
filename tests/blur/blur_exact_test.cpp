// The exact uniform blurs against the brute-force reference: row spans, FFT tiles, the
// separable and box paths, OIIO's filters and oiiotool's hard-edged kernels, and the
// parameters each refuses.
#include <bokeh/blur.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <tuple>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>

#include "blur_fixtures.h"
#include "test_util.h"

using namespace bokeh;
using namespace blur_test;

TEST(Blur, EveryKernelMatchesTheBruteForceReference)
{
    const OIIO::ImageBuf src = test_image(61, 47);
    for (const Named& n : kernels())
        for (BlurMethod m : exact_methods(n.k))
        for (Border border : { Border::Black, Border::Clamp, Border::Mirror }) {
            SCOPED_TRACE(n.name + method_name(m));
            BlurOptions o;
            o.border = border;
            o.method = m;
            OIIO::ImageBuf fast, ref;
            ASSERT_TRUE(blur(fast, src, n.k, o)) << fast.geterror();
            ASSERT_TRUE(convolve_reference(ref, src, kernel_weights(n.k), o));
            // Tolerance: float output of double sums, relative to the brightest value.
            EXPECT_LE(bokeh_test::max_difference(fast, ref), 2e-6 * peak(ref)) << int(border);
        }
}

TEST(Blur, ALoneBrightPixelGivesTheKernelExactly)
{
    // Every exact method gives the kernel; Kawase's bilinear taps and the three boxes give
    // theirs (the bands' own test is BandsGiveTheirKernelFromALone1e6Pixel). One, three and
    // four channels: the running sums have a loop for each (RGBA in vector types).
    for (int nc : { 1, 3, 4 })
    for (const Named& n : kernels())
    for (BlurMethod m : every_method(n.k)) {
        if (m == BlurMethod::Fast || m == BlurMethod::Bands || m == BlurMethod::Parallelograms)
            continue;
        SCOPED_TRACE(n.name + method_name(m) + " channels " + std::to_string(nc));
        const KernelWeights kw = m == BlurMethod::BilinearTaps ? bilinear_tap_weights(n.k)
                                 : m == BlurMethod::ThreeBoxes ? three_box_weights(n.k)
                                                               : kernel_weights(n.k);
        OIIO::ImageBuf src(OIIO::ImageSpec(2 * kw.rx + 9, 2 * kw.ry + 9, nc, OIIO::TypeFloat));
        const int cx = kw.rx + 4, cy = kw.ry + 4;
        const std::vector<float> bright(size_t(nc), 1e6f);
        src.setpixel(cx, cy, bright.data());
        BlurOptions o;
        o.method = m;
        OIIO::ImageBuf out;
        ASSERT_TRUE(blur(out, src, n.k, o));
        double worst = 0.0;
        std::vector<float> v(static_cast<size_t>(nc));
        for (int y = 0; y < src.spec().height; ++y)
            for (int x = 0; x < src.spec().width; ++x) {
                out.getpixel(x, y, v.data());
                const int dx = x - cx, dy = y - cy;
                const double want = (std::abs(dx) <= kw.rx && std::abs(dy) <= kw.ry) ? kw.at(dx, dy) : 0.0;
                for (float c : v)
                    worst = std::max(worst, std::abs(c / 1e6 - want));
            }
        EXPECT_LE(worst, 1e-7) << "max deviation from the normalised kernel";
    }
}

TEST(Blur, WideImagesMatchTheBruteForceReferenceStripByStrip)
{
    // Wider than the fused methods' column strips (box: column_chunks, two up to 2879 px,
    // four from 2880): edge strips read by the border rule (black: in place too, the
    // running sum reading zeros past the data window), inner strips (the 3000 px image
    // below) the source in place on both sides; 1, 2 (prefix-sum fallback), 3 and 4
    // channels; fractional sizes; an explicit ROI reaching past the data.
    const OIIO::ImageBuf rgba = test_image(700, 29, -11, 5);
    std::vector<Kernel> ks;
    for (auto [w, h] : { std::pair{ 7.0f, 7.0f }, { 6.5f, 4.2f }, { 41.3f, 9.0f }, { 1.0f, 13.6f },
                         { 101.5f, 9.0f },
                         { 1201.5f, 1.0f } }) {  // wider than the frame: both ends black at once
        Kernel k;
        k.shape     = KernelShape::Box;
        k.width_px  = w;
        k.height_px = h;
        ks.push_back(k);
    }
    for (int nc : { 1, 2, 3, 4 }) {
        std::vector<int> order;
        for (int c = 0; c < nc; ++c)
            order.push_back(c);
        const OIIO::ImageBuf src = OIIO::ImageBufAlgo::channels(rgba, nc, order);
        for (const Kernel& k : ks)
            for (Border border : { Border::Black, Border::Clamp, Border::Mirror })
                for (bool explicit_roi : { false, true }) {
                    SCOPED_TRACE(std::to_string(nc) + " channels, " + std::to_string(k.width_px) + "x"
                                 + std::to_string(k.height_px) + ", border " + std::to_string(int(border))
                                 + (explicit_roi ? ", roi" : ""));
                    BlurOptions o;
                    o.border = border;
                    OIIO::ROI roi;
                    if (explicit_roi)
                        roi = OIIO::ROI(-40, 600, 0, 40);
                    OIIO::ImageBuf fast, ref;
                    ASSERT_TRUE(blur(fast, src, k, o, roi)) << fast.geterror();
                    ASSERT_TRUE(convolve_reference(ref, src, kernel_weights(k), o, roi));
                    ASSERT_EQ(fast.roi(), ref.roi());
                    EXPECT_LE(bokeh_test::max_difference(fast, ref), 2e-6 * peak(ref));
                }
    }
    // Four strips of 750: the two inner ones read their reach from their neighbours' columns.
    const OIIO::ImageBuf wide = test_image(3000, 13, 3, -2);
    for (std::size_t i : { std::size_t(2), std::size_t(4) })
        for (Border border : { Border::Black, Border::Mirror }) {
            SCOPED_TRACE(std::to_string(ks[i].width_px) + ", border " + std::to_string(int(border)));
            BlurOptions o;
            o.border = border;
            OIIO::ImageBuf fast, ref;
            ASSERT_TRUE(blur(fast, wide, ks[i], o)) << fast.geterror();
            ASSERT_TRUE(convolve_reference(ref, wide, kernel_weights(ks[i]), o, {}));
            EXPECT_LE(bokeh_test::max_difference(fast, ref), 2e-6 * peak(ref));
        }
}

TEST(Blur, WideImagesMatchTheReferenceTileByTileForSpansFftAndBands)
{
    // Several tiles of the direct span, FFT and band paths (the FFT's transforms are 64 to
    // 256 px here, with partial tiles at the right and bottom edges): inner tiles read
    // the source in place, edge tiles by the border rule; an explicit ROI past the data;
    // 3 and 4 channels. Bands are checked against their own banded kernel.
    const OIIO::ImageBuf rgba = test_image(600, 150, 7, -9);
    std::vector<Named> ks;
    for (const Named& n : kernels())
        if (n.k.shape == KernelShape::Disk || n.k.shape == KernelShape::Polygon)
            ks.push_back(n);
    for (int nc : { 3, 4 }) {
        const OIIO::ImageBuf src = nc == 4 ? rgba : OIIO::ImageBufAlgo::channels(rgba, 3, { 0, 1, 2 });
        for (const Named& n : ks)
            for (BlurMethod m : { BlurMethod::Spans, BlurMethod::Fft, BlurMethod::Bands }) {
                const bool bands = m == BlurMethod::Bands;
                if (bands && n.k.hole > 0.0f)
                    continue;
                for (Border border : { Border::Black, Border::Clamp, Border::Mirror })
                    for (bool explicit_roi : { false, true }) {
                        SCOPED_TRACE(std::string(n.name) + (bands ? " bands" : method_name(m)) + ", "
                                     + std::to_string(nc) + " channels, border "
                                     + std::to_string(int(border)) + (explicit_roi ? ", roi" : ""));
                        BlurOptions o;
                        o.border = border;
                        o.method = m;
                        o.bands  = 8;
                        OIIO::ROI roi;
                        if (explicit_roi)
                            roi = OIIO::ROI(-20, 530, -30, 140);
                        const KernelWeights kw = bands ? banded_weights(n.k, o.bands) : kernel_weights(n.k);
                        OIIO::ImageBuf fast, ref;
                        ASSERT_TRUE(blur(fast, src, n.k, o, roi)) << fast.geterror();
                        ASSERT_TRUE(convolve_reference(ref, src, kw, o, roi));
                        ASSERT_EQ(fast.roi(), ref.roi());
                        EXPECT_LE(bokeh_test::max_difference(fast, ref), 2e-6 * peak(ref));
                    }
            }
    }
}

TEST(Blur, SpansAndFftTilesAgreeAndExactIsOneOfThem)
{
    // The cost models (blur_spans.cpp, blur_fft.cpp) pick row spans at 15 px and FFT tiles at
    // 151 px for the exact method. Both are exact in double, so their float results agree
    // to the last bit or so (which one ran shows in the time only: docs/benchmarks.md).
    const OIIO::ImageBuf src = test_image(640, 360);
    for (float size : { 15.0f, 151.0f }) {
        SCOPED_TRACE(size);
        Kernel k;
        k.shape    = KernelShape::Disk;
        k.width_px = k.height_px = size;
        BlurOptions spans, fft;
        spans.method = BlurMethod::Spans;
        fft.method   = BlurMethod::Fft;
        OIIO::ImageBuf exact, by_spans, by_fft;
        ASSERT_TRUE(blur(exact, src, k));
        ASSERT_TRUE(blur(by_spans, src, k, spans));
        ASSERT_TRUE(blur(by_fft, src, k, fft));
        EXPECT_LE(bokeh_test::max_difference(by_fft, by_spans), 2e-7 * peak(by_spans));
        EXPECT_LE(bokeh_test::max_difference(exact, size < 50.0f ? by_spans : by_fft), 2e-7 * peak(by_spans));
    }
    // 1 and 5 channels through the tiles.
    Kernel k;
    k.shape    = KernelShape::Polygon;
    k.width_px = k.height_px = 41;
    for (int nc : { 1, 5 }) {
        SCOPED_TRACE(nc);
        const OIIO::ImageBuf img = OIIO::ImageBufAlgo::channels(src, nc, nc == 1 ? std::vector<int>{ 2 }
                                                                       : std::vector<int>{ 0, 1, 2, 3, 0 });
        BlurOptions fft;
        fft.method = BlurMethod::Fft;
        OIIO::ImageBuf by_fft, ref;
        ASSERT_TRUE(blur(by_fft, img, k, fft));
        ASSERT_TRUE(convolve_reference(ref, img, kernel_weights(k)));
        EXPECT_LE(bokeh_test::max_difference(by_fft, ref), 2e-6 * peak(ref));
    }
    // Past the largest transform (8192 px): refused by name, not crashed.
    Kernel huge;
    huge.shape    = KernelShape::Gaussian;
    huge.sigma_px = 1024;  // 4 sigma each side: 8193 px
    BlurOptions fft;
    fft.method = BlurMethod::Fft;
    OIIO::ImageBuf out;
    EXPECT_FALSE(blur(out, OIIO::ImageBufAlgo::cut(src, OIIO::ROI(0, 8, 0, 8)), huge, fft));
    EXPECT_NE(out.geterror().find("under 8192 px"), std::string::npos) << out.geterror();
}

TEST(Blur, FftTilesGiveTheKernelFromALone1e6PixelAndNothingElsewhere)
{
    // A transform spreads its rounding over its whole tile: beside a 1e6 pixel, the 0.3
    // around it must still come out as 0.3, in every tile (700 x 400 at 121 px: several).
    Kernel k;
    k.shape    = KernelShape::Disk;
    k.width_px = k.height_px = 121;
    const KernelWeights kw   = kernel_weights(k);
    OIIO::ImageBuf src(OIIO::ImageSpec(700, 400, 1, OIIO::TypeFloat));
    OIIO::ImageBufAlgo::fill(src, { 0.3f });
    const int cx = 250, cy = 160;
    const float bright = 1e6f;
    src.setpixel(cx, cy, &bright);
    BlurOptions o;
    o.method = BlurMethod::Fft;
    o.border = Border::Clamp;
    OIIO::ImageBuf out;
    ASSERT_TRUE(blur(out, src, k, o));
    double worst_near = 0.0, worst_far = 0.0;
    for (int y = 0; y < 400; ++y)
        for (int x = 0; x < 700; ++x) {
            float v;
            out.getpixel(x, y, &v);
            const int dx = x - cx, dy = y - cy;
            const bool near = std::abs(dx) <= kw.rx && std::abs(dy) <= kw.ry;
            const double want = (near ? kw.at(dx, dy) * (1e6 - 0.3) : 0.0) + 0.3;
            (near ? worst_near : worst_far) = std::max(near ? worst_near : worst_far, std::abs(v - want));
        }
    EXPECT_LE(worst_near, 1e-7 * 1e6) << "the kernel, to float's precision of the peak";
    EXPECT_LE(worst_far, 1e-6) << "0.3 away from the bright pixel, to float's precision";
}

// OIIO's kernels, by the names oiiotool's --blur takes, and ours with a hard edge.
struct OiioKernel {
    const char* name;
    KernelShape shape;
};
constexpr OiioKernel kOiioKernels[] = { { "disk", KernelShape::Disk },
                                        { "box", KernelShape::Box },
                                        { "gaussian", KernelShape::Gaussian } };

TEST(Blur, HardEdgeWeightsAreOiiosMakeKernel)
{
    // Every weight of make_kernel(name, w, h) at its offset (its window is ceil(w) | 1
    // wide, centred on 0), and none past it; OIIO computes in float (its gaussian by an
    // approximate exp: 1.5e-6 apart at worst, 1x4), so to 5e-6 of the weights' sum.
    for (const OiioKernel& o : kOiioKernels)
        for (auto [w, h] : { std::pair{ 7.0f, 7.0f }, { 8.0f, 8.0f }, { 5.0f, 3.0f }, { 7.5f, 11.0f },
                             { 6.3f, 2.2f }, { 1.0f, 4.0f }, { 31.0f, 31.0f } }) {
            SCOPED_TRACE(testing::Message() << o.name << " " << w << "x" << h);
            Kernel k;
            k.shape     = o.shape;
            k.width_px  = w;
            k.height_px = h;
            k.edge      = KernelEdge::Hard;
            const KernelWeights ours    = kernel_weights(k);
            const OIIO::ImageBuf theirs = OIIO::ImageBufAlgo::make_kernel(o.name, w, h);
            ASSERT_FALSE(theirs.has_error()) << theirs.geterror();
            const OIIO::ROI r = theirs.roi();
            ASSERT_LE(ours.rx, -r.xbegin);
            ASSERT_LE(ours.ry, -r.ybegin);
            double worst = 0.0;
            for (int y = r.ybegin; y < r.yend; ++y)
                for (int x = r.xbegin; x < r.xend; ++x) {
                    const double w_ours = std::abs(x) <= ours.rx && std::abs(y) <= ours.ry ? ours.at(x, y) : 0.0;
                    worst = std::max(worst, std::abs(w_ours - double(theirs.getchannel(x, y, 0, 0))));
                }
            EXPECT_LE(worst, 5e-6);
        }
}

TEST(Blur, HardEdgeEqualsOiioConvolution)
{
    // Values in [0, 1], as the 1e-5 of the requirement assumes (OIIO sums in float).
    const OIIO::ImageBuf src = test_image(53, 41, 0, 0, false);
    for (const OiioKernel& o : kOiioKernels)
        for (auto [w, h] : { std::pair{ 7, 7 }, { 6, 6 }, { 5, 3 }, { 12, 9 }, { 31, 31 } }) {
            SCOPED_TRACE(testing::Message() << o.name << " " << w << "x" << h);
            Kernel k;
            k.shape     = o.shape;
            k.width_px  = float(w);
            k.height_px = float(h);
            k.edge      = KernelEdge::Hard;
            for (BlurMethod m : exact_methods(k)) {
                SCOPED_TRACE(method_name(m));
                BlurOptions opts;
                opts.method = m;
                OIIO::ImageBuf ours;
                ASSERT_TRUE(blur(ours, src, k, opts));
                const OIIO::ImageBuf kernel = OIIO::ImageBufAlgo::make_kernel(o.name, float(w), float(h));
                const OIIO::ImageBuf theirs = OIIO::ImageBufAlgo::convolve(src, kernel);
                // OIIO treats the image border its own way; away from it the two must agree.
                OIIO::ROI inner = src.roi();
                inner.xbegin += w / 2, inner.xend -= w / 2, inner.ybegin += h / 2, inner.yend -= h / 2;
                EXPECT_LE(bokeh_test::max_difference(OIIO::ImageBufAlgo::cut(ours, inner),
                                                     OIIO::ImageBufAlgo::cut(theirs, inner)),
                          1e-5);
            }
        }
}

TEST(Blur, OiioFiltersEqualOiioConvolution)
{
    // oiiotool's other --blur kernels, every one OIIO names: make_kernel(name, w, h)'s
    // weights, each exact method against IBA::convolve away from the border (1e-5, values
    // 0..1), the separable ones' factors reproducing the whole kernel.
    const OIIO::ImageBuf src = test_image(53, 41, 0, 0, false);
    const std::vector<std::string> names = oiio_filter_names();
    ASSERT_GE(names.size(), 10u);
    for (const std::string& name : names)
        for (auto [w, h] : { std::pair{ 5.0f, 5.0f }, { 7.5f, 11.0f } }) {
            if ((name == "binomial" && w != std::floor(w)) || name == "sinc")
                continue;  // odd whole sizes only; sinc is the identity (both refused below)
            SCOPED_TRACE(testing::Message() << name << " " << w << "x" << h);
            Kernel k;
            k.shape     = KernelShape::Filter;
            k.filter    = name;
            k.width_px  = w;
            k.height_px = h;
            const KernelWeights kw = kernel_weights(k);
            if (is_separable(k)) {
                const auto [wx, wy] = separable_weights(k);
                ASSERT_EQ(wx.size(), size_t(2 * kw.rx + 1));
                ASSERT_EQ(wy.size(), size_t(2 * kw.ry + 1));
                double worst = 0.0;
                for (int dy = -kw.ry; dy <= kw.ry; ++dy)
                    for (int dx = -kw.rx; dx <= kw.rx; ++dx)
                        worst = std::max(worst, std::abs(wx[size_t(dx + kw.rx)] * wy[size_t(dy + kw.ry)] - kw.at(dx, dy)));
                EXPECT_LE(worst, 1e-7) << "not a product of its row and column";
            }
            const OIIO::ImageBuf theirs = OIIO::ImageBufAlgo::convolve(src, OIIO::ImageBufAlgo::make_kernel(name, w, h));
            for (BlurMethod m : exact_methods(k)) {
                SCOPED_TRACE(method_name(m));
                BlurOptions opts;
                opts.method = m;
                OIIO::ImageBuf ours;
                ASSERT_TRUE(blur(ours, src, k, opts)) << ours.geterror();
                OIIO::ROI inner = src.roi();
                inner.xbegin += kw.rx, inner.xend -= kw.rx, inner.ybegin += kw.ry, inner.yend -= kw.ry;
                EXPECT_LE(bokeh_test::max_difference(OIIO::ImageBufAlgo::cut(ours, inner),
                                                     OIIO::ImageBufAlgo::cut(theirs, inner)),
                          1e-5);
            }
        }
    // Refused, each with its reason: an unknown name, binomial past its odd whole sizes
    // (OIIO's own kernel reads weights it never wrote there), the separable method on a
    // radial filter, iris mode with negative lobes.
    Kernel k;
    k.shape    = KernelShape::Filter;
    k.width_px = k.height_px = 8.0f;
    auto refused = [&](const char* why, BlurOptions o = {}) {
        OIIO::ImageBuf out;
        EXPECT_FALSE(blur(out, src, k, o)) << why;
        EXPECT_NE(out.geterror().find(why), std::string::npos) << out.geterror();
    };
    k.filter = "laplacian";
    refused("is not one of OIIO's filters");
    k.filter = "sinc";
    refused("not scaled to the kernel's size");
    k.filter = "binomial";
    refused("odd whole sizes up to 127");
    k.width_px = k.height_px = 129.0f;
    refused("odd whole sizes up to 127");
    k.filter = "triangle";
    BlurOptions reduced;
    reduced.method = BlurMethod::Reduced;
    refused("method=reduced is not offered for OIIO's filters", reduced);
    k.width_px = k.height_px = 8.0f;
    k.filter = "radial-lanczos3";
    BlurOptions separable;
    separable.method = BlurMethod::Separable;
    refused("OIIO's separable filters", separable);
    k.filter = "lanczos3";
    BlurOptions iris;
    iris.iris = 0.1f;
    refused("without negative weights (lanczos3 has some)", iris);
}

TEST(Blur, SeparableKernelsTallerThanTheImage)
{
    // The direct separable convolution reads source rows again past the image's edges
    // (clamp, mirror) and copies the x-filtered row it still holds: a Gaussian reaching 36
    // px and a 41 x 3 triangle on a 20 x 12 image, every border, grown or not, against the
    // brute force with the same weights.
    const OIIO::ImageBuf src = test_image(20, 12, 3, -2);
    Kernel gauss;
    gauss.shape    = KernelShape::Gaussian;
    gauss.sigma_px = 9.0f;
    Kernel tri;
    tri.shape     = KernelShape::Filter;
    tri.filter    = "triangle";
    tri.width_px  = 3.0f;
    tri.height_px = 41.0f;
    for (const Kernel& k : { gauss, tri })
        for (Border border : { Border::Black, Border::Clamp, Border::Mirror })
            for (bool grow : { false, true }) {
                SCOPED_TRACE(testing::Message() << int(k.shape) << " border " << int(border) << " grow " << grow);
                BlurOptions o;
                o.method = BlurMethod::Separable;
                o.border = border;
                o.grow   = grow;
                OIIO::ImageBuf got, ref;
                ASSERT_TRUE(blur(got, src, k, o)) << got.geterror();
                ASSERT_TRUE(convolve_reference(ref, src, kernel_weights(k), o));
                ASSERT_EQ(got.roi(), ref.roi());
                EXPECT_LE(bokeh_test::max_difference(got, ref), 2e-6 * peak(ref));
            }
}

TEST(Blur, LargeBinomialIsPascalsRow)
{
    // Past 65 px OIIO's 2-D binomial kernel sums past float's range (oiiotool's picture
    // turns black); ours is made from the 1-D rows, so a 101 x 3 binomial is C(100, i) /
    // 2^100 along x and (1, 2, 1) / 4 along y, to float's precision.
    Kernel k;
    k.shape     = KernelShape::Filter;
    k.filter    = "binomial";
    k.width_px  = 101.0f;
    k.height_px = 3.0f;
    std::string err;
    ASSERT_TRUE(check_kernel(k, err)) << err;
    const auto [wx, wy] = separable_weights(k);
    ASSERT_EQ(wy.size(), 3u);
    EXPECT_NEAR(wy[1], 0.5, 1e-7);
    double c = 1.0, worst = 0.0;  // C(100, i) / 2^100, built up along the row
    std::vector<double> want;
    for (int i = 0; i <= 100; ++i) {
        want.push_back(c / std::pow(2.0, 100.0));
        c = c * double(100 - i) / double(i + 1);
    }
    // The row's far tails are below float's reach next to its peak (C(100, 0) / C(100, 50)
    // is 1e-29) and trimmed only where exactly zero: compare where both have weight.
    ASSERT_LE(wx.size(), want.size());
    const size_t off = (want.size() - wx.size()) / 2;
    for (size_t i = 0; i < wx.size(); ++i)
        worst = std::max(worst, std::abs(wx[i] - want[i + off]) / want[50]);
    EXPECT_LE(worst, 1e-6);
    const KernelWeights kw = kernel_weights(k);
    EXPECT_NEAR(std::accumulate(kw.w.begin(), kw.w.end(), 0.0), 1.0, 1e-12);
}

TEST(Blur, HardGaussianIsCutAtItsFootprint)
{
    // oiiotool's Gaussian: sigma = W / 4, nothing at |x| >= W / 2; with a sigma of its
    // own, cut at the footprint given, or at 2 sigma without one. `fast` computes it
    // exactly (three boxes stand for the whole Gaussian, and are refused by name).
    Kernel k;
    k.shape    = KernelShape::Gaussian;
    k.width_px = k.height_px = 8.0f;
    k.edge     = KernelEdge::Hard;
    auto [wx, wy] = separable_weights(k);
    ASSERT_EQ(wx.size(), 7u);  // |x| < 4
    EXPECT_NEAR(wx[2] / wx[3], std::exp(-1.0 / (2.0 * 4.0)), 1e-12);  // sigma 2
    k.sigma_px = 1.0f;
    std::tie(wx, wy) = separable_weights(k);
    ASSERT_EQ(wx.size(), 7u);
    EXPECT_NEAR(wx[0] / wx[3], std::exp(-4.5), 1e-12);
    k.width_px = k.height_px = 0.0f;
    std::tie(wx, wy) = separable_weights(k);
    EXPECT_EQ(wx.size(), 3u);  // |x| < 2 sigma
    k.sigma_px = 0.0f;
    k.width_px = k.height_px = 9.0f;
    const OIIO::ImageBuf src = test_image(40, 30, 0, 0, false);
    BlurOptions fast;
    fast.method = BlurMethod::Fast;
    OIIO::ImageBuf a, b;
    ASSERT_TRUE(blur(a, src, k, fast));
    ASSERT_TRUE(blur(b, src, k));
    EXPECT_EQ(bokeh_test::max_difference(a, b), 0.0);
    BlurOptions boxes;
    boxes.method = BlurMethod::ThreeBoxes;
    EXPECT_FALSE(blur(a, src, k, boxes));
    EXPECT_NE(a.geterror().find("anti-aliased gaussian"), std::string::npos) << a.geterror();
}

TEST(Blur, BadParametersAreRefused)
{
    const OIIO::ImageBuf src = test_image(8, 8);
    auto refused = [&](Kernel k, const char* what) {
        OIIO::ImageBuf out;
        EXPECT_FALSE(blur(out, src, k)) << what;
        EXPECT_NE(out.geterror().find(what), std::string::npos) << out.geterror();
    };
    Kernel k;
    k.width_px = -1;
    refused(k, "outside 0..4096");
    k.width_px = NAN;
    refused(k, "outside 0..4096");
    k = Kernel();
    k.blades = 2;
    refused(k, "blades 2");
    k = Kernel();
    k.hole = 1.0f;
    refused(k, "hole 1");
    k = Kernel();
    k.curvature = 2.0f;
    refused(k, "curvature 2");
    k = Kernel();
    k.width_px = k.height_px = 5;
    auto method_refused = [&](BlurMethod m, const char* what, BlurOptions o = {}) {
        o.method = m;
        OIIO::ImageBuf out;
        EXPECT_FALSE(blur(out, src, k, o)) << what;
        EXPECT_NE(out.geterror().find(what), std::string::npos) << out.geterror();
    };
    method_refused(BlurMethod::Parallelograms, "needs a hexagon");
    method_refused(BlurMethod::ThreeBoxes, "for the anti-aliased gaussian");
    method_refused(BlurMethod::BilinearTaps, "9x9 or 17x17");
    BlurOptions bad;
    bad.bands = -1;
    method_refused(BlurMethod::Bands, "bands -1", bad);
    bad.bands = 65;
    method_refused(BlurMethod::Fast, "bands 65", bad);
    bad       = BlurOptions();
    bad.iris  = NAN;
    method_refused(BlurMethod::Auto, "iris nan", bad);
    k.hole = 0.3f;
    method_refused(BlurMethod::Bands, "without a hole");
}
