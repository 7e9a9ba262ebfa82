// defocus_bands.cpp — a flat defocus past its memory budget, drawn in bands of output rows.
// The plan (the CoC range, the rungs and reductions, the output region) is made once over
// the whole frame; each band is then prepared from its own rows and the layers' reach about
// them, composited, filled and written into the result. A frame then holds its result and
// one band's working planes, not the whole frame's (docs/defocus.md, "Memory").
//
// The same pixels as the frame drawn at once, wherever no uncovered background is
// continued: a band's first output row lies on every layer's tile grid (kLayerTilePx
// times the largest reduction, counted from the output's origin), so each reduced buffer
// is cut at the same rows, and a band reads the source as far as the largest kernel (and
// the depth dilation) reaches past its rows, so no border rule acts inside the frame. The
// disocclusion fill's plate is built from the band's rows: its coarse cells see less than
// the whole frame, so a continuation wider than the reach can differ
// (tests/defocus/defocus_bands_test.cpp measures by how much).
//
// Lens character: the frame's highlights are ranked first, a stretch of rows at a time, and
// each band keeps those that rank above the frame's cut (max_sprites), so every band
// draws the sprites the frame drawn at once would; the bands then lie on the lens layer's
// grid too, and reach as far as a sprite's PSF and the block its sprites merge in.
//
// Iris mode: its exp space is set from the whole frame's colour range, found the same way
// (after the sprites are taken out), and given to every band.
//
// Limits: the gather method (blurred copies of the whole frame) and the predicted planner
// (frame-wide statistics) are drawn at once only; over the budget they are refused, saying
// so. Ranking the highlights, and iris mode's range, each prepare the frame once more.

#include <bokeh/defocus.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

// What a band holds, in bytes (the flat defocus's estimate, core/defocus/defocus.cpp): its
// source pixels prepared (RGBA 16, CoC 4, shares 6), its result plane (16 an output pixel)
// and the fill's pyramid (8).
constexpr double kBandSourceBytes = 26.0;
// Iris mode keeps the linear colour beside its exp space (16 bytes a source pixel more).
double band_source_bytes(const DefocusOptions& o) { return kBandSourceBytes + (o.iris != 0.0f ? 16.0 : 0.0); }
constexpr double kBandOutputBytes = 24.0;
// The result every band writes into: RGBA float an output pixel.
constexpr double kResultBytes = 16.0;

// Each pixel's signed CoC over the data window, as prepare_frame makes it (the depth
// dilation included), the depth read a row at a time: 4 bytes a pixel.
void frame_cocs(std::vector<float>& coc, const OIIO::ImageBuf& src, const CocOptions& lens, int dilate_px,
                int nthreads)
{
    const OIIO::ROI d   = src.roi();
    const int zc        = find_channels(src.spec()).z;  // resolve_coc_options found one
    const int width_px  = src.spec().full_width > 0 ? src.spec().full_width : d.width();
    const CocOfDepth coc_of(lens, width_px);
    coc.assign(size_t(d.width()) * size_t(d.height()), 0.0f);
    parallel_rows(d, nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            float* row = coc.data() + size_t(y - d.ybegin) * size_t(d.width());
            src.get_pixels(OIIO::ROI(d.xbegin, d.xend, y, y + 1, d.zbegin, d.zbegin + 1, zc, zc + 1),
                           OIIO::TypeFloat, row);
            for (int x = 0; x < d.width(); ++x)
                row[x] = coc_of(row[x]);
        }
    });
    if (dilate_px > 0)
        dilate_nearest(coc, d.width(), d.height(), dilate_px, nthreads);
}

