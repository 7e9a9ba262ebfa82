// defocus_sprites.cpp — lens character in the depth defocus: highlights scattered as
// sprites carrying the lens's own PSF (optics.h), the rest left to the layers (the
// brute-force reference, every pixel scattered with its own PSF, is in
// core/defocus/defocus_reference.cpp).
//
// The hybrid is that of Kawase's "Bokeh Deep Dive" talk, on giant bokeh ("scatter only
// bright, important pixels; fringes and onion rings only on scattered sprites"). Ours:
// * Selection: a pixel's sprite share is a smoothstep in log2 of its premultiplied
//   luminance (Rec. 709 weights), 0 at threshold / 2 and 1 at threshold * 2, so a change
//   of exposure or threshold moves energy between the layers and the sprite continuously.
//   The share of the colour goes to the sprite and leaves the layers (colour - share *
//   colour stays), so it is counted once; the pixel's alpha stays in the layers, so its
//   coverage and what it hides are unchanged.
// * Shape: the PSFs of the two points of the cache's CoC grid around the sprite's CoC
//   (psf_coc_steps_around: below 1 px its linear bins, 1/8 px apart; above, its bins 1/16
//   octave apart cut into steps at most 1/2 px apart in rim radius, each built by lens_psf
//   at its CoC), crossfaded with weights linear in log2 |CoC| (in CoC below 1 px):
//   two anti-aliased rims that close draw one rim (a crossfade of the bins themselves drew
//   a sharp rim as two, 4.4 % apart; DefocusSprites.ARimStaysOneRimBetweenCachedCocs).
//   Between the four field bins around the pixel (1/8 of the half-diagonal apart, bilinear;
//   field = position from the display window's centre over its half-diagonal, y up), so a
//   sprite crossing a bin changes shape gradually. A lens with no field effect asks every
//   PSF at the centre: two PSFs a sprite, else up to eight. Each channel of a PSF sums to 1.
// * Occlusion: a sprite is added, colour only, into the layer of its depth after that
//   layer is composited and before any nearer one is: "over" is linear, so this is
//   exactly the sprite added into the layer's premultiplied colour (with zero alpha: the
//   light of a pixel whose coverage the layer already holds); nearer layers then hide it
//   as they hide the layer. A pixel shared between two layers shares its sprite alike.
//   On a flat frame the sprite is divided by the layer's visibility where it lands, as the
//   layer's own colour is (SpriteGain), so moving a pixel's light between the layer and
//   its sprite changes its shape only, never how it is occluded (measured: without it a
//   light beside an in-focus card lost 19 % of its visible energy,
//   DefocusSprites.ASpriteIsOccludedAsItsLayerIs), by no less than a floor where the
//   sprite's PSF is wider than the layer's kernel (kSpriteGainFloor: there the layer's
//   visibility says little of the sprite). A deep frame's layers are continued
//   under the same surface only (core/defocus/defocus_deep.cpp), and its sprites are not divided.
// * At focus (ours): the in-focus layer (within kLensLayerMaxCoc_px) is blurred with the
//   lens's PSF on axis (lens_layer_kernels; R, G, B each their own, coverage and visibility
//   their mean), by FFT: there the aperture is a point and the blur a dim texture gets is
//   the lens's aberrations and colour, which no highlight selection would carry.
// * Pseudo-high resolution (supersample 2): the sprites are drawn on the output's pixels,
//   half the frame's, with the lens PSF at the output's CoC and pixel pitch, box-folded
//   (box_folded) so each sits centred on its frame pixel; the layers are enlarged.
// * Drawing by rows (the talk's "most of the disk needs no lookup"): each PSF
//   once as ramps and literal runs (core/optics/psf_runs.cpp, ramps within kSpriteRampTolerance
//   of each pixel), added into a band of running sums, then into the layer times its gain.
// Limits: a lens with field effects draws up to eight PSFs a sprite; out of focus, dim
// pixels keep the aperture (the lens's rim and fringes show on highlights only); the grid
// builds about |CoC| PSFs an octave past 22 px (the giant scene at 1920x1080: 30, where the
// bins alone took 17; bokeh-bench --task lens --size 640x360 against the scatter
// reference: lights 46.4 and edges 51.0 dB as before, giant 47.2 against 48.0 dB, its
// largest differences at a few large rims where neither matches the reference); past H = 1.3 the
// field is held there; the `max_sprites` cut is hard; past the data window (clamp, mirror) the layers repeat the
// highlight-less pixels, so highlights are not repeated there.

#include <bokeh/defocus.h>
#include <bokeh/parallel.h>

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <tuple>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;

