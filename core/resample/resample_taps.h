// resample_taps.h — internal to the library: the weights of one axis of a resampling as
// sparse rows (TapMatrix: each output's first source index and its weights), built in
// core/resample/resample_taps.cpp, and the separable pass that runs them over a plane
// (core/resample/resample_pass.cpp). resample.cpp's planes and images are built on them.
#pragma once

#include <bokeh/base.h>
#include <bokeh/resample.h>

#include <cstddef>
#include <string>
#include <vector>

namespace bokeh::detail {

// Output i = sum_k w[k] * in[first + k], k < n (in double while being built and composed).
struct TapRow {
    int first       = 0;
    const double* w = nullptr;
    size_t n        = 0;
    bool empty() const { return n == 0; }
};

// The rows of one axis, their weights end to end in one array: an axis has thousands of
// rows, and one allocation each was most of the cost of building them.
struct TapMatrix {
    std::vector<int> first;
    std::vector<size_t> offset{ 0 };  // row i's weights are w[offset[i], offset[i + 1])
    std::vector<double> w;

    size_t size() const { return first.size(); }
    bool empty() const { return first.empty(); }
    TapRow operator[](size_t i) const
    {
        return { first[i], w.data() + offset[i], offset[i + 1] - offset[i] };
    }
    void reserve(size_t rows, size_t taps)
    {
        first.reserve(rows);
        offset.reserve(rows + 1);
        w.reserve(taps);
    }
    void clear()
    {
        first.clear();
        offset.resize(1);
        w.clear();
    }
    // Ends the row whose weights are w[offset.back(), w.size()), its first at `lo`, without
    // its zero ends (an empty row starts at 0).
    void close_row(int lo)
    {
        const size_t begin = offset.back();
        size_t b = begin, e = w.size();
        while (b < e && w[b] == 0.0)
            ++b;
        while (e > b && w[e - 1] == 0.0)
            --e;
        w.resize(e);
        w.erase(w.begin() + std::ptrdiff_t(begin), w.begin() + std::ptrdiff_t(b));
        first.push_back(e > b ? lo + int(b - begin) : 0);
        offset.push_back(w.size());
    }
};

// The weights of one axis. A compound method keeps its stages apart: `pre` takes the
// source to its last finer grid (n_mid pixels), `post` is the bilinear step from there to
// the output; every other method has only `post`, straight from the source.
struct AxisTaps {
    TapMatrix pre, post;
    int n_mid = 0;
    bool staged() const { return !pre.empty(); }
};

// The weights packed as float for the passes, each output's after the one before's.
// `runs` cuts the outputs into stretches of one tap count (bilinear: one run of 2 between a
// few border columns of 1), so that the horizontal pass picks its unrolled loop per run
// rather than per pixel.
struct Taps {
    struct Run {
        int begin, end, count;
    };
    std::vector<int> first, count, offset;
    std::vector<float> w;
    std::vector<Run> runs;
    explicit Taps(const TapMatrix& m)
    {
        first = m.first;
        count.reserve(m.size());
        offset.reserve(m.size());
        for (size_t i = 0; i < m.size(); ++i) {
            const int n = int(m.offset[i + 1] - m.offset[i]);
            count.push_back(n);
            offset.push_back(int(m.offset[i]));
            if (runs.empty() || runs.back().count != n)
                runs.push_back({ int(i), int(i), n });
            ++runs.back().end;
        }
        w.assign(m.w.begin(), m.w.end());
    }
};

/// The weights of one axis: n_dst outputs from n_src source pixels along map `m`, by the
/// options' filter (a compound method's stages kept apart in `taps.pre`). False + `err`.
bool axis_taps(AxisTaps& taps, int n_src, int n_dst, const AxisMap& m, const ResampleOptions& o,
               bool prefilter, std::string& err);

/// The area-exact box footprints of an axis (only the taps that hold a part of the
/// footprint); outside the source black, or renormalised over the inside.
TapMatrix box_taps(int n_src, int n_dst, const AxisMap& m, bool outside_is_black);

/// C = B * A: B maps the mid grid to the output, A the source to the mid grid.
TapMatrix compose(const TapMatrix& b, const TapMatrix& a);

/// `dst` = the source filtered by `tx` along x and `ty` along y, in strips of rows;
/// `pre_x`, when given, filters each source row along x before `tx` does (the first stages
/// of a compound method, run_axes). Values below 0 clamped when asked.
void separable_pass(const ConstPlaneView& src, const PlaneView& dst, const Taps& tx,
                    const Taps& ty, bool clamp_negative, int nthreads, const Taps* pre_x = nullptr);

/// Both axes of an enlargement: a compound method's x stages in turn where its last grid is
/// narrower than the output, its y stages multiplied into one list (resample_pass.cpp says
/// why).
void run_axes(const ConstPlaneView& src, const PlaneView& dst, const AxisTaps& ax,
              const AxisTaps& ay, bool clamp_negative, int nthreads);

}  // namespace bokeh::detail
