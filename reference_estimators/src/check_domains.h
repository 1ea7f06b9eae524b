// The sampler check's domains (harness/samplers/domains.py) as batch kernels: their
// equal-measure parameter maps both ways (domain_params, domain_points), the cap map of the
// Mitsuba adapter's area lights both ways and its density (cap_to_world, cap_to_hemisphere,
// cap_density), the rectangle light's map both ways and its density (rect_to_square,
// rect_to_world, rect_density), and the finite rows of a point array.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "check_rows.h"
#include "fastmath.h"

namespace re {

// The sampling domains of the sampler check, in the order of harness.samplers.domains.DOMAINS.
enum class CheckDomain : int { interval = 0, half_line = 1, square = 2, disk = 3, hemisphere = 4, sphere = 5 };

inline int domain_param_dim(CheckDomain d) { return d == CheckDomain::interval || d == CheckDomain::half_line ? 1 : 2; }
inline int domain_point_dim(CheckDomain d) {
    switch (d) {
        case CheckDomain::interval:
        case CheckDomain::half_line: return 1;
        case CheckDomain::square:
        case CheckDomain::disk: return 2;
        default: return 3;
    }
}

// s[2 i + 1] = the azimuth in turns of the disk's point (x[2 i], x[2 i + 1]), for n points:
// whole vectors of fastmath's atan2_turns, then the scalar tail (the same bits).
inline void disk_azimuths(const double *x, size_t n, double *s) {
    constexpr size_t W = simd::kWidth;
    size_t i = 0;
    for (; i + W <= n; i += W) {
        simd::f64v a, b;
        simd::deinterleave(x + 2 * i, a, b);
        const simd::f64v turns = fm::atan2_turns(b, a);
        for (size_t w = 0; w < W; ++w) s[2 * (i + w) + 1] = turns[w];
    }
    for (; i < n; ++i) s[2 * i + 1] = fm::atan2_turns(x[2 * i + 1], x[2 * i]);
}

// domain_params on the hemisphere or the sphere: a unit vector (a, b, c) within 1e-5 of unit
// squared norm (and c >= -1e-12 on the hemisphere) is inside; s0 = cos theta of the direction
// (a, b, c) / r, r = |(a, b, c)| (on the sphere (1 - cos theta) / 2), s1 its azimuth in turns.
// cos theta is taken across the nearer pole, 1 -+ cos theta = t / (r (r +- c)) with t = a^2 +
// b^2: near a pole a float32 renderer's c moves in steps of 6e-8 and its |(a, b, c)| misses 1
// by as much, while a and b keep their relative precision.  With c itself as s0, a lobe about
// the pole had those errors on a large part of its 1 - cos theta (GGX alpha = 0.003 at normal
// incidence: 1.8e-5 across the lobe), and Mitsuba's correct sampler failed the Cramer-von
// Mises test at p = 1e-37 on every seed (it passes now).  s0 so taken is the normalised
// direction's to a few 1e-16 (no cancellation: the quotient lies in [0, 1]).  Whole vectors of directions in lanes (load3's transposition, the azimuth in the same
// pass), the tail one at a time: the same bits (sqrt and division are correctly rounded; a
// scalar loop of stride-3 loads and a second pass for the azimuths had cost the dithered
// check's two maps of a million directions about 4 ms).
template <bool hemi, class D, class In>
RE_INLINE void direction_param(D a, D b, D c, D &s0, In &in) {
    const D t = a * a + b * b, norm = t + c * c, off = norm - 1.0;
    // |off| <= 1e-5 by two comparisons, false for NaN as fabs's is: a NaN or infinite
    // coordinate (or squares that overflow) makes the norm NaN or +inf, so it fails this too
    const auto ok = (off <= 1e-5) & (off >= -1e-5);
    const D r = simd::sqrt(norm);
    const auto north = c >= 0.0;
    const D across = t / (r * (r + (north ? c : D{} - c)));   // 1 -+ cos theta; NaN where r is 0
    if constexpr (hemi) {
        s0 = north ? 1.0 - across : across - 1.0;
    } else {   // (1 - cos theta) / 2
        const D half = across * 0.5;
        s0 = north ? half : 1.0 - half;
    }
    in = hemi ? ok & (c >= -1e-12) : ok;
}
template <bool hemi>
inline void direction_params(const double *x, size_t n, double *s, bool *inside) {
    constexpr size_t W = simd::kWidth;
    size_t i = 0;
    for (; i + W <= n; i += W) {
        simd::f64v a, b, c, s0;
        simd::load3(x + 3 * i, a, b, c);
        decltype(a == a) in;
        direction_param<hemi>(a, b, c, s0, in);
        for (size_t w = 0; w < W; ++w) inside[i + w] = in[w] != 0;
        if (s) simd::interleave(s + 2 * i, s0, fm::atan2_turns(b, a));
    }
    for (; i < n; ++i) {
        const double a = x[3 * i], b = x[3 * i + 1], c = x[3 * i + 2];
        double s0;
        bool in;
        direction_param<hemi>(a, b, c, s0, in);
        inside[i] = in;
        if (s) {
            s[2 * i] = s0;
            s[2 * i + 1] = fm::atan2_turns(b, a);
        }
    }
}

// Parameters s (n, k) of points x (n, point_dim) and whether each lies inside the domain:
// the equal-measure maps of harness/samplers/domains.py (see there).  Unit vectors count as
// inside when their squared norm is within 1e-5 of 1 (float32 renderers); a non-finite
// point is outside (its s may be NaN).  s null: `inside` alone (no azimuths).
inline void domain_params(CheckDomain d, double lo, double hi, const double *x, size_t n, double *s,
                          bool *inside) {
    switch (d) {
        case CheckDomain::interval:
            for (size_t i = 0; i < n; ++i) {
                const double v = x[i];
                if (s) s[i] = (v - lo) / (hi - lo);
                inside[i] = std::isfinite(v) && v >= lo && v <= hi;
            }
            return;
        case CheckDomain::half_line:
            for (size_t i = 0; i < n; ++i) {
                const double v = x[i];
                if (s) s[i] = v / (1.0 + v);
                inside[i] = std::isfinite(v) && v >= 0;
            }
            return;
        case CheckDomain::square:
            for (size_t i = 0; i < n; ++i) {
                const double a = x[2 * i], b = x[2 * i + 1];
                if (s) {
                    s[2 * i] = a;
                    s[2 * i + 1] = b;
                }
                inside[i] = std::isfinite(a) && std::isfinite(b) && a >= 0 && a <= 1 && b >= 0 && b <= 1;
            }
            return;
        case CheckDomain::disk:
            for (size_t i = 0; i < n; ++i) {
                const double a = x[2 * i], b = x[2 * i + 1];
                const double r2 = a * a + b * b;
                if (s) s[2 * i] = r2;
                inside[i] = std::isfinite(a) && std::isfinite(b) && r2 <= 1 + 1e-12;
            }
            if (s) disk_azimuths(x, n, s);
            return;
        case CheckDomain::hemisphere:
        case CheckDomain::sphere:
            d == CheckDomain::hemisphere ? direction_params<true>(x, n, s, inside) : direction_params<false>(x, n, s, inside);
            return;
    }
}

// World directions out (n, 3) of the points h (n, 3) of the hemisphere through the
// equal-area map of the cap {d : <d, axis> >= cos_alpha} (harness/adapters/mitsuba/cap.py,
// Cap.to_world; frame t, b, axis orthonormal, scale = 1 - cos_alpha): h normalised, then
// c = clamp(cos_alpha + z scale, -1, 1) along the axis and the azimuth's cosine and sine as
// x / r and y / r, r = sqrt(x^2 + y^2) (the pole r = 0 at azimuth 0).  A point below the
// horizon maps outside the cap; NaN rows give NaN.  Rows a .. b - 1, kWidth at a time in
// vector lanes (the same bits as one at a time): a cubature of an area light maps some 70
// million nodes, where libm's hypot and a scalar loop had cost 35 ns a node.
template <class D>
RE_INLINE void cap_point(D p0, D p1, D p2, const double *axis, const double *t, const double *b, double cos_alpha,
                         double scale, D &o0, D &o1, D &o2) {
    const D len = simd::sqrt(p0 * p0 + p1 * p1 + p2 * p2);
    const D x = p0 / len, y = p1 / len, z = p2 / len;
    D c = cos_alpha + z * scale;
    c = c < -1.0 ? D{} - 1.0 : (c > 1.0 ? D{} + 1.0 : c);  // NaN passes
    const D r = simd::sqrt(x * x + y * y), w = 1.0 - c * c;
    const auto pole = r == 0.0;
    const D s = simd::sqrt(0.0 < w ? w : D{}) / (pole ? D{} + 1.0 : r);   // std::max(0, w): NaN -> 0
    const D cos_phi = pole ? s : s * x, sin_phi = pole ? D{} : s * y;
    o0 = cos_phi * t[0] + sin_phi * b[0] + c * axis[0];
    o1 = cos_phi * t[1] + sin_phi * b[1] + c * axis[1];
    o2 = cos_phi * t[2] + sin_phi * b[2] + c * axis[2];
}

inline void cap_to_world(const double *h, size_t a, size_t b, const double *axis, const double *t, const double *bv,
                         double cos_alpha, double scale, double *out) {
    simd::map3x3(h + 3 * a, out + 3 * a, b - a, [&](auto p0, auto p1, auto p2, auto &o0, auto &o1, auto &o2) {
        cap_point(p0, p1, p2, axis, t, bv, cos_alpha, scale, o0, o1, o2);
    });
}

// Points out (n, 3) of the hemisphere of world directions d (n, 3) through the equal-area map
// of the cap (Cap.to_hemisphere, the inverse of cap_point): d normalised, c = <d, axis> moved
// onto cos_alpha where it lies below it by at most rim_slack (float32 rounding of the rim),
// z = (c - cos_alpha) / scale, the azimuth about the axis kept: its cosine and sine as
// <d, t> / rho and <d, b> / rho, rho = sqrt(<d, t>^2 + <d, b>^2) (the axis, rho = 0, at
// azimuth 0), times r = sqrt(max(0, 1 - z^2)).  NaN and zero rows give NaN.  A million
// directions by numpy's norm, matrix products, arctan2, cosine and sine had cost 0.09 s of an
// area light's check.
template <class D>
RE_INLINE void cap_inverse_point(D p0, D p1, D p2, const double *axis, const double *t, const double *b,
                                 double cos_alpha, double scale, double rim_slack, D &o0, D &o1, D &o2) {
    const D len = simd::sqrt(p0 * p0 + p1 * p1 + p2 * p2);
    const D x = p0 / len, y = p1 / len, z = p2 / len;
    D c = x * axis[0] + y * axis[1] + z * axis[2];
    c = c < cos_alpha && c >= cos_alpha - rim_slack ? D{} + cos_alpha : c;
    const D h = (c - cos_alpha) / scale;
    const D pt = x * t[0] + y * t[1] + z * t[2], pb = x * b[0] + y * b[1] + z * b[2];
    const D rho = simd::sqrt(pt * pt + pb * pb), w = 1.0 - h * h;
    const auto pole = rho == 0.0;
    const D r = simd::sqrt(w < 0.0 ? D{} : w);   // np.maximum(0, w): NaN stays NaN
    const D s = r / (pole ? D{} + 1.0 : rho);
    o0 = pole ? r : s * pt;
    o1 = pole ? D{} : s * pb;
    o2 = h;
}

inline void cap_to_hemisphere(const double *d, size_t a, size_t e, const double *axis, const double *t,
                              const double *bv, double cos_alpha, double scale, double rim_slack, double *out) {
    simd::map3x3(d + 3 * a, out + 3 * a, e - a, [&](auto p0, auto p1, auto p2, auto &o0, auto &o1, auto &o2) {
        cap_inverse_point(p0, p1, p2, axis, t, bv, cos_alpha, scale, rim_slack, o0, o1, o2);
    });
}

// CapView.pdf's density on the hemisphere, rows a .. b - 1: out[i] = the world pdf p[i] in
// float32 times the map's Jacobian `scale` in float32, widened (numpy's float32 product), at
// the points h[i] (rows of 3) that are finite with h_z >= 0, else 0.  One pass where numpy's
// five had cost 3.3 ns a cubature node.
inline void cap_density(const double *h, const double *p, size_t a, size_t b, double scale, double *out) {
    const float js = float(scale);
    for (size_t i = a; i < b; ++i) {
        const double *r = h + 3 * i;
        const bool in = finite_bits(r[0]) & finite_bits(r[1]) & finite_bits(r[2]) & (r[2] >= 0.0);
        const double v = double(float(p[i]) * js);
        out[i] = in ? v : 0.0;
    }
}

// The rectangle light's map (harness/adapters/mitsuba/rectangle.py): the parallelogram
// corner + s0 e0 + s1 e1, s in [0, 1]^2, seen from ref, its unit normal n, the dual basis f
// (rows f0, f1: f_i . e_j = delta_ij) and the plane's signed distance from ref, height =
// <n, corner - ref>.  Each row's value is its numpy definition's
// (tests/core/test_check_kernels_area_light_maps.py) in the same order of operations, left to
// right: one pass where numpy's temporaries had cost 100-150 ns a direction.
struct RectangleFrame {
    const double *to_corner;   // corner - ref
    const double *e0, *e1, *normal;
    const double *dual;        // f0 then f1
    double height, area;       // <n, corner - ref>, |e0 x e1|
};

// Points s (rows a .. b - 1, 2 a row) of world directions d (3 a row) from ref
// (Rectangle.to_domain): t = height / <d, n>, the ray's point o = (ref - corner) + t d
// (t = 0 where 0 < t < inf fails), s_i = <o, f_i>, each within slack of [0, 1] clamped onto
// it; (-1, -1) where 0 < t < inf fails (a ray that misses the plane in front of ref, or runs
// along it: a zero or parallel direction), NaN for a row with a NaN.
inline void rect_to_square(const double *d, size_t a, size_t b, const RectangleFrame &f, double slack, double *s) {
    const double *n = f.normal, *c = f.to_corner;
    for (size_t i = a; i < b; ++i) {
        const double *r = d + 3 * i;
        const double dn = r[0] * n[0] + r[1] * n[1] + r[2] * n[2];
        const double t = f.height / dn;
        const bool hit = t > 0 && t < __builtin_inf();
        const double tt = hit ? t : 0.0;
        const double o[3] = {-c[0] + tt * r[0], -c[1] + tt * r[1], -c[2] + tt * r[2]};
        const bool nan = r[0] != r[0] || r[1] != r[1] || r[2] != r[2];
        for (int k = 0; k < 2; ++k) {
            const double *fk = f.dual + 3 * k;
            double v = o[0] * fk[0] + o[1] * fk[1] + o[2] * fk[2];
            if (v >= -slack && v <= 1 + slack) v = v < 0 ? 0.0 : (v > 1 ? 1.0 : v);
            s[2 * i + k] = nan ? __builtin_nan("") : (hit ? v : -1.0);
        }
    }
}

// The vector P(s) - ref = (corner - ref) + s0 e0 + s1 e1 of the point s.
RE_INLINE void rect_vector(const RectangleFrame &f, double s0, double s1, double *w) {
    for (int k = 0; k < 3; ++k) w[k] = f.to_corner[k] + s0 * f.e0[k] + s1 * f.e1[k];
}

// Unit world directions out (3 a row) from ref towards the points s (2 a row), rows a .. b - 1
// (Rectangle.to_world): w / sqrt(w0^2 + w1^2 + w2^2), w = P(s) - ref.
inline void rect_to_world(const double *s, size_t a, size_t b, const RectangleFrame &f, double *out) {
    for (size_t i = a; i < b; ++i) {
        double w[3];
        rect_vector(f, s[2 * i], s[2 * i + 1], w);
        const double len = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
        for (int k = 0; k < 3; ++k) out[3 * i + k] = w[k] / len;
    }
}

// Rectangle.density, the density on the square, rows a .. b - 1: out[i] = the world pdf p[i] in
// float32 times the Jacobian J(s) = area |<w, n>| / (dist2 sqrt(dist2)) (w = P(s) - ref,
// dist2 = <w, w>) in float32, widened (numpy's float32 product), at the points s[i] inside
// [0, 1]^2 (NaN is not), else 0.
inline void rect_density(const double *s, const double *p, size_t a, size_t b, const RectangleFrame &f,
                         double *out) {
    const double *n = f.normal;
    for (size_t i = a; i < b; ++i) {
        const double s0 = s[2 * i], s1 = s[2 * i + 1];
        const bool in = s0 >= 0 && s0 <= 1 && s1 >= 0 && s1 <= 1;
        double w[3];
        rect_vector(f, in ? s0 : 0.5, in ? s1 : 0.5, w);
        const double dist2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
        const double jac = f.area * std::fabs(w[0] * n[0] + w[1] * n[1] + w[2] * n[2]) / (dist2 * std::sqrt(dist2));
        const double v = double(float(p[i]) * float(jac));
        out[i] = in ? v : 0.0;
    }
}

// Whether each of the rows a .. b - 1 of x (rows of k values, row i's value j at
// x[i * row + j * column], strides in values) is finite in every value: ok[i].  numpy's
// all(isfinite(x), axis=1) reduces along the short axis at 15 ns a row.  Strided rows are
// read in place: a renderer's (3, N) components seen as (N, 3) had been copied first, 24 MB
// of fresh pages a million directions.
// Contiguous rows (row == k, column == 1) are tested by their exponent bits, with k fixed
// where it is 1 to 3 (with_row_width), which the compiler vectorises (a strided loop had taken 1.8 ns a direction:
// an area light's pdf calls test every cubature node).
inline void finite_rows(const double *x, size_t row, size_t column, size_t a, size_t b, size_t k, bool *ok) {
    if (column == 1 && row == k) {
        with_row_width(k, [&](auto width) {
            constexpr size_t K = decltype(width)::value;
            const size_t w = K ? K : k;
            for (size_t i = a; i < b; ++i) {
                bool finite = true;
                for (size_t j = 0; j < w; ++j) finite &= finite_bits(x[i * w + j]);
                ok[i] = finite;
            }
        });
        return;
    }
    for (size_t i = a; i < b; ++i) {
        bool finite = true;
        for (size_t j = 0; j < k; ++j) finite &= std::isfinite(x[i * row + j * column]);
        ok[i] = finite;
    }
}

// Points x (n, point_dim; n values on the interval and half line) of parameters s (n, k):
// the inverse maps of domain_params, in numpy's order of operations except the azimuth's
// cosine and sine, which are fastmath's sincos_2pi of s1 (exact argument reduction; numpy's
// cos(2 pi s1) rounds 2 pi s1 first): the same points to rounding.
// One point on the disk (k = 2 coordinates out) or the (hemi)sphere (3 out) from its
// parameters, for double or simd::f64v lanes.
template <class D>
RE_INLINE void disk_point(D s0, D s1, D *x) {
    const D r = simd::sqrt(s0);
    D sn, cs;
    fm::sincos_2pi(s1, sn, cs);
    x[0] = r * cs;
    x[1] = r * sn;
}
template <class D>
RE_INLINE void sphere_point(bool hemi, D s0, D s1, D *x) {
    const D z = hemi ? s0 : 1 - 2 * s0;
    const D w = 1 - z * z;
    const D r = simd::sqrt(w > 0 ? w : D{});
    D sn, cs;
    fm::sincos_2pi(s1, sn, cs);
    x[0] = r * cs;
    x[1] = r * sn;
    x[2] = z;
}

// point(s0, s1, out) for every parameter pair of s (n, 2) into x (n, m): kWidth points at a
// time through the vector lanes (the azimuth's sincos is most of the work), the tail in
// scalars; the same bits either way.
template <int M, class Point>
RE_INLINE void map_pairs(const double *s, size_t n, double *x, Point point) {
    using simd::f64v;
    constexpr size_t W = simd::kWidth;
    size_t i = 0;
    for (; i + W <= n; i += W) {
        f64v s0, s1, out[M];
        for (size_t w = 0; w < W; ++w) {
            s0[w] = s[2 * (i + w)];
            s1[w] = s[2 * (i + w) + 1];
        }
        point(s0, s1, out);
        for (size_t w = 0; w < W; ++w)
            for (int j = 0; j < M; ++j) x[M * (i + w) + j] = out[j][w];
    }
    for (; i < n; ++i) point(s[2 * i], s[2 * i + 1], x + M * i);
}

inline void domain_points(CheckDomain d, double lo, double hi, const double *s, size_t n, double *x) {
    switch (d) {
        case CheckDomain::interval:
            for (size_t i = 0; i < n; ++i) x[i] = lo + (hi - lo) * s[i];
            return;
        case CheckDomain::half_line:
            for (size_t i = 0; i < n; ++i) x[i] = s[i] / (1.0 - s[i]);
            return;
        case CheckDomain::square:
            std::copy(s, s + 2 * n, x);
            return;
        case CheckDomain::disk:
            map_pairs<2>(s, n, x, [](auto s0, auto s1, auto *out) { disk_point(s0, s1, out); });
            return;
        case CheckDomain::hemisphere:
        case CheckDomain::sphere: {
            const bool hemi = d == CheckDomain::hemisphere;
            map_pairs<3>(s, n, x, [hemi](auto s0, auto s1, auto *out) { sphere_point(hemi, s0, s1, out); });
            return;
        }
    }
}

}  // namespace re
