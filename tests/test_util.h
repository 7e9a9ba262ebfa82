// test_util.h — helpers shared by the unit and CLI tests.
#pragma once

#include <string>

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

/// Largest absolute difference of two images over all channels (inf if sizes differ).
double max_difference(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b);

}  // namespace bokeh_test

// Tests on the real files in ../shared/data are skipped, with a message, when it is absent.
#define REQUIRE_SHARED(path)                                                      \
    if ((path).empty())                                                           \
    GTEST_SKIP() << "../shared/data is not beside the project"
