// Determinism: every command family gives bit-identical output for --threads 1, 2 and 8.
//
// Each family is one bokehtool command line that makes many outputs from small inputs
// (a 96x64 scene, a 40x30 deep image with points and volumes, a colour kernel picture),
// run once per thread count; outputs are written as float (-d float, so no difference can
// hide in half rounding) and compared bit by bit, sample by sample for deep ones. The
// library splits work in chunks whose bounds do not depend on the thread count
// (include/bokeh/parallel.h); this checks that every command keeps to it, the plugins'
// own work included. On this 2-core machine TBB runs at most 2 threads at once; 8 still
// changes the arenas the work is given to, and the scheduling.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/strutil.h>

#include <bokeh/scene.h>

#include "test_util.h"

using namespace bokeh_test;
using OIIO::Strutil::fmt::format;

namespace {

struct Output {
    std::string input, command, name;  // `input command -o name.exr`
};

// The deep input: 40 x 30 pixels of 0..4 samples, points and volumes that overlap and
// coincide, so tidy splits and merges; alphas 0..1.
OIIO::ImageBuf deep_input(int seed)
{
    std::vector<DeepPixel> px;
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 40; ++x) {
            DeepPixel p;
            const int n = (x * 3 + y * 5 + seed) % 5;
            for (int s = 0; s < n; ++s) {
                const double z  = 1.0 + ((x + 2 * s + seed) % 7) * 0.5 + y * 0.02;
                const double zb = (s + x + seed) % 3 == 0 ? z : z + 0.25 * (1 + (y + s) % 4);
                const double a  = 0.1 + 0.9 * double((x * 7 + y * 3 + s * 11 + seed) % 10) / 9.0;
                p.push_back({ a * 0.9, a * (x % 5) / 4.0, a * (y % 3) / 2.0, a, z, zb });
            }
            px.push_back(p);
        }
    return make_deep(40, 30, px, false, 3, 2);
}

// Every output of `outputs` made by one bokehtool run per thread count, compared.
void expect_same_bits_for_1_2_8_threads(const std::string& family, const std::vector<Output>& outputs,
                                        const std::string& dir)
{
    for (int threads : { 1, 2, 8 }) {
        std::string line = format("--threads {} -d float", threads);
        for (const Output& o : outputs)
            line += format(" {} {} -o {}/{}.t{}.exr", o.input, o.command, dir, o.name, threads);
        const RunResult r = bokehtool(line);
        ASSERT_EQ(r.status, 0) << family << ", " << threads << " threads: " << r.err;
    }
    for (const Output& o : outputs) {
        SCOPED_TRACE(family + ": " + o.input + " " + o.command);
        OIIO::ImageBuf one(format("{}/{}.t1.exr", dir, o.name));
        ASSERT_TRUE(one.read(0, 0, true, OIIO::TypeFloat)) << one.geterror();
        for (int threads : { 2, 8 }) {
            OIIO::ImageBuf other(format("{}/{}.t{}.exr", dir, o.name, threads));
            ASSERT_TRUE(other.read(0, 0, true, OIIO::TypeFloat)) << other.geterror();
            ASSERT_EQ(one.deep(), other.deep());
            ASSERT_EQ(one.roi(), other.roi()) << threads << " threads";
            if (!one.deep()) {
                std::vector<float> a(size_t(one.roi().npixels()) * size_t(one.nchannels()));
                std::vector<float> b(a.size());
                ASSERT_TRUE(one.get_pixels(one.roi(), OIIO::TypeFloat, a.data()));
                ASSERT_TRUE(other.get_pixels(other.roi(), OIIO::TypeFloat, b.data()));
                EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0)
                    << threads << " threads: other bits (largest difference "
                    << max_difference(one, other) << ")";
                continue;
            }
            const OIIO::DeepData &da = *one.deepdata(), &db = *other.deepdata();
            int64_t differ = 0;
            for (int64_t p = 0; p < da.pixels(); ++p) {
                if (da.samples(p) != db.samples(p)) {
                    ++differ;
                    continue;
                }
                for (int c = 0; c < da.channels(); ++c)
                    for (int s = 0; s < int(da.samples(p)); ++s) {
                        const float va = da.deep_value(p, c, s), vb = db.deep_value(p, c, s);
                        differ += std::memcmp(&va, &vb, sizeof va) != 0;
                    }
            }
            EXPECT_EQ(differ, 0) << threads << " threads: deep samples differ";
        }
    }
}

