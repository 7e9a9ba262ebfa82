// deep.cpp — the deep compositing operations of deep.h, by the OpenEXR rules.
//
// Source: "Interpreting OpenEXR Deep Pixels" (OpenEXR documentation) and P. Hillman, "The
// Theory of OpenEXR Deep Samples" (the rules are written out in docs/methods/deep.md):
// * a volume [Z, ZBack) of alpha a cut to the fraction x of its depth keeps
//   a' = 1 - (1 - a)^x, computed as -expm1(x log1p(-a)) so a thin slice of a faint medium
//   keeps its digits; its colour scales by a'/a (by x when a = 0: additive light);
// * coincident samples (same Z and ZBack) merge into a = 1 - prod(1 - a_k), colour
//   w sum(c_k v_k) with u_k = -log1p(-a_k), v_k = u_k / a_k (1 when a_k = 0) and
//   w = a / sum(u_k) (1 when every a_k = 0); when some a_k = 1, the colours of those
//   samples are averaged. A point never merges with a volume;
// * tidy = split every volume where another sample starts or ends, merge coincident
//   pieces, sort by (Z, ZBack): the pieces of a pixel are then disjoint and ordered, and
//   "over" front to back is its flat value.
//
// Every pixel is read once into doubles (half, float and uint32 values are exact there),
// worked on, and written back in the input's types: an untouched sample keeps its bits.
// Work is split in fixed chunks of rows, so results do not depend on the thread count.
//
// Choices where the rules are silent, kept simple and stated: a flat pixel's Z and ZBack
// are where its visible samples begin and end: non-zero alpha, not behind an accumulated
// opacity float stores as 1 (OIIO blends Z through alpha, a value no surface has; both ends
// are unchanged by tidying and by culling); in a holdout, a holdout point at a sample's depth counts as in front of it (so an
// opaque element held out by itself vanishes, as in Nuke and OIIO), while a holdout volume
// sharing a volume's depth range is mixed with it exactly (holdout_gains); merge culling
// drops what lies behind an accumulated opacity that float stores as 1.
//
// Limits: per-pixel cost grows as n log n in the samples of a pixel, plus the pieces that
// overlapping volumes split into (n^2 in the worst case of n nested volumes).

#include <bokeh/deep.h>
#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/half.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

