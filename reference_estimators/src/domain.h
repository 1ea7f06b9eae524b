// Integration domains: where points live and what measure pdfs are densities against.
#pragma once
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "simd.h"

namespace re {

enum class DomainKind { Box, HalfLine, Hemisphere, Sphere };

// Membership of directions: unit length to 1e-5 in |w|^2 (float32 renderers hand over unit
// vectors with |w|^2 - 1 of order 1e-7), and z >= 0 for the hemisphere.  Free functions,
// branch-free, so that the direction samplers' pdf loops vectorise (Domain::contains switches
// on the kind at run time).
// on_sphere for double or simd::f64v coordinates (a bool, or a lane mask).
constexpr double kUnitTolerance = 1e-5;   // on |w|^2 - 1
template <class V>
RE_INLINE auto on_sphere_v(V w0, V w1, V w2) {
    const V d = w0 * w0 + w1 * w1 + w2 * w2 - 1.0;
    return (d <= kUnitTolerance) & (d >= -kUnitTolerance);   // NaN: false
}
inline bool on_sphere(const double *w) { return on_sphere_v(w[0], w[1], w[2]); }

// (u, v) in [a0, b0] x [a1, b1], without a branch (NaN: false), for double or simd::f64v (a
// truth value, or a lane mask); the square's test inline where Domain::contains, a call with a
// loop over the dimensions, was a large part of a 2-D batch.
template <class D>
RE_INLINE auto in_rectangle(D u, D v, double a0, double b0, double a1, double b1) {
    return (u >= a0) & (u <= b0) & (v >= a1) & (v <= b1);
}
inline bool on_hemisphere(const double *w) { return on_sphere(w) & (w[2] >= 0); }

struct Domain {
    DomainKind kind = DomainKind::Box;
    int dim = 1;                   // coordinates per point (3 for directions)
    std::vector<double> lo, hi;    // Box only

    static Domain box(std::vector<double> lo, std::vector<double> hi) {
        Domain d;
        d.kind = DomainKind::Box;
        d.dim = int(lo.size());
        d.lo = std::move(lo);
        d.hi = std::move(hi);
        return d;
    }
    static Domain interval(double a, double b) { return box({a}, {b}); }
    static Domain half_line() { Domain d; d.kind = DomainKind::HalfLine; d.dim = 1; return d; }
    static Domain hemisphere() { Domain d; d.kind = DomainKind::Hemisphere; d.dim = 3; return d; }
    static Domain sphere() { Domain d; d.kind = DomainKind::Sphere; d.dim = 3; return d; }

    // Lebesgue volume (Box), solid angle (directions), or infinity.
    double measure() const {
        switch (kind) {
            case DomainKind::Box: {
                double v = 1;
                for (int j = 0; j < dim; ++j) v *= hi[j] - lo[j];
                return v;
            }
            case DomainKind::HalfLine: return std::numeric_limits<double>::infinity();
            case DomainKind::Hemisphere: return 2 * M_PI;
            case DomainKind::Sphere: return 4 * M_PI;
        }
        return 0;
    }

    // Closed membership (directions: on_sphere, on_hemisphere).
    bool contains(const double *x) const {
        switch (kind) {
            case DomainKind::Box:
                for (int j = 0; j < dim; ++j)
                    if (!(x[j] >= lo[j] && x[j] <= hi[j])) return false;
                return true;
            case DomainKind::HalfLine: return x[0] >= 0 && x[0] <= std::numeric_limits<double>::max();
            case DomainKind::Hemisphere: return on_hemisphere(x);
            case DomainKind::Sphere: return on_sphere(x);
        }
        return false;
    }

    // How many of the n points x[0..n) (n x dim) contains() rejects: the same tests, written
    // branch-free per kind so that the loop vectorises (it screens every sampled block).
    size_t count_outside(const double *x, size_t n) const {
        size_t out = 0;
        switch (kind) {
            case DomainKind::Box:
                if (dim == 1) {
                    const double a = lo[0], b = hi[0];
                    for (size_t i = 0; i < n; ++i) out += !((x[i] >= a) & (x[i] <= b));
                    return out;
                }
                if (dim == 2) {  // the square's points (table samplers), in vector lanes
                    const double a0 = lo[0], b0 = hi[0], a1 = lo[1], b1 = hi[1];
                    using simd::f64v;
                    simd::i64v lanes{};
                    size_t i = 0;
                    for (; i + simd::kWidth <= n; i += simd::kWidth) {
                        f64v u, v;
                        simd::deinterleave(x + 2 * i, u, v);
                        lanes += in_rectangle(u, v, a0, b0, a1, b1) ? simd::i64v{} : simd::i64v{} + 1;
                    }
                    for (size_t l = 0; l < simd::kWidth; ++l) out += size_t(lanes[l]);
                    for (; i < n; ++i) out += !in_rectangle(x[2 * i], x[2 * i + 1], a0, b0, a1, b1);
                    return out;
                }
                for (size_t i = 0; i < n; ++i) out += !contains(x + i * size_t(dim));
                return out;
            case DomainKind::HalfLine:
                for (size_t i = 0; i < n; ++i)
                    out += !((x[i] >= 0) & (x[i] <= std::numeric_limits<double>::max()));
                return out;
            case DomainKind::Hemisphere: return count_off_sphere<true>(x, n);
            case DomainKind::Sphere: return count_off_sphere<false>(x, n);
        }
        return n;
    }

    // Directions not on_sphere (not on_hemisphere when `hemisphere`) among x[0..n): kWidth at
    // a time, in vector lanes (the scalar loop's stride-3 loads did not vectorise: an eighth of
    // importance sampling's time on ggx_lobe).
    template <bool hemisphere>
    static size_t count_off_sphere(const double *x, size_t n) {
        constexpr size_t W = simd::kWidth;
        size_t i = 0, out = 0;
        simd::i64v off = {};
        for (; i + W <= n; i += W) {
            simd::f64v w0, w1, w2;
            simd::load3(x + 3 * i, w0, w1, w2);
            auto in = on_sphere_v(w0, w1, w2);
            if (hemisphere) in &= w2 >= 0.0;
            off += in ? simd::i64v{} : simd::i64v{} + 1;
        }
        for (size_t l = 0; l < W; ++l) out += size_t(off[l]);
        for (; i < n; ++i) out += hemisphere ? !on_hemisphere(x + 3 * i) : !on_sphere(x + 3 * i);
        return out;
    }

    std::string kind_name() const {
        switch (kind) {
            case DomainKind::Box: return dim == 1 ? "interval" : (dim == 2 ? "square" : "box");
            case DomainKind::HalfLine: return "half_line";
            case DomainKind::Hemisphere: return "hemisphere";
            case DomainKind::Sphere: return "sphere";
        }
        return "?";
    }
};

}  // namespace re
