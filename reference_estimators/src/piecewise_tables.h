// pbrt-v4's piecewise-constant tables, sampled in batches: the bins of a block of points by
// counting CDF entries in vector lanes, then the points.  Used by the table samplers
// (table_samplers.cpp: piecewise_constant_1d, piecewise_constant_2d).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "accumulator.h"
#include "simd.h"

namespace re {

// Tables of pbrt-v4's PiecewiseConstant1D over [a, b], any number of them with the same bin
// count laid out flat (table k's CDF at cdf[k (bins + 1) ..], its values and empty-bin map at
// [k bins ..]): one table for the 1-D sampler, a row's conditional each for the 2-D one,
// whose points draw from their rows' tables in one batch (sample_many).
struct PiecewiseTables {
    size_t bins;
    double a, b;
    std::vector<double> cdf, f, scale;
    std::vector<int64_t> below;   // below[k bins + o]: the last non-empty bin at or below o (or 0)
    // The CDFs again for bin_of_u's counting search, in levels: level 0 holds table k's
    // cdf[1 .. bins], level l + 1 the last entry of each group of kWidth entries of level l;
    // table k's level l at levels[l][k width[l] ..], padded with +inf to a whole number of
    // vectors and one vector more.  The top level (at most kTopVectors vectors) is counted
    // whole; each level below it, in the one group the count so far points to.  Where every
    // CDF is non-decreasing a group lies wholly at or below u exactly when its last entry
    // does, so the count is the last bin with cdf[o] <= u, as a halving search finds it; where
    // one is not (counted false), the halving search is used.
    std::vector<std::vector<double>> levels;
    std::vector<size_t> width;
    bool counted = true;
    // edge[o]: the least double x with bin_of_x(x) >= o (edge[0] = -inf, edge[bins] = inf), so
    // bin_of_x(x) == o exactly where edge[o] <= x < edge[o + 1]: two comparisons in place of
    // bin_of_x's division where a sampled point is checked to lie in its bin.
    std::vector<double> edge;
    double inv_bins;   // 1 / bins where bins is a power of 2 (dividing by it is multiplying by that, exactly), else 0
    double inv_width;  // 1 / (b - a) where b - a is a power of 2 (the unit interval's 1: likewise exact), else 0
    bool gaps = false; // whether a table has an empty bin (else below[k bins + o] = o)

    // No tables yet, each to have `bins` bins over [a, b].
    explicit PiecewiseTables(size_t bins, double a = 0, double b = 1)
        : bins(bins), a(a), b(b), edge(bins + 1), inv_bins((bins & (bins - 1)) == 0 ? 1.0 / double(bins) : 0.0),
          inv_width(exact_reciprocal(b - a)) {
        edge[0] = -INFINITY;
        for (size_t o = 1; o < bins; ++o) edge[o] = first_above(a, b, o - 1);
        edge[bins] = INFINITY;
        constexpr size_t W = simd::kWidth;
        size_t entries = bins;
        for (;;) {
            width.push_back((entries + W - 1) / W * W + W);
            if (entries <= kTopVectors * W) break;
            entries = (entries + W - 1) / W;
        }
        levels.resize(width.size());
    }

    // Appends the table of the values f (bins of them, the same count for every table; not all
    // zero): table k = the count of tables before it.
    void add(const std::vector<double> &values) {
        const size_t base = cdf.size();
        cdf.push_back(0.0);
        CompensatedSum s;
        for (double v : values) { s.add(v); cdf.push_back(s.value()); }
        const double total = s.value();
        for (size_t i = base; i < cdf.size(); ++i) cdf[i] /= total;
        cdf.back() = 1.0;
        f.insert(f.end(), values.begin(), values.end());
        scale.push_back(double(values.size()) / (total * (b - a)));
        for (size_t o = 0; o < bins; ++o) {
            size_t e = o;
            while (e > 0 && cdf[base + e + 1] == cdf[base + e]) --e;
            below.push_back(int64_t(e));
            gaps |= e != o;
        }
        for (size_t o = 0; counted && o < bins; ++o) counted = cdf[base + o] <= cdf[base + o + 1];
        if (!counted) {
            levels.clear();
            return;
        }
        constexpr size_t W = simd::kWidth;
        const size_t k = below.size() / bins - 1;
        for (size_t l = 0; l < levels.size(); ++l) {
            std::vector<double> &level = levels[l];
            if (l == 0) {
                level.insert(level.end(), cdf.begin() + base + 1, cdf.end());
            } else {
                const double *finer = &levels[l - 1][k * width[l - 1]];
                for (size_t g = 0; g < (width[l - 1] - W) / W; ++g) level.push_back(finer[g * W + W - 1]);
            }
            level.resize((k + 1) * width[l], INFINITY);
        }
    }

