// defocus.cpp — depth defocus of a flat RGBA + Z image: layered scatter with occlusion,
// its exact reference, and the dispatch to the seed 001 gather (core/defocus_gather.cpp).
//
// The layer model (ours; the idea of layers composited back to front is ZDefocus's and
// SEEDS.md section 11's). Pixels are sorted into layers by signed CoC (front to back).
// Layer k, with CoC c_k, is the blur by the aperture of diameter |c_k| of
//     numerator  [R, G, B, A] * w_k(p)               (p's share in the layer)
//     visibility 1 - A(p) * nearer_k(p)             (p's share in nearer layers, hiding k)
// and its colour and coverage are numerator / visibility. Dividing by the blurred
// visibility, not by the kernel's area, leaves out the pixels where a nearer layer hides
// this one: behind a sharp foreground the background keeps full coverage (its hidden part
// is taken as its visible surroundings), so no dark rim appears around in-focus objects,
// while a blurred foreground thins out softly over what is behind it. Layers are
// composited with "over", back to front, so an in-focus object never bleeds into the
// background's bokeh: they are in different layers.
//
// * Reference: every distinct CoC (quantised to reference_step_px) is its own layer, at
//   full resolution, with the exact anti-aliased kernel. Exact for the model; slow.
// * Layers: a scene of at most 64 distinct CoCs (0.25 px bins) gets one rung per CoC,
//   exact but for the reductions; others get a geometric ladder (0, +-1, +-r, +-r^2, ...),
//   a pixel between two rungs shared between them with weights that keep its kernel's
//   second moment (so the mixed kernel has the spread of the true one). A layer whose CoC
//   allows it is built in a buffer reduced by 2..16 (area-exact box), blurred there with
//   the exact kernel, and enlarged bilinearly as it is composited (SEEDS.md sections 4 and
//   11: large bokeh lose little at low resolution). The accuracy budget sets r and the
//   smallest reduced kernel q (settings_for_budget, from the defocus chart). Cost: layers
//   are computed in tiles, only where they hold pixels (trimmed to the pixels' reach), with
//   kernels of at most 2 q px unless at full resolution.
// * Iris mode: the layers average exp(k colour) and come back by log / k (IrisSpace).
// * Lens character (core/defocus_sprites.cpp): highlights leave the layers and are drawn
//   as the lens's PSF into the layer of their depth (composite_layers, after the layer);
//   the in-focus layer is blurred with the lens's PSF instead of the
//   aperture (by FFT, in tiles of kLensTile reduced pixels).
// * Sub-aperture views (core/defocus_views.cpp): the aperture cut into n x n cells, the
//   layers composited once a cell and the results averaged, so a blurred silhouette hides
//   what lies behind it along its own rays (one compositing multiplies whole-aperture
//   averages).
// * Gather (core/defocus_gather.cpp; SEEDS.md section 2, seed 001, as published): blurred copies of the image at a
//   few representative CoCs (4 behind focus, 3 in front; large ones in 1/2 and 1/4
//   buffers), per-pixel smoothstep blend between the two levels around its CoC, a back-
//   bokeh mask taken from the previous level, and a front-edge blur inside a widened Sobel
//   mask. Known and kept limits: in-focus colour bleeds into the first back level, front
//   silhouettes stay partly hard, nothing spreads past the data window.
//
// Known limits of the model: a flat image holds no background behind its foreground, so
// the hidden background is extrapolated from its visible neighbours (deep images remove
// this: deep.h); alpha is taken as coverage, so a semi-transparent pixel lets the layers
// behind it through.

#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus_layers.h"
#include "progress.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

// --- the image being defocused ------------------------------------------------------

// Full-resolution reach of a CoC: half the kernel, rounded up, plus one for bilinear reads.
int reach_x(float coc_px) { return int(std::ceil(0.5f * std::abs(coc_px))) + 1; }
int reach_y(float coc_px, float aspect) { return int(std::ceil(0.5f * std::abs(coc_px) * aspect)) + 1; }

// --- layers --------------------------------------------------------------------------

// Layers are computed in tiles of kTile x kTile reduced pixels, only where the layer has
// pixels within reach: sparse layers (a few lights, a thin band of floor) cost what they
// hold, not their bounding box. Tiles are independent, so they run in parallel.
constexpr int kTile = 64;
// A layer blurred with the lens's PSF goes by FFT, whose every call transforms its four
// kernels and pays a margin of the kernel's reach: its tiles are 4 times wider.
constexpr int kLensTile = 256;
// Which of a lens layer's kernels (lens_layer_kernels: R, G, B, mean) blurs each channel of
// its input (R, G, B, coverage, visibility).
constexpr std::array<int, 5> kLensChannelKernels = { 0, 1, 2, 3, 3 };

