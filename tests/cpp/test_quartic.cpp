// Tests of the closed-form polynomial solvers in fmu_src/core/quartic.hpp.
//
// solve_quartic is checked on 10^6 seeded random quartics in eight classes, each against
// Eigen's companion-matrix solver (Eigen::PolynomialSolver) and, where the roots are known by
// construction, against the true roots:
//   (a) every returned root has a small relative residual |p(x)| / sum |c_i| |x|^i (a backward
//       error; bound kResidualBound below);
//   (b) where the problem is well conditioned the number of real roots agrees with Eigen, and
//       each well-separated true root is matched within a tolerance derived from its condition
//       number (kForwardFactor below);
//   (c) no NaN/Inf ever, roots ascending, also on adversarial inputs.
// solve_cubic and solve_quadratic get direct unit tests. Each class prints what was measured.
#include "numerics/quartic.hpp"

#include <gtest/gtest.h>
#include <unsupported/Eigen/Polynomials>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <complex>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace {

using ipmsm::RealRoots;
using ipmsm::solve_cubic;
using ipmsm::solve_quadratic;
using ipmsm::solve_quartic;
using LD = long double;
using cplx = std::complex<double>;

constexpr double kEps = DBL_EPSILON;  // 2.2e-16

// (a) Relative residual bound. For a simple root the best double x has
// |p(x)| <~ |x p'(x)| u <= 4 u sum|c_i||x|^i (u = eps/2, |x p'(x)| <= 4 sum|c_i||x|^i), and
// the Newton polish, evaluated in double, stops at the level of its own evaluation error,
// gamma_8 sum|c_i||x|^i ~ 8u sum (Horner, degree 4). So a polished simple root is expected at
// a few eps, here evaluated in long double so that the measurement itself adds little. Double
// and clustered roots are not improved much by one Newton step; there the bound is the
// backward error of the closed form (the factorisation into quadratics). Measured: <= 8e-16
// (3.5 eps) over all classes below, <= 1.1e-15 in runs of 10^6 quartics per class with other
// seeds. 1e-14 (45 eps) leaves a margin of ~10 and is still tight enough to fail a solver
// without the Newton polish (2e-13 on "two real + complex pair", 3e-9 on "widely scaled")
// or one that depresses unconditionally (1e-3 on widely scaled roots).
constexpr double kResidualBound = 1e-14;
// (b) Forward error bound, in units of the condition-number estimate cond_tol() below: the
// true roots are those of the polynomial before its coefficients were rounded, so the
// computed root can differ by the rounding of the coefficients (a few eps in each) plus the
// solver's backward error, both times the root's condition number. Measured <= 2.4; without
// the Newton polish this ratio reaches 900 (two real + pair) and 1e7 (widely scaled).
constexpr double kForwardFactor = 16.0;

#ifdef NDEBUG
constexpr int kScale = 1;
#else
constexpr int kScale = 10;  // unoptimised Eigen is slow: a tenth of the sample in Debug builds
#endif

struct Quartic {
    double c[5];  // c[0] x^4 + c[1] x^3 + c[2] x^2 + c[3] x + c[4]
};

// p(x) and sum |c_i| |x|^i in long double.
void eval_ld(const Quartic& q, double x, LD& p, LD& s) {
    const LD X
    = x, ax = std::fabs(X);
    p = 0;
    s = 0;
    for (double c : q.c) {
        p = p * X
        +c;
        s = s * ax + std::fabs(static_cast<LD>(c));
    }
}

double rel_residual(const Quartic& q, double x) {
    LD p, s;
    eval_ld(q, x, p, s);
    return s > 0 ? static_cast<double>(std::fabs(p) / s) : 0.0;
}

// Condition-aware tolerance for a root r of q: the distance a perturbation of the coefficients
// by eps (relative) can move it, estimated from the Taylor coefficients T_k = p^(k)(r)/k! as
// min_k (eps sum|c_i||r|^i / |T_k|)^(1/k) (k = 1 for a simple root, 2 for a double one ...).
double cond_tol(const Quartic& q, double r) {
    LD w[5];
    for (int i = 0; i < 5; ++i) w[i] = q.c[i];
    LD T[5];
    for (int k = 0; k < 5; ++k) {  // synthetic division by (x - r), repeatedly
        LD acc = w[0];
        for (int i = 1; i < 5 - k; ++i) {
            acc = acc * r + w[i];
            w[i] = acc;
        }
        T[k] = w[4 - k];
    }
    LD p, s;
    eval_ld(q, r, p, s);
    double best = std::numeric_limits<double>::infinity();
    for (int k = 1; k <= 4; ++k) {
        if (T[k] == 0) continue;
        best = std::min(best, std::pow(static_cast<double>(kEps * s / std::fabs(T[k])), 1.0 / k));
    }
    return best;
}

// Coefficients of a * prod (x - r_i) (n real roots) times (x^2 - 2 re x + re^2 + im^2)^npairs.
Quartic from_roots(double a, const double* r, int n, const cplx* pairs = nullptr, int npairs = 0) {
    double p[5] = {a, 0, 0, 0, 0};
    int deg = 0;
    auto mul = [&](const double* f, int fdeg) {  // p *= f (f monic-free, descending, degree fdeg)
        double np[5] = {0, 0, 0, 0, 0};
        for (int i = 0; i <= deg; ++i)
            for (int j = 0; j <= fdeg; ++j) np[i + j] += p[i] * f[j];
        deg += fdeg;
        std::copy(np, np + 5, p);
    };
    for (int i = 0; i < n; ++i) {
        const double f[2] = {1.0, -r[i]};
        mul(f, 1);
    }
    for (int i = 0; i < npairs; ++i) {
        const double f[3] = {1.0, -2.0 * pairs[i].real(), std::norm(pairs[i])};
        mul(f, 2);
    }
    Quartic q;
    std::copy(p, p + 5, q.c);
    return q;
}

