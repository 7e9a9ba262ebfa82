// scene_truth.cpp — the thin-lens truth of a built-in scene (scene.h, make_scene_truth):
// rays from the aperture through each pixel's point on the focus plane, traced against
// the scene's own geometry (scene_geometry.h).
//
// Geometry: the convention of the deep-image truth (truth.h) and the flat defocus, so the
// three compare pixel for pixel. A ray from sensor point P (pixels) with aperture offset s
// (ApertureSampler: px per px of CoC, y down) is at image position Q(z) = P - s c(z) at
// depth z, with the signed thin-lens CoC c(z) = K (1/z_f - 1/z), K = z_f CoC(infinity)
// (thin_lens_coc_px; docs/methods/optics.md, "The thin lens"). In ray tangents (t = 2 half_w / width per px,
// image y down, tangent y up) that ray is the straight line
//     X(z) = O + D z,  O = (s_x t K, -s_y t K, 0),  D = d(P) + (-s_x t K / z_f, s_y t K / z_f, 0)
// with d(P) the pinhole ray of P (d.z = 1): O is the point on the lens plane, the
// aperture's diameter t K being, for the scene's own 50 mm on 36 mm, (f / F) z_f / (z_f - f)
// (the pupil f / F times the focus magnification the CoC formula carries); every ray of
// a pixel meets the focus plane at z_f d(P). The lens breathes no image: the pinhole projection stays the
// scene's (50 mm on 36 mm) whatever focal length the CoC is computed with, as the flat and
// deep defocus read the same sharp frame.
//
// Sampling: truth_sampler.h's per-pixel Owen-scrambled Sobol' points with truth.cpp's
// seeds and halves, so for the same seed and spp both truths draw the same (P, s) pairs;
// the noise estimate is the two halves' difference, as truth.h's.
//
// Limits: opaque surfaces only (every surface is); no vignetting (the aperture is the same
// for every pixel); the CoC has no gains, in-focus range or limit (a real lens has none).

#include <bokeh/parallel.h>
#include <bokeh/scene.h>
#include <bokeh/truth.h>

#include "base/plane.h"
#include "scene/scene_geometry.h"
#include "base/progress.h"
#include "truth/truth_sampler.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>

#include <OpenImageIO/strutil.h>

