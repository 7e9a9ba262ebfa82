// defocus_layers.h — internal to the library: the layer machinery the flat and the deep
// defocus share (core/defocus.cpp holds it; core/defocus_deep.cpp uses it).
//
// A frame is a data window of premultiplied RGBA pixels, each with its signed CoC; a
// membership puts every pixel in one layer or shares it between two neighbouring rungs of
// a CoC ladder; composite_layers blurs each layer with the aperture at its CoC (in a
// reduced buffer where the CoC allows) and composites the layers front over back. A deep
// frame instead brings each layer's pixels ready made (layer_rgba): a deep pixel holds
// samples in several layers, and what lies behind a nearer layer is known, not guessed.
#pragma once

#include <bokeh/defocus.h>

#include "plane.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace bokeh::detail {

// Iris mode (SEEDS.md section 3) in the layers: colour is carried as
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
    Border border = Border::Clamp;
    // A deep frame: per layer, its premultiplied RGBA per data-window pixel (the pixel's
    // samples in that layer composited front to back); img, coc and the membership's
    // per-pixel shares are then unused.
    std::vector<std::vector<float>> layer_rgba;
    // A deep frame: per layer, the part of each pixel its own split samples leave visible
    // (1 - (1 - u) a for a sample shared u / 1 - u with the nearer layer); the layer is
    // divided by its blur, as a flat frame's layers are by their visibility.
    std::vector<std::vector<float>> layer_vis;

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

/// Check the options that do not depend on the image. False + `err` naming the option.
bool check_defocus_options(const DefocusOptions& o, std::string& err);

/// The rungs of the layered method for CoCs `cocs` spanning [lo, hi]: one per distinct
/// CoC (0.25 px bins) for scenes of at most 64 (when `exact_allowed`), else the budget's
/// geometric ladder; a rung at 0 always.
std::vector<float> layer_rungs(const std::vector<float>& cocs, const DefocusOptions& o, float lo,
                               float hi, bool exact_allowed = true);

/// Where CoC `c` falls among ascending `rungs`: share 1 - upper in rung `lower`, `upper` in
/// the next, keeping the second moment (a disk's spread is proportional to its diameter).
void share_between(float c, const std::vector<float>& rungs, uint16_t& lower, float& upper);

/// Each rung's buffer reduction for the options' budget.
std::vector<int> layer_reductions(const std::vector<float>& rungs, const DefocusOptions& o);

/// The output region: the data window grown by the largest CoC radius `extreme_px` (and
/// the spill of a reduced buffer), within the display window joined to the data window.
OIIO::ROI defocus_output_region(const OIIO::ImageSpec& spec, const OIIO::ROI& data, float extreme_px,
                                const DefocusOptions& o);

/// Blur every layer of `m` with the aperture at its CoC and composite them, front over
/// back, into `out` (RGBA over f.out). With `per_layer`, each blurred layer is written
/// there instead (one RGBA plane over f.out per layer) and `out` is left alone.
void composite_layers(Plane& out, const Frame& f, const Membership& m, const DefocusOptions& o,
                      int nthreads, std::vector<Plane>* per_layer = nullptr);

/// The defocus of a deep image (core/defocus_deep.cpp); bokeh::defocus calls it.
bool defocus_deep(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DefocusOptions& o,
                  DefocusReport* report, int nthreads);

}  // namespace bokeh::detail