// Each test makes its inputs in a directory of its own: ctest runs the tests of this file
// as separate processes, side by side.
class Determinism : public testing::Test {
protected:
    void SetUp() override
    {
        s_dir = fresh_dir(std::string("determinism_") + testing::UnitTest::GetInstance()->current_test_info()->name());
        const RunResult r = bokehtool(format("-d float --scene lights:width=96:height=64 -o {0}/scene.exr "
                                             "--scene lights:width=9:height=7 --ch R,G,B,A -o {0}/kernel.exr",
                                             s_dir));
        ASSERT_EQ(r.status, 0) << r.err;
        ASSERT_TRUE(deep_input(0).write(s_dir + "/deep.exr"));
        ASSERT_TRUE(deep_input(3).write(s_dir + "/deep2.exr"));
    }
    static std::string s_dir;
    std::string scene() const { return s_dir + "/scene.exr"; }
    std::string kernel() const { return s_dir + "/kernel.exr"; }
    std::string deep() const { return s_dir + "/deep.exr"; }
    std::string deep2() const { return s_dir + "/deep2.exr"; }
};
std::string Determinism::s_dir;

}  // namespace

TEST_F(Determinism, BlurEveryKernelAndMethod)
{
    // Every method each kernel takes (tests/blur/blur_fixtures.cpp: exact_methods, approximations).
    const std::vector<std::pair<std::string, std::vector<std::string>>> kernels = {
        { "gaussian", { "auto", "exact", "fft", "separable", "boxes3", "fast", "reference" } },
        { "box", { "auto", "exact", "reference" } },
        { "disk", { "auto", "exact", "spans", "fft", "fast", "bands", "taps", "reduced", "reference" } },
        { "hex", { "auto", "spans", "fft", "fast", "bands", "parallelograms", "reduced" } },
        { "polygon:blades=5:curvature=0.3:rotation=10", { "auto", "spans", "fft", "bands", "reference" } },
        { "disk:hole=0.4", { "spans", "fft" } },
        { "blackman-harris", { "auto", "separable", "fft" } },
    };
    std::vector<Output> outputs;
    for (const auto& [kernel, methods] : kernels)
        for (const std::string& m : methods) {
            // Sizes each method takes: taps is Kawase's 9 and 17 only; reduced at factor 2.
            const std::vector<std::string> sizes = m == "taps"      ? std::vector<std::string>{ "9", "17" }
                                                   : m == "reduced" ? std::vector<std::string>{ "21" }
                                                                    : std::vector<std::string>{ "9", "21x13.5" };
            for (const std::string& size : sizes)
                outputs.push_back({ scene(),
                                    format("--blur:kernel={}:method={}{} {}", kernel, m,
                                           m == "reduced" ? ":reduction=2" : "", size),
                                    format("blur{}", outputs.size()) });
        }
    for (const char* iris : { "disk:method=spans", "disk:method=fft", "hex:method=auto" })
        outputs.push_back({ scene(), format("--blur:kernel={}:iris=0.5 11", iris), format("blur{}", outputs.size()) });
    outputs.push_back({ scene(), "--blur:border=clamp:grow=1 15", "blur_clamp_grow" });
    outputs.push_back({ scene(), "--blur:kernel=disk:border=mirror 15", "blur_mirror" });
    expect_same_bits_for_1_2_8_threads("blur", outputs, s_dir);
}

TEST_F(Determinism, ConvolveAndImageKernel)
{
    expect_same_bits_for_1_2_8_threads(
        "convolve",
        { { scene() + " " + kernel(), "--convolve", "convolve" },
          { scene() + " " + kernel(), "--convolve:iris=0.5:border=clamp", "convolve_iris" },
          { scene() + " " + kernel(), "--blur:kernel=image 15x11", "kernel_image" },
          { scene() + " " + kernel(), "--blur:kernel=image:grow=1 31", "kernel_image_grow" } },
        s_dir);
}

