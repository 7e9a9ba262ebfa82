// One API style (docs/architecture.md): every public image operation has ImageBufAlgo's two
// forms, `bool f(dst, ...)` with the error on dst and `ImageBuf f(...)` returning the image.
// Each value form is checked here against its dst form (the same pixels, bit for bit, flat
// or deep) and to carry a failed call's error on the image it returns.
#include <bokeh/blur.h>
#include <bokeh/deep.h>
#include <bokeh/defocus.h>
#include <bokeh/distortion.h>
#include <bokeh/lens.h>
#include <bokeh/lens_fit.h>
#include <bokeh/optics.h>
#include <bokeh/resample.h>
#include <bokeh/scene.h>
#include <bokeh/truth.h>

#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/imagebufalgo.h>

using namespace bokeh;

namespace {

// Same windows, channels and values, bit for bit (deep: the same samples).
void expect_same_image(const OIIO::ImageBuf& dst_form, const OIIO::ImageBuf& value_form, const char* what)
{
    ASSERT_FALSE(dst_form.has_error()) << what << ": " << dst_form.geterror();
    ASSERT_FALSE(value_form.has_error()) << what << ": " << value_form.geterror();
    ASSERT_TRUE(dst_form.initialized()) << what;
    const OIIO::ImageSpec &a = dst_form.spec(), &b = value_form.spec();
    ASSERT_EQ(a.channelnames, b.channelnames) << what;
    ASSERT_EQ(dst_form.roi(), value_form.roi()) << what;
    ASSERT_EQ(dst_form.deep(), value_form.deep()) << what;
    if (dst_form.deep()) {
        const OIIO::DeepData &da = *dst_form.deepdata(), &db = *value_form.deepdata();
        ASSERT_EQ(da.pixels(), db.pixels()) << what;
        for (int64_t p = 0; p < da.pixels(); ++p) {
            ASSERT_EQ(da.samples(p), db.samples(p)) << what << " pixel " << p;
            for (int c = 0; c < a.nchannels; ++c)
                for (int s = 0; s < int(da.samples(p)); ++s)
                    ASSERT_EQ(da.deep_value(p, c, s), db.deep_value(p, c, s)) << what << " pixel " << p;
        }
        return;
    }
    std::vector<float> pa(dst_form.roi().npixels() * size_t(a.nchannels)), pb(pa.size());
    ASSERT_TRUE(dst_form.get_pixels(dst_form.roi(), OIIO::TypeFloat, pa.data()));
    ASSERT_TRUE(value_form.get_pixels(value_form.roi(), OIIO::TypeFloat, pb.data()));
    EXPECT_EQ(std::memcmp(pa.data(), pb.data(), pa.size() * sizeof(float)), 0) << what;
}

void expect_error(const OIIO::ImageBuf& value_form, const char* what)
{
    EXPECT_TRUE(value_form.has_error()) << what << ": a failed call returns its error on the image";
}

SceneOptions small_scene()
{
    SceneOptions s;
    s.width  = 48;
    s.height = 27;
    s.aa     = 1;
    return s;
}

}  // namespace

TEST(ApiStyle, SceneResampleAndLensForms)
{
    const SceneOptions so = small_scene();
    OIIO::ImageBuf sharp;
    ASSERT_TRUE(make_scene(sharp, "lights", so, 2)) << sharp.geterror();
    expect_same_image(sharp, make_scene("lights", so, 2), "make_scene");
    OIIO::ImageBuf deep;
    ASSERT_TRUE(make_deep_scene(deep, "lights", so, 2)) << deep.geterror();
    expect_same_image(deep, make_deep_scene("lights", so, 2), "make_deep_scene");
    SceneTruthOptions t;
    t.lens.focus_distance = 6.0;
    t.spp                 = 4;
    OIIO::ImageBuf truth;
    ASSERT_TRUE(make_scene_truth(truth, "lights", so, t, nullptr, 2)) << truth.geterror();
    expect_same_image(truth, make_scene_truth("lights", so, t, nullptr, 2), "make_scene_truth");
    expect_error(make_scene("no such scene", so), "make_scene");

    OIIO::ImageBuf r;
    ASSERT_TRUE(reduce_to_size(r, sharp, 12, 7, {}, 2)) << r.geterror();
    expect_same_image(r, reduce_to_size(sharp, 12, 7, {}, 2), "reduce_to_size");
    ASSERT_TRUE(resize(r, sharp, 96, 54, {}, 2)) << r.geterror();
    expect_same_image(r, resize(sharp, 96, 54, {}, 2), "resize");
    ASSERT_TRUE(resample(r, sharp, 30, 20, true, 2)) << r.geterror();
    expect_same_image(r, resample(sharp, 30, 20, true, 2), "resample");
    expect_error(resize(OIIO::ImageBuf(), 4, 4), "resize");
    OIIO::ImageBuf low;
    ASSERT_TRUE(reduce(low, sharp, 2, {}, 2)) << low.geterror();
    ASSERT_TRUE(enlarge_depth_aware(r, low, sharp, 2.0, {}, 2)) << r.geterror();
    expect_same_image(r, enlarge_depth_aware(low, sharp, 2.0, {}, 2), "enlarge_depth_aware");

    LensDistortion barrel;
    barrel.k1 = -0.05;
    ASSERT_TRUE(lens_distort(r, sharp, barrel, DistortDirection::Distort, {}, 2)) << r.geterror();
    expect_same_image(r, lens_distort(sharp, barrel, DistortDirection::Distort, {}, 2), "lens_distort");
    ASSERT_TRUE(distortion_stmap(r, sharp.spec(), barrel, DistortDirection::Undistort, 2)) << r.geterror();
    expect_same_image(r, distortion_stmap(sharp.spec(), barrel, DistortDirection::Undistort, 2), "distortion_stmap");

    CocOptions coc;
    coc.lens.focus_distance = 6.0;
    ASSERT_TRUE(coc_map(r, sharp, coc, 2)) << r.geterror();
    expect_same_image(r, coc_map(sharp, coc, 2), "coc_map");
    ASSERT_TRUE(focal_plane_view(r, sharp, coc, 32.0f, 2)) << r.geterror();
    expect_same_image(r, focal_plane_view(sharp, coc, 32.0f, 2), "focal_plane_view");
    expect_error(coc_map(OIIO::ImageBuf(), coc), "coc_map");
}

