// truth.h — the thin-lens truth of a deep image: rays from each pixel's centre (or its
// area) over the aperture through the scene the deep image encodes, composited front to
// back.
//
// Geometry (the flat defocus's, so that methods compare): a point of signed CoC c (px,
// negative in front of focus) spreads over the aperture scaled to |c| and, in front of
// focus, point-reflected (core/defocus/defocus.cpp's aperture_weights). Equivalently the ray from
// sensor position P through aperture point s (an offset of the aperture shape of diameter
// 1 px, y down, height times the aspect) meets the depth of CoC c at image position
//     Q(c) = P - s c,
// a straight line in c; the thin-lens CoC is linear in w = 1/z, so the ray is a straight
// line in (x, y, w) and crosses the deep image's pixel cells (each pixel's frustum slice,
// [i, i+1) x [j, j+1)) in order of depth. Each ray walks those cells by a DDA over c,
// taking a point sample of a cell when its CoC lies in the c-interval the ray spends in
// the cell (an opaque point: when its reach does, below), and the part of a volume sample
// [Z, ZBack) whose depths map into that interval, by the OpenEXR split rule (expm1/log1p)
//     alpha' = 1 - (1 - alpha)^(dz / (ZBack - Z)),
// composited front to back with "over" until the transmittance of every alpha is 2^-25 or
// less (what float stores as an opacity of 1; the samples left out change the result by
// at most that fraction of their light).
//
// The CoC of a depth is CocOfDepth's, the one --defocus uses, so depth modes, gains,
// in-focus range and the CoC limit agree. Those shapings keep the CoC monotone in depth
// but not linear in 1/z; the walk never assumes the linearity: cells are found by CoC,
// and where a volume is cut by a cell boundary, the depth where the CoC reaches the
// boundary is found from CocOfDepth itself (regula falsi in 1/z: its first step is the
// thin lens's exact answer, a few more where the curve is bent). The CoC must not fall as
// Z grows within a pixel (a depth mode that reads Z backwards is refused).
//
// The sensor point (TruthPixel): a deep pixel's samples are already its area's average (the
// render's pixel filter), so the rays start at the pixel's centre by default; starting them
// over the pixel's square as well (TruthPixel::Area: pixel area times aperture, read
// literally) filters the image by the pixel a second time once the aperture is open.
// Against the built-in scenes' geometric truth (thin-lens rays against the surfaces
// themselves, over the pixel's area: the physics), 960x540, 1024 rays a pixel, 4 x 4 block
// averages, the centre is nearer: edges 46.1 dB against 45.1, lights 51.2 against 49.0
// (docs/methods/truth.md has the commands and figures). At a zero aperture both are the
// flatten.
//
// Sampling: per output pixel, a 4-D Sobol' sequence (Joe and Kuo's direction numbers)
// with hash-based Owen scrambling (Burley, "Practical Hash-based Owen Scrambling", JCGT
// 2020) seeded from the pixel and the seed: two dimensions place the ray on the aperture,
// mapped to the shape area-uniformly (ApertureSampler), two in the pixel (TruthPixel::Area
// only). The spp rays are
// two halves scrambled with different seeds; the output is their mean, and the RMS of the
// two halves' difference gives the output's noise without a second render. Each pixel's
// result depends on its coordinates and the options only: bit-identical for any thread
// count.
//
// Solid surfaces: an opaque point sample (alpha at least 1 - 1e-3) is met over half the
// CoC gap to the nearest opaque point of each 4-neighbour pixel, where that gap is at most
// 1 px, so a ray cannot slip between the tiles of a surface seen at a grazing angle
// (core/truth/truth.cpp, kConnectedCocPx).
//
// Limits: exact for the scene the file encodes (its opaque points joined as above) —
// surfaces seen only from the side of the aperture (silhouettes' flanks) are not in it; alpha is opacity spread over the cell, not
// sub-pixel coverage; samples a renderer culled behind opaque ones cannot be revealed.
// The aperture is the continuous shape (KernelEdge is ignored); disk and polygon only.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

