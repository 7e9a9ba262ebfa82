// blur_taps.cpp — the bilinear-tap disk of Kawase's "Anti reduced-buffer artifacts"
// (BlurMethod::BilinearTaps): the 9x9 disk from 25 bilinear fetches and the 17x17 one from
// 81 (77: the four corner fetches cover none of the disk and are left out).
//
// The taps are grouped 2 (or 1, the centre) per axis; a fetch sits at the area-weighted
// centroid of its group, weighted by the group's disk area, so its bilinear footprint
// matches the group's marginals but not its joint weights. On a GPU the fetches are free;
// on a CPU we convolve with the kernel they add up to (by row spans, blur.cpp).
// Limits: the talk's two sizes only; the joint weights differ from the disk's, which is
// the method's error (tests/blur/blur_approx_test.cpp measures it).

#include <bokeh/blur.h>

#include <algorithm>
#include <utility>
#include <vector>

namespace bokeh {

KernelWeights bilinear_tap_weights(const Kernel& k, int* fetches)
{
    const KernelWeights exact = kernel_weights(k);
    // Pixels grouped per axis: the centre alone, then pairs outward.
    auto groups = [](int r) {
        std::vector<std::pair<int, int>> g;  // [first, last]
        for (int a = -r; a < 0; a += 2)
            g.push_back({ a, std::min(a + 1, -1) });
        g.push_back({ 0, 0 });
        for (int a = 1; a <= r; a += 2)
            g.push_back({ a, std::min(a + 1, r) });
        return g;
    };
    const auto gx = groups(exact.rx), gy = groups(exact.ry);
    KernelWeights out{ exact.rx, exact.ry, std::vector<double>(exact.w.size(), 0.0) };
    const int nx = 2 * exact.rx + 1;
    int count    = 0;
    for (const auto& [y0, y1] : gy)
        for (const auto& [x0, x1] : gx) {
            double total = 0.0, sx = 0.0, sy = 0.0;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    total += exact.at(x, y);
                    sx += (x - x0) * exact.at(x, y);
                    sy += (y - y0) * exact.at(x, y);
                }
            if (total <= 0.0)
                continue;
            ++count;
            // One fetch at the centroid: bilinear weights (1 - f, f) on each axis.
            const double fx = sx / total, fy = sy / total;
            for (int y = y0; y <= y1; ++y)
                for (int x = x0; x <= x1; ++x) {
                    const double wx = x == x0 ? 1.0 - fx : fx, wy = y == y0 ? 1.0 - fy : fy;
                    out.w[size_t((y + exact.ry) * nx + (x + exact.rx))] += total * wx * wy;
                }
        }
    if (fetches)
        *fetches = count;
    return out;
}

}  // namespace bokeh
