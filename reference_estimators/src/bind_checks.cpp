// Bindings of the sampler check's batch kernels (checks.h, tables.h): domain maps, histograms,
// the Rosenblatt transform and its statistics, pdf summaries and float32 helpers (the
// cubature's kernels are bound in bind_cubature.cpp, a renderer's rows in bind_rows.cpp).
// Arrays are validated here (shape, table layout), so no call can read out of bounds.
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <memory>
#include <utility>

#include "bind_common.h"
#include "checks.h"
#include "tables.h"

namespace re::py {
namespace {

using namespace nb::literals;

// Parameter points s: shape (n, k), or (n,) when k == 1.
size_t check_params(const InArray &s, size_t k) {
    if (!((s.ndim() == 2 && s.shape(1) == k) || (k == 1 && s.ndim() == 1)))
        throw nb::value_error(k == 1 ? "'s' must have shape (N, 1) or (N,)" : "'s' must have shape (N, 2)");
    return s.shape(0);
}

// The shape a piecewise-linear table's arrays must have (one lo, hi, start and mass per leaf;
// offsets from 0 to the leaves, not decreasing), or a ValueError saying what is wrong.
template <class Offsets>
void check_table(const InArray &lo, const InArray &hi, const InArray &start, const InArray &mass,
                        const Offsets &offsets) {
    const size_t leaves = lo.size();
    if (hi.size() != leaves || start.size() != leaves || mass.size() != leaves)
        throw nb::value_error("'lo', 'hi', 'start' and 'mass' must have one value per leaf");
    if (leaves >= (size_t(1) << 31)) throw nb::value_error("a table must have fewer than 2^31 leaves");
    if (offsets.size() < 1 || offsets.data()[0] != 0 || size_t(offsets.data()[offsets.size() - 1]) != leaves)
        throw nb::value_error("'offsets' must run from 0 to the number of leaves");
    for (size_t g = 1; g < offsets.size(); ++g)
        if (offsets.data()[g] < offsets.data()[g - 1]) throw nb::value_error("'offsets' must not decrease");
}

// A piecewise-linear table given as (lo, hi, start, mass, offsets), validated, with its
// bucket index; the arrays are kept alive (and unchanged) by the caller's tuple.
struct BoundTable {
    InArray lo, hi, start, mass;
    I64Array offsets;
    std::unique_ptr<PiecewiseLinearTable> table;

    explicit BoundTable(nb::handle t) {
        nb::tuple parts = nb::cast<nb::tuple>(t);
        if (parts.size() != 5) throw nb::value_error("a table must be (lo, hi, start, mass, offsets)");
        lo = nb::cast<InArray>(parts[0]);
        hi = nb::cast<InArray>(parts[1]);
        start = nb::cast<InArray>(parts[2]);
        mass = nb::cast<InArray>(parts[3]);
        offsets = nb::cast<I64Array>(parts[4]);
        check_table(lo, hi, start, mass, offsets);
        table = std::make_unique<PiecewiseLinearTable>(lo.data(), hi.data(), start.data(), mass.data(),
                                                       offsets.data(), int64_t(offsets.size()) - 1);
    }
};

// A Rosenblatt transform's tables as Python passes them: the marginal and, on the square (a
// conditional given), the conditional, whose strips `edges` bound (one more edge than strips).
struct BoundTransform {
    BoundTable marginal;
    std::unique_ptr<BoundTable> conditional;
    size_t k;

