// Batch kernels of the sampler check (harness/samplers/check.py): the per-sample work between
// the user's sample() and pdf() calls.  In numpy each step was a pass (or several) over a
// million points with temporaries, 0.25-0.4 s a check in all; here each is one pass without
// temporaries, and the Cramer-von Mises statistic needs no sort (cramer_von_mises_sum
// brackets it from cell counts).  Every kernel computes what the numpy code did, in the same
// order of operations, so results agree to the last bit except where stated: sums
// (compensated here, pairwise in numpy) and the azimuth (fastmath's atan2_turns, within 2 ulp
// of numpy's mod(arctan2(y, x) / (2 pi), 1); libm's atan2 and fmod took 80 % of the sphere's
// map).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "accumulator.h"  // CompensatedSum
#include "fastmath.h"
#include "tables.h"       // RosenblattTransform

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

// s[2 i + 1] = the azimuth in turns of (x[stride i], x[stride i + 1]), for n points: whole
// vectors of fastmath's atan2_turns, then the scalar tail (the same bits).
inline void azimuths(const double *x, size_t stride, size_t n, double *s) {
    constexpr size_t W = simd::kWidth;
    size_t i = 0;
    for (; i + W <= n; i += W) {
        simd::f64v a, b;
        for (size_t w = 0; w < W; ++w) {
            a[w] = x[stride * (i + w)];
            b[w] = x[stride * (i + w) + 1];
        }
        const simd::f64v turns = fm::atan2_turns(b, a);
        for (size_t w = 0; w < W; ++w) s[2 * (i + w) + 1] = turns[w];
    }
    for (; i < n; ++i) s[2 * i + 1] = fm::atan2_turns(x[stride * i + 1], x[stride * i]);
}

