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

// Boxes a block of the interleaved node order of cubature_float32_directions and
// cubature_sums_interleaved: a block of w <= kInterleave boxes (w < kInterleave only for the
// last) holds node k of its box b at k w + b, so that one node of every box of the block is a
// vector's lanes, stored and summed contiguously.  Fixed (not the ISA's vector width), so the
// order is the same on every machine.
inline constexpr size_t kInterleave = 8;

// Box-major node rows (boxes x per rows of 3 doubles, in cubature_points' order) as float32
// unit vectors in the interleaved order (float32_unit_row on each): a rule with more than 8
// nodes an axis, which the separable map does not take.
inline void interleave_rows(const double *rows, size_t boxes, size_t per, double slack, size_t stride, float *out,
                            bool *ok) {
    const UnitSlack unit(slack);
    for (size_t m0 = 0; m0 < boxes; m0 += kInterleave) {
        const size_t w = std::min(kInterleave, boxes - m0);
        for (size_t b = 0; b < w; ++b)
            for (size_t k = 0; k < per; ++k) {
                const size_t at = m0 * per + k * w + b;
                float32_unit_row(rows + 3 * (m0 + b) * per, k, stride, unit, out + at - k, ok + at - k);
            }
    }
}

// One block of w boxes from box m0 (cubature_float32_directions): each box's g radii and
// heights at its s0 nodes and g sines and cosines at its s1 nodes, computed kWidth boxes a
// vector (a short block repeats its last box in the spare lanes), then node (i, j) of every
// box: its point (x, y, z) made into the row map(xyz, row) gives (placed by a permutation, or
// carried through the cap's map), its squared length checked against float32_unit_rows' inner
// interval, rounded to float32 and stored, V boxes' at a time in vector lanes.
template <size_t W, class Map>
void interleaved_block(CheckDomain d, const double *lo, const double *hi, size_t m0, size_t w, const double *nodes,
                       size_t g, const Map &map, const UnitSlack &unit, size_t stride, float *out, bool *ok) {
    constexpr size_t V = simd::kWidth;
    static_assert(kInterleave % V == 0, "a block is whole vectors");
    const size_t n = W ? W : w;
    alignas(64) double R[8][kInterleave], Z[8][kInterleave], S[8][kInterleave], C[8][kInterleave];
    for (size_t v = 0; v < n; v += V)
        for (size_t i = 0; i < g; ++i) {
            simd::f64v s0, s1, r, z = {}, sn, cs;
            for (size_t l = 0; l < V; ++l) {
                const size_t b = 2 * (m0 + std::min(v + l, n - 1));
                s0[l] = lo[b] + (hi[b] - lo[b]) * nodes[i];   // cubature_nodes' expression
                s1[l] = lo[b + 1] + (hi[b + 1] - lo[b + 1]) * nodes[i];
            }
            radial_part(d, s0, r, z);
            fm::sincos_2pi(s1, sn, cs);
            std::memcpy(&R[i][v], &r, sizeof r);
            std::memcpy(&Z[i][v], &z, sizeof z);
            std::memcpy(&S[i][v], &sn, sizeof sn);
            std::memcpy(&C[i][v], &cs, sizeof cs);
        }
    float *base = out + m0 * g * g;
    bool *okb = ok + m0 * g * g;
    using simd::f32v;
    using simd::f64v;
    for (size_t i = 0; i < g; ++i)
        for (size_t j = 0; j < g; ++j) {
            const size_t k = i * g + j;
            float *o[3] = {base + k * n, base + stride + k * n, base + 2 * stride + k * n};
            for (size_t v = 0; v < n; v += V) {   // V boxes' node (i, j) in lanes
                f64v r, cs, sn, xyz[3], row[3];
                std::memcpy(&r, &R[i][v], sizeof r);
                std::memcpy(&cs, &C[j][v], sizeof cs);
                std::memcpy(&sn, &S[j][v], sizeof sn);
                std::memcpy(&xyz[2], &Z[i][v], sizeof xyz[2]);
                xyz[0] = r * cs;   // write_box_points' products
                xyz[1] = r * sn;
                map(xyz, row);
                const f64v &r0 = row[0], &r1 = row[1], &r2 = row[2];
                const f64v n2 = r0 * r0 + r1 * r1 + r2 * r2;   // the row's, in its order
                const size_t lanes = std::min(V, n - v);
                if (!unit.all_inside(n2)) {
                    for (size_t l = 0; l < lanes; ++l) {   // a node off unit length (none is)
                        const double x[3] = {r0[l], r1[l], r2[l]};
                        float32_unit_row(x, 0, stride, unit, o[0] + v + l, okb + k * n + v + l);
                    }
                    continue;
                }
                const f32v f[3] = {__builtin_convertvector(r0, f32v), __builtin_convertvector(r1, f32v),
                                   __builtin_convertvector(r2, f32v)};
                for (size_t c = 0; c < 3; ++c) std::memcpy(o[c] + v, &f[c], lanes * sizeof(float));
                for (size_t l = 0; l < lanes; ++l) okb[k * n + v + l] = true;
            }
        }
}

