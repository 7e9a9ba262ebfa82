// aperture_options.h — the rule the plugins that take an aperture (`--blur`, `--defocus`)
// share for its options: which of them each `kernel=NAME` uses. It lives with those
// plugins, not in the registry (core/plugin/plugin.cpp), which knows no kernel or algorithm.
#pragma once

#include <bokeh/blur.h>
#include <bokeh/plugin.h>

#include <string>

namespace bokeh {

/// The aperture options `kernel=NAME` uses, as --blur and --defocus spell them (`sigma`,
/// `blades`, `rotation`, `curvature`, `hole`): false + `why` for the first one given
/// (of those `v` has) that the kernel would ignore (`kernel=hex:blades=5`, `kernel=disk:
/// rotation=30`), so it is refused rather than dropped unseen.
bool aperture_options_apply(const OptionValues& v, const std::string& kernel, std::string& why);

/// The disk, hex or polygon aperture `kernel=` names, with `blades`, `rotation`,
/// `curvature` and `hole` from `v` (size left 0), after aperture_options_apply's check:
/// the rule --defocus and --bokeh read their aperture by. False + `why`.
bool aperture_kernel_from(const OptionValues& v, Kernel& k, std::string& why);

}  // namespace bokeh
