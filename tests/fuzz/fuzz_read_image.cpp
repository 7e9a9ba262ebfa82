// fuzz_read_image.cpp — libFuzzer target: bokeh::read_image (the memory budget check of
// io_budget.cpp, then OIIO's read) on bytes from the fuzzer, as any format OIIO accepts
// (EXR scanline, tiled, multi-part and deep, PNG, ...). The bytes live in a memfd opened
// as /proc/self/fd/N, so no file is written per input.
//
// Built by `make fuzz` with clang-14 -fsanitize=fuzzer,address,undefined; our io sources
// are compiled into the target (instrumented), OIIO and OpenEXR come from Debian (not
// instrumented: libFuzzer sees no coverage inside them). The budget is 256 MiB so an
// input cannot make the fuzzer itself run out of memory (its default limit is 2 GiB).
#include <bokeh/io.h>

#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <string>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>

namespace {

int memory_file()
{
    static const int fd = memfd_create("bokeh_fuzz_input", 0);
    return fd;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    OIIO::attribute("threads", 1);
    OIIO::attribute("debug", 0);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const int fd = memory_file();
    if (fd < 0 || ftruncate(fd, 0) != 0 || pwrite(fd, data, size, 0) != ssize_t(size))
        return 0;
    const std::string path = "/proc/self/fd/" + std::to_string(fd);
    bokeh::ReadOptions opts;
    opts.memory_budget_bytes = int64_t(256) << 20;
    OIIO::ImageBuf buf;
    std::string err;
    if (bokeh::read_image(buf, path, opts, err) && !buf.deep())
        (void)buf.getchannel(buf.xbegin(), buf.ybegin(), 0, 0);  // the pixels are there
    return 0;
}
