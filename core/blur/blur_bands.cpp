// blur_bands.cpp — the disk and polygon approximated by bands (BlurMethod::Bands): the
// banded kernel, its running sums straight from the source, the summed-area table for
// iris mode, and method=fast's band count and cost model.
//
// The exact kernel's rows are grouped into a few horizontal bands (boundaries by dynamic
// programming, least squares on the row areas; over the lower half, mirrored, for a kernel
// symmetric in y, else over all rows), each band's rows replaced by one interval of the
// same mean area and centre, anti-aliased at its ends; the bands are rectangles, so the
// cost depends on the band count, not the kernel size.
// The direct path (convolve_bands_direct): each task walks down a strip of output columns
// reading the source once: a row's double prefix sums give every band profile's
// horizontal sum (a band and its mirror image share one), kept in a ring of the last
// 2 ry + 2 rows, and one double running total slides down the rows, each band window
// adding the row entering it and taking away the row leaving it. A summed-area table
// (Crow 1984) per output tile grew with the kernel's reach, and one for the whole frame
// took 68-77 MB at 1080p; convolve_banded keeps that table for iris mode alone.
//
// Limits: no catadioptric hole (blur.cpp refuses the method for one). Iris mode's
// whole-frame summed-area table is double: an image whose total energy exceeds ~1e12
// loses digits in dark areas (none of the test scenes comes within 1e4 of it); the direct
// path's prefix sums span one strip's row only.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/blur_methods.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <vector>

