// defocus_fill.h — internal to the library: the background a flat frame hides behind its
// foregrounds, continued under them (core/defocus/defocus_fill.cpp), and the fill of what the
// layers leave uncovered.
#pragma once

#include "defocus/defocus_layers.h"

#include <cstdint>
#include <vector>

namespace bokeh::detail {

/// The farther surfaces around each pixel of a flat frame, continued under it: a pyramid
/// of depth-aware 2 x 2 means (defocus_fill.cpp).
class BackgroundPlate {
public:
    BackgroundPlate(const Frame& f, int nthreads);
    /// The surfaces farther than `coc_px` seen around data-window pixel (x, y), continued
    /// under it: premultiplied RGBA, its coverage the share of them that is not empty;
    /// false when none lies within the pixel's blur radius (and a cell more).
    bool behind(int x, int y, float coc_px, float rgba[4]) const;
    /// The same with the background's own texture: the frame's pixel at the mirror image
    /// of (x, y) across the nearest farther pixel within reach (its colour held to the
    /// smooth continuation's luminance band); behind()'s colour where the mirror image is
    /// not itself behind. False as behind().
    bool mirrored(int x, int y, float coc_px, float rgba[4]) const;

private:
    const Frame& f_;
    struct Cell {
        float t[3] = { 0, 0, 0 };  // colour, tone-mapped x / (1 + |x|)
        float z = 0.0f;            // signed CoC (infinite: empty, behind everything)
        float a = 0.0f;            // coverage
        float w = 0.0f;            // share of the children known (0: nothing known)
    };
    static void pull(const Cell* kids, int n, Cell& c);
    // A frame pixel (from the data window's origin) as a cell, and a level-1 cell pulled
    // from its 2 x 2 frame pixels.
    void frame_cell(int x, int y, Cell& c) const;
    void level1_cell(int i, int j, Cell& c) const;
    struct Level {
        int w = 0, h = 0;
        std::vector<Cell> cells;
    };
    // Level L (cells of 2^L x 2^L pixels) at [L - 2], from level 2 up; level 1 is pulled
    // from the frame where it is read (defocus_fill.cpp says why).
    std::vector<Level> levels_;
    // Levels in all, level 1 included (a frame of one pixel has none).
    int level_count() const { return w0_ > 1 || h0_ > 1 ? int(levels_.size()) + 1 : 0; }
    int w0_ = 0, h0_ = 0;    // the data window's size
    int w1_ = 0, h1_ = 0;    // level 1's size
    int x0_ = 0, y0_ = 0;    // the data window's origin
};

/// Which continuation fill_disocclusions draws from a plate.
enum class PlateFill { Smooth, Mirror };

/// Pixels the fill gave the continued background, and the source's own colour.
struct FillCount {
    int64_t continued = 0, foreground = 0;
};

/// What the layers leave transparent where the source is opaque (background a flat image
/// never held, behind a blurred foreground's fringe), up to the coverage the source had:
/// the plate's background where it has one (null: none), else the source pixel itself,
/// which keeps an opaque image opaque. Only for pixels with a CoC nearer than `farthest`
/// (something can lie behind them).
FillCount fill_disocclusions(Plane& out, const Frame& f, float farthest, const BackgroundPlate* plate,
                             PlateFill how, int nthreads);

}  // namespace bokeh::detail
