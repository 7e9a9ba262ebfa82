// defocus_reference.cpp — the exact references of the flat defocus: the Reference method
// (every distinct CoC its own full-resolution layer, through the layer engine) and the
// brute-force scatter (defocus_scatter_reference: every pixel scattered with its own PSF,
// layer by layer, with the layered model's visibility).
//
// The scatter is the slowest and the plainest route to the model's answer: it shares the
// frame's preparation and the visibility rule with the layers, and nothing else, so the
// tests compare the layers, the sprites and the lens layer against it.
// Limits: PSFs are kept per CoC step and (with field effects) per 1/64 of the
// half-diagonal; its cost grows with pixels times PSF area.

#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

// Add `scale` * psf (per channel: rgb[c]) with its top-left pixel at (x0, y0) into rows
// [band0, band1) of `target` (RGBA over `out`), pixel by pixel: the reference's scatter.
void add_psf(Plane& target, const OIIO::ROI& out, const Psf& psf, int x0, int y0, const float rgb[3],
             float scale, int band0, int band1)
{
    const int top = std::max(y0, band0), bottom = std::min(y0 + psf.height, band1);
    const int left = std::max(x0, out.xbegin), right = std::min(x0 + psf.width, out.xend);
    if (left >= right)
        return;
    const float k[3] = { rgb[0] * scale, rgb[1] * scale, rgb[2] * scale };
    for (int y = top; y < bottom; ++y) {
        float* d       = target.row(y - out.ybegin) + size_t(left - out.xbegin) * 4;
        const float* p = psf.rgb.data() + (size_t(y - y0) * size_t(psf.width) + size_t(left - x0)) * 3;
        for (int x = left; x < right; ++x, d += 4, p += 3) {
            d[0] += k[0] * p[0];
            d[1] += k[1] * p[1];
            d[2] += k[2] * p[2];
        }
    }
}

// The scatter's sources: every non-empty pixel of the data window and, past it, the
// border rule's pixels within the PSFs' reach (clamp and mirror repeat the edge; black
// adds nothing), each keyed by its CoC step and (with field effects) its field position.
using ScatterKey = std::tuple<int64_t, int, int>;  // CoC step, field x, field y (1/64)
struct ScatterPoint {
    size_t at;
    int x, y;
    ScatterKey key;
};
struct ScatterSet {
    std::vector<ScatterPoint> points;
    std::map<ScatterKey, std::shared_ptr<Psf>> psfs;  // also each layer's on-axis PSF, for visibility
    std::vector<int64_t> coc_step;                     // per data-window pixel
    float extent = 0.0f;                               // the largest PSF half-size, px
};

// Field positions matter only with field effects; then PSFs are kept per 1/64 of the
// half-diagonal (8 times the cache's bins).
bool scatter_sources(ScatterSet& set, const Frame& f, const LensCharacter& lens, const FieldFrame& field, float step,
                     int nthreads, std::string& err)
{
    const bool by_field = field.used;
    set.coc_step.resize(f.coc.size());
    for (size_t i = 0; i < f.coc.size(); ++i)
        set.coc_step[i] = int64_t(std::llround(f.coc[i] / step));
    auto empty = [&](size_t i) {
        const float* px = f.img.rgba.data() + i * 4;
        return px[0] == 0.0f && px[1] == 0.0f && px[2] == 0.0f && px[3] == 0.0f;
    };
    auto add_point = [&](size_t i, int x, int y) {
        const double fx = (x + 0.5 - field.cx) / field.half_diagonal, fy = (field.cy - (y + 0.5)) / field.half_diagonal;
        const ScatterKey key = std::make_tuple(set.coc_step[i], by_field ? int(std::lround(64.0 * fx)) : 0,
                                               by_field ? int(std::lround(64.0 * fy)) : 0);
        set.points.push_back({ i, x, y, key });
        set.psfs.emplace(key, nullptr);
        set.psfs.emplace(std::make_tuple(set.coc_step[i], 0, 0), nullptr);  // the layer's, for visibility
    };
    auto build_psfs = [&]() {
        for (auto& [key, psf] : set.psfs) {
            if (psf)
                continue;
            PsfRequest r;
            r.coc_px  = double(std::get<0>(key)) * step;
            r.field_x = std::get<1>(key) / 64.0;
            r.field_y = std::get<2>(key) / 64.0;
            psf       = std::make_shared<Psf>();
            if (!lens_psf(*psf, lens, r, err, nthreads))
                return false;
            set.extent = std::max(set.extent, float(std::max(psf->width, psf->height) / 2));
        }
        return true;
    };
    const int w = f.data.width();
    for (size_t i = 0; i < f.coc.size(); ++i)
        if (!empty(i))
            add_point(i, f.data.xbegin + int(i % size_t(w)), f.data.ybegin + int(i / size_t(w)));
    if (!build_psfs())
        return false;
    const int reach = int(std::ceil(set.extent));
    for (int y = f.data.ybegin - reach; y < f.data.yend + reach; ++y)
        for (int x = f.data.xbegin - reach; x < f.data.xend + reach; ++x) {
            if (x >= f.data.xbegin && x < f.data.xend && y >= f.data.ybegin && y < f.data.yend)
                continue;
            const int64_t i = f.source(x, y);
            if (i >= 0 && !empty(size_t(i)))
                add_point(size_t(i), x, y);
        }
    return build_psfs();
}