namespace {

using OIIO::Strutil::fmt::format;
using Clock = std::chrono::steady_clock;

// Lens character in the in-focus layer. At focus the aperture is a point, so the blur a
// dim, in-focus texture gets is the lens's own: its aberrations and secondary spectrum (an
// achromat at f/1.06 softens the edges scene's in-focus checker by about 2 px, which the
// aperture's point leaves sharp). The layers within kLensLayerMaxCoc_px of focus take the
// lens's PSF; farther out the PSF is the aperture's disk with a modulated rim, which the
// highlights carry as sprites. Measured (bokeh-bench --task lens --size 640x360, achromat
// with rim diffraction, PSNR against the scatter reference; lights / edges / giant): no
// layer with the PSF 44.5 / 30.0 / 37.6 dB; with sprites undivided by their layer's
// visibility, |CoC| <= 0, 1, 2, 8 px and every layer gave 44.6 / 44.7 / 45.1 / 46.6 /
// 46.6 dB on lights and 38.4 dB on edges, 41.6 dB on giant for each; with the division,
// 0 px 45.4 / 42.3 / 43.0 dB and 1 px 45.5 / 42.3 / 43.0 dB. Cost on lights at 1920x1080
// (2 threads, in-process median of 7, PSFs cached): 0 px 1.26x the plain default, 1 px
// 1.34x, each further layer about 30 ms. So only the in-focus rung (the ladder always has
// one at 0).
constexpr float kLensLayerMaxCoc_px = 0.0f;
// The share of each channel's light a layer's lens kernel may leave out past its square:
// at 1e-4 the kernels shrink from 25..65 px to 3..25 px with no change in those figures.
constexpr double kLensKernelTail = 1e-4;
// The least visibility a sprite's gain divides by in a layer whose kernel is smaller than
// some of its sprites' PSFs (a pixel between two rungs is drawn in the nearer-to-focus one
// with its own, wider PSF). There the PSF reaches past where the layer's kernel carries
// any of the sprite's own pixel, so the layer's visibility says little of the sprite: it
// falls toward 0 under the pixels shared into nearer layers, and 1 / visibility made the
// sprite flicker as the CoCs moved. Where every PSF lies within the kernel (exact rungs,
// the in-focus rung) the division stays whole: an in-focus light beside a blurred panel
// glows through it only with gains past 100 (edges: a floor of 0.01 for every layer cost
// 4.9 dB against the scatter reference). Measured with tools/bokeh-bench/temporal.py's
// figure (lens off / achromat; the plain layers' figure 0.389 and 0.679) and
// `bokeh-bench --task lens --size 640x360`: no floor, plane dolly 1.675 / 1.684, lights
// dolly 0.566 / 0.907; floor 0.01: 0.438 / 0.517, 0.566 / 0.907; 0.02: 0.425 / 0.488,
// 0.568 / 0.908; 0.03: 0.422 / 0.481, 0.580 / 0.914; 0.1: 0.426 / 0.480, 0.686 / 1.059
// (there the gain no longer reaches the light behind the post's blurred edge); the lens
// task's figures the same for each (46.3 / 51.0 / 47.2 dB).
constexpr float kSpriteGainFloor = 0.02f;
// The PSF's excess over the kernel (its CoC over the rung's, less 1, times the sprite's
// share in the layer: continuous as a sprite moves between layers) at which the floor is
// whole; a ladder's rungs lie 1.5 apart, so a sprite halfway between two has 0.2.
constexpr float kSpriteGainFloorExcess = 0.05f;
// A sprite's PSF is drawn as ramps within this fraction of each pixel's value (psf_runs).
// Measured (bokeh-bench --task lens --size 640x360, PSNR against the scatter reference):
// lights / edges / giant 45.4 / 51.0 / 47.3 dB, as drawn pixel by pixel; 1e-3 of each
// channel's peak instead gave edges 41.4 dB (an achromat's faint halo near focus, under
// 20000 sprites).
constexpr double kSpriteRampTolerance = 1e-3;

// The centred square a PSF is trimmed to: the smallest half-sizes rx, ry (shrunk together
// from the PSF's own) outside which each channel holds at most `tail` of its light. A pixel
// (dx, dy) from the centre leaves the square at shrink step s > min(hw - |dx|, hh - |dy|),
// so one pass sums each channel's light by that shell and the running sum finds s.
void trimmed_reach(const Psf& psf, double tail, int& rx, int& ry)
{
    const int hw = psf.width / 2, hh = psf.height / 2, shells = std::min(hw, hh) + 1;
    std::vector<std::array<double, 3>> shell(size_t(shells), { 0.0, 0.0, 0.0 });
    for (int y = 0; y < psf.height; ++y)
        for (int x = 0; x < psf.width; ++x) {
            const int sh = std::min(hw - std::abs(x - hw), hh - std::abs(y - hh));
            for (int c = 0; c < 3; ++c)
                shell[size_t(sh)][size_t(c)] += std::abs(double(psf.at(x, y, c)));
        }
    std::array<double, 3> outside{ 0.0, 0.0, 0.0 };
    int s = 0;
    while (s < shells - 1) {  // step s + 1 also leaves out shell s
        bool ok = true;
        for (int c = 0; c < 3; ++c)
            ok = ok && outside[size_t(c)] + shell[size_t(s)][size_t(c)] <= tail;
        if (!ok)
            break;
        for (int c = 0; c < 3; ++c)
            outside[size_t(c)] += shell[size_t(s)][size_t(c)];
        ++s;
    }
    rx = hw - s;
    ry = hh - s;
}

double seconds_since(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

float smoothstep01(float t)
{
    t = std::clamp(t, 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

// Pseudo-high resolution at 2x: `psf` convolved with a 2 x 2 box, (width + 1) x (height
// + 1), its centre on the corner between its pixels (hw, hh) and (hw + 1, hh + 1). A frame
// pixel covers 2 x 2 output pixels and its centre is their common corner, so a sprite is
// this drawn with pixel (hw, hh) on the frame pixel's top-left output pixel: centred
// exactly, each channel still summing to 1.
std::shared_ptr<const Psf> box_folded(const Psf& psf)
{
    auto out    = std::make_shared<Psf>();
    out->width  = psf.width + 1;
    out->height = psf.height + 1;
    out->rgb.assign(size_t(out->width) * size_t(out->height) * 3, 0.0f);
    for (int y = 0; y < psf.height; ++y)
        for (int x = 0; x < psf.width; ++x)
            for (int c = 0; c < 3; ++c) {
                const float v = 0.25f * psf.at(x, y, c);
                for (int dy = 0; dy < 2; ++dy)
                    for (int dx = 0; dx < 2; ++dx)
                        out->rgb[(size_t(y + dy) * size_t(out->width) + size_t(x + dx)) * 3 + size_t(c)] += v;
            }
    return out;
}

// A cached PSF as a sprite draws it: box-folded at pseudo-high resolution, and as ramps and
// literal runs (psf_runs).
struct DrawnPsf {
    std::shared_ptr<const Psf> psf;
    std::shared_ptr<const PsfRuns> runs;
};

// drawn_psf's results, kept while their cache PSF lives: a sequence's later frames reuse
// them as they reuse the PSFs (encoding giant's 17 PSFs took about 5 % of its frame). Keyed
// by the cache PSF's address and `up`; an entry whose PSF has expired is stale (its address
// may be reused) and is dropped when the map is next written.
struct DrawnEntry {
    std::weak_ptr<const Psf> source;
    DrawnPsf drawn;
};
std::mutex g_drawn_mutex;
std::map<std::pair<const Psf*, int>, DrawnEntry> g_drawn;

DrawnPsf drawn_psf(const std::shared_ptr<const Psf>& psf, int up)
{
    const auto key = std::make_pair(psf.get(), up);
    {
        std::lock_guard<std::mutex> lock(g_drawn_mutex);
        const auto it = g_drawn.find(key);
        if (it != g_drawn.end() && it->second.source.lock() == psf) {
            DrawnPsf d = it->second.drawn;
            d.psf      = d.psf ? d.psf : psf;
            return d;
        }
    }
    DrawnPsf d;
    d.psf  = up == 2 ? box_folded(*psf) : psf;
    d.runs = std::make_shared<const PsfRuns>(psf_runs(*d.psf, kSpriteRampTolerance));
    std::lock_guard<std::mutex> lock(g_drawn_mutex);
    for (auto it = g_drawn.begin(); it != g_drawn.end();)
        it = it->second.source.expired() ? g_drawn.erase(it) : std::next(it);
    // At up 1 the entry must not own its source (the cache's eviction would not free it).
    DrawnEntry& e = g_drawn[key];
    e.source      = psf;
    e.drawn.psf   = up == 2 ? d.psf : nullptr;
    e.drawn.runs  = d.runs;
    return d;
}

}  // namespace

float detail::SpriteGain::at(int x, int y) const
{
    const int t = tile_of(x, y);
    if (t < 0 || !visibility[size_t(t)].px)
        return 1.0f;
    const OIIO::ROI& d = draw[size_t(t)];
    if (x < d.xbegin || x >= d.xend || y < d.ybegin || y >= d.yend)
        return 1.0f;
    const Plane& v = visibility[size_t(t)];
    float vis;
    bilinear(v, (float(x - gx) + 0.5f) / float(s) - 0.5f - float(low[size_t(t)].xbegin),
             (float(y - gy) + 0.5f) / float(s) - 0.5f - float(low[size_t(t)].ybegin), &vis, 0, 1);
    return vis > 1e-6f ? 1.0f / std::max(vis, floor) : 0.0f;
}

detail::FieldFrame::FieldFrame(const OIIO::ImageSpec& spec, const LensCharacter& lens)
{
    // The field enters lens_psf through these alone (core/optics/lens_psf.cpp: field curvature and
    // astigmatism by H^2, the barrel circle and the rings' centre by H).
    const bool rings = lens.onion > 0.0 || lens.onion_waves > 0.0 || lens.surface_noise > 0.0;
    used = lens.catseye > 0.0 || lens.field_curvature_px != 0.0 || lens.astigmatism_px != 0.0
           || (rings && lens.onion_offset != 0.0);
    const bool full = spec.full_width > 0 && spec.full_height > 0;
    const double x0 = full ? spec.full_x : spec.x, y0 = full ? spec.full_y : spec.y;
    const double w = full ? spec.full_width : spec.width, h = full ? spec.full_height : spec.height;
    cx            = x0 + 0.5 * w;
    cy            = y0 + 0.5 * h;
    half_diagonal = std::max(0.5, 0.5 * std::hypot(w, h));
}

void detail::FieldFrame::bins_around(int x, int y, double fx[4], double fy[4], double w[4], int& n) const
{
    n = 1;
    fx[0] = fy[0] = 0.0;
    w[0]          = 1.0;
    if (!used)
        return;
    // Overscan far past the display window: held at H = 1.3, so the bins around stay
    // within the PSF's field model (H <= 1.5).
    double px = (x + 0.5 - cx) / half_diagonal, py = (cy - (y + 0.5)) / half_diagonal;
    const double h = std::hypot(px, py);
    if (h > 1.3)
        px *= 1.3 / h, py *= 1.3 / h;
    const double gx = 8.0 * px, gy = 8.0 * py;
    const double ix = std::floor(gx), iy = std::floor(gy);
    const double tx = gx - ix, ty = gy - iy;
    n = 0;
    for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
            const double wij = (i ? tx : 1.0 - tx) * (j ? ty : 1.0 - ty);
            if (!(wij > 0.0))
                continue;
            fx[n] = (ix + i) / 8.0;
            fy[n] = (iy + j) / 8.0;
            w[n]  = wij;
            ++n;
        }
}

bool detail::defocus_lens(const DefocusOptions& o, const OIIO::ImageSpec& spec, LensCharacter& lens,
                          std::string& err)
{
    lens = o.lens;
    if (!Aperture::from_kernel(o.aperture, lens.aperture, err))
        return false;
    const int width_px  = spec.full_width > 0 ? spec.full_width : spec.width;
    lens.aspect         = o.aspect;
    lens.fstop          = o.coc.lens.fstop;
    lens.focal_mm       = o.coc.lens.focal_mm;
    // At pseudo-high resolution the sprites are drawn on the output's finer pixels.
    lens.pixel_pitch_mm = o.coc.lens.sensor_width_mm / std::max(1, width_px * o.supersample);
    if (!check_lens(lens, err)) {
        err = "lens character: " + err;
        return false;
    }
    return true;
}

bool detail::check_sprite_options(const DefocusOptions& o, std::string& err)
{
    if (!o.lens_character)
        return true;
    if (!(std::isfinite(o.highlight_threshold) && o.highlight_threshold > 0.0f)) {
        err = format("highlight threshold {} is not a positive luminance", o.highlight_threshold);
        return false;
    }
    if (o.max_sprites < 0 || o.max_sprites > 10000000) {
        err = format("max sprites {} is outside 0..10000000", o.max_sprites);
        return false;
    }
    if (o.method == DefocusMethod::Gather) {
        err = "lens character puts highlights into layers; the gather method has none (use "
              "method=layers, auto or reference)";
        return false;
    }
    // Lateral colour magnifies the whole frame, in focus or not: drawn on the sprites alone
    // it would colour the highlights' bokeh and leave every edge beside them white.
    if (o.lens.lateral_r_px != 0.0 || o.lens.lateral_b_px != 0.0) {
        err = "lateral colour moves the whole frame, not the highlights alone: defocus without it, then warp "
              "the result with lens_distort (--lensdistort:lateralr=...:lateralb=...)";
        return false;
    }
    return true;
}

float detail::sprite_share(const float* rgb, float threshold, float& luminance)
{
    luminance = 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2];
    if (!(luminance > 0.5f * threshold))
        return 0.0f;
    if (luminance >= 2.0f * threshold)
        return 1.0f;
    return smoothstep01(0.5f * (std::log2(luminance / threshold) + 1.0f));
}

bool detail::fetch_sprite_psfs(SpriteSet& set, PsfCache& cache, const FieldFrame& field, int up, int nthreads,
                               std::string& err)
{
    // Each sprite's requests: the two points of the PSF grid around its CoC
    // (psf_coc_steps_around: one rim at any CoC), times the field bins around it. The
    // distinct ones are fetched from the cache in parallel, each once, and made ready to
    // draw (drawn_psf).
    using Key = std::tuple<double, double, double>;  // CoC, field x, field y
    std::map<Key, DrawnPsf> wanted;
    std::vector<std::array<Key, kSpritePsfs>> requests(set.sprites.size());
    for (size_t i = 0; i < set.sprites.size(); ++i) {
        Sprite& s = set.sprites[i];
        double c[2], t;
        psf_coc_steps_around(double(s.coc_px) * up, c[0], c[1], t);  // the CoC in output pixels
        double fx[4], fy[4], fw[4];
        int nf;
        field.bins_around(s.x, s.y, fx, fy, fw, nf);
        int n = 0;
        for (int b = 0; b < 2; ++b) {
            const double wc = b == 0 ? 1.0 - t : t;
            if (!(wc > 0.0))
                continue;
            for (int q = 0; q < nf; ++q, ++n) {
                requests[i][size_t(n)] = Key(c[b], fx[q], fy[q]);
                s.weight[n]            = float(wc * fw[q]);
                wanted.emplace(requests[i][size_t(n)], DrawnPsf{});
            }
        }
    }
    std::vector<std::pair<const Key, DrawnPsf>*> todo;
    for (auto& w : wanted)
        todo.push_back(&w);
    std::vector<std::string> errors(todo.size());
    parallel_for_chunks(0, int64_t(todo.size()), 1, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t i = b; i < e; ++i) {
            PsfRequest r;
            std::tie(r.coc_px, r.field_x, r.field_y) = todo[size_t(i)]->first;
            if (const std::shared_ptr<const Psf> psf = cache.get_exact(r, errors[size_t(i)]))
                todo[size_t(i)]->second = drawn_psf(psf, up);
        }
    });
    for (size_t i = 0; i < todo.size(); ++i)
        if (!todo[i]->second.psf) {
            err = errors[i];
            return false;
        }
    std::map<const Psf*, int> ids;
    for (size_t i = 0; i < set.sprites.size(); ++i) {
        Sprite& s = set.sprites[i];
        for (int j = 0; j < kSpritePsfs && s.weight[j] > 0.0f; ++j) {
            const DrawnPsf& d = wanted.at(requests[i][size_t(j)]);
            s.psf[j]          = d.psf;
            s.runs[j]         = d.runs;
            const int side    = std::max(s.psf[j]->width, s.psf[j]->height);
            set.extent_px = std::max(set.extent_px, up == 1 ? float(side / 2) : std::ceil(0.5f * float(side) / float(up)));
            s.psf_id[j]   = ids.emplace(s.psf[j].get(), int(ids.size())).first->second;
        }
    }
    set.psfs = ids.size();
    return true;
}

