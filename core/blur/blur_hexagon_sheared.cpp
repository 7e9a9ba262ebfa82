// blur_hexagon_sheared.cpp — the hexagon at rotations off multiples of 30 degrees: the
// fused sweep (blur_hexagon_sweep.cpp) run in a sheared frame.
//
// The hexagon's three segments lie 60 degrees apart, so one is within 30 degrees of the
// rows and one within 30 degrees of the columns. Shearing the frame's columns,
// (x, y) -> (x, y - m x) with m = c.y / c.x, turns the first, c, along the rows and leaves
// the other two steep (for the regular hexagon |y'| / |x'| >= sin 60 / (cos 30 cos(angle
// c)) >= 1), so the fused sweep runs in that frame as for the flat-topped hexagon; likewise
// in the transposed frame (the source's rows sheared) with the segment near the columns,
// as for the upright one. A shear of determinant one maps the hexagon's rhombi to the
// sheared hexagon's, weights and all. The lines are gathered through the B-spline's taps
// and the outputs read back through them as the sweep goes (ShearedFrame): no padded
// planes. Of the two frames the cost model takes the cheaper (cheaper_shear: the sweep's
// lines grow by |m| per column of a chunk).
// Measured A/B (15-255 px, 1080p RGBA, two threads): 0.42-0.59x of the four passes' time;
// shearing whole planes before and after the sweep instead measured 0.87-1.15x (the planes'
// memory traffic and page faults).
//
// Limits: the two extra B-spline reads smooth across the lines by 1/2 px^2 more than the
// upright and flat-topped sweeps do, so the sheared sweep keeps the 40 dB budget of
// method=fast only from 27 px (parallelograms_budget_px); ~1.3x the upright sweep's time
// in the transposed frame and 1.5-1.9x the flat-topped's as given.

#include <bokeh/blur.h>
#include <bokeh/parallel.h>

#include "blur/hexagon.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <vector>

