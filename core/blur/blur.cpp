// blur.cpp — bokeh::blur: checks the kernel and options, resolves the method (named, or
// for exact and fast the cheapest by the methods' cost models) and runs it. The methods
// live one family a file:
//   blur_box.cpp            box by running sums; the Gaussian by three boxes
//   blur_separable.cpp      separable convolution (Gaussian, OIIO's separable filters);
//                           the brute-force reference
//   blur_spans.cpp          disk and polygon exactly, by row spans
//   blur_fft.cpp            any kernel exactly, by FFT tiles
//   blur_bands.cpp          disk and polygon approximated by bands
//   blur_hexagon*.cpp       the hexagon by three parallelograms (hexagon.h)
//   blur_taps.cpp           Kawase's bilinear-tap disk
//   blur_reduced.cpp        any shape at reduced resolution, enlarged
//   blur_nonfinite.cpp      NaN and infinities kept within their footprint
//   plane.cpp, plane.h      padded planes, the border rule, the shared inner loops
//
// Two kinds of path. The direct paths (the exact box, separable and row-span methods, the
// FFT tiles, the three boxes, the bands and the hexagon's sweeps) read the source ImageBuf
// and write the destination directly, tile by tile or column strip by column strip; the
// others, and every method in iris mode, work as a "valid" convolution of a padded plane:
// the source region the output needs, grown by the kernel radius and filled past the data
// window by the border rule, copied once into a contiguous float plane.
// Why direct: the plane path costs a padded copy and a copy out (~14 ms at 1080p) and, for
// spans and bands, a whole-frame double prefix plane of 68-77 MB (~60 ms); every pass is
// memory-bound. The direct paths keep their double sums per tile or column strip, in L2
// (restarted per tile, so they stay small: no drift from a 1e6 pixel), fuse the border
// rule into reading, and write the result once.
//
// Limits: the cost models behind `exact` and `fast` were fitted at 1080p RGBA on two
// threads on the project's machine (each cites its figures); elsewhere a choice near a
// crossover may be the slower of the two, both keeping the accuracy asked for.

#include <bokeh/blur.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>

#include "blur/blur_methods.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;

bool is_hexagon(const Kernel& k)
{
    return k.shape == KernelShape::Polygon && k.blades == 6 && k.curvature == 0.0f && k.hole == 0.0f;
}

