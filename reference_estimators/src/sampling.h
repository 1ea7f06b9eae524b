// Sampling triples in the style of pbrt-v4's sampling.h: sample_x(u, ...), x_pdf(x, ...),
// invert_x(x, ...).  A pdf is 0 outside its support and never throws; an inversion of a
// point outside the support returns NaN ("no value").  Inputs u are canonical uniforms.
// The hot ones use re::fm so that loops over them vectorise.
#pragma once
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "fastmath.h"

namespace re {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInvPi = 0.31830988618379067154;

// The one-dimensional samplers' sample_x and x_pdf are templates over D = double or
// simd::f64v (the same bits lane by lane: the batch loops run them on whole vectors, the
// scalar triples on one value); their inversions are scalar.

// --- exponential: p(x) = a exp(-a x) on [0, inf) ------------------------------------------
template <class D>
RE_INLINE D sample_exponential(D u, double a) { return -fm::log(1.0 - u) / a; }
template <class D>
RE_INLINE D exponential_pdf(D x, double a) { return x >= D{} ? a * fm::exp(-a * x) : D{}; }
inline double invert_exponential(double x, double a) { return x >= 0 ? -std::expm1(-a * x) : kNaN; }

// --- linear: p(x) proportional to (1-x) a + x b on [0, 1], a, b >= 0 -----------------------
template <class D>
RE_INLINE D linear_pdf(D x, double a, double b) {
    return (x >= D{}) & (x <= D{} + 1.0) ? 2 * ((1.0 - x) * a + x * b) / (a + b) : D{};
}
template <class D>
RE_INLINE D sample_linear(D u, double a, double b) {
    // The root of the CDF quadratic in the form without cancellation (pbrt-v4, SampleLinear);
    // u = 0 with a = 0 (0 / 0 there) is 0.
    const D x = u * (a + b) / (a + simd::sqrt((1.0 - u) * a * a + u * b * b));
    const D below_one = D{} + 0x1.fffffffffffffp-1;
    const D y = x < below_one ? x : below_one;
    return a == 0 ? (u == D{} ? D{} : y) : y;
}
inline double invert_linear(double x, double a, double b) {
    return (x >= 0 && x <= 1) ? x * (a * (2 - x) + b * x) / (a + b) : kNaN;
}

// --- power: p(x) = (k+1) x^k on (0, 1], k > -1 (integrable singularity at 0 for k < 0) ----
template <class D>
RE_INLINE D sample_power(D u, double k) { return fm::exp(fm::log(u) / (k + 1)); }
template <class D>
RE_INLINE D power_pdf(D x, double k) {
    return (x > D{}) & (x <= D{} + 1.0) ? (k + 1) * fm::exp(k * fm::log(x)) : D{};
}
inline double invert_power(double x, double k) {
    return (x > 0 && x <= 1) ? std::pow(x, k + 1) : kNaN;
}

// --- Lomax (Pareto II) with shape s: p(x) = s (1+x)^-(s+1) on [0, inf) ----------------------
template <class D>
RE_INLINE D sample_lomax(D u, double s) { return fm::exp(-fm::log(1.0 - u) / s) - 1.0; }
template <class D>
RE_INLINE D lomax_pdf(D x, double s) { return x >= D{} ? s * fm::exp(-(s + 1) * fm::log(1.0 + x)) : D{}; }
inline double invert_lomax(double x, double s) { return x >= 0 ? -std::expm1(-s * std::log1p(x)) : kNaN; }

// --- logistic(mu, s) trimmed to [a, b] (pbrt-v4's TrimmedLogistic) --------------------------
template <class D>
RE_INLINE D logistic_cdf(D x, double mu, double s) { return 1.0 / (1.0 + fm::exp(-(x - mu) / s)); }
template <class D>
RE_INLINE D trimmed_logistic_pdf(D x, double mu, double s, double a, double b) {
    const D z = (x - mu) / s, e = fm::exp(-fm::abs(z));
    const D p = e / (s * (1.0 + e) * (1.0 + e));
    const double mass = logistic_cdf(b, mu, s) - logistic_cdf(a, mu, s);
    return (x >= D{} + a) & (x <= D{} + b) ? p / mass : D{};
}
template <class D>
RE_INLINE D sample_trimmed_logistic(D u, double mu, double s, double a, double b) {
    const double ca = logistic_cdf(a, mu, s), cb = logistic_cdf(b, mu, s);
    const D c = ca + u * (cb - ca);
    const D x = mu + s * (fm::log(c) - fm::log(1.0 - c));
    return x < D{} + a ? D{} + a : (x > D{} + b ? D{} + b : x);
}
inline double invert_trimmed_logistic(double x, double mu, double s, double a, double b) {
    if (!(x >= a && x <= b)) return kNaN;
    double ca = logistic_cdf(a, mu, s), cb = logistic_cdf(b, mu, s);
    return (logistic_cdf(x, mu, s) - ca) / (cb - ca);
}

// --- directions: points are unit vectors (x, y, z), pdfs per steradian --------------------
// max(0, v), NaN giving 0 as std::fmax(0, v) does, but inline: GCC emits a libm call for
// std::fmax, which keeps the samplers' loops from vectorising.
// Templates over D = double or simd::f64v (the same bits lane by lane): the batch loops run
// them on whole vectors of samples (samplers.cpp, Directional), the scalar triples on one.
template <class D>
RE_INLINE D non_negative(D v) { return v > D{} ? v : D{}; }

// The z = cos(theta) of each direction sampler's point, from u0 alone: sample_x's w2, the
// same bits (the estimators' polar path draws z alone for integrands that read nothing else).
template <class D>
RE_INLINE D uniform_hemisphere_cos(D u0) { return u0; }
template <class D>
RE_INLINE D uniform_sphere_cos(D u0) { return 1.0 - 2.0 * u0; }
template <class D>
RE_INLINE D cosine_hemisphere_cos(D u0) { return simd::sqrt(non_negative(1.0 - u0)); }
template <class D>
RE_INLINE D uniform_cone_cos(D u0, double cos_max) { return (1.0 - u0) + u0 * cos_max; }
template <class D>
RE_INLINE D ggx_tan2(D u0, double alpha) { return alpha * alpha * u0 / (1.0 - u0); }
template <class D>
RE_INLINE D ggx_cos(D u0, double alpha) { return 1.0 / simd::sqrt(1.0 + ggx_tan2(u0, alpha)); }

template <class D>
RE_INLINE void sample_uniform_hemisphere(D u0, D u1, D &w0, D &w1, D &w2) {
    D z = uniform_hemisphere_cos(u0), r = simd::sqrt(non_negative(1.0 - z * z)), s, c;
    fm::sincos_2pi(u1, s, c);
    w0 = r * c; w1 = r * s; w2 = z;
}
template <class D>
RE_INLINE D uniform_hemisphere_pdf(D z) { return z >= D{} ? D{} + 0.5 * kInvPi : D{}; }

template <class D>
RE_INLINE void sample_uniform_sphere(D u0, D u1, D &w0, D &w1, D &w2) {
    D z = uniform_sphere_cos(u0), r = simd::sqrt(non_negative(1.0 - z * z)), s, c;
    fm::sincos_2pi(u1, s, c);
    w0 = r * c; w1 = r * s; w2 = z;
}
template <class D>
RE_INLINE D uniform_sphere_pdf(D) { return D{} + 0.25 * kInvPi; }

template <class D>
RE_INLINE void sample_cosine_hemisphere(D u0, D u1, D &w0, D &w1, D &w2) {
    D r = simd::sqrt(u0), s, c;
    fm::sincos_2pi(u1, s, c);
    w0 = r * c; w1 = r * s; w2 = cosine_hemisphere_cos(u0);
}
template <class D>
RE_INLINE D cosine_hemisphere_pdf(D z) { return z > D{} ? z * kInvPi : D{}; }

// Uniform in the cone of directions with cos(theta) >= cos_max around +z.
template <class D>
RE_INLINE void sample_uniform_cone(D u0, D u1, double cos_max, D &w0, D &w1, D &w2) {
    D z = uniform_cone_cos(u0, cos_max), r = simd::sqrt(non_negative(1.0 - z * z)), s, c;
    fm::sincos_2pi(u1, s, c);
    w0 = r * c; w1 = r * s; w2 = z;
}
template <class D>
RE_INLINE D uniform_cone_pdf(D z, double cos_max) {
    return z >= cos_max ? D{} + 1.0 / (2 * M_PI * (1 - cos_max)) : D{};
}

// GGX (Trowbridge-Reitz) normal distribution D(w) with roughness alpha, sampled
// proportionally to D(w) cos(theta): tan^2 theta = alpha^2 u0 / (1 - u0), phi = 2 pi u1.
template <class D>
RE_INLINE D ggx_d(D z, double alpha) {
    const double a2 = alpha * alpha;
    D t = z * z * (a2 - 1) + 1.0;
    D d = a2 / (M_PI * t * t);
    return z > D{} ? d : D{};
}
template <class D>
RE_INLINE void sample_ggx(D u0, D u1, double alpha, D &w0, D &w1, D &w2) {
    D t2 = ggx_tan2(u0, alpha);
    D z = 1.0 / simd::sqrt(1.0 + t2), r = simd::sqrt(t2) * z, s, c;
    fm::sincos_2pi(u1, s, c);
    w0 = r * c; w1 = r * s; w2 = z;
}
template <class D>
RE_INLINE D ggx_pdf(D z, double alpha) { return ggx_d(z, alpha) * z; }
// ggx_pdf's name with its parameter (Sampler::polar_function), alpha in hexadecimal: every bit
inline std::string ggx_pdf_name(double alpha) {
    char s[48];
    std::snprintf(s, sizeof s, "ggx_pdf(%a)", alpha);
    return s;
}

// Inversions of the direction samplers: u from w (NaN outside the support).
inline double azimuth_fraction(const double w[3]) {
    double phi = std::atan2(w[1], w[0]);
    double f = phi / (2 * M_PI);
    return f < 0 ? f + 1 : f;
}

}  // namespace re