// The layered model's visibility (composite_layers): the layer is divided by the blur of
// 1 - A over the pixels in nearer layers (`hides`, over the output region grown by
// `reach` px, `gw` wide), here with the layer's own PSF `vp` (its mean of R, G, B; on
// axis), so what a nearer layer hides is continued from the layer's visible
// surroundings, as there.
void divide_by_nearer(Plane& layer, const std::vector<float>& hides, const Psf& vp, int reach, size_t gw,
                      int nthreads)
{
    std::vector<float> mean(size_t(vp.width) * size_t(vp.height));
    for (size_t j = 0; j < mean.size(); ++j)
        mean[j] = (vp.rgb[j * 3] + vp.rgb[j * 3 + 1] + vp.rgb[j * 3 + 2]) / 3.0f;
    const int hw = vp.width / 2, hh = vp.height / 2;
    parallel_for_chunks(0, layer.h, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y) {
            float* l = layer.row(y);
            for (int x = 0; x < layer.w; ++x, l += 4) {
                if (l[0] == 0.0f && l[1] == 0.0f && l[2] == 0.0f && l[3] == 0.0f)
                    continue;
                // Source q = p + (hw - i, hh - j) reaches p through PSF pixel (i, j).
                double hidden = 0.0;
                for (int j = 0; j < vp.height; ++j) {
                    const float* h = &hides[size_t(y + reach + hh - j) * gw + size_t(x + reach + hw)];
                    const float* m = &mean[size_t(j) * size_t(vp.width)];
                    for (int i = 0; i < vp.width; ++i)
                        hidden += double(m[i]) * h[-i];
                }
                if (hidden <= 0.0)
                    continue;
                const double vis = 1.0 - hidden;
                const float inv  = vis > 1e-6 ? float(1.0 / vis) : 0.0f;
                for (int c = 0; c < 4; ++c)
                    l[c] *= inv;
            }
        }
    });
}

// The points of one layer, [b, e) of the sorted points, scattered into `layer` (RGBA over
// f.out): colour with its channel's PSF, alpha with their mean.
void scatter_layer(Plane& layer, const Frame& f, const ScatterSet& set, size_t b, size_t e, int nthreads)
{
    const int reach_all = int(std::ceil(set.extent));
    const auto& points  = set.points;
    parallel_for_chunks(f.out.ybegin, f.out.yend, 16, nthreads, [&](int64_t y0, int64_t y1) {
        auto first = std::lower_bound(points.begin() + int64_t(b), points.begin() + int64_t(e),
                                      int(y0) - reach_all, [](const ScatterPoint& p, int y) { return p.y < y; });
        for (auto it = first; it != points.begin() + int64_t(e) && it->y < int(y1) + reach_all; ++it) {
            const Psf& psf  = *set.psfs.at(it->key);
            const float* px = f.img.rgba.data() + it->at * 4;
            add_psf(layer, f.out, psf, it->x - psf.width / 2, it->y - psf.height / 2, px, 1.0f, int(y0), int(y1));
            const int hw = psf.width / 2, hh = psf.height / 2;
            for (int y = std::max(it->y - hh, int(y0)); y < std::min(it->y + hh + 1, int(y1)); ++y)
                for (int x = std::max(it->x - hw, f.out.xbegin); x < std::min(it->x + hw + 1, f.out.xend); ++x) {
                    const float* p = &psf.rgb[(size_t(y - it->y + hh) * size_t(psf.width) + size_t(x - it->x + hw)) * 3];
                    layer.row(y - f.out.ybegin)[size_t(x - f.out.xbegin) * 4 + 3] += px[3] * (p[0] + p[1] + p[2]) / 3.0f;
                }
        }
    });
}

}  // namespace

