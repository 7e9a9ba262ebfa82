// blur_fft.cpp — convolution by FFT in overlap-save tiles: image kernels (any shape,
// colour allowed) and, where its cost model says it is cheaper, the exact disk, polygon
// (against row spans) and Gaussian (against the separable convolution).
//
// Overlap-save (Stockham 1966, "High-speed convolution and correlation"; Oppenheim and
// Schafer, "Discrete-Time Signal Processing", section 8.7): a tile of ny x nx source
// pixels is transformed (FFTW's real 2-D transforms, Frigo and Johnson 2005), multiplied
// by the kernel's transform on the same grid, and transformed back; of the cyclic result,
// the (ny - 2 ry) x (nx - 2 rx) outputs whose footprint lies inside the tile equal the
// linear convolution, and only those are kept. Tiles step by that valid size over the
// output and read the source straight through the border rule, so no padded copy of the
// frame is made, and a channel of a tile of a few hundred pixels square stays in L2.
//
// Why tiles: transforming the whole padded frame keeps ~3 double planes per channel in
// flight (~80 MB at 1080p) and took 55-70 ms per channel at 1080p on one thread. Tiles
// cost ~14 ns per transformed point at 256 x 256 and more as they grow (tile_cost_ns);
// the tiling is chosen per call by that model, and blur.cpp compares the result
// (fft_convolve_cost_ns) with the other exact method's model. At 1080p the FFT
// takes a disk from about 99 px across (against the row spans of a kernel mirrored in y,
// two threads: 0.77x their time at 127 px, 1.05x at 95, 1.39x at 63; its wall time measured
// 0.69-0.85 of this model at 95-191 px, 0.85-1.0 at 15-63) and a Gaussian from sigma ~7.
//
// Double precision throughout: float transforms leave noise of ~1e-7 of a tile's largest
// value everywhere, so a 1e6 highlight would put ~0.1 into the black around it; in double
// it is ~1e-10. Tiles, plans and the order of every sum depend on the image and kernel
// sizes only, never on the thread count, so results are identical for any thread count.
// FFTW_ESTIMATE plans: measured plans (FFTW_MEASURE) run 20-30 % faster but take
// 0.2-2.5 s to make, and may differ from run to run, and so would the last bits. Debian's
// FFTW has SSE2 and AVX kernels, not AVX-512.
// Known limits: tiles grow with the kernel: a 4096 px kernel needs 6144 x 6144 points,
// 300 MB in double, per kernel channel in use plus one tile in flight (tiles of over 2^24
// points run one at a time): a 4096 px kernel image on a 640 x 360 image took 7.9 s and
// 0.9 GB. Kernels must be under 8192 px across. Tiles recompute the kernel-wide margins
// they share.

#include <bokeh/blur.h>
#include <bokeh/image.h>
#include <bokeh/parallel.h>

#include "base/fftw_planner.h"
#include "blur/convolve.h"
#include "base/progress.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>

#include <fftw3.h>
#include <tbb/enumerable_thread_specific.h>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace detail;
using OIIO::Strutil::fmt::format;

