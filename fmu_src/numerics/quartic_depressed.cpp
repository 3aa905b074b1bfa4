// Ferrari's method for the depressed quartic x^4 + p x^2 + q x + r: the controller's quartics
// (MTPA and Case ii have no cubic term; the limit quartics are centred first). Unlike
// solve_quartic() it neither scales nor reduces the degree: for the well-scaled coefficients it
// is made for it is about twice as fast and as accurate (tests/cpp/test_quartic_depressed.cpp
// checks it against solve_quartic()), and anything it cannot handle goes to solve_quartic().
#include <algorithm>
#include <cmath>
#include <utility>

#include "numerics/quartic.hpp"

namespace ipmsm {
namespace {

// Cardano's or the trigonometric resolvent root is taken as it is if z - p/3 cancels by at most
// 4 bits (a factor 16); otherwise one Newton step restores it.
constexpr double kCancellationFactor = 16.0;

// A centroid of the roots beyond 2^10 means a root near infinity (a tiny leading coefficient)
// for the O(1) roots centred_quartic_roots() is made for: the Taylor shift would cost the other
// roots their accuracy, so solve_quartic() takes over.
constexpr double kCentredMaxShift = 0x1p10;

// The largest root of the resolvent m^3 + p m^2 + (p^2/4 - r) m - q^2/8 of x^4 + p x^2 + q x + r.
double largest_resolvent_root(double p, double q, double r) {
    const double a1 = 0.25 * p * p - r, a0 = -0.125 * q * q, shift = p / 3.0;
    // Depressed by m = z - p/3: z^3 + P z + Q = 0.
    const double P = a1 - p * shift;
    const double Q = (2.0 / 27.0) * p * p * p - a1 * shift + a0;
    const double D = 0.25 * Q * Q + P * P * P / 27.0;
    double z;
    if (D > 0.0) {
        // One real root, Cardano: z = A + B, A = -cbrt(w), w = Q/2 + sign(Q) sqrt(D) (no
        // cancellation in w), B = -P / (3 A). For P > 0, A and B have opposite signs and cancel
        // where P^3 >> Q^2 (MTPA at high torque); then z = -Q / (A^2 + B^2 + P/3), a sum of
        // positive terms (from A^3 + B^3 = -Q and A B = -P/3).
        const double w = 0.5 * Q + std::copysign(std::sqrt(D), Q);
        const double A = -std::cbrt(w), B = A != 0.0 ? -P / (3.0 * A) : 0.0;
        z = P > 0.0 ? -Q / (A * A + B * B + P / 3.0) : A + B;
    } else {  // three real roots (P <= 0): the largest, in trigonometric form
        const double s = std::sqrt(std::max(0.0, -P / 3.0));
        const double c = s > 0.0 ? std::clamp(-0.5 * Q / (s * s * s), -1.0, 1.0) : 0.0;
        z = 2.0 * s * std::cos(std::acos(c) / 3.0);
    }
    double m = z - shift;
    if (!(kCancellationFactor * std::fabs(m) >= std::fabs(z) + std::fabs(shift))) {
        // The largest resolvent root is simple unless q = 0: one Newton step.
        const double f = ((m + p) * m + a1) * m + a0, df = (3.0 * m + 2.0 * p) * m + a1;
        const double dm = f / df;
        if (df > 0.0 && std::isfinite(dm)) m -= dm;
    }
    return m;
}

// The real roots of x^2 + b x + c appended to o (cancellation-free).
void append_quadratic_roots(double b, double c, RealRoots& o) {
    const double disc = b * b - 4.0 * c;
    if (disc < 0.0) return;
    const double t = -0.5 * (b + std::copysign(std::sqrt(disc), b));
    o.root[o.count++] = t;
    o.root[o.count++] = t != 0.0 ? c / t : 0.0;
}

// Ferrari's roots of x^4 + p x^2 + q x + r, unsorted and not polished.
RealRoots depressed_roots(double p, double q, double r) {
    RealRoots o;
    if (!(std::isfinite(p) && std::isfinite(q) && std::isfinite(r))) return o;  // count 0
    const double m = largest_resolvent_root(p, q, r);
    if (!std::isfinite(m)) return solve_quartic(1.0, 0.0, p, q, r);  // extreme scales
    if (m > 0.0 && q != 0.0) {
        // (x^2 + p/2 + m)^2 = 2m (x - q/(4m))^2  =>  x^2 -+ s x + k +- l = 0, s = sqrt(2m),
        // k = p/2 + m, l = q/(2s). The constants c+- = k +- l satisfy c+ c- = k^2 - l^2 = r:
        // |k| comes from k^2 = l^2 + r where that does not cancel (p/2 + m cancels when the
        // roots differ much in size, and m is only sqrt(eps) accurate where the resolvent's
        // largest root is nearly double); only its sign from p/2 + m. The smaller constant
        // comes from the product (no cancellation there).
        const double s = std::sqrt(2.0 * m), l = q / (2.0 * s), l2 = q * q / (8.0 * m), k_direct = 0.5 * p + m;
        const double k2 = l2 + r;
        const double k = (r >= 0.0 || k2 > 0.5 * l2) ? std::copysign(std::sqrt(std::max(0.0, k2)), k_direct) : k_direct;
        const bool plus_big = std::fabs(k + l) >= std::fabs(k - l);
        const double c_big = plus_big ? k + l : k - l;
        const double c_small = c_big != 0.0 ? r / c_big : 0.0;
        append_quadratic_roots(-s, plus_big ? c_big : c_small, o);
        append_quadratic_roots(s, plus_big ? c_small : c_big, o);
    } else {
        // Biquadratic (q = 0, or the resolvent root rounded to <= 0): x^2 = w, w^2 + p w + r = 0.
        RealRoots w;
        append_quadratic_roots(p, r, w);
        for (int k = 0; k < w.count; ++k) {
            if (w.root[k] < 0.0) continue;
            const double v = std::sqrt(w.root[k]);
            o.root[o.count++] = v;
            o.root[o.count++] = -v;
        }
    }
    for (int k = 0; k < o.count; ++k)
        if (!std::isfinite(o.root[k])) return solve_quartic(1.0, 0.0, p, q, r);
    return o;
}

}  // namespace

RealRoots solve_depressed_quartic(double p, double q, double r) {
    RealRoots out = depressed_roots(p, q, r);
    const double c[5] = {1.0, 0.0, p, q, r};
    for (int k = 0; k < out.count; ++k) out.root[k] = newton_step(c, out.root[k]).root();
    for (int k = 1; k < out.count; ++k)  // ascending (insertion sort of at most four)
        for (int j = k; j > 0 && out.root[j - 1] > out.root[j]; --j) std::swap(out.root[j - 1], out.root[j]);
    return out;
}

RealRoots centred_quartic_roots(double a, double b, double c, double d, double e) {
    if (a == 1.0 && b == 0.0) return depressed_roots(c, d, e);
    // Monic, then depressed by x = y + sh about the centroid sh of the roots (Taylor shift).
    const double inv_a = 1.0 / a, B = b * inv_a, C = c * inv_a, D = d * inv_a, E = e * inv_a, sh = -0.25 * B;
    if (!(std::fabs(sh) <= kCentredMaxShift) || !std::isfinite(C + D + E)) return solve_quartic(a, b, c, d, e);
    const double P = C + sh * (3.0 * B + 6.0 * sh);
    const double Q = D + sh * (2.0 * C + sh * (3.0 * B + 4.0 * sh));
    const double R = E + sh * (D + sh * (C + sh * (B + sh)));
    RealRoots out = depressed_roots(P, Q, R);
    for (int k = 0; k < out.count; ++k) out.root[k] += sh;
    return out;
}

}  // namespace ipmsm
