// resample_task.h — bokeh-bench's resample task (resample_task.cpp): reduced buffers and
// their enlargement, every method against the full-resolution effect, with the artifact
// metrics and OIIO's IBA::resize as the peer.
#pragma once

#include "defocus_task.h"

#include <string>
#include <vector>

namespace bokeh_bench {

/// Run the task and print its tables. Appends CSV rows in the blur task's columns (size_px
/// = the reduction factor) to `rows`; the artifact metrics per method and factor to
/// `artifact_rows` and the headline figures (timings against targets, peer ratios, the
/// upscale-blur's cost claim) to `figure_rows`, each starting with its own header line.
/// args.images_dir, if set, receives enlarge_sheet.png. False on an error, reported on
/// stderr.
bool run_resample_task(const BenchArgs& args, std::vector<std::string>& rows,
                       std::vector<std::string>& artifact_rows, std::vector<std::string>& figure_rows);

}  // namespace bokeh_bench
