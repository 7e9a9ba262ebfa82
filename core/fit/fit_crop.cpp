// fit_crop.cpp — the crops the lens fit reads (fit/fit_model.h): a crop's pixels, what
// is left out of it (the frame's non-finite pixels, clipped highlights, other bokeh), its
// background plane and texture, the largest lit region and the first estimates of its
// centre and CoC; the noise model (a read and a photon term) estimated from the crops'
// flat parts and again from the fit's residuals.

#include <bokeh/base.h>
#include <bokeh/lens_fit.h>

#include "fit/fit_model.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include <OpenImageIO/strutil.h>

namespace bokeh {
namespace fit {

using OIIO::Strutil::fmt::format;

namespace {

// The noise model's floor, a fraction of the brightest crop's light level (CropData::
// level): the model's own precision (the PSF's 0.5 px radial bins, bilinear sub-pixel
// shifts, the fit's spectral step), so that a noise-free crop does not weigh a rounding
// difference as a feature.
constexpr double kModelFloorOfLevel = 1e-2;

double median_of(std::vector<double> v)
{
    if (v.empty())
        return 0.0;
    const size_t m = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + m, v.end());
    return v[m];
}



// The difference of pixel (i, j) (interior) from the mean of its four neighbours, of
// channel `ch` (-1: the luminance); false when any of the five is left out. Its variance
// is (1 + 1/4) sigma^2 where the signal is locally linear.
bool four_neighbour_difference(const CropData& d, int i, int j, int ch, double& r)
{
    const size_t k       = size_t(j) * d.w + i;
    const size_t nb[4]   = { k - 1, k + 1, k - size_t(d.w), k + size_t(d.w) };
    if (!d.use[k] || !d.use[nb[0]] || !d.use[nb[1]] || !d.use[nb[2]] || !d.use[nb[3]])
        return false;
    auto value = [&](size_t n) { return ch < 0 ? luminance(&d.px[n * d.channels], d.channels) : d.px[n * d.channels + ch]; };
    double mean = 0.0;
    for (size_t n : nb)
        mean += 0.25 * value(n);
    r = value(k) - mean;
    return true;
}

// Fit a plane to the crop's outermost two rows and columns per channel (least squares),
// and estimate the noise.
void border_background(const CropData& d, double plane[3][3], double& sigma, double& texture)
{
    // Least squares, reweighted three times (Cauchy at 3 MADs of the residuals) so that a
    // neighbour highlight across part of the border does not tilt the plane.
    auto border = [&](int i, int j) { return i < 2 || j < 2 || i >= d.w - 2 || j >= d.h - 2; };
    std::vector<size_t> ring;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i)
            if (border(i, j) && d.use[size_t(j) * d.w + i])
                ring.push_back(size_t(j) * d.w + i);
    for (int ch = 0; ch < 3; ++ch) {
        double x[3] = { 0, 0, 0 };
        std::vector<double> w(ring.size(), 1.0);
        for (int pass = 0; pass < 4 && ch < d.channels; ++pass) {
            double ata[9] = {}, atb[3] = {};
            for (size_t n = 0; n < ring.size(); ++n) {
                const int i = int(ring[n] % size_t(d.w)), j = int(ring[n] / size_t(d.w));
                const double col[3] = { 1.0, plane_x(d, i), plane_y(d, j) };
                for (int r = 0; r < 3; ++r) {
                    for (int c = 0; c < 3; ++c)
                        ata[r * 3 + c] += w[n] * col[r] * col[c];
                    atb[r] += w[n] * col[r] * d.px[ring[n] * d.channels + ch];
                }
            }
            if (!solve_linear(3, ata, atb, x))
                x[0] = x[1] = x[2] = 0.0;
            std::vector<double> res(ring.size());
            for (size_t n = 0; n < ring.size(); ++n) {
                const int i = int(ring[n] % size_t(d.w)), j = int(ring[n] / size_t(d.w));
                res[n] = d.px[ring[n] * d.channels + ch] - (x[0] + x[1] * plane_x(d, i) + x[2] * plane_y(d, j));
            }
            std::vector<double> a(res.size());
            for (size_t n = 0; n < res.size(); ++n)
                a[n] = std::abs(res[n]);
            const double scale = std::max(3.0 * 1.4826 * median_of(a), 1e-30);
            for (size_t n = 0; n < res.size(); ++n)
                w[n] = 1.0 / (1.0 + (res[n] / scale) * (res[n] / scale));
        }
        std::copy(x, x + 3, plane[ch]);
    }
    // The background's own texture: the luminance's MAD about the plane along the border,
    // as a normal's sigma (a textured wall behind the light is not noise, but no more a
    // highlight than noise is).
    std::vector<double> dev;
    for (size_t k : ring) {
        const int i = int(k % size_t(d.w)), j = int(k / size_t(d.w));
        float bg[3];
        for (int c = 0; c < 3; ++c)
            bg[c] = float(plane[c][0] + plane[c][1] * plane_x(d, i) + plane[c][2] * plane_y(d, j));
        dev.push_back(std::abs(luminance(&d.px[k * d.channels], d.channels) - luminance(bg, d.channels)));
    }
    texture = 1.4826 * median_of(dev);
    // The noise: the median of the luminance's four-neighbour differences over the crop
    // (the median passes over the rim, a neighbour and blocking), as a normal's sigma.
    std::vector<double> lap;
    for (int j = 1; j + 1 < d.h; ++j)
        for (int i = 1; i + 1 < d.w; ++i) {
            double r = 0.0;
            if (four_neighbour_difference(d, i, j, -1, r))
                lap.push_back(std::abs(r));
        }
    sigma = 1.4826 * median_of(lap) / std::sqrt(1.25);
}

}  // namespace

