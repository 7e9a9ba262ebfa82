// iris_task.h — bokeh-bench's iris task (iris_task.cpp).
#pragma once

#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh_bench {

/// Run the task on `crop` (the blur task's), print a table, append CSV rows (blur task's
/// columns; median_ms empty, the task column naming |k| x range). False on an error,
/// reported on stderr.
bool run_iris_task(const OIIO::ImageBuf& crop, int threads, std::vector<std::string>& rows);

}  // namespace bokeh_bench