// The rows of output a band draws: the most whose working planes, beside the result, fit
// the budget, a whole number of `align` rows; 0 when not even `align` rows fit.
int band_rows_for(const DefocusOptions& o, const OIIO::ROI& data, const OIIO::ROI& out, int align, int halo)
{
    const double up2    = double(o.supersample) * double(o.supersample);
    const double result = double(out.npixels()) * up2 * kResultBytes;
    int best            = 0;
    for (int rows = align; rows < out.height() + align; rows += align) {
        const double read  = double(std::min(rows + 2 * halo, data.height())) * double(data.width());
        const double bytes = read * band_source_bytes(o) + double(rows) * double(out.width()) * up2 * kBandOutputBytes;
        if (result + bytes > double(o.memory_budget_bytes))
            break;
        best = rows;
    }
    return best;
}

// Lens character over the whole frame: its highlights ranked a stretch of rows at a time
// (each prepared without sprites, as prepare_frame prepares it), the max_sprites best kept
// as they come; the cut (the last kept, when there were more), the count, and the reach of
// the kept ones' PSFs (fetched into the process's cache, where the bands find them).
struct FrameSprites {
    SpriteCut cut;
    int64_t candidates = 0;
    int64_t kept       = 0;
    float extent_px    = 0.0f;
    size_t psfs        = 0;
    float min_coc_px = 0.0f, max_coc_px = 0.0f;
    std::vector<float> coc_px;  // each kept sprite's
};

// The frame prepared a stretch of rows at a time (half the budget of prepared pixels, 26
// bytes each, and the depth dilation's reach about them), with options `o` and lens
// character's cut `cut`: `fn(f, y0, y1)` for each, rows [y0, y1) its own. False + `err`.
template <class Fn>
bool for_each_stretch(const OIIO::ImageBuf& src, const DefocusOptions& o, const SpriteCut& cut, int nthreads,
                      std::string& err, Fn fn)
{
    const OIIO::ROI data = src.roi();
    const int stretch    = int(std::clamp(double(o.memory_budget_bytes) / 2.0 / (26.0 * double(data.width())),
                                          16.0, double(data.height())));
    for (int y0 = data.ybegin; y0 < data.yend; y0 += stretch) {
        const int y1 = std::min(data.yend, y0 + stretch);
        FrameBand rows;
        rows.read           = data;
        rows.read.ybegin    = std::max(data.ybegin, y0 - o.depth_dilate_px);
        rows.read.yend      = std::min(data.yend, y1 + o.depth_dilate_px);
        rows.out            = data;
        rows.counted_ybegin = y0, rows.counted_yend = y1;
        rows.sprite_cut        = cut;
        rows.sprite_cut.offset = int64_t(rows.read.ybegin - data.ybegin) * int64_t(data.width());
        Frame f;
        DefocusReport part;
        if (!prepare_frame(f, src, o, part, nthreads, err, &rows))
            return false;
        fn(f, y0, y1);
    }
    return true;
}

