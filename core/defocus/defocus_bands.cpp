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
// Limits: lens character (its highlights are chosen over the whole frame), iris mode (its
// exp space is set by the frame's colour range), the gather method (blurred copies of the
// whole frame) and the predicted planner (frame-wide statistics) are drawn at once only;
// over the budget they are refused, saying so.

#include <bokeh/defocus.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <cmath>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

// What a band holds, in bytes (the flat defocus's estimate, core/defocus/defocus.cpp): its
// source pixels prepared (RGBA 16, CoC 4, shares 6), its result plane (16 an output pixel)
// and the fill's pyramid (8).
constexpr double kBandSourceBytes = 26.0;
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
        const double bytes = read * kBandSourceBytes + double(rows) * double(out.width()) * up2 * kBandOutputBytes;
        if (result + bytes > double(o.memory_budget_bytes))
            break;
        best = rows;
    }
    return best;
}

}  // namespace

bool detail::defocus_bands_allowed(const DefocusOptions& o, std::string& why)
{
    if (o.lens_character)
        why = "lens character chooses its highlights over the whole frame and is not drawn in bands";
    else if (o.iris != 0.0f)
        why = "iris mode's exp space is set by the whole frame's colours and is not drawn in bands";
    else if (o.method == DefocusMethod::Gather)
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
    {
        Frame whole;
        frame_cocs(whole.coc, src, o.coc, o.depth_dilate_px, nthreads);
        const auto [lo, hi] = std::minmax_element(whole.coc.begin(), whole.coc.end());
        rep.min_coc_px      = whole.coc.empty() ? 0.0f : *lo;
        rep.max_coc_px      = whole.coc.empty() ? 0.0f : *hi;
        if (rep.method == DefocusMethod::Reference) {
            if ((rep.max_coc_px - rep.min_coc_px) / o.reference_step_px > 65535.0f) {
                dst.errorfmt("defocus: CoC range {} .. {} px holds too many {} px steps; raise the reference step",
                             rep.min_coc_px, rep.max_coc_px, o.reference_step_px);
                return false;
            }
            plan.coc_px = reference_rungs(whole.coc, rep.min_coc_px, rep.max_coc_px, o.reference_step_px);
            plan.reduction.assign(plan.coc_px.size(), 1);
        } else {
            plan = choose_layer_plan(whole, o, rep.min_coc_px, rep.max_coc_px, nthreads, rep.plans);
        }
    }
    rep.layer_coc_px    = plan.coc_px;
    rep.layer_reduction = plan.reduction;

    const float extreme = std::max(-rep.min_coc_px, rep.max_coc_px);
    const OIIO::ROI out = defocus_output_region(src.spec(), data, extreme, o);
    const int reduction = plan.reduction.empty() ? 1 : *std::max_element(plan.reduction.begin(), plan.reduction.end());
    const int align     = kLayerTilePx * reduction;
    // How far past its rows a band reads: the largest kernel's half height, a reduced
    // buffer's box and bilinear read on either side, the depth dilation's square.
    const int halo = int(std::ceil(0.5f * extreme * o.aspect)) + 4 * reduction + 2 + o.depth_dilate_px;
    const int rows = band_rows_for(o, data, out, align, halo);
    if (rows == 0) {
        const double up2 = double(o.supersample) * double(o.supersample);
        const double least =
            double(out.npixels()) * up2 * kResultBytes
            + double(std::min(align + 2 * halo, data.height())) * double(data.width()) * kBandSourceBytes
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

    const OIIO::ImageSpec& spec = src.spec();
    const int up                = o.supersample;
    bool alpha_known            = false;
    for (int b = 0; b < rep.bands; ++b) {
        FrameBand band;
        band.out        = out;
        band.out.ybegin = out.ybegin + b * rows;
        band.out.yend   = std::min(out.yend, band.out.ybegin + rows);
        band.read       = data;
        band.read.ybegin = std::clamp(band.out.ybegin - halo, data.ybegin, data.yend - 1);
        band.read.yend   = std::clamp(band.out.yend + halo, band.read.ybegin + 1, data.yend);
        // Each source row counted by the band whose output rows hold it.
        band.counted_ybegin = b == 0 ? data.ybegin : std::clamp(band.out.ybegin, data.ybegin, data.yend);
        band.counted_yend = b + 1 == rep.bands ? data.yend : std::clamp(band.out.yend, data.ybegin, data.yend);
        band.min_coc_px   = rep.min_coc_px;
        band.max_coc_px   = rep.max_coc_px;

        DefocusOptions ob = o;
        if (o.progress)
            ob.progress = [&, b](float p) { o.progress((float(b) + p) / float(rep.bands)); };
        DefocusReport part;
        Frame f;
        if (!prepare_frame(f, src, ob, part, nthreads, err, &band)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
        if (!alpha_known) {
            begin_result(dst, spec, f.lens, scaled_roi(out, up), up, f.img.has_alpha);
            alpha_known = true;
        }
        Plane plane(f.out.width() * up, f.out.height() * up, 4);
        std::fill_n(plane.px.get(), plane.size(), 0.0f);
        const Membership m = layer_membership(f, plan, nthreads);
        if (!composite_layers(plane, f, m, ob, nthreads, err)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
        fill_uncovered(plane, f, ob, part, nthreads);
        write_result_rows(dst, plane, f.out.xbegin * up, f.out.ybegin * up, nthreads);
        rep.nonfinite.colour += part.nonfinite.colour;
        rep.nonfinite.depth += part.nonfinite.depth;
        rep.fill_continued_px += part.fill_continued_px;
        rep.fill_foreground_px += part.fill_foreground_px;
    }
    summarise_defocus(rep, out.width() * up, out.height() * up);
    if (report)
        *report = std::move(rep);
    return true;
}

}  // namespace bokeh