namespace {

// A crop's pixels as floats (its first three channels, or one), the non-finite ones left
// out; `vmax` its largest finite value. False + `err` for an unusable image.
bool read_crop(CropData& d, const OIIO::ImageBuf& img, const std::string& name, float& vmax, std::string& err)
{
    const OIIO::ImageSpec& spec = img.spec();
    if (img.has_error() || spec.nchannels < 1 || spec.deep)
        return err = format("{}: not a flat image with channels", name), false;
    d.w = spec.width, d.h = spec.height;
    if (d.w < 9 || d.h < 9)
        return err = format("{} is {}x{} px: too small to hold a bokeh (at least 9x9)", name, d.w, d.h), false;
    if (size_t(d.w) * d.h > size_t(4096) * 4096)
        return err = format("{} is {}x{} px: larger than a crop of one highlight needs (at most 4096x4096)",
                            name, d.w, d.h),
               false;
    d.channels = spec.nchannels >= 3 ? 3 : 1;
    d.px.resize(size_t(d.w) * d.h * d.channels);
    img.get_pixels(OIIO::ROI(spec.x, spec.x + d.w, spec.y, spec.y + d.h, spec.z, spec.z + 1, 0, d.channels),
                   OIIO::TypeDesc::FLOAT, d.px.data());
    d.use.assign(size_t(d.w) * d.h, 1);

    // Left out: non-finite pixels.
    vmax = -std::numeric_limits<float>::infinity();
    for (size_t k = 0; k < d.use.size(); ++k)
        for (int c = 0; c < d.channels; ++c) {
            const float v = d.px[k * d.channels + c];
            if (!std::isfinite(v))
                d.use[k] = 0;
            else
                vmax = std::max(vmax, v);
        }
    for (uint8_t u : d.use)
        d.nonfinite += !u;
    if (size_t(d.nonfinite) == d.use.size())
        return err = format("{} holds no finite pixel", name), false;

    return true;
}

// Label the 4-connected regions of the pixels `lit` says are lit; the largest's label
// (-1: none). `label` holds each pixel's region (-1: not lit).
int largest_region(const CropData& d, const std::function<bool(size_t)>& lit, std::vector<int>& label)
{
    label.assign(size_t(d.w) * d.h, -1);
    int best_label = -1;
    size_t best_size = 0;
    std::vector<size_t> stack;
    for (size_t start = 0; start < label.size(); ++start) {
        if (label[start] >= 0 || !lit(start))
            continue;
        const int id = int(start);
        size_t size  = 0;
        stack.assign(1, start);
        label[start] = id;
        while (!stack.empty()) {
            const size_t k = stack.back();
            stack.pop_back();
            ++size;
            const int i = int(k % size_t(d.w)), j = int(k / size_t(d.w));
            const size_t nb[4] = { i > 0 ? k - 1 : k, i + 1 < d.w ? k + 1 : k, j > 0 ? k - size_t(d.w) : k,
                                   j + 1 < d.h ? k + size_t(d.w) : k };
            for (size_t n : nb)
                if (label[n] < 0 && lit(n)) {
                    label[n] = id;
                    stack.push_back(n);
                }
        }
        if (size > best_size)
            best_size = size, best_label = id;
    }
    return best_label;
}

// Whether a crop was cut inside its bokeh: no highlight stands above the plane the border
// gave, but the border itself holds light (its brightest tenth 10 noise levels above its
// darkest, as where the bokeh's edge crosses it); or the plane is the bokeh's plateau
// itself, a twentieth of the crop (its outside) far below it, past the noise and the
// background's texture.
bool cut_inside_bokeh(const CropData& d, const std::vector<double>& sig, double peak, double noise, double texture)
{
    std::vector<double> ring;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            if ((i == 0 || j == 0 || i == d.w - 1 || j == d.h - 1) && d.use[k])
                ring.push_back(luminance(&d.px[k * d.channels], d.channels));
        }
    std::sort(ring.begin(), ring.end());
    const double spread = ring.empty() ? 0.0 : ring[ring.size() * 9 / 10] - ring[ring.size() / 10];
    int below = 0;
    for (size_t k = 0; k < sig.size(); ++k)
        below += d.use[k] && sig[k] < -std::max(10.0 * noise, 6.0 * texture);
    return (!(peak > 10.0 * noise) && spread > 10.0 * noise) || below > int(sig.size() / 20);
}