namespace {

using OIIO::Strutil::fmt::format;

constexpr double kInf = std::numeric_limits<double>::infinity();
// The depth OIIO gives a flat pixel without samples (IBA::flatten), kept for files that
// go back and forth between the two tools.
constexpr double kEmptyDepth = 1.0e30;
// Accumulated transmittance at or below which float stores the accumulated alpha as 1:
// 1 - 2^-25 rounds to 1.0f.
constexpr double kOpaqueTransmittance = 1.0 / 33554432.0;

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

bool is_name(const std::string& n, std::initializer_list<const char*> any)
{
    for (const char* a : any)
        if (n == a)
            return true;
    return false;
}

DeepLayout layout_of(const OIIO::ImageBuf& img)
{
    const OIIO::ImageSpec& spec = img.spec();
    const OIIO::DeepData& dd    = *img.deepdata();
    DeepLayout L;
    L.nch = spec.nchannels;
    L.role.assign(size_t(L.nch), Role::Colour);
    L.alpha_of.assign(size_t(L.nch), -1);
    int a = -1, ar = -1, ag = -1, ab = -1;
    for (int c = 0; c < L.nch; ++c) {
        const std::string n = spec.channel_name(c);
        L.names.push_back(n);
        L.types.push_back(dd.channeltype(c));
        if (is_name(n, { "Z" })) {
            L.role[size_t(c)] = Role::Depth;
            L.z               = c;
        } else if (is_name(n, { "ZBack", "Zback" })) {
            L.role[size_t(c)] = Role::DepthBack;
            L.zback           = c;
        } else if (is_name(n, { "A", "AR", "AG", "AB" })) {
            L.role[size_t(c)] = Role::Alpha;
            L.alphas.push_back(c);
            (n == "A" ? a : n == "AR" ? ar : n == "AG" ? ag : ab) = c;
        } else if (dd.channeltype(c).basetype == OIIO::TypeDesc::UINT32) {
            L.role[size_t(c)] = Role::Carried;
        }
    }
    for (int c = 0; c < L.nch; ++c) {
        if (L.role[size_t(c)] != Role::Colour)
            continue;
        const std::string& n = L.names[size_t(c)];
        int own              = n == "R" ? ar : n == "G" ? ag : n == "B" ? ab : -1;
        L.alpha_of[size_t(c)] = own >= 0 ? own : a >= 0 ? a : (ar >= 0 ? ar : ag >= 0 ? ag : ab);
    }
    return L;
}

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

double front_of(const DeepLayout& L, const double* s) { return s[L.z]; }
double back_of(const DeepLayout& L, const double* s)
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

double load_value(const char* p, OIIO::TypeDesc::BASETYPE t)
{
    switch (t) {
    case OIIO::TypeDesc::FLOAT: {
        float f;
        std::memcpy(&f, p, sizeof f);
        return f;
    }
    case OIIO::TypeDesc::HALF: {
        half h;
        std::memcpy(&h, p, sizeof h);
        return float(h);
    }
    case OIIO::TypeDesc::UINT32: {
        uint32_t u;
        std::memcpy(&u, p, sizeof u);
        return double(u);
    }
    default: return 0.0;  // OpenEXR deep files hold only half, float and uint32
    }
}

void store_value(char* p, OIIO::TypeDesc::BASETYPE t, double v)
{
    switch (t) {
    case OIIO::TypeDesc::FLOAT: {
        const float f = float(v);
        std::memcpy(p, &f, sizeof f);
        break;
    }
    case OIIO::TypeDesc::HALF: {
        const half h = half(float(v));
        std::memcpy(p, &h, sizeof h);
        break;
    }
    case OIIO::TypeDesc::UINT32: {
        const uint32_t u = v <= 0.0 ? 0u : v >= 4294967295.0 ? 4294967295u : uint32_t(v);
        std::memcpy(p, &u, sizeof u);
        break;
    }
    default: break;
    }
}

// Per-chunk repairs and the first fault found (for the Error policy's message).
struct Faults {
    DeepRepairs counts;
    std::string first;
};

// Read pixel `p` of `raw` into `out` (appending), channels mapped by `to_out` (source
// channel -> output channel, -1 = dropped), applying the non-finite policy; p < 0 (outside
// the image) appends nothing.
void load_pixel(const RawDeep& raw, int64_t p, const std::vector<int>& to_out, const DeepLayout& L,
                Samples& out, Faults& f, int px, int py)
{
    const OIIO::DeepData& dd = *raw.dd;
    const int ns             = p >= 0 ? int(raw.counts[size_t(p)]) : 0;
    if (ns == 0)
        return;
    const char* base     = static_cast<const char*>(dd.data_ptr(p, 0, 0));
    const size_t stride  = dd.samplesize();
    const int src_nch    = dd.channels();
    // A source without the layout's ZBack holds point samples: ZBack = Z.
    const bool point_only = L.zback >= 0
                            && std::find(to_out.begin(), to_out.end(), L.zback) == to_out.end();
    // Room for every sample at once; a sample dropped below gives its row back.
    out.v.resize(size_t(out.n + ns) * size_t(out.nch), 0.0);
    for (int s = 0; s < ns; ++s) {
        const char* sp = base + size_t(s) * stride;
        double* o      = out.at(out.n++);
        for (int c = 0; c < src_nch; ++c)
            if (to_out[size_t(c)] >= 0)
                o[to_out[size_t(c)]] = load_value(sp + raw.offset[size_t(c)], raw.base[size_t(c)]);
        if (point_only)
            o[L.zback] = o[L.z];
        // The rules need a depth; NaN or -inf depth places the sample nowhere.
        const double z  = o[L.z];
        const double zb = L.zback >= 0 ? o[L.zback] : z;
        if (std::isnan(z) || std::isnan(zb) || z == -kInf || zb == -kInf) {
            if (f.first.empty())
                f.first = format("pixel ({}, {}) has a sample with depth {} .. {}", px, py, z, zb);
            ++f.counts.nan_depth;
            std::fill(o, o + out.nch, 0.0);  // the row is reused by the next sample
            --out.n;
            continue;
        }
        if (zb < z) {
            if (f.first.empty())
                f.first = format("pixel ({}, {}) has a sample with ZBack {} < Z {}", px, py, zb, z);
            ++f.counts.back_before;
            o[L.zback] = z;
        }
        for (int c = 0; c < out.nch; ++c)
            if ((L.role[size_t(c)] == Role::Colour || L.role[size_t(c)] == Role::Alpha)
                && !std::isfinite(o[c])) {
                if (f.first.empty())
                    f.first = format("pixel ({}, {}) has a non-finite {} value", px, py, L.names[size_t(c)]);
                ++f.counts.nonfinite;
                o[c] = 0.0;
            }
    }
    out.v.resize(size_t(out.n) * size_t(out.nch));
}

// The piece of sample `s` (a volume [Z, ZBack)) over [a, b): alphas -expm1(x log1p(-a)),
// colours scaled with their alpha (by x where the alpha is 0).
void volume_piece(const DeepLayout& L, const double* s, double a, double b, double* out)
{
    const double z0 = front_of(L, s), z1 = back_of(L, s);
    double x;
    if (std::isinf(z1))  // a medium reaching infinity holds all its opacity at infinity
        x = std::isinf(b) ? 1.0 : 0.0;
    else
        x = std::clamp((b - a) / (z1 - z0), 0.0, 1.0);
    std::copy(s, s + L.nch, out);
    out[L.z] = a;
    if (L.zback >= 0)
        out[L.zback] = b;
    if (x >= 1.0)
        return;
    for (int c : L.alphas) {
        const double al = s[c];
        out[c]          = al >= 1.0 ? (x > 0.0 ? 1.0 : 0.0) : -std::expm1(x * std::log1p(-al));
    }
    for (int c = 0; c < L.nch; ++c) {
        if (L.role[size_t(c)] != Role::Colour)
            continue;
        const int ac = L.alpha_of[size_t(c)];
        if (ac < 0 || s[ac] == 0.0)
            out[c] = s[c] * x;
        else
            out[c] = s[c] * (out[ac] / s[ac]);
    }
}

// The depths where the samples of `px` start or end, sorted, each once.
void sample_bounds(const DeepLayout& L, const Samples& px, std::vector<double>& bounds)
{
    bounds.clear();
    for (int s = 0; s < px.n; ++s) {
        bounds.push_back(front_of(L, px.at(s)));
        bounds.push_back(back_of(L, px.at(s)));
    }
    std::sort(bounds.begin(), bounds.end());
    bounds.erase(std::unique(bounds.begin(), bounds.end()), bounds.end());
}

// Append `smp` to `out`; a volume is cut at every depth of `bounds` (sorted, each once)
// strictly inside it.
void push_cut(const DeepLayout& L, const double* smp, const std::vector<double>& bounds, Samples& out)
{
    const double z0 = front_of(L, smp), z1 = back_of(L, smp);
    auto it         = std::upper_bound(bounds.begin(), bounds.end(), z0);
    if (!(z1 > z0) || it == bounds.end() || *it >= z1) {  // a point, or nothing cuts it
        out.push(smp);
        return;
    }
    double a = z0;
    for (; it != bounds.end() && *it < z1; ++it) {
        volume_piece(L, smp, a, *it, out.push());
        a = *it;
    }
    volume_piece(L, smp, a, z1, out.push());
}

// Merge `k` coincident samples (rows of `g`, same Z and ZBack) into `out`.
void merge_coincident(const DeepLayout& L, const double* const* g, int k, double* out)
{
    std::copy(g[0], g[0] + L.nch, out);
    if (k == 1)
        return;
    for (int a : L.alphas) {
        int opaque = 0;
        double U   = 0.0;
        for (int i = 0; i < k; ++i) {
            if (g[i][a] >= 1.0)
                ++opaque;
            else
                U += -std::log1p(-g[i][a]);
        }
        const double alpha = opaque > 0 ? 1.0 : -std::expm1(-U);
        const double w     = U > 0.0 ? alpha / U : 1.0;
        for (int c = 0; c < L.nch; ++c) {
            if (L.role[size_t(c)] != Role::Colour || L.alpha_of[size_t(c)] != a)
                continue;
            double sum = 0.0;
            for (int i = 0; i < k; ++i) {
                const double ai = g[i][a];
                if (opaque > 0) {
                    if (ai >= 1.0)
                        sum += g[i][c];
                } else {
                    sum += g[i][c] * (ai > 0.0 ? -std::log1p(-ai) / ai : 1.0);
                }
            }
            out[c] = opaque > 0 ? sum / opaque : w * sum;
        }
        out[a] = alpha;
    }
    if (L.alphas.empty())  // no alpha: the samples' light adds
        for (int c = 0; c < L.nch; ++c)
            if (L.role[size_t(c)] == Role::Colour)
                for (int i = 1; i < k; ++i)
                    out[c] += g[i][c];
}

// Whether light still passes the samples composited so far, whose transmittance per alpha
// channel is T: false once every alpha channel's accumulated opacity is 1 in float.
bool shows_through(const DeepLayout& L, const std::vector<double>& T)
{
    for (int a : L.alphas)
        if (T[size_t(a)] > kOpaqueTransmittance)
            return true;
    return L.alphas.empty();
}

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

bool already_tidy(const DeepLayout& L, const Samples& in)
{
    for (int s = 1; s < in.n; ++s) {
        const double* p = in.at(s - 1);
        const double* q = in.at(s);
        const double pz = front_of(L, p), pb = back_of(L, p);
        const double qz = front_of(L, q), qb = back_of(L, q);
        // Sorted by (Z, ZBack) with no two alike, and a volume ends before the next
        // starts (a point at the end of a volume is fine: the volume is [Z, ZBack)).
        if (qz < pz || (qz == pz && qb <= pb))
            return false;
        if (pb > pz && qz < pb)
            return false;
    }
    return true;
}

// Tidy `in` into `out` (cleared first).
void tidy_pixel(const DeepLayout& L, const Samples& in, Samples& out, TidyScratch& t)
{
    out.reset(in.nch);
    if (in.n <= 1 || already_tidy(L, in)) {
        out.v = in.v;
        out.n = in.n;
        return;
    }
    bool any_volume = false;
    for (int s = 0; s < in.n && !any_volume; ++s)
        any_volume = back_of(L, in.at(s)) > front_of(L, in.at(s));
    if (!any_volume) {
        // Points only (most renders' hard surfaces): nothing to cut; sort by depth, keeping
        // the input order among equal depths, and merge the points that share one.
        t.order.resize(size_t(in.n));
        std::iota(t.order.begin(), t.order.end(), 0);
        for (size_t i = 1; i < t.order.size(); ++i)  // insertion sort: pixels hold few
            for (size_t j = i; j > 0 && front_of(L, in.at(t.order[j])) < front_of(L, in.at(t.order[j - 1])); --j)
                std::swap(t.order[j], t.order[j - 1]);
        for (size_t i = 0; i < t.order.size();) {
            size_t j = i + 1;
            while (j < t.order.size() && front_of(L, in.at(t.order[j])) == front_of(L, in.at(t.order[i])))
                ++j;
            t.group.clear();
            for (size_t m = i; m < j; ++m)
                t.group.push_back(in.at(t.order[m]));
            merge_coincident(L, t.group.data(), int(t.group.size()), out.push());
            i = j;
        }
        return;
    }
    // Every depth where a sample starts or ends cuts the volumes that span it.
    sample_bounds(L, in, t.bounds);
    t.pieces.reset(in.nch);
    for (int s = 0; s < in.n; ++s)
        push_cut(L, in.at(s), t.bounds, t.pieces);
    // Sort by (Z, ZBack); stable, so merged colours do not depend on the sort's whims.
    t.order.resize(size_t(t.pieces.n));
    std::iota(t.order.begin(), t.order.end(), 0);
    std::stable_sort(t.order.begin(), t.order.end(), [&](int i, int j) {
        const double* p = t.pieces.at(i);
        const double* q = t.pieces.at(j);
        const double pz = front_of(L, p), qz = front_of(L, q);
        return pz < qz || (pz == qz && back_of(L, p) < back_of(L, q));
    });
    for (size_t i = 0; i < t.order.size();) {
        const double* first = t.pieces.at(t.order[i]);
        size_t j            = i + 1;
        while (j < t.order.size() && front_of(L, t.pieces.at(t.order[j])) == front_of(L, first)
               && back_of(L, t.pieces.at(t.order[j])) == back_of(L, first))
            ++j;
        t.group.clear();
        for (size_t m = i; m < j; ++m)
            t.group.push_back(t.pieces.at(t.order[m]));
        merge_coincident(L, t.group.data(), int(t.group.size()), out.push());
        i = j;
    }
}

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
              DeepResult& res, int nthreads)
{
    OIIO::ImageSpec spec = like;
    spec.deep            = true;
    spec.x               = res.roi.xbegin;
    spec.y               = res.roi.ybegin;
    spec.width           = res.roi.width();
    spec.height          = res.roi.height();
    spec.z = 0;
    spec.depth = 1;
    spec.channelformats  = types;
    spec.format          = types.empty() ? OIIO::TypeFloat : types[0];
    dst.reset(spec);
    OIIO::DeepData& dd = *dst.deepdata();
    dd.set_all_samples(res.counts);
    // OIIO allocates sample storage on the first non-const access; do it here, once, before
    // the offsets are read and the threads write.
    if (dd.pixels() > 0)
        (void)dd.data_ptr(0, 0, 0);
    RawDeep raw(dd);
    const int64_t w = res.roi.width();
    parallel_for_chunks(0, int64_t(res.rows.size()), 1, nthreads, [&](int64_t chunk, int64_t) {
        const std::vector<double>& vals = res.rows[size_t(chunk)];
        const int y0 = res.roi.ybegin + int(chunk) * DeepResult::kRowsPerChunk;
        const int y1 = std::min(res.roi.yend, y0 + DeepResult::kRowsPerChunk);
        size_t k     = 0;
        for (int64_t p = int64_t(y0 - res.roi.ybegin) * w; p < int64_t(y1 - res.roi.ybegin) * w; ++p) {
            const int ns = int(res.counts[size_t(p)]);
            if (ns == 0)
                continue;
            char* base = static_cast<char*>(dd.data_ptr(p, 0, 0));
            for (int s = 0; s < ns; ++s) {
                char* sp = base + size_t(s) * dd.samplesize();
                for (int c = 0; c < res.nch; ++c)
                    store_value(sp + raw.offset[size_t(c)], raw.base[size_t(c)], vals[k++]);
            }
        }
    });
    return true;
}

