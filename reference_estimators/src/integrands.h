// Integrands with exact reference values, and the catalogue of cases the harness ships:
// smooth, stiff (a peak of width 1e-6), discontinuous, singular, heavy-tailed, extreme in
// magnitude, offset (ruins E[f^2] - E[f]^2), and 16-dimensional.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "domain.h"
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
};
using IntegrandPtr = std::shared_ptr<const Integrand>;

enum class TechniqueKind { Uniform, Importance, HitOrMiss };

// How contributions Y are formed:
//   Uniform     Y = |D| f(X),           X uniform on D              (background eq. 3)
//   Importance  Y = f(X) / p(X),        X ~ p                       (eq. 4)
//   HitOrMiss   Y = c 1{xi c p(X) < f(X)}, X ~ p: the rejection method's acceptance rate
//               estimates the integral, E[Y] = c P(accept) = I when f <= c p holds.
struct Technique {
    std::string name;
    TechniqueKind kind = TechniqueKind::Uniform;
    SamplerPtr sampler;
    double bound = 0;                 // c, HitOrMiss only
    int finite_variance = -1;         // 1 known finite, 0 known infinite, -1 unknown
    std::string note;
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

}  // namespace re