namespace {

std::mutex& planner_mutex() { return fftw_planner_mutex(); }

struct FftBuffer {
    double* data = nullptr;
    explicit FftBuffer(size_t n) : data(fftw_alloc_real(n)) {}
    ~FftBuffer() { fftw_free(data); }
    FftBuffer(const FftBuffer&)            = delete;
    FftBuffer& operator=(const FftBuffer&) = delete;
};

// The largest tile (8192 x 8192: kernels under 8192 px across), and the size above which
// tiles run one at a time.
constexpr double kMaxTilePoints = double(1 << 26), kParallelTilePoints = double(1 << 24);

// One transform tile: ny x nx points; a real row is stored in 2 (nx / 2 + 1) doubles, as
// FFTW's in-place real transforms want.
struct TileGrid {
    int ny = 0, nx = 0;    // transform size
    int vy = 0, vx = 0;    // outputs per tile: ny - 2 ry, nx - 2 rx
    int nty = 0, ntx = 0;  // tiles down and across
    double cost_ns = std::numeric_limits<double>::infinity();  // one channel, one thread
    size_t row() const { return 2 * size_t(nx / 2 + 1); }
    size_t points() const { return size_t(ny) * row(); }
};

// Single-thread time of one channel of one tile, in ns: its forward and backward
// transforms and the copy in. Fitted to this file's loop on the project's machine (Xeon,
// AVX-512, 2 MB L2 per core, FFTW_ESTIMATE in-place plans, both cores busy; ns per
// transformed point): 14.2 at 256 x 256, 15.4 at 256 x 512, 18-19 at 384 x 384 to
// 512 x 512, 17.4 at 512 x 1024, 21-25 at 768, 23-30 at 1024, 29-32 at 1024 x 2048 and
// 1536 x 1536, 34 at 1536 x 768 (the larger, the more the two cores contend for L3);
// ~10 at 64 x 64 alone; the copy in ~2.5. The fit errs high for 512-1024 rather than low
// for the largest.
double tile_cost_ns(int ny, int nx)
{
    const double points = double(ny) * double(nx);
    const double octaves = std::log2(points / 65536.0);  // 256 x 256
    double per_point = octaves < 0 ? 14.0 + 1.0 * octaves : 14.0 + 4.0 * octaves;
    return (per_point + 2.5) * points;
}

// The cheapest tiling of a w x h output for a kernel reaching rx, ry, by tile_cost_ns.
// Sizes: powers of two 8 .. 8192 and 3 times them from 384. FFTW_ESTIMATE plans of others
// measured up to 1.7x slower per point, alone (96, 192, 288, 360) and in this loop
// (1152 x 1024: 1.15x 1024 x 1024; 1215 x 2048: 1.5x 1024 x 2048; 192 x 384 at 1080p:
// 1.3x the 256 x 256 tiles).
TileGrid choose_tiles(int w, int h, int rx, int ry)
{
    std::vector<int> sizes;
    for (int p = 8; p <= 8192; p *= 2) {
        sizes.push_back(p);
        if (3 * p >= 384 && 3 * p <= 8192)
            sizes.push_back(3 * p);
    }
    TileGrid best;
    for (int ny : sizes)
        for (int nx : sizes) {
            if (ny <= 2 * ry || nx <= 2 * rx || double(ny) * double(nx) > kMaxTilePoints)
                continue;
            TileGrid g;
            g.ny = ny, g.nx = nx, g.vy = ny - 2 * ry, g.vx = nx - 2 * rx;
            g.nty = (h + g.vy - 1) / g.vy, g.ntx = (w + g.vx - 1) / g.vx;
            // The copy out, ~3 ns per output value (strided writes into fresh pages).
            g.cost_ns = double(g.nty) * double(g.ntx) * tile_cost_ns(ny, nx) + 3.0 * double(w) * h;
            if (g.cost_ns < best.cost_ns)
                best = g;
        }
    return best;
}

struct Plans {
    fftw_plan forward = nullptr, backward = nullptr;
    explicit Plans(const TileGrid& g)
    {
        FftBuffer buf(g.points());
        auto* cplx = reinterpret_cast<fftw_complex*>(buf.data);
        std::lock_guard<std::mutex> lock(planner_mutex());
        forward  = fftw_plan_dft_r2c_2d(g.ny, g.nx, buf.data, cplx, FFTW_ESTIMATE);
        backward = fftw_plan_dft_c2r_2d(g.ny, g.nx, cplx, buf.data, FFTW_ESTIMATE);
    }
    ~Plans()
    {
        std::lock_guard<std::mutex> lock(planner_mutex());
        fftw_destroy_plan(forward);
        fftw_destroy_plan(backward);
    }
    Plans(const Plans&)            = delete;
    Plans& operator=(const Plans&) = delete;
};

// a[i] *= b[i] for n complex numbers stored as (re, im) pairs. Written out, not as
// std::complex: its product checks for NaN and calls a library routine, which keeps the
// loop from vectorising (9 % of the FFT disk's time at 63 px, A/B). A NaN pixel spoils
// its whole tile either way; bokehtool's --nan policy keeps them out of the blurs.
BOKEH_HOT void multiply_spectra(double* a, const double* b, size_t n)
{
    for (size_t i = 0; i < n; ++i) {
        const double ar = a[2 * i], ai = a[2 * i + 1], br = b[2 * i], bi = b[2 * i + 1];
        a[2 * i]     = ar * br - ai * bi;
        a[2 * i + 1] = ar * bi + ai * br;
    }
}

// The convolution of a w x h output in tiling `g`, every channel c with kernel
// kernels[kernel_of[c]] (all reaching the same rx, ry). `read_row(y, x0, x1, buf)`
// returns the source row y (output coordinates; y in [-ry, h + ry)) over columns
// [x0, x1), all channels interleaved, border rule applied (or `buf` filled with it), or
// nullptr for a black row; `out_pixel(x, y)` is where output pixel (x, y) goes, channels
// interleaved.
template<class ReadRow, class OutPixel>
void convolve_tiles(int w, int h, int nc, const TileGrid& g, const std::vector<KernelWeights>& kernels,
                    const std::vector<int>& kernel_of, ReadRow read_row, OutPixel out_pixel,
                    int nthreads, const std::function<void(float)>& progress = {})
{
    if (w <= 0 || h <= 0)
        return;
    const int rx = kernels[0].rx, ry = kernels[0].ry;
    const Plans plans(g);
    const size_t rs = g.row(), ncs = size_t(nc);
    const double scale = 1.0 / (double(g.ny) * double(g.nx));  // FFTW's transforms are unnormalised

    // The transforms of the kernels in use, each placed cyclically with its centre at the
    // origin, and divided by the transform size. out(x) = sum_d w(d) in(x - d), as
    // convolve_brute.
    std::vector<std::unique_ptr<FftBuffer>> spectra(kernels.size());
    std::vector<bool> used(kernels.size(), false);
    for (int k : kernel_of)
        used[size_t(k)] = true;
    parallel_for_chunks(0, int64_t(kernels.size()), 1, nthreads, [&](int64_t k0, int64_t k1) {
        for (int64_t k = k0; k < k1; ++k) {
            if (!used[size_t(k)])
                continue;
            const KernelWeights& kw = kernels[size_t(k)];
            auto s = std::make_unique<FftBuffer>(g.points());
            std::fill_n(s->data, g.points(), 0.0);
            for (int dy = -ry; dy <= ry; ++dy)
                for (int dx = -rx; dx <= rx; ++dx)
                    s->data[size_t((dy + g.ny) % g.ny) * rs + size_t((dx + g.nx) % g.nx)]
                        = kw.at(dx, dy) * scale;
            fftw_execute_dft_r2c(plans.forward, s->data, reinterpret_cast<fftw_complex*>(s->data));
            spectra[size_t(k)] = std::move(s);
        }
    });

    struct Scratch {
        std::unique_ptr<FftBuffer> tile;
        std::vector<float> row;
    };
    tbb::enumerable_thread_specific<Scratch> scratch;
    // Work items: a channel of a tile, channel fastest (neighbouring items read the same
    // source rows).
    const int64_t items = int64_t(g.nty) * g.ntx * nc;
    const bool huge     = double(g.points()) > kParallelTilePoints;
    ProgressCounter counter(progress, double(items));
    parallel_for_chunks(0, items, 1, huge ? 1 : nthreads, [&](int64_t i0, int64_t i1) {
        Scratch& s = scratch.local();
        if (!s.tile) {
            s.tile = std::make_unique<FftBuffer>(g.points());
            s.row.resize(size_t(g.nx) * ncs);
        }
        double* const t = s.tile->data;
        for (int64_t item = i0; item < i1; ++item) {
            const int c    = int(item % nc);
            const int tile = int(item / nc);
            const int x0 = (tile % g.ntx) * g.vx, y0 = (tile / g.ntx) * g.vy;
            const int vx = std::min(g.vx, w - x0), vy = std::min(g.vy, h - y0);
            // Source columns [x0 - rx, x0 + vx + rx), rows [y0 - ry, y0 + vy + ry); the rest
            // of the tile is zero (it reaches only outputs that are not kept).
            const int cols = vx + 2 * rx, rows = vy + 2 * ry;
            for (int r = 0; r < rows; ++r) {
                const float* v = read_row(y0 - ry + r, x0 - rx, x0 - rx + cols, s.row.data());
                double* o      = t + size_t(r) * rs;
                int x          = 0;
                for (; v && x < cols; ++x)
                    o[x] = double(v[size_t(x) * ncs + size_t(c)]);
                std::fill(o + x, o + rs, 0.0);
            }
            std::fill(t + size_t(rows) * rs, t + g.points(), 0.0);
            fftw_execute_dft_r2c(plans.forward, t, reinterpret_cast<fftw_complex*>(t));
            multiply_spectra(t, spectra[size_t(kernel_of[size_t(c)])]->data, g.points() / 2);
            fftw_execute_dft_c2r(plans.backward, reinterpret_cast<fftw_complex*>(t), t);
            // Output (x0 + x, y0 + y) is the tile's (rx + x, ry + y).
            for (int y = 0; y < vy; ++y) {
                const double* r = t + size_t(ry + y) * rs + size_t(rx);
                float* o        = out_pixel(x0, y0 + y) + c;
                for (int x = 0; x < vx; ++x)
                    o[size_t(x) * ncs] = float(r[x]);
            }
            counter.add();
        }
    });
}

}  // namespace

