// The built-in scenes' thin-lens truth (traced against their geometry) and deep images:
// the deep image flattens to the sharp scene, a tiny aperture gives the pinhole scene, the
// geometric truth agrees with the deep image's truth (truth.h) where the deep image holds
// the hidden surfaces, a lone light keeps its energy, and any thread count gives the same
// bits.
#include <bokeh/deep.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>
#include <bokeh/truth.h>

#include <gtest/gtest.h>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebufalgo.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>

using namespace bokeh;

namespace {

SceneOptions small_scene(int w, int h)
{
    SceneOptions o;
    o.width  = w;
    o.height = h;
    return o;
}

// The scene's own lens (its metadata's focus and f-number, 50 mm on 36 mm), a disk.
SceneTruthOptions scene_lens(const std::string& name, int spp)
{
    SceneCamera cam;
    EXPECT_TRUE(scene_camera(name, cam));
    SceneTruthOptions t;
    t.lens.focal_mm        = cam.focal_mm;
    t.lens.sensor_width_mm = cam.sensor_width_mm;
    t.lens.focus_distance  = cam.focus_m;
    t.lens.fstop           = cam.fstop;
    t.lens.depth_unit_mm   = 1000.0;
    t.aperture.shape       = KernelShape::Disk;
    t.spp                  = spp;
    return t;
}

// defocus_truth's options for the same lens, with no CoC limit in the way.
TruthOptions deep_truth_options(const SceneTruthOptions& s)
{
    TruthOptions t;
    t.coc.lens       = s.lens;
    t.coc.max_coc_px = 8192.0;
    t.aperture       = s.aperture;
    t.aspect         = s.aspect;
    t.spp            = s.spp;
    t.seed           = s.seed;
    return t;
}

ImageError rgba_error(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b)
{
    OIIO::ImageBuf a4, b4;
    const int ch[4] = { 0, 1, 2, 3 };
    EXPECT_TRUE(OIIO::ImageBufAlgo::channels(a4, a, 4, ch));
    EXPECT_TRUE(OIIO::ImageBufAlgo::channels(b4, b, 4, ch));
    ImageError e;
    std::string err;
    EXPECT_TRUE(compare(e, a4, b4, err)) << err;
    return e;
}

bool same_bits(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b)
{
    if (a.spec().width != b.spec().width || a.spec().height != b.spec().height
        || a.spec().nchannels != b.spec().nchannels)
        return false;
    std::vector<float> pa(a.spec().image_pixels() * size_t(a.spec().nchannels)), pb(pa.size());
    a.get_pixels(a.roi(), OIIO::TypeFloat, pa.data());
    b.get_pixels(b.roi(), OIIO::TypeFloat, pb.data());
    return std::memcmp(pa.data(), pb.data(), pa.size() * sizeof(float)) == 0;
}

}  // namespace

// The deep scene flattens to the sharp scene: layer 1's alphas weigh each surface by its
// share of the rays and end at 1, so what lies behind cannot show. Measured largest
// difference, relative to max(1, |value|), over the three scenes at 240 x 135: see the
// output (measured 1.1e-7: float rounding of alpha and premultiplied colour); Z is the
// nearest ray's, equal.
TEST(SceneDeep, FlattenIsTheSharpScene)
{
    for (const std::string& name : scene_names()) {
        const SceneOptions o = small_scene(240, 135);
        OIIO::ImageBuf sharp, deep, flat;
        ASSERT_TRUE(make_scene(sharp, name, o, 2)) << sharp.geterror();
        ASSERT_TRUE(make_deep_scene(deep, name, o, 2)) << deep.geterror();
        ASSERT_TRUE(deep.deep());
        ASSERT_EQ(deep.spec().channelnames, (std::vector<std::string>{ "R", "G", "B", "A", "Z" }));
        ASSERT_TRUE(deep_flatten(flat, deep, {}, nullptr, 2)) << flat.geterror();
        double worst = 0.0, worst_z = 0.0;
        for (int y = 0; y < o.height; ++y)
            for (int x = 0; x < o.width; ++x) {
                for (int c = 0; c < 4; ++c) {
                    const double s = sharp.getchannel(x, y, 0, c), f = flat.getchannel(x, y, 0, c);
                    worst          = std::max(worst, std::abs(s - f) / std::max(1.0, std::abs(s)));
                }
                worst_z = std::max(worst_z, std::abs(double(sharp.getchannel(x, y, 0, 4)) - flat.getchannel(x, y, 0, 4)));
            }
        // Samples behind the visible ones (the hidden surfaces).
        const OIIO::DeepData& dd = *deep.deepdata();
        int64_t hidden = 0, samples = 0;
        for (int64_t p = 0; p < dd.pixels(); ++p) {
            double T = 1.0;
            for (int s = 0; s < int(dd.samples(p)); ++s) {
                hidden += T <= 0.0;
                T *= 1.0 - dd.deep_value(p, 3, s);
                ++samples;
            }
        }
        std::cout << name << ": flatten vs sharp: largest relative difference " << worst << ", Z " << worst_z
                  << "; " << samples << " samples, " << hidden << " of them hidden\n";
        EXPECT_LE(worst, 2e-6) << name;
        EXPECT_EQ(worst_z, 0.0) << name;
        EXPECT_GT(hidden, int64_t(o.width) * o.height / 8) << name;  // every scene hides much
    }
}

