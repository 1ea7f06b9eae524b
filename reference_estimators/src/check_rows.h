// Row selection for the sampler check's arrays (bind_rows.cpp's take_rows and nan_rows): rows
// of k doubles, one keep flag (a byte, any non-zero value true) a row; the lookup of rows
// among others (RowLookup); and the adapter's weight check over rows (weight_agreement).
// The selections are branch-free:
// the flags of a sampler's rows follow its lobes and failures, not a pattern a branch predictor
// learns (a mask plugin passing 70 % of its samples through a Dirac lobe: inside its check,
// nan_rows took 7 ms and take_rows 3.4 ms for a million 3-vectors with branches, 1-4 and
// 0.8-1.3 ms without).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <vector>

namespace re {

// f(std::integral_constant<size_t, k>) for the row widths 1, 2 and 3 (values, parameters,
// directions), else f(std::integral_constant<size_t, 0>): the caller's loops with k fixed.
template <class F>
void with_row_width(size_t k, F f) {
    switch (k) {
        case 1: f(std::integral_constant<size_t, 1>{}); break;
        case 2: f(std::integral_constant<size_t, 2>{}); break;
        case 3: f(std::integral_constant<size_t, 3>{}); break;
        default: f(std::integral_constant<size_t, 0>{});
    }
}

// out (n rows of k) = x's rows, those whose flag is 0 all NaN: numpy's where(keep[:, None], x,
// nan), the same bits (the quiet NaN 0x7ff8...), by masks on the values' bits.
template <size_t K>
void nan_rows(const double *x, const uint8_t *flags, size_t n, size_t k, double *out) {
    const size_t w = K ? K : k;
    constexpr uint64_t kNaN = 0x7ff8000000000000ull;
    for (size_t i = 0; i < n; ++i) {
        const uint64_t keep = uint64_t(0) - uint64_t(flags[i] != 0);
        for (size_t j = 0; j < w; ++j) {
            uint64_t b;
            std::memcpy(&b, x + i * w + j, 8);
            b = (b & keep) | (kNaN & ~keep);
            std::memcpy(out + i * w + j, &b, 8);
        }
    }
}

// The first m rows of x (n rows of k) whose flag is not 0, in order, to out (m rows): x[keep]
// where keep holds m true flags.  Each row is written to the next free slot and the slot
// taken only where its flag is set; the loop stops when m are taken (out is never overrun,
// whatever the flags hold).
template <size_t K>
void compact_rows(const double *x, const uint8_t *flags, size_t n, size_t k, size_t m, double *out) {
    const size_t w = K ? K : k;
    size_t taken = 0;
    for (size_t i = 0; i < n && taken < m; ++i) {
        for (size_t j = 0; j < w; ++j) out[taken * w + j] = x[i * w + j];
        taken += flags[i] != 0;
    }
}

// Which of n rows of k doubles (k <= 3) equals a given row, value for value as numpy's ==
// (0.0 equals -0.0, NaN equals nothing): find() gives the first such row, or -1.  An
// open-addressing table of row indices with 32 hash bits beside each, built in one pass over
// the rows, at most half full (the Mitsuba adapter's CapView looks a few points up among a
// million drawn ones: a stable argsort of their keys had taken 0.12 s of an area light's check).
// The rows are read in place: they must outlive the lookup.
class RowLookup {
  public:
    RowLookup(const double *x, size_t n, size_t k) : x_(x), k_(k) {
        size_t capacity = 16;
        while (capacity < 2 * n) capacity *= 2;
        slots_.assign(capacity, kEmpty);
        mask_ = capacity - 1;
        for (size_t i = 0; i < n; ++i) {
            uint64_t h;
            if (!key(x + i * k, h)) continue;   // a NaN row equals nothing
            size_t at = size_t(h) & mask_;
            for (;; at = (at + 1) & mask_) {
                const uint64_t slot = slots_[at];
                if (slot == kEmpty) {
                    slots_[at] = (h & kHashBits) | uint64_t(i);
                    break;
                }
                if ((slot & kHashBits) == (h & kHashBits) && equal(x + (slot & kIndexBits) * k, x + i * k)) break;
            }
        }
    }

    int64_t find(const double *q) const {
        uint64_t h;
        if (!key(q, h)) return -1;
        for (size_t at = size_t(h) & mask_;; at = (at + 1) & mask_) {
            const uint64_t slot = slots_[at];
            if (slot == kEmpty) return -1;
            if ((slot & kHashBits) == (h & kHashBits) && equal(x_ + (slot & kIndexBits) * k_, q))
                return int64_t(slot & kIndexBits);
        }
    }