bool frame_sprites(FrameSprites& fs, const OIIO::ImageBuf& src, const DefocusOptions& o, int nthreads,
                   std::string& err)
{
    const OIIO::ROI data = src.roi();
    const int64_t w      = data.width();
    struct Ranked {
        float key;
        int64_t at;
        int x, y;
        float coc_px;
    };
    auto ranks_first = [](const Ranked& a, const Ranked& b) { return outranks(a.key, a.at, b.key, b.at); };
    const size_t most = size_t(o.max_sprites);
    std::vector<Ranked> best;
    DefocusOptions plain = o;
    plain.lens_character = false;
    plain.iris           = 0.0f;  // the highlights are taken out in linear light
    const bool ok = for_each_stretch(src, plain, SpriteCut(), nthreads, err, [&](const Frame& f, int y0, int y1) {
        for (int y = y0; y < y1; ++y)
            for (int x = data.xbegin; x < data.xend; ++x) {
                const size_t i = f.img.index(x, y);
                float lum;
                const float share = sprite_share(f.img.rgba.data() + i * 4, o.highlight_threshold, lum);
                if (!(share > 0.0f))
                    continue;
                ++fs.candidates;
                best.push_back({ share * lum, int64_t(y - data.ybegin) * w + int64_t(x - data.xbegin), x, y,
                                 f.coc[i] });
            }
        if (best.size() > 2 * most) {
            std::nth_element(best.begin(), best.begin() + std::ptrdiff_t(most), best.end(), ranks_first);
            best.resize(most);
        }
    });
    if (!ok)
        return false;
    if (best.size() > most) {
        std::nth_element(best.begin(), best.begin() + std::ptrdiff_t(most), best.end(), ranks_first);
        best.resize(most);
    }
    if (fs.candidates > int64_t(most) && !best.empty()) {
        const Ranked& last = *std::max_element(best.begin(), best.end(), ranks_first);
        fs.cut.active      = true;
        fs.cut.key         = last.key;
        fs.cut.at          = last.at;
    }
    fs.kept = int64_t(best.size());
    LensCharacter lens;
    if (!defocus_lens(o, src.spec(), lens, err))
        return false;
    SpriteSet set;
    for (const Ranked& r : best) {
        Sprite sp;
        sp.x = r.x, sp.y = r.y, sp.coc_px = r.coc_px;
        set.sprites.push_back(sp);
        fs.min_coc_px = set.sprites.size() == 1 ? r.coc_px : std::min(fs.min_coc_px, r.coc_px);
        fs.max_coc_px = set.sprites.size() == 1 ? r.coc_px : std::max(fs.max_coc_px, r.coc_px);
        fs.coc_px.push_back(r.coc_px);
    }
    if (!fetch_sprite_psfs(set, *shared_psf_cache(lens, nthreads), FieldFrame(src.spec(), lens), o.supersample,
                           nthreads, err))
        return false;
    fs.extent_px = set.extent_px;
    fs.psfs      = set.psfs;
    return true;
}

// Iris mode over the whole frame: its exp space from the colour range of every stretch of
// rows, prepared as a band prepares them (sprites taken out by the frame's cut), as
// prepare_frame sets it for the frame at once.
bool frame_iris(IrisSpace& iris, const OIIO::ImageBuf& src, const DefocusOptions& o, const SpriteCut& cut,
                int nthreads, std::string& err)
{
    IrisRange range;
    DefocusOptions linear = o;
    linear.iris           = 0.0f;
    if (!for_each_stretch(src, linear, cut, nthreads, err,
                          [&](const Frame& f, int, int) { iris_channel_range(f, range); }))
        return false;
    return iris_space_for(o.iris, range, iris, err);
}

// The plan of the whole frame (its CoC range in `rep`, the rungs and reductions), from its
// CoCs alone, as the frame at once would make it.
bool plan_whole_frame(LayerPlan& plan, DefocusReport& rep, const OIIO::ImageBuf& src, const DefocusOptions& o,
                      int nthreads, std::string& err)
{
    Frame whole;
    frame_cocs(whole.coc, src, o.coc, o.depth_dilate_px, nthreads);
    const auto [lo, hi] = std::minmax_element(whole.coc.begin(), whole.coc.end());
    rep.min_coc_px      = whole.coc.empty() ? 0.0f : *lo;
    rep.max_coc_px      = whole.coc.empty() ? 0.0f : *hi;
    if (rep.method != DefocusMethod::Reference) {
        plan = choose_layer_plan(whole, o, rep.min_coc_px, rep.max_coc_px, nthreads, rep.plans);
        return true;
    }
    if (!reference_range_fits(rep.min_coc_px, rep.max_coc_px, o.reference_step_px, err))
        return false;
    plan.coc_px = reference_rungs(whole.coc, rep.min_coc_px, rep.max_coc_px, o.reference_step_px);
    plan.reduction.assign(plan.coc_px.size(), 1);
    return true;
}

// Where the bands lie: the source's data window, the output region, the output rows a band
// draws, the rows past them it reads, and how many bands.
struct BandGeometry {
    OIIO::ROI data, out;
    int rows, halo, bands;
};

