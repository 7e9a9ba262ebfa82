// The thin-lens truth of a deep image (truth.h) against what it must equal: the tidy
// flatten at zero aperture, the aperture's own shape for a lone point (an expected image
// computed here from blur.h's exact kernel weights, not from the ray walk), a closed-form
// disocclusion at a defocused foreground edge, and its own noise estimate.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <random>

#include <OpenImageIO/imagebufalgo.h>

#include <bokeh/base.h>
#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/truth.h>

#include "test_util.h"

using bokeh::kPi;

namespace {


using Smp   = bokeh_test::DeepSample;
using Pixel = bokeh_test::DeepPixel;

// A deep R, G, B, A, Z, ZBack image over w x h at (x0, y0), display window = data window.
OIIO::ImageBuf framed_deep(int w, int h, const std::vector<Pixel>& px, int x0 = 0, int y0 = 0)
{
    OIIO::ImageBuf buf = bokeh_test::make_deep(w, h, px, false, x0, y0);
    buf.set_full(x0, x0 + w, y0, y0 + h, 0, 1);
    return buf;
}

// Options whose Z is the signed CoC itself (DepthMode::Direct): exact CoCs for the tests.
bokeh::TruthOptions direct_options(int spp)
{
    bokeh::TruthOptions o;
    o.coc.mode = bokeh::DepthMode::Direct;
    o.spp      = spp;
    return o;
}

float px_at(const OIIO::ImageBuf& img, int x, int y, int c)
{
    const OIIO::ROI r = img.roi();
    if (x < r.xbegin || x >= r.xend || y < r.ybegin || y >= r.yend)
        return 0.0f;
    return img.getchannel(x, y, 0, c);
}

// The exact image of a lone opaque white point of CoC c in the cell at the origin. From
// the pixel's centre, the ray through a uniform point of the aperture meets the point's
// depth uniformly over the aperture scaled by c, so pixel d receives the aperture's mass
// inside the unit square at d: blur.h's exact kernel weights (each pixel's area inside the
// shape), the flat defocus's own kernel. From a uniform point of the pixel (TruthPixel::Area),
// that mass is convolved with the overlap of two unit squares (a tent): E(d) = sum over
// the aperture's mass of tent(d - x), the mass taken at 8x resolution (each 1/8 px
// square's area inside the shape) at the squares' centres (midpoint rule; the tent is
// linear inside each square except at its kinks).
std::vector<double> expected_point(const bokeh::Kernel& aperture, float aspect, float coc, int r,
                                   bokeh::TruthPixel start)
{
    const bool area = start == bokeh::TruthPixel::Area;
    const int fine  = area ? 8 : 1;
    bokeh::Kernel k = aperture;
    if (coc < 0.0f && k.shape == bokeh::KernelShape::Opening)
        k.opening = k.opening.point_reflected();
    else if (coc < 0.0f)
        k.rotation_deg += 180.0f;
    k.width_px                 = std::abs(coc) * fine;
    k.height_px                = std::abs(coc) * aspect * fine;
    const bokeh::KernelWeights w = bokeh::kernel_weights(k, 1);
    const int n                = 2 * r + 1;
    std::vector<double> e(size_t(n) * n, 0.0);
    for (int j = -w.ry; j <= w.ry; ++j)
        for (int i = -w.rx; i <= w.rx; ++i) {
            const double m = w.at(i, j);
            if (m == 0.0)
                continue;
            if (!area) {
                if (std::abs(i) <= r && std::abs(j) <= r)
                    e[size_t(j + r) * n + size_t(i + r)] += m;
                continue;
            }
            const double x = double(i) / fine, y = double(j) / fine;
            for (int dy = int(std::floor(y)); dy <= int(std::ceil(y)); ++dy)
                for (int dx = int(std::floor(x)); dx <= int(std::ceil(x)); ++dx) {
                    const double t = std::max(0.0, 1.0 - std::abs(dx - x)) * std::max(0.0, 1.0 - std::abs(dy - y));
                    if (t > 0.0 && std::abs(dx) <= r && std::abs(dy) <= r)
                        e[size_t(dy + r) * n + size_t(dx + r)] += m * t;
                }
        }
    return e;
}

// A lone opaque white point of CoC `coc` at pixel (c, c) of an n x n image.
OIIO::ImageBuf lone_point(int n, float coc)
{
    std::vector<Pixel> px(size_t(n) * n);
    px[size_t(n / 2) * n + size_t(n / 2)] = { { 1, 1, 1, 1, coc, coc } };
    return framed_deep(n, n, px);
}

// A random scene: points and volumes, alpha 0 and 1 among them, up to 4 samples a pixel.
OIIO::ImageBuf random_scene(int w, int h, uint32_t seed, int x0 = 0, int y0 = 0, float depth_scale = 1.0f)
{
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<Pixel> px(size_t(w) * h);
    for (auto& p : px) {
        const int n = int(u(rng) * 5.0f);
        for (int s = 0; s < n; ++s) {
            const float a  = s == 0 && u(rng) < 0.2f ? 1.0f : u(rng) < 0.1f ? 0.0f : u(rng);
            const float z  = (1.0f + 9.0f * u(rng)) * depth_scale;
            const float zb = u(rng) < 0.5f ? z : z + 3.0f * u(rng) * depth_scale;
            p.push_back({ a * u(rng), a * u(rng), a * u(rng) + (a == 0.0f ? 0.05f : 0.0f), a, z, zb });
        }
    }
    return framed_deep(w, h, px, x0, y0);
}

double rms_difference(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b, int dx = 0, int dy = 0)
{
    // b's pixel (x + dx, y + dy) against a's (x, y), over the union of their windows.
    const OIIO::ROI ra = a.roi(), rb = b.roi();
    OIIO::ROI u = ra;
    u.xbegin    = std::min(ra.xbegin, rb.xbegin - dx);
    u.xend      = std::max(ra.xend, rb.xend - dx);
    u.ybegin    = std::min(ra.ybegin, rb.ybegin - dy);
    u.yend      = std::max(ra.yend, rb.yend - dy);
    double sq   = 0.0;
    int64_t n   = 0;
    for (int y = u.ybegin; y < u.yend; ++y)
        for (int x = u.xbegin; x < u.xend; ++x)
            for (int c = 0; c < 4; ++c) {
                const double d = px_at(a, x, y, c) - px_at(b, x + dx, y + dy, c);
                sq += d * d;
                ++n;
            }
    return std::sqrt(sq / double(n));
}

// The lens of the foreground-edge tests: 50 mm f/2 on a 2 mm wide back, depth in mm,
// focused at 1000, 1024 rays a pixel; over 64 px, depth 700 has a CoC of about -18 px.
bokeh::TruthOptions edge_lens()
{
    bokeh::TruthOptions o;
    o.coc.lens.focal_mm        = 50.0;
    o.coc.lens.fstop           = 2.0;
    o.coc.lens.sensor_width_mm = 2.0;
    o.coc.lens.depth_unit_mm   = 1.0;
    o.coc.lens.focus_distance  = 1000.0;
    o.spp                      = 1024;
    return o;
}

// The share of pixel x's rays that miss an opaque card covering x < edge at CoC c < 0 and
// reach focus at their own pixel: the rays from P = x + a through aperture offset s meet
// the card's depth at P - s c and miss it where P.x - s.x c >= edge. The disk (radius 1/2)
// beyond a chord at s.x = t: (acos(2t) - 2t sqrt(1 - 4t^2)) / pi, at a = 1/2 (rays from the
// pixel's centre) or averaged over a in [0, 1) (from its area).
double missed_card(int x, int edge, double c, bokeh::TruthPixel start = bokeh::TruthPixel::Centre)
{
    auto segment = [](double t) {
        const double q = std::clamp(2.0 * t, -1.0, 1.0);
        return (std::acos(q) - q * std::sqrt(1.0 - q * q)) / kPi;
    };
    if (start == bokeh::TruthPixel::Centre)
        return segment((edge - (x + 0.5)) / -c);
    double share         = 0.0;
    constexpr int kSteps = 1000;
    for (int i = 0; i < kSteps; ++i)
        share += segment((edge - (x + (i + 0.5) / kSteps)) / -c) / kSteps;
    return share;
}

// A pixel's coverage of the half-plane x >= edge: the render's box-filtered alpha.
double coverage(int x, double edge)
{
    return std::clamp(x + 1.0 - edge, 0.0, 1.0);
}

// The physics of a sharp edge: a camera pixel x (its area [x, x + 1)) through a disk
// aperture of CoC c sees the opaque half-plane x >= edge in the share of its rays
// (s.x + v) >= edge, v the disk's horizontal offset: the segment law, over the pixel.
double edge_through_lens(int x, double edge, double c)
{
    auto beyond = [&](double t) {  // P(v >= t) for v the x-offset of a uniform disk of radius |c| / 2
        const double q = std::clamp(t / (0.5 * std::abs(c)), -1.0, 1.0);
        return (std::acos(q) - q * std::sqrt(1.0 - q * q)) / kPi;
    };
    double share         = 0.0;
    constexpr int kSteps = 2000;
    for (int i = 0; i < kSteps; ++i)
        share += beyond(edge - (x + (i + 0.5) / kSteps)) / kSteps;
    return share;
}

}  // namespace