bool detail::select_sprites(Frame& f, const DefocusOptions& o, const OIIO::ImageSpec& spec, int nthreads,
                            std::string& err, const SpriteCut* cut, int counted_ybegin, int counted_yend)
{
    const Clock::time_point t0 = Clock::now();
    LensCharacter lens;
    if (!defocus_lens(o, spec, lens, err))
        return false;
    auto set = std::make_shared<SpriteSet>();
    struct Candidate {
        size_t at;
        float share, luminance;
    };
    std::vector<Candidate> found;
    const size_t n = f.coc.size();
    for (size_t i = 0; i < n; ++i) {
        float lum;
        const float share = sprite_share(f.img.rgba.data() + i * 4, o.highlight_threshold, lum);
        if (share > 0.0f
            && !(cut && cut->active && outranks(cut->key, cut->at, share * lum, cut->offset + int64_t(i))))
            found.push_back({ i, share, lum });
    }
    set->candidates = int64_t(found.size());
    if (!cut && found.size() > size_t(o.max_sprites)) {
        std::nth_element(found.begin(), found.begin() + o.max_sprites, found.end(),
                         [](const Candidate& a, const Candidate& b) {
                             return outranks(a.share * a.luminance, int64_t(a.at), b.share * b.luminance,
                                             int64_t(b.at));
                         });
        found.resize(size_t(o.max_sprites));
    }
    std::sort(found.begin(), found.end(), [](const Candidate& a, const Candidate& b) { return a.at < b.at; });
    const int w = f.data.width();
    for (const Candidate& c : found) {
        Sprite s;
        s.at     = c.at;
        s.x      = f.data.xbegin + int(c.at % size_t(w));
        s.y      = f.data.ybegin + int(c.at / size_t(w));
        s.coc_px = f.coc[c.at];
        s.counted = !cut || (s.y >= counted_ybegin && s.y < counted_yend);
        float* px = f.img.rgba.data() + c.at * 4;
        for (int k = 0; k < 3; ++k) {
            s.rgb[k] = px[k] * c.share;
            px[k]    = px[k] - s.rgb[k];
        }
        set->sprites.push_back(s);
    }
    set->lens = lens;
    if (!fetch_sprite_psfs(*set, *shared_psf_cache(lens, nthreads), FieldFrame(spec, lens), o.supersample, nthreads,
                           err))
        return false;
    set->seconds = seconds_since(t0);
    f.sprites    = std::move(set);
    return true;
}

