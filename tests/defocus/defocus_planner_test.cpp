// The flat Layers method's planner (core/defocus/defocus_planner.cpp): the steps' plan as the
// report states it, the ladder a ratio asks for, and the predicted planner's choice (the
// cheapest predicted to clear the budget, the same for any thread count).
#include <bokeh/defocus.h>
#include <bokeh/metrics.h>
#include <bokeh/scene.h>

#include "test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

using namespace bokeh;
using bokeh_test::at;
using bokeh_test::run_defocus;

namespace {

// A built-in scene at 480x270 and the lens its metadata suggests.
struct Shot {
    OIIO::ImageBuf image;
    DefocusOptions o;
};
Shot shot(const std::string& name)
{
    Shot s;
    SceneOptions so;
    so.width  = 480;
    so.height = 270;
    EXPECT_TRUE(make_scene(s.image, name, so)) << s.image.geterror();
    s.o = bokeh_test::scene_lens(s.image.spec());
    return s;
}

}  // namespace

// The default (the budget's steps) reports its one plan, which is the plan it drew.
TEST(DefocusPlanner, TheStepsReportTheirOnePlan)
{
    Shot s = shot("lights");
    DefocusReport rep;
    run_defocus(s.image, s.o, &rep);
    ASSERT_EQ(rep.plans.size(), 1u);
    EXPECT_TRUE(rep.plans[0].chosen);
    EXPECT_EQ(size_t(rep.plans[0].layers), rep.layer_coc_px.size());
    EXPECT_EQ(rep.plans[0].min_reduced_coc_px, 24.0f) << "the 40 dB budget's smallest reduced kernel";
}

// ratio=r draws the geometric ladder 0, +-1, +-r, +-r^2 ... up to the extremes; ratio=1 the
// exact rungs: the reference's grid points around the frame's CoCs, with a rung at 0.
TEST(DefocusPlanner, ARatioDrawsItsLadderAndOneTheExactRungs)
{
    Shot s = shot("lights");
    s.o.method       = DefocusMethod::Layers;
    s.o.ladder_ratio = 2.0f;
    DefocusReport rep;
    run_defocus(s.image, s.o, &rep);
    std::vector<float> expected = { 0.0f };
    for (float side : { -1.0f, 1.0f }) {
        const float extreme = side < 0 ? -rep.min_coc_px : rep.max_coc_px;
        for (float r = 1.0f;; r *= 2.0f) {
            if (r >= extreme * 0.999f) {
                expected.push_back(side * extreme);
                break;
            }
            expected.push_back(side * r);
        }
    }
    std::sort(expected.begin(), expected.end());
    EXPECT_EQ(rep.layer_coc_px, expected);

    s.o.ladder_ratio = 1.0f;
    DefocusReport exact, ref;
    run_defocus(s.image, s.o, &exact);
    DefocusOptions r = s.o;
    r.method         = DefocusMethod::Reference;
    run_defocus(s.image, r, &ref);
    std::vector<float> with_zero = ref.layer_coc_px;
    if (!std::binary_search(with_zero.begin(), with_zero.end(), 0.0f))
        with_zero.insert(std::upper_bound(with_zero.begin(), with_zero.end(), 0.0f), 0.0f);
    EXPECT_EQ(exact.layer_coc_px, with_zero);
}

