// numbers.h — internal to the library: numeric constants more than one family uses, named
// once (the library is compiled a few files at a time as one, so two files cannot each
// define their own under the same name).
#pragma once

#include <limits>

namespace bokeh::detail {

/// Positive infinity in double: an unbounded depth or ray parameter, an empty range's end.
inline constexpr double kInf = std::numeric_limits<double>::infinity();

}  // namespace bokeh::detail