// The concrete method for `k`, or false + `err` when the asked one does not apply.
// Fast is the cheapest approximation measured at >= 40 dB on bokeh-bench's crop
// (docs/benchmarks.md): for a disk or polygon where the automatic reduction exceeds 1
// (37.5 px up; a polygon 45) the reduced buffer, 2-6x faster than 6 bands at the same
// accuracy (disk 63 px: 21 ms at 41.3 dB against 46 ms at 41.1; 255 px: 11 ms at 51.2
// against 66 at 48.1), below it the bands. The hexagon keeps its parallelograms
// (50-72 dB); hard-edged shapes keep the bands (the reduction was measured on anti-aliased
// ones only). In iris mode it is the exact method: exp(k x) magnifies every weight an
// approximation misplaces next to a highlight, and on the crop (range 0 .. 276) with
// |k| x range = 5 the bands measured 32-43 dB, the parallelograms 34-37, the three boxes
// 31-34 (22-30 dB at 10), against the exact iris blur.
bool resolve_method(const Kernel& k, const BlurOptions& opts, BlurMethod& m, std::string& err)
{
    const BlurMethod asked = opts.method;
    const bool gaussian = k.shape == KernelShape::Gaussian;
    const bool shape    = k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon;
    const bool filter   = k.shape == KernelShape::Filter;
    const bool opening  = k.shape == KernelShape::Opening;
    // A method asked for by name: taken where it applies to `k`, else refused with `why`.
    auto named = [&](bool applies, const char* why) {
        m = asked;
        if (!applies)
            err = why;
        return applies;
    };
    switch (asked) {
    case BlurMethod::Auto:
    case BlurMethod::Exact: m = BlurMethod::Exact; return true;
    case BlurMethod::Reference: m = asked; return true;
    case BlurMethod::Fast:
        // The hexagon too takes the reduction from 45 px: 40.9-42.2 dB from 45 to 63 px at
        // rotations 0, 30 and 7 degrees, and 41 ms at 45 px (1080p RGBA, 2 threads) against
        // the parallelograms' 36 (flat-topped), 60 (upright) and 132 (7 degrees, four
        // passes); 27 against 35 / 55 at 63 px (bokeh-bench). The sheared sweep at 7 and 25
        // degrees, 63 px: 28 and 24 ms against the reduced buffer's 19 (one run, a slow
        // phase of the machine): still the reduction.
        // A hard-edged Gaussian is oiiotool's, cut at 2 sigma: three boxes stand for the
        // whole one.
        // OIIO's filters and the other openings (a star, a picture) have no approximation
        // measured here: exact.
        m = opts.iris != 0.0f || filter || opening ? BlurMethod::Exact
            : gaussian                  ? (k.edge == KernelEdge::Hard ? BlurMethod::Exact : BlurMethod::ThreeBoxes)
            : shape && k.edge == KernelEdge::Antialiased && reduction_factor(k) > 1.0
                ? BlurMethod::Reduced
            : is_hexagon(k)           ? BlurMethod::Parallelograms  // or Exact: see blur()
            : shape && k.hole == 0.0f ? BlurMethod::Bands           // or Exact: see blur()
                                      : BlurMethod::Exact;  // box: running sums are the fast method
        return true;
    case BlurMethod::ThreeBoxes:
        return named(gaussian && k.edge == KernelEdge::Antialiased,
                     "method=boxes3 is for the anti-aliased gaussian kernel (edge=hard is oiiotool's, cut at 2 "
                     "sigma: method=exact)");
    case BlurMethod::Parallelograms:
        return named(is_hexagon(k), "method=parallelograms needs a hexagon (6 straight blades, no hole)");
    case BlurMethod::Bands:
        return named(shape && k.hole == 0.0f, "method=bands is for disk and polygon kernels without a hole");
    case BlurMethod::Reduced:
        return named(!filter, "method=reduced is not offered for OIIO's filters (no approximation of them is "
                              "measured); use an exact method");
    case BlurMethod::Spans: return named(shape || opening, "method=spans is for disk, polygon and star kernels");
    case BlurMethod::Separable:
        return named(gaussian || (filter && is_separable(k)),
                     "method=separable is for the gaussian kernel and OIIO's separable filters");
    case BlurMethod::Fft:
        return named(shape || opening || gaussian || filter,
                     "method=fft is for disk, polygon, star, gaussian and OIIO's filter kernels");
    case BlurMethod::BilinearTaps:
        return named(k.shape == KernelShape::Disk && k.edge == KernelEdge::Antialiased
                         && k.width_px == k.height_px && (k.width_px == 9.0f || k.width_px == 17.0f)
                         && k.hole == 0.0f,
                     "method=taps is Kawase's 9x9 or 17x17 anti-aliased disk only");
    }
    err = "unknown method";
    return false;
}

// The options blur() takes besides the kernel's own: false + `err`. Iris mode is
// refused with the reduced buffer and with a filter of negative weights.
bool check_blur_options(const Kernel& k, const BlurOptions& opts, BlurMethod method, int nthreads, std::string& err)
{
    if (opts.bands < 0 || opts.bands > 64) {
        err = format("bands {} is outside 0..64 (0: the method's choice)", opts.bands);
        return false;
    }
    if (!std::isfinite(opts.iris) || std::abs(opts.iris) > 1000.0f) {
        err = format("iris {} is outside -1000..1000", opts.iris);
        return false;
    }
    if (!(opts.reduction == 0.0f || (opts.reduction >= 1.0f && opts.reduction <= 16.0f))) {
        err = format("reduction {} is outside 1..16 (0: automatic)", opts.reduction);
        return false;
    }
    if (method == BlurMethod::Reduced && opts.iris != 0.0f) {
        // Tried: the reduction and the blur on exp(k x), back by log / k before the
        // enlargement. A block's mean of exp(k x) is its brightest pixel's, so every
        // highlight grows by up to a block: 20 dB against the exact iris blur (disk 51 px,
        // iris 0.3, the lights scene at 640 x 360), too far to offer.
        err = "method=reduced does not take iris (a block's mean of exp(k x) widens every highlight by up to a "
              "block); use an exact method";
        return false;
    }
    if (k.shape == KernelShape::Filter && opts.iris != 0.0f) {
        // As for image kernels: a weighted mean of exp(k x) with negative weights can fall
        // to 0 or below, whose log is NaN.
        const KernelWeights w = kernel_weights(k, nthreads);
        if (std::any_of(w.w.begin(), w.w.end(), [](double v) { return v < 0.0; })) {
            err = format("iris mode needs a kernel without negative weights ({} has some)", k.filter);
            return false;
        }
    }
    return true;
}

