// defocus_options.h — `--defocus`'s option values made into bokeh::DefocusOptions. Shared
// by the defocus plugin and the Python module (python/), so that both take the same
// names, defaults and rules; the option specs themselves are the command's, registered
// by the plugin (the Python module reads them from the registry).
#pragma once

#include <bokeh/defocus.h>
#include <bokeh/plugin.h>

#include <memory>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// The thin lens as --defocus spells it: focus (a distance or a pixel x,y), fstop, focal,
/// sensor. Shared with --scene's geometric truth.
std::vector<OptionSpec> thin_lens_option_specs();

/// The aperture as --defocus spells it: kernel (disk, hex, polygon), blades, rotation,
/// curvature, hole, aspect. Shared with --scene's geometric truth.
std::vector<OptionSpec> defocus_aperture_option_specs();

/// The lens of thin_lens_option_specs() from `v`: each of focal length, film back,
/// f-number and focus distance from the option when given, else from the image's metadata
/// ("bokeh:focal_mm", "bokeh:sensor_width_mm", "bokeh:fstop", "bokeh:focus_m" in metres,
/// stored with any numeric type), else 50 mm, 36 mm, f/2.8 and 5. A recorded focus is
/// converted to the depth unit `coc.lens.depth_unit_mm` already holds. False + `err`
/// naming the option or the attribute.
bool thin_lens_from(const OptionValues& v, const OIIO::ImageSpec& spec, CocOptions& coc, std::string& err);

/// Fill `o` from `--defocus`'s option values `v` for an image with spec `spec`: its camera
/// metadata (thin_lens_from, as the built-in scenes write it) gives the lens unless the
/// options do. False + `err` naming the
/// option and why.
bool defocus_options_from(const OptionValues& v, const OIIO::ImageSpec& spec, DefocusOptions& o,
                          std::string& err);

/// `in`, or, when `v` names a depth channel (zchannel=), a copy of it whose spec makes
/// that channel its depth (z_channel). False + `err` when the image has no such channel.
bool with_named_depth(const OptionValues& v, const std::shared_ptr<OIIO::ImageBuf>& in,
                      std::shared_ptr<OIIO::ImageBuf>& out, std::string& err);

/// The lens-character options of `--defocus`: lens_option_specs() (lens=, diffraction=,
/// onion=, catseye=, ...) and highlights= (the sprite threshold), sprites= (their most).
/// Giving any of them switches lens character on.
std::vector<OptionSpec> defocus_sprite_option_specs();

/// The method `v` names: `quality=` and `method=` are one option under two spellings
/// (defocus_options_from refuses them when they disagree).
const std::string& defocus_method_named(const OptionValues& v);

}  // namespace bokeh
