// truth_sampler.h — internal to the library: the per-pixel sampler of the thin-lens
// truths (core/truth/truth.cpp through a deep image, core/scene/scene_truth.cpp through a built-in
// scene's geometry), so both draw the same rays for the same pixel and seed.
//
// A 4-D Sobol' sequence (direction numbers of Joe and Kuo, "Constructing Sobol sequences
// with better two-dimensional projections", 2008: the first four dimensions) with the
// hash-based nested uniform (Owen) scramble of Burley, "Practical Hash-based Owen
// Scrambling" (JCGT 9(4), 2020: the Laine-Karras style hash with his constants, applied to
// the bit-reversed value). Ours: the per-pixel and per-half seeds (pixel_seed, half_seed).
// Dimensions 0 and 1 place the ray on the aperture (ApertureSampler), 2 and 3 in the pixel.
// Also what both do with the rays: the noise estimate from two half renders.
#pragma once

#include <bokeh/aperture.h>

#include <cmath>
#include <cstdint>
#include <string>

namespace bokeh::detail {

// The rays both truths draw: the aperture a disk, a polygon or an opening
// (check_aperture, with the anamorphic aspect), 1..2^20 samples a pixel. False + `err`
// naming the bad one.
bool check_truth_rays(const Kernel& aperture, float aspect, int spp, std::string& err);

// The pupil points of an aperture check_truth_rays accepted.
ApertureSampler truth_pupil(const Kernel& aperture, float aspect);

inline uint32_t reverse_bits(uint32_t x)
{
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
    return (x >> 16) | (x << 16);
}

// Burley (2020), section 3: an Owen scramble of the bits of x, most significant first,
// as a hash of the reversed bits in which each bit only affects higher ones.
inline uint32_t owen_scramble(uint32_t x, uint32_t seed)
{
    x = reverse_bits(x);
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return reverse_bits(x);
}

// A 32-bit integer hash (a finaliser of the murmur / splitmix family) for seeds.
inline uint32_t hash32(uint32_t x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}
inline uint32_t hash_combine(uint32_t a, uint32_t b) { return hash32(a ^ (hash32(b) + 0x9e3779b9u + (a << 6) + (a >> 2))); }

// Direction numbers of the first four Sobol' dimensions, 32 bits each. Dimension 0 is van
// der Corput's (all m = 1); the others from Joe and Kuo's table: (s, a, m_1..m_s) =
// (1, 0, 1), (2, 1, 1 3), (3, 1, 1 3 1), extended by the recurrence
// m_k = 2 a_1 m_{k-1} ^ 4 a_2 m_{k-2} ^ ... ^ 2^s m_{k-s} ^ m_{k-s}.
struct SobolTable {
    uint32_t v[4][32];
    SobolTable()
    {
        struct Poly {
            int s;
            uint32_t a;
            uint32_t m[3];
        };
        const Poly polys[3] = { { 1, 0, { 1, 0, 0 } }, { 2, 1, { 1, 3, 0 } }, { 3, 1, { 1, 3, 1 } } };
        for (int k = 0; k < 32; ++k)
            v[0][k] = 1u << (31 - k);
        for (int d = 1; d < 4; ++d) {
            const Poly& p = polys[d - 1];
            uint32_t m[33];
            for (int k = 1; k <= p.s; ++k)
                m[k] = p.m[k - 1];
            for (int k = p.s + 1; k <= 32; ++k) {
                uint32_t mk = m[k - p.s] ^ (m[k - p.s] << p.s);
                for (int j = 1; j < p.s; ++j)
                    if ((p.a >> (p.s - 1 - j)) & 1u)
                        mk ^= m[k - j] << j;
                m[k] = mk;
            }
            for (int k = 1; k <= 32; ++k)
                v[d][k - 1] = m[k] << (32 - k);
        }
    }
};
inline const SobolTable& sobol_table()
{
    static const SobolTable t;
    return t;
}

// The points of one pixel's half render: Sobol' points in Gray-code order (the first 2^m
// are the sequence's first 2^m), each dimension Owen-scrambled with its own seed.
struct PixelSequence {
    const SobolTable& t;
    uint32_t seed[4];
    uint32_t x[4] = { 0, 0, 0, 0 };
    uint32_t i    = 0;

    PixelSequence(const SobolTable& table, uint32_t s) : t(table)
    {
        for (int d = 0; d < 4; ++d)
            seed[d] = hash_combine(s, uint32_t(d) + 1u);
    }
    // The next point, each coordinate in (0, 1).
    void next(double u[4])
    {
        if (i > 0) {
            const int bit = __builtin_ctz(i);
            for (int d = 0; d < 4; ++d)
                x[d] ^= t.v[d][bit];
        }
        ++i;
        for (int d = 0; d < 4; ++d)
            u[d] = (double(owen_scramble(x[d], seed[d])) + 0.5) * (1.0 / 4294967296.0);
    }
};

/// The seed of pixel (x, y)'s sequences under the user's `seed`.
inline uint32_t pixel_seed(uint32_t seed, int x, int y)
{
    return hash_combine(hash_combine(seed, uint32_t(x)), uint32_t(y));
}

/// The seed of one of a pixel's two half renders (0 or 1): the halves' difference is the
/// truths' noise estimate.
inline uint32_t half_seed(uint32_t px_seed, int half) { return hash_combine(px_seed, uint32_t(half)); }

/// The noise of a render made of two halves of n1 and n2 rays a pixel (truth.h's
/// TruthReport): add() each output value's two half means; figures() gives the RMS of
/// the full render's noise and its PSNR after metrics.h's tone map x / (1 + |x|), peak 1.
struct HalvesNoise {
    double sq = 0.0, sq_tone = 0.0;
    static double tone(double v) { return v / (1.0 + std::abs(v)); }
    void add(double a, double b)
    {
        sq += (a - b) * (a - b);
        sq_tone += (tone(a) - tone(b)) * (tone(a) - tone(b));
    }
    void merge(const HalvesNoise& o)
    {
        sq += o.sq;
        sq_tone += o.sq_tone;
    }
    /// Over `values` output values; rmse and psnr_db stay as they are for n2 = 0 (spp 1).
    /// The output (n1 A + n2 B) / n has variance E[(A - B)^2] n1 n2 / n^2 when each half's
    /// variance falls as 1 / n_half.
    void figures(int n1, int n2, double values, double& rmse, double& psnr_db) const
    {
        if (n2 <= 0 || values <= 0.0)
            return;
        const double n = double(n1) + double(n2), w = double(n1) * double(n2) / (n * n);
        rmse                = std::sqrt(sq * w / values);
        const double mse_tm = sq_tone * w / values;
        psnr_db             = mse_tm > 0.0 ? 10.0 * std::log10(1.0 / mse_tm) : 999.0;
    }
};

}  // namespace bokeh::detail
