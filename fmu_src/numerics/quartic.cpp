// Closed-form real roots of polynomials of degree <= 4 (see quartic.hpp).
//
// Pipeline shared by the three solvers (degree n, coefficients c_n ... c_0):
//
// 1. A non-finite coefficient gives count 0 (the contract is "finite coefficients"; this only
//    makes sure that garbage in never becomes NaN out).
// 2. Degree reduction (leading_negligible): c_n is dropped when
//      |c_n| <= 2^-52 max_{k<n} |c_k|   (below the rounding level of the other coefficients)
//    AND the roots it adds, about |c_j/c_n|^(1/(n-j)) with c_j the next nonzero coefficient,
//    lie more than 2^52 times further out than every root of the reduced polynomial (Newton
//    polygon estimates from the binary exponents). Then c_n x^n is below 2^-52 of the reduced
//    polynomial's leading term at all of its roots: the far roots are "at infinity" at double
//    precision. Also dropped: roots beyond 2^1000 (not representable). Neither condition alone
//    suffices: x^2 - 1e8 x + 1 and x^4 - 2^51 x^2 + 2^100 keep their leading coefficient.
//    All coefficients zero, or only a nonzero constant: count 0.
// 3. An exactly zero constant term deflates the exact root 0.
// 4. Scaling x = 2^m y, with 2^m at or just above the Fujiwara bound max_k |c_k/c_n|^(1/(n-k))
//    (from the binary exponents alone), and the polynomial multiplied by a power of two so that
//    its leading coefficient is in [1, 2). Then every scaled coefficient is < 2 and every root
//    |y| < 4. Powers of two are exact: the scaled polynomial IS the original one (unless a
//    coefficient underflows), so the Newton polish below is a polish on the original
//    polynomial. Scaling to the largest root rather than to the geometric mean |e/a|^(1/4) keeps
//    every intermediate of the method bounded (no overflow, whatever the spread of the roots),
//    and it is defined when e = 0. Limit: when the roots span more than ~1e75 the products of
//    the small scaled roots underflow and those roots lose accuracy (they stay finite).
// 5. The closed form on the monic scaled polynomial:
//    - quadratic: q = -(b + sign(b) sqrt(disc))/2, roots q and c/q; a discriminant negative by
//      less than its rounding level is a double root.
//    - cubic (cubic_roots): the root of largest magnitude from the depressed cubic, by the
//      trigonometric form (acos/cos) with three real roots, else Cardano with the cube root
//      of -q/2 - sign(q) sqrt(Delta) (no cancellation); the other two from the deflated
//      quadratic with Vieta's relations (a root much smaller than the shift would be lost).
//    - quartic (solve_quartic, ferrari_monic): Ferrari's factorisation into two quadratics via
//      the largest root of the resolvent cubic; depressed (x = y - b/4a) only when all roots
//      are near their centroid, else in the undepressed form that keeps widely scaled roots;
//      cancellation-prone factor coefficients recomputed from Vieta's relations.
// 6. Exactly one Newton step per root on the scaled polynomial, kept only if it is small (at
//    most half the gap to the neighbouring roots and |y|/16) and |p| decreases.
// 7. Unscale (exact), roots ascending, a double root twice.
//
// No heap allocation, no exceptions, no iteration apart from the single Newton step per root.
#include "numerics/quartic.hpp"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <utility>

