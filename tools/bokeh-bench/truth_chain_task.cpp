// truth_chain_task.cpp — bokeh-bench's truth-chain task: on the built-in scenes, every
// step from the lens's geometry to the fast methods, each measured against the thin-lens
// truth traced against the scene's own geometry (make_scene_truth, scene.h).
//
// Stages, all with the scene's own lens (its focus and f-number, 50 mm on 36 mm, a disk,
// no CoC limit):
//   geometric truth     its own noise (the two half renders' difference: truth.h)
//   deep truth          defocus_truth of the scene's deep image (make_deep_scene), the
//                       same rays (same spp and seed); and with other rays (seed 2), from
//                       the pixels' centres (the default) and, "pixel area", from their
//                       squares (TruthPixel::Area)
//   deep reference/auto the deep defocus (one layer per CoC step / the budget's layers)
//   flat truth          defocus_truth of the sharp scene deepened (no hidden surfaces)
//   flat reference/auto the flat defocus of the sharp scene (the default fill, and auto
//                       with the mirror and the foreground fills: defocus.h)
// PSNR as bench_common.h (tone-mapped, peak 1) over the frame's interior: the frame less
// half the largest CoC and a pixel on each side, where the geometric truth's rays see past
// the frame's edge and the others cannot. The disocclusion mask: interior pixels where the
// deep truth and the flat truth differ by more than 0.01 in R, G, B or A (what the flat
// image hides and the lens sees); its PSNR sets every pixel outside it to the truth and
// scales the error by the mask's share (bench_common.h, masked_psnr). Both again over 4 x 4 block
// averages of the interior: tiny HDR lights make the truths noisy (a ray meets a light or
// misses it), and averaging 16 pixels cuts that independent noise by 12 dB while keeping
// the errors wider than 4 px (a background missing or invented behind a foreground).

#include "truth_chain_task.h"

#include "bench_common.h"
#include "timing.h"

#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>
#include <bokeh/truth.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh_bench {

namespace {

using OIIO::Strutil::fmt::format;
namespace IBA = OIIO::ImageBufAlgo;

double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

OIIO::ImageBuf rgba_of(const OIIO::ImageBuf& img) { return IBA::channels(img, 4, { 0, 1, 2, 3 }); }

// R, G, B, A of `img` averaged over the 4 x 4 blocks of `roi` (its origin at 0, 0).
OIIO::ImageBuf blocks_of(const OIIO::ImageBuf& img, const OIIO::ROI& roi)
{
    const int w = roi.width() / 4, h = roi.height() / 4;
    OIIO::ImageBuf out(OIIO::ImageSpec(w, h, 4, OIIO::TypeFloat));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            float v[4] = {}, p[4];
            for (int j = 0; j < 4; ++j)
                for (int i = 0; i < 4; ++i) {
                    img.getpixel(roi.xbegin + 4 * x + i, roi.ybegin + 4 * y + j, p, 4);
                    for (int c = 0; c < 4; ++c)
                        v[c] += p[c] / 16.0f;
                }
            out.setpixel(x, y, v, 4);
        }
    return out;
}

}  // namespace

