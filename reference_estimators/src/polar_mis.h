// MIS of a pair of polar direction samplers in one loop: both techniques' draws, pdfs, weights
// and terms per vector of samples, with the u0s drawn from the generator as the loop uses them.
// The estimators' pass-by-pass polar path (estimator_blocks.cpp's polar_mis) stores and reloads
// every intermediate (each technique's z, its pdf, the other's pdf, f, the running sum) and
// draws the block's uniforms first; here none of it leaves the registers, so the generator's
// multiplications and the loads and stores overlap the divisions that bound the loop.
#pragma once
#include <cstddef>

#include "accumulator.h"
#include "estimators.h"
#include "pcg32.h"
#include "samplers.h"

namespace re {

// One block of a fused pair (fused_polar_pair): rows generator rows of u0s drawn from gen
// (LaneGenerator::Rows<true>: the even-numbered uniforms; sample i's u0 for technique a is the
// evens' value 2 i + a, as draw_uniforms lays them out), LaneGenerator::kEvensPerRow / 2
// samples a row.  Up to the stage `last`:
// - Contributions: y[i] = (0 + w_0 f / p_0) + w_1 f / p_1 for every sample, the pass-by-pass
//   path's operations in its order (the same bits), and scan = scan_block(y);
// - an earlier stage (profile_stages' prefixes): its values' sums into p and q, so that none is
//   left out (Sampled: each technique's pdf, p_0 into p and p_1 into q; Screened: also the
//   screening; Weighted: also each technique's pdf at the other's point, added).
// Returns the number of samples whose draw the screening rejects (a cosine no direction of the
// domain has, a pdf not in (0, max double]: Sampler::sample_polar's count, both techniques');
// with any, y and scan are not to be used.  The generator's odd lanes are not moved on
// (LaneGenerator::skip_odd(rows) after).
using FusedPairKernel = size_t (*)(const Sampler &s0, const Sampler &s1, Stage last, LaneGenerator &gen,
                                   size_t rows, double *y, double *p, double *q, BlockScan &scan);

// The fused kernel for MIS of the samplers s0 and s1 (techniques 0 and 1) with the balance
// (beta = 1) or power (beta = 2) heuristic on an integrand equal to the pdf of technique
// f_is_pdf (estimator_blocks.h's polar_pdf_equal_to_f), or null where there is none: the
// integrand then is not inlined into the loop, and the pass-by-pass path runs.  Kernels exist
// for every pair of direction sampler types of which the one f equals has a named polar
// function (Sampler::polar_function: GGX).
FusedPairKernel fused_polar_pair(const Sampler &s0, const Sampler &s1, int f_is_pdf, double beta);

}  // namespace re