namespace bokeh::detail {

// The shear that turns the segment nearest the rows of the frame (the source's, or its
// transpose's) along them, `m` and the segments in the sheared frame; none where a
// stretched hexagon's shear leaves a or b flat.
std::optional<ColumnShear> column_shear(const Kernel& k, bool transposed)
{
    std::array<Dir, 3> d = frame_dirs(k, transposed);
    auto rise = [](Dir v) { return std::abs(v.y) / std::max(std::abs(v.x), 1e-300); };
    std::sort(d.begin(), d.end(), [&](Dir p, Dir q) { return rise(p) < rise(q); });
    if (rise(d[0]) > 1.0)
        return std::nullopt;
    ColumnShear s;
    s.transposed = transposed;
    s.m          = d[0].y / d[0].x;
    s.c          = { d[0].x, 0.0 };
    Dir a = { d[1].x, d[1].y - s.m * d[1].x }, b = { d[2].x, d[2].y - s.m * d[2].x };
    if (!a.steep() || !b.steep())
        return std::nullopt;
    if (b.slope() < a.slope())
        std::swap(a, b);
    s.a = a;
    s.b = b;
    return s;
}

// The cheaper of the two frames' shears for a w x h output, by the sweeps' cost (the
// frames' base costs, parallelograms_cost_ns) times the lines a chunk of columns sweeps:
// its output's plus |m| per column of the chunk (two chunks at 1080p); `cost_ns` its
// cost in those units.
std::optional<ColumnShear> cheaper_shear(const Kernel& k, int w, int h, double* cost_ns)
{
    std::optional<ColumnShear> best;
    double best_cost = 0.0;
    for (bool t : { false, true }) {
        const std::optional<ColumnShear> s = column_shear(k, t);
        if (!s)
            continue;
        const int across = t ? h : w, lines = t ? w : h;
        const int chunk  = (across + column_chunks(across) - 1) / column_chunks(across);
        // As given, the diagonal reads and writes cost ~1.9 |m| more: the frames measured
        // alike at 15-22 degrees (15-255 px; the transposed frame 0.72x the as-given one's
        // time at 7 and 0.78x at 5, 1.1x at 25 and 1.3-1.4x at 28; 1080p RGBA, two threads).
        const double diagonal = t ? 1.0 : 1.0 + 1.9 * std::abs(s->m);
        const double cost     = (t ? kSweepUprightNs : kSweepFlatNs) * diagonal
                            * (1.0 + std::abs(s->m) * chunk / std::max(lines, 1));
        if (!best || cost < best_cost) {
            best      = s;
            best_cost = cost;
        }
    }
    if (cost_ns && best)  // else the caller's cost (the four passes') stands
        *cost_ns = best_cost;
    return best;
}

namespace {

// o[i] = w0[i] p0[i] + w1[i] p1[i] + w2[i] p2[i], i < n: three taps whose weights change
// per pixel (spread over its channels), on a run of pixels that read the same rows.
inline void three_taps(float* __restrict o, const float* p0, const float* p1, const float* p2,
                       const float* w0, const float* w1, const float* w2, size_t n)
{
    for (size_t i = 0; i < n; ++i)
        o[i] = w0[i] * p0[i] + w1[i] * p1[i] + w2[i] * p2[i];
}

// RGBA pixel o = t.w[0] p0 + t.w[1] p1 + t.w[2] p2, one vector.
inline void rgba_taps(float* o, const Taps& t, const float* p0, const float* p1, const float* p2)
{
    *reinterpret_cast<PixelRgba*>(o) = t.w[0] * *reinterpret_cast<const PixelRgba*>(p0)
                                       + t.w[1] * *reinterpret_cast<const PixelRgba*>(p1)
                                       + t.w[2] * *reinterpret_cast<const PixelRgba*>(p2);
}

// hexagon_direct at rotations off multiples of 30 degrees (column_shear). In the working
// frame (the source, or its transpose), working column x is source column (row) org + x;
// line r reads the source at (x, base + r + m x) through the quadratic B-spline's taps
// across the lines (the taps the sweep's windows use along them: energy and centroid
// exact, variance 1/4 px^2 at every phase), and output (x, Y) reads the sweep's result
// back at (x, Y - base - m x) through them. Both taps depend on the column alone (r and Y
// are whole), so each is tabled per column. The lines a chunk of columns needs drift by m
// per column (SweepIO::out_rows): 1080 + 960 |m| as given at 1080p (two chunks of 960),
// 1920 + 540 |m| transposed. The sweep's rows come to the store in batches of
// kColumnBatch with the two rows before them kept (SweepIO::keep), so an output is written
// with the batch holding its last tap.
// As given, a line runs along a diagonal of the source (~1 / m pixels from each row) and
// an output batch along one of `dst`: a batch of lines is gathered a run of columns with
// one first tap at a time (its 18 rows' pieces in L1), the next run's rows prefetched.
// Transposed, a batch of 16 lines at column x reads 18 adjacent pixels of a source row,
// all with x's weights, and writes 16 adjacent pixels of an output row: the upright
// sweep's pattern.
class ShearedFrame {
public:
    // Outputs over roi go to `out` (pixel roi.xbegin, roi.ybegin), rows `pitch` floats apart.
    ShearedFrame(const OIIO::ImageBuf& in, float* out, size_t pitch, const OIIO::ROI& roi, const Kernel& k,
                 const ColumnShear& s, int rx, int ry, Border border)
        : in_(in), s_(s), roi_(roi), data_(in.roi()), border_(border), black_(border == Border::Black),
          t_(s.transposed), m_(s.m), ncs_(size_t(in.nchannels())), pitch_(pitch), d0_(out)
    {
        const bool t = t_;
        // Along the working columns ("across") and the lines ("down"), in source coordinates.
        const int across0 = t ? roi.ybegin : roi.xbegin, across1 = t ? roi.yend : roi.xend;
        down0_   = t ? roi.xbegin : roi.ybegin;
        down1_   = t ? roi.xend : roi.yend;
        data_d0_ = t ? data_.xbegin : data_.ybegin;
        data_d1_ = t ? data_.xend : data_.yend;
        reach_a_ = t ? ry : rx;
        w_       = across1 - across0 + 2 * reach_a_;
        org_     = across0 - reach_a_;
        down_.reserve(size_t(w_));
        up_.reserve(size_t(w_));
        for (int x = 0; x < w_; ++x) {
            down_.emplace_back(m_ * x);
            up_.emplace_back(-m_ * x);
        }
        // The sheared kernel's reach across the lines, and the frame: outputs read lines
        // [ry_w, h - ry_w), the kernel's reach around them.
        double reach = 0.0;
        for (int i = 0; i < 6; ++i) {
            const auto [vx, vy] = hexagon_vertex(k, i);
            reach = std::max(reach, t ? std::abs(vx - m_ * vy) : std::abs(vy - m_ * vx));
        }
        ry_w_                   = int(std::ceil(reach)) + 2;
        const auto [u_lo, u_hi] = first_range(up_, reach_a_, w_ - reach_a_);
        base_                   = down0_ + u_lo - ry_w_;
        h_                      = down1_ - 1 - base_ + u_hi + 3 + ry_w_;
        const int data_a0 = t ? data_.ybegin : data_.xbegin, data_a1 = t ? data_.yend : data_.xend;
        lit_x0_ = black_ ? std::max(0, data_a0 - org_) : 0;
        lit_x1_ = black_ ? std::min(w_, data_a1 - org_) : w_;
        spread(down_, down_w_);
        spread(up_, up_w_);
        zero_.assign(size_t(std::max(data_.width(), data_.height()) + 2 * kColumnBatch) * ncs_, 0.0f);
        if (t)
            transposed_tables();
        else
            as_given_tables();
    }

