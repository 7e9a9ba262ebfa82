// iris_task.cpp — bokeh-bench's iris task: each approximation in iris mode (the iris
// filter's log(mean(exp(k x))) / k) against the exact iris blur of its own shape, as |k| times the
// channels' range grows towards its limit (30, kIrisMaxExponent). Accuracy only: the timing
// of iris mode is the exact path's plus two passes over the plane.
//
// Scene: the blur task's crop of the "lights" frame (240x135 RGBA: lights, floor, the
// sphere's edge, main.cpp), black border; PSNR after x / (1 + x) (bokeh::compare), as the blur task.
// What it showed (docs/benchmarks.md): exp(k x) magnifies every weight an approximation
// misplaces next to a highlight, so none keeps 40 dB from |k| x range 5 on; method=fast is
// the exact method in iris mode for that reason.

#include "iris_task.h"
#include "bench_common.h"

#include <bokeh/blur.h>
#include <bokeh/metrics.h>

#include <algorithm>
#include <cstdio>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh_bench {

using OIIO::Strutil::fmt::format;

bool run_iris_task(const OIIO::ImageBuf& crop, int threads, std::vector<std::string>& rows)
{
    namespace IBA = OIIO::ImageBufAlgo;
    // The exponent's span is |k| times the widest colour channel's range (black outside
    // counts as 0).
    const auto stats = IBA::computePixelStats(crop);
    double range     = 0.0;
    for (int c = 0; c < 3; ++c)
        range = std::max(range, double(stats.max[size_t(c)]) - std::min(0.0, double(stats.min[size_t(c)])));
    struct Method {
        const char* name;
        bokeh::KernelShape shape;
        bokeh::BlurMethod method;
        int bands;
    };
    using S = bokeh::KernelShape;
    using M = bokeh::BlurMethod;
    const Method methods[] = { { "disk, 6 bands", S::Disk, M::Bands, 6 },
                               { "disk, 8 bands", S::Disk, M::Bands, 8 },
                               { "hexagon, 3 parallelograms", S::Polygon, M::Parallelograms, 0 },
                               { "gaussian, 3 boxes", S::Gaussian, M::ThreeBoxes, 0 } };
    std::printf("iris mode against the exact iris blur (crop range 0 .. %.1f): PSNR dB\n", range);
    std::printf("%-10s %-28s %6s %10s\n", "|k|xrange", "method", "size", "psnr_db");
    for (double span : { 2.0, 5.0, 10.0, 20.0, 29.0 })
        for (const Method& m : methods)
            for (double size : { 15.0, 63.0 }) {
                bokeh::Kernel k;
                k.shape    = m.shape;
                k.blades   = 6;
                k.width_px = k.height_px = float(size);
                bokeh::BlurOptions o;
                o.method = m.method;
                o.iris   = float(span / range);
                if (m.bands > 0)
                    o.bands = m.bands;
                bokeh::BlurOptions exact = o;
                exact.method             = M::Exact;
                OIIO::ImageBuf got, want;
                if (!bokeh::blur(got, crop, k, o, {}, threads)
                    || !bokeh::blur(want, crop, k, exact, {}, threads)) {
                    std::fprintf(stderr, "bokeh-bench: iris: %s%s\n", got.geterror().c_str(),
                                 want.geterror().c_str());
                    return false;
                }
                bokeh::ImageError e;
                std::string err;
                if (!bokeh::compare(e, got, want, err, {}, threads)) {
                    std::fprintf(stderr, "bokeh-bench: iris: %s\n", err.c_str());
                    return false;
                }
                std::printf("%-10g %-28s %6.0f %10.1f\n", span, m.name, size, e.psnr_db);
                std::fflush(stdout);
                rows.push_back(format("iris |k|xrange {:g},{},,{},{},,,{}", span,
                                      OIIO::Strutil::replace(m.name, ",", ""), size, threads,
                                      error_fields(e)));
            }
    return true;
}

}  // namespace bokeh_bench
