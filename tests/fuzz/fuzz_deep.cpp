// fuzz_deep.cpp — libFuzzer target: the deep nodes (bokeh::deep_tidy, flatten, deep_merge,
// deep_holdout, deep_slice) on deep images built from the fuzzer's bytes: up to 4x3
// pixels, 0-5 samples a pixel, channel sets R,G,B,A / R,G,B,AR,AG,AB / A alone, with or
// without ZBack, half or float colour, an unsigned-int id channel, offset data windows;
// each value either one of a few meaningful ones (coincident depths, alpha 0 and 1, NaN,
// +-inf, 1e30, alpha just above 1) or four raw bytes as a float.
//
// Besides "never crash" (ASan, UBSan), each run checks what the rules of deep.h promise,
// cheaply, and stops (abort: a finding) when one does not hold:
// * under the default policy every operation succeeds on these well-formed images and
//   no output holds a NaN; under NonFinitePolicy::Error tidy fails exactly when the input
//   needs a repair (NaN or -inf depth, ZBack < Z, non-finite colour or alpha);
// * tidy's pixels are sorted by Z, a volume ends where the next sample starts or before,
//   and tidy is idempotent (a tidy image without infinities tidies to the same bits);
// * a slice's samples lie inside [near, far);
// and for valid input (finite depths, ZBack >= Z, alphas in [0, 1], |colour| <= 1e6):
// * every output value is finite, the flat alphas lie in [0, 1];
// * holding out never adds opacity, merging never removes it (flat alpha; to 1e-5 in float,
//   4e-3 in half, where the pieces cut are rounded).
//
// Instrumented: core/deep/deep.cpp; the rest of libOpenBokeh is the Release build's.
#include <bokeh/deep.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <OpenImageIO/deepdata.h>
#include <OpenImageIO/half.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

[[noreturn]] void finding(const char* what, int x, int y, double value = 0)
{
    std::fprintf(stderr, "fuzz_deep: %s (pixel %d,%d, value %g)\n", what, x, y, value);
    std::abort();
}

class Bytes {
public:
    Bytes(const uint8_t* d, size_t n) : m_d(d), m_n(n) {}
    uint8_t next() { return m_i < m_n ? m_d[m_i++] : 0; }
    bool empty() const { return m_i >= m_n; }
    // One of 15 meaningful values of a role, or (selector >= 240) four raw bytes.
    float value(const float (&table)[16])
    {
        const uint8_t s = next();
        if (s < 240)
            return table[s % 15];
        uint8_t b[4] = { next(), next(), next(), next() };
        float f;
        std::memcpy(&f, b, 4);
        return f;
    }

private:
    const uint8_t* m_d;
    size_t m_n, m_i = 0;
};

const float kDepths[16] = { 1, 2, 1, 3, 2, 0.5f, 0, 4, 10, 1e30f, kInf, -kInf, kNaN, -2, 1.0000001f, 0 };
const float kAlphas[16] = { 0, 1, 0.5f, 0.25f, 1, 0.75f, 0, 0.1f, 0.9999999f, 1e-7f, kNaN, 2, -0.5f, kInf, 1.0000001f, 0 };
const float kColours[16] = { 0, 1, 0.5f, 2, 0.25f, 10, 1e6f, -1, 0, 1, 1e-30f, kInf, -kInf, kNaN, 3e38f, 0 };

enum class Role { Colour, Alpha, Depth, DepthBack, Id };

struct Layout {
    std::vector<std::string> names;
    std::vector<Role> roles;
    std::vector<OIIO::TypeDesc> types;
    int w = 1, h = 1, x0 = 0, y0 = 0;
};

Layout layout_from(Bytes& in)
{
    Layout L;
    const uint8_t size = in.next(), kind = in.next();
    L.w = 1 + size % 4;
    L.h = 1 + (size >> 2) % 3;
    if (size & 0x40) {
        L.x0 = int(in.next() % 7) - 3;
        L.y0 = int(in.next() % 7) - 3;
    }
    const OIIO::TypeDesc colour = (kind & 1) ? OIIO::TypeHalf : OIIO::TypeFloat;
    auto add = [&](const char* n, Role r, OIIO::TypeDesc t) {
        L.names.push_back(n);
        L.roles.push_back(r);
        L.types.push_back(t);
    };
    switch ((kind >> 1) % 3) {
    case 0:
        for (const char* n : { "R", "G", "B" })
            add(n, Role::Colour, colour);
        add("A", Role::Alpha, colour);
        break;
    case 1:
        for (const char* n : { "R", "G", "B" })
            add(n, Role::Colour, colour);
        for (const char* n : { "AR", "AG", "AB" })
            add(n, Role::Alpha, colour);
        break;
    default: add("A", Role::Alpha, colour); break;
    }
    add("Z", Role::Depth, OIIO::TypeFloat);
    if (kind & 8)
        add("ZBack", Role::DepthBack, OIIO::TypeFloat);
    if (kind & 16)
        add("id", Role::Id, OIIO::TypeUInt32);
    return L;
}

