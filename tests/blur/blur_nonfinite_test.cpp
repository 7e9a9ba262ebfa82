// NaN and infinities in the source (core/blur/blur_nonfinite.cpp): each stays within its
// kernel's footprint, as in the brute-force convolution, for the uniform kernels and for
// image kernels.
#include <bokeh/blur.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>

#include "blur_fixtures.h"

using namespace bokeh;
using namespace blur_test;

namespace {

// test_image with NaN, +inf and -inf in some channels (and where +inf and -inf meet, NaN),
// a sky of +inf at the right edge (clamp and mirror repeat it); the same with them as 0;
// an indicator image of each kind (NaN, +inf, -inf).
struct NonFiniteImage {
    OIIO::ImageBuf src, zeroed, floored, kinds[3];  // floored: each channel's least finite value
    // The image the blur runs on in place of src: iris mode keeps its range.
    const OIIO::ImageBuf& replaced(float iris) const { return iris != 0.0f ? floored : zeroed; }
};

NonFiniteImage nonfinite_image()
{
    NonFiniteImage b;
    b.src    = test_image(61, 47);
    auto put = [&](int x, int y, int c, float v) {
        float px[4];
        b.src.getpixel(x, y, px);
        px[c] = v;
        b.src.setpixel(x, y, px);
    };
    const float inf = std::numeric_limits<float>::infinity();
    put(20, 15, 0, std::numeric_limits<float>::quiet_NaN());
    put(40, 30, 1, inf);
    put(43, 30, 1, -inf);
    put(10, 35, 2, -inf);
    for (int y = 5; y < 13; ++y)
        for (int x = 52; x < 61; ++x)
            put(x, y, 3, inf);
    b.zeroed = b.src;
    for (OIIO::ImageBuf& k : b.kinds) {
        k = OIIO::ImageBuf(b.src.spec());
        OIIO::ImageBufAlgo::zero(k);
    }
    for (OIIO::ImageBuf::Iterator<float> it(b.zeroed); !it.done(); ++it)
        for (int c = 0; c < 4; ++c)
            if (!std::isfinite(it[c])) {
                const int kind = std::isnan(it[c]) ? 0 : it[c] > 0 ? 1 : 2;
                float one[4]   = { 0, 0, 0, 0 };
                b.kinds[kind].getpixel(it.x(), it.y(), one);
                one[c] = 1.0f;
                b.kinds[kind].setpixel(it.x(), it.y(), one);
                it[c] = 0.0f;
            }
    b.floored = b.src;
    for (int c = 0; c < 4; ++c) {
        float least = std::numeric_limits<float>::infinity();
        for (OIIO::ImageBuf::ConstIterator<float> it(b.src); !it.done(); ++it)
            if (std::isfinite(it[c]))
                least = std::min(least, it[c]);
        for (OIIO::ImageBuf::Iterator<float> it(b.floored); !it.done(); ++it)
            if (!std::isfinite(it[c]))
                it[c] = least;
    }
    return b;
}

// Each output of `got` against the brute force's answer: NaN where `reach` (the brute
// force on each kind's indicator) says NaN reaches it or both infinities do, the infinity
// where one does, else `clean` (the blur with the bad values as 0) exactly. Also that some
// output is non-finite.
void expect_footprint(const OIIO::ImageBuf& got, const OIIO::ImageBuf& clean, const OIIO::ImageBuf (&reach)[3])
{
    const float inf = std::numeric_limits<float>::infinity();
    int wrong = 0, bad = 0;
    for (OIIO::ImageBuf::ConstIterator<float> it(got); !it.done(); ++it)
        for (int c = 0; c < got.nchannels(); ++c) {
            float r[3];
            for (int kind = 0; kind < 3; ++kind)
                r[kind] = reach[kind].getchannel(it.x(), it.y(), 0, c);
            const float v = it[c], want_clean = clean.getchannel(it.x(), it.y(), 0, c);
            bool ok;
            if (r[0] > 0.0f || (r[1] > 0.0f && r[2] > 0.0f))
                ok = std::isnan(v);
            else if (r[1] > 0.0f || r[2] > 0.0f)
                ok = v == (r[1] > 0.0f ? inf : -inf);
            else
                ok = v == want_clean;
            bad += !std::isfinite(v);
            if (!ok && wrong++ < 3)
                ADD_FAILURE() << "(" << it.x() << ", " << it.y() << ") channel " << c << ": " << v
                              << ", reached by NaN/+inf/-inf " << r[0] << "/" << r[1] << "/" << r[2]
                              << ", without them " << want_clean;
        }
    EXPECT_EQ(wrong, 0);
    EXPECT_GT(bad, 0) << "the bad values reach some outputs";
}

// reach[0..2] over `roi`: how much of the brute force with `w` falls on the NaN, +inf and
// -inf pixels of b.kinds, per channel, the positive and negative weights apart (through a
// negative weight an infinity counts as the other sign). `kernel_of(c)` gives channel c's
// weights, or, given `all`, one set for every channel at once.
template<class KernelOf>
void brute_force_reach(OIIO::ImageBuf (&reach)[3], const NonFiniteImage& b, const BlurOptions& plain, OIIO::ROI roi,
                       bool all, KernelOf kernel_of)
{
    for (int kind = 0; kind < 3; ++kind) {
        reach[kind] = OIIO::ImageBuf(OIIO::ImageSpec(roi, OIIO::TypeFloat));
        OIIO::ImageBufAlgo::zero(reach[kind]);
    }
    const int nc = b.src.nchannels();
    for (int c = 0; c < (all ? 1 : nc); ++c) {
        const KernelWeights w = kernel_of(c);
        const bool is_signed  = std::any_of(w.w.begin(), w.w.end(), [](double v) { return v < 0.0; });
        for (const double sign : { 1.0, -1.0 }) {
            if (sign < 0.0 && !is_signed)
                continue;
            KernelWeights part = w;
            for (double& v : part.w)
                v = std::max(0.0, sign * v);
            for (int kind = 0; kind < 3; ++kind) {
                const int as = sign > 0.0 || kind == 0 ? kind : 3 - kind;
                OIIO::ImageBuf out;
                ASSERT_TRUE(convolve_reference(out, all ? b.kinds[kind] : OIIO::ImageBufAlgo::channels(b.kinds[kind], 1, { c }),
                                               part, plain, roi));
                ASSERT_EQ(out.roi().xbegin, reach[as].roi().xbegin);
                ASSERT_EQ(out.roi().xend, reach[as].roi().xend);
                ASSERT_EQ(out.roi().ybegin, reach[as].roi().ybegin);
                ASSERT_EQ(out.roi().yend, reach[as].roi().yend);
                OIIO::ImageBuf::ConstIterator<float> from(out);
                for (OIIO::ImageBuf::Iterator<float> to(reach[as]); !to.done(); ++to, ++from)
                    for (int k = 0; k < (all ? nc : 1); ++k)
                        to[all ? k : c] = to[all ? k : c] + from[k];
            }
        }
    }
}

}  // namespace

