// deep_pixels.h — internal to the library: the deep family's pixel machinery, which every
// deep operation (core/deep/deep.cpp) and its tests share. A pixel is read once into
// doubles (a sample: nch values in the layout's channel order), worked on, and written
// back in the input's types (core/deep/deep_pixels.cpp); chunks of rows run in parallel
// and results do not depend on the thread count.
#pragma once

#include <bokeh/deep.h>
#include <bokeh/parallel.h>

#include "base/numbers.h"

#include <algorithm>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebuf.h>

namespace bokeh::detail {

// The depth OIIO gives a flat pixel without samples (IBA::flatten), kept for files that
// go back and forth between the two tools.
inline constexpr double kEmptyDepth = 1.0e30;

// Accumulated transmittance at or below which float stores the accumulated alpha as 1:
// 1 - 2^-25 rounds to 1.0f.
inline constexpr double kOpaqueTransmittance = 1.0 / 33554432.0;

enum class Role { Depth, DepthBack, Alpha, Colour, Carried };

// What each channel of a deep image is, and where its values sit in a sample.
struct DeepLayout {
    int nch = 0;
    int z = -1, zback = -1;
    std::vector<Role> role;
    std::vector<int> alpha_of;            // Colour: the channel index of its alpha; else -1
    std::vector<int> alphas;              // the alpha channels
    std::vector<OIIO::TypeDesc> types;
    std::vector<std::string> names;

    bool has_alpha() const { return !alphas.empty(); }
};

DeepLayout layout_of(const OIIO::ImageBuf& img);

// One pixel's samples: nch doubles each, in the layout's channel order.
struct Samples {
    int nch = 0;
    int n   = 0;
    std::vector<double> v;

    void reset(int channels)
    {
        nch = channels;
        n   = 0;
        v.clear();
    }
    double* at(int s) { return v.data() + size_t(s) * size_t(nch); }
    const double* at(int s) const { return v.data() + size_t(s) * size_t(nch); }
    double* push()
    {
        v.resize(size_t(n + 1) * size_t(nch));
        return at(n++);
    }
    void push(const double* s) { std::copy(s, s + nch, push()); }
};

inline double front_of(const DeepLayout& L, const double* s) { return s[L.z]; }
inline double back_of(const DeepLayout& L, const double* s)
{
    return L.zback >= 0 ? s[L.zback] : s[L.z];
}

// Raw access to a DeepData's samples: channel offsets inside a sample, found once.
struct RawDeep {
    const OIIO::DeepData* dd = nullptr;
    OIIO::cspan<unsigned int> counts;  // samples per pixel, read without a call per pixel
    std::vector<size_t> offset;
    std::vector<OIIO::TypeDesc::BASETYPE> base;