struct Built {
    OIIO::ImageBuf buf;
    bool needs_repair = false;  // what NonFinitePolicy::Error refuses
    bool valid        = true;   // the input the value checks hold for
};

Built build(Bytes& in, const Layout& L)
{
    OIIO::ImageSpec spec(L.w, L.h, int(L.names.size()), OIIO::TypeFloat);
    spec.x              = L.x0;
    spec.y              = L.y0;
    spec.channelnames   = L.names;
    spec.channelformats = L.types;
    spec.deep           = true;
    for (size_t c = 0; c < L.roles.size(); ++c) {
        if (L.names[c] == "A")
            spec.alpha_channel = int(c);
        if (L.roles[c] == Role::Depth)
            spec.z_channel = int(c);
    }
    Built b;
    b.buf              = OIIO::ImageBuf(spec);
    OIIO::DeepData& dd = *b.buf.deepdata();
    const int64_t npx  = int64_t(L.w) * L.h;
    for (int64_t p = 0; p < npx; ++p)
        dd.set_samples(p, in.next() % 6);
    for (int64_t p = 0; p < npx; ++p)
        for (int s = 0; s < int(dd.samples(p)); ++s) {
            float z = 0;
            for (size_t c = 0; c < L.roles.size(); ++c) {
                const int ch = int(c);
                switch (L.roles[c]) {
                case Role::Id: dd.set_deep_value(p, ch, s, uint32_t(in.next())); continue;
                case Role::Depth: z = in.value(kDepths); break;
                case Role::DepthBack: break;
                default: break;
                }
                float v = L.roles[c] == Role::Depth     ? z
                          : L.roles[c] == Role::Alpha   ? in.value(kAlphas)
                          : L.roles[c] == Role::Colour  ? in.value(kColours)
                                                        : 0.0f;
                if (L.roles[c] == Role::DepthBack) {
                    // Mostly a depth at or behind Z (a volume), sometimes anything.
                    const uint8_t k = in.next();
                    v = k < 200 ? z + float(k % 4) : in.value(kDepths);
                }
                if (L.types[c] == OIIO::TypeHalf)  // what the image will hold
                    v = float(Imath::half(v));
                dd.set_deep_value(p, ch, s, v);
                const bool bad_depth = std::isnan(v) || v == -kInf;
                if (L.roles[c] == Role::Depth || L.roles[c] == Role::DepthBack) {
                    b.needs_repair |= bad_depth || (L.roles[c] == Role::DepthBack && v < z);
                    b.valid &= std::isfinite(v) && !(L.roles[c] == Role::DepthBack && v < z);
                } else {
                    b.needs_repair |= !std::isfinite(v);
                    b.valid &= L.roles[c] == Role::Alpha ? (v >= 0 && v <= 1) : std::fabs(v) <= 1e6f;
                }
            }
        }
    return b;
}

int channel(const OIIO::ImageBuf& img, const char* name) { return img.spec().channelindex(name); }

// No NaN anywhere; with `finite`, no infinity either (flat or deep).
void check_values(const OIIO::ImageBuf& img, bool finite, const char* what)
{
    const OIIO::ImageSpec& s = img.spec();
    for (int y = s.y; y < s.y + s.height; ++y)
        for (int x = s.x; x < s.x + s.width; ++x) {
            const int64_t p = int64_t(y - s.y) * s.width + (x - s.x);
            for (int c = 0; c < s.nchannels; ++c) {
                if (s.channelformat(c) == OIIO::TypeUInt32)
                    continue;
                const int n = img.deep() ? int(img.deepdata()->samples(p)) : 1;
                for (int k = 0; k < n; ++k) {
                    const float v = img.deep() ? img.deepdata()->deep_value(p, c, k)
                                               : img.getchannel(x, y, 0, c);
                    if (std::isnan(v) || (finite && !std::isfinite(v)))
                        finding(what, x, y, v);
                }
            }
        }
}

bool all_finite(const OIIO::ImageBuf& img)
{
    const OIIO::DeepData& dd = *img.deepdata();
    for (int64_t p = 0; p < dd.pixels(); ++p)
        for (int c = 0; c < dd.channels(); ++c)
            for (int k = 0; k < int(dd.samples(p)); ++k)
                if (dd.channeltype(c) != OIIO::TypeUInt32 && !std::isfinite(dd.deep_value(p, c, k)))
                    return false;
    return true;
}

