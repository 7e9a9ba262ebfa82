// Deep compositing against the physics it encodes and against OIIO where OIIO is exact.
//
// The reference for flatten, merge and holdout is an independent model of the same scene:
// every sample is a medium of constant density (a volume [Z, ZBack) of alpha a has optical
// depth u = -log(1 - a) spread evenly over it, and emits c u / a per unit of u; a point is
// the limit of zero thickness), and the pixel's light is integrated in closed form between
// consecutive depths where a sample starts or ends. It shares no code with the splitting
// and merging of core/deep/deep.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <iostream>
#include <random>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebufalgo.h>

#include <bokeh/deep.h>
#include <bokeh/io.h>

#include "test_util.h"

using namespace bokeh_test;

namespace {

using Smp   = DeepSample;
using Pixel = DeepPixel;

Pixel read_pixel(const OIIO::ImageBuf& img, int x, int y)
{
    Pixel out;
    const OIIO::ImageSpec& s = img.spec();
    if (x < s.x || y < s.y || x >= s.x + s.width || y >= s.y + s.height)
        return out;
    const OIIO::DeepData& dd = *img.deepdata();
    const int64_t p          = int64_t(y - s.y) * s.width + (x - s.x);
    const int zb             = s.channelindex("ZBack");
    for (int k = 0; k < dd.samples(p); ++k)
        out.push_back({ dd.deep_value(p, 0, k), dd.deep_value(p, 1, k), dd.deep_value(p, 2, k),
                        dd.deep_value(p, 3, k), dd.deep_value(p, 4, k),
                        zb >= 0 ? dd.deep_value(p, zb, k) : dd.deep_value(p, 4, k) });
    return out;
}

// The flat R, G, B, A of a pixel by the density model (see the file's header).
std::array<double, 4> density_composite(const Pixel& px)
{
    std::vector<double> bounds;
    for (const Smp& s : px) {
        bounds.push_back(s.z);
        bounds.push_back(std::max(s.z, s.zb));
    }
    std::sort(bounds.begin(), bounds.end());
    bounds.erase(std::unique(bounds.begin(), bounds.end()), bounds.end());
    std::array<double, 4> out {};
    double T = 1.0;
    auto emit = [&](double weight, const Smp& s) {
        out[0] += weight * s.r;
        out[1] += weight * s.g;
        out[2] += weight * s.b;
    };
    for (size_t i = 0; i < bounds.size() && T > 0.0; ++i) {
        const double b = bounds[i];
        // Points at b: one zero-thickness mixture (opaque ones share the light evenly).
        double U = 0.0;
        int opaque = 0;
        for (const Smp& s : px)
            if (!(s.zb > s.z) && s.z == b && s.a >= 1.0)
                ++opaque;
        if (opaque > 0) {
            for (const Smp& s : px)
                if (!(s.zb > s.z) && s.z == b && s.a >= 1.0)
                    emit(T / opaque, s);
            T = 0.0;
            break;
        }
        std::array<double, 3> E {};
        for (const Smp& s : px)
            if (!(s.zb > s.z) && s.z == b) {
                const double u = -std::log(1.0 - s.a);
                const double k = s.a > 0.0 ? u / s.a : 1.0;
                E[0] += s.r * k, E[1] += s.g * k, E[2] += s.b * k;
                U += u;
            }
        const double f = U > 0.0 ? (1.0 - std::exp(-U)) / U : 1.0;
        out[0] += T * f * E[0], out[1] += T * f * E[1], out[2] += T * f * E[2];
        T *= std::exp(-U);
        if (i + 1 == bounds.size())
            break;
        // The slab [b, next): the volumes covering it, densities per unit depth.
        const double next = bounds[i + 1], dz = next - b;
        double sigma = 0.0;
        std::array<double, 3> e {};
        for (const Smp& s : px)
            if (s.zb > s.z && s.z <= b && s.zb >= next) {
                const double len = s.zb - s.z;
                if (s.a >= 1.0) {  // opaque medium: all its light at its front
                    if (s.z == b) {
                        emit(T, s);
                        T = 0.0;
                    }
                    continue;
                }
                const double u = -std::log(1.0 - s.a);
                const double k = s.a > 0.0 ? u / s.a : 1.0;
                sigma += u / len;
                e[0] += s.r * k / len, e[1] += s.g * k / len, e[2] += s.b * k / len;
            }
        const double g = sigma > 0.0 ? (1.0 - std::exp(-sigma * dz)) / sigma : dz;
        out[0] += T * g * e[0], out[1] += T * g * e[1], out[2] += T * g * e[2];
        T *= std::exp(-sigma * dz);
    }
    out[3] = 1.0 - T;
    return out;
}

// Random pixels with the cases the rules single out: points and volumes, shared depths
// (ties of Z, of ZBack, of both), alpha 0 with colour, alpha 1 points, overlaps.
std::vector<Pixel> random_pixels(int n, uint32_t seed, int max_samples = 7, bool opaque_points = true)
{
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::vector<Pixel> px(static_cast<size_t>(n));
    for (Pixel& p : px) {
        const int ns = int(rng() % uint32_t(max_samples + 1));
        for (int k = 0; k < ns; ++k) {
            Smp s {};
            // Depths on a coarse grid half the time, so samples share them.
            s.z  = (rng() % 2) ? double(1 + rng() % 5) : 1.0 + 5.0 * u01(rng);
            s.zb = s.z;
            if (rng() % 2)
                s.zb = (rng() % 2) ? s.z + double(1 + rng() % 3) : s.z + 3.0 * u01(rng);
            const uint32_t kind = rng() % 8;
            s.a = kind == 0 ? 0.0 : (kind == 1 && opaque_points && !(s.zb > s.z)) ? 1.0 : 0.95 * u01(rng);
            // Premultiplied colour up to the alpha, or light of its own when alpha is 0.
            const double scale = s.a > 0.0 ? s.a : 0.5;
            s.r = scale * u01(rng), s.g = scale * u01(rng), s.b = scale * u01(rng);
            p.push_back(s);
        }
    }
    return px;
}

void expect_flat_matches(const OIIO::ImageBuf& flat, int x, int y, const std::array<double, 4>& ref,
                         double tol, const char* what)
{
    float v[8] = {};
    flat.getpixel(x, y, v, 4);
    for (int c = 0; c < 4; ++c)
        EXPECT_NEAR(v[c], ref[size_t(c)], tol) << what << " pixel (" << x << ", " << y << ") channel " << c;
}

bool is_tidy(const Pixel& p)
{
    for (size_t s = 1; s < p.size(); ++s) {
        const Smp &a = p[s - 1], &b = p[s];
        if (b.z < a.z || (b.z == a.z && b.zb <= a.zb))
            return false;  // unsorted, or coincident
        if (a.zb > a.z && b.z < a.zb)
            return false;  // overlapping
    }
    return true;
}

}  // namespace

