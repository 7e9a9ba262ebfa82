// optics.h — lens character: the PSF of a real lens at a signed CoC and field position,
// from its aperture, aberrations (the light-beam map of Kawase's "Bokeh Deep Dive"),
// spectrum, diffraction fringes, onion rings and field effects (docs/methods/optics.md has
// the formulas and their sources).
//
// The model is geometric optics plus diffraction at the rim. A ray through the pupil at
// normalised radius s (0..1, the aperture's circumscribed circle) and direction psi lands
// on the sensor at the signed radius
//     r(s) = s (c / 2 - a(s, l)),   a(s, l) = NA LSA(s, l) / pixel_pitch      [px]
// along psi (negative: across the centre, as front bokeh are point-reflected), c the
// signed CoC in px and LSA the longitudinal aberration:
//     LSA(s, l) = chromatic LCA(l) + monochromatic SA3 (1 + spherochromatism dl) (s^2 - correction s^4)
// The intensity at image radius R is the density of the rays landing there, sum s ds /
// (R dR) (a column of the beam map, rotated about the axis and shaped by the aperture's
// edge distance, as the talk draws its bokeh). Many wavelengths are summed to RGB
// (spectrum.h). Diffraction multiplies the rim by the exact straight-edge law (Born & Wolf
// 8.7; the fringe scale from c_eff = 2 |dr/ds| at the rim, so aberrated beams get
// their own fringes). Field position adds the cat's eye (the pupil cut by a barrel circle
// shifted with the field height), field curvature, astigmatism (tangential and sagittal
// CoC differ: ovals that swap across focus) and the anamorphic squeeze and focus split.
//
// `LensPreset::Off` with every effect at its default is the plain aperture, the kernel
// the flat defocus uses (a test compares them). Only what the options turn on is
// computed: a lens without chromatic effects or diffraction is one wavelength.
#pragma once

#include <bokeh/aperture.h>
#include <bokeh/spectrum.h>

#include <map>
#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>

namespace bokeh {

/// A lens's design, which sets its aberrations' kind and size (docs/methods/optics.md).
enum class LensPreset {
    Off,          ///< no aberration (the plain aperture)
    Uncorrected,  ///< a singlet: under-corrected spherical aberration and the full axial
                  ///< colour of a BK7 lens (F-C focus spread ~ f / V)
    Achromat,     ///< a doublet: two wavelengths share a focus (secondary spectrum f / 2000),
                  ///< spherical aberration corrected at the rim with a zone left
    Apochromat,   ///< three wavelengths share a focus (a tenth of the achromat's colour)
};

/// How the rim's diffraction is modelled.
enum class DiffractionModel {
    Off,       ///< geometric rim
    EdgeLaw,   ///< the exact Fresnel straight-edge law at the rim
    PseudoMap,   ///< Kawase's pseudo-diffraction map ("Bokeh Deep Dive"; its fringes sit
               ///< 4-16 % off the exact ones, docs/methods/diffraction.md)
};

/// (same_lens, core/optics/lens_psf.cpp, compares every field: a new field goes there too.)
struct LensCharacter {
    LensPreset preset = LensPreset::Off;
    Aperture aperture;          ///< the stop's shape (round by default)
    double aspect = 1.0;        ///< anamorphic squeeze: bokeh height / width (0.05..20)

    // The camera the PSF is physically scaled by (the aberrations and fringes are in mm
    // on the sensor; the CoC in px).
    double fstop          = 2.0;
    double focal_mm       = 50.0;
    double pixel_pitch_mm = 36.0 / 1920.0;  ///< sensor width / image width

    // The talk's knobs, each a multiple of the preset's own amount.
    double monochromatic = 1.0;  ///< scales the spherical aberration (0 = none; negative
                                 ///< reverses its sign: marginal rays focus farther)
    double chromatic     = 1.0;  ///< scales the axial colour; negative reverses it
    /// The zonal correction: SA5 = -correction SA3, so LSA at the rim is SA3 (1 -
    /// correction); 0 uncorrected, 1 corrected at the rim, 1.6 over-corrected ("bubble"
    /// bokeh). Negative: the preset's own (uncorrected 0, achromat and apochromat 1.47,
    /// a double-Gauss 50 mm f/2's fit: SA5 / SA3 = 0.56 / 0.38).
    double correction       = -1.0;
    double spherochromatism = 0.0;  ///< relative change of SA3 per 100 nm above 587.6 nm

    DiffractionModel diffraction = DiffractionModel::Off;
    SpectrumOptions spectrum;