// Eigen's roots of the polynomial with leading coefficient dropped while it is exactly zero.
std::vector<cplx> eigen_roots(const Quartic& q) {
    int first = 0;
    while (first < 4 && q.c[first] == 0.0) ++first;
    const int deg = 4 - first;
    std::vector<cplx> out;
    if (deg < 1) return out;
    if (deg == 4) {
        Eigen::Matrix<double, 5, 1> p;
        for (int i = 0; i < 5; ++i) p[i] = q.c[4 - i];
        Eigen::PolynomialSolver<double, 4> solver(p);
        for (int i = 0; i < 4; ++i) out.push_back(solver.roots()[i]);
    } else {
        Eigen::VectorXd p(deg + 1);
        for (int i = 0; i <= deg; ++i) p[i] = q.c[4 - i];
        Eigen::PolynomialSolver<double, Eigen::Dynamic> solver(p);
        for (int i = 0; i < solver.roots().size(); ++i) out.push_back(solver.roots()[i]);
    }
    return out;
}

// What the generator knows about a quartic.
struct Truth {
    std::vector<double> real;   // real roots with multiplicity
    std::vector<cplx> complex;  // one of each conjugate pair
    bool exact = false;         // coefficients exact (dyadic roots): multiplicities are exact
};

// The monic quartic with the roots of t.
Quartic monic_with_roots(const Truth& t) {
    return from_roots(1.0, t.real.data(), static_cast<int>(t.real.size()), t.complex.data(),
                      static_cast<int>(t.complex.size()));
}

std::string fmt(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3g", v);
    return buf;
}

struct Stats {
    std::string name;
    long polys = 0, roots = 0;
    double worst_residual = 0;
    double worst_forward = 0;  // max over checked true roots of error / cond_tol
    long known_checked = 0, known_skipped = 0, known_count_checked = 0;
    long eigen_compared = 0, eigen_skipped = 0;
    double eigen_worst_dev = 0;  // max |ours - Eigen| / tolerance (see check_eigen)
    long failures = 0;
    Quartic worst_q{};

    void fail(const Quartic& q, const std::string& what) {
        if (failures < 5) {
            char buf[256];
            std::snprintf(buf, sizeof buf, "{%.17g, %.17g, %.17g, %.17g, %.17g}", q.c[0], q.c[1], q.c[2], q.c[3],
                          q.c[4]);
            ADD_FAILURE() << name << ": " << what << " for coefficients " << buf;
        }
        ++failures;
    }

    void print() const {
        std::printf(
            "[quartic] %-22s polys %7ld roots %8ld | worst residual %.2e | known roots: checked "
            "%7ld skipped %6ld, worst err/cond %.2f | Eigen: compared %7ld skipped %6ld, worst "
            "dev %.2e of tolerance\n",
            name.c_str(), polys, roots, worst_residual, known_checked, known_skipped, worst_forward, eigen_compared,
            eigen_skipped, eigen_worst_dev);
        std::fflush(stdout);
    }
};

// Basic sanity (c) and residuals (a) of a result; returns false if it is unusable.
bool check_basic(const Quartic& q, const RealRoots& r, Stats& st, bool residuals = true) {
    if (r.count < 0 || r.count > 4) {
        st.fail(q, "count out of range");
        return false;
    }
    for (int i = 0; i < r.count; ++i) {
        if (!std::isfinite(r.root[i])) {
            st.fail(q, "non-finite root");
            return false;
        }
        if (i > 0 && r.root[i] < r.root[i - 1]) st.fail(q, "roots not ascending");
        if (residuals) {
            const double res = rel_residual(q, r.root[i]);
            if (res > st.worst_residual) {
                st.worst_residual = res;
                st.worst_q = q;
            }
            if (!(res <= kResidualBound)) st.fail(q, "residual " + fmt(res) + " at " + fmt(r.root[i]));
        }
    }
    st.roots += r.count;
    return true;
}

// (b) against the true roots.
void check_known(const Quartic& q, const RealRoots& r, const Truth& t, Stats& st) {
    // All true roots, complex ones as both members of the pair.
    std::vector<cplx> all;
    for (double x : t.real) all.emplace_back(x, 0.0);
    for (cplx z : t.complex) {
        all.push_back(z);
        all.push_back(std::conj(z));
    }
    bool all_resolved = true;
    for (std::size_t i = 0; i < t.real.size(); ++i) {
        const double x = t.real[i];
        const double tol = cond_tol(q, x);
        // Separation from every other root (an exact double root's twin does not count).
        double sep = std::numeric_limits<double>::infinity();
        for (std::size_t j = 0; j < all.size(); ++j) {
            if (j == i) continue;
            if (t.exact && all[j] == cplx(x, 0.0)) continue;
            sep = std::min(sep, std::abs(all[j] - cplx(x, 0.0)));
        }
        if (!(sep > 100.0 * tol)) {  // clustered with another root: no forward check
            all_resolved = false;
            ++st.known_skipped;
            continue;
        }
        ++st.known_checked;
        double err = std::numeric_limits<double>::infinity();
        int near = 0;
        for (int k = 0; k < r.count; ++k) {
            const double e = std::fabs(r.root[k] - x);
            err = std::min(err, e);
            if (e <= kForwardFactor * tol + DBL_MIN) ++near;
        }
        const double ratio = err / (tol + DBL_MIN);
        if (std::isfinite(ratio)) st.worst_forward = std::max(st.worst_forward, ratio);
        if (!(err <= kForwardFactor * tol + DBL_MIN)) {
            st.fail(q, "true root " + std::to_string(x) + " not matched (err/cond " + std::to_string(ratio) + ")");
        } else if (t.exact) {
            const int mult = static_cast<int>(std::count(t.real.begin(), t.real.end(), x));
            if (near < mult) st.fail(q, "multiple root " + std::to_string(x) + " found too few times");
        }
    }
    for (cplx z : t.complex) {
        // A pair close to the real axis may legitimately come out as real roots.
        if (!(std::fabs(z.imag()) > 100.0 * cond_tol(q, z.real()) && std::fabs(z.imag()) > 1e-6 * std::abs(z)))
            all_resolved = false;
    }
    if (all_resolved) {
        ++st.known_count_checked;
        if (r.count != static_cast<int>(t.real.size()))
            st.fail(q, "count " + std::to_string(r.count) + ", expected " + std::to_string(t.real.size()));
    }
}

