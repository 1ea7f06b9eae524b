// The table samplers (pbrt-v4's piecewise-constant densities, sampled by inversion): one
// CDF table over an interval, and a marginal over rows with one conditional a row on the unit
// square (PiecewiseTables; small 2-D tables in vector lanes, SmallTable2D).  make_sampler
// builds them from a registry name ("piecewise_constant_1d", "piecewise_constant_2d").
#pragma once
#include <cstddef>
#include <vector>

#include "samplers.h"

namespace re {

// The density proportional to `values` on their bins over [a, b] (b > a, the values checked
// by the caller: finite, >= 0, not all 0).
SamplerPtr make_piecewise_constant_1d(const std::vector<double> &values, double a, double b);
// The density proportional to `values` (rows x cols of them, row-major; rows along y) on the
// cells of [0, 1]^2 (the values checked by the caller: finite, >= 0, not all 0); an all-zero
// row is never drawn.
SamplerPtr make_piecewise_constant_2d(const std::vector<double> &values, size_t rows, size_t cols);

}  // namespace re
