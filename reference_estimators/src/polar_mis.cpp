#include "polar_mis.h"

#include <type_traits>

#include "direction_samplers.h"

namespace re {
namespace {

using simd::f64v;
using simd::i64v;

constexpr size_t kW = simd::kWidth;
constexpr size_t kRowSamples = LaneGenerator::kEvensPerRow / 2;   // samples a generator row serves
static_assert(kRowSamples % kW == 0, "a generator row holds whole vectors of each technique's u0s");
static_assert(kRowSamples % kLanes == 0, "scan_values' steps fall on the rows' starts");

// bad += 1 in the lanes whose sample the screening rejects: either technique's draw (a cosine
// no direction of its domain has, a pdf not in (0, max double]: Sampler::sample_polar's test)
template <class S0, class S1>
RE_INLINE void count_rejected(f64v z0, f64v p0, f64v z1, f64v p1, i64v &bad) {
    bad += (S0::polar_valid(z0, p0) & S1::polar_valid(z1, p1)) ? i64v{} : i64v{} + 1;
}

// The contributions of kW samples from their directions' cosines (z0: technique 0's, z1:
// technique 1's), with f the pdf of technique FPdf; bad counts, per lane, the samples the
// screening rejects.  As
// estimator_blocks.cpp's polar_mis computes them with add_pair_terms (the same bits): technique 0's
// term at its point (p0, and technique 1's pdf q1 there), technique 1's at its own (q0, p1),
// y = (0 + term_0) + term_1.
template <class S0, class S1, int FPdf, bool Power>
RE_INLINE f64v pair_terms(const S0 &s0, const S1 &s1, f64v z0, f64v z1, i64v &bad) {
    const f64v p0 = s0.density(z0), p1 = s1.density(z1);
    count_rejected<S0, S1>(z0, p0, z1, p1, bad);
    const f64v q1 = s1.polar_pdf_v(z0), q0 = s0.polar_pdf_v(z1);
    const f64v f0 = FPdf == 0 ? p0 : q1, f1 = FPdf == 1 ? p1 : q0;
    // w_a f / p_a at the pdfs (w0, w1) of the two techniques, `own` technique a's
    auto term = [](f64v f, f64v own, f64v w0, f64v w1) __attribute__((always_inline)) {
        if constexpr (Power) return f == f64v{} ? f64v{} : (f64v{} + own) * f / ((f64v{} + w0 * w0) + w1 * w1);
        else return f == f64v{} ? f64v{} : f / ((f64v{} + w0) + w1);
    };
    return (f64v{} + term(f0, p0, p0, q1)) + term(f1, p1, q0, p1);
}

// The cosines of a generator row's samples, each technique's in kRowSamples / kW vectors.
template <class S0, class S1>
struct RowCosines {
    static constexpr size_t kVectors = kRowSamples / kW;
    f64v z0[kVectors], z1[kVectors];
    RE_INLINE RowCosines(const S0 &s0, const S1 &s1, LaneGenerator::Rows<true> &draw) {
        alignas(64) double row[LaneGenerator::kEvensPerRow];
        draw.next(row);
        for (size_t v = 0; v < kVectors; ++v) {
            f64v u0, u1;
            simd::deinterleave(row + 2 * kW * v, u0, u1);
            z0[v] = s0.cos_theta(u0);
            z1[v] = s1.cos_theta(u1);
        }
    }
};

// The profile's prefixes of pair_kernel (FusedPairKernel): up to `last` (before the
// contributions), the values' sums into p and q.
template <class S0, class S1>
size_t pair_prefix(const S0 &s0, const S1 &s1, Stage last, LaneGenerator &gen, size_t rows, double *p, double *q) {
    using Cosines = RowCosines<S0, S1>;
    i64v bad = {};
    LaneGenerator::Rows<true> draw(gen);
    for (size_t r = 0; r < rows; ++r) {
        const Cosines row(s0, s1, draw);
        for (size_t v = 0; v < Cosines::kVectors; ++v) {
            const f64v z0 = row.z0[v], z1 = row.z1[v];
            f64v p0 = s0.density(z0), p1 = s1.density(z1);
            if (last >= Stage::Screened) count_rejected<S0, S1>(z0, p0, z1, p1, bad);
            if (last >= Stage::Weighted) {
                p0 += s1.polar_pdf_v(z0);
                p1 += s0.polar_pdf_v(z1);
            }
            simd::store(p + r * kRowSamples + v * kW, p0);
            simd::store(q + r * kRowSamples + v * kW, p1);
        }
    }
    return simd::lane_total(bad);
}

// FusedPairKernel for samplers of types S0 and S1, f the pdf of technique FPdf, the power
// heuristic (beta = 2) or the balance heuristic.  A row's cosines are drawn a row ahead of its
// terms, so that its chain of dependent divisions (GGX: a division, a root, a division) comes
// before the last row's terms in the loop, and the divider that bounds the loop has work
// while they wait on it.  ggx_lobe's cosine + GGX pair, one thread, ns a sample: the passes
// 4.4; one loop, each row's cosines with its terms, 3.9 (two rows at a time 3.7, four 4.0:
// out of registers); a row ahead 3.3 (two rows ahead no better).  The divider's floor is 2.9
// (six divisions and two roots a sample).  y's scan after, one pass over the block in L1.
template <class S0, class S1, int FPdf, bool Power>
size_t pair_kernel(const Sampler &a, const Sampler &b, Stage last, LaneGenerator &gen, size_t rows, double *y,
                   double *p, double *q, BlockScan &scan) {
    const S0 &s0 = static_cast<const S0 &>(a);
    const S1 &s1 = static_cast<const S1 &>(b);
    if (last < Stage::Contributions) return pair_prefix(s0, s1, last, gen, rows, p, q);
    using Cosines = RowCosines<S0, S1>;
    i64v bad = {};
    if (rows > 0) {
        LaneGenerator::Rows<true> draw(gen);
        Cosines ahead(s0, s1, draw);
        for (size_t r = 0; r < rows; ++r) {
            const Cosines now = ahead;
            if (r + 1 < rows) ahead = Cosines(s0, s1, draw);
            for (size_t v = 0; v < Cosines::kVectors; ++v)
                simd::store(y + r * kRowSamples + v * kW,
                            pair_terms<S0, S1, FPdf, Power>(s0, s1, now.z0[v], now.z1[v], bad));
        }
    }
    scan = scan_block(y, rows * kRowSamples);
    return simd::lane_total(bad);
}

// fn(pointer to T), T the direction sampler type of s; null where s is none of them.
template <class Fn>
FusedPairKernel with_direction_type(const Sampler &s, Fn fn) {
    if (dynamic_cast<const UniformHemisphere *>(&s)) return fn(static_cast<const UniformHemisphere *>(nullptr));
    if (dynamic_cast<const UniformSphere *>(&s)) return fn(static_cast<const UniformSphere *>(nullptr));
    if (dynamic_cast<const CosineHemisphere *>(&s)) return fn(static_cast<const CosineHemisphere *>(nullptr));
    if (dynamic_cast<const UniformCone *>(&s)) return fn(static_cast<const UniformCone *>(nullptr));
    if (dynamic_cast<const Ggx *>(&s)) return fn(static_cast<const Ggx *>(nullptr));
    return nullptr;
}

}  // namespace

FusedPairKernel fused_polar_pair(const Sampler &s0, const Sampler &s1, int f_is_pdf, double beta) {
    if ((beta != 1 && beta != 2) || (f_is_pdf != 0 && f_is_pdf != 1)) return nullptr;
    // the sampler f equals: of a type with a named polar function
    if (!dynamic_cast<const Ggx *>(f_is_pdf == 0 ? &s0 : &s1)) return nullptr;
    const bool power = beta == 2;
    return with_direction_type(f_is_pdf == 0 ? s1 : s0, [&](auto *other) -> FusedPairKernel {
        using O = std::remove_const_t<std::remove_pointer_t<decltype(other)>>;
        if (f_is_pdf == 0) return power ? &pair_kernel<Ggx, O, 0, true> : &pair_kernel<Ggx, O, 0, false>;
        return power ? &pair_kernel<O, Ggx, 1, true> : &pair_kernel<O, Ggx, 1, false>;
    });
}

}  // namespace re
