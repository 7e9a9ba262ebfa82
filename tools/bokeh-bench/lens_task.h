// lens_task.h — bokeh-bench's lens task: lens character in the defocus (highlight sprites)
// against the plain defocus (cost) and against the brute-force scatter reference (PSNR).
#pragma once

#include "defocus_task.h"

#include <string>
#include <vector>

namespace bokeh_bench {

/// Run the task on the built-in scenes (args.only: a subset), print a table, append CSV
/// rows. False on an error, reported on stderr.
bool run_lens_task(const BenchArgs& args, std::vector<std::string>& rows);

}  // namespace bokeh_bench
