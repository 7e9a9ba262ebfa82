// metrics.cpp — error of a result against its reference, and the artifact metrics of
// enlargement (metrics.h). Sums are per row in double and combined in row order, so the
// figures do not depend on the thread count.
//
// The artifact metrics measure what Kawase's "Anti reduced-buffer artifacts" names (Mach
// bands, ringing, temporal twinkling, lost detail); the talk judges them by eye, so the
// formulas are ours and metrics.h states each. Their scenes are analytic and area-sampled exactly (erf for
// Gaussians, sinc attenuation for plane waves), so the low-resolution scene is the true
// reduction of the content and only the enlargement is measured.

#include <bokeh/base.h>
#include <bokeh/metrics.h>
#include <bokeh/parallel.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include <OpenImageIO/strutil.h>

namespace bokeh {

bool compare(ImageError& e, const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference,
             std::string& err, OIIO::ROI roi, int nthreads)
{
    if (result.deep() || reference.deep()) {
        err = "deep images cannot be compared; flatten them first";
        return false;
    }
    const int nc = result.nchannels();
    if (nc != reference.nchannels()) {
        err = OIIO::Strutil::fmt::format("channel counts differ ({} vs {})", nc,
                                         reference.nchannels());
        return false;
    }
    if (!roi.defined())
        roi = OIIO::roi_union(result.roi(), reference.roi());
    // Per chunk of rows: squared error, tone-mapped squared error, max, and the values
    // whose difference is not finite (NaN or an infinity on one side only). Those would
    // make the sums NaN, which compared as "no error" (999 dB) and fell out of the max:
    // a result full of NaN read as identical to its reference. Equal values (the same
    // infinity, or NaN on both sides) count as equal.
    using Sums = std::array<double, 4>;
    const Sums s = parallel_reduce_chunks(
        roi.ybegin, roi.yend, 8, nthreads, Sums{ 0.0, 0.0, 0.0, 0.0 },
        [&](int64_t y0, int64_t y1) {
            Sums t{ 0.0, 0.0, 0.0, 0.0 };
            std::vector<float> a(size_t(roi.width()) * size_t(nc)), b(a.size());
            for (int y = int(y0); y < int(y1); ++y) {
                const OIIO::ROI row(roi.xbegin, roi.xend, y, y + 1, 0, 1, 0, nc);
                // get_pixels fills pixels outside the data window with 0.
                result.get_pixels(row, OIIO::TypeFloat, a.data());
                reference.get_pixels(row, OIIO::TypeFloat, b.data());
                for (size_t i = 0; i < a.size(); ++i) {
                    const double x = a[i], r = b[i];
                    if (x == r || (std::isnan(x) && std::isnan(r)))
                        continue;
                    if (!std::isfinite(x - r)) {
                        t[3] += 1.0;
                        continue;
                    }
                    const double tx = x / (1.0 + std::abs(x)), tr = r / (1.0 + std::abs(r));
                    t[0] += (x - r) * (x - r);
                    t[1] += (tx - tr) * (tx - tr);
                    t[2] = std::max(t[2], std::abs(x - r));
                }
            }
            return t;
        },
        [](Sums& acc, const Sums& p) {
            acc[0] += p[0];
            acc[1] += p[1];
            acc[2] = std::max(acc[2], p[2]);
            acc[3] += p[3];
        });
    e.values      = int64_t(roi.width()) * roi.height() * nc;
    const double n = double(std::max<int64_t>(1, e.values));
    e.nonfinite = int64_t(s[3]);
    if (e.nonfinite > 0) {
        const double inf = std::numeric_limits<double>::infinity();
        e.rmse_linear    = inf;
        e.psnr_db        = -inf;
        e.max_abs        = inf;
        return true;
    }
    e.rmse_linear = std::sqrt(s[0] / n);
    e.psnr_db     = s[1] > 0.0 ? 10.0 * std::log10(n / s[1]) : 999.0;
    e.max_abs     = s[2];
    return true;
}

namespace {

using OIIO::Strutil::fmt::format;

// The pixels of `roi` (all channels) as floats; 0 outside the data window.
std::vector<float> pixels_of(const OIIO::ImageBuf& img, const OIIO::ROI& roi)
{
    std::vector<float> v(size_t(roi.width()) * size_t(roi.height()) * size_t(img.nchannels()));
    img.get_pixels(OIIO::ROI(roi.xbegin, roi.xend, roi.ybegin, roi.yend, img.roi().zbegin,
                             img.roi().zbegin + 1, 0, img.nchannels()),
                   OIIO::TypeFloat, v.data());
    return v;
}

OIIO::ROI shrunk(OIIO::ROI r, int by)
{
    r.xbegin += by;
    r.xend -= by;
    r.ybegin += by;
    r.yend -= by;
    return r;
}

bool flat(const OIIO::ImageBuf& img, const char* what, std::string& err)
{
    if (!img.initialized() || img.deep()) {
        err = format("{}: needs a flat (not deep), non-empty image", what);
        return false;
    }
    return true;
}

using Sums2 = std::array<double, 2>;

// One line of n samples `stride` floats apart: adds the squared Mach residual and the
// squared slope (metrics.h) where the curvature window fits.
Sums2 mach_line(const float* v, size_t stride, int n, int period)
{
    Sums2 s{ 0.0, 0.0 };
    if (n < 3)
        return s;
    std::vector<double> d2(size_t(n), 0.0), prefix(size_t(n) + 1, 0.0);
    for (int i = 1; i + 1 < n; ++i)
        d2[size_t(i)] = double(v[size_t(i + 1) * stride]) - 2.0 * double(v[size_t(i) * stride])
                        + double(v[size_t(i - 1) * stride]);
    for (int i = 0; i < n; ++i)
        prefix[size_t(i) + 1] = prefix[size_t(i)] + d2[size_t(i)];
    const int half = period / 2;
    for (int i = 1 + half; i + 1 + half < n; ++i) {
        // The mean of d2 over a centred window of `period` samples (an even window has half
        // weights at its two ends).
        double mean;
        if (period % 2 == 1) {
            mean = (prefix[size_t(i + half + 1)] - prefix[size_t(i - half)]) / period;
        } else {
            mean = (prefix[size_t(i + half)] - prefix[size_t(i - half + 1)]
                    + 0.5 * (d2[size_t(i - half)] + d2[size_t(i + half)]))
                   / period;
        }
        const double r  = d2[size_t(i)] - mean;
        const double d1 = 0.5 * (double(v[size_t(i + 1) * stride]) - double(v[size_t(i - 1) * stride]));
        s[0] += r * r;
        s[1] += d1 * d1;
    }
    return s;
}

}  // namespace

bool mach_bands(double& score, const OIIO::ImageBuf& img, int period_px, std::string& err,
                OIIO::ROI roi, int nthreads)
{
    if (!flat(img, "mach_bands", err))
        return false;
    if (period_px < 1) {
        err = format("mach_bands: period {} must be >= 1", period_px);
        return false;
    }
    if (!roi.defined())
        roi = shrunk(img.roi(), 3 * period_px);
    if (roi.width() < period_px + 3 || roi.height() < period_px + 3) {
        err = format("mach_bands: the region {}x{} is too small for period {}", roi.width(),
                     roi.height(), period_px);
        return false;
    }
    const int w = roi.width(), h = roi.height(), nc = img.nchannels();
    const std::vector<float> v = pixels_of(img, roi);
    auto add = [](Sums2& a, const Sums2& b) {
        a[0] += b[0];
        a[1] += b[1];
    };
    // Rows, then columns; every channel a line of its own.
    Sums2 total = parallel_reduce_chunks(0, int64_t(h) * nc, 16, nthreads, Sums2{ 0.0, 0.0 },
        [&](int64_t b, int64_t e) {
            Sums2 s{ 0.0, 0.0 };
            for (int64_t l = b; l < e; ++l)
                add(s, mach_line(v.data() + size_t(l / nc) * size_t(w) * size_t(nc) + size_t(l % nc),
                                 size_t(nc), w, period_px));
            return s;
        },
        add);
    add(total, parallel_reduce_chunks(0, int64_t(w) * nc, 16, nthreads, Sums2{ 0.0, 0.0 },
        [&](int64_t b, int64_t e) {
            Sums2 s{ 0.0, 0.0 };
            for (int64_t l = b; l < e; ++l)
                add(s, mach_line(v.data() + size_t(l / nc) * size_t(nc) + size_t(l % nc),
                                 size_t(w) * size_t(nc), h, period_px));
            return s;
        },
        add));
    score = total[1] > 0.0 ? 100.0 * std::sqrt(total[0] / total[1]) : 0.0;
    return true;
}

bool ringing(Ringing& r, const OIIO::ImageBuf& result, const OIIO::ImageBuf& source,
             std::string& err, int nthreads)
{
    if (!flat(result, "ringing", err) || !flat(source, "ringing", err))
        return false;
    const int nc = result.nchannels();
    if (nc != source.nchannels()) {
        err = format("ringing: channel counts differ ({} vs {})", nc, source.nchannels());
        return false;
    }
    // Per channel: min, max, and (result only) the count of values below 0.
    struct Range {
        std::vector<double> lo, hi;
        std::vector<int64_t> negative;
    };
    auto range_of = [&](const OIIO::ImageBuf& img) {
        const OIIO::ROI roi = img.roi();
        Range init{ std::vector<double>(size_t(nc), std::numeric_limits<double>::infinity()),
                    std::vector<double>(size_t(nc), -std::numeric_limits<double>::infinity()),
                    std::vector<int64_t>(size_t(nc), 0) };
        return parallel_reduce_chunks(roi.ybegin, roi.yend, 8, nthreads, init,
            [&](int64_t y0, int64_t y1) {
                Range p = init;
                const std::vector<float> v =
                    pixels_of(img, OIIO::ROI(roi.xbegin, roi.xend, int(y0), int(y1)));
                for (size_t i = 0; i < v.size(); ++i) {
                    const size_t c = i % size_t(nc);
                    p.lo[c]        = std::min(p.lo[c], double(v[i]));
                    p.hi[c]        = std::max(p.hi[c], double(v[i]));
                    p.negative[c] += v[i] < 0.0f ? 1 : 0;
                }
                return p;
            },
            [&](Range& a, const Range& p) {
                for (size_t c = 0; c < size_t(nc); ++c) {
                    a.lo[c] = std::min(a.lo[c], p.lo[c]);
                    a.hi[c] = std::max(a.hi[c], p.hi[c]);
                    a.negative[c] += p.negative[c];
                }
            });
    };
    const Range res = range_of(result), src = range_of(source);
    r = Ringing();
    for (size_t c = 0; c < size_t(nc); ++c) {
        const double range = src.hi[c] - src.lo[c];
        if (range > 0.0 && std::isfinite(range)) {
            r.overshoot  = std::max(r.overshoot, 100.0 * (res.hi[c] - src.hi[c]) / range);
            r.undershoot = std::max(r.undershoot, 100.0 * (src.lo[c] - res.lo[c]) / range);
        }
        if (src.lo[c] >= 0.0 && res.lo[c] < 0.0) {
            r.most_negative = std::min(r.most_negative, res.lo[c]);
            r.negative_values += res.negative[c];
        }
    }
    return true;
}

bool shimmer(double& score, const std::vector<OIIO::ImageBuf>& frames,
             const std::vector<std::array<int, 2>>& shifts_px, std::string& err, OIIO::ROI roi,
             int nthreads)
{
    if (frames.size() < 2 || frames.size() != shifts_px.size()) {
        err = format("shimmer: needs two or more frames, one shift each ({} frames, {} shifts)",
                     frames.size(), shifts_px.size());
        return false;
    }
    const int nc = frames[0].nchannels();
    for (const OIIO::ImageBuf& f : frames) {
        if (!flat(f, "shimmer", err))
            return false;
        if (f.nchannels() != nc) {
            err = "shimmer: the frames' channel counts differ";
            return false;
        }
    }
    if (!roi.defined()) {
        int reach = 0;
        for (size_t i = 0; i < frames.size(); ++i) {
            OIIO::ROI r = frames[i].roi();
            r.xbegin -= shifts_px[i][0], r.xend -= shifts_px[i][0];
            r.ybegin -= shifts_px[i][1], r.yend -= shifts_px[i][1];
            roi   = i == 0 ? r : OIIO::roi_intersection(roi, r);
            reach = std::max({ reach, std::abs(shifts_px[i][0]), std::abs(shifts_px[i][1]) });
        }
        roi = shrunk(roi, reach);
    }
    if (roi.width() < 1 || roi.height() < 1) {
        err = "shimmer: the aligned frames do not overlap";
        return false;
    }
    const size_t n = frames.size();
    // Per chunk of rows: sum of squared deviations from the mean, sum of squared means.
    const Sums2 s = parallel_reduce_chunks(roi.ybegin, roi.yend, 8, nthreads, Sums2{ 0.0, 0.0 },
        [&](int64_t y0, int64_t y1) {
            std::vector<std::vector<float>> aligned(n);
            for (size_t i = 0; i < n; ++i)
                aligned[i] = pixels_of(frames[i],
                                       OIIO::ROI(roi.xbegin + shifts_px[i][0], roi.xend + shifts_px[i][0],
                                                 int(y0) + shifts_px[i][1], int(y1) + shifts_px[i][1]));
            Sums2 p{ 0.0, 0.0 };
            for (size_t k = 0; k < aligned[0].size(); ++k) {
                double mean = 0.0;
                for (size_t i = 0; i < n; ++i)
                    mean += aligned[i][k];
                mean /= double(n);
                for (size_t i = 0; i < n; ++i)
                    p[0] += (aligned[i][k] - mean) * (aligned[i][k] - mean);
                p[1] += mean * mean * double(n);
            }
            return p;
        },
        [](Sums2& a, const Sums2& p) {
            a[0] += p[0];
            a[1] += p[1];
        });
    score = s[1] > 0.0 ? 100.0 * std::sqrt(s[0] / s[1]) : 0.0;
    return true;
}

bool detail_error(double& score, const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference,
                  std::string& err, OIIO::ROI roi, int nthreads)
{
    if (!flat(result, "detail_error", err) || !flat(reference, "detail_error", err))
        return false;
    const int nc = reference.nchannels();
    if (result.nchannels() != nc) {
        err = format("detail_error: channel counts differ ({} vs {})", result.nchannels(), nc);
        return false;
    }
    if (!roi.defined())
        roi = reference.roi();
    // Per chunk of rows: per channel sum and sum of squares of the reference, and the
    // squared error; the contrast is then sum(r^2) - sum(r)^2 / n per channel.
    using Acc = std::vector<double>;  // [sum_c..., sumsq_c..., error]
    const Acc init(size_t(2 * nc + 1), 0.0);
    const Acc a = parallel_reduce_chunks(roi.ybegin, roi.yend, 8, nthreads, init,
        [&](int64_t y0, int64_t y1) {
            Acc p = init;
            const OIIO::ROI rows(roi.xbegin, roi.xend, int(y0), int(y1));
            const std::vector<float> x = pixels_of(result, rows), r = pixels_of(reference, rows);
            for (size_t i = 0; i < r.size(); ++i) {
                const size_t c = i % size_t(nc);
                p[c] += r[i];
                p[size_t(nc) + c] += double(r[i]) * r[i];
                p[size_t(2 * nc)] += (double(x[i]) - r[i]) * (double(x[i]) - r[i]);
            }
            return p;
        },
        [](Acc& acc, const Acc& p) {
            for (size_t i = 0; i < acc.size(); ++i)
                acc[i] += p[i];
        });
    const double n = double(roi.width()) * roi.height();
    double contrast = 0.0;
    for (size_t c = 0; c < size_t(nc); ++c)
        contrast += a[size_t(nc) + c] - a[c] * a[c] / n;
    if (!(contrast > 0.0)) {
        err = "detail_error: the reference has no contrast";
        return false;
    }
    score = 100.0 * std::sqrt(a[size_t(2 * nc)] / contrast);
    return true;
}

// --- the protocol -------------------------------------------------------------------------

namespace {


// The mass of a unit Gaussian (mean m, sigma s) in [a, b).
double gaussian_mass(double a, double b, double m, double s)
{
    const double k = 1.0 / (s * std::sqrt(2.0));
    return 0.5 * (std::erf((b - m) * k) - std::erf((a - m) * k));
}

double sinc(double x) { return x == 0.0 ? 1.0 : std::sin(kPi * x) / (kPi * x); }

OIIO::ImageBuf one_channel(int w, int h, const std::function<double(int, int)>& f)
{
    OIIO::ImageBuf img(OIIO::ImageSpec(w, h, 1, OIIO::TypeFloat));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const float v = float(f(x, y));
            img.setpixel(x, y, &v);
        }
    return img;
}

struct Wave {
    double fx, fy, amplitude, phase;  // cycles per texel
};
constexpr Wave kWaves[] = {
    { 0.37, 0.05, 0.12, 0.3 },
    { 0.11, 0.29, 0.10, 1.1 },
    { -0.23, 0.31, 0.08, 2.0 },
    { 0.40, -0.12, 0.06, 0.7 },
};

// The pattern averaged over a pixel of `size` texels centred at (cx, cy) texels.
double pattern(double cx, double cy, double size)
{
    double v = 0.5;
    for (const Wave& w : kWaves)
        v += w.amplitude * sinc(w.fx * size) * sinc(w.fy * size)
             * std::cos(2.0 * kPi * (w.fx * cx + w.fy * cy) + w.phase);
    return v;
}

}  // namespace