namespace ipmsm {
namespace {

constexpr double kEps = 0x1p-52;              // DBL_EPSILON
constexpr double kSmallLead = 0x1p-52;        // degree reduction: |lead| <= 2^-52 max|others|
constexpr int kSeparationBits = 52;           // ... and the dropped roots >= 2^52 x the others
constexpr int kMaxRootExp = 1000;             // roots beyond 2^1000 are never reported
constexpr double kClampDisc = 64 * kEps;      // "tiny negative" discriminant, relative
constexpr double kNearDoubleDisc = 0x1p-20;   // window of the near-double-root test
constexpr double kNearDoubleRes = 16 * kEps;  // its residual tolerance
constexpr double kDepressRatio = 0.8;         // depress the quartic or not (solve_quartic)
constexpr int kZeroExp = -1000000;            // exponent given to 0 (below any real one)

// floor(log2|v|) for finite nonzero v (also subnormal); kZeroExp for 0.
inline int exponent_of(double v) {
    std::uint64_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    const int field = static_cast<int>((bits >> 52) & 0x7ff);
    if (field != 0) return field - 1023;
    if (v == 0.0) return kZeroExp;
    return std::ilogb(v);  // subnormal: rare
}

// 2^n for n in [-1022, 1023], built from the bits.
inline double pow2(int n) {
    const std::uint64_t bits = static_cast<std::uint64_t>(n + 1023) << 52;
    double r;
    std::memcpy(&r, &bits, sizeof r);
    return r;
}

// x * 2^n, exact unless the result over- or underflows.
inline double scale2(double x, int n) {
    if (n >= -1022 && n <= 1023) return x * pow2(n);
    return std::ldexp(x, n);
}

// ceil(n / d) for d > 0 and any n.
inline int ceil_div(int n, int d) {
    constexpr int kBias = 1 << 22;  // > |kZeroExp| + 2100: the numerator stays positive
    return (n + d * kBias + d - 1) / d - kBias;
}

inline bool all_finite(double a, double b, double c, double d, double e) {
    // x * 0 is 0 for finite x and NaN for inf/NaN; the sum is 0 iff all are finite.
    return (a * 0.0 + b * 0.0 + c * 0.0 + d * 0.0 + e * 0.0) == 0.0;
}

// Exponent m of the power-of-two root scale 2^m >= max_k |c_k/c_n|^(1/(n-k)) (Fujiwara), given
// binary exponents ex[0..n] (ex[n] of the nonzero leading coefficient).
template <int N>
inline int root_scale_exponent(const int (&ex)[N + 1]) {
    int m = kZeroExp;
    for (int k = 0; k < N; ++k) {
        if (ex[k] == kZeroExp) continue;
        m = std::max(m, ceil_div(ex[k] - ex[N], N - k));
    }
    return m == kZeroExp ? 0 : m;
}

// Degree reduction (step 2): is the leading coefficient c_N negligible? ex[0..N] are the binary
// exponents of c_0..c_N; `small` says |c_N| <= 2^-52 max_{k<N} |c_k|. Newton-polygon
// estimates in whole bits: with j the highest index below N with c_j != 0, the N - j roots
// that c_N creates have magnitude about F = |c_j/c_N|^(1/(N-j)), and the roots of the reduced
// polynomial c_j x^j + ... + c_0 are at most about R = max_{k<j} |c_k/c_j|^(1/(j-k)).
// c_N is negligible when
//  - it is small relative to the other coefficients (below the rounding level of the largest)
//    AND the roots it creates are beyond 2^52 R: then |c_N x^N| < 2^-52 |c_j x^j| at every root
//    of the reduced polynomial, and the far roots are "at infinity" at double precision; or
//  - F > 2^1000: those roots are not representable.
// Both conditions are needed: x^2 - 1e8 x + 1 (separation 1e16) and x^4 - 2^51 x^2 + 2^100
// (|c_4| = 2^-100 max |c_k|) keep their leading coefficient. A reduced polynomial c_j x^j
// (R = 0) gives no yardstick: c_N is kept. The exponents are multiplied by 12 so that the
// divisions by 1..4 are exact integer divisions.
template <int N>
inline bool leading_negligible(const int (&ex)[N + 1], bool small) {
    if (ex[N] == kZeroExp) return true;
    if (!small) return false;  // (F > 2^1000 implies |c_N| < 2^-999 max |c_k|: small)
    int j = N - 1;
    while (j >= 0 && ex[j] == kZeroExp) --j;
    if (j < 0) return false;  // c_N x^N: the root 0
    const int far = (12 / (N - j)) * (ex[j] - ex[N]);
    if (far > 12 * kMaxRootExp) return true;
    bool any = false;
    int rest = 0;
    for (int k = 0; k < j; ++k) {
        if (ex[k] == kZeroExp) continue;
        const int v = (12 / (j - k)) * (ex[k] - ex[j]);
        rest = any ? std::max(rest, v) : v;
        any = true;
    }
    return any && far >= rest + 12 * kSeparationBits;
}

// p(y) and p'(y) of sum_k q[k] y^k (degree N) by Horner's rule, unrolled.
template <int N, std::size_t... I>
inline void horner_pd(const double (&q)[N + 1], double y, double& p, double& dp, std::index_sequence<I...>) {
    p = q[N];
    dp = 0.0;
    ((dp = dp * y + p, p = p * y + q[N - 1 - I]), ...);
}
template <int N, std::size_t... I>
inline double horner_p(const double (&q)[N + 1], double y, std::index_sequence<I...>) {
    double p = q[N];
    ((p = p * y + q[N - 1 - I]), ...);
    return p;
}

// One Newton step on sum_k q[k] y^k (degree N) from y, kept only if the step is at most
// max_step and |p| decreases. The step limit keeps the step inside the basin of the root being
// polished: at a double root p and p' are both at rounding level and the "Newton step" is
// arbitrary; it could land on another root, where |p| is also small.
template <int N>
inline double polish(const double (&q)[N + 1], double y, double max_step) {
    double p, dp;
    horner_pd<N>(q, y, p, dp, std::make_index_sequence<N>{});
    if (p == 0.0 || dp == 0.0) return y;
    const double step = p / dp;
    if (!(std::fabs(step) <= max_step)) return y;  // also rejects NaN
    const double y1 = y - step;
    const double p1 = horner_p<N>(q, y1, std::make_index_sequence<N>{});
    return std::fabs(p1) < std::fabs(p) ? y1 : y;
}

inline void cswap(double& x, double& y) {
    const double lo = std::min(x, y), hi = std::max(x, y);
    x = lo;
    y = hi;
}

// Sorts y[0..4) ascending: a five-comparator network, no branches on the data.
inline void sort4(double* y) {
    cswap(y[0], y[1]);
    cswap(y[2], y[3]);
    cswap(y[0], y[2]);
    cswap(y[1], y[3]);
    cswap(y[1], y[2]);
}

// Adds the exact root 0 to a sorted list (count < 4).
inline RealRoots with_zero_root(RealRoots r) {
    int i = r.count;
    while (i > 0 && r.root[i - 1] > 0.0) {
        r.root[i] = r.root[i - 1];
        --i;
    }
    r.root[i] = 0.0;
    ++r.count;
    return r;
}

// A monic polynomial y^deg + c[deg-1] y^(deg-1) + ... + c[0] whose roots are sought, seen from
// a quadratic factor whose variable is y - shift (for the near-double-root test below).
struct MonicPoly {
    const double* c;
    int deg;
    double shift;
};

// Is y + shift a root of p to within rounding: |p| <= kNearDoubleRes * sum |c_k| |y|^k ?
inline bool root_to_rounding(const MonicPoly& p, double y) {
    const double x = y + p.shift, ax = std::fabs(x);
    double v = 1.0, s = 1.0;
    for (int k = p.deg - 1; k >= 0; --k) {
        v = v * x + p.c[k];
        s = s * ax + std::fabs(p.c[k]);
    }
    return std::fabs(v) <= kNearDoubleRes * s;
}

// Real roots of the monic quadratic y^2 + al y + be, appended to out[n..]; returns the new n.
// Cancellation-free form. A discriminant that is negative by less than its rounding level
// (relative kClampDisc) is taken as zero, which gives a double root. A factor computed from a
// quartic or cubic carries more error than that when roots of the two factors are close
// (clusters); a real double root of the whole polynomial can then come out as a complex pair
// with a tiny imaginary part. So, if `whole` is given and the discriminant is negative but
// small (relative < kNearDoubleDisc), the double root -al/2 is accepted when it is a root of
// the whole polynomial to within rounding.
inline int quadratic_roots(double al, double be, double* out, int n, const MonicPoly* whole = nullptr) {
    const double al2 = al * al;
    double disc = al2 - 4.0 * be;
    if (disc < 0.0) {
        const double size = al2 + 4.0 * std::fabs(be);
        if (disc < -kClampDisc * size &&
            !(whole && disc >= -kNearDoubleDisc * size && root_to_rounding(*whole, -0.5 * al)))
            return n;
        disc = 0.0;
    }
    if (disc == 0.0) {  // double root (also al == 0 == be)
        out[n] = out[n + 1] = -0.5 * al;
        return n + 2;
    }
    const double qq = -0.5 * (al + std::copysign(std::sqrt(disc), al));
    out[n] = qq;
    out[n + 1] = be / qq;
    return n + 2;
}

// Extreme real roots of the depressed cubic t^3 + p t + q = 0.
// Three real roots (Delta <= 0): trigonometric form; t[0] the largest, t[1] the smallest.
// One real root (Delta > 0): Cardano with the cancellation-free choice of the cube root, in t[0].
struct DepressedCubic {
    int count;  // 3 or 1
    double t[2];
};

inline DepressedCubic depressed_cubic(double p, double q) {
    DepressedCubic r{};
    const double hq = 0.5 * q, tp = p * (1.0 / 3.0);
    const double delta = hq * hq + tp * tp * tp;
    if (delta > 0.0) {
        // u^3 = -q/2 - sign(q) sqrt(Delta): both terms of the same sign, |u| as large as it gets.
        const double s = std::sqrt(delta);
        const double u = std::cbrt(-hq - std::copysign(s, hq));
        double t = 0.0;
        if (u != 0.0) {
            const double v = -tp / u;  // u v = -p/3
            // p >= 0: u and v have opposite signs, u + v cancels; use t = -q / (u^2 - u v + v^2)
            // whose denominator is then a sum of positive terms.
            if (tp >= 0.0) {
                const double den = u * u + tp + v * v;
                t = den > 0.0 ? -q / den : 0.0;
            } else {
                t = u + v;
            }
        }
        r.count = 1;
        r.t[0] = t;
        return r;
    }
    // Delta <= 0 implies p <= 0.
    const double rr = std::sqrt(std::max(-tp, 0.0));
    if (rr == 0.0) {  // triple root 0
        r.count = 3;
        return r;
    }
    double c = -hq / (rr * rr * rr);
    c = std::min(1.0, std::max(-1.0, c));
    const double phi = std::acos(c) * (1.0 / 3.0);  // [0, pi/3]
    const double cp = std::cos(phi);
    const double sp = std::sqrt(std::max(0.0, (1.0 - cp) * (1.0 + cp)));
    constexpr double kHalfSqrt3 = 0.86602540378443864676;
    r.count = 3;
    r.t[0] = 2.0 * rr * cp;                       // 2 r cos(phi),          cos in [1/2, 1]
    r.t[1] = -rr * (cp + 2.0 * kHalfSqrt3 * sp);  // 2 r cos(phi + 2 pi/3), cos in [-1, -1/2]
    return r;
}

// Real roots of the monic cubic x^3 + a2 x^2 + a1 x + a0 (coefficients O(1)) into x[0..3),
// unsorted; returns 1 or 3.
// The depressed form (x = t - a2/3) is accurate only for the root(s) of largest magnitude: a
// root much smaller than |a2| is lost to cancellation in the shift. So only the root r of
// largest magnitude is taken from the trigonometric/Cardano formula, and the other two come
// from the deflated quadratic x^2 + s x + P with Vieta's relations
//   a2 = s - r,   a1 = P - r s,   a0 = -r P,
// taking P = -a0/r (relatively accurate) and s from whichever of a2 + r, (P - a1)/r does not
// cancel. A double root that rounding moved to the one-real-root side is recovered by the
// discriminant clamp of the quadratic. When Cardano's single real root is small next to the
// complex pair, it is recomputed from the product, r = -a0 / P with P = a1 + r (a2 + r).
inline int cubic_roots(double a2, double a1, double a0, double* x, const MonicPoly* whole = nullptr) {
    const double sh = a2 * (1.0 / 3.0);
    const double p = a1 - a2 * sh;
    const double q = (2.0 / 27.0) * a2 * a2 * a2 - sh * a1 + a0;
    const DepressedCubic dc = depressed_cubic(p, q);
    double r;
    if (dc.count == 3) {
        const double r0 = dc.t[0] - sh, r2 = dc.t[1] - sh;
        r = std::fabs(r0) >= std::fabs(r2) ? r0 : r2;
    } else {
        r = dc.t[0] - sh;
        const double pc = a1 + r * (a2 + r);  // product of the complex pair
        if (r * r < 0x1p-10 * std::fabs(pc)) r = -a0 / pc;
    }
    double s, P;
    if (r == 0.0) {  // all roots 0
        s = a2;
        P = a1;
    } else {
        P = -a0 / r;
        s = (r * r > std::fabs(P) + std::fabs(a1)) ? (P - a1) / r : a2 + r;
    }
    x[0] = r;
    return quadratic_roots(s, P, x, 1, whole);
}

// Largest real root of the monic cubic x^3 + a2 x^2 + a1 x + a0 (the resolvent). Its
// coefficients are bounded (no overflow) but can be tiny when the quartic's roots are widely
// spread (resolvent roots are products of quartic roots); x = 2^k w with 2^k near the
// cubic's own Fujiwara bound keeps the cubic formulas (which square and cube q and p) clear
// of underflow.
inline double largest_cubic_root(double a2, double a1, double a0) {
    if (std::fabs(a2) > 0x1p-60 || std::fabs(a1) > 0x1p-120 || std::fabs(a0) > 0x1p-180) {
        double x[3];  // roots of magnitude > 2^-62: no underflow to fear
        const int n = cubic_roots(a2, a1, a0, x);
        double mx = x[0];
        for (int i = 1; i < n; ++i) mx = std::max(mx, x[i]);
        return mx;
    }
    const int e2 = exponent_of(a2), e1 = exponent_of(a1), e0 = exponent_of(a0);
    int k = kZeroExp;
    if (e2 != kZeroExp) k = e2 + 1;
    if (e1 != kZeroExp) k = std::max(k, ceil_div(e1 + 1, 2));
    if (e0 != kZeroExp) k = std::max(k, ceil_div(e0 + 1, 3));
    if (k == kZeroExp) return 0.0;  // x^3
    double x[3];
    const int n = cubic_roots(scale2(a2, -k), scale2(a1, -2 * k), scale2(a0, -3 * k), x);
    double m = x[0];
    for (int i = 1; i < n; ++i) m = std::max(m, x[i]);
    return scale2(m, k);
}

// The monic quartic y^4 + B y^3 + C y^2 + D y + E about y = sh, by synthetic division:
// z^4 + (B + 4 sh) z^3 + P z^2 + Q z + R with P = p''(sh)/2, Q = p'(sh), R = p(sh).
struct TaylorShift {
    double P, Q, R;
};

inline TaylorShift taylor_shift(double B, double C, double D, double E, double sh) {
    double c3 = B + sh;
    double c2 = C + sh * c3;
    double c1 = D + sh * c2;
    const double R = E + sh * c1;
    c3 += sh;
    c2 += sh * c3;
    const double Q = c1 + sh * c2;
    c3 += sh;
    return {c2 + sh * c3, Q, R};
}

// Roots y of the monic scaled quartic y^4 + B y^3 + C y^2 + D y + E (|B..E| < 2) by Ferrari's
// method; returns the number found in y[0..4) (unsorted, unpolished).
int ferrari_monic(double B, double C, double D, double E, double* y, const MonicPoly& whole) {
    // Ferrari: y^4 + B y^3 + C y^2 + D y + E = (y^2 + B/2 y + L/2)^2 - (g y + h)^2 with
    //   g^2 = B^2/4 - C + L,   2 g h = B L/2 - D,   h^2 = L^2/4 - E,
    // which requires L to be a root of the resolvent cubic
    //   L^3 - C L^2 + (B D - 4E) L + (4 C E - B^2 E - D^2) = 0.
    // The factors are y^2 + (B/2 +- g) y + (L/2 +- h). L = y1 y2 + y3 y4 for a pairing of the
    // roots, and g = ((y1 + y2) - (y3 + y4))/2: the largest resolvent root gives the largest |g|
    // (the pairing least prone to cancellation) and always a real factorisation.
    //
    // This is Ferrari's original (undepressed) form. Depressing the quartic first (y = z - B/4)
    // makes the depressed coefficients absolutely, not relatively, accurate: roots much smaller
    // than |B|/4 (1e-4 next to 1e4, say) are then lost to cancellation beyond what one Newton
    // step can repair. In this form the resolvent roots are sums of products of the roots and
    // keep their relative accuracy for widely scaled roots. (The resolvent cubic itself is
    // depressed for the trigonometric/Cardano formulas.)
    const double L = largest_cubic_root(-C, B * D - 4.0 * E, E * (4.0 * C - B * B) - D * D);

    const double hB = 0.5 * B, hL = 0.5 * L;
    // Magnitudes of the terms of g^2 and h^2. The floor 2^-960 counts values near the
    // underflow threshold (a resolvent root ~ D^2 of a near-biquadratic with tiny D can be
    // subnormal) as inaccurate.
    const double g2s = hB * hB + std::fabs(C) + std::fabs(L) + 0x1p-960;
    const double h2s = hL * hL + std::fabs(E) + 0x1p-960;
    double g2 = hB * hB - C + L;
    double h2 = hL * hL - E;
    g2 = std::max(g2, 0.0);
    h2 = std::max(h2, 0.0);
    const double k = hB * L - D;  // = 2 g h
    // Take the square root of whichever of g^2, h^2 is relatively more accurate (less
    // cancellation), and the other from 2 g h = k. Near-biquadratic quartics (g ~ 0) go through h.
    double g, h;
    if (g2 * h2s >= h2 * g2s) {
        g = std::sqrt(g2);
        h = g > 0.0 ? k / (2.0 * g) : std::sqrt(h2);
    } else {
        h = std::sqrt(h2);
        g = h > 0.0 ? k / (2.0 * h) : std::sqrt(g2);
    }

    // Factor i: y^2 + al[i] y + be[i]. The larger of each +- pair has no cancellation; the
    // smaller one is recomputed from Vieta's relations with the original coefficients:
    //   al0 + al1 = B,  be0 + be1 + al0 al1 = C,  al0 be1 + al1 be0 = D,  be0 be1 = E.
    double al[2] = {hB + g, hB - g};
    double be[2] = {hL + h, hL - h};
    {
        const int bi = std::fabs(be[0]) >= std::fabs(be[1]) ? 0 : 1;
        if (be[bi] != 0.0) be[1 - bi] = E / be[bi];
    }
    {
        const int i = std::fabs(al[0]) >= std::fabs(al[1]) ? 0 : 1;
        const int j = 1 - i;
        const double ai = al[i], bi = be[i], bj = be[j];
        // Three expressions for al[j]; take the one with the smallest a-priori rounding error
        // (in units of eps; compared by cross-multiplication, no division):
        //   B - al[i]                  ~ |al[i]|
        //   (C - be[i] - be[j]) / al[i] ~ (|C| + |be[i]| + |be[j]|) / |al[i]|
        //   (D - al[i] be[j]) / be[i]   ~ (|D| + |al[i] be[j]|) / |be[i]|
        const double aai = std::fabs(ai), abi = std::fabs(bi);
        const double nc = std::fabs(C) + abi + std::fabs(bj);
        const double nd = std::fabs(D) + aai * std::fabs(bj);
        const double e1 = aai;
        const bool c_beats_1 = nc < e1 * aai;        // e2 < e1
        const bool d_beats_1 = nd < e1 * abi;        // e3 < e1
        const bool d_beats_c = nd * aai < nc * abi;  // e3 < e2
        if (d_beats_1 && (d_beats_c || !c_beats_1)) {
            al[j] = (D - ai * bj) / bi;
        } else if (c_beats_1) {
            al[j] = (C - bi - bj) / ai;
        }
        // else keep al[j] = B/2 -+ g, which equals B - al[i] up to rounding
    }
    int n = quadratic_roots(al[0], be[0], y, 0, &whole);
    n = quadratic_roots(al[1], be[1], y, n, &whole);
    return n;
}

// b x + c = 0.
RealRoots solve_linear(double b, double c) {
    RealRoots out;
    const int ex[2] = {exponent_of(c), exponent_of(b)};
    // b == 0, or the root would overflow (there is no other root to compare with).
    if (leading_negligible<1>(ex, std::fabs(b) <= kSmallLead * std::fabs(c))) return out;
    const double x = c == 0.0 ? 0.0 : -c / b;  // correctly rounded; no polish needed
    if (std::isfinite(x)) {
        out.count = 1;
        out.root[0] = x;
    }
    return out;
}

// Polishes the scaled roots y[0..n) on q (degree N), unscales by 2^m, sorts, drops any root
// that would overflow. The Newton step of a root is limited to half the distance to the
// nearest other root and to |y|/16 (the closed form is far more accurate than that for any
// root that Newton's method can improve). An identical twin (a double root, both copies
// polished alike) does not count as another root. Always four slots, unused ones +inf, so
// that the work does not depend on the number of roots (fewer mispredicted branches).
template <int N>
inline RealRoots finish(const double (&q)[N + 1], const double* yin, int n, int m) {
    double y[4];
    for (int i = 0; i < 4; ++i) y[i] = i < n ? yin[i] : HUGE_VAL;
    sort4(y);
    // Sorted: the nearest other root is a neighbour, and steps of at most half the gap keep
    // the order. (A twin's gap 0 is skipped by taking the next distinct neighbour: y[i-2] or
    // y[i+2] can only matter for a double root, whose copies move alike.)
    double lo[4], hi[4];
    for (int i = 0; i < 4; ++i) {
        double gap_lo = HUGE_VAL, gap_hi = HUGE_VAL;
        for (int j = i - 1; j >= 0; --j)
            if (y[j] != y[i]) {
                gap_lo = y[i] - y[j];
                break;
            }
        for (int j = i + 1; j < 4; ++j)
            if (y[j] != y[i]) {
                gap_hi = y[j] - y[i];
                break;
            }
        lo[i] = gap_lo;
        hi[i] = gap_hi;
    }
    RealRoots out;
    int k = 0;
    for (int i = 0; i < 4; ++i) {
        const double lim = std::min(0.0625 * std::fabs(y[i]), 0.5 * std::min(lo[i], hi[i]));
        const double x = scale2(polish<N>(q, y[i], lim), m);  // +inf stays +inf
        // Roots that overflow to +-inf (possible only for a leading coefficient just above
        // the degree-reduction threshold) are left out, as are the +inf pads.
        out.root[k] = x;
        k += std::fabs(x) <= DBL_MAX;
    }
    for (int i = k; i < 4; ++i) out.root[i] = 0.0;
    out.count = k;
    return out;
}

}  // namespace

RealRoots solve_quadratic(double a, double b, double c) {
    if (!all_finite(a, b, c, 0.0, 0.0)) return RealRoots{};
    const int ex[3] = {exponent_of(c), exponent_of(b), exponent_of(a)};
    if (leading_negligible<2>(ex, std::fabs(a) <= kSmallLead * std::max(std::fabs(b), std::fabs(c))))
        return solve_linear(b, c);
    if (c == 0.0) return with_zero_root(solve_linear(a, b));
    const int m = root_scale_exponent<2>(ex);
    const int t = -ex[2];
    const double q[3] = {scale2(c, t - 2 * m), scale2(b, t - m), scale2(a, t)};
    const double inv = 1.0 / q[2];
    double y[2];
    const int n = quadratic_roots(q[1] * inv, q[0] * inv, y, 0);
    return finish<2>(q, y, n, m);
}

RealRoots solve_cubic(double a, double b, double c, double d) {
    if (!all_finite(a, b, c, d, 0.0)) return RealRoots{};
    const int ex[4] = {exponent_of(d), exponent_of(c), exponent_of(b), exponent_of(a)};
    const double rest = std::max(std::max(std::fabs(b), std::fabs(c)), std::fabs(d));
    if (leading_negligible<3>(ex, std::fabs(a) <= kSmallLead * rest)) return solve_quadratic(b, c, d);
    if (d == 0.0) return with_zero_root(solve_quadratic(a, b, c));
    const int m = root_scale_exponent<3>(ex);
    const int t = -ex[3];
    const double q[4] = {scale2(d, t - 3 * m), scale2(c, t - 2 * m), scale2(b, t - m), scale2(a, t)};
    const double inv = 1.0 / q[3];
    double y[3];
    const double mc[3] = {q[0] * inv, q[1] * inv, q[2] * inv};
    const MonicPoly whole{mc, 3, 0.0};
    const int n = cubic_roots(mc[2], mc[1], mc[0], y, &whole);
    return finish<3>(q, y, n, m);
}

RealRoots solve_quartic(double a, double b, double c, double d, double e) {
    if (!all_finite(a, b, c, d, e)) return RealRoots{};
    const int ex[5] = {exponent_of(e), exponent_of(d), exponent_of(c), exponent_of(b), exponent_of(a)};
    const double rest = std::max(std::max(std::fabs(b), std::fabs(c)), std::max(std::fabs(d), std::fabs(e)));
    if (leading_negligible<4>(ex, std::fabs(a) <= kSmallLead * rest)) return solve_cubic(b, c, d, e);
    if (e == 0.0) return with_zero_root(solve_cubic(a, b, c, d));
    const int m = root_scale_exponent<4>(ex);
    const int t = -ex[4];
    double q[5];
    if (m >= -255 && m <= 255 && t - 4 * m >= -1022 && t - 4 * m <= 1023 && t >= -1022 &&
        t <= 1023) {  // the usual case: every power of two below is a normal number
        const double f = pow2(t), g = pow2(-m), g2 = g * g;
        q[4] = a * f;
        q[3] = b * (f * g);
        q[2] = c * (f * g2);
        q[1] = d * (f * (g2 * g));
        q[0] = e * (f * (g2 * g2));
    } else {
        q[0] = scale2(e, t - 4 * m);
        q[1] = scale2(d, t - 3 * m);
        q[2] = scale2(c, t - 2 * m);
        q[3] = scale2(b, t - m);
        q[4] = scale2(a, t);
    }
    const double inv = 1.0 / q[4];
    const double B = q[3] * inv, C = q[2] * inv, D = q[1] * inv, E = q[0] * inv;
    const double mc[4] = {E, D, C, B};
    // Depress (y = z - B/4) only when every root is near the centroid sh = -B/4: then no root
    // is much smaller than the shift, and the depressed quartic z^4 + P z^2 + Q z + R is well
    // scaled even for a tight cluster of four roots (for which the undepressed resolvent is
    // degenerate: g^2 and h^2 below both cancel). Otherwise the undepressed form is used: it
    // keeps roots much smaller than |B|/4 (widely scaled roots), which the shift would destroy.
    // The test compares max(|P|^(1/2), |Q|^(1/3), |R|^(1/4)), the Newton-polygon estimate of
    // the largest |z_i| (within a factor of 2), with kDepressRatio |sh|. kDepressRatio = 0.8 was
    // tuned on the test classes: at 1.2 small real roots next to a distant complex pair lose
    // accuracy, at 0.5 a double root next to a complex pair of similar size stays on the
    // undepressed side with a cancelling g^2 (residuals up to 5e-15 instead of 1e-15).
    const double sh = -0.25 * B;
    const auto [P, Q, R] = taylor_shift(B, C, D, E, sh);  // the z^3 coefficient B + 4 sh is 0
    const double s1 = kDepressRatio * std::fabs(sh), s2 = s1 * s1;
    double y[4];
    int n;
    if (std::fabs(P) < s2 && std::fabs(Q) < s2 * s1 && std::fabs(R) < s2 * s2) {
        n = ferrari_monic(0.0, P, Q, R, y, MonicPoly{mc, 4, sh});
        for (int i = 0; i < n; ++i) y[i] += sh;
    } else {
        n = ferrari_monic(B, C, D, E, y, MonicPoly{mc, 4, 0.0});
    }
    return finish<4>(q, y, n, m);
}

}  // namespace ipmsm
