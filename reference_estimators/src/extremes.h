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

#include "simd.h"

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

// The extremes of the union of several sets of values from each set's SideExtremes (each
// with `keep` or more below its peak, or all it had): the highest peak, the ties of every part
// at it, and the `keep` largest of the rest, the lower peaks' atoms included (min(ties, keep)
// copies each).  One selection over all parts; the result does not depend on their order.
inline SideExtremes merge_sides(const std::vector<const SideExtremes *> &parts, size_t keep) {
    SideExtremes s;
    size_t total = 0;
    for (const SideExtremes *p : parts) {
        if (std::isnan(p->peak)) continue;
        if (std::isnan(s.peak) || p->peak > s.peak) s.peak = p->peak;
        total += p->below.size() + size_t(std::min<uint64_t>(p->ties, keep));
    }
    if (std::isnan(s.peak)) return s;
    std::vector<double> pool;
    pool.reserve(total);
    for (const SideExtremes *p : parts) {
        if (std::isnan(p->peak)) continue;
        if (p->peak == s.peak) s.ties += p->ties;
        else pool.insert(pool.end(), size_t(std::min<uint64_t>(p->ties, keep)), p->peak);
        pool.insert(pool.end(), p->below.begin(), p->below.end());
    }
    const size_t top = std::min(keep, pool.size());
    std::nth_element(pool.begin(), pool.begin() + top, pool.end(), std::greater<double>());
    std::sort(pool.begin(), pool.begin() + top, std::greater<double>());
    pool.resize(top);
    s.below = std::move(pool);
    return s;
}

// The extremes of one side of values fed in order (v, or -v for the lower side): the exact
// SideExtremes of everything fed, kept in O(keep) memory.  Values not above threshold() cannot
// change the result, so a caller may skip them; the rest go to push().  Candidates collect in
// a buffer that is cut back to the `keep` largest below the peak whenever it holds 2 keep + 64,
// which raises the threshold: about keep (1 + ln(n / keep)) of n i.i.d. values are ever pushed.
class SideCollector {
  public:
    explicit SideCollector(size_t keep) : keep_(keep) { buf_.reserve(2 * keep + 64); }

    double threshold() const { return t_; }

    // The value whose ties are being counted (NaN before any): values equal to it may be
    // counted with add_ties instead of pushed one by one.
    double atom() const { return ties_ > 0 ? peak_ : std::nan(""); }
    void add_ties(uint64_t k) { ties_ += k; }

    void push(double v) {  // v > threshold(), finite
        if (v == peak_) {
            ++ties_;
            return;
        }
        buf_.push_back(v);
        if (buf_.size() >= 2 * keep_ + 64) cut();
    }

    SideExtremes finish() {
        cut();
        SideExtremes s;
        if (ties_ == 0) return s;
        std::sort(below_.begin(), below_.end(), std::greater<double>());
        s.peak = peak_;
        s.ties = ties_;
        s.below = std::move(below_);
        return s;
    }

  private:
    void cut() {
        if (buf_.empty()) return;
        const double top = *std::max_element(buf_.begin(), buf_.end());
        if (top > peak_) {  // a new peak: the old one's atom joins the values below it
            if (ties_ > 0) below_.insert(below_.end(), size_t(std::min<uint64_t>(ties_, keep_)), peak_);
            peak_ = top;
            ties_ = 0;
        }
        for (double v : buf_) {
            if (v == peak_) ++ties_;
            else below_.push_back(v);
        }
        buf_.clear();
        if (below_.size() >= keep_ && keep_ > 0) {
            std::nth_element(below_.begin(), below_.begin() + (keep_ - 1), below_.end(), std::greater<double>());
            below_.resize(keep_);
            t_ = below_[keep_ - 1];
        } else if (keep_ == 0) {
            below_.clear();
            t_ = peak_;
        }
        if (t_ == peak_) t_ = std::nextafter(peak_, -HUGE_VAL);  // ties of the peak still count
    }

    size_t keep_;
    double peak_ = -HUGE_VAL, t_ = -HUGE_VAL;
    uint64_t ties_ = 0;
    std::vector<double> below_, buf_;
};

