// truth_measure — time the thin-lens truth on the three LowResLeftView passes merged.
//
//   build/tests/truth_measure [spp] [threads] [out.exr]
//
// The files hold Z ~72-990 and no camera data; the lens is a 50 mm f/2 on a 36 mm back
// focused at 200 units of 10 mm (2 m): CoC -43 px at the nearest sample, +13 px at the
// farthest (printed). Prints the report's line; writes the render when a path is given.
#include <cstdio>
#include <cstdlib>
#include <string>

#include <bokeh/deep.h>
#include <bokeh/io.h>
#include <bokeh/truth.h>

int main(int argc, char** argv)
{
    const int spp      = argc > 1 ? std::atoi(argv[1]) : 256;
    const int nthreads = argc > 2 ? std::atoi(argv[2]) : 2;
    const std::string dir = BOKEH_SHARED_DATA "/openexr-images/LowResLeftView_";
    std::string err;
    OIIO::ImageBuf b, l, t, merged;
    if (!bokeh::read_image(b, dir + "Balls.exr", err) || !bokeh::read_image(l, dir + "Leaves.exr", err)
        || !bokeh::read_image(t, dir + "Trunks.exr", err)) {
        std::fprintf(stderr, "truth_measure: %s\n", err.c_str());
        return 1;
    }
    if (!bokeh::deep_merge(merged, { &b, &l, &t }, false, {}, nthreads)) {
        std::fprintf(stderr, "truth_measure: %s\n", merged.geterror().c_str());
        return 1;
    }
    bokeh::TruthOptions o;
    o.coc.lens.focal_mm        = 50.0;
    o.coc.lens.fstop           = 2.0;
    o.coc.lens.sensor_width_mm = 36.0;
    o.coc.lens.focus_distance  = 200.0;
    o.coc.lens.depth_unit_mm   = 10.0;
    o.spp                      = spp;
    o.progress = [](float f) { std::fprintf(stderr, "\r%3d%%", int(f * 100.0f)); };
    OIIO::ImageBuf out;
    bokeh::TruthReport rep;
    if (!bokeh::defocus_truth(out, merged, o, &rep, nthreads)) {
        std::fprintf(stderr, "truth_measure: %s\n", out.geterror().c_str());
        return 1;
    }
    std::fprintf(stderr, "\n");
    std::printf("%s\n", rep.summary.c_str());
    std::printf("rays %lld, cells %lld, %.1f ns a ray (x %d threads)\n", (long long)rep.rays,
                (long long)rep.cells_visited, rep.seconds * 1e9 / double(rep.rays) * nthreads, nthreads);
    if (argc > 3 && !out.write(argv[3])) {
        std::fprintf(stderr, "truth_measure: %s\n", out.geterror().c_str());
        return 1;
    }
    return 0;
}
