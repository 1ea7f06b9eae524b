// Point sets an estimator draws its canonical uniforms from.  Sample i of an estimate of n
// samples with ud uniforms each:
//   Random      the chunk's PCG32 stream, in order (i.i.d. uniforms);
//   Stratified  jittered grid: k = floor(n^(1/ud)) strata per dimension; samples i < k^ud
//               take cell i (mixed radix) plus a uniform jitter from the stream, the rest
//               are plain uniform (each sample stays marginally uniform: unbiased for any n);
//   Sobol       Sobol' points (Joe-Kuo direction numbers, loaded from scipy at import) with
//               nested uniform (Owen) scrambling per dimension by the hash-based permutation
//               of Burley (2020), seeded from (seed, case, replica, dimension).
// Stratified and Sobol estimates are not sums of independent samples: their error comes
// from replicas (independent randomisations), never from the per-sample variance.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "pcg32.h"

namespace re {

enum class PointSetKind { Random, Stratified, Sobol };

inline const char *point_set_name(PointSetKind k) {
    switch (k) {
        case PointSetKind::Random: return "random";
        case PointSetKind::Stratified: return "stratified";
        case PointSetKind::Sobol: return "sobol";
    }
    return "?";
}

// Direction numbers v[d * 32 + k] (bit k of the index -> 32-bit direction), set once, and
// the unscrambled points of the first kSobolLow indices of every dimension, low[d * kSobolLow
// + l]: Sobol' points are linear over XOR in the index bits, x(i) = x(i's high bits) ^ x(i's
// low bits), so a point is one XOR with an entry of that table.  Built here once (2 MB for 256
// dimensions): built per block of points, its chain of dependent loads had cost as much as
// the points themselves.
inline constexpr uint32_t kSobolLowBits = 11, kSobolLow = 1u << kSobolLowBits;
struct SobolDirections {
    std::vector<uint32_t> v, low;
    int dims = 0;

    void set(const uint32_t *directions, int count) {
        v.assign(directions, directions + size_t(count) * 32);
        dims = count;
        low.assign(size_t(count) * kSobolLow, 0);
        for (int d = 0; d < count; ++d) {
            uint32_t *t = low.data() + size_t(d) * kSobolLow;
            for (uint32_t l = 1; l < kSobolLow; ++l) t[l] = t[l & (l - 1)] ^ v[size_t(d) * 32 + __builtin_ctz(l)];
        }
    }
};
SobolDirections &sobol_directions();

inline uint32_t reverse_bits(uint32_t x) {
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
    return (x >> 16) | (x << 16);
}

// Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020: a hash that only lets
// lower bits affect higher ones (a Laine-Karras style permutation), applied to the reversed
// bits, is a nested uniform scramble of the original bits.
inline uint32_t owen_scramble(uint32_t x, uint32_t seed) {
    x = reverse_bits(x);
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return reverse_bits(x);
}

inline uint32_t sobol_bits(uint64_t index, int dim, const SobolDirections &dirs) {
    const uint32_t *v = dirs.v.data() + size_t(dim) * 32;
    uint32_t x = 0;
    for (int k = 0; index && k < 32; ++k, index >>= 1)
        if (index & 1u) x ^= v[k];
    return x;
}

// Strata per dimension for n samples of ud dimensions: the largest k with k^ud <= n.
inline uint64_t strata_per_dim(uint64_t n, int ud) {
    uint64_t k = uint64_t(std::pow(double(n), 1.0 / ud));
    auto fits = [&](uint64_t kk) {
        long double p = 1;
        for (int j = 0; j < ud; ++j) p *= (long double)kk;
        return p <= (long double)n;
    };
    while (k > 1 && !fits(k)) --k;
    while (fits(k + 1)) ++k;
    return k < 1 ? 1 : k;
}

struct PointSetContext {
    PointSetKind kind = PointSetKind::Random;
    uint64_t n = 0;     // samples in the estimate (stratified: defines the grid)
    StreamKey key;      // (seed, case, replica): scrambling seeds for Sobol
};

// u[m * ud] for samples first..first+m of the estimate.
inline void fill_points(const PointSetContext &ctx, UniformStream &stream, uint64_t first, size_t m, int ud, double *u) {
    switch (ctx.kind) {
        case PointSetKind::Random:
            stream.fill(u, m * size_t(ud));
            return;
        case PointSetKind::Stratified: {
            stream.fill(u, m * size_t(ud));  // the jitter
            const uint64_t k = strata_per_dim(ctx.n, ud);
            uint64_t cells = 1;
            for (int j = 0; j < ud; ++j) cells *= k;
            const double inv = 1.0 / double(k);
            for (size_t i = 0; i < m; ++i) {
                uint64_t cell = first + i;
                if (cell >= cells) continue;
                for (int j = 0; j < ud; ++j) {
                    double c = double(cell % k);
                    cell /= k;
                    double v = (c + u[i * ud + j]) * inv;
                    u[i * ud + j] = v < 1.0 ? v : 0x1.fffffffffffffp-1;
                }
            }
            return;
        }
        case PointSetKind::Sobol: {
            const SobolDirections &dirs = sobol_directions();
            if (ud > dirs.dims)
                throw std::invalid_argument("Sobol' points need " + std::to_string(ud) +
                                            " dimensions; direction numbers are loaded for " + std::to_string(dirs.dims));
            // x(i) = x(hi) ^ x(lo), lo the low kSobolLowBits bits (SobolDirections::low)
            for (int j = 0; j < ud; ++j) {
                const uint32_t *low = dirs.low.data() + size_t(j) * kSobolLow;
                StreamKey dk = ctx.key;
                dk.chunk = 0x50b01ULL + uint64_t(j);
                uint32_t seed = uint32_t(splitmix64(dk.seed ^ splitmix64(dk.case_id ^ splitmix64(dk.replica ^ splitmix64(dk.chunk)))));
                // in runs of one high index, so that the loop over a run has no branch and
                // vectorises (a Sobol' estimate had spent two thirds of its time here)
                for (size_t i0 = 0; i0 < m;) {
                    const uint64_t hi_index = (first + i0) >> kSobolLowBits;
                    const size_t i1 = std::min<uint64_t>(m, ((hi_index + 1) << kSobolLowBits) - first);
                    const uint32_t hi_bits = sobol_bits(hi_index << kSobolLowBits, j, dirs);
                    const uint32_t lo0 = uint32_t((first + i0) & (kSobolLow - 1));
                    double *out = u + j;
                    for (size_t i = i0; i < i1; ++i) {
                        const uint32_t x = owen_scramble(hi_bits ^ low[lo0 + (i - i0)], seed);
                        out[i * ud] = (double(x) + 0.5) * 0x1p-32;
                    }
                    i0 = i1;
                }
            }
            return;
        }
    }
}

}  // namespace re
