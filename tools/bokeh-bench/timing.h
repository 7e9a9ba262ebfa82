// timing.h — how every bokeh-bench task times a case: one warm-up, then the median of
// `reps` runs, in milliseconds.
#pragma once

#include <algorithm>
#include <functional>
#include <vector>

#include <OpenImageIO/timer.h>

namespace bokeh_bench {

inline double median_ms(const std::function<void()>& fn, int reps)
{
    fn();  // warm-up
    std::vector<double> t;
    for (int i = 0; i < reps; ++i) {
        OIIO::Timer timer;
        fn();
        t.push_back(timer() * 1e3);
    }
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

}  // namespace bokeh_bench