TEST(Blur, NonFiniteValuesStayWithinTheirFootprint)
{
    // The bad-value rule: a NaN or an infinity reaches exactly the outputs whose kernel
    // has weight on it, as in the brute-force convolution (+inf or -inf where all it reaches
    // have that sign, NaN otherwise), and every other output is the blur of the image with
    // those values read as 0. Running and prefix sums alone would carry them along the rows
    // and down the columns (inf - inf is NaN), the FFT over its tile. Every method, every
    // border, a grown window; infinite depth (a sky) is the case met in practice.
    const NonFiniteImage b = nonfinite_image();
    for (const Named& n : kernels()) {
        std::vector<std::pair<BlurMethod, float>> methods;  // (method, iris)
        for (BlurMethod m : every_method(n.k))
            methods.push_back({ m, 0.0f });
        if (n.k.shape != KernelShape::Filter)  // OIIO's filters are not reduced (refused)
            methods.push_back({ BlurMethod::Reduced, 0.0f });
        methods.push_back({ BlurMethod::Auto, 0.05f });
        for (const auto& [method, iris] : methods)
            for (Border border : { Border::Black, Border::Clamp, Border::Mirror }) {
                SCOPED_TRACE(testing::Message() << n.name << method_name(method) << " " << int(method) << " iris "
                                                << iris << " border " << int(border));
                BlurOptions o;
                o.method    = method;
                o.iris      = iris;
                o.border    = border;
                o.grow      = border == Border::Black;
                o.reduction = method == BlurMethod::Reduced ? 2.0f : 0.0f;
                OIIO::ImageBuf got, clean, reach[3];
                const KernelWeights kw = kernel_weights(n.k);
                const bool is_signed   = std::any_of(kw.w.begin(), kw.w.end(), [](double v) { return v < 0.0; });
                if (iris != 0.0f && is_signed) {
                    // A mean of exp(k x) with negative weights can fall to 0 or below: refused.
                    EXPECT_FALSE(blur(got, b.src, n.k, o));
                    EXPECT_NE(got.geterror().find("without negative weights"), std::string::npos) << got.geterror();
                    continue;
                }
                ASSERT_TRUE(blur(got, b.src, n.k, o)) << got.geterror();
                ASSERT_TRUE(blur(clean, b.replaced(iris), n.k, o, got.roi())) << clean.geterror();
                // The brute force on the indicators, the positive and negative weights apart
                // (OIIO's lanczos3, say): an infinity through a negative weight changes sign.
                BlurOptions plain = o;
                plain.iris        = 0.0f;
                brute_force_reach(reach, b, plain, got.roi(), true, [&](int) { return kw; });
                if (testing::Test::HasFatalFailure())
                    return;
                expect_footprint(got, clean, reach);
            }
    }
}

