// The direction samplers (uniform on the sphere or hemisphere, cosine lobe, uniform cone, GGX)
// as types, with Pointwise, the batch loops every sampler type builds on (table_samplers.cpp's
// too): samplers.cpp makes them (make_sampler) and polar_mis.cpp inlines their polar parts into
// one loop over an MIS pair.  In namespace re, not an anonymous one, so that both see the same
// types.
#pragma once
#include <cmath>

#include "pcg32.h"
#include "samplers.h"
#include "sampling.h"
#include "simd.h"

namespace re {

// Batch loops over the scalar triples of sampling.h; D supplies sample_one/pdf_one/invert_one.
template <class D>
class Pointwise : public Sampler {
  public:
    void sample(const double *u, double *x, double *p, size_t n) const override {
        const D &d = static_cast<const D &>(*this);
        const int ud = udim, xd = domain.dim;
        for (size_t i = 0; i < n; ++i) p[i] = d.sample_one(u + i * ud, x + i * xd);
    }
    void pdf(const double *x, double *p, size_t n) const override {
        const D &d = static_cast<const D &>(*this);
        const int xd = domain.dim;
        for (size_t i = 0; i < n; ++i) p[i] = d.pdf_one(x + i * xd);
    }
    void invert(const double *x, double *u, size_t n) const override {
        const D &d = static_cast<const D &>(*this);
        const int ud = udim, xd = domain.dim;
        for (size_t i = 0; i < n; ++i) d.invert_one(x + i * xd, u + i * ud);
    }
};

// Direction samplers (u in [0,1)^2 to unit vectors), vectorised: D supplies draw(u0, u1, w0,
// w1, w2) and density(z) (the pdf at a direction of cosine z inside the support), templates
// over double and simd::f64v (the same bits lane by lane); the batch loops run them on kWidth
// samples at a time, the point's (x, y, z) gathered into and scattered from vector lanes, and
// the scalar tail and the scalar triple on one.  The per-sample scalar loop was a third of
// drjit's speed on ggx_lobe.  pdf is 0 off the sphere (off the hemisphere when `hemisphere`).
template <class D, bool hemisphere>
class Directional : public Pointwise<D> {
  public:
    Directional() { this->polar = true; }   // every one's pdf is density(z)
    template <class V>
    V sample_v(V u0, V u1, V &w0, V &w1, V &w2) const {
        self().draw(u0, u1, w0, w1, w2);
        return self().density(w2);
    }
    template <class V>
    V pdf_v(V w0, V w1, V w2) const {
        auto in = on_sphere_v(w0, w1, w2);
        if (hemisphere) in &= w2 >= V{};
        return in ? self().density(w2) : V{};
    }
    double sample_one(const double *u, double *w) const { return sample_v(u[0], u[1], w[0], w[1], w[2]); }
    double pdf_one(const double *w) const { return pdf_v(w[0], w[1], w[2]); }
    // u of the direction w: D's u0_of(w) and the azimuth's fraction of a turn, NaN outside the
    // domain or where D's in_support(w) is false
    void invert_one(const double *w, double *u) const {
        const bool in = this->domain.contains(w) && self().in_support(w);
        u[0] = in ? self().u0_of(w) : kNaN;
        u[1] = in ? azimuth_fraction(w) : kNaN;
    }
    // every direction of the domain, unless D says otherwise
    bool in_support(const double *) const { return true; }
    void sample(const double *u, double *x, double *p, size_t n) const override { sample_lanes<false>(u, x, p, n); }
    bool sample_valid(const double *u, double *x, double *p, size_t n) const override {
        return sample_lanes<true>(u, x, p, n) == 0;
    }
    void pdf(const double *x, double *p, size_t n) const override {
        simd::map3(x, p, n, [this](auto w0, auto w1, auto w2) { return pdf_v(w0, w1, w2); });
    }
    // The polar part alone (Sampler::sample_polar): D's cos_theta(u0), sample()'s w2, and its
    // density, screened in the lanes as sample_lanes screens (polar_lanes).
    size_t sample_polar(const double *u, size_t stride, double *z, double *p, size_t n) const override {
        constexpr size_t W = simd::kWidth;
        simd::i64v bad = {};
        size_t i = 0;
        for (; i + W <= n; i += W) polar_lanes(simd::load_strided(u + i * stride, stride), z + i, p + i, bad);
        size_t count = simd::lane_total(bad);
        for (; i < n; ++i) {
            z[i] = self().cos_theta(u[i * stride]);
            p[i] = self().density(z[i]);
            count += !polar_valid(z[i], p[i]);
        }
        return count;
    }
    size_t sample_polar_rows(LaneGenerator &gen, size_t rows, double *z, double *p) const override {
        constexpr size_t W = simd::kWidth, R = LaneGenerator::kEvensPerRow;
        static_assert(R % W == 0, "a generator row holds whole vectors of u0");
        alignas(64) double u[R];
        simd::i64v bad = {};
        {
            LaneGenerator::Rows<true> draw(gen);   // the even lanes' states, written back at the end
            for (size_t r = 0; r < rows; ++r, z += R, p += R) {
                draw.next(u);
                for (size_t i = 0; i < R; i += W) polar_lanes(simd::load(u + i), z + i, p + i, bad);
            }
        }
        gen.skip_odd(rows);
        return simd::lane_total(bad);
    }
    void pdf_polar(const double *z, double *p, size_t n) const override {
        simd::map(z, p, n, [this](auto zv) { return polar_pdf_v(zv); });
    }
    // pdf_polar at the cosines z (double or simd::f64v): density(z) where a direction of the
    // domain has cosine z (polar_in), else 0.
    template <class V>
    RE_INLINE V polar_pdf_v(V z) const { return polar_in(z) ? self().density(z) : V{}; }
    // Whether the screening (sample_valid's, on z alone) keeps a sample of cosine z and pdf p:
    // a bool, or a lane mask.
    template <class V>
    static RE_INLINE auto polar_valid(V z, V p) { return polar_in(z) & valid_pdf(p); }
  private:
    const D &self() const { return static_cast<const D &>(*this); }
    // z and the pdf of kWidth samples from their u0, stored; bad counts, per lane, those
    // sample_valid would reject (off the domain, or a pdf not in (0, max double])
    RE_INLINE void polar_lanes(simd::f64v u0, double *z, double *p, simd::i64v &bad) const {
        const simd::f64v zv = self().cos_theta(u0), pv = self().density(zv);
        simd::store(z, zv);
        simd::store(p, pv);
        bad += polar_valid(zv, pv) ? simd::i64v{} : simd::i64v{} + 1;
    }
    // whether some direction of the domain has cosine z: z^2 - 1 within on_sphere_v's tolerance
    // above (x^2 + y^2 makes up any shortfall below)
    template <class V>
    static auto polar_in(V z) {
        auto in = (z * z - 1.0 <= kUnitTolerance);
        if (hemisphere) in &= z >= V{};
        return in;
    }
    // sample(), kWidth directions at a time; with `screen`, also the number of them off the
    // domain or with a pdf not in (0, max double], counted in the lanes before they are
    // stored (the tests of Domain::count_outside and count_invalid_pdfs: a separate pass
    // reloading and transposing the block was 15 % of an importance estimate's time).
    template <bool screen>
    size_t sample_lanes(const double *u, double *x, double *p, size_t n) const {
        constexpr size_t W = simd::kWidth;
        simd::i64v bad = {};
        size_t i = 0;
        for (; i + W <= n; i += W) {
            simd::f64v u0, u1, w0, w1, w2;
            simd::deinterleave(u + 2 * i, u0, u1);
            const simd::f64v pv = sample_v(u0, u1, w0, w1, w2);
            simd::store(p + i, pv);
            simd::store3(x + 3 * i, w0, w1, w2);
            if (screen) {
                auto ok = on_sphere_v(w0, w1, w2) & valid_pdf(pv);
                if (hemisphere) ok &= w2 >= 0.0;
                bad += ok ? simd::i64v{} : simd::i64v{} + 1;
            }
        }
        size_t count = simd::lane_total(bad);
        for (; i < n; ++i) {
            p[i] = sample_one(u + 2 * i, x + 3 * i);
            if (screen) count += !(this->domain.contains(x + 3 * i) && valid_pdf(p[i]));
        }
        return count;
    }
};

class UniformHemisphere final : public Directional<UniformHemisphere, true> {
  public:
    UniformHemisphere() { name = "uniform_hemisphere"; domain = Domain::hemisphere(); udim = 2; }
    template <class V>
    void draw(V u0, V u1, V &w0, V &w1, V &w2) const { sample_uniform_hemisphere(u0, u1, w0, w1, w2); }
    template <class V>
    V cos_theta(V u0) const { return uniform_hemisphere_cos(u0); }
    template <class V>
    V density(V z) const { return uniform_hemisphere_pdf(z); }
    double u0_of(const double *w) const { return w[2]; }
};

class UniformSphere final : public Directional<UniformSphere, false> {
  public:
    UniformSphere() { name = "uniform_sphere"; domain = Domain::sphere(); udim = 2; }
    template <class V>
    void draw(V u0, V u1, V &w0, V &w1, V &w2) const { sample_uniform_sphere(u0, u1, w0, w1, w2); }
    template <class V>
    V cos_theta(V u0) const { return uniform_sphere_cos(u0); }
    template <class V>
    V density(V z) const { return uniform_sphere_pdf(z); }
    double u0_of(const double *w) const { return (1 - w[2]) / 2; }
};

class CosineHemisphere final : public Directional<CosineHemisphere, true> {
  public:
    CosineHemisphere() { name = "cosine_hemisphere"; domain = Domain::hemisphere(); udim = 2; }
    template <class V>
    void draw(V u0, V u1, V &w0, V &w1, V &w2) const { sample_cosine_hemisphere(u0, u1, w0, w1, w2); }
    template <class V>
    V cos_theta(V u0) const { return cosine_hemisphere_cos(u0); }
    template <class V>
    V density(V z) const { return cosine_hemisphere_pdf(z); }
    double u0_of(const double *w) const { return w[0] * w[0] + w[1] * w[1]; }
};

class UniformCone final : public Directional<UniformCone, false> {
  public:
    explicit UniformCone(double cos_max) : c_(cos_max) {
        name = "uniform_cone"; params = {{"cos_max", cos_max}}; domain = Domain::sphere(); udim = 2;
    }
    template <class V>
    void draw(V u0, V u1, V &w0, V &w1, V &w2) const { sample_uniform_cone(u0, u1, c_, w0, w1, w2); }
    template <class V>
    V cos_theta(V u0) const { return uniform_cone_cos(u0, c_); }
    template <class V>
    V density(V z) const { return uniform_cone_pdf(z, c_); }
    bool in_support(const double *w) const { return w[2] >= c_; }
    double u0_of(const double *w) const { return (1 - w[2]) / (1 - c_); }
  private:
    double c_;
};

class Ggx final : public Directional<Ggx, true> {
  public:
    explicit Ggx(double alpha) : a_(alpha) {
        name = "ggx";
        params = {{"alpha", alpha}};
        domain = Domain::hemisphere();
        udim = 2;
        polar_function = ggx_pdf_name(alpha);
    }
    template <class V>
    void draw(V u0, V u1, V &w0, V &w1, V &w2) const { sample_ggx(u0, u1, a_, w0, w1, w2); }
    template <class V>
    V cos_theta(V u0) const { return ggx_cos(u0, a_); }
    template <class V>
    V density(V z) const { return ggx_pdf(z, a_); }
    bool in_support(const double *w) const { return w[2] > 0; }
    double u0_of(const double *w) const {
        const double t2 = (w[0] * w[0] + w[1] * w[1]) / (w[2] * w[2]);
        return t2 / (a_ * a_ + t2);
    }
  private:
    double a_;
};

}  // namespace re