// Which tiles of each layer's grid (tile size kTile * reduction, from the output's
// origin) must be computed: those holding a share of the layer, those the border rule
// repeats them into, and their neighbours within the kernel's reach.
std::vector<std::vector<uint8_t>> layer_tiles(const Frame& f, const Membership& m, const DefocusOptions& o,
                                              const std::vector<std::vector<KernelWeights>>& lens,
                                              std::vector<int>& cols)
{
    const size_t K = m.coc_px.size();
    std::vector<std::vector<uint8_t>> tiles(K);
    std::vector<int> rows(K), size(K);
    cols.assign(K, 0);
    for (size_t k = 0; k < K; ++k) {
        size[k] = (lens[k].empty() ? kTile : kLensTile) * m.reduction[k];
        cols[k] = (f.out.width() + size[k] - 1) / size[k];
        rows[k] = (f.out.height() + size[k] - 1) / size[k];
        tiles[k].assign(size_t(cols[k]) * size_t(rows[k]), 0);
    }
    auto mark = [&](size_t k, int x0, int x1, int y) {  // pixels [x0, x1] of row y
        const int t = size[k], ty = (y - f.out.ybegin) / t;
        for (int tx = (x0 - f.out.xbegin) / t; tx <= (x1 - f.out.xbegin) / t; ++tx)
            tiles[k][size_t(ty) * size_t(cols[k]) + size_t(tx)] = 1;
    };
    for (int y = f.data.ybegin; y < f.data.yend && f.deep(); ++y)
        for (size_t k = 0; k < K; ++k) {
            const float* row = f.layer_rgba[k].data() + f.img.index(f.data.xbegin, y) * 4;
            for (int x = f.data.xbegin; x < f.data.xend; ++x, row += 4)
                if (row[0] != 0.0f || row[1] != 0.0f || row[2] != 0.0f || row[3] != 0.0f)
                    mark(k, x, x, y);
        }
    for (int y = f.data.ybegin; y < f.data.yend && !f.deep(); ++y) {
        int x = f.data.xbegin;
        while (x < f.data.xend) {  // runs of equal membership
            const size_t i  = f.img.index(x, y);
            const int lo    = m.lower[i];
            const float up  = m.upper[i];
            int e           = x + 1;
            while (e < f.data.xend && m.lower[i + size_t(e - x)] == lo
                   && (m.upper[i + size_t(e - x)] > 0.0f) == (up > 0.0f)
                   && (m.upper[i + size_t(e - x)] < 1.0f) == (up < 1.0f))
                ++e;
            if (up < 1.0f)
                mark(size_t(lo), x, e - 1, y);
            if (up > 0.0f)
                mark(size_t(lo) + 1, x, e - 1, y);
            x = e;
        }
    }
    for (size_t k = 0; k < K; ++k) {
        const int t = size[k], nx = cols[k], ny = rows[k];
        std::vector<uint8_t> held = tiles[k];
        // Tiles touching a data-window edge repeat past it (clamp, mirror) to the output's edge.
        auto tile_of_x = [&](int x) { return std::clamp((x - f.out.xbegin) / t, 0, nx - 1); };
        auto tile_of_y = [&](int y) { return std::clamp((y - f.out.ybegin) / t, 0, ny - 1); };
        if (o.border != Border::Black) {
            const int ex0 = tile_of_x(f.data.xbegin), ex1 = tile_of_x(f.data.xend - 1);
            const int ey0 = tile_of_y(f.data.ybegin), ey1 = tile_of_y(f.data.yend - 1);
            const std::vector<uint8_t> inside = held;
            for (int ty = 0; ty < ny; ++ty)
                for (int tx = 0; tx < nx; ++tx) {
                    if (!inside[size_t(ty) * size_t(nx) + size_t(tx)])
                        continue;
                    const int x0 = tx == ex0 ? 0 : tx, x1 = tx == ex1 ? nx - 1 : tx;
                    const int y0 = ty == ey0 ? 0 : ty, y1 = ty == ey1 ? ny - 1 : ty;
                    for (int j = y0; j <= y1; ++j)
                        for (int i2 = x0; i2 <= x1; ++i2)
                            held[size_t(j) * size_t(nx) + size_t(i2)] = 1;
                }
        }
        // Neighbours within reach of a held tile.
        const float c = m.coc_px[k];
        int reach_px = reach_x(c), reach_py = reach_y(c, o.aspect);
        if (!lens[k].empty()) {  // the lens's aberrations reach past the CoC
            reach_px = std::max(reach_px, (lens[k][0].rx + 2) * m.reduction[k]);
            reach_py = std::max(reach_py, (lens[k][0].ry + 2) * m.reduction[k]);
        }
        const int rx = (reach_px + t - 1) / t, ry = (reach_py + t - 1) / t;
        for (int ty = 0; ty < ny; ++ty)
            for (int tx = 0; tx < nx; ++tx) {
                uint8_t any = 0;
                for (int j = std::max(0, ty - ry); j <= std::min(ny - 1, ty + ry) && !any; ++j)
                    for (int i2 = std::max(0, tx - rx); i2 <= std::min(nx - 1, tx + rx); ++i2)
                        if (held[size_t(j) * size_t(nx) + size_t(i2)]) {
                            any = 1;
                            break;
                        }
                tiles[k][size_t(ty) * size_t(nx) + size_t(tx)] = any;
            }
    }
    return tiles;
}

// Layer k's share and the visibility it needs at full-resolution pixel `at`.
struct LayerPixel {
    float share, nearer;
};
inline LayerPixel layer_pixel(const Frame& f, const Membership& m, int k, size_t at)
{
    if (f.deep()) {  // the layer's own pixels: known, hidden by nothing that is not drawn
        const float* v = f.layer_rgba[size_t(k)].data() + at * 4;
        return { (v[0] != 0.0f || v[1] != 0.0f || v[2] != 0.0f || v[3] != 0.0f) ? 1.0f : 0.0f, 0.0f };
    }
    const int lo    = m.lower[at];
    const float up  = m.upper[at];
    return { lo == k ? 1.0f - up : lo + 1 == k ? up : 0.0f,
             lo + 1 < k ? 1.0f : lo + 1 == k ? 1.0f - up : 0.0f };
}

// The data-window column that stands for each full-resolution column under the reduced
// pixels `low` (grid origin gx, reduction s), by the border rule (kOutside: empty).
std::vector<int> source_columns(const Frame& f, const OIIO::ROI& low, int gx, int s)
{
    const int x_first = gx + low.xbegin * s;
    std::vector<int> sx(size_t(low.width()) * size_t(s));
    for (size_t i = 0; i < sx.size(); ++i)
        sx[i] = border_index(x_first + int(i), f.data.xbegin, f.data.xend, f.border);
    return sx;
}

// What a tile of layer k holds over reduced pixels `low` (grid origin gx, gy; reduction
// s): the reduced pixels with a share of the layer (empty when none), and whether a
// nearer layer hides any of it.
struct TileContent {
    OIIO::ROI held;
    bool hidden = false;
};
TileContent tile_content(const Frame& f, const Membership& m, int k, const OIIO::ROI& low, int gx,
                         int gy, int s)
{
    TileContent t;
    t.held = OIIO::ROI(low.xend, low.xbegin, low.yend, low.ybegin);  // empty; grows below
    const std::vector<int> sx = source_columns(f, low, gx, s);
    for (int j = low.ybegin; j < low.yend; ++j)
        for (int y = gy + j * s; y < gy + (j + 1) * s; ++y) {
            const int sy = border_index(y, f.data.ybegin, f.data.yend, f.border);
            if (sy == kOutside)
                continue;
            const size_t row = f.img.index(f.data.xbegin, sy) - size_t(f.data.xbegin);
            int first = -1, last = -1;  // columns (into sx) holding a share
            for (size_t i = 0; i < sx.size(); ++i) {
                if (sx[i] == kOutside)
                    continue;
                const size_t at    = row + size_t(sx[i]);
                const LayerPixel p = layer_pixel(f, m, k, at);
                t.hidden           = t.hidden || (f.deep() ? f.layer_vis[size_t(k)][at] < 1.0f
                                                               : p.nearer * f.img.rgba[at * 4 + 3] > 0.0f);
                if (p.share > 0.0f) {
                    first = first < 0 ? int(i) : first;
                    last  = int(i);
                }
            }
            if (first >= 0) {
                t.held.xbegin = std::min(t.held.xbegin, low.xbegin + first / s);
                t.held.xend   = std::max(t.held.xend, low.xbegin + last / s + 1);
                t.held.ybegin = std::min(t.held.ybegin, j);
                t.held.yend   = std::max(t.held.yend, j + 1);
            }
        }
    return t;
}

