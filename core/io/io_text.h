// io_text.h — internal to the library: how the io family quotes OpenImageIO's messages.
#pragma once

#include <string>

#include <OpenImageIO/strutil.h>

namespace bokeh::detail {

/// OIIO error texts can span several lines and repeat the file name; the first line.
inline std::string first_line(std::string s)
{
    s = OIIO::Strutil::strip(s);
    const size_t nl = s.find('\n');
    return nl == std::string::npos ? s : s.substr(0, nl);
}

}  // namespace bokeh::detail
