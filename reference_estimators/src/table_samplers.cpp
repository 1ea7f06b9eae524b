#include "table_samplers.h"

#include <algorithm>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "direction_samplers.h"
#include "domain.h"
#include "piecewise_tables.h"
#include "sampling.h"
#include "small_table2d.h"

namespace re {
namespace {

// pbrt-v4's PiecewiseConstant1D over [a, b]: one CDF table (PiecewiseTables), sampled by inversion.
class PiecewiseConstant1D final : public Pointwise<PiecewiseConstant1D> {
  public:
    PiecewiseConstant1D(const std::vector<double> &values, double a, double b) : t_(values.size(), a, b) {
        name = "piecewise_constant_1d";
        params = {{"a", a}, {"b", b}, {"bins", double(values.size())}};
        domain = Domain::interval(a, b);
        t_.add(values);
    }
    void sample(const double *u, double *x, double *p, size_t n) const override {
        t_.sample_many(nullptr, u, 1, n, x, 1, p);
    }
    double sample_one(const double *u, double *x) const { return t_.sample_one(0, u[0], x); }
    double pdf_one(const double *x) const { return x[0] >= t_.a && x[0] <= t_.b ? t_.density(0, x[0]) : 0.0; }
    void invert_one(const double *x, double *u) const {
        u[0] = x[0] >= t_.a && x[0] <= t_.b ? t_.cdf_at(0, x[0]) : kNaN;
    }

  private:
    PiecewiseTables t_;
};

// pbrt-v4's PiecewiseConstant2D over [0,1]^2: a marginal over rows (y) and one conditional
// per row over columns (x).  Table shape (rows, cols), row-major.
class PiecewiseConstant2D final : public Pointwise<PiecewiseConstant2D> {
  public:
    PiecewiseConstant2D(const std::vector<double> &values, size_t rows, size_t cols)
        : marginal_(rows), conditional_(cols) {
        name = "piecewise_constant_2d";
        params = {{"rows", double(rows)}, {"cols", double(cols)}};
        domain = Domain::box({0, 0}, {1, 1});
        udim = 2;
        std::vector<double> row_sums(rows);
        for (size_t r = 0; r < rows; ++r) {
            std::vector<double> row(values.begin() + r * cols, values.begin() + (r + 1) * cols);
            CompensatedSum s;
            for (double v : row) s.add(v);
            row_sums[r] = s.value() / double(cols);
            if (!(s.value() > 0)) row.assign(cols, 1.0);  // an empty row is never selected
            conditional_.add(row);
        }
        marginal_.add(row_sums);
        // marginal_.density(0, y) conditional_.density(row, x), the same products in the same order
        for (size_t r = 0; r < rows; ++r)
            for (size_t c = 0; c < cols; ++c)
                cell_pdf_.push_back(marginal_.f[r] * marginal_.scale[0]
                                    * (conditional_.f[r * cols + c] * conditional_.scale[r]));
        if (SmallTable2D::fits(marginal_, conditional_)) small_.emplace(marginal_, conditional_);
    }
    // In blocks: the marginal's y for every point, then each point's row, then the
    // conditionals' x and each point's column (PiecewiseTables::sample_many's passes), the
    // density read off the cells' table: the marginal's and the conditional's densities
    // multiplied as sample_one multiplies them, for the bins the point lies in, which on
    // [0, 1]^2 are the bins its uniforms in [0, 1] chose (each bin of a table under 2^50 bins
    // holds doubles; the bindings refuse other uniforms).
    // (gaussian2d's 16 x 16 table: 96 -> 102 Msamples/s a thread, without the two densities.)
    // Small tables' whole vectors of points take SmallTable2D's kernel, the same bits.
    void sample(const double *u, double *x, double *p, size_t n) const override {
        const size_t vectors = small_ ? small_->sample(marginal_, conditional_, cell_pdf_.data(), u, x, p, n) : 0;
        sample_from(vectors, u, x, p, n);
    }
    // Small tables screen their vectors' points in the kernel's lanes (SmallTable2D), the rest
    // in the screening's own passes (a pass over the block for each test was 0.6 ns a sample
    // of an MIS estimate's 12.5 with the uniform box).
    bool sample_valid(const double *u, double *x, double *p, size_t n) const override {
        if (!small_) return Sampler::sample_valid(u, x, p, n);
        size_t invalid = 0;
        const size_t vectors = small_->sample(marginal_, conditional_, cell_pdf_.data(), u, x, p, n, &invalid);
        sample_from(vectors, u, x, p, n);
        return invalid == 0 && all_valid(domain, x + 2 * vectors, p + vectors, n - vectors);
    }
    std::string kernel() const override { return small_ ? "small table in vector lanes" : "batch loop"; }
    double sample_one(const double *u, double *x) const {
        double y;
        const double py = marginal_.sample_one(0, u[1], &y);
        const size_t r = marginal_.bin_of_x(y);
        const double px = conditional_.sample_one(r, u[0], x);
        x[1] = y;
        return py * px;
    }
    double pdf_one(const double *x) const {
        if (!in_rectangle(x[0], x[1], 0.0, 1.0, 0.0, 1.0)) return 0.0;   // domain.contains, inline
        return cell_pdf_[marginal_.bin_of_x(x[1]) * conditional_.bins + conditional_.bin_of_x(x[0])];
    }
    // pdf_one, kWidth points at a time: the cells' indices in vector lanes (bin_of_x on [0, 1]
    // is min(floor(x bins), bins - 1), x bins exact for bins a power of 2 or not), then their
    // densities loaded lane by lane: pdf() 2.8x the speed of the loop over pdf_one on a 16 x 16
    // table, 2x on 256 x 512 (2e6 points through the Python API, Zen 4).
    void pdf(const double *x, double *p, size_t n) const override {
        using simd::f64v;
        constexpr size_t W = simd::kWidth;
        const double rows = double(marginal_.bins), cols = double(conditional_.bins);
        size_t i = 0;
        for (; i + W <= n; i += W) {
            f64v x0, x1;
            simd::deinterleave(x + 2 * i, x0, x1);
            const auto in = (x0 >= 0.0) & (x0 <= 1.0) & (x1 >= 0.0) & (x1 <= 1.0);
            const f64v row = simd::min_or_second(simd::floor(in ? x1 * rows : f64v{}), rows - 1 - f64v{});
            const f64v col = simd::min_or_second(simd::floor(in ? x0 * cols : f64v{}), cols - 1 - f64v{});
            const auto cell = __builtin_convertvector(row * cols + col, simd::i64v);
            f64v d;
            for (size_t l = 0; l < W; ++l) d[l] = cell_pdf_[size_t(cell[l])];
            simd::store(p + i, in ? d : f64v{});
        }
        for (; i < n; ++i) p[i] = pdf_one(x + 2 * i);
    }
    void invert_one(const double *x, double *u) const {
        if (!domain.contains(x)) { u[0] = u[1] = kNaN; return; }
        u[0] = conditional_.cdf_at(marginal_.bin_of_x(x[1]), x[0]);
        u[1] = marginal_.cdf_at(0, x[1]);
    }

