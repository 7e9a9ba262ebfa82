// wave_optics_fft.cpp — the exact PSF of an arbitrary pupil (bladed, vignetted, rippled,
// aberrated) by a zero-padded 2-D FFT of the pupil function (docs/methods/diffraction.md,
// "Any pupil: the FFT PSF").
//
// Source: Fraunhofer diffraction of the pupil function P(x, y) exp(i 2 pi W(x, y)) into the
// focal plane of the converging wave, defocus being part of W (Goodman, "Introduction to
// Fourier Optics", 3rd ed., 6.4; Born & Wolf 8.8 for the round pupil). prysm and poppy
// compute PSFs the same way; nothing of theirs is used here. The FFT is FFTW's complex 2-D
// transform in double (Frigo and Johnson 2005), planned with FFTW_ESTIMATE under the
// library's one planner lock (fftw_planner.h).
//
// Sampling: M pupil samples across the diameter, zero-padded to F; the
// PSF pixel is lambda N M / F (pi M / F in v) and the PSF repeats every M lambda N, so M must
// exceed the CoC in units of lambda N (8 W20) for the disc not to wrap onto itself, and the
// pupil phase must change by less than pi per sample (M > 4 max |dW/drho|). The default
// M = 8 max |dW/drho| meets both twice over. Each pupil cell averages s x s sub-samples of
// the complex amplitude, so a hard pupil edge is antialiased rather than a staircase; the
// sinc envelope this puts on the PSF is divided out.
// Limits: the pupil is sampled on [-1, 1]^2 only; the Fraunhofer form is paraxial (as is
// every model here); cost F^2 log F: a 1 mm CoC at f/2 and 550 nm is ~900 waves of slope,
// far beyond an affordable grid, so large bokeh are computed at a reduced scale and carried
// by the scaling law (fringes scale with sqrt(lambda N c), the edge law's scale).

#include <bokeh/base.h>
#include <bokeh/parallel.h>
#include <bokeh/wave_optics.h>

#include "base/fftw_planner.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <mutex>

#include <fftw3.h>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using OIIO::Strutil::fmt::format;

namespace {

constexpr int kMaxFft   = 8192;

// The smallest 2^a 3^b 5^c >= n (FFTW is fastest on such sizes).
int next_fast_size(int n)
{
    for (int m = std::max(1, n);; ++m) {
        int r = m;
        for (int p : {2, 3, 5})
            while (r % p == 0)
                r /= p;
        if (r == 1)
            return m;
    }
}

bool fail(std::string* error, const std::string& msg)
{
    if (error)
        *error = msg;
    return false;
}

}  // namespace

Pupil round_pupil(const RadialWavefront& wavefront)
{
    Pupil p;
    p.transmission    = [](double x, double y) { return x * x + y * y <= 1.0 ? 1.0 : 0.0; };
    p.wavefront_waves = [wavefront](double x, double y) {
        return wavefront.waves(std::sqrt(x * x + y * y));
    };
    return p;
}

