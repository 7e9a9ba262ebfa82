// optics_task.h — bokeh-bench's optics task (optics_task.cpp).
#pragma once

#include <string>
#include <vector>

namespace bokeh_bench {

/// Time lens-character PSFs (optics.h) at `threads`: each effect alone and all together,
/// built cold and taken warm from the cache, and the contact sheet; print a table and
/// append CSV rows (the blur task's columns; no error columns: the PSFs' accuracy is the
/// unit tests' and the diffraction chart's). False on an error, reported on stderr.
bool run_optics_task(int threads, int reps, std::vector<std::string>& rows);

}  // namespace bokeh_bench
