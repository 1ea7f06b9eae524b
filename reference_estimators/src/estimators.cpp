#include "estimators.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

#include "thread_pool.h"

namespace re {
namespace {

constexpr size_t kBlock = 2048;  // samples per block: u and y (16 KiB each) stay in L1
constexpr double kMax = std::numeric_limits<double>::max();

uint64_t chunk_count(uint64_t n) { return (n + kChunkSize - 1) / kChunkSize; }

int resolve_threads(int threads) { return threads > 0 ? threads : ThreadPool::default_threads(); }

StreamKey chunk_key(StreamKey k, uint64_t c) {
    k.chunk = c;
    return k;
}

// Calls fn(offset, m) for consecutive blocks of at most kBlock samples covering [0, count).
template <class Fn>
void for_each_block(uint64_t count, Fn fn) {
    for (uint64_t b = 0; b < count; b += kBlock) fn(b, size_t(std::min<uint64_t>(kBlock, count - b)));
}

bool is_unit_box(const Domain &d) {
    if (d.kind != DomainKind::Box) return false;
    for (int j = 0; j < d.dim; ++j)
        if (d.lo[j] != 0.0 || d.hi[j] != 1.0) return false;
    return true;
}

// Reusable per-block buffers of one chunk.
struct Scratch {
    std::vector<double> u, x, p, f, y, xi;
    std::vector<unsigned char> drop;
    double *points = nullptr;  // where this block's points are (x, or u on the unit box)
    explicit Scratch(int udim, int xdim)
        : u(kBlock * size_t(udim)), x(kBlock * size_t(xdim)), p(kBlock), f(kBlock), y(kBlock), xi(kBlock), drop(kBlock) {}
};

// Checks sampled points against the sampler's domain and pdf values for NaN / Inf / <= 0;
// records what fails and marks it in `drop`.  Returns the number marked.
size_t check_samples(const Domain &dom, const double *x, const double *p, size_t m, uint64_t first,
                     Diagnostics &diag, unsigned char *drop) {
    size_t badp = 0;
    for (size_t i = 0; i < m; ++i) badp += !(p[i] > 0 && p[i] <= kMax);
    size_t outside = 0;
    const int d = dom.dim;
    for (size_t i = 0; i < m; ++i) outside += !dom.contains(x + i * d);
    if (badp == 0 && outside == 0) return 0;
    size_t marked = 0;
    for (size_t i = 0; i < m; ++i) {
        const double *xi = x + i * d;
        drop[i] = 0;
        if (!dom.contains(xi)) diag.record(Issue::OutsideDomain, first + i, xi, d, p[i]);
        else if (p[i] == 0) diag.record(Issue::ZeroPdf, first + i, xi, d, p[i]);
        else if (!(p[i] > 0 && p[i] <= kMax)) diag.record(Issue::BadPdf, first + i, xi, d, p[i]);
        else continue;
        drop[i] = 1;
        ++marked;
    }
    return marked;
}

// Fills s.y[0..m) with the contributions of samples first..first+m of this chunk; samples
// the estimator cannot use are recorded in diag and flagged in s.drop (returns their count).
size_t block_contributions(const Integrand &f, const Technique &t, UniformStream &stream, size_t m, uint64_t first,
                           Scratch &s, Diagnostics &diag) {
    const Sampler &smp = *t.sampler;
    const int xd = f.domain.dim;
    size_t dropped = 0;
    if (t.kind == TechniqueKind::Uniform && f.domain.kind == DomainKind::Box) {
        // Eq. 3: Y = |D| f(X), X uniform on the box.  On [0,1]^d the map and the factor
        // |D| = 1 are identities and skipped (bitwise the same result).
        const bool unit = is_unit_box(f.domain);
        const double vol = f.domain.measure();
        double *x = unit ? s.u.data() : s.x.data();
        stream.fill(s.u.data(), m * xd);
        if (!unit)
            for (size_t i = 0; i < m; ++i)
                for (int j = 0; j < xd; ++j)
                    s.x[i * xd + j] = f.domain.lo[j] + (f.domain.hi[j] - f.domain.lo[j]) * s.u[i * xd + j];
        f.eval(x, unit ? s.y.data() : s.f.data(), m);
        if (!unit)
            for (size_t i = 0; i < m; ++i) s.y[i] = vol * s.f[i];
        s.points = x;
        diag.candidates += m;
        return 0;
    }
    s.points = s.x.data();
    smp.draw(stream, s.x.data(), s.p.data(), m, first, diag);
    dropped = check_samples(smp.domain, s.x.data(), s.p.data(), m, first, diag, s.drop.data());
    f.eval(s.x.data(), s.f.data(), m);
    if (t.kind == TechniqueKind::HitOrMiss) {
        // Y = c 1{xi c p(X) < f(X)}; a point with f > c p breaks the method and is reported.
        stream.fill(s.xi.data(), m);
        const double c = t.bound;
        size_t viol = 0;
        for (size_t i = 0; i < m; ++i) {
            double bound = c * s.p[i];
            viol += s.f[i] > bound;
            s.y[i] = s.xi[i] * bound < s.f[i] ? c : 0.0;
        }
        if (viol)
            for (size_t i = 0; i < m; ++i)
                if (s.f[i] > c * s.p[i])
                    diag.record(Issue::BoundViolation, first + i, &s.x[i * xd], xd, s.f[i] / (c * s.p[i]));
    } else {
        // Eq. 4: Y = f(X) / p(X).
        for (size_t i = 0; i < m; ++i) s.y[i] = s.f[i] / s.p[i];
    }
    return dropped;
}

template <class ChunkFn>
Estimate run_chunks(uint64_t n, const RunOptions &opt, ChunkFn chunk_fn) {
    auto t0 = std::chrono::steady_clock::now();
    const uint64_t nc = chunk_count(n);
    std::vector<Moments> moments(nc);
    std::vector<Diagnostics> diags(nc);
    const int threads = resolve_threads(opt.threads);
    ThreadPool::instance().run(nc, threads, [&](size_t c) {
        uint64_t first = c * kChunkSize, count = std::min(kChunkSize, n - first);
        chunk_fn(c, first, count, moments[c], diags[c]);
    });
    Estimate e;
    for (uint64_t c = 0; c < nc; ++c) {
        e.moments.merge(moments[c]);
        e.diagnostics.merge(diags[c]);
    }
    e.chunks = nc;
    e.threads = threads;
    e.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return e;
}

// Screens and accumulates one block, first dropping the samples marked in `drop` (already
// recorded as outside the domain or with a bad pdf); the kept ones remember their sample
// indices, so later examples in the block still name the right sample.
void finish_block(double *y, double *x, int xd, size_t m, size_t dropped, const unsigned char *drop, uint64_t first,
                  Moments &acc, Diagnostics &diag, bool higher) {
    if (!dropped) {
        screen_and_accumulate(acc, diag, y, x, xd, m, first, higher);
        return;
    }
    std::vector<uint64_t> index;
    index.reserve(m);
    size_t k = 0;
    for (size_t i = 0; i < m; ++i) {
        if (drop[i]) continue;
        y[k] = y[i];
        for (int j = 0; j < xd; ++j) x[k * xd + j] = x[i * xd + j];
        index.push_back(first + i);
        ++k;
    }
    screen_and_accumulate(acc, diag, y, x, xd, k, first, higher, index.data());
}

}  // namespace

Estimate integrate(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt) {
    const int xd = f.domain.dim;
    return run_chunks(n, opt, [&](uint64_t c, uint64_t first, uint64_t count, Moments &acc, Diagnostics &diag) {
        UniformStream stream(chunk_key(opt.key, c));
        Scratch s(std::max(t.sampler->udim, xd), xd);
        for_each_block(count, [&](uint64_t b, size_t m) {
            size_t dropped = block_contributions(f, t, stream, m, first + b, s, diag);
            diag.drawn += m;
            finish_block(s.y.data(), s.points, xd, m, dropped, s.drop.data(), first + b, acc, diag, opt.higher_moments);
        });
    });
}

void contributions(const Integrand &f, const Technique &t, uint64_t n, const RunOptions &opt, double *out) {
    const int xd = f.domain.dim;
    const uint64_t nc = chunk_count(n);
    ThreadPool::instance().run(nc, resolve_threads(opt.threads), [&](size_t c) {
        UniformStream stream(chunk_key(opt.key, c));
        Scratch s(std::max(t.sampler->udim, xd), xd);
        Diagnostics diag;
        uint64_t first = c * kChunkSize, count = std::min(kChunkSize, n - first);
        for_each_block(count, [&](uint64_t b, size_t m) {
            size_t dropped = block_contributions(f, t, stream, m, first + b, s, diag);
            for (size_t i = 0; i < m; ++i) out[first + b + i] = dropped && s.drop[i] ? std::nan("") : s.y[i];
        });
    });
}

Estimate accumulate_values(const double *y, uint64_t n, const RunOptions &opt) {
    return run_chunks(n, opt, [&](uint64_t, uint64_t first, uint64_t count, Moments &acc, Diagnostics &diag) {
        std::vector<double> buf(kBlock);
        for_each_block(count, [&](uint64_t b, size_t m) {
            std::copy(y + first + b, y + first + b + m, buf.begin());
            diag.drawn += m;
            screen_and_accumulate(acc, diag, buf.data(), nullptr, 0, m, first + b, opt.higher_moments);
        });
    });
}

Estimate estimate_from_samples(const Integrand &f, const double *x, const double *pdf, uint64_t n,
                               const Domain &sampler_domain, const RunOptions &opt) {
    const int xd = f.domain.dim;
    if (sampler_domain.dim != xd) throw std::invalid_argument("sampler domain and integrand differ in dimension");
    return run_chunks(n, opt, [&](uint64_t, uint64_t first, uint64_t count, Moments &acc, Diagnostics &diag) {
        Scratch s(1, xd);
        for_each_block(count, [&](uint64_t b, size_t m) {
            const double *xb = x + (first + b) * xd, *pb = pdf + first + b;
            std::copy(xb, xb + m * xd, s.x.begin());
            std::copy(pb, pb + m, s.p.begin());
            diag.drawn += m;
            size_t dropped = check_samples(sampler_domain, s.x.data(), s.p.data(), m, first + b, diag, s.drop.data());
            f.eval(s.x.data(), s.f.data(), m);
            for (size_t i = 0; i < m; ++i) s.y[i] = s.f[i] / s.p[i];
            finish_block(s.y.data(), s.x.data(), xd, m, dropped, s.drop.data(), first + b, acc, diag, opt.higher_moments);
        });
    });
}

Diagnostics draw_samples(const Sampler &smp, uint64_t n, const RunOptions &opt, double *x, double *pdf) {
    const uint64_t nc = chunk_count(n);
    const int xd = smp.domain.dim;
    std::vector<Diagnostics> diags(nc);
    ThreadPool::instance().run(nc, resolve_threads(opt.threads), [&](size_t c) {
        UniformStream stream(chunk_key(opt.key, c));
        uint64_t first = c * kChunkSize, count = std::min(kChunkSize, n - first);
        smp.draw(stream, x + first * xd, pdf + first, count, first, diags[c]);
        diags[c].drawn += count;
    });
    Diagnostics all;
    for (auto &d : diags) all.merge(d);
    return all;
}

}  // namespace re
