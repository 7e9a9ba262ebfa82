// psf_runs.cpp — a lens PSF as ramps and literal runs along its rows, and the band of
// running sums sprites are drawn into (psf_runs.h says why).
//
// Source: scatter by rows, as Kawase's "Bokeh Deep Dive" does it ("most of the disk needs no
// lookup"). Ours replaces the talk's flat span by a ramp found greedily: from a run's first pixel, the
// longest ramp is the farthest pixel whose chord stays within each channel's allowance of
// every pixel between, kept as the cone of slopes those pixels allow (one pass, O(length)).
// Ramps shorter than kMinRamp are drawn as literal pixels. Limit: a ramp's end points are
// the PSF's own values, so ramp pixels err by at most the allowance before the final
// rescale (which keeps each channel's sum).

#include "optics/psf_runs.h"

#include <algorithm>
#include <cmath>

namespace bokeh::detail {

namespace {

// A ramp costs 4 writes a channel plus its share of the row's two running sums; a literal
// pixel costs one. Below 6 pixels a ramp is not worth it.
constexpr int kMinRamp = 6;
// A ramp's allowance is relative to each pixel's value, so a faint halo keeps its shape as
// well as the peak; below this fraction of the channel's peak it is this level's.
constexpr double kRampFloor = 1e-6;

// The farthest x1 in [x0, end) such that, for every channel, the chord from x0 to x1 is
// within `tolerance` of each pixel between them, relative to the pixel's own value (at
// least floor[c]).
int ramp_end(const float* row, int x0, int end, double tolerance, const double floor[3])
{
    double lo[3] = { -HUGE_VAL, -HUGE_VAL, -HUGE_VAL }, hi[3] = { HUGE_VAL, HUGE_VAL, HUGE_VAL };
    int best = x0;
    for (int x1 = x0 + 1; x1 < end; ++x1) {
        const double d = double(x1 - x0);
        bool fits = true, open = true;
        for (int c = 0; c < 3; ++c) {
            const double v0 = row[size_t(x0) * 3 + size_t(c)], v = row[size_t(x1) * 3 + size_t(c)];
            const double slope = (v - v0) / d;
            fits = fits && slope >= lo[c] && slope <= hi[c];
            // x1 as a pixel between x0 and a farther end: the slopes it allows.
            const double allow = tolerance * std::max(std::abs(v), floor[c]);
            lo[c] = std::max(lo[c], (v - allow - v0) / d);
            hi[c] = std::min(hi[c], (v + allow - v0) / d);
            open  = open && lo[c] <= hi[c];
        }
        if (fits)
            best = x1;
        if (!open)
            break;
    }
    return best;
}

bool nonzero(const float* p) { return p[0] != 0.0f || p[1] != 0.0f || p[2] != 0.0f; }

}  // namespace

PsfRuns psf_runs(const Psf& psf, double tolerance)
{
    PsfRuns out;
    out.width  = psf.width;
    out.height = psf.height;
    double peak[3] = { 0, 0, 0 }, sum[3] = { 0, 0, 0 };
    for (size_t i = 0; i < psf.rgb.size(); ++i) {
        peak[i % 3] = std::max(peak[i % 3], std::abs(double(psf.rgb[i])));
        sum[i % 3] += double(psf.rgb[i]);
    }
    // Values below kRampFloor of their channel's peak are allowed the error of that level.
    const double floor[3] = { kRampFloor * peak[0], kRampFloor * peak[1], kRampFloor * peak[2] };
    for (int y = 0; y < psf.height; ++y) {
        out.ramp_begin.push_back(uint32_t(out.ramps.size()));
        out.literal_begin.push_back(uint32_t(out.literals.size()));
        const float* row = psf.rgb.data() + size_t(y) * size_t(psf.width) * 3;
        for (int x = 0; x < psf.width;) {
            if (!nonzero(row + size_t(x) * 3)) {
                ++x;
                continue;
            }
            int end = x;  // the run of nonzero pixels [x, end)
            while (end < psf.width && nonzero(row + size_t(end) * 3))
                ++end;
            while (x < end) {
                const int x1 = ramp_end(row, x, end, tolerance, floor);
                if (x1 - x + 1 >= kMinRamp) {
                    PsfRuns::Ramp r;
                    r.x0 = x, r.x1 = x1;
                    for (int c = 0; c < 3; ++c) {
                        r.a[c] = row[size_t(x) * 3 + size_t(c)];
                        r.b[c] = float((double(row[size_t(x1) * 3 + size_t(c)]) - r.a[c]) / double(x1 - x));
                    }
                    out.ramps.push_back(r);
                    x = x1 + 1;
                    continue;
                }
                PsfRuns::Literal* last = out.literals.size() > out.literal_begin.back() ? &out.literals.back() : nullptr;
                if (!last || last->x0 + last->n != x) {
                    out.literals.push_back({ x, 0, uint32_t(out.values.size()) });
                    last = &out.literals.back();
                }
                ++last->n;
                out.values.insert(out.values.end(), row + size_t(x) * 3, row + size_t(x) * 3 + 3);
                ++x;
            }
        }
    }
    out.ramp_begin.push_back(uint32_t(out.ramps.size()));
    out.literal_begin.push_back(uint32_t(out.literals.size()));
    // Each channel's sum as drawn, then everything scaled to the PSF's own.
    double drawn[3] = { 0, 0, 0 };
    for (size_t i = 0; i < out.values.size(); ++i)
        drawn[i % 3] += double(out.values[i]);
    for (const PsfRuns::Ramp& r : out.ramps) {
        const double n = double(r.x1 - r.x0 + 1);
        for (int c = 0; c < 3; ++c)
            drawn[c] += n * double(r.a[c]) + double(r.b[c]) * n * (n - 1.0) / 2.0;
    }
    float scale[3];
    for (int c = 0; c < 3; ++c)
        scale[c] = drawn[c] != 0.0 ? float(sum[c] / drawn[c]) : 1.0f;
    for (size_t i = 0; i < out.values.size(); ++i)
        out.values[i] *= scale[i % 3];
    for (PsfRuns::Ramp& r : out.ramps)
        for (int c = 0; c < 3; ++c) {
            r.a[c] *= scale[c];
            r.b[c] *= scale[c];
        }
    return out;
}

namespace {

// The calling thread's zeroed buffer, kept between bands (zeroing a whole band per layer
// would cost more than its sprites). A band inside a band on the same thread gets its own.
struct BandBuffer {
    std::vector<double> px;
    bool in_use = false;
};
thread_local BandBuffer t_band;

}  // namespace

RunBand::RunBand(int x0, int x1, int y0, int y1)
    : x0_(x0), x1_(std::max(x0, x1)), y0_(y0), y1_(std::max(y0, y1)), stride_(size_t(x1_ - x0_ + 2) * 3),
      lo_(size_t(y1_ - y0_), 0), hi_(size_t(y1_ - y0_), 0)
{
    const size_t need = 2 * stride_ * size_t(y1_ - y0_);
    if (t_band.in_use) {
        own_.assign(need, 0.0);
        lit_ = own_.data();
    } else {
        t_band.in_use = thread_buffer_ = true;
        if (t_band.px.size() < need)
            t_band.px.assign(need, 0.0);
        lit_ = t_band.px.data();
    }
    d2_ = lit_ + stride_ * size_t(y1_ - y0_);
}

RunBand::~RunBand()
{
    for (size_t r = 0; r < lo_.size(); ++r)
        if (lo_[r] < hi_[r])
            for (size_t i = size_t(lo_[r]) * 3; i < size_t(hi_[r]) * 3; ++i)
                lit_[r * stride_ + i] = d2_[r * stride_ + i] = 0.0;
    if (thread_buffer_)
        t_band.in_use = false;
}

void RunBand::touch(int r, int lo, int hi)
{
    if (lo_[size_t(r)] >= hi_[size_t(r)]) {
        lo_[size_t(r)] = lo;
        hi_[size_t(r)] = hi;
        return;
    }
    lo_[size_t(r)] = std::min(lo_[size_t(r)], lo);
    hi_[size_t(r)] = std::max(hi_[size_t(r)], hi);
}

void RunBand::add(const PsfRuns& runs, int left, int top, const float k[3])
{
    for (int y = std::max(top, y0_); y < std::min(top + runs.height, y1_); ++y) {
        const int py = y - top, r = y - y0_;
        double* lit = lit_ + size_t(r) * stride_;
        double* d2  = d2_ + size_t(r) * stride_;
        for (uint32_t q = runs.ramp_begin[size_t(py)]; q < runs.ramp_begin[size_t(py) + 1]; ++q) {
            const PsfRuns::Ramp& ramp = runs.ramps[q];
            const int i = std::max(left + ramp.x0, x0_) - x0_, j = std::min(left + ramp.x1, x1_ - 1) - x0_;
            if (i > j)
                continue;
            const double skip = double(x0_ + i - (left + ramp.x0)), n = double(j - i);
            for (int c = 0; c < 3; ++c) {
                // a + b (x - i) on [i, j]: its second difference is a at i, b - a at i + 1,
                // -(last + b) at j + 1 and last at j + 2 (last = a + b (j - i)).
                const double b = double(k[c]) * ramp.b[c], a = double(k[c]) * ramp.a[c] + b * skip, last = a + b * n;
                d2[size_t(i) * 3 + size_t(c)] += a;
                d2[size_t(i + 1) * 3 + size_t(c)] += b - a;
                d2[size_t(j + 1) * 3 + size_t(c)] -= last + b;
                d2[size_t(j + 2) * 3 + size_t(c)] += last;
            }
            touch(r, i, j + 3);
        }
        for (uint32_t q = runs.literal_begin[size_t(py)]; q < runs.literal_begin[size_t(py) + 1]; ++q) {
            const PsfRuns::Literal& run = runs.literals[q];
            const int i = std::max(left + run.x0, x0_) - x0_, j = std::min(left + run.x0 + run.n, x1_) - x0_;
            if (i >= j)
                continue;
            const float* v = runs.values.data() + run.at + size_t(x0_ + i - (left + run.x0)) * 3;
            for (int x = i; x < j; ++x, v += 3)
                for (int c = 0; c < 3; ++c)
                    lit[size_t(x) * 3 + size_t(c)] += double(k[c]) * v[c];
            touch(r, i, j);
        }
    }
}

}  // namespace bokeh::detail