// With f/10000 (every CoC under 0.02 px at 160 px) the geometric truth is the pinhole
// scene: both are estimates of the pixel's area mean (256 Sobol' points against 16 x 16
// stratified ones), so they differ only where the pixel holds an edge or fine texture.
TEST(SceneTruth, TinyApertureIsThePinholeScene)
{
    for (const std::string& name : scene_names()) {
        SceneOptions o = small_scene(160, 90);
        SceneTruthOptions t = scene_lens(name, 256);
        t.lens.fstop        = 1e4;  // CoC 0.012 px at most (the giant's 0.15 m lights)
        OIIO::ImageBuf truth, sharp;
        SceneTruthReport rep;
        ASSERT_TRUE(make_scene_truth(truth, name, o, t, &rep, 2)) << truth.geterror();
        EXPECT_LT(std::max(std::abs(rep.min_coc_px), std::abs(rep.max_coc_px)), 0.02f);
        o.aa = 16;
        ASSERT_TRUE(make_scene(sharp, name, o, 2));
        const ImageError e = rgba_error(truth, sharp);
        std::cout << name << ": f/10000 truth vs the pinhole scene (aa 16): " << e.psnr_db << " dB, RMS "
                  << e.rmse_linear << "; truth noise " << rep.noise_psnr_db << " dB\n";
        EXPECT_GE(e.psnr_db, 42.0) << name;  // measured: lights 45.2, edges 49.8, giant 50.3 dB
    }
}

namespace {

// PSNR of `a` against `b` over the pixels where `mask` is set, as bokeh-bench's truth-chain
// task measures it (the others set equal, the error scaled by the mask's share).
double masked_psnr(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b, const std::vector<uint8_t>& mask)
{
    OIIO::ImageBuf m = OIIO::ImageBufAlgo::channels(a, 4, { 0, 1, 2, 3 });
    const OIIO::ImageBuf b4 = OIIO::ImageBufAlgo::channels(b, 4, { 0, 1, 2, 3 });
    const int w = m.spec().width;
    int64_t n = 0;
    for (int y = 0; y < m.spec().height; ++y)
        for (int x = 0; x < w; ++x) {
            if (mask[size_t(y) * size_t(w) + size_t(x)]) {
                ++n;
                continue;
            }
            float v[4];
            b4.getpixel(x, y, v, 4);
            m.setpixel(x, y, v, 4);
        }
    ImageError e;
    std::string err;
    EXPECT_TRUE(compare(e, m, b4, err)) << err;
    return e.psnr_db + 10.0 * std::log10(double(n) / double(mask.size()));
}

// R, G, B, A averaged over 4 x 4 blocks.
OIIO::ImageBuf box4(const OIIO::ImageBuf& img)
{
    const int w = img.spec().width / 4, h = img.spec().height / 4;
    OIIO::ImageBuf out(OIIO::ImageSpec(w, h, 4, OIIO::TypeFloat));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float v[4] = {};
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i)
                    for (int c = 0; c < 4; ++c)
                        v[c] += img.getchannel(4 * x + i, 4 * y + j, 0, c) / 16.0f;
            out.setpixel(x, y, v, 4);
        }
    return out;
}

}  // namespace