bool detail::scatter_reference(Plane& out, Frame& f, const DefocusOptions& o, const OIIO::ImageSpec& spec,
                               int nthreads, std::string& err)
{
    LensCharacter lens;
    if (!defocus_lens(o, spec, lens, err))
        return false;
    ScatterSet set;
    if (!scatter_sources(set, f, lens, FieldFrame(spec, lens), o.reference_step_px, nthreads, err))
        return false;
    const float extreme = std::max({ std::abs(*std::min_element(f.coc.begin(), f.coc.end())),
                                     std::abs(*std::max_element(f.coc.begin(), f.coc.end())), 2.0f * set.extent });
    f.out = defocus_output_region(spec, f.data, extreme, o);
    out   = Plane(f.out.width(), f.out.height(), 4);
    std::fill_n(out.px.get(), out.size(), 0.0f);
    // Layers back to front: points by CoC step (descending), then by y.
    auto& points = set.points;
    std::sort(points.begin(), points.end(), [](const ScatterPoint& a, const ScatterPoint& b) {
        return std::get<0>(a.key) != std::get<0>(b.key) ? std::get<0>(a.key) > std::get<0>(b.key) : a.y < b.y;
    });
    // What hides a layer, over the output region grown by the PSFs' reach (the border
    // rule's pixels included): the coverage of the pixels in nearer layers.
    const int reach_all = int(std::ceil(set.extent));
    const OIIO::ROI grown(f.out.xbegin - reach_all, f.out.xend + reach_all, f.out.ybegin - reach_all,
                          f.out.yend + reach_all);
    const size_t gw = size_t(grown.width());
    std::vector<int64_t> grown_src(size_t(grown.npixels()));
    for (int y = grown.ybegin; y < grown.yend; ++y)
        for (int x = grown.xbegin; x < grown.xend; ++x)
            grown_src[size_t(y - grown.ybegin) * gw + size_t(x - grown.xbegin)] = f.source(x, y);
    std::vector<float> hides(grown_src.size());
    Plane layer(f.out.width(), f.out.height(), 4);
    for (size_t b = 0; b < points.size();) {
        const int64_t layer_step = std::get<0>(points[b].key);
        size_t e                 = b;
        while (e < points.size() && std::get<0>(points[e].key) == layer_step)
            ++e;
        std::fill_n(layer.px.get(), layer.size(), 0.0f);
        scatter_layer(layer, f, set, b, e, nthreads);
        bool any_nearer = false;
        for (size_t q = 0; q < grown_src.size(); ++q) {
            const int64_t i = grown_src[q];
            hides[q]        = i >= 0 && set.coc_step[size_t(i)] < layer_step ? f.img.rgba[size_t(i) * 4 + 3] : 0.0f;
            any_nearer      = any_nearer || hides[q] != 0.0f;
        }
        if (any_nearer)
            divide_by_nearer(layer, hides, *set.psfs.at(std::make_tuple(layer_step, 0, 0)), reach_all, gw, nthreads);
        parallel_for_chunks(0, out.h, 16, nthreads, [&](int64_t y0, int64_t y1) {
            for (int y = int(y0); y < int(y1); ++y) {
                float* d       = out.row(y);
                const float* l = layer.row(y);
                for (int x = 0; x < out.w; ++x, d += 4, l += 4) {
                    const float behind = 1.0f - l[3];
                    for (int c = 0; c < 4; ++c)
                        d[c] = l[c] + behind * d[c];
                }
            }
        });
        b = e;
    }
    return true;
}

bool detail::reference_layers(Plane& out, const Frame& f, const DefocusOptions& o, DefocusReport& rep, int nthreads,
                              std::string& err)
{
    if (!reference_range_fits(rep.min_coc_px, rep.max_coc_px, o.reference_step_px, err))
        return false;
    const Membership m = one_layer_per_coc(f, rep.min_coc_px, rep.max_coc_px, o.reference_step_px, nthreads);
    if (m.coc_px.size() > 65535) {
        err = format("{} distinct CoC values; raise the reference step", m.coc_px.size());
        return false;
    }
    rep.layer_coc_px    = m.coc_px;
    rep.layer_reduction = m.reduction;
    return composite_layers(out, f, m, o, nthreads, err);
}

}  // namespace bokeh
