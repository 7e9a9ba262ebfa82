// base.h — what every family of the library shares and none owns: the rule for pixels
// outside a data window and the constants. The base layer's other public headers are
// parallel.h (parallel loops) and image.h (channel lookup, the working image, metadata,
// the non-finite policy); its internal ones are in core/base/ (planes and float views,
// progress, FFT planning). Nothing here knows an algorithm (docs/architecture.md).
#pragma once

namespace bokeh {

/// Pixels outside the source's data window.
enum class Border { Black, Clamp, Mirror };

/// pi, to double precision.
inline constexpr double kPi = 3.14159265358979323846;

}  // namespace bokeh