    // Bin o of table k for uniform u: the last with cdf[o] <= u (u below cdf[0] = 0 or NaN
    // gives 0, u = 1 the last bin), moved down past empty bins: by counting the CDF's
    // entries <= u, a vector of entries a compare, one dependent load a level (see levels),
    // where a halving search waits for one a halving.
    size_t bin_of_u(size_t k, double u) const {
        size_t o;
        bins_of_u(&k, &u, &o, 1, 1);
        return o;
    }
    // bin_of_u for n points, point j's table k[j] (table 0 where k is null) and uniform
    // u[j * ustride], its bin to o[j]; the search chosen once for all of them.
    template <class K, class O>
    void bins_of_u(const K *k, const double *u, O *o, size_t n, size_t ustride) const {
        constexpr Search kLevels = Search::CountLevels, kHalving = Search::Halving;
        if (!counted)
            gaps ? search<kHalving, true>(k, u, o, n, ustride) : search<kHalving, false>(k, u, o, n, ustride);
        else if (levels.size() == 1)
            switch (width[0] / simd::kWidth - 1) {   // the vectors counted: 1 to 4 unrolled
                case 1: count_search<1>(k, u, o, n, ustride); break;
                case 2: count_search<2>(k, u, o, n, ustride); break;
                case 3: count_search<3>(k, u, o, n, ustride); break;
                case 4: count_search<4>(k, u, o, n, ustride); break;
                default: count_search<0>(k, u, o, n, ustride);
            }
        else
            gaps ? search<kLevels, true>(k, u, o, n, ustride) : search<kLevels, false>(k, u, o, n, ustride);
    }

    // x's position on [a, b] in units of bins: (x - a) / (b - a) * bins, the division a
    // multiplication where that is exact.
    template <class D>
    D position(D x) const { return (inv_width > 0 ? (x - a) * inv_width : (x - a) / (b - a)) * double(bins); }
    size_t bin_of_x(double x) const { return std::min(size_t(position(x)), bins - 1); }
    // bin_of_x in vector lanes, as doubles, for positions in [0, 2^53) (where size_t(p) is
    // floor(p)); a NaN lane stays NaN and a negative position gives a negative value: neither
    // is a bin (sample_many's landing check sends those points through placed).
    simd::f64v bins_of_x(simd::f64v x) const {
        return simd::min_or_second(double(bins - 1) - simd::f64v{}, simd::floor(position(x)));
    }
    bool in_bin(double x, size_t o) const { return x >= edge[o] && x < edge[o + 1]; }
    // Table k's density and CDF at x in [a, b].
    double density(size_t k, double x) const { return f[k * bins + bin_of_x(x)] * scale[k]; }
    double cdf_at(size_t k, double x) const {
        const size_t o = bin_of_x(x);
        const double *c = &cdf[k * (bins + 1)];
        const double s = position(x) - double(o);
        return c[o] + s * (c[o + 1] - c[o]);
    }

    // The points of uniforms u in bins o (vector lanes; o as doubles) whose CDF entries there
    // are lo and hi: sample_many's, lane by lane the same bits (unplaced, then placed point by
    // point in the rare vector with a lane outside its bin).  For kernels that find the bins
    // and their entries themselves (SmallTable2D).
    simd::f64v points_in(simd::f64v u, simd::f64v lo, simd::f64v hi, simd::f64v o) const {
        simd::f64v x = unplaced(u, lo, hi, o);
        if (!simd::all_equal(bins_of_x(x), o))
            for (size_t l = 0; l < simd::kWidth; ++l) x[l] = placed(x[l], size_t(o[l]));
        return x;
    }

    // pbrt's sample: x in bin o of table k, its density back.
    double sample_one(size_t k, double u, double *x) const { return point_in(k, bin_of_u(k, u), u, x); }