TEST(ApiStyle, DefocusTruthAndDeepForms)
{
    const SceneOptions so = small_scene();
    const OIIO::ImageBuf sharp = make_scene("lights", so, 2), deep = make_deep_scene("edges", so, 2);
    DefocusOptions o;
    o.coc.lens.focus_distance = 6.0;
    OIIO::ImageBuf r;
    ASSERT_TRUE(defocus(r, sharp, o, nullptr, 2)) << r.geterror();
    expect_same_image(r, defocus(sharp, o, nullptr, 2), "defocus");
    ASSERT_TRUE(defocus(r, deep, o, nullptr, 2)) << r.geterror();
    expect_same_image(r, defocus(deep, o, nullptr, 2), "defocus (deep)");
    ASSERT_TRUE(defocus_coc_map(r, sharp, o, 2)) << r.geterror();
    expect_same_image(r, defocus_coc_map(sharp, o, 2), "defocus_coc_map");
    ASSERT_TRUE(layer_map(r, sharp, o, 2)) << r.geterror();
    expect_same_image(r, layer_map(sharp, o, 2), "layer_map");
    ASSERT_TRUE(defocus_scatter_reference(r, sharp, o, 2)) << r.geterror();
    expect_same_image(r, defocus_scatter_reference(sharp, o, 2), "defocus_scatter_reference");
    expect_error(defocus(OIIO::ImageBuf(), o), "defocus");

    TruthOptions t;
    t.coc.lens.focus_distance = 6.0;
    t.spp                     = 4;
    ASSERT_TRUE(defocus_truth(r, deep, t, nullptr, 2)) << r.geterror();
    expect_same_image(r, defocus_truth(deep, t, nullptr, 2), "defocus_truth");
    expect_error(defocus_truth(sharp, t), "defocus_truth");

    ASSERT_TRUE(deep_tidy(r, deep, {}, nullptr, 2)) << r.geterror();
    expect_same_image(r, deep_tidy(deep, {}, nullptr, 2), "deep_tidy");
    ASSERT_TRUE(deep_merge(r, { &deep, &deep }, true, {}, nullptr, 2)) << r.geterror();
    expect_same_image(r, deep_merge({ &deep, &deep }, true, {}, nullptr, 2), "deep_merge");
    ASSERT_TRUE(deep_holdout(r, deep, deep, {}, nullptr, 2)) << r.geterror();
    expect_same_image(r, deep_holdout(deep, deep, {}, nullptr, 2), "deep_holdout");
    ASSERT_TRUE(deep_slice(r, deep, 2.0, 8.0, {}, nullptr, 2)) << r.geterror();
    expect_same_image(r, deep_slice(deep, 2.0, 8.0, {}, nullptr, 2), "deep_slice");
    ASSERT_TRUE(deep_flatten(r, deep, {}, nullptr, 2)) << r.geterror();
    expect_same_image(r, deep_flatten(deep, {}, nullptr, 2), "deep_flatten");
    ASSERT_TRUE(deep_from_flat(r, sharp, 1.0f, 2)) << r.geterror();
    expect_same_image(r, deep_from_flat(sharp, 1.0f, 2), "deep_from_flat");
    expect_error(deep_tidy(sharp), "deep_tidy");
    expect_error(deep_slice(deep, 5.0, 1.0), "deep_slice");
}