OIIO::ImageBuf artifact_scene(ArtifactScene scene, int factor, double shift)
{
    switch (scene) {
    case ArtifactScene::Glare:
        return one_channel(40, 40, [](int x, int y) {
            const double dx = x + 0.5 - 19.3, dy = y + 0.5 - 20.6;
            return 1.0 / (1.0 + (dx * dx + dy * dy) / (1.5 * 1.5));
        });
    case ArtifactScene::Step: return one_channel(24, 8, [](int x, int) { return x < 12 ? 0.0 : 1.0; });
    case ArtifactScene::Lights: {
        struct Light {
            double x, y, peak;
        };
        const Light lights[] = { { 5.3, 6.1, 1.0 },  { 12.7, 9.4, 2.0 }, { 20.2, 5.8, 4.0 },
                                 { 26.6, 14.3, 1.5 }, { 8.1, 22.7, 3.0 }, { 17.5, 19.9, 1.0 },
                                 { 24.9, 26.2, 2.5 } };
        const double s = 0.5;
        return one_channel(32, 32, [&](int x, int y) {
            double v = 0.0;
            for (const Light& l : lights)
                v += l.peak * 2.0 * kPi * s * s * gaussian_mass(x, x + 1, l.x + shift, s)
                     * gaussian_mass(y, y + 1, l.y + shift, s);
            return v;
        });
    }
    case ArtifactScene::Pattern:
        return one_channel(32, 32, [](int x, int y) { return pattern(x + 0.5, y + 0.5, 1.0); });
    case ArtifactScene::PatternReference: {
        const int k = std::max(1, factor);
        return one_channel(32 * k, 32 * k, [k](int x, int y) {
            return pattern((x + 0.5) / k, (y + 0.5) / k, 1.0 / k);
        });
    }
    }
    return {};
}