namespace bokeh {

using namespace detail;

namespace {

// --- the banded kernel's rectangles (its runs of equal rows) -----------------------------

struct Rect {
    int y0, y1, x0, x1;  // offsets, inclusive
    double weight;       // per pixel
};

// Runs of identical rows of the kernel's skyline spans, merged into rectangles.
std::vector<Rect> kernel_rects(const KernelWeights& k)
{
    std::vector<Rect> rects;
    std::vector<Span> open_spans;  // the spans of the previous row, with their rect index
    std::vector<size_t> open_index;
    int row = std::numeric_limits<int>::min();
    std::vector<Span> spans = kernel_spans(k);
    size_t i = 0;
    while (i < spans.size()) {
        const int dy = spans[i].dy;
        std::vector<Span> cur;
        for (; i < spans.size() && spans[i].dy == dy; ++i)
            cur.push_back(spans[i]);
        std::vector<size_t> idx;
        const bool continues = row == dy - 1 && cur.size() == open_spans.size()
                               && std::equal(cur.begin(), cur.end(), open_spans.begin(),
                                             [](const Span& a, const Span& b) {
                                                 return a.x0 == b.x0 && a.x1 == b.x1
                                                        && a.weight == b.weight;
                                             });
        for (size_t j = 0; j < cur.size(); ++j) {
            if (continues) {
                rects[open_index[j]].y1 = dy;
                idx.push_back(open_index[j]);
            } else {
                rects.push_back({ dy, dy, cur[j].x0, cur[j].x1, cur[j].weight });
                idx.push_back(rects.size() - 1);
            }
        }
        open_spans = cur;
        open_index = idx;
        row        = dy;
    }
    return rects;
}

// --- bands by running sums down the rows ---------------------------------------------------

// One bar of a band's rows in the reflected kernel: weight on offsets x0 .. x1.
struct Bar {
    int x0, x1;
    double weight;
    bool operator==(const Bar& o) const { return x0 == o.x0 && x1 == o.x1 && weight == o.weight; }
};

// The rows of one horizontal profile (a band and its mirror image share one): the bars
// along x, and the runs of kernel rows [y0, y1] (offsets) it covers.
struct Profile {
    std::vector<Bar> bars;
    std::vector<std::pair<int, int>> windows;
};

std::vector<Profile> band_profiles(const KernelWeights& banded)
{
    std::map<std::pair<int, int>, std::vector<Bar>> by_rows;
    for (const Rect& r : kernel_rects(reflected(banded)))
        by_rows[{ r.y0, r.y1 }].push_back({ r.x0, r.x1, r.weight });
    std::vector<Profile> profiles;
    for (const auto& [rows, bars] : by_rows) {
        auto same = std::find_if(profiles.begin(), profiles.end(),
                                 [&](const Profile& p) { return p.bars == bars; });
        if (same == profiles.end())
            profiles.push_back({ bars, { rows } });
        else
            same->windows.push_back(rows);
    }
    return profiles;
}

// h[i] = sum over the bars of w (p[i + hi] - p[i + lo]): one profile of a prefix row.
BOKEH_HOT void profile_row(float* h, const double* p, const size_t* hi, const size_t* lo,
                           const double* w, size_t nbars, size_t n)
{
    if (nbars == 1) {
        for (size_t i = 0; i < n; ++i)
            h[i] = float(w[0] * (p[i + hi[0]] - p[i + lo[0]]));
        return;
    }
    if (nbars == 2) {
        for (size_t i = 0; i < n; ++i)
            h[i] = float(w[0] * (p[i + hi[0]] - p[i + lo[0]]) + w[1] * (p[i + hi[1]] - p[i + lo[1]]));
        return;
    }
    if (nbars == 3) {
        for (size_t i = 0; i < n; ++i)
            h[i] = float(w[0] * (p[i + hi[0]] - p[i + lo[0]]) + w[1] * (p[i + hi[1]] - p[i + lo[1]])
                         + w[2] * (p[i + hi[2]] - p[i + lo[2]]));
        return;
    }
    for (size_t i = 0; i < n; ++i) {
        double s = 0.0;
        for (size_t b = 0; b < nbars; ++b)
            s += w[b] * (p[i + hi[b]] - p[i + lo[b]]);
        h[i] = float(s);
    }
}

// t[i] += sum over k < count of (add[k][i] - sub[k][i]), the differences in double.
BOKEH_HOT void slide_rows(double* t, const float* const* add, const float* const* sub,
                          size_t count, size_t n)
{
    size_t k = 0;
    for (; k + 4 <= count; k += 4) {
        const float *a0 = add[k], *a1 = add[k + 1], *a2 = add[k + 2], *a3 = add[k + 3];
        const float *s0 = sub[k], *s1 = sub[k + 1], *s2 = sub[k + 2], *s3 = sub[k + 3];
        for (size_t i = 0; i < n; ++i)
            t[i] += ((double(a0[i]) - double(s0[i])) + (double(a1[i]) - double(s1[i])))
                    + ((double(a2[i]) - double(s2[i])) + (double(a3[i]) - double(s3[i])));
    }
    for (; k < count; ++k)
        for (size_t i = 0; i < n; ++i)
            t[i] += double(add[k][i]) - double(sub[k][i]);
}

}  // namespace

namespace detail {

// Flat in the size, nearly linear in the band count: measured (1080p RGBA, two threads,
// bokeh-bench) 33-35 ms with 4 bands and 41-48 with 8 at 15-37 px, i.e. 5.5 + 0.67 ns a
// pixel and channel per band on one thread (a pentagon's 16 bands over all its rows: 62-70
// ms at 23-44 px, 15 ns); spans_cost_ns reads a disk's spans right (1.0-1.06 of measured
// at 15 and 63 px), so the two compare as they are.
double bands_cost_ns(int w, int h, int bands, bool mirrored)
{
    const int split = mirrored ? bands : 2 * bands;  // as banded_from splits
    return double(w) * double(h) * (5.5 + 0.67 * double(split));
}

bool convolve_bands_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                           const KernelWeights& banded, Border border, int nthreads)
{
    constexpr int kStrip = 256;
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    const int w = roi.width(), h = roi.height(), rx = banded.rx, ry = banded.ry;
    const std::vector<Profile> profiles = band_profiles(banded);
    // Per profile, its bars as offsets into a prefix row that starts rx columns left of
    // the strip: output x sums row pixels x + x0 .. x + x1 = prefix[x + rx + x1 + 1] -
    // prefix[x + rx + x0].
    std::vector<size_t> hi, lo, first_bar;
    std::vector<double> weight;
    for (const Profile& p : profiles) {
        first_bar.push_back(hi.size());
        for (const Bar& b : p.bars) {
            hi.push_back(size_t(rx + b.x1 + 1) * ncs);
            lo.push_back(size_t(rx + b.x0) * ncs);
            weight.push_back(b.weight);
        }
    }
    first_bar.push_back(hi.size());
    size_t nwindows = 0;
    for (const Profile& p : profiles)
        nwindows += p.windows.size();
    const int ring = 2 * ry + 2;  // padded rows y - 1 .. y + 2 ry are in use at output row y
    const size_t np = profiles.size();
    const int nstrips = (w + kStrip - 1) / kStrip;
    parallel_for_chunks(0, nstrips, 1, nthreads, [&](int64_t s, int64_t) {
        const int xs = int(s) * kStrip, xe = std::min(w, xs + kStrip);
        const size_t n = size_t(xe - xs) * ncs;
        const size_t npx = size_t(xe - xs + 2 * rx);
        std::vector<float> row(npx * ncs), rows(np * size_t(ring) * n), out_row(n);
        std::vector<double> prefix((npx + 1) * ncs), total(n);
        std::vector<const float*> add(nwindows), sub(nwindows);
        auto ring_row = [&](size_t p, int j) { return rows.data() + (p * size_t(ring) + size_t(j % ring)) * n; };
        // Padded row j (source row roi.ybegin - ry + j) through every profile.
        auto horizontal = [&](int j) {
            const int x0   = roi.xbegin + xs - rx, x1 = roi.xbegin + xe + rx;
            const float* v = bordered_row_view(in, roi.ybegin - ry + j, x0, x1, border, row.data());
            if (!v) {
                for (size_t p = 0; p < np; ++p)
                    std::fill_n(ring_row(p, j), n, 0.0f);
                return;
            }
            row_prefix(prefix.data(), v, npx, nc);
            for (size_t p = 0; p < np; ++p)
                profile_row(ring_row(p, j), prefix.data(), hi.data() + first_bar[p],
                            lo.data() + first_bar[p], weight.data() + first_bar[p],
                            first_bar[p + 1] - first_bar[p], n);
        };
        for (int j = 0; j < 2 * ry; ++j)
            horizontal(j);
        for (int y = 0; y < h; ++y) {
            horizontal(y + 2 * ry);
            // Kernel row dy of output row y is padded row y + ry + dy; each window slides
            // down by one row: its row y1 enters, the row above y0 leaves.
            if (y == 0) {
                std::fill(total.begin(), total.end(), 0.0);
                for (size_t p = 0; p < np; ++p)
                    for (const auto& [y0, y1] : profiles[p].windows)
                        for (int dy = y0; dy <= y1; ++dy)
                            add_scaled(total.data(), ring_row(p, ry + dy), 1.0, n);
            } else {
                size_t k = 0;
                for (size_t p = 0; p < np; ++p)
                    for (const auto& [y0, y1] : profiles[p].windows) {
                        add[k]   = ring_row(p, y + ry + y1);
                        sub[k++] = ring_row(p, y - 1 + ry + y0);
                    }
                slide_rows(total.data(), add.data(), sub.data(), nwindows, n);
            }
            to_float(out_row.data(), total.data(), n);
            stream_floats(static_cast<float*>(dst.pixeladdr(roi.xbegin + xs, roi.ybegin + y)),
                          out_row.data(), n);
        }
        stream_fence();
    });
    return true;
}

// The plane path, for iris mode: a whole-frame summed-area table (Crow 1984), four reads
// a rectangle.
Plane convolve_banded(const Plane& in, const KernelWeights& kernel, int nthreads)
{
    const int nc = in.nc;
    Plane out(in.w - 2 * kernel.rx, in.h - 2 * kernel.ry, nc);
    const KernelWeights k         = reflected(kernel);
    const std::vector<Rect> rects = kernel_rects(k);

    // S[y][(x + 1) nc + c] = sum of in over rows < y, columns <= x (row 0 is zeros).
    const size_t sstride = size_t(in.w + 1) * size_t(nc);
    std::unique_ptr<double[]> sat(new double[size_t(in.h + 1) * sstride]);
    std::fill_n(sat.get(), sstride, 0.0);
    row_prefix_sums(in, sat.get() + sstride, nthreads);
    // Down the columns, in strips so each task owns its columns.
    constexpr size_t kStrip = 512;
    parallel_for_chunks(0, int64_t((sstride + kStrip - 1) / kStrip), 1, nthreads, [&](int64_t s, int64_t) {
        const size_t i0 = size_t(s) * kStrip, i1 = std::min(sstride, i0 + kStrip);
        for (int y = 2; y <= in.h; ++y) {
            double* p       = sat.get() + size_t(y) * sstride;
            const double* q = p - sstride;
            for (size_t i = i0; i < i1; ++i)
                p[i] += q[i];
        }
    });

    accumulate_in_strips(out, nthreads, [&](int y, size_t i0, std::vector<double>& acc) {
        const size_t n = acc.size();
        for (const Rect& r : rects) {
            // Rows y + ry + y0 .. y + ry + y1 of `in`: SAT rows (y + ry + y0) and (.. y1 + 1).
            const double* top = sat.get() + size_t(y + k.ry + r.y0) * sstride + i0;
            const double* bot = sat.get() + size_t(y + k.ry + r.y1 + 1) * sstride + i0;
            const size_t hi = size_t(k.rx + r.x1 + 1) * size_t(nc), lo = size_t(k.rx + r.x0) * size_t(nc);
            add_span(acc.data(), bot + hi, bot + lo, r.weight, n);
            add_span(acc.data(), top + lo, top + hi, r.weight, n);
        }
    });
    return out;
}

}  // namespace detail

