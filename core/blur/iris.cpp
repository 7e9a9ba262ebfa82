// iris.cpp — iris mode's exp space (convolve.h's Iris): the highlight emphasis
// log(mean(exp(k x))) / k of Imagire's "Iris filter" (docs/methods/iris.md), carried as
// exp(k (x - shift)) - 1 so the sums keep the dark values' digits.

#include "blur/convolve.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

namespace {

// p = f(p, channel) on every channel but `skip_a` and `skip_b`.
template<class F> void map_channels(Plane& p, int skip_a, int skip_b, int nthreads, F f)
{
    parallel_for_chunks(0, p.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* r = p.row(y);
            for (size_t i = 0; i < p.stride(); ++i) {
                const int c = int(i % size_t(p.nc));
                if (c != skip_a && c != skip_b)
                    r[i] = f(r[i], c);
            }
        }
    });
}

}  // namespace

bool Iris::forward(Plane& p, std::string& err, int nthreads)
{
    const int nc = p.nc;
    shift.assign(size_t(nc), 0.0);
    for (int c = 0; c < nc; ++c) {
        if (c == alpha || c == z)
            continue;
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        for (size_t i = size_t(c); i < p.size(); i += size_t(nc))
            if (std::isfinite(p.px[i])) {
                lo = std::min(lo, double(p.px[i]));
                hi = std::max(hi, double(p.px[i]));
            }
        if (!(hi >= lo))
            continue;
        if (std::abs(k) * (hi - lo) > kIrisMaxExponent) {
            err = OIIO::Strutil::fmt::format(
                "iris {} times channel {}'s range {} .. {} exceeds {}: exp() would span more "
                "digits than the sums keep; lower iris",
                k, c, lo, hi, kIrisMaxExponent);
            return false;
        }
        shift[size_t(c)] = k > 0 ? lo : hi;
    }
    map_channels(p, alpha, z, nthreads,
                 [&](float v, int c) { return float(std::expm1(k * (v - shift[size_t(c)]))); });
    return true;
}

void Iris::inverse(Plane& p, int nthreads) const
{
    map_channels(p, alpha, z, nthreads,
                 [&](float v, int c) {
                     // A mean of values >= 0 by weights >= 0 is >= 0; below it is rounding.
                     return float(shift[size_t(c)] + std::log1p(std::max(double(v), 0.0)) / k);
                 });
}

}  // namespace bokeh::detail
