// The 2-D table sampler's kernel for small tables on AVX-512 (piecewise_constant_2d with at
// most 16 rows and 64 columns and no gaps, SmallTable2D::fits): each vector of points finds
// its row by a halving search and its column by counting CDF entries, in its lanes, where
// sample_many searches point by point.
// The same bits as PiecewiseConstant2D's passes through PiecewiseTables::sample_many.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "piecewise_tables.h"
#include "samplers.h"
#include "simd.h"

namespace re {

// For a marginal over at most 16 rows and one conditional a row, PiecewiseTables whose CDFs
// are non-decreasing (`counted`: a bin is then the count of its table's entries 1 .. bins - 1
// at or below u, as bins_of_u's searches find it, u = 1 included) and without gaps (an empty
// bin after the first, which bins_of_u moves down through `below`; an empty first bin is never
// chosen by either): a point's row is found by a halving search over the marginal's entries,
// one 16-entry permute (vpermt2pd) a step and one more for each of the row's CDF ends (4 + 2
// for 16 rows, where counting took 15 compares and blends), and its column by counting entry
// e of the rows' CDFs, read for every lane's row by one permute an entry, from the entries e
// of all rows laid out together (a halving search there needs a gather a step: 1.2x slower on
// Zen 4).  The column's two CDF ends are kept on the way by masked blends (two gathers after
// the count were slower), so a point's bins and entries cost no dependent loads, where
// sample_many's scalar count and entry loads held a point at its latency.  The cells'
// densities are gathered.  The conditional and the cell are those of the row searched, where
// PiecewiseConstant2D's passes take the row the point landed in: the same on [0, 1], whose
// bins all hold doubles below 2^50 bins.
// The rows, the columns and the points are three passes over a sub-block of points: in one
// loop, a vector's chain of dependent steps (row search, column count, two divisions) was
// longer than the out-of-order window could hide behind the next vector's.
// (gaussian2d's 16 x 16 table: 8.2 -> 6.0 ns a point, blocks of 2048 in L1, Zen 4; the row's
// halving search: importance sampling 9.1-9.6 -> 8.9-9.1 ns a sample on one thread; the three
// passes: the sampling stage 6.3 -> 4.8-4.9 ns a sample)
class SmallTable2D {
  public:
    // 16 rows: one permute's table; 64 columns: the count's loop over a row's entries costs
    // 3 vector operations an entry, so a wider table is left to the halving and level searches
    static constexpr size_t kMaxRows = 16, kMaxCols = 64;
    // Points a sub-block: the three passes over it (sample) keep their lanes in L1
    static constexpr size_t kSub = 256;

    // Whether the kernel applies: an AVX-512 build, and tables as described above.
    static bool fits(const PiecewiseTables &marginal, const PiecewiseTables &conditional) {
#if defined(__AVX512F__)
        return marginal.bins <= kMaxRows && conditional.bins <= kMaxCols && !marginal.gaps &&
               !conditional.gaps && marginal.counted && conditional.counted;
#else
        (void)marginal, (void)conditional;
        return false;
#endif
    }

    SmallTable2D(const PiecewiseTables &marginal, const PiecewiseTables &conditional)
        : row_first_step_(first_step(marginal.bins)), by_entry_((conditional.bins + 1) * kMaxRows, 0.0) {
        const size_t rows = marginal.bins, cols = conditional.bins;
        for (size_t r = 0; r < kMaxRows; ++r) {
            marginal_entries_[r] = r < rows ? marginal.cdf[r] : NAN;
            marginal_next_[r] = r < rows ? marginal.cdf[r + 1] : NAN;
        }
        for (size_t e = 0; e <= cols; ++e)
            for (size_t r = 0; r < rows; ++r) by_entry_[e * kMaxRows + r] = conditional.cdf[r * (cols + 1) + e];
    }