// The chunks' repairs summed into opt.repairs; under the Error policy, false + `err`
// naming the count and the first bad sample.
bool apply_policy(const std::vector<Faults>& faults, const DeepOptions& opt, std::string& err)
{
    DeepRepairs total;
    std::string first;
    for (const Faults& f : faults) {
        total.nan_depth += f.counts.nan_depth;
        total.back_before += f.counts.back_before;
        total.nonfinite += f.counts.nonfinite;
        if (first.empty())
            first = f.first;
    }
    if (opt.repairs)
        *opt.repairs = total;
    if (opt.policy == NonFinitePolicy::Error && total.total() > 0) {
        err = format("{} bad samples ({}; NaN policy 'error')", total.total(), first);
        return false;
    }
    return true;
}

// Run `per_pixel(x, y, Samples& out, Faults&, PixelScratch&)` over `roi`, collecting the samples each
// pixel gives into `res`; then apply the policy.
template<class PerPixel>
bool run_pixels(const OIIO::ROI& roi, int nch, const DeepOptions& opt, int nthreads, DeepResult& res,
                std::string& err, PerPixel&& per_pixel)
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
    return apply_policy(faults, opt, err);
}

// The checks every deep operation makes on an input.
bool check_deep(const OIIO::ImageBuf& img, const char* what, bool need_alpha, std::string& err)
{
    if (!img.initialized()) {
        err = format("{}: no image", what);
        return false;
    }
    if (!img.deep()) {
        err = format("{}: needs a deep image, this one is flat (--deepen makes one)", what);
        return false;
    }
    if (img.spec().depth > 1) {
        err = format("{}: volumetric (3-D) images are not supported", what);
        return false;
    }
    const DeepLayout L = layout_of(img);
    if (L.z < 0) {
        err = format("{}: the deep image has no Z channel (has {})", what,
                     OIIO::Strutil::join(img.spec().channelnames, ","));
        return false;
    }
    if (need_alpha && !L.has_alpha()) {
        err = format("{}: the deep image has no alpha channel (A, or AR, AG, AB)", what);
        return false;
    }
    return true;
}