// (b) against Eigen: only where Eigen's roots are well separated (relative 1e-3) and clearly
// real (imaginary part below 1e-12 relative) or clearly complex (above 1e-3 relative);
// "relative" is to max(|z|, 1e-3 * largest root), so that a multiple root at 0, which Eigen
// splits by ~sqrt(eps), does not look well separated. Roots beyond `max_mag` are ignored.
// Eigen's companion-matrix eigenvalues are backward stable for the balanced matrix, not
// coefficientwise, so its roots are compared to within 1e-9 of the largest root magnitude or
// 1000 times the root's condition estimate. With a `reference` polynomial (q without its
// leading term), Eigen solves that instead, and the tolerance adds the first-order shift
// 2 |a x^4 / p'(x)| of the root by the missing term.
void check_eigen(const Quartic& q, const RealRoots& r, Stats& st, double max_mag = HUGE_VAL,
                 const Quartic* reference = nullptr) {
    std::vector<cplx> z = eigen_roots(reference ? *reference : q);
    z.erase(std::remove_if(z.begin(), z.end(), [&](cplx v) { return !(std::abs(v) <= max_mag); }), z.end());
    double scale = 0;
    for (cplx v : z) scale = std::max(scale, std::abs(v));
    const double floor = 1e-3 * scale;
    bool ok = true;
    std::vector<double> eig_real;
    for (std::size_t i = 0; i < z.size() && ok; ++i) {
        const double mag = std::max(std::abs(z[i]), floor), im = std::fabs(z[i].imag());
        if (im <= 1e-12 * mag) {
            eig_real.push_back(z[i].real());
        } else if (im < 1e-3 * mag) {
            ok = false;
        }
        for (std::size_t j = 0; j < i && ok; ++j)
            if (std::abs(z[i] - z[j]) < 1e-3 * std::max(mag, std::abs(z[j]))) ok = false;
    }
    if (!ok || scale == 0) {
        ++st.eigen_skipped;
        return;
    }
    ++st.eigen_compared;
    std::vector<double> ours;
    for (int k = 0; k < r.count; ++k)
        if (std::fabs(r.root[k]) <= max_mag) ours.push_back(r.root[k]);
    if (ours.size() != eig_real.size()) {
        st.fail(q, "real root count " + std::to_string(ours.size()) + ", Eigen " + std::to_string(eig_real.size()));
        return;
    }
    std::sort(eig_real.begin(), eig_real.end());
    for (std::size_t k = 0; k < ours.size(); ++k) {
        double diff = std::fabs(ours[k] - eig_real[k]);
        if (reference) {
            const double x = ours[k];
            const double dp = ((4 * q.c[0] * x + 3 * q.c[1]) * x + 2 * q.c[2]) * x + q.c[3];
            diff = std::max(0.0, diff - 2 * std::fabs(q.c[0] * x * x * x * x / dp));
        }
        const double dev = std::min(diff / (1e-9 * scale), diff / (1e3 * cond_tol(q, ours[k])));
        st.eigen_worst_dev = std::max(st.eigen_worst_dev, dev);
        if (!(dev <= 1.0))
            st.fail(q, "root " + std::to_string(ours[k]) + " differs from Eigen's by " + std::to_string(diff));
    }
}

void run_one(const Quartic& q, const Truth* t, Stats& st, double max_mag = HUGE_VAL) {
    ++st.polys;
    const RealRoots r = solve_quartic(q.c[0], q.c[1], q.c[2], q.c[3], q.c[4]);
    if (!check_basic(q, r, st)) return;
    if (t) check_known(q, r, *t, st);
    check_eigen(q, r, st, max_mag);
}

class QuarticClasses : public ::testing::Test {
protected:
    std::mt19937_64 rng{0x5eed1234u};
    double U(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); }
    double sign() { return (rng() & 1) ? 1.0 : -1.0; }
    double pow10(double lo, double hi) { return std::pow(10.0, U(lo, hi)); }
    static long n(long full) { return full / kScale; }
    void finish(const Stats& st) {
        st.print();
        EXPECT_EQ(st.failures, 0) << st.name;
        EXPECT_LE(st.worst_residual, kResidualBound) << st.name;
    }
};

TEST_F(QuarticClasses, RandomCoefficients) {
    Stats st{"random coefficients"};
    for (long i = 0; i < n(200000); ++i) {
        Quartic q;
        for (double& c : q.c) c = U(-1, 1);
        run_one(q, nullptr, st);
    }
    finish(st);
    EXPECT_GT(st.eigen_compared, n(200000) * 9 / 10);
}