// Layer k's input over reduced pixels `low` (grid origin gx, gy; reduction s): the mean
// of [R, G, B, A] * share over each s x s block and, when `with_visibility`, of the
// visibility 1 - A * nearer (channel 4). Without it the visibility is 1 everywhere.
Plane layer_input(const Frame& f, const Membership& m, int k, const OIIO::ROI& low, int gx,
                  int gy, int s, bool with_visibility)
{
    const int nc = with_visibility ? 5 : 4;
    Plane p(low.width(), low.height(), nc);
    std::fill_n(p.px.get(), p.size(), 0.0f);
    const std::vector<int> sx = source_columns(f, low, gx, s);
    const float inv = 1.0f / float(s * s);
    for (int j = 0; j < p.h; ++j) {
        float* row = p.row(j);
        for (int y = gy + (low.ybegin + j) * s; y < gy + (low.ybegin + j + 1) * s; ++y) {
            const int sy = border_index(y, f.data.ybegin, f.data.yend, f.border);
            for (size_t i = 0; i < sx.size(); ++i) {
                float* v = row + (i / size_t(s)) * size_t(nc);
                if (sy == kOutside || sx[i] == kOutside) {
                    if (with_visibility)
                        v[4] += 1.0f;  // empty: seen through, hides nothing
                    continue;
                }
                const size_t at    = f.img.index(sx[i], sy);
                const LayerPixel q = layer_pixel(f, m, k, at);
                const float* px    = f.deep() ? f.layer_rgba[size_t(k)].data() + at * 4 : f.img.rgba.data() + at * 4;
                if (q.share > 0.0f)
                    for (int c = 0; c < 4; ++c)
                        v[c] += px[c] * q.share;
                if (with_visibility)
                    v[4] += f.deep() ? f.layer_vis[size_t(k)][at] : 1.0f - px[3] * q.nearer;
            }
        }
        if (s > 1)
            for (int i = 0; i < p.w * nc; ++i)
                row[i] *= inv;
    }
    return p;
}

// Iris-space colour (4 or more channels, premultiplied) back to linear, in place.
void from_iris_space(Plane& p, const IrisSpace& iris)
{
    if (iris.k == 0.0f)
        return;
    const size_t nc = size_t(p.nc);
    for (int j = 0; j < p.h; ++j) {
        float* px = p.row(j);
        for (int i = 0; i < p.w; ++i, px += nc) {
            const float a = px[3];
            for (int c = 0; c < 3; ++c)
                // exp-space colour / coverage is >= 0 up to rounding.
                px[c] = a > 0.0f ? a * float(iris.shift[size_t(c)]
                                             + std::log1p(std::max(double(px[c]) / a, 0.0)) / iris.k)
                                 : 0.0f;
        }
    }
}

}  // namespace

// The aperture at diameter |coc_px| / s (and the aspect), as exact weights. In front of
// focus the rays reach the sensor before they cross, behind it after: the two bokeh are
// the aperture and its point reflection, which shows with an odd number of blades.
KernelWeights detail::aperture_weights(const DefocusOptions& o, float coc_px, int s, int nthreads)
{
    Kernel k = o.aperture;
    if (coc_px < 0.0f)
        k.rotation_deg += 180.0f;
    k.width_px  = std::abs(coc_px) / float(s);
    k.height_px = std::abs(coc_px) * o.aspect / float(s);
    return kernel_weights(k, nthreads);
}

// Colour and coverage over visibility (channel 4), in place.
void detail::divide_by_visibility(Plane& p)
{
    for (int j = 0; j < p.h; ++j) {
        float* px = p.row(j);
        for (int i = 0; i < p.w; ++i, px += 5) {
            const float inv = px[4] > 1e-6f ? 1.0f / px[4] : 0.0f;
            for (int c = 0; c < 4; ++c)
                px[c] *= inv;
        }
    }
}

