// deep_task.cpp — bokeh-bench's deep task: the deep nodes and the deep defocus on real
// deep renders, side by side with OpenImageIO's deep functions in the same run.
//
// Frames: the three LowResLeftView passes (Weta, 1024x576, point samples; merged: up to 6
// samples a pixel) and Gaffer's representativeDeepImage (150x100, volumes only, up to 227
// samples a pixel). Every case is timed in interleaved rounds (timing.h), medians.
// Errors: our flatten against OIIO's where OIIO is exact (tidy, sorted input), the merge's
// flatten against OIIO's merge's (OIIO culls hidden samples, which a flatten cannot see),
// each defocus against the deep reference (one full-resolution layer per CoC step), and,
// on both frames, every defocus method (deep and of the flatten, timed; the deep ones also
// in sub-aperture views, layers=30 views=2 and the reference in 4 x 4) against the
// thin-lens truth over the frame and over the disocclusion mask ("vs truth" rows; chart.py
// draws them); with --images, deep_sheet.png shows LowResLeftView's results beside it.

#include "deep_task.h"
#include "bench_common.h"
#include "timing.h"

#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/io.h>
#include <bokeh/metrics.h>
#include <bokeh/truth.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

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


// A deep frame measured against its thin-lens truth.
struct TruthShot {
    std::string name;                   // the frame, as the CSV's task names it
    const OIIO::ImageBuf* deep = nullptr;
    const OIIO::ImageBuf* flat = nullptr;  // its flatten
    bokeh::DefocusOptions lens;
};

// What the picture sheet shows: the truth, the disocclusion mask over it, each method's
// result (RGBA over the truth's region) with its PSNR over the frame and the mask.
struct TruthPictures {
    OIIO::ImageBuf truth;
    std::vector<uint8_t> mask;  // per pixel of truth.roi()
    int spp = 0;
    struct Result {
        std::string name;
        OIIO::ImageBuf image;
        double frame_db = 0.0, mask_db = 0.0, held_db = 0.0;
    };
    std::vector<Result> results;
};