// What a blur computes with: the method it settled on, the weights (the effective ones for
// the approximations that have them), a separable kernel's 1-D factors, the three boxes,
// the row spans, and how far the method reads around an output pixel.
struct BlurPlan {
    BlurMethod method = BlurMethod::Exact;
    KernelWeights weights;
    std::optional<std::pair<std::vector<double>, std::vector<double>>> factors;
    std::vector<double> box3x, box3y;
    std::vector<Span> spans;
    int rx = 0, ry = 0;
};

// method=fast below the reduction weighs its approximation (the parallelograms for a
// hexagon, the bands for other shapes) against the exact row spans by the cost models,
// and takes the exact blur where it costs less: small kernels (15 px: a disk's spans
// 27 ms against 8 bands' 41, a hexagon's 26-29 against the parallelograms' 33
// flat-topped and 54 upright; bokeh-bench). With the spans model and fast_band_count's
// band counts the crossings fall at ~21 px for a disk (4 bands), ~31 for a pentagon,
// ~23 for an octagon, and with parallelograms_cost_ns (fitted on this machine) at ~9 px
// for the flat-topped hexagon and ~10 for the upright one, ~7 for the sheared sweep.
// The parallelograms are taken only from the size where they keep to the 40 dB budget
// (parallelograms_budget_px, on the narrow side: 15 px, stretched 21, sheared 27): the
// cost alone would take the sweep from 9 px at 36.5 dB, and the wide side would take a
// 27 x 9 hexagon at 36.9 dB.
// (Only up to 64 px across: the spans' cost grows with the size and is past every
// approximation's by then, and a large polygon's exact weights cost tens of ms.)
// Its bands, unless the user named a count: the fewest within its accuracy bound
// (fast_band_count; 8 bands measured 41-48 ms at 15-37 px, 4 bands 33-35).
// The budget holds at every size: a stretched hexagon past 64 px (81 x 15) too.
void weigh_fast_against_exact(BlurPlan& plan, std::optional<KernelWeights>& exact_weights, int& bands,
                               const Kernel& k, const BlurOptions& opts, const OIIO::ImageBuf& in, int nthreads)
{
    BlurMethod& method = plan.method;
    if (opts.method == BlurMethod::Fast && method == BlurMethod::Parallelograms
        && std::min(k.width_px, k.height_px) < parallelograms_budget_px(k))
        method = BlurMethod::Exact;
    if (opts.method == BlurMethod::Fast && std::max(k.width_px, k.height_px) <= 64.0f
        && (method == BlurMethod::Parallelograms || method == BlurMethod::Bands)) {
        exact_weights = kernel_weights(k, nthreads);
        if (method == BlurMethod::Bands && opts.bands == 0)
            bands = fast_band_count(*exact_weights, std::max(k.width_px, k.height_px));
        const std::vector<Span> s = kernel_spans(reflected(*exact_weights));
        const int w = in.roi().width(), h = in.roi().height();
        const bool mirrored    = spans_mirror_in_y(s);
        const double approx_ns = method == BlurMethod::Parallelograms
                                     ? parallelograms_cost_ns(k, w, h)
                                     : bands_cost_ns(w, h, bands, mirrored);
        if (spans_cost_ns(w, h, s) < approx_ns)
            method = BlurMethod::Exact;
    }
}

