// wave_optics.cpp — Fresnel integrals and the straight-edge law for the fringes at a
// bokeh's rim; the exact defocused PSF of a round pupil by its Hankel integral and
// Lommel's series; the radial profiles built on them (docs/methods/diffraction.md).
//
// Sources: Born & Wolf, "Principles of Optics", 7th ed., section 8.7 (Fresnel diffraction
// at a straight edge, the Cornu spiral) and 8.8 (the defocused circular pupil, Lommel);
// Abramowitz & Stegun 7.3 (Fresnel integrals: the power series 7.3.11-12 and the relation
// C + iS = (1 + i)/2 erf((sqrt(pi)/2)(1 - i) x), 7.3.22) and 7.1.15 (the continued fraction
// of erfc, valid for Re z > 0).
//
// Fresnel integrals: the power series below |x| = 2.5 (its largest term there is ~3e3,
// so cancellation costs ~3e-13), above it the erfc continued fraction evaluated by the
// modified Lentz method (Press et al., "Numerical Recipes", 3rd ed., 5.2) on the complex
// argument; exp(-z^2) = exp(i pi x^2 / 2) has modulus 1, so nothing overflows. Measured
// against scipy.special.fresnel (tests/optics/wave_optics_test.cpp): within 1e-13 absolute (the
// rounding of x^2 in the phase dominates far out: 4e-14 at x = 1000).
//
// Edge law: the bokeh's rim, seen over a few fringe widths, is a straight edge lit by a
// converging wave of radius of curvature ~ the sensor distance; the Fresnel number gives
// v = d sqrt(2 / (lambda N c)) (docs/methods/diffraction.md, "The edge law"; its extrema
// agree with the exact defocused-pupil integral at W20 = 100 waves). Limits: no free
// parameter, but it ignores the far rim's lambda N ripple and the disc's curvature, so it
// fails within a few fringe widths of focus (c of a few lambda N).
//
// Hankel integral: composite Simpson over rho with ~100 nodes per cycle of the integrand
// (the pupil phase's and J0's frequencies added); agrees with the Lommel series to 2e-9 of
// I_geo at W20 0.25-40 waves (tests). J0 per node is the costly part: a cubic Hermite table
// below x = 20 and the Hankel asymptotic expansion above, with its phase advanced by one
// complex product per node, ~35 ns a node (W20 100 waves out to v = u: 40k nodes, ~1.4 ms
// per radius on this machine, one thread).
// Lommel: Bessel functions of every order at once by Miller's backward recurrence.
// Limits: scalar, paraxial (NA well under 0.5, i.e. f/1 and slower); cost linear in W20.

#include <bokeh/base.h>
#include <bokeh/wave_optics.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <limits>
#include <vector>