    // The hexagon, into `out`.
    void sweep(int nthreads) const
    {
        hexagon_sweep(io(), int(ncs_), { reach_a_, ry_w_, w_ - reach_a_, h_ - ry_w_ }, s_.a.x, s_.a.y, s_.b.x, s_.b.y,
                      s_.c.x, nthreads);
    }

private:
    // The sweep's input and output through this frame.
    SweepIO io() const
    {
        SweepIO io;
        io.w        = w_;
        io.h        = h_;
        io.batch    = kColumnBatch;
        io.keep     = 2;
        io.out_rows = [this](int x0, int x1) {
            const auto [lo, hi] = first_range(up_, x0, x1);
            return std::pair{ down0_ - base_ + lo, down1_ - 1 - base_ + hi + 3 };
        };
        if (black_) {
            io.lit       = { lit_x0_, 0, lit_x1_, h_ };
            io.first_lit = [this](int c0, int c1) {
                const int a = std::max(c0, lit_x0_), b = std::min(c1, lit_x1_);
                return b > a ? data_d0_ - base_ - 2 - first_range(down_, a, b).second : h_;
            };
        }
        io.out_row = [](int, int, int) -> float* { return nullptr; };
        if (t_) {
            io.lines = [this](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
                lines_transposed(r, n, c0, c1, bufs, lines);
            };
            io.store = [this](int y, int n, int x0, int x1, const float* rows) { store_transposed(y, n, x0, x1, rows); };
        } else {
            io.lines = [this](int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) {
                lines_as_given(r, n, c0, c1, bufs, lines);
            };
            io.store = [this](int y, int n, int x0, int x1, const float* rows) { store_as_given(y, n, x0, x1, rows); };
        }
        return io;
    }

    // The first taps over columns [x0, x1): monotonic in x (round(m x) - 1), so the ends.
    static std::pair<int, int> first_range(const std::vector<Taps>& tp, int x0, int x1)
    {
        const int p = tp[size_t(x0)].first, q = tp[size_t(x1 - 1)].first;
        return { std::min(p, q), std::max(p, q) };
    }

    // Each tap's weights spread over the channels (a run of pixels with the same taps'
    // rows is then one vector loop).
    void spread(const std::vector<Taps>& tp, std::array<std::vector<float>, 3>& wt) const
    {
        for (int j = 0; j < 3; ++j) {
            wt[size_t(j)].resize(size_t(w_) * ncs_);
            for (int x = 0; x < w_; ++x)
                std::fill_n(wt[size_t(j)].data() + size_t(x) * ncs_, ncs_, tp[size_t(x)].w[j]);
        }
    }

    // Lines r .. r + n - 1 over [c0, c1), lit over [a, b): their spans (none where a line
    // reads only black: all its taps outside the data window); how many have pixels.
    int line_spans(int r, int n, int c0, float* const* bufs, RowSpan* lines, int a, int b) const
    {
        int lit = 0;
        for (int i = 0; i < n; ++i) {
            bool dark = b <= a;
            if (!dark && black_) {
                const int row0 = base_ + r + i, f0 = down_[size_t(a)].first, f1 = down_[size_t(b - 1)].first;
                dark = row0 + std::max(f0, f1) + 2 < data_d0_ || row0 + std::min(f0, f1) >= data_d1_;
            }
            lines[i] = dark ? RowSpan{} : RowSpan{ bufs[i], a - c0, b - c0 };
            lit += !dark;
        }
        return lit;
    }

