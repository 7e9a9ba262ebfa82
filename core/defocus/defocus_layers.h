// defocus_layers.h — internal to the library: the layer machinery the flat and the deep
// defocus share. The frame's preparation is in core/defocus/defocus_prepare.cpp, the plan of
// layers in core/defocus/defocus_plan.cpp, the engine that blurs and composites them in
// core/defocus/defocus_engine.cpp, the references in core/defocus/defocus_reference.cpp.
//
// A frame is a data window of premultiplied RGBA pixels, each with its signed CoC; a
// membership puts every pixel in one layer or shares it between two neighbouring rungs of
// a CoC ladder; composite_layers blurs each layer with the aperture at its CoC (in a
// reduced buffer where the CoC allows) and composites the layers front over back. A deep
// frame instead brings each layer's pixels ready made (layer_rgba): a deep pixel holds
// samples in several layers, and what lies behind a nearer layer is known, not guessed.
#pragma once

#include <bokeh/defocus.h>

#include "base/plane.h"
#include "blur/convolve.h"
#include "optics/psf_runs.h"

#include <bokeh/parallel.h>

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace bokeh::detail {

// A sprite's PSFs: the two CoC bins around its CoC times the (up to) four field bins
// around its field position.
constexpr int kSpritePsfs = 8;

// A highlight scattered with the lens's PSF (core/defocus/defocus_sprites.cpp): the share of a
// pixel's premultiplied colour taken out of the layers, drawn as the blend of the PSFs of
// the two CoC bins around its CoC (weights linear in log CoC) and the field bins around its
// field position (bilinear).
struct Sprite {
    int x = 0, y = 0;             // the pixel, full-resolution coordinates
    size_t at = 0;                // its index in the data window (flat frames)
    int layer = -1;               // deep frames: the layer it is drawn in (flat: by membership)
    bool counted = true;          // deep frames: false for the second layer's part of a piece
                                  // split between two (the report counts the piece once)
    float coc_px = 0.0f;
    float rgb[3] = { 0, 0, 0 };   // premultiplied colour taken from the pixel
    std::shared_ptr<const Psf> psf[kSpritePsfs];  // null past the ones in use
    std::shared_ptr<const PsfRuns> runs[kSpritePsfs];  // each psf as drawn (psf_runs.h)
    int psf_id[kSpritePsfs] = { -1, -1, -1, -1, -1, -1, -1, -1 };  // order of first use (fixed, for merging)
    float weight[kSpritePsfs] = {};
};

struct SpriteSet {
    std::vector<Sprite> sprites;
    int64_t candidates = 0;
    float extent_px   = 0.0f;  // the largest half-size of a sprite's PSFs, frame px
    size_t psfs       = 0;
    int64_t drawn     = 0;     // sprites drawn, after merging those of a block (one shared
                               // between two layers counted once)
    double seconds    = 0.0;   // selection, PSFs and (added as they are drawn) scatter
    LensCharacter lens;        // the defocus's lens (defocus_lens), pitch of the output's pixels
};


// Iris mode (docs/methods/iris.md) in the layers: colour is carried as
// A (exp(k (colour / A - shift)) - 1) (premultiplied exp-space colour), so each layer
// averages exp(k x) weighted by coverage; every layer comes back by
// shift + log(1 + mean) / k before it is composited ("over" is linear). The shift (the
// channel's minimum for k > 0, maximum for k < 0) keeps the exponents in
// [0, kIrisMaxExponent], and the 1 taken away keeps a small k's digits, as blur's Iris does.
struct IrisSpace {
    float k = 0.0f;
    std::array<float, 3> shift{};
};

struct Frame {
    WorkImage img;           // premultiplied RGBA over the data window (iris: exp space)
    std::vector<float> linear_rgba;  // iris mode: img.rgba before the exp; else empty
    IrisSpace iris;
    std::vector<float> coc;  // signed CoC per pixel of the data window
    OIIO::ROI data, out;     // the data window; the output region
    CocOptions lens;         // the CoC options as resolved (focus by pixel made a distance)
    Border border = Border::Clamp;
    // A deep frame: per layer, its premultiplied RGBA per data-window pixel (the pixel's
    // samples in that layer composited front to back); img, coc and the membership's
    // per-pixel shares are then unused.
    std::vector<std::vector<float>> layer_rgba;
    // A deep frame: per layer, the part of each pixel its own split samples leave visible
    // (1 - (1 - u) a for a sample shared u / 1 - u with the nearer layer); the layer is
    // divided by its blur, as a flat frame's layers are by their visibility.
    std::vector<std::vector<float>> layer_vis;
    // Lens character on a flat frame: each layer's sprite gain floor (sprite_gain_floors),
    // given by the whole frame's sprites when the frame is drawn in bands; else empty and
    // found from `sprites`.
    std::vector<float> sprite_gain_floors;
    // Lens character: the highlights taken out of img (null: off).
    std::shared_ptr<SpriteSet> sprites;
    // Pseudo-high resolution: the result plane is over `out` scaled by this (1 or 2).
    int up = 1;

    bool deep() const { return !layer_rgba.empty(); }

    // Index of the data-window pixel that stands for (x, y) by the border rule; -1 when
    // it is outside and empty.
    int64_t source(int x, int y) const
    {
        const int sx = border_index(x, data.xbegin, data.xend, border);
        const int sy = border_index(y, data.ybegin, data.yend, border);
        if (sx == kOutside || sy == kOutside)
            return -1;
        return int64_t(size_t(sy - data.ybegin) * size_t(data.width()) + size_t(sx - data.xbegin));
    }
    // The source's premultiplied RGBA in linear light (not in iris space).
    const std::vector<float>& linear() const { return linear_rgba.empty() ? img.rgba : linear_rgba; }
};

// Each pixel's place among the layers: its share 1 - upper in layer `lower` and `upper` in
// layer lower + 1.
struct Membership {
    std::vector<float> coc_px;     // the layers' CoCs, ascending (front to back)
    std::vector<int> reduction;    // each layer's buffer reduction
    std::vector<uint16_t> lower;   // per data-window pixel (flat frames)
    std::vector<float> upper;
};

/// `r` with its bounds times `up` (pseudo-high resolution's output region).
inline OIIO::ROI scaled_roi(OIIO::ROI r, int up)
{
    r.xbegin *= up, r.xend *= up, r.ybegin *= up, r.yend *= up;
    return r;
}

/// The display window of `spec` set to `like`'s times `up`.
inline void scale_display_window(OIIO::ImageSpec& spec, const OIIO::ImageSpec& like, int up)
{
    spec.full_x      = like.full_x * up;
    spec.full_y      = like.full_y * up;
    spec.full_width  = like.full_width * up;
    spec.full_height = like.full_height * up;
}

/// Whether `bytes` (what `what` would hold) fits the options' memory budget; false + `err`
/// saying both, with the options' hint and `remedy` (may be empty) in parentheses.
bool within_defocus_memory(const DefocusOptions& o, double bytes, const std::string& what, const std::string& remedy,
                           std::string& err);

/// zdilate: each pixel of the w x h CoC plane takes the nearest (smallest signed) CoC of
/// the (2r + 1)^2 square about it, cut by the frame's edge.
void dilate_nearest(std::vector<float>& coc, int w, int h, int r, int nthreads);

/// Which of a frame's highlights become sprites when it has more than max_sprites: those
/// that outrank the last one kept (its key and data-window index); all when not `active`.
/// `offset` is the frame's data-window index of the image's first pixel (a band's).
struct SpriteCut {
    bool active  = false;
    float key    = 0.0f;
    int64_t at   = 0;
    int64_t offset = 0;
};

/// A band of a flat frame's output drawn on its own under a memory budget
/// (core/defocus/defocus_bands.cpp): the source pixels it reads (its output rows and the
/// layers' reach about them), its output rows, the source rows whose non-finite values it
/// counts (each row counted by one band) and the whole frame's CoC range.
struct FrameBand {
    OIIO::ROI read, out;
    int counted_ybegin = 0, counted_yend = 0;
    float min_coc_px = 0.0f, max_coc_px = 0.0f;
    /// Lens character: the frame's cut of its highlights (select_sprites).
    SpriteCut sprite_cut;
    /// Iris mode: the frame's exp space (set from its colour range), when known.
    bool iris_known = false;
    IrisSpace iris;
};

/// Iris mode: each channel's colour range (unpremultiplied), empty until joined.
struct IrisRange {
    static constexpr float kNone = std::numeric_limits<float>::infinity();
    std::array<float, 3> lo{ kNone, kNone, kNone }, hi{ -kNone, -kNone, -kNone };
};

/// Iris mode: the range of each channel's colour over f.img's covered pixels, joined to
/// `range`.
void iris_channel_range(const Frame& f, IrisRange& range);

/// Iris mode: the exp space of exponent k for colours in `range` (IrisSpace's shift);
/// false + `err` when k times a channel's range passes kIrisMaxExponent.
bool iris_space_for(float k, IrisRange range, IrisSpace& iris, std::string& err);

/// A flat image made ready for a method (core/defocus/defocus_prepare.cpp): the options checked,
/// the pixels premultiplied and scrubbed (counted in `rep`), each pixel's signed CoC, the
/// depth dilation, bloom, the sprites taken out, iris space, the output region; the
/// report's CoC range. With `band`, only its part of the frame, its output rows and the
/// frame's CoC range. False + `err`.
bool prepare_frame(Frame& f, const OIIO::ImageBuf& src, const DefocusOptions& o, DefocusReport& rep,
                   int nthreads, std::string& err, const FrameBand* band = nullptr);

/// Iris-space colour (4 or more channels, premultiplied) back to linear, in place (no-op
/// when iris mode is off).
void from_iris_space(Plane& p, const IrisSpace& iris);

/// A plan of the Layers method: its rungs (ascending CoCs) and each one's buffer reduction.
struct LayerPlan {
    std::vector<float> coc_px;
    std::vector<int> reduction;
};

/// The flat Layers method's plan over the frame's CoC range [lo, hi]
/// (core/defocus/defocus_planner.cpp): the options' where they fix it (layers,
/// ladder_ratio, min_reduced_coc_px), else the budget's steps or, under the predicted
/// planner, the cheapest it predicts meets the budget; every plan weighed into
/// `considered`, cheapest first.
LayerPlan choose_layer_plan(const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads,
                            std::vector<DefocusPlanEstimate>& considered);

/// The Layers method's plan over the frame's CoC range [lo, hi] (choose_layer_plan), with
/// each pixel's shares; the plans weighed into `considered` when given.
Membership layer_plan(const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads,
                      std::vector<DefocusPlanEstimate>* considered = nullptr);

/// The geometric ladder over [lo, hi]: 0, +-1, +-r, +-r^2 ... on each side, the last rung
/// moved onto the extreme so it gets its exact kernel.
std::vector<float> coc_ladder(float lo, float hi, double ratio);

/// The exact rungs of CoCs `cocs` spanning [lo, hi], with a rung at 0: each CoC when the
/// frame holds at most 64, else the 0.25 px grid points around them; empty when there are
/// more than `most`.
std::vector<float> exact_layer_rungs(const std::vector<float>& cocs, float lo, float hi, size_t most);

/// The smallest reduced kernel diameter of the steps: the user's, or the budget's.
float layer_min_reduced_coc_px(const DefocusOptions& o);

/// The ladder ratio that puts `layers` rungs (0 and both sides) over [lo, hi].
double ratio_for_count(int layers, float lo, float hi);

/// The smallest reduced kernel the flat planner may choose (the output region leaves room
/// for the spill of a buffer reduced that far).
constexpr float kSmallestReducedCocPx = 8.0f;

/// The reduction for a layer of CoC c: the largest power of two s <= max_reduction that
/// leaves a kernel of at least q reduced pixels.
int reduction_for(float c, float q, int max_reduction);

/// The Reference's layers: the points of a grid `step` apart around the frame's CoCs, all
/// at full resolution; each pixel shared between the two around its CoC.
Membership one_layer_per_coc(const Frame& f, float lo, float hi, float step, int nthreads);

/// The Reference's rungs for CoCs `cocs` spanning [lo, hi]: each CoC when there are few,
/// else the points of a grid `step` apart around them.
std::vector<float> reference_rungs(const std::vector<float>& cocs, float lo, float hi, float step);

/// Whether [lo, hi] holds at most 65535 of the Reference's `step`s (its layers are counted
/// in 16 bits); else false + `err`.
bool reference_range_fits(float lo, float hi, float step, std::string& err);

/// Every pixel of `f` shared between the rungs of `plan` (share_between), with its reductions.
Membership layer_membership(const Frame& f, LayerPlan plan, int nthreads);

/// The Reference method (core/defocus/defocus_reference.cpp): one layer a distinct CoC over the
/// report's CoC range, composited into `out`; the layers into `rep`. False + `err` when
/// the range holds more than 65535 steps.
bool reference_layers(Plane& out, const Frame& f, const DefocusOptions& o, DefocusReport& rep, int nthreads,
                      std::string& err);

/// The rungs of the layered method for CoCs `cocs` spanning [lo, hi]: the reference's
/// (exact) rungs when there are at most 64 (and `exact_allowed`), else the budget's
/// geometric ladder, its ratio at most `ladder_ratio` when that is > 0; a rung at 0 always.
/// The user's `o.ladder_ratio` comes first: 1 the exact rungs whatever their count (when
/// `exact_allowed`), > 1 (without `o.layers`) the ladder of that ratio.
std::vector<float> layer_rungs(const std::vector<float>& cocs, const DefocusOptions& o, float lo,
                               float hi, bool exact_allowed = true, double ladder_ratio = 0.0);

/// Where CoC `c` falls among ascending `rungs`: share 1 - upper in rung `lower`, `upper` in
/// the next, keeping the second moment (a disk's spread is proportional to its diameter);
/// between two rungs on either side of focus, wholly in the nearer.
void share_between(float c, const std::vector<float>& rungs, uint16_t& lower, float& upper);

/// Each rung's buffer reduction for the options' budget.
std::vector<int> layer_reductions(const std::vector<float>& rungs, const DefocusOptions& o);

/// The most a defocus's output can cover: the data window joined to the display window
/// when it grows (`grow`), else the data window.
OIIO::ROI defocus_output_bound(const OIIO::ImageSpec& spec, const OIIO::ROI& data, bool grow);

/// The output region: the data window grown by the largest CoC radius `extreme_px` (and
/// the spill of a reduced buffer), within the display window joined to the data window.
OIIO::ROI defocus_output_region(const OIIO::ImageSpec& spec, const OIIO::ROI& data, float extreme_px,
                                const DefocusOptions& o);

/// The side of a layer's tile in its reduced pixels (core/defocus/defocus_engine.cpp): a
/// layer reduced by s is computed in tiles of kLayerTilePx * s frame pixels from the
/// output's origin.
constexpr int kLayerTilePx = 64;
/// The same for a layer blurred with the lens's PSF (by FFT: lens character's in-focus layers).
constexpr int kLensLayerTilePx = 256;

/// Blur every layer of `m` with the aperture at its CoC (with lens character, the lens's
/// PSF at focus: lens_layer_kernels) and composite them, front over back, into `out`
/// (RGBA over f.out). With `per_layer`, each blurred layer is written there instead (one
/// RGBA plane over f.out per layer) and `out` is left alone. Progress (o.progress) goes
/// from `progress_from` (what the caller's work before took) to 1. With sub-aperture views
/// and `view_targets` (one plane over f.out a view), each view's layers are laid over its
/// own target and `out` is left alone (the caller takes the views' mean: layers drawn in
/// groups). False + `err`.
/// `mean` += `share` times `view` (same size): one sub-aperture view's part of their mean.
void add_view_share(Plane& mean, const Plane& view, float share, int nthreads);

bool composite_layers(Plane& out, const Frame& f, const Membership& m, const DefocusOptions& o, int nthreads,
                      std::string& err, std::vector<Plane>* per_layer = nullptr, float progress_from = 0.0f,
                      std::vector<Plane>* view_targets = nullptr);

/// The display window's centre and half-diagonal, for field positions; a lens whose PSF
/// does not change with the field (no cat's eye, field curvature, astigmatism or offset
/// rings) gets every request at the centre, so the cache builds one PSF a CoC bin.
struct FieldFrame {
    double cx = 0.0, cy = 0.0, half_diagonal = 1.0;
    bool used = true;
    FieldFrame(const OIIO::ImageSpec& spec, const LensCharacter& lens);
    /// The cache's field bins around pixel (x, y) (their centres, 1/8 of the half-diagonal
    /// apart) and their bilinear weights: `n` of them (1 when the field is not used).
    void bins_around(int x, int y, double fx[4], double fy[4], double w[4], int& n) const;
};

/// The lens of a defocus: o.lens with the defocus's own aperture, aspect and camera.
bool defocus_lens(const DefocusOptions& o, const OIIO::ImageSpec& spec, LensCharacter& lens,
                  std::string& err);

/// Check the sprite options. False + `err` naming the option.
bool check_sprite_options(const DefocusOptions& o, std::string& err);

/// The sprite share of a pixel of premultiplied colour `rgb` (smoothstep in log luminance
/// from threshold / 2 to threshold * 2), and its luminance.
float sprite_share(const float* rgb, float threshold, float& luminance);

/// Lens character on a flat frame: select the highlights of f.img (f.coc known), take
/// their share out of f.img and fetch their PSFs into f.sprites. With `cut` (a band of a
/// frame: defocus_bands.cpp), the frame's own cut instead of this image's, and only the
/// sprites of the band's counted rows counted in the report. False + `err`.
bool select_sprites(Frame& f, const DefocusOptions& o, const OIIO::ImageSpec& spec, int nthreads,
                    std::string& err, const SpriteCut* cut = nullptr, int counted_ybegin = 0,
                    int counted_yend = 0);

/// A highlight's rank among a frame's: its sprite share times its luminance, then its
/// index in the data window (the lower first).
inline bool outranks(float key_a, int64_t at_a, float key_b, int64_t at_b)
{
    return key_a > key_b || (key_a == key_b && at_a < at_b);
}

/// Fetch both PSFs of every sprite from `cache` and set the set's extent. False + `err`.
/// `up` is the output's resolution over the frame's (2: PSFs at twice the CoC, box-folded).
bool fetch_sprite_psfs(SpriteSet& set, PsfCache& cache, const FieldFrame& field, int up, int nthreads,
                       std::string& err);

/// Lens character in the in-focus layer (core/defocus/defocus_sprites.cpp): for each layer of
/// `m` within kLensLayerMaxCoc_px of focus (the rung at CoC 0), the lens's PSF at its CoC on axis, at its
/// buffer's reduction, as four kernels: R, G, B, and their mean (for coverage and
/// visibility); empty for the layers that keep the aperture. False + `err`.
bool lens_layer_kernels(std::vector<std::vector<KernelWeights>>& out, const Frame& f, const Membership& m,
                        int nthreads, std::string& err);

/// What a layer's sprites are multiplied by where they land: 1 over the layer's blurred
/// visibility (composite_layers), as the layer's own colour is divided, so a sprite is the
/// highlight's light in its layer exactly as the layer treats it. Kept only for the
/// layer's tiles where a nearer layer hides some of it (elsewhere 1): the tile's reduced
/// visibility, read at a sprite's pixels only as they are drawn (a layer's sprites cover a
/// small part of its tiles).
struct SpriteGain {
    bool used = false;
    int gx = 0, gy = 0, tile_px = 1, cols = 0, s = 1;  // the layer's tile grid and reduction
    std::vector<OIIO::ROI> draw;  // per tile: the frame pixels the layer reaches (else 1)
    std::vector<OIIO::ROI> low;   // per tile: the reduced pixels `visibility` covers
    std::vector<Plane> visibility;  // per tile: the blurred visibility, 1 channel; empty: 1
    float floor = 0.0f;             // the least visibility the gain divides by (sprite_gain_floors)
    /// The tile holding frame pixel (x, y), or -1 past the grid.
    int tile_of(int x, int y) const
    {
        const int tx = floor_div(x - gx, tile_px), ty = floor_div(y - gy, tile_px);
        return tx < 0 || ty < 0 || tx >= cols || ty * cols + tx >= int(draw.size()) ? -1 : ty * cols + tx;
    }
    /// The gain at frame pixel (x, y): 1 / max(visibility, floor), the visibility read as
    /// `sample` reads colour (0 where it is under 1e-6), 1 where the layer is not hidden.
    float at(int x, int y) const;
};

/// Whether layer k holds a share of any sprite.
bool layer_has_sprites(const Frame& f, const Membership& m, int k);

/// Per layer of `rungs`, the least visibility its sprite gain divides by: 0 where every
/// sprite's PSF lies within the layer's kernel (its CoC at most the rung's), rising to
/// kSpriteGainFloor as the PSFs of the sprites it holds outgrow it (defocus_sprites.cpp).
std::vector<float> sprite_gain_floors(const std::vector<float>& sprite_coc_px, const std::vector<float>& rungs);

/// Add the sprites of layer k (share by `m` for flat frames, their own layer for deep
/// ones) into `target` (RGBA over f.out; colour only: a sprite is the light of a pixel
/// whose coverage stays in the layer), times `gain` where given. `counted`: add them to
/// the set's drawn count (false for the second and later sub-aperture views, which draw
/// the same sprites again).
void draw_layer_sprites(Plane& target, const Frame& f, const Membership& m, int k, int nthreads,
                        const SpriteGain* gain = nullptr, bool counted = true);

/// The report's sprite figures from `set` (null: lens character off), and its summary
/// part (", N sprites, CoC a .. b px, t s"; empty when off).
void report_sprites(DefocusReport& rep, const SpriteSet* set);
std::string sprite_summary(const DefocusReport& rep);

/// The disocclusion fill the options ask for (core/defocus/defocus_fill.h) over `out` (RGBA
/// over f.out), its counts added to `rep`.
void fill_uncovered(Plane& out, const Frame& f, const DefocusOptions& o, DefocusReport& rep, int nthreads);

/// The report's one-line summary, for an output of width x height pixels.
void summarise_defocus(DefocusReport& rep, int width, int height);

/// `dst` made the result of a flat defocus of an image of spec `src_spec`: float R, G, B
/// (and A with `alpha`) over `region` (the output region times `up`), the display window
/// times `up`, the lens recorded; its pixels not yet written.
void begin_result(OIIO::ImageBuf& dst, const OIIO::ImageSpec& src_spec, const CocOptions& lens,
                  const OIIO::ROI& region, int up, bool alpha);

/// Rows of `out` (RGBA) into `dst` (begin_result's), its top-left pixel at (x0, y0).
void write_result_rows(OIIO::ImageBuf& dst, const Plane& out, int x0, int y0, int nthreads);

/// Whether a flat defocus with options `o` can be drawn in bands; else `why` not.
bool defocus_bands_allowed(const DefocusOptions& o, std::string& why);

/// A flat defocus drawn in bands of output rows, each band's working planes within the
/// options' memory budget (core/defocus/defocus_bands.cpp). False + the error on `dst`.
bool defocus_in_bands(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& o,
                      DefocusReport* report, int nthreads);

/// The brute-force reference (defocus_scatter_reference) over a prepared flat frame: grows
/// f.out by the PSFs' reach and fills `out` (RGBA over f.out). False + `err`.
bool scatter_reference(Plane& out, Frame& f, const DefocusOptions& o, const OIIO::ImageSpec& spec,
                       int nthreads, std::string& err);

/// The aperture at diameter |coc_px| / s (and the aspect), as exact weights; rotated half
/// a turn in front of focus (core/defocus/defocus_engine.cpp).
KernelWeights aperture_weights(const DefocusOptions& o, float coc_px, int s, int nthreads);

/// One sub-aperture of DefocusOptions::aperture_views: cell (i, j) of an n x n grid over
/// the pupil's bounding square, and its share of the aperture's light (the views' shares
/// sum to 1). n = 1: the whole aperture.
struct ApertureView {
    int n = 1, i = 0, j = 0;
    double share = 1.0;
};

/// The views the options ask for, those that hold some of the aperture
/// (core/defocus/defocus_views.cpp).
std::vector<ApertureView> aperture_views(const DefocusOptions& o, int nthreads);

/// `full`, the aperture at signed CoC `coc_px` over reduction s (aperture_weights),
/// restricted to view `v` and scaled to sum 1; `full` itself for the whole aperture, an
/// in-focus layer, or a kernel too small to hold any of the view.
KernelWeights view_kernel(const KernelWeights& full, const ApertureView& v, float coc_px, float aspect, int s);

/// Colour and coverage (channels 0-3) over the visibility in channel 4, in place; 0 where
/// the visibility is 0.
void divide_by_visibility(Plane& p);

// The mean over s x s full-resolution pixels of `fetch(x, y, v)` (which adds nc values
// into v), for the reduced pixels of `low`: reduced pixel (i, j) covers full resolution
// [gx + i s, gx + (i + 1) s) x [gy + j s, ...).
template<class Fetch>
inline Plane reduce_region(const OIIO::ROI& low, int gx, int gy, int s, int nc, int nthreads, Fetch fetch)
{
    Plane p(low.width(), low.height(), nc);
    const float inv = 1.0f / float(s * s);
    parallel_for_chunks(0, p.h, 4, nthreads, [&](int64_t j0, int64_t j1) {
        std::vector<float> v(static_cast<size_t>(nc));
        for (int j = int(j0); j < int(j1); ++j) {
            float* row = p.row(j);
            for (int i = 0; i < p.w; ++i) {
                std::fill(v.begin(), v.end(), 0.0f);
                const int x0 = gx + (low.xbegin + i) * s, y0 = gy + (low.ybegin + j) * s;
                for (int y = y0; y < y0 + s; ++y)
                    for (int x = x0; x < x0 + s; ++x)
                        fetch(x, y, v.data());
                for (int c = 0; c < nc; ++c)
                    row[size_t(i) * size_t(nc) + size_t(c)] = s == 1 ? v[size_t(c)] : v[size_t(c)] * inv;
            }
        }
    });
    return p;
}

// Bilinear read of plane `p` at (u, v) in its pixels (pixel centres at integers, clamped
// to the plane); channels first .. first + count - 1 into `out`. Exact (a copy) on a pixel
// centre.
inline void bilinear(const Plane& p, float u, float v, float* out, int first = 0, int count = 4)
{
    const float fu = std::floor(u), fv = std::floor(v);
    const int i0 = std::clamp(int(fu), 0, p.w - 1), i1 = std::clamp(int(fu) + 1, 0, p.w - 1);
    const int j0 = std::clamp(int(fv), 0, p.h - 1), j1 = std::clamp(int(fv) + 1, 0, p.h - 1);
    const float tx = u - fu, ty = v - fv;
    const size_t nc = size_t(p.nc);
    const float *a = p.row(j0) + size_t(i0) * nc + first, *b = p.row(j0) + size_t(i1) * nc + first;
    const float *c = p.row(j1) + size_t(i0) * nc + first, *d = p.row(j1) + size_t(i1) * nc + first;
    if (tx == 0.0f && ty == 0.0f) {
        std::copy_n(a, count, out);
        return;
    }
    for (int k = 0; k < count; ++k) {
        const float top = a[k] + (b[k] - a[k]) * tx, bottom = c[k] + (d[k] - c[k]) * tx;
        out[k]          = top + (bottom - top) * ty;
    }
}

// Bilinear read of plane `p` (reduced pixels `low`, grid as in reduce_region) at the
// centre of full-resolution pixel (x, y); 4 channels into `out`. Exact at s = 1.
inline void sample(const Plane& p, const OIIO::ROI& low, int gx, int gy, int s, int x, int y,
                   float out[4])
{
    bilinear(p, (float(x - gx) + 0.5f) / float(s) - 0.5f - float(low.xbegin),
             (float(y - gy) + 0.5f) / float(s) - 0.5f - float(low.ybegin), out);
}

// The same at the centre of sub-pixel (sx, sy) of `up` x `up` in full-resolution pixel
// (x, y): the enlargement of pseudo-high resolution.
inline void sample_sub(const Plane& p, const OIIO::ROI& low, int gx, int gy, int s, int x, int y, int up,
                       int sx, int sy, float out[4])
{
    bilinear(p, (float(x - gx) + (float(sx) + 0.5f) / float(up)) / float(s) - 0.5f - float(low.xbegin),
             (float(y - gy) + (float(sy) + 0.5f) / float(up)) / float(s) - 0.5f - float(low.ybegin), out);
}

/// The gather of hikita12312's "Implementing depth of field" (core/defocus/defocus_gather.cpp):
/// blurred levels blended per pixel by its CoC, the front-edge blur; into `out` (RGBA over
/// f.out). lo, hi: the frame's CoC range.
void gather(Plane& out, const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads);

/// The defocus of a deep image (core/defocus/defocus_deep.cpp); bokeh::defocus calls it.
bool defocus_deep(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& o,
                  DefocusReport* report, int nthreads);

}  // namespace bokeh::detail
