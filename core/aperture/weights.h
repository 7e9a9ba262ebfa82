// weights.h — internal to the library: helpers over kernel weights the aperture family
// makes and the blur methods reuse.
#pragma once

#include <bokeh/aperture.h>

#include <vector>

namespace bokeh::detail {

/// The separable kernel wx (x) wy, each of odd length, centred (core/aperture/kernel.cpp).
KernelWeights outer(const std::vector<double>& wx, const std::vector<double>& wy);

}  // namespace bokeh::detail
