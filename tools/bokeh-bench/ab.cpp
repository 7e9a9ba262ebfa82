// bokeh-ab — a speed change measured A/B in one process: two builds of libOpenBokeh (the
// old one, say a worktree built at the previous commit, and the new one) are loaded side
// by side (dlopen, RTLD_LOCAL | RTLD_DEEPBIND, so each resolves its own symbols), and
// bokeh::blur is called through each in turn, alternating, on the same frame. On a shared
// machine whose speed drifts by +-30 % from one minute to the next, only such interleaved
// medians compare two versions; separate runs do not (docs/benchmarks.md).
//
//   bokeh-ab OLD.so NEW.so [--threads N] [--reps N] [--channels N] [--image FILE] [--iris K] CASE...
//   CASE: kernel:size[@rotation][:method[:N]]  kernel: box gaussian disk hex; method: auto exact fast
//         bands parallelograms reduced; N: the bands, or the reduction
//
// --iris K: every case in iris mode (BlurOptions::iris; `fast` is then the exact method).
// Prints per case the two medians (ms), new / old, the minimums and the largest absolute
// difference between the two results. The frame is 1920x1080 uniform noise in [0, 1], or
// the image given. Both builds must agree on blur.h's structs (fields are only appended)
// and on what their defaults mean: a library older than BlurOptions::bands = 0 ("the
// method's choice") refuses 0, so A/B against one names the count (:N).
#include <bokeh/blur.h>

#include <dlfcn.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace {

using BlurFn = bool (*)(OIIO::ImageBuf&, const OIIO::ImageBuf&, const bokeh::Kernel&,
                        const bokeh::BlurOptions&, OIIO::ROI, int);

int usage(const char* why)
{
    std::fprintf(stderr,
                 "bokeh-ab: %s\nusage: bokeh-ab OLD.so NEW.so [--threads N] [--reps N] "
                 "[--channels N] [--image FILE] [--iris K] kernel:size[@rotation][:method[:N]]...\n",
                 why);
    return 1;
}

BlurFn load(const char* path)
{
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_DEEPBIND);
    if (!lib) {
        std::fprintf(stderr, "bokeh-ab: %s\n", dlerror());
        return nullptr;
    }
    // bokeh::blur(ImageBuf&, const ImageBuf&, const Kernel&, const BlurOptions&, ROI, int),
    // mangled (Itanium ABI) with this OpenImageIO's namespace.
    const std::string ns = OIIO_NAMESPACE_STRING;
    const std::string name = "_ZN5bokeh4blurERN" + std::to_string(ns.size()) + ns
                             + "8ImageBufERKS1_RKNS_6KernelERKNS_11BlurOptionsENS0_3ROIEi";
    void* fn = dlsym(lib, name.c_str());
    if (!fn)
        std::fprintf(stderr, "bokeh-ab: %s: no bokeh::blur (%s)\n", path, dlerror());
    return reinterpret_cast<BlurFn>(fn);
}

bool parse_case(const std::string& text, bokeh::Kernel& k, bokeh::BlurOptions& o)
{
    using S = bokeh::KernelShape;
    using M = bokeh::BlurMethod;
    static const std::map<std::string, S> shapes{ { "box", S::Box }, { "gaussian", S::Gaussian },
                                                  { "disk", S::Disk }, { "hex", S::Polygon } };
    static const std::map<std::string, M> methods{ { "auto", M::Auto },
                                                   { "exact", M::Exact },
                                                   { "fast", M::Fast },
                                                   { "bands", M::Bands },
                                                   { "parallelograms", M::Parallelograms },
                                                   { "reduced", M::Reduced },
                                                   { "spans", M::Spans },
                                                   { "fft", M::Fft },
                                                   { "separable", M::Separable } };
    const std::vector<std::string> f = OIIO::Strutil::splits(text, ":");
    if (f.size() < 2 || f.size() > 4 || !shapes.count(f[0])
        || (f.size() > 2 && !methods.count(f[2])))
        return false;
    k.shape    = shapes.at(f[0]);
    k.blades   = 6;
    // SIZE[@DEGREES]: the kernel's rotation after '@'.
    const std::vector<std::string> size = OIIO::Strutil::splits(f[1], "@");
    k.width_px = k.height_px = OIIO::Strutil::stof(size[0]);
    if (size.size() > 1)
        k.rotation_deg = OIIO::Strutil::stof(size[1]);
    o.method   = f.size() > 2 ? methods.at(f[2]) : M::Auto;
    if (f.size() > 3) {
        o.bands     = OIIO::Strutil::stoi(f[3]);
        o.reduction = OIIO::Strutil::stof(f[3]);
    }
    return k.width_px > 0.0f;
}