bool detail::lens_layer_kernels(std::vector<std::vector<KernelWeights>>& out, const Frame& f, const Membership& m,
                                int nthreads, std::string& err)
{
    const size_t K = m.coc_px.size();
    out.assign(K, {});
    // Each layer's lens: its buffer's pixels are s times the frame's (the sprites' lens has
    // the output's pitch, f.up times finer than the frame's).
    std::vector<std::shared_ptr<PsfCache>> caches(K);
    for (size_t k = 0; k < K; ++k)
        if (std::abs(m.coc_px[k]) <= kLensLayerMaxCoc_px) {
            LensCharacter lens = f.sprites->lens;
            lens.pixel_pitch_mm *= double(f.up * m.reduction[k]);
            caches[k] = shared_psf_cache(lens, nthreads);
        }
    std::vector<std::string> errors(K);
    parallel_for_chunks(0, int64_t(K), 1, nthreads, [&](int64_t b, int64_t e) {
        for (int64_t k = b; k < e; ++k) {
            if (!caches[size_t(k)])
                continue;
            PsfRequest r;
            r.coc_px = double(m.coc_px[size_t(k)]) / m.reduction[size_t(k)];
            const std::shared_ptr<const Psf> built = caches[size_t(k)]->get_exact(r, errors[size_t(k)]);
            if (!built)
                continue;
            const Psf& psf = *built;
            // The PSF's square is sized for its faintest halo; the kernel keeps the centred
            // square outside which each channel has at most kLensKernelTail of its light,
            // renormalised (the FFT's tiles grow with the kernel).
            const int hw = psf.width / 2, hh = psf.height / 2;
            int rx, ry;
            trimmed_reach(psf, kLensKernelTail, rx, ry);
            std::vector<KernelWeights>& kernels = out[size_t(k)];
            kernels.assign(4, KernelWeights{});
            for (int c = 0; c < 4; ++c) {
                KernelWeights& w = kernels[size_t(c)];
                w.rx = rx, w.ry = ry;
                w.w.assign(size_t(2 * rx + 1) * size_t(2 * ry + 1), 0.0);
                double sum = 0.0;
                for (int y = -ry; y <= ry; ++y)
                    for (int x = -rx; x <= rx; ++x) {
                        const double v = c < 3 ? double(psf.at(x + hw, y + hh, c))
                                               : (double(psf.at(x + hw, y + hh, 0)) + psf.at(x + hw, y + hh, 1)
                                                  + psf.at(x + hw, y + hh, 2)) / 3.0;
                        w.w[size_t(y + ry) * size_t(2 * rx + 1) + size_t(x + rx)] = v;
                        sum += v;
                    }
                for (double& v : w.w)
                    v /= sum;
            }
        }
    });
    for (size_t k = 0; k < K; ++k)
        if (!errors[k].empty()) {
            err = "lens character: " + errors[k];
            return false;
        }
    return true;
}

