// defocus_gather.cpp — the gather of hikita12312's blog post "Implementing depth of field"
// (2017), as published: a depth defocus from a few blurred copies of the frame instead of
// layers (docs/methods/defocus.md, "Gather").
//
// Blurred copies of the image at a few representative CoCs (4 behind focus, 3 in front;
// those of 16 px and more in 1/2 and 1/4 buffers), a per-pixel smoothstep blend between
// the two levels around the pixel's CoC, a back-bokeh mask taken from the previous level
// (texels in front of it are dropped from the weight), and a front-edge blur inside a
// Sobel of the front CoC with taps 5 px apart. The levels are blurred with the aperture
// the layers use (aperture_weights, defocus_layers.h), so the two methods compare on the
// same bokeh. Known and kept limits (the method's own): in-focus colour bleeds into the
// first back level, front silhouettes stay partly hard, nothing spreads past the data
// window. Flat frames only; bokeh::defocus (core/defocus/defocus.cpp) calls it for method=gather.

#include "defocus/defocus_layers.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace bokeh {

using namespace detail;

namespace {

float smoothstep(float t)
{
    t = std::clamp(t, 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

// A blurred level: RGBA of the pixels `mask` accepts, blurred with CoC `c` at reduction
// s and normalised by the blurred mask (the post's back-bokeh mask: masked texels are
// dropped from the weight), over the output region.
struct Level {
    float coc_px = 0.0f;
    int s        = 1;
    OIIO::ROI low;
    Plane p;
};

template<class Mask>
Level blurred_level(const Frame& f, const DefocusOptions& o, float c, Mask mask, int nthreads)
{
    Level l;
    l.coc_px = c;
    l.s      = std::abs(c) >= 32.0f ? 4 : std::abs(c) >= 16.0f ? 2 : 1;  // "1/2 down to 1/4"
    const KernelWeights w = aperture_weights(o, c, l.s, nthreads);
    const int gx = f.out.xbegin, gy = f.out.ybegin, s = l.s;
    l.low = OIIO::ROI(-1, floor_div(f.out.width() - 1, s) + 2, -1, floor_div(f.out.height() - 1, s) + 2);
    Plane p = reduce_region(grown(l.low, w.rx, w.ry), gx, gy, s, 5, nthreads,
                            [&](int x, int y, float* v) {
                                const int64_t i = f.source(x, y);
                                if (i < 0 || !mask(f.coc[size_t(i)]))
                                    return;
                                const float* px = f.img.rgba.data() + size_t(i) * 4;
                                for (int c4 = 0; c4 < 4; ++c4)
                                    v[c4] += px[c4];
                                v[4] += 1.0f;
                            });
    l.p = w.is_identity() ? std::move(p) : convolve_spans(p, w, nthreads);
    divide_by_visibility(l.p);  // here: by the blurred mask
    return l;
}

// Representative CoCs for n levels up to `extreme` (> 0), geometric from extreme / 2^(n-1).
std::vector<float> level_cocs(float extreme, int n)
{
    std::vector<float> c;
    for (int i = n - 1; i >= 0; --i)
        c.push_back(extreme / float(1 << i));
    return c;
}

}  // namespace

void detail::gather(Plane& out, const Frame& f, const DefocusOptions& o, float lo, float hi, int nthreads)
{
    const int gx = f.out.xbegin, gy = f.out.ybegin;
    // Level 0 is the sharp image; back levels mask texels in front of the previous level.
    std::vector<Level> back, front;
    if (hi > 1.0f) {
        float previous = 0.0f;
        for (float c : level_cocs(hi, 4)) {
            const float keep_from = previous;
            back.push_back(blurred_level(f, o, c, [keep_from](float t) { return t >= keep_from; }, nthreads));
            previous = c;
        }
    }
    if (lo < -1.0f)
        for (float c : level_cocs(-lo, 3))
            front.push_back(blurred_level(f, o, -c, [](float) { return true; }, nthreads));

    auto read_level = [&](const Level& l, int x, int y, float v[4]) {
        sample(l.p, l.low, gx, gy, l.s, x, y, v);
    };
    // The CoC standing for output pixel (x, y); 0 where the border leaves it empty.
    auto coc_at = [&](int x, int y) {
        const int64_t i = f.source(x, y);
        return i < 0 ? 0.0f : f.coc[size_t(i)];
    };
    auto blend = [&](int x, int y, float c, float v[4]) {
        const std::vector<Level>& levels = c >= 0.0f ? back : front;
        const float a = std::abs(c);
        // Between level j (CoC cj, level -1 = sharp) and j + 1.
        float c_lo    = 0.0f;
        float lo_v[4] = { 0, 0, 0, 0 };
        const int64_t i = f.source(x, y);
        if (i >= 0)
            std::copy_n(f.img.rgba.data() + size_t(i) * 4, 4, lo_v);
        for (const Level& l : levels) {
            const float cl = std::abs(l.coc_px);
            float hi_v[4];
            read_level(l, x, y, hi_v);
            if (a <= cl) {
                const float t = smoothstep((a - c_lo) / (cl - c_lo));
                for (int k = 0; k < 4; ++k)
                    v[k] = lo_v[k] + (hi_v[k] - lo_v[k]) * t;
                return;
            }
            c_lo = cl;
            std::copy_n(hi_v, 4, lo_v);
        }
        std::copy_n(lo_v, 4, v);
    };
    parallel_for_chunks(f.out.ybegin, f.out.yend, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = f.out.xbegin; x < f.out.xend; ++x)
                blend(x, y, coc_at(x, y), out.row(y - gy) + size_t(x - gx) * 4);
    });
    if (front.empty())
        return;