namespace bokeh {

namespace {


// C and S for 0 <= x < 2.5 by their power series in pi x^2 / 2 (A&S 7.3.11-12): with
// a_k = x (pi x^2 / 2)^k / k!, C gets the even k terms (-1)^(k/2) a_k / (2k + 1), S the
// odd ones (-1)^((k-1)/2) a_k / (2k + 1).
FresnelCS fresnel_series(double x)
{
    const double z = 0.5 * kPi * x * x;
    double a = x, c = 0.0, s = 0.0;
    for (int k = 0; k < 200; ++k) {
        const double term = a / double(2 * k + 1);
        const double sign = ((k / 2) % 2 == 0) ? 1.0 : -1.0;
        if (k % 2 == 0)
            c += sign * term;
        else
            s += sign * term;
        if (term < 1e-18 * (1.0 + std::abs(c) + std::abs(s)) && k > 2)
            break;
        a *= z / double(k + 1);
    }
    return {c, s};
}

// erfc(z) exp(z^2) sqrt(pi) = 1 / (z + (1/2) / (z + 1 / (z + (3/2) / (z + ...)))) for
// Re z > 0 (A&S 7.1.15), by the modified Lentz method.
std::complex<double> erfc_scaled_cf(std::complex<double> z)
{
    using cd             = std::complex<double>;
    const double tiny    = 1e-300;
    cd f                 = z;
    cd Cn                = f;
    cd Dn                = 0.0;
    for (int n = 1; n < 5000; ++n) {
        const double an = 0.5 * n;
        Dn              = z + an * Dn;
        if (std::abs(Dn) < tiny)
            Dn = tiny;
        Cn = z + an / Cn;
        if (std::abs(Cn) < tiny)
            Cn = tiny;
        Dn             = 1.0 / Dn;
        const cd delta = Cn * Dn;
        f *= delta;
        if (std::abs(delta - 1.0) < 1e-16)
            break;
    }
    return 1.0 / f;
}

}  // namespace

FresnelCS fresnel_integrals(double x)
{
    if (std::isnan(x))
        return {x, x};
    const double ax = std::abs(x);
    FresnelCS r;
    if (ax < 2.5) {
        r = fresnel_series(ax);
    } else if (std::isinf(ax)) {
        r = {0.5, 0.5};
    } else {
        // C + iS = (1 + i)/2 (1 - erfc(z)), z = (sqrt(pi)/2)(1 - i) x; exp(-z^2) = exp(i pi x^2/2).
        const std::complex<double> z = 0.5 * std::sqrt(kPi) * std::complex<double>(ax, -ax);
        // The phase pi x^2 / 2 reduced modulo 2 pi in x's own terms keeps it exact for large x.
        const double phase            = 0.5 * kPi * std::fmod(ax * ax, 4.0);
        const std::complex<double> e  = std::polar(1.0, phase);
        const std::complex<double> ec = e * erfc_scaled_cf(z) / std::sqrt(kPi);
        const std::complex<double> cs = std::complex<double>(0.5, 0.5) * (1.0 - ec);
        r                             = {cs.real(), cs.imag()};
    }
    if (x < 0)
        r = {-r.C, -r.S};
    return r;
}

double fresnel_edge_intensity(double v)
{
    const FresnelCS f = fresnel_integrals(v);
    const double c = f.C + 0.5, s = f.S + 0.5;
    return 0.5 * (c * c + s * s);
}

double fringe_scale(double wavelength, double fnumber, double coc)
{
    if (!(wavelength > 0) || !(fnumber > 0) || !(coc >= 0) || std::isinf(wavelength)
        || std::isinf(fnumber) || std::isinf(coc))
        return std::numeric_limits<double>::quiet_NaN();
    return std::sqrt(wavelength * fnumber * coc);
}

double fringe_scale_px(double coc_px, double fnumber, double wavelength_nm, double pixel_pitch_mm)
{
    if (!(pixel_pitch_mm > 0))
        return std::numeric_limits<double>::quiet_NaN();
    return fringe_scale(wavelength_nm * 1e-6, fnumber, std::abs(coc_px) * pixel_pitch_mm)
           / pixel_pitch_mm;
}

// ---------------------------------------------------------------------------------------
// The exact defocused PSF of a circular pupil.

double RadialWavefront::waves(double rho) const
{
    const double r2 = rho * rho;
    return r2 * (defocus_waves + r2 * (spherical_waves + r2 * spherical6_waves))
           + ripple_waves * std::cos(kPi * ripple_cycles * rho);
}

double RadialWavefront::max_slope_waves() const
{
    return 2 * std::abs(defocus_waves) + 4 * std::abs(spherical_waves)
           + 6 * std::abs(spherical6_waves) + kPi * std::abs(ripple_cycles * ripple_waves);
}

namespace {

// Coefficients of J0's Hankel asymptotic expansion (A&S 9.2.5 with nu = 0):
// a_k = prod_{j<=k} (2j - 1)^2 / (k! 8^k); P = sum_{k even} (-1)^(k/2) a_k / x^k,
// Q = -sum_{k odd} (-1)^((k-1)/2) a_k / x^k, J0 = sqrt(2 / (pi x)) (P cos chi - Q sin chi),
// chi = x - pi / 4. At x >= 20 the 16th term is below 1e-14 and the series is still
// decreasing there (its smallest term is near k = 2x); measured against cyl_bessel_j over
// 20 <= x <= 2e4: within 5e-13.
constexpr int kAsymTerms = 16;
constexpr double kAsymFrom = 20.0;

const std::array<double, kAsymTerms>& asym_coeffs()
{
    static const std::array<double, kAsymTerms> a = [] {
        std::array<double, kAsymTerms> c{};
        c[0] = 1.0;
        for (int k = 1; k < kAsymTerms; ++k)
            c[k] = c[k - 1] * double((2 * k - 1) * (2 * k - 1)) / (8.0 * k);
        return c;
    }();
    return a;
}

// P and Q of the expansion at x >= kAsymFrom.
inline void asym_pq(double x, double& P, double& Q)
{
    const auto& a  = asym_coeffs();
    const double y = 1.0 / x;
    double p = 0.0, q = 0.0, yk = 1.0;
    for (int k = 0; k < kAsymTerms; ++k) {
        const double t = a[k] * yk;
        if (k % 2 == 0)
            p += ((k / 2) % 2 == 0) ? t : -t;
        else
            q -= (((k - 1) / 2) % 2 == 0) ? t : -t;
        if (t < 1e-17)  // the terms still decrease here (x >= 20, k < 16)
            break;
        yk *= y;
    }
    P = p;
    Q = q;
}

// Below kAsymFrom: cubic Hermite interpolation of J0 and J0' = -J1, tabulated once from
// the library's cyl_bessel_j at 256 points per unit (error h^4 / 384 max |J0 (4)| < 1e-12),
// much faster than calling cyl_bessel_j per node.
constexpr int kTablePerUnit = 256;

struct J0Table {
    std::vector<double> j0, dj0;
    J0Table()
    {
        const int n = int(kAsymFrom) * kTablePerUnit + 2;
        j0.resize(size_t(n));
        dj0.resize(size_t(n));
        for (int i = 0; i < n; ++i) {
            const double x = double(i) / kTablePerUnit;
            j0[size_t(i)]  = std::cyl_bessel_j(0.0, x);
            dj0[size_t(i)] = -std::cyl_bessel_j(1.0, x);
        }
    }
};

inline double j0_table(double x)
{
    static const J0Table table;
    const double s  = x * kTablePerUnit;
    const int i     = int(s);
    const double t  = s - i, h = 1.0 / kTablePerUnit;
    const double t2 = t * t, t3 = t2 * t;
    return (2 * t3 - 3 * t2 + 1) * table.j0[size_t(i)] + (t3 - 2 * t2 + t) * h * table.dj0[size_t(i)]
           + (3 * t2 - 2 * t3) * table.j0[size_t(i) + 1] + (t3 - t2) * h * table.dj0[size_t(i) + 1];
}

}  // namespace

double bessel_j0(double x)
{
    x = std::abs(x);
    if (x < kAsymFrom)
        return j0_table(x);
    double P, Q;
    asym_pq(x, P, Q);
    const double chi = x - 0.25 * kPi;
    return std::sqrt(2.0 / (kPi * x)) * (P * std::cos(chi) - Q * std::sin(chi));
}

HankelPsf::HankelPsf(const RadialWavefront& wavefront, double v_max) : wavefront_(wavefront)
{
    const double cycles = wavefront.max_slope_waves() + std::max(0.0, v_max) / (2 * kPi);
    int n               = 64 + int(std::ceil(100.0 * cycles));
    n += n % 2;  // Simpson: an even number of intervals
    step_ = 1.0 / n;
    rho_.resize(size_t(n) + 1);
    re_.resize(rho_.size());
    im_.resize(rho_.size());
    for (int j = 0; j <= n; ++j) {
        const double rho = j * step_;
        const double wgt = (j == 0 || j == n) ? 1.0 : (j % 2 ? 4.0 : 2.0);
        const double ph  = 2 * kPi * wavefront.waves(rho);
        rho_[size_t(j)]  = rho;
        re_[size_t(j)]   = wgt * rho * std::cos(ph);
        im_[size_t(j)]   = wgt * rho * std::sin(ph);
    }
}

double HankelPsf::operator()(double v) const
{
    v             = std::abs(v);
    const int n   = int(rho_.size());
    double sr = 0.0, si = 0.0;
    // Below the asymptotic range: the table.
    const int j_asym = v > 0 ? std::min(n, int(std::ceil(kAsymFrom / (v * step_)))) : n;
    for (int j = 0; j < j_asym; ++j) {
        const double b = j0_table(v * rho_[size_t(j)]);
        sr += b * re_[size_t(j)];
        si += b * im_[size_t(j)];
    }
    // Above: the expansion with its phase exp(i chi) advanced by exp(i v h) node to node,
    // recomputed exactly every 64 nodes so the rounding of the product cannot build up.
    if (j_asym < n) {
        const std::complex<double> stepper = std::polar(1.0, v * step_);
        std::complex<double> phasor;
        for (int j = j_asym; j < n; ++j) {
            const double x = v * rho_[size_t(j)];
            if ((j - j_asym) % 64 == 0)
                phasor = std::polar(1.0, x - 0.25 * kPi);
            double P, Q;
            asym_pq(x, P, Q);
            const double b = std::sqrt(2.0 / (kPi * x)) * (P * phasor.real() - Q * phasor.imag());
            sr += b * re_[size_t(j)];
            si += b * im_[size_t(j)];
            phasor *= stepper;
        }
    }
    const double scale = 2.0 * step_ / 3.0;  // Simpson h / 3, times the 2 of the integral
    sr *= scale;
    si *= scale;
    return sr * sr + si * si;
}

namespace {

// J_0(v) .. J_m_max(v) by Miller's backward recurrence J_(m-1) = (2m / v) J_m - J_(m+1),
// started well above both m_max and v and normalised by J0 + 2 sum J_2k = 1 (A&S 9.1.46,
// 9.12 "backward recurrence"). v > 0.
std::vector<double> bessel_j_orders(int m_max, double v)
{
    const int start = std::max(m_max, int(v)) + 40 + int(10 * std::cbrt(v));
    std::vector<double> j(size_t(start) + 2, 0.0);
    j[size_t(start) + 1] = 0.0;
    j[size_t(start)]     = 1e-300;
    for (int m = start; m >= 1; --m) {
        j[size_t(m) - 1] = (2.0 * m / v) * j[size_t(m)] - j[size_t(m) + 1];
        if (std::abs(j[size_t(m) - 1]) > 1e250) {  // rescale before overflow
            for (int k = m - 1; k <= start; ++k)
                j[size_t(k)] *= 1e-250;
        }
    }
    double norm = j[0];
    for (int m = 2; m <= start; m += 2)
        norm += 2 * j[size_t(m)];
    j.resize(size_t(m_max) + 1);
    for (double& x : j)
        x /= norm;
    return j;
}

}  // namespace

double defocus_psf_lommel(double u, double v)
{
    u = std::abs(u);
    v = std::abs(v);
    if (u == 0.0) {
        if (v == 0.0)
            return 1.0;
        const double a = 2 * std::cyl_bessel_j(1.0, v) / v;
        return a * a;
    }
    if (v == 0.0) {  // B&W 8.8 (30): (sin(u/4) / (u/4))^2
        const double s = std::sin(0.25 * u) / (0.25 * u);
        return s * s;
    }
    // Terms (ratio)^(n + 2s) J_(n+2s)(v) fall off once n + 2s passes v (J_m decays
    // faster than exponentially there) and geometrically with the ratio below 1.
    const int m_max  = int(v + 60 + 20 * std::cbrt(v));
    const std::vector<double> J = bessel_j_orders(m_max, v);
    const auto lommel = [&](int n, double ratio) {
        double sum = 0.0, pw = std::pow(ratio, n);
        const double r2 = ratio * ratio;
        for (int m = n, s = 0; m <= m_max; m += 2, ++s) {
            sum += (s % 2 ? -pw : pw) * J[size_t(m)];
            pw *= r2;
            if (pw < 1e-300)
                break;
        }
        return sum;
    };
    const double g = (2 / u) * (2 / u);
    if (v < u) {
        const double V0 = lommel(0, v / u), V1 = lommel(1, v / u);
        const double arg = 0.5 * (u + v * v / u);
        return g * (1 + V0 * V0 + V1 * V1 - 2 * V0 * std::cos(arg) - 2 * V1 * std::sin(arg));
    }
    const double U1 = lommel(1, u / v), U2 = lommel(2, u / v);
    return g * (U1 * U1 + U2 * U2);
}

double defocus_waves(double coc, double fnumber, double wavelength)
{
    if (!(wavelength > 0) || !(fnumber > 0) || std::isinf(wavelength) || std::isinf(fnumber)
        || !std::isfinite(coc))
        return std::numeric_limits<double>::quiet_NaN();
    return std::abs(coc) / (8 * fnumber * wavelength);
}

double defocus_waves_px(double coc_px, double fnumber, double wavelength_nm, double pixel_pitch_mm)
{
    if (!(pixel_pitch_mm > 0) || std::isinf(pixel_pitch_mm))
        return std::numeric_limits<double>::quiet_NaN();
    return defocus_waves(coc_px * pixel_pitch_mm, fnumber, wavelength_nm * 1e-6);
}

double radius_v_px(double r_px, double fnumber, double wavelength_nm, double pixel_pitch_mm)
{
    if (!(pixel_pitch_mm > 0) || !(fnumber > 0) || !(wavelength_nm > 0) || std::isinf(fnumber)
        || std::isinf(wavelength_nm) || std::isinf(pixel_pitch_mm))
        return std::numeric_limits<double>::quiet_NaN();
    return kPi * r_px * pixel_pitch_mm / (wavelength_nm * 1e-6 * fnumber);
}

// ---------------------------------------------------------------------------------------
// Radial profiles.

namespace {

class ExactProfile final : public RadialProfile {
public:
    ExactProfile(const RadialWavefront& w, double rho_max)
        : u_(defocus_u(w.defocus_waves)), rho_max_(rho_max), psf_(w, defocus_u(w.defocus_waves) * rho_max)
    {
    }
    double operator()(double rho) const override
    {
        return psf_(u_ * rho) * u_ * u_ / (4 * kPi);
    }
    double extent() const override { return rho_max_; }
    const char* name() const override { return "exact"; }

private:
    double u_, rho_max_;
    HankelPsf psf_;
};

class EdgeLawProfile final : public RadialProfile {
public:
    explicit EdgeLawProfile(double w) : sqrt_w_(std::sqrt(w)), extent_(1 + 3 / std::sqrt(w))
    {
        // Unit energy over [0, extent]: Simpson on a grid of ~20 nodes per fringe scale.
        const int n = 2 * int(std::ceil(10 * extent_ * sqrt_w_ + 200));
        const double h = extent_ / n;
        double e = 0.0;
        for (int j = 0; j <= n; ++j) {
            const double rho = j * h;
            const double wgt = (j == 0 || j == n) ? 1.0 : (j % 2 ? 4.0 : 2.0);
            e += wgt * 2 * kPi * rho * raw(rho);
        }
        scale_ = 1.0 / (e * h / 3);
    }
    double operator()(double rho) const override
    {
        return rho > extent_ ? 0.0 : scale_ * raw(std::abs(rho));
    }
    double extent() const override { return extent_; }
    const char* name() const override { return "edge law"; }

private:
    double raw(double rho) const { return fresnel_edge_intensity(2 * (1 - rho) * sqrt_w_); }
    double sqrt_w_, extent_, scale_ = 1.0;
};

}  // namespace

std::unique_ptr<RadialProfile> exact_radial_profile(const RadialWavefront& wavefront, double rho_max)
{
    if (!(wavefront.defocus_waves > 0) || !(rho_max > 0) || !std::isfinite(rho_max))
        return nullptr;
    return std::make_unique<ExactProfile>(wavefront, rho_max);
}

std::unique_ptr<RadialProfile> edge_law_radial_profile(double defocus_waves)
{
    if (!(defocus_waves > 0) || !std::isfinite(defocus_waves))
        return nullptr;
    return std::make_unique<EdgeLawProfile>(defocus_waves);
}

}  // namespace bokeh
