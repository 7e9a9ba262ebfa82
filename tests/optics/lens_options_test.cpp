// The lens's options, each against what it means (docs/methods/optics.md), with an
// expectation computed here another way: spherochromatism as the monochromatic aberration
// it scales per wavelength, the spectrum as the weighted sum of one-wavelength PSFs (the
// step, the range) and D65 against the CIE table, the onion rings against their pupil
// pattern (cycles, sharpness, contrast, the centre's offset and its side of the stop) and
// the physical ripple law, the surface noise as a pattern fixed in the pupil, field
// curvature as a CoC added with H^2, astigmatism as second moments of the oval.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <vector>

#include <bokeh/base.h>
#include <bokeh/optics.h>
#include <bokeh/spectrum.h>

#include "psf_support.h"
#include "test_util.h"

using bokeh::kPi;
using namespace bokeh_test;

namespace {

bokeh::LensCharacter one_wavelength(bokeh::LensCharacter lens, double wavelength_nm)
{
    lens.spectrum.first_nm = lens.spectrum.last_nm = wavelength_nm;
    return lens;
}

}  // namespace

TEST(LensOptions, SpherochromatismScalesTheAberrationPerWavelength)
{
    // LSA(s, l) = monochromatic SA3 (1 + spherochromatism (l - 587.6) / 100) (s^2 -
    // correction s^4) without axial colour: at 487.6 nm a spherochromatism of 0.8 leaves
    // 0.2 of the aberration, at 687.6 nm 1.8, at 587.6 nm all of it. So the PSF in that one
    // wavelength is the PSF of a lens with monochromatic = 0.2 (1.8, 1) and no
    // spherochromatism, to float rounding; and it is not the PSF without spherochromatism.
    bokeh::LensCharacter lens;
    lens.preset           = bokeh::LensPreset::Uncorrected;
    lens.chromatic        = 0.0;
    lens.spherochromatism = 0.8;
    for (double coc : { 40.0, -40.0 }) {
        for (const auto& [wavelength, scale] : { std::pair{ 487.6, 0.2 }, { 687.6, 1.8 }, { 587.6, 1.0 } }) {
            bokeh::LensCharacter same = lens;
            same.spherochromatism     = 0.0;
            same.monochromatic        = scale;
            const bokeh::Psf got  = psf_of(one_wavelength(lens, wavelength), coc, 0.0, 0.0, 61);
            const bokeh::Psf want = psf_of(same, coc, 0.0, 0.0, 61);
            EXPECT_LT(psf_difference(got, want), 1e-6 * psf_peak(want)) << wavelength << " nm, coc " << coc;
            if (scale != 1.0) {
                bokeh::LensCharacter without = lens;
                without.spherochromatism     = 0.0;
                EXPECT_GT(psf_difference(got, psf_of(without, coc, 0.0, 0.0, 61)), 0.05 * psf_peak(want))
                    << "spherochromatism changed nothing at " << wavelength << " nm";
            }
        }
    }
    // Its longitudinal aberration, the curve the PSF follows, by the same rule.
    bokeh::LensCharacter plain = lens;
    plain.spherochromatism     = 0.0;
    for (double s : { 0.3, 0.7, 1.0 })
        for (double l : { 450.0, 587.6, 650.0 })
            EXPECT_NEAR(bokeh::longitudinal_aberration_mm(lens, s, l),
                        bokeh::longitudinal_aberration_mm(plain, s, l) * (1.0 + 0.8 * (l - 587.6) / 100.0), 1e-12)
                << s << " " << l;
}

