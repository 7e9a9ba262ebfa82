// iris_task.h — bokeh-bench's iris task (iris_task.cpp).
#pragma once

#include "defocus_task.h"

#include <string>
#include <vector>

namespace bokeh_bench {

/// Run the task, print a table, append CSV rows (blur task's columns; median_ms empty, the
/// task column naming |k| x range). False on an error, reported on stderr.
bool run_iris_task(const BenchArgs& args, std::vector<std::string>& rows);

}  // namespace bokeh_bench
