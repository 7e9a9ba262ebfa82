// scene_deep.cpp — a deep image of a built-in scene (scene.h, make_deep_scene): the
// surfaces each pixel's pinhole rays meet, visible and hidden, as point samples whose
// alpha is their share of the pixel's rays.
//
// Source: the coverage-to-alpha rule of deep compositing (a fragment covering n of the N
// rays still open in front of it gets alpha n / open, so that "over" weighs it n / N:
// "Interpreting OpenEXR Deep Pixels"; docs/methods/deep.md), applied per layer of a depth
// peel (Everitt, "Interactive Order-Independent Transparency", 2001: layer k + 1 is each
// ray's next surface behind layer k).
//
// Ours: the grouping (a layer's hits on one surface make one sample: colour the mean, Z the
// nearest, as the sharp render's "closest" depth; equal depths merged, so tidy finds
// nothing to merge), and the layer cut: layer k + 1 takes only hits deeper than every
// sample of layer k. Layer 1 ends with alpha 1 (its last group takes every ray still
// open), so what lies behind it cannot reach the flatten, which is the sharp scene up to
// float rounding (tests/scene/scene_truth_test.cpp). Point samples of a pixel are spread over its
// cell (truth.h), so a surface hidden by a nearer one in some rays but lying in front of
// the pixel's deepest visible sample has no place: it would show through in the flatten.
// It is left out (the surfaces behind foreground edges inside a pixel; behind a pixel the
// foreground covers wholly, every surface is kept). At most kMaxLayers layers.

#include <bokeh/deep.h>
#include <bokeh/parallel.h>
#include <bokeh/scene.h>

#include "scene/scene_geometry.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <OpenImageIO/deepdata.h>