    // The points x (n x 2: column, row coordinates) and densities p of the uniforms u (n x 2:
    // u0 picks the column, u1 the row) for the whole vectors of n, from the tables this was
    // built for (the caller passes the same ones) and the cells' densities cell_pdf
    // (row-major); returns how many points that is (the caller samples the rest).  With
    // `invalid`, adds to it how many of them the estimators' screening rejects (Sampler::
    // sample_valid): a point off the tables' box [conditional.a, conditional.b] x [marginal.a,
    // marginal.b] or a density not in (0, max double], tested in the lanes that store them.
    size_t sample(const PiecewiseTables &marginal, const PiecewiseTables &conditional, const double *cell_pdf,
                  const double *u, double *x, double *p, size_t n, size_t *invalid = nullptr) const {
#if defined(__AVX512F__)
        using simd::f64v;
        using simd::i64v;
        constexpr size_t W = simd::kWidth;
        const __m512d m0 = _mm512_loadu_pd(marginal_entries_), m1 = _mm512_loadu_pd(marginal_entries_ + 8);
        const __m512d n0 = _mm512_loadu_pd(marginal_next_), n1 = _mm512_loadu_pd(marginal_next_ + 8);
        const size_t cols = conditional.bins;
        const i64v row_width = i64v{} + int64_t(cols);
        // a sub-block's lanes between the passes (16 KiB: they stay in L1)
        alignas(64) double u0s[kSub], u1s[kSub], row_lo[kSub], row_hi[kSub], col_lo[kSub], col_hi[kSub];
        alignas(64) int64_t row_of[kSub], col_of[kSub];
        const double x_lo = conditional.a, x_hi = conditional.b, y_lo = marginal.a, y_hi = marginal.b;
        i64v rejected{};
        const size_t whole = n / W * W;
        for (size_t start = 0; start < whole; start += kSub) {
            const size_t m = std::min(kSub, whole - start);
            // the rows: a halving search over the marginal's entries 0 .. rows - 1 (NaN above:
            // never taken, whatever u), one permute a step; then the row's entry (lo) and the
            // entry after (hi), one permute each
            for (size_t j = 0; j < m; j += W) {
                f64v u0, u1;
                simd::deinterleave(u + 2 * (start + j), u0, u1);
                i64v row{};
                for (int64_t step = int64_t(row_first_step_); step > 0; step >>= 1) {
                    const i64v cand = row + step;
                    const f64v v = (f64v)_mm512_permutex2var_pd(m0, (__m512i)cand, m1);
                    row = v <= u1 ? cand : row;
                }
                simd::store(row_lo + j, (f64v)_mm512_permutex2var_pd(m0, (__m512i)row, m1));
                simd::store(row_hi + j, (f64v)_mm512_permutex2var_pd(n0, (__m512i)row, n1));
                simd::store(u0s + j, u0);
                simd::store(u1s + j, u1);
                simd::store(row_of + j, row);
            }
            // the columns: counted, with their CDF ends
            for (size_t j = 0; j < m; j += W) {
                const f64v u0 = simd::load(u0s + j);
                const i64v row = simd::load(row_of + j);
                i64v col{};
                f64v next = entries(0, row);
                f64v clo = next;
                next = entries(1, row);
                f64v chi = next;
                for (size_t e = 1; e < cols; ++e) {
                    const f64v v = next;
                    next = entries(e + 1, row);
                    const i64v at_most = v <= u0;
                    col -= at_most;
                    clo = at_most ? v : clo;
                    chi = at_most ? next : chi;
                }
                simd::store(col_lo + j, clo);
                simd::store(col_hi + j, chi);
                simd::store(col_of + j, col);
            }
            // the points in their cells, and the cells' densities
            for (size_t j = 0; j < m; j += W) {
                const i64v row = simd::load(row_of + j), col = simd::load(col_of + j);
                const f64v y = marginal.points_in(simd::load(u1s + j), simd::load(row_lo + j), simd::load(row_hi + j),
                                                  __builtin_convertvector(row, f64v));
                const f64v xv = conditional.points_in(simd::load(u0s + j), simd::load(col_lo + j),
                                                      simd::load(col_hi + j), __builtin_convertvector(col, f64v));
                const size_t i = start + j;
                const f64v pv = gather(cell_pdf, row * row_width + col);
                if (invalid) {
                    const auto ok = in_rectangle(xv, y, x_lo, x_hi, y_lo, y_hi) & valid_pdf(pv);
                    rejected += ok ? i64v{} : i64v{} + 1;
                }
                simd::store(p + i, pv);
                simd::interleave(x + 2 * i, xv, y);
            }
        }
        if (invalid)
            for (size_t l = 0; l < W; ++l) *invalid += size_t(rejected[l]);
        return whole;
#else
        (void)marginal, (void)conditional, (void)cell_pdf, (void)u, (void)x, (void)p, (void)n, (void)invalid;
        return 0;
#endif
    }

  private:
    // A halving search's first step over n entries: half the least power of 2 >= n (0 for one).
    static size_t first_step(size_t n) {
        size_t w = 1;
        while (w < n) w *= 2;
        return w / 2;
    }
#if defined(__AVX512F__)
    // Entry e of the CDF of each lane's row.
    RE_INLINE simd::f64v entries(size_t e, simd::i64v row) const {
        const double *t = by_entry_.data() + e * kMaxRows;
        return (simd::f64v)_mm512_permutex2var_pd(_mm512_loadu_pd(t), (__m512i)row, _mm512_loadu_pd(t + 8));
    }
    // t[i] for each lane's index i (all lanes: the unmasked intrinsic trips GCC 12's
    // -Wmaybe-uninitialized).
    RE_INLINE static simd::f64v gather(const double *t, simd::i64v i) {
        return (simd::f64v)_mm512_mask_i64gather_pd(_mm512_setzero_pd(), 0xff, (__m512i)i, t, 8);
    }
#endif

    size_t row_first_step_;   // the row search's first step
    // marginal.cdf[r] and marginal.cdf[r + 1] for the rows r, NaN after them
    double marginal_entries_[kMaxRows], marginal_next_[kMaxRows];
    std::vector<double> by_entry_;   // entry e of row r's CDF at [e kMaxRows + r]
};

}  // namespace re