std::vector<int> identity_map(int n)
{
    std::vector<int> m(static_cast<size_t>(n));
    std::iota(m.begin(), m.end(), 0);
    return m;
}

int64_t pixel_of(const OIIO::ImageBuf& img, int x, int y)
{
    const OIIO::ImageSpec& s = img.spec();
    if (x < s.x || y < s.y || x >= s.x + s.width || y >= s.y + s.height)
        return -1;
    return int64_t(y - s.y) * int64_t(s.width) + int64_t(x - s.x);
}

// A one-input deep operation: read each pixel (policy applied), `op(in, out, scratch)`.
template<class Op>
bool unary_deep(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const char* what, bool need_alpha,
                const DeepOptions& opt, int nthreads, Op&& op)
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
    const bool ok = run_pixels(src.roi(), L.nch, opt, nthreads, res, err,
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

// The share of the light of the tidy, cut sample `o` (no holdout boundary strictly inside
// it) that passes the tidy holdout pixel `h`, per alpha channel of `o` (into gain[a]). Everything of the holdout in front of the sample's start counts in
// full, holdout points at its start included (so an opaque element held out by itself
// vanishes). Where `o` is a volume piece and holdout volumes share its depth range, the
// two media are mixed exactly: the piece's emission, of density u_i, meets the holdout's
// u_h on the way, which scales it by f = u_i / (u_i + u_h) (1 - e^-(u_i + u_h)) / a_i
// (the emission-weighted mean of the holdout's transmittance over the piece; with a_i = 0
// it is (1 - e^-u_h) / u_h).
void holdout_gains(const DeepLayout& L, const DeepLayout& H,
                   const std::vector<std::vector<int>>& hold_alpha, const Samples& h, const double* o,
                   double* gain)
{
    const double z0 = front_of(L, o), z1 = back_of(L, o);
    const bool vol  = z1 > z0;
    for (int a : L.alphas) {
        double log_front = 0.0, u_within = 0.0;
        for (int j = 0; j < h.n; ++j) {
            const double* hs  = h.at(j);
            const double hz0 = front_of(H, hs), hz1 = back_of(H, hs);
            if (vol ? hz0 >= z1 : hz0 > z0)
                break;
            double ha = 0.0;
            for (int hc : hold_alpha[size_t(a)])
                ha += hs[hc];
            ha = std::clamp(ha / double(hold_alpha[size_t(a)].size()), 0.0, 1.0);
            const double log_t = ha >= 1.0 ? -kInf : std::log1p(-ha);
            if (!(hz1 > hz0)) {  // a point: at or in front of the sample's start
                log_front += log_t;
                continue;
            }
            const double len = hz1 - hz0;
            const double before = std::isinf(len) ? (std::isinf(z0) ? 1.0 : 0.0)
                                                   : std::clamp((std::min(z0, hz1) - hz0) / len, 0.0, 1.0);
            if (before > 0.0)
                log_front += ha >= 1.0 ? -kInf : before * log_t;
            if (vol && !std::isinf(len)) {
                const double within = (std::min(z1, hz1) - std::max(z0, hz0)) / len;
                if (within > 0.0)
                    u_within += ha >= 1.0 ? kInf : -within * log_t;
            }
        }
        double f = 1.0;
        if (u_within > 0.0) {
            const double ai = std::clamp(o[a], 0.0, 1.0);
            if (ai >= 1.0)
                f = std::isinf(u_within) ? 0.5 : 1.0;  // an opaque piece emits at its front
            else if (std::isinf(u_within))
                f = 0.0;
            else if (ai == 0.0)
                f = -std::expm1(-u_within) / u_within;
            else {
                const double ui = -std::log1p(-ai), U = ui + u_within;
                f = ui / U * -std::expm1(-U) / ai;
            }
        }
        gain[a] = std::exp(log_front) * f;
    }
}

}  // namespace

