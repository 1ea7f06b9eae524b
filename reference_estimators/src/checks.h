// Batch kernels of the sampler check (harness/samplers/check.py): the per-sample work between
// the user's sample() and pdf() calls.  In numpy each step was a pass (or several) over a
// million points with temporaries, 0.25-0.4 s a check in all; here each is one pass without
// temporaries, and the Cramer-von Mises statistic needs no comparison sort, because its
// values lie in [0, 1] (a radix sort on their leading bits).  Every kernel computes what the numpy code
// did, in the same order of operations, so results agree to the last bit except where
// stated: sums (compensated here, pairwise in numpy) and the azimuth (fastmath's atan2_turns,
// within 2 ulp of numpy's mod(arctan2(y, x) / (2 pi), 1); libm's atan2 and fmod took 80 % of
// the sphere's map).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "accumulator.h"  // CompensatedSum
#include "fastmath.h"
#include "tables.h"       // RosenblattTransform

namespace re {

// The sampling domains of the sampler check, in the order of harness.samplers.domains.DOMAINS.
enum class CheckDomain : int { interval = 0, half_line = 1, square = 2, disk = 3, hemisphere = 4, sphere = 5 };

inline int domain_param_dim(CheckDomain d) { return d == CheckDomain::interval || d == CheckDomain::half_line ? 1 : 2; }
inline int domain_point_dim(CheckDomain d) {
    switch (d) {
        case CheckDomain::interval:
        case CheckDomain::half_line: return 1;
        case CheckDomain::square:
        case CheckDomain::disk: return 2;
        default: return 3;
    }
}

// s[2 i + 1] = the azimuth in turns of (x[stride i], x[stride i + 1]), for n points: whole
// vectors of fastmath's atan2_turns, then the scalar tail (the same bits).
inline void azimuths(const double *x, size_t stride, size_t n, double *s) {
    constexpr size_t W = simd::kWidth;
    size_t i = 0;
    for (; i + W <= n; i += W) {
        simd::f64v a, b;
        for (size_t w = 0; w < W; ++w) {
            a[w] = x[stride * (i + w)];
            b[w] = x[stride * (i + w) + 1];
        }
        const simd::f64v turns = fm::atan2_turns(b, a);
        for (size_t w = 0; w < W; ++w) s[2 * (i + w) + 1] = turns[w];
    }
    for (; i < n; ++i) s[2 * i + 1] = fm::atan2_turns(x[stride * i + 1], x[stride * i]);
}

// Parameters s (n, k) of points x (n, point_dim) and whether each lies inside the domain:
// the equal-measure maps of harness/samplers/domains.py (see there).  Unit vectors count as
// inside when their squared norm is within 1e-5 of 1 (float32 renderers); a non-finite
// point is outside (its s may be NaN).
inline void domain_params(CheckDomain d, double lo, double hi, const double *x, size_t n, double *s,
                          bool *inside) {
    switch (d) {
        case CheckDomain::interval:
            for (size_t i = 0; i < n; ++i) {
                const double v = x[i];
                s[i] = (v - lo) / (hi - lo);
                inside[i] = std::isfinite(v) && v >= lo && v <= hi;
            }
            return;
        case CheckDomain::half_line:
            for (size_t i = 0; i < n; ++i) {
                const double v = x[i];
                s[i] = v / (1.0 + v);
                inside[i] = std::isfinite(v) && v >= 0;
            }
            return;
        case CheckDomain::square:
            for (size_t i = 0; i < n; ++i) {
                const double a = x[2 * i], b = x[2 * i + 1];
                s[2 * i] = a;
                s[2 * i + 1] = b;
                inside[i] = std::isfinite(a) && std::isfinite(b) && a >= 0 && a <= 1 && b >= 0 && b <= 1;
            }
            return;
        case CheckDomain::disk:
            for (size_t i = 0; i < n; ++i) {
                const double a = x[2 * i], b = x[2 * i + 1];
                const double r2 = a * a + b * b;
                s[2 * i] = r2;
                inside[i] = std::isfinite(a) && std::isfinite(b) && r2 <= 1 + 1e-12;
            }
            azimuths(x, 2, n, s);
            return;
        case CheckDomain::hemisphere:
        case CheckDomain::sphere: {
            const bool hemi = d == CheckDomain::hemisphere;
            for (size_t i = 0; i < n; ++i) {
                const double a = x[3 * i], b = x[3 * i + 1], c = x[3 * i + 2];
                const double norm = a * a + b * b + c * c;
                const bool ok = std::isfinite(a) && std::isfinite(b) && std::isfinite(c) && std::fabs(norm - 1) <= 1e-5;
                const double z = c < -1 ? -1.0 : (c > 1 ? 1.0 : c);  // NaN passes
                s[2 * i] = hemi ? z : (1 - z) / 2;
                inside[i] = hemi ? ok && c >= -1e-12 : ok;
            }
            azimuths(x, 3, n, s);
            return;
        }
    }
}

// World directions out (n, 3) of the points h (n, 3) of the hemisphere through the
// equal-area map of the cap {d : <d, axis> >= cos_alpha} (harness/adapters/mitsuba/cap.py,
// Cap.to_world; frame t, b, axis orthonormal, scale = 1 - cos_alpha): h normalised, then
// c = clamp(cos_alpha + z scale, -1, 1) along the axis and the azimuth's cosine and sine as
// x / r and y / r (the pole r = 0 at azimuth 0), in numpy's order of operations.  A point
// below the horizon maps outside the cap; NaN rows give NaN.
inline void cap_to_world(const double *h, size_t n, const double *axis, const double *t, const double *b,
                         double cos_alpha, double scale, double *out) {
    for (size_t i = 0; i < n; ++i) {
        const double *p = h + 3 * i;
        const double len = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        const double x = p[0] / len, y = p[1] / len, z = p[2] / len;
        double c = cos_alpha + z * scale;
        c = c < -1 ? -1.0 : (c > 1 ? 1.0 : c);  // NaN passes
        const double r = std::hypot(x, y);
        const bool pole = r == 0;
        const double s = std::sqrt(std::max(0.0, 1 - c * c)) / (pole ? 1.0 : r);
        const double cos_phi = pole ? s : s * x, sin_phi = pole ? 0.0 : s * y;
        for (int j = 0; j < 3; ++j) out[3 * i + j] = cos_phi * t[j] + sin_phi * b[j] + c * axis[j];
    }
}

// Points x (n, point_dim; n values on the interval and half line) of parameters s (n, k):
// the inverse maps of domain_params, in numpy's order of operations except the azimuth's
// cosine and sine, which are fastmath's sincos_2pi of s1 (exact argument reduction; numpy's
// cos(2 pi s1) rounds 2 pi s1 first): the same points to rounding.
// One point on the disk (k = 2 coordinates out) or the (hemi)sphere (3 out) from its
// parameters, for double or simd::f64v lanes.
template <class D>
RE_INLINE void disk_point(D s0, D s1, D *x) {
    const D r = simd::sqrt(s0);
    D sn, cs;
    fm::sincos_2pi(s1, sn, cs);
    x[0] = r * cs;
    x[1] = r * sn;
}
template <class D>
RE_INLINE void sphere_point(bool hemi, D s0, D s1, D *x) {
    const D z = hemi ? s0 : 1 - 2 * s0;
    const D w = 1 - z * z;
    const D r = simd::sqrt(w > 0 ? w : D{});
    D sn, cs;
    fm::sincos_2pi(s1, sn, cs);
    x[0] = r * cs;
    x[1] = r * sn;
    x[2] = z;
}

// point(s0, s1, out) for every parameter pair of s (n, 2) into x (n, m): kWidth points at a
// time through the vector lanes (the azimuth's sincos is most of the work), the tail in
// scalars; the same bits either way.
template <int M, class Point>
RE_INLINE void map_pairs(const double *s, size_t n, double *x, Point point) {
    using simd::f64v;
    constexpr size_t W = simd::kWidth;
    size_t i = 0;
    for (; i + W <= n; i += W) {
        f64v s0, s1, out[M];
        for (size_t w = 0; w < W; ++w) {
            s0[w] = s[2 * (i + w)];
            s1[w] = s[2 * (i + w) + 1];
        }
        point(s0, s1, out);
        for (size_t w = 0; w < W; ++w)
            for (int j = 0; j < M; ++j) x[M * (i + w) + j] = out[j][w];
    }
    for (; i < n; ++i) point(s[2 * i], s[2 * i + 1], x + M * i);
}

inline void domain_points(CheckDomain d, double lo, double hi, const double *s, size_t n, double *x) {
    switch (d) {
        case CheckDomain::interval:
            for (size_t i = 0; i < n; ++i) x[i] = lo + (hi - lo) * s[i];
            return;
        case CheckDomain::half_line:
            for (size_t i = 0; i < n; ++i) x[i] = s[i] / (1.0 - s[i]);
            return;
        case CheckDomain::square:
            std::copy(s, s + 2 * n, x);
            return;
        case CheckDomain::disk:
            map_pairs<2>(s, n, x, [](auto s0, auto s1, auto *out) { disk_point(s0, s1, out); });
            return;
        case CheckDomain::hemisphere:
        case CheckDomain::sphere: {
            const bool hemi = d == CheckDomain::hemisphere;
            map_pairs<3>(s, n, x, [hemi](auto s0, auto s1, auto *out) { sphere_point(hemi, s0, s1, out); });
            return;
        }
    }
}

// Rows x (n, 3) as float32 unit vectors, column by column into out (3 rows of n): a row of
// length within `slack` of 1 is rounded as given, another finite non-zero one is normalised
// in double first; a row that is not a finite non-zero vector becomes +z with ok false.  What
// a float32 renderer's pdf is called with (Mitsuba's adapter), in one pass.
inline void float32_unit_rows(const double *x, size_t n, double slack, float *out, bool *ok) {
    for (size_t i = 0; i < n; ++i) {
        double a = x[3 * i], b = x[3 * i + 1], c = x[3 * i + 2];
        const double norm = std::sqrt(a * a + b * b + c * c);
        const bool good = std::isfinite(norm) && norm > 0;
        const double scale = good && std::fabs(norm - 1) > slack ? norm : 1.0;
        a = good ? a / scale : 0.0;
        b = good ? b / scale : 0.0;
        c = good ? c / scale : 1.0;
        out[i] = float(a);
        out[n + i] = float(b);
        out[2 * n + i] = float(c);
        ok[i] = good;
    }
}

// The nodes of a tensor rule with the g points `nodes` (in [0, 1]) per axis on each box
// [lo, hi] (boxes m = 0 .. boxes - 1, k = 1 or 2 coordinates each): node (i, j) of box m at
// row m g^k + i g + j, coordinate lo + (hi - lo) * node (numpy's meshgrid "ij" order).
inline void cubature_nodes(const double *lo, const double *hi, size_t boxes, size_t k, const double *nodes, size_t g,
                           double *out) {
    for (size_t m = 0; m < boxes; ++m) {
        const double a0 = lo[k * m], w0 = hi[k * m] - lo[k * m];
        if (k == 1) {
            for (size_t i = 0; i < g; ++i) out[m * g + i] = a0 + w0 * nodes[i];
            continue;
        }
        const double a1 = lo[k * m + 1], w1 = hi[k * m + 1] - lo[k * m + 1];
        double *row = out + 2 * m * g * g;
        for (size_t i = 0; i < g; ++i)
            for (size_t j = 0; j < g; ++j) {
                row[2 * (i * g + j)] = a0 + w0 * nodes[i];
                row[2 * (i * g + j) + 1] = a1 + w1 * nodes[j];
            }
    }
}

// Counts of the points marked inside on the regular grid of m0 (x m1) cells over [0, 1]^k
// (k = 1 when m1 == 0), C order: each coordinate clamped to [0, 1 - 2^-53] first, then cell
// floor(s m) (at most m - 1).  Points outside, or with a NaN coordinate, are not counted.
inline void grid_histogram(const double *s, size_t n, const bool *inside, int64_t m0, int64_t m1, double *counts) {
    constexpr double top = 1.0 - 0x1p-53;  // np.nextafter(1, 0)
    const size_t k = m1 > 0 ? 2 : 1;
    const size_t cells = size_t(m0) * size_t(m1 > 0 ? m1 : 1);
    std::vector<int64_t> c(cells, 0);
    auto cell = [top](double v, int64_t m) {
        v = v < 0 ? 0.0 : (v > top ? top : v);
        const int64_t j = int64_t(v * double(m));
        return j < m - 1 ? j : m - 1;
    };
    for (size_t i = 0; i < n; ++i) {
        if (!inside[i]) continue;
        const double a = s[k * i];
        if (a != a) continue;
        int64_t idx = cell(a, m0);
        if (k == 2) {
            const double b = s[k * i + 1];
            if (b != b) continue;
            idx = idx * m1 + cell(b, m1);
        }
        ++c[size_t(idx)];
    }
    for (size_t j = 0; j < cells; ++j) counts[j] = double(c[j]);
}

// Scratch buffer `which` (0 to 3) of this thread, at least n doubles, contents undefined:
// kept between calls, because a fresh 8 MB buffer a call costs thousands of page faults
// (more than the sort itself on a loaded machine).
inline double *scratch(int which, size_t n) {
    thread_local std::vector<double> buffers[4];  // 0, 1: sort_unit_interval; 2, 3: transform_statistics
    std::vector<double> &b = buffers[which];
    if (b.size() < n) b.resize(n);
    return b.data();
}

// The values of u (n, at stride `stride`) sorted ascending into out (n), for values in
// [0, 1]: a least-significant-digit radix sort on the 20-bit key floor(u 2^20) (clamped to
// 0 .. 2^20 - 1; two stable scatters of 10 bits, each into 1024 buckets whose write streams
// stay in cache), then an insertion sort within equal keys: O(n) for values spread over
// [0, 1], O(n log n) at worst (std::sort takes over), correct for any finite values (the key
// is monotone).  Measured at a million values: 1.7x faster than 11-bit digits, and faster
// than a most-significant-digit first pass; 9-bit digits leave too many values per key for
// the insertion sort.  No NaN may be present.
inline void sort_unit_interval(const double *u, size_t stride, size_t n, double *out) {
    constexpr int64_t kBits = 10, kDigit = int64_t(1) << kBits, kKeys = kDigit * kDigit;
    auto key = [](double v) {
        const double f = v * double(kKeys);
        return f < 0 ? int64_t(0) : (f < double(kKeys) ? int64_t(f) : kKeys - 1);
    };
    std::vector<size_t> low(kDigit + 1, 0), high(kDigit + 1, 0);
    for (size_t i = 0; i < n; ++i) {
        const int64_t k = key(u[i * stride]);
        ++low[size_t(k & (kDigit - 1)) + 1];
        ++high[size_t(k >> kBits) + 1];
    }
    for (int64_t j = 0; j < kDigit; ++j) {
        low[size_t(j + 1)] += low[size_t(j)];
        high[size_t(j + 1)] += high[size_t(j)];
    }
    double *tmp = scratch(1, n);
    for (size_t i = 0; i < n; ++i) {
        const double v = u[i * stride];
        tmp[low[size_t(key(v) & (kDigit - 1))]++] = v;
    }
    for (size_t i = 0; i < n; ++i) {
        const double v = tmp[i];
        out[high[size_t(key(v) >> kBits)]++] = v;
    }
    // now sorted by key: only values of equal key can be out of order.  An insertion sort
    // finishes that in one pass where keys are spread; where values crowd into a few keys its
    // moves would grow as their square, so past 8 n moves std::sort takes over.
    size_t moves = 0;
    for (size_t i = 1; i < n; ++i) {
        const double v = out[i];
        if (!(out[i - 1] > v)) continue;
        size_t y = i;
        for (; y > 0 && out[y - 1] > v; --y) out[y] = out[y - 1];
        out[y] = v;
        moves += i - y;
        if (moves > 8 * n) {
            std::sort(out, out + n);
            return;
        }
    }
}

// sqrt(sum_i (c_i - x_(i))^2), c_i = (2 i - 1) / (2 n), over the sorted values x_(1..n) of u
// (n, at stride `stride`, meant in [0, 1]): the root part of the Cramer-von Mises statistic
// n W^2 - 1/(12 n).  NaN if any u is NaN (numpy's sort puts NaN last and the sum is NaN).
inline double cramer_von_mises_root(const double *u, size_t stride, size_t n) {
    for (size_t i = 0; i < n; ++i)
        if (u[i * stride] != u[i * stride]) return std::numeric_limits<double>::quiet_NaN();
    double *x = scratch(0, n);
    sort_unit_interval(u, stride, n, x);
    // blocks of 1024 terms summed in vector lanes, the block sums compensated: error of the
    // order of numpy's pairwise sum.  2 i + 1 is carried as an exact double, so c_i is the
    // same correctly rounded quotient as numpy's.
    constexpr size_t W = simd::kWidth;
    CompensatedSum acc;
    const double twice_n = 2.0 * double(n);
    simd::f64v odd;
    for (size_t w = 0; w < W; ++w) odd[w] = double(2 * w + 1);
    for (size_t a = 0; a < n; a += 1024) {
        const size_t b = std::min(n, a + 1024);
        simd::f64v lanes{};
        size_t i = a;
        for (; i + W <= b; i += W) {
            const simd::f64v d = odd / twice_n - simd::load(x + i);
            lanes += d * d;
            odd += double(2 * W);
        }
        double block = 0;
        for (; i < b; ++i) {
            const double d = double(2 * i + 1) / twice_n - x[i];
            block += d * d;
        }
        for (size_t w = 0; w < W; ++w) block += lanes[w];
        acc.add(block);
        for (size_t w = 0; w < W; ++w) odd[w] = double(2 * (i + w) + 1);
    }
    return std::sqrt(acc.value());
}

// The statistics of the sampler check's transform tests (harness/samplers/transform.py) in one
// call: the Rosenblatt transform u of the parameter points s (n, k) (RosenblattTransform), the
// Cramer-von Mises root of each column of u (cramer_von_mises_root, to roots[0 .. k)) and
// the counts of the cells of equal claimed probability (point j in cell strip * bins +
// min(floor(v bins), bins - 1), v its u1 on the square and its u0 (strip 0) on an interval;
// a NaN v counts nowhere).  u stays in this thread's scratch buffers instead of going to
// Python with its strips: 24 MB of fresh arrays a check cost 8 ms of page faults, more than a
// third of the transform.  Fixed chunks on all hardware threads, the columns sorted in
// parallel, per-chunk integer counts summed: the same for any thread count.
inline void transform_statistics(const PiecewiseLinearTable &marginal, const PiecewiseLinearTable *conditional,
                                 const double *edges, size_t nedges, const double *s, size_t k, size_t n,
                                 int64_t bins, double *roots, double *counts) {
    const RosenblattTransform transform(marginal, conditional, edges, nedges);
    const int64_t strips = k == 2 ? int64_t(nedges) - 1 : 1;
    double *u[2] = {scratch(2, n), k == 2 ? scratch(3, n) : nullptr};
    const size_t chunks = (n + kCheckChunk - 1) / kCheckChunk;
    std::vector<int64_t> chunk_counts(chunks * size_t(strips * bins), 0);
    for_chunks(n, kCheckChunk, [&](size_t c, size_t a, size_t b, int) {
        thread_local std::vector<int64_t> strip;
        strip.resize(kCheckChunk);
        transform(s, k, a, b, u[0], u[1], 1, strip.data());
        const double *binned = u[k - 1];
        int64_t *cells = &chunk_counts[c * size_t(strips * bins)];
        for (size_t j = a; j < b; ++j) {
            const double v = binned[j];
            if (v != v) continue;
            int64_t i = int64_t(v * double(bins));
            i = i < 0 ? 0 : (i < bins - 1 ? i : bins - 1);
            ++cells[size_t(strip[j - a] * bins + i)];
        }
    });
    for (size_t c = 0; c < size_t(strips * bins); ++c) {
        int64_t total = 0;
        for (size_t h = 0; h < chunks; ++h) total += chunk_counts[h * size_t(strips * bins) + c];
        counts[c] = double(total);
    }
    ThreadPool::instance().run(k, ThreadPool::default_threads(),
                               [&](size_t c, int) { roots[c] = cramer_von_mises_root(u[c], 1, n); });
}

// The deterministic pdf checks and the pdf moment of the sampler check, in one pass over the
// pdf values p (n) at the points with parameters s (n, k) and inside flags: `bad` counts p
// NaN, infinite or negative (all points), `zero` counts p == 0 at inside points; for the
// inside points with a good p, ps = p * J(s) (J the domain's measure per unit of parameter
// space: `measure`, or 1 / (1 - s)^2 on the half line) and h = ps / (ps + c) (c > 0) are
// summed.
struct PdfSummary {
    int64_t bad = 0, zero = 0, used = 0;
    double h_sum = 0;
};

inline PdfSummary pdf_summary(CheckDomain d, double measure, const double *s, const bool *inside, const double *p,
                              size_t n, double c) {
    PdfSummary r;
    CompensatedSum h;
    const size_t k = size_t(domain_param_dim(d));
    const bool half_line = d == CheckDomain::half_line;
    for (size_t i = 0; i < n; ++i) {
        const double v = p[i];
        const bool bad = !std::isfinite(v) || v < 0;
        r.bad += bad;
        if (!inside[i]) continue;
        r.zero += v == 0;
        if (bad) continue;
        double ps;
        if (half_line) {
            const double t = 1.0 - s[k * i];
            ps = v * (1.0 / (t * t));
        } else {
            ps = v * measure;
        }
        ++r.used;
        if (c > 0) h.add(ps / (ps + c));
    }
    r.h_sum = h.value();
    return r;
}

}  // namespace re
