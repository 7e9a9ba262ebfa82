// psf_runs.h — internal to the library: a lens PSF written as runs along its rows, and the
// band of running sums sprites are drawn into (core/optics/psf_runs.cpp; used by
// core/defocus/defocus_sprites.cpp).
//
// Kawase's "Bokeh Deep Dive" scatters a sprite by rows: "most of the disk needs no
// lookup". A lens PSF's disk is not flat (an achromat's secondary spectrum, the rim's diffraction
// ripples reaching inwards), so ours generalises the flat span to a ramp: each row is cut
// into ramps, where every channel is a straight line within a tolerance of each pixel's value,
// and literal runs, drawn pixel by pixel where the PSF is too bumpy for ramps (the rim's
// fringes). A ramp costs four writes a channel into a second-difference buffer, whatever
// its length; the band is summed twice along each row once all its sprites are in.
#pragma once

#include <bokeh/optics.h>

#include "base/plane.h"

#include <cstdint>
#include <vector>

namespace bokeh::detail {

/// `psf` as ramps and literal runs along its rows. Pixels outside every run are exactly 0
/// in the PSF; a ramp's pixels are within `tolerance` of the PSF's, relative to each
/// pixel's value (below 1e-6 of the channel's peak, to that level); literal runs are exact;
/// then every value is scaled so each channel sums to the PSF's own sum.
struct PsfRuns {
    int width = 0, height = 0;
    /// Channel c is a[c] + b[c] (x - x0) for x0 <= x <= x1.
    struct Ramp {
        int x0 = 0, x1 = 0;
        float a[3] = { 0, 0, 0 }, b[3] = { 0, 0, 0 };
    };
    /// n pixels from x0, their RGB at values[at ..].
    struct Literal {
        int x0 = 0, n = 0;
        uint32_t at = 0;
    };
    std::vector<uint32_t> ramp_begin, literal_begin;  // per row, and one past the last row
    std::vector<Ramp> ramps;
    std::vector<Literal> literals;
    std::vector<float> values;
};

/// Encode `psf`, ramps within `tolerance` (relative) of it.
PsfRuns psf_runs(const Psf& psf, double tolerance);

/// Rows [y0, y1) of an RGB image over columns [x0, x1), where sprites are added as PSF runs
/// and then flushed (added into a target). Its buffers are the calling thread's and are
/// kept zero past each flush, so a band costs only the columns its sprites touch.
class RunBand {
public:
    RunBand(int x0, int x1, int y0, int y1);
    RunBand(const RunBand&) = delete;
    RunBand& operator=(const RunBand&) = delete;
    ~RunBand();

    /// Add `k` (per channel) times `runs`, its pixel (0, 0) at (left, top), clipped to the band.
    void add(const PsfRuns& runs, int left, int top, const float k[3]);

    /// Row y's sums (x from xbegin(y) to xend(y)), zeroing the row. `put(x, rgb)` gets
    /// every touched pixel once, in order of x.
    template<class Put>
    void flush_row(int y, Put&& put)
    {
        const int r = y - y0_;
        if (lo_[size_t(r)] >= hi_[size_t(r)])
            return;
        double* lit = lit_ + size_t(r) * stride_;
        double* d2  = d2_ + size_t(r) * stride_;
        double s1[3] = { 0, 0, 0 }, s0[3] = { 0, 0, 0 };
        for (int i = lo_[size_t(r)]; i < hi_[size_t(r)]; ++i) {
            float rgb[3];
            for (int c = 0; c < 3; ++c) {
                s1[c] += d2[size_t(i) * 3 + size_t(c)];
                s0[c] += s1[c];
                rgb[c] = float(lit[size_t(i) * 3 + size_t(c)] + s0[c]);
                d2[size_t(i) * 3 + size_t(c)] = lit[size_t(i) * 3 + size_t(c)] = 0.0;
            }
            if (i < x1_ - x0_)
                put(x0_ + i, rgb);
        }
        lo_[size_t(r)] = hi_[size_t(r)] = 0;
    }

private:
    void touch(int r, int lo, int hi);
    int x0_, x1_, y0_, y1_;
    size_t stride_;  // doubles a row: (columns + 2) * 3
    bool thread_buffer_ = false;  // lit_ and d2_ are the thread's buffer (else own_)
    std::vector<double> own_;     // the buffer when the thread's is in use
    double* lit_;    // literal pixels
    double* d2_;     // ramps' second differences
    std::vector<int> lo_, hi_;  // per row, the touched columns (relative to x0)
};

}  // namespace bokeh::detail
