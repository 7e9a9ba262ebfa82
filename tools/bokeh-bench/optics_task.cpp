// optics_task.cpp — bokeh-bench's optics task: what lens character costs. A 255 px PSF
// (the yardstick: a large bokeh at 1080p) with each effect alone and with every
// effect on, built cold (lens_psf) and taken warm from a PsfCache; the 9 x 4 contact sheet
// `--bokeh:sheet=1` draws. Interleaved rounds, medians (timing.h).

#include "optics_task.h"
#include "bench_common.h"
#include "timing.h"

#include <bokeh/optics.h>

#include <cstdio>
#include <functional>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

namespace bokeh_bench {

using OIIO::Strutil::fmt::format;

bool run_optics_task(int threads, int reps, std::vector<std::string>& rows)
{
    struct Setup {
        std::string name;
        bokeh::LensCharacter lens;
    };
    std::vector<Setup> setups;
    auto add = [&](std::string name, const std::function<void(bokeh::LensCharacter&)>& set) {
        bokeh::LensCharacter l;
        set(l);
        setups.push_back({ std::move(name), l });
    };
    std::string err;
    add("off", [](bokeh::LensCharacter&) {});
    add("spherical", [](bokeh::LensCharacter& l) {
        l.preset    = bokeh::LensPreset::Achromat;
        l.chromatic = 0.0;
    });
    add("achromat", [](bokeh::LensCharacter& l) { l.preset = bokeh::LensPreset::Achromat; });
    add("achromat+fringes", [](bokeh::LensCharacter& l) {
        l.preset      = bokeh::LensPreset::Achromat;
        l.diffraction = bokeh::DiffractionModel::EdgeLaw;
    });
    add("everything", [&](bokeh::LensCharacter& l) {
        l.preset      = bokeh::LensPreset::Achromat;
        l.diffraction = bokeh::DiffractionModel::EdgeLaw;
        l.onion       = 0.2;
        l.surface_noise = 0.1;
        l.catseye     = 0.6;
        l.astigmatism_px = -20.0;
        bokeh::Kernel k;
        k.shape     = bokeh::KernelShape::Polygon;
        k.blades    = 7;
        k.curvature = 0.3f;
        bokeh::Aperture::from_kernel(k, l.aperture, err);
    });

    std::vector<std::function<void()>> fns;
    std::vector<std::string> labels;
    std::vector<std::shared_ptr<bokeh::PsfCache>> caches;
    bokeh::PsfRequest req;
    req.coc_px  = 255.0;
    req.field_x = 0.6;
    req.field_y = 0.34;
    bool ok = true;
    for (const Setup& s : setups) {
        fns.push_back([&, s] {
            bokeh::Psf p;
            std::string e;
            ok = bokeh::lens_psf(p, s.lens, req, e, threads) && ok;
        });
        labels.push_back("psf cold " + s.name);
        auto cache = std::make_shared<bokeh::PsfCache>(s.lens, threads);
        std::string e;
        if (!cache->get(req, e)) {
            std::fprintf(stderr, "bokeh-bench: optics: %s\n", e.c_str());
            return false;
        }
        caches.push_back(cache);
        fns.push_back([&, cache] {
            std::string e;
            ok = bool(cache->get(req, e)) && ok;
        });
        labels.push_back("psf warm " + s.name);
    }
    const bokeh::LensCharacter sheet_lens = setups.back().lens;
    fns.push_back([&] {
        OIIO::ImageBuf sheet;
        ok = bokeh::bokeh_sheet_image(sheet, sheet_lens, 60.0, 9, 4, 83, threads) && ok;
    });
    labels.push_back("sheet 9x4 everything");

    std::vector<int> r(fns.size(), reps);
    const std::vector<double> ms = interleaved_medians_ms(fns, r, std::vector<bool>(fns.size(), true));
    if (!ok) {
        std::fprintf(stderr, "bokeh-bench: optics: a PSF failed\n");
        return false;
    }
    std::printf("optics: %d threads, 255 px PSF at field (0.6, 0.34), medians of %d\n", threads, reps);
    std::printf("%-28s %12s\n", "case", "median ms");
    for (size_t i = 0; i < fns.size(); ++i) {
        std::printf("%-28s %12.3f\n", labels[i].c_str(), ms[i]);
        rows.push_back(format("optics,{},,{},{},{:.4f},{},,,", labels[i], i + 1 == fns.size() ? 60 : 255, threads,
                              ms[i], reps));
    }
    return true;
}

}  // namespace bokeh_bench
