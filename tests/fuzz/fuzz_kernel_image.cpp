// fuzz_kernel_image.cpp — libFuzzer target: the image-kernel path of `--blur:kernel=image`
// and `--convolve`: a kernel image either read from the fuzzer's bytes as a file
// (bokeh::read_image with a 64 MiB budget: EXR, PNG, ...) or built from them pixel by
// pixel (1..9 x 1..9, 1..4 channels, values from a table of meaningful ones, 0, negative,
// denormal, 3e38, NaN, +-inf, or four raw bytes as a float); optionally resized to the
// bokeh's size as the command does (bokeh::resize); then bokeh::check_kernel_image and
// bokeh::convolve_image on a small finite source of 1, 3 or 4 channels, plain or in iris
// mode, black or clamped border, with or without grow.
//
// Checked on every run (abort: a finding), besides ASan and UBSan:
// * check_kernel_image and convolve_image agree (the first is the second's kernel checks);
// * a kernel accepted gives a finite output on a finite source;
// * a kernel of non-negative weights gives a weighted mean: every output value lies within
//   the source channel's range, to 1e-4 of that range (iris mode included: a mean in exp space).
//
// Instrumented: core/io/io.cpp, io_budget.cpp, blur_fft.cpp and resample.cpp; the rest of
// libOpenBokeh is the Release build's.
#include <bokeh/blur.h>
#include <bokeh/io.h>
#include <bokeh/resample.h>

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
const float kWeights[16] = { 1, 0, 0.5f, 2, 1, 0.25f, -1, 1e-30f, 1e-45f, 3e38f, -3e38f, std::nanf(""), kInf, -kInf, 100, 1 };

[[noreturn]] void finding(const char* what, double value = 0)
{
    std::fprintf(stderr, "fuzz_kernel_image: %s (%g)\n", what, value);
    std::abort();
}

class Bytes {
public:
    Bytes(const uint8_t* d, size_t n) : m_d(d), m_n(n) {}
    uint8_t next() { return m_i < m_n ? m_d[m_i++] : 0; }
    float value()
    {
        const uint8_t s = next();
        if (s < 240)
            return kWeights[s % 15];
        uint8_t b[4] = { next(), next(), next(), next() };
        float f;
        std::memcpy(&f, b, 4);
        return f;
    }
    const uint8_t* rest(size_t& n) const
    {
        n = m_n - std::min(m_i, m_n);
        return m_d + std::min(m_i, m_n);
    }

private:
    const uint8_t* m_d;
    size_t m_n, m_i = 0;
};

bool read_kernel_file(const uint8_t* data, size_t size, OIIO::ImageBuf& kernel)
{
    static const int fd = memfd_create("bokeh_fuzz_kernel", 0);
    if (fd < 0 || ftruncate(fd, 0) != 0 || pwrite(fd, data, size, 0) != ssize_t(size))
        return false;
    bokeh::ReadOptions opts;
    opts.memory_budget_bytes = int64_t(64) << 20;
    std::string err;
    return bokeh::read_image(kernel, "/proc/self/fd/" + std::to_string(fd), opts, err)
           && !kernel.deep();
}

