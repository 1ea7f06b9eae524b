// The bookkeeping of the sampler check's grouped cubature (harness/samplers/cubature.py,
// grouped_integrals) and of its CDF tables' leaves (harness/samplers/cdf_tables.py, tabulate's
// quarters): which boxes a leaf's quarters are, which boxes' rules agree with their parent's,
// and the boxes' integrals summed back into each leaf's quarter masses.  The integrals need the
// user's pdf, so Python calls it between these steps.  Each step does what the numpy code it
// replaces did, in its order of operations (bincount's sums in row order, sum's pairwise
// summation): the same bits.  That code's forty array passes a level, each with temporaries of
// up to a million boxes, had cost a tilted microfacet lobe's check a quarter of its own time
// (its quarters' boxes and the grouped judgement a tenth of its tabulation each).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "check_refine.h"

namespace re {

// The pairwise part of numpy's sum of n contiguous doubles: plain from 0.0 below 8 values,
// eight interleaved partial sums up to 128, halves (cut at a multiple of 8) beyond.
inline double pairwise_sum(const double *a, size_t n) {
    if (n < 8) {
        double s = 0.0;
        for (size_t i = 0; i < n; ++i) s += a[i];
        return s;
    }
    if (n <= 128) {
        double r[8];
        for (size_t j = 0; j < 8; ++j) r[j] = a[j];
        size_t i = 8;
        for (; i < n - n % 8; i += 8)
            for (size_t j = 0; j < 8; ++j) r[j] += a[i + j];
        double s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; ++i) s += a[i];
        return s;
    }
    size_t half = n / 2;
    half -= half % 8;
    return pairwise_sum(a, half) + pairwise_sum(a + half, n - half);
}

// numpy's sum of n contiguous doubles, bit for bit (np.sum along a contiguous axis): 0.0 plus
// the pairwise sum, so that a sum of -0.0s is 0.0 as numpy's.
inline double numpy_sum(const double *a, size_t n) { return 0.0 + pairwise_sum(a, n); }

// index[i] as an index below `count`, read once; std::invalid_argument (a ValueError in Python)
// naming `what` if it is not.  The kernels check each index where they read it: an array
// checked first and read later could have been changed by another thread in between.
inline size_t checked_index(const int64_t *index, size_t i, size_t count, const char *what) {
    const int64_t v = index[i];
    if (v < 0 || uint64_t(v) >= count)
        throw std::invalid_argument(std::string(what) + " index " + std::to_string(v) + " outside [0, " +
                                    std::to_string(count) + ")");
    return size_t(v);
}

// How many of `parents` parent boxes are not cut along every axis by their boxes: parent g is
// cut along an axis where one of the boxes i with group[i] == g ends below the parent's end
// (hi[i] < parent_hi[g]; k coordinates each).  An index outside [0, parents) throws.
inline size_t uncut_parents(const double *hi, const int64_t *group, size_t boxes, size_t k, const double *parent_hi,
                            size_t parents) {
    std::vector<unsigned char> cut(parents, 0);   // bit `axis`: cut along it
    for (size_t i = 0; i < boxes; ++i) {
        const size_t g = checked_index(group, i, parents, "a parent");
        for (size_t axis = 0; axis < k; ++axis)
            if (hi[i * k + axis] < parent_hi[g * k + axis]) cut[g] |= (unsigned char)(1u << axis);
    }
    const unsigned char all = (unsigned char)((1u << k) - 1);
    size_t uncut = 0;
    for (unsigned char c : cut) uncut += c != all;
    return uncut;
}