// The geometric truth and the deep scene's truth (defocus_truth, same lens, spp and seed)
// agree to within the noise: tiny HDR lights make a lot of it (a ray meets a light or
// misses it in the geometry, where the deep image spreads it over its pixel's cell), so
// the deep scene's truth is held to the geometric truth rendered again with other rays.
// Compared after a 4 x 4 box average, which cuts independent noise by 12 dB and keeps
// errors wider than 4 px, as a background missing behind a defocused foreground is. Where
// the lens sees behind the foreground (the disocclusion mask: the deep and the flat
// scene's truths differ by more than 0.01 in a block), the deep scene's truth is closer to
// the geometry than the flat scene's (deepen: no hidden surfaces). aa 8, so the sharp
// pixels' own sampling error (aa 3 on the in-focus checker) stays below the noise.
// Measured (dB, frame / mask; re-render, deep scene's truth, flat scene's): lights 36.8 /
// 30.6, 37.7 / 31.5, 36.6 / 29.2; edges 32.1 / 31.0, 32.0 / 27.7, 28.9 / 20.4; giant
// 21.1 / 20.0, 26.6 / 25.5, 26.4 / 24.4. The deep image's shortfall in the edges mask
// (3.3 dB under the re-render) is the near panel's edge pixels, where the wall it hides in
// some of their rays lies in front of the far wall they show and is left out.
TEST(SceneTruth, AgreesWithTheDeepScenesTruth)
{
    for (const std::string& name : scene_names()) {
        SceneOptions o            = small_scene(320, 180);
        o.aa                      = 8;
        const SceneTruthOptions t = scene_lens(name, 64);
        SceneTruthOptions t2      = t;
        t2.seed                   = 2;
        OIIO::ImageBuf geo, geo2, deep, sharp, deepened, from_deep, from_flat;
        ASSERT_TRUE(make_scene_truth(geo, name, o, t, nullptr, 2)) << geo.geterror();
        ASSERT_TRUE(make_scene_truth(geo2, name, o, t2, nullptr, 2));
        ASSERT_TRUE(make_deep_scene(deep, name, o, 2));
        ASSERT_TRUE(make_scene(sharp, name, o, 2));
        ASSERT_TRUE(deep_from_flat(deepened, sharp));
        ASSERT_TRUE(defocus_truth(from_deep, deep, deep_truth_options(t), nullptr, 2)) << from_deep.geterror();
        ASSERT_TRUE(defocus_truth(from_flat, deepened, deep_truth_options(t), nullptr, 2)) << from_flat.geterror();
        const OIIO::ImageBuf g = box4(geo), g2 = box4(geo2), d = box4(from_deep), f = box4(from_flat);
        const int w = g.spec().width, h = g.spec().height;
        std::vector<uint8_t> mask(size_t(w) * size_t(h), 0);
        int64_t in_mask = 0;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                bool differs = false;
                for (int c = 0; c < 4; ++c)
                    differs |= std::abs(d.getchannel(x, y, 0, c) - f.getchannel(x, y, 0, c)) > 0.01f;
                mask[size_t(y) * size_t(w) + size_t(x)] = differs;
                in_mask += differs;
            }
        const double gg = rgba_error(g2, g).psnr_db, dg = rgba_error(d, g).psnr_db, fg = rgba_error(f, g).psnr_db;
        const double mg = masked_psnr(g2, g, mask), md = masked_psnr(d, g, mask), mf = masked_psnr(f, g, mask);
        std::cout << name << " (4 x 4 blocks) vs the geometric truth: again with other rays " << gg << " dB (mask "
                  << mg << "), deep scene's truth " << dg << " dB (mask " << md << "), flat scene's " << fg
                  << " dB (mask " << mf << "); mask " << in_mask << " of " << w * h << " blocks\n";
        EXPECT_GE(dg, gg - 1.0) << name;
        EXPECT_GE(md, mg - 4.0) << name;
        EXPECT_GE(md, mf + 0.5) << name;
    }
}

