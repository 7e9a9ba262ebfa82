// fftw_planner.cpp — the one lock around FFTW's planner (fftw_planner.h): FFTW's planner is
// not thread-safe; executing a made plan on new arrays is. Every FFTW user in the library
// (the blur's FFT tiles, the wave optics) plans under it.

#include "base/fftw_planner.h"

namespace bokeh::detail {

std::mutex& fftw_planner_mutex()
{
    static std::mutex m;
    return m;
}

}  // namespace bokeh::detail