TEST(Deep, FlattenIsTheDensityIntegral)
{
    const int w = 40, h = 25;
    const auto px  = random_pixels(w * h, 7);
    const auto img = make_deep(w, h, px);
    OIIO::ImageBuf flat;
    ASSERT_TRUE(bokeh::deep_flatten(flat, img)) << flat.geterror();
    ASSERT_FALSE(flat.deep());
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            expect_flat_matches(flat, x, y, density_composite(px[size_t(y * w + x)]), 2e-6, "flatten");
}

TEST(Deep, TidyIsTidyIdempotentAndKeepsTheFlatten)
{
    const int w = 30, h = 20;
    const auto px  = random_pixels(w * h, 11);
    const auto img = make_deep(w, h, px);
    OIIO::ImageBuf tidy, tidy2, flat, flat_tidy;
    ASSERT_TRUE(bokeh::deep_tidy(tidy, img)) << tidy.geterror();
    ASSERT_TRUE(bokeh::deep_tidy(tidy2, tidy)) << tidy2.geterror();
    ASSERT_TRUE(bokeh::deep_flatten(flat, img));
    ASSERT_TRUE(bokeh::deep_flatten(flat_tidy, tidy));
    int split = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const Pixel t = read_pixel(tidy, x, y);
            EXPECT_TRUE(is_tidy(t)) << "pixel " << x << "," << y;
            split += t.size() > px[size_t(y * w + x)].size();
            const Pixel t2 = read_pixel(tidy2, x, y);
            ASSERT_EQ(t2.size(), t.size());
            for (size_t s = 0; s < t.size(); ++s)  // a tidy pixel is left bit for bit
                EXPECT_TRUE(t2[s].r == t[s].r && t2[s].a == t[s].a && t2[s].z == t[s].z && t2[s].zb == t[s].zb);
        }
    EXPECT_GT(split, 50) << "the random pixels should exercise volume splits";
    EXPECT_LT(max_difference(flat, flat_tidy), 2e-6);
}

