// blur_spans.cpp — the exact disk and polygon by row spans (BlurMethod::Spans), straight
// from the source into the destination, with the plane path for iris mode and the cost
// model blur.cpp weighs against the FFT's.
//
// Row spans: each kernel row's weight profile is cut into horizontal bars ("skyline"
// decomposition: one bar per rise of the profile), so a kernel becomes a list of
// (dy, x0, x1, weight) spans; a span's sum is a difference of two row prefix sums. Cost per
// pixel is linear in the number of spans, about 3 per kernel row for convex anti-aliased
// shapes, so linear in the diameter, not in the area as brute force's is. Prefix sums are
// double so a 1e6 pixel leaves no drift.
//
// The direct path (convolve_spans_direct) works per 128 x (>= 256)-pixel tile: the rows'
// prefix sums in a ring, then 128 x 4 sub-tiles whose double accumulators stay in L1, each
// prefix row visited once per sub-tile and the spans of two kernel rows added per pass
// (add_spans); with 4 channels each prefix row is kept twice, the copy one pixel on, so
// every span's vector loads start on a 64-byte boundary. A kernel mirrored in y (a disk; a
// polygon symmetric about its horizontal axis) takes convolve_symmetric_spans: each prefix
// row's span sums for rows dy and -dy, the same spans, are added into both output rows
// that read them, held in a ring of 2 ry + 1 output rows: 0.65-0.8x the time of the
// general path.
//
// Limits: the cost still grows linearly with the diameter (about 2.6 spans per kernel row:
// 161 at 63 px), and blur.cpp takes the FFT from about 99 px for a disk; a tile recomputes
// the prefix sums of its kernel-high margin (tile height >= twice the kernel height, so
// under half a row more per output row).

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/convolve.h"

#include <algorithm>
#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <tuple>
#include <vector>

namespace bokeh {

using namespace detail;

namespace {

// The first 64-byte boundary at or after p (p from an allocation of 8 doubles more).
double* aligned64(double* p)
{
    return p + (8 - (reinterpret_cast<uintptr_t>(p) / sizeof(double)) % 8) % 8;
}

}  // namespace

namespace detail {

void row_prefix_sums(const Plane& in, double* prefix, int nthreads)
{
    const size_t nc = size_t(in.nc), pstride = size_t(in.w + 1) * nc;
    parallel_for_chunks(0, in.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y)
            row_prefix(prefix + size_t(y) * pstride, in.row(int(y)), size_t(in.w), in.nc);
    });
}

// The weights point-reflected: out(x) = sum_d w(d) in(x - d) = sum_d w(-d) in(x + d), so a
// point spreads into the kernel's own shape (this matters for shapes without point
// symmetry, such as a pentagon).
KernelWeights reflected(const KernelWeights& k)
{
    KernelWeights r = k;
    std::reverse(r.w.begin(), r.w.end());
    return r;
}

// Skyline decomposition of each kernel row into stacked horizontal bars.
std::vector<Span> kernel_spans(const KernelWeights& k)
{
    std::vector<Span> spans;
    struct Open {
        int start;
        double level;
    };
    for (int dy = -k.ry; dy <= k.ry; ++dy) {
        std::vector<Open> stack;
        for (int dx = -k.rx; dx <= k.rx + 1; ++dx) {
            const double h = dx <= k.rx ? k.at(dx, dy) : 0.0;
            while (!stack.empty() && h < stack.back().level) {
                const Open top = stack.back();
                stack.pop_back();
                const double below = std::max(h, stack.empty() ? 0.0 : stack.back().level);
                spans.push_back({ dy, top.start, dx - 1, top.level - below });
                if (h > (stack.empty() ? 0.0 : stack.back().level)) {
                    stack.push_back({ top.start, h });  // the lower part continues
                    break;
                }
            }
            if (h > (stack.empty() ? 0.0 : stack.back().level))
                stack.push_back({ dx, h });
        }
    }
    return spans;
}

