// Bindings of a renderer's rows in the sampler check and its adapters (check_rows.h,
// check_float32.h): directions rounded to float32 unit vectors, float32 columns and float64
// rows, row selection and lookup.  Arrays are validated here, so no call can read out of
// bounds.
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <utility>
#include <vector>

#include "bind_common.h"
#include "check_rows.h"
#include "checks.h"

namespace re::py {
namespace {

using namespace nb::literals;

// The rows of x (N,) or (N, k), k >= 1, with one `keep` flag per row: N.
size_t check_rows(const InArray &x, const BoolArray &keep) {
    if (x.ndim() < 1 || x.ndim() > 2 || (x.ndim() == 2 && x.shape(1) == 0) || keep.size() != x.shape(0))
        throw nb::value_error("'x' must be (N,) or (N, k), k >= 1, with one 'keep' flag per row");
    return x.shape(0);
}

}  // namespace

void bind_rows(nb::module_ &m) {
    struct RowsLookup {   // the rows kept alive beside the lookup that reads them
        InArray rows;
        RowLookup lookup;
    };
    nb::class_<RowsLookup>(m, "RowLookup", "Which of the rows x (N, k), k <= 3, equals a given row (numpy's ==).")
        .def("__init__", [](RowsLookup *self, InArray x) {
            if (x.ndim() != 2 || x.shape(1) < 1 || x.shape(1) > 3) throw nb::value_error("'x' must have shape (N, k), k 1 to 3");
            if (x.shape(0) >= size_t(0xffffffffu)) throw nb::value_error("'x' must have fewer than 2^32 - 1 rows");
            RowLookup lookup = [&] {
                nb::gil_scoped_release r;
                return RowLookup(x.data(), x.shape(0), x.shape(1));
            }();
            new (self) RowsLookup{x, std::move(lookup)};
        }, "x"_a)
        .def("find", [](const RowsLookup &r, InArray q) {
            if (q.ndim() != 2 || q.shape(1) != r.rows.shape(1)) throw nb::value_error("'q' must have the rows' width");
            const size_t m = q.shape(0), k = q.shape(1);
            int64_t *out;
            auto found = new_index_array(m, &out);
            {
                nb::gil_scoped_release g;
                for (size_t i = 0; i < m; ++i) out[i] = r.lookup.find(q.data() + i * k);
            }
            return found;
        }, "q"_a, "(M,) int64: for each row of q the first equal row of x, or -1.");
    m.def("float32_unit_rows", [](InArray x, double slack) {
        const size_t n = check_points(x, 3, "x");
        const Float32Directions out(n);
        {
            nb::gil_scoped_release g;
            // each row's result is its own: chunks on all threads
            for_chunks(n, kCubatureChunk, [&](size_t, size_t a, size_t b, int) {
                float32_unit_rows(x.data(), a, b, n, slack, out.cols, out.flags);
            });
        }
        return out.result();
    }, "x"_a, "slack"_a,
       "(columns (3, N) float32, ok (N,)): rows x (N, 3) as float32 unit vectors (normalised first where their "
       "length is off 1 by more than `slack`); rows that are not finite non-zero vectors become +z, ok False.");
    // float32 columns as float64 rows: columns[j] points at column j's n values
    auto rows_of = [](const std::vector<const float *> &columns, size_t n) {
        double *out;
        OutArray rows = new_array(n, columns.size(), &out);
        {
            nb::gil_scoped_release g;
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                float64_rows(columns.data(), columns.size(), a, b, out);
            });
        }
        return rows;
    };
    m.def("float64_rows", [rows_of](nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu> columns) {
        const size_t c = columns.shape(0), n = columns.shape(1);
        if (c == 0) throw nb::value_error("'columns' must have at least one column (c, N), c >= 1");
        std::vector<const float *> at(c);
        for (size_t j = 0; j < c; ++j) at[j] = columns.data() + j * n;
        return rows_of(at, n);
    }, "columns"_a.noconvert(), "(N, c) float64: the float32 columns (c, N) as rows.");
    m.def("float64_rows_of", [rows_of](
              const std::vector<nb::ndarray<const float, nb::ndim<1>, nb::c_contig, nb::device::cpu>> &columns) {
        if (columns.empty()) throw nb::value_error("'columns' must hold at least one column");
        const size_t n = columns[0].shape(0);
        std::vector<const float *> at;
        for (const auto &column : columns) {
            if (column.shape(0) != n) throw nb::value_error("'columns' must all have the same length");
            at.push_back(column.data());
        }
        return rows_of(at, n);
    }, "columns"_a.noconvert(), "(N, c) float64: the c float32 columns (N,) each, as rows.");
    m.def("float32_columns", [](nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu> rows,
                                float cap) {
        const size_t n = rows.shape(0), c = rows.shape(1);
        if (c == 0) throw nb::value_error("'rows' must have at least one column (N, c), c >= 1");
        nb::capsule owner;
        float *out = output_buffer<float>(c * n, owner);   // reused memory, as float64_rows'
        nb::ndarray<nb::numpy, float> columns(out, {c, n}, owner);
        {
            nb::gil_scoped_release g;
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                float32_columns(rows.data(), c, n, a, b, cap, out);
            });
        }
        return columns;
    }, "rows"_a.noconvert(), "cap"_a, "(c, N) float32: the float64 rows (N, c) as columns, each value rounded to "
       "float32, then capped at `cap` (NaN kept).");
    m.def("take_rows", [](InArray x, BoolArray keep) {
        const size_t n = check_rows(x, keep), k = x.ndim() == 2 ? x.shape(1) : 1;
        // the flags as bytes: a numpy bool array may hold other values than 0 and 1 (a view of
        // uint8), which a bool read in C++ need not treat as true
        const uint8_t *flags = reinterpret_cast<const uint8_t *>(keep.data());
        size_t m = 0;
        for (size_t i = 0; i < n; ++i) m += flags[i] != 0;
        double *out;
        OutArray rows = new_array(m, x.ndim() == 2 ? k : 0, &out);
        {
            nb::gil_scoped_release g;
            // at most m rows, whatever another thread does to `keep` meanwhile
            with_row_width(k, [&](auto width) {
                compact_rows<decltype(width)::value>(x.data(), flags, n, k, m, out);
            });
        }
        return rows;
    }, "x"_a, "keep"_a, "The rows of x (N,) or (N, k) where keep, in order: x[keep].");
    m.def("nan_rows", [](InArray x, BoolArray keep) {
        const size_t n = check_rows(x, keep), k = x.ndim() == 2 ? x.shape(1) : 1;
        const uint8_t *flags = reinterpret_cast<const uint8_t *>(keep.data());   // bytes, as in take_rows
        double *out;
        OutArray rows = new_array(n, x.ndim() == 2 ? k : 0, &out);
        {
            nb::gil_scoped_release g;
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                with_row_width(k, [&](auto width) {
                    nan_rows<decltype(width)::value>(x.data() + a * k, flags + a, b - a, k, out + a * k);
                });
            });
        }
        return rows;
    }, "x"_a, "keep"_a, "x (N,) or (N, k) with the rows not kept NaN: where(keep[:, None], x, nan).");
    m.def("weight_agreement", [](InArray w, bool constant, InArray e, InArray p, double atol, double rtol) {
        if (e.ndim() != 2 || e.shape(1) == 0 || p.ndim() != 1 || p.size() != e.shape(0))
            throw nb::value_error("'e' must be (N, c), c >= 1, and 'p' (N,)");
        const size_t n = e.shape(0), c = e.shape(1);
        if (w.ndim() != 2 || w.shape(1) != c || w.shape(0) != (constant ? 1 : n))
            throw nb::value_error("'w' must be (N, c) as 'e', or (1, c) for one constant weight");
        bool *mismatch, *bad;
        auto ma = new_bool_array(n, &mismatch), ba = new_bool_array(n, &bad);
        const size_t chunks = (n + kCheckChunk - 1) / kCheckChunk;
        std::vector<double> most(chunks, 0.0);
        {
            nb::gil_scoped_release g;
            for_chunks(n, kCheckChunk, [&](size_t k, size_t a, size_t b, int) {
                most[k] = weight_agreement(w.data(), constant ? 0 : c, e.data(), p.data(), a, b, c, atol, rtol,
                                           mismatch, bad);
            });
        }
        double largest = 0.0;
        for (double v : most) largest = std::max(largest, v);
        return nb::make_tuple(ma, ba, largest);
    }, "w"_a, "constant"_a, "e"_a, "p"_a, "atol"_a, "rtol"_a,
       "(mismatch (N,), bad (N,), max_rel): the weight check of samples' weights w against e / p per channel.");
    m.def("produced_rows", [](InArray x, InArray p, bool weighted, InArray w, bool constant, bool flagged,
                              InArray delta) {
        if (x.ndim() != 2 || x.shape(1) != 3 || p.ndim() != 1 || p.size() != x.shape(0))
            throw nb::value_error("'x' must be (N, 3) and 'p' (N,)");
        const size_t n = x.shape(0);
        const size_t c = weighted && w.ndim() == 2 ? w.shape(1) : 0;
        if (weighted && (w.ndim() != 2 || c == 0 || w.shape(0) != (constant ? 1 : n)))
            throw nb::value_error("'weight' must be (N, c), c >= 1, or (1, c) for one constant weight");
        if (flagged && (delta.ndim() != 1 || delta.size() != n)) throw nb::value_error("'delta' must be (N,)");
        bool *ok;
        auto oa = new_bool_array(n, &ok);
        {
            nb::gil_scoped_release g;
            // each row's flag is its own: chunks on all threads
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                produced_rows(x.data(), p.data(), weighted ? w.data() : nullptr, constant ? 0 : c, c,
                              flagged ? delta.data() : nullptr, a, b, ok);
            });
        }
        return oa;
    }, "x"_a, "p"_a, "weighted"_a, "w"_a, "constant"_a, "flagged"_a, "delta"_a,
       "(N,) bool: x's row finite, p > 0, a channel of w not 0 (where weighted), delta 0 (where flagged).");
}

}  // namespace re::py
