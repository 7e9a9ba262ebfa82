// bokeh-bench — speed and accuracy of OpenBokeh's methods, side by side with peers.
//
// Each case is timed in this process on an RGBA float frame (the median of --reps runs,
// each after an untimed warm-up run, the cases' runs interleaved in shuffled rounds:
// timing.h), and its error is measured against the brute-force reference with the same
// kernel on a crop of at most 240x135 (brute force on the whole frame would take minutes
// for large kernels). Error: RMSE in linear light, PSNR after the fixed tone map
// x / (1 + x) per channel (peak 1), and the largest absolute difference (bench_common.h).
// Frames: the built-in scenes named by --scenes (default "lights", --size WxH, default
// 1920x1080; its crop is the lights, the floor and the sphere's edge at 1920x1080, else
// where brightness varies most) and each --image FILE (R, G, B and the file's alpha, or
// alpha 1; the crop where brightness varies most). A frame other than lights at 1920x1080
// names its rows' task "<shape> (<frame>)", so the chart draws it apart.
//
// --task defocus runs the depth-defocus task instead (defocus_task.cpp); --task resample
// the reduced-buffer and enlargement study (resample_task.cpp), which writes two more
// tables beside --csv FILE: <FILE stem>_artifacts.csv and <FILE stem>_figures.csv.
// --task diffraction times the fringe models of a bokeh's rim against the exact PSF
// (diffraction_task.cpp; its own CSV columns, one thread); --task optics the lens PSFs
// (optics_task.cpp); --task lens lens character's highlight sprites against the plain
// defocus (lens_task.cpp); --task truth-chain every step from the built-in scenes' geometric
// thin-lens truth to the fast methods (truth_chain_task.cpp; its own CSV columns); --task
// lensfit round trips of the lens fit, 8 x --reps random lenses (lens_fit_task.cpp; its
// own columns); --task plans the flat planner's predicted plans against measured ones
// (defocus_task.cpp; its own columns).
//
//   bokeh-bench [--task blur|defocus|resample|iris|deep|lens|truth-chain] [--threads N] [--reps N] [--csv FILE] [--quick]
//               [--size WxH] [--data DIR] [--images DIR] [--scenes a,b] [--image FILE]...

#include "bench_common.h"
#include "deep_task.h"
#include "defocus_task.h"
#include "diffraction_task.h"
#include "lens_fit_task.h"
#include "lens_task.h"
#include "gegl_peer.h"
#include "iris_task.h"
#include "optics_task.h"
#include "resample_task.h"
#include "truth_chain_task.h"
#include "timing.h"

#include <bokeh/blur.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/timer.h>

using OIIO::Strutil::fmt::format;
namespace IBA = OIIO::ImageBufAlgo;

namespace {

struct Case {
    std::string task, method, peer;  // peer: empty for ours
    double size;
    bokeh::Kernel kernel;
    bokeh::BlurOptions options;
    int reps = -1;                    // -1: the default
};

bokeh::Kernel kernel(bokeh::KernelShape s, double size, int blades = 6)
{
    bokeh::Kernel k;
    k.shape     = s;
    k.width_px  = float(size);
    k.height_px = float(size);
    k.blades    = blades;
    return k;
}

// Write the rows to `path` (none when empty); the exit status.
int write_csv(const std::string& path, const std::vector<std::string>& rows)
{
    if (path.empty())
        return 0;
    std::ofstream f(path);
    for (const std::string& r : rows)
        f << r << "\n";
    if (!f) {
        std::fprintf(stderr, "bokeh-bench: cannot write %s\n", path.c_str());
        return 1;
    }
    return 0;
}

}  // namespace

