// metrics.cpp — error of a result against its reference (metrics.h). Sums are per row in
// double and combined in row order, so the figures do not depend on the thread count.

#include <bokeh/metrics.h>
#include <bokeh/parallel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include <OpenImageIO/strutil.h>

namespace bokeh {

bool compare(ImageError& e, const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference,
             std::string& err, OIIO::ROI roi, int nthreads)
{
    if (result.deep() || reference.deep()) {
        err = "deep images cannot be compared; flatten them first";
        return false;
    }
    const int nc = result.nchannels();
    if (nc != reference.nchannels()) {
        err = OIIO::Strutil::fmt::format("channel counts differ ({} vs {})", nc,
                                         reference.nchannels());
        return false;
    }
    if (!roi.defined())
        roi = OIIO::roi_union(result.roi(), reference.roi());
    // Per chunk of rows: squared error, tone-mapped squared error, max.
    using Sums = std::array<double, 3>;
    const Sums s = parallel_reduce_chunks(
        roi.ybegin, roi.yend, 8, nthreads, Sums{ 0.0, 0.0, 0.0 },
        [&](int64_t y0, int64_t y1) {
            Sums t{ 0.0, 0.0, 0.0 };
            std::vector<float> a(size_t(roi.width()) * size_t(nc)), b(a.size());
            for (int y = int(y0); y < int(y1); ++y) {
                const OIIO::ROI row(roi.xbegin, roi.xend, y, y + 1, 0, 1, 0, nc);
                // get_pixels fills pixels outside the data window with 0.
                result.get_pixels(row, OIIO::TypeFloat, a.data());
                reference.get_pixels(row, OIIO::TypeFloat, b.data());
                for (size_t i = 0; i < a.size(); ++i) {
                    const double x = a[i], r = b[i];
                    const double tx = x / (1.0 + std::abs(x)), tr = r / (1.0 + std::abs(r));
                    t[0] += (x - r) * (x - r);
                    t[1] += (tx - tr) * (tx - tr);
                    t[2] = std::max(t[2], std::abs(x - r));
                }
            }
            return t;
        },
        [](Sums& acc, const Sums& p) {
            acc[0] += p[0];
            acc[1] += p[1];
            acc[2] = std::max(acc[2], p[2]);
        });
    e.values      = int64_t(roi.width()) * roi.height() * nc;
    const double n = double(std::max<int64_t>(1, e.values));
    e.rmse_linear = std::sqrt(s[0] / n);
    e.psnr_db     = s[1] > 0.0 ? 10.0 * std::log10(n / s[1]) : 999.0;
    e.max_abs     = s[2];
    return true;
}

}  // namespace bokeh
