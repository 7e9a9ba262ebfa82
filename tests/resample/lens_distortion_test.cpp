// Lens distortion and lateral colour (distortion.h): round trips of positions, the warp
// against closed forms measured on the image (a circle's radius, a line through the centre,
// a white point's colour fringe), the STMap against OpenImageIO's own interpolation, and
// refusals.
#include <bokeh/distortion.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <set>

#include <OpenImageIO/imagebuf.h>

using namespace bokeh;

namespace {

constexpr int kW = 480, kH = 270;
const double kHalfDiagonal = 0.5 * std::hypot(double(kW), double(kH));

// A kW x kH image, one channel per entry of `names`, each pixel the mean of `fn` over 8 x 8
// points of its square (anti-aliased shapes).
OIIO::ImageBuf shape_image(const std::function<float(double, double)>& fn, std::vector<std::string> names = { "Y" })
{
    OIIO::ImageSpec spec(kW, kH, int(names.size()), OIIO::TypeFloat);
    spec.channelnames = names;
    OIIO::ImageBuf img(spec);
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            double v = 0.0;
            for (int j = 0; j < 8; ++j)
                for (int i = 0; i < 8; ++i)
                    v += fn(x + (i + 0.5) / 8.0, y + (j + 0.5) / 8.0) / 64.0;
            std::vector<float> px(names.size(), float(v));
            img.setpixel(x, y, px.data());
        }
    return img;
}

// The intensity-weighted mean of f(x, y) over channel c of `img` (pixel centres).
double weighted_mean(const OIIO::ImageBuf& img, int c, const std::function<double(double, double)>& f)
{
    double sw = 0.0, s = 0.0;
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const double w = img.getchannel(x, y, 0, c);
            sw += w;
            s += w * f(x + 0.5, y + 0.5);
        }
    return s / sw;
}

OIIO::ImageBuf warp(const OIIO::ImageBuf& src, const LensDistortion& l, DistortDirection d)
{
    OIIO::ImageBuf dst;
    EXPECT_TRUE(lens_distort(dst, src, l, d)) << dst.geterror();
    return dst;
}

}  // namespace

TEST(LensDistortion, PositionsRoundTripWithinAHundredthOfAPixel)
{
    // Over the whole frame of a 1920x1080 plate (half-diagonal 1101 px), both models, barrel
    // and pincushion: undistort(distort(p)) within 0.01 px (measured: below 1e-9 px).
    const double half_diagonal = 0.5 * std::hypot(1920.0, 1080.0);
    double worst_px            = 0.0;
    for (DistortionModel m : { DistortionModel::Polynomial, DistortionModel::Division })
        for (const auto& [k1, k2] : { std::make_pair(-0.2, 0.03), std::make_pair(0.15, -0.02), std::make_pair(-0.05, 0.0) }) {
            LensDistortion l;
            l.model = m, l.k1 = k1, l.k2 = k2;
            std::string err;
            ASSERT_TRUE(check_distortion(l, OIIO::ROI(0, 1920, 0, 1080), err)) << err;
            for (double y = -0.49; y <= 0.49; y += 0.07)
                for (double x = -0.87; x <= 0.87; x += 0.05) {
                    double xd, yd, xu, yu;
                    l.distort(x, y, xd, yd);
                    ASSERT_TRUE(l.undistort(xd, yd, xu, yu));
                    worst_px = std::max(worst_px, std::hypot(xu - x, yu - y) * half_diagonal);
                }
        }
    std::printf("[ figures  ] distort -> undistort: worst %.3g px over 1920x1080\n", worst_px);
    EXPECT_LE(worst_px, 0.01);
}

