// blur_hexagon.cpp — the hexagon by three parallelograms (BlurMethod::Parallelograms):
// which frame and path a hexagon takes, the direct path from the source, the path on a
// padded plane (iris mode), and the method's reach, cost model and accuracy bound.
//
// Source: Kawase, "Anti reduced-buffer artifacts" (a hexagon as three parallelograms, each
// two skewed 1-D blurs); the rhombus split of McIntosh, Riecke and DiPaola
// 2012, "Efficiently simulating the bokeh of polygonal apertures in a post-process depth
// of field shader". A hexagon with centre O and vertices P0..P5 is the union of the rhombi
// {a P(2j) + b P(2j+2) : a, b in [0, 1]}, j = 0, 1, 2 (P1 = P0 + P2 for any affine image of
// a regular hexagon), so the uniform hexagon is the mean of three parallelogram kernels,
// and a parallelogram is the convolution of two uniform segments. Each segment pass costs
// the same whatever its length (blur_hexagon_sweep.cpp): a running sum along its major
// axis, a shear through the three-tap quadratic B-spline across it. The interpolations keep
// energy and the centroid exactly and soften the kernel's slanted edges by under a pixel;
// that is the method's error against the exact hexagon.
//
// Three paths, by rotation:
// * Multiples of 30 degrees (the upright and the flat-topped hexagon): one segment runs
//   along the rows of the working frame (the source's transpose for the upright one, the
//   source itself for the flat-topped) and one sweep down the rows makes the hexagon
//   (hexagon_sweep). Outside iris mode hexagon_direct reads the source and writes `dst`
//   directly: the flat-topped frame's lines are source rows, read in place; the upright
//   frame's are source columns, gathered into a ring and scattered back kColumnBatch at a
//   time. A/B against the four passes at 15-255 px (1080p RGBA, two threads): 0.56-0.68 of
//   their time upright, 0.42-0.53 flat-topped.
// * Other rotations: one segment lies within 30 degrees of the rows; the frame is sheared
//   so that it runs along them and the same sweep runs there (blur_hexagon_sheared.cpp).
// * A hexagon stretched so far that no shear leaves two of its segments steep (45 x 15 px
//   at 20 degrees, say): four segment passes on a padded plane (hexagon_parallelograms).
//
// Limits: six straight blades only (no curvature, no hole: blur.cpp refuses the method
// for them). The softening makes small hexagons miss the 40 dB budget of method=fast:
// parallelograms_budget_px says from which size they keep it.

#include <bokeh/base.h>
#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/hexagon.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <utility>

