// A float32 renderer's numbers in the sampler check: directions rounded to float32 unit
// vectors as Mitsuba's pdf takes them (float32_unit_rows), its float32 columns as float64
// rows and float64 rows as its float32 columns (float64_rows, float32_columns), whether values
// are float32 (all_float32), float32 points dithered within their rounding intervals
// (dither_float32), and float32 points with one coordinate moved by whole ulps (float32_nudged).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

#include "simd.h"

namespace re {

// The rows float32_unit_rows rounds as given, by their squared length n2: a row whose n2 lies
// within (1 -+ slack / 2)^2 is within slack of 1 whatever the rounding (it is far inside);
// none where slack >= 1 (fast false: 1 - slack / 2 may be <= 0) or is NaN.
struct UnitSlack {
    double slack, lo, hi;
    bool fast;
    explicit UnitSlack(double s)
        : slack(s), lo((1 - s / 2) * (1 - s / 2)), hi((1 + s / 2) * (1 + s / 2)), fast(s < 1) {}
    bool inside(double n2) const { return fast && n2 >= lo && n2 <= hi; }
    // every lane's n2 inside (a NaN is not): n2 where inside, NaN elsewhere, equal to n2
    bool all_inside(simd::f64v n2) const {
        return fast && simd::all_equal((n2 >= lo) & (n2 <= hi) ? n2 : simd::f64v{} + NAN, n2);
    }
};

// Row i of float32_unit_rows (below), one at a time.
inline void float32_unit_row(const double *x, size_t i, size_t stride, const UnitSlack &unit, float *out, bool *ok) {
    double u = x[3 * i], v = x[3 * i + 1], w = x[3 * i + 2];
    const double n2 = u * u + v * v + w * w;
    if (!unit.inside(n2)) {
        const double norm = std::sqrt(n2);
        const bool good = std::isfinite(norm) && norm > 0;
        const double scale = good && std::fabs(norm - 1) > unit.slack ? norm : 1.0;
        u = good ? u / scale : 0.0;
        v = good ? v / scale : 0.0;
        w = good ? w / scale : 1.0;
        ok[i] = good;
    } else {
        ok[i] = true;
    }
    out[i] = float(u);
    out[stride + i] = float(v);
    out[2 * stride + i] = float(w);
}

// Rows x (n, 3) as float32 unit vectors, column by column into out (3 rows of n, row stride
// `stride` >= n; rows a .. b - 1 of x): a row of length within `slack` of 1 is rounded as
// given, another finite non-zero one is normalised in double first; a row that is not a
// finite non-zero vector becomes +z with ok false.  What a float32 renderer's pdf is called
// with (Mitsuba's adapter).  A row whose squared length lies within (1 -+ slack / 2)^2 is
// within slack of 1 whatever the rounding (it is far inside), and is rounded as given without
// the root and three divisions (x / 1 is x: the same bits), which had held every row at the
// divider: 2.5 ns a row, a third of a Mitsuba pdf call's time.  A vector of rows all inside
// is transposed and rounded in lanes (load3, one conversion a column: the same bits as
// float() a value), the others a row at a time (the scalar loop had cost the cubature's 2.8
// million directions of a diffuse BSDF's check 15 ms).
inline void float32_unit_rows(const double *x, size_t a, size_t b, size_t stride, double slack, float *out,
                              bool *ok) {
    const UnitSlack unit(slack);
    constexpr size_t W = simd::kWidth;
    using simd::f32v;
    size_t i = a;
    for (; unit.fast && i + W <= b; i += W) {
        simd::f64v u, v, w;
        simd::load3(x + 3 * i, u, v, w);
        const simd::f64v n2 = u * u + v * v + w * w;
        if (!unit.all_inside(n2)) {
            for (size_t j = i; j < i + W; ++j) float32_unit_row(x, j, stride, unit, out, ok);
            continue;
        }
        const f32v fu = __builtin_convertvector(u, f32v), fv = __builtin_convertvector(v, f32v),
                   fw = __builtin_convertvector(w, f32v);
        std::memcpy(out + i, &fu, sizeof fu);
        std::memcpy(out + stride + i, &fv, sizeof fv);
        std::memcpy(out + 2 * stride + i, &fw, sizeof fw);
        for (size_t j = i; j < i + W; ++j) ok[j] = true;
    }
    for (; i < b; ++i) float32_unit_row(x, i, stride, unit, out, ok);
}

// Columns of float32 values (column j's n values at columns[j], c of them), rows a .. b - 1,
// as rows (n, c) of doubles into out: a float32 renderer's vectors (drjit's (3, N) arrays, or
// a drjit vector's components, each its own array) in the row order the check's kernels read.
// Three columns (directions) a vector of rows at a time, widened in lanes and stored by
// store3's transposition (GCC's element loop had cost a diffuse BSDF's check 3.8 ms).
inline void float64_rows(const float *const *columns, size_t c, size_t a, size_t b, double *out) {
    size_t i = a;
    if (c == 3) {
        constexpr size_t W = simd::kWidth;
        for (; i + W <= b; i += W) {
            simd::f32v p[3];
            for (size_t j = 0; j < 3; ++j) std::memcpy(&p[j], columns[j] + i, sizeof p[j]);
            simd::store3(out + 3 * i, __builtin_convertvector(p[0], simd::f64v), __builtin_convertvector(p[1], simd::f64v),
                         __builtin_convertvector(p[2], simd::f64v));
        }
    }
    for (; i < b; ++i)
        for (size_t j = 0; j < c; ++j) out[i * c + j] = double(columns[j][i]);
}

// Rows (n, c) of doubles, rows a .. b - 1, as columns (c, n) of float32 into out, each value
// rounded to float32 (to nearest) and then capped at `cap` (a NaN stays NaN): what a float32
// renderer's sample call is given, the uniforms u (N, udim) clamped below 1 after rounding
// (numpy's minimum(u[:, j], cap, dtype=float32), the same bits; its strided pass a column
// took 2.5 ms a million uniforms).
inline void float32_columns(const double *rows, size_t c, size_t n, size_t a, size_t b, float cap, float *out) {
    for (size_t j = 0; j < c; ++j)
        for (size_t i = a; i < b; ++i) {
            const float v = float(rows[i * c + j]);
            out[j * n + i] = cap < v ? cap : v;   // v NaN: the comparison is false, v kept
        }
}

// Whether every finite non-zero value of v (n) is a float32 (rounds to itself through float),
// and there is one: a float32 renderer's numbers, whether returned as float32 or float64.
// Stops after the block of 1024 values holding the first value that is not.  Written so that
// GCC vectorises it (3.8 -> 0.6 ms on a million directions, where the value-by-value loop ran
// scalar): the range tests on the bits (|x|'s bits order as |x| does; a floating-point
// comparison may trap on a NaN, which kept the loop's branches), the value beyond float's
// range replaced by 0 through its bits (a select of doubles feeding the conversion became a
// branch), flags in 64-bit integers as wide as the doubles' lanes.
inline bool all_float32(const double *v, size_t n) {
    constexpr uint64_t kMagnitude = ~(uint64_t(1) << 63), kInfinity = 0x7ff0000000000000ull;
    constexpr uint64_t kFloatMax = 0x47efffffe0000000ull;   // the bits of double(FLT_MAX)
    constexpr size_t kBlock = 1024;
    bool any = false;
    for (size_t start = 0; start < n; start += kBlock) {
        const size_t end = start + kBlock < n ? start + kBlock : n;
        int64_t bad = 0, some = 0;
        for (size_t i = start; i < end; ++i) {
            uint64_t bits;
            std::memcpy(&bits, v + i, 8);
            const uint64_t magnitude = bits & kMagnitude;
            const int64_t counted = int64_t(magnitude != 0) & int64_t(magnitude < kInfinity);   // finite, non-zero
            const uint64_t in_range = bits & (uint64_t(0) - uint64_t(magnitude <= kFloatMax));  // else 0
            double y;
            std::memcpy(&y, &in_range, 8);
            bad |= counted & int64_t(double(float(y)) != v[i]);
            some |= counted;
        }
        if (bad) return false;
        any |= some != 0;
    }
    return any;
}

// out[i] = v[i] moved to below + (above - below) u[i], below and above half way to v's float32
// neighbours (v rounded to float32 first), for n values; v itself where that is not finite (v
// NaN, infinite, or beyond the float32 range or at its end, where a neighbour is infinite).
// The sampler check's dithering of float32 points: the bits of numpy's nextafter
// expression (tests/core/test_check_kernels_float32.py, dither_reference), in one pass where numpy's
// eight took 0.1 s a million directions.
//
// Written for GCC to vectorise it (1.5 -> 0.4 ns a value; nextafterf and a step of the
// float's bits by sign had kept it scalar): the neighbours as f -+ the float32 spacing below
// and above f, exact in double, the spacing 2^(max(e, -126) - 23) for f's exponent e (the
// subnormals' 2^-149 at and below 2^-126), halved below a positive power of two (and above
// a negative one) above the subnormals; every choice made on the bits, as all_float32's are.
inline void dither_float32(const double *v, const double *u, size_t n, double *out) {
    constexpr uint64_t kMagnitude = ~(uint64_t(1) << 63), kMantissa = (uint64_t(1) << 52) - 1;
    constexpr uint64_t kFloatMax = 0x47efffffe0000000ull, kInfinity = 0x7ff0000000000000ull;
    constexpr int64_t kMinNormal = 1023 - 126;   // the biased double exponent of 2^-126
    auto bits = [](double x) { uint64_t b; std::memcpy(&b, &x, 8); return b; };
    auto value = [](uint64_t b) { double x; std::memcpy(&x, &b, 8); return x; };
    auto pick = [](uint64_t yes, uint64_t a, uint64_t b) { return (a & yes) | (b & ~yes); };  // yes: all ones or 0
    auto all_ones = [](bool c) { return uint64_t(0) - uint64_t(c); };
    for (size_t i = 0; i < n; ++i) {
        const double x = v[i];
        const uint64_t xb = bits(x);
        const uint64_t in_range = all_ones((xb & kMagnitude) <= kFloatMax);     // float(x) defined
        const double f = double(float(value(xb & in_range)));
        const uint64_t fb = bits(f), magnitude = fb & kMagnitude;
        const int64_t e = int64_t(magnitude >> 52);
        const int64_t up = (e > kMinNormal ? e : kMinNormal) - 23;              // the spacing's exponent
        const int64_t down = up - int64_t((magnitude & kMantissa) == 0 && e > kMinNormal);
        const uint64_t negative = all_ones((fb >> 63) != 0);
        const double step_up = value(uint64_t(pick(negative, uint64_t(down), uint64_t(up))) << 52);
        const double step_down = value(uint64_t(pick(negative, uint64_t(up), uint64_t(down))) << 52);
        const double below = (x + (f - step_down)) / 2;
        const double above = (x + (f + step_up)) / 2;
        const double d = below + (above - below) * u[i];
        const uint64_t keep = ~in_range | all_ones(magnitude == kFloatMax) | all_ones((bits(d) & kMagnitude) >= kInfinity);
        out[i] = value(pick(keep, xb, bits(d)));
    }
}

// Rows x (n, d), rows a .. b - 1, rounded to float32 with column c moved |steps| float32 ulps
// (up if steps > 0, down if < 0), back as doubles into out (n, d): the points whose pdf the
// reported-pdf check's rounding tolerance reads (harness.samplers.reported).  The bits of
// numpy's |steps| nextafter calls in float32 towards +-inf (tests/core/test_check_kernels_float32.py):
// a step is one on the integer that orders the floats (its magnitude's bits, negated for a
// negative float; +0 and -0 both 0, as nextafter steps from either to the same subnormal), held
// at the infinities; a zero reached from the other side keeps the start's sign (nextafter's
// -denorm_min up is -0); NaN stays NaN.  numpy's copy, nextafter passes and cast had cost a
// check of a steep lobe 0.13 s for its 0.8 million mismatching samples.
inline void float32_nudged(const double *x, size_t d, size_t c, int steps, size_t a, size_t b, double *out) {
    constexpr int64_t kInfinity = 0x7f800000;
    for (size_t i = a; i < b; ++i)
        for (size_t j = 0; j < d; ++j) out[i * d + j] = double(float(x[i * d + j]));
    for (size_t i = a; i < b; ++i) {
        const float f = float(x[i * d + c]);
        uint32_t fb;
        std::memcpy(&fb, &f, 4);
        const uint32_t sign = fb & 0x80000000u;
        const int64_t key = sign ? -int64_t(fb & 0x7fffffffu) : int64_t(fb);
        int64_t k = key + steps;
        k = k > kInfinity ? kInfinity : (k < -kInfinity ? -kInfinity : k);
        uint32_t ob = k < 0 ? (0x80000000u | uint32_t(-k)) : uint32_t(k);
        if (k == 0) ob = sign;
        float g;
        std::memcpy(&g, &ob, 4);
        out[i * d + c] = std::isnan(f) ? double(f) : double(g);
    }
}

}  // namespace re