// grouped_integrals' judgement of boxes against their parents: own (boxes, m) the rule's
// integrals over the boxes, parent (parents, m) over the parents, group[i] box i's parent, tol
// (boxes) each box's tolerance.  A parent agrees where every column of |sum of its boxes' -
// its own| is finite and column 0 is within the sum of its boxes' tolerances or `floor` times
// |its own|; the boxes of an agreeing parent take their own integrals (value, a copy of own)
// with the parent's change shared by tolerance as their error; the others' rows go to `rest`,
// in order (their value own's, their error 0: box_integrals' to fill).  An index outside
// [0, parents) throws.
inline void grouped_agreement(const double *own, const double *parent, const int64_t *group, const double *tol,
                              size_t boxes, size_t parents, size_t m, double floor, double *value, double *error,
                              std::vector<int64_t> &rest) {
    std::vector<double> change(parents * m, 0.0), group_tol(parents, 0.0);
    std::vector<size_t> owner(boxes);   // group read (and checked) once
    for (size_t i = 0; i < boxes; ++i) owner[i] = checked_index(group, i, parents, "a parent");
    for (size_t i = 0; i < boxes; ++i) {   // np.bincount's sums: from 0, in row order
        const size_t g = owner[i];
        for (size_t c = 0; c < m; ++c) change[g * m + c] += own[i * m + c];
        group_tol[g] += tol[i];
    }
    std::vector<unsigned char> agreed(parents);
    for (size_t g = 0; g < parents; ++g) {
        bool finite = true;
        for (size_t c = 0; c < m; ++c) {
            const double d = std::fabs(change[g * m + c] - parent[g * m + c]);
            change[g * m + c] = d;
            finite &= std::isfinite(d);
        }
        agreed[g] = finite && change[g * m] <= nan_max(group_tol[g], floor * std::fabs(parent[g * m]));
    }
    for (size_t i = 0; i < boxes; ++i) {
        const size_t g = owner[i];
        for (size_t c = 0; c < m; ++c) value[i * m + c] = own[i * m + c];
        if (!agreed[g]) {
            for (size_t c = 0; c < m; ++c) error[i * m + c] = 0.0;
            rest.push_back(int64_t(i));
            continue;
        }
        const double share = tol[i] / nan_max(group_tol[g], 1e-300);
        for (size_t c = 0; c < m; ++c) error[i * m + c] = change[g * m + c] * share;
    }
}

// The boxes of tabulate's quarters: leaf l of strip strip[l] spans [a[l], b[l]) along `axis`
// and is cut into four quarters there, edges a + ((b - a) j) / 4; on the square (k == 2) each
// quarter is cut across into the strip's pieces pieces[strip, p] = (lo, hi) (strips x npiece
// of them, empty ones padding: hi <= lo), and each such box into halves across at its middle.
// A box (l, j, p) is integrated where it is not empty, its tolerance the strip's
// strip_tol[strip] times max(quarter width, 1/4096) over used[strip] (the strip's non-empty
// pieces), shared equally by its halves; its parent is leaf l's piece p, [a, b) along the axis
// (the parents present, in order).  The constructor lays them out (which boxes, how many),
// boxes() writes them into the caller's arrays (one pass, no reallocation: vectors grown a box
// at a time and copied out had cost more than the numpy code), sums() folds the boxes'
// integrals back into each leaf's four quarter masses (those not finite: mass 0, error 1) and
// the sum of its boxes' errors.  The leaves and pieces are copied (a few thousand: small
// beside the boxes) and their indices checked on the copies.
class LeafQuarters {
  public:
    LeafQuarters(const int64_t *strip, const double *a, const double *b, size_t leaves, const double *pieces,
                 size_t strips, size_t npiece, const int64_t *used, const double *strip_tol, size_t axis, size_t k)
        : strip_(strip, strip + leaves), a_(a, a + leaves), b_(b, b + leaves), leaves_(leaves), npiece_(npiece),
          axis_(axis), k_(k), full_(4 * leaves * npiece), parent_of_(leaves * npiece, -1) {
        pieces_.assign(pieces, pieces + 2 * strips * npiece);
        used_.assign(used, used + strips);
        strip_tol_.assign(strip_tol, strip_tol + strips);
        // checked on the copies (the caller's arrays could change meanwhile)
        for (size_t l = 0; l < leaves; ++l) checked_index(strip_.data(), l, strips, "a strip (of 'pieces')");
        for (int64_t u : used_)
            if (u < 1) throw std::invalid_argument("'used' must count at least one piece per strip");
        for (size_t l = 0; l < leaves; ++l) {
            double qa[4], qb[4];
            quarter_edges(l, qa, qb);
            // the parents present (a piece with a box integrated), numbered in (leaf, piece) order
            for (size_t p = 0; p < npiece; ++p) {
                const double *piece = piece_of(l, p);
                bool any = false;
                for (size_t j = 0; j < 4; ++j) {
                    const bool full = qb[j] > qa[j] && (k == 1 || piece[1] > piece[0]);
                    full_[(l * 4 + j) * npiece + p] = full;
                    full_boxes_ += full;
                    any |= full;
                }
                if (any) parent_of_[l * npiece + p] = int64_t(parents_++);
            }
        }
    }