// The sampler covers the aperture with uniform density: a 1024 x 1024 grid of the unit
// square, mapped and binned at 48 px, against blur.h's exact area weights of the same
// shape (the orientation of odd polygons included); its area in closed form.
TEST(Truth, ApertureSamplerIsAreaUniform)
{
    struct Case {
        bokeh::KernelShape shape;
        int blades;
        float rotation, curvature, hole, aspect, inner = 0.0f;  // inner: a star's (Opening)
    };
    const Case cases[] = {
        { bokeh::KernelShape::Disk, 6, 0, 0, 0, 1 },       { bokeh::KernelShape::Disk, 6, 0, 0, 0.4f, 1.5f },
        { bokeh::KernelShape::Polygon, 5, 10, 0, 0, 1 },   { bokeh::KernelShape::Polygon, 3, 0, 0, 0, 1 },
        { bokeh::KernelShape::Polygon, 6, 0, 0.5f, 0.3f, 0.7f }, { bokeh::KernelShape::Polygon, 9, 33, 0.2f, 0, 2 },
        { bokeh::KernelShape::Opening, 5, 0, 0, 0, 1, 0.45f },  { bokeh::KernelShape::Opening, 7, 20, 0, 0, 1.4f, 0.7f },
    };
    for (const Case& c : cases) {
        bokeh::Kernel k;
        k.shape        = c.shape;
        k.blades       = c.blades;
        k.rotation_deg = c.rotation;
        k.curvature    = c.curvature;
        k.hole         = c.hole;
        std::string err;
        if (c.shape == bokeh::KernelShape::Opening) {
            ASSERT_TRUE(bokeh::Aperture::star(c.blades, c.inner, c.rotation, k.opening, err)) << err;
        }
        bokeh::Aperture opening;
        ASSERT_TRUE(bokeh::Aperture::from_kernel(k, opening, err)) << err;
        const bokeh::ApertureSampler sampler(opening, c.aspect);
        constexpr float kSize = 48.0f;
        k.width_px            = kSize;
        k.height_px           = kSize * c.aspect;
        const bokeh::KernelWeights w = bokeh::kernel_weights(k, 1);
        std::vector<double> hist(w.w.size(), 0.0);
        constexpr int kGrid = 1024;
        int64_t outside     = 0;
        for (int j = 0; j < kGrid; ++j)
            for (int i = 0; i < kGrid; ++i) {
                const auto s = sampler((i + 0.5) / kGrid, (j + 0.5) / kGrid);
                const int x = int(std::lround(s[0] * kSize)), y = int(std::lround(s[1] * kSize));
                if (std::abs(x) > w.rx || std::abs(y) > w.ry || w.at(x, y) == 0.0) {
                    ++outside;
                    continue;
                }
                hist[size_t((y + w.ry) * (2 * w.rx + 1) + (x + w.rx))] += 1.0 / (double(kGrid) * kGrid);
            }
        // Points in pixels the weights give 0: slivers of the shape that none of the 64 x 64
        // samples blur.h takes in a boundary pixel catches; counted as error.
        double l1 = double(outside) / (double(kGrid) * kGrid);
        for (size_t i = 0; i < hist.size(); ++i)
            l1 += std::abs(hist[i] - w.w[i]);
        std::cout << "blades " << c.blades << " curvature " << c.curvature << " hole " << c.hole << " aspect "
                  << c.aspect << ": L1 " << l1 << ", outside " << outside << "\n";
        EXPECT_LT(outside, 300);
        EXPECT_LT(l1, 0.015) << "blades " << c.blades;
        // The areas in closed form: a polygon's N triangles (N/2 sin(2 pi / N)); a star's 2N
        // triangles between an outer vertex (1) and an inner one (rho) pi/N apart (N rho
        // sin(pi / N)), whose sum the sampler and Aperture::area integrate at 8192 angles.
        double area = kPi;
        if (c.shape == bokeh::KernelShape::Polygon && c.curvature == 0.0f)
            area = 0.5 * c.blades * std::sin(2.0 * kPi / c.blades);
        if (c.shape == bokeh::KernelShape::Opening)
            area = c.blades * c.inner * std::sin(kPi / c.blades);
        const double tol = c.shape == bokeh::KernelShape::Opening ? 1e-6 * area : 1e-9;
        if (c.curvature == 0.0f) {
            EXPECT_NEAR(sampler.area(), area * 0.25 * c.aspect * (1.0 - double(c.hole) * c.hole), tol);
            EXPECT_NEAR(opening.area(), area * (1.0 - double(c.hole) * c.hole), tol * 4.0 / c.aspect);
        }
    }
}

