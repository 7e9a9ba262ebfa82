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

#include "deep/deep_pixels.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/half.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

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

bool deep_tidy(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DeepOptions& opt, DeepRepairs* report,
               int nthreads)
{
    return unary_deep(dst, src, "deeptidy", false, opt, report, nthreads,
                      [](const DeepLayout& L, const Samples& in, Samples& out, TidyScratch& t) {
                          tidy_pixel(L, in, out, t);
                      });
}

bool deep_slice(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, double znear, double zfar,
                const DeepOptions& opt, DeepRepairs* report, int nthreads)
{
    if (std::isnan(znear) || std::isnan(zfar) || !(znear < zfar)) {
        dst.errorfmt("deepslice: the range [{}, {}) is empty; give near < far", znear, zfar);
        return false;
    }
    return unary_deep(dst, src, "deepslice", false, opt, report, nthreads,
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
                const DeepOptions& opt, DeepRepairs* report, int nthreads)
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
    const bool ok = run_pixels(roi, L.nch, opt, report, nthreads, res, err,
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
                  const DeepOptions& opt, DeepRepairs* report, int nthreads)
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
    const bool ok = run_pixels(src.roi(), L.nch, opt, report, nthreads, res, err,
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

bool deep_flatten(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DeepOptions& opt, DeepRepairs* report,
                  int nthreads)
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
    if (!apply_policy(faults, opt, report, err)) {
        dst.errorfmt("flatten: {}", err);
        return false;
    }
    dst = std::move(result);
    return true;
}

bool deep_from_flat(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, float z_without_depth, int nthreads)
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
    run_pixels(src.roi(), like.nchannels, opt, nullptr, nthreads, res, err, [&](int x, int y, Samples& out, Faults&, PixelScratch&) {
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