TEST(ApiStyle, OpticsAndFitForms)
{
    LensCharacter lens;
    lens.preset = LensPreset::Uncorrected;
    PsfRequest req;
    req.coc_px = 21.0;
    OIIO::ImageBuf r;
    ASSERT_TRUE(lens_psf_image(r, lens, req, 2)) << r.geterror();
    expect_same_image(r, lens_psf_image(lens, req, 2), "lens_psf_image");
    ASSERT_TRUE(beam_map_image(r, lens, -20.0, 20.0, 64, 32, 2)) << r.geterror();
    expect_same_image(r, beam_map_image(lens, -20.0, 20.0, 64, 32, 2), "beam_map_image");
    ASSERT_TRUE(bokeh_sheet_image(r, lens, 20.0, 3, 2, 33, 2)) << r.geterror();
    expect_same_image(r, bokeh_sheet_image(lens, 20.0, 3, 2, 33, 2), "bokeh_sheet_image");
    expect_error(beam_map_image(lens, -20.0, 20.0, 0, 0), "beam_map_image");

    std::vector<LensFitCrop> crops(1);
    SyntheticCrop sc;
    sc.coc_px  = 24.0;
    sc.size_px = 63;
    std::string err;
    ASSERT_TRUE(synthetic_crop(crops[0], LensCharacter(), sc, err, 2)) << err;
    LensFit fit;
    ASSERT_TRUE(fit_lens(fit, crops, LensFitOptions(), err, 2)) << err;
    ASSERT_TRUE(lens_fit_model_image(r, fit, crops, 0, 2)) << r.geterror();
    expect_same_image(r, lens_fit_model_image(fit, crops, 0, 2), "lens_fit_model_image");
    ASSERT_TRUE(lens_fit_sheet(r, fit, crops, 2)) << r.geterror();
    expect_same_image(r, lens_fit_sheet(fit, crops, 2), "lens_fit_sheet");
    expect_error(lens_fit_model_image(fit, crops, 5), "lens_fit_model_image");
}

// Each options struct's public check passes its defaults (with what the operation needs
// set) and refuses a bad value naming it, as the operation itself refuses it.
TEST(ApiStyle, EveryOptionsStructHasItsCheck)
{
    std::string err;
    auto refused = [&](bool ok, const char* name) {
        EXPECT_FALSE(ok) << name;
        EXPECT_NE(err.find(name), std::string::npos) << name << ": " << err;
        err.clear();
    };
    Kernel k;
    k.width_px = k.height_px = 9.0f;
    EXPECT_TRUE(check_kernel(k, err)) << err;
    EXPECT_TRUE(check_blur_options(k, BlurOptions(), err)) << err;
    BlurOptions bo;
    bo.iris = 5000.0f;
    refused(check_blur_options(k, bo, err), "iris");
    OIIO::ImageBuf src = make_scene("lights", small_scene());
    EXPECT_FALSE(blur(src, k, bo).geterror().empty()) << "blur refuses what its check refuses";
    k.blades = 2;
    refused(check_kernel(k, err), "blades");
    EXPECT_TRUE(check_aperture(Kernel(), 1.0f, err)) << err;
    refused(check_aperture(Kernel(), 30.0f, err), "aspect");

    DefocusOptions d;
    d.coc.lens.focus_distance = 6.0;
    EXPECT_TRUE(check_defocus_options(d, err)) << err;
    d.aperture_views = 9;
    refused(check_defocus_options(d, err), "views");
    EXPECT_FALSE(defocus(src, d).geterror().empty());

    TruthOptions t;
    EXPECT_TRUE(check_truth_options(t, err)) << err;
    t.spp = 0;
    refused(check_truth_options(t, err), "spp");

    EXPECT_TRUE(check_scene_options("lights", small_scene(), err)) << err;
    SceneOptions so = small_scene();
    so.aa           = 40;
    refused(check_scene_options("lights", so, err), "aa");
    refused(check_scene_options("nowhere", small_scene(), err), "unknown scene");
    SceneTruthOptions st;
    st.lens.focus_distance = 6.0;
    EXPECT_TRUE(check_scene_truth_options(st, err)) << err;
    st.lens.focus_distance = 0.01;
    refused(check_scene_truth_options(st, err), "focus");

    EXPECT_TRUE(check_resample_options(ResampleOptions(), err)) << err;
    ResampleOptions ro;
    ro.blur_sigma = 100.0f;
    refused(check_resample_options(ro, err), "blur_sigma");
    EXPECT_FALSE(enlarge(src, 2.0, ro).geterror().empty());
    EXPECT_TRUE(check_depth_aware_options(DepthAwareOptions(), err)) << err;
    DepthAwareOptions da;
    da.sigma_depth = 0.0f;
    refused(check_depth_aware_options(da, err), "sigma_depth");

    EXPECT_TRUE(check_lens(LensCharacter(), err)) << err;
    LensCharacter lc;
    lc.fstop = 1000.0;
    refused(check_lens(lc, err), "f");
    EXPECT_TRUE(check_lens_fit_options(LensFitOptions(), err)) << err;
    LensFitOptions fo;
    fo.max_evaluations = 3;
    refused(check_lens_fit_options(fo, err), "max_evaluations");
}
