// defocus_fill.cpp — the background a flat frame hides behind its foregrounds, continued from
// what the frame shows around them: the plate a flat defocus draws on where a blurred
// foreground uncovers what was behind it.
//
// A flat frame holds one surface a pixel. Where a defocused foreground's blurred coverage
// falls below 1 inside its own silhouette, a lens sees the surface behind it (the rays
// that pass beside the foreground), which the frame never recorded. The plate continues
// the farther surfaces seen around a pixel under it:
//
// * a pyramid of 2 x 2 cells, each the coverage-weighted mean of its children's colour and
//   CoC, taken only over the children of the farthest depth among them (within
//   kClusterPx + kClusterShare |CoC|): a cell straddling a silhouette keeps its background
//   and drops the foreground (a depth-aware "pull" of Gortler et al.'s pull-push, "The
//   Lumigraph", SIGGRAPH 1996, section 3.4.2);
// * under a pixel of CoC c, the cells farther than c (by kFartherPx + kFartherShare |c|)
//   read bilinearly at each level from the coarsest that spans the pixel's blur down to
//   the finest, each level's mean replacing the coarser estimate by its share of the taps
//   that qualify (the "push"): the background's nearest side wins, and the estimate varies
//   smoothly along the silhouette.
//
// Colour is averaged as x / (1 + |x|) (and brought back by x / (1 - |x|)), so an HDR light
// behind an edge lends the plate its hue over a cell, not its energy: a light must not
// smear into a bright streak under a foreground.
//
// Known limits: a smooth continuation, not a texture: a textured background comes back as
// its local mean (cells of up to the foreground's CoC); of several surfaces behind a
// foreground at a coarse level, the farthest is the one continued.

#include "defocus/defocus_fill.h"

#include <bokeh/parallel.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace bokeh::detail {

namespace {

// Children within this CoC of the farthest among them are one surface (px, and share of
// |CoC|): a slanted floor's neighbours differ by a fraction of a pixel.
constexpr float kClusterPx    = 1.0f;
constexpr float kClusterShare = 0.1f;
// A surface is behind a pixel when its CoC is farther by this much: nearer than that, the
// layers treat the two as one surface already (share_between spreads a pixel over rungs).
constexpr float kFartherPx    = 1.0f;
constexpr float kFartherShare = 0.05f;

inline float tone(float x) { return x / (1.0f + std::abs(x)); }
inline float untone(float t) { return t / std::max(1.0f - std::abs(t), 1e-7f); }

// The CoC a surface must pass to lie behind a pixel of CoC `coc_px`.
inline float farther_than(float coc_px) { return coc_px + kFartherPx + kFartherShare * std::abs(coc_px); }

// Rec. 709 luminance.
inline float luminance(const float* rgb) { return 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2]; }

// A mirrored pixel may be this many times brighter than the smooth continuation at its
// place or the silhouette's own background pixel it is mirrored across: a light that
// touches the silhouette continues under it (its hidden part is most likely more of it),
// a light farther out does not come back as a phantom mirror image under the foreground.
constexpr float kMirrorMaxGain = 2.0f;
// The widest blur (px) the mirror gives a defocused background's texture; past it the
// texture is gone and the mean over a larger disk costs its area per pixel for nothing.
constexpr int kMirrorMaxBlurPx = 16;

// The report counts a pixel as filled when it lost more coverage than this (rounding in
// the layers' division leaves 1e-4 and less on pixels that lost nothing).
constexpr float kCountedLoss = 1e-3f;

}  // namespace

// A frame pixel as a cell. An empty pixel (coverage 0) is nothing at any depth: it lies
// behind everything, so a foreground over empty space continues over emptiness and its
// silhouette thins out as a lens makes it (the layers' own transparency).
void BackgroundPlate::frame_cell(int x, int y, Cell& c) const
{
    const size_t i = size_t(y) * size_t(w0_) + size_t(x);
    const float* p = f_.linear().data() + i * 4;
    c.w            = 1.0f;
    c.a            = std::clamp(p[3], 0.0f, 1.0f);
    c.z            = c.a > 0.0f ? f_.coc[i] : std::numeric_limits<float>::infinity();
    for (int k = 0; k < 3 && c.a > 0.0f; ++k)
        c.t[k] = tone(p[k] / p[3]);
}

