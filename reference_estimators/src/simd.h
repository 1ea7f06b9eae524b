// Native-width double vectors, and the few operations vector kernels need that GCC's and
// Clang's vector extensions lack: fused multiply-add, floor, a 16-entry table lookup and
// scaling by 2^k.  Every operation has a scalar twin of the same name taking double, and the
// two give bitwise the same result lane by lane.  A kernel written once as a template over
// double and f64v (see map) therefore computes the same numbers in its vector body, in its
// scalar tail and on every ISA: AVX-512 (one instruction each), AVX2 + FMA, and plain x86-64.
#pragma once
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#if defined(__AVX__) || defined(__AVX512F__)
#include <immintrin.h>
#endif

#define RE_INLINE inline __attribute__((always_inline))

namespace re::simd {

// Wider-than-native vector types are lowered badly by GCC 12 (10x slower), so the width is
// the machine's: 8 doubles with AVX-512, 4 with AVX, 2 otherwise.
#if defined(__AVX512F__)
constexpr size_t kWidth = 8;
constexpr const char *kIsa = "AVX-512";
#elif defined(__AVX2__) && defined(__FMA__)
constexpr size_t kWidth = 4;
constexpr const char *kIsa = "AVX2+FMA";
#elif defined(__AVX__)
constexpr size_t kWidth = 4;
constexpr const char *kIsa = "AVX";
#else
constexpr size_t kWidth = 2;
constexpr const char *kIsa = "SSE2";
#endif

typedef double f64v __attribute__((vector_size(8 * kWidth)));
typedef int64_t i64v __attribute__((vector_size(8 * kWidth)));
typedef uint64_t u64v __attribute__((vector_size(8 * kWidth)));
typedef float f32v __attribute__((vector_size(4 * kWidth)));   // kWidth floats: f64v's lanes narrowed

RE_INLINE f64v load(const double *p) { f64v v; std::memcpy(&v, p, sizeof v); return v; }
RE_INLINE void store(double *p, f64v v) { std::memcpy(p, &v, sizeof v); }
RE_INLINE i64v load(const int64_t *p) { i64v v; std::memcpy(&v, p, sizeof v); return v; }
RE_INLINE void store(int64_t *p, i64v v) { std::memcpy(p, &v, sizeof v); }
// The pairs p[0..2 kWidth) split into their first and second members: two loads and two
// shuffles (GCC loads a lane at a time for a stride it cannot see).
RE_INLINE void deinterleave(const double *p, f64v &even, f64v &odd) {
    const f64v a = load(p), b = load(p + kWidth);
#if defined(__AVX512F__)
    even = __builtin_shufflevector(a, b, 0, 2, 4, 6, 8, 10, 12, 14);
    odd = __builtin_shufflevector(a, b, 1, 3, 5, 7, 9, 11, 13, 15);
#elif defined(__AVX__)
    even = __builtin_shufflevector(a, b, 0, 2, 4, 6);
    odd = __builtin_shufflevector(a, b, 1, 3, 5, 7);
#else
    even = __builtin_shufflevector(a, b, 0, 2);
    odd = __builtin_shufflevector(a, b, 1, 3);
#endif
}
// deinterleave's inverse: even and odd stored as the pairs p[0..2 kWidth).
RE_INLINE void interleave(double *p, f64v even, f64v odd) {
#if defined(__AVX512F__)
    store(p, __builtin_shufflevector(even, odd, 0, 8, 1, 9, 2, 10, 3, 11));
    store(p + kWidth, __builtin_shufflevector(even, odd, 4, 12, 5, 13, 6, 14, 7, 15));
#elif defined(__AVX__)
    store(p, __builtin_shufflevector(even, odd, 0, 4, 1, 5));
    store(p + kWidth, __builtin_shufflevector(even, odd, 2, 6, 3, 7));
#else
    store(p, __builtin_shufflevector(even, odd, 0, 2));
    store(p + kWidth, __builtin_shufflevector(even, odd, 1, 3));
#endif
}
// Columns F and F + 1 of the m rows of four at u into out (m x 2): whole vectors of rows by one
// shuffle of two loads, the rest a row at a time.  The uniforms of each sampler of an MIS pair
// that read two each (UniformStream::fill_pairs, the estimators' column copies).
template <int F>
RE_INLINE void pair_columns(const double *__restrict u, size_t m, double *__restrict out) {
    static_assert(F == 0 || F == 2, "a pair of columns of rows of four");
    size_t i = 0;
#if defined(__AVX__)
    constexpr size_t R = kWidth / 2;   // rows an output vector holds
    for (; i + R <= m; i += R) {
        const f64v a = load(u + 4 * i), b = load(u + 4 * i + kWidth);
#if defined(__AVX512F__)
        store(out + 2 * i, __builtin_shufflevector(a, b, F, F + 1, F + 4, F + 5, F + 8, F + 9, F + 12, F + 13));
#else
        store(out + 2 * i, __builtin_shufflevector(a, b, F, F + 1, F + 4, F + 5));
#endif
    }
#endif
    for (; i < m; ++i) std::memcpy(out + 2 * i, u + 4 * i + F, 2 * sizeof(double));
}
// p[0], p[stride], ..., p[(kWidth - 1) stride]: whole loads for strides 1 and 2 (deinterleave),
// a lane at a time otherwise.
RE_INLINE f64v load_strided(const double *p, size_t stride) {
    if (stride == 1) return load(p);
    f64v v, odd;
    if (stride == 2) deinterleave(p, v, odd);
    else
        for (size_t l = 0; l < kWidth; ++l) v[l] = p[l * stride];
    return v;
}

// The sum of the lanes of a vector of counts.
RE_INLINE size_t lane_total(i64v count) {
    size_t total = 0;
    for (size_t l = 0; l < kWidth; ++l) total += size_t(count[l]);
    return total;
}

RE_INLINE uint64_t bits(double d) { uint64_t b; std::memcpy(&b, &d, 8); return b; }
RE_INLINE u64v bits(f64v v) { return (u64v)v; }
RE_INLINE double from_bits(uint64_t b) { double d; std::memcpy(&d, &b, 8); return d; }
RE_INLINE f64v from_bits(u64v b) { return (f64v)b; }

// Applies a scalar function to each lane (the fallback where no instruction exists).
template <class Fn>
RE_INLINE f64v per_lane(f64v x, Fn fn) {
    for (size_t w = 0; w < kWidth; ++w) x[w] = fn(x[w]);
    return x;
}

// a * b + c with one rounding (std::fma is correctly rounded by definition).
RE_INLINE double fma(double a, double b, double c) { return std::fma(a, b, c); }
RE_INLINE f64v fma(f64v a, f64v b, f64v c) {
#if defined(__AVX512F__)
    return (f64v)_mm512_fmadd_pd((__m512d)a, (__m512d)b, (__m512d)c);
#elif defined(__AVX__) && defined(__FMA__)
    return (f64v)_mm256_fmadd_pd((__m256d)a, (__m256d)b, (__m256d)c);
#else
    for (size_t w = 0; w < kWidth; ++w) a[w] = std::fma(a[w], b[w], c[w]);
    return a;
#endif
}

// a > b ? a : b and a < b ? a : b, exactly (a NaN in either, or a tie, gives b): the
// definition of x86's maxpd / minpd, one instruction where compilers emit compare and blend.
RE_INLINE double max_or_second(double a, double b) { return a > b ? a : b; }
RE_INLINE double min_or_second(double a, double b) { return a < b ? a : b; }
RE_INLINE f64v max_or_second(f64v a, f64v b) {
#if defined(__AVX512F__)
    return (f64v)_mm512_mask_max_pd((__m512d)a, 0xff, (__m512d)a, (__m512d)b);  // mask form: see scale2k
#elif defined(__AVX__)
    return (f64v)_mm256_max_pd((__m256d)a, (__m256d)b);
#else
    return a > b ? a : b;
#endif
}
RE_INLINE f64v min_or_second(f64v a, f64v b) {
#if defined(__AVX512F__)
    return (f64v)_mm512_mask_min_pd((__m512d)a, 0xff, (__m512d)a, (__m512d)b);
#elif defined(__AVX__)
    return (f64v)_mm256_min_pd((__m256d)a, (__m256d)b);
#else
    return a < b ? a : b;
#endif
}

// Whether a == b in every lane (false where either holds a NaN): on AVX and AVX-512 one
// compare and a mask test.
RE_INLINE bool all_equal(f64v a, f64v b) {
#if defined(__AVX512F__)
    return _mm512_cmp_pd_mask((__m512d)a, (__m512d)b, _CMP_EQ_OQ) == 0xff;
#elif defined(__AVX__)
    return _mm256_movemask_pd(_mm256_cmp_pd((__m256d)a, (__m256d)b, _CMP_EQ_OQ)) == 0xf;
#else
    bool all = true;
    for (size_t w = 0; w < kWidth; ++w) all &= a[w] == b[w];
    return all;
#endif
}

// sqrt, correctly rounded (IEEE), so the lanes equal std::sqrt's.
RE_INLINE double sqrt(double x) { return std::sqrt(x); }
RE_INLINE f64v sqrt(f64v x) {
#if defined(__AVX512F__)
    // the all-lanes mask form: the unmasked intrinsic trips GCC 12's -Wmaybe-uninitialized
    return (f64v)_mm512_maskz_sqrt_pd(0xff, (__m512d)x);
#elif defined(__AVX__)
    return (f64v)_mm256_sqrt_pd((__m256d)x);
#else
    return per_lane(x, [](double v) { return std::sqrt(v); });
#endif
}

RE_INLINE double floor(double x) { return std::floor(x); }
RE_INLINE f64v floor(f64v x) {
#if defined(__AVX512F__)
    return (f64v)_mm512_mask_roundscale_pd((__m512d)x, 0xff, (__m512d)x, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
#elif defined(__AVX__)
    return (f64v)_mm256_floor_pd((__m256d)x);
#else
    return per_lane(x, [](double v) { return std::floor(v); });
#endif
}

// How many of the kWidth doubles at c are <= u (none where u is NaN): a compare and a
// population count of its mask.
RE_INLINE unsigned count_at_most(const double *c, double u) {
#if defined(__AVX512F__)
    return unsigned(__builtin_popcount(_mm512_cmp_pd_mask(_mm512_loadu_pd(c), _mm512_set1_pd(u), _CMP_LE_OQ)));
#elif defined(__AVX__)
    return unsigned(__builtin_popcount(_mm256_movemask_pd(_mm256_cmp_pd(_mm256_loadu_pd(c), _mm256_set1_pd(u), _CMP_LE_OQ))));
#else
    unsigned n = 0;
    for (size_t w = 0; w < kWidth; ++w) n += c[w] <= u;
    return n;
#endif
}

// count_at_most over the kVectors * kWidth doubles at c.  AVX2 without AVX-512, four vectors:
// their compare masks packed to one byte mask (two packs and a pack) and counted once, where a
// movemask and a population count for each vector lengthened the chain a point's count waits
// on; elsewhere count_at_most a vector.
template <size_t kVectors>
RE_INLINE unsigned count_at_most_vectors(const double *c, double u) {
#if defined(__AVX2__) && !defined(__AVX512F__)
    if constexpr (kVectors == 4) {
        const __m256d uv = _mm256_set1_pd(u);
        const auto le = [&](int v) { return _mm256_castpd_si256(_mm256_cmp_pd(_mm256_loadu_pd(c + 4 * v), uv, _CMP_LE_OQ)); };
        const __m256i packed = _mm256_packs_epi16(_mm256_packs_epi32(le(0), le(1)), _mm256_packs_epi32(le(2), le(3)));
        return unsigned(__builtin_popcount(unsigned(_mm256_movemask_epi8(packed)))) / 2;
    }
#endif
    unsigned n = 0;
    for (size_t v = 0; v < kVectors; ++v) n += count_at_most(c + v * kWidth, u);
    return n;
}

// table[bits(t) & 15]: the low four bits of t's representation pick the entry (table: 16
// doubles, 64-byte aligned).
RE_INLINE double lookup16(const double *table, double t) { return table[bits(t) & 15u]; }
RE_INLINE f64v lookup16(const double *table, f64v t) {
#if defined(__AVX512F__)
    // The table lives in two registers; vpermt2pd reads the low four bits of each index lane.
    return (f64v)_mm512_permutex2var_pd(_mm512_load_pd(table), (__m512i)t, _mm512_load_pd(table + 8));
#elif defined(__AVX2__)
    return (f64v)_mm256_i64gather_pd(table, (__m256i)(bits(t) & 15u), 8);
#else
    u64v j = bits(t) & 15u;
    f64v r;
    for (size_t w = 0; w < kWidth; ++w) r[w] = table[j[w]];
    return r;
#endif
}

// 2^k for integral k in [-1022, 1023], from the bits of k + 2^52 + 1023 (whose low bits are
// the biased exponent).
template <class D>
RE_INLINE D pow2_integral(D k) {
    return from_bits(bits(k + (0x1p52 + 1023.0)) << 52u);
}

// y * 2^floor(k), correctly rounded (one rounding: overflow gives inf, subnormal results are
// rounded once), for |y| in [0.5, 4) and floor(k) in [-1077, 1024]; NaN stays NaN.  Without
// AVX-512's vscalefpd, in two exact-or-once-rounded steps 2^k1 2^k2 with k1 = floor(k/2): y 2^k1
// is a normal number, so only the second product rounds.
template <class D>
RE_INLINE D scale2k_steps(D y, D k) {
    D kf = floor(k), k1 = floor(kf * 0.5), k2 = kf - k1;
    return y * pow2_integral(k1) * pow2_integral(k2);
}
RE_INLINE double scale2k(double y, double k) { return scale2k_steps(y, k); }
RE_INLINE f64v scale2k(f64v y, f64v k) {
#if defined(__AVX512F__)
    // the all-lanes mask form: the unmasked intrinsic reads an "undefined" register, which GCC
    // 12 warns about under -Wall
    return (f64v)_mm512_mask_scalef_pd((__m512d)y, 0xff, (__m512d)y, (__m512d)k);
#elif defined(__AVX__)
    // Where every 2^floor(k) is a normal double, y 2^floor(k) is one correctly rounded product
    // (IEEE multiplication rounds once, into the subnormals too): the same bits as the two
    // steps for a third of the work (exp on the unit interval: 1.77 -> 1.66 ns a value).
    f64v kf = floor(k);
    auto normal = (kf >= -1022.0) & (kf <= 1023.0);
    if (__builtin_expect(_mm256_movemask_pd((__m256d)normal) == 0xf, 1)) return y * pow2_integral(kf);
    return scale2k_steps(y, k);
#else
    return scale2k_steps(y, k);
#endif
}

// y[i] = fn(x[i]) for i < n: fn is a generic lambda, called on whole vectors (f64v) and on
// the scalar tail (double); written with the operations above it gives the same bits in both.
template <class Fn>
RE_INLINE void map(const double *x, double *y, size_t n, Fn fn) {
    size_t i = 0;
    for (; i + kWidth <= n; i += kWidth) store(y + i, fn(load(x + i)));
    for (; i < n; ++i) y[i] = fn(x[i]);
}

// kWidth consecutive 3-vectors at x (coordinates interleaved, as directions are stored)
// gathered into one vector per coordinate, and scattered back: stride-3 loops do not vectorise.
// AVX-512: three whole-vector loads (stores) and a transposition in registers, two vpermt2pd
// per coordinate.  GCC 12 compiles the 8-lane loops into an insert or extract per element, half
// of importance sampling's time on directions (ggx_lobe: 107 -> 205 Msamples/s a thread); its
// 4-lane AVX2 code for the loops is as fast as the same transposition by hand (measured), so
// the loops stay there and below.
RE_INLINE void load3(const double *x, f64v &a, f64v &b, f64v &c) {
#if defined(__AVX512F__)
    // v0 = a0 b0 c0 a1 b1 c1 a2 b2, v1 = c2 a3 b3 c3 a4 b4 c4 a5, v2 = b5 c5 a6 b6 c6 a7 b7 c7
    const __m512d v0 = _mm512_loadu_pd(x), v1 = _mm512_loadu_pd(x + 8), v2 = _mm512_loadu_pd(x + 16);
    const auto pick = [&](__m512i first, __m512i second) {
        return (f64v)_mm512_permutex2var_pd(_mm512_permutex2var_pd(v0, first, v1), second, v2);
    };
    a = pick(_mm512_setr_epi64(0, 3, 6, 9, 12, 15, 0, 0), _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 10, 13));
    b = pick(_mm512_setr_epi64(1, 4, 7, 10, 13, 0, 0, 0), _mm512_setr_epi64(0, 1, 2, 3, 4, 8, 11, 14));
    c = pick(_mm512_setr_epi64(2, 5, 8, 11, 14, 0, 0, 0), _mm512_setr_epi64(0, 1, 2, 3, 4, 9, 12, 15));
#else
    for (size_t l = 0; l < kWidth; ++l) { a[l] = x[3 * l]; b[l] = x[3 * l + 1]; c[l] = x[3 * l + 2]; }
#endif
}
RE_INLINE void store3(double *x, f64v a, f64v b, f64v c) {
#if defined(__AVX512F__)
    // each of load3's v0, v1, v2: a's and b's entries interleaved, then c's put in its lanes
    const __m512d va = (__m512d)a, vb = (__m512d)b, vc = (__m512d)c;
    const auto put = [&](__m512i first, __m512i second) {
        return _mm512_permutex2var_pd(_mm512_permutex2var_pd(va, first, vb), second, vc);
    };
    _mm512_storeu_pd(x, put(_mm512_setr_epi64(0, 8, 0, 1, 9, 0, 2, 10), _mm512_setr_epi64(0, 1, 8, 3, 4, 9, 6, 7)));
    _mm512_storeu_pd(x + 8, put(_mm512_setr_epi64(0, 3, 11, 0, 4, 12, 0, 5),
                                _mm512_setr_epi64(10, 1, 2, 11, 4, 5, 12, 7)));
    _mm512_storeu_pd(x + 16, put(_mm512_setr_epi64(13, 0, 6, 14, 0, 7, 15, 0),
                                 _mm512_setr_epi64(0, 13, 2, 3, 14, 5, 6, 15)));
#else
    for (size_t l = 0; l < kWidth; ++l) { x[3 * l] = a[l]; x[3 * l + 1] = b[l]; x[3 * l + 2] = c[l]; }
#endif
}

// y[i] = fn(x[2 i], x[2 i + 1]) for i < n (n 2-vectors in, one value each out), as map; the
// element loop compiles to two permutes a vector.
template <class Fn>
RE_INLINE void map2(const double *x, double *y, size_t n, Fn fn) {
    size_t i = 0;
    for (; i + kWidth <= n; i += kWidth) {
        f64v a, b;
        for (size_t l = 0; l < kWidth; ++l) { a[l] = x[2 * (i + l)]; b[l] = x[2 * (i + l) + 1]; }
        store(y + i, fn(a, b));
    }
    for (; i < n; ++i) y[i] = fn(x[2 * i], x[2 * i + 1]);
}

// y[i] = fn(x[3 i], x[3 i + 1], x[3 i + 2]) for i < n (n 3-vectors in, one value each out), as map.
template <class Fn>
RE_INLINE void map3(const double *x, double *y, size_t n, Fn fn) {
    size_t i = 0;
    for (; i + kWidth <= n; i += kWidth) {
        f64v a, b, c;
        load3(x + 3 * i, a, b, c);
        store(y + i, fn(a, b, c));
    }
    for (; i < n; ++i) y[i] = fn(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
}

// fn(x[3 i], x[3 i + 1], x[3 i + 2], y[3 i], y[3 i + 1], y[3 i + 2]) for i < n (n 3-vectors in,
// n out, the outputs by reference), as map: whole vectors through load3 and store3.
template <class Fn>
RE_INLINE void map3x3(const double *x, double *y, size_t n, Fn fn) {
    size_t i = 0;
    for (; i + kWidth <= n; i += kWidth) {
        f64v a, b, c, p, q, r;
        load3(x + 3 * i, a, b, c);
        fn(a, b, c, p, q, r);
        store3(y + 3 * i, p, q, r);
    }
    for (; i < n; ++i) fn(x[3 * i], x[3 * i + 1], x[3 * i + 2], y[3 * i], y[3 * i + 1], y[3 * i + 2]);
}

// y[i] = fn(a[i], b[i], y[i]) for i < n, as map.
template <class Fn>
RE_INLINE void update(const double *a, const double *b, double *y, size_t n, Fn fn) {
    size_t i = 0;
    for (; i + kWidth <= n; i += kWidth) store(y + i, fn(load(a + i), load(b + i), load(y + i)));
    for (; i < n; ++i) y[i] = fn(a[i], b[i], y[i]);
}

// y[i] = fn(a[i], b[i], c[i], y[i]) for i < n, as map.
template <class Fn>
RE_INLINE void map4(const double *a, const double *b, const double *c, double *y, size_t n, Fn fn) {
    size_t i = 0;
    for (; i + kWidth <= n; i += kWidth) store(y + i, fn(load(a + i), load(b + i), load(c + i), load(y + i)));
    for (; i < n; ++i) y[i] = fn(a[i], b[i], c[i], y[i]);
}

}  // namespace re::simd