    size_t k() const { return k_; }
    size_t full_boxes() const { return full_boxes_; }                 // the boxes (l, j, p) integrated
    size_t rows() const { return k_ == 2 ? 2 * full_boxes_ : full_boxes_; }   // halves on the square
    size_t parents() const { return parents_; }
    size_t leaves() const { return leaves_; }

    // The boxes to integrate, lo and hi (rows() x k), tol and group (rows()), and their parents,
    // parent_lo and parent_hi (parents() x k).
    void boxes(double *lo, double *hi, double *tol, int64_t *group, double *parent_lo, double *parent_hi) const {
        const size_t P = npiece_;
        for (size_t l = 0; l < leaves_; ++l) {
            const size_t g = size_t(strip_[l]);
            double qa[4], qb[4];
            quarter_edges(l, qa, qb);
            for (size_t p = 0; p < P; ++p) {
                const int64_t parent = parent_of_[l * P + p];
                if (parent >= 0)
                    write_box(parent_lo, parent_hi, size_t(parent), a_[l], b_[l], piece_of(l, p)[0], piece_of(l, p)[1]);
            }
            for (size_t j = 0; j < 4; ++j) {
                const double t = strip_tol_[g] * nan_max(qb[j] - qa[j], 1.0 / 4096) / double(used_[g]);
                for (size_t p = 0; p < P; ++p) {
                    if (!full_[(l * 4 + j) * P + p]) continue;
                    const double *piece = piece_of(l, p);
                    const int64_t parent = parent_of_[l * P + p];
                    if (k_ == 1) {
                        write_box(lo, hi, 0, qa[j], qb[j], 0.0, 0.0);
                        lo += 1, hi += 1;
                        *tol++ = t;
                        *group++ = parent;
                        continue;
                    }
                    const double cut = (piece[0] + piece[1]) / 2;
                    write_box(lo, hi, 0, qa[j], qb[j], piece[0], cut);
                    write_box(lo, hi, 1, qa[j], qb[j], cut, piece[1]);
                    lo += 4, hi += 4;
                    tol[0] = tol[1] = t / 2;
                    group[0] = group[1] = parent;
                    tol += 2, group += 2;
                }
            }
        }
    }

    // From the integrals v and errors e (rows() x m, column 0 used) over the boxes: each leaf's
    // quarter masses qs (leaves x 4: its non-empty boxes' integrals, halves summed, those below
    // 0 as 0) and errs (leaves: its boxes' errors summed), np.sum's pairwise order over each
    // leaf's 4 npiece boxes, empty ones 0.
    void sums(const double *v, const double *e, size_t m, double *qs, double *errs) const {
        const size_t per = 4 * npiece_;
        std::vector<double> val(per), err(per);
        size_t row = 0;
        for (size_t l = 0; l < leaves_; ++l) {
            for (size_t i = 0; i < per; ++i) {
                double v0 = 0.0, e0 = 0.0;
                if (full_[l * per + i]) {
                    if (k_ == 2) {
                        v0 = 0.0 + v[row * m] + v[(row + 1) * m];
                        e0 = 0.0 + e[row * m] + e[(row + 1) * m];
                        row += 2;
                    } else {
                        v0 = v[row * m], e0 = e[row * m];
                        row += 1;
                    }
                    const bool bad = !(std::isfinite(v0) && std::isfinite(e0));
                    v0 = bad ? 0.0 : v0;
                    e0 = bad ? 1.0 : e0;
                }
                val[i] = v0 > 0 ? v0 : 0.0;   // np.maximum(val, 0), -0.0 to 0.0 as numpy's
                err[i] = e0;
            }
            for (size_t j = 0; j < 4; ++j) qs[4 * l + j] = numpy_sum(val.data() + j * npiece_, npiece_);
            errs[l] = numpy_sum(err.data(), per);
        }
    }