std::vector<float> detail::sprite_gain_floors(const std::vector<float>& sprite_coc_px, const std::vector<float>& rungs)
{
    // Continuous in every sprite's CoC, so a sequence does not step as a sprite moves
    // between layers: per layer, the widest PSF's excess over the kernel times its share.
    std::vector<float> excess(rungs.size(), 0.0f);
    if (rungs.empty())
        return excess;
    for (float c : sprite_coc_px) {
        uint16_t lo;
        float up;
        share_between(c, rungs, lo, up);
        for (size_t k : { size_t(lo), size_t(lo) + 1 }) {
            const float share = k == lo ? 1.0f - up : up;
            const float rung  = k < rungs.size() ? std::abs(rungs[k]) : 0.0f;
            if (share > 0.0f && rung > 0.0f)
                excess[k] = std::max(excess[k], share * (std::abs(c) / rung - 1.0f));
        }
    }
    for (float& e : excess)
        e = kSpriteGainFloor * std::clamp(e / kSpriteGainFloorExcess, 0.0f, 1.0f);
    return excess;
}

bool detail::layer_has_sprites(const Frame& f, const Membership& m, int k)
{
    if (!f.sprites)
        return false;
    for (const Sprite& sp : f.sprites->sprites) {
        if (f.deep() ? sp.layer == k
                     : m.lower[sp.at] == k || (m.lower[sp.at] + 1 == k && m.upper[sp.at] > 0.0f))
            return true;
    }
    return false;
}