// With a zero aperture (every CoC 0: the CoC limit 0, or both gains 0) every ray stays
// in its pixel's cell and meets all of its samples: the tidy flatten, to float rounding
// (the mean of identical rays in double, and rays stop once 2^-25 of the light is left).
TEST(Truth, ZeroApertureEqualsTidyFlatten)
{
    const OIIO::ImageBuf deep = random_scene(23, 17, 7, 3, -2);
    OIIO::ImageBuf tidy, flat;
    ASSERT_TRUE(bokeh::deep_tidy(tidy, deep));
    ASSERT_TRUE(bokeh::deep_flatten(flat, tidy));
    for (int variant = 0; variant < 2; ++variant) {
        bokeh::TruthOptions o;
        o.coc.lens.focus_distance = 5.0;
        o.coc.lens.depth_unit_mm  = 1000.0;
        o.coc.lens.fstop          = 1.4;
        if (variant == 0)
            o.coc.max_coc_px = 0.0;
        else
            o.coc.front_gain = o.coc.back_gain = 0.0;
        o.spp = 16;
        OIIO::ImageBuf out;
        bokeh::TruthReport rep;
        ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, &rep, 2)) << out.geterror();
        EXPECT_EQ(out.roi().xbegin, deep.roi().xbegin);
        EXPECT_EQ(out.roi().xend, deep.roi().xend);
        EXPECT_EQ(out.roi().ybegin, deep.roi().ybegin);
        EXPECT_EQ(out.roi().yend, deep.roi().yend);
        double worst = 0.0;
        for (int y = flat.roi().ybegin; y < flat.roi().yend; ++y)
            for (int x = flat.roi().xbegin; x < flat.roi().xend; ++x)
                for (int c = 0; c < 4; ++c) {
                    const double f = flat.getchannel(x, y, 0, c), t = out.getchannel(x, y, 0, c);
                    worst          = std::max(worst, std::abs(f - t) / std::max(1.0, std::abs(f)));
                }
        std::cout << "zero aperture: largest difference from the tidy flatten " << worst << ", noise "
                  << rep.noise_rmse << "\n";
        EXPECT_LE(worst, 1.2e-7);
        EXPECT_EQ(rep.noise_rmse, 0.0);  // identical rays: the two halves agree exactly
    }
}

// A lone opaque point renders as the aperture of diameter |CoC| (point-reflected in
// front of focus), its energy kept, the image the exact expected one within the render's
// own noise. From the pixels' centres that is the flat defocus's own kernel; from their
// area it is that kernel with a second 1-px box (its edge a pixel softer), the two agreeing
// in energy and centre.
TEST(Truth, LonePointIsTheAperture)
{
    struct Case {
        bokeh::KernelShape shape;
        int blades;
        float rotation, curvature, hole, aspect, coc, inner = 0.0f;  // inner: a star's (Opening)
    };
    const Case cases[] = {
        { bokeh::KernelShape::Disk, 6, 0, 0, 0, 1, 14.0f },
        { bokeh::KernelShape::Polygon, 3, 0, 0, 0, 1, -15.0f },
        { bokeh::KernelShape::Polygon, 5, 20, 0.3f, 0.35f, 1.5f, 13.0f },
        { bokeh::KernelShape::Opening, 5, 10, 0, 0, 1.2f, -16.0f, 0.5f },
    };
    constexpr int kN = 41, kR = 14;
    for (const bokeh::TruthPixel start : { bokeh::TruthPixel::Centre, bokeh::TruthPixel::Area })
    for (const Case& c : cases) {
        bokeh::TruthOptions o = direct_options(4096);
        o.pixel                 = start;
        o.aperture.shape        = c.shape;
        o.aperture.blades       = c.blades;
        o.aperture.rotation_deg = c.rotation;
        o.aperture.curvature    = c.curvature;
        o.aperture.hole         = c.hole;
        if (c.shape == bokeh::KernelShape::Opening) {
            std::string err;
            ASSERT_TRUE(bokeh::Aperture::star(c.blades, c.inner, c.rotation, o.aperture.opening, err)) << err;
        }
        o.aspect                = c.aspect;
        o.grow                  = false;
        OIIO::ImageBuf out;
        bokeh::TruthReport rep;
        ASSERT_TRUE(bokeh::defocus_truth(out, lone_point(kN, c.coc), o, &rep, 2)) << out.geterror();
        const std::vector<double> e    = expected_point(o.aperture, c.aspect, c.coc, kR, start);
        const std::vector<double> flip = expected_point(o.aperture, c.aspect, -c.coc, kR, start);  // point-reflected
        bokeh::Kernel k = o.aperture;
        if (c.coc < 0 && c.shape == bokeh::KernelShape::Opening)
            k.opening = k.opening.point_reflected();
        else
            k.rotation_deg += c.coc < 0 ? 180.0f : 0.0f;
        k.width_px  = std::abs(c.coc);
        k.height_px = std::abs(c.coc) * c.aspect;
        const bokeh::KernelWeights flat = bokeh::kernel_weights(k, 1);
        double energy = 0.0, sq = 0.0, sq_flip = 0.0, mx = 0.0, my = 0.0, fx = 0.0, fy = 0.0, l1_flat = 0.0;
        for (int dy = -kR; dy <= kR; ++dy)
            for (int dx = -kR; dx <= kR; ++dx) {
                const double t = px_at(out, kN / 2 + dx, kN / 2 + dy, 3);
                EXPECT_EQ(t, px_at(out, kN / 2 + dx, kN / 2 + dy, 0));  // white: R = A
                const double ex = e[size_t(dy + kR) * (2 * kR + 1) + size_t(dx + kR)];
                const double ef = flip[size_t(dy + kR) * (2 * kR + 1) + size_t(dx + kR)];
                const double w  = std::abs(dx) <= flat.rx && std::abs(dy) <= flat.ry ? flat.at(dx, dy) : 0.0;
                energy += t;
                sq += (t - ex) * (t - ex);
                sq_flip += (t - ef) * (t - ef);
                l1_flat += std::abs(t - w);
                mx += t * dx;
                my += t * dy;
                fx += w * dx;
                fy += w * dy;
            }
        const double n   = double(2 * kR + 1) * (2 * kR + 1);
        const double rms = std::sqrt(sq / n), rms_flip = std::sqrt(sq_flip / n);
        // The noise estimate is per value over the whole output; the point's values are
        // all in the window compared, where R = G = B = A.
        const double noise = rep.noise_rmse * std::sqrt(double(out.roi().npixels()) / n);
        std::cout << (start == bokeh::TruthPixel::Area ? "area" : "centre") << ", blades " << c.blades << " coc "
                  << c.coc << ": energy " << energy << ", RMS from expected "
                  << rms << " (noise " << noise << "), from the point-reflected " << rms_flip << ", L1 from the flat "
                  << "kernel " << l1_flat << ", centre (" << mx << ", " << my << ") vs (" << fx << ", " << fy << ")\n";
        // The energy is a sum over the footprint of values whose noise is independent from
        // pixel to pixel: its noise is the values' times sqrt(count). The centre weighs the
        // rim's pixels, the noisiest, most: its scatter over 8 seeds, the first three cases and
        // both starts was 0.024 px RMS, 0.060 px at most; 0.1 px is allowed.
        const double n_in = double(std::count_if(e.begin(), e.end(), [](double v) { return v > 0.0; }));
        const double sigma_energy = noise * std::sqrt(n_in);
        constexpr double kCentreScatterPx = 0.1;
        EXPECT_NEAR(energy, 1.0, 4.0 * sigma_energy);
        EXPECT_LT(rms, 1.5 * noise + 2e-6);
        if (c.blades % 2 == 1 && c.shape != bokeh::KernelShape::Disk) {
            EXPECT_GT(rms_flip, 2.0 * rms) << "orientation";
        }
        EXPECT_NEAR(mx, fx, kCentreScatterPx);
        EXPECT_NEAR(my, fy, kCentreScatterPx);
        // From the centre the flat kernel is the expected image (L1 0.04-0.06 measured, the
        // noise); from the area it is a pixel softer (0.09-0.12).
        EXPECT_LT(l1_flat, start == bokeh::TruthPixel::Centre ? 0.08 : 0.15);
    }
}