double median(std::vector<double> t)
{
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

}  // namespace

int main(int argc, char** argv)
{
    if (argc < 4)
        return usage("two libraries and at least one case");
    int threads = 2, reps = 15, channels = 4;
    float iris = 0.0f;
    std::string image;
    std::vector<std::string> cases;
    for (int i = 3; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--threads" && i + 1 < argc)
            threads = std::atoi(argv[++i]);
        else if (a == "--reps" && i + 1 < argc)
            reps = std::max(1, std::atoi(argv[++i]));
        else if (a == "--channels" && i + 1 < argc)
            channels = std::atoi(argv[++i]);
        else if (a == "--image" && i + 1 < argc)
            image = argv[++i];
        else if (a == "--iris" && i + 1 < argc)
            iris = float(std::atof(argv[++i]));
        else
            cases.push_back(a);
    }
    const BlurFn fn[2] = { load(argv[1]), load(argv[2]) };
    if (!fn[0] || !fn[1])
        return 1;
    OIIO::ImageBuf src;
    if (!image.empty()) {
        src = OIIO::ImageBuf(image);
        if (!src.read(0, 0, true, OIIO::TypeFloat)) {
            std::fprintf(stderr, "bokeh-ab: %s: %s\n", image.c_str(), src.geterror().c_str());
            return 1;
        }
    } else {
        if (channels < 1 || channels > 4)
            return usage("--channels is 1..4");
        src.reset(OIIO::ImageSpec(1920, 1080, channels, OIIO::TypeFloat));
        OIIO::ImageBufAlgo::noise(src, "uniform", 0.0f, 1.0f);
    }
    std::vector<std::pair<bokeh::Kernel, bokeh::BlurOptions>> parsed(cases.size());
    for (size_t i = 0; i < cases.size(); ++i) {
        if (!parse_case(cases[i], parsed[i].first, parsed[i].second))
            return usage(("bad case '" + cases[i] + "'").c_str());
        parsed[i].second.iris = iris;
    }
    std::printf("%-24s %9s %9s %9s %9s %9s %10s\n", "case", "old ms", "new ms", "new/old",
                "old min", "new min", "max |diff|");
    for (size_t i = 0; i < cases.size(); ++i) {
        const std::string& c        = cases[i];
        const auto& [k, o]          = parsed[i];
        std::vector<double> t[2];
        OIIO::ImageBuf out[2];
        for (int r = 0; r <= reps; ++r)  // the first round warms up
            for (int v = 0; v < 2; ++v) {
                const auto t0 = std::chrono::steady_clock::now();
                if (!fn[v](out[v], src, k, o, {}, threads)) {
                    std::fprintf(stderr, "bokeh-ab: %s: %s\n", c.c_str(), out[v].geterror().c_str());
                    return 1;
                }
                const std::chrono::duration<double, std::milli> dt = std::chrono::steady_clock::now() - t0;
                if (r > 0)
                    t[v].push_back(dt.count());
            }
        const auto diff = OIIO::ImageBufAlgo::compare(out[0], out[1], 0.0f, 0.0f);
        std::printf("%-24s %9.2f %9.2f %9.3f %9.2f %9.2f %10.3g\n", c.c_str(), median(t[0]),
                    median(t[1]), median(t[1]) / median(t[0]), *std::min_element(t[0].begin(), t[0].end()),
                    *std::min_element(t[1].begin(), t[1].end()), double(diff.maxerror));
    }
    return 0;
}