bool deep_tidy(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DeepOptions& opt, int nthreads)
{
    return unary_deep(dst, src, "deeptidy", false, opt, nthreads,
                      [](const DeepLayout& L, const Samples& in, Samples& out, TidyScratch& t) {
                          tidy_pixel(L, in, out, t);
                      });
}

bool deep_slice(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, double znear, double zfar,
                const DeepOptions& opt, int nthreads)
{
    if (std::isnan(znear) || std::isnan(zfar) || !(znear < zfar)) {
        dst.errorfmt("deepslice: the range [{}, {}) is empty; give near < far", znear, zfar);
        return false;
    }
    return unary_deep(dst, src, "deepslice", false, opt, nthreads,
                      [&](const DeepLayout& L, const Samples& in, Samples& out, TidyScratch&) {
                          for (int s = 0; s < in.n; ++s) {
                              const double* smp = in.at(s);
                              const double z0 = front_of(L, smp), z1 = back_of(L, smp);
                              if (!(z1 > z0)) {
                                  if (z0 >= znear && z0 < zfar)
                                      out.push(smp);
                                  continue;
                              }
                              const double a = std::max(z0, znear), b = std::min(z1, zfar);
                              if (!(b > a))
                                  continue;
                              if (a == z0 && b == z1)
                                  out.push(smp);
                              else
                                  volume_piece(L, smp, a, b, out.push());
                          }
                      });
}