// The energy of a lone point with many rays: 65536 a pixel over a CoC of 6 px. Each
// pixel's value is an independent estimate, so the energy's noise is the values' noise
// times sqrt(pixels): about 1.4e-3 here (4 sigma allowed; 2e-4 and 7e-4 measured).
TEST(Truth, LonePointKeepsEnergy)
{
    for (float coc : { 6.0f, -5.0f }) {
        bokeh::TruthOptions o = direct_options(65536);
        o.aperture.shape      = bokeh::KernelShape::Polygon;
        o.aperture.blades     = 7;
        o.grow                = false;
        OIIO::ImageBuf out;
        bokeh::TruthReport rep;
        ASSERT_TRUE(bokeh::defocus_truth(out, lone_point(11, coc), o, &rep, 2)) << out.geterror();
        double energy = 0.0;
        for (int y = 0; y < 11; ++y)
            for (int x = 0; x < 11; ++x)
                energy += out.getchannel(x, y, 0, 3);
        const double sigma = rep.noise_rmse * 11.0;
        std::cout << "coc " << coc << ": energy " << energy << " (noise " << sigma << "), " << rep.seconds << " s\n";
        EXPECT_LT(sigma, 1.6e-3);
        EXPECT_NEAR(energy, 1.0, 4.0 * sigma);
    }
}

// Moving the deep image moves the truth: the same pixels within the two renders' noise
// (per-pixel seeds come from absolute coordinates, so the noise itself does not move).
TEST(Truth, TranslationEquivariant)
{
    const OIIO::ImageBuf a = random_scene(30, 20, 11, 0, 0, 4.0f);
    const OIIO::ImageBuf b = random_scene(30, 20, 11, 7, -3, 4.0f);
    bokeh::TruthOptions o  = direct_options(64);
    OIIO::ImageBuf ta, tb, tc;
    bokeh::TruthReport ra, rb, rc;
    ASSERT_TRUE(bokeh::defocus_truth(ta, a, o, &ra, 2));
    ASSERT_TRUE(bokeh::defocus_truth(tb, b, o, &rb, 2));
    o.seed = 99;
    ASSERT_TRUE(bokeh::defocus_truth(tc, a, o, &rc, 2));
    EXPECT_EQ(tb.roi().xbegin, ta.roi().xbegin + 7);
    EXPECT_EQ(tb.roi().ybegin, ta.roi().ybegin - 3);
    EXPECT_EQ(tb.roi().width(), ta.roi().width());
    const double moved = rms_difference(ta, tb, 7, -3), reseeded = rms_difference(ta, tc);
    const double expect = std::sqrt(ra.noise_rmse * ra.noise_rmse + rb.noise_rmse * rb.noise_rmse);
    std::cout << "moved: RMS " << moved << ", another seed: " << reseeded << ", noise estimates " << expect << "\n";
    EXPECT_LT(moved, 1.3 * expect);
    EXPECT_GT(moved, 0.7 * expect);
    EXPECT_NEAR(moved, reseeded, 0.2 * reseeded);
}

// The noise estimate falls at least as 1 / sqrt(spp) and says what the render's error
// against a 64x longer render is.
TEST(Truth, NoiseFallsAndIsHonest)
{
    const OIIO::ImageBuf deep = random_scene(32, 24, 5, 0, 0, 3.0f);
    bokeh::TruthOptions o     = direct_options(16);
    o.aperture.shape          = bokeh::KernelShape::Polygon;
    o.aperture.blades         = 5;
    std::vector<double> noise;
    OIIO::ImageBuf at64;
    for (int spp : { 16, 64, 256 }) {
        o.spp = spp;
        OIIO::ImageBuf out;
        bokeh::TruthReport rep;
        ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, &rep, 2));
        noise.push_back(rep.noise_rmse);
        std::cout << spp << " spp: noise " << rep.noise_rmse << " (" << rep.noise_psnr_db << " dB)\n";
        if (spp == 64)
            at64 = out;
    }
    EXPECT_LT(noise[1], 0.5 * noise[0] * 1.15);
    EXPECT_LT(noise[2], 0.5 * noise[1] * 1.15);
    o.spp  = 4096;
    o.seed = 1234;
    OIIO::ImageBuf ref;
    bokeh::TruthReport rr;
    ASSERT_TRUE(bokeh::defocus_truth(ref, deep, o, &rr, 2));
    const double actual = rms_difference(at64, ref);
    const double said   = std::sqrt(noise[1] * noise[1] + rr.noise_rmse * rr.noise_rmse);
    std::cout << "64 spp against 4096: RMS " << actual << ", estimated " << said << "\n";
    EXPECT_GT(actual, 0.75 * said);
    EXPECT_LT(actual, 1.33 * said);
}

