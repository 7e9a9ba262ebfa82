// test_util.h — helpers shared by the unit and CLI tests.
#pragma once

#include <bokeh/aperture.h>
#include <bokeh/defocus.h>
#include <bokeh/metrics.h>

#include <array>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh_test {

/// Where the tests find things, set when the build is configured. They are compiled into
/// test_util.cpp alone (a clone in another folder then changes one file, and the compiler
/// cache serves the rest); the macros below are what the tests use.
namespace paths {
extern const char* const bokehtool;       ///< the built bokehtool
extern const char* const source_dir;      ///< the checkout
extern const char* const shared_data;     ///< ../shared/data: test images kept beside it
extern const char* const test_tmp;        ///< scratch space under the build tree
extern const char* const bad_plugin_dir;  ///< the plugins that fail on purpose
extern const char* const ocio_config;     ///< ocio/config.ocio
}  // namespace paths

/// A new empty directory for one test, under the build tree.
std::string fresh_dir(const std::string& name);

/// A file in ../shared/data, or "" when the shared data is not beside the project.
std::string shared_data(const std::string& relative);

/// The whole content of a file ("" if it cannot be read).
std::string file_bytes(const std::string& path);

bool exists(const std::string& path);

/// Result of running bokehtool.
struct RunResult {
    int status = -1;
    std::string out, err;
};

/// RunResult bokehtool with `args` (shell words), with `env` ("NAME=value ...") before it.
RunResult bokehtool(const std::string& args, const std::string& env = "");

/// Run a shell command line (no standard input), its exit status and output captured.
RunResult run_shell(const std::string& command);

/// Expect a clean failure: exit 1, one line "bokehtool ERROR: ..." holding `what`, and
/// nothing written at `output` (unless it is "").
void expect_clean_failure(const RunResult& r, const std::string& what, const std::string& output);

/// A float R, G, B, A, Z image (alpha_channel 3, z_channel 4) over a w x h data window at
/// (x0, y0), display window `full` (default: the data window); `fn(x, y)` gives the pixel.
OIIO::ImageBuf rgbaz_image(int w, int h, const std::function<std::array<float, 5>(int, int)>& fn,
                           int x0 = 0, int y0 = 0, OIIO::ROI full = {});

/// One pixel of a flat test image: premultiplied colour, alpha, and the depth channel (in
/// DepthMode::Direct, the signed CoC in pixels itself).
struct Px {
    float r = 0.0f, g = 0.0f, b = 0.0f, a = 1.0f, z = 0.0f;
};

/// rgbaz_image with each pixel a Px: a float R, G, B, A, Z image over a w x h data window
/// at (x0, y0), display window `full` (default: the data window).
OIIO::ImageBuf make_image(int w, int h, const std::function<Px(int, int)>& fn, int x0 = 0, int y0 = 0,
                          OIIO::ROI full = {});

/// Channel c of pixel (x, y) of a float image; 0 outside the data window.
float at(const OIIO::ImageBuf& img, int x, int y, int c);

/// Sum of channel c of a float image over its data window, in double.
double channel_sum(const OIIO::ImageBuf& img, int c);

/// A deterministic texture value in [0, 1] at (x, y); `salt` gives another texture.
float texture(int x, int y, int salt = 0);

/// The disk aperture's weights at diameter |c| px (the library's default aperture; its
/// pixel areas are checked against the exact circle in aperture/kernel_area_test.cpp).
bokeh::KernelWeights disk(float c);

/// Defocus options for a DepthMode::Direct image (Z is the signed CoC in px): the method,
/// the border rule (each test names its own) and whether the data window grows.
bokeh::DefocusOptions direct_options(bokeh::DefocusMethod m, bokeh::Border border, bool grow = true);

/// The lens of the focus-pull tests' slanted plane: 85 mm f/1.4 on a 36 mm back, Z in
/// metres (the focus left to the test).
bokeh::DefocusOptions plane_lens(bokeh::DefocusMethod m);

