// Batch kernels of the sampler check (harness/samplers/check.py): the per-sample work between
// the user's sample() and pdf() calls.  In numpy each step was a pass (or several) over a
// million points with temporaries, 0.25-0.4 s a check in all; here each is one pass without
// temporaries, and the Cramer-von Mises statistic needs no sort (cramer_von_mises_sum
// brackets it from cell counts).  Every kernel computes what the numpy code did, in the same
// order of operations, so results agree to the last bit except where stated: sums
// (compensated here, pairwise in numpy) and the azimuth (fastmath's atan2_turns, within 2 ulp
// of numpy's mod(arctan2(y, x) / (2 pi), 1); libm's atan2 and fmod took 80 % of the sphere's
// map).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

#include "accumulator.h"  // CompensatedSum
#include "check_cubature.h"
#include "check_domains.h"
#include "check_float32.h"
#include "tables.h"       // RosenblattTransform

namespace re {

// grid_histogram's counting of points a .. b - 1 into c (its own function: with its arguments
// in registers the loop ran 2.5-3.5x faster than with them read through a lambda's captures).
inline void count_cells(const double *s, size_t a, size_t b, const bool *inside, int64_t m0, int64_t m1,
                        int64_t *c) {
    constexpr double top = 1.0 - 0x1p-53;  // np.nextafter(1, 0)
    auto cell = [](double v, int64_t m) {
        v = v < 0 ? 0.0 : (v > top ? top : v);
        const int64_t j = int64_t(v * double(m));
        return j < m - 1 ? j : m - 1;
    };
    if (m1 == 0) {
        for (size_t i = a; i < b; ++i) {
            const double x = s[i];
            if (inside[i] && x == x) ++c[cell(x, m0)];
        }
        return;
    }
    for (size_t i = a; i < b; ++i) {
        const double x = s[2 * i], y = s[2 * i + 1];
        if (inside[i] && x == x && y == y) ++c[cell(x, m0) * m1 + cell(y, m1)];
    }
}

// Integer counts in `cells` cells of n items, on all hardware threads: count(a, b, table, worker)
// adds the items a .. b - 1 of a fixed chunk to `table`, the thread's own (worker its index);
// the tables' sums go to counts (float64).  Integer sums: the same whichever thread counted
// what.
template <class Count>
void count_on_threads(size_t n, size_t cells, double *counts, Count count) {
    std::vector<std::vector<int64_t>> tables(size_t(ThreadPool::default_threads()));
    for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int worker) {
        std::vector<int64_t> &table = tables[size_t(worker)];
        if (table.empty()) table.assign(cells, 0);
        count(a, b, table.data(), worker);
    });
    for (size_t j = 0; j < cells; ++j) {
        int64_t total = 0;
        for (const auto &table : tables) total += table.empty() ? 0 : table[j];
        counts[j] = double(total);
    }
}

// Counts of the points marked inside on the regular grid of m0 (x m1) cells over [0, 1]^k
// (k = 1 when m1 == 0), C order: each coordinate clamped to [0, 1 - 2^-53] first, then cell
// floor(s m) (at most m - 1).  Points outside, or with a NaN coordinate, are not counted.
inline void grid_histogram(const double *s, size_t n, const bool *inside, int64_t m0, int64_t m1, double *counts) {
    count_on_threads(n, size_t(m0) * size_t(m1 > 0 ? m1 : 1), counts,
                     [&](size_t a, size_t b, int64_t *table, int) {
                         count_cells(s, a, b, inside, m0, m1, table);
                     });
}

// Scratch buffer `which` (0 or 1) of this thread, at least n doubles, contents undefined:
// kept between calls, because a fresh 8 MB buffer a call costs thousands of page faults
// (more than the transform itself on a loaded machine).
inline double *scratch(int which, size_t n) {
    thread_local std::vector<double> buffers[2];  // transform_statistics: u0, u1
    std::vector<double> &b = buffers[which];
    if (b.size() < n) b.resize(n);
    return b.data();
}

// The Cramer-von Mises sum S = sum_i (u_(i) - c_i)^2, c_i = (2 i - 1) / (2 n), over the sorted
// values u_(1..n) of u (n values at stride `stride`, each clamped to [0, 1]: the uniform law's
// CDF there, as in scipy's cramervonmises): S + 1 / (12 n) is the statistic n W^2.  Bracketed
// without sorting: `upper` >= S >= upper - `slack`.
struct CramerVonMisesSum {
    double upper, slack;
};