TEST(Deep, SplitAndMergeFollowTheOpenExrFormulas)
{
    // One volume of alpha 0.75 over [0, 4) and a point at 1: tidy cuts the volume at 1;
    // its front quarter keeps 1 - 0.25^0.25 of alpha, colour in proportion.
    const Pixel p = { { 0.6, 0.3, 0.0, 0.75, 0.0, 4.0 }, { 0.2, 0.2, 0.2, 0.5, 1.0, 1.0 } };
    OIIO::ImageBuf tidy;
    ASSERT_TRUE(bokeh::deep_tidy(tidy, make_deep(1, 1, { p })));
    const Pixel t = read_pixel(tidy, 0, 0);
    ASSERT_EQ(t.size(), 3u);
    const double a_front = 1.0 - std::pow(0.25, 0.25), a_back = 1.0 - std::pow(0.25, 0.75);
    EXPECT_NEAR(t[0].a, a_front, 1e-7);
    EXPECT_NEAR(t[0].r, 0.6 * a_front / 0.75, 1e-7);
    EXPECT_EQ(t[0].z, 0.0);
    EXPECT_EQ(t[0].zb, 1.0);
    EXPECT_EQ(t[1].z, 1.0);  // the point sorts before the volume that starts at its depth
    EXPECT_EQ(t[1].zb, 1.0);
    EXPECT_NEAR(t[2].a, a_back, 1e-7);
    // Coincident points merge with the -log1p weights: 0.5 and 0.25.
    const Pixel q = { { 0.4, 0.0, 0.0, 0.5, 2.0, 2.0 }, { 0.0, 0.2, 0.0, 0.25, 2.0, 2.0 } };
    ASSERT_TRUE(bokeh::deep_tidy(tidy, make_deep(1, 1, { q })));
    const Pixel m = read_pixel(tidy, 0, 0);
    ASSERT_EQ(m.size(), 1u);
    const double u1 = -std::log(0.5), u2 = -std::log(0.75), a = 1.0 - 0.5 * 0.75, w = a / (u1 + u2);
    EXPECT_NEAR(m[0].a, a, 1e-7);
    EXPECT_NEAR(m[0].r, w * 0.4 * u1 / 0.5, 1e-7);
    EXPECT_NEAR(m[0].g, w * 0.2 * u2 / 0.25, 1e-7);
    // Alpha 1: two opaque coincident points average; one takes its own colour; alpha 0
    // light adds.
    const Pixel o = { { 1.0, 0.0, 0.0, 1.0, 3.0, 3.0 }, { 0.0, 1.0, 0.0, 1.0, 3.0, 3.0 },
                      { 0.0, 0.0, 1.0, 0.5, 3.0, 3.0 } };
    ASSERT_TRUE(bokeh::deep_tidy(tidy, make_deep(1, 1, { o })));
    const Pixel om = read_pixel(tidy, 0, 0);
    ASSERT_EQ(om.size(), 1u);
    EXPECT_EQ(om[0].a, 1.0);
    EXPECT_NEAR(om[0].r, 0.5, 1e-7);
    EXPECT_NEAR(om[0].g, 0.5, 1e-7);
    EXPECT_NEAR(om[0].b, 0.0, 1e-7);
    const Pixel add = { { 0.1, 0.0, 0.0, 0.0, 3.0, 3.0 }, { 0.2, 0.0, 0.0, 0.0, 3.0, 3.0 } };
    ASSERT_TRUE(bokeh::deep_tidy(tidy, make_deep(1, 1, { add })));
    EXPECT_NEAR(read_pixel(tidy, 0, 0)[0].r, 0.3, 1e-7);
    // A thin slice of a faint medium keeps its digits (expm1/log1p): alpha 1e-7 over
    // [0, 1) cut at 1e-4 gives 1e-11, where 1 - pow(1 - a, x) in float would give 0.
    const Pixel faint = { { 1e-7, 0.0, 0.0, 1e-7, 0.0, 1.0 }, { 0.0, 0.0, 0.0, 0.0, 1e-4f, 1e-4f } };
    ASSERT_TRUE(bokeh::deep_tidy(tidy, make_deep(1, 1, { faint })));
    const Pixel ft = read_pixel(tidy, 0, 0);
    ASSERT_EQ(ft.size(), 3u);
    EXPECT_NEAR(ft[0].a / (1e-7 * double(1e-4f)), 1.0, 1e-4);
}

TEST(Deep, MergeIsTheDensityIntegralOfThePooledSamplesAndCommutes)
{
    const int w = 24, h = 18;
    const auto pa = random_pixels(w * h, 21, 4), pb = random_pixels(w * h, 22, 4), pc = random_pixels(w * h, 23, 3);
    const auto A = make_deep(w, h, pa), B = make_deep(w, h, pb, true), C = make_deep(w, h, pc);
    OIIO::ImageBuf abc, cba, flat1, flat2;
    ASSERT_TRUE(bokeh::deep_merge(abc, { &A, &B, &C })) << abc.geterror();
    ASSERT_TRUE(bokeh::deep_merge(cba, { &C, &B, &A })) << cba.geterror();
    ASSERT_TRUE(bokeh::deep_flatten(flat1, abc));
    ASSERT_TRUE(bokeh::deep_flatten(flat2, cba));
    // B stores half colour: the reference reads what B holds.
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            Pixel all = pa[size_t(y * w + x)];
            for (const Smp& s : read_pixel(B, x, y))
                all.push_back(s);
            for (const Smp& s : pc[size_t(y * w + x)])
                all.push_back(s);
            expect_flat_matches(flat1, x, y, density_composite(all), 3e-6, "merge");
        }
    EXPECT_LT(max_difference(flat1, flat2), 1e-6) << "merge must not depend on the order of its inputs";
    // The first image's channel types are kept.
    EXPECT_EQ(abc.deepdata()->channeltype(0), OIIO::TypeFloat);
    EXPECT_EQ(abc.deepdata()->channeltype(4), OIIO::TypeFloat);
}

