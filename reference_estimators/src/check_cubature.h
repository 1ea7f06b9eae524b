// The tensor rule's batch kernels of the sampler check's cubature
// (harness/samplers/cubature.py): the nodes on many boxes, their points on a domain, and the
// weighted sums that make the boxes' integrals.
#pragma once

#include <algorithm>
#include <cstddef>
#include <type_traits>
#include <vector>

#include "check_domains.h"
#include "check_float32.h"

namespace re {

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

// Where each coordinate of a point goes in its row: dest[c] for coordinate c (x, y, z), the
// identity or a permutation of the sphere's about another pole (cubature_points' `columns`).
struct Placement {
    int dest[3] = {0, 1, 2};
    bool identity(int dim) const { return dest[0] == 0 && dest[1] == 1 && (dim < 3 || dest[2] == 2); }
};

// Box m's nodes' points (per = g^2 rows of 2 or 3 into out) from its g radii, heights,
// sines and cosines, lane l of each, each coordinate at its place in the row (written there
// at once: a second pass permuting the rows had taken twice the map's time; kPlaced false:
// the identity, with constant offsets, which the stores of a permutation read at run time
// had slowed by a third).
template <bool kPlaced, class D>
RE_INLINE void write_box_points(const D *r, const D *z, const D *sn, const D *cs, size_t l, size_t g, bool planar,
                                const Placement &at, double *out) {
    auto lane = [l](const D &v) -> double {
        if constexpr (std::is_same_v<D, double>) return v; else return v[l];
    };
    const int d0 = kPlaced ? at.dest[0] : 0, d1 = kPlaced ? at.dest[1] : 1, d2 = kPlaced ? at.dest[2] : 2;
    for (size_t i = 0; i < g; ++i)
        for (size_t j = 0; j < g; ++j) {
            double *p = out + (i * g + j) * (planar ? 2 : 3);
            p[d0] = lane(r[i]) * lane(cs[j]);
            p[d1] = lane(r[i]) * lane(sn[j]);
            if (!planar) p[d2] = lane(z[i]);
        }
}

// cubature_points for the 2-D rule on the disk, hemisphere and sphere: their maps are
// separable (radius and height from s0, the azimuth's sine and cosine from s1) and a box's
// g x g nodes have g values of each coordinate, so those are mapped once per box, kWidth
// boxes at a time in vector lanes, and multiplied out: the same expressions on the same
// values as domain_points(cubature_nodes), the same bits, for 2g transcendental evaluations
// a box instead of 2 g^2.  g <= 8.
template <bool kPlaced>
void separable_points(CheckDomain d, const double *lo, const double *hi, size_t boxes, const double *nodes, size_t g,
                      const Placement &at, double *x) {
    const bool planar = d == CheckDomain::disk;
    const size_t stride = g * g * (planar ? 2 : 3);
    auto write = [&](const auto *r, const auto *z, const auto *sn, const auto *cs, size_t l, double *out) {
        write_box_points<kPlaced>(r, z, sn, cs, l, g, planar, at, out);
    };
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
        for (size_t l = 0; l < W; ++l) write(r, z, sn, cs, l, x + (m + l) * stride);
    }
    for (; m < boxes; ++m) {
        double r[8], z[8], sn[8], cs[8];
        auto coordinate = [&](size_t j, size_t i) { return lo[2 * m + j] + (hi[2 * m + j] - lo[2 * m + j]) * nodes[i]; };
        box(r, z, sn, cs, [&](size_t i) { return coordinate(0, i); }, [&](size_t i) { return coordinate(1, i); });
        write(r, z, sn, cs, 0, x + m * stride);
    }
}

