// blur_fixtures.cpp — the images, kernels and method lists the blur tests share.
#include "blur_fixtures.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>

using namespace bokeh;

namespace blur_test {

// Deterministic texture in 4 channels with a few very bright pixels.
OIIO::ImageBuf test_image(int w, int h, int x0, int y0, bool bright)
{
    OIIO::ImageSpec spec(w, h, 4, OIIO::TypeFloat);
    spec.x = x0;
    spec.y = y0;
    OIIO::ImageBuf img(spec);
    for (int y = y0; y < y0 + h; ++y)
        for (int x = x0; x < x0 + w; ++x) {
            const int i = (x - x0) + 7 * (y - y0);
            float px[4] = { 0.5f + 0.5f * std::sin(0.37f * i), float((i * 7919) % 101) / 100.0f,
                            (x - x0) % 9 == 0 ? 4.0f : 0.1f, 1.0f };
            if (bright && (x - x0) * 13 % w == 5 && (y - y0) * 17 % h == 3)
                px[0] = px[1] = px[2] = 500.0f;
            img.setpixel(x, y, px);
        }
    return img;
}

Kernel hexagon(float w, float h, float rotation)
{
    Kernel k;
    k.shape        = KernelShape::Polygon;
    k.blades       = 6;
    k.width_px     = w;
    k.height_px    = h;
    k.rotation_deg = rotation;
    return k;
}

std::vector<Named> kernels()
{
    std::vector<Named> list;
    auto add = [&](const char* name, KernelShape s, float w, float h) {
        Kernel k;
        k.shape     = s;
        k.width_px  = w;
        k.height_px = h;
        list.push_back({ name, k });
        return &list.back().k;
    };
    add("box 7x7", KernelShape::Box, 7, 7);
    add("box 6.5x4.2", KernelShape::Box, 6.5f, 4.2f);
    add("box 8x1", KernelShape::Box, 8, 1);
    add("gaussian 9x9", KernelShape::Gaussian, 9, 9);
    add("gaussian sigma 1.3", KernelShape::Gaussian, 0, 0)->sigma_px = 1.3f;
    add("box hard 8x5.5 (oiiotool's: 9 x 5 taps)", KernelShape::Box, 8, 5.5f)->edge = KernelEdge::Hard;
    add("gaussian hard 7.5x11 (oiiotool's, cut at the footprint)", KernelShape::Gaussian, 7.5f, 11)->edge =
        KernelEdge::Hard;
    add("disk 15", KernelShape::Disk, 15, 15);
    add("disk 9 (the seed's bilinear taps too)", KernelShape::Disk, 9, 9);
    add("disk 17 (the seed's 17x17 bilinear taps too)", KernelShape::Disk, 17, 17);
    add("disk 10.5", KernelShape::Disk, 10.5f, 10.5f);
    add("disk 21x9", KernelShape::Disk, 21, 9);
    add("disk 61x7 (15 spans in its top row)", KernelShape::Disk, 61, 7);
    add("disk hard 12", KernelShape::Disk, 12, 12)->edge = KernelEdge::Hard;
    add("hexagon 17", KernelShape::Polygon, 17, 17);
    Kernel* p = add("pentagon 19 rotated curved", KernelShape::Polygon, 19, 19);
    p->blades = 5, p->rotation_deg = 17, p->curvature = 0.4f;
    add("catadioptric 23", KernelShape::Disk, 23, 23)->hole = 0.45f;
    add("hexagon 21 at 7 degrees", KernelShape::Polygon, 21, 21)->rotation_deg = 7;
    add("hexagon 25x11 at 20 degrees", KernelShape::Polygon, 25, 11)->rotation_deg = 20;
    p = add("heptagon 17x23 curved 1 (a disk)", KernelShape::Polygon, 17, 23);
    p->blades = 7, p->curvature = 1.0f;
    p = add("octagon 21 with a hole", KernelShape::Polygon, 21, 21);
    p->blades = 8, p->hole = 0.3f, p->rotation_deg = 11;
    // OIIO's filters (oiiotool's other --blur kernels): negative lobes, a fractional size,
    // one that is not separable.
    add("OIIO lanczos3 7x7 (negative lobes)", KernelShape::Filter, 7, 7)->filter = "lanczos3";
    add("OIIO triangle 6.5x9", KernelShape::Filter, 6.5f, 9)->filter = "triangle";
    add("OIIO radial-lanczos3 9x9 (not separable)", KernelShape::Filter, 9, 9)->filter = "radial-lanczos3";
    return list;
}

// The ways to compute `k` exactly: the automatic choice, and each exact method by name
// (disk, polygon: row spans and FFT tiles; Gaussian: FFT tiles).
std::vector<BlurMethod> exact_methods(const Kernel& k)
{
    if (k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon)
        return { BlurMethod::Auto, BlurMethod::Spans, BlurMethod::Fft };
    if (k.shape == KernelShape::Gaussian)
        return { BlurMethod::Auto, BlurMethod::Fft };
    if (k.shape == KernelShape::Filter && is_separable(k))
        return { BlurMethod::Auto, BlurMethod::Separable, BlurMethod::Fft };
    if (k.shape == KernelShape::Filter)
        return { BlurMethod::Auto, BlurMethod::Fft };
    return { BlurMethod::Auto };
}

// The approximations that apply to `k` (each against its own effective kernel elsewhere):
// the bands, the parallelograms, the three boxes, Kawase's bilinear taps, and fast.
std::vector<BlurMethod> approximations(const Kernel& k)
{
    std::vector<BlurMethod> m{ BlurMethod::Fast };
    const bool shape = k.shape == KernelShape::Disk || k.shape == KernelShape::Polygon;
    if (shape && k.hole == 0.0f)
        m.push_back(BlurMethod::Bands);
    if (k.shape == KernelShape::Polygon && k.blades == 6 && k.curvature == 0.0f && k.hole == 0.0f)
        m.push_back(BlurMethod::Parallelograms);
    if (k.shape == KernelShape::Gaussian && k.edge == KernelEdge::Antialiased)
        m.push_back(BlurMethod::ThreeBoxes);
    if (k.shape == KernelShape::Disk && k.edge == KernelEdge::Antialiased && k.hole == 0.0f
        && k.width_px == k.height_px && (k.width_px == 9.0f || k.width_px == 17.0f))
        m.push_back(BlurMethod::BilinearTaps);
    return m;
}

std::vector<BlurMethod> every_method(const Kernel& k)
{
    std::vector<BlurMethod> m = exact_methods(k), a = approximations(k);
    m.insert(m.end(), a.begin(), a.end());
    return m;
}

std::string method_name(BlurMethod m)
{
    return m == BlurMethod::Spans          ? " (spans)"
           : m == BlurMethod::Fft          ? " (fft)"
           : m == BlurMethod::Fast         ? " (fast)"
           : m == BlurMethod::Bands        ? " (bands)"
           : m == BlurMethod::Parallelograms ? " (parallelograms)"
           : m == BlurMethod::ThreeBoxes   ? " (three boxes)"
           : m == BlurMethod::BilinearTaps ? " (taps)"
           : m == BlurMethod::Separable    ? " (separable)"
                                           : "";
}

double peak(const OIIO::ImageBuf& img)
{
    const auto st = OIIO::ImageBufAlgo::computePixelStats(img);
    double m = 0.0;
    for (float v : st.max)
        m = std::max(m, double(v));
    return m;
}

std::vector<double> channel_sums(const OIIO::ImageBuf& img)
{
    std::vector<double> sums(size_t(img.nchannels()), 0.0);
    for (OIIO::ImageBuf::ConstIterator<float> it(img); !it.done(); ++it)
        for (int c = 0; c < img.nchannels(); ++c)
            sums[size_t(c)] += it[c];
    return sums;
}

// sum |a - b| over the kernel grid of the larger one (the L1 distance of two kernels,
// 0..2; 2 = disjoint).
double kernel_distance(const KernelWeights& a, const KernelWeights& b)
{
    const int rx = std::max(a.rx, b.rx), ry = std::max(a.ry, b.ry);
    auto at = [](const KernelWeights& k, int dx, int dy) {
        return std::abs(dx) <= k.rx && std::abs(dy) <= k.ry ? k.at(dx, dy) : 0.0;
    };
    double d = 0.0;
    for (int dy = -ry; dy <= ry; ++dy)
        for (int dx = -rx; dx <= rx; ++dx)
            d += std::abs(at(a, dx, dy) - at(b, dx, dy));
    return d;
}

}  // namespace blur_test