bool deep_merge(OIIO::ImageBuf& dst, const std::vector<const OIIO::ImageBuf*>& srcs, bool cull,
                const DeepOptions& opt, int nthreads)
{
    if (srcs.empty()) {
        dst.errorfmt("deepmerge: no images to merge");
        return false;
    }
    std::string err;
    for (size_t i = 0; i < srcs.size(); ++i)
        if (!srcs[i] || !check_deep(*srcs[i], "deepmerge", cull, err)) {
            dst.errorfmt("{} (image {})", srcs[i] ? err : std::string("deepmerge: no image"), i + 1);
            return false;
        }
    // Point samples merge with volume samples: a sample without ZBack is a point at its Z,
    // as one whose ZBack equals its Z is ("Interpreting OpenEXR Deep Pixels"), so the result
    // has ZBack when any input has it, and the channels are laid out as the first such
    // input's; an input without ZBack gets ZBack = Z (load_pixel).
    std::vector<bool> has_zback(srcs.size());
    for (size_t i = 0; i < srcs.size(); ++i)
        has_zback[i] = layout_of(*srcs[i]).zback >= 0;
    const auto first_volume = std::find(has_zback.begin(), has_zback.end(), true);
    const size_t lead       = first_volume == has_zback.end() ? 0 : size_t(first_volume - has_zback.begin());
    const DeepLayout L = layout_of(*srcs[lead]);
    // Each image's channels mapped onto the lead's by name.
    std::vector<std::vector<int>> maps;
    std::vector<RawDeep> raws;
    OIIO::ROI roi = srcs[0]->roi();
    for (size_t i = 0; i < srcs.size(); ++i) {
        const OIIO::ImageSpec& s = srcs[i]->spec();
        const bool point_only    = L.zback >= 0 && !has_zback[i];
        if (s.nchannels != L.nch - (point_only ? 1 : 0)) {
            dst.errorfmt("deepmerge: image {} has channels {}, image {} has {}", i + 1,
                         OIIO::Strutil::join(s.channelnames, ","), lead + 1,
                         OIIO::Strutil::join(L.names, ","));
            return false;
        }
        std::vector<int> m(size_t(s.nchannels), -1);
        for (int c = 0; c < s.nchannels; ++c) {
            auto it = std::find(L.names.begin(), L.names.end(), s.channel_name(c));
            if (it == L.names.end()) {
                dst.errorfmt("deepmerge: image {} has channel '{}', image {} has not ({})", i + 1,
                             s.channel_name(c), lead + 1, OIIO::Strutil::join(L.names, ","));
                return false;
            }
            m[size_t(c)] = int(it - L.names.begin());
        }
        maps.push_back(std::move(m));
        raws.emplace_back(*srcs[i]->deepdata());
        roi = OIIO::roi_union(roi, srcs[i]->roi());
    }
    DeepResult res;
    const bool ok = run_pixels(roi, L.nch, opt, nthreads, res, err,
                               [&](int x, int y, Samples& out, Faults& f, PixelScratch& sc) {
                                   sc.in.reset(L.nch);
                                   for (size_t i = 0; i < srcs.size(); ++i) {
                                       const int64_t p = pixel_of(*srcs[i], x, y);
                                       if (p >= 0)
                                           load_pixel(raws[i], p, maps[i], L, sc.in, f, x, y);
                                   }
                                   tidy_pixel(L, sc.in, out, sc.t);
                                   if (!cull)
                                       return;
                                   // Keep the samples some light of which still shows.
                                   std::vector<double>& T = sc.weights;
                                   T.assign(size_t(L.nch), 1.0);
                                   int keep = 0;
                                   for (; keep < out.n && shows_through(L, T); ++keep)
                                       for (int a : L.alphas)
                                           T[size_t(a)] *= 1.0 - std::clamp(out.at(keep)[a], 0.0, 1.0);
                                   out.n = keep;
                                   out.v.resize(size_t(keep) * size_t(L.nch));
                               });
    if (!ok) {
        dst.errorfmt("deepmerge: {}", err);
        return false;
    }
    // The lead's channels; the first image's display window and metadata.
    OIIO::ImageSpec like = srcs[lead]->spec();
    like.extra_attribs   = srcs[0]->spec().extra_attribs;
    like.full_x = srcs[0]->spec().full_x, like.full_y = srcs[0]->spec().full_y;
    like.full_width = srcs[0]->spec().full_width, like.full_height = srcs[0]->spec().full_height;
    OIIO::ImageBuf result;
    assemble(result, like, L.types, res, nthreads);
    dst = std::move(result);
    return true;
}

