// Piecewise-linear tables looked up in batch: the sampler check's Rosenblatt transform
// (harness/samplers/transform.py) maps a million points through CDFs tabulated on a few
// thousand leaves of very different widths, in strips.  numpy's searchsorted over unsorted
// queries cost about 0.26-0.5 us a point there (a long, mispredicted binary search, one numpy
// call per strip); a bucket index narrows each search to a few leaves.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "thread_pool.h"

namespace re {

// The first element of the sorted a[0 .. n) greater than x (std::upper_bound), by a search
// without branches on the data: in a table lookup the comparisons are unpredictable, and a
// mispredicted branch per step cost more than the rest of the lookup.  x must not be NaN.
inline const double *upper_bound_branchless(const double *a, size_t n, double x) {
    if (n == 0) return a;
    while (n > 1) {
        const size_t half = n / 2;
        a = a[half] <= x ? a + half : a;
        n -= half;
    }
    return a + (a[0] <= x);
}

// upper_bound over a short sorted array (the strip edges of the Rosenblatt transform) through
// a bucket index of 1024 buckets over [0, 1]: the answer for x in bucket b lies between the
// first elements at or above b / 1024 and (b + 1) / 1024 (the outer buckets reach to the ends,
// so values outside [0, 1] are answered too), mostly a single candidate.  x must not be NaN.
class BucketedUpperBound {
  public:
    BucketedUpperBound(const double *a, size_t n) : a_(a), n_(n), first_(kBuckets + 1) {
        size_t i = 0;
        for (size_t b = 0; b <= kBuckets; ++b) {
            while (i < n && a[i] < double(b) / double(kBuckets)) ++i;
            first_[b] = i;
        }
    }
    size_t operator()(double x) const {
        double f = x * double(kBuckets);
        const size_t b = f < 0 ? 0 : (f < double(kBuckets - 1) ? size_t(f) : kBuckets - 1);
        const size_t begin = b == 0 ? 0 : first_[b], end = b == kBuckets - 1 ? n_ : first_[b + 1];
        return size_t(upper_bound_branchless(a_ + begin, end - begin, x) - a_);
    }

  private:
    static constexpr size_t kBuckets = 1024;
    const double *a_;
    size_t n_;
    std::vector<size_t> first_;
};

// A piecewise-linear table over leaves [lo, hi) in strips (leaves offsets[g] .. offsets[g+1]-1
// of strip g, sorted by lo, inside [0, 1]), looked up in batch.  A two-level bucket index
// narrows each search to the leaves that start in the point's sub-bucket, and the one before:
// mostly one or two candidates, told apart by one comparison without a branch.  The top level
// has B buckets per strip (a power of two, about two per leaf of the fullest strip, 256 to
// 2^14, at most 2^16 in all, so that it stays in cache); bucket b is cut into S_b sub-buckets
// (S_b = 1 where at most one leaf starts in it; else a power of two, about four per leaf
// starting there, to 2^16): a narrow lobe's leaves, down to 2^-40 wide, crowd into a few
// buckets, where a one-level index left a binary search of seven dependent loads and its
// mispredicted loop a point.  Every lookup takes the same path (bucket, sub-bucket, leaf),
// so the branch predictor has nothing to miss.  Bucket and sub-bucket edges are exact binary
// fractions and a point's sub-bucket is read off the bits of floor(x 2^52) (exact), so the
// index agrees with the comparisons lo <= x it stands for, and the answer does not depend on it.
class PiecewiseLinearTable {
  public:
    PiecewiseLinearTable(const double *lo, const double *hi, const double *start, const double *mass,
                         const int64_t *offsets, int64_t strips)
        : offsets_(offsets), strips_(strips), leaves_(size_t(offsets[strips]) + 1) {
        // a leaf's four numbers side by side: one cache line a lookup instead of four; the
        // last leaf is a sentinel that no x reaches (lo = +inf), so a lookup may always read
        // the leaf after its first candidate, and whose value is NaN (start)
        for (size_t i = 0; i + 1 < leaves_.size(); ++i) leaves_[i] = {lo[i], hi[i], start[i], mass[i]};
        leaves_.back() = {__builtin_inf(), __builtin_inf(), __builtin_nan(""), 0.0};
        int64_t most = 0;
        for (int64_t g = 0; g < strips; ++g) most = std::max(most, offsets[g + 1] - offsets[g]);
        const int64_t cap = std::max<int64_t>(256, (int64_t(1) << 16) / std::max<int64_t>(strips, 1));
        while (buckets_ < 2 * most && buckets_ < (int64_t(1) << 14) && buckets_ < cap) buckets_ *= 2, ++log2_buckets_;
        // the first leaf of strip g at or after `edge`, searched from leaf i on
        auto first_from = [&](int64_t g, int64_t i, double edge) {
            while (i < offsets[g + 1] && lo[i] < edge) ++i;
            return i;
        };
        index_.resize(size_t(strips * buckets_));
        const double B = double(buckets_);
        for (int64_t g = 0; g < strips; ++g) {
            int64_t i = offsets[g], next = first_from(g, i, 0.0);
            for (int64_t b = 0; b < buckets_; ++b) {
                i = next;
                next = first_from(g, i, double(b + 1) / B);
                int shift = 0;
                while ((int64_t(1) << shift) < 4 * (next - i) && next - i > 1 && shift < 16) ++shift;
                const int64_t S = int64_t(1) << shift;
                index_[size_t(g * buckets_ + b)] = {int32_t(subs_.size()), shift};
                // subs_[base + j]: the first leaf of strip g whose lo >= (b + j / S) / B
                // (offsets[g + 1] if none), j = 0 .. S; the edges are exact
                int64_t k = i;
                for (int64_t j = 0; j < S; ++j)
                    subs_.push_back(int32_t(k = first_from(g, k, (double(b) + double(j) / double(S)) / B)));
                subs_.push_back(int32_t(next));
            }
        }
    }