TEST(Deep, MergeOverDifferentWindowsAndChannelOrders)
{
    const auto pa = random_pixels(6 * 4, 31), pb = random_pixels(5 * 5, 32);
    const auto A = make_deep(6, 4, pa, false, 0, 0), B = make_deep(5, 5, pb, false, 4, 2);
    OIIO::ImageBuf m;
    ASSERT_TRUE(bokeh::deep_merge(m, { &A, &B }));
    EXPECT_EQ(m.spec().x, 0);
    EXPECT_EQ(m.spec().y, 0);
    EXPECT_EQ(m.spec().width, 9);
    EXPECT_EQ(m.spec().height, 7);
    OIIO::ImageBuf flat;
    ASSERT_TRUE(bokeh::deep_flatten(flat, m));
    for (int y = 0; y < 7; ++y)
        for (int x = 0; x < 9; ++x) {
            Pixel all = read_pixel(A, x, y);
            for (const Smp& s : read_pixel(B, x, y))
                all.push_back(s);
            expect_flat_matches(flat, x, y, density_composite(all), 3e-6, "windows");
        }
    // The same channels in another order merge by name; a channel the first lacks fails.
    OIIO::ImageBuf reordered;
    ASSERT_TRUE(OIIO::ImageBufAlgo::channels(reordered, B, 6, { 4, 5, 3, 0, 1, 2 }));
    OIIO::ImageBuf m2, flat2;
    ASSERT_TRUE(bokeh::deep_merge(m2, { &A, &reordered })) << m2.geterror();
    ASSERT_TRUE(bokeh::deep_flatten(flat2, m2));
    EXPECT_EQ(max_difference(flat, flat2), 0.0);
    OIIO::ImageBuf renamed = B;
    renamed.specmod().channelnames[0] = "X";
    OIIO::ImageBuf bad;
    EXPECT_FALSE(bokeh::deep_merge(bad, { &A, &renamed }));
    EXPECT_NE(bad.geterror().find("'X'"), std::string::npos) << bad.geterror();
}

// A pass of point samples (R, G, B, A, Z: what renderers and --defocus:output=deep's
// inputs hold) merges with a pass of volume samples (with ZBack): OpenEXR reads a sample
// without ZBack as a point at Z, so the merge adds ZBack = Z to it. Every combination
// flattens to the density integral of the pooled samples.
TEST(Deep, PointPassesMergeWithVolumePasses)
{
    const int w = 12, h = 9;
    std::vector<Pixel> pp = random_pixels(w * h, 41, 3);
    for (Pixel& px : pp)
        for (Smp& s : px)
            s.zb = s.z;  // points: the pass below has no ZBack to hold anything else
    const auto pv = random_pixels(w * h, 42, 3);
    OIIO::ImageBuf points;
    ASSERT_TRUE(OIIO::ImageBufAlgo::channels(points, make_deep(w, h, pp), 5, { 0, 1, 2, 3, 4 }));
    ASSERT_EQ(points.spec().channelindex("ZBack"), -1);
    const OIIO::ImageBuf volumes = make_deep(w, h, pv);
    struct Combo {
        const OIIO::ImageBuf *first, *second;
        const std::vector<Pixel> *a, *b;
        bool zback;
    };
    const Combo combos[] = { { &points, &points, &pp, &pp, false },
                             { &points, &volumes, &pp, &pv, true },
                             { &volumes, &points, &pv, &pp, true },
                             { &volumes, &volumes, &pv, &pv, true } };
    for (const Combo& k : combos) {
        OIIO::ImageBuf merged, flat;
        bokeh::DeepRepairs repairs;
        ASSERT_TRUE(bokeh::deep_merge(merged, { k.first, k.second }, false, {}, &repairs)) << merged.geterror();
        EXPECT_EQ(repairs.total(), 0) << "a point without ZBack is no fault to repair";
        EXPECT_EQ(merged.spec().channelindex("ZBack") >= 0, k.zback);
        EXPECT_EQ(merged.spec().channelindex("R"), 0) << "colour stays first";
        ASSERT_TRUE(bokeh::deep_flatten(flat, merged)) << flat.geterror();
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                Pixel all = (*k.a)[size_t(y * w + x)];
                for (const Smp& s : (*k.b)[size_t(y * w + x)])
                    all.push_back(s);
                expect_flat_matches(flat, x, y, density_composite(all), 3e-6, "point + volume merge");
            }
    }
}

TEST(Deep, CullDropsOnlyWhatAccumulatedOpacityHides)
{
    // 30 samples of alpha 0.5, then one more: after 25 of them the transmittance is 2^-25,
    // which float shows as alpha 1; OIIO's culling (behind one opaque sample) keeps all.
    Pixel p;
    for (int k = 0; k < 31; ++k)
        p.push_back({ 0.25, 0.25, 0.25, 0.5, 1.0 + k, 1.0 + k });
    const auto img = make_deep(1, 1, { p });
    OIIO::ImageBuf kept, culled, fk, fc;
    ASSERT_TRUE(bokeh::deep_merge(kept, { &img }, false));
    ASSERT_TRUE(bokeh::deep_merge(culled, { &img }, true));
    EXPECT_EQ(kept.deepdata()->samples(0), 31);
    EXPECT_EQ(culled.deepdata()->samples(0), 25);
    OIIO::ImageBuf oiio_culled = OIIO::ImageBufAlgo::deep_merge(img, make_deep(1, 1, { {} }), true);
    EXPECT_EQ(oiio_culled.deepdata()->samples(0), 31) << "OIIO culls behind single opaque samples only";
    ASSERT_TRUE(bokeh::deep_flatten(fk, kept));
    ASSERT_TRUE(bokeh::deep_flatten(fc, culled));
    EXPECT_LT(max_difference(fk, fc), 1e-7);
    // Behind an opaque sample: dropped by cull, kept (for a deep defocus) by default.
    const Pixel q = { { 0.1, 0.1, 0.1, 1.0, 2.0, 2.0 }, { 0.9, 0.9, 0.9, 0.9, 5.0, 5.0 } };
    const auto qi = make_deep(1, 1, { q });
    ASSERT_TRUE(bokeh::deep_merge(kept, { &qi }, false));
    ASSERT_TRUE(bokeh::deep_merge(culled, { &qi }, true));
    EXPECT_EQ(kept.deepdata()->samples(0), 2);
    EXPECT_EQ(culled.deepdata()->samples(0), 1);
}