TEST(LensOptions, TheSpectrumIsTheWeightedSumOfItsWavelengths)
{
    // A spectral PSF is sum over the samples of w_c(l) PSF_l (spectrum.h), each PSF_l the
    // lens in that one wavelength. Checked by building the one-wavelength PSFs and summing
    // them here, for a 50 nm step under both illuminants (the step and range set the
    // samples: ceil(310 / 50) + 1 = 8 evenly spaced over 400..710 nm). Tolerance: the
    // spectral PSF tabulates every wavelength's landing radius over one radial grid sized
    // by the widest wavelength, the one-wavelength PSFs each over their own, so the rim's
    // pixels differ by the grid's interpolation: bounded at 2 % of the peak (measured below).
    bokeh::LensCharacter lens;
    lens.preset          = bokeh::LensPreset::Uncorrected;
    lens.spectrum.step_nm = 50.0;
    const double coc     = 36.0;
    const int size       = 61;
    for (bokeh::Illuminant light : { bokeh::Illuminant::EqualEnergy, bokeh::Illuminant::D65 }) {
        lens.spectrum.illuminant = light;
        std::vector<bokeh::SpectralSample> samples;
        std::string err;
        ASSERT_TRUE(bokeh::spectral_samples(samples, lens.spectrum, nullptr, err)) << err;
        ASSERT_EQ(samples.size(), 8u);
        EXPECT_NEAR(samples[1].wavelength_nm - samples[0].wavelength_nm, 310.0 / 7.0, 1e-9);
        EXPECT_EQ(samples.back().wavelength_nm, 710.0);
        const bokeh::Psf got = psf_of(lens, coc, 0.0, 0.0, size);
        std::vector<double> want(got.rgb.size(), 0.0);
        for (const bokeh::SpectralSample& smp : samples) {
            const bokeh::Psf one = psf_of(one_wavelength(lens, smp.wavelength_nm), coc, 0.0, 0.0, size);
            ASSERT_EQ(one.rgb.size(), want.size());
            for (size_t i = 0; i < want.size(); ++i)
                want[i] += smp.rgb_weight[i % 3] * one.at(int(i / 3) % size, int(i / 3) / size, 1);
        }
        double worst = 0.0, peak = 0.0;
        for (size_t i = 0; i < want.size(); ++i) {
            worst = std::max(worst, std::abs(double(got.rgb[i]) - want[i]));
            peak  = std::max(peak, want[i]);
        }
        std::printf("[ figures  ] spectral PSF vs the weighted sum of 8 one-wavelength PSFs (%s): "
                    "worst %.3g of the peak\n",
                    light == bokeh::Illuminant::D65 ? "D65" : "equal energy", worst / peak);
        EXPECT_LT(worst, 0.02 * peak);
    }
    // The step is what samples the spectrum: a finer step is a different (converging) PSF.
    bokeh::LensCharacter fine = lens, finer = lens;
    fine.spectrum.step_nm  = 10.0;
    finer.spectrum.step_nm = 5.0;
    const bokeh::Psf coarse_psf = psf_of(lens, coc, 0.0, 0.0, size), fine_psf = psf_of(fine, coc, 0.0, 0.0, size),
                     finer_psf = psf_of(finer, coc, 0.0, 0.0, size);
    EXPECT_LT(psf_difference(fine_psf, finer_psf), psf_difference(coarse_psf, finer_psf));
}

TEST(LensOptions, D65WeighsEachWavelengthByTheCieTable)
{
    // Under D65 each sample's weight is the equal-energy weight times the illuminant's
    // relative power S(l), renormalised per channel: the ratio of the two weights at l,
    // divided by that at 560 nm, is S(l) / S(560), CIE 15:2004 table T.1 (D65, 10 nm).
    const double cie_d65[] = { 82.7549, 91.486,  93.4318, 86.6823, 104.865, 117.008, 117.812, 114.861,
                               115.923, 108.811, 109.354, 107.802, 104.790, 107.689, 104.405, 104.046,
                               100.000, 96.3342, 95.788,  88.6856, 90.0062, 89.5991, 87.6987, 83.2886,
                               83.6992, 80.0268, 80.2146, 82.2778, 78.2842, 69.7213, 71.6091 };
    bokeh::SpectrumOptions o;
    o.first_nm = 400.0;
    o.last_nm  = 700.0;
    o.step_nm  = 10.0;
    std::vector<bokeh::SpectralSample> equal, d65;
    std::string err;
    ASSERT_TRUE(bokeh::spectral_samples(equal, o, nullptr, err)) << err;
    o.illuminant = bokeh::Illuminant::D65;
    ASSERT_TRUE(bokeh::spectral_samples(d65, o, nullptr, err)) << err;
    ASSERT_EQ(equal.size(), 31u);
    ASSERT_EQ(d65.size(), 31u);
    // Green carries weight at every wavelength of the range (its colour-matching sum is
    // positive throughout); the table is quoted to 2 decimals in the code: 1e-4 relative.
    const double at560 = d65[16].rgb_weight[1] / equal[16].rgb_weight[1];
    for (size_t i = 0; i < 31; ++i) {
        if (std::abs(equal[i].rgb_weight[1]) < 1e-3)
            continue;
        const double ratio = d65[i].rgb_weight[1] / equal[i].rgb_weight[1] / at560;
        EXPECT_NEAR(ratio, cie_d65[i] / 100.0, 1e-4 * cie_d65[i] / 100.0) << d65[i].wavelength_nm << " nm";
    }
    // And it changes a chromatic PSF: D65's blue-heavy light moves blue's share.
    bokeh::LensCharacter lens;
    lens.preset = bokeh::LensPreset::Uncorrected;
    bokeh::LensCharacter daylight = lens;
    daylight.spectrum.illuminant  = bokeh::Illuminant::D65;
    const bokeh::Psf white = psf_of(lens, 36.0, 0.0, 0.0, 61);
    EXPECT_GT(psf_difference(white, psf_of(daylight, 36.0, 0.0, 0.0, 61)), 0.01 * psf_peak(white));
}

