// blur_nonfinite.cpp — a blur of a source holding NaN or infinities, with each of them
// kept within its own footprint (docs/methods/uniform-kernels.md, "Non-finite source
// values").
//
// Every fast method would carry a non-finite value beyond its footprint: the running and
// prefix sums along the rest of its row and down the columns (and inf - inf is NaN), the
// FFT over its tile. So the blur runs on the source with them replaced, and each output
// whose kernel reaches one takes what the linear convolution (the brute force) gives it.
// Only sources that hold one pay for it: blur() checks with one pass over the source
// (any_nonfinite, about a read of the frame: +1.1-1.9 ms at 1080p RGBA) and comes here
// if any. Limits: in iris mode -inf would count for nothing (exp(k * -inf) = 0); one rule,
// the linear convolution's, is kept for both.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/convolve.h"

#include <cmath>
#include <functional>
#include <limits>
#include <utility>
#include <vector>

namespace bokeh::detail {

// Non-finite source values: a bad value never spreads beyond its own pixel's footprint.
// The running and prefix sums would carry a NaN or an infinity along the rest of its row
// and down the columns (and inf - inf is NaN), the FFT over its tile. So the blur runs on
// the source with them replaced (`clean`: by 0; in iris mode by the channel's least finite
// value, which leaves the range iris mode checks as the data's), and each output whose
// kernel has weight on one of them takes what the linear convolution gives it: an
// infinity (of the sign its weight gives it) where all those it reaches agree, NaN
// otherwise. (In iris mode exp(k * -inf) would be 0, so -inf would count for nothing
// there; one rule is kept for both.) Which outputs they reach: an indicator per channel
// and kind, convolved with the kernel's support (1 where its weight is positive; the
// negative weights of an image kernel, likewise, apart) by row spans, which leave exact
// whole counts, or by the FFT where the exact blur would take it (fft_cheaper_than_spans;
// counts to within 1e-9, read as reached from 0.5). Infinite depth (+inf in Z, "no depth")
// is the common case.
bool blur_nonfinite(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const std::vector<KernelWeights>& kernels,
                    const std::vector<int>& kernel_of, Border border, bool keep_range,
                    const std::function<bool(OIIO::ImageBuf&, const OIIO::ImageBuf&)>& clean, int nthreads)
{
    const OIIO::ROI data = in.roi();
    const int nc         = in.nchannels();
    const size_t ncs     = size_t(nc);
    // Kinds: 0 NaN, 1 +inf, 2 -inf; a negative weight swaps the infinities.
    auto kind = [](float v) { return std::isnan(v) ? 0 : v > 0.0f ? 1 : 2; };
    // Per channel: which kinds it holds (held[3 c + kind]) and its least finite value.
    struct Found {
        std::vector<int> held;
        std::vector<float> least;
    };
    const Found none{ std::vector<int>(3 * ncs, 0),
                      std::vector<float>(ncs, std::numeric_limits<float>::infinity()) };
    const Found found = parallel_reduce_chunks(
        data.ybegin, data.yend, 16, nthreads, none,
        [&](int64_t y0, int64_t y1) {
            Found f = none;
            for (int64_t y = y0; y < y1; ++y) {
                const float* row = static_cast<const float*>(in.pixeladdr(data.xbegin, int(y), data.zbegin));
                for (size_t i = 0; i < size_t(data.width()) * ncs; ++i) {
                    if (std::isfinite(row[i]))
                        f.least[i % ncs] = std::min(f.least[i % ncs], row[i]);
                    else
                        f.held[3 * (i % ncs) + size_t(kind(row[i]))] = 1;
                }
            }
            return f;
        },
        [](Found& acc, const Found& part) {
            for (size_t i = 0; i < acc.held.size(); ++i)
                acc.held[i] |= part.held[i];
            for (size_t c = 0; c < acc.least.size(); ++c)
                acc.least[c] = std::min(acc.least[c], part.least[c]);
        });
    std::vector<float> substitute(ncs, 0.0f);
    if (keep_range)
        for (size_t c = 0; c < ncs; ++c)
            substitute[c] = std::isfinite(found.least[c]) ? found.least[c] : 0.0f;
    OIIO::ImageBuf replaced;
    replaced.copy(in);
    parallel_rows(data, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            auto* row = static_cast<float*>(replaced.pixeladdr(data.xbegin, y, data.zbegin));
            for (size_t i = 0; i < size_t(data.width()) * ncs; ++i)
                if (!std::isfinite(row[i]))
                    row[i] = substitute[i % ncs];
        }
    });
    if (!clean(dst, replaced))
        return false;
    const OIIO::ROI out = dst.roi();
    const size_t npx    = size_t(out.npixels());
    // reached[3 c + kind]: where that kind (after the weights' signs) reaches channel c.
    std::vector<std::vector<char>> reached(3 * ncs);
    for (size_t j = 0; j < kernels.size(); ++j) {
        std::vector<std::pair<int, int>> channels;  // (channel, kind) convolved with kernel j
        for (int c = 0; c < nc; ++c)
            for (int kd = 0; kd < 3; ++kd)
                if (kernel_of[size_t(c)] == int(j) && found.held[size_t(3 * c + kd)])
                    channels.push_back({ c, kd });
        if (channels.empty())
            continue;
        const int nind = int(channels.size());
        OIIO::ImageSpec ispec(data.width(), data.height(), nind, OIIO::TypeFloat);
        ispec.x = data.xbegin;
        ispec.y = data.ybegin;
        OIIO::ImageBuf indicators(ispec, OIIO::InitializePixels::Yes);
        detail::require_pixels(indicators);
        parallel_rows(data, nthreads, [&](int y0, int y1) {
            for (int y = y0; y < y1; ++y) {
                const auto* row = static_cast<const float*>(in.pixeladdr(data.xbegin, y, data.zbegin));
                auto* ind       = static_cast<float*>(indicators.pixeladdr(data.xbegin, y));
                for (int x = 0; x < data.width(); ++x)
                    for (int i = 0; i < nind; ++i) {
                        const float v = row[size_t(x) * ncs + size_t(channels[size_t(i)].first)];
                        ind[size_t(x) * size_t(nind) + size_t(i)]
                            = !std::isfinite(v) && kind(v) == channels[size_t(i)].second ? 1.0f : 0.0f;
                    }
            }
        });
        for (const double sign : { 1.0, -1.0 }) {
            KernelWeights support = kernels[j];
            bool any              = false;
            for (double& w : support.w) {
                w   = w * sign > 0.0 ? 1.0 : 0.0;
                any = any || w > 0.0;
            }
            if (!any)
                continue;
            const std::vector<Span> spans = kernel_spans(reflected(support));
            const bool by_fft = fft_cheaper_than_spans(out.width(), out.height(), nind, support.rx, support.ry, spans);
            OIIO::ImageBuf reach;
            const bool ok = by_fft ? convolve_fft_direct(reach, indicators, out, { support },
                                                         std::vector<int>(size_t(nind), 0), border, nthreads)
                                   : convolve_spans_direct(reach, indicators, out, support.rx, support.ry, spans,
                                                           border, nthreads);
            if (!ok) {
                dst.errorfmt("blur: where the non-finite values reach: {}", reach.geterror());
                return false;
            }
            for (int i = 0; i < nind; ++i) {
                const auto [c, kd] = channels[size_t(i)];
                const int as       = sign > 0.0 || kd == 0 ? kd : 3 - kd;  // -inf through a negative weight: +inf
                std::vector<char>& r = reached[size_t(3 * c + as)];
                r.resize(npx, 0);
                parallel_rows(out, nthreads, [&](int y0, int y1) {
                    for (int y = y0; y < y1; ++y) {
                        const auto* v = static_cast<const float*>(reach.pixeladdr(out.xbegin, y));
                        char* hit     = r.data() + size_t(y - out.ybegin) * size_t(out.width());
                        for (int x = 0; x < out.width(); ++x)
                            hit[x] = char(hit[x] | (v[size_t(x) * size_t(nind) + size_t(i)] > 0.5f));
                    }
                });
            }
        }
    }
    constexpr float kInf = std::numeric_limits<float>::infinity();
    parallel_rows(out, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            auto* row = static_cast<float*>(dst.pixeladdr(out.xbegin, y));
            for (int x = 0; x < out.width(); ++x)
                for (int c = 0; c < nc; ++c) {
                    const size_t p = size_t(y - out.ybegin) * size_t(out.width()) + size_t(x);
                    auto hit       = [&](int kd) {
                        const std::vector<char>& r = reached[size_t(3 * c + kd)];
                        return !r.empty() && r[p];
                    };
                    const bool nan = hit(0), pos = hit(1), neg = hit(2);
                    float& v       = row[size_t(x) * ncs + size_t(c)];
                    if (nan || (pos && neg))
                        v = std::numeric_limits<float>::quiet_NaN();
                    else if (pos || neg)
                        v = pos ? kInf : -kInf;
                }
        }
    });
    return true;
}

}  // namespace bokeh::detail
