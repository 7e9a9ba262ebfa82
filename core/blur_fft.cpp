// blur_fft.cpp — convolution with an image kernel (any shape, colour allowed) by FFT.
//
// The padded source plane and each kernel channel are transformed with FFTW's real 2-D
// transforms (Frigo and Johnson 2005), multiplied, and transformed back. Cyclic
// convolution on an N x M grid equals the linear one on every output whose footprint
// lies inside the padded plane when N and M are at least the plane's size, so the plane
// is only rounded up to a size FFTW does fast (a product of 2, 3, 5, 7). Cost:
// O(N M log(N M)) per channel whatever the kernel, which beats spans once kernels are
// irregular (a scanned aperture, a dirty-lens image) and large.
//
// Double precision throughout: float FFTs leave noise of ~1e-7 of the frame's largest
// value everywhere, and a 1e6 highlight would then put ~0.1 into black areas.
// Known limit: memory is about 3 double planes per channel in flight.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "plane.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <mutex>

#include <fftw3.h>

namespace bokeh {

using namespace detail;

namespace {

// FFTW's planner is not thread-safe; execution of a made plan on new arrays is.
std::mutex& planner_mutex()
{
    static std::mutex m;
    return m;
}

int fast_size(int n)
{
    for (int m = std::max(1, n);; ++m) {
        int r = m;
        for (int p : { 2, 3, 5, 7 })
            while (r % p == 0)
                r /= p;
        if (r == 1)
            return m;
    }
}

struct FftBuffer {
    double* data = nullptr;
    explicit FftBuffer(size_t n) : data(static_cast<double*>(fftw_malloc(n * sizeof(double)))) {}
    ~FftBuffer() { fftw_free(data); }
    FftBuffer(const FftBuffer&)            = delete;
    FftBuffer& operator=(const FftBuffer&) = delete;
};

struct Plans {
    fftw_plan forward = nullptr, backward = nullptr;
    Plans(int ny, int nx)
    {
        const size_t nreal = size_t(ny) * size_t(nx), ncomplex = size_t(ny) * size_t(nx / 2 + 1);
        FftBuffer real(nreal), cplx(2 * ncomplex);
        std::lock_guard<std::mutex> lock(planner_mutex());
        forward  = fftw_plan_dft_r2c_2d(ny, nx, real.data, reinterpret_cast<fftw_complex*>(cplx.data),
                                        FFTW_ESTIMATE);
        backward = fftw_plan_dft_c2r_2d(ny, nx, reinterpret_cast<fftw_complex*>(cplx.data), real.data,
                                        FFTW_ESTIMATE);
    }
    ~Plans()
    {
        std::lock_guard<std::mutex> lock(planner_mutex());
        fftw_destroy_plan(forward);
        fftw_destroy_plan(backward);
    }
};

}  // namespace

bool convolve_image(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ImageBuf& kernel,
                    const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    if (!check_source(dst, src) || !check_source(dst, kernel, "blur kernel image"))
        return false;
    OIIO::ImageBuf src_holder, kernel_holder;
    const OIIO::ImageBuf& in = float_source(src, src_holder);
    const OIIO::ImageBuf& kf = float_source(kernel, kernel_holder);
    const OIIO::ROI kr       = kf.roi();
    const int knc = kf.nchannels(), nc = in.nchannels();
    if (kr.width() > 4096 || kr.height() > 4096) {
        dst.errorfmt("blur: the kernel image is {}x{}; at most 4096x4096", kr.width(), kr.height());
        return false;
    }

    // Kernel channels, normalised; source channel c -> kernel plane kmap[c].
    std::vector<std::vector<double>> kplanes(static_cast<size_t>(knc));
    for (int c = 0; c < knc; ++c) {
        std::vector<double>& k = kplanes[size_t(c)];
        double sum = 0.0;
        for (OIIO::ImageBuf::ConstIterator<float> it(kf); !it.done(); ++it) {
            if (!std::isfinite(it[c])) {
                dst.errorfmt("blur: the kernel image has a non-finite value at ({}, {})", it.x(), it.y());
                return false;
            }
            k.push_back(it[c]);
            sum += it[c];
        }
        if (!(sum > 0.0)) {
            dst.errorfmt("blur: kernel image channel {} sums to {}; it must be positive", c, sum);
            return false;
        }
        for (double& v : k)
            v /= sum;
    }
    std::vector<int> kmap(static_cast<size_t>(nc));
    if (knc > 1 && knc < nc) {  // the extra source channels use the kernel channels' mean
        std::vector<double> mean(kplanes[0].size(), 0.0);
        for (const auto& k : kplanes)
            for (size_t i = 0; i < k.size(); ++i)
                mean[i] += k[i] / knc;
        kplanes.push_back(std::move(mean));
    }
    for (int c = 0; c < nc; ++c)
        kmap[size_t(c)] = knc == 1 ? 0 : (c < knc ? c : knc);

    // Centre and reach.
    const int cx = kr.xbegin + kr.width() / 2, cy = kr.ybegin + kr.height() / 2;
    const int rx = std::max(cx - kr.xbegin, kr.xend - 1 - cx);
    const int ry = std::max(cy - kr.ybegin, kr.yend - 1 - cy);
    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), rx, ry) : in.roi();
    Plane p = pad(in, grown(roi, rx, ry), opts.border, nthreads);
    Iris iris;
    if (opts.iris != 0.0f) {
        iris.k     = opts.iris;
        iris.alpha = in.spec().alpha_channel;
        iris.z     = in.spec().z_channel;
        std::string err;
        if (!iris.forward(p, err, nthreads)) {
            dst.errorfmt("blur: {}", err);
            return false;
        }
    }

    const int ny = fast_size(p.h), nx = fast_size(p.w), nxc = nx / 2 + 1;
    const size_t nreal = size_t(ny) * size_t(nx), ncomplex = size_t(ny) * size_t(nxc);
    const Plans plans(ny, nx);
    const double scale = 1.0 / double(nreal);

    // Transforms of the kernel planes in use, the kernel placed cyclically at the origin.
    std::vector<std::unique_ptr<FftBuffer>> kspec(kplanes.size());
    for (int c = 0; c < nc; ++c) {
        const size_t kc = size_t(kmap[size_t(c)]);
        if (kspec[kc])
            continue;
        FftBuffer real(nreal);
        std::fill_n(real.data, nreal, 0.0);
        size_t i = 0;
        for (int y = kr.ybegin; y < kr.yend; ++y)
            for (int x = kr.xbegin; x < kr.xend; ++x, ++i) {
                const int dx = ((x - cx) % nx + nx) % nx, dy = ((y - cy) % ny + ny) % ny;
                real.data[size_t(dy) * size_t(nx) + size_t(dx)] += kplanes[kc][i];
            }
        kspec[kc] = std::make_unique<FftBuffer>(2 * ncomplex);
        fftw_execute_dft_r2c(plans.forward, real.data, reinterpret_cast<fftw_complex*>(kspec[kc]->data));
    }

    Plane out(roi.width(), roi.height(), nc);
    parallel_for_chunks(0, nc, 1, nthreads, [&](int64_t c0, int64_t c1) {
        FftBuffer real(nreal), cplx(2 * ncomplex);
        for (int c = int(c0); c < int(c1); ++c) {
            std::fill_n(real.data, nreal, 0.0);
            for (int y = 0; y < p.h; ++y) {
                const float* r = p.row(y);
                double* o      = real.data + size_t(y) * size_t(nx);
                for (int x = 0; x < p.w; ++x)
                    o[x] = r[size_t(x) * size_t(nc) + size_t(c)];
            }
            auto* spec = reinterpret_cast<std::complex<double>*>(cplx.data);
            fftw_execute_dft_r2c(plans.forward, real.data, reinterpret_cast<fftw_complex*>(cplx.data));
            const auto* k = reinterpret_cast<const std::complex<double>*>(kspec[size_t(kmap[size_t(c)])]->data);
            for (size_t i = 0; i < ncomplex; ++i)
                spec[i] *= k[i] * scale;
            fftw_execute_dft_c2r(plans.backward, reinterpret_cast<fftw_complex*>(cplx.data), real.data);
            // Output (x, y) is the padded plane's (x + rx, y + ry).
            for (int y = 0; y < out.h; ++y) {
                const double* r = real.data + size_t(y + ry) * size_t(nx) + size_t(rx);
                float* o        = out.row(y);
                for (int x = 0; x < out.w; ++x)
                    o[size_t(x) * size_t(nc) + size_t(c)] = float(r[x]);
            }
        }
    });
    if (opts.iris != 0.0f)
        iris.inverse(out, nthreads);
    return finish(dst, in, roi, out, 0, 0, false, nthreads);
}

}  // namespace bokeh