// Rays from the pixel's centre are nearer the physics than rays from its area. A render's
// deep pixel holds its area's coverage (its alpha the box-filtered edge); a camera pixel
// behind a lens sees the edge through the disk once over its own area. Starting the rays
// over the pixel's area as well filters by the pixel twice. Measured over 16 sub-pixel
// phases of a vertical edge at CoC 3 px, 8192 rays a pixel, the 7 pixels around the edge:
// RMS from the physics 0.0097 from the centre, 0.0155 from the area.
TEST(Truth, RaysFromThePixelsCentreAreNearerTheLens)
{
    // Each phase fills 5 rows, its middle row measured: the rays (radius 1.5 px) stay
    // within the phase's own rows.
    constexpr int kW = 20, kPhases = 16, kRows = 5, kH = kPhases * kRows;
    constexpr float kCoc = 3.0f;
    std::vector<Pixel> px(size_t(kW) * kH);
    auto edge_of_row = [&](int y) { return kW / 2 + (y / kRows + 0.5) / kPhases; };
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const float a = float(coverage(x, edge_of_row(y)));
            if (a > 0.0f)
                px[size_t(y) * kW + x] = { { a, a, a, a, kCoc, kCoc } };
        }
    const OIIO::ImageBuf deep = framed_deep(kW, kH, px);
    double rms[2]             = {};
    for (const bokeh::TruthPixel start : { bokeh::TruthPixel::Centre, bokeh::TruthPixel::Area }) {
        bokeh::TruthOptions o = direct_options(8192);
        o.pixel               = start;
        o.grow                = false;
        OIIO::ImageBuf out;
        ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, nullptr, 2)) << out.geterror();
        double sq = 0.0;
        int n     = 0;
        for (int y = kRows / 2; y < kH; y += kRows)
            for (int x = kW / 2 - 3; x <= kW / 2 + 3; ++x, ++n) {
                const double d = out.getchannel(x, y, 0, 3) - edge_through_lens(x, edge_of_row(y), kCoc);
                sq += d * d;
            }
        rms[start == bokeh::TruthPixel::Area] = std::sqrt(sq / n);
    }
    std::cout << "RMS from the lens's physics: rays from the centre " << rms[0] << ", from the area " << rms[1] << "\n";
    EXPECT_LT(rms[0], 0.8 * rms[1]);
    EXPECT_LT(rms[0], 0.012);
}

// A solid surface seen at a grazing angle has no cracks: a plane whose CoC climbs 0.4 px a
// pixel (opaque red, from CoC -12 to +3.6) over a recorded green wall at CoC +6. Each of
// its pixels is a thin tile at its own depth, and a ray crossing from one pixel to the next
// between two tiles' depths would reach the wall; the plane's opaque points are met over
// half the CoC gap to their neighbours (truth.cpp, kConnectedCocPx), so no ray passes.
// Measured with every tile a point: green up to 0.098 inside the plane, a tenth of the
// rays; joined, exactly 0. With nothing behind the plane, a crack would show as alpha
// below 1 and as `unknown`; a plane of alpha 0.99 is not a solid surface and keeps its
// cracks.
TEST(Truth, ASteepOpaqueSurfaceHasNoCracks)
{
    constexpr int kW = 40, kH = 16;
    // behind: the green wall, or nothing (the rays through a crack then meet space the file
    // does not record). slope_alpha: 1, or 0.99, which is a partly transparent sample, not a
    // tile of a solid surface, and stays a point.
    auto render = [&](bool wall, float slope_alpha, OIIO::ImageBuf& out) {
        std::vector<Pixel> px(size_t(kW) * kH);
        for (int y = 0; y < kH; ++y)
            for (int x = 0; x < kW; ++x) {
                const float c = -12.0f + 0.4f * x, a = slope_alpha;
                Pixel& p      = px[size_t(y) * kW + x];
                p             = { { a, 0, 0, a, c, c } };
                if (wall)
                    p.push_back({ 0, 1, 0, 1, 6, 6 });
            }
        bokeh::TruthOptions o = direct_options(256);
        o.grow                = false;
        o.unknown             = true;
        return bokeh::defocus_truth(out, framed_deep(kW, kH, px), o, nullptr, 2);
    };
    struct Worst {
        double green = 0.0, unknown = 0.0, alpha = 0.0;
    };
    auto inside = [&](const OIIO::ImageBuf& out) {
        Worst w;
        for (int x = 8; x < kW - 8; ++x) {  // rays within the frame: |CoC| / 2 <= 6 px
            w.green   = std::max(w.green, double(out.getchannel(x, kH / 2, 0, 1)));
            w.unknown = std::max(w.unknown, double(out.getchannel(x, kH / 2, 0, 4)));
            w.alpha   = std::max(w.alpha, std::abs(1.0 - out.getchannel(x, kH / 2, 0, 3)));
        }
        return w;
    };
    OIIO::ImageBuf walled, bare, translucent;
    ASSERT_TRUE(render(true, 1.0f, walled)) << walled.geterror();
    ASSERT_TRUE(render(false, 1.0f, bare)) << bare.geterror();
    ASSERT_TRUE(render(true, 0.99f, translucent)) << translucent.geterror();
    const Worst w = inside(walled), b = inside(bare), t = inside(translucent);
    std::cout << "inside the plane: green at most " << w.green << "; with nothing behind it, alpha off 1 by " << b.alpha
              << ", unknown " << b.unknown << "; alpha 0.99, green " << t.green << "\n";
    EXPECT_EQ(w.green, 0.0);
    EXPECT_LT(w.alpha, 1e-6);
    EXPECT_LT(b.alpha, 1e-6);  // no ray leaves through the plane
    EXPECT_EQ(b.unknown, 0.0);
    EXPECT_GT(t.green, 0.01);  // a partly transparent slope is not joined: its cracks stay
}

// Two opaque surfaces side by side, the right one's CoC higher by a step, over a recorded
// green wall at CoC +4: rays that cross from the right surface's pixels to the left one's
// between their two depths meet neither. A step of at most 1 px (kConnectedCocPx) is taken
// for one surface's slope and joined: no green; a step of 1.5 px is two surfaces, and the
// wall shows between them. Measured: green 0 at 0.8 px; up to 0.089 at 1.5 px.
TEST(Truth, OnlyCloseDepthsAreJoined)
{
    constexpr int kW = 32, kH = 16, kStepAt = kW / 2;
    auto greenest = [&](float step) {
        std::vector<Pixel> px(size_t(kW) * kH);
        for (int y = 0; y < kH; ++y)
            for (int x = 0; x < kW; ++x) {
                const float c            = x < kStepAt ? -6.0f : -6.0f + step;
                px[size_t(y) * kW + x] = { { 1, 0, 0, 1, c, c }, { 0, 1, 0, 1, 4, 4 } };
            }
        bokeh::TruthOptions o = direct_options(1024);
        o.grow                = false;
        OIIO::ImageBuf out;
        EXPECT_TRUE(bokeh::defocus_truth(out, framed_deep(kW, kH, px), o, nullptr, 2)) << out.geterror();
        double g = 0.0;
        for (int x = kStepAt - 3; x < kStepAt + 3; ++x)
            g = std::max(g, double(out.getchannel(x, kH / 2, 0, 1)));
        return g;
    };
    const double joined = greenest(0.8f), apart = greenest(1.5f);
    std::cout << "green at the step: " << joined << " (0.8 px), " << apart << " (1.5 px)\n";
    EXPECT_EQ(joined, 0.0);
    EXPECT_GT(apart, 0.01);
}

