// The bookkeeping of the sampler check's adaptive cubature (harness/samplers/cubature.py,
// box_integrals): which boxes to split where, which have converged, what error each keeps,
// and the boxes of the next level.  The integrals themselves need the user's pdf, so Python
// calls it between the steps; this state does the rest, in the order of operations of the
// numpy code it replaces (the same bits): that code's thirty array passes a level, each with
// its temporaries, had cost an environment map's check a fifth of its time.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

namespace re {

// Where the interval [lo, hi) is split (cubature.py's split_points): the break of `breaks`
// (sorted, n of them) strictly inside it (more than 1e-9 of its width from either end)
// nearest its middle, of the first at or above the middle and the one before it, the one
// before only when strictly nearer; the middle where no break is inside.
inline double split_point(double lo, double hi, const double *breaks, size_t n) {
    const double mid = (lo + hi) / 2;
    if (n == 0) return mid;
    const double margin = 1e-9 * (hi - lo);
    auto at_or_above = [&](double x, bool strictly) {   // numpy's searchsorted, side right / left
        return size_t((strictly ? std::upper_bound(breaks, breaks + n, x) : std::lower_bound(breaks, breaks + n, x)) -
                      breaks);
    };
    const size_t first = at_or_above(lo + margin, true);
    const size_t last = at_or_above(hi - margin, false);
    if (last <= first) return mid;
    const size_t top = last - 1;                            // max(last - 1, first), last > first
    const size_t near = std::clamp(at_or_above(mid, false), first, top);
    const size_t below = near > first ? near - 1 : first;   // clip(near - 1, first, top)
    const double a = breaks[std::min(near, n - 1)], b = breaks[std::min(below, n - 1)];
    return std::fabs(b - mid) < std::fabs(a - mid) ? b : a;
}

// Whether the n breaks are sorted numbers (no NaN), as split_point needs them.
inline bool sorted_breaks(const double *b, size_t n) {
    return std::is_sorted(b, b + n) && std::none_of(b, b + n, [](double x) { return x != x; });
}

// numpy's maximum: NaN if either is.
inline double nan_max(double a, double b) { return a != a ? a : (b != b ? b : (a > b ? a : b)); }

// The refinement of boxes [lo, hi] (k = 1 or 2 coordinates) of values with m columns, level
// by level: halves() gives every box's two halves along each axis (axis-major: axis 0's
// 2B rows, then axis 1's), the caller integrates them, step() takes those integrals, finishes
// the boxes that converged (or all, at the last level) and keeps the others' best halves as
// the next level's boxes.  result() sums each original box's finished parts in the order they
// finished (numpy's bincount).
class BoxRefinement {
  public:
    // lo, hi (n, k); whole (n, m): the rule's integrals over the boxes; tol (n): each box's
    // tolerance; breaks[axis]: sorted split coordinates (empty: none).
    BoxRefinement(const double *lo, const double *hi, const double *whole, const double *tol, size_t n, size_t k,
                  size_t m, double floor, bool extrapolate, std::vector<std::vector<double>> breaks)
        : k_(k), m_(m), cells_(n), floor_(floor), extrapolate_(extrapolate), breaks_(std::move(breaks)),
          tol_(tol, tol + n), lo_(lo, lo + n * k), hi_(hi, hi + n * k), whole_(whole, whole + n * m),
          share_(n, 1.0), history_(2 * n, std::numeric_limits<double>::quiet_NaN()), owner_(n) {
        if (k != 1 && k != 2) throw std::invalid_argument("boxes of 1 or 2 coordinates");
        if (m == 0) throw std::invalid_argument("integrals of at least one column");
        if (breaks_.size() != k) throw std::invalid_argument("one list of breaks per axis");
        for (const std::vector<double> &b : breaks_)
            if (!sorted_breaks(b.data(), b.size())) throw std::invalid_argument("breaks must be sorted numbers, no NaN");
        for (size_t i = 0; i < n; ++i) owner_[i] = int64_t(i);
    }

    size_t boxes() const { return owner_.size(); }
    size_t k() const { return k_; }
    size_t m() const { return m_; }
    size_t cells() const { return cells_; }