void BackgroundPlate::level1_cell(int i, int j, Cell& c) const
{
    Cell kids[4];
    int n = 0;
    for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
            const int x = 2 * i + dx, y = 2 * j + dy;
            if (x < w0_ && y < h0_)
                frame_cell(x, y, kids[n++]);
        }
    c = Cell{};
    pull(kids, n, c);
}

// Level 1 is not stored: its cells are a quarter of the frame's pixels at 24 bytes each,
// three quarters of the pyramid (50 of 66 MB at 3840x2160), held while the defocus's
// working frame and result are (the fill is the defocus's peak, docs/defocus.md "Memory");
// a read pulls 4 frame pixels, for the few pixels a fill continues.
BackgroundPlate::BackgroundPlate(const Frame& f, int nthreads)
    : f_(f), w0_(f.data.width()), h0_(f.data.height()), w1_((w0_ + 1) / 2), h1_((h0_ + 1) / 2),
      x0_(f.data.xbegin), y0_(f.data.ybegin)
{
    if (level_count() == 0)
        return;  // one pixel: no level
    int w = w1_, h = h1_;
    while (w > 1 || h > 1) {
        const int cw = (w + 1) / 2, ch = (h + 1) / 2;
        Level next{ cw, ch, std::vector<Cell>(size_t(cw) * size_t(ch)) };
        const Level* below = levels_.empty() ? nullptr : &levels_.back();
        parallel_for_chunks(0, ch, 8, nthreads, [&](int64_t j0, int64_t j1) {
            for (int j = int(j0); j < int(j1); ++j)
                for (int i = 0; i < cw; ++i) {
                    Cell kids[4];
                    int n = 0;
                    for (int dy = 0; dy < 2; ++dy)
                        for (int dx = 0; dx < 2; ++dx) {
                            const int x = 2 * i + dx, y = 2 * j + dy;
                            if (x >= w || y >= h)
                                continue;
                            if (below)
                                kids[n] = below->cells[size_t(y) * size_t(w) + size_t(x)];
                            else
                                level1_cell(x, y, kids[n]);
                            ++n;
                        }
                    pull(kids, n, next.cells[size_t(j) * size_t(cw) + size_t(i)]);
                }
        });
        levels_.push_back(std::move(next));
        w = cw, h = ch;
    }
}

// A cell from its `n` children: the mean over those of the farthest depth among them.
void BackgroundPlate::pull(const Cell* kids, int n, Cell& c)
{
    float far = -std::numeric_limits<float>::infinity();
    for (int k = 0; k < n; ++k)
        if (kids[k].w > 0.0f)
            far = std::max(far, kids[k].z);
    if (far == -std::numeric_limits<float>::infinity())
        return;  // nothing known: weight 0
    const float near_end = std::isinf(far) ? far : far - (kClusterPx + kClusterShare * std::abs(far));
    float sw = 0.0f, swa = 0.0f, sz = 0.0f, st[3] = { 0, 0, 0 };
    for (int k = 0; k < n; ++k) {
        const Cell& q = kids[k];
        if (q.w <= 0.0f || q.z < near_end)
            continue;
        const float wa = q.w * q.a;  // colour and depth weigh by what the child covers
        sw += q.w;
        swa += wa;
        if (!std::isinf(q.z))
            sz += wa * q.z;
        for (int m = 0; m < 3; ++m)
            st[m] += wa * q.t[m];
    }
    c.w = sw / float(n);
    c.a = swa / sw;
    c.z = swa > 0.0f ? sz / swa : far;
    for (int m = 0; m < 3 && swa > 0.0f; ++m)
        c.t[m] = st[m] / swa;
}

