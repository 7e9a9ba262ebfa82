// fit_stages.h — the lens fit's search (core/fit/lens_fit.cpp drives it): the stages over
// the crops' model (fit/fit_model.h), each kept by its price; the least-squares steps
// after them (Levenberg-Marquardt, the uncertainties: fit_least_squares.cpp).
#pragma once

#include "fit/fit_model.h"

#include <string>
#include <vector>

namespace bokeh {
namespace fit {

// The noise floor a stage searches under (graduated non-convexity: fit_model.h), a
// fraction of each crop's light level.
inline constexpr double kSearchFloorOfLevel = 0.02;

// BIC's price of a parameter, k ln(N) / 2, times this: the PSF's 0.5 px radial bins make
// the cost rough at the 0.1 %-of-light level, and at the plain price the round trips of
// tests/fit/lens_fit_test.cpp (which print each stage's costs) kept holes and onion rings
// their crops do not have. At 4 they keep fewer; not none (a 9-blade aperture of
// curvature 0.74 on a round front bokeh with spherical aberration).
inline constexpr double kPriceFactor = 4.0;

// A CoC's bounds about its first estimate from the highlight's moments: spherical
// aberration moves the rim by up to the CoC itself before rays cross (a bright centre
// reads as a small highlight, a bright rim as a large one).
inline constexpr double kCocLow = 0.25, kCocHigh = 3.0;

// The crops a stage searches on (the rest join the final polish): 8 crops of 96 px took
// 2.6 times as long as 3 with all of them searched.
inline constexpr size_t kSearchCrops = 3;

// A stage's shared parameter: where it lives in the State, its bounds, grid of starts.
struct StageParam {
    const char* name;
    double State::*field;
    double lo, hi, step;
    std::vector<double> starts;
};


class Fitter {
public:
    Fitter(std::vector<CropData>& crops, const LensFitOptions& opts, int nthreads)
        : m_crops(crops), m_opts(opts), m_model(crops, opts, nthreads)
    {
        for (const CropData& d : crops) {
            m_s.coc.push_back(d.coc0);
            m_s.cx.push_back(d.cx0);
            m_s.cy.push_back(d.cy0);
        }
        use_all_crops();
    }
    void count_residuals();

    State& state() { return m_s; }
    const State& state() const { return m_s; }
    const Model& model() const { return m_model; }
    std::vector<std::string>& log() { return m_log; }
    double price(int k) const { return kPriceFactor * 0.5 * k * std::log(std::max(m_residuals, 2.0)); }
    int left() const { return std::max(0, m_opts.max_evaluations - m_model.evaluations()); }
    double cost() const { return m_model.cost(m_s, true, m_active); }

    // The stages search on the crops that show the most (a large, bright bokeh above its
    // noise): at most kSearchCrops of them; the final polish takes them all.
    void choose_search_crops(double read2, double photon);
    void use_all_crops();
    size_t searched() const { return m_active.size(); }

    // Each crop's CoC and centre, the lens held.
    // `search`: first under the search floor; `scan`: each CoC first from a scan.
    double refine_crops(int evaluations_each, bool search = false, bool scan = false);

    // Free the shared `params` (from their current values), those kept by earlier stages
    // and every CoC; the best cost.
    double polish(const std::vector<StageParam>& params, int evaluations);

    // A stage: the cost with what is kept polished; the best grid start (each parameter's
    // starts tried in turn, the others at their best); the polish; kept when the cost
    // falls by more than the parameters' price.
    bool stage(const char* name, const std::vector<StageParam>& params);

    // A stage for `added` with the kept parameter `again` searched from its grid at each
    // of `added`'s starts (the CoCs refitted): for a parameter whose effect a kept one's
    // other basin mimics (onion rings and a larger CoC with less spherical aberration).
    // `min_gain`: kept only when the cost also falls by this fraction of itself.
    bool joint_stage(const char* name, const StageParam& added, const StageParam& again, double min_gain = 0.0);

    const std::vector<StageParam>& kept() const { return m_kept; }

    // The crops' centres, free while a field effect is fitted (a cut pupil's light is
    // not centred where a round one's is), within 4 px of the crop's first estimate.
    void add_centres(std::vector<Free>& f);
    void free_centres(bool on) { m_free_centres = on; }
    void centres_at_light(bool on) { m_model.set_centres_at_light(on); }

    // Only the CoCs free, a few evaluations a crop; the best cost.
    double polish_cocs(int evaluations_each);

    // The aperture: each blade count's best rotation on a grid, briefly polished; the best
    // counts polished fully, the best kept against round.
    bool aperture_stage();

private:
    // Crop i's CoC as a free parameter, bounded about its first estimate, first step
    // `step_of_coc` of it (+ 0.2 px).
    Free coc_free(size_t i, double step_of_coc);
    // Each of `p`'s starts from `from` (the CoCs refitted, `cocs_evaluations` a crop) under
    // the search floor; the state left at the best of them, or as it was when none costs
    // under `best`; the best cost.
    double best_start(const StageParam& p, const State& from, double best, int cocs_evaluations);

    std::vector<CropData>& m_crops;
    const LensFitOptions& m_opts;
    Model m_model;
    State m_s;
    double m_residuals = 0.0;
    std::vector<std::string> m_log;
    std::vector<StageParam> m_kept;  // continuous shared parameters of the stages kept
    bool m_free_centres = false;
    std::vector<size_t> m_active;  // the crops the cost sums
};

/// The rotation brought into one blade period, [0, 360 / blades) (round: untouched).
void wrap_rotation(State& s);

/// Crop i's weighted residuals sqrt(w) r (empty when its PSF is refused).
std::vector<double> crop_residuals(const Model& model, const State& s, size_t i, bool coarse);
/// Every crop's weighted residuals, a block a crop (the crops in parallel).
std::vector<std::vector<double>> residual_blocks(const Model& model, const State& s, bool coarse, int nthreads);
/// The blocks one after another.
std::vector<double> residuals(const Model& model, const State& s, bool coarse = false, int nthreads = 0);

/// Levenberg-Marquardt on the weighted residuals over `fields` (held within lo..hi), every
/// CoC and every centre; at most `iterations` steps.
void levenberg_marquardt(const Model& model, State& s, const std::vector<double State::*>& fields,
                         const std::vector<double>& lo, const std::vector<double>& hi, int iterations, int nthreads);

/// One-sigma uncertainties of `fields` (returned) and of every CoC (`coc_sigma`) from
/// s^2 (J^T J)^-1 at `s` (the camera's own spectral step).
std::vector<double> uncertainties(const Model& model, const State& s, const std::vector<double State::*>& fields,
                                  std::vector<double>& coc_sigma, int nthreads);

}  // namespace fit
}  // namespace bokeh