Plane convolve_spans(const Plane& in, const KernelWeights& kernel, int nthreads)
{
    const int nc = in.nc;
    Plane out(in.w - 2 * kernel.rx, in.h - 2 * kernel.ry, nc);
    const KernelWeights k         = reflected(kernel);
    const std::vector<Span> spans = kernel_spans(k);

    // Row prefix sums: P[y][(x + 1) nc + c] = sum of in[y][0..x] in channel c.
    const size_t pstride = size_t(in.w + 1) * size_t(nc);
    // Every entry is written below: no need to zero 8 bytes x 4 channels x the plane.
    std::unique_ptr<double[]> prefix(new double[size_t(in.h) * pstride]);
    row_prefix_sums(in, prefix.get(), nthreads);

    accumulate_in_strips(out, nthreads, [&](int y, size_t i0, std::vector<double>& acc) {
        for (const Span& s : spans) {
            const double* p  = prefix.get() + size_t(y + k.ry + s.dy) * pstride + i0;
            const double* hi = p + size_t(k.rx + s.x1 + 1) * size_t(nc);
            const double* lo = p + size_t(k.rx + s.x0) * size_t(nc);
            add_span(acc.data(), hi, lo, s.weight, acc.size());
        }
    });
    return out;
}

// Single-thread time in ns of convolve_spans_direct over a w x h output, per channel:
// 0.10 ns per span and pixel (two prefix loads and a multiply-add) and 0.29 per kernel
// row and pixel (the row's accumulators loaded and stored, its prefix row found), both
// 0.7 of that for a kernel mirrored in y (convolve_symmetric_spans shares each span's sum
// between two output rows: 0.65-0.79x the time, bokeh-ab), plus 0.75 for the prefix sums
// and the copy out. Fitted (least relative squares) to 44 timings at 1080p RGBA on two
// threads (bokeh-micro's BM_ExactBlur times such cases): disks 15-191 px, hexagons at 0,
// 30 and 7 degrees, pentagons, a curved octagon, 2:1 and 1:2 ellipses and a catadioptric
// disk; it reads them within 0.84-1.21 of measured. A model charging spans alone (0.15 ns
// each, growing with the rows) read a hexagon's spans up to 1.30x low and large or holed
// kernels up to 1.7x high (a hexagon has ~2.2 spans per row against a disk's 2.6, a holed
// disk 5).
double spans_cost_ns(int w, int h, const std::vector<Span>& spans)
{
    std::set<int> rows;
    for (const Span& s : spans)
        rows.insert(s.dy);
    const double shared = spans_mirror_in_y(spans) ? 0.7 : 1.0;
    return double(w) * double(h)
           * (shared * (0.10 * double(spans.size()) + 0.29 * double(rows.size())) + 0.75);
}

bool spans_mirror_in_y(const std::vector<Span>& spans)
{
    std::map<int, std::vector<std::tuple<int, int, double>>> rows;
    for (const Span& s : spans)
        rows[s.dy].emplace_back(s.x0, s.x1, s.weight);
    for (const auto& [dy, bars] : rows) {
        const auto mirror = rows.find(-dy);
        if (mirror == rows.end() || mirror->second != bars)
            return false;
    }
    return true;
}

// Padded source row y over columns [x0, x1) as row prefix sums into p (pw values); with
// twin_at, again from p[twin_at] one pixel on (see convolve_spans_direct).
void span_prefix_row(double* p, const OIIO::ImageBuf& in, int y, int x0, int x1, Border border,
                     float* row, size_t pw, size_t twin_at)
{
    const size_t ncs = size_t(in.nchannels());
    const float* v   = bordered_row_view(in, y, x0, x1, border, row);
    if (v)
        row_prefix(p, v, pw / ncs - 1, in.nchannels());
    else
        std::fill_n(p, pw, 0.0);
    if (twin_at)
        std::copy(p + ncs, p + pw, p + twin_at);
}

// Columns per tile of the row-span methods (see convolve_spans_direct).
constexpr int kSpanTileW = 128;

