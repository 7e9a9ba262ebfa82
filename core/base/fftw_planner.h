// fftw_planner.h — the one lock around FFTW's planner, shared by every FFTW user in the
// library (FFTW's planner is not thread-safe; executing a made plan on new arrays is).
#pragma once

#include <mutex>

namespace bokeh {
namespace detail {

std::mutex& fftw_planner_mutex();

}  // namespace detail
}  // namespace bokeh