// Parameters s (n, k) of points x (n, point_dim) and whether each lies inside the domain:
// the equal-measure maps of harness/samplers/domains.py (see there).  Unit vectors count as
// inside when their squared norm is within 1e-5 of 1 (float32 renderers); a non-finite
// point is outside (its s may be NaN).
inline void domain_params(CheckDomain d, double lo, double hi, const double *x, size_t n, double *s,
                          bool *inside) {
    switch (d) {
        case CheckDomain::interval:
            for (size_t i = 0; i < n; ++i) {
                const double v = x[i];
                s[i] = (v - lo) / (hi - lo);
                inside[i] = std::isfinite(v) && v >= lo && v <= hi;
            }
            return;
        case CheckDomain::half_line:
            for (size_t i = 0; i < n; ++i) {
                const double v = x[i];
                s[i] = v / (1.0 + v);
                inside[i] = std::isfinite(v) && v >= 0;
            }
            return;
        case CheckDomain::square:
            for (size_t i = 0; i < n; ++i) {
                const double a = x[2 * i], b = x[2 * i + 1];
                s[2 * i] = a;
                s[2 * i + 1] = b;
                inside[i] = std::isfinite(a) && std::isfinite(b) && a >= 0 && a <= 1 && b >= 0 && b <= 1;
            }
            return;
        case CheckDomain::disk:
            for (size_t i = 0; i < n; ++i) {
                const double a = x[2 * i], b = x[2 * i + 1];
                const double r2 = a * a + b * b;
                s[2 * i] = r2;
                inside[i] = std::isfinite(a) && std::isfinite(b) && r2 <= 1 + 1e-12;
            }
            azimuths(x, 2, n, s);
            return;
        case CheckDomain::hemisphere:
        case CheckDomain::sphere: {
            const bool hemi = d == CheckDomain::hemisphere;
            for (size_t i = 0; i < n; ++i) {
                const double a = x[3 * i], b = x[3 * i + 1], c = x[3 * i + 2];
                const double norm = a * a + b * b + c * c;
                const bool ok = std::isfinite(a) && std::isfinite(b) && std::isfinite(c) && std::fabs(norm - 1) <= 1e-5;
                const double z = c < -1 ? -1.0 : (c > 1 ? 1.0 : c);  // NaN passes
                s[2 * i] = hemi ? z : (1 - z) / 2;
                inside[i] = hemi ? ok && c >= -1e-12 : ok;
            }
            azimuths(x, 3, n, s);
            return;
        }
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
    constexpr size_t W = simd::kWidth;
    size_t i = a;
    for (; i + W <= b; i += W) {
        simd::f64v p0, p1, p2, o0, o1, o2;
        simd::load3(h + 3 * i, p0, p1, p2);
        cap_point(p0, p1, p2, axis, t, bv, cos_alpha, scale, o0, o1, o2);
        simd::store3(out + 3 * i, o0, o1, o2);
    }
    for (; i < b; ++i)
        cap_point(h[3 * i], h[3 * i + 1], h[3 * i + 2], axis, t, bv, cos_alpha, scale, out[3 * i], out[3 * i + 1],
                  out[3 * i + 2]);
}

// Whether each of the rows a .. b - 1 of x (rows of k values) is finite in every value: ok[i].
// numpy's all(isfinite(x), axis=1) reduces along the short axis at 15 ns a row.
inline void finite_rows(const double *x, size_t a, size_t b, size_t k, bool *ok) {
    for (size_t i = a; i < b; ++i) {
        bool finite = true;
        for (size_t j = 0; j < k; ++j) finite &= std::isfinite(x[i * k + j]);
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

// Whether every finite non-zero value of v (n) is a float32 (rounds to itself through float),
// and there is one: a float32 renderer's numbers, whether returned as float32 or float64.
// Stops at the first value that is not.
inline bool all_float32(const double *v, size_t n) {
    bool any = false;
    for (size_t i = 0; i < n; ++i) {
        const double x = v[i];
        if (!std::isfinite(x) || x == 0) continue;
        if (!(std::fabs(x) <= double(std::numeric_limits<float>::max())) || double(float(x)) != x) return false;
        any = true;
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

// The nodes of a tensor rule with the g points `nodes` (in [0, 1]) per axis on each box
// [lo, hi] (boxes m = 0 .. boxes - 1, k = 1 or 2 coordinates each): node (i, j) of box m at
// row m g^k + i g + j, coordinate lo + (hi - lo) * node (numpy's meshgrid "ij" order).
inline void cubature_nodes(const double *lo, const double *hi, size_t boxes, size_t k, const double *nodes, size_t g,
                           double *out) {
    for (size_t m = 0; m < boxes; ++m) {
        const double a0 = lo[k * m], w0 = hi[k * m] - lo[k * m];
        if (k == 1) {
            for (size_t i = 0; i < g; ++i) out[m * g + i] = a0 + w0 * nodes[i];
            continue;
        }
        const double a1 = lo[k * m + 1], w1 = hi[k * m + 1] - lo[k * m + 1];
        double *row = out + 2 * m * g * g;
        for (size_t i = 0; i < g; ++i)
            for (size_t j = 0; j < g; ++j) {
                row[2 * (i * g + j)] = a0 + w0 * nodes[i];
                row[2 * (i * g + j) + 1] = a1 + w1 * nodes[j];
            }
    }
}

// The radius r (and height z) of the disk's, hemisphere's or sphere's point at s0 and the
// sine and cosine of its azimuth at s1: disk_point's and sphere_point's expressions, split
// by the parameter they depend on.
template <class D>
RE_INLINE void radial_part(CheckDomain d, D s0, D &r, D &z) {
    if (d == CheckDomain::disk) {
        r = simd::sqrt(s0);
        return;
    }
    z = d == CheckDomain::hemisphere ? s0 : 1 - 2 * s0;
    const D w = 1 - z * z;
    r = simd::sqrt(w > 0 ? w : D{});
}

// Box m's nodes' points (per = g^2 rows of 2 or 3 into out) from its g radii, heights,
// sines and cosines, lane l of each.
template <class D>
RE_INLINE void write_box_points(const D *r, const D *z, const D *sn, const D *cs, size_t l, size_t g, bool planar,
                                double *out) {
    auto lane = [l](const D &v) -> double {
        if constexpr (std::is_same_v<D, double>) return v; else return v[l];
    };
    for (size_t i = 0; i < g; ++i)
        for (size_t j = 0; j < g; ++j) {
            double *p = out + (i * g + j) * (planar ? 2 : 3);
            p[0] = lane(r[i]) * lane(cs[j]);
            p[1] = lane(r[i]) * lane(sn[j]);
            if (!planar) p[2] = lane(z[i]);
        }
}

// cubature_points for the 2-D rule on the disk, hemisphere and sphere: their maps are
// separable (radius and height from s0, the azimuth's sine and cosine from s1) and a box's
// g x g nodes have g values of each coordinate, so those are mapped once per box, kWidth
// boxes at a time in vector lanes, and multiplied out: the same expressions on the same
// values as domain_points(cubature_nodes), the same bits, for 2g transcendental evaluations
// a box instead of 2 g^2.  g <= 8.
inline void separable_points(CheckDomain d, const double *lo, const double *hi, size_t boxes, const double *nodes,
                             size_t g, double *x) {
    const bool planar = d == CheckDomain::disk;
    const size_t stride = g * g * (planar ? 2 : 3);
    auto box = [&](auto *r, auto *z, auto *sn, auto *cs, auto s0_at, auto s1_at) {
        for (size_t i = 0; i < g; ++i) {
            radial_part(d, s0_at(i), r[i], z[i]);
            fm::sincos_2pi(s1_at(i), sn[i], cs[i]);
        }
    };
    constexpr size_t W = simd::kWidth;
    size_t m = 0;
    for (; m + W <= boxes; m += W) {
        simd::f64v r[8], z[8], sn[8], cs[8];
        auto coordinate = [&](size_t j, size_t i) {
            simd::f64v v;
            for (size_t l = 0; l < W; ++l) {
                const size_t b = 2 * (m + l) + j;
                v[l] = lo[b] + (hi[b] - lo[b]) * nodes[i];   // cubature_nodes' expression
            }
            return v;
        };
        box(r, z, sn, cs, [&](size_t i) { return coordinate(0, i); }, [&](size_t i) { return coordinate(1, i); });
        for (size_t l = 0; l < W; ++l) write_box_points(r, z, sn, cs, l, g, planar, x + (m + l) * stride);
    }
    for (; m < boxes; ++m) {
        double r[8], z[8], sn[8], cs[8];
        auto coordinate = [&](size_t j, size_t i) { return lo[2 * m + j] + (hi[2 * m + j] - lo[2 * m + j]) * nodes[i]; };
        box(r, z, sn, cs, [&](size_t i) { return coordinate(0, i); }, [&](size_t i) { return coordinate(1, i); });
        write_box_points(r, z, sn, cs, 0, g, planar, x + m * stride);
    }
}

// The domain points x (boxes g^k rows) of the tensor rule's nodes on boxes [lo, hi]:
// domain_points(cubature_nodes(...)) bit for bit, without the caller's parameter array
// (separable_points on the disk and sphere, else the nodes through `scratch`).
inline void cubature_points(CheckDomain d, double dlo, double dhi, const double *lo, const double *hi, size_t boxes,
                            size_t k, const double *nodes, size_t g, double *x, std::vector<double> &scratch) {
    if (k == 2 && g <= 8 && (d == CheckDomain::disk || d == CheckDomain::hemisphere || d == CheckDomain::sphere)) {
        separable_points(d, lo, hi, boxes, nodes, g, x);
        return;
    }
    if (d == CheckDomain::square) {  // the identity map: the nodes are the points
        cubature_nodes(lo, hi, boxes, k, nodes, g, x);
        return;
    }
    const size_t count = boxes * (k == 1 ? g : g * g);
    scratch.resize(count * k);
    cubature_nodes(lo, hi, boxes, k, nodes, g, scratch.data());
    domain_points(d, dlo, dhi, scratch.data(), count, x);
}

// The volume prod (hi - lo) of a box with corners lo, hi (k coordinates each), in axis order.
inline double box_volume(const double *lo, const double *hi, size_t k) {
    double vol = 1.0;
    for (size_t j = 0; j < k; ++j) vol *= hi[j] - lo[j];
    return vol;
}

// The tensor rule's integrals out (boxes, cols): for box m and column c, the sum over its
// `per` nodes, in order, of weights[node] v[m per + node, c] (v (boxes per, cols), the values
// at cubature_nodes' nodes) times the box's volume prod (hi - lo), times `scale` (a constant
// factor of the integrand, say a Jacobian; 1 changes no bit).  Summed in place: numpy's einsum
// and product took a fifth of a sampler check's cubature.  Up to four columns are summed in
// one pass over a box's rows, each column's terms in node order as alone (a pass per column
// read the rows with a stride: 3.5x the time a node at three columns).  One column (the
// check's every call but the moment pass) is summed kSideBySide boxes at a time, each box's
// sum its own chain in node order (the same bits): a box's 16 dependent additions alone had
// the loop waiting on the adder, 1.8 ns a node.
inline constexpr size_t kSideBySide = 8;

inline void cubature_sums(const double *lo, const double *hi, size_t boxes, size_t k, const double *v, size_t cols,
                          const double *weights, size_t per, double scale, double *out) {
    size_t m = 0;
    if (cols == 1) {
        for (; m + kSideBySide <= boxes; m += kSideBySide) {
            const double *vm = v + m * per;
            double sum[kSideBySide] = {};
            for (size_t i = 0; i < per; ++i)
                for (size_t b = 0; b < kSideBySide; ++b) sum[b] += weights[i] * vm[b * per + i];
            for (size_t b = 0; b < kSideBySide; ++b)
                out[m + b] = sum[b] * box_volume(lo + k * (m + b), hi + k * (m + b), k) * scale;
        }
    }
    for (; m < boxes; ++m) {
        const double vol = box_volume(lo + k * m, hi + k * m, k);
        const double *vm = v + m * per * cols;
        for (size_t c = 0; c < cols; c += 4) {
            const size_t width = std::min<size_t>(4, cols - c);
            double sum[4] = {0.0, 0.0, 0.0, 0.0};
            for (size_t i = 0; i < per; ++i)
                for (size_t j = 0; j < width; ++j) sum[j] += weights[i] * vm[i * cols + c + j];
            for (size_t j = 0; j < width; ++j) out[m * cols + c + j] = sum[j] * vol * scale;
        }
    }
}

// The sampler check's moment integrals (harness/samplers/domains.py, MomentColumns): the
// tensor rule's integrals out (boxes, 3) of q, h q and h^2 q, h = q / (q + c) (h = 0 when
// c <= 0), from q's values v (boxes per) at the nodes: cubature_sums of those three columns
// made in numpy's order of operations (h * q, then (h * h) * q), the same bits, without the
// columns' array (making it cost more than the pdf calls on a cheap pdf).  kSideBySide boxes
// at a time, as cubature_sums' single column.
inline void cubature_moment_sums(const double *lo, const double *hi, size_t boxes, size_t k, const double *v,
                                 const double *weights, size_t per, double c, double *out) {
    auto sums = [&](size_t m, auto count) {   // boxes m .. m + count - 1
        constexpr size_t B = decltype(count)::value;
        const double *vm = v + m * per;
        double s0[B] = {}, s1[B] = {}, s2[B] = {};
        for (size_t i = 0; i < per; ++i) {
            const double w = weights[i];
            for (size_t b = 0; b < B; ++b) {
                const double q = vm[b * per + i], h = c > 0 ? q / (q + c) : 0.0;
                s0[b] += w * q;
                s1[b] += w * (h * q);
                s2[b] += w * (h * h * q);
            }
        }
        for (size_t b = 0; b < B; ++b) {
            const double vol = box_volume(lo + k * (m + b), hi + k * (m + b), k);
            out[3 * (m + b)] = s0[b] * vol, out[3 * (m + b) + 1] = s1[b] * vol, out[3 * (m + b) + 2] = s2[b] * vol;
        }
    };
    size_t m = 0;
    for (; m + kSideBySide <= boxes; m += kSideBySide) sums(m, std::integral_constant<size_t, kSideBySide>{});
    for (; m < boxes; ++m) sums(m, std::integral_constant<size_t, 1>{});
}

// grid_histogram's counting of points a .. b - 1 into c (its own function: with its arguments
// in registers the loop ran 2.5-3.5x faster than with them read through a lambda's captures).
inline void count_cells(const double *s, size_t a, size_t b, const bool *inside, int64_t m0, int64_t m1,
                        int64_t *c) {
    constexpr double top = 1.0 - 0x1p-53;  // np.nextafter(1, 0)
    auto cell = [](double v, int64_t m) {
        v = v < 0 ? 0.0 : (v > top ? top : v);
        const int64_t j = int64_t(v * double(m));
        return j < m - 1 ? j : m - 1;
    };
    if (m1 == 0) {
        for (size_t i = a; i < b; ++i) {
            const double x = s[i];
            if (inside[i] && x == x) ++c[cell(x, m0)];
        }
        return;
    }
    for (size_t i = a; i < b; ++i) {
        const double x = s[2 * i], y = s[2 * i + 1];
        if (inside[i] && x == x && y == y) ++c[cell(x, m0) * m1 + cell(y, m1)];
    }
}

// Integer counts in `cells` cells of n items, on all hardware threads: count(a, b, table) adds
// the items a .. b - 1 of a fixed chunk to `table`, each thread's own; the tables' sums go to
// counts (float64).  Integer sums: the same whichever thread counted what.
template <class Count>
void count_on_threads(size_t n, size_t cells, double *counts, Count count) {
    std::vector<std::vector<int64_t>> tables(size_t(ThreadPool::default_threads()));
    for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int worker) {
        std::vector<int64_t> &table = tables[size_t(worker)];
        if (table.empty()) table.assign(cells, 0);
        count(a, b, table.data());
    });
    for (size_t j = 0; j < cells; ++j) {
        int64_t total = 0;
        for (const auto &table : tables) total += table.empty() ? 0 : table[j];
        counts[j] = double(total);
    }
}

// Counts of the points marked inside on the regular grid of m0 (x m1) cells over [0, 1]^k
// (k = 1 when m1 == 0), C order: each coordinate clamped to [0, 1 - 2^-53] first, then cell
// floor(s m) (at most m - 1).  Points outside, or with a NaN coordinate, are not counted.
inline void grid_histogram(const double *s, size_t n, const bool *inside, int64_t m0, int64_t m1, double *counts) {
    count_on_threads(n, size_t(m0) * size_t(m1 > 0 ? m1 : 1), counts,
                     [&](size_t a, size_t b, int64_t *table) { count_cells(s, a, b, inside, m0, m1, table); });
}

// Scratch buffer `which` (0 or 1) of this thread, at least n doubles, contents undefined:
// kept between calls, because a fresh 8 MB buffer a call costs thousands of page faults
// (more than the transform itself on a loaded machine).
inline double *scratch(int which, size_t n) {
    thread_local std::vector<double> buffers[2];  // transform_statistics: u0, u1
    std::vector<double> &b = buffers[which];
    if (b.size() < n) b.resize(n);
    return b.data();
}

// The Cramer-von Mises sum S = sum_i (u_(i) - c_i)^2, c_i = (2 i - 1) / (2 n), over the sorted
// values u_(1..n) of u (n values at stride `stride`, each clamped to [0, 1]: the uniform law's
// CDF there, as in scipy's cramervonmises): S + 1 / (12 n) is the statistic n W^2.  Bracketed
// without sorting: `upper` >= S >= upper - `slack`.
struct CramerVonMisesSum {
    double upper, slack;
};

// How (why not a sort): the values are counted in K cells of width h = 1 / K (K a power of
// two, about 64 sqrt(n): the counts stay in L2).  The m_b values of cell b take the ranks
// r_b + 1 .. r_b + m_b whatever their order inside it, so with cbar_b the mean of their c,
//     S = sum_i (u_i - cbar_b(i))^2 + sum_b (m_b^3 - m_b) / (12 n^2) - 2 sum_b C_b,
// C_b = sum_j (u_(b,j) - mean)(c_(b,j) - cbar_b) >= 0 the within-cell covariance of the
// sorted pairing (rearrangement inequality), at most h m_b (m_b - 1) / (4 n).  `upper` drops
// C, `slack` is the sum of the C bounds doubled: about n / (2 K^2) <= 1.2e-4 for uniform
// values, against a statistic whose 1 % point is 0.74.  Two passes over u (count, then sum),
// where a radix sort took five and twice the time.  The second pass sums in blocks of 1024
// terms, the block sums compensated; it reads the values in order, so the result is the same
// on any thread.  NaN (both) if any u is NaN.  32-bit counts (the table at K = 2^16 fits in
// L2: 1.4x faster than 64-bit ones): at most 2^32 - 1 values.
inline CramerVonMisesSum cramer_von_mises_sum(const double *u, size_t stride, size_t n) {
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    if (n == 0) return {0.0, 0.0};
    if (n > UINT32_MAX) throw std::length_error("the Cramer-von Mises sum takes at most 2^32 - 1 values");
    int bits = 10;
    while (bits < 22 && double(int64_t(1) << bits) < 64.0 * std::sqrt(double(n))) ++bits;
    const int64_t K = int64_t(1) << bits;
    const double scale = double(K);
    auto clamped = [](double v) { return v < 0 ? 0.0 : (v > 1 ? 1.0 : v); };
    auto cell = [K, scale](double v) {  // of a clamped v
        const double f = v * scale;  // exact: K is a power of two, so cell edges are b / K exactly
        return f < scale ? int64_t(f) : K - 1;
    };
    thread_local std::vector<uint32_t> first;  // per cell its count, then the rank before it
    first.assign(size_t(K) + 1, 0);
    for (size_t i = 0; i < n; ++i) {
        const double v = u[i * stride];
        if (v != v) return {kNaN, kNaN};
        ++first[size_t(cell(clamped(v)))];
    }
    CompensatedSum cubes, pairs;
    uint32_t rank = 0;
    for (int64_t b = 0; b < K; ++b) {
        const uint32_t m = first[size_t(b)];
        first[size_t(b)] = rank;
        rank += m;
        if (m < 2) continue;
        const double md = double(m);
        cubes.add(md * (md * md - 1.0));
        pairs.add(md * (md - 1.0));
    }
    first[size_t(K)] = rank;
    const double twice_n = 2.0 * double(n);
    CompensatedSum acc;
    for (size_t a = 0; a < n; a += 1024) {
        const size_t e = std::min(n, a + 1024);
        double block = 0;
        for (size_t i = a; i < e; ++i) {
            const double v = clamped(u[i * stride]);
            const size_t b = size_t(cell(v));
            const uint32_t r = first[b], m = first[b + 1] - r;
            const double d = v - (2.0 * double(r) + double(m)) / twice_n;   // cbar_b = (2 r + m) / (2 n)
            block += d * d;
        }
        acc.add(block);
    }
    const double nn = double(n) * double(n);
    return {acc.value() + cubes.value() / (12.0 * nn), pairs.value() / (scale * twice_n)};
}

// The statistics of the sampler check's transform tests (harness/samplers/transform.py) in one
// call: the Rosenblatt transform u of the parameter points s (n, k) (RosenblattTransform), the
// Cramer-von Mises sum of each column of u (cramer_von_mises_sum, to sums[0 .. k)) and
// the counts of the cells of equal claimed probability (point j in cell strip * bins +
// min(floor(v bins), bins - 1), v its u1 on the square and its u0 (strip 0) on an interval;
// a NaN v counts nowhere).  u stays in this thread's scratch buffers instead of going to
// Python with its strips: 24 MB of fresh arrays a check cost 8 ms of page faults, more than a
// third of the transform.  Fixed chunks on all hardware threads (count_on_threads), the
// columns' sums in parallel: the same for any thread count.
inline void transform_statistics(const PiecewiseLinearTable &marginal, const PiecewiseLinearTable *conditional,
                                 const double *edges, size_t nedges, const double *s, size_t k, size_t n,
                                 int64_t bins, CramerVonMisesSum *sums, double *counts) {
    const RosenblattTransform transform(marginal, conditional, edges, nedges);
    const int64_t strips = k == 2 ? int64_t(nedges) - 1 : 1;
    double *u[2] = {scratch(0, n), k == 2 ? scratch(1, n) : nullptr};
    count_on_threads(n, size_t(strips * bins), counts, [&](size_t a, size_t b, int64_t *cells) {
        thread_local std::vector<int64_t> strip;
        strip.resize(kCheckChunk);
        transform(s, k, a, b, u[0], u[1], 1, strip.data());
        const double *binned = u[k - 1];
        for (size_t j = a; j < b; ++j) {
            const double v = binned[j];
            if (v != v) continue;
            int64_t i = int64_t(v * double(bins));
            i = i < 0 ? 0 : (i < bins - 1 ? i : bins - 1);
            ++cells[size_t(strip[j - a] * bins + i)];
        }
    });
    ThreadPool::instance().run(k, ThreadPool::default_threads(),
                               [&](size_t c, int) { sums[c] = cramer_von_mises_sum(u[c], 1, n); });
}

// The deterministic pdf checks and the pdf moment of the sampler check, in one pass over the
// pdf values p (n) at the points with parameters s (n, k) and inside flags: `bad` counts p
// NaN, infinite or negative (all points), `zero` counts p == 0 at inside points; for the
// inside points with a good p, ps = p * J(s) (J the domain's measure per unit of parameter
// space: `measure`, or 1 / (1 - s)^2 on the half line) and h = ps / (ps + c) (c > 0) are
// summed.
struct PdfSummary {
    int64_t bad = 0, zero = 0, used = 0;
    double h_sum = 0;
};

// pdf_summary of points a .. b - 1 (its own function, arguments in registers; `s` null: the
// constant measure, else the half line's 1 / (1 - s)^2).  Without a branch on the data
// (nothing to mispredict where outside points and bad values mix in); h summed in blocks of
// 256, the block sums compensated (h is in [0, 1]: a block's plain sum is exact to 256 ulp).
// With the chunks on two threads, 2.2 -> 1.1 ms a million points.
inline PdfSummary pdf_summary_of(const double *s, size_t k, const bool *inside, const double *p, size_t a, size_t b,
                                 double measure, double c) {
    PdfSummary r;
    CompensatedSum h;
    for (size_t e = a; e < b;) {
        const size_t end = std::min(b, e + 256);
        int64_t bad = 0, zero = 0, used = 0;
        double block = 0;
        for (size_t i = e; i < end; ++i) {
            const double v = p[i];
            const bool is_bad = !(v >= 0 && v <= std::numeric_limits<double>::max());   // NaN, inf or < 0
            const bool in = inside[i];
            bad += is_bad;
            zero += in & (v == 0);
            const bool good = in & !is_bad;
            used += good;
            double jac = measure;
            if (s) {
                const double t = 1.0 - s[k * i];
                jac = 1.0 / (t * t);
            }
            const double ps = good ? v * jac : 0.0;
            block += c > 0 ? ps / (ps + c) : 0.0;
        }
        r.bad += bad, r.zero += zero, r.used += used;
        h.add(block);
        e = end;
    }
    r.h_sum = h.value();
    return r;
}

inline PdfSummary pdf_summary(CheckDomain d, double measure, const double *s, const bool *inside, const double *p,
                              size_t n, double c) {
    const size_t k = size_t(domain_param_dim(d));
    const bool half_line = d == CheckDomain::half_line;
    const size_t chunks = (n + kCheckChunk - 1) / kCheckChunk;
    std::vector<PdfSummary> part(chunks);
    // fixed chunks on all hardware threads, each with its own compensated sum, merged in chunk
    // order below: the same for any thread count
    for_chunks(n, kCheckChunk, [&](size_t j, size_t a, size_t b, int) {
        part[j] = pdf_summary_of(half_line ? s : nullptr, k, inside, p, a, b, measure, c);
    });
    PdfSummary r;
    CompensatedSum h;
    for (const PdfSummary &q : part) {
        r.bad += q.bad;
        r.zero += q.zero;
        r.used += q.used;
        h.add(q.h_sum);
    }
    r.h_sum = h.value();
    return r;
}

}  // namespace re