#include <bokeh/aperture.h>
#include <bokeh/base.h>
#include <bokeh/deep.h>
#include <bokeh/image.h>
#include <bokeh/lens.h>

namespace bokeh {

/// Where a pixel's rays leave the sensor.
enum class TruthPixel {
    Centre,  ///< the pixel's centre: the deep pixel already holds its area's average
    Area,    ///< uniformly over the pixel's square: the pixel's area filtered twice
};

struct TruthOptions {
    CocOptions coc;
    /// The aperture: disk, polygon (blades, rotation, curvature, hole) or an opening (a
    /// star). Its size is ignored (each depth's CoC sets it).
    Kernel aperture;
    float aspect = 1.0f;  ///< bokeh height / width (anamorphic squeeze), 0.05..20
    int spp = 64;         ///< rays per pixel (1..1048576); two halves for the noise estimate
    TruthPixel pixel = TruthPixel::Centre;
    uint32_t seed = 1;
    /// Grow the data window by the largest CoC radius within the display window (as the
    /// flat defocus grows it); false: the output covers the data window.
    bool grow = true;
    NonFinitePolicy nonfinite = NonFinitePolicy::Zero;
    /// Add a fifth channel, "unknown": per pixel, the mean over its rays of the share of
    /// their light that crossed space the deep image does not record: behind the samples
    /// of a pixel the camera could not see through (transmittance 1e-3 or less), or past
    /// the data window; the ray's transmittance there, summed along it, at most 1. 0 where
    /// the file holds everything the rays can meet; elsewhere the truth shows what the
    /// file leaves out (a hole where a render would have had a hidden surface).
    bool unknown = false;
    /// Called with the fraction done (0..1), from one thread at a time, in rising order.
    std::function<void(float)> progress;
};

struct TruthReport {
    int64_t rays          = 0;  ///< rays traced (pixels whose rays can reach no sample trace none)
    int64_t cells_visited = 0;  ///< pixel cells the rays walked through
    double seconds        = 0.0;
    float min_coc_px = 0.0f, max_coc_px = 0.0f;  ///< over the samples
    /// The output's noise: RMS over its R, G, B, A values of the two half renders'
    /// difference, scaled to the full render (times sqrt(n1 n2) / n: a half for even spp);
    /// -1 when spp is 1. The PSNR it equals after metrics.h's tone map x / (1 + |x|),
    /// peak 1 (the halves tone-mapped before they are compared): what comparing the output
    /// with the noiseless truth would score.
    double noise_rmse    = -1.0;
    double noise_psnr_db = -1.0;
    DeepRepairs repairs;  ///< samples the non-finite policy repaired
    std::string summary;  ///< one line
};

/// Render the thin-lens truth of the deep image `deep_src` (channels R, G, B, an alpha
/// (A, or AR, AG, AB), Z, optional ZBack; colour premultiplied) into `dst`: R, G, B, A,
/// float, premultiplied, over the data window grown as TruthOptions::grow says, with the
/// source's metadata. R, G and B composite through AR, AG, AB where present, else A; the
/// output A through A, else the mean of AR, AG, AB. Other channels are not carried.
/// False + dst.geterror() on bad input.
bool defocus_truth(OIIO::ImageBuf& dst, const OIIO::ImageBuf& deep_src, const TruthOptions& opt,
                   TruthReport* report = nullptr, int nthreads = 0);
/// What defocus_truth() checks before it reads an image: the aperture and its aspect, the
/// rays a pixel. False + `err` naming the option.
bool check_truth_options(const TruthOptions& opt, std::string& err);
inline OIIO::ImageBuf defocus_truth(const OIIO::ImageBuf& deep_src, const TruthOptions& opt,
                                    TruthReport* report = nullptr, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    defocus_truth(dst, deep_src, opt, report, nthreads);
    return dst;
}


}  // namespace bokeh
