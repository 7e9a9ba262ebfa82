// timing.h — how every bokeh-bench task times a case: one warm-up, then the median of
// `reps` runs, in milliseconds.
#pragma once

#include <algorithm>
#include <functional>
#include <numeric>
#include <random>
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

// The medians of many cases timed in interleaved rounds: each case warmed up once, then
// every round runs each case still short of its reps[i] runs once, in an order shuffled
// per round (fixed seed, so runs repeat). This machine has slow phases of minutes (the
// same call seen 30 % slower, and once 4x, for a while): one case after another, a phase
// falls on some cases and not others and skews their ratios (a box at 255 px against one
// at 15); interleaved, it falls on every case alike.
inline std::vector<double> interleaved_medians_ms(const std::vector<std::function<void()>>& fns,
                                                  const std::vector<int>& reps)
{
    const size_t n = fns.size();
    for (const auto& fn : fns)
        fn();  // warm-up
    std::vector<std::vector<double>> t(n);
    const int rounds = reps.empty() ? 0 : *std::max_element(reps.begin(), reps.end());
    std::vector<size_t> order(n);
    std::iota(order.begin(), order.end(), size_t(0));
    std::mt19937 rng(12345);
    for (int r = 0; r < rounds; ++r) {
        std::shuffle(order.begin(), order.end(), rng);
        for (size_t i : order) {
            if (r >= reps[i])
                continue;
            OIIO::Timer timer;
            fns[i]();
            t[i].push_back(timer() * 1e3);
        }
    }
    std::vector<double> medians(n, 0.0);
    for (size_t i = 0; i < n; ++i) {
        std::sort(t[i].begin(), t[i].end());
        if (!t[i].empty())
            medians[i] = t[i][t[i].size() / 2];
    }
    return medians;
}

}  // namespace bokeh_bench
