// Elementary functions written so that GCC and Clang vectorise loops that call them
// (straight-line code, selects instead of branches, no errno) and so that scalar and
// vector lanes give bitwise the same result.  libm's exp/log/sin are scalar calls that
// block vectorisation, and libmvec's variants are only declared under -ffast-math, which
// would also break the NaN/Inf accounting this project is about.  Accuracy: within 2 ulp
// over the full double range (tested against libm in tests/test_core_math.py).  Polynomials
// use std::fma, which is correctly rounded by definition: one instruction where the CPU has
// FMA, the same bits (slowly) where it has not.
#pragma once
#include <cmath>
#include <cstdint>
#include <limits>

#include "simd.h"

namespace re::fm {

// 2^(j/16), j = 0..15, each the correctly rounded double (computed with Python's decimal
// module at 60 digits).
alignas(64) inline constexpr double kExp2Table[16] = {
    0x1.0000000000000p+0, 0x1.0b5586cf9890fp+0, 0x1.172b83c7d517bp+0, 0x1.2387a6e756238p+0,
    0x1.306fe0a31b715p+0, 0x1.3dea64c123422p+0, 0x1.4bfdad5362a27p+0, 0x1.5ab07dd485429p+0,
    0x1.6a09e667f3bcdp+0, 0x1.7a11473eb0187p+0, 0x1.8ace5422aa0dbp+0, 0x1.9c49182a3f090p+0,
    0x1.ae89f995ad3adp+0, 0x1.c199bdd85529cp+0, 0x1.d5818dcfba487p+0, 0x1.ea4afa2a490dap+0,
};

// y 2^k for exp below, k = floor(n / 16), n = t - 1.5 2^52 (the integer in t's low bits).
// Where |x| keeps y 2^k normal (x in (-707, 709), y in [0.97, 2.05)), k is added to y's
// exponent field: n's bits shifted so that bits 4.. land at 52.. (two's complement, so a
// negative k wraps into the field exactly), four integer operations where the scaling by
// 2^floor(k) took eight; elsewhere (and for NaN) scale2k, which rounds subnormals once.  Both
// give the same bits wherever both apply.  AVX-512's vscalefpd is one instruction already.
template <class D>
RE_INLINE D add_k_to_exponent(D y, D t) {
    return simd::from_bits(simd::bits(y) + (((simd::bits(t) - simd::bits(0x1.8p52)) << 48u) & 0xfff0000000000000ULL));
}
RE_INLINE double times_2k(double y, double t, double n, double x) {
    return x > -707.0 && x < 709.0 ? add_k_to_exponent(y, t) : simd::scale2k(y, n * 0.0625);
}
RE_INLINE simd::f64v times_2k(simd::f64v y, simd::f64v t, simd::f64v n, simd::f64v x) {
#if defined(__AVX512F__)
    (void)t, (void)x;
    return simd::scale2k(y, n * 0.0625);
#else
    const auto normal = (x > -707.0) & (x < 709.0);
#if defined(__AVX__)
    const bool all = _mm256_movemask_pd((__m256d)normal) == 0xf;
#else
    const bool all = normal[0] && normal[1];
#endif
    return __builtin_expect(all, 1) ? add_k_to_exponent(y, t) : simd::scale2k(y, n * 0.0625);
#endif
}

// exp(x) for double or simd::f64v (the same bits lane by lane): x = (16 k + j) ln2/16 + r
// with |r| <= ln2/32, exp(x) = 2^k 2^(j/16) exp(r), exp(r) - 1 by a degree-7 Taylor
// polynomial (truncation < 2e-18; the terms past r are below r^2/2 < 2.4e-4, so their
// rounding is far below an ulp of the result).  t = x 16/ln2 + 1.5 2^52 rounds to the integer 16 k + j in
// its low mantissa bits, so j is read from t's bits (AVX-512: an in-register permute, no
// gather) and 2^k is applied by one correctly rounded scaling (AVX-512: vscalefpd), so
// subnormal results come out right.  The clamp to [-746, 710] passes NaN through; the overflow
// threshold is explicit so that exp overflows exactly where libm's does.
template <class D>
RE_INLINE D exp(D x) {
    using simd::fma;
    const D lo = D{} - 746.0, hi = D{} + 710.0, shift = D{} + 0x1.8p52;
    const D ln2_hi = D{} - 0.693147180559890330187045037746429443359375 / 16;  // hi + lo = ln 2
    const D ln2_lo = D{} - 5.497923018708371174712471492138406e-14 / 16;
    D xc = simd::min_or_second(hi, simd::max_or_second(lo, x));  // NaN passes
    D t = fma(xc, D{} + 16 * 1.4426950408889634, shift);
    D n = t - shift;  // round(16 x / ln 2) = 16 k + j
    D r = fma(n, ln2_hi, xc);
    r = fma(n, ln2_lo, r);
    // p = r + r^2 (1/2 + r/6 + r^2 (1/24 + r/120 + r^2 (1/720 + r/5040))): Estrin's pairs
    // take the dependent chain from eight operations to five, and the loops calling exp are
    // bound by that chain's latency (exp on the unit interval: 1.66 -> 1.55 ns a value).
    const D r2 = r * r;
    const D c01 = fma(r, D{} + 1.0 / 6, D{} + 0.5), c23 = fma(r, D{} + 1.0 / 120, D{} + 1.0 / 24);
    const D c45 = fma(r, D{} + 1.0 / 5040, D{} + 1.0 / 720);
    const D p = fma(r2, fma(r2, fma(r2, c45, c23), c01), r);
    D tj = simd::lookup16(kExp2Table, t);
    D y = times_2k(fma(tj, p, tj), t, n, xc);
    const D inf = D{} + std::numeric_limits<double>::infinity();
    return x > D{} + 709.782712893384 ? inf : y;
}

// log(x): x = (1 + f) 2^e with 1 + f in [sqrt(1/2), sqrt(2)) and f exact; with s = f/(2+f),
// log(1+f) = 2 atanh(s) = f - (f^2/2 - s (f^2/2 + R)), R = 2 s^2/3 + 2 s^4/5 + ... to s^22
// (truncation < 1e-18): the leading term f carries no rounding error (the arrangement of
// fdlibm's e_log.c, with a Taylor series instead of its minimax coefficients).  For double or
// simd::f64v, the same bits lane by lane.
template <class D>
RE_INLINE D log(D x) {
    using simd::fma;
    const auto sub = x < D{} + 0x1p-1022;
    const D xs = sub ? x * 0x1p54 : x;
    const auto b = simd::bits(xs);
    // the exponent field and its bias as a double: 1.5 2^52 + e holds e in its low bits
    // (exact for |e| < 2^51), so the conversion is two integer-free steps on every ISA
    D m = simd::from_bits((b & 0x000fffffffffffffULL) | 0x3ff0000000000000ULL);
    D de = simd::from_bits(((b >> 52) & 0x7ffu) + simd::bits(0x1.8p52)) - (0x1.8p52 + 1023.0);
    const auto big = m > D{} + 1.4142135623730951;
    m = big ? m * 0.5 : m;
    de = big ? de + 1.0 : de;
    de = sub ? de - 54.0 : de;
    const D f = m - 1.0;  // exact (Sterbenz)
    const D s = f / (2.0 + f), z = s * s;
    D r = D{} + 2.0 / 23.0;
    r = fma(r, z, D{} + 2.0 / 21.0);
    r = fma(r, z, D{} + 2.0 / 19.0);
    r = fma(r, z, D{} + 2.0 / 17.0);
    r = fma(r, z, D{} + 2.0 / 15.0);
    r = fma(r, z, D{} + 2.0 / 13.0);
    r = fma(r, z, D{} + 2.0 / 11.0);
    r = fma(r, z, D{} + 2.0 / 9.0);
    r = fma(r, z, D{} + 2.0 / 7.0);
    r = fma(r, z, D{} + 2.0 / 5.0);
    r = fma(r, z, D{} + 2.0 / 3.0);
    r *= z;
    const D hfsq = 0.5 * f * f;
    D y = de * 6.93147180369123816490e-01 - ((hfsq - (s * (hfsq + r) + de * 1.90821492927058770002e-10)) - f);
    const D inf = D{} + std::numeric_limits<double>::infinity();
    y = x == inf ? x : y;
    y = x == D{} ? -inf : y;
    y = x < D{} ? D{} + std::numeric_limits<double>::quiet_NaN() : y;
    return x != x ? x : y;
}

// sin and cos of 2 pi u for double or simd::f64v (the same bits lane by lane), |u| < 2^48:
// the reduction u - q/4 is exact, so the result is accurate for the canonical uniforms the
// samplers feed in; the quadrant is read from the low bits of u 4 + 1.5 2^52 (which hold
// round(4 u) in two's complement) and applied by selects, so a vector of random azimuths
// costs no mispredicted branch.
template <class D>
RE_INLINE void sincos_2pi(D u, D &s, D &c) {
    using simd::fma;
    const D shift = D{} + 0x1.8p52;
    const D t = u * 4.0 + shift;
    const D qn = t - shift;  // nearest integer to 4 u
    const D r = (u - qn * 0.25) * 6.283185307179586;  // |r| <= pi/4
    const D r2 = r * r;
    D ps = D{} - 1.0 / 1307674368000.0;
    ps = fma(ps, r2, D{} + 1.0 / 6227020800.0);
    ps = fma(ps, r2, D{} - 1.0 / 39916800.0);
    ps = fma(ps, r2, D{} + 1.0 / 362880.0);
    ps = fma(ps, r2, D{} - 1.0 / 5040.0);
    ps = fma(ps, r2, D{} + 1.0 / 120.0);
    ps = fma(ps, r2, D{} - 1.0 / 6.0);
    const D sr = r + r * r2 * ps;
    D pc = D{} + 1.0 / 20922789888000.0;
    pc = fma(pc, r2, D{} - 1.0 / 87178291200.0);
    pc = fma(pc, r2, D{} + 1.0 / 479001600.0);
    pc = fma(pc, r2, D{} - 1.0 / 3628800.0);
    pc = fma(pc, r2, D{} + 1.0 / 40320.0);
    pc = fma(pc, r2, D{} - 1.0 / 720.0);
    pc = fma(pc, r2, D{} + 1.0 / 24.0);
    pc = fma(pc, r2, D{} - 0.5);
    const D cr = 1.0 + r2 * pc;
    const auto quadrant = simd::bits(t) & 3u;
    const D nsr = -sr, ncr = -cr;
    s = quadrant == 0 ? sr : (quadrant == 1 ? cr : (quadrant == 2 ? nsr : ncr));
    c = quadrant == 0 ? cr : (quadrant == 1 ? nsr : (quadrant == 2 ? ncr : sr));
}

// |x| and the sign bit of x (true for -0 and negative NaNs), for double or simd::f64v.
RE_INLINE double abs(double x) { return std::fabs(x); }
RE_INLINE simd::f64v abs(simd::f64v x) { return simd::from_bits(simd::bits(x) & 0x7fffffffffffffffULL); }
RE_INLINE bool sign_bit(double x) { return std::signbit(x); }
RE_INLINE simd::i64v sign_bit(simd::f64v x) { return (simd::i64v)(simd::bits(x) >> 63) != 0; }

// atan2(y, x) / (2 pi) taken mod 1, in [0, 1): the azimuth of (x, y) in turns, as numpy's
// mod(arctan2(y, x) / (2 pi), 1) gives it (signed zeros as atan2 treats them; NaN for a NaN
// coordinate or two infinite ones), for double or simd::f64v (the same bits lane by lane),
// within 2 ulp (tested against long double atan2 in tests/core/test_fastmath.py).  libm's
// atan2 is a scalar call with branches, twice the time of the rest of a domain map.
// t = min/max(|x|, |y|) in [0, 1]; above tan(pi/8), atan t = pi/4 + atan((t - 1) / (t + 1));
// then atan r = r + r z g(z), z = r^2 <= tan^2(pi/8), g a degree-10 polynomial interpolating
// (atan r - r) / (r z) at Chebyshev nodes (fitted in long double by tools/fit_atan_turns.py:
// truncation below 1e-17 relative); the octant is restored in turns, where the constants
// 1/8, 1/4 and 1/2 are exact.
template <class D>
RE_INLINE D atan2_turns(D y, D x) {
    using simd::fma;
    const D zero{}, one = zero + 1.0;
    const D ax = abs(x), ay = abs(y);
    const D mn = ax < ay ? ax : ay, mx = ax < ay ? ay : ax;
    const D t = mn / (mx == zero ? one : mx);   // divisions unconditional, selects after: a
    const D reduced = (t - 1.0) / (t + 1.0);    // conditional division blocks vectorisation
    const auto big = t > zero + 0.41421356237309503;  // tan(pi/8)
    const D r = big ? reduced : t;
    const D z = r * r;
    D g = zero - 0x1.3a331903e1769p-6;
    g = fma(g, z, zero + 0x1.4163550d329f5p-5);
    g = fma(g, z, zero - 0x1.a099d072df655p-5);
    g = fma(g, z, zero + 0x1.dfe65376724e6p-5);
    g = fma(g, z, zero - 0x1.10fa7842b94e9p-4);
    g = fma(g, z, zero + 0x1.3b12631038debp-4);
    g = fma(g, z, zero - 0x1.745d0b290bd9bp-4);
    g = fma(g, z, zero + 0x1.c71c71853f824p-4);
    g = fma(g, z, zero - 0x1.249249243621ep-3);
    g = fma(g, z, zero + 0x1.999999999934cp-3);
    g = fma(g, z, zero - 0x1.5555555555555p-2);
    D turns = fma(r * z, g, r) / 6.283185307179586;
    turns = big ? turns + 0.125 : turns;
    turns = ay > ax ? 0.25 - turns : turns;
    turns = sign_bit(x) ? 0.5 - turns : turns;
    turns = sign_bit(y) ? zero - turns : turns;
    return turns < zero ? turns + 1.0 : turns + 0.0;  // + 0.0: a zero comes out +0, as numpy's mod
}

}  // namespace re::fm