bool BackgroundPlate::behind(int x, int y, float coc_px, float rgba[4]) const
{
    static const Cell kEmpty{ { 0, 0, 0 }, std::numeric_limits<float>::infinity(), 0.0f, 1.0f };
    const float farther = farther_than(coc_px);
    // The coarsest level whose cells span the pixel's blur radius (and a cell more).
    const int span  = int(std::ceil(std::log2(0.5f * std::abs(coc_px) + 2.0f))) + 1;
    const int top   = std::min(level_count(), std::max(span, 1));
    bool have       = false;
    float v[4]      = { 0, 0, 0, 0 };  // tone-mapped colour, coverage
    for (int L = top; L >= 1; --L) {
        const Level* lv   = L >= 2 ? &levels_[size_t(L - 2)] : nullptr;
        const int lw = lv ? lv->w : w1_, lh = lv ? lv->h : h1_;
        const float scale = float(1 << L);
        const float u = (float(x - x0_) + 0.5f) / scale - 0.5f, t = (float(y - y0_) + 0.5f) / scale - 0.5f;
        const float fu = std::floor(u), ft = std::floor(t);
        const float bx = u - fu, by = t - ft;
        float W = 0.0f, WA = 0.0f, acc[4] = { 0, 0, 0, 0 };
        for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx) {
                const int i = int(fu) + dx, j = int(ft) + dy;
                const bool past = i < 0 || j < 0 || i >= lw || j >= lh;
                // Past the data window: empty by a black border, else the edge's cells.
                const int ci = std::clamp(i, 0, lw - 1), cj = std::clamp(j, 0, lh - 1);
                Cell pulled;
                const Cell* cell = &kEmpty;
                if (!(past && f_.border == Border::Black)) {
                    if (lv) {
                        cell = &lv->cells[size_t(cj) * size_t(lw) + size_t(ci)];
                    } else {
                        level1_cell(ci, cj, pulled);
                        cell = &pulled;
                    }
                }
                const Cell& c = *cell;
                if (c.w <= 0.0f || c.z <= farther)
                    continue;
                const float b = (dx ? bx : 1.0f - bx) * (dy ? by : 1.0f - by) * c.w;
                W += b;
                WA += b * c.a;
                for (int m = 0; m < 3; ++m)
                    acc[m] += b * c.a * c.t[m];
                acc[3] += b * c.a;
            }
        if (W <= 0.0f)
            continue;
        const float a = have ? std::min(W, 1.0f) : 1.0f;
        // Colour only where the level covers something; its coverage always.
        const float ac = WA > 0.0f ? a : 0.0f;
        for (int m = 0; m < 3; ++m)
            v[m] = ac * (WA > 0.0f ? acc[m] / WA : 0.0f) + (1.0f - ac) * v[m];
        v[3] = a * (acc[3] / W) + (1.0f - a) * v[3];
        have = true;
    }
    if (!have)
        return false;
    for (int m = 0; m < 3; ++m)
        rgba[m] = untone(v[m]) * v[3];
    rgba[3] = v[3];
    return true;
}