    // out[j * ostride] = the table's value at the point x[j * xstride] of strip g[j] (strip 0
    // when g is null), for j < n: for the leaf i of strip g with the largest lo[i] <= x (the
    // strip's first leaf when none is), start[i] + mass[i] * clamp((x - lo[i]) / (hi[i] -
    // lo[i]), 0, 1), clamped to [0, 1]; NaN for a strip outside [0, strips), an empty strip or
    // a NaN x.  Each point's leaf index to leaves[j] if asked (the sentinel's, the last, where
    // its value is NaN).
    void lookup(const int64_t *g, const double *x, size_t xstride, size_t n, double *out, size_t ostride,
                int64_t *leaves = nullptr) const {
        leaves ? lookup_leaves<true>(g, x, xstride, n, out, ostride, leaves)
               : lookup_leaves<false>(g, x, xstride, n, out, ostride, leaves);
    }

    // fn (non-decreasing in x, NaN aside) per leaf: for each of strip 0's leaves its value on
    // every x the lookup maps to that leaf, and fn(NaN) for the others and the sentinel (a NaN
    // x's).  Empty where strip 0 is empty or fn is not constant on some leaf's span.
    template <class Fn>
    std::vector<int64_t> per_leaf(Fn fn) const {
        if (strips_ < 1) return {};
        const int64_t first = offsets_[0], end = offsets_[1];
        if (end <= first) return {};
        std::vector<int64_t> of(leaves_.size(), fn(__builtin_nan("")));
        for (int64_t i = first; i < end; ++i) {
            // leaf i answers for [lo_i, lo_{i+1}), the first from -inf, the last to +inf
            const double from = i == first ? -__builtin_inf() : leaves_[size_t(i)].lo;
            const double to = i + 1 == end ? __builtin_inf() : std::nextafter(leaves_[size_t(i) + 1].lo, -__builtin_inf());
            if (fn(from) != fn(to)) return {};
            of[size_t(i)] = fn(from);
        }
        return of;
    }

  private:
    // lookup, the leaves stored or not by a template (a test of `leaves` in the loop had cost
    // the interval's transform a tenth of its time).  A batch of points goes through four
    // passes, each with one level of the lookup's dependent loads (the bucket, its sub-bucket's
    // candidates, the candidate after the first, the leaf's numbers), so that the out-of-order
    // core overlaps that level's loads across the batch, where two passes (each point's leaf
    // by its whole chain of loads, then its value) had it waiting on one point's chain at a
    // time: a GGX check's Rosenblatt transform (a million points; marginal 2 092 leaves,
    // conditional 28 544 in 32 strips) on one thread 30-32 -> 18-21 ms.  Batches of 64: 256
    // and more came out 5-10 % slower.
    template <bool kLeaves>
    void lookup_leaves(const int64_t *g, const double *x, size_t xstride, size_t n, double *out, size_t ostride,
                       int64_t *leaves) const {
        constexpr size_t kBatch = 64;
        int64_t first[kBatch], strip[kBatch];   // pass 1: subs_ slot (-1: NaN leaf), strip; then begin, end
        uint32_t found[kBatch];
        const uint32_t nan_leaf = uint32_t(leaves_.size() - 1);
        if (strips_ < 1) {   // no strip to look up: every point's value is the NaN leaf's (the passes
                             // below read strip 0's index in place of a bad point's)
            for (size_t j = 0; j < n; ++j) out[j * ostride] = value(nan_leaf, x[j * xstride]);
            if (kLeaves) std::fill(leaves, leaves + n, int64_t(nan_leaf));
            return;
        }
        for (size_t a = 0; a < n; a += kBatch) {
            const size_t m = std::min(kBatch, n - a);
            for (size_t j = 0; j < m; ++j) sub_bucket(g ? g[a + j] : 0, x[(a + j) * xstride], first[j], strip[j]);
            for (size_t j = 0; j < m; ++j) candidates(first[j], strip[j]);
            for (size_t j = 0; j < m; ++j)
                found[j] = first[j] < 0 ? nan_leaf : leaf(first[j], strip[j], x[(a + j) * xstride]);
            for (size_t j = 0; j < m; ++j) out[(a + j) * ostride] = value(found[j], x[(a + j) * xstride]);
            if (kLeaves)
                for (size_t j = 0; j < m; ++j) leaves[a + j] = int64_t(found[j]);
        }
    }