    BoundTransform(nb::handle m, nb::handle c, const InArray &edges) : marginal(m), k(c.is_none() ? 1 : 2) {
        if (k == 1) return;
        conditional = std::make_unique<BoundTable>(c);
        if (edges.size() != conditional->offsets.size())
            throw nb::value_error("'edges' must hold one more value than the conditional has strips");
    }
    const PiecewiseLinearTable *conditional_table() const { return conditional ? conditional->table.get() : nullptr; }
};

// Rows of x (N, dim_in) through map(a, e, out) into N rows of dim_out (0: (N,)), chunks on all
// threads (each row from that row alone).
template <class Map>
OutArray map_rows(const InArray &x, int dim_in, const char *arg, size_t dim_out, Map map) {
    const size_t n = check_points(x, dim_in, arg);
    double *out;
    OutArray rows = new_array(n, dim_out, &out);
    {
        nb::gil_scoped_release g;
        for_chunks(n, kCubatureChunk, [&](size_t, size_t a, size_t e, int) { map(a, e, out); });
    }
    return rows;
}

// The rows x (N, 3) through one of the cap's maps (cap_to_world, cap_to_hemisphere): map_rows,
// the frame (axis, t, b) checked first.
template <class Map>
OutArray cap_rows(const InArray &x, const char *arg, const InArray &axis, const InArray &t, const InArray &b,
                  Map map) {
    if (axis.size() != 3 || t.size() != 3 || b.size() != 3)
        throw nb::value_error("'axis', 't' and 'b' must be 3-vectors");
    return map_rows(x, 3, arg, 3, map);
}

// The rectangle light's frame (rect_to_square, rect_to_world, rect_density) from its
// 3-vectors and the dual basis (2, 3), checked.
RectangleFrame rectangle_frame(const InArray &to_corner, const InArray &e0, const InArray &e1, const InArray &normal,
                               const InArray &dual, double height, double area) {
    if (to_corner.size() != 3 || e0.size() != 3 || e1.size() != 3 || normal.size() != 3)
        throw nb::value_error("'to_corner', 'e0', 'e1' and 'normal' must be 3-vectors");
    if (dual.size() != 6) throw nb::value_error("'dual' must hold the two dual basis vectors (2, 3)");
    return {to_corner.data(), e0.data(), e1.data(), normal.data(), dual.data(), height, area};
}

// (s, inside) of domain_params for points x on domain `kind`, on all threads in fixed chunks
// (each point's parameters its own; the maps' vector lanes and scalar tails give the same
// bits).  With uniforms u, s is of the points dithered within their float32 rounding
// (dither_float32), a chunk at a time into this thread's scratch rows (reused from chunk to
// chunk: no fresh memory), and `inside` of the points as given.  With a stream key in place
// of u, the uniforms are those of points(N, coordinates, seed, case_id) (chunk c of them from
// the stream (seed, case_id, 0, c), as the bindings' `points` draws them), drawn a chunk at a
// time into scratch too: no array of N uniforms is written out and read back (what that saves
// is small: points() cost 1.3 ms a million directions of a pass of 6-11 ms).
static_assert(kCheckChunk == kChunkSize, "a check chunk's dither uniforms are one stream chunk's");
nb::tuple parameters(int kind, double lo, double hi, const InArray &x, const double *u,
                     const StreamKey *stream = nullptr) {
    const CheckDomain d = check_domain(kind);
    const int pdim = domain_point_dim(d), k = domain_param_dim(d);
    const size_t n = check_points(x, pdim, "x");
    double *s;
    bool *inside;
    OutArray sa = new_array(n, size_t(k), &s);
    auto ia = new_bool_array(n, &inside);
    {
        nb::gil_scoped_release g;
        for_chunks(n, kCheckChunk, [&](size_t c, size_t a, size_t b, int) {
            const size_t rows = b - a, values = rows * size_t(pdim);
            const double *xa = x.data() + a * size_t(pdim);
            if (!u && !stream) {
                domain_params(d, lo, hi, xa, rows, s + a * size_t(k), inside + a);
                return;
            }
            thread_local std::vector<double> moved, drawn;
            thread_local std::unique_ptr<bool[]> unused;   // the dithered points' mask, not wanted
            thread_local size_t unused_size = 0;
            moved.resize(values);
            if (unused_size < rows) unused.reset(new bool[unused_size = rows]);
            domain_params(d, lo, hi, xa, rows, nullptr, inside + a);
            const double *ua = u ? u + a * size_t(pdim) : nullptr;
            if (!ua) {
                drawn.resize(values);
                UniformStream chunk({stream->seed, stream->case_id, stream->replica, c});
                chunk.fill(drawn.data(), values);
                ua = drawn.data();
            }
            dither_float32(xa, ua, values, moved.data());
            domain_params(d, lo, hi, moved.data(), rows, s + a * size_t(k), unused.get());
        });
    }
    return nb::make_tuple(sa, ia);
}

}  // namespace

void bind_checks(nb::module_ &m) {
    m.def("domain_params", [](int kind, double lo, double hi, InArray x) {
        return parameters(kind, lo, hi, x, nullptr);
    }, "kind"_a, "lo"_a, "hi"_a, "x"_a,
       "(s (N, k), inside (N,)): the equal-measure parameters of points x on domain `kind` "
       "(0 interval [lo, hi], 1 half line, 2 square, 3 disk, 4 hemisphere, 5 sphere).");
    m.def("dithered_domain_params", [](int kind, double lo, double hi, InArray x, InArray u) {
        if (u.size() != x.size()) throw nb::value_error("'u' must have one uniform per coordinate of 'x'");
        return parameters(kind, lo, hi, x, u.data());
    }, "kind"_a, "lo"_a, "hi"_a, "x"_a, "u"_a,
       "(s (N, k), inside (N,)): domain_params' s of the points x dithered by dither_float32 with uniforms u, and "
       "its inside of x as given.");
    m.def("streamed_dithered_domain_params", [](int kind, double lo, double hi, InArray x, uint64_t seed,
                                                uint64_t case_id) {
        const StreamKey key{seed, case_id, 0, 0};
        return parameters(kind, lo, hi, x, nullptr, &key);
    }, "kind"_a, "lo"_a, "hi"_a, "x"_a, "seed"_a, "case_id"_a,
       "dithered_domain_params with the uniforms points(N, coordinates, seed=seed, case_id=case_id) would give, "
       "drawn chunk by chunk inside the pass.");
    m.def("domain_points", [](int kind, double lo, double hi, InArray s) {
        const CheckDomain d = check_domain(kind);
        const int pdim = domain_point_dim(d), k = domain_param_dim(d);
        const size_t n = check_params(s, size_t(k));
        double *x;
        OutArray xa = new_array(n, pdim == 1 ? 0 : size_t(pdim), &x);
        {
            nb::gil_scoped_release g;
            // each point depends on its parameters alone (the vector and scalar maps give the
            // same bits): chunks on all threads
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                domain_points(d, lo, hi, s.data() + a * size_t(k), b - a, x + a * size_t(pdim));
            });
        }
        return xa;
    }, "kind"_a, "lo"_a, "hi"_a, "s"_a, "Points x(s) (N,) or (N, point_dim) of parameters s (N, k) on domain `kind`.");
    m.def("cap_to_world", [](InArray h, InArray axis, InArray t, InArray b, double cos_alpha, double scale) {
        return cap_rows(h, "h", axis, t, b, [&](size_t a, size_t e, double *out) {
            cap_to_world(h.data(), a, e, axis.data(), t.data(), b.data(), cos_alpha, scale, out);
        });
    }, "h"_a, "axis"_a, "t"_a, "b"_a, "cos_alpha"_a, "scale"_a,
       "World directions (N, 3) of hemisphere points h (N, 3) through the equal-area map of the cap about `axis` "
       "(frame t, b, axis) with cosine `cos_alpha`, scale = 1 - cos_alpha.");
    m.def("cap_to_hemisphere", [](InArray d, InArray axis, InArray t, InArray b, double cos_alpha, double scale,
                                  double rim_slack) {
        return cap_rows(d, "d", axis, t, b, [&](size_t a, size_t e, double *out) {
            cap_to_hemisphere(d.data(), a, e, axis.data(), t.data(), b.data(), cos_alpha, scale, rim_slack, out);
        });
    }, "d"_a, "axis"_a, "t"_a, "b"_a, "cos_alpha"_a, "scale"_a, "rim_slack"_a,
       "Hemisphere points (N, 3) of world directions d (N, 3) through the equal-area map of the cap about `axis` "
       "(frame t, b, axis) with cosine `cos_alpha`, scale = 1 - cos_alpha; within rim_slack below the rim: on it.");
    m.def("cap_density", [](InArray h, InArray p, double scale) {
        if (p.ndim() != 1 || p.size() != check_points(h, 3, "h"))
            throw nb::value_error("'p' must hold one value per row of 'h'");
        return map_rows(h, 3, "h", 0, [&](size_t a, size_t e, double *out) {
            cap_density(h.data(), p.data(), a, e, scale, out);
        });
    }, "h"_a, "p"_a, "scale"_a, "(N,): float32(p) * float32(scale), widened, where the row of h (N, 3) is finite "
       "with h_z >= 0, else 0.");
    m.def("rect_to_square", [](InArray d, InArray to_corner, InArray e0, InArray e1, InArray normal, InArray dual,
                               double height, double area, double slack) {
        const RectangleFrame f = rectangle_frame(to_corner, e0, e1, normal, dual, height, area);
        return map_rows(d, 3, "d", 2,
                        [&](size_t a, size_t e, double *out) { rect_to_square(d.data(), a, e, f, slack, out); });
    }, "d"_a, "to_corner"_a, "e0"_a, "e1"_a, "normal"_a, "dual"_a, "height"_a, "area"_a, "slack"_a,
       "Points (N, 2) of the rectangle light's square where the rays from ref along d (N, 3) hit its plane "
       "(harness.adapters.mitsuba.rectangle.Rectangle.to_domain).");
    m.def("rect_to_world", [](InArray s, InArray to_corner, InArray e0, InArray e1, InArray normal, InArray dual,
                              double height, double area) {
        const RectangleFrame f = rectangle_frame(to_corner, e0, e1, normal, dual, height, area);
        return map_rows(s, 2, "s", 3, [&](size_t a, size_t e, double *out) { rect_to_world(s.data(), a, e, f, out); });
    }, "s"_a, "to_corner"_a, "e0"_a, "e1"_a, "normal"_a, "dual"_a, "height"_a, "area"_a,
       "Unit world directions (N, 3) from ref towards the points s (N, 2) of the rectangle light "
       "(Rectangle.to_world).");
    m.def("rect_density", [](InArray s, InArray p, InArray to_corner, InArray e0, InArray e1, InArray normal,
                             InArray dual, double height, double area) {
        const RectangleFrame f = rectangle_frame(to_corner, e0, e1, normal, dual, height, area);
        if (p.ndim() != 1 || p.size() != check_points(s, 2, "s"))
            throw nb::value_error("'p' must hold one value per row of 's'");
        return map_rows(s, 2, "s", 0, [&](size_t a, size_t e, double *out) {
            rect_density(s.data(), p.data(), a, e, f, out);
        });
    }, "s"_a, "p"_a, "to_corner"_a, "e0"_a, "e1"_a, "normal"_a, "dual"_a, "height"_a, "area"_a,
       "(N,): float32(p) * float32(J(s)), widened, at the points s (N, 2) inside [0, 1]^2, else 0 "
       "(Rectangle.density).");
    m.def("grid_histogram", [](InArray s, BoolArray inside, const std::vector<int64_t> &shape) {
        if (shape.empty() || shape.size() > 2 || shape[0] < 1 || (shape.size() == 2 && shape[1] < 1))
            throw nb::value_error("'shape' must be one or two positive cell counts");
        const size_t n = check_params(s, shape.size());
        if (inside.size() != n) throw nb::value_error("'inside' must have one flag per point");
        double *c;
        OutArray counts = new_array(size_t(shape[0]), shape.size() == 2 ? size_t(shape[1]) : 0, &c);
        {
            nb::gil_scoped_release g;
            grid_histogram(s.data(), n, inside.data(), shape[0], shape.size() == 2 ? shape[1] : 0, c);
        }
        return counts;
    }, "s"_a, "inside"_a, "shape"_a,
       "Counts of the inside points s (N, k) in [0, 1]^k on the regular grid `shape`, coordinates clamped "
       "to [0, 1).");
    m.def("rosenblatt", [](nb::handle marginal, nb::handle conditional, InArray edges, InArray s) {
        const BoundTransform t(marginal, conditional, edges);
        const size_t k = t.k, n = check_params(s, k);
        double *u;
        OutArray ua = new_array(n, k, &u);
        int64_t *g;
        auto strip = new_index_array(n, &g);
        {
            nb::gil_scoped_release r;
            rosenblatt(*t.marginal.table, t.conditional_table(), edges.data(), edges.size(), s.data(), k, n, u, g);
        }
        return nb::make_tuple(ua, strip);
    }, "marginal"_a, "conditional"_a.none(), "edges"_a, "s"_a,
       "(u (N, k), strip (N,)): the Rosenblatt transform of parameter points s through the marginal table "
       "and, on the square, the conditional one given the strip of s0 among `edges`; tables are "
       "(lo, hi, start, mass, offsets).");
    m.def("transform_statistics", [](nb::handle marginal, nb::handle conditional, InArray edges, InArray s,
                                     int64_t bins) {
        const BoundTransform t(marginal, conditional, edges);
        const size_t k = t.k, n = check_params(s, k);
        if (bins < 1) throw nb::value_error("'bins' must be positive");
        double *r, *c;
        OutArray sums = new_array(k, 2, &r);
        OutArray counts = new_array(size_t((k == 2 ? int64_t(edges.size()) - 1 : 1) * bins), 0, &c);
        {
            nb::gil_scoped_release g;
            CramerVonMisesSum found[2];
            transform_statistics(*t.marginal.table, t.conditional_table(), edges.data(), edges.size(), s.data(), k,
                                 n, bins, found, c);
            for (size_t j = 0; j < k; ++j) r[2 * j] = found[j].upper, r[2 * j + 1] = found[j].slack;
        }
        return nb::make_tuple(sums, counts);
    }, "marginal"_a, "conditional"_a.none(), "edges"_a, "s"_a, "bins"_a,
       "(sums (k, 2), counts (strips * bins,)) of the Rosenblatt transform u of parameter points s (as rosenblatt): "
       "the Cramer-von Mises sum of each column of u (as cramer_von_mises_sum) and the counts of strips x bins "
       "of u1 on the square, of bins of u0 on an interval (cell strip * bins + min(floor(u bins), bins - 1); "
       "NaN u nowhere), without returning u.");
    m.def("cramer_von_mises_sum", [](nb::ndarray<const double, nb::ndim<2>, nb::device::cpu> u) {
        const size_t n = u.shape(0), k = u.shape(1);
        double *r;
        OutArray sums = new_array(k, 2, &r);
        {
            nb::gil_scoped_release g;
            // a column at a time, each on all threads
            for (size_t c = 0; c < k; ++c) {
                const CramerVonMisesSum s =
                    cramer_von_mises_sum(u.data() + c * size_t(u.stride(1)), size_t(u.stride(0)), n);
                r[2 * c] = s.upper, r[2 * c + 1] = s.slack;
            }
        }
        return sums;
    }, "u"_a, "For each column of u (N, k), (upper, slack) with upper >= S >= upper - slack, S = "
       "sum_i ((2 i - 1) / (2 N) - u_(i))^2 over its sorted values; NaN for a column holding a NaN.");
    m.def("finite_rows", [](nb::ndarray<const double, nb::device::cpu> x) {
        if (x.ndim() != 1 && x.ndim() != 2) throw nb::value_error("'x' must have shape (N,) or (N, k)");
        const size_t n = x.shape(0), k = x.ndim() == 2 ? x.shape(1) : 1;
        const int64_t row = x.stride(0), column = x.ndim() == 2 ? x.stride(1) : 1;
        if (row < 0 || column < 0) throw nb::value_error("'x' must not have negative strides");
        bool *ok;
        auto oa = new_bool_array(n, &ok);
        {
            nb::gil_scoped_release g;
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                finite_rows(x.data(), size_t(row), size_t(column), a, b, k, ok);
            });
        }
        return oa;
    }, "x"_a, "(N,) bool: whether each row of x (N, k) (or value of x (N,)) is finite in every value; strided "
       "views read in place.");
    m.def("all_float32", [](InArray v) {
        nb::gil_scoped_release g;
        return all_float32(v.data(), v.size());
    }, "v"_a, "Whether every finite non-zero value of v is a float32, and there is one.");
    m.def("dither_float32", [](InArray v, InArray u) {
        if (u.size() != v.size()) throw nb::value_error("'u' must have one uniform per value of 'v'");
        double *out;
        OutArray r = new_array(v.size(), 0, &out);
        {
            nb::gil_scoped_release g;
            // each value depends on itself and its uniform alone: chunks on all threads
            for_chunks(v.size(), kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                dither_float32(v.data() + a, u.data() + a, b - a, out + a);
            });
        }
        return r;
    }, "v"_a, "u"_a, "The values v (flattened) each moved to below + (above - below) u, below and above half "
       "way to its float32 neighbours; v itself where that is not finite.");
    m.def("float32_nudged", [](InArray x, size_t column, int steps) {
        if (x.ndim() != 2 || column >= x.shape(1))
            throw nb::value_error("'x' must be an array (N, d) and 'column' one of its columns");
        const size_t n = x.shape(0), d = x.shape(1);
        double *out;
        OutArray r = new_array(n, d, &out);
        {
            nb::gil_scoped_release g;
            // each row depends on itself alone: chunks on all threads
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                float32_nudged(x.data(), d, column, steps, a, b, out);
            });
        }
        return r;
    }, "x"_a, "column"_a, "steps"_a,
       "x (N, d) rounded to float32 with column `column` moved |steps| float32 ulps (up if steps > 0), as float64.");
    m.def("pdf_summary", [](int kind, double measure, InArray s, BoolArray inside, InArray p, double c, double total) {
        const CheckDomain d = check_domain(kind);
        const size_t n = check_params(s, size_t(domain_param_dim(d)));
        if (inside.size() != n || p.size() != n) throw nb::value_error("'inside' and 'p' must have one value per point");
        PdfSummary r;
        {
            nb::gil_scoped_release g;
            r = pdf_summary(d, measure, s.data(), inside.data(), p.data(), n, c, total);
        }
        return nb::make_tuple(r.bad, r.zero, r.used, r.h_sum);
    }, "kind"_a, "measure"_a, "s"_a, "inside"_a, "p"_a, "c"_a, "total"_a,
       "(bad, zero, used, h_sum): of p / total, values NaN/infinite/negative, zero at inside points, good inside "
       "ones, and the sum of h = p J / (p J + c) over those.");
    m.def("pdf_mismatches", [](InArray reported, InArray p, double rtol) {
        if (reported.ndim() != 1 || p.ndim() != 1 || reported.size() != p.size())
            throw nb::value_error("'reported' and 'p' must be arrays (N,) of the same length");
        std::vector<int64_t> rows;
        {
            nb::gil_scoped_release g;
            pdf_mismatches(reported.data(), p.data(), p.size(), rtol, rows);
        }
        return index_array(rows);
    }, "reported"_a, "p"_a, "rtol"_a,
       "(M,) int64: the rows where |reported - p| > rtol |p| (or NaN), or reported is infinite or negative.");
    m.def("piecewise_linear_lookup", [](InArray lo, InArray hi, InArray start, InArray mass,
                                        nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu> offsets,
                                        nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu> strip,
                                        InArray x) {
        check_table(lo, hi, start, mass, offsets);
        if (strip.size() != x.size()) throw nb::value_error("'strip' and 'x' must have one value per point");
        double *out;
        OutArray u = new_array(x.size(), 0, &out);
        {
            nb::gil_scoped_release g;
            piecewise_linear_lookup(lo.data(), hi.data(), start.data(), mass.data(), offsets.data(),
                                    int64_t(offsets.size()) - 1, strip.data(), x.data(), x.size(), out);
        }
        return u;
    }, "lo"_a, "hi"_a, "start"_a, "mass"_a, "offsets"_a, "strip"_a, "x"_a,
       "u = start[i] + mass[i] * clamp((x - lo[i]) / (hi[i] - lo[i]), 0, 1) for the leaf i of the point's strip "
       "(leaves offsets[g] .. offsets[g+1]-1, sorted by lo) with the largest lo <= x; NaN for a strip out of range.");
}

}  // namespace re::py