TEST(Deep, HoldoutOfOneSampleImagesIsTheDensityIntegral)
{
    // The image: one sample a pixel (point or volume); the holdout: random samples. The
    // reference: the image's light integrated through the holdout's medium alone (points
    // of the holdout at the image point's depth count as in front).
    const int w = 40, h = 30;
    auto pimg       = random_pixels(w * h, 41, 1, false);
    const auto phold = random_pixels(w * h, 42, 6);
    const auto img = make_deep(w, h, pimg), hold = make_deep(w, h, phold);
    OIIO::ImageBuf out, flat;
    ASSERT_TRUE(bokeh::deep_holdout(out, img, hold)) << out.geterror();
    ASSERT_TRUE(out.deep());
    ASSERT_TRUE(bokeh::deep_flatten(flat, out));
    int attenuated = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const Pixel& ip = pimg[size_t(y * w + x)];
            std::array<double, 4> ref {};
            if (!ip.empty()) {
                const Smp s = ip[0];
                // Optical depth of the holdout up to depth d, points at d included.
                auto holdout_u = [&](double d) {
                    double u = 0.0;
                    for (const Smp& q : phold[size_t(y * w + x)]) {
                        const double uq = q.a >= 1.0 ? 1e300 : -std::log(1.0 - q.a);
                        if (!(q.zb > q.z))
                            u += q.z <= d ? uq : 0.0;
                        else
                            u += uq * std::clamp((d - q.z) / (q.zb - q.z), 0.0, 1.0);
                    }
                    return u;
                };
                double frac = 1.0;  // the share of the image's light that passes
                if (!(s.zb > s.z)) {
                    frac = std::exp(-holdout_u(s.z));
                } else {
                    // Emission spread as exp(-u_i t) over the volume; integrate numerically
                    // (fine midpoint rule) through the holdout's transmittance.
                    const int n = 20000;
                    const double ui = -std::log(1.0 - s.a), len = s.zb - s.z;
                    double acc = 0.0, norm = 0.0;
                    for (int k = 0; k < n; ++k) {
                        const double t = (k + 0.5) / n;
                        const double wgt = s.a > 0.0 ? std::exp(-ui * t) : 1.0;
                        acc += wgt * std::exp(-holdout_u(s.z + t * len));
                        norm += wgt;
                    }
                    frac = acc / norm;
                }
                ref = { s.r * frac, s.g * frac, s.b * frac, s.a * frac };
                attenuated += frac < 0.99;
            }
            expect_flat_matches(flat, x, y, ref, 2e-5, "holdout");
        }
    EXPECT_GT(attenuated, 200);
}

TEST(Deep, HoldoutByItselfAndByNothing)
{
    // Opaque points held out by themselves vanish; semi-transparent ones keep (1 - a);
    // a volume held out by itself keeps (2 - a) / 2 of its light (the two media mix).
    const Pixel opaque = { { 0.3, 0.2, 0.1, 1.0, 4.0, 4.0 } };
    const Pixel half   = { { 0.3, 0.2, 0.1, 0.5, 4.0, 4.0 } };
    const Pixel fog    = { { 0.3, 0.2, 0.1, 0.5, 4.0, 8.0 } };
    const auto img = make_deep(3, 1, { opaque, half, fog });
    OIIO::ImageBuf out, flat;
    ASSERT_TRUE(bokeh::deep_holdout(out, img, img));
    ASSERT_TRUE(bokeh::deep_flatten(flat, out));
    float v[6];
    flat.getpixel(0, 0, v, 6);
    EXPECT_EQ(v[0], 0.0f);
    EXPECT_EQ(v[3], 0.0f);
    flat.getpixel(1, 0, v, 6);
    EXPECT_NEAR(v[0], 0.3 * 0.5, 1e-7);
    flat.getpixel(2, 0, v, 6);
    EXPECT_NEAR(v[0], 0.3 * (2.0 - 0.5) / 2.0, 1e-6);
    // Held out by an empty image: the tidy image, unchanged.
    const auto many = make_deep(20, 10, random_pixels(200, 43));
    const auto none = make_deep(20, 10, std::vector<Pixel>(200));
    OIIO::ImageBuf held, tidy, fh, ft;
    ASSERT_TRUE(bokeh::deep_holdout(held, many, none));
    ASSERT_TRUE(bokeh::deep_tidy(tidy, many));
    ASSERT_TRUE(bokeh::deep_flatten(fh, held));
    ASSERT_TRUE(bokeh::deep_flatten(ft, tidy));
    EXPECT_EQ(max_difference(fh, ft), 0.0);
}

