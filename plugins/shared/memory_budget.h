// memory_budget.h — what a command will hold for the sizes a user typed, checked before
// anything is allocated, against the run's memory budget (--maxmemory, else half the
// machine's memory): a 32768 x 32768 scene is refused in one line instead of growing
// until the kernel kills the process. And a truth's rays against --timeout, before the
// first is traced.
#pragma once

#include <bokeh/plugin.h>

#include <cstdint>
#include <string>

namespace bokeh {

/// True when `bytes` fits the budget of `c` (CommandContext::memory_budget_bytes, 0: the
/// default); else false with `c.error` set: "<what> would take 20.0 GiB, over the memory
/// budget of 11.7 GiB (--maxmemory raises it)". `bytes` < 0 stands for an overflow.
bool within_memory_budget(CommandContext& c, int64_t bytes, const std::string& what);

/// The rays of a thin-lens truth against the run's --timeout (CommandContext::
/// timeout_seconds; none: true): false with `c.error` set when even the fastest pace
/// measured for a ray, five times over (kTruthFloorNsPerRay a ray a thread), cannot trace
/// `rays` on the command's threads in time: "<what> is 2.2e+12 rays: at least 7.5 h on 2
/// threads, past --timeout 5 s". A run that may fit is left to --timeout's own pace check.
bool within_timeout(CommandContext& c, double rays, const std::string& what);

/// The floor of a truth ray's cost on one thread, ns: a fifth of the fastest measured
/// (128 ns a ray a thread, `bokehtool -v --scene:output=truth:spp=256 lights` at 192x108
/// on 2 threads; the deep truth 140-210 ns, docs/methods/truth.md).
constexpr double kTruthFloorNsPerRay = 25.0;

/// w * h * per_pixel bytes, or -1 past int64_t.
int64_t image_bytes(int64_t width, int64_t height, int64_t per_pixel);

}  // namespace bokeh
