#include "integrands.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "fastmath.h"
#include "sampling.h"

namespace re {

void Integrand::eval_polar(const double *, double *, size_t) const {
    throw std::logic_error("integrand '" + name + "' is not polar (it reads more of a point than cos(theta))");
}

namespace {

constexpr double kSqrtPi = 1.7724538509055160273;

inline bool in_unit(double x) { return x >= 0.0 && x <= 1.0; }
// value where x is in [0, 1], else 0: for double and simd::f64v (simd::map's lambdas)
template <class D>
RE_INLINE D on_unit(D x, D value) { return (x >= 0.0) & (x <= 1.0) ? value : D{}; }

// Standard normal probability of (lo, hi) in units of sigma, without cancellation in the tails.
double normal_mass(double lo, double hi) {
    const double r = 1.0 / std::sqrt(2.0);
    if (lo >= 0) return 0.5 * (std::erfc(lo * r) - std::erfc(hi * r));
    if (hi <= 0) return 0.5 * (std::erfc(-hi * r) - std::erfc(-lo * r));
    return 1.0 - 0.5 * (std::erfc(-lo * r) + std::erfc(hi * r));
}

// s * exp(-x^2) on [0, 1]: `gaussian` (s = 1) and the extreme-magnitude `huge` / `tiny`.
class ScaledGaussian final : public Integrand {
  public:
    ScaledGaussian(std::string n, double s, std::string d) : s_(s) {
        name = std::move(n);
        description = std::move(d);
        domain = Domain::interval(0, 1);
        reference = s * 0.5 * kSqrtPi * std::erf(1.0);
    }
    void eval(const double *x, double *f, size_t n) const override {
        simd::map(x, f, n, [s = s_](auto v) { return on_unit(v, s * fm::exp(-v * v)); });
    }
  private:
    double s_;
};

class Polynomial final : public Integrand {
  public:
    explicit Polynomial(std::vector<double> c) : c_(std::move(c)) {  // c[k] x^k on [0, 1]
        name = "polynomial";
        domain = Domain::interval(0, 1);
        reference = 0;
        for (size_t k = 0; k < c_.size(); ++k) reference += c_[k] / double(k + 1);
        nonnegative = false;
        description = "5x^4 - 4x^3 + 0.1 on [0,1]; negative on part of the domain";
    }
    void eval(const double *x, double *f, size_t n) const override {
        simd::map(x, f, n, [&c = c_](auto v) {   // Horner, in vector lanes
            using V = decltype(v);
            V y{};
            for (size_t k = c.size(); k-- > 0;) y = y * v + c[k];
            return on_unit(v, y);
        });
    }
  private:
    std::vector<double> c_;
};

// Normalised Gaussian peak N(mu, sigma^2) restricted to [0, 1].
class GaussianPeak final : public Integrand {
  public:
    GaussianPeak(double mu, double sigma) : mu_(mu), sigma_(sigma) {
        name = "peak";
        domain = Domain::interval(0, 1);
        reference = normal_mass((0 - mu) / sigma, (1 - mu) / sigma);
        std::ostringstream s;
        s << "normal density, mean " << mu << ", width " << sigma << ", on [0,1] (stiff)";
        description = s.str();
    }
    void eval(const double *x, double *f, size_t n) const override {
        const double k = 1.0 / (sigma_ * std::sqrt(2 * M_PI)), h = -0.5 / (sigma_ * sigma_), mu = mu_;
        simd::map(x, f, n, [=](auto v) {
            auto d = v - mu;
            return on_unit(v, k * fm::exp(h * d * d));
        });
    }
  private:
    double mu_, sigma_;
};

class Step final : public Integrand {
  public:
    Step(double t, double left, double right) : t_(t), l_(left), r_(right) {
        name = "step";
        domain = Domain::interval(0, 1);
        reference = t * left + (1 - t) * right;
        description = "1 for x < 1/sqrt(2), 0.25 after: a jump inside a cell";
    }
    void eval(const double *x, double *f, size_t n) const override {
        for (size_t i = 0; i < n; ++i) f[i] = in_unit(x[i]) ? (x[i] < t_ ? l_ : r_) : 0.0;
    }
  private:
    double t_, l_, r_;
};

// c x^k on (0, 1], k > -1: an integrable singularity at 0.
class PowerLaw final : public Integrand {
  public:
    PowerLaw(std::string n, double c, double k, std::string d) : c_(c), k_(k) {
        name = std::move(n);
        description = std::move(d);
        domain = Domain::interval(0, 1);
        reference = c / (k + 1);
    }
    void eval(const double *x, double *f, size_t n) const override {
        simd::map(x, f, n, [c = c_, k = k_](auto v) {
            using V = decltype(v);
            return (v > V{}) & (v <= V{} + 1.0) ? c * fm::exp(k * fm::log(v)) : V{};
        });
    }
  private:
    double c_, k_;
};

class HalfCauchy final : public Integrand {
  public:
    HalfCauchy() {
        name = "half_cauchy";
        domain = Domain::half_line();
        reference = 1.0;
        description = "2 / (pi (1 + x^2)) on [0, inf): a power-law tail";
    }
    void eval(const double *x, double *f, size_t n) const override {
        for (size_t i = 0; i < n; ++i) f[i] = x[i] >= 0 ? 2.0 * kInvPi / (1.0 + x[i] * x[i]) : 0.0;
    }
};

class Offset final : public Integrand {
  public:
    explicit Offset(double c) : c_(c) {
        name = "offset";
        domain = Domain::interval(0, 1);
        reference = c;
        description = "1e8 + sin(2 pi x): variance 1/2 under a huge mean; E[f^2]-E[f]^2 loses every digit";
    }
    void eval(const double *x, double *f, size_t n) const override {
        simd::map(x, f, n, [c0 = c_](auto v) {
            decltype(v) s, c;
            fm::sincos_2pi(v, s, c);
            return on_unit(v, c0 + s);
        });
    }
  private:
    double c_;
};

// exp(-|x - 1/2|^2) on [0,1]^d: a smooth product integrand in high dimension.
class GaussianProduct final : public Integrand {
  public:
    explicit GaussianProduct(int d) {
        name = "gaussian" + std::to_string(d);
        domain = Domain::box(std::vector<double>(d, 0.0), std::vector<double>(d, 1.0));
        reference = std::pow(kSqrtPi * std::erf(0.5), d);
        description = "prod_i exp(-(x_i - 1/2)^2) on [0,1]^" + std::to_string(d);
    }
    void eval(const double *x, double *f, size_t n) const override {
        const int d = domain.dim;
        for (size_t i = 0; i < n; ++i) {
            double s = 0;
            bool in = true;
            for (int j = 0; j < d; ++j) {
                double v = x[i * d + j];
                s += (v - 0.5) * (v - 0.5);
                in = in && in_unit(v);
            }
            f[i] = in ? -s : -std::numeric_limits<double>::infinity();  // exp(-inf) = 0
        }
        simd::map(f, f, n, [](auto s) { return fm::exp(s); });
    }
};

class CosinePower final : public Integrand {
  public:
    explicit CosinePower(int k) : k_(k) {
        name = "cosine_power";
        domain = Domain::hemisphere();
        reference = 2 * M_PI / (k + 1);
        description = "cos^" + std::to_string(k) + "(theta) over the hemisphere";
        polar = true;
    }
    void eval(const double *w, double *f, size_t n) const override {
        for (size_t i = 0; i < n; ++i) f[i] = value(w[3 * i + 2]);
    }
    void eval_polar(const double *z, double *f, size_t n) const override {
        for (size_t i = 0; i < n; ++i) f[i] = value(z[i]);
    }
  private:
    double value(double z) const {
        double v = 1;
        for (int j = 0; j < k_; ++j) v *= z;
        return z >= 0 ? v : 0.0;
    }
    int k_;
};

class GgxLobe final : public Integrand {
  public:
    explicit GgxLobe(double alpha) : a_(alpha) {
        name = "ggx_lobe";
        domain = Domain::hemisphere();
        reference = 1.0;
        std::ostringstream s;
        s << "GGX D(w) cos(theta), alpha = " << alpha << ": a sharp lobe that integrates to 1";
        description = s.str();
        polar = true;
        polar_function = ggx_pdf_name(alpha);
    }
    void eval(const double *w, double *f, size_t n) const override {
        // in vector lanes: the scalar loop did not vectorise (stride 3)
        simd::map3(w, f, n, [a = a_](auto, auto, auto z) { return ggx_pdf(z, a); });
    }
    void eval_polar(const double *z, double *f, size_t n) const override {
        simd::map(z, f, n, [a = a_](auto zv) { return ggx_pdf(zv, a); });
    }
  private:
    double a_;
};

class SphericalCap final : public Integrand {
  public:
    explicit SphericalCap(double cos_c) : c_(cos_c) {
        name = "spherical_cap";
        domain = Domain::sphere();
        reference = 2 * M_PI * (1 - cos_c);
        description = "indicator of the cap theta < 30 deg on the sphere: a discontinuity";
        polar = true;
    }
    void eval(const double *w, double *f, size_t n) const override {
        for (size_t i = 0; i < n; ++i) f[i] = w[3 * i + 2] >= c_ ? 1.0 : 0.0;
    }
    void eval_polar(const double *z, double *f, size_t n) const override {
        for (size_t i = 0; i < n; ++i) f[i] = z[i] >= c_ ? 1.0 : 0.0;
    }
  private:
    double c_;
};

class Gaussian2D final : public Integrand {
  public:
    Gaussian2D(double mx, double my, double s) : mx_(mx), my_(my), s_(s) {
        name = "gaussian2d";
        domain = Domain::box({0, 0}, {1, 1});
        double w = s * std::sqrt(2 * M_PI);
        reference = w * normal_mass(-mx / s, (1 - mx) / s) * w * normal_mass(-my / s, (1 - my) / s);
        description = "exp(-|x - (0.3, 0.6)|^2 / (2 * 0.08^2)) on [0,1]^2: an environment-map-like bump";
    }
    void eval(const double *x, double *f, size_t n) const override {
        // in vector lanes, 0 outside the box (GCC had compiled the scalar loop of the exponents
        // with a branch per coordinate test and the centre reloaded a point, behind the exp
        // pass: 2.1 ns a point, three times the 1-D Gaussian's; the same bits)
        const double h = -0.5 / (s_ * s_), mx = mx_, my = my_;
        simd::map2(x, f, n, [h, mx, my](auto a, auto b) {
            using D = decltype(a);
            const D dx = a - mx, dy = b - my;
            return on_unit(a, on_unit(b, fm::exp(h * (dx * dx + dy * dy))));
        });
    }
    double value(double x, double y) const { double f, p[2] = {x, y}; eval(p, &f, 1); return f; }
  private:
    double mx_, my_, s_;
};

class Tabulated final : public Integrand {
  public:
    Tabulated(std::vector<double> v, double a, double b) : v_(std::move(v)), a_(a), b_(b) {
        name = "tabulated";
        domain = Domain::interval(a, b);
        CompensatedSum s;
        for (double x : v_) s.add(x);
        reference = s.value() * (b - a) / double(v_.size());
        nonnegative = false;
        description = "piecewise-constant from " + std::to_string(v_.size()) + " values";
    }
    void eval(const double *x, double *f, size_t n) const override {
        const double k = double(v_.size()) / (b_ - a_);
        for (size_t i = 0; i < n; ++i) {
            bool in = x[i] >= a_ && x[i] <= b_;
            size_t j = in ? std::min(size_t((x[i] - a_) * k), v_.size() - 1) : 0;
            f[i] = in ? v_[j] : 0.0;
        }
    }
  private:
    std::vector<double> v_;
    double a_, b_;
};

Technique named(Technique t, std::string name, int finite_variance, std::string note = "") {
    t.name = std::move(name);
    t.finite_variance = finite_variance;
    t.note = std::move(note);
    return t;
}

std::vector<CatalogueEntry> build_catalogue() {
    std::vector<CatalogueEntry> c;
    auto sampler = [](const std::string &n, std::map<std::string, double> p = {}) { return make_sampler(n, p); };
    auto add = [&](IntegrandPtr f, std::vector<Technique> t) { c.push_back({std::move(f), std::move(t)}); };
    const Domain unit = Domain::interval(0, 1);

    auto gaussian = std::make_shared<ScaledGaussian>("gaussian", 1.0, "exp(-x^2) on [0,1]");
    auto linear = sampler("linear", {{"a", 1.0}, {"b", 0.37}});
    auto uniform01 = make_uniform_sampler(unit);
    add(gaussian, {named(make_uniform_technique(unit), "uniform", 1),
                   named(with_points(make_uniform_technique(unit), PointSetKind::Stratified), "uniform/stratified", 1,
                         "n strata: error ~ n^-1.5 for a smooth integrand"),
                   named(with_points(make_uniform_technique(unit), PointSetKind::Sobol), "uniform/sobol", 1,
                         "Owen-scrambled Sobol': error ~ n^-1.5 for a smooth integrand"),
                   named(make_importance_technique(linear), "importance:linear", 1),
                   named(with_points(make_importance_technique(linear), PointSetKind::Sobol), "importance:linear/sobol", 1),
                   named(make_hit_or_miss_technique(uniform01, 1.0), "rejection", 1,
                         "hit-or-miss under c = 1 with uniform proposals"),
                   named(make_russian_roulette_technique(uniform01, 0.5, 0.0, true), "roulette:uniform(q=0.5)", 1,
                         "f evaluated for half the samples, survivors weighted 1/q"),
                   named(make_russian_roulette_technique(uniform01, 0.9, 0.0, false), "roulette_biased:uniform(q=0.9)", 1,
                         "survivors not reweighted: E[Y] = 0.9 I (biased on purpose)"),
                   named(make_mis_technique({uniform01, linear}, 1), "mis_balance:uniform+linear", 1),
                   named(make_mis_technique({uniform01, linear}, 2), "mis_power:uniform+linear", 1),
                   named(with_clamp(make_uniform_technique(unit), 0.9), "clamped:uniform(0.9)", 1,
                         "contributions above 0.9 cut: bias -0.0206 (biased on purpose)"),
                   named(make_self_normalized_technique(linear, 4), "snis:linear(b=4)", 1,
                         "ratio of means over 4 samples: O(1/4) relative bias (biased on purpose)")});

    add(std::make_shared<Polynomial>(std::vector<double>{0.1, 0, 0, -4, 5}),
        {named(make_uniform_technique(unit), "uniform", 1),
         named(make_importance_technique(sampler("linear", {{"a", 0.2}, {"b", 1.8}})), "importance:linear", 1)});

    const double sigma = 1e-6;
    add(std::make_shared<GaussianPeak>(0.3, sigma),
        {named(make_uniform_technique(unit), "uniform", 1, "variance ~ 1/(2 sqrt(pi) sigma): almost every sample misses"),
         named(make_importance_technique(sampler("trimmed_logistic",
                                                 {{"mu", 0.3}, {"s", sigma * std::sqrt(3.0) / M_PI}, {"a", 0}, {"b", 1}})),
               "importance:trimmed_logistic", 1)});

    const double t = 1 / std::sqrt(2.0);
    add(std::make_shared<Step>(t, 1.0, 0.25),
        {named(make_uniform_technique(unit), "uniform", 1),
         named(with_points(make_uniform_technique(unit), PointSetKind::Stratified), "uniform/stratified", 1,
               "one stratum holds the jump: error ~ n^-1"),
         named(with_points(make_uniform_technique(unit), PointSetKind::Sobol), "uniform/sobol", 1),
         named(make_importance_technique(make_sampler("piecewise_constant_1d", {}, {1.0, 1.0, 0.87, 0.25})),
               "importance:piecewise_constant_1d", 1),
         named(make_hit_or_miss_technique(make_uniform_sampler(unit), 1.0), "rejection", 1)});

    add(std::make_shared<PowerLaw>("singularity", 0.5, -0.5, "1 / (2 sqrt(x)) on (0,1]: integrable singularity at 0"),
        {named(make_uniform_technique(unit), "uniform", 0, "f/p has infinite variance (tail index 2)"),
         named(make_importance_technique(sampler("power", {{"k", -0.5}})), "importance:power", 1,
               "p matches f: zero variance")});

    add(std::make_shared<PowerLaw>("pareto_tail", 1.0 / 3.0, -2.0 / 3.0, "x^(-2/3) / 3 on (0,1]: Pareto-tailed contributions"),
        {named(make_uniform_technique(unit), "uniform", 0, "contributions have a Pareto tail of index 3/2: infinite variance"),
         named(make_importance_technique(sampler("power", {{"k", -0.5}})), "importance:power", 1)});

    add(std::make_shared<HalfCauchy>(),
        {named(make_importance_technique(sampler("exponential", {{"rate", 1.0}})), "importance:exponential", 0,
               "light-tailed proposal for a heavy tail: f/p unbounded, infinite variance"),
         named(make_importance_technique(sampler("lomax", {{"shape", 1.0}})), "importance:lomax", 1),
         named(make_mis_technique({sampler("exponential", {{"rate", 1.0}}), sampler("lomax", {{"shape", 1.0}})}, 1),
               "mis_balance:exponential+lomax", 1, "the Lomax partner bounds f/p: finite variance again")});

    for (auto [n, s] : {std::pair<const char *, double>{"huge", 1e300}, {"tiny", 1e-300}}) {
        add(std::make_shared<ScaledGaussian>(n, s, std::string(n == std::string("huge") ? "1e300" : "1e-300") + " exp(-x^2) on [0,1]"),
            {named(make_uniform_technique(unit), "uniform", 1),
             named(make_importance_technique(sampler("linear", {{"a", 1.0}, {"b", 0.37}})), "importance:linear", 1)});
    }

    add(std::make_shared<Offset>(1e8), {named(make_uniform_technique(unit), "uniform", 1)});

    auto g16 = std::make_shared<GaussianProduct>(16);
    add(g16, {named(make_uniform_technique(g16->domain), "uniform", 1),
              named(with_points(make_uniform_technique(g16->domain), PointSetKind::Stratified), "uniform/stratified", 1,
                    "2^16 strata at most below 3^16 samples: barely better than random"),
              named(with_points(make_uniform_technique(g16->domain), PointSetKind::Sobol), "uniform/sobol", 1)});

    add(std::make_shared<CosinePower>(8),
        {named(make_uniform_technique(Domain::hemisphere()), "uniform", 1),
         named(make_importance_technique(sampler("cosine_hemisphere")), "importance:cosine_hemisphere", 1),
         named(with_points(make_importance_technique(sampler("cosine_hemisphere")), PointSetKind::Sobol),
               "importance:cosine_hemisphere/sobol", 1),
         named(make_russian_roulette_technique(sampler("cosine_hemisphere"), 0.25, 0.0, true),
               "roulette:cosine_hemisphere(q=0.25)", 1)});

    const double alpha = 0.01;
    add(std::make_shared<GgxLobe>(alpha),
        {named(make_uniform_technique(Domain::hemisphere()), "uniform", 1, "sharp lobe: variance ~ 1/alpha^2"),
         named(make_importance_technique(sampler("cosine_hemisphere")), "importance:cosine_hemisphere", 1),
         named(make_importance_technique(sampler("ggx", {{"alpha", alpha}})), "importance:ggx", 1, "p matches f: zero variance"),
         named(make_mis_technique({sampler("cosine_hemisphere"), sampler("ggx", {{"alpha", alpha}})}, 1),
               "mis_balance:cosine_hemisphere+ggx", 1),
         named(make_mis_technique({sampler("cosine_hemisphere"), sampler("ggx", {{"alpha", alpha}})}, 2),
               "mis_power:cosine_hemisphere+ggx", 1)});

    const double cap = std::cos(30 * M_PI / 180);
    add(std::make_shared<SphericalCap>(cap),
        {named(make_uniform_technique(Domain::sphere()), "uniform", 1),
         named(with_points(make_uniform_technique(Domain::sphere()), PointSetKind::Sobol), "uniform/sobol", 1),
         named(make_importance_technique(sampler("uniform_cone", {{"cos_max", std::cos(40 * M_PI / 180)}})),
               "importance:uniform_cone", 1)});

    auto g2 = std::make_shared<Gaussian2D>(0.3, 0.6, 0.08);
    const size_t res = 16;
    std::vector<double> table(res * res);
    for (size_t r = 0; r < res; ++r)
        for (size_t k = 0; k < res; ++k) table[r * res + k] = g2->value((k + 0.5) / res, (r + 0.5) / res) + 1e-3;
    auto table2d = make_sampler("piecewise_constant_2d", {}, table, {res, res});
    add(g2, {named(make_uniform_technique(g2->domain), "uniform", 1),
             named(with_points(make_uniform_technique(g2->domain), PointSetKind::Stratified), "uniform/stratified", 1),
             named(with_points(make_uniform_technique(g2->domain), PointSetKind::Sobol), "uniform/sobol", 1),
             named(make_splitting_technique(g2->domain, 4), "splitting(M=4)", 1, "1 outer x 4 inner samples"),
             named(make_importance_technique(table2d), "importance:piecewise_constant_2d", 1,
                   "16x16 table of f at cell centres (+1e-3 floor)"),
             named(make_mis_technique({make_uniform_sampler(g2->domain), table2d}, 1),
                   "mis_balance:uniform_box+piecewise_constant_2d", 1)});
    return c;
}

}  // namespace

const std::vector<CatalogueEntry> &catalogue() {
    static const std::vector<CatalogueEntry> c = build_catalogue();
    return c;
}

const CatalogueEntry &catalogue_entry(const std::string &name) {
    for (auto &e : catalogue())
        if (e.integrand->name == name) return e;
    std::string names;
    for (auto &e : catalogue()) names += (names.empty() ? "" : ", ") + e.integrand->name;
    throw std::invalid_argument("unknown integrand '" + name + "'; the catalogue has: " + names);
}

IntegrandPtr make_tabulated_integrand(const std::vector<double> &values, double a, double b) {
    if (values.empty()) throw std::invalid_argument("tabulated integrand: values must not be empty");
    if (!(b > a && std::isfinite(a) && std::isfinite(b))) {
        std::ostringstream s;
        s << "tabulated integrand: need finite a < b, got a = " << a << ", b = " << b;
        throw std::invalid_argument(s.str());
    }
    return std::make_shared<Tabulated>(values, a, b);
}

}  // namespace re
