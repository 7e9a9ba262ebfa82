// test_util.h — helpers shared by the unit and CLI tests.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh_test {

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

}  // namespace bokeh_test

// Tests on the real files in ../shared/data are skipped, with a message, when it is absent.
#define REQUIRE_SHARED(path)                                                      \
    if ((path).empty())                                                           \
    GTEST_SKIP() << "../shared/data is not beside the project"
