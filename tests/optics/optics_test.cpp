// Lens character (aperture.h, spectrum.h, optics.h) against what it must equal: the
// polygon rule of the flat kernels, the CIE colour-matching functions' published values,
// unit energy per channel, the flat disk kernel when every effect is off, the caustic
// where dr/ds = 0, the front/back asymmetry and rim colours that Kawase's "Bokeh Deep Dive"
// describes, the edge law's first fringe at the rim, and the field effects' geometry (cat's
// eye, anamorphic focus split); docs/methods/optics.md has the formulas.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <sstream>

#include <OpenImageIO/imagebufalgo.h>

#include <bokeh/base.h>
#include <bokeh/aperture.h>
#include <bokeh/blur.h>
#include <bokeh/color.h>
#include <bokeh/optics.h>
#include <bokeh/spectrum.h>
#include <bokeh/wave_optics.h>

#include "psf_support.h"
#include "test_util.h"

using bokeh::kPi;
using namespace bokeh_test;


TEST(Aperture, PolygonEdgeIsTheKernelsRule)
{
    // At a vertex the edge is the circumradius; mid-blade it is the apothem cos(pi / N).
    for (int n : { 3, 5, 6, 9 }) {
        EXPECT_NEAR(bokeh::polygon_edge_distance(n, 0.0, 0.0), 1.0, 1e-12);
        EXPECT_NEAR(bokeh::polygon_edge_distance(n, 0.0, kPi / n), std::cos(kPi / n), 1e-12);
        EXPECT_NEAR(bokeh::polygon_edge_distance(n, 1.0, kPi / n), 1.0, 1e-12);
    }
    bokeh::Kernel k;
    k.shape        = bokeh::KernelShape::Polygon;
    k.blades       = 6;
    k.rotation_deg = 0.0f;
    bokeh::Aperture a;
    std::string err;
    ASSERT_TRUE(bokeh::Aperture::from_kernel(k, a, err)) << err;
    EXPECT_NEAR(a.edge(kPi / 2), 1.0, 1e-12);  // rotation 0 puts a vertex straight up
    EXPECT_NEAR(a.min_edge(), std::cos(kPi / 6), 1e-12);
    // The flat kernel's hard-edged inside test and the aperture's agree at every pixel
    // centre of a 101 px hexagon.
    k.width_px = k.height_px = 101.0f;
    k.edge                   = bokeh::KernelEdge::Hard;
    const bokeh::KernelWeights kw = bokeh::kernel_weights(k, 1);
    int disagree = 0;
    for (int dy = -kw.ry; dy <= kw.ry; ++dy)
        for (int dx = -kw.rx; dx <= kw.rx; ++dx)
            disagree += (kw.at(dx, dy) > 0.0) != a.inside(dx / 50.5, -dy / 50.5);
    EXPECT_EQ(disagree, 0);
    // A cos edge-normal factor on a blade's middle is 1; near a vertex cos(pi / N).
    EXPECT_NEAR(a.edge_normal_cos(kPi / 2 + kPi / 6), 1.0, 1e-6);
}