TEST_F(QuarticClasses, FourRealRoots) {
    Stats st{"four real roots"};
    for (long i = 0; i < n(150000); ++i) {
        const double s = pow10(-3, 3);
        Truth t;
        for (int k = 0; k < 4; ++k) t.real.push_back(s * U(-1, 1));
        run_one(from_roots(sign() * U(0.5, 2), t.real.data(), 4), &t, st);
    }
    finish(st);
    EXPECT_GT(st.known_count_checked, n(150000) / 2);
}

TEST_F(QuarticClasses, TwoRealAndComplexPair) {
    Stats st{"two real + complex pair"};
    for (long i = 0; i < n(150000); ++i) {
        const double s = pow10(-3, 3);
        Truth t;
        t.real = std::vector<double>{s * U(-1, 1), s * U(-1, 1)};
        t.complex = std::vector<cplx>{cplx(s * U(-1, 1), s * U(0.01, 1))};
        run_one(from_roots(sign() * U(0.5, 2), t.real.data(), 2, t.complex.data(), 1), &t, st);
    }
    finish(st);
    EXPECT_GT(st.known_count_checked, n(150000) / 2);
}

TEST_F(QuarticClasses, ClusteredRoots) {
    // 2, 3 or 4 roots within a relative spread of 1e-6 ... 1e-3 around a centre, the others
    // anywhere; about a quarter of the clusters are a complex pair next to real roots.
    Stats st{"clustered roots"};
    for (long i = 0; i < n(100000); ++i) {
        const double centre = sign() * pow10(-2, 2), spread = pow10(-6, -3);
        const int kc = 2 + static_cast<int>(rng() % 3);
        Truth t;
        for (int k = 0; k < kc; ++k) t.real.push_back(centre * (1 + spread * U(-1, 1)));
        if (kc == 4 && (rng() & 1)) {  // two of the four as a pair just off the axis
            t.real.resize(2);
            t.complex = std::vector<cplx>{cplx(centre, std::fabs(centre) * spread * U(0.1, 1))};
        } else {
            for (int k = kc; k < 4; ++k) t.real.push_back(sign() * pow10(-2, 2) * U(0.1, 1));
        }
        run_one(monic_with_roots(t), &t, st);
    }
    finish(st);
}

TEST_F(QuarticClasses, ExactDoubleRoots) {
    // Dyadic roots k/64, |k| <= 1000: the coefficients are exact, so the double roots are exact.
    Stats st{"exact double roots"};
    auto dy = [&] { return static_cast<double>(static_cast<long>(rng() % 2001) - 1000) / 64.0; };
    for (long i = 0; i < n(100000); ++i) {
        Truth t;
        t.exact = true;
        const double r = dy();
        switch (i % 4) {
            case 0: t.real = std::vector<double>{r, r, dy(), dy()}; break;
            case 1: {
                const double s = dy();
                t.real = std::vector<double>{r, r, s, s};
                break;
            }
            case 2:
                t.real = std::vector<double>{r, r};
                t.complex = std::vector<cplx>{cplx(dy() / 4, static_cast<double>(1 + rng() % 200) / 64.0)};
                break;
            default: {
                const double s = dy();
                t.real = std::vector<double>{r, r, r, s};  // triple root
                break;
            }
        }
        const Quartic q = monic_with_roots(t);
        if (i % 4 == 3) {  // a triple root: residual and Eigen comparison only
            ++st.polys;
            const RealRoots res = solve_quartic(q.c[0], q.c[1], q.c[2], q.c[3], q.c[4]);
            if (check_basic(q, res, st)) check_eigen(q, res, st);
            continue;
        }
        run_one(q, &t, st);
    }
    finish(st);
    EXPECT_GT(st.known_count_checked, n(100000) / 2);
}

TEST_F(QuarticClasses, WidelyScaledRoots) {
    // Root magnitudes log-uniform in 1e-4 ... 1e4 within one polynomial.
    Stats st{"widely scaled roots"};
    for (long i = 0; i < n(100000); ++i) {
        Truth t;
        if (i % 2 == 0) {
            for (int k = 0; k < 4; ++k) t.real.push_back(sign() * pow10(-4, 4));
        } else {
            t.real = std::vector<double>{sign() * pow10(-4, 4), sign() * pow10(-4, 4)};
            const double m = pow10(-4, 4), ph = U(0.05, 3.09);
            t.complex = std::vector<cplx>{cplx(m * std::cos(ph), m * std::sin(ph))};
        }
        run_one(monic_with_roots(t), &t, st);
    }
    finish(st);
}

TEST_F(QuarticClasses, BiquadraticAndNearBiquadratic) {
    Stats st{"(near-)biquadratic"};
    for (long i = 0; i < n(100000); ++i) {
        if (i % 2 == 0) {  // b = d = 0 exactly
            Quartic q{{U(-1, 1), 0.0, U(-1, 1), 0.0, U(-1, 1)}};
            run_one(q, nullptr, st);
        } else {  // roots +-r1 (1 + tiny), +-r2: depressed linear term ~ 0
            const double s = pow10(-3, 3), e = pow10(-16, -6);
            const double r1 = s * U(0.01, 1), r2 = s * U(0.01, 1);
            Truth t;
            t.real = std::vector<double>{r1 * (1 + e), -r1, r2, -r2 * (1 + e * U(-1, 1))};
            run_one(from_roots(1.0, t.real.data(), 4), &t, st);
        }
    }
    finish(st);
}

