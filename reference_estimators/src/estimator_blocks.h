// One block of an estimate (kBlock samples of a chunk): its scratch buffers (Scratch), what an
// estimate needs besides the technique (Kernel), the block's contributions
// (block_contributions, estimator_blocks.cpp) and their screening and accumulation
// (finish_block).  Internal to the core: estimators.cpp runs the blocks over chunks and
// threads.
#pragma once
#include <algorithm>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "estimators.h"
#include "polar_mis.h"
#include "thread_pool.h"

namespace re::blocks {

constexpr size_t kBlock = 2048;  // samples per block: u and y (16 KiB each) stay in L1

inline uint64_t chunk_count(uint64_t n) { return (n + kChunkSize - 1) / kChunkSize; }

inline int resolve_threads(int threads) { return threads > 0 ? threads : ThreadPool::default_threads(); }

inline StreamKey chunk_key(StreamKey k, uint64_t c) {
    k.chunk = c;
    return k;
}

// Calls fn(offset, m) for consecutive blocks of at most kBlock samples covering [0, count).
template <class Fn>
void for_each_block(uint64_t count, Fn fn) {
    for (uint64_t b = 0; b < count; b += kBlock) fn(b, size_t(std::min<uint64_t>(kBlock, count - b)));
}

// Reusable per-block buffers of one chunk.
struct Scratch {
    std::vector<double> u, x, p, f, y, xi, q, w, cols;
    std::vector<unsigned char> drop, sub_drop;
    std::vector<size_t> live;
    double *points = nullptr;  // where this block's points are (x, or u on the unit box)
    std::optional<BlockScan> scan;  // scan_block of the block's y where it was taken (the polar path's)
    // evals: f evaluations per contribution; the point buffer holds at least two blocks
    // (Russian roulette and MIS keep the drawn points after the block's own).
    Scratch(int udim, int xdim, int evals)
        : u(kBlock * size_t(udim)), x(kBlock * size_t(xdim) * std::max(evals, 2)), p(kBlock * evals), f(kBlock * evals), y(kBlock),
          xi(kBlock), q(kBlock * evals), w(kBlock), cols(kBlock * size_t(udim)), drop(kBlock), sub_drop(kBlock * evals) {
        live.reserve(kBlock);
    }
};

// Whether importance sampling or MIS of f may take the polar path: f and the pdf of every
// sampler read a direction's z = cos(theta) alone (Integrand::polar, Sampler::polar), so the
// azimuth (a sincos a sample) and the points' x and y are never formed, stored or reloaded
// (drjit leaves out what nothing reads too).  The same bits as the general path.
inline bool polar_path(const Integrand &f, const Technique &t) {
    if (!f.polar) return false;
    std::vector<const Sampler *> used;
    if (t.kind == TechniqueKind::Mis)
        for (const SamplerPtr &s : t.mis) used.push_back(s.get());
    else if (t.kind == TechniqueKind::Importance || t.kind == TechniqueKind::Uniform)
        used.push_back(t.sampler.get());
    for (const Sampler *s : used)
        if (!s || !s->polar || s->method != SamplingMethod::Inversion) return false;
    return !used.empty();
}

// The sampler among the technique's (its sampler: 0; MIS: the index of one of t.mis) whose pdf
// is f on the polar path: the same named function of z (Sampler::polar_function) on the same
// domain, so f at any point is that pdf there, bit for bit; -1 for none.
inline int polar_pdf_equal_to_f(const Integrand &f, const Technique &t) {
    auto same = [&](const Sampler &s) {
        return !f.polar_function.empty() && s.polar_function == f.polar_function && s.domain.kind == f.domain.kind;
    };
    if (t.kind == TechniqueKind::Mis) {
        for (size_t b = 0; b < t.mis.size(); ++b)
            if (same(*t.mis[b])) return int(b);
        return -1;
    }
    return t.sampler && same(*t.sampler) ? 0 : -1;
}

// Whether MIS technique t weighs two samplers by the balance or the power heuristic:
// add_pair_terms then does the work of mis_weights and add_mis_terms in one pass.
inline bool mis_pair(const Technique &t) { return t.mis.size() == 2 && (t.mis_power == 1 || t.mis_power == 2); }

// What one estimate needs besides the technique: its point set and dimensions.
struct Kernel {
    const Integrand &f;
    const Technique &t;
    PointSetContext points;
    int ud, xd;
    bool polar;     // polar_path(f, t)
    int f_is_pdf;   // on the polar path, polar_pdf_equal_to_f(f, t), else -1
    // on the polar path from a random stream, where every sampler reads u0 of its (u0, u1)
    // alone: the even-numbered uniforms are what it reads (draw_uniforms)
    bool evens;
    // with `evens`, for MIS of a pair whose integrand is one technique's pdf: the kernel that
    // runs the pair in one loop (fused_polar_pair), or null
    FusedPairKernel fused;
    // an MIS pair of samplers that read two uniforms each, on the general path from random
    // points: draw_uniforms writes each sampler's columns apart, sampler a's at u[2 m a ..]
    // (UniformStream::fill_pairs)
    bool pairs_split;
    Kernel(const Integrand &f_, const Technique &t_, uint64_t n, const StreamKey &key)
        : f(f_), t(t_), ud(t_.udim(f_)), xd(f_.domain.dim), polar(polar_path(f_, t_)),
          f_is_pdf(polar ? polar_pdf_equal_to_f(f_, t_) : -1),
          evens(polar && t_.points == PointSetKind::Random && ud == 2 * int(std::max<size_t>(t_.mis.size(), 1)) &&
                std::all_of(t_.mis.begin(), t_.mis.end(), [](const SamplerPtr &s) { return s->udim == 2; }) &&
                (t_.kind == TechniqueKind::Mis || t_.sampler->udim == 2)),
          fused(evens && mis_pair(t_) ? fused_polar_pair(*t_.mis[0], *t_.mis[1], f_is_pdf, t_.mis_power) : nullptr),
          pairs_split(!polar && t_.kind == TechniqueKind::Mis && t_.mis.size() == 2 && t_.mis[0]->udim == 2 &&
                      t_.mis[1]->udim == 2 && t_.points == PointSetKind::Random) {
        points.kind = t_.points;
        points.n = n;
        points.key = key;
    }
    Scratch scratch() const { return Scratch(ud, xd, t.evaluations()); }
    // The path an estimate's blocks took (Estimate::kernel; those handed back then took the
    // general path too: Diagnostics::redone_blocks): the general path; the polar path, its
    // uniforms drawn first and its stages in passes; with `inside` (some block drew its u0s
    // inside a loop: Diagnostics::inside_blocks; only blocks of whole generator rows can,
    // rows_drawn_in_sampler) importance sampling on it with the u0s drawn in the sampler's
    // loop, or an MIS pair on it in one loop (fused).
    std::string path(bool inside) const {
        if (!polar) return "general";
        if (!inside) return "polar";
        return fused ? "polar: MIS pair in one loop" : "polar: u0s drawn in the sampler";
    }
};

// The block's uniforms u[m * ud] (fill_points; Kernel::pairs_split: the two samplers' columns
// apart, u[2 m a ..] sampler a's m x 2, UniformStream::fill_pairs), or on a polar path reading
// u0 alone (Kernel::evens) with the stream row-aligned, the even-numbered ones alone
// u[m * ud / 2]: each sampler's u0, sample i's of sampler a at u[i * ud / 2 + a] (fill_even:
// half the generator's work, which drjit's tracer leaves out too).  Returns, where it drew the evens
// alone, where the stream stood before them (UniformStream::rewind draws them all again).
inline std::optional<LaneGenerator> draw_uniforms(const Kernel &k, UniformStream &stream, uint64_t first, size_t m,
                                           double *u) {
    if (k.evens && stream.row_aligned()) {   // (elsewhere the shortcut saves nothing)
        const LaneGenerator before = stream.position();
        stream.fill_even(u, m * size_t(k.ud));
        return before;
    }
    if (k.pairs_split) {
        stream.fill_pairs(u, u + 2 * m, m);
        return std::nullopt;
    }
    fill_points(k.points, stream, first, m, k.ud, u);
    return std::nullopt;
}

// Checks sampled points against the sampler's domain and pdf values for NaN / Inf / <= 0;
// records what fails and marks it in `drop` (untouched when nothing fails).  Returns the
// number marked.
size_t check_samples(const Domain &dom, const double *x, const double *p, size_t m, uint64_t first,
                     Diagnostics &diag, unsigned char *drop);

// Fills s.y[0..m) with the contributions of samples first..first+m of this chunk; samples
// the estimator cannot use are recorded in diag and flagged in s.drop (returns their count).
// With `last` before Contributions, a technique that draws points from samplers stops after
// that stage (s.y is then not filled; MIS goes on to its next technique).
size_t block_contributions(const Kernel &k, UniformStream &stream, size_t m, uint64_t first, Scratch &s,
                           Diagnostics &diag, Stage last = Stage::Contributions);

// Screens and accumulates one block, first dropping the samples marked in `drop` (already
// recorded as outside the domain or with a bad pdf); the kept ones remember their sample
// indices, so later examples in the block still name the right sample.  `scan`: y's
// scan_block where block_contributions took it (Scratch::scan).
void finish_block(double *y, double *x, int xd, size_t m, size_t dropped, const unsigned char *drop, uint64_t first,
                  Moments &acc, Diagnostics &diag, bool higher, const std::optional<BlockScan> &scan);

}  // namespace re::blocks
