// Row selection for the sampler check's arrays (bind_checks.cpp's take_rows and nan_rows): rows
// of k doubles, one keep flag (a byte, any non-zero value true) a row.  Both are branch-free:
// the flags of a sampler's rows follow its lobes and failures, not a pattern a branch predictor
// learns (a mask plugin passing 70 % of its samples through a Dirac lobe: inside its check,
// nan_rows took 7 ms and take_rows 3.4 ms for a million 3-vectors with branches, 1-4 and
// 0.8-1.3 ms without).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

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

}  // namespace re
