// lens_fit_task.h — bokeh-bench's lens-fit task (lens_fit_task.cpp).
#pragma once

#include <string>
#include <vector>

namespace bokeh_bench {

/// The CSV header of the lens-fit task: a row per parameter per round trip (its own
/// columns), and rows "time" for the speed cases.
inline constexpr const char* kLensFitCsvHeader
    = "task,trial,crops,crop_px,peak_snr,parameter,true_value,fitted,sigma,status,seconds,psf_psnr_db";

/// Round trips of the lens fit over `trials` random lenses (seeded: the same lenses on
/// every run), and the speed of one 128 px crop and of 8; prints a summary and appends
/// CSV rows. False on an error.
bool run_lens_fit_task(int trials, int threads, std::vector<std::string>& rows);

}  // namespace bokeh_bench
