// Piecewise-linear tables looked up in batch: the sampler check's Rosenblatt transform
// (harness/samplers/transform.py) maps a million points through CDFs tabulated on a few
// thousand leaves of very different widths, in strips.  numpy's searchsorted over unsorted
// queries cost about 0.26-0.5 us a point there (a long, mispredicted binary search, one numpy
// call per strip); a bucket index narrows each search to a few leaves.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace re {

// For each point j: the leaf i of strip strip[j] (leaves offsets[g] .. offsets[g+1]-1, sorted
// by lo, inside [0, 1]) with the largest lo[i] <= x[j] (the strip's first leaf when none is),
// and out[j] = start[i] + mass[i] * clamp((x[j] - lo[i]) / (hi[i] - lo[i]), 0, 1), clamped to
// [0, 1].  Strips outside [0, strips) and empty strips give NaN.  A bucket index of 256
// buckets per strip narrows each binary search to the leaves that start in the point's bucket
// (or the one before), so the search stays short and cache-resident where leaves are many.
inline void piecewise_linear_lookup(const double *lo, const double *hi, const double *start, const double *mass,
                                    const int64_t *offsets, int64_t strips, const int64_t *strip, const double *x,
                                    size_t n, double *out) {
    constexpr int64_t B = 256;
    // first[g * (B + 1) + b]: the first leaf of strip g whose lo >= b / B (offsets[g + 1] if none)
    std::vector<int64_t> first(size_t(strips) * (B + 1));
    for (int64_t g = 0; g < strips; ++g) {
        int64_t i = offsets[g];
        for (int64_t b = 0; b <= B; ++b) {
            while (i < offsets[g + 1] && lo[i] < double(b) / B) ++i;
            first[size_t(g * (B + 1) + b)] = i;
        }
    }
    for (size_t j = 0; j < n; ++j) {
        const int64_t g = strip[j];
        if (g < 0 || g >= strips || offsets[g + 1] <= offsets[g] || !(x[j] == x[j])) {
            out[j] = __builtin_nan("");
            continue;
        }
        const double xj = x[j];
        int64_t b = int64_t(xj * B);
        b = b < 0 ? 0 : (b >= B ? B - 1 : b);
        // the answer lies in [first[b] - 1, first[b + 1] - 1]: leaves starting before b / B end
        // with the last one, and none starting at or after (b + 1) / B can hold x
        const int64_t *row = &first[size_t(g * (B + 1))];
        const int64_t begin = std::max(row[b] - 1, offsets[g]), end = std::max(row[b + 1], begin + 1);
        const double *it = std::upper_bound(lo + begin, lo + end, xj);
        const size_t i = size_t((it == lo + begin ? it : it - 1) - lo);
        const double width = hi[i] - lo[i];
        double t = width > 0 ? (xj - lo[i]) / width : 0.0;
        t = t < 0 ? 0 : (t > 1 ? 1 : t);
        const double u = start[i] + mass[i] * t;
        out[j] = u < 0 ? 0 : (u > 1 ? 1 : u);
    }
}

}  // namespace re