// The tails of a set of values for the bias test's tail sample: the largest values (upper) and
// the largest of -y (lower), each side's peak, ties and `keep` below it; NaN and infinite
// values ignored.
struct ValueTails {
    SideExtremes upper, lower;
    double median = std::nan("");  // the upper median of the finite values, when asked for
};

// Both sides' collectors over values fed block by block.
class TailCollector {
  public:
    explicit TailCollector(size_t keep) : up_(keep), down_(keep) {}

    // The finite values of y[0..m) not marked in `drop` (may be null).  Groups of 4 vectors
    // are screened first (simd.h: the same on every ISA): per side, the extreme of the values
    // other than the side's atom, and how many equal the atom.  A group whose other values are
    // all at or below the side's threshold only adds its atom's ties; the rest are read value
    // by value.  So a side costs a compare per value, and an atom (roulette's zeros, a clamp)
    // is counted without pushing each of its values.
    void feed(const double *y, size_t m, const unsigned char *drop) {
        using simd::f64v;
        using simd::i64v;
        using simd::kWidth;
        constexpr size_t kGroup = 4 * kWidth;
        size_t i = 0;
        if (!drop) {
            for (; i + kGroup <= m; i += kGroup) {
                const double au = up_.atom(), al = -down_.atom();  // the lower atom as a value of y
                f64v hi = f64v{} - HUGE_VAL, lo = f64v{} + HUGE_VAL, inf = f64v{} + HUGE_VAL;
                i64v nu = i64v{}, nl = i64v{};
                for (size_t j = 0; j < kGroup; j += kWidth) {
                    const f64v v = simd::load(y + i + j);
                    const i64v eu = v == au, el = v == al;
                    nu -= eu;
                    nl -= el;
                    hi = simd::max_or_second(eu ? -inf : v, hi);  // NaN ignored
                    lo = simd::min_or_second(el ? inf : v, lo);
                }
                double h = -HUGE_VAL, l = HUGE_VAL;
                int64_t cu = 0, cl = 0;
                for (size_t w = 0; w < kWidth; ++w) {
                    h = hi[w] > h ? hi[w] : h;
                    l = lo[w] < l ? lo[w] : l;
                    cu += nu[w];
                    cl += nl[w];
                }
                if (h > up_.threshold()) upper(y, i, i + kGroup, nullptr);
                else up_.add_ties(uint64_t(cu));
                if (-l > down_.threshold()) lower(y, i, i + kGroup, nullptr);
                else down_.add_ties(uint64_t(cl));
            }
        }
        upper(y, i, m, drop);
        lower(y, i, m, drop);
    }

    ValueTails finish() { return {up_.finish(), down_.finish(), std::nan("")}; }

  private:
    void upper(const double *y, size_t a, size_t b, const unsigned char *drop) {
        for (size_t j = a; j < b; ++j)
            if (!(drop && drop[j]) && std::isfinite(y[j]) && y[j] > up_.threshold()) up_.push(y[j]);
    }
    void lower(const double *y, size_t a, size_t b, const unsigned char *drop) {
        for (size_t j = a; j < b; ++j)
            if (!(drop && drop[j]) && std::isfinite(y[j]) && -y[j] > down_.threshold()) down_.push(-y[j]);
    }

    SideCollector up_, down_;
};

inline double upper_median(const double *y, size_t n) {
    std::vector<double> v;
    v.reserve(n);
    for (size_t i = 0; i < n; ++i)
        if (std::isfinite(y[i])) v.push_back(y[i]);
    if (v.empty()) return std::nan("");
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
}

inline ValueTails value_tails(const double *y, size_t n, size_t keep, bool median) {
    TailCollector c(keep);
    c.feed(y, n, nullptr);
    ValueTails t = c.finish();
    if (median) t.median = upper_median(y, n);
    return t;
}

// The tails of the union of the parts' values (merge_sides per side); the median the first's.
inline ValueTails merge_tails(const std::vector<ValueTails> &parts, size_t keep) {
    ValueTails t;
    if (parts.empty()) return t;
    std::vector<const SideExtremes *> up, down;
    for (const ValueTails &p : parts) {
        up.push_back(&p.upper);
        down.push_back(&p.lower);
    }
    t.upper = merge_sides(up, keep);
    t.lower = merge_sides(down, keep);
    t.median = parts.front().median;
    return t;
}

}  // namespace re
