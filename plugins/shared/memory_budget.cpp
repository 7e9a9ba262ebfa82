// memory_budget.cpp — see memory_budget.h.

#include "memory_budget.h"

#include <bokeh/io.h>

#include <algorithm>
#include <limits>
#include <thread>

#include <OpenImageIO/strutil.h>

namespace bokeh {

int64_t image_bytes(int64_t width, int64_t height, int64_t per_pixel)
{
    constexpr int64_t most = std::numeric_limits<int64_t>::max();
    if (width <= 0 || height <= 0 || per_pixel <= 0)
        return 0;
    if (width > most / height || width * height > most / per_pixel)
        return -1;
    return width * height * per_pixel;
}

bool within_memory_budget(CommandContext& c, int64_t bytes, const std::string& what)
{
    const int64_t budget = c.memory_budget_bytes > 0 ? c.memory_budget_bytes : default_memory_budget_bytes();
    if (bytes >= 0 && bytes <= budget)
        return true;
    return c.fail(OIIO::Strutil::fmt::format("{} would take {}, over the memory budget of {} (--maxmemory "
                                             "raises it)",
                                             what, bytes < 0 ? std::string("more than 8 EiB") : memory_size_text(bytes),
                                             memory_size_text(budget)));
}

bool within_timeout(CommandContext& c, double rays, const std::string& what)
{
    if (!(c.timeout_seconds > 0.0))
        return true;
    const int threads    = c.nthreads > 0 ? c.nthreads : std::max(1, int(std::thread::hardware_concurrency()));
    const double seconds = rays * kTruthFloorNsPerRay * 1e-9 / threads;
    if (seconds <= c.timeout_seconds)
        return true;
    const std::string at_least = seconds >= 7200.0 ? OIIO::Strutil::fmt::format("{:.1f} h", seconds / 3600.0)
                                 : seconds >= 120.0 ? OIIO::Strutil::fmt::format("{:.0f} min", seconds / 60.0)
                                                    : OIIO::Strutil::fmt::format("{:.0f} s", seconds);
    return c.fail(OIIO::Strutil::fmt::format("{} is {:.2g} rays: at least {} on {} thread{}, past --timeout {:g} s",
                                             what, rays, at_least, threads, threads == 1 ? "" : "s",
                                             c.timeout_seconds));
}

}  // namespace bokeh