namespace detail {

double fft_convolve_cost_ns(int w, int h, int nc, int rx, int ry)
{
    const TileGrid g = choose_tiles(w, h, rx, ry);
    // The kernel's transform, one tile's worth, runs before the tiles.
    return double(nc) * g.cost_ns + tile_cost_ns(g.ny, g.nx);
}

bool convolve_fft_direct(OIIO::ImageBuf& dst, const OIIO::ImageBuf& in, const OIIO::ROI& roi,
                         const std::vector<KernelWeights>& kernels, const std::vector<int>& kernel_of,
                         Border border, int nthreads, const std::function<void(float)>& progress)
{
    const TileGrid g = choose_tiles(roi.width(), roi.height(), kernels[0].rx, kernels[0].ry);
    if (g.ny == 0) {
        dst.errorfmt("blur: FFT tiles take kernels under 8192 px across; this one reaches {}x{}",
                     2 * kernels[0].rx + 1, 2 * kernels[0].ry + 1);
        return false;
    }
    prepare_destination(dst, in, roi);
    convolve_tiles(
        roi.width(), roi.height(), in.nchannels(), g, kernels, kernel_of,
        [&](int y, int x0, int x1, float* buf) {
            return bordered_row_view(in, roi.ybegin + y, roi.xbegin + x0, roi.xbegin + x1, border, buf);
        },
        [&](int x, int y) {
            return static_cast<float*>(dst.pixeladdr(roi.xbegin + x, roi.ybegin + y));
        },
        nthreads, progress);
    return true;
}

Plane convolve_fft(const Plane& in, const std::vector<KernelWeights>& kernels,
                   const std::vector<int>& kernel_of, int nthreads)
{
    const int rx = kernels[0].rx, ry = kernels[0].ry;
    Plane out(in.w - 2 * rx, in.h - 2 * ry, in.nc);
    const size_t ncs = size_t(in.nc);
    convolve_tiles(
        out.w, out.h, in.nc, choose_tiles(out.w, out.h, rx, ry), kernels, kernel_of,
        [&](int y, int x0, int, float*) { return in.row(y + ry) + size_t(x0 + rx) * ncs; },
        [&](int x, int y) { return out.row(y) + size_t(x) * ncs; }, nthreads);
    return out;
}

}  // namespace detail

