// PCG32 (O'Neill 2014, XSH-RR 64/32) with one stream per chunk, and a lane-parallel
// generator that reproduces that single stream eight values at a time.
//
// Canonical uniforms are doubles in the open interval (0, 1): sample k of a chunk is
// built from the stream's 32-bit outputs 2k and 2k+1, keeps 52 bits and is centred in
// its cell, u = (m + 0.5) * 2^-52.  Open, so -log(u), 1/sqrt(u) and friends never see 0
// or 1; centred, so E[u] = 1/2 exactly.
#pragma once
#include <cstdint>
#include <cstring>

#include "simd.h"

#if defined(__AVX2__) || defined(__AVX512F__)
#include <immintrin.h>
#endif

namespace re {

constexpr uint64_t kPcgMult = 0x5851f42d4c957f2dULL;

inline uint64_t splitmix64(uint64_t x) {
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

inline uint32_t pcg32_output(uint64_t old) {
    uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = uint32_t(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31u));
}

// Affine map of the LCG after `delta` steps: state -> mult * state + plus.
struct LcgJump {
    uint64_t mult = 1, plus = 0;
};

inline LcgJump lcg_jump(uint64_t delta, uint64_t inc) {
    // Brown, "Random number generation with arbitrary strides" (1994): square-and-multiply.
    LcgJump acc, cur{kPcgMult, inc};
    while (delta) {
        if (delta & 1u) {
            acc.mult *= cur.mult;
            acc.plus = acc.plus * cur.mult + cur.plus;
        }
        cur.plus = (cur.mult + 1u) * cur.plus;
        cur.mult *= cur.mult;
        delta >>= 1u;
    }
    return acc;
}

// Where a chunk's stream comes from: every estimate is keyed by these four numbers.
struct StreamKey {
    uint64_t seed = 0, case_id = 0, replica = 0, chunk = 0;
};

// The scalar reference generator: the definition of a chunk's stream.
struct Pcg32 {
    uint64_t state = 0, inc = 1;

    explicit Pcg32(const StreamKey &k) {
        uint64_t h = splitmix64(k.seed ^ splitmix64(k.case_id ^ splitmix64(k.replica ^ splitmix64(k.chunk))));
        uint64_t initstate = splitmix64(h), initseq = splitmix64(h ^ 0xda3e39cb94b95bdbULL);
        inc = (initseq << 1u) | 1u;
        state = 0;
        next_u32();
        state += initstate;
        next_u32();
    }
    uint32_t next_u32() {
        uint64_t old = state;
        state = old * kPcgMult + inc;
        return pcg32_output(old);
    }
    void advance(uint64_t delta) {
        LcgJump j = lcg_jump(delta, inc);
        state = j.mult * state + j.plus;
    }
};

// Lanes over ONE PCG32 stream: lane l produces uniforms l, l+L, l+2L, ... so a fill yields
// exactly the sequence of the scalar generator, while the lanes run in SIMD registers.
// Uniform k uses outputs 2k (high word) and 2k+1 (low word).  L = 32 (four vectors of 8
// with AVX-512): independent vectors hide the latency of each lane's two dependent 64-bit
// multiplies per uniform.
class LaneGenerator {
  public:
    // Native vector width (see accumulator.h: wider types are lowered badly), 32 lanes.
#if defined(__AVX512F__)
    static constexpr int kVec = 8;
#elif defined(__AVX__)
    static constexpr int kVec = 4;
#else
    static constexpr int kVec = 2;
#endif
    static constexpr int kLanes = 32, kVecs = kLanes / kVec;

    explicit LaneGenerator(const StreamKey &key) {
        Pcg32 g(key);
        jump_ = lcg_jump(2 * kLanes - 1, g.inc);
        inc_ = g.inc;
        for (int l = 0; l < kLanes; ++l) {
            state_[l] = g.state;
            g.advance(2);
        }
    }

    // Fills out[0..rows*L) with the next rows*L uniforms of the stream.
    void fill(double *out, size_t rows) { fill_lanes<false>(out, rows); }
    // Fills out[0..rows*L/2) with the even-numbered ones of the next rows*L uniforms (the
    // stream moves on by rows*L): the u0 of every sample that reads u0 of (u0, u1) alone (the
    // estimators' polar path), at half the cost.  The even lanes alone make them; the odd
    // lanes' states jump over the rows at once.
    void fill_even(double *out, size_t rows) {
        fill_lanes<true>(out, rows);
        skip_odd(rows);
    }
    // The lanes' states held in vector registers while rows of uniforms are drawn one at a
    // time (all lanes, or with `even` the even ones alone: fill_even's values), written back
    // when it goes out of scope.  fill and fill_even draw through it; a loop that uses each
    // row as it comes (a sampler, whose divisions then overlap the generator's
    // multiplications) draws next() rows times and, for the evens, skip_odd(rows) after: the
    // same values and the same stream position as fill_even.  Written with GCC/Clang vector
    // extensions: compilers do not vectorise PCG's output on their own.  The 32-bit rotate
    // runs on the 64-bit lanes viewed as pairs of 32-bit words (the low word of each lane is
    // PCG's output, the high word is ignored), and one shuffle pairs the two outputs of a
    // uniform into a 64-bit lane: no packing to 32-bit lanes and back.
    template <bool even>
    class Rows {
      public:
        static constexpr int kVecsDrawn = even ? kVecs / 2 : kVecs, kStride = even ? 2 : 1;
        static constexpr int kPerRow = kLanes / kStride;   // values next() writes

