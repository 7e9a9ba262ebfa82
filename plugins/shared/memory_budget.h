// memory_budget.h — what a command will hold for the sizes a user typed, checked before
// anything is allocated, against the run's memory budget (--maxmemory, else half the
// machine's memory): a 32768 x 32768 scene is refused in one line instead of growing
// until the kernel kills the process.
#pragma once

#include <bokeh/plugin.h>

#include <cstdint>
#include <string>

namespace bokeh {

/// True when `bytes` fits the budget of `c` (CommandContext::memory_budget_bytes, 0: the
/// default); else false with `c.error` set: "<what> would take 20.0 GiB, over the memory
/// budget of 11.7 GiB (--maxmemory raises it)". `bytes` < 0 stands for an overflow.
bool within_memory_budget(CommandContext& c, int64_t bytes, const std::string& what);

/// w * h * per_pixel bytes, or -1 past int64_t.
int64_t image_bytes(int64_t width, int64_t height, int64_t per_pixel);

}  // namespace bokeh