    explicit RawDeep(const OIIO::DeepData& d) : dd(&d), counts(d.all_samples())
    {
        const int nch = d.channels();
        // Where each channel sits in a sample: read off a pixel that has samples; OIIO
        // packs them in channel order, which is the answer when no pixel has any.
        int64_t with = -1;
        for (int64_t p = 0; p < d.pixels() && with < 0; ++p)
            if (d.samples(p) > 0)
                with = p;
        size_t off = 0;
        for (int c = 0; c < nch; ++c) {
            if (with >= 0)
                off = size_t(static_cast<const char*>(d.data_ptr(with, c, 0))
                             - static_cast<const char*>(d.data_ptr(with, 0, 0)));
            offset.push_back(off);
            off += d.channelsize(c);
            base.push_back(OIIO::TypeDesc::BASETYPE(d.channeltype(c).basetype));
        }
    }
};

double load_value(const char* p, OIIO::TypeDesc::BASETYPE t);

void store_value(char* p, OIIO::TypeDesc::BASETYPE t, double v);

// Per-chunk repairs and the first fault found (for the Error policy's message).
struct Faults {
    DeepRepairs counts;
    std::string first;
};

// Read pixel `p` of `raw` into `out` (appending), channels mapped by `to_out` (source
// channel -> output channel, -1 = dropped), applying the non-finite policy; p < 0 (outside
// the image) appends nothing.
void load_pixel(const RawDeep& raw, int64_t p, const std::vector<int>& to_out, const DeepLayout& L,
                Samples& out, Faults& f, int px, int py);

// The piece of sample `s` (a volume [Z, ZBack)) over [a, b): alphas -expm1(x log1p(-a)),
// colours scaled with their alpha (by x where the alpha is 0).
void volume_piece(const DeepLayout& L, const double* s, double a, double b, double* out);

// The depths where the samples of `px` start or end, sorted, each once.
void sample_bounds(const DeepLayout& L, const Samples& px, std::vector<double>& bounds);

// Append `smp` to `out`; a volume is cut at every depth of `bounds` (sorted, each once)
// strictly inside it.
void push_cut(const DeepLayout& L, const double* smp, const std::vector<double>& bounds, Samples& out);

// Merge `k` coincident samples (rows of `g`, same Z and ZBack) into `out`.
void merge_coincident(const DeepLayout& L, const double* const* g, int k, double* out);

// Whether light still passes the samples composited so far, whose transmittance per alpha
// channel is T: false once every alpha channel's accumulated opacity is 1 in float.
bool shows_through(const DeepLayout& L, const std::vector<double>& T);

// Scratch space reused across the pixels of one chunk.
struct TidyScratch {
    std::vector<double> bounds;
    Samples pieces;
    std::vector<int> order;
    std::vector<const double*> group;
};

// Everything a pixel's work needs besides its result, made once per chunk of rows.
struct PixelScratch {
    Samples in, tidy, hin, h, cut;
    TidyScratch t;
    std::vector<double> weights;
};

bool already_tidy(const DeepLayout& L, const Samples& in);

// Tidy `in` into `out` (cleared first).
void tidy_pixel(const DeepLayout& L, const Samples& in, Samples& out, TidyScratch& t);

// A deep result built chunk by chunk of rows: the samples of each pixel in doubles.
struct DeepResult {
    OIIO::ROI roi;
    int nch = 0;
    std::vector<uint32_t> counts;            // per pixel of roi
    std::vector<std::vector<double>> rows;   // per chunk: the values of its pixels' samples
    static constexpr int kRowsPerChunk = 8;
};

// Make `dst` a deep image over `res.roi` with `spec`'s channels and `types`, holding the
// samples of `res`.
bool assemble(OIIO::ImageBuf& dst, const OIIO::ImageSpec& like, const std::vector<OIIO::TypeDesc>& types,
              DeepResult& res, int nthreads);

// The chunks' repairs summed into `*report` (when given); under the Error policy, false +
// `err` naming the count and the first bad sample.
bool apply_policy(const std::vector<Faults>& faults, const DeepOptions& opt, DeepRepairs* report, std::string& err);

// Run `per_pixel(x, y, Samples& out, Faults&, PixelScratch&)` over `roi`, collecting the samples each
// pixel gives into `res`; then apply the policy.
template<class PerPixel>
bool run_pixels(const OIIO::ROI& roi, int nch, const DeepOptions& opt, DeepRepairs* report, int nthreads,
                DeepResult& res, std::string& err, PerPixel&& per_pixel)
{
    res.roi = roi;
    res.nch = nch;
    res.counts.assign(size_t(roi.npixels()), 0u);
    const int64_t nchunks = (roi.height() + DeepResult::kRowsPerChunk - 1) / DeepResult::kRowsPerChunk;
    res.rows.assign(size_t(nchunks), {});
    std::vector<Faults> faults(static_cast<size_t>(nchunks));
    parallel_for_chunks(0, nchunks, 1, nthreads, [&](int64_t chunk, int64_t) {
        Samples out;
        PixelScratch scratch;
        std::vector<double>& vals = res.rows[size_t(chunk)];
        const int y0 = roi.ybegin + int(chunk) * DeepResult::kRowsPerChunk;
        const int y1 = std::min(roi.yend, y0 + DeepResult::kRowsPerChunk);
        for (int y = y0; y < y1; ++y)
            for (int x = roi.xbegin; x < roi.xend; ++x) {
                out.reset(nch);
                per_pixel(x, y, out, faults[size_t(chunk)], scratch);
                res.counts[size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)] = uint32_t(out.n);
                vals.insert(vals.end(), out.v.begin(), out.v.begin() + size_t(out.n) * size_t(nch));
            }
    });
    return apply_policy(faults, opt, report, err);
}

// The checks every deep operation makes on an input.
bool check_deep(const OIIO::ImageBuf& img, const char* what, bool need_alpha, std::string& err);

std::vector<int> identity_map(int n);

int64_t pixel_of(const OIIO::ImageBuf& img, int x, int y);

// A one-input deep operation: read each pixel (policy applied), `op(in, out, scratch)`.
template<class Op>
bool unary_deep(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const char* what, bool need_alpha,
                const DeepOptions& opt, DeepRepairs* report, int nthreads, Op&& op)
{
    std::string err;
    if (!check_deep(src, what, need_alpha, err)) {
        dst.errorfmt("{}", err);
        return false;
    }
    const DeepLayout L = layout_of(src);
    const RawDeep raw(*src.deepdata());
    const std::vector<int> map = identity_map(L.nch);
    DeepResult res;
    const bool ok = run_pixels(src.roi(), L.nch, opt, report, nthreads, res, err,
                               [&](int x, int y, Samples& out, Faults& f, PixelScratch& sc) {
                                   sc.in.reset(L.nch);
                                   load_pixel(raw, pixel_of(src, x, y), map, L, sc.in, f, x, y);
                                   op(L, sc.in, out, sc.t);
                               });
    if (!ok) {
        dst.errorfmt("{}: {}", what, err);
        return false;
    }
    OIIO::ImageBuf result;
    assemble(result, src.spec(), L.types, res, nthreads);
    dst = std::move(result);
    return true;
}

}  // namespace bokeh::detail