bool detail::composite_layers(Plane& out, const Frame& f, const Membership& m, const DefocusOptions& o,
                              int nthreads, std::string& err, std::vector<Plane>* per_layer, float progress_from)
{
    if (per_layer) {
        per_layer->clear();
        for (size_t k = 0; k < m.coc_px.size(); ++k) {
            per_layer->emplace_back(f.out.width(), f.out.height(), 4);
            std::fill_n(per_layer->back().px.get(), per_layer->back().size(), 0.0f);
        }
    }
    std::vector<std::vector<KernelWeights>> lens(m.coc_px.size());
    if (f.sprites && !lens_layer_kernels(lens, f, m, nthreads, err))
        return false;
    std::vector<int> cols;
    const std::vector<std::vector<uint8_t>> tiles = layer_tiles(f, m, o, lens, cols);
    const int gx = f.out.xbegin, gy = f.out.ybegin;
    const int up = f.up;  // `out` is over f.out scaled by up (per-layer planes: up is 1)
    // Progress by tiles, each weighted by its kernel's rows plus its own (a tile's spans
    // grow with the kernel's height in reduced pixels).
    auto tile_weight = [&](size_t k) { return 2.0 + std::abs(m.coc_px[k]) / float(m.reduction[k]); };
    double all_tiles = 0.0;
    for (size_t k = 0; k < tiles.size() && o.progress; ++k)
        all_tiles += tile_weight(k)
                     * double(std::count_if(tiles[k].begin(), tiles[k].end(), [](uint8_t t) { return t != 0; }));
    // Sub-aperture views: each composites the layers over its own copy of `out`, and
    // `out` becomes their mean weighted by their shares ("over" is linear in what it is
    // laid on). The aperture's kernels are made once a layer and cut per view.
    const std::vector<ApertureView> views = per_layer ? std::vector<ApertureView>{ ApertureView{} }
                                                      : aperture_views(o, nthreads);
    ProgressCounter progress(o.progress, all_tiles * double(views.size()), progress_from);
    // With one view each layer's kernel is made as its turn comes (a reference of
    // thousands of layers would otherwise hold them all).
    std::vector<KernelWeights> full(views.size() > 1 ? m.coc_px.size() : 0);
    for (size_t k = 0; k < full.size(); ++k)
        if (lens[k].empty())
            full[k] = aperture_weights(o, m.coc_px[k], m.reduction[k], nthreads);
    Plane under(1, 1, 4), mean(1, 1, 4);
    if (views.size() > 1) {
        under = Plane(out.w, out.h, out.nc);
        std::copy_n(out.px.get(), out.size(), under.px.get());
        mean = Plane(out.w, out.h, out.nc);
        std::fill_n(mean.px.get(), mean.size(), 0.0f);
    }
    // What each tile of a layer holds does not depend on the view (a view's kernel keeps
    // the whole aperture's extent): found in the first view, read in the others.
    std::vector<std::vector<TileContent>> contents(m.coc_px.size());
    for (const ApertureView& view : views) {
        const bool first_view = &view == &views.front();
        if (views.size() > 1)
            std::copy_n(under.px.get(), under.size(), out.px.get());
        for (int k = int(m.coc_px.size()) - 1; k >= 0; --k) {
            const float c = m.coc_px[size_t(k)];
            const std::vector<KernelWeights>& lens_kernels = lens[size_t(k)];
            const int cells       = lens_kernels.empty() ? kTile : kLensTile;
            const int s           = m.reduction[size_t(k)], t = cells * s;
            const KernelWeights w = !lens_kernels.empty() ? lens_kernels[3]
                                    : full.empty()        ? aperture_weights(o, c, s, nthreads)
                                                          : view_kernel(full[size_t(k)], view, c, o.aspect, s);
            std::vector<int> todo;
            for (size_t i = 0; i < tiles[size_t(k)].size(); ++i)
                if (tiles[size_t(k)][i])
                    todo.push_back(int(i));
            if (first_view)
                contents[size_t(k)].resize(tiles[size_t(k)].size());
            const double weight = tile_weight(size_t(k));
            // Lens character on a flat frame: the layer's sprites are divided by its visibility
            // as its colour is (a deep frame's layers are continued only under the same
            // surface, composite_layers' deep visibility; its sprites are not).
            SpriteGain gain;
            if (f.sprites && !f.deep() && layer_has_sprites(f, m, k)) {
                gain.used    = true;
                gain.gx      = gx;
                gain.gy      = gy;
                gain.tile_px = t;
                gain.cols    = cols[size_t(k)];
                gain.s       = s;
                gain.draw.resize(tiles[size_t(k)].size());
                gain.low.resize(tiles[size_t(k)].size());
                gain.visibility.resize(tiles[size_t(k)].size());
            }
            parallel_for_chunks(0, int64_t(todo.size()), 1, nthreads, [&](int64_t n, int64_t) {
                struct Counted {  // the tile counts as done however it returns
                    ProgressCounter& p;
                    double units;
                    ~Counted() { p.add(units); }
                } counted{ progress, weight };
                const int tx = todo[size_t(n)] % cols[size_t(k)], ty = todo[size_t(n)] / cols[size_t(k)];
                const OIIO::ROI region = OIIO::roi_intersection(
                    OIIO::ROI(gx + tx * t, gx + (tx + 1) * t, gy + ty * t, gy + (ty + 1) * t), f.out);
                // The tile's reduced pixels, one more each side for bilinear reads.
                const OIIO::ROI low(tx * cells - 1, floor_div(region.xend - 1 - gx, s) + 2,
                                    ty * cells - 1, floor_div(region.yend - 1 - gy, s) + 2);
                // Only where the layer's pixels reach: past its pixels' bounding box grown by
                // the kernel the layer is exactly 0 (so compositing it changes nothing). One
                // reduced pixel more keeps the bilinear reads at the edge exact.
                TileContent& known = contents[size_t(k)][size_t(todo[size_t(n)])];
                if (first_view)
                    known = tile_content(f, m, k, grown(low, w.rx, w.ry), gx, gy, s);
                const TileContent content = known;
                if (content.held.xbegin >= content.held.xend)
                    return;
                const OIIO::ROI need = OIIO::roi_intersection(grown(content.held, w.rx + 1, w.ry + 1), low);
                if (need.xbegin >= need.xend || need.ybegin >= need.yend)
                    return;
                // Full-resolution pixels whose bilinear taps lie in `need` (the others read
                // only zeros), or all of the region's where `need` is the tile's edge.
                auto first_px = [&](int lo, int g, int r0) { return lo == r0 ? std::numeric_limits<int>::min() : g + lo * s + s / 2; };
                auto end_px   = [&](int hi, int g, int r1) { return hi == r1 ? std::numeric_limits<int>::max() : g + (hi - 1) * s + s / 2 + 1; };
                const OIIO::ROI draw = OIIO::roi_intersection(
                    OIIO::ROI(first_px(need.xbegin, gx, low.xbegin), end_px(need.xend, gx, low.xend),
                              first_px(need.ybegin, gy, low.ybegin), end_px(need.yend, gy, low.yend)),
                    region);
                if (draw.xbegin >= draw.xend || draw.ybegin >= draw.yend)
                    return;
                Plane p     = layer_input(f, m, k, grown(need, w.rx, w.ry), gx, gy, s, content.hidden);
                Plane layer;
                if (w.is_identity())
                    layer = std::move(p);
                else if (lens_kernels.empty())
                    layer = convolve_spans(p, w, 1);
                else {  // R, G and B each with its own PSF; coverage (and visibility, when hidden) their mean
                    const std::vector<int> kernel_of(kLensChannelKernels.begin(), kLensChannelKernels.begin() + p.nc);
                    layer = convolve_fft(p, lens_kernels, kernel_of, 1);
                }
                if (content.hidden)
                    divide_by_visibility(layer);
                if (content.hidden && gain.used) {  // the visibility (channel 4), kept for the sprites
                    const size_t i = size_t(todo[size_t(n)]);
                    gain.draw[i]   = draw;
                    gain.low[i]    = need;
                    Plane& v       = gain.visibility[i];
                    v              = Plane(layer.w, layer.h, 1);
                    for (int y = 0; y < layer.h; ++y)
                        for (int x = 0; x < layer.w; ++x)
                            v.row(y)[x] = layer.row(y)[size_t(x) * size_t(layer.nc) + 4];
                }
                from_iris_space(layer, f.iris);
                Plane& target = per_layer ? (*per_layer)[size_t(k)] : out;
                if (up == 1) {
                    for (int y = draw.ybegin; y < draw.yend; ++y) {
                        float* dst = target.row(y - gy) + size_t(draw.xbegin - gx) * 4;
                        for (int x = draw.xbegin; x < draw.xend; ++x, dst += 4) {
                            float l[4];
                            sample(layer, need, gx, gy, s, x, y, l);
                            const float behind = 1.0f - l[3];
                            for (int c4 = 0; c4 < 4; ++c4)
                                dst[c4] = l[c4] + behind * dst[c4];
                        }
                    }
                    return;
                }
                // Pseudo-high resolution: the up x up output pixels of each pixel, each its own
                // bilinear read (the layer is zero past `need`'s margin, so `draw` still holds
                // every output pixel the layer touches).
                for (int y = draw.ybegin; y < draw.yend; ++y)
                    for (int sy = 0; sy < up; ++sy) {
                        float* dst = target.row((y - gy) * up + sy) + size_t(draw.xbegin - gx) * size_t(up) * 4;
                        for (int x = draw.xbegin; x < draw.xend; ++x)
                            for (int sx = 0; sx < up; ++sx, dst += 4) {
                                float l[4];
                                sample_sub(layer, need, gx, gy, s, x, y, up, sx, sy, l);
                                const float behind = 1.0f - l[3];
                                for (int c4 = 0; c4 < 4; ++c4)
                                    dst[c4] = l[c4] + behind * dst[c4];
                            }
                    }
            });
            // Lens character: the layer's highlights, before any nearer layer hides them.
            if (f.sprites)
                draw_layer_sprites(per_layer ? (*per_layer)[size_t(k)] : out, f, m, k, nthreads, &gain,
                                   first_view);
        }
        if (views.size() > 1) {
            const float share = float(view.share);
            parallel_for_chunks(0, int64_t(out.size()), 1 << 16, nthreads, [&](int64_t b, int64_t e) {
                for (int64_t i = b; i < e; ++i)
                    mean.px[size_t(i)] += share * out.px[size_t(i)];
            });
        }
    }
    if (views.size() > 1)
        std::copy_n(mean.px.get(), mean.size(), out.px.get());
    return true;
}

