// psf_cache.cpp — the PSFs a defocus reads (optics.h: PsfCache, shared_psf_cache):
// lens_psf's PSFs kept by (CoC, field) bin, or by exact request, for one lens; and the
// process's caches, one per lens, so the frames of a sequence build each PSF once.
//
// Bins: 1 / kPsfCocBinsPerOctave octave in |CoC| from 1 px (1/8 px below, sign kept) and
// 1/8 of the half-diagonal in field; a request takes its bin's PSF, built at the bin's centre.
// The sprites (core/defocus/defocus_sprites.cpp) crossfade the exact PSFs of two points of a
// finer CoC grid (psf_coc_steps_around: between bins, steps at most kPsfGridStepRadius_px
// apart in rim radius): one rim, where a crossfade of two bins 4.4 % apart drew two past
// about 12 px. The shared caches hold
// at most kSharedPsfCacheBytes over all lenses, the least recently used lens dropped
// first; a PSF is the same for any thread count, so a warm cache changes no result.
// Limits: a lens is found by comparing every field of LensCharacter (same_lens), a linear
// search over the lenses held (a handful in practice).

#include <bokeh/optics.h>

#include <algorithm>
#include <cmath>
#include <list>
#include <mutex>

namespace bokeh {

namespace {
std::tuple<int, int, int> bin_of(const PsfRequest& r)
{
    const double a = std::abs(r.coc_px);
    const int c    = a < 1.0 ? int(std::lround(8.0 * r.coc_px))
                             : (r.coc_px < 0 ? -1 : 1) * (100 + int(std::lround(kPsfCocBinsPerOctave * std::log2(a))));
    return { c, int(std::lround(8.0 * r.field_x)), int(std::lround(8.0 * r.field_y)) };
}

PsfRequest centre_of(const std::tuple<int, int, int>& key)
{
    PsfRequest r;
    const int c = std::get<0>(key);
    r.coc_px    = std::abs(c) < 100 ? c / 8.0 : (c < 0 ? -1.0 : 1.0) * std::exp2((std::abs(c) - 100) / double(kPsfCocBinsPerOctave));
    r.field_x   = std::get<1>(key) / 8.0;
    r.field_y   = std::get<2>(key) / 8.0;
    return r;
}
}  // namespace

PsfCache::PsfCache(LensCharacter lens, int nthreads)
    : m_lens(std::move(lens))
    , m_nthreads(nthreads)
{
}

namespace {
size_t psf_bytes(const Psf& p) { return sizeof(Psf) + p.rgb.size() * sizeof(float); }
}  // namespace

std::shared_ptr<const Psf> PsfCache::get(const PsfRequest& req, std::string& err)
{
    return get_exact(centre_of(bin_of(req)), err);
}

namespace {
// The grid's steps between bin b and b + 1 (psf_coc_steps_around), equal in log2 |CoC|: the
// widest is the last, r1 (1 - 2^(-1 / (n m))) in rim radius for the next bin's rim r1, so m
// is the least for which that is at most kPsfGridStepRadius_px.
double steps_after_bin(double b)
{
    const double n  = kPsfCocBinsPerOctave;
    const double r1 = 0.5 * std::exp2((b + 1.0) / n);
    if (r1 <= kPsfGridStepRadius_px)
        return 1.0;
    return std::max(1.0, std::ceil(-1.0 / (n * std::log2(1.0 - kPsfGridStepRadius_px / r1))));
}
}  // namespace

void psf_coc_steps_around(double coc_px, double& coc0_px, double& coc1_px, double& t)
{
    const double a = std::abs(coc_px), sign = coc_px < 0.0 ? -1.0 : 1.0;
    if (a < 1.0) {  // the cache's linear bins, 1/8 px (the last one's neighbour is 1 px)
        const double l = 8.0 * a, b0 = std::floor(l);
        coc0_px = sign * b0 / 8.0;
        coc1_px = sign * (b0 + 1.0) / 8.0;
        t       = l - b0;
        return;
    }
    const double n = kPsfCocBinsPerOctave;
    const double l = n * std::log2(a), b = std::floor(l);
    const double m = steps_after_bin(b);
    const double s = (l - b) * m, j = std::floor(s);
    coc0_px = sign * std::exp2((b + j / m) / n);
    coc1_px = sign * std::exp2((b + (j + 1.0) / m) / n);
    t       = s - j;
}

std::shared_ptr<const Psf> PsfCache::get_exact(const PsfRequest& req, std::string& err)
{
    const auto key = std::make_tuple(req.coc_px, req.field_x, req.field_y, req.size_px);
    {
        std::lock_guard<std::mutex> lock(m_mutex);
        auto it = m_psfs.find(key);
        if (it != m_psfs.end())
            return it->second;
    }
    auto psf = std::make_shared<Psf>();
    if (!lens_psf(*psf, m_lens, req, err, m_nthreads))
        return nullptr;
    std::lock_guard<std::mutex> lock(m_mutex);
    auto [it, added] = m_psfs.emplace(key, std::move(psf));
    m_bytes += added ? psf_bytes(*it->second) : 0;
    return it->second;
}

size_t PsfCache::size() const
{
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_psfs.size();
}

size_t PsfCache::bytes() const
{
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_bytes;
}

bool same_lens(const LensCharacter& a, const LensCharacter& b)
{
    const SpectrumOptions &sa = a.spectrum, &sb = b.spectrum;
    return a.preset == b.preset && a.aperture == b.aperture && a.aspect == b.aspect && a.fstop == b.fstop
           && a.focal_mm == b.focal_mm && a.pixel_pitch_mm == b.pixel_pitch_mm && a.monochromatic == b.monochromatic
           && a.chromatic == b.chromatic && a.correction == b.correction && a.spherochromatism == b.spherochromatism
           && a.diffraction == b.diffraction && sa.first_nm == sb.first_nm && sa.last_nm == sb.last_nm
           && sa.step_nm == sb.step_nm && sa.illuminant == sb.illuminant && a.onion == b.onion
           && a.onion_waves == b.onion_waves && a.onion_cycles == b.onion_cycles
           && a.onion_sharpness == b.onion_sharpness && a.onion_offset == b.onion_offset
           && a.onion_behind_stop == b.onion_behind_stop && a.surface_noise == b.surface_noise
           && a.catseye == b.catseye && a.field_curvature_px == b.field_curvature_px
           && a.astigmatism_px == b.astigmatism_px && a.anamorphic_focus_px == b.anamorphic_focus_px
           && a.lateral_r_px == b.lateral_r_px && a.lateral_b_px == b.lateral_b_px;
}

namespace {
struct SharedCaches {
    std::mutex mutex;
    std::list<std::shared_ptr<PsfCache>> lenses;  // most recently used first
};
SharedCaches& shared_caches()
{
    static SharedCaches caches;
    return caches;
}
}  // namespace

std::shared_ptr<PsfCache> shared_psf_cache(const LensCharacter& lens, int nthreads)
{
    SharedCaches& all = shared_caches();
    std::lock_guard<std::mutex> lock(all.mutex);
    auto it = std::find_if(all.lenses.begin(), all.lenses.end(),
                           [&](const std::shared_ptr<PsfCache>& c) { return same_lens(c->lens(), lens); });
    std::shared_ptr<PsfCache> cache;
    if (it != all.lenses.end() && (*it)->bytes() <= kSharedPsfCacheBytes) {
        cache = *it;
        all.lenses.erase(it);
    } else {
        if (it != all.lenses.end())
            all.lenses.erase(it);
        cache = std::make_shared<PsfCache>(lens, nthreads);
    }
    cache->set_threads(nthreads);
    all.lenses.push_front(cache);
    // Past the bound, the least recently used lenses go (not the one just asked for).
    size_t held = 0;
    for (auto c = all.lenses.begin(); c != all.lenses.end();) {
        held += (*c)->bytes();
        if (held > kSharedPsfCacheBytes && c != all.lenses.begin())
            c = all.lenses.erase(c);
        else
            ++c;
    }
    return cache;
}

void clear_shared_psf_caches()
{
    SharedCaches& all = shared_caches();
    std::lock_guard<std::mutex> lock(all.mutex);
    all.lenses.clear();
}

}  // namespace bokeh
