#include "estimators.h"

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <vector>

#include "estimator_blocks.h"
#include "thread_pool.h"

namespace re {
using namespace blocks;

namespace {

// Per-thread scratch, built on a worker's first chunk and reused by its later ones.
template <class T>
class PerWorker {
  public:
    explicit PerWorker(int threads) : items_(size_t(threads)) {}
    template <class Make>
    T &get(int worker, Make make) {
        auto &p = items_[size_t(worker)];
        if (!p) p = std::make_unique<T>(make());
        return *p;
    }
  private:
    std::vector<std::unique_ptr<T>> items_;
};

// chunk_fn(c, first, count, moments, diagnostics, worker) for each chunk c of the range.
template <class ChunkFn>
Estimate run_chunks(uint64_t n, const RunOptions &opt, ChunkFn chunk_fn) {
    auto t0 = std::chrono::steady_clock::now();
    const uint64_t total = chunk_count(n);
    const uint64_t c0 = std::min(opt.chunk_begin, total), c1 = std::min(opt.chunk_end, total);
    const uint64_t nc = c1 > c0 ? c1 - c0 : 0;
    std::vector<Moments> moments(nc);
    std::vector<Diagnostics> diags(nc);
    const int threads = resolve_threads(opt.threads);
    Estimate e;
    e.busy = ThreadPool::instance().run(nc, threads, [&](size_t i, int worker) {
        uint64_t c = c0 + i, first = c * kChunkSize, count = std::min(kChunkSize, n - first);
        chunk_fn(c, first, count, moments[i], diags[i], worker);
    });
    for (uint64_t i = 0; i < nc; ++i) {
        e.moments.merge(moments[i]);
        e.diagnostics.merge(diags[i]);
    }
    e.chunks = nc;
    e.threads = threads;
    e.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return e;
}

}  // namespace

Estimate integrate(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt) {
    check_technique(f, t);
    const Kernel k(f, t, n, opt.key);
    const int threads = resolve_threads(opt.threads);
    PerWorker<Scratch> scratch(threads);
    // The tails: each chunk's finite contributions fed to its own collector, merged in chunk
    // order afterwards (the same bits on any thread count); the first chunk's values kept for
    // its median when asked for.
    const bool tails = opt.tail_keep > 0;
    const uint64_t c0 = std::min(opt.chunk_begin, chunk_count(n)), c1 = std::min(opt.chunk_end, chunk_count(n));
    std::vector<ValueTails> chunk_tails(tails && c1 > c0 ? c1 - c0 : 0);
    std::vector<double> first_chunk;
    Estimate e = run_chunks(n, opt, [&](uint64_t c, uint64_t first, uint64_t count, Moments &acc, Diagnostics &diag,
                                        int w) {
        UniformStream stream(chunk_key(opt.key, c));
        Scratch &s = scratch.get(w, [&] { return k.scratch(); });
        std::optional<TailCollector> collector;
        if (tails) collector.emplace(opt.tail_keep);
        const bool median = tails && opt.tail_median && c == c0;
        for_each_block(count, [&](uint64_t b, size_t m) {
            size_t dropped = block_contributions(k, stream, m, first + b, s, diag);
            diag.drawn += m;
            if (collector) collector->feed(s.y.data(), m, dropped ? s.drop.data() : nullptr);
            if (median)
                for (size_t i = 0; i < m; ++i) first_chunk.push_back(dropped && s.drop[i] ? std::nan("") : s.y[i]);
            finish_block(s.y.data(), s.points, k.xd, m, dropped, s.drop.data(), first + b, acc, diag, opt.higher_moments,
                         s.scan);
        });
        if (collector) chunk_tails[c - c0] = collector->finish();
    });
    if (!chunk_tails.empty() && opt.tail_median) chunk_tails[0].median = upper_median(first_chunk.data(), first_chunk.size());
    if (tails) e.tails = merge_tails(chunk_tails, opt.tail_keep);
    e.kernel = k.path(e.diagnostics.inside_blocks > 0);
    return e;
}

// fn(stream, scratch, diag, first, m) for every block of every chunk of an n-sample estimate
// by kernel k, chunks on the pool (each worker with its own scratch, each chunk its stream and
// diagnostics), for the callers that keep no accumulator state.
template <class BlockFn>
void for_each_kernel_block(const Kernel &k, uint64_t n, const RunOptions &opt, BlockFn fn) {
    const int threads = resolve_threads(opt.threads);
    PerWorker<Scratch> scratch(threads);
    ThreadPool::instance().run(chunk_count(n), threads, [&](size_t c, int w) {
        UniformStream stream(chunk_key(opt.key, c));
        Scratch &s = scratch.get(w, [&] { return k.scratch(); });
        Diagnostics diag;
        uint64_t first = c * kChunkSize, count = std::min(kChunkSize, n - first);
        for_each_block(count, [&](uint64_t b, size_t m) { fn(stream, s, diag, c, first + b, m); });
    });
}

StageTimes profile_stages(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt) {
    check_technique(f, t);
    const Kernel k(f, t, n, opt.key);
    const bool rejection = t.sampler->method == SamplingMethod::Rejection;
    const bool mis = t.kind == TechniqueKind::Mis;
    const bool samples = mis || t.kind == TechniqueKind::Importance ||
                         (t.kind == TechniqueKind::Uniform && f.domain.kind != DomainKind::Box);
    // One pass stopping after the points, or after the stage `last` of the contributions; each
    // chunk keeps one of its values (sink), so nothing computed can be optimised away.
    auto pass = [&](std::optional<Stage> last) {
        std::vector<double> sink(chunk_count(n), 0.0);
        auto t0 = std::chrono::steady_clock::now();
        for_each_kernel_block(k, n, opt, [&](UniformStream &stream, Scratch &s, Diagnostics &diag, size_t c,
                                             uint64_t first, size_t m) {
            if (last) {
                block_contributions(k, stream, m, first, s, diag, *last);
                sink[c] += *last == Stage::Contributions ? s.y[m - 1] : s.p[m - 1];
            } else if (!rejection) {  // the uniforms the block reads
                const bool evens = draw_uniforms(k, stream, first, m, s.u.data()).has_value();
                sink[c] += s.u[m * size_t(k.ud) / (evens ? 2 : 1) - 1];
            }
        });
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    StageTimes r;
    r.points = rejection ? 0.0 : pass(std::nullopt);
    if (samples) {
        r.sampled = pass(Stage::Sampled);
        r.screened = pass(Stage::Screened);
        if (mis) r.weighted = pass(Stage::Weighted);
    }
    r.contributions = pass(Stage::Contributions);
    r.estimate = integrate(f, t, n, opt);
    return r;
}

void contributions(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt, double *out) {
    check_technique(f, t);
    const Kernel k(f, t, n, opt.key);
    for_each_kernel_block(k, n, opt, [&](UniformStream &stream, Scratch &s, Diagnostics &diag, size_t,
                                         uint64_t first, size_t m) {
        size_t dropped = block_contributions(k, stream, m, first, s, diag);
        for (size_t i = 0; i < m; ++i) out[first + i] = dropped && s.drop[i] ? std::nan("") : s.y[i];
    });
}

Estimate accumulate_values(const double *y, uint64_t n, const RunOptions &opt) {
    PerWorker<std::vector<double>> buffers(resolve_threads(opt.threads));
    return run_chunks(n, opt, [&](uint64_t, uint64_t first, uint64_t count, Moments &acc, Diagnostics &diag, int w) {
        std::vector<double> &buf = buffers.get(w, [] { return std::vector<double>(kBlock); });
        for_each_block(count, [&](uint64_t b, size_t m) {
            std::copy(y + first + b, y + first + b + m, buf.begin());
            diag.drawn += m;
            screen_and_accumulate(acc, diag, buf.data(), nullptr, 0, m, first + b, opt.higher_moments);
        });
    });
}

Estimate accumulate_chunk(const double *y, uint64_t count, uint64_t first, const double *u, int ud) {
    Estimate e;
    std::vector<double> buf(kBlock);
    for_each_block(count, [&](uint64_t b, size_t m) {
        std::copy(y + b, y + b + m, buf.begin());
        e.diagnostics.drawn += m;
        screen_and_accumulate(e.moments, e.diagnostics, buf.data(), u ? u + b * ud : nullptr, ud, m, first + b, true);
    });
    e.chunks = 1;
    e.threads = 1;
    return e;
}

Estimate estimate_from_samples(const Integrand &f, const double *x, const double *pdf, uint64_t n,
                               const Domain &sampler_domain, const RunOptions &opt) {
    const int xd = f.domain.dim;
    if (sampler_domain.dim != xd) throw std::invalid_argument("sampler domain and integrand differ in dimension");
    PerWorker<Scratch> scratch(resolve_threads(opt.threads));
    return run_chunks(n, opt, [&](uint64_t, uint64_t first, uint64_t count, Moments &acc, Diagnostics &diag, int w) {
        Scratch &s = scratch.get(w, [&] { return Scratch(1, xd, 1); });
        for_each_block(count, [&](uint64_t b, size_t m) {
            const double *xb = x + (first + b) * xd, *pb = pdf + first + b;
            std::copy(xb, xb + m * xd, s.x.begin());
            std::copy(pb, pb + m, s.p.begin());
            diag.drawn += m;
            size_t dropped = check_samples(sampler_domain, s.x.data(), s.p.data(), m, first + b, diag, s.drop.data());
            f.eval(s.x.data(), s.f.data(), m);
            for (size_t i = 0; i < m; ++i) s.y[i] = s.f[i] / s.p[i];
            finish_block(s.y.data(), s.x.data(), xd, m, dropped, s.drop.data(), first + b, acc, diag, opt.higher_moments,
                         std::nullopt);
        });
    });
}

Diagnostics draw_samples(const Sampler &smp, uint64_t n, const RunOptions &opt, double *x, double *pdf) {
    const uint64_t nc = chunk_count(n);
    const int xd = smp.domain.dim;
    std::vector<Diagnostics> diags(nc);
    ThreadPool::instance().run(nc, resolve_threads(opt.threads), [&](size_t c, int) {
        UniformStream stream(chunk_key(opt.key, c));
        uint64_t first = c * kChunkSize, count = std::min(kChunkSize, n - first);
        smp.draw(stream, x + first * xd, pdf + first, count, first, diags[c]);
        diags[c].drawn += count;
    });
    Diagnostics all;
    for (auto &d : diags) all.merge(d);
    return all;
}

Estimate merge_estimates(const std::vector<Estimate> &parts) {
    Estimate e;
    for (const Estimate &p : parts) {
        e.moments.merge(p.moments);
        e.diagnostics.merge(p.diagnostics);
        e.seconds += p.seconds;
        e.chunks += p.chunks;
        e.threads = std::max(e.threads, p.threads);
        if (e.kernel.empty()) e.kernel = p.kernel;
        if (e.busy.size() < p.busy.size()) e.busy.resize(p.busy.size(), 0.0);
        for (size_t w = 0; w < p.busy.size(); ++w) e.busy[w] += p.busy[w];
    }
    return e;
}

}  // namespace re