namespace {

// The layered method's CoC ladder over [lo, hi]: 0, then +-1, +-r, +-r^2 ... on each side
// up to the extreme, the last rung moved onto the extreme so it gets its exact kernel.
std::vector<float> coc_ladder(float lo, float hi, double ratio)
{
    std::vector<float> rungs = { 0.0f };
    for (int side = -1; side <= 1; side += 2) {
        const float extreme = side < 0 ? -lo : hi;
        if (extreme <= 0.0f)
            continue;
        for (double r = 1.0;; r *= ratio) {
            if (r >= extreme * 0.999) {
                rungs.push_back(float(side) * extreme);
                break;
            }
            rungs.push_back(float(side * r));
        }
    }
    std::sort(rungs.begin(), rungs.end());
    return rungs;
}

// Shares of every pixel in the ladder `rungs` (share_between).
Membership share_between_rungs(const Frame& f, std::vector<float> rungs, int nthreads)
{
    Membership m;
    m.coc_px = std::move(rungs);
    m.lower.resize(f.coc.size());
    m.upper.resize(f.coc.size());
    parallel_for_chunks(0, int64_t(f.coc.size()), 4096, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i)
            share_between(f.coc[size_t(i)], m.coc_px, m.lower[size_t(i)], m.upper[size_t(i)]);
    });
    return m;
}

constexpr float kRungStep_px   = 0.25f;  // CoCs closer than this count as one
constexpr size_t kMaxExactRungs = 64;

// The frame's CoCs in bins `step` wide: each occupied bin's mean CoC (ascending), and
// every pixel's bin among them. A bin holding one CoC value has it exactly.
struct CocBins {
    std::vector<float> mean_px;
    std::vector<uint32_t> of_pixel;
};
CocBins coc_bins(const std::vector<float>& cocs, float lo, float hi, float step)
{
    const int64_t first = int64_t(std::floor(lo / step)), last = int64_t(std::floor(hi / step));
    const size_t n = size_t(last - first + 1);
    std::vector<double> sum(n, 0.0);
    std::vector<int64_t> count(n, 0);
    auto bin = [&](float c) { return size_t(std::clamp(int64_t(std::floor(c / step)) - first, int64_t(0), int64_t(n) - 1)); };
    for (float c : cocs) {
        const size_t b = bin(c);
        sum[b] += c;
        ++count[b];
    }
    CocBins r;
    std::vector<uint32_t> index(n, 0);
    for (size_t b = 0; b < n; ++b)
        if (count[b]) {
            index[b] = uint32_t(r.mean_px.size());
            r.mean_px.push_back(float(sum[b] / double(count[b])));
        }
    r.of_pixel.resize(cocs.size());
    for (size_t i = 0; i < cocs.size(); ++i)
        r.of_pixel[i] = index[bin(cocs[i])];
    return r;
}

// The reference's layers: one per occupied CoC bin `step` wide, at the bin's mean CoC
// (exact when a bin holds one value, as in scenes of few depths).
Membership one_layer_per_coc(const Frame& f, float lo, float hi, float step)
{
    CocBins bins = coc_bins(f.coc, lo, hi, step);
    Membership m;
    m.coc_px = std::move(bins.mean_px);
    m.reduction.assign(m.coc_px.size(), 1);
    m.lower.assign(bins.of_pixel.begin(), bins.of_pixel.end());
    m.upper.assign(f.coc.size(), 0.0f);
    return m;
}

// Layer settings an accuracy budget asks for: the ladder's ratio r and the smallest reduced
// kernel diameter q. From the defocus chart (docs/benchmarks.md), the coarsest settings at
// which every synthetic scene meets the budget: the ladder's spacing sets the error of
// scenes of continuous depth (lights), q that of hard bokeh and silhouette edges in
// reduced buffers (edges, giant: q = 16 gave 41.6 and 35.5 dB, q = 24 gives 92.8 and 42.0).
struct LayerSettings {
    double ratio;
    float min_reduced_coc_px;
};
LayerSettings settings_for_budget(float budget_db)
{
    if (budget_db <= 30.0f) return { 2.0, 12.0f };
    if (budget_db <= 40.0f) return { 1.5, 24.0f };
    if (budget_db <= 50.0f) return { 1.125, 64.0f };
    return { 1.0625, 96.0f };
}

// The reduction for a layer of CoC c: the largest power of two s <= max_reduction that
// leaves a kernel of at least q reduced pixels.
int reduction_for(float c, float q, int max_reduction)
{
    int s = 1;
    while (s * 2 <= max_reduction && std::abs(c) / float(s * 2) >= q)
        s *= 2;
    return s;
}

// The smallest reduced kernel diameter: the user's, or the budget's.
float min_reduced_coc_px(const DefocusOptions& o)
{
    return o.min_reduced_coc_px > 0.0f ? o.min_reduced_coc_px
                                       : settings_for_budget(o.budget_db).min_reduced_coc_px;
}

Membership layer_plan(const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads)
{
    Membership m = share_between_rungs(f, layer_rungs(f.coc, o, lo, hi), nthreads);
    m.reduction  = layer_reductions(m.coc_px, o);
    return m;
}

// What the layers leave transparent where the source is opaque is background that a
// flat image never held: behind a blurred foreground's fringe over a sharp background (the
// sharp background's kernel cannot reach in from its visible neighbours). It is filled
// with the source pixel itself, up to the source's coverage: the foreground stands in for
// the unknown background, which keeps an opaque image opaque (a deep image has the real
// background: deep.h).
void fill_disocclusions(Plane& out, const Frame& f, float farthest, int nthreads)
{
    parallel_for_chunks(0, out.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* d = out.row(y);
            for (int x = 0; x < out.w; ++x, d += 4) {
                const int64_t i = f.source(f.out.xbegin + x / f.up, f.out.ybegin + y / f.up);
                // Only pixels with something behind them in depth can have lost it.
                if (i < 0 || f.coc[size_t(i)] >= farthest)
                    continue;
                const float* px = f.linear().data() + size_t(i) * 4;
                if (px[3] <= d[3])
                    continue;
                // Only the coverage the source had and the layers lost.
                const float w = (px[3] - d[3]) / px[3];
                for (int c = 0; c < 4; ++c)
                    d[c] += w * px[c];
            }
        }
    });
}