// The domain points x (boxes g^k rows) of the tensor rule's nodes on boxes [lo, hi]:
// domain_points(cubature_nodes(...)) bit for bit, without the caller's parameter array
// (separable_points on the disk and sphere, else the nodes through `scratch`), each point's
// coordinates placed in its row by `at`.
inline void cubature_points(CheckDomain d, double dlo, double dhi, const double *lo, const double *hi, size_t boxes,
                            size_t k, const double *nodes, size_t g, const Placement &at, double *x,
                            std::vector<double> &scratch) {
    if (k == 2 && g <= 8 && (d == CheckDomain::disk || d == CheckDomain::hemisphere || d == CheckDomain::sphere)) {
        const bool placed = !at.identity(d == CheckDomain::disk ? 2 : 3);   // the identity's stores fixed
        placed ? separable_points<true>(d, lo, hi, boxes, nodes, g, at, x)
               : separable_points<false>(d, lo, hi, boxes, nodes, g, at, x);
        return;
    }
    const size_t count = boxes * (k == 1 ? g : g * g);
    if (d == CheckDomain::square) {  // the identity map: the nodes are the points
        cubature_nodes(lo, hi, boxes, k, nodes, g, x);
    } else {
        scratch.resize(count * k);
        cubature_nodes(lo, hi, boxes, k, nodes, g, scratch.data());
        domain_points(d, dlo, dhi, scratch.data(), count, x);
    }
    const int dim = domain_point_dim(d);
    if (dim == 1 || at.identity(dim)) return;
    for (size_t i = 0; i < count; ++i) {   // rows still in cache
        double *row = x + size_t(dim) * i, was[3];
        std::copy(row, row + dim, was);
        for (int c = 0; c < dim; ++c) row[at.dest[c]] = was[c];
    }
}

// The directions of the tensor rule's nodes on boxes [lo, hi] of the hemisphere or sphere as
// float32 unit vectors, columns into out (column c of node i at out[c * stride + i]) and ok:
// float32_unit_rows(cubature_points(...), slack), the same bits, the points of a chunk of
// boxes in `points` (still in cache when rounded: an (N, 3) array of doubles written out and
// read back had cost a Mitsuba BSDF's check 2.5 ns a table node, where this takes 1.8).
// (Writing float32 from the separable map's lanes directly was slower: a box-major block
// copied out of lanes, 2.1 ns; a box at a time from its coordinates, 2.7.)
inline void cubature_float32_directions(CheckDomain d, const double *lo, const double *hi, size_t boxes, size_t k,
                                        const double *nodes, size_t g, const Placement &at, double slack,
                                        size_t stride, float *out, bool *ok, std::vector<double> &scratch,
                                        std::vector<double> &points) {
    const size_t count = boxes * (k == 1 ? g : g * g);
    points.resize(3 * count);
    cubature_points(d, 0.0, 1.0, lo, hi, boxes, k, nodes, g, at, points.data(), scratch);
    float32_unit_rows(points.data(), 0, count, stride, slack, out, ok);
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
// the loop waiting on the adder, 1.8 ns a node.  Values of type T (double, or float: a float32
// renderer's pdf as it returned them) are widened to double as read, the same bits as summing
// their float64 copy.
inline constexpr size_t kSideBySide = 8;

template <class T>
void cubature_sums(const double *lo, const double *hi, size_t boxes, size_t k, const T *v, size_t cols,
                   const double *weights, size_t per, double scale, double *out) {
    size_t m = 0;
    if (cols == 1) {
        for (; m + kSideBySide <= boxes; m += kSideBySide) {
            const T *vm = v + m * per;
            double sum[kSideBySide] = {};
            for (size_t i = 0; i < per; ++i)
                for (size_t b = 0; b < kSideBySide; ++b) sum[b] += weights[i] * double(vm[b * per + i]);
            for (size_t b = 0; b < kSideBySide; ++b)
                out[m + b] = sum[b] * box_volume(lo + k * (m + b), hi + k * (m + b), k) * scale;
        }
    }
    for (; m < boxes; ++m) {
        const double vol = box_volume(lo + k * m, hi + k * m, k);
        const T *vm = v + m * per * cols;
        for (size_t c = 0; c < cols; c += 4) {
            const size_t width = std::min<size_t>(4, cols - c);
            double sum[4] = {0.0, 0.0, 0.0, 0.0};
            for (size_t i = 0; i < per; ++i)
                for (size_t j = 0; j < width; ++j) sum[j] += weights[i] * double(vm[i * cols + c + j]);
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

}  // namespace re
