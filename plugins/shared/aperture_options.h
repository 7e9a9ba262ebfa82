// aperture_options.h — the rule the plugins that take an aperture (`--blur`, `--defocus`)
// share for its options: which of them each `kernel=NAME` uses. It lives with those
// plugins, not in the registry (core/plugin/plugin.cpp), which knows no kernel or algorithm.
#pragma once

#include <bokeh/aperture.h>
#include <bokeh/plugin.h>

#include <string>
#include <vector>

namespace bokeh {

/// The aperture's shape options: blades, rotation, curvature, hole, inner (the kernel
/// choice is the command's: its list of shapes differs, aperture_kernel_names() in every
/// command that takes an aperture).
std::vector<OptionSpec> aperture_shape_option_specs();

/// The apertures every command that takes one draws: disk, hex, polygon, star. A new
/// shape is one more name here and in aperture_kernel_from, and its Aperture factory.
std::vector<std::string> aperture_kernel_names();

/// The anamorphic squeeze of a depth-dependent aperture (`aspect`, bokeh height / width,
/// 0.05..20): --blur has none (its size is WxH).
OptionSpec aspect_option_spec();

/// The camera: fstop, focal, sensor. `from_image`: the command reads them from an image's
/// metadata when not given (--defocus, --scene's truth), which the help says.
std::vector<OptionSpec> camera_option_specs(bool from_image);

/// The aperture options `kernel=NAME` uses, as --blur and --defocus spell them (`sigma`,
/// `blades`, `rotation`, `curvature`, `hole`): false + `why` for the first one given
/// (of those `v` has) that the kernel would ignore (`kernel=hex:blades=5`, `kernel=disk:
/// rotation=30`), so it is refused rather than dropped unseen.
bool aperture_options_apply(const OptionValues& v, const std::string& kernel, std::string& why);

/// The disk, hex, polygon or star aperture `kernel=` names, with `blades`, `rotation`,
/// `curvature`, `hole` and `inner` from `v` (size left 0), after aperture_options_apply's
/// check: the rule every command reads its aperture by. False + `why`.
bool aperture_kernel_from(const OptionValues& v, Kernel& k, std::string& why);

}  // namespace bokeh