// --- preparation ---------------------------------------------------------------------

void apply_bloom(WorkImage& w, float threshold, float gain, int nthreads)
{
    parallel_for_chunks(0, int64_t(w.rgba.size() / 4), 4096, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i) {
            float* p = w.rgba.data() + size_t(i) * 4;
            if (p[3] <= 0.0f)
                continue;
            for (int c = 0; c < 3; ++c) {
                const float x = p[c] / p[3];  // unpremultiplied
                if (x > threshold)
                    p[c] = (x + (gain - 1.0f) * (x - threshold)) * p[3];
            }
        }
    });
}

// Iris mode: f.img's colour into iris space (see IrisSpace), the linear copy kept for the
// disocclusion fill. False + err when |k| times a channel's range exceeds kIrisMaxExponent.
bool to_iris_space(Frame& f, float k, int nthreads, std::string& err)
{
    std::array<float, 3> lo, hi;
    lo.fill(std::numeric_limits<float>::infinity());
    hi.fill(-std::numeric_limits<float>::infinity());
    for (size_t i = 0; i < f.img.rgba.size(); i += 4)
        if (f.img.rgba[i + 3] > 0.0f)
            for (size_t c = 0; c < 3; ++c) {
                const float x = f.img.rgba[i + c] / f.img.rgba[i + 3];
                lo[c]         = std::min(lo[c], x);
                hi[c]         = std::max(hi[c], x);
            }
    f.iris.k = k;
    for (size_t c = 0; c < 3; ++c) {
        if (!(hi[c] >= lo[c]))
            lo[c] = hi[c] = 0.0f;  // no covered pixel
        if (std::abs(double(k)) * (double(hi[c]) - double(lo[c])) > kIrisMaxExponent) {
            err = format("iris {} times channel {}'s range {} .. {} exceeds {}: exp() would span "
                         "more digits than the sums keep; lower iris",
                         k, "RGB"[c], lo[c], hi[c], kIrisMaxExponent);
            return false;
        }
        f.iris.shift[c] = k > 0.0f ? lo[c] : hi[c];
    }
    f.linear_rgba = f.img.rgba;
    parallel_for_chunks(0, int64_t(f.img.rgba.size() / 4), 4096, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i) {
            float* p = f.img.rgba.data() + size_t(i) * 4;
            for (size_t c = 0; c < 3; ++c)
                p[c] = p[3] > 0.0f ? p[3] * float(std::expm1(double(k) * (double(p[c]) / p[3] - f.iris.shift[c])))
                                   : 0.0f;
        }
    });
    return true;
}

// Each pixel takes the nearest (smallest signed) CoC within `r` px: a separable min filter.
void dilate_nearest(std::vector<float>& coc, int w, int h, int r, int nthreads)
{
    std::vector<float> tmp(coc.size());
    parallel_for_chunks(0, h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = 0; x < w; ++x) {
                float m = coc[size_t(y) * size_t(w) + size_t(x)];
                for (int i = std::max(0, x - r); i <= std::min(w - 1, x + r); ++i)
                    m = std::min(m, coc[size_t(y) * size_t(w) + size_t(i)]);
                tmp[size_t(y) * size_t(w) + size_t(x)] = m;
            }
    });
    parallel_for_chunks(0, h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = 0; x < w; ++x) {
                float m = tmp[size_t(y) * size_t(w) + size_t(x)];
                for (int j = std::max(0, y - r); j <= std::min(h - 1, y + r); ++j)
                    m = std::min(m, tmp[size_t(j) * size_t(w) + size_t(x)]);
                coc[size_t(y) * size_t(w) + size_t(x)] = m;
            }
    });
}

}  // namespace

bool detail::check_defocus_options(const DefocusOptions& o, std::string& err)
{
    if (!validate_aperture(o.aperture, o.aspect, err))
        return false;
    if (o.layers < 0 || o.layers > 1024) {
        err = format("layers {} is outside 0..1024 (0: automatic)", o.layers);
        return false;
    }
    // Any bound 1..16: the buffers are powers of two, the largest up to it (reduction_for).
    if (o.max_reduction < 1 || o.max_reduction > 16) {
        err = format("max reduction {} is outside 1..16", o.max_reduction);
        return false;
    }
    if (!(o.min_reduced_coc_px >= 0.0f && o.min_reduced_coc_px <= 256.0f)) {
        err = format("minimum reduced CoC {} is outside 0..256", o.min_reduced_coc_px);
        return false;
    }
    if (!(o.budget_db > 0.0f && o.budget_db <= 120.0f)) {
        err = format("budget {} dB is outside 0..120", o.budget_db);
        return false;
    }
    if (!std::isfinite(o.bloom_threshold) || !(o.bloom_gain >= 0.0f && o.bloom_gain <= 1e4f)) {
        err = format("bloom threshold {} / gain {}: finite, gain 0..10000", o.bloom_threshold,
                     o.bloom_gain);
        return false;
    }
    if (!(std::abs(o.iris) <= 1000.0f)) {
        err = format("iris {} is outside -1000..1000", o.iris);
        return false;
    }
    if (o.depth_dilate_px < 0 || o.depth_dilate_px > 64) {
        err = format("depth dilation {} px is outside 0..64", o.depth_dilate_px);
        return false;
    }
    if (!(o.reference_step_px >= 1.0f / 64.0f && o.reference_step_px <= 8.0f)) {
        err = format("reference step {} px is outside 1/64..8", o.reference_step_px);
        return false;
    }
    if (o.supersample != 1 && o.supersample != 2) {
        err = format("supersample {} is not 1 or 2", o.supersample);
        return false;
    }
    if (o.supersample > 1 && o.method == DefocusMethod::Gather) {
        err = "supersample enlarges layers as they are composited; the gather method has none (use "
              "method=layers, auto or reference)";
        return false;
    }
    if (o.aperture_views < 1 || o.aperture_views > 8) {
        err = format("views {} is outside 1..8", o.aperture_views);
        return false;
    }
    if (o.aperture_views > 1 && o.aperture.shape != KernelShape::Disk && o.aperture.shape != KernelShape::Polygon
        && o.aperture.shape != KernelShape::Box) {
        err = "views cut the pupil of a disk, polygon or box aperture; this one has no pupil edge to cut within";
        return false;
    }
    if (o.aperture_views > 1 && o.method == DefocusMethod::Gather) {
        err = "views cut the aperture for the layers' compositing; the gather method has no layers (use "
              "method=layers, auto or reference)";
        return false;
    }
    if (o.aperture_views > 1 && o.deep_output) {
        err = "views average flat compositings; a deep result keeps one sample a layer (use output=image)";
        return false;
    }
    if (o.supersample > 1 && o.deep_output) {
        err = "supersample gives a flat image; a deep result is not supersampled";
        return false;
    }
    return check_sprite_options(o, err);
}