    // As given: the source rows the lines read (the zero row where black), each working
    // column's source column by the border rule, the runs of columns whose taps start on
    // one row and read adjacent source columns (run_end_[x]: where x's run ends), and the
    // unshear's columns by first tap.
    void as_given_tables()
    {
        const auto [d_lo, d_hi] = first_range(down_, 0, w_);
        s0_                     = base_ + d_lo;
        const int s1            = base_ + h_ + d_hi + 2;
        src_rows_.resize(size_t(s1 - s0_));
        for (int sr = s0_; sr < s1; ++sr) {
            const int sy = border_index(sr, data_.ybegin, data_.yend, border_);
            src_rows_[size_t(sr - s0_)] =
                sy == kOutside ? zero_.data() : static_cast<const float*>(in_.pixeladdr(data_.xbegin, sy, data_.zbegin));
        }
        col_.assign(size_t(w_), 0);
        for (int x = 0; x < w_; ++x) {
            const int sx   = border_index(org_ + x, data_.xbegin, data_.xend, border_);
            col_[size_t(x)] = sx == kOutside ? 0 : size_t(sx - data_.xbegin) * ncs_;
        }
        run_end_.resize(size_t(w_));
        for (int x = w_ - 1; x >= 0; --x) {
            const bool on = x + 1 < w_ && down_[size_t(x + 1)].first == down_[size_t(x)].first
                            && col_[size_t(x + 1)] == col_[size_t(x)] + ncs_;
            run_end_[size_t(x)] = on ? run_end_[size_t(x + 1)] : x + 1;
        }
        const auto [u_lo, u_hi] = first_range(up_, 0, w_);
        up_lo_                  = u_lo;
        up_columns_.assign(size_t(u_hi - u_lo + 1), { 0, 0 });
        for (int x = w_ - 1; x >= 0; --x) {
            auto& c = up_columns_[size_t(up_[size_t(x)].first - up_lo_)];
            c       = c.second > c.first ? std::pair{ x, c.second } : std::pair{ x, x + 1 };
        }
    }

    // Transposed: per working column, source row org + x by the border rule (null: black).
    void transposed_tables()
    {
        row_of_.resize(size_t(w_));
        for (int x = 0; x < w_; ++x) {
            const int sy = border_index(org_ + x, data_.ybegin, data_.yend, border_);
            row_of_[size_t(x)] =
                sy == kOutside ? nullptr : static_cast<const float*>(in_.pixeladdr(data_.xbegin, sy, data_.zbegin));
        }
    }

    void lines_as_given(int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) const
    {
        const int a = std::max(c0, lit_x0_), b = std::min(c1, lit_x1_);
        if (line_spans(r, n, c0, bufs, lines, a, b) == 0)
            return;
        // Line r + i reads rows[i + first + 0..2]; a run of columns with one first tap is
        // done for the batch's lines at once, its n + 2 rows' pieces in L1.
        const float* const* const rows = src_rows_.data() + (base_ + r - s0_);
        for (int x = a; x < b;) {
            const int e = std::min(run_end_[size_t(x)], b), f = down_[size_t(x)].first;
            const size_t j = col_[size_t(x)], kx = size_t(x) * ncs_, ox = size_t(x - a) * ncs_;
            const size_t len = size_t(e - x) * ncs_;
            if (e < b) {  // the next run's rows: a diagonal the hardware's prefetchers miss
                const int fn       = down_[size_t(e)].first;
                const size_t jn    = col_[size_t(e)];
                const size_t bytes = size_t(std::min(run_end_[size_t(e)], b) - e) * ncs_ * sizeof(float);
                for (int t = 0; t < n + 2; ++t)
                    prefetch_lines(rows[fn + t] + jn, bytes);
            }
            for (int i = 0; i < n; ++i)
                if (lines[i].p)
                    three_taps(bufs[i] + ox, rows[i + f] + j, rows[i + f + 1] + j, rows[i + f + 2] + j,
                               down_w_[0].data() + kx, down_w_[1].data() + kx, down_w_[2].data() + kx, len);
            x = e;
        }
    }