TEST(Deep, HoldoutDiffersFromOiioWherePartialAlphaHoldsOut)
{
    // OIIO 2.4's deep_holdout cuts at the holdout's first opaque sample and ignores partial
    // holdout alpha; the exact holdout passes (1 - 0.5) of the light behind a half-
    // transparent holdout.
    const auto img  = make_deep(1, 1, { { { 0.8, 0.8, 0.8, 1.0, 10.0, 10.0 } } });
    const auto hold = make_deep(1, 1, { { { 0.0, 0.0, 0.0, 0.5, 5.0, 5.0 } } });
    OIIO::ImageBuf ours, flat;
    ASSERT_TRUE(bokeh::deep_holdout(ours, img, hold));
    ASSERT_TRUE(bokeh::deep_flatten(flat, ours));
    float v[6];
    flat.getpixel(0, 0, v, 6);
    EXPECT_NEAR(v[0], 0.4, 1e-7);
    EXPECT_NEAR(v[3], 0.5, 1e-7);
    OIIO::ImageBuf theirs = OIIO::ImageBufAlgo::deep_holdout(img, hold);
    ASSERT_FALSE(theirs.has_error()) << theirs.geterror();
    EXPECT_EQ(theirs.deepdata()->deep_value(0, 0, 0), 0.8f) << "OIIO leaves the sample whole";
}

TEST(Deep, SlicesTileTheDepthRange)
{
    const int w = 30, h = 20;
    const auto img = make_deep(w, h, random_pixels(w * h, 51));
    OIIO::ImageBuf s1, s2, s12, all, merged, f_merged, f_whole, f_all, f_src;
    ASSERT_TRUE(bokeh::deep_slice(s1, img, -1.0, 3.5));
    ASSERT_TRUE(bokeh::deep_slice(s2, img, 3.5, 100.0));
    ASSERT_TRUE(bokeh::deep_slice(s12, img, -1.0, 100.0));
    ASSERT_TRUE(bokeh::deep_merge(merged, { &s1, &s2 }));
    ASSERT_TRUE(bokeh::deep_flatten(f_merged, merged));
    ASSERT_TRUE(bokeh::deep_flatten(f_whole, s12));
    EXPECT_LT(max_difference(f_merged, f_whole), 2e-6);
    ASSERT_TRUE(bokeh::deep_slice(all, img, -HUGE_VAL, HUGE_VAL));
    ASSERT_TRUE(bokeh::deep_flatten(f_all, all));
    ASSERT_TRUE(bokeh::deep_flatten(f_src, img));
    EXPECT_EQ(max_difference(f_all, f_src), 0.0);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (const Smp& s : read_pixel(s1, x, y)) {
                EXPECT_GE(s.z, -1.0);
                EXPECT_LE(std::max(s.z, s.zb), 3.5);
                if (!(s.zb > s.z)) {
                    EXPECT_LT(s.z, 3.5) << "a point at FAR belongs to the next slice";
                }
            }
    OIIO::ImageBuf bad;
    EXPECT_FALSE(bokeh::deep_slice(bad, img, 5.0, 5.0));
}

TEST(Deep, DeepenAndFlattenRoundTrip)
{
    const auto flat = rgbaz_image(23, 11, [](int x, int y) {
        const float a = ((x + y) % 4) * 0.25f;
        return std::array<float, 5> { 0.1f * a * x, 0.05f * a, a, a, 1.0f + 0.5f * y };
    });
    OIIO::ImageBuf deep, back;
    ASSERT_TRUE(bokeh::deep_from_flat(deep, flat)) << deep.geterror();
    ASSERT_TRUE(deep.deep());
    ASSERT_TRUE(bokeh::deep_flatten(back, deep));
    int empty = 0;
    for (int y = 0; y < 11; ++y)
        for (int x = 0; x < 23; ++x) {
            float a[5], b[5];
            flat.getpixel(x, y, a, 5);
            back.getpixel(x, y, b, 5);
            for (int c = 0; c < 4; ++c)
                EXPECT_EQ(a[c], b[c]);
            // Every pixel has a finite depth, so every pixel has a sample, alpha 0 or not.
            EXPECT_EQ(b[4], a[4]);
            empty += deep.deepdata()->samples(int64_t(y) * 23 + x) == 0;
        }
    EXPECT_EQ(empty, 0);
    OIIO::ImageBuf twice;
    EXPECT_FALSE(bokeh::deep_from_flat(twice, deep));
}