namespace {

// Everything but the method: the scrubbed, premultiplied pixels, their CoC, the regions.
bool prepare(Frame& f, const OIIO::ImageBuf& src, const DefocusOptions& o, DefocusReport& rep,
             int nthreads, std::string& err)
{
    if (!check_defocus_options(o, err))
        return false;
    if (src.deep()) {
        err = "a deep image cannot be defocused here; flatten it first (--flatten)";
        return false;
    }
    CocOptions coc = o.coc;
    if (!resolve_coc_options(coc, src, err) || !to_work_image(f.img, src, nthreads, err))
        return false;
    f.lens = coc;
    // The bad-value policy (DESIGN.md): colour -> 0, depth -> far ("no depth"), counted.
    using Counts  = std::array<int64_t, 2>;
    const int64_t npx = int64_t(f.img.z.size());
    const Counts bad  = parallel_reduce_chunks(
        0, npx, 1 << 14, nthreads, Counts{ 0, 0 },
        [&](int64_t b, int64_t e) {
            Counts n{ 0, 0 };
            for (int64_t i = b; i < e; ++i) {
                float* px = f.img.rgba.data() + size_t(i) * 4;
                for (int c = 0; c < 4; ++c)
                    if (!std::isfinite(px[c])) {
                        px[c] = 0.0f;
                        ++n[0];
                    }
                const float z = f.img.z[size_t(i)];
                n[1] += std::isnan(z) || z == -std::numeric_limits<float>::infinity();
            }
            return n;
        },
        [](Counts& a, const Counts& p) {
            a[0] += p[0];
            a[1] += p[1];
        });
    rep.nonfinite.colour = bad[0];
    rep.nonfinite.depth  = bad[1];
    if (o.nonfinite == NonFinitePolicy::Error && bad[0] + bad[1] > 0) {
        err = format("{} non-finite colour and {} non-finite depth values (nonfinite=error)",
                     bad[0], bad[1]);
        return false;
    }
    const int width_px = src.spec().full_width > 0 ? src.spec().full_width : f.img.width();
    const CocOfDepth coc_of(coc, width_px);
    f.coc.resize(size_t(npx));
    parallel_for_chunks(0, npx, 1 << 14, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i)
            f.coc[size_t(i)] = coc_of(f.img.z[size_t(i)]);
    });
    f.data   = f.img.roi;
    f.border = o.border;
    f.up     = o.supersample;
    if (o.depth_dilate_px > 0)
        dilate_nearest(f.coc, f.data.width(), f.data.height(), o.depth_dilate_px, nthreads);
    if (o.bloom_gain != 1.0f)
        apply_bloom(f.img, o.bloom_threshold, o.bloom_gain, nthreads);
    // Highlights leave the layers in linear light (before iris mode's exp space).
    if (o.lens_character && !select_sprites(f, o, src.spec(), nthreads, err))
        return false;
    if (o.iris != 0.0f && !to_iris_space(f, o.iris, nthreads, err))
        return false;

    const auto [lo, hi] = std::minmax_element(f.coc.begin(), f.coc.end());
    rep.min_coc_px      = f.coc.empty() ? 0.0f : *lo;
    rep.max_coc_px      = f.coc.empty() ? 0.0f : *hi;
    // Sprites spread as far as their PSFs (aberrations can reach past the CoC).
    const float extreme = std::max({ -rep.min_coc_px, rep.max_coc_px,
                                     f.sprites ? 2.0f * f.sprites->extent_px : 0.0f });
    f.out               = defocus_output_region(src.spec(), f.data, extreme, o);
    return true;
}

}  // namespace

void detail::share_between(float c, const std::vector<float>& r, uint16_t& lower, float& upper)
{
    c        = std::clamp(c, r.front(), r.back());
    size_t j = size_t(std::upper_bound(r.begin(), r.end(), c) - r.begin());
    j        = j == 0 ? 0 : std::min(j - 1, r.size() - 1);
    float u  = 0.0f;
    if (j + 1 < r.size()) {
        const double a2 = double(r[j]) * r[j], b2 = double(r[j + 1]) * r[j + 1];
        u = float(std::clamp((double(c) * c - a2) / (b2 - a2), 0.0, 1.0));
    }
    lower = uint16_t(j);
    upper = u;
}

std::vector<float> detail::layer_rungs(const std::vector<float>& cocs, const DefocusOptions& o, float lo, float hi,
                                       bool exact_allowed)
{
    const LayerSettings set = settings_for_budget(o.budget_db);
    double ratio            = set.ratio;
    if (o.layers > 0) {
        // The ratio that puts o.layers rungs (0 and both sides) over the range.
        const double span = std::log(std::max(1.0f, -lo)) + std::log(std::max(1.0f, hi));
        const int sides   = (lo < -1.0f ? 1 : 0) + (hi > 1.0f ? 1 : 0);
        const int steps   = std::max(1, o.layers - 1 - sides);
        ratio             = span > 0.0 ? std::exp(span / steps) : 2.0;
        ratio             = std::max(ratio, 1.01);
    }
    // A scene of few depths (planes, a handful of lights) gets one rung per CoC it holds,
    // so its layers are exact but for the reductions; others get the ladder.
    std::vector<float> rungs;
    if (o.layers == 0) {
        if (exact_allowed && (hi - lo) / kRungStep_px < 1e6f) {
            rungs = coc_bins(cocs, lo, hi, kRungStep_px).mean_px;
            if (rungs.size() > kMaxExactRungs)
                rungs.clear();
        }
        // A rung at 0, so no two neighbouring rungs lie on opposite sides of focus (the
        // shares keep the second moment of one side's disks).
        if (!rungs.empty() && !std::binary_search(rungs.begin(), rungs.end(), 0.0f))
            rungs.insert(std::upper_bound(rungs.begin(), rungs.end(), 0.0f), 0.0f);
    }
    if (rungs.empty())
        rungs = coc_ladder(lo, hi, ratio);
    return rungs;
}

std::vector<int> detail::layer_reductions(const std::vector<float>& rungs, const DefocusOptions& o)
{
    std::vector<int> r;
    const float q = min_reduced_coc_px(o);
    for (float c : rungs)
        r.push_back(reduction_for(c, q, o.max_reduction));
    return r;
}

OIIO::ROI detail::defocus_output_region(const OIIO::ImageSpec& s, const OIIO::ROI& data, float extreme,
                                const DefocusOptions& o)
{
    OIIO::ROI out = data;
    if (o.grow) {
        const OIIO::ROI display(s.full_x, s.full_x + s.full_width, s.full_y, s.full_y + s.full_height);
        const OIIO::ROI limit = OIIO::roi_union(display, data);
        // Half the largest kernel: how far bokeh spread past the data window; a layer in a
        // buffer reduced by s reaches up to 1.5 s px farther (its box and the bilinear
        // enlargement).
        int spill = 0;
        if (o.method == DefocusMethod::Auto || o.method == DefocusMethod::Layers) {
            const int r = reduction_for(extreme, min_reduced_coc_px(o), o.max_reduction);
            spill       = r > 1 ? (3 * r + 1) / 2 : 0;
        }
        const int gx = int(std::ceil(0.5f * extreme)) + spill;
        const int gy = int(std::ceil(0.5f * extreme * o.aspect)) + spill;
        out = OIIO::roi_intersection(grown(data, gx, gy), limit);
    }
    out.chbegin = 0;
    out.chend   = 4;
    return out;
}