namespace bokeh {

using detail::HitList;
using detail::Light;
using detail::SceneRay;

namespace {

constexpr int kMaxLayers = 8;

struct RayHit {
    double z;
    int key;  // the surface: a scene's own number, lights 1000 + their index
    glm::dvec3 colour;
};

struct Group {
    int key;
    int n;
    double zmin;
    glm::dvec3 sum;
};

struct DeepSample {
    float v[5];  // R, G, B (premultiplied), A, Z
};

// The samples of one pixel from its rays' hits (each ray's sorted by depth).
void pixel_samples(const std::vector<std::vector<RayHit>>& rays, std::vector<DeepSample>& out,
                   std::vector<size_t>& pos, std::vector<Group>& groups, std::vector<size_t>& taken)
{
    out.clear();
    pos.assign(rays.size(), 0);
    taken.assign(rays.size(), 0);
    double cut = -std::numeric_limits<double>::infinity();
    for (int layer = 0; layer < kMaxLayers; ++layer) {
        groups.clear();
        int open = 0;
        for (size_t r = 0; r < rays.size(); ++r) {
            size_t i = pos[r];
            while (i < rays[r].size() && !(float(rays[r][i].z) > float(cut)))
                ++i;
            taken[r] = i;
            if (i == rays[r].size())
                continue;
            ++open;
            const RayHit& h = rays[r][i];
            auto g = std::find_if(groups.begin(), groups.end(), [&](const Group& q) { return q.key == h.key; });
            if (g == groups.end())
                groups.push_back({ h.key, 1, h.z, h.colour });
            else {
                ++g->n;
                g->zmin = std::min(g->zmin, h.z);
                g->sum += h.colour;
            }
        }
        if (groups.empty())
            break;
        std::sort(groups.begin(), groups.end(), [](const Group& a, const Group& b) {
            return a.zmin < b.zmin || (a.zmin == b.zmin && a.key < b.key);
        });
        // Surfaces meeting at one depth make one sample (tidy would merge them otherwise).
        size_t m = 0;
        for (size_t g = 1; g < groups.size(); ++g) {
            if (float(groups[g].zmin) == float(groups[m].zmin)) {
                groups[m].n += groups[g].n;
                groups[m].sum += groups[g].sum;
            } else {
                groups[++m] = groups[g];
            }
        }
        groups.resize(m + 1);
        for (const Group& g : groups) {
            const double alpha = double(g.n) / double(open);
            const glm::dvec3 c = g.sum * (alpha / double(g.n));
            out.push_back({ { float(c.r), float(c.g), float(c.b), float(alpha), float(g.zmin) } });
            open -= g.n;
        }
        cut = groups.back().zmin;
        for (size_t r = 0; r < rays.size(); ++r)
            pos[r] = taken[r] < rays[r].size() ? taken[r] + 1 : taken[r];
    }
}

}  // namespace

bool make_deep_scene(OIIO::ImageBuf& dst, const std::string& name, const SceneOptions& opts, int nthreads)
{
    OIIO::ImageSpec spec;
    std::string err;
    if (!detail::scene_spec(name, opts, { "R", "G", "B", "A", "Z" }, spec, err)) {
        dst.errorfmt("deep scene: {}", err);
        return false;
    }
    std::unique_ptr<detail::SceneGeometry> scene = detail::make_scene_geometry(name, opts);
    const int width = opts.width, height = opts.height, aa = opts.aa;
    const Light* first_light = scene->lights().empty() ? nullptr : scene->lights().data();

    // Every row's samples, then one deep image of them.
    std::vector<std::vector<DeepSample>> rows(static_cast<size_t>(height));
    std::vector<uint32_t> counts(size_t(width) * size_t(height), 0);
    parallel_rows(OIIO::ROI(0, width, 0, height), nthreads, [&](int y0, int y1) {
        std::vector<const Light*> row_lights;
        HitList hits;
        std::vector<std::vector<RayHit>> rays(size_t(aa) * size_t(aa));
        std::vector<DeepSample> px;
        std::vector<size_t> pos, taken;
        std::vector<Group> groups;
        for (int y = y0; y < y1; ++y) {
            scene->lights_of_row(y, row_lights);
            std::vector<DeepSample>& row = rows[size_t(y)];
            for (int x = 0; x < width; ++x) {
                for (int j = 0; j < aa; ++j)
                    for (int i = 0; i < aa; ++i) {
                        const SceneRay r = scene->ray(x + (i + 0.5) / aa, y + (j + 0.5) / aa);
                        hits.reset(true);
                        scene->intersect(r, row_lights, hits);
                        std::stable_sort(hits.hits.begin(), hits.hits.end(),
                                         [](const detail::SceneHit& a, const detail::SceneHit& b) { return a.z < b.z; });
                        std::vector<RayHit>& list = rays[size_t(j) * size_t(aa) + size_t(i)];
                        list.clear();
                        for (const detail::SceneHit& h : hits.hits)
                            list.push_back({ h.z, h.light ? 1000 + int(h.light - first_light) : h.surface,
                                             scene->colour(r, h, row_lights) });
                    }
                pixel_samples(rays, px, pos, groups, taken);
                counts[size_t(y) * size_t(width) + size_t(x)] = uint32_t(px.size());
                row.insert(row.end(), px.begin(), px.end());
            }
        }
    });

    spec.deep = true;
    OIIO::ImageBuf deep(spec);
    OIIO::DeepData& dd = *deep.deepdata();
    dd.set_all_samples(counts);
    if (dd.pixels() > 0)
        (void)dd.data_ptr(0, 0, 0);  // OIIO allocates on the first non-const access
    parallel_rows(OIIO::ROI(0, width, 0, height), nthreads, [&](int y0, int y1) {
        for (int y = y0; y < y1; ++y) {
            size_t k = 0;
            const std::vector<DeepSample>& row = rows[size_t(y)];
            for (int x = 0; x < width; ++x) {
                const int64_t p = int64_t(y) * width + x;
                const int ns    = int(counts[size_t(p)]);
                for (int s = 0; s < ns; ++s, ++k) {
                    float* sp = static_cast<float*>(dd.data_ptr(p, 0, s));
                    std::copy(row[k].v, row[k].v + 5, sp);
                }
            }
        }
    });
    OIIO::ImageBuf tidy;
    if (!deep_tidy(tidy, deep, {}, nullptr, nthreads)) {
        dst.errorfmt("deep scene: {}", tidy.geterror());
        return false;
    }
    dst = std::move(tidy);
    return true;
}

}  // namespace bokeh
