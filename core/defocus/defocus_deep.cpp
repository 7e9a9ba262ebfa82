// defocus_deep.cpp — depth defocus of a deep image: every sample blurred with its own CoC,
// in layers, with the background that the render holds behind each foreground.
//
// The flat defocus (defocus.cpp) must invent what a foreground hides (the disocclusion
// problem Kawase's "Bokeh Deep Dive" answers with deep compositing; docs/methods/deep.md);
// a deep image holds it. Here every sample of the tidy image takes the
// signed CoC of its own depth (CocOfDepth, so the depth math modes, gains and limits are
// the flat defocus's), a volume is cut where its CoC crosses a rung of the layer ladder
// (expm1/log1p, as deep.cpp cuts), and each piece is shared between the two rungs around
// its CoC with the flat method's second-moment weights. Layer k of a pixel is its pieces
// in that layer composited front to back ("over"); the layers then go through the flat
// method's machinery (composite_layers: the aperture at the rung's CoC, large ones in
// reduced buffers, nearer over farther) with nothing divided or filled: what is behind a
// nearer layer is the layer's own, rendered content.
//
// The layers, views and ladder are planned from the samples in
// core/defocus/defocus_deep_plan.cpp.
//
// Deep output: each layer of a pixel becomes one sample, a volume from the depth of its
// rung's CoC to the next rung's (the last a point), so a later merge with another deep
// element interleaves by depth, and the flatten of the result is the flat output.
//
// Lens character (core/defocus/defocus_sprites.cpp): a bright piece's sprite share is taken out of
// each layer it has a share in (as far as it shows through the nearer pieces of that
// layer) and drawn there with the lens PSF of the piece's own CoC.
//
// Limits: every layer holds a dense RGBA and visibility plane over the data window (20
// bytes a pixel a layer: 18 layers of LowResLeftView's 1024x576, 212 MB); samples between
// two rungs are blurred by a mix of the two kernels (as in the flat method); within a layer, the order of a pixel's pieces is kept but their blur is
// one; iris mode and depth dilation are flat-image tools and are refused here; the
// gather method is flat only.

#include <bokeh/deep.h>
#include <bokeh/defocus.h>

#include "defocus/defocus_deep_plan.h"
#include "defocus/defocus_layers.h"
#include "base/progress.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <tuple>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

// A flat result's layers drawn in groups whose planes take about this much (at least
// kMinGroupLayers layers a group; measured in defocus_deep below).
constexpr double kGroupPlanesBytes = 128.0 * 1024.0 * 1024.0;
constexpr size_t kMinGroupLayers   = 4;

using OIIO::Strutil::fmt::format;
using Clock = std::chrono::steady_clock;

// In front of a deep pixel's last sample, an empty layer is continued under a nearer piece
// only when it is the next rung behind the piece's, or its CoC lies within
// max(kSameSurfaceCocPx, kSameSurfaceCocShare |CoC|) of the piece's farthest rung: the piece
// is then taken for the same surface's nearer ribbon. A ribbon must go on under its
// neighbours for its blur radius |CoC| / 2; over that distance a surface whose CoC changes
// by up to 0.5 px a pixel changes its CoC by |CoC| / 4. Measured on the lights scene
// against its thin-lens truth (rays started over the pixel's area, pixel=area; bokeh-bench
// --task truth-chain --scenes lights, 4x4 blocks,
// disocclusion mask): a flat window of 0.5 / 1 / 2 / 4 px gave 34.5 / 35.4 / 36.8 / 36.8 dB,
// the share changes nothing there; without it a steep sloped plane over a recorded wall
// shows the wall through its ribbons (DeepDefocus.ASlopedSurfaceOverARecordedWallStaysOpaque).
constexpr float kSameSurfaceCocPx = 2.0f, kSameSurfaceCocShare = 0.25f;

// One piece of a sample: premultiplied colour and alpha, its CoC.
struct Piece {
    float rgba[4];
    float coc;
};