TEST_F(Determinism, Resample)
{
    std::vector<Output> outputs;
    for (const char* f : { "lanczos3", "catmull-rom", "gaussian", "box", "nearest", "bilinear", "bspline" }) {
        outputs.push_back({ scene(), format("--resize:filter={} 40x27", f), format("down_{}", f) });
        outputs.push_back({ scene(), format("--resize:filter={} 150x100", f), format("up_{}", f) });
    }
    for (const char* f : { "bilinear", "lanczos3", "reduced-blur", "upscale-blur", "upscale-blur-fused",
                           "upscale-blur-2stage" })
        outputs.push_back({ scene(), format("--reduce 4 --enlarge:filter={} 4", f), format("enlarge_{}", f) });
    for (const char* z : { "min", "max", "nearest", "mean" })
        outputs.push_back({ scene(), format("--reduce:z={} 3", z), format("reduce_{}", z) });
    outputs.push_back({ scene(), "--resample 50x40", "resample" });
    outputs.push_back({ scene(), "--resample:interp=0 130x90", "resample_nearest" });
    expect_same_bits_for_1_2_8_threads("resample", outputs, s_dir);
}

TEST_F(Determinism, DefocusEveryMethod)
{
    const std::string lens = "focus=6:fstop=1.4:focal=50";
    std::vector<Output> outputs;
    for (const char* m : { "auto", "layers", "gather", "reference" })
        outputs.push_back({ scene(), format("--defocus:{}:method={}", lens, m), format("defocus_{}", m) });
    for (const char* k : { "kernel=hex", "kernel=polygon:blades=5:curvature=0.2:hole=0.3", "aspect=1.5",
                           "iris=0.5", "bloom=0.5:bloomgain=4", "zdilate=2:border=black", "budget=30dB",
                           "layers=6:reduction=4" })
        outputs.push_back({ scene(), format("--defocus:{}:{}", lens, k), format("defocus_{}", outputs.size()) });
    for (const char* o : { "coc", "focalplane", "layers" })
        outputs.push_back({ scene(), format("--defocus:{}:output={}", lens, o), format("defocus_{}", o) });
    // A deep input: layered (flat and deep output), the reference, and the truth.
    const std::string deep_lens = "focus=2:fstop=1.4:focal=50:sensor=8";
    for (const char* m : { "method=layers", "method=reference", "method=layers:output=deep",
                           "method=truth:spp=16", "method=truth:spp=16:seed=7" })
        outputs.push_back({ deep(), format("--defocus:{}:{}", deep_lens, m), format("defocus_deep_{}", outputs.size()) });
    expect_same_bits_for_1_2_8_threads("defocus", outputs, s_dir);
}

TEST_F(Determinism, DeepNodes)
{
    expect_same_bits_for_1_2_8_threads(
        "deep",
        { { deep(), "--deeptidy", "tidy" },
          { deep() + " " + deep2(), "--deepmerge", "merge" },
          { deep() + " " + deep2(), "--deepmerge:cull=1", "merge_cull" },
          { deep() + " " + deep2(), "--deepholdout", "holdout" },
          { deep(), "--deepslice 1.5 2.75", "slice" },
          { deep(), "--flatten", "flatten" },
          { deep() + " " + deep2(), "--deepmerge --flatten", "merge_flatten" },
          { scene(), "--deepen", "deepen" } },
        s_dir);
}

TEST_F(Determinism, EveryScene)
{
    std::vector<Output> outputs;
    for (const std::string& name : bokeh::scene_names())
        outputs.push_back({ "", format("--scene {}:width=96:height=64", name), "scene_" + name });
    ASSERT_FALSE(outputs.empty());
    expect_same_bits_for_1_2_8_threads("scene", outputs, s_dir);
}

TEST_F(Determinism, LensPsf)
{
    // Lens PSFs build their radial and fringe tables and their pixels in parallel: every
    // effect on, front and back, each diffraction model, and a contact sheet.
    const std::string every = "lens=achromat:diffraction=exact:onion=0.2:noise=0.1:catseye=0.6:astigmatism=-20:"
                              "kernel=polygon:blades=7:curvature=0.3:field=0.6,0.34";
    expect_same_bits_for_1_2_8_threads(
        "bokeh",
        { { "", format("--bokeh:{} 255", every), "psf_every_255" },
          { "", format("--bokeh:{} -45", every), "psf_every_front" },
          { "", "--bokeh:lens=uncorrected:fstop=1.4:diffraction=pseudo:onion=0.15:catseye=0.5:field=0.3,-0.5 80",
            "psf_seed" },
          { "", "--bokeh:lens=achromat:correction=1.6:diffraction=exact:onionwaves=0.05:onionsharpness=3 100",
            "psf_bubble" },
          { "", "--bokeh:lens=apochromat:chromatic=10:diffraction=exact:onion=0.15:catseye=0.5:sheet=1 20",
            "psf_sheet" } },
        s_dir);
}
