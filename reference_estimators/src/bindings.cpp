// Python bindings of the core (module reference_estimators._core).  Every batch function
// allocates its outputs, then releases the GIL for the computation.  Inputs are validated
// here too (shape, dimension), so no call can read out of bounds; the Python layer adds
// friendlier messages on top.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/map.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/shared_ptr.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <sys/mman.h>  // madvise: huge pages under big arrays

#include <cmath>
#include <memory>
#include <sstream>

#include "estimators.h"
#include "checks.h"
#include "extremes.h"
#include "fastmath.h"
#include "tables.h"
#include "thread_pool.h"

namespace nb = nanobind;
using namespace nb::literals;
using namespace re;

namespace {

using InArray = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;
using OutArray = nb::ndarray<nb::numpy, double>;

const char *kIssueNames[kIssueKinds] = {"nan",         "posinf",   "neginf",  "negative",
                                        "outside_domain", "zero_pdf", "bad_pdf", "bound_violation"};

// Asks the kernel for transparent huge pages under a new array of `bytes` from 4 MiB (what
// numpy does for its own arrays): a million 3-vectors are 24 MB, 6000 page faults of 4 KiB
// without it, 11 ms of this VM's time a fresh array (as long as the computation filling
// it), and 12 with it.  Only advice: where THP is off it changes nothing.
void advise_huge_pages(void *p, size_t bytes) {
    if (bytes < (size_t(1) << 22)) return;
    const uintptr_t first = (reinterpret_cast<uintptr_t>(p) + 4095) & ~uintptr_t(4095);
    const uintptr_t end = reinterpret_cast<uintptr_t>(p) + bytes;
    if (end > first) madvise(reinterpret_cast<void *>(first), end - first, MADV_HUGEPAGE);
}

// A new numpy array that owns its memory: shape (rows,) when cols == 0, else (rows, cols).
OutArray new_array(size_t rows, size_t cols, double **data) {
    size_t size = rows * (cols == 0 ? 1 : cols);
    double *p = new double[size > 0 ? size : 1];
    advise_huge_pages(p, size * sizeof(double));
    nb::capsule owner(p, [](void *q) noexcept { delete[] static_cast<double *>(q); });
    *data = p;
    if (cols == 0) return OutArray(p, {rows}, owner);
    return OutArray(p, {rows, cols}, owner);
}

// Points array: shape (n, dim), or (n,) when dim == 1.
size_t check_points(const InArray &x, int dim, const char *arg) {
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
void check_uniforms(const InArray &u) {
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

// A new numpy bool array of n values that owns its memory.
nb::ndarray<nb::numpy, bool> new_bool_array(size_t n, bool **data) {
    bool *p = new bool[n > 0 ? n : 1];
    advise_huge_pages(p, n);
    nb::capsule owner(p, [](void *q) noexcept { delete[] static_cast<bool *>(q); });
    *data = p;
    return nb::ndarray<nb::numpy, bool>(p, {n}, owner);
}

using I64Array = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using BoolArray = nb::ndarray<const bool, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using StridedArray = nb::ndarray<const double, nb::ndim<1>, nb::device::cpu>;

CheckDomain check_domain(int kind) {
    if (kind < 0 || kind > 5) throw nb::value_error("'kind' must be a domain code 0 .. 5");
    return CheckDomain(kind);
}

// Parameter points s: shape (n, k), or (n,) when k == 1.
size_t check_params(const InArray &s, size_t k) {
    if (!((s.ndim() == 2 && s.shape(1) == k) || (k == 1 && s.ndim() == 1)))
        throw nb::value_error(k == 1 ? "'s' must have shape (N, 1) or (N,)" : "'s' must have shape (N, 2)");
    return s.shape(0);
}

// Boxes [lo, hi]: both of shape (M, 1) or (M, 2); returns k.
size_t check_boxes(const InArray &lo, const InArray &hi) {
    if (lo.ndim() != 2 || hi.ndim() != 2 || lo.shape(0) != hi.shape(0) || lo.shape(1) != hi.shape(1) ||
        (lo.shape(1) != 1 && lo.shape(1) != 2))
        throw nb::value_error("'lo' and 'hi' must both have shape (M, 1) or (M, 2)");
    return lo.shape(1);
}

// The shape a piecewise-linear table's arrays must have (one lo, hi, start and mass per leaf;
// offsets from 0 to the leaves, not decreasing), or a ValueError saying what is wrong.
template <class Offsets>
static void check_table(const InArray &lo, const InArray &hi, const InArray &start, const InArray &mass,
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

nb::dict diagnostics_dict(const Diagnostics &d) {
    nb::dict counts;
    for (int k = 0; k < kIssueKinds; ++k) counts[kIssueNames[k]] = d.counts[k];
    nb::list examples;
    for (auto &e : d.examples) {
        nb::dict ex;
        ex["issue"] = kIssueNames[e.kind];
        ex["index"] = e.index;
        nb::list pt;
        for (int j = 0; j < e.dim; ++j) pt.append(e.point[j]);
        ex["point"] = nb::tuple(pt);
        ex["value"] = e.value;
        examples.append(ex);
    }
    nb::dict r;
    r["counts"] = counts;
    r["examples"] = examples;
    r["drawn"] = d.drawn;
    r["candidates"] = d.candidates;
    return r;
}

// Final figures from an accumulator state; scale-free ones computed before unscaling, so
// magnitudes near 1e+-300 report a finite standard error.
nb::dict estimate_dict(const Estimate &e) {
    const Moments &m = e.moments;
    const int E = m.scale_exp;
    const double n = m.n, nan = std::nan("");
    double var_s = n > 1 ? m.m2 / (n - 1) : nan;
    nb::dict r = diagnostics_dict(e.diagnostics);
    r["n"] = uint64_t(n);
    r["mean"] = n > 0 ? std::ldexp(m.total.value() / n, E) : nan;
    r["variance"] = std::ldexp(var_s, 2 * E);
    r["stderr"] = n > 1 ? std::ldexp(std::sqrt(var_s / n), E) : nan;
    r["log10_variance"] = var_s > 0 ? std::log10(var_s) + 2 * E * std::log10(2.0) : (var_s == 0 ? -INFINITY : nan);
    r["skewness"] = m.m2 > 0 ? std::sqrt(n) * m.m3 / std::pow(m.m2, 1.5) : nan;
    r["kurtosis"] = m.m2 > 0 ? n * m.m4 / (m.m2 * m.m2) : nan;
    r["min"] = n > 0 ? std::ldexp(m.min, E) : nan;
    r["max"] = n > 0 ? std::ldexp(m.max, E) : nan;
    r["seconds"] = e.seconds;
    r["chunks"] = e.chunks;
    r["threads"] = e.threads;
    r["busy"] = nb::tuple(nb::cast(e.busy));
    return r;
}

// The whole accumulator state, for storage: every field, so a state read back merges to
// exactly the bits a fresh computation gives.
nb::dict state_dict(const Estimate &e) {
    const Moments &m = e.moments;
    nb::dict d;
    d["n"] = m.n; d["mean"] = m.mean; d["m2"] = m.m2; d["m3"] = m.m3; d["m4"] = m.m4;
    d["sum"] = m.total.sum; d["comp"] = m.total.comp; d["min"] = m.min; d["max"] = m.max;
    d["scale_exp"] = m.scale_exp; d["scale_set"] = m.scale_set;
    nb::list counts;
    for (int k = 0; k < kIssueKinds; ++k) counts.append(e.diagnostics.counts[k]);
    d["counts"] = counts;
    nb::list ex;
    for (auto &x : e.diagnostics.examples)
        ex.append(nb::make_tuple(x.kind, x.index, x.point[0], x.point[1], x.point[2], x.dim, x.value));
    d["examples"] = ex;
    d["drawn"] = e.diagnostics.drawn; d["candidates"] = e.diagnostics.candidates;
    d["seconds"] = e.seconds; d["chunks"] = e.chunks; d["threads"] = e.threads;
    return d;
}

nb::dict side_dict(const SideExtremes &e) {
    nb::dict d;
    d["peak"] = e.peak;
    d["ties"] = e.ties;
    d["below"] = nb::cast(e.below);
    return d;
}

SideExtremes side_from(const nb::handle &h) {
    nb::dict d = nb::cast<nb::dict>(h);
    SideExtremes e;
    e.peak = d["peak"].is_none() ? std::nan("") : nb::cast<double>(d["peak"]);
    e.ties = nb::cast<uint64_t>(d["ties"]);
    e.below = nb::cast<std::vector<double>>(d["below"]);
    return e;
}

// A contributions' tails (value_tails) as plain numbers and lists: JSON-serialisable (a NaN
// peak or median as None).
nb::dict tails_dict(const ValueTails &t) {
    nb::dict d;
    d["upper"] = side_dict(t.upper);
    d["lower"] = side_dict(t.lower);
    for (nb::dict s : {nb::dict(d["upper"]), nb::dict(d["lower"])})
        if (std::isnan(nb::cast<double>(s["peak"]))) s["peak"] = nb::none();
    d["median"] = std::isnan(t.median) ? nb::none() : nb::cast(t.median);
    return d;
}

ValueTails tails_from(const nb::dict &d) {
    ValueTails t;
    t.upper = side_from(d["upper"]);
    t.lower = side_from(d["lower"]);
    t.median = d["median"].is_none() ? std::nan("") : nb::cast<double>(d["median"]);
    return t;
}

Estimate state_from(const nb::dict &d) {
    Estimate e;
    Moments &m = e.moments;
    m.n = nb::cast<double>(d["n"]); m.mean = nb::cast<double>(d["mean"]);
    m.m2 = nb::cast<double>(d["m2"]); m.m3 = nb::cast<double>(d["m3"]); m.m4 = nb::cast<double>(d["m4"]);
    m.total.sum = nb::cast<double>(d["sum"]); m.total.comp = nb::cast<double>(d["comp"]);
    m.min = nb::cast<double>(d["min"]); m.max = nb::cast<double>(d["max"]);
    m.scale_exp = nb::cast<int>(d["scale_exp"]); m.scale_set = nb::cast<bool>(d["scale_set"]);
    std::vector<uint64_t> counts = nb::cast<std::vector<uint64_t>>(d["counts"]);
    if (counts.size() != size_t(kIssueKinds)) throw nb::value_error("state: 'counts' has the wrong length");
    for (int k = 0; k < kIssueKinds; ++k) e.diagnostics.counts[k] = counts[k];
    for (nb::handle h : nb::iter(d["examples"])) {  // tuples, or lists after a JSON round trip
        nb::object t = nb::borrow(h);
        Example x;
        x.kind = nb::cast<int>(t[0]); x.index = nb::cast<uint64_t>(t[1]);
        x.point[0] = nb::cast<double>(t[2]); x.point[1] = nb::cast<double>(t[3]); x.point[2] = nb::cast<double>(t[4]);
        x.dim = nb::cast<int>(t[5]); x.value = nb::cast<double>(t[6]);
        e.diagnostics.examples.push_back(x);
    }
    e.diagnostics.drawn = nb::cast<uint64_t>(d["drawn"]);
    e.diagnostics.candidates = nb::cast<uint64_t>(d["candidates"]);
    e.seconds = nb::cast<double>(d["seconds"]); e.chunks = nb::cast<uint64_t>(d["chunks"]);
    e.threads = nb::cast<int>(d["threads"]);
    return e;
}

RunOptions options(uint64_t seed, uint64_t case_id, uint64_t replica, int threads, bool higher = true) {
    if (threads < 0) throw nb::value_error("'threads' must be >= 1 (or None for all cores)");
    RunOptions o;
    o.key = {seed, case_id, replica, 0};
    o.threads = threads;
    o.higher_moments = higher;
    return o;
}

void check_n(int64_t n) {
    if (n <= 0) throw nb::value_error(("'n' must be a positive number of samples, got " + std::to_string(n)).c_str());
}

const char *technique_kind(TechniqueKind k) {
    switch (k) {
        case TechniqueKind::Uniform: return "uniform";
        case TechniqueKind::Importance: return "importance";
        case TechniqueKind::HitOrMiss: return "rejection";
        case TechniqueKind::RussianRoulette: return "russian_roulette";
        case TechniqueKind::Splitting: return "splitting";
        case TechniqueKind::Mis: return "mis";
        case TechniqueKind::SelfNormalized: return "self_normalized";
    }
    return "?";
}

PointSetKind point_set(const std::string &name) {
    if (name == "random") return PointSetKind::Random;
    if (name == "stratified") return PointSetKind::Stratified;
    if (name == "sobol") return PointSetKind::Sobol;
    throw nb::value_error(("'points' must be 'random', 'stratified' or 'sobol', got '" + name + "'").c_str());
}

}  // namespace

NB_MODULE(_core, m) {
    m.doc() = "C++ core of the reference estimators: PCG32 chunk streams, accumulators, samplers, integrands.";
    m.attr("CHUNK_SIZE") = kChunkSize;
    m.attr("ISSUES") = nb::make_tuple("nan", "posinf", "neginf", "negative", "outside_domain", "zero_pdf", "bad_pdf",
                                      "bound_violation");
    m.def("hardware_threads", &ThreadPool::default_threads);
    m.def("build_info", [] {
        nb::dict d;
        d["isa"] = simd::kIsa;  // what the kernels were compiled for: no runtime dispatch
        d["vector_doubles"] = simd::kWidth;
        d["rng_lanes"] = LaneGenerator::kLanes;
        d["march"] = RE_MARCH;
        d["compiler"] = __VERSION__;
        d["chunk_size"] = kChunkSize;
        __builtin_cpu_init();
        d["cpu_isa"] = __builtin_cpu_supports("avx512f") ? "AVX-512"
                       : (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) ? "AVX2+FMA"
                       : __builtin_cpu_supports("avx") ? "AVX" : "SSE2";
        return d;
    }, "How the core was built (ISA, vector width, -march, compiler) and the best ISA this CPU supports.");

    nb::class_<Integrand>(m, "Integrand")
        .def_ro("name", &Integrand::name)
        .def_ro("description", &Integrand::description)
        .def_ro("reference", &Integrand::reference)
        .def_ro("nonnegative", &Integrand::nonnegative)
        .def_prop_ro("domain", [](const Integrand &f) { return f.domain.kind_name(); })
        .def_prop_ro("dim", [](const Integrand &f) { return f.domain.dim; })
        .def_prop_ro("measure", [](const Integrand &f) { return f.domain.measure(); })
        .def_prop_ro("bounds", [](const Integrand &f) { return std::make_pair(f.domain.lo, f.domain.hi); })
        .def("eval", [](const Integrand &f, InArray x) {
            size_t n = check_points(x, f.domain.dim, "x");
            double *out;
            OutArray r = new_array(n, 0, &out);
            {
                nb::gil_scoped_release g;
                f.eval(x.data(), out, n);
            }
            return r;
        }, "x"_a, "f(x) for points of shape (N, dim); 0 outside the domain.")
        .def("__repr__", [](const Integrand &f) { return "<Integrand " + f.name + " on " + f.domain.kind_name() + ">"; });

    nb::class_<Sampler>(m, "Sampler")
        .def_ro("name", &Sampler::name)
        .def_ro("params", &Sampler::params)
        .def_ro("udim", &Sampler::udim)
        .def_ro("invertible", &Sampler::invertible)
        .def_prop_ro("method", [](const Sampler &s) { return s.method == SamplingMethod::Inversion ? "inversion" : "rejection"; })
        .def_prop_ro("domain", [](const Sampler &s) { return s.domain.kind_name(); })
        .def_prop_ro("dim", [](const Sampler &s) { return s.domain.dim; })
        .def("describe", &Sampler::describe)
        .def("sample", [](const Sampler &s, InArray u) {
            size_t n = check_points(u, s.udim, "u");
            check_uniforms(u);
            double *x, *p;
            OutArray xs = new_array(n, s.domain.dim == 1 ? 0 : s.domain.dim, &x);
            OutArray ps = new_array(n, 0, &p);
            {
                nb::gil_scoped_release g;
                s.sample(u.data(), x, p, n);
            }
            return nb::make_tuple(xs, ps);
        }, "u"_a)
        .def("pdf", [](const Sampler &s, InArray x) {
            size_t n = check_points(x, s.domain.dim, "x");
            double *p;
            OutArray ps = new_array(n, 0, &p);
            {
                nb::gil_scoped_release g;
                s.pdf(x.data(), p, n);
            }
            return ps;
        }, "x"_a)
        .def("invert", [](const Sampler &s, InArray x) {
            size_t n = check_points(x, s.domain.dim, "x");
            double *u;
            OutArray us = new_array(n, s.udim == 1 ? 0 : s.udim, &u);
            {
                nb::gil_scoped_release g;
                s.invert(x.data(), u, n);
            }
            return us;
        }, "x"_a)
        .def("draw", [](const Sampler &s, int64_t n, uint64_t seed, uint64_t case_id, uint64_t replica, int threads) {
            check_n(n);
            RunOptions o = options(seed, case_id, replica, threads);
            double *x, *p;
            OutArray xs = new_array(size_t(n), s.domain.dim == 1 ? 0 : s.domain.dim, &x);
            OutArray ps = new_array(size_t(n), 0, &p);
            Diagnostics d;
            {
                nb::gil_scoped_release g;
                d = draw_samples(s, uint64_t(n), o, x, p);
            }
            return nb::make_tuple(xs, ps, diagnostics_dict(d));
        }, "n"_a, "seed"_a = 0, "case_id"_a = 0, "replica"_a = 0, "threads"_a = 0)
        .def("__repr__", [](const Sampler &s) { return "<Sampler " + s.describe() + ">"; });

    nb::class_<Technique>(m, "Technique")
        .def_ro("name", &Technique::name)
        .def_ro("sampler", &Technique::sampler)
        .def_ro("bound", &Technique::bound)
        .def_ro("note", &Technique::note)
        .def_prop_ro("kind", [](const Technique &t) { return technique_kind(t.kind); })
        .def_prop_ro("points", [](const Technique &t) { return point_set_name(t.points); })
        .def_prop_ro("iid", [](const Technique &t) { return t.points == PointSetKind::Random; },
                     "contributions are independent (random points): the per-sample variance gives the error")
        .def_ro("biased", &Technique::biased)
        .def_ro("mis", &Technique::mis)
        .def_prop_ro("evaluations", &Technique::evaluations)
        .def("udim", [](const Technique &t, const Integrand &f) { return t.udim(f); }, "integrand"_a)
        .def_prop_ro("finite_variance", [](const Technique &t) -> nb::object {
            if (t.finite_variance < 0) return nb::none();
            return nb::bool_(t.finite_variance == 1);
        })
        .def("__repr__", [](const Technique &t) { return "<Technique " + t.name + " (" + t.sampler->describe() + ")>"; });

    m.def("catalogue", [] {
        std::vector<std::pair<IntegrandPtr, std::vector<Technique>>> r;
        for (auto &e : catalogue()) r.emplace_back(e.integrand, e.techniques);
        return r;
    });
    m.def("sampler_registry", [] {
        nb::list r;
        for (auto &i : sampler_registry()) {
            nb::dict d;
            d["name"] = i.name; d["method"] = i.method; d["domain"] = i.domain; d["description"] = i.description;
            nb::dict p;
            for (auto &[k, v] : i.params) p[k.c_str()] = v;
            d["params"] = p;
            d["needs_table"] = i.needs_table;
            r.append(d);
        }
        return r;
    });
    m.def("make_sampler", [](const std::string &name, const std::map<std::string, double> &params, nb::object table) {
        std::vector<double> values;
        std::vector<size_t> shape;
        if (!table.is_none()) {
            InArray t = nb::cast<InArray>(table);
            values.assign(t.data(), t.data() + t.size());
            for (size_t i = 0; i < t.ndim(); ++i) shape.push_back(t.shape(i));
        }
        return make_sampler(name, params, values, shape);
    }, "name"_a, "params"_a, "table"_a = nb::none());
    m.def("make_rejection_sampler", &make_rejection_sampler, "target"_a, "proposal"_a, "c"_a);
    m.def("make_uniform_sampler", [](const Integrand &f) { return make_uniform_sampler(f.domain); }, "integrand"_a);
    m.def("uniform_technique", [](const Integrand &f) { return make_uniform_technique(f.domain); }, "integrand"_a);
    m.def("importance_technique", &make_importance_technique, "sampler"_a);
    m.def("hit_or_miss_technique", &make_hit_or_miss_technique, "proposal"_a, "c"_a);
    m.def("russian_roulette_technique", &make_russian_roulette_technique, "sampler"_a, "q"_a, "c"_a, "reweight"_a);
    m.def("splitting_technique", [](const Integrand &f, int m) { return make_splitting_technique(f.domain, m); },
          "integrand"_a, "m"_a);
    m.def("mis_technique", &make_mis_technique, "samplers"_a, "power"_a);
    m.def("self_normalized_technique", &make_self_normalized_technique, "sampler"_a, "batch"_a);
    m.def("with_points", [](const Technique &t, const std::string &points) { return with_points(t, point_set(points)); },
          "technique"_a, "points"_a);
    m.def("with_clamp", &with_clamp, "technique"_a, "clamp"_a);
    m.def("check_technique", &check_technique, "integrand"_a, "technique"_a);
    m.def("set_sobol_directions", [](nb::ndarray<const uint32_t, nb::ndim<2>, nb::c_contig, nb::device::cpu> v) {
        if (v.shape(1) != 32) throw nb::value_error("Sobol' direction numbers must have shape (dims, 32)");
        SobolDirections &d = sobol_directions();
        d.v.assign(v.data(), v.data() + v.size());
        d.dims = int(v.shape(0));
    }, "directions"_a, "Direction numbers v[d, k] (bit k of the index, 32-bit), set once at import.");
    m.def("points", [](int64_t n, int dim, const std::string &kind, uint64_t seed, uint64_t case_id, uint64_t replica,
                       int threads, uint64_t chunk_begin, uint64_t chunk_end) {
        check_n(n);
        if (dim < 1) throw nb::value_error("'dim' must be >= 1");
        PointSetContext ctx;
        ctx.kind = point_set(kind);
        ctx.n = uint64_t(n);
        ctx.key = {seed, case_id, replica, 0};
        const uint64_t nc = (uint64_t(n) + kChunkSize - 1) / kChunkSize;
        const uint64_t c0 = std::min(chunk_begin, nc), c1 = std::min(chunk_end, nc);
        if (c0 >= c1) throw nb::value_error("'chunk_begin' must be below 'chunk_end' and the chunk count");
        const uint64_t offset = c0 * kChunkSize, rows = std::min(c1 * kChunkSize, uint64_t(n)) - offset;
        double *u;
        OutArray r = new_array(size_t(rows), size_t(dim), &u);
        {
            nb::gil_scoped_release g;
            ThreadPool::instance().run(c1 - c0, threads > 0 ? threads : ThreadPool::default_threads(), [&](size_t i, int) {
                uint64_t c = c0 + i;
                UniformStream stream({seed, case_id, replica, c});
                uint64_t first = c * kChunkSize, count = std::min<uint64_t>(kChunkSize, uint64_t(n) - first);
                fill_points(ctx, stream, first, count, dim, u + (first - offset) * dim);
            });
        }
        return r;
    }, "n"_a, "dim"_a, "kind"_a = "random", "seed"_a = 0, "case_id"_a = 0, "replica"_a = 0, "threads"_a = 0,
       "chunk_begin"_a = 0, "chunk_end"_a = UINT64_MAX,
       "Canonical points of chunks [chunk_begin, chunk_end) of an estimate of n samples (all of them by default): "
       "exactly what a technique with this point set consumes.");
    m.def("accumulate_chunk", [](InArray y, uint64_t first, nb::object points) {
        if (y.ndim() != 1) throw nb::value_error("'values' must be one-dimensional");
        const double *u = nullptr;
        int ud = 0;
        InArray pts;
        if (!points.is_none()) {
            pts = nb::cast<InArray>(points);
            if (pts.ndim() != 2 || pts.shape(0) != y.shape(0))
                throw nb::value_error("'points' must have shape (N, dim), one row per value");
            u = pts.data();
            ud = int(pts.shape(1));
        }
        Estimate e;
        {
            nb::gil_scoped_release g;
            e = accumulate_chunk(y.data(), y.shape(0), first, u, ud);
        }
        return state_dict(e);
    }, "values"_a, "first"_a = 0, "points"_a = nb::none(),
       "The accumulator state of one chunk of given contributions (samples first.. of an estimate).");
    m.def("tabulated_integrand", [](InArray v, double a, double b) {
        return make_tabulated_integrand(std::vector<double>(v.data(), v.data() + v.size()), a, b);
    }, "values"_a, "a"_a, "b"_a);

    auto check_pair = [](const Integrand &f, const Technique &t) { check_technique(f, t); };
    m.def("integrate", [check_pair](const Integrand &f, const Technique &t, int64_t n, uint64_t seed, uint64_t case_id,
                                    uint64_t replica, int threads, bool higher_moments) {
        check_n(n);
        check_pair(f, t);
        RunOptions o = options(seed, case_id, replica, threads, higher_moments);
        Estimate e;
        {
            nb::gil_scoped_release g;
            e = integrate(f, t, uint64_t(n), o);
        }
        return estimate_dict(e);
    }, "integrand"_a, "technique"_a, "n"_a, "seed"_a = 0, "case_id"_a = 0, "replica"_a = 0, "threads"_a = 0,
       "higher_moments"_a = true);
    m.def("side_extremes", [](InArray y, double center, bool upper, int64_t keep) {
        if (y.ndim() != 1) throw nb::value_error("'values' must be one-dimensional");
        if (keep < 0) throw nb::value_error("'keep' must be >= 0");
        SideExtremes s;
        {
            nb::gil_scoped_release g;
            s = side_extremes(y.data(), y.size(), center, upper, size_t(keep));
        }
        double *out;
        OutArray below = new_array(s.below.size(), 0, &out);
        std::copy(s.below.begin(), s.below.end(), out);
        return nb::make_tuple(s.peak, s.ties, below);
    }, "values"_a, "center"_a, "upper"_a, "keep"_a,
       "(peak, ties, below): the largest positive deviation y - center (upper) or center - y (lower), how many "
       "equal it, and the `keep` largest strictly below it, descending; peak NaN if none is positive.");
    m.def("domain_params", [](int kind, double lo, double hi, InArray x) {
        const CheckDomain d = check_domain(kind);
        const int pdim = domain_point_dim(d), k = domain_param_dim(d);
        const size_t n = check_points(x, pdim, "x");
        double *s;
        bool *inside;
        OutArray sa = new_array(n, size_t(k), &s);
        auto ia = new_bool_array(n, &inside);
        {
            nb::gil_scoped_release g;
            // each point's parameters depend on that point alone (the azimuths' vector and
            // scalar paths give the same bits): chunks on all threads
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
                domain_params(d, lo, hi, x.data() + a * size_t(pdim), b - a, s + a * size_t(k), inside + a);
            });
        }
        return nb::make_tuple(sa, ia);
    }, "kind"_a, "lo"_a, "hi"_a, "x"_a,
       "(s (N, k), inside (N,)): the equal-measure parameters of points x on domain `kind` "
       "(0 interval [lo, hi], 1 half line, 2 square, 3 disk, 4 hemisphere, 5 sphere).");
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
        const size_t n = check_points(h, 3, "h");
        if (axis.size() != 3 || t.size() != 3 || b.size() != 3)
            throw nb::value_error("'axis', 't' and 'b' must be 3-vectors");
        double *out;
        OutArray wa = new_array(n, 3, &out);
        {
            nb::gil_scoped_release g;
            // each row from that row alone: chunks on all threads
            for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t e, int) {
                cap_to_world(h.data() + 3 * a, e - a, axis.data(), t.data(), b.data(), cos_alpha, scale, out + 3 * a);
            });
        }
        return wa;
    }, "h"_a, "axis"_a, "t"_a, "b"_a, "cos_alpha"_a, "scale"_a,
       "World directions (N, 3) of hemisphere points h (N, 3) through the equal-area map of the cap about `axis` "
       "(frame t, b, axis) with cosine `cos_alpha`, scale = 1 - cos_alpha.");
    m.def("float32_unit_rows", [](InArray x, double slack) {
        const size_t n = check_points(x, 3, "x");
        float *cols = new float[n > 0 ? 3 * n : 1];
        nb::capsule owner(cols, [](void *q) noexcept { delete[] static_cast<float *>(q); });
        nb::ndarray<nb::numpy, float> ca(cols, {size_t(3), n}, owner);
        bool *ok;
        auto oa = new_bool_array(n, &ok);
        {
            nb::gil_scoped_release g;
            float32_unit_rows(x.data(), n, slack, cols, ok);
        }
        return nb::make_tuple(ca, oa);
    }, "x"_a, "slack"_a,
       "(columns (3, N) float32, ok (N,)): rows x (N, 3) as float32 unit vectors (normalised first where their "
       "length is off 1 by more than `slack`); rows that are not finite non-zero vectors become +z, ok False.");
    m.def("cubature_nodes", [](InArray lo, InArray hi, InArray nodes) {
        const size_t k = check_boxes(lo, hi), boxes = lo.shape(0), g = nodes.size();
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
    m.def("cubature_points", [](int kind, double dlo, double dhi, InArray lo, InArray hi, InArray nodes) {
        const CheckDomain d = check_domain(kind);
        const size_t k = check_boxes(lo, hi), g = nodes.size(), per = k == 1 ? g : g * g;
        if (size_t(domain_param_dim(d)) != k) throw nb::value_error("the boxes' dimension is not the domain's");
        const int pdim = domain_point_dim(d);
        const size_t boxes = lo.shape(0);
        double *x;
        OutArray xa = new_array(boxes * per, pdim == 1 ? 0 : size_t(pdim), &x);
        {
            nb::gil_scoped_release r;
            // each box's points from that box alone: chunks of boxes on all threads (quarter
            // chunks: a cubature's blocks of 2^16 nodes would otherwise run on one)
            for_chunks(boxes, std::max<size_t>(kCheckChunk / 4 / per, 1), [&](size_t, size_t a, size_t b, int) {
                thread_local std::vector<double> scratch;
                cubature_points(d, dlo, dhi, lo.data() + a * k, hi.data() + a * k, b - a, k, nodes.data(), g,
                                x + a * per * size_t(pdim), scratch);
            });
        }
        return xa;
    }, "kind"_a, "dlo"_a, "dhi"_a, "lo"_a, "hi"_a, "nodes"_a,
       "Domain points of the tensor rule's nodes on the boxes [lo, hi] (M, k): domain_points(cubature_nodes(...)).");
    m.def("cubature_sums", [](InArray lo, InArray hi, InArray values, InArray weights, double scale) {
        const size_t k = check_boxes(lo, hi), boxes = lo.shape(0), per = weights.size();
        const size_t cols = values.ndim() == 2 ? values.shape(1) : 1;
        if ((values.ndim() != 1 && values.ndim() != 2) || values.shape(0) != boxes * per)
            throw nb::value_error("'values' must have one row per node: shape (M g^k,) or (M g^k, m)");
        double *out;
        OutArray oa = new_array(boxes, cols, &out);
        {
            nb::gil_scoped_release r;
            for_chunks(boxes, std::max<size_t>(kCheckChunk / per, 1), [&](size_t, size_t a, size_t b, int) {
                cubature_sums(lo.data() + a * k, hi.data() + a * k, b - a, k, values.data() + a * per * cols, cols,
                              weights.data(), per, scale, out + a * cols);
            });
        }
        return oa;
    }, "lo"_a, "hi"_a, "values"_a, "weights"_a, "scale"_a,
       "(M, m) integrals of the tensor rule on the boxes [lo, hi] (M, k): the weighted sum of the values "
       "(M g^k, m) at their nodes times the volume, times `scale`.");
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
        int64_t *g = new int64_t[n > 0 ? n : 1];
        nb::capsule owner(g, [](void *q) noexcept { delete[] static_cast<int64_t *>(q); });
        nb::ndarray<nb::numpy, int64_t> strip(g, {n}, owner);
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
            // a column on each thread: the sums do not depend on which thread computed them
            ThreadPool::instance().run(k, ThreadPool::default_threads(), [&](size_t c, int) {
                const CramerVonMisesSum s =
                    cramer_von_mises_sum(u.data() + c * size_t(u.stride(1)), size_t(u.stride(0)), n);
                r[2 * c] = s.upper, r[2 * c + 1] = s.slack;
            });
        }
        return sums;
    }, "u"_a, "For each column of u (N, k), (upper, slack) with upper >= S >= upper - slack, S = "
       "sum_i ((2 i - 1) / (2 N) - u_(i))^2 over its sorted values; NaN for a column holding a NaN.");
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
    m.def("pdf_summary", [](int kind, double measure, InArray s, BoolArray inside, InArray p, double c) {
        const CheckDomain d = check_domain(kind);
        const size_t n = check_params(s, size_t(domain_param_dim(d)));
        if (inside.size() != n || p.size() != n) throw nb::value_error("'inside' and 'p' must have one value per point");
        PdfSummary r;
        {
            nb::gil_scoped_release g;
            r = pdf_summary(d, measure, s.data(), inside.data(), p.data(), n, c);
        }
        return nb::make_tuple(r.bad, r.zero, r.used, r.h_sum);
    }, "kind"_a, "measure"_a, "s"_a, "inside"_a, "p"_a, "c"_a,
       "(bad, zero, used, h_sum): pdf values NaN/infinite/negative, zero at inside points, good inside ones, "
       "and the sum of h = p J / (p J + c) over those.");
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
    m.def("profile_stages", [check_pair](const Integrand &f, const Technique &t, int64_t n, uint64_t seed, int threads) {
        check_n(n);
        check_pair(f, t);
        RunOptions o = options(seed, 0, 0, threads);
        StageTimes st;
        {
            nb::gil_scoped_release g;
            st = profile_stages(f, t, uint64_t(n), o);
        }
        nb::dict d;
        d["points"] = st.points;
        d["sampled"] = st.sampled;
        d["screened"] = st.screened;
        d["weighted"] = st.weighted;
        d["contributions"] = st.contributions;
        d["estimate"] = estimate_dict(st.estimate);
        return d;
    }, "integrand"_a, "technique"_a, "n"_a, "seed"_a = 0, "threads"_a = 0,
       "Seconds of the pipeline's prefixes (points; sampled, screened, weighted (NaN where the technique "
       "has no such stage); contributions; the whole estimate) on the same chunks.");
    m.def("integrate_chunks", [check_pair](const Integrand &f, const Technique &t, int64_t n, uint64_t seed,
                                           uint64_t case_id, uint64_t replica, uint64_t chunk_begin, uint64_t chunk_end,
                                           int threads, int64_t tail_keep, bool tail_median) {
        check_n(n);
        check_pair(f, t);
        if (tail_keep < 0) throw nb::value_error("'tail_keep' must be >= 0");
        RunOptions o = options(seed, case_id, replica, threads);
        o.chunk_begin = chunk_begin;
        o.chunk_end = chunk_end;
        o.tail_keep = size_t(tail_keep);
        o.tail_median = tail_median;
        Estimate e;
        {
            nb::gil_scoped_release g;
            e = integrate(f, t, uint64_t(n), o);
        }
        nb::dict d = state_dict(e);
        if (tail_keep > 0) d["tails"] = tails_dict(e.tails);
        return d;
    }, "integrand"_a, "technique"_a, "n"_a, "seed"_a, "case_id"_a, "replica"_a, "chunk_begin"_a, "chunk_end"_a,
       "threads"_a = 0, "tail_keep"_a = 0, "tail_median"_a = false,
       "The accumulator state of chunks [chunk_begin, chunk_end) of an estimate of n samples (with tail_keep > 0 "
       "also the contributions' tails, key 'tails').");
    m.def("value_tails", [](InArray y, int64_t keep, bool median) {
        if (y.ndim() != 1) throw nb::value_error("'values' must be one-dimensional");
        if (keep < 0) throw nb::value_error("'keep' must be >= 0");
        ValueTails t;
        {
            nb::gil_scoped_release g;
            t = value_tails(y.data(), y.size(), size_t(keep), median);
        }
        return tails_dict(t);
    }, "values"_a, "keep"_a, "median"_a = false,
       "The tails of values (NaN ignored): {'upper', 'lower': {'peak', 'ties', 'below'}, 'median'}.");
    m.def("merge_tails", [](const std::vector<nb::dict> &parts, int64_t keep) {
        if (keep < 0) throw nb::value_error("'keep' must be >= 0");
        std::vector<ValueTails> ts;
        ts.reserve(parts.size());
        for (auto &d : parts) ts.push_back(tails_from(d));
        ValueTails t;
        {
            nb::gil_scoped_release g;
            t = merge_tails(ts, size_t(keep));
        }
        return tails_dict(t);
    }, "parts"_a, "keep"_a, "The tails of the union of the parts' values, merged in the order given.");
    m.def("merge_states", [](const std::vector<nb::dict> &states) {
        std::vector<Estimate> parts;
        for (auto &d : states) parts.push_back(state_from(d));
        return state_dict(merge_estimates(parts));
    }, "states"_a, "Merge states in the order given.");
    m.def("estimate_from_state", [](const nb::dict &state) { return estimate_dict(state_from(state)); }, "state"_a);
    m.def("contributions", [check_pair](const Integrand &f, const Technique &t, int64_t n, uint64_t seed,
                                        uint64_t case_id, uint64_t replica, int threads) {
        check_n(n);
        check_pair(f, t);
        RunOptions o = options(seed, case_id, replica, threads);
        double *y;
        OutArray r = new_array(size_t(n), 0, &y);
        {
            nb::gil_scoped_release g;
            contributions(f, t, uint64_t(n), o, y);
        }
        return r;
    }, "integrand"_a, "technique"_a, "n"_a, "seed"_a = 0, "case_id"_a = 0, "replica"_a = 0, "threads"_a = 0);
    m.def("accumulate", [](InArray y, int threads, bool higher_moments) {
        if (y.ndim() != 1) throw nb::value_error("'values' must be one-dimensional");
        RunOptions o = options(0, 0, 0, threads, higher_moments);
        Estimate e;
        {
            nb::gil_scoped_release g;
            e = accumulate_values(y.data(), y.shape(0), o);
        }
        return estimate_dict(e);
    }, "values"_a, "threads"_a = 0, "higher_moments"_a = true);
    m.def("estimate_from_samples", [](const Integrand &f, InArray x, InArray pdf, const Sampler *domain_of,
                                      int threads) {
        size_t n = check_points(x, f.domain.dim, "points");
        if (pdf.ndim() != 1 || pdf.shape(0) != n)
            throw nb::value_error(("'pdf' must have shape (" + std::to_string(n) + ",), one value per point").c_str());
        const Domain &dom = domain_of ? domain_of->domain : f.domain;
        RunOptions o = options(0, 0, 0, threads);
        Estimate e;
        {
            nb::gil_scoped_release g;
            e = estimate_from_samples(f, x.data(), pdf.data(), n, dom, o);
        }
        return estimate_dict(e);
    }, "integrand"_a, "points"_a, "pdf"_a, "sampler"_a = nb::none(), "threads"_a = 0);

    // The canonical uniforms of one chunk's stream, for reproducibility checks.
    m.def("uniforms", [](int64_t n, uint64_t seed, uint64_t case_id, uint64_t replica, uint64_t chunk) {
        check_n(n);
        double *u;
        OutArray r = new_array(size_t(n), 0, &u);
        UniformStream s({seed, case_id, replica, chunk});
        s.fill(u, size_t(n));
        return r;
    }, "n"_a, "seed"_a = 0, "case_id"_a = 0, "replica"_a = 0, "chunk"_a = 0);
    m.def("pcg32_outputs", [](int64_t n, uint64_t seed, uint64_t case_id, uint64_t replica, uint64_t chunk) {
        check_n(n);
        Pcg32 g({seed, case_id, replica, chunk});
        std::vector<uint32_t> out(static_cast<size_t>(n));
        for (auto &o : out) o = g.next_u32();
        return out;
    }, "n"_a, "seed"_a = 0, "case_id"_a = 0, "replica"_a = 0, "chunk"_a = 0);

    // The vectorisable elementary functions, exposed for accuracy tests.
    m.def("fm_exp", [](InArray x) {
        double *y;
        OutArray r = new_array(x.size(), 0, &y);
        simd::map(x.data(), y, x.size(), [](auto v) { return fm::exp(v); });
        return r;
    });
    m.def("fm_log", [](InArray x) {
        double *y;
        OutArray r = new_array(x.size(), 0, &y);
        for (size_t i = 0; i < x.size(); ++i) y[i] = fm::log(x.data()[i]);
        return r;
    });
    m.def("fm_sincos_2pi", [](InArray x) {
        double *s, *c;
        OutArray rs = new_array(x.size(), 0, &s), rc = new_array(x.size(), 0, &c);
        for (size_t i = 0; i < x.size(); ++i) fm::sincos_2pi(x.data()[i], s[i], c[i]);
        return nb::make_tuple(rs, rc);
    });
}