// The field position of the highlight's centre: given, else from the crop's data window
// in its display window (a crop cut from a frame with its origin kept).
void set_field_position(CropData& d, const LensFitCrop& crop)
{
    const OIIO::ImageSpec& spec = crop.image.spec();
    const bool windowed = spec.full_width > 0 && spec.full_height > 0
                          && (spec.full_x != spec.x || spec.full_y != spec.y || spec.full_width != spec.width
                              || spec.full_height != spec.height);
    if (std::isfinite(crop.field_x) && std::isfinite(crop.field_y)) {
        d.fx = crop.field_x, d.fy = crop.field_y, d.field_known = true;
    } else if (windowed) {
        const double half_diag = 0.5 * std::hypot(double(spec.full_width), double(spec.full_height));
        d.fx = (spec.x + d.cx0 - (spec.full_x + 0.5 * spec.full_width)) / half_diag;
        d.fy = -(spec.y + d.cy0 - (spec.full_y + 0.5 * spec.full_height)) / half_diag;
        d.field_known = true;
    }
}

}  // namespace

bool prepare_crop(CropData& d, const LensFitCrop& crop, size_t index, double clip_level, std::string& err)
{
    const std::string name = format("crop {}", index + 1);
    float vmax             = 0.0f;
    if (!read_crop(d, crop.image, name, vmax, err))
        return false;

    // The background plane and read noise from the border (before clipping is decided:
    // a highlight's plateau shares its maximum exactly only where the plate clipped it, or
    // where there is no noise at all, as in a render).
    double plane[3][3];
    double sigma = 0.0, texture = 0.0;
    border_background(d, plane, sigma, texture);
    double clip = clip_level;
    if (clip <= 0.0 && std::isfinite(vmax) && vmax > 0.0f && sigma > 1e-7 * vmax) {
        int at_max = 0;
        for (size_t k = 0; k < d.use.size(); ++k)
            for (int c = 0; c < d.channels && d.use[k]; ++c)
                at_max += d.px[k * d.channels + c] == vmax;
        if (at_max > 2)
            clip = vmax;
    }
    if (clip > 0.0)
        for (size_t k = 0; k < d.use.size(); ++k)
            for (int c = 0; c < d.channels && d.use[k]; ++c)
                if (d.px[k * d.channels + c] >= clip) {
                    d.use[k] = 0;
                    ++d.clipped;
                }

    // The highlight's moments.
    std::vector<double> sig(d.use.size(), 0.0);
    double peak = 0.0;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            float bg[3];
            for (int c = 0; c < 3; ++c)
                bg[c] = float(plane[c][0] + plane[c][1] * plane_x(d, i) + plane[c][2] * plane_y(d, j));
            sig[k] = luminance(&d.px[k * d.channels], d.channels) - luminance(bg, d.channels);
            if (d.use[k])
                peak = std::max(peak, sig[k]);
        }
    const double noise = std::max(sigma, 1e-6 * std::max(peak, 1e-30));
    int clipped_in_light = 0, light = 0;
    double clip_sig = 0.0;
    for (size_t k = 0; k < sig.size(); ++k)
        if (!d.use[k] && d.nonfinite == 0 && sig[k] > 0.0)
            clip_sig = std::max(clip_sig, sig[k]);
    // The highlight: above a tenth of its peak (on a plate, the glow of other lights and
    // the background's large-scale shading reach past a few percent; a bright-centred
    // bokeh's halo below a tenth is then left to the stages, whose CoC may go to 3 times
    // this first estimate), 6 noise levels and 4 of the background's texture.
    const double level = std::max({ 0.1 * std::max(peak, clip_sig), 6.0 * noise, 4.0 * texture });
    // The highlight is the largest 4-connected region above the level; the others (a
    // neighbour across the crop's edge) are left out of the fit.
    std::vector<int> label;
    const int best_label = largest_region(
        d, [&](size_t k) { return sig[k] > level || (!d.use[k] && std::isfinite(sig[k]) && d.clipped > 0); }, label);
    for (size_t k = 0; k < sig.size(); ++k)
        if (label[k] >= 0 && label[k] != best_label && d.use[k]) {
            d.use[k] = 0;
            ++d.others;
        }
    double m0 = 0, mx = 0, my = 0;
    int touches[4] = { 0, 0, 0, 0 };
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            const bool clipped = !d.use[k] && std::isfinite(sig[k]) && d.clipped > 0;
            if (label[k] != best_label || label[k] < 0)
                continue;
            ++light;
            clipped_in_light += clipped;
            const double wgt = clipped ? std::max(peak, clip_sig) : sig[k];
            m0 += wgt, mx += wgt * (i + 0.5), my += wgt * (j + 0.5);
            touches[0] += i == 0, touches[1] += i == d.w - 1, touches[2] += j == 0, touches[3] += j == d.h - 1;
        }
    if (cut_inside_bokeh(d, sig, peak, noise, texture))
        return err = format("{} ({}x{} px) is smaller than its bokeh: light crosses its border; cut it wider "
                            "than the bokeh",
                            name, d.w, d.h),
               false;
    if (peak > 10.0 * noise && m0 <= 0.0)  // light, but none above the border's own spread
        return err = format("{} ({}x{} px) is smaller than its bokeh: its border holds light as bright as "
                            "its inside; cut it wider than the bokeh",
                            name, d.w, d.h),
               false;
    if (!(peak > 10.0 * noise) || m0 <= 0.0)
        return err = format("{} holds no highlight: its brightest pixel stands {:.1f} noise levels above the "
                            "background (a highlight needs 10)",
                            name, noise > 0 ? std::max(peak, 0.0) / noise : 0.0),
               false;
    if (light > 0 && clipped_in_light > 0.95 * light)
        return err = format("{} is clipped over {:.0f} % of its highlight: too little of the bokeh's profile "
                            "is left to fit",
                            name, 100.0 * clipped_in_light / light),
               false;
    d.cx0 = mx / m0, d.cy0 = my / m0;
    // Size from the second moment about the centre: a uniform disk of diameter D has
    // E[r^2] = D^2 / 8.
    double m2 = 0, ms = 0;
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i) {
            const size_t k = size_t(j) * d.w + i;
            if (label[k] != best_label || label[k] < 0)
                continue;
            const double dx = i + 0.5 - d.cx0, dy = j + 0.5 - d.cy0;
            m2 += dx * dx + dy * dy;
            ms += 1.0;
        }
    d.coc0 = std::max(2.0, std::sqrt(8.0 * m2 / std::max(ms, 1.0)));
    const int sides = (touches[0] > 0) + (touches[1] > 0) + (touches[2] > 0) + (touches[3] > 0);
    if (sides >= 3 || d.coc0 > 1.05 * std::min(d.w, d.h))
        return err = format("{} ({}x{} px) is smaller than its bokeh (about {:.0f} px across): cut it at least "
                            "{:.0f} px wide",
                            name, d.w, d.h, d.coc0, d.coc0 + 8.0),
               false;
    d.peak = std::max(peak, clip_sig);
    // The light's level: its plateau, the 90th percentile over the highlight (clipped
    // pixels at the peak), the scale the noise floors are set in (a bright-centred
    // bokeh's peak can be many times its plateau; the percentile does not lean on the
    // first CoC's estimate, nor on how much of a plate's glow the highlight's region took).
    std::vector<double> lit_values;
    for (size_t k = 0; k < sig.size(); ++k)
        if (label[k] == best_label && best_label >= 0)
            lit_values.push_back(d.use[k] ? sig[k] : d.peak);
    std::sort(lit_values.begin(), lit_values.end());
    d.level = lit_values.empty() ? d.peak : std::min(d.peak, lit_values[lit_values.size() * 9 / 10]);

    set_field_position(d, crop);
    if (std::hypot(d.fx, d.fy) > 1.5)
        return err = format("{}: field position ({:g}, {:g}) is outside the frame (half-diagonals)", name, d.fx,
                            d.fy),
               false;
    d.inv_var.assign(d.px.size(), float(1.0 / (noise * noise)));  // estimate_noise sets the model
    prepare_fit_arrays(d);
    return true;
}

