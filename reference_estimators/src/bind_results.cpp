// Bindings of accumulator states (their dicts, merges and accumulation of given values) and of
// the contributions' tails and extremes (extremes.h).  A state dict holds every field of the
// accumulator, so a state read back merges to exactly the bits a fresh computation gives.
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <cmath>

#include "bind_common.h"
#include "extremes.h"

namespace re::py {

using namespace nb::literals;

namespace {

const char *kIssueNames[kIssueKinds] = {"nan",         "posinf",   "neginf",  "negative",
                                        "outside_domain", "zero_pdf", "bad_pdf", "bound_violation"};

}  // namespace

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
    r["redone_blocks"] = d.redone_blocks;
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
    r["kernel"] = e.kernel;
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

static nb::dict side_dict(const SideExtremes &e) {
    nb::dict d;
    d["peak"] = e.peak;
    d["ties"] = e.ties;
    d["below"] = nb::cast(e.below);
    return d;
}

static SideExtremes side_from(const nb::handle &h) {
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

static ValueTails tails_from(const nb::dict &d) {
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

void bind_results(nb::module_ &m) {
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
}

}  // namespace re::py
