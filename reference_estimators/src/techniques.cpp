// The techniques' factories (integrands.h): each validates its parameters and names the
// technique as the catalogue and the bindings show it; Technique's uniform count and
// evaluations a sample; and check_technique, which refuses a technique an integrand cannot be
// estimated with.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "integrands.h"

namespace re {

Technique make_uniform_technique(const Domain &domain) {
    Technique t;
    t.name = "uniform";
    t.kind = TechniqueKind::Uniform;
    t.sampler = make_uniform_sampler(domain);
    return t;
}

Technique make_importance_technique(SamplerPtr sampler) {
    if (!sampler) throw std::invalid_argument("importance sampling needs a sampler");
    Technique t;
    t.name = "importance:" + sampler->name;
    t.kind = TechniqueKind::Importance;
    t.sampler = std::move(sampler);
    return t;
}

Technique make_hit_or_miss_technique(SamplerPtr proposal, double c) {
    if (!proposal) throw std::invalid_argument("the rejection method needs a proposal sampler");
    if (!(c > 0 && std::isfinite(c))) {
        std::ostringstream s;
        s << "the rejection method's bound c must be finite and > 0, got " << c;
        throw std::invalid_argument(s.str());
    }
    Technique t;
    t.name = "rejection";
    t.kind = TechniqueKind::HitOrMiss;
    t.sampler = std::move(proposal);
    t.bound = c;
    return t;
}

Technique make_russian_roulette_technique(SamplerPtr sampler, double q, double c, bool reweight) {
    if (!sampler) throw std::invalid_argument("Russian roulette needs a sampler");
    if (!(q > 0 && q <= 1)) {
        std::ostringstream s;
        s << "Russian roulette's survival probability q must be in (0, 1], got " << q;
        throw std::invalid_argument(s.str());
    }
    if (!std::isfinite(c)) throw std::invalid_argument("Russian roulette's constant c must be finite");
    Technique t;
    std::ostringstream name;
    name << (reweight ? "roulette:" : "roulette_biased:") << sampler->name << "(q=" << q << (c != 0 ? ",c=" : "");
    if (c != 0) name << c;
    name << ")";
    t.name = name.str();
    t.kind = TechniqueKind::RussianRoulette;
    t.sampler = std::move(sampler);
    t.rr_q = q;
    t.rr_c = c;
    t.reweight = reweight;
    t.biased = !reweight;
    return t;
}

Technique make_splitting_technique(const Domain &domain, int m) {
    if (domain.kind != DomainKind::Box || domain.dim != 2)
        throw std::invalid_argument("splitting needs a 2-dimensional box domain (outer x0, inner x1), got '" +
                                    domain.kind_name() + "' of dimension " + std::to_string(domain.dim));
    if (m < 1) throw std::invalid_argument("splitting needs M >= 1 inner samples, got " + std::to_string(m));
    Technique t;
    t.name = "splitting(M=" + std::to_string(m) + ")";
    t.kind = TechniqueKind::Splitting;
    t.sampler = make_uniform_sampler(domain);
    t.split = m;
    return t;
}

Technique make_mis_technique(std::vector<SamplerPtr> samplers, double power) {
    if (samplers.size() < 2) throw std::invalid_argument("MIS needs at least two samplers");
    if (!(power >= 1 && std::isfinite(power))) {
        std::ostringstream s;
        s << "MIS heuristic exponent must be >= 1 (1 balance, 2 power), got " << power;
        throw std::invalid_argument(s.str());
    }
    Technique t;
    t.name = std::string(power == 1 ? "mis_balance:" : (power == 2 ? "mis_power:" : "mis_beta:"));
    for (size_t i = 0; i < samplers.size(); ++i) {
        if (!samplers[i]) throw std::invalid_argument("MIS: sampler " + std::to_string(i) + " is missing");
        if (samplers[i]->method != SamplingMethod::Inversion)
            throw std::invalid_argument("MIS: sampler '" + samplers[i]->name + "' must be an inversion sampler");
        if (samplers[i]->domain.dim != samplers[0]->domain.dim)
            throw std::invalid_argument("MIS: samplers '" + samplers[0]->name + "' and '" + samplers[i]->name +
                                        "' draw points of different dimension");
        t.name += (i ? "+" : "") + samplers[i]->name;
    }
    t.kind = TechniqueKind::Mis;
    t.sampler = samplers[0];
    t.mis = std::move(samplers);
    t.mis_power = power;
    return t;
}

Technique make_self_normalized_technique(SamplerPtr sampler, int batch) {
    if (!sampler) throw std::invalid_argument("self-normalised IS needs a sampler");
    if (batch < 1) throw std::invalid_argument("self-normalised IS needs a batch of >= 1 samples, got " + std::to_string(batch));
    if (sampler->method != SamplingMethod::Inversion)
        throw std::invalid_argument("self-normalised IS: sampler '" + sampler->name + "' must be an inversion sampler");
    Technique t;
    t.name = "snis:" + sampler->name + "(b=" + std::to_string(batch) + ")";
    t.kind = TechniqueKind::SelfNormalized;
    t.sampler = std::move(sampler);
    t.batch = batch;
    t.biased = true;  // O(1/b) bias: a ratio of means is not the mean of ratios
    return t;
}

Technique with_points(Technique t, PointSetKind points) {
    if (points != PointSetKind::Random) t.name += std::string("/") + point_set_name(points);
    t.points = points;
    return t;
}

Technique with_clamp(Technique t, double clamp) {
    if (!(clamp > 0) || std::isnan(clamp)) {
        std::ostringstream s;
        s << "clamp must be > 0, got " << clamp;
        throw std::invalid_argument(s.str());
    }
    std::ostringstream name;
    name << "clamped:" << t.name << "(" << clamp << ")";
    t.name = name.str();
    t.clamp = clamp;
    t.biased = true;
    return t;
}

int Technique::udim(const Integrand &f) const {
    switch (kind) {
        case TechniqueKind::Uniform: return f.domain.kind == DomainKind::Box ? f.domain.dim : sampler->udim;
        case TechniqueKind::Importance: return sampler->udim;
        case TechniqueKind::HitOrMiss:
        case TechniqueKind::RussianRoulette: return sampler->udim + 1;
        case TechniqueKind::Splitting: return 1 + split;
        case TechniqueKind::Mis: {
            int d = 0;
            for (auto &s : mis) d += s->udim;
            return d;
        }
        case TechniqueKind::SelfNormalized: return batch * sampler->udim;
    }
    return 0;
}

int Technique::evaluations() const {
    switch (kind) {
        case TechniqueKind::Splitting: return split;
        case TechniqueKind::Mis: return int(mis.size());
        case TechniqueKind::SelfNormalized: return batch;
        default: return 1;
    }
}

void check_technique(const Integrand &f, const Technique &t) {
    auto fail = [&](const std::string &why) {
        throw std::invalid_argument("technique '" + t.name + "' cannot estimate integrand '" + f.name + "': " + why);
    };
    for (const SamplerPtr &s : t.kind == TechniqueKind::Mis ? t.mis : std::vector<SamplerPtr>{t.sampler})
        if (s->domain.dim != f.domain.dim)
            fail("it draws " + std::to_string(s->domain.dim) + "-dimensional points, the integrand is " +
                 std::to_string(f.domain.dim) + "-dimensional");
    if (t.points != PointSetKind::Random && t.sampler->method == SamplingMethod::Rejection)
        fail("a rejection sampler consumes a variable number of uniforms; only random points can feed it");
    if (t.kind == TechniqueKind::Splitting && (f.domain.kind != DomainKind::Box || f.domain.dim != 2))
        fail("splitting needs a 2-dimensional box");
    if (t.kind == TechniqueKind::SelfNormalized && !std::isfinite(f.domain.measure()))
        fail("self-normalised IS against 1 needs a domain of finite measure");
    if ((t.kind == TechniqueKind::HitOrMiss || t.kind == TechniqueKind::RussianRoulette) &&
        t.sampler->method == SamplingMethod::Rejection)
        fail("needs an inversion sampler");
}

}  // namespace re
