// synthetic_crop.cpp — a known lens's highlight rendered as a plate would hold it (lens_fit.h):
// the round trips of the lens fit (tests/fit/, bokeh-bench --task lensfit) and its demo.
// The noise is Gaussian with the variance of photon noise (sigma^2 = g v, g from the SNR
// at the peak) plus a read noise of 1 % of the peak's; a Poisson draw would differ only
// at counts of a few photons, below any plate's highlight.

#include <bokeh/lens_fit.h>

#include <algorithm>
#include <cmath>
#include <random>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

bool synthetic_crop(LensFitCrop& dst, const LensCharacter& lens, const SyntheticCrop& spec, std::string& err,
                    int nthreads)
{
    if (spec.size_px < 9 || spec.size_px > 4095 || !(spec.peak_snr >= 0.0) || !(spec.clip >= 0.0))
        return err = "synthetic_crop: size 9..4095 px, SNR and clip >= 0", false;
    PsfRequest req;
    req.coc_px  = spec.coc_px;
    req.field_x = spec.field_x, req.field_y = spec.field_y;
    req.size_px = spec.size_px | 1;
    Psf p;
    if (!lens_psf(p, lens, req, err, nthreads))
        return false;
    double peak = 0.0;
    for (int j = 0; j < p.height; ++j)
        for (int i = 0; i < p.width; ++i)
            for (int c = 0; c < 3; ++c)
                peak = std::max(peak, spec.energy[c] * p.at(i, j, c));
    const double gain = spec.peak_snr > 0 ? peak / (spec.peak_snr * spec.peak_snr) : 0.0;
    const double read = spec.peak_snr > 0 ? 0.01 * peak / spec.peak_snr : 0.0;
    std::mt19937 rng(spec.seed);
    std::normal_distribution<double> n01(0.0, 1.0);
    const int n = spec.size_px;
    OIIO::ImageBuf img(OIIO::ImageSpec(n, n, 3, OIIO::TypeDesc::FLOAT));
    std::vector<float> px(size_t(n) * n * 3);
    const int ox = (n - p.width) / 2 + spec.offset_x, oy = (n - p.height) / 2 + spec.offset_y;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            for (int c = 0; c < 3; ++c) {
                const int pi = i - ox, pj = j - oy;
                const double light
                    = (pi >= 0 && pj >= 0 && pi < p.width && pj < p.height) ? spec.energy[c] * p.at(pi, pj, c) : 0.0;
                double v = light + spec.background[c] + spec.gradient_x * (i - n / 2) + spec.gradient_y * (j - n / 2);
                if (spec.peak_snr > 0)
                    v += std::sqrt(gain * std::max(v, 0.0) + read * read) * n01(rng);
                if (spec.clip > 0)
                    v = std::min(v, spec.clip);
                px[(size_t(j) * n + i) * 3 + c] = float(v);
            }
    img.set_pixels(img.roi(), OIIO::TypeDesc::FLOAT, px.data());
    dst.image   = img;
    dst.field_x = spec.field_x, dst.field_y = spec.field_y;
    return true;
}

}  // namespace bokeh