    // The halves of every box along every axis, into clo, chi (k * 2B rows of k): rows
    // axis * 2B + 2i and + 2i + 1 are box i's lower and upper part along `axis`, cut at its
    // split point.  Keeps the cuts for step(), which makes the next level's boxes from them.
    void halves(double *clo, double *chi) {
        const size_t B = boxes();
        cut_.resize(k_ * B);
        for (size_t axis = 0; axis < k_; ++axis) {
            const std::vector<double> &br = breaks_[axis];
            for (size_t i = 0; i < B; ++i) {
                const double cut = split_point(lo_[i * k_ + axis], hi_[i * k_ + axis], br.data(), br.size());
                cut_[axis * B + i] = cut;
                for (size_t half = 0; half < 2; ++half)
                    half_box(i, axis, cut, half, clo + (axis * 2 * B + 2 * i + half) * k_,
                             chi + (axis * 2 * B + 2 * i + half) * k_);
            }
        }
        halved_ = true;
    }

    // parts (k * 2B rows of m): the integrals over halves()' boxes, in its order.  `last`:
    // finish every box (the depth or evaluation limit).  Returns whether boxes remain.
    bool step(const double *parts, bool last) {
        if (!halved_) throw std::logic_error("step() takes the integrals over halves()' boxes: call halves() first");
        halved_ = false;
        const size_t B = boxes(), m = m_;
        std::vector<double> change(k_ * B), refined(m), diff(m);
        std::vector<size_t> best(B);
        std::vector<unsigned char> keep(B);
        for (size_t i = 0; i < B; ++i) {
            const double *w = &whole_[i * m];
            for (size_t axis = 0; axis < k_; ++axis) {
                const double *p = parts + (axis * 2 * B + 2 * i) * m;
                change[i * k_ + axis] = std::fabs((p[0] + p[m]) - w[0]);
            }
            // numpy's argmax: the first maximum, or the first NaN
            size_t b = 0;
            if (k_ == 2) {
                const double c0 = change[i * k_], c1 = change[i * k_ + 1];
                b = c0 != c0 ? 0 : (c1 != c1 ? 1 : (c1 > c0 ? 1 : 0));
            }
            best[i] = b;
            const double *p = parts + (b * 2 * B + 2 * i) * m;
            for (size_t c = 0; c < m; ++c) {
                refined[c] = p[c] + p[m + c];
                diff[c] = std::fabs(refined[c] - w[c]);
            }
            const double moved = change[i * k_ + b];
            const double limit = nan_max(tol_[size_t(owner_[i])] * share_[i], floor_ * std::fabs(w[0]));
            const bool converged = moved <= limit;
            const bool done = converged || last;
            keep[i] = !done;
            if (!done) continue;
            if (extrapolate_ && !converged) {
                const double factor = unconverged_factor(moved, history_[2 * i], history_[2 * i + 1]);
                for (size_t c = 0; c < m; ++c) diff[c] *= factor;
            }
            fin_owner_.push_back(owner_[i]);
            fin_value_.insert(fin_value_.end(), refined.begin(), refined.end());
            fin_error_.insert(fin_error_.end(), diff.begin(), diff.end());
        }
        // the next level: the kept boxes' best halves, axis by axis, each in row order (laid out
        // first and written in place: growing seven vectors a half at a time had cost 48 ns a box)
        const size_t next = 2 * size_t(std::count(keep.begin(), keep.end(), 1));
        std::vector<double> lo(next * k_), hi(next * k_), whole(next * m), share(next), history(2 * next);
        std::vector<int64_t> owner(next);
        size_t at = 0;
        for (size_t axis = 0; axis < k_; ++axis)
            for (size_t i = 0; i < B; ++i) {
                if (!keep[i] || best[i] != axis) continue;
                // the first part's share of the box's tolerance: half, or its share of the
                // width where the box is cut at a break (exactly half where at the middle)
                const double a = lo_[i * k_ + axis], b = hi_[i * k_ + axis], cut = cut_[axis * B + i];
                const double f = cut == (a + b) / 2 ? 0.5 : (cut - a) / (b - a);
                for (size_t half = 0; half < 2; ++half, ++at) {
                    const size_t r = axis * 2 * B + 2 * i + half;
                    half_box(i, axis, cut, half, &lo[at * k_], &hi[at * k_]);
                    std::copy(parts + r * m, parts + r * m + m, &whole[at * m]);
                    owner[at] = owner_[i];
                    share[at] = half ? share_[i] * (1 - f) : share_[i] * f;
                    history[2 * at] = change[i * k_ + axis];
                    history[2 * at + 1] = history_[2 * i];
                }
            }
        lo_.swap(lo), hi_.swap(hi), whole_.swap(whole), owner_.swap(owner), share_.swap(share);
        history_.swap(history);
        return !owner_.empty();
    }