// From the pixels' centres, a CoC below 1 px keeps every ray in its own pixel's cell (the
// aperture's offset at most half the CoC): the result is the tidy flatten, as at a zero
// aperture, whatever the samples' reach.
TEST(Truth, SubPixelCocsFromTheCentreAreTheFlatten)
{
    const OIIO::ImageBuf deep = random_scene(23, 17, 11, 0, 0, 0.07f);  // CoCs 0.07 .. 0.91 px
    OIIO::ImageBuf tidy, flat, out;
    ASSERT_TRUE(bokeh::deep_tidy(tidy, deep));
    ASSERT_TRUE(bokeh::deep_flatten(flat, tidy));
    bokeh::TruthOptions o = direct_options(64);
    o.grow                = false;
    ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, nullptr, 2)) << out.geterror();
    double worst = 0.0;
    for (int y = 0; y < 17; ++y)
        for (int x = 0; x < 23; ++x)
            for (int c = 0; c < 4; ++c) {
                const double f = flat.getchannel(x, y, 0, c);
                worst          = std::max(worst, std::abs(out.getchannel(x, y, 0, c) - f) / std::max(1.0, std::abs(f)));
            }
    std::cout << "CoC below 1 px from the centre: largest difference from the tidy flatten " << worst << "\n";
    EXPECT_LE(worst, 1.2e-7);
}

// A sharp background behind a defocused foreground edge: the foreground's blur thins out
// and the rays passing it see the background that was rendered behind it (green, which no
// pixel of the flattened image shows), in the amount the disk's segment gives; the flat
// defocus of the flattened image cannot show it.
TEST(Truth, RevealsHiddenBackground)
{
    constexpr int kW = 64, kH = 24, kEdge = 32;
    std::vector<Pixel> px(size_t(kW) * kH);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            Pixel& p = px[size_t(y) * kW + x];
            if (x < kEdge)
                p = { { 1, 0, 0, 1, 700, 700 }, { 0, 1, 0, 1, 1000, 1000 } };  // red over hidden green
            else
                p = { { 0, 0, 1, 1, 1000, 1000 } };  // visible blue
        }
    const OIIO::ImageBuf deep = framed_deep(kW, kH, px);
    const bokeh::TruthOptions o = edge_lens();
    const double c              = bokeh::thin_lens_coc_px(o.coc.lens, 700.0, kW);  // about -18 px
    OIIO::ImageBuf out;
    bokeh::TruthReport rep;
    ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, &rep, 2)) << out.geterror();
    // Expected green at pixel x: the share of its rays that miss the red card and meet
    // the background at their own pixel (CoC 0), green there.
    double worst = 0.0;
    for (int x = kEdge - 12; x < kEdge; ++x) {
        const double expected = missed_card(x, kEdge, c);
        const double g        = out.getchannel(x, kH / 2, 0, 1);
        worst          = std::max(worst, std::abs(g - expected));
        if (x >= kEdge - 3)
            std::cout << "x " << x << ": green " << g << ", expected " << expected << "\n";
        if (x == kEdge - 2) {
            EXPECT_GT(g, 0.3);
        }
    }
    std::cout << "largest green error " << worst << " (noise " << rep.noise_rmse << ")\n";
    EXPECT_LT(worst, 0.02);
    // The flat image holds no green; neither does its flat defocus.
    OIIO::ImageBuf flat, flat_out;
    ASSERT_TRUE(bokeh::deep_flatten(flat, deep));
    bokeh::DefocusOptions d;
    d.coc    = o.coc;
    d.method = bokeh::DefocusMethod::Reference;
    ASSERT_TRUE(bokeh::defocus(flat_out, flat, d)) << flat_out.geterror();
    float flat_green = 0.0f;
    for (int x = kEdge - 12; x < kEdge; ++x)
        flat_green = std::max(flat_green, flat_out.getchannel(x, kH / 2, 0, 1));
    EXPECT_EQ(flat_green, 0.0f);
}

// The `unknown` channel: the share of a pixel's rays that cross space the file does not
// record. The scene above without its hidden green: an opaque red card (CoC about -18 px)
// over the left half, the blue wall at focus on the right only. A ray from a left pixel
// that misses the card goes on behind the card's pixels, where nothing is recorded: its
// share is the closed form of the test above, and those rays see nothing (alpha 1 - it).
// A right pixel's rays either meet the card or stay over the wall: 0, exactly. Rays that
// start past the frame's edge (the card's blur reaches 9 px) count too. RGBA is the same
// bits with the channel or without.
TEST(Truth, UnknownIsTheShareOfRaysBehindWhatTheFileHides)
{
    constexpr int kW = 64, kH = 24, kEdge = 32;
    std::vector<Pixel> px(size_t(kW) * kH);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x)
            px[size_t(y) * kW + x] = x < kEdge ? Pixel{ { 1, 0, 0, 1, 700, 700 } } : Pixel{ { 0, 0, 1, 1, 1000, 1000 } };
    const OIIO::ImageBuf deep = framed_deep(kW, kH, px);
    bokeh::TruthOptions o     = edge_lens();
    o.unknown                 = true;
    OIIO::ImageBuf out, plain;
    ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, nullptr, 2)) << out.geterror();
    ASSERT_EQ(out.nchannels(), 5);
    EXPECT_EQ(out.spec().channel_name(4), "unknown");
    bokeh::TruthOptions without = o;
    without.unknown             = false;
    ASSERT_TRUE(bokeh::defocus_truth(plain, deep, without, nullptr, 2)) << plain.geterror();
    ASSERT_EQ(plain.nchannels(), 4);
    for (int y = out.roi().ybegin; y < out.roi().yend; ++y)
        for (int x = out.roi().xbegin; x < out.roi().xend; ++x)
            for (int c = 0; c < 4; ++c) {
                ASSERT_EQ(out.getchannel(x, y, 0, c), plain.getchannel(x, y, 0, c)) << x << "," << y;
            }

    const double c = bokeh::thin_lens_coc_px(o.coc.lens, 700.0, kW);
    double worst = 0.0, worst_alpha = 0.0;
    for (int x = kEdge - 8; x < kEdge; ++x) {
        const double expected = missed_card(x, kEdge, c);
        const double u = out.getchannel(x, kH / 2, 0, 4), a = out.getchannel(x, kH / 2, 0, 3);
        worst          = std::max(worst, std::abs(u - expected));
        worst_alpha    = std::max(worst_alpha, std::abs(a - (1.0 - expected)));
        if (x == kEdge - 1) {
            EXPECT_GT(u, 0.3);
        }
    }
    std::cout << "unknown: largest error against the closed form " << worst << ", alpha's " << worst_alpha << "\n";
    EXPECT_LT(worst, 0.02);
    EXPECT_LT(worst_alpha, 0.02);
    for (int x = kEdge; x < kW - 12; ++x)
        EXPECT_EQ(out.getchannel(x, kH / 2, 0, 4), 0.0f) << "x " << x;
    EXPECT_GT(out.getchannel(1, kH / 2, 0, 4), 0.2f);  // its rays start past the left edge
}