// The row spans of a kernel whose rows dy and -dy have the same spans, from the source
// into `dst`, in tiles of kSpanTileW columns as convolve_spans_direct's. Prefix row r is
// read as row d = dy + ry of output row r - d and, with the same spans, as row
// nd - 1 - d of output row r - nd + 1 + d: its span sums for each d are computed once and
// added into both (add_spans_pair), so each span costs its two loads and two operations
// once per pair of output rows instead of once per output row. Each prefix row is used
// once, as it arrives, so the tile keeps a ring of the 2 ry + 1 output rows being summed
// instead of prefix rows (258 KB in double at 63 px, in L2). A/B against the general
// path: 0.77x at 63 px, 0.75x at 31, 0.79x at 15, 0.65x at 127, the same bits to 3e-8.
// A row's first spans are stored, not added, and its last written out with them as float
// (start_and_finish_rows), so no pass zeroes or copies the ring: 0.93-0.97x more at
// 15-63 px. Narrower column strips, so the ring fits L1, measured slower (16 px: 1.11x
// at 63; 64 px: 0.84x): a span's loop over fewer columns pays its setup more often.
// Tiles are fixed by the kernel and the image, so results do not depend on the thread
// count.
bool convolve_symmetric_spans(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                              int rx, int ry, const std::vector<size_t>& first,
                              const std::vector<size_t>& hi_off, const std::vector<size_t>& lo_off,
                              const std::vector<double>& span_w, size_t rs, size_t twin_at,
                              Border border, int nthreads)
{
    const int nc     = in.nchannels();
    const size_t ncs = size_t(nc);
    const int nd     = 2 * ry + 1;
    size_t most      = 0;
    for (size_t d = 0; d + 1 < first.size(); ++d)
        most = std::max(most, first[d + 1] - first[d]);
    const int w = roi.width(), h = roi.height();
    const int th  = std::max(256, 2 * nd);
    const int ntx = (w + kSpanTileW - 1) / kSpanTileW, nty = (h + th - 1) / th;
    parallel_for_chunks(0, int64_t(ntx) * nty, 1, nthreads, [&](int64_t t, int64_t) {
        const int xs = int(t % ntx) * kSpanTileW, xe = std::min(w, xs + kSpanTileW);
        const int ys = int(t / ntx) * th, ye = std::min(h, ys + th);
        const int rows_out = ye - ys;
        const size_t pw    = size_t(xe - xs + 2 * rx + 1) * ncs;  // one prefix row
        const size_t n     = size_t(xe - xs) * ncs;                // one output row
        // Uninitialised: every value read is written below.
        std::unique_ptr<double[]> prefix_store(new double[rs + 8]);
        double* const p = aligned64(prefix_store.get());
        std::vector<float> row(pw);
        // Output row yl sums into ring row yl % nd, set by its first prefix row.
        const size_t an = (n + 7) / 8 * 8;  // rows on 64-byte boundaries
        std::vector<double> acc_store(size_t(nd) * an + 8);
        double* const acc_base = aligned64(acc_store.data());
        auto acc = [&](int yl) { return acc_base + size_t(yl % nd) * an; };
        std::vector<const double*> hi_ptr(most), lo_ptr(most);
        for (int r = 0; r < rows_out + nd - 1; ++r) {
            span_prefix_row(p, in, roi.ybegin + ys - ry + r, roi.xbegin + xs - rx, roi.xbegin + xe + rx,
                            border, row.data(), pw, twin_at);
            for (int d = 0; d <= ry; ++d) {
                const int ya = r - d, yb = r - (nd - 1 - d);
                const bool a_ok = ya >= 0 && ya < rows_out;
                const bool b_ok = d < ry && yb >= 0 && yb < rows_out;
                if (!a_ok && !b_ok)
                    continue;
                size_t count = 0;
                for (size_t i = first[size_t(d)]; i < first[size_t(d) + 1]; ++i, ++count) {
                    hi_ptr[count] = p + hi_off[i];
                    lo_ptr[count] = p + lo_off[i];
                }
                const double* w_d = span_w.data() + first[size_t(d)];
                if (d > 0) {
                    add_spans_pair(a_ok ? acc(ya) : acc(yb), a_ok && b_ok ? acc(yb) : nullptr,
                                   hi_ptr.data(), lo_ptr.data(), w_d, count, n);
                    continue;
                }
                // d = 0: prefix row r is output row r's first (ya = r) and output row
                // r - 2 ry's last (yb): the one is stored, not added to, and the other
                // written out as float, with no pass to zero or copy either.
                float* out = b_ok ? static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + ys + yb))
                                  : nullptr;
                start_and_finish_rows(a_ok ? acc(ya) : nullptr, b_ok ? acc(yb) : nullptr, out,
                                      hi_ptr.data(), lo_ptr.data(), w_d, count, n);
            }
        }
    });
    return true;
}