TEST(Aperture, StarAndPicture)
{
    bokeh::Aperture star;
    std::string err;
    ASSERT_TRUE(bokeh::Aperture::star(5, 0.4, 0.0, star, err)) << err;
    EXPECT_NEAR(star.edge(kPi / 2), 1.0, 1e-9);           // a point straight up
    EXPECT_NEAR(star.edge(kPi / 2 + kPi / 5), 0.4, 1e-9);  // an inner vertex
    EXPECT_NEAR(star.min_edge(), 0.4, 1e-9);
    EXPECT_FALSE(bokeh::Aperture::star(2, 0.4, 0.0, star, err));
    EXPECT_FALSE(bokeh::Aperture::star(5, 0.0, 0.0, star, err));

    // A picture of a hexagon 201 px across gives the hexagon's edge within a pixel.
    bokeh::Kernel k;
    k.shape    = bokeh::KernelShape::Polygon;
    k.blades   = 6;
    k.width_px = k.height_px = 201.0f;
    const bokeh::KernelWeights kw = bokeh::kernel_weights(k, 1);
    OIIO::ImageBuf pic(OIIO::ImageSpec(2 * kw.rx + 1, 2 * kw.ry + 1, 1, OIIO::TypeDesc::FLOAT));
    for (int y = 0; y <= 2 * kw.ry; ++y)
        for (int x = 0; x <= 2 * kw.rx; ++x) {
            const float v = float(kw.at(x - kw.rx, y - kw.ry) > 0.0);
            pic.setpixel(x, y, &v);
        }
    bokeh::Aperture from_pic, hexagon;
    ASSERT_TRUE(bokeh::Aperture::from_picture(pic, from_pic, err)) << err;
    ASSERT_TRUE(bokeh::Aperture::from_kernel(k, hexagon, err)) << err;
    double worst = 0.0;
    for (int i = 0; i < 360; ++i) {
        const double phi = 2.0 * kPi * i / 360.0;
        worst = std::max(worst, std::abs(from_pic.edge(phi) - hexagon.edge(phi)));
    }
    EXPECT_LT(worst, 1.5 / 100.5) << "picture edge vs the hexagon, in radii";

    OIIO::ImageBuf empty(OIIO::ImageSpec(16, 16, 1, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBufAlgo::zero(empty);
    EXPECT_FALSE(bokeh::Aperture::from_picture(empty, from_pic, err));
    EXPECT_NE(err.find("no opening"), std::string::npos) << err;
}

TEST(Spectrum, ColourMatchingFunctionsAndWhite)
{
    // CIE 1931 2-degree values (CIE 015:2004 table): y(555) = 1.000, x(600) = 1.0622,
    // z(450) = 1.7721; the fit is within ~3 % of the table's peak there.
    EXPECT_NEAR(bokeh::cie1931_xyz(555.0)[1], 1.000, 0.03);
    EXPECT_NEAR(bokeh::cie1931_xyz(600.0)[0], 1.0622, 0.03);
    EXPECT_NEAR(bokeh::cie1931_xyz(450.0)[2], 1.7721, 0.05);
    // D65 white XYZ (0.9505, 1, 1.089) maps to Rec.709 (1, 1, 1) within the matrix's digits.
    const auto rgb = bokeh::xyz_to_rec709({ 0.9505, 1.0, 1.089 });
    for (double v : rgb)
        EXPECT_NEAR(v, 1.0, 2e-3);

    std::vector<bokeh::SpectralSample> s;
    std::string err;
    bokeh::SpectrumOptions o;
    ASSERT_TRUE(bokeh::spectral_samples(s, o, nullptr, err)) << err;
    EXPECT_EQ(s.size(), 32u);  // 400, 410, ..., 710
    for (int c = 0; c < 3; ++c) {
        double sum = 0.0;
        for (const auto& smp : s)
            sum += smp.rgb_weight[size_t(c)];
        EXPECT_NEAR(sum, 1.0, 1e-12) << "channel " << c;
    }
    // Red's weight peaks in the red, blue's in the blue.
    auto peak = [&](int c) {
        return std::max_element(s.begin(), s.end(), [&](const auto& a, const auto& b) {
                   return a.rgb_weight[size_t(c)] < b.rgb_weight[size_t(c)];
               })->wavelength_nm;
    };
    EXPECT_GT(peak(0), 580.0);
    EXPECT_LT(peak(2), 480.0);

    o.first_nm = 700.0;
    o.last_nm  = 400.0;
    EXPECT_FALSE(bokeh::spectral_samples(s, o, nullptr, err));
    EXPECT_NE(err.find("wavelength range"), std::string::npos) << err;
}

TEST(Spectrum, WorkingSpaceFromTheOcioConfig)
{
    // The shipped config with ACEScg as its working space: the weights come through its
    // CIE-XYZ-D65 space, still sum to 1 per channel, and the wider AP1 gamut leaves the
    // colour-matching functions' negative lobes smaller than Rec.709 does.
    std::ifstream in(BOKEH_OCIO_CONFIG);
    std::stringstream text;
    text << in.rdbuf();
    std::string cfg = text.str();
    const std::string role = "scene_linear: lin_rec709";
    ASSERT_NE(cfg.find(role), std::string::npos);
    cfg.replace(cfg.find(role), role.size(), "scene_linear: ACEScg");
    const std::string path = bokeh_test::fresh_dir("spectrum_ocio") + "/acescg.ocio";
    std::ofstream(path) << cfg;
    bokeh::ColorSystem acescg;
    std::string err;
    ASSERT_TRUE(acescg.load(path, err)) << err;
    std::vector<bokeh::SpectralSample> ap1, rec709;
    ASSERT_TRUE(bokeh::spectral_samples(ap1, {}, &acescg, err)) << err;
    ASSERT_TRUE(bokeh::spectral_samples(rec709, {}, nullptr, err)) << err;
    ASSERT_EQ(ap1.size(), rec709.size());
    double most_negative_ap1 = 0.0, most_negative_709 = 0.0;
    for (int c = 0; c < 3; ++c) {
        double sum = 0.0;
        for (size_t i = 0; i < ap1.size(); ++i) {
            sum += ap1[i].rgb_weight[size_t(c)];
            most_negative_ap1 = std::min(most_negative_ap1, ap1[i].rgb_weight[size_t(c)]);
            most_negative_709 = std::min(most_negative_709, rec709[i].rgb_weight[size_t(c)]);
        }
        EXPECT_NEAR(sum, 1.0, 1e-9) << "channel " << c;
    }
    std::cout << "most negative weight: Rec.709 " << most_negative_709 << ", ACEScg " << most_negative_ap1 << "\n";
    EXPECT_GT(most_negative_ap1, most_negative_709);
}

TEST(LensPsf, EnergyPerChannelAndSymmetry)
{
    std::vector<bokeh::LensCharacter> lenses(6);
    lenses[1].preset = bokeh::LensPreset::Uncorrected;
    lenses[2].preset = bokeh::LensPreset::Achromat;
    lenses[2].diffraction = bokeh::DiffractionModel::EdgeLaw;
    lenses[3].preset = bokeh::LensPreset::Apochromat;
    lenses[3].onion  = 0.3;
    lenses[3].catseye = 0.6;
    lenses[4].anamorphic_focus_px = 12.0;
    lenses[4].aspect = 1.5;
    lenses[5].onion_waves = 0.05;
    lenses[5].surface_noise = 0.3;
    std::string err;
    ASSERT_TRUE(bokeh::Aperture::star(5, 0.5, 10.0, lenses[5].aperture, err));
    for (size_t i = 0; i < lenses.size(); ++i)
        for (double coc : { -40.0, 3.0, 25.0 }) {
            const bokeh::Psf p = psf_of(lenses[i], coc, 0.5, 0.4);
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(channel_sum(p, c), 1.0, 1e-5) << "lens " << i << " coc " << coc << " channel " << c;
        }
    // A round aperture on the axis is symmetric under both mirrors; front and back bokeh
    // of a lens without aberration are each other's point reflection.
    bokeh::LensCharacter plain;
    const bokeh::Psf back = psf_of(plain, 30.0), front = psf_of(plain, -30.0);
    ASSERT_EQ(back.width, front.width);
    double worst = 0.0;
    for (int y = 0; y < back.height; ++y)
        for (int x = 0; x < back.width; ++x) {
            worst = std::max(worst, double(std::abs(back.at(x, y, 0) - back.at(back.width - 1 - x, y, 0))));
            worst = std::max(worst, double(std::abs(back.at(x, y, 0) - back.at(x, back.height - 1 - y, 0))));
            worst = std::max(worst, double(std::abs(back.at(x, y, 1)
                                                    - front.at(back.width - 1 - x, back.height - 1 - y, 1))));
        }
    EXPECT_LT(worst, 1e-6);
}

TEST(LensPsf, OctantCopyIsTheFullComputation)
{
    // A radially symmetric PSF is computed over one octant and copied (core/optics/lens_psf.cpp).
    // An anamorphic focus split of 1e-9 px breaks the symmetry test without changing the
    // physics past 1e-9: that PSF is computed pixel by pixel, and the two agree within
    // 1e-6 of the peak (only each pixel's sub-sample sum runs in another order), for an
    // achromat with rim fringes, centred onion rings and a hole, at and out of focus, and
    // off the axis without rings.
    bokeh::LensCharacter lens;
    lens.preset      = bokeh::LensPreset::Achromat;
    lens.diffraction = bokeh::DiffractionModel::EdgeLaw;
    lens.onion       = 0.3;
    bokeh::Kernel holed;
    holed.hole = 0.3f;
    std::string err;
    ASSERT_TRUE(bokeh::Aperture::from_kernel(holed, lens.aperture, err)) << err;
    bokeh::LensCharacter split = lens;
    split.anamorphic_focus_px  = 1e-9;
    // Off the axis without rings nothing depends on the field but the CoC: also radial.
    bokeh::LensCharacter no_rings = lens, no_rings_split = split;
    no_rings.onion = no_rings_split.onion = 0.0;
    for (double coc : { 0.0, 2.0, 9.0, -25.0, 7.0 }) {
        const bool off_axis  = coc == 7.0;
        const bokeh::Psf a = off_axis ? psf_of(no_rings, coc, 0.6, 0.34) : psf_of(lens, coc);
        const bokeh::Psf b = off_axis ? psf_of(no_rings_split, coc, 0.6, 0.34) : psf_of(split, coc);
        ASSERT_EQ(a.width, b.width) << "coc " << coc;
        ASSERT_EQ(a.height, b.height) << "coc " << coc;
        double worst = 0.0, peak = 0.0;
        for (size_t i = 0; i < a.rgb.size(); ++i) {
            worst = std::max(worst, double(std::abs(a.rgb[i] - b.rgb[i])));
            peak  = std::max(peak, double(a.rgb[i]));
        }
        EXPECT_LT(worst, 1e-6 * peak) << "coc " << coc;
    }
}

TEST(LensPsf, OffIsTheFlatDiskKernel)
{
    // Every effect off: the anti-aliased disk kernel of the flat defocus. The kernel's rim
    // is the exact pixel-area coverage; the PSF's is its sub-samples' under 16 px and a
    // pixel-wide tent along the radius above (core/optics/lens_psf.cpp). Under 16 px they differ
    // at rim pixels by up to 4 % of the disk's level, 1 % rms over the square (measured
    // 2.7 %, 0.5 % at 9 px); above, where the tent stands in for the pixel's area, by up to
    // 15 %, 3 % rms (measured 14 %, 2.4 % at 31 px). Under a pixel of CoC both are a point.
    for (double coc : { 0.0, 0.5, 9.0, 31.0, 64.0 }) {
        bokeh::LensCharacter off;
        const bokeh::Psf p = psf_of(off, coc);
        bokeh::Kernel k;
        k.shape    = bokeh::KernelShape::Disk;
        k.width_px = k.height_px = float(coc);
        const bokeh::KernelWeights kw = bokeh::kernel_weights(k, 1);
        const double level = coc < 1.0 ? 1.0 : 1.0 / (kPi * coc * coc / 4.0);
        double worst = 0.0, sq = 0.0;
        for (int y = 0; y < p.height; ++y)
            for (int x = 0; x < p.width; ++x) {
                const int dx = x - p.width / 2, dy = y - p.height / 2;
                const double ref = (std::abs(dx) <= kw.rx && std::abs(dy) <= kw.ry) ? kw.at(dx, dy) : 0.0;
                const double d   = std::abs(p.at(x, y, 0) - ref);
                worst = std::max(worst, d);
                sq += d * d;
            }
        const bool sub_sampled = coc < 16.0;
        EXPECT_LT(worst, (sub_sampled ? 0.04 : 0.15) * level) << "coc " << coc;
        EXPECT_LT(std::sqrt(sq / (p.width * p.height)), (sub_sampled ? 0.01 : 0.03) * level) << "coc " << coc;
        // The interior equals the level to 1 % (the rim's share of the energy differs).
        EXPECT_NEAR(p.at(p.width / 2, p.height / 2, 0), level, 0.01 * level) << "coc " << coc;
        std::cout << "off vs disk kernel, CoC " << coc << ": max " << worst / level << " of the level, rms "
                  << std::sqrt(sq / (p.width * p.height)) / level << "\n";
    }
}

TEST(LensPsf, JustPastAPixelOfCocTheDiskGrowsFromThePoint)
{
    // Under a pixel of CoC the PSF is a point; just past it, the disk's light starts to
    // reach the neighbours as the disk's area covers them, as the flat kernel's does. The
    // radial table's bins are then a fraction of the disk's radius: half-pixel bins spread a
    // 1.044 px disk a pixel (22 % of its light outside the centre pixel, where the disk's
    // area puts 0.5 %), a step in time as a light's CoC passed 1 px in a focus pull
    // (core/optics/psf_table.h, radial_bin_px). Measured against the kernel (absolute, the
    // PSF summing to 1): 0.007 at 1.02 px, 0.027-0.030 at 1.05-1.1 (the PSF's sub-samples
    // reach the neighbours later than the disk's area does), under 0.012 from 1.25 to 3 px;
    // with half-pixel bins 0.19-0.22 from 1.02 to 1.25 px.
    bokeh::LensCharacter off;
    double previous_centre = 1.0;
    for (double coc : { 1.0, 1.02, 1.05, 1.1, 1.25, 1.5, 2.0, 3.0 }) {
        const bokeh::Psf p = psf_of(off, coc);
        bokeh::Kernel k;
        k.shape    = bokeh::KernelShape::Disk;
        k.width_px = k.height_px = float(coc);
        const bokeh::KernelWeights kw = bokeh::kernel_weights(k, 1);
        double worst = 0.0;
        for (int y = 0; y < p.height; ++y)
            for (int x = 0; x < p.width; ++x) {
                const int dx = x - p.width / 2, dy = y - p.height / 2;
                const double ref = (std::abs(dx) <= kw.rx && std::abs(dy) <= kw.ry) ? kw.at(dx, dy) : 0.0;
                worst = std::max(worst, std::abs(p.at(x, y, 0) - ref));
            }
        const double centre = p.at(p.width / 2, p.height / 2, 0);
        std::printf("[ figures  ] off, CoC %.2f: centre %.4f, largest difference from the disk kernel %.4f\n", coc,
                    centre, worst);
        EXPECT_LT(worst, 0.04) << "coc " << coc;
        EXPECT_LE(centre, previous_centre + 1e-6) << "coc " << coc << ": the centre only falls as the disk grows";
        previous_centre = centre;
    }
}

TEST(LensPsf, CausticWhereTheLandingRadiusTurns)
{
    // Pure third-order spherical aberration (no colour, no zonal correction):
    // r(s) = s (c/2 - a3 s^2), a3 = NA SA3 / pitch. For c/2 and a3 of one sign the
    // landing radius turns at s_c = sqrt(c / (6 a3)): the bright caustic rim sits at
    // |r(s_c)| (docs/methods/optics.md, "Longitudinal aberration").
    bokeh::LensCharacter lens;
    lens.preset        = bokeh::LensPreset::Uncorrected;
    lens.chromatic     = 0.0;
    lens.monochromatic = 4.0;
    const double sa3 = bokeh::longitudinal_aberration_mm(lens, 1.0, 587.6);
    const double a3  = 0.5 / lens.fstop * sa3 / lens.pixel_pitch_mm;  // px, negative
    ASSERT_LT(a3, -10.0);
    const double c   = 2.0 * a3 * 1.5;  // front bokeh (c < 0), caustic inside the pupil
    const double s_c = std::sqrt(c / (6.0 * a3));
    ASSERT_LT(s_c, 1.0);
    const double r_c = std::abs(s_c * (0.5 * c - a3 * s_c * s_c));
    const bokeh::Psf p = psf_of(lens, c);
    const std::vector<double> prof = radial_profile(p, 1);
    const size_t peak = size_t(std::max_element(prof.begin() + 2, prof.end()) - prof.begin());
    EXPECT_NEAR(double(peak), r_c, 1.0) << "caustic at " << r_c << " px";
    // The rim ray lands inside the caustic: nothing past it.
    EXPECT_LT(prof[size_t(std::ceil(r_c)) + 2], 1e-3 * prof[peak]);
}

TEST(LensPsf, FrontHardBackSoftAndTheReverse)
{
    // Under-corrected spherical aberration: front bokeh hard-edged (a bright rim), back
    // bokeh soft (as Kawase's talk shows); reversing the aberration's sign reverses them. The
    // rim is the outer fifth of the bokeh's own extent (aberration changes its size).
    auto rim_ratio = [](const bokeh::Psf& p) {
        const double R = outer_radius(p);
        return annulus_mean(p, 1, 0.8 * R, 0.95 * R) / annulus_mean(p, 1, 0.0, 0.5 * R);
    };
    bokeh::LensCharacter lens;
    lens.preset        = bokeh::LensPreset::Uncorrected;
    lens.chromatic     = 0.0;
    const double coc   = 96.0;
    const double front = rim_ratio(psf_of(lens, -coc)), back = rim_ratio(psf_of(lens, coc));
    std::cout << "under-corrected: rim / centre front " << front << ", back " << back << "\n";
    EXPECT_GT(front, 1.3);
    EXPECT_LT(back, 0.9);
    lens.monochromatic = -1.0;
    const double front_r = rim_ratio(psf_of(lens, -coc)), back_r = rim_ratio(psf_of(lens, coc));
    std::cout << "over-corrected: rim / centre front " << front_r << ", back " << back_r << "\n";
    EXPECT_LT(front_r, 0.9);
    EXPECT_GT(back_r, 1.3);
}

TEST(LensPsf, AnamorphicFocusSplitSwapsAcrossFocus)
{
    // Horizontal and vertical CoC differ by 20 px: at +10 px the bokeh is a horizontal
    // line 20 px long, at -10 px a vertical one (Kawase's anamorphic bokeh).
    bokeh::LensCharacter lens;
    lens.anamorphic_focus_px = 20.0;
    auto extent = [](const bokeh::Psf& p, bool horizontal) {
        double lo = 1e9, hi = -1e9;
        for (int y = 0; y < p.height; ++y)
            for (int x = 0; x < p.width; ++x)
                if (p.at(x, y, 0) > 1e-4) {
                    const double t = horizontal ? x : y;
                    lo = std::min(lo, t);
                    hi = std::max(hi, t);
                }
        return hi - lo + 1.0;
    };
    const bokeh::Psf back = psf_of(lens, 10.0), front = psf_of(lens, -10.0);
    EXPECT_NEAR(extent(back, true), 20.0, 2.0);
    EXPECT_LE(extent(back, false), 2.0);
    EXPECT_NEAR(extent(front, false), 20.0, 2.0);
    EXPECT_LE(extent(front, true), 2.0);
}

TEST(LensPsf, CatsEyeNarrowsTheBokehAlongTheField)
{
    // At the corner the barrel circle, offset 0.6 pupil radii along the field direction
    // (+x here), cuts the pupil to a lens shape 2 - 0.6 = 1.4 radii wide along x and,
    // through the pupil's centre, 2 sqrt(1 - 0.6^2) = 1.6 tall.
    bokeh::LensCharacter lens;
    lens.catseye = 0.6;
    const double coc = 60.0;
    const bokeh::Psf p = psf_of(lens, coc, 1.0, 0.0, 71);
    double wx = 0.0, wy = 0.0;
    for (int x = 0; x < p.width; ++x)
        wx += p.at(x, p.height / 2, 0) > 0.5 * p.at(p.width / 2, p.height / 2, 0);
    for (int y = 0; y < p.height; ++y)
        wy += p.at(p.width / 2, y, 0) > 0.5 * p.at(p.width / 2, p.height / 2, 0);
    EXPECT_NEAR(wx, 1.4 * coc / 2.0, 1.5);
    EXPECT_NEAR(wy, 1.6 * coc / 2.0, 1.5);
}

TEST(LensPsf, EdgeLawFringeAtTheRim)
{
    // One wavelength, a large CoC at f/8 so the first fringe is several px wide: the rim
    // intensity (relative to the plateau) peaks at d = 0.861 sqrt(l N c) inside the
    // geometric edge at 1.37 I_geo (the edge law's first maximum), averaged over a pixel.
    bokeh::LensCharacter lens;
    lens.diffraction      = bokeh::DiffractionModel::EdgeLaw;
    lens.fstop            = 8.0;
    lens.spectrum.first_nm = 550.0;
    lens.spectrum.last_nm  = 550.0;
    const double coc = 200.0;
    const bokeh::Psf p = psf_of(lens, coc);
    const double scale = bokeh::fringe_scale_px(coc, lens.fstop, 550.0, lens.pixel_pitch_mm);
    ASSERT_GT(scale, 4.0) << "fringe scale px";
    const std::vector<double> prof = radial_profile(p, 1);
    const double plateau = annulus_mean(p, 1, 0.0, 0.5 * coc / 2.0);
    // The brightest ring within three fringe scales of the edge.
    const size_t lo = size_t(coc / 2.0 - 3.0 * scale), hi = size_t(coc / 2.0);
    size_t best = lo;
    for (size_t r = lo; r <= hi; ++r)
        if (prof[r] > prof[best])
            best = r;
    const double d = coc / 2.0 - double(best);
    std::cout << "first fringe at d = " << d << " px (law " << 0.861 * scale << "), height "
              << prof[best] / plateau << " I_geo\n";
    EXPECT_NEAR(d, 0.861 * scale, 1.0);
    EXPECT_NEAR(prof[best] / plateau, 1.37, 0.12);
    // At the geometric edge a quarter of the plateau.
    EXPECT_NEAR(prof[size_t(coc / 2.0)] / plateau, 0.25, 0.1);

    // Kawase's pseudo-diffraction map in its place: unit energy, and a first fringe
    // within the talk's own stated 30 % of the exact law's position.
    lens.diffraction   = bokeh::DiffractionModel::PseudoMap;
    const bokeh::Psf q = psf_of(lens, coc);
    EXPECT_NEAR(channel_sum(q, 1), 1.0, 1e-5);
    const std::vector<double> qprof = radial_profile(q, 1);
    const double qplateau = annulus_mean(q, 1, 0.0, 0.5 * coc / 2.0);
    size_t qbest = lo;
    for (size_t r = lo; r <= hi; ++r)
        if (qprof[r] > qprof[qbest])
            qbest = r;
    const double qd = coc / 2.0 - double(qbest);
    std::cout << "pseudo map: first fringe at d = " << qd << " px, height " << qprof[qbest] / qplateau << " I_geo\n";
    EXPECT_NEAR(qd, 0.861 * scale, 0.3 * 0.861 * scale + 1.0);
    EXPECT_GT(qprof[qbest] / qplateau, 1.05);
}

TEST(LensPsf, AchromatAndApochromatRimColours)
{
    // As Kawase's talk describes them: an achromat leaves a purple soft edge on front bokeh
    // and a green hard edge behind; an apochromat a cyan fringe behind. Measured as the
    // outer rim's colour (each channel over its own interior level) near focus, where axial
    // colour is strongest relative to the CoC.
    auto rim_colour = [](const bokeh::Psf& p, double, int c) {
        const double R = outer_radius(p);
        return annulus_mean(p, c, 0.8 * R, 1.05 * R) / annulus_mean(p, c, 0.0, 0.5 * R);
    };
    bokeh::LensCharacter ach;
    ach.preset = bokeh::LensPreset::Achromat;
    ach.fstop  = 1.4;
    for (double coc : { -24.0, 24.0 }) {
        const bokeh::Psf p = psf_of(ach, coc);
        const double r = rim_colour(p, coc, 0), g = rim_colour(p, coc, 1), b = rim_colour(p, coc, 2);
        std::cout << "achromat " << (coc < 0 ? "front" : "back") << " rim RGB " << r << " " << g << " " << b << "\n";
        if (coc < 0) {
            EXPECT_GT(std::min(r, b), g) << "front rim purple";
        } else {
            EXPECT_GT(g, std::max(r, b)) << "back rim green";
        }
    }
    // The apochromat's own colour is 2.5 um of focus at 50 mm, a twentieth of a pixel at
    // the rim: shown ten times over, as the `chromatic` knob allows.
    bokeh::LensCharacter apo;
    apo.preset    = bokeh::LensPreset::Apochromat;
    apo.fstop     = 1.4;
    apo.chromatic = 10.0;
    const bokeh::Psf p = psf_of(apo, 24.0);
    const double r = rim_colour(p, 24.0, 0), g = rim_colour(p, 24.0, 1), b = rim_colour(p, 24.0, 2);
    std::cout << "apochromat back rim RGB " << r << " " << g << " " << b << "\n";
    EXPECT_GT(std::min(g, b), r) << "back rim cyan";
}

TEST(LensPsf, CacheAndBadInput)
{
    bokeh::PsfCache cache(bokeh::LensCharacter{}, 1);
    std::string err;
    bokeh::PsfRequest a, b, c;
    a.coc_px = 30.0;
    b.coc_px = 30.3;  // the same 1/8-octave bin
    c.coc_px = 40.0;
    auto pa = cache.get(a, err), pb = cache.get(b, err), pc = cache.get(c, err);
    ASSERT_TRUE(pa && pb && pc) << err;
    EXPECT_EQ(pa.get(), pb.get());
    EXPECT_NE(pa.get(), pc.get());
    EXPECT_EQ(cache.size(), 2u);

    bokeh::LensCharacter bad;
    bad.fstop = -2.0;
    bokeh::Psf p;
    EXPECT_FALSE(bokeh::lens_psf(p, bad, a, err));
    EXPECT_NE(err.find("fstop"), std::string::npos) << err;
    bad       = bokeh::LensCharacter{};
    bad.correction = 5.0;
    EXPECT_FALSE(bokeh::lens_psf(p, bad, a, err));
    EXPECT_NE(err.find("correction"), std::string::npos) << err;
    a.coc_px = std::nan("");
    EXPECT_FALSE(bokeh::lens_psf(p, bokeh::LensCharacter{}, a, err));
}

TEST(LensPsf, TheSpritesCocGridHoldsItsStepAndMeetsTheBins)
{
    // psf_coc_steps_around over 0.05 .. 400 px, both signs: the two points bracket the CoC
    // with the weight that places it in log2 |CoC| (in CoC below 1 px), they are at most
    // kPsfGridStepRadius_px apart in rim radius past 1 px (1/8 px in CoC below), every
    // cache bin 2^(b/16) is a grid point, and the grid is continuous across 1 px.
    double widest = 0.0;
    for (double sign : { -1.0, 1.0 })
        for (double a = 0.05; a < 400.0; a *= 1.0137) {
            const double c = sign * a;
            double c0, c1, t;
            bokeh::psf_coc_steps_around(c, c0, c1, t);
            ASSERT_GE(t, 0.0);
            ASSERT_LT(t, 1.0);
            ASSERT_LE(std::abs(c0), a + 1e-9) << c;
            ASSERT_GT(std::abs(c1), a) << c;
            ASSERT_EQ(c0 < 0.0 || (c0 == 0.0 && c < 0.0), c < 0.0) << c;
            if (a < 1.0) {
                EXPECT_NEAR(std::abs(c1) - std::abs(c0), 0.125, 1e-12) << c;
                EXPECT_NEAR(std::abs(c0) + t * 0.125, a, 1e-9) << c;
            } else {
                const double l0 = std::log2(std::abs(c0)), l1 = std::log2(std::abs(c1));
                EXPECT_NEAR(l0 + t * (l1 - l0), std::log2(a), 1e-9) << c;
                EXPECT_LE(0.5 * (std::abs(c1) - std::abs(c0)), bokeh::kPsfGridStepRadius_px + 1e-9) << c;
                widest = std::max(widest, 0.5 * (std::abs(c1) - std::abs(c0)));
            }
        }
    for (int b = 0; b <= 128; b += 7) {
        const double bin = std::exp2(b / double(bokeh::kPsfCocBinsPerOctave));
        double c0, c1, t;
        bokeh::psf_coc_steps_around(bin * (1.0 + 1e-12), c0, c1, t);
        EXPECT_NEAR(c0, bin, 1e-9 * bin) << "bin " << b;
    }
    double c0, c1, t;
    bokeh::psf_coc_steps_around(0.99, c0, c1, t);
    EXPECT_DOUBLE_EQ(c1, 1.0);
    bokeh::psf_coc_steps_around(1.0, c0, c1, t);
    EXPECT_DOUBLE_EQ(c0, 1.0);
    std::printf("[ figures  ] CoC grid: widest step %.3f px in rim radius (bound %.2f)\n", widest,
                bokeh::kPsfGridStepRadius_px);
}

TEST(LensPsf, LateralColourDisplacesRedAndBlueByTheirMagnification)
{
    // The closed form of a magnification per channel: off the axis at field (0.6, 0.3)
    // (H = 0.671), red displaced by 6 px at the corner and blue by -4 px, each channel's
    // centroid sits 6 H and -4 H px from green's along the field's direction (x right, y
    // up) to 0.02 px (the rim's sub-samples land elsewhere on a shifted disk: measured 0.013),
    // and the R-B fringe is 10 H px (to 0.01 px); each channel still sums to 1; green
    // is the PSF without lateral colour, pixel for pixel (centred on the same point); on
    // the axis the PSF is the one without it, bit for bit.
    bokeh::LensCharacter lens;
    lens.preset = bokeh::LensPreset::Achromat;
    bokeh::PsfRequest req;
    req.coc_px  = 20.0;
    req.field_x = 0.6;
    req.field_y = 0.3;
    bokeh::LensCharacter shifted = lens;
    shifted.lateral_r_px         = 6.0;
    shifted.lateral_b_px         = -4.0;
    bokeh::Psf plain, psf;
    std::string err;
    ASSERT_TRUE(bokeh::lens_psf(plain, lens, req, err)) << err;
    ASSERT_TRUE(bokeh::lens_psf(psf, shifted, req, err)) << err;
    double cx[3] = {}, cy[3] = {}, sum[3] = {};
    for (int y = 0; y < psf.height; ++y)
        for (int x = 0; x < psf.width; ++x)
            for (int c = 0; c < 3; ++c) {
                const double v = psf.at(x, y, c);
                sum[c] += v;
                cx[c] += v * (x - psf.width / 2);
                cy[c] += v * (psf.height / 2 - y);  // y up
            }
    const double H = std::hypot(0.6, 0.3);
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(sum[c], 1.0, 1e-5) << "channel " << c;
    EXPECT_NEAR(cx[0] - cx[1], 6.0 * 0.6, 0.02);
    EXPECT_NEAR(cy[0] - cy[1], 6.0 * 0.3, 0.02);
    EXPECT_NEAR(cx[2] - cx[1], -4.0 * 0.6, 0.02);
    EXPECT_NEAR(cy[2] - cy[1], -4.0 * 0.3, 0.02);
    EXPECT_NEAR(std::hypot(cx[0] - cx[2], cy[0] - cy[2]), 10.0 * H, 0.01);
    double worst = 0.0;
    for (int y = 0; y < psf.height; ++y)
        for (int x = 0; x < psf.width; ++x) {
            const int px = x - psf.width / 2 + plain.width / 2, py = y - psf.height / 2 + plain.height / 2;
            const double want = px >= 0 && py >= 0 && px < plain.width && py < plain.height ? plain.at(px, py, 1) : 0.0;
            worst = std::max(worst, std::abs(double(psf.at(x, y, 1)) - want));
        }
    EXPECT_LT(worst, 1e-7) << "green moved";
    std::printf("[ figures  ] lateral colour at H %.3f: R-B fringe %.4f px (closed form %.4f), green within %.1e\n", H,
                std::hypot(cx[0] - cx[2], cy[0] - cy[2]), 10.0 * H, worst);

    req.field_x = req.field_y = 0.0;
    ASSERT_TRUE(bokeh::lens_psf(plain, lens, req, err)) << err;
    ASSERT_TRUE(bokeh::lens_psf(psf, shifted, req, err)) << err;
    EXPECT_EQ(plain.width, psf.width);
    EXPECT_TRUE(plain.rgb == psf.rgb) << "on the axis lateral colour moves nothing";

    shifted.lateral_b_px = std::nan("");
    EXPECT_FALSE(bokeh::lens_psf(psf, shifted, req, err));
    EXPECT_NE(err.find("lateral_b"), std::string::npos) << err;
}
