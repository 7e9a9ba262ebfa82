// blur_approx.cpp — the fast approximations of the flat bokeh kernels, each measured
// against the exact kernel it stands for (bokeh-bench, tests/blur_test.cpp).
//
// Hexagon from three parallelograms (SEEDS.md section 5, seed 004; the rhombus split of
// McIntosh, Riecke and DiPaola 2012, "Efficiently simulating the bokeh of polygonal
// apertures in a post-process depth of field shader"). A hexagon with centre O and
// vertices P0..P5 is the union of the rhombi {a P(2j) + b P(2j+2) : a, b in [0, 1]},
// j = 0, 1, 2 (P1 = P0 + P2 for any affine image of a regular hexagon), so the uniform
// hexagon is the mean of three parallelogram kernels, and a parallelogram is the
// convolution of two uniform segments. Four segment passes make it: A = seg(P0) in,
// B = seg(P2) in, then (seg(P2) A + seg(P4) (A + B)) / 3. Each segment pass costs the
// same whatever its length: along its major axis it is a running sum (prefix
// differences, fractional ends weighted by overlap); across, the plane is sheared by
// linear interpolation so the segment runs along a row, and sheared back. Both
// interpolations keep energy and the centroid exactly and soften the kernel's slanted
// edges by under a pixel; that is the method's error against the exact hexagon.
//
// Bands (disk, polygon): the exact kernel's rows are grouped into a few horizontal bands
// (boundaries by dynamic programming, least squares on the row areas), each band's rows
// replaced by one interval of the same mean area and centre, anti-aliased at its ends;
// the bands are rectangles, each summed from a summed-area table (Crow 1984) with four
// reads a corner pair, so the cost depends on the band count, not the kernel size.
// Changed for speed (issue 3): outside iris mode the table is no longer one whole-frame
// double plane (68-77 MB at 1080p, ~60 ms per call) but built per output tile by
// convolve_spans_direct (blur.cpp) straight from the source, each rectangle becoming two
// signed spans of the tile's table (banded_table_spans); convolve_banded keeps the plane
// path for iris mode and for kernels reaching over 64 px: the tile's table covers the
// tile plus the kernel's reach, so its building cost grows with the kernel.
//
// Bilinear taps (SEEDS.md section 5): the seed's 9x9 disk from 25 bilinear fetches and
// a 17x17 one from 81. The taps are grouped 2 (or 1, the centre) per axis; a fetch sits
// at the area-weighted centroid of its group, weighted by the group's disk area, so its
// bilinear footprint matches the group's marginals but not its joint weights. On a GPU
// the fetches are free; on a CPU we convolve with the kernel they add up to.
//
// Known limits: the parallelogram split is for six-bladed straight apertures only;
// bands do not model a catadioptric hole. Summed-area tables are double: an image whose
// total energy exceeds ~1e12 loses digits in dark areas (none of the test scenes comes
// within 1e4 of it).

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "plane.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace bokeh {

using namespace detail;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Pixel i's share of the interval [a, b]: the length of [i - 1/2, i + 1/2] inside it,
// over b - a. `first` is the first pixel with a share; `w` the shares from there.
struct IntervalWeights {
    int first = 0;
    std::vector<double> w;
    int last() const { return first + int(w.size()) - 1; }
};

IntervalWeights interval_weights(double a, double b)
{
    IntervalWeights iw;
    iw.first     = int(std::floor(a + 0.5));
    const int i1 = int(std::ceil(b - 0.5));
    for (int i = iw.first; i <= i1; ++i) {
        const double lo = std::max(a, i - 0.5), hi = std::min(b, i + 0.5);
        iw.w.push_back(std::max(0.0, hi - lo) / (b - a));
    }
    return iw;
}

// --- hexagon from three parallelograms -----------------------------------------------

