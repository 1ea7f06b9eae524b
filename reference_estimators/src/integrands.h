// Integrands with exact reference values, and the catalogue of cases the harness ships:
// smooth, stiff (a peak of width 1e-6), discontinuous, singular, heavy-tailed, extreme in
// magnitude, offset (ruins E[f^2] - E[f]^2), and 16-dimensional.
#pragma once
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "domain.h"
#include "pointsets.h"
#include "samplers.h"

namespace re {

class Integrand {
  public:
    virtual ~Integrand() = default;
    std::string name, description;
    Domain domain;
    double reference = 0;       // exact value of the integral over the domain
    bool nonnegative = true;    // a negative value is then an error, not a feature
    // f[n] from x[n * domain.dim]; f is 0 outside the domain.
    virtual void eval(const double *x, double *f, size_t n) const = 0;
    // On the sphere or hemisphere, whether f depends on a direction through its z = cos(theta)
    // alone; eval_polar is then f[n] at directions of cosine z[n] (eval's bits at any of them),
    // and importance sampling and MIS by `polar` samplers draw no azimuth (Sampler::polar).
    // Others throw std::logic_error.
    bool polar = false;
    virtual void eval_polar(const double *z, double *f, size_t n) const;
    // The function of z that eval_polar computes, by name (empty: none named), for the polar
    // path to merge it with a sampler's density of the same name (Sampler::polar_function).
    std::string polar_function;
};
using IntegrandPtr = std::shared_ptr<const Integrand>;

enum class TechniqueKind { Uniform, Importance, HitOrMiss, RussianRoulette, Splitting, Mis, SelfNormalized };

// How contributions Y are formed (n contributions per estimate; one may use several samples):
//   Uniform         Y = |D| f(X), X uniform on D                                (background eq. 3)
//   Importance      Y = f(X) / p(X), X ~ p                                      (eq. 4)
//   HitOrMiss       Y = c 1{xi c p(X) < f(X)}: the rejection method's acceptance rate,
//                   E[Y] = c P(accept) = I when f <= c p holds
//   RussianRoulette with survival probability q, f is evaluated only when xi < q:
//                   Y = (f/p - (1-q) c) / q if xi < q, else c         (section 3.1; unbiased)
//                   biased twin (reweight = false): Y = f/p if xi < q, else c
//   Splitting       f on a 2-D box: one outer sample x0, M inner samples x1_j,
//                   Y = |D| (1/M) sum_j f(x0, x1_j)
//   Mis             one sample X_i from each sampler p_i, Y = sum_i w_i(X_i) f(X_i) / p_i(X_i),
//                   w_i = p_i^beta / sum_j p_j^beta (beta = 1 balance, 2 power heuristic)
//   SelfNormalized  ratio over a batch of b samples: Y = |D| sum f/p / sum 1{X in D}/p
//                   (consistent, biased by O(1/b): the self-normalised IS estimator)
// Any kind may clamp, Y = min(Y, clamp) (biased low wherever Y exceeds the clamp).
struct Technique {
    std::string name;
    TechniqueKind kind = TechniqueKind::Uniform;
    SamplerPtr sampler;                        // the sampler (a uniform one for Uniform/Splitting)
    PointSetKind points = PointSetKind::Random;
    double bound = 0;                          // HitOrMiss: c
    double rr_q = 1, rr_c = 0;                 // RussianRoulette: survival probability, constant
    bool reweight = true;                      // RussianRoulette: false gives the biased twin
    int split = 1;                             // Splitting: inner samples M
    std::vector<SamplerPtr> mis;               // Mis: the samplers
    double mis_power = 1;                      // Mis: heuristic exponent beta
    int batch = 1;                             // SelfNormalized: samples per ratio
    double clamp = std::numeric_limits<double>::infinity();
    bool biased = false;                       // deliberately biased: measurements must see it
    int finite_variance = -1;                  // 1 known finite, 0 known infinite, -1 unknown
    std::string note;

    // Canonical uniforms per contribution (the point set's dimension).
    int udim(const Integrand &f) const;
    // f evaluations per contribution.
    int evaluations() const;
};

struct CatalogueEntry {
    IntegrandPtr integrand;
    std::vector<Technique> techniques;
};

const std::vector<CatalogueEntry> &catalogue();
const CatalogueEntry &catalogue_entry(const std::string &name);  // throws naming the choices

// A piecewise-constant integrand on [a, b] from tabulated values (values may be anything,
// NaN included: that is how tests plant faults that must be reported).
IntegrandPtr make_tabulated_integrand(const std::vector<double> &values, double a, double b);

Technique make_uniform_technique(const Domain &domain);
Technique make_importance_technique(SamplerPtr sampler);
Technique make_hit_or_miss_technique(SamplerPtr proposal, double c);
Technique make_russian_roulette_technique(SamplerPtr sampler, double q, double c, bool reweight);
Technique make_splitting_technique(const Domain &domain, int m);
Technique make_mis_technique(std::vector<SamplerPtr> samplers, double power);
Technique make_self_normalized_technique(SamplerPtr sampler, int batch);
// A copy of t drawing from another point set / clamping its contributions (name updated).
Technique with_points(Technique t, PointSetKind points);
Technique with_clamp(Technique t, double clamp);
// Throws std::invalid_argument if t cannot estimate f (dimensions, point set, domain).
void check_technique(const Integrand &f, const Technique &t);

}  // namespace re
