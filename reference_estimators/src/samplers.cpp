#include "samplers.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "direction_samplers.h"
#include "integrands.h"
#include "sampling.h"
#include "table_samplers.h"

namespace re {

void Sampler::invert(const double *, double *, size_t) const {
    throw std::invalid_argument("sampler '" + name + "' has no inverse (" +
                                (method == SamplingMethod::Rejection ? "rejection sampler" : "not invertible") + ")");
}

size_t count_invalid_pdfs(const double *p, size_t n) {
    // in vector lanes (GCC's loop compared one at a time)
    size_t bad = 0, i = 0;
    simd::i64v lanes = {};
    for (; i + simd::kWidth <= n; i += simd::kWidth)
        lanes += valid_pdf(simd::load(p + i)) ? simd::i64v{} : simd::i64v{} + 1;
    for (size_t l = 0; l < simd::kWidth; ++l) bad += size_t(lanes[l]);
    for (; i < n; ++i) bad += !valid_pdf(p[i]);
    return bad;
}

bool Sampler::sample_valid(const double *u, double *x, double *p, size_t n) const {
    sample(u, x, p, n);
    return all_valid(domain, x, p, n);
}

size_t Sampler::sample_polar(const double *, size_t, double *, double *, size_t) const {
    throw std::logic_error("sampler '" + name + "' draws no polar part alone (not a polar direction sampler)");
}
size_t Sampler::sample_polar_rows(LaneGenerator &, size_t, double *, double *) const {
    throw std::logic_error("sampler '" + name + "' draws no polar part alone (not a polar direction sampler)");
}
void Sampler::pdf_polar(const double *, double *, size_t) const {
    throw std::logic_error("sampler '" + name + "' has no polar pdf (not a polar direction sampler)");
}

void Sampler::draw(UniformStream &stream, double *x, double *pdf, size_t n, uint64_t, Diagnostics &diag) const {
    constexpr size_t kBlock = 256;
    std::vector<double> u(kBlock * udim);
    for (size_t i = 0; i < n; i += kBlock) {
        size_t m = std::min(kBlock, n - i);
        stream.fill(u.data(), m * udim);
        sample(u.data(), x + i * domain.dim, pdf + i, m);
    }
    diag.candidates += n;
}

std::string Sampler::describe() const {
    std::ostringstream s;
    s << name;
    if (!params.empty()) {
        s << "(";
        bool first = true;
        for (auto &[k, v] : params) { s << (first ? "" : ", ") << k << "=" << v; first = false; }
        s << ")";
    }
    return s.str();
}

namespace {

// One-dimensional inversion samplers (one uniform to one coordinate), vectorised: D supplies
// point(u) and density(x), templates over double and simd::f64v (the same bits lane by lane);
// the batch loops run them on kWidth samples at a time and the scalar tail on one.  The
// per-sample scalar loop (libm-free but scalar exp and log) ran power and trimmed-logistic
// importance sampling at 10-20 Msamples/s a thread.
template <class D>
class Interval1D : public Pointwise<D> {
  public:
    double sample_one(const double *u, double *x) const { x[0] = self().point(u[0]); return self().density(x[0]); }
    double pdf_one(const double *x) const { return self().density(x[0]); }
    void sample(const double *u, double *x, double *p, size_t n) const override {
        constexpr size_t W = simd::kWidth;
        size_t i = 0;
        for (; i + W <= n; i += W) {
            const simd::f64v xv = self().point(simd::load(u + i));
            simd::store(x + i, xv);
            simd::store(p + i, self().density(xv));
        }
        for (; i < n; ++i) p[i] = sample_one(u + i, x + i);
    }
    void pdf(const double *x, double *p, size_t n) const override {
        simd::map(x, p, n, [this](auto v) { return self().density(v); });
    }
  private:
    const D &self() const { return static_cast<const D &>(*this); }
};

class UniformBox final : public Pointwise<UniformBox> {
  public:
    explicit UniformBox(const Domain &d) : inv_measure_(1.0 / d.measure()) {
        name = "uniform_box";
        domain = d;
        udim = d.dim;
    }
    double sample_one(const double *u, double *x) const {
        for (int j = 0; j < domain.dim; ++j) x[j] = domain.lo[j] + (domain.hi[j] - domain.lo[j]) * u[j];
        return inv_measure_;
    }
    double pdf_one(const double *x) const { return domain.contains(x) ? inv_measure_ : 0.0; }
    void invert_one(const double *x, double *u) const {
        bool in = domain.contains(x);
        for (int j = 0; j < domain.dim; ++j) u[j] = in ? (x[j] - domain.lo[j]) / (domain.hi[j] - domain.lo[j]) : kNaN;
    }
    // The square's batches in vector lanes, the corners in registers: a sample's two
    // coordinates are neighbours in x, so a vector of coordinates takes its lanes' corners
    // from vectors alternating between the two axes' (the generic loops reloaded the corners a
    // coordinate and called contains() a point: an eighth of an MIS estimate with a table
    // sampler; then stride-2 loops, 0.6 ns a sample of such an estimate's 12.5 for sample, pdf
    // and the screening's passes together).  The same bits.  Other boxes: Pointwise's loops.
    void sample(const double *u, double *x, double *p, size_t n) const override {
        if (domain.dim != 2) return Pointwise::sample(u, x, p, n);
        square_points<false>(u, x, p, n);
    }
    bool sample_valid(const double *u, double *x, double *p, size_t n) const override {
        if (domain.dim != 2) return Sampler::sample_valid(u, x, p, n);
        return square_points<true>(u, x, p, n) && (n == 0 || valid_pdf(inv_measure_));
    }
    void pdf(const double *x, double *p, size_t n) const override {
        if (domain.dim != 2) return Pointwise::pdf(x, p, n);
        const double a0 = domain.lo[0], b0 = domain.hi[0], a1 = domain.lo[1], b1 = domain.hi[1], q = inv_measure_;
        simd::map2(x, p, n, [=](auto s, auto t) {
            using D = decltype(s);
            return in_rectangle(s, t, a0, b0, a1, b1) ? D{} + q : D{};
        });
    }

