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

inline uint32_t reverse_bits(uint32_t x) {
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
    return (x >> 16) | (x << 16);
}

// Direction numbers, set once, bit-reversed: rv[d * 32 + k] (bit k of the index -> the
// reversed 32-bit direction), and the reversed unscrambled points of the first kSobolLow
// indices of every dimension, rlow[d * kSobolLow + l].  Sobol' points are linear over XOR in
// the index bits, x(i) = x(i's high bits) ^ x(i's low bits), so a point is one XOR with an
// entry of that table; and bit reversal is linear over XOR too, so the reversed point, which
// Owen scrambling starts from (owen_scramble_reversed), is the XOR of reversed entries: no
// reversal a point on the way in.  Built here once (2 MB for 256 dimensions): built per block
// of points, its chain of dependent loads had cost as much as the points themselves.
inline constexpr uint32_t kSobolLowBits = 11, kSobolLow = 1u << kSobolLowBits;
struct SobolDirections {
    std::vector<uint32_t> rv, rlow;
    int dims = 0;

    void set(const uint32_t *directions, int count) {
        rv.resize(size_t(count) * 32);
        for (size_t k = 0; k < rv.size(); ++k) rv[k] = reverse_bits(directions[k]);
        dims = count;
        rlow.assign(size_t(count) * kSobolLow, 0);
        for (int d = 0; d < count; ++d) {
            uint32_t *t = rlow.data() + size_t(d) * kSobolLow;
            for (uint32_t l = 1; l < kSobolLow; ++l) t[l] = t[l & (l - 1)] ^ rv[size_t(d) * 32 + __builtin_ctz(l)];
        }
    }
};
SobolDirections &sobol_directions();

// Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020: a hash that only lets
// lower bits affect higher ones (a Laine-Karras style permutation), applied to the reversed
// bits, is a nested uniform scramble of the original bits.  r: the point's bits reversed
// (SobolDirections); the scrambled point's bits are returned in their own order.
inline constexpr uint32_t kOwenHash[4] = {0x6c50b47cu, 0xb82f1e52u, 0xc7afe638u, 0x8d22f6e6u};
inline uint32_t owen_scramble_reversed(uint32_t r, uint32_t seed) {
    r += seed;
    for (uint32_t k : kOwenHash) r ^= r * k;
    return reverse_bits(r);
}

// (x + 1/2) 2^-32 for a 32-bit x, exactly (x + 1/2 has 33 significant bits): converted as the
// signed x - 2^31, which every ISA converts in one instruction (the unsigned conversion took
// a compare and a masked add a vector).
inline double centred_unit(uint32_t x) {
    return (double(int32_t(x ^ 0x80000000u)) + 2147483648.5) * 0x1p-32;
}

// One dimension's scrambled points of `count` samples of a run of one high index, at
// out[i * stride]: hi the run's reversed high bits, rlow[i] sample i's reversed low point,
// seed the dimension's scramble.
inline void sobol_run(const uint32_t *rlow, uint32_t hi, uint32_t seed, size_t count, double *out, size_t stride) {
    for (size_t i = 0; i < count; ++i) out[i * stride] = centred_unit(owen_scramble_reversed(hi ^ rlow[i], seed));
}

#if defined(__AVX512BW__) && defined(__GFNI__)
// sobol_run, 16 points a step where the CPU has GFNI: the final bit reversal as one affine
// transform of each byte and one byte shuffle (the shifts and masks took 13 vector operations
// a reversal), the points stored as whole vectors, interleaved for two dimensions (GCC's
// strided stores, a lane extracted and stored at a time, had cost as much as the points).
// The same bits.  u: the 16 points of rlow[0..16) in two vectors of 8.
inline void sobol_lanes(const uint32_t *rlow, uint32_t hi, uint32_t seed, __m512d (&u)[2]) {
    __m512i r = _mm512_xor_si512(_mm512_loadu_si512(rlow), _mm512_set1_epi32(int(hi)));
    r = _mm512_add_epi32(r, _mm512_set1_epi32(int(seed)));
    for (uint32_t k : kOwenHash) r = _mm512_xor_si512(r, _mm512_mullo_epi32(r, _mm512_set1_epi32(int(k))));
    r = _mm512_gf2p8affine_epi64_epi8(r, _mm512_set1_epi64(0x8040201008040201LL), 0);    // bits within bytes
    const __m512i bytes = _mm512_set4_epi32(0x0c0d0e0f, 0x08090a0b, 0x04050607, 0x00010203);
    r = _mm512_shuffle_epi8(r, bytes);                                                    // bytes within words
    // (the all-lanes mask forms: the unmasked intrinsics trip GCC 12's -Wmaybe-uninitialized)
    const __m512d half = _mm512_set1_pd(0.5), scale = _mm512_set1_pd(0x1p-32);
    const __m256i low = _mm512_maskz_extracti64x4_epi64(0xf, r, 0), high = _mm512_maskz_extracti64x4_epi64(0xf, r, 1);
    u[0] = _mm512_mul_pd(_mm512_add_pd(_mm512_maskz_cvtepu32_pd(0xff, low), half), scale);
    u[1] = _mm512_mul_pd(_mm512_add_pd(_mm512_maskz_cvtepu32_pd(0xff, high), half), scale);
}

