#include "estimator_blocks.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <vector>

namespace re::blocks {
namespace {

bool is_unit_box(const Domain &d) {
    if (d.kind != DomainKind::Box) return false;
    for (int j = 0; j < d.dim; ++j)
        if (d.lo[j] != 0.0 || d.hi[j] != 1.0) return false;
    return true;
}

// Whether importance sampling on the polar path draws the block's u0s inside the sampler's
// loop (Sampler::sample_polar_rows; an MIS pair: inside its fused loop, Kernel::fused), where
// it reads the evens alone (Kernel::evens) and the
// stream stands at a generator row with the block whole rows of it: the generator's
// multiplications then overlap the sampler's divisions, where drawing them first had added
// its time to theirs (GGX: 0.39 ns a sample of 2.44).
bool rows_drawn_in_sampler(const Kernel &k, UniformStream &stream, size_t m) {
    return k.evens && (k.t.kind != TechniqueKind::Mis || k.fused) && stream.row_aligned() &&
           (m * size_t(k.ud)) % LaneGenerator::kLanes == 0;
}

// Copies columns [from, from + count) of the m x ud matrix u into out (m x count).
// (the common widths by fixed-size copies: the generic double loop, its trip counts unknown,
// was a fifth of an MIS estimate's time)
void take_columns(const double *__restrict u, size_t m, int ud, int from, int count, double *__restrict out) {
    const double *src = u + from;
    if (count == 1) {
        for (size_t i = 0; i < m; ++i) out[i] = src[i * ud];
    } else if (count == 2 && ud == 4 && (from == 0 || from == 2)) {
        // an MIS pair of samplers reading two uniforms each where they are not drawn apart
        // (Kernel::pairs_split): Sobol' or stratified points, a polar pair's blocks handed back
        from == 0 ? simd::pair_columns<0>(u, m, out) : simd::pair_columns<2>(u, m, out);
    } else if (count == 2) {
        for (size_t i = 0; i < m; ++i) std::memcpy(out + 2 * i, src + i * ud, 2 * sizeof(double));
    } else {
        for (size_t i = 0; i < m; ++i)
            for (int j = 0; j < count; ++j) out[i * count + j] = src[i * ud + j];
    }
}

// Records the sampled points outside the sampler's domain and the pdf values NaN / Inf / <= 0
// in diag and marks them in `drop` (every entry set); returns the number marked.
size_t mark_invalid_samples(const Domain &dom, const double *x, const double *p, size_t m, uint64_t first,
                            Diagnostics &diag, unsigned char *drop) {
    const int d = dom.dim;
    size_t marked = 0;
    for (size_t i = 0; i < m; ++i) {
        const double *xi = x + i * d;
        drop[i] = 0;
        if (!dom.contains(xi)) diag.record(Issue::OutsideDomain, first + i, xi, d, p[i]);
        else if (p[i] == 0) diag.record(Issue::ZeroPdf, first + i, xi, d, p[i]);
        else if (!valid_pdf(p[i])) diag.record(Issue::BadPdf, first + i, xi, d, p[i]);
        else continue;
        drop[i] = 1;
        ++marked;
    }
    return marked;
}

// The sampler's points and pdfs for the uniforms u, checked as check_samples checks them, in
// the sampler's own pass where it has one (Sampler::sample_valid).
size_t sample_and_check(const Sampler &smp, const double *u, double *x, double *p, size_t m, uint64_t first,
                        Diagnostics &diag, unsigned char *drop) {
    if (smp.sample_valid(u, x, p, m)) return 0;
    return mark_invalid_samples(smp.domain, x, p, m, first, diag, drop);
}

// acc[i] += p[i]^beta: multiplications for the exponents the heuristics use (0, 1, 2; the
// balance heuristic's p^0 = 1 and p^1 = p are exact, as std::pow's are), std::pow otherwise
// (a scalar libm call: 12 Msamples/s for the balance heuristic before).
void add_power(const double *p, double beta, double *acc, size_t m) {
    if (beta == 0) {
        for (size_t i = 0; i < m; ++i) acc[i] += 1.0;
    } else if (beta == 1) {
        for (size_t i = 0; i < m; ++i) acc[i] += p[i];
    } else if (beta == 2) {
        for (size_t i = 0; i < m; ++i) acc[i] += p[i] * p[i];
    } else {
        for (size_t i = 0; i < m; ++i) acc[i] += std::pow(p[i], beta);
    }
}

// The sums of MIS technique a's block: s.w = sum_j p_j^beta at its points (p_a is s.p, the
// others' pdfs from other_pdf(sampler j, out), sampler `into_f`'s into s.f: f is that pdf) and,
// unless beta = 1, s.q = p_a^(beta - 1), so that w_a f / p_a = p_a^(beta - 1) f / sum_j p_j^beta
// (the balance heuristic's p_a^0 = 1 is left out: 1 * f is f, the same bits, a pass fewer).
template <class OtherPdf>
void mis_weights(const Technique &t, size_t a, Scratch &s, size_t m, OtherPdf other_pdf, int into_f = -1) {
    const double beta = t.mis_power;
    std::fill(s.w.begin(), s.w.begin() + m, 0.0);
    for (size_t b = 0; b < t.mis.size(); ++b) {
        double *q = int(b) == into_f ? s.f.data() : s.q.data();
        if (b != a) other_pdf(*t.mis[b], q);
        add_power(b == a ? s.p.data() : q, beta, s.w.data(), m);
    }
    if (beta != 1) {
        std::fill(s.q.begin(), s.q.begin() + m, 0.0);
        add_power(s.p.data(), beta - 1, s.q.data(), m);
    }
}

// y += w_a f / p_a for one MIS technique a: f / w (balance heuristic, w = sum_j p_j), else
// q f / w (q = p_a^(beta - 1), w = sum_j p_j^beta); 0 where f is 0.  In explicit vector lanes
// with a select (GCC kept the scalar loop, branching on f).
void add_mis_terms(bool balance, const double *f, Scratch &s, size_t m) {
    if (balance)
        simd::update(f, s.w.data(), s.y.data(), m, [](auto fv, auto w, auto y) {
            using V = decltype(fv);
            return y + (fv == V{} ? V{} : fv / w);
        });
    else
        simd::map4(s.q.data(), f, s.w.data(), s.y.data(), m, [](auto q, auto fv, auto w, auto y) {
            using V = decltype(q);
            return y + (fv == V{} ? V{} : q * fv / w);
        });
}

// y += w_a f / p_a for technique a of a pair (mis_pair) in one pass, from its pdf pa and the
// other's q at its points: f / ((0 + p_0) + p_1) (balance), (0 + p_a) f / ((0 + p_0^2) +
// p_1^2) (power), 0 where f is 0: mis_weights' and add_mis_terms' operations in their order
// (the same bits), where they took four to six passes over the block.  With `scan`, also
// scan_block of the new y, in the same pass (the last technique's).
std::optional<BlockScan> add_pair_terms(double beta, size_t a, const double *f, const double *pa, const double *q,
                                        double *y, size_t m, bool scan = false) {
    const double *p0 = a == 0 ? pa : q, *p1 = a == 0 ? q : pa;
    auto pass = [&](auto term) -> std::optional<BlockScan> {
        if (!scan) {
            simd::map4(f, p0, p1, y, m, term);
            return std::nullopt;
        }
        return scan_values(
            m,
            [&](size_t i) {
                const simd::f64v v = term(simd::load(f + i), simd::load(p0 + i), simd::load(p1 + i), simd::load(y + i));
                simd::store(y + i, v);
                return v;
            },
            [&](size_t i) { return y[i] = term(f[i], p0[i], p1[i], y[i]); });
    };
    if (beta == 1)
        return pass([](auto fx, auto q0, auto q1, auto acc) {
            using V = decltype(fx);
            return acc + (fx == V{} ? V{} : fx / ((V{} + q0) + q1));
        });
    return pass([a](auto fx, auto q0, auto q1, auto acc) {
        using V = decltype(fx);
        const V own = a == 0 ? q0 : q1;
        return acc + (fx == V{} ? V{} : (V{} + own) * fx / ((V{} + q0 * q0) + q1 * q1));
    });
}

// Whether a block's contributions s.y hold nothing to report: all finite and, unless f may be
// negative, none below 0 (screen_and_accumulate then notes no example, so needs no points).
// The scan (scan_block of s.y, unless given) is kept in s.scan for finish_block (a pass over
// the block fewer).
bool nothing_to_report(const Integrand &f, Scratch &s, size_t m, std::optional<BlockScan> scan = std::nullopt) {
    s.scan = scan ? *scan : scan_block(s.y.data(), m);
    return !s.scan->maybe_nonfinite() && !(f.nonnegative && s.scan->min < 0);
}

// Importance sampling on the polar path (Kernel::polar): z and the pdf from u0
// (Sampler::sample_polar: the general path's w2 and pdf, the same bits; `evens`: s.u holds
// the u0s alone, draw_uniforms; `rows`: the u0s are drawn from the generator inside the
// sampler's loop instead, Sampler::sample_polar_rows, rows_drawn_in_sampler), f from z
// (Integrand::eval_polar; the pdf itself where f is the sampler's pdf: Kernel::f_is_pdf),
// y = f / p; up to the stage `last`.  False for a block with something to report (a point or
// pdf the screening fails, a contribution not finite or negative): the caller redoes it on
// the general path from the same uniforms, whose examples name whole points.
bool polar_importance(const Kernel &k, bool evens, size_t m, Scratch &s, Stage last, LaneGenerator *rows) {
    const Sampler &smp = *k.t.sampler;
    const size_t bad = rows ? smp.sample_polar_rows(*rows, m / LaneGenerator::kEvensPerRow, s.q.data(), s.p.data())
                            : smp.sample_polar(s.u.data(), evens ? 1 : smp.udim, s.q.data(), s.p.data(), m);
    if (bad != 0) return false;
    if (last < Stage::Contributions) return true;
    const double *fv = s.p.data();
    if (k.f_is_pdf != 0) {
        k.f.eval_polar(s.q.data(), s.f.data(), m);
        fv = s.f.data();
    }
    return nothing_to_report(k.f, s, m, divide_and_scan(fv, s.p.data(), s.y.data(), m));
}

// MIS on the polar path (Kernel::polar), as the general path below computes it (the same
// order of operations, the same bits) with directions' z alone: each technique's z and pdf
// from its u0 (Sampler::sample_polar; `evens`: s.u holds the u0s alone, draw_uniforms), the
// others' pdfs at z (Sampler::pdf_polar), f at z (the pdf of sampler Kernel::f_is_pdf where
// f is one, computed once; a pair of techniques: add_pair_terms).  With `rows`, the pair's
// fused loop (Kernel::fused) draws the u0s from the generator instead (rows_drawn_in_sampler)
// and computes the same.  False for a block with something to report, as polar_importance.
bool polar_mis(const Kernel &k, bool evens, size_t m, Scratch &s, Stage last, LaneGenerator *rows) {
    const Integrand &f = k.f;
    const Technique &t = k.t;
    if (rows) {
        const size_t count = m * size_t(k.ud) / LaneGenerator::kLanes;
        BlockScan scan;
        const size_t bad = k.fused(*t.mis[0], *t.mis[1], last, *rows, count, s.y.data(), s.p.data(), s.q.data(), scan);
        rows->skip_odd(count);
        return bad == 0 && (last < Stage::Contributions || nothing_to_report(f, s, m, scan));
    }
    const int ud = k.ud;
    const bool pair = mis_pair(t);
    double *z = s.x.data();
    std::fill(s.y.begin(), s.y.begin() + m, 0.0);
    std::optional<BlockScan> scan;   // of y, by the last technique's pass (add_pair_terms)
    int col = 0;
    for (size_t a = 0; a < t.mis.size(); ++a) {
        const Sampler &sa = *t.mis[a];
        if (sa.sample_polar(s.u.data() + (evens ? col / 2 : col), size_t(evens ? ud / 2 : ud), z, s.p.data(), m) != 0)
            return false;
        col += sa.udim;
        if (last <= Stage::Screened) continue;
        const double *fv = k.f_is_pdf == int(a) ? s.p.data() : s.f.data();
        if (pair) {
            // the other technique's pdf, into s.f where it is f
            const size_t b = 1 - a;
            double *q = k.f_is_pdf == int(b) ? s.f.data() : s.q.data();
            t.mis[b]->pdf_polar(z, q, m);
            if (last == Stage::Weighted) continue;
            if (k.f_is_pdf < 0) f.eval_polar(z, s.f.data(), m);
            scan = add_pair_terms(t.mis_power, a, fv, s.p.data(), q, s.y.data(), m, a == 1);
            continue;
        }
        mis_weights(t, a, s, m, [&](const Sampler &sb, double *q) { sb.pdf_polar(z, q, m); }, k.f_is_pdf);
        if (last == Stage::Weighted) continue;
        if (k.f_is_pdf < 0) f.eval_polar(z, s.f.data(), m);   // else s.f holds it (mis_weights), or s.p
        add_mis_terms(t.mis_power == 1, fv, s, m);
    }
    return last < Stage::Contributions || nothing_to_report(f, s, m, scan);
}

}  // namespace

size_t check_samples(const Domain &dom, const double *x, const double *p, size_t m, uint64_t first,
                     Diagnostics &diag, unsigned char *drop) {
    if (all_valid(dom, x, p, m)) return 0;
    return mark_invalid_samples(dom, x, p, m, first, diag, drop);
}

size_t block_contributions(const Kernel &k, UniformStream &stream, size_t m, uint64_t first, Scratch &s,
                           Diagnostics &diag, Stage last) {
    const Integrand &f = k.f;
    const Technique &t = k.t;
    const Sampler &smp = *t.sampler;
    const int xd = k.xd, ud = k.ud;
    const bool rejection = smp.method == SamplingMethod::Rejection;
    // where the polar path hands the block back, the general path needs all of its uniforms
    const bool in_sampler = !rejection && rows_drawn_in_sampler(k, stream, m);
    diag.inside_blocks += in_sampler;
    const std::optional<LaneGenerator> replay =
        rejection ? std::nullopt
                  : in_sampler ? std::optional<LaneGenerator>(stream.position())
                               : draw_uniforms(k, stream, first, m, s.u.data());
    const bool evens = replay.has_value();
    auto all_uniforms = [&] {
        if (!evens) return;
        stream.rewind(*replay);
        fill_points(k.points, stream, first, m, ud, s.u.data());
    };
    s.points = s.x.data();
    s.scan.reset();
    size_t dropped = 0;
    diag.candidates += m;

    switch (t.kind) {
    case TechniqueKind::Uniform:
        if (f.domain.kind == DomainKind::Box) {
            // Eq. 3: Y = |D| f(X), X uniform on the box.  On [0,1]^d the map and the factor
            // |D| = 1 are identities and skipped (bitwise the same result).
            const bool unit = is_unit_box(f.domain);
            const double vol = f.domain.measure();
            double *x = unit ? s.u.data() : s.x.data();
            if (!unit)
                for (size_t i = 0; i < m; ++i)
                    for (int j = 0; j < xd; ++j)
                        s.x[i * xd + j] = f.domain.lo[j] + (f.domain.hi[j] - f.domain.lo[j]) * s.u[i * xd + j];
            f.eval(x, unit ? s.y.data() : s.f.data(), m);
            if (!unit)
                for (size_t i = 0; i < m; ++i) s.y[i] = vol * s.f[i];
            s.points = x;
            break;
        }
        [[fallthrough]];  // uniform on the sphere or hemisphere: f / (1 / |D|) with its sampler
    case TechniqueKind::Importance:
        // Eq. 4: Y = f(X) / p(X).
        if (rejection) {
            diag.candidates -= m;
            smp.draw(stream, s.x.data(), s.p.data(), m, first, diag);
            if (last == Stage::Sampled) return 0;
            dropped = check_samples(smp.domain, s.x.data(), s.p.data(), m, first, diag, s.drop.data());
        } else if (k.polar && polar_importance(k, evens, m, s, last, in_sampler ? &stream.rows() : nullptr)) {
            if (last < Stage::Contributions) return 0;
            break;
        } else {
            diag.redone_blocks += k.polar;
            all_uniforms();
            if (last == Stage::Sampled) {  // the profile's prefix: the points alone, unchecked
                smp.sample(s.u.data(), s.x.data(), s.p.data(), m);
                return 0;
            }
            dropped = sample_and_check(smp, s.u.data(), s.x.data(), s.p.data(), m, first, diag, s.drop.data());
        }
        if (last < Stage::Contributions) return dropped;
        f.eval(s.x.data(), s.f.data(), m);
        for (size_t i = 0; i < m; ++i) s.y[i] = s.f[i] / s.p[i];
        break;
    case TechniqueKind::HitOrMiss: {
        // Y = c 1{xi c p(X) < f(X)}; a point with f > c p breaks the method and is reported.
        const int sd = smp.udim;
        take_columns(s.u.data(), m, ud, 0, sd, s.cols.data());
        take_columns(s.u.data(), m, ud, sd, 1, s.xi.data());
        dropped = sample_and_check(smp, s.cols.data(), s.x.data(), s.p.data(), m, first, diag, s.drop.data());
        f.eval(s.x.data(), s.f.data(), m);
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
        break;
    }
    case TechniqueKind::RussianRoulette: {
        // Only survivors (xi < q) are sampled and evaluated: that is where roulette saves time.
        const int sd = smp.udim;
        const double q = t.rr_q, c = t.rr_c;
        take_columns(s.u.data(), m, ud, sd, 1, s.xi.data());
        s.live.clear();
        for (size_t i = 0; i < m; ++i) {
            s.drop[i] = 0;
            if (s.xi[i] < q) {
                for (int j = 0; j < sd; ++j) s.cols[s.live.size() * sd + j] = s.u[i * ud + j];
                s.live.push_back(i);
            } else {
                s.y[i] = c;
                for (int j = 0; j < xd; ++j) s.x[i * xd + j] = std::nan("");  // no point drawn
            }
        }
        const size_t L = s.live.size();
        double *lx = s.x.data() + m * xd;  // survivors' points, after the block's
        size_t bad = sample_and_check(smp, s.cols.data(), lx, s.p.data(), L, first, diag, s.sub_drop.data());
        f.eval(lx, s.f.data(), L);
        for (size_t a = 0; a < L; ++a) {
            size_t i = s.live[a];
            double y = s.f[a] / s.p[a];
            s.y[i] = t.reweight ? (y - (1 - q) * c) / q : y;
            for (int j = 0; j < xd; ++j) s.x[i * xd + j] = lx[a * xd + j];
            if (bad && s.sub_drop[a]) { s.drop[i] = 1; ++dropped; }
        }
        break;
    }
    case TechniqueKind::Splitting: {
        // x0 from u[:, 0]; x1_j from u[:, 1 + j]; Y = |D| mean_j f(x0, x1_j).
        const int M = t.split;
        const double a0 = f.domain.lo[0], w0 = f.domain.hi[0] - a0, a1 = f.domain.lo[1], w1 = f.domain.hi[1] - a1;
        const double vol = f.domain.measure();
        for (size_t i = 0; i < m; ++i)
            for (int j = 0; j < M; ++j) {
                double *pt = &s.x[(i * M + j) * 2];
                pt[0] = a0 + w0 * s.u[i * ud];
                pt[1] = a1 + w1 * s.u[i * ud + 1 + j];
            }
        f.eval(s.x.data(), s.f.data(), m * M);
        for (size_t i = 0; i < m; ++i) {
            double sum = 0;
            for (int j = 0; j < M; ++j) sum += s.f[i * M + j];
            s.y[i] = vol * sum / M;
            s.x[i * 2] = s.x[i * M * 2];            // the outer point stands for the sample
            s.x[i * 2 + 1] = s.x[i * M * 2 + 1];
        }
        break;
    }
    case TechniqueKind::Mis: {
        // One sample from each technique i; w_i = p_i^beta / sum_j p_j^beta at X_i.
        if (k.polar && polar_mis(k, evens, m, s, last, in_sampler ? &stream.rows() : nullptr)) {
            if (last < Stage::Contributions) return 0;
            break;
        }
        diag.redone_blocks += k.polar;
        all_uniforms();
        std::fill(s.y.begin(), s.y.begin() + m, 0.0);
        std::fill(s.drop.begin(), s.drop.begin() + m, 0);
        int col = 0;
        for (size_t a = 0; a < t.mis.size(); ++a) {
            const Sampler &sa = *t.mis[a];
            // the first technique's points stand for the sample (examples name them): drawn
            // straight into the block's points, the others' after them
            double *xi_pts = s.x.data() + (a == 0 ? 0 : m * xd);
            const double *ua = s.cols.data();
            if (k.pairs_split)
                ua = s.u.data() + 2 * m * a;   // drawn apart
            else
                take_columns(s.u.data(), m, ud, col, sa.udim, s.cols.data());
            col += sa.udim;
            if (last == Stage::Sampled) {  // the profile's prefix: the points alone, unchecked
                sa.sample(ua, xi_pts, s.p.data(), m);
                continue;
            }
            size_t bad = sample_and_check(sa, ua, xi_pts, s.p.data(), m, first, diag, s.sub_drop.data());
            if (last == Stage::Screened) continue;
            if (mis_pair(t)) {
                t.mis[1 - a]->pdf(xi_pts, s.q.data(), m);
                if (last == Stage::Weighted) continue;
                f.eval(xi_pts, s.f.data(), m);
                add_pair_terms(t.mis_power, a, s.f.data(), s.p.data(), s.q.data(), s.y.data(), m);
            } else {
                mis_weights(t, a, s, m, [&](const Sampler &sb, double *q) { sb.pdf(xi_pts, q, m); });
                if (last == Stage::Weighted) continue;
                f.eval(xi_pts, s.f.data(), m);
                add_mis_terms(t.mis_power == 1, s.f.data(), s, m);
            }
            if (bad)
                for (size_t i = 0; i < m; ++i)
                    if (s.sub_drop[i] && !s.drop[i]) { s.drop[i] = 1; ++dropped; }
        }
        break;
    }
    case TechniqueKind::SelfNormalized: {
        // Y = |D| sum_b f/p / sum_b 1{X in D}/p over the batch.
        const int B = t.batch;
        const double vol = f.domain.measure();
        std::fill(s.drop.begin(), s.drop.begin() + m, 0);
        size_t bad = sample_and_check(smp, s.u.data(), s.x.data(), s.p.data(), m * B, first * B, diag,
                                      s.sub_drop.data());
        f.eval(s.x.data(), s.f.data(), m * B);
        for (size_t i = 0; i < m; ++i) {
            double num = 0, den = 0;
            for (int b = 0; b < B; ++b) {
                size_t r = i * B + b;
                num += s.f[r] / s.p[r];
                den += f.domain.contains(&s.x[r * xd]) ? 1.0 / s.p[r] : 0.0;
                if (bad && s.sub_drop[r] && !s.drop[i]) { s.drop[i] = 1; ++dropped; }
            }
            s.y[i] = vol * num / den;
            for (int j = 0; j < xd && B > 1; ++j) s.x[i * xd + j] = s.x[i * B * xd + j];  // batch's first point
        }
        break;
    }
    }
    if (t.clamp < std::numeric_limits<double>::infinity()) {
        for (size_t i = 0; i < m; ++i) s.y[i] = std::min(s.y[i], t.clamp);
        s.scan.reset();
    }
    return dropped;
}

void finish_block(double *y, double *x, int xd, size_t m, size_t dropped, const unsigned char *drop, uint64_t first,
                  Moments &acc, Diagnostics &diag, bool higher, const std::optional<BlockScan> &scan) {
    if (!dropped) {
        screen_and_accumulate(acc, diag, y, x, xd, m, first, higher, nullptr, scan ? &*scan : nullptr);
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

}  // namespace re::blocks