TEST_F(QuarticClasses, TinyOrZeroLeadingCoefficient) {
    // a = 0 (a fifth of the cases) or |a| = 1e-20 ... 1e-6, the others O(1) with |b| >= 0.1.
    // The roots of the cubic part then lie within |x| < 20, and a tiny a adds one far root near
    // -b/a (beyond 1e5), which degree reduction drops when it is more than 2^52 times further
    // out (quartic.cpp, step 2). Eigen's companion matrix of such a quartic has entries up to
    // 1e20 and gives the small roots to ~1e-16 |b/a| only, so the reference for the roots
    // within |x| < 1e3 is Eigen on the cubic part: the a x^4 term moves them by ~|a| only.
    Stats st{"tiny/zero leading coef"};
    long far_kept = 0, far_dropped = 0;
    for (long i = 0; i < n(100000); ++i) {
        Quartic q;
        for (double& c : q.c) c = U(-1, 1);
        q.c[1] = sign() * U(0.1, 1);
        q.c[0] = (i % 5 == 0) ? 0.0 : sign() * pow10(-20, -6);
        ++st.polys;
        const RealRoots r = solve_quartic(q.c[0], q.c[1], q.c[2], q.c[3], q.c[4]);
        if (!check_basic(q, r, st)) continue;
        Quartic cubic = q;
        cubic.c[0] = 0.0;
        check_eigen(q, r, st, 1e3, &cubic);
        int far = 0;
        for (int k = 0; k < r.count; ++k) far += std::fabs(r.root[k]) > 1e3;
        if (far > 1 || (far == 1 && q.c[0] == 0.0)) st.fail(q, "spurious far root");
        if (q.c[0] != 0.0) (far ? far_kept : far_dropped) += 1;
    }
    std::printf("[quartic] tiny/zero leading coef: far root returned %ld times, dropped %ld times\n", far_kept,
                far_dropped);
    finish(st);
    EXPECT_GT(far_kept, 0);
    EXPECT_GT(far_dropped, 0);
}

// Is the root spread of q small enough that the solver's scaling to the largest root does not
// underflow the scaled coefficients? The smallest scaled coefficient is about the product of
// the scaled roots, (smallest/largest)^k for k small roots, so the spread must stay below about
// 1e75. Rough bounds from the coefficients (Fujiwara for the largest root, and for the smallest
// via the reversed polynomial, exact zero roots removed). Beyond that the smallest roots are
// lost to underflow (finite, but not accurate): a documented limit.
bool roots_representable(const Quartic& q) {
    int hi = 0, lo = 4;
    while (hi < 4 && q.c[hi] == 0.0) ++hi;
    while (lo > hi && q.c[lo] == 0.0) --lo;
    if (lo <= hi) return true;
    double big = 0, small = 0;
    for (int k = hi + 1; k <= lo; ++k) {
        if (q.c[k] == 0.0) continue;
        big = std::max(big, std::pow(std::fabs(q.c[k] / q.c[hi]), 1.0 / (k - hi)));
    }
    for (int k = lo - 1; k >= hi; --k) {
        if (q.c[k] == 0.0) continue;
        small = std::max(small, std::pow(std::fabs(q.c[k] / q.c[lo]), 1.0 / (lo - k)));
    }
    return std::isfinite(big) && std::isfinite(small) && big * small < 1e70;
}

// (c) adversarial inputs: no NaN/Inf, sorted, count <= 4; residuals where no root can under-
// or overflow (coefficients within 1e-150 ... 1e150, root spread below ~1e70).
TEST(QuarticAdversarial, NoNanOrInfOnExtremeCoefficients) {
    Stats st{"adversarial"};
    std::mt19937_64 rng(99);
    auto U = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
    const double specials[] = {0.0,     -0.0,     1e-150, -1e150, 1e150,  DBL_MIN, DBL_TRUE_MIN,
                               DBL_MAX, -DBL_MAX, 1.0,    -1.0,   1e-300, 1e300,   4.9e-324};
    const int nspecial = sizeof specials / sizeof specials[0];
    long residual_checked = 0;
    for (long i = 0; i < 200000 / kScale; ++i) {
        Quartic q;
        const int mode = static_cast<int>(i % 3);
        bool moderate = true;
        for (double& c : q.c) {
            if (mode == 0) {
                c = specials[rng() % nspecial];
            } else {
                const int z = static_cast<int>(rng() % 5);
                c = z == 0 ? 0.0
                           : (rng() & 1 ? 1 : -1) * std::pow(10.0, U(mode == 1 ? -150 : -300, mode == 1 ? 150 : 300));
            }
            if (c != 0.0 && !(std::fabs(c) >= 1e-150 && std::fabs(c) <= 1e150)) moderate = false;
        }
        ++st.polys;
        const RealRoots r = solve_quartic(q.c[0], q.c[1], q.c[2], q.c[3], q.c[4]);
        if (!check_basic(q, r, st, false)) continue;
        if (moderate && mode == 1 && roots_representable(q)) {
            ++residual_checked;
            for (int k = 0; k < r.count; ++k) {
                const double res = rel_residual(q, r.root[k]);
                st.worst_residual = std::max(st.worst_residual, res);
                if (!(res <= kResidualBound)) st.fail(q, "residual " + std::to_string(res));
            }
        }
        // The cubic and quadratic solvers on the same coefficients.
        const RealRoots rc = solve_cubic(q.c[1], q.c[2], q.c[3], q.c[4]);
        const RealRoots rq = solve_quadratic(q.c[2], q.c[3], q.c[4]);
        for (const RealRoots* x : {&rc, &rq}) {
            ASSERT_GE(x->count, 0);
            ASSERT_LE(x->count, 4);
            for (int k = 0; k < x->count; ++k) ASSERT_TRUE(std::isfinite(x->root[k]));
        }
    }
    st.print();
    std::printf("[quartic] adversarial: residual checked on %ld quartics with moderate coefficients\n",
                residual_checked);
    EXPECT_EQ(st.failures, 0);
}

