// Accumulator states: what one chunk of contributions leaves behind, merged in a fixed
// order into an estimate.
//
// Moments are never formed as E[Y^2] - E[Y]^2.  Each block of finite values is reduced
// two-pass (its own mean, then central moments about it), and blocks are merged with the
// pairwise update of Chan, Golub & LeVeque (1979) extended to M3, M4 by Pebay (2008).  The
// mean is reported from a Neumaier-compensated sum of block sums.  Values are carried
// scaled by a power of two that follows the largest magnitude seen so far, so magnitudes near
// 1e+-300 neither overflow nor underflow in M2..M4 (each rescaling is exact but for underflow
// of values negligible next to the new maximum).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "simd.h"

namespace re {

// Neumaier (1974) compensated sum.
struct CompensatedSum {
    double sum = 0.0, comp = 0.0;
    void add(double v) {
        double t = sum + v;
        comp += std::fabs(sum) >= std::fabs(v) ? (sum - t) + v : (v - t) + sum;
        sum = t;
    }
    double value() const { return sum + comp; }
};

struct Moments {
    double n = 0;            // finite values accumulated
    double mean = 0;         // running mean (scaled units), for the merge deltas
    double m2 = 0, m3 = 0, m4 = 0;
    CompensatedSum total;    // compensated sum of values (scaled units)
    double min = std::numeric_limits<double>::infinity();
    double max = -std::numeric_limits<double>::infinity();
    int scale_exp = 0;       // values are stored times 2^-scale_exp
    bool scale_set = false;

    // Rescales this state to exponent e (e >= scale_exp): multiply by 2^(scale_exp - e).
    void rescale_to(int e) {
        if (!scale_set) { scale_exp = e; scale_set = true; return; }
        int d = scale_exp - e;
        if (d == 0) return;
        double f = std::ldexp(1.0, d), f2 = f * f;
        mean *= f; m2 *= f2; m3 *= f2 * f; m4 *= f2 * f2;
        total.sum *= f; total.comp *= f;
        if (n > 0) { min *= f; max *= f; }
        scale_exp = e;
    }

    // Chan/Pebay merge of another state with the same scale.
    void merge_same_scale(const Moments &b) {
        if (b.n == 0) return;
        if (n == 0) { *this = b; return; }
        double na = n, nb = b.n, nn = na + nb;
        double delta = b.mean - mean, dn = delta / nn;
        double dn2 = dn * dn, t1 = delta * dn * na * nb;
        m4 += b.m4 + t1 * dn2 * (na * na - na * nb + nb * nb) + 6.0 * dn2 * (na * na * b.m2 + nb * nb * m2) +
              4.0 * dn * (na * b.m3 - nb * m3);
        m3 += b.m3 + t1 * dn * (na - nb) + 3.0 * dn * (na * b.m2 - nb * m2);
        m2 += b.m2 + t1;
        mean += dn * nb;
        n = nn;
        total.add(b.total.sum);
        total.add(b.total.comp);
        min = std::min(min, b.min);
        max = std::max(max, b.max);
    }

