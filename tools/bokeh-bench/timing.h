// timing.h — how bokeh-bench times its cases: median_ms, one warm-up then the median of
// `reps` runs; interleaved_medians_ms, many cases in shuffled rounds (milliseconds).
#pragma once

#include <algorithm>
#include <functional>
#include <numeric>
#include <random>
#include <vector>

#include <OpenImageIO/timer.h>

namespace bokeh_bench {

// The medians of many cases timed in interleaved rounds: every round runs each case still
// short of its reps[i] timed runs once, in an order shuffled per round (fixed seed, so runs
// repeat), each timed run right after an untimed one of the same case (its warm-up: caches
// and allocations as the back-to-back runs of median_ms have them), or, for the cases with
// warm[i] false (the slow peers), after one warm-up at the start. This machine has slow
// phases of minutes (the same call 30 % slower, once 4x, for a while): one case after
// another, a phase falls on some cases and not others and skews their ratios (a box at
// 255 px against one at 15); interleaved, it falls on every case alike.
inline std::vector<double> interleaved_medians_ms(const std::vector<std::function<void()>>& fns,
                                                  const std::vector<int>& reps,
                                                  const std::vector<bool>& warm)
{
    const size_t n = fns.size();
    for (size_t i = 0; i < n; ++i)
        if (!warm[i])
            fns[i]();  // the one warm-up
    std::vector<std::vector<double>> t(n);
    const int rounds = reps.empty() ? 0 : *std::max_element(reps.begin(), reps.end());
    std::vector<size_t> order(n);
    std::iota(order.begin(), order.end(), size_t(0));
    std::mt19937 rng(12345);
    for (int r = 0; r < rounds; ++r) {
        std::shuffle(order.begin(), order.end(), rng);
        for (size_t i : order) {
            // A case of fewer reps runs in rounds spread over the whole run (3 of 9: rounds
            // 2, 5, 8), not only in the first ones, so its median sees the run's phases too.
            if ((r + 1) * reps[i] / rounds == r * reps[i] / rounds)
                continue;
            if (warm[i])
                fns[i]();
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

// One case: one warm-up, then the median of `reps` runs.
inline double median_ms(const std::function<void()>& fn, int reps)
{
    return interleaved_medians_ms({ fn }, { reps }, { false })[0];
}

}  // namespace bokeh_bench