bool deep_holdout(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ImageBuf& holdout,
                  const DeepOptions& opt, int nthreads)
{
    std::string err;
    if (!check_deep(src, "deepholdout", true, err) || !check_deep(holdout, "deepholdout (holdout)", true, err)) {
        dst.errorfmt("{}", err);
        return false;
    }
    const DeepLayout L = layout_of(src);
    const DeepLayout H = layout_of(holdout);
    // Which holdout alpha attenuates each of the image's alpha channels: the same name,
    // else A, else the mean of AR, AG, AB.
    std::vector<std::vector<int>> hold_alpha(size_t(L.nch));
    for (int a : L.alphas) {
        auto it = std::find(H.names.begin(), H.names.end(), L.names[size_t(a)]);
        auto hA = std::find(H.names.begin(), H.names.end(), std::string("A"));
        if (it != H.names.end())
            hold_alpha[size_t(a)] = { int(it - H.names.begin()) };
        else if (hA != H.names.end())
            hold_alpha[size_t(a)] = { int(hA - H.names.begin()) };
        else
            hold_alpha[size_t(a)] = H.alphas;
    }
    const RawDeep raw_src(*src.deepdata()), raw_hold(*holdout.deepdata());
    const std::vector<int> map_src = identity_map(L.nch), map_hold = identity_map(H.nch);
    DeepResult res;
    const bool ok = run_pixels(src.roi(), L.nch, opt, nthreads, res, err,
                               [&](int x, int y, Samples& out, Faults& f, PixelScratch& sc) {
                                   Samples &in = sc.in, &tidy = sc.tidy, &hin = sc.hin, &h = sc.h, &cut = sc.cut;
                                   TidyScratch& t = sc.t;
                                   in.reset(L.nch);
                                   load_pixel(raw_src, pixel_of(src, x, y), map_src, L, in, f, x, y);
                                   if (in.n == 0)
                                       return;  // nothing to hold out
                                   tidy_pixel(L, in, tidy, t);
                                   hin.reset(H.nch);
                                   const int64_t hp = pixel_of(holdout, x, y);
                                   if (hp >= 0)
                                       load_pixel(raw_hold, hp, map_hold, H, hin, f, x, y);
                                   tidy_pixel(H, hin, h, t);
                                   if (h.n == 0) {
                                       out.v = tidy.v;
                                       out.n = tidy.n;
                                       return;
                                   }
                                   // Cut the image's volumes where holdout samples start or end.
                                   sample_bounds(H, h, t.bounds);
                                   cut.reset(L.nch);
                                   for (int s = 0; s < tidy.n; ++s)
                                       push_cut(L, tidy.at(s), t.bounds, cut);
                                   // Each piece's light and coverage scaled by its gain, then
                                   // its alpha and colour chosen so that "over" front to back
                                   // composites to those scaled contributions: the pieces of
                                   // one volume must keep occluding one another as the
                                   // unscaled volume did (A_i = a_i g_i prod(1 - a_j), and
                                   // a'_i = A_i / (1 - sum_j<i A_j)).
                                   std::vector<double>& gain = sc.weights;
                                   gain.assign(size_t(cut.n) * size_t(L.nch), 1.0);
                                   for (int s = 0; s < cut.n; ++s) {
                                       holdout_gains(L, H, hold_alpha, h, cut.at(s), &gain[size_t(s) * size_t(L.nch)]);
                                       out.push(cut.at(s));
                                   }
                                   for (int a : L.alphas) {
                                       double own_t = 1.0, shown = 0.0;
                                       for (int s = 0; s < cut.n; ++s) {
                                           const double* in_s = cut.at(s);
                                           double* o          = out.at(s);
                                           const double g     = gain[size_t(s) * size_t(L.nch) + size_t(a)];
                                           const double al    = std::clamp(in_s[a], 0.0, 1.0);
                                           const double rest  = 1.0 - shown;
                                           const double k     = rest > 0.0 ? g * own_t / rest : 0.0;
                                           o[a]               = in_s[a] * k;
                                           for (int c = 0; c < L.nch; ++c)
                                               if (L.role[size_t(c)] == Role::Colour && L.alpha_of[size_t(c)] == a)
                                                   o[c] = in_s[c] * k;
                                           shown += al * g * own_t;
                                           own_t *= 1.0 - al;
                                       }
                                   }
                               });
    if (!ok) {
        dst.errorfmt("deepholdout: {}", err);
        return false;
    }
    OIIO::ImageBuf result;
    assemble(result, src.spec(), L.types, res, nthreads);
    dst = std::move(result);
    return true;
}

