// Ferrari's fast path for depressed quartics x^4 + p x^2 + q x + r (see quartic.hpp), inline so
// that a caller with an independent iteration can interleave it (linear_optimal_current.cpp:
// the T_max polish runs between the stages of the command's solution, and the CPU overlaps the
// two dependency chains; called one after the other they ran nearly in series).
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "numerics/quartic.hpp"

namespace ipmsm::fast {

// a if take, else b, without a branch (SSE2 masks; GCC makes a branch of ?: on doubles, and
// which way these go is data-dependent).
inline double select(bool take, double a, double b) {
#if defined(__SSE2__)
    const __m128d mask = _mm_castsi128_pd(_mm_set1_epi64x(-static_cast<long long>(take)));
    return _mm_cvtsd_f64(_mm_or_pd(_mm_and_pd(mask, _mm_set_sd(a)), _mm_andnot_pd(mask, _mm_set_sd(b))));
#else
    return take ? a : b;
#endif
}

// Cardano's resolvent root is taken as it is if its terms cancel by at most 4 bits (a factor 16).
constexpr double kCancellationFactor = 16.0;
// Largest and smallest x for which inv_cbrt's bit trick and steps stay normal.
constexpr double kInvCbrtMin = 0x1p-300, kInvCbrtMax = 0x1p300;

// x^(-1/3) for x > 0 without a division (the divider is the busiest unit of the controller's
// hot path): a third of the exponent by integer arithmetic (relative error <= 3.4e-2), then two
// fourth-order steps r (1 + e/3 + 2e^2/9 + 14e^3/81), e = 1 - x r^3, the series of (1 - e)^(-1/3)
// (error ~12 d^4: 3.4e-2 -> 1.6e-5 -> 1e-18, i.e. rounding).
inline double inv_cbrt(double x) {
    if (!(x > kInvCbrtMin && x < kInvCbrtMax)) return 1.0 / std::cbrt(x);  // 0, tiny, huge, inf, NaN
    std::uint64_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    bits = 0x553EF10000000000ull - bits / 3;
    double r;
    std::memcpy(&r, &bits, sizeof r);
    for (int k = 0; k < 2; ++k) {
        const double e = 1.0 - x * (r * r * r);
        r += r * e * ((1.0 / 3.0) + e * ((2.0 / 9.0) + (14.0 / 81.0) * e));
    }
    return r;
}

// cos(acos(c) / 3) for c in [-1, 1], to 5.5e-10 (the resolvent root it gives gets a Newton step,
// which squares that): the largest root of the trigonometric form without acos and cos, about
// four times faster. The function is smooth (analytic) in delta = sqrt((1 + c) / 2), not in c
// (its derivative is infinite at c = -1, where two roots of the cubic merge); this is its
// degree-9 interpolant at the Chebyshev nodes of t = 2 delta - 1 in [-1, 1], in powers of t.
inline double cos_third_acos(double c) {
    constexpr double k[10] = {0.76604444273159433,     0.24740906643480404,    -0.015509169100052247,
                              0.0024663472272839172,   -0.00050427800952661532, 0.00011646974919498619,
                              -2.8499026575801157e-05, 7.4195274194721653e-06,  -2.4961721109661992e-06,
                              6.9693870159426301e-07};
    const double t = 2.0 * std::sqrt(0.5 * (1.0 + c)) - 1.0;
    // Estrin's scheme: four levels of multiply-add instead of Horner's nine (latency).
    const double t2 = t * t, t4 = t2 * t2, t8 = t4 * t4;
    const double p01 = k[0] + k[1] * t, p23 = k[2] + k[3] * t, p45 = k[4] + k[5] * t, p67 = k[6] + k[7] * t,
                 p89 = k[8] + k[9] * t;
    return (p01 + p23 * t2) + (p45 + p67 * t2) * t4 + p89 * t8;
}

// x^2 + b x + c = 0, cancellation-free; returns the discriminant (negative: no real roots).
inline double quad_root_pair(double b, double c, double& r1, double& r2) {
    const double disc = b * b - 4.0 * c;
    if (disc < 0.0) return disc;
    const double t = -0.5 * (b + std::copysign(std::sqrt(disc), b));
    r1 = t;
    r2 = t != 0.0 ? c / t : 0.0;
    return disc;
}

// Both reciprocals of the roots x1, x2 of x^2 + b x + c, given 1/c: 1/x1 = x2 / c.
inline void inv_pair(double x1, double x2, double inv_c, double* inv) {
    inv[0] = x2 * inv_c;
    inv[1] = x1 * inv_c;
}

// The reciprocals of roots by division (the rare paths), +inf in the unused slots; returns r.
inline RealRoots with_inverses(const RealRoots& r, double* inv) {
    if (inv)
        for (int k = 0; k < 4; ++k) inv[k] = k < r.count ? 1.0 / r.root[k] : INFINITY;
    return r;
}

// Ferrari's roots of x^4 + p x^2 + q x + r, unsorted and not polished; `interleaved` is called
// three times, between the stages (pass [] {} when there is nothing to interleave). With `inv`,
// also their reciprocals (+inf in the unused slots, as 1/0), without a division per root: the
// roots come in pairs from x^2 + b x + c with c_+ c_- = r, so 1/x1 = x2 / c = x2 c_other / r, and
// 1/r is known from the start, off the dependency chain.
template <class Interleaved>
inline RealRoots depressed_quartic_roots(double p, double q, double r, Interleaved&& interleaved,
                                         double* inv = nullptr) {
    constexpr double kThird = 1.0 / 3.0;
    RealRoots o;
    if (inv) std::fill(inv, inv + 4, INFINITY);
    if (!(std::isfinite(p) && std::isfinite(q) && std::isfinite(r))) return o;  // count 0
    const double inv_r = 1.0 / r;
    // Resolvent cubic m^3 + a2 m^2 + a1 m + a0 = 0 (a2 = p); depressed by m = z - p/3: z^3 + P z + Q = 0.
    const double a1 = 0.25 * p * p - r, a0 = -0.125 * q * q;
    const double a2_3 = p * kThird;
    const double P = a1 - p * a2_3;
    const double Q = (2.0 / 27.0) * p * p * p - a1 * a2_3 + a0;
    const double D = 0.25 * Q * Q + P * P * P * (1.0 / 27.0);
    interleaved();
    double m, cancelled;  // the resolvent root, and the size of the terms it is the sum of
    if (D > 0.0) {
        // One real root, Cardano without cancellation in w: z = A + B, A = -cbrt(w),
        // w = Q/2 + sign(Q) sqrt(D), B = -P / (3 A); with A = -w |w|^(-2/3) and
        // 1/A = -sign(w) |w|^(-1/3), one inverse cube root gives both terms. For P > 0 they
        // have opposite signs and cancel (badly where P^3 >> Q^2: MTPA at high torque); then
        // z = (A^3 + B^3) / (A^2 - AB + B^2) = -Q / (A^2 + B^2 + P/3), a sum of positive terms.
        const double w = 0.5 * Q + std::copysign(std::sqrt(D), Q);
        const double ir = inv_cbrt(std::fabs(w)), A = -w * ir * ir, B = P * kThird * std::copysign(ir, w);
        // A branch, not a select (1-3 ns faster on the linear benchmark): the division is then off
        // the chain where it is not needed. MTPA always has P = -r > 0; Case ii nearly never.
        const double z = P > 0.0 ? -Q / (A * A + B * B + P * kThird) : A + B;
        m = z - a2_3;
        cancelled = std::fabs(z) + std::fabs(a2_3);
    } else {  // three real roots (P <= 0): the largest, in trigonometric form
        const double s = std::sqrt(std::max(0.0, -P * kThird));
        const double c = s > 0.0 ? std::clamp(-0.5 * Q / (s * s * s), -1.0, 1.0) : 0.0;
        m = 2.0 * s * cos_third_acos(c) - a2_3;
        cancelled = INFINITY;  // cos_third_acos is good to 5.5e-10 only: always the Newton step
    }
    // One Newton step on the resolvent (its largest root is simple unless q = 0) where m is not
    // accurate to a few ulps: after the trigonometric form (it squares cos_third_acos's error),
    // and after Cardano if z - p/3 cancels by more than 4 bits.
    if (!(kCancellationFactor * std::fabs(m) >= cancelled)) {
        const double f = ((m + p) * m + a1) * m + a0;
        const double df = (3.0 * m + 2.0 * p) * m + a1;
        const double dm = f / df;
        if (df > 0.0 && std::isfinite(dm)) m -= dm;
    }
    interleaved();
    if (!std::isfinite(m) || !std::isfinite(D)) return with_inverses(solve_quartic(1.0, 0.0, p, q, r), inv);  // extreme scales
    double* y = o.root;
    int n = 0;
    if (m > 0.0 && q != 0.0) {
        // (y^2 + p/2 + m)^2 = 2m (y - q/(4m))^2  =>  y^2 -+ s y + k +- l = 0, s = sqrt(2m),
        // k = p/2 + m, l = q/(2s). The constants c+- = k +- l satisfy c+ c- = k^2 - l^2 = r, so
        // k^2 = l^2 + r exactly: take |k| from that whenever it does not cancel, because
        // p/2 + m cancels when the roots differ much in size, and m itself is only sqrt(eps)
        // accurate when the resolvent's largest root is nearly double (s, a square root of m,
        // stays accurate enough for the final Newton step). Only the sign comes from p/2 + m.
        // l = q s / (4 m) and l^2 = q^2 / (8 m) both come from 1/m: the two square roots run side by side.
        const double inv_m = 1.0 / m, l2 = 0.125 * q * q * inv_m;
        const double s = std::sqrt(2.0 * m), l = (0.25 * q * inv_m) * s, k_direct = 0.5 * p + m;
        const double k2 = l2 + r;
        const double k = (r >= 0.0 || k2 > 0.5 * l2) ? std::copysign(std::sqrt(std::max(0.0, k2)), k_direct) : k_direct;
        interleaved();
        // The smaller constant from the product (no cancellation there).
        const bool plus_big = std::fabs(k + l) >= std::fabs(k - l);
        const double c_big = plus_big ? k + l : k - l;
        const double c_small = c_big != 0.0 ? r / c_big : 0.0;
        const double c_plus = plus_big ? c_big : c_small, c_minus = plus_big ? c_small : c_big;
        if (quad_root_pair(-s, c_plus, y[n], y[n + 1]) >= 0.0) {
            if (inv) inv_pair(y[n], y[n + 1], c_minus * inv_r, inv + n);
            n += 2;
        }
        if (quad_root_pair(s, c_minus, y[n], y[n + 1]) >= 0.0) {
            if (inv) inv_pair(y[n], y[n + 1], c_plus * inv_r, inv + n);
            n += 2;
        }
    } else {
        interleaved();
        // Biquadratic (q = 0, or the resolvent root rounded to <= 0): y^2 = w, w^2 + p w + r = 0.
        double w1, w2;
        if (quad_root_pair(p, r, w1, w2) >= 0.0) {
            for (double w : {w1, w2}) {
                if (w < 0.0) continue;
                // +-v are the roots of y^2 - w: the pair's constant is -w, 1/(-w) = -w_other / r.
                const double v = std::sqrt(w);
                if (inv) inv_pair(v, -v, -(w == w1 ? w2 : w1) * inv_r, inv + n);
                y[n++] = v;
                y[n++] = -v;
            }
        }
    }
    bool finite = true;
    for (int k = 0; k < 4; ++k) finite &= std::isfinite(y[k]);
    if (!finite) return with_inverses(solve_quartic(1.0, 0.0, p, q, r), inv);
    o.count = n;
    if (inv) {
        // r = 0, subnormal or huge, or a pair constant so small that c_other / r overflowed: divide.
        bool inv_finite = std::fabs(inv_r) < INFINITY && std::fabs(inv_r) >= DBL_MIN;
        for (int k = 0; k < n; ++k) inv_finite &= std::isfinite(inv[k]);
        if (!inv_finite) with_inverses(o, inv);
    }
    return o;
}

// Without reciprocals.
inline RealRoots depressed_quartic_roots(double p, double q, double r) {
    return depressed_quartic_roots(p, q, r, [] {});
}

}  // namespace ipmsm::fast