// The noise model from the data alone (a model's misfit must not pass for noise): each
// interior pixel's difference from the mean of its four neighbours, r = v - (n + s + e +
// w) / 4, has variance (1 + 1/4) sigma^2 where the signal is locally linear.
void estimate_noise(std::vector<CropData>& crops, double& read2, double& photon)
{
    struct Point {
        double v, r2;
    };
    std::vector<Point> pts;
    double peak = 0.0;
    for (const CropData& d : crops) {
        peak = std::max(peak, d.level);
        for (int ch = 0; ch < d.channels; ++ch)
            for (int j = 1; j + 1 < d.h; ++j)
                for (int i = 1; i + 1 < d.w; ++i) {
                    double r = 0.0;
                    if (four_neighbour_difference(d, i, j, ch, r))
                        pts.push_back({ d.px[(size_t(j) * d.w + i) * d.channels + ch], r * r / 1.25 });
                }
    }
    // In 16 bins of equal count by value: the median of r^2 / 0.4549 (the median of a
    // chi-square of one degree), robust to the few pixels of structure (a bright centre, the
    // rim) a bin holds; then least squares of those on the bins' mean values.
    std::sort(pts.begin(), pts.end(), [](const Point& x, const Point& y) { return x.v < y.v; });
    constexpr int kBins = 16;
    double s11 = 0, s1m = 0, smm = 0, s1r = 0, smr = 0;
    for (int bin = 0; bin < kBins && pts.size() >= size_t(4 * kBins); ++bin) {
        const size_t lo = pts.size() * size_t(bin) / kBins, hi = pts.size() * size_t(bin + 1) / kBins;
        std::vector<double> r2;
        double mv = 0.0;
        for (size_t k = lo; k < hi; ++k) {
            r2.push_back(pts[k].r2);
            mv += std::max(pts[k].v, 0.0) / double(hi - lo);
        }
        const double var = median_of(r2) / 0.4549;
        s11 += 1, s1m += mv, smm += mv * mv, s1r += var, smr += mv * var;
    }
    double a = s1r / std::max(s11, 1.0), b = 0.0;
    const double det = s11 * smm - s1m * s1m;
    if (det > 1e-12 * s11 * smm) {
        const double a2 = (smm * s1r - s1m * smr) / det, b2 = (s11 * smr - s1m * s1r) / det;
        if (b2 >= 0.0 && a2 >= 0.0)
            a = a2, b = b2;
        else if (b2 >= 0.0)
            a = 0.0, b = smr / std::max(smm, 1e-300);
    }
    read2  = std::max(a, kModelFloorOfLevel * kModelFloorOfLevel * peak * peak);
    photon = b;
    set_noise(crops, read2, photon);
}

