// What every binding file of reference_estimators._core shares: the array types, new numpy
// arrays, the checks of array arguments and run options, and the conversions of estimates and
// accumulator states to Python dicts (bind_results.cpp).  The module itself is bindings.cpp;
// bind_checks.cpp binds the sampler check's kernels, bind_cubature.cpp its cubature's,
// bind_rows.cpp a renderer's rows and bind_results.cpp the accumulator states, tails and
// extremes.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <cstdint>
#include <sstream>
#include <string>
#include <vector>

#include "buffer_cache.h"
#include "check_domains.h"
#include "estimators.h"

namespace re::py {

namespace nb = nanobind;

using InArray = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;
using OutArray = nb::ndarray<nb::numpy, double>;

// Memory for `count` values of an output array, from the BufferCache, and the capsule that
// gives it back when numpy frees the array: the buffer's capacity sits in a header of
// kBufferHeader bytes before the values.
inline constexpr size_t kBufferHeader = 64;
template <class T>
T *output_buffer(size_t count, nb::capsule &owner) {
    size_t capacity;
    char *base = static_cast<char *>(BufferCache::instance().take(kBufferHeader + count * sizeof(T), capacity));
    *reinterpret_cast<size_t *>(base) = capacity;
    owner = nb::capsule(base + kBufferHeader, [](void *q) noexcept {
        char *b = static_cast<char *>(q) - kBufferHeader;
        BufferCache::instance().give(b, *reinterpret_cast<size_t *>(b));
    });
    return reinterpret_cast<T *>(base + kBufferHeader);
}

// A new numpy array that owns its memory: shape (rows,) when cols == 0, else (rows, cols).
inline OutArray new_array(size_t rows, size_t cols, double **data) {
    nb::capsule owner;
    double *p = output_buffer<double>(rows * (cols == 0 ? 1 : cols), owner);
    *data = p;
    if (cols == 0) return OutArray(p, {rows}, owner);
    return OutArray(p, {rows, cols}, owner);
}

// Points array: shape (n, dim), or (n,) when dim == 1.
inline size_t check_points(const InArray &x, int dim, const char *arg) {
    bool ok = (x.ndim() == 2 && x.shape(1) == size_t(dim)) || (dim == 1 && x.ndim() == 1);
    if (!ok) {
        std::ostringstream s;
        s << "'" << arg << "' must have shape (N, " << dim << ")" << (dim == 1 ? " or (N,)" : "") << ", got (";
        for (size_t i = 0; i < x.ndim(); ++i) s << (i ? ", " : "") << x.shape(i);
        s << ")";
        throw nb::value_error(s.str().c_str());
    }
    return x.shape(0);
}

// Canonical uniforms must lie in [0, 1]: the samplers' maps assume it (outside it a table
// sampler's search has no bin to land in).  A ValueError with the count and the first examples.
inline void check_uniforms(const InArray &u) {
    const double *v = u.data();
    const size_t total = u.size(), cols = u.ndim() == 2 ? u.shape(1) : 1;
    size_t bad = 0;
    std::ostringstream examples;
    examples.precision(17);
    for (size_t i = 0; i < total; ++i) {
        if (v[i] >= 0.0 && v[i] <= 1.0) continue;
        if (bad < 3) examples << (bad ? ", " : "") << "u[" << i / cols << "] = " << v[i];
        ++bad;
    }
    if (bad) {
        std::ostringstream s;
        s << "'u' must hold canonical uniforms in [0, 1]; " << bad << " of " << total << " values are not ("
          << examples.str() << (bad > 3 ? ", ..." : "") << ")";
        throw nb::value_error(s.str().c_str());
    }
}

// A new numpy array (n,) of T (bool, int64) that owns its memory.
template <class T>
nb::ndarray<nb::numpy, T> new_vector(size_t n, T **data) {
    nb::capsule owner;
    T *p = output_buffer<T>(n, owner);
    *data = p;
    return nb::ndarray<nb::numpy, T>(p, {n}, owner);
}
inline nb::ndarray<nb::numpy, bool> new_bool_array(size_t n, bool **data) { return new_vector(n, data); }
inline nb::ndarray<nb::numpy, int64_t> new_index_array(size_t n, int64_t **data) { return new_vector(n, data); }

// Direction columns (3, n) of float32 (row j C-contiguous), from reused memory (no page faults
// a call), and a bool array ok (n,): float32_unit_rows' result and the cubature's float32
// directions; `cols` and `flags` their memory.
struct Float32Directions {
    float *cols;
    bool *flags;
    nb::ndarray<nb::numpy, float> columns;
    nb::ndarray<nb::numpy, bool> ok;

    explicit Float32Directions(size_t n) {
        nb::capsule owner;
        cols = output_buffer<float>(3 * n, owner);
        columns = nb::ndarray<nb::numpy, float>(cols, {size_t(3), n}, owner);
        ok = new_bool_array(n, &flags);
    }
    nb::tuple result() const { return nb::make_tuple(columns, ok); }
};

// A new int64 numpy array (n,) holding `values` (row indices a kernel collected).
inline nb::ndarray<nb::numpy, int64_t> index_array(const std::vector<int64_t> &values) {
    int64_t *out;
    auto a = new_index_array(values.size(), &out);
    std::copy(values.begin(), values.end(), out);
    return a;
}

using I64Array = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using BoolArray = nb::ndarray<const bool, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using StridedArray = nb::ndarray<const double, nb::ndim<1>, nb::device::cpu>;

inline RunOptions options(uint64_t seed, uint64_t case_id, uint64_t replica, int threads, bool higher = true) {
    if (threads < 0) throw nb::value_error("'threads' must be >= 1 (or None for all cores)");
    RunOptions o;
    o.key = {seed, case_id, replica, 0};
    o.threads = threads;
    o.higher_moments = higher;
    return o;
}

inline void check_n(int64_t n) {
    if (n <= 0) throw nb::value_error(("'n' must be a positive number of samples, got " + std::to_string(n)).c_str());
}

// Estimates and accumulator states as Python dicts, and back (bind_results.cpp).
nb::dict diagnostics_dict(const Diagnostics &d);
nb::dict estimate_dict(const Estimate &e);
nb::dict state_dict(const Estimate &e);
Estimate state_from(const nb::dict &d);
nb::dict tails_dict(const ValueTails &t);

// A domain code 0 .. 5 as a CheckDomain, or a ValueError.
inline CheckDomain check_domain(int kind) {
    if (kind < 0 || kind > 5) throw nb::value_error("'kind' must be a domain code 0 .. 5");
    return CheckDomain(kind);
}

// The module's functions, by file.
void bind_checks(nb::module_ &m);
void bind_cubature(nb::module_ &m);
void bind_rows(nb::module_ &m);
void bind_results(nb::module_ &m);

}  // namespace re::py
