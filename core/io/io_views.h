// io_views.h — internal to the library: the views of a multi-view EXR (core/io/io_views.cpp).
#pragma once

#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh::detail {

/// The views a single-part file's "multiView" attribute lists (the first is the default);
/// empty when it lists none.
std::vector<std::string> multiview_list(const OIIO::ImageSpec& spec);

/// The view of channel `name` in a single-part multi-view file (OpenEXR's convention: the
/// component before the last when it names a view, "right.Z" and "diffuse.right.R", else
/// the default view), and the name without that component in `plain`.
std::string channel_view(const std::string& name, const std::vector<std::string>& views, std::string& plain);

/// `img` (a single-part image read from `path`) cut to view `view`'s channels, each named
/// without its view; `view` empty: the default view's channels named without it (where
/// the plain name is free), the others' kept. A file that lists no views is left alone.
/// False + `err` naming the file and its views when it has no such view.
bool select_single_part_view(OIIO::ImageBuf& img, const std::string& path, const std::string& view,
                             std::string& err);

/// A merged multipart image without a "Z" whose parts of its first part's view (or of no
/// view) hold exactly one channel whose own name is "Z" (`depth_of_first_view`: its index
/// in the merged image, else -1): that channel is the view's depth and takes the name "Z".
void name_first_view_depth(OIIO::ImageSpec& spec, int depth_of_first_view);

}  // namespace bokeh::detail