// The depth value (in the Z channel's own terms) at which `coc_of` reaches `target`,
// between depth values lo and hi whose CoCs bracket it (CocOfDepth is monotone in the
// depth value for every depth mode).
double depth_of_coc(const CocOfDepth& coc_of, double lo, double hi, float target)
{
    const bool rising = coc_of(float(hi)) >= coc_of(float(lo));
    for (int i = 0; i < 60; ++i) {
        const double mid = 0.5 * (lo + hi);
        if ((coc_of(float(mid)) < target) == rising)
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

// Pixel p's samples as pieces, front to back: a point sample whole, a volume cut where its
// CoC crosses a rung (expm1/log1p, as deep.cpp cuts), each piece at its middle's CoC;
// bloom applied to the unpremultiplied colour (ZDefocus's).
void pixel_pieces(std::vector<Piece>& pieces, std::vector<double>& cuts, const OIIO::DeepData& dd, int64_t p,
                  const DeepChannels& ch, const CocOfDepth& coc_of, const Membership& m, const DefocusOptions& o)
{
    const size_t K = m.coc_px.size();
    const float bloom_t = o.bloom_threshold, bloom_g = o.bloom_gain;
    pieces.clear();
    for (int s = 0; s < dd.samples(p); ++s) {
        float rgba[4] = { dd.deep_value(p, ch.r, s), dd.deep_value(p, ch.g, s), dd.deep_value(p, ch.b, s),
                          dd.deep_value(p, ch.a, s) };
        if (bloom_g != 1.0f)
            for (int c = 0; c < 3; ++c) {
                const float un = rgba[3] > 0.0f ? rgba[c] / rgba[3] : rgba[c];
                if (un > bloom_t)
                    rgba[c] *= bloom_g;
            }
        const double z  = dd.deep_value(p, ch.z, s);
        const double zb = ch.zback >= 0 ? std::max(double(dd.deep_value(p, ch.zback, s)), z) : z;
        const float c0 = coc_of(float(z)), c1 = coc_of(float(zb));
        if (!(zb > z) || std::isinf(zb)) {
            pieces.push_back({ { rgba[0], rgba[1], rgba[2], rgba[3] }, c0 });
            continue;
        }
        cuts.assign(1, z);
        for (size_t k = 0; k < K; ++k)
            if ((m.coc_px[k] > std::min(c0, c1)) && (m.coc_px[k] < std::max(c0, c1)))
                cuts.push_back(depth_of_coc(coc_of, z, zb, m.coc_px[k]));
        cuts.push_back(zb);
        std::sort(cuts.begin(), cuts.end());
        const double a = std::clamp(double(rgba[3]), 0.0, 1.0);
        for (size_t i = 0; i + 1 < cuts.size(); ++i) {
            const double x  = (cuts[i + 1] - cuts[i]) / (zb - z);
            const double ap = a >= 1.0 ? (i == 0 ? 1.0 : 0.0) : -std::expm1(x * std::log1p(-a));
            // Colour scales with the piece's alpha; light of alpha 0 with its depth.
            const double scale = a > 0.0 ? ap / a : x;
            // Pieces behind an opaque volume's first are hidden by it: alpha 1 keeps
            // the light at the front.
            Piece pc;
            for (int c = 0; c < 3; ++c)
                pc.rgba[c] = float(rgba[c] * (a >= 1.0 ? (i == 0 ? 1.0 : 0.0) : scale));
            pc.rgba[3] = float(ap);
            pc.coc     = coc_of(float(0.5 * (cuts[i] + cuts[i + 1])));
            pieces.push_back(pc);
        }
    }
}

// A thread's working rows for pixel_layers, one value a layer.
struct LayerScratch {
    std::vector<float> T, self, nearer_t, close_t;
    std::vector<uint8_t> holds;
    explicit LayerScratch(size_t K) : T(K, 1.0f), self(K), nearer_t(K), close_t(K), holds(K) {}
};

// Pixel p's pieces into its layers (f.layer_rgba, each layer's pieces composited front to
// back) and what the pixel leaves visible of each layer (f.layer_vis); with lens character,
// each piece's sprite share a layer into `found`.
//
// The visibility, the divisor of a layer's blurred content as the flat method's:
//   self_k:   pieces shared between k - 1 and k are seen through their nearer
//             shares, 1 - sum T (1 - u) a, T what the earlier pieces of layer k
//             leave in front of the piece's share there. With T of layer k, a
//             pixel's layers composited unblurred are its flatten exactly (any
//             pieces, shares and alphas: a random trial of 20000 pixels agreed
//             to 4e-16, where T of layer k - 1 erred by up to 0.09): a piece whose
//             nearer share a nearer surface hides in k - 1 (a cone's edge over a
//             wall 1.6 px of CoC behind it, LowResLeftView) keeps its share in k
//             at its own level, so the wall goes on behind the cone's blurred edge
//             instead of cracking (alpha 0.89 over 6 px where the truth is
//             opaque). A product of 1 - (1 - u) a instead counts a piece hidden
//             behind another again, and two close, nearly opaque samples drew a
//             table top of representativeDeepImage at 1.5x its coverage;
//   hidden_k: what lies wholly in nearer layers covers 1 - prod(1 - a) of the
//             pixel; where the pixel holds nothing in layer k itself, that part
//             of layer k is unknown, and layer k is continued under it (a surface
//             crossing layers goes on under its nearer ribbons: without this,
//             seams open between the ribbons of one surface, and what lies
//             farther behind shows through them). So
//   vis_k = self_k (1 - hidden_k in_k), in_k = prod(1 - a) of the pieces with a
//   share in layer k (content the layer holds at the pixel needs no guess).
// But a deep pixel records everything along its ray up to its last sample: in
// front of the pixel's last layer, a layer that holds nothing there is known to
// be empty, and is continued only under a nearer piece of nearly the same CoC, a
// ribbon of the same surface (close_t; kSameSurfaceCocPx says how near).
// Continued under any nearer piece, a light hidden behind a post spreads its one
// pixel over its whole disk at its own level (lights scene, 960x540: the light
// behind the post a full disk 20x too bright where the thin-lens truth shows a
// sliver); not continued at all, seams open between a round post's ribbons.
// Behind the pixel's last layer nothing is known, and every nearer piece hides.
//
// Only layers [first, end) are written, f.layer_rgba[k - first] and f.layer_vis[k - first]
// (a frame drawn in groups of layers to fit the memory budget); the rest is computed for all.
void pixel_layers(Frame& f, std::vector<Sprite>& found, LayerScratch& sc, int64_t p, const std::vector<Piece>& pieces,
                  const Membership& m, const DefocusOptions& o, bool reference, size_t first, size_t end)
{
    const size_t K = m.coc_px.size();
    std::vector<float>& T = sc.T;
    std::fill(sc.self.begin(), sc.self.end(), 1.0f);
    std::fill(sc.nearer_t.begin(), sc.nearer_t.end(), 1.0f);
    std::fill(sc.close_t.begin(), sc.close_t.end(), 1.0f);
    std::fill(sc.holds.begin(), sc.holds.end(), uint8_t(0));
    size_t last_layer = 0;
    for (const Piece& pc : pieces) {
        uint16_t lower;
        float upper;
        share_between(pc.coc, m.coc_px, lower, upper);
        // The reference's rungs are the occupied bins, a step apart where a surface
        // runs on: a piece between two such rungs is shared, as the layered method
        // shares, but one between rungs farther apart goes wholly to the nearer
        // rung. Shared, a piece a hair off its rung would put a sliver in the next
        // rung, however far, and hide all that rung holds behind it there (on the
        // edges scene the in-focus wall behind the near panel's edge took the
        // panel's colour).
        if (reference && upper > 0.0f && size_t(lower) + 1 < K
            && m.coc_px[size_t(lower) + 1] - m.coc_px[lower] > 1.001f * o.reference_step_px)
            upper = pc.coc - m.coc_px[lower] > m.coc_px[size_t(lower) + 1] - pc.coc ? 1.0f : 0.0f;
        last_layer = std::max(last_layer, std::min(size_t(lower) + (upper > 0.0f ? 1 : 0), K - 1));
        const float alpha = std::clamp(pc.rgba[3], 0.0f, 1.0f);
        const bool split  = upper > 0.0f && upper < 1.0f && size_t(lower) + 1 < K;
        if (split)
            sc.self[size_t(lower) + 1] =
                std::max(0.0f, sc.self[size_t(lower) + 1] - T[size_t(lower) + 1] * (1.0f - upper) * alpha);
        const size_t wholly_nearer_from = size_t(lower) + (upper > 0.0f ? 2 : 1);
        if (wholly_nearer_from < K)
            sc.nearer_t[wholly_nearer_from] *= 1.0f - alpha;
        const float farthest_coc = m.coc_px[std::min(size_t(lower) + (upper > 0.0f ? 1 : 0), K - 1)];
        auto same_surface = [&](size_t k) {
            return k == wholly_nearer_from
                   || m.coc_px[k] <= farthest_coc + std::max(kSameSurfaceCocPx, kSameSurfaceCocShare * std::abs(m.coc_px[k]));
        };
        for (size_t k = wholly_nearer_from; k < K && same_surface(k); ++k)
            sc.close_t[k] *= 1.0f - alpha;
        if (upper < 1.0f)
            sc.holds[lower] = 1;
        if (upper > 0.0f && size_t(lower) + 1 < K)
            sc.holds[size_t(lower) + 1] = 1;
        for (int side = 0; side < 2; ++side) {
            const size_t k = size_t(lower) + size_t(side);
            const float w  = side == 0 ? 1.0f - upper : upper;
            if (w <= 0.0f || k >= K)
                continue;
            if (k < first || k >= end) {  // not drawn now; what it hides behind it still counts
                T[k] *= 1.0f - alpha;
                continue;
            }
            float* v = f.layer_rgba[k - first].data() + size_t(p) * 4;
            for (int c = 0; c < 4; ++c)
                v[c] += T[k] * w * pc.rgba[c];
            float lum;
            const float share = o.lens_character ? sprite_share(pc.rgba, o.highlight_threshold, lum) : 0.0f;
            if (share > 0.0f) {
                Sprite sp;
                sp.at      = size_t(p);
                sp.layer   = int(k);
                sp.coc_px  = pc.coc;
                sp.counted = side == 0 || !(1.0f - upper > 0.0f);  // the piece once
                for (int c = 0; c < 3; ++c)
                    sp.rgb[c] = T[k] * w * share * pc.rgba[c];
                found.push_back(sp);
            }
            // Whatever follows lies behind this piece in depth: hidden by all of it,
            // whichever share of it this layer holds.
            T[k] *= 1.0f - alpha;
        }
    }
    // nearer_t: transmittance of what lies wholly in front of layer k (a running
    // product forward).
    for (size_t k = 1; k < K; ++k)
        sc.nearer_t[k] *= sc.nearer_t[k - 1];
    for (size_t k = first; k < end; ++k)
        f.layer_vis[k - first][size_t(p)] =
            sc.self[k] * (k > last_layer ? sc.nearer_t[k] : sc.holds[k] ? 1.0f : sc.close_t[k]);
    std::fill(T.begin(), T.end(), 1.0f);
}

// Lens character: the brightest `max_sprites` of the pieces' sprite shares (in a fixed
// order), taken out of their layers, with their PSFs fetched. False + `err`.
bool take_deep_sprites(Frame& f, std::vector<Sprite>& highlights, const DefocusOptions& o, const OIIO::ImageSpec& spec,
                       const OIIO::ImageSpec& src_spec, int nthreads, std::string& err)
{
    const Clock::time_point t0 = Clock::now();
    auto set = std::make_shared<SpriteSet>();
    LensCharacter lens;
    if (!defocus_lens(o, spec, lens, err))
        return false;
    auto luminance = [](const Sprite& a) { return 0.2126f * a.rgb[0] + 0.7152f * a.rgb[1] + 0.0722f * a.rgb[2]; };
    set->candidates = int64_t(highlights.size());
    if (highlights.size() > size_t(o.max_sprites)) {
        std::nth_element(highlights.begin(), highlights.begin() + o.max_sprites, highlights.end(),
                         [&](const Sprite& a, const Sprite& b) {
                             return luminance(a) > luminance(b)
                                    || (luminance(a) == luminance(b) && std::tie(a.at, a.layer) < std::tie(b.at, b.layer));
                         });
        highlights.resize(size_t(o.max_sprites));
    }
    // A fixed order (the threads' is not), by pixel as the drawing wants.
    std::sort(highlights.begin(), highlights.end(), [](const Sprite& a, const Sprite& b) {
        return std::make_tuple(a.at, a.layer, a.coc_px, a.rgb[0], a.rgb[1], a.rgb[2])
               < std::make_tuple(b.at, b.layer, b.coc_px, b.rgb[0], b.rgb[1], b.rgb[2]);
    });
    const int w = f.data.width();
    for (Sprite& sp : highlights) {
        sp.x     = f.data.xbegin + int(sp.at % size_t(w));
        sp.y     = f.data.ybegin + int(sp.at / size_t(w));
        float* v = f.layer_rgba[size_t(sp.layer)].data() + sp.at * 4;
        for (int c = 0; c < 3; ++c)
            v[c] -= sp.rgb[c];
    }
    set->sprites = std::move(highlights);
    set->lens    = lens;
    if (!fetch_sprite_psfs(*set, *shared_psf_cache(lens, nthreads), FieldFrame(src_spec, lens), o.supersample,
                           nthreads, err))
        return false;
    set->seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    f.sprites    = std::move(set);
    return true;
}

void write_flat_plane(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Frame& f, const Plane& out, int nthreads);

// The flat result: the layers composited (pseudo-high resolution: f.out times f.up).
bool write_flat_result(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Frame& f, const Membership& m,
                       const DefocusOptions& o, float progress_from, int nthreads, std::string& err)
{
    const OIIO::ROI region = scaled_roi(f.out, f.up);
    Plane out(region.width(), region.height(), 4);
    std::fill_n(out.px.get(), out.size(), 0.0f);
    if (!composite_layers(out, f, m, o, nthreads, err, nullptr, progress_from))
        return false;
    write_flat_plane(dst, src, f, out, nthreads);
    return true;
}

// The flat result `out` (RGBA over f.out times f.up) into dst, with src's metadata.
void write_flat_plane(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Frame& f, const Plane& out, int nthreads)
{
    const OIIO::ROI region = scaled_roi(f.out, f.up);
    OIIO::ImageSpec fs = derived_spec(src.spec(), { "R", "G", "B", "A" }, region);
    scale_display_window(fs, src.spec(), f.up);
    record_lens(fs, f.lens);
    fs.deep            = false;
    fs.channelformats.clear();
    reset_uninitialised(dst, fs);
    parallel_for_chunks(0, out.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            std::copy_n(out.row(y), size_t(out.w) * 4,
                        static_cast<float*>(dst.pixeladdr(region.xbegin, region.ybegin + y)));
    });
}

// A deep frame's flat result drawn `group` layers at a time, farthest first, each group
// composited over what the farther ones left (with views, over each view's own plane):
// only `group` layers' planes are alive at once, at the price of sorting every pixel's
// pieces again for each group. Each layer is filled, blurred and laid over in the same order and with the same
// operations as when all are alive, so the pixels are the same.
bool draw_flat_in_groups(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, Frame& f, const Membership& m,
                         const DefocusOptions& o, const OIIO::DeepData& dd, const DeepChannels& ch,
                         const CocOfDepth& coc_of, bool reference, size_t group, int nthreads, std::string& err)
{
    const size_t K    = m.coc_px.size();
    const int64_t npx = dd.pixels();
    Plane out(f.out.width() * f.up, f.out.height() * f.up, 4);
    std::fill_n(out.px.get(), out.size(), 0.0f);
    // Sub-aperture views: each its own plane over all the groups, their mean at the end (as
    // composite_layers takes it with every layer alive).
    const std::vector<ApertureView> views = aperture_views(o, nthreads);
    std::vector<Plane> view_out;
    for (size_t v = 0; v < views.size() && views.size() > 1; ++v) {
        view_out.emplace_back(out.w, out.h, out.nc);
        std::fill_n(view_out.back().px.get(), view_out.back().size(), 0.0f);
    }
    const size_t groups = (K + group - 1) / group;
    for (size_t g = 0; g < groups; ++g) {
        const size_t end = K - g * group, first = end > group ? end - group : 0;
        f.layer_rgba.assign(end - first, std::vector<float>(size_t(npx) * 4, 0.0f));
        f.layer_vis.assign(end - first, std::vector<float>(size_t(npx), 1.0f));
        parallel_for_chunks(0, npx, 2048, nthreads, [&](int64_t b, int64_t e) {
            std::vector<Sprite> found;  // none: lens character is not drawn in groups
            std::vector<Piece> pieces;
            std::vector<double> cuts;
            LayerScratch scratch(K);
            for (int64_t p = b; p < e; ++p)
                if (dd.samples(p) > 0) {
                    pixel_pieces(pieces, cuts, dd, p, ch, coc_of, m, o);
                    pixel_layers(f, found, scratch, p, pieces, m, o, reference, first, end);
                }
        });
        Membership part;
        part.coc_px.assign(m.coc_px.begin() + std::ptrdiff_t(first), m.coc_px.begin() + std::ptrdiff_t(end));
        part.reduction.assign(m.reduction.begin() + std::ptrdiff_t(first), m.reduction.begin() + std::ptrdiff_t(end));
        DefocusOptions og = o;
        if (o.progress)
            og.progress = [&o, g, groups](float x) { o.progress((float(g) + x) / float(groups)); };
        if (!composite_layers(out, f, part, og, nthreads, err, nullptr, 0.0f, view_out.empty() ? nullptr : &view_out))
            return false;
    }
    f.layer_rgba.clear();
    f.layer_vis.clear();
    for (size_t v = 0; v < view_out.size(); ++v)
        add_view_share(out, view_out[v], float(views[v].share), nthreads);
    write_flat_plane(dst, src, f, out, nthreads);
    return true;
}

// The deep result: each blurred layer of a pixel one sample, a volume from its rung's depth
// to the next rung's (the last a point), kept strictly increasing so that no two layers of
// a pixel coincide (a tidy would merge them).
bool write_deep_result(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Frame& f, const Membership& m,
                       const std::vector<double>& rung_depth, const DefocusOptions& o, float progress_from,
                       int nthreads, std::string& err)
{
    const size_t K = m.coc_px.size();
    std::vector<Plane> layers;
    Plane unused(1, 1, 4);
    if (!composite_layers(unused, f, m, o, nthreads, err, &layers, progress_from))
        return false;
    std::vector<float> z0(K), z1(K);
    for (size_t k = 0; k < K; ++k) {
        z0[k] = k == 0 ? float(rung_depth[0])
                       : std::max(float(rung_depth[k]), std::nextafter(z1[k - 1], HUGE_VALF));
        z1[k] = k + 1 < K ? std::max(float(rung_depth[k + 1]), std::nextafter(z0[k], HUGE_VALF)) : z0[k];
    }
    OIIO::ImageSpec ds = derived_spec(src.spec(), { "R", "G", "B", "A", "Z", "ZBack" }, f.out);
    record_lens(ds, f.lens);
    ds.deep            = true;
    ds.z_channel       = 4;
    ds.channelformats  = std::vector<OIIO::TypeDesc>(6, OIIO::TypeFloat);
    OIIO::ImageBuf result(ds);
    OIIO::DeepData& out = *result.deepdata();
    const int w = f.out.width();
    auto shows = [](const float* v) { return v[0] != 0.0f || v[1] != 0.0f || v[2] != 0.0f || v[3] != 0.0f; };
    std::vector<unsigned int> counts(size_t(out.pixels()), 0u);
    parallel_for_chunks(0, f.out.height(), 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y)
            for (int x = 0; x < w; ++x)
                for (size_t k = 0; k < K; ++k)
                    counts[size_t(y) * size_t(w) + size_t(x)] += shows(layers[k].row(int(y)) + size_t(x) * 4);
    });
    out.set_all_samples(counts);
    if (out.pixels() > 0)
        (void)out.data_ptr(0, 0, 0);  // allocate once, before the threads write
    parallel_for_chunks(0, f.out.height(), 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int64_t y = y0; y < y1; ++y)
            for (int x = 0; x < w; ++x) {
                const int64_t p = y * w + x;
                int s           = 0;
                for (size_t k = 0; k < K; ++k) {
                    const float* v = layers[k].row(int(y)) + size_t(x) * 4;
                    if (!shows(v))
                        continue;
                    for (int c = 0; c < 4; ++c)
                        out.set_deep_value(p, c, s, v[c]);
                    out.set_deep_value(p, 4, s, z0[k]);
                    out.set_deep_value(p, 5, s, z1[k]);
                    ++s;
                }
            }
    });
    dst = std::move(result);
    return true;
}