bool BackgroundPlate::mirrored(int x, int y, float coc_px, float rgba[4]) const
{
    float smooth[4];
    if (!behind(x, y, coc_px, smooth))
        return false;
    const float farther = farther_than(coc_px);
    const OIIO::ROI& d  = f_.data;
    const std::vector<float>& px = f_.linear();
    auto behind_at = [&](int qx, int qy) {
        if (qx < d.xbegin || qx >= d.xend || qy < d.ybegin || qy >= d.yend)
            return f_.border == Border::Black;  // empty past a black border, else unknown
        const size_t i = f_.img.index(qx, qy);
        return px[i * 4 + 3] <= 0.0f || f_.coc[i] > farther;  // empty lies behind everything
    };
    // The nearest farther pixel within the blur radius: rings of growing Chebyshev radius,
    // stopped once a ring lies farther than the best found.
    const int reach = int(std::ceil(0.5f * std::abs(coc_px))) + 2;
    int best = std::numeric_limits<int>::max(), qx = 0, qy = 0;
    for (int r = 1; r <= reach && r * r <= best; ++r)
        for (int dy = -r; dy <= r; ++dy) {
            const int step = (dy == -r || dy == r) ? 1 : 2 * r;
            for (int dx = -r; dx <= r; dx += step)
                if (dx * dx + dy * dy < best && behind_at(x + dx, y + dy)) {
                    best = dx * dx + dy * dy;
                    qx = x + dx, qy = y + dy;
                }
        }
    if (best == std::numeric_limits<int>::max()) {
        std::copy_n(smooth, 4, rgba);
        return true;
    }
    // The mirror line runs between q and its neighbour toward (x, y): a pixel next to the
    // silhouette takes q itself, the next q's neighbour beyond, and so on.
    const double len = std::sqrt(double(best));
    const int mx = 2 * qx - x + int(std::lround(double(x - qx) / len));
    const int my = 2 * qy - y + int(std::lround(double(y - qy) / len));
    if (!behind_at(mx, my)) {
        std::copy_n(smooth, 4, rgba);
        return true;
    }
    if (f_.source(mx, my) < 0 || f_.source(qx, qy) < 0) {  // past a black border: empty
        std::fill_n(rgba, 4, 0.0f);
        return true;
    }
    // A defocused background is seen blurred: the mean over the disk of its CoC (up to
    // kMirrorMaxBlurPx across) around the mirror image, of the pixels that lie behind.
    const int rb = std::min(int(0.5f * std::abs(f_.coc[f_.img.index(qx, qy)])), kMirrorMaxBlurPx / 2);
    float mean[4] = { 0, 0, 0, 0 };
    int count = 0;
    for (int dy = -rb; dy <= rb; ++dy)
        for (int dx = -rb; dx <= rb; ++dx)
            if (dx * dx + dy * dy <= rb * rb && f_.source(mx + dx, my + dy) >= 0 && behind_at(mx + dx, my + dy)) {
                const float* v = px.data() + f_.img.index(mx + dx, my + dy) * 4;
                for (int c = 0; c < 4; ++c)
                    mean[c] += v[c];
                ++count;
            }
    for (int c = 0; c < 4; ++c)
        rgba[c] = mean[c] / float(count);  // count >= 1: the mirror image itself lies behind
    const float* m = rgba;
    if (m[3] <= 0.0f)
        return true;
    // Held to the brighter of the smooth continuation and the edge's own pixel.
    const float* e   = px.data() + f_.img.index(qx, qy) * 4;
    const float held = kMirrorMaxGain * std::max({ smooth[3] > 0.0f ? luminance(smooth) / smooth[3] : 0.0f,
                                                   e[3] > 0.0f ? luminance(e) / e[3] : 0.0f, 0.0f });
    const float lum = luminance(m) / m[3];
    if (lum > held)
        for (int c = 0; c < 3; ++c)
            rgba[c] *= held / lum;
    return true;
}

FillCount fill_disocclusions(Plane& out, const Frame& f, float farthest, const BackgroundPlate* plate,
                             PlateFill how, int nthreads)
{
    std::vector<FillCount> counts(size_t(out.h));
    parallel_for_chunks(0, out.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* d = out.row(y);
            FillCount& n = counts[size_t(y)];
            const int sy = border_index(f.out.ybegin + y / f.up, f.data.ybegin, f.data.yend, f.border);
            for (int x = 0; x < out.w; ++x, d += 4) {
                const int sx = border_index(f.out.xbegin + x / f.up, f.data.xbegin, f.data.xend, f.border);
                if (sx == kOutside || sy == kOutside)
                    continue;
                const size_t i = f.img.index(sx, sy);
                // Only pixels with something behind them in depth can have lost it.
                if (f.coc[i] >= farthest)
                    continue;
                const float* px = f.linear().data() + i * 4;
                if (px[3] <= d[3])
                    continue;
                // Only the coverage the source had and the layers lost.
                const float lost = px[3] - d[3];
                float behind[4];
                if (plate
                    && (how == PlateFill::Mirror ? plate->mirrored(sx, sy, f.coc[i], behind)
                                                 : plate->behind(sx, sy, f.coc[i], behind))) {
                    for (int c = 0; c < 4; ++c)
                        d[c] += lost * behind[c];
                    n.continued += lost > kCountedLoss;
                    continue;
                }
                const float w = lost / px[3];
                for (int c = 0; c < 4; ++c)
                    d[c] += w * px[c];
                n.foreground += lost > kCountedLoss;
            }
        }
    });
    FillCount all;
    for (const FillCount& n : counts) {
        all.continued += n.continued;
        all.foreground += n.foreground;
    }
    return all;
}

}  // namespace bokeh::detail