// A lone HDR disc on the far wall of "edges" (30 m, CoC 9.6 px at 480 px) spreads into
// its bokeh; summed over a window holding all of it (and only dim wall besides) the light
// is what the sharp scene holds there.
TEST(SceneTruth, LoneLightKeepsEnergy)
{
    const SceneOptions o = small_scene(480, 270);
    SceneTruthOptions t  = scene_lens("edges", 64);
    OIIO::ImageBuf truth, sharp;
    ASSERT_TRUE(make_scene_truth(truth, "edges", o, t, nullptr, 2));
    ASSERT_TRUE(make_scene(sharp, "edges", o, 2));
    // The far wall's light grid: frame position (-0.95 + 0.1 i, 0.9 - 0.2 j); i = 2, j = 0.
    const int cx = int(std::lround((1.0 - 0.75) * 0.5 * o.width)), cy = int(std::lround((1.0 - 0.9) * 0.5 * o.height));
    double sum_truth[3] = {}, sum_sharp[3] = {}, ring_truth = 0.0;
    for (int y = std::max(0, cy - 6); y < cy + 7; ++y)
        for (int x = cx - 8; x < cx + 8; ++x)
            for (int c = 0; c < 3; ++c) {
                sum_truth[c] += truth.getchannel(x, y, 0, c);
                sum_sharp[c] += sharp.getchannel(x, y, 0, c);
                if (std::abs(x - cx) >= 4 || std::abs(y - cy) >= 4)
                    ring_truth += truth.getchannel(x, y, 0, c);
            }
    for (int c = 0; c < 3; ++c) {
        std::cout << "lone light, channel " << c << ": sharp " << sum_sharp[c] << ", truth " << sum_truth[c] << "\n";
        EXPECT_NEAR(sum_truth[c], sum_sharp[c], 0.01 * sum_sharp[c]) << c;
    }
    EXPECT_GT(sum_sharp[0] + sum_sharp[1] + sum_sharp[2], 60.0);  // a light, not only the dim wall (~25)
    EXPECT_GT(ring_truth, 10.0);  // and it did spread: light beyond 4 px of its centre
}

TEST(SceneTruth, SameBitsForAnyThreadCount)
{
    const SceneOptions o = small_scene(96, 54);
    for (const std::string& name : scene_names()) {
        SceneTruthOptions t = scene_lens(name, 16);
        t.aperture.shape    = KernelShape::Polygon;
        t.aperture.blades   = 6;
        t.aperture.rotation_deg = 10.0f;
        t.aspect            = 1.5f;
        OIIO::ImageBuf one, two, d1, d2;
        ASSERT_TRUE(make_scene_truth(one, name, o, t, nullptr, 1));
        ASSERT_TRUE(make_scene_truth(two, name, o, t, nullptr, 2));
        EXPECT_TRUE(same_bits(one, two)) << name;
        ASSERT_TRUE(make_deep_scene(d1, name, o, 1));
        ASSERT_TRUE(make_deep_scene(d2, name, o, 2));
        const OIIO::DeepData &a = *d1.deepdata(), &b = *d2.deepdata();
        ASSERT_EQ(a.all_samples(), b.all_samples()) << name;
        bool same = true;
        for (int64_t p = 0; p < a.pixels(); ++p)
            for (int s = 0; s < int(a.samples(p)); ++s)
                for (int c = 0; c < 5; ++c)
                    same = same && a.deep_value(p, c, s) == b.deep_value(p, c, s);
        EXPECT_TRUE(same) << name;
    }
}

TEST(SceneTruth, BadOptions)
{
    const SceneOptions o = small_scene(16, 9);
    OIIO::ImageBuf out;
    SceneTruthOptions t = scene_lens("lights", 4);
    t.lens.focus_distance = 0.04;  // inside the focal length
    EXPECT_FALSE(make_scene_truth(out, "lights", o, t));
    EXPECT_NE(out.geterror().find("beyond the focal length"), std::string::npos) << out.geterror();
    t = scene_lens("lights", 0);
    EXPECT_FALSE(make_scene_truth(out, "lights", o, t));
    EXPECT_NE(out.geterror().find("spp"), std::string::npos);
    t = scene_lens("lights", 4);
    t.lens.depth_unit_mm = 10.0;
    EXPECT_FALSE(make_scene_truth(out, "lights", o, t));
    t = scene_lens("lights", 4);
    EXPECT_FALSE(make_scene_truth(out, "nosuch", o, t));
    EXPECT_NE(out.geterror().find("unknown scene"), std::string::npos);
    EXPECT_FALSE(make_deep_scene(out, "nosuch", o));
    SceneOptions big = o;
    big.width        = 0;
    EXPECT_FALSE(make_deep_scene(out, "lights", big));
}