// How many of a deep frame's K layers are alive at once. The layers' planes take 20 bytes
// a pixel a layer (RGBA and visibility), the result 32 bytes an output pixel (a flat plane
// and image) or 40 an output pixel a layer (a deep one's blurred layers and samples); the
// output is at most the display and data windows joined. A flat result without sprites
// can be drawn in groups (draw_flat_in_groups): then groups of kGroupPlanesBytes, fewer
// past the memory budget. A deep result holds every layer, sprites reach across them:
// past the budget they are refused. False + `err`.
struct LayersAlive {
    size_t at_once = 0;
    bool by_budget = false;  // fewer than kGroupPlanesBytes would hold: the budget's doing
};
bool layers_alive(LayersAlive& alive, size_t K, int64_t npx, const OIIO::ROI& data, const OIIO::ImageSpec& spec,
                  const DefocusOptions& o, std::string& err)
{
    alive.at_once        = K;
    const bool groupable = !o.deep_output && !o.lens_character;
    const OIIO::ROI out    = defocus_output_bound(spec, data, o.grow);
    const double up2       = double(o.supersample) * double(o.supersample);
    const double result    = o.deep_output ? double(K) * double(out.npixels()) * 40.0 : double(out.npixels()) * up2 * 32.0;
    const double per_layer = double(npx) * 20.0;
    if (!within_defocus_memory(o, double(K) * per_layer + result,
                               format("{} layers of {}x{} deep pixels{}", K, data.width(), data.height(),
                                      o.deep_output ? " and their deep result" : ""),
                               "fewer layers need less", err)) {
        const double fits = (double(o.memory_budget_bytes) - result) / per_layer;
        if (!groupable || fits < 1.0)
            return false;
        alive.at_once   = size_t(fits);
        alive.by_budget = true;
    }
    // Fewer layers alive are also faster: allocating and clearing the planes of them all
    // costs more than sorting each pixel's samples once a group. LowResLeftView's merged
    // passes, method=reference (137 layers, 1024x576, 2 threads): all alive 8.2 s and
    // 1.79 GB; 51 at a time 4.4 s; 25: 3.6 s; 11 (kGroupPlanesBytes): 2.75 s and 342 MB;
    // 5: 3.6 s (bokehtool -v --maxmemory N ... --deepmerge
    // --defocus:method=reference:focus=300:fstop=2:unit=cm).
    if (groupable)
        alive.at_once = std::min(alive.at_once,
                                 std::max<size_t>(kMinGroupLayers, size_t(kGroupPlanesBytes / per_layer)));
    return true;
}