// How (why not a sort): the values are counted in K cells of width h = 1 / K (K a power of
// two, about 64 sqrt(n): the counts stay in L2).  The m_b values of cell b take the ranks
// r_b + 1 .. r_b + m_b whatever their order inside it, so with cbar_b the mean of their c,
//     S = sum_i (u_i - cbar_b(i))^2 + sum_b (m_b^3 - m_b) / (12 n^2) - 2 sum_b C_b,
// C_b = sum_j (u_(b,j) - mean)(c_(b,j) - cbar_b) >= 0 the within-cell covariance of the
// sorted pairing (rearrangement inequality), at most h m_b (m_b - 1) / (4 n).  `upper` drops
// C, `slack` is the sum of the C bounds doubled: about n / (2 K^2) <= 1.2e-4 for uniform
// values, against a statistic whose 1 % point is 0.74.  Two passes over u (count, then sum),
// where a radix sort took five and twice the time.  The second pass sums in blocks of 1024
// terms, the block sums compensated in order, so the result is the same on any thread count.
// Both passes run on the thread pool (so not to be called from inside one of its jobs).  NaN
// (both) if any u is NaN.  32-bit counts (the table at K = 2^16 fits in L2: 1.4x faster than
// 64-bit ones): at most 2^32 - 1 values.
//
// CramerVonMisesCounts holds the two passes: the first (count) a caller may run inside its own
// pass over the values, chunk by chunk while they are in cache (transform_statistics), the
// second (sum) once every chunk is counted; cramer_von_mises_sum runs both on its own.
class CramerVonMisesCounts {
  public:
    // For n values (at most 2^32 - 1: 32-bit counts).
    explicit CramerVonMisesCounts(size_t n)
        : n_(n), tables_(size_t(ThreadPool::default_threads())), nan_in_(tables_.size(), 0) {
        if (n > UINT32_MAX) throw std::length_error("the Cramer-von Mises sum takes at most 2^32 - 1 values");
        int bits = 10;
        while (bits < 22 && double(int64_t(1) << bits) < 64.0 * std::sqrt(double(n))) ++bits;
        K_ = int64_t(1) << bits;
    }

    // Counts values a .. b - 1 (u[i * stride]) on worker `worker` of the thread pool.
    void count(const double *u, size_t stride, size_t a, size_t b, int worker) {
        std::vector<uint32_t> &table = tables_[size_t(worker)];
        if (table.empty()) table.assign(size_t(K_), 0);
        for (size_t i = a; i < b; ++i) {
            const double v = u[i * stride];
            if (v != v) { nan_in_[size_t(worker)] = 1; return; }
            ++table[size_t(cell(clamped(v)))];
        }
    }

    // The bracket, from the counts of all n values and a second pass over them; on all threads
    // (so not to be called from inside one of the pool's jobs).
    CramerVonMisesSum sum(const double *u, size_t stride) const;

  private:
    static double clamped(double v) { return v < 0 ? 0.0 : (v > 1 ? 1.0 : v); }
    int64_t cell(double v) const {   // of a clamped v
        const double f = v * double(K_);  // exact: K is a power of two, so cell edges are b / K exactly
        return f < double(K_) ? int64_t(f) : K_ - 1;
    }

    size_t n_;
    int64_t K_;
    // each worker's counts, owned by this object: the pool serves other callers between its
    // jobs, so a table kept by the worker's thread could be reset under the merge
    std::vector<std::vector<uint32_t>> tables_;
    std::vector<unsigned char> nan_in_;   // per worker: a NaN value seen
};