void detail::draw_layer_sprites(Plane& target, const Frame& f, const Membership& m, int k, int nthreads,
                                const SpriteGain* gain, bool counted)
{
    if (!f.sprites || f.sprites->sprites.empty())
        return;
    const Clock::time_point t0 = Clock::now();
    // The layer's sprites, as colour per PSF (share and crossfade weight applied), and the
    // source block each falls in.
    struct Drawn {
        int x, y, bx, by;
        const PsfRuns* runs[kSpritePsfs];  // null past the ones in use
        std::array<int, kSpritePsfs> id;
        float rgb[kSpritePsfs][3];
        bool counted;
    };
    std::vector<Drawn> list;
    for (const Sprite& s : f.sprites->sprites) {
        float share;
        bool first;  // the first layer the sprite is drawn in: where the report counts it
        if (s.layer >= 0) {
            share = s.layer == k ? 1.0f : 0.0f;
            first = s.counted;
        } else {
            const int lo   = m.lower[s.at];
            const float up = m.upper[s.at];
            share          = lo == k ? 1.0f - up : lo + 1 == k ? up : 0.0f;
            first          = (lo == k || !(1.0f - up > 0.0f)) && s.counted;
        }
        if (!(share > 0.0f))
            continue;
        Drawn d;
        d.x = s.x, d.y = s.y;
        d.counted = first;
        // The talk's decimation (one sprite per 2 x 2 sources for large bokeh): sources of a
        // large PSF are drawn once per block of b x b pixels, b the largest power of two up
        // to its width / 32 (at most 8), at the block's brightest-weighted pixel: a shift of
        // at most b / 2 px, a 1/64 of the PSF's width.
        const int width = s.psf[0]->width / f.up;  // in frame pixels
        int b           = 1;
        while (b < 8 && 2 * b * 32 <= width)
            b *= 2;
        d.bx = floor_div(s.x, b), d.by = floor_div(s.y, b);
        for (int j = 0; j < kSpritePsfs; ++j) {
            d.runs[j] = s.runs[j].get();
            d.id[j]   = s.psf_id[j];
            for (int c = 0; c < 3; ++c)
                d.rgb[j][c] = s.runs[j] ? s.rgb[c] * share * s.weight[j] : 0.0f;
        }
        list.push_back(d);
    }
    if (list.empty())
        return;
    // Merge the sprites of a block that share all their PSFs (their colours add: drawing is
    // linear), placed at the luminance-weighted mean position, rounded.
    auto key = [](const Drawn& d) { return std::make_tuple(d.by, d.bx, d.id, d.y, d.x); };
    std::sort(list.begin(), list.end(), [&](const Drawn& a, const Drawn& b) { return key(a) < key(b); });
    std::vector<Drawn> merged;
    for (size_t i = 0; i < list.size();) {
        size_t e = i + 1;
        while (e < list.size() && list[e].by == list[i].by && list[e].bx == list[i].bx && list[e].id == list[i].id)
            ++e;
        Drawn d = list[i];
        if (e > i + 1) {
            double sx = 0.0, sy = 0.0, sw = 0.0;
            for (size_t j = i; j < e; ++j) {
                const Drawn& o = list[j];
                double lum     = 0.0;
                for (int p = 0; p < kSpritePsfs; ++p)
                    lum += 0.2126 * o.rgb[p][0] + 0.7152 * o.rgb[p][1] + 0.0722 * o.rgb[p][2];
                const double wgt = std::max(lum, 1e-30);
                sx += wgt * o.x, sy += wgt * o.y, sw += wgt;
                d.counted = d.counted || o.counted;
                if (j > i)
                    for (int p = 0; p < kSpritePsfs; ++p)
                        for (int c = 0; c < 3; ++c)
                            d.rgb[p][c] += o.rgb[p][c];
            }
            d.x = int(std::lround(sx / sw));
            d.y = int(std::lround(sy / sw));
        }
        merged.push_back(d);
        i = e;
    }
    std::stable_sort(merged.begin(), merged.end(), [](const Drawn& a, const Drawn& b) { return a.y < b.y; });
    // Drawn in output pixels (f.out scaled by f.up): a PSF's pixel (hw, hh) on the sprite's
    // pixel (up 1: its centre), or on its top-left output pixel (up 2: box_folded).
    const int up             = f.up;
    const OIIO::ROI region   = scaled_roi(f.out, up);
    const int reach          = int(std::ceil(f.sprites->extent_px)) + 1;  // frame pixels
    const float scale        = float(up * up);  // radiance: a frame pixel is up^2 output pixels
    constexpr int kBand      = 16;
    parallel_for_chunks(region.ybegin, region.yend, kBand, nthreads, [&](int64_t b, int64_t e) {
        const int y0 = int(b), y1 = int(e);
        // Sprites are sorted by y: those within reach of the band.
        auto first = std::lower_bound(merged.begin(), merged.end(), floor_div(y0, up) - reach,
                                      [](const Drawn& d, int y) { return d.y < y; });
        auto last = first;
        while (last != merged.end() && last->y < floor_div(y1, up) + reach + 1)
            ++last;
        if (first == last)
            return;
        RunBand band(region.xbegin, region.xend, y0, y1);
        for (auto it = first; it != last; ++it)
            for (int j = 0; j < kSpritePsfs; ++j)
                if (const PsfRuns* runs = it->runs[j]) {
                    const int hw = (runs->width - (up - 1)) / 2, hh = (runs->height - (up - 1)) / 2;
                    const float k[3] = { it->rgb[j][0] * scale, it->rgb[j][1] * scale, it->rgb[j][2] * scale };
                    band.add(*runs, it->x * up - hw, it->y * up - hh, k);
                }
        // Into the layer, times the gain at each pixel's frame pixel (read only in tiles
        // the layer's visibility is kept for).
        const bool gained = gain && gain->used;
        for (int y = y0; y < y1; ++y) {
            float* row   = target.row(y - region.ybegin);
            const int fy = floor_div(y, up);
            band.flush_row(y, [&](int x, const float* rgb) {
                const float g = gained ? gain->at(floor_div(x, up), fy) : 1.0f;
                float* d      = row + size_t(x - region.xbegin) * 4;
                d[0] += g * rgb[0];
                d[1] += g * rgb[1];
                d[2] += g * rgb[2];
            });
        }
    });
    // A sprite shared between two layers is drawn in both but counted once, in the first.
    if (counted)
        f.sprites->drawn += std::count_if(merged.begin(), merged.end(), [](const Drawn& d) { return d.counted; });
    f.sprites->seconds += seconds_since(t0);
}

