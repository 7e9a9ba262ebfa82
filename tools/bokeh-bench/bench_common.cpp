// bench_common.cpp — see bench_common.h.

#include "bench_common.h"

#include <bokeh/resample.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/strutil.h>

namespace bokeh_bench {

std::string error_fields(const bokeh::ImageError& e)
{
    return OIIO::Strutil::fmt::format("{:.6g},{:.2f},{:.6g}", e.rmse_linear, e.psnr_db, e.max_abs);
}

double masked_psnr(const OIIO::ImageBuf& got, const OIIO::ImageBuf& ref, const std::vector<uint8_t>& in,
                   const OIIO::ROI& roi, int threads)
{
    const int64_t n = std::count(in.begin(), in.end(), uint8_t(1));
    if (n == 0)
        return -1.0;
    OIIO::ImageBuf masked = got;
    for (int y = roi.ybegin; y < roi.yend; ++y)
        for (int x = roi.xbegin; x < roi.xend; ++x)
            if (!in[size_t(y - roi.ybegin) * size_t(roi.width()) + size_t(x - roi.xbegin)]) {
                float v[4];
                ref.getpixel(x, y, v, 4);
                masked.setpixel(x, y, v, 4);
            }
    bokeh::ImageError e;
    std::string why;
    bokeh::compare(e, masked, ref, why, {}, threads);
    return e.psnr_db + 10.0 * std::log10(double(n) / double(roi.npixels()));
}

OIIO::ROI most_varied_crop(const OIIO::ImageBuf& img, int w, int h, int threads)
{
    constexpr int b = 8;
    w = std::min(w, img.roi().width());
    h = std::min(h, img.roi().height());
    const OIIO::ImageBuf small = bokeh::reduce(img, b, {}, threads);
    const OIIO::ROI r          = small.roi();
    const int bw = w / b, bh = h / b;
    std::vector<double> lum(size_t(r.width()) * size_t(r.height()));
    for (OIIO::ImageBuf::ConstIterator<float> p(small); !p.done(); ++p)
        lum[size_t(p.y() - r.ybegin) * size_t(r.width()) + size_t(p.x() - r.xbegin)] =
            double(p[0]) + double(p[1]) + double(p[2]);
    double best = -1.0;
    int bx = 0, by = 0;
    for (int y = 1; y + bh + 1 < r.height(); ++y)  // a block away from the edges
        for (int x = 1; x + bw + 1 < r.width(); ++x) {
            double lo = 1e30, hi = -1e30;
            for (int j = 0; j < bh; ++j)
                for (int i = 0; i < bw; ++i) {
                    const double v = lum[size_t(y + j) * size_t(r.width()) + size_t(x + i)];
                    lo = std::min(lo, v);
                    hi = std::max(hi, v);
                }
            if (hi - lo > best) {
                best = hi - lo;
                bx = x, by = y;
            }
        }
    // Inside the data window (a frame too small for the search keeps its corner).
    const OIIO::ROI d = img.roi();
    const int x0 = std::clamp((r.xbegin + bx) * b, d.xbegin, d.xend - w);
    const int y0 = std::clamp((r.ybegin + by) * b, d.ybegin, d.yend - h);
    return OIIO::ROI(x0, x0 + w, y0, y0 + h);
}

bool write_sheet(const std::string& path, const std::vector<std::pair<std::string, OIIO::ImageBuf>>& tiles,
                 int cols, int threads, std::string& err)
{
    namespace IBA = OIIO::ImageBufAlgo;
    if (tiles.empty())
        return true;
    const int tw = tiles[0].second.spec().width, th = tiles[0].second.spec().height;
    cols           = std::max(1, std::min(cols, int(tiles.size())));
    const int rows = int(tiles.size() + size_t(cols) - 1) / cols;
    const int gap = 6, label_h = 24;
    OIIO::ImageSpec spec(cols * tw + (cols + 1) * gap, rows * (th + label_h + gap) + gap, 3, OIIO::TypeFloat);
    OIIO::ImageBuf sheet(spec);
    const float grey[3] = { 0.12f, 0.12f, 0.12f };
    IBA::fill(sheet, grey);
    const std::string font = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
    const bool have_font   = OIIO::Filesystem::exists(font);
    const float white[3]   = { 1.0f, 1.0f, 1.0f };
    for (size_t i = 0; i < tiles.size(); ++i) {
        const int x = gap + int(i % size_t(cols)) * (tw + gap);
        const int y = gap + int(i / size_t(cols)) * (th + label_h + gap);
        if (!IBA::paste(sheet, x, y + label_h, 0, 0, tiles[i].second, {}, threads)) {
            err = path + ": " + sheet.geterror();
            return false;
        }
        if (have_font)
            IBA::render_text(sheet, x + 4, y + label_h - 6, tiles[i].first, 17, font, white);
    }
    if (!have_font) {
        std::string order;
        for (const auto& t : tiles)
            order += (order.empty() ? "" : ", ") + t.first;
        std::printf("(no font at %s: %s is unlabelled; tiles left to right, top to bottom: %s)\n", font.c_str(),
                    path.c_str(), order.c_str());
    }
    if (!sheet.write(path, OIIO::TypeUInt8)) {
        err = path + ": " + sheet.geterror();
        return false;
    }
    return true;
}


}  // namespace bokeh_bench