TEST(LensOptions, OnionRingsFollowTheirPupilPattern)
{
    // A plain round aperture lands pupil radius s at image radius s |c| / 2, so inside the
    // disk the PSF is the pupil's ring pattern, scaled: rings per diameter (onioncycles),
    // their profile (onionsharpness), their depth (onion), and off the axis their centre
    // moved onionoffset H pupil radii along the field direction (behind the stop), or
    // against it (in front of the stop, onionfront), point-reflected in a front bokeh.
    // Tolerance: the PSF samples the pattern at each pixel's centre (one sample a pixel at
    // these sizes), as it is evaluated here; its ring table is linear between entries 0.01
    // rad of phase apart (within 1.3e-5 of the amplitude): 1e-4 of the intensity (measured
    // 4e-6 to 2.3e-5). A cycle count 15 % off, a sharpness 1 higher or the centre on the
    // other side is off by percents.
    struct Case {
        double cycles, sharpness, contrast, offset, fx, fy;
        bool front;
        double coc;
    };
    const Case cases[] = {
        { 6.0, 1.0, 0.5, 0.3, 0.0, 0.0, false, 120.0 },  { 10.0, 4.0, 0.8, 0.3, 0.0, 0.0, false, 120.0 },
        { 4.0, 2.0, 0.6, 0.5, 1.0, 0.0, false, 120.0 },  { 4.0, 2.0, 0.6, 0.5, 1.0, 0.0, true, 120.0 },
        { 4.0, 2.0, 0.6, 0.4, 0.3, 0.5, false, -100.0 }, { 4.0, 2.0, 0.6, -0.8, 0.0, 0.7, true, 100.0 },
    };
    for (const Case& k : cases) {
        bokeh::LensCharacter lens;
        lens.onion             = k.contrast;
        lens.onion_cycles      = k.cycles;
        lens.onion_sharpness   = k.sharpness;
        lens.onion_offset      = k.offset;
        lens.onion_behind_stop = !k.front;
        const bokeh::Psf p     = psf_of(lens, k.coc, k.fx, k.fy);
        const double side      = k.front ? -1.0 : 1.0;
        OnionPattern pattern{ k.cycles, k.sharpness, k.contrast, side * k.offset * k.fx, side * k.offset * k.fy };
        const double misfit = onion_misfit(p, k.coc, pattern);
        std::printf("[ figures  ] rings K %g p %g offset %g%s at (%g, %g), coc %g: within %.2g of the pattern\n",
                    k.cycles, k.sharpness, k.offset, k.front ? " front" : "", k.fx, k.fy, k.coc, misfit);
        EXPECT_LT(misfit, 1e-4) << "cycles " << k.cycles << " sharpness " << k.sharpness << " offset " << k.offset
                                 << " front " << k.front << " coc " << k.coc;
        // Each parameter moved: the pattern no longer fits.
        OnionPattern wrong_cycles = pattern, wrong_sharpness = pattern, wrong_centre = pattern;
        wrong_cycles.cycles *= 1.15;
        wrong_sharpness.sharpness += 1.0;
        wrong_centre.centre_x = -pattern.centre_x + (k.fx == 0.0 && k.fy == 0.0 ? 0.2 : 0.0);
        wrong_centre.centre_y = -pattern.centre_y;
        EXPECT_GT(onion_misfit(p, k.coc, wrong_cycles), 0.01);
        EXPECT_GT(onion_misfit(p, k.coc, wrong_sharpness), 0.01);
        EXPECT_GT(onion_misfit(p, k.coc, wrong_centre), 0.01);
    }
}

