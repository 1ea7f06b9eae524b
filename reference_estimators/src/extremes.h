// The largest deviations on one side of a centre, for the tail estimates of harness.stats.tails
// (numpy's masks, max, count and partition over every block cost 17x the estimate itself).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <vector>

namespace re {

struct SideExtremes {
    double peak = std::nan("");  // the largest deviation (NaN: no positive deviation)
    uint64_t ties = 0;           // how many deviations equal it
    std::vector<double> below;   // the `keep` largest deviations strictly below it, descending
};

namespace detail {

// The positive deviations of y that are >= floor (floor > 0), compacted into out (room for n);
// returns their count and sets peak to their maximum (0 if none).  Branch-free.
inline size_t deviations_at_least(const double *y, size_t n, double center, bool upper, double floor, double *out,
                                  double &peak) {
    size_t k = 0;
    double top = 0;
    for (size_t i = 0; i < n; ++i) {
        double v = upper ? y[i] - center : center - y[i];
        out[k] = v;
        k += v >= floor;  // false for NaN
        top = v > top ? v : top;
    }
    peak = top;
    return k;
}

}  // namespace detail

// Over the positive deviations d = y - center (upper) or center - y (lower) of y[0..n), as
// numpy computes them (NaN values have none).  A subsample of every 16th deviation gives a
// floor that about 1.5 keep + 1000 deviations clear; only those are kept and selected from.
// Where too few clear it (a heavy atom, or unlucky), the selection is redone over every
// positive deviation, so the result is exact either way.
inline SideExtremes side_extremes(const double *y, size_t n, double center, bool upper, size_t keep) {
    constexpr size_t kStride = 16;
    std::unique_ptr<double[]> buf(new double[n > 0 ? n : 1]);
    const double positive = std::numeric_limits<double>::denorm_min();  // v >= it: v > 0
    double peak = 0, floor = positive;
    const size_t want = keep + keep / 2 + 1000;
    if (n / kStride > 4 * (want / kStride + 1)) {
        std::vector<double> sub;
        sub.reserve(n / kStride + 1);
        for (size_t i = 0; i < n; i += kStride) {
            double v = upper ? y[i] - center : center - y[i];
            if (v > 0) sub.push_back(v);
        }
        const size_t q = want / kStride + 1;
        if (sub.size() > q) {
            std::nth_element(sub.begin(), sub.begin() + (q - 1), sub.end(), std::greater<double>());
            floor = sub[q - 1];
        }
    }
    size_t m = detail::deviations_at_least(y, n, center, upper, floor, buf.get(), peak);
    SideExtremes s;
    if (!(peak > 0)) return s;
    auto below_peak = [&] {
        size_t kept = 0;
        s.ties = 0;
        for (size_t i = 0; i < m; ++i) {
            double v = buf[i];
            if (v == peak) ++s.ties;
            else buf[kept++] = v;
        }
        return kept;
    };
    size_t kept = below_peak();
    if (kept < keep && floor > positive) {  // too few cleared the floor: all of them
        floor = positive;
        m = detail::deviations_at_least(y, n, center, upper, floor, buf.get(), peak);
        kept = below_peak();
    }
    s.peak = peak;
    const size_t top = std::min(keep, kept);
    std::nth_element(buf.get(), buf.get() + top, buf.get() + kept, std::greater<double>());
    std::sort(buf.get(), buf.get() + top, std::greater<double>());
    s.below.assign(buf.get(), buf.get() + top);
    return s;
}

}  // namespace re