// Band `b`'s output rows, the source rows it reads, and the source rows whose non-finite
// values it counts (each row once: by the band whose output rows hold it).
FrameBand band_at(const BandGeometry& g, int b)
{
    FrameBand band;
    band.out         = g.out;
    band.out.ybegin  = g.out.ybegin + b * g.rows;
    band.out.yend    = std::min(g.out.yend, band.out.ybegin + g.rows);
    band.read        = g.data;
    band.read.ybegin = std::clamp(band.out.ybegin - g.halo, g.data.ybegin, g.data.yend - 1);
    band.read.yend   = std::clamp(band.out.yend + g.halo, band.read.ybegin + 1, g.data.yend);
    band.counted_ybegin = b == 0 ? g.data.ybegin : std::clamp(band.out.ybegin, g.data.ybegin, g.data.yend);
    band.counted_yend   = b + 1 == g.bands ? g.data.yend : std::clamp(band.out.yend, g.data.ybegin, g.data.yend);
    return band;
}

// One band: prepared from its rows, its layers composited on the frame's plan, the
// uncovered background filled, and its rows written into `dst` (begun by the first band,
// `begun` false: it knows whether the source has alpha). What it reports is added to `rep`.
bool draw_band(OIIO::ImageBuf& dst, bool& begun, DefocusReport& rep, const OIIO::ImageBuf& src,
               const DefocusOptions& o, const LayerPlan& plan, const std::vector<float>& gain_floors,
               const FrameBand& band, const OIIO::ROI& out, int nthreads, std::string& err)
{
    const int up = o.supersample;
    DefocusReport part;
    Frame f;
    if (!prepare_frame(f, src, o, part, nthreads, err, &band))
        return false;
    f.sprite_gain_floors = gain_floors;  // the whole frame's sprites, as the frame at once
    if (!begun)
        begin_result(dst, src.spec(), f.lens, scaled_roi(out, up), up, f.img.has_alpha);
    begun = true;
    Plane plane(f.out.width() * up, f.out.height() * up, 4);
    std::fill_n(plane.px.get(), plane.size(), 0.0f);
    const Membership m = layer_membership(f, plan, nthreads);
    if (!composite_layers(plane, f, m, o, nthreads, err))
        return false;
    fill_uncovered(plane, f, o, part, nthreads);
    report_sprites(part, f.sprites.get());
    write_result_rows(dst, plane, f.out.xbegin * up, f.out.ybegin * up, nthreads);
    rep.sprites_drawn += part.sprites_drawn;
    rep.sprite_seconds += part.sprite_seconds;
    rep.nonfinite.colour += part.nonfinite.colour;
    rep.nonfinite.depth += part.nonfinite.depth;
    rep.fill_continued_px += part.fill_continued_px;
    rep.fill_foreground_px += part.fill_foreground_px;
    return true;
}

}  // namespace

bool detail::defocus_bands_allowed(const DefocusOptions& o, std::string& why)
{
    if (o.method == DefocusMethod::Gather)
        why = "the gather method blurs copies of the whole frame and is not drawn in bands";
    else if (o.planner == DefocusPlanner::Predicted)
        why = "the predicted planner weighs the whole frame and is not drawn in bands";
    else
        return true;
    return false;
}

