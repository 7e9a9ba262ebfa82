// deep_task.h — bokeh-bench's deep task (deep_task.cpp).
#pragma once

#include "defocus_task.h"

#include <string>
#include <vector>

namespace bokeh_bench {

/// Run the task on the real deep files under args.data_dir (skipped, saying so, when it is
/// empty or they are absent), print a table, append CSV rows (blur task's columns).
/// False on an error, reported on stderr.
bool run_deep_task(const BenchArgs& args, std::vector<std::string>& rows);

}  // namespace bokeh_bench
