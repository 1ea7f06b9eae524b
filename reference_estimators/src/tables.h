// Piecewise-linear tables looked up in batch: the sampler check's Rosenblatt transform
// (harness/samplers/transform.py) maps a million points through CDFs tabulated on a few
// thousand leaves of very different widths, in strips.  numpy's searchsorted over unsorted
// queries cost about 0.26-0.5 us a point there (a long, mispredicted binary search, one numpy
// call per strip); a bucket index narrows each search to a few leaves.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

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
// of strip g, sorted by lo, inside [0, 1]), looked up in batch.  A bucket index of B buckets
// per strip (a power of two, about eight per leaf of the fullest strip, 256 to 2^16, at most
// 2^17 32-bit entries in all, so that it stays in cache) narrows each search to the leaves
// that start in the point's bucket (or the one before): mostly none, so that the search is
// skipped.  The answer does not depend on B.
class PiecewiseLinearTable {
  public:
    PiecewiseLinearTable(const double *lo, const double *hi, const double *start, const double *mass,
                         const int64_t *offsets, int64_t strips)
        : offsets_(offsets), strips_(strips), leaves_(size_t(offsets[strips])) {
        // a leaf's four numbers side by side: one cache line a lookup instead of four
        for (size_t i = 0; i < leaves_.size(); ++i) leaves_[i] = {lo[i], hi[i], start[i], mass[i]};
        int64_t most = 0;
        for (int64_t g = 0; g < strips; ++g) most = std::max(most, offsets[g + 1] - offsets[g]);
        const int64_t cap = std::max<int64_t>(256, (int64_t(1) << 17) / std::max<int64_t>(strips, 1));
        while (buckets_ < 8 * most && buckets_ < (int64_t(1) << 16) && buckets_ < cap) buckets_ *= 2;
        // first_[g * (B + 1) + b]: the first leaf of strip g whose lo >= b / B (offsets[g + 1] if none)
        first_.resize(size_t(strips * (buckets_ + 1)));
        for (int64_t g = 0; g < strips; ++g) {
            int64_t i = offsets[g];
            for (int64_t b = 0; b <= buckets_; ++b) {
                while (i < offsets[g + 1] && lo[i] < double(b) / double(buckets_)) ++i;
                first_[size_t(g * (buckets_ + 1) + b)] = int32_t(i);
            }
        }
    }

    // The leaf i of strip g with the largest lo[i] <= x (the strip's first leaf when none is),
    // and start[i] + mass[i] * clamp((x - lo[i]) / (hi[i] - lo[i]), 0, 1), clamped to [0, 1].
    // A strip outside [0, strips), an empty strip or a NaN x gives NaN.
    double operator()(int64_t g, double x) const {
        if (g < 0 || g >= strips_ || offsets_[g + 1] <= offsets_[g] || !(x == x)) return __builtin_nan("");
        int64_t b = int64_t(x * double(buckets_));
        b = b < 0 ? 0 : (b >= buckets_ ? buckets_ - 1 : b);
        // the answer lies in [first[b] - 1, first[b + 1] - 1]: leaves starting before b / B end
        // with the last one, and none starting at or after (b + 1) / B can hold x
        const int32_t *row = &first_[size_t(g * (buckets_ + 1))];
        const int64_t begin = std::max(int64_t(row[b]) - 1, offsets_[g]), end = std::max(int64_t(row[b + 1]), begin + 1);
        const Leaf *leaf = &leaves_[size_t(begin)];
        // mostly a single candidate (no leaf starts in the bucket): no search, no extra load;
        // else the last candidate with lo <= x (the first when none is), without branches
        for (size_t m = size_t(end - begin); m > 1;) {
            const size_t half = m / 2;
            leaf = leaf[half].lo <= x ? leaf + half : leaf;
            m -= half;
        }
        const double width = leaf->hi - leaf->lo;
        double t = (x - leaf->lo) / (width > 0 ? width : 1.0);  // unconditional: a select, not a branch
        t = width > 0 ? t : 0.0;
        t = t < 0 ? 0 : (t > 1 ? 1 : t);
        const double u = leaf->start + leaf->mass * t;
        return u < 0 ? 0 : (u > 1 ? 1 : u);
    }

  private:
    struct Leaf {
        double lo, hi, start, mass;
    };
    const int64_t *offsets_;
    int64_t strips_, buckets_ = 256;
    std::vector<Leaf> leaves_;
    std::vector<int32_t> first_;  // leaf indices: the tables hold well under 2^31 leaves
};

// out[j] = the table's value at x[j] in strip strip[j], for n points.
inline void piecewise_linear_lookup(const double *lo, const double *hi, const double *start, const double *mass,
                                    const int64_t *offsets, int64_t strips, const int64_t *strip, const double *x,
                                    size_t n, double *out) {
    const PiecewiseLinearTable table(lo, hi, start, mass, offsets, strips);
    for (size_t j = 0; j < n; ++j) out[j] = table(strip[j], x[j]);
}

// The Rosenblatt transform of the sampler check (harness/samplers/transform.py) of parameter
// points s (n, k): u0 = marginal(0, s0); on the square (k == 2) also the strip g of s0 among
// the strip edges (the last edge e with e <= s0, clamped to 0 .. edges - 2; NaN: the last
// strip, as numpy's searchsorted) and u1 = conditional(g, s1).  u (n, k), strip (n,) (0 when
// k == 1).
inline void rosenblatt(const PiecewiseLinearTable &marginal, const PiecewiseLinearTable *conditional,
                       const double *edges, size_t nedges, const double *s, size_t k, size_t n, double *u,
                       int64_t *strip) {
    // three passes, each with a short loop body, so that the out-of-order core overlaps the
    // dependent loads of many points (one fused loop ran at half the speed)
    for (size_t j = 0; j < n; ++j) u[k * j] = marginal(0, s[k * j]);
    if (k == 1) {
        std::fill(strip, strip + n, int64_t(0));
        return;
    }
    const int64_t last = int64_t(nedges) - 2;
    const BucketedUpperBound above(edges, nedges);
    for (size_t j = 0; j < n; ++j) {
        const double s0 = s[k * j];
        int64_t g = s0 == s0 ? int64_t(above(s0)) - 1 : last;
        strip[j] = g < 0 ? 0 : (g > last ? last : g);
    }
    for (size_t j = 0; j < n; ++j) u[k * j + 1] = conditional->operator()(strip[j], s[k * j + 1]);
}

}  // namespace re
