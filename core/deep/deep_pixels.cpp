// deep_pixels.cpp — the deep family's pixel machinery (deep_pixels.h): channel layouts,
// raw sample access, the non-finite policy as pixels are read, volume cuts, the merge of
// coincident samples, the tidy of one pixel, and the assembly of a result. The rules are
// those core/deep/deep.cpp's header states (docs/methods/deep.md writes them out).

#include "deep/deep_pixels.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/half.h>
#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

namespace {


using OIIO::Strutil::fmt::format;

bool is_name(const std::string& n, std::initializer_list<const char*> any)
{
    for (const char* a : any)
        if (n == a)
            return true;
    return false;
}

}  // namespace

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

bool shows_through(const DeepLayout& L, const std::vector<double>& T)
{
    for (int a : L.alphas)
        if (T[size_t(a)] > kOpaqueTransmittance)
            return true;
    return L.alphas.empty();
}

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

bool apply_policy(const std::vector<Faults>& faults, const DeepOptions& opt, DeepRepairs* report, std::string& err)
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
    if (report)
        *report = total;
    if (opt.nonfinite == NonFinitePolicy::Error && total.total() > 0) {
        err = format("{} bad samples ({}; NaN policy 'error')", total.total(), first);
        return false;
    }
    return true;
}

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

}  // namespace bokeh::detail
