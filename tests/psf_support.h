// psf_support.h — small measurements of a lens PSF (bokeh::Psf) shared by the optics
// tests: the PSF of a request, per-channel sums, radial profiles and second moments.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <OpenImageIO/imagebuf.h>

#include <bokeh/base.h>
#include <bokeh/optics.h>

namespace bokeh_test {

inline bokeh::Psf psf_of(const bokeh::LensCharacter& lens, double coc, double fx = 0.0, double fy = 0.0,
                         int size = 0)
{
    bokeh::Psf p;
    bokeh::PsfRequest r;
    r.coc_px  = coc;
    r.field_x = fx;
    r.field_y = fy;
    r.size_px = size;
    std::string err;
    EXPECT_TRUE(bokeh::lens_psf(p, lens, r, err, 2)) << err;
    return p;
}

// Mean of channel c over rings 1 px wide about the centre.
inline std::vector<double> radial_profile(const bokeh::Psf& p, int c)
{
    const int cx = p.width / 2, cy = p.height / 2;
    std::vector<double> sum(size_t(std::max(cx, cy) + 2), 0.0), n(sum.size(), 0.0);
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x) {
            const size_t r = size_t(std::lround(std::hypot(x - cx, y - cy)));
            if (r < sum.size()) {
                sum[r] += p.at(x, y, c);
                n[r] += 1.0;
            }
        }
    for (size_t i = 0; i < sum.size(); ++i)
        sum[i] = n[i] > 0 ? sum[i] / n[i] : 0.0;
    return sum;
}

inline double channel_sum(const bokeh::Psf& p, int c)
{
    double s = 0.0;
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x)
            s += p.at(x, y, c);
    return s;
}

// Mean over the annulus lo <= r < hi (in px) of channel c.
inline double annulus_mean(const bokeh::Psf& p, int c, double lo, double hi)
{
    const int cx = p.width / 2, cy = p.height / 2;
    double s = 0.0, n = 0.0;
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x) {
            const double r = std::hypot(x - cx, y - cy);
            if (r >= lo && r < hi) {
                s += p.at(x, y, c);
                n += 1.0;
            }
        }
    return n > 0 ? s / n : 0.0;
}

// The bokeh's outer radius: the last ring whose green mean is above 2 % of the largest.
inline double outer_radius(const bokeh::Psf& p)
{
    const std::vector<double> prof = radial_profile(p, 1);
    const double peak = *std::max_element(prof.begin(), prof.end());
    size_t r = prof.size() - 1;
    while (r > 0 && prof[r] < 0.02 * peak)
        --r;
    return double(r) + 0.5;
}

// Channel c's centroid and central second moments, in px from the PSF's centre pixel
// (x right, y up).
struct PsfMoments {
    double mean_x = 0.0, mean_y = 0.0;
    double var_x = 0.0, var_y = 0.0, cov_xy = 0.0;
};

inline PsfMoments psf_moments(const bokeh::Psf& p, int c)
{
    PsfMoments m;
    double sum = 0.0;
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x) {
            const double v = p.at(x, y, c);
            sum += v;
            m.mean_x += v * (x - p.width / 2);
            m.mean_y += v * (p.height / 2 - y);
        }
    m.mean_x /= sum;
    m.mean_y /= sum;
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x) {
            const double v  = p.at(x, y, c) / sum;
            const double dx = (x - p.width / 2) - m.mean_x, dy = (p.height / 2 - y) - m.mean_y;
            m.var_x += v * dx * dx;
            m.var_y += v * dy * dy;
            m.cov_xy += v * dx * dy;
        }
    return m;
}

// The largest |a - b| of two PSFs of one size, over every channel.
inline double psf_difference(const bokeh::Psf& a, const bokeh::Psf& b)
{
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    if (a.rgb.size() != b.rgb.size())
        return 1e30;
    double worst = 0.0;
    for (size_t i = 0; i < a.rgb.size(); ++i)
        worst = std::max(worst, double(std::abs(a.rgb[i] - b.rgb[i])));
    return worst;
}

inline double psf_peak(const bokeh::Psf& p)
{
    return *std::max_element(p.rgb.begin(), p.rgb.end());
}

// The mean of |cos t|^p over a period, by the midpoint rule (the code uses the Gamma-function
// closed form; this is the integral itself).
inline double mean_abs_cos_pow(double p)
{
    const int n = 200000;
    double s    = 0.0;
    for (int i = 0; i < n; ++i)
        s += std::pow(std::abs(std::cos(bokeh::kPi * (i + 0.5) / n)), p);
    return s / n;
}

// The onion-ring pattern as docs/methods/optics.md defines it: at pupil distance rho from
// the rings' centre, (|cos(pi K rho / 2)|^p - m_p) / max(m_p, 1 - m_p), mean 0 over a period.
struct OnionPattern {
    double cycles = 10.0, sharpness = 1.0, contrast = 0.5;
    double centre_x = 0.0, centre_y = 0.0;  // in pupil radii (x right, y up)
    double operator()(double px, double py) const
    {
        static thread_local double cached_p = -1.0, cached_m = 0.0;
        if (sharpness != cached_p) {
            cached_p = sharpness;
            cached_m = mean_abs_cos_pow(sharpness);
        }
        const double rho  = std::hypot(px - centre_x, py - centre_y);
        const double wave = std::pow(std::abs(std::cos(0.5 * bokeh::kPi * cycles * rho)), sharpness);
        return 1.0 + contrast * (wave - cached_m) / std::max(cached_m, 1.0 - cached_m);
    }
};

// A plain round aperture with rings at CoC `coc` (|coc| / 2 px = one pupil radius; a front
// bokeh, coc < 0, is the pupil point-reflected) against the pattern: over the pixels within
// 0.9 of the radius, the PSF / pattern ratio's spread about its mean (the disk's uniform
// intensity), as a fraction of that mean.
inline double onion_misfit(const bokeh::Psf& p, double coc, const OnionPattern& pattern)
{
    const double radius = 0.5 * std::abs(coc), sign = coc < 0.0 ? -1.0 : 1.0;
    std::vector<double> ratio;
    for (int y = 0; y < p.height; ++y)
        for (int x = 0; x < p.width; ++x) {
            const double ix = x - p.width / 2, iy = p.height / 2 - y;  // image px, y up
            if (std::hypot(ix, iy) > 0.9 * radius)
                continue;
            ratio.push_back(p.at(x, y, 1) / pattern(sign * ix / radius, sign * iy / radius));
        }
    double mean = 0.0;
    for (double r : ratio)
        mean += r;
    mean /= double(ratio.size());
    double worst = 0.0;
    for (double r : ratio)
        worst = std::max(worst, std::abs(r / mean - 1.0));
    return worst;
}

// A PSF read back from an image (bokehtool --bokeh's output), its data window centred.
inline bokeh::Psf psf_from_image(const OIIO::ImageBuf& img)
{
    bokeh::Psf p;
    p.width  = img.spec().width;
    p.height = img.spec().height;
    p.rgb.resize(size_t(p.width) * p.height * 3);
    img.get_pixels(img.roi(), OIIO::TypeFloat, p.rgb.data());
    return p;
}

}  // namespace bokeh_test