namespace bokeh::detail {

namespace {


}  // namespace

// Vertex i of the kernel's hexagon in pixel offsets (y down), as kernel.cpp places them.
std::pair<double, double> hexagon_vertex(const Kernel& k, int i)
{
    const double theta = kPi * (90.0 + k.rotation_deg + 60.0 * i) / 180.0;
    return { 0.5 * k.width_px * std::cos(theta), -0.5 * k.height_px * std::sin(theta) };
}

// The three segments in the source's frame or, `transposed`, in its transpose's.
std::array<Dir, 3> frame_dirs(const Kernel& k, bool transposed)
{
    std::array<Dir, 3> d;
    for (int i = 0; i < 3; ++i) {
        const auto [x, y] = hexagon_vertex(k, 2 * i);
        d[size_t(i)]      = { x, y };
    }
    if (transposed)
        for (Dir& v : d)
            std::swap(v.x, v.y);
    return d;
}

namespace {

// Whether the planes' passes (the sweep along the rows, the four passes) run on the
// transposed plane: where fewer than two segments are steep as given.
bool frame_transposed(const Kernel& k)
{
    const std::array<Dir, 3> d = frame_dirs(k, false);
    return std::count_if(d.begin(), d.end(), [](Dir v) { return v.steep(); }) < 2;
}

// The steep segments a and b (a the less sheared) and c in the frame the passes run in.
std::array<Dir, 3> working_dirs(const Kernel& k)
{
    std::array<Dir, 3> d = frame_dirs(k, frame_transposed(k));
    std::sort(d.begin(), d.end(), [](Dir p, Dir q) { return p.slope() < q.slope(); });
    return d;
}

bool runs_along_rows(const Dir& c) { return std::abs(c.y) < 1e-9 * std::abs(c.x); }

// Whether the hexagon's third segment runs along the rows of its working frame (the
// upright and the flat-topped hexagon: no shear needed).
bool along_rows(const Kernel& k) { return runs_along_rows(working_dirs(k)[2]); }

// Whether the hexagon takes a sheared frame: not along the rows, and a shear serves.
bool sheared(const Kernel& k) { return !along_rows(k) && (column_shear(k, false) || column_shear(k, true)); }

}  // namespace

Plane hexagon_parallelograms(Plane in, const Kernel& k, int margin_x, int margin_y, int nthreads)
{
    // a and b steep (a the less sheared: it runs twice), c the third.
    const std::array<Dir, 3> d = working_dirs(k);
    const Dir a = d[0], b = d[1], c = d[2];

    // hexagon = (rhombus(a, b) + rhombus(b, c) + rhombus(c, a)) / 3
    //         = (seg_c (seg_a + seg_b) + seg_a seg_b) / 3: one pass of c, here the
    // costliest (hexagon_sweep, where c runs along the rows, groups them the other way).
    // Two planes besides `in`, each reused once its values are used up (a fresh 1080p
    // plane costs its page faults).
    // Each pass computes only what the later ones read, back from the output region (the
    // plane less its margins): without that the passes would cover the whole padded
    // plane, which grows with the kernel (1.37x the pixels at 255 px).
    const int w = in.w, h = in.h;
    const Region all{ 0, 0, w, h };
    const Region out_region{ margin_x, margin_y, w - margin_x, h - margin_y };
    // Other rotations: the sheared frame's sweep, if one serves (blur.cpp padded the plane
    // as given then: hexagon_transposed is false for them); else the four passes below.
    if (!runs_along_rows(c))
        if (std::optional<Plane> out = sheared_on_plane(in, k, margin_x, margin_y, nthreads))
            return std::move(*out);
    if (runs_along_rows(c)) {  // one sweep (iris mode; hexagon_direct otherwise)
        Plane out(w, h, in.nc);
        const size_t ncs = size_t(in.nc);
        SweepIO io;
        io.w    = w;
        io.h    = h;
        io.lines = [&](int r, int n, int c0, int c1, float* const*, RowSpan* lines) {
            for (int i = 0; i < n; ++i)
                lines[i] = { in.row(r + i) + size_t(c0) * ncs, 0, c1 - c0 };
        };
        io.out_row = [&](int y, int x0, int) { return out.row(y) + size_t(x0) * ncs; };
        hexagon_sweep(io, in.nc, out_region, a.x, a.y, b.x, b.y, c.x, nthreads);
        return out;
    }
    const Region s_region = grown_by(out_region, c.x, c.y, w, h);
    const Region b_region = hull(s_region, grown_by(out_region, a.x, a.y, w, h));
    Plane segb(w, h, in.nc), sum_ab(w, h, in.nc);
    segment_pass(in, all, segb, b_region, b.x, b.y, nullptr, 1.0f, nthreads);
    segment_pass(in, all, sum_ab, s_region, a.x, a.y, &segb, 1.0f, nthreads);
    Plane& ab = in;
    segment_pass(segb, b_region, ab, out_region, a.x, a.y, nullptr, 1.0f, nthreads);
    Plane& out = segb;
    segment_pass(sum_ab, s_region, out, out_region, c.x, c.y, &ab, float(1.0 / 3.0), nthreads);
    return std::move(out);
}

bool hexagon_transposed(const Kernel& k) { return frame_transposed(k) && !sheared(k); }

int hexagon_plane_extra(const Kernel& k) { return sheared(k) ? 4 : 0; }

bool hexagon_sweeps(const Kernel& k) { return along_rows(k) || sheared(k); }

// Flat in the size, by path, in spans_cost_ns's units (ns a pixel and channel on one
// thread): the sweep 3.6 flat-topped and 4.6 upright, the four passes 30. Fitted on this
// project's machine (AMD EPYC, 1 MiB L2), where the sweep is the cheaper of the two
// against the exact spans from 9-10 px (spot timings, 1080p RGBA, two threads, 9 runs each:
// upright 10.8 against the spans' 10.6 ms at 9 px, 11.1 against 12.1 at 11; flat-topped
// 10.3 against 10.6 at 9, 10.2 against 9.0 at 7): with these, `fast` takes the sweep from
// 9 px flat-topped and 10 px upright. The constants are the machine's: 5 and 7.5, fitted
// on an earlier one, crossed at 13 and 19 px (the four passes measured 3.7-3.8x the spans
// at 15 px on both). spans_cost_ns reads a hexagon's spans within 0.84-1.18 of measured at
// 31-63 px, so the two models compare as they are. The sheared sweep: its frame's cost
// (cheaper_shear) times kShearTapsCost.
double parallelograms_cost_ns(const Kernel& k, int w, int h)
{
    double ns = 30.0;  // the four passes
    if (along_rows(k))
        ns = hexagon_transposed(k) ? kSweepUprightNs : kSweepFlatNs;
    else if (cheaper_shear(k, w, h, &ns))
        ns *= kShearTapsCost;
    return double(w) * double(h) * ns;
}

// Their error is the slanted edges' softening by the taps, under a pixel, so it falls with
// the size: on bokeh-bench's scene (PSNR after its tone map, 1080p) the sweep
// along the rows measured 38.8-39.0 dB at 13 px and 40.5-40.6 at 15; the sheared sweep,
// two reads through the taps more, 38.5-38.7 at 23 px and 40.0-40.2 at 27 (7 and 20
// degrees). Stretched hexagons (anamorphic) are softened as much on their narrow side, so
// that side decides, and more (bokeh-bench's crop blurred alone): 2:1 and 3:1
// along the rows (0 and 90 degrees) 38.2-40.1 dB at 15 px across, 39.7-43.0 at 18,
// 43.0-45.1 at 21; sheared or the four passes (left for hexagons stretched past any shear)
// 36.4-37.2 at 15 across, 39.2 at 21, 40.5-43.7 at 27 (54 x 27 to 81 x 27 at 7 and 20
// degrees).
double parallelograms_budget_px(const Kernel& k)
{
    if (!along_rows(k))
        return 27.0;
    return k.width_px == k.height_px ? 15.0 : 21.0;
}

bool hexagon_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                    const Kernel& k, int rx, int ry, Border border, int nthreads)
{
    const std::array<Dir, 3> d = working_dirs(k);
    const Dir a = d[0], b = d[1], c = d[2];
    if (!runs_along_rows(c))
        return hexagon_sheared_direct(dst, in, roi, k, *cheaper_shear(k, roi.width(), roi.height()), rx, ry,
                                      border, nthreads);
    const bool t = hexagon_transposed(k);
    prepare_destination(dst, in, roi);
    const int nc = in.nchannels();
    const size_t ncs = size_t(nc);
    const OIIO::ROI data = in.roi(), region = grown(roi, rx, ry);
    // Working pixel (x, y) is source pixel (region.xbegin + x, region.ybegin + y), or
    // (region.xbegin + y, region.ybegin + x) transposed; outputs are the frame less its
    // margins, which is roi.
    SweepIO io;
    io.w = t ? region.height() : region.width();
    io.h = t ? region.width() : region.height();
    const Region out_region{ t ? ry : rx, t ? rx : ry, io.w - (t ? ry : rx), io.h - (t ? rx : ry) };
    if (border == Border::Black) {
        const Region lit{ data.xbegin - region.xbegin, data.ybegin - region.ybegin,
                          data.xend - region.xbegin, data.yend - region.ybegin };
        io.lit = t ? transposed(lit) : lit;
    }
    if (!t) {
        io.lines = [&](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
            for (int i = 0; i < n; ++i)
                lines[i] = bordered_row_span(in, region.ybegin + r + i, region.xbegin + c0,
                                             region.xbegin + c1, border, bufs[i]);
        };
        io.out_row = [&](int y, int x0, int) {
            return static_cast<float*>(dst.pixeladdr(region.xbegin + x0, region.ybegin + y));
        };
    } else {
        // Lines are source columns and output rows destination columns, so both go by
        // batches of adjacent columns (kColumnBatch): a row's pixels of a batch share cache
        // lines, read or written at once. One column at a time, a 1920 px frame's column
        // put its pixels' cache lines in 2 of L1's 64 sets (the row pitch, 30720 bytes, is
        // 480 lines), and each line was fetched again for each of its four pixels: the
        // upright hexagon at 63 px took 45-51 ms on a 1900 px wide frame against 54-58 at
        // 1920, and a bare column-at-a-time transpose 6.6 ms against 14.7. Batched, A/B
        // against one at a time (bokeh-ab): 0.79-0.86x at 15-63 px, 0.89-0.92x at 127-255.
        io.batch = kColumnBatch;
        io.lines = [&](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
            // Only the lit part of a column is gathered; the rest is black by the span.
            const int a = std::max(c0, io.lit.x0), b = std::min(c1, io.lit.x1);
            for (int i = 0; i < n;) {
                const int sx = border_index(region.xbegin + r + i, data.xbegin, data.xend, border);
                if (sx == kOutside || b <= a) {
                    lines[i++] = {};
                    continue;
                }
                int run = 1;  // the source columns adjacent to sx, in order
                while (i + run < n
                       && border_index(region.xbegin + r + i + run, data.xbegin, data.xend, border) == sx + run)
                    ++run;
                source_columns(in, sx, run, region.ybegin + a, region.ybegin + b, border, bufs + i);
                for (int j = 0; j < run; ++j, ++i)
                    lines[i] = { bufs[i], a - c0, b - c0 };
            }
        };
        io.out_row = [](int, int, int) -> float* { return nullptr; };
        const size_t pitch = size_t(dst.spec().width) * ncs;  // prepare_destination: roi-sized
        // `pitch` by value: this block ends before hexagon_sweep calls the lambda.
        io.store = [&, pitch](int y, int n, int x0, int x1, const float* rows) {
            const size_t row_len = size_t(x1 - x0) * ncs;
            float* d = static_cast<float*>(dst.pixeladdr(region.xbegin + y, region.ybegin + x0));
            const size_t bytes = size_t(n) * ncs * sizeof(float);
            for (int x = x0; x < x1; ++x, d += pitch) {
                if (x + kPrefetchRows < x1)
                    prefetch_lines(d + kPrefetchRows * pitch, bytes, true);
                copy_pixels(d, ncs, rows + size_t(x - x0) * ncs, row_len, n, nc);
            }
        };
    }
    hexagon_sweep(io, nc, out_region, a.x, a.y, b.x, b.y, c.x, nthreads);
    return true;
}

int hexagon_reach(const Kernel& k, bool along_x)
{
    double r = 0.0;
    for (int i = 0; i < 6; ++i) {
        const auto [x, y] = hexagon_vertex(k, i);
        r = std::max(r, std::abs(along_x ? x : y));
    }
    // A rhombus is two steep segments in series, and each spreads its segment by its
    // shear's and its unshear's three taps (< 1.5 px each) and its last row's drift
    // (< 0.5 px): < 7 px past the hexagon, so at whole offsets at most ceil(r) + 6.
    // A reach of ceil(r) + 2 is too short: measured, the parallelograms reach up to 5 px
    // past the hexagon (9 px: 10 against 4.5), and under clamp or mirror the frame's edge
    // pixels then lost up to 7.7e-6 of a constant image, read as black past the padding
    // (tests/blur/blur_properties_test.cpp checks a constant image under every border).
    return int(std::ceil(r)) + 6;
}

}  // namespace bokeh::detail
