// Bindings of the sampler check's cubature kernels (check_cubature.h, check_refine.h,
// check_quarters.h): the tensor rule's nodes and domain points on boxes, the split points at
// declared breaks, the adaptive refinement's bookkeeping (BoxRefinement), the grouped
// cubature's and the CDF tables' (grouped_agreement, LeafQuarters) and the rule's weighted
// sums.  Arrays are validated here (shapes, sorted breaks; indices by the kernels, where they
// read them), so no call can read out of bounds.
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <vector>

#include "bind_common.h"
#include "check_quarters.h"
#include "check_refine.h"
#include "checks.h"

namespace re::py {

using namespace nb::literals;

namespace {

// Boxes [lo, hi]: both of shape (M, 1) or (M, 2); returns k.
size_t check_boxes(const InArray &lo, const InArray &hi) {
    if (lo.ndim() != 2 || hi.ndim() != 2 || lo.shape(0) != hi.shape(0) || lo.shape(1) != hi.shape(1) ||
        (lo.shape(1) != 1 && lo.shape(1) != 2))
        throw nb::value_error("'lo' and 'hi' must both have shape (M, 1) or (M, 2)");
    return lo.shape(1);
}

// The arguments of a call mapping the tensor rule's nodes on boxes to domain points
// (cubature_points, cubature_float32_directions), checked: the domain, the boxes (M, k) of its
// parameter dimension, the nodes per axis, and `columns`, a permutation of the points'
// coordinates (coordinate columns[j] goes to column j) or empty.
struct CubatureCall {
    CheckDomain d;
    double dlo, dhi;
    const InArray &lo, &hi, &nodes;
    size_t k, g, per, boxes;
    int pdim;
    Placement at;

    CubatureCall(int kind, double dlo_, double dhi_, const InArray &lo_, const InArray &hi_, const InArray &nodes_,
                 const std::vector<int> &columns)
        : d(check_domain(kind)), dlo(dlo_), dhi(dhi_), lo(lo_), hi(hi_), nodes(nodes_), k(check_boxes(lo_, hi_)),
          g(nodes_.size()), per(k == 1 ? g : g * g), boxes(lo_.shape(0)), pdim(domain_point_dim(d)) {
        if (size_t(domain_param_dim(d)) != k) throw nb::value_error("the boxes' dimension is not the domain's");
        if (g == 0) throw nb::value_error("'nodes' must hold at least one point");
        if (columns.empty()) return;
        std::vector<int> seen(columns);
        std::sort(seen.begin(), seen.end());
        bool ok = int(seen.size()) == pdim;
        for (int j = 0; ok && j < pdim; ++j) ok = seen[size_t(j)] == j;
        if (!ok) throw nb::value_error("'columns' must be a permutation of the points' coordinates (or empty)");
        for (int j = 0; j < pdim; ++j) at.dest[columns[size_t(j)]] = j;
    }

    // Boxes a chunk: kCubatureChunk nodes, so that a block of the cubature runs on all threads.
    size_t chunk() const { return std::max<size_t>(kCubatureChunk / per, 1); }