bool flatten(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DeepOptions& opt, int nthreads)
{
    std::string err;
    if (!check_deep(src, "flatten", true, err)) {
        dst.errorfmt("{}", err);
        return false;
    }
    const DeepLayout L = layout_of(src);
    const RawDeep raw(*src.deepdata());
    const std::vector<int> map = identity_map(L.nch);
    OIIO::ImageSpec spec = src.spec();
    spec.deep            = false;
    spec.set_format(OIIO::TypeFloat);
    spec.channelformats.clear();
    OIIO::ImageBuf result(spec);
    const OIIO::ROI roi = src.roi();
    constexpr int rows = DeepResult::kRowsPerChunk;
    std::vector<Faults> faults(static_cast<size_t>((roi.height() + rows - 1) / rows));
    parallel_for_chunks(0, int64_t(faults.size()), 1, nthreads, [&](int64_t chunk, int64_t) {
        Samples in, tidy;
        TidyScratch t;
        std::vector<double> acc(size_t(L.nch)), T(size_t(L.nch));
        const int y0 = roi.ybegin + int(chunk) * rows, y1 = std::min(roi.yend, y0 + rows);
        for (int y = y0; y < y1; ++y) {
            float* row = static_cast<float*>(result.pixeladdr(roi.xbegin, y));
            for (int x = roi.xbegin; x < roi.xend; ++x, row += L.nch) {
                in.reset(L.nch);
                load_pixel(raw, pixel_of(src, x, y), map, L, in, faults[size_t(chunk)], x, y);
                tidy_pixel(L, in, tidy, t);
                std::fill(acc.begin(), acc.end(), 0.0);
                std::fill(T.begin(), T.end(), 1.0);
                int nearest = -1;
                double z_front = kInf, z_back = -kInf;
                for (int s = 0; s < tidy.n; ++s) {
                    const double* smp = tidy.at(s);
                    const bool shows  = shows_through(L, T);
                    for (int c = 0; c < L.nch; ++c)
                        if (L.role[size_t(c)] == Role::Colour)
                            acc[size_t(c)] += T[size_t(L.alpha_of[size_t(c)])] * smp[c];
                    bool visible = false;
                    for (int a : L.alphas) {
                        acc[size_t(a)] += T[size_t(a)] * smp[a];
                        T[size_t(a)] *= 1.0 - smp[a];
                        visible |= smp[a] != 0.0;
                    }
                    if (visible && shows) {
                        nearest = nearest < 0 ? s : nearest;
                        z_front = std::min(z_front, front_of(L, smp));
                        z_back  = std::max(z_back, back_of(L, smp));
                    }
                }
                if (nearest < 0 && tidy.n > 0) {  // only light of alpha 0: its whole range
                    nearest = 0;
                    z_front = front_of(L, tidy.at(0));
                    for (int s = 0; s < tidy.n; ++s)
                        z_back = std::max(z_back, back_of(L, tidy.at(s)));
                }
                for (int c = 0; c < L.nch; ++c) {
                    const Role r = L.role[size_t(c)];
                    double v     = acc[size_t(c)];
                    if (r == Role::Depth)
                        v = nearest < 0 ? kEmptyDepth : z_front;
                    else if (r == Role::DepthBack)
                        v = nearest < 0 ? kEmptyDepth : z_back;
                    else if (r == Role::Carried)
                        v = nearest < 0 ? 0.0 : tidy.at(nearest)[c];
                    row[c] = float(v);
                }
            }
        }
    });
    if (!apply_policy(faults, opt, err)) {
        dst.errorfmt("flatten: {}", err);
        return false;
    }
    dst = std::move(result);
    return true;
}

bool deepen(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, float z_without_depth, int nthreads)
{
    if (!src.initialized()) {
        dst.errorfmt("deepen: no image");
        return false;
    }
    if (src.deep()) {
        dst.errorfmt("deepen: the image is deep already");
        return false;
    }
    if (!std::isfinite(z_without_depth)) {
        dst.errorfmt("deepen: the depth to give ({}) must be finite", z_without_depth);
        return false;
    }
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf* f = &src;
    if (src.spec().format != OIIO::TypeFloat || !src.localpixels()) {
        holder.copy(src, OIIO::TypeFloat);
        f = &holder;
    }
    const OIIO::ImageSpec& spec = src.spec();
    const OIIO::ImageSpec& native = src.nativespec();
    const int nch = spec.nchannels;
    int zc = -1, zbc = -1;
    std::vector<OIIO::TypeDesc> types;
    for (int c = 0; c < nch; ++c) {
        const std::string n = spec.channel_name(c);
        zc  = n == "Z" ? c : zc;
        zbc = (n == "ZBack" || n == "Zback") ? c : zbc;
        OIIO::TypeDesc t = native.nchannels == nch ? native.channelformat(c) : OIIO::TypeFloat;
        if (t != OIIO::TypeHalf && t.basetype != OIIO::TypeDesc::UINT32)
            t = OIIO::TypeFloat;  // deep EXR holds half, float and uint only
        types.push_back(t);
    }
    OIIO::ImageSpec like = spec;
    const bool add_z     = zc < 0;
    if (add_z) {
        like.channelnames.push_back("Z");
        types.push_back(OIIO::TypeFloat);
    }
    like.nchannels = int(types.size());
    like.z_channel = add_z ? nch : zc;
    DeepResult res;
    std::string err;
    DeepOptions opt;
    run_pixels(src.roi(), like.nchannels, opt, nthreads, res, err, [&](int x, int y, Samples& out, Faults&, PixelScratch&) {
        const float* px = static_cast<const float*>(f->pixeladdr(x, y));
        bool has        = false;
        for (int c = 0; c < nch && !has; ++c)
            has = c != zc && c != zbc && px[c] != 0.0f;
        for (int c = 0; c < nch && !has; ++c)
            has = (c == zc || c == zbc) && std::isfinite(px[c]) && px[c] != 0.0f && px[c] < 1e30f;
        if (!has)
            return;
        double* o = out.push();
        for (int c = 0; c < nch; ++c)
            o[c] = px[c];
        if (add_z)
            o[nch] = z_without_depth;
    });
    OIIO::ImageBuf result;
    assemble(result, like, types, res, nthreads);
    dst = std::move(result);
    return true;
}

}  // namespace bokeh