TEST(QuarticAdversarial, NonFiniteInputGivesNoRoots) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    EXPECT_EQ(solve_quartic(1, nan, 0, 0, -1).count, 0);
    EXPECT_EQ(solve_quartic(inf, 1, 0, 0, -1).count, 0);
    EXPECT_EQ(solve_cubic(1, 0, -inf, 0).count, 0);
    EXPECT_EQ(solve_quadratic(1, 0, nan).count, 0);
}

TEST(QuarticSpecial, DegenerateAndExactCases) {
    RealRoots r = solve_quartic(0, 0, 0, 0, 0);
    EXPECT_EQ(r.count, 0);
    r = solve_quartic(0, 0, 0, 0, 5);
    EXPECT_EQ(r.count, 0);
    r = solve_quartic(2, 0, 0, 0, 0);  // 2 x^4: quadruple root 0
    ASSERT_EQ(r.count, 4);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(r.root[i], 0.0);
    r = solve_quartic(1, 0, 0, 0, -16);  // x = +-2
    ASSERT_EQ(r.count, 2);
    EXPECT_DOUBLE_EQ(r.root[0], -2.0);
    EXPECT_DOUBLE_EQ(r.root[1], 2.0);
    r = solve_quartic(1, -10, 35, -50, 24);  // 1, 2, 3, 4
    ASSERT_EQ(r.count, 4);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(r.root[i], i + 1.0, 1e-13);
    r = solve_quartic(1, 1, 0, 0, 0);  // x^3 (x + 1): no yardstick, nothing dropped
    ASSERT_EQ(r.count, 4);
    EXPECT_EQ(r.root[0], -1.0);
    r = solve_quartic(1, -4, 6, -4, 1);  // (x - 1)^4
    ASSERT_GE(r.count, 2);
    for (int i = 0; i < r.count; ++i) EXPECT_NEAR(r.root[i], 1.0, 1e-3);
    r = solve_quartic(1, 0, -2, 0, 1);  // (x^2 - 1)^2: double roots -1, 1
    ASSERT_EQ(r.count, 4);
    EXPECT_NEAR(r.root[0], -1.0, 1e-7);
    EXPECT_NEAR(r.root[1], -1.0, 1e-7);
    EXPECT_NEAR(r.root[2], 1.0, 1e-7);
    EXPECT_NEAR(r.root[3], 1.0, 1e-7);
    r = solve_quartic(1, 0, 1, 0, 1);  // no real roots
    EXPECT_EQ(r.count, 0);
    // Huge and tiny but balanced: (x - 1)(x - 2)(x - 3)(x - 4) * 1e300, and roots 1e100 * k.
    r = solve_quartic(1e300, -1e301, 3.5e301, -5e301, 2.4e301);
    ASSERT_EQ(r.count, 4);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(r.root[i], i + 1.0, 1e-12);
    r = solve_quartic(1e-300, -1e-199, 3.5e-99, -5e1, 2.4e101);  // roots 1e100 * {1, 2, 3, 4}
    ASSERT_EQ(r.count, 4);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(r.root[i] / 1e100, i + 1.0, 1e-12);
    // Degree reduction: a far below the rest -> the cubic's roots only.
    r = solve_quartic(1e-40, 1, -6, 11, -6);  // root ~ -1e40 dropped; 1, 2, 3 kept
    ASSERT_EQ(r.count, 3);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(r.root[i], i + 1.0, 1e-14);
    r = solve_quartic(1e-10, 1, -6, 11, -6);  // root ~ -1e10 kept
    ASSERT_EQ(r.count, 4);
    EXPECT_NEAR(r.root[0] / -1e10, 1.0, 1e-8);
    // Monic with large roots is not "leading coefficient negligible".
    r = solve_quartic(1, 0, -0x1p51, 0, 0x1p100);  // (x^2 - 2^50)^2: double roots +-2^25
    ASSERT_EQ(r.count, 4);
    EXPECT_NEAR(r.root[0], -0x1p25, 1e-6);
    EXPECT_NEAR(r.root[1], -0x1p25, 1e-6);
    EXPECT_NEAR(r.root[2], 0x1p25, 1e-6);
    EXPECT_NEAR(r.root[3], 0x1p25, 1e-6);
}

// ---------------------------------------------------------------------------------------------
// solve_quadratic

TEST(Quadratic, Basics) {
    RealRoots r = solve_quadratic(1, -3, 2);
    ASSERT_EQ(r.count, 2);
    EXPECT_EQ(r.root[0], 1.0);
    EXPECT_EQ(r.root[1], 2.0);
    r = solve_quadratic(1, -2, 1);
    ASSERT_EQ(r.count, 2);
    EXPECT_EQ(r.root[0], 1.0);
    EXPECT_EQ(r.root[1], 1.0);
    EXPECT_EQ(solve_quadratic(1, 0, 1).count, 0);
    EXPECT_EQ(solve_quadratic(0, 0, 0).count, 0);
    EXPECT_EQ(solve_quadratic(0, 0, 3).count, 0);
    r = solve_quadratic(0, 2, -3);  // linear
    ASSERT_EQ(r.count, 1);
    EXPECT_EQ(r.root[0], 1.5);
    r = solve_quadratic(3, 0, 0);
    ASSERT_EQ(r.count, 2);
    EXPECT_EQ(r.root[0], 0.0);
    EXPECT_EQ(r.root[1], 0.0);
    r = solve_quadratic(1, 5, 0);
    ASSERT_EQ(r.count, 2);
    EXPECT_EQ(r.root[0], -5.0);
    EXPECT_EQ(r.root[1], 0.0);
    r = solve_quadratic(-1, 0, 4);  // negative leading coefficient
    ASSERT_EQ(r.count, 2);
    EXPECT_EQ(r.root[0], -2.0);
    EXPECT_EQ(r.root[1], 2.0);
}