TEST(LensOptions, PhysicalRingsFollowTheRippleLaw)
{
    // A ripple of a waves with K cycles across the pupil gives rings of contrast
    // 2 (2 pi a) |sin(pi K^2 / (8 w))| in light of wavelength l, w = W20 / l the defocus
    // in waves, W20 = c pitch / (8 N) (docs/methods/optics.md, "Onion rings"). In one
    // wavelength the PSF with onion_waves = a is the PSF with that procedural contrast, to
    // float rounding; where K^2 / (8 w) = 1 the rings vanish.
    bokeh::LensCharacter lens;
    lens.onion_waves  = 0.1;
    lens.onion_cycles = 10.0;
    const double wavelength_nm = 550.0;
    auto w20_waves = [&](double coc_px) {
        return std::abs(coc_px) * lens.pixel_pitch_mm / (8.0 * lens.fstop) / (wavelength_nm * 1e-6);
    };
    for (double coc : { 100.0, -70.0 }) {
        const double law = 4.0 * kPi * lens.onion_waves
                           * std::abs(std::sin(kPi * lens.onion_cycles * lens.onion_cycles / (8.0 * w20_waves(coc))));
        bokeh::LensCharacter procedural;
        procedural.onion_cycles = lens.onion_cycles;
        procedural.onion        = law;
        const bokeh::Psf got = psf_of(one_wavelength(lens, wavelength_nm), coc, 0.0, 0.0, 121);
        EXPECT_LT(psf_difference(got, psf_of(procedural, coc, 0.0, 0.0, 121)), 1e-6 * psf_peak(got)) << coc;
        EXPECT_GT(law, 0.1) << "the case must show rings";
        EXPECT_GT(psf_difference(got, psf_of(bokeh::LensCharacter(), coc, 0.0, 0.0, 121)), 0.05 * psf_peak(got));
    }
    // The CoC where pi K^2 / (8 w) = pi: w = K^2 / 8 waves.
    const double coc_null = lens.onion_cycles * lens.onion_cycles / 8.0 * (8.0 * lens.fstop) * (wavelength_nm * 1e-6)
                            / lens.pixel_pitch_mm;
    const bokeh::Psf at_null = psf_of(one_wavelength(lens, wavelength_nm), coc_null, 0.0, 0.0, 61);
    EXPECT_LT(psf_difference(at_null, psf_of(bokeh::LensCharacter(), coc_null, 0.0, 0.0, 61)), 1e-6 * psf_peak(at_null))
        << "no rings at " << coc_null << " px";
}

TEST(LensOptions, SurfaceNoiseIsAPatternFixedInThePupil)
{
    // The noise multiplies the pupil's transmission by 1 + n N(p), then the PSF is
    // renormalised: inside the disk, where the plain PSF is uniform, the ratio to it is
    // r_n = K_n (1 + n N) with K_n = 1 / (1 + n <N>) (<N> the disk's mean). So r_0.3 is an
    // affine function of r_0.15 over the pixels, slope 2 K_0.3 / K_0.15 (2 within the
    // noise's mean, |<N>| << 1), exactly (float rounding); the pattern is fixed in the
    // pupil, so a front bokeh is the back one point-reflected; and it is visible.
    bokeh::LensCharacter plain, light = plain, strong = plain;
    light.surface_noise  = 0.15;
    strong.surface_noise = 0.3;
    const double coc     = 80.0;
    const bokeh::Psf p0 = psf_of(plain, coc), p1 = psf_of(light, coc), p2 = psf_of(strong, coc);
    const bokeh::Psf front = psf_of(strong, -coc);
    ASSERT_EQ(p0.width, p2.width);
    ASSERT_EQ(p0.width, front.width);
    std::vector<double> r1, r2;
    double reflect = 0.0;
    for (int y = 0; y < p0.height; ++y)
        for (int x = 0; x < p0.width; ++x) {
            if (std::hypot(x - p0.width / 2, y - p0.height / 2) > 0.45 * coc)
                continue;
            r1.push_back(p1.at(x, y, 1) / p0.at(x, y, 1));
            r2.push_back(p2.at(x, y, 1) / p0.at(x, y, 1));
            reflect = std::max(reflect, double(std::abs(front.at(p0.width - 1 - x, p0.height - 1 - y, 1) - p2.at(x, y, 1))));
        }
    // Least squares r2 = slope r1 + offset.
    const double n = double(r1.size());
    double m1 = 0.0, m2 = 0.0;
    for (size_t i = 0; i < r1.size(); ++i) {
        m1 += r1[i] / n;
        m2 += r2[i] / n;
    }
    double s11 = 0.0, s12 = 0.0, s22 = 0.0;
    for (size_t i = 0; i < r1.size(); ++i) {
        s11 += (r1[i] - m1) * (r1[i] - m1);
        s12 += (r1[i] - m1) * (r2[i] - m2);
        s22 += (r2[i] - m2) * (r2[i] - m2);
    }
    const double slope = s12 / s11, offset = m2 - slope * m1;
    double residual = 0.0;
    for (size_t i = 0; i < r1.size(); ++i)
        residual = std::max(residual, std::abs(r2[i] - (slope * r1[i] + offset)));
    const double spread = std::sqrt(s22 / n) / m2;
    std::printf("[ figures  ] surface noise 0.3: spread %.4f of the mean; r(0.3) = %.4f r(0.15) %+.4f within %.2g; "
                "front vs back reflected %.2g\n",
                spread, slope, offset, residual, reflect);
    EXPECT_GT(spread, 0.02) << "the noise is visible";
    EXPECT_LT(spread, 0.3) << "and no larger than the contrast asked for";
    EXPECT_NEAR(slope, 2.0, 0.3);
    EXPECT_LT(residual, 1e-5);
    EXPECT_LT(reflect, 1e-6 * psf_peak(p2));
}