TEST(LensDistortion, CircleTakesThePolynomialRadius)
{
    // A thin anti-aliased ring of radius r about the centre, distorted: its intensity-weighted
    // mean radius is r (1 + k1 r^2 + k2 r^4) (normalised), to 0.05 px (the ring's width
    // and the bilinear sampling spread it symmetrically; its mean moves by far less).
    const double cx = kW / 2.0, cy = kH / 2.0;
    for (const auto& [k1, k2] : { std::make_pair(-0.15, 0.02), std::make_pair(0.1, 0.0) }) {
        for (double r_px : { 60.0, 110.0 }) {
            const OIIO::ImageBuf ring = shape_image([&](double x, double y) {
                return std::abs(std::hypot(x - cx, y - cy) - r_px) < 1.0 ? 1.0f : 0.0f;
            });
            LensDistortion l;
            l.k1 = k1, l.k2 = k2;
            const OIIO::ImageBuf out = warp(ring, l, DistortDirection::Distort);
            const double got = weighted_mean(out, 0, [&](double x, double y) { return std::hypot(x - cx, y - cy); });
            const double r   = r_px / kHalfDiagonal;
            const double want = r_px * (1.0 + k1 * r * r + k2 * r * r * r * r);
            EXPECT_NEAR(got, want, 0.05) << "k1 " << k1 << " r " << r_px;
        }
    }
}

TEST(LensDistortion, ALineThroughTheCentreStaysStraight)
{
    // A thin diagonal line through the centre, strongly barrel-distorted: in 10 px stretches
    // along it, the intensity-weighted distance across it (signed, perpendicular) stays 0 to
    // 0.05 px. (The distortion changes the line's brightness along it; a distance taken
    // across it does not feel that.)
    const double cx = kW / 2.0, cy = kH / 2.0, slope = 0.45, norm = std::sqrt(1.0 + slope * slope);
    const OIIO::ImageBuf line = shape_image([&](double x, double y) {
        return std::abs((y - cy) - slope * (x - cx)) / norm < 0.75 ? 1.0f : 0.0f;
    });
    LensDistortion l;
    l.k1 = -0.25, l.k2 = 0.05;
    const OIIO::ImageBuf out = warp(line, l, DistortDirection::Distort);
    std::map<int, std::pair<double, double>> bins;  // stretch -> (sum w, sum w d)
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            const double w = out.getchannel(x, y, 0, 0);
            if (w <= 0.0)
                continue;
            const double X = x + 0.5 - cx, Y = y + 0.5 - cy;
            const double along = (X + slope * Y) / norm, across = (Y - slope * X) / norm;
            auto& b = bins[int(std::floor(along / 10.0))];
            b.first += w, b.second += w * across;
        }
    double worst = 0.0;
    for (const auto& [stretch, b] : bins)
        if (b.first > 5.0)
            worst = std::max(worst, std::abs(b.second / b.first));
    EXPECT_GT(bins.size(), 30u);
    EXPECT_LE(worst, 0.05);
}

TEST(LensDistortion, WhitePointFringeIsTheMagnificationDifferenceTimesItsRadius)
{
    // A white dot 150 px right and 60 px down of the centre; red magnified by 1 + 0.004, blue
    // by 1 - 0.003: the red and blue centroids lie (0.004 + 0.003) r apart along the radius.
    const double cx = kW / 2.0, cy = kH / 2.0, dx = 150.0, dy = 60.0;
    const OIIO::ImageBuf dot = shape_image(
        [&](double x, double y) { return std::hypot(x - cx - dx, y - cy - dy) < 2.0 ? 1.0f : 0.0f; }, { "R", "G", "B" });
    LensDistortion l;
    l.lateral_r = 0.004, l.lateral_b = -0.003;
    const OIIO::ImageBuf out = warp(dot, l, DistortDirection::Distort);
    auto centroid = [&](int c) {
        return std::make_pair(weighted_mean(out, c, [](double x, double) { return x; }),
                              weighted_mean(out, c, [](double, double y) { return y; }));
    };
    const auto [rx, ry] = centroid(0);
    const auto [gx, gy] = centroid(1);
    const auto [bx, by] = centroid(2);
    const double r = std::hypot(dx, dy);
    EXPECT_NEAR(std::hypot(rx - bx, ry - by), 0.007 * r, 0.02);
    EXPECT_NEAR(gx, cx + dx, 0.02) << "green stays";
    EXPECT_NEAR(gy, cy + dy, 0.02);
    EXPECT_NEAR(rx - gx, 0.004 * dx, 0.02) << "red outward";
    EXPECT_NEAR(bx - gx, -0.003 * dx, 0.02) << "blue inward";
}