    void merge(Moments b) {
        if (b.n == 0) return;
        if (n == 0) { *this = b; return; }
        // A side that has seen only zeros has no scale yet: it takes the other's.
        int e = !scale_set ? b.scale_exp : (!b.scale_set ? scale_exp : std::max(scale_exp, b.scale_exp));
        rescale_to(e);
        b.rescale_to(e);
        merge_same_scale(b);
    }
};

// Picks the power of two that brings a block's largest magnitude near 1.
inline int scale_exponent_for(double maxabs) {
    int e = std::ilogb(maxabs);
    return std::clamp(e, -1000, 1000);
}

// Block reductions run over 8 logical lanes in a fixed order, held in native-width vectors
// (simd.h): 1 x 8 with AVX-512, 2 x 4 with AVX, 4 x 2 otherwise.  The arithmetic per logical
// lane is the same in all three, so results are bitwise identical across ISAs.
using simd::f64v;
using simd::i64v;
constexpr size_t kVecWidth = simd::kWidth;
constexpr size_t kLanes = 8, kParts = kLanes / kVecWidth;

// Sum of the 8 logical lanes of parts[0..kParts), always in the same tree order.
template <class V>
RE_INLINE double lane_sum(const V (&parts)[kParts]) {
    double l[kLanes];
    for (size_t k = 0; k < kParts; ++k)
        for (size_t w = 0; w < kVecWidth; ++w) l[k * kVecWidth + w] = double(parts[k][w]);
    return ((l[0] + l[1]) + (l[2] + l[3])) + ((l[4] + l[5]) + (l[6] + l[7]));
}

// One vector pass over a block: the lane sums, the smallest and the largest of the
// (unscaled) values.  Three operations per vector; what screening needs follows from them: a
// NaN or an infinity makes the sum non-finite (the converse fails only where a finite sum
// overflows, and then the slow path counts exactly), and a negative value makes min < 0.
struct BlockScan {
    double sum = 0;
    double min = std::numeric_limits<double>::infinity(), max = -std::numeric_limits<double>::infinity();
    bool maybe_nonfinite() const { return !(std::fabs(sum) <= std::numeric_limits<double>::max()); }
    double maxabs() const { return std::max(-min, max); }  // -inf for an empty block
};

// The scan of `count` values, value(i) giving the vector of values i .. i + kVecWidth and
// value_one(i) value i alone (each called once per value, in order within its lane).
template <class Value, class ValueOne>
RE_INLINE BlockScan scan_values(size_t count, Value value, ValueOne value_one) {
    const size_t full = count / kLanes * kLanes;
    const f64v zero = {}, inf = zero + std::numeric_limits<double>::infinity();
    f64v s[kParts], lo[kParts], hi[kParts];
    for (size_t k = 0; k < kParts; ++k) { s[k] = zero; lo[k] = inf; hi[k] = -inf; }
    for (size_t i = 0; i < full; i += kLanes)
        for (size_t k = 0; k < kParts; ++k) {
            f64v v = value(i + k * kVecWidth);
            s[k] += v;
            lo[k] = v < lo[k] ? v : lo[k];
            hi[k] = v > hi[k] ? v : hi[k];
        }
    BlockScan r;
    for (size_t k = 0; k < kParts; ++k)
        for (size_t w = 0; w < kVecWidth; ++w) { r.min = std::min(r.min, lo[k][w]); r.max = std::max(r.max, hi[k][w]); }
    r.sum = lane_sum(s);
    for (size_t i = full; i < count; ++i) {
        const double v = value_one(i);
        r.sum += v;
        r.min = std::min(r.min, v);
        r.max = std::max(r.max, v);
    }
    return r;
}

RE_INLINE BlockScan scan_block(const double *y, size_t count) {
    return scan_values(count, [y](size_t i) { return simd::load(y + i); }, [y](size_t i) { return y[i]; });
}

// y = f / p, and scan_block of it, in one pass (the same bits as the two).
RE_INLINE BlockScan divide_and_scan(const double *f, const double *p, double *y, size_t count) {
    return scan_values(
        count,
        [=](size_t i) {
            const f64v v = simd::load(f + i) / simd::load(p + i);
            simd::store(y + i, v);
            return v;
        },
        [=](size_t i) { return y[i] = f[i] / p[i]; });
}

// Adds y[0..count) (finite, unscaled; `scan` is scan_block of them) as one block: two-pass
// within the block (the block's mean from the scan's sum, then central moments about it),
// then merge.  Compilers' own vectorisation of these reductions was 2-3x slower than these
// explicit lanes.  The scaled value v 2^-e is exact (a power of two, and v is at most 2 after
// scaling), so d = fma(v, 2^-e, -mean) rounds once, as (v 2^-e) - mean would; the min and max
// of the scaled values are the scan's, scaled (scaling is monotone).
RE_INLINE void accumulate_block(Moments &acc, const double *y, size_t count, bool higher, const BlockScan &scan) {
    if (count == 0) return;
    const size_t full = count / kLanes * kLanes;
    const f64v zero = {};
    // The scale follows the largest magnitude seen so far, so scaled values stay <= 2.
    const double maxabs = scan.maxabs();
    if (maxabs > 0) {
        int e = scale_exponent_for(maxabs);
        if (!acc.scale_set || e > acc.scale_exp) acc.rescale_to(e);
    }
    const double scale = acc.scale_set ? std::ldexp(1.0, -acc.scale_exp) : 1.0;
    // Scaling by a power of two commutes with rounding unless something over- or underflows:
    // then the sum is redone on scaled values (same lane order, so a deterministic choice).
    double sum = scan.sum * scale;
    if (scan.maybe_nonfinite() || maxabs < 0x1p-1000) {
        f64v s[kParts];
        for (size_t k = 0; k < kParts; ++k) s[k] = zero;
        for (size_t i = 0; i < full; i += kLanes)
            for (size_t k = 0; k < kParts; ++k) s[k] += simd::load(y + i + k * kVecWidth) * scale;
        sum = lane_sum(s);
        for (size_t i = full; i < count; ++i) sum += y[i] * scale;
    }
    const double nb = double(count), mb = sum / nb;
    const f64v vscale = zero + scale, vmean = zero - mb;

    f64v c2[kParts], c3[kParts], c4[kParts];
    for (size_t k = 0; k < kParts; ++k) c2[k] = c3[k] = c4[k] = zero;
    if (higher) {
        for (size_t i = 0; i < full; i += kLanes)
            for (size_t k = 0; k < kParts; ++k) {
                f64v d = simd::fma(simd::load(y + i + k * kVecWidth), vscale, vmean), d2 = d * d;
                c2[k] += d2;
                c3[k] = simd::fma(d2, d, c3[k]);
                c4[k] = simd::fma(d2, d2, c4[k]);
            }
    } else {
        for (size_t i = 0; i < full; i += kLanes)
            for (size_t k = 0; k < kParts; ++k) {
                f64v d = simd::fma(simd::load(y + i + k * kVecWidth), vscale, vmean);
                c2[k] += d * d;  // as above: M2 does not depend on `higher`
            }
    }
    Moments b;
    b.scale_exp = acc.scale_exp;
    b.scale_set = acc.scale_set;
    b.n = nb;
    b.mean = mb;
    b.m2 = lane_sum(c2);
    b.m3 = lane_sum(c3);
    b.m4 = lane_sum(c4);
    b.min = scan.min * scale;
    b.max = scan.max * scale;
    for (size_t i = full; i < count; ++i) {
        double d = std::fma(y[i], scale, -mb), d2 = d * d;
        b.m2 += d2;
        if (higher) {
            b.m3 = std::fma(d2, d, b.m3);
            b.m4 = std::fma(d2, d2, b.m4);
        }
    }
    b.total.sum = sum;
    acc.merge_same_scale(b);
}

// What went wrong, with counts and the first examples (lowest sample index first).
enum class Issue : int {
    NaN = 0,
    PosInf,
    NegInf,
    Negative,         // negative contribution (an error only for non-negative integrands)
    OutsideDomain,    // sampler returned a point outside its own domain
    ZeroPdf,          // sampled point where the claimed pdf is 0
    BadPdf,           // pdf NaN, infinite or negative
    BoundViolation,   // rejection: f(x) > c p(x)
    Count_
};
constexpr int kIssueKinds = int(Issue::Count_);
constexpr size_t kMaxExamples = 8;

struct Example {
    int kind = 0;
    uint64_t index = 0;   // sample index within the estimate
    double point[3] = {0, 0, 0};
    int dim = 0;
    double value = 0;     // the offending contribution, pdf or f/(c p)
};

struct Diagnostics {
    uint64_t counts[kIssueKinds] = {0};
    uint64_t drawn = 0;        // samples drawn (finite or not)
    uint64_t candidates = 0;   // rejection: candidates tried
    // blocks an estimator's fast path (Estimate::kernel) handed back to the general path,
    // which reports what it found there: a speed diagnostic, not stored with a state
    uint64_t redone_blocks = 0;
    // blocks that drew their u0s inside the sampler's loop or an MIS pair's fused loop, handed
    // back or not (what Estimate::kernel names; likewise not stored)
    uint64_t inside_blocks = 0;
    std::vector<Example> examples;

