// defocus_task.cpp — bokeh-bench's defocus task: the layered method at several accuracy
// budgets and the published gather, against the reference (one full-resolution layer per
// CoC value), on the built-in scenes and on the real files in ../shared/data (test images
// kept beside the repository; without them, the built-in scenes only).
//
// Each scene is defocused with the lens its metadata suggests (bokeh:focus_m, bokeh:fstop)
// or, for the files, the lens stated below; times are in-process medians, errors are
// bokeh::compare's (RMSE linear, PSNR after x/(1+x)). With --images it writes the picture
// sheet: previews of each shot, and lens-character columns on lights and giant.

#include "defocus_task.h"
#include "bench_common.h"
#include "timing.h"

#include <bokeh/defocus.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>
#include <functional>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/timer.h>

using OIIO::Strutil::fmt::format;
namespace IBA = OIIO::ImageBufAlgo;

namespace bokeh_bench {

namespace {

// Rays a pixel of the plans' thin-lens truths: two truths of 256 rays agree to 41.9 dB on
// lights at 1920x1080, the PSNR past which neither can tell plans apart.
constexpr int kPlanTruthRays = 256;

struct Shot {
    std::string name;
    OIIO::ImageBuf image;
    bokeh::DefocusOptions base;
};

// Whether --scenes asks for the shot `name` (all when it is empty).
bool wanted(const BenchArgs& a, const std::string& name)
{
    return a.only.empty() || std::find(a.only.begin(), a.only.end(), name) != a.only.end();
}

std::vector<Shot> shots(const BenchArgs& a)
{
    std::vector<Shot> out;
    for (const std::string& name : bokeh::scene_names()) {
        if (!wanted(a, name))
            continue;
        Shot s;
        s.name = name;
        bokeh::SceneOptions so;
        so.width  = a.width;
        so.height = a.height;
        bokeh::make_scene(s.image, name, so, a.threads);
        s.base.coc.lens.focal_mm        = s.image.spec().get_float_attribute("bokeh:focal_mm", 50.0f);
        s.base.coc.lens.sensor_width_mm = s.image.spec().get_float_attribute("bokeh:sensor_width_mm", 36.0f);
        s.base.coc.lens.focus_distance  = s.image.spec().get_float_attribute("bokeh:focus_m", 5.0f);
        s.base.coc.lens.fstop           = s.image.spec().get_float_attribute("bokeh:fstop", 2.8f);
        out.push_back(std::move(s));
    }
    if (a.data_dir.empty())
        return out;
    // Beachball frame 1: Z = 0 outside the ball (no depth, far); Z is 7..11 on the ball,
    // read as metres. Focus on the window centre (Z = 9.0), 100 mm f/1.4 on full frame:
    // the ball's edges reach ~6 px, its silhouette against "no depth" 45 px.
    if (wanted(a, "beachball")) {
        Shot s;
        s.name = "beachball";
        if (s.image.init_spec(a.data_dir + "/openexr-images/Beachball_singlepart.0001.exr", 0, 0)
            && s.image.read(0, 0, true, OIIO::TypeFloat)) {
            s.base.coc.lens.fstop          = 1.4;
            s.base.coc.lens.focal_mm       = 100.0;
            s.base.coc.focus_at_pixel      = true;
            s.base.coc.focus_x             = s.image.roi().xbegin + s.image.roi().width() / 2;
            s.base.coc.focus_y             = s.image.roi().ybegin + s.image.roi().height() / 2;
            s.base.coc.max_coc_px          = 64.0;
            out.push_back(std::move(s));
        }
    }
    // LowResLeftView: the three deep passes merged and flattened (OIIO), Z = the
    // nearest sample's depth. Z is 72..300 on the objects; read as centimetres it is a
    // 0.7..3 m model forest. Focus on the large red ball (pixel 780,390, Z = 197), 50 mm
    // f/2: the nearest cone gets -32 px, the empty background +18 px.
    if (wanted(a, "lowresleftview")) {
        OIIO::ImageBuf merged;
        bool ok = true;
        for (const char* part : { "Balls", "Leaves", "Trunks" }) {
            OIIO::ImageBuf d(a.data_dir + "/openexr-images/LowResLeftView_" + std::string(part) + ".exr");
            ok = ok && d.read(0, 0, true);
            if (!ok)
                break;
            merged = merged.initialized() ? IBA::deep_merge(merged, d) : d;
        }
        if (ok) {
            Shot s;
            s.name  = "lowresleftview";
            s.image = IBA::flatten(merged);
            s.base.coc.lens.fstop = 2.0;
            s.base.coc.lens.depth_unit_mm = 10.0;
            s.base.coc.focus_at_pixel = true;
            s.base.coc.focus_x    = 780;
            s.base.coc.focus_y    = 390;
            s.base.coc.max_coc_px = 64.0;
            if (!s.image.has_error() && bokeh::find_channels(s.image.spec()).z >= 0)
                out.push_back(std::move(s));
        }
    }
    return out;
}

// A 640-pixel-wide sRGB JPEG of `img` (premultiplied RGB over black) for the picture sheet.
void write_preview(const OIIO::ImageBuf& img, const std::string& path, int threads)
{
    const OIIO::ROI full(img.spec().full_x, img.spec().full_x + img.spec().full_width, img.spec().full_y,
                         img.spec().full_y + img.spec().full_height, 0, 1, 0, 3);
    OIIO::ImageBuf rgb = IBA::channels(img, 3, { 0, 1, 2 });
    rgb                = IBA::cut(rgb, full);  // display window, black outside the data
    const int w = 640, h = std::max(1, full.height() * 640 / std::max(1, full.width()));
    OIIO::ImageBuf small = IBA::resize(rgb, "box", 0.0f, OIIO::ROI(0, w, 0, h, 0, 1, 0, 3), threads);
    OIIO::ImageBuf srgb  = IBA::colorconvert(small, "linear", "sRGB", true, "", "", nullptr, {}, threads);
    srgb.specmod().attribute("Compression", "jpeg:90");
    if (!srgb.write(path, OIIO::TypeUInt8))
        std::fprintf(stderr, "bokeh-bench: cannot write %s: %s\n", path.c_str(), srgb.geterror().c_str());
}

// A 1:1 crop (480 x 270 of the display window, within it) centred on (cx, cy), as an sRGB
// JPEG: the lens character's rims, fringes and rings at the frame's own pixels.
void write_crop(const OIIO::ImageBuf& img, int cx, int cy, const std::string& path, int threads)
{
    const OIIO::ImageSpec& s = img.spec();
    const int w = std::min(480, s.full_width), h = std::min(270, s.full_height);
    const int x0 = std::clamp(cx - w / 2, s.full_x, s.full_x + s.full_width - w);
    const int y0 = std::clamp(cy - h / 2, s.full_y, s.full_y + s.full_height - h);
    OIIO::ImageBuf rgb  = IBA::channels(img, 3, { 0, 1, 2 });
    OIIO::ImageBuf crop = IBA::cut(rgb, OIIO::ROI(x0, x0 + w, y0, y0 + h, 0, 1, 0, 3));
    OIIO::ImageBuf srgb = IBA::colorconvert(crop, "linear", "sRGB", true, "", "", nullptr, {}, threads);
    srgb.specmod().attribute("Compression", "jpeg:90");
    if (!srgb.write(path, OIIO::TypeUInt8))
        std::fprintf(stderr, "bokeh-bench: cannot write %s: %s\n", path.c_str(), srgb.geterror().c_str());
}

// The picture sheet's lens-character columns (lights and giant): the default method with
// lens character on, an uncorrected singlet, an achromat and an apochromat, each with rim
// fringes (the Fresnel edge law) and onion rings (contrast 0.15), as 640-px previews and
// 1:1 crops, and the plain default's crop beside them. The crop is centred on the
// brightest pixel of the sharp input (a highlight the lens shapes).
void write_lens_sheet(const Shot& shot, const OIIO::ImageBuf& plain, const std::string& dir, int threads)
{
    const OIIO::ImageBuf& sharp = shot.image;
    int cx = 0, cy = 0;
    float best = -1.0f;
    const OIIO::ROI look = sharp.roi();
    for (int y = look.ybegin; y < look.yend; ++y)
        for (int x = look.xbegin; x < look.xend; ++x) {
            float p[3];
            sharp.getpixel(x, y, p, 3);
            const float l = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
            if (l > best)
                best = l, cx = x, cy = y;
        }
    const std::string stem = dir + "/defocus_" + shot.name + "_lens_";
    write_crop(plain, cx, cy, stem + "off_crop.jpg", threads);
    const std::pair<bokeh::LensPreset, const char*> lenses[] = { { bokeh::LensPreset::Uncorrected, "uncorrected" },
                                                                 { bokeh::LensPreset::Achromat, "achromat" },
                                                                 { bokeh::LensPreset::Apochromat, "apochromat" } };
    for (const auto& [preset, name] : lenses) {
        bokeh::DefocusOptions o = shot.base;
        o.lens_character        = true;
        o.lens.preset           = preset;
        o.lens.diffraction      = bokeh::DiffractionModel::EdgeLaw;
        o.lens.onion            = 0.15;
        OIIO::ImageBuf out;
        if (!bokeh::defocus(out, shot.image, o, nullptr, threads)) {
            std::fprintf(stderr, "bokeh-bench: %s, %s: %s\n", shot.name.c_str(), name, out.geterror().c_str());
            continue;
        }
        write_preview(out, stem + name + ".jpg", threads);
        write_crop(out, cx, cy, stem + name + "_crop.jpg", threads);
    }
}

}  // namespace

bool run_defocus_task(const BenchArgs& a, std::vector<std::string>& rows)
{
    std::vector<Shot> all = shots(a);
    for (const std::string& name : a.only)
        if (std::none_of(all.begin(), all.end(), [&](const Shot& s) { return s.name == name; })) {
            std::fprintf(stderr, "bokeh-bench: --scenes: '%s' is not a shot here (the built-in scenes, "
                                 "or beachball / lowresleftview with --data)\n",
                         name.c_str());
            return false;
        }
    std::printf("\n%-16s %-34s %8s %10s %10s %8s\n", "scene", "method", "max CoC", "median ms",
                "RMSE", "PSNR dB");
    for (Shot& shot : all) {
        bokeh::DefocusOptions ref_opts = shot.base;
        ref_opts.method                = bokeh::DefocusMethod::Reference;
        OIIO::ImageBuf ref;
        bokeh::DefocusReport rep;
        if (!bokeh::defocus(ref, shot.image, ref_opts, &rep, a.threads)) {  // untimed: its report, its pixels
            std::fprintf(stderr, "bokeh-bench: %s: %s\n", shot.name.c_str(), ref.geterror().c_str());
            return false;
        }
        const float extreme = std::max(-rep.min_coc_px, rep.max_coc_px);
        auto report = [&](const std::string& method, double ms, int n, const OIIO::ImageBuf& r) {
            bokeh::ImageError e;
            std::string err;
            bokeh::compare(e, r, ref, err, {}, a.threads);
            std::printf("%-16s %-34s %8.1f %10.1f %10.3g %8.1f\n", shot.name.c_str(), method.c_str(),
                        extreme, ms, e.rmse_linear, e.psnr_db);
            std::fflush(stdout);
            rows.push_back(format("defocus {},{},,{:.1f},{},{:.3f},{},{}", shot.name, method, extreme,
                                  a.threads, ms, n, error_fields(e)));
        };
        if (!a.images_dir.empty()) {
            write_preview(shot.image, a.images_dir + "/defocus_" + shot.name + "_sharp.jpg", a.threads);
            write_preview(ref, a.images_dir + "/defocus_" + shot.name + "_reference.jpg", a.threads);
        }

        struct Variant {
            std::string name;
            std::function<void(bokeh::DefocusOptions&)> set;
        };
        std::vector<Variant> variants;
        for (float db : { 30.0f, 40.0f, 50.0f, 60.0f })
            variants.push_back({ format("layers budget {:g} dB{}", db, db == 40.0f ? " (default)" : ""),
                                 [db](bokeh::DefocusOptions& o) {
                                     o.method    = bokeh::DefocusMethod::Auto;
                                     o.budget_db = db;
                                 } });
        variants.push_back({ "layers 40 dB at full resolution", [](bokeh::DefocusOptions& o) {
                                o.method        = bokeh::DefocusMethod::Layers;
                                o.max_reduction = 1;
                            } });
        variants.push_back({ "layers 8 (user count)", [](bokeh::DefocusOptions& o) {
                                o.method = bokeh::DefocusMethod::Layers;
                                o.layers = 8;
                            } });
        variants.push_back({ "gather (hikita)", [](bokeh::DefocusOptions& o) {
                                o.method = bokeh::DefocusMethod::Gather;
                            } });
        // The reference and every variant timed together in interleaved rounds (timing.h),
        // each timed run right after an untimed one of the same case; the reference (seconds
        // a run on giant) the median of 3, drawn again into `ref` (the same pixels).
        std::vector<OIIO::ImageBuf> outs(variants.size());
        std::vector<std::function<void()>> fns = { [&] { bokeh::defocus(ref, shot.image, ref_opts, nullptr, a.threads); } };
        std::vector<int> nreps = { std::min(a.reps, 3) };
        for (size_t i = 0; i < variants.size(); ++i) {
            bokeh::DefocusOptions o = shot.base;
            variants[i].set(o);
            fns.push_back([&, o, i] { bokeh::defocus(outs[i], shot.image, o, nullptr, a.threads); });
            nreps.push_back(a.reps);
        }
        const std::vector<double> ms = interleaved_medians_ms(fns, nreps, std::vector<bool>(fns.size(), true));
        report(format("reference ({} layers)", rep.layer_coc_px.size()), ms[0], nreps[0], ref);
        for (size_t i = 0; i < variants.size(); ++i) {
            const Variant& v          = variants[i];
            const OIIO::ImageBuf& out = outs[i];
            report(v.name, ms[i + 1], nreps[i + 1], out);
            if (!a.images_dir.empty() && (v.name.find("default") != std::string::npos
                                          || v.name.find("gather") != std::string::npos))
                write_preview(out, a.images_dir + "/defocus_" + shot.name + "_"
                                       + (v.name.find("gather") != std::string::npos ? "gather" : "layers")
                                       + ".jpg",
                              a.threads);
            if (!a.images_dir.empty() && v.name.find("default") != std::string::npos
                && (shot.name == "lights" || shot.name == "giant"))
                write_lens_sheet(shot, out, a.images_dir, a.threads);
        }
    }
    return true;
}

// The thin-lens truth of a built-in scene's shot (make_scene_truth: rays against the scene's
// own geometry), with ray seed `seed`; false for a shot read from a file.
bool shot_truth(OIIO::ImageBuf& truth, const Shot& shot, const BenchArgs& a, uint32_t seed)
{
    const std::vector<std::string> names = bokeh::scene_names();
    if (std::find(names.begin(), names.end(), shot.name) == names.end())
        return false;
    bokeh::SceneOptions so;
    so.width  = a.width;
    so.height = a.height;
    bokeh::SceneTruthOptions t;
    t.lens               = shot.base.coc.lens;
    t.lens.depth_unit_mm = 1000.0;  // the scenes' metres
    t.aperture.shape     = bokeh::KernelShape::Disk;
    t.spp                = kPlanTruthRays;
    t.seed               = seed;
    if (!bokeh::make_scene_truth(truth, shot.name, so, t, nullptr, a.threads)) {
        std::fprintf(stderr, "bokeh-bench: %s: truth: %s\n", shot.name.c_str(), truth.geterror().c_str());
        return false;
    }
    return true;
}

// The plans task: on each shot, the default (the budget's steps) and the plans the predicted
// planner weighs (its run's report), a grid of them run and measured (in-process median
// time, PSNR against the reference and, on the built-in scenes, against the thin-lens truth)
// beside what it predicted of them, and its choice. A second truth with another seed gives
// the floor: the PSNR past which the truth cannot tell two plans apart (a "floor" row).
bool run_plans_task(const BenchArgs& a, std::vector<std::string>& rows)
{
    std::vector<Shot> all = shots(a);
    const std::vector<float> ratios = { 1.0f, 1.0625f, 1.125f, 1.25f, 1.5f, 2.0f, 3.0f };
    const std::vector<float> qs     = { 8.0f, 16.0f, 32.0f, 64.0f, 128.0f, std::numeric_limits<float>::infinity() };
    std::printf("\n%-16s %-7s %-8s %6s %9s %9s %9s %9s %9s\n", "scene", "ratio", "q", "layers", "pred dB", "PSNR dB",
                "pred ms", "ms", "truth dB");
    for (Shot& shot : all) {
        bokeh::DefocusOptions ref_opts = shot.base;
        ref_opts.method                = bokeh::DefocusMethod::Reference;
        OIIO::ImageBuf ref;
        if (!bokeh::defocus(ref, shot.image, ref_opts, nullptr, a.threads)) {
            std::fprintf(stderr, "bokeh-bench: %s: %s\n", shot.name.c_str(), ref.geterror().c_str());
            return false;
        }
        OIIO::ImageBuf truth, truth2;
        const bool have_truth = shot_truth(truth, shot, a, 1) && shot_truth(truth2, shot, a, 2);
        // PSNR against the truth ("" without one).
        auto truth_db = [&](const OIIO::ImageBuf& img) {
            if (!have_truth)
                return std::string();
            bokeh::ImageError e;
            std::string err;
            bokeh::compare(e, img, truth, err, {}, a.threads);
            return format("{:.2f}", e.psnr_db);
        };
        if (have_truth) {
            const std::string floor_db = truth_db(truth2);
            std::printf("%-16s two truths of %d rays agree to %s dB\n", shot.name.c_str(), kPlanTruthRays,
                        floor_db.c_str());
            rows.push_back(format("{},,,,,,,,{},floor,{}", shot.name, a.threads, floor_db));
        }
        OIIO::ImageBuf out;
        bokeh::DefocusReport rep;
        bokeh::DefocusOptions predicted = shot.base;
        predicted.planner               = bokeh::DefocusPlanner::Predicted;
        if (!bokeh::defocus(out, shot.image, predicted, &rep, a.threads)) {
            std::fprintf(stderr, "bokeh-bench: %s: %s\n", shot.name.c_str(), out.geterror().c_str());
            return false;
        }
        // Every plan run below timed together in interleaved rounds (timing.h), each timed run
        // right after an untimed one of the same plan: the steps' plan (the default) first.
        std::vector<const bokeh::DefocusPlanEstimate*> grid;
        std::vector<std::function<void()>> fns;
        std::vector<OIIO::ImageBuf> outs(1 + rep.plans.size());
        bokeh::DefocusReport steps;  // the steps' plan, as its timed runs report it
        fns.push_back([&] { bokeh::defocus(outs[0], shot.image, shot.base, &steps, a.threads); });
        for (const bokeh::DefocusPlanEstimate& p : rep.plans) {
            const bool on_grid = p.chosen
                                 || (std::find(qs.begin(), qs.end(), p.min_reduced_coc_px) != qs.end()
                                     && std::any_of(ratios.begin(), ratios.end(), [&](float r) {
                                            return std::abs(r - p.ladder_ratio) < 1e-3f;
                                        }));
            if (!on_grid)
                continue;
            bokeh::DefocusOptions o = shot.base;
            o.method                = bokeh::DefocusMethod::Layers;
            o.ladder_ratio          = p.ladder_ratio;
            if (std::isinf(p.min_reduced_coc_px))
                o.max_reduction = 1;
            else
                o.min_reduced_coc_px = p.min_reduced_coc_px;
            const size_t k = fns.size();
            fns.push_back([&, o, k] { bokeh::defocus(outs[k], shot.image, o, nullptr, a.threads); });
            grid.push_back(&p);
        }
        const std::vector<double> times = interleaved_medians_ms(fns, std::vector<int>(fns.size(), a.reps),
                                                                 std::vector<bool>(fns.size(), true));
        {
            const double ms = times[0];
            bokeh::ImageError e;
            std::string err;
            bokeh::compare(e, outs[0], ref, err, {}, a.threads);
            const bokeh::DefocusPlanEstimate& p = steps.plans.at(0);
            const std::string vs_truth = truth_db(outs[0]);
            std::printf("%-16s %-7s %-8g %6d %9s %9.1f %9s %9.1f %9s  (default: steps)\n", shot.name.c_str(), "steps",
                        p.min_reduced_coc_px, p.layers, "", e.psnr_db, "", ms, vs_truth.c_str());
            rows.push_back(format("{},0,{:g},{},,{:.2f},,{:.2f},{},steps,{}", shot.name, p.min_reduced_coc_px, p.layers,
                                  e.psnr_db, ms, a.threads, vs_truth));
        }
        for (size_t g = 0; g < grid.size(); ++g) {
            const bokeh::DefocusPlanEstimate& p = *grid[g];
            const double ms                     = times[g + 1];
            bokeh::ImageError e;
            std::string err;
            bokeh::compare(e, outs[g + 1], ref, err, {}, a.threads);
            const std::string vs_truth = truth_db(outs[g + 1]);
            std::printf("%-16s %-7.4g %-8g %6d %9.1f %9.1f %9.1f %9.1f %9s%s\n", shot.name.c_str(), p.ladder_ratio,
                        p.min_reduced_coc_px, p.layers, p.predicted_psnr_db, e.psnr_db, p.predicted_ms, ms,
                        vs_truth.c_str(), p.chosen ? "  (planner=predicted)" : "");
            std::fflush(stdout);
            rows.push_back(format("{},{:g},{:g},{},{:.2f},{:.2f},{:.2f},{:.2f},{},{},{}", shot.name, p.ladder_ratio,
                                  p.min_reduced_coc_px, p.layers, p.predicted_psnr_db, e.psnr_db, p.predicted_ms,
                                  ms, a.threads, p.chosen ? "predicted" : "", vs_truth));
        }
    }
    return true;
}

}  // namespace bokeh_bench
