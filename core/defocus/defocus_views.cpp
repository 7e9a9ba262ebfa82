// defocus_views.cpp — sub-aperture views for the layered defocus (flat and deep): the
// aperture cut into an n x n grid of pupil cells, each cell's share of the light, and each
// layer's kernel restricted to a cell (composite_layers composites the layers once a view
// and takes the views' mean).
//
// The layers multiply averages where a lens averages products: a nearer layer's blurred
// coverage hides the blurred farther layer as if the rays that pass the nearer layer's
// edge were any of the aperture's, when they are the rays on one side of it, the same ones
// that meet the farther layer on that side. Cut the aperture into sub-apertures and
// composite each on its own, and the product is taken over each sub-aperture's rays; the
// views' mean, weighted by their share of the aperture, tends to the rays' average as the
// cells shrink (one ray a view is the thin-lens truth). The ray that lands at kernel
// offset d (reduced pixels, reduction s) for signed CoC c passes the pupil at
// u = 2 d s / c (y: over c * aspect): the aperture in front of focus is the point
// reflection of the one behind (aperture_weights), so u names one pupil point in every
// layer. The cells are an n x n grid over the pupil's bounding square [-1, 1]^2.
//
// Measured (bokehtool --defocus:focus=300:fstop=2:unit=cm:border=black:layers=45:views=N
// on the three LowResLeftView passes merged, against the thin-lens truth, 256 rays a
// pixel): docs/deep.md has the figures. A test scene with a card over what the file
// records only behind it (DefocusViews.TheViewsTendToTheThinLensRays): RMS against the
// rays 0.030 in one view, 0.0092 in 2 x 2, 0.0042 in 4 x 4.
//
// Limits: a kernel pixel that straddles a cell's edge is shared by area, as if its weight
// were even across it (an anti-aliased edge pixel's is not): one depth's views differ from
// the whole aperture's blur by up to 3.4e-3 on an 11 px hexagon. The cells are a square
// grid, not the aperture's own shape (a polygon's corners fall in cells of their own, with
// small shares; cells under 1e-4 of the light are dropped); a Gaussian aperture, with no
// pupil edge, is refused; views of lens character draw each highlight's whole PSF in every
// view (counted once).

#include "defocus/defocus_layers.h"

#include <algorithm>

namespace bokeh::detail {

namespace {

// The share of the kernel cell [lo, hi] (pupil units, either order) that lies in the
// view's [v0, v1], counted within the pupil's [-1, 1]: a cell wider than the pupil (an
// in-focus layer's) is shared by every view alike.
double pupil_share(double lo, double hi, double v0, double v1)
{
    if (lo > hi)
        std::swap(lo, hi);
    lo = std::max(lo, -1.0), hi = std::min(hi, 1.0);
    if (!(hi > lo))
        return 0.0;
    return std::max(0.0, std::min(hi, v1) - std::max(lo, v0)) / (hi - lo);
}

// The weight of kernel cell (dx, dy) in view v, before scaling: its share of the view's
// pupil cell.
double view_share(const ApertureView& v, int dx, int dy, double ux, double uy)
{
    const double n = v.n;
    return pupil_share((dx - 0.5) * ux, (dx + 0.5) * ux, -1.0 + 2.0 * v.i / n, -1.0 + 2.0 * (v.i + 1) / n)
           * pupil_share((dy - 0.5) * uy, (dy + 0.5) * uy, -1.0 + 2.0 * v.j / n, -1.0 + 2.0 * (v.j + 1) / n);
}

}  // namespace

std::vector<ApertureView> aperture_views(const DefocusOptions& o, int nthreads)
{
    const int n = o.aperture_views;
    if (n <= 1)
        return { ApertureView{} };
    // Each cell's share of the aperture, read off its kernel 255 px across its longer
    // side (a kernel pixel is 1/128 of the pupil) and at least 64 px across its shorter
    // (an anamorphic squeeze of up to 20 keeps 1/32 of the pupil a pixel).
    const double squeeze = std::max(double(o.aspect), 1.0 / o.aspect);
    const float share_coc_px = float(std::max(255.0 / squeeze, 64.0) * (o.aspect < 1.0f ? squeeze : 1.0));
    const KernelWeights big = aperture_weights(o, share_coc_px, 1, nthreads);
    const double ux = 2.0 / share_coc_px, uy = ux / o.aspect;
    std::vector<ApertureView> views;
    double total = 0.0;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            ApertureView v{ n, i, j, 0.0 };
            for (int dy = -big.ry; dy <= big.ry; ++dy)
                for (int dx = -big.rx; dx <= big.rx; ++dx)
                    v.share += big.at(dx, dy) * view_share(v, dx, dy, ux, uy);
            total += v.share;
            views.push_back(v);
        }
    // A cell in a central hole, or past a polygon's corner with a sliver of it, would cost
    // a whole compositing for under 1e-4 of the light: its share goes to the others.
    const auto sliver = [&](const ApertureView& v) { return v.share < 1e-4 * total; };
    views.erase(std::remove_if(views.begin(), views.end(), sliver), views.end());
    total = 0.0;
    for (const ApertureView& v : views)
        total += v.share;
    for (ApertureView& v : views)
        v.share /= total;
    return views;
}

KernelWeights view_kernel(const KernelWeights& full, const ApertureView& v, float coc_px, float aspect, int s)
{
    if (v.n <= 1 || full.is_identity() || coc_px == 0.0f)
        return full;
    KernelWeights w = full;
    const double ux = 2.0 * s / coc_px, uy = ux / aspect;
    double sum = 0.0;
    for (int dy = -w.ry; dy <= w.ry; ++dy)
        for (int dx = -w.rx; dx <= w.rx; ++dx) {
            double& x = w.w[size_t((dy + w.ry) * (2 * w.rx + 1) + (dx + w.rx))];
            x *= view_share(v, dx, dy, ux, uy);
            sum += x;
        }
    if (!(sum > 0.0))  // a small kernel whose weight lies all in other cells
        return full;
    for (double& x : w.w)
        x /= sum;
    return w;
}

}  // namespace bokeh::detail