    size_t examples_of(Issue kind) const {
        size_t seen = 0;
        for (const auto &e : examples) seen += e.kind == int(kind);
        return seen;
    }
    // Keeps an example (if fewer than kMaxExamples of its kind are kept) without counting.
    void note(Issue kind, uint64_t index, const double *x, int dim, double value) {
        if (examples_of(kind) >= kMaxExamples) return;
        Example ex;
        ex.kind = int(kind);
        ex.index = index;
        ex.dim = dim;
        for (int j = 0; j < std::min(dim, 3); ++j) ex.point[j] = x[j];
        ex.value = value;
        examples.push_back(ex);
    }
    void record(Issue kind, uint64_t index, const double *x, int dim, double value) {
        counts[int(kind)]++;
        note(kind, index, x, dim, value);
    }
    void merge(const Diagnostics &b) {
        for (int k = 0; k < kIssueKinds; ++k) {
            size_t seen = 0;
            for (const auto &e : examples) seen += e.kind == k;
            for (const auto &e : b.examples)
                if (e.kind == k && seen < kMaxExamples) { examples.push_back(e); ++seen; }
            counts[k] += b.counts[k];
        }
        drawn += b.drawn;
        candidates += b.candidates;
        redone_blocks += b.redone_blocks;
        inside_blocks += b.inside_blocks;
    }
};

// Screens a block of contributions and accumulates what is usable: NaN and +-Inf are
// counted, noted and left out; negatives are counted, noted and kept.  One vector pass when
// nothing is wrong (a second one where a value is negative); the slow path runs only for blocks with something to report.  y is
// compacted in place.  x (may be null) holds the points, for the examples; entry i is sample
// index[i] when `index` is given (a block compacted before), else first_index + i.
// (known: scan_block(y, count) where the caller has it already)
inline void screen_and_accumulate(Moments &acc, Diagnostics &diag, double *y, const double *x, int dim,
                                  size_t count, uint64_t first_index, bool higher, const uint64_t *index = nullptr,
                                  const BlockScan *known = nullptr) {
    BlockScan scan = known ? *known : scan_block(y, count);
    auto point = [&](size_t i) { return x ? x + i * dim : nullptr; };
    auto sample = [&](size_t i) { return index ? index[i] : first_index + i; };
    const int d = x ? dim : 0;
    if (!scan.maybe_nonfinite()) {
        if (scan.min < 0) {
            size_t want = kMaxExamples - std::min(kMaxExamples, diag.examples_of(Issue::Negative));
            for (size_t i = 0; i < count; ++i)
                if (y[i] < 0.0) {
                    diag.counts[int(Issue::Negative)]++;
                    if (want > 0) { diag.note(Issue::Negative, sample(i), point(i), d, y[i]); --want; }
                }
        }
        accumulate_block(acc, y, count, higher, scan);
        return;
    }
    size_t kept = 0;
    for (size_t i = 0; i < count; ++i) {
        double v = y[i];
        if (v != v) diag.record(Issue::NaN, sample(i), point(i), d, v);
        else if (v == std::numeric_limits<double>::infinity()) diag.record(Issue::PosInf, sample(i), point(i), d, v);
        else if (v == -std::numeric_limits<double>::infinity()) diag.record(Issue::NegInf, sample(i), point(i), d, v);
        else {
            if (v < 0.0) diag.record(Issue::Negative, sample(i), point(i), d, v);
            y[kept++] = v;
        }
    }
    accumulate_block(acc, y, kept, higher, scan_block(y, kept));
}

}  // namespace re
