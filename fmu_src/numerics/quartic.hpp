// Real roots of polynomials up to degree four in closed form: Ferrari's method for the quartic,
// the resolvent cubic in trigonometric form when it has three real roots. No iteration apart
// from one Newton polish per root; never NaN for finite coefficients.
//
// Common to the three solvers (details in quartic.cpp):
// - Roots are returned ascending in root[0..count); a double root appears twice. Unused
//   entries are 0.
// - Any coefficient non-finite (NaN, +-inf): count = 0.
// - The leading coefficient is dropped (degree reduction) when it is negligible in both senses:
//   |lead| <= 2^-52 * max|other coefficients|, and the roots it adds lie more than 2^52 times
//   further out than all other roots. Roots beyond 2^1000 are never reported. So
//   1e-40 x^4 + x^3 - 6x^2 + 11x - 6 gives 1, 2, 3; x^2 - 1e8 x + 1 gives both roots.
// - The variable is scaled by a power of two (exact) before solving: no overflow or underflow
//   for roots anywhere in the double range, as long as the roots of one polynomial span less
//   than about 75 decades.
// - Each root has a small backward error: |p(x)| <= ~1e-15 * sum |c_i| |x|^i in tests on 10^6
//   quartics of many kinds (tests/cpp/test_quartic.cpp).
// - No heap allocation, no exceptions; thread-safe (no state).
#pragma once

#include <cmath>

namespace ipmsm {

struct RealRoots {
    int count = 0;                  // number of real roots found, 0..4
    double root[4] = {0, 0, 0, 0};  // ascending; a double root appears twice
};

// a x^4 + b x^3 + c x^2 + d x + e = 0. Leading zeros reduce the degree (a = 0: cubic, ...);
// all coefficients zero gives count = 0.
RealRoots solve_quartic(double a, double b, double c, double d, double e);

// x^4 + p x^2 + q x + r = 0 (depressed, monic): the form of the controller's own quartics (MTPA
// and Case ii have no cubic term). Ferrari directly (quartic_depressed.cpp): the largest root of
// the resolvent cubic, two quadratics, one Newton polish per root. No scaling or degree tests:
// for well-scaled coefficients (|roots| within ~1e-6..1e6 of each other) about twice as fast as
// solve_quartic and as accurate; never NaN for finite input.
RealRoots solve_depressed_quartic(double p, double q, double r);

// The same Ferrari path for a caller that wants one root: the roots unsorted and not polished
// (pick one, then polish it with newton_step). a x^4 + b x^3 + c x^2 + d x + e = 0, made monic and
// depressed about the centroid -b/4a, for quartics whose roots of interest are O(1) (the
// controller's tan-half-angle quartics) or that are depressed already (a = 1, b = 0). If the
// centroid is beyond 2^10 (a root near infinity) it returns solve_quartic()'s roots instead.
RealRoots centred_quartic_roots(double a, double b, double c, double d, double e);

// A quartic c[0] x^4 + ... + c[4] and its slope at x (Horner).
struct QuarticValue {
    double f, df;
};
inline QuarticValue quartic_value(const double (&c)[5], double x) {
    return {(((c[0] * x + c[1]) * x + c[2]) * x + c[3]) * x + c[4],
            ((4.0 * c[0] * x + 3.0 * c[1]) * x + 2.0 * c[2]) * x + c[3]};
}

// One Newton step on the quartic c from a root estimate x0, to x1. `better` says whether it
// lowered |c(x)| (false for NaN): then take x1, else keep x0 (at a double root p and p' are both
// rounding noise and the step is arbitrary). Both ends are returned so that a caller can map both
// to what it needs at once and select, instead of waiting for the comparison.
struct NewtonStep {
    double x0, x1;
    bool better;
    double root() const { return better ? x1 : x0; }  // the polished root
};
inline NewtonStep newton_step(const double (&c)[5], double x0) {
    const QuarticValue v = quartic_value(c, x0);
    const double x1 = x0 - v.f / v.df;
    return {x0, x1, std::fabs(quartic_value(c, x1).f) < std::fabs(v.f)};
}

// a x^3 + b x^2 + c x + d = 0, same conventions.
RealRoots solve_cubic(double a, double b, double c, double d);

// a x^2 + b x + c = 0, same conventions (cancellation-free form).
RealRoots solve_quadratic(double a, double b, double c);

}  // namespace ipmsm