  private:
    // Leaf l's quarters [qa[j], qb[j]): numpy's a + ((b - a) j) / 4.
    void quarter_edges(size_t l, double *qa, double *qb) const {
        const double width = b_[l] - a_[l];
        for (size_t j = 0; j < 4; ++j) {
            qa[j] = a_[l] + width * double(j) / 4;
            qb[j] = a_[l] + width * double(j + 1) / 4;
        }
    }

    const double *piece_of(size_t l, size_t p) const { return &pieces_[2 * (size_t(strip_[l]) * npiece_ + p)]; }

    // Row `row` of lo, hi (k each): [x0, x1) along the axis, [y0, y1) across (k == 2).
    void write_box(double *lo, double *hi, size_t row, double x0, double x1, double y0, double y1) const {
        double *l = lo + row * k_, *h = hi + row * k_;
        l[axis_] = x0, h[axis_] = x1;
        if (k_ == 2) l[1 - axis_] = y0, h[1 - axis_] = y1;
    }

    std::vector<int64_t> strip_, used_;           // (leaves), (strips)
    std::vector<double> a_, b_, pieces_, strip_tol_;  // (leaves), (leaves), (strips x npiece x 2), (strips)
    size_t leaves_, npiece_, axis_, k_, full_boxes_ = 0, parents_ = 0;
    std::vector<unsigned char> full_;   // (l, j, p): integrated
    std::vector<int64_t> parent_of_;    // (l, p): the parent's index among those present, or -1
};

// numpy's maximum and minimum of two doubles, its scalar rule (a NaN in either gives a NaN;
// a tie the first): the bound below takes them where the numpy code it replaces did.
inline double numpy_maximum(double a, double b) { return (a >= b || a != a) ? a : b; }
inline double numpy_minimum(double a, double b) { return (a <= b || a != a) ? a : b; }

// The interpolation bound of tabulate's leaves (harness/samplers/cdf_tables.py,
// _interpolation_bound, which states it) from their quarter masses qs (n, 4), into out (n):
// the numpy code's expressions in its order of operations (a row's sum and cumulative sums left
// to right, as numpy's along a row of four), the same values, NaN where numpy's is, but
// for the sign of a zero (numpy's vector maximum and minimum pick it by the ISA; no use of
// the bound reads it: it is compared, and added to non-negative errors).  In one pass over
// the leaves, where the numpy code's thirty array passes a level had cost a lobe's
// tabulation a twelfth of its time.
inline void interpolation_bound(const double *qs, size_t n, double *out) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < n; ++i) {
        const double *q = qs + 4 * i;
        // the leaf's bound: twice the CDF's largest deviation from the chord at the quarter
        // points, at most the largest quarter
        const double cum[3] = {q[0], q[0] + q[1], (q[0] + q[1]) + q[2]};
        const double m = cum[2] + q[3];
        const double at[3] = {0.25, 0.5, 0.75};
        double gap = std::fabs(cum[0] - m * at[0]);
        for (size_t j = 1; j < 3; ++j) gap = numpy_maximum(gap, std::fabs(cum[j] - m * at[j]));
        double largest = q[0];
        for (size_t j = 1; j < 4; ++j) largest = numpy_maximum(largest, q[j]);
        const double leaf = numpy_minimum(2 * gap, largest);
        bool rising = true, falling = true;
        for (size_t j = 0; j < 3; ++j) {
            const double step = q[j + 1] - q[j];
            rising &= step >= 0;
            falling &= step <= 0;
        }
        if (!(rising || falling)) {
            out[i] = leaf;
            continue;
        }
        // the quarters' bound: quarter j's density between its neighbours' (the falling case
        // as the rising one reversed), the extreme step's deviation
        double d[4];
        for (size_t j = 0; j < 4; ++j) d[j] = falling ? q[3 - j] : q[j];
        double quarters = 0;
        for (size_t j = 0; j < 4; ++j) {
            const double low = j == 0 ? 0.0 : d[j - 1], high = j == 3 ? kInf : d[j + 1];
            const double inner = (d[j] - low) * (high - d[j]) / (high - low);
            const double v = high == kInf || high == -kInf ? d[j] - low : (high > low ? inner : 0.0);
            quarters = j == 0 ? v : numpy_maximum(quarters, v);
        }
        out[i] = numpy_minimum(leaf, quarters);
    }
}

}  // namespace re
