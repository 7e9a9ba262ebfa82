// images.cpp — numpy arrays and OpenImageIO.ImageBufs in and out of the Python module
// (images.h).

#include "images.h"

#include <pybind11/stl.h>

#include <OpenImageIO/strutil.h>

namespace openbokeh_python {

using OIIO::Strutil::fmt::format;

bool have_oiio_module(std::string* why)
{
    static bool tried = false, found = false;
    static std::string error;
    if (!tried) {
        tried = true;
        try {
            py::module_::import("OpenImageIO");
            found = true;
        } catch (const py::error_already_set& e) {
            error = e.what();
        }
    }
    if (!found && why)
        *why = format("OpenImageIO's Python module (Debian: python3-openimageio) cannot be "
                      "imported: {}",
                      error);
    return found;
}

static std::string type_name(const py::object& obj)
{
    return py::str(py::type::of(obj).attr("__name__")).cast<std::string>();
}

static std::string shape_text(const py::array& a)
{
    std::vector<std::string> dims;
    for (py::ssize_t i = 0; i < a.ndim(); ++i)
        dims.push_back(std::to_string(a.shape(i)));
    return "(" + OIIO::Strutil::join(dims, ", ") + (a.ndim() == 1 ? ",)" : ")");
}

std::vector<std::string> channel_names(const py::object& channels, int count, const char* name)
{
    std::vector<std::string> names;
    if (channels.is_none()) {
        OIIO::ImageSpec spec(1, 1, count, OIIO::TypeFloat);
        names = spec.channelnames;
        if (count >= 5)
            names[4] = "Z";
        return names;
    }
    if (py::isinstance<py::str>(channels)) {
        for (const std::string& n : OIIO::Strutil::splits(channels.cast<std::string>(), ","))
            names.push_back(std::string(OIIO::Strutil::strip(n)));
    } else {
        try {
            names = channels.cast<std::vector<std::string>>();
        } catch (const py::cast_error&) {
            throw py::type_error(format("channels for argument '{}' must be a str (\"R,G,B,A,Z\") "
                                        "or a sequence of str, not {}",
                                        name, type_name(channels)));
        }
    }
    if (int(names.size()) != count)
        throw py::value_error(format("channels for argument '{}' names {} channel(s) ({}) but the "
                                     "array has {}",
                                     name, names.size(), OIIO::Strutil::join(names, ","), count));
    for (const std::string& n : names)
        if (n.empty())
            throw py::value_error(format("channels for argument '{}' has an empty name", name));
    return names;
}

// An array checked and wrapped (not copied): the ImageBuf reads the array's memory, which
// `owner` keeps alive for the call.
static ImageArg array_arg(const py::object& obj, const char* name, const py::object& channels)
{
    const py::array a = py::reinterpret_borrow<py::array>(obj);
    if (!py::isinstance<py::array_t<float>>(obj))
        throw py::type_error(format("argument '{}' has dtype {}; it must be float32 "
                                    "(convert with .astype(numpy.float32))",
                                    name, py::str(a.dtype()).cast<std::string>()));
    if (a.ndim() != 3)
        throw py::value_error(format("argument '{}' has {} dimension(s) {}; it must have 3, (H, W, C)"
                                     "{}",
                                     name, a.ndim(), shape_text(a),
                                     a.ndim() == 2 ? " (one channel: image[..., None])" : ""));
    if (!(a.flags() & py::array::c_style))
        throw py::value_error(format("argument '{}' is not C-contiguous (a slice with a step, a "
                                     "transpose or a reversed view); pass "
                                     "numpy.ascontiguousarray(...)",
                                     name));
    if (a.shape(0) < 1 || a.shape(1) < 1 || a.shape(2) < 1)
        throw py::value_error(format("argument '{}' has shape {}: no pixels", name, shape_text(a)));
    if (a.shape(0) > (1 << 30) || a.shape(1) > (1 << 30) || a.shape(2) > 1024)
        throw py::value_error(format("argument '{}' has shape {}: too large (at most 1024 channels)",
                                     name, shape_text(a)));
    const int height = int(a.shape(0)), width = int(a.shape(1)), count = int(a.shape(2));
    OIIO::ImageSpec spec(width, height, count, OIIO::TypeFloat);
    spec.channelnames  = channel_names(channels, count, name);
    spec.alpha_channel = spec.channelindex("A");
    spec.z_channel     = spec.channelindex("Z");
    ImageArg arg;
    arg.name   = name;
    arg.origin = name;
    arg.owner  = obj;
    // The library takes its inputs const; the wrapper's pointer is not written through.
    arg.buf = std::make_shared<OIIO::ImageBuf>(spec, const_cast<void*>(a.data()));
    return arg;
}

static bool is_imagebuf(const py::object& obj, std::string& why)
{
    if (!have_oiio_module())
        return false;
    const py::object cls = py::module_::import("OpenImageIO").attr("ImageBuf");
    if (!py::isinstance(obj, cls))
        return false;
    if (!py::detail::get_type_info(typeid(OIIO::ImageBuf)))
        why = "this OpenImageIO.ImageBuf cannot be reached from C++: OpenImageIO's Python module "
              "does not share pybind11's internals with this one (built with another compiler or "
              "pybind11 version)";
    return true;
}

static ImageArg checked_image_arg(const py::object& obj, const char* name, const py::object& channels,
                                  bool allow_array)
{
    std::string why;
    if (is_imagebuf(obj, why)) {
        if (!why.empty())
            throw py::type_error(format("argument '{}': {}", name, why));
        OIIO::ImageBuf& b = obj.cast<OIIO::ImageBuf&>();
        b.spec();  // a file-backed ImageBuf reads its header here
        if (!b.initialized() || b.has_error())
            throw py::value_error(format("argument '{}' is an ImageBuf without an image{}", name,
                                         b.has_error() ? " (" + b.geterror() + ")" : std::string()));
        if (!channels.is_none())
            throw py::value_error(format("channels= names an array's channels; argument '{}' is an "
                                         "ImageBuf, whose channels have names",
                                         name));
        ImageArg arg;
        arg.name          = name;
        arg.origin        = b.name().empty() ? std::string(name) : std::string(b.name());
        arg.owner         = obj;
        arg.from_imagebuf = true;
        if (!b.deep() && (b.spec().format != OIIO::TypeFloat || !b.localpixels())) {
            // As bokehtool reads a flat file: float pixels in memory (file-backed ImageBufs
            // read through the cache, half or integer pixels converted).
            py::gil_scoped_release release;
            arg.buf = std::make_shared<OIIO::ImageBuf>();
            if (!arg.buf->copy(b, OIIO::TypeFloat)) {
                py::gil_scoped_acquire acquire;
                throw py::value_error(format("argument '{}': cannot read its pixels: {}", name,
                                             arg.buf->geterror()));
            }
        } else {
            arg.buf = std::shared_ptr<OIIO::ImageBuf>(&b, [](OIIO::ImageBuf*) {});
        }
        return arg;
    }
    if (!why.empty())
        throw py::type_error(format("argument '{}': {}", name, why));
    if (!py::isinstance<py::array>(obj)) {
        std::string expected = allow_array ? "a numpy array (H, W, C) float32 or an OpenImageIO.ImageBuf"
                                           : "an OpenImageIO.ImageBuf (deep data is not an array)";
        std::string oiio;
        if (!have_oiio_module(&oiio))
            expected += " (" + oiio + ")";
        throw py::type_error(format("argument '{}' must be {}, not {}", name, expected, type_name(obj)));
    }
    if (!allow_array)
        throw py::type_error(format("argument '{}' must be a deep OpenImageIO.ImageBuf (deep data is "
                                    "not an array: read it with read_image, or make it with deepen), "
                                    "not a numpy array",
                                    name));
    return array_arg(obj, name, channels);
}

ImageArg image_arg(const std::string& function, const py::object& obj, const char* name,
                   const py::object& channels, bool allow_array)
{
    try {
        return checked_image_arg(obj, name, channels, allow_array);
    } catch (const py::type_error& e) {
        throw py::type_error(function + ": " + e.what());
    } catch (const py::value_error& e) {
        throw py::value_error(function + ": " + e.what());
    }
}

py::array image_to_array(const std::shared_ptr<OIIO::ImageBuf>& buf, bool owned)
{
    if (buf->deep())
        throw py::type_error("a deep image is not an array: keep it as an OpenImageIO.ImageBuf "
                             "(flatten makes it flat)");
    const OIIO::ROI roi = buf->roi();
    const py::ssize_t h = roi.height(), w = roi.width(), c = buf->nchannels();
    const py::ssize_t fs = sizeof(float);
    if (owned && buf->storage() == OIIO::ImageBuf::LOCALBUFFER
        && buf->spec().format == OIIO::TypeFloat && roi.depth() == 1 && buf->pixel_stride() == c * fs
        && buf->scanline_stride() == w * c * fs) {
        // Hand the buffer over: the array owns the ImageBuf through a capsule.
        auto* keep          = new OIIO::ImageBuf(std::move(*buf));
        const float* pixels = static_cast<const float*>(keep->localpixels());
        py::capsule free_it(keep, [](void* p) { delete static_cast<OIIO::ImageBuf*>(p); });
        return py::array_t<float>({ h, w, c }, { w * c * fs, c * fs, fs }, pixels, free_it);
    }
    py::array_t<float> out({ h, w, c });
    float* dst = out.mutable_data();
    bool ok;
    {
        py::gil_scoped_release release;
        ok = buf->get_pixels(roi, OIIO::TypeFloat, dst);
    }
    if (!ok)
        throw std::runtime_error(format("cannot read the result's pixels: {}", buf->geterror()));
    return std::move(out);
}

py::object image_to_imagebuf(const std::shared_ptr<OIIO::ImageBuf>& buf, bool owned)
{
    std::string why;
    if (!have_oiio_module(&why))
        throw std::runtime_error(why);
    if (!py::detail::get_type_info(typeid(OIIO::ImageBuf)))
        throw std::runtime_error("OpenImageIO's Python module does not share pybind11's internals "
                                 "with this one (built with another compiler or pybind11 version): "
                                 "its ImageBuf cannot be returned");
    if (owned && buf->storage() != OIIO::ImageBuf::APPBUFFER)
        return py::cast(std::move(*buf));
    OIIO::ImageBuf copy;
    copy.copy(*buf);
    return py::cast(std::move(copy));
}

}  // namespace openbokeh_python
