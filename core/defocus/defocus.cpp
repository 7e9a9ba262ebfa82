// defocus.cpp — depth defocus of a flat RGBA + Z image: the options checked, the frame
// prepared (core/defocus/defocus_prepare.cpp) and the method dispatched.
//
// The methods, each in its own file:
// * Layers (auto): the planner's layers (core/defocus/defocus_plan.cpp) blurred and composited by
//   the layer engine (core/defocus/defocus_engine.cpp, where the layer model is written out).
// * Reference: one full-resolution layer a distinct CoC through the same engine; and the
//   brute-force scatter, every pixel with its own PSF (core/defocus/defocus_reference.cpp).
// * Gather (core/defocus/defocus_gather.cpp): the source talk's first method as published,
//   blurred copies at a few representative CoCs blended per pixel.
// * Lens character (core/defocus/defocus_sprites.cpp): highlights drawn as the lens's PSF into the
//   layer of their depth; sub-aperture views (core/defocus/defocus_views.cpp): the layers
//   composited once a cell of the pupil; a deep image (core/defocus/defocus_deep.cpp): the layers
//   come ready made from its samples.
// * Past the memory budget, a flat frame is drawn in bands of output rows
//   (core/defocus/defocus_bands.cpp), the same plan for every band.
//
// Known limits of the model: a flat image holds no background behind its foreground, so
// the hidden background is extrapolated from its visible neighbours (deep images remove
// this: deep.h); alpha is taken as coverage, so a semi-transparent pixel lets the layers
// behind it through.

#include <bokeh/defocus.h>
#include <bokeh/io.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_fill.h"
#include "defocus/defocus_layers.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

constexpr const char* kDeepResultNeedsDeep = "a deep result needs a deep image (--deepen makes one)";

std::string fill_summary(const DefocusReport& rep)
{
    if (rep.fill_continued_px == 0 && rep.fill_foreground_px == 0)
        return std::string();
    return format(", uncovered background: {} px continued, {} px the foreground's own colour",
                  rep.fill_continued_px, rep.fill_foreground_px);
}

}  // namespace

void detail::fill_uncovered(Plane& out, const Frame& f, const DefocusOptions& o, DefocusReport& rep, int nthreads)
{
    std::unique_ptr<BackgroundPlate> plate;
    if (o.fill != DisocclusionFill::Foreground)
        plate = std::make_unique<BackgroundPlate>(f, nthreads);
    const PlateFill how = o.fill == DisocclusionFill::Mirror ? PlateFill::Mirror : PlateFill::Smooth;
    const FillCount n      = fill_disocclusions(out, f, rep.max_coc_px, plate.get(), how, nthreads);
    rep.fill_continued_px += n.continued;
    rep.fill_foreground_px += n.foreground;
}

void detail::summarise_defocus(DefocusReport& rep, int width, int height)
{
    rep.summary = format("{}: CoC {:.1f} .. {:.1f} px, {} layers, output {}x{}{}{}{}{}", method_name(rep.method),
                         rep.min_coc_px, rep.max_coc_px, rep.layer_coc_px.size(), width, height,
                         rep.bands > 1 ? format(", in {} bands of {} rows (memory budget)", rep.bands,
                                                rep.band_rows)
                                       : std::string(),
                         fill_summary(rep),
                         rep.nonfinite.total() ? format(", {} non-finite values replaced",
                                                        rep.nonfinite.total())
                                               : std::string(),
                         sprite_summary(rep));
}

