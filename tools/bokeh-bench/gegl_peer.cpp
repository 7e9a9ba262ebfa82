// gegl_peer.cpp — gegl:lens-blur through GEGL's public C API (see gegl_peer.h for what
// the operation computes and how its result lines up with ours).

#include "gegl_peer.h"

#if defined(BOKEH_HAVE_GEGL) && BOKEH_HAVE_GEGL

#include <gegl.h>

#include <cmath>
#include <mutex>

namespace bokeh_bench {

namespace {

void set_error(std::string* error, std::string msg)
{
    if (error)
        *error = std::move(msg);
}

// GEGL is a process-wide engine: start it once and keep it until the process ends (the
// bench never calls gegl_exit, which would have to come after the last GEGL object is
// gone). The result of the first start is remembered, so a failure is reported each time.
bool start_gegl(std::string* error)
{
    static std::once_flag once;
    static std::string failure;
    std::call_once(once, [] {
        // Keep every tile in memory: a swap file would add disk I/O to the timing, and
        // without gegl_exit it would be left behind in ~/.cache. OpenCL stays off so the
        // peer is timed on the CPU like our methods (it is GEGL's default, stated here).
        g_object_set(gegl_config(), "swap", "RAM", "use-opencl", FALSE, nullptr);
        gegl_init(nullptr, nullptr);
        if (!gegl_has_operation("gegl:lens-blur"))
            failure = "GEGL has no gegl:lens-blur operation (its plug-ins are not installed?)";
    });
    if (!failure.empty()) {
        set_error(error, failure);
        return false;
    }
    return true;
}

}  // namespace

bool gegl_available() { return true; }

bool gegl_lens_blur(const float* rgba, int w, int h, float radius_px, int threads, float* out,
                    std::string* error, GeglAlpha alpha)
{
    if (!rgba || !out || w <= 0 || h <= 0) {
        set_error(error, "gegl_lens_blur: empty image or null pointer");
        return false;
    }
    if (!std::isfinite(radius_px) || radius_px < 0.0f) {
        set_error(error, "gegl_lens_blur: radius must be finite and >= 0");
        return false;
    }
    if (threads < 1 || threads > 64) {  // GeglConfig:threads accepts up to 64
        set_error(error, "gegl_lens_blur: threads must be 1..64");
        return false;
    }
    if (!start_gegl(error))
        return false;

    // The thread count is read when the work is split, so setting it per call lets one
    // run time several counts.
    g_object_set(gegl_config(), "threads", threads, nullptr);

    // babl converts between this format and the operation's own ("RGBA float", straight
    // alpha, in the input's space) on the way in and out.
    const Babl* format = babl_format(alpha == GeglAlpha::Premultiplied ? "RaGaBaA float"
                                                                       : "RGBA float");
    const GeglRectangle rect = { 0, 0, w, h };

    // A GEGL-owned tiled buffer, filled by copy: the way an application hands its pixels
    // to GEGL, so the copy is part of what is timed, as our own methods' conversions are.
    GeglBuffer* input = gegl_buffer_new(&rect, format);
    gegl_buffer_set(input, &rect, 0, format, rgba, GEGL_AUTO_ROWSTRIDE);

    GeglNode* graph  = gegl_node_new();
    GeglNode* source = gegl_node_new_child(graph, "operation", "gegl:buffer-source",
                                           "buffer", input, nullptr);
    // Highlights off (factor 0 gives every tap weight 1: a plain disk). clip = FALSE
    // reads past the edges as transparent black, i.e. our Border::Black; we ask only
    // for the w x h input rectangle, not the grown bounding box that clip = FALSE gives.
    GeglNode* blur = gegl_node_new_child(graph, "operation", "gegl:lens-blur",
                                         "radius", double(radius_px),
                                         "highlight-factor", 0.0,
                                         "clip", FALSE, nullptr);
    gegl_node_link(source, blur);
    g_object_unref(input);  // the source node holds its own reference

    // GEGL computes nothing until pixels are asked for: the blit renders the rectangle
    // (split over the worker threads) and converts it into `out`.
    gegl_node_blit(blur, 1.0, &rect, format, out, GEGL_AUTO_ROWSTRIDE, GEGL_BLIT_DEFAULT);

    g_object_unref(graph);  // frees the nodes and, through the source, the input buffer
    return true;
}

}  // namespace bokeh_bench

#else  // GEGL not found at build time

namespace bokeh_bench {

bool gegl_available() { return false; }

bool gegl_lens_blur(const float*, int, int, float, int, float*, std::string* error, GeglAlpha)
{
    if (error)
        *error = "GEGL not available at build time";
    return false;
}

}  // namespace bokeh_bench

#endif