    // sample_one for n points, point j from table k[j] (table 0 when k is null) with the
    // uniform u[j * ustride], its x to x[j * xstride] and its density to p[j] (unless p is
    // null); the bin x lies in to landed[j] if asked.  In blocks of four passes: the points'
    // bins (one pass, so that the out-of-order core overlaps many points' searches; the bins'
    // entries loaded in the same loop ran the 2-D table sampler 1.4x slower), those bins' CDF
    // entries (scalar loads: vector gathers were slower, on AMD's Zen 3 and Zen 4 alike), the
    // points in vector lanes, then the checks that they landed in their bins (in vector lanes)
    // and the strided stores.
    // The same bits as sample_one.
    void sample_many(const int64_t *k, const double *u, size_t ustride, size_t n, double *x, size_t xstride,
                     double *p, int64_t *landed = nullptr) const {
        constexpr size_t kBlock = 256;
        uint32_t bin[kBlock];
        alignas(64) double uj[kBlock], lo[kBlock], hi[kBlock], o[kBlock], xj[kBlock];
        for (size_t a0 = 0; a0 < n; a0 += kBlock) {
            const size_t m = std::min(kBlock, n - a0);
            bins_of_u(k ? k + a0 : k, u + a0 * ustride, bin, m, ustride);
            for (size_t j = 0; j < m; ++j) {
                const size_t t = k ? size_t(k[a0 + j]) : 0, bj = bin[j];
                const double *c = &cdf[t * (bins + 1)];
                uj[j] = u[(a0 + j) * ustride];
                lo[j] = c[bj];
                hi[j] = c[bj + 1];
                o[j] = double(bj);
                if (p) p[a0 + j] = f[t * bins + bj] * scale[t];
            }
            size_t j = 0;
            for (; j + simd::kWidth <= m; j += simd::kWidth)
                simd::store(xj + j, unplaced(simd::load(uj + j), simd::load(lo + j), simd::load(hi + j),
                                             simd::load(o + j)));
            for (; j < m; ++j) xj[j] = unplaced(uj[j], lo[j], hi[j], o[j]);
            // a vector whose points all lie in their bins is stored as it is (x lies in bin o
            // exactly where bin_of_x(x) == o, edge's definition; bins_of_x gives it in lanes),
            // the rare other one point by point through placed: the scalar check a point had
            // cost a sample a tenth of its time
            const auto place = [&](size_t i) {
                const double xs = placed(xj[i], bin[i]);
                x[(a0 + i) * xstride] = xs;
                // bin[i], unless bin i holds no double (placed then went past it)
                if (landed) landed[a0 + i] = int64_t(in_bin(xs, bin[i]) ? bin[i] : bin_of_x(xs));
            };
            for (j = 0; j + simd::kWidth <= m; j += simd::kWidth) {
                const simd::f64v xv = simd::load(xj + j);
                if (!simd::all_equal(bins_of_x(xv), simd::load(o + j))) {
                    for (size_t l = 0; l < simd::kWidth; ++l) place(j + l);
                    continue;
                }
                for (size_t l = 0; l < simd::kWidth; ++l) x[(a0 + j + l) * xstride] = xv[l];
                if (landed)
                    for (size_t l = 0; l < simd::kWidth; ++l) landed[a0 + j + l] = int64_t(bin[j + l]);
            }
            for (; j < m; ++j) place(j);
        }
    }

  private:
    static constexpr size_t kTopVectors = 8;