        explicit Rows(LaneGenerator &g) : g_(g) {
            uint64_t lanes[kVecsDrawn * kVec];
            for (int l = 0; l < kVecsDrawn * kVec; ++l) lanes[l] = g.state_[l * kStride];
            std::memcpy(s_, lanes, sizeof s_);
        }
        ~Rows() {
            uint64_t lanes[kVecsDrawn * kVec];
            std::memcpy(lanes, s_, sizeof s_);
            for (int l = 0; l < kVecsDrawn * kVec; ++l) g_.state_[l * kStride] = lanes[l];
        }
        Rows(const Rows &) = delete;
        Rows &operator=(const Rows &) = delete;

        // The next row: out[0 .. kPerRow).
        __attribute__((always_inline)) void next(double *out) {
            const u64v zero = {}, mult = zero + kPcgMult, inc = zero + g_.inc_;
            const u64v jm = zero + g_.jump_.mult, jp = zero + g_.jump_.plus;
            const u64v exponent = zero + 0x4330000000000000ULL;
            // (the AVX2 path below needs neither of these two)
            [[maybe_unused]] const f64v offset = f64v{} + 4503599627370495.5;  // 2^52 - 0.5
            [[maybe_unused]] auto output = [](u64v old) __attribute__((always_inline)) {  // PCG32 XSH-RR, low word of each lane
                u32v x = (u32v)(((old >> 18u) ^ old) >> 27u), rot = (u32v)(old >> 59u);
#if defined(__AVX512F__)
                // all-lanes mask form: the unmasked intrinsic trips GCC 12's -Wmaybe-uninitialized
                return (u32v)_mm512_mask_rorv_epi32((__m512i)x, 0xffff, (__m512i)x, (__m512i)rot);
#else
                return (x >> rot) | (x << ((-rot) & 31u));
#endif
            };
            for (int v = 0; v < kVecsDrawn; ++v) {
                u64v s1 = s_[v] * mult + inc;
                // Lane i = (output(s) << 32) | output(s1): low word from s1, high from s.
#if defined(__AVX512F__)
                u32v hi = output(s_[v]), lo = output(s1);
                u64v pair = (u64v)__builtin_shufflevector(lo, hi, 0, 16, 2, 18, 4, 20, 6, 22, 8, 24, 10, 26, 12, 28, 14, 30);
#elif defined(__AVX2__)
                // AVX2 has no 32-bit rotate.  With x copied into both words of a lane (one
                // shuffle), rotr32(x, r) is the low word of (x:x) >> r and the high word of
                // (x:x) << (32 - r): one 64-bit variable shift per output, each already in the
                // word of the pair it belongs to, and one blend joins them (14 operations
                // where the rotate by shifts took 21: PCG32 points 1.20 -> 1.0 ns a uniform).
                auto doubled = [](u64v old) __attribute__((always_inline)) {
                    return (__m256i)_mm256_shuffle_epi32((__m256i)(((old >> 18u) ^ old) >> 27u), 0xa0);
                };
                __m256i lo = _mm256_srlv_epi64(doubled(s1), (__m256i)(s1 >> 59u));
                __m256i hi = _mm256_sllv_epi64(doubled(s_[v]), (__m256i)(32u - (s_[v] >> 59u)));
                u64v pair = (u64v)_mm256_blend_epi32(lo, hi, 0xaa);
#else
                u32v hi = output(s_[v]), lo = output(s1);
                u64v pair = ((u64v)hi << 32u) | (((u64v)lo << 32u) >> 32u);
#endif
                s_[v] = s1 * jm + jp;
                u64v bits = exponent | (pair >> 12u);
                f64v d;
                std::memcpy(&d, &bits, sizeof d);
                // (2^52 + m) - (2^52 - 0.5) = m + 0.5 exactly, times 2^-52: u in (0, 1).  With
                // FMA in one instruction, d 2^-52 - (1 - 2^-53): the exact result is the same
                // representable (2 m + 1) 2^-53, so both forms give the same bits.
#if defined(__AVX2__) && defined(__FMA__) && !defined(__AVX512F__)
                d = (f64v)_mm256_fmadd_pd((__m256d)d, _mm256_set1_pd(0x1p-52), _mm256_set1_pd(-(1.0 - 0x1p-53)));
#else
                d = (d - offset) * 0x1p-52;
#endif
                std::memcpy(out + v * kVec, &d, sizeof d);
            }
        }

