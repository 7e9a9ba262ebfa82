// diffraction_task.h — bokeh-bench's diffraction task (diffraction_task.cpp).
#pragma once

#include <string>
#include <vector>

namespace bokeh_bench {

/// The CSV header of the diffraction task (its own columns: its errors are of radial
/// profiles, not images).
inline constexpr const char* kDiffractionCsvHeader
    = "task,method,size_px,defocus_waves,median_ms,reps,rms_rel_flat,max_rel_flat";

/// Time and error of each diffraction method against the exact PSF, per CoC size; prints a
/// table and appends CSV rows. `quick`: the two smallest sizes only. False on an error.
bool run_diffraction_task(int reps, bool quick, std::vector<std::string>& rows);

}  // namespace bokeh_bench