// sobol_run for one dimension (stride 1) or two (rlow, hi, seed of each; out interleaved).
inline void sobol_run_lanes(int dims, const uint32_t *const rlow[2], const uint32_t hi[2], const uint32_t seed[2],
                            size_t count, double *out) {
    size_t i = 0;
    const __m512i first = _mm512_set_epi64(11, 3, 10, 2, 9, 1, 8, 0), second = _mm512_set_epi64(15, 7, 14, 6, 13, 5, 12, 4);
    for (; i + 16 <= count; i += 16) {
        __m512d a[2], b[2];
        sobol_lanes(rlow[0] + i, hi[0], seed[0], a);
        if (dims == 1) {
            _mm512_storeu_pd(out + i, a[0]);
            _mm512_storeu_pd(out + i + 8, a[1]);
            continue;
        }
        sobol_lanes(rlow[1] + i, hi[1], seed[1], b);
        for (int h = 0; h < 2; ++h) {
            _mm512_storeu_pd(out + 2 * (i + 8 * h), _mm512_permutex2var_pd(a[h], first, b[h]));
            _mm512_storeu_pd(out + 2 * (i + 8 * h) + 8, _mm512_permutex2var_pd(a[h], second, b[h]));
        }
    }
    for (int j = 0; j < dims; ++j) sobol_run(rlow[j] + i, hi[j], seed[j], count - i, out + size_t(dims) * i + j, size_t(dims));
}
#endif

// The reversed bits of the point of `index` in dimension dim (SobolDirections::rv).
inline uint32_t sobol_bits_reversed(uint64_t index, int dim, const SobolDirections &dirs) {
    const uint32_t *rv = dirs.rv.data() + size_t(dim) * 32;
    uint32_t r = 0;
    for (int k = 0; index && k < 32; ++k, index >>= 1)
        if (index & 1u) r ^= rv[k];
    return r;
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
            // x(i) = x(hi) ^ x(lo), lo the low kSobolLowBits bits (SobolDirections::rlow), in
            // runs of one high index, so that the loop over a run has no branch and vectorises
            // (a Sobol' estimate had spent two thirds of its time here)
            auto dimension_seed = [&](int j) {
                StreamKey dk = ctx.key;
                dk.chunk = 0x50b01ULL + uint64_t(j);
                return uint32_t(splitmix64(dk.seed ^ splitmix64(dk.case_id ^ splitmix64(dk.replica ^ splitmix64(dk.chunk)))));
            };
            for (size_t i0 = 0; i0 < m;) {
                const uint64_t hi_index = (first + i0) >> kSobolLowBits;
                const size_t i1 = std::min<uint64_t>(m, ((hi_index + 1) << kSobolLowBits) - first);
                const uint32_t lo0 = uint32_t((first + i0) & (kSobolLow - 1));
                auto run = [&](int j, const uint32_t *&rlow, uint32_t &hi, uint32_t &seed) {
                    rlow = dirs.rlow.data() + size_t(j) * kSobolLow + lo0;
                    hi = sobol_bits_reversed(hi_index << kSobolLowBits, j, dirs);
                    seed = dimension_seed(j);
                };
#if defined(__AVX512BW__) && defined(__GFNI__)
                if (ud <= 2) {
                    const uint32_t *rlow[2];
                    uint32_t hi[2], seed[2];
                    for (int j = 0; j < ud; ++j) run(j, rlow[j], hi[j], seed[j]);
                    sobol_run_lanes(ud, rlow, hi, seed, i1 - i0, u + i0 * size_t(ud));
                    i0 = i1;
                    continue;
                }
#endif
                for (int j = 0; j < ud; ++j) {
                    const uint32_t *rlow;
                    uint32_t hi, seed;
                    run(j, rlow, hi, seed);
                    sobol_run(rlow, hi, seed, i1 - i0, u + i0 * size_t(ud) + j, size_t(ud));
                }
                i0 = i1;
            }
            return;
        }
    }
}

}  // namespace re