namespace bokeh {

using detail::HitList;
using detail::Light;
using detail::SceneRay;
using OIIO::Strutil::fmt::format;

bool check_scene_truth_options(const SceneTruthOptions& o, std::string& err)
{
    const Lens& l = o.lens;
    if (l.depth_unit_mm != 1000.0) {
        err = format("the scenes' depths are in metres (depth_unit_mm 1000, not {})", l.depth_unit_mm);
        return false;
    }
    if (!(l.focal_mm > 0.0) || !std::isfinite(l.focal_mm) || !(l.fstop > 0.0) || !std::isfinite(l.fstop)
        || !(l.sensor_width_mm > 0.0) || !std::isfinite(l.sensor_width_mm)) {
        err = format("focal {} mm, f/{} and sensor {} mm must be positive and finite", l.focal_mm, l.fstop,
                     l.sensor_width_mm);
        return false;
    }
    if (!std::isfinite(l.focus_distance) || !(l.focus_distance * 1000.0 > l.focal_mm)) {
        err = format("focus {} m must be finite and beyond the focal length ({} mm)", l.focus_distance,
                     l.focal_mm);
        return false;
    }
    return detail::check_truth_rays(o.aperture, o.aspect, o.spp, err);
}

bool make_scene_truth(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts,
                      const SceneTruthOptions& lo, SceneTruthReport* report, int nthreads)
{
    const auto start = std::chrono::steady_clock::now();
    OIIO::ImageSpec spec;
    std::string err;
    if (!detail::scene_spec(name, opts, { "R", "G", "B", "A" }, spec, err) || !check_scene_truth_options(lo, err)) {
        dst.errorfmt("scene truth: {}", err);
        return false;
    }
    std::unique_ptr<detail::SceneGeometry> scene = detail::make_scene_geometry(name, opts);
    const double focus_m = lo.lens.focus_distance;
    // c(z) = K (1/z_f - 1/z): K from the CoC at infinity, K / z_f.
    const double K = focus_m * thin_lens_coc_px(lo.lens, std::numeric_limits<double>::infinity(), opts.width);
    auto coc_of    = [&](double z) { return K * (1.0 / focus_m - 1.0 / z); };
    // A ray from row y reaches half the CoC (times the aspect) above or below it.
    scene->widen_light_rows([&](const Light& l) {
        const double c = std::max(std::abs(coc_of(std::max(l.centre.z - l.radius, 1e-6))),
                                  std::abs(coc_of(l.centre.z + l.radius)));
        return 0.5 * c * double(lo.aspect) + 1.0;
    });

    OIIO::ImageBuf result(spec);
    detail::require_pixels(result);
    const ApertureSampler aperture = detail::truth_pupil(lo.aperture, lo.aspect);
    const detail::SobolTable& table = detail::sobol_table();
    const double tan_px = scene->tangent_per_px(), lens_tan = tan_px * K;
    const int n_first = (lo.spp + 1) / 2, n_second = lo.spp / 2;
    const double inv_n   = 1.0 / lo.spp;
    const int width = opts.width, height = opts.height;

    struct Part {
        detail::HalvesNoise noise;
        int64_t rays = 0;
        double zmin = std::numeric_limits<double>::infinity(), zmax = 0.0;
    };
    const int64_t row_chunk = 2, nchunks = (height + row_chunk - 1) / row_chunk;
    detail::ProgressCounter progress(lo.progress, double(nchunks));
    const Part total = parallel_reduce_chunks(
        0, height, row_chunk, nthreads, Part{},
        [&](int64_t y0, int64_t y1) {
            Part part;
            std::vector<const Light*> row_lights;
            HitList hits;
            double u[4];
            for (int y = int(y0); y < int(y1); ++y) {
                scene->lights_of_row(y, row_lights);
                float* row = static_cast<float*>(result.pixeladdr(0, y));
                for (int x = 0; x < width; ++x) {
                    const uint32_t px_seed = detail::pixel_seed(lo.seed, x, y);
                    double sum[2][4]       = {};
                    for (int half = 0; half < 2; ++half) {
                        detail::PixelSequence seq(table, detail::half_seed(px_seed, half));
                        const int n = half == 0 ? n_first : n_second;
                        for (int i = 0; i < n; ++i) {
                            seq.next(u);
                            const auto s = aperture(u[0], u[1]);
                            SceneRay r   = scene->ray(x + u[2], y + u[3]);
                            r.origin     = { s[0] * lens_tan, -s[1] * lens_tan, 0.0 };
                            r.dir.x -= s[0] * lens_tan / focus_m;
                            r.dir.y += s[1] * lens_tan / focus_m;
                            hits.reset(false);
                            scene->intersect(r, row_lights, hits);
                            const glm::dvec3 c = scene->colour(r, hits.nearest, row_lights);
                            part.zmin          = std::min(part.zmin, hits.nearest.z);
                            part.zmax          = std::max(part.zmax, hits.nearest.z);
                            sum[half][0] += c.r;
                            sum[half][1] += c.g;
                            sum[half][2] += c.b;
                            sum[half][3] += 1.0;
                            ++part.rays;
                        }
                    }
                    for (int c = 0; c < 4; ++c) {
                        row[size_t(x) * 4 + size_t(c)] = float((sum[0][c] + sum[1][c]) * inv_n);
                        if (n_second > 0)
                            part.noise.add(sum[0][c] / n_first, sum[1][c] / n_second);
                    }
                }
            }
            progress.add();
            return part;
        },
        [](Part& acc, const Part& p) {
            acc.noise.merge(p.noise);
            acc.rays += p.rays;
            acc.zmin = std::min(acc.zmin, p.zmin);
            acc.zmax = std::max(acc.zmax, p.zmax);
        });

    SceneTruthReport rep;
    rep.rays            = total.rays;
    rep.min_coc_px      = float(coc_of(total.zmin));
    rep.max_coc_px      = float(coc_of(total.zmax));
    const double values = double(width) * double(height) * 4.0;
    total.noise.figures(n_first, n_second, values, rep.noise_rmse, rep.noise_psnr_db);
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    rep.summary = format("scene truth: {} {}x{}, CoC {:.1f} .. {:.1f} px, {} spp, {} rays, noise RMS {:.3g} "
                         "({:.1f} dB), {:.2f} s",
                         name, width, height, rep.min_coc_px, rep.max_coc_px, lo.spp, rep.rays, rep.noise_rmse,
                         rep.noise_psnr_db, rep.seconds);
    dst = std::move(result);
    if (report)
        *report = std::move(rep);
    return true;
}

}  // namespace bokeh