  private:
    // The square's points and pdfs of the uniforms u (n x 2); with `screen`, whether all of
    // them lie in the square (a NaN coordinate does not).
    template <bool screen>
    bool square_points(const double *u, double *x, double *p, size_t n) const {
        using simd::f64v;
        constexpr size_t W = simd::kWidth;
        f64v lo, width, hi;   // the axes' corners, alternating
        for (size_t l = 0; l < W; ++l) {
            lo[l] = domain.lo[l % 2];
            width[l] = domain.hi[l % 2] - domain.lo[l % 2];
            hi[l] = domain.hi[l % 2];
        }
        const size_t coords = 2 * n;
        simd::i64v outside{};
        size_t j = 0;
        for (; j + W <= coords; j += W) {
            const f64v v = lo + width * simd::load(u + j);
            if (screen) outside |= (v >= lo) & (v <= hi) ? simd::i64v{} : simd::i64v{} + 1;
            simd::store(x + j, v);
        }
        bool inside = true;
        for (; j < coords; ++j) {
            x[j] = lo[j % 2] + width[j % 2] * u[j];
            if (screen) inside &= (x[j] >= lo[j % 2]) & (x[j] <= hi[j % 2]);
        }
        std::fill(p, p + n, inv_measure_);
        for (size_t l = 0; l < W; ++l) inside &= outside[l] == 0;
        return inside;
    }