TEST(Blur, NonFiniteFootprintsOfLargeKernels)
{
    // Large kernels, where the footprints are found by FFT rather than row spans (counts to
    // within rounding, read as reached from 0.5): each output is checked against the
    // kernel's weights at its offset from each bad pixel (black border, grown window).
    OIIO::ImageBuf src = test_image(150, 110);
    const float inf    = std::numeric_limits<float>::infinity();
    struct Bad {
        int x, y, c;
        float v;
    };
    const Bad bads[] = { { 30, 40, 0, std::numeric_limits<float>::quiet_NaN() }, { 100, 60, 1, inf },
                         { 120, 20, 1, -inf }, { 75, 100, 3, inf } };
    for (const Bad& b : bads) {
        float px[4];
        src.getpixel(b.x, b.y, px);
        px[b.c] = b.v;
        src.setpixel(b.x, b.y, px);
    }
    for (float size : { 101.0f, 151.0f }) {
        Kernel k;
        k.shape    = KernelShape::Disk;
        k.width_px = k.height_px = size;
        const KernelWeights w    = kernel_weights(k);
        BlurOptions o;
        o.grow = true;
        for (BlurMethod m : { BlurMethod::Auto, BlurMethod::Fast }) {
            SCOPED_TRACE(testing::Message() << size << method_name(m));
            o.method = m;
            OIIO::ImageBuf got;
            ASSERT_TRUE(blur(got, src, k, o)) << got.geterror();
            int wrong = 0;
            for (OIIO::ImageBuf::ConstIterator<float> it(got); !it.done(); ++it)
                for (int c = 0; c < 4; ++c) {
                    bool nan = false, pos = false, neg = false;
                    for (const Bad& b : bads) {
                        const int dx = it.x() - b.x, dy = it.y() - b.y;
                        if (b.c != c || std::abs(dx) > w.rx || std::abs(dy) > w.ry || w.at(dx, dy) <= 0.0)
                            continue;
                        nan = nan || std::isnan(b.v);
                        pos = pos || b.v == inf;
                        neg = neg || b.v == -inf;
                    }
                    const bool ok = nan || (pos && neg) ? std::isnan(it[c])
                                    : pos || neg       ? it[c] == (pos ? inf : -inf)
                                                       : std::isfinite(it[c]);
                    if (!ok && wrong++ < 3)
                        ADD_FAILURE() << "(" << it.x() << ", " << it.y() << ") channel " << c << ": " << it[c];
                }
            EXPECT_EQ(wrong, 0);
        }
    }
}