// What a deep input refuses of the options (beside check_defocus_options): false + `err`.
bool check_deep_defocus_options(const DefocusOptions& o, std::string& err)
{
    if (!check_defocus_options(o, err))
        return false;
    if (o.method == DefocusMethod::Gather)
        err = "the gather method is for flat images; a deep image takes auto, layers or reference";
    else if (o.iris != 0.0f)
        err = "iris mode is not available for deep images yet; flatten first (--flatten) to use it";
    else if (o.depth_dilate_px > 0)
        err = "zdilate is a remedy for flat images' filtered depth; a deep sample has its own depth";
    else if (o.planner == DefocusPlanner::Predicted)
        err = "planner=predicted weighs a flat frame's plans; a deep image's layers come from its samples "
              "(leave the planner, or set layers= or ratio=)";
    else
        return true;
    return false;
}

// The progress shares at which the layers' planes are allocated and filled.
struct FillShares {
    float allocated, filled;
};

// Every layer's plane at once: allocated, then each pixel's pieces composited into the
// layers they fall in; lens character's highlights (each piece's sprite share, per layer
// it is drawn in) gathered into `highlights` for take_deep_sprites.
void fill_every_layer(Frame& f, std::vector<Sprite>& highlights, const OIIO::DeepData& dd, const DeepChannels& ch,
                      const CocOfDepth& coc_of, const Membership& m, const DefocusOptions& o, bool reference,
                      const FillShares& shares, int nthreads)
{
    const size_t K    = m.coc_px.size();
    const int64_t npx = dd.pixels();
    ProgressCounter alloc_progress(o.progress, double(K), 0.0f, shares.allocated);
    f.layer_rgba.resize(K);
    f.layer_vis.resize(K);
    for (size_t k = 0; k < K; ++k) {
        f.layer_rgba[k].assign(size_t(npx) * 4, 0.0f);
        f.layer_vis[k].assign(size_t(npx), 1.0f);
        alloc_progress.add();
    }
    std::mutex highlights_mutex;
    ProgressCounter fill_progress(o.progress, double((npx + 2047) / 2048), shares.allocated, shares.filled);
    parallel_for_chunks(0, npx, 2048, nthreads, [&](int64_t b, int64_t e) {
        std::vector<Sprite> found;
        std::vector<Piece> pieces;
        std::vector<double> cuts;
        LayerScratch scratch(K);
        for (int64_t p = b; p < e; ++p) {
            if (dd.samples(p) == 0)
                continue;
            pixel_pieces(pieces, cuts, dd, p, ch, coc_of, m, o);
            pixel_layers(f, found, scratch, p, pieces, m, o, reference, 0, K);
        }
        if (!found.empty()) {
            std::lock_guard<std::mutex> lock(highlights_mutex);
            highlights.insert(highlights.end(), found.begin(), found.end());
        }
        fill_progress.add();
    });
}

}  // namespace

