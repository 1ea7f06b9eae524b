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
#include <cstring>
#include <limits>

namespace re::fm {

inline double bits_as_double(uint64_t b) { double d; std::memcpy(&d, &b, 8); return d; }
inline uint64_t double_as_bits(double d) { uint64_t b; std::memcpy(&b, &d, 8); return b; }

// 2^(j/64), j = 0..63, each the correctly rounded double (computed with Python's decimal
// module at 60 digits).
alignas(64) inline constexpr double kExp2Table[64] = {
    0x1.0000000000000p+0, 0x1.02c9a3e778061p+0, 0x1.059b0d3158574p+0, 0x1.0874518759bc8p+0,
    0x1.0b5586cf9890fp+0, 0x1.0e3ec32d3d1a2p+0, 0x1.11301d0125b51p+0, 0x1.1429aaea92de0p+0,
    0x1.172b83c7d517bp+0, 0x1.1a35beb6fcb75p+0, 0x1.1d4873168b9aap+0, 0x1.2063b88628cd6p+0,
    0x1.2387a6e756238p+0, 0x1.26b4565e27cddp+0, 0x1.29e9df51fdee1p+0, 0x1.2d285a6e4030bp+0,
    0x1.306fe0a31b715p+0, 0x1.33c08b26416ffp+0, 0x1.371a7373aa9cbp+0, 0x1.3a7db34e59ff7p+0,
    0x1.3dea64c123422p+0, 0x1.4160a21f72e2ap+0, 0x1.44e086061892dp+0, 0x1.486a2b5c13cd0p+0,
    0x1.4bfdad5362a27p+0, 0x1.4f9b2769d2ca7p+0, 0x1.5342b569d4f82p+0, 0x1.56f4736b527dap+0,
    0x1.5ab07dd485429p+0, 0x1.5e76f15ad2148p+0, 0x1.6247eb03a5585p+0, 0x1.6623882552225p+0,
    0x1.6a09e667f3bcdp+0, 0x1.6dfb23c651a2fp+0, 0x1.71f75e8ec5f74p+0, 0x1.75feb564267c9p+0,
    0x1.7a11473eb0187p+0, 0x1.7e2f336cf4e62p+0, 0x1.82589994cce13p+0, 0x1.868d99b4492edp+0,
    0x1.8ace5422aa0dbp+0, 0x1.8f1ae99157736p+0, 0x1.93737b0cdc5e5p+0, 0x1.97d829fde4e50p+0,
    0x1.9c49182a3f090p+0, 0x1.a0c667b5de565p+0, 0x1.a5503b23e255dp+0, 0x1.a9e6b5579fdbfp+0,
    0x1.ae89f995ad3adp+0, 0x1.b33a2b84f15fbp+0, 0x1.b7f76f2fb5e47p+0, 0x1.bcc1e904bc1d2p+0,
    0x1.c199bdd85529cp+0, 0x1.c67f12e57d14bp+0, 0x1.cb720dcef9069p+0, 0x1.d072d4a07897cp+0,
    0x1.d5818dcfba487p+0, 0x1.da9e603db3285p+0, 0x1.dfc97337b9b5fp+0, 0x1.e502ee78b3ff6p+0,
    0x1.ea4afa2a490dap+0, 0x1.efa1bee615a27p+0, 0x1.f50765b6e4540p+0, 0x1.fa7c1819e90d8p+0,
};

// exp(x): x = (64 k + j) ln2/64 + r with |r| <= ln2/128, exp(x) = 2^k 2^(j/64) exp(r), and
// exp(r) - 1 by a degree-5 Taylor polynomial (truncation < 4e-17).  The table lookup
// vectorises to a gather; 2^k is applied in two steps so subnormal results come out right.
inline double exp(double x) {
    const double kShift = 0x1.8p52;
    const double kLn2Hi = 0.693147180559890330187045037746429443359375;  // hi + lo = ln 2
    const double kLn2Lo = 5.497923018708371174712471492138406e-14;
    double xc = x < -746.0 ? -746.0 : (x > 710.0 ? 710.0 : x);
    double t = std::fma(xc, 64 * 1.4426950408889634, kShift);
    double n = t - kShift;  // round(64 x / ln 2)
    double r = std::fma(n, -kLn2Hi / 64, xc);
    r = std::fma(n, -kLn2Lo / 64, r);
    double p = 1.0 / 120;
    p = std::fma(p, r, 1.0 / 24);
    p = std::fma(p, r, 1.0 / 6);
    p = std::fma(p, r, 0.5);
    p = std::fma(p, r, 1.0);
    p = p * r;
    int64_t ni = int64_t(n);
    int64_t k = ni >> 6, k1 = k >> 1, k2 = k - k1;
    double tj = kExp2Table[ni & 63];
    double s1 = bits_as_double(uint64_t(k1 + 1023) << 52);
    double s2 = bits_as_double(uint64_t(k2 + 1023) << 52);
    double y = std::fma(tj, p, tj) * s1 * s2;
    y = x > 709.782712893384 ? std::numeric_limits<double>::infinity() : y;
    y = x < -745.2 ? 0.0 : y;
    return x != x ? x : y;
}

// log(x): x = (1 + f) 2^e with 1 + f in [sqrt(1/2), sqrt(2)) and f exact; with s = f/(2+f),
// log(1+f) = 2 atanh(s) = f - (f^2/2 - s (f^2/2 + R)), R = 2 s^2/3 + 2 s^4/5 + ... to s^22
// (truncation < 1e-18): the leading term f carries no rounding error (the arrangement of
// fdlibm's e_log.c, with a Taylor series instead of its minimax coefficients).
inline double log(double x) {
    bool sub = x < 0x1p-1022;
    double xs = sub ? x * 0x1p54 : x;
    uint64_t b = double_as_bits(xs);
    int64_t e = int64_t((b >> 52) & 0x7ff) - 1023;
    double m = bits_as_double((b & 0x000fffffffffffffULL) | 0x3ff0000000000000ULL);
    bool big = m > 1.4142135623730951;
    m = big ? m * 0.5 : m;
    e = big ? e + 1 : e;
    e = sub ? e - 54 : e;
    double f = m - 1.0;  // exact (Sterbenz)
    double s = f / (2.0 + f), z = s * s;
    double r = 2.0 / 23.0;
    r = std::fma(r, z, 2.0 / 21.0);
    r = std::fma(r, z, 2.0 / 19.0);
    r = std::fma(r, z, 2.0 / 17.0);
    r = std::fma(r, z, 2.0 / 15.0);
    r = std::fma(r, z, 2.0 / 13.0);
    r = std::fma(r, z, 2.0 / 11.0);
    r = std::fma(r, z, 2.0 / 9.0);
    r = std::fma(r, z, 2.0 / 7.0);
    r = std::fma(r, z, 2.0 / 5.0);
    r = std::fma(r, z, 2.0 / 3.0);
    r *= z;
    double hfsq = 0.5 * f * f, de = double(e);
    double y = de * 6.93147180369123816490e-01 - ((hfsq - (s * (hfsq + r) + de * 1.90821492927058770002e-10)) - f);
    y = x == std::numeric_limits<double>::infinity() ? x : y;
    y = x == 0.0 ? -std::numeric_limits<double>::infinity() : y;
    y = x < 0.0 ? std::numeric_limits<double>::quiet_NaN() : y;
    return x != x ? x : y;
}

// sin and cos of 2*pi*u for any finite u: the reduction u - q/4 is exact, so the result
// is accurate for the canonical uniforms the samplers feed in.
inline void sincos_2pi(double u, double &s, double &c) {
    double q = u * 4.0;
    const double kShift = 0x1.8p52;
    double qn = (q + kShift) - kShift;  // nearest integer
    double r = (u - qn * 0.25) * 6.283185307179586;  // |r| <= pi/4
    double r2 = r * r;
    double ps = -1.0 / 1307674368000.0;
    ps = std::fma(ps, r2, 1.0 / 6227020800.0);
    ps = std::fma(ps, r2, -1.0 / 39916800.0);
    ps = std::fma(ps, r2, 1.0 / 362880.0);
    ps = std::fma(ps, r2, -1.0 / 5040.0);
    ps = std::fma(ps, r2, 1.0 / 120.0);
    ps = std::fma(ps, r2, -1.0 / 6.0);
    double sr = r + r * r2 * ps;
    double pc = 1.0 / 20922789888000.0;
    pc = std::fma(pc, r2, -1.0 / 87178291200.0);
    pc = std::fma(pc, r2, 1.0 / 479001600.0);
    pc = std::fma(pc, r2, -1.0 / 3628800.0);
    pc = std::fma(pc, r2, 1.0 / 40320.0);
    pc = std::fma(pc, r2, -1.0 / 720.0);
    pc = std::fma(pc, r2, 1.0 / 24.0);
    pc = std::fma(pc, r2, -0.5);
    double cr = 1.0 + r2 * pc;
    int64_t quadrant = int64_t(qn) & 3;
    double ss = quadrant == 0 ? sr : (quadrant == 1 ? cr : (quadrant == 2 ? -sr : -cr));
    double cc = quadrant == 0 ? cr : (quadrant == 1 ? -sr : (quadrant == 2 ? -cr : sr));
    s = ss;
    c = cc;
}

}  // namespace re::fm
