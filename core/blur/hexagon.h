// hexagon.h — internal to the library: what the hexagon's three files share.
// blur_hexagon.cpp picks the frame and the path; blur_hexagon_sweep.cpp holds the segment
// windows, the four passes and the fused sweep; blur_hexagon_sheared.cpp the sheared frame.
#pragma once

#include "blur/convolve.h"

#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <utility>

namespace bokeh::detail {

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

// A rectangle of plane pixels, [x0, x1) x [y0, y1).
struct Region {
    int x0, y0, x1, y1;
};

// The same rectangle in the transposed frame.
inline Region transposed(const Region& r) { return { r.y0, r.x0, r.y1, r.x1 }; }

// Where the fused sweep reads and writes, in its working frame of w x h pixels: `lines`
// gives lines r .. r + n - 1 over columns [c0, c1) (lines[i] a view or filled into
// bufs[i], its span relative to c0; no pixels when all black), `out_row` where output
// row y goes over [x0, x1), or null to hand the rows to `store`, up to `batch` at once
// (y .. y + n - 1, one after another).
// A batch of more than one line suits a source read down its columns (hexagon_direct).
// `keep`: the rows handed to `store` come with the `keep` rows before them in memory
// (rows - keep * row length on; those before the chunk's first row undefined), for a
// store that reads taps across batches (the sheared frame's unshear).
// `lit`: lines and columns outside it are black (the source's data window under the black
// border), so no window slides before its first lit line, nor makes T where no lit column
// reaches. `first_lit`, where given, says the first line with a lit pixel in columns
// [c0, c1) instead of lit.y0; `out_rows` the output rows [y0, y1) a chunk of columns
// [x0, x1) needs instead of the out region's (the sheared frame, where they drift with x).
struct SweepIO {
    int w = 0, h = 0;
    int batch = 1, keep = 0;
    Region lit{ 0, 0, std::numeric_limits<int>::max(), std::numeric_limits<int>::max() };
    std::function<int(int c0, int c1)> first_lit;
    std::function<std::pair<int, int>(int x0, int x1)> out_rows;
    std::function<void(int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines)> lines;
    std::function<float*(int y, int x0, int x1)> out_row;
    std::function<void(int y, int n, int x0, int x1, const float* rows)> store;
};

/// The hexagon in one sweep down the rows of the working frame `io` describes, its third
/// segment (cx, 0) along the rows and a, b steep; outputs over `out_region`
/// (blur_hexagon_sweep.cpp).
void hexagon_sweep(const SweepIO& io, int nc, const Region& out_region, double ax, double ay,
                   double bx, double by, double cx, int nthreads);
/// out = (seg(in) + add) * scale over `region`, `in` read as zero outside `valid`, for a
/// segment e = (ex, ey) not along the rows: one of the four passes.
void segment_pass(const Plane& in, const Region& valid, Plane& out, const Region& region,
                  double ex, double ey, const Plane* add, float scale, int nthreads);
/// `r` grown by what a segment pass along e reads around an output, clipped to w x h.
Region grown_by(const Region& r, double ex, double ey, int w, int h);
/// The smallest region holding a and b.
Region hull(const Region& a, const Region& b);

// The three segment directions P0, P2, P4 of the hexagon. Steep segments sweep down the
// rows, the cheapest pass, so the passes run in the frame (as given or transposed) where
// two of them are steep: three directions 60 degrees apart always leave two within 45
// degrees of one axis. For the upright hexagon (rotation 0) that is the transposed frame,
// where the third segment runs along the rows and needs no shear.
struct Dir {
    double x, y;
    bool steep() const { return std::abs(y) >= std::abs(x); }
    double slope() const { return steep() ? std::abs(x / y) : 2.0; }
};

/// Vertex i of the kernel's hexagon in pixel offsets (y down), as kernel.cpp places them.
std::pair<double, double> hexagon_vertex(const Kernel& k, int i);
/// The three segments in the source's frame or, `transposed`, in its transpose's.
std::array<Dir, 3> frame_dirs(const Kernel& k, bool transposed);

// The sweep's cost in spans_cost_ns's units, flat-topped (its lines the source's rows) and
// upright (its lines the source's columns): see parallelograms_cost_ns.
constexpr double kSweepFlatNs = 3.6, kSweepUprightNs = 4.6;
// The sheared frame's lines and outputs read through three taps, over the sweep's cost
// in its frame (cheaper_shear): measured 1.14-1.56 at 63 px (1080p RGBA, two threads,
// against the upright and the flat-topped sweeps in the same runs).
constexpr double kShearTapsCost = 1.4;

// A shear of the frame's columns, (x, y) -> (x, y - m x) (in the transposed frame: of the
// source's rows), that turns segment c along the working rows and leaves a and b steep;
// the segments as they are in the sheared frame (blur_hexagon_sheared.cpp).
struct ColumnShear {
    bool transposed = false;  // the frame is the source's transpose (c near the columns)
    double m        = 0.0;
    Dir a, b, c;
};

/// The shear that turns the segment nearest the rows of the frame (the source's, or its
/// transpose's) along them; none where a stretched hexagon's shear leaves a or b flat.
std::optional<ColumnShear> column_shear(const Kernel& k, bool transposed);
/// The cheaper of the two frames' shears for a w x h output; `cost_ns` its cost in
/// parallelograms_cost_ns's units (left alone when there is none).
std::optional<ColumnShear> cheaper_shear(const Kernel& k, int w, int h, double* cost_ns = nullptr);
/// hexagon_direct at rotations off multiples of 30 degrees, in the frame of shear `s`.
bool hexagon_sheared_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                            const Kernel& k, const ColumnShear& s, int rx, int ry, Border border,
                            int nthreads);
/// The sheared frame's sweep on a padded plane (iris mode), the plane less `margin_x`,
/// `margin_y` on each side computed; none where no shear serves.
std::optional<Plane> sheared_on_plane(const Plane& in, const Kernel& k, int margin_x, int margin_y, int nthreads);

}  // namespace bokeh::detail
