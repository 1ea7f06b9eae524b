// A float32 renderer's numbers in the sampler check: directions rounded to float32 unit
// vectors as Mitsuba's pdf takes them (float32_unit_rows), whether values are float32
// (all_float32), and float32 points dithered within their rounding intervals (dither_float32).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace re {

// Rows x (n, 3) as float32 unit vectors, column by column into out (3 rows of n, row stride
// `stride` >= n; rows a .. b - 1 of x): a row of length within `slack` of 1 is rounded as
// given, another finite non-zero one is normalised in double first; a row that is not a
// finite non-zero vector becomes +z with ok false.  What a float32 renderer's pdf is called
// with (Mitsuba's adapter).  A row whose squared length lies within (1 -+ slack / 2)^2 is
// within slack of 1 whatever the rounding (it is far inside), and is rounded as given without
// the root and three divisions (x / 1 is x: the same bits), which had held every row at the
// divider: 2.5 ns a row, a third of a Mitsuba pdf call's time.
inline void float32_unit_rows(const double *x, size_t a, size_t b, size_t stride, double slack, float *out,
                              bool *ok) {
    const double inner_lo = (1 - slack / 2) * (1 - slack / 2), inner_hi = (1 + slack / 2) * (1 + slack / 2);
    const bool fast = slack < 1;   // else 1 - slack / 2 may be <= 0: no inner interval
    for (size_t i = a; i < b; ++i) {
        double u = x[3 * i], v = x[3 * i + 1], w = x[3 * i + 2];
        const double n2 = u * u + v * v + w * w;
        if (!(fast && n2 >= inner_lo && n2 <= inner_hi)) {
            const double norm = std::sqrt(n2);
            const bool good = std::isfinite(norm) && norm > 0;
            const double scale = good && std::fabs(norm - 1) > slack ? norm : 1.0;
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
}

// Columns (c, n) of float32 values, rows a .. b - 1, as rows (n, c) of doubles into out: a
// float32 renderer's vectors (drjit's (3, N) arrays) in the row order the check's kernels read.
inline void float64_rows(const float *columns, size_t c, size_t n, size_t a, size_t b, double *out) {
    for (size_t i = a; i < b; ++i)
        for (size_t j = 0; j < c; ++j) out[i * c + j] = double(columns[j * n + i]);
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

// The float32 after f (finite) toward +infinity, as nextafterf(f, inf): one step of its bits
// (FLT_MAX steps to inf, -denorm_min to -0, both zeros to denorm_min); inline, where libm's
// call took most of dither_float32's time.
inline float float32_up(float f) {
    if (f == 0) return std::numeric_limits<float>::denorm_min();
    uint32_t b;
    std::memcpy(&b, &f, 4);
    b = f > 0 ? b + 1 : b - 1;
    std::memcpy(&f, &b, 4);
    return f;
}

// out[i] = v[i] moved to below + (above - below) u[i], below and above half way to v's float32
// neighbours (v rounded to float32 first), for n values; v itself where that is not finite (v
// NaN, infinite, or beyond the float32 range or at its end, where a neighbour is infinite).
// The sampler check's dithering of float32 points; numpy's operations in numpy's order, the
// same bits, in one pass where numpy's eight took 0.1 s a million directions.
inline void dither_float32(const double *v, const double *u, size_t n, double *out) {
    for (size_t i = 0; i < n; ++i) {
        const double x = v[i];
        if (!(std::fabs(x) <= double(std::numeric_limits<float>::max()))) {  // float(x) would be inf (or UB)
            out[i] = x;
            continue;
        }
        const float f = float(x);
        const double below = (x + double(-float32_up(-f))) / 2;
        const double above = (x + double(float32_up(f))) / 2;
        const double d = below + (above - below) * u[i];
        out[i] = std::isfinite(d) ? d : x;
    }
}

}  // namespace re
