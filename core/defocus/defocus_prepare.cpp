// defocus_prepare.cpp — a flat RGBA + Z image made ready for a defocus: its pixels
// premultiplied and scrubbed of non-finite values, each pixel's signed CoC from its depth
// (the thin-lens formula, lens.h), the nearest-depth dilation, bloom, the highlights taken
// out for the lens's sprites, iris mode's exp space, and the output region.
//
// Iris mode (the source talk's highlight emphasis, log(mean(exp(k x))) / k): colour is
// carried as A (exp(k (colour / A - shift)) - 1), so each layer averages exp(k x)
// weighted by coverage and comes back by shift + log(1 + mean) / k (IrisSpace).

#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

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

// Iris mode: f.img's colour into iris space `iris` (see IrisSpace), the linear copy kept for
// the disocclusion fill.
void to_iris_space(Frame& f, const IrisSpace& iris, int nthreads)
{
    f.iris        = iris;
    f.linear_rgba = f.img.rgba;
    const double k = double(iris.k);
    parallel_for_chunks(0, int64_t(f.img.rgba.size() / 4), 4096, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i) {
            float* p = f.img.rgba.data() + size_t(i) * 4;
            for (size_t c = 0; c < 3; ++c)
                p[c] = p[3] > 0.0f ? p[3] * float(std::expm1(k * (double(p[c]) / p[3] - f.iris.shift[c])))
                                   : 0.0f;
        }
    });
}

}  // namespace

void detail::iris_channel_range(const Frame& f, IrisRange& range)
{
    auto& [lo, hi] = range;
    for (size_t i = 0; i < f.img.rgba.size(); i += 4)
        if (f.img.rgba[i + 3] > 0.0f)
            for (size_t c = 0; c < 3; ++c) {
                const float x = f.img.rgba[i + c] / f.img.rgba[i + 3];
                lo[c]         = std::min(lo[c], x);
                hi[c]         = std::max(hi[c], x);
            }
}

bool detail::iris_space_for(float k, IrisRange range, IrisSpace& iris, std::string& err)
{
    auto& [lo, hi] = range;
    iris.k = k;
    for (size_t c = 0; c < 3; ++c) {
        if (!(hi[c] >= lo[c]))
            lo[c] = hi[c] = 0.0f;  // no covered pixel
        if (std::abs(double(k)) * (double(hi[c]) - double(lo[c])) > kIrisMaxExponent) {
            err = format("iris {} times channel {}'s range {} .. {} exceeds {}: exp() would span "
                         "more digits than the sums keep; lower iris",
                         k, "RGB"[c], lo[c], hi[c], kIrisMaxExponent);
            return false;
        }
        iris.shift[c] = k > 0.0f ? lo[c] : hi[c];
    }
    return true;
}

// A separable min filter: the (2r + 1)^2 square's min is the min over its rows of each
// row's min.
void detail::dilate_nearest(std::vector<float>& coc, int w, int h, int r, int nthreads)
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

// Everything but the method: the scrubbed, premultiplied pixels, their CoC, the regions.
bool detail::prepare_frame(Frame& f, const OIIO::ImageBuf& src, const DefocusOptions& o, DefocusReport& rep,
                           int nthreads, std::string& err, const FrameBand* band)
{
    if (!check_defocus_options(o, err))
        return false;
    if (src.deep()) {
        err = "a deep image cannot be defocused here; flatten it first (--flatten)";
        return false;
    }
    CocOptions coc = o.coc;
    if (!resolve_coc_options(coc, src, err)
        || !to_work_image(f.img, src, err, nthreads, band ? band->read : OIIO::ROI()))
        return false;
    f.lens = coc;
    // The bad-value policy (docs/robustness.md): colour -> 0, depth -> far ("no depth"), counted.
    using Counts  = std::array<int64_t, 2>;
    const int64_t npx = int64_t(f.img.z.size());
    // A band counts its own rows only (its reach about them is another band's).
    const int64_t row_px        = int64_t(f.img.width());
    const int64_t counted_begin = band ? (band->counted_ybegin - f.img.roi.ybegin) * row_px : 0;
    const int64_t counted_end   = band ? (band->counted_yend - f.img.roi.ybegin) * row_px : npx;
    const Counts bad  = parallel_reduce_chunks(
        0, npx, 1 << 14, nthreads, Counts{ 0, 0 },
        [&](int64_t b, int64_t e) {
            Counts n{ 0, 0 };
            for (int64_t i = b; i < e; ++i) {
                const bool counted = i >= counted_begin && i < counted_end;
                float* px          = f.img.rgba.data() + size_t(i) * 4;
                for (int c = 0; c < 4; ++c)
                    if (!std::isfinite(px[c])) {
                        px[c] = 0.0f;
                        n[0] += counted;
                    }
                const float z = f.img.z[size_t(i)];
                n[1] += counted && (std::isnan(z) || z == -std::numeric_limits<float>::infinity());
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
    // The CoC stands for the depth from here on: computed in the depth's own plane, so the
    // frame never holds both while the input is still alive (the defocus's memory peak:
    // docs/defocus.md, "Memory").
    parallel_for_chunks(0, npx, 1 << 14, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i)
            f.img.z[size_t(i)] = coc_of(f.img.z[size_t(i)]);
    });
    f.coc = std::move(f.img.z);
    f.img.z.clear();
    f.data   = f.img.roi;
    f.border = o.border;
    f.up     = o.supersample;
    if (o.depth_dilate_px > 0)
        detail::dilate_nearest(f.coc, f.data.width(), f.data.height(), o.depth_dilate_px, nthreads);
    if (o.bloom_gain != 1.0f)
        apply_bloom(f.img, o.bloom_threshold, o.bloom_gain, nthreads);
    // Highlights leave the layers in linear light (before iris mode's exp space).
    if (o.lens_character
        && !(band ? select_sprites(f, o, src.spec(), nthreads, err, &band->sprite_cut, band->counted_ybegin,
                                   band->counted_yend)
                  : select_sprites(f, o, src.spec(), nthreads, err)))
        return false;
    if (o.iris != 0.0f) {
        IrisSpace iris;
        if (band && band->iris_known) {
            iris = band->iris;
        } else {
            IrisRange range;
            iris_channel_range(f, range);
            if (!iris_space_for(o.iris, range, iris, err))
                return false;
        }
        to_iris_space(f, iris, nthreads);
    }

    if (band) {  // the frame's range and the band's rows
        rep.min_coc_px = band->min_coc_px;
        rep.max_coc_px = band->max_coc_px;
        f.out          = band->out;
        return true;
    }
    const auto [lo, hi] = std::minmax_element(f.coc.begin(), f.coc.end());
    rep.min_coc_px      = f.coc.empty() ? 0.0f : *lo;
    rep.max_coc_px      = f.coc.empty() ? 0.0f : *hi;
    // Sprites spread as far as their PSFs (aberrations can reach past the CoC).
    const float extreme = std::max({ -rep.min_coc_px, rep.max_coc_px,
                                     f.sprites ? 2.0f * f.sprites->extent_px : 0.0f });
    f.out               = defocus_output_region(src.spec(), f.data, extreme, o);
    return true;
}

}  // namespace bokeh
