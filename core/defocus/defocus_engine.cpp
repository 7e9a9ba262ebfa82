// defocus_engine.cpp — the layer engine every layered defocus runs on: a flat frame's
// layers (the Layers and Reference methods), a deep frame's (core/defocus/defocus_deep.cpp), each
// sub-aperture view's (core/defocus/defocus_views.cpp) and the lens's sprites drawn into them
// (core/defocus/defocus_sprites.cpp).
//
// The layer model (ours; the idea of layers composited back to front is ZDefocus's, and
// layered depth of field is the one the source talk names for occlusion-correct bokeh).
// Pixels are sorted into layers by signed CoC (front to back). Layer k, with CoC c_k, is
// the blur by the aperture of diameter |c_k| of
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
// A layer whose CoC allows it is built in a buffer reduced by 2..16 (area-exact box),
// blurred there with the exact kernel, and enlarged bilinearly as it is composited (large
// bokeh lose little at low resolution; which layers, core/defocus/defocus_plan.cpp). Cost: layers
// are computed in tiles, only where they hold pixels (trimmed to the pixels' reach), so a
// sparse layer costs what it holds, not its bounding box.
//
// Known limits: a flat image holds no background behind its foreground; what the layers
// leave uncovered there is filled afterwards (core/defocus/defocus_fill.cpp).

#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"
#include "base/progress.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace bokeh {

using namespace detail;

