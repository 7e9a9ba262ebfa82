// images.h — how the Python module takes and gives images: C-contiguous numpy arrays
// (H, W, C) float32, and OpenImageIO.ImageBuf objects (Debian's python3-openimageio, a
// pybind11 module whose ImageBuf this module reaches when both share pybind11's internals:
// the same g++ and pybind11). An array is wrapped, not copied, for the call; a wrong one
// is refused with an exception naming the argument and the reason.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <OpenImageIO/imagebuf.h>

namespace openbokeh_python {

namespace py = pybind11;

/// An image argument as the library takes it.
struct ImageArg {
    std::string name;       ///< the argument's name, for messages
    std::string origin;     ///< what it came from (the ImageBuf's file, else the name)
    py::object owner;       ///< the Python object whose pixels `buf` reads, kept alive
    std::shared_ptr<OIIO::ImageBuf> buf;
    bool from_imagebuf = false;  ///< given as an OpenImageIO.ImageBuf (else an array)
};

/// Import OpenImageIO's Python module once; false (and `why`) when it is not installed.
bool have_oiio_module(std::string* why = nullptr);

/// Take `obj` as the image argument `name`: an OpenImageIO.ImageBuf (flat ones not held
/// as local float pixels are copied to float, as bokehtool reads files), or, when
/// `allow_array`, a C-contiguous (H, W, C) float32 array whose channels are named by
/// `channels` (None: by count, see channel_names). TypeError for another type or dtype,
/// ValueError for another shape, a non-contiguous array or a broken ImageBuf; each message
/// begins "function: ".
ImageArg image_arg(const std::string& function, const py::object& obj, const char* name,
                   const py::object& channels, bool allow_array = true);

/// The channel names of an array with `count` channels: `channels` (None, a comma-separated
/// str or a sequence of str; its length must be `count`), else OpenImageIO's defaults for
/// the count (Y; R,G; R,G,B; R,G,B,A; R,G,B,A,channel4, ...) except that a fifth channel is
/// Z, the RGBA + Z layout of the scenes and the defocus.
std::vector<std::string> channel_names(const py::object& channels, int count, const char* name);

/// An image's data window as an (H, W, C) float32 array: when `owned` (the caller gives the
/// buffer away; it is left empty) and it holds local float pixels, without a copy (the
/// array keeps the buffer alive), else copied.
py::array image_to_array(const std::shared_ptr<OIIO::ImageBuf>& buf, bool owned);

/// `buf` as an OpenImageIO.ImageBuf object: moved when `owned` (left empty), else copied.
py::object image_to_imagebuf(const std::shared_ptr<OIIO::ImageBuf>& buf, bool owned);

}  // namespace openbokeh_python