TEST(BlurImageKernel, NonFiniteValuesStayWithinTheirFootprint)
{
    // As for the uniform kernels (Blur.NonFiniteValuesStayWithinTheirFootprint): the FFT
    // runs on the image with them replaced, and their footprints are the kernel channels'
    // supports. A one-channel kernel, a colour one (each channel its own support: the
    // third channel's ring, the fourth source channel the channels' mean), and one with
    // negative weights (a sharpening ring), through which an infinity changes sign.
    const NonFiniteImage b = nonfinite_image();
    // 9 x 7 kernels: a ring, a filled ellipse, a ramp heavier to the right.
    auto weight = [](int kc, int dx, int dy) {
        const int r2 = dx * dx + dy * dy;
        return kc == 0 ? (r2 >= 6 && r2 <= 14 ? 1.0f + 0.1f * float(dx) : 0.0f)
               : kc == 1 ? (4 * dx * dx + 9 * dy * dy <= 60 ? 1.0f : 0.0f)
               : kc == 2 ? 1.0f + 0.25f * float(dx + 4)
                         : (r2 <= 2 ? 3.0f : std::abs(dx) == 4 ? -0.5f : 0.0f);
    };
    auto kernel = [&](int nchannels, int first = 0) {
        OIIO::ImageSpec spec(9, 7, nchannels, OIIO::TypeFloat);
        spec.x = -4;
        spec.y = -3;
        OIIO::ImageBuf img(spec);
        for (int dy = -3; dy <= 3; ++dy)
            for (int dx = -4; dx <= 4; ++dx) {
                float px[3];
                for (int kc = 0; kc < nchannels; ++kc)
                    px[kc] = weight(first + kc, dx, dy);
                img.setpixel(dx, dy, px);
            }
        return img;
    };
    struct Case {
        const char* name;
        OIIO::ImageBuf kernel;
    };
    for (const Case& k : { Case{ "ring", kernel(1) }, Case{ "colour", kernel(3) }, Case{ "signed", kernel(1, 3) } })
        for (Border border : { Border::Black, Border::Clamp, Border::Mirror })
            for (float iris : { 0.0f, 0.05f }) {
                SCOPED_TRACE(testing::Message() << k.name << " border " << int(border) << " iris " << iris);
                BlurOptions o;
                o.border = border;
                o.grow   = border == Border::Black;
                o.iris   = iris;
                OIIO::ImageBuf got, clean, reach[3];
                if (iris != 0.0f && std::string(k.name) == "signed") {
                    // A mean of exp(k x) with negative weights can fall to 0 or below: refused.
                    EXPECT_FALSE(convolve_image(got, b.src, k.kernel, o));
                    EXPECT_NE(got.geterror().find("without negative weights"), std::string::npos) << got.geterror();
                    continue;
                }
                ASSERT_TRUE(convolve_image(got, b.src, k.kernel, o)) << got.geterror();
                ASSERT_TRUE(convolve_image(clean, b.replaced(iris), k.kernel, o, got.roi())) << clean.geterror();
                // The brute force on the indicators, channel by channel with its kernel, its
                // positive and negative weights apart: an infinity through a negative weight
                // changes sign.
                BlurOptions plain = o;
                plain.iris        = 0.0f;
                const int knc     = k.kernel.nchannels();
                brute_force_reach(reach, b, plain, got.roi(), false, [&](int c) {
                    KernelWeights w{ 4, 3, std::vector<double>(63, 0.0) };
                    for (int kc = 0; kc < knc; ++kc)
                        if (knc == 1 || kc == c || c >= knc)
                            for (int dy = -3; dy <= 3; ++dy)
                                for (int dx = -4; dx <= 4; ++dx)
                                    w.w[size_t((dy + 3) * 9 + dx + 4)] += k.kernel.getchannel(dx, dy, 0, kc);
                    return w;
                });
                if (testing::Test::HasFatalFailure())
                    return;
                expect_footprint(got, clean, reach);
            }
}