    // The points of boxes a .. b - 1 into x (rows of pdim).
    void points(size_t a, size_t b, double *x, std::vector<double> &scratch) const {
        cubature_points(d, dlo, dhi, lo.data() + a * k, hi.data() + a * k, b - a, k, nodes.data(), g, at, x, scratch);
    }
};

// Boxes a chunk of a kernel on the interleaved order: `chunk` rounded down to whole blocks
// (kInterleave), at least one, so that the order is the same on any number of threads.
inline size_t whole_blocks(size_t chunk) { return std::max<size_t>(chunk / kInterleave * kInterleave, kInterleave); }

// Weights of a tensor rule: at least one (a chunk's boxes are counted in nodes per box).
inline size_t checked_per(const InArray &weights) {
    if (weights.size() == 0) throw nb::value_error("'weights' must hold at least one weight");
    return weights.size();
}

// (columns (3, N) float32, ok (N,)) of the N = boxes x per nodes, filled by
// fill(a, b, N, columns, ok) for boxes a .. b - 1 in chunks of whole blocks (whole_blocks), on
// all threads.
template <class Fill>
nb::tuple float32_directions(size_t boxes, size_t per, size_t chunk, Fill fill) {
    const size_t n = boxes * per;
    const Float32Directions out(n);
    {
        nb::gil_scoped_release r;
        for_chunks(boxes, whole_blocks(chunk),
                   [&](size_t, size_t a, size_t b, int) { fill(a, b, n, out.cols, out.flags); });
    }
    return out.result();
}

}  // namespace

void bind_cubature(nb::module_ &m) {
    m.def("cubature_nodes", [](InArray lo, InArray hi, InArray nodes) {
        const size_t k = check_boxes(lo, hi), boxes = lo.shape(0), g = nodes.size();
        if (g == 0) throw nb::value_error("'nodes' must hold at least one point");
        const size_t per = k == 1 ? g : g * g;
        double *out;
        OutArray pts = new_array(boxes * per, k, &out);
        {
            nb::gil_scoped_release r;
            // box by box, each box's nodes from that box alone: chunks of boxes on all threads
            for_chunks(boxes, std::max<size_t>(kCheckChunk / per, 1), [&](size_t, size_t a, size_t b, int) {
                cubature_nodes(lo.data() + a * k, hi.data() + a * k, b - a, k, nodes.data(), g, out + a * per * k);
            });
        }
        return pts;
    }, "lo"_a, "hi"_a, "nodes"_a,
       "(M g^k, k) nodes of the tensor rule with points `nodes` per axis on the boxes [lo, hi] (M, k), box by box.");
    m.def("cubature_points", [](int kind, double dlo, double dhi, InArray lo, InArray hi, InArray nodes,
                                std::vector<int> columns) {
        const CubatureCall c(kind, dlo, dhi, lo, hi, nodes, columns);
        double *x;
        OutArray xa = new_array(c.boxes * c.per, c.pdim == 1 ? 0 : size_t(c.pdim), &x);
        {
            nb::gil_scoped_release r;
            // each box's points from that box alone: chunks of boxes on all threads
            for_chunks(c.boxes, c.chunk(), [&](size_t, size_t a, size_t b, int) {
                thread_local std::vector<double> scratch;
                c.points(a, b, x + a * c.per * size_t(c.pdim), scratch);
            });
        }
        return xa;
    }, "kind"_a, "dlo"_a, "dhi"_a, "lo"_a, "hi"_a, "nodes"_a, "columns"_a,
       "Domain points of the tensor rule's nodes on the boxes [lo, hi] (M, k): domain_points(cubature_nodes(...)), "
       "with columns[j] as coordinate j where `columns` is given (a permutation; empty: as computed).");
    m.def("cubature_float32_directions", [](int kind, InArray lo, InArray hi, InArray nodes, std::vector<int> columns,
                                            double slack) {
        const CubatureCall c(kind, 0.0, 1.0, lo, hi, nodes, columns);
        if (c.pdim != 3) throw nb::value_error("float32 directions are points of the hemisphere or sphere");
        return float32_directions(c.boxes, c.per, c.chunk(), [&](size_t a, size_t b, size_t n, float *cols, bool *ok) {
            thread_local std::vector<double> scratch, points;
            cubature_float32_directions(c.d, lo.data() + a * c.k, hi.data() + a * c.k, b - a, c.k, nodes.data(), c.g,
                                        c.at, slack, n, cols + a * c.per, ok + a * c.per, scratch, points);
        });
    }, "kind"_a, "lo"_a, "hi"_a, "nodes"_a, "columns"_a, "slack"_a,
       "(columns (3, N) float32, ok (N,)): float32_unit_rows(cubature_points(kind, 0, 1, lo, hi, nodes, columns), "
       "slack) on the hemisphere or sphere, the same bits, in the interleaved order (blocks of 8 boxes, node k of "
       "box b of a block of w at k w + b): the order cubature_sums(..., interleaved=True) reads.");
    m.def("cubature_cap_float32_directions", [](InArray lo, InArray hi, InArray nodes, InArray axis, InArray t,
                                                InArray b, double cos_alpha, double scale, double slack) {
        const CubatureCall c(int(CheckDomain::hemisphere), 0.0, 1.0, lo, hi, nodes, {});
        if (axis.size() != 3 || t.size() != 3 || b.size() != 3)
            throw nb::value_error("'axis', 't' and 'b' must be 3-vectors");
        return float32_directions(c.boxes, c.per, c.chunk(), [&](size_t a, size_t e, size_t n, float *cols, bool *ok) {
            thread_local std::vector<double> scratch, points;
            cubature_cap_float32_directions(lo.data() + a * c.k, hi.data() + a * c.k, e - a, nodes.data(), c.g,
                                            axis.data(), t.data(), b.data(), cos_alpha, scale, slack, n,
                                            cols + a * c.per, ok + a * c.per, scratch, points);
        });
    }, "lo"_a, "hi"_a, "nodes"_a, "axis"_a, "t"_a, "b"_a, "cos_alpha"_a, "scale"_a, "slack"_a,
       "(columns (3, N) float32, ok (N,)): float32_unit_rows(cap_to_world(cubature_points(hemisphere, 0, 1, lo, hi, "
       "nodes), axis, t, b, cos_alpha, scale), slack), the same bits, in cubature_float32_directions' order.");
    m.def("split_points", [](InArray lo, InArray hi, InArray breaks) {
        if (lo.ndim() != 1 || hi.ndim() != 1 || lo.size() != hi.size() || breaks.ndim() != 1)
            throw nb::value_error("'lo' and 'hi' must be arrays (B,) and 'breaks' (n,)");
        if (!sorted_breaks(breaks.data(), breaks.size())) throw nb::value_error("'breaks' must be sorted numbers, no NaN");
        double *out;
        OutArray cuts = new_array(lo.size(), 0, &out);
        {
            nb::gil_scoped_release g;
            for (size_t i = 0; i < lo.size(); ++i)
                out[i] = split_point(lo.data()[i], hi.data()[i], breaks.data(), breaks.size());
        }
        return cuts;
    }, "lo"_a, "hi"_a, "breaks"_a, "Where each interval [lo, hi) is split: the break strictly inside nearest its "
       "middle, else the middle (breaks sorted).");
    nb::class_<BoxRefinement>(m, "BoxRefinement",
        "The bookkeeping of box_integrals' adaptive refinement (harness/samplers/cubature.py): halves() the "
        "boxes' halves along each axis, step(parts, last) the decision on their integrals, result() the sums.")
        .def("__init__", [](BoxRefinement *self, InArray lo, InArray hi, InArray whole, InArray tol, double floor,
                            bool extrapolate, std::vector<std::vector<double>> breaks) {
            const size_t k = check_boxes(lo, hi), n = lo.shape(0);
            if (whole.ndim() != 2 || whole.shape(0) != n || tol.size() != n)
                throw nb::value_error("'whole' must be (N, m) and 'tol' (N,) for the N boxes");
            new (self) BoxRefinement(lo.data(), hi.data(), whole.data(), tol.data(), n, k, whole.shape(1), floor,
                                     extrapolate, std::move(breaks));
        }, "lo"_a, "hi"_a, "whole"_a, "tol"_a, "floor"_a, "extrapolate"_a, "breaks"_a)
        .def_prop_ro("boxes", &BoxRefinement::boxes)
        .def("halves", [](BoxRefinement &r) {
            const size_t k = r.k(), rows = 2 * k * r.boxes();
            double *clo, *chi;
            OutArray a = new_array(rows, k, &clo), b = new_array(rows, k, &chi);
            {
                nb::gil_scoped_release g;
                r.halves(clo, chi);
            }
            return nb::make_tuple(a, b);
        }, "(clo, chi): every box's two halves along each axis, axis-major, (2 k B, k) each.")
        .def("step", [](BoxRefinement &r, InArray parts, bool last) {
            if (parts.ndim() != 2 || parts.shape(0) != 2 * r.k() * r.boxes() || parts.shape(1) != r.m())
                throw nb::value_error("'parts' must hold the integrals over halves()' boxes, (2 k B, m)");
            nb::gil_scoped_release g;
            return r.step(parts.data(), last);
        }, "parts"_a, "last"_a, "Finishes the converged boxes (all when `last`); whether boxes remain.")
        .def("result", [](const BoxRefinement &r) {
            double *value, *error;
            OutArray a = new_array(r.cells(), r.m(), &value), b = new_array(r.cells(), r.m(), &error);
            r.result(value, error);
            return nb::make_tuple(a, b);
        }, "(integrals, errors) (N, m): each box's finished parts summed in the order they finished.");
    m.def("uncut_parents", [](InArray hi, I64Array group, InArray parent_hi) {
        if (hi.ndim() != 2 || (hi.shape(1) != 1 && hi.shape(1) != 2))
            throw nb::value_error("'hi' must have shape (B, 1) or (B, 2)");
        const size_t k = hi.shape(1);
        if (group.size() != hi.shape(0) || parent_hi.ndim() != 2 || parent_hi.shape(1) != k)
            throw nb::value_error("'group' must be (B,) for the boxes 'hi' (B, k), and 'parent_hi' (G, k)");
        nb::gil_scoped_release r;   // the kernel checks each index as it reads it
        return uncut_parents(hi.data(), group.data(), group.size(), k, parent_hi.data(), parent_hi.shape(0));
    }, "hi"_a, "group"_a.noconvert(), "parent_hi"_a,
       "How many parents are not cut along every axis by their boxes (a box ends below its parent's end).");
    m.def("grouped_agreement", [](InArray own, InArray parent, I64Array group, InArray tol, double floor) {
        if (own.ndim() != 2 || parent.ndim() != 2 || own.shape(1) != parent.shape(1) || own.shape(1) == 0 ||
            group.size() != own.shape(0) || tol.size() != own.shape(0))
            throw nb::value_error("'own' must be (B, m), 'parent' (G, m), 'group' and 'tol' (B,)");
        const size_t boxes = own.shape(0), m = own.shape(1);
        double *value, *error;
        OutArray va = new_array(boxes, m, &value), ea = new_array(boxes, m, &error);
        std::vector<int64_t> rest;
        {
            nb::gil_scoped_release r;
            grouped_agreement(own.data(), parent.data(), group.data(), tol.data(), boxes, parent.shape(0), m, floor,
                              value, error, rest);
        }
        return nb::make_tuple(va, ea, index_array(rest));
    }, "own"_a, "parent"_a, "group"_a.noconvert(), "tol"_a, "floor"_a,
       "(value, error, rest): the boxes of parents whose rule agrees with their boxes' sum take their own "
       "integrals, the parent's change shared by tolerance as error; `rest` the other boxes' rows.");
    nb::class_<LeafQuarters>(m, "LeafQuarters",
        "The boxes of the CDF tables' leaf quarters (harness/samplers/cdf_tables.py) and their integrals "
        "summed back into quarter masses (sums).")
        .def("__init__", [](LeafQuarters *self, I64Array strip, InArray a, InArray b, InArray pieces,
                            I64Array used, InArray strip_tol, size_t axis, size_t k) {
            if ((k != 1 && k != 2) || axis >= k) throw nb::value_error("'k' must be 1 or 2 and 'axis' below it");
            if (a.ndim() != 1 || b.ndim() != 1 || a.size() != strip.size() || b.size() != strip.size())
                throw nb::value_error("'strip', 'a' and 'b' must be (L,) each");
            if (pieces.ndim() != 3 || pieces.shape(2) != 2 || pieces.shape(1) == 0 || used.size() != pieces.shape(0) ||
                strip_tol.ndim() != 1 || strip_tol.size() != pieces.shape(0))
                throw nb::value_error("'pieces' must be (S, P, 2) with P >= 1, 'used' and 'strip_tol' (S,)");
            nb::gil_scoped_release r;   // the indices are checked on the constructor's copies
            new (self) LeafQuarters(strip.data(), a.data(), b.data(), strip.size(), pieces.data(), pieces.shape(0),
                                    pieces.shape(1), used.data(), strip_tol.data(), axis, k);
        }, "strip"_a.noconvert(), "a"_a, "b"_a, "pieces"_a, "used"_a.noconvert(), "strip_tol"_a, "axis"_a, "k"_a)
        .def("boxes", [](const LeafQuarters &q) {
            const size_t k = q.k(), rows = q.rows(), parents = q.parents();
            double *lo, *hi, *tol, *plo, *phi;
            OutArray la = new_array(rows, k, &lo), ha = new_array(rows, k, &hi), ta = new_array(rows, 0, &tol);
            OutArray pla = new_array(parents, k, &plo), pha = new_array(parents, k, &phi);
            int64_t *group;
            auto ga = new_index_array(rows, &group);
            {
                nb::gil_scoped_release r;
                q.boxes(lo, hi, tol, group, plo, phi);
            }
            return nb::make_tuple(la, ha, ga, pla, pha, ta);
        }, "(lo, hi, group, parent_lo, parent_hi, tol): the boxes to integrate (rows, k), their parents' indices "
           "(rows,) int64, the parents (G, k) and the boxes' tolerances (rows,), as grouped_integrals takes them.")
        .def_prop_ro("count", &LeafQuarters::full_boxes, "the non-empty boxes (l, j, p) integrated")
        .def("sums", [](const LeafQuarters &q, InArray v, InArray e) {
            if (v.ndim() != 2 || e.ndim() != 2 || v.shape(0) != q.rows() || e.shape(0) != q.rows() ||
                v.shape(1) != e.shape(1) || v.shape(1) == 0)
                throw nb::value_error("'v' and 'e' must be the integrals and errors (rows, m) over the boxes");
            double *qs, *errs;
            OutArray qa = new_array(q.leaves(), 4, &qs), ea = new_array(q.leaves(), 0, &errs);
            {
                nb::gil_scoped_release r;
                q.sums(v.data(), e.data(), v.shape(1), qs, errs);
            }
            return nb::make_tuple(qa, ea);
        }, "v"_a, "e"_a, "(qs (L, 4), errs (L,)): each leaf's quarter masses and its boxes' summed errors.");
    m.def("interpolation_bound", [](InArray qs) {
        if (qs.ndim() != 2 || qs.shape(1) != 4) throw nb::value_error("'qs' must be quarter masses of shape (L, 4)");
        double *out;
        OutArray oa = new_array(qs.shape(0), 0, &out);
        {
            nb::gil_scoped_release r;
            interpolation_bound(qs.data(), qs.shape(0), out);
        }
        return oa;
    }, "qs"_a, "(L,): the CDF tables' interpolation bound of each leaf from its quarter masses (L, 4).");
    // values as float64, or as float32 (a float32 renderer's pdf as it returned them); box-major,
    // or (one column) in cubature_float32_directions' interleaved order
    auto sums = [](const InArray &lo, const InArray &hi, const auto &values, const InArray &weights, double scale,
                   bool interleaved) {
        const size_t k = check_boxes(lo, hi), boxes = lo.shape(0), per = checked_per(weights);
        const size_t cols = values.ndim() == 2 ? values.shape(1) : 1;
        if ((values.ndim() != 1 && values.ndim() != 2) || values.shape(0) != boxes * per)
            throw nb::value_error("'values' must have one row per node: shape (M g^k,) or (M g^k, m)");
        if (interleaved && values.ndim() != 1) throw nb::value_error("interleaved 'values' must be one column (M g^k,)");
        double *out;
        OutArray oa = new_array(boxes, cols, &out);
        {
            nb::gil_scoped_release r;
            const size_t chunk = std::max<size_t>(kCheckChunk / per, 1);
            for_chunks(boxes, interleaved ? whole_blocks(chunk) : chunk, [&](size_t, size_t a, size_t b, int) {
                if (interleaved)
                    cubature_sums_interleaved(lo.data() + a * k, hi.data() + a * k, b - a, k, values.data() + a * per,
                                              weights.data(), per, scale, out + a);
                else
                    cubature_sums(lo.data() + a * k, hi.data() + a * k, b - a, k, values.data() + a * per * cols, cols,
                                  weights.data(), per, scale, out + a * cols);
            });
        }
        return oa;
    };
    const char *sums_doc = "(M, m) integrals of the tensor rule on the boxes [lo, hi] (M, k): the weighted sum of the "
                           "values (M g^k, m) at their nodes (float64 or float32; with `interleaved` one column in "
                           "cubature_float32_directions' order) times the volume, times `scale`.";
    m.def("cubature_sums", [sums](InArray lo, InArray hi, InArray values, InArray weights, double scale,
                                  bool interleaved) {
        return sums(lo, hi, values, weights, scale, interleaved);
    }, "lo"_a, "hi"_a, "values"_a, "weights"_a, "scale"_a, "interleaved"_a = false, sums_doc);
    m.def("cubature_sums", [sums](InArray lo, InArray hi, nb::ndarray<const float, nb::c_contig, nb::device::cpu> values,
                                  InArray weights, double scale, bool interleaved) {
        return sums(lo, hi, values, weights, scale, interleaved);
    }, "lo"_a, "hi"_a, "values"_a, "weights"_a, "scale"_a, "interleaved"_a = false, sums_doc);
    // values as float64 or float32, box-major or interleaved (as cubature_sums')
    auto moments = [](const InArray &lo, const InArray &hi, const auto &values, const InArray &weights, double c,
                      double scale, bool interleaved) {
        const size_t k = check_boxes(lo, hi), boxes = lo.shape(0), per = checked_per(weights);
        if (values.ndim() != 1 || values.shape(0) != boxes * per)
            throw nb::value_error("'values' must have one value per node: shape (M g^k,)");
        double *out;
        OutArray oa = new_array(boxes, 3, &out);
        {
            nb::gil_scoped_release r;
            const size_t chunk = std::max<size_t>(kCheckChunk / per, 1);
            for_chunks(boxes, interleaved ? whole_blocks(chunk) : chunk, [&](size_t, size_t a, size_t b, int) {
                cubature_moment_sums(lo.data() + a * k, hi.data() + a * k, b - a, k, values.data() + a * per,
                                     weights.data(), per, c, scale, interleaved, out + a * 3);
            });
        }
        return oa;
    };
    const char *moments_doc = "(M, 3) integrals of q, h q and h^2 q (h = q / (q + c), 0 when c <= 0) by the tensor "
                              "rule on the boxes [lo, hi] (M, k), q = values * scale from the values (M g^k,) at the "
                              "nodes (float64 or float32; with `interleaved` in cubature_float32_directions' order).";
    m.def("cubature_moment_sums", [moments](InArray lo, InArray hi, InArray values, InArray weights, double c,
                                            double scale, bool interleaved) {
        return moments(lo, hi, values, weights, c, scale, interleaved);
    }, "lo"_a, "hi"_a, "values"_a, "weights"_a, "c"_a, "scale"_a = 1.0, "interleaved"_a = false, moments_doc);
    m.def("cubature_moment_sums", [moments](InArray lo, InArray hi,
                                            nb::ndarray<const float, nb::c_contig, nb::device::cpu> values,
                                            InArray weights, double c, double scale, bool interleaved) {
        return moments(lo, hi, values, weights, c, scale, interleaved);
    }, "lo"_a, "hi"_a, "values"_a, "weights"_a, "c"_a, "scale"_a = 1.0, "interleaved"_a = false, moments_doc);
}

}  // namespace re::py