inline CramerVonMisesSum CramerVonMisesCounts::sum(const double *u, size_t stride) const {
    constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
    const size_t n = n_;
    if (n == 0) return {0.0, 0.0};
    if (std::find(nan_in_.begin(), nan_in_.end(), 1) != nan_in_.end()) return {kNaN, kNaN};
    const int64_t K = K_;
    thread_local std::vector<double> centres;   // per cell its values' mean c, cbar_b
    centres.resize(size_t(K));
    double *centre = centres.data();   // (a worker naming centres would get its own thread's)
    CompensatedSum cubes, pairs;
    const double twice_n = 2.0 * double(n);
    uint32_t rank = 0;   // of the values before cell b
    for (int64_t b = 0; b < K; ++b) {
        uint32_t m = 0;
        for (const std::vector<uint32_t> &table : tables_) m += table.empty() ? 0 : table[size_t(b)];
        // cbar_b = (2 r + m) / (2 n), once a cell (a division a value had cost the pass a
        // tenth of its time)
        centre[b] = (2.0 * double(rank) + double(m)) / twice_n;
        rank += m;
        if (m < 2) continue;
        const double md = double(m);
        cubes.add(md * (md * md - 1.0));
        pairs.add(md * (md - 1.0));
    }
    std::vector<double> blocks((n + 1023) / 1024);
    for_chunks(n, kCheckChunk, [&](size_t, size_t a, size_t b, int) {
        for (size_t s = a; s < b; s += 1024) {
            const size_t e = std::min(b, s + 1024);
            double block = 0;
            for (size_t i = s; i < e; ++i) {
                const double v = clamped(u[i * stride]);
                const double d = v - centre[cell(v)];
                block += d * d;
            }
            blocks[s / 1024] = block;
        }
    });
    CompensatedSum acc;
    for (double block : blocks) acc.add(block);
    const double nn = double(n) * double(n);
    return {acc.value() + cubes.value() / (12.0 * nn), pairs.value() / (double(K) * twice_n)};
}

// The bracket of S of n values u[i * stride] (above).
inline CramerVonMisesSum cramer_von_mises_sum(const double *u, size_t stride, size_t n) {
    // both passes on all threads in fixed chunks (kCheckChunk: whole blocks of the sums): the
    // counts merged, the block sums added in order after, so the same bits on any thread count
    // as one thread's loop (a column on one thread had left the other idle in a 1-D check)
    static_assert(kCheckChunk % 1024 == 0, "a chunk holds whole blocks of the sums");
    CramerVonMisesCounts counts(n);
    for_chunks(n, kCheckChunk,
               [&](size_t, size_t a, size_t b, int worker) { counts.count(u, stride, a, b, worker); });
    return counts.sum(u, stride);
}

// The statistics of the sampler check's transform tests (harness/samplers/transform.py) in one
// call: the Rosenblatt transform u of the parameter points s (n, k) (RosenblattTransform), the
// Cramer-von Mises sum of each column of u (cramer_von_mises_sum, to sums[0 .. k)) and
// the counts of the cells of equal claimed probability (point j in cell strip * bins +
// min(floor(v bins), bins - 1), v its u1 on the square and its u0 (strip 0) on an interval;
// a NaN v counts nowhere).  u stays in this thread's scratch buffers instead of going to
// Python with its strips: 24 MB of fresh arrays a check cost 8 ms of page faults, more than a
// third of the transform.  Fixed chunks on all hardware threads (count_on_threads), each
// chunk's values counted for the sums as it is transformed; the columns' second passes one
// after the other, each on all threads: the same for any thread count.
inline void transform_statistics(const PiecewiseLinearTable &marginal, const PiecewiseLinearTable *conditional,
                                 const double *edges, size_t nedges, const double *s, size_t k, size_t n,
                                 int64_t bins, CramerVonMisesSum *sums, double *counts) {
    const RosenblattTransform transform(marginal, conditional, edges, nedges);
    const int64_t strips = k == 2 ? int64_t(nedges) - 1 : 1;
    double *u[2] = {scratch(0, n), k == 2 ? scratch(1, n) : nullptr};
    std::vector<CramerVonMisesCounts> cvm(k, CramerVonMisesCounts(n));
    count_on_threads(n, size_t(strips * bins), counts, [&](size_t a, size_t b, int64_t *cells, int worker) {
        thread_local std::vector<int64_t> strip;
        strip.resize(kCheckChunk);
        transform(s, k, a, b, u[0], u[1], 1, strip.data());
        const double *binned = u[k - 1];
        for (size_t j = a; j < b; ++j) {
            const double v = binned[j];
            if (v != v) continue;
            int64_t i = int64_t(v * double(bins));
            i = i < 0 ? 0 : (i < bins - 1 ? i : bins - 1);
            ++cells[size_t(strip[j - a] * bins + i)];
        }
        // the sums' first pass while the chunk's u is in cache (a pass of its own over u had
        // cost the statistics a tenth of their time)
        for (size_t col = 0; col < k; ++col) cvm[col].count(u[col], 1, a, b, worker);
    });
    for (size_t col = 0; col < k; ++col) sums[col] = cvm[col].sum(u[col], 1);
}