// The truth of `shot` and every method against it (the layered methods with a black
// border: the rays see nothing past the frame), over the frame, over the disocclusion
// mask (the pixels where the truth of the deep image and the truth of its flatten differ
// by more than 0.01, what the flat image hides) and over the held pixels (the truth's
// `unknown` 0: no ray of theirs crosses space the file does not record, behind an opaque
// pixel or past the frame). A second truth with another seed gives the floor over each.
// Each method is timed (its median with that border) so the CSV's rows put accuracy
// against time. False + message on stderr.
bool against_truth(const TruthShot& shot, const BenchArgs& args, std::vector<std::string>& rows, TruthPictures& pic)
{
    const int t = args.threads;
    bokeh::TruthOptions to;
    to.coc      = shot.lens.coc;
    to.aperture = shot.lens.aperture;
    to.spp      = args.reps >= 5 ? 256 : 64;
    to.unknown  = true;
    pic.spp     = to.spp;
    OIIO::ImageBuf truth_flat, flat_deep, truth_seed2;
    bokeh::TruthReport tr;
    const bool ok = bokeh::defocus_truth(pic.truth, *shot.deep, to, &tr, t);  // untimed: timed below
    bokeh::TruthOptions same = to, other = to;  // the flatten's truth draws the same rays
    same.unknown = other.unknown = false;
    other.seed                   = to.seed + 1;
    if (!ok || !bokeh::deep_from_flat(flat_deep, *shot.flat, 1.0f, t) || !bokeh::defocus_truth(truth_flat, flat_deep, same, nullptr, t)
        || !bokeh::defocus_truth(truth_seed2, *shot.deep, other, nullptr, t)) {
        std::fprintf(stderr, "bokeh-bench: deep: %s: truth: %s%s%s\n", shot.name.c_str(), pic.truth.geterror().c_str(),
                     truth_flat.geterror().c_str(), truth_seed2.geterror().c_str());
        return false;
    }
    OIIO::ROI roi = pic.truth.roi();
    roi.chbegin   = 0;
    roi.chend     = 4;  // R, G, B, A (the truth's fifth channel is `unknown`)
    const OIIO::ImageBuf tr4 = rgba_of(pic.truth, roi), tf4 = rgba_of(truth_flat, roi);
    pic.mask.assign(size_t(roi.npixels()), 0);
    std::vector<uint8_t> held(size_t(roi.npixels()), 0);
    int64_t in_mask = 0, in_held = 0;
    for (int y = roi.ybegin; y < roi.yend; ++y)
        for (int x = roi.xbegin; x < roi.xend; ++x) {
            float a[5], b[4];
            pic.truth.getpixel(x, y, a, 5);
            tf4.getpixel(x, y, b, 4);
            bool differs = false;
            for (int c = 0; c < 4; ++c)
                differs |= std::abs(a[c] - b[c]) > 0.01f;
            const size_t i = size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin);
            pic.mask[i]    = differs;
            held[i]        = a[4] == 0.0f;
            in_mask += differs;
            in_held += held[i];
        }
    std::printf("%s: truth: %d rays a pixel, CoC %.1f .. %.1f px, noise %.1f dB; disocclusion mask %lld px "
                "(%.1f %%); held %lld px (%.1f %%)\n",
                shot.name.c_str(), to.spp, tr.min_coc_px, tr.max_coc_px, tr.noise_psnr_db, (long long)in_mask,
                100.0 * double(in_mask) / double(roi.npixels()), (long long)in_held,
                100.0 * double(in_held) / double(roi.npixels()));
    std::vector<std::pair<const char*, double>> floor_db;  // its rows go after the timing, below
    {  // the floor over each set of pixels: two truths' difference (3 dB below one truth's noise)
        const OIIO::ImageBuf s2 = rgba_of(truth_seed2, roi);
        std::vector<uint8_t> all(held.size(), 1);
        const double f = masked_psnr(s2, tr4, all, roi, t), m = masked_psnr(s2, tr4, pic.mask, roi, t),
                     h = masked_psnr(s2, tr4, held, roi, t);
        std::printf("  %-30s vs truth: frame %.2f dB, disocclusion mask %.2f dB, held %.2f dB\n",
                    "another seed's truth", f, m, h);
        floor_db = { { "", f }, { " (mask)", m }, { " (held)", h } };
    }

    struct Method {
        std::string name;
        const OIIO::ImageBuf* src;
        bokeh::DefocusMethod method;
        int layers = 0, views = 0;  // DefocusOptions::layers, aperture_views (0: the planner's)
    };
    const std::vector<Method> methods = {
        { "deep reference", shot.deep, bokeh::DefocusMethod::Reference },
        { "deep auto", shot.deep, bokeh::DefocusMethod::Auto },
        { "deep auto views=1", shot.deep, bokeh::DefocusMethod::Auto, 0, 1 },
        { "deep layers=30 views=2", shot.deep, bokeh::DefocusMethod::Layers, 30, 2 },
        { "deep reference views=4", shot.deep, bokeh::DefocusMethod::Reference, 0, 4 },
        { "flat reference of the flatten", shot.flat, bokeh::DefocusMethod::Reference },
        { "flat auto of the flatten", shot.flat, bokeh::DefocusMethod::Auto },
    };
    std::vector<OIIO::ImageBuf> outs(methods.size());
    std::vector<std::function<void()>> fns;
    std::vector<int> reps;
    std::vector<bool> warm;
    for (size_t i = 0; i < methods.size(); ++i) {
        bokeh::DefocusOptions o = shot.lens;
        o.method                = methods[i].method;
        o.layers                = methods[i].layers;
        o.aperture_views        = methods[i].views;
        o.border                = bokeh::Border::Black;
        fns.push_back([&, o, i] {
            if (!bokeh::defocus(outs[i], *methods[i].src, o, nullptr, t))
                std::fprintf(stderr, "bokeh-bench: deep: %s: %s\n", methods[i].name.c_str(), outs[i].geterror().c_str());
        });
        const bool reference = methods[i].method == bokeh::DefocusMethod::Reference;
        reps.push_back(reference ? std::min(args.reps, 3) : args.reps);  // seconds a run: the median of 3
        warm.push_back(true);
    }
    // The truth too, its time the median of 3 as the references' (the first run above made
    // its pixels, untimed).
    fns.push_back([&] {
        OIIO::ImageBuf again;
        bokeh::defocus_truth(again, *shot.deep, to, nullptr, t);
    });
    reps.push_back(std::min(args.reps, 3));
    warm.push_back(true);
    const std::vector<double> ms = interleaved_medians_ms(fns, reps, warm);
    const double truth_ms = ms.back();
    rows.push_back(format("deep {},truth {} spp,,0,{},{:.3f},{},,{:.2f},", shot.name, to.spp, t, truth_ms, reps.back(),
                          tr.noise_psnr_db));
    for (const auto& [suffix, db] : floor_db)
        rows.push_back(format("deep {},another seed's truth vs truth{},,0,{},{:.3f},{},,{:.2f},", shot.name, suffix, t,
                              truth_ms, reps.back(), db));
    for (size_t i = 0; i < methods.size(); ++i) {
        if (!outs[i].initialized())
            return false;
        const OIIO::ImageBuf got = rgba_of(outs[i], roi);
        bokeh::ImageError frame;
        std::string why;
        bokeh::compare(frame, got, tr4, why, {}, t);
        const double mask_db = masked_psnr(got, tr4, pic.mask, roi, t), held_db = masked_psnr(got, tr4, held, roi, t);
        std::printf("  %-30s %9.0f ms  vs truth: frame %.2f dB, disocclusion mask %.2f dB, held %.2f dB\n",
                    methods[i].name.c_str(), ms[i], frame.psnr_db, mask_db, held_db);
        rows.push_back(format("deep {},{} vs truth,,0,{},{:.3f},{},{}", shot.name, methods[i].name, t, ms[i], reps[i],
                              error_fields(frame)));
        rows.push_back(format("deep {},{} vs truth (mask),,0,{},{:.3f},{},,{:.2f},", shot.name, methods[i].name, t, ms[i],
                              reps[i], mask_db));
        rows.push_back(format("deep {},{} vs truth (held),,0,{},{:.3f},{},,{:.2f},", shot.name, methods[i].name, t, ms[i],
                              reps[i], held_db));
        pic.results.push_back({ methods[i].name, got, frame.psnr_db, mask_db, held_db });
    }
    return true;
}