bool enlargement_artifacts(EnlargementArtifacts& a, int factor, const EnlargeFunction& enlarge,
                           std::string& err, int nthreads)
{
    if (factor < 1 || factor > 64) {
        err = format("enlargement_artifacts: factor {} is outside 1..64", factor);
        return false;
    }
    const int k = factor;
    auto run = [&](OIIO::ImageBuf& out, const OIIO::ImageBuf& in, const char* scene) {
        if (!enlarge(out, in)) {
            err = format("enlarging the {} scene failed: {}", scene, out.geterror());
            return false;
        }
        const OIIO::ROI want(0, in.spec().width * k, 0, in.spec().height * k);
        if (out.roi().xbegin != want.xbegin || out.roi().xend != want.xend
            || out.roi().ybegin != want.ybegin || out.roi().yend != want.yend) {
            err = format("enlarging the {} scene gave {}x{} pixels at {},{}, not {}x{} at 0,0",
                         scene, out.roi().width(), out.roi().height(), out.roi().xbegin,
                         out.roi().ybegin, want.width(), want.height());
            return false;
        }
        return true;
    };
    OIIO::ImageBuf out;
    if (!run(out, artifact_scene(ArtifactScene::Glare), "glare")
        || !mach_bands(a.mach, out, k, err, {}, nthreads))
        return false;
    const OIIO::ImageBuf step = artifact_scene(ArtifactScene::Step);
    if (!run(out, step, "step") || !ringing(a.ring, out, step, err, nthreads))
        return false;
    // Lights moved along the diagonal in steps of 1/4 texel (whole output pixels).
    const int step_px = std::max(1, k / 4);
    std::vector<OIIO::ImageBuf> frames;
    std::vector<std::array<int, 2>> shifts;
    for (int s = 0; s < k; s += step_px) {
        frames.emplace_back();
        if (!run(frames.back(), artifact_scene(ArtifactScene::Lights, k, double(s) / k), "lights"))
            return false;
        shifts.push_back({ s, s });
    }
    if (frames.size() < 2) {
        a.shimmer = 0.0;  // factor 1: nothing moves between output pixels
    } else if (!shimmer(a.shimmer, frames, shifts, err, shrunk(frames[0].roi(), 3 * k), nthreads)) {
        return false;
    }
    if (!run(out, artifact_scene(ArtifactScene::Pattern), "pattern"))
        return false;
    const OIIO::ImageBuf reference = artifact_scene(ArtifactScene::PatternReference, k);
    return detail_error(a.detail, out, reference, err, shrunk(reference.roi(), 3 * k), nthreads);
}

}  // namespace bokeh