bool detail::defocus_deep(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& o,
                          DefocusReport* report, int nthreads)
{
    std::string err;
    auto fail = [&](const std::string& why) {
        dst.errorfmt("defocus: {}", why);
        return false;
    };
    if (!check_deep_defocus_options(o, err))
        return fail(err);
    DeepOptions dopt;
    DeepRepairs repairs;
    dopt.nonfinite = o.nonfinite;
    OIIO::ImageBuf tidy, flat;
    // The repairs are the tidy's: the flatten reads the repaired samples.
    if (!deep_tidy(tidy, src, dopt, &repairs, nthreads) || !deep_flatten(flat, tidy, dopt, nullptr, nthreads))
        return fail(tidy.has_error() ? tidy.geterror() : flat.geterror());
    const OIIO::ImageSpec& spec = tidy.spec();
    DeepChannels ch;
    ch.r = spec.channelindex("R"), ch.a = spec.channelindex("A"), ch.z = spec.channelindex("Z");
    ch.g = spec.channelindex("G"), ch.b = spec.channelindex("B");
    ch.zback = spec.channelindex("ZBack");
    ch.zback = ch.zback >= 0 ? ch.zback : spec.channelindex("Zback");
    if (ch.r < 0 || ch.a < 0)
        return fail(format("a deep image to defocus needs R and A channels (has {})",
                           OIIO::Strutil::join(spec.channelnames, ",")));
    ch.g = ch.g >= 0 ? ch.g : ch.r;  // a grey image
    ch.b = ch.b >= 0 ? ch.b : ch.r;

    // The lens: focus by pixel samples the flattened depth.
    CocOptions coc = o.coc;
    if (!resolve_coc_options(coc, flat, err))
        return fail(err);
    const int width_px = spec.full_width > 0 ? spec.full_width : spec.width;
    const CocOfDepth coc_of(coc, width_px);

    DefocusReport rep;
    rep.method = o.method == DefocusMethod::Auto ? DefocusMethod::Layers : o.method;
    rep.nonfinite.colour = repairs.nonfinite;
    rep.nonfinite.depth  = repairs.nan_depth + repairs.back_before;

    const OIIO::DeepData& dd = *tidy.deepdata();
    const int64_t npx        = dd.pixels();
    DeepPlan dp;
    if (!plan_deep_layers(dp, dd, ch, coc_of, o, rep, err))
        return fail(err);
    const Membership& m        = dp.m;
    const DefocusOptions& plan = dp.options;  // the options with the planner's choices made
    const size_t K = m.coc_px.size();
    LayersAlive alive;
    if (!layers_alive(alive, K, npx, tidy.roi(), spec, o, err))
        return fail(err);
    const size_t group = alive.at_once;

    // Each layer's pixels: the pixel's pieces in it, composited front to back.
    Frame f;
    f.lens     = coc;
    f.data     = tidy.roi();
    f.img.roi  = f.data;
    f.border   = o.border;
    f.up       = o.supersample;
    // Progress in three phases, their shares of the time on LowResLeftView merged (focus
    // 3 m, f/2, 2 threads; bokehtool --progress:interval=0): the layers' planes allocated
    // (20 bytes a pixel a layer: 3.1 of the reference's 7.6 s), filled (1.1 s), blurred.
    constexpr float kAllocatedShare = 0.4f, kFilledShare = 0.55f;
    const bool reference = rep.method == DefocusMethod::Reference;
    std::string views;  // the views, and why when the planner took them
    if (plan.aperture_views > 1)
        views = format(", {0} x {0} views", plan.aperture_views);
    if (plan.aperture_views > 1 && o.aperture_views == 0)
        views += format(" ({:.0f} % of the pixels hold samples over 1 px of CoC apart)", 100.0 * dp.layered_share);
    if (group < K) {
        const float extreme = std::max(-rep.min_coc_px, rep.max_coc_px);
        f.out               = defocus_output_region(src.spec(), f.data, extreme, o);
        rep.layer_coc_px    = m.coc_px;
        rep.layer_reduction = m.reduction;
        if (!draw_flat_in_groups(dst, src, f, m, plan, dd, ch, coc_of, reference, group, nthreads, err))
            return fail(err);
        rep.summary = format("deep {}: CoC {:.1f} .. {:.1f} px, {} layers ({} at a time{}){}, output {}x{}{}",
                             method_name(rep.method), rep.min_coc_px, rep.max_coc_px, K, group,
                             alive.by_budget ? ": the memory budget" : "", views, f.out.width() * f.up,
                             f.out.height() * f.up,
                             repairs.total() ? format(", {} bad samples repaired", repairs.total()) : std::string());
        if (report)
            *report = std::move(rep);
        return true;
    }
    std::vector<double> rung_depth(K, 0.0);
    if (dp.zlo <= dp.zhi) {
        const float c_lo = coc_of(float(dp.zlo)), c_hi = coc_of(float(dp.zhi));
        for (size_t k = 0; k < K; ++k)
            rung_depth[k] = depth_of_coc(coc_of, dp.zlo, dp.zhi,
                                         std::clamp(m.coc_px[k], std::min(c_lo, c_hi), std::max(c_lo, c_hi)));
    }
    std::vector<Sprite> highlights;
    fill_every_layer(f, highlights, dd, ch, coc_of, m, o, reference, FillShares{ kAllocatedShare, kFilledShare },
                     nthreads);
    if (o.lens_character && !take_deep_sprites(f, highlights, o, spec, src.spec(), nthreads, err))
        return fail(err);
    const float sprite_extent_px = f.sprites ? f.sprites->extent_px : 0.0f;

    const float extreme = std::max({ -rep.min_coc_px, rep.max_coc_px, 2.0f * sprite_extent_px });
    f.out               = defocus_output_region(src.spec(), f.data, extreme, o);
    rep.layer_coc_px    = m.coc_px;
    rep.layer_reduction = m.reduction;
    if (!(o.deep_output ? write_deep_result(dst, src, f, m, rung_depth, o, kFilledShare, nthreads, err)
                        : write_flat_result(dst, src, f, m, plan, kFilledShare, nthreads, err)))
        return fail(err);
    report_sprites(rep, f.sprites.get());
    rep.summary = format("deep {}: CoC {:.1f} .. {:.1f} px, {} layers{}, output {}x{}{}{}{}", method_name(rep.method),
                         rep.min_coc_px, rep.max_coc_px, K, views, f.out.width() * f.up, f.out.height() * f.up,
                         o.deep_output ? ", deep" : "",
                         repairs.total() ? format(", {} bad samples repaired", repairs.total()) : std::string(),
                         sprite_summary(rep));
    if (report)
        *report = std::move(rep);
    return true;
}

}  // namespace bokeh
