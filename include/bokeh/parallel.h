// parallel.h — the one way OpenBokeh runs work on several threads.
//
// `nthreads` follows ImageBufAlgo: 0 = all cores, N = at most N threads (mapped onto a
// tbb::task_arena). Work is split into fixed chunks whose boundaries do not depend on the
// thread count, and reductions combine chunk results in chunk order, so every result is
// bit-identical for any thread count (docs/robustness.md, "Determinism").
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include <OpenImageIO/imageio.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace bokeh {

/// The calling thread's arena of `nthreads` threads (0 = all cores), made on its first use
/// and kept for the thread's life. oneTBB releases a destroyed arena lazily, once its
/// workers have left it; arenas made and destroyed a few hundred microseconds apart piled
/// up and every later parallel call slowed (the lens fit's unit tests: each fit's
/// evaluations slower than the last, 0.9 -> 4.2 ms over five fits in one process, the
/// process at 500 MB; oneTBB issue #967 reports the memory). One arena per thread and
/// count keeps what a call gets as before: its own arena, capped at `nthreads`.
inline tbb::task_arena& thread_arena(int nthreads)
{
    nthreads = std::max(nthreads, 0);
    thread_local std::vector<std::pair<int, std::unique_ptr<tbb::task_arena>>> arenas;
    for (const auto& a : arenas)
        if (a.first == nthreads)
            return *a.second;
    arenas.emplace_back(nthreads, nthreads == 0 ? std::make_unique<tbb::task_arena>()
                                                : std::make_unique<tbb::task_arena>(nthreads));
    return *arenas.back().second;
}

/// Run `fn()` inside an arena of `nthreads` threads (0 = all cores).
template<class Fn> void run_in_arena(int nthreads, Fn&& fn)
{
    thread_arena(nthreads).execute(fn);
}

/// Call `fn(begin, end)` on consecutive chunks of [begin, end), each at most `chunk` long.
template<class Fn>
void parallel_for_chunks(int64_t begin, int64_t end, int64_t chunk, int nthreads, Fn&& fn)
{
    if (end <= begin)
        return;
    if (chunk < 1)
        chunk = 1;
    const int64_t nchunks = (end - begin + chunk - 1) / chunk;
    if (nthreads == 1) {
        // One thread: the same chunks in order, without an arena (work already running
        // inside a parallel loop, per tile, calls in here this way).
        for (int64_t c = 0; c < nchunks; ++c)
            fn(begin + c * chunk, std::min(end, begin + (c + 1) * chunk));
        return;
    }
    run_in_arena(nthreads, [&] {
        tbb::parallel_for(int64_t(0), nchunks, [&](int64_t c) {
            const int64_t b = begin + c * chunk;
            fn(b, std::min(end, b + chunk));
        });
    });
}

/// Call `fn(ybegin, yend)` over the rows of `roi` (a few rows per task).
template<class Fn> void parallel_rows(const OIIO::ROI& roi, int nthreads, Fn&& fn)
{
    parallel_for_chunks(roi.ybegin, roi.yend, 8, nthreads,
                        [&](int64_t b, int64_t e) { fn(int(b), int(e)); });
}

/// Deterministic reduction: `partial(begin, end)` returns a T for one chunk; chunk
/// results are combined with `combine(acc, part)` in chunk order.
template<class T, class Partial, class Combine>
T parallel_reduce_chunks(int64_t begin, int64_t end, int64_t chunk, int nthreads, T init,
                         Partial&& partial, Combine&& combine)
{
    // std::vector<bool> packs the parts as bits of shared words, which the chunks' tasks
    // would write at once (a data race): reduce an int instead.
    static_assert(!std::is_same_v<T, bool>, "parallel_reduce_chunks: use int, not bool");
    if (end <= begin)
        return init;
    if (chunk < 1)
        chunk = 1;
    const int64_t nchunks = (end - begin + chunk - 1) / chunk;
    std::vector<T> parts(size_t(nchunks), init);
    parallel_for_chunks(0, nchunks, 1, nthreads, [&](int64_t c, int64_t) {
        const int64_t b = begin + c * chunk;
        parts[size_t(c)]  = partial(b, std::min(end, b + chunk));
    });
    T acc = init;
    for (const T& p : parts)
        combine(acc, p);
    return acc;
}

}  // namespace bokeh
