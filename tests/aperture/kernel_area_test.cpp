// The anti-aliased disk and polygon weights against the exact area of each pixel square
// inside the shape, computed here another way than the library does (it counts 64 x 64
// stratified samples on the pixels the boundary crosses):
// * disk: the area under the circle's chord, integrated in closed form column by column
//   (the antiderivative of sqrt(R^2 - x^2)), clipped to the pixel's rows;
// * polygon: the pixel square clipped by the polygon's edges (Sutherland-Hodgman), its
//   area by the shoelace formula.
// The weights are the areas over their sum; errors are in pixel areas. What the library's
// method can err by: a pixel its first look judges whole or empty may hold a sliver under
// 1/128 (a boundary between two border points 1/8 apart); a boundary pixel's 64 x 64
// count rounds each sample row's run at its ends, at most 2 * 64 / 64^2 = 1/32, far less
// for an edge crossing the rows at an angle (the roundings cancel). Measured over the cases
// below: at most 0.0073 (the 7-blade polygon rotated 17 degrees), mean over the boundary
// pixels at most 0.001. The bounds, 1/64 on any pixel and 1/512 on the mean, leave twice
// that and catch a misjudged pixel (a 5 x 5 look inside the pixel alone erred by 0.035 on
// the 31 px disk's rim and 0.08 at a polygon's tip).
#include <bokeh/base.h>
#include <bokeh/blur.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

using namespace bokeh;

