// lens_task.cpp — bokeh-bench's lens task. Each built-in scene with the lens its metadata
// suggests, defocused by the default method plain and with lens character (an achromat
// with rim diffraction; highlights above luminance 1 become sprites): the median times
// and their ratio, lens character both cold (the process's PSF caches dropped before each
// run: a single frame) and warm (the PSFs kept from the run before: the frames of a
// sequence after the first), the sprite count, and the PSNR of each against the brute-force scatter
// reference (every pixel scattered with its own PSF: bokeh::defocus_scatter_reference),
// which is run only when the frame has at most 640 x 360 pixels (it is slow by design);
// and the lens character at pseudo-high resolution (supersample 2: a frame of twice the
// width and height, the sprites drawn at it) against the plain default's time.

#include "lens_task.h"
#include "bench_common.h"
#include "timing.h"

#include <bokeh/defocus.h>
#include <bokeh/metrics.h>
#include <bokeh/optics.h>
#include <bokeh/scene.h>

#include <algorithm>
#include <cstdio>

#include <OpenImageIO/strutil.h>
#include <OpenImageIO/timer.h>

using OIIO::Strutil::fmt::format;

namespace bokeh_bench {

namespace {

// Where the hybrid's error against the scatter reference comes from, each variant's PSNR
// against the reference of its own lens (printed and as CSV rows "gap: ..."):
//   plain default, lens off      the layers against the scatter with the plain aperture:
//                                the model's floor (visibility division, disocclusion fill,
//                                ladder, reductions), no lens character anywhere;
//   plain exact layers, lens off as above with one full-resolution layer per CoC step: the
//                                model alone, without the ladder and reductions;
//   hybrid, exact layers         lens character with one layer per CoC step;
//   every pixel a sprite         highlights threshold 1e-6 and no cap: each pixel carries
//                                the lens (the dim ones too), drawn in its layer.
bool explain_gap(const BenchArgs& a, const std::string& name, const OIIO::ImageBuf& img,
                 const bokeh::DefocusOptions& plain, const bokeh::DefocusOptions& lens,
                 const OIIO::ImageBuf& lens_ref, std::vector<std::string>& rows)
{
    bokeh::DefocusOptions off = plain;
    OIIO::ImageBuf off_ref;
    if (!bokeh::defocus_scatter_reference(off_ref, img, off, a.threads)) {
        std::fprintf(stderr, "bokeh-bench: %s: %s\n", name.c_str(), off_ref.geterror().c_str());
        return false;
    }
    struct Variant {
        const char* what;
        bokeh::DefocusOptions o;
        const OIIO::ImageBuf* ref;
    };
    std::vector<Variant> variants;
    variants.push_back({ "plain default, lens off", plain, &off_ref });
    variants.push_back({ "plain exact layers, lens off", plain, &off_ref });
    variants.back().o.method = bokeh::DefocusMethod::Reference;
    variants.push_back({ "hybrid, exact layers", lens, &lens_ref });
    variants.back().o.method = bokeh::DefocusMethod::Reference;
    variants.push_back({ "every pixel a sprite", lens, &lens_ref });
    variants.back().o.highlight_threshold = 1e-6f;
    variants.back().o.max_sprites         = 10000000;
    // The variants' times in interleaved rounds (timing.h), each timed run right after an
    // untimed one of the same variant, the median of 3 (every pixel a sprite takes seconds).
    // Each run leaves its pixels and report in the variant's slot (the same every run).
    std::vector<OIIO::ImageBuf> outs(variants.size());
    std::vector<bokeh::DefocusReport> reports(variants.size());
    std::vector<char> drawn(variants.size(), 1);
    std::vector<std::function<void()>> fns;
    for (size_t i = 0; i < variants.size(); ++i)
        fns.push_back([&, i] { drawn[i] = bokeh::defocus(outs[i], img, variants[i].o, &reports[i], a.threads); });
    const int n = std::min(a.reps, 3);
    const std::vector<double> times = interleaved_medians_ms(fns, std::vector<int>(fns.size(), n),
                                                             std::vector<bool>(fns.size(), true));
    for (size_t i = 0; i < variants.size(); ++i) {
        const Variant& v                = variants[i];
        const OIIO::ImageBuf& out       = outs[i];
        const bokeh::DefocusReport& rep = reports[i];
        if (!drawn[i]) {
            std::fprintf(stderr, "bokeh-bench: %s: %s\n", name.c_str(), out.geterror().c_str());
            return false;
        }
        const double ms = times[i];
        bokeh::ImageError e;
        std::string err;
        bokeh::compare(e, out, *v.ref, err, {}, a.threads);
        std::printf("%-10s   gap: %-30s %8.1f dB (%lld sprites, %.0f ms)\n", name.c_str(), v.what, e.psnr_db,
                    static_cast<long long>(rep.sprites), ms);
        rows.push_back(format("lens {},\"gap: {}\",,{},{},{:.3f},{},{}", name, v.what, a.width, a.threads, ms, n,
                              error_fields(e)));
    }
    std::fflush(stdout);
    return true;
}

}  // namespace

bool run_lens_task(const BenchArgs& a, std::vector<std::string>& rows)
{
    std::printf("\n%-10s %-24s %10s %10s %7s %10s %7s %10s %7s %8s %12s %12s\n", "scene", "lens", "plain ms",
                "lens ms", "ratio", "warm ms", "ratio", "ss2 ms", "ratio", "sprites", "plain dB", "lens dB");
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
        bokeh::DefocusOptions fine = lens;
        fine.supersample           = 2;
        OIIO::ImageBuf out_fine;
        // The four timed together in interleaved rounds (timing.h), each timed run right after
        // an untimed one of the same case (the cold ones clear the PSF caches in both, so the
        // warm one's warm-up refills them).
        const std::vector<double> times = interleaved_medians_ms(
            { [&] { bokeh::defocus(out_plain, img, plain, nullptr, a.threads); },
              [&] {
                  bokeh::clear_shared_psf_caches();
                  bokeh::defocus(out_lens, img, lens, nullptr, a.threads);
              },
              [&] { bokeh::defocus(out_lens, img, lens, nullptr, a.threads); },
              [&] {
                  bokeh::clear_shared_psf_caches();
                  bokeh::defocus(out_fine, img, fine, nullptr, a.threads);
              } },
            std::vector<int>(4, a.reps), std::vector<bool>(4, true));
        const double plain_ms = times[0], lens_ms = times[1], warm_ms = times[2], fine_ms = times[3];
        const std::string no_error = ",,";
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
            if (!explain_gap(a, name, img, plain, lens, ref, rows))
                return false;
            rows.push_back(format("lens {},plain default vs scatter reference,,{},{},{:.3f},{},{}", name, a.width,
                                  a.threads, plain_ms, a.reps, error_fields(ep)));
            rows.push_back(format("lens {},achromat sprites vs scatter reference,,{},{},{:.3f},{},{}", name,
                                  a.width, a.threads, lens_ms, a.reps, error_fields(el)));
        } else {
            rows.push_back(format("lens {},plain default,,{},{},{:.3f},{},{}", name, a.width, a.threads, plain_ms,
                                  a.reps, no_error));
            rows.push_back(format("lens {},achromat sprites ({} sprites),,{},{},{:.3f},{},{}", name, rep.sprites,
                                  a.width, a.threads, lens_ms, a.reps, no_error));
        }
        rows.push_back(format("lens {},achromat sprites warm,,{},{},{:.3f},{},{}", name, a.width, a.threads,
                              warm_ms, a.reps, no_error));
        rows.push_back(format("lens {},achromat sprites supersample 2,,{},{},{:.3f},{},{}", name, a.width,
                              a.threads, fine_ms, a.reps, no_error));
        std::printf("%-10s %-24s %10.1f %10.1f %7.2f %10.1f %7.2f %10.1f %7.2f %8lld %12s %12s\n", name.c_str(),
                    "achromat, diffraction", plain_ms, lens_ms, lens_ms / plain_ms, warm_ms, warm_ms / plain_ms,
                    fine_ms, fine_ms / plain_ms, static_cast<long long>(rep.sprites), plain_db.c_str(),
                    lens_db.c_str());
        std::fflush(stdout);
    }
    return true;
}

}  // namespace bokeh_bench