// planner=predicted weighs every plan and takes the cheapest whose predicted PSNR clears
// the budget; the plan it reports is the one it drew.
TEST(DefocusPlanner, ThePredictedPlanIsTheCheapestPredictedToMeetTheBudget)
{
    for (const char* name : { "lights", "edges", "giant" })
        for (float budget : { 30.0f, 40.0f, 50.0f }) {
            SCOPED_TRACE(std::string(name) + " at " + std::to_string(budget) + " dB");
            Shot s = shot(name);
            s.o.planner   = DefocusPlanner::Predicted;
            s.o.budget_db = budget;
            DefocusReport rep;
            run_defocus(s.image, s.o, &rep);
            ASSERT_GT(rep.plans.size(), 4u);
            const auto chosen = std::find_if(rep.plans.begin(), rep.plans.end(),
                                             [](const DefocusPlanEstimate& p) { return p.chosen; });
            ASSERT_NE(chosen, rep.plans.end());
            EXPECT_EQ(std::count_if(rep.plans.begin(), rep.plans.end(),
                                    [](const DefocusPlanEstimate& p) { return p.chosen; }),
                      1);
            EXPECT_EQ(size_t(chosen->layers), rep.layer_coc_px.size());
            double best_ms = 1e300, best_db = -1e300;
            for (const DefocusPlanEstimate& p : rep.plans) {
                EXPECT_TRUE(std::isfinite(p.predicted_ms) && p.predicted_ms > 0.0);
                if (p.predicted_psnr_db >= budget)
                    best_ms = std::min(best_ms, p.predicted_ms);
                best_db = std::max(best_db, p.predicted_psnr_db);
            }
            if (best_ms < 1e300) {
                EXPECT_GE(chosen->predicted_psnr_db, budget);
                EXPECT_EQ(chosen->predicted_ms, best_ms);
            } else {  // none is predicted to meet it: the most accurate
                EXPECT_EQ(chosen->predicted_psnr_db, best_db);
            }
            for (size_t i = 1; i < rep.plans.size(); ++i)
                EXPECT_LE(rep.plans[i - 1].predicted_ms, rep.plans[i].predicted_ms) << "cheapest first";
        }
}

// A higher budget never buys a cheaper plan, nor a less accurate one.
TEST(DefocusPlanner, AHigherBudgetBuysAtLeastAsMuch)
{
    Shot s = shot("lights");
    s.o.planner = DefocusPlanner::Predicted;
    double last_ms = 0.0, last_db = -1e300;
    for (float budget : { 25.0f, 35.0f, 45.0f, 55.0f }) {
        s.o.budget_db = budget;
        DefocusReport rep;
        run_defocus(s.image, s.o, &rep);
        const auto chosen = std::find_if(rep.plans.begin(), rep.plans.end(),
                                         [](const DefocusPlanEstimate& p) { return p.chosen; });
        ASSERT_NE(chosen, rep.plans.end());
        std::printf("[ figures  ] lights 480x270, budget %.0f dB: ratio %g, q %g, %d layers, predicted %.1f dB "
                    "in %.1f ms\n",
                    budget, chosen->ladder_ratio, chosen->min_reduced_coc_px, chosen->layers,
                    chosen->predicted_psnr_db, chosen->predicted_ms);
        EXPECT_GE(chosen->predicted_ms, last_ms);
        EXPECT_GE(chosen->predicted_psnr_db, std::min(last_db, double(budget)));
        last_ms = chosen->predicted_ms;
        last_db = chosen->predicted_psnr_db;
    }
}

// The plan, and so every pixel, is the same on 1 and 2 threads.
TEST(DefocusPlanner, ThePredictedPlanDoesNotDependOnTheThreadCount)
{
    Shot s      = shot("lights");
    s.o.planner = DefocusPlanner::Predicted;
    DefocusReport r1, r2;
    const OIIO::ImageBuf a = run_defocus(s.image, s.o, &r1, 1);
    const OIIO::ImageBuf b = run_defocus(s.image, s.o, &r2, 2);
    EXPECT_EQ(r1.layer_coc_px, r2.layer_coc_px);
    EXPECT_EQ(r1.layer_reduction, r2.layer_reduction);
    ASSERT_EQ(a.roi(), b.roi());
    int64_t differ = 0;
    const OIIO::ROI d = a.roi();
    for (int y = d.ybegin; y < d.yend; ++y)
        for (int x = d.xbegin; x < d.xend; ++x)
            for (int c = 0; c < a.nchannels(); ++c) {
                const float u = at(a, x, y, c), v = at(b, x, y, c);
                differ += std::memcmp(&u, &v, sizeof(float)) != 0;
            }
    EXPECT_EQ(differ, 0);
}

// A ratio outside 1..16 (but 0) is refused with its name.
TEST(DefocusPlanner, ABadRatioIsRefused)
{
    Shot s = shot("edges");
    for (float bad : { 0.5f, 17.0f, std::nanf("") }) {
        s.o.ladder_ratio = bad;
        OIIO::ImageBuf out;
        EXPECT_FALSE(defocus(out, s.image, s.o));
        EXPECT_NE(out.geterror().find("ladder ratio"), std::string::npos) << out.geterror();
    }
}
