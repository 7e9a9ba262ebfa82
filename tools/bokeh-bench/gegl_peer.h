// gegl_peer.h — GEGL's gegl:lens-blur as a peer in bokeh-bench, timed in this process.
//
// What gegl:lens-blur (GEGL 0.4.42, operations/common-cxx/lens-blur.cc) computes with
// highlights off, and so what this peer is compared with:
//   * a hard-edged disk, not anti-aliased: offset (dx, dy) is in the kernel when
//     dx^2 + dy^2 <= (radius + 0.5)^2, every tap weight 1. For an integer radius r that
//     is our Disk of width_px = height_px = 2 r + 1 with KernelEdge::Hard (centre test
//     against radius r + 0.5); a radius of 30 is a disk 61 pixels across.
//   * it works in straight "RGBA float" and weights colour by alpha: straight RGB out =
//     sum(a c) / sum(a), A out = sum(a) / N, N the taps counted; so premultiplied out =
//     sum(a c) / N, a plain average of premultiplied RGBA. Handing it our premultiplied
//     frames (babl converts them to and from straight alpha) is therefore the same filter
//     as ours, which blurs premultiplied RGBA channel by channel. One exception: colour on
//     a pixel of alpha 0 (pure emission) is lost, as straight alpha cannot carry it.
//   * edges: we set clip = FALSE, so taps outside the image are read as transparent black
//     and counted in N: on premultiplied data that is our Border::Black. (GEGL's default,
//     clip = TRUE, drops those taps and renormalises, which none of our borders does.)
//
// The GEGL dependency is optional: without it (BOKEH_HAVE_GEGL undefined or 0) both
// functions report that GEGL is missing and the bench leaves the peer out.
#pragma once

#include <string>

namespace bokeh_bench {

/// How the colour of the RGBA floats handed to gegl_lens_blur relates to their alpha.
enum class GeglAlpha {
    Premultiplied,  ///< colour already multiplied by alpha: OpenBokeh's working images
    Straight,       ///< colour not multiplied by alpha
};

/// True when GEGL was found at build time (gegl_peer.cpp is then compiled with
/// -DBOKEH_HAVE_GEGL=1). It does not start GEGL.
bool gegl_available();

/// Blur a w x h interleaved RGBA float image (linear light, 4 floats a pixel, rows top
/// to bottom, no padding) with gegl:lens-blur of `radius_px`, highlights off (a plain
/// disk, see above), on `threads` GEGL worker threads (1..64). Writes w * h * 4 floats
/// to `out` (which must not overlap `rgba`) in the same alpha convention as the input.
/// The whole job is done inside the call (GEGL is lazy; the blit forces it), so timing
/// the call times the blur plus the copies into and out of GEGL's buffers.
///
/// Where every tap of a pixel's disk has alpha 0, GEGL's straight colour is 0 / 0: that
/// pixel's colour comes back NaN (frames with alpha 1 everywhere never hit this).
///
/// GEGL is started on the first call and left running; its thread count is global, so
/// call this from one thread at a time. Returns false with a message in *error (when
/// `error` is not null) on failure, and when GEGL was not available at build time.
bool gegl_lens_blur(const float* rgba, int w, int h, float radius_px, int threads, float* out,
                    std::string* error, GeglAlpha alpha = GeglAlpha::Premultiplied);

}  // namespace bokeh_bench