namespace {

// How far a kernel image's weights may cancel: their absolute sum over their sum.
constexpr double kMaxKernelCancellation = 1e6;

// A kernel image (float, any data window) as normalised weights for an image of `nc`
// channels: kernels[kernel_of[c]] blurs channel c (convolve_image's rules, blur.h). False +
// `err` for a kernel it refuses.
bool kernel_image_weights(const OIIO::ImageBuf& kf, int nc, float iris, std::vector<KernelWeights>& kernels,
                          std::vector<int>& kernel_of, std::string& err)
{
    const OIIO::ROI kr = kf.roi();
    // An aperture picture's alpha (its coverage, not a weight) is dropped where the image has
    // no channel for it: an RGBA aperture scan on an RGB plate.
    const int knc = kf.nchannels() > nc && kf.spec().alpha_channel == kf.nchannels() - 1 ? kf.nchannels() - 1
                                                                                          : kf.nchannels();
    if (kr.width() > 4096 || kr.height() > 4096) {
        err = format("the kernel image is {}x{}; at most 4096x4096", kr.width(), kr.height());
        return false;
    }
    // Other kernel channels past the image's would be dropped unseen (6 on RGBA).
    if (knc > nc) {
        err = format("the kernel image has {} channels, the image {}: a kernel has 1 channel (for all) or at most "
                     "one per image channel",
                     knc, nc);
        return false;
    }
    // Centre and reach: kernel pixel (x, y) is offset (x - cx, y - cy).
    const int cx = kr.xbegin + kr.width() / 2, cy = kr.ybegin + kr.height() / 2;
    const int rx = std::max(cx - kr.xbegin, kr.xend - 1 - cx);
    const int ry = std::max(cy - kr.ybegin, kr.yend - 1 - cy);
    // Kernel channels as weights, normalised; source channel c uses kernels[kernel_of[c]].
    kernels.assign(size_t(knc), KernelWeights{ rx, ry, {} });
    for (int c = 0; c < knc; ++c) {
        KernelWeights& k = kernels[size_t(c)];
        k.w.assign(size_t(2 * rx + 1) * size_t(2 * ry + 1), 0.0);
        double sum = 0.0, abs_sum = 0.0;
        for (OIIO::ImageBuf::ConstIterator<float> it(kf); !it.done(); ++it) {
            if (!std::isfinite(it[c])) {
                err = format("the kernel image has a non-finite value at ({}, {})", it.x(), it.y());
                return false;
            }
            k.w[size_t(it.y() - cy + ry) * size_t(2 * rx + 1) + size_t(it.x() - cx + rx)] = it[c];
            sum += it[c];
            abs_sum += std::fabs(double(it[c]));
        }
        if (!(sum > 0.0)) {
            err = format("kernel image channel {} sums to {}; it must be positive", c, sum);
            return false;
        }
        // Weights that cancel to a sum far below their size make each output a difference of
        // huge terms, up to abs_sum / sum times the source's values: past float's range, and
        // decided by rounding (the kernel-image fuzz target's 7x1 kernel 1, 1, 1, -3e38, 1,
        // 3e38, 0.5 gave infinities on a source in [0, 1];
        // tests/fuzz/regressions/kernel_image). A sharpening kernel is a few times its sum.
        if (abs_sum > kMaxKernelCancellation * sum) {
            err = format("kernel image channel {}: its weights cancel (absolute sum {:g}, sum {:g}); the "
                         "absolute sum may be at most {:g} times the sum",
                         c, abs_sum, sum, kMaxKernelCancellation);
            return false;
        }
        // A weighted mean of exp(k x) with negative weights can fall to 0 or below, whose log
        // is NaN or -inf: iris mode takes kernels without them.
        if (iris != 0.0f && *std::min_element(k.w.begin(), k.w.end()) < 0.0) {
            err = format("iris mode needs a kernel image without negative weights (channel {} has some)", c);
            return false;
        }
        for (double& v : k.w)
            v /= sum;
    }
    if (knc > 1 && knc < nc) {  // the extra source channels use the kernel channels' mean
        KernelWeights mean{ rx, ry, std::vector<double>(kernels[0].w.size(), 0.0) };
        for (const KernelWeights& k : kernels)
            for (size_t i = 0; i < k.w.size(); ++i)
                mean.w[i] += k.w[i] / knc;
        kernels.push_back(std::move(mean));
    }
    kernel_of.resize(static_cast<size_t>(nc));
    for (int c = 0; c < nc; ++c)
        kernel_of[size_t(c)] = knc == 1 ? 0 : (c < knc ? c : knc);
    return true;
}

}  // namespace

