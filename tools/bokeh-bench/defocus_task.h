// defocus_task.h — bokeh-bench's defocus task (defocus_task.cpp).
#pragma once

#include <string>
#include <vector>

namespace bokeh_bench {

struct BenchArgs {
    int threads = 2, reps = 5;
    int width = 1920, height = 1080;  ///< size of the built-in scenes
    std::string data_dir;             ///< ../shared/data, or empty to skip the real files
    std::string images_dir;           ///< where to write the picture sheet's JPEGs (or none)
    std::vector<std::string> only;    ///< the defocus shots to run (empty: all)
};

/// Run the task, print a table, append CSV rows (blur task's columns; size_px = the
/// largest |CoC|). False on an error, reported on stderr.
bool run_defocus_task(const BenchArgs& args, std::vector<std::string>& rows);

/// The flat planner's plans on each shot: the steps' default, and the predicted planner's
/// plans predicted against measured (PSNR against the reference and, on the built-in
/// scenes, against the thin-lens truth; in-process median ms), a grid of them and its
/// choice; kPlansCsvHeader's columns (chosen: steps, predicted, floor (two truths' PSNR in
/// truth_psnr_db) or empty; ladder_ratio 0: the steps').
constexpr const char* kPlansCsvHeader
    = "scene,ladder_ratio,min_reduced_coc_px,layers,predicted_psnr_db,psnr_db,predicted_ms,median_ms,threads,chosen,"
      "truth_psnr_db";
bool run_plans_task(const BenchArgs& args, std::vector<std::string>& rows);

}  // namespace bokeh_bench