/// The focus-pull tests' 160 x 90 slanted plane: 1 / Z linear in x from 1 m (left) to 10 m
/// (right), textured (6 px checker in red, horizontal sine in green, 3 px blocks of noise in
/// blue; luminance up to about 0.9).
OIIO::ImageBuf slanted_plane();

/// How a sequence changes in time: sqrt(mean over frames of mean(d2_a d2_b) / mean of
/// mean(d1_a d1_b)), d1 and d2 the first and second differences of the frames' R, G, B
/// after the tone map x / (1 + |x|). A sequence that changes at a steady rate scores 0; one
/// that steps scores about 1 and more. `a` and `b` are two renders of the same sequence: a
/// method's twice (the same frames: the RMS ratio), or the truth's with two ray seeds,
/// whose noise is independent, so its products average to zero and the figure is the
/// noiseless truth's (a noisy truth alone scores sqrt(3) for its noise).
double second_to_first_difference(const std::vector<OIIO::ImageBuf>& a, const std::vector<OIIO::ImageBuf>& b);

/// Defocus options for a built-in scene (make_scene): depth in metres and the lens and
/// focus its metadata records.
bokeh::DefocusOptions scene_lens(const OIIO::ImageSpec& scene);

/// The defocus of `src` with `o` (a test failure if it fails), its report in `rep`.
OIIO::ImageBuf run_defocus(const OIIO::ImageBuf& src, const bokeh::DefocusOptions& o,
                           bokeh::DefocusReport* rep = nullptr, int nthreads = 0);

/// bokeh::compare of `result` against `reference` over their data windows (a test
/// failure if they cannot be compared).
bokeh::ImageError error_of(const OIIO::ImageBuf& result, const OIIO::ImageBuf& reference);

/// One sample of a deep R, G, B, A, Z, ZBack image (zb == z: a point).
struct DeepSample {
    double r, g, b, a, z, zb;
};
using DeepPixel = std::vector<DeepSample>;

/// A deep R, G, B, A, Z, ZBack image over w x h at (x0, y0) (display window: w x h at the
/// origin), colour half when `half_colour`, Z and ZBack float; `px` row by row.
OIIO::ImageBuf make_deep(int w, int h, const std::vector<DeepPixel>& px, bool half_colour = false, int x0 = 0,
                         int y0 = 0);

/// Largest absolute difference of two images over all channels (inf if sizes differ).
double max_difference(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b);

/// A stereo pair as renders write it, 16 x 8, in `dir`: part 0 the left view's R, G, B, A,
/// part 1 the right view's, then a depth part per view (channel "Z"), each part tagged with
/// its "view". Left: R = 0.25, Z = 3; right: R = 0.75, Z = 5. Returns its path.
std::string stereo_parts_exr(const std::string& dir);

/// The same pair in one part, every channel prefixed by its view (left.R ... right.Z),
/// "multiView" listing left, right.
std::string stereo_single_part_exr(const std::string& dir);

}  // namespace bokeh_test

#define BOKEHTOOL (::bokeh_test::paths::bokehtool)
#define BOKEH_SOURCE_DIR (::bokeh_test::paths::source_dir)
#define BOKEH_SHARED_DATA (::bokeh_test::paths::shared_data)
#define BOKEH_TEST_TMP (::bokeh_test::paths::test_tmp)
#define BOKEH_BAD_PLUGIN_DIR (::bokeh_test::paths::bad_plugin_dir)
#define BOKEH_OCIO_CONFIG (::bokeh_test::paths::ocio_config)

// Tests on the real files in ../shared/data (test images kept beside the repository) are
// skipped, with a message naming the folder, when it is absent.
#define REQUIRE_SHARED(path)                                                      \
    if ((path).empty())                                                           \
    GTEST_SKIP() << "../shared/data is not beside the project"