    // Front-edge blur: a Sobel of the front CoC with taps 5 px apart finds where a blurred
    // foreground meets what is behind it; there the result is blurred again, by the front
    // CoC found nearby, so the foreground's silhouette softens over the background.
    constexpr int kTap = 5;
    // The front CoC over the output grown by the taps' reach, read directly below.
    const OIIO::ROI fr = grown(f.out, kTap, kTap);
    std::vector<float> fcoc(size_t(fr.width()) * size_t(fr.height()));
    parallel_for_chunks(fr.ybegin, fr.yend, 16, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = fr.xbegin; x < fr.xend; ++x)
                fcoc[size_t(y - fr.ybegin) * size_t(fr.width()) + size_t(x - fr.xbegin)]
                    = std::max(0.0f, -coc_at(x, y));
    });
    auto front_coc = [&](int x, int y) {
        return fcoc[size_t(y - fr.ybegin) * size_t(fr.width()) + size_t(x - fr.xbegin)];
    };
    Frame pass;  // the gathered result as the source of the edge blur
    pass.data    = f.out;
    pass.out     = f.out;
    pass.border  = f.border;
    pass.img.roi = f.out;
    pass.img.rgba.assign(out.px.get(), out.px.get() + out.size());
    pass.coc.assign(size_t(f.out.width()) * size_t(f.out.height()), 0.0f);
    std::vector<Level> soft;
    for (const Level& l : front)
        soft.push_back(blurred_level(pass, o, l.coc_px, [](float) { return true; }, nthreads));
    parallel_for_chunks(f.out.ybegin, f.out.yend, 8, nthreads, [&](int64_t y0, int64_t y1) {
        for (int y = int(y0); y < int(y1); ++y)
            for (int x = f.out.xbegin; x < f.out.xend; ++x) {
                const float gxs = front_coc(x + kTap, y - kTap) + 2.0f * front_coc(x + kTap, y)
                                  + front_coc(x + kTap, y + kTap) - front_coc(x - kTap, y - kTap)
                                  - 2.0f * front_coc(x - kTap, y) - front_coc(x - kTap, y + kTap);
                const float gys = front_coc(x - kTap, y + kTap) + 2.0f * front_coc(x, y + kTap)
                                  + front_coc(x + kTap, y + kTap) - front_coc(x - kTap, y - kTap)
                                  - 2.0f * front_coc(x, y - kTap) - front_coc(x + kTap, y - kTap);
                // |gradient| / 8 is the CoC step across the edge; a 2 px step is a full edge.
                const float mask = std::min(1.0f, std::hypot(gxs, gys) / 16.0f);
                if (mask <= 0.0f)
                    continue;
                float near = 0.0f;
                for (int dy = -kTap; dy <= kTap; dy += kTap)
                    for (int dx = -kTap; dx <= kTap; dx += kTap)
                        near = std::max(near, front_coc(x + dx, y + dy));
                float v[4];
                const Level* pick = &soft.back();
                for (const Level& l : soft)
                    if (std::abs(l.coc_px) >= near) {
                        pick = &l;
                        break;
                    }
                read_level(*pick, x, y, v);
                float* d = out.row(y - gy) + size_t(x - gx) * 4;
                for (int k = 0; k < 4; ++k)
                    d[k] += (v[k] - d[k]) * mask;
            }
    });
}

}  // namespace bokeh
