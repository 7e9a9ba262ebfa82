// lens_task.cpp — bokeh-bench's lens task. Each built-in scene with the lens its metadata
// suggests, defocused by the default method plain and with lens character (an achromat
// with rim diffraction; highlights above luminance 1 become sprites): the median times
// and their ratio, the sprite count, and the PSNR of each against the brute-force scatter
// reference (every pixel scattered with its own PSF: bokeh::defocus_scatter_reference),
// which is run only when the frame has at most 640 x 360 pixels (it is slow by design).

#include "lens_task.h"
#include "bench_common.h"
#include "timing.h"

#include <bokeh/defocus.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>

#include <algorithm>
#include <cstdio>

#include <OpenImageIO/strutil.h>

using OIIO::Strutil::fmt::format;

namespace bokeh_bench {

bool run_lens_task(const BenchArgs& a, std::vector<std::string>& rows)
{
    std::printf("\n%-10s %-24s %10s %10s %7s %8s %12s %12s\n", "scene", "lens", "plain ms", "lens ms", "ratio",
                "sprites", "plain dB", "lens dB");
    for (const std::string& name : bokeh::scene_names()) {
        if (!a.only.empty() && std::find(a.only.begin(), a.only.end(), name) == a.only.end())
            continue;
        bokeh::SceneOptions so;
        so.width  = a.width;
        so.height = a.height;
        OIIO::ImageBuf img;
        if (!bokeh::make_scene(img, name, so, a.threads)) {
            std::fprintf(stderr, "bokeh-bench: scene %s: %s\n", name.c_str(), img.geterror().c_str());
            return false;
        }
        bokeh::DefocusOptions plain;
        plain.coc.lens.focal_mm        = img.spec().get_float_attribute("bokeh:focal_mm", 50.0f);
        plain.coc.lens.sensor_width_mm = img.spec().get_float_attribute("bokeh:sensor_width_mm", 36.0f);
        plain.coc.lens.focus_distance  = img.spec().get_float_attribute("bokeh:focus_m", 5.0f);
        plain.coc.lens.fstop           = img.spec().get_float_attribute("bokeh:fstop", 2.8f);
        bokeh::DefocusOptions lens = plain;
        lens.lens_character        = true;
        lens.lens.preset           = bokeh::LensPreset::Achromat;
        lens.lens.diffraction      = bokeh::DiffractionModel::EdgeLaw;
        OIIO::ImageBuf out_plain, out_lens;
        bokeh::DefocusReport rep;
        if (!bokeh::defocus(out_lens, img, lens, &rep, a.threads)) {
            std::fprintf(stderr, "bokeh-bench: %s: %s\n", name.c_str(), out_lens.geterror().c_str());
            return false;
        }
        const double plain_ms = median_ms([&] { bokeh::defocus(out_plain, img, plain, nullptr, a.threads); }, a.reps);
        const double lens_ms  = median_ms([&] { bokeh::defocus(out_lens, img, lens, nullptr, a.threads); }, a.reps);
        std::string plain_db = "-", lens_db = "-";
        if (int64_t(a.width) * a.height <= 640 * 360) {
            OIIO::ImageBuf ref;
            if (!bokeh::defocus_scatter_reference(ref, img, lens, a.threads)) {
                std::fprintf(stderr, "bokeh-bench: %s: %s\n", name.c_str(), ref.geterror().c_str());
                return false;
            }
            bokeh::ImageError ep, el;
            std::string err;
            bokeh::compare(ep, out_plain, ref, err, {}, a.threads);
            bokeh::compare(el, out_lens, ref, err, {}, a.threads);
            plain_db = format("{:.1f}", ep.psnr_db);
            lens_db  = format("{:.1f}", el.psnr_db);
            rows.push_back(format("lens {},achromat sprites vs scatter reference,,{},{},{:.3f},{},{}", name,
                                  a.width, a.threads, lens_ms, a.reps, error_fields(el)));
        }
        std::printf("%-10s %-24s %10.1f %10.1f %7.2f %8lld %12s %12s\n", name.c_str(), "achromat, diffraction",
                    plain_ms, lens_ms, lens_ms / plain_ms, static_cast<long long>(rep.sprites), plain_db.c_str(),
                    lens_db.c_str());
        std::fflush(stdout);
    }
    return true;
}

}  // namespace bokeh_bench
