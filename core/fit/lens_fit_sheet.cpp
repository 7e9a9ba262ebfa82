// lens_fit_sheet.cpp — what a lens fit looks like (lens_fit.h): each crop's model
// rendered as the crop (the fitted light over its background plane), and the comparison
// sheet of crop, fit, difference and fitted light.

#include <bokeh/lens_fit.h>

#include "fit/fit_model.h"

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh {

using namespace fit;
using OIIO::Strutil::fmt::format;

namespace {

// Crop `index`'s fit over its data window, RGB a pixel: the fitted light (amplitude x PSF)
// and the background plane apart. False + `err`.
bool crop_fit(std::vector<double>& light, std::vector<double>& background, const LensFit& fit,
              const std::vector<LensFitCrop>& crops, int index, std::string& err, int nthreads)
{
    if (index < 0 || size_t(index) >= crops.size() || size_t(index) >= fit.crops.size())
        return err = format("crop {} of {}", index + 1, crops.size()), false;
    const OIIO::ImageSpec& cs  = crops[size_t(index)].image.spec();
    const LensFitCropResult& r = fit.crops[size_t(index)];
    PsfRequest req;
    req.coc_px = r.coc_px, req.field_x = r.field_x, req.field_y = r.field_y;
    Psf p;
    if (!lens_psf(p, fit.lens, req, err, nthreads))
        return false;
    CropData d;
    d.w = cs.width, d.h = cs.height;
    std::vector<float> smp;
    Model::sample(smp, p, d, r.centre_x, r.centre_y);
    const size_t n = size_t(d.w) * d.h;
    light.resize(n * 3);
    background.resize(n * 3);
    for (int j = 0; j < d.h; ++j)
        for (int i = 0; i < d.w; ++i)
            for (int c = 0; c < 3; ++c) {
                const size_t k         = size_t(j) * d.w + i;
                light[k * 3 + c]      = r.amplitude[c] * smp[c * n + k];
                background[k * 3 + c] = r.background[c] + r.background_dx[c] * plane_x(d, i)
                                        + r.background_dy[c] * plane_y(d, j);
            }
    return true;
}

}  // namespace

bool lens_fit_model_image(OIIO::ImageBuf& dst, const LensFit& fit, const std::vector<LensFitCrop>& crops, int index,
                          int nthreads)
{
    std::vector<double> light, background;
    std::string err;
    if (!crop_fit(light, background, fit, crops, index, err, nthreads))
        return dst.errorfmt("lens_fit_model_image: {}", err), false;
    const OIIO::ImageSpec& cs = crops[size_t(index)].image.spec();
    OIIO::ImageSpec spec(cs.width, cs.height, 3, OIIO::TypeDesc::FLOAT);
    spec.x = cs.x, spec.y = cs.y, spec.full_x = cs.full_x, spec.full_y = cs.full_y;
    spec.full_width = cs.full_width, spec.full_height = cs.full_height;
    dst.reset(spec);
    std::vector<float> rgb(light.size());
    for (size_t k = 0; k < rgb.size(); ++k)
        rgb[k] = float(light[k] + background[k]);
    dst.set_pixels(dst.roi(), OIIO::TypeDesc::FLOAT, rgb.data());
    return true;
}

bool lens_fit_sheet(OIIO::ImageBuf& dst, const LensFit& fit, const std::vector<LensFitCrop>& crops, int nthreads)
{
    if (crops.empty() || fit.crops.size() != crops.size())
        return dst.errorfmt("lens_fit_sheet: {} crops for a fit of {}", crops.size(), fit.crops.size()), false;
    constexpr int kGutter = 2;
    int cell_w = 0, height = kGutter;
    for (const LensFitCrop& c : crops) {
        cell_w = std::max(cell_w, c.image.spec().width);
        height += c.image.spec().height + kGutter;
    }
    const int width = 4 * cell_w + 5 * kGutter;
    dst.reset(OIIO::ImageSpec(width, height, 3, OIIO::TypeDesc::FLOAT));
    OIIO::ImageBufAlgo::zero(dst);
    int y = kGutter;
    for (size_t i = 0; i < crops.size(); ++i) {
        const OIIO::ImageSpec& cs = crops[i].image.spec();
        std::vector<double> light, background;
        std::string err;
        if (!crop_fit(light, background, fit, crops, int(i), err, nthreads))
            return dst.errorfmt("lens_fit_sheet: {}", err), false;
        const int channels = std::min(cs.nchannels, 3);
        for (int j = 0; j < cs.height; ++j)
            for (int x = 0; x < cs.width; ++x) {
                float crop[3], cells[4][3];
                crops[i].image.getpixel(cs.x + x, cs.y + j, crop, channels);
                const size_t k = size_t(j) * cs.width + x;
                for (int c = 0; c < 3; ++c) {
                    const float v      = crop[channels == 3 ? c : 0];
                    const float fitted = float(light[k * 3 + c] + background[k * 3 + c]);
                    cells[0][c]        = v;
                    cells[1][c]        = fitted;
                    cells[2][c]        = 4.0f * std::abs(v - fitted);
                    cells[3][c]        = float(light[k * 3 + c]);
                }
                for (int k2 = 0; k2 < 4; ++k2)
                    dst.setpixel(kGutter + k2 * (cell_w + kGutter) + x, y + j, 0, cells[k2], 3);
            }
        y += cs.height + kGutter;
    }
    return true;
}

}  // namespace bokeh