TEST(LensDistortion, StmapSamplesTheSourceAsTheCommandDoes)
{
    // OpenImageIO's interppixel_NDC (bilinear, black past the window) at the STMap's (s, 1 - t)
    // gives lens_distort's image, both directions, both models, to float rounding.
    const OIIO::ImageBuf src = shape_image(
        [](double x, double y) { return float(0.5 + 0.5 * std::sin(x * 0.21) * std::cos(y * 0.17)); }, { "R", "G", "B" });
    for (DistortionModel m : { DistortionModel::Polynomial, DistortionModel::Division })
        for (DistortDirection d : { DistortDirection::Distort, DistortDirection::Undistort }) {
            LensDistortion l;
            l.model = m, l.k1 = -0.12, l.k2 = 0.01, l.centre_x_px = 7.0;
            OIIO::ImageBuf map;
            ASSERT_TRUE(distortion_stmap(map, src.spec(), l, d)) << map.geterror();
            const OIIO::ImageBuf out = warp(src, l, d);
            double worst = 0.0;
            for (int y = 0; y < kH; ++y)
                for (int x = 0; x < kW; ++x) {
                    float st[2], px[3];
                    map.getpixel(x, y, st, 2);
                    src.interppixel_NDC(st[0], 1.0f - st[1], px, OIIO::ImageBuf::WrapBlack);
                    for (int c = 0; c < 3; ++c)
                        worst = std::max(worst, double(std::abs(px[c] - out.getchannel(x, y, 0, c))));
                }
            EXPECT_LE(worst, 1e-4);
        }
}

TEST(LensDistortion, NoDistortionIsTheIdentityAndDepthIsNeverBlended)
{
    const OIIO::ImageBuf src = shape_image([](double x, double y) { return float(x > 200 ? 3.0 : 40.0) + float(y) * 0.0f; },
                                           { "R", "G", "B", "A", "Z" });
    const OIIO::ImageBuf same = warp(src, LensDistortion(), DistortDirection::Distort);
    double worst = 0.0;
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x)
            for (int c = 0; c < 5; ++c)
                worst = std::max(worst, double(std::abs(same.getchannel(x, y, 0, c) - src.getchannel(x, y, 0, c))));
    EXPECT_LE(worst, 1e-5);
    // Distorted, Z holds only depths the source holds (3, 40, the edge pixel's mean, 0 past
    // the frame); R is blended.
    LensDistortion l;
    l.k1 = -0.1;
    const OIIO::ImageBuf out = warp(src, l, DistortDirection::Distort);
    std::set<float> source_z{ 0.0f };
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x)
            source_z.insert(src.getchannel(x, y, 0, 4));
    int invented = 0, blended = 0;
    for (int y = 0; y < kH; ++y)
        for (int x = 0; x < kW; ++x) {
            invented += source_z.count(out.getchannel(x, y, 0, 4)) == 0;
            blended += source_z.count(out.getchannel(x, y, 0, 0)) == 0;
        }
    EXPECT_EQ(invented, 0);
    EXPECT_GT(blended, 0);
}

TEST(LensDistortion, RefusesWhatHasNoInverse)
{
    std::string err;
    LensDistortion l;
    l.k1 = -3.0;
    EXPECT_FALSE(check_distortion(l, OIIO::ROI(0, 100, 0, 100), err));
    EXPECT_NE(err.find("fold the polynomial mapping over itself at 0.334"), std::string::npos) << err;
    l.k1 = std::nan("");
    EXPECT_FALSE(check_distortion(l, OIIO::ROI(0, 100, 0, 100), err));
    EXPECT_EQ(err, "k1 is nan, not a finite number");
    l    = LensDistortion();
    l.lateral_r = 0.01;
    OIIO::ImageBuf map;
    EXPECT_FALSE(distortion_stmap(map, OIIO::ImageSpec(8, 8, 3, OIIO::TypeFloat), l, DistortDirection::Distort));
    EXPECT_NE(map.geterror().find("an STMap holds one source position a pixel"), std::string::npos);
}