// Exact convolution by row spans straight from the source ImageBuf into `dst`: no padded
// copy, no whole-frame prefix plane, no copy out. The output is cut into tiles of
// kSpanTileW columns x th rows; a tile takes the row prefix sums (double) of the source
// rows it reads, from its own first column on (border rule applied while reading), into a
// ring of its own that stays in L2: the rows one sub-tile reads, each computed once as the
// sub-tiles move down the tile. It then works in sub-tiles of kSubW x kSubH outputs
// whose double accumulators stay in L1, and walks the prefix rows once per sub-tile, each
// row adding its spans into every output row that reads it: each prefix row is fetched
// from L2 once per sub-tile instead of once per span and output row. Prefix sums start
// afresh at every tile, so they stay small (a 1e6 pixel leaves no drift, and digits are
// not lost to a long row's sum); tiles are fixed, so results do not depend on the thread
// count.
bool convolve_spans_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                           int rx, int ry, std::vector<Span> spans, Border border, int nthreads)
{
    // 128-column tiles: at D = 63 the tile's prefix ring (66 rows of 191 pixels, twice) is
    // 0.8 MB and stays in L2. Measured A/B in one process against 256 x 64 x 8: 5-9 % faster
    // at 15-127 px; sub-tiles of 32 x 16 were slower. The ring and tiles of >= 256 rows
    // (against a table of all the tile's rows in tiles of 64 rows, whose prefix rows were
    // computed twice per output row at 63 px): 6-7 % faster at 63 and 127 px, same bits.
    constexpr int kSubW = 128, kSubH = 4;
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    // Output row y reads table rows y + d, d = dy + ry in [0, nd): the padded rows
    // y .. y + 2 ry.
    const int nd = 2 * ry + 1;
    std::stable_sort(spans.begin(), spans.end(),
                     [](const Span& a, const Span& b) { return a.dy < b.dy; });
    // first[d] .. first[d + 1]: the spans of table row d, as offsets into a table row
    // (hi, lo) and weights.
    std::vector<size_t> first(size_t(nd) + 1, spans.size());
    for (size_t i = spans.size(); i-- > 0;)
        first[size_t(spans[i].dy + ry)] = i;
    for (size_t d = first.size() - 1; d-- > 0;)
        first[d] = std::min(first[d], first[d + 1]);
    // A table row holds at most pmax values; rows are `rs` apart, on 64-byte boundaries.
    // With 4 channels a pixel is half a 64-byte vector, so half the spans would start
    // mid-vector and every load of theirs would split a cache line; each row is then
    // stored twice, the second copy one pixel on (twin), and a span starting at an odd
    // pixel reads the twin, from a vector boundary.
    const bool twin   = nc == 4;
    const size_t pmax = size_t(kSpanTileW + 2 * rx + 1) * ncs;
    const size_t pal  = (pmax + 7) / 8 * 8;
    const size_t rs   = twin ? 2 * pal : pal;
    auto offset = [&](int px) {
        return twin && px % 2 == 1 ? pal + size_t(px - 1) * ncs : size_t(px) * ncs;
    };
    std::vector<size_t> hi_off, lo_off;
    std::vector<double> span_w;
    for (const Span& s : spans) {
        hi_off.push_back(offset(rx + s.x1 + 1));
        lo_off.push_back(offset(rx + s.x0));
        span_w.push_back(s.weight);
    }

    // Rows dy and -dy with the same spans (a disk; a polygon symmetric about its
    // horizontal axis): each prefix row's span sums serve two output rows.
    if (ry > 0 && spans_mirror_in_y(spans))
        return convolve_symmetric_spans(dst, in, roi, rx, ry, first, hi_off, lo_off, span_w, rs,
                                        twin ? pal : 0, border, nthreads);

    // The most spans two consecutive kernel rows have (one pass of add_spans below).
    size_t most = 0;
    for (size_t d = 0; d + 1 < first.size(); ++d)
        most = std::max(most, first[std::min(d + 2, first.size() - 1)] - first[d]);
    const int w = roi.width(), h = roi.height();
    // Tile height: twice the kernel's at least, so a tile computes under 1.5 prefix rows
    // per output row (fixed by the kernel alone, never by the thread count).
    const int th = std::max(256, (2 * nd + kSubH - 1) / kSubH * kSubH);
    const int ntx = (w + kSpanTileW - 1) / kSpanTileW, nty = (h + th - 1) / th;
    // The prefix rows a sub-tile reads: a ring of that many, each row computed once per
    // tile as the sub-tiles move down.
    const int ring = nd - 1 + kSubH;
    parallel_for_chunks(0, int64_t(ntx) * nty, 1, nthreads, [&](int64_t t, int64_t) {
        const int xs = int(t % ntx) * kSpanTileW, xe = std::min(w, xs + kSpanTileW);
        const int ys = int(t / ntx) * th, ye = std::min(h, ys + th);
        const int tw = xe - xs;
        const size_t pw = size_t(tw + 2 * rx + 1) * ncs;  // one prefix row
        // Uninitialised: every value read is written below.
        std::unique_ptr<double[]> table_store(new double[size_t(ring) * rs + 8]);
        double* const table = aligned64(table_store.get());
        auto table_row = [&](int r) { return table + size_t(r % ring) * rs; };
        std::vector<float> row(pw);
        int computed = 0;  // tile-local prefix rows done
        auto compute_rows = [&](int r_end) {
            for (; computed < r_end; ++computed)
                span_prefix_row(table_row(computed), in, roi.ybegin + ys - ry + computed,
                                roi.xbegin + xs - rx, roi.xbegin + xe + rx, border, row.data(), pw,
                                twin ? pal : 0);
        };
        std::vector<const double*> hi_ptr(most), lo_ptr(most);
        std::vector<double> w_list(most);
        // Accumulators on a 64-byte boundary: rows of kSubW pixels then start on one too,
        // and no vector store splits a cache line.
        std::vector<double> acc_store(size_t(kSubH) * size_t(kSubW) * ncs + 8);
        double* const acc_base = aligned64(acc_store.data());
        const size_t acc_len = size_t(kSubH) * size_t(kSubW) * ncs;
        for (int sy0 = ys; sy0 < ye; sy0 += kSubH)
            for (int sx0 = xs; sx0 < xe; sx0 += kSubW) {
                const int sh = std::min(kSubH, ye - sy0);
                const size_t n = size_t(std::min(kSubW, xe - sx0)) * ncs;
                std::fill_n(acc_base, acc_len, 0.0);
                // Output row y (tile-local yl) reads prefix rows yl .. yl + 2 ry. Two prefix
                // rows at a time: each output row takes the spans of both in one pass.
                const int yl0   = sy0 - ys;
                const int r_end = yl0 + sh + nd - 1;
                compute_rows(r_end);
                for (int r = yl0; r < r_end; r += 2) {
                    const bool pair  = r + 1 < r_end;
                    const int j0 = std::max(0, r - yl0 - nd + 1);
                    const int j1 = std::min(sh, r - yl0 + (pair ? 2 : 1));
                    for (int j = j0; j < j1; ++j) {
                        size_t count = 0;
                        for (int q = 0; q < (pair ? 2 : 1); ++q) {
                            const int d = r + q - yl0 - j;
                            if (d < 0 || d >= nd)
                                continue;
                            const double* p = table_row(r + q) + size_t(sx0 - xs) * ncs;
                            for (size_t i = first[size_t(d)]; i < first[size_t(d) + 1]; ++i) {
                                hi_ptr[count] = p + hi_off[i];
                                lo_ptr[count] = p + lo_off[i];
                                w_list[count++] = span_w[i];
                            }
                        }
                        add_spans(acc_base + size_t(j) * n, hi_ptr.data(), lo_ptr.data(),
                                  w_list.data(), count, n);
                    }
                }
                for (int j = 0; j < sh; ++j)
                    to_float(static_cast<float*>(
                                 dst.pixeladdr(roi.xbegin + sx0, roi.ybegin + sy0 + j)),
                             acc_base + size_t(j) * n, n);
            }
    });
    return true;
}

bool fft_cheaper_than_spans(int w, int h, int nc, int rx, int ry, const std::vector<Span>& spans)
{
    return fft_convolve_cost_ns(w, h, nc, rx, ry) < 1.2 * nc * spans_cost_ns(w, h, spans);
}

}  // namespace detail

}  // namespace bokeh