bool pupil_psf_fft(PupilPsf& out, const Pupil& pupil, double max_slope_waves,
                   const PupilSampling& sampling, std::string* error, int nthreads)
{
    if (!std::isfinite(max_slope_waves) || max_slope_waves < 0)
        return fail(error, format("pupil FFT: wavefront slope {} waves is not a finite value >= 0",
                                  max_slope_waves));
    int M = sampling.pupil_samples;
    if (M == 0)
        M = std::max(64, int(std::ceil(8 * max_slope_waves)));
    if (M < 8 || M > kMaxFft)
        return fail(error, format("pupil FFT: {} pupil samples (8 .. {} allowed)", M, kMaxFft));
    const int F = sampling.fft_size ? sampling.fft_size : next_fast_size(2 * M);
    if (F < M || F > kMaxFft)
        return fail(error, format("pupil FFT: FFT size {} (from {} pupil samples to {} allowed)", F,
                                  M, kMaxFft));
    const int s = sampling.edge_supersample;
    if (s < 1 || s > 16)
        return fail(error, format("pupil FFT: edge supersampling {} (1 .. 16 allowed)", s));

    const size_t n = size_t(F) * size_t(F);
    struct Buffer {
        fftw_complex* data;
        explicit Buffer(size_t n) : data(fftw_alloc_complex(n)) {}
        ~Buffer() { fftw_free(data); }
    } buf(n);
    if (!buf.data)
        return fail(error, format("pupil FFT: cannot allocate {} x {} complex points", F, F));
    std::fill(&buf.data[0][0], &buf.data[0][0] + 2 * n, 0.0);

    // The pupil: cell (i, j) centred at ((i + 1/2) 2 / M - 1, (j + 1/2) 2 / M - 1), placed at
    // offset (F - M) / 2 (any offset gives the same |FFT|^2).
    const int o      = (F - M) / 2;
    const double h   = 2.0 / M;
    const double inv = 1.0 / (double(s) * s);
    parallel_for_chunks(0, M, 16, nthreads, [&](int64_t j0, int64_t j1) {
        for (int64_t j = j0; j < j1; ++j)
            for (int i = 0; i < M; ++i) {
                std::complex<double> a = 0.0;
                for (int b = 0; b < s; ++b)
                    for (int c = 0; c < s; ++c) {
                        const double x = (i + (c + 0.5) / s) * h - 1.0;
                        const double y = (double(j) + (b + 0.5) / s) * h - 1.0;
                        const double t = pupil.transmission ? pupil.transmission(x, y)
                                                            : (x * x + y * y <= 1.0 ? 1.0 : 0.0);
                        if (t == 0.0)
                            continue;
                        const double w = pupil.wavefront_waves ? pupil.wavefront_waves(x, y) : 0.0;
                        a += std::polar(t, 2 * kPi * w);
                    }
                a *= inv;
                fftw_complex& dst = buf.data[size_t(o + j) * size_t(F) + size_t(o + i)];
                dst[0]            = a.real();
                dst[1]            = a.imag();
            }
    });

    fftw_plan plan;
    {
        std::lock_guard<std::mutex> lock(detail::fftw_planner_mutex());
        plan = fftw_plan_dft_2d(F, F, buf.data, buf.data, FFTW_FORWARD, FFTW_ESTIMATE);
    }
    if (!plan)
        return fail(error, format("pupil FFT: FFTW could not plan a {} x {} transform", F, F));
    fftw_execute(plan);
    {
        std::lock_guard<std::mutex> lock(detail::fftw_planner_mutex());
        fftw_destroy_plan(plan);
    }

    // |FFT|^2, the zero frequency moved to (F / 2, F / 2); row sums in double, in row order.
    std::vector<double> power(n);
    std::vector<double> row_sum(size_t(F), 0.0);
    parallel_for_chunks(0, F, 32, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y) {
            const size_t sy = size_t((y + F / 2) % F);
            double sum      = 0.0;
            for (int x = 0; x < F; ++x) {
                const fftw_complex& v = buf.data[sy * size_t(F) + size_t((x + F / 2) % F)];
                const double p        = v[0] * v[0] + v[1] * v[1];
                power[size_t(y) * size_t(F) + size_t(x)] = p;
                sum += p;
            }
            row_sum[size_t(y)] = sum;
        }
    });
    double total = 0.0;
    for (double r : row_sum)
        total += r;
    if (!(total > 0) || !std::isfinite(total))
        return fail(error, "pupil FFT: the pupil lets no light through (or its values are not finite)");

    // Averaging s x s sub-samples over a cell is the pupil convolved with a box one cell
    // wide, sampled: its transform is the pupil's times sinc(x / (M lambda N)) in each axis
    // (x from the axis); divided out here, so only the periodic repeats (aliases) remain.
    if (s > 1) {
        std::vector<double> env(static_cast<size_t>(F));
        for (int x = 0; x < F; ++x) {
            const double t  = kPi * double(x - F / 2) / F;  // pi x / (M lambda N), x in pixels of lambda N M / F
            const double sc = t == 0 ? 1.0 : std::sin(t) / t;
            env[size_t(x)]  = 1.0 / (sc * sc);
        }
        total = 0.0;
        for (int y = 0; y < F; ++y) {
            double sum = 0.0;
            for (int x = 0; x < F; ++x) {
                double& p = power[size_t(y) * size_t(F) + size_t(x)];
                p *= env[size_t(x)] * env[size_t(y)];
                sum += p;
            }
            total += sum;
        }
    }

    OIIO::ImageBuf img(OIIO::ImageSpec(F, F, 1, OIIO::TypeDesc::FLOAT));
    float* px = static_cast<float*>(img.localpixels());
    for (size_t k = 0; k < n; ++k)
        px[k] = float(power[k] / total);
    out.image          = std::move(img);
    out.pixel_lambda_n = double(M) / F;
    out.pixel_v        = kPi * M / F;
    out.pupil_samples  = M;
    return true;
}

}  // namespace bokeh