// Per-pixel seeds and fixed chunks: the same bits for 1 and 2 threads.
TEST(Truth, SameBitsForAnyThreadCount)
{
    const OIIO::ImageBuf deep = random_scene(40, 30, 3, 0, 0, 4.0f);
    bokeh::TruthOptions o     = direct_options(32);
    OIIO::ImageBuf one, two;
    bokeh::TruthReport r1, r2;
    ASSERT_TRUE(bokeh::defocus_truth(one, deep, o, &r1, 1));
    ASSERT_TRUE(bokeh::defocus_truth(two, deep, o, &r2, 2));
    ASSERT_EQ(one.roi(), two.roi());
    const size_t bytes = size_t(one.roi().npixels()) * 4 * sizeof(float);
    EXPECT_EQ(std::memcmp(one.localpixels(), two.localpixels(), bytes), 0);
    EXPECT_EQ(r1.noise_rmse, r2.noise_rmse);
    EXPECT_EQ(r1.cells_visited, r2.cells_visited);
}

// Volumes: a slab [Z, ZBack) cut by the cells the rays cross composites to the same
// opacity along each ray; a uniform slab over the whole frame stays uniform (every ray
// meets the whole slab, whatever cells it crosses), and matches the flatten inside.
TEST(Truth, VolumeSlabStaysUniform)
{
    constexpr int kN = 24;
    std::vector<Pixel> px(size_t(kN) * kN, Pixel{ { 0.3f, 0.2f, 0.1f, 0.6f, -10.0f, 10.0f } });
    const OIIO::ImageBuf deep = framed_deep(kN, kN, px);
    bokeh::TruthOptions o     = direct_options(64);
    o.grow                    = false;
    OIIO::ImageBuf out, flat;
    ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, nullptr, 2));
    ASSERT_TRUE(bokeh::deep_flatten(flat, deep));
    double worst = 0.0;
    for (int y = 8; y < 16; ++y)
        for (int x = 8; x < 16; ++x)  // rays reach at most 5 px: all inside the slab
            for (int c = 0; c < 4; ++c)
                worst = std::max(worst, double(std::abs(out.getchannel(x, y, 0, c) - flat.getchannel(x, y, 0, c))));
    EXPECT_LT(worst, 1e-6);
}

TEST(Truth, BadInput)
{
    OIIO::ImageBuf out;
    bokeh::TruthOptions o = direct_options(4);
    const OIIO::ImageBuf flat = bokeh_test::rgbaz_image(4, 4, [](int, int) { return std::array<float, 5>{ 1, 1, 1, 1, 1 }; });
    EXPECT_FALSE(bokeh::defocus_truth(out, flat, o));
    EXPECT_NE(out.geterror().find("needs a deep image"), std::string::npos) << out.geterror();

    const OIIO::ImageBuf deep = random_scene(4, 4, 1);
    o.aperture.shape          = bokeh::KernelShape::Box;
    EXPECT_FALSE(bokeh::defocus_truth(out, deep, o));
    EXPECT_NE(out.geterror().find("a disk, a polygon or a star"), std::string::npos) << out.geterror();
    o = direct_options(0);
    EXPECT_FALSE(bokeh::defocus_truth(out, deep, o));
    EXPECT_NE(out.geterror().find("spp 0"), std::string::npos) << out.geterror();

    // Z read backwards (inverse depth on a file whose Z is a distance): refused.
    o          = direct_options(4);
    o.coc.mode = bokeh::DepthMode::InverseDepth;
    o.coc.lens.depth_unit_mm = 1000.0;
    EXPECT_FALSE(bokeh::defocus_truth(out, deep, o));
    EXPECT_NE(out.geterror().find("CoC falls"), std::string::npos) << out.geterror();

    // A NaN depth under the error policy: refused, naming it; under Zero: dropped, counted.
    std::vector<Pixel> px(4, Pixel{ { 1, 1, 1, 1, 2, 2 } });
    px[1] = { { 1, 1, 1, 1, std::nanf(""), std::nanf("") } };
    const OIIO::ImageBuf bad = framed_deep(2, 2, px);
    o                        = direct_options(4);
    o.nonfinite              = bokeh::NonFinitePolicy::Error;
    EXPECT_FALSE(bokeh::defocus_truth(out, bad, o));
    EXPECT_NE(out.geterror().find("depth"), std::string::npos) << out.geterror();
    o.nonfinite = bokeh::NonFinitePolicy::Zero;
    bokeh::TruthReport rep;
    EXPECT_TRUE(bokeh::defocus_truth(out, bad, o, &rep));
    EXPECT_EQ(rep.repairs.nan_depth, 1);
    // Focused at a pixel, the truth flattens the repaired samples to read its depth: the
    // count stays the repair's.
    o.coc.focus_at_pixel = true;
    o.coc.focus_x = o.coc.focus_y = 0;
    rep                  = {};
    EXPECT_TRUE(bokeh::defocus_truth(out, bad, o, &rep)) << out.geterror();
    EXPECT_EQ(rep.repairs.nan_depth, 1);
}