bool check_kernel_image(const OIIO::ImageBuf& kernel, int image_channels, const BlurOptions& opts, std::string& err)
{
    OIIO::ImageBuf checked;
    if (!check_source(checked, kernel, "blur kernel image")) {
        err = checked.geterror();
        return false;
    }
    OIIO::ImageBuf kernel_holder;
    std::vector<KernelWeights> kernels;
    std::vector<int> kernel_of;
    return kernel_image_weights(float_source(kernel, kernel_holder), image_channels, opts.iris, kernels, kernel_of,
                                err);
}

bool convolve_image(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ImageBuf& kernel,
                    const BlurOptions& opts, OIIO::ROI roi, int nthreads)
{
    if (!check_source(dst, src) || !check_source(dst, kernel, "blur kernel image"))
        return false;
    OIIO::ImageBuf src_holder, kernel_holder;
    const OIIO::ImageBuf& in = float_source(src, src_holder);
    const int nc             = in.nchannels();
    std::vector<KernelWeights> kernels;
    std::vector<int> kernel_of;
    std::string err;
    if (!kernel_image_weights(float_source(kernel, kernel_holder), nc, opts.iris, kernels, kernel_of, err)) {
        dst.errorfmt("convolve: {}", err);
        return false;
    }
    const int rx = kernels[0].rx, ry = kernels[0].ry;

    if (!roi.defined())
        roi = opts.grow ? grown(in.roi(), rx, ry) : in.roi();
    // The FFT would spread a NaN or an infinity over its whole tile.
    if (any_nonfinite(in, nthreads))
        return blur_nonfinite(dst, in, kernels, kernel_of, opts.border, opts.iris != 0.0f,
                              [&](OIIO::ImageBuf& out, const OIIO::ImageBuf& replaced) {
                                  return convolve_image(out, replaced, kernel, opts, roi, nthreads);
                              }, nthreads);
    if (opts.iris == 0.0f)
        return convolve_fft_direct(dst, in, roi, kernels, kernel_of, opts.border, nthreads, opts.progress);
    // Iris mode needs each channel's range over the whole padded region first (Iris), so it
    // works on a padded plane.
    Plane p = pad(in, grown(roi, rx, ry), opts.border, nthreads);
    Iris iris;
    iris.k     = opts.iris;
    iris.alpha = in.spec().alpha_channel;
    iris.z     = in.spec().z_channel;
    if (!iris.forward(p, err, nthreads)) {
        dst.errorfmt("convolve: {}", err);
        return false;
    }
    Plane out = convolve_fft(p, kernels, kernel_of, nthreads);
    iris.inverse(out, nthreads);
    return finish(dst, in, roi, out, 0, 0, false, nthreads);
}

}  // namespace bokeh