    double inv_measure_;
};

class Exponential final : public Interval1D<Exponential> {
  public:
    explicit Exponential(double a) : a_(a) { name = "exponential"; params = {{"rate", a}}; domain = Domain::half_line(); }
    template <class V>
    V point(V u) const { return sample_exponential(u, a_); }
    template <class V>
    V density(V x) const { return exponential_pdf(x, a_); }
    void invert_one(const double *x, double *u) const { u[0] = invert_exponential(x[0], a_); }
  private:
    double a_;
};

class Linear final : public Interval1D<Linear> {
  public:
    Linear(double a, double b) : a_(a), b_(b) { name = "linear"; params = {{"a", a}, {"b", b}}; domain = Domain::interval(0, 1); }
    template <class V>
    V point(V u) const { return sample_linear(u, a_, b_); }
    template <class V>
    V density(V x) const { return linear_pdf(x, a_, b_); }
    void invert_one(const double *x, double *u) const { u[0] = invert_linear(x[0], a_, b_); }
  private:
    double a_, b_;
};

class Power final : public Interval1D<Power> {
  public:
    explicit Power(double k) : k_(k) { name = "power"; params = {{"k", k}}; domain = Domain::interval(0, 1); }
    template <class V>
    V point(V u) const { return sample_power(u, k_); }
    template <class V>
    V density(V x) const { return power_pdf(x, k_); }
    void invert_one(const double *x, double *u) const { u[0] = invert_power(x[0], k_); }
  private:
    double k_;
};

class Lomax final : public Interval1D<Lomax> {
  public:
    explicit Lomax(double s) : s_(s) { name = "lomax"; params = {{"shape", s}}; domain = Domain::half_line(); }
    template <class V>
    V point(V u) const { return sample_lomax(u, s_); }
    template <class V>
    V density(V x) const { return lomax_pdf(x, s_); }
    void invert_one(const double *x, double *u) const { u[0] = invert_lomax(x[0], s_); }
  private:
    double s_;
};

class TrimmedLogistic final : public Interval1D<TrimmedLogistic> {
  public:
    TrimmedLogistic(double mu, double s, double a, double b) : mu_(mu), s_(s), a_(a), b_(b) {
        name = "trimmed_logistic";
        params = {{"mu", mu}, {"s", s}, {"a", a}, {"b", b}};
        domain = Domain::interval(a, b);
    }
    template <class V>
    V point(V u) const { return sample_trimmed_logistic(u, mu_, s_, a_, b_); }
    template <class V>
    V density(V x) const { return trimmed_logistic_pdf(x, mu_, s_, a_, b_); }
    void invert_one(const double *x, double *u) const { u[0] = invert_trimmed_logistic(x[0], mu_, s_, a_, b_); }
  private:
    double mu_, s_, a_, b_;
};

class Rejection final : public Sampler {
  public:
    Rejection(IntegrandPtr target, SamplerPtr proposal, double c)
        : target_(std::move(target)), proposal_(std::move(proposal)), c_(c) {
        name = "rejection";
        params = {{"c", c}};
        domain = target_->domain;
        udim = proposal_->udim + 1;
        method = SamplingMethod::Rejection;
        invertible = false;
    }
    void sample(const double *, double *, double *, size_t) const override {
        throw std::invalid_argument(
            "sampler 'rejection' consumes a variable number of uniforms per point; use draw(n, seed=...)");
    }
    void pdf(const double *x, double *p, size_t n) const override {
        target_->eval(x, p, n);
        for (size_t i = 0; i < n; ++i) p[i] /= target_->reference;
    }
    void draw(UniformStream &stream, double *x, double *pdf, size_t n, uint64_t first_index,
              Diagnostics &diag) const override {
        constexpr size_t kBlock = 64;
        const int xd = domain.dim, ud = proposal_->udim;
        std::vector<double> u(kBlock * ud), xi(kBlock), cand(kBlock * xd), p(kBlock), f(kBlock);
        size_t got = 0, dry = 0;
        while (got < n) {
            // A target that is 0 wherever the proposal goes would loop forever.
            if (dry > kMaxDryCandidates)
                throw std::runtime_error("rejection sampler: no candidate accepted in " +
                                         std::to_string(kMaxDryCandidates) + " tries (target '" + target_->name +
                                         "', proposal '" + proposal_->describe() + "')");
            size_t before = got;
            stream.fill(u.data(), kBlock * ud);
            stream.fill(xi.data(), kBlock);
            proposal_->sample(u.data(), cand.data(), p.data(), kBlock);
            target_->eval(cand.data(), f.data(), kBlock);
            for (size_t i = 0; i < kBlock && got < n; ++i) {
                diag.candidates++;
                if (!(f[i] >= 0 && f[i] <= std::numeric_limits<double>::max())) {
                    diag.record(Issue::BadPdf, first_index + got, &cand[i * xd], xd, f[i]);
                    continue;
                }
                double bound = c_ * p[i];
                if (f[i] > bound)
                    diag.record(Issue::BoundViolation, first_index + got, &cand[i * xd], xd, f[i] / bound);
                if (xi[i] * bound < f[i]) {
                    for (int j = 0; j < xd; ++j) x[got * xd + j] = cand[i * xd + j];
                    pdf[got] = f[i] / target_->reference;
                    ++got;
                }
            }
            dry = got == before ? dry + kBlock : 0;
        }
    }
    const Integrand &target() const { return *target_; }