TEST(Deep, AgreesWithOiioReferenceOutputs)
{
    const std::string az = shared_data("oiio-testsuite/oiiotool-deep_src_az.exr");
    REQUIRE_SHARED(az);
    std::string err;
    OIIO::ImageBuf src, ref;
    ASSERT_TRUE(bokeh::read_image(src, az, err)) << err;
    ASSERT_TRUE(bokeh::read_image(ref, shared_data("oiio-testsuite/oiiotool-deep_ref_deepen.exr"), err)) << err;
    OIIO::ImageBuf deep;
    ASSERT_TRUE(bokeh::deep_from_flat(deep, src));
    ASSERT_EQ(deep.deepdata()->pixels(), ref.deepdata()->pixels());
    for (int64_t p = 0; p < ref.deepdata()->pixels(); ++p) {
        ASSERT_EQ(deep.deepdata()->samples(p), ref.deepdata()->samples(p)) << "pixel " << p;
        for (int s = 0; s < ref.deepdata()->samples(p); ++s)
            for (int c = 0; c < 2; ++c)
                EXPECT_EQ(deep.deepdata()->deep_value(p, c, s), ref.deepdata()->deep_value(p, c, s));
    }

    // Flatten of deepalpha (half A, float Z, up to 22 samples a pixel): alpha as OIIO's
    // reference. Z by our documented rule (deep.h; OIIO's blends depths through alpha):
    // the nearest depth of the samples with alpha > 0 (the first of them is always
    // visible), of all samples when none has alpha, 1e30 where there are none; computed
    // here from the raw samples.
    OIIO::ImageBuf alpha_src, flat_ref, ours;
    ASSERT_TRUE(bokeh::read_image(alpha_src, shared_data("oiio-testsuite/oiiotool-deep_src_deepalpha.exr"), err));
    ASSERT_TRUE(bokeh::read_image(flat_ref, shared_data("oiio-testsuite/oiiotool-deep_ref_flat.exr"), err));
    ASSERT_TRUE(bokeh::deep_flatten(ours, alpha_src));
    double max_a = 0.0, max_z = 0.0;
    for (int y = 0; y < 120; ++y)
        for (int x = 0; x < 160; ++x) {
            float a[2], b[2];
            ours.getpixel(x, y, a, 2);
            flat_ref.getpixel(x, y, b, 2);
            max_a = std::max(max_a, double(std::abs(a[0] - b[0])));
            if (b[1] < 1e29f)
                max_z = std::max(max_z, double(std::abs(a[1] - b[1])));
            const int64_t p          = int64_t(y) * 160 + x;
            const OIIO::DeepData& dd = *alpha_src.deepdata();
            const int ca = alpha_src.spec().channelindex("A"), cz = alpha_src.spec().channelindex("Z");
            float nearest_visible = 1e30f, nearest = 1e30f;
            for (int k = 0; k < dd.samples(p); ++k) {
                const float z = dd.deep_value(p, cz, k);
                nearest       = std::min(nearest, z);
                if (dd.deep_value(p, ca, k) > 0.0f)
                    nearest_visible = std::min(nearest_visible, z);
            }
            EXPECT_EQ(a[1], nearest_visible < 1e30f ? nearest_visible : nearest) << x << "," << y;
        }
    std::cout << "flatten of deepalpha: max |A - OIIO's A| " << max_a << ", max |Z - OIIO's Z| " << max_z << "\n";
    EXPECT_LE(max_a, 1e-6) << "deepalpha's samples are sorted and apart, where OIIO's flatten is exact";
}

TEST(Deep, LowResLeftViewPassesFlattenToTheComposite)
{
    const std::string balls = shared_data("openexr-images/LowResLeftView_Balls.exr");
    REQUIRE_SHARED(balls);
    std::string err;
    OIIO::ImageBuf b, l, t, comp;
    ASSERT_TRUE(bokeh::read_image(b, balls, err)) << err;
    ASSERT_TRUE(bokeh::read_image(l, shared_data("openexr-images/LowResLeftView_Leaves.exr"), err)) << err;
    ASSERT_TRUE(bokeh::read_image(t, shared_data("openexr-images/LowResLeftView_Trunks.exr"), err)) << err;
    ASSERT_TRUE(bokeh::read_image(comp, shared_data("openexr-images/LowResLeftView_composited.exr"), err)) << err;
    OIIO::ImageBuf merged, flat;
    ASSERT_TRUE(bokeh::deep_merge(merged, { &b, &l, &t })) << merged.geterror();
    ASSERT_TRUE(bokeh::deep_flatten(flat, merged)) << flat.geterror();
    // The composite also holds a Ground pass that is not among the files, so compare where
    // the three passes are opaque: nothing behind them shows. (Where the ground is in
    // front of a pass, the two differ: counted, not compared.)
    const OIIO::ROI roi = comp.roi();
    int64_t compared = 0, close = 0;
    double worst = 0.0;
    for (int y = roi.ybegin; y < roi.yend; ++y)
        for (int x = roi.xbegin; x < roi.xend; ++x) {
            float f[5], c[4];
            flat.getpixel(x, y, f, 5);
            comp.getpixel(x, y, c, 4);
            if (f[3] < 0.999f)
                continue;
            ++compared;
            double d = 0.0;
            for (int k = 0; k < 4; ++k)
                d = std::max(d, double(std::abs(f[k] - c[k])));
            close += d <= 2e-3;
            worst = std::max(worst, d);
        }
    std::cout << close << " of " << compared << " opaque pixels within 2e-3 of the composite; worst " << worst
              << "\n";
    ASSERT_GT(compared, 200000);
    EXPECT_GT(double(close) / double(compared), 0.995)
        << close << " of " << compared << " opaque pixels within 2e-3; worst " << worst;
}