    void store_as_given(int y, int n, int x0, int x1, const float* rows) const
    {
        const ptrdiff_t no = ptrdiff_t(x1 - x0) * ptrdiff_t(ncs_);
        // Output row Y takes the columns whose last tap, line Y - base + u + 2, came in
        // this batch: u in [y - Y + base - 2, y + n - Y + base - 2), each u a run.
        const auto [u0, u1] = first_range(up_, x0, x1);
        const int yy0 = std::max(down0_, y + base_ - u1 - 2), yy1 = std::min(down1_, y + n + base_ - u0 - 2);
        for (int yy = yy0; yy < yy1; ++yy) {
            const int lo = y - yy + base_ - 2;
            // Line yy - base + u of the batch is row (yy - base - y) + u of `rows` (>= -2:
            // the kept rows); column x of the frame is pixel org + x - roi.xbegin of the row.
            const ptrdiff_t line0 = ptrdiff_t(yy - base_ - y);
            float* const orow     = d0_ + size_t(yy - roi_.ybegin) * pitch_;
            auto out_px           = [&](int x) { return orow + size_t(org_ + x - roi_.xbegin) * ncs_; };
            // Left to right (u falls with x where m > 0).
            const int ua = std::max(lo, u0), ub = std::min(lo + n, u1 + 1);
            if (ub <= ua)
                continue;
            if (ncs_ == 4) {  // one vector a pixel, each reading its own lines
                const int ul = m_ > 0.0 ? ub - 1 : ua, ur = m_ > 0.0 ? ua : ub - 1;
                const int xa = std::max(x0, up_columns_[size_t(ul - up_lo_)].first);
                const int xb = std::min(x1, up_columns_[size_t(ur - up_lo_)].second);
                for (int x = xa; x < xb; ++x) {
                    const Taps& tp  = up_[size_t(x)];
                    const float* qx = rows + (line0 + tp.first) * no + ptrdiff_t(x - x0) * 4;
                    rgba_taps(out_px(x), tp, qx, qx + no, qx + 2 * no);
                }
                continue;
            }
            for (int i = 0; i < ub - ua; ++i) {
                const int u         = m_ > 0.0 ? ub - 1 - i : ua + i;
                const auto [ca, cb] = up_columns_[size_t(u - up_lo_)];
                const int xa = std::max(ca, x0), xb = std::min(cb, x1);
                if (xb <= xa)
                    continue;
                const float* qx = rows + (line0 + u) * no + ptrdiff_t(xa - x0) * ptrdiff_t(ncs_);
                const size_t kx = size_t(xa) * ncs_;
                three_taps(out_px(xa), qx, qx + no, qx + 2 * no, up_w_[0].data() + kx, up_w_[1].data() + kx,
                           up_w_[2].data() + kx, size_t(xb - xa) * ncs_);
            }
        }
    }

    void lines_transposed(int r, int n, int c0, int c1, float* const* bufs, RowSpan* lines) const
    {
        const int a = std::max(c0, lit_x0_), b = std::min(c1, lit_x1_);
        if (line_spans(r, n, c0, bufs, lines, a, b) == 0)
            return;
        std::vector<float> run;  // a row's pixels by the border rule, near the data window's edges
        for (int x = a; x < b; ++x) {
            // Source row org + x, columns base + r + f + [0, n + 2): in place inside the
            // data window, else by the border rule.
            const float* const row = row_of_[size_t(x)];
            const int sx0          = base_ + r + down_[size_t(x)].first;
            const float* p         = zero_.data();
            if (row) {
                if (sx0 >= data_.xbegin && sx0 + n + 2 <= data_.xend)
                    p = row + size_t(sx0 - data_.xbegin) * ncs_;
                else {
                    run.resize(size_t(n + 2) * ncs_);
                    for (int j = 0; j < n + 2; ++j) {
                        const int sx   = border_index(sx0 + j, data_.xbegin, data_.xend, border_);
                        const float* v = sx == kOutside ? zero_.data() : row + size_t(sx - data_.xbegin) * ncs_;
                        std::copy_n(v, ncs_, run.data() + size_t(j) * ncs_);
                    }
                    p = run.data();
                }
            }
            const size_t kx = size_t(x) * ncs_, ox = size_t(x - a) * ncs_;
            if (ncs_ == 4) {  // one vector a pixel, the weights held
                const Taps& tp = down_[size_t(x)];
                for (int i = 0; i < n; ++i, p += 4)
                    rgba_taps(bufs[i] + ox, tp, p, p + 4, p + 8);
                continue;
            }
            for (int i = 0; i < n; ++i, p += ncs_)
                three_taps(bufs[i] + ox, p, p + ncs_, p + 2 * ncs_, down_w_[0].data() + kx, down_w_[1].data() + kx,
                           down_w_[2].data() + kx, ncs_);
        }
    }