// The nodes of boxes [lo, hi] (from a multiple of kInterleave) through `map`, rounded to float32
// columns in the interleaved order, block by block (interleaved_block).
template <class Map>
void interleaved_directions(CheckDomain d, const double *lo, const double *hi, size_t boxes, const double *nodes,
                            size_t g, const Map &map, double slack, size_t stride, float *out, bool *ok) {
    const UnitSlack unit(slack);
    for (size_t m0 = 0; m0 < boxes; m0 += kInterleave) {
        const size_t w = std::min(kInterleave, boxes - m0);
        w == kInterleave ? interleaved_block<kInterleave>(d, lo, hi, m0, w, nodes, g, map, unit, stride, out, ok)
                         : interleaved_block<0>(d, lo, hi, m0, w, nodes, g, map, unit, stride, out, ok);
    }
}

// The directions of the tensor rule's nodes on boxes [lo, hi] (boxes from a multiple of
// kInterleave) of the hemisphere or sphere as float32 unit vectors, columns into out (column
// c of node i at out[c * stride + i]) and ok, in the interleaved order (kInterleave): the
// values of float32_unit_rows(cubature_points(...), slack), the same bits, each node where
// the order puts it.  On the separable map (g <= 8) a block's nodes are mapped, rounded and
// stored in vector lanes, one node of every box at a time: 0.8 ns a node on two threads in
// calls of 2^18 nodes (1.5 in calls of 2^16), what cubature_points alone takes, where its rows
// written out, read back and rounded had taken 1.2 (2.5) and each chunk's rows rounded while in
// cache 1.1 (1.8); writing floats from separable_points' lanes, box-major, 2.1-2.7 (2^16).
inline void cubature_float32_directions(CheckDomain d, const double *lo, const double *hi, size_t boxes, size_t k,
                                        const double *nodes, size_t g, const Placement &at, double slack,
                                        size_t stride, float *out, bool *ok, std::vector<double> &scratch,
                                        std::vector<double> &points) {
    if (k == 2 && g <= 8) {
        int from[3];   // coordinate c of a node's row is its coordinate from[c] (at.dest inverted)
        for (int c = 0; c < 3; ++c) from[at.dest[c]] = c;
        auto placed = [&](const simd::f64v *xyz, simd::f64v *row) {
            for (int c = 0; c < 3; ++c) row[c] = xyz[from[c]];
        };
        interleaved_directions(d, lo, hi, boxes, nodes, g, placed, slack, stride, out, ok);
        return;
    }
    const size_t per = k == 1 ? g : g * g;
    points.resize(3 * boxes * per);
    cubature_points(d, 0.0, 1.0, lo, hi, boxes, k, nodes, g, at, points.data(), scratch);
    interleave_rows(points.data(), boxes, per, slack, stride, out, ok);
}