TEST(Quadratic, CancellationFree) {
    // x^2 - (1e8 + 1e-8) x + 1: the textbook formula loses the small root completely.
    RealRoots r = solve_quadratic(1, -(1e8 + 1e-8), 1);
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[0], 1e-8, 1e-8 * 4 * kEps);
    EXPECT_NEAR(r.root[1], 1e8, 1e8 * 4 * kEps);
    r = solve_quadratic(1, 1e12, -1);
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[1], 1e-12, 1e-12 * 4 * kEps);
}

TEST(Quadratic, TinyNegativeDiscriminantIsADoubleRoot) {
    // (x - 0.1)^2 and (x - 1/3)^2 with rounded coefficients.
    for (double x0 : {0.1, 1.0 / 3.0, 0.7, 123.456, -9.87e-5}) {
        const RealRoots r = solve_quadratic(1, -2 * x0, x0 * x0);
        ASSERT_EQ(r.count, 2) << x0;
        EXPECT_NEAR(r.root[0], x0, 1e-7 * std::fabs(x0));
        EXPECT_NEAR(r.root[1], x0, 1e-7 * std::fabs(x0));
    }
    // Many of them: x0^2 rounds either way, so about half have a slightly negative discriminant.
    std::mt19937_64 rng(5);
    int lost = 0;
    for (int i = 0; i < 10000; ++i) {
        const double x0 = std::uniform_real_distribution<double>(-100, 100)(rng);
        const RealRoots r = solve_quadratic(3.0, -6 * x0, 3 * (x0 * x0));
        if (r.count != 2 || !(std::fabs(r.root[0] - x0) <= 1e-7 * std::fabs(x0)) ||
            !(std::fabs(r.root[1] - x0) <= 1e-7 * std::fabs(x0)))
            ++lost;
    }
    EXPECT_EQ(lost, 0);
}

TEST(Quadratic, ExtremeScales) {
    RealRoots r = solve_quadratic(1e300, -3e300, 2e300);  // b^2 would overflow unscaled
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[0], 1.0, 4 * kEps);
    EXPECT_NEAR(r.root[1], 2.0, 4 * kEps);
    r = solve_quadratic(1e-300, -3e-300, 2e-300);  // would underflow unscaled
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[0], 1.0, 4 * kEps);
    EXPECT_NEAR(r.root[1], 2.0, 4 * kEps);
}

TEST(Quadratic, DegreeReduction) {
    // The leading coefficient is dropped only when |a| <= 2^-52 max(|b|, |c|) AND the root it
    // adds (~ -b/a) lies more than 2^52 times further out than the other one (quartic.cpp).
    RealRoots r = solve_quadratic(1e-17, 1, 1);  // far root -1e17, other -1: dropped
    ASSERT_EQ(r.count, 1);
    EXPECT_EQ(r.root[0], -1.0);
    r = solve_quadratic(1e-15, 1, 1);  // far root -1e15 < 2^52: kept
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[0] / -(1e15 - 1), 1.0, 4 * kEps);
    EXPECT_NEAR(r.root[1], -(1 + 1e-15), 4 * kEps);
    r = solve_quadratic(1, -2e200, 1e300);  // roots 2e200 and 5e99: 2e200 dropped
    ASSERT_EQ(r.count, 1);
    EXPECT_NEAR(r.root[0] / 5e99, 1.0, 4 * kEps);
    r = solve_quadratic(1, -1e8, 1);  // a not small next to c: both roots
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[0], 1e-8, 4 * kEps * 1e-8);
    EXPECT_NEAR(r.root[1], 1e8, 4 * kEps * 1e8);
    r = solve_quadratic(1e-20, 0, -1);  // no yardstick (b = 0): roots +-1e10 kept
    ASSERT_EQ(r.count, 2);
    EXPECT_NEAR(r.root[0], -1e10, 4 * kEps * 1e10);
    EXPECT_NEAR(r.root[1], 1e10, 4 * kEps * 1e10);
    r = solve_quadratic(1e-300, 1e10, 1);  // root -1e310 would overflow: dropped
    ASSERT_EQ(r.count, 1);
    EXPECT_NEAR(r.root[0], -1e-10, 4 * kEps * 1e-10);
}

TEST(Quadratic, RandomAgainstExactRoots) {
    std::mt19937_64 rng(7);
    auto U = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
    double worst = 0;
    for (int i = 0; i < 200000 / kScale; ++i) {
        const double r1 = std::pow(10.0, U(-8, 8)) * (rng() & 1 ? 1 : -1);
        const double r2 = std::pow(10.0, U(-8, 8)) * (rng() & 1 ? 1 : -1);
        const double a = U(0.5, 2);
        const Quartic q{{0, 0, a, -a * (r1 + r2), a * r1 * r2}};
        const RealRoots r = solve_quadratic(q.c[2], q.c[3], q.c[4]);
        ASSERT_EQ(r.count, 2);
        const double lo = std::min(r1, r2), hi = std::max(r1, r2);
        for (int k = 0; k < 2; ++k) {
            const double x = k == 0 ? lo : hi;
            const double tol = kForwardFactor * cond_tol(q, x);
            if (std::fabs(r1 - r2) > 100 * tol) {
                EXPECT_NEAR(r.root[k], x, tol);
            }
            worst = std::max(worst, rel_residual(q, r.root[k]));
        }
    }
    std::printf("[quartic] quadratic: worst residual %.2e\n", worst);
    EXPECT_LE(worst, kResidualBound);
}

// ---------------------------------------------------------------------------------------------
// solve_cubic