    void store_transposed(int y, int n, int x0, int x1, const float* rows) const
    {
        const ptrdiff_t no = ptrdiff_t(x1 - x0) * ptrdiff_t(ncs_);
        for (int x = x0; x < x1; ++x) {
            // Output row org + x takes the columns X whose last tap, line X - base + u + 2,
            // came in this batch.
            const int u  = up_[size_t(x)].first;
            const int xa = std::max(down0_, y + base_ - u - 2), xb = std::min(down1_, y + n + base_ - u - 2);
            if (xb <= xa)
                continue;
            float* o = d0_ + size_t(org_ + x - roi_.ybegin) * pitch_ + size_t(xa - roi_.xbegin) * ncs_;
            if (x + kPrefetchRows < x1)
                prefetch_lines(o + kPrefetchRows * pitch_, size_t(xb - xa) * ncs_ * sizeof(float), true);
            const float* q  = rows + ptrdiff_t(xa - base_ + u - y) * no + ptrdiff_t(x - x0) * ptrdiff_t(ncs_);
            const size_t kx = size_t(x) * ncs_;
            if (ncs_ == 4) {  // one vector a pixel, the weights held
                const Taps& tp = up_[size_t(x)];
                for (int X = xa; X < xb; ++X, o += ncs_, q += no)
                    rgba_taps(o, tp, q, q + no, q + 2 * no);
                continue;
            }
            for (int X = xa; X < xb; ++X, o += ncs_, q += no)
                three_taps(o, q, q + no, q + 2 * no, up_w_[0].data() + kx, up_w_[1].data() + kx, up_w_[2].data() + kx,
                           ncs_);
        }
    }

    const OIIO::ImageBuf& in_;
    const ColumnShear s_;
    const OIIO::ROI roi_, data_;
    const Border border_;
    const bool black_, t_;
    const double m_;
    const size_t ncs_, pitch_;  // pitch_: floats from one output row to the next
    float* const d0_;
    int down0_ = 0, down1_ = 0, data_d0_ = 0, data_d1_ = 0, reach_a_ = 0;
    int w_ = 0, h_ = 0, org_ = 0, base_ = 0, ry_w_ = 0, lit_x0_ = 0, lit_x1_ = 0;
    std::vector<Taps> down_, up_;  // per working column: the shear's taps, the unshear's
    std::array<std::vector<float>, 3> down_w_, up_w_;
    std::vector<float> zero_;
    // As given (as_given_tables).
    int s0_ = 0, up_lo_ = 0;
    std::vector<const float*> src_rows_;
    std::vector<size_t> col_;
    std::vector<int> run_end_;
    std::vector<std::pair<int, int>> up_columns_;
    // Transposed (transposed_tables).
    std::vector<const float*> row_of_;
};

}  // namespace

bool hexagon_sheared_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                            const Kernel& k, const ColumnShear& s, int rx, int ry, Border border,
                            int nthreads)
{
    prepare_destination(dst, in, roi);
    ShearedFrame(in, static_cast<float*>(dst.localpixels()), size_t(dst.spec().width) * size_t(in.nchannels()), roi,
                 k, s, rx, ry, border)
        .sweep(nthreads);
    return true;
}

std::optional<Plane> sheared_on_plane(const Plane& in, const Kernel& k, int margin_x, int margin_y, int nthreads)
{
    const int w = in.w - 2 * margin_x, h = in.h - 2 * margin_y;
    const std::optional<ColumnShear> s = cheaper_shear(k, w, h);
    if (!s)
        return std::nullopt;
    // The plane as a source (no copy; only read), its outputs past the margins; the taps'
    // phases count from the reach before the output, as hexagon_direct's do.
    const OIIO::ImageSpec spec(in.w, in.h, in.nc, OIIO::TypeFloat);
    const OIIO::ImageBuf view(spec, const_cast<float*>(in.row(0)));
    const OIIO::ROI roi(margin_x, margin_x + w, margin_y, margin_y + h);
    Plane out(in.w, in.h, in.nc);
    ShearedFrame(view, out.row(margin_y) + size_t(margin_x) * size_t(in.nc), out.stride(), roi, k, *s,
                 hexagon_reach(k, true), hexagon_reach(k, false), Border::Black)
        .sweep(nthreads);
    return out;
}

}  // namespace bokeh::detail