namespace {


// Area of {x0 <= x <= x1, y0 <= y <= y1} inside the circle of radius R at the origin.
double disk_pixel_area(double R, double x0, double x1, double y0, double y1)
{
    // For |x| <= R the circle spans y in [-h(x), h(x)], h = sqrt(R^2 - x^2); the pixel's
    // rows clip it. Split [x0, x1] where h(x) crosses y0 or y1 (there min/max switch), and
    // integrate each piece: the length is linear in h, whose integral is F below.
    auto F = [R](double x) {  // integral of sqrt(R^2 - x^2) dx
        x = std::clamp(x, -R, R);
        return 0.5 * (x * std::sqrt(std::max(0.0, R * R - x * x)) + R * R * std::asin(x / R));
    };
    std::vector<double> cuts = { x0, x1 };
    for (double y : { y0, y1 })
        if (std::abs(y) < R) {
            const double c = std::sqrt(R * R - y * y);
            for (double x : { -c, c })
                if (x > x0 && x < x1)
                    cuts.push_back(x);
        }
    for (double x : { -R, R })
        if (x > x0 && x < x1)
            cuts.push_back(x);
    std::sort(cuts.begin(), cuts.end());
    double area = 0.0;
    for (size_t i = 0; i + 1 < cuts.size(); ++i) {
        // Which of curve and constant bounds the piece is the same all along it but where
        // they touch (the circle's top at x = 0 against y1 = R): judged off the middle.
        const double a = cuts[i], b = cuts[i + 1], m = a + 0.37 * (b - a);
        if (std::abs(m) >= R)
            continue;
        const double h = std::sqrt(R * R - m * m);
        // On this piece the top is min(y1, h) and the bottom max(y0, -h), each either a
        // constant or the curve throughout; the length is top - bottom where positive.
        const bool top_curve = h < y1, bottom_curve = -h > y0;
        const double top_const = top_curve ? 0.0 : y1, bottom_const = bottom_curve ? 0.0 : y0;
        if ((top_curve ? h : y1) <= (bottom_curve ? -h : y0))
            continue;
        const double curve = F(b) - F(a);
        area += (top_curve ? curve : top_const * (b - a)) - (bottom_curve ? -curve : bottom_const * (b - a));
    }
    return area;
}

struct Pt {
    double x, y;
};

double shoelace(const std::vector<Pt>& p)
{
    double a = 0.0;
    for (size_t i = 0; i < p.size(); ++i) {
        const Pt &u = p[i], &v = p[(i + 1) % p.size()];
        a += u.x * v.y - v.x * u.y;
    }
    return 0.5 * std::abs(a);
}

// The pixel square clipped by each edge of a convex polygon given counter-clockwise.
double polygon_pixel_area(const std::vector<Pt>& poly, double x0, double x1, double y0, double y1)
{
    std::vector<Pt> out = { { x0, y0 }, { x1, y0 }, { x1, y1 }, { x0, y1 } };
    for (size_t e = 0; e < poly.size() && !out.empty(); ++e) {
        const Pt a = poly[e], b = poly[(e + 1) % poly.size()];
        auto side = [&](const Pt& p) { return (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x); };
        std::vector<Pt> in = std::move(out);
        out.clear();
        for (size_t i = 0; i < in.size(); ++i) {
            const Pt p = in[i], q = in[(i + 1) % in.size()];
            const double sp = side(p), sq = side(q);
            if (sp >= 0)
                out.push_back(p);
            if ((sp >= 0) != (sq >= 0)) {
                const double t = sp / (sp - sq);
                out.push_back({ p.x + t * (q.x - p.x), p.y + t * (q.y - p.y) });
            }
        }
    }
    return out.size() < 3 ? 0.0 : shoelace(out);
}

// Compare kernel_weights(k) with areas(dx, dy) normalised; `typical` bounds the mean error
// over the pixels the boundary crosses, `worst` any one pixel.
template <class Area>
void expect_weights_are_areas(const Kernel& k, Area area, double worst, double typical, const char* what)
{
    const KernelWeights kw = kernel_weights(k, 1);
    double total = 0.0;
    std::vector<double> exact(kw.w.size());
    for (int dy = -kw.ry; dy <= kw.ry; ++dy)
        for (int dx = -kw.rx; dx <= kw.rx; ++dx) {
            const double a = area(dx - 0.5, dx + 0.5, dy - 0.5, dy + 0.5);
            exact[size_t((dy + kw.ry) * (2 * kw.rx + 1) + dx + kw.rx)] = a;
            total += a;
        }
    double sum_err = 0.0, max_err = 0.0;
    int boundary = 0;
    for (size_t i = 0; i < exact.size(); ++i) {
        const double a = exact[i] / total;  // the exact weight
        const double full = 1.0 / total;    // the weight of a whole pixel
        const double err = std::abs(kw.w[i] - a) / full;  // in pixel areas
        if (exact[i] > 1e-12 && exact[i] < 1.0 - 1e-12) {
            ++boundary;
            sum_err += err;
        }
        if (err > max_err)
            max_err = err;
        const int dx = int(i % size_t(2 * kw.rx + 1)) - kw.rx, dy = int(i / size_t(2 * kw.rx + 1)) - kw.ry;
        EXPECT_LE(err, worst) << what << ": pixel (" << dx << ", " << dy << ") weight " << kw.w[i] * total
                              << " pixel areas, exact " << exact[i];
    }
    ASSERT_GT(boundary, 0) << what;
    EXPECT_LE(sum_err / boundary, typical) << what << ": mean error over " << boundary << " boundary pixels";
}

}  // namespace

// The closed form itself, on cases with known answers: a whole pixel, a pixel cut by the
// axis-aligned extreme of the circle, the quarter disk.
TEST(KernelArea, DiskAreaClosedFormChecks)
{
    EXPECT_NEAR(disk_pixel_area(10.0, 0.0, 1.0, 0.0, 1.0), 1.0, 1e-12);
    EXPECT_NEAR(disk_pixel_area(1.0, 0.0, 1.0, 0.0, 1.0), kPi / 4.0, 1e-12);
    EXPECT_NEAR(disk_pixel_area(1.0, -1.0, 1.0, -1.0, 1.0), kPi, 1e-12);
    EXPECT_NEAR(disk_pixel_area(2.0, -2.0, 2.0, 0.0, 5.0), 2.0 * kPi, 1e-12);
    EXPECT_NEAR(disk_pixel_area(1.0, 2.0, 3.0, 0.0, 1.0), 0.0, 1e-15);
    const std::vector<Pt> square = { { -1, -1 }, { 1, -1 }, { 1, 1 }, { -1, 1 } };
    EXPECT_NEAR(polygon_pixel_area(square, 0.5, 1.5, 0.5, 1.5), 0.25, 1e-12);
}