  private:
    static constexpr size_t kMaxDryCandidates = size_t(1) << 26;
    IntegrandPtr target_;
    SamplerPtr proposal_;
    double c_;
};

[[noreturn]] void bad_param(const std::string &sampler, const std::string &p, const std::string &rule, double got) {
    std::ostringstream s;
    s << "sampler '" << sampler << "': parameter '" << p << "' must be " << rule << ", got " << got;
    throw std::invalid_argument(s.str());
}

}  // namespace

const std::vector<SamplerInfo> &sampler_registry() {
    static const std::vector<SamplerInfo> r = {
        {"exponential", "inversion", "half_line", "p(x) = rate exp(-rate x)", {{"rate", 1.0}}},
        {"linear", "inversion", "interval", "p(x) proportional to (1-x) a + x b on [0,1]", {{"a", 1.0}, {"b", 0.5}}},
        {"power", "inversion", "interval", "p(x) = (k+1) x^k on (0,1], k > -1", {{"k", -0.5}}},
        {"lomax", "inversion", "half_line", "p(x) = shape (1+x)^-(shape+1)", {{"shape", 1.0}}},
        {"trimmed_logistic", "inversion", "interval", "logistic(mu, s) restricted to [a, b]",
         {{"mu", 0.5}, {"s", 0.1}, {"a", 0.0}, {"b", 1.0}}},
        {"piecewise_constant_1d", "inversion", "interval", "tabulated 1D density on [a, b]", {{"a", 0.0}, {"b", 1.0}}, true},
        {"piecewise_constant_2d", "inversion", "square", "tabulated 2D density on [0,1]^2 (rows = y)", {}, true},
        {"uniform_hemisphere", "inversion", "hemisphere", "1 / (2 pi) per steradian", {}},
        {"cosine_hemisphere", "inversion", "hemisphere", "cos(theta) / pi per steradian", {}},
        {"uniform_sphere", "inversion", "sphere", "1 / (4 pi) per steradian", {}},
        {"uniform_cone", "inversion", "sphere", "uniform in the cone cos(theta) >= cos_max", {{"cos_max", 0.9}}},
        {"ggx", "inversion", "hemisphere", "GGX D(w) cos(theta), roughness alpha", {{"alpha", 0.1}}},
    };
    return r;
}

SamplerPtr make_sampler(const std::string &name, const std::map<std::string, double> &given,
                        const std::vector<double> &table, const std::vector<size_t> &shape) {
    const SamplerInfo *info = nullptr;
    for (auto &i : sampler_registry())
        if (i.name == name) info = &i;
    if (!info) {
        std::string names;
        for (auto &i : sampler_registry()) names += (names.empty() ? "" : ", ") + i.name;
        throw std::invalid_argument("unknown sampler '" + name + "'; known samplers: " + names);
    }
    std::map<std::string, double> p;
    for (auto &[k, v] : info->params) p[k] = v;
    for (auto &[k, v] : given) {
        if (!p.count(k)) {
            std::string names;
            for (auto &[pk, pv] : info->params) names += (names.empty() ? "" : ", ") + pk;
            throw std::invalid_argument("sampler '" + name + "' has no parameter '" + k + "'; its parameters: " +
                                        (names.empty() ? "(none)" : names));
        }
        if (!std::isfinite(v)) bad_param(name, k, "finite", v);
        p[k] = v;
    }
    if (info->needs_table) {
        if (table.empty()) throw std::invalid_argument("sampler '" + name + "' needs a table of values");
        double total = 0;
        for (size_t i = 0; i < table.size(); ++i) {
            if (!(table[i] >= 0 && std::isfinite(table[i]))) {
                std::ostringstream s;
                s << "sampler '" << name << "': table values must be finite and >= 0, got " << table[i] << " at index " << i;
                throw std::invalid_argument(s.str());
            }
            total += table[i];
        }
        if (!(total > 0)) throw std::invalid_argument("sampler '" + name + "': table values must not all be 0");
    } else if (!table.empty()) {
        throw std::invalid_argument("sampler '" + name + "' takes no table");
    }
    if (name == "exponential") {
        if (!(p["rate"] > 0)) bad_param(name, "rate", "> 0", p["rate"]);
        return std::make_shared<Exponential>(p["rate"]);
    }
    if (name == "linear") {
        if (!(p["a"] >= 0)) bad_param(name, "a", ">= 0", p["a"]);
        if (!(p["b"] >= 0)) bad_param(name, "b", ">= 0", p["b"]);
        if (!(p["a"] + p["b"] > 0)) bad_param(name, "a + b", "> 0", p["a"] + p["b"]);
        return std::make_shared<Linear>(p["a"], p["b"]);
    }
    if (name == "power") {
        if (!(p["k"] > -1)) bad_param(name, "k", "> -1", p["k"]);
        return std::make_shared<Power>(p["k"]);
    }
    if (name == "lomax") {
        if (!(p["shape"] > 0)) bad_param(name, "shape", "> 0", p["shape"]);
        return std::make_shared<Lomax>(p["shape"]);
    }
    if (name == "trimmed_logistic") {
        if (!(p["s"] > 0)) bad_param(name, "s", "> 0", p["s"]);
        if (!(p["b"] > p["a"])) bad_param(name, "b", "> a", p["b"]);
        return std::make_shared<TrimmedLogistic>(p["mu"], p["s"], p["a"], p["b"]);
    }
    if (name == "piecewise_constant_1d") {
        if (!(p["b"] > p["a"])) bad_param(name, "b", "> a", p["b"]);
        if (!shape.empty() && shape.size() != 1)
            throw std::invalid_argument("sampler 'piecewise_constant_1d': table must be 1-dimensional");
        return make_piecewise_constant_1d(table, p["a"], p["b"]);
    }
    if (name == "piecewise_constant_2d") {
        if (shape.size() != 2)
            throw std::invalid_argument("sampler 'piecewise_constant_2d': table must be 2-dimensional (rows, cols)");
        return make_piecewise_constant_2d(table, shape[0], shape[1]);
    }
    if (name == "uniform_hemisphere") return std::make_shared<UniformHemisphere>();
    if (name == "cosine_hemisphere") return std::make_shared<CosineHemisphere>();
    if (name == "uniform_sphere") return std::make_shared<UniformSphere>();
    if (name == "uniform_cone") {
        if (!(p["cos_max"] > -1 && p["cos_max"] < 1)) bad_param(name, "cos_max", "in (-1, 1)", p["cos_max"]);
        return std::make_shared<UniformCone>(p["cos_max"]);
    }
    if (name == "ggx") {
        if (!(p["alpha"] > 0)) bad_param(name, "alpha", "> 0", p["alpha"]);
        return std::make_shared<Ggx>(p["alpha"]);
    }
    throw std::logic_error("sampler registry and factory disagree on '" + name + "'");
}

SamplerPtr make_rejection_sampler(IntegrandPtr target, SamplerPtr proposal, double c) {
    if (!target) throw std::invalid_argument("rejection sampler: target integrand is missing");
    if (!proposal) throw std::invalid_argument("rejection sampler: proposal sampler is missing");
    if (proposal->method != SamplingMethod::Inversion)
        throw std::invalid_argument("rejection sampler: the proposal must be an inversion sampler, got '" +
                                    proposal->name + "'");
    if (proposal->domain.dim != target->domain.dim)
        throw std::invalid_argument("rejection sampler: proposal '" + proposal->name + "' draws " +
                                    std::to_string(proposal->domain.dim) + "-dimensional points, target '" +
                                    target->name + "' needs " + std::to_string(target->domain.dim));
    if (!target->nonnegative)
        throw std::invalid_argument("rejection sampler: target '" + target->name + "' takes negative values");
    if (!(c > 0 && std::isfinite(c))) bad_param("rejection", "c", "finite and > 0", c);
    if (!(target->reference > 0))
        throw std::invalid_argument("rejection sampler: target '" + target->name + "' must integrate to > 0");
    return std::make_shared<Rejection>(std::move(target), std::move(proposal), c);
}

SamplerPtr make_uniform_sampler(const Domain &d) {
    switch (d.kind) {
        case DomainKind::Box: return std::make_shared<UniformBox>(d);
        case DomainKind::Hemisphere: return std::make_shared<UniformHemisphere>();
        case DomainKind::Sphere: return std::make_shared<UniformSphere>();
        case DomainKind::HalfLine: break;
    }
    throw std::invalid_argument("uniform sampling needs a domain of finite measure, got '" + d.kind_name() + "'");
}

}  // namespace re