    // Per original box, the sums of its finished parts' integrals and errors (cells x m each),
    // added in the order the parts finished.
    void result(double *integral, double *error) const {
        std::fill(integral, integral + cells_ * m_, 0.0);
        std::fill(error, error + cells_ * m_, 0.0);
        for (size_t r = 0; r < fin_owner_.size(); ++r)
            for (size_t c = 0; c < m_; ++c) {
                integral[size_t(fin_owner_[r]) * m_ + c] += fin_value_[r * m_ + c];
                error[size_t(fin_owner_[r]) * m_ + c] += fin_error_[r * m_ + c];
            }
    }

  private:
    // Box i's lower (half 0) or upper part along `axis`, cut at `cut`, into lo, hi (k each).
    void half_box(size_t i, size_t axis, double cut, size_t half, double *lo, double *hi) const {
        for (size_t j = 0; j < k_; ++j) {
            lo[j] = lo_[i * k_ + j];
            hi[j] = hi_[i * k_ + j];
        }
        (half ? lo : hi)[axis] = cut;
    }

    // How many times its last change `change` the error left in a box that stopped
    // unconverged is taken to be, from the changes of its parent's and grandparent's splits
    // c1, c2 (NaN where none): the changes shrinking geometrically at the ratio r of the sums
    // of two successive ones (a pair sum evens out splits alternating between axes around a
    // point singularity; at depth 1 the single changes), the error left is the pair sum times
    // r / (1 - r); never below 1 (the change itself), 1 at depth 0 or without a change.  r is
    // at most kMaxRatio: a box whose changes shrink more slowly (a singularity stronger than
    // x^-0.985, a density not integrable there, changes at rounding level) is taken to shrink
    // at that ratio, 99 times its change remaining.  numpy's nan_to_num and clip, value for
    // value (tests/samplers/test_cubature.py holds the numpy algorithm).
    static double unconverged_factor(double change, double c1, double c2) {
        constexpr double kMaxRatio = 0.99;
        constexpr double kHuge = std::numeric_limits<double>::max();
        if (c1 != c1 || !(change > 0)) return 1.0;
        const double pair = change + c1, before = c1 + c2;
        const bool single = c2 != c2;
        double ratio = single ? change / c1 : pair / before;
        const double base = single ? change : pair;
        ratio = ratio != ratio ? 0.0 : (ratio == std::numeric_limits<double>::infinity() ? kMaxRatio : ratio);
        ratio = std::min(std::max(ratio, 0.0), kMaxRatio);     // np.clip(..., 0, 0.99), -inf to 0
        double factor = base * ratio / (1 - ratio) / change;
        factor = factor != factor ? 1.0 : (factor > kHuge ? kHuge : (factor < -kHuge ? -kHuge : factor));
        return factor > 1.0 ? factor : 1.0;
    }

    size_t k_, m_, cells_;
    double floor_;
    bool extrapolate_, halved_ = false;   // halves() made this level's halves, step() not yet taken them
    std::vector<std::vector<double>> breaks_;
    std::vector<double> tol_, lo_, hi_, whole_, share_, history_, cut_;   // cut_: halves()' cuts, axis-major
    std::vector<int64_t> owner_;
    std::vector<int64_t> fin_owner_;
    std::vector<double> fin_value_, fin_error_;
};

}  // namespace re