TEST(Deep, RepresentativeVolumeImageTidiesAndFlattensToTheDensityIntegral)
{
    const std::string path = shared_data("gaffer/representativeDeepImage.exr");
    REQUIRE_SHARED(path);
    std::string err;
    OIIO::ImageBuf img;
    ASSERT_TRUE(bokeh::read_image(img, path, err)) << err;
    OIIO::ImageBuf tidy, flat, flat_tidy;
    ASSERT_TRUE(bokeh::deep_tidy(tidy, img)) << tidy.geterror();
    ASSERT_TRUE(bokeh::deep_flatten(flat, img));
    ASSERT_TRUE(bokeh::deep_flatten(flat_tidy, tidy));
    EXPECT_LT(max_difference(flat, flat_tidy), 1e-5);
    const OIIO::ImageSpec& s = img.spec();
    const int r = s.channelindex("R"), a = s.channelindex("A");
    ASSERT_EQ(r, 0);
    ASSERT_EQ(a, 3);
    int checked = 0;
    for (int y = s.y; y < s.y + s.height; y += 3)
        for (int x = s.x; x < s.x + s.width; x += 3) {
            const Pixel p = read_pixel(img, x, y);
            EXPECT_TRUE(is_tidy(read_pixel(tidy, x, y)));
            std::array<double, 4> ref = density_composite(p);
            float v[16];
            flat.getpixel(x, y, v, 16);
            for (int c = 0; c < 4; ++c)
                EXPECT_NEAR(v[c], ref[size_t(c)], 1e-5 + 1e-5 * std::abs(ref[size_t(c)]))
                    << "pixel (" << x << ", " << y << ") channel " << c << ", " << p.size() << " samples";
            checked += !p.empty();
        }
    EXPECT_GT(checked, 500);
}

TEST(Deep, BadSamplesFollowThePolicy)
{
    const Pixel p = { { 0.5, 0.5, 0.5, 0.5, NAN, NAN }, { 0.2, 0.2, 0.2, 0.5, 3.0, 1.0 },
                      { NAN, 0.1, 0.1, 0.5, 4.0, 4.0 } };
    const auto img = make_deep(1, 1, { p });
    bokeh::DeepRepairs rep;
    OIIO::ImageBuf out;
    ASSERT_TRUE(bokeh::deep_tidy(out, img, {}, &rep)) << out.geterror();
    EXPECT_EQ(rep.nan_depth, 1);
    EXPECT_EQ(rep.back_before, 1);
    EXPECT_EQ(rep.nonfinite, 1);
    const Pixel t = read_pixel(out, 0, 0);
    ASSERT_EQ(t.size(), 2u);
    EXPECT_EQ(t[0].z, 3.0);
    EXPECT_EQ(t[0].zb, 3.0) << "ZBack < Z: a point at Z";
    EXPECT_EQ(t[1].r, 0.0) << "NaN colour: 0";
    bokeh::DeepOptions strict;
    strict.nonfinite = bokeh::NonFinitePolicy::Error;
    for (auto fn : { +[](OIIO::ImageBuf& d, const OIIO::ImageBuf& s, const bokeh::DeepOptions& o) {
                         return bokeh::deep_tidy(d, s, o);
                     },
                     +[](OIIO::ImageBuf& d, const OIIO::ImageBuf& s, const bokeh::DeepOptions& o) {
                         return bokeh::deep_flatten(d, s, o);
                     } }) {
        OIIO::ImageBuf bad;
        EXPECT_FALSE(fn(bad, img, strict));
        EXPECT_NE(bad.geterror().find("pixel (0, 0)"), std::string::npos) << bad.geterror();
    }
    // Flat images and deep ones without Z or alpha are refused by name.
    OIIO::ImageBuf bad;
    EXPECT_FALSE(bokeh::deep_flatten(bad, rgbaz_image(2, 2, [](int, int) { return std::array<float, 5> {}; })));
    EXPECT_NE(bad.geterror().find("flat"), std::string::npos) << bad.geterror();
    OIIO::ImageSpec noz(2, 2, 2, OIIO::TypeFloat);
    noz.channelnames = { "R", "A" };
    noz.deep         = true;
    OIIO::ImageBuf nozbuf(noz), bad2;
    EXPECT_FALSE(bokeh::deep_tidy(bad2, nozbuf));
    EXPECT_NE(bad2.geterror().find("no Z channel"), std::string::npos) << bad2.geterror();
}

TEST(Deep, ResultsDoNotDependOnTheThreadCount)
{
    const auto a = make_deep(64, 48, random_pixels(64 * 48, 61));
    const auto b = make_deep(64, 48, random_pixels(64 * 48, 62));
    OIIO::ImageBuf m1, m2, f1, f2, h1, h2;
    ASSERT_TRUE(bokeh::deep_merge(m1, { &a, &b }, false, {}, nullptr, 1));
    ASSERT_TRUE(bokeh::deep_merge(m2, { &a, &b }, false, {}, nullptr, 2));
    ASSERT_EQ(m1.deepdata()->all_data().size(), m2.deepdata()->all_data().size());
    EXPECT_TRUE(std::equal(m1.deepdata()->all_data().begin(), m1.deepdata()->all_data().end(),
                           m2.deepdata()->all_data().begin()));
    ASSERT_TRUE(bokeh::deep_holdout(h1, a, b, {}, nullptr, 1));
    ASSERT_TRUE(bokeh::deep_holdout(h2, a, b, {}, nullptr, 2));
    EXPECT_TRUE(std::equal(h1.deepdata()->all_data().begin(), h1.deepdata()->all_data().end(),
                           h2.deepdata()->all_data().begin()));
    ASSERT_TRUE(bokeh::deep_flatten(f1, m1, {}, nullptr, 1));
    ASSERT_TRUE(bokeh::deep_flatten(f2, m1, {}, nullptr, 2));
    EXPECT_EQ(max_difference(f1, f2), 0.0);
}