// The plan for blurring `in` with `k` by `method` (resolve_method's), and the region
// computed (`roi`, set when undefined). False + `err`.
bool plan_blur(BlurPlan& plan, OIIO::ROI& roi, const Kernel& k, const BlurOptions& opts, BlurMethod method,
               const OIIO::ImageBuf& in, int nthreads, std::string& err)
{
    plan.method = method;
    std::optional<KernelWeights> exact_weights;
    int bands = opts.bands > 0 ? opts.bands : 8;
    weigh_fast_against_exact(plan, exact_weights, bands, k, opts, in, nthreads);
    method = plan.method;
    // The parallelograms read no weights, only whether the kernel is a point (the
    // identity); the exact weights of a large polygon (supersampled) cost tens of ms.
    const bool no_weights = method == BlurMethod::Parallelograms && !exact_weights
                            && std::min(k.width_px, k.height_px) >= 2.0f;
    // Separable kernels (box, Gaussian, OIIO's separable filters) run from their 1-D
    // factors, made once here, on every path but the brute force and the FFT, so their N^2
    // weights are made only for those (below, once the FFT is chosen): a Gaussian of sigma
    // 1024 made 8193^2 doubles, 1.2 GB, to read its reach.
    plan.factors = is_separable(k) && method != BlurMethod::Reference && method != BlurMethod::Fft
                       ? std::optional{ separable_weights(k) }
                       : std::nullopt;
    const auto& factors = plan.factors;
    plan.weights = no_weights ? KernelWeights{ 1, 1, {} }
                   : factors  ? KernelWeights{ int(factors->first.size() / 2), int(factors->second.size() / 2), {} }
                         : method == BlurMethod::Bands && exact_weights
                             ? banded_from(*exact_weights, bands)
                         : method == BlurMethod::Bands        ? banded_weights(k, bands, nthreads)
                         : method == BlurMethod::BilinearTaps ? bilinear_tap_weights(k)
                         : exact_weights                      ? *exact_weights
                                                              : kernel_weights(k, nthreads);
    KernelWeights& weights = plan.weights;
    int& rx = plan.rx;
    int& ry = plan.ry;
    rx = weights.rx, ry = weights.ry;
    if (method == BlurMethod::ThreeBoxes) {
        std::tie(plan.box3x, plan.box3y) = gaussian_boxes(k);
        rx    = 3 * int(plan.box3x.size() / 2);
        ry    = 3 * int(plan.box3y.size() / 2);
    } else if (method == BlurMethod::Parallelograms && !weights.is_identity()) {
        rx = hexagon_reach(k, true);
        ry = hexagon_reach(k, false);
    }
    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), rx, ry) : in.roi();
    // A disk or polygon, exactly: row spans or FFT tiles, whichever the cost models say is
    // cheaper. In iris mode too: against the brute force (disk 19 px, 0.003 .. 500, k x
    // range = 29.9) both err by 2.2e-4 at most, the transform spreading its brightest
    // exp(k x)'s rounding over its tile as the spans do along their rows. The FFT is taken
    // when its model is under 1.2 times the spans': at 95-191 px its wall time measured
    // 0.69-0.85 of its model, at 15-63 px 0.85-1.0, against the spans model's 0.84-1.21
    // (44 timings, 1080p RGBA, two threads); of the factors 0.85-1.25 tried, 1.2 lost the
    // least time by its wrong picks over those timings (33 ms in all: a 63 px pentagon
    // by FFT at 1.11-1.17x the spans' time; 0.85 lost 876 ms, 1.0 lost 427). A disk
    // crosses at ~99 px (measured FFT / spans: 1.05 at 95 px, 0.77 at 127).
    // A Gaussian: the separable convolution or FFT tiles when the FFT's model promises
    // to be 15 % cheaper (at 1080p the FFT from sigma ~7: 0.72x the separable's time at
    // sigma 7.75, 0.47x at 15.75, 0.25x at 63.75, bokeh-ab).
    const int nc = in.nchannels();
    auto fft_ns      = [&] { return fft_convolve_cost_ns(roi.width(), roi.height(), nc, rx, ry); };
    const bool shape = k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon || k.shape == KernelShape::Opening;
    const bool by_spans = method == BlurMethod::Spans || method == BlurMethod::BilinearTaps
                          || (shape && method == BlurMethod::Exact);
    plan.spans = by_spans && !weights.is_identity() ? kernel_spans(reflected(weights)) : std::vector<Span>{};
    if (shape && method == BlurMethod::Exact && !weights.is_identity())
        method = fft_cheaper_than_spans(roi.width(), roi.height(), nc, rx, ry, plan.spans) ? BlurMethod::Fft
                                                                                            : BlurMethod::Spans;
    // OIIO's separable filters likewise (rows and columns, any signs); the others by FFT.
    const bool separable = k.shape == KernelShape::Gaussian || (k.shape == KernelShape::Filter && is_separable(k));
    if (separable && method == BlurMethod::Exact && !weights.is_identity())
        method = fft_ns() < 0.85 * nc * separable_cost_ns(roi.width(), roi.height(), 2 * rx + 1, 2 * ry + 1)
                     ? BlurMethod::Fft
                     : BlurMethod::Separable;
    if (k.shape == KernelShape::Filter && method == BlurMethod::Exact && !weights.is_identity())
        method = BlurMethod::Fft;
    if (method == BlurMethod::Fft && weights.w.empty() && !weights.is_identity())
        weights = kernel_weights(k, nthreads);
    plan.method = method;
    if (opts.method == BlurMethod::Fft && !std::isfinite(fft_ns())) {  // chosen, it is finite
        err = format("method=fft takes kernels under 8192 px across; this one reaches {}x{}", 2 * rx + 1, 2 * ry + 1);
        return false;
    }
    return true;
}