// Quadratic B-spline weights for reading a row at real position p: three taps from
// `first`, sum 1, centroid exactly p. Linear interpolation (two taps) also keeps both,
// but its response to a thin line depends on the line's phase ((1 - f)^2 + f^2 at
// coincidence): two sheared passes crossing each other then leave a 20 % moire inside
// the hexagon; the B-spline's phase dependence is an order smaller.
struct Taps {
    int first;
    float w[3];
    explicit Taps(double p, bool on_grid = false)
    {
        const double n = std::floor(p + 0.5), d = p - n;  // d in [-1/2, 1/2)
        first = int(n) - 1;
        if (on_grid) {  // no shear: read the pixel itself, no smoothing
            w[0] = w[2] = 0.0f;
            w[1]        = 1.0f;
            return;
        }
        w[0]  = float(0.5 * (0.5 - d) * (0.5 - d));
        w[1]  = float(0.75 - d * d);
        w[2]  = float(0.5 * (0.5 + d) * (0.5 + d));
    }
};

// out(p) = mean over t in [0, 1] of in(p - t (ex, ey)), for |ey| <= |ex|: the uniform
// segment from 0 to e, run along x. Same-size planes; `in` is zero outside itself.
// Shear: G(x, v) = in(x, v + m x), m = ey / ex, so the segment lies along G's row
// v = y - m x; H = the running sum along G's rows; out(x, y) = H(x, y - m x).
Plane segment_pass_x(const Plane& in, double ex, double ey, int nthreads)
{
    const int w = in.w, h = in.h, nc = in.nc;
    const size_t ncs = size_t(nc);
    // A slope under 1e-9 moves a segment of any allowed length by under a micro-pixel.
    const double m = std::abs(ey) < 1e-9 * std::abs(ex) ? 0.0 : ey / ex;
    const IntervalWeights iw = interval_weights(std::min(0.0, ex), std::max(0.0, ex));
    const int first = iw.first, last = iw.last();
    const double inner = iw.w.size() > 2 ? iw.w[1] : 0.0;

    // Rows v of G that any output reads (with the +1 of the interpolation).
    const int vlo = int(std::floor(std::min(0.0, -m * (w - 1)))) - 2;
    const int vhi = int(std::ceil(h - 1 + std::max(0.0, -m * (w - 1)))) + 2;
    const int nv  = vhi - vlo + 1;
    Plane hsum(w, nv, nc);
    std::vector<int> hx0(static_cast<size_t>(nv)), hx1(static_cast<size_t>(nv));  // the columns of each row written

    parallel_for_chunks(0, nv, 8, nthreads, [&](int64_t r0, int64_t r1) {
        std::vector<float> g;
        std::vector<double> prefix;
        for (int r = int(r0); r < int(r1); ++r) {
            const int v = vlo + r;
            // Columns where row v of G touches the plane: -1.5 < v + m x < h + 0.5.
            int gx0 = 0, gx1 = w;
            if (m != 0.0) {
                const double a = (-1.5 - v) / m, b = (h + 0.5 - v) / m;
                gx0 = int(std::clamp(std::floor(std::min(a, b)), 0.0, double(w)));
                gx1 = int(std::clamp(std::ceil(std::max(a, b)) + 1.0, 0.0, double(w)));
            } else if (v < 0 || v >= h) {
                gx1 = 0;
            }
            if (gx1 <= gx0) {
                hx0[size_t(r)] = hx1[size_t(r)] = 0;
                continue;
            }
            // G's row, with (last - first + 1) zeros each side so every read below is inside.
            const int margin = last - first + 1;
            const int base   = gx0 - margin;  // G column of g[0]
            const size_t len = size_t(gx1 - gx0 + 2 * margin);
            g.assign(len * ncs, 0.0f);
            for (int x = gx0; x < gx1; ++x) {
                const Taps t(v + m * x, m == 0.0);
                float* out = g.data() + size_t(x - base) * ncs;
                for (int j = 0; j < 3; ++j) {
                    const int y = t.first + j;
                    if (y < 0 || y >= h)
                        continue;
                    const float* p = in.row(y) + size_t(x) * ncs;
                    for (int c = 0; c < nc; ++c)
                        out[c] += t.w[j] * p[c];
                }
            }
            prefix.assign((len + 1) * ncs, 0.0);
            for (size_t i = 0; i < len * ncs; ++i)
                prefix[i + ncs] = prefix[i] + double(g[i]);
            // H(x) = sum_i w_i G(x - i), i in [first, last]; outputs where that touches G.
            const int x0 = std::max(0, gx0 + first), x1 = std::min(w, gx1 + last);
            hx0[size_t(r)] = x0;
            hx1[size_t(r)] = std::max(x0, x1);
            float* out     = hsum.row(r);
            for (int x = x0; x < x1; ++x) {
                const size_t k = size_t(x - base);  // g index of G(x)
                const float* g_first = g.data() + (k - size_t(first)) * ncs;
                const float* g_last  = g.data() + (k - size_t(last)) * ncs;
                for (int c = 0; c < nc; ++c) {
                    double s = iw.w.front() * g_first[c];
                    if (last != first)
                        s += iw.w.back() * g_last[c];
                    if (last - first > 1)  // G(x - last + 1) .. G(x - first - 1)
                        s += inner * (prefix[(k - size_t(first)) * ncs + size_t(c)]
                                      - prefix[(k - size_t(last) + 1) * ncs + size_t(c)]);
                    out[size_t(x) * ncs + size_t(c)] = float(s);
                }
            }
        }
    });

    Plane out(w, h, nc);
    parallel_for_chunks(0, h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* o = out.row(y);
            for (int x = 0; x < w; ++x) {
                const Taps t(y - m * x, m == 0.0);
                float* px = o + size_t(x) * ncs;
                std::fill_n(px, nc, 0.0f);
                for (int j = 0; j < 3; ++j) {
                    const int r = t.first + j - vlo;
                    if (x < hx0[size_t(r)] || x >= hx1[size_t(r)])
                        continue;
                    const float* p = hsum.row(r) + size_t(x) * ncs;
                    for (int c = 0; c < nc; ++c)
                        px[c] += t.w[j] * p[c];
                }
            }
        }
    });
    return out;
}