// The world directions (cap_to_world) of the tensor rule's nodes on boxes [lo, hi] of the
// hemisphere, as float32 unit vectors in the interleaved order: the values of
// float32_unit_rows(cap_to_world(cubature_points("hemisphere", ...)), slack), the same bits
// (an area light's pdf at the cubature's nodes of its cap's map).  g <= 8 in lanes (cap_point
// on the vectors), else through the rows.
inline void cubature_cap_float32_directions(const double *lo, const double *hi, size_t boxes, const double *nodes,
                                            size_t g, const double *axis, const double *t, const double *b,
                                            double cos_alpha, double scale, double slack, size_t stride, float *out,
                                            bool *ok, std::vector<double> &scratch, std::vector<double> &points) {
    if (g <= 8) {
        auto capped = [&](const simd::f64v *xyz, simd::f64v *row) {
            cap_point(xyz[0], xyz[1], xyz[2], axis, t, b, cos_alpha, scale, row[0], row[1], row[2]);
        };
        interleaved_directions(CheckDomain::hemisphere, lo, hi, boxes, nodes, g, capped, slack, stride, out, ok);
        return;
    }
    const size_t per = g * g;
    points.resize(6 * boxes * per);
    cubature_points(CheckDomain::hemisphere, 0.0, 1.0, lo, hi, boxes, 2, nodes, g, Placement{}, points.data(),
                    scratch);
    double *world = points.data() + 3 * boxes * per;
    cap_to_world(points.data(), 0, boxes * per, axis, t, b, cos_alpha, scale, world);
    interleave_rows(world, boxes, per, slack, stride, out, ok);
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

// cubature_sums of one column of values in the interleaved order (kInterleave; boxes from a
// multiple of it): box b's sum over its nodes in node order, the same bits as cubature_sums on
// the box-major values, a block's boxes summed side by side in vector lanes.
template <class T>
void cubature_sums_interleaved(const double *lo, const double *hi, size_t boxes, size_t k, const T *v,
                               const double *weights, size_t per, double scale, double *out) {
    for (size_t m0 = 0; m0 < boxes; m0 += kInterleave) {
        const size_t w = std::min(kInterleave, boxes - m0);
        const T *vb = v + m0 * per;
        double sum[kInterleave] = {};
        if (w == kInterleave) {
            for (size_t i = 0; i < per; ++i)
                for (size_t b = 0; b < kInterleave; ++b) sum[b] += weights[i] * double(vb[i * kInterleave + b]);
        } else {
            for (size_t i = 0; i < per; ++i)
                for (size_t b = 0; b < w; ++b) sum[b] += weights[i] * double(vb[i * w + b]);
        }
        for (size_t b = 0; b < w; ++b)
            out[m0 + b] = sum[b] * box_volume(lo + k * (m0 + b), hi + k * (m0 + b), k) * scale;
    }
}

// The sampler check's moment integrals (harness/samplers/domains.py, MomentColumns): the
// tensor rule's integrals out (boxes, 3) of q, h q and h^2 q, h = q / (q + c) (h = 0 when
// c <= 0), from q's values v (boxes per) at the nodes: cubature_sums of those three columns
// made in numpy's order of operations (h * q, then (h * h) * q), the same bits, without the
// columns' array (making it cost more than the pdf calls on a cheap pdf).  kSideBySide boxes
// at a time, as cubature_sums' single column.  q = double(v) * scale (a constant factor, the
// Jacobian: numpy's pdf * jacobian; 1 changes no bit), v of type T (double, or a float32
// renderer's float as returned); box-major, or in cubature_float32_directions' interleaved
// order (blocks of kInterleave boxes, node i of box b of a block of w at i w + b).
template <class T>
void cubature_moment_sums(const double *lo, const double *hi, size_t boxes, size_t k, const T *v,
                          const double *weights, size_t per, double c, double scale, bool interleaved, double *out) {
    // boxes m .. m + count - 1, node i of box b at vm[b row + i column]
    auto sums = [&](const T *vm, size_t m, auto count, size_t row, size_t column) {
        constexpr size_t B = decltype(count)::value;
        double s0[B] = {}, s1[B] = {}, s2[B] = {};
        for (size_t i = 0; i < per; ++i) {
            const double w = weights[i];
            for (size_t b = 0; b < B; ++b) {
                const double q = double(vm[b * row + i * column]) * scale, h = c > 0 ? q / (q + c) : 0.0;
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
    using One = std::integral_constant<size_t, 1>;
    size_t m = 0;
    if (interleaved) {
        for (; m + kInterleave <= boxes; m += kInterleave)
            sums(v + m * per, m, std::integral_constant<size_t, kInterleave>{}, 1, kInterleave);
        for (size_t w = boxes - m, b = 0; b < w; ++b)   // the last, short block: box b at b + i w
            sums(v + m * per + b, m + b, One{}, 0, w);
        return;
    }
    for (; m + kSideBySide <= boxes; m += kSideBySide)
        sums(v + m * per, m, std::integral_constant<size_t, kSideBySide>{}, per, 1);
    for (; m < boxes; ++m) sums(v + m * per, m, One{}, per, 1);
}

}  // namespace re