// The deterministic pdf checks and the pdf moment of the sampler check, in one pass over the
// pdf values p (n) at the points with parameters s (n, k) and inside flags, each divided by
// `total` first (the density the check tests, pdf / total: numpy's division, here without
// its array; 1 changes no bit): `bad` counts p
// NaN, infinite or negative (all points), `zero` counts p == 0 at inside points; for the
// `used` inside points with a good p > 0, ps = p * J(s) (J the domain's measure per unit of
// parameter space: `measure`, or 1 / (1 - s)^2 on the half line) and h = ps / (ps + c)
// (c > 0) are summed.  A point where p is 0 is not used: under the claimed density it has
// probability 0, and it fails on its own (`zero`); used, it moved the moment's mean by 1 / n
// of h's mean, which for a constant density (h constant, its variance 0) rejected at p =
// 1e-58 a correct Mitsuba rectangle light whose one float32 edge sample in a million had
// pdf() 0.
struct PdfSummary {
    int64_t bad = 0, zero = 0, used = 0;
    double h_sum = 0;
};

// pdf_summary of points a .. b - 1 (its own function, arguments in registers; `s` null: the
// constant measure, else the half line's 1 / (1 - s)^2).  Without a branch on the data
// (nothing to mispredict where outside points and bad values mix in); h summed in blocks of
// 256, the block sums compensated (h is in [0, 1]: a block's plain sum is exact to 256 ulp).
// With the chunks on two threads, 2.2 -> 1.1 ms a million points.
inline PdfSummary pdf_summary_of(const double *s, size_t k, const bool *inside, const double *p, size_t a, size_t b,
                                 double measure, double c, double total) {
    PdfSummary r;
    CompensatedSum h;
    for (size_t e = a; e < b;) {
        const size_t end = std::min(b, e + 256);
        int64_t bad = 0, zero = 0, used = 0;
        double block = 0;
        for (size_t i = e; i < end; ++i) {
            const double v = p[i] / total;
            const bool is_bad = !(v >= 0 && v <= std::numeric_limits<double>::max());   // NaN, inf or < 0
            const bool in = inside[i];
            bad += is_bad;
            zero += in & (v == 0);
            const bool good = in & !is_bad & (v != 0);
            used += good;
            double jac = measure;
            if (s) {
                const double t = 1.0 - s[k * i];
                jac = 1.0 / (t * t);
            }
            const double ps = good ? v * jac : 0.0;
            block += c > 0 ? ps / (ps + c) : 0.0;
        }
        r.bad += bad, r.zero += zero, r.used += used;
        h.add(block);
        e = end;
    }
    r.h_sum = h.value();
    return r;
}

inline PdfSummary pdf_summary(CheckDomain d, double measure, const double *s, const bool *inside, const double *p,
                              size_t n, double c, double total) {
    const size_t k = size_t(domain_param_dim(d));
    const bool half_line = d == CheckDomain::half_line;
    const size_t chunks = (n + kCheckChunk - 1) / kCheckChunk;
    std::vector<PdfSummary> part(chunks);
    // fixed chunks on all hardware threads, each with its own compensated sum, merged in chunk
    // order below: the same for any thread count
    for_chunks(n, kCheckChunk, [&](size_t j, size_t a, size_t b, int) {
        part[j] = pdf_summary_of(half_line ? s : nullptr, k, inside, p, a, b, measure, c, total);
    });
    PdfSummary r;
    CompensatedSum h;
    for (const PdfSummary &q : part) {
        r.bad += q.bad;
        r.zero += q.zero;
        r.used += q.used;
        h.add(q.h_sum);
    }
    r.h_sum = h.value();
    return r;
}

// The rows i, in order, where the pdf a sampler reported with its sample, r[i], differs from
// the claimed pdf at the sample, p[i]: |r - p| > rtol |p| (or undefined: a NaN), or r is
// infinite or negative.  numpy's ~(abs(r - p) <= rtol * abs(p)) | ~isfinite(r) | (r < 0), the
// same operations, without its four temporaries of n values (12 ms a million samples in a
// Mitsuba check, in page faults).  Mismatches are rare: the rows are collected, not masked.
inline void pdf_mismatches(const double *r, const double *p, size_t n, double rtol, std::vector<int64_t> &rows) {
    constexpr double kMax = std::numeric_limits<double>::max();
    for (size_t i = 0; i < n; ++i) {
        const double v = r[i];
        if (!(std::fabs(v - p[i]) <= rtol * std::fabs(p[i]) && v >= 0 && v <= kMax)) rows.push_back(int64_t(i));
    }
}

}  // namespace re