bool check_defocus_options(const DefocusOptions& o, std::string& err)
{
    if (!check_aperture(o.aperture, o.aspect, err))
        return false;
    if (o.layers < 0 || o.layers > 1024) {
        err = format("layers {} is outside 0..1024 (0: automatic)", o.layers);
        return false;
    }
    if (!(o.ladder_ratio == 0.0f || (o.ladder_ratio >= 1.0f && o.ladder_ratio <= 16.0f))) {
        err = format("ladder ratio {} is outside 1..16 (0: the planner's)", o.ladder_ratio);
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
    if (o.aperture_views < 0 || o.aperture_views > 8) {
        err = format("views {} is outside 0..8", o.aperture_views);
        return false;
    }
    if (o.aperture_views > 1 && o.aperture.shape != KernelShape::Disk && o.aperture.shape != KernelShape::Polygon
        && o.aperture.shape != KernelShape::Opening && o.aperture.shape != KernelShape::Box) {
        err = "views cut the pupil of a disk, polygon, star or box aperture; this one has no pupil edge to cut "
              "within";
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

// The frame's working planes given back (before the result is allocated).
void release_pixels(Frame& f)
{
    for (std::vector<float>* v : { &f.img.rgba, &f.img.z, &f.coc, &f.linear_rgba })
        std::vector<float>().swap(*v);
}

}  // namespace

void detail::begin_result(OIIO::ImageBuf& dst, const OIIO::ImageSpec& src_spec, const CocOptions& lens,
                          const OIIO::ROI& region, int up, bool alpha)
{
    OIIO::ImageSpec spec = derived_spec(src_spec, alpha ? std::vector<std::string>{ "R", "G", "B", "A" }
                                                        : std::vector<std::string>{ "R", "G", "B" },
                                        region);
    scale_display_window(spec, src_spec, up);
    record_lens(spec, lens);
    reset_uninitialised(dst, spec);
}

void detail::write_result_rows(OIIO::ImageBuf& dst, const Plane& out, int x0, int y0, int nthreads)
{
    const int nc = dst.nchannels();
    parallel_for_chunks(0, out.h, 16, nthreads, [&](int64_t r0, int64_t r1) {
        for (int y = int(r0); y < int(r1); ++y) {
            float* d       = static_cast<float*>(dst.pixeladdr(x0, y0 + y));
            const float* s = out.row(y);
            for (int x = 0; x < out.w; ++x)
                for (int c = 0; c < nc; ++c)
                    d[size_t(x) * size_t(nc) + size_t(c)] = s[size_t(x) * 4 + size_t(c)];
        }
    });
}

bool detail::within_defocus_memory(const DefocusOptions& o, double bytes, const std::string& what,
                                   const std::string& remedy, std::string& err)
{
    if (o.memory_budget_bytes <= 0 || bytes <= double(o.memory_budget_bytes))
        return true;
    std::string why = o.memory_budget_hint;
    if (!remedy.empty())
        why += (why.empty() ? "" : "; ") + remedy;
    err = format("{} would take {}, over the memory budget of {}{}", what,
                 bytes >= 9.2e18 ? std::string("more than 8 EiB") : memory_size_text(int64_t(bytes)),
                 memory_size_text(o.memory_budget_bytes), why.empty() ? std::string() : " (" + why + ")");
    return false;
}

bool defocus(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts,
             DefocusReport* report, int nthreads)
{
    if (src.initialized() && src.deep())
        return defocus_deep(dst, src, opts, report, nthreads);
    DefocusReport rep;
    Frame f;
    std::string err;
    if (src.initialized()) {
        // What the flat defocus holds at its peak (the disocclusion fill), measured on lights
        // at 3840x2160 (heaptrack): the working RGBA (16 bytes a source pixel), CoC (4) and
        // shares (6); the result plane (16 an output pixel), the fill's pyramid (8) and the
        // result as an image (16, after the frame is given back). The output is at most the
        // display and data windows joined, times the supersampling.
        const OIIO::ROI data = src.roi();
        const OIIO::ROI out  = defocus_output_bound(src.spec(), data, opts.grow);
        const double up2     = double(opts.supersample) * double(opts.supersample);
        const double bytes   = double(data.npixels()) * (26.0 + (opts.iris != 0.0f ? 16.0 : 0.0))
                             + double(out.npixels()) * up2 * 32.0;
        if (opts.memory_budget_bytes > 0 && bytes > double(opts.memory_budget_bytes)) {
            // Over the budget at once: in bands of output rows when the options allow it.
            std::string why;
            if (!check_defocus_options(opts, err)) {
                dst.errorfmt("defocus: {}", err);
                return false;
            }
            if (opts.deep_output) {
                dst.errorfmt("defocus: {}", kDeepResultNeedsDeep);
                return false;
            }
            if (defocus_bands_allowed(opts, why))
                return defocus_in_bands(dst, src, opts, report, nthreads);
            within_defocus_memory(opts, bytes, format("the defocus of {}x{} pixels into {}x{}", data.width(),
                                                      data.height(), out.width() * opts.supersample,
                                                      out.height() * opts.supersample),
                                  why, err);
            dst.errorfmt("defocus: {}", err);
            return false;
        }
    }
    if (!prepare_frame(f, src, opts, rep, nthreads, err)) {
        dst.errorfmt("defocus: {}", err);
        return false;
    }
    if (opts.deep_output) {
        dst.errorfmt("defocus: {}", kDeepResultNeedsDeep);
        return false;
    }
    // The frame holds the pixels from here on: the source's spec is all the result needs.
    const OIIO::ImageSpec src_spec = src.spec();
    if (opts.source_done)
        opts.source_done();
    rep.method = opts.method == DefocusMethod::Auto ? DefocusMethod::Layers : opts.method;
    Plane out(f.out.width() * f.up, f.out.height() * f.up, 4);
    std::fill_n(out.px.get(), out.size(), 0.0f);
    switch (rep.method) {
    case DefocusMethod::Gather:
        gather(out, f, opts, rep.min_coc_px, rep.max_coc_px, nthreads);
        from_iris_space(out, f.iris);  // the blend of levels, averaged in iris space
        break;
    case DefocusMethod::Reference:
        if (!reference_layers(out, f, opts, rep, nthreads, err)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
        break;
    default: {
        const Membership m  = layer_plan(f, opts, rep.min_coc_px, rep.max_coc_px, nthreads, &rep.plans);
        rep.layer_coc_px    = m.coc_px;
        rep.layer_reduction = m.reduction;
        if (!composite_layers(out, f, m, opts, nthreads, err)) {
            dst.errorfmt("defocus: {}", err);
            return false;
        }
    }
    }
    if (rep.method != DefocusMethod::Gather)
        fill_uncovered(out, f, opts, rep, nthreads);
    report_sprites(rep, f.sprites.get());
    // The frame's pixels are done with: given back before the result is allocated, the
    // peak is the larger of the two, not their sum.
    release_pixels(f);
    summarise_defocus(rep, out.w, out.h);
    const OIIO::ROI region = scaled_roi(f.out, f.up);
    begin_result(dst, src_spec, f.lens, region, f.up, f.img.has_alpha);
    write_result_rows(dst, out, region.xbegin, region.ybegin, nthreads);
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
    if (!prepare_frame(f, src, o, rep, nthreads, err) || !scatter_reference(out, f, o, src.spec(), nthreads, err)) {
        dst.errorfmt("defocus scatter reference: {}", err);
        return false;
    }
    fill_uncovered(out, f, o, rep, nthreads);  // as the layered method ends
    const OIIO::ROI region = scaled_roi(f.out, f.up);
    begin_result(dst, src.spec(), f.lens, region, f.up, f.img.has_alpha);
    write_result_rows(dst, out, region.xbegin, region.ybegin, nthreads);
    return true;
}

bool defocus_coc_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts, int nthreads)
{
    std::string err;
    if (!check_defocus_options(opts, err)) {
        dst.errorfmt("coc: {}", err);
        return false;
    }
    if (!coc_map(dst, src, opts.coc, nthreads))
        return false;
    if (opts.depth_dilate_px > 0) {
        const OIIO::ROI d = dst.roi();
        std::vector<float> coc(d.npixels());
        dst.get_pixels(d, OIIO::TypeFloat, coc.data());
        dilate_nearest(coc, d.width(), d.height(), opts.depth_dilate_px, nthreads);
        dst.set_pixels(d, OIIO::TypeFloat, coc.data());
    }
    return true;
}

bool layer_map(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& opts, int nthreads)
{
    DefocusReport rep;
    Frame f;
    std::string err;
    if (!prepare_frame(f, src, opts, rep, nthreads, err)) {
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