// Tidy: Z ascending, a volume ending at or before the next sample's start.
void check_tidy(const OIIO::ImageBuf& t)
{
    const OIIO::ImageSpec& s = t.spec();
    const int z = channel(t, "Z"), zb = channel(t, "ZBack");
    const OIIO::DeepData& dd = *t.deepdata();
    for (int64_t p = 0; p < int64_t(s.width) * s.height; ++p)
        for (int k = 1; k < int(dd.samples(p)); ++k) {
            const float z0 = dd.deep_value(p, z, k - 1), z1 = dd.deep_value(p, z, k);
            const float back0 = zb >= 0 ? dd.deep_value(p, zb, k - 1) : z0;
            if (!(z1 >= z0))
                finding("tidy: samples not sorted by Z", int(p % s.width), int(p / s.width), z1);
            if (back0 > z0 && z1 < back0)
                finding("tidy: a volume overlaps the next sample", int(p % s.width), int(p / s.width), z1);
        }
}

// BOKEH_FUZZ_VERBOSE=1: the images of a run on stderr, to see what a finding is.
void dump(const char* what, const OIIO::ImageBuf& img)
{
    if (!std::getenv("BOKEH_FUZZ_VERBOSE"))
        return;
    const OIIO::ImageSpec& s = img.spec();
    std::fprintf(stderr, "%s: %dx%d at %d,%d, channels", what, s.width, s.height, s.x, s.y);
    for (int c = 0; c < s.nchannels; ++c)
        std::fprintf(stderr, " %s%s", s.channel_name(c).c_str(), s.channelformat(c) == OIIO::TypeHalf ? "(h)" : "");
    std::fprintf(stderr, "\n");
    for (int64_t p = 0; p < int64_t(s.width) * s.height; ++p) {
        const int n = img.deep() ? int(img.deepdata()->samples(p)) : 1;
        for (int k = 0; k < n; ++k) {
            std::fprintf(stderr, "  px %d sample %d:", int(p), k);
            for (int c = 0; c < s.nchannels; ++c)
                std::fprintf(stderr, " %.9g", img.deep() ? img.deepdata()->deep_value(p, c, k)
                                                          : img.getchannel(s.x + int(p % s.width), s.y + int(p / s.width), 0, c));
            std::fprintf(stderr, "\n");
        }
    }
}

bool same_bits(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b)
{
    const OIIO::DeepData &da = *a.deepdata(), &db = *b.deepdata();
    if (a.spec().width != b.spec().width || a.spec().height != b.spec().height
        || da.channels() != db.channels())
        return false;
    for (int64_t p = 0; p < da.pixels(); ++p) {
        if (da.samples(p) != db.samples(p))
            return false;
        for (int c = 0; c < da.channels(); ++c)
            for (int k = 0; k < int(da.samples(p)); ++k) {
                const float va = da.deep_value(p, c, k), vb = db.deep_value(p, c, k);
                if (std::memcmp(&va, &vb, sizeof va) != 0)
                    return false;
            }
    }
    return true;
}

// The flat alphas (A or AR, AG, AB) in [0, 1].
std::vector<int> alpha_channels(const OIIO::ImageBuf& img)
{
    std::vector<int> a;
    for (const char* n : { "A", "AR", "AG", "AB" })
        if (channel(img, n) >= 0)
            a.push_back(channel(img, n));
    return a;
}

void check_alpha_range(const OIIO::ImageBuf& flat)
{
    const OIIO::ImageSpec& s = flat.spec();
    for (int c : alpha_channels(flat))
        for (int y = s.y; y < s.y + s.height; ++y)
            for (int x = s.x; x < s.x + s.width; ++x) {
                const float a = flat.getchannel(x, y, 0, c);
                if (!(a >= 0.0f && a <= 1.0f))
                    finding("flatten: alpha outside [0, 1]", x, y, a);
            }
}

// sign * (a - b) <= tol for every flat alpha: held out <= source, merged >= each input.
// `tol`: 1e-5 for float samples; for half ones 4e-3, since the volume pieces a holdout or
// merge cuts are stored in half (a relative error of 2^-12 each; a 0.75 volume cut in two
// at z = 1 flattened to 0.75005: 1 - 0.25^0.25 and 1 - 0.25^0.75 rounded to half).
void check_alpha_order(const OIIO::ImageBuf& a, const OIIO::ImageBuf& b, float sign, float tol,
                       const char* what)
{
    const OIIO::ImageSpec& s = b.spec();
    for (int c : alpha_channels(b))
        for (int y = s.y; y < s.y + s.height; ++y)
            for (int x = s.x; x < s.x + s.width; ++x) {
                const float va = a.getchannel(x, y, 0, c), vb = b.getchannel(x, y, 0, c);
                if (sign * (va - vb) > tol)
                    finding(what, x, y, va - vb);
            }
}