  private:
    static constexpr uint64_t kEmpty = ~uint64_t(0);
    static constexpr uint64_t kHashBits = 0xffffffff00000000ull, kIndexBits = 0xffffffffull;

    // The row's hash (zeros of either sign alike), false for a row with a NaN.
    bool key(const double *r, uint64_t &h) const {
        h = 0x243f6a8885a308d3ull;
        for (size_t j = 0; j < k_; ++j) {
            if (r[j] != r[j]) return false;
            const double v = r[j] == 0.0 ? 0.0 : r[j];
            uint64_t b;
            std::memcpy(&b, &v, 8);
            h = (h ^ b) * 0x9e3779b97f4a7c15ull;
            h ^= h >> 29;
        }
        h ^= h >> 32;
        return true;
    }

    bool equal(const double *a, const double *b) const {
        for (size_t j = 0; j < k_; ++j)
            if (!(a[j] == b[j])) return false;
        return true;
    }

    const double *x_;
    size_t k_, mask_ = 0;
    std::vector<uint64_t> slots_;   // hash bits above, row index below (rows < 2^32); kEmpty
};

// Mitsuba's adapter's weight check (harness/adapters/mitsuba/checks.py, weight_consistency),
// rows a .. b - 1 of n samples of c channels: the weight w a sample call returned (row i at
// w + i * w_row; w_row 0 for one constant weight), the value e re-evaluated at its direction
// (rows of c) and the pdf p there.  Per channel ratio = e / p and diff = |w - ratio|; bad[i]:
// a channel of w not finite, or negative; mismatch[i]: not bad, and a channel whose diff is
// not within atol + rtol |ratio| (NaN: not within).  Returns the largest relative difference
// (diff / |ratio| where |ratio| > atol, else diff) over the rows that are not bad, a NaN
// counted as +inf and +inf as the largest double (numpy's nan_to_num(nan=inf)); 0 for none.
// numpy's expressions, the same values, without its dozen temporaries of n c values (80 ms a
// million samples: most of the weight check's time).
inline double weight_agreement(const double *w, size_t w_row, const double *e, const double *p, size_t a,
                               size_t b, size_t c, double atol, double rtol, bool *mismatch, bool *bad) {
    constexpr double kMax = std::numeric_limits<double>::max(), kInf = std::numeric_limits<double>::infinity();
    double most = 0.0;
    for (size_t i = a; i < b; ++i) {
        const double *wi = w + i * w_row, *ei = e + i * c;
        bool is_bad = false, within = true;
        double row_most = 0.0;
        for (size_t j = 0; j < c; ++j) {
            const double ratio = ei[j] / p[i], size = std::fabs(ratio);
            const double diff = std::fabs(wi[j] - ratio);
            is_bad |= !(std::isfinite(wi[j]) && wi[j] >= 0);
            within &= diff <= atol + rtol * size;
            double rel = size > atol ? diff / size : diff;
            rel = rel != rel ? kInf : (rel == kInf ? kMax : rel);
            row_most = std::max(row_most, rel);
        }
        bad[i] = is_bad;
        mismatch[i] = !within && !is_bad;
        if (!is_bad) most = std::max(most, row_most);
    }
    return most;
}

// Whether the double v is finite, by its exponent bits (no branch, vectorisable).
inline __attribute__((always_inline)) bool finite_bits(double v) {
    uint64_t u;
    std::memcpy(&u, &v, 8);
    return (u & 0x7ff0000000000000ull) != 0x7ff0000000000000ull;
}

// Which of rows a .. b - 1 of a renderer's samples it produced (the Mitsuba adapter's
// SampleBatch.valid): ok[i] = the direction x (rows of 3) finite, its reported pdf p[i] > 0,
// some channel of its weight w (rows of c at w + i * w_row; w_row 0 for one constant weight;
// null for none) not 0 (a NaN is not 0, as numpy's !=), and delta[i] (null for none) 0: it did
// not sample a Dirac lobe.  numpy's comparisons, the same flags, in one pass where numpy had
// made eight (3 ms a million BSDF samples).
inline void produced_rows(const double *x, const double *p, const double *w, size_t w_row, size_t c,
                          const double *delta, size_t a, size_t b, bool *ok) {
    for (size_t i = a; i < b; ++i) {
        const double *xi = x + 3 * i;
        bool produced = finite_bits(xi[0]) & finite_bits(xi[1]) & finite_bits(xi[2]) & (p[i] > 0);
        if (w) {
            bool nonzero = false;
            for (size_t j = 0; j < c; ++j) nonzero |= w[i * w_row + j] != 0;
            produced &= nonzero;
        }
        if (delta) produced &= delta[i] == 0;
        ok[i] = produced;
    }
}

}  // namespace re