// Gaffer's Arnold render: every sample a volume, up to 227 a pixel, samples of alpha 0
// with colour. At zero aperture the truth is its tidy flatten; focused on its centre
// pixel, the rays cut the volumes at cell boundaries and the render stays finite with
// its alpha within [0, 1].
TEST(Truth, VolumesOfGaffersImage)
{
    const std::string path = bokeh_test::shared_data("gaffer/representativeDeepImage.exr");
    REQUIRE_SHARED(path);
    OIIO::ImageBuf deep(path), tidy, flat;
    ASSERT_TRUE(deep.read(0, 0, true)) << deep.geterror();
    ASSERT_TRUE(bokeh::deep_tidy(tidy, deep));
    ASSERT_TRUE(bokeh::deep_flatten(flat, tidy));
    bokeh::TruthOptions o;
    o.coc.max_coc_px = 0.0;
    o.spp            = 4;
    OIIO::ImageBuf out;
    bokeh::TruthReport rep;
    ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, &rep, 2)) << out.geterror();
    double worst = 0.0;
    for (int y = flat.roi().ybegin; y < flat.roi().yend; ++y)
        for (int x = flat.roi().xbegin; x < flat.roi().xend; ++x)
            for (int c = 0; c < 4; ++c) {
                const double f = flat.getchannel(x, y, 0, c);
                worst = std::max(worst, std::abs(f - out.getchannel(x, y, 0, c)) / std::max(1.0, std::abs(f)));
            }
    std::cout << "zero aperture: largest difference from the tidy flatten " << worst << "\n";
    EXPECT_LE(worst, 1.2e-7);

    o                       = bokeh::TruthOptions{};
    o.coc.lens.focal_mm     = 35.0;
    o.coc.lens.fstop        = 16.0;
    o.coc.lens.depth_unit_mm = 10.0;
    o.coc.focus_at_pixel    = true;
    o.coc.focus_x           = 75;
    o.coc.focus_y           = 50;
    o.spp                   = 16;
    ASSERT_TRUE(bokeh::defocus_truth(out, deep, o, &rep, 2)) << out.geterror();
    std::cout << rep.summary << "\n";
    EXPECT_GT(rep.max_coc_px - rep.min_coc_px, 4.0f);
    float lo = 1.0f, hi = 0.0f;
    for (int y = out.roi().ybegin; y < out.roi().yend; ++y)
        for (int x = out.roi().xbegin; x < out.roi().xend; ++x) {
            for (int c = 0; c < 4; ++c)
                ASSERT_TRUE(std::isfinite(out.getchannel(x, y, 0, c))) << x << "," << y;
            lo = std::min(lo, out.getchannel(x, y, 0, 3));
            hi = std::max(hi, out.getchannel(x, y, 0, 3));
        }
    EXPECT_GE(lo, 0.0f);
    EXPECT_LE(hi, 1.0f + 1e-6f);
}

// A sample at Z = 0 in front of others reads as "no depth" (infinitely far) under the
// depth mode, which contradicts its place in the pixel: refused, saying why.
TEST(Truth, ZeroDepthInFrontIsRefused)
{
    std::vector<Pixel> px(4, Pixel{ { 1, 1, 1, 0.5, 0, 0 }, { 1, 1, 1, 1, 3, 3 } });
    bokeh::TruthOptions o;
    o.coc.lens.focus_distance = 2.0;
    OIIO::ImageBuf out;
    EXPECT_FALSE(bokeh::defocus_truth(out, framed_deep(2, 2, px), o));
    EXPECT_NE(out.geterror().find("no depth"), std::string::npos) << out.geterror();
}

// Progress goes up to 1 in rising steps.
TEST(Truth, ProgressRises)
{
    bokeh::TruthOptions o = direct_options(4);
    std::vector<float> seen;
    o.progress = [&](float f) { seen.push_back(f); };
    OIIO::ImageBuf out;
    ASSERT_TRUE(bokeh::defocus_truth(out, random_scene(20, 40, 2), o, nullptr, 2));
    ASSERT_FALSE(seen.empty());
    EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
    EXPECT_FLOAT_EQ(seen.back(), 1.0f);
}

// A volume cut where the rays leave it: a slab [700, 1600) of alpha 0.8 fills columns
// x < 20, and the CoC is bent away from 1/z by an in-focus range, unequal gains and the
// CoC limit, so the cell boundaries cut the slab at depths the walk must find on the
// shaped curve. Expected alpha at pixel x, integrated here independently: over the disk's
// x offset t (density 2 sqrt(1/4 - t^2) / (pi / 4)), from the pixel's centre P = x + 1/2,
// the share of the slab's depth where the ray is over the slab, P - t c(z) < 20, gives
// the alpha 1 - (1 - 0.8)^share.
TEST(Truth, VolumeCutOnTheShapedCurve)
{
    constexpr int kW = 40, kH = 24, kEdge = 20;
    constexpr float kZ0 = 700.0f, kZ1 = 1600.0f, kAlpha = 0.8f;
    std::vector<Pixel> px(size_t(kW) * kH);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kEdge; ++x)
            px[size_t(y) * kW + x] = { { kAlpha, kAlpha, kAlpha, kAlpha, kZ0, kZ1 } };
    bokeh::TruthOptions o      = edge_lens();
    o.coc.infocus_range        = 200.0;
    o.coc.front_gain           = 0.7;
    o.coc.back_gain            = 1.3;
    o.coc.max_coc_px           = 10.0;
    o.spp                      = 512;  // each cut costs a bisection on the shaped curve
    OIIO::ImageBuf out;
    bokeh::TruthReport rep;
    ASSERT_TRUE(bokeh::defocus_truth(out, framed_deep(kW, kH, px), o, &rep, 2)) << out.geterror();
    std::cout << rep.summary << "\n";
    // The CoC of 20000 depths through the slab (midpoints), from the library's CocOfDepth.
    const bokeh::CocOfDepth coc_of(o.coc, kW);
    constexpr int kZs = 20000, kT = 2000;
    std::vector<double> c(kZs);
    for (int k = 0; k < kZs; ++k)
        c[size_t(k)] = coc_of(kZ0 + (kZ1 - kZ0) * (k + 0.5f) / kZs);
    std::sort(c.begin(), c.end());  // only how many are inside counts
    double worst = 0.0;
    for (int x = kEdge - 7; x < kEdge + 7; ++x) {
        double expected = 0.0, weight = 0.0;
        {
            const double P = x + 0.5;
            for (int j = 0; j < kT; ++j) {
                const double t = -0.5 + (j + 0.5) / kT, w = std::sqrt(0.25 - t * t);
                // Inside where t c > P - 20: c above (P - 20) / t for t > 0, below for t < 0.
                const double bound = (P - kEdge) / t;
                const auto above   = c.end() - std::upper_bound(c.begin(), c.end(), bound);
                const auto below   = std::lower_bound(c.begin(), c.end(), bound) - c.begin();
                const double inside = t > 0.0 ? double(above) : double(below);
                expected += w * (1.0 - std::pow(1.0 - kAlpha, inside / kZs));
                weight += w;
            }
        }
        expected /= weight;
        const double got = out.getchannel(x, kH / 2, 0, 3);
        worst            = std::max(worst, std::abs(got - expected));
        std::cout << "x " << x << ": alpha " << got << ", expected " << expected << "\n";
    }
    // Noise: 1.3e-3 a value at the boundary pixels at 512 rays (the standard deviation of
    // 64 seeds' renders; the frame's mean noise, rep.noise_rmse, is lower, most pixels being
    // 0 or 0.8 exactly); the mean of those 64 renders is within 1.7e-4 of the expected
    // values at x = 20, 21, 24 (1.0, 0.6 and 0.3 of the mean's sigma): no bias.
    EXPECT_LT(worst, 6e-3);
}