// The w x h window (inside `roi`) holding the most pixels of `mask`, searched on a 4-pixel
// grid by a summed-area table.
OIIO::ROI densest_window(const std::vector<uint8_t>& mask, const OIIO::ROI& roi, int w, int h)
{
    const int W = roi.width(), H = roi.height();
    w = std::min(w, W), h = std::min(h, H);
    std::vector<int64_t> sat(size_t(W + 1) * size_t(H + 1), 0);
    auto at = [&](int x, int y) -> int64_t& { return sat[size_t(y) * size_t(W + 1) + size_t(x)]; };
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
            at(x + 1, y + 1) = mask[size_t(y) * size_t(W) + size_t(x)] + at(x, y + 1) + at(x + 1, y) - at(x, y);
    int64_t best = -1;
    int bx = 0, by = 0;
    for (int y = 0; y + h <= H; y += 4)
        for (int x = 0; x + w <= W; x += 4) {
            const int64_t n = at(x + w, y + h) - at(x, y + h) - at(x + w, y) + at(x, y);
            if (n > best)
                best = n, bx = x, by = y;
        }
    return OIIO::ROI(roi.xbegin + bx, roi.xbegin + bx + w, roi.ybegin + by, roi.ybegin + by + h);
}

// The picture sheet of a frame against its truth (bench_common's write_sheet): a crop of
// 256 x 144 where the disocclusion mask is densest, magnified 2x with nearest so pixels
// show; linear premultiplied RGB clamped to 0..1 and encoded sRGB, the same for every tile.
// Tiles: the truth, the mask (red over the dimmed truth), each method with its PSNR.
bool write_truth_sheet(const std::string& path, const TruthPictures& pic, int threads, std::string& err)
{
    const OIIO::ROI roi  = pic.truth.roi();
    const OIIO::ROI crop = densest_window(pic.mask, roi, 256, 144);
    constexpr int magnify = 2;
    auto display = [&](const OIIO::ImageBuf& img) {
        OIIO::ROI c = crop;
        c.chbegin = 0, c.chend = 3;
        OIIO::ImageBuf rgb = IBA::cut(img, c, threads);
        rgb                = IBA::clamp(rgb, 0.0f, 1.0f, false, {}, threads);
        return IBA::colorconvert(rgb, "linear", "sRGB", false, "", "", nullptr, {}, threads);
    };
    auto magnified = [&](const OIIO::ImageBuf& tile) {
        return IBA::resize(tile, "box", 0.0f,
                           OIIO::ROI(0, crop.width() * magnify, 0, crop.height() * magnify, 0, 1, 0, 3), threads);
    };
    std::vector<std::pair<std::string, OIIO::ImageBuf>> tiles;
    const OIIO::ImageBuf truth = display(pic.truth);
    tiles.emplace_back(format("truth ({} rays a pixel)", pic.spp), magnified(truth));
    OIIO::ImageBuf mask = IBA::mul(truth, 0.35f, {}, threads);
    int64_t n = 0;
    for (int y = 0; y < crop.height(); ++y)
        for (int x = 0; x < crop.width(); ++x)
            if (pic.mask[size_t(crop.ybegin + y - roi.ybegin) * size_t(roi.width()) + size_t(crop.xbegin + x - roi.xbegin)]) {
                const float red[3] = { 1.0f, 0.25f, 0.2f };
                mask.setpixel(mask.xbegin() + x, mask.ybegin() + y, red, 3);
                ++n;
            }
    tiles.emplace_back(format("disocclusion mask ({:.0f} % here)", 100.0 * double(n) / double(crop.npixels())),
                       magnified(mask));
    for (const TruthPictures::Result& r : pic.results)
        tiles.emplace_back(format("{}: {:.1f} / {:.1f} dB", r.name, r.frame_db, r.mask_db), magnified(display(r.image)));
    std::printf("%s: crop %dx%d at (%d, %d), %dx; labels: PSNR vs truth over the frame / the mask\n", path.c_str(),
                crop.width(), crop.height(), crop.xbegin, crop.ybegin, magnify);
    return write_sheet(path, tiles, 3, threads, err);
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
    if (!bokeh::deep_merge(merged, { &pass[0], &pass[1], &pass[2] }, false, {}, nullptr, t)
        || !bokeh::deep_flatten(flat, merged, {}, nullptr, t)) {
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
    add("merge 3 passes", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_merge(d, { &pass[0], &pass[1], &pass[2] }, false, {}, nullptr, t); }, args.reps);
    add("merge 3 passes (cull)", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_merge(d, { &pass[0], &pass[1], &pass[2] }, true, {}, nullptr, t); }, args.reps);
    add("merge 3 passes (cull)", "oiio", lr, [&] {
        OIIO::ImageBuf ab = IBA::deep_merge(pass[0], pass[1], true, {}, t);
        OIIO::ImageBuf abc = IBA::deep_merge(ab, pass[2], true, {}, t);
    }, args.reps);
    add("tidy", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_tidy(d, merged, {}, nullptr, t); }, args.reps);
    add("flatten", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_flatten(d, merged, {}, nullptr, t); }, args.reps);
    add("flatten", "oiio", lr, [&] { OIIO::ImageBuf d = IBA::flatten(merged, {}, t); }, args.reps);
    add("holdout by Leaves", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_holdout(d, merged, pass[1], {}, nullptr, t); }, args.reps);
    add("holdout by Leaves", "oiio", lr, [&] { OIIO::ImageBuf d = IBA::deep_holdout(merged, pass[1], {}, t); }, args.reps);
    add("slice 200..600", "", lr, [&] { OIIO::ImageBuf d; bokeh::deep_slice(d, merged, 200.0, 600.0, {}, nullptr, t); }, args.reps);
    add("defocus deep auto", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, merged, with(bokeh::DefocusMethod::Auto, false), nullptr, t); }, args.reps);
    add("defocus deep auto (deep out)", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, merged, with(bokeh::DefocusMethod::Auto, true), nullptr, t); }, args.reps);
    add("defocus flat of the flatten (auto)", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, flat, with(bokeh::DefocusMethod::Auto, false), nullptr, t); }, args.reps);
    add("defocus deep reference", "", lr, [&] { OIIO::ImageBuf d; bokeh::defocus(d, merged, with(bokeh::DefocusMethod::Reference, false), nullptr, t); }, std::min(args.reps, 3));
    if (have_rep) {
        add("tidy", "", "representativeDeepImage", [&] { OIIO::ImageBuf d; bokeh::deep_tidy(d, rep_img, {}, nullptr, t); }, args.reps);
        add("flatten", "", "representativeDeepImage", [&] { OIIO::ImageBuf d; bokeh::deep_flatten(d, rep_img, {}, nullptr, t); }, args.reps);
        add("flatten", "oiio", "representativeDeepImage", [&] { OIIO::ImageBuf d = IBA::flatten(rep_img, {}, t); }, args.reps);
    }
    std::vector<std::function<void()>> fns;
    std::vector<int> reps;
    std::vector<bool> warm;
    for (const Case& c : cases) {
        fns.push_back(c.run);
        reps.push_back(c.reps);
        warm.push_back(true);
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
    bokeh::deep_flatten(deep_out_flat, auto_deep, {}, nullptr, t);
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

    // Against the thin-lens truth: LowResLeftView with the defocus cases' lens, and
    // representativeDeepImage (Z 2.8 .. 10.8, units not stated) read as decimetres, a
    // 0.3 .. 1.1 m table-top scene, 50 mm f/2 focused at 0.55 m (its median sample depth):
    // CoCs about -10 .. +5 px on its 150 px width.
    {
        TruthShot lrv{ lr, &merged, &flat, lens };
        TruthPictures pic;
        if (!against_truth(lrv, args, rows, pic))
            return false;
        if (!args.images_dir.empty() && !write_truth_sheet(args.images_dir + "/deep_sheet.png", pic, t, err)) {
            std::fprintf(stderr, "bokeh-bench: %s\n", err.c_str());
            return false;
        }
    }
    if (have_rep) {
        OIIO::ImageBuf rep_flat;
        if (!bokeh::deep_flatten(rep_flat, rep_img, {}, nullptr, t)) {
            std::fprintf(stderr, "bokeh-bench: deep: %s\n", rep_flat.geterror().c_str());
            return false;
        }
        TruthShot rep{ "representativeDeepImage", &rep_img, &rep_flat, {} };
        rep.lens.coc.lens.focal_mm       = 50.0;
        rep.lens.coc.lens.fstop          = 2.0;
        rep.lens.coc.lens.depth_unit_mm  = 100.0;
        rep.lens.coc.lens.focus_distance = 5.5;
        TruthPictures pic;
        if (!against_truth(rep, args, rows, pic))
            return false;
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
