// blur_separable.cpp — the separable convolution (the Gaussian below the FFT's
// crossover, OIIO's separable filters) and the brute-force reference: both are weighted
// sums of source rows, 16 sums held in registers over every tap (weighted_sum, plane.cpp).
//
// Separable (separable_direct): per column strip, each padded source row is filtered
// along x into a ring of the last 2 ry + 1 rows, and the ring's rows are summed along y
// straight into `dst`, each value's taps in the order the plane path (convolve_separable,
// iris mode) adds them, so both give the same bits. A padded plane, a middle and an output
// plane (whose first touch took a quarter of the time) and a copy into `dst` are saved.
// The brute force (convolve_brute, convolve_reference) adds every non-zero tap of the
// reflected kernel: the reference every other method is tested against.
//
// Limits: the cost grows with the taps (2 per kernel width and height for the separable
// convolution, the kernel's area for the brute force); blur.cpp takes the FFT where its
// cost model is cheaper (separable_cost_ns against fft_convolve_cost_ns).

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/blur_methods.h"
#include "base/progress.h"

#include <algorithm>
#include <functional>
#include <limits>
#include <utility>
#include <vector>

namespace bokeh {

using namespace detail;

namespace {

// Each row y of `out` = sum_j w[j] * source(y, j), accumulated in double (weighted_sum:
// 16 sums in registers over every tap; a row of double sums, added to once a tap, was
// load- and store-bound, 61 KiB a 1080p RGBA row, past L1).
template<class Source>
void weighted_rows(Plane& out, const std::vector<double>& w, Source source, int nthreads,
                   ProgressCounter* progress = nullptr)
{
    parallel_for_chunks(0, out.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        std::vector<const float*> taps(w.size());
        for (int y = int(y0); y < int(y1); ++y) {
            for (size_t j = 0; j < w.size(); ++j)
                taps[j] = source(y, j);
            weighted_sum(out.row(y), taps.data(), w.data(), w.size(), out.stride());
        }
        if (progress)
            progress->add(double(y1 - y0));
    });
}

}  // namespace