void detail::report_sprites(DefocusReport& rep, const SpriteSet* set)
{
    rep.lens_character = set != nullptr;
    if (!set)
        return;
    rep.sprites = std::count_if(set->sprites.begin(), set->sprites.end(), [](const Sprite& s) { return s.counted; });
    rep.sprite_candidates = set->candidates;
    rep.sprites_drawn     = set->drawn;
    rep.sprite_seconds    = set->seconds;
    rep.sprite_psfs       = set->psfs;
    for (size_t i = 0; i < set->sprites.size(); ++i) {
        const float c         = set->sprites[i].coc_px;
        rep.sprite_min_coc_px = i == 0 ? c : std::min(rep.sprite_min_coc_px, c);
        rep.sprite_max_coc_px = i == 0 ? c : std::max(rep.sprite_max_coc_px, c);
    }
}

std::string detail::sprite_summary(const DefocusReport& rep)
{
    if (!rep.lens_character)
        return std::string();
    return format(", {} sprites{} (CoC {:.1f} .. {:.1f} px, {} PSFs, {} drawn) in {:.3f} s", rep.sprites,
                  rep.sprite_candidates > rep.sprites ? format(" of {} highlights", rep.sprite_candidates)
                                                      : std::string(),
                  rep.sprite_min_coc_px, rep.sprite_max_coc_px, rep.sprite_psfs, rep.sprites_drawn,
                  rep.sprite_seconds);
}

}  // namespace bokeh