bool run_truth_chain_task(const BenchArgs& args, std::vector<std::string>& rows)
{
    const int t = args.threads;
    const int spp = args.reps >= 5 ? 256 : 64;
    const std::vector<std::string> scenes = args.only.empty() ? bokeh::scene_names() : args.only;
    std::printf("truth chain: %dx%d, %d rays a pixel, %d threads; PSNR (dB) against the geometric truth\n",
                args.width, args.height, spp, t);
    std::printf("%-8s %-26s %7s %7s %7s %7s %8s\n", "scene", "stage", "frame", "mask", "frame/4", "mask/4",
                "seconds");
    for (const std::string& name : scenes) {
        bokeh::SceneCamera cam;
        if (!bokeh::scene_camera(name, cam)) {
            std::fprintf(stderr, "bokeh-bench: truth-chain: no built-in scene '%s'\n", name.c_str());
            return false;
        }
        bokeh::SceneOptions so;
        so.width  = args.width;
        so.height = args.height;
        bokeh::SceneTruthOptions lens;
        lens.lens.focal_mm        = cam.focal_mm;
        lens.lens.sensor_width_mm = cam.sensor_width_mm;
        lens.lens.focus_distance  = cam.focus_m;
        lens.lens.fstop           = cam.fstop;
        lens.lens.depth_unit_mm   = 1000.0;
        lens.aperture.shape       = bokeh::KernelShape::Disk;
        lens.spp                  = spp;

        OIIO::ImageBuf geo, sharp, deep;
        bokeh::SceneTruthReport geo_rep;
        auto t0 = std::chrono::steady_clock::now();
        if (!bokeh::make_scene_truth(geo, name, so, lens, &geo_rep, t)) {
            std::fprintf(stderr, "bokeh-bench: truth-chain: %s\n", geo.geterror().c_str());
            return false;
        }
        const double geo_s = seconds_since(t0);
        t0 = std::chrono::steady_clock::now();
        if (!bokeh::make_scene(sharp, name, so, t) || !bokeh::make_deep_scene(deep, name, so, t)) {
            std::fprintf(stderr, "bokeh-bench: truth-chain: %s%s\n", sharp.geterror().c_str(), deep.geterror().c_str());
            return false;
        }
        const double deep_scene_s = seconds_since(t0);

        bokeh::TruthOptions to;
        to.coc.lens       = lens.lens;
        to.coc.max_coc_px = 8192.0;
        to.aperture       = lens.aperture;
        to.spp            = spp;
        bokeh::DefocusOptions dof;
        dof.coc      = to.coc;
        dof.aperture = lens.aperture;

        struct Stage {
            std::string name;
            OIIO::ImageBuf out;
            double seconds = 0.0;
            std::function<bool(OIIO::ImageBuf&)> fn;  // its run, for the timing below
        };
        std::vector<Stage> stages;
        auto run = [&](const std::string& stage, const std::function<bool(OIIO::ImageBuf&)>& fn) {
            Stage s{ stage, {}, 0.0, fn };
            const auto s0 = std::chrono::steady_clock::now();
            if (!fn(s.out)) {
                std::fprintf(stderr, "bokeh-bench: truth-chain: %s %s: %s\n", name.c_str(), stage.c_str(),
                             s.out.geterror().c_str());
                return false;
            }
            s.seconds = seconds_since(s0);
            s.out     = rgba_of(s.out);
            stages.push_back(std::move(s));
            return true;
        };
        OIIO::ImageBuf deepened;
        if (!bokeh::deep_from_flat(deepened, sharp, 1.0f, t))
            return false;
        auto defocus_with = [&](const OIIO::ImageBuf& src, bokeh::DefocusMethod m,
                                bokeh::DisocclusionFill fill = bokeh::DefocusOptions().fill) {
            return [&, m, fill](OIIO::ImageBuf& out) {
                bokeh::DefocusOptions o = dof;
                o.method                = m;
                o.fill                  = fill;
                return bokeh::defocus(out, src, o, nullptr, t);
            };
        };
        bokeh::TruthOptions other = to;
        other.seed                = 2;
        bokeh::TruthOptions other_area = other;
        other_area.pixel               = bokeh::TruthPixel::Area;
        if (!run("deep truth", [&](OIIO::ImageBuf& out) { return bokeh::defocus_truth(out, deep, to, nullptr, t); })
            || !run("deep truth (other rays)",
                    [&](OIIO::ImageBuf& out) { return bokeh::defocus_truth(out, deep, other, nullptr, t); })
            || !run("deep truth (pixel area)",
                    [&](OIIO::ImageBuf& out) { return bokeh::defocus_truth(out, deep, other_area, nullptr, t); })
            || !run("deep reference", defocus_with(deep, bokeh::DefocusMethod::Reference))
            || !run("deep auto", defocus_with(deep, bokeh::DefocusMethod::Auto))
            || !run("flat truth", [&](OIIO::ImageBuf& out) { return bokeh::defocus_truth(out, deepened, to, nullptr, t); })
            || !run("flat reference", defocus_with(sharp, bokeh::DefocusMethod::Reference))
            || !run("flat auto", defocus_with(sharp, bokeh::DefocusMethod::Auto))
            || !run("flat auto fill=mirror",
                    defocus_with(sharp, bokeh::DefocusMethod::Auto, bokeh::DisocclusionFill::Mirror))
            || !run("flat auto fill=foreground",
                    defocus_with(sharp, bokeh::DefocusMethod::Auto, bokeh::DisocclusionFill::Foreground)))
            return false;

        // The defocus stages' times: the median of 3 in interleaved rounds (timing.h), each timed
        // run right after an untimed one of the same stage (the run above made its pixels). The
        // truths keep their one run: references of seconds each, not contenders.
        {
            std::vector<std::function<void()>> fns;
            std::vector<size_t> which;
            for (size_t i = 0; i < stages.size(); ++i)
                if (stages[i].name.find("truth") == std::string::npos) {
                    which.push_back(i);
                    fns.push_back([&, i] { OIIO::ImageBuf o; stages[i].fn(o); });
                }
            const std::vector<double> ms = interleaved_medians_ms(fns, std::vector<int>(fns.size(), std::min(args.reps, 3)),
                                                                  std::vector<bool>(fns.size(), true));
            for (size_t j = 0; j < which.size(); ++j)
                stages[which[j]].seconds = ms[j] / 1e3;
        }

        // The interior, and the mask: where the deep and the flat truth differ.
        const int inset = int(std::ceil(0.5 * std::max(std::abs(geo_rep.min_coc_px), std::abs(geo_rep.max_coc_px)))) + 1;
        const OIIO::ROI interior(inset, so.width - inset, inset, so.height - inset, 0, 1, 0, 4);
        if (interior.width() < 1 || interior.height() < 1) {
            std::fprintf(stderr, "bokeh-bench: truth-chain: %s: the CoC (%d px inset) leaves no interior at %dx%d\n",
                         name.c_str(), inset, so.width, so.height);
            return false;
        }
        // Everything cut to the interior (origin 0, 0), and its 4 x 4 blocks: averaging 16
        // pixels cuts independent noise (tiny HDR lights make much of it) by 12 dB and
        // keeps errors wider than 4 px, as a background missing behind a foreground is.
        auto cut = [&](const OIIO::ImageBuf& img) { return IBA::cut(rgba_of(img), interior); };
        const OIIO::ImageBuf geo4 = cut(geo), geo_blocks = blocks_of(geo4, geo4.roi());
        auto stage_named = [&](const std::string& n) -> const OIIO::ImageBuf& {
            const auto it = std::find_if(stages.begin(), stages.end(), [&](const Stage& s) { return s.name == n; });
            return it != stages.end() ? it->out : stages.front().out;  // every name asked for is run above
        };
        const OIIO::ImageBuf deep_truth = cut(stage_named("deep truth")), flat_truth = cut(stage_named("flat truth"));
        const int iw = interior.width(), ih = interior.height(), bw = iw / 4, bh = ih / 4;
        std::vector<uint8_t> mask(size_t(iw) * size_t(ih), 0), block_mask(size_t(bw) * size_t(bh), 0);
        int64_t in_mask = 0;
        for (int y = 0; y < ih; ++y)
            for (int x = 0; x < iw; ++x) {
                bool differs = false;
                for (int c = 0; c < 4; ++c)
                    differs |= std::abs(deep_truth.getchannel(x, y, 0, c) - flat_truth.getchannel(x, y, 0, c)) > 0.01f;
                mask[size_t(y) * size_t(iw) + size_t(x)] = differs;
                in_mask += differs;
                if (differs && x / 4 < bw && y / 4 < bh)
                    block_mask[size_t(y / 4) * size_t(bw) + size_t(x / 4)] = 1;
            }
        const double share = double(in_mask) / double(interior.npixels());
        struct Figures {
            double frame, mask, frame_blocks, mask_blocks;
        };
        auto measure = [&](const OIIO::ImageBuf& img) {
            const OIIO::ImageBuf px = cut(img), blocks = blocks_of(px, px.roi());
            bokeh::ImageError e, eb;
            std::string why;
            bokeh::compare(e, px, geo4, why, {}, t);
            bokeh::compare(eb, blocks, geo_blocks, why, {}, t);
            return Figures{ e.psnr_db, masked_psnr(px, geo4, mask, geo4.roi(), t), eb.psnr_db,
                            masked_psnr(blocks, geo_blocks, block_mask, geo_blocks.roi(), t) };
        };
        auto row = [&](const std::string& stage, const Figures& f, double secs) {
            std::printf("%-8s %-26s %7.2f %7.2f %7.2f %7.2f %8.2f\n", name.c_str(), stage.c_str(), f.frame, f.mask,
                        f.frame_blocks, f.mask_blocks, secs);
            rows.push_back(format("{},{},{},{},{},{},{:.2f},{:.2f},{:.2f},{:.2f},{},{},{:.3f}", name, so.width,
                                  so.height, spp, t, stage, f.frame, f.mask, f.frame_blocks, f.mask_blocks, in_mask,
                                  interior.npixels(), secs));
            std::fflush(stdout);
        };
        // The geometric truth's own noise: what comparing it with a noiseless truth scores.
        row("geometric truth (noise)", Figures{ geo_rep.noise_psnr_db, -1.0, -1.0, -1.0 }, geo_s);
        row("deep scene (make)", Figures{ -1.0, -1.0, -1.0, -1.0 }, deep_scene_s);
        for (const Stage& s : stages)
            row(s.name, measure(s.out), s.seconds);
        std::printf("%-8s mask: %lld of %lld interior px (%.1f %%), inset %d px; CoC %.1f .. %.1f px\n", name.c_str(),
                    (long long)in_mask, (long long)interior.npixels(), 100.0 * share, inset, geo_rep.min_coc_px,
                    geo_rep.max_coc_px);
    }
    return true;
}

}  // namespace bokeh_bench
