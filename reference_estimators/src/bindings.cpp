// Python bindings of the core (module reference_estimators._core): the module, integrands,
// samplers, techniques, point sets and estimates; the sampler check's kernels are bound in
// bind_checks.cpp, bind_cubature.cpp and bind_rows.cpp, accumulator states, tails and extremes in
// bind_results.cpp.  Every batch function allocates its outputs, then releases the GIL for the
// computation.  Inputs are validated here too (shape, dimension), so no call can read out of
// bounds; the Python layer adds friendlier messages on top.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/map.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/shared_ptr.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <string>

#include "bind_common.h"
#include "fastmath.h"
#include "thread_pool.h"

namespace nb = nanobind;
using namespace nb::literals;
using namespace re;
using namespace re::py;

namespace {

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
    bind_checks(m);
    bind_cubature(m);
    bind_rows(m);
    bind_results(m);
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
        .def_ro("polar", &Integrand::polar, "whether f reads a direction's cos(theta) alone")
        .def_ro("polar_function", &Integrand::polar_function,
                "the function of cos(theta) f is, by name ('' for none): a sampler's pdf of the same name is f")
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
        .def_ro("polar", &Sampler::polar, "whether the pdf reads a direction's cos(theta) alone")
        .def_ro("polar_function", &Sampler::polar_function,
                "the function of cos(theta) the pdf is, by name ('' for none): an integrand of the same name is it")
        .def_prop_ro("method", [](const Sampler &s) { return s.method == SamplingMethod::Inversion ? "inversion" : "rejection"; })
        .def_prop_ro("domain", [](const Sampler &s) { return s.domain.kind_name(); })
        .def_prop_ro("dim", [](const Sampler &s) { return s.domain.dim; })
        .def_prop_ro("kernel", &Sampler::kernel,
                     "the path sample() takes for whole vectors of points: 'small table in vector lanes' or 'batch loop'")
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
        sobol_directions().set(v.data(), int(v.shape(0)));
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
    m.def("uniforms_in_pieces", [](const std::vector<int64_t> &counts, const std::vector<bool> &evens, uint64_t seed) {
        if (counts.size() != evens.size()) throw std::invalid_argument("counts and evens differ in length");
        size_t total = 0;
        for (size_t i = 0; i < counts.size(); ++i) {
            check_n(counts[i]);
            if (evens[i] && counts[i] % 2) throw std::invalid_argument("a piece of even-numbered uniforms needs an even count");
            total += evens[i] ? size_t(counts[i]) / 2 : size_t(counts[i]);
        }
        double *u;
        OutArray r = new_array(total, 0, &u);
        UniformStream s({seed, 0, 0, 0});
        for (size_t i = 0; i < counts.size(); ++i) {
            if (evens[i]) s.fill_even(u, size_t(counts[i]));
            else s.fill(u, size_t(counts[i]));
            u += evens[i] ? size_t(counts[i]) / 2 : size_t(counts[i]);
        }
        return r;
    }, "counts"_a, "evens"_a, "seed"_a = 0);
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
        simd::map(x.data(), y, x.size(), [](auto v) { return fm::log(v); });
        return r;
    });
    m.def("fm_sincos_2pi", [](InArray x) {
        double *s, *c;
        OutArray rs = new_array(x.size(), 0, &s), rc = new_array(x.size(), 0, &c);
        for (size_t i = 0; i < x.size(); ++i) fm::sincos_2pi(x.data()[i], s[i], c[i]);
        return nb::make_tuple(rs, rc);
    });
}
