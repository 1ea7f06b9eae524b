// Estimators over chunks: every entry point splits its n samples into fixed-size chunks,
// gives chunk c the PCG32 stream keyed by (seed, case, replica, c), runs chunks on the
// thread pool and merges their accumulator states in chunk order.
#pragma once
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "accumulator.h"
#include "extremes.h"
#include "integrands.h"
#include "pcg32.h"

namespace re {

constexpr uint64_t kChunkSize = uint64_t(1) << 16;  // samples per chunk: fixes the streams

struct Estimate {
    Moments moments;          // of the finite contributions
    Diagnostics diagnostics;  // counts and examples of everything excluded or suspicious
    double seconds = 0;       // wall time of the whole call
    std::vector<double> busy; // seconds each thread spent in chunks (the caller's first)
    uint64_t chunks = 0;
    int threads = 1;
    ValueTails tails;         // with RunOptions::tail_keep > 0: the finite contributions' tails
    // the path integrate()'s blocks took (estimator_blocks.h's Kernel::path: "general", or
    // one of the polar path's, its loops named where some block took them); empty elsewhere
    std::string kernel;
};

struct RunOptions {
    StreamKey key;            // chunk field ignored: set per chunk
    int threads = 0;          // 0: all hardware threads
    bool higher_moments = true;
    // Only chunks [chunk_begin, chunk_end) of the estimate (clamped to its chunk count): a
    // storage unit of the suite runner.  Merging the ranges' states in order rebuilds the
    // estimate (bitwise, for the same ranges).
    uint64_t chunk_begin = 0, chunk_end = UINT64_MAX;
    // With tail_keep > 0, integrate() also keeps the tails of the finite contributions it
    // accumulates (value_tails: `tail_keep` per side, merged over the range's chunks in chunk
    // order) and, with tail_median, the upper median of the range's first chunk: the bias
    // test's tail sample, drawn in the same pass as the estimate (no second pass over them).
    size_t tail_keep = 0;
    bool tail_median = false;
};

// The stages of a block's contributions after its uniforms, in order (StageTimes):
// profile_stages stops after each in turn.
enum class Stage { Sampled, Screened, Weighted, Contributions };

// Wall seconds of each prefix of integrate()'s pipeline, each run over the same chunks on the
// same threads: the point set alone (0 for rejection samplers, which draw inside the
// sampler); for the techniques that draw points from samplers (importance, uniform on a
// sphere or hemisphere, MIS) the points also drawn (`sampled`), then screened for the domain
// and bad pdfs (`screened`), and for MIS also weighted (every technique's pdf at every point:
// `weighted`), NaN where the technique has no such stage; the contributions (the integrand
// and the estimator's arithmetic too), and the whole estimate (the contributions' screening
// and accumulation too).  Differences give each stage's cost.
struct StageTimes {
    static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
    double points = 0, sampled = kNone, screened = kNone, weighted = kNone, contributions = 0;
    Estimate estimate;  // the whole pipeline: its seconds and per-thread busy time
};
StageTimes profile_stages(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt);

// Merges states in the order given (Chan/Pebay; the same order gives the same bits).
Estimate merge_estimates(const std::vector<Estimate> &parts);

// Runs the technique's estimator on the integrand with n samples.
Estimate integrate(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt);

// The per-sample contributions the same call would accumulate (NaN and Inf kept; samples
// the estimator would drop for a bad pdf or a point outside the sampler's domain are NaN).
void contributions(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt, double *out);

// Moments and diagnostics of given values (chunked the same way; no random numbers).
Estimate accumulate_values(const double *y, uint64_t n, const RunOptions &opt);

// The state of one chunk of a user's contributions y[0..count) (samples first.. of the
// estimate, accumulated in blocks as integrate() does), with the canonical points u (count, ud)
// that produced them named in the examples of faulty values; u may be null.
Estimate accumulate_chunk(const double *y, uint64_t count, uint64_t first, const double *u, int ud);

// Importance-sampling estimate f(x)/pdf from points and pdf values drawn elsewhere (a
// renderer's sampler): reports points outside `sampler_domain` and bad pdfs.
Estimate estimate_from_samples(const Integrand &f, const double *x, const double *pdf, uint64_t n,
                               const Domain &sampler_domain, const RunOptions &opt);

// n points and their pdf values from a sampler (any method), chunked like integrate().
Diagnostics draw_samples(const Sampler &s, uint64_t n, const RunOptions &opt, double *x, double *pdf);

}  // namespace re
