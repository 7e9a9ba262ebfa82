// micro.cpp — bokeh-micro: Google Benchmark microbenchmarks behind the exact methods' cost
// models (core/blur/blur_spans.cpp, core/blur/blur_separable.cpp, core/blur/blur_fft.cpp).
//
// * BM_FftwTile: FFTW's in-place real 2-D transform of one tile, forward and back, with
//   FFTW_ESTIMATE plans as blur_fft.cpp makes them: the ns per transformed point that
//   tile_cost_ns is fitted to (the loop adds the copies in and out and, with both cores
//   busy, their contention). Counter `ns_per_point`.
// * BM_ExactBlur: bokeh::blur on a 1920x1080 RGBA float frame of noise with each exact
//   method by name (spans, fft, separable), and `exact` (the cost models' choice), side by
//   side at the same sizes; the ratios of these rows are what the models must rank.
//   Counter `ns_per_pixel_channel` is single-thread-equivalent (time x threads).
//
// Run: `make micro` (docs/benchmarks.md quotes its medians). It interleaves the cases'
// repetitions at random: the machine's speed drifts by 20-30 % over minutes, and run one
// after the other, neighbouring cases measured up to 1.3x apart at equal work.

#include <bokeh/blur.h>

#include <benchmark/benchmark.h>
#include <fftw3.h>

#include <OpenImageIO/imagebufalgo.h>

#include <map>

namespace {

void BM_FftwTile(benchmark::State& state)
{
    const int ny = int(state.range(0)), nx = int(state.range(1));
    const size_t points = size_t(ny) * size_t(2 * (nx / 2 + 1));
    double* t           = fftw_alloc_real(points);
    auto* c             = reinterpret_cast<fftw_complex*>(t);
    const fftw_plan forward  = fftw_plan_dft_r2c_2d(ny, nx, t, c, FFTW_ESTIMATE);
    const fftw_plan backward = fftw_plan_dft_c2r_2d(ny, nx, c, t, FFTW_ESTIMATE);
    for (size_t i = 0; i < points; ++i)
        t[i] = double(i % 13) * 0.1;
    for (auto _ : state) {
        fftw_execute(forward);
        fftw_execute(backward);
        benchmark::ClobberMemory();
    }
    state.counters["ns_per_point"] = benchmark::Counter(
        double(ny) * double(nx), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
    fftw_destroy_plan(forward);
    fftw_destroy_plan(backward);
    fftw_free(t);
}
BENCHMARK(BM_FftwTile)
    ->Args({ 64, 64 })->Args({ 128, 128 })->Args({ 256, 256 })->Args({ 256, 512 })
    ->Args({ 384, 384 })->Args({ 512, 512 })->Args({ 512, 768 })->Args({ 768, 768 })
    ->Args({ 1024, 1024 })->Args({ 1536, 768 })->Args({ 2048, 1024 })
    ->Unit(benchmark::kMicrosecond)->MinWarmUpTime(0.1);  // untimed runs first: caches, plans, pages

const OIIO::ImageBuf& frame()
{
    static const OIIO::ImageBuf f = [] {
        OIIO::ImageBuf b(OIIO::ImageSpec(1920, 1080, 4, OIIO::TypeFloat));
        OIIO::ImageBufAlgo::noise(b, "uniform", 0.0f, 1.0f, false, 1);
        return b;
    }();
    return f;
}

// range(0): kernel size in px; range(1): BlurMethod; range(2): shape (0 disk, 1 Gaussian);
// range(3): threads.
void BM_ExactBlur(benchmark::State& state)
{
    bokeh::Kernel k;
    k.shape    = state.range(2) == 0 ? bokeh::KernelShape::Disk : bokeh::KernelShape::Gaussian;
    k.width_px = k.height_px = float(state.range(0));
    bokeh::BlurOptions o;
    o.method          = bokeh::BlurMethod(state.range(1));
    const int threads = int(state.range(3));
    OIIO::ImageBuf out;
    for (auto _ : state)
        if (!bokeh::blur(out, frame(), k, o, {}, threads))
            state.SkipWithError(out.geterror().c_str());
    state.counters["ns_per_pixel_channel"] = benchmark::Counter(
        1920.0 * 1080.0 * 4.0 / double(threads),
        benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void exact_cases(benchmark::internal::Benchmark* b)
{
    using M = bokeh::BlurMethod;
    for (int threads : { 1, 2 })
        for (int size : { 15, 31, 63, 95, 127, 255 }) {
            for (M m : { M::Exact, M::Spans, M::Fft })
                b->Args({ size, int64_t(m), 0, threads });
            for (M m : { M::Exact, M::Separable, M::Fft })
                b->Args({ size, int64_t(m), 1, threads });
        }
    b->ArgNames({ "size", "method", "gaussian", "threads" });
}
BENCHMARK(BM_ExactBlur)->Apply(exact_cases)->Unit(benchmark::kMillisecond)->UseRealTime()
    ->MinTime(0.5)->MinWarmUpTime(0.2);

}  // namespace

BENCHMARK_MAIN();