// The methods that go straight from the source to `dst` (no padded plane): their result
// when the plan is one of them, else nothing. Iris mode transforms a padded plane, so it
// keeps the plane path.
std::optional<bool> blur_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                                const BlurPlan& plan, const Kernel& k, const BlurOptions& opts, int nthreads)
{
    const BlurMethod method = plan.method;
    const KernelWeights& weights = plan.weights;
    const auto& factors = plan.factors;
    if (opts.iris != 0.0f || weights.is_identity())
        return std::nullopt;
    const std::vector<int> one_kernel(size_t(in.nchannels()), 0);
    if (method == BlurMethod::Exact && k.shape == KernelShape::Box)
        return box_direct(dst, in, roi, BoxPass(factors->first), BoxPass(factors->second), opts.border, nthreads);
    if (method == BlurMethod::Spans || method == BlurMethod::BilinearTaps)
        return convolve_spans_direct(dst, in, roi, weights.rx, weights.ry, plan.spans, opts.border, nthreads);
    if (method == BlurMethod::Separable)
        return separable_direct(dst, in, roi, factors->first, factors->second, opts.border, nthreads);
    if (method == BlurMethod::Fft)
        return convolve_fft_direct(dst, in, roi, { weights }, one_kernel, opts.border, nthreads, opts.progress);
    if (method == BlurMethod::ThreeBoxes)
        return three_boxes_direct(dst, in, roi, BoxPass(plan.box3x), BoxPass(plan.box3y), opts.border, nthreads);
    if (method == BlurMethod::Bands)
        return convolve_bands_direct(dst, in, roi, weights, opts.border, nthreads);
    if (method == BlurMethod::Parallelograms && hexagon_sweeps(k))
        return hexagon_direct(dst, in, roi, k, plan.rx, plan.ry, opts.border, nthreads);
    return std::nullopt;
}