namespace {

// Full-resolution reach of a CoC: half the kernel, rounded up, plus one for bilinear reads.
int reach_x(float coc_px) { return int(std::ceil(0.5f * std::abs(coc_px))) + 1; }
int reach_y(float coc_px, float aspect) { return int(std::ceil(0.5f * std::abs(coc_px) * aspect)) + 1; }

// Layers are computed in tiles of kTile x kTile reduced pixels, only where the layer has
// pixels within reach: sparse layers (a few lights, a thin band of floor) cost what they
// hold, not their bounding box. Tiles are independent, so they run in parallel.
constexpr int kTile = kLayerTilePx;
// A layer blurred with the lens's PSF goes by FFT, whose every call transforms its four
// kernels and pays a margin of the kernel's reach: its tiles are 4 times wider.
constexpr int kLensTile = kLensLayerTilePx;
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
    // A pixel past the output (a band's reach: defocus_bands.cpp) marks the nearest tile:
    // its neighbours within reach then hold all it reaches, and more.
    auto mark = [&](size_t k, int x0, int x1, int y) {  // pixels [x0, x1] of row y
        const int t = size[k], ty = std::clamp(floor_div(y - f.out.ybegin, t), 0, rows[k] - 1);
        const int tx0 = std::clamp(floor_div(x0 - f.out.xbegin, t), 0, cols[k] - 1);
        const int tx1 = std::clamp(floor_div(x1 - f.out.xbegin, t), 0, cols[k] - 1);
        for (int tx = tx0; tx <= tx1; ++tx)
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

}  // namespace

// Iris-space colour (4 or more channels, premultiplied) back to linear, in place.
void detail::from_iris_space(Plane& p, const IrisSpace& iris)
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

// The aperture at diameter |coc_px| / s (and the aspect), as exact weights. In front of
// focus the rays reach the sensor before they cross, behind it after: the two bokeh are
// the aperture and its point reflection, which shows with an odd number of blades.
KernelWeights detail::aperture_weights(const DefocusOptions& o, float coc_px, int s, int nthreads)
{
    Kernel k = coc_px < 0.0f ? point_reflected(o.aperture) : o.aperture;
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

namespace {

// One layer as composite_layers draws it: its kernels, its tile grid and where it goes.
struct LayerPass {
    const Frame& f;
    const Membership& m;
    int k;
    const KernelWeights& w;                          // the aperture's (or the lens's mean) kernel
    const std::vector<KernelWeights>& lens_kernels;  // R, G, B, mean; empty: the aperture
    int cells, s, cols;                              // tile side in reduced pixels, reduction, grid columns
    int gx, gy, up;                                  // grid origin (f.out's); output pixels a pixel
    Plane& target;                                   // RGBA over f.out scaled by up
};

// The layer blurred over reduced pixels `need` laid under `target` ("over") at the
// full-resolution pixels `draw`; up x up bilinear reads a pixel for pseudo-high
// resolution (the layer is zero past `need`'s margin, so `draw` holds every output pixel
// the layer touches).
void lay_over(const LayerPass& lp, const Plane& layer, const OIIO::ROI& need, const OIIO::ROI& draw)
{
    const int gx = lp.gx, gy = lp.gy, s = lp.s, up = lp.up;
    if (up == 1) {
        for (int y = draw.ybegin; y < draw.yend; ++y) {
            float* dst = lp.target.row(y - gy) + size_t(draw.xbegin - gx) * 4;
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
    for (int y = draw.ybegin; y < draw.yend; ++y)
        for (int sy = 0; sy < up; ++sy) {
            float* dst = lp.target.row((y - gy) * up + sy) + size_t(draw.xbegin - gx) * size_t(up) * 4;
            for (int x = draw.xbegin; x < draw.xend; ++x)
                for (int sx = 0; sx < up; ++sx, dst += 4) {
                    float l[4];
                    sample_sub(layer, need, gx, gy, s, x, y, up, sx, sy, l);
                    const float behind = 1.0f - l[3];
                    for (int c4 = 0; c4 < 4; ++c4)
                        dst[c4] = l[c4] + behind * dst[c4];
                }
        }
}

// Tile `tile` of the layer: its input reduced, blurred, divided by its visibility, back
// from iris space and laid under the target. `known` is what the tile holds (found when
// `first_view`: it does not depend on the view, whose kernel keeps the whole aperture's
// extent). A hidden tile's visibility is kept in `gain` for the layer's sprites.
void composite_tile(const LayerPass& lp, int tile, TileContent& known, bool first_view, SpriteGain& gain)
{
    const Frame& f = lp.f;
    const KernelWeights& w = lp.w;
    const int gx = lp.gx, gy = lp.gy, s = lp.s, cells = lp.cells, t = cells * s;
    const int tx = tile % lp.cols, ty = tile / lp.cols;
    const OIIO::ROI region = OIIO::roi_intersection(
        OIIO::ROI(gx + tx * t, gx + (tx + 1) * t, gy + ty * t, gy + (ty + 1) * t), f.out);
    // The tile's reduced pixels, one more each side for bilinear reads.
    const OIIO::ROI low(tx * cells - 1, floor_div(region.xend - 1 - gx, s) + 2,
                        ty * cells - 1, floor_div(region.yend - 1 - gy, s) + 2);
    // Only where the layer's pixels reach: past its pixels' bounding box grown by
    // the kernel the layer is exactly 0 (so compositing it changes nothing). One
    // reduced pixel more keeps the bilinear reads at the edge exact.
    if (first_view)
        known = tile_content(f, lp.m, lp.k, grown(low, w.rx, w.ry), gx, gy, s);
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
    Plane p = layer_input(f, lp.m, lp.k, grown(need, w.rx, w.ry), gx, gy, s, content.hidden);
    Plane layer;
    if (w.is_identity())
        layer = std::move(p);
    else if (lp.lens_kernels.empty())
        layer = convolve_spans(p, w, 1);
    else {  // R, G and B each with its own PSF; coverage (and visibility, when hidden) their mean
        const std::vector<int> kernel_of(kLensChannelKernels.begin(), kLensChannelKernels.begin() + p.nc);
        layer = convolve_fft(p, lp.lens_kernels, kernel_of, 1);
    }
    if (content.hidden)
        divide_by_visibility(layer);
    if (content.hidden && gain.used) {  // the visibility (channel 4), kept for the sprites
        const size_t i = size_t(tile);
        gain.draw[i]   = draw;
        gain.low[i]    = need;
        Plane& v       = gain.visibility[i];
        v              = Plane(layer.w, layer.h, 1);
        for (int y = 0; y < layer.h; ++y)
            for (int x = 0; x < layer.w; ++x)
                v.row(y)[x] = layer.row(y)[size_t(x) * size_t(layer.nc) + 4];
    }
    from_iris_space(layer, f.iris);
    lay_over(lp, layer, need, draw);
}

// Lens character on a flat frame: the layer's sprites are divided by its visibility as its
// colour is (a deep frame's layers are continued only under the same surface, the deep
// visibility; its sprites are not). The gain's grid is the layer's tiles.
SpriteGain sprite_gain(const Frame& f, const Membership& m, int k, int gx, int gy, int tile_px, int cols,
                       int s, size_t tiles, const std::vector<float>& floors)
{
    SpriteGain gain;
    if (f.sprites && !f.deep() && layer_has_sprites(f, m, k)) {
        gain.used    = true;
        gain.gx      = gx;
        gain.gy      = gy;
        gain.tile_px = tile_px;
        gain.cols    = cols;
        gain.s       = s;
        gain.draw.resize(tiles);
        gain.low.resize(tiles);
        gain.visibility.resize(tiles);
        gain.floor = size_t(k) < floors.size() ? floors[size_t(k)] : 0.0f;
    }
    return gain;
}

}  // namespace

void detail::add_view_share(Plane& mean, const Plane& view, float share, int nthreads)
{
    parallel_for_chunks(0, int64_t(mean.size()), 1 << 16, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i)
            mean.px[size_t(i)] += share * view.px[size_t(i)];
    });
}

bool detail::composite_layers(Plane& out, const Frame& f, const Membership& m, const DefocusOptions& o,
                              int nthreads, std::string& err, std::vector<Plane>* per_layer, float progress_from,
                              std::vector<Plane>* view_targets)
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
    // With `view_targets` each view composites over its own plane there, and the mean is
    // the caller's (layers drawn in groups: draw_flat_in_groups).
    if (view_targets && view_targets->size() != views.size()) {
        err = "composite_layers: one target a view is needed";
        return false;
    }
    const bool own_views = views.size() > 1 && !view_targets;
    Plane under(1, 1, 4), mean(1, 1, 4);
    if (own_views) {
        under = Plane(out.w, out.h, out.nc);
        std::copy_n(out.px.get(), out.size(), under.px.get());
        mean = Plane(out.w, out.h, out.nc);
        std::fill_n(mean.px.get(), mean.size(), 0.0f);
    }
    std::vector<std::vector<TileContent>> contents(m.coc_px.size());
    std::vector<float> gain_floors = f.sprite_gain_floors;
    if (gain_floors.empty() && f.sprites && !f.deep()) {
        std::vector<float> cocs;
        for (const Sprite& sp : f.sprites->sprites)
            cocs.push_back(sp.coc_px);
        gain_floors = sprite_gain_floors(cocs, m.coc_px);
    }
    for (const ApertureView& view : views) {
        const bool first_view = &view == &views.front();
        if (own_views)
            std::copy_n(under.px.get(), under.size(), out.px.get());
        Plane& view_out = view_targets ? (*view_targets)[size_t(&view - views.data())] : out;
        for (int k = int(m.coc_px.size()) - 1; k >= 0; --k) {
            const float c = m.coc_px[size_t(k)];
            const std::vector<KernelWeights>& lens_kernels = lens[size_t(k)];
            const int cells       = lens_kernels.empty() ? kTile : kLensTile;
            const int s           = m.reduction[size_t(k)];
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
            Plane& target = per_layer ? (*per_layer)[size_t(k)] : view_out;
            SpriteGain gain = sprite_gain(f, m, k, gx, gy, cells * s, cols[size_t(k)], s, tiles[size_t(k)].size(),
                                          gain_floors);
            const LayerPass pass{ f, m, k, w, lens_kernels, cells, s, cols[size_t(k)], gx, gy, up, target };
            parallel_for_chunks(0, int64_t(todo.size()), 1, nthreads, [&](int64_t n, int64_t) {
                struct Counted {  // the tile counts as done however it returns
                    ProgressCounter& p;
                    double units;
                    ~Counted() { p.add(units); }
                } counted{ progress, weight };
                const int tile = todo[size_t(n)];
                composite_tile(pass, tile, contents[size_t(k)][size_t(tile)], first_view, gain);
            });
            // Lens character: the layer's highlights, before any nearer layer hides them.
            if (f.sprites)
                draw_layer_sprites(target, f, m, k, nthreads, &gain, first_view);
        }
        if (own_views)
            add_view_share(mean, out, float(view.share), nthreads);
    }
    if (own_views)
        std::copy_n(mean.px.get(), mean.size(), out.px.get());
    return true;
}

}  // namespace bokeh