// The anti-aliased disk: every pixel's weight is its area inside the circle. The 31 px
// disk's rim pixel (15, 1) is cut at a corner (0.965 of it inside) although all 25 points
// of a 5 x 5 look at it are inside.
TEST(KernelArea, AntialiasedDiskWeightsAreExactAreas)
{
    for (float size : { 5.0f, 9.0f, 15.5f, 31.0f, 63.0f }) {
        Kernel k;
        k.shape     = KernelShape::Disk;
        k.width_px  = size;
        k.height_px = size;
        const double R = 0.5 * size;
        expect_weights_are_areas(
            k, [R](double x0, double x1, double y0, double y1) { return disk_pixel_area(R, x0, x1, y0, y1); },
            1.0 / 64.0, 1.0 / 512.0, "disk");
    }
}

// The anti-aliased polygon: every pixel's weight is its area inside the polygon (straight
// blades; rotation 0 puts a vertex up, y down in the kernel).
TEST(KernelArea, AntialiasedPolygonWeightsAreExactAreas)
{
    for (int blades : { 3, 5, 6, 7, 9 })
        for (float rotation : { 0.0f, 17.0f }) {
            Kernel k;
            k.shape        = KernelShape::Polygon;
            k.blades       = blades;
            k.rotation_deg = rotation;
            k.width_px = k.height_px = 21.0f;
            std::vector<Pt> poly;
            for (int j = 0; j < blades; ++j) {
                // Counter-clockwise in kernel coordinates (y down) is clockwise with y up.
                const double a = 0.5 * kPi + rotation * kPi / 180.0 - 2.0 * kPi * j / blades;
                poly.push_back({ 10.5 * std::cos(a), -10.5 * std::sin(a) });
            }
            expect_weights_are_areas(
                k, [&poly](double x0, double x1, double y0, double y1) { return polygon_pixel_area(poly, x0, x1, y0, y1); },
                1.0 / 64.0, 1.0 / 512.0, "polygon");
        }
}

// The anti-aliased star (an Opening: the Aperture's own inside test, no convex short cut):
// every pixel's weight is its area inside the star, the star cut here into its 2N
// triangles (centre, an outer vertex, the next inner one), each convex and clipped as the
// polygons are.
TEST(KernelArea, AntialiasedStarWeightsAreExactAreas)
{
    for (int points : { 5, 6, 8 })
        for (float rotation : { 0.0f, 13.0f }) {
            const double inner = points == 6 ? 0.7 : 0.45;
            Kernel k;
            k.shape = KernelShape::Opening;
            std::string err;
            ASSERT_TRUE(Aperture::star(points, inner, rotation, k.opening, err)) << err;
            k.width_px = k.height_px = 21.0f;
            const double R = 10.5, half = kPi / points;
            std::vector<std::vector<Pt>> triangles;
            for (int j = 0; j < points; ++j) {
                // Clockwise with y up (counter-clockwise in kernel coordinates, y down).
                const double a = 0.5 * kPi + rotation * kPi / 180.0 - 2.0 * half * j;
                auto at = [&](double r, double t) { return Pt{ r * std::cos(t), -r * std::sin(t) }; };
                triangles.push_back({ { 0, 0 }, at(R, a), at(R * inner, a - half) });
                triangles.push_back({ { 0, 0 }, at(R * inner, a - half), at(R, a - 2.0 * half) });
            }
            expect_weights_are_areas(
                k,
                [&triangles](double x0, double x1, double y0, double y1) {
                    double a = 0.0;
                    for (const std::vector<Pt>& t : triangles)
                        a += polygon_pixel_area(t, x0, x1, y0, y1);
                    return a;
                },
                1.0 / 64.0, 1.0 / 512.0, "star");
        }
}