KernelWeights banded_weights(const Kernel& k, int bands, int nthreads)
{
    return detail::banded_from(kernel_weights(k, nthreads), bands);
}

namespace detail {

KernelWeights banded_from(const KernelWeights& exact, int bands)
{
    if (exact.is_identity() || bands < 1)
        return exact;
    // A kernel symmetric in y (a disk, a polygon with an even number of blades) is split
    // over rows 0..ry of its lower half and the split mirrored; any other (a pentagon) over
    // all its rows -ry..ry, with twice the bands. (Mirroring every kernel would make a
    // pentagon's upper half its lower half's mirror image: measured 28-32 dB against the
    // exact pentagon at 23-44 px, a heptagon 33-38.)
    double peak = 0.0;
    for (double v : exact.w)
        peak = std::max(peak, v);
    bool mirrored = true;
    for (int r = 1; r <= exact.ry && mirrored; ++r)
        for (int dx = -exact.rx; dx <= exact.rx && mirrored; ++dx)
            mirrored = std::abs(exact.at(dx, r) - exact.at(dx, -r)) <= 1e-12 * peak;
    const int row0 = mirrored ? 0 : -exact.ry;  // band row r is kernel row row0 + r
    const int n    = exact.ry + 1 - row0;
    std::vector<double> area(static_cast<size_t>(n)), centre(static_cast<size_t>(n));
    for (int r = 0; r < n; ++r) {
        double a = 0.0, c = 0.0;
        for (int dx = -exact.rx; dx <= exact.rx; ++dx) {
            a += exact.at(dx, row0 + r);
            c += dx * exact.at(dx, row0 + r);
        }
        area[size_t(r)]   = a;
        centre[size_t(r)] = a > 0.0 ? c / a : 0.0;
    }
    // Least-squares split of rows 0..n-1 into at most `bands` runs (dynamic programming
    // over prefix sums: cost of a run = sum of (area - mean)^2).
    std::vector<double> s1(size_t(n) + 1, 0.0), s2(size_t(n) + 1, 0.0);
    for (int r = 0; r < n; ++r) {
        s1[size_t(r) + 1] = s1[size_t(r)] + area[size_t(r)];
        s2[size_t(r) + 1] = s2[size_t(r)] + area[size_t(r)] * area[size_t(r)];
    }
    auto run_cost = [&](int i, int j) {  // rows [i, j)
        const double s = s1[size_t(j)] - s1[size_t(i)];
        return (s2[size_t(j)] - s2[size_t(i)]) - s * s / (j - i);
    };
    const int nb = std::min(mirrored ? bands : 2 * bands, n);
    const double inf = std::numeric_limits<double>::infinity();
    std::vector<std::vector<double>> best(size_t(nb) + 1, std::vector<double>(size_t(n) + 1, inf));
    std::vector<std::vector<int>> cut(size_t(nb) + 1, std::vector<int>(size_t(n) + 1, 0));
    best[0][0] = 0.0;
    for (int b = 1; b <= nb; ++b)
        for (int j = 1; j <= n; ++j)
            for (int i = b - 1; i < j; ++i)
                if (best[size_t(b) - 1][size_t(i)] < inf) {
                    const double c = best[size_t(b) - 1][size_t(i)] + run_cost(i, j);
                    if (c < best[size_t(b)][size_t(j)]) {
                        best[size_t(b)][size_t(j)] = c;
                        cut[size_t(b)][size_t(j)]  = i;
                    }
                }
    std::vector<int> starts;
    for (int b = nb, j = n; b > 0; j = cut[size_t(b)][size_t(j)], --b)
        starts.push_back(cut[size_t(b)][size_t(j)]);
    std::reverse(starts.begin(), starts.end());
    starts.push_back(n);

    KernelWeights out;
    out.rx = exact.rx + 1;  // an interval of the mean width may end a pixel further out
    out.ry = exact.ry;
    const int onx = 2 * out.rx + 1;
    out.w.assign(size_t(onx) * size_t(2 * out.ry + 1), 0.0);
    for (size_t b = 0; b + 1 < starts.size(); ++b) {
        const int i = starts[b], j = starts[b + 1];
        double a = 0.0, c = 0.0;
        for (int r = i; r < j; ++r) {
            a += area[size_t(r)];
            c += centre[size_t(r)] * area[size_t(r)];
        }
        const double mean_area = a / (j - i), mean_centre = a > 0.0 ? c / a : 0.0;
        if (mean_area <= 0.0)
            continue;
        const double len = mean_area / peak;  // an interval at the kernel's full level
        const IntervalWeights iw = interval_weights(mean_centre - 0.5 * len, mean_centre + 0.5 * len);
        for (int r = i; r < j; ++r)
            for (int sign : { 1, -1 }) {
                if (sign < 0 && (r == 0 || !mirrored))
                    continue;
                const int dy = sign * (row0 + r);
                for (size_t q = 0; q < iw.w.size(); ++q) {
                    const int dx = iw.first + int(q);
                    if (std::abs(dx) <= out.rx)
                        out.w[size_t((dy + out.ry) * onx + (dx + out.rx))] = iw.w[q] * mean_area;
                }
            }
    }
    double sum = 0.0;
    for (double v : out.w)
        sum += v;
    for (double& v : out.w)
        v /= sum;
    return out;
}

// The banded kernel's error is in its edge rows, and on an image it grows with the kernel at
// equal L1 distance: on bokeh-bench's crop of the lights frame (disk, pentagon, heptagon,
// octagon at 0 and 22.5 degrees, 21-47 px, 2-8 bands), a distance of 0.049
// gave 38.9 dB at 47 px and 0.075 gave 40.9 at 21 px. Distance times the square root of
// the size under 0.27 kept all 490 cases at 41.0 dB or more (the least: a heptagon, 31
// px, 6 bands); the fewest bands within it are 4-6 for a disk at 21-47 px, 4-8 for the
// others. Calibrated on one frame, so a bound with ~1 dB to spare, not a guarantee.
int fast_band_count(const KernelWeights& exact, double size_px)
{
    constexpr int kFewest = 3, kMost = 8;
    for (int bands = kFewest; bands < kMost; ++bands) {
        const KernelWeights banded = banded_from(exact, bands);
        double l1 = 0.0;  // banded's grid is exact's, a column wider each side
        for (int dy = -banded.ry; dy <= banded.ry; ++dy)
            for (int dx = -banded.rx; dx <= banded.rx; ++dx)
                l1 += std::abs(banded.at(dx, dy) - (std::abs(dx) <= exact.rx ? exact.at(dx, dy) : 0.0));
        if (l1 * std::sqrt(size_px) < 0.27)
            return bands;
    }
    return kMost;
}

}  // namespace detail

}  // namespace bokeh
