// deep.h — deep-image compositing by the OpenEXR rules: tidy, merge, holdout, flatten,
// deepen, slice.
//
// The rules are those of "Interpreting OpenEXR Deep Pixels" (OpenEXR documentation) and
// Hillman, "The Theory of OpenEXR Deep Samples": a sample with Z < ZBack is a volume of
// constant density over [Z, ZBack), any other sample a point at Z; a volume split at a
// fraction x of its depth keeps alpha 1 - (1 - a)^x and colour scaled with its alpha;
// coincident samples merge with the -log1p(-a) weights; tidy = split, merge, sort. Where
// OpenImageIO 2.4 departs from them (no tidy before flatten, culling behind single opaque
// samples in merge, holdout at the first opaque sample), these functions follow the rules
// (docs/methods/deep.md lists the differences; tests/deep/deep_test.cpp shows each).
//
// Channels: Z and ZBack (or Zback) are depths; A, AR, AG, AB are alphas; R, G, B take AR,
// AG, AB where present and A otherwise; every other float or half channel is a colour
// premultiplied by A; unsigned-int channels (sample ids) are carried unchanged. Results
// keep the input's channel types (half colour, float Z), names and windows.
//
// Errors follow ImageBufAlgo: false and the message on `dst`.
#pragma once

#include <cstdint>
#include <vector>

#include <OpenImageIO/imagebuf.h>

#include <bokeh/image.h>

namespace bokeh {

/// Samples a deep operation repaired (under NonFinitePolicy::Zero) or found (under
/// NonFinitePolicy::Error, which then fails naming the first).
struct DeepRepairs {
    int64_t nan_depth   = 0;  ///< samples with a NaN or -inf Z or ZBack: dropped
    int64_t back_before = 0;  ///< samples with ZBack < Z: made points at Z
    int64_t nonfinite   = 0;  ///< NaN or infinite colour or alpha values: set to 0
    int64_t total() const { return nan_depth + back_before + nonfinite; }
};

/// Options shared by the deep operations. Each takes a `DeepRepairs* report` (may be null)
/// for what it repaired, as the defocus and the truth take theirs.
struct DeepOptions {
    NonFinitePolicy nonfinite = NonFinitePolicy::Zero;  ///< bad samples: repaired and counted, or refused
};

/// Tidy `src` into `dst`: every volume split where another sample of its pixel starts or
/// ends, coincident samples merged, samples sorted by Z then ZBack (a point before a
/// volume that starts at its depth). Flattening is unchanged by tidying.
bool deep_tidy(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DeepOptions& opt = {},
               DeepRepairs* report = nullptr, int nthreads = 0);
inline OIIO::ImageBuf deep_tidy(const OIIO::ImageBuf& src, const DeepOptions& opt = {}, DeepRepairs* report = nullptr,
                                int nthreads = 0)
{
    OIIO::ImageBuf dst;
    deep_tidy(dst, src, opt, report, nthreads);
    return dst;
}

/// Merge any number of deep images (their samples pooled per pixel, then tidied). They
/// must have the same channel names (in any order; the first image's order and types are
/// kept), except that point passes without ZBack merge with volume passes: their samples
/// get ZBack = Z and the result is laid out as the first image with ZBack. The data
/// window is the union of theirs. With `cull`, samples behind the depth
/// where the accumulated opacity rounds to 1 in float (transmittance <= 2^-25) are dropped.
bool deep_merge(OIIO::ImageBuf& dst, const std::vector<const OIIO::ImageBuf*>& srcs,
                bool cull = false, const DeepOptions& opt = {}, DeepRepairs* report = nullptr,
                int nthreads = 0);
inline OIIO::ImageBuf deep_merge(const std::vector<const OIIO::ImageBuf*>& srcs, bool cull = false,
                                 const DeepOptions& opt = {}, DeepRepairs* report = nullptr, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    deep_merge(dst, srcs, cull, opt, report, nthreads);
    return dst;
}

/// Hold `src` out by `holdout`: every sample of `src` (tidied, volumes split where the
/// holdout's samples start or end) has its colour and alpha multiplied by the holdout's
/// transmittance in front of it. A holdout point at a sample's depth counts as in front
/// (an opaque image held out by itself is empty); a holdout volume over the same depth
/// range as a volume piece is mixed with it exactly (its emission meets the holdout medium
/// on the way). The samples' alphas are then set so that the result flattens to the exact
/// held-out image, colour and alpha (for a lone sample: alpha times the transmittance).
/// The result stays deep.
bool deep_holdout(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const OIIO::ImageBuf& holdout,
                  const DeepOptions& opt = {}, DeepRepairs* report = nullptr, int nthreads = 0);
inline OIIO::ImageBuf deep_holdout(const OIIO::ImageBuf& src, const OIIO::ImageBuf& holdout,
                                   const DeepOptions& opt = {}, DeepRepairs* report = nullptr, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    deep_holdout(dst, src, holdout, opt, report, nthreads);
    return dst;
}

/// Keep the part of every sample inside [znear, zfar): volumes straddling an end are split
/// there, points kept when znear <= Z < zfar. Slices at consecutive ranges merge back into
/// the slice of their union.
bool deep_slice(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, double znear, double zfar,
                const DeepOptions& opt = {}, DeepRepairs* report = nullptr, int nthreads = 0);
inline OIIO::ImageBuf deep_slice(const OIIO::ImageBuf& src, double znear, double zfar, const DeepOptions& opt = {},
                                 DeepRepairs* report = nullptr, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    deep_slice(dst, src, znear, zfar, opt, report, nthreads);
    return dst;
}

/// Flatten (--flatten; OIIO's ImageBufAlgo::flatten): tidy, then composite front to back
/// with "over" (each colour through its own alpha's transmittance). The flat image has the
/// deep one's channels (float); Z is the nearest depth and ZBack the farthest of the
/// visible samples (a non-zero alpha, in front of an accumulated opacity that float stores
/// as 1; all samples when none has alpha), 1e30 (OIIO's value) in pixels without samples;
/// unsigned-int channels come from the nearest such sample.
bool deep_flatten(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, const DeepOptions& opt = {},
                  DeepRepairs* report = nullptr, int nthreads = 0);
inline OIIO::ImageBuf deep_flatten(const OIIO::ImageBuf& src, const DeepOptions& opt = {}, DeepRepairs* report = nullptr,
                                   int nthreads = 0)
{
    OIIO::ImageBuf dst;
    deep_flatten(dst, src, opt, report, nthreads);
    return dst;
}

/// Deepen a flat image (--deepen; OIIO's ImageBufAlgo::deepen): one sample a pixel holding its channel values, none where every
/// non-depth channel is 0 and the depth is 0, not finite or >= 1e30 (OIIO's rule); Z =
/// `z_without_depth` when the image has no Z channel. Channel types come from the flat
/// image's native spec (half stays half).
bool deep_from_flat(OIIO::ImageBuf& dst, const OIIO::ImageBuf& src, float z_without_depth = 1.0f,
                    int nthreads = 0);
inline OIIO::ImageBuf deep_from_flat(const OIIO::ImageBuf& src, float z_without_depth = 1.0f, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    deep_from_flat(dst, src, z_without_depth, nthreads);
    return dst;
}

}  // namespace bokeh
