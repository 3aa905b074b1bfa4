// Real roots of polynomials up to degree four in closed form: Ferrari's method for the quartic,
// the resolvent cubic in trigonometric form when it has three real roots. No iteration apart
// from one Newton polish per root; never NaN for finite coefficients.
#pragma once

namespace ipmsm {

struct RealRoots {
    int count = 0;             // number of real roots found, 0..4
    double root[4] = {0, 0, 0, 0};  // ascending; a double root appears twice
};

// a x^4 + b x^3 + c x^2 + d x + e = 0. Leading zeros reduce the degree (a = 0: cubic, ...);
// all coefficients zero gives count = 0.
RealRoots solve_quartic(double a, double b, double c, double d, double e);

// a x^3 + b x^2 + c x + d = 0, same conventions.
RealRoots solve_cubic(double a, double b, double c, double d);

// a x^2 + b x + c = 0, same conventions (cancellation-free form).
RealRoots solve_quadratic(double a, double b, double c);

}  // namespace ipmsm