      private:
        typedef uint64_t u64v __attribute__((vector_size(8 * kVec)));
        typedef uint32_t u32v __attribute__((vector_size(8 * kVec)));
        typedef double f64v __attribute__((vector_size(8 * kVec)));
        LaneGenerator &g_;
        u64v s_[kVecsDrawn];
    };
    static constexpr int kEvensPerRow = Rows<true>::kPerRow;

    // fill's next rows * L uniforms as samples of four (a0 a1 b0 b1: an MIS pair of samplers
    // that read two each), sample i's a0 a1 to a[2 i ..] and b0 b1 to b[2 i ..]: each row split where it
    // was drawn, in L1 (a block's worth of samples written whole and copied column by column
    // after had cost 0.8 ns a sample of such an estimate's 11.9).
    void fill_pairs(double *a, double *b, size_t rows) {
        static_assert(kLanes % 4 == 0, "a row holds whole samples of four");
        constexpr int kSamples = kLanes / 4;
        Rows<false> draw(*this);
        alignas(64) double row[kLanes];
        for (size_t r = 0; r < rows; ++r) {
            draw.next(row);
            simd::pair_columns<0>(row, kSamples, a + 2 * kSamples * r);
            simd::pair_columns<2>(row, kSamples, b + 2 * kSamples * r);
        }
    }

    // The odd lanes' states moved on by `rows` rows at once (fill_even's second half).
    void skip_odd(size_t rows) {
        const LcgJump j = lcg_jump(2 * kLanes * uint64_t(rows), inc_);
        for (int l = 1; l < kLanes; l += 2) state_[l] = j.mult * state_[l] + j.plus;
    }

  private:
    // fill, or with `even` the even lanes' part of it (their states advanced, the odd ones'
    // left), row by row through Rows.
    template <bool even>
    void fill_lanes(double *out, size_t rows) {
        Rows<even> draw(*this);
        for (size_t r = 0; r < rows; ++r) draw.next(out + r * Rows<even>::kPerRow);
    }

    uint64_t state_[kLanes];
    uint64_t inc_;
    LcgJump jump_;
};

// Scalar consumer of a LaneGenerator, for code that needs one uniform at a time (rejection).
class UniformStream {
  public:
    explicit UniformStream(const StreamKey &key) : gen_(key) {}
    double next() {
        if (pos_ == kBuf) {
            gen_.fill(buf_, kBuf / LaneGenerator::kLanes);
            pos_ = 0;
        }
        return buf_[pos_++];
    }
    // Next `count` uniforms (count a multiple of 8 and the stream row-aligned: fast path).
    void fill(double *out, size_t count) {
        size_t i = 0;
        while (i < count && pos_ != kBuf) out[i++] = buf_[pos_++];
        size_t rows = (count - i) / LaneGenerator::kLanes;
        gen_.fill(out + i, rows);
        i += rows * LaneGenerator::kLanes;
        while (i < count) out[i++] = next();
    }
    // Whether the stream stands at the start of a generator row (its buffer used up): where
    // fill_even and rewind apply.
    bool row_aligned() const { return pos_ == kBuf; }
    // The even-numbered ones of the next `count` uniforms (count even) into out[0..count/2),
    // the same bits as fill's (the lanes' shortcut where the stream is row-aligned).
    void fill_even(double *out, size_t count) {
        size_t i = 0;
        if (row_aligned()) {
            const size_t rows = count / LaneGenerator::kLanes;
            gen_.fill_even(out, rows);
            i = rows * LaneGenerator::kLanes;
        }
        for (; i < count; i += 2) {
            out[i / 2] = next();
            next();
        }
    }
    // The next 4 x `samples` uniforms as fill gives them, split into two samplers' pairs (sample
    // i's first two to a[2 i ..], its last two to b[2 i ..]): by whole generator rows
    // (LaneGenerator::fill_pairs) where the stream is row-aligned (an estimate's blocks are),
    // one value at a time after them and elsewhere.
    void fill_pairs(double *a, double *b, size_t samples) {
        size_t i = 0;
        if (row_aligned()) {
            constexpr size_t kPerRow = LaneGenerator::kLanes / 4;
            const size_t rows = samples / kPerRow;
            gen_.fill_pairs(a, b, rows);
            i = rows * kPerRow;
        }
        for (; i < samples; ++i) {
            a[2 * i] = next();
            a[2 * i + 1] = next();
            b[2 * i] = next();
            b[2 * i + 1] = next();
        }
    }
    // The generator itself, for a caller drawing whole rows from it where the stream is
    // row-aligned (LaneGenerator::even_row); the stream stays row-aligned.
    LaneGenerator &rows() { return gen_; }
    // Where the stream stands (row-aligned), and back there: the same uniforms again.
    LaneGenerator position() const { return gen_; }
    void rewind(const LaneGenerator &at) {
        gen_ = at;
        pos_ = kBuf;
    }

  private:
    static constexpr size_t kBuf = 256;
    LaneGenerator gen_;
    double buf_[kBuf];
    size_t pos_ = kBuf;
};

}  // namespace re