const char* method_name(DefocusMethod m)
{
    switch (m) {
    case DefocusMethod::Auto: return "auto";
    case DefocusMethod::Layers: return "layers";
    case DefocusMethod::Gather: return "gather";
    case DefocusMethod::Reference: return "reference";
    }
    return "?";
}

namespace {

// The result plane (RGBA over f.out) into dst: R, G, B(, A) as float, src's metadata.
void write_result(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Frame& f, const Plane& out, int nthreads)
{
    const int nc = f.img.has_alpha ? 4 : 3;
    const OIIO::ROI region = scaled_roi(f.out, f.up);
    OIIO::ImageSpec spec   = derived_spec(src.spec(), nc == 4 ? std::vector<std::string>{ "R", "G", "B", "A" }
                                                              : std::vector<std::string>{ "R", "G", "B" },
                                          region);
    scale_display_window(spec, src.spec(), f.up);
    record_lens(spec, f.lens);
    reset_uninitialised(dst, spec);
    parallel_for_chunks(0, out.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* d       = static_cast<float*>(dst.pixeladdr(region.xbegin, region.ybegin + y));
            const float* s = out.row(y);
            for (int x = 0; x < out.w; ++x)
                for (int c = 0; c < nc; ++c)
                    d[size_t(x) * size_t(nc) + size_t(c)] = s[size_t(x) * 4 + size_t(c)];
        }
    });
}

}  // namespace

bool defocus(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
             DefocusReport* report, int nthreads)
{
    if (src.initialized() && src.deep())
        return defocus_deep(dst, src, opts, report, nthreads);
    DefocusReport rep;
    Frame f;
    std::string err;
    if (!prepare(f, src, opts, rep, nthreads, err)) {
        dst.errorfmt("defocus: {}", err);
        return false;
    }
    if (opts.deep_output) {
        dst.errorfmt("defocus: a deep result needs a deep image (--deepen makes one)");
        return false;
    }
    rep.method = opts.method == DefocusMethod::Auto ? DefocusMethod::Layers : opts.method;
    Plane out(f.out.width() * f.up, f.out.height() * f.up, 4);
    std::fill_n(out.px.get(), out.size(), 0.0f);
    switch (rep.method) {
    case DefocusMethod::Gather:
        gather(out, f, opts, rep.min_coc_px, rep.max_coc_px, nthreads);
        from_iris_space(out, f.iris);  // the blend of levels, averaged in iris space
        break;
    case DefocusMethod::Reference: {
        if ((rep.max_coc_px - rep.min_coc_px) / opts.reference_step_px > 65535.0f) {
            dst.errorfmt("defocus: CoC range {} .. {} px holds too many {} px steps; raise the "
                         "reference step", rep.min_coc_px, rep.max_coc_px, opts.reference_step_px);
            return false;
        }
        const Membership m = one_layer_per_coc(f, rep.min_coc_px, rep.max_coc_px, opts.reference_step_px);
        if (m.coc_px.size() > 65535) {
            dst.errorfmt("defocus: {} distinct CoC values; raise the reference step", m.coc_px.size());
            return false;
        }
        rep.layer_coc_px    = m.coc_px;
        rep.layer_reduction = m.reduction;
        if (!composite_layers(out, f, m, opts, nthreads, err)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
        break;
    }
    default: {
        const Membership m  = layer_plan(f, opts, rep.min_coc_px, rep.max_coc_px, nthreads);
        rep.layer_coc_px    = m.coc_px;
        rep.layer_reduction = m.reduction;
        if (!composite_layers(out, f, m, opts, nthreads, err)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
    }
    }
    if (rep.method != DefocusMethod::Gather)
        fill_disocclusions(out, f, rep.max_coc_px, nthreads);
    report_sprites(rep, f.sprites.get());
    rep.summary = format("{}: CoC {:.1f} .. {:.1f} px, {} layers, output {}x{}{}{}", method_name(rep.method),
                         rep.min_coc_px, rep.max_coc_px, rep.layer_coc_px.size(), f.out.width() * f.up,
                         f.out.height() * f.up,
                         rep.nonfinite.total() ? format(", {} non-finite values replaced",
                                                        rep.nonfinite.total())
                                               : std::string(),
                         sprite_summary(rep));

    write_result(dst, src, f, out, nthreads);
    if (report)
        *report = std::move(rep);
    return true;
}

bool defocus_scatter_reference(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
                               int nthreads)
{
    DefocusOptions o  = opts;
    o.lens_character  = false;  // every pixel is scattered here; none is taken out
    o.method          = DefocusMethod::Reference;
    o.supersample     = 1;      // at the frame's resolution
    DefocusReport rep;
    Frame f;
    std::string err;
    Plane out;
    if (src.initialized() && src.deep()) {
        dst.errorfmt("defocus scatter reference: a flat image only (--flatten a deep one)");
        return false;
    }
    if (opts.aperture_views > 1) {
        dst.errorfmt("defocus scatter reference: every pixel is scattered with the whole aperture; views do not apply");
        return false;
    }
    if (!prepare(f, src, o, rep, nthreads, err) || !scatter_reference(out, f, o, src.spec(), nthreads, err)) {
        dst.errorfmt("defocus scatter reference: {}", err);
        return false;
    }
    fill_disocclusions(out, f, rep.max_coc_px, nthreads);  // as the layered method ends
    write_result(dst, src, f, out, nthreads);
    return true;
}

bool layer_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts, int nthreads)
{
    DefocusReport rep;
    Frame f;
    std::string err;
    if (!prepare(f, src, opts, rep, nthreads, err)) {
        dst.errorfmt("layer map: {}", err);
        return false;
    }
    const Membership m = layer_plan(f, opts, rep.min_coc_px, rep.max_coc_px, nthreads);
    reset_uninitialised(dst, derived_spec(src.spec(), { "layer" }));
    for (int y = f.data.ybegin; y < f.data.yend; ++y) {
        float* d = static_cast<float*>(dst.pixeladdr(f.data.xbegin, y));
        for (int x = f.data.xbegin; x < f.data.xend; ++x) {
            const size_t i      = f.img.index(x, y);
            d[x - f.data.xbegin] = float(m.lower[i]) + m.upper[i];
        }
    }
    return true;
}

}  // namespace bokeh
