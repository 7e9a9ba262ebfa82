// io_views.cpp — multi-view EXR: which channels belong to which view, a view picked for a
// whole command line, and the depth of the view a file shows first.
//
// OpenEXR's conventions ("Storing multi-view images in OpenEXR files", Kainz and Bogart,
// openexr.com): in a multipart file each part carries a "view" attribute; in a single-part
// file the "multiView" attribute lists the views, the first being the default, and a
// channel belongs to the view named by the component before its last ("right.Z",
// "diffuse.right.R"), else to the default view (so "R" and "Z" are the default view's).
// Stereo renders put each view's RGBA and its depth in parts of their own; read without a
// view chosen, part 0's view is the image (other views' channels prefixed by their view,
// io.h), and its depth, in a part of its own, is its "Z".

#include "io/io_views.h"

#include <algorithm>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

using OIIO::Strutil::fmt::format;

std::vector<std::string> multiview_list(const OIIO::ImageSpec& spec)
{
    std::vector<std::string> views;
    const OIIO::ParamValue* p = spec.find_attribute("multiView");
    if (!p || p->type().basetype != OIIO::TypeDesc::STRING)
        return views;
    // A string array is one value of arraylen strings.
    const int n = p->nvalues() * std::max(p->type().arraylen, 1);
    for (int i = 0; i < n; ++i)
        views.push_back(p->get_string_indexed(i));
    return views;
}

std::string channel_view(const std::string& name, const std::vector<std::string>& views, std::string& plain)
{
    plain            = name;
    const size_t end = name.rfind('.');
    if (end == std::string::npos || views.empty())
        return views.empty() ? std::string() : views.front();
    const size_t begin     = name.rfind('.', end - 1);
    const size_t from      = begin == std::string::npos ? 0 : begin + 1;
    const std::string view = name.substr(from, end - from);
    if (std::find(views.begin(), views.end(), view) == views.end())
        return views.front();
    plain = name.substr(0, from) + name.substr(end + 1);
    return view;
}

bool select_single_part_view(OIIO::ImageBuf& img, const std::string& path, const std::string& view,
                             std::string& err)
{
    const std::vector<std::string> views = multiview_list(img.spec());
    if (views.empty())
        return true;
    if (view.empty()) {  // the default view is the image: "left.R" is its "R"
        OIIO::ImageSpec& spec = img.specmod();
        for (std::string& name : spec.channelnames) {
            std::string plain;
            if (channel_view(name, views, plain) == views.front() && plain != name && spec.channelindex(plain) < 0)
                name = plain;
        }
        spec.alpha_channel = spec.channelindex("A");
        spec.z_channel     = spec.channelindex("Z");
        return true;
    }
    if (std::find(views.begin(), views.end(), view) == views.end()) {
        err = format("{}: no view '{}' (its views: {})", path, view, OIIO::Strutil::join(views, ", "));
        return false;
    }
    std::vector<int> order;
    std::vector<std::string> names;
    for (int c = 0; c < img.nchannels(); ++c) {
        std::string plain;
        if (channel_view(img.spec().channel_name(c), views, plain) == view) {
            order.push_back(c);
            names.push_back(plain);
        }
    }
    OIIO::ImageBuf cut;
    if (order.empty() || !OIIO::ImageBufAlgo::channels(cut, img, int(order.size()), order, {}, names)) {
        err = format("{}: view '{}' holds no channel", path, view);
        return false;
    }
    cut.specmod().alpha_channel = cut.spec().channelindex("A");
    cut.specmod().z_channel     = cut.spec().channelindex("Z");
    cut.specmod().erase_attribute("multiView");
    cut.specmod().attribute("view", view);
    img = std::move(cut);
    return true;
}

void name_first_view_depth(OIIO::ImageSpec& spec, int depth_of_first_view)
{
    if (spec.channelindex("Z") >= 0 || depth_of_first_view < 0)
        return;
    spec.channelnames[size_t(depth_of_first_view)] = "Z";
    spec.z_channel                                 = depth_of_first_view;
}

}  // namespace bokeh::detail
