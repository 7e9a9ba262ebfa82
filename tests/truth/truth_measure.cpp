// truth_measure — time the thin-lens truth on the three LowResLeftView passes merged.
//
//   build/bin/truth_measure [spp = 256] [threads = 2] [depth unit mm = 10] [out.exr]
//
// The files hold Z ~72-990 and no camera data; the lens is a 50 mm f/2 on a 36 mm back
// focused at 200 units; at 10 mm a unit (focus 2 m) the CoC runs from -32 px at the
// nearest sample to +15 px at the farthest, at 5 mm from -66 to +30 (printed). Prints
// the report's line and, beside it, how far the flat defocus (Auto and Reference) of the
// flattened passes is from the truth; writes the render when a path is given.
#include <cstdio>
#include <cstdlib>
#include <string>

#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/io.h>
#include <bokeh/metrics.h>
#include <bokeh/truth.h>

int main(int argc, char** argv)
{
    const int spp      = argc > 1 ? std::atoi(argv[1]) : 256;
    const int nthreads = argc > 2 ? std::atoi(argv[2]) : 2;
    const double unit  = argc > 3 ? std::atof(argv[3]) : 10.0;
    const std::string dir = BOKEH_SHARED_DATA "/openexr-images/LowResLeftView_";
    std::string err;
    OIIO::ImageBuf b, l, t, merged;
    if (!bokeh::read_image(b, dir + "Balls.exr", err) || !bokeh::read_image(l, dir + "Leaves.exr", err)
        || !bokeh::read_image(t, dir + "Trunks.exr", err)) {
        std::fprintf(stderr, "truth_measure: %s\n", err.c_str());
        return 1;
    }
    if (!bokeh::deep_merge(merged, { &b, &l, &t }, false, {}, nullptr, nthreads)) {
        std::fprintf(stderr, "truth_measure: %s\n", merged.geterror().c_str());
        return 1;
    }
    bokeh::TruthOptions o;
    o.coc.lens.focal_mm        = 50.0;
    o.coc.lens.fstop           = 2.0;
    o.coc.lens.sensor_width_mm = 36.0;
    o.coc.lens.focus_distance  = 200.0;
    o.coc.lens.depth_unit_mm   = unit;
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
    OIIO::ImageBuf flat;
    if (!bokeh::deep_flatten(flat, merged, {}, nullptr, nthreads)) {
        std::fprintf(stderr, "truth_measure: %s\n", flat.geterror().c_str());
        return 1;
    }
    for (bokeh::DefocusMethod m : { bokeh::DefocusMethod::Auto, bokeh::DefocusMethod::Reference }) {
        bokeh::DefocusOptions d;
        d.coc    = o.coc;
        d.method = m;
        OIIO::ImageBuf dof;
        bokeh::ImageError e;
        if (!bokeh::defocus(dof, flat, d, nullptr, nthreads) || !bokeh::compare(e, dof, out, err, {}, nthreads)) {
            std::fprintf(stderr, "truth_measure: %s%s\n", dof.geterror().c_str(), err.c_str());
            return 1;
        }
        std::printf("flat defocus (%s) of the flattened passes against the truth: %.2f dB, RMSE %.4f\n",
                    bokeh::method_name(m), e.psnr_db, e.rmse_linear);
    }
    if (argc > 4 && !out.write(argv[4])) {
        std::fprintf(stderr, "truth_measure: %s\n", out.geterror().c_str());
        return 1;
    }
    return 0;
}