// The uniform segment from 0 to e along whichever axis is its major one.
Plane segment_pass(const Plane& in, double ex, double ey, int nthreads)
{
    if (std::abs(ex) >= std::abs(ey))
        return segment_pass_x(in, ex, ey, nthreads);
    return transposed(segment_pass_x(transposed(in, nthreads), ey, ex, nthreads), nthreads);
}

// a = (a + b) * scale.
void add_into(Plane& a, const Plane& b, float scale, int nthreads)
{
    parallel_for_chunks(0, a.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* p       = a.row(y);
            const float* q = b.row(y);
            for (size_t i = 0; i < a.stride(); ++i)
                p[i] = (p[i] + q[i]) * scale;
        }
    });
}

// Vertex i of the kernel's hexagon in pixel offsets (y down), as kernel.cpp places them.
std::pair<double, double> hexagon_vertex(const Kernel& k, int i)
{
    const double theta = kPi * (90.0 + k.rotation_deg + 60.0 * i) / 180.0;
    return { 0.5 * k.width_px * std::cos(theta), -0.5 * k.height_px * std::sin(theta) };
}

// --- bands on a summed-area table ----------------------------------------------------

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

}  // namespace

namespace detail {

std::vector<Span> banded_table_spans(const KernelWeights& kernel)
{
    // Rectangle rows y0 .. y1 of the reflected kernel: + the table row below it (y1 + 1),
    // - the row on top (y0), as in convolve_banded.
    std::vector<Span> spans;
    for (const Rect& r : kernel_rects(reflected(kernel))) {
        spans.push_back({ r.y1 + 1, r.x0, r.x1, r.weight });
        spans.push_back({ r.y0, r.x0, r.x1, -r.weight });
    }
    return spans;
}

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

// --- public --------------------------------------------------------------------------

KernelWeights banded_weights(const Kernel& k, int bands)
{
    const KernelWeights exact = kernel_weights(k);
    if (exact.is_identity() || bands < 1)
        return exact;
    // Row areas and centres, rows 0..ry of the lower half (the kernel is symmetric in y
    // for every shape here: the band split is mirrored).
    const int n = exact.ry + 1;
    std::vector<double> area(static_cast<size_t>(n)), centre(static_cast<size_t>(n));
    double peak = 0.0;
    for (double v : exact.w)
        peak = std::max(peak, v);
    for (int r = 0; r < n; ++r) {
        double a = 0.0, c = 0.0;
        for (int dx = -exact.rx; dx <= exact.rx; ++dx) {
            a += exact.at(dx, r);
            c += dx * exact.at(dx, r);
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
    const int nb = std::min(bands, n);
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
                if (sign < 0 && r == 0)
                    continue;
                const int dy = sign * r;
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

KernelWeights bilinear_tap_weights(const Kernel& k, int* fetches)
{
    const KernelWeights exact = kernel_weights(k);
    // Pixels grouped per axis: the centre alone, then pairs outward.
    auto groups = [](int r) {
        std::vector<std::pair<int, int>> g;  // [first, last]
        for (int a = -r; a < 0; a += 2)
            g.push_back({ a, std::min(a + 1, -1) });
        g.push_back({ 0, 0 });
        for (int a = 1; a <= r; a += 2)
            g.push_back({ a, std::min(a + 1, r) });
        return g;
    };
    const auto gx = groups(exact.rx), gy = groups(exact.ry);
    KernelWeights out{ exact.rx, exact.ry, std::vector<double>(exact.w.size(), 0.0) };
    const int nx = 2 * exact.rx + 1;
    int count    = 0;
    for (const auto& [y0, y1] : gy)
        for (const auto& [x0, x1] : gx) {
            double total = 0.0, sx = 0.0, sy = 0.0;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    total += exact.at(x, y);
                    sx += (x - x0) * exact.at(x, y);
                    sy += (y - y0) * exact.at(x, y);
                }
            if (total <= 0.0)
                continue;
            ++count;
            // One fetch at the centroid: bilinear weights (1 - f, f) on each axis.
            const double fx = sx / total, fy = sy / total;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    const double wx = x == x0 ? 1.0 - fx : fx, wy = y == y0 ? 1.0 - fy : fy;
                    out.w[size_t((y + exact.ry) * nx + (x + exact.rx))] += total * wx * wy;
                }
        }
    if (fetches)
        *fetches = count;
    return out;
}

namespace detail {

Plane hexagon_parallelograms(const Plane& in, const Kernel& k, int nthreads)
{
    const auto [p0x, p0y] = hexagon_vertex(k, 0);
    const auto [p2x, p2y] = hexagon_vertex(k, 2);
    const auto [p4x, p4y] = hexagon_vertex(k, 4);
    Plane a = segment_pass(in, p0x, p0y, nthreads);
    Plane b = segment_pass(in, p2x, p2y, nthreads);
    Plane r0 = segment_pass(a, p2x, p2y, nthreads);
    add_into(a, b, 1.0f, nthreads);
    b        = Plane();
    Plane r12 = segment_pass(a, p4x, p4y, nthreads);
    add_into(r12, r0, float(1.0 / 3.0), nthreads);
    return r12;
}

int hexagon_reach(const Kernel& k, bool along_x)
{
    double r = 0.0;
    for (int i = 0; i < 6; ++i) {
        const auto [x, y] = hexagon_vertex(k, i);
        r = std::max(r, std::abs(along_x ? x : y));
    }
    return int(std::ceil(r)) + 2;  // + the shear's interpolation
}

}  // namespace detail

}  // namespace bokeh