int main(int argc, char* argv[])
{
    int threads = 2, reps = 5;
    bool quick  = false;
    std::string csv, task = "blur";
    bokeh_bench::BenchArgs args;
    std::vector<std::string> image_files;  // the blur task's frames from files
    const char* usage = "usage: bokeh-bench [--task blur|defocus|resample|iris|deep|optics|diffraction|lens|lensfit|truth-chain|plans] "
                        "[--threads N] [--reps N] [--csv FILE] [--quick] [--size WxH] [--data DIR] "
                        "[--images DIR] [--scenes a,b] [--image FILE]...\n";
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--help" || a == "-h") {
            std::fputs(usage, stdout);
            std::fputs("Times the methods and their peers on this machine and writes a CSV row a case "
                       "(make bench charts them into docs/bench and docs/benchmarks.md).\n",
                       stdout);
            return 0;
        }
        if (a == "--threads" && i + 1 < argc)
            threads = std::atoi(argv[++i]);
        else if (a == "--task" && i + 1 < argc && (std::string(argv[i + 1]) == "blur"
                                                   || std::string(argv[i + 1]) == "defocus"
                                                   || std::string(argv[i + 1]) == "resample"
                                                   || std::string(argv[i + 1]) == "iris"
                                                   || std::string(argv[i + 1]) == "deep"
                                                   || std::string(argv[i + 1]) == "optics"
                                                   || std::string(argv[i + 1]) == "diffraction"
                                                   || std::string(argv[i + 1]) == "lens"
                                                   || std::string(argv[i + 1]) == "lensfit"
                                                   || std::string(argv[i + 1]) == "truth-chain"
                                                   || std::string(argv[i + 1]) == "plans"))
            task = argv[++i];
        else if (a == "--size" && i + 1 < argc
                 && std::sscanf(argv[i + 1], "%dx%d", &args.width, &args.height) == 2 && args.width > 0
                 && args.height > 0)
            ++i;
        else if (a == "--data" && i + 1 < argc)
            args.data_dir = argv[++i];
        else if (a == "--images" && i + 1 < argc) {
            args.images_dir = argv[++i];
            std::error_code why;
            std::filesystem::create_directories(args.images_dir, why);
            if (!std::filesystem::is_directory(args.images_dir)) {
                std::fprintf(stderr, "bokeh-bench: --images %s: cannot make the folder: %s\n",
                             args.images_dir.c_str(), why.message().c_str());
                return 1;
            }
        }
        else if (a == "--scenes" && i + 1 < argc)
            args.only = OIIO::Strutil::splits(argv[++i], ",");
        else if (a == "--reps" && i + 1 < argc)
            reps = std::max(1, std::atoi(argv[++i]));
        else if (a == "--csv" && i + 1 < argc)
            csv = argv[++i];
        else if (a == "--image" && i + 1 < argc)
            image_files.push_back(argv[++i]);
        else if (a == "--quick")
            quick = true;
        else {
            std::fprintf(stderr, "bokeh-bench: unknown argument '%s'\n%s", a.c_str(), usage);
            return 1;
        }
    }

    if (!image_files.empty() && task != "blur") {
        std::fprintf(stderr, "bokeh-bench: --image is for the blur task, not --task %s\n", task.c_str());
        return 1;
    }
    if (!args.only.empty() && task == "iris") {
        std::fprintf(stderr, "bokeh-bench: --scenes is not for --task iris (it runs on the lights scene's crop)\n");
        return 1;
    }
    std::vector<std::string> rows;
    if (task == "diffraction") {  // radial profiles, one thread: its own columns
        rows.push_back(bokeh_bench::kDiffractionCsvHeader);
        if (!bokeh_bench::run_diffraction_task(reps, quick, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "lensfit") {  // round trips of the lens fit: its own columns
        rows.push_back(bokeh_bench::kLensFitCsvHeader);
        if (!bokeh_bench::run_lens_fit_task(quick ? 3 : 8 * reps, threads, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "plans") {  // the flat planner's predictions against measurements: its own columns
        rows.push_back(bokeh_bench::kPlansCsvHeader);
        args.threads = threads;
        args.reps    = reps;
        if (!bokeh_bench::run_plans_task(args, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "truth-chain") {  // its own columns
        rows.push_back(bokeh_bench::kTruthChainCsvHeader);
        args.threads = threads;
        args.reps    = reps;
        if (!bokeh_bench::run_truth_chain_task(args, rows))
            return 1;
        return write_csv(csv, rows);
    }
    rows.push_back(bokeh_bench::kCsvHeader);
    if (task == "defocus") {
        args.threads = threads;
        args.reps    = reps;
        if (!bokeh_bench::run_defocus_task(args, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "optics") {
        if (!bokeh_bench::run_optics_task(threads, reps, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "lens") {
        args.threads = threads;
        args.reps    = reps;
        if (!bokeh_bench::run_lens_task(args, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "deep") {
        args.threads = threads;
        args.reps    = reps;
        if (!bokeh_bench::run_deep_task(args, rows))
            return 1;
        return write_csv(csv, rows);
    }
    if (task == "resample") {
        args.threads = threads;
        args.reps    = reps;
        std::vector<std::string> artifacts, figures;
        if (!bokeh_bench::run_resample_task(args, rows, artifacts, figures))
            return 1;
        // The extra tables beside FILE: <stem>_artifacts.csv, <stem>_figures.csv.
        auto beside = [&](const char* suffix) {
            if (csv.empty())
                return std::string();
            std::filesystem::path p(csv);
            return (p.parent_path() / (p.stem().string() + suffix)).string();
        };
        const int status = write_csv(csv, rows);
        return std::max({ status, write_csv(beside("_artifacts.csv"), artifacts),
                          write_csv(beside("_figures.csv"), figures) });
    }

    // The frames: built-in scenes, then files; each with the crop its errors are measured on.
    // A frame's rows are named "<shape> (<frame>)", but for the docs' frame (lights at
    // 1920x1080, its curated crop), whose rows keep the bare shape names.
    struct Frame {
        std::string name;
        OIIO::ImageBuf pixels, small;  // small: the crop, its origin at 0, 0 (IBA::cut)
        OIIO::ROI crop;
        bool bare = false;
    };
    std::vector<Frame> frames;
    auto unique_name = [&](std::string name) {  // no two frames' rows under one name
        const std::string base = name;
        for (int n = 2; std::any_of(frames.begin(), frames.end(), [&](const Frame& f) { return f.name == name; }); ++n)
            name = format("{} #{}", base, n);
        return name;
    };
    const std::vector<std::string> scenes = args.only.empty() ? std::vector<std::string>{ "lights" } : args.only;
    for (const std::string& name : scenes) {
        const std::vector<std::string> known = bokeh::scene_names();
        if (std::find(known.begin(), known.end(), name) == known.end()) {
            std::fprintf(stderr, "bokeh-bench: --scenes: no built-in scene '%s' (%s)\n", name.c_str(),
                         OIIO::Strutil::join(known, ", ").c_str());
            return 1;
        }
        bokeh::SceneOptions so;
        so.width  = args.width;
        so.height = args.height;
        OIIO::ImageBuf scene;
        if (!bokeh::make_scene(scene, name, so, threads)) {
            std::fprintf(stderr, "bokeh-bench: scene %s: %s\n", name.c_str(), scene.geterror().c_str());
            return 1;
        }
        const bool curated = name == "lights" && args.width == 1920 && args.height == 1080;
        Frame f{ unique_name(curated ? name : format("{} {}x{}", name, args.width, args.height)),
                 IBA::channels(scene, 4, { 0, 1, 2, 3 }), {}, {}, curated };
        f.crop  = curated ? OIIO::ROI(840, 1080, 300, 435)  // lights, floor, sphere edge
                          : bokeh_bench::most_varied_crop(f.pixels, 240, 135, threads);
        f.small = IBA::cut(f.pixels, f.crop);
        frames.push_back(std::move(f));
    }
    if (task == "iris") {
        if (!bokeh_bench::run_iris_task(frames[0].small, threads, rows))
            return 1;
        return write_csv(csv, rows);
    }
    for (const std::string& path : image_files) {
        OIIO::ImageBuf file(path);
        if (!file.read(0, 0, true, OIIO::TypeFloat)) {
            std::fprintf(stderr, "bokeh-bench: --image %s: %s\n", path.c_str(), file.geterror().c_str());
            return 1;
        }
        const int nc = file.nchannels();
        if (nc < 3 || file.deep()) {
            std::fprintf(stderr, "bokeh-bench: --image %s: needs RGB or RGBA pixels (it has %d channel%s%s)\n",
                         path.c_str(), nc, nc == 1 ? "" : "s", file.deep() ? ", deep" : "");
            return 1;
        }
        // The first three channels and the file's alpha, or alpha 1 where it has none (a plate;
        // a fourth channel that is not alpha, depth say, is not taken for it).
        const int alpha = file.spec().alpha_channel;
        Frame f{ unique_name(OIIO::Filesystem::filename(path)),
                 alpha >= 3 ? IBA::channels(file, 4, { 0, 1, 2, alpha })
                            : IBA::channels(file, 4, { 0, 1, 2, -1 }, { 0, 0, 0, 1 }),
                 {}, {}, false };
        f.crop  = bokeh_bench::most_varied_crop(f.pixels, 240, 135, threads);
        f.small = IBA::cut(f.pixels, f.crop);
        frames.push_back(std::move(f));
    }

    using S = bokeh::KernelShape;
    std::vector<Case> cases;  // error is against the exact kernel of the case's shape
    auto ours = [&](std::string task, std::string method, double size, bokeh::Kernel k,
                    bokeh::BlurMethod m = bokeh::BlurMethod::Auto) {
        Case c{ std::move(task), std::move(method), "", size, k, {} };
        c.options.method = m;
        cases.push_back(c);
    };
    const std::vector<double> sizes = quick ? std::vector<double>{ 15, 63 }
                                            : std::vector<double>{ 15, 31, 63, 127, 255 };
    using M = bokeh::BlurMethod;
    for (double d : sizes) {
        ours("box", "running sums", d, kernel(S::Box, d));
        ours("disk", "row spans (exact)", d, kernel(S::Disk, d), M::Spans);
        ours("disk", "FFT tiles (exact)", d, kernel(S::Disk, d), M::Fft);
        for (int bands : { 4, 6, 8, 16 }) {
            ours("disk", format("{} bands (running sums)", bands), d, kernel(S::Disk, d), M::Bands);
            cases.back().options.bands = bands;
        }
        ours("disk", "FFT (image kernel)", d, kernel(S::Disk, d));
        // The reduced buffer at its automatic factor N = D / 25 (1 below 37.5 px: exact).
        ours("disk", "reduced 1/N (bilinear)", d, kernel(S::Disk, d), M::Reduced);
        // What `method=fast` chooses: the cheapest method at >= 40 dB by the cost models.
        ours("disk", "fast (the tool's choice)", d, kernel(S::Disk, d), M::Fast);
        ours("hexagon", "row spans (exact)", d, kernel(S::Polygon, d), M::Spans);
        ours("hexagon", "FFT tiles (exact)", d, kernel(S::Polygon, d), M::Fft);
        ours("hexagon", "3 parallelograms", d, kernel(S::Polygon, d), M::Parallelograms);
        // Flat-topped: the sweep reads rows, where the upright hexagon's reads columns.
        bokeh::Kernel flat = kernel(S::Polygon, d);
        flat.rotation_deg  = 30.0f;
        ours("hexagon", "3 parallelograms (flat top)", d, flat, M::Parallelograms);
        // Any other rotation: the sweep in a sheared frame, transposed at 7 degrees (the
        // segment near the columns sheared upright), as given at 25 (the one near the rows;
        // the cost model changes frame at ~21 degrees).
        for (float degrees : { 7.0f, 25.0f }) {
            bokeh::Kernel turned = kernel(S::Polygon, d);
            turned.rotation_deg  = degrees;
            ours("hexagon", "3 parallelograms (" + std::to_string(int(degrees)) + " degrees)", d, turned,
                 M::Parallelograms);
        }
        ours("hexagon", "reduced 1/N (bilinear)", d, kernel(S::Polygon, d), M::Reduced);
        ours("hexagon", "fast (the tool's choice)", d, kernel(S::Polygon, d), M::Fast);
        bokeh::Kernel g = kernel(S::Gaussian, d);
        ours("gaussian", "separable (exact)", d, g, M::Separable);
        ours("gaussian", "FFT tiles (exact)", d, g, M::Fft);
        ours("gaussian", "3 boxes (fast)", d, g, M::ThreeBoxes);
    }
    for (double d : { 9.0, 17.0 })
        ours("disk", "Kawase bilinear taps", d, kernel(S::Disk, d), M::BilinearTaps);
    // The peer in the same run: OIIO's brute-force convolution with make_kernel("disk").
    for (double d : quick ? std::vector<double>{ 9 } : std::vector<double>{ 9, 31 }) {
        Case c{ "disk", "OIIO IBA::convolve (hard disk)", "oiio", d, kernel(S::Disk, d), {} };
        c.kernel.edge = bokeh::KernelEdge::Hard;
        c.reps        = std::min(reps, 3);  // seconds a run: the median of 3, as the GEGL peer
        cases.push_back(c);
    }

    // GEGL's gegl:lens-blur at radius 30 is a hard disk 61 pixels across (see
    // gegl_peer.h): it and our exact hard disk are measured against that kernel.
    if (bokeh_bench::gegl_available()) {
        bokeh::Kernel hard = kernel(S::Disk, 61);
        hard.edge          = bokeh::KernelEdge::Hard;
        ours("disk hard", "row spans (exact)", 61, hard, M::Spans);
        ours("disk hard", "8 bands (running sums)", 61, hard, M::Bands);
        Case c{ "disk hard", "GEGL gegl:lens-blur radius 30", "gegl", 61, hard, {} };
        c.reps = std::min(reps, 3);
        cases.push_back(c);
    } else {
        std::printf("(GEGL not built in: the gegl:lens-blur peer is left out)\n");
    }

    for (const Frame& fr : frames) {
        const OIIO::ImageBuf &frame = fr.pixels, &small = fr.small;
        // The lights scene keeps the bare task names (the docs' charts); other frames are
        // charted apart. (No comma: the CSV is unquoted.)
        const std::string suffix = fr.bare ? "" : " (" + OIIO::Strutil::replace(fr.name, ",", " ", true) + ")";
        const OIIO::ROI& crop = fr.crop;
        std::printf("\n%s: %dx%d; errors on the %dx%d crop at (%d, %d)\n", fr.name.c_str(), frame.spec().width,
                    frame.spec().height, crop.width(), crop.height(), crop.xbegin, crop.ybegin);
        // Per case: how a run on the frame is timed, and its error on the crop, measured once.
        std::vector<std::function<void()>> runs;
        std::vector<int> nreps;
        std::vector<bool> warm_each;  // a warm-up before each timed run, every case alike
        std::vector<bokeh::ImageError> errors;
        for (const Case& c : cases) {
            OIIO::ImageBuf result_small;
            if (c.peer == "gegl") {
                auto run = [threads, size = c.size](const OIIO::ImageBuf& in, OIIO::ImageBuf& out) {
                    out.reset(in.spec());
                    std::string err;
                    if (!bokeh_bench::gegl_lens_blur(static_cast<const float*>(in.localpixels()),
                                                     in.spec().width, in.spec().height,
                                                     0.5f * float(size - 1), threads,
                                                     static_cast<float*>(out.localpixels()), &err)) {
                        std::fprintf(stderr, "bokeh-bench: GEGL: %s\n", err.c_str());
                        std::exit(1);
                    }
                };
                runs.push_back([run, &frame] {
                    OIIO::ImageBuf out;
                    run(frame, out);
                });
                run(small, result_small);
                result_small.set_origin(small.spec().x, small.spec().y);
            } else if (c.peer == "oiio") {
                const OIIO::ImageBuf k = IBA::make_kernel("disk", float(c.size), float(c.size));
                runs.push_back([k, &frame, threads] {
                    OIIO::ImageBuf out;
                    IBA::convolve(out, frame, k, true, {}, threads);
                });
                IBA::convolve(result_small, small, k, true, {}, threads);
            } else if (c.method.rfind("FFT (image", 0) == 0) {
                // The exact kernel handed over as an image, as a user's aperture image would be.
                const bokeh::KernelWeights kw = bokeh::kernel_weights(c.kernel);
                OIIO::ImageSpec ks(2 * kw.rx + 1, 2 * kw.ry + 1, 1, OIIO::TypeFloat);
                ks.x = -kw.rx;
                ks.y = -kw.ry;
                OIIO::ImageBuf kimg(ks);
                for (int dy = -kw.ry; dy <= kw.ry; ++dy)
                    for (int dx = -kw.rx; dx <= kw.rx; ++dx) {
                        const float v = float(kw.at(dx, dy));
                        kimg.setpixel(dx, dy, &v, 1);
                    }
                runs.push_back([kimg, opts = c.options, &frame, threads] {
                    OIIO::ImageBuf out;
                    bokeh::convolve_image(out, frame, kimg, opts, {}, threads);
                });
                bokeh::convolve_image(result_small, small, kimg, c.options, {}, threads);
            } else {
                runs.push_back([k = c.kernel, opts = c.options, &frame, threads] {
                    OIIO::ImageBuf out;
                    bokeh::blur(out, frame, k, opts, {}, threads);
                });
                bokeh::blur(result_small, small, c.kernel, c.options, {}, threads);
            }
            nreps.push_back(c.reps > 0 ? c.reps : reps);
            warm_each.push_back(true);
            OIIO::ImageBuf ref;
            bokeh::convolve_reference(ref, small, bokeh::kernel_weights(c.kernel), {}, {}, threads);
            bokeh::ImageError e;
            std::string err;
            bokeh::compare(e, result_small, ref, err, {}, threads);
            errors.push_back(e);
        }
        std::printf("timing %zu cases in interleaved rounds ...\n", runs.size());
        std::fflush(stdout);
        const std::vector<double> ms = bokeh_bench::interleaved_medians_ms(runs, nreps, warm_each);

        std::printf("%-9s %-32s %6s %10s %12s %10s %12s\n", "task", "method", "size", "median ms",
                    "RMSE", "PSNR dB", "max error");
        for (size_t i = 0; i < cases.size(); ++i) {
            const Case& c = cases[i];
            std::printf("%-9s %-32s %6.0f %10.2f %12.3g %10.1f %12.3g\n", c.task.c_str(), c.method.c_str(),
                        c.size, ms[i], errors[i].rmse_linear, errors[i].psnr_db, errors[i].max_abs);
            rows.push_back(format("{}{},{},{},{},{},{:.3f},{},{}", c.task, suffix, c.method, c.peer, c.size,
                                  threads, ms[i], nreps[i], bokeh_bench::error_fields(errors[i])));
        }
    }
    return write_csv(csv, rows);
}