TEST(LensOptions, FieldCurvatureAddsCocWithTheSquareOfTheFieldHeight)
{
    // CoC(H) = c + fieldcurvature H^2: off the axis the PSF is the one of that CoC on the
    // axis (a lens whose other effects do not change with field), across focus too.
    bokeh::LensCharacter lens;
    lens.preset = bokeh::LensPreset::Uncorrected;
    bokeh::LensCharacter curved = lens;
    struct Case {
        double coc, curvature, fx, fy;
    };
    for (const Case& k : { Case{ 20.0, 40.0, 0.6, 0.0 }, Case{ 10.0, -50.0, 0.36, -0.48 }, Case{ -12.0, 30.0, 0.0, 0.9 } }) {
        curved.field_curvature_px = k.curvature;
        const double h2           = k.fx * k.fx + k.fy * k.fy;
        const bokeh::Psf got      = psf_of(curved, k.coc, k.fx, k.fy, 81);
        const bokeh::Psf want     = psf_of(lens, k.coc + k.curvature * h2, 0.0, 0.0, 81);
        EXPECT_LT(psf_difference(got, want), 1e-6 * psf_peak(want)) << k.coc << " " << k.curvature;
        EXPECT_GT(psf_difference(got, psf_of(lens, k.coc, k.fx, k.fy, 81)), 0.1 * psf_peak(want));
    }
}

TEST(LensOptions, AstigmatismMakesOvalsThatSwapAcrossFocus)
{
    // The tangential (along the field direction t) and sagittal CoCs are c + A H^2 / 2 and
    // c - A H^2 / 2: an ellipse of uniform intensity, whose second moment along each axis is
    // (diameter / 4)^2, plus the pixel's own 1/12 px^2. At field (0.5, 0.5), A = 24: 66 px
    // radially and 54 px across at c = 60 (a radial oval), swapped at c = -60 (a tangential
    // one, the "swirl"); the long axis along t = (1, 1) / sqrt 2 (x right, y up).
    // Tolerance: the rim's anti-aliasing, 1 % of the variance.
    bokeh::LensCharacter lens;
    lens.astigmatism_px = 24.0;
    const double fx = 0.5, fy = 0.5, h2 = fx * fx + fy * fy;
    for (double coc : { 60.0, -60.0 }) {
        const PsfMoments m = psf_moments(psf_of(lens, coc, fx, fy), 1);
        // Along t and n = (-1, 1) / sqrt 2.
        const double var_t = 0.5 * (m.var_x + m.var_y) + m.cov_xy, var_n = 0.5 * (m.var_x + m.var_y) - m.cov_xy;
        const double d_t = std::abs(coc + 0.5 * lens.astigmatism_px * h2), d_n = std::abs(coc - 0.5 * lens.astigmatism_px * h2);
        EXPECT_NEAR(var_t, d_t * d_t / 16.0 + 1.0 / 12.0, 0.01 * d_t * d_t / 16.0) << coc;
        EXPECT_NEAR(var_n, d_n * d_n / 16.0 + 1.0 / 12.0, 0.01 * d_n * d_n / 16.0) << coc;
        EXPECT_NEAR(m.var_x, m.var_y, 0.01 * m.var_x) << "the axes are the diagonals";
        EXPECT_NEAR(m.mean_x, 0.0, 0.01);
        EXPECT_NEAR(m.mean_y, 0.0, 0.01);
    }
    // On the axis there is no astigmatism (H = 0).
    EXPECT_LT(psf_difference(psf_of(lens, 60.0), psf_of(bokeh::LensCharacter(), 60.0)), 1e-7);
}