TEST(Cubic, Basics) {
    RealRoots r = solve_cubic(1, -6, 11, -6);
    ASSERT_EQ(r.count, 3);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(r.root[i], i + 1.0, 1e-15);
    r = solve_cubic(1, 0, 1, 1);  // one real root
    ASSERT_EQ(r.count, 1);
    EXPECT_NEAR(r.root[0], -0.68232780382801932737, 1e-15);
    r = solve_cubic(1, -3, 3, -1);  // (x - 1)^3
    ASSERT_EQ(r.count, 3);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(r.root[i], 1.0, 1e-5);
    r = solve_cubic(1, -5, 8, -4);  // (x - 1)(x - 2)^2
    ASSERT_EQ(r.count, 3);
    EXPECT_NEAR(r.root[0], 1.0, 1e-15);
    EXPECT_NEAR(r.root[1], 2.0, 1e-7);
    EXPECT_NEAR(r.root[2], 2.0, 1e-7);
    r = solve_cubic(2, 0, 0, 0);
    ASSERT_EQ(r.count, 3);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(r.root[i], 0.0);
    r = solve_cubic(0, 1, -3, 2);  // quadratic
    ASSERT_EQ(r.count, 2);
    EXPECT_EQ(r.root[0], 1.0);
    EXPECT_EQ(r.root[1], 2.0);
    r = solve_cubic(1, 1, 0, 0);  // x^2 (x + 1)
    ASSERT_EQ(r.count, 3);
    EXPECT_EQ(r.root[0], -1.0);
    EXPECT_EQ(r.root[1], 0.0);
    EXPECT_EQ(r.root[2], 0.0);
    r = solve_cubic(-1, 0, 0, 8);  // -x^3 + 8
    ASSERT_EQ(r.count, 1);
    EXPECT_NEAR(r.root[0], 2.0, 1e-15);
    EXPECT_EQ(solve_cubic(0, 0, 0, 0).count, 0);
}

TEST(Cubic, GradedRoots) {
    // Roots 1e-8, 1, 1e8 (and with signs): the depressed form alone loses the small root.
    for (double s1 : {1.0, -1.0})
        for (double s2 : {1.0, -1.0}) {
            const double r[3] = {s1 * 1e-8, s2 * 1.0, 1e8};
            const double b = -(r[0] + r[1] + r[2]), c = r[0] * r[1] + r[0] * r[2] + r[1] * r[2],
                         d = -r[0] * r[1] * r[2];
            const RealRoots x = solve_cubic(1, b, c, d);
            ASSERT_EQ(x.count, 3);
            std::vector<double> want(r, r + 3);
            std::sort(want.begin(), want.end());
            for (int i = 0; i < 3; ++i) EXPECT_NEAR(x.root[i], want[i], 1e-14 * std::fabs(want[i]));
        }
}

TEST(Cubic, RandomAgainstEigenAndKnownRoots) {
    std::mt19937_64 rng(11);
    auto U = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
    double worst_res = 0, worst_fwd = 0;
    long compared = 0, mismatched = 0;
    for (int i = 0; i < 200000 / kScale; ++i) {
        Quartic q{};
        std::vector<double> truth;
        if (i % 2 == 0) {  // random coefficients
            for (int k = 1; k < 5; ++k) q.c[k] = U(-1, 1);
        } else {  // three known real roots, scales 1e-3 .. 1e3
            for (int k = 0; k < 3; ++k) truth.push_back(std::pow(10.0, U(-3, 3)) * (rng() & 1 ? 1 : -1));
            const Quartic p = from_roots(U(0.5, 2), truth.data(), 3);
            std::copy(p.c, p.c + 4, q.c + 1);
        }
        const RealRoots r = solve_cubic(q.c[1], q.c[2], q.c[3], q.c[4]);
        ASSERT_LE(r.count, 3);
        for (int k = 0; k < r.count; ++k) {
            ASSERT_TRUE(std::isfinite(r.root[k]));
            if (k > 0) {
                EXPECT_LE(r.root[k - 1], r.root[k]);
            }
            worst_res = std::max(worst_res, rel_residual(q, r.root[k]));
        }
        for (double x : truth) {
            const double tol = cond_tol(q, x);
            double sep = HUGE_VAL;
            for (double y : truth)
                if (y != x) sep = std::min(sep, std::fabs(y - x));
            if (!(sep > 100 * tol)) continue;
            double err = HUGE_VAL;
            for (int k = 0; k < r.count; ++k) err = std::min(err, std::fabs(r.root[k] - x));
            worst_fwd = std::max(worst_fwd, err / tol);
        }
        // Count against Eigen where its roots are well separated and clearly real/complex.
        Eigen::Vector4d p(q.c[4], q.c[3], q.c[2], q.c[1]);
        Eigen::PolynomialSolver<double, 3> solver(p);
        bool ok = true;
        int nreal = 0;
        for (int k = 0; k < 3; ++k) {
            const cplx z = solver.roots()[k];
            if (std::fabs(z.imag()) <= 1e-12 * std::abs(z))
                ++nreal;
            else if (std::fabs(z.imag()) < 1e-3 * std::abs(z))
                ok = false;
            for (int j = 0; j < k; ++j)
                if (std::abs(z - cplx(solver.roots()[j])) < 1e-3 * std::abs(z)) ok = false;
        }
        if (ok) {
            ++compared;
            if (nreal != r.count) ++mismatched;
        }
    }
    std::printf(
        "[quartic] cubic: worst residual %.2e, worst err/cond %.2f, Eigen count compared "
        "%ld, mismatched %ld\n",
        worst_res, worst_fwd, compared, mismatched);
    EXPECT_LE(worst_res, kResidualBound);
    EXPECT_LE(worst_fwd, kForwardFactor);
    EXPECT_EQ(mismatched, 0);
    EXPECT_GT(compared, 200000 / kScale * 8 / 10);
}

}  // namespace
