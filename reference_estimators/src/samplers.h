// Samplers as batch objects over arrays: sample(u) -> (x, pdf), pdf(x), invert(x), and a
// stream-driven draw() that also serves samplers needing a variable number of uniforms
// (rejection).  One virtual call per block, never per sample.
#pragma once
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "accumulator.h"
#include "domain.h"
#include "pcg32.h"

namespace re {

class Integrand;

enum class SamplingMethod { Inversion, Rejection };

class Sampler {
  public:
    virtual ~Sampler() = default;

    std::string name;                        // registry name, e.g. "ggx"
    std::map<std::string, double> params;    // its parameters, for display and re-creation
    Domain domain;                           // where its points live
    int udim = 1;                            // canonical uniforms per point (inversion)
    SamplingMethod method = SamplingMethod::Inversion;
    bool invertible = true;

    // x[n * domain.dim] and pdf[n] from u[n * udim].  Inversion samplers only.
    virtual void sample(const double *u, double *x, double *pdf, size_t n) const = 0;
    // sample(), and whether every point lies in `domain` with a pdf in (0, max double]: the
    // estimators' screening of every sampled block (they look at single points only when
    // not), in the same pass where a sampler can (the direction samplers test their vector
    // lanes before storing them).  Inversion samplers only.
    virtual bool sample_valid(const double *u, double *x, double *pdf, size_t n) const;
    virtual void pdf(const double *x, double *p, size_t n) const = 0;
    // u[n * udim] from x; NaN rows for points outside the support.
    virtual void invert(const double *x, double *u, size_t n) const;
    // n points from a stream; rejection samplers count candidates and bound violations.
    virtual void draw(UniformStream &stream, double *x, double *pdf, size_t n, uint64_t first_index,
                      Diagnostics &diag) const;
    // Direction samplers whose pdf depends on a direction through its z = cos(theta) alone
    // (`polar`): sample_polar gives z[n] and pdf[n] of the points sample() draws from uniforms
    // whose u0 for point i is u[i * stride] (z = their x[3 i + 2], the same bits, without the
    // azimuth; u1 is not read) and returns how many of them fail the screening sample_valid
    // applies, on z alone (z^2 - 1 <= kUnitTolerance, and z >= 0 on the hemisphere; the pdf in
    // (0, max double]); pdf_polar is pdf() at directions of cosine z[n] (0 where no direction
    // of the domain has it).  The estimators' path for integrands that read z alone
    // (Integrand::polar).  Others throw std::logic_error.
    bool polar = false;
    virtual size_t sample_polar(const double *u, size_t stride, double *z, double *pdf, size_t n) const;
    // sample_polar for rows * LaneGenerator::kEvensPerRow points whose u0 are the even-numbered
    // uniforms of the next rows generator rows (stride 1: fill_even's values), drawn from `gen`
    // row by row as the loop uses them (LaneGenerator::Rows), the odd lanes skipped after:
    // the same results and the same stream position as fill_even then sample_polar, with the
    // generator's work overlapping the sampler's divisions.
    virtual size_t sample_polar_rows(LaneGenerator &gen, size_t rows, double *z, double *pdf) const;
    virtual void pdf_polar(const double *z, double *pdf, size_t n) const;
    // The function of z that the pdf is on the sampler's domain, by name (empty: none named).
    // An integrand whose polar_function has the same name computes the same bits at every z
    // of that domain (both call one function with the same parameters, e.g. ggx_pdf_name):
    // the polar path then reads f off the pdf it already has, as drjit merges the same
    // expression computed twice (a division a point fewer on GGX).
    std::string polar_function;
    // The path sample() takes for whole vectors of points, by name, where a sampler has more
    // than one: "small table in vector lanes" (the 2-D table's SmallTable2D), else "batch loop".
    virtual std::string kernel() const { return "batch loop"; }
    std::string describe() const;
};

using SamplerPtr = std::shared_ptr<const Sampler>;

// Whether a pdf value is usable: in (0, max double] (NaN, infinite, negative and 0 are not),
// for double or simd::f64v (a bool, or a lane mask).
template <class V>
RE_INLINE auto valid_pdf(V p) { return (p > 0.0) & (p <= std::numeric_limits<double>::max()); }

// How many of the pdf values p[0..n) are not valid_pdf, in vector lanes.
size_t count_invalid_pdfs(const double *p, size_t n);
// The estimators' screening of sampled points: whether every point of x (n points) lies in
// `dom` and every pdf value of p is valid_pdf.
inline bool all_valid(const Domain &dom, const double *x, const double *p, size_t n) {
    return count_invalid_pdfs(p, n) == 0 && dom.count_outside(x, n) == 0;
}

// Registry: names, parameter names with defaults, and what each sampler is.
struct SamplerInfo {
    std::string name, method, domain, description;
    std::vector<std::pair<std::string, double>> params;  // name, default
    bool needs_table = false;                            // piecewise-constant: values
};
const std::vector<SamplerInfo> &sampler_registry();

// Builds a sampler; unknown names, unknown or invalid parameters throw std::invalid_argument
// naming the parameter and the rule.  `table` / `table_shape` feed piecewise-constant ones.
SamplerPtr make_sampler(const std::string &name, const std::map<std::string, double> &params,
                        const std::vector<double> &table = {}, const std::vector<size_t> &table_shape = {});

// The rejection method: points with density target(x) / target.reference, from a
// proposal with the user's bound c (target(x) <= c * proposal_pdf(x) must hold).
SamplerPtr make_rejection_sampler(std::shared_ptr<const Integrand> target, SamplerPtr proposal, double c);

// Uniform density over a finite domain (box, hemisphere, sphere).
SamplerPtr make_uniform_sampler(const Domain &domain);

}  // namespace re