  private:
    // sample()'s points first .. n - 1, in blocks (sample_many's passes).
    void sample_from(size_t first, const double *u, double *x, double *p, size_t n) const {
        constexpr size_t kBlock = 256;
        int64_t row[kBlock], col[kBlock];
        const size_t cols = conditional_.bins;
        for (size_t a = first; a < n; a += kBlock) {
            const size_t m = std::min(kBlock, n - a);
            marginal_.sample_many(nullptr, u + 2 * a + 1, 2, m, x + 2 * a + 1, 2, nullptr, row);
            conditional_.sample_many(row, u + 2 * a, 2, m, x + 2 * a, 2, nullptr, col);
            for (size_t j = 0; j < m; ++j) p[a + j] = cell_pdf_[size_t(row[j]) * cols + size_t(col[j])];
        }
    }

    PiecewiseTables marginal_, conditional_;   // rows over y; each row's columns over x
    std::vector<double> cell_pdf_;   // the density of cell (row, col) at [row cols + col]
    std::optional<SmallTable2D> small_;   // where the tables fit it (SmallTable2D::fits)
};

}  // namespace

SamplerPtr make_piecewise_constant_1d(const std::vector<double> &values, double a, double b) {
    return std::make_shared<PiecewiseConstant1D>(values, a, b);
}

SamplerPtr make_piecewise_constant_2d(const std::vector<double> &values, size_t rows, size_t cols) {
    return std::make_shared<PiecewiseConstant2D>(values, rows, cols);
}

}  // namespace re