namespace detail {

// The brute force: every output a weighted sum of its footprint's source pixels.
Plane convolve_brute(const Plane& in, const KernelWeights& kernel, int nthreads,
                     const std::function<void(float)>& progress)
{
    const KernelWeights k = reflected(kernel);
    // The non-zero taps as (row offset, column offset) with their weights.
    std::vector<std::pair<int, int>> taps;
    std::vector<double> weights;
    for (int dy = -k.ry; dy <= k.ry; ++dy)
        for (int dx = -k.rx; dx <= k.rx; ++dx)
            if (k.at(dx, dy) != 0.0) {
                taps.emplace_back(k.ry + dy, k.rx + dx);
                weights.push_back(k.at(dx, dy));
            }
    Plane out(in.w - 2 * k.rx, in.h - 2 * k.ry, in.nc);
    const size_t nc = size_t(in.nc);
    ProgressCounter counter(progress, double(out.h));
    weighted_rows(out, weights,
                  [&](int y, size_t j) { return in.row(y + taps[j].first) + size_t(taps[j].second) * nc; },
                  nthreads, counter.active() ? &counter : nullptr);
    return out;
}

// Horizontal then vertical direct convolution with 1-D weights (Gaussian).
Plane convolve_separable(const Plane& in, const std::vector<double>& wx,
                         const std::vector<double>& wy, int nthreads)
{
    const int rx = int(wx.size() / 2), ry = int(wy.size() / 2);
    const size_t nc = size_t(in.nc);
    Plane mid(in.w - 2 * rx, in.h, in.nc);
    weighted_rows(mid, wx, [&](int y, size_t j) { return in.row(y) + j * nc; }, nthreads);
    Plane out(mid.w, in.h - 2 * ry, in.nc);
    weighted_rows(out, wy, [&](int y, size_t j) { return mid.row(y + int(j)); }, nthreads);
    return out;
}

// The separable convolution straight from the source to `dst` (the Gaussian's and OIIO's
// separable filters' exact method outside iris mode): each task walks down a strip of
// output columns, filters each padded source row along x into a ring of the last 2 ry + 1
// rows, and sums the ring's rows along y into the output row, each value's taps in the
// order convolve_separable adds them (the same bits). The plane path's padded, middle
// and output planes (fresh pages: their zeroing took a quarter of its time) and its copy
// into `dst` are saved.
bool separable_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                      const std::vector<double>& wx, const std::vector<double>& wy, Border border, int nthreads)
{
    prepare_destination(dst, in, roi);
    const size_t ncs = size_t(in.nchannels());
    const int w = roi.width(), h = roi.height();
    const int rx = int(wx.size() / 2), ry = int(wy.size() / 2), ring = 2 * ry + 1;
    for_each_column_strip(w, nthreads, [&](int xs, int xe) {
        const size_t n = size_t(xe - xs) * ncs;
        const int x0 = roi.xbegin + xs - rx, x1 = roi.xbegin + xe + rx;
        Plane rows(xe - xs, ring, int(ncs));  // written before read, or marked black
        std::vector<char> slot_black(size_t(ring), 0);
        std::vector<float> row(size_t(x1 - x0) * ncs), black(n, 0.0f), out_row(n);
        std::vector<const float*> taps(std::max(wx.size(), wy.size()));
        // The last padded row that read each source row: past an edge the clamp and mirror
        // borders read source rows again, and one still in the ring is copied, not filtered
        // again (a sigma 512 Gaussian on a 960 x 64 image: 13 s under clamp and 7 s under
        // mirror filtered again, 1.1 and ~1 s copied; the same bits).
        const int src_y0 = in.roi().ybegin;
        std::vector<int> last_read(size_t(in.roi().height()), std::numeric_limits<int>::min());
        // Padded row j (source row roi.ybegin - ry + j) along x into its ring slot.
        auto horizontal = [&](int j) {
            const int sy     = roi.ybegin - ry + j;
            const int source = border_index(sy, src_y0, in.roi().yend, border);
            if (source != kOutside) {
                int& prev = last_read[size_t(source - src_y0)];
                if (prev != std::numeric_limits<int>::min() && j - prev < ring) {
                    slot_black[size_t(j % ring)] = slot_black[size_t(prev % ring)];
                    if (prev % ring != j % ring)
                        std::copy_n(rows.row(prev % ring), n, rows.row(j % ring));
                    prev = j;
                    return;
                }
                prev = j;
            }
            const RowSpan span = bordered_row_span(in, sy, x0, x1, border, row.data());
            slot_black[size_t(j % ring)] = !span.p;
            if (!span.p)
                return;
            const float* v = span.lo == 0 && span.hi == x1 - x0 ? span.p
                                                                 : bordered_row_view(in, sy, x0, x1, border, row.data());
            for (size_t t = 0; t < wx.size(); ++t)
                taps[t] = v + t * ncs;
            weighted_sum(rows.row(j % ring), taps.data(), wx.data(), wx.size(), n);
        };
        for (int j = 0; j < 2 * ry; ++j)
            horizontal(j);
        for (int y = 0; y < h; ++y) {
            horizontal(y + 2 * ry);
            for (int t = 0; t < ring; ++t)
                taps[size_t(t)] = slot_black[size_t((y + t) % ring)] ? black.data() : rows.row((y + t) % ring);
            weighted_sum(out_row.data(), taps.data(), wy.data(), wy.size(), n);
            stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + y)), out_row.data(), n);
        }
        stream_fence();
    });
    return true;
}

// Single-thread time in ns of the separable convolution over a w x h output, per channel:
// ~0.4 ns per tap of the two passes, plus ~2 for the padded plane and the copy out.
// Fitted to Gaussians at 1080p on the project's machine (sigma = size / 4, 8 sigma + 1
// taps per pass; 2 threads: 114, 213, 407 ms at sizes 15, 31, 63; the model errs low
// above, 2250 ms measured at 255 against 1700). With the direct path (separable_direct),
// on this machine: 43, 54, 71, 88, 116 ms at sizes 11, 15, 19, 23, 31 against the FFT
// tiles' 78, 60, 64, 93, 96 (medians of 9, one run; bokeh-micro's BM_ExactBlur times both
// by name): the crossover falls between 19 and 31, where the model puts it (sigma ~7,
// size 28).
double separable_cost_ns(int w, int h, int taps_x, int taps_y)
{
    return double(w) * double(h) * (0.4 * double(taps_x + taps_y) + 2.0);
}

}  // namespace detail

bool convolve_reference(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src,
                        const KernelWeights& weights, const BlurOptions& opts, OIIO::ROI roi,
                        int nthreads)
{
    if (!check_source(dst, src))
        return false;
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = float_source(src, holder);
    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), weights.rx, weights.ry) : in.roi();
    const Plane p = pad(in, grown(roi, weights.rx, weights.ry), opts.border, nthreads);
    return finish(dst, in, roi, convolve_brute(p, weights, nthreads), 0, 0, false, nthreads);
}

}  // namespace bokeh
