// lens_options.h — the lens-character options (`lens=achromat:diffraction=exact:...`) the
// commands that draw with a lens share (`--bokeh`), as OptionSpecs and as the
// LensCharacter they describe. The aperture and the camera are the caller's: each command
// already has its own spelling of them.
#pragma once

#include <bokeh/optics.h>
#include <bokeh/plugin.h>

#include <string>
#include <vector>

namespace bokeh {

/// The lens-character option specs (defaults: no character).
std::vector<OptionSpec> lens_option_specs();

/// Fill the aberration, spectrum, diffraction, onion-ring and field fields of `lens` from
/// `v` (aperture, aspect and camera untouched). False + `err` naming the option.
bool lens_character_from(const OptionValues& v, LensCharacter& lens, std::string& err);

}  // namespace bokeh