void build_kernel(Bytes& in, OIIO::ImageBuf& kernel)
{
    const int w = 1 + in.next() % 9, h = 1 + in.next() % 9, nch = 1 + in.next() % 4;
    OIIO::ImageSpec spec(w, h, nch, OIIO::TypeFloat);
    if (nch == 4)
        spec.channelnames = { "R", "G", "B", "A" }, spec.alpha_channel = 3;
    std::vector<float> px(size_t(w) * size_t(h) * size_t(nch));
    for (float& v : px)
        v = in.value();
    kernel.reset(spec);
    kernel.set_pixels(OIIO::ROI::All(), OIIO::TypeFloat, px.data());
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
    if (size > 65536)
        return 0;
    Bytes in(data, size);
    const uint8_t mode = in.next(), how = in.next(), resize_to = in.next();
    OIIO::ImageBuf kernel;
    if (mode & 1) {
        size_t n = 0;
        const uint8_t* file = in.rest(n);
        if (!read_kernel_file(file, n, kernel))
            return 0;
        // A large picture is legal but slow to convolve: the fuzzer's time goes to the
        // reader and the checks, the size is resize's business below.
        if (int64_t(kernel.spec().width) * kernel.spec().height > 64 * 64 && !(resize_to & 0x80))
            return 0;
    } else {
        build_kernel(in, kernel);
    }
    if (resize_to & 0x80) {  // --blur:kernel=image WxH: resized to the bokeh's size first
        OIIO::ImageBuf resized;
        const int w = 1 + resize_to % 7, h = 1 + (resize_to >> 3) % 7;
        if (!bokeh::resize(resized, kernel, w, h, {}, 1))
            return 0;  // refused with a message (a zero-channel kernel, say): that is allowed
        kernel = std::move(resized);
    }

    const int src_nch = (how & 3) == 0 ? 1 : (how & 3) == 1 ? 3 : 4;
    OIIO::ImageSpec spec(12, 10, src_nch, OIIO::TypeFloat);
    OIIO::ImageBuf src(spec);
    float lo[4], hi[4];
    for (int c = 0; c < src_nch; ++c)
        lo[c] = kInf, hi[c] = -kInf;
    for (int y = 0; y < 10; ++y)
        for (int x = 0; x < 12; ++x) {
            float px[4];
            for (int c = 0; c < src_nch; ++c) {
                px[c] = float(((x * 7 + y * 13 + c * 5) % 11)) * 0.1f + (c == 3 ? 0.0f : 0.05f);
                lo[c] = std::min(lo[c], px[c]);
                hi[c] = std::max(hi[c], px[c]);
            }
            src.setpixel(x, y, 0, px, src_nch);
        }
    bokeh::BlurOptions opts;
    opts.iris   = (how & 4) ? 2.0f : 0.0f;
    opts.border = (how & 8) ? bokeh::Border::Clamp : bokeh::Border::Black;
    opts.grow   = (how & 16) != 0;

    std::string err;
    const bool accepted = bokeh::check_kernel_image(kernel, src_nch, opts, err);
    OIIO::ImageBuf dst;
    const bool done = bokeh::convolve_image(dst, src, kernel, opts, {}, 1);
    if (accepted != done) {
        std::fprintf(stderr, "check: %s / convolve: %s\n", err.c_str(), dst.geterror().c_str());
        finding(accepted ? "a kernel check_kernel_image accepts fails in convolve_image"
                         : "a kernel check_kernel_image refuses is convolved");
    }
    if (!done)
        return 0;

    bool nonnegative = true;
    for (OIIO::ImageBuf::ConstIterator<float> it(kernel); !it.done(); ++it)
        for (int c = 0; c < kernel.nchannels(); ++c)
            nonnegative &= it[c] >= 0.0f;
    // With a black border the outside counts as 0 (a value of the range only with grow or
    // the border reached): widen the range to 0 then.
    for (int c = 0; c < src_nch; ++c)
        if (opts.border == bokeh::Border::Black)
            lo[c] = std::min(lo[c], 0.0f);
    if (std::getenv("BOKEH_FUZZ_VERBOSE")) {  // what a finding is: the kernel and the result
        std::fprintf(stderr, "kernel %dx%d, %d channels, iris %g, border %d, grow %d:", kernel.spec().width,
                     kernel.spec().height, kernel.nchannels(), double(opts.iris), int(opts.border), int(opts.grow));
        for (OIIO::ImageBuf::ConstIterator<float> it(kernel); !it.done(); ++it)
            for (int c = 0; c < kernel.nchannels(); ++c)
                std::fprintf(stderr, " %g", double(it[c]));
        std::fprintf(stderr, "\n");
        for (OIIO::ImageBuf::ConstIterator<float> it(dst); !it.done(); ++it)
            for (int c = 0; c < dst.nchannels(); ++c)
                if (!std::isfinite(it[c]) || std::fabs(it[c]) > 2)
                    std::fprintf(stderr, "  out (%d, %d) channel %d: %g\n", it.x(), it.y(), c, double(it[c]));
    }
    for (OIIO::ImageBuf::ConstIterator<float> it(dst); !it.done(); ++it)
        for (int c = 0; c < dst.nchannels(); ++c) {
            const float v = it[c];
            if (!std::isfinite(v))
                finding("a non-finite output from a finite source", v);
            const float tol = 1e-4f * (hi[c] - lo[c]) + 1e-6f;
            if (nonnegative && (v < lo[c] - tol || v > hi[c] + tol))
                finding("a non-negative kernel's output outside the source's range", v);
        }
    return 0;
}