    // The one-level count over a top level of kTop vectors (0: as many as it holds), its loop
    // unrolled where kTop is known: a 16-bin table's two vectors (AVX-512; four on AVX2) had
    // cost a loop branch a point (hot_paths.py's 16 x 16 table row ran 1.06x faster unrolled);
    // AVX2's four counted at once (simd::count_at_most_vectors: the AVX2 build's 16 x 16 table
    // sampling 8.1 -> 6.4 ns a sample, Zen 4).
    template <size_t kTop, class K, class O>
    void count_search(const K *k, const double *u, O *o, size_t n, size_t ustride) const {
        gaps ? search<Search::Count, true, kTop>(k, u, o, n, ustride)
             : search<Search::Count, false, kTop>(k, u, o, n, ustride);
    }
    // bins_of_u's searches: by counting, in one level (Count) or several (CountLevels), or a
    // branch-free halving search (a mispredicted branch a step cost more than the rest; it
    // moves lo only onto values <= u, so lo is the bin or 0 already); then past empty bins
    // where a table has any (has_gaps).
    enum class Search { Count, CountLevels, Halving };
    template <Search how, bool has_gaps, size_t kTop = 0, class K, class O>
    void search(const K *k, const double *u, O *o, size_t n, size_t ustride) const {
        constexpr size_t W = simd::kWidth;
        const size_t top = levels.empty() ? 0 : levels.size() - 1, top_width = levels.empty() ? 0 : width[top];
        const double *top_level = levels.empty() ? nullptr : levels[top].data();
        // its entries, less the padding vector
        const size_t top_count = kTop ? kTop * W : levels.empty() ? 0 : top_width - W;
        for (size_t j = 0; j < n; ++j) {
            const size_t t = k ? size_t(k[j]) : 0;
            const double uj = u[j * ustride];
            size_t lo = 0;
            if (how == Search::Halving) {
                const double *c = &cdf[t * (bins + 1)];
                size_t len = bins + 1;
                while (len > 1) {
                    const size_t half = len / 2;
                    lo = c[lo + half] <= uj ? lo + half : lo;
                    len -= half;
                }
            } else {
                const double *c = top_level + t * top_width;
                if constexpr (kTop > 0)
                    lo = simd::count_at_most_vectors<kTop>(c, uj);
                else
                    for (size_t i = 0; i < top_count; i += W) lo += simd::count_at_most(c + i, uj);
                for (size_t l = top; how == Search::CountLevels && l-- > 0;) {
                    lo = std::min(lo, width[l] / W - 1);   // the padding's group at most (u = +inf)
                    lo = lo * W + simd::count_at_most(&levels[l][t * width[l] + lo * W], uj);
                }
            }
            lo = std::min(lo, bins - 1);
            o[j] = O(has_gaps ? size_t(below[t * bins + lo]) : lo);
        }
    }

    // 1 / w where w is a power of 2 and 1 / w a normal double (then v / w == v * (1 / w) for
    // every v, subnormal results included), else 0.
    static double exact_reciprocal(double w) {
        int e;
        const bool power_of_two = w > 0 && std::frexp(w, &e) == 0.5;
        const double r = 1.0 / w;
        return power_of_two && std::isnormal(r) ? r : 0.0;
    }

    // x in bin o of table k for uniform u, and its density.
    double point_in(size_t k, size_t o, double u, double *x) const {
        const double *c = &cdf[k * (bins + 1)];
        x[0] = placed(unplaced(u, c[o], c[o + 1], double(o)), o);
        return f[k * bins + o] * scale[k];
    }

    // The point of uniform u in bin o (as a double: D may be a vector of bins) whose CDF runs
    // from lo to hi, before placed: min(a + t (b - a), b) as std::min gives it.
    template <class D>
    RE_INLINE D unplaced(D u, D lo, D hi, D o) const {
        const D du = (u - lo) / (hi - lo);
        const D t = inv_bins > 0 ? (o + du) * inv_bins : (o + du) / double(bins);
        return simd::min_or_second(b - D{}, a + t * (b - a));   // b - 0 is b, -0 included
    }

    // Rounding can put x on the edge of a neighbouring bin (then pdf(x) would report that
    // bin's density, possibly 0): x moved to the nearest double inside bin o, the last below
    // its upper edge or its lower edge itself (if bin o holds no double, that edge).
    double placed(double xs, size_t o) const {
        if (!in_bin(xs, o)) {
            if (xs >= edge[o + 1]) xs = std::nextafter(edge[o + 1], -INFINITY);
            if (xs < edge[o]) xs = edge[o];
        }
        return xs;
    }

    // The smallest double x in (lo, hi] with bin_of_x(x) > o, for bin_of_x(lo) <= o <
    // bin_of_x(hi): bin_of_x never decreases as x grows, so a bisection over the doubles in
    // their order (sign-adjusted bits as integers) finds it in at most 64 steps (the edges;
    // point_in once stepped to them one ulp at a time, which never ended where an edge lies
    // near 0: the ulps there are as small as the subnormals).
    double first_above(double lo, double hi, size_t o) const {
        const auto key = [](double d) { const uint64_t u = simd::bits(d); return u >> 63 ? ~u : u | (1ull << 63); };
        const auto value = [](uint64_t q) { return simd::from_bits(q >> 63 ? q & ~(1ull << 63) : ~q); };
        uint64_t below = key(lo), above = key(hi);
        while (above - below > 1) {
            const uint64_t mid = below + (above - below) / 2;
            (bin_of_x(value(mid)) > o ? above : below) = mid;
        }
        return value(above);
    }
};

}  // namespace re