    // Pass 1 of a lookup: the slot in subs_ of the sub-bucket (g, x) falls in, to `slot`, and
    // the strip to `strip`; slot -1 for a strip outside [0, strips) or a NaN x (the NaN leaf;
    // an empty strip's is found in pass 2).  x in 52-bit fixed point, floor(x 2^52) of x
    // clamped to [0, 1 - 2^-53]: the bucket and sub-bucket are its leading bits, found by
    // shifts (exact: x 2^52 is, and floor commutes with them), where clamped double products
    // and conversions had lengthened each lookup's chain of dependent loads (1.3-1.5x slower).
    void sub_bucket(int64_t g, double x, int64_t &slot, int64_t &strip) const {
        // without a branch: g and x of the NaN leaf's points are replaced by harmless ones
        const bool bad = (g < 0) | (g >= strips_) | !(x == x);
        const int64_t gg = bad ? 0 : g;
        const double clamped = std::min(std::max(bad ? 0.0 : x, 0.0), 0x1.fffffffffffffp-1);
        const uint64_t fixed = uint64_t(clamped * 0x1p52);
        const uint64_t b = fixed >> (52 - log2_buckets_);
        const Bucket bucket = index_[size_t(gg * buckets_ + int64_t(b))];
        const uint64_t j = (fixed >> (52 - log2_buckets_ - bucket.shift)) & ((uint64_t(1) << bucket.shift) - 1);
        slot = bad ? -1 : int64_t(bucket.base) + int64_t(j);
        strip = gg;
    }

    // Pass 2: the candidate leaves begin .. end - 1 of the sub-bucket at `slot` of strip g:
    // those that start in it and the one before (at least one), in place of (slot, g).
    void candidates(int64_t &slot, int64_t &g) const {
        const int32_t *first = &subs_[size_t(slot < 0 ? 0 : slot)];
        const int64_t begin = std::max(int64_t(first[0]) - 1, offsets_[g]);
        const int64_t end = std::max(int64_t(first[1]), begin + 1);
        slot = (slot < 0) | (offsets_[g + 1] <= offsets_[g]) ? -1 : begin;   // an empty strip's: NaN
        g = end;
    }

    // Pass 3: the leaf among begin .. end - 1 with the largest lo <= x (begin if none): one
    // comparison without a branch for the usual one or two candidates; a binary search for
    // leaves narrower than the finest sub-bucket (rare).
    uint32_t leaf(int64_t begin, int64_t end, double x) const {
        if (end - begin > 2) {
            const Leaf *at = &leaves_[size_t(begin)];
            for (size_t m = size_t(end - begin); m > 1;) {
                const size_t half = m / 2;
                at = at[half].lo <= x ? at + half : at;
                m -= half;
            }
            return uint32_t(at - leaves_.data());
        }
        return uint32_t(begin + ((end - begin == 2) & (leaves_[size_t(begin) + 1].lo <= x)));
    }

    // The table's value at x in leaf i (NaN in the sentinel); min and max, not branches
    double value(uint32_t i, double x) const {
        const Leaf &l = leaves_[i];
        const double width = l.hi - l.lo;
        double t = (x - l.lo) / (width > 0 ? width : 1.0);  // unconditional: a select, not a branch
        t = width > 0 ? t : 0.0;
        t = std::min(std::max(t, 0.0), 1.0);
        const double u = l.start + l.mass * t;
        return std::min(std::max(u, 0.0), 1.0);  // NaN stays NaN
    }