OIIO::ImageBuf must(bool ok, OIIO::ImageBuf& dst, const char* what)
{
    if (!ok) {
        std::fprintf(stderr, "fuzz_deep: %s failed: %s\n", what, dst.geterror().c_str());
        std::abort();
    }
    return std::move(dst);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    OIIO::attribute("threads", 1);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size > 2048)
        return 0;
    Bytes in(data, size);
    const Layout L = layout_from(in);
    const Built a = build(in, L), b = build(in, L);
    const bool valid = a.valid && b.valid;
    const float tol  = L.types[0] == OIIO::TypeHalf ? 4e-3f : 1e-5f;
    const uint8_t range = in.next();
    const double znear = kDepths[range % 15], zfar = kDepths[(range >> 4) % 15];

    bokeh::DeepOptions strict;
    strict.nonfinite = bokeh::NonFinitePolicy::Error;
    OIIO::ImageBuf scratch;
    if (bokeh::deep_tidy(scratch, a.buf, strict, nullptr, 1) == a.needs_repair)
        finding(a.needs_repair ? "tidy with policy=error passed a damaged input"
                               : "tidy with policy=error refused a sound input",
                0, 0);

    OIIO::ImageBuf d;
    const OIIO::ImageBuf tidy = must(bokeh::deep_tidy(d, a.buf, {}, nullptr, 1), d, "deep_tidy");
    check_values(tidy, a.valid, "tidy: a NaN or infinity");
    check_tidy(tidy);
    const OIIO::ImageBuf tidy2 = must(bokeh::deep_tidy(d, tidy, {}, nullptr, 1), d, "deep_tidy (again)");
    dump("a", a.buf);
    dump("b", b.buf);
    dump("tidy(a)", tidy);
    dump("tidy(tidy(a))", tidy2);
    // (A finite but absurd input, alpha -3e38 say, may tidy to an infinity, which the
    // second tidy repairs to 0: idempotent where the first result is finite.)
    if (all_finite(tidy) && !same_bits(tidy, tidy2))
        finding("tidy is not idempotent", 0, 0);

    const OIIO::ImageBuf flat_a = must(bokeh::deep_flatten(d, a.buf, {}, nullptr, 1), d, "flatten");
    check_values(flat_a, a.valid, "flatten: a NaN or infinity");
    if (a.valid)
        check_alpha_range(flat_a);

    const OIIO::ImageBuf merged = must(bokeh::deep_merge(d, { &a.buf, &b.buf }, (range & 1) != 0, {}, nullptr, 1),
                                       d, "deep_merge");
    check_values(merged, valid, "merge: a NaN or infinity");
    check_tidy(merged);
    if (valid && !(range & 1)) {
        const OIIO::ImageBuf flat_b = must(bokeh::deep_flatten(d, b.buf, {}, nullptr, 1), d, "flatten (b)");
        const OIIO::ImageBuf flat_m = must(bokeh::deep_flatten(d, merged, {}, nullptr, 1), d, "flatten (merged)");
        check_alpha_range(flat_m);
        check_alpha_order(flat_a, flat_m, 1, tol, "merge: less opaque than an input");
        check_alpha_order(flat_b, flat_m, 1, tol, "merge: less opaque than an input");
    }

    if (!alpha_channels(b.buf).empty()) {
        const OIIO::ImageBuf held = must(bokeh::deep_holdout(d, a.buf, b.buf, {}, nullptr, 1), d, "deep_holdout");
        check_values(held, valid, "holdout: a NaN or infinity");
        if (valid) {
            const OIIO::ImageBuf flat_h = must(bokeh::deep_flatten(d, held, {}, nullptr, 1), d, "flatten (held out)");
            check_alpha_range(flat_h);
            check_alpha_order(flat_h, flat_a, 1, tol, "holdout: more opaque than its source");
        }
    }

    if (znear < zfar) {
        const OIIO::ImageBuf slice = must(bokeh::deep_slice(d, a.buf, znear, zfar, {}, nullptr, 1), d, "deep_slice");
        check_values(slice, a.valid, "slice: a NaN or infinity");
        const int z = channel(slice, "Z"), zb = channel(slice, "ZBack");
        const OIIO::DeepData& dd = *slice.deepdata();
        for (int64_t p = 0; p < dd.pixels(); ++p)
            for (int k = 0; k < int(dd.samples(p)); ++k) {
                const float z0 = dd.deep_value(p, z, k), z1 = zb >= 0 ? dd.deep_value(p, zb, k) : z0;
                const bool inside = z1 > z0 ? z0 >= float(znear) && z1 <= float(zfar)
                                            : z0 >= float(znear) && z0 < float(zfar);
                if (!inside)
                    finding("slice: a sample outside [near, far)", int(p), k, z0);
            }
    }
    return 0;
}