void set_noise(std::vector<CropData>& crops, double read2, double photon)
{
    for (CropData& d : crops) {
        for (size_t k = 0; k < d.inv_var.size(); ++k) {
            const double v = d.px[k];
            d.inv_var[k]   = std::isfinite(v) ? float(1.0 / (read2 + photon * std::max(v, 0.0))) : 0.0f;
        }
        d.cached_floor2 = -1.0;
    }
}

void residual_noise(const std::vector<CropData>& crops, const Model& model, const State& s, double& read2,
                    double& photon)
{
    double s11 = 0, s1m = 0, smm = 0, s1r = 0, smr = 0, peak = 0;
    for (size_t i = 0; i < crops.size(); ++i) {
        const CropData& d = crops[i];
        peak = std::max(peak, d.level);
        Psf p;
        if (!model.psf(p, s, i, true, 0))
            continue;
        std::vector<float> smp;
        model.sample_crop(smp, p, s, i);
        Linear lin;
        Model::fit_linear(d, smp, lin);
        const size_t m = d.fit_k.size();
        for (int ch = 0; ch < d.channels; ++ch)
            for (size_t n = 0; n < m; ++n) {
                const double mod = lin.a[ch] * smp[size_t(ch) * m + n] + lin.b0[ch]
                                   + lin.bx[ch] * d.fit_x[n] + lin.by[ch] * d.fit_y[n];
                const double r  = d.fit_v[size_t(ch) * m + n] - mod;
                const double iv = d.inv_var[size_t(d.fit_k[n]) * d.channels + ch];
                if (r * r * iv > 25.0)  // past 5 sigma of the current model: not noise
                    continue;
                const double mm = std::max(mod, 0.0);
                s11 += 1, s1m += mm, smm += mm * mm, s1r += r * r, smr += mm * r * r;
            }
    }
    const double det = s11 * smm - s1m * s1m;
    double a = s1r / std::max(s11, 1.0), b = 0.0;
    if (det > 1e-12 * s11 * smm) {
        const double a2 = (smm * s1r - s1m * smr) / det, b2 = (s11 * smr - s1m * s1r) / det;
        if (a2 >= 0.0 && b2 >= 0.0)
            a = a2, b = b2;
    }
    read2  = std::max(a, kModelFloorOfLevel * kModelFloorOfLevel * peak * peak);
    photon = b;
}

}  // namespace fit
}  // namespace bokeh