    struct Leaf {
        double lo, hi, start, mass;
    };
    struct Bucket {
        int32_t base, shift;  // leaf indices: the tables hold well under 2^31 leaves
    };
    const int64_t *offsets_;
    int64_t strips_, buckets_ = 256;
    int log2_buckets_ = 8;
    std::vector<Leaf> leaves_;
    std::vector<Bucket> index_;   // [g * B + b]: where bucket b's sub-buckets start in subs_, log2 S_b
    std::vector<int32_t> subs_;   // per bucket, its S_b + 1 sub-bucket firsts
};

// out[j] = the table's value at x[j] in strip strip[j], for n points.
inline void piecewise_linear_lookup(const double *lo, const double *hi, const double *start, const double *mass,
                                    const int64_t *offsets, int64_t strips, const int64_t *strip, const double *x,
                                    size_t n, double *out) {
    const PiecewiseLinearTable table(lo, hi, start, mass, offsets, strips);
    table.lookup(strip, x, 1, n, out, 1);
}

// The Rosenblatt transform of the sampler check (harness/samplers/transform.py) of parameter
// points s (n, k): u0 = marginal(0, s0); on the square (k == 2) also the strip g of s0 among
// the strip edges (the last edge e with e <= s0, clamped to 0 .. edges - 2; NaN: the last
// strip, as numpy's searchsorted) and u1 = conditional(g, s1).  Each point's result depends
// on that point alone, so callers may cut the points into chunks on any threads.
class RosenblattTransform {
  public:
    RosenblattTransform(const PiecewiseLinearTable &marginal, const PiecewiseLinearTable *conditional,
                        const double *edges, size_t nedges)
        : marginal_(marginal), conditional_(conditional), above_(edges, nedges), last_(int64_t(nedges) - 2),
          strip_of_leaf_(conditional ? marginal.per_leaf([this](double s0) { return strip_of(s0); })
                                     : std::vector<int64_t>{}) {}

    // Points a .. b - 1 of s (n, k): u0 to u0[j * stride], on the square u1 to u1[j * stride],
    // and the strip to strip[j - a] (0 on an interval).
    void operator()(const double *s, size_t k, size_t a, size_t b, double *u0, double *u1, size_t stride,
                    int64_t *strip) const {
        // three passes, each with a short loop body, so that the out-of-order core overlaps
        // the dependent loads of many points (one fused loop ran at half the speed)
        // the strips, where the edges lie on the marginal's leaves (the sampler check's do), by
        // the leaf each s0 fell in: a search among the edges a point had taken a fifth of the
        // transform's time
        const bool by_leaf = !strip_of_leaf_.empty();
        marginal_.lookup(nullptr, s + k * a, k, b - a, u0 + a * stride, stride, by_leaf ? strip : nullptr);
        if (k == 1) {
            std::fill(strip, strip + (b - a), int64_t(0));
            return;
        }
        if (by_leaf)
            for (size_t j = a; j < b; ++j) strip[j - a] = strip_of_leaf_[size_t(strip[j - a])];
        else
            for (size_t j = a; j < b; ++j) strip[j - a] = strip_of(s[k * j]);
        conditional_->lookup(strip, s + k * a + 1, k, b - a, u1 + a * stride, stride);
    }

  private:
    // The strip of s0: the last edge e <= s0, clamped to 0 .. last_ (NaN: last_, as numpy's
    // searchsorted).
    int64_t strip_of(double s0) const {
        const int64_t g = s0 == s0 ? int64_t(above_(s0)) - 1 : last_;
        return g < 0 ? 0 : (g > last_ ? last_ : g);
    }

    const PiecewiseLinearTable &marginal_;
    const PiecewiseLinearTable *conditional_;
    BucketedUpperBound above_;
    int64_t last_;
    std::vector<int64_t> strip_of_leaf_;   // strip_of per marginal leaf (PiecewiseLinearTable::per_leaf), or empty
};

// Points a chunk of the sampler check's batch kernels (this transform, the histogram, the
// domain maps): fixed, so that work is cut the same way on any number of threads.
inline constexpr size_t kCheckChunk = size_t(1) << 16;
// Points a chunk of the kernels called once per block of the sampler check's cubature (2^16
// nodes, one call of the user's pdf: the nodes, the cap map, float32 rounding): a quarter of
// kCheckChunk, so that a block runs on all threads.
inline constexpr size_t kCubatureChunk = kCheckChunk / 4;

// rosenblatt: u (n, k) and strip (n,) of the points s (n, k), on all hardware threads.
inline void rosenblatt(const PiecewiseLinearTable &marginal, const PiecewiseLinearTable *conditional,
                       const double *edges, size_t nedges, const double *s, size_t k, size_t n, double *u,
                       int64_t *strip) {
    const RosenblattTransform transform(marginal, conditional, edges, nedges);
    for_chunks(n, kCheckChunk,
               [&](size_t, size_t a, size_t b, int) { transform(s, k, a, b, u, u + 1, k, strip + a); });
}

}  // namespace re
