// deep_task.cpp — bokeh-bench's deep task: the deep nodes and the deep defocus on real
// deep renders, side by side with OpenImageIO's deep functions in the same run.
//
// Frames: the three LowResLeftView passes (Weta, 1024x576, point samples; merged: up to 6
// samples a pixel) and Gaffer's representativeDeepImage (150x100, volumes only, up to 227
// samples a pixel). Every case is timed in interleaved rounds (timing.h), medians.
// Errors: our flatten against OIIO's where OIIO is exact (tidy, sorted input), the merge's
// flatten against OIIO's merge's (OIIO culls hidden samples, which a flatten cannot see),
// and each defocus against the deep reference (one full-resolution layer per CoC step).

#include "deep_task.h"
#include "bench_common.h"
#include "timing.h"

#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/io.h>
#include <bokeh/metrics.h>
#include <bokeh/truth.h>

#include <cmath>
#include <cstdio>
#include <functional>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/timer.h>

namespace bokeh_bench {

namespace {

using OIIO::Strutil::fmt::format;
namespace IBA = OIIO::ImageBufAlgo;

struct Case {
    std::string method, peer, frame;
    std::function<void()> run;
    int reps;
};

// RGBA of a flat image over `roi` (missing channels 0), for comparisons.
OIIO::ImageBuf rgba_of(const OIIO::ImageBuf& img, const OIIO::ROI& roi)
{
    OIIO::ImageBuf out = IBA::channels(img, 4, { 0, 1, 2, 3 });
    return IBA::crop(out, roi);
}

}  // namespace

bool run_deep_task(const BenchArgs& args, std::vector<std::string>& rows)
{
    const std::string dir = args.data_dir + "/openexr-images";
    const std::string names[3] = { "Balls", "Leaves", "Trunks" };
    OIIO::ImageBuf pass[3], rep_img;
    std::string err;
    for (int i = 0; i < 3; ++i)
        if (args.data_dir.empty()
            || !bokeh::read_image(pass[i], format("{}/LowResLeftView_{}.exr", dir, names[i]), err)) {
            std::printf("deep task: the LowResLeftView passes are not under %s; skipped\n", dir.c_str());
            return true;
        }
    const bool have_rep = bokeh::read_image(rep_img, args.data_dir + "/gaffer/representativeDeepImage.exr", err);
    const int t = args.threads;

    OIIO::ImageBuf merged, flat, tidy_rep;
    if (!bokeh::deep_merge(merged, { &pass[0], &pass[1], &pass[2] }, false, {}, t)
        || !bokeh::flatten(flat, merged, {}, t)) {
        std::fprintf(stderr, "bokeh-bench: deep: %s%s\n", merged.geterror().c_str(), flat.geterror().c_str());
        return false;
    }
    const bokeh::DeepStats st = bokeh::deep_stats(*merged.deepdata());
    std::printf("deep: LowResLeftView merged: %lld samples, up to %d a pixel; %d threads\n",
                (long long)st.total_samples, st.max_samples, t);

    // The lens of the defocus cases: Z in centimetres, focus 3 m, f/2: CoCs -38 .. 8 px.
    bokeh::DefocusOptions lens;
    lens.coc.lens.focus_distance = 300.0;
    lens.coc.lens.fstop          = 2.0;
    lens.coc.lens.depth_unit_mm  = 10.0;
    auto with = [&](bokeh::DefocusMethod m, bool deep_out) {
        bokeh::DefocusOptions o = lens;
        o.method                = m;
        o.deep_output           = deep_out;
        return o;
    };

    std::vector<Case> cases;
    auto add = [&](std::string method, std::string peer, std::string frame, std::function<void()> fn, int reps) {
        cases.push_back({ std::move(method), std::move(peer), std::move(frame), std::move(fn), reps });
    };
    const std::string lr = "LowResLeftView merged";
    add("merge 3 passes", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_merge(d, { &pass[0], &pass[1], &pass[2] }, false, {}, t); }, args.reps);
    add("merge 3 passes (cull)", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_merge(d, { &pass[0], &pass[1], &pass[2] }, true, {}, t); }, args.reps);
    add("merge 3 passes (cull)", "oiio", lr, [&] {
        OIIO::ImageBuf ab = IBA::deep_merge(pass[0], pass[1], true, {}, t);
        OIIO::ImageBuf abc = IBA::deep_merge(ab, pass[2], true, {}, t);
    }, args.reps);
    add("tidy", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_tidy(d, merged, {}, t); }, args.reps);
    add("flatten", "", lr, [&] { OIIO::ImageBuf d; bokeh::flatten(d, merged, {}, t); }, args.reps);
    add("flatten", "oiio", lr, [&] { OIIO::ImageBuf d = IBA::flatten(merged, {}, t); }, args.reps);
    add("holdout by Leaves", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_holdout(d, merged, pass[1], {}, t); }, args.reps);
    add("holdout by Leaves", "oiio", lr, [&] { OIIO::ImageBuf d = IBA::deep_holdout(merged, pass[1], {}, t); }, args.reps);
    add("slice 200..600", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_slice(d, merged, 200.0, 600.0, {}, t); }, args.reps);
    add("defocus deep auto", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, merged, with(bokeh::DefocusMethod::Auto, false), nullptr, t); }, args.reps);
    add("defocus deep auto (deep out)", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, merged, with(bokeh::DefocusMethod::Auto, true), nullptr, t); }, args.reps);
    add("defocus flat of the flatten (auto)", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, flat, with(bokeh::DefocusMethod::Auto, false), nullptr, t); }, args.reps);
    add("defocus deep reference", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, merged, with(bokeh::DefocusMethod::Reference, false), nullptr, t); }, std::max(1, args.reps / 3));
    if (have_rep) {
        add("tidy", "", "representativeDeepImage", [&] { OIIO::ImageBuf d; bokeh::deep_tidy(d, rep_img, {}, t); }, args.reps);
        add("flatten", "", "representativeDeepImage", [&] { OIIO::ImageBuf d; bokeh::flatten(d, rep_img, {}, t); }, args.reps);
        add("flatten", "oiio", "representativeDeepImage", [&] { OIIO::ImageBuf d = IBA::flatten(rep_img, {}, t); }, args.reps);
    }
    std::vector<std::function<void()>> fns;
    std::vector<int> reps;
    std::vector<bool> warm;
    for (const Case& c : cases) {
        fns.push_back(c.run);
        reps.push_back(c.reps);
        warm.push_back(c.method.find("reference") == std::string::npos);
    }
    const std::vector<double> ms = interleaved_medians_ms(fns, reps, warm);

    // Errors where a comparison means something.
    std::vector<std::string> error_of(cases.size());
    auto measure = [&](const OIIO::ImageBuf& got, const OIIO::ImageBuf& want) {
        bokeh::ImageError e;
        std::string why;
        const OIIO::ROI roi = OIIO::roi_union(got.roi(), want.roi());
        if (!bokeh::compare(e, rgba_of(got, roi), rgba_of(want, roi), why, {}, t))
            return std::string(",,");
        return error_fields(e);
    };
    OIIO::ImageBuf oiio_flat = IBA::flatten(merged, {}, t);
    OIIO::ImageBuf ref, auto_flat, auto_deep, flat_dof, deep_out_flat;
    bokeh::defocus(ref, merged, with(bokeh::DefocusMethod::Reference, false), nullptr, t);
    bokeh::defocus(auto_flat, merged, with(bokeh::DefocusMethod::Auto, false), nullptr, t);
    bokeh::defocus(auto_deep, merged, with(bokeh::DefocusMethod::Auto, true), nullptr, t);
    bokeh::flatten(deep_out_flat, auto_deep, {}, t);
    bokeh::defocus(flat_dof, flat, with(bokeh::DefocusMethod::Auto, false), nullptr, t);
    for (size_t i = 0; i < cases.size(); ++i) {
        const Case& c = cases[i];
        if (c.frame != lr)
            continue;
        if (c.method == "flatten" && c.peer.empty())
            error_of[i] = measure(flat, oiio_flat);
        else if (c.method == "defocus deep auto")
            error_of[i] = measure(auto_flat, ref);
        else if (c.method == "defocus deep auto (deep out)")
            error_of[i] = measure(deep_out_flat, ref);
        else if (c.method == "defocus flat of the flatten (auto)")
            error_of[i] = measure(flat_dof, ref);
    }

    // Against the thin-lens truth (the layered methods with a black border: the rays see
    // nothing past the frame), over the frame and over the disocclusion mask: the pixels
    // where the truth of the deep image and the truth of its flatten differ by more than
    // 0.01, what the flat image hides.
    {
        bokeh::TruthOptions to;
        to.coc      = lens.coc;
        to.aperture = lens.aperture;
        to.spp      = args.reps >= 5 ? 256 : 64;
        OIIO::ImageBuf truth, truth_flat, flat_deep;
        bokeh::TruthReport tr;
        OIIO::Timer timer;
        const bool ok = bokeh::defocus_truth(truth, merged, to, &tr, t);
        const double truth_ms = timer() * 1e3;
        if (!ok || !bokeh::deepen(flat_deep, flat, 1.0f, t) || !bokeh::defocus_truth(truth_flat, flat_deep, to, nullptr, t)) {
            std::fprintf(stderr, "bokeh-bench: deep: truth: %s%s\n", truth.geterror().c_str(), truth_flat.geterror().c_str());
            return false;
        }
        const OIIO::ROI roi = truth.roi();
        const OIIO::ImageBuf tr4 = rgba_of(truth, roi), tf4 = rgba_of(truth_flat, roi);
        std::vector<uint8_t> mask(size_t(roi.npixels()), 0);
        int64_t in_mask = 0;
        for (int y = roi.ybegin; y < roi.yend; ++y)
            for (int x = roi.xbegin; x < roi.xend; ++x) {
                float a[4], b[4];
                tr4.getpixel(x, y, a, 4);
                tf4.getpixel(x, y, b, 4);
                bool differs = false;
                for (int c = 0; c < 4; ++c)
                    differs |= std::abs(a[c] - b[c]) > 0.01f;
                mask[size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)] = differs;
                in_mask += differs;
            }
        std::printf("truth: %d rays a pixel, %.0f ms, noise %.1f dB; disocclusion mask %lld px (%.1f %%)\n",
                    to.spp, truth_ms, tr.noise_psnr_db, (long long)in_mask, 100.0 * double(in_mask) / double(roi.npixels()));
        rows.push_back(format("deep {},truth {} spp,,0,{},{:.3f},1,,{:.2f},", lr, to.spp, t, truth_ms, tr.noise_psnr_db));
        auto vs_truth = [&](const std::string& name, const OIIO::ImageBuf& src, bokeh::DefocusMethod m) {
            bokeh::DefocusOptions o = with(m, false);
            o.border                = bokeh::Border::Black;
            OIIO::ImageBuf out;
            if (!bokeh::defocus(out, src, o, nullptr, t))
                return;
            const OIIO::ImageBuf got = rgba_of(out, roi);
            bokeh::ImageError frame, inside;
            std::string why;
            bokeh::compare(frame, got, tr4, why, {}, t);
            // The mask's error: outside it the result is set to the truth, so the mean
            // squared error over the frame is the mask's times its share of the frame.
            OIIO::ImageBuf masked = got;
            for (int y = roi.ybegin; y < roi.yend; ++y)
                for (int x = roi.xbegin; x < roi.xend; ++x)
                    if (!mask[size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)]) {
                        float v[4];
                        tr4.getpixel(x, y, v, 4);
                        masked.setpixel(x, y, v, 4);
                    }
            bokeh::compare(inside, masked, tr4, why, {}, t);
            const double share = in_mask > 0 ? double(in_mask) / double(roi.npixels()) : 1.0;
            const double mask_db = inside.psnr_db + 10.0 * std::log10(share);
            std::printf("  %-34s vs truth: frame %.2f dB, disocclusion mask %.2f dB\n", name.c_str(), frame.psnr_db, mask_db);
            rows.push_back(format("deep {},{} vs truth,,0,{},,,{}", lr, name, t, error_fields(frame)));
            rows.push_back(format("deep {},{} vs truth (mask),,0,{},,,,{:.2f},", lr, name, t, mask_db));
        };
        vs_truth("deep reference", merged, bokeh::DefocusMethod::Reference);
        vs_truth("deep auto", merged, bokeh::DefocusMethod::Auto);
        vs_truth("flat reference of the flatten", flat, bokeh::DefocusMethod::Reference);
        vs_truth("flat auto of the flatten", flat, bokeh::DefocusMethod::Auto);
    }

    std::printf("%-38s %-5s %-24s %10s %10s\n", "method", "peer", "frame", "median_ms", "psnr_db");
    for (size_t i = 0; i < cases.size(); ++i) {
        const Case& c = cases[i];
        const std::vector<std::string> f = OIIO::Strutil::splits(error_of[i], ",");
        std::printf("%-38s %-5s %-24s %10.1f %10s\n", c.method.c_str(), c.peer.c_str(), c.frame.c_str(), ms[i],
                    f.size() == 3 ? f[1].c_str() : "");
        rows.push_back(format("deep {},{},{},{},{},{:.3f},{},{}", c.frame, c.method, c.peer, 0, t, ms[i], c.reps,
                              error_of[i].empty() ? std::string(",,") : error_of[i]));
    }
    return true;
}

}  // namespace bokeh_bench