// The plan run on a padded plane of the source (iris mode, the brute force, the
// parallelograms' passes, the plane paths of the other methods), finished into `dst`.
bool blur_on_plane(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi, const BlurPlan& plan,
                   const Kernel& k, const BlurOptions& opts, int nthreads)
{
    const BlurMethod method = plan.method;
    const KernelWeights& weights = plan.weights;
    const auto& factors = plan.factors;
    const int rx = plan.rx, ry = plan.ry;
    const std::vector<int> one_kernel(size_t(in.nchannels()), 0);
    // The parallelograms of an upright hexagon run on the transposed plane (blur_hexagon.cpp);
    // it is padded and finished transposed rather than transposed twice more.
    const bool transpose = method == BlurMethod::Parallelograms && !weights.is_identity()
                           && hexagon_transposed(k);
    const int extra = method == BlurMethod::Parallelograms && !weights.is_identity() ? hexagon_plane_extra(k) : 0;
    Plane p = pad(in, grown(roi, rx + extra, ry + extra), opts.border, nthreads, transpose);
    if (weights.is_identity())
        return finish(dst, in, roi, p, 0, 0, false, nthreads);  // bit-exact copy

    Iris iris;
    if (opts.iris != 0.0f) {
        iris.k     = opts.iris;
        iris.alpha = in.spec().alpha_channel;
        iris.z     = in.spec().z_channel;
        std::string err;
        if (!iris.forward(p, err, nthreads)) {
            dst.errorfmt("blur: {}", err);
            return false;
        }
    }
    Plane out;
    int ox = 0, oy = 0;  // where the output starts in `out` (planes the size of p)
    switch (method) {
    case BlurMethod::Reference: out = convolve_brute(p, weights, nthreads, opts.progress); break;
    case BlurMethod::ThreeBoxes:
        out = std::move(p);
        for (int pass = 0; pass < 3; ++pass)
            out = box_blur(out, plan.box3x, plan.box3y, nthreads);
        break;
    case BlurMethod::Parallelograms:
        out = hexagon_parallelograms(std::move(p), k, (transpose ? ry : rx) + extra, (transpose ? rx : ry) + extra,
                                     nthreads);
        ox  = rx + extra;
        oy  = ry + extra;
        break;
    case BlurMethod::Bands: out = convolve_banded(p, weights, nthreads); break;
    case BlurMethod::BilinearTaps:
    case BlurMethod::Spans: out = convolve_spans(p, weights, nthreads); break;
    case BlurMethod::Fft: out = convolve_fft(p, { weights }, one_kernel, nthreads); break;
    case BlurMethod::Separable: out = convolve_separable(p, factors->first, factors->second, nthreads); break;
    default:  // Exact: the box (the shapes and the Gaussian took their methods above)
        out = box_blur(p, factors->first, factors->second, nthreads);
    }
    if (opts.iris != 0.0f)
        iris.inverse(out, nthreads);
    return finish(dst, in, roi, out, ox, oy, transpose, nthreads);
}

}  // namespace

bool blur(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const Kernel& k,
          const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    std::string err;
    BlurMethod method = BlurMethod::Exact;
    if (!check_kernel(k, err) || !resolve_method(k, opts, method, err)
        || !check_blur_options(k, opts, method, nthreads, err)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    if (!check_source(dst, src))
        return false;
    OIIO::ImageBuf holder;
    const OIIO::ImageBuf& in = float_source(src, holder);
    if (any_nonfinite(in, nthreads))
        return blur_nonfinite(dst, in, { kernel_weights(k, nthreads) }, std::vector<int>(size_t(in.nchannels()), 0),
                              opts.border, opts.iris != 0.0f,
                              [&](OIIO::ImageBuf& out, const OIIO::ImageBuf& replaced) {
                                  return blur(out, replaced, k, opts, roi, nthreads);
                              }, nthreads);
    // Before the exact weights, which it does not need at full size.
    if (method == BlurMethod::Reduced)
        return blur_reduced(dst, in, k, opts, roi, nthreads);
    BlurPlan plan;
    if (!plan_blur(plan, roi, k, opts, method, in, nthreads, err)) {
        dst.errorfmt("blur: {}", err);
        return false;
    }
    if (const std::optional<bool> done = blur_direct(dst, in, roi, plan, k, opts, nthreads))
        return *done;
    return blur_on_plane(dst, in, roi, plan, k, opts, nthreads);
}

bool check_blur_options(const Kernel& k, const BlurOptions& opts, std::string& err)
{
    BlurMethod method = opts.method;
    return check_kernel(k, err) && resolve_method(k, opts, method, err)
           && check_blur_options(k, opts, method, 0, err);
}

OIIO::ImageBuf blur(const OIIO::ImageBuf& src, const Kernel& k, const BlurOptions& opts,
                    OIIO::ROI roi, int nthreads)
{
    OIIO::ImageBuf dst;
    blur(dst, src, k, opts, roi, nthreads);
    return dst;
}

}  // namespace bokeh