    // Onion rings (machining marks on aspheric elements): rings in the pupil, centre
    // offset with field.
    double onion            = 0.0;   ///< procedural ring contrast (0..1)
    double onion_waves      = 0.0;   ///< physical: ripple amplitude in waves; contrast by
                                     ///< the law 2 (2 pi a) sin(pi K^2 / (8 w))
    double onion_cycles     = 10.0;  ///< K, rings per pupil diameter
    double onion_sharpness  = 1.0;   ///< 1 = sinusoidal; larger = thin bright rings
    double onion_offset     = 0.3;   ///< ring-centre shift at the frame corner, pupil radii
    bool onion_behind_stop  = true;  ///< the rough element behind the stop (moves faster)
    double surface_noise    = 0.0;   ///< lens-surface noise contrast (0..1)

    // Field effects; field height H is 0 at the centre and 1 at the frame corner.
    double catseye            = 0.0;  ///< barrel circle offset at H = 1, pupil radii (0..1.5)
    double field_curvature_px = 0.0;  ///< CoC added at H = 1 (H^2 law), px
    double astigmatism_px     = 0.0;  ///< tangential minus sagittal CoC at H = 1, px;
                                      ///< negative: ovals along the tangent ("swirl")
    double anamorphic_focus_px = 0.0; ///< horizontal minus vertical CoC, px
    /// Lateral colour (magnification varying with wavelength): the red and blue images
    /// displaced radially against the green at the frame corner, px, growing linearly with
    /// H (a magnification: `--lensdistort`'s lateralr times the half-diagonal in px). A
    /// white point's R-B fringe at field H is |lateral_r_px - lateral_b_px| H px.
    double lateral_r_px = 0.0;
    double lateral_b_px = 0.0;
};

/// Names of the presets ("off", "uncorrected", "achromat", "apochromat").
bool lens_preset_named(const std::string& name, LensPreset& out);
const char* lens_preset_name(LensPreset p);

/// Check the description (f-stop, pitch, knobs and their ranges); false + `err` naming
/// the bad value.
bool check_lens(const LensCharacter& lens, std::string& err);

/// The longitudinal aberration LSA(s, l) of the lens in mm (positive: the ray focuses
/// behind the paraxial focus of the reference wavelength 587.6 nm).
double longitudinal_aberration_mm(const LensCharacter& lens, double s, double wavelength_nm);

/// Where one PSF is wanted.
struct PsfRequest {
    double coc_px  = 32.0;  ///< signed CoC: negative in front of focus
    double field_x = 0.0;   ///< field position, in units of the half-diagonal: H = |(x, y)|
    double field_y = 0.0;   ///< (x right, y up; H <= 1 inside the frame)
    /// Side of the square image in px (odd); 0: just large enough for the PSF.
    int size_px = 0;
};

/// A PSF as an RGB image: `width` x `height` (odd), centred, row-major, each channel
/// summing to 1.
struct Psf {
    int width = 0, height = 0;
    std::vector<float> rgb;  ///< 3 floats a pixel
    float at(int x, int y, int c) const { return rgb[(size_t(y) * width + x) * 3 + c]; }
};

/// The PSF of `lens` for `req`. False + `err` for an invalid lens or request (a PSF over
/// 8192 px across is refused: `size` with memory).
bool lens_psf(Psf& out, const LensCharacter& lens, const PsfRequest& req, std::string& err,
              int nthreads = 0);
/// The same as an RGB float image (its data window centred on (0, 0), as OIIO's
/// make_kernel, so it can serve as `--blur:kernel=image`).
bool lens_psf_image(OIIO::ImageBuf& dst, const LensCharacter& lens, const PsfRequest& req,
                    int nthreads = 0);
inline OIIO::ImageBuf lens_psf_image(const LensCharacter& lens, const PsfRequest& req, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    lens_psf_image(dst, lens, req, nthreads);
    return dst;
}

/// The light-beam map of Kawase's "Bokeh Deep Dive": U (x) the signed CoC from `coc_min_px`
/// to `coc_max_px`, V (y, up) the ray height, each column normalised by its own spread (the
/// largest landing radius) and its peak; RGB from the spectrum.
bool beam_map_image(OIIO::ImageBuf& dst, const LensCharacter& lens, double coc_min_px,
                    double coc_max_px, int width, int height, int nthreads = 0);
inline OIIO::ImageBuf beam_map_image(const LensCharacter& lens, double coc_min_px, double coc_max_px, int width,
                                     int height, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    beam_map_image(dst, lens, coc_min_px, coc_max_px, width, height, nthreads);
    return dst;
}

/// The PSF cache's CoC bins per octave of |CoC| (from 1 px; below, bins 1/8 px apart). A
/// sprite crossfades two points of a finer grid between them (psf_coc_steps_around).
constexpr int kPsfCocBinsPerOctave = 16;

/// The CoC grid sprites draw on (|CoC| >= 1 px): between two CoC bins, steps at most
/// this far apart in rim radius (px). At 0.5 a rim between two bins draws 0.16 px wider
/// than lens_psf's own at 64..67 px, at 0.25 0.14 px, with the bins alone 0.98 px
/// (DefocusSprites.ARimStaysOneRimBetweenCachedCocs); 0.25 built twice the PSFs (giant's
/// first frame at supersample 2 took 2.8x the plain defocus against 2.2x for the bins).
constexpr double kPsfGridStepRadius_px = 0.5;

/// The two points of the sprites' CoC grid around `coc_px` (signed) and the weight `t`
/// (0..1, linear in log2 |CoC|; in CoC below 1 px) of the second: below 1 px the cache's
/// linear bins (1/8 px apart), above it the bins cut into steps of at most
/// kPsfGridStepRadius_px in rim radius. A crossfade of two anti-aliased rims that close
/// is one rim: measured on the achromat with rim diffraction at 36 mm / 640 px pitch, the
/// crossfade of the grid's two PSFs is 45..48 dB (peak PSNR) from lens_psf at the CoC
/// itself over 33..130 px, where the bins' own crossfade fell from 44 to 23 dB (a rim drawn
/// twice); below 22 px the grid is the bins. A PSF radially resampled from the nearest bin
/// does worse below 20 px (its one-pixel anti-aliased edge is not band-limited: 32..38 dB
/// at 13.7 px with Lanczos-3), so each grid point is built by lens_psf
/// (PsfCache::get_exact).
void psf_coc_steps_around(double coc_px, double& coc0_px, double& coc1_px, double& t);

/// PSFs by (CoC, field) bin, built on first use (thread-safe). CoC bins are
/// 1 / kPsfCocBinsPerOctave octave apart (|CoC| >= 1 px; 1/8 px below; sign kept), field
/// bins 1/8 of the half-diagonal; a request takes its bin's PSF, built at the bin's centre.
class PsfCache {
public:
    explicit PsfCache(LensCharacter lens, int nthreads = 0);
    const LensCharacter& lens() const { return m_lens; }
    /// The PSF of the bin `req` falls in; null + `err` on failure.
    std::shared_ptr<const Psf> get(const PsfRequest& req, std::string& err);
    /// The PSF of exactly `req` (not its bin's centre), built once; null + `err`.
    std::shared_ptr<const Psf> get_exact(const PsfRequest& req, std::string& err);
    /// PSFs held, and their bytes.
    size_t size() const;
    size_t bytes() const;
    /// The threads a PSF is built with (lens_psf's `nthreads`).
    void set_threads(int nthreads) { m_nthreads = nthreads; }

private:
    LensCharacter m_lens;
    std::atomic<int> m_nthreads;
    mutable std::mutex m_mutex;
    // By exact request (a bin's PSF is its centre's request).
    std::map<std::tuple<double, double, double, int>, std::shared_ptr<const Psf>> m_psfs;
    size_t m_bytes = 0;
};

/// Whether two lenses draw the same PSFs: every field of LensCharacter equal.
bool same_lens(const LensCharacter& a, const LensCharacter& b);

/// The process's PSF cache for `lens` (built with `nthreads`), so that the frames of a
/// sequence, and repeated calls, draw their sprites and near-focus layers without
/// building the same PSFs again (a PSF is the same for any thread count, so reuse
/// changes no result). At most kSharedPsfCacheBytes are held over all lenses: past it
/// the least recently used lenses' caches are dropped, and a lens whose cache alone is
/// past it starts a new one.
constexpr size_t kSharedPsfCacheBytes = size_t(512) << 20;
std::shared_ptr<PsfCache> shared_psf_cache(const LensCharacter& lens, int nthreads);
/// Drop every shared PSF cache (a benchmark's cold start).
void clear_shared_psf_caches();

/// A contact sheet: PSFs across defocus (columns, from `coc_max_px` in front through focus
/// to `coc_max_px` behind) and field height (rows, centre to corner along the diagonal),
/// each in a `cell_px` square, RGB, each PSF scaled so its peak is 1 (for viewing).
bool bokeh_sheet_image(OIIO::ImageBuf& dst, const LensCharacter& lens, double coc_max_px,
                       int columns, int rows, int cell_px, int nthreads = 0);
inline OIIO::ImageBuf bokeh_sheet_image(const LensCharacter& lens, double coc_max_px, int columns, int rows,
                                        int cell_px, int nthreads = 0)
{
    OIIO::ImageBuf dst;
    bokeh_sheet_image(dst, lens, coc_max_px, columns, rows, cell_px, nthreads);
    return dst;
}

}  // namespace bokeh