bool detail::defocus_in_bands(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
                              DefocusReport* report, int nthreads)
{
    std::string err;
    DefocusOptions o = opts;
    if (!resolve_coc_options(o.coc, src, err)) {  // focus by pixel made a distance, once
        dst.errorfmt("defocus: {}", err);
        return false;
    }
    const OIIO::ROI data = src.roi();
    DefocusReport rep;
    rep.method = o.method == DefocusMethod::Auto ? DefocusMethod::Layers : o.method;

    // The plan over the whole frame, from its CoCs alone.
    LayerPlan plan;
    if (!plan_whole_frame(plan, rep, src, o, nthreads, err)) {
        dst.errorfmt("defocus: {}", err);
        return false;
    }
    rep.layer_coc_px    = plan.coc_px;
    rep.layer_reduction = plan.reduction;
    FrameSprites sprites;
    const auto t0 = std::chrono::steady_clock::now();
    if (o.lens_character && !frame_sprites(sprites, src, o, nthreads, err)) {
        dst.errorfmt("defocus: {}", err);
        return false;
    }
    rep.sprite_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    IrisSpace iris;
    if (o.iris != 0.0f && !frame_iris(iris, src, o, sprites.cut, nthreads, err)) {
        dst.errorfmt("defocus: {}", err);
        return false;
    }

    // Sprites spread as far as their PSFs (prepare_frame's output region).
    const float extreme = std::max({ -rep.min_coc_px, rep.max_coc_px, 2.0f * sprites.extent_px });
    const OIIO::ROI out = defocus_output_region(src.spec(), data, extreme, o);
    const int reduction = plan.reduction.empty() ? 1 : *std::max_element(plan.reduction.begin(), plan.reduction.end());
    // Every layer's tile grid: 64 px times its reduction, and with lens character 256 px
    // for the in-focus rung blurred with the lens's PSF (reduction 1: defocus_sprites.cpp).
    const int align = std::max(kLayerTilePx * reduction, o.lens_character ? kLensLayerTilePx : 0);
    // How far past its rows a band reads: the largest kernel's half height (or a sprite's
    // PSF's), a reduced buffer's box and bilinear read on either side, the depth dilation's
    // square, and a sprite block (up to 8 px: draw_layer_sprites merges a block's sprites).
    const int halo = int(std::ceil(std::max(0.5f * extreme * o.aspect, sprites.extent_px))) + 4 * reduction + 2
                     + o.depth_dilate_px + (o.lens_character ? 8 : 0);
    const int rows = band_rows_for(o, data, out, align, halo);
    if (rows == 0) {
        const double up2 = double(o.supersample) * double(o.supersample);
        const double least =
            double(out.npixels()) * up2 * kResultBytes
            + double(std::min(align + 2 * halo, data.height())) * double(data.width()) * band_source_bytes(o)
            + double(align) * double(out.width()) * up2 * kBandOutputBytes;
        within_defocus_memory(o, least,
                              format("the defocus of {}x{} pixels in bands of {} rows", data.width(), data.height(),
                                     align * o.supersample),
                              "", err);
        dst.errorfmt("defocus: {}", err);
        return false;
    }
    rep.bands     = (out.height() + rows - 1) / rows;
    rep.band_rows = rows * o.supersample;

    const BandGeometry geometry{ data, out, rows, halo, rep.bands };
    const std::vector<float> gain_floors =
        o.lens_character ? sprite_gain_floors(sprites.coc_px, plan.coc_px) : std::vector<float>();
    bool begun = false;
    for (int b = 0; b < rep.bands; ++b) {
        FrameBand band = band_at(geometry, b);
        band.min_coc_px        = rep.min_coc_px;
        band.max_coc_px        = rep.max_coc_px;
        band.sprite_cut        = sprites.cut;
        band.sprite_cut.offset = int64_t(band.read.ybegin - data.ybegin) * int64_t(data.width());
        band.iris_known        = o.iris != 0.0f;
        band.iris              = iris;
        DefocusOptions ob = o;
        if (o.progress)
            ob.progress = [&, b](float p) { o.progress((float(b) + p) / float(rep.bands)); };
        if (!draw_band(dst, begun, rep, src, ob, plan, gain_floors, band, out, nthreads, err)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
    }
    if (o.lens_character) {
        rep.lens_character    = true;
        rep.sprites           = sprites.kept;
        rep.sprite_candidates = sprites.candidates;
        rep.sprite_psfs       = sprites.psfs;
        rep.sprite_min_coc_px = sprites.min_coc_px;
        rep.sprite_max_coc_px = sprites.max_coc_px;
    }
    summarise_defocus(rep, out.width() * o.supersample, out.height() * o.supersample);
    if (report)
        *report = std::move(rep);
    return true;
}

}  // namespace bokeh
